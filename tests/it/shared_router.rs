//! A router shared by several runs: each run takes only its own messages from it, whatever
//! another client publishes on its keys.

use crate::common::{scene, scene_text};
use crate::distributed::assert_identical;
use glissade::distributed::Network;
use glissade::run::Run;
use glissade::runner::RunOptions;
use glissade_zenoh as transport;
use std::path::Path;
use std::time::Duration;
use zenoh::Wait;

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_glissade"))
}

/// Two runs of the same scene share one Zenoh router (a stand-in for `zenohd`, the launchers
/// connect to it as clients) while a third session publishes messages of another run on the
/// first run's own keys: a stop decision, boundary states, local directions, and a decision of
/// another scene. Each run ignores them and gives the in-process result bit for bit.
#[test]
fn messages_of_another_run_are_ignored() {
    use glissade_messages::{Decision, Envelope, Field, Message, NodeId, Payload, Role, Stage, Verdict};
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    let sc = scene(&scene_text("small-three-layer"));
    let local = Run::new(&sc, &RunOptions::new("local"))
        .in_process()
        .map(|o| o.result)
        .unwrap();
    let port = transport::free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let _router =
        transport::open(transport::config("router", std::slice::from_ref(&endpoint), &[], false).unwrap()).unwrap();
    let intruder =
        transport::open(transport::config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
    let net = Network {
        connect: vec![endpoint.clone()],
        ..Network::default()
    };
    // The victim's run is recorded: what its recorder keeps must be the run's own messages.
    let dir = crate::common::scratch("foreign-messages");
    let recording = dir.join("victim.mcap");
    let victim = "shared-bus-a";
    let stop = Arc::new(AtomicBool::new(false));
    let publisher = {
        let stop = stop.clone();
        let fingerprint = sc.fingerprint;
        std::thread::spawn(move || {
            let envelope = |run_id: &str, fingerprint: u64, role: Role, index: u32, stage: Stage| Envelope {
                schema_version: glissade_messages::SCHEMA_VERSION,
                run_id: run_id.into(),
                scene_fingerprint: fingerprint,
                iteration: 0,
                stage,
                sender: NodeId { role, index },
            };
            let decision = Payload::Decision(Decision {
                eta: 0.0,
                contact_indicator: 0.0,
                force_error: 0.0,
                jump_error: 0.0,
                counts: [0; 3],
                status_changes: 0,
                direction_updates: Vec::new(),
                force_step: 0.0,
                estimate: None,
                contraction: None,
                pointwise_step: 0.0,
                pointwise_estimate: None,
                verdict: Verdict::Converged,
            });
            let foreign = [
                (
                    envelope("intruder", fingerprint, Role::Interface, 0, Stage::Local),
                    decision.clone(),
                ),
                (
                    envelope("intruder", fingerprint, Role::Subdomain, 0, Stage::Linear),
                    Payload::BoundaryState {
                        subdomain: 0,
                        to: None,
                        interfaces: vec![0],
                        w: Field::zeros(4, 11),
                        f: Field::zeros(4, 11),
                    },
                ),
                (
                    envelope("intruder", fingerprint, Role::Interface, 0, Stage::Local),
                    Payload::LocalDirections {
                        subdomain: 1,
                        interfaces: vec![0],
                        q_hat: Field::zeros(4, 11),
                    },
                ),
                // The victim's run id but another scene.
                (
                    envelope(victim, fingerprint ^ 1, Role::Interface, 0, Stage::Local),
                    decision,
                ),
                // The victim's run and scene, but fields of the wrong shape: the nodes refuse them
                // and stay unchanged, the transport logs and skips them.
                (
                    envelope(victim, fingerprint, Role::Subdomain, 0, Stage::Linear),
                    Payload::BoundaryState {
                        subdomain: 0,
                        to: None,
                        interfaces: vec![0],
                        w: Field::zeros(4, 11),
                        f: Field::zeros(4, 11),
                    },
                ),
                (
                    envelope(victim, fingerprint, Role::Interface, 0, Stage::Local),
                    Payload::LocalDirections {
                        subdomain: 1,
                        interfaces: vec![0],
                        q_hat: Field::zeros(4, 11),
                    },
                ),
            ];
            let mut sent = 0u64;
            while !stop.load(Ordering::SeqCst) {
                for (envelope, payload) in &foreign {
                    let msg = Message {
                        envelope: envelope.clone(),
                        payload: payload.clone(),
                    };
                    // Published on the key the victim's nodes listen to.
                    let key = glissade_messages::topic(victim, envelope.sender, payload);
                    intruder.put(key, glissade_messages::encode(&msg)).wait().expect("put");
                    sent += 1;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            sent
        })
    };
    let (a, b) = std::thread::scope(|s| {
        let a = s.spawn(|| {
            Run::new(&sc, &RunOptions::new(victim))
                .recorded(Some(&recording))
                .processes(exe(), &net)
                .map(|o| (o.result, o.traffic.unwrap_or_default()))
        });
        let b = s.spawn(|| {
            Run::new(&sc, &RunOptions::new("shared-bus-b"))
                .processes(exe(), &net)
                .map(|o| (o.result, o.traffic.unwrap_or_default()))
        });
        (a.join().unwrap(), b.join().unwrap())
    });
    stop.store(true, Ordering::SeqCst);
    let sent = publisher.join().unwrap();
    let (a, traffic) = a.unwrap();
    let (b, _) = b.unwrap();
    // The other scene's decisions carry the victim's run id: the launcher counts them, so they
    // show that foreign messages did reach the victim's keys during its run.
    let decisions = traffic.by_kind["decision"].messages;
    println!(
        "{sent} foreign messages published, {decisions} decisions seen on the victim's keys; runs: {} and {} iterations, in-process {}",
        a.iterations.len(),
        b.iterations.len(),
        local.iterations.len()
    );
    assert!(
        decisions > a.iterations.len() as u64,
        "{decisions} decisions on the bus for {} iterations: the foreign ones did not arrive",
        a.iterations.len()
    );
    assert_identical(&local, &a);
    assert_identical(&local, &b);
    // The other scene's decisions reached the recorder too: it left them out, so that every
    // recorded message decodes as one of the run (as `glissade replay` decodes them).
    let r = glissade_recorder::Recording::open(&recording).unwrap();
    let recorded_decisions = r.messages().filter(|m| m.topic.ends_with("/decision")).count();
    assert_eq!(recorded_decisions, a.iterations.len(), "decisions recorded");
    for m in r.messages() {
        if let Err(e) = r.decode(&m) {
            panic!("a recorded message on {} does not decode: {e}", m.topic);
        }
    }
}
