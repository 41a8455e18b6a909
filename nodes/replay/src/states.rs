//! Full boundary fields from a run's messages: a `BoundaryState` of the whole boundary as it was
//! sent, the rows a subdomain sent to several interface nodes put together, a PGD subdomain's
//! `BoundaryModes` expanded from the mode form its earlier messages built ([`ModeForm`], the
//! same expansion the interface node makes).

use faer::Mat;
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::model::Model;
use glissade_mechanics::modes::ModeForm;
use glissade_messages::{Field, Message, Payload};
use std::borrow::Cow;
use std::collections::BTreeMap;

/// The boundary layouts of a model's subdomains, the mode forms of the PGD subdomains seen so
/// far, and the states of subdomains whose rows came in part.
pub struct BoundaryStates {
    /// Per subdomain, its slots: (interface, first row, rows).
    slots: Vec<Vec<(u32, usize, usize)>>,
    forms: BTreeMap<u32, ModeForm>,
    /// Per subdomain whose state is coming in parts: its iteration, W, F and which of its slots
    /// arrived.
    parts: BTreeMap<u32, Partial>,
    /// (subdomain, iteration) of the states whose parts did not all come: a part of a later
    /// iteration arrived first (a recording that left messages out).
    incomplete: Vec<(u32, u32)>,
}

struct Partial {
    iteration: u32,
    w: Field,
    f: Field,
    seen: Vec<bool>,
}

/// A subdomain's boundary state: (subdomain, W, F), each n_b × (N+1).
pub type State<'a> = (u32, Cow<'a, Field>, Cow<'a, Field>);

impl BoundaryStates {
    /// For the states of a run of `model`.
    pub fn new(model: &Model) -> Self {
        let k = vec![1.0; model.interfaces.len()];
        let slots = (0..model.subdomains.len())
            .map(|s| {
                BoundaryLayout::new(model, s, &k)
                    .slots
                    .iter()
                    .map(|sl| (sl.interface as u32, sl.offset, 2 * sl.n_pairs))
                    .collect()
            })
            .collect();
        Self {
            slots,
            forms: BTreeMap::new(),
            parts: BTreeMap::new(),
            incomplete: Vec::new(),
        }
    }

    /// (subdomain, iteration) of the states left out because some of their parts never came.
    pub fn incomplete(&self) -> &[(u32, u32)] {
        &self.incomplete
    }

    /// The subdomain and full (W, F) of a boundary-state message, None for other payloads and
    /// for a part of a state whose other parts are still to come, or why a message cannot be
    /// taken (a part that does not fit the subdomain's boundary, a mode-form message without a
    /// particular part before it or with sizes that do not fit the held modes). Messages must
    /// come in the order the subdomain sent them.
    pub fn fields<'a>(&mut self, msg: &'a Message) -> Option<Result<State<'a>, String>> {
        let iteration = msg.envelope.iteration;
        match &msg.payload {
            Payload::BoundaryState {
                subdomain,
                to: None,
                w,
                f,
                ..
            } => Some(Ok((*subdomain, Cow::Borrowed(w), Cow::Borrowed(f)))),
            Payload::BoundaryState {
                subdomain,
                interfaces,
                w,
                f,
                ..
            } => self.part(*subdomain, iteration, interfaces, w, f).transpose(),
            Payload::BoundaryModes {
                subdomain,
                particular,
                first_mode,
                z,
                g,
                lambda,
            } => Some(self.expand(*subdomain, particular.as_ref(), *first_mode as usize, z, g, lambda)),
            _ => None,
        }
    }

    /// Puts the rows of `interfaces` into subdomain `s`'s state; the state once every slot came.
    fn part<'a>(
        &mut self,
        s: u32,
        iteration: u32,
        interfaces: &[u32],
        w: &Field,
        f: &Field,
    ) -> Result<Option<State<'a>>, String> {
        let at = |e: String| format!("boundary state of subdomain {s}: {e}");
        let slots = self
            .slots
            .get(s as usize)
            .ok_or_else(|| at("no such subdomain".into()))?;
        let n_b: usize = slots.iter().map(|&(_, _, n)| n).sum();
        let nt = w.cols();
        let mut picked = Vec::with_capacity(interfaces.len());
        for &i in interfaces {
            let k = slots
                .iter()
                .position(|&(j, _, _)| j == i)
                .ok_or_else(|| at(format!("interface {i} is not on its boundary")))?;
            picked.push(k);
        }
        let rows: usize = picked.iter().map(|&k| slots[k].2).sum();
        if (w.rows(), f.rows(), f.cols()) != (rows, rows, nt) {
            return Err(at(format!(
                "W of {} × {nt} and F of {} × {} for interfaces {interfaces:?}, of {rows} rows",
                w.rows(),
                f.rows(),
                f.cols()
            )));
        }
        // A held state of another iteration never got all its parts: it is left out, and said.
        if self.parts.get(&s).is_some_and(|p| p.iteration != iteration) {
            let stale = self.parts.remove(&s).expect("checked just above");
            self.incomplete.push((s, stale.iteration));
        }
        let Partial {
            w: full_w,
            f: full_f,
            seen,
            ..
        } = self.parts.entry(s).or_insert_with(|| Partial {
            iteration,
            w: Field::zeros(n_b, nt),
            f: Field::zeros(n_b, nt),
            seen: vec![false; slots.len()],
        });
        if full_w.cols() != nt {
            return Err(at(format!("parts of {} and {nt} time points", full_w.cols())));
        }
        let (to_w, to_f) = (full_w.data.vec_mut(), full_f.data.vec_mut());
        let mut r0 = 0;
        for &k in &picked {
            let (_, offset, n) = slots[k];
            for c in 0..nt {
                let (from, to) = (c * rows + r0, c * n_b + offset);
                to_w[to..to + n].copy_from_slice(&w.data[from..from + n]);
                to_f[to..to + n].copy_from_slice(&f.data[from..from + n]);
            }
            seen[k] = true;
            r0 += n;
        }
        if !seen.iter().all(|&b| b) {
            return Ok(None);
        }
        let done = self.parts.remove(&s).expect("held just above");
        Ok(Some((s, Cow::Owned(done.w), Cow::Owned(done.f))))
    }

    fn expand<'a>(
        &mut self,
        s: u32,
        particular: Option<&glissade_messages::ParticularModes>,
        first: usize,
        z: &Field,
        g: &Field,
        lambda: &Field,
    ) -> Result<State<'a>, String> {
        let at = |e: String| format!("boundary modes of subdomain {s}: {e}");
        if let Some(pm) = particular {
            let form = ModeForm::new(
                pm.w.rows(),
                pm.time.cols(),
                pm.time.rows(),
                &pm.w.data,
                &pm.f.data,
                &pm.time.data,
            )
            .map_err(|e| at(e.to_string()))?;
            self.forms.insert(s, form);
        }
        let form = self
            .forms
            .get_mut(&s)
            .ok_or_else(|| at("mode form before its particular part".into()))?;
        if z.rows() != form.n_boundary() || lambda.cols() != form.n_times() {
            return Err(at(format!(
                "modes of {} entries and time functions of {} time points, expected {} and {}",
                z.rows(),
                lambda.cols(),
                form.n_boundary(),
                form.n_times()
            )));
        }
        form.update(first, &z.data, &g.data, &lambda.data)
            .map_err(|e| at(e.to_string()))?;
        let (n_b, nt) = (form.n_boundary(), form.n_times());
        let (mut w, mut f) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
        form.expand_into(w.as_mut(), f.as_mut());
        let field = |m: &Mat<f64>| Field::from_fn(n_b, nt, |r, c| m[(r, c)]);
        Ok((s, Cow::Owned(field(&w)), Cow::Owned(field(&f))))
    }
}

/// The final solutions as every output shows them: one value per physical point where copies of
/// a node pair sit on several contact interfaces
/// ([`glissade_mechanics::points::one_value_per_point`]). The run's messages (and its recording)
/// keep each copy's own share; the launcher's result, fields.json, the CSV, the VTU files and
/// Rerun show the point's.
pub fn one_value_per_point(model: &Model, solutions: &mut [glissade_messages::InterfaceSolution]) {
    use glissade_mechanics::points::FinalColumns;
    let mut fields: Vec<Option<FinalColumns<'_>>> = (0..model.interfaces.len()).map(|_| None).collect();
    for s in solutions.iter_mut() {
        let Some(slot) = fields.get_mut(s.interface as usize) else {
            continue;
        };
        let values = [
            &mut s.w_a,
            &mut s.w_b,
            &mut s.f_a,
            &mut s.f_b,
            &mut s.w_a_hat,
            &mut s.w_b_hat,
            &mut s.f_a_hat,
            &mut s.f_b_hat,
        ]
        .map(|f| &mut *f.data);
        *slot = Some(FinalColumns {
            values,
            status: &mut s.status,
        });
    }
    glissade_mechanics::points::one_value_per_point(&model.interfaces, &mut fields);
}

/// The final solutions as every output reports them: one value per physical point
/// ([`one_value_per_point`]), then the statuses the run reports ([`settle_statuses`]) in place
/// of the local stage's own.
pub fn as_reported(model: &Model, solutions: &mut [glissade_messages::InterfaceSolution]) {
    one_value_per_point(model, solutions);
    settle_statuses(model, solutions, model.time.n_points());
}

/// On each contact interface of solutions over `nt` time points, the status decided from ŝ (the
/// last local stage's fields, which obey the interface laws exactly, so that only the margins
/// decide, not how far s is from them) with the margins of the scene's accuracy
/// ([`glissade_mechanics::settled`]: separated, stick, slip, or within a margin: limit, grazing);
/// copies of one physical point (`glissade_mechanics::points::contact_points`) all get the status
/// of its first copy (their values are the point's already; the status does not depend on which
/// side a copy calls a). A solution whose shape does not fit the scene is left as it is (the
/// outputs name it).
pub fn settle_statuses(model: &Model, solutions: &mut [glissade_messages::InterfaceSolution], nt: usize) {
    use glissade_mechanics::settled::{in_frame, largest_traction, settle_interface, Margins, PairValues};
    let fits = |s: &glissade_messages::InterfaceSolution| {
        model.interfaces.get(s.interface as usize).is_some_and(|itf| {
            let rows = 2 * itf.n_pairs();
            [&s.w_a_hat, &s.w_b_hat, &s.f_a_hat]
                .iter()
                .all(|f| f.rows() == rows && f.cols() == nt)
        })
    };
    let mut by_interface: Vec<Option<usize>> = vec![None; model.interfaces.len()];
    for (j, s) in solutions.iter().enumerate() {
        if fits(s) {
            by_interface[s.interface as usize] = Some(j);
        }
    }
    let values = |sol: &glissade_messages::InterfaceSolution,
                  itf: &glissade_mechanics::model::Interface,
                  i: usize,
                  p: usize|
     -> PairValues {
        in_frame(itf, p, |r| {
            [sol.w_a_hat.get(r, i), sol.w_b_hat.get(r, i), sol.f_a_hat.get(r, i)]
        })
    };
    let t_max = largest_traction(&model.interfaces, nt, |k, i, p| {
        by_interface[k].map_or([0.0; 4], |j| values(&solutions[j], &model.interfaces[k], i, p))
    });
    let margins = Margins::new(model, Margins::accuracy_of(model), t_max);
    for (k, itf) in model.interfaces.iter().enumerate() {
        let Some(j) = by_interface[k].filter(|_| itf.is_contact()) else {
            continue;
        };
        let codes = settle_interface(itf, &margins, k, nt, |i, p| values(&solutions[j], itf, i, p));
        solutions[j].status = codes;
    }
    // One status per physical point: its first copy's.
    for point in glissade_mechanics::points::contact_points(&model.interfaces) {
        let Some((first, rest)) = point.copies.split_first() else {
            continue;
        };
        let Some(j0) = by_interface[first.interface] else {
            continue;
        };
        for c in rest {
            let Some(j) = by_interface[c.interface] else {
                continue;
            };
            let (np0, np) = (
                model.interfaces[first.interface].n_pairs(),
                model.interfaces[c.interface].n_pairs(),
            );
            for i in 0..nt {
                solutions[j].status[c.pair + np * i] = solutions[j0].status[first.pair + np0 * i];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_messages::{Envelope, NodeId, Role, Stage, SCHEMA_VERSION};

    fn part(s: u32, iteration: u32, to: u32, interfaces: Vec<u32>, rows: usize, value: f64) -> Message {
        Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: "r".into(),
                scene_fingerprint: 1,
                iteration,
                stage: Stage::Linear,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: s,
                },
            },
            payload: Payload::BoundaryState {
                subdomain: s,
                to: Some(to),
                interfaces,
                w: Field::from_fn(rows, 2, |_, _| value),
                f: Field::from_fn(rows, 2, |_, _| -value),
            },
        }
    }

    /// The parts of a state are put together at their slots' rows; a state whose parts did not
    /// all come before a part of a later iteration is left out and named, never mixed with the
    /// later one.
    #[test]
    fn parts_make_a_state_and_a_missing_part_is_named() {
        let text = include_str!("../../../launch/scenes/small-three-layer.toml");
        let model = glissade_scene::load_str(text, "small.toml").unwrap().model;
        let k = vec![1.0; model.interfaces.len()];
        // A subdomain with two interfaces or more.
        let (s, layout) = (0..model.subdomains.len())
            .map(|s| (s as u32, BoundaryLayout::new(&model, s, &k)))
            .find(|(_, l)| l.slots.len() >= 2)
            .expect("a subdomain with two interfaces");
        let (first, rest) = layout.slots.split_first().unwrap();
        let rest_rows: usize = rest.iter().map(|sl| 2 * sl.n_pairs).sum();
        let rest_ifs: Vec<u32> = rest.iter().map(|sl| sl.interface as u32).collect();
        let a = |it, v| part(s, it, 0, vec![first.interface as u32], 2 * first.n_pairs, v);
        let b = |it, v| part(s, it, 1, rest_ifs.clone(), rest_rows, v);
        let mut states = BoundaryStates::new(&model);
        // Iteration 1 loses its second part.
        assert!(states.fields(&a(1, 1.0)).is_none());
        // Iteration 2 whole, second part first.
        let (b2, a2) = (b(2, 2.0), a(2, 3.0));
        assert!(states.fields(&b2).is_none());
        assert_eq!(states.incomplete(), &[(s, 1)]);
        let a2_state = states.fields(&a2).expect("complete").expect("fits");
        let (got, w, f) = a2_state;
        assert_eq!(got, s);
        assert_eq!((w.rows(), w.cols()), (layout.len(), 2));
        for c in 0..2 {
            for r in 0..layout.len() {
                let want = if r >= first.offset && r < first.offset + 2 * first.n_pairs {
                    3.0
                } else {
                    2.0
                };
                assert_eq!(w.data[c * layout.len() + r], want, "row {r}");
                assert_eq!(f.data[c * layout.len() + r], -want, "row {r}");
            }
        }
        // A part naming an interface off the boundary is refused, naming it.
        let e = states.fields(&part(s, 3, 0, vec![999], 2, 0.0)).unwrap().unwrap_err();
        assert!(e.contains("interface 999 is not on its boundary"), "{e}");
    }

    /// Copies of one physical point report one status: the first copy's, whatever their own
    /// fields would decide. Small three-layer scene, a point shared by two contact interfaces;
    /// every pair pressed (f_n = −100 MPa, f_t = 0) and still, except the second copy, moved
    /// tangentially by 1 mm at the last time point (its own decision: slip).
    #[test]
    fn copies_of_one_point_report_the_first_copys_status() {
        use glissade_mechanics::settled::Settled;
        let text = include_str!("../../../launch/scenes/small-three-layer.toml");
        let model = glissade_scene::load_str(text, "small.toml").unwrap().model;
        let nt = model.time.n_points();
        let point = glissade_mechanics::points::contact_points(&model.interfaces)
            .into_iter()
            .find(|p| p.copies.len() >= 2)
            .expect("a point on two contact interfaces");
        let moved = point.copies[1];
        let mut solutions: Vec<glissade_messages::InterfaceSolution> = model
            .interfaces
            .iter()
            .enumerate()
            .map(|(k, itf)| {
                let rows = 2 * itf.n_pairs();
                let zero = Field::from_fn(rows, nt, |_, _| 0.0);
                // Pressed along each pair's normal: F on side a is −100 n.
                let pressed = Field::from_fn(rows, nt, |r, _| -100.0 * itf.normal(r / 2)[r % 2]);
                let w_b = Field::from_fn(rows, nt, |r, i| {
                    let p = r / 2;
                    if k == moved.interface && p == moved.pair && i == nt - 1 {
                        itf.tangent(p)[r % 2]
                    } else {
                        0.0
                    }
                });
                glissade_messages::InterfaceSolution {
                    interface: k as u32,
                    w_a: zero.clone(),
                    w_b: w_b.clone(),
                    f_a: pressed.clone(),
                    f_b: zero.clone(),
                    w_a_hat: zero.clone(),
                    w_b_hat: w_b,
                    f_a_hat: pressed,
                    f_b_hat: zero,
                    status: Vec::new(),
                }
            })
            .collect();
        settle_statuses(&model, &mut solutions, nt);
        let status = |k: usize, p: usize, i: usize| solutions[k].status[p + model.interfaces[k].n_pairs() * i];
        let first = point.copies[0];
        assert_eq!(status(first.interface, first.pair, nt - 1), Settled::Stick as u8);
        assert_eq!(status(moved.interface, moved.pair, nt - 1), Settled::Stick as u8);
        // Every other pair is pressed and still: stick, at every time point.
        assert!(solutions
            .iter()
            .all(|s| s.status.iter().all(|&c| c == Settled::Stick as u8)));
    }
}
