//! Anderson mixing's global step on the deciding node: the subdomains' partials summed in
//! subdomain order, the small least-squares problem solved and the step sent to every subdomain.

use crate::InterfaceNode;
use glissade_bus::{expect_origin, expect_shape, NodeError};
use glissade_mechanics::anderson::{AndersonStep, GramPartials};
use glissade_messages::{Message, Payload, Role, Stage};

impl InterfaceNode {
    /// Stores one subdomain's Anderson partials; with every participant's, sums them in subdomain
    /// order, decides the step and sends it.
    pub(crate) fn anderson_gram(
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
        let d = self
            .decider
            .as_mut()
            .expect("checked on entry: a decider with Anderson");
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
        d.stepped = Some(at);
        let changed = std::mem::take(&mut d.directions_changed);
        let step = d
            .anderson
            .as_mut()
            .expect("checked on entry: a decider with Anderson")
            .step(d.grams.values(), changed);
        d.grams.clear();
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
