//! Monolithic incremental reference solver of the same discrete problem as the LATIN solver
//! (docs/method.md, "The discrete problem", "The interface mass" and "Cross-points").
//!
//! **Discrete problem.** All subdomains' QUA8 stiffnesses are assembled in one global numbering
//! in which the node pairs of *perfect* interfaces are merged (union–find, as
//! [`crate::glued::GluedNumbering`] but over perfect interfaces only) while the two nodes of
//! a *contact* pair stay separate and are coupled node to node. Copies of one merged node pair on
//! several contact interfaces (cross-points where perfect interfaces meet a contact interface)
//! are one merged contact pair whose weight is the sum of the copies' weights. Per merged contact
//! pair m (nodes A on side a, B on side b, normal n out of a, tangent t = (−n_y, n_x), gap g0,
//! friction f) and time point t_i, with λ the nodal contact force on side a (N; −λ acts on b):
//! - equilibrium on free dofs: K u = f(t_i) + Σ_m (λ_m on A, −λ_m on B);
//! - g = (u_B − u_A)·n + g0 ≥ 0, λ_n = λ·n ≤ 0, λ_n g = 0;
//! - backward-Euler Coulomb on the slip increment Δs = (u_B − u_A)·t − (u_B − u_A)(t_{i−1})·t
//!   (the jump before t_0 is zero): |λ_t| ≤ f|λ_n|, and Δs = 0 or λ_t = f|λ_n| sign Δs (the
//!   friction on side a has the sign of the slip increment, as in [`glissade_mechanics::laws::contact`]).
//!
//! Prescribed displacements are imposed strongly (eliminated); loads are Σ LoadCase.force·φ(t_i).
//!
//! **Solver.** Per time point, semi-smooth Newton on the (non-symmetric) Alart–Curnier
//! augmented Lagrangian, unknowns (u_free, λ_n, λ_t per merged pair), with the complementarity
//! functions written in force units:
//! C_n = λ_n − min(0, ν), ν = λ_n + r g;
//! C_t = λ_t − proj_[−τ, τ](λ_t + r Δs), τ = f·max(0, −ν);
//! r_m = r_factor · E_m · W_m / h_Γ (E_m the mean Young modulus of the two sides, W_m the merged
//! weight, h_Γ = 1.5 × the largest pair weight of the interface = the edge length of a uniform
//! edge mesh: GetFEM's r·α_i; in axisymmetry each weight over its 2πr, a length again). Each step is warm-started from the previous one. Steps are
//! globalised by backtracking on ψ = ‖[R_u; C]‖² (full steps whenever they decrease ψ; without
//! it, full steps cycle between two all-slip active sets at load reversals of the small
//! three-layer scene). A step is tried by [`Attempt`]s in turn, each from the previous converged
//! state (see [`ReferenceOptions::attempts`]): first with the monotone line search and
//! `max_newton_iterations`; then, if that fails (or a factorisation fails), with a non-monotone
//! line search and a larger budget; then with r scaled by each of `fallback_r_factors`.
//! Every attempt solves the same step (same loads, same friction history, same pairs), so the
//! attempt that converges only changes how the solution is found.
//!
//! Why a step can need the non-monotone attempt: where many pairs sit at the edge of their law
//! in the solution (separated pairs with a gap near zero, e.g. near a clamp where the plies of a
//! laminate leave each other with a gap growing like x²; or a stick zone whose shear is close to
//! f|λ_n| when a slip front sweeps it), a pair's status is only decided once the iterate is more
//! accurate than its margin. Full steps then flip tens of pairs back and forth, and the monotone
//! test cuts steps to 1/64–1/256 with one to five status changes per iteration, so a slip front
//! of a few hundred pairs does not fit in 50 iterations, whatever r. Letting ψ rise against the
//! largest of the last iterates' values accepts longer steps: on the 4-ply laminate of the tests
//! (fixtures/laminate*.toml) it solves in tens of iterations a step that the five monotone
//! attempts do not solve in 250, and the variant without pressure in a few hundred.
//!
//! Each Newton step solves J [Δu; Δλ] = −[R_u; C] with J = [K_ff Bᵀ; C_u C_λ] (Bᵀ the fixed
//! contact coupling, C_u with ≤ 4 entries per row, C_λ 2 × 2 blocks), by one of
//! ([`LinearSolver`]):
//! - `SparseLu`: faer's sparse LU of the whole J. The pattern keeps every λ unknown, so it is
//!   fixed: one symbolic factorisation serves every Newton iteration and every step.
//! - `Condensed` (default): block elimination. K_ff is factorised once (sparse Cholesky), the
//!   contact-dof rows of Z = K_ff⁻¹ Bᵀ are computed once, and each iteration solves the dense
//!   Schur complement S = C_λ − C_u Z (2 unknowns per merged pair) plus two sparse solves. Same
//!   Newton systems as `SparseLu` (iterates equal up to round-off), but measured on the
//!   stratified scene (N = 100, 45 000 dofs, 480 merged pairs, release): 83 s against 956 s for
//!   the same 837 Newton iterations (one numeric sparse LU of J costs about 1.1 s). Falls back to
//!   `SparseLu` when K_ff is not positive definite (a body held only through contact).
//!
//! **Parts held only by contact across a gap.** K_ff is factorised (sparse Cholesky) once,
//! whichever linear solver is chosen; where it is not positive definite a part, or one of its
//! rigid motions, is held by nothing but contact. If such a scene has pairs with an open initial
//! gap (g0 > 0), the first Newton step from zero (those pairs separated) would be singular: the part
//! floats until its gaps close. Step 0 then starts with every such pair closed and stuck
//! (λ_n = −(F_s + r·g0), see `Problem::initial_state`), so its first Newton step is the linear
//! solve with every pair in contact; the pairs that are open in the solution open in the
//! following iterations. The discrete problem and the checks are unchanged.
//!
//! J is singular where the active contact constraints are linearly dependent: where contact pairs
//! close a cycle of node copies (parts cut into sectors at the same angles in two layers, contact
//! on the cuts and between the layers: four pairs around each cross-point, whose jumps sum to zero),
//! a force circulating around the cycle balances at every node, so with every pair of the cycle
//! in contact the multipliers are not unique. A step whose solve fails or is not finite is then
//! solved once more with a small shift of the λ diagonal (a proximal step in λ, see
//! `Problem::newton_step`); the residual and the checks are unchanged, so only the route differs.
//!
//! **Convergence** (per step, all ≤ `tolerance`), against the scene's scales F_s (N) and U_s (mm)
//! of [`Scales::of`], the same for every step and for [`verify`]: F_s = max(P, E_max·U_d), U_s =
//! max(U_d, P/E_min), with P the largest total applied load Σ|f| over the time points, U_d the
//! largest prescribed displacement or |g0|, E_min, E_max the extreme Young moduli (and a floor of
//! a strain of 1e-12 over the scene's size, so that both stay positive for a scene without load).
//! They come from the scene alone, never from the solution checked, and a time point of zero load
//! (an unloaded laminate, where the pairs sit at λ ≈ 0 and g ≈ 0) is checked against the same
//! scales as the loaded ones:
//! equilibrium ‖K u − f − contact‖_∞,free / F_s; penetration max(0, −g)/U_s; tension
//! max(0, λ_n)/F_s; complementarity min(|λ_n|/F_s, |g|/U_s); cone max(0, |λ_t| − f|λ_n|)/F_s;
//! slip direction min(|Δs|/U_s, |λ_t − f|λ_n| sign Δs|/F_s). Only the part of a residual, a gap
//! or a slip increment beyond its round-off ([`ROUND_OFF`] times the magnitudes of the
//! terms it is computed from) counts: a cantilever bent by a rigid rotation of tens of mm has
//! terms of K u a million times the loads, whose round-off is above 1e-10 of the loads.
//!
//! A converged step whose displacement exceeds [`DISPLACEMENT_BOUND`] times the scene's size and
//! [`LOAD_DISPLACEMENT_BOUND`] times U_s, or
//! whose nodal forces (K u, supports and contact) exceed [`FORCE_BOUND`] times F_s, ends the run
//! with [`ReferenceError::Implausible`] naming the step: small residuals against the scene's
//! scales cannot be reached by such a solution unless the problem is singular.
//!
//! **Output** per interface in the layout of [`InterfaceFields`] (traction = nodal force /
//! weight). A contact copy carries the share w_p/W_m of its merged pair's force (all copies have
//! the same traction, so each copy satisfies the law with its own weight, and the copies' nodal
//! forces sum to the merged force). A perfect copy carries the interface force left at its nodes
//! after the contact forces: per merged node group, the vertex forces r_v = (K_s u_s − f_s)(node)
//! − contact forces are distributed over the perfect copies joining the group's subdomain nodes by
//! the minimum of Σ_e w_e |F_e|² (unique on a tree; where copies form a loop the circulating part
//! is indeterminate and this picks the one of least M-norm). If a group's dofs are prescribed, the
//! support reaction (Σ_v r_v) is indeterminate between the subdomains and is shared equally.

pub mod glued;
mod newton;
mod numbering;
mod output;
mod sparse;
mod verify;

pub use glissade_mechanics::scales::{Scales, DISPLACEMENT_BOUND, FORCE_BOUND, LOAD_DISPLACEMENT_BOUND, ROUND_OFF};
pub use verify::{verify, Checks};

use faer::Mat;
use glissade_mechanics::assembly::AssemblyError;
use glissade_mechanics::laws::{dot, Status};
use glissade_mechanics::local::InterfaceFields;
use glissade_mechanics::model::Model;
use newton::Problem;
use output::postprocess;

pub(crate) const NONE: usize = usize::MAX;

/// Settings of [`solve_reference`].
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceOptions {
    /// Relative tolerance of every convergence check (see the module docs).
    pub tolerance: f64,
    /// Newton iterations (linear solves) of each monotone attempt at a step (see [`Self::attempts`]).
    pub max_newton_iterations: usize,
    /// r = r_factor · E · W / h.
    pub r_factor: f64,
    /// Factors applied to `r_factor` when a step is restarted after a failed attempt.
    pub fallback_r_factors: Vec<f64>,
    /// Linear solver of the Newton steps.
    pub linear_solver: LinearSolver,
    /// Step halvings of the backtracking line search (0: full Newton steps only).
    pub line_search_halvings: usize,
    /// Iterates whose largest ψ the Armijo test of the non-monotone attempt compares with.
    pub nonmonotone_window: usize,
    /// Newton iterations of the non-monotone attempt (0: no such attempt).
    pub nonmonotone_iterations: usize,
}

/// One way of solving a time step: Newton from the previous converged state with this r factor,
/// line search and iteration budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attempt {
    /// r = r_factor · E · W / h.
    pub r_factor: f64,
    /// The Armijo test compares with the largest ψ of the last `window` iterates (1: monotone).
    pub window: usize,
    /// Newton iterations (linear solves) at most.
    pub max_iterations: usize,
}

impl std::fmt::Display for Attempt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let search = if self.window <= 1 {
            "monotone line search".to_string()
        } else {
            format!("non-monotone line search over {} iterates", self.window)
        };
        write!(
            f,
            "r factor {}, {search}, {} iterations",
            self.r_factor, self.max_iterations
        )
    }
}

/// An attempt that did not converge: how many iterations it ran and the worst relative
/// violation of the convergence checks at its last iterate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FailedAttempt {
    pub attempt: Attempt,
    pub iterations: usize,
    pub violation: f64,
}

impl ReferenceOptions {
    /// The attempts at a step, in the order they are tried: the monotone line search at
    /// `r_factor` with `max_newton_iterations`; the non-monotone one with
    /// `nonmonotone_iterations` (if not 0); the monotone one at each of `fallback_r_factors`
    /// (× `r_factor`).
    pub fn attempts(&self) -> Vec<Attempt> {
        let plain = |r_factor| Attempt {
            r_factor,
            window: 1,
            max_iterations: self.max_newton_iterations,
        };
        let mut out = vec![plain(self.r_factor)];
        if self.nonmonotone_iterations > 0 {
            out.push(Attempt {
                r_factor: self.r_factor,
                window: self.nonmonotone_window,
                max_iterations: self.nonmonotone_iterations,
            });
        }
        out.extend(self.fallback_r_factors.iter().map(|&k| plain(k * self.r_factor)));
        out
    }
}

/// How each Newton step's linear system is solved (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinearSolver {
    /// Sparse Cholesky of K_ff once + dense Schur complement on the λ unknowns (falls back to
    /// `SparseLu` when K_ff is not positive definite).
    Condensed,
    /// faer sparse LU of the whole Jacobian, symbolic factorisation reused.
    SparseLu,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-10,
            max_newton_iterations: 50,
            r_factor: 1.0,
            fallback_r_factors: vec![0.1, 0.01, 10.0, 100.0],
            linear_solver: LinearSolver::Condensed,
            line_search_halvings: 8,
            nonmonotone_window: 30,
            nonmonotone_iterations: 1000,
        }
    }
}

/// Contact quantities of one contact interface, per pair p and time point i.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactSolution {
    /// Nodal contact force on side a (N, global x/y): (2·n_pairs) × (N+1), entry 2p + c.
    pub lambda: Mat<f64>,
    /// Jump [u] = u_b − u_a (mm): (2·n_pairs) × (N+1).
    pub jump: Mat<f64>,
    /// Status at index p + n_pairs·i: the Alart–Curnier active set at convergence (ν > 0:
    /// separated; |λ_t + rΔs| ≤ τ: stick; else slip). A tie ν = 0 (e.g. unloaded and g0 = 0)
    /// counts as contact, as C_N = 0 does in [`glissade_mechanics::laws::contact`].
    pub status: Vec<Status>,
}

/// The reference solution over all time points.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceSolution {
    /// Displacement of every subdomain: n_dofs(s) × (N+1) (mm).
    pub u: Vec<Mat<f64>>,
    /// Traces and tractions of every interface of the model (perfect and contact), in the layout
    /// of LATIN's [`InterfaceFields`] (mm, N/mm).
    pub interfaces: Vec<InterfaceFields>,
    /// `Some` for contact interfaces, indexed like `model.interfaces`.
    pub contact: Vec<Option<ContactSolution>>,
    /// Newton iterations (linear solves) per time point, over all attempts of the step.
    pub newton_iterations: Vec<usize>,
    /// r factor of the attempt that converged, per time point.
    pub r_factor_used: Vec<f64>,
    /// The linear solver actually used (`Condensed` may fall back to `SparseLu`).
    pub linear_solver: LinearSolver,
}

/// Errors of the reference solver.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReferenceError {
    #[error(transparent)]
    Assembly(#[from] AssemblyError),
    #[error("interface {interface}, pair {pair}: both nodes are joined by perfect interfaces, so the contact pair has no jump")]
    ContactPairGlued { interface: usize, pair: usize },
    #[error("interface {interface}, pair {pair}: every dof of the merged contact pair is prescribed (such pairs must be left out)")]
    ConstrainedPair { interface: usize, pair: usize },
    #[error("interface {interface}, pair {pair}: copies of one merged contact pair disagree on {what}")]
    InconsistentCopies {
        interface: usize,
        pair: usize,
        what: &'static str,
    },
    #[error("sparse matrix: {0}")]
    Sparse(String),
    #[error("time step {step} (t = {time}): Newton did not converge in {} iterations; worst relative violation {violation:e} (tolerance {tolerance:e}); tried: {}", .tried.iter().map(|a| a.iterations).sum::<usize>(), tried_list(.tried))]
    NotConverged {
        step: usize,
        time: f64,
        /// Every attempt, in the order tried.
        tried: Vec<FailedAttempt>,
        /// The smallest of the attempts' worst relative violations.
        violation: f64,
        tolerance: f64,
    },
    /// A step converged to a solution of absurd size ([`Scales::implausible`]).
    #[error("time step {step} (t = {time}): the solution is implausible: {reason}")]
    Implausible { step: usize, time: f64, reason: String },
}

fn tried_list(tried: &[FailedAttempt]) -> String {
    tried
        .iter()
        .map(|a| format!("{} (worst {:.2e})", a.attempt, a.violation))
        .collect::<Vec<_>>()
        .join("; ")
}

/// What [`solve_reference_steps`] solved: the solution over the time points 0..k solved (all of
/// them unless a step failed) and the failure of step k, if any.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceRun {
    /// The solution over the steps solved: its matrices have one column per solved time point.
    pub solution: ReferenceSolution,
    /// Why step `solution.newton_iterations.len()` was not solved.
    pub failure: Option<ReferenceError>,
}

/// Solves the model by semi-smooth Newton on the Alart–Curnier augmented Lagrangian, time point
/// by time point (see the module docs for the discrete problem, the convergence checks and the
/// output conventions).
pub fn solve_reference(model: &Model, opts: &ReferenceOptions) -> Result<ReferenceSolution, ReferenceError> {
    let run = solve_reference_steps(model, opts)?;
    match run.failure {
        None => Ok(run.solution),
        Some(e) => Err(e),
    }
}

/// As [`solve_reference`], but a step that does not converge ends the run with the steps solved
/// before it (an error in setting up the problem is still an `Err`).
pub fn solve_reference_steps(model: &Model, opts: &ReferenceOptions) -> Result<ReferenceRun, ReferenceError> {
    solve_reference_watched(model, opts, &mut |_| {})
}

/// One time point solved by [`solve_reference_watched`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSolved {
    /// Time points solved so far (this one included) and in all.
    pub solved: usize,
    pub of: usize,
    /// Newton iterations of this time point, every attempt counted.
    pub newton_iterations: usize,
}

/// As [`solve_reference_steps`], calling `on_step` after each time point solved (a progress
/// display).
pub fn solve_reference_watched(
    model: &Model,
    opts: &ReferenceOptions,
    on_step: &mut dyn FnMut(StepSolved),
) -> Result<ReferenceRun, ReferenceError> {
    let pb = Problem::new(model, opts.linear_solver)?;
    let nt = model.time.n_points();
    let attempts = opts.attempts();
    let r_max = attempts.iter().map(|a| a.r_factor).fold(0.0, f64::max);
    let mut state = pb.initial_state(r_max);
    let mut slip_prev = vec![0.0; pb.pairs.len()];
    let mut states = Vec::with_capacity(nt);
    let mut newton_iterations = Vec::with_capacity(nt);
    let mut r_factor_used = Vec::with_capacity(nt);
    let mut failure = None;
    for i in 0..nt {
        let t = model.time.t(i);
        let (f, prescribed) = pb.loads(t);
        let mut total = 0;
        let mut tried = Vec::new();
        let mut done = None;
        for attempt in &attempts {
            match pb.newton(&state, &f, &prescribed, &slip_prev, attempt, opts) {
                Ok((s, it, status)) => {
                    total += it;
                    done = Some((s, status, attempt.r_factor));
                    break;
                }
                Err((iterations, violation)) => {
                    total += iterations;
                    tried.push(FailedAttempt {
                        attempt: *attempt,
                        iterations,
                        violation,
                    });
                }
            }
        }
        let Some((s, status, rf)) = done else {
            failure = Some(ReferenceError::NotConverged {
                step: i,
                time: t,
                violation: tried.iter().map(|a| a.violation).fold(f64::INFINITY, f64::min),
                tried,
                tolerance: opts.tolerance,
            });
            break;
        };
        let u = pb.displacement(&s.x, &prescribed);
        let (u_max, f_max) = pb.magnitudes(&s.x, &u);
        if let Some(reason) = pb.scales.implausible(u_max, f_max) {
            failure = Some(ReferenceError::Implausible {
                step: i,
                time: t,
                reason,
            });
            break;
        }
        for (m, sp) in slip_prev.iter_mut().enumerate() {
            *sp = dot(pb.jump(m, &u), pb.pairs[m].tangent);
        }
        newton_iterations.push(total);
        r_factor_used.push(rf);
        states.push((u, s.x.clone(), status, f));
        state = s;
        on_step(StepSolved {
            solved: i + 1,
            of: nt,
            newton_iterations: total,
        });
    }
    Ok(ReferenceRun {
        solution: postprocess(&pb, states, newton_iterations, r_factor_used),
        failure,
    })
}
