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

use crate::children::{spawn_node, Children, NodeName, NodeRole};
use crate::runner::{IterationRecord, RunOptions, RunResult};
use anyhow::{bail, Context};
use glissade_bus::RunContext;
use glissade_deploy::{build_interface_node, build_nodes, Plan, Selection};
use glissade_messages::{
    decode, encode, Expected, Field, InterfaceSolution, Message, NodeId, Payload, Role, Stage, Verdict,
};
use glissade_scene::{fingerprint, load_str, LoadedScene};
use glissade_zenoh as transport;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How long nodes may take to fetch the scene, build their operators and report ready.
const READY_TIMEOUT: Duration = Duration::from_secs(300);
/// Longest wait for the answer to "is this run id in use on the router?".
const RUN_ID_PROBE: Duration = Duration::from_secs(2);
/// Longest silence on the bus before a run is declared stalled.
const IDLE_TIMEOUT: Duration = Duration::from_secs(600);
/// After a peer's token disappears, how long a node still handles messages already on their way
/// before it gives up (a peer that finished leaves right after its last messages).
const DEPARTURE_GRACE: Duration = Duration::from_secs(2);
/// How long a child whose token disappeared may take to exit before it counts as failed.
const EXIT_GRACE: Duration = Duration::from_secs(3);
/// How long nodes get to leave after `stop` before they are killed.
const STOP_TIMEOUT: Duration = Duration::from_secs(5);
/// How long nodes started by hand may take to leave once the run has ended.
const FINISH_TIMEOUT: Duration = Duration::from_secs(30);
/// How long a node process whose nodes are finished waits for the launcher's word that it holds
/// the run's results before it leaves anyway.
const DONE_TIMEOUT: Duration = Duration::from_secs(30);
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

/// A free TCP port on the loopback interface.
fn free_port() -> anyhow::Result<u16> {
    transport::free_loopback_port().context("cannot bind a loopback port")
}

/// The endpoint a node on this machine connects to for a router listening on `listen`.
fn local_endpoint(listen: &str) -> String {
    listen.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:")
}

/// Least room in `/dev/shm` for the launcher to choose shared memory: the processes' 16 MiB
/// pools and the lenders' pools of a run of the stratified scene at N = 1000, with room to spare.
pub const SHARED_MEMORY_ROOM: u64 = 512 << 20;

/// Why a dead node process could not resume from the recording of a run (`recorded` or not) of
/// `scene`, whatever the transport: no recording, or an incomplete one.
fn unresumable(scene: &LoadedScene, recorded: bool) -> Option<String> {
    if recorded {
        scene.recording.incomplete()
    } else {
        Some("the run is not recorded".to_string())
    }
}

/// What [`auto_shared_memory`] looks at besides the scene.
#[derive(Debug, Clone)]
pub struct Host {
    /// The run is recorded.
    pub recorded: bool,
    /// Some nodes run on other machines (started by hand).
    pub remote_nodes: bool,
    /// Bytes free in `/dev/shm`; None if it cannot be read.
    pub room: Option<u64>,
    /// Whether processes here may lock shared memory ([`transport::shared_memory_lockable`]).
    pub lockable: Result<(), String>,
}

/// Whether a run whose scene leaves `network.shared_memory` unset passes its fields through
/// shared memory: Ok(why) when node restarts are off for it anyway (they need fields that do not
/// go through shared memory: see [`run_distributed`]), every node runs on this machine, the bus
/// is not encrypted (with TLS, fields stay on the encrypted link), processes may lock shared
/// memory and `/dev/shm` has [`SHARED_MEMORY_ROOM`] free; Err(why not) otherwise.
pub fn auto_shared_memory(scene: &LoadedScene, host: &Host) -> Result<String, String> {
    let restarts_off = if scene.deployment.restarts == 0 {
        Some("deployment.restarts = 0".to_string())
    } else {
        unresumable(scene, host.recorded)
    };
    let Some(restarts_off) = restarts_off else {
        return Err("node restarts are on: they need fields that do not go through shared memory".into());
    };
    if host.remote_nodes {
        return Err("nodes on other machines".into());
    }
    if scene.network.tls.is_some() {
        return Err("network.tls: fields stay on the encrypted link".into());
    }
    host.lockable.clone()?;
    match host.room {
        Some(room) if room >= SHARED_MEMORY_ROOM => Ok(format!(
            "network.shared_memory unset: node restarts are off ({restarts_off}) and /dev/shm has {} MiB free",
            room >> 20
        )),
        Some(room) => Err(format!(
            "/dev/shm has {} MiB free, less than {} MiB",
            room >> 20,
            SHARED_MEMORY_ROOM >> 20
        )),
        None => Err("no /dev/shm".into()),
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

/// The `--tls-*` arguments of a node process that trusts the certificate authority `root_ca` and,
/// with mutual TLS, presents `identity` (certificate, private key).
fn tls_args(root_ca: &Path, identity: Option<(&Path, &Path)>) -> Vec<String> {
    let mut args = vec!["--tls-root-ca".to_string(), root_ca.display().to_string()];
    if let Some((cert, key)) = identity {
        args.extend([
            "--tls-cert".to_string(),
            cert.display().to_string(),
            "--tls-key".to_string(),
            key.display().to_string(),
        ]);
    }
    args
}

/// The common name of the (first) certificate in PEM file `path`, if it has one.
fn cert_common_name(path: &Path) -> anyhow::Result<Option<String>> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (_, pem) = x509_parser::pem::parse_x509_pem(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a PEM certificate: {e}", path.display()))?;
    let cert = pem
        .parse_x509()
        .map_err(|e| anyhow::anyhow!("{}: not an X.509 certificate: {e}", path.display()))?;
    let cn = cert.subject().iter_common_name().next().and_then(|cn| cn.as_str().ok());
    Ok(cn.map(str::to_string))
}

/// The TLS of a node process from its `--tls-root-ca`, `--tls-cert` and `--tls-key` arguments
/// (None without them); each file must be readable.
pub fn node_tls(
    root_ca: Option<&Path>,
    cert: Option<&Path>,
    key: Option<&Path>,
) -> anyhow::Result<Option<transport::Tls>> {
    let identity = match (cert, key) {
        (Some(c), Some(k)) => Some((c.to_path_buf(), k.to_path_buf())),
        (None, None) => None,
        _ => bail!("--tls-cert and --tls-key go together (a certificate and its private key)"),
    };
    let Some(root_ca) = root_ca else {
        if identity.is_some() {
            bail!("--tls-cert needs --tls-root-ca (the certificate authority of the run)");
        }
        return Ok(None);
    };
    for (flag, path) in [
        ("--tls-root-ca", Some(root_ca)),
        ("--tls-cert", cert),
        ("--tls-key", key),
    ] {
        if let Some(p) = path {
            std::fs::File::open(p).with_context(|| format!("{flag} {}: cannot read it", p.display()))?;
        }
    }
    Ok(Some(transport::Tls {
        root_ca: root_ca.to_path_buf(),
        identity,
        mutual: false,
    }))
}

/// The message identity of node process `name`.
fn node_id(name: NodeName) -> NodeId {
    NodeId {
        role: name.role.role(),
        index: name.index,
    }
}

/// The identity of the recorder process on the bus.
pub const RECORDER: NodeId = NodeId {
    role: Role::Recorder,
    index: 0,
};

/// The credentials of a node process from its `--credentials` argument: a file the launcher
/// wrote (readable by its owner only, as an SSH key must be), or `-` for the line the launcher
/// writes to a process it starts. The user must be the node's own ([`transport::user_of`]).
pub fn node_credentials(arg: Option<&Path>, id: NodeId) -> anyhow::Result<Option<transport::Credentials>> {
    let Some(path) = arg else {
        return Ok(None);
    };
    let text = if path == Path::new("-") {
        let mut line = String::new();
        std::io::stdin()
            .read_line(&mut line)
            .context("--credentials -: cannot read standard input")?;
        line
    } else {
        use std::os::unix::fs::PermissionsExt;
        let meta =
            std::fs::metadata(path).with_context(|| format!("--credentials {}: cannot read it", path.display()))?;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            bail!(
                "--credentials {}: readable by others (mode {mode:03o}); whoever reads it can speak for this node \
                 in the run: `chmod 600` it",
                path.display()
            );
        }
        std::fs::read_to_string(path).with_context(|| format!("--credentials {}: cannot read it", path.display()))?
    };
    let credentials =
        transport::Credentials::parse(&text).map_err(|e| anyhow::anyhow!("--credentials {}: {e}", path.display()))?;
    let own = transport::user_of(id);
    if credentials.user != own {
        bail!(
            "--credentials {}: they are {}'s, not this node's ({own}); each node has its own",
            path.display(),
            credentials.user
        );
    }
    Ok(Some(credentials))
}

/// The credentials files of the nodes started by hand, removed when the run ends.
struct CredentialFiles(Vec<PathBuf>);

impl Drop for CredentialFiles {
    fn drop(&mut self) {
        for f in &self.0 {
            let _ = std::fs::remove_file(f);
        }
    }
}

/// Writes `credentials` for node `name` into a new file of `dir`, readable by this user only.
fn write_credentials(
    dir: &Path,
    run_id: &str,
    name: NodeName,
    credentials: &transport::Credentials,
) -> anyhow::Result<PathBuf> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let path = dir.join(format!("{run_id}-{}-{}.credentials", name.role.key(), name.index));
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(&path)
        .with_context(|| format!("cannot create {} (the credentials of node {name})", path.display()))?;
    f.write_all(credentials.line().as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
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

/// The run's bus as the launcher joins it ([`join_bus`]).
struct Bus {
    session: zenoh::Session,
    /// The endpoints node processes connect to.
    node_connect: Vec<String>,
    /// What the bus is, for messages ("this launcher hosting the Zenoh router on …").
    description: String,
    /// The launcher hosts the router (and says who may connect to it).
    hosting: bool,
    /// Fields between processes go through shared memory.
    shared_memory: bool,
    /// The `--tls-*`, `--shared-memory` and `--credentials -` arguments of the node processes
    /// the launcher starts.
    node_args: Vec<String>,
    /// Each process's credentials, when the launcher hosts the router.
    credentials: BTreeMap<NodeId, transport::Credentials>,
}

/// Opens the run's bus: a router hosted here (TLS and access control as the scene's `[network]`
/// says, only the run's processes admitted, DESIGN §4) or a client of the router of
/// `--connect`, refusing a run id already in use there.
fn join_bus(
    scene: &LoadedScene,
    run_id: &str,
    net: &Network,
    all_nodes: &[NodeName],
    groups: &[Vec<u32>],
) -> anyhow::Result<Bus> {
    for l in &net.listen {
        if l.ends_with(":0") {
            bail!("--listen {l}: give an explicit port (nodes started elsewhere must know it)");
        }
    }
    if !net.connect.is_empty() && !net.listen.is_empty() {
        bail!("--listen and --connect exclude each other: the launcher either hosts the router or connects to one");
    }
    // TLS and access control as the scene's [network] says.
    let tls = scene.network.tls.as_ref().map(|t| transport::Tls {
        root_ca: t.root_ca.clone(),
        identity: Some((t.cert.clone(), t.key.clone())),
        mutual: t.mutual,
    });
    // Who may connect (DESIGN §4): to a router hosted here, only the run's own processes, each
    // under its own user with a random password, speaking only on its own keys.
    let hosting = net.connect.is_empty();
    let mut members: Vec<NodeId> = all_nodes.iter().map(|&n| node_id(n)).collect();
    if net.recording.is_some() {
        members.push(RECORDER);
    }
    let credentials: BTreeMap<NodeId, transport::Credentials> = if hosting {
        members
            .iter()
            .map(|&id| Ok((id, transport::Credentials::random(&transport::user_of(id))?)))
            .collect::<Result<_, transport::TransportError>>()?
    } else {
        BTreeMap::new()
    };
    let access = if hosting {
        Some(transport::Access {
            run_id: run_id.to_string(),
            common_names: scene.network.allow.clone(),
            members: Some(
                members
                    .iter()
                    .map(|&id| {
                        let mut m = transport::Member::node(run_id, id);
                        if id.role == Role::Subdomain {
                            // A subdomain process speaks for the subdomains it hosts.
                            m.keys = vec![glissade_messages::topic::alive(run_id, id.role.key(), id.index)];
                            m.keys.extend(groups[id.index as usize].iter().map(|&s| {
                                glissade_messages::topic::sent_by(
                                    run_id,
                                    NodeId {
                                        role: Role::Subdomain,
                                        index: s,
                                    },
                                )
                            }));
                        }
                        m
                    })
                    .collect(),
            ),
        })
    } else {
        None
    };
    if scene.network.allow.is_some() && !hosting {
        bail!(
            "network.allow: access control is enforced by the router this launcher hosts; with --connect {}, \
             configure it on that router",
            net.connect.join(", ")
        );
    }
    if let (Some(allow), Some(t)) = (&scene.network.allow, &scene.network.tls) {
        // The nodes this launcher starts present its certificate.
        let cn = cert_common_name(&t.cert)?;
        if all_nodes.iter().any(|n| !net.remote.contains(n)) && !cn.as_ref().is_some_and(|cn| allow.contains(cn)) {
            bail!(
                "network.allow: the launcher's certificate {} has common name {}, which the list does not allow; \
                 the nodes it starts present that certificate (list it, or start every node by hand)",
                t.cert.display(),
                cn.map_or("(none)".to_string(), |cn| format!("`{cn}`"))
            );
        }
    }
    let shared_memory = match scene.network.shared_memory {
        Some(on) => on,
        None => {
            let host = Host {
                recorded: net.recording.is_some(),
                remote_nodes: !net.remote.is_empty(),
                room: transport::shared_memory_room(),
                lockable: transport::shared_memory_lockable(),
            };
            let auto = auto_shared_memory(scene, &host);
            if let Ok(why) = &auto {
                crate::console::note(&format!("fields through shared memory ({why})"));
            }
            auto.is_ok()
        }
    };
    let bus_config = |mode: &str, listen: &[String], connect: &[String], auth: Option<&transport::Auth>| {
        let access = if mode == "router" { access.as_ref() } else { None };
        let mut c = transport::secure_config(mode, listen, connect, false, tls.as_ref(), auth, access)
            .context("the bus (the scene's [network] section, --listen, --connect)")?;
        transport::set_shared_memory(&mut c, shared_memory)?;
        anyhow::Ok(c)
    };
    // How every process joins the bus: TLS, and shared memory when the scene asks for it or the
    // launcher chose it (only between processes on one machine; across machines Zenoh uses the
    // link).
    let mut node_args = match &scene.network.tls {
        Some(t) => tls_args(&t.root_ca, t.mutual.then_some((&*t.cert, &*t.key))),
        None => Vec::new(),
    };
    node_args.extend(shared_memory.then(|| "--shared-memory".to_string()));
    if hosting {
        node_args.extend(["--credentials".to_string(), "-".to_string()]);
    }
    // The bus: a router hosted here, or a client of the given router.
    let (session, node_connect, description) = if hosting {
        let listen = if net.listen.is_empty() {
            let scheme = if tls.is_some() { "tls" } else { "tcp" };
            vec![format!("{scheme}/127.0.0.1:{}", free_port()?)]
        } else {
            net.listen.clone()
        };
        // The router reads its users when it opens; their file goes right after.
        let users: Vec<transport::Credentials> = credentials.values().cloned().collect();
        let dictionary = transport::Dictionary::write(&std::env::temp_dir(), &users)?;
        let auth = transport::Auth::Router {
            dictionary: dictionary.path().to_path_buf(),
        };
        let session = transport::open(bus_config("router", &listen, &[], Some(&auth))?)
            .with_context(|| format!("cannot host the Zenoh router on {}", listen.join(", ")))?;
        drop(dictionary);
        let connect = vec![local_endpoint(&listen[0])];
        (
            session,
            connect,
            format!("this launcher hosting the Zenoh router on {}", listen.join(", ")),
        )
    } else {
        let session = transport::open(bus_config("client", &[], &net.connect, None)?)
            .with_context(|| format!("cannot connect to the Zenoh router at {}", net.connect.join(", ")))?;
        (
            session,
            net.connect.clone(),
            format!("the Zenoh router at {}", net.connect.join(", ")),
        )
    };
    // Another launcher (or its nodes) on a shared router with this run id would mix two runs (a
    // router hosted here is new: nobody else is on it yet).
    if !net.connect.is_empty() {
        let taken = transport::tokens_alive(&session, run_id, RUN_ID_PROBE)?;
        if !taken.is_empty() {
            bail!(
                "run id {run_id} is already in use on {description}: {} alive there; nothing was started: choose \
                 another --run-id (or leave it out for a new random one)",
                taken.join(", ")
            );
        }
    }
    Ok(Bus {
        session,
        node_connect,
        description,
        hosting,
        shared_memory,
        node_args,
        credentials,
    })
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
            .push(spawn_node(exe, name, &args, credentials.get(&node_id(name)).cloned())?);
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
                let cr = &credentials[&node_id(r)];
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
                if let Some(o) = observe.as_mut() {
                    o(&m);
                }
                if let Some(rec) = got.take(m) {
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
            if let Some(o) = observe.as_mut() {
                o(&m);
            }
            if let Some(rec) = got.take(m) {
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
    /// Keeps the results of message `m`; a decision's record is returned.
    fn take(&mut self, m: Message) -> Option<&IterationRecord> {
        let from = m.envelope.sender;
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
            Payload::InterfaceSolution(_) if from.role != Role::Interface => {}
            Payload::Displacement { .. } if from.role != Role::Subdomain => {}
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

/// How a node or recorder process joins a run's bus: the router's endpoints, TLS, and its
/// credentials (`glissade node --connect --tls-* --credentials`).
pub struct Joining<'a> {
    pub connect: &'a [String],
    pub tls: Option<&'a transport::Tls>,
    pub credentials: Option<&'a transport::Credentials>,
}

impl Joining<'_> {
    /// A client session on the bus (shared memory on or off), or an error saying what to check.
    pub fn open(&self, shared_memory: bool) -> anyhow::Result<zenoh::Session> {
        let auth = self.credentials.cloned().map(transport::Auth::Client);
        let mut config = transport::secure_config("client", &[], self.connect, false, self.tls, auth.as_ref(), None)
            .context("--connect, --tls-*")?;
        transport::set_shared_memory(&mut config, shared_memory)?;
        transport::open(config).with_context(|| {
            let mut hints = Vec::new();
            if self.tls.is_some() {
                hints.push(
                    "TLS: --tls-root-ca must be the run's certificate authority, and with mutual TLS --tls-cert a \
                     certificate it signed",
                );
            }
            hints.push(if self.credentials.is_some() {
                "credentials: --credentials must be the file the launcher wrote for this node, for this run"
            } else {
                "a router hosted by `glissade run` admits only the run's processes: give --credentials, the file \
                 the launcher wrote for this node"
            });
            format!(
                "cannot join the run's bus at {} ({})",
                self.connect.join(", "),
                hints.join("; ")
            )
        })
    }
}

/// Runs one node process: joins the bus, fetches the scene of run `run_id` over it, builds its
/// nodes and runs them until the run ends. A subdomain node hosts the subdomains of group `index`
/// of the scene's deployment; `subdomains`, when given, must name the same ones.
pub fn run_node_process(
    role: NodeRole,
    run_id: &str,
    bus: &Joining,
    subdomains: &[u32],
    index: u32,
    supervision: Supervision,
) -> anyhow::Result<()> {
    let interior = supervision.interior;
    let name = NodeName { role, index };
    if role == NodeRole::Coarse && index != 0 {
        bail!("node {name}: a run has one coarse node, index 0");
    }
    let session = bus.open(supervision.shared_memory)?;
    let bytes = transport::fetch_scene(&session, run_id, Duration::from_secs(60))?;
    let fp = transport::scene_fingerprint_of(&bytes, run_id)?;
    let expected = Expected {
        run_id: run_id.to_string(),
        scene_fingerprint: fp,
    };
    let msg = decode(&bytes, &expected)?;
    let Payload::Scene { text } = msg.payload else {
        bail!(
            "the launcher's scene query returned a {} message",
            msg.payload.field_key()
        )
    };
    if fingerprint(&text) != fp {
        bail!("the scene received from the bus does not match its fingerprint {fp:016x}");
    }
    let scene = load_str(&text, "<scene from the bus>")?;
    let model = Arc::new(scene.model.clone());
    let plan = Plan::new(&model).with_scene(&scene);
    let selection = match role {
        NodeRole::Subdomain => {
            let groups = plan.groups(scene.deployment.subdomain_nodes);
            let Some(group) = groups.get(index as usize) else {
                bail!(
                    "node {name}: the scene's deployment has {} subdomain node(s), indices 0 to {}",
                    groups.len(),
                    groups.len().saturating_sub(1)
                );
            };
            if !subdomains.is_empty() && subdomains != group.as_slice() {
                bail!("node {name}: --subdomains {subdomains:?} differ from the deployment's group {index}, {group:?}");
            }
            Selection {
                subdomains: group.clone(),
                interface: false,
                coarse: false,
            }
        }
        NodeRole::Interface => Selection {
            subdomains: Vec::new(),
            interface: false,
            coarse: false,
        },
        NodeRole::Coarse => Selection {
            subdomains: Vec::new(),
            interface: false,
            coarse: true,
        },
    };
    if role == NodeRole::Coarse && !plan.coarse {
        bail!("node {name}: the scene needs no coarse node (its coarse problem is off)");
    }
    let ctx = RunContext {
        run_id: run_id.to_string(),
        scene_fingerprint: fp,
    };
    let mut nodes = build_nodes(&model, &ctx, interior, &plan, &selection)?;
    if role == NodeRole::Interface {
        nodes.push(
            build_interface_node(&model, &ctx, &plan, index as usize)
                .map_err(|e| anyhow::anyhow!("node {name}: {e}"))?,
        );
    }
    let run = transport::NodeRun {
        run_id: run_id.to_string(),
        expected,
        token_role: role.key().to_string(),
        token_index: index,
        start_timeout: READY_TIMEOUT,
        idle_timeout: IDLE_TIMEOUT,
        departure_grace: DEPARTURE_GRACE,
        supervised: supervision.supervised,
        resume: supervision.resume,
        done_timeout: DONE_TIMEOUT,
    };
    let outcome = transport::run_nodes(&session, &run, nodes, |l| eprintln!("{l}"));
    let _ = session.close().wait();
    Ok(outcome?)
}
