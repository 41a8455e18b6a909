//! The Zenoh transport of glissade (DESIGN §4): runs sans-IO [`Node`]s over a Zenoh session.
//!
//! Topology (STACK.md, "topology trap"): the launcher opens a session in `router` mode listening
//! on an explicit endpoint (or connects as a client to a `zenohd` router); every node process
//! opens a `client` session connected to that router, with multicast scouting off. Clients route
//! through the router, so every node reaches every other.
//!
//! Start-up without lost messages: Zenoh pub/sub is not durable, so
//! 1. a node process fetches the scene with a query to the launcher's queryable (no race);
//! 2. it declares its subscribers, then a liveliness token `glissade/<run>/alive/<role>/<id>`;
//! 3. the launcher waits until every expected token is alive, then publishes `start`;
//! 4. only then do nodes call [`Node::start`] and publish.
//!
//! End without lost messages: a put returns once the message is queued, so a process that closed
//! its session right after its last put could lose it. A process whose nodes are finished waits
//! (bounded) for the launcher's `done`, published once it holds the final decision and every
//! final output, and only then leaves.
//!
//! Failure: every node process watches the liveliness tokens of the run (the launcher's and every
//! other node's: each node's progress depends on all of them). A token that disappears while this
//! process still has work stops it with an error naming the peer, after a short grace period in
//! which messages already on their way are still handled (a peer that finished normally leaves
//! once its last messages are out). The launcher's `stop` message stops every node at once. Link
//! leases are shortened to [`LEASE`] so a peer that vanishes without closing its connection is
//! noticed within seconds; a killed process closes its connections at once.
//!
//! Every put uses `CongestionControl::Block` (multi-MB fields are never dropped). Every wait is
//! bounded by a timeout.

use glissade_bus::{Node, NodeError};
use glissade_messages::{
    decode, decode_from_slices, encode, BlockLender, BufferPool, DecodeBuffers, DecodeError, Expected, Message, Piece,
    ValueBlock,
};
use rayon::prelude::*;
use std::collections::{BTreeSet, HashSet, VecDeque};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;
use zenoh::{Config, Session, Wait};

/// Link lease: a peer whose link is silent this long is declared gone (Zenoh's default is 10 s).
pub const LEASE: Duration = Duration::from_secs(4);

/// Errors of the Zenoh transport.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error("zenoh: {what}: {detail}")]
    Zenoh { what: String, detail: String },
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error("no message for {0:?}: the run stalled or a peer died")]
    Timeout(Duration),
    #[error(
        "peer {peer} left the run (its liveliness token disappeared) while this process still had work{}",
        also_gone(.others)
    )]
    PeerLeft { peer: String, others: Vec<String> },
    #[error("stopped by the launcher: {0}")]
    Stopped(String),
    #[error("{0}")]
    Protocol(String),
}

fn also_gone(others: &[String]) -> String {
    if others.is_empty() {
        String::new()
    } else {
        format!("; also gone: {}", others.join(", "))
    }
}

fn zerr(what: &str, e: impl std::fmt::Display) -> TransportError {
    TransportError::Zenoh {
        what: what.to_string(),
        detail: e.to_string(),
    }
}

/// Key of the scene queryable of a run.
pub fn scene_key(run_id: &str) -> String {
    format!("glissade/{run_id}/launcher/0/scene")
}

/// Key the launcher publishes on once every node is ready.
pub fn start_key(run_id: &str) -> String {
    format!("glissade/{run_id}/launcher/0/start")
}

/// Key the launcher publishes on to stop every node of a run (payload: the reason, UTF-8).
pub fn stop_key(run_id: &str) -> String {
    format!("glissade/{run_id}/launcher/0/stop")
}

/// Key the launcher publishes on once it holds the run's results (the final decision and every
/// final output): node processes leave only then.
pub fn done_key(run_id: &str) -> String {
    format!("glissade/{run_id}/launcher/0/done")
}

/// Liveliness token of a node (the launcher's is role `launcher`, index 0).
pub fn alive_key(run_id: &str, role: &str, index: u32) -> String {
    format!("glissade/{run_id}/alive/{role}/{index}")
}

/// Every liveliness token of a run.
pub fn alive_pattern(run_id: &str) -> String {
    format!("glissade/{run_id}/alive/**")
}

/// `role:index` of a liveliness key (`glissade/<run>/alive/<role>/<index>`).
pub fn node_of_alive_key(key: &str) -> String {
    let mut chunks = key.rsplit('/');
    match (chunks.next(), chunks.next()) {
        (Some(index), Some(role)) => format!("{role}:{index}"),
        _ => key.to_string(),
    }
}

/// A TCP port free on the loopback interface now (the OS picks it; another process could take it
/// before it is listened on).
pub fn free_loopback_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Session configuration: `mode` ("router", "peer" or "client"), explicit listen and connect
/// endpoints, multicast scouting off unless asked, link lease [`LEASE`].
pub fn config(mode: &str, listen: &[String], connect: &[String], multicast: bool) -> Result<Config, TransportError> {
    let mut c = Config::default();
    let json_list = |v: &[String]| {
        format!(
            "[{}]",
            v.iter().map(|e| format!("\"{e}\"")).collect::<Vec<_>>().join(",")
        )
    };
    c.insert_json5("mode", &format!("\"{mode}\""))
        .map_err(|e| zerr("config mode", e))?;
    c.insert_json5("scouting/multicast/enabled", if multicast { "true" } else { "false" })
        .map_err(|e| zerr("config scouting", e))?;
    c.insert_json5("listen/endpoints", &json_list(listen))
        .map_err(|e| zerr("config listen", e))?;
    c.insert_json5("connect/endpoints", &json_list(connect))
        .map_err(|e| zerr("config connect", e))?;
    c.insert_json5("transport/link/tx/lease", &LEASE.as_millis().to_string())
        .map_err(|e| zerr("config lease", e))?;
    if !multicast && connect.is_empty() {
        // A router (or peer) opening with `scouting/delay` left at Zenoh's 500 ms sleeps that
        // long before `open` returns, to let scouted or connecting peers arrive first; with
        // neither there is nothing to wait for (measured: the launcher's `open` took 0.50 s).
        c.insert_json5("scouting/delay", "0")
            .map_err(|e| zerr("config scouting delay", e))?;
    }
    set_shared_memory(&mut c, false)?;
    Ok(c)
}

/// Turns Zenoh's shared-memory transport on or off in `c` (off in [`config`]). On, between two
/// sessions on one machine that both have it on, every payload of 3 KiB or more is copied into a
/// 16 MiB shared pool and passed by reference instead of through the socket; a payload that
/// does not fit in the pool, or a peer on another machine, goes over the link.
pub fn set_shared_memory(c: &mut Config, on: bool) -> Result<(), TransportError> {
    c.insert_json5("transport/shared_memory/enabled", if on { "true" } else { "false" })
        .map_err(|e| zerr("config shared_memory", e))
}

/// TLS of a session (PEM files): links are encrypted and the router's certificate is checked
/// against `root_ca` (its subject alternative names must cover the address connected to).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tls {
    /// The certificate authority that signs the run's certificates.
    pub root_ca: PathBuf,
    /// This session's certificate and private key: what a router presents to its clients, and
    /// what a client presents to a router that asks for it (mutual TLS). None: a client that
    /// presents none.
    pub identity: Option<(PathBuf, PathBuf)>,
    /// As a router: clients must present a certificate signed by `root_ca`.
    pub mutual: bool,
}

/// Access control on a router: deny by default; the sessions whose certificate common name is in
/// `allow` may publish, subscribe, query, reply and hold liveliness tokens on `key_exprs`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Access {
    pub allow: Vec<String>,
    pub key_exprs: Vec<String>,
}

impl Access {
    /// Access to the key space of run `run_id` (`glissade/<run>/**`) for `allow`.
    pub fn run(run_id: &str, allow: &[String]) -> Self {
        Self {
            allow: allow.to_vec(),
            key_exprs: vec![format!("glissade/{run_id}/**")],
        }
    }
}

/// [`config`] with TLS on every endpoint (`tls/…`) and, on a router, access control: the
/// endpoints must all be `tls/…` exactly when `tls` is given; access control needs a router with
/// mutual TLS (a client's common name is known only from the certificate it presents).
pub fn secure_config(
    mode: &str,
    listen: &[String],
    connect: &[String],
    multicast: bool,
    tls: Option<&Tls>,
    access: Option<&Access>,
) -> Result<Config, TransportError> {
    let endpoints = listen.iter().chain(connect);
    match tls {
        Some(_) => {
            if let Some(e) = endpoints.clone().find(|e| !e.starts_with("tls/")) {
                return Err(TransportError::Protocol(format!(
                    "endpoint {e}: TLS is on, so every endpoint must be tls/<host>:<port>"
                )));
            }
        }
        None => {
            if let Some(e) = endpoints.clone().find(|e| e.starts_with("tls/")) {
                return Err(TransportError::Protocol(format!(
                    "endpoint {e}: a TLS endpoint needs the certificate authority's file (and, for mutual TLS, \
                     a certificate and key)"
                )));
            }
        }
    }
    if let Some(a) = access {
        let ok = mode == "router" && tls.is_some_and(|t| t.mutual);
        if !ok {
            return Err(TransportError::Protocol(
                "access control by certificate common name needs a router with mutual TLS".into(),
            ));
        }
        if a.allow.is_empty() || a.key_exprs.is_empty() {
            return Err(TransportError::Protocol(
                "access control with no allowed name or no key expression would let nothing through".into(),
            ));
        }
    }
    let mut c = config(mode, listen, connect, multicast)?;
    let path = |p: &Path| json_string(&p.to_string_lossy());
    if let Some(t) = tls {
        let prefix = "transport/link/tls";
        let mut set = |key: &str, value: String| {
            c.insert_json5(&format!("{prefix}/{key}"), &value)
                .map_err(|e| zerr(&format!("config tls {key}"), e))
        };
        set("root_ca_certificate", path(&t.root_ca))?;
        let router = mode == "router";
        if let Some((cert, key)) = &t.identity {
            let (cert_key, key_key) = if router {
                ("listen_certificate", "listen_private_key")
            } else {
                ("connect_certificate", "connect_private_key")
            };
            set(cert_key, path(cert))?;
            set(key_key, path(key))?;
        }
        // A router asks for client certificates; a client presents its own when it has one.
        let mtls = if router { t.mutual } else { t.identity.is_some() };
        set("enable_mtls", mtls.to_string())?;
    }
    if let Some(a) = access {
        let list = |v: &[String]| format!("[{}]", v.iter().map(|s| json_string(s)).collect::<Vec<_>>().join(","));
        let acl = format!(
            r#"{{
                enabled: true,
                default_permission: "deny",
                rules: [{{
                    id: "run",
                    messages: ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                               "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"],
                    flows: ["egress", "ingress"],
                    permission: "allow",
                    key_exprs: {keys},
                }}],
                subjects: [{{ id: "allowed", cert_common_names: {names} }}],
                policies: [{{ rules: ["run"], subjects: ["allowed"] }}],
            }}"#,
            keys = list(&a.key_exprs),
            names = list(&a.allow),
        );
        c.insert_json5("access_control", &acl)
            .map_err(|e| zerr("config access_control", e))?;
    }
    Ok(c)
}

/// `s` as a JSON string literal (quotes and backslashes escaped).
fn json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

pub fn open(config: Config) -> Result<Session, TransportError> {
    zenoh::open(config).wait().map_err(|e| zerr("open session", e))
}

/// Publishes one message on its topic, blocking rather than dropping under congestion. With
/// shared memory on ([`set_shared_memory`]), a message of [`SHARED_ENCODING_MIN`] bytes or more is
/// encoded straight into a buffer of the session's shared-memory pool; otherwise, or when the pool
/// has no room, into a buffer of its own, which Zenoh copies into the pool (or sends over the link).
pub fn publish(session: &Session, msg: &Message) -> Result<(), TransportError> {
    let key = msg.topic();
    match encode_shared(session, msg) {
        Some(bytes) => put_bytes(session, &key, bytes),
        None => put_bytes(session, &key, encode(msg)),
    }
}

/// Smallest message encoded straight into shared memory: the boundary fields (MBs) and the macro
/// data (tens of kB) are, the small control messages are not.
pub const SHARED_ENCODING_MIN: usize = 64 << 10;

/// `msg` encoded into a buffer of the session's shared-memory pool, or None: shared memory off or
/// not ready yet, a small message, or no room in the pool after collecting the buffers receivers
/// released. Saves the copy of an encoded buffer into the pool that Zenoh makes otherwise.
fn encode_shared(session: &Session, msg: &Message) -> Option<zenoh::bytes::ZBytes> {
    use zenoh::shm::GarbageCollect;
    let len = glissade_messages::encoded_len(msg);
    if len < SHARED_ENCODING_MIN {
        return None;
    }
    let provider = session.get_shm_provider().into_option()?;
    let mut buffer = provider.alloc(len).with_policy::<GarbageCollect>().wait().ok()?;
    // A message's bytes are exactly its encoding (decoding refuses trailing bytes).
    if buffer.len() != len || glissade_messages::encode_into(msg, &mut buffer) != Some(len) {
        return None;
    }
    Some(buffer.into())
}

/// Publishes a message a node made, taking the shared-memory blocks its fields were written
/// into ([`ShmLender`]) out of it: they are sent as they are, without copying their values, and
/// the message keeps its other fields (for the node to reuse, [`Node::recycle`]). A message
/// without lent fields is published as [`publish`] does.
pub fn publish_lent(session: &Session, msg: &mut Message) -> Result<(), TransportError> {
    let mut lent = false;
    msg.payload.fields(|f| lent |= f.data.is_lent());
    if !lent {
        return publish(session, msg);
    }
    let key = msg.topic();
    let pieces = glissade_messages::encode_pieces(msg);
    let mut blocks = Vec::new();
    msg.payload.fields_mut(|f| blocks.extend(f.data.take_block()));
    let mut out = zenoh::bytes::ZBytes::writer();
    for piece in pieces {
        match piece {
            Piece::Bytes(b) => std::io::Write::write_all(&mut out, &b).expect("writing into memory cannot fail"),
            Piece::Block(at) => {
                let k = blocks
                    .iter()
                    .position(|b| b.values().as_ptr() as usize == at)
                    .ok_or_else(|| TransportError::Protocol(format!("{key}: a field block vanished while encoding")))?;
                // Blocks come from this transport's lender only.
                let shm = blocks.swap_remove(k).into_any().downcast::<ShmBlock>().map_err(|_| {
                    TransportError::Protocol(format!("{key}: a field block not lent by this transport"))
                })?;
                out.append(shm.0.into());
            }
        }
    }
    put_bytes(session, &key, out.finish())
}

/// A block of a shared-memory pool holding a field's values ([`ShmLender`]).
struct ShmBlock(zenoh::shm::ZShmMut);

impl ValueBlock for ShmBlock {
    fn values(&self) -> &[f64] {
        bytemuck::cast_slice(&self.0)
    }

    fn values_mut(&mut self) -> &mut [f64] {
        bytemuck::cast_slice_mut(&mut self.0)
    }

    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any> {
        self
    }
}

/// Lends a process's nodes blocks of shared memory to write their large fields into, so that
/// they are sent without a copy ([`publish_lent`]). The blocks come from pools of the lender's
/// own, added one at a time as the nodes' fields need room (an interface node writes every
/// subdomain's local directions before the first is read, 34 MB at N = 1000), up to
/// [`ShmLender::POOLS`] of them. Not from the session's pool: Zenoh's transport copies other
/// messages into that one with a collection that may free a block a receiver still reads (one
/// whose watchdog a starved process missed), and receivers now read blocks in place
/// ([`PayloadBlocks`]). The blocks receivers have released are collected before each lend, so
/// that new blocks reuse memory already written. When no pool has room, a field takes memory of
/// its own and is copied into the session's pool when sent, as without lending.
pub struct ShmLender {
    pools: Mutex<Vec<ShmPool>>,
    /// Blocks lent, and requests refused.
    lent: std::sync::atomic::AtomicUsize,
    refused: std::sync::atomic::AtomicUsize,
}

type ShmPool = zenoh::shm::ShmProvider<zenoh::shm::PosixShmProviderBackend>;

impl ShmLender {
    /// Size of each pool (Zenoh locks a pool's whole segment in memory when it is created, and
    /// every receiver when it maps it: small pools keep that to what the fields need).
    pub const POOL_BYTES: usize = 8 << 20;
    /// Most pools.
    pub const POOLS: usize = 32;

    /// A lender for the nodes of `session`'s process, or None when shared memory is off in it or
    /// this process may not lock the pools' memory ([`shared_memory_lockable`]).
    pub fn new(session: &Session) -> Option<Self> {
        let on = !matches!(session.get_shm_provider(), zenoh::shm::ShmProviderState::Disabled);
        (on && shared_memory_lockable().is_ok()).then(|| Self {
            pools: Mutex::new(Vec::new()),
            lent: Default::default(),
            refused: Default::default(),
        })
    }

    /// Blocks lent so far, and requests refused (no room).
    pub fn counts(&self) -> (usize, usize) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.lent.load(Relaxed), self.refused.load(Relaxed))
    }

    /// Whether `/dev/shm` (where the pools' segments live) has room for twice a pool of `size`
    /// bytes, so that a new pool never takes the last of it.
    fn room_for_a_pool(size: usize) -> bool {
        shared_memory_room().is_some_and(|room| room >= 2 * size as u64)
    }
}

/// Bytes free in `/dev/shm`, where Zenoh's and the lenders' shared-memory pools live; None if it
/// cannot be read (no such file system).
pub fn shared_memory_room() -> Option<u64> {
    let path = c"/dev/shm";
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `path` is a NUL-terminated string and `st` a statvfs to fill.
    let ok = unsafe { libc::statvfs(path.as_ptr(), &mut st) } == 0;
    ok.then(|| (st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
}

/// Ok when this process may lock any amount of memory: Zenoh locks (`mlock`) every
/// shared-memory segment a process creates or maps, and a receiver that cannot map a sender's
/// segment drops its message (Zenoh 1.10.2 logs it at debug level only), which stalls a run.
/// That needs an unlimited `RLIMIT_MEMLOCK` or the `CAP_IPC_LOCK` capability; Err says which
/// limit is in the way.
pub fn shared_memory_lockable() -> Result<(), String> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is an rlimit to fill.
    if unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) } == 0 && lim.rlim_cur == libc::RLIM_INFINITY {
        return Ok(());
    }
    // CAP_IPC_LOCK is capability 14 of the effective set.
    let cap_ipc_lock = std::fs::read_to_string("/proc/self/status").ok().is_some_and(|status| {
        status
            .lines()
            .find_map(|l| l.strip_prefix("CapEff:"))
            .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
            .is_some_and(|caps| caps & (1 << 14) != 0)
    });
    if cap_ipc_lock {
        return Ok(());
    }
    Err(format!(
        "RLIMIT_MEMLOCK is {} KiB and the process lacks CAP_IPC_LOCK: Zenoh locks every shared-memory \
         segment it maps, and a receiver that cannot map one drops the message",
        lim.rlim_cur / 1024
    ))
}

impl BlockLender for ShmLender {
    fn lend(&self, len: usize) -> Option<Box<dyn ValueBlock>> {
        use zenoh::shm::ShmProviderBuilder;
        let bytes = len.checked_mul(8)?;
        let take = |p: &ShmPool| {
            p.garbage_collect();
            p.alloc(bytes).wait().ok()
        };
        let mut pools = self.pools.lock().unwrap_or_else(|e| e.into_inner());
        let mut buffer = pools.iter().find_map(take);
        // A pool for a field larger than the usual pools has room for the allocator's own
        // bookkeeping too (a pool of exactly the field's size could not hold it).
        let size = Self::POOL_BYTES.max(bytes.div_ceil(1 << 20) * (1 << 20) + (1 << 20));
        if buffer.is_none() && pools.len() < Self::POOLS && Self::room_for_a_pool(size) {
            if let Ok(pool) = ShmProviderBuilder::default_backend(size).wait() {
                // A pool that cannot give even the block it was made for is not kept.
                buffer = pool.alloc(bytes).wait().ok();
                if buffer.is_some() {
                    pools.push(pool);
                }
            }
        }
        drop(pools);
        // The pools' layouts are byte-aligned, but their allocator hands out 8-byte aligned
        // blocks: checked here, since a field's values are read in place as f64.
        let block = buffer
            .filter(|b| b.len() == bytes && (b.as_ptr() as usize).is_multiple_of(8))
            .map(|b| Box::new(ShmBlock(b)) as Box<dyn ValueBlock>);
        let counter = if block.is_some() { &self.lent } else { &self.refused };
        counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        block
    }
}

fn put_bytes(session: &Session, key: &str, bytes: impl Into<zenoh::bytes::ZBytes>) -> Result<(), TransportError> {
    session
        .put(key, bytes)
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| zerr(&format!("put {key}"), e))
}

/// Fetches a run's scene message from the launcher's queryable (bytes), waiting up to `timeout`.
pub fn fetch_scene(session: &Session, run_id: &str, timeout: Duration) -> Result<Vec<u8>, TransportError> {
    let deadline = Instant::now() + timeout;
    loop {
        let replies = session
            .get(scene_key(run_id))
            .timeout(Duration::from_secs(2))
            .wait()
            .map_err(|e| zerr("query scene", e))?;
        while let Ok(reply) = replies.recv() {
            if let Ok(sample) = reply.result() {
                return Ok(sample.payload().to_bytes().into_owned());
            }
        }
        if Instant::now() >= deadline {
            return Err(TransportError::Protocol(format!(
                "no launcher of run `{run_id}` answered the scene query within {timeout:?} (wrong --run or --connect?)"
            )));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// What a node process needs to take part in a run.
#[derive(Debug, Clone)]
pub struct NodeRun {
    pub run_id: String,
    pub expected: Expected,
    /// Role and index of this process's liveliness token.
    pub token_role: String,
    pub token_index: u32,
    /// Longest wait for the launcher's start.
    pub start_timeout: Duration,
    /// Longest wait for any message once started.
    pub idle_timeout: Duration,
    /// How long messages are still handled after a peer's token disappeared, before this
    /// process gives up (a peer that finished leaves right after its last messages).
    pub departure_grace: Duration,
    /// The launcher restarts node processes that die: a peer leaving is not fatal here (the
    /// launcher stops the run when it gives up on one); only the launcher's departure is.
    pub supervised: bool,
    /// This process replaces one that died mid-run: it rebuilds its nodes' state from the
    /// recorder's log of the run ([`fetch_log`]) instead of waiting for the launcher's start.
    pub resume: bool,
    /// Longest wait, once this process's nodes are finished, for the launcher's word that it
    /// holds the run's results ([`publish_done`]); past it the process leaves anyway (logged).
    pub done_timeout: Duration,
}

/// What reaches a node process from the bus.
enum Event {
    Data(Box<Received>),
    Start,
    Stop(String),
    /// The launcher holds the run's results: leaving is safe.
    Done,
    /// A liveliness token appeared (true) or disappeared (false).
    Alive(String, bool),
}

/// A message as it arrived: its key, its hash ([`message_hash`]: repeats are recognised by it),
/// and the message decoded, or why it was not.
struct Received {
    key: String,
    hash: u64,
    message: Result<Message, DecodeError>,
}

impl Received {
    fn from_bytes(key: String, bytes: &[u8], expected: &Expected) -> Self {
        Self {
            hash: message_hash(&key, bytes),
            message: decode(bytes, expected),
            key,
        }
    }

    /// Decodes a sample's payload where it lies, fragments and all (a large message over TCP
    /// arrives in many), instead of first copying it into one buffer.
    fn from_payload(key: String, payload: &zenoh::bytes::ZBytes, expected: &Expected, buffers: DecodeBuffers) -> Self {
        Self {
            hash: payload_hash(&key, payload),
            message: decode_payload(payload, expected, buffers),
            key,
        }
    }
}

/// [`message_hash`] of a payload that arrived on `key`, read across its slices (fragments, or the
/// blocks of a message sent with [`publish_lent`]) without joining them.
pub fn payload_hash(key: &str, payload: &zenoh::bytes::ZBytes) -> u64 {
    let slices: Vec<&[u8]> = payload.slices().collect();
    let head: Vec<u8> = slices.iter().flat_map(|s| s.iter()).take(HASHED_END).copied().collect();
    let mut tail: Vec<u8> = slices
        .iter()
        .rev()
        .flat_map(|s| s.iter().rev())
        .take(HASHED_END)
        .copied()
        .collect();
    tail.reverse();
    hash_parts(key, payload.len(), &head, &tail)
}

/// A payload decoded where its slices lie, into `buffers`.
pub fn decode_payload(
    payload: &zenoh::bytes::ZBytes,
    expected: &Expected,
    buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    decode_from_slices(payload.slices(), payload.len(), expected, buffers)
}

/// The blocks of a received payload that its fields may be read from in place: its slices of
/// [`PayloadBlocks::MIN`] bytes or more, 8-byte aligned. Over a link a large message arrives in
/// fragments smaller than that; such slices are the shared-memory blocks a sender wrote its
/// fields into ([`publish_lent`]). A field that keeps one holds the sender's block until the
/// field is dropped (once its node has handled the message).
struct PayloadBlocks {
    payload: zenoh::bytes::ZBytes,
    /// Address, length and index of each block among the payload's slices.
    blocks: Vec<(usize, usize, usize)>,
}

impl PayloadBlocks {
    /// Larger than any batch of a link (64 KiB at most).
    const MIN: usize = 1 << 16;

    fn of(payload: &zenoh::bytes::ZBytes) -> Option<Self> {
        let blocks: Vec<_> = payload
            .slices()
            .enumerate()
            .filter(|(_, s)| s.len() >= Self::MIN && (s.as_ptr() as usize).is_multiple_of(8))
            .map(|(k, s)| (s.as_ptr() as usize, s.len(), k))
            .collect();
        (!blocks.is_empty()).then(|| Self {
            payload: payload.clone(),
            blocks,
        })
    }

    /// `buffers` that read `payload`'s blocks in place, if it has any.
    fn holding(buffers: DecodeBuffers, payload: &zenoh::bytes::ZBytes) -> DecodeBuffers {
        match Self::of(payload) {
            Some(blocks) => buffers.holding(Arc::new(blocks)),
            None => buffers,
        }
    }
}

impl glissade_messages::HoldSource for PayloadBlocks {
    fn hold(&self, at: usize, len: usize) -> Option<Box<dyn glissade_messages::HeldBlock>> {
        let &(_, _, k) = self.blocks.iter().find(|&&(a, n, _)| a == at && n == len)?;
        Some(Box::new(HeldSlice {
            payload: self.payload.clone(),
            k,
        }))
    }
}

/// A field's values read in place: slice `k` of a received payload (kept alive by it).
struct HeldSlice {
    payload: zenoh::bytes::ZBytes,
    k: usize,
}

impl glissade_messages::HeldBlock for HeldSlice {
    fn values(&self) -> &[f64] {
        // Checked aligned and of a whole number of values when the block was taken.
        bytemuck::cast_slice(self.payload.slices().nth(self.k).expect("the payload's slice"))
    }
}

/// Messages in arrival order, cut into batches in which none repeats another (by hash): a repeat
/// starts the next batch, so that it is dropped only if its first copy was taken.
fn batches(received: impl IntoIterator<Item = Box<Received>>) -> Vec<Vec<Received>> {
    let mut out: Vec<Vec<Received>> = Vec::new();
    let mut hashes = HashSet::new();
    for r in received {
        if out.is_empty() || !hashes.insert(r.hash) {
            hashes = HashSet::from([r.hash]);
            out.push(Vec::new());
        }
        out.last_mut().expect("a batch").push(*r);
    }
    out
}

/// Declares a liveliness subscriber on every token of `run_id` (with the tokens already alive)
/// that forwards its changes to `tx` through `wrap`.
fn watch_tokens<T: Send + 'static>(
    session: &Session,
    run_id: &str,
    tx: mpsc::Sender<T>,
    wrap: impl Fn(String, bool) -> T + Send + Sync + 'static,
) -> Result<zenoh::pubsub::Subscriber<()>, TransportError> {
    session
        .liveliness()
        .declare_subscriber(alive_pattern(run_id))
        .history(true)
        .callback(move |s| {
            let _ = tx.send(wrap(s.key_expr().as_str().to_string(), s.kind() == SampleKind::Put));
        })
        .wait()
        .map_err(|e| zerr("liveliness subscriber", e))
}

/// Runs `nodes` (all hosted by this process) on `session` until each is finished.
///
/// Messages that do not decode for this run (other run, other scene, other schema version,
/// corrupt), repeats of a message already handled, and messages a node refuses while staying
/// unchanged ([`NodeError::is_rejection`]) are skipped with a reason passed to `log`; any other
/// node error (e.g. a non-finite result) stops the process with that node's error. A peer whose liveliness token disappears while a node here
/// is unfinished stops the process after `departure_grace` ([`TransportError::PeerLeft`]), so
/// does the launcher's stop message ([`TransportError::Stopped`]); `idle_timeout` bounds the
/// wait for any message.
pub fn run_nodes(
    session: &Session,
    run: &NodeRun,
    mut nodes: Vec<Box<dyn Node>>,
    mut log: impl FnMut(&str),
) -> Result<(), TransportError> {
    let (run_id, expected) = (&run.run_id, &run.expected);
    let own_token = alive_key(run_id, &run.token_role, run.token_index);
    let launcher_token = alive_key(run_id, "launcher", 0);
    let (tx, rx) = mpsc::channel::<Event>();
    let subscriptions: Vec<Vec<String>> = nodes.iter().map(|n| n.subscriptions()).collect();
    let mut keys: Vec<String> = subscriptions.iter().flatten().cloned().collect();
    keys.sort();
    keys.dedup();
    let mut subscribers = Vec::new();
    // The received fields' buffers: filled by the subscribers' decoding, given back once the
    // nodes have handled their message.
    let buffers = Arc::new(Mutex::new(BufferPool::default()));
    for key in &keys {
        let (tx, expected, pooled) = (tx.clone(), expected.clone(), DecodeBuffers::pooled(buffers.clone()));
        let sub = session
            .declare_subscriber(key.as_str())
            .callback(move |sample| {
                let key = sample.key_expr().as_str().to_string();
                let payload = sample.payload();
                let buffers = PayloadBlocks::holding(pooled.clone(), payload);
                let _ = tx.send(Event::Data(Box::new(Received::from_payload(
                    key, payload, &expected, buffers,
                ))));
            })
            .wait()
            .map_err(|e| zerr(&format!("subscribe {key}"), e))?;
        subscribers.push(sub);
    }
    for (key, control) in [(start_key(run_id), 0), (stop_key(run_id), 1), (done_key(run_id), 2)] {
        let tx = tx.clone();
        let sub = session
            .declare_subscriber(key.as_str())
            .callback(move |s| {
                let _ = tx.send(match control {
                    0 => Event::Start,
                    1 => Event::Stop(String::from_utf8_lossy(&s.payload().to_bytes()).into_owned()),
                    _ => Event::Done,
                });
            })
            .wait()
            .map_err(|e| zerr(&format!("subscribe {key}"), e))?;
        subscribers.push(sub);
    }
    let _peers = watch_tokens(session, run_id, tx.clone(), Event::Alive)?;
    let _token = session
        .liveliness()
        .declare_token(own_token.as_str())
        .wait()
        .map_err(|e| zerr("liveliness token", e))?;

    // With shared memory, the nodes write their large fields straight into the pools' blocks.
    let lender = ShmLender::new(session).map(Arc::new);
    if let Some(lender) = &lender {
        let lender: Arc<dyn BlockLender> = lender.clone();
        nodes.iter_mut().for_each(|n| n.lend_fields(lender.clone()));
    }
    // Messages already handled (a replacement process re-sends outputs its predecessor may have
    // sent: a repeat is dropped), and, when resuming, this process's outputs already on the bus.
    let mut seen: HashSet<u64> = HashSet::new();
    let mut published: HashSet<u64> = HashSet::new();
    // A batch of messages, as they arrived, none a repeat of another ([`batches`]): each node
    // handles the ones it subscribes to in arrival order, and the process's nodes do so in
    // parallel (a process hosting several subdomains uses every core, as the in-process bus
    // does); a node publishes its replies as it makes them. A node's error stops every node
    // before its next message, and the error of the earliest message is the one reported.
    let mut handle = |batch: Vec<Received>,
                      nodes: &mut Vec<Box<dyn Node>>,
                      published: &HashSet<u64>,
                      log: &mut dyn FnMut(&str)|
     -> Result<(), TransportError> {
        // A handled or ignored message's buffers hold the next ones.
        let recycle = |msg: Message| buffers.lock().unwrap_or_else(|e| e.into_inner()).recycle(msg.payload);
        let mut msgs: Vec<(String, u64, Message)> = Vec::with_capacity(batch.len());
        for received in batch {
            let Received { key, hash, message } = received;
            let msg = match message {
                Ok(m) => m,
                Err(e) => {
                    log(&format!("ignored a message on {key}: {e}"));
                    continue;
                }
            };
            if msg.topic() != key {
                log(&format!(
                    "ignored a message on {key}: its envelope and payload belong on {}",
                    msg.topic()
                ));
                recycle(msg);
                continue;
            }
            if seen.contains(&hash) {
                log(&format!(
                    "ignored a repeat of the message on {key} (iteration {}, {:?}): already handled",
                    msg.envelope.iteration, msg.envelope.stage
                ));
                recycle(msg);
                continue;
            }
            msgs.push((key, hash, msg));
        }
        let msgs_ref = &msgs;
        let failed = std::sync::atomic::AtomicBool::new(false);
        // Per node: the messages it refused (index, reason), or the error that ends the run with
        // the index of the message that caused it.
        type Outcome = Result<Vec<(usize, String)>, (usize, TransportError)>;
        let outcomes: Vec<Outcome> = nodes
            .par_iter_mut()
            .zip(subscriptions.par_iter())
            .map(|(node, subs)| {
                let mut refused = Vec::new();
                for (k, (key, _, msg)) in msgs_ref.iter().enumerate() {
                    if !subs.iter().any(|s| glissade_messages::key_matches(s, key)) {
                        continue;
                    }
                    if failed.load(std::sync::atomic::Ordering::Relaxed) {
                        break;
                    }
                    let mut handled = || -> Result<(), TransportError> {
                        let outs = node.handle(msg)?;
                        publish_outputs(session, node.as_mut(), outs, published)
                    };
                    match handled() {
                        Ok(()) => {}
                        // The node refused this message and is unchanged: it is not the run's (a
                        // damaged or stray copy); the genuine one may still come.
                        Err(TransportError::Node(e)) if e.is_rejection() => {
                            refused.push((k, format!("ignored a message on {key}: {e}")))
                        }
                        Err(e) => {
                            failed.store(true, std::sync::atomic::Ordering::Relaxed);
                            return Err((k, e));
                        }
                    }
                }
                Ok(refused)
            })
            .collect();
        let mut taken = vec![true; msgs.len()];
        let mut refusals = Vec::new();
        let mut first_error: Option<(usize, TransportError)> = None;
        for outcome in outcomes {
            match outcome {
                Ok(refused) => refusals.extend(refused),
                Err((k, e)) => {
                    if first_error.as_ref().is_none_or(|(first, _)| k < *first) {
                        first_error = Some((k, e));
                    }
                }
            }
        }
        // Logged in arrival order (a stable sort keeps node order within a message).
        refusals.sort_by_key(|(k, _)| *k);
        for (k, why) in refusals {
            log(&why);
            taken[k] = false;
        }
        if let Some((_, e)) = first_error {
            return Err(e);
        }
        // Only a message the nodes took counts as handled: a refused copy does not hide the
        // genuine one.
        for ((_, hash, msg), taken) in msgs.into_iter().zip(taken) {
            if taken {
                seen.insert(hash);
            }
            recycle(msg);
        }
        Ok(())
    };
    if run.resume {
        // Replace a process that died: the recorder's log holds every input its nodes handled
        // and every output they published; handling the inputs again in recorded order rebuilds
        // their state (nodes are deterministic whatever the arrival order of one stage's
        // inputs), and the outputs not yet on the bus are published as they come.
        let own: Vec<String> = nodes
            .iter()
            .map(|n| {
                let id = n.id();
                format!("glissade/{run_id}/{}/{}/**", id.role.key(), id.index)
            })
            .collect();
        let mut patterns = keys.clone();
        patterns.extend(own.iter().cloned());
        let recorded = fetch_log(session, run_id, &patterns, run.start_timeout)?;
        let mut inputs = Vec::new();
        for (key, bytes) in recorded {
            if own.iter().any(|p| glissade_messages::key_matches(p, &key)) {
                published.insert(message_hash(&key, &bytes));
            }
            if keys.iter().any(|p| glissade_messages::key_matches(p, &key)) {
                inputs.push((key, bytes));
            }
        }
        log(&format!(
            "resuming from the recorder's log: {} input(s) to handle again, {} output(s) already on the bus",
            inputs.len(),
            published.len()
        ));
        for node in &mut nodes {
            let outs = node.start()?;
            publish_outputs(session, node.as_mut(), outs, &published)?;
        }
        for (key, bytes) in inputs {
            handle(
                vec![Received::from_bytes(key, &bytes, expected)],
                &mut nodes,
                &published,
                &mut log,
            )?;
        }
        log("resumed: state rebuilt, continuing on the bus");
    } else {
        // Until the launcher's start: keep the data that arrives early (a faster peer may start
        // first), fail on a departure or a stop.
        let start_deadline = Instant::now() + run.start_timeout;
        let mut early = VecDeque::new();
        loop {
            let left = start_deadline.saturating_duration_since(Instant::now());
            match rx.recv_timeout(left) {
                Ok(Event::Start) => break,
                Ok(Event::Stop(reason)) => return Err(TransportError::Stopped(reason)),
                Ok(Event::Alive(key, false)) if key != own_token => {
                    return Err(TransportError::PeerLeft {
                        peer: node_of_alive_key(&key),
                        others: Vec::new(),
                    })
                }
                Ok(Event::Data(received)) => early.push_back(received),
                Ok(Event::Alive(..)) | Ok(Event::Done) => {}
                Err(_) => {
                    return Err(TransportError::Protocol(format!(
                        "the launcher did not start the run within {:?}",
                        run.start_timeout
                    )))
                }
            }
        }
        for node in &mut nodes {
            let outs = node.start()?;
            publish_outputs(session, node.as_mut(), outs, &published)?;
        }
        for batch in batches(early.drain(..)) {
            handle(batch, &mut nodes, &published, &mut log)?;
        }
    }
    let mut last_message = Instant::now();
    // The peers that left (first first), and when this process gives up on them.
    let mut departed: Vec<String> = Vec::new();
    let mut give_up: Option<Instant> = None;
    // The launcher may hold every result before a node here has heard the final decision.
    let mut done = false;
    // An event of another kind taken from the channel behind a batch of messages, handled next.
    let mut pending: Option<Event> = None;
    while !nodes.iter().all(|n| n.is_finished()) {
        let now = Instant::now();
        if give_up.is_some_and(|t| now >= t) {
            // The launcher's token going with the others means the bus itself went away: name it.
            let launcher = alive_key(run_id, "launcher", 0);
            let first = departed.iter().position(|k| *k == launcher).unwrap_or(0);
            let peer = node_of_alive_key(&departed.remove(first));
            return Err(TransportError::PeerLeft {
                peer,
                others: departed.iter().map(|k| node_of_alive_key(k)).collect(),
            });
        }
        if now.duration_since(last_message) >= run.idle_timeout {
            return Err(TransportError::Timeout(run.idle_timeout));
        }
        let mut wait = run.idle_timeout - now.duration_since(last_message);
        if let Some(t) = give_up {
            wait = wait.min(t.saturating_duration_since(now));
        }
        let event = match pending.take() {
            Some(event) => Ok(event),
            None => rx.recv_timeout(wait),
        };
        match event {
            Ok(Event::Data(received)) => {
                last_message = Instant::now();
                // With the messages already waiting behind it, up to the next event of another
                // kind (handled next, in its turn), in batches cut at repeats.
                let mut waiting = vec![received];
                loop {
                    match rx.try_recv() {
                        Ok(Event::Data(r)) => waiting.push(r),
                        Ok(other) => {
                            pending = Some(other);
                            break;
                        }
                        Err(_) => break,
                    }
                }
                for batch in batches(waiting) {
                    handle(batch, &mut nodes, &published, &mut log)?;
                }
            }
            Ok(Event::Stop(reason)) => return Err(TransportError::Stopped(reason)),
            Ok(Event::Alive(key, false)) if run.supervised && key != own_token && key != launcher_token => {
                log(&format!(
                    "peer {} left the run; waiting for the launcher to restart it",
                    node_of_alive_key(&key)
                ));
            }
            Ok(Event::Alive(key, false)) if key != own_token => {
                give_up.get_or_insert_with(|| Instant::now() + run.departure_grace);
                departed.push(key);
            }
            Ok(Event::Done) => done = true,
            Ok(Event::Alive(..)) | Ok(Event::Start) | Err(_) => {}
        }
    }
    // A put returns once the message is queued, not delivered: closing the session right after
    // the last one can lose it. Leave once the launcher says it holds the run's results.
    let deadline = Instant::now() + run.done_timeout;
    while !done {
        let event = match pending.take() {
            Some(event) => Ok(event),
            None => rx.recv_timeout(deadline.saturating_duration_since(Instant::now())),
        };
        match event {
            Ok(Event::Done) => done = true,
            Ok(Event::Stop(reason)) => return Err(TransportError::Stopped(reason)),
            Ok(Event::Alive(key, false)) if key == launcher_token => {
                log("the launcher left before it acknowledged the run's results; leaving");
                break;
            }
            Ok(_) => {}
            Err(_) => {
                log(&format!(
                    "the launcher did not acknowledge the run's results within {:?}; leaving",
                    run.done_timeout
                ));
                break;
            }
        }
    }
    if let Some((lent, refused)) = lender.map(|l| l.counts()).filter(|&(lent, refused)| lent + refused > 0) {
        log(&format!(
            "shared memory: {lent} large field(s) written in place and sent without a copy, {refused} copied \
             for lack of room{}",
            if refused > 0 {
                " (every pool full, or no room in /dev/shm for another)"
            } else {
                ""
            }
        ));
    }
    Ok(())
}

/// The launcher's side: serves the scene to the node processes' queries. Returns the queryable
/// (keep it alive for the whole run).
pub fn serve_scene(
    session: &Session,
    run_id: &str,
    scene_message: Vec<u8>,
) -> Result<zenoh::query::Queryable<()>, TransportError> {
    let key = scene_key(run_id);
    let reply_key = key.clone();
    session
        .declare_queryable(key.as_str())
        .callback(move |query| {
            let _ = query.reply(reply_key.as_str(), scene_message.clone()).wait();
        })
        .wait()
        .map_err(|e| zerr("scene queryable", e))
}

/// The launcher's view of which nodes of a run are alive (their liveliness tokens).
pub struct Presence {
    _subscriber: zenoh::pubsub::Subscriber<()>,
    rx: mpsc::Receiver<(String, bool)>,
    alive: BTreeSet<String>,
}

impl Presence {
    /// Watches every token of `run_id`, including those already alive.
    pub fn watch(session: &Session, run_id: &str) -> Result<Self, TransportError> {
        let (tx, rx) = mpsc::channel();
        let subscriber = watch_tokens(session, run_id, tx, |k, up| (k, up))?;
        Ok(Self {
            _subscriber: subscriber,
            rx,
            alive: BTreeSet::new(),
        })
    }

    /// The changes since the last call: (token key, appeared?), in arrival order.
    pub fn changes(&mut self) -> Vec<(String, bool)> {
        let changes: Vec<(String, bool)> = self.rx.try_iter().collect();
        for (key, up) in &changes {
            if *up {
                self.alive.insert(key.clone());
            } else {
                self.alive.remove(key);
            }
        }
        changes
    }

    pub fn is_alive(&self, key: &str) -> bool {
        self.alive.contains(key)
    }
}

/// Declares the launcher's liveliness token (nodes stop when it disappears).
pub fn launcher_token(session: &Session, run_id: &str) -> Result<zenoh::liveliness::LivelinessToken, TransportError> {
    session
        .liveliness()
        .declare_token(alive_key(run_id, "launcher", 0))
        .wait()
        .map_err(|e| zerr("liveliness token", e))
}

fn put_control(session: &Session, key: String, payload: Vec<u8>) -> Result<(), TransportError> {
    session
        .put(key.as_str(), payload)
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| zerr(&format!("put {key}"), e))
}

/// Tells every node of a run to start (once all are ready).
pub fn publish_start(session: &Session, run_id: &str) -> Result<(), TransportError> {
    put_control(session, start_key(run_id), Vec::new())
}

/// Tells every node of a run that the launcher holds the run's results: they may leave.
pub fn publish_done(session: &Session, run_id: &str) -> Result<(), TransportError> {
    put_control(session, done_key(run_id), Vec::new())
}

/// Tells every node of a run to stop now, with the reason.
pub fn publish_stop(session: &Session, run_id: &str, reason: &str) -> Result<(), TransportError> {
    put_control(session, stop_key(run_id), reason.as_bytes().to_vec())
}

/// Decodes the envelope only, to learn the scene fingerprint of a scene message.
pub fn scene_fingerprint_of(bytes: &[u8], run_id: &str) -> Result<u64, DecodeError> {
    glissade_messages::peek_envelope(bytes, run_id).map(|e| e.scene_fingerprint)
}

/// Key of the recorder's log queryable of a run: the recorded messages whose key matches one of
/// the query's patterns, in recorded order ([`fetch_log`]).
pub fn log_key(run_id: &str) -> String {
    format!("glissade/{run_id}/recorder/0/log")
}

/// A 64-bit hash of a message's key and bytes (its envelope and up to 4 KiB at each end, and its
/// length: a re-sent message is byte-identical, since nodes are deterministic).
pub fn message_hash(key: &str, bytes: &[u8]) -> u64 {
    let n = bytes.len();
    hash_parts(
        key,
        n,
        &bytes[..n.min(HASHED_END)],
        &bytes[n.saturating_sub(HASHED_END)..],
    )
}

/// Bytes of each end of a message that [`message_hash`] reads.
const HASHED_END: usize = 4096;

/// [`message_hash`] of a message of `len` bytes from its first and last (up to) [`HASHED_END`].
fn hash_parts(key: &str, len: usize, head: &[u8], tail: &[u8]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    key.hash(&mut h);
    len.hash(&mut h);
    head.hash(&mut h);
    tail.hash(&mut h);
    h.finish()
}

/// Publishes `outs`, a node's outputs, then its further outputs one at a time, each once the one
/// before is out ([`Node::next_output`]), giving each back to the node ([`Node::recycle`]).
fn publish_outputs(
    session: &Session,
    node: &mut dyn Node,
    outs: Vec<Message>,
    published: &HashSet<u64>,
) -> Result<(), TransportError> {
    for mut out in outs {
        publish_new(session, &mut out, published)?;
        node.recycle(out);
    }
    while let Some(mut out) = node.next_output() {
        publish_new(session, &mut out, published)?;
        node.recycle(out);
    }
    Ok(())
}

/// Publishes `msg` unless it is among the outputs already on the bus (`published`, the hashes
/// of a resumed process's outputs that the recorder holds).
/// Lent field blocks are sent without a copy ([`publish_lent`]).
fn publish_new(session: &Session, msg: &mut Message, published: &HashSet<u64>) -> Result<(), TransportError> {
    if published.is_empty() {
        return publish_lent(session, msg);
    }
    let (topic, bytes) = (msg.topic(), encode(msg));
    if published.contains(&message_hash(&topic, &bytes)) {
        return Ok(());
    }
    put_bytes(session, &topic, bytes)
}

/// Encodes a log: per message its key length (u32 LE), key, length (u64 LE) and bytes.
pub fn encode_log(messages: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::with_capacity(messages.iter().map(|(k, b)| 12 + k.len() + b.len()).sum());
    for (k, b) in messages {
        out.extend_from_slice(&(k.len() as u32).to_le_bytes());
        out.extend_from_slice(k.as_bytes());
        out.extend_from_slice(&(b.len() as u64).to_le_bytes());
        out.extend_from_slice(b);
    }
    out
}

/// Decodes [`encode_log`]'s bytes; a truncated or malformed log is an error naming the offset.
pub fn decode_log(bytes: &[u8]) -> Result<Vec<(String, Vec<u8>)>, TransportError> {
    let bad = |at: usize, what: &str| TransportError::Protocol(format!("malformed recorder log at byte {at}: {what}"));
    let mut out = Vec::new();
    let mut at = 0;
    let take = |at: &mut usize, n: usize, what: &str| -> Result<&[u8], TransportError> {
        let end = at
            .checked_add(n)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| bad(*at, what))?;
        let s = &bytes[*at..end];
        *at = end;
        Ok(s)
    };
    while at < bytes.len() {
        let n = u32::from_le_bytes(take(&mut at, 4, "key length")?.try_into().expect("4 bytes")) as usize;
        let key = std::str::from_utf8(take(&mut at, n, "key")?)
            .map_err(|_| bad(at, "key is not UTF-8"))?
            .to_string();
        let n = u64::from_le_bytes(take(&mut at, 8, "message length")?.try_into().expect("8 bytes"));
        let n = usize::try_from(n).map_err(|_| bad(at, "message length"))?;
        out.push((key, take(&mut at, n, "message")?.to_vec()));
    }
    Ok(out)
}

/// Asks the recorder of run `run_id` for every recorded message whose key matches one of
/// `patterns`, in recorded order (what a replacement node process needs to resume).
pub fn fetch_log(
    session: &Session,
    run_id: &str,
    patterns: &[String],
    timeout: Duration,
) -> Result<Vec<(String, Vec<u8>)>, TransportError> {
    let replies = session
        .get(log_key(run_id))
        .payload(patterns.join("\n"))
        .timeout(timeout)
        .wait()
        .map_err(|e| zerr("query the recorder's log", e))?;
    match replies.recv_timeout(timeout) {
        Ok(Some(reply)) => match reply.result() {
            Ok(sample) => decode_log(&sample.payload().to_bytes()),
            Err(e) => Err(TransportError::Protocol(format!(
                "the recorder cannot serve its log: {}",
                String::from_utf8_lossy(&e.payload().to_bytes())
            ))),
        },
        _ => Err(TransportError::Protocol(format!(
            "no answer from the recorder's log within {timeout:?} (is the run recorded?)"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_messages::{Envelope, Field, NodeId, Payload, Role, Stage, SCHEMA_VERSION};

    /// The payloads `session` receives on `key`, in a channel (keep the subscriber alive).
    fn received(session: &Session, key: &str) -> (zenoh::pubsub::Subscriber<()>, mpsc::Receiver<Vec<u8>>) {
        let (tx, rx) = mpsc::channel();
        let sub = session
            .declare_subscriber(key)
            .callback(move |s| {
                let _ = tx.send(s.payload().to_bytes().into_owned());
            })
            .wait()
            .unwrap();
        (sub, rx)
    }

    /// Subdomain 0's boundary state of iteration 0 in run `run_id`, `rows` × `cols` fields of
    /// distinct values.
    fn boundary_state(run_id: &str, scene_fingerprint: u64, rows: usize, cols: usize) -> Message {
        Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: run_id.into(),
                scene_fingerprint,
                iteration: 0,
                stage: Stage::Linear,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: 0,
                },
            },
            payload: Payload::BoundaryState {
                subdomain: 0,
                w: Field::from_fn(rows, cols, |r, c| (r * cols + c) as f64 * 1e-3),
                f: Field::from_fn(rows, cols, |r, c| -((r + c) as f64)),
            },
        }
    }

    /// A boundary state of several MB (about the size of one subdomain's field at N = 1000)
    /// crosses the router between two client sessions intact, and decodes.
    #[test]
    fn multi_megabyte_message_arrives_intact() {
        let port = free_loopback_port().unwrap();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let router = open(config("router", std::slice::from_ref(&endpoint), &[], false).unwrap()).unwrap();
        let a = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        let b = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        let msg = boundary_state("mb", 1, 320, 1001);
        let (_sub, rx) = received(&b, &msg.topic());
        // Let the subscription reach the router before publishing (pub/sub is not durable).
        std::thread::sleep(Duration::from_millis(500));
        publish(&a, &msg).unwrap();
        let bytes = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        assert!(bytes.len() > 5_000_000, "{} bytes", bytes.len());
        let back = decode(
            &bytes,
            &Expected {
                run_id: "mb".into(),
                scene_fingerprint: 1,
            },
        )
        .unwrap();
        assert_eq!(back, msg);
        drop(router);
    }

    /// A router and three clients on loopback: two with shared memory on, one without.
    fn shm_sessions() -> [Session; 4] {
        let port = free_loopback_port().unwrap();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let shm_config = |mode: &str, listen: &[String], connect: &[String]| {
            let mut c = config(mode, listen, connect, false).unwrap();
            set_shared_memory(&mut c, true).unwrap();
            c
        };
        let router = open(shm_config("router", std::slice::from_ref(&endpoint), &[])).unwrap();
        let a = open(shm_config("client", &[], std::slice::from_ref(&endpoint))).unwrap();
        let b = open(shm_config("client", &[], std::slice::from_ref(&endpoint))).unwrap();
        let plain = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        [router, a, b, plain]
    }

    /// With shared memory on, a large message is encoded straight into the session's pool (its
    /// bytes are a shared-memory buffer holding exactly `encode`'s bytes), and arrives through
    /// the router as such and intact; a small message, or a session without shared memory, takes
    /// the encoded-buffer path.
    #[test]
    fn large_messages_are_encoded_into_shared_memory() {
        let [router, a, b, plain] = shm_sessions();
        let msg = boundary_state("shm", 1, 300, 1001);
        // The pool is set up on first use, in the background.
        let deadline = Instant::now() + Duration::from_secs(20);
        let shared = loop {
            if let Some(bytes) = encode_shared(&a, &msg) {
                break bytes;
            }
            assert!(Instant::now() < deadline, "no shared-memory pool within 20 s");
            std::thread::sleep(Duration::from_millis(50));
        };
        assert!(shared.as_shm().is_some(), "not a shared-memory buffer");
        assert_eq!(shared.to_bytes().as_ref(), &encode(&msg)[..]);
        let small = boundary_state("shm", 1, 2, 3);
        assert!(encode(&small).len() < SHARED_ENCODING_MIN);
        assert!(encode_shared(&a, &small).is_none());
        assert!(encode_shared(&plain, &msg).is_none());

        let (tx, rx) = mpsc::channel();
        let _sub = b
            .declare_subscriber(msg.topic())
            .callback(move |s| {
                let _ = tx.send((s.payload().as_shm().is_some(), s.payload().to_bytes().into_owned()));
            })
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(500));
        publish(&a, &msg).unwrap();
        let (in_shm, bytes) = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        assert!(in_shm, "the message did not arrive through shared memory");
        let expected = Expected {
            run_id: "shm".into(),
            scene_fingerprint: 1,
        };
        assert_eq!(decode(&bytes, &expected).unwrap(), msg);
        drop((plain, router));
    }

    /// Fields a node wrote into blocks the shared-memory lender lent are sent as those blocks:
    /// they reach another process's session as slices of exactly their size (over the link a
    /// multi-MB message arrives in fragments of at most 64 KiB), the bytes are those of the
    /// message's encoding, the receiver's decoding reads the fields in place (held), and the
    /// sender's message no longer holds them. A field larger than the lender's pools gets a pool
    /// of its own; a session without shared memory has no lender.
    #[test]
    fn lent_fields_are_sent_as_their_shared_memory_blocks() {
        if let Err(why) = shared_memory_lockable() {
            eprintln!("skipped: {why}");
            return;
        }
        let [router, a, b, plain] = shm_sessions();
        assert!(ShmLender::new(&plain).is_none());
        let shm_lender = Arc::new(ShmLender::new(&a).expect("shared memory is on"));
        let lender: Arc<dyn BlockLender> = shm_lender.clone();
        // As in a run, the session's own pool is ready (set up on first use, in the background).
        let deadline = Instant::now() + Duration::from_secs(20);
        while encode_shared(&a, &boundary_state("shm", 1, 300, 30)).is_none() {
            assert!(Instant::now() < deadline, "no shared-memory pool within 20 s");
            std::thread::sleep(Duration::from_millis(50));
        }
        // Blocks larger than a pool, three at once: 3 × 12 MiB.
        let big: Vec<_> = (0..3).map(|_| lender.lend(3 << 19).expect("a block")).collect();
        assert!(big.iter().all(|b| b.values().len() == 3 << 19));
        assert_eq!(shm_lender.counts(), (3, 0));
        drop(big);
        // A pool is added only with room for two in /dev/shm.
        assert!(ShmLender::room_for_a_pool(ShmLender::POOL_BYTES));
        assert!(!ShmLender::room_for_a_pool(1 << 60));

        let (rows, cols) = (300, 1001);
        let expected = boundary_state("shm", 1, rows, cols);
        let mut pool = glissade_bus::convert::FieldPool::default();
        pool.lend_from(lender.clone());
        let Payload::BoundaryState { w, f, .. } = &expected.payload else {
            unreachable!()
        };
        let (w, f) = (glissade_bus::convert::view(w), glissade_bus::convert::view(f));
        let mut msg = Message {
            envelope: expected.envelope.clone(),
            payload: Payload::BoundaryState {
                subdomain: 0,
                w: pool.field_of(w),
                f: pool.field_of(f),
            },
        };
        msg.payload.fields(|f| assert!(f.data.is_lent()));
        assert_eq!(msg, expected);

        let (tx, rx) = mpsc::channel();
        let _sub = b
            .declare_subscriber(expected.topic())
            .callback(move |s| {
                let payload = s.payload();
                let sizes: Vec<usize> = payload.slices().map(|x| x.len()).collect();
                // As a node process decodes it: its fields read in place.
                let exp = Expected {
                    run_id: "shm".into(),
                    scene_fingerprint: 1,
                };
                assert!(PayloadBlocks::of(payload).is_some(), "blocks in the payload");
                let buffers = PayloadBlocks::holding(DecodeBuffers::default(), payload);
                let held = Received::from_payload(s.key_expr().to_string(), payload, &exp, buffers).message;
                let _ = tx.send((sizes, payload.to_bytes().into_owned(), held));
            })
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(500));
        publish_lent(&a, &mut msg).unwrap();
        msg.payload
            .fields(|f| assert!(f.data.is_empty() && !f.data.is_lent(), "the blocks were sent"));
        let (sizes, bytes, held) = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        let block = rows * cols * 8;
        assert_eq!(sizes.iter().filter(|&&n| n == block).count(), 2, "slices {sizes:?}");
        assert_eq!(bytes, encode(&expected));
        let exp = Expected {
            run_id: "shm".into(),
            scene_fingerprint: 1,
        };
        assert_eq!(decode(&bytes, &exp).unwrap(), expected);
        let held = held.unwrap();
        held.payload
            .fields(|f| assert!(f.data.is_held(), "a field copied out of its block"));
        assert_eq!(held, expected);
        drop((plain, router));
    }

    /// A payload in many fragments (as a large message arrives over TCP) decodes and hashes as
    /// its bytes do in one piece; damaged, it is refused for the same reason.
    #[test]
    fn a_fragmented_payload_decodes_and_hashes_as_its_bytes() {
        let msg = boundary_state("frag", 3, 40, 101);
        let expected = Expected {
            run_id: "frag".into(),
            scene_fingerprint: 3,
        };
        let fragmented = |bytes: &[u8], size: usize| {
            let mut w = zenoh::bytes::ZBytes::writer();
            for chunk in bytes.chunks(size) {
                w.append(zenoh::bytes::ZBytes::from(chunk.to_vec()));
            }
            w.finish()
        };
        // Fragments smaller than, equal to and larger than the 4 KiB ends the hash reads, of a
        // large message and of one shorter than those ends (its head and tail overlap).
        let small = boundary_state("frag", 3, 3, 20);
        for msg in [&msg, &small] {
            let bytes = encode(msg);
            let key = msg.topic();
            for size in [7, 1000, 4096, 5000, bytes.len()] {
                let z = fragmented(&bytes, size);
                assert_eq!(z.slices().count(), bytes.len().div_ceil(size));
                let (a, b) = (
                    Received::from_payload(key.clone(), &z, &expected, DecodeBuffers::default()),
                    Received::from_bytes(key.clone(), &bytes, &expected),
                );
                assert_eq!(a.hash, b.hash, "fragments of {size}");
                assert_eq!(&a.message.unwrap(), msg);
            }
        }
        let (bytes, key) = (encode(&msg), msg.topic());
        let cut = &bytes[..bytes.len() - 100];
        let (a, b) = (
            Received::from_payload(key.clone(), &fragmented(cut, 1000), &expected, DecodeBuffers::default()),
            Received::from_bytes(key.clone(), cut, &expected),
        );
        assert_eq!(a.hash, b.hash);
        let (ea, eb) = (a.message.unwrap_err(), b.message.unwrap_err());
        assert_eq!(ea, eb, "{ea} / {eb}");
    }

    /// A node that publishes one multi-MB message on start and is then finished.
    struct OneShot {
        msg: Message,
        done: bool,
    }

    impl Node for OneShot {
        fn id(&self) -> NodeId {
            self.msg.envelope.sender
        }
        fn subscriptions(&self) -> Vec<String> {
            Vec::new()
        }
        fn start(&mut self) -> Result<Vec<Message>, NodeError> {
            self.done = true;
            Ok(vec![self.msg.clone()])
        }
        fn handle(&mut self, _: &Message) -> Result<Vec<Message>, NodeError> {
            Ok(Vec::new())
        }
        fn is_finished(&self) -> bool {
            self.done
        }
    }

    /// A launcher-side router session on a free loopback port, with its endpoint.
    fn test_launcher() -> (Session, String) {
        let port = free_loopback_port().unwrap();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let launcher = open(config("router", std::slice::from_ref(&endpoint), &[], false).unwrap()).unwrap();
        (launcher, endpoint)
    }

    /// What a test node process of run `run_id` (scene fingerprint 1) is told, with its token's
    /// role and its wait for the launcher's `done`.
    fn test_run(run_id: &str, token_role: &str, done_timeout: Duration) -> NodeRun {
        NodeRun {
            run_id: run_id.into(),
            expected: Expected {
                run_id: run_id.into(),
                scene_fingerprint: 1,
            },
            token_role: token_role.into(),
            token_index: 0,
            start_timeout: Duration::from_secs(20),
            idle_timeout: Duration::from_secs(20),
            departure_grace: Duration::from_secs(2),
            supervised: false,
            resume: false,
            done_timeout,
        }
    }

    /// Subdomain `index`'s final displacement `u` at `iteration` in run `run_id` (scene
    /// fingerprint 1).
    fn displacement(run_id: &str, index: u32, iteration: u32, u: Field) -> Message {
        Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: run_id.into(),
                scene_fingerprint: 1,
                iteration,
                stage: Stage::Final,
                sender: NodeId {
                    role: Role::Subdomain,
                    index,
                },
            },
            payload: Payload::Displacement { subdomain: index, u },
        }
    }

    /// Waits until `ready` holds, or 10 s have passed.
    fn wait_until(ready: impl Fn() -> bool) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while !ready() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Waits (up to 20 s) for liveliness token `key` to appear among `changes`.
    fn wait_token(changes: &mpsc::Receiver<(String, bool)>, key: &str) {
        loop {
            let (k, up) = changes.recv_timeout(Duration::from_secs(20)).expect("the node's token");
            if k == key && up {
                break;
            }
        }
    }

    /// A process whose nodes are finished leaves only once the launcher says `done` (its last
    /// put may still be queued), and without it only after its bounded wait, saying so.
    #[test]
    fn finished_process_waits_for_the_launchers_done() {
        let (launcher, endpoint) = test_launcher();
        let run_id = "done";
        let expected = test_run(run_id, "subdomain", Duration::ZERO).expected;
        let msg = displacement(run_id, 0, 3, Field::from_fn(400, 1001, |r, c| (r + 2 * c) as f64));
        let (_sub, rx) = received(&launcher, &msg.topic());
        let (alive_tx, alive_rx) = mpsc::channel::<(String, bool)>();
        let _alive = watch_tokens(&launcher, run_id, alive_tx, |k, up| (k, up)).unwrap();
        let _launcher_token = launcher_token(&launcher, run_id).unwrap();
        let spawn = |done_timeout: Duration| {
            let (endpoint, msg) = (endpoint.clone(), msg.clone());
            std::thread::spawn(move || {
                let session = open(config("client", &[], &[endpoint], false).unwrap()).unwrap();
                let run = test_run(run_id, "subdomain", done_timeout);
                let mut lines = Vec::new();
                let out = run_nodes(&session, &run, vec![Box::new(OneShot { msg, done: false })], |l| {
                    lines.push(l.to_string())
                });
                let _ = session.close().wait();
                (out, lines)
            })
        };
        let node_token = alive_key(run_id, "subdomain", 0);

        // Acknowledged: the node is still there a second after its message arrived, and leaves
        // at once after `done`.
        let node = spawn(Duration::from_secs(60));
        wait_token(&alive_rx, &node_token);
        publish_start(&launcher, run_id).unwrap();
        let bytes = rx.recv_timeout(Duration::from_secs(20)).expect("the node's output");
        assert_eq!(decode(&bytes, &expected).unwrap(), msg);
        std::thread::sleep(Duration::from_secs(1));
        assert!(!node.is_finished(), "the node left before the launcher's done");
        let asked = Instant::now();
        publish_done(&launcher, run_id).unwrap();
        let (out, lines) = node.join().unwrap();
        out.unwrap();
        assert!(asked.elapsed() < Duration::from_secs(10), "{:?}", asked.elapsed());
        assert!(lines.is_empty(), "{lines:?}");

        // Not acknowledged: the node leaves after its bounded wait and says why.
        let node = spawn(Duration::from_millis(500));
        wait_token(&alive_rx, &node_token);
        publish_start(&launcher, run_id).unwrap();
        rx.recv_timeout(Duration::from_secs(20)).expect("the node's output");
        let (out, lines) = node.join().unwrap();
        out.unwrap();
        assert!(
            lines
                .iter()
                .any(|l| l.contains("did not acknowledge the run's results")),
            "{lines:?}"
        );
    }

    /// A node that, handling its message, waits (up to 10 s) for the other nodes of its process
    /// to be handling theirs at the same time, and says whether they were.
    struct Meeting {
        id: NodeId,
        topic: String,
        inside: Arc<std::sync::atomic::AtomicUsize>,
        met: Arc<Mutex<Vec<bool>>>,
        done: bool,
    }

    impl Node for Meeting {
        fn id(&self) -> NodeId {
            self.id
        }
        fn subscriptions(&self) -> Vec<String> {
            vec![self.topic.clone()]
        }
        fn start(&mut self) -> Result<Vec<Message>, NodeError> {
            Ok(Vec::new())
        }
        fn handle(&mut self, _: &Message) -> Result<Vec<Message>, NodeError> {
            use std::sync::atomic::Ordering;
            self.inside.fetch_add(1, Ordering::SeqCst);
            wait_until(|| self.inside.load(Ordering::SeqCst) >= 2);
            self.met.lock().unwrap().push(self.inside.load(Ordering::SeqCst) == 2);
            self.done = true;
            Ok(Vec::new())
        }
        fn is_finished(&self) -> bool {
            self.done
        }
    }

    /// A node that, handling its message, waits (up to 10 s) until `open` is set.
    struct Gate {
        topic: String,
        open: Arc<std::sync::atomic::AtomicBool>,
        done: bool,
    }

    impl Node for Gate {
        fn id(&self) -> NodeId {
            NodeId {
                role: Role::Coarse,
                index: 0,
            }
        }
        fn subscriptions(&self) -> Vec<String> {
            vec![self.topic.clone()]
        }
        fn start(&mut self) -> Result<Vec<Message>, NodeError> {
            Ok(Vec::new())
        }
        fn handle(&mut self, _: &Message) -> Result<Vec<Message>, NodeError> {
            wait_until(|| self.open.load(std::sync::atomic::Ordering::SeqCst));
            self.done = true;
            Ok(Vec::new())
        }
        fn is_finished(&self) -> bool {
            self.done
        }
    }

    /// Two nodes of one process, each waiting inside its `handle` for the other, both see the
    /// other there: the process handled their messages in parallel (handled one after the
    /// other, the first would wait its 10 s alone). The two messages wait on the process's
    /// channel together: sent before the launcher's start, or, after it, while a third node
    /// (the gate) holds the process's loop until they are there.
    fn nodes_meet(run_id: &str, after_start: bool) {
        let (launcher, endpoint) = test_launcher();
        let message = |index: u32| displacement(run_id, index, 1, Field::zeros(2, 3));
        let (alive_tx, alive_rx) = mpsc::channel::<(String, bool)>();
        let _alive = watch_tokens(&launcher, run_id, alive_tx, |k, up| (k, up)).unwrap();
        let _launcher_token = launcher_token(&launcher, run_id).unwrap();
        let inside = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let met = Arc::new(Mutex::new(Vec::new()));
        let gate = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let mut nodes: Vec<Box<dyn Node>> = (0..2)
            .map(|i| {
                Box::new(Meeting {
                    id: NodeId {
                        role: Role::Interface,
                        index: i,
                    },
                    topic: message(i).topic(),
                    inside: inside.clone(),
                    met: met.clone(),
                    done: false,
                }) as Box<dyn Node>
            })
            .collect();
        if after_start {
            nodes.push(Box::new(Gate {
                topic: message(2).topic(),
                open: gate.clone(),
                done: false,
            }));
        }
        let run_id_owned = run_id.to_string();
        let node = std::thread::spawn(move || {
            let session = open(config("client", &[], &[endpoint], false).unwrap()).unwrap();
            let run = test_run(&run_id_owned, "interface", Duration::from_millis(200));
            // Two threads, whatever the machine's core count.
            let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
            let out = pool.install(|| run_nodes(&session, &run, nodes, |_| {}));
            let _ = session.close().wait();
            out
        });
        wait_token(&alive_rx, &alive_key(run_id, "interface", 0));
        let started = Instant::now();
        if after_start {
            publish_start(&launcher, run_id).unwrap();
            publish(&launcher, &message(2)).unwrap();
            std::thread::sleep(Duration::from_millis(300));
        }
        for i in 0..2 {
            publish(&launcher, &message(i)).unwrap();
        }
        std::thread::sleep(Duration::from_millis(500));
        if after_start {
            gate.store(true, std::sync::atomic::Ordering::SeqCst);
        } else {
            publish_start(&launcher, run_id).unwrap();
        }
        node.join().unwrap().unwrap();
        assert_eq!(
            *met.lock().unwrap(),
            vec![true, true],
            "the nodes did not handle their messages together"
        );
        assert!(started.elapsed() < Duration::from_secs(9), "{:?}", started.elapsed());
    }

    /// Messages are cut into batches at a repeat: the repeat starts the next batch (its first
    /// copy's fate is known by then).
    #[test]
    fn a_repeat_starts_the_next_batch() {
        let expected = test_run("batches", "interface", Duration::ZERO).expected;
        let received = |bytes: &[u8]| Box::new(Received::from_bytes("k".into(), bytes, &expected));
        let (a, b, c) = (received(&[1]), received(&[2]), received(&[3]));
        let hashes = |batch: &Vec<Received>| batch.iter().map(|r| r.hash).collect::<Vec<_>>();
        let (ha, hb, hc) = (a.hash, b.hash, c.hash);
        let cut = batches([a, b, received(&[1]), c, received(&[2])]);
        assert_eq!(
            cut.iter().map(hashes).collect::<Vec<_>>(),
            vec![vec![ha, hb], vec![ha, hc, hb]]
        );
        assert!(batches(Vec::new()).is_empty());
    }

    #[test]
    fn a_process_handles_its_nodes_early_messages_in_parallel() {
        nodes_meet("parallel-early", false);
    }

    #[test]
    fn a_process_handles_its_nodes_waiting_messages_in_parallel() {
        nodes_meet("parallel-waiting", true);
    }

    /// The recorder's log survives its encoding, and a truncated one is refused with the offset.
    #[test]
    fn log_round_trip_and_truncation() {
        let log = vec![
            ("glissade/r/subdomain/0/boundary_state".to_string(), vec![1u8, 2, 3]),
            ("glissade/r/interface/0/decision".to_string(), Vec::new()),
        ];
        let bytes = encode_log(&log);
        assert_eq!(decode_log(&bytes).unwrap(), log);
        assert_eq!(decode_log(&[]).unwrap(), Vec::new());
        for cut in 1..bytes.len() {
            let e = decode_log(&bytes[..cut]);
            // A cut between two entries is a shorter valid log; anywhere else, an error.
            if cut != 4 + log[0].0.len() + 8 + 3 {
                let msg = e.expect_err("truncated").to_string();
                assert!(msg.contains("malformed recorder log at byte"), "{msg}");
            }
        }
        assert_ne!(message_hash("a", &[1, 2]), message_hash("a", &[1, 3]));
        assert_ne!(message_hash("a", &[1, 2]), message_hash("b", &[1, 2]));
    }
}
