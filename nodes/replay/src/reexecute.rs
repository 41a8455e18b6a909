//! Re-executing one node of a recorded run (`glissade replay --node <role>:<id>`): the node is
//! rebuilt from the recording's scene (its text and the command-line overrides the run applied),
//! fed every recorded message it subscribes to, in recorded
//! order, and its outputs are compared byte for byte with the messages the recording holds from
//! it, topic by topic. A mismatch names the first differing recorded message (key, iteration,
//! stage) and the first differing field in it.

use crate::{run_messages, Skipped};
use glissade_bus::{take_when_ready, Node, NodeError, RunContext};
use glissade_deploy::{build_nodes, BuildError, Plan, Selection};
use glissade_messages::{encode, key_matches, DecodeError, Message, NodeId, Role};
use glissade_recorder::{Recording, THINNED_FIELDS};
use glissade_scene::{load_with, SceneError};
use glissade_subdomain::{LinearStageRecord, LinearStageRecords};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Why a node could not be re-executed (a difference from the recording is not an error: it is
/// [`Reexecution::mismatch`]).
#[derive(Debug, thiserror::Error)]
pub enum ReexecuteError {
    /// `--node` is not `<role>:<index>`.
    #[error("--node `{text}`: {problem}")]
    NodeArgument { text: String, problem: String },
    /// The recording cannot serve a re-execution (unfinished, thinned, without a scene…).
    #[error("{path}: {problem}")]
    Recording { path: String, problem: String },
    /// The cause is part of the message (not a separate `source`, so a chain prints it once).
    #[error("{path}: {what}: {cause}")]
    Decode {
        path: String,
        what: String,
        cause: DecodeError,
    },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Build(#[from] BuildError),
    /// The node failed on its start or on a recorded input.
    #[error("node {node} failed on {what}: {cause}")]
    Node {
        node: NodeId,
        what: String,
        cause: NodeError,
    },
}

/// The first difference between a re-executed node's outputs and the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct Mismatch {
    /// Position of the recorded message in the recording (file order), when there is one.
    pub index: Option<usize>,
    pub topic: String,
    pub iteration: u32,
    pub stage: String,
    /// What differs: a field path with both values, or a missing or extra message.
    pub detail: String,
}

impl Mismatch {
    /// A difference on `topic` about message `msg` (the recorded one at `index`, or an extra one).
    fn about(index: Option<usize>, topic: &str, msg: &Message, detail: String) -> Self {
        Self {
            index,
            topic: topic.to_string(),
            iteration: msg.envelope.iteration,
            stage: format!("{:?}", msg.envelope.stage),
            detail,
        }
    }
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.index {
            Some(i) => write!(f, "recorded message #{i} "),
            None => write!(f, "message "),
        }?;
        write!(
            f,
            "`{}` (iteration {}, stage {}): {}",
            self.topic, self.iteration, self.stage, self.detail
        )
    }
}

/// What a re-execution found.
#[derive(Debug, Clone, PartialEq)]
pub struct Reexecution {
    pub node: NodeId,
    /// Recorded messages fed to the node.
    pub inputs: usize,
    /// Messages the node published.
    pub outputs: usize,
    /// Messages the recording holds from the node.
    pub recorded_outputs: usize,
    /// Output bytes compared.
    pub bytes: u64,
    /// None: every output is bit-identical to the recorded one.
    pub mismatch: Option<Mismatch>,
    /// A subdomain node's linear stages, iteration by iteration (PGD basis sizes among them), from
    /// the `linear_stage_stats` it published; untimed (seconds 0: no bus ran it).
    pub linear_stages: Vec<LinearStageRecord>,
    /// Recorded messages that are not the run's, not fed to the node.
    pub skipped: Skipped,
}

/// Parses `role:id` (`subdomain:3`, `interface:0`, `coarse:0`).
pub fn parse_node(text: &str) -> Result<NodeId, ReexecuteError> {
    let bad = |problem: String| ReexecuteError::NodeArgument {
        text: text.to_string(),
        problem,
    };
    let (role, id) = text
        .split_once(':')
        .ok_or_else(|| bad("expected <role>:<id>, e.g. subdomain:0".into()))?;
    let role = match role {
        "subdomain" => Role::Subdomain,
        "interface" => Role::Interface,
        "coarse" => Role::Coarse,
        other => return Err(bad(format!("unknown role `{other}` (subdomain, interface or coarse)"))),
    };
    let index = id
        .parse::<u32>()
        .map_err(|_| bad(format!("`{id}` is not a node index")))?;
    Ok(NodeId { role, index })
}

/// The nodes whose outputs a recording holds (sender of at least one message), in order.
pub fn recorded_nodes(recording: &Recording) -> Result<Vec<NodeId>, ReexecuteError> {
    let mut nodes = std::collections::BTreeSet::new();
    let mut skipped = Skipped::default();
    for (_, _, msg) in run_messages(recording, &mut skipped) {
        if matches!(
            msg.envelope.sender.role,
            Role::Subdomain | Role::Interface | Role::Coarse
        ) {
            nodes.insert(msg.envelope.sender);
        }
    }
    Ok(nodes.into_iter().collect())
}

/// Re-executes node `id` of `recording` and compares its outputs with the recorded ones.
pub fn reexecute(recording: &Recording, id: NodeId) -> Result<Reexecution, ReexecuteError> {
    let path = recording.path().display().to_string();
    let refuse = |problem: String| ReexecuteError::Recording {
        path: path.clone(),
        problem,
    };
    if !recording.is_finished() {
        return Err(refuse(format!(
            "the recording is not finished ({}): re-execution needs every input of the run",
            recording.truncated().unwrap_or("no summary section")
        )));
    }
    if let Some(why) = recording.damaged() {
        return Err(refuse(format!(
            "{why}: re-execution needs every input of the run, unchanged"
        )));
    }
    let text = recording
        .scene_text()
        .ok_or_else(|| refuse("the recording holds no scene".into()))?;
    let overrides = recording
        .scene_overrides()
        .ok_or_else(|| refuse("the recording holds no command-line overrides (attachment overrides.json)".into()))?;
    // The scene as written with the run's command-line overrides: the model the run solved.
    let scene = load_with(text, &format!("{path} (scene.toml)"), overrides)?;
    if scene.fingerprint != recording.scene_fingerprint() {
        return Err(refuse(format!(
            "the recorded scene's fingerprint {:016x} differs from the recording's {:016x}",
            scene.fingerprint,
            recording.scene_fingerprint()
        )));
    }
    let meta = recording.metadata();
    if let Some(topics) = meta.get("topics").filter(|t| t.as_str() != "**") {
        return Err(refuse(format!("the recording keeps only the topics `{topics}`; re-execution needs every message of the run (recording.topics = [\"**\"])")));
    }
    let thinning: u32 = match meta.get("full_fields_every") {
        Some(k) => k
            .parse::<u32>()
            .map_err(|_| refuse(format!("metadata full_fields_every = `{k}` is not a number")))?,
        None => 1,
    };
    let model = Arc::new(scene.model.clone());
    let ctx = RunContext {
        run_id: recording.run_id().to_string(),
        scene_fingerprint: scene.fingerprint,
    };
    let plan = Plan::new(&model).with_scene(&scene);
    let interior = recording.channels().iter().any(|c| c.topic.ends_with("/displacement"));
    let selection = match id.role {
        Role::Subdomain => Selection {
            subdomains: vec![id.index],
            interface: false,
            coarse: false,
        },
        Role::Interface => Selection {
            subdomains: vec![],
            interface: true,
            coarse: false,
        },
        Role::Coarse if id.index == 0 && plan.coarse => Selection {
            subdomains: vec![],
            interface: false,
            coarse: true,
        },
        _ => return Err(refuse(format!("the run has no node {id}"))),
    };
    // Every interface node is built when one is asked for: keep the one asked for.
    let mut node: Box<dyn Node> = build_nodes(&model, &ctx, interior, &plan, &selection)?
        .into_iter()
        .find(|n| n.id() == id)
        .ok_or_else(|| refuse(format!("the run has no node {id}")))?;
    let subs = node.subscriptions();
    if thinning > 1 {
        let needs: Vec<&str> = THINNED_FIELDS
            .iter()
            .copied()
            .filter(|f| {
                subs.iter()
                    .any(|s| s.ends_with(&format!("/{f}")) || s.contains(&format!("/{f}/")))
            })
            .collect();
        if !needs.is_empty() {
            return Err(refuse(format!(
                "the recording keeps {} only every {thinning} iterations (recording.full_fields_every = {thinning}); node {id} needs every one of them: record with full_fields_every = 1 (`glissade run --record full`)",
                needs.join(" and ")
            )));
        }
    }

    // The recording in file order: inputs of the node, and its own outputs per topic.
    let mut inputs: Vec<(usize, Message)> = Vec::new();
    let mut recorded: BTreeMap<String, Vec<(usize, Vec<u8>, Message)>> = BTreeMap::new();
    let mut recorded_outputs = 0;
    let mut skipped = Skipped::default();
    // A node's status is no output of its algorithm (repeats are passed over by `run_messages`).
    for (i, m, msg) in run_messages(recording, &mut skipped) {
        if msg.envelope.sender == id && !matches!(msg.payload, glissade_messages::Payload::NodeStatus(_)) {
            recorded_outputs += 1;
            recorded
                .entry(m.topic.to_string())
                .or_default()
                .push((i, m.data.to_vec(), msg.clone()));
        }
        if subs.iter().any(|s| key_matches(s, m.topic)) {
            inputs.push((i, msg));
        }
    }

    // Drive the node.
    let mut produced: BTreeMap<String, Vec<Message>> = BTreeMap::new();
    let mut outputs = 0;
    let mut stages = LinearStageRecords::default();
    let mut keep = |out: Vec<Message>| {
        for o in out {
            outputs += 1;
            stages.observe(&o);
            produced.entry(o.topic()).or_default().push(o);
        }
    };
    keep(node.start().map_err(|cause| ReexecuteError::Node {
        node: id,
        what: "its start".into(),
        cause,
    })?);
    keep(std::iter::from_fn(|| node.next_output()).collect());
    // The file is in the order the recorder heard the messages, which need not be one the node
    // could have seen: a message the node refuses as not yet its turn is handed again once it
    // has taken another ([`take_when_ready`]).
    let failed = |i: usize, msg: &Message, cause| ReexecuteError::Node {
        node: id,
        what: format!(
            "recorded message #{i} `{}` (iteration {}, stage {:?})",
            msg.topic(),
            msg.envelope.iteration,
            msg.envelope.stage
        ),
        cause,
    };
    let refused = take_when_ready(&inputs, |&(i, msg)| match node.handle(msg) {
        Ok(out) => {
            keep(out);
            keep(std::iter::from_fn(|| node.next_output()).collect());
            Ok(None)
        }
        Err(cause) if cause.is_rejection() => Ok(Some(cause)),
        Err(cause) => Err(failed(*i, msg, cause)),
    })?;
    // Refused to the end: the node's reason for the earliest such message.
    if let Some(((i, msg), cause)) = refused.into_iter().min_by_key(|((i, _), _)| *i) {
        return Err(failed(*i, msg, cause));
    }

    // Compare, topic by topic, in order; keep the mismatch of the earliest recorded message.
    let mut first: Option<Mismatch> = None;
    let mut bytes = 0u64;
    let empty = Vec::new();
    let topics: std::collections::BTreeSet<&String> = recorded.keys().chain(produced.keys()).collect();
    for topic in topics {
        let rec = recorded.get(topic).unwrap_or(&empty);
        let got = produced.get(topic).map(Vec::as_slice).unwrap_or(&[]);
        for (k, (index, data, rmsg)) in rec.iter().enumerate() {
            let Some(g) = got.get(k) else {
                note(
                    Mismatch::about(
                        Some(*index),
                        topic,
                        rmsg,
                        format!(
                            "the re-executed node published only {} message(s) on this key, the recording has {}",
                            got.len(),
                            rec.len()
                        ),
                    ),
                    &mut first,
                );
                break;
            };
            let g_bytes = encode(g);
            bytes += g_bytes.len() as u64;
            if &g_bytes != data {
                note(
                    Mismatch::about(Some(*index), topic, rmsg, field_difference(rmsg, g, data, &g_bytes)),
                    &mut first,
                );
                break;
            }
        }
        if got.len() > rec.len() {
            let g = &got[rec.len()];
            note(
                Mismatch::about(
                    None,
                    topic,
                    g,
                    format!(
                        "the re-executed node published {} message(s) on this key, the recording has {}",
                        got.len(),
                        rec.len()
                    ),
                ),
                &mut first,
            );
        }
    }
    Ok(Reexecution {
        node: id,
        inputs: inputs.len(),
        outputs,
        recorded_outputs,
        bytes,
        mismatch: first,
        linear_stages: stages.records(&[]),
        skipped,
    })
}

/// Keeps `m` if it is about an earlier recorded message than `first`.
fn note(m: Mismatch, first: &mut Option<Mismatch>) {
    let earlier = match (&first, m.index) {
        (None, _) => true,
        (Some(f), Some(i)) => f.index.is_none_or(|j| i < j),
        (Some(_), None) => false,
    };
    if earlier {
        *first = Some(m);
    }
}

/// Names the first field where `replayed` differs from `recorded` (a path such as
/// `payload.BoundaryState.w[row 3, column 7]` with both values), or the first differing byte.
fn field_difference(recorded: &Message, replayed: &Message, recorded_bytes: &[u8], replayed_bytes: &[u8]) -> String {
    let as_value = |m: &Message| {
        serde_json::json!({
            "envelope": serde_json::to_value(&m.envelope).unwrap_or_default(),
            "payload": serde_json::to_value(&m.payload).unwrap_or_default(),
        })
    };
    if let Some(d) = value_difference(&as_value(recorded), &as_value(replayed), "") {
        return d;
    }
    let at = recorded_bytes
        .iter()
        .zip(replayed_bytes)
        .position(|(a, b)| a != b)
        .unwrap_or(recorded_bytes.len().min(replayed_bytes.len()));
    format!(
        "byte {at} differs ({} recorded bytes, {} re-executed)",
        recorded_bytes.len(),
        replayed_bytes.len()
    )
}

fn value_difference(a: &serde_json::Value, b: &serde_json::Value, path: &str) -> Option<String> {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            // A Field: name the entry by (row, column).
            if let (Some(Value::Array(dx)), Some(Value::Array(dy)), Some(rows)) =
                (x.get("data"), y.get("data"), x.get("rows").and_then(Value::as_u64))
            {
                if x.get("rows") == y.get("rows") && x.get("cols") == y.get("cols") && dx.len() == dy.len() {
                    let rows = rows.max(1) as usize;
                    return dx.iter().zip(dy).enumerate().find_map(|(k, (u, v))| {
                        (!same_number(u, v)).then(|| {
                            format!(
                                "field {path}[row {}, column {}]: recorded {u}, re-executed {v}",
                                k % rows,
                                k / rows
                            )
                        })
                    });
                }
            }
            let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
            keys.into_iter().find_map(|k| {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                match (x.get(k), y.get(k)) {
                    (Some(u), Some(v)) => value_difference(u, v, &p),
                    (u, v) => Some(format!(
                        "field {p}: recorded {}, re-executed {}",
                        u.map_or("absent".into(), Value::to_string),
                        v.map_or("absent".into(), Value::to_string)
                    )),
                }
            })
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(k, (u, v))| value_difference(u, v, &format!("{path}[{k}]"))),
        _ if same_number(a, b) => None,
        _ => Some(format!("field {path}: recorded {}, re-executed {}", short(a), short(b))),
    }
}

/// Equal values; numbers compared bit for bit.
fn same_number(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) if a.is_f64() || b.is_f64() => x.to_bits() == y.to_bits(),
        _ => a == b,
    }
}

fn short(v: &serde_json::Value) -> String {
    let s = v.to_string();
    if s.len() > 80 {
        format!("{}…", &s[..s.char_indices().nth(77).map_or(s.len(), |(i, _)| i)])
    } else {
        s
    }
}

/// (iteration, subdomain, basis size) of a PGD subdomain after its linear stage.
pub type BasisSize = (u32, u32, usize);

/// The PGD basis sizes of a recorded run, (iteration, subdomain, basis size after the linear
/// stage): the row count of the time functions of each `boundary_modes` message, the state a PGD
/// subdomain sends in mode form (never thinned by `full_fields_every`). None when no subdomain of
/// the run uses the PGD stage.
pub fn recorded_basis_sizes(recording: &Recording) -> Result<Option<Vec<BasisSize>>, ReexecuteError> {
    let mut sizes = Vec::new();
    for m in recording.messages() {
        if glissade_messages::topic_field(m.topic) != Some("boundary_modes") {
            continue;
        }
        let msg = recording
            .decode(&m)
            .map_err(|source| decode_error(recording, m.topic, source))?;
        if let glissade_messages::Payload::BoundaryModes { subdomain, lambda, .. } = &msg.payload {
            sizes.push((msg.envelope.iteration, *subdomain, lambda.rows()));
        }
    }
    if sizes.is_empty() {
        return Ok(None);
    }
    sizes.sort_unstable();
    Ok(Some(sizes))
}

/// The linear-stage counters of a recorded run, (iteration, counters) sorted by (iteration,
/// subdomain): every subdomain's `linear_stage_stats` messages ([`glissade_messages::topic::linear_stage_stats`]).
pub fn recorded_linear_stage_stats(
    recording: &Recording,
) -> Result<Vec<(u32, glissade_messages::LinearStageStats)>, ReexecuteError> {
    let key = glissade_messages::topic::linear_stage_stats(recording.run_id());
    let mut stats = Vec::new();
    for m in recording.messages() {
        if !key_matches(&key, m.topic) {
            continue;
        }
        let msg = recording
            .decode(&m)
            .map_err(|source| decode_error(recording, m.topic, source))?;
        if let glissade_messages::Payload::LinearStageStats(s) = msg.payload {
            stats.push((msg.envelope.iteration, s));
        }
    }
    stats.sort_by_key(|(it, s)| (*it, s.subdomain));
    Ok(stats)
}

/// A recorded message on `topic` that does not decode.
fn decode_error(recording: &Recording, topic: &str, source: DecodeError) -> ReexecuteError {
    ReexecuteError::Decode {
        path: recording.path().display().to_string(),
        what: format!("message on `{topic}`"),
        cause: source,
    }
}
