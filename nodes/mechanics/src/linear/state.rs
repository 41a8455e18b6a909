//! One subdomain's linear stage on full fields, step by step, in the buffers it keeps from one
//! iteration to the next ([`SubdomainFields`]): the subdomain node calls these steps as its
//! messages arrive, the crate's one-thread iteration (`tests/support/latin.rs`) in the same
//! order, so both make the same floating-point operations.

use super::fields::{relax_into, sum_into, sum_relax_into};
use super::solver::SubdomainSolver;
use crate::anderson::{AndersonHistory, AndersonStep, GramPartials};
use faer::Mat;

/// Relaxation μ of iteration `iteration`: 1 at iterations 0 and 1 (the first linear stage from
/// ŝ = 0 and the first from a local stage), `relaxation` from iteration 2 on.
pub fn relaxation_at(iteration: u32, relaxation: f64) -> f64 {
    if iteration <= 1 {
        1.0
    } else {
        relaxation
    }
}

/// How a linear stage ends ([`SubdomainFields::finish`]).
#[derive(Debug, Clone, PartialEq)]
pub enum LinearEnd {
    /// The state s = (W, F) is ready to send.
    State,
    /// Anderson mixing from iteration 2 on: this subdomain's share of the least-squares problem,
    /// to be summed over every subdomain; the state follows the step
    /// ([`SubdomainFields::take_step`]).
    Partials(GramPartials),
}

/// One subdomain's fields of the linear stage, n_b × (N+1) on its boundary (n_m × (N+1) for the
/// macro ones), allocated once: the input q̂ = F̂ + k⁻Ŵ, the solutions s₁ = (W₁, F₁) and
/// s₂ = (W₂, F₂) of micro problems 1 and 2, the state s = (W, F), the macro forces F̂ᴹ and
/// displacements w̃, and the Anderson history when the run mixes. With PGD the subdomain node
/// keeps its state in its basis and uses these fields as its messages' and kernels' buffers.
pub struct SubdomainFields {
    pub q_hat: Mat<f64>,
    pub w1: Mat<f64>,
    pub f1: Mat<f64>,
    pub w2: Mat<f64>,
    pub f2: Mat<f64>,
    pub w: Mat<f64>,
    pub f: Mat<f64>,
    pub w_tilde: Mat<f64>,
    pub macro_forces: Mat<f64>,
    pub anderson: Option<AndersonHistory>,
}

impl SubdomainFields {
    /// Zero fields for `solver`'s boundary and macro columns over `n_times` time points, with
    /// `anderson`'s history or plain relaxation.
    pub fn new(solver: &SubdomainSolver, n_times: usize, anderson: Option<AndersonHistory>) -> Self {
        let z = |rows: usize| Mat::<f64>::zeros(rows, n_times);
        let (n_b, n_m) = (solver.n_boundary(), solver.n_macro());
        Self {
            q_hat: z(n_b),
            w1: z(n_b),
            f1: z(n_b),
            w2: z(n_b),
            f2: z(n_b),
            w: z(n_b),
            f: z(n_b),
            w_tilde: z(n_m),
            macro_forces: z(n_m),
            anderson,
        }
    }

    /// Micro problem 1 from q̂: (W₁, F₁) ([`SubdomainSolver::micro1_into`]).
    pub fn micro1(&mut self, solver: &mut SubdomainSolver) {
        solver.micro1_into(self.q_hat.as_ref(), self.w1.as_mut(), self.f1.as_mut());
    }

    /// The macro forces F̂ᴹ = 𝔼ᵀ M F₁ of micro problem 1 ([`SubdomainSolver::macro_forces_into`]).
    pub fn macro_forces(&mut self, solver: &mut SubdomainSolver) {
        solver.macro_forces_into(self.f1.as_ref(), self.macro_forces.as_mut());
    }

    /// Micro problem 2 from w̃: (W₂, F₂) ([`SubdomainSolver::micro2_into`]).
    pub fn micro2(&mut self, solver: &mut SubdomainSolver) {
        solver.micro2_into(self.w_tilde.as_ref(), self.w2.as_mut(), self.f2.as_mut());
    }

    /// Without the macro problem (w̃ = 0): s₂ = 0, micro problem 2 unsolved.
    pub fn skip_micro2(&mut self) {
        self.w2.fill(0.0);
        self.f2.fill(0.0);
    }

    /// The end of iteration `iteration`'s linear stage, s_new = s₁ + s₂ (into s₁):
    /// - plain relaxation: s ← μ s_new + (1 − μ) s in the same pass (μ of [`relaxation_at`]);
    /// - Anderson mixing: the relaxation, after recording (s, s_new) from iteration 1 on; from
    ///   iteration 2 on s_new is only recorded (summed inside the history's pass) and the
    ///   history's partials returned, s waits for the step.
    pub fn finish(&mut self, iteration: u32, relaxation: f64) -> LinearEnd {
        let mu = relaxation_at(iteration, relaxation);
        let Some(history) = self.anderson.as_mut() else {
            sum_relax_into(
                mu,
                self.w1.as_mut(),
                self.f1.as_mut(),
                self.w2.as_ref(),
                self.f2.as_ref(),
                self.w.as_mut(),
                self.f.as_mut(),
            );
            return LinearEnd::State;
        };
        if iteration >= 2 {
            history.record_sum(&self.w, &self.f, [&self.w1, &self.w2], [&self.f1, &self.f2]);
            return LinearEnd::Partials(history.partials());
        }
        sum_into(self.w1.as_mut(), self.f1.as_mut(), self.w2.as_ref(), self.f2.as_ref());
        if iteration >= 1 {
            history.record(&self.w, &self.f, &self.w1, &self.f1);
        }
        relax_into(mu, self.w1.as_ref(), self.f1.as_ref(), self.w.as_mut(), self.f.as_mut());
        LinearEnd::State
    }

    /// The Anderson step of the iteration whose partials [`Self::finish`] returned: the next s.
    pub fn take_step(&mut self, step: &AndersonStep) {
        let history = self
            .anderson
            .as_mut()
            .expect("a step follows partials, which only a history gives");
        history.apply(step, &mut self.w, &mut self.f);
    }
}
