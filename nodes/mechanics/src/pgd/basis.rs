//! The basis of a [`PgdStage`]: its enrichment (criterion, rank-one fit, a new M-orthonormal
//! mode and its admissible pair) and its compression; the formulas are in the `pgd` module docs.

use super::{PgdCriterion, PgdReport, PgdStage};
use crate::anderson::AndersonHistory;
use crate::linear::SubdomainSolver;
use crate::simd::matmul;
use faer::{Accum, Mat, MatMut, Par};

/// Below this fraction of the target's norm a residual is round-off: no enrichment.
const ROUND_OFF: f64 = 1e-13;
/// Alternating fixed point of the rank-one fit: at most this many sweeps, stop when the fit's
/// norm changes by less than this fraction.
const FIT_SWEEPS: usize = 8;
const FIT_TOL: f64 = 1e-6;

impl PgdStage {
    /// resid −= L λ (λ = λ¹ or λ²).
    pub(super) fn residual_minus_projection(&mut self, first: bool) {
        let lambda = if first { &self.lambda1 } else { &self.lambda2 };
        matmul(
            self.resid.as_mut(),
            Accum::Add,
            self.l.as_ref().subcols(0, self.p),
            lambda.as_ref().subrows(0, self.p),
            -1.0,
            Par::Seq,
        );
    }

    /// The criterion and the enrichment loop on the residual in `resid`, for the time functions
    /// of micro 1 (`first`) or micro 2, with their previous values in `prev`; `step` is
    /// ‖targetₙ − targetₙ₋₁‖² with the forcing criterion.
    pub(super) fn enrich(
        &mut self,
        solver: &mut SubdomainSolver,
        first: bool,
        xi0: f64,
        step: Option<f64>,
    ) -> PgdReport {
        let (n_b, nt) = (self.resid.nrows(), self.resid.ncols());
        // Two coordinate norms and the residual's norm.
        self.count(2 * (3 * self.p * nt + 2 * nt) + 3 * n_b * nt + 2 * nt);
        let lambda = if first { &self.lambda1 } else { &self.lambda2 };
        let in_basis = self.coord_norm2(lambda, None);
        let moved = self.coord_norm2(lambda, Some(&self.prev));
        let mut r2 = self.norm2(self.resid.as_ref());
        let target2 = r2 + in_basis;
        let reference2 = match self.settings.criterion {
            PgdCriterion::Accumulated => target2,
            PgdCriterion::Increment | PgdCriterion::IncrementSvd => r2 + moved,
            PgdCriterion::Forcing | PgdCriterion::ForcingSvd => step.unwrap_or(r2 + moved),
        };
        let reference = reference2.sqrt();
        // A residual against a zero reference (a stationary target under the forcing criterion)
        // is infinitely too large; the round-off guard below stops the enrichment.
        let xi_of = |r2: f64| match (reference > 0.0, r2 > 0.0) {
            (true, _) => r2.sqrt() / reference,
            (false, true) => f64::INFINITY,
            (false, false) => 0.0,
        };
        let mut report = PgdReport {
            xi_update: xi_of(r2),
            xi: xi_of(r2),
            new_modes: 0,
            reference_norm: reference,
        };
        let cap = self.l.ncols();
        while report.xi > xi0
            && report.new_modes < self.settings.max_new_modes
            && self.p < cap
            && r2.sqrt() > ROUND_OFF * target2.sqrt()
        {
            self.fit_rank_one();
            if !self.add_mode(solver) {
                break;
            }
            let m = self.p - 1;
            // Coordinates of the residual on the new mode, the residual losing that part, and
            // its norm.
            self.count(5 * n_b * nt + 3 * n_b * nt + 2 * nt);
            for i in 0..nt {
                let mut c = 0.0;
                for r in 0..self.resid.nrows() {
                    c += self.l[(r, m)] * self.mass[r] * self.resid[(r, i)];
                }
                for r in 0..self.resid.nrows() {
                    self.resid[(r, i)] -= c * self.l[(r, m)];
                }
                let (own, other) = if first {
                    (&mut self.lambda1, &mut self.lambda2)
                } else {
                    (&mut self.lambda2, &mut self.lambda1)
                };
                own[(m, i)] = c;
                other[(m, i)] = 0.0;
                self.prev[(m, i)] = 0.0;
                self.state[(m, i)] = 0.0;
            }
            r2 = self.norm2(self.resid.as_ref());
            report.new_modes += 1;
            report.xi = xi_of(r2);
        }
        report
    }

    /// Rank-one fit of `resid` ≈ l λ(t)ᵀ by alternating fixed point; l into `fit_l`.
    fn fit_rank_one(&mut self) {
        let (n_b, nt) = (self.resid.nrows(), self.resid.ncols());
        // Start from the time column of largest norm.
        self.count(nt * (3 * n_b + 1));
        let mut best = (0, -1.0);
        for i in 0..nt {
            let c: f64 = (0..n_b).map(|r| self.mass[r] * self.resid[(r, i)].powi(2)).sum();
            if self.tw[i] * c > best.1 {
                best = (i, self.tw[i] * c);
            }
        }
        for r in 0..n_b {
            self.fit_l[r] = self.resid[(r, best.0)];
        }
        let mut last = 0.0;
        for _ in 0..FIT_SWEEPS {
            self.count(3 * n_b);
            let ll: f64 = (0..n_b).map(|r| self.mass[r] * self.fit_l[r] * self.fit_l[r]).sum();
            if ll <= 0.0 {
                return;
            }
            // λ = (Lᵀ M r)/‖L‖² and its norm.
            self.count(nt * (3 * n_b + 1) + 3 * nt);
            for i in 0..nt {
                let c: f64 = (0..n_b)
                    .map(|r| self.mass[r] * self.fit_l[r] * self.resid[(r, i)])
                    .sum();
                self.fit_lam[i] = c / ll;
            }
            let lam2: f64 = (0..nt).map(|i| self.tw[i] * self.fit_lam[i] * self.fit_lam[i]).sum();
            if lam2 <= 0.0 {
                return;
            }
            // L = r W λ / ‖λ‖² and the fitted part's norm.
            self.count(nt * (2 + 2 * n_b) + 3 * n_b + 1);
            self.fit_l.fill(0.0);
            for i in 0..nt {
                let c = self.tw[i] * self.fit_lam[i] / lam2;
                for r in 0..n_b {
                    self.fit_l[r] += c * self.resid[(r, i)];
                }
            }
            // ‖l‖²_M ‖λ‖²_w after the sweep is the fitted part's norm²: stop when it settles.
            let fitted = (0..n_b)
                .map(|r| self.mass[r] * self.fit_l[r] * self.fit_l[r])
                .sum::<f64>()
                * lam2;
            if (fitted - last).abs() <= FIT_TOL * fitted {
                return;
            }
            last = fitted;
        }
    }

    /// Appends `fit_l`, M-orthonormalised against the basis, with its admissible pair. False when
    /// it lies in the span of the basis (to round-off).
    fn add_mode(&mut self, solver: &mut SubdomainSolver) -> bool {
        let (n_b, m) = (self.fit_l.len(), self.p);
        // Norm before and after Gram–Schmidt twice against m modes (a weighted dot product and
        // an axpy each).
        self.count(3 * n_b + 2 * m * (3 * n_b + 2 * n_b) + 3 * n_b);
        let dot = |a: &[f64], l: &Mat<f64>, c: usize, mass: &[f64]| -> f64 {
            (0..a.len()).map(|r| mass[r] * a[r] * l[(r, c)]).sum()
        };
        let norm0 = (0..n_b)
            .map(|r| self.mass[r] * self.fit_l[r].powi(2))
            .sum::<f64>()
            .sqrt();
        for _ in 0..2 {
            for c in 0..m {
                let d = dot(&self.fit_l, &self.l, c, &self.mass);
                for r in 0..n_b {
                    self.fit_l[r] -= d * self.l[(r, c)];
                }
            }
        }
        let norm = (0..n_b)
            .map(|r| self.mass[r] * self.fit_l[r].powi(2))
            .sum::<f64>()
            .sqrt();
        // In the span to round-off (or not a number): no new mode.
        if norm.is_nan() || norm <= 1e-10 * norm0 {
            return false;
        }
        self.count(n_b);
        for r in 0..n_b {
            self.l[(r, m)] = self.fit_l[r] / norm;
        }
        solver.boundary_response_into(self.l.as_ref().subcols(m, 1), self.z.as_mut().subcols_mut(m, 1));
        self.finish_mode(m);
        self.p += 1;
        self.changed_from = self.changed_from.min(m);
        true
    }

    /// G = L − k⁻Z, 𝔼ᵀ M G and Lᵀ M k⁻𝔼 of column `m` (L and Z set).
    pub(super) fn finish_mode(&mut self, m: usize) {
        let n_b = self.l.nrows();
        // G = L − k⁻Z, then per macro mode 𝔼ᵀ M G and Lᵀ M k⁻𝔼.
        self.count(2 * n_b + 5 * n_b * self.me.ncols());
        for r in 0..n_b {
            self.g[(r, m)] = self.l[(r, m)] - self.k[r] * self.z[(r, m)];
        }
        for c in 0..self.me.ncols() {
            let (mut emg, mut lmke) = (0.0, 0.0);
            for r in 0..n_b {
                emg += self.me[(r, c)] * self.g[(r, m)];
                lmke += self.l[(r, m)] * self.mass[r] * self.ke[(r, c)];
            }
            self.emg[(c, m)] = emg;
            self.lmke[(m, c)] = lmke;
        }
    }

    /// Compression of the free modes (module docs) with the tolerance ξ₀,₁ times the criterion's
    /// reference of the last micro 1 (‖δ₁‖, or the step with the forcing criterion): the state (w, f), which must lie in the span (W = W_d + Z λ, F = −k⁻W_d + G λ),
    /// loses exactly the truncated admissible part. Returns the number of modes dropped.
    ///
    /// The state's coordinates λˢ and, when given, the coordinates an Anderson history mixes
    /// rotate with the basis: λˢ' = U_kᵀ λˢ on the free modes.
    pub fn compress(&mut self, w: MatMut<'_, f64>, f: MatMut<'_, f64>, history: Option<&mut AndersonHistory>) -> usize {
        let tol = self.settings.xi1 * self.last_delta1;
        let dropped = self.compress_with(w, f, tol);
        if let (Some(history), Some(uk)) = (history, self.rotation.take()) {
            history.rotate_coordinates(self.n_frozen, uk.nrows(), uk.as_ref());
        }
        dropped
    }

    /// As [`PgdStage::compress`] with an explicit tolerance on the norm of the removed part.
    pub fn compress_with(&mut self, mut w: MatMut<'_, f64>, mut f: MatMut<'_, f64>, tol: f64) -> usize {
        let (n_b, nt) = (w.nrows(), w.ncols());
        let (f0, pf) = (self.n_frozen, self.p - self.n_frozen);
        if pf == 0 {
            return 0;
        }
        // M (F + k⁻W), λ = Lᵀ (…) and λ W^½.
        self.count(3 * n_b * nt + 2 * pf * n_b * nt + pf * nt);
        for i in 0..nt {
            for r in 0..n_b {
                self.mq[(r, i)] = self.mass[r] * (f[(r, i)] + self.k[r] * w[(r, i)]);
            }
        }
        let mut lam = Mat::<f64>::zeros(pf, nt);
        matmul(
            lam.as_mut(),
            Accum::Replace,
            self.l.as_ref().subcols(f0, pf).transpose(),
            self.mq.as_ref(),
            1.0,
            Par::Seq,
        );
        let scaled = Mat::from_fn(pf, nt, |m, i| lam[(m, i)] * self.tw[i].sqrt());
        let Ok(svd) = scaled.svd() else {
            return 0;
        };
        let u = svd.U();
        let s = svd.S().column_vector();
        let sigma = |j: usize| if j < s.nrows() { s[j] } else { 0.0 };
        let mut keep = pf;
        let mut dropped2 = 0.0;
        while keep > 0 && dropped2 + sigma(keep - 1).powi(2) <= tol * tol {
            dropped2 += sigma(keep - 1).powi(2);
            keep -= 1;
        }
        if keep == pf {
            return 0;
        }
        let (d, n_m) = (pf - keep, self.emg.nrows());
        // U_dᵀ λ, (Z U_d) and (G U_d) subtracted, then L U_k, Z U_k, G U_k, (𝔼ᵀMG) U_k and
        // U_kᵀ on Lᵀ M k⁻𝔼, λ¹ and λ².
        self.count(
            2 * d * pf * nt
                + 2 * (2 * n_b * pf * d + 2 * n_b * d * nt)
                + 3 * (2 * n_b * pf * keep)
                + 2 * n_m * pf * keep
                + 2 * keep * pf * n_m
                + 2 * (2 * keep * pf * nt),
        );
        // Remove the truncated part: (Z, G) U_d U_dᵀ λ.
        let ud = u.subcols(keep, pf - keep);
        let mut c = Mat::<f64>::zeros(pf - keep, nt);
        matmul(c.as_mut(), Accum::Replace, ud.transpose(), lam.as_ref(), 1.0, Par::Seq);
        let mut zu = Mat::<f64>::zeros(n_b, pf - keep);
        matmul(
            zu.as_mut(),
            Accum::Replace,
            self.z.as_ref().subcols(f0, pf),
            ud,
            1.0,
            Par::Seq,
        );
        matmul(w.as_mut(), Accum::Add, zu.as_ref(), c.as_ref(), -1.0, Par::Seq);
        matmul(
            zu.as_mut(),
            Accum::Replace,
            self.g.as_ref().subcols(f0, pf),
            ud,
            1.0,
            Par::Seq,
        );
        matmul(f.as_mut(), Accum::Add, zu.as_ref(), c.as_ref(), -1.0, Par::Seq);
        // Rotate the kept part: columns L U_k, rows U_kᵀ λ.
        let uk = u.subcols(0, keep).to_owned();
        for mat in [&mut self.l, &mut self.z, &mut self.g] {
            let rotated = mat.as_ref().subcols(f0, pf) * &uk;
            mat.as_mut().subcols_mut(f0, keep).copy_from(&rotated);
        }
        let emg = self.emg.as_ref().subcols(f0, pf) * &uk;
        self.emg.as_mut().subcols_mut(f0, keep).copy_from(&emg);
        for mat in [&mut self.lmke, &mut self.lambda1, &mut self.lambda2, &mut self.state] {
            let rotated = uk.transpose() * mat.as_ref().subrows(f0, pf);
            mat.as_mut().subrows_mut(f0, keep).copy_from(&rotated);
        }
        self.count(2 * keep * pf * nt);
        self.p = f0 + keep;
        self.changed_from = self.changed_from.min(f0);
        self.rotation = Some(uk);
        pf - keep
    }
}
