//! Building the node, the `Node` implementation (subscriptions and message handling), the
//! boundary states it stores (in full or in mode form) and the final solutions it publishes.

use crate::{Decider, InterfaceNode, ModeReceiver, StateRows, StopRule};
use faer::{Mat, MatRef};
use glissade_bus::convert::{view, FieldPool};
use glissade_bus::{expect_origin, expect_shape, Node, NodeError, RunContext};
use glissade_mechanics::anderson::{AndersonCoordinator, MAX_CONDITION};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::local::{force_step_sums, InterfaceFields, InterfaceLocal, StepSums};
use glissade_mechanics::model::{Acceleration, Model};
use glissade_mechanics::modes::ModeForm;
use glissade_messages::topic::sender_field_topic;
use glissade_messages::{role_field_topic, Awaited, InterfaceSolution, Message, NodeId, Payload, Role, Stage};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// First (row, column, value) of a matrix that is NaN or infinite.
fn first_non_finite(m: &Mat<f64>) -> Option<(usize, usize, f64)> {
    (0..m.ncols()).find_map(|c| {
        m.col_as_slice(c)
            .iter()
            .position(|v| !v.is_finite())
            .map(|r| (r, c, m[(r, c)]))
    })
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
        // With several interface nodes a subdomain sends each node owning one of its interfaces
        // the rows of those, addressed to it (the owner of an interface: the group that holds
        // it, as the subdomain reckons); with one, its whole state, unaddressed.
        let mode_senders = (0..layouts.len() as u32)
            .filter(|&s| layouts[s as usize].is_some())
            .collect();
        let state_rows = layouts
            .iter()
            .enumerate()
            .map(|(s, l)| {
                let l = l.as_ref()?;
                if !participants.contains(&(s as u32)) {
                    return None;
                }
                // The rule the subdomain cuts its state by ([`BoundaryLayout::parts`]).
                let part = (groups.len() > 1)
                    .then(|| l.parts(groups))
                    .flatten()
                    .and_then(|parts| parts.into_iter().find(|p| p.node == index as u32));
                Some(match part {
                    Some(part) => StateRows {
                        to: Some(index as u32),
                        interfaces: part.interfaces(l),
                        at: part.at,
                        rows: part.rows,
                    },
                    None => StateRows {
                        to: None,
                        interfaces: l.slots.iter().map(|sl| sl.interface as u32).collect(),
                        at: l.slots.iter().map(|sl| Some(sl.offset)).collect(),
                        rows: l.len(),
                    },
                })
            })
            .collect();
        let decider = (index == 0).then(|| Decider {
            rule: StopRule::new(&model.solver)
                .with_traction_scale(glissade_mechanics::scales::Scales::of(&model).traction()),
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
            .map(|&i| {
                let mut local = InterfaceLocal::new(i, &model.interfaces[i], k0[i], nt);
                local.watch_sides(glissade_mechanics::sliding::free_sides(&model, i));
                local
            })
            .collect();
        let fields = owned
            .iter()
            .map(|&i| InterfaceFields::zeros(model.interfaces[i].n_pairs(), nt))
            .collect();
        let n_subdomains = model.subdomains.len();
        let any_contact = model.interfaces.iter().any(|i| i.is_contact());
        let steps = owned
            .iter()
            .map(|&i| (model.interfaces[i].is_contact() || !any_contact).then(StepSums::default))
            .collect();
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
            mode_senders,
            participants,
            state_rows,
            locals,
            fields,
            steps,
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

    /// Only `subdomains` send their state in mode form (the PGD linear stage): this node listens
    /// for mode-form states from those of them on its interfaces only.
    pub fn with_mode_senders(mut self, subdomains: Vec<u32>) -> Self {
        self.mode_senders = subdomains;
        self
    }

    /// The rejection of a message this node does not take.
    pub(crate) fn not_taken(&self, msg: &Message) -> NodeError {
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

    pub(crate) fn msg(&self, stage: Stage, iteration: u32, payload: Payload) -> Message {
        Message {
            envelope: self.ctx.envelope(self.id, iteration, stage),
            payload,
        }
    }

    /// Names a boundary entry: interface, pair and component.
    fn locate(&self, s: usize, row: usize) -> String {
        let layout = self.layouts[s]
            .as_ref()
            .expect("handle refuses a subdomain without a boundary layout");
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
    /// The step of the forces since the previous iteration is summed on the way, on the
    /// interfaces the error estimate follows ([`force_step_sums`]).
    /// W and F span the subdomain's whole boundary (mode form, or a state for every node: as
    /// many rows as its layout) or hold the rows of [`StateRows`] (a node that owns all of a
    /// subdomain's interfaces gets the whole state: its rows are the layout's).
    fn store(&mut self, s: u32, w: MatRef<'_, f64>, f: MatRef<'_, f64>) {
        let layout = self.layouts[s as usize]
            .as_ref()
            .expect("handle refuses a subdomain without a boundary layout");
        let rows = self.state_rows[s as usize]
            .as_ref()
            .filter(|_| w.nrows() != layout.len());
        for (k, slot) in layout.slots.iter().enumerate() {
            if let Some(p) = self.position[slot.interface] {
                let at = rows.map_or(slot.offset, |r| r.at[k].expect("the rows of this node's interfaces"));
                let (to_w, to_f) = self.fields[p].side_mut(slot.side);
                let rows = to_w.nrows();
                let new_f = f.subrows(at, rows);
                let step = &mut self.steps[p];
                let pair_weights = &self.model.interfaces[slot.interface].weights;
                let time_weights = &self.time_weights;
                rayon::join(
                    || to_w.copy_from(w.subrows(at, rows)),
                    || {
                        if let Some(sums) = step {
                            sums.add(&force_step_sums(pair_weights, time_weights, to_f.as_ref(), new_f));
                        }
                        to_f.copy_from(new_f)
                    },
                );
            }
        }
    }

    /// The row of subdomain `s`'s boundary layout that row `r` of the rows it sends this node
    /// ([`StateRows`]) is.
    fn layout_row(&self, s: u32, r: usize) -> usize {
        let layout = self.layouts[s as usize].as_ref().expect("a participant has a layout");
        let rows = self.state_rows[s as usize]
            .as_ref()
            .expect("a participant has its state rows");
        layout
            .slots
            .iter()
            .enumerate()
            .filter(|(_, sl)| self.position[sl.interface].is_some())
            .find_map(|(k, sl)| {
                let at = rows.at[k]?;
                (r >= at && r < at + 2 * sl.n_pairs).then(|| sl.offset + r - at)
            })
            .unwrap_or(r)
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
        let n_b = self.layouts[s as usize]
            .as_ref()
            .expect("handle refuses a subdomain without a boundary layout")
            .len();
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
            (None, true) => self.modes[s as usize]
                .take()
                .expect("this arm is taken when a form is held"),
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
            .expect("`check` accepted these modes above");
        receiver.form.expand_into(receiver.w.as_mut(), receiver.f.as_mut());
        Ok(receiver)
    }
}

impl Node for InterfaceNode {
    fn id(&self) -> NodeId {
        self.id
    }

    fn subscriptions(&self) -> Vec<String> {
        let run = &self.ctx.run_id;
        let with_boundary = self.layouts.iter().filter(|l| l.is_some()).count();
        let all = self.participants.len() == with_boundary;
        let addressed = self.state_rows.iter().flatten().any(|r| r.to.is_some());
        let mut subs = vec![if addressed {
            // The states addressed to this node, from whichever subdomain sends one.
            role_field_topic(run, Role::Subdomain, "boundary_state", Some(self.id.index))
        } else {
            role_field_topic(run, Role::Subdomain, "boundary_state", None)
        }];
        // Mode-form states are not addressed: those of the subdomains on its interfaces only
        // (the others would cross the network to be dropped), or all when that is every one.
        let modes = self.participants.iter().filter(|s| self.mode_senders.contains(s));
        if all && self.mode_senders.len() == with_boundary {
            subs.push(role_field_topic(run, Role::Subdomain, "boundary_modes", None));
        } else {
            subs.extend(modes.map(|&s| {
                let sender = NodeId {
                    role: Role::Subdomain,
                    index: s,
                };
                sender_field_topic(run, sender, "boundary_modes")
            }));
        }
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
        let (s, state) = match &msg.payload {
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
            Payload::BoundaryState {
                subdomain,
                to,
                interfaces,
                w,
                f,
            } => (*subdomain, Some((to, interfaces, w, f))),
            Payload::BoundaryModes { subdomain, .. } => (*subdomain, None),
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
        if let Some((to, interfaces, w, f)) = state {
            let expected = self.state_rows[s as usize]
                .as_ref()
                .expect("a participant has its state rows");
            if *to != expected.to || *interfaces != expected.interfaces {
                let name =
                    |to: &Option<u32>| to.map_or("every interface node".to_string(), |k| format!("interface:{k}"));
                return Err(NodeError::rejected(
                    self.id,
                    format!(
                        "boundary state of subdomain {s} for {} over interfaces {interfaces:?}; this node takes the \
                         rows of {:?} for {}",
                        name(to),
                        expected.interfaces,
                        name(&expected.to)
                    ),
                ));
            }
            let rows = expected.rows;
            let nt = self.model.time.n_points();
            expect_shape(self.id, "w", w, rows, nt)?;
            expect_shape(self.id, "f", f, rows, nt)?;
            self.received.insert(s);
            // Both fields checked on two threads; W's non-finite value is named first.
            let (bad_w, bad_f) = rayon::join(|| w.first_non_finite(), || f.first_non_finite());
            for (name, bad) in [("W", bad_w), ("F", bad_f)] {
                if let Some((r, c, v)) = bad {
                    let r = self.layout_row(s, r);
                    let detail = self.non_finite_detail(s, name, (r, c, v));
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

    fn awaits(&self) -> Vec<Awaited> {
        if self.finished {
            return Vec::new();
        }
        let it = self.iteration;
        let one = |role, index, field: &str, to| Awaited {
            from: NodeId { role, index },
            field: field.to_string(),
            iteration: it,
            to,
        };
        let mut awaits = Vec::new();
        if !self.reported {
            // The Anderson partials (decider, from iteration 2 on, before the step), and the
            // states not yet in.
            if let Some(d) = self.decider.as_ref().filter(|d| d.anderson.is_some()) {
                if it >= 2 && d.stepped != Some(it) {
                    awaits.extend(
                        d.anderson_participants
                            .iter()
                            .filter(|s| !d.grams.contains_key(s))
                            .map(|&s| one(Role::Subdomain, s, "anderson_gram", None)),
                    );
                }
            }
            for &s in self.participants.iter().filter(|s| !self.received.contains(s)) {
                awaits.push(if self.mode_senders.contains(&s) {
                    one(Role::Subdomain, s, "boundary_modes", None)
                } else {
                    let to = self.state_rows[s as usize].as_ref().and_then(|r| r.to);
                    one(Role::Subdomain, s, "boundary_state", to)
                });
            }
        } else if let Some(d) = &self.decider {
            awaits.extend(
                (1..d.n_nodes)
                    .filter(|k| !d.shares.contains_key(k))
                    .map(|k| one(Role::Interface, k, "indicator_partials", None)),
            );
        } else {
            awaits.push(one(Role::Interface, 0, "decision", None));
        }
        awaits
    }

    fn recycle(&mut self, msg: Message) {
        self.pool.recycle(msg);
    }

    fn lend_fields(&mut self, lender: std::sync::Arc<dyn glissade_messages::BlockLender>) {
        self.pool.lend_from(lender);
    }
}
