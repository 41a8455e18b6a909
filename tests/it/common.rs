//! Helpers shared by the integration tests.

use glissade::run::Run;
use glissade::runner::{RunOptions, RunResult};
use glissade_scene::{load_str, LoadedScene};
use std::path::{Path, PathBuf};

/// The text of scene `launch/scenes/<name>.toml`.
pub fn scene_text(name: &str) -> String {
    std::fs::read_to_string(format!("{}/launch/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"))).expect("scene file")
}

/// A copy of scene `launch/scenes/<name>.toml` in `dir`, for the binary to run; its path.
pub fn scene_file(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, scene_text(name)).expect("scene copy");
    path
}

pub fn scene(text: &str) -> LoadedScene {
    match load_str(text, "test.toml") {
        Ok(s) => s,
        Err(e) => panic!("test scene rejected: {e}"),
    }
}

pub fn run(scene: &LoadedScene) -> RunResult {
    Run::new(scene, &RunOptions::new("test"))
        .in_process()
        .map(|o| o.result)
        .expect("run")
}

/// max |a − b| / max |b| over two lists.
pub fn rel_max(a: &[f64], b: &[f64]) -> f64 {
    let den = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / den
}

/// A scratch folder, removed when dropped.
pub struct Scratch(pub PathBuf);

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

/// A Python interpreter with `modules` importable, to check outputs with a foreign reader. None
/// (with the reason printed) when Python or a module is missing, unless `GLISSADE_REQUIRE_PYTHON`
/// is set (CI sets it after installing the modules), where a missing one fails the test.
pub fn python_with(modules: &[&str]) -> Option<&'static str> {
    let required = std::env::var_os("GLISSADE_REQUIRE_PYTHON").is_some();
    let skip = |why: String| {
        assert!(!required, "GLISSADE_REQUIRE_PYTHON is set but {why}");
        println!("skipped the Python reader: {why}");
        None
    };
    let python = ["python3", "python"].into_iter().find(|p| {
        std::process::Command::new(p)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    });
    let Some(python) = python else {
        return skip("no python3 on PATH".into());
    };
    for m in modules {
        let probe = std::process::Command::new(python)
            .args(["-c", &format!("import {m}")])
            .output()
            .expect("python runs");
        if !probe.status.success() {
            return skip(format!(
                "the `{m}` package is not installed (pip install -r .ci/python-requirements.txt): {}",
                String::from_utf8_lossy(&probe.stderr).trim()
            ));
        }
    }
    Some(python)
}

/// Runs the `glissade` binary with `args`, asserts that it succeeded (printing both streams if
/// not), and returns its standard output.
pub fn glissade_ok(args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "glissade {:?} failed: {stdout}{}",
        args.iter().map(|a| a.as_ref().to_string_lossy()).collect::<Vec<_>>(),
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Runs the `glissade` binary with `args`, asserts that it exits with `code` (printing both
/// streams if not), and returns its standard error.
pub fn glissade_exits(code: i32, args: &[&dyn AsRef<std::ffi::OsStr>]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(code),
        "glissade {:?}: {}{stderr}",
        args.iter().map(|a| a.as_ref().to_string_lossy()).collect::<Vec<_>>(),
        String::from_utf8_lossy(&out.stdout)
    );
    stderr
}

/// The one file in `dir` whose name ends with `suffix`.
pub fn output_file(dir: &Path, suffix: &str) -> PathBuf {
    let found: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(suffix))
        .collect();
    assert_eq!(found.len(), 1, "{suffix} in {}: {found:?}", dir.display());
    found.into_iter().next().unwrap()
}

/// The issue's rings on the sheath's mesh (three steel layers 10–13, 13–16 and 16–20 mm, each cut
/// into 8 sectors glued along their cuts; an interference of 0.01 mm at r = 13, none at r = 16;
/// f = 0.2; the bore clamped) twisted by a shear rising as `shear` on r = 20.
pub fn rings(shear: &str) -> LoadedScene {
    let path = format!("{}/launch/scenes/rings.toml", env!("CARGO_MANIFEST_DIR"));
    let text = format!(
        r#"
name = "rings"
plane = "strain"
[time]
T = 1.0
N = 4
[materials.steel]
E = 210000.0
nu = 0.3
[mesh]
file = "meshes/sheath.msh"
materials = {{ inner = "steel", middle = "steel", outer = "steel" }}
[[interface]]
curve = "inner-middle"
kind = "contact"
friction = 0.2
gap = -0.01
[[interface]]
curve = "middle-outer"
kind = "contact"
friction = 0.2
[[boundary]]
curve = "bore"
ux = 0.0
uy = 0.0
[[boundary]]
curve = "outside"
shear = "{shear}"
"#
    );
    load_str(&text, &path).expect("scene")
}
