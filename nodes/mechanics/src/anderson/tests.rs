use super::*;

/// G(x) = A x + c on x = (W, F) stacked as one vector, W first.
struct Linear {
    a: Vec<Vec<f64>>,
    c: Vec<f64>,
    n_w: usize,
}

impl Linear {
    fn n(&self) -> usize {
        self.c.len()
    }

    fn apply(&self, w: &Mat<f64>, f: &Mat<f64>) -> (Mat<f64>, Mat<f64>) {
        let x: Vec<f64> = (0..self.n_w)
            .map(|i| w[(i, 0)])
            .chain((0..f.nrows()).map(|i| f[(i, 0)]))
            .collect();
        let y: Vec<f64> = (0..self.n()).map(|i| self.c[i] + dot(&self.a[i], &x)).collect();
        let nf = self.n() - self.n_w;
        (
            Mat::from_fn(self.n_w, 1, |i, _| y[i]),
            Mat::from_fn(nf, 1, |i, _| y[self.n_w + i]),
        )
    }

    /// The exact fixed point (I − A) x = c by Gaussian elimination.
    fn fixed_point(&self) -> Vec<f64> {
        let n = self.n();
        let m = nalgebra::DMatrix::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } - self.a[i][j]);
        let x = m.lu().solve(&nalgebra::DVector::from_column_slice(&self.c)).unwrap();
        x.iter().copied().collect()
    }
}

/// A deterministic pseudo-random number in [−1, 1).
fn rnd(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
}

/// A linear map with spectral radius ≤ `rho` (a random matrix scaled by its ∞-norm).
fn contraction(n: usize, n_w: usize, rho: f64, seed: u64) -> Linear {
    let mut s = seed;
    let mut a: Vec<Vec<f64>> = (0..n).map(|_| (0..n).map(|_| rnd(&mut s)).collect()).collect();
    let norm = a
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    a.iter_mut().flatten().for_each(|v| *v *= rho / norm);
    let c = (0..n).map(|_| rnd(&mut s)).collect();
    Linear { a, c, n_w }
}

/// Runs the mixed (window Some(m)) or plain (None) iteration from 0 until ‖r‖ ≤ tol; returns
/// the state, the number of G evaluations and the mixing counts.
fn run(g: &Linear, mu: f64, window: Option<usize>, tol: f64, max: usize) -> (Vec<f64>, usize, AndersonCounts) {
    let nf = g.n() - g.n_w;
    let mut w = Mat::<f64>::zeros(g.n_w, 1);
    let mut f = Mat::<f64>::zeros(nf, 1);
    let mut history = window.map(|m| {
        // W and F of one part must share a shape: pad the shorter one with zeros.
        let rows = g.n_w.max(nf);
        AndersonHistory::new(m, mu, rows, 1)
    });
    let mut coord = AndersonCoordinator::new(MAX_CONDITION);
    let pad = |m: &Mat<f64>, rows: usize| Mat::from_fn(rows, 1, |i, _| if i < m.nrows() { m[(i, 0)] } else { 0.0 });
    for it in 1..=max {
        let (gw, gf) = g.apply(&w, &f);
        let r: f64 = (0..g.n_w)
            .map(|i| (gw[(i, 0)] - w[(i, 0)]).powi(2))
            .chain((0..nf).map(|i| (gf[(i, 0)] - f[(i, 0)]).powi(2)))
            .sum::<f64>()
            .sqrt();
        if r <= tol {
            let x = (0..g.n_w)
                .map(|i| w[(i, 0)])
                .chain((0..nf).map(|i| f[(i, 0)]))
                .collect();
            return (x, it, coord.counts);
        }
        match history.as_mut() {
            None => {
                for i in 0..g.n_w {
                    w[(i, 0)] += mu * (gw[(i, 0)] - w[(i, 0)]);
                }
                for i in 0..nf {
                    f[(i, 0)] += mu * (gf[(i, 0)] - f[(i, 0)]);
                }
            }
            Some(h) => {
                let rows = g.n_w.max(nf);
                let (mut sw, mut sf) = (pad(&w, rows), pad(&f, rows));
                h.record(&sw, &sf, &pad(&gw, rows), &pad(&gf, rows));
                let step = coord.decide(&h.partials(), false);
                h.apply(&step, &mut sw, &mut sf);
                w = Mat::from_fn(g.n_w, 1, |i, _| sw[(i, 0)]);
                f = Mat::from_fn(nf, 1, |i, _| sf[(i, 0)]);
            }
        }
    }
    panic!("no convergence in {max} evaluations");
}

#[test]
fn same_fixed_point_as_plain_relaxation() {
    // W is a third of the state and enters the least squares only through its effect on F.
    let g = contraction(30, 10, 0.95, 7);
    let exact = g.fixed_point();
    let (plain, n_plain, _) = run(&g, 0.8, None, 1e-12, 5000);
    let (mixed, n_mixed, counts) = run(&g, 0.8, Some(5), 1e-12, 5000);
    let err = |x: &[f64]| x.iter().zip(&exact).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    // ‖x − x*‖ ≤ ‖r‖ / (1 − ρ) = 1e-12 / 0.05 for both.
    assert!(
        err(&plain) < 1e-10 && err(&mixed) < 1e-10,
        "{} {}",
        err(&plain),
        err(&mixed)
    );
    assert!(counts.mixed > 0);
    assert!(n_mixed < n_plain, "Anderson {n_mixed} vs plain {n_plain} evaluations");
}

#[test]
fn a_linear_problem_of_dimension_at_most_m_converges_in_m_plus_one_steps() {
    for (d, m, mu) in [(4, 4, 1.0), (5, 6, 0.8), (6, 6, 0.5)] {
        // Spectral radius up to 0.9 (plain relaxation would need hundreds of steps).
        let g = contraction(d, 0, 0.9, 11 + d as u64);
        let r0 = g.c.iter().map(|v| v * v).sum::<f64>().sqrt();
        // ≤ m + 1 steps = m + 2 evaluations of G (the last one only measures the residual).
        // The tolerance 1e-9 ‖r₀‖ leaves round-off of the normal equations room (cond ≤ 1e10).
        let (_, evals, counts) = run(&g, mu, Some(m), 1e-9 * r0, m + 2);
        assert!(evals <= m + 2, "d = {d}, m = {m}: {evals} evaluations");
        assert_eq!(counts.restarts, 0);
    }
}

#[test]
fn split_parts_sum_to_the_whole() {
    // The coordinator sees the sum of the parts' partials: cutting the state changes nothing
    // but the order of the additions.
    let (rows, m) = (6, 3);
    let mut seed = 3;
    let states: Vec<(Mat<f64>, Mat<f64>)> = (0..5)
        .map(|_| {
            (
                Mat::from_fn(rows, 2, |_, _| rnd(&mut seed)),
                Mat::from_fn(rows, 2, |_, _| rnd(&mut seed)),
            )
        })
        .collect();
    let mut whole = AndersonHistory::new(m, 0.7, rows, 2);
    let mut parts = [
        AndersonHistory::new(m, 0.7, rows, 1),
        AndersonHistory::new(m, 0.7, rows, 1),
    ];
    let col = |x: &Mat<f64>, j: usize| Mat::from_fn(rows, 1, |r, _| x[(r, j)]);
    for k in 0..4 {
        let (s, g) = (&states[k], &states[k + 1]);
        whole.record(&s.0, &s.1, &g.0, &g.1);
        for (j, p) in parts.iter_mut().enumerate() {
            p.record(&col(&s.0, j), &col(&s.1, j), &col(&g.0, j), &col(&g.1, j));
        }
    }
    let w = whole.partials();
    let mut sum = parts[0].partials();
    sum.add(&parts[1].partials());
    assert_eq!(w.k, m, "the ring keeps the last m of 3 differences");
    for (a, b) in w
        .gram
        .iter()
        .chain(&w.projection)
        .zip(sum.gram.iter().chain(&sum.projection))
    {
        assert!((a - b).abs() <= 1e-14 * a.abs().max(1.0), "{a} vs {b}");
    }
    // And the Gram matrix kept column by column equals the one recomputed from scratch.
    let mut fresh = AndersonHistory::new(m, 0.7, rows, 2);
    for k in 1..4 {
        let (s, g) = (&states[k], &states[k + 1]);
        fresh.record(&s.0, &s.1, &g.0, &g.1);
    }
    let f = fresh.partials();
    assert_eq!(f.k, 2);
    assert_eq!(
        &w.gram[4..6],
        &f.gram[0..2],
        "newest two differences, same Gram entries"
    );
}

#[test]
fn safeguard_falls_back_to_plain_when_the_mixed_step_made_the_residual_grow() {
    let mut c = AndersonCoordinator::new(MAX_CONDITION);
    let p = |r2: f64| GramPartials {
        k: 1,
        // Powers of 2 so that γ = 2/4 comes out exact.
        gram: vec![4.0],
        projection: vec![2.0],
        residual2: r2,
    };
    assert_eq!(c.decide(&p(1.0), false), AndersonStep::Mix(vec![0.5]));
    // The mixed step's residual is larger: plain step.
    assert_eq!(c.decide(&p(1.5), false), AndersonStep::Plain);
    // After a plain step growth is not the mixing's doing: mix again.
    assert_eq!(c.decide(&p(2.0), false), AndersonStep::Mix(vec![0.5]));
    // Decreasing after a mixed step: keep mixing.
    assert_eq!(c.decide(&p(1.0), false), AndersonStep::Mix(vec![0.5]));
    assert_eq!(
        c.counts,
        AndersonCounts {
            mixed: 3,
            safeguarded: 1,
            restarts: 0
        }
    );
}

#[test]
fn restart_when_ill_conditioned_not_finite_or_the_map_changed() {
    let mut c = AndersonCoordinator::new(MAX_CONDITION);
    // Two nearly parallel differences: scaled Gram [[1, 1−ε], [1−ε, 1]], condition ≈ 2/ε.
    let eps = 1e-12;
    let nearly = GramPartials {
        k: 2,
        gram: vec![1.0, 1.0 - eps, 1.0 - eps, 1.0],
        projection: vec![1.0, 1.0],
        residual2: 1.0,
    };
    assert_eq!(c.decide(&nearly, false), AndersonStep::Restart);
    // Same with a comfortable angle: solved.
    let fine = GramPartials {
        gram: vec![1.0, 0.5, 0.5, 1.0],
        ..nearly.clone()
    };
    let AndersonStep::Mix(g) = c.decide(&fine, false) else {
        panic!("expected a mixed step")
    };
    // [[1, .5], [.5, 1]] γ = [1, 1] → γ = [2/3, 2/3].
    assert!(g.iter().all(|v| (v - 2.0 / 3.0).abs() < 1e-14), "{g:?}");
    assert_eq!(c.decide(&fine, true), AndersonStep::Restart);
    let nan = GramPartials {
        residual2: f64::NAN,
        ..fine.clone()
    };
    assert_eq!(c.decide(&nan, false), AndersonStep::Restart);
    assert_eq!(c.counts.restarts, 3);

    // A history told to restart forgets its differences but not its last iterate.
    let z = Mat::<f64>::zeros(2, 1);
    let one = Mat::<f64>::from_fn(2, 1, |_, _| 1.0);
    let two = Mat::<f64>::from_fn(2, 1, |_, _| 2.0);
    let mut h = AndersonHistory::new(3, 1.0, 2, 1);
    h.record(&z, &z, &one, &one);
    h.record(&one, &one, &two, &two);
    assert_eq!(h.len(), 1);
    let (mut w, mut f) = (one.clone(), one.clone());
    h.apply(&AndersonStep::Restart, &mut w, &mut f);
    assert!(h.is_empty());
    assert_eq!((w[(0, 0)], f[(1, 0)]), (2.0, 2.0), "a plain step s + μ r");
    h.record(&two, &two, &two, &two);
    assert_eq!(h.len(), 1, "the next record forms a difference with the kept iterate");
}

/// Coordinates mixed beside the state give the state the fields mix to: fields W = B_W λ,
/// F = B_F λ of coordinates λ on a basis that grows (new coordinates start at 0) and is once
/// rotated (B U, Uᵀ λ: the same fields), under the fixed point λ ↦ A λ + c. Recording the
/// force residuals alone gives the same sums and steps, bit for bit.
#[test]
fn coordinates_mix_as_the_fields_do() {
    let (n, cols, cap, window, mu) = (9, 3, 6, 3, 0.8);
    let mut seed = 77u64;
    let mut r = |rows: usize, c: usize| Mat::<f64>::from_fn(rows, c, |_, _| rnd(&mut seed));
    let (b_w, b_f) = (r(n, cap), r(n, cap));
    let a = r(cap, cap) * 0.1;
    let c = r(cap, cols);
    let mut history = AndersonHistory::new(window, mu, n, cols).with_coordinates(cap);
    // The same iterates recorded by their force residuals alone.
    let mut by_residual = AndersonHistory::new(window, mu, n, cols).with_coordinates(cap);
    let mut coordinator = AndersonCoordinator::new(MAX_CONDITION);
    let mut basis = (b_w.clone(), b_f.clone());
    let mut lam = Mat::<f64>::zeros(2, cols);
    for it in 0..12 {
        // The basis grows by one coordinate at iterations 3 and 6, and rotates at 8.
        let p = lam.nrows();
        if it == 3 || it == 6 {
            let mut grown = Mat::<f64>::zeros(p + 1, cols);
            grown.as_mut().subrows_mut(0, p).copy_from(&lam);
            lam = grown;
        }
        let p = lam.nrows();
        if it == 8 {
            let q = r(p, p).qr().compute_Q();
            history.rotate_coordinates(0, p, q.as_ref());
            by_residual.rotate_coordinates(0, p, q.as_ref());
            lam = q.transpose() * &lam;
            basis = (basis.0.as_ref().subcols(0, p) * &q, basis.1.as_ref().subcols(0, p) * &q);
        }
        let fields = |l: &Mat<f64>| {
            let p = l.nrows();
            (basis.0.as_ref().subcols(0, p) * l, basis.1.as_ref().subcols(0, p) * l)
        };
        let image = a.as_ref().subrows(0, p).subcols(0, p) * &lam + c.as_ref().subrows(0, p);
        let (s_w, s_f) = fields(&lam);
        let (g_w, g_f) = fields(&image);
        history.record(&s_w, &s_f, &g_w, &g_f);
        history.record_coordinates(lam.as_ref(), image.as_ref());
        by_residual.record_residual(&(&g_f - &s_f));
        by_residual.record_coordinates(lam.as_ref(), image.as_ref());
        assert_eq!(by_residual.partials(), history.partials(), "iteration {it}: same sums");
        let step = coordinator.decide(&history.partials(), false);
        let (mut w, mut f) = (s_w.clone(), s_f.clone());
        history.apply(&step, &mut w, &mut f);
        // A restart step restarts a history once: apply_coordinates on `history` repeats it.
        let mut next = Mat::<f64>::zeros(p, cols);
        history.apply_coordinates(&step, next.as_mut());
        let mut again = Mat::<f64>::zeros(p, cols);
        by_residual.apply_coordinates(&step, again.as_mut());
        assert!(again == next, "iteration {it}: same coordinates");
        let (nw, nf) = fields(&next);
        let scale = w.norm_max().max(f.norm_max());
        // The same affine combination, one evaluated on coordinates and mapped, the other on
        // the mapped vectors: round-off of sums of a few O(1) terms.
        assert!((&nw - &w).norm_max() <= 1e-12 * scale, "iteration {it}: W");
        assert!((&nf - &f).norm_max() <= 1e-12 * scale, "iteration {it}: F");
        lam = next;
    }
    assert!(coordinator.counts.mixed > 3, "{:?}", coordinator.counts);
}

#[test]
fn the_ring_gives_what_differences_stored_one_by_one_give() {
    // A plain re-statement of the history: every iterate's p = s + μ r and r_F kept in a list,
    // the last `window` differences taken afresh, the Gram matrix, the projections and the mixed
    // state computed from them. Through full and partial windows, plain steps and restarts, the
    // ring must give the same numbers bit for bit: its differences are the same subtractions of the
    // same stored values, its sums the same dot products in the same order.
    let (rows, cols, mu) = (7, 3, 0.8);
    let mut seed = 11;
    let mut field = |scale: f64| Mat::from_fn(rows, cols, |_, _| scale * rnd(&mut seed));
    let sub = |a: &Mat<f64>, b: &Mat<f64>| Mat::from_fn(rows, cols, |r, c| a[(r, c)] - b[(r, c)]);
    let dot_cols = |a: &Mat<f64>, b: &Mat<f64>| {
        (0..cols)
            .map(|j| dot(a.col_as_slice(j), b.col_as_slice(j)))
            .sum::<f64>()
    };
    for window in [1, 2, 4] {
        let mut h = AndersonHistory::new(window, mu, rows, cols);
        let (mut s_w, mut s_f) = (field(1.0), field(1.0));
        // The naive history: (p_w, p_f, r_f) per iterate since the last restart's iterate.
        let mut kept: Vec<(Mat<f64>, Mat<f64>, Mat<f64>)> = Vec::new();
        for it in 0..17 {
            let scale = 0.8f64.powi(it);
            let (g_w, g_f) = (field(scale), field(scale));
            h.record(&s_w, &s_f, &g_w, &g_f);
            let r_f = sub(&g_f, &s_f);
            let p =
                |s: &Mat<f64>, g: &Mat<f64>| Mat::from_fn(rows, cols, |r, c| s[(r, c)] + mu * (g[(r, c)] - s[(r, c)]));
            kept.push((
                p(&s_w, &g_w),
                Mat::from_fn(rows, cols, |r, c| s_f[(r, c)] + mu * r_f[(r, c)]),
                r_f,
            ));
            let k = (kept.len() - 1).min(window);
            let last = &kept[kept.len() - k - 1..];
            let dr: Vec<Mat<f64>> = last.windows(2).map(|x| sub(&x[1].2, &x[0].2)).collect();
            let parts = h.partials();
            assert_eq!(parts.k, k, "window {window}, iteration {it}");
            let r_n = &last[k].2;
            for i in 0..k {
                assert_eq!(parts.projection[i], dot_cols(&dr[i], r_n), "projection {i}");
                for j in 0..k {
                    // Entry (i, j) was summed when the newer of the two was recorded.
                    let (new, old) = if i > j { (i, j) } else { (j, i) };
                    assert_eq!(parts.gram[j * k + i], dot_cols(&dr[new], &dr[old]), "Gram ({i}, {j})");
                }
            }
            assert_eq!(parts.residual2, dot_cols(r_n, r_n));
            let step = match it % 7 {
                3 => AndersonStep::Plain,
                5 => AndersonStep::Restart,
                // Coefficients well away from zero, so that every difference shows in the mix.
                _ => AndersonStep::Mix((0..k).map(|i| 0.3 - 0.05 * i as f64).collect()),
            };
            h.apply(&step, &mut s_w, &mut s_f);
            let gamma = match &step {
                AndersonStep::Mix(g) => g.clone(),
                _ => Vec::new(),
            };
            for (s, part) in [(&s_w, 0), (&s_f, 1)] {
                let pick = |x: &(Mat<f64>, Mat<f64>, Mat<f64>)| if part == 0 { x.0.clone() } else { x.1.clone() };
                let mut expected = pick(&last[k]);
                for (i, g) in gamma.iter().enumerate() {
                    let d = sub(&pick(&last[i + 1]), &pick(&last[i]));
                    for c in 0..cols {
                        for r in 0..rows {
                            expected[(r, c)] -= g * d[(r, c)];
                        }
                    }
                }
                assert_eq!(s, &expected, "mixed state, window {window}, iteration {it}");
            }
            if let AndersonStep::Restart = step {
                kept.drain(..kept.len() - 1);
            }
        }
    }
}
