//! The glissade launcher as a library: loads scenes, builds the nodes of a run and drives them on
//! a bus, and writes run outputs. The `glissade` binary only parses arguments and calls this.

pub mod accuracy;
pub mod bench;
/// Every boundary rule's force on the parts ([`glissade_studies::boundary`]).
pub use glissade_studies::boundary;
pub mod bus;
pub mod children;
pub mod console;
pub mod distributed;
pub mod error;
pub mod files;
pub mod generate;
pub mod node_process;
pub mod output;
pub mod recording;
pub mod report;
pub mod resultants;
pub mod run;
pub mod runner;
pub mod stability;
pub mod starter;
pub mod study;
pub mod validate;
pub mod vtu;

use error::IoWhat;
pub use error::{Error, Result};
use glissade_scene::{load_str, LoadedScene};
use std::path::Path;

/// This machine's memory in bytes (`MemTotal` of /proc/meminfo), if the system says.
pub fn machine_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let kb: u64 = info
        .lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))?
        .trim()
        .strip_suffix("kB")?
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// The builder of the process's compute threads (rayon's global pool): `RAYON_NUM_THREADS` or one
/// per core, named `compute-<i>`. Unnamed, each would take the name of the thread that first
/// used the pool (in the launcher, an interface node's thread: profiles and `top -H` then showed
/// every compute thread as that node).
pub fn compute_threads() -> rayon::ThreadPoolBuilder {
    rayon::ThreadPoolBuilder::new().thread_name(|i| format!("compute-{i}"))
}

/// Starts the process's compute threads ([`compute_threads`]); call it before anything uses rayon.
pub fn start_compute_threads() -> std::result::Result<(), rayon::ThreadPoolBuildError> {
    compute_threads().build_global()
}

/// Reads and validates a scene file; its TLS files (`network.tls`) become relative to its folder
/// and must be readable.
pub fn load_scene(path: &Path) -> Result<LoadedScene> {
    // A scene is a text of a few kB (meshes are files of their own, or base64 in `mesh.data`):
    // anything but a file, or a file of more than this, is not one (a device such as /dev/zero
    // would be read until memory runs out).
    const MAX_SCENE_BYTES: u64 = 256 << 20;
    if let Ok(meta) = std::fs::metadata(path) {
        if !meta.is_file() {
            return Err(Error::Option {
                option: format!("scene file {}", path.display()),
                why: "is not a regular file".into(),
            });
        }
        if meta.len() > MAX_SCENE_BYTES {
            return Err(Error::Option {
                option: format!("scene file {}", path.display()),
                why: format!(
                    "is {} MiB, more than a scene can be (at most {} MiB)",
                    meta.len() >> 20,
                    MAX_SCENE_BYTES >> 20
                ),
            });
        }
    }
    let text = std::fs::read_to_string(path).what(|| format!("cannot read scene file {}", path.display()))?;
    let mut scene = load_str(&text, &path.display().to_string())?;
    scene.network.resolve_files(path)?;
    Ok(scene)
}

#[cfg(test)]
mod tests {
    /// Every compute thread is named `compute-<i>`, also for the system (what profilers and
    /// `top -H` show), whichever thread builds the pool.
    #[test]
    fn compute_threads_are_named_for_the_system() {
        let pool = std::thread::Builder::new()
            .name("node interface:0".into())
            .spawn(|| super::compute_threads().num_threads(2).build().unwrap())
            .unwrap()
            .join()
            .unwrap();
        let mut names = pool.broadcast(|ctx| {
            // SAFETY: gettid has no preconditions.
            let tid = unsafe { libc::gettid() };
            let comm = std::fs::read_to_string(format!("/proc/self/task/{tid}/comm")).unwrap();
            (
                ctx.index(),
                std::thread::current().name().map(String::from),
                comm.trim().to_string(),
            )
        });
        names.sort();
        assert_eq!(
            names,
            (0..2)
                .map(|i| (i, Some(format!("compute-{i}")), format!("compute-{i}")))
                .collect::<Vec<_>>()
        );
    }
}
