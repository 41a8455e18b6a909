//! Anderson acceleration of the LATIN fixed point (docs/method.md, "Relaxation and Anderson mixing"): the same limit as
//! plain relaxation, the reduction's messages only when it is on, and the multi-process run
//! bit-identical to the in-process one with it on.

use crate::common::{scene, scene_text};
use crate::distributed::assert_identical;
use glissade::distributed::Network;
use glissade::run::Run;
use glissade::runner::{RunOptions, RunResult};
use glissade_mechanics::local::error_against_reference;
use glissade_mechanics::model::Acceleration;
use glissade_messages::{Payload, Verdict};
use glissade_scene::LoadedScene;
use std::path::Path;
use std::time::Duration;

/// Runs `sc` with `acceleration` to η ≤ `tolerance` (no stagnation stop); returns the result and
/// the number of Anderson partials and steps seen on the bus.
fn solve(sc: &LoadedScene, acceleration: Acceleration, tolerance: f64, k0_factor: f64) -> (RunResult, usize, usize) {
    let mut sc = sc.clone();
    sc.model.solver.acceleration = acceleration;
    (sc.model.solver.accuracy, sc.model.solver.tolerance) = (None, Some(tolerance));
    sc.model.solver.k0_factor = k0_factor;
    sc.model.solver.max_iterations = 20_000;
    sc.model.solver.stagnation_window = 20_000;
    let (mut grams, mut steps) = (0, 0);
    let result = Run::new(&sc, &RunOptions::new("acceleration"))
        .observe(|m| {
            match m.payload {
                Payload::AndersonGram { .. } => grams += 1,
                Payload::AndersonStep { .. } => steps += 1,
                _ => {}
            }
            Duration::ZERO
        })
        .in_process()
        .map(|o| o.result)
        .expect("run");
    assert_eq!(
        result.verdict,
        Verdict::Converged,
        "{acceleration:?}: {:?}",
        result.iterations.last().map(|r| &r.decision)
    );
    (result, grams, steps)
}

/// s of every interface at the stop.
/// Both runs stop at η ≤ 1e-12 (which is ≤ 1e-10), and the contact tractions of the Anderson run
/// must be within 1e-8 of the plain run's, relative, in the space-time norm of the error against
/// a reference (forces of cross-point copies summed: only their sum is determined; individual
/// copies differ by percents between the runs on the three-layer scene). Why 1e-12: measured on
/// hertz-slip, plain LATIN stopped at η ≤ 1e-10 is itself 1.5e-8 (space-time) and 5e-8 (max) from
/// its limit (η underestimates the traction error), so two runs at 1e-10 may differ by a few 1e-8
/// whatever the acceleration; at 1e-12 each is within about 2e-10 of the limit. The k₀ factors
/// are those of the monolithic comparison (tests/it/monolithic.rs).
#[test]
fn anderson_reaches_the_plain_limit() {
    for (name, k0) in [("two-blocks", 3.0), ("hertz-slip", 10.0), ("small-three-layer", 1.0)] {
        let sc = scene(&scene_text(name));
        let (plain, plain_grams, plain_steps) = solve(&sc, Acceleration::None, 1e-12, k0);
        let (mixed, grams, steps) = solve(&sc, Acceleration::Anderson { window: 5 }, 1e-12, k0);
        let weights = sc.model.time.trapezoid_weights();
        let (e_f, e_w) = error_against_reference(
            &sc.model.interfaces,
            &mixed.interface_fields(),
            &plain.interface_fields(),
            &weights,
        );
        println!(
            "{name}: {} iterations plain, {} with Anderson (m = 5); contact tractions differ by {e_f:.2e}, jumps by {e_w:.2e}",
            plain.iterations.len(),
            mixed.iterations.len()
        );
        assert!(sc.model.interfaces.iter().any(|i| i.is_contact()), "{name}");
        assert!(e_f <= 1e-8 && e_w <= 1e-8, "{name}: tractions {e_f:e}, jumps {e_w:e}");
        assert!(mixed.iterations.len() < plain.iterations.len(), "{name}");
        // No reduction messages when acceleration is off; with it, one partials message per
        // subdomain and one step per iteration from iteration 2 on.
        assert_eq!((plain_grams, plain_steps), (0, 0), "{name}");
        let participants = (0..sc.model.subdomains.len())
            .filter(|&s| sc.model.interfaces.iter().any(|i| i.a == s || i.b == s))
            .count();
        assert_eq!(
            steps,
            mixed.iterations.len() - 2,
            "{name}: one step per iteration from 2 on"
        );
        assert_eq!(grams, steps * participants, "{name}");
    }
}

#[test]
fn processes_match_in_process_bit_for_bit_with_anderson() {
    let text = scene_text("small-three-layer").replace("[solver]", "[solver]\nacceleration = \"anderson\"");
    let sc = scene(&text);
    assert!(matches!(sc.model.solver.acceleration, Acceleration::Anderson { .. }));
    assert!(sc.deployment.subdomain_nodes >= 2);
    let local = Run::new(&sc, &RunOptions::new("local"))
        .linear_stages()
        .in_process()
        .unwrap();
    let remote = Run::new(&sc, &RunOptions::new("acceleration-distributed-1"))
        .linear_stages()
        .processes(Path::new(env!("CARGO_BIN_EXE_glissade")), &Network::default())
        .unwrap();
    // The linear stages' counters as processes are the in-process ones (untimed), one per
    // subdomain and iteration: the launcher keeps every subdomain's `linear_stage_stats` once.
    let counters = |o: &glissade::run::Outcome| -> Vec<(u32, u32, u64)> {
        o.linear_stages
            .iter()
            .map(|r| (r.iteration, r.subdomain, r.flops))
            .collect()
    };
    assert_eq!(
        local.linear_stages.len(),
        sc.model.subdomains.len() * local.result.iterations.len()
    );
    assert_eq!(counters(&local), counters(&remote));
    assert!(local.linear_stages.iter().all(|r| r.seconds > 0.0 && r.flops > 0));
    assert!(remote.linear_stages.iter().all(|r| r.seconds == 0.0));
    let (local, remote) = (local.result, remote.result);
    println!(
        "Anderson: in-process {} iterations, processes {} iterations",
        local.iterations.len(),
        remote.iterations.len()
    );
    assert_eq!(local.verdict, Verdict::Converged);
    assert_identical(&local, &remote);
}
