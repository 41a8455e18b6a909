//! Zenoh session configuration: mode and endpoints, link lease, shared memory on or off, TLS
//! and access control by certificate common name.

use crate::error::zerr;
use crate::TransportError;
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
            key_exprs: vec![glissade_messages::topic::run_topics(run_id)],
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
