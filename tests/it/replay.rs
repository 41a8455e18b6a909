//! Replay of recordings: every node of a small recorded run, re-executed from its recorded inputs,
//! publishes bit-identical outputs; a recording tampered with by one bit is caught, naming the
//! message and field; a recording thinned by `full_fields_every` still replays into Rerun but
//! refuses to re-execute the nodes that need the thinned fields; `glissade replay` writes an .rrd
//! the pinned Rerun CLI accepts, and `glissade run --rerun <file.rrd>` streams a live run's view.
//! A run's linear-stage counters are recorded messages, sent again bit for bit on re-execution.

use crate::common::{glissade_ok, python_with, scene, scene_text, scratch, Scratch};
use glissade::run::Run;
use glissade::runner::RunOptions;
use glissade_messages::{encode, Overrides, Payload, RecordOverride, Role, Stage, Verdict};
use glissade_recorder::{Recorder, RecorderOptions, Recording, RunInfo};
use glissade_replay::reexecute::{parse_node, recorded_nodes, reexecute};
use glissade_scene::LoadedScene;
use std::path::{Path, PathBuf};
use std::process::Command;

fn temp_dir(tag: &str) -> Scratch {
    scratch(&format!("replay-{tag}"))
}

/// Records an in-process run of `text` into `dir`; returns the file.
fn record(text: &str, dir: &Path, run_id: &str) -> PathBuf {
    record_scene(&scene(text), dir, run_id)
}

/// Records an in-process run of `sc` into `dir`; returns the file.
fn record_scene(sc: &LoadedScene, dir: &Path, run_id: &str) -> PathBuf {
    let path = dir.join(format!("{}-{run_id}.mcap", sc.model.name));
    let opts = RunOptions::new(run_id);
    let (result, outcome) = Run::new(sc, &opts)
        .recorded(Some(path.as_path()))
        .in_process()
        .map(|o| (o.result, o.recording))
        .unwrap();
    assert!(result.iterations.len() > 2, "{} iterations", result.iterations.len());
    assert!(outcome.is_some());
    path
}

#[test]
fn every_node_of_a_recorded_run_reexecutes_bit_identically() {
    let dir = temp_dir("reexec");
    let path = record(&scene_text("small-three-layer"), &dir, "rx-1");
    let recording = Recording::open(&path).unwrap();
    let nodes = recorded_nodes(&recording).unwrap();
    // 6 subdomains, the interface node and the coarse node.
    let roles: Vec<Role> = nodes.iter().map(|n| n.role).collect();
    assert_eq!(roles.iter().filter(|r| **r == Role::Subdomain).count(), 6, "{nodes:?}");
    assert!(
        roles.contains(&Role::Interface) && roles.contains(&Role::Coarse),
        "{nodes:?}"
    );
    for id in nodes {
        let r = reexecute(&recording, id).unwrap();
        assert_eq!(r.mismatch, None, "node {id}");
        assert_eq!(r.outputs, r.recorded_outputs, "node {id}");
        assert!(r.inputs > 0 && r.outputs > 0, "node {id}: {r:?}");
    }
}

/// A run with command-line overrides records the scene text as written and the overrides beside
/// it, and readers rebuild the overridden model from the two: the replay's final state has the
/// overridden cap and accuracy, and every node re-executes bit for bit, the interface node's stop
/// at the overridden cap included (the text alone would let the run go on: it converges later).
#[test]
fn a_recording_with_overrides_rebuilds_the_overridden_model() {
    let dir = temp_dir("reexec-overrides");
    let written = scene(&scene_text("small-three-layer"));
    let overrides = Overrides {
        accuracy: Some(1e-4),
        tolerance: None,
        max_iterations: Some(4),
        record: Some(RecordOverride::Full),
    };
    let sc = written.with_overrides("test.toml", &overrides).unwrap();
    assert!(
        written.model.solver.max_iterations > 4 && sc.fingerprint != written.fingerprint,
        "{}",
        written.model.solver.max_iterations
    );
    let path = record_scene(&sc, &dir, "rx-ov");
    let recording = Recording::open(&path).unwrap();
    assert_eq!(
        recording.scene_text(),
        Some(written.text.as_str()),
        "the text as written"
    );
    assert_eq!(recording.scene_overrides(), Some(&overrides));
    assert_eq!(recording.scene_fingerprint(), sc.fingerprint);
    let decisions: Vec<(u32, Verdict)> = recording
        .messages()
        .filter(|m| m.topic.ends_with("/decision"))
        .map(|m| {
            let msg = recording.decode(&m).unwrap();
            match msg.payload {
                Payload::Decision(d) => (msg.envelope.iteration, d.verdict),
                p => panic!("{}", p.field_key()),
            }
        })
        .collect();
    assert_eq!(
        decisions.last(),
        Some(&(3, Verdict::MaxIterations)),
        "stopped at the overridden cap"
    );
    let state = glissade_replay::final_state(&recording).unwrap();
    let solver = &state.model.solver;
    assert_eq!((solver.max_iterations, solver.accuracy), (4, Some(1e-4)));
    let nodes = recorded_nodes(&recording).unwrap();
    assert!(nodes.iter().any(|n| n.role == Role::Interface), "{nodes:?}");
    for id in nodes {
        let r = reexecute(&recording, id).unwrap();
        assert_eq!(r.mismatch, None, "node {id}");
        assert_eq!(r.outputs, r.recorded_outputs, "node {id}");
    }
    // The written scene run without the cap goes on past it: the cap is the overrides'.
    let plain = crate::common::run(&written);
    assert!(plain.iterations.len() > 4, "{} iterations", plain.iterations.len());
}

/// With a time-coarse start the subdomains' first inputs are the launcher's local directions:
/// they are recorded, so every node still re-executes bit for bit.
#[test]
fn a_time_coarse_start_recording_reexecutes_bit_identically() {
    let dir = temp_dir("reexec-time-start");
    let text = scene_text("small-three-layer").replace("[solver]", "[solver]\ntime_coarsening = 2");
    let path = record(&text, &dir, "rx-ts");
    let recording = Recording::open(&path).unwrap();
    let nodes = recorded_nodes(&recording).unwrap();
    assert_eq!(
        nodes.iter().filter(|n| n.role == Role::Subdomain).count(),
        6,
        "{nodes:?}"
    );
    assert!(!nodes.iter().any(|n| n.role == Role::Launcher), "{nodes:?}");
    for id in nodes {
        let r = reexecute(&recording, id).unwrap();
        assert_eq!(r.mismatch, None, "node {id}");
        assert_eq!(r.outputs, r.recorded_outputs, "node {id}");
    }
}

#[test]
fn a_tampered_recording_names_the_first_differing_message_and_field() {
    let dir = temp_dir("tamper");
    let text = scene_text("small-three-layer");
    let path = record(&text, &dir, "rx-2");
    let original = Recording::open(&path).unwrap();
    let sc = scene(&text);
    // Copy the recording, changing one entry of subdomain 1's boundary state at iteration 2 by a
    // relative 1e-9 (plus 1e-12 mm, should it be zero): small, yet large enough to reach the
    // interface node's outputs through its local stage.
    let tampered_path = dir.join("tampered.mcap");
    let run = RunInfo {
        run_id: "rx-2".into(),
        scene_name: sc.model.name.clone(),
        scene_fingerprint: sc.fingerprint,
        scene_text: text.clone(),
        scene_overrides: sc.overrides,
        software: "test".into(),
    };
    let mut rec = Recorder::create(&tampered_path, &run, &RecorderOptions::default()).unwrap();
    let (row, col) = (5usize, 3usize);
    let mut changed = false;
    for m in original.messages() {
        let mut msg = original.decode(&m).unwrap();
        if let Payload::BoundaryState { subdomain: 1, w, .. } = &mut msg.payload {
            if msg.envelope.iteration == 2 && msg.envelope.stage != Stage::Final {
                let k = col * w.rows() + row;
                w.data[k] = w.data[k] * (1.0 + 1e-9) + 1e-12;
                changed = true;
            }
        }
        rec.record(m.topic, m.log_time, &encode(&msg)).unwrap();
    }
    rec.finish().unwrap();
    assert!(changed);
    let tampered = Recording::open(&tampered_path).unwrap();

    // Subdomain 1 re-executed publishes the untampered value: its recorded output differs.
    let r = reexecute(&tampered, parse_node("subdomain:1").unwrap()).unwrap();
    let m = r.mismatch.expect("the tampered output is caught");
    assert!(m.topic.ends_with("/subdomain/1/boundary_state"), "{m}");
    assert_eq!(m.iteration, 2, "{m}");
    assert!(
        m.detail.contains(&format!("BoundaryState.w[row {row}, column {col}]")),
        "{m}"
    );
    // The other subdomains do not read subdomain 1's state: still identical.
    let r0 = reexecute(&tampered, parse_node("subdomain:0").unwrap()).unwrap();
    assert_eq!(r0.mismatch, None);
    // The interface node reads it: its outputs from iteration 2 on differ from the recorded ones.
    let ri = reexecute(&tampered, parse_node("interface:0").unwrap()).unwrap();
    let mi = ri.mismatch.expect("the interface node's outputs change with its input");
    assert_eq!(mi.iteration, 2, "{mi}");
    assert!(mi.detail.starts_with("field "), "{mi}");
    // And the command line says the same, exiting 3.
    let out = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["replay", "--node", "subdomain:1"])
        .arg(&tampered_path)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(3),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("subdomain/1/boundary_state` (iteration 2, stage Linear)")
            && stdout.contains(&format!("w[row {row}, column {col}]")),
        "{stdout}"
    );
}

/// `rerun rrd verify` of the pinned Python package (`rerun-sdk`) on `rrd`, or None (reason
/// printed) when Python or the package is missing (a failure under GLISSADE_REQUIRE_PYTHON).
fn rerun_verify(rrd: &Path) -> Option<()> {
    let python = python_with(&["rerun"])?;
    let v = Command::new(python)
        .args(["-m", "rerun", "rrd", "verify"])
        .arg(rrd)
        .output()
        .unwrap();
    assert!(
        v.status.success(),
        "`rerun rrd verify` rejected {}: {}{}",
        rrd.display(),
        String::from_utf8_lossy(&v.stdout),
        String::from_utf8_lossy(&v.stderr)
    );
    println!("`rerun rrd verify` accepted {}", rrd.display());
    Some(())
}

/// The 2nd and 98th percentiles (numpy's "linear") and the extremes of the von Mises stress at
/// every node and time point of the final state `recording` holds, computed by sorting.
fn von_mises_percentiles(recording: &Path) -> (f64, f64, f64, f64) {
    use glissade_mechanics::post::{nodal_stresses, von_mises};
    let state = glissade_replay::final_state(&Recording::open(recording).unwrap()).unwrap();
    let model = &state.model;
    let mut v: Vec<f64> = Vec::new();
    for (&s, per_time) in &state.u {
        let sub = &model.subdomains[s as usize];
        for u in per_time {
            v.extend(nodal_stresses(sub, model.plane, u).unwrap().iter().map(von_mises));
        }
    }
    v.sort_by(f64::total_cmp);
    let at = |p: f64| {
        let h = (v.len() - 1) as f64 * p / 100.0;
        let k = h.floor() as usize;
        v[k] + (h - k as f64) * (v[(k + 1).min(v.len() - 1)] - v[k])
    };
    (at(2.0), at(98.0), v[0], v[v.len() - 1])
}

/// The .rrd opens ready: one blueprint, activated, with the structure seen from above, the
/// convergence plot and the counts, no automatic layout; the legend's range is `range` (lower,
/// upper, min, max) up to the last bits (the same order statistics and interpolation formula).
fn assert_opens_ready(rrd: &Path, range: (f64, f64, f64, f64)) {
    use glissade_replay::blueprint::{CONVERGENCE_VIEW, COUNTS_VIEW, FORCES_VIEW, STRUCTURE_VIEW};
    let c = glissade_replay::rrd::RrdContents::read(rrd).unwrap();
    assert_eq!((c.blueprints, c.activations), (1, 1), "{}", rrd.display());
    assert_eq!((c.auto_layout, c.auto_views), (Some(false), Some(false)));
    let classes: Vec<(&str, &str)> = c.views.iter().map(|v| (v.name.as_str(), v.class.as_str())).collect();
    for view in [
        (STRUCTURE_VIEW, "3D"),
        (CONVERGENCE_VIEW, "TimeSeries"),
        (COUNTS_VIEW, "TimeSeries"),
        (FORCES_VIEW, "TimeSeries"),
    ] {
        assert!(classes.contains(&view), "{view:?} in {classes:?}");
    }
    let (eye, target, _) = c.view(STRUCTURE_VIEW).unwrap().eye.expect("eye");
    assert!(
        eye[0] == target[0] && eye[1] == target[1] && eye[2] > 0.0,
        "{eye:?} {target:?}"
    );
    let stated = |k: &str| c.legend_range[k];
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
    let (lo, hi, min, max) = range;
    assert!(
        close(stated("lower"), lo) && close(stated("upper"), hi),
        "legend {:?} against {lo} – {hi}",
        c.legend_range
    );
    assert_eq!((stated("min"), stated("max")), (min, max));
    assert!(
        min < lo && hi < max,
        "the scale is narrower than the extremes: {range:?}"
    );
}

#[test]
fn a_thinned_recording_replays_but_refuses_to_reexecute_nodes_that_need_every_field() {
    let dir = temp_dir("thinned");
    let text = scene_text("small-three-layer");
    assert!(
        !text.contains("[recording]"),
        "the test appends its own [recording] table"
    );
    let path = record(&format!("{text}\n[recording]\nfull_fields_every = 3\n"), &dir, "rx-3");
    let recording = Recording::open(&path).unwrap();
    let err = reexecute(&recording, parse_node("subdomain:0").unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("local_directions and macro_displacements only every 3 iterations")
            && err.contains("full_fields_every = 1"),
        "{err}"
    );
    let err = reexecute(&recording, parse_node("interface:0").unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("boundary_state only every 3 iterations"), "{err}");
    // The coarse node reads the macro forces, thinned too.
    let err = reexecute(&recording, parse_node("coarse:0").unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("macro_forces only every 3 iterations"), "{err}");

    // The Rerun view: meshes only at the iterations that kept the boundary states, and the final
    // state (from the interface solutions) at every time point.
    let rrd = dir.join("thinned.rrd");
    let stdout = glissade_ok(&[&"replay", &"--save", &rrd, &path]);
    let iterations = recording.messages().filter(|m| m.topic.ends_with("/decision")).count();
    let kept = recording
        .messages()
        .filter(|m| m.topic.ends_with("/boundary_state"))
        .count();
    let sc = scene(&text);
    let meshes = kept + sc.model.subdomains.len() * sc.model.time.n_points();
    assert!(
        stdout.contains(&format!("{iterations} iterations, {meshes} meshes")),
        "expected {iterations} iterations and {meshes} meshes: {stdout}"
    );
    // The final state comes from the interface solutions, which are never thinned.
    assert_opens_ready(&rrd, von_mises_percentiles(&path));
    rerun_verify(&rrd);
}

/// `glissade run --rerun` on a multi-process run: the launcher feeds the view every message it
/// receives from the node processes; the .rrd holds every iteration and the final meshes.
#[test]
fn multi_process_live_view_writes_an_rrd_the_rerun_cli_accepts() {
    let dir = temp_dir("rrd-mp");
    let scene_path = dir.join("small-three-layer.toml");
    std::fs::write(&scene_path, scene_text("small-three-layer")).unwrap();
    let live = dir.join("live-mp.rrd");
    let stdout = glissade_ok(&[
        &"run",
        &"--quiet",
        &"--run-id",
        &"rx-mp",
        &"--out",
        &dir,
        &"--rerun",
        &live,
        &scene_path,
    ]);
    // "rerun: <iterations> iterations, <meshes> meshes written to <file>": every decision reached the view
    // (the run's iteration count is in the summary), and each of the 6 subdomains was drawn at
    // least once per iteration.
    let line = stdout.lines().find(|l| l.starts_with("rerun: ")).expect("rerun line");
    let nums: Vec<u64> = line.split_whitespace().filter_map(|w| w.parse().ok()).collect();
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("small-three-layer-rx-mp.summary.json")).unwrap())
            .unwrap();
    let iterations = summary["iterations"].as_u64().expect("iterations in the summary");
    assert_eq!(nums[0], iterations, "{line}");
    assert!(nums[1] >= 6 * iterations, "{line}");
    assert!(std::fs::metadata(&live).unwrap().len() > 10_000);
    rerun_verify(&live);
}

#[test]
fn replay_and_live_run_write_rrd_files_the_rerun_cli_accepts() {
    let dir = temp_dir("rrd");
    let scene_path = dir.join("small-three-layer.toml");
    std::fs::write(&scene_path, scene_text("small-three-layer")).unwrap();
    // A live in-process run streamed to an .rrd, recorded at the same time.
    let live = dir.join("live.rrd");
    let stdout = glissade_ok(&[
        &"run",
        &"--in-process",
        &"--quiet",
        &"--run-id",
        &"rx-4",
        &"--out",
        &dir,
        &"--rerun",
        &live,
        &scene_path,
    ]);
    assert!(stdout.contains("rerun: "), "{stdout}");
    // Replay of the recording, coloured by |u|.
    let replayed = dir.join("replayed.rrd");
    let recorded = dir.join("small-three-layer-rx-4.mcap");
    glissade_ok(&[
        &"replay",
        &"--color-by",
        &"displacement",
        &"--save",
        &replayed,
        &recorded,
    ]);
    // Every node of that run re-executes bit-identically from the command line too.
    let stdout = glissade_ok(&[&"replay", &"--node", &"all", &recorded]);
    assert_eq!(stdout.matches("bit-identical").count(), 8, "{stdout}");
    for rrd in [&live, &replayed] {
        assert!(std::fs::metadata(rrd).unwrap().len() > 10_000, "{}", rrd.display());
        rerun_verify(rrd);
    }
    // The live view, which cannot know the final range up front, ends on the final state's
    // (its legend's last value); the replay, coloured by |u|, has another range.
    assert_opens_ready(&live, von_mises_percentiles(&recorded));
    let c = glissade_replay::rrd::RrdContents::read(&replayed).unwrap();
    assert_eq!(c.blueprints, 1);
    // The forces over time: each contact interface's resultants, each boundary rule's force.
    for entity in [
        "resultants/interface_1/normal",
        "resultants/interface_1/tangential",
        "boundary/boundary_0/force_x",
    ] {
        assert!(c.entities.iter().any(|e| e == entity), "{entity} in {:?}", c.entities);
    }
    assert!(c.legend_range["upper"] < 1.0, "|u| in mm: {:?}", c.legend_range);
}

/// `replay --reference` logs each iteration's error against the monolithic Newton reference, and
/// it is exactly what `glissade report` measures on the same run: the recording's boundary states
/// are the run's, the reference solve and the error formula are the same, so the numbers are
/// bit-identical.
#[test]
fn replay_logs_the_error_against_the_reference_as_the_report_measures_it() {
    let dir = temp_dir("reference");
    let text = scene_text("small-three-layer");
    let path = record(&text, &dir, "rx-ref");
    let (report, _, _) = glissade::report::build_report(&scene(&text), "rx-ref-report", None).unwrap();
    let summary = glissade_replay::replay(
        &Recording::open(&path).unwrap(),
        &glissade_replay::ReplayOptions {
            sink: glissade_replay::Sink::Save(dir.join("reference.rrd")),
            color_by: glissade_replay::ColorBy::VonMises,
            amplification: None,
            time_point: None,
            reference: true,
            basis_sizes: Vec::new(),
        },
    )
    .unwrap();
    assert!(summary.reference_s.is_some());
    assert_eq!(summary.errors.len(), report.points.len(), "one error per iteration");
    for p in &report.points {
        let &(_, e_f, e_w) = summary
            .errors
            .iter()
            .find(|e| e.0 == p.iteration)
            .unwrap_or_else(|| panic!("no error logged for iteration {}", p.iteration));
        assert_eq!(e_f.to_bits(), p.traction_error.to_bits(), "iteration {}", p.iteration);
        assert_eq!(e_w.to_bits(), p.jump_error.to_bits(), "iteration {}", p.iteration);
    }
}

/// Subdomain nodes read no clock and hold no log: their linear-stage counters (flops, PGD basis
/// size, new and dropped modes, ξ) go out as `linear_stage_stats`, once per subdomain and
/// iteration. On a PGD run with compression and Anderson: the recorded counters are exactly the
/// run's linear-stage records (each timed by the bus, > 0 s), their basis sizes those of the
/// recorded mode-form states, and a subdomain re-executed from the recording sends them again
/// bit for bit (its records untimed).
#[test]
fn linear_stage_counters_are_recorded_messages() {
    use glissade_replay::reexecute::{recorded_basis_sizes, recorded_linear_stage_stats};
    let dir = temp_dir("stage-stats");
    let text = scene_text("small-three-layer").replace("[solver]\n", "[solver]\nlinear_stage = \"pgd\"\n")
        + "\n[solver.pgd]\ncriterion = \"increment-svd\"\n";
    let sc = scene(&text);
    assert!(matches!(
        sc.model.solver.acceleration,
        glissade_mechanics::model::Acceleration::Anderson { .. }
    ));
    let path = dir.join("stage-stats.mcap");
    let opts = RunOptions::new("stage-stats");
    let outcome = Run::new(&sc, &opts)
        .recorded(Some(path.as_path()))
        .linear_stages()
        .in_process()
        .unwrap();
    let (result, records, outcome) = (outcome.result, outcome.linear_stages, outcome.recording);
    assert!(outcome.is_some());
    // One record per subdomain (6) and iteration, each timed by the bus.
    assert_eq!(records.len(), 6 * result.iterations.len());
    assert!(records.iter().all(|r| r.seconds > 0.0 && r.flops > 0), "{records:?}");
    assert!(records.iter().any(|r| r.modes > 2 && r.new_modes > 0));
    let counters = |r: &glissade_subdomain::LinearStageRecord| {
        (
            r.iteration,
            r.subdomain,
            r.flops,
            r.modes,
            r.new_modes,
            r.dropped_modes,
            r.xi1.to_bits(),
            r.xi2.to_bits(),
        )
    };
    let recording = Recording::open(&path).unwrap();
    let recorded = recorded_linear_stage_stats(&recording).unwrap();
    let recorded: Vec<_> = recorded
        .iter()
        .map(|(it, s)| counters(&glissade_subdomain::LinearStageRecord::new(*it, s, 0.0)))
        .collect();
    assert_eq!(recorded, records.iter().map(counters).collect::<Vec<_>>());
    let sizes: Vec<(u32, u32, usize)> = records.iter().map(|r| (r.iteration, r.subdomain, r.modes)).collect();
    assert_eq!(recorded_basis_sizes(&recording).unwrap(), Some(sizes));
    let id = parse_node("subdomain:3").unwrap();
    let r = reexecute(&recording, id).unwrap();
    assert_eq!(r.mismatch, None);
    assert!(r.linear_stages.iter().all(|r| r.seconds == 0.0));
    assert_eq!(
        r.linear_stages.iter().map(counters).collect::<Vec<_>>(),
        records
            .iter()
            .filter(|r| r.subdomain == 3)
            .map(counters)
            .collect::<Vec<_>>()
    );
}

/// A PGD run's basis sizes come back from its recorded mode-form states (the time functions'
/// row counts): exactly the sizes the run's own linear stages logged, and `glissade replay` puts
/// them in the view (`pgd/basis/<subdomain>`).
#[test]
fn a_pgd_recording_replays_with_the_runs_basis_sizes() {
    let dir = temp_dir("pgd-basis");
    let text = scene_text("small-three-layer");
    assert!(text.contains("[solver]\n"));
    let text = text.replace("[solver]\n", "[solver]\nlinear_stage = \"pgd\"\n");
    let path = record(&text, &dir, "rx-pgd");
    let opts = RunOptions::new("rx-pgd-log");
    let (_, records) = Run::new(&scene(&text), &opts)
        .linear_stages()
        .in_process()
        .map(|o| (o.result, o.linear_stages))
        .unwrap();
    let mut expected: Vec<(u32, u32, usize)> = records.iter().map(|r| (r.iteration, r.subdomain, r.modes)).collect();
    expected.sort_unstable();
    assert!(
        expected.iter().any(|e| e.2 > 1),
        "the run built PGD bases: {expected:?}"
    );
    let sizes = glissade_replay::reexecute::recorded_basis_sizes(&Recording::open(&path).unwrap())
        .unwrap()
        .expect("a PGD run");
    assert_eq!(sizes, expected);
    // Another linear stage: nothing to show.
    let plain = record(&scene_text("small-three-layer"), &dir, "rx-plain");
    assert_eq!(
        glissade_replay::reexecute::recorded_basis_sizes(&Recording::open(&plain).unwrap()).unwrap(),
        None
    );
    let stdout = glissade_ok(&[&"replay", &"--save", &dir.join("pgd.rrd"), &path]);
    assert!(
        stdout.contains(&format!("PGD basis sizes: {} linear stages", expected.len())),
        "{stdout}"
    );
    rerun_verify(&dir.join("pgd.rrd"));
}

/// Without a display, `glissade replay --spawn` fails at once, saying why and what to do
/// instead, rather than waiting on a viewer that cannot open (issue: it hung until killed).
#[test]
fn spawning_a_viewer_without_a_display_fails_at_once() {
    if !cfg!(target_os = "linux") {
        println!("skipped: the display check is Linux's");
        return;
    }
    let dir = temp_dir("no-display");
    let path = record(&scene_text("two-blocks"), &dir, "nodisplay");
    let start = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .args(["replay", "--spawn"])
        .arg(&path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("no display to spawn a viewer on (DISPLAY and WAYLAND_DISPLAY are unset)")
            && stderr.contains("--save <f.rrd>"),
        "{stderr}"
    );
    // The bar is 10 s: the check comes before any viewer is started.
    assert!(
        start.elapsed() < std::time::Duration::from_secs(10),
        "{:?}",
        start.elapsed()
    );
}

/// A recording with one byte flipped inside a chunk in its middle (the check Python's `mcap`
/// makes too): `glissade replay` warns with the chunk's position and replays every other message;
/// re-execution refuses it rather than blame a healthy node.
#[test]
fn a_recording_with_a_damaged_chunk_replays_the_rest_and_refuses_reexecution() {
    let dir = temp_dir("damaged");
    let path = record(&scene_text("small-three-layer"), &dir, "dmg");
    let intact = Recording::open(&path).unwrap().messages().count();
    let mut bytes = std::fs::read(&path).unwrap();
    // The middle of the file lies inside a chunk of boundary states (they make most of its bytes).
    let at = bytes.len() / 2;
    bytes[at] ^= 0x10;
    std::fs::write(&path, &bytes).unwrap();
    let r = Recording::open(&path).unwrap();
    let why = r.damaged().expect("the flipped byte is found");
    let read = r.messages().count();
    assert!(read > 0 && read < intact, "{read} of {intact} messages");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_glissade"))
            .arg("replay")
            .arg(&path)
            .args(args)
            .output()
            .unwrap()
    };
    let o = run(&["--save", &dir.join("damaged.rrd").display().to_string()]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("warning: {}: {why}", path.display())),
        "{stderr}"
    );
    assert!(String::from_utf8_lossy(&o.stdout).contains(&format!("replayed {read} messages")));
    let o = run(&["--node", "all"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("damaged chunk(s)") && stderr.contains("re-execution needs every input"),
        "{stderr}"
    );
}

/// A recording holds messages in the order the recorder heard them, and the router forwards each
/// sender's messages on its own: the recorder can hear an Anderson step before the macro
/// displacements and local directions its subdomains had received first. Re-execution takes such
/// a recording too: here every subdomain input of iteration 3 is moved after that iteration's
/// Anderson step, and every node still re-executes bit for bit (before, a subdomain refused the
/// early step and re-execution failed).
#[test]
fn a_recording_out_of_causal_order_reexecutes_bit_identically() {
    let dir = temp_dir("reexec-order");
    let text = scene_text("small-three-layer");
    let path = record(&text, &dir, "rx-order");
    let original = Recording::open(&path).unwrap();
    let sc = scene(&text);
    let run = RunInfo {
        run_id: "rx-order".into(),
        scene_name: sc.model.name.clone(),
        scene_fingerprint: sc.fingerprint,
        scene_text: text.clone(),
        scene_overrides: sc.overrides,
        software: "test".into(),
    };
    let reordered_path = dir.join("reordered.mcap");
    let mut rec = Recorder::create(&reordered_path, &run, &RecorderOptions::default()).unwrap();
    let (mut delayed, mut moved) = (Vec::new(), 0);
    for m in original.messages() {
        let msg = original.decode(&m).unwrap();
        let input = matches!(
            msg.payload,
            Payload::MacroDisplacements { .. } | Payload::LocalDirections { .. }
        );
        if input && msg.envelope.iteration == 3 && delayed.len() < 1000 && moved == 0 {
            delayed.push((m.topic.to_string(), m.log_time, m.data.to_vec()));
            continue;
        }
        rec.record(m.topic, m.log_time, &m.data).unwrap();
        if matches!(msg.payload, Payload::AndersonStep { .. }) && msg.envelope.iteration == 3 && moved == 0 {
            for (topic, t, data) in delayed.drain(..) {
                rec.record(&topic, t, &data).unwrap();
                moved += 1;
            }
        }
    }
    rec.finish().unwrap();
    assert!(moved >= 6, "{moved} inputs moved after the step");
    let reordered = Recording::open(&reordered_path).unwrap();
    for id in recorded_nodes(&reordered).unwrap() {
        let r = reexecute(&reordered, id).unwrap_or_else(|e| panic!("node {id}: {e}"));
        assert_eq!(r.mismatch, None, "node {id}");
        assert_eq!(r.outputs, r.recorded_outputs, "node {id}");
    }
}

/// `replay --save` and the default `<f>.rrd` never overwrite a file: not the recording itself
/// (which `--save <f.mcap>` used to replace with the view), not an earlier view; `run --rerun`
/// neither. Each refusal names the file, exits 2 and leaves the file byte for byte as it was.
#[test]
fn a_rerun_view_never_overwrites_a_file() {
    let dir = temp_dir("no-overwrite");
    let path = record(&scene_text("small-three-layer"), &dir, "keep");
    let original = std::fs::read(&path).unwrap();
    let replay = |args: &[&dyn AsRef<std::ffi::OsStr>]| {
        Command::new(env!("CARGO_BIN_EXE_glissade"))
            .arg("replay")
            .args(args.iter().map(|a| a.as_ref()))
            .output()
            .unwrap()
    };
    let refused = |o: &std::process::Output, file: &Path| {
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert!(
            stderr.contains(&file.display().to_string()) && stderr.contains("already exists; nothing was overwritten"),
            "{stderr}"
        );
    };
    // The recording as the view's file.
    refused(&replay(&[&path, &"--save", &path]), &path);
    assert_eq!(std::fs::read(&path).unwrap(), original, "the recording changed");
    // The default <f>.rrd, once written, is not written again.
    let rrd = path.with_extension("rrd");
    glissade_ok(&[&"replay", &path]);
    let view = std::fs::read(&rrd).unwrap();
    refused(&replay(&[&path]), &rrd);
    assert_eq!(std::fs::read(&rrd).unwrap(), view, "the earlier view changed");
    // A live view onto an existing file: refused before the run starts (no summary written).
    let o = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["run", "--in-process", "--run-id", "live", "--out"])
        .arg(&*dir)
        .arg("--rerun")
        .arg(&rrd)
        .arg(format!(
            "{}/launch/scenes/small-three-layer.toml",
            env!("CARGO_MANIFEST_DIR")
        ))
        .output()
        .unwrap();
    refused(&o, &rrd);
    assert_eq!(std::fs::read(&rrd).unwrap(), view, "the earlier view changed");
    assert!(!dir.join("small-three-layer-live.summary.json").exists());
}

/// `glissade export` reads and checks everything before it writes anything: a recording cut in
/// half (its run's final solutions missing) and a target that already exists both stop it with
/// exit 2 and a message naming the file, and leave no file and no folder behind.
#[test]
fn an_export_that_cannot_finish_writes_nothing() {
    let dir = temp_dir("export-nothing");
    let path = record(&scene_text("small-three-layer"), &dir, "whole");
    let bytes = std::fs::read(&path).unwrap();
    let half = dir.join("half.mcap");
    std::fs::write(&half, &bytes[..bytes.len() / 2]).unwrap();
    let export = |recording: &Path, targets: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_glissade"))
            .arg("export")
            .arg(recording)
            .args(["--vtu", &format!("{}/v{targets}", dir.display())])
            .args(["--csv", &format!("{}/c{targets}", dir.display())])
            .args(["--foreign", &format!("{}/f{targets}", dir.display())])
            .output()
            .unwrap();
        (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (code, stderr) = export(&half, "1");
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!("{}: no final solution of interface 0", half.display()))
            && stderr.contains("nothing was exported"),
        "{stderr}"
    );
    for d in ["v1", "c1", "f1"] {
        assert!(!dir.join(d).exists(), "{d} was created");
    }
    // The CSV target exists: neither the series nor the foreign copy is written.
    std::fs::create_dir_all(dir.join("c2")).unwrap();
    let csv = dir.join("c2/small-three-layer-whole.interfaces.csv");
    std::fs::write(&csv, b"earlier").unwrap();
    let (code, stderr) = export(&path, "2");
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!("{} already exists; nothing was overwritten", csv.display())),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&csv).unwrap(), b"earlier");
    assert!(!dir.join("v2").exists() && !dir.join("f2").exists());
}
