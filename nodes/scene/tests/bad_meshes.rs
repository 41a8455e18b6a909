//! Meshes glissade refuses, written by Gmsh (`launch/scenes/meshes/bad-meshes.py` into the
//! repository's `tests/fixtures/msh-bad/`), loaded through the scene loader: each refusal names
//! the problem and where (element type and count with the Gmsh options for QUA8, the parts that
//! do not conform, the element of another piece, the duplicate nodes, the element in two physical
//! surfaces). The expected tags are read from the mesh files themselves.

use glissade_scene::msh::{self, Msh, MshElement};
use glissade_scene::SceneError;
use std::collections::BTreeSet;
use std::path::PathBuf;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/msh-bad")
}

fn mesh(name: &str) -> Msh {
    let path = dir().join(format!("{name}.msh"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    msh::parse(&bytes).unwrap_or_else(|e| panic!("{name}.msh: {e}"))
}

/// The scene of the brief on `<name>.msh` (`materials` of its parts), with `more` rules after its
/// two boundary rules.
fn scene_text(name: &str, materials: &str, more: &str) -> String {
    format!(
        r#"[time]
T = 1.0
N = 1

[materials.m]
E = 1000.0
nu = 0.3

[mesh]
file = "{name}.msh"
materials = {materials}

[[boundary]]
curve = "left"
ux = 0.0
uy = 0.0

[[boundary]]
curve = "right"
tx = 1.0
{more}"#
    )
}

/// Loads the scene of the brief on `<name>.msh` (materials for `a`, and `b` if `two`); the error.
fn refusal(name: &str, two: bool) -> SceneError {
    let materials = if two {
        r#"{ a = "m", b = "m" }"#
    } else {
        r#"{ a = "m" }"#
    };
    let text = scene_text(name, materials, "");
    let scene = dir().join("scene.toml");
    let scene = scene.to_str().expect("a UTF-8 path");
    match glissade_scene::load_str(&text, scene) {
        Ok(_) => panic!("{name}.msh: loaded"),
        Err(e) => {
            assert_eq!(e.key, "mesh.file", "{name}: {e}");
            assert!(e.problem.starts_with(&format!("{name}.msh: ")), "{name}: {e}");
            e
        }
    }
}

/// The numbers written after `word` in `text`, in order.
fn numbers_after(text: &str, word: &str) -> Vec<u64> {
    text.match_indices(word)
        .filter_map(|(i, _)| {
            let digits: String = text[i + word.len()..]
                .chars()
                .take_while(char::is_ascii_digit)
                .collect();
            digits.parse().ok()
        })
        .collect()
}

fn element(m: &Msh, tag: u64) -> &MshElement {
    m.elements
        .iter()
        .find(|e| e.tag == tag)
        .unwrap_or_else(|| panic!("no element {tag}"))
}

#[test]
fn other_element_types_are_refused_with_their_count_and_the_gmsh_options() {
    for (name, kind) in [("triangles", 9), ("mixed", 9), ("quad9", 10), ("linear", 3)] {
        let m = mesh(name);
        let bad: Vec<&MshElement> = m.elements.iter().filter(|e| e.kind == kind).collect();
        assert!(!bad.is_empty(), "{name}: the fixture has type {kind}");
        let e = refusal(name, false);
        let p = &e.problem;
        for want in [
            "8-node quadrilaterals (Gmsh type 16) only".to_string(),
            format!(
                "{} × {} (Gmsh type {kind}, e.g. element {})",
                bad.len(),
                msh::type_name(kind),
                bad[0].tag
            ),
            "Mesh.ElementOrder = 2".to_string(),
            "Mesh.SecondOrderIncomplete = 1".to_string(),
            "Mesh.RecombineAll = 1".to_string(),
        ] {
            assert!(p.contains(&want), "{name}: `{want}` in: {e}");
        }
    }
    assert_eq!(msh::type_name(9), "6-node triangle");
    assert_eq!(msh::type_name(10), "9-node quadrangle");
    assert_eq!(msh::type_name(3), "4-node quadrangle");
    // mixed.msh: QUA8 and triangles in one physical surface.
    let m = mesh("mixed");
    let kinds: BTreeSet<u32> = m.elements.iter().filter(|e| e.dim == 2).map(|e| e.kind).collect();
    assert_eq!(kinds, BTreeSet::from([9, 16]));
    assert!(m.elements.iter().filter(|e| e.dim == 2).all(|e| e.physicals == [1]));
}

/// nonconforming.msh (parts `a` and `b` meshed with 4 and 6 elements along their common side,
/// end points shared) is no longer refused: the parts meet on a non-matching interface whose
/// pairs are the coarser side's 9 nodes, each seeing the other side through its projection.
#[test]
fn parts_meshed_on_their_own_meet_on_a_non_matching_interface() {
    let text = scene_text("nonconforming", r#"{ a = "m", b = "m" }"#, "");
    let scene = dir().join("scene.toml");
    let model = glissade_scene::load_str(&text, scene.to_str().expect("a UTF-8 path"))
        .unwrap_or_else(|e| panic!("{e}"))
        .model;
    assert_eq!(model.interfaces.len(), 1);
    let itf = &model.interfaces[0];
    assert!(itf.is_non_matching());
    assert_eq!(itf.n_pairs(), 9);
    assert!((itf.length - 1.0).abs() < 1e-12, "{}", itf.length);
    // Every pair sits on x = 1, and side b's projection reproduces the coordinate y there.
    let xb = &model.subdomains[itf.b].mesh.coords;
    for p in 0..itf.n_pairs() {
        assert!((itf.coords[p][0] - 1.0).abs() < 1e-12);
        let y: f64 = itf
            .trace(glissade_mechanics::model::Side::B, p)
            .iter()
            .map(|&(n, c)| c * xb[n][1])
            .sum();
        assert!((y - itf.coords[p][1]).abs() < 1e-12, "pair {p}: {y}");
    }
}

#[test]
fn a_part_in_pieces_is_refused_with_an_element_of_each() {
    let m = mesh("pieces");
    let e = refusal("pieces", false);
    assert!(e.problem.contains("part `a` is in several pieces"), "{e}");
    let tags = numbers_after(&e.problem, "element ");
    assert_eq!(tags.len(), 2, "{e}");
    let (x, y) = (element(&m, tags[0]), element(&m, tags[1]));
    assert!(x.kind == 16 && y.kind == 16, "{e}");
    assert_ne!(x.entity, y.entity, "{e}: elements of the two rectangles");
}

#[test]
fn duplicate_nodes_are_refused_with_their_tags() {
    let m = mesh("duplicates");
    let e = refusal("duplicates", false);
    assert!(e.problem.contains("are duplicates"), "{e}");
    let a = numbers_after(&e.problem, "nodes ")[0];
    let b = numbers_after(&e.problem, " and ")[0];
    assert_ne!(a, b, "{e}");
    let at = |t: u64| m.nodes[m.node_tags.iter().position(|&n| n == t).expect("the node")];
    assert_eq!(at(a), at(b), "{e}");
    assert!((at(a)[0] - 1.0).abs() < 1e-12, "{e}: on the side the rectangles share");
}

#[test]
fn an_element_in_two_physical_surfaces_is_refused_with_its_tag() {
    let m = mesh("two-physicals");
    let twice = m
        .elements
        .iter()
        .find(|e| e.dim == 2 && e.physicals.len() == 2)
        .expect("the fixture's element in a and b");
    let e = refusal("two-physicals", true);
    assert!(
        e.problem.contains(&format!(
            "element {} belongs to several physical surfaces (`a`, `b`)",
            twice.tag
        )),
        "{e}"
    );
}

/// A boundary curve on an edge inside a part (shared by two of its elements) is refused, naming
/// the curve, its element and nodes (the file's tags) and the part: such a curve was accepted
/// where the rest of it lay on the part's boundary. Made by hand (README): a 2 × 1 rectangle `a`
/// of 2 QUA8 with the physical curve `load` along the right half of its top and then down the
/// edge x = 1 the two elements share.
#[test]
fn a_boundary_curve_inside_a_part_is_refused_with_its_element() {
    let m = mesh("interior-curve");
    // The element of `load` on x = 1 (the other is on the top edge).
    let line = m
        .elements
        .iter()
        .find(|e| e.dim == 1 && e.physicals == [5] && e.nodes.iter().all(|&n| m.nodes[n][0] == 1.0))
        .expect("the fixture's element of `load` inside `a`");
    let tags: Vec<u64> = line.nodes.iter().map(|&n| m.node_tags[n]).collect();
    let scene = dir().join("scene.toml");
    let scene = scene.to_str().expect("a UTF-8 path");
    let text = |more: &str| scene_text("interior-curve", r#"{ a = "m" }"#, more);
    // Without a rule on `load`, the mesh is a good one.
    glissade_scene::load_str(&text(""), scene).unwrap_or_else(|e| panic!("{e}"));
    for rule in ["ty = 1.0", "ux = 0.0"] {
        let e = match glissade_scene::load_str(&text(&format!("\n[[boundary]]\ncurve = \"load\"\n{rule}\n")), scene) {
            Ok(_) => panic!("a rule `{rule}` on a curve partly inside part `a` was accepted"),
            Err(e) => e,
        };
        assert_eq!(e.key, "boundary[2].curve", "{e}");
        assert_eq!(
            e.problem,
            format!(
                "boundary curve `load` element {} (nodes {}, {}, {}) lies on an edge shared by two elements of \
                 part `a`: a boundary curve must lie on a part's outer boundary",
                line.tag, tags[0], tags[1], tags[2]
            ),
            "{e}"
        );
    }
}

/// crossing.msh: `b` is taller than `a` and meshed on its own, so one of its edges along their
/// common side crosses a's corner: a non-matching interface would stop short of that edge, and
/// the scene is refused at the first edge found with a node inside the other part's edge (a's
/// top edge, whose corner (1, 1) lies inside b's edge). A `match_tolerance`
/// that is not a finite number > 0 is refused too.
#[test]
fn an_edge_crossing_the_end_of_a_shared_curve_is_refused() {
    let e = refusal("crossing", true);
    assert!(
        e.problem.contains("parts `a` and `b` do not conform near (1, 1)"),
        "{e}"
    );
    assert!(e.problem.contains("crosses the end of the curve they share"), "{e}");
    let scene = dir().join("scene.toml");
    let scene = scene.to_str().expect("a UTF-8 path");
    for bad in ["0.0", "-1e-3", "nan"] {
        let text = scene_text("nonconforming", r#"{ a = "m", b = "m" }"#, "")
            .replace("[mesh]\n", &format!("[mesh]\nmatch_tolerance = {bad}\n"));
        match glissade_scene::load_str(&text, scene) {
            Ok(_) => panic!("match_tolerance = {bad} accepted"),
            Err(e) => assert_eq!(e.key, "mesh.match_tolerance", "{e}"),
        }
    }
}
