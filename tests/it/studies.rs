//! Design studies (docs/studies.md): `glissade sweep` end to end, warm-started against cold.

use crate::common::{glissade_exits, glissade_ok, scratch};
use std::process::Command;

/// Lamé's contact pressure of shrink-fit.toml at an interference of 0.010 mm (the scene's
/// closed form, plane strain); linear in the interference.
const LAME_PRESSURE_AT_0_01: f64 = 27.25;

fn read_json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The shipped interference study (5 variants): warm and cold runs both converge every variant,
/// give the contact pressure of Lamé's closed form within 0.5 % (the bound; measured
/// 0.01 %: the mesh's discretisation error), agree with each other within 1e-3 of the pressure
/// and of the tangential resultant (each run is within its accuracy 1e-4 of the fixed point, and
/// the estimate is checked to within a few times on the validation set), and the warm study takes
/// fewer iterations in all: each warm variant starts from the one before (a snake through the
/// list), operators reused.
#[test]
fn a_warm_started_study_agrees_with_cold_runs_in_fewer_iterations() {
    let dir = scratch("study-interference");
    let study = format!(
        "{}/launch/studies/shrink-fit-interference.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let warm_out = glissade_ok(&[&"sweep", &study, &"--out", &dir.0]);
    let cold_out = glissade_ok(&[&"sweep", &study, &"--cold", &"--out", &dir.0]);
    assert!(warm_out.contains("5 variants (warm"), "{warm_out}");
    assert!(cold_out.contains("5 variants (cold"), "{cold_out}");
    let warm = read_json(&dir.0.join("shrink-fit-interference.json"));
    let cold = read_json(&dir.0.join("shrink-fit-interference-cold.json"));
    let (wv, cv) = (
        warm["variants"].as_array().unwrap(),
        cold["variants"].as_array().unwrap(),
    );
    assert_eq!((wv.len(), cv.len()), (5, 5));
    let last = |v: &serde_json::Value, q: &str| {
        let series = v["interfaces"][0][q].as_array().unwrap();
        series.last().unwrap().as_f64().unwrap()
    };
    let (mut warm_iterations, mut cold_iterations) = (0, 0);
    for (k, (w, c)) in wv.iter().zip(cv).enumerate() {
        assert_eq!(w["converged"], true, "{w}");
        assert_eq!(c["converged"], true, "{c}");
        assert_eq!(c["started_from"], serde_json::Value::Null);
        if k > 0 {
            assert_eq!(w["started_from"], k - 1, "variant {k}");
            assert!(w["operators"].as_str().unwrap().starts_with("reused for all 2"), "{w}");
        }
        let gap = w["values"]["gap"].as_f64().unwrap();
        assert_eq!(gap, c["values"]["gap"].as_f64().unwrap());
        let lame = LAME_PRESSURE_AT_0_01 * (-gap / 0.01);
        let (pw, pc) = (last(w, "mean_pressure"), last(c, "mean_pressure"));
        assert!(
            (pw - lame).abs() <= 5e-3 * lame,
            "variant {k}: {pw} MPa against Lamé's {lame}"
        );
        assert!((pw - pc).abs() <= 1e-3 * lame, "variant {k}: warm {pw}, cold {pc}");
        let (tw, tc) = (last(w, "tangential"), last(c, "tangential"));
        assert!((tw - tc).abs() <= 1e-3 * tc.abs(), "variant {k}: warm {tw}, cold {tc}");
        warm_iterations += w["iterations"].as_u64().unwrap();
        cold_iterations += c["iterations"].as_u64().unwrap();
    }
    assert!(
        warm_iterations < cold_iterations,
        "warm {warm_iterations} iterations, cold {cold_iterations}"
    );
    // One CSV row per variant, time point (N = 10) and contact interface, units in the header.
    let csv = std::fs::read_to_string(dir.0.join("shrink-fit-interference.csv")).unwrap();
    let mut lines = csv.lines();
    let header = lines.next().unwrap();
    assert!(
        header.starts_with("variant,gap,verdict,iterations,started_from,time_s,interface,a,b,normal_N_per_mm,"),
        "{header}"
    );
    assert!(header.ends_with("max_slip_mm,dissipation_N"), "{header}");
    assert_eq!(lines.count(), 5 * 11);
    for q in [
        "mean_pressure",
        "max_pressure",
        "tangential",
        "slip_share",
        "iterations",
    ] {
        let svg = std::fs::read_to_string(dir.0.join(format!("shrink-fit-interference-{q}-vs-gap.svg"))).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>") && !svg.contains("NaN"),
            "{q}"
        );
        assert_eq!(svg.matches("<circle").count(), 5, "{q}: one marker per variant");
    }
    // A second study into the same folder overwrites nothing: refused before it solves.
    let err = glissade_exits(2, &[&"sweep", &study, &"--out", &dir.0]);
    assert!(err.contains("shrink-fit-interference.csv"), "{err}");
    assert!(!err.contains("[1/5]"), "{err}");
}

/// A study's mistakes are named with where they are, before anything is solved or written.
#[test]
fn bad_studies_are_refused_with_the_place_of_the_mistake() {
    let dir = scratch("study-bad");
    let scene = format!("{}/launch/scenes/shrink-fit.toml", env!("CARGO_MANIFEST_DIR"));
    let refuse = |args: &[&str], expected: &str| {
        let mut all: Vec<&dyn AsRef<std::ffi::OsStr>> = vec![&"sweep"];
        all.extend(args.iter().map(|a| a as &dyn AsRef<std::ffi::OsStr>));
        all.extend([&"--out" as &dyn AsRef<std::ffi::OsStr>, &dir.0]);
        let err = glissade_exits(2, &all);
        assert!(err.contains(expected), "{args:?}: {err}");
    };
    refuse(
        &[&scene, "--vary", "friction=-0.1,0.2"],
        "--vary friction=-0.1,0.2: -0.1 is negative",
    );
    refuse(&[&scene, "--vary", "friction"], "expected `name=from:to:count`");
    refuse(&[&scene, "--vary", "boundary[7].scale=1,2"], "2 boundary rule(s)");
    refuse(&[&scene, "--vary", "materials.brass.E=1e5"], "no material `brass`");
    refuse(
        &[&scene, "--vary", "torque=1,2"],
        "`torque` is not a parameter that can vary",
    );
    let study = dir.0.join("s.toml");
    std::fs::write(
        &study,
        "scene = \"missing.toml\"\n[[vary]]\nparameter = \"gap\"\nvalues = [0]\n",
    )
    .unwrap();
    refuse(&[study.to_str().unwrap()], "missing.toml");
    std::fs::write(
        &study,
        "scene = \"x.toml\"\n[[vary]]\nparameter = \"gap\"\nrange = \"0:1\"\n",
    )
    .unwrap();
    refuse(&[study.to_str().unwrap()], "s.toml: vary[0].range");
    assert_eq!(
        std::fs::read_dir(&dir.0).unwrap().count(),
        1,
        "nothing written but the study file"
    );
}

/// `glissade onset` on the shrink fit's twist (shear 1.5·t MPa on the outside, rule 1): the
/// outer ring slips as a whole, and has no equilibrium beyond, at the closed form f·p·b²/c² =
/// 1.962 MPa (Lamé's pressure 27.25 MPa, f = 0.2, b = 30, c = 50), a factor 1.962/1.5 = 1.308 on
/// the rule. The search brackets that factor to the 1 % asked (the bound; measured: the
/// bracket's middle within 0.05 % of it), finds the first slip at a point no later (the pressure
/// along the fit is uniform to the mesh, so the pairs go within 1 % of each other), names the
/// first time point beyond capacity in the trials (t = 0.7 at a factor of 2: 2.1 > 1.962 MPa
/// there, 1.8 at t = 0.6), and warm-starts each trial from the last that held.
#[test]
fn the_onset_of_slip_of_the_shrink_fit_is_the_closed_form() {
    let dir = scratch("onset");
    let scene = format!("{}/launch/scenes/shrink-fit.toml", env!("CARGO_MANIFEST_DIR"));
    let out = glissade_ok(&[&"onset", &scene, &"--rule", &"1", &"--out", &dir.0]);
    assert!(out.contains("slip over a whole interface"), "{out}");
    let r = read_json(&dir.0.join("shrink-fit-onset.json"));
    let closed = 1.962 / 1.5;
    let (lo, hi) = (
        r["full_slip"]["below"].as_f64().unwrap(),
        r["full_slip"]["above"].as_f64().unwrap(),
    );
    assert!(lo < hi && hi - lo <= 1e-2 * hi, "[{lo}, {hi}]");
    let middle = 0.5 * (lo + hi);
    assert!(
        (middle - closed).abs() <= 1e-2 * closed,
        "full slip at {middle}, closed form {closed}"
    );
    let first = r["first_slip"]["above"].as_f64().unwrap();
    assert!(
        first <= hi && first >= 0.99 * lo,
        "first slip {first}, full slip [{lo}, {hi}]"
    );
    let trials = r["trials"].as_array().unwrap();
    let at_two = trials
        .iter()
        .find(|t| t["scale"] == 2.0)
        .expect("the bracket grows to 2");
    assert_eq!(at_two["full_slip_at"].as_f64(), Some(0.7), "{at_two}");
    assert_eq!(at_two["converged"], false);
    // Every trial after the first held one starts from a trial that held.
    for t in trials.iter().skip(1) {
        let from = t["started_from"].as_u64().expect("warm-started") as usize;
        let source = &trials[from];
        assert!(
            source["converged"] == true && source["full_slip_at"].is_null(),
            "{t} from {source}"
        );
    }
}

/// Measurement (docs/studies.md, "What warm starts gain"): the 32-variant study of the stratified
/// scene at N = 100, warm-started, and three of its variants (the first, one in the middle, the
/// last: friction 0.15, 0.2 and 0.3) against the reference Newton solve of their own scene: the
/// contact-force error e_F of each variant's written fields within its accuracy 1e-3. About 3
/// minutes: `cargo test --test integration -- --ignored warm_started_variants_against_the_reference --nocapture`.
#[test]
#[ignore]
fn warm_started_variants_against_the_reference() {
    use glissade::study::PipelineSolver;
    use glissade_bus::convert::mat_of;
    use glissade_mechanics::local::{error_against_reference, InterfaceFields};
    use glissade_studies::study::Study;
    let dir = scratch("study-reference");
    let scene = dir.0.join("strat100.toml");
    std::fs::write(
        &scene,
        crate::common::scene_text("stratified").replace("N = 1000", "N = 100"),
    )
    .unwrap();
    let study = Study::from_vary(
        &scene,
        &["friction=0.15:0.3:4".into(), "boundary[3].scale=0.6:1.3:8".into()],
        None,
    )
    .unwrap();
    let text = std::fs::read_to_string(&scene).unwrap();
    let mut solver = PipelineSolver::new(None);
    let run = glissade_studies::driver::run(&study, &text, &mut solver, false, |_| {}).unwrap();
    assert!(run.outcomes.iter().all(|o| o.converged()));
    for k in [0, 15, 31] {
        let o = &run.outcomes[k];
        let (solved, _) = o.result.as_ref().unwrap();
        let variant_text = glissade_studies::patch::variant_text(&study, &text, &o.variant).unwrap();
        let sc = glissade_scene::load_str(&variant_text, scene.to_str().unwrap()).unwrap();
        let reference = glissade_reference::solve_reference(&sc.model, &Default::default()).expect("reference");
        let fields: Vec<InterfaceFields> = solved
            .interfaces
            .iter()
            .map(|s| InterfaceFields {
                w_a: mat_of(&s.w_a),
                w_b: mat_of(&s.w_b),
                f_a: mat_of(&s.f_a),
                f_b: mat_of(&s.f_b),
            })
            .collect();
        let w = sc.model.time.trapezoid_weights();
        let (e_f, e_w) = error_against_reference(&sc.model.interfaces, &fields, &reference.interfaces, &w);
        println!(
            "variant {k} {:?}: {} iterations from {:?}, e_F = {e_f:.2e}, e_W = {e_w:.2e}",
            o.variant.values, solved.iterations, o.started_from
        );
        assert!(e_f <= 1e-3, "variant {k}: e_F = {e_f}");
    }
}

/// A variant that does not converge does not stop the study: the shrink fit at interferences of
/// 0.005 mm (the twist beyond what friction holds there: the run stagnates) and 0.010 mm. The
/// study ends with exit status 3, both variants reported with their verdicts, the second
/// started cold (no converged variant to start from). With `--record`, each variant's recording
/// is written and replays like a run's.
#[test]
fn a_failed_variant_is_reported_and_the_study_goes_on() {
    let dir = scratch("study-failed-variant");
    let scene = format!("{}/launch/scenes/shrink-fit.toml", env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["sweep", &scene, "--vary", "gap=-0.005,-0.01", "--record", "--out"])
        .arg(&dir.0)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(3), "{stdout}{stderr}");
    let json = read_json(&dir.0.join("shrink-fit-sweep.json"));
    let v = json["variants"].as_array().unwrap();
    assert_eq!(v.len(), 2);
    assert_eq!(v[0]["converged"], false, "{}", v[0]);
    assert!(
        v[0]["verdict"].as_str().unwrap().starts_with("NOT converged"),
        "{}",
        v[0]
    );
    assert_eq!(
        (v[1]["converged"].clone(), v[1]["started_from"].clone()),
        (true.into(), serde_json::Value::Null)
    );
    assert!(
        stdout.contains("2 variants (warm") && stdout.contains("1 converged"),
        "{stdout}"
    );
    for k in 0..2 {
        let mcap = dir.0.join(format!("shrink-fit-sweep-v{k}.mcap"));
        assert!(mcap.is_file(), "{}", mcap.display());
        let rrd = dir.0.join(format!("v{k}.rrd"));
        glissade_ok(&[&"replay", &"--save", &rrd, &mcap]);
        assert!(std::fs::metadata(&rrd).unwrap().len() > 1000);
    }
}
