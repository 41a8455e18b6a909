//! Scene settings given on the command line ([`Overrides`]): they travel with the scene text
//! ([`Payload::Scene`](crate::Payload::Scene)) and are recorded with it, so that every process and
//! every reader of a recording rebuilds the model of the run from the text as written and these.
//! The scene crate (`glissade_scene`) applies and validates them.

use serde::{Deserialize, Serialize};

/// Scene settings given on the command line: each `Some` replaces the scene file's value.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[serde(deny_unknown_fields)]
pub struct Overrides {
    /// `[solver] accuracy` (`--accuracy`).
    pub accuracy: Option<f64>,
    /// `[solver] tolerance` (`--tolerance`).
    pub tolerance: Option<f64>,
    /// `[solver] max_iterations` (`--max-iterations`).
    pub max_iterations: Option<usize>,
    /// The recording (`--record`, `--no-record`).
    pub record: Option<RecordOverride>,
}

/// What `--record` / `--no-record` ask of the recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[serde(rename_all = "lowercase")]
pub enum RecordOverride {
    /// No recording (`[recording] enabled = false`).
    Off,
    /// Every message, full fields at every iteration (`enabled = true`, `topics = ["**"]`,
    /// `full_fields_every = 1`).
    Full,
}

/// `accuracy = 0.0001, max_iterations = 7, record = full` (the keys given), or `none`.
impl std::fmt::Display for Overrides {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut given = Vec::new();
        if let Some(a) = self.accuracy {
            given.push(format!("accuracy = {a}"));
        }
        if let Some(t) = self.tolerance {
            given.push(format!("tolerance = {t}"));
        }
        if let Some(m) = self.max_iterations {
            given.push(format!("max_iterations = {m}"));
        }
        match self.record {
            Some(RecordOverride::Off) => given.push("record = off".to_string()),
            Some(RecordOverride::Full) => given.push("record = full".to_string()),
            None => {}
        }
        if given.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&given.join(", "))
        }
    }
}

impl Overrides {
    /// Nothing is overridden: the scene is run as written.
    pub fn is_none(&self) -> bool {
        *self == Overrides::default()
    }

    /// These overrides with `later`'s on top (each `Some` of `later` wins).
    pub fn then(self, later: Overrides) -> Overrides {
        Overrides {
            accuracy: later.accuracy.or(self.accuracy),
            tolerance: later.tolerance.or(self.tolerance),
            max_iterations: later.max_iterations.or(self.max_iterations),
            record: later.record.or(self.record),
        }
    }
}
