//! Anderson acceleration in a subdomain node (docs/method.md, "Relaxation and Anderson mixing"): the Gram partials of
//! the iteration's record sent to the interface node (`AndersonGram`), and the step it returns
//! (`AndersonStep`: mixed, plain or restart) taken on the fields, or with PGD on the coordinates,
//! before the state is sent.

use crate::{Phase, SubdomainNode};
use glissade_bus::{expect_origin, NodeError};
use glissade_mechanics::anderson::{AndersonStep, GramPartials};
use glissade_messages::{Field, Message, Payload, Role, Stage};

impl SubdomainNode {
    /// The Gram partials of this iteration's record; the node then waits for the step.
    pub(crate) fn anderson_gram(&mut self, p: GramPartials) -> Message {
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

    /// Takes the step of `msg` (coefficients `gamma`, or a plain step when empty; `restart`
    /// forgets the differences), checked in full first, and sends the state. With PGD the step
    /// is taken in coordinates (its flops go to the stage's counters).
    pub(crate) fn anderson_step(
        &mut self,
        msg: &Message,
        gamma: &[f64],
        restart: bool,
    ) -> Result<Vec<Message>, NodeError> {
        let it = msg.envelope.iteration;
        expect_origin(self.id, msg, Role::Interface, Some(0))?;
        if it != self.iteration || self.phase != Phase::Step {
            return Err(self.out_of_turn("Anderson step", it));
        }
        let history = self.fields.anderson.as_mut().expect("checked by the caller");
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
                AndersonStep::Mix(gamma.to_vec())
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
            let flops0 = pgd.flops();
            pgd.apply_coordinates(history, &step);
            self.stats.flops += pgd.flops() - flops0;
            return Ok(self.boundary_modes());
        }
        self.fields.take_step(&step);
        Ok(self.boundary_state())
    }
}
