//! Zenoh session configuration: mode and endpoints, link lease, shared memory on or off, TLS
//! user/password authentication, and access control by certificate common name and by user.

use crate::error::zerr;
use crate::TransportError;
use glissade_messages::NodeId;
use std::path::{Path, PathBuf};
use std::time::Duration;
use zenoh::{Config, Session, Wait};

/// Link lease: a peer whose link is silent this long is declared gone (Zenoh's default is 10 s).
pub const LEASE: Duration = Duration::from_secs(4);

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
    // Fields are multi-MB messages of data priority, cut into 64 KiB batches: with Zenoh's
    // default queue of 2 batches a publisher waits on the link's sender thread after every
    // 128 KiB; 16 (the most Zenoh allows, allocated as needed) lets it run ahead by 1 MiB.
    c.insert_json5("transport/link/tx/queue/size/data", &TX_QUEUE_BATCHES.to_string())
        .map_err(|e| zerr("config tx queue", e))?;
    set_shared_memory(&mut c, false)?;
    Ok(c)
}

/// Batches in each link's transmission queue of data priority ([`config`]).
pub const TX_QUEUE_BATCHES: usize = 16;

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

/// Access control on a router (deny by default) over the key space of one run.
///
/// - Sessions must present a certificate whose common name is in `common_names` (mutual TLS)
///   when it is given;
/// - with `members` (user/password authentication, [`Auth::Router`]), every member may
///   subscribe to, query and watch the tokens of the whole run, but may publish, declare
///   tokens and queryables and reply only on its own keys (for a node process, those of the
///   nodes it hosts, [`glissade_messages::topic::own_keys`]); without, every allowed session may
///   do anything within the run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Access {
    pub run_id: String,
    pub common_names: Option<Vec<String>>,
    /// The run's users and the keys each one may speak on.
    pub members: Option<Vec<Member>>,
}

/// A user of a run's bus and the key expressions it may speak on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Member {
    pub user: String,
    pub keys: Vec<String>,
}

impl Member {
    /// Node `id` alone: its user ([`user_of`]) and its own keys.
    pub fn node(run_id: &str, id: NodeId) -> Self {
        Self {
            user: user_of(id),
            keys: glissade_messages::topic::own_keys(run_id, id),
        }
    }
}

impl Access {
    /// Access to the run's key space for sessions whose certificate common name is in `allow`.
    pub fn run(run_id: &str, allow: &[String]) -> Self {
        Self {
            run_id: run_id.to_string(),
            common_names: Some(allow.to_vec()),
            members: None,
        }
    }
}

/// The user name of node `id` on its run's bus: `<role>-<index>` (e.g. `subdomain-3`).
pub fn user_of(id: NodeId) -> String {
    format!("{}-{}", id.role.key(), id.index)
}

/// A user of a run's bus and its password. Zenoh's user/password authentication: the router
/// sends a random nonce and checks the client's HMAC of it, so the password never crosses the
/// link.
#[derive(Clone, PartialEq, Eq)]
pub struct Credentials {
    pub user: String,
    password: String,
}

impl std::fmt::Debug for Credentials {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Credentials {{ user: {:?}, password: *** }}", self.user)
    }
}

impl Credentials {
    /// A new random password (256 bits from the operating system) for `user`.
    pub fn random(user: &str) -> Result<Self, TransportError> {
        let mut bytes = [0u8; 32];
        getrandom::fill(&mut bytes)
            .map_err(|e| TransportError::Protocol(format!("no random bytes for a password: {e}")))?;
        Ok(Self {
            user: user.to_string(),
            password: bytes.iter().map(|b| format!("{b:02x}")).collect(),
        })
    }

    /// Credentials from their text: one line `user:password` (a final newline allowed).
    pub fn parse(text: &str) -> Result<Self, String> {
        let line = text.strip_suffix('\n').unwrap_or(text);
        let (user, password) = line
            .split_once(':')
            .ok_or("expected one line `user:password` (the file the launcher wrote)")?;
        let plain = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_graphic() && b != b':');
        if !plain(user) || !plain(password) {
            return Err(
                "expected one line `user:password`, both non-empty, without spaces, colons or other lines".into(),
            );
        }
        Ok(Self {
            user: user.into(),
            password: password.into(),
        })
    }

    /// `user:password` and a newline: the text [`Credentials::parse`] reads, and a line of a
    /// router's dictionary.
    pub fn line(&self) -> String {
        format!("{}:{}\n", self.user, self.password)
    }
}

/// User/password authentication of a session.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Auth {
    /// A router that accepts only the users listed in this dictionary file (`user:password`
    /// lines, [`Dictionary`]); it reads it once, when opened.
    Router { dictionary: PathBuf },
    /// A client (or peer) that presents these credentials.
    Client(Credentials),
}

/// A router's user dictionary, written in a folder only this user can enter and removed (folder
/// and file) when dropped: a router reads it when it opens, so it can go right after.
pub struct Dictionary {
    dir: PathBuf,
    file: PathBuf,
}

impl Dictionary {
    /// Writes the `members`' lines into a new private file under `parent` (mode 0700 folder,
    /// 0600 file, both new).
    pub fn write(parent: &Path, members: &[Credentials]) -> Result<Self, TransportError> {
        use std::io::Write;
        use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
        let io = |what: &str, p: &Path, e: std::io::Error| {
            TransportError::Protocol(format!("the bus's user dictionary: cannot {what} {}: {e}", p.display()))
        };
        let mut tag = [0u8; 8];
        getrandom::fill(&mut tag)
            .map_err(|e| TransportError::Protocol(format!("no random bytes for a folder name: {e}")))?;
        let dir = parent.join(format!(
            "glissade-bus-{}",
            tag.iter().map(|b| format!("{b:02x}")).collect::<String>()
        ));
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&dir)
            .map_err(|e| io("create", &dir, e))?;
        let file = dir.join("users");
        let d = Self { dir, file };
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(&d.file)
            .map_err(|e| io("create", &d.file, e))?;
        let text: String = members.iter().map(Credentials::line).collect();
        f.write_all(text.as_bytes())
            .and_then(|_| f.sync_all())
            .map_err(|e| io("write", &d.file, e))?;
        Ok(d)
    }

    pub fn path(&self) -> &Path {
        &self.file
    }
}

impl Drop for Dictionary {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.file);
        let _ = std::fs::remove_dir(&self.dir);
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
    auth: Option<&Auth>,
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
        if mode != "router" {
            return Err(TransportError::Protocol("access control is a router's".into()));
        }
        if a.common_names.is_some() && !tls.is_some_and(|t| t.mutual) {
            return Err(TransportError::Protocol(
                "access control by certificate common name needs a router with mutual TLS".into(),
            ));
        }
        if a.members.is_some() && !matches!(auth, Some(Auth::Router { .. })) {
            return Err(TransportError::Protocol(
                "access control by user needs a router with user/password authentication".into(),
            ));
        }
        if a.common_names.as_ref().is_some_and(Vec::is_empty) || a.members.as_ref().is_some_and(Vec::is_empty) {
            return Err(TransportError::Protocol(
                "access control with no allowed name or no member would let nothing through".into(),
            ));
        }
        if a.common_names.is_none() && a.members.is_none() {
            return Err(TransportError::Protocol(
                "access control needs common names or members to allow".into(),
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
    match auth {
        Some(Auth::Router { dictionary }) => c
            .insert_json5("transport/auth/usrpwd/dictionary_file", &path(dictionary))
            .map_err(|e| zerr("config auth dictionary", e))?,
        Some(Auth::Client(cr)) => {
            c.insert_json5("transport/auth/usrpwd/user", &json_string(&cr.user))
                .map_err(|e| zerr("config auth user", e))?;
            c.insert_json5("transport/auth/usrpwd/password", &json_string(&cr.password))
                .map_err(|e| zerr("config auth password", e))?;
        }
        None => {}
    }
    if let Some(a) = access {
        c.insert_json5("access_control", &acl(a))
            .map_err(|e| zerr("config access_control", e))?;
    }
    Ok(c)
}

/// Every kind of message Zenoh's access control knows.
const ALL: &[&str] = &[
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
];

/// The access control configuration of [`Access`] (zenoh's `access_control`, JSON5).
fn acl(a: &Access) -> String {
    let list = |v: &[String]| format!("[{}]", v.iter().map(|s| json_string(s)).collect::<Vec<_>>().join(","));
    let run = vec![glissade_messages::topic::run_topics(&a.run_id)];
    let rule = |id: &str, messages: &[&str], flow: &str, keys: &[String]| {
        format!(
            r#"{{ id: {id}, messages: {messages}, flows: ["{flow}"], permission: "allow", key_exprs: {keys} }}"#,
            id = json_string(id),
            messages = list(&messages.iter().map(|m| m.to_string()).collect::<Vec<_>>()),
            keys = list(keys),
        )
    };
    let names = a
        .common_names
        .as_ref()
        .map(|n| format!(", cert_common_names: {}", list(n)));
    let names = names.as_deref().unwrap_or("");
    let (mut rules, mut subjects, mut policies) = (Vec::new(), Vec::new(), Vec::new());
    match &a.members {
        None => {
            rules.push(rule("run-in", ALL, "ingress", &run));
            rules.push(rule("run-out", ALL, "egress", &run));
            subjects.push(format!(r#"{{ id: "allowed"{names} }}"#));
            policies.push(r#"{ rules: ["run-in", "run-out"], subjects: ["allowed"] }"#.to_string());
        }
        Some(members) => {
            // Everyone of the run listens to all of it; what reaches a member (egress) is
            // whatever the run carries.
            const LISTEN: &[&str] = &[
                "declare_subscriber",
                "query",
                "liveliness_query",
                "declare_liveliness_subscriber",
            ];
            const SPEAK: &[&str] = &["put", "delete", "reply", "declare_queryable", "liveliness_token"];
            rules.push(rule("listen", LISTEN, "ingress", &run));
            rules.push(rule("hear", ALL, "egress", &run));
            let mut all = Vec::new();
            for (k, m) in members.iter().enumerate() {
                let (rule_id, subject_id) = (format!("speak-{k}"), format!("member-{k}"));
                rules.push(rule(&rule_id, SPEAK, "ingress", &m.keys));
                subjects.push(format!(
                    "{{ id: {}, usernames: {}{names} }}",
                    json_string(&subject_id),
                    list(std::slice::from_ref(&m.user))
                ));
                policies.push(format!(
                    "{{ rules: [{}], subjects: [{}] }}",
                    json_string(&rule_id),
                    json_string(&subject_id)
                ));
                all.push(subject_id);
            }
            policies.push(format!(r#"{{ rules: ["listen", "hear"], subjects: {} }}"#, list(&all)));
        }
    }
    format!(
        r#"{{ enabled: true, default_permission: "deny", rules: [{}], subjects: [{}], policies: [{}] }}"#,
        rules.join(","),
        subjects.join(","),
        policies.join(",")
    )
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every session of a run (node, recorder, the launcher's router) queues up to
    /// [`TX_QUEUE_BATCHES`] batches of data per link, not Zenoh's default of 2.
    #[test]
    fn every_session_queues_sixteen_data_batches_per_link() {
        for mode in ["router", "client", "peer"] {
            let c = config(mode, &[], &[], false).unwrap();
            assert_eq!(
                c.get_json("transport/link/tx/queue/size/data").unwrap(),
                TX_QUEUE_BATCHES.to_string(),
                "{mode}"
            );
        }
        let c = secure_config(
            "client",
            &[],
            &["tcp/127.0.0.1:7447".to_string()],
            false,
            None,
            None,
            None,
        )
        .unwrap();
        assert_eq!(
            c.get_json("transport/link/tx/queue/size/data").unwrap(),
            TX_QUEUE_BATCHES.to_string()
        );
    }
}
