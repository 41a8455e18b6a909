//! Tests of the linear stage's floating-point counts and of a solver moved to another time
//! grid; [`model_and_solver`] also serves the PGD and SIMD tests.

use super::{default_k0, macro_bases, SubdomainSolver};
use crate::model::Model;
use faer::Mat;
use std::sync::Arc;
/// core.2: loaded on its free end, clamped nowhere, a perfect and two contact interfaces (so
/// three macro slots).
const SUB: usize = 3;

/// The small-three-layer model and the solver of its subdomain core.2 (also the PGD tests').
pub(crate) fn model_and_solver(dense: bool) -> (Model, SubdomainSolver) {
    let model = crate::fixtures::small_three_layer();
    let k0 = default_k0(&model);
    let bases = macro_bases(&model);
    let solver = SubdomainSolver::with_dense(&model, SUB, &k0, &bases, dense).unwrap();
    (model, solver)
}

fn solver(dense: bool) -> SubdomainSolver {
    model_and_solver(dense).1
}

fn ramp(n: usize, m: usize) -> Mat<f64> {
    Mat::from_fn(n, m, |i, j| (i as f64 + 1.0).sin() * (j as f64 + 0.5))
}

/// Counts of one linear stage: micro 1, macro forces, micro 2.
fn stage_counts(s: &mut SubdomainSolver) -> [u64; 3] {
    let (n_b, n_m, nt) = (s.n_boundary(), s.n_macro(), s.w_d.ncols());
    let (mut w, mut f, mut mf) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt), Mat::zeros(n_m, nt));
    let mut counts = [0; 3];
    let before = s.flops();
    s.micro1_into(ramp(n_b, nt).as_ref(), w.as_mut(), f.as_mut());
    counts[0] = s.flops() - before;
    s.macro_forces_into(f.as_ref(), mf.as_mut());
    counts[1] = s.flops() - before - counts[0];
    s.micro2_into(ramp(n_m, nt).as_ref(), w.as_mut(), f.as_mut());
    counts[2] = s.flops() - before - counts[0] - counts[1];
    counts
}

#[test]
fn condensed_counts_are_the_formula() {
    let mut s = solver(true);
    // The setup's products are not counted.
    assert_eq!(s.flops(), 0);
    let (n_b, n_m, nt) = (s.n_boundary() as u64, s.n_macro() as u64, s.w_d.ncols() as u64);
    assert!(n_b > 0 && n_m > 0 && nt > 1);
    // Interfaces' rows: n_b is the sum of 2·n_pairs over the slots; each mode's dot product
    // runs over its interface's rows only.
    let mode_rows: u64 = s
        .macro_slots
        .iter()
        .zip(&s.op.layout.slots)
        .map(|(m, slot)| (2 * slot.n_pairs * m.n_modes) as u64)
        .sum();
    assert!(mode_rows < n_b * n_m, "𝔼 is block sparse: {mode_rows} vs {}", n_b * n_m);
    let counts = stage_counts(&mut s);
    // micro 1: M q̂ (n_b), A_E (M q̂) (2 n_b²), F₁ = q̂ − k⁻W₁ (2 n_b), per time point.
    assert_eq!(counts[0], nt * (n_b + 2 * n_b * n_b + 2 * n_b));
    assert_eq!(counts[1], 2 * mode_rows * nt);
    // micro 2: two n_b × n_m by n_m × nt products.
    assert_eq!(counts[2], 4 * n_b * n_m * nt);
    // The counter accumulates: a second stage adds the same again.
    let total = s.flops();
    assert_eq!(stage_counts(&mut s), counts);
    assert_eq!(s.flops(), 2 * total);
}

/// A solver moved to another time grid (the time-coarse start's coarse solve) is the solver
/// built on that grid, bit for bit: its linear stage gives the same fields, dense or sparse.
#[test]
fn retimed_is_the_solver_built_on_that_grid() {
    for dense in [true, false] {
        let (model, fine) = model_and_solver(dense);
        let mut coarse_model = model.clone();
        coarse_model.time.n_steps = model.time.n_steps / 2;
        assert!(coarse_model.time.n_steps >= 2);
        let mut moved = fine.retimed(&coarse_model);
        let mut built = SubdomainSolver::with_dense(
            &coarse_model,
            SUB,
            &default_k0(&coarse_model),
            &macro_bases(&coarse_model),
            dense,
        )
        .unwrap();
        // The operator is shared, not rebuilt.
        assert!(Arc::ptr_eq(&moved.op, &fine.op));
        assert_eq!(moved.w_d, built.w_d);
        assert_eq!(moved.load_time, built.load_time);
        assert_eq!(
            (moved.e.clone(), moved.a_mk_e.clone()),
            (built.e.clone(), built.a_mk_e.clone())
        );
        assert_eq!(moved.l_e, built.l_e);
        assert_eq!(moved.w_d.ncols(), coarse_model.time.n_points());
        // The grids differ, so W_d does too (the loads vary in time).
        assert_ne!(moved.w_d.ncols(), fine.w_d.ncols());
        let (a, b) = (stage_fields(&mut moved), stage_fields(&mut built));
        assert!(a == b, "dense {dense}: the linear stage differs");
        assert_eq!(moved.flops(), built.flops());
    }
}

/// W₁, F₁, the macro forces, W₂ and F₂ of one linear stage from fixed inputs.
fn stage_fields(s: &mut SubdomainSolver) -> [Mat<f64>; 5] {
    let (n_b, n_m, nt) = (s.n_boundary(), s.n_macro(), s.w_d.ncols());
    let (mut w1, mut f1, mut mf) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt), Mat::zeros(n_m, nt));
    let (mut w2, mut f2) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
    s.micro1_into(ramp(n_b, nt).as_ref(), w1.as_mut(), f1.as_mut());
    s.macro_forces_into(f1.as_ref(), mf.as_mut());
    s.micro2_into(ramp(n_m, nt).as_ref(), w2.as_mut(), f2.as_mut());
    [w1, f1, mf, w2, f2]
}

#[test]
fn sparse_counts_are_nt_times_the_per_solve_count() {
    let mut s = solver(false);
    assert_eq!(s.flops(), 0);
    let (n_b, n_m, nt) = (s.n_boundary() as u64, s.n_macro() as u64, s.w_d.ncols() as u64);
    let n_free = s.op.n_free() as u64;
    let per_solve = s.op.sparse_response_flops();
    // One solve: at least the diagonal both ways plus the M q scatter of ≤ n_b entries, at
    // most a dense factor's 4·n(n+1)/2 − 2n.
    assert!(
        per_solve > 2 * n_free && per_solve <= 2 * n_free * n_free + 2 * n_b,
        "{per_solve}"
    );
    let counts = stage_counts(&mut s);
    // micro 1: one solve per time point, + W_d (n_b) and F₁ (2 n_b).
    assert_eq!(counts[0], nt * (per_solve + 3 * n_b));
    // micro 2: 𝔼 w̃ (2 n_b n_m), k⁻ (n_b), one solve, F₂ (2 n_b) per time point.
    assert_eq!(counts[2], nt * (2 * n_b * n_m + n_b + per_solve + 2 * n_b));
    // The same macro-force kernel as the condensed stage.
    assert_eq!(counts[1], stage_counts(&mut solver(true))[1]);
    // A boundary response of m columns is m solves.
    let before = s.flops();
    let mut out = Mat::zeros(n_b as usize, 3);
    s.boundary_response_into(ramp(n_b as usize, 3).as_ref(), out.as_mut());
    assert_eq!(s.flops() - before, 3 * per_solve);
}
