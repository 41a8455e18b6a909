//! Nodes as separate processes over Zenoh (loopback, launcher-hosted router, multicast scouting
//! off): the same scene run in-process and as processes gives bit-identical results.

use crate::common::{scene, scene_text};
use glissade::distributed::Network;
use glissade::run::Run;
use glissade::runner::{RunOptions, RunResult};
use glissade_zenoh as transport;
use std::path::Path;
use std::time::Duration;

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_glissade"))
}

/// Same iterations, same decisions, and the same bits in every interface field.
pub(crate) fn assert_identical(a: &RunResult, b: &RunResult) {
    assert_eq!(a.iterations.len(), b.iterations.len(), "iteration counts");
    for (x, y) in a.iterations.iter().zip(&b.iterations) {
        assert_eq!(x.decision, y.decision, "decision of iteration {}", x.iteration);
    }
    assert_eq!(a.interfaces.len(), b.interfaces.len());
    for (x, y) in a.interfaces.iter().zip(&b.interfaces) {
        assert_eq!(x.interface, y.interface);
        for (f, g) in [
            (&x.w_a, &y.w_a),
            (&x.w_b, &y.w_b),
            (&x.f_a, &y.f_a),
            (&x.f_b, &y.f_b),
            (&x.w_a_hat, &y.w_a_hat),
            (&x.w_b_hat, &y.w_b_hat),
            (&x.f_a_hat, &y.f_a_hat),
            (&x.f_b_hat, &y.f_b_hat),
        ] {
            let same = f.data.iter().zip(&g.data).all(|(p, q)| p.to_bits() == q.to_bits());
            assert!(
                same && f.data.len() == g.data.len(),
                "interface {} differs",
                x.interface
            );
        }
        assert_eq!(x.status, y.status);
    }
}

/// Runs `sc` in-process and as processes (run id `run_id`), asserts that both give the same bits,
/// and returns the in-process result.
pub(crate) fn in_process_equals_processes(sc: &glissade_scene::LoadedScene, run_id: &str) -> RunResult {
    let opts = |id: &str| RunOptions::new(id);
    let local = Run::new(sc, &opts("local")).in_process().map(|o| o.result).unwrap();
    let remote = Run::new(sc, &opts(run_id))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    assert_identical(&local, &remote);
    local
}

/// Command-line overrides reach the node processes: the launcher serves the scene text as
/// written with the overrides beside it, and every node process rebuilds the overridden model
/// from the two. With `--max-iterations` below the scene's own convergence the processes stop at
/// the cap, and with a looser `--accuracy` they stop earlier, bit for bit as the overridden model
/// runs in-process (a node process with the file's settings would stop elsewhere, and would
/// refuse the scene's fingerprint).
#[test]
fn command_line_overrides_reach_the_node_processes() {
    use glissade_messages::{Overrides, Verdict};
    let written = scene(&scene_text("small-three-layer"));
    let plain = crate::common::run(&written);
    let n = plain.iterations.len();
    assert!(
        n > 5 && plain.verdict == Verdict::Converged,
        "{n} iterations, {:?}",
        plain.verdict
    );
    let cap = n - 2;
    let capped = written
        .with_overrides(
            "test.toml",
            &Overrides {
                max_iterations: Some(cap),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(capped.text, written.text, "the text travels as written");
    let r = in_process_equals_processes(&capped, "overrides-cap");
    assert_eq!((r.iterations.len(), &r.verdict), (cap, &Verdict::MaxIterations));
    let loose = written
        .with_overrides(
            "test.toml",
            &Overrides {
                accuracy: Some(5e-2),
                max_iterations: Some(n + 10),
                ..Default::default()
            },
        )
        .unwrap();
    let r = in_process_equals_processes(&loose, "overrides-accuracy");
    assert!(
        r.iterations.len() < n && r.verdict == Verdict::Converged,
        "accuracy 5e-2: {} iterations ({n} at the scene's 1e-3), {:?}",
        r.iterations.len(),
        r.verdict
    );
}

/// `text` with `lines` added at the top of its `[deployment]` section.
fn with_deployment(text: &str, lines: &str) -> String {
    assert!(text.contains("\n[deployment]\n"), "the scene has a deployment section");
    text.replacen("\n[deployment]\n", &format!("\n[deployment]\n{lines}\n"), 1)
}

/// An in-process run of `sc` and how many `indicator_partials` messages crossed its bus.
fn in_process_with_partials(sc: &glissade_scene::LoadedScene) -> (RunResult, usize) {
    let mut partials = 0;
    let result = Run::new(sc, &RunOptions::new("local"))
        .observe(|m| {
            if matches!(m.payload, glissade_messages::Payload::IndicatorPartials { .. }) {
                partials += 1;
            }
            Duration::ZERO
        })
        .in_process()
        .map(|o| o.result)
        .unwrap();
    (result, partials)
}

/// Several interface nodes, each running the local stage of the interfaces it owns and sending
/// its per-interface indicator sums to node 0, give the one-node run bit for bit: node 0 adds
/// the sums in interface order, the additions one node makes, and the subdomains take each
/// interface's q̂ rows from its owner. In-process, with the automatic split and with an explicit
/// assignment that interleaves the contact interfaces, with plain relaxation and with Anderson
/// acceleration plus search-direction updates (node 0's Anderson step, the updates in the
/// decision); then as processes.
#[test]
fn several_interface_nodes_match_one_bit_for_bit() {
    let base = scene_text("small-three-layer");
    let anderson = base.replace(
        "[solver]\n",
        "[solver]\nacceleration = \"anderson\"\nsearch_direction_update = true\n",
    );
    assert_ne!(anderson, base);
    let split =
        "interface_groups = [[\"bottom|core\", \"top|top\"], [\"core|top\", \"bottom|bottom\"], [\"core|core\"]]";
    for (what, text) in [("relaxation", &base), ("Anderson + direction updates", &anderson)] {
        let (one, none) = in_process_with_partials(&scene(text));
        assert_eq!(none, 0, "one interface node sends no partials");
        assert!(one.iterations.len() > 2 && one.verdict.is_stop());
        for deployment in ["interface_nodes = 3", split] {
            let sc = scene(&with_deployment(text, deployment));
            assert_eq!(sc.deployment.interface_nodes, 3);
            let (several, partials) = in_process_with_partials(&sc);
            println!(
                "{what}, {deployment}: {} iterations, {partials} partials; nodes {:?}",
                several.iterations.len(),
                several.nodes
            );
            assert!(
                several.nodes.contains(&"interface × 3".to_string()),
                "{:?}",
                several.nodes
            );
            // Nodes 1 and 2 report every iteration.
            assert_eq!(partials, 2 * several.iterations.len(), "{what}, {deployment}");
            assert_identical(&one, &several);
            if what != "relaxation" {
                assert!(
                    several
                        .iterations
                        .iter()
                        .any(|r| !r.decision.direction_updates.is_empty()),
                    "the search directions were updated"
                );
            }
        }
    }
    let sc = scene(&with_deployment(&base, "interface_nodes = 3"));
    let one = crate::common::run(&scene(&base));
    let remote = Run::new(&sc, &RunOptions::new("distributed-test-3"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    println!(
        "processes: {} iterations; nodes {:?}",
        remote.iterations.len(),
        remote.nodes
    );
    assert!(
        remote.nodes.iter().any(|n| n.starts_with("processes: 3 ")),
        "2 subdomain + 1 coarse processes: {:?}",
        remote.nodes
    );
    assert!(
        remote
            .nodes
            .contains(&"in the launcher's process: interface:0, interface:1, interface:2".to_string()),
        "the interface nodes run beside the router: {:?}",
        remote.nodes
    );
    assert_identical(&one, &remote);
    // The same with the interface nodes in processes of their own.
    let sc = scene(&with_deployment(
        &base,
        "interface_nodes = 3\ninterfaces_in_launcher = false",
    ));
    let remote = Run::new(&sc, &RunOptions::new("distributed-test-3b"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    assert!(
        remote.nodes.iter().any(|n| n.starts_with("processes: 6 ")),
        "2 subdomain + 3 interface + 1 coarse processes: {:?}",
        remote.nodes
    );
    assert_identical(&one, &remote);
}

/// `interfaces_with_subdomains` (the stratified scene's deployment, one process per column of
/// 60 mm through the three layers): interface node 0 owns the 6 perfect interfaces between
/// columns and runs beside the router, nodes 1 to 3 the 4 contact and 3 perfect interfaces
/// inside each column, in that column's process. Each subdomain sends each node owning one of
/// its interfaces the rows of those, each on a key of its own, so that the fields of the
/// interfaces inside a column never leave their process. The run is the one-interface-node run
/// bit for bit, in-process and as processes.
#[test]
fn interfaces_with_their_subdomains_match_one_node_bit_for_bit() {
    use glissade_messages::{Field, Payload};
    use std::collections::BTreeMap;
    let text = scene_text("stratified").replace("N = 1000", "N = 10");
    let sc = scene(&text);
    assert!(sc.deployment.interfaces_with_subdomains);
    let one_node = scene(&text.replace("interfaces_with_subdomains = true\n", ""));
    // Per (subdomain, recipient): the interfaces of its rows and their count; the keys; and every
    // (iteration, subdomain)'s whole state as the replay puts it back together.
    type States = BTreeMap<(u32, u32), (Field, Field)>;
    type Parts = BTreeMap<(u32, Option<u32>), (Vec<u32>, usize)>;
    type Bits = Vec<((u32, u32), Vec<u64>, Vec<u64>)>;
    let run_observed = |sc: &glissade_scene::LoadedScene,
                        parts: &mut Parts,
                        keys: &mut std::collections::BTreeSet<String>|
     -> (RunResult, States) {
        let mut states = glissade_replay::BoundaryStates::new(&sc.model);
        let mut whole = States::new();
        let result = Run::new(sc, &RunOptions::new("local"))
            .observe(|m| {
                if let Payload::BoundaryState {
                    subdomain,
                    to,
                    interfaces,
                    w,
                    ..
                } = &m.payload
                {
                    parts.insert((*subdomain, *to), (interfaces.clone(), w.rows()));
                    keys.insert(m.topic());
                }
                if let Some(state) = states.fields(m) {
                    let (s, w, f) = state.expect("a state that fits");
                    whole.insert((m.envelope.iteration, s), (w.into_owned(), f.into_owned()));
                }
                Duration::ZERO
            })
            .in_process()
            .map(|o| o.result)
            .unwrap();
        (result, whole)
    };
    let (mut parts, mut keys) = (BTreeMap::new(), std::collections::BTreeSet::new());
    let (one, one_states) = run_observed(&one_node, &mut parts, &mut keys);
    assert!(
        parts.keys().all(|(_, to)| to.is_none()),
        "one interface node: whole states"
    );
    let (mut parts, mut keys) = (BTreeMap::new(), std::collections::BTreeSet::new());
    let (local, local_states) = run_observed(&sc, &mut parts, &mut keys);
    assert!(local.nodes.contains(&"interface × 4".to_string()), "{:?}", local.nodes);
    assert_identical(&one, &local);
    // The parts put back together are the whole states, bit for bit, every iteration.
    assert_eq!(local_states.len(), 18 * one.iterations.len());
    let bits = |states: &States| -> Bits {
        let b = |f: &Field| f.data.iter().map(|x| x.to_bits()).collect();
        states.iter().map(|(k, (w, f))| (*k, b(w), b(f))).collect()
    };
    assert!(
        bits(&local_states) == bits(&one_states),
        "the states put together differ from the whole ones"
    );
    // Each subdomain sends a part to each node owning one of its interfaces (node 0: the
    // perfect interfaces between columns; node 1 + column: those inside its column), the rows
    // of exactly those interfaces; the outer columns' subdomains touch no interface between
    // columns: 6 subdomains with one part, 12 with two, never a whole state.
    let plan = glissade_deploy::Plan::new(&sc.model).with_scene(&sc);
    assert!(plan.interface_groups[0]
        .iter()
        .all(|&i| !sc.model.interfaces[i].is_contact()));
    assert_eq!(plan.interface_groups[0].len(), 6);
    assert_eq!(parts.len(), 6 + 2 * 12, "{parts:?}");
    let n_pairs = |i: u32| sc.model.interfaces[i as usize].n_pairs();
    for s in 0..18u32 {
        let column = (s % 6) / 2;
        let mut expected = 0;
        for (k, owned) in plan.interface_groups.iter().enumerate() {
            let mine: Vec<u32> = owned
                .iter()
                .filter(|&&i| [sc.model.interfaces[i].a, sc.model.interfaces[i].b].contains(&(s as usize)))
                .map(|&i| i as u32)
                .collect();
            if mine.is_empty() {
                continue;
            }
            expected += 1;
            assert!(k == 0 || k == 1 + column as usize, "subdomain {s}, node {k}");
            let (interfaces, rows) = &parts[&(s, Some(k as u32))];
            let mut sorted = interfaces.clone();
            sorted.sort_unstable();
            assert_eq!(sorted, mine, "subdomain {s}, node {k}");
            assert_eq!(*rows, mine.iter().map(|&i| 2 * n_pairs(i)).sum::<usize>());
        }
        assert_eq!(parts.keys().filter(|(t, _)| *t == s).count(), expected, "subdomain {s}");
    }
    assert!(keys.contains("glissade/local/subdomain/7/boundary_state/1"), "{keys:?}");
    let remote = Run::new(&sc, &RunOptions::new("distributed-test-owner"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    println!(
        "stratified N = 10, interfaces with their subdomains: nodes {:?}",
        remote.nodes
    );
    assert!(
        remote.nodes.iter().any(|n| n.starts_with("processes: 4 ")),
        "3 subdomain processes (with interface nodes 1 to 3) + 1 coarse: {:?}",
        remote.nodes
    );
    assert!(
        remote
            .nodes
            .contains(&"in the launcher's process: interface:0".to_string()),
        "{:?}",
        remote.nodes
    );
    assert_identical(&one, &remote);
}

/// The stratified scene (N = 10) over 3 subdomain processes and 3 interface-node processes gives
/// the in-process one-interface-node run bit for bit.
#[test]
fn stratified_over_three_interface_processes() {
    let text = scene_text("stratified")
        .replace("N = 1000", "N = 10")
        .replace("interfaces_with_subdomains = true\n", "");
    let one = crate::common::run(&scene(&text));
    let sc = scene(&with_deployment(&text, "interface_nodes = 3"));
    let groups = sc.deployment.interface_groups(&sc.model);
    println!(
        "interfaces per node: {:?}",
        groups.iter().map(Vec::len).collect::<Vec<_>>()
    );
    let remote = Run::new(&sc, &RunOptions::new("distributed-test-4"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    println!(
        "stratified N = 10, 3 interface nodes: {} iterations; nodes {:?}",
        remote.iterations.len(),
        remote.nodes
    );
    assert!(remote.nodes.iter().any(|n| n == "interface × 3"), "{:?}", remote.nodes);
    assert_identical(&one, &remote);
}

/// With plain relaxation: the default Anderson path is covered by the stratified tests here and
/// by `acceleration::processes_match_in_process_bit_for_bit_with_anderson`.
#[test]
fn processes_match_in_process_bit_for_bit() {
    let text = scene_text("small-three-layer").replace("[solver]\n", "[solver]\nacceleration = \"none\"\n");
    let sc = scene(&text);
    assert_eq!(
        sc.model.solver.acceleration,
        glissade_mechanics::model::Acceleration::None
    );
    assert!(
        sc.deployment.subdomain_nodes >= 2,
        "the scene spreads its subdomains over processes"
    );
    let local = Run::new(&sc, &RunOptions::new("local"))
        .in_process()
        .map(|o| o.result)
        .unwrap();
    let remote = Run::new(&sc, &RunOptions::new("distributed-test-1"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    println!(
        "in-process {} iterations, processes {} iterations; nodes {:?}",
        local.iterations.len(),
        remote.iterations.len(),
        remote.nodes
    );
    assert_identical(&local, &remote);
}

/// PGD subdomains send their state in mode form over Zenoh too (new modes, and after each SVD
/// compression the rotated free modes, then time functions), with Anderson mixing their time
/// functions: the run as processes equals the in-process run bit for bit. The compression is
/// checked to have rotated modes on the wire (a message restarting below the modes held).
#[test]
fn pgd_mode_form_processes_match_in_process_bit_for_bit() {
    use glissade_messages::Payload;
    use std::collections::BTreeMap;
    let text = scene_text("small-three-layer")
        .replace("[solver]\n", "[solver]\nlinear_stage = \"pgd\"\n")
        .replace(
            "[deployment]\n",
            "[solver.pgd]\ncriterion = \"increment-svd\"\nmax_new_modes = 2\n\n[deployment]\n",
        );
    let sc = scene(&text);
    assert_eq!(sc.linear_stage, glissade_mechanics::linear::LinearStage::Pgd);
    let (mut held, mut rotations) = (BTreeMap::new(), 0);
    let local = Run::new(&sc, &RunOptions::new("local-pgd"))
        .observe(|m| {
            if let Payload::BoundaryModes {
                subdomain,
                first_mode,
                lambda,
                ..
            } = &m.payload
            {
                let before: usize = held.get(subdomain).copied().unwrap_or(0);
                if (*first_mode as usize) < before {
                    rotations += 1;
                }
                held.insert(*subdomain, lambda.rows());
            }
            Duration::ZERO
        })
        .in_process()
        .map(|o| o.result)
        .unwrap();
    assert!(rotations > 0, "the compression rotated modes on the wire");
    let remote = Run::new(&sc, &RunOptions::new("distributed-pgd"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    println!(
        "PGD in mode form: {} iterations in-process and as processes, {rotations} messages with rotated modes",
        local.iterations.len()
    );
    assert_identical(&local, &remote);
}

/// The stratified scene (18 subdomains) over 3 subdomain processes, one interface node and one
/// coarse node (N = 10 to keep the debug-profile test short).
#[test]
fn stratified_over_three_subdomain_processes() {
    let text = scene_text("stratified").replace("N = 1000", "N = 10");
    let sc = scene(&text);
    assert_eq!(sc.deployment.subdomain_nodes, 3);
    let local = Run::new(&sc, &RunOptions::new("local"))
        .in_process()
        .map(|o| o.result)
        .unwrap();
    let remote = Run::new(&sc, &RunOptions::new("distributed-test-2"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    println!(
        "stratified N = 10: {} iterations; nodes {:?}",
        remote.iterations.len(),
        remote.nodes
    );
    assert!(
        remote.nodes.iter().any(|n| n.contains("in 3 process")),
        "{:?}",
        remote.nodes
    );
    assert_identical(&local, &remote);
}

/// `network.shared_memory = true`: the processes pass their fields (a subdomain's boundary-state
/// rows for one interface node, 20–40 kB at N = 30, every one above Zenoh's 3 KiB threshold) through shared memory, and the run,
/// with the displacement fields sent at the end (`interior`: the launcher's `done` then also
/// waits for them), is bit-identical to the in-process run.
#[test]
fn shared_memory_processes_match_in_process_bit_for_bit() {
    let text = scene_text("stratified").replace("N = 1000", "N = 30") + "\n[network]\nshared_memory = true\n";
    let sc = scene(&text);
    assert_eq!(sc.network.shared_memory, Some(true));
    let opts = |run_id: &str| RunOptions {
        run_id: run_id.into(),
        interior: true,
        keep_state: false,
    };
    let local = Run::new(&sc, &opts("local")).in_process().map(|o| o.result).unwrap();
    let remote = Run::new(&sc, &opts("distributed-shm"))
        .processes(exe(), &Network::default())
        .map(|o| o.result)
        .unwrap();
    assert!(!local.displacements.is_empty());
    assert_eq!(remote.displacements.len(), local.displacements.len());
    assert_identical(&local, &remote);
    assert_eq!(local.displacements, remote.displacements);
}

/// A scene that leaves `network.shared_memory` unset passes its fields through shared memory
/// exactly when node restarts are off for the run anyway, every node is local, the bus is not
/// encrypted, processes may lock shared memory and `/dev/shm` has room.
#[test]
fn shared_memory_is_chosen_when_restarts_are_off_anyway() {
    use glissade::bus::{auto_shared_memory, Host, SHARED_MEMORY_ROOM};
    let host = |recorded: bool| Host {
        recorded,
        remote_nodes: false,
        room: Some(SHARED_MEMORY_ROOM),
        lockable: Ok(()),
    };
    // Full recording, restarts on by default: not chosen, unless the run is not recorded.
    let full = scene(&scene_text("small-three-layer"));
    assert_eq!(full.network.shared_memory, None);
    assert!(full.deployment.restarts > 0 && full.recording.incomplete().is_none());
    let why = auto_shared_memory(&full, &host(true)).unwrap_err();
    assert!(why.contains("node restarts are on"), "{why}");
    let why = auto_shared_memory(&full, &host(false)).unwrap();
    assert!(why.contains("the run is not recorded"), "{why}");
    let mut no_restarts = full.clone();
    no_restarts.deployment.restarts = 0;
    assert!(auto_shared_memory(&no_restarts, &host(true))
        .unwrap()
        .contains("deployment.restarts = 0"));
    // The stratified scene records full fields every 10th iteration only: chosen.
    let thinned = scene(&scene_text("stratified"));
    let why = auto_shared_memory(&thinned, &host(true)).unwrap();
    assert!(why.contains("full_fields_every = 10"), "{why}");
    // Not without room in /dev/shm, nor without /dev/shm, nor when memory cannot be locked, nor
    // with nodes on other machines.
    let short = Host {
        room: Some(SHARED_MEMORY_ROOM - 1),
        ..host(true)
    };
    assert!(auto_shared_memory(&thinned, &short)
        .unwrap_err()
        .contains("/dev/shm has"));
    assert!(auto_shared_memory(
        &thinned,
        &Host {
            room: None,
            ..host(true)
        }
    )
    .is_err());
    let locked = Host {
        lockable: Err("RLIMIT_MEMLOCK is 8192 KiB".into()),
        ..host(true)
    };
    assert!(auto_shared_memory(&thinned, &locked)
        .unwrap_err()
        .contains("RLIMIT_MEMLOCK"));
    let remote = Host {
        remote_nodes: true,
        ..host(true)
    };
    assert!(auto_shared_memory(&thinned, &remote)
        .unwrap_err()
        .contains("other machines"));
    // Nor with TLS.
    let mut tls = thinned.clone();
    tls.network.tls = Some(glissade_scene::TlsFiles {
        root_ca: "ca.pem".into(),
        cert: "node.pem".into(),
        key: "node.key".into(),
        mutual: true,
    });
    assert!(auto_shared_memory(&tls, &host(true))
        .unwrap_err()
        .contains("network.tls"));
}

/// With shared memory, `glissade run` as processes has its nodes write their large fields
/// (at N = 120 a subdomain's rows for one interface node are those of one or two faces of 41
/// nodes, 82 or 164 × 121 values, 79–159 kB; the macro data are far smaller) into
/// shared-memory blocks and send those: every node process that sends such fields says so at
/// the end, with none copied for lack of room.
#[test]
fn with_shared_memory_large_fields_are_sent_without_a_copy() {
    // Lending needs processes that may lock shared memory; elsewhere nodes copy, as they should.
    if let Err(why) = transport::shared_memory_lockable() {
        eprintln!("skipped: {why}");
        return;
    }
    let dir = crate::common::scratch("lent-fields");
    let scene_file = dir.join("stratified.toml");
    let text = scene_text("stratified").replace("N = 1000", "N = 120") + "\n[network]\nshared_memory = true\n";
    std::fs::write(&scene_file, text).expect("scene file");
    let output = std::process::Command::new(exe())
        .args(["run", "--quiet", "--verbose", "--out"])
        .arg(dir.join("out"))
        .arg(&scene_file)
        .output()
        .expect("spawn glissade");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let written = |node: &str| -> Vec<(u64, u64)> {
        stderr
            .lines()
            .filter_map(|l| l.strip_prefix(&format!("[{node}")))
            .filter_map(|l| l.split_once("] note: shared memory: ").map(|(_, rest)| rest))
            .map(|rest| {
                let n: Vec<u64> = rest.split(' ').filter_map(|w| w.parse().ok()).collect();
                (n[0], n[1])
            })
            .collect()
    };
    for node in ["interface", "subdomain"] {
        let counts = written(node);
        assert!(
            !counts.is_empty(),
            "no {node} process reported on shared memory:\n{stderr}"
        );
        for (lent, refused) in counts {
            assert!(
                lent > 0 && refused == 0,
                "{node}: {lent} written in place, {refused} copied"
            );
        }
    }
}

/// `RUST_LOG` shows the log of every process of a run: the node processes inherit it and the
/// launcher forwards their lines under the node's name (Zenoh logs its session id at `info` when
/// a session opens). Without it, no log line at all.
#[test]
fn rust_log_shows_every_process_log_lines() {
    let dir = crate::common::scratch("rust-log");
    let scene = dir.join("two-blocks.toml");
    std::fs::write(&scene, scene_text("two-blocks")).expect("scene file");
    let run = |log: Option<&str>| {
        let mut cmd = std::process::Command::new(exe());
        cmd.args(["run", "--quiet", "--out"]).arg(dir.join("out")).arg(&scene);
        match log {
            Some(l) => cmd.env("RUST_LOG", l),
            None => cmd.env_remove("RUST_LOG"),
        };
        let output = cmd.output().expect("spawn glissade");
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        String::from_utf8_lossy(&output.stderr).into_owned()
    };
    let with = run(Some("zenoh=info"));
    let without = run(None);
    // The launcher's own lines carry no name: they start with the log's time stamp.
    let launcher = |l: &str| l.starts_with(|c: char| c.is_ascii_digit());
    let zid = |l: &str| l.contains("INFO zenoh::net::runtime: Using ZID");
    assert!(
        with.lines().any(|l| launcher(l) && zid(l)),
        "no Zenoh log line from the launcher:\n{with}"
    );
    for who in ["[subdomain:0] ", "[interface:0] ", "[coarse:0] "] {
        assert!(
            with.lines().any(|l| l.starts_with(who) && zid(l)),
            "no Zenoh log line from `{who}`:\n{with}"
        );
    }
    assert!(
        !without.contains("INFO zenoh"),
        "a log line without RUST_LOG:\n{without}"
    );
    // Zenoh logs a session's configuration at debug level, the bus password among it: never
    // shown, whatever RUST_LOG asks. (Every other Zenoh debug line is: the processes log.)
    let debug = run(Some("zenoh=debug"));
    assert!(debug
        .lines()
        .any(|l| l.starts_with("[subdomain:0] ") && l.contains("DEBUG zenoh")));
    assert!(!debug.contains("password: Some("), "{debug}");
}

/// The console of a run as processes says what matters: what it records, the verdict, the
/// resultants of the first contact interfaces (at most 4, and how many more), the recording with
/// its size and the output files (6 lines beside the resultants, the progress line aside, which
/// is hidden when the output is not a terminal). How it went (shared memory, readiness, bytes on the bus per kind, each
/// node's notes) only with `--verbose`, and the bus statistics are in the summary either way.
#[test]
fn a_run_prints_its_verdict_and_files_and_the_rest_with_verbose() {
    let dir = crate::common::scratch("console");
    let scene = dir.join("small-three-layer.toml");
    std::fs::write(&scene, scene_text("small-three-layer")).expect("scene file");
    let run = |run_id: &str, verbose: bool| {
        let mut cmd = std::process::Command::new(exe());
        cmd.args(["run", "--run-id", run_id, "--out"]).arg(&*dir).arg(&scene);
        if verbose {
            cmd.arg("--verbose");
        }
        let o = cmd.output().expect("spawn glissade");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (out, err) = run("quiet", false);
    let all: Vec<&str> = out.lines().chain(err.lines()).collect();
    // The resultants' lines: interfaces, then supports, at most 4 of each and a count of the rest.
    let resultant = |l: &str| l.starts_with("interface ") || l.starts_with("support ") || l.starts_with("… and ");
    let resultants = all.iter().filter(|l| resultant(l)).count();
    assert!((2..=10).contains(&resultants), "{out}{err}");
    let lines: Vec<&str> = all.iter().copied().filter(|l| !resultant(l)).collect();
    assert_eq!(lines.len(), 7, "{out}{err}");
    assert!(
        lines[0].starts_with("recording to ") && lines[0].contains("full fields at every iteration, 52 kB each"),
        "{out}"
    );
    assert!(
        lines[1].starts_with("scene `small-three-layer`: Converged after "),
        "{out}"
    );
    // The times of the verdict line: set-up, iterations and outputs, within the time since the
    // command started (which also holds loading the scene, starting the recorder and its end).
    let secs = |after: &str| -> f64 {
        let rest = &lines[1][lines[1].find(after).unwrap_or_else(|| panic!("`{after}` in {out}")) + after.len()..];
        rest[..rest.find(" s").expect("seconds")]
            .parse()
            .expect("a number of seconds")
    };
    let (setup, iterations, outputs, total) = (secs("setup "), secs("iterations "), secs("outputs "), secs("s ("));
    assert!(lines[1].ends_with(" s since the command started)"), "{out}");
    // Each printed to 0.01 s (a small scene writes its outputs in less): their sum may exceed the
    // total by the rounding of the three.
    assert!(
        setup > 0.0 && iterations > 0.0 && outputs >= 0.0 && setup + iterations + outputs <= total + 0.015,
        "{out}"
    );
    assert!(
        lines[2].starts_with("recording: ") && lines[2].ends_with(" MB)"),
        "{out}"
    );
    assert!(
        lines[3].starts_with("summary: ")
            && lines[4].starts_with("fields: ")
            && lines[5].starts_with("resultants: ")
            && lines[6].starts_with("boundaries: "),
        "{out}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("small-three-layer-quiet.summary.json")).unwrap())
            .unwrap();
    assert!(
        summary["bus"]["by_kind"]["boundary_state"]["bytes"].as_u64().unwrap() > 0,
        "{}",
        summary["bus"]
    );
    // The linear stages' flops, from the subdomains' counters; their time is not measured as
    // processes.
    let stages = summary["linear_stages"].as_array().unwrap();
    assert_eq!(stages.len(), 1, "{stages:?}");
    assert!(stages[0]["flops"].as_u64().unwrap() > 0, "{stages:?}");
    assert!(
        stages[0]["seconds"].is_null() && stages[0]["gflops_per_s"].is_null(),
        "{stages:?}"
    );

    let (out, err) = run("verbose", true);
    assert!(err.contains("node(s) ready, iterating"), "{err}");
    assert!(err.contains("[recorder:0] note: recorded "), "{err}");
    assert!(err.contains("bus: boundary_state: "), "{err}");
    // The deployment, as `glissade check` prints it.
    assert!(
        err.contains("subdomain processes: 2 (partition = \"contiguous\")\n  subdomain:0: 3 subdomain(s): 0-2\n  subdomain:1: 3 subdomain(s): 3-5\n"),
        "{err}"
    );
    assert!(
        err.contains("GFLOP per iteration over ") && err.contains("time not measured as processes"),
        "{err}"
    );
    assert!(out.contains("summary: "), "{out}");
}
