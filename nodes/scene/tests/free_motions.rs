//! `glissade check`'s warning for parts held in some rigid motion by nothing but frictionless
//! contact (glissade_scene::free_motions).

use glissade_scene::{free_motions, load_str};

fn two_blocks(friction: &str) -> String {
    let text = include_str!("../../../launch/scenes/two-blocks.toml");
    // The upper block loses its own support: it is held by the contact only, pressed down by 10 MPa.
    let cut = text.find("[[boundary]]\ny = 40.0").expect("the upper block's rule");
    format!("{}[[boundary]]\ny = 40.0\np = 10.0\n", &text[..cut]).replace("friction = 0.2", friction)
}

/// A block pressed on a frictionless floor can slide along it: the warning names the block and
/// the x translation; with friction, or with its own support, there is none.
#[test]
fn a_block_on_a_frictionless_floor_is_free_to_slide() {
    let frictionless = load_str(&two_blocks("friction = 0.0"), "two-blocks.toml").unwrap();
    let w = free_motions(&frictionless.model);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with("part [upper] is held in a translation along ("),
        "{w:?}"
    );
    assert!(
        w[0].contains("(1.000, 0.000)") || w[0].contains("(-1.000, -0.000)") || w[0].contains("(-1.000, 0.000)"),
        "{w:?}"
    );
    assert!(w[0].contains("frictionless contact (interfaces [0])"), "{w:?}");
    let frictional = load_str(&two_blocks("friction = 0.2"), "two-blocks.toml").unwrap();
    assert!(free_motions(&frictional.model).is_empty());
    let supported = load_str(
        include_str!("../../../launch/scenes/two-blocks.toml"),
        "two-blocks.toml",
    )
    .unwrap();
    assert!(free_motions(&supported.model).is_empty());
}

/// The outer ring of a frictionless shrink fit may turn about the centre of the fit: radial
/// normals hold no rotation.
#[test]
fn a_frictionless_ring_is_free_to_turn() {
    let text = include_str!("../../../launch/scenes/shrink-fit.toml").replace("friction = 0.2", "friction = 0.0");
    // Named as the shipped scene, so that its mesh file is found beside it.
    let scene = load_str(
        &text,
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../launch/scenes/shrink-fit.toml"),
    )
    .unwrap();
    let w = free_motions(&scene.model);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].starts_with("part [outer] is held in a rotation about ("), "{w:?}");
    let centre: Vec<f64> = w[0]["part [outer] is held in a rotation about (".len()..]
        .split(')')
        .next()
        .unwrap()
        .split(", ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(centre[0].abs() < 1e-3 && centre[1].abs() < 1e-3, "{w:?}");
}
