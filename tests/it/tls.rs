//! Runs over Zenoh TLS (issue 9, "runs across machines"): the test certificates of
//! `tests/fixtures/tls` (one CA; `node` with CN `glissade-node`, `intruder` with CN `intruder`,
//! both signed by it; `stranger`, CN `glissade-node`, signed by another CA). Loopback only,
//! multicast scouting off, every wait bounded, every process reaped.

use crate::common::scratch;
use glissade::distributed::Network;
use glissade::run::Run;
use glissade::runner::RunOptions;
use glissade_zenoh as transport;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// The tests of this file take turns: the routers of the in-process tests share this process's
/// Zenoh runtime with the launcher of the multi-process run, whose 4 s link lease a starved
/// runtime could miss.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/tls")
        .join(name)
}

fn tls_endpoint() -> String {
    let port = transport::free_loopback_port().unwrap();
    format!("tls/127.0.0.1:{port}")
}

/// TLS trusting `ca`, presenting certificate `who` (`who.pem`, `who.key`) when given.
fn tls(ca: &str, who: Option<&str>, mutual: bool) -> transport::Tls {
    transport::Tls {
        root_ca: fixture(&format!("{ca}.pem")),
        identity: who.map(|w| (fixture(&format!("{w}.pem")), fixture(&format!("{w}.key")))),
        mutual,
    }
}

/// A router on `endpoint` with mutual TLS (certificate `node`), and access control allowing
/// `allow` on the key space of run `run` when given.
fn router(endpoint: &str, allow: Option<(&str, &[String])>) -> zenoh::Session {
    let access = allow.map(|(run, names)| transport::Access::run(run, names));
    let config = transport::secure_config(
        "router",
        &[endpoint.to_string()],
        &[],
        false,
        Some(&tls("ca", Some("node"), true)),
        None,
        access.as_ref(),
    )
    .unwrap();
    transport::open(config).expect("the TLS router opens")
}

fn client(endpoint: &str, tls: &transport::Tls) -> Result<zenoh::Session, transport::TransportError> {
    transport::open(transport::secure_config(
        "client",
        &[],
        &[endpoint.to_string()],
        false,
        Some(tls),
        None,
        None,
    )?)
}

/// The small three-layer scene as processes over mutual TLS with access control (the launcher's
/// certificate, CN `glissade-node`, is the allowed name; the TLS paths are relative to the scene
/// file's folder) gives the in-process run bit for bit: TLS changes how bytes travel, not which.
/// A list that leaves the launcher's own name out is refused up front.
#[test]
fn three_layers_over_mutual_tls_with_access_control_match_in_process() {
    let _turn = one_at_a_time();
    let dir = scratch("tls-run");
    std::fs::create_dir_all(dir.join("certs")).unwrap();
    for f in ["ca.pem", "node.pem", "node.key"] {
        std::fs::copy(fixture(f), dir.join("certs").join(f)).unwrap();
    }
    let base = crate::common::scene_text("small-three-layer");
    let text = format!(
        "{base}\n[network]\ntls = {{ root_ca = \"certs/ca.pem\", cert = \"certs/node.pem\", key = \"certs/node.key\", \
         mutual = true }}\nallow = [\"glissade-node\"]\n"
    );
    // An access list without the launcher's own name is refused before any process starts.
    let path = dir.join("three-layer-tls.toml");
    std::fs::write(
        &path,
        text.replace("allow = [\"glissade-node\"]", "allow = [\"node-b\"]"),
    )
    .unwrap();
    let options = RunOptions::new("tls-test-0");
    let exe = Path::new(env!("CARGO_BIN_EXE_glissade"));
    let e = Run::new(&glissade::load_scene(&path).unwrap(), &options)
        .processes(exe, &Network::default())
        .map(|o| o.result)
        .unwrap_err();
    let message = format!("{e:#}");
    assert!(
        message.contains("network.allow: the launcher's certificate")
            && message.contains("has common name `glissade-node`, which the list does not allow"),
        "{message}"
    );
    std::fs::write(&path, &text).unwrap();
    let sc = glissade::load_scene(&path).unwrap();
    assert_eq!(sc.network.tls.as_ref().unwrap().cert, dir.join("certs/node.pem"));
    // The run as `glissade run` does it (launcher, recorder and node processes over TLS), against
    // the same scene run in-process: the interface fields, written with round-trip precision,
    // are equal bit for bit. The launcher is a process of its own, like a user's.
    let out = |args: &[&str], scene: &Path| {
        let o = std::process::Command::new(exe)
            .arg("run")
            .args(args)
            .args(["--quiet", "--out"])
            .arg(&*dir)
            .arg(scene)
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(o.status.success(), "{text}");
        text
    };
    let plain = dir.join("three-layer-plain.toml");
    std::fs::write(&plain, &base).unwrap();
    out(&["--in-process", "--run-id", "local"], &plain);
    let text = out(&["--run-id", "tls-test-1"], &path);
    println!("{text}");
    let json = |run: &str, what: &str| -> serde_json::Value {
        let f = dir.join(format!("{}-{run}.{what}.json", sc.model.name));
        serde_json::from_str(&std::fs::read_to_string(&f).unwrap()).unwrap()
    };
    let nodes = json("tls-test-1", "summary")["nodes"].to_string();
    assert!(nodes.contains("router on tls/127.0.0.1:"), "the bus was TLS: {nodes}");
    assert_eq!(
        json("local", "summary")["iterations"],
        json("tls-test-1", "summary")["iterations"]
    );
    assert_eq!(
        json("local", "fields")["interfaces"],
        json("tls-test-1", "fields")["interfaces"]
    );
    // The recorder took part over TLS too: its file is complete.
    let rec = glissade_recorder::Recording::open(&dir.join(format!("{}-tls-test-1.mcap", sc.model.name))).unwrap();
    assert!(rec.is_finished());
}

/// A node process whose certificate another CA signed cannot join: `glissade node` fails within
/// its connection attempt, naming the endpoint it could not reach; so does a session that does
/// not trust the router's CA, and one without TLS.
#[test]
fn a_certificate_from_another_ca_cannot_join() {
    let _turn = one_at_a_time();
    let endpoint = tls_endpoint();
    let _router = router(&endpoint, None);
    // The right CA and certificate join (the router is up and the fixtures are valid).
    let ok = client(&endpoint, &tls("ca", Some("node"), false)).expect("the node certificate joins");
    drop(ok);
    let mut child = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args([
            "node",
            "subdomain",
            "--run",
            "tls-test-2",
            "--connect",
            &endpoint,
            "--tls-root-ca",
        ])
        .arg(fixture("ca.pem"))
        .arg("--tls-cert")
        .arg(fixture("stranger.pem"))
        .arg("--tls-key")
        .arg(fixture("stranger.key"))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Bounded wait: the node gives up after its single connection attempt (client sessions do
    // not retry); 60 s leaves room for a loaded machine.
    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the node with a foreign certificate did not fail within 60 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    assert!(!status.success());
    assert!(
        stderr.contains(&format!("cannot join the run's bus at {endpoint}")),
        "{stderr}"
    );
    for (what, t) in [
        ("a foreign certificate", tls("ca", Some("stranger"), false)),
        ("no certificate", tls("ca", None, false)),
        ("the other CA's trust", tls("other-ca", Some("stranger"), false)),
    ] {
        assert!(client(&endpoint, &t).is_err(), "{what} joined");
    }
    let plain = endpoint.replace("tls/", "tcp/");
    let no_tls = transport::open(transport::config("client", &[], &[plain], false).unwrap());
    assert!(no_tls.is_err(), "a session without TLS joined");
}

/// What a subscriber received within `window` after the last of `expected` allowed payloads (or
/// within `limit` if they never all arrive).
fn collect(rx: &mpsc::Receiver<String>, expected: usize, window: Duration, limit: Duration) -> Vec<String> {
    let mut got = Vec::new();
    let deadline = Instant::now() + limit;
    let mut quiet_until: Option<Instant> = None;
    loop {
        let now = Instant::now();
        let until = quiet_until.unwrap_or(deadline).min(deadline);
        if now >= until {
            return got;
        }
        if let Ok(m) = rx.recv_timeout(until - now) {
            got.push(m);
            if quiet_until.is_none() && got.iter().filter(|m| m.starts_with("allowed")).count() >= expected {
                quiet_until = Some(Instant::now() + window);
            }
        }
    }
}

fn subscribe(session: &zenoh::Session, key: &str) -> (zenoh::pubsub::Subscriber<()>, mpsc::Receiver<String>) {
    let (tx, rx) = mpsc::channel();
    let sub = session
        .declare_subscriber(key)
        .callback(move |s| {
            let _ = tx.send(String::from_utf8_lossy(&s.payload().to_bytes()).into_owned());
        })
        .wait()
        .unwrap();
    (sub, rx)
}

/// Access control: on a router that allows CN `glissade-node` on the run's key space, a session
/// whose certificate (same CA) says `intruder` connects but neither publishes into the run nor
/// receives from it, while allowed sessions exchange every message. (A session hears its own
/// puts locally, so the intruder publishes and listens on two sessions.)
#[test]
fn access_control_keeps_a_name_not_allowed_out_of_the_run() {
    let _turn = one_at_a_time();
    let endpoint = tls_endpoint();
    let run = "tls-test-3";
    let _router = router(&endpoint, Some((run, &["glissade-node".to_string()])));
    let allowed = client(&endpoint, &tls("ca", Some("node"), false)).unwrap();
    let listener = client(&endpoint, &tls("ca", Some("node"), false)).unwrap();
    let intruder = client(&endpoint, &tls("ca", Some("intruder"), false)).expect("same CA: the TLS link opens");
    let intruder_ear = client(&endpoint, &tls("ca", Some("intruder"), false)).unwrap();
    let key = glissade_messages::topic::within_run(run, "subdomain/0/boundary");
    let (_s1, heard) = subscribe(&listener, &key);
    let (_s2, intruder_heard) = subscribe(&intruder_ear, &key);
    // Let the subscriptions reach the router (pub/sub is not durable).
    std::thread::sleep(Duration::from_millis(500));
    let n = 10;
    for i in 0..n {
        intruder.put(&key, format!("intruder {i}")).wait().unwrap();
        allowed.put(&key, format!("allowed {i}")).wait().unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    // Everything the allowed publisher sent, and 1 s more for anything else to show up.
    let got = collect(&heard, n, Duration::from_secs(1), Duration::from_secs(20));
    let expected: Vec<String> = (0..n).map(|i| format!("allowed {i}")).collect();
    assert_eq!(got, expected, "the allowed subscriber hears the allowed puts only");
    let intruder_got: Vec<String> = intruder_heard.try_iter().collect();
    assert!(intruder_got.is_empty(), "the intruder heard {intruder_got:?}");
}
