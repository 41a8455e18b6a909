//! `glissade bench`: timing the nodes does not change the run, and the stage split accounts for
//! every message the nodes handled; the process comparison runs the same run every time.

use crate::common::{run, scene, scene_text};
use glissade::bench::{
    anderson_record_passes, anderson_step_passes, bench, compare_processes, render, render_processes,
    ProcessComparison, ProcessRound, FIELD_PASSES,
};
use glissade::runner::RunResult;
use glissade_mechanics::model::Acceleration;
use glissade_scene::LoadedScene;
use std::path::Path;

/// The small three-layer scene and its plain in-process run.
fn small_three_layer() -> (LoadedScene, RunResult) {
    let sc = scene(&scene_text("small-three-layer"));
    let plain = run(&sc);
    (sc, plain)
}

#[test]
fn bench_splits_an_unchanged_run_by_stage() {
    let (sc, plain) = small_three_layer();
    let report = bench(&sc, "test").expect("bench");
    // Timing only reads clocks around the handlers: the run is the same run.
    assert_eq!(report.iterations, plain.iterations.len());
    let n = report.iterations as u64;
    let subdomains = report.subdomains as u64;
    let calls = |role: &str, field: &str| {
        report
            .stages
            .iter()
            .find(|s| s.role == role && s.field == field)
            .map_or(0, |s| s.calls)
    };
    // Every iteration: each subdomain handles its macro displacements, the coarse node the macro
    // forces of every subdomain, the interface node every subdomain's boundary state; local
    // directions arrive from the second iteration on (the first linear stage starts from zero
    // directions, when the subdomain node starts).
    assert_eq!(
        calls("subdomain", "local_directions"),
        (n - 1) * subdomains,
        "{}",
        render(&report)
    );
    assert_eq!(
        calls("subdomain", "macro_displacements"),
        n * subdomains,
        "{}",
        render(&report)
    );
    assert_eq!(calls("coarse", "macro_forces"), n * subdomains, "{}", render(&report));
    assert_eq!(
        calls("interface", "boundary_state"),
        n * subdomains,
        "{}",
        render(&report)
    );
    for s in &report.stages {
        assert!(s.ms_per_iteration.is_finite() && s.ms_per_iteration >= 0.0, "{s:?}");
    }
    let m = &report.machine;
    assert!(
        m.gflops_one_thread > 0.0 && m.gflops_all_threads > 0.0 && m.read_gb_s > 0.0,
        "{m:?}"
    );
    // The condensed stage's flops: 2 n_b² (N+1) per subdomain for A_E M q̂ at least.
    let flops = report.linear_flops_per_iteration.expect("condensed stage");
    assert!(flops >= 2.0 * (report.largest_boundary.pow(2) * report.time_points) as f64);
    assert!(report.memory_bound_ms > 0.0 && report.wall_over_memory_bound.is_finite());
    // The scene runs Anderson (window 5): its records and steps add passes to the plain
    // iteration's, at most those of a full window's mixed step every iteration (34 + 4 + 14).
    let (full_record, full_step) = (anderson_record_passes(5), anderson_step_passes(5));
    assert_eq!(FIELD_PASSES + full_record + full_step, 52);
    assert!(
        report.field_passes > FIELD_PASSES as f64
            && report.field_passes < (FIELD_PASSES + full_record + full_step) as f64,
        "{}",
        render(&report)
    );
    // Plain relaxation: exactly the plain iteration's passes, and less traffic.
    let mut plain_scene = sc.clone();
    plain_scene.model.solver.acceleration = Acceleration::None;
    let plain_report = bench(&plain_scene, "test").expect("bench");
    assert_eq!(
        plain_report.field_passes,
        FIELD_PASSES as f64,
        "{}",
        render(&plain_report)
    );
    assert!(plain_report.bytes_per_iteration < report.bytes_per_iteration);
}

/// `glissade bench --processes`: every round runs the same run in-process, over TCP and through
/// shared memory, and the ratios are those of the rounds' times.
#[test]
fn bench_compares_processes_with_the_same_run_in_process() {
    let (sc, plain) = small_three_layer();
    let mut k = 0;
    let c = compare_processes(&sc, Path::new(env!("CARGO_BIN_EXE_glissade")), 2, || {
        k += 1;
        Ok(format!("bench-processes-{}-{k}", std::process::id()))
    })
    .expect("comparison");
    // Six runs, each with its own run id; all of them the plain run (the comparison checks the
    // decisions bit for bit).
    assert_eq!(k, 6);
    assert_eq!(c.iterations, plain.iterations.len());
    assert_eq!(c.rounds.len(), 2);
    for r in &c.rounds {
        assert!(
            r.in_process_s > 0.0 && r.tcp_s > 0.0 && r.shared_memory_s > 0.0,
            "{r:?}"
        );
    }
    // The median of two ratios is their mean.
    let mean = |f: fn(&ProcessRound) -> f64| c.rounds.iter().map(|r| f(r) / r.in_process_s).sum::<f64>() / 2.0;
    assert!((c.tcp_over_in_process - mean(|r| r.tcp_s)).abs() <= 1e-12 * c.tcp_over_in_process);
    assert!(
        (c.shared_memory_over_in_process - mean(|r| r.shared_memory_s)).abs()
            <= 1e-12 * c.shared_memory_over_in_process
    );
    // The same with the set-up: every set-up is measured, and the ratios are those of the
    // rounds' set-up + iterations.
    for r in &c.rounds {
        assert!(
            r.in_process_setup_s > 0.0 && r.tcp_setup_s > 0.0 && r.shared_memory_setup_s > 0.0,
            "{r:?}"
        );
    }
    let total = |k: usize| c.rounds.iter().map(|r| r.totals()[k] / r.totals()[0]).sum::<f64>() / 2.0;
    assert!((c.tcp_total_over_in_process - total(1)).abs() <= 1e-12 * c.tcp_total_over_in_process);
    assert!((c.shared_memory_total_over_in_process - total(2)).abs() <= 1e-12 * c.shared_memory_total_over_in_process);
    assert_eq!(c.rounds[0].totals()[1], c.rounds[0].tcp_setup_s + c.rounds[0].tcp_s);
    let text = render_processes(&c);
    assert!(!c.tls && text.contains("| processes, TCP |"), "{text}");
    assert!(
        text.contains("median ratio to in-process, set-up + iterations: TCP"),
        "{text}"
    );
    assert!(text.contains("median ratio to in-process: TCP"), "{text}");
    // A scene with TLS links says so in both places.
    let with_tls = ProcessComparison { tls: true, ..c };
    let text = render_processes(&with_tls);
    assert!(text.contains("| processes, TCP with TLS |"), "{text}");
    assert!(text.contains("median ratio to in-process: TCP with TLS"), "{text}");
}

/// `glissade bench --kernels baseline` runs the element-wise kernels without wide vectors and
/// says so in its text and its JSON; the run takes as many iterations as at the CPU's widest
/// level (that the kernels give the same bits at every level is the numerics crate's test).
#[test]
fn bench_kernels_level_changes_the_code_not_the_run() {
    let dir = crate::common::scratch("bench-kernels");
    let scene = dir.join("small-three-layer.toml");
    std::fs::write(&scene, scene_text("small-three-layer")).expect("scene file");
    let detected = glissade_mechanics::simd::detected().name();
    let mut decisions = Vec::new();
    for (arg, name) in [(Some("baseline"), "baseline"), (None, detected)] {
        let out = dir.join(name);
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"));
        cmd.args(["bench", "--out"]).arg(&out).arg(&scene);
        if let Some(a) = arg {
            cmd.args(["--kernels", a]);
        }
        let output = cmd.output().expect("spawn glissade");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "{stdout}{}",
            String::from_utf8_lossy(&output.stderr)
        );
        assert!(stdout.contains(&format!("element-wise kernels {name};")), "{stdout}");
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("small-three-layer-bench.json")).expect("bench json"),
        )
        .expect("bench json");
        assert_eq!(json["kernels"], name);
        decisions.push(json["iterations"].clone());
    }
    assert_eq!(decisions[0], decisions[1]);
}

/// `glissade bench --max-iterations m --processes 1`: the node processes run the iteration cap of
/// the command line too (they build their model from the scene text the launcher serves, which
/// carries the override), so every run stops after m iterations and repeats the in-process run.
#[test]
fn bench_processes_run_the_command_line_iteration_cap() {
    let dir = crate::common::scratch("bench-cap");
    let scene_file = dir.join("small-three-layer.toml");
    std::fs::write(&scene_file, scene_text("small-three-layer")).expect("scene file");
    // Far below the scene's own run (which the cap must cut short for the test to mean anything).
    let cap = 6;
    let (_, plain) = small_three_layer();
    assert!(
        plain.iterations.len() > 2 * cap,
        "{} iterations",
        plain.iterations.len()
    );
    let out = dir.join("out");
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args([
            "bench",
            "--max-iterations",
            &cap.to_string(),
            "--processes",
            "1",
            "--out",
        ])
        .arg(&out)
        .arg(&scene_file)
        .output()
        .expect("spawn glissade");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("small-three-layer-bench.json")).expect("bench json"))
            .expect("bench json parses");
    assert_eq!(json["iterations"], cap, "{json}");
    assert_eq!(json["processes"]["iterations"], cap, "{json}");
    // The steady iteration of every run: a positive time, and its ratio reported.
    let round = &json["processes"]["rounds"][0];
    for run in ["in_process", "tcp", "shared_memory"] {
        let ms = round[format!("{run}_iteration_ms")].as_f64().unwrap_or(f64::NAN);
        assert!(ms > 0.0, "{run}: {json}");
    }
    assert!(
        json["processes"]["shared_memory_iteration_over_in_process"]
            .as_f64()
            .is_some(),
        "{json}"
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("median ratio to in-process, iteration from the 3rd on"),
        "{stdout}"
    );
}
