//! The mechanics crate reads no scene format: its unit tests take their models from JSON fixtures
//! in `nodes/mechanics/tests/fixtures/`. This test keeps each fixture equal to what its scene
//! builds today, so that a change of the builder cannot leave the numerics tests on a stale model.
//! `GLISSADE_BLESS=1 cargo test -p glissade-scene --test model_fixtures` rewrites them.

use glissade_mechanics::model::Model;
use std::path::PathBuf;

/// (scene, relative to the repository root; its fixture in `nodes/mechanics/tests/fixtures/`).
const FIXTURES: [(&str, &str); 2] = [
    ("launch/scenes/small-three-layer.toml", "small-three-layer.model.json"),
    (
        "nodes/mechanics/tests/fixtures/two-blocks-contact.toml",
        "two-blocks-contact.model.json",
    ),
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn model_fixtures_are_what_the_scenes_build() {
    let bless = std::env::var("GLISSADE_BLESS").is_ok_and(|v| v == "1");
    for (scene, fixture) in FIXTURES {
        let text = std::fs::read_to_string(root().join(scene)).expect("the fixture's scene");
        let model = match glissade_scene::load_str(&text, scene) {
            Ok(sc) => sc.model,
            Err(e) => panic!("{e}"),
        };
        let json = serde_json::to_string(&model).expect("a model serialises") + "\n";
        // JSON keeps every f64 exactly (shortest round-trip digits): the model read back is the
        // model built, bit for bit.
        let back: Model = serde_json::from_str(&json).expect("the fixture reads back");
        assert_eq!(
            serde_json::to_string(&back).expect("serialises") + "\n",
            json,
            "{scene}"
        );
        let path = root().join("nodes/mechanics/tests/fixtures").join(fixture);
        if bless {
            std::fs::write(&path, &json).expect("fixture written");
            continue;
        }
        let kept = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            kept == json,
            "{} is not what {scene} builds today: rerun with GLISSADE_BLESS=1 and review the diff",
            path.display()
        );
    }
}
