//! Multi-process runs (docs/architecture.md): the launcher spawns one OS process per node group as the
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

//!
//! A run as processes is set up ([`setup`]: plan, time-coarse start, bus, scene served), its
//! processes started ([`spawn`]), supervised until they exit ([`supervise`]), and its result put
//! together here.

mod arrival;
mod hosted;
mod setup;
mod spawn;
mod stall;
mod supervise;

pub(crate) use crate::bus::unresumable;
pub use crate::bus::Network;
pub use crate::error::Interrupted;
pub(crate) use hosted::node_run;

use crate::error::{Error, Result};
use crate::runner::{IterationRecord, RunOptions, RunResult};
use glissade_messages::{Message, Verdict};
use glissade_scene::LoadedScene;
use glissade_subdomain::LinearStageRecord;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

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
pub fn install_interrupt_handler() -> Result<()> {
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only touches an atomic and calls the async-signal-safe _exit.
        let previous =
            unsafe { libc::signal(signal, on_interrupt as extern "C" fn(libc::c_int) as libc::sighandler_t) };
        if previous == libc::SIG_ERR {
            return Err(Error::Io {
                what: format!("cannot install the handler of signal {signal}"),
                source: std::io::Error::last_os_error(),
            });
        }
    }
    Ok(())
}

/// Whether SIGINT or SIGTERM was received since [`install_interrupt_handler`].
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
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
    /// Which messages `by_kind` counts.
    pub counted: Counted,
}

/// Which of a run's messages the launcher hears, and so counts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Counted {
    /// Every message of the run: the router is in the launcher's process, or the run is
    /// recorded or observed.
    #[default]
    Every,
    /// Only what the launcher keeps (decisions, final solutions and displacements, linear-stage
    /// counters): an unrecorded run through a router outside the launcher's process, whose fields
    /// the launcher does not receive.
    Kept,
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

/// The run as processes behind [`crate::run::Run::processes`]: one process per node group on the
/// bus `net` describes, nodes listed in `net.remote` left to be started by hand, a recorder
/// process writing `recording` when given. `observe`, when given, sees every message of the run
/// the launcher receives, in arrival order (the live Rerun view of a multi-process run). Without
/// it, the launcher copies and decodes only the messages it keeps (decisions, interface
/// solutions, displacements, linear-stage counters) and just counts the others, most of the bus's
/// bytes. Returns the result, the bus traffic and the subdomains' linear-stage counters (untimed).
pub(crate) fn run_processes(
    scene: &LoadedScene,
    opts: &RunOptions,
    exe: &Path,
    net: &Network,
    recording: Option<&Path>,
    mut on_iteration: impl FnMut(&IterationRecord),
    mut observe: Option<impl FnMut(&Message)>,
) -> Result<(RunResult, Traffic, Vec<LinearStageRecord>)> {
    let model = &scene.model;
    if model.interfaces.is_empty() {
        // `Run::processes` solves such a scene in-process: there is nothing to distribute.
        return Err(Error::NoInterface {
            scene: model.name.clone(),
            consequence: "nothing to run as processes",
        });
    }
    let run_id = &opts.run_id;
    let (set_up, handover) = setup::set_up(scene, opts, net, recording, observe.is_some())?;
    let mut spawned = spawn::spawn(&set_up, scene, opts, exe, net, recording)?;
    let mut supervisor = supervise::Supervisor::new(run_id, scene, &set_up, handover, net, exe, opts.interior);
    supervisor.supervise(&mut spawned, &mut on_iteration, &mut observe)?;
    supervisor.drain(&mut on_iteration, &mut observe);
    let (got, mut traffic) = (supervisor.got, supervisor.traffic);
    if got.interfaces.len() != model.interfaces.len() {
        return Err(Error::MissingSolutions {
            got: got.interfaces.len(),
            expected: model.interfaces.len(),
        });
    }
    traffic.iterations = got.iterations.len() as u64;
    traffic.counted = set_up.counted;
    let (mut names, mut left_out) = set_up.plan.describe(model, set_up.groups.len());
    names.push(format!(
        "processes: {} (+ {})",
        set_up.all_nodes.len() - set_up.hosted.len(),
        set_up.bus.description
    ));
    if !set_up.hosted.is_empty() {
        names.push(format!(
            "in the launcher's process: {}",
            set_up
                .hosted
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if let Some(r) = spawned.recorder.take() {
        let seen = traffic.by_kind.values().map(|t| t.messages).sum();
        if let Some(problem) = r.finish(&set_up.bus.session, run_id, seen) {
            crate::console::warn(&format!("recording: {problem}"));
            left_out.push(format!("recording: {problem}"));
        }
    }
    if let Some(where_) = net.starter.describe() {
        names.push(where_);
    }
    if !net.remote.is_empty() {
        names.push(format!(
            "started by hand: {}",
            net.remote.iter().map(|r| r.to_string()).collect::<Vec<_>>().join(", ")
        ));
    }
    let linear_stages = got.linear_stages.records(&[]);
    Ok((
        got.into_result(model, &set_up.plan, Verdict::MaxIterations, names, left_out),
        traffic,
        linear_stages,
    ))
}
