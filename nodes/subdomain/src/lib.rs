//! The subdomain node: hosts one subdomain's linear stage (docs/method.md, "Linear stage").
//!
//! Setup: builds A_E and sends L_E (when the coarse problem is on), then runs the first linear
//! stage from ŝ = 0. Each iteration: `LocalDirections` (q̂, from every interface node owning one
//! of its interfaces) → micro problem 1 → `MacroForces`;
//! `MacroDisplacements` (w̃) → micro problem 2, relaxation → `BoundaryState` (s = (W, F); with
//! several interface nodes, one message per node owning one of its interfaces, with the rows of
//! those, addressed to it). Without
//! the coarse problem micro 2 is skipped (w̃ = 0). A stop `Decision` ends the node, after sending
//! the full displacement field when asked.
//!
//! With Anderson acceleration (docs/method.md, "Relaxation and Anderson mixing"), from iteration 2 on the end of the
//! linear stage is a reduction: the node records s and G(s) = s₁ + s₂, sends its `AndersonGram`
//! partials, and takes the `AndersonStep` the interface node returns (mixed, plain or restart)
//! before it sends `BoundaryState`. Without acceleration no such message exists.
//!
//! With the PGD linear stage the node holds its state in mode form (docs/pgd.md,
//! the PGD linear stage): the coordinates λˢ of s − s₀ on its basis, relaxed (or mixed, with the same Anderson
//! coefficients as the fields would be) in coordinates, and sends `BoundaryModes` instead of
//! `BoundaryState`: the particular part once, each new basis column once, λˢ every iteration. Its
//! own fields (W, F) are expanded from the same [`ModeForm`] a receiver builds from the messages,
//! so both hold the same numbers bit for bit.
//!
//! After its state, every iteration, the node sends its `LinearStageStats`: the flops its kernels
//! counted and, with PGD, its basis size and criteria. The node reads no clock: the time of its
//! linear stage is the bus's time of its handling of the inputs that run it, and a launcher puts
//! both together ([`LinearStageRecords`]).
//!
//! One file per concern:
//! - this file: the node's state and how it is built ([`SubdomainNode`], [`SubdomainOptions`]);
//! - `node`: its message handling (the [`Node`](glissade_bus::Node) implementation: every input
//!   checked in full before it changes anything, and the phase it is in);
//! - `stage`: the linear stage, full or PGD (micro problems 1 and 2, the relaxation, the state
//!   and counters sent, the displacement field at the end);
//! - `anderson`: the Anderson records and steps;
//! - `records`: the launcher's view, a [`LinearStageRecord`] per subdomain and iteration from the
//!   counters' messages and the bus's handling times.

use glissade_bus::convert::{field_of, FieldPool};
use glissade_bus::RunContext;
use glissade_mechanics::anderson::AndersonHistory;
use glissade_mechanics::linear::{SubdomainFields, SubdomainSolver};
use glissade_mechanics::model::{Acceleration, Model};
use glissade_mechanics::modes::ModeForm;
use glissade_mechanics::pgd::{PgdSettings, PgdStage};
use glissade_messages::{Field, LinearStageStats, Message, NodeId, ParticularModes, Payload, Role, Stage};
use std::sync::Arc;

mod anderson;
mod node;
mod records;
mod stage;

pub use records::{LinearStageRecord, LinearStageRecords, LINEAR_STAGE_INPUTS};

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

/// The rows of the state one interface node receives ([`SubdomainNode::state_parts`]).
struct StatePart {
    to: u32,
    interfaces: Vec<u32>,
    rows: Vec<(usize, usize)>,
}

pub struct SubdomainNode {
    id: NodeId,
    ctx: RunContext,
    model: Arc<Model>,
    solver: SubdomainSolver,
    options: SubdomainOptions,
    iteration: u32,
    /// q̂, s₁, s₂, s, w̃, the macro forces and the Anderson history (acceleration on).
    fields: SubdomainFields,
    phase: Phase,
    /// The last iteration whose decision arrived.
    decided: Option<u32>,
    /// Per boundary slot (interface), whether this iteration's q̂ rows arrived (several interface
    /// nodes each send the rows of their interfaces).
    directions_in: Vec<bool>,
    finished: bool,
    /// PGD linear stage (docs/pgd.md), when the scene asks for it, the mode form of the state as
    /// receivers hold it, and the particular part until the first message carries it.
    pgd: Option<PgdStage>,
    modes: Option<ModeForm>,
    particular: Option<ParticularModes>,
    /// With PGD: (w, f) lag behind the mode form until a consumer needs them
    /// ([`Self::expand_state`]: the compression, the displacement).
    fields_stale: bool,
    /// The counters of the current linear stage, sent after its state.
    stats: LinearStageStats,
    /// Per boundary slot, the index of the interface node that owns its interface (None: any
    /// interface node is taken).
    owners: Option<Vec<u32>>,
    /// With several interface nodes in the deployment: per node owning one of its interfaces
    /// (ascending), its index, its interfaces and their rows (offset, count) in the boundary
    /// layout. Each gets only those rows of the state, addressed to it. Empty: one interface
    /// node, which gets the whole state unaddressed.
    state_parts: Vec<StatePart>,
    /// Buffers of the fields this node sent, back from the bus ([`glissade_bus::Node::recycle`]).
    pool: FieldPool,
    /// Iteration 0 has run (at once from ŝ = 0, or with a time-coarse start once the launcher's
    /// q̂ arrived: [`Self::time_start`]).
    started: bool,
}

impl SubdomainNode {
    pub fn new(ctx: RunContext, model: Arc<Model>, solver: SubdomainSolver, options: SubdomainOptions) -> Self {
        let s = solver.subdomain;
        let (n_b, nt) = (solver.n_boundary(), model.time.n_points());
        let n_slots = solver.op.layout.slots.len();
        let anderson = match options.acceleration {
            Acceleration::None => None,
            Acceleration::Anderson { window } => Some(AndersonHistory::new(window, options.relaxation, n_b, nt)),
        };
        Self {
            fields: SubdomainFields::new(&solver, nt, anderson),
            id: NodeId {
                role: Role::Subdomain,
                index: s as u32,
            },
            ctx,
            model,
            solver,
            options,
            iteration: 0,
            phase: Phase::Directions,
            decided: None,
            directions_in: vec![false; n_slots],
            finished: false,
            pgd: None,
            modes: None,
            particular: None,
            fields_stale: false,
            stats: LinearStageStats::default(),
            owners: None,
            state_parts: Vec::new(),
            pool: FieldPool::default(),
            started: false,
        }
    }

    /// The interfaces each interface node owns (the deployment's groups, by node index): local
    /// directions of an interface are then taken only from its owner.
    pub fn with_interface_owners(mut self, groups: &[Vec<usize>]) -> Self {
        let layout = &self.solver.op.layout;
        self.owners = layout.owners(groups);
        // With several interface nodes every state is addressed: each node subscribes to the
        // states for it with one key expression, `subdomain/*/boundary_state/<node>`.
        self.state_parts = match layout.parts(groups) {
            Some(parts) if groups.len() > 1 => parts
                .iter()
                .map(|p| StatePart {
                    to: p.node,
                    interfaces: p.interfaces(layout),
                    rows: p.ranges(layout),
                })
                .collect(),
            _ => Vec::new(),
        };
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
        self.fields.anderson = self.fields.anderson.take().map(|h| h.with_coordinates(n_b));
        self
    }

    /// The interfaces of this subdomain's boundary, in the order of its layout's slots.
    fn boundary_interfaces(&self) -> Vec<u32> {
        self.solver
            .op
            .layout
            .slots
            .iter()
            .map(|sl| sl.interface as u32)
            .collect()
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
}
