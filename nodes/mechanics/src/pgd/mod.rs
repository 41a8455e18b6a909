//! The PGD linear stage of one subdomain (docs/pgd.md).
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
//! ([`PgdCriterion::Increment`], [`PgdCriterion::IncrementSvd`]), the accumulated correction
//! target − q₀ ([`PgdCriterion::Accumulated`]) or the target's own step since the previous linear
//! stage, targetₙ − targetₙ₋₁ ([`PgdCriterion::Forcing`], [`PgdCriterion::ForcingSvd`]). Because the residual r is
//! M-orthogonal to the basis, ‖δ‖² = ‖r‖² + Σ_i w_i |λ_i − λ_i(previous)|² exactly.
//!
//! The increment δ = targetₙ − L λ(previous) holds the previous residual: ‖δ‖ ≥ ‖rₙ₋₁‖ roughly,
//! so ξ ≤ ξ₀ asks the residual to fall ten times (ξ₀ = 0.1) at every linear stage, which no
//! bounded basis does: the increment criteria add modes at every iteration. The forcing
//! criterion asks only ‖rₙ‖ ≤ ξ₀ ‖targetₙ − targetₙ₋₁‖: the residual may stay while the LATIN
//! step is larger, and must fall with it. At a fixed point of the iteration the step is zero, so
//! the basis is enriched until the residual is round-off: the limit is the exact one.
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

mod basis;
#[cfg(test)]
mod tests;

/// How the PGD enrichment criterion ξ is measured (docs/pgd.md, "The enrichment criterion decides the limit").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PgdCriterion {
    /// ξ relative to the increment δ.
    Increment,
    /// ξ relative to the accumulated correction.
    Accumulated,
    /// Relative to the increment, plus SVD compression of the basis.
    IncrementSvd,
    /// Relative to the step of the micro problem's own target since the previous linear stage,
    /// ‖q̂ₙ − q̂ₙ₋₁‖ (micro 1) or ‖k⁻𝔼(w̃ₙ − w̃ₙ₋₁)‖ (micro 2): a forcing term. The linear stage
    /// is solved to a tolerance that follows the LATIN step, as in an inexact fixed point.
    Forcing,
    /// The forcing criterion, plus SVD compression of the basis (tolerance ξ₀,₁ times the step).
    ForcingSvd,
}

impl PgdCriterion {
    /// Every criterion, in the order of [`PgdCriterion::key`].
    pub const ALL: [PgdCriterion; 5] = [
        PgdCriterion::Increment,
        PgdCriterion::Accumulated,
        PgdCriterion::IncrementSvd,
        PgdCriterion::Forcing,
        PgdCriterion::ForcingSvd,
    ];

    /// The basis is compressed before every micro problem 1 but the first.
    pub fn compresses(self) -> bool {
        matches!(self, PgdCriterion::IncrementSvd | PgdCriterion::ForcingSvd)
    }

    /// ξ is relative to the target's own step ([`PgdCriterion::Forcing`]).
    pub fn forcing(self) -> bool {
        matches!(self, PgdCriterion::Forcing | PgdCriterion::ForcingSvd)
    }

    /// The criterion's name in a scene (`solver.pgd.criterion`) and in a report variant.
    pub fn key(self) -> &'static str {
        match self {
            PgdCriterion::Increment => "increment",
            PgdCriterion::Accumulated => "accumulated",
            PgdCriterion::IncrementSvd => "increment-svd",
            PgdCriterion::Forcing => "forcing",
            PgdCriterion::ForcingSvd => "forcing-svd",
        }
    }
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
    /// The criterion's reference norm (‖δ‖, ‖target − q₀‖ or ‖targetₙ − targetₙ₋₁‖).
    pub reference_norm: f64,
}

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
    /// The targets of the last micro 1 and micro 2 (n_b × (N+1); empty unless the criterion is
    /// [`PgdCriterion::Forcing`]).
    target1: Mat<f64>,
    target2: Mat<f64>,
    /// U_k of the last compression (free modes before × kept), for the Anderson coordinates.
    rotation: Option<Mat<f64>>,
    /// Floating-point operations of this stage's own kernels ([`PgdStage::flops`]).
    flops: u64,
}

/// The buffer of a previous target: n_b × (N+1) with the forcing criterion, else empty.
fn forcing_buffer(n_b: usize, nt: usize, criterion: PgdCriterion) -> Mat<f64> {
    if criterion.forcing() {
        Mat::zeros(n_b, nt)
    } else {
        Mat::zeros(0, 0)
    }
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
            target1: forcing_buffer(n_b, nt, settings.criterion),
            target2: forcing_buffer(n_b, nt, settings.criterion),
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
        let step = self.target_step(true);
        self.residual_minus_projection(true);
        let report = self.enrich(solver, true, self.settings.xi1, step);
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
        let step = self.target_step(false);
        self.residual_minus_projection(false);
        self.enrich(solver, false, self.settings.xi2, step)
    }

    /// With the forcing criterion: ‖target − previous target‖² (the target in `resid`), and the
    /// target kept for the next linear stage; None otherwise.
    fn target_step(&mut self, first: bool) -> Option<f64> {
        if !self.settings.criterion.forcing() {
            return None;
        }
        let (n_b, nt) = (self.resid.nrows(), self.resid.ncols());
        self.count(4 * n_b * nt + 2 * nt);
        let prev = if first { &mut self.target1 } else { &mut self.target2 };
        let mut s = 0.0;
        for i in 0..nt {
            let mut c = 0.0;
            for r in 0..n_b {
                let d = self.resid[(r, i)] - prev[(r, i)];
                c += self.mass[r] * d * d;
                prev[(r, i)] = self.resid[(r, i)];
            }
            s += self.tw[i] * c;
        }
        Some(s)
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
}
