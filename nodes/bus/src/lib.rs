//! Nodes and buses. A [`Node`] is a sans-IO state machine: it consumes messages and returns the
//! messages it publishes; it never blocks, reads a clock or touches a socket. A bus moves
//! messages between nodes: [`InProcessBus`] runs every node in one process, delivering in rounds
//! (all messages of a round are handled, nodes in parallel on a rayon pool, outputs collected in
//! node order), so a run is deterministic whatever the thread count.
//!
//! The bus is what times a run's work, when asked: each node's handling of what it is delivered,
//! summed per (role, message field) ([`HandleTime`]) or per (node, iteration, message field)
//! ([`IterationTime`]). A node counts its own work (e.g. flops) and says so in messages.

use glissade_messages::{topic_field, Envelope, Field, Message, NodeId, Payload, Role, Routes, Stage, SCHEMA_VERSION};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

pub mod convert;

/// What every node of a run shares: its run id and the scene fingerprint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunContext {
    pub run_id: String,
    pub scene_fingerprint: u64,
}

impl RunContext {
    pub fn envelope(&self, sender: NodeId, iteration: u32, stage: Stage) -> Envelope {
        Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: self.run_id.clone(),
            scene_fingerprint: self.scene_fingerprint,
            iteration,
            stage,
            sender,
        }
    }
}

/// What a [`NodeError`] means for the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The node could not go on: a value became non-finite, an operator could not be built, a
    /// received field holds NaN or ∞. The run must stop with this error.
    Failed,
    /// The node refused one message and its state is exactly what it was before: a message of
    /// another iteration or stage, a duplicate, a wrong sender or recipient, a field of the wrong
    /// shape. A transport that may carry foreign or damaged messages logs it and goes on; the
    /// in-process bus, where every message comes from a node of the run, stops on it (a bug).
    Rejected,
}

/// A failure inside a node, or a message it refused, named by the node.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{node}: {detail}")]
pub struct NodeError {
    pub node: NodeId,
    pub detail: String,
    pub kind: ErrorKind,
}

impl NodeError {
    /// A failure: the run cannot go on.
    pub fn new(node: NodeId, detail: impl std::fmt::Display) -> Self {
        Self {
            node,
            detail: detail.to_string(),
            kind: ErrorKind::Failed,
        }
    }

    /// A refused message: the node's state is unchanged and the run may go on without it.
    pub fn rejected(node: NodeId, detail: impl std::fmt::Display) -> Self {
        Self {
            node,
            detail: detail.to_string(),
            kind: ErrorKind::Rejected,
        }
    }

    /// The node refused one message and is unchanged ([`ErrorKind::Rejected`]).
    pub fn is_rejection(&self) -> bool {
        self.kind == ErrorKind::Rejected
    }
}

/// A participant of a run.
pub trait Node: Send {
    fn id(&self) -> NodeId;
    /// Key expressions this node consumes.
    fn subscriptions(&self) -> Vec<String>;
    /// Messages published when the run starts.
    fn start(&mut self) -> Result<Vec<Message>, NodeError>;
    /// Consumes one message and returns the messages it publishes in reply.
    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError>;
    /// The next of the messages this node publishes after those its last `start` or `handle`
    /// returned, or None when there is none left. A bus asks for them one at a time, after it has
    /// published the ones before (and given them back, [`Node::recycle`]), so that a node's large
    /// final outputs can be written one after the other into the same memory instead of all
    /// existing at once. By default a node has none.
    fn next_output(&mut self) -> Option<Message> {
        None
    }
    /// The node has nothing more to do.
    fn is_finished(&self) -> bool;
    /// The messages this node waits for now, any one of which moves it on (a message it would
    /// take): what a run that stopped moving reports, so that the one lost can be found and its
    /// sender named. Empty when the node is finished or waits for nothing.
    fn awaits(&self) -> Vec<glissade_messages::Awaited> {
        Vec::new()
    }
    /// Takes back a message this node published, once the bus has delivered it (and no longer
    /// needs it), so that the node can reuse its field buffers ([`convert::FieldPool`]). A bus
    /// may not return every message; by default the message is dropped.
    fn recycle(&mut self, msg: Message) {
        drop(msg);
    }
    /// From now on the node writes its large outgoing fields into blocks `lender` lends
    /// ([`convert::FieldPool::lend_from`]), for a transport that sends them without copying their
    /// values. By default a node's fields stay in memory of its own.
    fn lend_fields(&mut self, lender: std::sync::Arc<dyn glissade_messages::BlockLender>) {
        drop(lender);
    }
}

/// Errors of a bus run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BusError {
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error("no message in flight but nodes {0} are not finished (a node waits for an input that never came)")]
    Stalled(String),
}

/// Time nodes spent in [`Node::handle`], summed per kind of work: the receiving node's role and
/// the field of the message it handled (the last key-expression chunk before any destination,
/// e.g. `local_directions` for a subdomain's micro problem 1).
#[derive(Debug, Clone, PartialEq)]
pub struct HandleTime {
    pub role: Role,
    pub field: String,
    pub calls: u64,
    /// Summed over nodes: on several threads this is CPU time, not wall time.
    pub seconds: f64,
}

/// Time one node spent on the work of one iteration: its [`Node::handle`] calls on the messages of
/// that iteration (by their envelope) of one field, or its [`Node::start`] (iteration 0). The
/// linear stage of a subdomain in an iteration, e.g., is its handling of that iteration's
/// `local_directions` (micro problem 1), `macro_displacements` (micro problem 2) and
/// `anderson_step`, and at iteration 0 its start (micro problem 1 from ŝ = 0).
#[derive(Debug, Clone, PartialEq)]
pub struct IterationTime {
    pub node: NodeId,
    pub iteration: u32,
    /// The field of the messages handled (the last key-expression chunk before any destination),
    /// or None for the node's [`Node::start`].
    pub field: Option<String>,
    pub calls: u64,
    /// Wall time of the calls (each call runs on one thread).
    pub seconds: f64,
}

/// Handling times per (node index, iteration, field index into `fields`; None: start).
#[derive(Default)]
struct IterationTiming {
    fields: Vec<String>,
    times: BTreeMap<(usize, u32, Option<usize>), (u64, Duration)>,
}

impl IterationTiming {
    fn add(&mut self, node: usize, iteration: u32, field: Option<&str>, d: Duration) {
        let field = field.map(|f| match self.fields.iter().position(|g| g == f) {
            Some(k) => k,
            None => {
                self.fields.push(f.to_string());
                self.fields.len() - 1
            }
        });
        let e = self.times.entry((node, iteration, field)).or_default();
        e.0 += 1;
        e.1 += d;
    }
}

/// Runs nodes in one process.
pub struct InProcessBus {
    nodes: Vec<Box<dyn Node>>,
    routes: Routes,
    /// (role, field) → (calls, time), when timing is on.
    timing: Option<BTreeMap<(Role, String), (u64, Duration)>>,
    /// Per (node, iteration, field), when timing per iteration is on.
    iteration_timing: Option<IterationTiming>,
    /// Which delivered messages the caller keeps ([`Self::keeping`]) instead of their senders.
    keep: Option<Keep>,
    kept: Vec<Message>,
}

/// Which delivered messages an [`InProcessBus`]'s caller keeps.
type Keep = Box<dyn Fn(&Message) -> bool + Send>;

impl InProcessBus {
    pub fn new(nodes: Vec<Box<dyn Node>>) -> Self {
        let routes = Routes::new(nodes.iter().map(|n| n.subscriptions()).collect());
        Self {
            nodes,
            routes,
            timing: None,
            iteration_timing: None,
            keep: None,
            kept: Vec::new(),
        }
    }

    /// Hands the messages `keep` selects to the caller ([`Self::take_kept`]) once they are
    /// delivered, instead of back to their senders: a run's final fields, which the caller holds
    /// after the run, are then moved out of the bus rather than copied by the observer. When
    /// `observe` stops the run, the selected messages it saw in that round are kept undelivered.
    pub fn keeping(mut self, keep: impl Fn(&Message) -> bool + Send + 'static) -> Self {
        self.keep = Some(Box::new(keep));
        self
    }

    /// The messages kept so far ([`Self::keeping`]), in publication order.
    pub fn take_kept(&mut self) -> Vec<Message> {
        std::mem::take(&mut self.kept)
    }

    /// Whether the caller keeps `m` ([`Self::keeping`]).
    fn keeps(&self, m: &Message) -> bool {
        self.keep.as_ref().is_some_and(|k| k(m))
    }

    /// Times every [`Node::handle`] call (two clock reads per call; off by default).
    pub fn with_timing(mut self, on: bool) -> Self {
        self.timing = on.then(BTreeMap::new);
        self
    }

    /// Times every [`Node::start`] and [`Node::handle`] call per (node, iteration, field)
    /// ([`Self::iteration_times`]; two clock reads per call; off by default).
    pub fn with_iteration_timing(mut self, on: bool) -> Self {
        self.iteration_timing = on.then(IterationTiming::default);
        self
    }

    /// The handling times per (node, iteration, field) gathered so far (empty when timing per
    /// iteration is off), in node order (the order the bus was given them), then by iteration.
    pub fn iteration_times(&self) -> Vec<IterationTime> {
        let Some(t) = &self.iteration_timing else {
            return Vec::new();
        };
        t.times
            .iter()
            .map(|(&(node, iteration, field), &(calls, d))| IterationTime {
                node: self.nodes[node].id(),
                iteration,
                field: field.map(|k| t.fields[k].clone()),
                calls,
                seconds: d.as_secs_f64(),
            })
            .collect()
    }

    /// The handling times gathered so far (empty when timing is off), ordered by role and field.
    pub fn handle_times(&self) -> Vec<HandleTime> {
        self.timing
            .iter()
            .flatten()
            .map(|((role, field), (calls, d))| HandleTime {
                role: *role,
                field: field.clone(),
                calls: *calls,
                seconds: d.as_secs_f64(),
            })
            .collect()
    }

    /// Runs until no message is in flight. `observe` sees every message once, in publication order
    /// (the recorder's and the progress display's view); returning false from it aborts the run.
    /// A round's messages go back to their senders ([`Node::recycle`]) once it is handled.
    pub fn run(&mut self, mut observe: impl FnMut(&Message) -> bool) -> Result<(), BusError> {
        let ids: Vec<NodeId> = self.nodes.iter().map(|n| n.id()).collect();
        let mut queue = Vec::new();
        for (k, node) in self.nodes.iter_mut().enumerate() {
            let t0 = self.iteration_timing.is_some().then(Instant::now);
            queue.extend(node.start()?);
            queue.extend(std::iter::from_fn(|| node.next_output()));
            if let (Some(t0), Some(timing)) = (t0, &mut self.iteration_timing) {
                timing.add(k, 0, None, t0.elapsed());
            }
        }
        while !queue.is_empty() {
            if let Some(stop) = queue.iter().position(|m| !observe(m)) {
                // The messages observed before the stop, the stopping one included.
                let seen = queue.into_iter().take(stop + 1);
                let kept: Vec<Message> = seen.filter(|m| self.keeps(m)).collect();
                self.kept.extend(kept);
                return Ok(());
            }
            let topics: Vec<String> = queue.iter().map(Message::topic).collect();
            let deliveries = self.routes.deliveries(topics.iter().map(String::as_str));
            let queue_ref = &queue;
            let timed = self.timing.is_some() || self.iteration_timing.is_some();
            type Timed = Vec<(usize, Duration)>;
            let results: Vec<Result<(Vec<Message>, Timed), NodeError>> = self
                .nodes
                .par_iter_mut()
                .zip(deliveries.par_iter())
                .map(|(node, mine)| {
                    let (mut out, mut times) = (Vec::new(), Vec::new());
                    for &k in mine {
                        let t0 = timed.then(Instant::now);
                        out.extend(node.handle(&queue_ref[k])?);
                        out.extend(std::iter::from_fn(|| node.next_output()));
                        if let Some(t0) = t0 {
                            times.push((k, t0.elapsed()));
                        }
                    }
                    Ok((out, times))
                })
                .collect();
            let mut next = Vec::new();
            for (j, (node, r)) in self.nodes.iter().zip(results).enumerate() {
                let (out, times) = r?;
                next.extend(out);
                let role = node.id().role;
                for (k, d) in times {
                    let field = topic_field(&topics[k]).unwrap_or(&topics[k]);
                    if let Some(timing) = &mut self.timing {
                        let e = timing.entry((role, field.to_string())).or_default();
                        e.0 += 1;
                        e.1 += d;
                    }
                    if let Some(timing) = &mut self.iteration_timing {
                        timing.add(j, queue[k].envelope.iteration, Some(field), d);
                    }
                }
            }
            for m in std::mem::replace(&mut queue, next) {
                if self.keeps(&m) {
                    self.kept.push(m);
                } else if let Some(k) = ids.iter().position(|id| *id == m.envelope.sender) {
                    self.nodes[k].recycle(m);
                }
            }
        }
        let unfinished: Vec<String> = self
            .nodes
            .iter()
            .filter(|n| !n.is_finished())
            .map(|n| n.id().to_string())
            .collect();
        if unfinished.is_empty() {
            Ok(())
        } else {
            Err(BusError::Stalled(unfinished.join(", ")))
        }
    }

    /// The nodes, e.g. to read their final state.
    pub fn into_nodes(self) -> Vec<Box<dyn Node>> {
        self.nodes
    }
}

/// Checks that a field has the expected shape and holds as many values as it declares; names the
/// field in the error (a rejection: the node has not read it).
pub fn expect_shape(node: NodeId, what: &str, f: &Field, rows: usize, cols: usize) -> Result<(), NodeError> {
    if f.rows() != rows || f.cols() != cols {
        return Err(NodeError::rejected(
            node,
            format!("{what} has shape {} × {}, expected {rows} × {cols}", f.rows(), f.cols()),
        ));
    }
    if f.data.len() as u64 != rows as u64 * cols as u64 {
        return Err(NodeError::rejected(
            node,
            format!("{what} declares {rows} × {cols} values but holds {}", f.data.len()),
        ));
    }
    Ok(())
}

/// Checks that a received field holds finite values only; names the field, the entry and `from`
/// in the error (a failure: its sender diverged or the message was damaged, the run stops).
pub fn expect_finite(node: NodeId, what: &str, from: &str, f: &Field) -> Result<(), NodeError> {
    match f.first_non_finite() {
        Some((r, c, v)) => Err(NodeError::new(
            node,
            format!("{what} from {from} holds {v} at row {r}, column {c}: not finite"),
        )),
        None => Ok(()),
    }
}

/// The stage every payload is published at.
pub fn stage_of(payload: &Payload) -> Stage {
    match payload {
        Payload::Scene { .. } | Payload::HomogenizedOperator { .. } => Stage::Setup,
        Payload::MacroForces { .. } => Stage::Micro1,
        Payload::MacroDisplacements { .. } => Stage::Macro,
        Payload::BoundaryState { .. }
        | Payload::BoundaryModes { .. }
        | Payload::AndersonGram { .. }
        | Payload::AndersonStep { .. }
        | Payload::LinearStageStats(_) => Stage::Linear,
        Payload::LocalDirections { .. }
        | Payload::Decision(_)
        | Payload::IndicatorPartials { .. }
        | Payload::NodeStatus(_)
        | Payload::Stall(_) => Stage::Local,
        Payload::InterfaceSolution(_) | Payload::Displacement { .. } => Stage::Final,
    }
}

/// Checks a message's origin: sent by a node of `role` (with index `index` when given) at the
/// stage its payload belongs to. Names the message, the sender and the stage in the rejection.
pub fn expect_origin(node: NodeId, msg: &Message, role: Role, index: Option<u32>) -> Result<(), NodeError> {
    let (env, field) = (&msg.envelope, msg.payload.field_key());
    if env.sender.role != role || index.is_some_and(|i| env.sender.index != i) {
        let from = match index {
            Some(i) => format!("{}:{i}", role.key()),
            None => format!("a {} node", role.key()),
        };
        return Err(NodeError::rejected(
            node,
            format!(
                "{field} of iteration {} sent by {}, expected from {from}",
                env.iteration, env.sender
            ),
        ));
    }
    let stage = stage_of(&msg.payload);
    if env.stage != stage {
        return Err(NodeError::rejected(
            node,
            format!(
                "{field} of iteration {} from {} at stage {:?}, expected stage {stage:?}",
                env.iteration, env.sender, env.stage
            ),
        ));
    }
    Ok(())
}

/// Hands `inputs` to `take` in their order, as a replacement node process or a re-execution
/// replays a recording. A recording's order is the order the recorder heard the messages, which
/// need not be one the nodes could have seen (the router forwards each sender's messages on its
/// own): an input `take` refuses as not yet its turn (`Ok(Some(why))`) is held and handed again
/// after every input taken, until a pass over what is held takes nothing. Returns the inputs
/// refused to the end with their last refusal, in the order they are held; stops at `take`'s
/// first error.
pub fn take_when_ready<T, R, E>(
    inputs: impl IntoIterator<Item = T>,
    mut take: impl FnMut(&T) -> Result<Option<R>, E>,
) -> Result<Vec<(T, R)>, E> {
    let mut held: std::collections::VecDeque<(T, R)> = std::collections::VecDeque::new();
    for input in inputs {
        if let Some(why) = take(&input)? {
            held.push_back((input, why));
            continue;
        }
        let mut taken = true;
        while taken && !held.is_empty() {
            taken = false;
            for _ in 0..held.len() {
                let (h, _) = held.pop_front().expect("the pass is as long as what is held");
                match take(&h)? {
                    Some(why) => held.push_back((h, why)),
                    None => taken = true,
                }
            }
        }
    }
    Ok(held.into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_messages::role_field_topic;

    fn ctx() -> RunContext {
        RunContext {
            run_id: "t".into(),
            scene_fingerprint: 1,
        }
    }

    /// Sends one message when started (after `start_ms`) and handles what it subscribes to in
    /// `handle_ms` each, finishing after the first.
    struct Toy {
        id: NodeId,
        subs: Vec<String>,
        out: Vec<Message>,
        start_ms: u64,
        handle_ms: u64,
        handled: bool,
    }

    impl Node for Toy {
        fn id(&self) -> NodeId {
            self.id
        }
        fn subscriptions(&self) -> Vec<String> {
            self.subs.clone()
        }
        fn start(&mut self) -> Result<Vec<Message>, NodeError> {
            std::thread::sleep(Duration::from_millis(self.start_ms));
            Ok(std::mem::take(&mut self.out))
        }
        fn handle(&mut self, _msg: &Message) -> Result<Vec<Message>, NodeError> {
            std::thread::sleep(Duration::from_millis(self.handle_ms));
            self.handled = true;
            Ok(Vec::new())
        }
        fn is_finished(&self) -> bool {
            self.handled || self.subs.is_empty()
        }
    }

    fn nodes() -> Vec<Box<dyn Node>> {
        let launcher = NodeId {
            role: Role::Launcher,
            index: 0,
        };
        let subdomain = NodeId {
            role: Role::Subdomain,
            index: 0,
        };
        let q = Message {
            envelope: ctx().envelope(launcher, 3, Stage::Local),
            payload: Payload::LocalDirections {
                subdomain: 0,
                interfaces: vec![0],
                q_hat: Field::zeros(2, 1),
            },
        };
        vec![
            Box::new(Toy {
                id: launcher,
                subs: Vec::new(),
                out: vec![q],
                start_ms: 0,
                handle_ms: 0,
                handled: false,
            }),
            Box::new(Toy {
                id: subdomain,
                subs: vec![role_field_topic("t", Role::Launcher, "local_directions", Some(0))],
                out: Vec::new(),
                start_ms: 20,
                handle_ms: 30,
                handled: false,
            }),
        ]
    }

    /// Timing per iteration gives each node's start (iteration 0) and its handling of each
    /// iteration's messages per field, in node order; off, nothing.
    #[test]
    fn the_bus_times_each_nodes_work_per_iteration() {
        let mut bus = InProcessBus::new(nodes()).with_iteration_timing(true);
        bus.run(|_| true).unwrap();
        let times = bus.iteration_times();
        let got: Vec<(Role, u32, Option<&str>, u64)> = times
            .iter()
            .map(|t| (t.node.role, t.iteration, t.field.as_deref(), t.calls))
            .collect();
        assert_eq!(
            got,
            [
                (Role::Launcher, 0, None, 1),
                (Role::Subdomain, 0, None, 1),
                (Role::Subdomain, 3, Some("local_directions"), 1)
            ]
        );
        assert!(times[1].seconds >= 0.02, "{times:?}");
        assert!(times[2].seconds >= 0.03, "{times:?}");
        assert!(bus.handle_times().is_empty(), "timing per (role, field) is off");
        let mut untimed = InProcessBus::new(nodes());
        untimed.run(|_| true).unwrap();
        assert!(untimed.iteration_times().is_empty());
    }

    /// Kept messages come out of the bus after delivery, in publication order, and are not given
    /// back to their senders; without `keeping` none is kept. A run stopped by its observer keeps
    /// the selected messages it saw of the round it did not deliver, and not the ones after.
    #[test]
    fn kept_messages_are_moved_to_the_caller() {
        // The launcher of `nodes()` publishes, in one round, local directions of iteration 3, an
        // Anderson step (not kept) and local directions of iteration 4.
        let with_more = || {
            let mut n = nodes();
            let launcher = n[0].id();
            let q3 = n[0].start().unwrap().remove(0);
            let mut q4 = q3.clone();
            q4.envelope.iteration = 4;
            let step = Message {
                envelope: q3.envelope.clone(),
                payload: Payload::AndersonStep {
                    gamma: Vec::new(),
                    restart: false,
                },
            };
            n[0] = Box::new(Toy {
                id: launcher,
                subs: Vec::new(),
                out: vec![q3, step, q4],
                start_ms: 0,
                handle_ms: 0,
                handled: false,
            });
            n
        };
        let is_q = |m: &Message| matches!(m.payload, Payload::LocalDirections { .. });
        let mut bus = InProcessBus::new(with_more()).keeping(is_q);
        let mut seen = 0;
        bus.run(|m| {
            seen += is_q(m) as usize;
            true
        })
        .unwrap();
        assert_eq!(seen, 2);
        let kept = bus.take_kept();
        let iterations: Vec<u32> = kept.iter().map(|m| m.envelope.iteration).collect();
        assert_eq!(iterations, [3, 4], "both, in publication order");
        assert!(kept.iter().all(is_q), "not the Anderson step");
        assert!(bus.take_kept().is_empty(), "taken once");
        assert!(bus.into_nodes()[1].is_finished(), "delivered before they were kept");
        // Stopped at the Anderson step (the second message): the first is kept, the third not.
        let mut stopped = InProcessBus::new(with_more()).keeping(is_q);
        stopped
            .run(|m| !matches!(m.payload, Payload::AndersonStep { .. }))
            .unwrap();
        let kept: Vec<u32> = stopped.take_kept().iter().map(|m| m.envelope.iteration).collect();
        assert_eq!(kept, [3], "what the observer saw, up to the stop");
        let mut plain = InProcessBus::new(with_more());
        plain.run(|_| true).unwrap();
        assert!(plain.take_kept().is_empty());
    }

    /// Inputs 3, 1, 9, 2 to a taker of 1, 2, 3 in that order: each is taken once it is its turn,
    /// and 9, never its turn, comes back with its last refusal.
    #[test]
    fn inputs_are_taken_when_ready_and_the_rest_comes_back() {
        let mut next = 1;
        let mut order = Vec::new();
        let left = take_when_ready([3, 1, 9, 2], |&i| -> Result<Option<String>, ()> {
            if i != next {
                return Ok(Some(format!("{i} while at {next}")));
            }
            order.push(i);
            next += 1;
            Ok(None)
        })
        .unwrap();
        assert_eq!(order, [1, 2, 3]);
        assert_eq!(left, [(9, "9 while at 4".to_string())]);
        let failed = take_when_ready([2, 1], |&i| if i == 1 { Err(i) } else { Ok(Some(())) });
        assert_eq!(failed, Err(1));
    }
}
