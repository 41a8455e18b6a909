//! Time-coarse start (`solver.time_coarsening`): the fine iteration starts from a coarse time
//! grid's solution instead of ŝ = 0. It must reach the same limit, run the same in processes as
//! in-process, and record what it sent so that a node re-executes from the recording.

use crate::common::{scene, scene_text};
use crate::distributed::assert_identical;
use glissade::distributed::Network;
use glissade::run::Run;
use glissade::runner::{RunOptions, RunResult};
use glissade_mechanics::local::error_against_reference;
use glissade_mechanics::model::TimeStart;
use glissade_messages::{Payload, Role, Verdict};
use glissade_scene::LoadedScene;
use std::path::Path;
use std::time::Duration;

/// Runs `sc` to η ≤ `tolerance` (no stagnation stop) with or without a time-coarse start; returns
/// the result and the launcher's messages seen on the bus (subdomain, first q̂ value).
fn solve(sc: &LoadedScene, start: Option<TimeStart>, tolerance: f64, k0_factor: f64) -> (RunResult, Vec<u32>) {
    let mut sc = sc.clone();
    sc.model.solver.time_start = start;
    (sc.model.solver.accuracy, sc.model.solver.tolerance) = (None, Some(tolerance));
    sc.model.solver.k0_factor = k0_factor;
    sc.model.solver.max_iterations = 20_000;
    sc.model.solver.stagnation_window = 20_000;
    let mut from_launcher = Vec::new();
    let result = Run::new(&sc, &RunOptions::new("time-start"))
        .observe(|m| {
            if let (Role::Launcher, Payload::LocalDirections { subdomain, q_hat, .. }) =
                (m.envelope.sender.role, &m.payload)
            {
                assert_eq!(m.envelope.iteration, 0);
                assert!(
                    q_hat.data.iter().any(|v| *v != 0.0),
                    "q̂ of subdomain {subdomain} is zero"
                );
                from_launcher.push(*subdomain);
            }
            Duration::ZERO
        })
        .in_process()
        .map(|o| o.result)
        .expect("run");
    assert_eq!(result.verdict, Verdict::Converged, "{start:?}");
    (result, from_launcher)
}

/// Both runs stop at η ≤ 1e-12 and their contact tractions and jumps must agree within 1e-8,
/// relative, in the space-time norm of the error against a reference: the start changes the
/// path, not the fixed point. Why 1e-12 and 1e-8: as in `acceleration.rs`, a run stopped at
/// η ≤ 1e-10 may itself be a few 1e-8 from its limit, at 1e-12 about 2e-10. The k₀ factors are
/// those of the monolithic comparison. The coarse grids: N = 40 → 10, 20 → 5, 10 → 5.
#[test]
fn time_coarse_start_reaches_the_same_limit() {
    for (name, k0, c) in [
        ("two-blocks", 3.0, 4),
        ("hertz-slip", 10.0, 4),
        ("small-three-layer", 1.0, 2),
    ] {
        let sc = scene(&scene_text(name));
        assert_eq!(sc.model.time.n_steps % c, 0, "{name}");
        let (cold, none) = solve(&sc, None, 1e-12, k0);
        let start = TimeStart {
            coarsening: c,
            tolerance: 1e-4,
        };
        let (warm, sent) = solve(&sc, Some(start), 1e-12, k0);
        let (e_f, e_w) = error_against_reference(
            &sc.model.interfaces,
            &warm.interface_fields(),
            &cold.interface_fields(),
            &sc.model.time.trapezoid_weights(),
        );
        println!(
            "{name}: {} iterations from ŝ = 0, {} from the coarse start (c = {c}); tractions differ by {e_f:.2e}, jumps by {e_w:.2e}",
            cold.iterations.len(),
            warm.iterations.len()
        );
        assert!(e_f <= 1e-8 && e_w <= 1e-8, "{name}: tractions {e_f:e}, jumps {e_w:e}");
        // One start message per subdomain with an interface, none without the start.
        assert!(none.is_empty(), "{name}");
        let participants: Vec<u32> = (0..sc.model.subdomains.len() as u32)
            .filter(|&s| {
                sc.model
                    .interfaces
                    .iter()
                    .any(|i| i.a == s as usize || i.b == s as usize)
            })
            .collect();
        assert_eq!(sent, participants, "{name}");
        assert!(
            warm.nodes.iter().any(|n| n.contains("time-coarse start")),
            "{name}: {:?}",
            warm.nodes
        );
        // The start is closer to the solution than ŝ = 0: iteration 0's η is smaller.
        let eta0 = |r: &RunResult| r.iterations[0].decision.eta;
        assert!(
            eta0(&warm) < eta0(&cold),
            "{name}: η₀ {} against {}",
            eta0(&warm),
            eta0(&cold)
        );
    }
}

/// The launcher's start messages travel over the bus like every other message: the processes
/// give the in-process run's decisions and fields bit for bit.
#[test]
fn time_coarse_start_processes_match_in_process_bit_for_bit() {
    let text = scene_text("small-three-layer").replace("[solver]", "[solver]\ntime_coarsening = 2");
    let sc = scene(&text);
    assert!(sc.model.solver.time_start.is_some());
    assert!(sc.deployment.subdomain_nodes >= 2);
    let local = Run::new(&sc, &RunOptions::new("local"))
        .in_process()
        .map(|o| o.result)
        .unwrap();
    let remote = Run::new(&sc, &RunOptions::new("time-start-distributed-1"))
        .processes(Path::new(env!("CARGO_BIN_EXE_glissade")), &Network::default())
        .map(|o| o.result)
        .unwrap();
    assert_eq!(local.verdict, Verdict::Converged);
    assert_identical(&local, &remote);
}

/// `glissade report --variants …+start<c>` / `+zero`: one reference, a run from ŝ = 0 and one
/// from a time-coarse start, named as such; a start the scene cannot take is refused.
#[test]
fn report_variants_switch_the_time_coarse_start() {
    use glissade::report::{build_reports, comparison_table, Variant};
    let mut sc = scene(&scene_text("two-blocks"));
    sc.model.solver.max_iterations = 40;
    let n = sc.model.time.n_steps;
    assert_eq!(n % 4, 0);
    let variants: Vec<Variant> = ["condensed+plain+zero", "condensed+plain+start4"]
        .iter()
        .map(|v| v.parse().expect("a variant"))
        .collect();
    let (reports, _) = build_reports(&sc, "report-start", &variants, None).expect("reports");
    let (cold, warm) = (&reports[0], &reports[1]);
    assert_eq!(cold.start, "from ŝ = 0");
    assert_eq!(warm.start, "time-coarse start (c = 4, η ≤ 1e-4)");
    let table = comparison_table(&reports);
    assert!(
        table.contains("| condensed + time-coarse start (c = 4, η ≤ 1e-4) | "),
        "{table}"
    );
    // The start is closer to the reference than ŝ = 0 at the first iteration.
    assert!(
        warm.points[0].traction_error < cold.points[0].traction_error,
        "{} against {}",
        warm.points[0].traction_error,
        cold.points[0].traction_error
    );
    // `+zero` overrides a scene's own start.
    let mut with_start = sc.clone();
    with_start.model.solver.time_start = Some(TimeStart {
        coarsening: 2,
        tolerance: 1e-3,
    });
    let zero: Variant = "condensed+zero".parse().unwrap();
    let z = glissade::report::variant_scene(&with_start, &zero).unwrap();
    assert_eq!(z.model.solver.time_start, None);
    // `+start<c>` keeps the scene's coarse tolerance.
    let s8: Variant = "condensed+start8".parse().unwrap();
    let s = glissade::report::variant_scene(&with_start, &s8).unwrap();
    assert_eq!(
        s.model.solver.time_start,
        Some(TimeStart {
            coarsening: 8,
            tolerance: 1e-3
        })
    );
    for bad in [
        "condensed+start",
        "condensed+start1",
        "condensed+startx",
        "condensed+zero+start4",
        "condensed+plain+anderson",
        "condensed+cold",
    ] {
        assert!(bad.parse::<Variant>().is_err(), "{bad}");
    }
    // Refused before the reference solve: c must divide N, and not with PGD.
    for (v, words) in [
        (
            format!("condensed+start{}", n + 1),
            format!("does not divide the scene's N = {n}"),
        ),
        ("pgd+start4".to_string(), "PGD".to_string()),
    ] {
        let v: Variant = v.parse().unwrap();
        let Err(e) = build_reports(&sc, "bad-start", &[Variant::from(sc.linear_stage), v], None) else {
            panic!("a start the scene cannot take was run");
        };
        let e = e.to_string();
        assert!(e.contains(&words), "{e}");
    }
}
