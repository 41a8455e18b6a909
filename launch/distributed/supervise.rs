//! Supervising a run as processes once its nodes are started: the launcher watches its children's
//! exit statuses and every node's liveliness token, restarts a dead node process when the run
//! allows it, starts the iterations once every node is ready, keeps the results from the bus
//! (decisions, interface solutions, displacements), tells the nodes to leave once it holds them
//! all, and stops every node when one fails, when the run stalls or when it is interrupted.

use super::arrival::{count, kind_of, Arrival};
use super::hosted::HostedNode;
use super::setup::{token_of, Handover, SetUp, TimeStartSolve};
use super::spawn::Spawned;
use super::stall::{Stall, StallWatch};
use super::{
    interrupted, Interrupted, Traffic, DEPARTURE_GRACE, EXIT_GRACE, FINISH_TIMEOUT, IDLE_TIMEOUT, READY_TIMEOUT,
    STOP_TIMEOUT, STRAGGLER_TIMEOUT,
};
use crate::children::{spawn_node, Children, NodeName, NodeProcess};
use crate::error::{Error, IoWhat, Result};
use crate::runner::{IterationRecord, RunResult};
use glissade_deploy::Plan;
use glissade_messages::{Awaited, Expected, Field, InterfaceSolution, Message, NodeId, Payload, Role, Verdict};
use glissade_scene::LoadedScene;
use glissade_subdomain::LinearStageRecords;
use glissade_zenoh as transport;
use std::collections::{BTreeMap, HashSet};
use std::path::Path;
use std::time::{Duration, Instant};

/// How long a node step's exit waits, under Slurm, for the launcher's own SIGTERM of a `scancel`
/// before it counts as the node's failure ([`Supervisor::failure`]).
const SLURM_SIGNAL_GRACE: Duration = Duration::from_secs(2);
/// The state of a run's supervision, from the start of its processes to their exit.
pub(super) struct Supervisor<'r> {
    run_id: &'r str,
    scene: &'r LoadedScene,
    set_up: &'r SetUp,
    /// The watch on the nodes' liveliness tokens.
    presence: transport::Presence,
    net: &'r super::Network,
    exe: &'r Path,
    expected: Expected,
    /// The nodes by liveliness token key.
    tokens: BTreeMap<String, NodeName>,
    /// Restarts per node process, up to the scene's `deployment.restarts`.
    restarts: usize,
    restarted: BTreeMap<NodeName, usize>,
    /// When each node started by hand was seen to leave.
    remote_lost: BTreeMap<NodeName, Instant>,
    /// Final displacement fields the launcher waits for (with `interior`).
    final_displacements: usize,
    /// Messages already taken (a restarted node re-sends what its predecessor may have sent).
    heard: HashSet<u64>,
    pub(super) got: Collected,
    pub(super) traffic: Traffic,
    stop_seen: bool,
    done_sent: bool,
    ended_at: Option<Instant>,
    last_message: Instant,
    /// The time-coarse start's coarse solve, until the start takes its result.
    time_start: TimeStartSolve,
    /// The watch on the run's progress: a run that stops moving is looked at within seconds.
    stall: StallWatch,
    /// The launcher's own messages to the nodes (a time-coarse start's local directions), to
    /// publish again if one is lost, until the first decision.
    own_messages: Vec<Message>,
}

impl<'r> Supervisor<'r> {
    pub(super) fn new(
        run_id: &'r str,
        scene: &'r LoadedScene,
        set_up: &'r SetUp,
        handover: Handover,
        net: &'r super::Network,
        exe: &'r Path,
        interior: bool,
    ) -> Self {
        let Handover { presence, time_start } = handover;
        let expected = Expected {
            run_id: run_id.to_string(),
            scene_fingerprint: scene.fingerprint,
        };
        // Every node answers the launcher's status requests: the subdomains, the interface
        // nodes and the coarse node, wherever they run.
        let mut nodes: std::collections::BTreeSet<NodeId> = set_up
            .groups
            .iter()
            .flatten()
            .map(|&index| NodeId {
                role: Role::Subdomain,
                index,
            })
            .collect();
        nodes.extend((0..set_up.plan.interface_groups.len() as u32).map(|index| NodeId {
            role: Role::Interface,
            index,
        }));
        nodes.extend(
            set_up
                .all_nodes
                .iter()
                .filter(|n| n.role == crate::children::NodeRole::Coarse)
                .map(|n| n.id()),
        );
        Self {
            run_id,
            scene,
            set_up,
            presence,
            net,
            exe,
            stall: StallWatch::new(run_id, expected.clone(), nodes),
            own_messages: Vec::new(),
            expected,
            tokens: set_up.tokens(run_id),
            restarts: scene.deployment.restarts,
            restarted: BTreeMap::new(),
            remote_lost: BTreeMap::new(),
            final_displacements: if interior {
                set_up.groups.iter().map(Vec::len).sum()
            } else {
                0
            },
            heard: HashSet::new(),
            got: Collected::default(),
            traffic: Traffic::default(),
            stop_seen: false,
            done_sent: false,
            ended_at: None,
            last_message: Instant::now(),
            time_start,
        }
    }

    /// Stops every node (`stop` on the bus, then kills what is left after [`STOP_TIMEOUT`]).
    fn stop_all(&self, spawned: &mut Spawned, reason: &str) {
        let _ = transport::publish_stop(&self.set_up.bus.session, self.run_id, reason);
        let deadline = Instant::now() + STOP_TIMEOUT;
        spawned.children.wait_all(STOP_TIMEOUT);
        for h in &mut spawned.hosted {
            h.wait(deadline.saturating_duration_since(Instant::now()));
        }
    }

    /// Supervises the run until every node process has exited (or fails): the launcher's main
    /// loop. `on_iteration` sees each decision, `observe` every message kept.
    pub(super) fn supervise(
        &mut self,
        spawned: &mut Spawned,
        mut on_iteration: impl FnMut(&IterationRecord),
        observe: &mut Option<impl FnMut(&Message)>,
    ) -> Result<()> {
        loop {
            if interrupted() {
                self.stop_all(spawned, "the launcher was interrupted");
                let (nodes, left_out) = self.set_up.plan.describe(&self.scene.model, self.set_up.groups.len());
                let got = std::mem::take(&mut self.got);
                return Err(Interrupted {
                    partial: got.into_result(&self.scene.model, &self.set_up.plan, Verdict::Continue, nodes, left_out),
                }
                .into());
            }
            self.watch_presence(&mut spawned.children)?;
            if let Some(f) = self.failure(spawned)? {
                self.stop_all(
                    spawned,
                    &format!("the run failed: {}", f.split("; its last lines").next().unwrap_or("")),
                );
                return Err(Error::Failed(f));
            }
            if self.got.started.is_none() {
                // Waiting for the nodes' tokens: look again every few milliseconds (the run
                // starts as soon as the last node is ready).
                if let Ok(a) = self.set_up.arrivals.recv_timeout(Duration::from_millis(5)) {
                    count(&mut self.traffic, &a);
                }
                continue;
            }
            // Once `done` is out the node processes are leaving: look for their exits every few
            // milliseconds instead of every 50 ms.
            let poll = if self.done_sent {
                Duration::from_millis(2)
            } else {
                Duration::from_millis(50)
            };
            match self.set_up.arrivals.recv_timeout(poll) {
                Ok(a) => {
                    // The launcher's own requests and the statuses they bring are not the run
                    // moving.
                    if a.ours && !matches!(kind_of(&a.key), "status" | "stall") {
                        self.last_message = Instant::now();
                        self.stall.moved();
                    }
                    self.receive(&a, &mut on_iteration, observe)?;
                }
                Err(_) => {
                    if self.idle(spawned)? {
                        return Ok(());
                    }
                }
            }
            if !self.done_sent {
                self.look_for_a_stall(spawned)?;
            }
        }
    }

    /// Takes the liveliness tokens that came and went since the last look. A node process whose
    /// token comes after `done` went out (a replacement started just before) is told again: it
    /// subscribes before it shows its token, so it hears this one.
    fn watch_presence(&mut self, children: &mut Children) -> Result<()> {
        for (key, up) in self.presence.changes() {
            let Some(&name) = self.tokens.get(&key) else { continue };
            if let Some(p) = children.0.iter_mut().find(|p| p.name == name) {
                if up {
                    p.token_seen = true;
                    p.token_lost = None;
                    if self.done_sent {
                        transport::publish_done(&self.set_up.bus.session, self.run_id)?;
                    }
                } else if p.status.is_none() && p.token_seen {
                    p.token_lost = Some(Instant::now());
                }
            } else if !up && !self.set_up.hosted.contains(&name) {
                self.remote_lost.entry(name).or_insert_with(Instant::now);
            }
        }
        Ok(())
    }

    /// What stops the run, if anything: a node process that failed (and may not be restarted),
    /// a node started by hand that left, the recorder's failure before the start, nodes not
    /// ready in time. Starts the iterations once every node is ready.
    fn failure(&mut self, spawned: &mut Spawned) -> Result<Option<String>> {
        if matches!(self.net.starter, crate::starter::Starter::Slurm(_)) && !self.done_sent {
            // `scancel` signals the job's steps and the launcher each on their own: a node step
            // can end before the launcher hears its own SIGTERM. A node exit is taken for a
            // failure (or restarted) only once the launcher was not interrupted meanwhile.
            let exited = spawned
                .children
                .0
                .iter_mut()
                .any(|p| p.status.is_none() && matches!(p.child.try_wait(), Ok(Some(_))));
            if exited {
                let until = Instant::now() + SLURM_SIGNAL_GRACE;
                while Instant::now() < until && !interrupted() {
                    std::thread::sleep(Duration::from_millis(20));
                }
                if interrupted() {
                    return Ok(None);
                }
            }
        }
        let mut child_failure = if self.done_sent {
            // The launcher holds every result: a node process that fails now (killed on its way
            // out, say) costs nothing, and a replacement would wait for a `done` already sent. One
            // that lost the bus but still runs has nothing left to do: it is stopped.
            for p in spawned.children.0.iter_mut() {
                if p.status.is_none() && p.token_lost.is_some_and(|t| t.elapsed() > EXIT_GRACE) {
                    let _ = p.child.kill();
                    p.status = p.child.wait().ok();
                    crate::console::warn(&format!(
                        "node {} lost the bus after the run's results were in and did not exit: stopped",
                        p.name
                    ));
                }
            }
            if let Some(late) = self.child_failure(&mut spawned.children, false)? {
                crate::console::warn(&format!(
                    "{late}\n(after the launcher held the run's results: they are complete and kept)"
                ));
            }
            None
        } else if self.set_up.supervised && self.got.started.is_some() {
            // Every node process that died mid-run is restarted, whichever died first: a
            // replacement resumes from the recorder's log, up to `restarts` times per node.
            self.restart_dead(&mut spawned.children)?
        } else {
            self.child_failure(&mut spawned.children, true)?
        };
        if child_failure.is_none() {
            child_failure = self.hosted_failure(&mut spawned.hosted).map(|(name, why)| {
                // A node of the launcher's process that left because a peer's token went is not
                // the culprit when that peer's process still runs (stopped or hung): name it, as
                // for a node process that exited for that reason.
                match silent_peer(&mut spawned.children) {
                    Some((p, lost)) => format!(
                        "node {} stopped answering: its liveliness token disappeared {:.1} s ago, before node {name} \
                         (in the launcher's process) failed, while its process still runs (stopped or hung?); its last \
                         lines:\n    {}",
                        p.name,
                        lost.elapsed().as_secs_f64(),
                        p.last_lines()
                    ),
                    None => why,
                }
            });
        }
        // A node started by hand that left before the end is the culprit if it left first (the
        // others leave after it, DEPARTURE_GRACE later); messages already sent may still bring
        // the stop decision within that grace.
        let first_remote_lost = self.remote_lost.iter().min_by_key(|(_, &t)| t).map(|(&n, &t)| (n, t));
        let mut failure = match first_remote_lost {
            Some((name, lost)) if !self.stop_seen && (lost.elapsed() > DEPARTURE_GRACE || child_failure.is_some()) => {
                Some(format!(
                    "node {name} (started by hand elsewhere) left the run before it finished; \
                     its exit status and log are on its own machine"
                ))
            }
            _ => child_failure,
        };
        if self.got.started.is_none() && failure.is_none() {
            failure = spawned
                .recorder
                .as_mut()
                .and_then(|r| r.check().err())
                .map(|e| crate::error::chain(&e));
        }
        if self.got.started.is_none() && failure.is_none() {
            failure = self.start_when_ready(spawned)?;
        }
        Ok(failure)
    }

    /// Restarts every local node process that died: exited with a failure, or lost its
    /// connection to the bus while still running. One that exited successfully has finished
    /// (it is not restarted). The run's failure when a node has no restart left.
    fn restart_dead(&mut self, children: &mut Children) -> Result<Option<String>> {
        for k in 0..children.0.len() {
            if let Look::Dead { why, .. } = look(&mut children.0[k], true)? {
                if let Some(failure) = self.restart(children, k, &why)? {
                    return Ok(Some(failure));
                }
            }
        }
        Ok(None)
    }

    /// The first local node process that failed: exited with a failure (or before the run
    /// started), or lost its connection to the bus while still running (`running_too`). A node
    /// that exited because a peer left is not the culprit when that peer's token went first.
    fn child_failure(&self, children: &mut Children, running_too: bool) -> Result<Option<String>> {
        let mut child_failure: Option<String> = None;
        let mut exited: Option<usize> = None;
        for (k, p) in children.0.iter_mut().enumerate() {
            if child_failure.is_some() {
                continue;
            }
            match look(p, running_too)? {
                Look::Dead { why, exited: e } => {
                    child_failure = Some(why);
                    exited = e.then_some(k);
                }
                Look::Finished if self.got.started.is_none() => {
                    child_failure = Some(format!("node {} exited before the run started", p.name));
                }
                Look::Finished | Look::Unchanged => {}
            }
        }
        // A node that exited because a peer left is not the culprit when that peer's token went
        // first while its process still runs (stopped or hung), or when that peer died too:
        // name the peer. A peer that exited successfully has finished: not the culprit.
        if let (Some(k), true) = (exited, running_too) {
            let exited_lost = children.0[k].token_lost;
            let silent = children
                .0
                .iter()
                .enumerate()
                .filter(|(j, p)| *j != k && p.status.is_none())
                .filter_map(|(j, p)| Some((j, p.token_lost?)))
                .filter(|(_, lost)| exited_lost.is_none_or(|e| *lost <= e))
                .min_by_key(|(_, lost)| *lost);
            if let Some((j, lost)) = silent {
                let exited = children.0[k].name;
                let p = &mut children.0[j];
                let status = p
                    .child
                    .try_wait()
                    .what(|| format!("cannot wait for node process {}", p.name))?;
                match status {
                    // It died too (before the other, as its token says): the usual report.
                    Some(status) if !status.success() => {
                        p.status = Some(status);
                        child_failure = Some(failed(p, status));
                    }
                    Some(status) => p.status = Some(status),
                    None => {
                        child_failure = Some(format!(
                            "node {} stopped answering: its liveliness token disappeared {:.1} s ago, before node \
                             {exited} failed, while its process still runs (stopped or hung?); its last lines:\n    {}",
                            p.name,
                            lost.elapsed().as_secs_f64(),
                            p.last_lines()
                        ))
                    }
                }
            }
        }
        Ok(child_failure)
    }

    /// The first node run in the launcher's process that failed (or ended before the run
    /// started).
    fn hosted_failure(&self, hosted: &mut [HostedNode]) -> Option<(NodeName, String)> {
        let started = self.got.started.is_some();
        hosted.iter_mut().find_map(|h| {
            let name = h.name;
            match h.outcome()? {
                Err(e) => Some((name, format!("node {name} (in the launcher's process) failed: {e}"))),
                Ok(()) if !started => Some((name, format!("node {name} ended before the run started"))),
                Ok(()) => None,
            }
        })
    }

    /// Restarts dead node process `k` (it resumes from the recording) if it has restarts left;
    /// otherwise the run's failure.
    fn restart(&mut self, children: &mut Children, k: usize, why: &str) -> Result<Option<String>> {
        let name = children.0[k].name;
        let restarts = self.restarts;
        let count = self.restarted.entry(name).or_default();
        let why_short = why.split("; its last lines").next().unwrap_or(why).to_string();
        if *count >= restarts {
            return Ok(Some(format!(
                "node {name} died again after {restarts} restart(s) (deployment.restarts = {restarts}): {why}"
            )));
        }
        *count += 1;
        crate::console::say(&format!(
            "{why_short}; restarting it ({} of {restarts}): it resumes from the recording",
            *count
        ));
        let p = &mut children.0[k];
        let _ = p.child.kill();
        let _ = p.child.wait();
        let base = p.args.clone();
        let mut args = base.clone();
        args.push("--resume".into());
        let credentials = p.credentials.clone();
        *p = spawn_node(
            self.net.starter.command(self.exe, name, self.set_up.node_counts()),
            name,
            &args,
            credentials,
        )?;
        p.args = base;
        Ok(None)
    }

    /// Starts the iterations (`start`, then a time-coarse start's local directions) once every
    /// node's token is up, the recorder is ready and the time-coarse start's coarse solve is over;
    /// fails when nodes are not ready in time, or (after stopping them) as soon as that solve
    /// failed.
    fn start_when_ready(&mut self, spawned: &mut Spawned) -> Result<Option<String>> {
        let set_up = self.set_up;
        let recorder_ready = spawned.recorder.as_ref().is_none_or(|r| r.is_ready());
        let missing: Vec<NodeName> = self
            .tokens
            .iter()
            .filter(|(k, _)| !self.presence.is_alive(k))
            .map(|(_, &n)| n)
            .collect();
        let solved = match self.time_start.poll() {
            Ok(solved) => solved,
            Err(e) => {
                self.stop_all(spawned, "the time-coarse start failed");
                return Err(e);
            }
        };
        if solved && missing.is_empty() && recorder_ready {
            let time_start = self.time_start.take();
            if let Some(t) = &time_start {
                crate::console::note(&format!("run {}: {}", self.run_id, t.describe()));
            }
            let session = &set_up.bus.session;
            transport::publish_start(session, self.run_id)?;
            for m in time_start.iter().flat_map(|t| &t.messages) {
                transport::publish(session, m)?;
                self.stall.launcher_sent(Some((&m.topic(), m.envelope.iteration)));
            }
            self.own_messages = time_start.map(|t| t.messages).unwrap_or_default();
            self.got.setup_s = self.set_up.t0.elapsed().as_secs_f64();
            self.got.started = Some(Instant::now());
            self.last_message = Instant::now();
            self.stall.moved();
            crate::console::note(&format!(
                "run {}: {} node(s) ready, iterating",
                self.run_id,
                set_up.all_nodes.len()
            ));
            return Ok(None);
        }
        let remote = &self.net.remote;
        let local_late = missing.iter().any(|n| !remote.contains(n)) && self.set_up.t0.elapsed() > READY_TIMEOUT;
        let remote_late =
            missing.iter().any(|n| remote.contains(n)) && self.set_up.t0.elapsed() > spawned.remote_timeout;
        if !(local_late || remote_late) {
            return Ok(None);
        }
        Ok(Some(format!(
            "nodes not ready within {} s: {} (a node started by hand must use --run {} and reach the bus)",
            if remote_late {
                spawned.remote_timeout
            } else {
                READY_TIMEOUT
            }
            .as_secs(),
            missing.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", "),
            self.run_id
        )))
    }

    /// Counts message `a` and keeps what the launcher needs of it; says `done` once the launcher
    /// holds the final decision and every final output (a node that closed its session right
    /// after its last put could lose it).
    fn receive(
        &mut self,
        a: &Arrival,
        on_iteration: &mut impl FnMut(&IterationRecord),
        observe: &mut Option<impl FnMut(&Message)>,
    ) -> Result<()> {
        if let Some(rec) = self.take(a, observe) {
            self.stop_seen |= rec.decision.verdict.is_stop();
            self.stall.decided(rec.iteration, rec.decision.verdict.is_stop());
            // Every subdomain took the launcher's initial local directions (iteration 0) before
            // any decision.
            self.stall.launcher_sent(None);
            self.own_messages.clear();
            on_iteration(&rec);
        }
        if !self.done_sent
            && self.stop_seen
            && self.got.interfaces.len() == self.scene.model.interfaces.len()
            && self.got.displacements.len() >= self.final_displacements
        {
            transport::publish_done(&self.set_up.bus.session, self.run_id)?;
            self.got.finished = Some(Instant::now());
            self.done_sent = true;
        }
        Ok(())
    }

    /// Counts message `a`, decodes it if the launcher keeps it and it is its sender's (once:
    /// a restarted node re-sends outputs its predecessor may have sent already), shows it to
    /// `observe` and keeps its result; a decision's record is returned.
    fn take(&mut self, a: &Arrival, observe: &mut Option<impl FnMut(&Message)>) -> Option<IterationRecord> {
        let bytes = count(&mut self.traffic, a)?;
        if !self.heard.insert(transport::payload_hash(&a.key, bytes)) {
            return None;
        }
        let m = transport::decode_payload(bytes, &self.expected, Default::default()).ok()?;
        // Only what its sender may send, on its sender's key (a member may publish on its own
        // keys only, but anything there).
        if m.not_from_its_sender(&a.key).is_some() {
            return None;
        }
        if let Some(o) = observe.as_mut() {
            o(&m);
        }
        if let Payload::NodeStatus(st) = &m.payload {
            self.stall.status(m.envelope.sender, st.clone());
            return None;
        }
        self.got.take(m, &self.set_up.plan).cloned()
    }

    /// Asks the nodes for their status when the run stops moving, asks senders to publish again
    /// what was lost on the way, or ends the run with a diagnosis ([`super::stall`]).
    fn look_for_a_stall(&mut self, spawned: &mut Spawned) -> Result<()> {
        if self.got.started.is_none() {
            return Ok(());
        }
        // A node process being replaced (restarts) or whose token is gone (its failure is being
        // looked at) makes the others wait: that is not a stall.
        let replacing = spawned
            .children
            .0
            .iter()
            .any(|p| p.status.is_none() && (!p.token_seen || p.token_lost.is_some()));
        if replacing {
            self.stall.moved();
            return Ok(());
        }
        self.stall.gone(&self.exited_nodes(spawned));
        let lacks = self.launcher_lacks();
        let session = &self.set_up.bus.session;
        let run_id = self.run_id;
        let own = &self.own_messages;
        // Blocking rather than dropped under congestion: the very load that loses messages.
        let put = |key: String, bytes: Vec<u8>| {
            let put = session
                .put(key.as_str(), bytes)
                .congestion_control(zenoh::qos::CongestionControl::Block);
            if let Err(e) = zenoh::Wait::wait(put) {
                crate::console::warn(&format!("cannot publish on {key}: {e}"));
            }
        };
        let verdict = self.stall.look(
            &lacks,
            |round| {
                put(
                    glissade_messages::topic::status_request(run_id),
                    round.to_le_bytes().to_vec(),
                )
            },
            |key| match own.iter().find(|m| m.topic() == key) {
                // The launcher's own message: it publishes it again itself.
                Some(m) => {
                    if let Err(e) = transport::publish(session, m) {
                        crate::console::warn(&format!("cannot publish {key} again: {e}"));
                    }
                }
                None => put(glissade_messages::topic::republish(run_id), key.as_bytes().to_vec()),
            },
        );
        match verdict {
            Stall::None => Ok(()),
            Stall::Recovered(report) => {
                if let Payload::Stall(r) = &report.payload {
                    crate::console::warn(&format!(
                        "the run stopped moving and was set going again: {}",
                        r.diagnosis
                    ));
                }
                transport::publish(session, &report)?;
                Ok(())
            }
            Stall::Ended(report, diagnosis) => {
                transport::publish(session, &report)?;
                self.stop_all(spawned, "the run stopped moving");
                Err(Error::Stalled { diagnosis })
            }
        }
    }

    /// The nodes of the node processes that exited (they answer no status request).
    fn exited_nodes(&self, spawned: &Spawned) -> Vec<NodeId> {
        let plan = &self.set_up.plan;
        let mut gone = Vec::new();
        for p in spawned.children.0.iter().filter(|p| p.status.is_some()) {
            let k = p.name.index as usize;
            match p.name.role {
                crate::children::NodeRole::Subdomain => {
                    gone.extend(self.set_up.groups.get(k).into_iter().flatten().map(|&index| NodeId {
                        role: Role::Subdomain,
                        index,
                    }));
                    gone.extend(
                        plan.interface_hosts
                            .iter()
                            .enumerate()
                            .filter(|(_, h)| **h == Some(k))
                            .map(|(i, _)| NodeId {
                                role: Role::Interface,
                                index: i as u32,
                            }),
                    );
                }
                _ => gone.push(p.name.id()),
            }
        }
        gone
    }

    /// What the launcher itself waits for once the stop decision is in: the final solutions of
    /// the interfaces it lacks (from the interface node that owns each) and, with `interior`,
    /// the subdomains' displacements.
    fn launcher_lacks(&self) -> Vec<Awaited> {
        if !self.stop_seen {
            // The next decision: lost on its way to the launcher alone, it would hold the run.
            let next = self.got.iterations.last().map_or(0, |r| r.iteration + 1);
            return vec![Awaited {
                from: NodeId {
                    role: Role::Interface,
                    index: 0,
                },
                field: "decision".into(),
                iteration: next,
                to: None,
            }];
        }
        // The final solutions carry the iteration after the stop decision's (an interface node
        // moves on once it has decided), the displacements the decision's.
        let last = self.got.iterations.last().map_or(0, |r| r.iteration);
        let awaited = |role, index, field: &str| Awaited {
            from: NodeId { role, index },
            field: field.to_string(),
            iteration: last,
            to: None,
        };
        let mut lacks: Vec<Awaited> = Vec::new();
        for (k, group) in self.set_up.plan.interface_groups.iter().enumerate() {
            if group
                .iter()
                .any(|&i| !self.got.interfaces.iter().any(|s| s.interface as usize == i))
            {
                lacks.push(Awaited {
                    iteration: last + 1,
                    ..awaited(Role::Interface, k as u32, "interface_solution")
                });
            }
        }
        if self.final_displacements > 0 {
            for &s in self.set_up.groups.iter().flatten() {
                if !self.got.displacements.iter().any(|(d, _)| *d == s) {
                    lacks.push(awaited(Role::Subdomain, s, "displacement"));
                }
            }
        }
        lacks
    }

    /// Nothing arrived for a while: true once every node process has exited and every node
    /// started by hand has left; fails when nodes started by hand do not leave after the end or
    /// when the bus has been silent for [`IDLE_TIMEOUT`].
    fn idle(&mut self, spawned: &mut Spawned) -> Result<bool> {
        let presence = &self.presence;
        let remote = &self.net.remote;
        let locals_done = spawned.children.0.iter().all(|p| p.status.is_some())
            && spawned.hosted.iter_mut().all(|h| h.outcome().is_some());
        let remotes_gone = remote.iter().all(|&r| !presence.is_alive(&token_of(self.run_id, r)));
        if locals_done && remotes_gone {
            return Ok(true);
        }
        if locals_done && self.stop_seen {
            let since = *self.ended_at.get_or_insert_with(Instant::now);
            if since.elapsed() > FINISH_TIMEOUT {
                let late: Vec<String> = remote
                    .iter()
                    .filter(|&&r| presence.is_alive(&token_of(self.run_id, r)))
                    .map(|r| r.to_string())
                    .collect();
                self.stop_all(spawned, "the run is over");
                return Err(Error::NotLeaving {
                    nodes: late,
                    timeout: FINISH_TIMEOUT,
                });
            }
        }
        if self.last_message.elapsed() > IDLE_TIMEOUT {
            // What each node process last said is what it was waiting for.
            let said: Vec<String> = spawned
                .children
                .0
                .iter()
                .map(|p| format!("node {}: {}", p.name, p.last_lines()))
                .collect();
            self.stop_all(spawned, "the run stalled");
            let said = if said.is_empty() {
                String::new()
            } else {
                format!("; the node processes' last lines:\n  {}", said.join("\n  "))
            };
            return Err(Error::Silent {
                idle: IDLE_TIMEOUT,
                what: format!("the run stalled{said}"),
            });
        }
        Ok(false)
    }

    /// Whether an interface solution, or a subdomain's linear-stage counters of the last decided
    /// iteration, has yet to arrive. The counters travel on each subdomain's own key, so the
    /// decision they preceded (it needed every subdomain's state, sent just before them) may
    /// overtake them.
    fn missing_outputs(&self) -> bool {
        let model = &self.scene.model;
        self.got.interfaces.len() < model.interfaces.len()
            || self.got.iterations.last().is_some_and(|last| {
                (0..model.subdomains.len() as u32).any(|k| !self.got.linear_stages.has(last.iteration, k))
            })
    }

    /// Takes the messages still queued (sent before their nodes left), and the ones the router
    /// has yet to hand to this process's subscriber: a node's last puts may arrive after the node
    /// exited. Waits for them up to [`STRAGGLER_TIMEOUT`] while [`Self::missing_outputs`].
    pub(super) fn drain(
        &mut self,
        mut on_iteration: impl FnMut(&IterationRecord),
        observe: &mut Option<impl FnMut(&Message)>,
    ) {
        let drain_until = Instant::now() + STRAGGLER_TIMEOUT;
        loop {
            let next = match self.set_up.arrivals.try_recv() {
                Ok(m) => Some(m),
                Err(_) if self.missing_outputs() && Instant::now() < drain_until => {
                    self.set_up.arrivals.recv_timeout(Duration::from_millis(50)).ok()
                }
                Err(_) => break,
            };
            let Some(a) = next else { continue };
            if let Some(rec) = self.take(&a, observe) {
                on_iteration(&rec);
            }
        }
    }
}

/// What the launcher gathers from the bus: the decisions, the interfaces' and subdomains' final
/// fields, the set-up time and when the iterations started.
#[derive(Default)]
pub(super) struct Collected {
    pub(super) iterations: Vec<IterationRecord>,
    pub(super) interfaces: Vec<InterfaceSolution>,
    displacements: Vec<(u32, Field)>,
    setup_s: f64,
    pub(super) started: Option<Instant>,
    /// When the launcher held every result and said `done`: the end of the iterations. The node
    /// processes leave after it (the kernel's release of their memory takes some 30–80 ms at
    /// N = 1000), which is not counted, as an in-process run's release of its nodes' memory is
    /// not.
    finished: Option<Instant>,
    /// The subdomains' linear-stage counters (flops, PGD basis), untimed.
    pub(super) linear_stages: LinearStageRecords,
}
impl Collected {
    /// Keeps the results of message `m` (already checked to be its sender's kind, on its key); a
    /// decision's record is returned. Each result is taken from the node that owns it, once.
    fn take(&mut self, m: Message, plan: &Plan) -> Option<&IterationRecord> {
        let from = m.envelope.sender;
        let owns_interface = |i: u32| {
            plan.interface_groups
                .get(from.index as usize)
                .is_some_and(|g| g.contains(&(i as usize)))
        };
        if let Payload::LinearStageStats(s) = &m.payload {
            // A subdomain's own counters, each (iteration, subdomain) once.
            if from.role == Role::Subdomain && s.subdomain == from.index {
                self.linear_stages.observe(&m);
            }
            return None;
        }
        match m.payload {
            // Decisions come from interface node 0, one per iteration, in order; anything else on
            // that key is not the run's.
            Payload::Decision(_)
                if from
                    != (NodeId {
                        role: Role::Interface,
                        index: 0,
                    })
                    || self
                        .iterations
                        .last()
                        .is_some_and(|r| r.iteration >= m.envelope.iteration) => {}
            Payload::InterfaceSolution(s)
                if from.role != Role::Interface
                    || !owns_interface(s.interface)
                    || self.interfaces.iter().any(|k| k.interface == s.interface) => {}
            Payload::Displacement { subdomain, .. }
                if from.role != Role::Subdomain
                    || subdomain != from.index
                    || self.displacements.iter().any(|(k, _)| *k == subdomain) => {}
            Payload::Decision(decision) => {
                self.iterations.push(IterationRecord {
                    iteration: m.envelope.iteration,
                    elapsed_s: self.started.map_or(0.0, |t| t.elapsed().as_secs_f64()),
                    decision,
                });
                return self.iterations.last();
            }
            Payload::InterfaceSolution(s) => self.interfaces.push(s),
            Payload::Displacement { subdomain, u } => self.displacements.push((subdomain, u)),
            _ => {}
        }
        None
    }

    /// The run's result (complete, or what there is after an interruption); `verdict` when no
    /// decision came.
    pub(super) fn into_result(
        mut self,
        model: &glissade_mechanics::model::Model,
        plan: &Plan,
        verdict: Verdict,
        nodes: Vec<String>,
        left_out: Vec<String>,
    ) -> RunResult {
        self.interfaces.sort_by_key(|s| s.interface);
        let boundary = crate::boundary::boundary_resultants(model, &self.interfaces, model.moment_about);
        glissade_replay::as_reported(model, &mut self.interfaces);
        self.displacements.sort_by_key(|d| d.0);
        RunResult {
            setup_s: self.setup_s,
            solve_s: self.started.map_or(0.0, |t| {
                self.finished
                    .unwrap_or_else(Instant::now)
                    .saturating_duration_since(t)
                    .as_secs_f64()
            }),
            verdict: self.iterations.last().map_or(verdict, |r| r.decision.verdict.clone()),
            iterations: self.iterations,
            interfaces: self.interfaces,
            state: None,
            boundary,
            displacements: self.displacements,
            k0: plan.k0.clone(),
            nodes,
            left_out,
        }
    }
}

/// The node process whose liveliness token went first while the process still runs (stopped or
/// hung), and when its token went.
fn silent_peer(children: &mut Children) -> Option<(&NodeProcess, Instant)> {
    let k = children
        .0
        .iter_mut()
        .enumerate()
        .filter_map(|(k, p)| {
            let running = p.status.is_none() && p.child.try_wait().ok().flatten().is_none();
            Some((k, p.token_lost.filter(|_| running)?))
        })
        .min_by_key(|(_, lost)| *lost)
        .map(|(k, _)| k)?;
    let p = &children.0[k];
    Some((p, p.token_lost?))
}

/// What a node process has come to since the launcher last looked.
enum Look {
    /// Nothing new: it runs, or its exit was seen before.
    Unchanged,
    /// It exited successfully just now.
    Finished,
    /// It exited with a failure just now (`exited`), or it still runs but lost the bus: why.
    Dead { why: String, exited: bool },
}

/// Looks at node process `p` (unless it was seen exited before), noting its exit status; a
/// process cut off from the bus for [`EXIT_GRACE`] while it runs is dead if `lost_counts`.
fn look(p: &mut NodeProcess, lost_counts: bool) -> Result<Look> {
    if p.status.is_some() {
        return Ok(Look::Unchanged);
    }
    Ok(
        match p
            .child
            .try_wait()
            .what(|| format!("cannot wait for node process {}", p.name))?
        {
            Some(status) => {
                p.status = Some(status);
                if status.success() {
                    Look::Finished
                } else {
                    Look::Dead {
                        why: failed(p, status),
                        exited: true,
                    }
                }
            }
            None if lost_counts && p.token_lost.is_some_and(|t| t.elapsed() > EXIT_GRACE) => Look::Dead {
                why: lost_the_bus(p),
                exited: false,
            },
            None => Look::Unchanged,
        },
    )
}

/// Node process `p` exited with the failure `status`: what it said last.
fn failed(p: &NodeProcess, status: std::process::ExitStatus) -> String {
    p.output.settle();
    format!(
        "node {} failed ({status}); its last lines:\n    {}",
        p.name,
        p.last_lines()
    )
}

/// Node process `p` still runs but its liveliness token is gone: what it said last.
fn lost_the_bus(p: &NodeProcess) -> String {
    format!(
        "node {} lost its connection to the bus (its liveliness token disappeared {} s ago, the process \
         still runs); its last lines:\n    {}",
        p.name,
        EXIT_GRACE.as_secs(),
        p.last_lines()
    )
}
