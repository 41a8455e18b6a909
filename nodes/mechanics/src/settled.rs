//! The status a run reports at each contact pair and time point, decided from the converged
//! fields with a margin tied to the accuracy asked (docs/accuracy.md, "Stick, slip or open").
//!
//! The local stage's own status (`laws::Status`) is exact for ŝ: a pair whose tangential force is
//! on the friction cone is "slip" even where its slip increment is 1e-17 mm, and one a hair inside
//! it is "stick". A run stopped at accuracy a determines the tractions only to about a times the
//! largest one (the pointwise estimate), so at a pair held at the cone without moving (a joint
//! at capacity under a constant load) the local stage's status changes from one time point and
//! one run to the next while the forces do not. The reported status says what the fields
//! determine, with margins
//! - m_T = [`MARGIN_FACTOR`] · a · T_max on tractions (T_max the largest contact traction of the
//!   run, over pairs and time points);
//! - m_W = m_T · L_Γ / E_Γ on displacement jumps (L_Γ the interface's length, E_Γ its modulus
//!   √(E_a' E_b') as in the default search direction k₀ = E_Γ/L_Γ): the jump that a traction
//!   error of m_T spread over the interface makes.
//!
//! The fields judged are ŝ's (the outputs' `as_reported`): they obey the laws exactly, so a pair
//! sticks there with no slip increment at all and slips with its traction on the cone; only the
//! margins decide, not how far s still is from ŝ.
//!
//! With N = −f_n the compressive normal traction, g = [W]·n + g₀ the gap and Δ the tangential
//! jump's increment over the time step (from 0 at t = 0):
//! - N ≤ m_T and g > m_W: **separated**; N ≤ m_T and g ≤ m_W: **grazing** (touching or not, with
//!   a force within the margin of zero: open or closed cannot be told apart);
//! - N > m_T, frictionless: **slip** (free to slide);
//! - N > m_T and |Δ| > m_W: **slip**; |Δ| ≤ m_W and |f_t| < f·N − m_T: **stick**; |Δ| ≤ m_W and
//!   |f_t| ≥ f·N − m_T: **limit** (on the friction cone within the margin and not moving beyond
//!   it: stick or slip cannot be told apart).

use crate::laws::dot;
use crate::local::InterfaceFields;
use crate::model::{Interface, InterfaceKind, Model};

/// Reported status of a pair at a time point (codes in the outputs: the discriminants).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Settled {
    Separated = 0,
    Stick = 1,
    Slip = 2,
    /// On the friction cone within the margin, not moving beyond it.
    Limit = 3,
    /// Gap and contact force both within the margin of zero.
    Grazing = 4,
}

/// The reported statuses' names, by code (what outputs and views call them).
pub const SETTLED_NAMES: [&str; 5] = ["separated", "stick", "slip", "limit", "grazing"];

/// m_T = MARGIN_FACTOR · accuracy · T_max. Fixed before the validation set was run, from the
/// stop's promise (the true traction error at a stop is at most 2× the accuracy); the
/// calibration part agrees with the reference at every factor from 0.5 to 4, the held-out part
/// at 2 (docs/accuracy.md, "Stick, slip or open").
pub const MARGIN_FACTOR: f64 = 2.0;

impl Settled {
    /// Whether the status is decided (outside the margins): stick, slip or separated.
    pub fn is_decided(self) -> bool {
        matches!(self, Settled::Separated | Settled::Stick | Settled::Slip)
    }

    /// The status of code `c`, if it is one.
    pub fn of_code(c: u8) -> Option<Self> {
        [
            Settled::Separated,
            Settled::Stick,
            Settled::Slip,
            Settled::Limit,
            Settled::Grazing,
        ]
        .get(c as usize)
        .copied()
    }
}

/// The margins of one run: m_T (MPa) and m_W per interface (mm; 0 on perfect interfaces).
#[derive(Debug, Clone, PartialEq)]
pub struct Margins {
    pub traction: f64,
    pub jump: Vec<f64>,
}

impl Margins {
    /// The margins of accuracy `accuracy` for fields whose largest contact traction is `t_max`.
    pub fn new(model: &Model, accuracy: f64, t_max: f64) -> Self {
        Self::with_factor(model, MARGIN_FACTOR, accuracy, t_max)
    }

    /// The same with m_T = `factor` · accuracy · T_max (the calibration compares factors).
    pub fn with_factor(model: &Model, factor: f64, accuracy: f64, t_max: f64) -> Self {
        let traction = factor * accuracy * t_max;
        let jump = model
            .interfaces
            .iter()
            .map(|itf| {
                let modulus = |s: usize| model.subdomains[s].material.interface_modulus(model.plane);
                traction * itf.length / (modulus(itf.a) * modulus(itf.b)).sqrt()
            })
            .collect();
        Self { traction, jump }
    }

    /// The accuracy a run's fields are judged at: its `accuracy`, or where it stops on the
    /// indicators alone, the contact indicator's tolerance, else η's, else the default accuracy.
    pub fn accuracy_of(model: &Model) -> f64 {
        let s = &model.solver;
        s.accuracy
            .or(s.contact_tolerance)
            .or(s.tolerance)
            .unwrap_or(crate::model::DEFAULT_ACCURACY)
    }
}

/// One pair's values at one time point in its own frame: [f_n, f_t, jump_n, jump_t] (the
/// traction on side a along the normal and the tangent, MPa; the jump W_b − W_a along them, mm).
pub type PairValues = [f64; 4];

/// The largest contact traction |(f_n, f_t)| over the contact interfaces' pairs and `nt` time
/// points, `value(k, i, p)` giving interface k's pair p at time point i.
pub fn largest_traction(interfaces: &[Interface], nt: usize, value: impl Fn(usize, usize, usize) -> PairValues) -> f64 {
    let mut t_max = 0.0f64;
    for (k, itf) in interfaces.iter().enumerate() {
        if !itf.is_contact() {
            continue;
        }
        for i in 0..nt {
            for p in 0..itf.n_pairs() {
                let [f_n, f_t, _, _] = value(k, i, p);
                t_max = t_max.max(f_n.hypot(f_t));
            }
        }
    }
    t_max
}

/// The reported status of pair `p` of contact interface `itf` (interface `k` of the margins) at
/// time point i, from its values there and its tangential jump at time point i − 1 (0 at i = 0).
pub fn settle(itf: &Interface, margin_t: f64, margin_w: f64, p: usize, v: PairValues, jump_t_before: f64) -> Settled {
    let InterfaceKind::Contact { friction, gap } = &itf.kind else {
        return Settled::Stick;
    };
    let [f_n, f_t, jump_n, jump_t] = v;
    let pressed = -f_n;
    if pressed <= margin_t {
        return if jump_n + gap[p] > margin_w {
            Settled::Separated
        } else {
            Settled::Grazing
        };
    }
    if *friction == 0.0 || (jump_t - jump_t_before).abs() > margin_w {
        return Settled::Slip;
    }
    if f_t.abs() < friction * pressed - margin_t {
        Settled::Stick
    } else {
        Settled::Limit
    }
}

/// The reported statuses of contact interface `k` over `nt` time points, at p + n_pairs·i
/// (codes of [`SETTLED_NAMES`]), `value(i, p)` giving its pair p at time point i.
pub fn settle_interface(
    itf: &Interface,
    margins: &Margins,
    k: usize,
    nt: usize,
    value: impl Fn(usize, usize) -> PairValues,
) -> Vec<u8> {
    let np = itf.n_pairs();
    let mut out = Vec::with_capacity(np * nt);
    for i in 0..nt {
        for p in 0..np {
            let before = if i == 0 { 0.0 } else { value(i - 1, p)[3] };
            out.push(settle(itf, margins.traction, margins.jump[k], p, value(i, p), before) as u8);
        }
    }
    out
}

/// Pair `p` of interface `itf` at time point `i` of `fields`, in its frame ([`PairValues`]).
pub fn values_of(itf: &Interface, fields: &InterfaceFields, i: usize, p: usize) -> PairValues {
    in_frame(itf, p, |r| [fields.w_a[(r, i)], fields.w_b[(r, i)], fields.f_a[(r, i)]])
}

/// Pair `p` of `itf` in its frame ([`PairValues`]), from `at(r)` = [W_a, W_b, F_a] at row r
/// (2p: x, 2p + 1: y) of the time point wanted.
pub fn in_frame(itf: &Interface, p: usize, at: impl Fn(usize) -> [f64; 3]) -> PairValues {
    let ([wa_x, wb_x, f_x], [wa_y, wb_y, f_y]) = (at(2 * p), at(2 * p + 1));
    let (f, jump) = ([f_x, f_y], [wb_x - wa_x, wb_y - wa_y]);
    let (n, t) = (itf.normal(p), itf.tangent(p));
    [dot(f, n), dot(f, t), dot(jump, n), dot(jump, t)]
}

/// How two solutions' reported statuses compare, pair-time point by pair-time point over the
/// contact interfaces: both decided and equal, both decided and different, or at least one within
/// its margin (limit or grazing).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Agreement {
    pub agree: usize,
    pub disagree: usize,
    pub within_margin: usize,
}

impl Agreement {
    /// The share of the decided pair-time points that agree (1 with none decided).
    pub fn share(&self) -> f64 {
        let decided = self.agree + self.disagree;
        if decided == 0 {
            1.0
        } else {
            self.agree as f64 / decided as f64
        }
    }
}

/// The reported statuses of `run` and `reference` (fields in interface order, both over the
/// same time points) compared with the same margins: those of `factor` at `accuracy` for the
/// run's largest traction.
pub fn agreement(
    model: &Model,
    run: &[InterfaceFields],
    reference: &[InterfaceFields],
    factor: f64,
    accuracy: f64,
) -> Agreement {
    let nt = run.first().map_or(0, |f| f.f_a.ncols());
    let t_max = largest_traction(&model.interfaces, nt, |k, i, p| {
        values_of(&model.interfaces[k], &run[k], i, p)
    });
    let margins = Margins::with_factor(model, factor, accuracy, t_max);
    let mut out = Agreement::default();
    for (k, itf) in model.interfaces.iter().enumerate() {
        if !itf.is_contact() {
            continue;
        }
        let mine = settle_interface(itf, &margins, k, nt, |i, p| values_of(itf, &run[k], i, p));
        let theirs = settle_interface(itf, &margins, k, nt, |i, p| values_of(itf, &reference[k], i, p));
        for (&a, &b) in mine.iter().zip(&theirs) {
            let decided = |c: u8| Settled::of_code(c).is_some_and(Settled::is_decided);
            if !(decided(a) && decided(b)) {
                out.within_margin += 1;
            } else if a == b {
                out.agree += 1;
            } else {
                out.disagree += 1;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(friction: f64, gap: f64) -> Interface {
        Interface {
            kind: InterfaceKind::Contact {
                friction,
                gap: vec![gap],
            },
            a: 0,
            b: 1,
            pairs: vec![(0, 0)],
            coords: vec![[0.0, 0.0]],
            weights: vec![1.0],
            normals: vec![[0.0, 1.0]],
            length: 1.0,
            centroid: [0.0, 0.0],
            projection: None,
            projection_a: None,
        }
    }

    /// Each branch, and the margins' edges: m_T = 0.1 MPa, m_W = 1e-5 mm, f = 0.2.
    #[test]
    fn each_status_and_the_margins() {
        let itf = contact(0.2, 0.0);
        let s = |v: PairValues, before: f64| settle(&itf, 0.1, 1e-5, 0, v, before);
        // Open by more than the margin, no force: separated; open by less: grazing.
        assert_eq!(s([0.0, 0.0, 2e-5, 0.0], 0.0), Settled::Separated);
        assert_eq!(s([0.0, 0.0, 0.5e-5, 0.0], 0.0), Settled::Grazing);
        // A compression within the margin is no contact force: grazing where touching.
        assert_eq!(s([-0.05, 0.0, 0.0, 0.0], 0.0), Settled::Grazing);
        // Pressed by 100: the cone is at 20; inside by more than the margin and not moving: stick.
        assert_eq!(s([-100.0, 19.8, 0.0, 3e-3], 3e-3), Settled::Stick);
        // On the cone within the margin, not moving beyond m_W: limit, whichever side of it.
        assert_eq!(s([-100.0, 19.95, 0.0, 3e-3], 3e-3 + 0.9e-5), Settled::Limit);
        assert_eq!(s([-100.0, -20.0, 0.0, 3e-3], 3e-3), Settled::Limit);
        // Moving by more than m_W: slip.
        assert_eq!(s([-100.0, 20.0, 0.0, 3e-3], 3e-3 - 2e-5), Settled::Slip);
        // Frictionless and pressed: slip (free to slide), moving or not.
        let free = contact(0.0, 0.0);
        assert_eq!(settle(&free, 0.1, 1e-5, 0, [-100.0, 0.0, 0.0, 0.0], 0.0), Settled::Slip);
        // An initial gap counts: jump_n = −g₀ closes it.
        let gapped = contact(0.2, 1e-3);
        assert_eq!(
            settle(&gapped, 0.1, 1e-5, 0, [0.0, 0.0, -1e-3, 0.0], 0.0),
            Settled::Grazing
        );
        assert_eq!(
            settle(&gapped, 0.1, 1e-5, 0, [0.0, 0.0, 0.0, 0.0], 0.0),
            Settled::Separated
        );
    }

    /// The time series: the first time point's increment is from 0, the later ones from the
    /// time point before.
    #[test]
    fn increments_over_the_time_steps() {
        let itf = contact(0.2, 0.0);
        let margins = Margins {
            traction: 0.1,
            jump: vec![1e-5],
        };
        let jumps = [1e-3, 1e-3, 2e-3];
        let codes = settle_interface(&itf, &margins, 0, 3, |i, _| [-100.0, 20.0, 0.0, jumps[i]]);
        assert_eq!(
            codes,
            vec![Settled::Slip as u8, Settled::Limit as u8, Settled::Slip as u8]
        );
    }

    #[test]
    fn codes_and_names_agree() {
        for c in 0..5u8 {
            assert_eq!(Settled::of_code(c).map(|s| s as u8), Some(c));
        }
        assert_eq!(Settled::of_code(5), None);
        assert_eq!(SETTLED_NAMES.len(), 5);
        assert!(Settled::Stick.is_decided() && !Settled::Limit.is_decided() && !Settled::Grazing.is_decided());
    }
}
