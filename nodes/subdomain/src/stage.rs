//! The linear stage of a subdomain node, full or PGD (docs/method.md, "Linear stage"): micro problems 1 and 2 (into
//! full fields, or through the PGD basis), the relaxation (in coordinates with PGD), the state
//! sent (`BoundaryState`, or `BoundaryModes` in mode form) followed by the stage's counters
//! (`LinearStageStats`), and the displacement field recovered from the state at the end. The
//! counters are the kernels' own (flops, basis size, ξ): nothing here reads a clock.

use crate::{Phase, SubdomainNode};
use faer::Mat;
use glissade_bus::convert::field_of;
use glissade_mechanics::linear::{relaxation_at, LinearEnd};
use glissade_mechanics::pgd::PgdStage;
use glissade_messages::{LinearStageStats, Message, Payload, Stage};

impl SubdomainNode {
    /// Micro problem 1 into (w1, f1) or, with PGD, into the basis' time functions (expanded
    /// here only without the coarse problem) and the macro forces when the coarse problem is on.
    /// Starts the counters of this iteration's linear stage.
    fn solve_micro1(&mut self, coarse: bool) {
        self.stats = LinearStageStats {
            subdomain: self.subdomain(),
            ..LinearStageStats::default()
        };
        let flops0 = self.flops();
        let compress = self
            .pgd
            .as_ref()
            .is_some_and(|p| self.iteration >= 1 && p.settings.criterion.compresses());
        if compress {
            // The compression works on the state's fields.
            self.expand_state();
        }
        let x = &mut self.fields;
        match self.pgd.as_mut() {
            None => {
                x.micro1(&mut self.solver);
                if coarse {
                    x.macro_forces(&mut self.solver);
                }
            }
            Some(pgd) => {
                if self.iteration >= 1 && pgd.settings.criterion.compresses() {
                    self.stats.dropped_modes = pgd.compress(x.w.as_mut(), x.f.as_mut(), x.anderson.as_mut()) as u32;
                }
                let report = pgd.micro1(&mut self.solver, x.q_hat.as_ref());
                self.stats.new_modes = report.new_modes as u32;
                self.stats.xi1 = report.xi;
                if coarse {
                    pgd.macro_forces_into(x.macro_forces.as_mut());
                }
                self.stats.modes = pgd.n_modes() as u32;
            }
        }
        self.stats.flops += self.flops() - flops0;
    }

    /// Floating-point operations of the linear-stage kernels so far (solver and PGD stage).
    pub(crate) fn flops(&self) -> u64 {
        self.solver.flops() + self.pgd.as_ref().map_or(0, PgdStage::flops)
    }

    /// Micro problem 2 into (w2, f2), or with PGD into the basis' time functions λ².
    fn solve_micro2(&mut self) {
        let flops0 = self.flops();
        match self.pgd.as_mut() {
            None => self.fields.micro2(&mut self.solver),
            Some(pgd) => {
                let report = pgd.micro2(&mut self.solver, self.fields.w_tilde.as_ref());
                self.stats.new_modes += report.new_modes as u32;
                self.stats.xi2 = report.xi;
                self.stats.modes = pgd.n_modes() as u32;
            }
        }
        self.stats.flops += self.flops() - flops0;
    }

    /// Micro problem 1 from the stored q̂; returns the macro forces message or, without the coarse
    /// problem, finishes the linear stage at once.
    pub(crate) fn micro1(&mut self) -> Vec<Message> {
        let coarse = self.options.coarse && self.solver.n_macro() > 0;
        self.solve_micro1(coarse);
        if coarse {
            self.phase = Phase::Macro;
            let payload = Payload::MacroForces {
                subdomain: self.subdomain(),
                forces: self.pool.field_of(self.fields.macro_forces.as_ref()),
            };
            vec![self.msg(Stage::Micro1, payload)]
        } else {
            self.fields.skip_micro2();
            self.finish_linear_stage()
        }
    }

    /// Micro problem 2 from the stored w̃, then the end of the linear stage.
    pub(crate) fn micro2(&mut self) -> Vec<Message> {
        self.solve_micro2();
        self.finish_linear_stage()
    }

    /// s_new = s₁ + s₂, relaxed: s ← μ s_new + (1 − μ) s (μ = 1 for iterations 0 and 1). With
    /// Anderson acceleration from iteration 2 on: records (s, s_new) and returns the Gram
    /// partials instead; the step comes with `AndersonStep` ([`SubdomainFields::finish`]).
    ///
    /// [`SubdomainFields::finish`]: glissade_mechanics::linear::SubdomainFields::finish
    fn finish_linear_stage(&mut self) -> Vec<Message> {
        if self.pgd.is_some() {
            return self.finish_pgd(relaxation_at(self.iteration, self.options.relaxation));
        }
        match self.fields.finish(self.iteration, self.options.relaxation) {
            LinearEnd::Partials(p) => vec![self.anderson_gram(p)],
            LinearEnd::State => {
                self.phase = Phase::Directions;
                self.boundary_state()
            }
        }
    }

    /// [`Self::finish_linear_stage`] in mode form: the relaxation in coordinates, or with
    /// Anderson from iteration 1 on the record of the iterate (its force residual
    /// G(λ¹ + λ² − λˢ) for the least-squares problem, its coordinates for the step) and from
    /// iteration 2 on its Gram partials. Neither the state nor its image is expanded.
    fn finish_pgd(&mut self, mu: f64) -> Vec<Message> {
        let flops0 = self.flops();
        let pgd = self.pgd.as_mut().expect("PGD stage");
        let x = &mut self.fields;
        match x.anderson.as_mut() {
            Some(history) if self.iteration >= 1 => {
                pgd.residual_forces_into(x.f1.as_mut());
                history.record_residual(&x.f1);
                pgd.record_coordinates(history);
                if self.iteration >= 2 {
                    let p = history.partials();
                    self.stats.flops += self.flops() - flops0;
                    return vec![self.anderson_gram(p)];
                }
                pgd.relax_state(mu);
            }
            _ => pgd.relax_state(mu),
        }
        self.stats.flops += self.flops() - flops0;
        self.phase = Phase::Directions;
        self.boundary_modes()
    }

    /// The state in mode form: the basis columns changed since the last message, λˢ, and the
    /// particular part in the first message; the node's own (W, F) are expanded from the same
    /// mode form as a receiver's. Then the stage's counters.
    pub(crate) fn boundary_modes(&mut self) -> Vec<Message> {
        let pgd = self.pgd.as_mut().expect("PGD stage");
        let form = self.modes.as_mut().expect("mode form with PGD");
        let first = pgd.take_changed();
        let p = pgd.n_modes();
        let z = field_of(pgd.z().subcols(first, p - first));
        let g = field_of(pgd.g().subcols(first, p - first));
        let lambda = field_of(pgd.state());
        form.update(first, &z.data, &g.data, &lambda.data)
            .expect("the subdomain's own basis fits its mode form");
        self.fields_stale = true;
        let particular = self.particular.take();
        let state = self.msg(
            Stage::Linear,
            Payload::BoundaryModes {
                subdomain: self.subdomain(),
                particular,
                first_mode: first as u32,
                z,
                g,
                lambda,
            },
        );
        vec![state, self.stats_message()]
    }

    /// With PGD, (w, f) from the mode form when they lag behind it (the flops go to the current
    /// linear stage's counters).
    pub(crate) fn expand_state(&mut self) {
        if let (true, Some(form)) = (self.fields_stale, self.modes.as_ref()) {
            form.expand_into(self.fields.w.as_mut(), self.fields.f.as_mut());
            self.stats.flops += form.expand_flops();
            self.fields_stale = false;
        }
    }

    /// The state s = (W, F) (with several interface nodes, to each one owning one of its
    /// interfaces the rows of those, addressed), then the stage's counters.
    pub(crate) fn boundary_state(&mut self) -> Vec<Message> {
        let subdomain = self.subdomain();
        let mut out = Vec::with_capacity(self.state_parts.len().max(1) + 1);
        if self.state_parts.is_empty() {
            let payload = Payload::BoundaryState {
                subdomain,
                to: None,
                interfaces: self.boundary_interfaces(),
                w: self.pool.field_of(self.fields.w.as_ref()),
                f: self.pool.field_of(self.fields.f.as_ref()),
            };
            out.push(self.msg(Stage::Linear, payload));
        } else {
            let nt = self.fields.w.ncols();
            let n_slots = self.solver.op.layout.slots.len();
            for part in &self.state_parts {
                let n: usize = part.rows.iter().map(|&(_, n)| n).sum();
                let (w, f) = if part.interfaces.len() == n_slots {
                    // Every interface to one node: the whole state, in layout order.
                    (
                        self.pool.field_of(self.fields.w.as_ref()),
                        self.pool.field_of(self.fields.f.as_ref()),
                    )
                } else {
                    let rows_of = |from: faer::MatRef<'_, f64>, mut to: faer::MatMut<'_, f64>| {
                        let mut r0 = 0;
                        for &(offset, n) in &part.rows {
                            to.as_mut().subrows_mut(r0, n).copy_from(from.subrows(offset, n));
                            r0 += n;
                        }
                    };
                    (
                        self.pool.field_with(n, nt, |to| rows_of(self.fields.w.as_ref(), to)),
                        self.pool.field_with(n, nt, |to| rows_of(self.fields.f.as_ref(), to)),
                    )
                };
                let payload = Payload::BoundaryState {
                    subdomain,
                    to: Some(part.to),
                    interfaces: part.interfaces.clone(),
                    w,
                    f,
                };
                out.push(self.msg(Stage::Linear, payload));
            }
        }
        out.push(self.stats_message());
        out
    }

    /// The counters of this iteration's linear stage, sent once, after its state.
    fn stats_message(&self) -> Message {
        self.msg(Stage::Linear, Payload::LinearStageStats(self.stats))
    }

    /// The full displacement field u of every time point, recovered from the state s.
    pub(crate) fn displacement(&mut self) -> Message {
        self.expand_state();
        let sub = &self.model.subdomains[self.solver.subdomain];
        let layout = &self.solver.op.layout;
        let nt = self.model.time.n_points();
        let mut u = Mat::<f64>::zeros(sub.n_dofs(), nt);
        let mut q = vec![0.0; layout.len()];
        for i in 0..nt {
            for (r, qr) in q.iter_mut().enumerate() {
                *qr = self.fields.f[(r, i)] + layout.k[r] * self.fields.w[(r, i)];
            }
            let phi: Vec<f64> = sub.loads.iter().map(|c| c.time.eval(self.model.time.t(i))).collect();
            for (d, v) in self.solver.op.recover(&q, &phi).into_iter().enumerate() {
                u[(d, i)] = v;
            }
        }
        self.msg(
            Stage::Final,
            Payload::Displacement {
                subdomain: self.subdomain(),
                u: field_of(u.as_ref()),
            },
        )
    }
}
