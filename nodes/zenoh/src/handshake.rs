//! The start and end handshakes between the launcher and the node processes (crate doc): the
//! scene served by the launcher and fetched by the nodes, and the launcher's `start`, `stop` and
//! `done`.

use crate::error::zerr;
use crate::publish::put_bytes;
use crate::TransportError;
use glissade_messages::{topic, DecodeError};
use std::time::{Duration, Instant};
use zenoh::{Session, Wait};

/// Fetches a run's scene message from the launcher's queryable (bytes), waiting up to `timeout`.
pub fn fetch_scene(session: &Session, run_id: &str, timeout: Duration) -> Result<Vec<u8>, TransportError> {
    let deadline = Instant::now() + timeout;
    loop {
        let replies = session
            .get(topic::scene(run_id))
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

/// The launcher's side: serves the scene to the node processes' queries. Returns the queryable
/// (keep it alive for the whole run).
pub fn serve_scene(
    session: &Session,
    run_id: &str,
    scene_message: Vec<u8>,
) -> Result<zenoh::query::Queryable<()>, TransportError> {
    let key = topic::scene(run_id);
    let reply_key = key.clone();
    session
        .declare_queryable(key.as_str())
        .callback(move |query| {
            let _ = query.reply(reply_key.as_str(), scene_message.clone()).wait();
        })
        .wait()
        .map_err(|e| zerr("scene queryable", e))
}

/// Tells every node of a run to start (once all are ready).
pub fn publish_start(session: &Session, run_id: &str) -> Result<(), TransportError> {
    put_bytes(session, &topic::start(run_id), Vec::new())
}

/// Tells every node of a run that the launcher holds the run's results: they may leave.
pub fn publish_done(session: &Session, run_id: &str) -> Result<(), TransportError> {
    put_bytes(session, &topic::done(run_id), Vec::new())
}

/// Tells every node of a run to stop now, with the reason.
pub fn publish_stop(session: &Session, run_id: &str, reason: &str) -> Result<(), TransportError> {
    put_bytes(session, &topic::stop(run_id), reason.as_bytes().to_vec())
}

/// Decodes the envelope only, to learn the scene fingerprint of a scene message.
pub fn scene_fingerprint_of(bytes: &[u8], run_id: &str) -> Result<u64, DecodeError> {
    glissade_messages::peek_envelope(bytes, run_id).map(|e| e.scene_fingerprint)
}
