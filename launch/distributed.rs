//! Multi-process runs (DESIGN §4): the launcher spawns one OS process per node group as the
//! scene's deployment section says (subdomain groups, interface nodes, the coarse node), hosts the Zenoh router they connect to (or connects to a
//! `zenohd` router), serves them the scene over the bus, forwards their logs with a prefix,
//! watches the run's messages for progress and results, and stops every node when one fails or
//! when it is interrupted (Ctrl-C, SIGTERM). Nodes may also be started by hand on other machines
//! (`glissade node`); the launcher then waits, bounded, for their liveliness tokens.
//!
//! Failure handling: the launcher watches its children's exit statuses and every node's
//! liveliness token. The first node that exits with a failure, or whose token disappears before
//! the run is over, is named in the error with its exit status (when it is a child) and its last
//! log lines; the launcher then publishes `stop`, waits briefly for the others to leave and kills
//! what is left. Every node also watches the others' tokens and the launcher's, so a run stops
//! even if the launcher itself is killed (local children also die with it: parent-death signal).

use crate::bus::{join_bus, tls_args, write_credentials, Bus, CredentialFiles, RECORDER};
use crate::children::{spawn_node, Children, NodeName, NodeRole};
use crate::runner::{IterationRecord, RunOptions, RunResult};
use anyhow::bail;
use glissade_bus::RunContext;
use glissade_deploy::Plan;
use glissade_messages::{encode, Expected, Field, InterfaceSolution, Message, NodeId, Payload, Role, Stage, Verdict};
use glissade_scene::LoadedScene;
use glissade_zenoh as transport;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How long nodes may take to fetch the scene, build their operators and report ready.
pub(crate) const READY_TIMEOUT: Duration = Duration::from_secs(300);
/// Longest silence on the bus before a run is declared stalled.
pub(crate) const IDLE_TIMEOUT: Duration = Duration::from_secs(600);
/// After a peer's token disappears, how long a node still handles messages already on their way
/// before it gives up (a peer that finished leaves right after its last messages).
pub(crate) const DEPARTURE_GRACE: Duration = Duration::from_secs(2);
/// How long a child whose token disappeared may take to exit before it counts as failed.
const EXIT_GRACE: Duration = Duration::from_secs(3);
/// How long nodes get to leave after `stop` before they are killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);
/// How long nodes started by hand may take to leave once the run has ended.
const FINISH_TIMEOUT: Duration = Duration::from_secs(30);
/// How long a node process whose nodes are finished waits for the launcher's word that it holds
/// the run's results before it leaves anyway.
pub(crate) const DONE_TIMEOUT: Duration = Duration::from_secs(30);
/// Longest wait, once every node process has exited, for its last messages still on their way
/// through the router.
const STRAGGLER_TIMEOUT: Duration = Duration::from_secs(5);

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_interrupt(_signal: libc::c_int) {
    if INTERRUPTED.swap(true, Ordering::SeqCst) {
        // A second Ctrl-C: leave at once (children die with us: parent-death signal).
        // SAFETY: _exit is async-signal-safe.
        unsafe { libc::_exit(130) };
    }
}

/// Makes SIGINT and SIGTERM request a clean stop of the run (see [`interrupted`]); a second
/// signal exits at once with status 130.
pub fn install_interrupt_handler() -> anyhow::Result<()> {
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only touches an atomic and calls the async-signal-safe _exit.
        let previous =
            unsafe { libc::signal(signal, on_interrupt as extern "C" fn(libc::c_int) as libc::sighandler_t) };
        if previous == libc::SIG_ERR {
            bail!("cannot install the handler of signal {signal}");
        }
    }
    Ok(())
}

/// Whether SIGINT or SIGTERM was received since [`install_interrupt_handler`].
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// Where the run's bus is and which nodes the launcher leaves to be started elsewhere.
#[derive(Debug, Clone, Default)]
pub struct Network {
    /// Endpoints the launcher's router listens on (e.g. `tcp/0.0.0.0:7447`); empty: a free
    /// loopback port.
    pub listen: Vec<String>,
    /// Router endpoints (e.g. a `zenohd`) the launcher and its nodes connect to instead of the
    /// launcher hosting the router.
    pub connect: Vec<String>,
    /// Nodes the launcher does not start: they are started by hand with `glissade node`.
    pub remote: Vec<NodeName>,
    /// Longest wait for the nodes started by hand to be ready (default: 300 s).
    pub remote_timeout: Option<Duration>,
    /// MCAP file a recorder process writes every message of the run to; None: no recorder.
    pub recording: Option<std::path::PathBuf>,
    /// Folder where the credentials of the nodes started by hand (`remote`) are written, one
    /// file each, readable by this user only, removed when the run ends (the run's `--out`).
    pub credentials: Option<std::path::PathBuf>,
}

/// Messages and bytes of one kind seen on the bus.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct KindTraffic {
    pub messages: u64,
    pub bytes: u64,
}

/// What crossed the bus during a run, by message kind (the field chunk of the key), as encoded.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Traffic {
    pub by_kind: BTreeMap<String, KindTraffic>,
    /// Iterations (decisions) of the run, to express the traffic per iteration.
    pub iterations: u64,
}

/// The run was interrupted (SIGINT/SIGTERM); every node was stopped. `partial` holds the
/// iterations done so far.
#[derive(Debug, thiserror::Error)]
#[error("interrupted after {} iteration(s); every node was stopped", .partial.iterations.len())]
pub struct Interrupted {
    pub partial: RunResult,
}

/// How a node process takes part in a run.
#[derive(Debug, Clone, Copy, Default)]
pub struct Supervision {
    /// Send the full displacement fields at the end (subdomain role, `glissade node --interior`).
    pub interior: bool,
    /// The launcher restarts node processes that die (`glissade node --supervised`).
    pub supervised: bool,
    /// This process replaces one that died (`glissade node --resume`).
    pub resume: bool,
    /// Pass fields to processes on this machine through shared memory (`glissade node
    /// --shared-memory`, the scene's `network.shared_memory`).
    pub shared_memory: bool,
}

/// Why a dead node process could not resume from the recording of a run (`recorded` or not) of
/// `scene`, whatever the transport: no recording, or an incomplete one.
pub(crate) fn unresumable(scene: &LoadedScene, recorded: bool) -> Option<String> {
    if recorded {
        scene.recording.incomplete()
    } else {
        Some("the run is not recorded".to_string())
    }
}

/// The `glissade node` arguments of node `name` (after the executable); `tls`: its `--tls-*`
/// arguments ([`tls_args`]) and the `--credentials` argument.
fn node_args(name: NodeName, run_id: &str, connect: &[String], interior: bool, tls: &[String]) -> Vec<String> {
    let mut args = vec![
        "node".to_string(),
        name.role.key().to_string(),
        "--run".into(),
        run_id.into(),
    ];
    for c in connect {
        args.extend(["--connect".to_string(), c.clone()]);
    }
    if name.role != NodeRole::Coarse {
        args.extend(["--index".to_string(), name.index.to_string()]);
    }
    if name.role == NodeRole::Subdomain && interior {
        args.push("--interior".into());
    }
    args.extend_from_slice(tls);
    args
}

/// The node processes a run needs: one per subdomain group, one per interface group, the coarse
/// node.
fn run_nodes_of(plan: &Plan, groups: usize) -> Vec<NodeName> {
    let mut names: Vec<NodeName> = (0..groups as u32)
        .map(|index| NodeName {
            role: NodeRole::Subdomain,
            index,
        })
        .collect();
    names.extend((0..plan.interface_groups.len() as u32).map(|index| NodeName {
        role: NodeRole::Interface,
        index,
    }));
    if plan.coarse {
        names.push(NodeName {
            role: NodeRole::Coarse,
            index: 0,
        });
    }
    names
}

/// Runs `scene` with one process per node group, all on this machine over loopback.
pub fn run_multi_process(
    scene: &LoadedScene,
    opts: &RunOptions,
    exe: &Path,
    on_iteration: impl FnMut(&IterationRecord),
) -> anyhow::Result<RunResult> {
    run_distributed(scene, opts, exe, &Network::default(), on_iteration).map(|(result, _)| result)
}

/// Runs `scene` with one process per node group on the bus `net` describes; nodes listed in
/// `net.remote` are left to be started by hand. Returns the result and the bus traffic.
pub fn run_distributed(
    scene: &LoadedScene,
    opts: &RunOptions,
    exe: &Path,
    net: &Network,
    on_iteration: impl FnMut(&IterationRecord),
) -> anyhow::Result<(RunResult, Traffic)> {
    run_distributed_observed(scene, opts, exe, net, on_iteration, None::<fn(&Message)>)
}

/// As [`run_distributed`]; `observe`, when given, sees every message of the run the launcher
/// receives, in arrival order (the live Rerun view of a multi-process run). Without it, the
/// launcher copies and decodes only the messages it keeps (decisions, interface solutions,
/// displacements) and just counts the others, most of the bus's bytes.
pub fn run_distributed_observed(
    scene: &LoadedScene,
    opts: &RunOptions,
    exe: &Path,
    net: &Network,
    mut on_iteration: impl FnMut(&IterationRecord),
    mut observe: Option<impl FnMut(&Message)>,
) -> anyhow::Result<(RunResult, Traffic)> {
    let model = &scene.model;
    if model.interfaces.is_empty() {
        // Nothing to distribute: the in-process direct solve.
        let result = crate::runner::run_in_process(scene, opts, on_iteration)?;
        return Ok((result, Traffic::default()));
    }
    let t0 = Instant::now();
    let run_id = &opts.run_id;
    let plan = Plan::new(model).with_scene(scene);
    // A time-coarse start's coarse solve runs here, in-process, before the nodes start; its
    // initial local directions follow `start` on the bus.
    let time_start = crate::runner::time_start(
        scene,
        &RunContext {
            run_id: run_id.clone(),
            scene_fingerprint: scene.fingerprint,
        },
        &plan,
        None,
    )?;
    if let Some(t) = &time_start {
        crate::console::note(&format!("run {run_id}: {}", t.describe()));
    }
    let groups = plan.groups(scene.deployment.subdomain_nodes);
    let all_nodes = run_nodes_of(&plan, groups.len());
    for r in &net.remote {
        if !all_nodes.contains(r) {
            bail!(
                "--remote {r}: this run has no such node (its nodes: {})",
                all_nodes.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")
            );
        }
    }
    let Bus {
        session,
        node_connect,
        description: bus,
        hosting,
        shared_memory,
        node_args: node_tls,
        credentials,
    } = join_bus(scene, run_id, net, &all_nodes, &groups)?;
    let _launcher_token = transport::launcher_token(&session, run_id)?;
    let mut presence = transport::Presence::watch(&session, run_id)?;
    let launcher = NodeId {
        role: Role::Launcher,
        index: 0,
    };
    let scene_msg = Message {
        envelope: RunContext {
            run_id: run_id.clone(),
            scene_fingerprint: scene.fingerprint,
        }
        .envelope(launcher, 0, Stage::Setup),
        payload: Payload::Scene {
            text: scene.text.clone(),
            overrides: scene.overrides,
        },
    };
    let _queryable = transport::serve_scene(&session, run_id, encode(&scene_msg))?;
    let (tx, rx) = mpsc::channel::<Arrival>();
    let (watched_run, keep_all) = (run_id.clone(), observe.is_some());
    let _watch = session
        .declare_subscriber(glissade_messages::run_topics(run_id))
        .callback(move |s| {
            let _ = tx.send(Arrival::of(s.key_expr().as_str(), s.payload(), &watched_run, keep_all));
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: subscribe to the run: {e}"))?;

    // Node processes that die mid-run are restarted (they resume from the recorder's log) when
    // the scene allows restarts, the run is recorded completely and its fields do not go through
    // shared memory; otherwise a death stops the run, and the launcher says why up front.
    //
    // Shared memory: a message lies in its sender's pool, and Zenoh (1.10.2) drops, with no more
    // than a debug log ("Error receiving SHM buffer: Buffer is invalidated"), a message whose
    // shared buffer a receiver no longer takes as valid, which happens to the last messages of a
    // process killed mid-run. The recorder may hold such a message and a node not: the resumed
    // node then takes it for already delivered and never sends it again, and the node that
    // missed it waits (seen with shared memory forced on in the restart test, on a loaded
    // machine: 2 of 100 runs went wrong, a stall and a recorder missing 7 messages).
    let restarts = scene.deployment.restarts;
    let no_resume = unresumable(scene, net.recording.is_some()).or_else(|| {
        shared_memory.then(|| {
            "network.shared_memory = true: a killed node's last messages may reach some nodes and not others"
                .to_string()
        })
    });
    let supervised = restarts > 0 && no_resume.is_none();
    if let (true, Some(why)) = (restarts > 0, &no_resume) {
        crate::console::note(&format!(
            "node restarts off ({why}): a node process that dies stops the run"
        ));
    }
    let with_supervision = |mut args: Vec<String>| {
        if supervised {
            args.push("--supervised".into());
        }
        args
    };
    let mut restarted: BTreeMap<NodeName, usize> = BTreeMap::new();
    // Spawn the local node processes; tell how to start the others.
    let mut children = Children(Vec::new());
    for &name in all_nodes.iter().filter(|n| !net.remote.contains(n)) {
        let args = with_supervision(node_args(name, run_id, &node_connect, opts.interior, &node_tls));
        children
            .0
            .push(spawn_node(exe, name, &args, credentials.get(&name.id()).cloned())?);
    }
    let mut recorder = match &net.recording {
        Some(path) => Some(crate::recording::spawn_recorder_process(
            exe,
            &session,
            run_id,
            &node_connect[0],
            &node_tls,
            credentials.get(&RECORDER),
            path,
        )?),
        None => None,
    };
    let remote_timeout = net.remote_timeout.unwrap_or(READY_TIMEOUT);
    let mut hand_credentials = CredentialFiles(Vec::new());
    if !net.remote.is_empty() {
        let connect: Vec<String> = if net.connect.is_empty() {
            net.listen
                .iter()
                .map(|l| l.replace("/0.0.0.0:", "/<this machine's address>:"))
                .collect()
        } else {
            net.connect.clone()
        };
        eprintln!(
            "waiting up to {} s for {} node(s) started by hand; on the other machine(s) run:",
            remote_timeout.as_secs(),
            net.remote.len()
        );
        let mut remote_tls = match &scene.network.tls {
            Some(t) => {
                eprintln!(
                    "(TLS: copy {} to the other machine(s){})",
                    t.root_ca.display(),
                    if t.mutual {
                        "; each node presents its own certificate signed by it"
                    } else {
                        ""
                    }
                );
                let ca = Path::new(t.root_ca.file_name().unwrap_or(t.root_ca.as_os_str()));
                let identity = (Path::new("<node-cert.pem>"), Path::new("<node-key.pem>"));
                tls_args(ca, t.mutual.then_some(identity))
            }
            None => Vec::new(),
        };
        remote_tls.extend(shared_memory.then(|| "--shared-memory".to_string()));
        let dir = match (&net.credentials, hosting) {
            (Some(d), true) => Some(d),
            (None, true) => bail!("nodes started by hand need their credentials written to a folder (none given)"),
            (_, false) => None,
        };
        for &r in &net.remote {
            let mut args = remote_tls.clone();
            if let Some(dir) = dir {
                let cr = &credentials[&r.id()];
                let file = write_credentials(dir, run_id, r, cr)?;
                eprintln!(
                    "(node {r}: copy {} to its machine, readable by its user only; it lets a process speak as {r} in \
                     this run and nothing else)",
                    file.display()
                );
                hand_credentials.0.push(file.clone());
                let name = file.file_name().map(PathBuf::from).unwrap_or(file);
                args.extend(["--credentials".to_string(), name.display().to_string()]);
            }
            eprintln!(
                "  glissade {}",
                with_supervision(node_args(r, run_id, &connect, opts.interior, &args)).join(" ")
            );
        }
    }
    let expected = Expected {
        run_id: run_id.clone(),
        scene_fingerprint: scene.fingerprint,
    };
    let token_of = |n: NodeName| glissade_messages::topic::alive(run_id, n.role.key(), n.index);
    let tokens: BTreeMap<String, NodeName> = all_nodes.iter().map(|&n| (token_of(n), n)).collect();

    // Stops every node, then fails with `error`.
    let stop_all = |children: &mut Children, reason: &str| {
        let _ = transport::publish_stop(&session, run_id, reason);
        children.wait_all(STOP_TIMEOUT);
    };

    let mut got = Collected::default();
    // The launcher tells the nodes to leave once it holds the final decision and every final
    // output (a node that closed its session right after its last put could lose it).
    let final_displacements: usize = if opts.interior {
        groups.iter().map(Vec::len).sum()
    } else {
        0
    };
    let mut done_sent = false;
    let mut heard: std::collections::HashSet<u64> = std::collections::HashSet::new();
    let mut traffic = Traffic::default();
    let mut remote_lost: BTreeMap<NodeName, Instant> = BTreeMap::new();
    let mut stop_seen = false;
    let mut ended_at: Option<Instant> = None;
    let mut last_message = Instant::now();
    loop {
        if interrupted() {
            stop_all(&mut children, "the launcher was interrupted");
            let (nodes, left_out) = plan.describe(model, groups.len());
            return Err(Interrupted {
                partial: got.into_result(&plan, Verdict::Continue, nodes, left_out),
            }
            .into());
        }
        // Which node failed first, if any.
        for (key, up) in presence.changes() {
            let Some(&name) = tokens.get(&key) else { continue };
            if let Some(p) = children.0.iter_mut().find(|p| p.name == name) {
                if up {
                    p.token_seen = true;
                    p.token_lost = None;
                } else if p.status.is_none() && p.token_seen {
                    p.token_lost = Some(Instant::now());
                }
            } else if !up {
                remote_lost.entry(name).or_insert_with(Instant::now);
            }
        }
        let mut child_failure: Option<String> = None;
        let mut dead: Option<usize> = None;
        for (k, p) in children.0.iter_mut().enumerate() {
            if p.status.is_some() || child_failure.is_some() {
                continue;
            }
            if let Some(status) = p.child.try_wait()? {
                p.status = Some(status);
                if !status.success() {
                    p.output.settle();
                    child_failure = Some(format!(
                        "node {} failed ({status}); its last lines:\n    {}",
                        p.name,
                        p.last_lines()
                    ));
                    dead = Some(k);
                } else if got.started.is_none() {
                    child_failure = Some(format!("node {} exited before the run started", p.name));
                }
            } else if p.token_lost.is_some_and(|t| t.elapsed() > EXIT_GRACE) {
                child_failure = Some(format!(
                    "node {} lost its connection to the bus (its liveliness token disappeared {} s ago, \
                     the process still runs); its last lines:\n    {}",
                    p.name,
                    EXIT_GRACE.as_secs(),
                    p.last_lines()
                ));
                dead = Some(k);
            }
        }
        // A node that exited because a peer left is not the culprit when that peer's token went
        // first while its process still runs (stopped or hung): name the peer.
        if let Some(k) = dead.filter(|&k| children.0[k].status.is_some()) {
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
                child_failure = Some(match p.child.try_wait()? {
                    // It died too (before the other, as its token says): the usual report.
                    Some(status) => {
                        p.status = Some(status);
                        p.output.settle();
                        format!(
                            "node {} failed ({status}); its last lines:\n    {}",
                            p.name,
                            p.last_lines()
                        )
                    }
                    None => format!(
                        "node {} stopped answering: its liveliness token disappeared {:.1} s ago, before node \
                         {exited} failed, while its process still runs (stopped or hung?); its last lines:\n    {}",
                        p.name,
                        lost.elapsed().as_secs_f64(),
                        p.last_lines()
                    ),
                });
                dead = Some(j);
            }
        }
        // A node process that died mid-run: a replacement resumes from the recorder's log, up to
        // `restarts` times per node.
        if let (Some(k), Some(why), true) = (dead, &child_failure, supervised && got.started.is_some()) {
            let name = children.0[k].name;
            let count = restarted.entry(name).or_default();
            let why_short = why.split("; its last lines").next().unwrap_or(why).to_string();
            if *count < restarts {
                *count += 1;
                eprintln!(
                    "{why_short}; restarting it ({} of {restarts}): it resumes from the recording",
                    *count
                );
                let p = &mut children.0[k];
                let _ = p.child.kill();
                let _ = p.child.wait();
                let base = p.args.clone();
                let mut args = base.clone();
                args.push("--resume".into());
                let credentials = p.credentials.clone();
                *p = spawn_node(exe, name, &args, credentials)?;
                p.args = base;
                child_failure = None;
            } else {
                child_failure = Some(format!(
                    "node {name} died again after {restarts} restart(s) (deployment.restarts = {restarts}): {why}"
                ));
            }
        }
        // A node started by hand that left before the end is the culprit if it left first (the
        // others leave after it, DEPARTURE_GRACE later); messages already sent may still bring
        // the stop decision within that grace.
        let first_remote_lost = remote_lost.iter().min_by_key(|(_, &t)| t).map(|(&n, &t)| (n, t));
        let mut failure = match first_remote_lost {
            Some((name, lost)) if !stop_seen && (lost.elapsed() > DEPARTURE_GRACE || child_failure.is_some()) => {
                Some(format!(
                    "node {name} (started by hand elsewhere) left the run before it finished; \
                     its exit status and log are on its own machine"
                ))
            }
            _ => child_failure,
        };
        if got.started.is_none() && failure.is_none() {
            failure = recorder
                .as_mut()
                .and_then(|r| r.check().err())
                .map(|e| format!("{e:#}"));
        }
        let recorder_ready = recorder.as_ref().is_none_or(|r| r.is_ready());
        if got.started.is_none() && failure.is_none() {
            let missing: Vec<NodeName> = tokens
                .iter()
                .filter(|(k, _)| !presence.is_alive(k))
                .map(|(_, &n)| n)
                .collect();
            if missing.is_empty() && recorder_ready {
                transport::publish_start(&session, run_id)?;
                for m in time_start.iter().flat_map(|t| &t.messages) {
                    transport::publish(&session, m)?;
                }
                got.setup_s = t0.elapsed().as_secs_f64();
                got.started = Some(Instant::now());
                last_message = Instant::now();
                crate::console::note(&format!("run {run_id}: {} node(s) ready, iterating", all_nodes.len()));
            } else {
                let local_late = missing.iter().any(|n| !net.remote.contains(n)) && t0.elapsed() > READY_TIMEOUT;
                let remote_late = missing.iter().any(|n| net.remote.contains(n)) && t0.elapsed() > remote_timeout;
                if local_late || remote_late {
                    failure = Some(format!(
                        "nodes not ready within {} s: {} (a node started by hand must use --run {run_id} and \
                         reach the bus)",
                        if remote_late { remote_timeout } else { READY_TIMEOUT }.as_secs(),
                        missing.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")
                    ));
                }
            }
        }
        if let Some(f) = failure {
            stop_all(
                &mut children,
                &format!("the run failed: {}", f.split("; its last lines").next().unwrap_or("")),
            );
            bail!("{f}");
        }
        if got.started.is_none() {
            // Waiting for the nodes' tokens: look again every few milliseconds (the run starts
            // as soon as the last node is ready).
            if let Ok(a) = rx.recv_timeout(Duration::from_millis(5)) {
                count(&mut traffic, &a);
            }
            continue;
        }
        // Once `done` is out the node processes are leaving: look for their exits every few
        // milliseconds instead of every 50 ms.
        let poll = if done_sent {
            Duration::from_millis(2)
        } else {
            Duration::from_millis(50)
        };
        match rx.recv_timeout(poll) {
            Ok(a) => {
                last_message = Instant::now();
                let Some(bytes) = count(&mut traffic, &a) else { continue };
                // A restarted node re-sends outputs its predecessor may have sent already.
                if !heard.insert(transport::payload_hash(&a.key, bytes)) {
                    continue;
                }
                let Ok(m) = transport::decode_payload(bytes, &expected, Default::default()) else {
                    continue;
                };
                // Only what its sender may send, on its sender's key (a member may publish on
                // its own keys only, but anything there).
                if m.not_from_its_sender(&a.key).is_some() {
                    continue;
                }
                if let Some(o) = observe.as_mut() {
                    o(&m);
                }
                if let Some(rec) = got.take(m, &plan) {
                    stop_seen |= rec.decision.verdict.is_stop();
                    on_iteration(rec);
                }
                if !done_sent
                    && stop_seen
                    && got.interfaces.len() == model.interfaces.len()
                    && got.displacements.len() >= final_displacements
                {
                    transport::publish_done(&session, run_id)?;
                    got.finished = Some(Instant::now());
                    done_sent = true;
                }
            }
            Err(_) => {
                let locals_done = children.0.iter().all(|p| p.status.is_some());
                let remotes_gone = net.remote.iter().all(|&r| !presence.is_alive(&token_of(r)));
                if locals_done && remotes_gone {
                    break;
                }
                if locals_done && stop_seen {
                    let since = *ended_at.get_or_insert_with(Instant::now);
                    if since.elapsed() > FINISH_TIMEOUT {
                        let late: Vec<String> = net
                            .remote
                            .iter()
                            .filter(|&&r| presence.is_alive(&token_of(r)))
                            .map(|r| r.to_string())
                            .collect();
                        stop_all(&mut children, "the run is over");
                        bail!(
                            "node(s) {} did not leave within {} s after the run ended",
                            late.join(", "),
                            FINISH_TIMEOUT.as_secs()
                        );
                    }
                }
                if last_message.elapsed() > IDLE_TIMEOUT {
                    stop_all(&mut children, "the run stalled");
                    bail!(
                        "no message on the bus for {} s: the run stalled",
                        IDLE_TIMEOUT.as_secs()
                    );
                }
            }
        }
    }
    // Messages still queued (sent before their nodes left), and the ones the router has yet to
    // hand to this process's subscriber: a node's last puts may arrive after the node exited.
    let drain_until = Instant::now() + STRAGGLER_TIMEOUT;
    loop {
        let next = match rx.try_recv() {
            Ok(m) => Some(m),
            Err(_) if got.interfaces.len() < model.interfaces.len() && Instant::now() < drain_until => {
                rx.recv_timeout(Duration::from_millis(50)).ok()
            }
            Err(_) => break,
        };
        let Some(a) = next else { continue };
        let Some(bytes) = count(&mut traffic, &a) else { continue };
        if !heard.insert(transport::payload_hash(&a.key, bytes)) {
            continue;
        }
        if let Ok(m) = transport::decode_payload(bytes, &expected, Default::default()) {
            if m.not_from_its_sender(&a.key).is_some() {
                continue;
            }
            if let Some(o) = observe.as_mut() {
                o(&m);
            }
            if let Some(rec) = got.take(m, &plan) {
                on_iteration(rec);
            }
        }
    }
    if got.interfaces.len() != model.interfaces.len() {
        bail!(
            "the run ended with {} of the {} interface solutions on the bus",
            got.interfaces.len(),
            model.interfaces.len()
        );
    }
    traffic.iterations = got.iterations.len() as u64;
    let (mut names, mut left_out) = plan.describe(model, groups.len());
    names.push(format!("processes: {} (+ {bus})", all_nodes.len()));
    if let Some(r) = recorder {
        let seen = traffic.by_kind.values().map(|t| t.messages).sum();
        if let Some(problem) = r.finish(&session, run_id, seen) {
            eprintln!("warning: recording: {problem}");
            left_out.push(format!("recording: {problem}"));
        }
    }
    if !net.remote.is_empty() {
        names.push(format!(
            "started by hand: {}",
            net.remote.iter().map(|r| r.to_string()).collect::<Vec<_>>().join(", ")
        ));
    }
    Ok((got.into_result(&plan, Verdict::MaxIterations, names, left_out), traffic))
}

/// What the launcher gathers from the bus: the decisions, the interfaces' and subdomains' final
/// fields, the set-up time and when the iterations started.
#[derive(Default)]
struct Collected {
    iterations: Vec<IterationRecord>,
    interfaces: Vec<InterfaceSolution>,
    displacements: Vec<(u32, Field)>,
    setup_s: f64,
    started: Option<Instant>,
    /// When the launcher held every result and said `done`: the end of the iterations. The node
    /// processes leave after it (the kernel's release of their memory takes some 30–80 ms at
    /// N = 1000), which is not counted, as an in-process run's release of its nodes' memory is
    /// not.
    finished: Option<Instant>,
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
    fn into_result(mut self, plan: &Plan, verdict: Verdict, nodes: Vec<String>, left_out: Vec<String>) -> RunResult {
        self.interfaces.sort_by_key(|s| s.interface);
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
            displacements: self.displacements,
            k0: plan.k0.clone(),
            nodes,
            left_out,
        }
    }
}

/// A message as the launcher's subscriber passes it on.
struct Arrival {
    key: String,
    /// Its size on the bus.
    size: usize,
    /// Its envelope says it belongs to the run.
    ours: bool,
    /// The message, when the launcher keeps it ([`Arrival::of`]): Zenoh's buffers themselves,
    /// read where they are by the thread that decodes them.
    bytes: Option<zenoh::bytes::ZBytes>,
}

impl Arrival {
    /// A message of run `run_id` seen on `key`: Zenoh's buffers are kept (shared, not copied)
    /// only if it is the run's and it is a decision, an interface solution or a displacement
    /// (what the launcher keeps), or `keep_all`; the multi-MB fields in between are only
    /// counted. The launcher's main thread decodes the kept ones straight from those buffers:
    /// a copy made here, on Zenoh's receiving thread, took its memory from that thread's
    /// allocator arena, fresh pages from the kernel for the 141 MB of final solutions at
    /// N = 1000, freed again on the main thread once decoded.
    fn of(key: &str, payload: &zenoh::bytes::ZBytes, run_id: &str, keep_all: bool) -> Self {
        // The envelope is the message's first bytes: the first slice holds it unless the
        // message came in tiny fragments, then the whole message is looked at.
        let first = payload.slices().next().unwrap_or(&[]);
        let ours = glissade_messages::peek_envelope(first, run_id).is_ok()
            || (first.len() < payload.len() && glissade_messages::peek_envelope(&payload.to_bytes(), run_id).is_ok());
        let kept = keep_all || matches!(kind_of(key), "decision" | "interface_solution" | "displacement");
        Self {
            key: key.to_string(),
            size: payload.len(),
            ours,
            bytes: (ours && kept).then(|| payload.clone()),
        }
    }
}

/// The field of a key ("?" if it has none).
fn kind_of(key: &str) -> &str {
    glissade_messages::topic_field(key).unwrap_or("?")
}

/// Adds a message to the traffic if it belongs to the run (its envelope says so); returns its
/// bytes if the launcher keeps them.
fn count<'a>(traffic: &mut Traffic, a: &'a Arrival) -> Option<&'a zenoh::bytes::ZBytes> {
    if !a.ours {
        return None;
    }
    let t = traffic.by_kind.entry(kind_of(&a.key).to_string()).or_default();
    t.messages += 1;
    t.bytes += a.size as u64;
    a.bytes.as_ref()
}
