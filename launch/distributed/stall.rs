//! A run as processes that stops moving is noticed within seconds, not after the last-resort
//! [`super::IDLE_TIMEOUT`]: when nothing has moved for a few times the recent iterations' median
//! length (a floor of [`FLOOR`]), the launcher asks every node for its status (what it waits
//! for, whether its process is busy, what it last handled and put on each key:
//! [`glissade_messages::NodeStatus`]), twice. Two rounds that show the same counters, no process
//! busy and no message of the run in between make a stall: a message a node waits for that its
//! sender says it put on the bus was lost on the way, and the launcher asks the sender to publish
//! it again (messages are idempotent: a receiver drops a repeat); anything else ends the run with
//! a diagnosis naming the node that waits, the message it lacks, the node that should send it and
//! what that node last did. Both are a [`glissade_messages::StallReport`] on the bus (recorded,
//! shown by `glissade replay`) and a line on the console.

use glissade_messages::{
    topic, Awaited, Envelope, Expected, Message, MessageSeen, Missing, NodeId, NodeStatus, Payload, Role, Stage,
    StallReport, SCHEMA_VERSION,
};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::{Duration, Instant};

/// Shortest silence before the nodes are asked.
pub(super) const FLOOR: Duration = Duration::from_millis(1500);
/// Silence before asking, in recent iteration lengths (median).
const ITERATIONS: f64 = 5.0;
/// How long the nodes get to answer a status request.
const REPLY_WAIT: Duration = Duration::from_secs(2);
/// How many times one message is asked again before the run is ended.
const REPUBLISH_LIMIT: u32 = 2;
/// A process busy for longer than this is not taken to move (stuck in a put, say): the last-resort
/// timeout of the processes is as long.
const BUSY_LIMIT: Duration = Duration::from_secs(600);
/// How long nodes may stay silent (their process alive but not answering) before the run is
/// ended with their names.
const SILENT_LIMIT: Duration = Duration::from_secs(30);
/// Waits named in a diagnosis.
const LINES: usize = 6;
/// Shortest time between the two rounds that confirm a stall (half the patience: a message on
/// its way lands meanwhile).
const CONFIRM_GAP: Duration = Duration::from_millis(500);

/// What the launcher should do about the run.
pub(super) enum Stall {
    /// Nothing (moving, or being looked at).
    None,
    /// Messages were lost on the way and asked again: the report to publish.
    Recovered(Message),
    /// The run cannot go on: the report to publish, and the diagnosis.
    Ended(Message, String),
}

/// A status round under way.
struct Round {
    number: u64,
    asked: Instant,
    replies: BTreeMap<NodeId, NodeStatus>,
}

/// The launcher's watch on a run's progress.
pub(super) struct StallWatch {
    run_id: String,
    expected: Expected,
    /// The nodes that answer status requests.
    nodes: BTreeSet<NodeId>,
    last_moved: Instant,
    last_decision: Option<Instant>,
    iterations: VecDeque<f64>,
    rounds: u64,
    round: Option<Round>,
    /// The previous round's answers, when nothing moved since, and when they were complete.
    previous: Option<BTreeMap<NodeId, NodeStatus>>,
    previous_at: Option<Instant>,
    /// Messages asked again (key, iteration), and how often.
    republished: BTreeMap<(String, u32), u32>,
    /// Nodes that answered no status, since when.
    silent_since: BTreeMap<NodeId, Instant>,
    /// The launcher's own messages a node may wait for (a time-coarse start's local
    /// directions), until every node has taken them.
    own: Vec<MessageSeen>,
    /// The decisions the launcher heard, by iteration: whether each stopped the run.
    decisions: BTreeMap<u32, bool>,
    /// The last decision's iteration (the envelope of the launcher's reports).
    iteration: u32,
}

impl StallWatch {
    pub(super) fn new(run_id: &str, expected: Expected, nodes: BTreeSet<NodeId>) -> Self {
        Self {
            run_id: run_id.to_string(),
            expected,
            nodes,
            last_moved: Instant::now(),
            last_decision: None,
            iterations: VecDeque::new(),
            rounds: 0,
            round: None,
            previous: None,
            previous_at: None,
            republished: BTreeMap::new(),
            silent_since: BTreeMap::new(),
            own: Vec::new(),
            decisions: BTreeMap::new(),
            iteration: 0,
        }
    }

    /// A message of the run other than a status moved: the run is not stalled.
    pub(super) fn moved(&mut self) {
        self.last_moved = Instant::now();
        self.round = None;
        self.previous = None;
        self.previous_at = None;
    }

    /// The launcher put `key` (iteration `iteration`) on the bus for the nodes; None forgets its
    /// messages (every node has taken them).
    pub(super) fn launcher_sent(&mut self, sent: Option<(&str, u32)>) {
        match sent {
            Some((key, iteration)) => self.own.push(MessageSeen {
                key: key.to_string(),
                iteration,
                ms_ago: 0,
            }),
            None => self.own.clear(),
        }
    }

    /// The node processes of these nodes exited: they answer no more.
    pub(super) fn gone(&mut self, nodes: &[NodeId]) {
        for n in nodes {
            self.nodes.remove(n);
        }
    }

    /// A decision of `iteration` came (`stop`: it ends the run): its length counts towards the
    /// silence allowed.
    pub(super) fn decided(&mut self, iteration: u32, stop: bool) {
        self.decisions.insert(iteration, stop);
        let now = Instant::now();
        if let Some(t) = self.last_decision.replace(now) {
            self.iterations.push_back(now.duration_since(t).as_secs_f64());
            if self.iterations.len() > 10 {
                self.iterations.pop_front();
            }
        }
        self.iteration = iteration;
        self.moved();
    }

    /// A node's status.
    pub(super) fn status(&mut self, from: NodeId, status: NodeStatus) {
        if let Some(r) = self.round.as_mut().filter(|r| r.number == status.round) {
            r.replies.insert(from, status);
        }
    }

    /// The silence allowed before the nodes are asked.
    pub(super) fn patience(&self) -> Duration {
        let mut v: Vec<f64> = self.iterations.iter().copied().collect();
        v.sort_by(f64::total_cmp);
        let median = v.get(v.len() / 2).copied().unwrap_or(0.0);
        FLOOR.max(Duration::from_secs_f64(ITERATIONS * median))
    }

    /// Looks at the run: asks for the nodes' statuses (`ask(round)` publishes the request) when
    /// nothing moved for [`Self::patience`], and once two rounds agree, says what to do.
    /// `launcher_lacks` are the messages the launcher itself waits for (the final outputs after
    /// the stop decision).
    pub(super) fn look(
        &mut self,
        launcher_lacks: &[Awaited],
        mut ask: impl FnMut(u64),
        mut republish: impl FnMut(&str),
    ) -> Stall {
        let now = Instant::now();
        let Some(round) = &self.round else {
            let due = match self.previous_at {
                Some(t) => t + CONFIRM_GAP.max(self.patience() / 2),
                None => self.last_moved + self.patience(),
            };
            if now >= due {
                self.rounds += 1;
                self.round = Some(Round {
                    number: self.rounds,
                    asked: now,
                    replies: BTreeMap::new(),
                });
                ask(self.rounds);
            }
            return Stall::None;
        };
        let all_in = self.nodes.iter().all(|n| round.replies.contains_key(n));
        if !all_in && now.duration_since(round.asked) < REPLY_WAIT {
            return Stall::None;
        }
        let replies = self.round.take().expect("a round under way").replies;
        let limit = BUSY_LIMIT.as_millis() as u64;
        if replies.values().any(|s| s.busy_ms.is_some_and(|b| b < limit)) {
            // A node is computing: the run moves.
            self.moved();
            return Stall::None;
        }
        match self.previous.take() {
            // A second round confirms (a message may be on its way).
            Some(previous) if same(&previous, &replies) => {}
            _ => {
                self.previous = Some(replies);
                self.previous_at = Some(now);
                return Stall::None;
            }
        }
        let silent = now.duration_since(self.last_moved);
        self.moved();
        self.decide(&replies, launcher_lacks, silent, &mut republish)
    }

    /// Two agreeing rounds: what is missing, what can be asked again, or the end.
    fn decide(
        &mut self,
        replies: &BTreeMap<NodeId, NodeStatus>,
        launcher_lacks: &[Awaited],
        silent: Duration,
        republish: &mut impl FnMut(&str),
    ) -> Stall {
        let launcher = NodeId {
            role: Role::Launcher,
            index: 0,
        };
        let mut waits: Vec<(NodeId, &Awaited)> = replies
            .iter()
            .filter(|(_, s)| !s.finished)
            .flat_map(|(&n, s)| s.awaits.iter().map(move |a| (n, a)))
            .collect();
        waits.extend(launcher_lacks.iter().map(|a| (launcher, a)));
        // A node waits for a decision only in case it stops the run: one the launcher heard
        // going on would not move it.
        let going_on = |a: &Awaited| a.field == "decision" && self.decisions.get(&a.iteration) == Some(&false);
        waits.retain(|(waiter, a)| *waiter == launcher || !going_on(a));
        let missing: Vec<Missing> = waits
            .iter()
            .map(|&(waiter, a)| Missing {
                waiter,
                awaited: a.clone(),
                sent: self.sent(replies, a).is_some(),
            })
            .collect();
        let answered = replies.keys().copied().collect::<BTreeSet<_>>();
        let silent_nodes: Vec<NodeId> = self.nodes.difference(&answered).copied().collect();
        let now = Instant::now();
        self.silent_since.retain(|n, _| silent_nodes.contains(n));
        for n in &silent_nodes {
            self.silent_since.entry(*n).or_insert(now);
        }
        let mut asked = Vec::new();
        for m in missing.iter().filter(|m| m.sent) {
            let key = topic::awaited(&self.run_id, &m.awaited);
            let times = self.republished.entry((key.clone(), m.awaited.iteration)).or_default();
            if *times < REPUBLISH_LIMIT && !asked.contains(&key) {
                *times += 1;
                republish(&key);
                asked.push(key);
            }
        }
        // A node whose process lives but does not answer (busy sending, say) gets time: the run
        // ends on it only once it has been silent for SILENT_LIMIT.
        let waiting_for_silent = asked.is_empty()
            && self
                .silent_since
                .values()
                .any(|since| now.duration_since(*since) < SILENT_LIMIT);
        if waiting_for_silent {
            return Stall::None;
        }
        let diagnosis = format!(
            "nothing moved for {:.1} s: {}",
            silent.as_secs_f64(),
            self.diagnosis(replies, &missing, &silent_nodes, &asked)
        );
        let ended = asked.is_empty();
        let report = Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: self.expected.run_id.clone(),
                scene_fingerprint: self.expected.scene_fingerprint,
                iteration: self.iteration,
                stage: Stage::Local,
                sender: launcher,
            },
            payload: Payload::Stall(StallReport {
                silent_ms: silent.as_millis() as u64,
                missing,
                republished: asked,
                ended,
                diagnosis: diagnosis.clone(),
            }),
        };
        if ended {
            Stall::Ended(report, diagnosis)
        } else {
            Stall::Recovered(report)
        }
    }

    /// What the sender of `a` says it put on `a`'s key at `a`'s iteration (the launcher's own
    /// messages from its list).
    fn sent<'s>(&'s self, replies: &'s BTreeMap<NodeId, NodeStatus>, a: &Awaited) -> Option<&'s MessageSeen> {
        let key = topic::awaited(&self.run_id, a);
        let sent = match a.from.role {
            Role::Launcher => &self.own,
            _ => &replies.get(&a.from)?.sent,
        };
        sent.iter().find(|s| s.key == key && s.iteration == a.iteration)
    }

    /// The diagnosis in words: the messages lost on the way if any; otherwise the waits whose
    /// sender is finished, silent or waiting for nothing (where the run is stuck), or else every
    /// wait (they wait for each other). At most [`LINES`] of them, then how many more.
    fn diagnosis(
        &self,
        replies: &BTreeMap<NodeId, NodeStatus>,
        missing: &[Missing],
        silent: &[NodeId],
        asked: &[String],
    ) -> String {
        let lost: Vec<&Missing> = missing.iter().filter(|m| m.sent).collect();
        let stuck: Vec<&Missing> = missing
            .iter()
            .filter(|m| {
                replies
                    .get(&m.awaited.from)
                    .is_none_or(|s| s.finished || s.awaits.is_empty())
            })
            .collect();
        let named = if !lost.is_empty() {
            lost
        } else if !stuck.is_empty() {
            stuck
        } else {
            missing.iter().collect()
        };
        let mut lines: Vec<String> = named
            .iter()
            .take(LINES)
            .map(|m| {
                let a = &m.awaited;
                let what = format!("{} of iteration {} from {}", a.field, a.iteration, a.from);
                match self.sent(replies, a) {
                    Some(s) => format!(
                        "{} lacks {what}, which {} put on the bus {:.1} s ago ({}): lost on the way",
                        m.waiter,
                        a.from,
                        s.ms_ago as f64 / 1e3,
                        s.key
                    ),
                    None => format!(
                        "{} waits for {what}, which {} has not sent: {}",
                        m.waiter,
                        a.from,
                        doing(a.from, replies.get(&a.from))
                    ),
                }
            })
            .collect();
        if named.len() > LINES {
            lines.push(format!("and {} more", named.len() - LINES));
        }
        for n in silent {
            lines.push(format!(
                "{n} did not answer the status request within {} s",
                REPLY_WAIT.as_secs()
            ));
        }
        if lines.is_empty() {
            lines.push("every node waits for nothing, yet the run is not over".into());
        }
        if !asked.is_empty() {
            lines.push(format!("asked their senders to publish again: {}", asked.join(", ")));
        } else if missing.iter().any(|m| m.sent) {
            lines.push(format!(
                "still missing after its sender was asked {REPUBLISH_LIMIT} times to publish it again"
            ));
        }
        lines.join("; ")
    }
}

/// What node `n` last did, from its status.
fn doing(n: NodeId, status: Option<&NodeStatus>) -> String {
    let Some(s) = status else {
        return format!("{n} did not answer the status request");
    };
    if s.finished {
        return format!("{n} is finished");
    }
    let waits = if s.awaits.is_empty() {
        "waits for nothing".to_string()
    } else {
        format!(
            "it waits for {}",
            s.awaits
                .iter()
                .map(|a| format!("{} of iteration {} from {}", a.field, a.iteration, a.from))
                .collect::<Vec<_>>()
                .join(" or ")
        )
    };
    let last = s.sent.iter().min_by_key(|m| m.ms_ago).map_or(String::new(), |m| {
        format!(
            "; its last message went {:.1} s ago ({} of iteration {})",
            m.ms_ago as f64 / 1e3,
            topic::topic_field(&m.key).unwrap_or(&m.key),
            m.iteration
        )
    });
    format!("{waits}{last}")
}

/// Whether two rounds show the same state: the same counters and waits at every node.
fn same(a: &BTreeMap<NodeId, NodeStatus>, b: &BTreeMap<NodeId, NodeStatus>) -> bool {
    let key = |s: &NodeStatus| {
        (
            s.finished,
            s.handled,
            s.awaits.clone(),
            s.sent.iter().map(|m| (m.key.clone(), m.iteration)).collect::<Vec<_>>(),
        )
    };
    a.len() == b.len() && a.iter().zip(b).all(|((n, s), (m, t))| n == m && key(s) == key(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(role: Role, index: u32) -> NodeId {
        NodeId { role, index }
    }

    fn status(round: u64, awaits: Vec<Awaited>, sent: Vec<(&str, u32)>) -> NodeStatus {
        NodeStatus {
            round,
            finished: false,
            awaits,
            busy_ms: None,
            handled: 10,
            last_handled: None,
            sent: sent
                .into_iter()
                .map(|(k, i)| MessageSeen {
                    key: k.into(),
                    iteration: i,
                    ms_ago: 500,
                })
                .collect(),
        }
    }

    fn watch() -> StallWatch {
        StallWatch::new(
            "r",
            Expected {
                run_id: "r".into(),
                scene_fingerprint: 1,
            },
            [id(Role::Interface, 0), id(Role::Interface, 1)].into(),
        )
    }

    /// Asks once nothing moved for its patience; after two agreeing rounds, asks the sender of a
    /// message it says it sent to publish it again, and ends the run (with the diagnosis naming
    /// waiter, message and sender) when nothing can be asked again.
    #[test]
    fn a_lost_message_is_asked_again_then_the_run_ends() {
        let mut w = watch();
        w.last_moved = Instant::now() - FLOOR;
        let partials = Awaited {
            from: id(Role::Interface, 1),
            field: "indicator_partials".into(),
            iteration: 5,
            to: None,
        };
        let decision = Awaited {
            from: id(Role::Interface, 0),
            field: "decision".into(),
            iteration: 5,
            to: None,
        };
        let mut asked_again = Vec::new();
        let run_round = |w: &mut StallWatch, asked_again: &mut Vec<String>| {
            w.previous_at = w.previous_at.map(|t| t - FLOOR);
            let mut round = 0;
            assert!(matches!(w.look(&[], |r| round = r, |_| {}), Stall::None));
            assert!(round > 0, "no status request");
            w.status(
                id(Role::Interface, 0),
                status(
                    round,
                    vec![partials.clone()],
                    vec![("glissade/r/interface/0/local_directions/3", 4)],
                ),
            );
            w.status(
                id(Role::Interface, 1),
                status(
                    round,
                    vec![decision.clone()],
                    vec![("glissade/r/interface/1/indicator_partials", 5)],
                ),
            );
            w.look(&[], |_| {}, |k| asked_again.push(k.to_string()))
        };
        assert!(
            matches!(run_round(&mut w, &mut asked_again), Stall::None),
            "one round is not enough"
        );
        match run_round(&mut w, &mut asked_again) {
            Stall::Recovered(m) => {
                let Payload::Stall(r) = m.payload else { panic!() };
                assert!(!r.ended);
                assert_eq!(r.republished, ["glissade/r/interface/1/indicator_partials"]);
                assert!(
                    r.diagnosis
                        .contains("interface:0 lacks indicator_partials of iteration 5 from interface:1"),
                    "{}",
                    r.diagnosis
                );
            }
            _ => panic!("not recovered"),
        }
        // Still lacking after the limit: the run ends.
        for _ in 0..REPUBLISH_LIMIT - 1 {
            w.last_moved = Instant::now() - FLOOR;
            assert!(matches!(run_round(&mut w, &mut asked_again), Stall::None));
            assert!(matches!(run_round(&mut w, &mut asked_again), Stall::Recovered(_)));
        }
        w.last_moved = Instant::now() - FLOOR;
        assert!(matches!(run_round(&mut w, &mut asked_again), Stall::None));
        match run_round(&mut w, &mut asked_again) {
            Stall::Ended(_, diagnosis) => {
                assert!(
                    diagnosis.contains("interface:0 lacks indicator_partials of iteration 5 from interface:1")
                        && diagnosis.contains("still missing after its sender was asked 2 times"),
                    "{diagnosis}"
                );
            }
            _ => panic!("not ended"),
        }
        assert_eq!(asked_again.len(), REPUBLISH_LIMIT as usize);
    }

    /// With no message lost, the diagnosis names the waits whose sender waits for nothing (where
    /// the run is stuck), not the waits that follow from them.
    #[test]
    fn without_a_lost_message_the_run_ends_naming_where_it_is_stuck() {
        let mut w = watch();
        w.last_moved = Instant::now() - FLOOR;
        let decision = Awaited {
            from: id(Role::Interface, 0),
            field: "decision".into(),
            iteration: 3,
            to: None,
        };
        for k in 0..2 {
            w.previous_at = w.previous_at.map(|t| t - FLOOR);
            let mut round = 0;
            w.look(&[], |r| round = r, |_| {});
            w.status(id(Role::Interface, 0), status(round, vec![], vec![]));
            w.status(id(Role::Interface, 1), status(round, vec![decision.clone()], vec![]));
            let verdict = w.look(&[], |_| {}, |_| panic!("nothing was sent"));
            match (k, verdict) {
                (0, Stall::None) => {}
                (1, Stall::Ended(_, d)) => assert!(
                    d.contains("interface:1 waits for decision of iteration 3 from interface:0, which interface:0 has not sent: waits for nothing"),
                    "{d}"
                ),
                (k, _) => panic!("round {k}"),
            }
        }
    }

    /// A busy node, or a message that moves between the rounds, is no stall.
    #[test]
    fn a_busy_node_or_a_moving_run_is_no_stall() {
        let mut w = watch();
        w.last_moved = Instant::now() - FLOOR;
        let mut round = 0;
        w.look(&[], |r| round = r, |_| {});
        let mut busy = status(round, vec![], vec![]);
        busy.busy_ms = Some(3000);
        w.status(id(Role::Interface, 0), busy);
        w.status(id(Role::Interface, 1), status(round, vec![], vec![]));
        assert!(matches!(w.look(&[], |_| {}, |_| panic!()), Stall::None));
        assert!(w.previous.is_none() && w.round.is_none());
        // Not asked again before the patience has passed.
        w.look(&[], |_| panic!("asked again at once"), |_| panic!());
        w.last_moved = Instant::now() - FLOOR;
        w.look(&[], |r| round = r, |_| {});
        assert!(w.round.is_some());
        w.moved();
        assert!(w.round.is_none(), "a message of the run cancels the round");
    }

    /// The patience is five times the median iteration length, at least the floor.
    #[test]
    fn patience_follows_the_iterations() {
        let mut w = watch();
        assert_eq!(w.patience(), FLOOR);
        w.iterations = [0.5, 0.9, 0.6].into();
        assert_eq!(w.patience(), Duration::from_secs_f64(3.0));
    }
}
