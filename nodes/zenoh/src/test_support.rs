//! Sessions, messages and runs for the tests of every module.

use crate::{config, free_loopback_port, open, set_shared_memory, NodeRun};
use glissade_messages::{Envelope, Expected, Field, Message, NodeId, Payload, Role, Stage, SCHEMA_VERSION};
use std::sync::mpsc;
use std::time::Duration;
use zenoh::{Session, Wait};

/// The payloads `session` receives on `key`, in a channel (keep the subscriber alive).
pub(crate) fn received(session: &Session, key: &str) -> (zenoh::pubsub::Subscriber<()>, mpsc::Receiver<Vec<u8>>) {
    let (tx, rx) = mpsc::channel();
    let sub = session
        .declare_subscriber(key)
        .callback(move |s| {
            let _ = tx.send(s.payload().to_bytes().into_owned());
        })
        .wait()
        .unwrap();
    (sub, rx)
}

/// Subdomain 0's boundary state of iteration 0 in run `run_id`, `rows` × `cols` fields of
/// distinct values.
pub(crate) fn boundary_state(run_id: &str, scene_fingerprint: u64, rows: usize, cols: usize) -> Message {
    Message {
        envelope: Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: run_id.into(),
            scene_fingerprint,
            iteration: 0,
            stage: Stage::Linear,
            sender: NodeId {
                role: Role::Subdomain,
                index: 0,
            },
        },
        payload: Payload::BoundaryState {
            subdomain: 0,
            to: None,
            interfaces: vec![0],
            w: Field::from_fn(rows, cols, |r, c| (r * cols + c) as f64 * 1e-3),
            f: Field::from_fn(rows, cols, |r, c| -((r + c) as f64)),
        },
    }
}

/// A router and three clients on loopback: two with shared memory on, one without.
pub(crate) fn shm_sessions() -> [Session; 4] {
    let port = free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let shm_config = |mode: &str, listen: &[String], connect: &[String]| {
        let mut c = config(mode, listen, connect, false).unwrap();
        set_shared_memory(&mut c, true).unwrap();
        c
    };
    let router = open(shm_config("router", std::slice::from_ref(&endpoint), &[])).unwrap();
    let a = open(shm_config("client", &[], std::slice::from_ref(&endpoint))).unwrap();
    let b = open(shm_config("client", &[], std::slice::from_ref(&endpoint))).unwrap();
    let plain = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
    [router, a, b, plain]
}

/// A launcher-side router session on a free loopback port, with its endpoint.
pub(crate) fn test_launcher() -> (Session, String) {
    let port = free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let launcher = open(config("router", std::slice::from_ref(&endpoint), &[], false).unwrap()).unwrap();
    (launcher, endpoint)
}

/// What a test node process of run `run_id` (scene fingerprint 1) is told, with its token's
/// role and its wait for the launcher's `done`.
pub(crate) fn test_run(run_id: &str, token_role: &str, done_timeout: Duration) -> NodeRun {
    NodeRun {
        run_id: run_id.into(),
        expected: Expected {
            run_id: run_id.into(),
            scene_fingerprint: 1,
        },
        token_role: token_role.into(),
        token_index: 0,
        start_timeout: Duration::from_secs(20),
        idle_timeout: Duration::from_secs(20),
        departure_grace: Duration::from_secs(2),
        supervised: false,
        resume: false,
        done_timeout,
    }
}

/// Subdomain `index`'s final displacement `u` at `iteration` in run `run_id` (scene
/// fingerprint 1).
pub(crate) fn displacement(run_id: &str, index: u32, iteration: u32, u: Field) -> Message {
    Message {
        envelope: Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: run_id.into(),
            scene_fingerprint: 1,
            iteration,
            stage: Stage::Final,
            sender: NodeId {
                role: Role::Subdomain,
                index,
            },
        },
        payload: Payload::Displacement { subdomain: index, u },
    }
}

/// Waits (up to 20 s) for liveliness token `key` to appear among `changes`.
pub(crate) fn wait_token(changes: &mpsc::Receiver<(String, bool)>, key: &str) {
    loop {
        let (k, up) = changes.recv_timeout(Duration::from_secs(20)).expect("the node's token");
        if k == key && up {
            break;
        }
    }
}
