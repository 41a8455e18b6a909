//! The initial search directions of a run that starts from a known ŝ instead of ŝ = 0
//! (docs/accuracy.md, "Time-coarse start"): a time-coarse start, whose coarse solve gives ŝ on
//! every c-th time point, or a study's given start (ŝ of a solved variant on the run's own grid:
//! docs/studies.md, "How variants are solved").

use crate::condensed::BoundaryLayout;
use crate::model::{Side, TimeGrid};
use faer::{Mat, MatRef};

/// q̂ = F̂ + k⁻Ŵ over one subdomain's boundary (`layout`) at the time points of `fine`, from ŝ
/// on `coarse`, whose points are every c-th point of `fine` (c = 1: the same grid), interpolated
/// linearly in time: the fine points between two coarse ones take the chord. `hat(k, side)` is
/// interface k's (Ŵ, F̂) of that side, 2·n_pairs × (coarse N + 1).
pub fn interpolated_directions<'a>(
    fine: &TimeGrid,
    coarse: &TimeGrid,
    layout: &BoundaryLayout,
    hat: impl Fn(usize, Side) -> (MatRef<'a, f64>, MatRef<'a, f64>),
) -> Mat<f64> {
    let nt = fine.n_points();
    let c = fine.n_steps / coarse.n_steps;
    let mut q = Mat::<f64>::zeros(layout.len(), nt);
    for slot in &layout.slots {
        let (w, f) = hat(slot.interface, slot.side);
        for i in 0..nt {
            // Fine point i lies between coarse points j and j + 1, at fraction a.
            let j = (i / c).min(coarse.n_steps - 1);
            let a = (i - j * c) as f64 / c as f64;
            for r in 0..2 * slot.n_pairs {
                let row = slot.offset + r;
                let at = |m: MatRef<'_, f64>| (1.0 - a) * m[(r, j)] + a * m[(r, j + 1)];
                q[(row, i)] = at(f) + layout.k[row] * at(w);
            }
        }
    }
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fields linear in time on the coarse grid are interpolated exactly at every fine point, and
    /// every slot takes its own side's fields with its own k. Small three-layer scene, N = 4
    /// coarsened by 2; on interface k, side a: Ŵ = k + r + t, F̂ = 10·(k + r) − t; side b the
    /// negatives (r the row, t the time).
    #[test]
    fn linear_fields_are_interpolated_exactly() {
        let model = crate::fixtures::small_three_layer();
        let fine = TimeGrid { t_end: 1.0, n_steps: 4 };
        let coarse = TimeGrid { t_end: 1.0, n_steps: 2 };
        let k0 = crate::linear::default_k0(&model);
        let s = (0..model.subdomains.len())
            .find(|&s| BoundaryLayout::new(&model, s, &k0).slots.len() >= 2)
            .expect("a subdomain with two interfaces");
        let layout = BoundaryLayout::new(&model, s, &k0);
        let value = |k: usize, side: Side, r: usize, t: f64, force: bool| {
            let sign = if side == Side::A { 1.0 } else { -1.0 };
            let (k, r) = (k as f64, r as f64);
            sign * if force { 10.0 * (k + r) - t } else { k + r + t }
        };
        let fields: Vec<[(Mat<f64>, Mat<f64>); 2]> = model
            .interfaces
            .iter()
            .enumerate()
            .map(|(k, itf)| {
                let rows = 2 * itf.n_pairs();
                [Side::A, Side::B].map(|side| {
                    let at = |force| Mat::from_fn(rows, 3, |r, j| value(k, side, r, coarse.t(j), force));
                    (at(false), at(true))
                })
            })
            .collect();
        let q = interpolated_directions(&fine, &coarse, &layout, |k, side| {
            let (w, f) = &fields[k][if side == Side::A { 0 } else { 1 }];
            (w.as_ref(), f.as_ref())
        });
        for slot in &layout.slots {
            for i in 0..fine.n_points() {
                for r in 0..2 * slot.n_pairs {
                    let row = slot.offset + r;
                    let t = fine.t(i);
                    let want = value(slot.interface, slot.side, r, t, true)
                        + layout.k[row] * value(slot.interface, slot.side, r, t, false);
                    assert!(
                        (q[(row, i)] - want).abs() <= 1e-9 * want.abs().max(1.0),
                        "row {row}, time point {i}"
                    );
                }
            }
        }
    }
}
