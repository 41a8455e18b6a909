//! A subdomain node's message handling: the [`Node`] implementation (subscriptions, start, one
//! message at a time) and the checks every input passes before it changes anything (origin,
//! stage, iteration, phase, recipient, shapes, finite values): a refused message leaves the node
//! as it was. What the inputs run is in `stage` (the linear stage) and `anderson`.

use crate::{Phase, SubdomainNode};
use glissade_bus::convert::{copy_into, field_of};
use glissade_bus::{expect_finite, expect_origin, expect_shape, Node, NodeError};
use glissade_messages::{role_field_topic, Awaited, Field, Message, NodeId, Payload, Role, Stage};

impl SubdomainNode {
    /// Time-coarse start (`solver.time_coarsening`) or given start (a study's warm start):
    /// iteration 0 waits for q̂ from the launcher instead of starting from ŝ = 0.
    fn time_start(&self) -> bool {
        self.model.solver.launcher_start()
    }

    /// Iteration 0 of a time-coarse or given start: q̂ over the whole boundary (every interface of the
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
        let layout = self.boundary_interfaces();
        if interfaces != layout.as_slice() {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "initial local directions over interfaces {interfaces:?}; this subdomain's boundary has {layout:?}"
                ),
            ));
        }
        let (rows, cols) = self.fields.q_hat.shape();
        expect_shape(self.id, "q_hat", q_hat, rows, cols)?;
        expect_finite(self.id, "q_hat", "launcher:0", q_hat)?;
        copy_into(q_hat, &mut self.fields.q_hat);
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
    pub(crate) fn out_of_turn(&self, what: &str, it: u32) -> NodeError {
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
        if self.fields.anderson.is_some() {
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
            self.fields.q_hat.fill(0.0);
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
                expect_shape(self.id, "q_hat", q_hat, rows, self.fields.q_hat.ncols())?;
                expect_finite(self.id, "q_hat", &msg.envelope.sender.to_string(), q_hat)?;
                let mut r0 = 0;
                for &k in &at {
                    let (offset, n) = (slots[k].offset, 2 * slots[k].n_pairs);
                    if n > 0 {
                        for (j, column) in q_hat.data.chunks_exact(rows).enumerate() {
                            self.fields.q_hat.col_as_slice_mut(j)[offset..offset + n]
                                .copy_from_slice(&column[r0..r0 + n]);
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
                let (rows, cols) = self.fields.w_tilde.shape();
                expect_shape(self.id, "w_tilde", w_tilde, rows, cols)?;
                expect_finite(self.id, "w_tilde", "coarse:0", w_tilde)?;
                copy_into(w_tilde, &mut self.fields.w_tilde);
                Ok(self.micro2())
            }
            Payload::AndersonStep { gamma, restart } if self.fields.anderson.is_some() => {
                self.anderson_step(msg, gamma, *restart)
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

    fn awaits(&self) -> Vec<Awaited> {
        if self.finished {
            return Vec::new();
        }
        let me = Some(self.subdomain());
        let from = |role, index| NodeId { role, index };
        let one = |sender: NodeId, field: &str, iteration: u32, to: Option<u32>| Awaited {
            from: sender,
            field: field.to_string(),
            iteration,
            to,
        };
        match self.phase {
            Phase::Directions if !self.started => {
                vec![one(from(Role::Launcher, 0), "local_directions", 0, me)]
            }
            Phase::Directions => {
                // The local directions of every interface node whose share has not come, or the
                // decision to stop.
                let mut owners: Vec<u32> = (0..self.directions_in.len())
                    .filter(|&k| !self.directions_in[k])
                    .map(|k| self.owners.as_ref().map_or(0, |o| o[k]))
                    .collect();
                owners.sort_unstable();
                owners.dedup();
                let mut awaits: Vec<Awaited> = owners
                    .into_iter()
                    .map(|o| one(from(Role::Interface, o), "local_directions", self.iteration + 1, me))
                    .collect();
                if self.decided != Some(self.iteration) {
                    awaits.push(one(from(Role::Interface, 0), "decision", self.iteration, None));
                }
                awaits
            }
            Phase::Macro => vec![one(from(Role::Coarse, 0), "macro_displacements", self.iteration, me)],
            Phase::Step => vec![one(from(Role::Interface, 0), "anderson_step", self.iteration, None)],
        }
    }

    fn recycle(&mut self, msg: Message) {
        self.pool.recycle(msg);
    }

    fn lend_fields(&mut self, lender: std::sync::Arc<dyn glissade_messages::BlockLender>) {
        self.pool.lend_from(lender);
    }
}
