//! Presence: the liveliness tokens of a run's nodes and launcher, and the watch on them.

use crate::error::zerr;
use crate::TransportError;
use glissade_messages::topic;
use std::collections::BTreeSet;
use std::sync::mpsc;
use zenoh::sample::SampleKind;
use zenoh::{Session, Wait};

/// Declares a liveliness subscriber on every token of `run_id` (with the tokens already alive)
/// that forwards its changes to `tx` through `wrap`.
pub(crate) fn watch_tokens<T: Send + 'static>(
    session: &Session,
    run_id: &str,
    tx: mpsc::Sender<T>,
    wrap: impl Fn(String, bool) -> T + Send + Sync + 'static,
) -> Result<zenoh::pubsub::Subscriber<()>, TransportError> {
    session
        .liveliness()
        .declare_subscriber(topic::alive_all(run_id))
        .history(true)
        .callback(move |s| {
            let _ = tx.send(wrap(s.key_expr().as_str().to_string(), s.kind() == SampleKind::Put));
        })
        .wait()
        .map_err(|e| zerr("liveliness subscriber", e))
}

/// The launcher's view of which nodes of a run are alive (their liveliness tokens).
pub struct Presence {
    _subscriber: zenoh::pubsub::Subscriber<()>,
    rx: mpsc::Receiver<(String, bool)>,
    alive: BTreeSet<String>,
}

impl Presence {
    /// Watches every token of `run_id`, including those already alive.
    pub fn watch(session: &Session, run_id: &str) -> Result<Self, TransportError> {
        let (tx, rx) = mpsc::channel();
        let subscriber = watch_tokens(session, run_id, tx, |k, up| (k, up))?;
        Ok(Self {
            _subscriber: subscriber,
            rx,
            alive: BTreeSet::new(),
        })
    }

    /// The changes since the last call: (token key, appeared?), in arrival order.
    pub fn changes(&mut self) -> Vec<(String, bool)> {
        let changes: Vec<(String, bool)> = self.rx.try_iter().collect();
        for (key, up) in &changes {
            if *up {
                self.alive.insert(key.clone());
            } else {
                self.alive.remove(key);
            }
        }
        changes
    }

    pub fn is_alive(&self, key: &str) -> bool {
        self.alive.contains(key)
    }
}

/// Declares the launcher's liveliness token (nodes stop when it disappears).
pub fn launcher_token(session: &Session, run_id: &str) -> Result<zenoh::liveliness::LivelinessToken, TransportError> {
    session
        .liveliness()
        .declare_token(topic::alive(run_id, "launcher", 0))
        .wait()
        .map_err(|e| zerr("liveliness token", e))
}

/// The liveliness tokens of `run_id` alive on the bus now (asked with a bounded wait): another
/// launcher or nodes already using this run id.
pub fn tokens_alive(
    session: &Session,
    run_id: &str,
    timeout: std::time::Duration,
) -> Result<Vec<String>, TransportError> {
    let replies = session
        .liveliness()
        .get(topic::alive_all(run_id))
        .timeout(timeout)
        .wait()
        .map_err(|e| zerr("liveliness query", e))?;
    let mut keys = Vec::new();
    while let Ok(reply) = replies.recv() {
        if let Ok(sample) = reply.result() {
            keys.push(sample.key_expr().as_str().to_string());
        }
    }
    keys.sort();
    keys.dedup();
    Ok(keys)
}
