//! What the launcher prints besides results: notes (how fields travel, node readiness, bus
//! statistics, node processes' own notes) only with `--verbose`; warnings and errors always.

use std::sync::atomic::{AtomicBool, Ordering};

static VERBOSE: AtomicBool = AtomicBool::new(false);

/// Shows the notes from now on (`--verbose`).
pub fn set_verbose(on: bool) {
    VERBOSE.store(on, Ordering::Relaxed);
}

pub fn verbose() -> bool {
    VERBOSE.load(Ordering::Relaxed)
}

/// Prints `line` to stderr with `--verbose`.
pub fn note(line: &str) {
    if verbose() {
        eprintln!("{line}");
    }
}

/// Whether a line a node process printed is to be shown: its notes (lines starting with
/// [`glissade_zenoh::NOTE`]) only with `--verbose`, everything else always.
pub fn shows_child_line(line: &str) -> bool {
    verbose() || !line.starts_with(glissade_zenoh::NOTE)
}
