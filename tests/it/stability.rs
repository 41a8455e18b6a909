//! The quick stability matrix (issue 8, `glissade stability --quick`): no case panics, no
//! interface field, error or indicator is NaN or Inf, and every case ends the way it states:
//! converged to its reference within its tolerances, or stopped or rejected with the named
//! diagnosis. Every case also runs with Anderson acceleration, which must not turn a converging
//! case into a failing one.

use glissade::stability::{cases, markdown, run_matrix, AccelerationEffect, Assessment, Outcome, ERROR_TOLERANCE};
use glissade_mechanics::model::Acceleration;

/// Per case of the quick matrix: the outcome it must end with ([`Outcome::kind`]).
const EXPECTED: [(&str, &str); 27] = [
    ("base", "converged"),
    ("stiffness-ratio-1e6", "converged"),
    // Converges since k₀ follows √(2G·M) (1586 iterations; it crawled with k₀ from E).
    ("nu-0.499", "converged"),
    ("nu-0.5", "rejected"),
    ("friction-0", "converged"),
    ("friction-5", "converged"),
    ("all-slip", "converged"),
    ("pressure-1e-6", "converged"),
    ("pressure-1e6", "converged"),
    ("all-loads-1e6", "converged"),
    ("zero-load", "converged"),
    ("k0-x1e-3", "max_iterations"),
    ("k0-x0.3", "converged"),
    ("k0-x3", "converged"),
    ("k0-x10", "converged"),
    ("k0-x1e3", "max_iterations"),
    ("relaxation-1", "stagnated"),
    ("relaxation-0.3", "converged"),
    // α above 2(1 − μ)/(2 − μ) diverges: rejected at validation.
    ("direction-update-alpha-0.5", "rejected"),
    ("direction-update-alpha-0.5-relaxation-0.6", "converged"),
    ("direction-update-on", "converged"),
    ("direction-update-off", "converged"),
    ("steps-1", "converged"),
    ("gap-open", "converged"),
    ("gap-open-rigid", "converged"),
    ("gap-closing", "converged"),
    ("gap-closing-direction-update", "converged"),
];

#[test]
fn quick_stability_matrix() {
    let rows = run_matrix(true, |_| {});
    println!("{}", markdown(&rows));
    let names: Vec<&str> = rows.iter().map(|r| r.case.as_str()).collect();
    assert_eq!(
        names,
        EXPECTED.map(|e| e.0),
        "the quick matrix changed: update EXPECTED"
    );
    for (row, (name, kind)) in rows.iter().zip(EXPECTED) {
        for (run, how) in [(&row.plain, "plain"), (&row.anderson, "Anderson")] {
            assert!(
                !matches!(run.outcome, Outcome::Panicked { .. }),
                "{name} ({how}) panicked: {:?}",
                run.outcome
            );
            assert!(
                run.fields_finite,
                "{name} ({how}): a field, error or time is not finite"
            );
            assert!(run.indicators_finite, "{name} ({how}): an indicator is not finite");
        }
        assert_eq!(
            row.assessment,
            Assessment::AsExpected,
            "{name}: {:?}",
            row.plain.outcome
        );
        assert_eq!(row.plain.outcome.kind(), kind, "{name}: {:?}", row.plain.outcome);
        if kind == "converged" {
            // Acceleration must not turn a converging case into a failing one. The mixed
            // iteration has the plain one's fixed point (anderson.rs), η is the same indicator,
            // and a mixed step that makes the residual grow is followed by a plain one, so the
            // accelerated run must meet the same η tolerance and reach the same reference within
            // the same traction error bound as the plain run (measured: ≤ 1.6e-5 on every quick
            // case, plain ≤ 3.6e-5; the bound is 1e-4).
            for (run, how) in [(&row.plain, "plain"), (&row.anderson, "Anderson")] {
                assert_eq!(run.outcome, Outcome::Converged, "{name} ({how})");
                assert!(
                    run.eta.is_some_and(|e| e <= row.tolerance.unwrap_or(0.0)),
                    "{name} ({how}): η = {:?}",
                    run.eta
                );
                // Compared with the reference: on tractions, or on jumps where the reference's
                // contact tractions are all zero (every point separated).
                let error = run.traction_error.or(run.jump_error);
                assert!(
                    error.is_some_and(|e| e <= ERROR_TOLERANCE),
                    "{name} ({how}): traction error {:?}, jump error {:?}, {:?}",
                    run.traction_error,
                    run.jump_error,
                    row.reference_note
                );
            }
            assert_eq!(row.acceleration, AccelerationEffect::Kept, "{name}");
            // The accelerated scene does mix: every run of more than two iterations (the
            // first mixed step is at iteration 2) takes mixed steps.
            let steps = row.anderson.anderson_steps.expect("Anderson steps counted");
            let n = row.anderson.iterations.expect("iterations");
            if n > 2 {
                assert!(steps.mixed > 0, "{name}: {steps:?}");
            }
            // One step per iteration from iteration 2 on (iterations 0 and 1 only record), each
            // counted once; every one holds at least one difference (the subdomains send
            // partials from their first difference on, and a restart keeps the last iterate).
            assert_eq!(
                steps.mixed + steps.safeguarded + steps.restarted + steps.unmixed,
                n.saturating_sub(2) as u32,
                "{name}: {steps:?}"
            );
            assert_eq!(steps.unmixed, 0, "{name}: {steps:?}");
        }
        assert_ne!(row.acceleration, AccelerationEffect::Broke, "{name}");
        if kind == "rejected" {
            // Same scene but for the acceleration: rejected for the same reason.
            assert_eq!(row.anderson.outcome, row.plain.outcome, "{name}");
        }
    }
    let row = |name: &str| rows.iter().find(|r| r.case == name).expect("case");
    // The stops name their cause.
    assert!(
        matches!(&row("nu-0.5").plain.outcome, Outcome::Rejected { reason }
            if reason.contains("materials.bottom.nu") && reason.contains("outside (−1, 0.5)")),
        "{:?}",
        row("nu-0.5").plain.outcome
    );
    assert!(
        row("relaxation-1")
            .plain
            .outcome
            .detail()
            .contains("alternates between"),
        "{:?}",
        row("relaxation-1").plain.outcome
    );
    // The cases do what their names say at t = T.
    let counts = |name: &str| row(name).plain.final_counts.expect("counts");
    let all_slip = counts("all-slip");
    assert!(
        all_slip[0] == 0 && all_slip[1] == 0 && all_slip[2] > 0,
        "all-slip: {all_slip:?}"
    );
    let open = counts("gap-open");
    assert!(open[0] > 0 && open[1] == 0 && open[2] == 0, "gap-open: {open:?}");
    let closing = counts("gap-closing");
    assert!(
        closing[0] > 0 && closing[1] + closing[2] > 0,
        "gap-closing: {closing:?}"
    );
    assert_eq!(row("zero-load").plain.iterations, Some(1));
    assert_eq!(row("zero-load").plain.eta, Some(0.0));
    // Scaling every load leaves the iteration unchanged, accelerated or not.
    assert_eq!(row("all-loads-1e6").plain.iterations, row("base").plain.iterations);
    assert_eq!(
        row("all-loads-1e6").anderson.iterations,
        row("base").anderson.iterations
    );
}

/// Every case of the full matrix builds a scene that loads or is meant to be rejected, and the
/// quick matrix is a subset of it.
#[test]
fn full_matrix_scenes_load() {
    let full = cases(false);
    for c in &full {
        for scene in [&c.scene, &c.accelerated] {
            let loaded = glissade_scene::load_str(scene, "case.toml");
            match &c.expect {
                glissade::stability::Expect::Rejected { reason } => {
                    let e = loaded.expect_err(c.name);
                    assert!(e.to_string().contains(reason), "{}: {e}", c.name);
                }
                _ => assert!(loaded.is_ok(), "{}: {:?}", c.name, loaded.err()),
            }
        }
        // The accelerated scene is the case's scene with Anderson acceleration and nothing else.
        let plain = glissade_scene::load_str(&c.scene, "case.toml");
        let accelerated = glissade_scene::load_str(&c.accelerated, "case.toml");
        if let (Ok(p), Ok(a)) = (plain, accelerated) {
            assert_eq!(p.model.solver.acceleration, Acceleration::None, "{}", c.name);
            assert!(
                matches!(a.model.solver.acceleration, Acceleration::Anderson { .. }),
                "{}",
                c.name
            );
            let mut a = a.model.solver.clone();
            a.acceleration = Acceleration::None;
            assert_eq!(a, p.model.solver, "{}", c.name);
        }
    }
    for q in cases(true) {
        assert!(
            full.iter().any(|c| c.name == q.name && c.scene == q.scene),
            "{}",
            q.name
        );
    }
}

/// The stop on accuracy on every converging quick case (docs/accuracy.md,
/// "Stopping on accuracy"): where the default solver's estimate first reaches 1e-2, 1e-3 and 1e-4, the true
/// contact-traction error against the reference is at most the accuracy in at least 95 % of the
/// stops and never above 3× it (the bar). A case whose reference or run fails is a
/// failure here, not a skipped row; the two gap-open cases, whose reference has no contact force
/// at all (a relative traction error is undefined), have no true error to compare. The counts
/// measured on the whole matrix are in docs/accuracy.md.
#[test]
fn quick_cases_stop_within_the_requested_accuracy() {
    use glissade::accuracy::{check_cases, summary};
    let results = check_cases(&cases(true), |_| {});
    let failures: Vec<&String> = results.iter().filter_map(|r| r.as_ref().err()).collect();
    assert!(failures.is_empty(), "{failures:?}");
    let checks: Vec<_> = results.into_iter().map(Result::unwrap).collect();
    println!("{}", glissade::accuracy::markdown(&checks));
    println!("{}", summary(&checks));
    let ratios: Vec<(String, f64, f64)> = checks
        .iter()
        .flat_map(|c| {
            c.stops
                .iter()
                .filter_map(|s| s.ratio().map(|r| (c.name.clone(), s.accuracy, r)))
        })
        .collect();
    assert!(ratios.len() >= 54, "too few stops to judge: {ratios:?}");
    let within = ratios.iter().filter(|r| r.2 <= 1.0).count() as f64 / ratios.len() as f64;
    assert!(within >= 0.95, "{within} of the stops within the accuracy: {ratios:?}");
    let worst = ratios.iter().max_by(|a, b| a.2.total_cmp(&b.2)).expect("stops");
    assert!(worst.2 <= 3.0, "{worst:?}");
    // Sharpness: the estimate within 3× of the true error over the iterations below 1e-2. The
    // calibrated estimate gave 22 % here (2026-11-27), the bound alone 10 % (the same cases with
    // the calibration turned off): 15 % fails if the calibration stops taking effect.
    let compared: usize = checks.iter().map(|c| c.compared).sum();
    let sharp = checks.iter().map(|c| c.within_3x * c.compared as f64).sum::<f64>() / compared as f64;
    assert!(
        sharp >= 0.15,
        "the estimate within 3× of the true error in {sharp:.2} of {compared} iterations"
    );
}
