//! Displacements of the subdomains recovered from boundary states (W, F), one sparse solve per
//! time point (the crate docs give the formula), and each subdomain's displacements at the end
//! of a run.

use glissade_mechanics::condensed::{BoundaryLayout, CondensedOperator};
use glissade_mechanics::linear::default_k0;
use glissade_mechanics::model::{Model, Side};
use glissade_messages::{Field, InterfaceSolution};
use std::collections::BTreeMap;

/// Displacement recovery of the subdomains (built on first use).
pub(crate) struct Recovery {
    k0: Vec<f64>,
    ops: BTreeMap<u32, CondensedOperator>,
}

impl Recovery {
    pub(crate) fn new(model: &Model) -> Self {
        Self {
            k0: default_k0(model),
            ops: BTreeMap::new(),
        }
    }

    /// u of subdomain `s` at time point `i` from its boundary state (W, F).
    pub(crate) fn displacement(
        &mut self,
        model: &Model,
        s: u32,
        w: &Field,
        f: &Field,
        i: usize,
    ) -> Result<Vec<f64>, String> {
        if !self.ops.contains_key(&s) {
            let sub = model
                .subdomains
                .get(s as usize)
                .ok_or_else(|| format!("boundary state of subdomain {s}, which the scene does not have"))?;
            let layout = BoundaryLayout::new(model, s as usize, &self.k0);
            let op = CondensedOperator::with_dense(sub, model.plane, layout, false)
                .map_err(|e| format!("subdomain `{}`: {e}", sub.name))?;
            self.ops.insert(s, op);
        }
        let op = &self.ops[&s];
        let n_b = op.layout.len();
        if w.rows() != n_b || f.rows() != n_b || w.cols() != model.time.n_points() {
            return Err(format!(
                "boundary state of subdomain {s} is {} × {}, the scene gives {n_b} × {}",
                w.rows(),
                w.cols(),
                model.time.n_points()
            ));
        }
        let q: Vec<f64> = (0..n_b).map(|b| f.get(b, i) + op.layout.k[b] * w.get(b, i)).collect();
        let t = model.time.t(i);
        let phi: Vec<f64> = model.subdomains[s as usize]
            .loads
            .iter()
            .map(|l| l.time.eval(t))
            .collect();
        Ok(op.recover(&q, &phi))
    }
}

/// The boundary state (W, F) of subdomain `s` assembled from the interface solutions (the s of
/// the last linear stage, side by side), when every interface of `s` has one.
fn state_from_interfaces(model: &Model, k0: &[f64], s: usize, sols: &[InterfaceSolution]) -> Option<(Field, Field)> {
    let layout = BoundaryLayout::new(model, s, k0);
    let nt = model.time.n_points();
    let n_b = layout.len();
    let (mut w, mut f) = (Field::zeros(n_b, nt), Field::zeros(n_b, nt));
    for slot in &layout.slots {
        let sol = sols.iter().find(|x| x.interface as usize == slot.interface)?;
        let (sw, sf) = match slot.side {
            Side::A => (&sol.w_a, &sol.f_a),
            Side::B => (&sol.w_b, &sol.f_b),
        };
        if sw.rows() != 2 * slot.n_pairs || sw.cols() != nt || sf.rows() != sw.rows() || sf.cols() != nt {
            return None;
        }
        for i in 0..nt {
            for r in 0..2 * slot.n_pairs {
                let k = i * n_b + slot.offset + r;
                w.data[k] = sw.get(r, i);
                f.data[k] = sf.get(r, i);
            }
        }
    }
    Some((w, f))
}

/// Each subdomain's displacement at every time point at the end of the run: recorded
/// (`--interior`), or recovered from its boundary state, taken from the interface solutions or
/// else from its last recorded boundary state.
pub(crate) fn final_displacements(
    model: &Model,
    recovery: &mut Recovery,
    interfaces: &[InterfaceSolution],
    displacements: &BTreeMap<u32, Field>,
    last_states: &BTreeMap<u32, (Field, Field)>,
) -> Result<BTreeMap<u32, Vec<Vec<f64>>>, String> {
    let nt = model.time.n_points();
    let mut out = BTreeMap::new();
    for s in 0..model.subdomains.len() as u32 {
        let n_dofs = model.subdomains[s as usize].n_dofs();
        let per_time: Vec<Vec<f64>> = if let Some(u) = displacements.get(&s) {
            if u.rows() != n_dofs || u.cols() != nt {
                return Err(format!(
                    "displacement of subdomain {s} is {} × {}, the scene gives {n_dofs} × {nt}",
                    u.rows(),
                    u.cols()
                ));
            }
            (0..nt).map(|i| (0..n_dofs).map(|r| u.get(r, i)).collect()).collect()
        } else {
            let in_iteration = model.interfaces.iter().any(|i| i.side_of(s as usize).is_some());
            let state = if in_iteration {
                state_from_interfaces(model, &recovery.k0, s as usize, interfaces)
            } else {
                None
            };
            let Some((w, f)) = state.as_ref().or(last_states.get(&s)) else {
                continue;
            };
            (0..nt)
                .map(|i| recovery.displacement(model, s, w, f, i))
                .collect::<Result<_, _>>()?
        };
        out.insert(s, per_time);
    }
    Ok(out)
}
