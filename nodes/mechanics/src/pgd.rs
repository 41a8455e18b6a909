//! The PGD linear stage of one subdomain (DESIGN §3, "PGD linear stage").
//!
//! Every boundary state of the iteration is admissible: W = A_E M q + W_d, F = q − k⁻W for a
//! right-hand side q = F + k⁻W (N/mm²); the initial state s₀ = (W_d, −k⁻W_d) has q₀ = 0. PGD
//! approximates q in a reduced basis {L_k} (n_b vectors, M-orthonormal: L_jᵀ M L_k = δ_jk)
//! with time functions λ_k(t): q ≈ Σ L_k λ_k, so that
//!
//!   W = W_d + Σ Z_k λ_k,  F = −k⁻W_d + Σ G_k λ_k,  Z_k = A_E M L_k,  G_k = L_k − k⁻Z_k,
//!
//! and every pair (Z_k, G_k) is admissible (subdomain equilibrium without loads). One basis per
//! subdomain serves micro problems 1 and 2:
//! - micro 1 (target q̂ = F̂ + k⁻Ŵ): λ¹ = Lᵀ M q̂. This is the update of all time functions on the
//!   current basis: with δ = q̂ − Σ L_k λ¹_k(previous) the increment, Δλ solves
//!   (LᵀML) Δλ = LᵀM δ(t) for every t (LᵀML = I), and λ¹ = λ¹(previous) + Δλ.
//! - micro 2 (target k⁻𝔼w̃): λ² = (Lᵀ M k⁻𝔼) w̃, a thin product. With `macro_modes` the basis
//!   starts with the macro modes 𝔼 (M-orthonormal already), frozen, and micro 2 is exact.
//!
//! Each micro problem is a correction of its own previous solution (micro 1 of q̂ − q̂_prev,
//! micro 2 of k⁻𝔼(w̃ − w̃_prev)): these increments vanish as the iteration converges, so a
//! criterion relative to them forces the linear stage's error to vanish too. (The full state
//! s_n mixes micro 1 and micro 2: q̂ − q_n tends to k⁻𝔼w̃, not to 0, when the coarse problem is on.)
//!
//! Criterion (space-time norm ‖x‖² = Σ_i w_i x_iᵀ M x_i, trapezoid w_i):
//! ξ = ‖target − Σ L_k λ_k‖ / ‖reference‖, where the reference is the increment δ
//! ([`PgdCriterion::Increment`], [`PgdCriterion::IncrementSvd`]) or the accumulated correction
//! target − q₀ ([`PgdCriterion::Accumulated`]). Because the residual r is M-orthogonal to the
//! basis, ‖δ‖² = ‖r‖² + Σ_i w_i |λ_i − λ_i(previous)|² exactly.
//!
//! Enrichment when ξ > ξ₀: the rank-one fit r ≈ L λ(t) by alternating fixed point (λ from L,
//! L from λ), L made M-orthogonal to the basis (Gram–Schmidt twice) and M-normalised, then
//! Z = A_E M L, G = L − k⁻Z, and the new coordinates λ = Lᵀ M r.
//!
//! Compression ([`PgdStage::compress`]): the accumulated time functions of the state,
//! λˢ = Lᵀ M (F + k⁻W), are factored Λ W^½ = U Σ Vᵀ; the basis becomes L' = L U, Z' = Z U,
//! G' = G U (admissible: Z is linear in L), λ' = Uᵀ λ, and the trailing modes whose Σ σ² stays
//! within tol² are dropped: the state changes by exactly that admissible part. Frozen macro modes
//! are never compressed.

use crate::anderson::AndersonHistory;
use crate::linear::SubdomainSolver;
use crate::simd::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// How the PGD enrichment criterion ξ is measured (DESIGN §3, "Where PGD pays").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PgdCriterion {
    /// ξ relative to the increment δ.
    Increment,
    /// ξ relative to the accumulated correction.
    Accumulated,
    /// Relative to the increment, plus SVD compression of the basis.
    IncrementSvd,
}

/// PGD settings of the linear stage.
#[derive(Debug, Clone, PartialEq)]
pub struct PgdParams {
    pub enabled: bool,
    /// ξ₀ of micro problem 1.
    pub xi1: f64,
    /// ξ₀ of micro problem 2.
    pub xi2: f64,
    pub criterion: PgdCriterion,
    /// The macro modes 𝔼 start the basis, frozen (micro 2 exact).
    pub macro_modes: bool,
    /// New modes per micro problem and iteration, at most.
    pub max_new_modes: usize,
}

impl PgdParams {
    /// The settings a subdomain's PGD linear stage runs with.
    pub fn settings(&self) -> PgdSettings {
        PgdSettings {
            criterion: self.criterion,
            xi1: self.xi1,
            xi2: self.xi2,
            macro_modes: self.macro_modes,
            max_new_modes: self.max_new_modes,
        }
    }
}

impl Default for PgdParams {
    fn default() -> Self {
        Self {
            enabled: false,
            xi1: 0.1,
            xi2: 0.01,
            criterion: PgdCriterion::Increment,
            macro_modes: false,
            max_new_modes: 1,
        }
    }
}

/// Settings of a PGD linear stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PgdSettings {
    pub criterion: PgdCriterion,
    /// ξ₀ of micro problem 1.
    pub xi1: f64,
    /// ξ₀ of micro problem 2.
    pub xi2: f64,
    /// The macro modes 𝔼 are frozen leading modes of the basis: micro 2 is exact.
    pub macro_modes: bool,
    /// At most this many new modes per micro problem and linear stage (≥ 1).
    pub max_new_modes: usize,
}

/// What one PGD micro problem did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PgdReport {
    /// ξ after the update on the previous basis, before enrichment.
    pub xi_update: f64,
    /// ξ at the end of the micro problem.
    pub xi: f64,
    pub new_modes: usize,
    /// The criterion's reference norm (‖δ‖ or ‖target − q₀‖).
    pub reference_norm: f64,
}

/// Below this fraction of the target's norm a residual is round-off: no enrichment.
const ROUND_OFF: f64 = 1e-13;
/// Alternating fixed point of the rank-one fit: at most this many sweeps, stop when the fit's
/// norm changes by less than this fraction.
const FIT_SWEEPS: usize = 8;
const FIT_TOL: f64 = 1e-6;

/// The reduced basis of one subdomain and the time functions of its last micro problems.
pub struct PgdStage {
    pub settings: PgdSettings,
    mass: Vec<f64>,
    k: Vec<f64>,
    tw: Vec<f64>,
    n_frozen: usize,
    p: usize,
    /// L, Z, G (n_b × capacity); the first p columns are the basis.
    l: Mat<f64>,
    z: Mat<f64>,
    g: Mat<f64>,
    /// 𝔼ᵀ M G (n_m × capacity): macro forces per mode.
    emg: Mat<f64>,
    /// Lᵀ M k⁻ 𝔼 (capacity × n_m): micro 2's projection.
    lmke: Mat<f64>,
    /// k⁻ 𝔼 and M 𝔼 (n_b × n_m).
    ke: Mat<f64>,
    me: Mat<f64>,
    /// 𝔼ᵀ M (−k⁻ W_d) (n_m × (N+1)): macro forces of s₀.
    mf0: Mat<f64>,
    /// Time functions of micro 1 and micro 2 (capacity × (N+1)), their previous values and sum.
    lambda1: Mat<f64>,
    lambda2: Mat<f64>,
    prev: Mat<f64>,
    sum: Mat<f64>,
    /// Coordinates λˢ of the current state s − s₀ on the basis (capacity × (N+1)): the relaxed
    /// or mixed combination of the linear stages' λ¹ + λ² ([`PgdStage::relax_state`], Anderson
    /// coordinates), rotated with the basis by a compression.
    state: Mat<f64>,
    /// First basis column added or changed since [`PgdStage::take_changed`].
    changed_from: usize,
    /// Residual and M-weighted scratch (n_b × (N+1)).
    resid: Mat<f64>,
    mq: Mat<f64>,
    fit_l: Vec<f64>,
    fit_lam: Vec<f64>,
    /// ‖δ‖ of the last micro 1 (scale of the compression tolerance).
    last_delta1: f64,
    /// U_k of the last compression (free modes before × kept), for the Anderson coordinates.
    rotation: Option<Mat<f64>>,
    /// Floating-point operations of this stage's own kernels ([`PgdStage::flops`]).
    flops: u64,
}

impl PgdStage {
    /// An empty basis (or the frozen macro modes) for `solver`'s subdomain; `time_weights` are
    /// the trapezoid weights w_i. Buffers are allocated here, for a basis of up to n_b modes.
    pub fn new(solver: &mut SubdomainSolver, time_weights: &[f64], settings: PgdSettings) -> Self {
        let layout = &solver.op.layout;
        let (n_b, nt, n_m) = (solver.n_boundary(), solver.w_d.ncols(), solver.n_macro());
        assert_eq!(time_weights.len(), nt, "one time weight per time point");
        let mass = layout.mass.clone();
        let k = layout.k.clone();
        let cap = n_b.max(1);
        let ke = Mat::from_fn(n_b, n_m, |r, c| k[r] * solver.e[(r, c)]);
        let me = Mat::from_fn(n_b, n_m, |r, c| mass[r] * solver.e[(r, c)]);
        let mut mf0 = Mat::<f64>::zeros(n_m, nt);
        let kwd = Mat::from_fn(n_b, nt, |r, i| -k[r] * solver.w_d[(r, i)]);
        matmul(
            mf0.as_mut(),
            Accum::Replace,
            me.transpose(),
            kwd.as_ref(),
            1.0,
            Par::Seq,
        );
        let mut stage = Self {
            settings,
            mass,
            k,
            tw: time_weights.to_vec(),
            n_frozen: 0,
            p: 0,
            l: Mat::zeros(n_b, cap),
            z: Mat::zeros(n_b, cap),
            g: Mat::zeros(n_b, cap),
            emg: Mat::zeros(n_m, cap),
            lmke: Mat::zeros(cap, n_m),
            ke,
            me,
            mf0,
            lambda1: Mat::zeros(cap, nt),
            lambda2: Mat::zeros(cap, nt),
            prev: Mat::zeros(cap, nt),
            sum: Mat::zeros(cap, nt),
            state: Mat::zeros(cap, nt),
            changed_from: 0,
            resid: Mat::zeros(n_b, nt),
            mq: Mat::zeros(n_b, nt),
            fit_l: vec![0.0; n_b],
            fit_lam: vec![0.0; nt],
            last_delta1: 0.0,
            rotation: None,
            flops: 0,
        };
        if settings.macro_modes && n_m > 0 {
            // 𝔼 is M-orthonormal (per interface, interfaces on disjoint entries).
            stage.l.as_mut().subcols_mut(0, n_m).copy_from(solver.e.as_ref());
            solver.boundary_response_into(stage.l.as_ref().subcols(0, n_m), stage.z.as_mut().subcols_mut(0, n_m));
            for c in 0..n_m {
                stage.finish_mode(c);
            }
            stage.p = n_m;
            stage.n_frozen = n_m;
        }
        stage.flops = 0;
        stage
    }

    /// Floating-point operations made by this stage's own kernels since construction: dense
    /// products (m × k by k × n: 2mkn) and the passes over entries of n_b × (N+1), n_b, p × (N+1)
    /// or N+1 arrays (one flop per multiply, add, subtract or divide of an entry); scalar
    /// operations outside those passes, square roots and the SVD of the compression are not
    /// counted. The boundary responses of new modes (Z = A_E M L) are the solver's:
    /// [`SubdomainSolver::flops`] counts them, so a PGD linear stage makes the sum of both.
    pub fn flops(&self) -> u64 {
        self.flops
    }

    fn count(&mut self, flops: usize) {
        self.flops += flops as u64;
    }

    /// Number of modes (frozen ones included).
    pub fn n_modes(&self) -> usize {
        self.p
    }

    /// Number of frozen macro modes at the head of the basis.
    pub fn n_frozen(&self) -> usize {
        self.n_frozen
    }

    /// The basis L, Z, G (n_b × p).
    pub fn l(&self) -> MatRef<'_, f64> {
        self.l.as_ref().subcols(0, self.p)
    }
    pub fn z(&self) -> MatRef<'_, f64> {
        self.z.as_ref().subcols(0, self.p)
    }
    pub fn g(&self) -> MatRef<'_, f64> {
        self.g.as_ref().subcols(0, self.p)
    }

    /// Time functions of the last micro 1 and micro 2 (p × (N+1)).
    pub fn lambda1(&self) -> MatRef<'_, f64> {
        self.lambda1.as_ref().subrows(0, self.p)
    }
    pub fn lambda2(&self) -> MatRef<'_, f64> {
        self.lambda2.as_ref().subrows(0, self.p)
    }

    /// Coordinates λˢ of the current state on the basis (p × (N+1)): s = s₀ + Σ (Z_k, G_k) λˢ_k.
    pub fn state(&self) -> MatRef<'_, f64> {
        self.state.as_ref().subrows(0, self.p)
    }
    pub fn state_mut(&mut self) -> MatMut<'_, f64> {
        self.state.as_mut().subrows_mut(0, self.p)
    }

    /// The force residual of the state, r_F = F(s₁ + s₂) − F(s) = G (λ¹ + λ² − λˢ)
    /// (n_b × (N+1)), what Anderson's least-squares problem needs of a state held in mode form:
    /// the particular parts cancel exactly, and neither state is expanded.
    pub fn residual_forces_into(&mut self, mut out: MatMut<'_, f64>) {
        let (p, nt, n_b) = (self.p, self.sum.ncols(), self.g.nrows());
        self.count(2 * p * nt + 2 * n_b * p * nt);
        for i in 0..nt {
            for m in 0..p {
                self.sum[(m, i)] = self.lambda1[(m, i)] + self.lambda2[(m, i)] - self.state[(m, i)];
            }
        }
        if p == 0 {
            out.fill(0.0);
            return;
        }
        matmul(
            out.as_mut(),
            Accum::Replace,
            self.g.as_ref().subcols(0, p),
            self.sum.as_ref().subrows(0, p),
            1.0,
            Par::Seq,
        );
    }

    /// Records the state's coordinates λˢ and those of the last linear stage's solution
    /// s₁ + s₂ (λ¹ + λ²) in `history`, after it recorded the same iterate's fields
    /// ([`AndersonHistory::record_coordinates`]).
    pub fn record_coordinates(&mut self, history: &mut AndersonHistory) {
        let (p, nt) = (self.p, self.sum.ncols());
        self.count(p * nt);
        for i in 0..nt {
            for m in 0..p {
                self.sum[(m, i)] = self.lambda1[(m, i)] + self.lambda2[(m, i)];
            }
        }
        history.record_coordinates(self.state.as_ref().subrows(0, p), self.sum.as_ref().subrows(0, p));
    }

    /// The mixing `step` of `history` on the state's coordinates λˢ
    /// ([`AndersonHistory::apply_coordinates`]).
    pub fn apply_coordinates(&mut self, history: &mut AndersonHistory, step: &crate::anderson::AndersonStep) {
        let (p, nt, k) = (self.p, self.state.ncols(), history.len());
        if let crate::anderson::AndersonStep::Mix(_) = step {
            self.count(2 * k * p * nt);
        }
        history.apply_coordinates(step, self.state.as_mut().subrows_mut(0, p));
    }

    /// The relaxation in coordinates: λˢ ← μ (λ¹ + λ²) + (1 − μ) λˢ (a new mode's λˢ is 0).
    pub fn relax_state(&mut self, mu: f64) {
        let (p, nt) = (self.p, self.state.ncols());
        self.count(4 * p * nt);
        for i in 0..nt {
            for m in 0..p {
                let image = self.lambda1[(m, i)] + self.lambda2[(m, i)];
                self.state[(m, i)] = mu * image + (1.0 - mu) * self.state[(m, i)];
            }
        }
    }

    /// The first basis column added or changed since the last call (p when none); the next call
    /// starts from p.
    pub fn take_changed(&mut self) -> usize {
        let first = self.changed_from.min(self.p);
        self.changed_from = self.p;
        first
    }

    /// Space-time norm² Σ_i w_i Σ_r M_r x_ri² of an n_b × (N+1) field.
    pub fn norm2(&self, x: MatRef<'_, f64>) -> f64 {
        let mut s = 0.0;
        for i in 0..x.ncols() {
            let mut c = 0.0;
            for r in 0..x.nrows() {
                c += self.mass[r] * x[(r, i)] * x[(r, i)];
            }
            s += self.tw[i] * c;
        }
        s
    }

    /// Σ_i w_i Σ_k (a_ki − b_ki)² over the first p rows (b = None: zero).
    fn coord_norm2(&self, a: &Mat<f64>, b: Option<&Mat<f64>>) -> f64 {
        let mut s = 0.0;
        for i in 0..a.ncols() {
            let mut c = 0.0;
            for m in 0..self.p {
                let d = a[(m, i)] - b.map_or(0.0, |b| b[(m, i)]);
                c += d * d;
            }
            s += self.tw[i] * c;
        }
        s
    }

    /// Micro problem 1 on the basis: λ¹ = Lᵀ M q̂ (the exact least-squares update), then
    /// enrichment while ξ > ξ₀,₁. Call [`PgdStage::expand_into`] for the fields.
    pub fn micro1(&mut self, solver: &mut SubdomainSolver, q_hat: MatRef<'_, f64>) -> PgdReport {
        let (n_b, nt, p) = (q_hat.nrows(), q_hat.ncols(), self.p);
        // M q̂, λ¹ = Lᵀ (M q̂), and the residual q̂ − L λ¹.
        self.count(n_b * nt + 2 * p * n_b * nt + 2 * n_b * p * nt);
        self.prev
            .as_mut()
            .subrows_mut(0, p)
            .copy_from(self.lambda1.as_ref().subrows(0, p));
        for i in 0..nt {
            for r in 0..n_b {
                self.mq[(r, i)] = self.mass[r] * q_hat[(r, i)];
            }
        }
        matmul(
            self.lambda1.as_mut().subrows_mut(0, p),
            Accum::Replace,
            self.l.as_ref().subcols(0, p).transpose(),
            self.mq.as_ref(),
            1.0,
            Par::Seq,
        );
        self.resid.copy_from(q_hat);
        self.residual_minus_projection(true);
        let report = self.enrich(solver, true, self.settings.xi1);
        self.last_delta1 = report.reference_norm;
        report
    }

    /// Micro problem 2 on the basis: λ² = (Lᵀ M k⁻𝔼) w̃, then (unless the macro modes are in the
    /// basis, where it is exact) enrichment while ξ > ξ₀,₂.
    pub fn micro2(&mut self, solver: &mut SubdomainSolver, w_tilde: MatRef<'_, f64>) -> PgdReport {
        let p = self.p;
        let (n_b, n_m, nt) = (self.l.nrows(), w_tilde.nrows(), w_tilde.ncols());
        // λ² = (Lᵀ M k⁻𝔼) w̃.
        self.count(2 * p * n_m * nt);
        self.prev
            .as_mut()
            .subrows_mut(0, p)
            .copy_from(self.lambda2.as_ref().subrows(0, p));
        matmul(
            self.lambda2.as_mut().subrows_mut(0, p),
            Accum::Replace,
            self.lmke.as_ref().subrows(0, p),
            w_tilde,
            1.0,
            Par::Seq,
        );
        if self.settings.macro_modes {
            return PgdReport::default();
        }
        // The target k⁻𝔼 w̃ and the residual k⁻𝔼 w̃ − L λ².
        self.count(2 * n_b * n_m * nt + 2 * n_b * p * nt);
        matmul(
            self.resid.as_mut(),
            Accum::Replace,
            self.ke.as_ref(),
            w_tilde,
            1.0,
            Par::Seq,
        );
        self.residual_minus_projection(false);
        self.enrich(solver, false, self.settings.xi2)
    }

    /// resid −= L λ (λ = λ¹ or λ²).
    fn residual_minus_projection(&mut self, first: bool) {
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
    /// of micro 1 (`first`) or micro 2, with their previous values in `prev`.
    fn enrich(&mut self, solver: &mut SubdomainSolver, first: bool, xi0: f64) -> PgdReport {
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
        };
        let reference = reference2.sqrt();
        let xi_of = |r2: f64| if reference > 0.0 { r2.sqrt() / reference } else { 0.0 };
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
    fn finish_mode(&mut self, m: usize) {
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

    /// The fields of the last micro problems: W = W_d + Z λ, F = −k⁻W_d + G λ with
    /// λ = λ¹ (+ λ² when `with_micro2`).
    pub fn expand_into(
        &mut self,
        w_d: MatRef<'_, f64>,
        mut w: MatMut<'_, f64>,
        mut f: MatMut<'_, f64>,
        with_micro2: bool,
    ) {
        let p = self.p;
        let (n_b, nt) = (w_d.nrows(), w_d.ncols());
        // λ¹ + λ², W_d + Z λ, G λ and − k⁻W_d.
        self.count(if with_micro2 { p * nt } else { 0 } + 2 * (2 * n_b * p * nt) + 2 * n_b * nt);
        let mut sum = self.sum.as_mut().subrows_mut(0, p);
        sum.copy_from(self.lambda1.as_ref().subrows(0, p));
        if with_micro2 {
            for i in 0..sum.ncols() {
                for m in 0..p {
                    sum[(m, i)] += self.lambda2[(m, i)];
                }
            }
        }
        let sum = self.sum.as_ref().subrows(0, p);
        w.copy_from(w_d);
        matmul(
            w.as_mut(),
            Accum::Add,
            self.z.as_ref().subcols(0, p),
            sum,
            1.0,
            Par::Seq,
        );
        matmul(
            f.as_mut(),
            Accum::Replace,
            self.g.as_ref().subcols(0, p),
            sum,
            1.0,
            Par::Seq,
        );
        for i in 0..w_d.ncols() {
            for r in 0..w_d.nrows() {
                f[(r, i)] -= self.k[r] * w_d[(r, i)];
            }
        }
    }

    /// Macro forces 𝔼ᵀ M F₁ of the last micro 1 (n_m × (N+1)), from the modes' 𝔼ᵀ M G.
    pub fn macro_forces_into(&mut self, mut out: MatMut<'_, f64>) {
        self.count(2 * out.nrows() * self.p * out.ncols());
        out.copy_from(self.mf0.as_ref());
        matmul(
            out.as_mut(),
            Accum::Add,
            self.emg.as_ref().subcols(0, self.p),
            self.lambda1.as_ref().subrows(0, self.p),
            1.0,
            Par::Seq,
        );
    }

    /// Compression of the free modes (module docs) with the tolerance ξ₀,₁·‖δ₁‖ of the last
    /// micro 1: the state (w, f), which must lie in the span (W = W_d + Z λ, F = −k⁻W_d + G λ),
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

#[cfg(test)]
mod tests {
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
}
