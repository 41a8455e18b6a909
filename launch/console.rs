//! What the launcher says besides results, as `tracing` events of target [`TARGET`]: notes (how
//! fields travel, node readiness, bus statistics, node processes' own notes) at debug level,
//! shown only with `--verbose`; lines always shown (instructions, forwarded node output) at info;
//! warnings and errors at their levels. The binary prints these events verbatim on stderr
//! ("warning: …" for a warning); a program using the library chooses its own subscriber.

use std::sync::atomic::{AtomicBool, Ordering};

/// The target of the console's events.
pub const TARGET: &str = "glissade::console";

static VERBOSE: AtomicBool = AtomicBool::new(false);

/// Shows the notes from now on (`--verbose`).
pub fn set_verbose(on: bool) {
    VERBOSE.store(on, Ordering::Relaxed);
}

pub fn verbose() -> bool {
    VERBOSE.load(Ordering::Relaxed)
}

/// A note: shown with `--verbose`.
pub fn note(line: &str) {
    tracing::debug!(target: TARGET, "{line}");
}

/// A line always shown.
pub fn say(line: &str) {
    tracing::info!(target: TARGET, "{line}");
}

/// A warning: the run goes on, or its results do not depend on what failed.
pub fn warn(line: &str) {
    tracing::warn!(target: TARGET, "{line}");
}

/// Whether a line a node process printed is to be shown: its notes (lines starting with
/// [`glissade_zenoh::NOTE`]) only with `--verbose`, everything else always.
pub fn shows_child_line(line: &str) -> bool {
    verbose() || !line.starts_with(glissade_zenoh::NOTE)
}
