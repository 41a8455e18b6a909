//! The quick stability matrix (issue 8, `glissade stability --quick`): no case panics, no
//! interface field, error or indicator is NaN or Inf, and every case ends the way it states:
//! converged to its reference within its tolerances, or stopped or rejected with the named
//! diagnosis.

use glissade::stability::{cases, markdown, run_matrix, Assessment, Outcome, ERROR_TOLERANCE};

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
        assert!(
            !matches!(row.outcome, Outcome::Panicked { .. }),
            "{name} panicked: {:?}",
            row.outcome
        );
        assert!(row.fields_finite, "{name}: a field, error or time is not finite");
        assert!(row.indicators_finite, "{name}: an indicator is not finite");
        assert_eq!(row.assessment, Assessment::AsExpected, "{name}: {:?}", row.outcome);
        assert_eq!(row.outcome.kind(), kind, "{name}: {:?}", row.outcome);
        if kind == "converged" {
            assert!(row.eta.is_some_and(|e| e <= row.tolerance.unwrap_or(0.0)), "{name}");
            // Compared with the reference: on tractions, or on jumps where the reference's
            // contact tractions are all zero (every point separated).
            let error = row.traction_error.or(row.jump_error);
            assert!(
                error.is_some_and(|e| e <= ERROR_TOLERANCE),
                "{name}: traction error {:?}, jump error {:?}, {:?}",
                row.traction_error,
                row.jump_error,
                row.reference_note
            );
        }
    }
    let row = |name: &str| rows.iter().find(|r| r.case == name).expect("case");
    // The stops name their cause.
    assert!(
        matches!(&row("nu-0.5").outcome, Outcome::Rejected { reason }
            if reason.contains("materials.bottom.nu") && reason.contains("outside (−1, 0.5)")),
        "{:?}",
        row("nu-0.5").outcome
    );
    assert!(
        row("relaxation-1").outcome.detail().contains("alternates between"),
        "{:?}",
        row("relaxation-1").outcome
    );
    // The cases do what their names say at t = T.
    let counts = |name: &str| row(name).final_counts.expect("counts");
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
    assert_eq!(row("zero-load").iterations, Some(1));
    assert_eq!(row("zero-load").eta, Some(0.0));
    // Scaling every load leaves the iteration unchanged.
    assert_eq!(row("all-loads-1e6").iterations, row("base").iterations);
}

/// Every case of the full matrix builds a scene that loads or is meant to be rejected, and the
/// quick matrix is a subset of it.
#[test]
fn full_matrix_scenes_load() {
    let full = cases(false);
    for c in &full {
        let loaded = glissade_mechanics::scene::load_str(&c.scene, "case.toml");
        match &c.expect {
            glissade::stability::Expect::Rejected { reason } => {
                let e = loaded.expect_err(c.name);
                assert!(e.to_string().contains(reason), "{}: {e}", c.name);
            }
            _ => assert!(loaded.is_ok(), "{}: {:?}", c.name, loaded.err()),
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
