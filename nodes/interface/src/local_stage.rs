//! The local stage of the owned interfaces, with their search-direction update, and what follows
//! the decision: q̂ to every participant for the next linear stage, or the final solutions.

use crate::decision::indicators_of;
use crate::InterfaceNode;
use glissade_mechanics::model::Side;
use glissade_messages::{InterfaceIndicators, Message, Payload, Stage};
use rayon::prelude::*;

impl InterfaceNode {
    /// The local stage on the owned interfaces and their indicators, in interface order.
    pub(crate) fn local_stage(&mut self) -> Vec<Message> {
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
            .zip(self.steps.par_iter_mut())
            .map(|(((local, fields), &i), step)| {
                let itf = &model.interfaces[i];
                let (mut sums, updated) = local.local_iteration(itf, &model.solver, weights, fields, n == 0);
                // The step of the forces, summed as the subdomains' states arrived.
                if let Some(step) = step.as_mut().map(std::mem::take) {
                    (sums.step_num, sums.step_den) = (step.num, step.den);
                    (sums.step_max, sums.force_max) = (step.max_step, step.max_force);
                }
                indicators_of(i, &sums, updated, local.sliding)
            })
            .collect();
        self.report(share, None)
    }

    /// After the decision of the current iteration: the owned interfaces' s and ŝ at a stop,
    /// else q̂ to every participant for the next linear stage.
    pub(crate) fn after_decision(&mut self, stop: bool) -> Vec<Message> {
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
                    let layout = layouts[s as usize]
                        .as_ref()
                        .expect("every participant has a boundary layout");
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
}
