//! The recorder's log protocol: a replacement node process asks the recorder for the messages
//! of the run it needs to resume ([`fetch_log`]); the recorder answers with them encoded as one
//! log ([`encode_log`]).

use crate::error::zerr;
use crate::TransportError;
use glissade_messages::topic;
use std::time::Duration;
use zenoh::{Session, Wait};

/// Encodes a log: per message its key length (u32 LE), key, length (u64 LE) and bytes.
pub fn encode_log(messages: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::with_capacity(messages.iter().map(|(k, b)| 12 + k.len() + b.len()).sum());
    for (k, b) in messages {
        out.extend_from_slice(&(k.len() as u32).to_le_bytes());
        out.extend_from_slice(k.as_bytes());
        out.extend_from_slice(&(b.len() as u64).to_le_bytes());
        out.extend_from_slice(b);
    }
    out
}

/// Decodes [`encode_log`]'s bytes; a truncated or malformed log is an error naming the offset.
pub fn decode_log(bytes: &[u8]) -> Result<Vec<(String, Vec<u8>)>, TransportError> {
    let bad = |at: usize, what: &str| TransportError::Protocol(format!("malformed recorder log at byte {at}: {what}"));
    let mut out = Vec::new();
    let mut at = 0;
    let take = |at: &mut usize, n: usize, what: &str| -> Result<&[u8], TransportError> {
        let end = at
            .checked_add(n)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| bad(*at, what))?;
        let s = &bytes[*at..end];
        *at = end;
        Ok(s)
    };
    while at < bytes.len() {
        let n = u32::from_le_bytes(
            take(&mut at, 4, "key length")?
                .try_into()
                .expect("take returns the 4 bytes asked for"),
        ) as usize;
        let key = std::str::from_utf8(take(&mut at, n, "key")?)
            .map_err(|_| bad(at, "key is not UTF-8"))?
            .to_string();
        let n = u64::from_le_bytes(
            take(&mut at, 8, "message length")?
                .try_into()
                .expect("take returns the 8 bytes asked for"),
        );
        let n = usize::try_from(n).map_err(|_| bad(at, "message length"))?;
        out.push((key, take(&mut at, n, "message")?.to_vec()));
    }
    Ok(out)
}

/// Asks the recorder of run `run_id` for every recorded message whose key matches one of
/// `patterns`, in recorded order (what a replacement node process needs to resume).
pub fn fetch_log(
    session: &Session,
    run_id: &str,
    patterns: &[String],
    timeout: Duration,
) -> Result<Vec<(String, Vec<u8>)>, TransportError> {
    let replies = session
        .get(topic::log(run_id))
        .payload(patterns.join("\n"))
        .timeout(timeout)
        .wait()
        .map_err(|e| zerr("query the recorder's log", e))?;
    match replies.recv_timeout(timeout) {
        Ok(Some(reply)) => match reply.result() {
            Ok(sample) => decode_log(&sample.payload().to_bytes()),
            Err(e) => Err(TransportError::Protocol(format!(
                "the recorder cannot serve its log: {}",
                String::from_utf8_lossy(&e.payload().to_bytes())
            ))),
        },
        _ => Err(TransportError::Protocol(format!(
            "no answer from the recorder's log within {timeout:?} (is the run recorded?)"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recorder's log survives its encoding, and a truncated one is refused with the offset.
    #[test]
    fn log_round_trip_and_truncation() {
        let log = vec![
            ("glissade/r/subdomain/0/boundary_state".to_string(), vec![1u8, 2, 3]),
            ("glissade/r/interface/0/decision".to_string(), Vec::new()),
        ];
        let bytes = encode_log(&log);
        assert_eq!(decode_log(&bytes).unwrap(), log);
        assert_eq!(decode_log(&[]).unwrap(), Vec::new());
        for cut in 1..bytes.len() {
            let e = decode_log(&bytes[..cut]);
            // A cut between two entries is a shorter valid log; anywhere else, an error.
            if cut != 4 + log[0].0.len() + 8 + 3 {
                let msg = e.expect_err("truncated").to_string();
                assert!(msg.contains("malformed recorder log at byte"), "{msg}");
            }
        }
    }
}
