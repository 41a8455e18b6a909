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
//!
//! The reader is cut by concern: `parser` reads the words and binary values of a file and locates
//! its errors, `sections` reads each section into the `state` (nodes, their index, the
//! elements, the physical groups), and `types` is Gmsh's table of element types. The turning of
//! physical groups into parts is the scene builder's (`build/gmsh.rs`), not the reader's.

mod parser;
mod sections;
mod state;
mod types;

pub use types::{type_name, type_nodes};

use parser::{clip, Parser};
use state::State;
use std::collections::BTreeMap;

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
