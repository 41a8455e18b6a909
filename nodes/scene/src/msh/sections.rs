//! The sections of a mesh file: `$MeshFormat`, `$PhysicalNames`, `$Entities`, `$Nodes` and
//! `$Elements` in MSH 4.1 and 2.2, and the skipping of any other.

use super::parser::{clip, Parser};
use super::state::State;
use super::types::{type_name, type_nodes};
use super::{MshElement, MshError, Version};
use std::collections::HashMap;

impl Parser<'_> {
    pub(super) fn mesh_format(&mut self) -> Result<Version, MshError> {
        self.skip_ws();
        self.at = self.pos;
        let first = if self.pos < self.b.len() {
            self.token("$MeshFormat")?
        } else {
            ""
        };
        if first != "$MeshFormat" {
            return Err(self.err_at(self.at, "missing $MeshFormat: not a Gmsh mesh file".into()));
        }
        self.end_of_line();
        let v = self.token("the version of $MeshFormat")?;
        let version = match v {
            "4.1" => Version::V41,
            "2.2" => Version::V22,
            _ => {
                return Err(self.err(format!(
                    "MSH version {} is not read: only 4.1 and 2.2 (Gmsh option Mesh.MshFileVersion)",
                    clip(v)
                )))
            }
        };
        let file_type: i32 = self.parse_tok("the file type of $MeshFormat (0 ASCII, 1 binary)")?;
        let data_size: i32 = self.parse_tok("the data size of $MeshFormat")?;
        match file_type {
            0 => {}
            1 => {
                if data_size != 8 {
                    return Err(self.err(format!(
                        "binary file with a size_t of {data_size} bytes: only 8 is read"
                    )));
                }
                self.end_of_line();
                let one: [u8; 4] = self.raw("the endianness check (the int 1)")?;
                self.binary = true;
                if one == [0, 0, 0, 1] {
                    return Err(self.err("big-endian binary file: only little-endian is read".into()));
                }
                if one != [1, 0, 0, 0] {
                    return Err(self.err(format!(
                        "the endianness check is not the int 1 of 4 bytes (found bytes {one:?})"
                    )));
                }
                self.at = self.pos;
                if self.b.get(self.pos) != Some(&b'\n') {
                    return Err(self.err("the endianness check is not an int of 4 bytes: only 4 is read".into()));
                }
            }
            _ => return Err(self.err(format!("file type {file_type}: expected 0 (ASCII) or 1 (binary)"))),
        }
        self.expect_end("MeshFormat")?;
        Ok(version)
    }

    pub(super) fn expect_end(&mut self, name: &str) -> Result<(), MshError> {
        let end = format!("$End{name}");
        let tok = self.token(&end)?;
        if tok != end && self.pos == self.b.len() && end.starts_with(tok) {
            return Err(self.eof(&end));
        }
        if tok != end {
            return Err(self.err(format!("{end} expected, found '{}'", clip(tok))));
        }
        self.end_of_line();
        Ok(())
    }

    /// Skips a section up to its `$End<Name>` line (in binary files too: searched as bytes).
    pub(super) fn skip_section(&mut self, name: &str) -> Result<(), MshError> {
        let end = format!("$End{name}");
        let start = self.at;
        let mut i = self.pos;
        while let Some(off) = self.b[i..].iter().position(|&c| c == b'$') {
            let j = i + off;
            let after = j + end.len();
            if (j == 0 || self.b[j - 1] == b'\n')
                && self.b[j..].starts_with(end.as_bytes())
                && (after == self.b.len() || self.b[after].is_ascii_whitespace())
            {
                self.pos = after;
                self.end_of_line();
                return Ok(());
            }
            i = j + 1;
        }
        self.at = self.b.len();
        Err(self.err(format!(
            "unexpected end of file: {end} expected (section ${name} of {} has no end)",
            self.err_at(start, String::new()).location
        )))
    }

    pub(super) fn physical_names(&mut self, st: &mut State) -> Result<(), MshError> {
        // ASCII in binary files too.
        let n: u64 = self.parse_tok("the number of physical names")?;
        let n = self.count(n, "number of physical names")?;
        for _ in 0..n {
            let dim: u8 = self.parse_tok("the dimension of a physical name")?;
            if dim > 3 {
                return Err(self.err(format!("physical name of dimension {dim}: expected 0 to 3")));
            }
            let tag: i32 = self.parse_tok("the tag of a physical name")?;
            self.skip_ws_in_line();
            self.at = self.pos;
            if !self.b[self.pos..].contains(&b'\n') {
                return Err(self.eof("a physical name"));
            }
            let rest = self.end_of_line().trim();
            let name = rest.strip_prefix('"').and_then(|r| r.strip_suffix('"'));
            let Some(name) = name else {
                return Err(self.err(format!("physical name '{}' is not in double quotes", clip(rest))));
            };
            st.names.insert((dim, tag), name.to_string());
        }
        Ok(())
    }

    /// MSH 4.1 `$Entities`: the physical tags of every point, curve, surface and volume.
    pub(super) fn entities(&mut self, st: &mut State) -> Result<(), MshError> {
        let mut counts = [0usize; 4];
        for (dim, c) in counts.iter_mut().enumerate() {
            let what = [
                "number of points",
                "number of curves",
                "number of surfaces",
                "number of volumes",
            ][dim];
            let v = self.size(what)?;
            *c = self.count(v, what)?;
        }
        for (dim, &n) in counts.iter().enumerate() {
            for _ in 0..n {
                let tag = self.int("an entity tag")?;
                let boxes = if dim == 0 { 3 } else { 6 };
                for _ in 0..boxes {
                    self.double("an entity's coordinates or bounding box")?;
                }
                let np = self.size("the number of physical tags of an entity")?;
                let np = self.count(np, "number of physical tags")?;
                let mut phys = Vec::new();
                for _ in 0..np {
                    phys.push(self.int("a physical tag")?);
                }
                if dim > 0 {
                    let nb = self.size("the number of bounding entities")?;
                    let nb = self.count(nb, "number of bounding entities")?;
                    for _ in 0..nb {
                        self.int("a bounding entity tag")?;
                    }
                }
                st.entity_physicals.insert((dim as u8, tag), phys);
            }
        }
        Ok(())
    }

    pub(super) fn nodes41(&mut self, st: &mut State) -> Result<(), MshError> {
        let blocks = self.size("the number of node blocks")?;
        let blocks = self.count(blocks, "number of node blocks")?;
        let total = self.size("the number of nodes")?;
        let total_at = self.at;
        let total = self.count(total, "number of nodes")?;
        self.size("the smallest node tag")?;
        self.size("the largest node tag")?;
        let cap = self.capacity(total, 32, 4);
        st.nodes.reserve(cap);
        st.node_tags.reserve(cap);
        st.node_z.reserve(cap);
        let mut tags = Vec::new();
        for _ in 0..blocks {
            let dim = self.int_in(0, 3, "the dimension of a node block")?;
            self.int("the entity of a node block")?;
            let parametric = self.int_in(0, 1, "the parametric flag of a node block")?;
            let n = self.size("the number of nodes of a block")?;
            let n = self.count(n, "number of nodes of a block")?;
            tags.clear();
            for _ in 0..n {
                let tag = self.size("a node tag")?;
                tags.push((tag, self.at));
            }
            let extra = if parametric == 1 { dim as usize } else { 0 };
            for &(tag, tag_at) in &tags {
                let mut xyz = [0.0; 3];
                for (k, c) in xyz.iter_mut().enumerate() {
                    *c = self.double(["x of a node", "y of a node", "z of a node"][k])?;
                }
                let at = if self.binary { tag_at } else { self.at };
                for _ in 0..extra {
                    self.double("a parametric coordinate of a node")?;
                }
                st.add_node(tag, xyz, at, self)?;
            }
        }
        if st.nodes.len() != total {
            return Err(self.err_at(
                total_at,
                format!("$Nodes announces {total} nodes, its blocks hold {}", st.nodes.len()),
            ));
        }
        Ok(())
    }

    pub(super) fn nodes22(&mut self, st: &mut State) -> Result<(), MshError> {
        // The count is ASCII in binary files too, binary data starts on the next line.
        let n: u64 = self.parse_tok("the number of nodes")?;
        let n = self.count(n, "number of nodes")?;
        if self.binary {
            self.end_of_line();
        }
        let cap = self.capacity(n, 28, 4);
        st.nodes.reserve(cap);
        st.node_tags.reserve(cap);
        st.node_z.reserve(cap);
        for _ in 0..n {
            let tag = self.tag22("a node tag")?;
            let at = self.at;
            let mut xyz = [0.0; 3];
            for (k, c) in xyz.iter_mut().enumerate() {
                *c = self.double(["x of a node", "y of a node", "z of a node"][k])?;
            }
            st.add_node(tag, xyz, at, self)?;
        }
        Ok(())
    }

    /// A node or element tag of MSH 2.2: an `int` (binary) that must be positive.
    fn tag22(&mut self, what: &str) -> Result<u64, MshError> {
        if self.binary {
            let v = self.int(what)?;
            u64::try_from(v).map_err(|_| self.err(format!("{what} {v}: expected a positive number")))
        } else {
            self.parse_tok(what)
        }
    }

    fn element_type(&mut self, what: &str) -> Result<(u32, usize, u8), MshError> {
        let kind = self.int(what)?;
        let Some((n, dim)) = u32::try_from(kind).ok().and_then(type_nodes) else {
            return Err(self.err(format!(
                "element type {kind}: not a Gmsh element type with a fixed number of nodes"
            )));
        };
        Ok((kind as u32, n, dim))
    }

    pub(super) fn elements41(&mut self, st: &mut State) -> Result<(), MshError> {
        let blocks = self.size("the number of element blocks")?;
        let blocks = self.count(blocks, "number of element blocks")?;
        let total = self.size("the number of elements")?;
        let total_at = self.at;
        let total = self.count(total, "number of elements")?;
        self.size("the smallest element tag")?;
        self.size("the largest element tag")?;
        st.elements.reserve(self.capacity(total, 16, 2));
        let mut read = 0usize;
        for _ in 0..blocks {
            let entity_dim = self.int_in(0, 3, "the dimension of an element block")?;
            let entity = self.int("the entity of an element block")?;
            let (kind, n_nodes, dim) = self.element_type("the element type of a block")?;
            if i32::from(dim) != entity_dim {
                return Err(self.err(format!(
                    "element type {kind} ({}, dimension {dim}) in a block of dimension {entity_dim}",
                    type_name(kind)
                )));
            }
            let n = self.size("the number of elements of a block")?;
            let n = self.count(n, "number of elements of a block")?;
            let physicals = st.entity_physicals.get(&(dim, entity)).cloned().unwrap_or_default();
            for _ in 0..n {
                let tag = self.size("an element tag")?;
                let mut nodes = Vec::with_capacity(n_nodes);
                for _ in 0..n_nodes {
                    let t = self.size("a node of an element")?;
                    nodes.push(st.node(tag, t, self.at, self)?);
                }
                st.elements.push(MshElement {
                    tag,
                    kind,
                    nodes,
                    dim,
                    entity,
                    physicals: physicals.clone(),
                });
            }
            read += n;
        }
        if read != total {
            return Err(self.err_at(
                total_at,
                format!("$Elements announces {total} elements, its blocks hold {read}"),
            ));
        }
        Ok(())
    }

    pub(super) fn elements22(&mut self, st: &mut State) -> Result<(), MshError> {
        let total: u64 = self.parse_tok("the number of elements")?;
        let total = self.count(total, "number of elements")?;
        if self.binary {
            self.end_of_line();
        }
        // Gmsh 2.2 writes an element once per physical group: copies (same type, entity and
        // nodes) are merged into the first.
        let mut seen: HashMap<(u32, i32, Vec<usize>), usize> = HashMap::new();
        if self.binary {
            let mut read = 0;
            while read < total {
                let (kind, n_nodes, dim) = self.element_type("the element type of a block")?;
                let n = self.int_in(1, i32::MAX, "the number of elements of a block")? as usize;
                let ntags = self.int_in(0, 1 << 16, "the number of tags of a block")? as usize;
                if n > total - read {
                    return Err(self.err(format!(
                        "a block of {n} elements where only {} are left of the {total} announced",
                        total - read
                    )));
                }
                for _ in 0..n {
                    let tag = self.tag22("an element tag")?;
                    self.element22(st, &mut seen, tag, (kind, n_nodes, dim), ntags)?;
                }
                read += n;
            }
        } else {
            for _ in 0..total {
                let tag = self.tag22("an element tag")?;
                let kind = self.element_type("an element type")?;
                let ntags = self.int_in(0, 1 << 16, "the number of tags of an element")? as usize;
                self.element22(st, &mut seen, tag, kind, ntags)?;
            }
        }
        Ok(())
    }

    /// The rest of an MSH 2.2 element record after its tag (and, in ASCII, its type and number of
    /// tags): the tags (physical, entity, partitions), then the nodes. A copy of an element
    /// already read (same type, entity and nodes) adds its physical tag to the first.
    fn element22(
        &mut self,
        st: &mut State,
        seen: &mut HashMap<(u32, i32, Vec<usize>), usize>,
        tag: u64,
        (kind, n_nodes, dim): (u32, usize, u8),
        ntags: usize,
    ) -> Result<(), MshError> {
        let mut tags = Vec::with_capacity(ntags.min(16));
        for _ in 0..ntags {
            tags.push(self.int("an element's tag (physical, entity, partitions)")?);
        }
        let physical = tags.first().copied().unwrap_or(0);
        let entity = tags.get(1).copied().unwrap_or(0);
        let mut nodes = Vec::with_capacity(n_nodes);
        for _ in 0..n_nodes {
            let t = self.tag22("a node of an element")?;
            nodes.push(st.node(tag, t, self.at, self)?);
        }
        let key = (kind, entity, nodes);
        if let Some(&i) = seen.get(&key) {
            let e = &mut st.elements[i];
            if physical != 0 && !e.physicals.contains(&physical) {
                e.physicals.push(physical);
            }
        } else {
            seen.insert(key.clone(), st.elements.len());
            st.elements.push(MshElement {
                tag,
                kind,
                nodes: key.2,
                dim,
                entity,
                physicals: if physical != 0 { vec![physical] } else { Vec::new() },
            });
        }
        Ok(())
    }
}
