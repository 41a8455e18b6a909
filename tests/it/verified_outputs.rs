//! What a run writes is the state its verdict judged, and a "Converged" run writes the answer.
//!
//! The outputs (fields.json, the CSV, the VTU interfaces, the recording's final solutions) hold
//! s, the last linear stage's interface state: the state whose forces the estimate follows and
//! which the verdict requires to agree with ŝ (the interface laws) within the accuracy.

use crate::common::scene;
use glissade::output::{interface_csv, interface_fields, pair_values, solution_of_fields};
use glissade::run::Run;
use glissade::runner::{RunOptions, RunResult};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::default_k0;
use glissade_mechanics::local::{pointwise_traction_error, InterfaceFields};
use glissade_messages::{InterfaceSolution, Verdict};
use glissade_reference::solve_reference;
use glissade_scene::{load_str, LoadedScene};
use std::time::Duration;

fn fixture(name: &str) -> LoadedScene {
    let path = format!("{}/tests/fixtures/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    load_str(&std::fs::read_to_string(&path).expect("fixture"), &path).expect("fixture scene")
}

/// Every shipped scene.
const SHIPPED: [&str; 11] = [
    "two-blocks",
    "small-three-layer",
    "hertz-slip",
    "wedge",
    "shrink-fit",
    "shrink-fit-twist",
    "sheath",
    "sheath-cuts",
    "layered",
    "stratified",
    "stratified-gmsh",
];

/// A shipped scene with its time steps set to `n` (the property checked does not depend on N;
/// the paper's N = 1000 would only make the debug test slow).
fn shipped(name: &str, n: Option<usize>) -> LoadedScene {
    let path = format!("{}/launch/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let mut text = std::fs::read_to_string(&path).expect("scene file");
    if let Some(n) = n {
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with("N = "))
            .expect("the scene sets N")
            .to_string();
        text = text.replacen(&line, &format!("N = {n}"), 1);
    }
    load_str(&text, &path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Runs `sc` in process and keeps the last complete interface state the subdomains sent (the s
/// the last local stage and the verdict judged), assembled from their boundary-state messages.
fn run_keeping_last_state(sc: &LoadedScene) -> (RunResult, Vec<InterfaceFields>) {
    let model = &sc.model;
    let k0 = default_k0(model);
    let layouts: Vec<BoundaryLayout> = (0..model.subdomains.len())
        .map(|s| BoundaryLayout::new(model, s, &k0))
        .collect();
    let nt = model.time.n_points();
    let mut fields: Vec<InterfaceFields> = model
        .interfaces
        .iter()
        .map(|i| InterfaceFields::zeros(i.n_pairs(), nt))
        .collect();
    let mut states = glissade_replay::BoundaryStates::new(model);
    let outcome = Run::new(sc, &RunOptions::new("verified"))
        .observe(|m| {
            if let Some(state) = states.fields(m) {
                let (s, w, f) = state.expect("a readable boundary state");
                let (w, f) = (glissade_bus::convert::view(&w), glissade_bus::convert::view(&f));
                for slot in &layouts[s as usize].slots {
                    fields[slot.interface].set_side(slot.side, slot.offset, w, f);
                }
            }
            Duration::ZERO
        })
        .in_process()
        .expect("run");
    (outcome.result, fields)
}

/// Every value fields.json and the CSV hold for each pair and time point (traction and jump in
/// the pair's frame) equals the one of the state the subdomains sent last, bit for bit: both are
/// [`pair_values`] of the same numbers (at a point with copies on several contact interfaces,
/// of the same weighted mean).
fn assert_outputs_are_the_judged_state(name: &str, sc: &LoadedScene) {
    let model = &sc.model;
    let (result, judged) = run_keeping_last_state(sc);
    assert!(!result.iterations.is_empty(), "{name}: no iteration");
    let doc = interface_fields(model, &result.interfaces);
    let csv = interface_csv(model, &result.interfaces).expect("csv");
    let mut rows = csv.lines().skip(1);
    let nt = model.time.n_points();
    // In interface order: the state judged, with one value per point where copies of a node
    // pair sit on several contact interfaces (as every output shows it), and the run's final s.
    let as_solutions = |fields: &[InterfaceFields]| -> Vec<InterfaceSolution> {
        fields
            .iter()
            .enumerate()
            .map(|(k, f)| solution_of_fields(k, f, vec![1; model.interfaces[k].n_pairs() * nt]))
            .collect()
    };
    let (mut judged, finals) = (as_solutions(&judged), as_solutions(&result.interface_fields()));
    glissade_replay::one_value_per_point(model, &mut judged);
    for i in 0..nt {
        for (k, itf) in model.interfaces.iter().enumerate() {
            let entry = &doc["interfaces"][k];
            assert_eq!(entry["interface"], k, "{name}: interfaces in order");
            for p in 0..itf.n_pairs() {
                let want = pair_values(itf, &judged[k], i, p);
                let json: Vec<f64> = ["f_n", "f_t", "jump_n", "jump_t"]
                    .iter()
                    .map(|q| entry[q][i][p].as_f64().expect("a number"))
                    .collect();
                assert_eq!(
                    json,
                    want.to_vec(),
                    "{name}: fields.json, interface {k}, time point {i}, pair {p}"
                );
                let row = rows.next().expect("a CSV row per pair and time point");
                let cells: Vec<&str> = row.rsplitn(6, ',').collect();
                let csv_values: Vec<f64> = cells[1..5].iter().rev().map(|c| c.parse().expect("a number")).collect();
                assert_eq!(
                    csv_values,
                    want.to_vec(),
                    "{name}: CSV, interface {k}, time point {i}, pair {p}"
                );
                // The solution message carries that same s.
                assert_eq!(pair_values(itf, &finals[k], i, p), want, "{name}: final solution");
            }
        }
    }
}

/// The largest difference between the tractions a run writes and the reference's, relative to
/// the reference's largest contact traction: first per physical point (copies of one node pair
/// on several contact interfaces, a cross-point where perfect interfaces meet the contact, are
/// one point whose traction is Σ m·F over its copies / Σ m: `pointwise_traction_error`, as the
/// report measures it); second copy by copy, both sides, against the reference's copy (which
/// carries its point's traction), as fields.json, the CSV and the VTU hold them.
fn largest_traction_difference(sc: &LoadedScene, result: &RunResult) -> (f64, f64) {
    let model = &sc.model;
    let reference = solve_reference(model, &Default::default()).expect("reference");
    let reference = &reference.interfaces;
    let got = result.interface_fields();
    let diff = pointwise_traction_error(&model.interfaces, &got, reference).error;
    let mut scale = 0.0f64;
    for (k, itf) in model.interfaces.iter().enumerate().filter(|(_, i)| i.is_contact()) {
        for i in 0..model.time.n_points() {
            for e in 0..2 * itf.n_pairs() {
                scale = scale.max(reference[k].f_a[(e, i)].abs());
            }
        }
    }
    let mut copies = 0.0f64;
    for (k, itf) in model.interfaces.iter().enumerate().filter(|(_, i)| i.is_contact()) {
        for i in 0..model.time.n_points() {
            for e in 0..2 * itf.n_pairs() {
                for (x, r) in [(&got[k].f_a, &reference[k].f_a), (&got[k].f_b, &reference[k].f_b)] {
                    copies = copies.max((x[(e, i)] - r[(e, i)]).abs());
                }
            }
        }
    }
    (diff, copies / scale)
}

/// The scene of the issue: before, "Converged after 25 iterations" (the estimate followed s's
/// forces, exact at 3e-7) while the pushed block sat off its place by a rigid offset that no
/// force of s shows, so ŝ, which the outputs held, carried 8.5 of the 10 N/mm (15 % off at every
/// pair; η = 0.11). Now the macro problem is off there (the block is held along x by the contact
/// alone) and a run is "Converged" only with s and ŝ within the accuracy: it writes the
/// reference's tractions. Tolerance: the default accuracy 1e-3 bounds the relative L2 error; the
/// run stops with e_c ≈ 5e-7, and the largest pointwise difference measured is 5e-6 of the
/// largest traction, so 1e-3 pointwise has a wide margin and would catch the old 15 %.
#[test]
fn two_blocks_side_by_side_write_the_reference_tractions() {
    let sc = fixture("side-by-side");
    let (result, _) = run_keeping_last_state(&sc);
    assert_eq!(
        result.verdict,
        Verdict::Converged,
        "{:?}",
        result.iterations.last().map(|r| &r.decision)
    );
    let d = &result.iterations.last().expect("iterations").decision;
    assert!(d.contact_indicator <= 1e-3, "e_c {:e} at the stop", d.contact_indicator);
    let (diff, _) = largest_traction_difference(&sc, &result);
    assert!(
        diff <= 1e-3,
        "largest traction difference {diff:e} of the largest traction"
    );
    // The hand answer: the contact carries the load, f_n = −10 on average at t = 1.
    let doc = interface_fields(&sc.model, &result.interfaces);
    let itf = &sc.model.interfaces[0];
    let nt = sc.model.time.n_points();
    let total: f64 = (0..itf.n_pairs())
        .map(|p| itf.weights[p] * doc["interfaces"][0]["f_n"][nt - 1][p].as_f64().expect("f_n"))
        .sum();
    // The right block's balance along x, within the accuracy asked (1e-3 of the 10 N/mm; measured
    // 2.6e-7 of it: s at the stop is a mixture of iterates, balanced to the iteration's error).
    assert!(
        (total + 10.0).abs() < 1e-3 * 10.0,
        "the contact carries {total} N/mm of the 10 applied"
    );
}

/// The same scene with the macro problem asked for: Anderson mixing with it cannot place the
/// block, and the scene says so instead of running.
#[test]
fn the_macro_problem_is_refused_where_a_part_is_held_only_by_contact() {
    let path = format!("{}/tests/fixtures/side-by-side.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("fixture") + "\n[solver]\ncoarse = true\n";
    let err = load_str(&text, &path).expect_err("coarse = true refused").to_string();
    assert!(err.contains("solver.coarse") && err.contains("`right`"), "{err}");
}

/// A run held at the iteration cap before s and ŝ agree is not "Converged", whatever the
/// estimate says: the scene with the macro problem forced on under Anderson mixing (the
/// combination the scene builder refuses) is the run, whose estimate was met at its 25th
/// iteration with s and ŝ 18 % apart; capped there, it must not say "Converged".
#[test]
fn converged_needs_s_and_s_hat_within_the_accuracy() {
    let mut sc = fixture("side-by-side");
    sc.model.solver.coarse = true;
    sc.model.solver.max_iterations = 25;
    let result = crate::common::run(&sc);
    let d = &result.iterations.last().expect("iterations").decision;
    if d.contact_indicator > 1e-3 {
        assert_ne!(result.verdict, Verdict::Converged, "e_c {:e}", d.contact_indicator);
    } else {
        panic!(
            "the check needs a run stopped with s and ŝ apart (e_c {:e})",
            d.contact_indicator
        );
    }
}

/// On every shipped scene (at a small N) and the side-by-side blocks, fields.json, the CSV and the
/// final solution message hold the state the last local stage and the verdict judged.
#[test]
fn every_output_is_the_state_the_verdict_judged() {
    assert_outputs_are_the_judged_state("side-by-side", &fixture("side-by-side"));
    for name in SHIPPED {
        // The three scenes of 100 time points or more at 10.
        let n = matches!(name, "layered" | "stratified" | "stratified-gmsh").then_some(10);
        assert_outputs_are_the_judged_state(name, &shipped(name, n));
    }
}

/// "Converged" means every contact traction written is within the accuracy of the reference's,
/// at every point and time point (relative to the reference's largest contact traction): on the
/// side-by-side blocks and the shipped scenes that were furthest off before the pointwise
/// estimate (layered and stratified at 20 time points, where the loaded ends and the
/// cross-points of the laminates converge last, and hertz-slip); the ignored
/// `outputs_against_the_reference` measures every scene. Tolerance: the accuracy itself, 1e-3,
/// which the pointwise estimate bounds; before it, layered and stratified stopped "Converged"
/// 4.0e-2 and 4.7e-2 off at a corner and hertz-slip 1.7e-3.
#[test]
fn converged_runs_write_every_traction_within_the_accuracy() {
    let mut scenes = vec![("side-by-side", fixture("side-by-side"))];
    for name in ["two-blocks", "hertz-slip", "layered", "stratified"] {
        let n = matches!(name, "layered" | "stratified").then_some(20);
        scenes.push((name, shipped(name, n)));
    }
    for (name, sc) in &scenes {
        let result = crate::common::run(sc);
        assert_eq!(result.verdict, Verdict::Converged, "{name}");
        let a = sc.model.solver.accuracy.expect("an accuracy");
        let (diff, copies) = largest_traction_difference(sc, &result);
        assert!(
            diff <= a,
            "{name}: a traction {diff:e} of the largest off, accuracy {a:e}"
        );
        // Copy by copy too: where copies of a node pair sit on several contact interfaces (the
        // cross-points of stratified), each one written holds its point's traction, not a share
        // that only sums right (2–3 % of the largest traction off at stratified's cross-points
        // before the outputs gave each copy its point's values).
        assert!(copies <= a, "{name}: a copy's traction {copies:e} of the largest off");
        let d = &result.iterations.last().expect("iterations").decision;
        assert!(d.pointwise_estimate.is_some_and(|e| e <= a), "{name}: {d:?}");
    }
}

/// The table of docs/accuracy.md ("What the outputs hold against the reference"): per scene, the
/// verdict and the largest difference between the tractions written and the reference's.
/// `cargo test --release --test integration -- --ignored outputs_against_the_reference --nocapture`
#[test]
#[ignore = "a measurement for docs/accuracy.md, 21 minutes in a debug build"]
fn outputs_against_the_reference() {
    let mut scenes = vec![("side-by-side".to_string(), fixture("side-by-side"))];
    for name in SHIPPED {
        // The paper's N = 1000 at 100: the reference at 1000 time points takes too long here.
        let n = matches!(name, "stratified" | "stratified-gmsh").then_some(100);
        let label = n.map_or(name.to_string(), |n| format!("{name} (N = {n})"));
        scenes.push((label, shipped(name, n)));
    }
    for case in glissade::stability::cases(false) {
        let converges = matches!(case.expect, glissade::stability::Expect::Converge { .. });
        if case.reference.is_some() && converges {
            scenes.push((format!("stability: {}", case.name), scene(&case.accelerated)));
        }
    }
    println!(
        "| scene | verdict | iterations | largest traction difference / largest traction | the same copy by copy |"
    );
    println!("|---|---|---|---|---|");
    for (name, sc) in &scenes {
        let result = crate::common::run(sc);
        let (diff, copies) = largest_traction_difference(sc, &result);
        let verdict = match &result.verdict {
            Verdict::Converged => "Converged".to_string(),
            v => format!("NOT converged ({v:?})").chars().take(60).collect(),
        };
        println!(
            "| {name} | {verdict} | {} | {diff:.1e} | {copies:.1e} |",
            result.iterations.len()
        );
    }
}

/// Two rings press-fitted (the rings, on the sheath's mesh: three layers each cut into 8
/// sectors glued along their cuts, all steel, an interference of 0.01 mm on the inner circle, the
/// outer circle in contact without one, the bore clamped, a shear on the rim rising from 0): at
/// t = 0 nothing shears the fit, so the tangential traction must vanish at every pair, the 8
/// points where two sectors meet on each circle included. The outputs hold it within 1e-3 of the
/// largest normal traction (measured 4.7e-6); the run's own copies at those points carry shares
/// of the point's force that only sum right (measured 1.9e-1 of the largest normal traction, the
/// issue's ±13 % on its own rings), which the outputs must not show.
#[test]
fn press_fitted_sectors_have_no_shear_at_rest_at_their_boundaries() {
    let sc = crate::common::rings("1.9*t");
    let model = &sc.model;
    let (result, judged) = run_keeping_last_state(&sc);
    assert_eq!(result.verdict, Verdict::Converged);
    let written = result.interface_fields();
    let ratio = |fields: &[InterfaceFields]| {
        let (mut t_max, mut n_max) = (0.0f64, 0.0f64);
        for (k, itf) in model.interfaces.iter().enumerate().filter(|(_, i)| i.is_contact()) {
            for p in 0..itf.n_pairs() {
                let f = [fields[k].f_a[(2 * p, 0)], fields[k].f_a[(2 * p + 1, 0)]];
                let (n, t) = (itf.normal(p), itf.tangent(p));
                n_max = n_max.max((f[0] * n[0] + f[1] * n[1]).abs());
                t_max = t_max.max((f[0] * t[0] + f[1] * t[1]).abs());
            }
        }
        t_max / n_max
    };
    let (written, own) = (ratio(&written), ratio(&judged));
    println!("tangential / normal at t = 0: written {written:.2e}, the run's own copies {own:.2e}");
    assert!(written <= 1e-3, "written: {written:e}");
    // The scene does exercise copies that disagree (else the check above would prove nothing).
    assert!(own > 1e-2, "the run's own copies: {own:e}");
}
