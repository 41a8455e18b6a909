use super::*;
use crate::assembly::{stiffness_triplets, triplet_matvec};
use crate::linear::flop_tests::model_and_solver;
use crate::model::Model;

/// The small-three-layer scene's subdomain core.2 ([`model_and_solver`]) with a PGD stage.
fn setup(macro_modes: bool, dense: bool) -> (Model, SubdomainSolver, PgdStage) {
    let (model, mut solver) = model_and_solver(dense);
    let tw = model.time.trapezoid_weights();
    let settings = PgdSettings {
        criterion: PgdCriterion::Increment,
        xi1: 1e-14,
        xi2: 1e-14,
        macro_modes,
        max_new_modes: 1,
    };
    let stage = PgdStage::new(&mut solver, &tw, settings);
    (model, solver, stage)
}

fn rng(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

fn random(n: usize, m: usize, seed: u64) -> Mat<f64> {
    let mut r = rng(seed);
    Mat::from_fn(n, m, |_, _| r())
}

/// Σ_j s_j a_j b_jᵀ with random a_j, b_j.
fn low_rank(n: usize, m: usize, scales: &[f64], seed: u64) -> Mat<f64> {
    let a = random(n, scales.len(), seed);
    let b = random(m, scales.len(), seed + 1);
    Mat::from_fn(n, m, |r, i| {
        (0..scales.len()).map(|j| scales[j] * a[(r, j)] * b[(i, j)]).sum()
    })
}

fn max_abs(m: MatRef<'_, f64>) -> f64 {
    let mut x: f64 = 0.0;
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            x = x.max(m[(i, j)].abs());
        }
    }
    x
}

/// Grows the basis by one mode per random right-hand side.
fn grow(solver: &mut SubdomainSolver, stage: &mut PgdStage, n: usize, seed: u64) {
    let (n_b, nt) = (solver.n_boundary(), solver.w_d.ncols());
    for s in 0..n as u64 {
        let before = stage.n_modes();
        stage.micro1(solver, random(n_b, nt, seed + 7 * s).as_ref());
        assert_eq!(stage.n_modes(), before + 1);
    }
}

fn gram(stage: &PgdStage) -> Mat<f64> {
    let l = stage.l();
    Mat::from_fn(l.ncols(), l.ncols(), |a, b| {
        (0..l.nrows()).map(|r| l[(r, a)] * stage.mass[r] * l[(r, b)]).sum()
    })
}

#[test]
fn update_is_the_exact_least_squares_projection() {
    let (_, mut solver, mut stage) = setup(false, true);
    grow(&mut solver, &mut stage, 8, 11);
    let (n_b, nt, p) = (solver.n_boundary(), solver.w_d.ncols(), stage.n_modes());
    let previous = stage.lambda1().to_owned();
    let q_hat = random(n_b, nt, 99);
    stage.settings.xi1 = f64::INFINITY; // update only
    stage.micro1(&mut solver, q_hat.as_ref());
    assert_eq!(stage.n_modes(), p);
    // Normal equations (LᵀML) Δλ = LᵀM δ(t), δ = q̂ − L λ_prev, with the Gram matrix computed
    // here rather than assumed to be I.
    let l = stage.l();
    let delta = &q_hat - l * &previous;
    let mdelta = Mat::from_fn(n_b, nt, |r, i| stage.mass[r] * delta[(r, i)]);
    let rhs = l.transpose() * &mdelta;
    let dlambda = stage.lambda1() - &previous;
    let lhs = gram(&stage) * &dlambda;
    // Round-off of p·n_b-term sums of O(1) numbers: 1e-12 relative to the right-hand side.
    assert!(max_abs((&lhs - &rhs).as_ref()) <= 1e-12 * max_abs(rhs.as_ref()));
    // And the residual is M-orthogonal to every mode (the least-squares optimality condition).
    let resid = &q_hat - l * stage.lambda1();
    let mres = Mat::from_fn(n_b, nt, |r, i| stage.mass[r] * resid[(r, i)]);
    let ortho = l.transpose() * &mres;
    assert!(max_abs(ortho.as_ref()) <= 1e-12 * max_abs(rhs.as_ref()));
}

#[test]
fn rank_one_increment_is_recovered_to_round_off() {
    for dense in [true, false] {
        let (_, mut solver, mut stage) = setup(false, dense);
        let (n_b, nt) = (solver.n_boundary(), solver.w_d.ncols());
        let q_hat = low_rank(n_b, nt, &[3.0], 5);
        let report = stage.micro1(&mut solver, q_hat.as_ref());
        assert_eq!((report.new_modes, stage.n_modes()), (1, 1));
        // One mode holds a rank-one δ: the residual is round-off of n_b·N-term sums.
        assert!(report.xi <= 1e-13, "ξ = {:e}", report.xi);
        let (mut w, mut f) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
        stage.expand_into(solver.w_d.as_ref(), w.as_mut(), f.as_mut(), false);
        let (mut we, mut fe) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
        solver.micro1_into(q_hat.as_ref(), we.as_mut(), fe.as_mut());
        assert!(max_abs((&w - &we).as_ref()) <= 1e-12 * max_abs(we.as_ref()));
        assert!(max_abs((&f - &fe).as_ref()) <= 1e-12 * max_abs(fe.as_ref()));
        // Macro forces from the modes equal 𝔼ᵀ M F₁ of the exact solution.
        let n_m = solver.n_macro();
        let (mut mf, mut mfe) = (Mat::zeros(n_m, nt), Mat::zeros(n_m, nt));
        stage.macro_forces_into(mf.as_mut());
        solver.macro_forces_into(fe.as_ref(), mfe.as_mut());
        assert!(max_abs((&mf - &mfe).as_ref()) <= 1e-12 * max_abs(mfe.as_ref()));
    }
}

/// Every pair satisfies subdomain equilibrium without loads: with u the interior field of L
/// ((K + BᵀkMB) u = BᵀML), Z = B u and K u = Bᵀ M G on the free dofs.
#[test]
fn every_pair_is_admissible() {
    for dense in [true, false] {
        let (model, mut solver, mut stage) = setup(true, dense);
        assert!(stage.n_frozen() > 0);
        grow(&mut solver, &mut stage, 6, 23);
        let sub = &model.subdomains[solver.subdomain];
        let k = stiffness_triplets(&sub.mesh, sub.material, model.plane).unwrap();
        let layout = &solver.op.layout;
        let n = sub.n_dofs();
        for m in 0..stage.n_modes() {
            let l: Vec<f64> = (0..layout.len()).map(|r| stage.l()[(r, m)]).collect();
            let u = solver.op.recover(&l, &[]);
            let z_scale = (0..layout.len()).map(|r| stage.z()[(r, m)].abs()).fold(0.0, f64::max);
            for (r, &d) in layout.dofs.iter().enumerate() {
                assert!((stage.z()[(r, m)] - u[d]).abs() <= 1e-10 * z_scale, "mode {m} trace");
            }
            let mut ku = vec![0.0; n];
            triplet_matvec(&k, &u, &mut ku);
            let mut bmg = vec![0.0; n];
            for (r, &d) in layout.dofs.iter().enumerate() {
                bmg[d] += layout.mass[r] * stage.g()[(r, m)];
            }
            let scale = bmg.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let worst = (0..n)
                .filter(|&d| !sub.constrained[d])
                .map(|d| (ku[d] - bmg[d]).abs())
                .fold(0.0, f64::max);
            // The bound: 1e-10 relative to the boundary forces.
            assert!(
                worst <= 1e-10 * scale,
                "mode {m}: {worst:e} vs {scale:e} (dense {dense})"
            );
        }
    }
}

#[test]
fn flops_grow_with_the_basis() {
    for dense in [true, false] {
        let (_, mut solver, mut stage) = setup(false, dense);
        let (n_b, nt) = (solver.n_boundary(), solver.w_d.ncols());
        // Construction is not counted.
        assert_eq!(stage.flops(), 0);
        let q_hat = random(n_b, nt, 5);
        // The update alone (ξ₀ = ∞) on p modes: M q̂, Lᵀ(M q̂) and q̂ − Lλ (n_b + 4 p n_b per
        // time point), two coordinate norms and the residual's norm.
        let update =
            |p: usize| (n_b * nt + 4 * p * n_b * nt + 2 * (3 * p * nt + 2 * nt) + 3 * n_b * nt + 2 * nt) as u64;
        let mut last = 0;
        for modes in [0, 2, 5] {
            while stage.n_modes() < modes {
                // Each new mode costs the stage's own kernels and one boundary response.
                let (own, solver_before) = (stage.flops(), solver.flops());
                stage.settings.xi1 = 1e-14;
                stage.micro1(&mut solver, random(n_b, nt, 100 + stage.n_modes() as u64).as_ref());
                assert!(stage.flops() - own > update(stage.n_modes() - 1));
                let per_response = if dense {
                    (n_b + 2 * n_b * n_b) as u64
                } else {
                    solver.op.sparse_response_flops()
                };
                assert_eq!(solver.flops() - solver_before, per_response);
            }
            stage.settings.xi1 = f64::INFINITY;
            let before = stage.flops();
            stage.micro1(&mut solver, q_hat.as_ref());
            let count = stage.flops() - before;
            assert_eq!(count, update(modes), "{modes} modes (dense {dense})");
            assert!(count > last);
            last = count;
        }
    }
}

#[test]
fn basis_stays_m_orthonormal() {
    let (_, mut solver, mut stage) = setup(true, true);
    grow(&mut solver, &mut stage, 30, 41);
    let p = stage.n_modes();
    let err = &gram(&stage) - Mat::<f64>::identity(p, p);
    // Gram–Schmidt twice: orthonormal to a few ulps times the number of modes.
    assert!(max_abs(err.as_ref()) <= 1e-12, "{:e}", max_abs(err.as_ref()));
}

#[test]
fn micro2_by_pgd_needs_at_most_the_macro_rank() {
    let (_, mut solver, mut stage) = setup(false, true);
    let (nt, n_m) = (solver.w_d.ncols(), solver.n_macro());
    stage.settings.max_new_modes = n_m + 5;
    let report = stage.micro2(&mut solver, random(n_m, nt, 8).as_ref());
    // k⁻𝔼w̃ has rank ≤ n_m: the fit needs at most n_m modes and then holds it to round-off.
    assert!(report.new_modes <= n_m && report.new_modes > 0, "{report:?}");
    assert!(report.xi <= 1e-12, "{report:?}");
}

#[test]
fn micro2_is_exact_with_macro_modes() {
    let (_, mut solver, mut stage) = setup(true, true);
    let (n_b, nt, n_m) = (solver.n_boundary(), solver.w_d.ncols(), solver.n_macro());
    let w_tilde = random(n_m, nt, 3);
    stage.micro2(&mut solver, w_tilde.as_ref());
    let (mut w2, mut f2) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
    solver.micro2_into(w_tilde.as_ref(), w2.as_mut(), f2.as_mut());
    // Expansion of λ² alone: W = W_d + Zλ² and F = −kW_d + Gλ²; subtract s₀ = (W_d, −kW_d).
    stage.lambda1.fill(0.0);
    let (mut w, mut f) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
    stage.expand_into(solver.w_d.as_ref(), w.as_mut(), f.as_mut(), true);
    let w_wd = &w - &solver.w_d;
    assert!(max_abs((&w_wd - &w2).as_ref()) <= 1e-12 * max_abs(w2.as_ref()));
    let kwd = Mat::from_fn(n_b, nt, |r, i| solver.op.layout.k[r] * solver.w_d[(r, i)]);
    let f_f0 = &f + &kwd;
    assert!(max_abs((&f_f0 - &f2).as_ref()) <= 1e-12 * max_abs(f2.as_ref()));
}

#[test]
fn compression_removes_exactly_the_truncated_part() {
    let (_, mut solver, mut stage) = setup(true, true);
    let (n_b, nt) = (solver.n_boundary(), solver.w_d.ncols());
    stage.settings.max_new_modes = 10;
    let q_hat = low_rank(n_b, nt, &[1.0, 0.3, 1e-3, 1e-5], 17);
    stage.micro1(&mut solver, q_hat.as_ref());
    let p = stage.n_modes();
    assert!(p >= stage.n_frozen() + 4, "{p}");
    let (mut w, mut f) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
    stage.expand_into(solver.w_d.as_ref(), w.as_mut(), f.as_mut(), false);
    let k = stage.k.clone();
    let q_of = |w: &Mat<f64>, f: &Mat<f64>| Mat::from_fn(n_b, nt, |r, i| f[(r, i)] + k[r] * w[(r, i)]);
    let q = q_of(&w, &f);
    let norm_q = stage.norm2(q.as_ref()).sqrt();
    // Keeps the two large directions (plus frozen modes), drops the 1e-3 and 1e-5 ones.
    let tol = 1e-2 * norm_q;
    let (w_old, f_old) = (w.clone(), f.clone());
    // The state's coordinates are those of (w, f): they rotate with the basis.
    let lambda1 = stage.lambda1().to_owned();
    stage.state_mut().copy_from(&lambda1);
    stage.take_changed();
    let dropped = stage.compress_with(w.as_mut(), f.as_mut(), tol);
    assert!(dropped >= 2, "{dropped}");
    // The compressed state in coordinates is the compressed state; the rotated free modes are
    // what the next mode-form message must carry again.
    let (mut ws, mut fs) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
    let state = stage.state().to_owned();
    let p_now = stage.n_modes();
    stage.lambda1.as_mut().subrows_mut(0, p_now).copy_from(&state);
    stage.expand_into(solver.w_d.as_ref(), ws.as_mut(), fs.as_mut(), false);
    assert!(max_abs((&ws - &w).as_ref()) <= 1e-12 * max_abs(w_old.as_ref()));
    assert!(max_abs((&fs - &f).as_ref()) <= 1e-12 * max_abs(f_old.as_ref()));
    assert_eq!(stage.take_changed(), stage.n_frozen());
    let q_new = q_of(&w, &f);
    let removed = &q - &q_new;
    let removed_norm = stage.norm2(removed.as_ref()).sqrt();
    assert!(removed_norm <= tol && removed_norm > 0.0);
    // The removed part is what the truncated modes carried: the new state is in the new span
    // (its own projection) and the removed part is orthogonal to it (SVD truncation).
    let l = stage.l();
    let mq = Mat::from_fn(n_b, nt, |r, i| stage.mass[r] * q_new[(r, i)]);
    let back = l * (l.transpose() * &mq);
    assert!(max_abs((&back - &q_new).as_ref()) <= 1e-12 * max_abs(q_new.as_ref()));
    let inner: f64 = (0..nt)
        .map(|i| {
            stage.tw[i]
                * (0..n_b)
                    .map(|r| stage.mass[r] * removed[(r, i)] * q_new[(r, i)])
                    .sum::<f64>()
        })
        .sum();
    assert!(inner.abs() <= 1e-12 * norm_q * norm_q, "{inner:e}");
    // Still admissible: the compressed state is the exact micro 1 solution of its own q.
    let (mut we, mut fe) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
    solver.micro1_into(q_new.as_ref(), we.as_mut(), fe.as_mut());
    assert!(max_abs((&w - &we).as_ref()) <= 1e-10 * max_abs(w_old.as_ref()));
    assert!(max_abs((&f - &fe).as_ref()) <= 1e-10 * max_abs(f_old.as_ref()));
    // And the basis stays orthonormal with admissible pairs Z = A_E M L.
    let p = stage.n_modes();
    assert!(max_abs((&gram(&stage) - Mat::<f64>::identity(p, p)).as_ref()) <= 1e-12);
    let mut z = Mat::zeros(n_b, p);
    let l = stage.l().to_owned();
    solver.boundary_response_into(l.as_ref(), z.as_mut());
    assert!(max_abs((&z - stage.z()).as_ref()) <= 1e-12 * max_abs(z.as_ref()));
}

/// The forcing criterion measures the residual against the target's own step: a target that
/// moves by much more than its part outside the basis adds no mode, and a target that stops
/// moving is enriched until its residual is round-off (so a fixed point of the PGD iteration is
/// one of the exact iteration), after which the basis stays as it is.
#[test]
fn forcing_criterion_follows_the_step_and_resolves_a_stationary_target() {
    let (_, mut solver, mut stage) = setup(false, true);
    stage.settings.criterion = PgdCriterion::Forcing;
    stage.settings.xi1 = 0.1;
    stage.settings.max_new_modes = 8;
    // The stage was built for the increment criterion: rebuild it with the forcing buffers.
    let tw = stage.tw.clone();
    let mut stage = PgdStage::new(&mut solver, &tw, stage.settings);
    let (n_b, nt) = (solver.n_boundary(), solver.w_d.ncols());
    let q = low_rank(n_b, nt, &[1.0, 0.5, 0.25], 5);
    // First stage: the step is the target itself; modes until the residual is a tenth of it.
    let r = stage.micro1(&mut solver, q.as_ref());
    assert!(r.new_modes >= 1 && r.xi <= 0.1, "{r:?}");
    // The same target again: zero step, every residual is too large, the rank-3 target is
    // resolved to round-off and no more.
    let r = stage.micro1(&mut solver, q.as_ref());
    assert_eq!(r.reference_norm, 0.0);
    assert_eq!(stage.n_modes(), 3, "{r:?}");
    let r = stage.micro1(&mut solver, q.as_ref());
    assert_eq!((r.new_modes, stage.n_modes()), (0, 3), "{r:?}");
    // A large step along the basis with a small part outside it: ξ ≈ 1e-3 ≤ ξ₀, no new mode.
    let noise = random(n_b, nt, 77);
    let moved = Mat::from_fn(n_b, nt, |r, i| 3.0 * q[(r, i)] + 1e-3 * noise[(r, i)]);
    let r = stage.micro1(&mut solver, moved.as_ref());
    assert_eq!(r.new_modes, 0, "{r:?}");
    assert!(r.xi_update > 0.0 && r.xi_update < 0.1, "{r:?}");
    // It stops moving: its residual, however small, is now above ξ₀ times a zero step.
    let r = stage.micro1(&mut solver, moved.as_ref());
    assert!(r.xi_update.is_infinite() && r.new_modes >= 1, "{r:?}");
}

/// ξ₀ above 1 is meaningful with the forcing criterion (a residual up to ξ₀ times the step):
/// a residual half the step adds a mode at ξ₀ = 0.1 and none at ξ₀ = 1.
#[test]
fn forcing_threshold_may_exceed_one() {
    for (xi1, expected) in [(0.1, 1), (1.0, 0)] {
        let (_, mut solver, stage) = setup(false, true);
        let settings = PgdSettings {
            criterion: PgdCriterion::Forcing,
            xi1,
            max_new_modes: 1,
            ..stage.settings
        };
        let tw = stage.tw.clone();
        let mut stage = PgdStage::new(&mut solver, &tw, settings);
        let (n_b, nt) = (solver.n_boundary(), solver.w_d.ncols());
        let q = low_rank(n_b, nt, &[1.0], 3);
        stage.settings.xi1 = 1e-14;
        stage.micro1(&mut solver, q.as_ref());
        assert_eq!(stage.n_modes(), 1);
        stage.settings.xi1 = xi1;
        // Step: 2q (in the basis, norm 2‖q‖) plus a part outside of norm ‖q‖ → ξ = 1/√5.
        let out = low_rank(n_b, nt, &[1.0], 9);
        let mut outside = out.clone();
        let lam = stage.l().transpose() * Mat::from_fn(n_b, nt, |r, i| stage.mass[r] * out[(r, i)]);
        outside -= stage.l() * &lam;
        let scale = (stage.norm2(q.as_ref()) / stage.norm2(outside.as_ref())).sqrt();
        let next = Mat::from_fn(n_b, nt, |r, i| 3.0 * q[(r, i)] + scale * outside[(r, i)]);
        let r = stage.micro1(&mut solver, next.as_ref());
        assert!((r.xi_update - 1.0 / 5f64.sqrt()).abs() < 1e-9, "{r:?}");
        assert_eq!(r.new_modes, expected, "ξ₀ = {xi1}: {r:?}");
    }
}
