//! The launcher library's errors (thiserror enums carrying data in the libraries,
//! anyhow only in the binary). Each says what failed and where, in the words the console prints;
//! the cause, when there is one, is its `source`, and the binary prints the chain
//! ("what: cause").

use crate::runner::{RunError, RunResult};
use glissade_recorder::RecorderError;
use glissade_scene::SceneError;
use glissade_zenoh::TransportError;
use std::path::PathBuf;

/// What went wrong in the launcher library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Building or iterating a run's nodes.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A scene that cannot be used (located: file, key, line).
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The bus: Zenoh, a node's stop, a peer that left.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// A message that does not decode as one of the run's.
    #[error(transparent)]
    Decode(#[from] glissade_messages::DecodeError),
    /// The monolithic reference that a report or check needs.
    #[error(transparent)]
    Reference(#[from] glissade_reference::ReferenceError),
    /// A recording that cannot be written or read.
    #[error(transparent)]
    Recorder(#[from] RecorderError),
    /// The run was interrupted (SIGINT, SIGTERM); it holds what was done.
    #[error(transparent)]
    Interrupted(Box<Interrupted>),
    /// A file or folder that cannot be read, created or written (`what` names it).
    #[error("{what}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
    /// The bus cannot be hosted, reached or joined (`what` says which and what to check).
    #[error("{what}")]
    Bus {
        what: String,
        #[source]
        source: TransportError,
    },
    /// A command-line option or a setting that cannot be used: `option` names it as the user
    /// wrote it (`--listen tcp/…`, `--credentials <file>`, `network.allow`, `+start4`).
    #[error("{option}: {why}")]
    Option { option: String, why: String },
    /// Another launcher's run with this id is on the bus (`alive`: its liveliness tokens there).
    #[error(
        "run id {run_id} is already in use on {bus}: {} alive there; nothing was started: choose another --run-id \
         (or leave it out for a new random one)",
        .alive.join(", ")
    )]
    RunIdTaken {
        run_id: String,
        bus: String,
        alive: Vec<String>,
    },
    /// A node process's own arguments that do not fit the run's scene.
    #[error("node {node}: {why}")]
    Node { node: String, why: String },
    /// What the bus gave as the run's scene is not it.
    #[error("the scene received from the bus does not match its fingerprint {fingerprint:016x}")]
    SceneMismatch { fingerprint: u64 },
    /// The launcher's scene query answered with another kind of message.
    #[error("the launcher's scene query returned a {kind} message")]
    NotAScene { kind: String },
    /// A scene without interface asked for what only interfaces give.
    #[error("scene `{scene}` has no interface: {consequence}")]
    NoInterface { scene: String, consequence: &'static str },
    /// Results (a run's, a recording's) that do not fit the scene: `what` is the result and its
    /// shape, `scene` what the scene gives.
    #[error("{what}, the scene gives {scene}")]
    ResultShape { what: String, scene: String },
    /// A result the run did not give.
    #[error("the run returned no {what}")]
    ResultMissing { what: String },
    /// A file that could not be written: nothing of it was kept.
    #[error("cannot write {}: {why}", .path.display())]
    Write { path: PathBuf, why: String },
    /// A finished file or folder that could not be moved to its name.
    #[error("cannot move {} to {}: {why}", .from.display(), .to.display())]
    Move { from: PathBuf, to: PathBuf, why: String },
    /// Nothing came on the bus for `idle`: `what` happened then.
    #[error("no message on the bus for {} s: {what}", .idle.as_secs())]
    Silent { idle: std::time::Duration, what: String },
    /// The run stopped moving and could not be set going again: who waits for what from whom.
    #[error("the run stopped moving: {diagnosis}")]
    Stalled { diagnosis: String },
    /// Node processes that did not leave after the run ended.
    #[error("node(s) {} did not leave within {} s after the run ended", .nodes.join(", "), .timeout.as_secs())]
    NotLeaving {
        nodes: Vec<String>,
        timeout: std::time::Duration,
    },
    /// The run ended without every interface's solution.
    #[error("the run ended with {got} of the {expected} interface solutions on the bus")]
    MissingSolutions { got: usize, expected: usize },
    /// A file that is there already: nothing was overwritten.
    #[error("{} already exists; nothing was overwritten", .0.display())]
    Exists(PathBuf),
    /// Another input that cannot be used (a combination of options, a bus message the launcher
    /// cannot take): the message names it and says why.
    #[error("{0}")]
    Invalid(String),
    /// Another failure and why: a node process that failed (how, and its last lines), a recorder
    /// process that failed, a benchmark's runs that disagree.
    #[error("{0}")]
    Failed(String),
    /// What was not done (`what`) because of `source`.
    #[error("{what}")]
    NotDone {
        what: String,
        #[source]
        source: Box<Error>,
    },
}

impl From<Interrupted> for Error {
    fn from(i: Interrupted) -> Self {
        Error::Interrupted(Box::new(i))
    }
}

/// The launcher library's results.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// `e` and its causes, as the binary prints them: "what: cause: cause's cause".
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        text += &format!(": {c}");
        cause = c.source();
    }
    text
}

/// An I/O error with what was being done (`what`: e.g. "cannot read scene file x.toml").
pub(crate) trait IoWhat<T> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T>;
}

impl<T> IoWhat<T> for std::io::Result<T> {
    fn what(self, what: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|source| Error::Io { what: what(), source })
    }
}

/// An `Error::Failed` with this message.
macro_rules! failed {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Failed(format!($($arg)*)))
    };
}
pub(crate) use failed;

/// The Zenoh error of `what`, as [`TransportError::Zenoh`].
pub(crate) fn zenoh(what: &str, e: impl std::fmt::Display) -> Error {
    Error::Transport(TransportError::Zenoh {
        what: what.to_string(),
        detail: e.to_string(),
    })
}

/// The run was interrupted (SIGINT/SIGTERM); every node was stopped. `partial` holds the
/// iterations done so far.
#[derive(Debug, thiserror::Error)]
#[error("interrupted after {} iteration(s); every node was stopped", .partial.iterations.len())]
pub struct Interrupted {
    pub partial: RunResult,
}
