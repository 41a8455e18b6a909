//! The launcher library's errors (DESIGN §1: thiserror enums carrying data in the libraries,
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
    /// A file that is there already: nothing was overwritten.
    #[error("{} already exists; nothing was overwritten", .0.display())]
    Exists(PathBuf),
    /// An argument, a setting or an input that cannot be used: the message names it and says why.
    #[error("{0}")]
    Invalid(String),
    /// Something that failed and why: a run as processes (the node, how it failed and its last
    /// lines; or why the run stopped: stalled, nodes not ready, a recorder that failed), a file
    /// that could not be written (nothing of it kept), results that do not fit the scene.
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

/// An `Error::Invalid` with this message.
macro_rules! invalid {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Invalid(format!($($arg)*)))
    };
}
pub(crate) use invalid;

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
