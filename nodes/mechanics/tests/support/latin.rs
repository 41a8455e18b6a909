//! A LATIN iteration on a whole model in one thread, without nodes or bus: the steps the
//! subdomain, coarse and interface nodes take ([`SubdomainFields`], [`MacroProblem::rhs_into`]
//! and [`MacroProblem::subdomain_part_into`], [`InterfaceLocal::local_iteration`],
//! [`AndersonCoordinator::step`]), called in the order the nodes' messages make them, with the
//! copies the bus would make in between. Shared by the allocation test, the iteration benchmark
//! and the reference crate's tests of the macro problem on curved interfaces (which also switch
//! the macro problem off, mix with Anderson and start from a given ŝ).

// Each user reads a part of it (the test does not read the stage names).
#![allow(dead_code)]

use faer::Mat;
use glissade_mechanics::anderson::{AndersonCoordinator, AndersonHistory, MAX_CONDITION};
use glissade_mechanics::coarse::{Contribution, MacroProblem};
use glissade_mechanics::linear::{default_k0, macro_bases, LinearEnd, SubdomainFields, SubdomainSolver};
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

pub struct Latin {
    pub model: Model,
    pub solvers: Vec<SubdomainSolver>,
    fields: Vec<SubdomainFields>,
    pub coarse: MacroProblem,
    /// Per subdomain, the global macro unknown of each of its macro columns.
    columns: Vec<Vec<usize>>,
    /// Whether the macro problem is solved (else w̃ = 0: micro problem 2 is skipped).
    pub use_coarse: bool,
    pub rhs: Mat<f64>,
    pub locals: Vec<InterfaceLocal>,
    pub interface_fields: Vec<InterfaceFields>,
    time_weights: Vec<f64>,
    pub iteration: usize,
    /// Time spent per stage of [`STAGES`], summed over the iterations run.
    pub stage_time: [Duration; 6],
    /// Anderson mixing's global step (as the interface node: the subdomains record from
    /// iteration 1, mix from iteration 2), or plain relaxation; and whether search directions
    /// changed since its last step.
    anderson: Option<AndersonCoordinator>,
    directions_changed: bool,
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
        let mu = model.solver.relaxation;
        let fields = solvers
            .iter()
            .map(|s| {
                let history = anderson.map(|window| AndersonHistory::new(window, mu, s.n_boundary(), nt));
                SubdomainFields::new(s, nt, history)
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
        Self {
            rhs: Mat::zeros(coarse.n(), nt),
            columns: slots.iter().map(|sl| coarse.columns_of(sl)).collect(),
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
            anderson: anderson.map(|_| AndersonCoordinator::new(MAX_CONDITION)),
            directions_changed: false,
        }
    }

    /// ŝ := `hat` on every interface, as if a local stage had made it: the next iteration's linear
    /// stage starts from it (relaxed, not the first).
    pub fn start_from(&mut self, hat: &[InterfaceFields]) {
        for (local, h) in self.locals.iter_mut().zip(hat) {
            local.hat = h.clone();
        }
        self.scatter_q_hat();
        self.iteration = 1;
    }

    /// −Σ_sides 𝔼ᵀ M F per macro unknown (rows) and time point for the interface fields `s` (the
    /// macro problem's right-hand side were they micro problem 1's forces), and the largest of
    /// one side's macro forces: the macro problem's constraint, evaluated.
    pub fn macro_balance(&mut self, s: &[InterfaceFields]) -> (Mat<f64>, f64) {
        let mut size = 0.0f64;
        for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
            for slot in &solver.op.layout.slots {
                let f = &s[slot.interface];
                let f = if slot.side == Side::A { &f.f_a } else { &f.f_b };
                x.f1.as_mut().subrows_mut(slot.offset, f.nrows()).copy_from(f);
            }
            x.macro_forces(solver);
            size = size.max(x.macro_forces.norm_max());
        }
        let mut rhs = Mat::<f64>::zeros(self.rhs.nrows(), self.rhs.ncols());
        MacroProblem::rhs_into(&mut rhs, macro_forces(&self.columns, &self.fields));
        (rhs, size)
    }

    /// q̂ of every subdomain's boundary from its interfaces' ŝ.
    fn scatter_q_hat(&mut self) {
        for (solver, x) in self.solvers.iter().zip(&mut self.fields) {
            for slot in &solver.op.layout.slots {
                self.locals[slot.interface].q_hat_into(slot.side == Side::A, x.q_hat.as_mut(), slot.offset);
            }
        }
    }

    /// One iteration: linear stage from the stored q̂ (0 at iteration 0), relaxation (μ = 1 at
    /// iterations 0 and 1) or Anderson mixing, local stage and indicators, q̂ for the next one.
    pub fn iterate(&mut self) -> IndicatorSums {
        let n = self.iteration as u32;
        let relaxation = self.model.solver.relaxation;
        let mut clock = Instant::now();
        let mut lap = |stage: usize, times: &mut [Duration; 6]| {
            let now = Instant::now();
            times[stage] += now - clock;
            clock = now;
        };
        // The subdomain nodes, on q̂: micro problem 1, and the macro forces they send.
        let use_coarse = self.use_coarse;
        let coarse = |solver: &SubdomainSolver| use_coarse && solver.n_macro() > 0;
        for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
            x.micro1(solver);
            lap(0, &mut self.stage_time);
            if coarse(solver) {
                x.macro_forces(solver);
            }
            lap(1, &mut self.stage_time);
        }
        // The coarse node, on every subdomain's macro forces: w̃, each subdomain's part sent.
        if use_coarse {
            MacroProblem::rhs_into(&mut self.rhs, macro_forces(&self.columns, &self.fields));
            self.coarse.solve_in_place(&mut self.rhs);
            for (c, x) in self.columns.iter().zip(&mut self.fields) {
                MacroProblem::subdomain_part_into(self.rhs.as_ref(), c, x.w_tilde.as_mut());
            }
        }
        lap(2, &mut self.stage_time);
        // The subdomain nodes, on w̃: micro problem 2 and the end of the linear stage; with
        // Anderson from iteration 2 on the interface node's step on their partials first.
        let mut partials = Vec::new();
        for (solver, x) in self.solvers.iter_mut().zip(&mut self.fields) {
            if coarse(solver) {
                x.micro2(solver);
            } else {
                x.skip_micro2();
            }
            if let LinearEnd::Partials(p) = x.finish(n, relaxation) {
                partials.push(p);
            }
        }
        if !partials.is_empty() {
            let coordinator = self.anderson.as_mut().expect("partials come with Anderson");
            let step = coordinator.step(&partials, std::mem::take(&mut self.directions_changed));
            for x in &mut self.fields {
                x.take_step(&step);
            }
        }
        lap(3, &mut self.stage_time);
        // The interface node, on every subdomain's s: the local stage, q̂ sent.
        for (solver, x) in self.solvers.iter().zip(&self.fields) {
            for slot in &solver.op.layout.slots {
                self.interface_fields[slot.interface].set_side(slot.side, slot.offset, x.w.as_ref(), x.f.as_ref());
            }
        }
        lap(5, &mut self.stage_time);
        let mut sums = IndicatorSums::default();
        for ((local, itf), s) in self
            .locals
            .iter_mut()
            .zip(&self.model.interfaces)
            .zip(&self.interface_fields)
        {
            let (own, updated) = local.local_iteration(itf, &self.model.solver, &self.time_weights, s, n == 0);
            sums.add(&own);
            self.directions_changed |= updated;
        }
        lap(4, &mut self.stage_time);
        self.scatter_q_hat();
        lap(5, &mut self.stage_time);
        self.iteration += 1;
        sums
    }
}

/// Each subdomain's macro columns and macro forces, in subdomain order (the coarse node's).
fn macro_forces<'a>(
    columns: &'a [Vec<usize>],
    fields: &'a [SubdomainFields],
) -> impl Iterator<Item = (&'a [usize], faer::MatRef<'a, f64>)> {
    columns
        .iter()
        .zip(fields)
        .map(|(c, x)| (c.as_slice(), x.macro_forces.as_ref()))
}
