//! The errors of the Zenoh transport.

use glissade_bus::NodeError;
use std::time::Duration;

/// Errors of the Zenoh transport.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error("zenoh: {what}: {detail}")]
    Zenoh { what: String, detail: String },
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error("no message for {0:?}: the run stalled or a peer died")]
    Timeout(Duration),
    #[error(
        "peer {peer} left the run (its liveliness token disappeared) while this process still had work{}",
        also_gone(.others)
    )]
    PeerLeft { peer: String, others: Vec<String> },
    #[error("stopped by the launcher: {0}")]
    Stopped(String),
    #[error("{0}")]
    Protocol(String),
}

fn also_gone(others: &[String]) -> String {
    if others.is_empty() {
        String::new()
    } else {
        format!("; also gone: {}", others.join(", "))
    }
}

pub(crate) fn zerr(what: &str, e: impl std::fmt::Display) -> TransportError {
    TransportError::Zenoh {
        what: what.to_string(),
        detail: e.to_string(),
    }
}
