//! Helpers shared by the integration tests.

use glissade::runner::{run_in_process, RunOptions, RunResult};
use glissade_scene::{load_str, LoadedScene};
use std::path::{Path, PathBuf};

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

/// A scratch folder, removed when dropped.
pub struct Scratch(PathBuf);

impl std::ops::Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A new, empty folder `glissade-<name>-<pid>` in the system's temporary folder, removed with
/// its contents when the returned value is dropped (also when a test fails).
pub fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("glissade-{name}-{}", std::process::id()));
    // A folder left by an earlier, killed run of the same process id starts empty.
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    Scratch(dir)
}
