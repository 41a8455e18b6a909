//! Setting a run as processes up: its plan and node processes, the time-coarse start's coarse
//! solve, the bus the launcher joins (or hosts), the scene served to the nodes and the launcher's
//! subscription to the run, and whether dead node processes are restarted.

use super::supervise::{Arrival, KEPT};
use super::unresumable;
use super::Counted;
use crate::bus::{join_bus, Bus, RECORDER};
use crate::children::{NodeName, NodeRole};
use crate::error::{zenoh, Error, Result};
use crate::runner::{RunOptions, TimeStartRun};
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
/// nodes' liveliness tokens ([`transport::Presence`]) is handed to the supervisor.
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
    pub(super) time_start: Option<TimeStartRun>,
    /// Dead node processes are restarted (they resume from the recording).
    pub(super) supervised: bool,
    /// When the launcher began to set the run up (its set-up time counts from here).
    pub(super) t0: Instant,
    pub(super) bus: Bus,
}

impl SetUp {
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

/// Sets the run of `scene` up: plans it, runs a time-coarse start's coarse solve (in-process,
/// before the nodes start; its initial local directions follow `start` on the bus), checks
/// `net.remote` names nodes of the run, joins the bus, serves the scene and subscribes to the
/// run (`keep_all`: the launcher keeps every message, not only the ones it needs, for an
/// observer), and decides whether dead node processes are restarted.
pub(super) fn set_up(
    scene: &LoadedScene,
    opts: &RunOptions,
    net: &super::Network,
    recording: Option<&Path>,
    keep_all: bool,
) -> Result<(SetUp, transport::Presence)> {
    let t0 = Instant::now();
    let model = &scene.model;
    let run_id = &opts.run_id;
    let plan = Plan::new(model).with_scene(scene);
    let ctx = RunContext {
        run_id: run_id.clone(),
        scene_fingerprint: scene.fingerprint,
    };
    let time_start = crate::runner::time_start(scene, &ctx, &plan, None)?;
    if let Some(t) = &time_start {
        crate::console::note(&format!("run {run_id}: {}", t.describe()));
    }
    let groups = plan.groups(scene.deployment.subdomain_nodes);
    let all_nodes = run_nodes_of(&plan, groups.len());
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
    let bus = join_bus(scene, run_id, net, recording.is_some(), &all_nodes, &groups)?;
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
    // The launcher hears every message of the run where that costs no socket (the router is in
    // its process), where an observer wants them, or where the recorder's end needs their count.
    // Through a router outside its process, an unrecorded run's fields would cross one more
    // socket each only to be counted: the launcher then subscribes to what it keeps.
    let counted = if bus.hosting || keep_all || recording.is_some() {
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
        let (tx, watched_run) = (tx.clone(), run_id.clone());
        let subscriber = session
            .declare_subscriber(pattern)
            .callback(move |s| {
                let _ = tx.send(Arrival::of(s.key_expr().as_str(), s.payload(), &watched_run, keep_all));
            })
            .wait()
            .map_err(|e| zenoh("subscribe to the run", e))?;
        watch.push(subscriber);
    }

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
    let no_resume = unresumable(scene, recording.is_some()).or_else(|| {
        bus.shared_memory.then(|| {
            "network.shared_memory = true: a killed node's last messages may reach some nodes and not others"
                .to_string()
        })
    });
    let supervised = restarts > 0 && no_resume.is_none();
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
    if let (true, Some(why)) = (restarts > 0, &no_resume) {
        crate::console::note(&format!(
            "node restarts off ({why}): a node process that dies stops the run"
        ));
    }
    let set_up = SetUp {
        plan,
        groups,
        all_nodes,
        hosted,
        bus,
        time_start,
        arrivals,
        counted,
        supervised,
        t0,
        _launcher_token: launcher_token,
        _scene: queryable,
        _watch: watch,
    };
    Ok((set_up, presence))
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
