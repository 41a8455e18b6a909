//! The Zenoh transport of glissade (DESIGN §4): runs sans-IO [`Node`]s over a Zenoh session.
//!
//! Topology (STACK.md, "topology trap"): the launcher opens a session in `router` mode listening
//! on an explicit endpoint; every node process opens a `client` session connected to it, with
//! multicast scouting off. Clients route through the router, so every node reaches every other.
//!
//! Start-up without lost messages: Zenoh pub/sub is not durable, so
//! 1. a node process fetches the scene with a query to the launcher's queryable (no race);
//! 2. it declares its subscribers, then a liveliness token `glissade/<run>/alive/<role>/<id>`;
//! 3. the launcher waits until every expected token is alive, then publishes `start`;
//! 4. only then do nodes call [`Node::start`] and publish.
//!
//! Every put uses `CongestionControl::Block` (multi-MB fields are never dropped). Every wait is
//! bounded by a timeout.

use glissade_bus::{Node, NodeError};
use glissade_messages::{decode, encode, DecodeError, Expected, Message};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;
use zenoh::{Config, Session, Wait};

/// Errors of the Zenoh transport.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error("zenoh: {what}: {detail}")]
    Zenoh { what: String, detail: String },
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error("no message for {0:?}: the run stalled or a peer died")]
    Timeout(Duration),
    #[error("{0}")]
    Protocol(String),
}

fn zerr(what: &str, e: impl std::fmt::Display) -> TransportError {
    TransportError::Zenoh {
        what: what.to_string(),
        detail: e.to_string(),
    }
}

/// Key of the scene queryable of a run.
pub fn scene_key(run_id: &str) -> String {
    format!("glissade/{run_id}/launcher/0/scene")
}

/// Key the launcher publishes on once every node is ready.
pub fn start_key(run_id: &str) -> String {
    format!("glissade/{run_id}/launcher/0/start")
}

/// Liveliness token of a node.
pub fn alive_key(run_id: &str, role: &str, index: u32) -> String {
    format!("glissade/{run_id}/alive/{role}/{index}")
}

/// Session configuration: `mode` ("router", "peer" or "client"), explicit listen and connect
/// endpoints, multicast scouting off unless asked.
pub fn config(mode: &str, listen: &[String], connect: &[String], multicast: bool) -> Result<Config, TransportError> {
    let mut c = Config::default();
    let json_list = |v: &[String]| {
        format!(
            "[{}]",
            v.iter().map(|e| format!("\"{e}\"")).collect::<Vec<_>>().join(",")
        )
    };
    c.insert_json5("mode", &format!("\"{mode}\""))
        .map_err(|e| zerr("config mode", e))?;
    c.insert_json5("scouting/multicast/enabled", if multicast { "true" } else { "false" })
        .map_err(|e| zerr("config scouting", e))?;
    c.insert_json5("listen/endpoints", &json_list(listen))
        .map_err(|e| zerr("config listen", e))?;
    c.insert_json5("connect/endpoints", &json_list(connect))
        .map_err(|e| zerr("config connect", e))?;
    Ok(c)
}

pub fn open(config: Config) -> Result<Session, TransportError> {
    zenoh::open(config).wait().map_err(|e| zerr("open session", e))
}

/// Publishes one message on its topic, blocking rather than dropping under congestion.
pub fn publish(session: &Session, msg: &Message) -> Result<(), TransportError> {
    session
        .put(msg.topic(), encode(msg))
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| zerr(&format!("put {}", msg.topic()), e))
}

/// Fetches a run's scene message from the launcher's queryable (bytes), waiting up to `timeout`.
pub fn fetch_scene(session: &Session, run_id: &str, timeout: Duration) -> Result<Vec<u8>, TransportError> {
    let deadline = Instant::now() + timeout;
    loop {
        let replies = session
            .get(scene_key(run_id))
            .timeout(Duration::from_secs(2))
            .wait()
            .map_err(|e| zerr("query scene", e))?;
        while let Ok(reply) = replies.recv() {
            if let Ok(sample) = reply.result() {
                return Ok(sample.payload().to_bytes().into_owned());
            }
        }
        if Instant::now() >= deadline {
            return Err(TransportError::Protocol(format!(
                "no launcher of run `{run_id}` answered the scene query within {timeout:?} (wrong --run or --connect?)"
            )));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// What a node process needs to take part in a run.
#[derive(Debug, Clone)]
pub struct NodeRun {
    pub run_id: String,
    pub expected: Expected,
    /// Role and index of this process's liveliness token.
    pub token_role: String,
    pub token_index: u32,
    /// Longest wait for the launcher's start.
    pub start_timeout: Duration,
    /// Longest wait for any message once started.
    pub idle_timeout: Duration,
}

/// Runs `nodes` (all hosted by this process) on `session` until each is finished.
///
/// Messages that do not decode for this run (other run, other scene, other schema version,
/// corrupt) are skipped with a reason passed to `log`; a message a node rejects stops the
/// process with that node's error. `idle_timeout` bounds the wait for any message.
pub fn run_nodes(
    session: &Session,
    run: &NodeRun,
    mut nodes: Vec<Box<dyn Node>>,
    mut log: impl FnMut(&str),
) -> Result<(), TransportError> {
    let (run_id, expected, start_timeout, idle_timeout) =
        (&run.run_id, &run.expected, run.start_timeout, run.idle_timeout);
    let (tx, rx) = mpsc::channel::<(String, Vec<u8>)>();
    let subscriptions: Vec<Vec<String>> = nodes.iter().map(|n| n.subscriptions()).collect();
    let mut keys: Vec<String> = subscriptions.iter().flatten().cloned().collect();
    keys.sort();
    keys.dedup();
    let mut subscribers = Vec::new();
    for key in &keys {
        let tx = tx.clone();
        let sub = session
            .declare_subscriber(key.as_str())
            .callback(move |sample| {
                let _ = tx.send((
                    sample.key_expr().as_str().to_string(),
                    sample.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .map_err(|e| zerr(&format!("subscribe {key}"), e))?;
        subscribers.push(sub);
    }
    let (start_tx, start_rx) = mpsc::channel::<()>();
    let _start_sub = session
        .declare_subscriber(start_key(run_id))
        .callback(move |_| {
            let _ = start_tx.send(());
        })
        .wait()
        .map_err(|e| zerr("subscribe start", e))?;
    let _token = session
        .liveliness()
        .declare_token(alive_key(run_id, &run.token_role, run.token_index))
        .wait()
        .map_err(|e| zerr("liveliness token", e))?;
    start_rx.recv_timeout(start_timeout).map_err(|_| {
        TransportError::Protocol(format!("the launcher did not start the run within {start_timeout:?}"))
    })?;
    for node in &mut nodes {
        for m in node.start()? {
            publish(session, &m)?;
        }
    }
    while !nodes.iter().all(|n| n.is_finished()) {
        let (key, bytes) = rx
            .recv_timeout(idle_timeout)
            .map_err(|_| TransportError::Timeout(idle_timeout))?;
        let msg = match decode(&bytes, expected) {
            Ok(m) => m,
            Err(e) => {
                log(&format!("ignored a message on {key}: {e}"));
                continue;
            }
        };
        if msg.topic() != key {
            log(&format!(
                "ignored a message on {key}: its envelope and payload belong on {}",
                msg.topic()
            ));
            continue;
        }
        for (node, subs) in nodes.iter_mut().zip(&subscriptions) {
            if subs.iter().any(|s| glissade_messages::key_matches(s, &key)) {
                for out in node.handle(&msg)? {
                    publish(session, &out)?;
                }
            }
        }
    }
    Ok(())
}

/// The launcher's side: serves the scene, waits for the expected nodes' liveliness tokens, then
/// publishes `start`. Returns the queryable (keep it alive for the whole run).
pub fn serve_scene(
    session: &Session,
    run_id: &str,
    scene_message: Vec<u8>,
) -> Result<zenoh::query::Queryable<()>, TransportError> {
    let key = scene_key(run_id);
    let reply_key = key.clone();
    session
        .declare_queryable(key.as_str())
        .callback(move |query| {
            let _ = query.reply(reply_key.as_str(), scene_message.clone()).wait();
        })
        .wait()
        .map_err(|e| zerr("scene queryable", e))
}

/// Waits until every key of `expected` has a live token (or `timeout` passes); calls
/// `is_alive()` between polls so a launcher can notice a child that died.
pub fn wait_for_nodes(
    session: &Session,
    run_id: &str,
    expected: &[String],
    timeout: Duration,
    mut still_ok: impl FnMut() -> Result<(), TransportError>,
) -> Result<(), TransportError> {
    let (tx, rx) = mpsc::channel::<(String, bool)>();
    let _watch = session
        .liveliness()
        .declare_subscriber(format!("glissade/{run_id}/alive/**"))
        .history(true)
        .callback(move |s| {
            let _ = tx.send((s.key_expr().as_str().to_string(), s.kind() == SampleKind::Put));
        })
        .wait()
        .map_err(|e| zerr("liveliness subscriber", e))?;
    let deadline = Instant::now() + timeout;
    let mut alive = std::collections::BTreeSet::new();
    while !expected.iter().all(|k| alive.contains(k)) {
        still_ok()?;
        if Instant::now() >= deadline {
            let missing: Vec<&String> = expected.iter().filter(|k| !alive.contains(*k)).collect();
            return Err(TransportError::Protocol(format!(
                "nodes not ready within {timeout:?}: {missing:?}"
            )));
        }
        if let Ok((key, up)) = rx.recv_timeout(Duration::from_millis(100)) {
            if up {
                alive.insert(key);
            } else {
                alive.remove(&key);
            }
        }
    }
    session
        .put(start_key(run_id), Vec::<u8>::new())
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| zerr("put start", e))?;
    Ok(())
}

/// Decodes the envelope only, to learn the scene fingerprint of a scene message.
pub fn scene_fingerprint_of(bytes: &[u8], run_id: &str) -> Result<u64, DecodeError> {
    glissade_messages::peek_envelope(bytes, run_id).map(|e| e.scene_fingerprint)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_messages::{Envelope, Field, NodeId, Payload, Role, Stage, SCHEMA_VERSION};

    /// A boundary state of several MB (about the size of one subdomain's field at N = 1000)
    /// crosses the router between two client sessions intact, and decodes.
    #[test]
    fn multi_megabyte_message_arrives_intact() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let router = open(config("router", std::slice::from_ref(&endpoint), &[], false).unwrap()).unwrap();
        let a = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        let b = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        let (rows, cols) = (320, 1001);
        let msg = Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: "mb".into(),
                scene_fingerprint: 1,
                iteration: 0,
                stage: Stage::Linear,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: 0,
                },
            },
            payload: Payload::BoundaryState {
                subdomain: 0,
                w: Field::from_fn(rows, cols, |r, c| (r * cols + c) as f64 * 1e-3),
                f: Field::from_fn(rows, cols, |r, c| -((r + c) as f64)),
            },
        };
        let (tx, rx) = mpsc::channel::<Vec<u8>>();
        let _sub = b
            .declare_subscriber(msg.topic())
            .callback(move |s| {
                let _ = tx.send(s.payload().to_bytes().into_owned());
            })
            .wait()
            .unwrap();
        // Let the subscription reach the router before publishing (pub/sub is not durable).
        std::thread::sleep(Duration::from_millis(500));
        publish(&a, &msg).unwrap();
        let bytes = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        assert!(bytes.len() > 5_000_000, "{} bytes", bytes.len());
        let back = decode(
            &bytes,
            &Expected {
                run_id: "mb".into(),
                scene_fingerprint: 1,
            },
        )
        .unwrap();
        assert_eq!(back, msg);
        drop(router);
    }
}
