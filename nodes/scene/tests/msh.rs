//! The Gmsh reader on files written by Gmsh itself, compared with Gmsh's own account of them.
//!
//! `tests/fixtures/msh/` holds one small QUA8 mesh in the four formats Gmsh writes (MSH 4.1 and
//! 2.2, ASCII and binary; and MSH 4.1 with parametric coordinates) with what Gmsh's API says of it (`two-parts.json`), the node count and
//! dimension of every element type Gmsh knows (`element-types.json`), and Gmsh's account of each
//! shipped mesh of `launch/scenes/meshes/` (`<mesh>.json`). All were written by the scripts of
//! `launch/scenes/meshes/`: these tests need no Gmsh.
//!
//! By topic: `account` reads the fixtures in every format and compares them with Gmsh's account;
//! `malformed` refuses broken files at their line or byte offset; `scene_meshes` reads and checks
//! the shipped meshes of `launch/scenes/meshes/`. The helpers they share are here.

#[path = "msh/account.rs"]
mod account;
#[path = "msh/malformed.rs"]
mod malformed;
#[path = "msh/scene_meshes.rs"]
mod scene_meshes;

use glissade_scene::msh::{self, Msh};
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn fixture(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/msh")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn json(name: &str) -> Value {
    serde_json::from_slice(&fixture(name)).expect("a fixture's JSON")
}

fn read(bytes: &[u8], what: &str) -> Msh {
    msh::parse(bytes).unwrap_or_else(|e| panic!("{what}: {e}"))
}

/// The four formats, then MSH 4.1 with the nodes' parametric coordinates (ASCII, binary).
const FORMATS: [&str; 6] = [
    "two-parts-4.1.msh",
    "two-parts-4.1-binary.msh",
    "two-parts-2.2.msh",
    "two-parts-2.2-binary.msh",
    "two-parts-4.1-parametric.msh",
    "two-parts-4.1-parametric-binary.msh",
];

/// An element as a comparable value, by node tags: (kind, node tags, dim, entity, physicals sorted).
type ElementKey = (u32, Vec<u64>, u8, i32, Vec<i32>);

fn element_keys(m: &Msh) -> BTreeSet<ElementKey> {
    m.elements
        .iter()
        .map(|e| {
            let mut p = e.physicals.clone();
            p.sort_unstable();
            let tags = e.nodes.iter().map(|&i| m.node_tags[i]).collect();
            (e.kind, tags, e.dim, e.entity, p)
        })
        .collect()
}

fn as_u64(v: &Value) -> u64 {
    v.as_u64().expect("an unsigned integer")
}

/// The text of a section of an ASCII file, between its header and end lines.
fn section<'a>(text: &'a str, name: &str) -> &'a str {
    let start = text.find(&format!("${name}\n")).expect("the section") + name.len() + 2;
    let end = text.find(&format!("$End{name}")).expect("its end");
    &text[start..end]
}
