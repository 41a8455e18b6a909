//! A reader of the mesh files Gmsh writes: MSH 4.1 and MSH 2.2, ASCII and binary.
//!
//! [`parse`] returns the nodes (x, y) in file order, the elements of every type with their nodes
//! as indices into the node list, and the physical groups with their names. The physical
//! membership of an element comes from its geometric entity (`$Entities`) in MSH 4.1 and from its
//! own tags in MSH 2.2, where Gmsh writes an element once per physical group it belongs to: such
//! copies are merged, so each element appears once with all its physical tags.
//!
//! Binary files are read as Gmsh writes them on x86: little-endian, `size_t` of 8 bytes, `int` of
//! 4 bytes; anything else is refused. Partitioned MSH 4.1 files are refused. Sections other than
//! `$MeshFormat`, `$PhysicalNames`, `$Entities`, `$Nodes` and `$Elements` are skipped up to their
//! `$End…` line. The mesh must lie in the plane z = 0.
//!
//! Every problem is an [`MshError`] located by its line (ASCII files) or its byte offset (binary
//! files).

use std::collections::{BTreeMap, HashMap};

/// A mesh as read from a Gmsh file: nodes in file order, elements of every type, physical groups.
#[derive(Debug, Clone, PartialEq)]
pub struct Msh {
    /// Node coordinates (x, y); index = position in this vector.
    pub nodes: Vec<[f64; 2]>,
    /// Gmsh's tag of each node (for messages).
    pub node_tags: Vec<u64>,
    pub elements: Vec<MshElement>,
    /// Physical groups: (dimension, tag) -> name ("" if the file gives no $PhysicalNames entry).
    pub physical_names: BTreeMap<(u8, i32), String>,
}

/// One element of a [`Msh`].
#[derive(Debug, Clone, PartialEq)]
pub struct MshElement {
    pub tag: u64,
    /// Gmsh element type (16 = 8-node quadrangle, 8 = 3-node line, 1 = 2-node line, 15 = point, ...).
    pub kind: u32,
    /// Node indices into `Msh::nodes` in Gmsh's node order.
    pub nodes: Vec<usize>,
    /// Dimension of the element (from its type).
    pub dim: u8,
    /// Tag of the geometric entity it belongs to.
    pub entity: i32,
    /// Physical tags (of dimension `dim`) it belongs to; empty if none.
    pub physicals: Vec<i32>,
}

/// A problem of a mesh file, with its place: `line N` (ASCII) or `byte offset N` (binary).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{problem} ({location})")]
pub struct MshError {
    pub problem: String,
    pub location: String,
}

/// Largest |z| accepted, relative to the size of the mesh (its bounding box diagonal in x, y).
const PLANAR_TOLERANCE: f64 = 1e-9;

/// Gmsh's element types with a fixed number of nodes: (type, nodes, dimension, order, shape), as
/// `gmsh.model.mesh.getElementProperties` gives them (Gmsh 4.15; the tests compare this table with
/// its account in `tests/fixtures/msh/element-types.json`).
const TYPES: &[(u32, usize, u8, u8, &str)] = &[
    (1, 2, 1, 1, "line"),
    (2, 3, 2, 1, "triangle"),
    (3, 4, 2, 1, "quadrangle"),
    (4, 4, 3, 1, "tetrahedron"),
    (5, 8, 3, 1, "hexahedron"),
    (6, 6, 3, 1, "prism"),
    (7, 5, 3, 1, "pyramid"),
    (8, 3, 1, 2, "line"),
    (9, 6, 2, 2, "triangle"),
    (10, 9, 2, 2, "quadrangle"),
    (11, 10, 3, 2, "tetrahedron"),
    (12, 27, 3, 2, "hexahedron"),
    (13, 18, 3, 2, "prism"),
    (14, 14, 3, 2, "pyramid"),
    (15, 1, 0, 0, "point"),
    (16, 8, 2, 2, "quadrangle"),
    (17, 20, 3, 2, "hexahedron"),
    (18, 15, 3, 2, "prism"),
    (19, 13, 3, 2, "pyramid"),
    (20, 9, 2, 3, "triangle"),
    (21, 10, 2, 3, "triangle"),
    (22, 12, 2, 4, "triangle"),
    (23, 15, 2, 4, "triangle"),
    (24, 15, 2, 5, "triangle"),
    (25, 21, 2, 5, "triangle"),
    (26, 4, 1, 3, "line"),
    (27, 5, 1, 4, "line"),
    (28, 6, 1, 5, "line"),
    (29, 20, 3, 3, "tetrahedron"),
    (30, 35, 3, 4, "tetrahedron"),
    (31, 56, 3, 5, "tetrahedron"),
    (32, 22, 3, 4, "tetrahedron"),
    (33, 28, 3, 5, "tetrahedron"),
    (36, 16, 2, 3, "quadrangle"),
    (37, 25, 2, 4, "quadrangle"),
    (38, 36, 2, 5, "quadrangle"),
    (39, 12, 2, 3, "quadrangle"),
    (40, 16, 2, 4, "quadrangle"),
    (41, 20, 2, 5, "quadrangle"),
    (42, 28, 2, 6, "triangle"),
    (43, 36, 2, 7, "triangle"),
    (44, 45, 2, 8, "triangle"),
    (45, 55, 2, 9, "triangle"),
    (46, 66, 2, 10, "triangle"),
    (47, 49, 2, 6, "quadrangle"),
    (48, 64, 2, 7, "quadrangle"),
    (49, 81, 2, 8, "quadrangle"),
    (50, 100, 2, 9, "quadrangle"),
    (51, 121, 2, 10, "quadrangle"),
    (52, 18, 2, 6, "triangle"),
    (53, 21, 2, 7, "triangle"),
    (54, 24, 2, 8, "triangle"),
    (55, 27, 2, 9, "triangle"),
    (56, 30, 2, 10, "triangle"),
    (57, 24, 2, 6, "quadrangle"),
    (58, 28, 2, 7, "quadrangle"),
    (59, 32, 2, 8, "quadrangle"),
    (60, 36, 2, 9, "quadrangle"),
    (61, 40, 2, 10, "quadrangle"),
    (62, 7, 1, 6, "line"),
    (63, 8, 1, 7, "line"),
    (64, 9, 1, 8, "line"),
    (65, 10, 1, 9, "line"),
    (66, 11, 1, 10, "line"),
    (71, 84, 3, 6, "tetrahedron"),
    (72, 120, 3, 7, "tetrahedron"),
    (73, 165, 3, 8, "tetrahedron"),
    (74, 220, 3, 9, "tetrahedron"),
    (75, 286, 3, 10, "tetrahedron"),
    (79, 34, 3, 6, "tetrahedron"),
    (80, 40, 3, 7, "tetrahedron"),
    (81, 46, 3, 8, "tetrahedron"),
    (82, 52, 3, 9, "tetrahedron"),
    (83, 58, 3, 10, "tetrahedron"),
    (84, 1, 1, 0, "line"),
    (85, 1, 2, 0, "triangle"),
    (86, 1, 2, 0, "quadrangle"),
    (87, 1, 3, 0, "tetrahedron"),
    (88, 1, 3, 0, "hexahedron"),
    (89, 1, 3, 0, "prism"),
    (92, 64, 3, 3, "hexahedron"),
    (93, 125, 3, 4, "hexahedron"),
    (94, 216, 3, 5, "hexahedron"),
    (95, 343, 3, 6, "hexahedron"),
    (96, 512, 3, 7, "hexahedron"),
    (97, 729, 3, 8, "hexahedron"),
    (98, 1000, 3, 9, "hexahedron"),
    (99, 32, 3, 3, "hexahedron"),
    (100, 44, 3, 4, "hexahedron"),
    (101, 56, 3, 5, "hexahedron"),
    (102, 68, 3, 6, "hexahedron"),
    (103, 80, 3, 7, "hexahedron"),
    (104, 92, 3, 8, "hexahedron"),
    (105, 104, 3, 9, "hexahedron"),
    (118, 30, 3, 3, "pyramid"),
    (119, 55, 3, 4, "pyramid"),
    (120, 91, 3, 5, "pyramid"),
    (121, 140, 3, 6, "pyramid"),
    (122, 204, 3, 7, "pyramid"),
    (123, 285, 3, 8, "pyramid"),
    (124, 385, 3, 9, "pyramid"),
    (125, 21, 3, 3, "pyramid"),
    (126, 29, 3, 4, "pyramid"),
    (127, 37, 3, 5, "pyramid"),
    (128, 45, 3, 6, "pyramid"),
    (129, 53, 3, 7, "pyramid"),
    (130, 61, 3, 8, "pyramid"),
    (131, 69, 3, 9, "pyramid"),
    (132, 1, 3, 0, "pyramid"),
    (137, 16, 3, 3, "tetrahedron"),
];

fn type_entry(kind: u32) -> Option<&'static (u32, usize, u8, u8, &'static str)> {
    TYPES.iter().find(|t| t.0 == kind)
}

/// Gmsh's name of an element type ("8-node quadrangle", "6-node triangle", ...), for refusals.
/// Where two types share a node count and a shape, their order tells them apart
/// ("15-node triangle of order 4").
pub fn type_name(kind: u32) -> String {
    let Some(&(_, n, _, order, shape)) = type_entry(kind) else {
        return format!("unknown element type {kind}");
    };
    let shared = TYPES.iter().filter(|t| t.1 == n && t.4 == shape).count() > 1;
    if shared {
        format!("{n}-node {shape} of order {order}")
    } else {
        format!("{n}-node {shape}")
    }
}

/// Number of nodes of an element type (None if unknown) and its dimension.
pub fn type_nodes(kind: u32) -> Option<(usize, u8)> {
    type_entry(kind).map(|&(_, n, dim, _, _)| (n, dim))
}

/// Reads a Gmsh mesh file (MSH 4.1 or 2.2, ASCII or binary) from its bytes.
pub fn parse(bytes: &[u8]) -> Result<Msh, MshError> {
    let mut p = Parser {
        b: bytes,
        pos: 0,
        at: 0,
        binary: false,
    };
    let mut st = State::default();
    let version = p.mesh_format()?;
    loop {
        p.skip_ws();
        if p.pos >= p.b.len() {
            break;
        }
        let tok = p.token("a section")?;
        let Some(name) = tok.strip_prefix('$') else {
            return Err(p.err(format!("expected a section ($Name), found '{}'", clip(tok))));
        };
        if name.is_empty() {
            if p.pos >= p.b.len() {
                return Err(p.eof("a section name"));
            }
            return Err(p.err("'$' without a section name".into()));
        }
        let name = name.to_string();
        p.end_of_line();
        match (name.as_str(), version) {
            ("MeshFormat", _) => return Err(p.err("a second $MeshFormat section".into())),
            ("PhysicalNames", _) => p.physical_names(&mut st)?,
            ("Entities", Version::V41) => p.entities(&mut st)?,
            ("PartitionedEntities", Version::V41) => {
                return Err(p.err(
                    "a partitioned mesh ($PartitionedEntities): not read; save the mesh without partitions".into(),
                ))
            }
            ("Nodes", v) => {
                if st.nodes_read {
                    return Err(p.err("a second $Nodes section".into()));
                }
                match v {
                    Version::V41 => p.nodes41(&mut st)?,
                    Version::V22 => p.nodes22(&mut st)?,
                }
                st.finish_nodes(&p)?;
            }
            ("Elements", v) => {
                if !st.nodes_read {
                    return Err(p.err("$Elements before $Nodes".into()));
                }
                if st.elements_read {
                    return Err(p.err("a second $Elements section".into()));
                }
                match v {
                    Version::V41 => p.elements41(&mut st)?,
                    Version::V22 => p.elements22(&mut st)?,
                }
                st.elements_read = true;
            }
            _ => {
                p.skip_section(&name)?;
                continue;
            }
        }
        p.expect_end(&name)?;
    }
    if !st.nodes_read {
        return Err(p.eof("a $Nodes section"));
    }
    if !st.elements_read {
        return Err(p.eof("an $Elements section"));
    }
    // Every physical group, named or not: those of the entities (MSH 4.1) and of the elements.
    let mut physical_names = st.names;
    for (&(dim, _), tags) in &st.entity_physicals {
        for &t in tags {
            physical_names.entry((dim, t)).or_default();
        }
    }
    for e in &st.elements {
        for &t in &e.physicals {
            physical_names.entry((e.dim, t)).or_default();
        }
    }
    Ok(Msh {
        nodes: st.nodes,
        node_tags: st.node_tags,
        elements: st.elements,
        physical_names,
    })
}

#[derive(Clone, Copy, PartialEq)]
enum Version {
    V41,
    V22,
}

/// What the sections read so far have given.
#[derive(Default)]
struct State {
    nodes: Vec<[f64; 2]>,
    node_tags: Vec<u64>,
    /// z of each node and where it was read, for the check of planarity once all are known.
    node_z: Vec<(f64, usize)>,
    index: NodeIndex,
    nodes_read: bool,
    elements: Vec<MshElement>,
    elements_read: bool,
    names: BTreeMap<(u8, i32), String>,
    /// MSH 4.1: physical tags of each geometric entity (dimension, tag).
    entity_physicals: HashMap<(u8, i32), Vec<i32>>,
}

/// Node tag -> index into the node list: a dense vector when the tags are dense (as Gmsh writes
/// them), else a hash map.
#[derive(Default)]
enum NodeIndex {
    #[default]
    Empty,
    Dense(Vec<usize>),
    Sparse(HashMap<u64, usize>),
}

impl NodeIndex {
    fn get(&self, tag: u64) -> Option<usize> {
        match self {
            NodeIndex::Empty => None,
            NodeIndex::Dense(v) => usize::try_from(tag)
                .ok()
                .and_then(|t| v.get(t))
                .copied()
                .filter(|&i| i != usize::MAX),
            NodeIndex::Sparse(m) => m.get(&tag).copied(),
        }
    }
}

impl State {
    fn add_node(&mut self, tag: u64, xyz: [f64; 3], at: usize, p: &Parser) -> Result<(), MshError> {
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(p.err_at(at, format!("node {tag}: a coordinate is not finite")));
        }
        self.nodes.push([xyz[0], xyz[1]]);
        self.node_tags.push(tag);
        self.node_z.push((xyz[2], at));
        Ok(())
    }

    /// Builds the tag index (refusing a tag given twice) and checks that the mesh is planar.
    fn finish_nodes(&mut self, p: &Parser) -> Result<(), MshError> {
        let n = self.node_tags.len();
        let max = self.node_tags.iter().copied().max().unwrap_or(0);
        let duplicate = |tag: u64, i: usize| p.err_at(self.node_z[i].1, format!("node tag {tag} given twice"));
        if max <= 2 * n as u64 + 1024 {
            let mut v = vec![usize::MAX; max as usize + 1];
            for (i, &t) in self.node_tags.iter().enumerate() {
                if v[t as usize] != usize::MAX {
                    return Err(duplicate(t, i));
                }
                v[t as usize] = i;
            }
            self.index = NodeIndex::Dense(v);
        } else {
            let mut m = HashMap::with_capacity(n);
            for (i, &t) in self.node_tags.iter().enumerate() {
                if m.insert(t, i).is_some() {
                    return Err(duplicate(t, i));
                }
            }
            self.index = NodeIndex::Sparse(m);
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for x in &self.nodes {
            for k in 0..2 {
                lo[k] = lo[k].min(x[k]);
                hi[k] = hi[k].max(x[k]);
            }
        }
        let size = if n == 0 {
            0.0
        } else {
            (hi[0] - lo[0]).hypot(hi[1] - lo[1])
        };
        for (i, &(z, at)) in self.node_z.iter().enumerate() {
            if z.abs() > PLANAR_TOLERANCE * size {
                return Err(p.err_at(
                    at,
                    format!(
                        "node {} has z = {z}: the mesh must lie in the plane z = 0 (|z| at most {PLANAR_TOLERANCE:e} × \
                         the mesh size {size})",
                        self.node_tags[i]
                    ),
                ));
            }
        }
        self.node_z = Vec::new();
        self.nodes_read = true;
        Ok(())
    }

    fn node(&self, element: u64, tag: u64, at: usize, p: &Parser) -> Result<usize, MshError> {
        self.index.get(tag).ok_or_else(|| {
            p.err_at(
                at,
                format!("element {element} refers to node {tag}, which is not in $Nodes"),
            )
        })
    }
}

fn clip(s: &str) -> String {
    if s.chars().count() > 40 {
        format!("{}…", s.chars().take(40).collect::<String>())
    } else {
        s.to_string()
    }
}

struct Parser<'a> {
    b: &'a [u8],
    pos: usize,
    /// Start of the token or value read last: where an error is located.
    at: usize,
    binary: bool,
}

impl<'a> Parser<'a> {
    fn err(&self, problem: String) -> MshError {
        self.err_at(self.at, problem)
    }

    fn err_at(&self, at: usize, problem: String) -> MshError {
        let at = at.min(self.b.len());
        let location = if self.binary {
            format!("byte offset {at}")
        } else {
            format!("line {}", 1 + self.b[..at].iter().filter(|&&c| c == b'\n').count())
        };
        MshError { problem, location }
    }

    fn eof(&mut self, what: &str) -> MshError {
        self.at = self.b.len();
        self.err(format!("unexpected end of file: {what} expected"))
    }

    fn skip_ws(&mut self) {
        while self.pos < self.b.len() && self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    /// The next whitespace-delimited word (ASCII text).
    fn token(&mut self, what: &str) -> Result<&'a str, MshError> {
        self.skip_ws();
        if self.pos >= self.b.len() {
            return Err(self.eof(what));
        }
        self.at = self.pos;
        let start = self.pos;
        while self.pos < self.b.len() && !self.b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        // Gmsh ends every line with a newline: a word cut by the end of the file is a truncated
        // file (but a final `$End…` without its newline is accepted).
        if self.pos == self.b.len() && !self.b[start..].starts_with(b"$End") {
            return Err(self.eof(what));
        }
        std::str::from_utf8(&self.b[start..self.pos])
            .map_err(|_| self.err(format!("{what} expected, found bytes that are not text")))
    }

    /// Consumes the rest of the current line, its newline included (binary data starts after it).
    fn end_of_line(&mut self) -> &'a str {
        let start = self.pos;
        while self.pos < self.b.len() && self.b[self.pos] != b'\n' {
            self.pos += 1;
        }
        let line = &self.b[start..self.pos];
        if self.pos < self.b.len() {
            self.pos += 1;
        }
        std::str::from_utf8(line).unwrap_or("")
    }

    fn parse_tok<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, MshError> {
        let tok = self.token(what)?;
        tok.parse()
            .map_err(|_| self.err(format!("bad number '{}' ({what} expected)", clip(tok))))
    }

    fn raw<const N: usize>(&mut self, what: &str) -> Result<[u8; N], MshError> {
        self.at = self.pos;
        match self.b.get(self.pos..self.pos + N) {
            Some(s) => {
                self.pos += N;
                Ok(s.try_into().expect("N bytes"))
            }
            None => Err(self.eof(what)),
        }
    }

    /// An `int` of the format: a 4-byte integer in binary files, a word in ASCII ones.
    fn int(&mut self, what: &str) -> Result<i32, MshError> {
        if self.binary {
            Ok(i32::from_le_bytes(self.raw(what)?))
        } else {
            self.parse_tok(what)
        }
    }

    /// A `size_t` of the format: an 8-byte unsigned integer in binary files, a word in ASCII ones.
    fn size(&mut self, what: &str) -> Result<u64, MshError> {
        if self.binary {
            Ok(u64::from_le_bytes(self.raw(what)?))
        } else {
            self.parse_tok(what)
        }
    }

    fn double(&mut self, what: &str) -> Result<f64, MshError> {
        if self.binary {
            Ok(f64::from_le_bytes(self.raw(what)?))
        } else {
            self.parse_tok(what)
        }
    }

    /// A count read from the file, as a `usize`.
    fn count(&self, value: u64, what: &str) -> Result<usize, MshError> {
        usize::try_from(value).map_err(|_| self.err(format!("{what} {value}: too large")))
    }

    /// How many of `n` items to reserve room for: no more than the rest of the file can hold (at
    /// least `binary_bytes` per item in binary files, `words` words of two bytes in ASCII ones),
    /// so that a corrupt count cannot ask for a huge allocation.
    fn capacity(&self, n: usize, binary_bytes: usize, words: usize) -> usize {
        let min = if self.binary { binary_bytes } else { 2 * words };
        n.min((self.b.len() - self.pos) / min.max(1))
    }

    /// A tag of an entity, element type or flag: an `int` that must be within `lo..=hi`.
    fn int_in(&mut self, lo: i32, hi: i32, what: &str) -> Result<i32, MshError> {
        let v = self.int(what)?;
        if v < lo || v > hi {
            return Err(self.err(format!("{what} {v}: expected {lo} to {hi}")));
        }
        Ok(v)
    }

    fn mesh_format(&mut self) -> Result<Version, MshError> {
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

    fn expect_end(&mut self, name: &str) -> Result<(), MshError> {
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
    fn skip_section(&mut self, name: &str) -> Result<(), MshError> {
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

    fn physical_names(&mut self, st: &mut State) -> Result<(), MshError> {
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

    fn skip_ws_in_line(&mut self) {
        while self.pos < self.b.len() && matches!(self.b[self.pos], b' ' | b'\t') {
            self.pos += 1;
        }
    }

    /// MSH 4.1 `$Entities`: the physical tags of every point, curve, surface and volume.
    fn entities(&mut self, st: &mut State) -> Result<(), MshError> {
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

    fn nodes41(&mut self, st: &mut State) -> Result<(), MshError> {
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

    fn nodes22(&mut self, st: &mut State) -> Result<(), MshError> {
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

    fn elements41(&mut self, st: &mut State) -> Result<(), MshError> {
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

    fn elements22(&mut self, st: &mut State) -> Result<(), MshError> {
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
