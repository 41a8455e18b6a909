//! Helpers shared by the integration tests.

use glissade::runner::{run_in_process, RunOptions, RunResult};
use glissade_mechanics::scene::{load_str, LoadedScene};

/// The text of scene `launch/scenes/<name>.toml`.
pub fn scene_text(name: &str) -> String {
    std::fs::read_to_string(format!("{}/launch/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"))).expect("scene file")
}

pub fn scene(text: &str) -> LoadedScene {
    match load_str(text, "test.toml") {
        Ok(s) => s,
        Err(e) => panic!("test scene rejected: {e}"),
    }
}

pub fn run(scene: &LoadedScene) -> RunResult {
    run_in_process(
        scene,
        &RunOptions {
            run_id: "test".into(),
            interior: false,
        },
        |_| {},
    )
    .expect("run")
}

/// max |a − b| / max |b| over two lists.
pub fn rel_max(a: &[f64], b: &[f64]) -> f64 {
    let den = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / den
}
