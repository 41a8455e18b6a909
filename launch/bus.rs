//! The run's bus (docs/architecture.md): how the launcher opens it (hosting the Zenoh router, or as a client
//! of the router of `--connect`), who may connect to it (TLS and certificate names as the scene's
//! `[network]` says; each process of the run under its own user with a random password, speaking
//! only on its own keys), whether fields go through shared memory, and how a node or recorder
//! process joins it (`glissade node --connect --tls-* --credentials`).

use crate::children::NodeName;
use crate::error::{Error, IoWhat, Result};
use glissade_messages::{NodeId, Role};
use glissade_scene::LoadedScene;
use glissade_zenoh as transport;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Longest wait for the answer to "is this run id in use on the router?".
const RUN_ID_PROBE: Duration = Duration::from_secs(2);

/// A free TCP port on the loopback interface.
pub(crate) fn free_port() -> Result<u16> {
    transport::free_loopback_port().what(|| "cannot bind a loopback port".into())
}

/// The endpoint a node on this machine connects to for a router listening on `listen`.
pub(crate) fn local_endpoint(listen: &str) -> String {
    listen.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:")
}

/// The endpoint other hosts reach a router listening on `listen` by: a wildcard address
/// replaced by `host`.
pub(crate) fn host_endpoint(listen: &str, host: &str) -> String {
    listen
        .replace("/0.0.0.0:", &format!("/{host}:"))
        .replace("/[::]:", &format!("/{host}:"))
}

/// Least room in `/dev/shm` for the launcher to choose shared memory: the processes' 16 MiB
/// pools and the lenders' pools of a run of the stratified scene at N = 1000, with room to spare.
pub const SHARED_MEMORY_ROOM: u64 = 512 << 20;

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
/// go through shared memory: see [`crate::distributed::run_processes`]), every node runs on this machine, the bus
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

/// The `--tls-*` arguments of a node process that trusts the certificate authority `root_ca` and,
/// with mutual TLS, presents `identity` (certificate, private key).
pub(crate) fn tls_args(root_ca: &Path, identity: Option<(&Path, &Path)>) -> Vec<String> {
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
pub(crate) fn cert_common_name(path: &Path) -> Result<Option<String>> {
    let bytes = std::fs::read(path).what(|| format!("cannot read {}", path.display()))?;
    let (_, pem) = x509_parser::pem::parse_x509_pem(&bytes).map_err(|e| Error::Option {
        option: path.display().to_string(),
        why: format!("not a PEM certificate: {e}"),
    })?;
    let cert = pem.parse_x509().map_err(|e| Error::Option {
        option: path.display().to_string(),
        why: format!("not an X.509 certificate: {e}"),
    })?;
    let cn = cert.subject().iter_common_name().next().and_then(|cn| cn.as_str().ok());
    Ok(cn.map(str::to_string))
}

/// The TLS of a node process from its `--tls-root-ca`, `--tls-cert` and `--tls-key` arguments
/// (None without them); each file must be readable.
pub fn node_tls(root_ca: Option<&Path>, cert: Option<&Path>, key: Option<&Path>) -> Result<Option<transport::Tls>> {
    let identity = match (cert, key) {
        (Some(c), Some(k)) => Some((c.to_path_buf(), k.to_path_buf())),
        (None, None) => None,
        _ => {
            return Err(Error::Option {
                option: "--tls-cert, --tls-key".into(),
                why: "they go together (a certificate and its private key)".into(),
            })
        }
    };
    let Some(root_ca) = root_ca else {
        if identity.is_some() {
            return Err(Error::Option {
                option: "--tls-cert".into(),
                why: "it needs --tls-root-ca (the certificate authority of the run)".into(),
            });
        }
        return Ok(None);
    };
    for (flag, path) in [
        ("--tls-root-ca", Some(root_ca)),
        ("--tls-cert", cert),
        ("--tls-key", key),
    ] {
        if let Some(p) = path {
            std::fs::File::open(p).what(|| format!("{flag} {}: cannot read it", p.display()))?;
        }
    }
    Ok(Some(transport::Tls {
        root_ca: root_ca.to_path_buf(),
        identity,
        mutual: false,
    }))
}

/// The identity of the recorder process on the bus.
pub const RECORDER: NodeId = NodeId {
    role: Role::Recorder,
    index: 0,
};

/// The credentials of a node process from its `--credentials` argument: a file the launcher
/// wrote (readable by its owner only, as an SSH key must be), or `-` for the line the launcher
/// writes to a process it starts. The user must be the node's own ([`transport::user_of`]).
pub fn node_credentials(arg: Option<&Path>, id: NodeId) -> Result<Option<transport::Credentials>> {
    let Some(path) = arg else {
        return Ok(None);
    };
    let text = if path == Path::new("-") {
        let mut line = String::new();
        std::io::stdin()
            .read_line(&mut line)
            .what(|| "--credentials -: cannot read standard input".into())?;
        line
    } else {
        use std::os::unix::fs::PermissionsExt;
        let meta = std::fs::metadata(path).what(|| format!("--credentials {}: cannot read it", path.display()))?;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(Error::Option {
                option: format!("--credentials {}", path.display()),
                why: format!(
                    "readable by others (mode {mode:03o}); whoever reads it can speak for this node in the run: \
                     `chmod 600` it"
                ),
            });
        }
        std::fs::read_to_string(path).what(|| format!("--credentials {}: cannot read it", path.display()))?
    };
    let credentials = transport::Credentials::parse(&text).map_err(|e| Error::Option {
        option: format!("--credentials {}", path.display()),
        why: e.to_string(),
    })?;
    let own = transport::user_of(id);
    if credentials.user != own {
        return Err(Error::Option {
            option: format!("--credentials {}", path.display()),
            why: format!(
                "they are {}'s, not this node's ({own}); each node has its own",
                credentials.user
            ),
        });
    }
    Ok(Some(credentials))
}

/// The credentials files of the nodes started by hand, removed when the run ends.
pub(crate) struct CredentialFiles(pub(crate) Vec<PathBuf>);

impl Drop for CredentialFiles {
    fn drop(&mut self) {
        for f in &self.0 {
            let _ = std::fs::remove_file(f);
        }
    }
}

/// Writes `credentials` for node `name` into a new file of `dir`, readable by this user only.
pub(crate) fn write_credentials(
    dir: &Path,
    run_id: &str,
    name: NodeName,
    credentials: &transport::Credentials,
) -> Result<PathBuf> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let path = dir.join(format!("{run_id}-{}-{}.credentials", name.role.key(), name.index));
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(&path)
        .what(|| format!("cannot create {} (the credentials of node {name})", path.display()))?;
    f.write_all(credentials.line().as_bytes())
        .what(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// The run's bus as the launcher joins it ([`join_bus`]).
pub(crate) struct Bus {
    pub(crate) session: zenoh::Session,
    /// The endpoints node processes connect to.
    pub(crate) node_connect: Vec<String>,
    /// What the bus is, for messages ("this launcher hosting the Zenoh router on …").
    pub(crate) description: String,
    /// The launcher hosts the router (and says who may connect to it).
    pub(crate) hosting: bool,
    /// Fields between processes go through shared memory.
    pub(crate) shared_memory: bool,
    /// The `--tls-*`, `--shared-memory` and `--credentials -` arguments of the node processes
    /// the launcher starts.
    pub(crate) node_args: Vec<String>,
    /// Each process's credentials, when the launcher hosts the router.
    pub(crate) credentials: BTreeMap<NodeId, transport::Credentials>,
}

/// Opens the run's bus: a router hosted here (TLS and access control as the scene's `[network]`
/// says, only the run's processes admitted, docs/architecture.md) or a client of the router of
/// `--connect`, refusing a run id already in use there.
pub(crate) fn join_bus(
    scene: &LoadedScene,
    run_id: &str,
    net: &Network,
    recorded: bool,
    all_nodes: &[NodeName],
    groups: &[Vec<u32>],
    hosted_interfaces: &[Vec<usize>],
) -> Result<Bus> {
    check_bus_options(scene, net, all_nodes)?;
    // TLS and access control as the scene's [network] says.
    let tls = scene.network.tls.as_ref().map(|t| transport::Tls {
        root_ca: t.root_ca.clone(),
        identity: Some((t.cert.clone(), t.key.clone())),
        mutual: t.mutual,
    });
    // Who may connect (docs/architecture.md): to a router hosted here, only the run's own processes, each
    // under its own user with a random password, speaking only on its own keys.
    let hosting = net.connect.is_empty();
    let mut members: Vec<NodeId> = all_nodes.iter().map(|n| n.id()).collect();
    if recorded {
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
    let access = hosting.then(|| access_of(scene, run_id, &members, groups, hosted_interfaces));
    let shared_memory = choose_shared_memory(scene, net, recorded);
    let bus_config = |mode: &str, listen: &[String], connect: &[String], auth: Option<&transport::Auth>| {
        let access = if mode == "router" { access.as_ref() } else { None };
        let mut c =
            transport::secure_config(mode, listen, connect, false, tls.as_ref(), auth, access).map_err(|e| {
                Error::Option {
                    option: "the bus (the scene's [network] section, --listen, --connect)".into(),
                    why: e.to_string(),
                }
            })?;
        transport::set_shared_memory(&mut c, shared_memory)?;
        Ok::<_, Error>(c)
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
        let users: Vec<transport::Credentials> = credentials.values().cloned().collect();
        host_router(net, tls.is_some(), &users, |listen, auth| {
            bus_config("router", listen, &[], Some(auth))
        })?
    } else {
        let session = transport::open(bus_config("client", &[], &net.connect, None)?).map_err(|source| Error::Bus {
            what: format!("cannot connect to the Zenoh router at {}", net.connect.join(", ")),
            source,
        })?;
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
            return Err(Error::RunIdTaken {
                run_id: run_id.to_string(),
                bus: description,
                alive: taken,
            });
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

/// The launcher's bus options against each other and the scene's `[network]`: explicit ports,
/// `--listen` or `--connect`, access control only on a router hosted here and admitting the
/// certificate of the nodes the launcher starts.
fn check_bus_options(scene: &LoadedScene, net: &Network, all_nodes: &[NodeName]) -> Result<()> {
    for l in &net.listen {
        if l.ends_with(":0") {
            return Err(Error::Option {
                option: format!("--listen {l}"),
                why: "give an explicit port (nodes started elsewhere must know it)".into(),
            });
        }
    }
    if !net.connect.is_empty() && !net.listen.is_empty() {
        return Err(Error::Option {
            option: "--listen, --connect".into(),
            why: "they exclude each other: the launcher either hosts the router or connects to one".into(),
        });
    }
    if scene.network.allow.is_some() && !net.connect.is_empty() {
        return Err(Error::Option {
            option: "network.allow".into(),
            why: format!(
                "access control is enforced by the router this launcher hosts; with --connect {}, configure it on \
                 that router",
                net.connect.join(", ")
            ),
        });
    }
    if let (Some(allow), Some(t)) = (&scene.network.allow, &scene.network.tls) {
        // The nodes this launcher starts present its certificate.
        let cn = cert_common_name(&t.cert)?;
        if all_nodes.iter().any(|n| !net.remote.contains(n)) && !cn.as_ref().is_some_and(|cn| allow.contains(cn)) {
            return Err(Error::Option {
                option: "network.allow".into(),
                why: format!(
                    "the launcher's certificate {} has common name {}, which the list does not allow; the nodes it \
                     starts present that certificate (list it, or start every node by hand)",
                    t.cert.display(),
                    cn.map_or("(none)".to_string(), |cn| format!("`{cn}`"))
                ),
            });
        }
    }
    Ok(())
}

/// The access control of a router hosted here: the run's processes (`members`), each speaking
/// only on its own keys; a subdomain process also for the subdomains it hosts and the interface
/// nodes it runs (`interfaces_with_subdomains`).
fn access_of(
    scene: &LoadedScene,
    run_id: &str,
    members: &[NodeId],
    groups: &[Vec<u32>],
    hosted_interfaces: &[Vec<usize>],
) -> transport::Access {
    transport::Access {
        run_id: run_id.to_string(),
        common_names: scene.network.allow.clone(),
        members: Some(
            members
                .iter()
                .map(|&id| {
                    let mut m = transport::Member::node(run_id, id);
                    if id.role == Role::Subdomain {
                        // A subdomain process speaks for the subdomains it hosts, and for the
                        // interface nodes it runs (`interfaces_with_subdomains`).
                        let g = id.index as usize;
                        m.keys = vec![glissade_messages::topic::alive(run_id, id.role.key(), id.index)];
                        let subdomains = groups[g].iter().map(|&s| NodeId {
                            role: Role::Subdomain,
                            index: s,
                        });
                        let interfaces = hosted_interfaces[g].iter().map(|&k| NodeId {
                            role: Role::Interface,
                            index: k as u32,
                        });
                        m.keys.extend(
                            subdomains
                                .chain(interfaces)
                                .map(|n| glissade_messages::topic::sent_by(run_id, n)),
                        );
                    }
                    m
                })
                .collect(),
        ),
    }
}

/// Whether fields go through shared memory: as the scene's `network.shared_memory` says, or when
/// unset, where every process runs on this host and the machine has room for it (said as a note
/// either way).
fn choose_shared_memory(scene: &LoadedScene, net: &Network, recorded: bool) -> bool {
    match scene.network.shared_memory {
        Some(on) => {
            crate::console::note(&format!(
                "fields {} (network.shared_memory = {on})",
                if on { "through shared memory" } else { "over TCP" }
            ));
            on
        }
        None => {
            let host = Host {
                recorded,
                // Nodes started by hand, or job steps of an allocation of several hosts, may run
                // on other machines.
                remote_nodes: !net.remote.is_empty() || net.starter.hosts() > 1,
                room: transport::shared_memory_room(),
                lockable: transport::shared_memory_lockable(),
            };
            let auto = auto_shared_memory(scene, &host);
            match &auto {
                Ok(why) => crate::console::note(&format!("fields through shared memory ({why})")),
                Err(why) => crate::console::note(&format!(
                    "fields over TCP (network.shared_memory unset; not through shared memory: {why})"
                )),
            }
            auto.is_ok()
        }
    }
}

/// Hosts the run's router: on `--listen`, or on a free port of the loopback (of every interface
/// where node processes may run on other hosts, reached by this host's name); its users
/// `users` read from a file that is gone once the router has opened. `config` makes the router's
/// configuration from its listening endpoints and authentication. Returns the session, the
/// endpoint node processes connect to and the bus's description.
fn host_router(
    net: &Network,
    tls: bool,
    users: &[transport::Credentials],
    config: impl Fn(&[String], &transport::Auth) -> Result<zenoh::Config>,
) -> Result<(zenoh::Session, Vec<String>, String)> {
    // Node processes that may run on other hosts (Slurm job steps) reach the router by this
    // host's name, on every interface unless --listen says where.
    let advertised = net.starter.advertised_host()?;
    if advertised.is_some() {
        if let Some(l) = net
            .listen
            .iter()
            .find(|l| l.contains("/127.") || l.contains("/[::1]") || l.contains("/localhost:"))
        {
            return Err(Error::Option {
                option: "--listen".into(),
                why: format!(
                    "{l} is this host's loopback, which node processes on the allocation's other hosts cannot \
                     reach; with --slurm listen on tcp/0.0.0.0:<port> or on an address the other hosts reach"
                ),
            });
        }
    }
    let scheme = if tls { "tls" } else { "tcp" };
    let listen = match (net.listen.is_empty(), &advertised) {
        (true, None) => vec![format!("{scheme}/127.0.0.1:{}", free_port()?)],
        (true, Some(_)) => vec![format!("{scheme}/0.0.0.0:{}", free_port()?)],
        (false, _) => net.listen.clone(),
    };
    // The router reads its users when it opens; their file goes right after.
    let dictionary = transport::Dictionary::write(&std::env::temp_dir(), users)?;
    let auth = transport::Auth::Router {
        dictionary: dictionary.path().to_path_buf(),
    };
    let session = transport::open(config(&listen, &auth)?).map_err(|source| Error::Bus {
        what: format!("cannot host the Zenoh router on {}", listen.join(", ")),
        source,
    })?;
    drop(dictionary);
    let connect = vec![match &advertised {
        Some(host) => host_endpoint(&listen[0], host),
        None => local_endpoint(&listen[0]),
    }];
    Ok((
        session,
        connect,
        format!("this launcher hosting the Zenoh router on {}", listen.join(", ")),
    ))
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
    pub fn open(&self, shared_memory: bool) -> Result<zenoh::Session> {
        let auth = self.credentials.cloned().map(transport::Auth::Client);
        let mut config = transport::secure_config("client", &[], self.connect, false, self.tls, auth.as_ref(), None)
            .map_err(|e| Error::Option {
                option: "--connect, --tls-*".into(),
                why: e.to_string(),
            })?;
        transport::set_shared_memory(&mut config, shared_memory)?;
        transport::open(config).map_err(|source| {
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
            Error::Bus {
                what: format!(
                    "cannot join the run's bus at {} ({})",
                    self.connect.join(", "),
                    hints.join("; ")
                ),
                source,
            }
        })
    }
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
    /// Folder where the credentials of the nodes started by hand (`remote`) are written, one
    /// file each, readable by this user only, removed when the run ends (the run's `--out`).
    pub credentials: Option<std::path::PathBuf>,
    /// Where the launcher starts the other node processes: here, or as Slurm job steps.
    pub starter: crate::starter::Starter,
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

/// The scene of run `run_id` as its launcher serves it on the bus (a node or recorder process
/// needs no scene file): fetched (bounded), checked against the fingerprint its envelope
/// carries, and loaded with the launcher's command-line overrides, so that it is the run's model
/// and not the file's. Also returns what every message of the run carries ([`Expected`]).
pub(crate) fn fetch_run_scene(
    session: &zenoh::Session,
    run_id: &str,
) -> Result<(LoadedScene, glissade_messages::Expected)> {
    let bytes = transport::fetch_scene(session, run_id, std::time::Duration::from_secs(60))?;
    let fingerprint = transport::scene_fingerprint_of(&bytes, run_id)?;
    let expected = glissade_messages::Expected {
        run_id: run_id.to_string(),
        scene_fingerprint: fingerprint,
    };
    let msg = glissade_messages::decode(&bytes, &expected)?;
    let glissade_messages::Payload::Scene { text, overrides } = msg.payload else {
        return Err(Error::NotAScene {
            kind: msg.payload.field_key().to_string(),
        });
    };
    if glissade_scene::fingerprint_with(&text, &overrides) != fingerprint {
        return Err(Error::SceneMismatch { fingerprint });
    }
    Ok((
        glissade_scene::load_with(&text, "<scene from the bus>", &overrides)?,
        expected,
    ))
}
