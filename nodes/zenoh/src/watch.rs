//! What a node process tells the launcher when a run stops moving (issue: never hang): for each
//! of its nodes, what it waits for, whether the process is busy, what it last handled and the
//! last message it put on each key ([`Watch`], kept up to date by the node loop), sent as a
//! [`NodeStatus`] when the launcher asks; and the last message on each key, kept so that the
//! launcher can ask for it again when its receiver lacks it ([`Responder`]).
//!
//! A message put on the bus can still be lost on the way: Zenoh 1.10.2 drops, logging it at debug
//! level only, a shared-memory message whose buffer's watchdog lapsed while it was in flight
//! (a process starved of CPU misses the 50 ms confirmations). Messages are idempotent by their
//! bytes (a receiver drops a repeat), so publishing the same bytes again is safe; they go again
//! as a copy over the link, not as the shared buffer whose watchdog lapsed.

use crate::publish::put_bytes;
use glissade_messages::{
    encode, Awaited, Envelope, Expected, Message, MessageSeen, NodeId, NodeStatus, Payload, Role, Stage, SCHEMA_VERSION,
};
use std::collections::BTreeMap;
use std::sync::{mpsc, Arc, Mutex};
use std::time::Instant;
use zenoh::bytes::ZBytes;
use zenoh::Session;

/// Name of the environment variable of the transport's test hook: `<role>[:<index>]/<field>/<iteration>`
/// makes this process leave out the first message it would publish that matches (by a node of
/// that role, and index when given, on a key of that field, at that iteration), as if the bus had
/// lost it; the process still counts it as published, and keeps it to publish again when asked.
/// With `/unrecoverable` appended it does not keep it: asked again, it has nothing to send.
pub const DROP_HOOK: &str = "GLISSADE_TEST_DROP";

/// A message to leave out once ([`DROP_HOOK`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct DropOnce {
    role: Role,
    index: Option<u32>,
    field: String,
    iteration: u32,
    /// The message is not kept either (the hook's `/unrecoverable`).
    unrecoverable: bool,
}

/// What the test hook does with a message about to be published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Hook {
    Publish,
    LeaveOut,
    /// Leave it out and do not keep it.
    Lose,
}

impl DropOnce {
    /// The hook of this process's environment, if set; Err names what is wrong with it.
    pub(crate) fn from_env() -> Result<Option<Self>, String> {
        match std::env::var(DROP_HOOK) {
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(e) => Err(format!("{DROP_HOOK}: {e}")),
            Ok(v) => Self::parse(&v).map(Some),
        }
    }

    pub(crate) fn parse(v: &str) -> Result<Self, String> {
        let bad = |why: &str| {
            format!("{DROP_HOOK} = {v:?}: {why} (expected <role>[:<index>]/<field>/<iteration>[/unrecoverable], e.g. interface/indicator_partials/5)")
        };
        let mut parts: Vec<&str> = v.split('/').collect();
        let unrecoverable = parts.last() == Some(&"unrecoverable");
        if unrecoverable {
            parts.pop();
        }
        let [who, field, iteration] = parts[..] else {
            return Err(bad("not three parts separated by /"));
        };
        let (role, index) = match who.split_once(':') {
            Some((r, i)) => (r, Some(i.parse::<u32>().map_err(|_| bad("the index is not a number"))?)),
            None => (who, None),
        };
        let role = [Role::Subdomain, Role::Interface, Role::Coarse]
            .into_iter()
            .find(|r| r.key() == role)
            .ok_or_else(|| bad("the role is not subdomain, interface or coarse"))?;
        if field.is_empty() {
            return Err(bad("no field"));
        }
        let iteration = iteration.parse().map_err(|_| bad("the iteration is not a number"))?;
        Ok(Self {
            role,
            index,
            field: field.to_string(),
            iteration,
            unrecoverable,
        })
    }

    fn matches(&self, msg: &Message) -> bool {
        let s = msg.envelope.sender;
        s.role == self.role
            && self.index.is_none_or(|i| i == s.index)
            && msg.payload.field_key() == self.field
            && msg.envelope.iteration == self.iteration
    }
}

/// One node's part of the snapshot.
struct NodeState {
    id: NodeId,
    finished: bool,
    awaits: Vec<Awaited>,
}

impl NodeState {
    fn of(node: &dyn glissade_bus::Node) -> Self {
        Self {
            id: node.id(),
            finished: node.is_finished(),
            awaits: node.awaits(),
        }
    }
}

/// The last messages a node put on a key: the last one, or all of the last iteration's where a
/// key carries several (an interface node's final solutions).
struct Kept {
    sender: NodeId,
    iteration: u32,
    at: Instant,
    /// Empty when the test hook lost the message ([`Hook::Lose`]).
    bytes: Vec<ZBytes>,
}

#[derive(Default)]
struct State {
    nodes: Vec<NodeState>,
    handled: u64,
    last_handled: Option<(String, u32, Instant)>,
    busy_since: Option<Instant>,
    kept: BTreeMap<String, Kept>,
    drop: Option<DropOnce>,
}

/// A node process's progress, kept by its node loop and read by its [`Responder`].
#[derive(Clone, Default)]
pub(crate) struct Watch(Arc<Mutex<State>>);

impl Watch {
    pub(crate) fn new(drop: Option<DropOnce>) -> Self {
        Self(Arc::new(Mutex::new(State {
            drop,
            ..State::default()
        })))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A poisoned lock only means another thread panicked while holding it: the state is a
        // snapshot, still readable.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The nodes' waits and states, once the process has handled what it had (it is idle).
    pub(crate) fn update(&self, nodes: &[Box<dyn glissade_bus::Node>]) {
        let states = nodes.iter().map(|n| NodeState::of(n.as_ref())).collect();
        let mut s = self.lock();
        s.nodes = states;
        s.busy_since = None;
    }

    /// [`Watch::update`] of the nodes `touched` marks (those handed a message since the last
    /// look; the marks are cleared): the others' waits cannot have changed. A process hosting
    /// hundreds of subdomains looks at one or a few per message instead of all.
    pub(crate) fn update_touched(&self, nodes: &[Box<dyn glissade_bus::Node>], touched: &mut [bool]) {
        let fresh: Vec<(usize, NodeState)> = touched
            .iter_mut()
            .enumerate()
            .filter(|(_, t)| **t)
            .map(|(k, t)| {
                *t = false;
                (k, NodeState::of(nodes[k].as_ref()))
            })
            .collect();
        let mut s = self.lock();
        if s.nodes.len() != nodes.len() {
            drop(s);
            return self.update(nodes);
        }
        for (k, state) in fresh {
            s.nodes[k] = state;
        }
        s.busy_since = None;
    }

    /// The process starts handling messages.
    pub(crate) fn busy(&self) {
        self.lock().busy_since = Some(Instant::now());
    }

    /// The process handled `count` messages, the last on `key` at `iteration`.
    pub(crate) fn handled(&self, count: usize, last: Option<(&str, u32)>) {
        let mut s = self.lock();
        s.handled += count as u64;
        if let Some((key, iteration)) = last {
            s.last_handled = Some((key.to_string(), iteration, Instant::now()));
        }
    }

    /// What the test hook does with `msg`, about to be published (it acts once).
    pub(crate) fn hook(&self, msg: &Message) -> Hook {
        let mut s = self.lock();
        match s.drop.take_if(|d| d.matches(msg)) {
            Some(d) if d.unrecoverable => Hook::Lose,
            Some(_) => Hook::LeaveOut,
            None => Hook::Publish,
        }
    }

    /// `bytes` went out on `key` (or were left out by the test hook): kept until the next message
    /// on that key, to be put again if the launcher asks (None: recorded as sent, not kept).
    pub(crate) fn sent(&self, key: &str, sender: NodeId, iteration: u32, bytes: Option<ZBytes>) {
        let mut s = self.lock();
        let at = Instant::now();
        match s.kept.get_mut(key) {
            Some(k) if k.iteration == iteration && k.sender == sender => {
                k.bytes.extend(bytes);
                k.at = at;
            }
            _ => {
                s.kept.insert(
                    key.to_string(),
                    Kept {
                        sender,
                        iteration,
                        at,
                        bytes: bytes.into_iter().collect(),
                    },
                );
            }
        }
    }

    /// The status of each node, answering round `round`.
    fn statuses(&self, expected: &Expected, round: u64) -> Vec<Message> {
        let s = self.lock();
        let now = Instant::now();
        let ms = |t: Instant| now.saturating_duration_since(t).as_millis() as u64;
        s.nodes
            .iter()
            .map(|n| {
                let sent: Vec<MessageSeen> = s
                    .kept
                    .iter()
                    .filter(|(_, k)| k.sender == n.id)
                    .map(|(key, k)| MessageSeen {
                        key: key.clone(),
                        iteration: k.iteration,
                        ms_ago: ms(k.at),
                    })
                    .collect();
                let iteration = n.awaits.iter().map(|a| a.iteration).max().unwrap_or(0);
                Message {
                    envelope: Envelope {
                        schema_version: SCHEMA_VERSION,
                        run_id: expected.run_id.clone(),
                        scene_fingerprint: expected.scene_fingerprint,
                        iteration,
                        stage: Stage::Local,
                        sender: n.id,
                    },
                    payload: Payload::NodeStatus(NodeStatus {
                        round,
                        finished: n.finished,
                        awaits: n.awaits.clone(),
                        busy_ms: s.busy_since.map(ms),
                        handled: s.handled,
                        last_handled: s.last_handled.as_ref().map(|(key, iteration, at)| MessageSeen {
                            key: key.clone(),
                            iteration: *iteration,
                            ms_ago: ms(*at),
                        }),
                        sent,
                    }),
                }
            })
            .collect()
    }

    /// Copies of the last messages kept on `key`, with their iteration (the bytes are copied
    /// after the lock is released: the publishing threads do not wait for it).
    fn copy_of(&self, key: &str) -> Option<(Vec<Vec<u8>>, u32)> {
        let (held, iteration) = {
            let s = self.lock();
            let k = s.kept.get(key)?;
            (k.bytes.clone(), k.iteration)
        };
        Some((held.iter().map(|b| b.to_bytes().into_owned()).collect(), iteration))
    }
}

/// What the launcher asks of a node process.
pub(crate) enum Ask {
    Status(u64),
    Republish(String),
    Quit,
}

/// Answers the launcher's status requests and republish requests on a thread of its own, so that
/// a process busy in a long computation, or finished and waiting for the launcher's word, still
/// answers.
pub(crate) struct Responder {
    tx: mpsc::Sender<Ask>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Responder {
    /// Starts the responder of `watch` on `session`, taking what the launcher asks from `rx`
    /// (`tx` is its sender, kept to stop it); its log lines go to `note`.
    pub(crate) fn start(
        session: &Session,
        expected: Expected,
        watch: Watch,
        (tx, rx): (mpsc::Sender<Ask>, mpsc::Receiver<Ask>),
        note: impl Fn(String) + Send + Sync + 'static,
    ) -> Result<Self, crate::TransportError> {
        let session = session.clone();
        let note = Arc::new(note);
        let thread = std::thread::Builder::new()
            .name("glissade-status".into())
            .spawn(move || {
                let mine = |key: &str| watch.lock().kept.contains_key(key);
                while let Ok(ask) = rx.recv() {
                    match ask {
                        Ask::Quit => break,
                        Ask::Status(round) => {
                            for m in watch.statuses(&expected, round) {
                                if let Err(e) = put_bytes(&session, &m.topic(), encode(&m)) {
                                    note(format!("cannot send the status the launcher asked for: {e}"));
                                }
                            }
                        }
                        // On a thread of its own: copying and sending a large message again must
                        // not delay the answers to status requests.
                        Ask::Republish(key) if mine(&key) => {
                            let (session, watch, n) = (session.clone(), watch.clone(), note.clone());
                            let spawned = std::thread::Builder::new()
                                .name("glissade-republish".into())
                                .spawn(move || republish(&session, &watch, &key, &*n));
                            if let Err(e) = spawned {
                                note(format!("cannot publish a message again: no thread: {e}"));
                            }
                        }
                        Ask::Republish(_) => {}
                    }
                }
            })
            .map_err(|e| crate::TransportError::Protocol(format!("cannot start the status responder's thread: {e}")))?;
        Ok(Self {
            tx,
            thread: Some(thread),
        })
    }
}

/// Puts the last messages kept on `key` again, as copies over the link.
fn republish(session: &Session, watch: &Watch, key: &str, note: &(dyn Fn(String) + Send + Sync)) {
    let Some((copies, iteration)) = watch.copy_of(key) else {
        return;
    };
    if copies.is_empty() {
        note(format!(
            "cannot publish {key} (iteration {iteration}) again: it was not kept"
        ));
        return;
    }
    let outcome = copies.into_iter().try_for_each(|bytes| put_bytes(session, key, bytes));
    note(match outcome {
        Ok(()) => format!(
            "{}published {key} (iteration {iteration}) again: the launcher says its receiver lacks it",
            crate::NOTE
        ),
        Err(e) => format!("cannot publish {key} again: {e}"),
    });
}

impl Drop for Responder {
    fn drop(&mut self) {
        let _ = self.tx.send(Ask::Quit);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hook's value names a role (and index), a field and an iteration; anything else is
    /// refused with the variable's name and the expected form.
    #[test]
    fn the_drop_hook_is_parsed_or_refused() {
        let d = DropOnce::parse("interface/indicator_partials/5").unwrap();
        assert_eq!(
            (d.role, d.index, d.field.as_str(), d.iteration),
            (Role::Interface, None, "indicator_partials", 5)
        );
        let d = DropOnce::parse("subdomain:3/boundary_state/2").unwrap();
        assert_eq!((d.role, d.index, d.unrecoverable), (Role::Subdomain, Some(3), false));
        assert!(
            DropOnce::parse("coarse/macro_displacements/4/unrecoverable")
                .unwrap()
                .unrecoverable
        );
        for bad in [
            "",
            "interface/5",
            "launcher/x/1",
            "coarse:a/macro_displacements/1",
            "coarse/macro/x",
            "coarse//1",
        ] {
            let e = DropOnce::parse(bad).unwrap_err();
            assert!(e.contains(DROP_HOOK) && e.contains("expected"), "{bad}: {e}");
        }
    }
}
