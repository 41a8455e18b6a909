//! Who may speak on a run's bus (docs/architecture.md), at the transport: a router with the run's users
//! (user/password authentication) and access control by user lets in only the sessions that
//! present a member's password, and lets each member publish and declare tokens only on its own
//! keys, while every member hears the whole run.

use glissade_messages::{topic, NodeId, Role};
use glissade_zenoh as transport;
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::Wait;

fn id(role: Role, index: u32) -> NodeId {
    NodeId { role, index }
}

/// A router on a free loopback port for run `run` with `members`; returns it, its endpoint and
/// the members' credentials (the dictionary file is gone once the router is open).
fn router(run: &str, members: &[NodeId]) -> (zenoh::Session, String, Vec<transport::Credentials>) {
    let endpoint = format!("tcp/127.0.0.1:{}", transport::free_loopback_port().unwrap());
    let credentials: Vec<_> = members
        .iter()
        .map(|&m| transport::Credentials::random(&transport::user_of(m)).unwrap())
        .collect();
    let dictionary = transport::Dictionary::write(&std::env::temp_dir(), &credentials).unwrap();
    let auth = transport::Auth::Router {
        dictionary: dictionary.path().to_path_buf(),
    };
    let access = transport::Access {
        run_id: run.to_string(),
        common_names: None,
        members: Some(members.iter().map(|&m| transport::Member::node(run, m)).collect()),
    };
    let config = transport::secure_config(
        "router",
        std::slice::from_ref(&endpoint),
        &[],
        false,
        None,
        Some(&auth),
        Some(&access),
    )
    .unwrap();
    let session = transport::open(config).expect("the router opens");
    let file = dictionary.path().to_path_buf();
    drop(dictionary);
    assert!(!file.exists(), "the dictionary outlives the router's opening");
    (session, endpoint, credentials)
}

fn client(endpoint: &str, credentials: Option<&transport::Credentials>) -> Result<zenoh::Session, String> {
    let auth = credentials.cloned().map(transport::Auth::Client);
    let config = transport::secure_config("client", &[], &[endpoint.to_string()], false, None, auth.as_ref(), None)
        .map_err(|e| e.to_string())?;
    // Bounded: a client that cannot connect fails at once (Zenoh's client connect timeout is 0),
    // and a thread keeps a hung open from hanging the test.
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(transport::open(config).map_err(|e| e.to_string()));
    });
    rx.recv_timeout(Duration::from_secs(30))
        .map_err(|_| "open did not return within 30 s".to_string())?
}

/// Everything a subscriber on `key` receives until `window` passes without a message (or
/// `limit` in all).
fn heard(rx: &mpsc::Receiver<String>, window: Duration, limit: Duration) -> Vec<String> {
    let deadline = Instant::now() + limit;
    let mut got = Vec::new();
    while let Ok(m) = rx.recv_timeout(window.min(deadline.saturating_duration_since(Instant::now()))) {
        got.push(m);
    }
    got.sort();
    got
}

#[test]
fn only_members_join_and_each_speaks_on_its_own_keys_only() {
    let run = "auth-1";
    let (s0, i0) = (id(Role::Subdomain, 0), id(Role::Interface, 0));
    let (_router, endpoint, cr) = router(run, &[s0, i0]);

    // No password, a wrong one, a user the run does not have: refused at the link.
    assert!(client(&endpoint, None).is_err(), "a session without credentials joined");
    let wrong = transport::Credentials::parse(&format!("{}:{}", cr[0].user, "0".repeat(64))).unwrap();
    assert!(client(&endpoint, Some(&wrong)).is_err(), "a wrong password joined");
    let stranger = transport::Credentials::random("coarse-0").unwrap();
    assert!(
        client(&endpoint, Some(&stranger)).is_err(),
        "a user the run does not have joined"
    );

    let sub = client(&endpoint, Some(&cr[0])).expect("subdomain-0 joins");
    let itf = client(&endpoint, Some(&cr[1])).expect("interface-0 joins");
    // interface-0 listens to the whole run and to its liveliness tokens.
    let (tx, rx) = mpsc::channel();
    let _s = itf
        .declare_subscriber(topic::run_topics(run))
        .callback(move |s| {
            let _ = tx.send(format!(
                "{} {}",
                s.key_expr().as_str(),
                String::from_utf8_lossy(&s.payload().to_bytes())
            ));
        })
        .wait()
        .unwrap();
    let (ttx, trx) = mpsc::channel();
    let _t = itf
        .liveliness()
        .declare_subscriber(topic::alive_all(run))
        .callback(move |s| {
            let _ = ttx.send(format!("{:?} {}", s.kind(), s.key_expr().as_str()));
        })
        .wait()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));

    // subdomain-0 on its own keys (heard), on interface-0's and the launcher's (not), and in
    // another run (not).
    let own = topic::within_run(run, "subdomain/0/boundary_state");
    let others = [
        topic::within_run(run, "interface/0/local_directions/0"),
        topic::within_run(run, "coarse/0/macro_displacements"),
        topic::stop(run),
        topic::within_run("auth-2", "subdomain/0/boundary_state"),
    ];
    for k in 0..3 {
        sub.put(&own, format!("genuine {k}")).wait().unwrap();
        for key in &others {
            sub.put(key, format!("forged {k}")).wait().unwrap();
        }
    }
    let _own_token = sub
        .liveliness()
        .declare_token(topic::alive(run, "subdomain", 0))
        .wait()
        .unwrap();
    let forged_token = sub
        .liveliness()
        .declare_token(topic::alive(run, "subdomain", 99))
        .wait()
        .unwrap();
    let _launcher_token = sub
        .liveliness()
        .declare_token(topic::alive(run, "launcher", 0))
        .wait()
        .unwrap();
    forged_token.undeclare().wait().unwrap();

    let expected: Vec<String> = (0..3).map(|k| format!("{own} genuine {k}")).collect();
    assert_eq!(
        heard(&rx, Duration::from_secs(1), Duration::from_secs(20)),
        expected,
        "interface-0 hears subdomain-0's own keys and nothing it forged"
    );
    assert_eq!(
        heard(&trx, Duration::from_secs(1), Duration::from_secs(20)),
        vec![format!("Put {}", topic::alive(run, "subdomain", 0))],
        "the only token declared is subdomain-0's own"
    );
}

/// Credentials: their text round-trips, a password never shows in a debug print, malformed
/// lines are refused, and two random passwords differ.
#[test]
fn credentials_parse_and_hide_the_password() {
    let c = transport::Credentials::random("subdomain-3").unwrap();
    assert_eq!(transport::Credentials::parse(&c.line()).unwrap(), c);
    let line = c.line();
    let password = line.trim_end().split_once(':').unwrap().1;
    assert_eq!(password.len(), 64, "256 bits as hex");
    assert!(!format!("{c:?}").contains(password));
    assert_ne!(transport::Credentials::random("subdomain-3").unwrap(), c);
    for bad in ["", "user", ":pw", "user:", "user:pw\nmore", "us er:pw", "user:p:w"] {
        assert!(transport::Credentials::parse(bad).is_err(), "{bad:?} accepted");
    }
    assert_eq!(transport::user_of(id(Role::Recorder, 0)), "recorder-0");
}

/// A whole run as processes whose subdomain node 1 is started by hand, with a second session
/// holding that node's credentials (a member of the run gone rogue, the worst a foreign process
/// can be once the bus is authenticated) that copies every message it hears on the other nodes'
/// keys (the interface and coarse nodes', the launcher's, subdomain 0's) with the iteration
/// raised by one (the forgery that used to be taken), puts a stop,
/// declares and drops a token of a node that does not exist, and sends on its own keys a kind a
/// subdomain node never sends. Also: sessions without the credentials cannot join. The run ends
/// as an undisturbed in-process run does, bit for bit; its recording holds no forgery and every
/// node re-executes from it bit-identically; the credentials file is gone at the end.
#[test]
fn a_rogue_member_changes_nothing_and_strangers_cannot_join() {
    use crate::common::{glissade_ok, scratch};
    use crate::node_failures::{start_hand_node, Launcher};
    use glissade_messages::{decode, encode, peek_envelope, Expected, Message};
    use std::os::unix::fs::PermissionsExt;
    use std::process::Command;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    let exe = env!("CARGO_BIN_EXE_glissade");
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    let dir = scratch("bus-auth-run");
    let run_id = format!("rogue-{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", transport::free_loopback_port().unwrap());
    let mut launcher = Launcher::spawn(
        Command::new(exe)
            .arg("run")
            .arg(&scene)
            .args([
                "--quiet",
                "--interior",
                "--run-id",
                &run_id,
                "--listen",
                &endpoint,
                "--remote",
                "subdomain:1",
            ])
            .arg("--out")
            .arg(&*dir),
    );
    launcher.wait_for_line("on the other machine", Duration::from_secs(120));
    let file = dir.join(format!("{run_id}-subdomain-1.credentials"));
    let mode = std::fs::metadata(&file).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600, "the credentials file is readable by its owner only");
    let credentials = transport::Credentials::parse(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(credentials.user, "subdomain-1");

    // Strangers: no credentials, or another node's name with this password.
    assert!(
        client(&endpoint, None).is_err(),
        "a session without credentials joined the run"
    );
    let other = transport::Credentials::parse(&credentials.line().replacen("subdomain-1", "interface-0", 1)).unwrap();
    assert!(
        client(&endpoint, Some(&other)).is_err(),
        "another user with this password joined"
    );

    let rogue = client(&endpoint, Some(&credentials)).expect("the member's credentials join");
    let node = start_hand_node(Command::new(exe), &run_id, &endpoint, &dir, &["--interior"]);
    // The rogue copies what it hears on the others' keys, iteration + 1; on its own keys it sends
    // the coarse node's macro displacements as its own.
    let (tx, rx) = mpsc::channel::<(String, Vec<u8>)>();
    let _ear = rogue
        .declare_subscriber(topic::run_topics(&run_id))
        .callback(move |s| {
            let _ = tx.send((s.key_expr().as_str().to_string(), s.payload().to_bytes().into_owned()));
        })
        .wait()
        .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let forger = {
        let (stop, run_id) = (stop.clone(), run_id.clone());
        std::thread::spawn(move || {
            // What the member may say itself: the subdomains its process hosts (those of the
            // deployment's group 1, not subdomain 0's, which is group 0's).
            let subdomains = topic::within_run(&run_id, "subdomain/**");
            let subdomain_0 = topic::sent_by(&run_id, id(Role::Subdomain, 0));
            let (mut forged, mut disguised) = (0u64, 0u64);
            let mut fingerprint = None;
            while !stop.load(Ordering::SeqCst) {
                let Ok((key, bytes)) = rx.recv_timeout(Duration::from_millis(50)) else {
                    continue;
                };
                let Ok(envelope) = peek_envelope(&bytes, &run_id) else {
                    continue;
                };
                let fp = *fingerprint.get_or_insert(envelope.scene_fingerprint);
                let expected = Expected {
                    run_id: run_id.clone(),
                    scene_fingerprint: fp,
                };
                let Ok(mut m) = decode(&bytes, &expected) else {
                    continue;
                };
                if topic::key_matches(&subdomains, &key) && !topic::key_matches(&subdomain_0, &key) {
                    continue;
                }
                let genuine = m.clone();
                m.envelope.iteration += 1;
                let _ = rogue.put(&key, encode(&m)).wait();
                forged += 1;
                use glissade_messages::Payload as P;
                if matches!(
                    genuine.payload,
                    P::MacroDisplacements { .. } | P::Decision(_) | P::InterfaceSolution(_) | P::Displacement { .. }
                ) {
                    // On the rogue's own keys (subdomain 5 of 6 is hosted by process 1 of 2: the
                    // deployment's groups are consecutive), so the router lets these through:
                    // the genuine bytes (their envelope names another sender), and a copy "sent"
                    // by subdomain 5 (a kind a subdomain does not send, or another subdomain's
                    // displacement). The launcher, the nodes and the recorder must take neither.
                    let field = genuine.payload.field_key();
                    let _ = rogue
                        .put(
                            topic::within_run(&run_id, format_args!("subdomain/5/{field}")),
                            encode(&m),
                        )
                        .wait();
                    let mut mine: Message = genuine;
                    mine.envelope.sender = id(Role::Subdomain, 5);
                    let _ = rogue.put(mine.topic(), encode(&mine)).wait();
                    disguised += 1;
                }
                if forged % 50 == 1 {
                    let _ = rogue.put(topic::stop(&run_id), "forged stop").wait();
                    if let Ok(t) = rogue
                        .liveliness()
                        .declare_token(topic::alive(&run_id, "subdomain", 99))
                        .wait()
                    {
                        let _ = t.undeclare().wait();
                    }
                }
            }
            (forged, disguised)
        })
    };
    let mut node = node;
    let status = launcher.wait_exit(Duration::from_secs(600));
    let node_status = node.wait_exit(Duration::from_secs(60));
    stop.store(true, Ordering::SeqCst);
    let (forged, disguised) = forger.join().unwrap();
    println!("the rogue forged {forged} messages on other keys and {disguised} on its own");
    assert!(status.success(), "launcher: {status}\n{}", launcher.output());
    assert!(node_status.success(), "node: {node_status}\n{}", node.output());
    assert!(
        forged > 100 && disguised > 3,
        "{forged} forged, {disguised} disguised: the rogue heard too little"
    );
    assert!(!file.exists(), "the credentials outlive the run");

    // Bit for bit the undisturbed result.
    let local = dir.join("local");
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--quiet",
        &"--interior",
        &"--no-record",
        &"--run-id",
        &run_id,
        &"--out",
        &local,
    ]);
    let read_file = |d: &std::path::Path, what: &str| -> serde_json::Value {
        let p = d.join(format!("small-three-layer-{run_id}.{what}.json"));
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
    };
    let read = |d: &std::path::Path| read_file(d, "fields");
    assert_eq!(
        read_file(&dir, "displacement"),
        read_file(&local, "displacement"),
        "displacements of the attacked run and of an undisturbed one"
    );
    let (attacked, undisturbed) = (read_file(&dir, "summary"), read_file(&local, "summary"));
    for key in ["iterations", "eta"] {
        assert_eq!(attacked[key], undisturbed[key], "{key}: forged decisions were taken");
    }
    assert_eq!(
        read(&dir),
        read(&local),
        "fields of the attacked run and of an undisturbed one"
    );

    // The recording holds the run's messages only, and every node re-executes from it.
    let recording = dir.join(format!("small-three-layer-{run_id}.mcap"));
    let r = glissade_recorder::Recording::open(&recording).unwrap();
    let macro_on_subdomain_keys = r
        .messages()
        .filter(|m| {
            m.topic.starts_with(&topic::within_run(&run_id, "subdomain/")) && m.topic.ends_with("/macro_displacements")
        })
        .count();
    assert_eq!(macro_on_subdomain_keys, 0, "a disguised message was recorded");
    let out = launcher.output();
    assert!(
        out.lines().any(|l| l.starts_with("[recorder:0] warning: ")
            && l.contains("were not the run's and were not recorded")
            && (l.contains("does not send") || l.contains("belong on"))),
        "the recorder says what it left out and why:\n{out}"
    );
    let replayed = glissade_ok(&[&"replay", &"--node", &"all", &recording]);
    let nodes = replayed.matches("bit-identical").count();
    assert!(nodes >= 4, "{replayed}");
    assert!(!replayed.contains("differ"), "{replayed}");
}

/// `glissade node --credentials` refuses, before joining anything, a file others can read, a file
/// of another node, and a malformed one, naming the file and the problem (exit 2).
#[test]
fn node_credentials_are_checked_before_joining() {
    use std::os::unix::fs::PermissionsExt;
    let dir = crate::common::scratch("bus-auth-credentials");
    let write = |name: &str, text: &str, mode: u32| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(mode)).unwrap();
        p
    };
    let line = transport::Credentials::random("subdomain-1").unwrap().line();
    let cases = [
        (write("open.credentials", &line, 0o644), "readable by others (mode 644)"),
        (
            write("other.credentials", &line, 0o600),
            "they are subdomain-1's, not this node's (subdomain-2)",
        ),
        (
            write("bad.credentials", "subdomain-2\n", 0o600),
            "expected one line `user:password`",
        ),
    ];
    // Nothing listens on this port: a check that let the file through would fail on joining.
    let endpoint = format!("tcp/127.0.0.1:{}", transport::free_loopback_port().unwrap());
    for (file, expected) in cases {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args([
                "node",
                "subdomain",
                "--run",
                "x",
                "--index",
                "2",
                "--connect",
                &endpoint,
            ])
            .arg("--credentials")
            .arg(&file)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains(expected) && stderr.contains(&*file.to_string_lossy()),
            "{}: {stderr}",
            file.display()
        );
    }
}

/// A recording that holds messages which are not the run's (as a recorder kept them before the
/// bus was authenticated: bytes that do not decode, a node's message re-sent by a role that never
/// sends it, a message on another node's key) still replays and re-executes: those messages are
/// skipped and reported, every node is bit-identical.
#[test]
fn replay_skips_and_reports_what_is_not_the_runs() {
    use crate::common::{glissade_ok, scratch};
    use glissade_messages::{encode, Payload};
    let dir = scratch("bus-auth-forged-recording");
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--quiet",
        &"--run-id",
        &"fr",
        &"--out",
        &dir.to_path_buf(),
    ]);
    let original = glissade_recorder::Recording::open(&dir.join("small-three-layer-fr.mcap")).unwrap();
    let loaded = glissade_scene::load_with(
        original.scene_text().unwrap(),
        "scene.toml",
        original.scene_overrides().unwrap(),
    )
    .unwrap();
    let forged_path = dir.join("forged.mcap");
    let (info, options) = glissade::recording::recorder_settings(&loaded, "fr");
    let mut out = glissade_recorder::Recorder::create(&forged_path, &info, &options).unwrap();
    let mut forged = 0;
    for (i, m) in original.messages().enumerate() {
        out.record(m.topic, m.log_time, &m.data).unwrap();
        if forged > 0 || !m.topic.ends_with("/boundary_state") {
            continue;
        }
        let at = i + 1;
        let msg = original.decode(&m).unwrap();
        // Bytes that do not decode, on a node's key.
        out.record(m.topic, m.log_time, &m.data[..m.data.len() / 2]).unwrap();
        // The same message re-sent by the coarse node, which never sends this kind.
        let mut by_coarse = msg.clone();
        by_coarse.envelope.sender = id(Role::Coarse, 0);
        assert!(
            !by_coarse.payload.senders().contains(&Role::Coarse),
            "{}",
            msg.payload.field_key()
        );
        out.record(&by_coarse.topic(), m.log_time, &encode(&by_coarse)).unwrap();
        // The same message on another node's key.
        let elsewhere = topic::within_run("fr", "interface/0/decision");
        assert!(!matches!(msg.payload, Payload::Decision(_)));
        out.record(&elsewhere, m.log_time, &m.data).unwrap();
        forged = at;
    }
    out.finish().unwrap();
    assert!(forged > 0, "the recording has no boundary state");
    let expected = format!("3 recorded message(s) are not the run's and were skipped (the first, message #{forged} on");

    let o = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["replay", "--node", "all"])
        .arg(&forged_path)
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains(&expected), "{stderr}");
    let nodes = stdout.matches("bit-identical").count();
    assert_eq!(nodes, stdout.lines().count(), "{stdout}");
    assert!(nodes >= 4, "{stdout}");

    let o = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
        .arg("replay")
        .arg("--save")
        .arg(dir.join("forged.rrd"))
        .arg(&forged_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains(&expected), "{stderr}");
}
