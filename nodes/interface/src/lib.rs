//! The interface node: receives s = (W, F) from every subdomain, runs the local stage on every
//! interface (docs/method.md, "Local stage"), computes the indicators, updates search directions when asked, decides
//! whether to continue, and sends each subdomain q̂ = F̂ + k⁻Ŵ for its next linear stage. At the
//! stop it publishes every interface's s and ŝ.
//!
//! A run may have several interface nodes, each owning a set of interfaces (the scene's
//! deployment): each runs the local stage of its interfaces, receives from each subdomain only
//! the rows of its own, addressed to it (`StateRows`), and sends q̂ for their rows only.
//! Node 0 decides: the others send it their per-interface indicator sums (`IndicatorPartials`),
//! it adds every interface's in interface order (the additions of a one-node run, so the
//! decision is bit for bit the same), applies the stop rule and publishes the `Decision` the
//! others wait for before they send q̂ or, at the stop, their interfaces' solutions.
//!
//! A subdomain with the PGD linear stage sends its state in mode form (`BoundaryModes`): the node
//! keeps that subdomain's particular part and basis ([`ModeForm`]) and expands W and F from the
//! time functions of each message.
//!
//! With Anderson acceleration node 0 also hosts the mixing's global step (docs/method.md, "Relaxation and Anderson mixing"):
//! it sums the subdomains' `AndersonGram` partials in subdomain order (so the sum does not depend
//! on arrival order), solves the small least-squares problem and sends one `AndersonStep` to
//! every subdomain. A search-direction update changes the fixed-point map: the next step restarts
//! the histories.

mod anderson;
mod decision;
mod local_stage;
mod node;
mod stop;
#[cfg(test)]
mod tests;

pub use stop::{stagnated, StopRule};

use faer::Mat;
use glissade_bus::convert::FieldPool;
use glissade_bus::RunContext;
use glissade_mechanics::anderson::{AndersonCoordinator, GramPartials};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::local::{InterfaceFields, InterfaceLocal, StepSums};
use glissade_mechanics::model::Model;
use glissade_mechanics::modes::ModeForm;
use glissade_messages::{InterfaceIndicators, NodeId};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// What the deciding interface node (index 0) holds: the stop rule, the shares of the current
/// iteration by interface node, and the Anderson mixing's global step.
struct Decider {
    rule: StopRule,
    n_nodes: u32,
    /// The interfaces each interface node owns (ascending), by node index.
    groups: Vec<Vec<u32>>,
    /// Each interface node's per-interface indicators of the current iteration, by node index.
    shares: BTreeMap<u32, Vec<InterfaceIndicators>>,
    /// Why the current iteration diverged, when a node saw a non-finite value.
    diverged: Option<String>,
    /// Anderson mixing's global step (acceleration on), the partials of this iteration by
    /// subdomain, the subdomains that send them (every one with an interface), and whether search
    /// directions changed since the last step.
    anderson: Option<AndersonCoordinator>,
    /// Largest number of stored differences a subdomain may hold (the scene's window).
    window: usize,
    grams: BTreeMap<u32, GramPartials>,
    /// The last iteration whose Anderson step was sent.
    stepped: Option<u32>,
    anderson_participants: Vec<u32>,
    directions_changed: bool,
}

pub struct InterfaceNode {
    id: NodeId,
    ctx: RunContext,
    model: Arc<Model>,
    layouts: Vec<Option<BoundaryLayout>>,
    /// The interfaces this node owns (ascending) and, per model interface, its position there.
    owned: Vec<usize>,
    position: Vec<Option<usize>>,
    /// Subdomains with a side on an owned interface.
    participants: Vec<u32>,
    /// Per subdomain, the boundary-state rows it sends this node (None: not a participant).
    state_rows: Vec<Option<StateRows>>,
    /// The subdomains that may send their state in mode form (PGD linear stage; by default
    /// every subdomain with a boundary).
    mode_senders: Vec<u32>,
    locals: Vec<InterfaceLocal>,
    fields: Vec<InterfaceFields>,
    /// Per owned interface followed by the error estimate (contact interfaces; every interface
    /// of a scene without contact), the sums of the forces' step of the current iteration
    /// ([`StepSums`]).
    steps: Vec<Option<StepSums>>,
    received: BTreeSet<u32>,
    /// Per subdomain, its mode form once its first `BoundaryModes` arrived (PGD linear stage).
    modes: Vec<Option<ModeReceiver>>,
    iteration: u32,
    time_weights: Vec<f64>,
    /// This node's share of the current iteration went to the decider; it waits for the decision.
    reported: bool,
    decider: Option<Decider>,
    finished: bool,
    /// After a stop: the positions (in `owned`) of the interfaces whose solution is still to be
    /// published, one message at a time ([`Node::next_output`](glissade_bus::Node::next_output)).
    solutions_left: std::ops::Range<usize>,
    /// Buffers of the fields this node sent, back from the bus ([`Node::recycle`](glissade_bus::Node::recycle)).
    pool: FieldPool,
}

/// The rows of a subdomain's `BoundaryState` this node receives: its whole boundary (`to` None)
/// when the run has one interface node, else the rows of this node's interfaces only (`to` this
/// node's index).
struct StateRows {
    to: Option<u32>,
    interfaces: Vec<u32>,
    /// Per slot of the subdomain's boundary layout, its first row in the message (None: the
    /// slot of another node's interface).
    at: Vec<Option<usize>>,
    rows: usize,
}

/// A PGD subdomain's mode form as this node holds it, and its last state expanded.
struct ModeReceiver {
    form: ModeForm,
    w: Mat<f64>,
    f: Mat<f64>,
}
