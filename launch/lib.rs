//! The glissade launcher as a library: loads scenes, builds the nodes of a run and drives them on
//! a bus, and writes run outputs. The `glissade` binary only parses arguments and calls this.

pub mod accuracy;
pub mod bench;
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
pub mod run;
pub mod runner;
pub mod stability;
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

/// Reads and validates a scene file; its TLS files (`network.tls`) become relative to its folder
/// and must be readable.
pub fn load_scene(path: &Path) -> Result<LoadedScene> {
    let text = std::fs::read_to_string(path).what(|| format!("cannot read scene file {}", path.display()))?;
    let mut scene = load_str(&text, &path.display().to_string())?;
    scene.network.resolve_files(path)?;
    Ok(scene)
}
