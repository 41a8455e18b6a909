//! `glissade reference` and `glissade report` when the reference does not converge at a time
//! step: exit 3 (not 2, which is bad input), the error names the step and every attempt tried,
//! with a hint; what was solved is written and marked as partial, and the report keeps the LATIN
//! run.

use std::path::Path;
use std::process::Command;

/// The laminate without pressure of the reference crate's fixtures: its step 1 needs a few hundred
/// Newton iterations, so `--newton-iterations 2` (2 per attempt, 40 for the non-monotone one)
/// makes the reference fail there.
fn scene() -> String {
    format!(
        "{}/nodes/reference/tests/fixtures/laminate-no-pressure.toml",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn glissade(args: &[&str], out: &Path) -> (Option<i32>, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("spawn glissade");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

fn assert_failure_reported(stderr: &str, out: &Path) {
    for part in [
        "error: reference: time step 1 (t = 0.02): Newton did not converge in 50 iterations",
        "tried: r factor 1, monotone line search, 2 iterations",
        "r factor 1, non-monotone line search over 30 iterates, 40 iterations",
        "r factor 100, monotone line search, 2 iterations",
        "hint: ",
        "--newton-iterations",
        "reference: 1 of 51 time points solved",
        "(PARTIAL)",
    ] {
        assert!(stderr.contains(part), "`{part}` not in stderr:\n{stderr}");
    }
    let partial = out.join("laminate-no-pressure-reference-partial.fields.json");
    let fields: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&partial).expect("partial fields")).expect("json");
    assert_eq!(fields["times"], serde_json::json!([0.0]));
}

#[test]
fn a_reference_that_fails_exits_3_and_writes_the_steps_solved() {
    let dir = crate::common::scratch("reference-fails");
    let out = dir.join("out");
    let (code, _, stderr) = glissade(&["reference", &scene(), "--newton-iterations", "2"], &out);
    assert_eq!(code, Some(3), "{stderr}");
    assert_failure_reported(&stderr, &out);
    assert!(!out.join("laminate-no-pressure-reference.fields.json").exists());
}

#[test]
fn a_report_whose_reference_fails_keeps_the_latin_run_and_exits_3() {
    let dir = crate::common::scratch("report-reference-fails");
    let out = dir.join("out");
    let (code, stdout, stderr) = glissade(
        &["report", &scene(), "--newton-iterations", "2", "--max-iterations", "3"],
        &out,
    );
    assert_eq!(code, Some(3), "{stdout}\n{stderr}");
    assert_failure_reported(&stderr, &out);
    assert!(
        stdout.contains("reference") && stdout.contains("FAILED after 1 of 51 time points"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("laminate-no-pressure-report.json")).expect("report"))
            .expect("json");
    assert_eq!(report["reference_steps_solved"], 1);
    let failure = report["reference_failure"].as_str().expect("reference_failure");
    assert!(failure.starts_with("time step 1 (t = 0.02)"), "{failure}");
    let points = report["points"].as_array().expect("points");
    assert_eq!(points.len(), 3);
    // One time point solved (t = 0, no load): nothing to compare.
    assert_eq!(report["errors_over_time_points"], 0);
    for p in points {
        assert!(p["traction_error"].is_null() && p["jump_error"].is_null(), "{p}");
        assert!(p["eta"].as_f64().is_some_and(|e| e > 0.0), "{p}");
    }
    assert!(out.join("laminate-no-pressure-report.svg").exists());
}

/// A reference that solves some time points and then fails: the report compares LATIN with it
/// over those. Held-out seed 65 of the validation set: a shrink fit (interference 3.9e-3 mm,
/// f = 0.25) whose outer ring is twisted by a shear rising to 1.64 MPa, more than the fit's
/// friction holds: the reference solves 23 of the 106 time points and refuses the 24th
/// (displacements of 6.6e5 mm: the ring slides away as a whole).
#[test]
fn a_report_compares_over_the_time_points_a_failed_reference_solved() {
    let dir = crate::common::scratch("report-reference-partial");
    let g = glissade::validate::generate(65);
    assert_eq!(g.family, "shrink-fit");
    for (name, text) in glissade::validate::MESHES {
        std::fs::write(dir.join(name), text).unwrap();
    }
    let scene = dir.join("seed-65.toml");
    std::fs::write(&scene, &g.toml).unwrap();
    let out = dir.join("out");
    let (code, stdout, stderr) = glissade(&["report", &scene.to_string_lossy(), "--max-iterations", "30"], &out);
    assert_eq!(code, Some(3), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("ERRORS OVER THE FIRST 23 OF 106 TIME POINTS ONLY")
            && stdout.contains("FAILED after 23 of 106 time points; the errors are over those 23 time points only"),
        "{stdout}"
    );
    assert!(stderr.contains("slides away as a whole"), "{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("validation-0065-report.json")).expect("report"))
            .expect("json");
    assert_eq!(report["reference_steps_solved"], 23);
    assert_eq!(report["errors_over_time_points"], 23);
    let points = report["points"].as_array().expect("points");
    assert_eq!(points.len(), 30);
    // Errors over the points solved: finite, and falling as LATIN converges there (release
    // build: 1e-2 reached at iteration 25, 9.1e-3 the best of 30).
    let errors: Vec<f64> = points
        .iter()
        .map(|p| p["traction_error"].as_f64().expect("a traction error"))
        .collect();
    assert!(errors.iter().all(|e| e.is_finite()), "{errors:?}");
    assert!(errors[29] < 0.1 * errors[0] && errors[29] < 2e-2, "{errors:?}");
}
