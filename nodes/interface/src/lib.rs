//! The interface node: receives s = (W, F) from every subdomain, runs the local stage on every
//! interface (DESIGN §3), computes the indicators, updates search directions when asked, decides
//! whether to continue, and sends each subdomain q̂ = F̂ + k⁻Ŵ for its next linear stage. At the
//! stop it publishes every interface's s and ŝ.
//!
//! With Anderson acceleration it also hosts the mixing's global step (DESIGN §3 "Acceleration"):
//! it sums the subdomains' `AndersonGram` partials in subdomain order (so the sum does not depend
//! on arrival order), solves the small least-squares problem and sends one `AndersonStep` to
//! every subdomain. A search-direction update changes the fixed-point map: the next step restarts
//! the histories.

use faer::Mat;
use glissade_bus::convert::field_of;
use glissade_bus::{expect_shape, Node, NodeError, RunContext};
use glissade_mechanics::anderson::{AndersonCoordinator, AndersonStep, GramPartials, MAX_CONDITION};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::local::{IndicatorSums, InterfaceFields, InterfaceLocal};
use glissade_mechanics::model::{Acceleration, Model, Side};
use glissade_messages::{
    role_field_topic, Decision, InterfaceSolution, Message, NodeId, Payload, Role, Stage, Verdict,
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

pub struct InterfaceNode {
    id: NodeId,
    ctx: RunContext,
    model: Arc<Model>,
    layouts: Vec<Option<BoundaryLayout>>,
    participants: Vec<u32>,
    locals: Vec<InterfaceLocal>,
    fields: Vec<InterfaceFields>,
    received: BTreeSet<u32>,
    iteration: u32,
    time_weights: Vec<f64>,
    rule: StopRule,
    /// Anderson mixing's global step (acceleration on), the partials of this iteration by
    /// subdomain, and whether search directions changed since the last step.
    anderson: Option<AndersonCoordinator>,
    grams: BTreeMap<u32, GramPartials>,
    directions_changed: bool,
    finished: bool,
}

impl InterfaceNode {
    /// An interface node owning every interface of `model`, with k⁻ = k₀ = `k0[i]`.
    pub fn new(ctx: RunContext, model: Arc<Model>, k0: &[f64]) -> Self {
        let nt = model.time.n_points();
        let model_acceleration = model.solver.acceleration;
        let layouts: Vec<Option<BoundaryLayout>> = (0..model.subdomains.len())
            .map(|s| {
                let l = BoundaryLayout::new(&model, s, k0);
                (!l.is_empty()).then_some(l)
            })
            .collect();
        let participants = layouts
            .iter()
            .enumerate()
            .filter(|(_, l)| l.is_some())
            .map(|(s, _)| s as u32)
            .collect();
        let locals = model
            .interfaces
            .iter()
            .enumerate()
            .map(|(i, itf)| InterfaceLocal::new(i, itf, k0[i], nt))
            .collect();
        let fields = model
            .interfaces
            .iter()
            .map(|itf| InterfaceFields::zeros(itf.n_pairs(), nt))
            .collect();
        Self {
            id: NodeId {
                role: Role::Interface,
                index: 0,
            },
            ctx,
            time_weights: model.time.trapezoid_weights(),
            rule: StopRule::new(&model.solver),
            model,
            layouts,
            participants,
            locals,
            fields,
            received: BTreeSet::new(),
            iteration: 0,
            anderson: match model_acceleration {
                Acceleration::None => None,
                Acceleration::Anderson { .. } => Some(AndersonCoordinator::new(MAX_CONDITION)),
            },
            grams: BTreeMap::new(),
            directions_changed: false,
            finished: false,
        }
    }

    /// Subdomains that take part in the iteration.
    pub fn participants(&self) -> &[u32] {
        &self.participants
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

    fn store(&mut self, s: u32, w: &glissade_messages::Field, f: &glissade_messages::Field) {
        let layout = self.layouts[s as usize].as_ref().expect("participant");
        for slot in &layout.slots {
            self.fields[slot.interface].set_side(slot.side, slot.offset, |r, c| w.get(r, c), |r, c| f.get(r, c));
        }
    }

    fn local_stage(&mut self) -> Vec<Message> {
        let n = self.iteration;
        // Interfaces are independent: run them in parallel, then combine in interface order so
        // the sums are the same whatever the thread count.
        let model = &self.model;
        let weights = &self.time_weights;
        let per_interface: Vec<(IndicatorSums, bool)> = self
            .locals
            .par_iter_mut()
            .zip(self.fields.par_iter())
            .zip(model.interfaces.par_iter())
            .map(|((local, fields), itf)| {
                local.local_stage(itf, fields);
                let sums = local.indicator_sums(itf, weights, fields, n == 0);
                let updated = model.solver.search_direction_update
                    && local.update_directions(itf, model.solver.alpha, model.solver.i0);
                (sums, updated)
            })
            .collect();
        let mut sums = IndicatorSums::default();
        let mut updates = Vec::new();
        for (i, (s, updated)) in per_interface.iter().enumerate() {
            sums.add(s);
            if *updated {
                updates.push(i as u32);
            }
        }
        let verdict = self.rule.decide(n, &sums);
        self.finish_iteration(sums, updates, verdict)
    }

    fn finish_iteration(&mut self, sums: IndicatorSums, updates: Vec<u32>, verdict: Verdict) -> Vec<Message> {
        let n = self.iteration;
        self.directions_changed |= !updates.is_empty();
        let stop = verdict.is_stop();
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
        let mut out = vec![self.msg(Stage::Local, n, Payload::Decision(decision))];
        if stop {
            self.finished = true;
            for (i, local) in self.locals.iter().enumerate() {
                let s = &self.fields[i];
                let h = &local.hat;
                out.push(self.msg(
                    Stage::Final,
                    n,
                    Payload::InterfaceSolution(InterfaceSolution {
                        interface: i as u32,
                        w_a: field_of(s.w_a.as_ref()),
                        w_b: field_of(s.w_b.as_ref()),
                        f_a: field_of(s.f_a.as_ref()),
                        f_b: field_of(s.f_b.as_ref()),
                        w_a_hat: field_of(h.w_a.as_ref()),
                        w_b_hat: field_of(h.w_b.as_ref()),
                        f_a_hat: field_of(h.f_a.as_ref()),
                        f_b_hat: field_of(h.f_b.as_ref()),
                        status: local.status.iter().map(|s| *s as u8).collect(),
                    }),
                ));
            }
        } else {
            let nt = self.model.time.n_points();
            for &s in &self.participants {
                let layout = self.layouts[s as usize].as_ref().expect("participant");
                let mut q = Mat::<f64>::zeros(layout.len(), nt);
                for slot in &layout.slots {
                    self.locals[slot.interface].q_hat_into(slot.side == Side::A, q.as_mut(), slot.offset);
                }
                out.push(self.msg(
                    Stage::Local,
                    n + 1,
                    Payload::LocalDirections {
                        subdomain: s,
                        q_hat: field_of(q.as_ref()),
                    },
                ));
            }
        }
        self.iteration += 1;
        self.received.clear();
        out
    }
}

impl InterfaceNode {
    /// Stores one subdomain's Anderson partials; with every participant's, sums them in subdomain
    /// order, decides the step and sends it.
    fn anderson_gram(
        &mut self,
        iteration: u32,
        s: u32,
        gram: &glissade_messages::Field,
        projection: &glissade_messages::Field,
        residual2: f64,
    ) -> Result<Vec<Message>, NodeError> {
        if self.anderson.is_none() {
            return Ok(Vec::new());
        }
        if !self.participants.contains(&s) {
            return Err(NodeError::new(
                self.id,
                format!("Anderson partials from subdomain {s}, which has no interface"),
            ));
        }
        if iteration != self.iteration {
            return Err(NodeError::new(
                self.id,
                format!(
                    "Anderson partials of iteration {iteration} from subdomain {s} while at iteration {}",
                    self.iteration
                ),
            ));
        }
        let k = gram.rows();
        expect_shape(self.id, "gram", gram, k, k)?;
        expect_shape(self.id, "projection", projection, k, 1)?;
        if let Some((other, p)) = self.grams.iter().next() {
            if p.k != k {
                return Err(NodeError::new(
                    self.id,
                    format!(
                        "Anderson partials of iteration {iteration}: subdomain {s} holds {k} differences, subdomain {other} {}",
                        p.k
                    ),
                ));
            }
        }
        let partials = GramPartials {
            k,
            gram: gram.data.clone(),
            projection: projection.data.clone(),
            residual2,
        };
        if self.grams.insert(s, partials).is_some() {
            return Err(NodeError::new(
                self.id,
                format!("second Anderson partials of iteration {iteration} from subdomain {s}"),
            ));
        }
        if self.grams.len() < self.participants.len() {
            return Ok(Vec::new());
        }
        let mut sum = GramPartials::zeros(k);
        for p in self.grams.values() {
            sum.add(p);
        }
        self.grams.clear();
        let changed = std::mem::take(&mut self.directions_changed);
        let step = self.anderson.as_mut().expect("checked").decide(&sum, changed);
        let (gamma, restart) = match step {
            AndersonStep::Mix(g) => (g, false),
            AndersonStep::Plain => (Vec::new(), false),
            AndersonStep::Restart => (Vec::new(), true),
        };
        Ok(vec![self.msg(
            Stage::Linear,
            self.iteration,
            Payload::AndersonStep { gamma, restart },
        )])
    }
}

impl Node for InterfaceNode {
    fn id(&self) -> NodeId {
        self.id
    }

    fn subscriptions(&self) -> Vec<String> {
        let mut subs = vec![role_field_topic(
            &self.ctx.run_id,
            Role::Subdomain,
            "boundary_state",
            None,
        )];
        if self.anderson.is_some() {
            subs.push(role_field_topic(
                &self.ctx.run_id,
                Role::Subdomain,
                "anderson_gram",
                None,
            ));
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
        if let Payload::AndersonGram {
            subdomain,
            gram,
            projection,
            residual2,
        } = &msg.payload
        {
            return self.anderson_gram(msg.envelope.iteration, *subdomain, gram, projection, *residual2);
        }
        let Payload::BoundaryState { subdomain, w, f } = &msg.payload else {
            return Ok(Vec::new());
        };
        let s = *subdomain;
        if !self.participants.contains(&s) {
            return Err(NodeError::new(
                self.id,
                format!("boundary state from subdomain {s}, which has no interface"),
            ));
        }
        if msg.envelope.iteration != self.iteration {
            return Err(NodeError::new(
                self.id,
                format!(
                    "boundary state of iteration {} from subdomain {s} while at iteration {}",
                    msg.envelope.iteration, self.iteration
                ),
            ));
        }
        if !self.received.insert(s) {
            return Err(NodeError::new(
                self.id,
                format!(
                    "second boundary state of iteration {} from subdomain {s}",
                    self.iteration
                ),
            ));
        }
        let n_b = self.layouts[s as usize].as_ref().expect("participant").len();
        let nt = self.model.time.n_points();
        expect_shape(self.id, "w", w, n_b, nt)?;
        expect_shape(self.id, "f", f, n_b, nt)?;
        for (name, field) in [("W", w), ("F", f)] {
            if let Some((r, c, v)) = field.first_non_finite() {
                let detail = format!(
                    "subdomain {} (`{}`) sent {name} = {v} at {}, time t_{c} = {} s, iteration {}",
                    s,
                    self.model.subdomains[s as usize].name,
                    self.locate(s as usize, r),
                    self.model.time.t(c),
                    self.iteration
                );
                return Ok(self.finish_iteration(IndicatorSums::default(), Vec::new(), Verdict::Diverged { detail }));
            }
        }
        self.store(s, w, f);
        if self.received.len() == self.participants.len() {
            return Ok(self.local_stage());
        }
        Ok(Vec::new())
    }

    fn is_finished(&self) -> bool {
        self.finished
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_mechanics::local::IndicatorSums;
    use glissade_mechanics::model::SolverParams;
    use glissade_mechanics::scene::load_str;
    use glissade_messages::{Envelope, Field, SCHEMA_VERSION};

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

    #[test]
    fn nan_stops_the_run_and_names_where() {
        let text = r#"
[time]
T = 1.0
N = 2
[materials.m]
E = 1000.0
nu = 0.3
[[block]]
name = "b"
material = "m"
x = [0.0, 2.0]
y = [0.0, 1.0]
nx = 2
ny = 1
split = [2, 1]
[[boundary]]
x = 0.0
ux = 0.0
uy = 0.0
"#;
        let sc = load_str(text, "nan.toml").unwrap();
        let model = Arc::new(sc.model);
        let ctx = RunContext {
            run_id: "r".into(),
            scene_fingerprint: sc.fingerprint,
        };
        let k0 = vec![1000.0; model.interfaces.len()];
        let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
        let n_b = BoundaryLayout::new(&model, 1, &k0).len();
        let mut w = Field::zeros(n_b, 3);
        w.data[n_b + 3] = f64::NAN;
        let msg = Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: "r".into(),
                scene_fingerprint: sc.fingerprint,
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
}
