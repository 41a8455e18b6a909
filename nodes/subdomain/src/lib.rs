//! The subdomain node: hosts one subdomain's linear stage (DESIGN §3–4).
//!
//! Setup: builds A_E and sends L_E (when the coarse problem is on), then runs the first linear
//! stage from ŝ = 0. Each iteration: `LocalDirections` (q̂, from every interface node owning one
//! of its interfaces) → micro problem 1 → `MacroForces`;
//! `MacroDisplacements` (w̃) → micro problem 2, relaxation → `BoundaryState` (s = (W, F)). Without
//! the coarse problem micro 2 is skipped (w̃ = 0). A stop `Decision` ends the node, after sending
//! the full displacement field when asked.
//!
//! With Anderson acceleration (DESIGN §3 "Acceleration"), from iteration 2 on the end of the
//! linear stage is a reduction: the node records s and G(s) = s₁ + s₂, sends its `AndersonGram`
//! partials, and takes the `AndersonStep` the interface node returns (mixed, plain or restart)
//! before it sends `BoundaryState`. Without acceleration no such message exists.
//!
//! With the PGD linear stage the node holds its state in mode form (DESIGN §3 "PGD linear
//! stage"): the coordinates λˢ of s − s₀ on its basis, relaxed (or mixed, with the same Anderson
//! coefficients as the fields would be) in coordinates, and sends `BoundaryModes` instead of
//! `BoundaryState`: the particular part once, each new basis column once, λˢ every iteration. Its
//! own fields (W, F) are expanded from the same [`ModeForm`] a receiver builds from the messages,
//! so both hold the same numbers bit for bit.

use faer::Mat;
use glissade_bus::convert::{copy_into, field_of, FieldPool};
use glissade_bus::{expect_finite, expect_origin, expect_shape, Node, NodeError, RunContext};
use glissade_mechanics::anderson::{AndersonHistory, AndersonStep, GramPartials};
use glissade_mechanics::linear::{relax_into, sum_into, sum_relax_into, SubdomainSolver};
use glissade_mechanics::model::{Acceleration, Model};
use glissade_mechanics::modes::ModeForm;
use glissade_mechanics::pgd::{PgdSettings, PgdStage};
use glissade_messages::{role_field_topic, Field, Message, NodeId, ParticularModes, Payload, Role, Stage};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// What one linear stage of one subdomain did: its wall time (micro 1 + micro 2, kept out of the
/// numerics and messages: only the log sees it) and, with PGD, the basis size and criteria.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinearStageRecord {
    pub subdomain: u32,
    pub iteration: u32,
    pub seconds: f64,
    /// Floating-point operations of the stage (micro 1, macro forces, micro 2; with PGD the
    /// compression, update, enrichment and expansion too), as its kernels count them
    /// ([`SubdomainSolver::flops`], [`PgdStage::flops`]).
    pub flops: u64,
    /// PGD basis size after the stage (0 without PGD), frozen macro modes included.
    pub modes: usize,
    /// Modes added in this stage (micro 1 + micro 2) and dropped by compression.
    pub new_modes: usize,
    pub dropped_modes: usize,
    /// ξ at the end of micro 1 and micro 2.
    pub xi1: f64,
    pub xi2: f64,
}

/// Where subdomain nodes append their [`LinearStageRecord`]s (one per iteration).
pub type LinearStageLog = Arc<Mutex<Vec<LinearStageRecord>>>;

/// Options of a subdomain node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SubdomainOptions {
    /// Solve the macro problem (wait for w̃ after micro 1).
    pub coarse: bool,
    /// Relaxation μ (1 on the first iteration).
    pub relaxation: f64,
    /// Send the full displacement field at the end.
    pub send_displacement: bool,
    /// Plain relaxation or Anderson mixing (damping = `relaxation`).
    pub acceleration: Acceleration,
}

/// What a subdomain node waits for next within its iteration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// q̂ of the next iteration (its boundary state is sent).
    Directions,
    /// w̃ of this iteration (its macro forces are sent).
    Macro,
    /// The Anderson step of this iteration (its partials are sent).
    Step,
}

pub struct SubdomainNode {
    id: NodeId,
    ctx: RunContext,
    model: Arc<Model>,
    solver: SubdomainSolver,
    options: SubdomainOptions,
    iteration: u32,
    q_hat: Mat<f64>,
    w1: Mat<f64>,
    f1: Mat<f64>,
    w2: Mat<f64>,
    f2: Mat<f64>,
    w: Mat<f64>,
    f: Mat<f64>,
    w_tilde: Mat<f64>,
    macro_forces: Mat<f64>,
    /// Anderson history (acceleration on) and whether the node waits for its step.
    anderson: Option<AndersonHistory>,
    phase: Phase,
    /// The last iteration whose decision arrived.
    decided: Option<u32>,
    /// Per boundary slot (interface), whether this iteration's q̂ rows arrived (several interface
    /// nodes each send the rows of their interfaces).
    directions_in: Vec<bool>,
    finished: bool,
    /// PGD linear stage (DESIGN §3), when the scene asks for it, the mode form of the state as
    /// receivers hold it, and the particular part until the first message carries it.
    pgd: Option<PgdStage>,
    modes: Option<ModeForm>,
    particular: Option<ParticularModes>,
    /// With PGD: (w, f) lag behind the mode form until a consumer needs them
    /// ([`Self::expand_state`]: the compression, the displacement).
    fields_stale: bool,
    log: Option<LinearStageLog>,
    record: LinearStageRecord,
    /// Per boundary slot, the index of the interface node that owns its interface (None: any
    /// interface node is taken).
    owners: Option<Vec<u32>>,
    /// Buffers of the fields this node sent, back from the bus ([`Node::recycle`]).
    pool: FieldPool,
    /// Iteration 0 has run (at once from ŝ = 0, or with a time-coarse start once the launcher's
    /// q̂ arrived: [`Self::time_start`]).
    started: bool,
}

impl SubdomainNode {
    pub fn new(ctx: RunContext, model: Arc<Model>, solver: SubdomainSolver, options: SubdomainOptions) -> Self {
        let s = solver.subdomain;
        let (n_b, n_m, nt) = (solver.n_boundary(), solver.n_macro(), model.time.n_points());
        let n_slots = solver.op.layout.slots.len();
        let z = |r: usize| Mat::<f64>::zeros(r, nt);
        Self {
            id: NodeId {
                role: Role::Subdomain,
                index: s as u32,
            },
            ctx,
            model,
            solver,
            options,
            iteration: 0,
            q_hat: z(n_b),
            w1: z(n_b),
            f1: z(n_b),
            w2: z(n_b),
            f2: z(n_b),
            w: z(n_b),
            f: z(n_b),
            w_tilde: z(n_m),
            macro_forces: z(n_m),
            anderson: match options.acceleration {
                Acceleration::None => None,
                Acceleration::Anderson { window } => Some(AndersonHistory::new(window, options.relaxation, n_b, nt)),
            },
            phase: Phase::Directions,
            decided: None,
            directions_in: vec![false; n_slots],
            finished: false,
            pgd: None,
            modes: None,
            particular: None,
            fields_stale: false,
            log: None,
            record: LinearStageRecord::default(),
            owners: None,
            pool: FieldPool::default(),
            started: false,
        }
    }

    /// The interfaces each interface node owns (the deployment's groups, by node index): local
    /// directions of an interface are then taken only from its owner.
    pub fn with_interface_owners(mut self, groups: &[Vec<usize>]) -> Self {
        let owner = |i: usize| groups.iter().position(|g| g.contains(&i)).map(|g| g as u32);
        self.owners = self
            .solver
            .op
            .layout
            .slots
            .iter()
            .map(|sl| owner(sl.interface))
            .collect::<Option<Vec<u32>>>();
        self
    }

    /// Runs micro problems 1 and 2 through a PGD basis ([`PgdStage`]): the state stays
    /// W = W_d + Σ Z_k λ_k, F = −k⁻W_d + Σ G_k λ_k, expanded to full fields for the messages.
    pub fn with_pgd(mut self, settings: PgdSettings) -> Self {
        let tw = self.model.time.trapezoid_weights();
        self.pgd = Some(PgdStage::new(&mut self.solver, &tw, settings));
        // s₀ = (W_d, −k⁻W_d) in separated form: the load cases' boundary responses and φ.
        let k = &self.solver.op.layout.k;
        let p_w = self.solver.op.load_boundary.as_ref();
        let particular = ParticularModes {
            w: field_of(p_w),
            f: Field::from_fn(p_w.nrows(), p_w.ncols(), |r, c| -k[r] * p_w[(r, c)]),
            time: field_of(self.solver.load_time.as_ref()),
        };
        let (n_b, nt) = (self.solver.n_boundary(), self.model.time.n_points());
        let form = ModeForm::new(
            n_b,
            nt,
            particular.time.rows(),
            &particular.w.data,
            &particular.f.data,
            &particular.time.data,
        )
        .expect("the particular part has the subdomain's sizes");
        self.modes = Some(form);
        self.particular = Some(particular);
        self.anderson = self.anderson.take().map(|h| h.with_coordinates(n_b));
        self
    }

    /// Appends a [`LinearStageRecord`] per iteration to `log`.
    pub fn with_log(mut self, log: LinearStageLog) -> Self {
        self.log = Some(log);
        self
    }

    /// Micro problem 1 into (w1, f1) or, with PGD, into the basis' time functions (expanded
    /// here only without the coarse problem) and the macro forces when the coarse problem is on.
    fn solve_micro1(&mut self, coarse: bool) {
        let t0 = Instant::now();
        let flops0 = self.flops();
        self.record = LinearStageRecord {
            subdomain: self.subdomain(),
            iteration: self.iteration,
            ..LinearStageRecord::default()
        };
        let compress = self
            .pgd
            .as_ref()
            .is_some_and(|p| self.iteration >= 1 && p.settings.criterion.compresses());
        if compress {
            // The compression works on the state's fields.
            self.expand_state();
        }
        match self.pgd.as_mut() {
            None => {
                self.solver
                    .micro1_into(self.q_hat.as_ref(), self.w1.as_mut(), self.f1.as_mut());
                if coarse {
                    self.solver
                        .macro_forces_into(self.f1.as_ref(), self.macro_forces.as_mut());
                }
            }
            Some(pgd) => {
                if self.iteration >= 1 && pgd.settings.criterion.compresses() {
                    self.record.dropped_modes = pgd.compress(self.w.as_mut(), self.f.as_mut(), self.anderson.as_mut());
                }
                let report = pgd.micro1(&mut self.solver, self.q_hat.as_ref());
                self.record.new_modes = report.new_modes;
                self.record.xi1 = report.xi;
                if coarse {
                    pgd.macro_forces_into(self.macro_forces.as_mut());
                }
                self.record.modes = pgd.n_modes();
            }
        }
        self.record.seconds = t0.elapsed().as_secs_f64();
        self.record.flops = self.flops() - flops0;
    }

    /// Floating-point operations of the linear-stage kernels so far (solver and PGD stage).
    fn flops(&self) -> u64 {
        self.solver.flops() + self.pgd.as_ref().map_or(0, PgdStage::flops)
    }

    /// Micro problem 2 into (w2, f2), or with PGD into the basis' time functions λ². Then the
    /// linear stage's record goes to the log (with PGD, when the state is sent).
    fn solve_micro2(&mut self) {
        let t0 = Instant::now();
        let flops0 = self.flops();
        match self.pgd.as_mut() {
            None => self
                .solver
                .micro2_into(self.w_tilde.as_ref(), self.w2.as_mut(), self.f2.as_mut()),
            Some(pgd) => {
                let report = pgd.micro2(&mut self.solver, self.w_tilde.as_ref());
                self.record.new_modes += report.new_modes;
                self.record.xi2 = report.xi;
                self.record.modes = pgd.n_modes();
            }
        }
        self.record.seconds += t0.elapsed().as_secs_f64();
        self.record.flops += self.flops() - flops0;
        if self.pgd.is_none() {
            self.log_record();
        }
    }

    fn log_record(&self) {
        if let Some(log) = &self.log {
            if let Ok(mut v) = log.lock() {
                v.push(self.record);
            }
        }
    }

    fn subdomain(&self) -> u32 {
        self.solver.subdomain as u32
    }

    fn msg(&self, stage: Stage, payload: Payload) -> Message {
        Message {
            envelope: self.ctx.envelope(self.id, self.iteration, stage),
            payload,
        }
    }

    /// Micro problem 1 from the stored q̂; returns the macro forces message or, without the coarse
    /// problem, finishes the linear stage at once.
    fn micro1(&mut self) -> Vec<Message> {
        let coarse = self.options.coarse && self.solver.n_macro() > 0;
        self.solve_micro1(coarse);
        if coarse {
            self.phase = Phase::Macro;
            let payload = Payload::MacroForces {
                subdomain: self.subdomain(),
                forces: self.pool.field_of(self.macro_forces.as_ref()),
            };
            vec![self.msg(Stage::Micro1, payload)]
        } else {
            self.w2.fill(0.0);
            self.f2.fill(0.0);
            if self.pgd.is_none() {
                self.log_record();
            }
            vec![self.finish_linear_stage()]
        }
    }

    /// s_new = s₁ + s₂, relaxed: s ← μ s_new + (1 − μ) s (μ = 1 for iterations 0 and 1). With
    /// Anderson acceleration from iteration 2 on: records (s, s_new) and returns the Gram
    /// partials instead; the step comes with `AndersonStep`.
    fn finish_linear_stage(&mut self) -> Message {
        let mu = if self.iteration <= 1 {
            1.0
        } else {
            self.options.relaxation
        };
        if self.pgd.is_some() {
            return self.finish_pgd(mu);
        }
        let Some(history) = self.anderson.as_mut() else {
            // s₁ + s₂ and the relaxation in one pass.
            sum_relax_into(
                mu,
                self.w1.as_mut(),
                self.f1.as_mut(),
                self.w2.as_ref(),
                self.f2.as_ref(),
                self.w.as_mut(),
                self.f.as_mut(),
            );
            self.phase = Phase::Directions;
            return self.boundary_state();
        };
        if self.iteration >= 2 {
            // s₁ + s₂ is only recorded: summed inside the history's pass.
            history.record_sum(&self.w, &self.f, [&self.w1, &self.w2], [&self.f1, &self.f2]);
        } else {
            sum_into(self.w1.as_mut(), self.f1.as_mut(), self.w2.as_ref(), self.f2.as_ref());
            if self.iteration >= 1 {
                history.record(&self.w, &self.f, &self.w1, &self.f1);
            }
        }
        if self.iteration >= 2 {
            let p = history.partials();
            return self.anderson_gram(p);
        }
        relax_into(mu, self.w1.as_ref(), self.f1.as_ref(), self.w.as_mut(), self.f.as_mut());
        self.phase = Phase::Directions;
        self.boundary_state()
    }

    /// The Gram partials of this iteration's record; the node then waits for the step.
    fn anderson_gram(&mut self, p: GramPartials) -> Message {
        self.phase = Phase::Step;
        self.msg(
            Stage::Linear,
            Payload::AndersonGram {
                subdomain: self.subdomain(),
                gram: Field::from_fn(p.k, p.k, |i, j| p.gram[j * p.k + i]),
                projection: Field::from_fn(p.k, 1, |i, _| p.projection[i]),
                residual2: p.residual2,
            },
        )
    }

    /// [`Self::finish_linear_stage`] in mode form: the relaxation in coordinates, or with
    /// Anderson from iteration 1 on the record of the iterate (its force residual
    /// G(λ¹ + λ² − λˢ) for the least-squares problem, its coordinates for the step) and from
    /// iteration 2 on its Gram partials. Neither the state nor its image is expanded.
    fn finish_pgd(&mut self, mu: f64) -> Message {
        let t0 = Instant::now();
        let flops0 = self.flops();
        let pgd = self.pgd.as_mut().expect("PGD stage");
        match self.anderson.as_mut() {
            Some(history) if self.iteration >= 1 => {
                pgd.residual_forces_into(self.f1.as_mut());
                history.record_residual(&self.f1);
                pgd.record_coordinates(history);
                if self.iteration >= 2 {
                    let p = history.partials();
                    self.record.seconds += t0.elapsed().as_secs_f64();
                    self.record.flops += self.flops() - flops0;
                    return self.anderson_gram(p);
                }
                pgd.relax_state(mu);
            }
            _ => pgd.relax_state(mu),
        }
        self.record.seconds += t0.elapsed().as_secs_f64();
        self.record.flops += self.flops() - flops0;
        self.phase = Phase::Directions;
        self.boundary_modes()
    }

    /// The state in mode form: the basis columns changed since the last message, λˢ, and the
    /// particular part in the first message; the node's own (W, F) are expanded from the same
    /// mode form as a receiver's. Ends the linear stage's record.
    fn boundary_modes(&mut self) -> Message {
        let t0 = Instant::now();
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
        self.record.seconds += t0.elapsed().as_secs_f64();
        self.log_record();
        let particular = self.particular.take();
        self.msg(
            Stage::Linear,
            Payload::BoundaryModes {
                subdomain: self.subdomain(),
                particular,
                first_mode: first as u32,
                z,
                g,
                lambda,
            },
        )
    }

    /// With PGD, (w, f) from the mode form when they lag behind it (the flops go to the current
    /// linear stage's record).
    fn expand_state(&mut self) {
        if let (true, Some(form)) = (self.fields_stale, self.modes.as_ref()) {
            form.expand_into(self.w.as_mut(), self.f.as_mut());
            self.record.flops += form.expand_flops();
            self.fields_stale = false;
        }
    }

    fn boundary_state(&mut self) -> Message {
        let payload = Payload::BoundaryState {
            subdomain: self.subdomain(),
            w: self.pool.field_of(self.w.as_ref()),
            f: self.pool.field_of(self.f.as_ref()),
        };
        self.msg(Stage::Linear, payload)
    }

    /// Time-coarse start (`solver.time_coarsening`): iteration 0 waits for q̂ from the launcher
    /// instead of starting from ŝ = 0.
    fn time_start(&self) -> bool {
        self.model.solver.time_start.is_some()
    }

    /// Iteration 0 of a time-coarse start: q̂ over the whole boundary (every interface of the
    /// layout, in layout order) from the launcher, checked in full before it is taken.
    fn initial_directions(
        &mut self,
        msg: &Message,
        subdomain: u32,
        interfaces: &[u32],
        q_hat: &Field,
    ) -> Result<Vec<Message>, NodeError> {
        if self.started {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "local directions of iteration {} sent by {}: after the start only interface nodes send them",
                    msg.envelope.iteration, msg.envelope.sender
                ),
            ));
        }
        expect_origin(self.id, msg, Role::Launcher, Some(0))?;
        self.expect_recipient("initial local directions", subdomain)?;
        if self.started || msg.envelope.iteration != 0 || msg.envelope.stage != Stage::Local {
            return Err(self.out_of_turn("initial local directions", msg.envelope.iteration));
        }
        let layout: Vec<u32> = self
            .solver
            .op
            .layout
            .slots
            .iter()
            .map(|sl| sl.interface as u32)
            .collect();
        if interfaces != layout.as_slice() {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "initial local directions over interfaces {interfaces:?}; this subdomain's boundary has {layout:?}"
                ),
            ));
        }
        expect_shape(self.id, "q_hat", q_hat, self.q_hat.nrows(), self.q_hat.ncols())?;
        expect_finite(self.id, "q_hat", "launcher:0", q_hat)?;
        copy_into(q_hat, &mut self.q_hat);
        self.started = true;
        Ok(self.micro1())
    }

    /// Refuses a message addressed to another subdomain.
    fn expect_recipient(&self, what: &str, subdomain: u32) -> Result<(), NodeError> {
        if subdomain != self.subdomain() {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "{what} addressed to subdomain {subdomain}, this is subdomain {}",
                    self.subdomain()
                ),
            ));
        }
        Ok(())
    }

    /// The rejection of a message that is not the one this node waits for.
    fn out_of_turn(&self, what: &str, it: u32) -> NodeError {
        let waits = match self.phase {
            Phase::Directions if !self.started => "the launcher's initial local directions (iteration 0)".to_string(),
            Phase::Directions => format!("local directions of iteration {}", self.iteration + 1),
            Phase::Macro => format!("macro displacements of iteration {}", self.iteration),
            Phase::Step => format!("the Anderson step of iteration {}", self.iteration),
        };
        NodeError::rejected(
            self.id,
            format!(
                "{what} of iteration {it} while at iteration {}, waiting for {waits}",
                self.iteration
            ),
        )
    }

    fn displacement(&mut self) -> Message {
        self.expand_state();
        let sub = &self.model.subdomains[self.solver.subdomain];
        let layout = &self.solver.op.layout;
        let nt = self.model.time.n_points();
        let mut u = Mat::<f64>::zeros(sub.n_dofs(), nt);
        let mut q = vec![0.0; layout.len()];
        for i in 0..nt {
            for (r, qr) in q.iter_mut().enumerate() {
                *qr = self.f[(r, i)] + layout.k[r] * self.w[(r, i)];
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

impl Node for SubdomainNode {
    fn id(&self) -> NodeId {
        self.id
    }

    fn subscriptions(&self) -> Vec<String> {
        let run = &self.ctx.run_id;
        let s = Some(self.subdomain());
        let mut subs = vec![
            role_field_topic(run, Role::Interface, "local_directions", s),
            role_field_topic(run, Role::Coarse, "macro_displacements", s),
            role_field_topic(run, Role::Interface, "decision", None),
        ];
        if self.anderson.is_some() {
            subs.push(role_field_topic(run, Role::Interface, "anderson_step", None));
        }
        if self.time_start() {
            subs.push(role_field_topic(run, Role::Launcher, "local_directions", s));
        }
        subs
    }

    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        let mut out = Vec::new();
        if self.options.coarse && self.solver.n_macro() > 0 {
            let slots = self
                .solver
                .macro_slots
                .iter()
                .map(|m| (m.interface as u32, m.n_modes as u32))
                .collect();
            out.push(self.msg(
                Stage::Setup,
                Payload::HomogenizedOperator {
                    subdomain: self.subdomain(),
                    slots,
                    l_e: field_of(self.solver.l_e.as_ref()),
                },
            ));
        }
        // Iteration 0: linear stage from ŝ = 0, or, with a time-coarse start, from the q̂ the
        // launcher sends (`initial_directions`).
        if !self.time_start() {
            self.q_hat.fill(0.0);
            self.started = true;
            out.extend(self.micro1());
        }
        Ok(out)
    }

    /// Every message is checked in full (origin, stage, iteration, phase, recipient, shapes, finite
    /// values) before it changes anything: a refused message leaves the node as it was.
    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError> {
        if self.finished {
            return Ok(Vec::new());
        }
        let it = msg.envelope.iteration;
        let me = self.subdomain();
        match &msg.payload {
            Payload::LocalDirections {
                subdomain,
                interfaces,
                q_hat,
            } if self.time_start() && msg.envelope.sender.role == Role::Launcher => {
                self.initial_directions(msg, *subdomain, interfaces, q_hat)
            }
            Payload::LocalDirections {
                subdomain,
                interfaces,
                q_hat,
            } => {
                expect_origin(self.id, msg, Role::Interface, None)?;
                self.expect_recipient("local directions", *subdomain)?;
                if it != self.iteration + 1 || self.phase != Phase::Directions || !self.started {
                    return Err(self.out_of_turn("local directions", it));
                }
                // One interface node's rows: its interfaces' slots, one after the other.
                let slots = &self.solver.op.layout.slots;
                if interfaces.is_empty() {
                    return Err(NodeError::rejected(
                        self.id,
                        format!(
                            "local directions of iteration {it} from {} cover no interface",
                            msg.envelope.sender
                        ),
                    ));
                }
                let mut at = Vec::with_capacity(interfaces.len());
                for &i in interfaces {
                    let Some(k) = slots.iter().position(|sl| sl.interface == i as usize) else {
                        return Err(NodeError::rejected(
                            self.id,
                            format!("local directions of interface {i}, which is not on this subdomain's boundary"),
                        ));
                    };
                    if let Some(owner) = self.owners.as_ref().map(|o| o[k]) {
                        if msg.envelope.sender.index != owner {
                            return Err(NodeError::rejected(
                                self.id,
                                format!(
                                    "local directions of interface {i} at iteration {it} from {}, which does not own it (interface:{owner} does)",
                                    msg.envelope.sender
                                ),
                            ));
                        }
                    }
                    if self.directions_in[k] || at.contains(&k) {
                        return Err(NodeError::rejected(
                            self.id,
                            format!("second local directions of interface {i} at iteration {it}"),
                        ));
                    }
                    at.push(k);
                }
                let rows = at.iter().map(|&k| 2 * slots[k].n_pairs).sum();
                expect_shape(self.id, "q_hat", q_hat, rows, self.q_hat.ncols())?;
                expect_finite(self.id, "q_hat", &msg.envelope.sender.to_string(), q_hat)?;
                let mut r0 = 0;
                for &k in &at {
                    let (offset, n) = (slots[k].offset, 2 * slots[k].n_pairs);
                    if n > 0 {
                        for (j, column) in q_hat.data.chunks_exact(rows).enumerate() {
                            self.q_hat.col_as_slice_mut(j)[offset..offset + n].copy_from_slice(&column[r0..r0 + n]);
                        }
                    }
                    r0 += n;
                    self.directions_in[k] = true;
                }
                if !self.directions_in.iter().all(|&b| b) {
                    return Ok(Vec::new());
                }
                self.directions_in.fill(false);
                self.iteration = it;
                Ok(self.micro1())
            }
            Payload::MacroDisplacements { subdomain, w_tilde } => {
                expect_origin(self.id, msg, Role::Coarse, Some(0))?;
                self.expect_recipient("macro displacements", *subdomain)?;
                if it != self.iteration || self.phase != Phase::Macro {
                    return Err(self.out_of_turn("macro displacements", it));
                }
                expect_shape(self.id, "w_tilde", w_tilde, self.w_tilde.nrows(), self.w_tilde.ncols())?;
                expect_finite(self.id, "w_tilde", "coarse:0", w_tilde)?;
                copy_into(w_tilde, &mut self.w_tilde);
                self.solve_micro2();
                Ok(vec![self.finish_linear_stage()])
            }
            Payload::AndersonStep { gamma, restart } if self.anderson.is_some() => {
                expect_origin(self.id, msg, Role::Interface, Some(0))?;
                if it != self.iteration || self.phase != Phase::Step {
                    return Err(self.out_of_turn("Anderson step", it));
                }
                let history = self.anderson.as_mut().expect("checked");
                let step = match (restart, gamma.is_empty()) {
                    (true, _) => AndersonStep::Restart,
                    (false, true) => AndersonStep::Plain,
                    (false, false) if gamma.len() == history.len() => {
                        if let Some((i, g)) = gamma.iter().enumerate().find(|(_, g)| !g.is_finite()) {
                            return Err(NodeError::new(
                                self.id,
                                format!("Anderson step of iteration {it} has coefficient γ_{i} = {g}: not finite"),
                            ));
                        }
                        AndersonStep::Mix(gamma.clone())
                    }
                    (false, false) => {
                        return Err(NodeError::rejected(
                            self.id,
                            format!(
                                "Anderson step with {} coefficients for {} stored differences",
                                gamma.len(),
                                history.len()
                            ),
                        ))
                    }
                };
                self.phase = Phase::Directions;
                if let Some(pgd) = self.pgd.as_mut() {
                    let t0 = Instant::now();
                    let flops0 = pgd.flops();
                    pgd.apply_coordinates(history, &step);
                    self.record.flops += pgd.flops() - flops0;
                    self.record.seconds += t0.elapsed().as_secs_f64();
                    return Ok(vec![self.boundary_modes()]);
                }
                history.apply(&step, &mut self.w, &mut self.f);
                Ok(vec![self.boundary_state()])
            }
            Payload::Decision(d) => {
                expect_origin(self.id, msg, Role::Interface, Some(0))?;
                if it > self.iteration || self.decided == Some(it) || (d.verdict.is_stop() && it != self.iteration) {
                    return Err(NodeError::rejected(
                        self.id,
                        format!(
                            "{} decision of iteration {it} while at iteration {}",
                            if self.decided == Some(it) { "second" } else { "a" },
                            self.iteration
                        ),
                    ));
                }
                if !d.verdict.is_stop() {
                    // Nothing to do on a decision to go on (q̂ brings the next iteration); a late
                    // one, after that q̂, is let pass.
                    if it == self.iteration {
                        self.decided = Some(it);
                    }
                    return Ok(Vec::new());
                }
                self.finished = true;
                Ok(if self.options.send_displacement {
                    vec![self.displacement()]
                } else {
                    Vec::new()
                })
            }
            other => Err(NodeError::rejected(
                self.id,
                format!(
                    "subdomain {me} does not take {} messages (from {}, iteration {it})",
                    other.field_key(),
                    msg.envelope.sender
                ),
            )),
        }
    }

    fn is_finished(&self) -> bool {
        self.finished
    }

    fn recycle(&mut self, msg: Message) {
        self.pool.recycle(msg);
    }

    fn lend_fields(&mut self, lender: std::sync::Arc<dyn glissade_messages::BlockLender>) {
        self.pool.lend_from(lender);
    }
}
