//! What a message carries: the [`Payload`]s of docs/architecture.md and their structs ([`Decision`],
//! [`Verdict`], [`InterfaceIndicators`], [`ParticularModes`], [`InterfaceSolution`],
//! [`LinearStageStats`], and a stall's [`NodeStatus`] and [`StallReport`]), the checks of their sizes after decoding, and the [`Message`]
//! (envelope + payload).

use crate::{DecodeBuffers, DecodeError, Envelope, Field, NodeId, Overrides, Role};
use serde::{Deserialize, Serialize};

/// How a run ended, or that it goes on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub enum Verdict {
    Continue,
    /// The estimated contact-traction errors (relative L2, and the largest at one point) reached
    /// the requested accuracy, s and ŝ agree within it (and η, e_c met their tolerances where the
    /// scene sets them).
    Converged,
    MaxIterations,
    /// η stopped decreasing.
    Stagnated {
        detail: String,
    },
    /// η grew without bound or a value became NaN/Inf; the detail names where.
    Diverged {
        detail: String,
    },
    /// The loads exceed what friction and the supports hold at some time points: a contact
    /// interface slips as a whole there and its slip grows by steady steps (no fixed point); the
    /// detail names the interfaces, the parts and the first such time point.
    NoEquilibrium {
        detail: String,
    },
}

impl Verdict {
    pub fn is_stop(&self) -> bool {
        !matches!(self, Verdict::Continue)
    }
}

/// Indicators of one iteration and the stop decision (interface node → everyone).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct Decision {
    /// LATIN indicator η (eq. 10).
    pub eta: f64,
    /// Contact indicator e_c = max(e_F, e_W) (independent of k).
    pub contact_indicator: f64,
    pub force_error: f64,
    pub jump_error: f64,
    /// Contact points (pair × time) separated, stuck, slipping.
    pub counts: [u64; 3],
    pub status_changes: u64,
    /// Contact interfaces whose search direction was updated at this iteration.
    pub direction_updates: Vec<u32>,
    /// Relative step of the contact forces since the previous iteration, ‖Fₙ − Fₙ₋₁‖/‖Fₙ‖.
    pub force_step: f64,
    /// Estimated relative error of the contact tractions and the contraction it was estimated
    /// with (`glissade_mechanics::estimate`); none until the iteration shows a contraction.
    pub estimate: Option<f64>,
    pub contraction: Option<f64>,
    /// The largest step of a contact traction at one point and time point since the previous
    /// iteration, relative to the largest contact traction.
    pub pointwise_step: f64,
    /// Estimated largest error of a contact traction at one point and time point, relative to
    /// the largest contact traction (the same estimate made on the pointwise steps).
    pub pointwise_estimate: Option<f64>,
    pub verdict: Verdict,
}

/// One interface's indicator sums after a local stage (the terms of η, e_F, e_W and the contact
/// counts, docs/method.md, "Indicators") and whether its search direction was updated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct InterfaceIndicators {
    pub interface: u32,
    pub eta_num: f64,
    pub eta_den: f64,
    pub force_num: f64,
    pub force_den: f64,
    pub jump_num: f64,
    pub jump_den: f64,
    pub counts: [u64; 3],
    pub status_changes: u64,
    pub direction_updated: bool,
    /// Σ w_i ‖Fₙ − Fₙ₋₁‖²_M and Σ w_i ‖Fₙ‖²_M over both sides (contact interfaces).
    pub step_num: f64,
    pub step_den: f64,
    /// max |Fₙ − Fₙ₋₁| and max |Fₙ| over the pairs, time points, components and sides of the same
    /// interfaces (tractions, MPa).
    pub step_max: f64,
    pub force_max: f64,
    /// The first time point beyond what friction holds, when the interface slides (it slips as
    /// a whole while the forces of a side whose part no support holds stay beyond the friction
    /// cone: no equilibrium there).
    pub sliding_from: Option<u32>,
    /// The sides (a, b) whose forces showed it: their parts would slide or turn away.
    pub sliding_sides: [bool; 2],
}

/// The particular part s₀ = (W_d, −k⁻W_d) of a subdomain's state in separated form: the boundary
/// responses to its load cases and their time functions, W_d = `w` φ, −k⁻W_d = `f` φ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[bincode(decode_context = "DecodeBuffers")]
pub struct ParticularModes {
    /// n_b × n_c each.
    pub w: Field,
    pub f: Field,
    /// φ, n_c × (N+1).
    pub time: Field,
}

/// One interface's fields at the end of a run: s (last linear stage) and ŝ (last local stage),
/// and the contact status per (pair, time) at index p + n_pairs·i (0 separated, 1 stick, 2 slip).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[bincode(decode_context = "DecodeBuffers")]
pub struct InterfaceSolution {
    pub interface: u32,
    pub w_a: Field,
    pub w_b: Field,
    pub f_a: Field,
    pub f_b: Field,
    pub w_a_hat: Field,
    pub w_b_hat: Field,
    pub f_a_hat: Field,
    pub f_b_hat: Field,
    pub status: Vec<u8>,
}

/// What one subdomain's linear stage of one iteration did, counted by the subdomain itself (the
/// iteration is the envelope's): its kernels' floating-point operations and, with the PGD stage,
/// its basis and criteria. Counters only, no time: the message is as deterministic as the
/// numbers it describes (a bus times a node's handling of its inputs, not the node).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct LinearStageStats {
    pub subdomain: u32,
    /// Floating-point operations of the stage (micro 1, macro forces, micro 2; with PGD the
    /// compression, update, enrichment, expansion and the relaxation or mixing in coordinates),
    /// as the kernels count them (`SubdomainSolver::flops`, `PgdStage::flops`).
    pub flops: u64,
    /// PGD basis size after the stage, frozen macro modes included (0 without PGD).
    pub modes: u32,
    /// Modes added in this stage (micro 1 + micro 2) and dropped by its compression.
    pub new_modes: u32,
    pub dropped_modes: u32,
    /// ξ at the end of micro 1 and micro 2 (0 without PGD, or for a micro problem not solved).
    pub xi1: f64,
    pub xi2: f64,
}

/// A message a node waits for: its sender, its kind (the field chunk of its key), its iteration
/// and the destination chunk of its key (None: the key has none). [`crate::topic::awaited`] is
/// its key.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct Awaited {
    pub from: NodeId,
    pub field: String,
    pub iteration: u32,
    pub to: Option<u32>,
}

/// A message as a node's status names it: its key, its iteration, and how long before the status
/// (ms) it was handled or put on the bus.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct MessageSeen {
    pub key: String,
    pub iteration: u32,
    pub ms_ago: u64,
}

/// What a node is doing, sent when the launcher asks (a run that stopped moving): what it waits
/// for, whether its process is busy, what it last handled and what it last put on each key.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct NodeStatus {
    /// The launcher's request this answers.
    pub round: u64,
    pub finished: bool,
    /// The messages the node waits for (any one of them moves it on); empty when it waits for
    /// none (finished, or between its outputs).
    pub awaits: Vec<Awaited>,
    /// The node's process is handling messages, since this many ms (None: it waits).
    pub busy_ms: Option<u64>,
    /// Messages the node's process has handled so far.
    pub handled: u64,
    pub last_handled: Option<MessageSeen>,
    /// The node's last message on each key it published on.
    pub sent: Vec<MessageSeen>,
}

/// A message a stalled run lacks: the node that waits for it, the message, and whether its
/// sender says it put it on the bus (then it was lost on the way).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct Missing {
    pub waiter: NodeId,
    pub awaited: Awaited,
    pub sent: bool,
}

/// The launcher's diagnosis of a run that stopped moving: how long nothing moved, what was
/// missing, the messages it asked their senders to publish again, and whether it ended the run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct StallReport {
    pub silent_ms: u64,
    pub missing: Vec<Missing>,
    /// Keys of the messages asked again.
    pub republished: Vec<String>,
    pub ended: bool,
    /// The diagnosis in words: who waits for what from whom, and what that sender last did.
    pub diagnosis: String,
}

/// The payloads of docs/architecture.md.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[bincode(decode_context = "DecodeBuffers")]
pub enum Payload {
    /// The scene file's text as written, so that remote nodes need no file, and the command-line
    /// settings applied to it: the text and the overrides together build the run's model.
    Scene {
        text: String,
        overrides: Overrides,
    },
    /// L_E of a subdomain over its macro slots (interface, number of modes), sent once.
    HomogenizedOperator {
        subdomain: u32,
        slots: Vec<(u32, u32)>,
        l_e: Field,
    },
    /// F̂ᴹ_{E,d} = 𝔼ᵀ M F₁ (n_m × (N+1)) after micro problem 1.
    MacroForces {
        subdomain: u32,
        forces: Field,
    },
    /// w̃ over the subdomain's macro columns (n_m × (N+1)).
    MacroDisplacements {
        subdomain: u32,
        w_tilde: Field,
    },
    /// s = (W, F) of a subdomain's boundary after a linear stage: the rows of `interfaces`, one
    /// after the other (2 × pairs rows each, in the subdomain's boundary layout), × (N+1).
    BoundaryState {
        subdomain: u32,
        /// The interface node these rows are for, when the run has several (each owner of one
        /// of the subdomain's interfaces then gets the rows of those; the key ends with its
        /// index). None: the whole boundary, for the run's one interface node.
        to: Option<u32>,
        interfaces: Vec<u32>,
        w: Field,
        f: Field,
    },
    /// s = (W, F) of a subdomain's boundary after a linear stage, in PGD mode form (docs/pgd.md, "Messages in mode form"):
    /// W = P_W φ + Σ_k Z_k λ_k, F = P_F φ + Σ_k G_k λ_k. The receiver keeps the particular part
    /// (in the subdomain's first message only) and the basis: it keeps its first `first_mode`
    /// modes and replaces the rest by the columns of `z` and `g` (n_b × new: new modes, or the
    /// free modes a compression rotated). `lambda` is the state's time functions, p × (N+1) with
    /// p = `first_mode` + new.
    BoundaryModes {
        subdomain: u32,
        particular: Option<ParticularModes>,
        first_mode: u32,
        z: Field,
        g: Field,
        lambda: Field,
    },
    /// q̂ = F̂ + k⁻Ŵ on a subdomain's boundary: all the linear stage needs from the local stage.
    /// One interface node sends the rows of the interfaces it owns: `interfaces` in the order of
    /// the subdomain's boundary layout, `q_hat` their rows one after the other. The subdomain
    /// starts its linear stage once every interface of its boundary is covered.
    LocalDirections {
        subdomain: u32,
        interfaces: Vec<u32>,
        q_hat: Field,
    },
    /// A subdomain's share of the Anderson least-squares problem after its linear stage (docs/method.md,
    /// "Relaxation and Anderson mixing"), over its k stored residual differences Δr_i (oldest first), forces only:
    /// `gram` Δr_iᵀΔr_j (k × k), `projection` Δr_iᵀ r (k × 1), `residual2` ‖r‖².
    AndersonGram {
        subdomain: u32,
        gram: Field,
        projection: Field,
        residual2: f64,
    },
    /// The mixing step every subdomain takes (summed Gram matrix solved by the interface node):
    /// coefficients γ (oldest difference first), or empty for a plain relaxation step; `restart`
    /// tells the subdomains to forget their differences.
    AndersonStep {
        gamma: Vec<f64>,
        restart: bool,
    },
    Decision(Decision),
    InterfaceSolution(InterfaceSolution),
    /// Full displacement field of a subdomain (n_dofs × (N+1)), on request at the end.
    Displacement {
        subdomain: u32,
        u: Field,
    },
    /// An interface node's share of an iteration's indicators, sent to the deciding interface
    /// node (index 0) when the run has several: one entry per interface it owns, in interface
    /// order, or the reason the iteration diverged (a non-finite value received).
    IndicatorPartials {
        interfaces: Vec<InterfaceIndicators>,
        diverged: Option<String>,
    },
    /// A subdomain's counters of its linear stage, once per iteration after its state: recorded
    /// for whoever needs them (a report, a replay), taken by no node.
    LinearStageStats(LinearStageStats),
    /// A node's status, asked by the launcher when the run stops moving; taken by no node.
    NodeStatus(NodeStatus),
    /// The launcher's diagnosis of a run that stopped moving; taken by no node.
    Stall(StallReport),
}

/// The fields of a payload (`$p`), in wire order, each passed to `$visit` as `&` or `&mut`.
macro_rules! for_each_field {
    ($p:expr, $visit:ident, $($r:tt)+) => {{
        let mut $visit = $visit;
        match $p {
            Payload::Scene { .. }
            | Payload::AndersonStep { .. }
            | Payload::Decision(_)
            | Payload::IndicatorPartials { .. }
            | Payload::LinearStageStats(_)
            | Payload::NodeStatus(_)
            | Payload::Stall(_) => {}
            Payload::HomogenizedOperator { l_e, .. } => $visit(l_e),
            Payload::MacroForces { forces, .. } => $visit(forces),
            Payload::MacroDisplacements { w_tilde, .. } => $visit(w_tilde),
            Payload::BoundaryState { w, f, .. } => {
                $visit(w);
                $visit(f);
            }
            Payload::BoundaryModes {
                particular,
                z,
                g,
                lambda,
                ..
            } => {
                if let Some(p) = particular {
                    $visit($($r)+ p.w);
                    $visit($($r)+ p.f);
                    $visit($($r)+ p.time);
                }
                $visit(z);
                $visit(g);
                $visit(lambda);
            }
            Payload::LocalDirections { q_hat, .. } => $visit(q_hat),
            Payload::AndersonGram { gram, projection, .. } => {
                $visit(gram);
                $visit(projection);
            }
            Payload::InterfaceSolution(s) => {
                for f in [
                    $($r)+ s.w_a,
                    $($r)+ s.w_b,
                    $($r)+ s.f_a,
                    $($r)+ s.f_b,
                    $($r)+ s.w_a_hat,
                    $($r)+ s.w_b_hat,
                    $($r)+ s.f_a_hat,
                    $($r)+ s.f_b_hat,
                ] {
                    $visit(f);
                }
            }
            Payload::Displacement { u, .. } => $visit(u),
        }
    }};
}

impl Payload {
    /// The field chunk of the key expression.
    pub fn field_key(&self) -> &'static str {
        match self {
            Payload::Scene { .. } => "scene",
            Payload::HomogenizedOperator { .. } => "homogenized_operator",
            Payload::MacroForces { .. } => "macro_forces",
            Payload::MacroDisplacements { .. } => "macro_displacements",
            Payload::BoundaryState { .. } => "boundary_state",
            Payload::BoundaryModes { .. } => "boundary_modes",
            Payload::LocalDirections { .. } => "local_directions",
            Payload::AndersonGram { .. } => "anderson_gram",
            Payload::AndersonStep { .. } => "anderson_step",
            Payload::Decision(_) => "decision",
            Payload::InterfaceSolution(_) => "interface_solution",
            Payload::Displacement { .. } => "displacement",
            Payload::IndicatorPartials { .. } => "indicator_partials",
            Payload::LinearStageStats(_) => "linear_stage_stats",
            Payload::NodeStatus(_) => "status",
            Payload::Stall(_) => "stall",
        }
    }

    /// The roles that send this kind of payload: a message of another sender is not the run's
    /// (the launcher sends the scene and, after a time-coarse start, the first local directions).
    pub fn senders(&self) -> &'static [Role] {
        match self {
            Payload::Scene { .. } | Payload::Stall(_) => &[Role::Launcher],
            Payload::NodeStatus(_) => &[Role::Subdomain, Role::Interface, Role::Coarse],
            Payload::HomogenizedOperator { .. }
            | Payload::MacroForces { .. }
            | Payload::BoundaryState { .. }
            | Payload::BoundaryModes { .. }
            | Payload::AndersonGram { .. }
            | Payload::Displacement { .. }
            | Payload::LinearStageStats(_) => &[Role::Subdomain],
            Payload::MacroDisplacements { .. } => &[Role::Coarse],
            Payload::LocalDirections { .. } => &[Role::Interface, Role::Launcher],
            Payload::AndersonStep { .. }
            | Payload::Decision(_)
            | Payload::InterfaceSolution(_)
            | Payload::IndicatorPartials { .. } => &[Role::Interface],
        }
    }

    /// Hands the value buffer of every field of the payload to `keep`, e.g. back to its sender's
    /// pool once the message is delivered (other contents are dropped).
    pub fn into_buffers(mut self, mut keep: impl FnMut(Vec<f64>)) {
        // A lent block goes back to its lender when dropped, not to a pool.
        self.fields_mut(|f| {
            if let Some(v) = std::mem::take(&mut f.data).into_vec() {
                keep(v)
            }
        });
    }

    /// Calls `visit` on every field of the payload, in wire order.
    pub fn fields(&self, visit: impl FnMut(&Field)) {
        for_each_field!(self, visit, &);
    }

    /// Calls `visit` on every field of the payload, in wire order, to change it.
    pub fn fields_mut(&mut self, visit: impl FnMut(&mut Field)) {
        for_each_field!(self, visit, &mut);
    }

    /// The last chunk of a payload's key, for payloads with one recipient: the subdomain of
    /// `MacroDisplacements` and `LocalDirections`, the interface node of an addressed
    /// `BoundaryState`.
    pub fn destination(&self) -> Option<u32> {
        match self {
            Payload::MacroDisplacements { subdomain, .. } | Payload::LocalDirections { subdomain, .. } => {
                Some(*subdomain)
            }
            Payload::BoundaryState { to, .. } => *to,
            _ => None,
        }
    }

    pub(crate) fn check(&self) -> Result<(), DecodeError> {
        match self {
            Payload::Scene { .. } => Ok(()),
            Payload::HomogenizedOperator { l_e, .. } => l_e.check("l_e"),
            Payload::MacroForces { forces, .. } => forces.check("forces"),
            Payload::MacroDisplacements { w_tilde, .. } => w_tilde.check("w_tilde"),
            Payload::BoundaryState { w, f, .. } => {
                w.check("w")?;
                f.check("f")?;
                if (w.rows, w.cols) != (f.rows, f.cols) {
                    return Err(DecodeError::WrongSize {
                        field: "f (differs from w)".into(),
                        rows: f.rows,
                        cols: f.cols,
                        len: f.data.len(),
                    });
                }
                Ok(())
            }
            Payload::BoundaryModes {
                particular,
                first_mode,
                z,
                g,
                lambda,
                ..
            } => {
                z.check("z")?;
                g.check("g")?;
                lambda.check("lambda")?;
                if (g.rows, g.cols) != (z.rows, z.cols) {
                    return Err(DecodeError::WrongSize {
                        field: format!("g (z is {} × {})", z.rows, z.cols),
                        rows: g.rows,
                        cols: g.cols,
                        len: g.data.len(),
                    });
                }
                if lambda.rows as u64 != *first_mode as u64 + z.cols as u64 {
                    return Err(DecodeError::WrongSize {
                        field: format!("lambda (first mode {first_mode} + {} new modes)", z.cols),
                        rows: lambda.rows,
                        cols: lambda.cols,
                        len: lambda.data.len(),
                    });
                }
                if let Some(pm) = particular {
                    pm.w.check("particular.w")?;
                    pm.f.check("particular.f")?;
                    pm.time.check("particular.time")?;
                    if (pm.f.rows, pm.f.cols) != (pm.w.rows, pm.w.cols) || pm.time.rows != pm.w.cols {
                        return Err(DecodeError::WrongSize {
                            field: format!(
                                "particular part (w {} × {}, f {} × {})",
                                pm.w.rows, pm.w.cols, pm.f.rows, pm.f.cols
                            ),
                            rows: pm.time.rows,
                            cols: pm.time.cols,
                            len: pm.time.data.len(),
                        });
                    }
                }
                Ok(())
            }
            Payload::LocalDirections { q_hat, .. } => q_hat.check("q_hat"),
            Payload::IndicatorPartials { .. } => Ok(()),
            Payload::AndersonGram { gram, projection, .. } => {
                gram.check("gram")?;
                projection.check("projection")?;
                if gram.rows != gram.cols || (projection.rows, projection.cols) != (gram.rows, 1) {
                    return Err(DecodeError::WrongSize {
                        field: format!("projection (gram is {} × {})", gram.rows, gram.cols),
                        rows: projection.rows,
                        cols: projection.cols,
                        len: projection.data.len(),
                    });
                }
                Ok(())
            }
            Payload::AndersonStep { .. } => Ok(()),
            Payload::Decision(_) => Ok(()),
            Payload::InterfaceSolution(s) => {
                for (name, f) in [
                    ("w_a", &s.w_a),
                    ("w_b", &s.w_b),
                    ("f_a", &s.f_a),
                    ("f_b", &s.f_b),
                    ("w_a_hat", &s.w_a_hat),
                    ("w_b_hat", &s.w_b_hat),
                    ("f_a_hat", &s.f_a_hat),
                    ("f_b_hat", &s.f_b_hat),
                ] {
                    f.check(name)?;
                }
                Ok(())
            }
            Payload::Displacement { u, .. } => u.check("u"),
            // Counters of fixed width: nothing sized to check.
            Payload::LinearStageStats(_) => Ok(()),
            Payload::NodeStatus(_) | Payload::Stall(_) => Ok(()),
        }
    }
}

/// A message: envelope + payload.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub envelope: Envelope,
    pub payload: Payload,
}

impl Message {
    /// The key expression this message is published on.
    pub fn topic(&self) -> String {
        crate::topic(&self.envelope.run_id, self.envelope.sender, &self.payload)
    }

    /// Why this message, received or recorded on `key`, cannot be its sender's (None when it
    /// can): it belongs on another key, or its sender's role never sends its kind. Nodes, the
    /// recorder and replay leave such a message out.
    pub fn not_from_its_sender(&self, key: &str) -> Option<String> {
        let topic = self.topic();
        if topic != key {
            return Some(format!("its envelope and payload belong on {topic}"));
        }
        let role = self.envelope.sender.role;
        if !self.payload.senders().contains(&role) {
            return Some(format!(
                "a {} node does not send {}",
                role.key(),
                self.payload.field_key()
            ));
        }
        // A subdomain speaks for itself only.
        let own = match &self.payload {
            Payload::HomogenizedOperator { subdomain, .. }
            | Payload::MacroForces { subdomain, .. }
            | Payload::BoundaryState { subdomain, .. }
            | Payload::BoundaryModes { subdomain, .. }
            | Payload::AndersonGram { subdomain, .. }
            | Payload::Displacement { subdomain, .. }
            | Payload::LinearStageStats(LinearStageStats { subdomain, .. }) => Some(*subdomain),
            _ => None,
        };
        own.filter(|&s| s != self.envelope.sender.index).map(|s| {
            format!(
                "subdomain {}'s {} is about subdomain {s}",
                self.envelope.sender.index,
                self.payload.field_key()
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{expected, msg};
    use crate::{decode, encode};

    /// A message is its sender's on its own key only, and only of a kind its role sends.
    #[test]
    fn a_message_is_its_senders_on_its_key_only() {
        let m = msg();
        assert_eq!(m.not_from_its_sender(&m.topic()), None, "{:?}", m.envelope.sender);
        assert!(m
            .not_from_its_sender("glissade/r1/subdomain/3/boundary_state")
            .unwrap()
            .contains("belong on glissade/r1/subdomain/2/boundary_state"));
        let mut forged = m.clone();
        forged.envelope.sender.role = Role::Coarse;
        let why = forged.not_from_its_sender(&forged.topic()).unwrap();
        assert_eq!(why, "a coarse node does not send boundary_state");
        let mut other = m.clone();
        other.envelope.sender.index = 3;
        let why = other.not_from_its_sender(&other.topic()).unwrap();
        assert_eq!(why, "subdomain 3's boundary_state is about subdomain 2");
    }

    /// A subdomain's linear-stage counters: on its own key, from itself only, decoded as sent.
    #[test]
    fn linear_stage_stats_are_their_subdomains() {
        let mut m = msg();
        m.payload = Payload::LinearStageStats(LinearStageStats {
            subdomain: 2,
            flops: 123_456_789_012,
            modes: 7,
            new_modes: 2,
            dropped_modes: 1,
            xi1: 0.25,
            xi2: -0.0,
        });
        assert_eq!(m.topic(), "glissade/r1/subdomain/2/linear_stage_stats");
        assert!(crate::key_matches(&crate::topic::linear_stage_stats("r1"), &m.topic()));
        assert_eq!(m.not_from_its_sender(&m.topic()), None);
        let back = decode(&encode(&m), &expected()).unwrap();
        assert_eq!(back, m);
        let mut forged = m.clone();
        forged.envelope.sender.role = Role::Interface;
        let why = forged.not_from_its_sender(&forged.topic()).unwrap();
        assert_eq!(why, "a interface node does not send linear_stage_stats");
        let mut other = m.clone();
        other.envelope.sender.index = 5;
        let why = other.not_from_its_sender(&other.topic()).unwrap();
        assert_eq!(why, "subdomain 5's linear_stage_stats is about subdomain 2");
        let mut none = Vec::new();
        m.payload.into_buffers(|b| none.push(b));
        assert!(none.is_empty(), "no field");
    }

    #[test]
    fn into_buffers_hands_back_every_field() {
        let lengths = |p: Payload| {
            let mut v = Vec::new();
            p.into_buffers(|b| v.push(b.len()));
            v
        };
        assert_eq!(lengths(msg().payload), [6, 6]);
        let modes = Payload::BoundaryModes {
            subdomain: 2,
            particular: Some(ParticularModes {
                w: Field::zeros(3, 1),
                f: Field::zeros(3, 1),
                time: Field::zeros(1, 2),
            }),
            first_mode: 0,
            z: Field::zeros(3, 2),
            g: Field::zeros(3, 2),
            lambda: Field::zeros(2, 2),
        };
        assert_eq!(lengths(modes), [3, 3, 2, 6, 6, 4]);
        let directions = Payload::LocalDirections {
            subdomain: 0,
            interfaces: vec![1],
            q_hat: Field::zeros(4, 5),
        };
        assert_eq!(lengths(directions), [20]);
        assert!(lengths(Payload::Scene {
            text: "x".into(),
            overrides: Overrides::default()
        })
        .is_empty());
    }

    #[test]
    fn mode_form_sizes_are_checked() {
        let mut m = msg();
        let modes = |first_mode: u32, lambda_rows: usize, g_cols: usize| Payload::BoundaryModes {
            subdomain: 2,
            particular: Some(ParticularModes {
                w: Field::zeros(3, 1),
                f: Field::zeros(3, 1),
                time: Field::zeros(1, 2),
            }),
            first_mode,
            z: Field::zeros(3, 2),
            g: Field::zeros(3, g_cols),
            lambda: Field::zeros(lambda_rows, 2),
        };
        m.payload = modes(1, 3, 2);
        assert_eq!(decode(&encode(&m), &expected()).unwrap(), m);
        assert_eq!(m.topic(), "glissade/r1/subdomain/2/boundary_modes");
        m.payload = modes(1, 2, 2);
        let e = decode(&encode(&m), &expected()).unwrap_err();
        assert!(e.to_string().contains("lambda (first mode 1 + 2 new modes)"), "{e}");
        m.payload = modes(1, 3, 1);
        let e = decode(&encode(&m), &expected()).unwrap_err();
        assert!(e.to_string().contains("g (z is 3 × 2)"), "{e}");
        m.payload = modes(1, 3, 2);
        if let Payload::BoundaryModes {
            particular: Some(p), ..
        } = &mut m.payload
        {
            p.time = Field::zeros(2, 2);
        }
        let e = decode(&encode(&m), &expected()).unwrap_err();
        assert!(e.to_string().contains("particular part"), "{e}");
    }
}
