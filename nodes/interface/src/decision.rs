//! The stop decision: each node's per-interface indicators, their sum in interface order on the
//! deciding node (node 0), the stop rule applied to it and the `Decision` the other nodes act on.

use crate::InterfaceNode;
use glissade_bus::{expect_origin, NodeError};
use glissade_mechanics::local::IndicatorSums;
use glissade_mechanics::sliding::Sliding;
use glissade_messages::{Decision, InterfaceIndicators, Message, Payload, Role, Stage, Verdict};
use std::collections::BTreeSet;

/// One interface's sums as they travel to the decider.
pub(crate) fn indicators_of(
    interface: usize,
    s: &IndicatorSums,
    direction_updated: bool,
    sliding: Option<Sliding>,
) -> InterfaceIndicators {
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
        step_num: s.step_num,
        step_den: s.step_den,
        step_max: s.step_max,
        force_max: s.force_max,
        sliding_from: sliding.map(|s| s.from as u32),
        sliding_sides: sliding.map_or([false; 2], |s| s.sides),
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
        step_num: i.step_num,
        step_den: i.step_den,
        step_max: i.step_max,
        force_max: i.force_max,
    }
}

impl InterfaceNode {
    /// Hands this node's share of the iteration to the decider: itself (node 0) or node 0 over
    /// the bus.
    pub(crate) fn report(&mut self, share: Vec<InterfaceIndicators>, diverged: Option<String>) -> Vec<Message> {
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
        let d = self
            .decider
            .as_mut()
            .expect("only the deciding node takes shares: report and indicator_partials check it");
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
        let d = self
            .decider
            .as_mut()
            .expect("only the deciding node takes shares: report and indicator_partials check it");
        let shares = std::mem::take(&mut d.shares);
        let (sums, updates, verdict) = match d.diverged.take() {
            Some(detail) => (IndicatorSums::default(), Vec::new(), Verdict::Diverged { detail }),
            None => {
                let mut all: Vec<&InterfaceIndicators> = shares.values().flatten().collect();
                all.sort_by_key(|i| i.interface);
                let mut sums = IndicatorSums::default();
                let mut updates = Vec::new();
                let mut sliding = Vec::new();
                for i in all {
                    sums.add(&sums_of(i));
                    if i.direction_updated {
                        updates.push(i.interface);
                    }
                    if let Some(t) = i.sliding_from {
                        let found = Sliding {
                            from: t as usize,
                            sides: i.sliding_sides,
                        };
                        sliding.push((i.interface as usize, found));
                    }
                }
                // The residual of the last step mixed: iteration n − 1's (its step came before s_n).
                let fixed_point = d.anderson.as_ref().and_then(|a| a.last_residual2()).map(f64::sqrt);
                let mut verdict = d.rule.decide(n, &sums, fixed_point);
                // Sliding interfaces: the loads have no equilibrium, the iteration no fixed point;
                // said as such instead of running on to a stagnation (a converged or diverged
                // verdict stands).
                if !sliding.is_empty() && !matches!(verdict, Verdict::Converged | Verdict::Diverged { .. }) {
                    verdict = Verdict::NoEquilibrium {
                        detail: glissade_mechanics::sliding::no_equilibrium(&self.model, &sliding),
                    };
                }
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
            force_step: sums.force_step(),
            estimate: d.rule.estimate().map(|e| e.error),
            contraction: d.rule.estimate().map(|e| e.rate),
            pointwise_step: sums.pointwise_step(),
            pointwise_estimate: d.rule.pointwise_estimate().map(|e| e.error),
            verdict,
        };
        let stop = decision.verdict.is_stop();
        let mut out = vec![self.msg(Stage::Local, n, Payload::Decision(decision))];
        out.extend(self.after_decision(stop));
        out
    }

    /// The decider takes another interface node's share of the current iteration.
    pub(crate) fn indicator_partials(
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
        let nt = self.model.time.n_points() as u32;
        // A slide names a time point of the scene, on a contact interface, shown by a side whose
        // part no support holds (the sides the watch reads).
        let slides_right = |i: &InterfaceIndicators| {
            let k = i.interface as usize;
            match i.sliding_from {
                None => i.sliding_sides == [false; 2],
                Some(t) => {
                    let free = glissade_mechanics::sliding::free_sides(&self.model, k);
                    t < nt
                        && self.model.interfaces[k].is_contact()
                        && i.sliding_sides != [false; 2]
                        && (0..2).all(|s| !i.sliding_sides[s] || free[s])
                }
            }
        };
        if let Some(bad) = share.iter().find(|i| !slides_right(i)) {
            return Err(NodeError::rejected(
                self.id,
                format!(
                    "indicators of interface {} from interface node {from} say it slides from time point {:?} as \
                     sides {:?} show: the scene has {nt} time points, the interface is {}, and only sides {:?} are of \
                     parts no support holds",
                    bad.interface,
                    bad.sliding_from,
                    bad.sliding_sides,
                    if self.model.interfaces[bad.interface as usize].is_contact() {
                        "a contact"
                    } else {
                        "not a contact"
                    },
                    glissade_mechanics::sliding::free_sides(&self.model, bad.interface as usize)
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
    pub(crate) fn decision(&mut self, msg: &Message, d: &Decision) -> Result<Vec<Message>, NodeError> {
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
