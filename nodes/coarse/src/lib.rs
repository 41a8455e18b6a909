//! The coarse node: assembles Σ_E L_E once from the subdomains' homogenized operators and, each
//! iteration, solves the macro problem (Σ L_E) w̃ = −Σ F̂ᴹ_{E,d} (DESIGN §3, Problem 3) and sends
//! each subdomain its columns of w̃.

use faer::Mat;
use glissade_bus::convert::{field_of, mat_of};
use glissade_bus::{expect_shape, Node, NodeError, RunContext};
use glissade_mechanics::coarse::{Contribution, MacroProblem};
use glissade_messages::{role_field_topic, Message, NodeId, Payload, Role, Stage};
use std::collections::BTreeMap;

/// A subdomain's macro slots (interface, number of modes) and its L_E.
type MacroContribution = (Vec<(usize, usize)>, Mat<f64>);

pub struct CoarseNode {
    id: NodeId,
    ctx: RunContext,
    /// Macro modes per interface.
    n_modes: Vec<usize>,
    /// Subdomains that take part (those with at least one interface).
    subdomains: Vec<u32>,
    n_times: usize,
    /// Per subdomain: its macro slots (interface, modes) and L_E.
    operators: BTreeMap<u32, MacroContribution>,
    problem: Option<MacroProblem>,
    columns: BTreeMap<u32, Vec<usize>>,
    forces: BTreeMap<u32, Mat<f64>>,
    iteration: u32,
    finished: bool,
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
            subdomains,
            n_times,
            operators: BTreeMap::new(),
            problem: None,
            columns: BTreeMap::new(),
            forces: BTreeMap::new(),
            iteration: 0,
            finished: false,
        }
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
        self.problem = Some(problem);
        Ok(())
    }

    fn solve(&mut self) -> Vec<Message> {
        let problem = self.problem.as_ref().expect("assembled before the first solve");
        let mut rhs = Mat::<f64>::zeros(problem.n(), self.n_times);
        for (s, f) in &self.forces {
            for (r, &g) in self.columns[s].iter().enumerate() {
                for j in 0..self.n_times {
                    rhs[(g, j)] -= f[(r, j)];
                }
            }
        }
        problem.solve_in_place(&mut rhs);
        let mut out = Vec::with_capacity(self.columns.len());
        for (s, cols) in &self.columns {
            let w = Mat::from_fn(cols.len(), self.n_times, |r, j| rhs[(cols[r], j)]);
            out.push(Message {
                envelope: self.ctx.envelope(self.id, self.iteration, Stage::Macro),
                payload: Payload::MacroDisplacements {
                    subdomain: *s,
                    w_tilde: field_of(w.as_ref()),
                },
            });
        }
        self.forces.clear();
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

    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError> {
        if self.finished {
            return Ok(Vec::new());
        }
        match &msg.payload {
            Payload::HomogenizedOperator { subdomain, slots, l_e } => {
                if !self.subdomains.contains(subdomain) {
                    return Err(NodeError::new(
                        self.id,
                        format!("homogenized operator from unknown subdomain {subdomain}"),
                    ));
                }
                let slots: Vec<(usize, usize)> = slots.iter().map(|&(i, k)| (i as usize, k as usize)).collect();
                for &(i, k) in &slots {
                    if self.n_modes.get(i) != Some(&k) {
                        return Err(NodeError::new(
                            self.id,
                            format!("subdomain {subdomain} reports {k} macro modes on interface {i}"),
                        ));
                    }
                }
                let n: usize = slots.iter().map(|s| s.1).sum();
                expect_shape(self.id, "l_e", l_e, n, n)?;
                self.operators.insert(*subdomain, (slots, mat_of(l_e)));
                if self.operators.len() == self.subdomains.len() {
                    self.assemble()?;
                    if self.forces.len() == self.subdomains.len() {
                        return Ok(self.solve());
                    }
                }
                Ok(Vec::new())
            }
            Payload::MacroForces { subdomain, forces } => {
                if !self.subdomains.contains(subdomain) {
                    return Err(NodeError::new(
                        self.id,
                        format!("macro forces from unknown subdomain {subdomain}"),
                    ));
                }
                if self.forces.is_empty() {
                    self.iteration = msg.envelope.iteration;
                } else if msg.envelope.iteration != self.iteration {
                    return Err(NodeError::new(
                        self.id,
                        format!(
                            "macro forces of iteration {} mixed with iteration {}",
                            msg.envelope.iteration, self.iteration
                        ),
                    ));
                }
                let n_m = self
                    .operators
                    .get(subdomain)
                    .map(|(slots, _)| slots.iter().map(|s| s.1).sum())
                    .ok_or_else(|| {
                        NodeError::new(
                            self.id,
                            format!("macro forces from subdomain {subdomain} before its homogenized operator"),
                        )
                    })?;
                expect_shape(self.id, "forces", forces, n_m, self.n_times)?;
                self.forces.insert(*subdomain, mat_of(forces));
                if self.forces.len() == self.subdomains.len() && self.problem.is_some() {
                    return Ok(self.solve());
                }
                Ok(Vec::new())
            }
            Payload::Decision(d) if d.verdict.is_stop() => {
                self.finished = true;
                Ok(Vec::new())
            }
            _ => Ok(Vec::new()),
        }
    }

    fn is_finished(&self) -> bool {
        self.finished
    }
}
