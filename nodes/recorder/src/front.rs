//! The one front-end of a run's recording, whatever the run mode: what reaches it is either a
//! message the in-process bus delivered ([`RunRecorder::delivered`]: one of the run's own nodes',
//! encoded as on the wire) or the bytes a recorder process heard on the run's keys
//! ([`RunRecorder::heard`]: counted when they carry the run's envelope, kept only when they decode
//! as a message of this run and scene, on its sender's own key, of a kind that sender sends).
//! The first failed write is kept and stops the recording; the caller stops the run on it.

use crate::{Recorder, RecorderError, RecorderOptions, RecordingStats, RunInfo};
use glissade_messages::{decode, encode, peek_envelope, Expected, Message};
use std::path::Path;

/// A run's recording as the run feeds it.
pub struct RunRecorder {
    recorder: Recorder,
    expected: Expected,
    /// Messages with the run's envelope that reached the recorder.
    seen: u64,
    /// Of those, the ones that were not the run's, and the first of them (key and why).
    refused: u64,
    first_refused: Option<String>,
    /// The first failed write: nothing is written after it.
    failure: Option<RecorderError>,
}

/// What a finished recording holds and what it left out.
#[derive(Debug, Clone, PartialEq)]
pub struct Finished {
    pub stats: RecordingStats,
    /// Messages on the run's keys, with its envelope, that were not the run's (not recorded),
    /// and the first of them: "on <key>: <why>".
    pub refused: u64,
    pub first_refused: Option<String>,
}

impl RunRecorder {
    /// Creates the file (it exists and holds the scene when this returns).
    pub fn create(path: &Path, run: &RunInfo, options: &RecorderOptions) -> Result<Self, RecorderError> {
        Ok(Self {
            recorder: Recorder::create(path, run, options)?,
            expected: Expected {
                run_id: run.run_id.clone(),
                scene_fingerprint: run.scene_fingerprint,
            },
            seen: 0,
            refused: 0,
            first_refused: None,
            failure: None,
        })
    }

    pub fn path(&self) -> &Path {
        self.recorder.path()
    }

    /// Records `m`, a message of the run's own nodes delivered by the in-process bus, on the key
    /// it would have over Zenoh, logged now.
    pub fn delivered(&mut self, m: &Message) {
        self.seen += 1;
        let topic = m.topic();
        if self.failure.is_none() && self.recorder.leaves_out(&topic, &m.envelope).is_none() {
            let bytes = encode(m);
            let written = self.recorder.record(&topic, crate::log_time_now(), &bytes);
            self.keep_failure(written);
        }
    }

    /// Records `bytes`, heard on `key` at `log_time_ns`, if they are a message of the run: bytes
    /// without the run's envelope (control messages, another run's) are not counted; bytes with
    /// it that do not decode as this run's, or that their sender does not send on this key, are
    /// counted and refused.
    pub fn heard(&mut self, key: &str, bytes: &[u8], log_time_ns: u64) {
        let Ok(envelope) = peek_envelope(bytes, &self.expected.run_id) else {
            return;
        };
        self.seen += 1;
        if self.recorder.leaves_out(key, &envelope).is_some() {
            // Not written, so not decoded either: most of a thinned recording's bytes (full
            // fields of the iterations it leaves out) are only counted.
            return;
        }
        let refusal = match decode(bytes, &self.expected) {
            Ok(m) => m.not_from_its_sender(key),
            Err(e) => Some(e.to_string()),
        };
        match refusal {
            None if self.failure.is_none() => {
                let written = self.recorder.record(key, log_time_ns, bytes);
                self.keep_failure(written);
            }
            None => {}
            Some(why) => {
                self.refused += 1;
                self.first_refused.get_or_insert_with(|| format!("on {key}: {why}"));
            }
        }
    }

    fn keep_failure<T>(&mut self, written: Result<T, RecorderError>) {
        if let Err(e) = written {
            self.failure.get_or_insert(e);
        }
    }

    /// Messages with the run's envelope that reached the recorder (refused ones included).
    pub fn seen(&self) -> u64 {
        self.seen
    }

    /// The first failed write, if any: the recording stopped there (its file is readable up to
    /// its last complete chunk).
    pub fn failure(&self) -> Option<&RecorderError> {
        self.failure.as_ref()
    }

    /// Appends what is recorded so far to the file, so that a reader of the file sees it.
    pub fn flush(&mut self) -> Result<(), RecorderError> {
        self.recorder.flush()
    }

    /// Finalises the file; a write that failed earlier is the error.
    pub fn finish(mut self) -> Result<Finished, RecorderError> {
        if let Some(e) = self.failure.take() {
            drop(self.recorder.finish());
            return Err(e);
        }
        Ok(Finished {
            stats: self.recorder.finish()?,
            refused: self.refused,
            first_refused: self.first_refused,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Recording;
    use glissade_messages::{Envelope, LinearStageStats, NodeId, Overrides, Payload, Role, Stage, SCHEMA_VERSION};

    fn info() -> RunInfo {
        RunInfo {
            run_id: "front".into(),
            scene_name: "s".into(),
            scene_fingerprint: 7,
            scene_text: "[scene]\n".into(),
            scene_overrides: Overrides::default(),
            software: "test".into(),
        }
    }

    /// Subdomain 0's linear-stage counters of `iteration`.
    fn stats(run_id: &str, fingerprint: u64, iteration: u32) -> Message {
        Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: run_id.into(),
                scene_fingerprint: fingerprint,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: 0,
                },
                iteration,
                stage: Stage::Linear,
            },
            payload: Payload::LinearStageStats(LinearStageStats::default()),
        }
    }

    /// What the bus delivers is recorded; what is heard is recorded only when it is the run's:
    /// another run's bytes are not counted, another scene's and a message on another sender's key
    /// are counted and refused, the first named.
    #[test]
    fn heard_bytes_are_kept_only_when_they_are_the_runs() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("front.mcap");
        let mut rec = RunRecorder::create(&path, &info(), &RecorderOptions::default()).unwrap();
        let own = stats("front", 7, 1);
        rec.delivered(&own);
        let bytes = encode(&stats("front", 7, 2));
        rec.heard(&stats("front", 7, 2).topic(), &bytes, 1);
        rec.heard(&own.topic(), &encode(&stats("other", 7, 3)), 2);
        rec.heard(&own.topic(), &encode(&stats("front", 8, 4)), 3);
        let wrong_key = own.topic().replace("subdomain/0", "subdomain/1");
        rec.heard(&wrong_key, &bytes, 4);
        assert_eq!(rec.seen(), 4, "the bus's one, the run's one and the two refused");
        let finished = rec.finish().unwrap();
        assert_eq!(finished.stats.messages, 2);
        assert_eq!(finished.refused, 2);
        let first = finished.first_refused.unwrap();
        assert!(first.starts_with(&format!("on {}: ", own.topic())), "{first}");
        let recording = Recording::open(&path).unwrap();
        let iterations: Vec<u32> = recording
            .messages()
            .map(|m| peek_envelope(&m.data, "front").unwrap().iteration)
            .collect();
        assert_eq!(iterations, [1, 2]);
    }
}
