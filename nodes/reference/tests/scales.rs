//! The checks' scales come from the scene (loads over the whole history, prescribed motion, gaps,
//! materials, size), not from the solution they check, and a solution of absurd size is refused.

use glissade_mechanics::model::Model;
use glissade_reference::*;

fn model_of(text: &str, file: &str) -> Model {
    match glissade_scene::load_str(text, file) {
        Ok(sc) => sc.model,
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn scales_come_from_the_loads_and_the_scene() {
    // The laminate unloading to zero: its only load is the tip shear on the 20 mm end, 10 MPa at
    // its largest (t = 0.4..0.6) and 0 at t = 0 and t = 1. Its consistent nodal forces all point
    // down, so Σ|f| is the resultant, 200 N, to round-off (1e-12 relative: ~100 terms of O(1)).
    // The scales are the largest over the history, so the zero-load time points are checked
    // against the same positive scales.
    let model = model_of(include_str!("fixtures/laminate-unload.toml"), "laminate-unload.toml");
    let s = Scales::of(&model);
    assert!((s.force - 200.0).abs() <= 1e-12 * 200.0, "{s:?}");
    // U_s = P / E_min (aluminium, 70 000 MPa): no prescribed motion other than the clamp, no gap.
    assert!(
        (s.displacement - 200.0 / 70000.0).abs() <= 1e-12 * s.displacement,
        "{s:?}"
    );
    assert_eq!(s.size, 200.0);
    assert_eq!(s.implausible(0.0, 0.0), None);
    assert_eq!(s.implausible(DISPLACEMENT_BOUND * 200.0, FORCE_BOUND * 200.0), None);
    // Beyond the size but within what the loads give (a scene of absurd loads): plausible.
    let absurd_loads = Scales { displacement: 1e3, ..s };
    assert_eq!(absurd_loads.implausible(1.1e4, 0.0), None);
    let far = s
        .implausible(8e9, 0.0)
        .expect("a displacement of 8e9 mm is implausible");
    assert!(
        far.contains("8.000e9 mm") && far.contains("2.000e2 mm") && far.contains("2.857e-3 mm"),
        "{far}"
    );
    let strong = s.implausible(1.0, 7e11).expect("a force of 7e11 N is implausible");
    assert!(
        strong.contains("7.000e11 N") && strong.contains("2.000e2 N"),
        "{strong}"
    );
}

#[test]
fn a_scene_without_any_load_has_positive_scales_and_solves_to_zero() {
    // The laminate without its tip shear: nothing loads it at any time point. Its scales are the
    // floor of a strain of 1e-12 over the scene (E_max·D·1e-12 N, D·1e-12 mm), so that every
    // check stays defined; the solution is zero and verifies.
    let text = include_str!("fixtures/laminate-unload.toml");
    let cut = text.find("[[boundary]]\nx = 200.0").expect("the tip shear rule");
    let model = model_of(&text[..cut], "laminate-unload.toml");
    let s = Scales::of(&model);
    assert_eq!(
        (s.force, s.displacement, s.size),
        (1e-12 * 210000.0 * 200.0, 1e-12 * 200.0, 200.0)
    );
    let sol = solve_reference(&model, &ReferenceOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(sol.newton_iterations.iter().all(|&n| n == 0));
    assert!(sol.u.iter().all(|u| u.norm_max() == 0.0));
    let checks = verify(&model, &sol).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(checks.max(), 0.0, "{checks:?}");
}

/// The solution of the small three-layer scene with its fields from time point 5 on multiplied
/// by `c`.
fn scaled(sol: &ReferenceSolution, c: f64) -> ReferenceSolution {
    let mut out = sol.clone();
    let scale = |m: &mut faer::Mat<f64>| {
        for j in 5..m.ncols() {
            for i in 0..m.nrows() {
                m[(i, j)] *= c;
            }
        }
    };
    out.u.iter_mut().for_each(scale);
    for f in &mut out.interfaces {
        for m in [&mut f.w_a, &mut f.w_b, &mut f.f_a, &mut f.f_b] {
            scale(m);
        }
    }
    out
}

#[test]
fn a_solution_of_the_wrong_size_is_not_verified() {
    let model = model_of(
        include_str!("../../../launch/scenes/small-three-layer.toml"),
        "small-three-layer.toml",
    );
    let sol = solve_reference(&model, &ReferenceOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let checks = verify(&model, &sol).unwrap_or_else(|e| panic!("{e}"));
    assert!(checks.max() <= 1e-10, "{checks:?}");
    // 1000 times too large from time point 5 on: still of plausible size (displacements of
    // 1e-2 mm become 10 mm in a 40 mm scene), but its internal forces are 1000 times those the
    // loads balance: equilibrium is violated by about the loads themselves, far above 1e-3 of the
    // force scale (a check relative to the solution's own forces would see 1e-3 of them).
    let c = verify(&model, &scaled(&sol, 1e3)).unwrap_or_else(|e| panic!("{e}"));
    println!("× 1e3: {c:?}");
    assert!(c.equilibrium > 1e-3, "{c:?}");
    assert_eq!(
        (c.force_scale, c.displacement_scale),
        (checks.force_scale, checks.displacement_scale)
    );
    // 1e12 times too large: every relative residual of the scaled solution against its own size
    // is as small as the solution's (all residuals scale with it but the loads, which become
    // 1e-12 of it), so checks scaled by the solution would pass it; its size is refused, at the
    // first time point scaled.
    match verify(&model, &scaled(&sol, 1e12)) {
        Err(ReferenceError::Implausible { step, time, ref reason }) => {
            assert_eq!((step, time), (5, model.time.t(5)));
            assert!(reason.contains("times the scene's size"), "{reason}");
        }
        other => panic!("expected an implausible solution, got {other:?}"),
    }
}
