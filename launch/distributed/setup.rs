//! Setting a run as processes up: its plan and node processes, the time-coarse start's coarse
//! solve, the bus the launcher joins (or hosts), the scene served to the nodes and the launcher's
//! subscription to the run, and whether dead node processes are restarted.

use super::arrival::{Arrival, KEPT};
use super::unresumable;
use super::Counted;
use crate::bus::{join_bus, Bus, RECORDER};
use crate::children::{NodeName, NodeRole};
use crate::error::{zenoh, Error, Result};
use crate::runner::{RunError, RunOptions, TimeStartRun};
use glissade_bus::RunContext;
use glissade_deploy::Plan;
use glissade_messages::{encode, Message, NodeId, Payload, Role, Stage};
use glissade_scene::LoadedScene;
use glissade_zenoh as transport;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::mpsc;
use std::time::Instant;
use zenoh::Wait;

/// A run as processes, set up and not yet started: what the launcher holds while its nodes
/// start. Its subscriptions and the scene's queryable live as long as it does; the watch on the
/// nodes' liveliness tokens ([`transport::Presence`]) and the time-coarse start's solve are handed
/// to the supervisor ([`Handover`]).
pub(super) struct SetUp {
    // Fields drop in this order: the subscriptions, the scene's queryable and the launcher's
    // token before the session they were declared on (in `bus`).
    _watch: Vec<zenoh::pubsub::Subscriber<()>>,
    _scene: zenoh::query::Queryable<()>,
    _launcher_token: zenoh::liveliness::LivelinessToken,
    /// What the launcher's subscriptions to the run hear.
    pub(super) arrivals: mpsc::Receiver<Arrival>,
    /// What they are: every message of the run, or only what the launcher keeps.
    pub(super) counted: Counted,
    pub(super) plan: Plan,
    /// The subdomains of each subdomain process.
    pub(super) groups: Vec<Vec<u32>>,
    /// Every node process of the run, started here or by hand.
    pub(super) all_nodes: Vec<NodeName>,
    /// The nodes that run in the launcher's process, on its session (the router's).
    pub(super) hosted: Vec<NodeName>,
    /// Dead node processes are restarted (they resume from the recording).
    pub(super) supervised: bool,
    /// When the launcher began to set the run up (its set-up time counts from here).
    pub(super) t0: Instant,
    pub(super) bus: Bus,
}

impl SetUp {
    /// How many subdomain and interface node processes the run has.
    pub(super) fn node_counts(&self) -> crate::starter::NodeCounts {
        let count = |role| self.all_nodes.iter().filter(|n| n.role == role).count() as u32;
        crate::starter::NodeCounts {
            subdomain: count(crate::children::NodeRole::Subdomain),
            interface: count(crate::children::NodeRole::Interface),
        }
    }
    /// The liveliness token key of node `n`, and the nodes by token key.
    pub(super) fn tokens(&self, run_id: &str) -> BTreeMap<String, NodeName> {
        self.all_nodes.iter().map(|&n| (token_of(run_id, n), n)).collect()
    }

    /// The credentials of the recorder process, if the launcher hosts the router.
    pub(super) fn recorder_credentials(&self) -> Option<&transport::Credentials> {
        self.bus.credentials.get(&RECORDER)
    }
}

/// The liveliness token key of node `n` of run `run_id`.
pub(super) fn token_of(run_id: &str, n: NodeName) -> String {
    glissade_messages::topic::alive(run_id, n.role.key(), n.index)
}

/// What the supervisor takes over from the set-up: the watch on the nodes' liveliness tokens and
/// the time-coarse start's coarse solve under way.
pub(super) struct Handover {
    pub(super) presence: transport::Presence,
    pub(super) time_start: TimeStartSolve,
}

/// A time-coarse start's coarse solve, run in a thread of the launcher while the node processes
/// start and build their operators: its initial local directions are needed only after `start`.
pub(super) enum TimeStartSolve {
    Solving(std::thread::JoinHandle<std::result::Result<Option<TimeStartRun>, RunError>>),
    /// Solved (None: the scene asks for no time-coarse start, or [`Self::take`] took the result).
    Solved(Option<TimeStartRun>),
}

impl TimeStartSolve {
    /// Starts the coarse solve of `scene`, if it asks for one.
    fn start(scene: &LoadedScene, ctx: &RunContext, plan: &Plan) -> Result<Self> {
        if scene.model.solver.time_start.is_none() {
            return Ok(Self::Solved(None));
        }
        let (scene, ctx, plan) = (scene.clone(), ctx.clone(), plan.clone());
        // Unnamed: the launcher's compute threads, created on first use by this one, would take
        // its name.
        std::thread::Builder::new()
            .spawn(move || crate::runner::time_start(&scene, &ctx, &plan, None))
            .map(Self::Solving)
            .map_err(|source| Error::Io {
                what: "cannot start the thread of the time-coarse start's coarse solve".into(),
                source,
            })
    }

    /// Whether the solve is over, without waiting for it; its failure (or panic) is the error.
    pub(super) fn poll(&mut self) -> Result<bool> {
        match self {
            Self::Solving(h) if !h.is_finished() => Ok(false),
            Self::Solving(_) => {
                let Self::Solving(h) = std::mem::replace(self, Self::Solved(None)) else {
                    unreachable!("matched above")
                };
                let solved = h.join().map_err(|panic| {
                    Error::Failed(format!(
                        "the time-coarse start's coarse solve panicked: {}",
                        super::hosted::panic_message(panic.as_ref())
                    ))
                })??;
                *self = Self::Solved(solved);
                Ok(true)
            }
            Self::Solved(_) => Ok(true),
        }
    }

    /// The solve's result once [`Self::poll`] said it is over, once (None: no time-coarse start,
    /// or taken already).
    pub(super) fn take(&mut self) -> Option<TimeStartRun> {
        match self {
            Self::Solved(solved) => solved.take(),
            Self::Solving(_) => None,
        }
    }
}

/// Sets the run of `scene` up: plans it, starts a time-coarse start's coarse solve (in-process,
/// in a thread, while the nodes start; its initial local directions follow `start` on the bus),
/// checks `net.remote` names nodes of the run, joins the bus, serves the scene and subscribes to
/// the run (`keep_all`: the launcher keeps every message, not only the ones it needs, for an
/// observer), and decides whether dead node processes are restarted.
pub(super) fn set_up(
    scene: &LoadedScene,
    opts: &RunOptions,
    net: &super::Network,
    recording: Option<&Path>,
    keep_all: bool,
) -> Result<(SetUp, Handover)> {
    let t0 = Instant::now();
    let model = &scene.model;
    let run_id = &opts.run_id;
    let plan = Plan::new(model).with_scene(scene);
    let ctx = RunContext {
        run_id: run_id.clone(),
        scene_fingerprint: scene.fingerprint,
    };
    let time_start = TimeStartSolve::start(scene, &ctx, &plan)?;
    let groups = plan.groups(scene.deployment.subdomain_nodes);
    let all_nodes = run_nodes_of(&plan, groups.len());
    check_remote(net, &all_nodes)?;
    let hosted_interfaces: Vec<Vec<usize>> = (0..groups.len()).map(|g| plan.interface_nodes_in(g)).collect();
    let bus = join_bus(
        scene,
        run_id,
        net,
        recording.is_some(),
        &all_nodes,
        &groups,
        &hosted_interfaces,
    )?;
    let session = &bus.session;
    let launcher_token = transport::launcher_token(session, run_id)?;
    let presence = transport::Presence::watch(session, run_id)?;
    let launcher = NodeId {
        role: Role::Launcher,
        index: 0,
    };
    let scene_msg = Message {
        envelope: ctx.envelope(launcher, 0, Stage::Setup),
        payload: Payload::Scene {
            text: scene.text.clone(),
            overrides: scene.overrides,
        },
    };
    let queryable = transport::serve_scene(session, run_id, encode(&scene_msg))?;
    let (counted, arrivals, watch) = watch_run(session, run_id, &plan, bus.hosting, keep_all, recording.is_some())?;
    let supervised = restart_policy(scene, recording.is_some(), bus.shared_memory);
    // The interface nodes run in this process, beside the router, where nothing calls for a
    // process of their own: fields between them and the subdomain processes then cross one
    // socket instead of two.
    let hosted: Vec<NodeName> = if bus.hosting && !supervised && scene.deployment.interfaces_in_launcher {
        all_nodes
            .iter()
            .copied()
            .filter(|n| n.role == NodeRole::Interface && !net.remote.contains(n))
            .collect()
    } else {
        Vec::new()
    };
    // With --verbose: which subdomains each process hosts (as `glissade check` prints it).
    for line in plan.deployment_lines(&groups) {
        crate::console::note(&line);
    }
    let set_up = SetUp {
        plan,
        groups,
        all_nodes,
        hosted,
        bus,
        arrivals,
        counted,
        supervised,
        t0,
        _launcher_token: launcher_token,
        _scene: queryable,
        _watch: watch,
    };
    Ok((set_up, Handover { presence, time_start }))
}

/// Refuses a `--remote` node that is not one of the run's.
fn check_remote(net: &super::Network, all_nodes: &[NodeName]) -> Result<()> {
    for r in &net.remote {
        if !all_nodes.contains(r) {
            return Err(Error::Option {
                option: format!("--remote {r}"),
                why: format!(
                    "this run has no such node (its nodes: {})",
                    all_nodes.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")
                ),
            });
        }
    }
    Ok(())
}

/// The launcher's subscriptions to the run (`hosting`: it hosts the router; `keep_all`: an
/// observer wants every message; `recorded`: the recorder's end needs their count): which
/// messages it counts, the channel they arrive on, and the subscribers.
fn watch_run(
    session: &zenoh::Session,
    run_id: &str,
    plan: &Plan,
    hosting: bool,
    keep_all: bool,
    recorded: bool,
) -> Result<(Counted, mpsc::Receiver<Arrival>, Vec<zenoh::pubsub::Subscriber<()>>)> {
    // The launcher hears every message of the run where that costs no socket (the router is in
    // its process and every field crosses it anyway), where an observer wants them, or where
    // the recorder's end needs their count. Through a router outside its process, an unrecorded
    // run's fields would cross one more socket each only to be counted, and with interface nodes
    // in the subdomain processes the fields between the nodes of one process would leave it only
    // to be counted: the launcher then subscribes to what it keeps.
    let own_fields_stay = plan.interface_hosts.iter().any(Option::is_some);
    let counted = if (hosting && !own_fields_stay) || keep_all || recorded {
        Counted::Every
    } else {
        Counted::Kept
    };
    let patterns: Vec<String> = match counted {
        Counted::Every => vec![glissade_messages::run_topics(run_id)],
        Counted::Kept => KEPT
            .iter()
            .map(|(role, kind)| glissade_messages::role_field_topic(run_id, *role, kind, None))
            .collect(),
    };
    let (tx, arrivals) = mpsc::channel::<Arrival>();
    let mut watch = Vec::with_capacity(patterns.len());
    for pattern in patterns {
        let (tx, watched_run) = (tx.clone(), run_id.to_string());
        let subscriber = session
            .declare_subscriber(pattern)
            .callback(move |s| {
                let _ = tx.send(Arrival::of(s.key_expr().as_str(), s.payload(), &watched_run, keep_all));
            })
            .wait()
            .map_err(|e| zenoh("subscribe to the run", e))?;
        watch.push(subscriber);
    }

    Ok((counted, arrivals, watch))
}

/// Whether node processes that die are restarted (said as a note either way).
fn restart_policy(scene: &LoadedScene, recorded: bool, shared_memory: bool) -> bool {
    // Node processes that die mid-run are restarted (they resume from the recorder's log) when
    // the scene allows restarts, the run is recorded completely and its fields do not go through
    // shared memory; otherwise a death stops the run, and the launcher says why up front.
    //
    // Shared memory: a message lies in its sender's pool, and Zenoh (1.10.2) drops, with no more
    // than a debug log ("Error receiving SHM buffer: Buffer is invalidated"), a message whose
    // shared buffer a receiver no longer takes as valid, which happens to the last messages of a
    // process killed mid-run. The recorder may hold such a message and a node not: the resumed
    // node then takes it for already delivered and never sends it again, and the node that
    // missed it waits.
    let restarts = scene.deployment.restarts;
    let no_resume = unresumable(scene, recorded).or_else(|| {
        shared_memory.then(|| {
            "network.shared_memory = true: a killed node's last messages may reach some nodes and not others"
                .to_string()
        })
    });
    let supervised = restarts > 0 && no_resume.is_none();
    match (restarts > 0, &no_resume) {
        (true, Some(why)) => crate::console::note(&format!(
            "node restarts off ({why}): a node process that dies stops the run"
        )),
        (true, None) => crate::console::note(&format!(
            "node restarts on: a node process the launcher started that dies is restarted, up to {restarts} \
             times (deployment.restarts), and resumes from the recording"
        )),
        (false, _) => {
            crate::console::note("node restarts off (deployment.restarts = 0): a node process that dies stops the run")
        }
    }
    supervised
}

/// The `glissade node` arguments of node `name` (after the executable); `tls`: its `--tls-*`
/// arguments ([`crate::bus::tls_args`]) and the `--credentials` argument.
pub(super) fn node_args(
    name: NodeName,
    run_id: &str,
    connect: &[String],
    interior: bool,
    tls: &[String],
) -> Vec<String> {
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

/// The node processes a run needs: one per subdomain group, one per interface group not run by a
/// subdomain process, the coarse node.
fn run_nodes_of(plan: &Plan, groups: usize) -> Vec<NodeName> {
    let mut names: Vec<NodeName> = (0..groups as u32)
        .map(|index| NodeName {
            role: NodeRole::Subdomain,
            index,
        })
        .collect();
    names.extend(
        (0..plan.interface_groups.len() as u32)
            .filter(|&k| plan.interface_hosts[k as usize].is_none())
            .map(|index| NodeName {
                role: NodeRole::Interface,
                index,
            }),
    );
    if plan.coarse {
        names.push(NodeName {
            role: NodeRole::Coarse,
            index: 0,
        });
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// Polls `solve` until it is over (at most 10 s): its result or its error.
    fn settle(solve: &mut TimeStartSolve) -> Result<Option<TimeStartRun>> {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !solve.poll()? {
            assert!(Instant::now() < deadline, "the solve's thread did not end");
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(solve.take())
    }

    /// A coarse solve that fails or panics in its thread is the run's error, named, as soon as
    /// its thread ends; one that is still running is not over; a result is taken once.
    #[test]
    fn a_failed_coarse_solve_is_an_error_naming_it() {
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let mut failed = TimeStartSolve::Solving(std::thread::spawn(move || {
            let _ = rx.recv();
            Err(RunError::TimeStart(
                "the coarse solve on 100 steps ended Diverged".into(),
            ))
        }));
        assert!(!failed.poll().expect("still running"), "not over while its thread runs");
        assert!(failed.take().is_none(), "nothing to take while it runs");
        tx.send(()).expect("the thread waits");
        let e = crate::error::chain(&settle(&mut failed).expect_err("a failed solve"));
        assert!(
            e.contains("time-coarse start (solver.time_coarsening): the coarse solve on 100 steps ended Diverged"),
            "{e}"
        );

        let mut panicked = TimeStartSolve::Solving(std::thread::spawn(|| panic!("an index out of bounds")));
        let e = crate::error::chain(&settle(&mut panicked).expect_err("a panicked solve"));
        assert!(
            e.contains("the time-coarse start's coarse solve panicked: an index out of bounds"),
            "{e}"
        );

        let mut none = TimeStartSolve::Solving(std::thread::spawn(|| Ok(None)));
        assert!(settle(&mut none).expect("solved").is_none());
        assert!(none.poll().expect("over"), "taken: over");
    }
}
