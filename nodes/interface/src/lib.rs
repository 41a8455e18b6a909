//! The interface node: receives s = (W, F) from every subdomain, runs the local stage on every
//! interface (DESIGN §3), computes the indicators, updates search directions when asked, decides
//! whether to continue, and sends each subdomain q̂ = F̂ + k⁻Ŵ for its next linear stage. At the
//! stop it publishes every interface's s and ŝ.
//!
//! A run may have several interface nodes, each owning a set of interfaces (the scene's
//! deployment): each runs the local stage of its interfaces and sends q̂ for their rows only.
//! Node 0 decides: the others send it their per-interface indicator sums (`IndicatorPartials`),
//! it adds every interface's in interface order (the additions of a one-node run, so the
//! decision is bit for bit the same), applies the stop rule and publishes the `Decision` the
//! others wait for before they send q̂ or, at the stop, their interfaces' solutions.
//!
//! A subdomain with the PGD linear stage sends its state in mode form (`BoundaryModes`): the node
//! keeps that subdomain's particular part and basis ([`ModeForm`]) and expands W and F from the
//! time functions of each message.
//!
//! With Anderson acceleration node 0 also hosts the mixing's global step (DESIGN §3 "Acceleration"):
//! it sums the subdomains' `AndersonGram` partials in subdomain order (so the sum does not depend
//! on arrival order), solves the small least-squares problem and sends one `AndersonStep` to
//! every subdomain. A search-direction update changes the fixed-point map: the next step restarts
//! the histories.

use faer::{Mat, MatRef};
use glissade_bus::convert::{view, FieldPool};
use glissade_bus::{expect_origin, expect_shape, Node, NodeError, RunContext};
use glissade_mechanics::anderson::{AndersonCoordinator, AndersonStep, GramPartials, MAX_CONDITION};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::local::{IndicatorSums, InterfaceFields, InterfaceLocal};
use glissade_mechanics::model::{Acceleration, Model, Side};
use glissade_mechanics::modes::ModeForm;
use glissade_messages::{
    role_field_topic, Decision, InterfaceIndicators, InterfaceSolution, Message, NodeId, Payload, Role, Stage, Verdict,
};
use rayon::prelude::*;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// The stop rules of DESIGN §3: tolerance, max iterations, stagnation, divergence.
#[derive(Debug, Clone, PartialEq)]
pub struct StopRule {
    pub tolerance: f64,
    pub contact_tolerance: Option<f64>,
    pub max_iterations: usize,
    pub stagnation_window: usize,
    pub stagnation_ratio: f64,
    /// Diverged when Σ(‖s‖² + ‖ŝ‖²) exceeds this factor times its value at iteration 1.
    pub growth_limit: f64,
    history: Vec<f64>,
    first_norm: Option<f64>,
}

impl StopRule {
    pub fn new(p: &glissade_mechanics::model::SolverParams) -> Self {
        Self {
            tolerance: p.tolerance,
            contact_tolerance: p.contact_tolerance,
            max_iterations: p.max_iterations,
            stagnation_window: p.stagnation_window,
            stagnation_ratio: p.stagnation_ratio,
            growth_limit: 1e12,
            history: Vec::new(),
            first_norm: None,
        }
    }

    /// Verdict after the local stage of iteration `n` (0-based).
    pub fn decide(&mut self, n: u32, sums: &IndicatorSums) -> Verdict {
        let eta = sums.eta();
        self.history.push(eta);
        if !eta.is_finite() || !sums.contact_indicator().is_finite() {
            return Verdict::Diverged {
                detail: format!("indicator is not finite at iteration {n} (η = {eta})"),
            };
        }
        if n == 1 {
            self.first_norm = Some(sums.eta_den);
        }
        if let Some(first) = self.first_norm {
            if first > 0.0 && sums.eta_den > self.growth_limit * first {
                return Verdict::Diverged {
                    detail: format!(
                        "the solution's norm grew {:.1e}-fold since iteration 1 (iteration {n})",
                        sums.eta_den / first
                    ),
                };
            }
        }
        let contact_ok = self.contact_tolerance.is_none_or(|t| sums.contact_indicator() <= t);
        if eta <= self.tolerance && contact_ok {
            return Verdict::Converged;
        }
        if n as usize + 1 >= self.max_iterations {
            return Verdict::MaxIterations;
        }
        let w = self.stagnation_window;
        if w > 0 && self.history.len() > 2 * w {
            let k = self.history.len();
            let recent = self.history[k - w..].iter().cloned().fold(f64::INFINITY, f64::min);
            let before = self.history[..k - w].iter().cloned().fold(f64::INFINITY, f64::min);
            if recent > self.stagnation_ratio * before {
                let mut detail = format!(
                    "min η over the last {w} iterations is {recent:.3e}, not below {} × the earlier minimum {before:.3e}",
                    self.stagnation_ratio
                );
                if let Some((a, b)) = period_two(&self.history[k - w..]) {
                    detail.push_str(&format!(
                        "; η alternates between {a:.3e} and {b:.3e}: the iteration has a mode at −1 \
                         (an undamped cycle; lower solver.relaxation below 1)"
                    ));
                }
                return Verdict::Stagnated { detail };
            }
        }
        Verdict::Continue
    }
}

/// The two values η alternates between when the window is a period-2 cycle: its successive
/// differences alternate in sign throughout, and every two-step change |η_k − η_{k−2}| is below a
/// tenth of the smallest one-step change (the cycle may drift slowly, it does not converge).
fn period_two(window: &[f64]) -> Option<(f64, f64)> {
    if window.len() < 4 {
        return None;
    }
    let steps: Vec<f64> = window.windows(2).map(|p| p[1] - p[0]).collect();
    let alternating = steps.windows(2).all(|d| d[0] * d[1] < 0.0);
    let smallest_step = steps.iter().fold(f64::INFINITY, |m, d| m.min(d.abs()));
    let largest_drift = window.windows(3).fold(0.0f64, |m, p| m.max((p[2] - p[0]).abs()));
    let k = window.len();
    (alternating && largest_drift <= 0.1 * smallest_step).then_some((window[k - 2], window[k - 1]))
}

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
    locals: Vec<InterfaceLocal>,
    fields: Vec<InterfaceFields>,
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
    /// published, one message at a time ([`Node::next_output`]).
    solutions_left: std::ops::Range<usize>,
    /// Buffers of the fields this node sent, back from the bus ([`Node::recycle`]).
    pool: FieldPool,
}

/// A PGD subdomain's mode form as this node holds it, and its last state expanded.
struct ModeReceiver {
    form: ModeForm,
    w: Mat<f64>,
    f: Mat<f64>,
}

/// First (row, column, value) of a matrix that is NaN or infinite.
fn first_non_finite(m: &Mat<f64>) -> Option<(usize, usize, f64)> {
    (0..m.ncols()).find_map(|c| {
        m.col_as_slice(c)
            .iter()
            .position(|v| !v.is_finite())
            .map(|r| (r, c, m[(r, c)]))
    })
}

/// One interface's sums as they travel to the decider.
fn indicators_of(interface: usize, s: &IndicatorSums, direction_updated: bool) -> InterfaceIndicators {
    InterfaceIndicators {
        interface: interface as u32,
        eta_num: s.eta_num,
        eta_den: s.eta_den,
        force_num: s.force_num,
        force_den: s.force_den,
        jump_num: s.jump_num,
        jump_den: s.jump_den,
        counts: s.counts,
        status_changes: s.status_changes,
        direction_updated,
    }
}

fn sums_of(i: &InterfaceIndicators) -> IndicatorSums {
    IndicatorSums {
        eta_num: i.eta_num,
        eta_den: i.eta_den,
        force_num: i.force_num,
        force_den: i.force_den,
        jump_num: i.jump_num,
        jump_den: i.jump_den,
        counts: i.counts,
        status_changes: i.status_changes,
    }
}

impl InterfaceNode {
    /// The only interface node of a run: it owns every interface of `model`, with
    /// k⁻ = k₀ = `k0[i]`.
    pub fn new(ctx: RunContext, model: Arc<Model>, k0: &[f64]) -> Self {
        let all = vec![(0..model.interfaces.len()).collect()];
        Self::owning(ctx, model, k0, &all, 0)
    }

    /// Interface node `index` of `groups.len()`, owning the interfaces `groups[index]` (the groups
    /// partition the model's interfaces). Node 0 also decides: it sums every node's indicators in
    /// interface order, applies the stop rule, sends the decision and hosts the Anderson step.
    pub fn owning(ctx: RunContext, model: Arc<Model>, k0: &[f64], groups: &[Vec<usize>], index: usize) -> Self {
        let nt = model.time.n_points();
        let mut owned = groups[index].clone();
        owned.sort_unstable();
        let mut position = vec![None; model.interfaces.len()];
        for (p, &i) in owned.iter().enumerate() {
            position[i] = Some(p);
        }
        let layouts: Vec<Option<BoundaryLayout>> = (0..model.subdomains.len())
            .map(|s| {
                let l = BoundaryLayout::new(&model, s, k0);
                (!l.is_empty()).then_some(l)
            })
            .collect();
        let with_slot = |pred: &dyn Fn(usize) -> bool| -> Vec<u32> {
            layouts
                .iter()
                .enumerate()
                .filter(|(_, l)| l.as_ref().is_some_and(|l| l.slots.iter().any(|sl| pred(sl.interface))))
                .map(|(s, _)| s as u32)
                .collect()
        };
        let participants = with_slot(&|i| position[i].is_some());
        let decider = (index == 0).then(|| Decider {
            rule: StopRule::new(&model.solver),
            n_nodes: groups.len() as u32,
            groups: groups
                .iter()
                .map(|g| {
                    let mut g: Vec<u32> = g.iter().map(|&i| i as u32).collect();
                    g.sort_unstable();
                    g
                })
                .collect(),
            shares: BTreeMap::new(),
            diverged: None,
            anderson: match model.solver.acceleration {
                Acceleration::None => None,
                Acceleration::Anderson { .. } => Some(AndersonCoordinator::new(MAX_CONDITION)),
            },
            window: match model.solver.acceleration {
                Acceleration::None => 0,
                Acceleration::Anderson { window } => window,
            },
            grams: BTreeMap::new(),
            stepped: None,
            anderson_participants: with_slot(&|_| true),
            directions_changed: false,
        });
        let locals = owned
            .iter()
            .map(|&i| InterfaceLocal::new(i, &model.interfaces[i], k0[i], nt))
            .collect();
        let fields = owned
            .iter()
            .map(|&i| InterfaceFields::zeros(model.interfaces[i].n_pairs(), nt))
            .collect();
        let n_subdomains = model.subdomains.len();
        Self {
            id: NodeId {
                role: Role::Interface,
                index: index as u32,
            },
            ctx,
            time_weights: model.time.trapezoid_weights(),
            model,
            layouts,
            owned,
            position,
            participants,
            locals,
            fields,
            received: BTreeSet::new(),
            modes: std::iter::repeat_with(|| None).take(n_subdomains).collect(),
            iteration: 0,
            reported: false,
            decider,
            finished: false,
            solutions_left: 0..0,
            pool: FieldPool::default(),
        }
    }

    /// The rejection of a message this node does not take.
    fn not_taken(&self, msg: &Message) -> NodeError {
        NodeError::rejected(
            self.id,
            format!(
                "interface node {} does not take {} messages (from {}, iteration {})",
                self.id.index,
                msg.payload.field_key(),
                msg.envelope.sender,
                msg.envelope.iteration
            ),
        )
    }

    /// Subdomains whose boundary state this node needs (a side on an interface it owns).
    pub fn participants(&self) -> &[u32] {
        &self.participants
    }

    /// The interfaces this node owns.
    pub fn owned(&self) -> &[usize] {
        &self.owned
    }

    fn msg(&self, stage: Stage, iteration: u32, payload: Payload) -> Message {
        Message {
            envelope: self.ctx.envelope(self.id, iteration, stage),
            payload,
        }
    }

    /// Names a boundary entry: interface, pair and component.
    fn locate(&self, s: usize, row: usize) -> String {
        let layout = self.layouts[s].as_ref().expect("participant");
        for slot in &layout.slots {
            if row >= slot.offset && row < slot.offset + 2 * slot.n_pairs {
                let e = row - slot.offset;
                let itf = &self.model.interfaces[slot.interface];
                let [x, y] = itf.coords[e / 2];
                return format!(
                    "interface {} ({} | {}), pair {} at ({x}, {y}), component {}",
                    slot.interface,
                    self.model.subdomains[itf.a].name,
                    self.model.subdomains[itf.b].name,
                    e / 2,
                    if e.is_multiple_of(2) { "x" } else { "y" }
                );
            }
        }
        format!("boundary entry {row}")
    }

    /// Copies subdomain `s`'s rows of W and F into its interfaces' fields: the traces on one
    /// thread and the forces on another (the other nodes wait for the local stage).
    fn store(&mut self, s: u32, w: MatRef<'_, f64>, f: MatRef<'_, f64>) {
        let layout = self.layouts[s as usize].as_ref().expect("participant");
        for slot in &layout.slots {
            if let Some(p) = self.position[slot.interface] {
                let (to_w, to_f) = self.fields[p].side_mut(slot.side);
                let rows = to_w.nrows();
                rayon::join(
                    || to_w.copy_from(w.subrows(slot.offset, rows)),
                    || to_f.copy_from(f.subrows(slot.offset, rows)),
                );
            }
        }
    }

    /// Where a non-finite value of subdomain `s`'s W or F sits, for the divergence diagnosis.
    fn non_finite_detail(&self, s: u32, name: &str, (r, c, v): (usize, usize, f64)) -> String {
        format!(
            "subdomain {} (`{}`) sent {name} = {v} at {}, time t_{c} = {} s, iteration {}",
            s,
            self.model.subdomains[s as usize].name,
            self.locate(s as usize, r),
            self.model.time.t(c),
            self.iteration
        )
    }

    /// A subdomain's state in mode form, checked in full before anything changes: the
    /// particular part in its first message only, the basis update and λ of the sizes its
    /// boundary and the held modes allow. Returns the subdomain's mode receiver, updated and
    /// expanded, for the caller to put back.
    fn take_modes(&mut self, s: u32, payload: &Payload) -> Result<ModeReceiver, NodeError> {
        let Payload::BoundaryModes {
            particular,
            first_mode,
            z,
            g,
            lambda,
            ..
        } = payload
        else {
            unreachable!("called on boundary modes")
        };
        let n_b = self.layouts[s as usize].as_ref().expect("participant").len();
        let nt = self.model.time.n_points();
        let reject = |what: String| NodeError::rejected(self.id, format!("boundary modes of subdomain {s}: {what}"));
        if z.rows() != n_b || lambda.cols() != nt {
            return Err(reject(format!(
                "modes of {} entries and time functions of {} time points, expected {n_b} and {nt}",
                z.rows(),
                lambda.cols()
            )));
        }
        let mut receiver = match (particular, self.modes[s as usize].is_some()) {
            (Some(pm), false) => {
                if pm.w.rows() != n_b || pm.time.cols() != nt {
                    return Err(reject(format!(
                        "particular part of {} entries and {} time points, expected {n_b} and {nt}",
                        pm.w.rows(),
                        pm.time.cols()
                    )));
                }
                let form = ModeForm::new(n_b, nt, pm.time.rows(), &pm.w.data, &pm.f.data, &pm.time.data)
                    .map_err(|e| reject(e.to_string()))?;
                ModeReceiver {
                    form,
                    w: Mat::zeros(n_b, nt),
                    f: Mat::zeros(n_b, nt),
                }
            }
            (Some(_), true) => return Err(reject("a second particular part".into())),
            (None, false) => return Err(reject("mode form before its particular part".into())),
            (None, true) => self.modes[s as usize].take().expect("held"),
        };
        if let Err(e) = receiver
            .form
            .check(*first_mode as usize, &z.data, &g.data, &lambda.data)
        {
            // Put a held form back unchanged.
            if particular.is_none() {
                self.modes[s as usize] = Some(receiver);
            }
            return Err(reject(e.to_string()));
        }
        receiver
            .form
            .update(*first_mode as usize, &z.data, &g.data, &lambda.data)
            .expect("checked");
        receiver.form.expand_into(receiver.w.as_mut(), receiver.f.as_mut());
        Ok(receiver)
    }

    /// The local stage on the owned interfaces and their indicators, in interface order.
    fn local_stage(&mut self) -> Vec<Message> {
        let n = self.iteration;
        // Interfaces are independent: run them in parallel; the decider sums them in interface
        // order, so the sums are the same whatever the thread and node count.
        let model = &self.model;
        let weights = &self.time_weights;
        let share: Vec<InterfaceIndicators> = self
            .locals
            .par_iter_mut()
            .zip(self.fields.par_iter())
            .zip(self.owned.par_iter())
            .map(|((local, fields), &i)| {
                let itf = &model.interfaces[i];
                let sums = local.local_stage_with_sums(itf, weights, fields, n == 0);
                let updated = model.solver.search_direction_update
                    && local.update_directions(itf, model.solver.alpha, model.solver.i0);
                indicators_of(i, &sums, updated)
            })
            .collect();
        self.report(share, None)
    }

    /// Hands this node's share of the iteration to the decider: itself (node 0) or node 0 over
    /// the bus.
    fn report(&mut self, share: Vec<InterfaceIndicators>, diverged: Option<String>) -> Vec<Message> {
        self.reported = true;
        if self.decider.is_some() {
            self.take_share(0, share, diverged)
        } else {
            vec![self.msg(
                Stage::Local,
                self.iteration,
                Payload::IndicatorPartials {
                    interfaces: share,
                    diverged,
                },
            )]
        }
    }

    /// The decider stores node `from`'s share; with every node's (or a divergence), it decides.
    fn take_share(&mut self, from: u32, share: Vec<InterfaceIndicators>, diverged: Option<String>) -> Vec<Message> {
        let d = self.decider.as_mut().expect("decider");
        d.shares.insert(from, share);
        if d.diverged.is_none() {
            d.diverged = diverged;
        }
        if d.diverged.is_none() && d.shares.len() < d.n_nodes as usize {
            return Vec::new();
        }
        self.decide()
    }

    /// Sums the shares in interface order (the one-node order of additions), applies the stop
    /// rule and acts on the decision.
    fn decide(&mut self) -> Vec<Message> {
        let n = self.iteration;
        let d = self.decider.as_mut().expect("decider");
        let shares = std::mem::take(&mut d.shares);
        let (sums, updates, verdict) = match d.diverged.take() {
            Some(detail) => (IndicatorSums::default(), Vec::new(), Verdict::Diverged { detail }),
            None => {
                let mut all: Vec<&InterfaceIndicators> = shares.values().flatten().collect();
                all.sort_by_key(|i| i.interface);
                let mut sums = IndicatorSums::default();
                let mut updates = Vec::new();
                for i in all {
                    sums.add(&sums_of(i));
                    if i.direction_updated {
                        updates.push(i.interface);
                    }
                }
                let verdict = d.rule.decide(n, &sums);
                (sums, updates, verdict)
            }
        };
        d.directions_changed |= !updates.is_empty();
        let decision = Decision {
            eta: sums.eta(),
            contact_indicator: sums.contact_indicator(),
            force_error: sums.force_error(),
            jump_error: sums.jump_error(),
            counts: sums.counts,
            status_changes: sums.status_changes,
            direction_updates: updates,
            verdict,
        };
        let stop = decision.verdict.is_stop();
        let mut out = vec![self.msg(Stage::Local, n, Payload::Decision(decision))];
        out.extend(self.after_decision(stop));
        out
    }

    /// After the decision of the current iteration: the owned interfaces' s and ŝ at a stop,
    /// else q̂ to every participant for the next linear stage.
    fn after_decision(&mut self, stop: bool) -> Vec<Message> {
        let n = self.iteration;
        let mut out = Vec::new();
        if stop {
            self.finished = true;
            // The solutions are the run's largest messages (s and ŝ of every owned interface, all
            // time points: 141 MB at N = 1000 on the stratified scene): they follow the decision
            // one at a time ([`Node::next_output`]), each written into the buffers of the one
            // before once the bus has it, instead of all into new memory at once (whose pages
            // are faulted in as they are written).
            self.solutions_left = 0..self.owned.len();
        } else {
            let nt = self.model.time.n_points();
            let (layouts, position, locals) = (&self.layouts, &self.position, &self.locals);
            let mine: Vec<Vec<_>> = self
                .participants
                .iter()
                .map(|&s| {
                    let layout = layouts[s as usize].as_ref().expect("participant");
                    layout
                        .slots
                        .iter()
                        .filter_map(|sl| position[sl.interface].map(|p| (p, sl)))
                        .collect()
                })
                .collect();
            let rows: Vec<usize> = mine
                .iter()
                .map(|m| m.iter().map(|(_, sl)| 2 * sl.n_pairs).sum())
                .collect();
            // Written in place into the messages' fields (buffers of earlier ones), one
            // subdomain per task: the subdomains wait for these.
            let q_hats = self.pool.fields_with(&rows, nt, |i, mut q| {
                let mut offset = 0;
                for (p, sl) in &mine[i] {
                    locals[*p].q_hat_into(sl.side == Side::A, q.as_mut(), offset);
                    offset += 2 * sl.n_pairs;
                }
            });
            for ((&s, mine), q_hat) in self.participants.iter().zip(&mine).zip(q_hats) {
                out.push(self.msg(
                    Stage::Local,
                    n + 1,
                    Payload::LocalDirections {
                        subdomain: s,
                        interfaces: mine.iter().map(|(_, sl)| sl.interface as u32).collect(),
                        q_hat,
                    },
                ));
            }
        }
        self.iteration += 1;
        self.received.clear();
        self.reported = false;
        out
    }

    /// The decider takes another interface node's share of the current iteration.
    fn indicator_partials(
        &mut self,
        msg: &Message,
        share: &[InterfaceIndicators],
        diverged: &Option<String>,
    ) -> Result<Vec<Message>, NodeError> {
        let Some(d) = self.decider.as_ref() else {
            return Err(self.not_taken(msg));
        };
        expect_origin(self.id, msg, Role::Interface, None)?;
        let (from, it) = (msg.envelope.sender.index, msg.envelope.iteration);
        if from == 0 || from >= d.n_nodes {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "indicators from interface node {from}; this run has interface nodes 0 to {}",
                    d.n_nodes - 1
                ),
            ));
        }
        if it != self.iteration {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "indicators of iteration {it} from interface node {from} while at iteration {}",
                    self.iteration
                ),
            ));
        }
        if d.shares.contains_key(&from) {
            return Err(NodeError::rejected(
                self.id,
                format!("second indicators of iteration {it} from interface node {from}"),
            ));
        }
        let n_itf = self.model.interfaces.len() as u32;
        if let Some(bad) = share.iter().find(|i| i.interface >= n_itf) {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "indicators of interface {} from interface node {from}: the scene has {n_itf}",
                    bad.interface
                ),
            ));
        }
        let owned = &d.groups[from as usize];
        let covers: Vec<u32> = share.iter().map(|i| i.interface).collect();
        if diverged.is_none() && &covers != owned {
            return Err(NodeError::rejected(
                self.id,
                format!("indicators of interfaces {covers:?} from interface node {from}, which owns {owned:?}"),
            ));
        }
        let held: BTreeSet<u32> = d.shares.values().flatten().map(|i| i.interface).collect();
        if let Some(dup) = share.iter().find(|i| held.contains(&i.interface)) {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "indicators of interface {} from interface node {from}, which another node owns",
                    dup.interface
                ),
            ));
        }
        Ok(self.take_share(from, share.to_vec(), diverged.clone()))
    }

    /// A non-deciding node acts on the decider's decision.
    fn decision(&mut self, msg: &Message, d: &Decision) -> Result<Vec<Message>, NodeError> {
        if self.decider.is_some() {
            return Err(self.not_taken(msg));
        }
        expect_origin(self.id, msg, Role::Interface, Some(0))?;
        let it = msg.envelope.iteration;
        if it != self.iteration {
            return Err(NodeError::rejected(
                self.id,
                format!("decision of iteration {it} while at iteration {}", self.iteration),
            ));
        }
        if !self.reported && !d.verdict.is_stop() {
            return Err(NodeError::rejected(
                self.id,
                format!("decision to continue at iteration {it} before this node's indicators"),
            ));
        }
        Ok(self.after_decision(d.verdict.is_stop()))
    }
}

impl InterfaceNode {
    /// Stores one subdomain's Anderson partials; with every participant's, sums them in subdomain
    /// order, decides the step and sends it.
    fn anderson_gram(
        &mut self,
        msg: &Message,
        s: u32,
        gram: &glissade_messages::Field,
        projection: &glissade_messages::Field,
        residual2: f64,
    ) -> Result<Vec<Message>, NodeError> {
        let id = self.id;
        let at = self.iteration;
        let iteration = msg.envelope.iteration;
        if self.decider.as_ref().is_none_or(|d| d.anderson.is_none()) {
            return Err(self.not_taken(msg));
        }
        expect_origin(id, msg, Role::Subdomain, Some(s))?;
        let d = self.decider.as_mut().expect("checked");
        if !d.anderson_participants.contains(&s) {
            return Err(NodeError::rejected(
                id,
                format!("Anderson partials from subdomain {s}, which has no interface"),
            ));
        }
        if iteration != at {
            return Err(NodeError::rejected(
                id,
                format!("Anderson partials of iteration {iteration} from subdomain {s} while at iteration {at}"),
            ));
        }
        if d.stepped == Some(iteration) {
            return Err(NodeError::rejected(
                id,
                format!("Anderson partials of iteration {iteration} from subdomain {s} after the step was sent"),
            ));
        }
        if d.grams.contains_key(&s) {
            return Err(NodeError::rejected(
                id,
                format!("second Anderson partials of iteration {iteration} from subdomain {s}"),
            ));
        }
        let k = gram.rows();
        if k > d.window {
            return Err(NodeError::rejected(
                id,
                format!(
                    "Anderson partials of iteration {iteration} from subdomain {s} over {k} differences; the window is {}",
                    d.window
                ),
            ));
        }
        expect_shape(id, "gram", gram, k, k)?;
        expect_shape(id, "projection", projection, k, 1)?;
        if let Some((other, p)) = d.grams.iter().next() {
            if p.k != k {
                return Err(NodeError::rejected(
                    id,
                    format!(
                        "Anderson partials of iteration {iteration}: subdomain {s} holds {k} differences, subdomain {other} {}",
                        p.k
                    ),
                ));
            }
        }
        let partials = GramPartials {
            k,
            gram: gram.data.to_vec(),
            projection: projection.data.to_vec(),
            residual2,
        };
        d.grams.insert(s, partials);
        if d.grams.len() < d.anderson_participants.len() {
            return Ok(Vec::new());
        }
        let mut sum = GramPartials::zeros(k);
        for p in d.grams.values() {
            sum.add(p);
        }
        d.grams.clear();
        d.stepped = Some(at);
        let changed = std::mem::take(&mut d.directions_changed);
        let step = d.anderson.as_mut().expect("checked").decide(&sum, changed);
        let (gamma, restart) = match step {
            AndersonStep::Mix(g) => (g, false),
            AndersonStep::Plain => (Vec::new(), false),
            AndersonStep::Restart => (Vec::new(), true),
        };
        Ok(vec![self.msg(
            Stage::Linear,
            at,
            Payload::AndersonStep { gamma, restart },
        )])
    }
}

impl Node for InterfaceNode {
    fn id(&self) -> NodeId {
        self.id
    }

    fn subscriptions(&self) -> Vec<String> {
        let run = &self.ctx.run_id;
        let mut subs = vec![
            role_field_topic(run, Role::Subdomain, "boundary_state", None),
            role_field_topic(run, Role::Subdomain, "boundary_modes", None),
        ];
        match &self.decider {
            Some(d) => {
                if d.n_nodes > 1 {
                    subs.push(role_field_topic(run, Role::Interface, "indicator_partials", None));
                }
                if d.anderson.is_some() {
                    subs.push(role_field_topic(run, Role::Subdomain, "anderson_gram", None));
                }
            }
            None => subs.push(role_field_topic(run, Role::Interface, "decision", None)),
        }
        subs
    }

    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        Ok(Vec::new())
    }

    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError> {
        if self.finished {
            return Ok(Vec::new());
        }
        let (s, w, f) = match &msg.payload {
            Payload::AndersonGram {
                subdomain,
                gram,
                projection,
                residual2,
            } => return self.anderson_gram(msg, *subdomain, gram, projection, *residual2),
            Payload::IndicatorPartials { interfaces, diverged } => {
                return self.indicator_partials(msg, interfaces, diverged)
            }
            Payload::Decision(d) => return self.decision(msg, d),
            Payload::BoundaryState { subdomain, w, f } => (*subdomain, Some(w), Some(f)),
            Payload::BoundaryModes { subdomain, .. } => (*subdomain, None, None),
            _ => return Err(self.not_taken(msg)),
        };
        if self.layouts.get(s as usize).is_none_or(Option::is_none) {
            return Err(NodeError::rejected(
                self.id,
                format!("boundary state from subdomain {s}, which has no interface"),
            ));
        }
        if !self.participants.contains(&s) {
            // A side on interfaces other nodes own only.
            return Ok(Vec::new());
        }
        expect_origin(self.id, msg, Role::Subdomain, Some(s))?;
        if msg.envelope.iteration != self.iteration {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "boundary state of iteration {} from subdomain {s} while at iteration {}",
                    msg.envelope.iteration, self.iteration
                ),
            ));
        }
        if self.received.contains(&s) {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "second boundary state of iteration {} from subdomain {s}",
                    self.iteration
                ),
            ));
        }
        if self.reported {
            // This iteration already diverged here: the decision is on its way.
            return Ok(Vec::new());
        }
        if let (Some(w), Some(f)) = (w, f) {
            let n_b = self.layouts[s as usize].as_ref().expect("participant").len();
            let nt = self.model.time.n_points();
            expect_shape(self.id, "w", w, n_b, nt)?;
            expect_shape(self.id, "f", f, n_b, nt)?;
            self.received.insert(s);
            // Both fields checked on two threads; W's non-finite value is named first.
            let (bad_w, bad_f) = rayon::join(|| w.first_non_finite(), || f.first_non_finite());
            for (name, bad) in [("W", bad_w), ("F", bad_f)] {
                if let Some(at) = bad {
                    let detail = self.non_finite_detail(s, name, at);
                    return Ok(self.report(Vec::new(), Some(detail)));
                }
            }
            self.store(s, view(w), view(f));
        } else {
            let receiver = self.take_modes(s, &msg.payload)?;
            self.received.insert(s);
            let bad = [("W", &receiver.w), ("F", &receiver.f)]
                .into_iter()
                .find_map(|(name, m)| first_non_finite(m).map(|at| (name, at)));
            if let Some((name, at)) = bad {
                let detail = self.non_finite_detail(s, name, at);
                self.modes[s as usize] = Some(receiver);
                return Ok(self.report(Vec::new(), Some(detail)));
            }
            self.store(s, receiver.w.as_ref(), receiver.f.as_ref());
            self.modes[s as usize] = Some(receiver);
        }
        if self.received.len() == self.participants.len() {
            return Ok(self.local_stage());
        }
        Ok(Vec::new())
    }

    fn next_output(&mut self) -> Option<Message> {
        let p = self.solutions_left.next()?;
        // The launcher keeps the solutions: written into the buffers of the one before, not
        // into shared-memory blocks the launcher would hold while the next ones need new ones.
        let (local, s, pool) = (&self.locals[p], &self.fields[p], &mut self.pool);
        let h = &local.hat;
        let solution = InterfaceSolution {
            interface: self.owned[p] as u32,
            w_a: pool.field_of_unlent(s.w_a.as_ref()),
            w_b: pool.field_of_unlent(s.w_b.as_ref()),
            f_a: pool.field_of_unlent(s.f_a.as_ref()),
            f_b: pool.field_of_unlent(s.f_b.as_ref()),
            w_a_hat: pool.field_of_unlent(h.w_a.as_ref()),
            w_b_hat: pool.field_of_unlent(h.w_b.as_ref()),
            f_a_hat: pool.field_of_unlent(h.f_a.as_ref()),
            f_b_hat: pool.field_of_unlent(h.f_b.as_ref()),
            status: local.status.iter().map(|s| *s as u8).collect(),
        };
        Some(self.msg(Stage::Final, self.iteration, Payload::InterfaceSolution(solution)))
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

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_bus::convert::field_of;
    use glissade_mechanics::local::IndicatorSums;
    use glissade_mechanics::model::SolverParams;
    use glissade_messages::{Envelope, Field, SCHEMA_VERSION};
    use glissade_scene::load_str;

    fn sums(eta: f64, norm: f64) -> IndicatorSums {
        // η² = num / (½ den)
        IndicatorSums {
            eta_num: 0.5 * eta * eta * norm,
            eta_den: norm,
            ..Default::default()
        }
    }

    #[test]
    fn stop_rules() {
        let p = SolverParams {
            tolerance: 1e-3,
            max_iterations: 100,
            stagnation_window: 5,
            stagnation_ratio: 0.9,
            ..Default::default()
        };
        let mut r = StopRule::new(&p);
        assert_eq!(r.decide(0, &sums(0.5, 1.0)), Verdict::Continue);
        assert_eq!(r.decide(1, &sums(1e-4, 1.0)), Verdict::Converged);

        let mut r = StopRule::new(&p);
        let mut v = Verdict::Continue;
        for n in 0..20 {
            v = r.decide(n, &sums(0.1, 1.0));
            if v.is_stop() {
                assert_eq!(n, 10, "stagnation is seen once the history holds two windows");
                break;
            }
        }
        assert!(
            matches!(&v, Verdict::Stagnated { detail } if !detail.contains("alternates")),
            "{v:?}"
        );

        // A period-2 cycle (η = 0.4, 0.3, 0.4, …) is named as such.
        let mut r = StopRule::new(&p);
        let mut v = Verdict::Continue;
        for n in 0..20 {
            v = r.decide(n, &sums(if n % 2 == 0 { 0.4 } else { 0.3 }, 1.0));
            if v.is_stop() {
                break;
            }
        }
        assert!(
            matches!(&v, Verdict::Stagnated { detail } if detail.contains("alternates between")),
            "{v:?}"
        );

        let mut r = StopRule::new(&p);
        r.decide(0, &sums(0.5, 1.0));
        r.decide(1, &sums(0.5, 1.0));
        let v = r.decide(2, &sums(0.5, 1e13));
        assert!(
            matches!(&v, Verdict::Diverged { detail } if detail.contains("grew")),
            "{v:?}"
        );

        let mut r = StopRule::new(&SolverParams { max_iterations: 3, ..p });
        assert_eq!(r.decide(0, &sums(0.5, 1.0)), Verdict::Continue);
        assert_eq!(r.decide(1, &sums(0.4, 1.0)), Verdict::Continue);
        assert_eq!(r.decide(2, &sums(0.3, 1.0)), Verdict::MaxIterations);
    }

    /// A block of `n` unit subdomains in a row, clamped at x = 0: interfaces 0 (b.1 | b.2),
    /// 1 (b.2 | b.3), …
    fn in_a_row(n: usize) -> (Arc<Model>, RunContext) {
        let text = format!(
            "[time]\nT = 1.0\nN = 2\n[materials.m]\nE = 1000.0\nnu = 0.3\n[[block]]\nname = \"b\"\n\
             material = \"m\"\nx = [0.0, {n}.0]\ny = [0.0, 1.0]\nnx = {n}\nny = 1\nsplit = [{n}, 1]\n\
             [[boundary]]\nx = 0.0\nux = 0.0\nuy = 0.0\n"
        );
        let sc = load_str(&text, "row.toml").unwrap();
        let ctx = RunContext {
            run_id: "r".into(),
            scene_fingerprint: sc.fingerprint,
        };
        (Arc::new(sc.model), ctx)
    }

    fn message(ctx: &RunContext, sender: NodeId, iteration: u32, payload: Payload) -> Message {
        Message {
            envelope: ctx.envelope(sender, iteration, Stage::Linear),
            payload,
        }
    }

    /// Boundary states of iteration 0 with distinct values per entry, subdomains 0 to 2.
    fn states(model: &Model, ctx: &RunContext, k0: &[f64]) -> Vec<Message> {
        (0..3u32)
            .map(|s| {
                let n_b = BoundaryLayout::new(model, s as usize, k0).len();
                let w = Field::from_fn(n_b, 3, |r, c| 1e-3 * ((7 * r + 3 * c + s as usize) % 11) as f64);
                let f = Field::from_fn(n_b, 3, |r, c| ((5 * r + c + 2 * s as usize) % 13) as f64 - 6.0);
                let sender = NodeId {
                    role: Role::Subdomain,
                    index: s,
                };
                message(ctx, sender, 0, Payload::BoundaryState { subdomain: s, w, f })
            })
            .collect()
    }

    #[test]
    fn two_interface_nodes_decide_as_one() {
        let (model, ctx) = in_a_row(3);
        assert_eq!(model.interfaces.len(), 2);
        let k0 = vec![1000.0; 2];
        let mut one = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
        let groups = [vec![1], vec![0]];
        let mut n0 = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 0);
        let mut n1 = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 1);
        assert_eq!((n0.participants(), n1.participants()), (&[1, 2][..], &[0, 1][..]));
        let (mut single, mut from0, mut from1) = (Vec::new(), Vec::new(), Vec::new());
        for m in states(&model, &ctx, &k0) {
            single.extend(one.handle(&m).unwrap());
            from0.extend(n0.handle(&m).unwrap());
            from1.extend(n1.handle(&m).unwrap());
        }
        assert!(from0.is_empty(), "node 0 waits for node 1's indicators");
        let [partials] = &from1[..] else {
            panic!("node 1 sends its indicators only: {from1:?}")
        };
        assert!(
            matches!(&partials.payload, Payload::IndicatorPartials { interfaces, diverged: None }
            if interfaces.len() == 1 && interfaces[0].interface == 0)
        );
        // A share that names node 0's interface is refused, naming it.
        let mut wrong = partials.clone();
        if let Payload::IndicatorPartials { interfaces, .. } = &mut wrong.payload {
            interfaces[0].interface = 1;
        }
        let mut n0_copy = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 0);
        for m in states(&model, &ctx, &k0) {
            n0_copy.handle(&m).unwrap();
        }
        let err = n0_copy.handle(&wrong).unwrap_err();
        assert!(
            err.detail
                .contains("indicators of interfaces [1] from interface node 1, which owns [0]"),
            "{err}"
        );
        assert!(err.is_rejection(), "{err:?}");

        from0.extend(n0.handle(partials).unwrap());
        let decision = |out: &[Message]| {
            out.iter()
                .find_map(|m| match &m.payload {
                    Payload::Decision(d) => Some(d.clone()),
                    _ => None,
                })
                .expect("a decision")
        };
        assert_eq!(decision(&single), decision(&from0));
        assert_eq!(decision(&single).verdict, Verdict::Continue);
        let err = n0.handle(partials).unwrap_err();
        assert!(
            err.detail
                .contains("indicators of iteration 0 from interface node 1 while at iteration 1"),
            "{err}"
        );
        // Node 1 sends its q̂ rows once it has the decision; with node 0's they make the one-node q̂.
        let d = from0
            .iter()
            .find(|m| matches!(m.payload, Payload::Decision(_)))
            .unwrap();
        from1 = n1.handle(d).unwrap();
        let q_of = |out: &[Message], s: u32| -> Vec<(Vec<u32>, Field)> {
            out.iter()
                .filter_map(|m| match &m.payload {
                    Payload::LocalDirections {
                        subdomain,
                        interfaces,
                        q_hat,
                    } if *subdomain == s => Some((interfaces.clone(), q_hat.clone())),
                    _ => None,
                })
                .collect()
        };
        // Subdomain 1 has interface 0 (side b) then interface 1 (side a).
        let [(all, q)] = &q_of(&single, 1)[..] else { panic!() };
        assert_eq!(all, &[0, 1]);
        let [(i0, q0)] = &q_of(&from1, 1)[..] else { panic!() };
        let [(i1, q1)] = &q_of(&from0, 1)[..] else { panic!() };
        assert_eq!((i0, i1), (&vec![0], &vec![1]));
        assert_eq!(q0.rows() + q1.rows(), q.rows());
        let mut joined = Vec::new();
        for c in 0..q.cols() {
            joined.extend((0..q0.rows()).map(|r| q0.get(r, c)));
            joined.extend((0..q1.rows()).map(|r| q1.get(r, c)));
        }
        assert_eq!(joined, q.data, "the pieces are the one-node q̂, bit for bit");
    }

    #[test]
    fn final_solutions_follow_the_decision_one_at_a_time_in_the_same_buffers() {
        // One iteration allowed: the first decision is a stop.
        let (model, ctx) = in_a_row(3);
        let mut capped = (*model).clone();
        capped.solver.max_iterations = 1;
        let model = Arc::new(capped);
        let k0 = vec![1000.0; model.interfaces.len()];
        let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
        let mut out = Vec::new();
        for m in states(&model, &ctx, &k0) {
            out.extend(node.handle(&m).unwrap());
        }
        let [decision] = &out[..] else {
            panic!("the stop's reply is its decision alone: {out:?}")
        };
        assert!(matches!(&decision.payload, Payload::Decision(d) if d.verdict.is_stop()));
        assert!(node.is_finished());
        // Solution p: of interface p, at the final stage, s and ŝ as the node holds them, bit
        // for bit; returns its fields' buffers.
        let check = |node: &InterfaceNode, m: &Message, p: usize| -> Vec<*const f64> {
            let Payload::InterfaceSolution(sol) = &m.payload else {
                panic!("an interface solution: {m:?}")
            };
            assert_eq!((sol.interface, m.envelope.stage), (p as u32, Stage::Final));
            let (s, h) = (&node.fields[p], &node.locals[p].hat);
            let expected =
                [&s.w_a, &s.w_b, &s.f_a, &s.f_b, &h.w_a, &h.w_b, &h.f_a, &h.f_b].map(|m| field_of(m.as_ref()));
            let got = [
                &sol.w_a,
                &sol.w_b,
                &sol.f_a,
                &sol.f_b,
                &sol.w_a_hat,
                &sol.w_b_hat,
                &sol.f_a_hat,
                &sol.f_b_hat,
            ];
            assert!(got.iter().zip(&expected).all(|(g, e)| *g == e), "interface {p}");
            let mut buffers: Vec<_> = got.iter().map(|f| f.data.as_ptr()).collect();
            buffers.sort();
            buffers
        };
        let first = node.next_output().expect("interface 0's solution");
        let buffers = check(&node, &first, 0);
        node.recycle(first);
        // Once given back, its buffers hold the next solution.
        let second = node.next_output().expect("interface 1's solution");
        assert_eq!(
            check(&node, &second, 1),
            buffers,
            "interface 1's fields reuse interface 0's buffers"
        );
        assert!(node.next_output().is_none(), "two interfaces, two solutions");
    }

    #[test]
    fn nan_stops_the_run_and_names_where() {
        let (model, ctx) = in_a_row(2);
        let k0 = vec![1000.0; model.interfaces.len()];
        let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
        let n_b = BoundaryLayout::new(&model, 1, &k0).len();
        let mut w = Field::zeros(n_b, 3);
        w.data[n_b + 3] = f64::NAN;
        let msg = Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: "r".into(),
                scene_fingerprint: ctx.scene_fingerprint,
                iteration: 0,
                stage: Stage::Linear,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: 1,
                },
            },
            payload: Payload::BoundaryState {
                subdomain: 1,
                w,
                f: Field::zeros(n_b, 3),
            },
        };
        let out = node.handle(&msg).unwrap();
        let Payload::Decision(d) = &out[0].payload else {
            panic!("expected a decision")
        };
        let Verdict::Diverged { detail } = &d.verdict else {
            panic!("{:?}", d.verdict)
        };
        assert!(detail.contains("subdomain 1 (`b.2`) sent W = NaN"), "{detail}");
        assert!(
            detail.contains("pair 1") && detail.contains("component y") && detail.contains("t_1 = 0.5"),
            "{detail}"
        );
        assert!(node.is_finished());
    }

    /// A PGD subdomain's state in mode form gives the local stage what the same state as full
    /// fields gives it, bit for bit; a mode form without its particular part, a second particular
    /// part or modes past those held are refused and change nothing.
    #[test]
    fn mode_form_states_give_the_full_fields() {
        let (model, ctx) = in_a_row(3);
        let k0 = vec![1000.0; model.interfaces.len()];
        let full = states(&model, &ctx, &k0);
        let sender = |s: u32| NodeId {
            role: Role::Subdomain,
            index: s,
        };
        // Each state as W = P_W φ + Z λ, F = P_F φ + G λ with one load case and two modes whose
        // expansion the full-field node gets.
        let (mut by_modes, mut by_fields) = (Vec::new(), Vec::new());
        for s in 0..3u32 {
            let n_b = BoundaryLayout::new(&model, s as usize, &k0).len();
            let v = |n: usize, k: usize| {
                (0..n)
                    .map(|i| ((i * 7 + k * 3 + s as usize) % 13) as f64 - 6.0)
                    .collect::<Vec<f64>>()
            };
            let (pw, pf, phi) = (v(n_b, 1), v(n_b, 2), v(3, 3));
            let (z, g, lambda) = (v(2 * n_b, 4), v(2 * n_b, 5), v(2 * 3, 6));
            let mut form = ModeForm::new(n_b, 3, 1, &pw, &pf, &phi).unwrap();
            form.update(0, &z, &g, &lambda).unwrap();
            let (mut w, mut f) = (Mat::zeros(n_b, 3), Mat::zeros(n_b, 3));
            form.expand_into(w.as_mut(), f.as_mut());
            by_fields.push(message(
                &ctx,
                sender(s),
                0,
                Payload::BoundaryState {
                    subdomain: s,
                    w: field_of(w.as_ref()),
                    f: field_of(f.as_ref()),
                },
            ));
            let col = |data: Vec<f64>, rows: usize| Field {
                rows: rows as u32,
                cols: (data.len() / rows) as u32,
                data: data.into(),
            };
            by_modes.push(message(
                &ctx,
                sender(s),
                0,
                Payload::BoundaryModes {
                    subdomain: s,
                    particular: Some(glissade_messages::ParticularModes {
                        w: col(pw, n_b),
                        f: col(pf, n_b),
                        time: col(phi, 1),
                    }),
                    first_mode: 0,
                    z: col(z, n_b),
                    g: col(g, n_b),
                    lambda: col(lambda, 2),
                },
            ));
        }
        assert_eq!(full.len(), 3);
        let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
        // Refused, nothing changes: no particular part yet, modes past those held.
        let mut orphan = by_modes[0].clone();
        if let Payload::BoundaryModes { particular, .. } = &mut orphan.payload {
            *particular = None;
        }
        let e = node.handle(&orphan).unwrap_err();
        assert!(e.to_string().contains("before its particular part"), "{e}");
        let mut gap = by_modes[0].clone();
        if let Payload::BoundaryModes { first_mode, lambda, .. } = &mut gap.payload {
            *first_mode = 1;
            *lambda = Field::zeros(3, 3);
        }
        let e = node.handle(&gap).unwrap_err();
        assert!(
            e.to_string()
                .contains("modes from column 1 on, but only 0 modes are held"),
            "{e}"
        );
        let mut from_modes = Vec::new();
        for m in &by_modes {
            from_modes.extend(node.handle(m).unwrap());
        }
        let mut reference = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
        let mut from_fields = Vec::new();
        for m in &by_fields {
            from_fields.extend(reference.handle(m).unwrap());
        }
        assert!(!from_fields.is_empty());
        assert_eq!(from_modes, from_fields, "the same local stage, bit for bit");
    }
}
