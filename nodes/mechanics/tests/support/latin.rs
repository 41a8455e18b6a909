//! A LATIN iteration on a whole model in one thread, from the crate's kernels alone (no nodes, no
//! bus): the same calls, in the same order, as the subdomain, coarse and interface nodes make.
//! Shared by the allocation test, the iteration benchmark and the reference crate's tests of the
//! macro problem on curved interfaces (which also switch the macro problem off, mix with
//! Anderson and start from a given ŝ).

// Each user reads a part of it (the test does not read the stage names).
#![allow(dead_code)]

use faer::Mat;
use glissade_mechanics::anderson::{AndersonCoordinator, AndersonHistory, GramPartials, MAX_CONDITION};
use glissade_mechanics::coarse::{Contribution, MacroProblem};
use glissade_mechanics::linear::{default_k0, macro_bases, relax_into, sum_into, sum_relax_into, SubdomainSolver};
use glissade_mechanics::local::{IndicatorSums, InterfaceFields, InterfaceLocal};
use glissade_mechanics::model::{Model, Side};
use std::time::{Duration, Instant};

/// Stages of one iteration, in the order they run.
pub const STAGES: [&str; 6] = [
    "micro problem 1",
    "macro forces",
    "macro problem",
    "micro problem 2 and relaxation",
    "local stage and indicators",
    "gather s, scatter q̂",
];

/// One subdomain's fields, allocated once.
struct SubdomainFields {
    q_hat: Mat<f64>,
    w1: Mat<f64>,
    f1: Mat<f64>,
    w2: Mat<f64>,
    f2: Mat<f64>,
    w: Mat<f64>,
    f: Mat<f64>,
    w_tilde: Mat<f64>,
    macro_forces: Mat<f64>,
    /// Global macro unknown of each of its macro columns.
    columns: Vec<usize>,
}

pub struct Latin {
    pub model: Model,
    pub solvers: Vec<SubdomainSolver>,
    fields: Vec<SubdomainFields>,
    pub coarse: MacroProblem,
    /// Whether the macro problem is solved (else w̃ = 0).
    pub use_coarse: bool,
    pub rhs: Mat<f64>,
    pub locals: Vec<InterfaceLocal>,
    pub interface_fields: Vec<InterfaceFields>,
    time_weights: Vec<f64>,
    pub iteration: usize,
    /// Time spent per stage of [`STAGES`], summed over the iterations run.
    pub stage_time: [Duration; 6],
    /// Anderson mixing (as the subdomain and interface nodes: records from iteration 1, mixes
    /// from iteration 2), or plain relaxation.
    anderson: Option<(Vec<AndersonHistory>, AndersonCoordinator)>,
}

impl Latin {
    /// Builds every subdomain's solver (condensed linear stage), the macro problem and the
    /// interfaces' local-stage state, as the runner does.
    pub fn new(model: Model) -> Self {
        Self::with_dense(model, true)
    }

    /// As [`Latin::new`], with the condensed linear stage (`dense`) or the sparse one.
    pub fn with_dense(model: Model, dense: bool) -> Self {
        Self::with_options(model, dense, true, None)
    }

    /// As [`Latin::with_dense`], with the macro problem solved or not and Anderson mixing over
    /// `anderson` iterates (window) or plain relaxation.
    pub fn with_options(model: Model, dense: bool, use_coarse: bool, anderson: Option<usize>) -> Self {
        let k0 = default_k0(&model);
        let bases = macro_bases(&model);
        let nt = model.time.n_points();
        let solvers: Vec<SubdomainSolver> = (0..model.subdomains.len())
            .map(|s| SubdomainSolver::with_dense(&model, s, &k0, &bases, dense).expect("subdomain operator"))
            .collect();
        let n_modes: Vec<usize> = bases.iter().map(|b| b.len()).collect();
        let slots: Vec<Vec<(usize, usize)>> = solvers
            .iter()
            .map(|s| s.macro_slots.iter().map(|m| (m.interface, m.n_modes)).collect())
            .collect();
        let parts: Vec<Contribution<'_>> = solvers
            .iter()
            .zip(&slots)
            .map(|(s, sl)| Contribution {
                subdomain: s.subdomain,
                interfaces: sl,
                l_e: s.l_e.as_ref(),
            })
            .collect();
        let coarse = MacroProblem::new(&n_modes, &parts).expect("macro problem");
        let fields = solvers
            .iter()
            .zip(&slots)
            .map(|(s, sl)| {
                let z = |r: usize| Mat::<f64>::zeros(r, nt);
                SubdomainFields {
                    q_hat: z(s.n_boundary()),
                    w1: z(s.n_boundary()),
                    f1: z(s.n_boundary()),
                    w2: z(s.n_boundary()),
                    f2: z(s.n_boundary()),
                    w: z(s.n_boundary()),
                    f: z(s.n_boundary()),
                    w_tilde: z(s.n_macro()),
                    macro_forces: z(s.n_macro()),
                    columns: coarse.columns_of(sl),
                }
            })
            .collect();
        let locals = model
            .interfaces
            .iter()
            .enumerate()
            .map(|(i, itf)| InterfaceLocal::new(i, itf, k0[i], nt))
            .collect();
        let interface_fields = model
            .interfaces
            .iter()
            .map(|itf| InterfaceFields::zeros(itf.n_pairs(), nt))
            .collect();
        let mu = model.solver.relaxation;
        let anderson = anderson.map(|window| {
            let histories = solvers
                .iter()
                .map(|s| AndersonHistory::new(window, mu, s.n_boundary(), nt))
                .collect();
            (histories, AndersonCoordinator::new(MAX_CONDITION))
        });
        Self {
            rhs: Mat::zeros(coarse.n(), nt),
            time_weights: model.time.trapezoid_weights(),
            model,
            solvers,
            fields,
            coarse,
            use_coarse,
            locals,
            interface_fields,
            iteration: 0,
            stage_time: [Duration::ZERO; 6],
            anderson,
        }
    }

    /// ŝ := `hat` on every interface, as if a local stage had made it: the next iteration's linear
    /// stage starts from it (relaxed, not the first).
    pub fn start_from(&mut self, hat: &[InterfaceFields]) {
        for (local, h) in self.locals.iter_mut().zip(hat) {
            local.hat = h.clone();
        }
        for (solver, x) in self.solvers.iter().zip(&mut self.fields) {
            for slot in &solver.op.layout.slots {
                self.locals[slot.interface].q_hat_into(slot.side == Side::A, x.q_hat.as_mut(), slot.offset);
            }
        }
        self.iteration = 1;
    }

    /// Σ_sides 𝔼ᵀ M F per macro unknown (rows) and time point for the interface fields `s`, and
    /// the largest of one side's macro forces: the macro problem's constraint, evaluated.
    pub fn macro_balance(&mut self, s: &[InterfaceFields]) -> (Mat<f64>, f64) {
        let mut sum = Mat::<f64>::zeros(self.rhs.nrows(), self.rhs.ncols());
        let mut size = 0.0f64;
        for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
            for slot in &solver.op.layout.slots {
                let f = &s[slot.interface];
                let f = if slot.side == Side::A { &f.f_a } else { &f.f_b };
                x.f.as_mut().subrows_mut(slot.offset, f.nrows()).copy_from(f);
            }
            solver.macro_forces_into(x.f.as_ref(), x.macro_forces.as_mut());
            size = size.max(x.macro_forces.norm_max());
            for j in 0..sum.ncols() {
                for (r, &g) in x.columns.iter().enumerate() {
                    sum[(g, j)] += x.macro_forces[(r, j)];
                }
            }
        }
        (sum, size)
    }

    /// One iteration: linear stage from the stored q̂ (0 at iteration 0), relaxation (μ = 1 at
    /// iterations 0 and 1), local stage and indicators, q̂ for the next one.
    pub fn iterate(&mut self) -> IndicatorSums {
        let n = self.iteration;
        let mu = if n <= 1 { 1.0 } else { self.model.solver.relaxation };
        let mut clock = Instant::now();
        let mut lap = |stage: usize, times: &mut [Duration; 6]| {
            let now = Instant::now();
            times[stage] += now - clock;
            clock = now;
        };
        for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
            solver.micro1_into(x.q_hat.as_ref(), x.w1.as_mut(), x.f1.as_mut());
            lap(0, &mut self.stage_time);
            solver.macro_forces_into(x.f1.as_ref(), x.macro_forces.as_mut());
            lap(1, &mut self.stage_time);
        }
        // The coarse node: rhs = −Σ F̂ᴹ, then w̃ per subdomain.
        self.rhs.fill(0.0);
        for x in &self.fields {
            for j in 0..self.rhs.ncols() {
                for (r, &g) in x.columns.iter().enumerate() {
                    self.rhs[(g, j)] -= x.macro_forces[(r, j)];
                }
            }
        }
        if self.use_coarse {
            self.coarse.solve_in_place(&mut self.rhs);
        } else {
            self.rhs.fill(0.0);
        }
        for x in &mut self.fields {
            for j in 0..self.rhs.ncols() {
                for (r, &g) in x.columns.iter().enumerate() {
                    x.w_tilde[(r, j)] = self.rhs[(g, j)];
                }
            }
        }
        lap(2, &mut self.stage_time);
        match self.anderson.as_mut() {
            None => {
                for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
                    solver.micro2_into(x.w_tilde.as_ref(), x.w2.as_mut(), x.f2.as_mut());
                    sum_relax_into(
                        mu,
                        x.w1.as_mut(),
                        x.f1.as_mut(),
                        x.w2.as_ref(),
                        x.f2.as_ref(),
                        x.w.as_mut(),
                        x.f.as_mut(),
                    );
                }
            }
            Some((histories, coordinator)) => {
                for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
                    solver.micro2_into(x.w_tilde.as_ref(), x.w2.as_mut(), x.f2.as_mut());
                }
                if n >= 2 {
                    let mut sum: Option<GramPartials> = None;
                    for (h, x) in histories.iter_mut().zip(&self.fields) {
                        h.record_sum(&x.w, &x.f, [&x.w1, &x.w2], [&x.f1, &x.f2]);
                        let p = h.partials();
                        match sum.as_mut() {
                            None => sum = Some(p),
                            Some(s) => s.add(&p),
                        }
                    }
                    let step = coordinator.decide(&sum.expect("a subdomain"), false);
                    for (h, x) in histories.iter_mut().zip(&mut self.fields) {
                        h.apply(&step, &mut x.w, &mut x.f);
                    }
                } else {
                    for (h, x) in histories.iter_mut().zip(&mut self.fields) {
                        sum_into(x.w1.as_mut(), x.f1.as_mut(), x.w2.as_ref(), x.f2.as_ref());
                        if n >= 1 {
                            h.record(&x.w, &x.f, &x.w1, &x.f1);
                        }
                        relax_into(mu, x.w1.as_ref(), x.f1.as_ref(), x.w.as_mut(), x.f.as_mut());
                    }
                }
            }
        }
        lap(3, &mut self.stage_time);
        for (solver, x) in self.solvers.iter().zip(&self.fields) {
            for slot in &solver.op.layout.slots {
                self.interface_fields[slot.interface].set_side(slot.side, slot.offset, x.w.as_ref(), x.f.as_ref());
            }
        }
        lap(5, &mut self.stage_time);
        let mut sums = IndicatorSums::default();
        let solver_params = &self.model.solver;
        for (i, (local, s)) in self.locals.iter_mut().zip(&self.interface_fields).enumerate() {
            let itf = &self.model.interfaces[i];
            sums.add(&local.local_stage_with_sums(itf, &self.time_weights, s, n == 0));
            if solver_params.search_direction_update {
                local.update_directions(itf, solver_params.alpha, solver_params.i0);
            }
        }
        lap(4, &mut self.stage_time);
        for (solver, x) in self.solvers.iter().zip(&mut self.fields) {
            for slot in &solver.op.layout.slots {
                self.locals[slot.interface].q_hat_into(slot.side == Side::A, x.q_hat.as_mut(), slot.offset);
            }
        }
        lap(5, &mut self.stage_time);
        self.iteration += 1;
        sums
    }
}
