//! The quick stability matrix (issue 8, `glissade stability --quick`): no case panics, no
//! interface field, error or indicator is NaN or Inf, and every case ends the way it states:
//! converged to its reference within its tolerances, or stopped or rejected with the named
//! diagnosis.

use glissade::stability::{cases, markdown, run_matrix, Assessment, Outcome, ERROR_TOLERANCE};

/// Per case of the quick matrix: the outcome it must end with ([`Outcome::kind`]) and, for a
/// case with a known issue (see its `known` text in `launch/stability.rs`), the outcome it ends
/// with until the fix is in.
const EXPECTED: [(&str, &str, Option<&str>); 26] = [
    ("base", "converged", None),
    ("stiffness-ratio-1e6", "converged", None),
    // k₀ ignores ν.
    ("nu-0.499", "converged", Some("max_iterations")),
    ("nu-0.5", "rejected", None),
    ("friction-0", "converged", None),
    ("friction-5", "converged", None),
    ("all-slip", "converged", None),
    ("pressure-1e-6", "converged", None),
    ("pressure-1e6", "converged", None),
    ("all-loads-1e6", "converged", None),
    ("zero-load", "converged", None),
    ("k0-x1e-3", "max_iterations", None),
    ("k0-x0.3", "converged", None),
    ("k0-x3", "converged", None),
    ("k0-x10", "converged", None),
    ("k0-x1e3", "max_iterations", None),
    ("relaxation-1", "stagnated", None),
    ("relaxation-0.3", "converged", None),
    // α beyond the stability limit 2(1 − μ)/(2 − μ) is not rejected yet.
    ("direction-update-alpha-0.5", "rejected", Some("diverged")),
    ("direction-update-on", "converged", None),
    ("direction-update-off", "converged", None),
    ("steps-1", "converged", None),
    // e_F = ∞ when every contact point is separated.
    ("gap-open", "converged", Some("diverged")),
    ("gap-open-rigid", "converged", Some("diverged")),
    ("gap-closing", "converged", None),
    ("gap-closing-direction-update", "converged", None),
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
    for (row, (name, kind, known)) in rows.iter().zip(EXPECTED) {
        assert!(
            !matches!(row.outcome, Outcome::Panicked { .. }),
            "{name} panicked: {:?}",
            row.outcome
        );
        assert!(row.fields_finite, "{name}: a field, error or time is not finite");
        if row.assessment == Assessment::KnownIssue {
            assert_eq!(Some(row.outcome.kind()), known, "{name}: {:?}", row.outcome);
            // The only non-finite value allowed is the known e_c = ∞ of an all-separated
            // interface, which the stop rule reports as divergence at iteration 0.
            if !row.indicators_finite {
                assert!(
                    row.outcome.detail().contains("indicator is not finite") && row.iterations == Some(1),
                    "{name}: {:?}",
                    row.outcome
                );
            }
            continue;
        }
        assert!(row.indicators_finite, "{name}: an indicator is not finite");
        assert_eq!(row.assessment, Assessment::AsExpected, "{name}: {:?}", row.outcome);
        assert_eq!(row.outcome.kind(), kind, "{name}: {:?}", row.outcome);
        if kind == "converged" {
            assert!(row.eta.is_some_and(|e| e <= row.tolerance.unwrap_or(0.0)), "{name}");
            // Compared with the reference: on tractions, or on jumps where the reference's
            // contact tractions are all zero (every point separated); gap-open-rigid has no
            // reference (zero force scale, see the report).
            let error = row.traction_error.or(row.jump_error);
            assert!(
                error.is_some_and(|e| e <= ERROR_TOLERANCE) || name == "gap-open-rigid",
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
        row("relaxation-1").outcome.detail().contains("min η over the last"),
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
            glissade::stability::Expect::Rejected { reason } if c.known.is_none() => {
                let e = loaded.expect_err(c.name);
                assert!(e.to_string().contains(reason), "{}: {e}", c.name);
            }
            glissade::stability::Expect::Rejected { .. } => {}
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
