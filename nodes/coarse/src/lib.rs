//! The coarse node: assembles Σ_E L_E once from the subdomains' homogenized operators and, each
//! iteration, solves the macro problem (Σ L_E) w̃ = −Σ F̂ᴹ_{E,d} (docs/method.md, "Macro problem") and sends
//! each subdomain its columns of w̃.

use faer::Mat;
use glissade_bus::convert::{copy_into, mat_of, FieldPool};
use glissade_bus::{expect_finite, expect_origin, expect_shape, Node, NodeError, RunContext};
use glissade_mechanics::coarse::{Contribution, MacroProblem};
use glissade_messages::{role_field_topic, Awaited, Message, NodeId, Payload, Role, Stage};
use std::collections::{BTreeMap, BTreeSet};

/// A subdomain's macro slots (interface, number of modes) and its L_E.
type MacroContribution = (Vec<(usize, usize)>, Mat<f64>);

pub struct CoarseNode {
    id: NodeId,
    ctx: RunContext,
    /// Macro modes per interface.
    n_modes: Vec<usize>,
    /// Subdomains that take part (those with at least one interface).
    subdomains: BTreeSet<u32>,
    n_times: usize,
    /// Per subdomain: its macro slots (interface, modes) and L_E.
    operators: BTreeMap<u32, MacroContribution>,
    problem: Option<MacroProblem>,
    columns: BTreeMap<u32, Vec<usize>>,
    /// Per subdomain, its last macro forces (allocated at its first), and the subdomains whose
    /// forces of the current iteration arrived.
    forces: BTreeMap<u32, Mat<f64>>,
    gathered: BTreeSet<u32>,
    /// The macro problem's right-hand side, then its solution (allocated with the problem).
    rhs: Mat<f64>,
    /// Iteration of the macro forces being gathered: the number of macro problems solved.
    iteration: u32,
    /// The last iteration whose decision arrived.
    decided: Option<u32>,
    finished: bool,
    /// Buffers of the fields this node sent, back from the bus ([`Node::recycle`]).
    pool: FieldPool,
}

impl CoarseNode {
    pub fn new(ctx: RunContext, n_modes: Vec<usize>, subdomains: Vec<u32>, n_times: usize) -> Self {
        Self {
            id: NodeId {
                role: Role::Coarse,
                index: 0,
            },
            ctx,
            n_modes,
            subdomains: subdomains.into_iter().collect(),
            n_times,
            operators: BTreeMap::new(),
            problem: None,
            columns: BTreeMap::new(),
            forces: BTreeMap::new(),
            gathered: BTreeSet::new(),
            rhs: Mat::new(),
            iteration: 0,
            decided: None,
            finished: false,
            pool: FieldPool::default(),
        }
    }

    /// Refuses a message of a subdomain that takes no part, or sent by another node than the
    /// subdomain it names, or at another stage than its payload's.
    fn expect_subdomain(&self, msg: &Message, what: &str, subdomain: u32) -> Result<(), NodeError> {
        if !self.subdomains.contains(&subdomain) {
            return Err(NodeError::rejected(
                self.id,
                format!("{what} from unknown subdomain {subdomain}"),
            ));
        }
        expect_origin(self.id, msg, Role::Subdomain, Some(subdomain))
    }

    fn assemble(&mut self) -> Result<(), NodeError> {
        let parts: Vec<Contribution<'_>> = self
            .operators
            .iter()
            .map(|(s, (slots, l))| Contribution {
                subdomain: *s as usize,
                interfaces: slots,
                l_e: l.as_ref(),
            })
            .collect();
        let problem = MacroProblem::new(&self.n_modes, &parts).map_err(|e| NodeError::new(self.id, e))?;
        for (s, (slots, _)) in &self.operators {
            self.columns.insert(*s, problem.columns_of(slots));
        }
        self.rhs = Mat::zeros(problem.n(), self.n_times);
        self.problem = Some(problem);
        Ok(())
    }

    fn solve(&mut self) -> Vec<Message> {
        let problem = self
            .problem
            .as_mut()
            .expect("both callers solve once assemble has set the problem");
        let rhs = &mut self.rhs;
        let columns = &self.columns;
        MacroProblem::rhs_into(
            rhs,
            self.forces.iter().map(|(s, f)| (columns[s].as_slice(), f.as_ref())),
        );
        problem.solve_in_place(rhs);
        let mut out = Vec::with_capacity(self.columns.len());
        for (s, cols) in &self.columns {
            let w_tilde = self.pool.field_with(cols.len(), self.n_times, |w| {
                MacroProblem::subdomain_part_into(rhs.as_ref(), cols, w)
            });
            out.push(Message {
                envelope: self.ctx.envelope(self.id, self.iteration, Stage::Macro),
                payload: Payload::MacroDisplacements { subdomain: *s, w_tilde },
            });
        }
        self.gathered.clear();
        self.iteration += 1;
        out
    }
}

impl Node for CoarseNode {
    fn id(&self) -> NodeId {
        self.id
    }

    fn subscriptions(&self) -> Vec<String> {
        let run = &self.ctx.run_id;
        vec![
            role_field_topic(run, Role::Subdomain, "homogenized_operator", None),
            role_field_topic(run, Role::Subdomain, "macro_forces", None),
            role_field_topic(run, Role::Interface, "decision", None),
        ]
    }

    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        Ok(Vec::new())
    }

    /// Every message is checked in full (origin, stage, iteration, shapes, finite values) before
    /// it changes anything: a refused message leaves the node as it was.
    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError> {
        if self.finished {
            return Ok(Vec::new());
        }
        let it = msg.envelope.iteration;
        match &msg.payload {
            Payload::HomogenizedOperator { subdomain, slots, l_e } => {
                self.expect_subdomain(msg, "homogenized operator", *subdomain)?;
                if it != 0 {
                    return Err(NodeError::rejected(
                        self.id,
                        format!(
                            "homogenized operator of iteration {it} from subdomain {subdomain}: it is sent at setup"
                        ),
                    ));
                }
                if self.operators.contains_key(subdomain) {
                    return Err(NodeError::rejected(
                        self.id,
                        format!("second homogenized operator from subdomain {subdomain}"),
                    ));
                }
                let slots: Vec<(usize, usize)> = slots.iter().map(|&(i, k)| (i as usize, k as usize)).collect();
                for (n, &(i, k)) in slots.iter().enumerate() {
                    if self.n_modes.get(i) != Some(&k) {
                        return Err(NodeError::rejected(
                            self.id,
                            format!("subdomain {subdomain} reports {k} macro modes on interface {i}"),
                        ));
                    }
                    if slots[..n].iter().any(|s| s.0 == i) {
                        return Err(NodeError::rejected(
                            self.id,
                            format!("subdomain {subdomain} reports interface {i} twice"),
                        ));
                    }
                }
                let n: usize = slots.iter().map(|s| s.1).sum();
                expect_shape(self.id, "l_e", l_e, n, n)?;
                expect_finite(self.id, "l_e", &format!("subdomain {subdomain}"), l_e)?;
                self.operators.insert(*subdomain, (slots, mat_of(l_e)));
                if self.operators.len() == self.subdomains.len() {
                    self.assemble()?;
                    if self.gathered.len() == self.subdomains.len() {
                        return Ok(self.solve());
                    }
                }
                Ok(Vec::new())
            }
            Payload::MacroForces { subdomain, forces } => {
                self.expect_subdomain(msg, "macro forces", *subdomain)?;
                if it != self.iteration {
                    return Err(NodeError::rejected(
                        self.id,
                        format!(
                            "macro forces of iteration {it} from subdomain {subdomain} while gathering iteration {}",
                            self.iteration
                        ),
                    ));
                }
                if self.gathered.contains(subdomain) {
                    return Err(NodeError::rejected(
                        self.id,
                        format!("second macro forces of iteration {it} from subdomain {subdomain}"),
                    ));
                }
                let n_m = self
                    .operators
                    .get(subdomain)
                    .map(|(slots, _)| slots.iter().map(|s| s.1).sum())
                    .ok_or_else(|| {
                        NodeError::rejected(
                            self.id,
                            format!("macro forces from subdomain {subdomain} before its homogenized operator"),
                        )
                    })?;
                expect_shape(self.id, "forces", forces, n_m, self.n_times)?;
                expect_finite(self.id, "forces", &format!("subdomain {subdomain}"), forces)?;
                let n_times = self.n_times;
                let stored = self
                    .forces
                    .entry(*subdomain)
                    .or_insert_with(|| Mat::zeros(n_m, n_times));
                copy_into(forces, stored);
                self.gathered.insert(*subdomain);
                if self.gathered.len() == self.subdomains.len() && self.problem.is_some() {
                    return Ok(self.solve());
                }
                Ok(Vec::new())
            }
            Payload::Decision(d) => {
                expect_origin(self.id, msg, Role::Interface, Some(0))?;
                // The decision of iteration n follows the macro problem of iteration n; a late
                // decision to go on is let pass.
                let current = it.checked_add(1) == Some(self.iteration);
                if it >= self.iteration || self.decided == Some(it) || (d.verdict.is_stop() && !current) {
                    return Err(NodeError::rejected(
                        self.id,
                        format!(
                            "{} decision of iteration {it} while gathering the macro forces of iteration {}",
                            if self.decided == Some(it) { "second" } else { "a" },
                            self.iteration
                        ),
                    ));
                }
                if !d.verdict.is_stop() {
                    if current {
                        self.decided = Some(it);
                    }
                    return Ok(Vec::new());
                }
                self.finished = true;
                Ok(Vec::new())
            }
            other => Err(NodeError::rejected(
                self.id,
                format!(
                    "the coarse node does not take {} messages (from {}, iteration {it})",
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
        let one = |role, index, field: &str, iteration| Awaited {
            from: NodeId { role, index },
            field: field.to_string(),
            iteration,
            to: None,
        };
        let mut awaits: Vec<Awaited> = self
            .subdomains
            .iter()
            .filter(|s| !self.operators.contains_key(s))
            .map(|&s| one(Role::Subdomain, s, "homogenized_operator", 0))
            .collect();
        awaits.extend(
            self.subdomains
                .iter()
                .filter(|s| !self.gathered.contains(s))
                .map(|&s| one(Role::Subdomain, s, "macro_forces", self.iteration)),
        );
        // Or the decision to stop after the last macro problem.
        if let Some(last) = self.iteration.checked_sub(1).filter(|&n| self.decided != Some(n)) {
            awaits.push(one(Role::Interface, 0, "decision", last));
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
