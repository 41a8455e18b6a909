//! Nodes as separate processes over Zenoh (loopback, launcher-hosted router, multicast scouting
//! off): the same scene run in-process and as processes gives bit-identical results.

use crate::common::scene;
use glissade::distributed::run_multi_process;
use glissade::runner::{run_in_process, RunOptions, RunResult};
use std::path::Path;

fn scene_file(name: &str) -> String {
    std::fs::read_to_string(format!("{}/launch/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"))).expect("scene file")
}

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_glissade"))
}

/// Same iterations, same decisions, and the same bits in every interface field.
fn assert_identical(a: &RunResult, b: &RunResult) {
    assert_eq!(a.iterations.len(), b.iterations.len(), "iteration counts");
    for (x, y) in a.iterations.iter().zip(&b.iterations) {
        assert_eq!(x.decision, y.decision, "decision of iteration {}", x.iteration);
    }
    assert_eq!(a.interfaces.len(), b.interfaces.len());
    for (x, y) in a.interfaces.iter().zip(&b.interfaces) {
        assert_eq!(x.interface, y.interface);
        for (f, g) in [
            (&x.w_a, &y.w_a),
            (&x.f_a, &y.f_a),
            (&x.w_b_hat, &y.w_b_hat),
            (&x.f_a_hat, &y.f_a_hat),
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

#[test]
fn processes_match_in_process_bit_for_bit() {
    let sc = scene(&scene_file("small-three-layer"));
    assert!(
        sc.deployment.subdomain_nodes >= 2,
        "the scene spreads its subdomains over processes"
    );
    let local = run_in_process(
        &sc,
        &RunOptions {
            run_id: "local".into(),
            interior: false,
        },
        |_| {},
    )
    .unwrap();
    let remote = run_multi_process(
        &sc,
        &RunOptions {
            run_id: "distributed-test-1".into(),
            interior: false,
        },
        exe(),
        |_| {},
    )
    .unwrap();
    println!(
        "in-process {} iterations, processes {} iterations; nodes {:?}",
        local.iterations.len(),
        remote.iterations.len(),
        remote.nodes
    );
    assert_identical(&local, &remote);
}

/// The stratified scene (18 subdomains) over 3 subdomain processes, one interface node and one
/// coarse node (N = 10 to keep the debug-profile test short).
#[test]
fn stratified_over_three_subdomain_processes() {
    let text = scene_file("stratified").replace("N = 100", "N = 10");
    let sc = scene(&text);
    assert_eq!(sc.deployment.subdomain_nodes, 3);
    let local = run_in_process(
        &sc,
        &RunOptions {
            run_id: "local".into(),
            interior: false,
        },
        |_| {},
    )
    .unwrap();
    let remote = run_multi_process(
        &sc,
        &RunOptions {
            run_id: "distributed-test-2".into(),
            interior: false,
        },
        exe(),
        |_| {},
    )
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
