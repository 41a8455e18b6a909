//! Loads beyond what friction holds, seen while the iteration runs (docs/studies.md, "No
//! equilibrium").
//!
//! Where the loads on a part exceed what its contacts' friction and its supports can hold at a
//! time point, the problem has no solution there and LATIN has no fixed point: the local stage
//! keeps every pair of the interface on the friction cone (all slipping), while the linear
//! stage's forces s stay in equilibrium with the part's loads, so that their tangential resultant
//! exceeds f times their normal resultant by the same amount at every iteration. Where the loads
//! are held, s tends to ŝ, which obeys the cone, and that excess falls to zero or below.
//! A part that its supports hold in every rigid motion always has an equilibrium (the supports
//! take what friction does not), so only the sides of parts no support holds that way are
//! watched. [`SlidingWatch`] follows, per time point of one contact interface, the friction
//! excess of s on each of those sides
//!
//!   x = (|Σ w F_T| − f Σ w max(−F_N, 0)) / Σ w |F|
//!
//! and reports the interface as sliding when at some time point, over the last
//! [`SLIDING_WINDOW`] iterations, every pair in contact slipped, ŝ's mean tangential jump moved
//! the same way at every iteration (the part moving away) and a side's x stayed above
//! [`SLIDING_EXCESS`] and steady (its smallest at least [`SLIDING_KEPT`] of its largest); it then
//! names, on the sides that showed it, the first time point whose x stayed above
//! [`SLIDING_EXCESS`] over the window.

use crate::laws::Status;
use crate::local::{InterfaceFields, InterfaceLocal};
use crate::model::{Interface, InterfaceKind, Model, Plane};
use crate::settled::in_frame;

/// Iterations of whole slip with a steady excess before a time point is said to slide.
pub const SLIDING_WINDOW: usize = 10;

/// The friction excess of s, (|Σ w F_T| − f Σ w max(−F_N, 0)) / Σ w |F|, above which a time
/// point of an interface carries more tangential force than its normal force lets friction hold.
pub const SLIDING_EXCESS: f64 = 1e-3;

/// The share of the window's largest excess that its smallest must keep: the excess holds
/// steady (a run that converges sees it fall to zero or below, at its contraction rate).
pub const SLIDING_KEPT: f64 = 0.97;

/// Per time point of one contact interface: how many iterations in a row every pair in contact
/// slipped, and the last [`SLIDING_WINDOW`] friction excesses of s.
#[derive(Debug, Clone)]
pub struct SlidingWatch {
    /// The sides (a, b) whose parts no support holds in every rigid motion: only their forces
    /// in s balance their loads whatever the iteration; a part held by supports always has an
    /// equilibrium.
    pub sides: [bool; 2],
    streak: Vec<u32>,
    /// ŝ's mean tangential jump at each time point after the last iteration, and how many
    /// iterations in a row it moved the same way (signed: + forward, − backward).
    jump: Vec<f64>,
    drift: Vec<i32>,
    /// Side k's excesses at time point i in `excess[k][i·W..(i + 1)·W]`, rings written at `next`.
    excess: [Vec<f64>; 2],
    next: usize,
    observed: usize,
}

/// What [`SlidingWatch::observe`] found: the first time point beyond what friction holds, and
/// the sides (a, b) whose forces showed it (their parts would slide or turn away).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sliding {
    pub from: usize,
    pub sides: [bool; 2],
}

impl SlidingWatch {
    pub fn new(n_times: usize) -> Self {
        Self {
            sides: [false; 2],
            streak: vec![0; n_times],
            jump: vec![0.0; n_times],
            drift: vec![0; n_times],
            excess: [vec![0.0; n_times * SLIDING_WINDOW], vec![0.0; n_times * SLIDING_WINDOW]],
            next: 0,
            observed: 0,
        }
    }

    /// Takes the local stage just run on `itf` (its statuses) from `s`, the linear stage's
    /// fields, and returns, when the interface slides, the first time point beyond what friction
    /// holds and the sides that showed it (see the module's text).
    pub fn observe(&mut self, itf: &Interface, local: &InterfaceLocal, s: &InterfaceFields) -> Option<Sliding> {
        let np = itf.n_pairs();
        let nt = self.streak.len();
        let InterfaceKind::Contact { friction, .. } = itf.kind else {
            return None;
        };
        if np == 0 || self.sides == [false; 2] {
            return None;
        }
        let w = SLIDING_WINDOW;
        let (mut first_beyond, mut slides) = ([None::<usize>; 2], [false; 2]);
        let total: f64 = itf.weights.iter().sum();
        for i in 0..nt {
            let status = &local.status[np * i..np * (i + 1)];
            let slipping = status.contains(&Status::Slip);
            let whole = slipping && status.iter().all(|s| *s != Status::Stick);
            self.streak[i] = if whole { self.streak[i].saturating_add(1) } else { 0 };
            // The part moving away: ŝ's mean tangential jump steps the same way every iteration.
            let (w_a, w_b) = (local.hat.w_a.col_as_slice(i), local.hat.w_b.col_as_slice(i));
            let mut jump = 0.0;
            for p in 0..np {
                let t = itf.tangent(p);
                jump += itf.weights[p] * ((w_b[2 * p] - w_a[2 * p]) * t[0] + (w_b[2 * p + 1] - w_a[2 * p + 1]) * t[1]);
            }
            jump /= total;
            let step = jump - self.jump[i];
            self.jump[i] = jump;
            let d = self.drift[i];
            self.drift[i] = if step > 0.0 {
                d.max(0).saturating_add(1)
            } else if step < 0.0 {
                d.min(0).saturating_sub(1)
            } else {
                0
            };
            let moving = self.streak[i] as usize >= w && self.drift[i].unsigned_abs() as usize >= w;
            // The forces of a free side in s balance its part's loads (a subdomain's linear
            // stage is in equilibrium with whatever the interface carries).
            for (k, (f, sign)) in [(&s.f_a, 1.0), (&s.f_b, -1.0)].into_iter().enumerate() {
                if !self.sides[k] {
                    continue;
                }
                let (mut tangential, mut pressed, mut size) = (0.0, 0.0, 0.0);
                for p in 0..np {
                    let [f_n, f_t, _, _] = in_frame(itf, p, |r| [0.0, 0.0, sign * f[(r, i)]]);
                    let weight = itf.weights[p];
                    tangential += weight * f_t;
                    pressed += weight * (-f_n).max(0.0);
                    size += weight * f_n.hypot(f_t);
                }
                let excess = if size > 0.0 {
                    (tangential.abs() - friction * pressed) / size
                } else {
                    0.0
                };
                let ring = &mut self.excess[k][i * w..(i + 1) * w];
                ring[self.next] = excess;
                if self.observed + 1 >= w {
                    let (lo, hi) = ring.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                        (lo.min(*x), hi.max(*x))
                    });
                    if lo > SLIDING_EXCESS {
                        first_beyond[k].get_or_insert(i);
                        slides[k] |= moving && lo >= SLIDING_KEPT * hi;
                    }
                }
            }
        }
        self.next = (self.next + 1) % w;
        self.observed += 1;
        // The first time point beyond, on the sides that slide.
        let from = (0..2).filter(|&k| slides[k]).filter_map(|k| first_beyond[k]).min()?;
        Some(Sliding { from, sides: slides })
    }
}

/// What a run that stops on sliding interfaces says: per part that would slide or turn away (a
/// group of subdomains joined by perfect interfaces, on a side that showed it; the loaded ones
/// where some are), the interfaces that showed it, each with its two sides and its first time
/// point beyond what friction holds.
pub fn no_equilibrium(model: &Model, sliding: &[(usize, Sliding)]) -> String {
    let parts = parts(model);
    let name = |s: usize| model.subdomains[s].name.as_str();
    // (part, the interfaces and first time points that show it), in order of first mention.
    let mut loose: Vec<(usize, Vec<(usize, usize)>)> = Vec::new();
    for &(i, Sliding { from, sides }) in sliding {
        let itf = &model.interfaces[i];
        for s in [(itf.a, sides[0]), (itf.b, sides[1])]
            .into_iter()
            .filter(|x| x.1)
            .map(|x| x.0)
        {
            let part = parts
                .iter()
                .position(|p| p.contains(&s))
                .expect("every subdomain is in a part");
            match loose.iter_mut().find(|(p, _)| *p == part) {
                Some((_, shown)) if shown.iter().any(|x| x.0 == i) => {}
                Some((_, shown)) => shown.push((i, from)),
                None => loose.push((part, vec![(i, from)])),
            }
        }
    }
    // A part without loads of its own shows the excess where it passes on what a loaded part
    // pushes it with (a ring between the twisted one and the fit that holds it): the loaded parts
    // are the ones that move, where any showed it.
    if loose.iter().any(|(p, _)| loaded(model, &parts[*p])) {
        loose.retain(|(p, _)| loaded(model, &parts[*p]));
    }
    let first = loose
        .iter()
        .flat_map(|(_, shown)| shown.iter().map(|x| x.1))
        .min()
        .unwrap_or(0);
    let said: Vec<String> = loose
        .iter()
        .map(|(part, shown)| {
            let members = &parts[*part];
            let mut who: Vec<&str> = members.iter().take(4).map(|&m| name(m)).collect();
            if members.len() > who.len() {
                who.push("…");
            }
            let count = if members.len() > 4 {
                format!(" ({} subdomains)", members.len())
            } else {
                String::new()
            };
            let mut by: Vec<String> = shown
                .iter()
                .take(3)
                .map(|&(i, t)| {
                    let itf = &model.interfaces[i];
                    format!("{i} ({} | {}) from t = {}", name(itf.a), name(itf.b), model.time.t(t))
                })
                .collect();
            if shown.len() > by.len() {
                by.push(format!("and {} more", shown.len() - by.len()));
            }
            format!(
                "part [{}]{count} would slide or turn away: its interface{} {} slip{} as a whole, carrying more \
                 tangential force than friction holds under the normal force at every iteration",
                who.join(", "),
                if shown.len() > 1 { "s" } else { "" },
                by.join(", "),
                if shown.len() > 1 { "" } else { "s" },
            )
        })
        .collect();
    format!(
        "the loads exceed what friction and the supports hold from t = {}: {}; `glissade onset <scene> --rule <k>` \
         finds the factor on a load at which it begins",
        model.time.t(first),
        said.join("; ")
    )
}

/// Which sides (a, b) of interface `i` belong to parts that no support holds in every rigid
/// motion ([`SlidingWatch::sides`]).
pub fn free_sides(model: &Model, i: usize) -> [bool; 2] {
    let parts = parts(model);
    let itf = &model.interfaces[i];
    [itf.a, itf.b].map(|s| {
        let part = parts
            .iter()
            .find(|p| p.contains(&s))
            .expect("every subdomain is in a part");
        !held_by_supports(model, part)
    })
}

/// The parts of a model: groups of subdomains joined by perfect interfaces, each in ascending
/// order.
fn parts(model: &Model) -> Vec<Vec<usize>> {
    let n = model.subdomains.len();
    let mut root: Vec<usize> = (0..n).collect();
    fn find(root: &mut [usize], mut s: usize) -> usize {
        while root[s] != s {
            root[s] = root[root[s]];
            s = root[s];
        }
        s
    }
    for itf in model.interfaces.iter().filter(|i| !i.is_contact()) {
        let (a, b) = (find(&mut root, itf.a), find(&mut root, itf.b));
        root[a.max(b)] = a.min(b);
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut of_root = vec![usize::MAX; n];
    for s in 0..n {
        let r = find(&mut root, s);
        if of_root[r] == usize::MAX {
            of_root[r] = groups.len();
            groups.push(Vec::new());
        }
        groups[of_root[r]].push(s);
    }
    groups
}

/// Whether some subdomain of a part has a load of its own: a force, or a prescribed displacement
/// other than zero.
fn loaded(model: &Model, part: &[usize]) -> bool {
    part.iter().any(|&s| {
        model.subdomains[s]
            .loads
            .iter()
            .any(|l| l.force.iter().chain(&l.displacement).any(|v| *v != 0.0))
    })
}

/// Whether the prescribed displacements of a part block all its rigid motions (two translations
/// and a rotation; in axisymmetry the one translation along the axis).
fn held_by_supports(model: &Model, part: &[usize]) -> bool {
    let mut rows: Vec<([f64; 2], usize)> = Vec::new();
    for &s in part {
        let sub = &model.subdomains[s];
        for (d, _) in sub.constrained.iter().enumerate().filter(|(_, c)| **c) {
            rows.push((sub.mesh.coords[d / 2], d % 2));
        }
    }
    if model.plane == Plane::Axisymmetric {
        return rows.iter().any(|r| r.1 == 1);
    }
    if rows.is_empty() {
        return false;
    }
    let n = rows.len() as f64;
    let c = rows
        .iter()
        .fold([0.0, 0.0], |c, r| [c[0] + r.0[0] / n, c[1] + r.0[1] / n]);
    let scale = rows
        .iter()
        .fold(0.0f64, |m, r| m.max((r.0[0] - c[0]).hypot(r.0[1] - c[1])))
        .max(f64::MIN_POSITIVE);
    // Each constrained dof blocks the rigid motions (u_x, u_y, ω) along its row: δ_c0, δ_c1 and
    // the rotation's displacement along it, −(y − ȳ) or (x − x̄), over the part's size.
    let mut gram = nalgebra::Matrix3::<f64>::zeros();
    for (x, comp) in &rows {
        let v = if *comp == 0 {
            nalgebra::Vector3::new(1.0, 0.0, -(x[1] - c[1]) / scale)
        } else {
            nalgebra::Vector3::new(0.0, 1.0, (x[0] - c[0]) / scale)
        };
        gram += v * v.transpose();
    }
    let eig = gram.symmetric_eigenvalues();
    let top = eig.max();
    eig.iter().all(|&e| e > 1e-10 * top)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `iterations` of a made-up iteration on the two-block contact (f = 0.3): in ŝ every
    /// pair of time points 1.. slips (but pair np/2 at time point `stuck_at`), time point 0
    /// sticks; in s, side a's force at pair p, time point i, iteration n is N(−n + r(n, i)·t)
    /// (N = 10), side b's its opposite. Returns what the watch said after each iteration.
    fn watch(iterations: usize, r: impl Fn(usize, usize) -> f64, stuck_at: Option<usize>) -> Vec<Option<Sliding>> {
        watch_sides(iterations, r, stuck_at, [true, true], 1e-3)
    }

    /// [`watch`] reading the forces of `sides` only.
    fn watch_sides(
        iterations: usize,
        r: impl Fn(usize, usize) -> f64,
        stuck_at: Option<usize>,
        sides: [bool; 2],
        drift: f64,
    ) -> Vec<Option<Sliding>> {
        let model = crate::fixtures::two_blocks_contact();
        let itf = &model.interfaces[0];
        let (np, nt) = (itf.n_pairs(), model.time.n_points());
        let mut local = InterfaceLocal::new(0, itf, 1.0, nt);
        let mut s = InterfaceFields::zeros(np, nt);
        let mut w = SlidingWatch::new(nt);
        w.sides = sides;
        (0..iterations)
            .map(|n| {
                for i in 0..nt {
                    for p in 0..np {
                        let stuck = i == 0 || stuck_at == Some(i) && p == np / 2;
                        local.status[p + np * i] = if stuck { Status::Stick } else { Status::Slip };
                        let (normal, t) = (itf.normal(p), itf.tangent(p));
                        for c in 0..2 {
                            s.f_a[(2 * p + c, i)] = 10.0 * (-normal[c] + r(n, i) * t[c]);
                            s.f_b[(2 * p + c, i)] = -s.f_a[(2 * p + c, i)];
                            // ŝ's side b moved along the tangent by `drift` per iteration.
                            local.hat.w_b[(2 * p + c, i)] = drift * (n + 1) as f64 * t[c];
                        }
                    }
                }
                w.observe(itf, &local, &s)
            })
            .collect()
    }

    /// A tangential force steadily beyond the cone at time points 1 (by 3 % of f·N, an excess
    /// x = 0.009/√1.0955 ≈ 8.6e-3) and 2 (33 %) while every pair slips (a part pulled beyond what
    /// friction holds) slides from time point 1 once the window is full; not before.
    #[test]
    fn a_steady_excess_slides() {
        let said = watch(14, |_, i| [0.2, 0.309, 0.4][i.min(2)], None);
        assert!(said[..SLIDING_WINDOW - 1].iter().all(Option::is_none), "{said:?}");
        let both = Sliding {
            from: 1,
            sides: [true, true],
        };
        assert!(said[SLIDING_WINDOW - 1..].iter().all(|s| *s == Some(both)), "{said:?}");
    }

    /// An excess that falls as a run converges (a factor 0.99 per iteration: the window admits
    /// nothing that falls faster than 0.9966) never slides, nor one that
    /// changes sign (Anderson's mixing overshooting the cone), nor a steady one where a pair
    /// sticks, nor one below [`SLIDING_EXCESS`] (2e-4 here).
    #[test]
    fn a_falling_or_held_excess_does_not_slide() {
        let converging = watch(60, |n, _| 0.3 + 0.1 * 0.99f64.powi(n as i32), None);
        assert!(converging.iter().all(Option::is_none), "{converging:?}");
        let overshooting = watch(40, |n, _| 0.3 + 0.05 * (-0.999f64).powi(n as i32), None);
        assert!(overshooting.iter().all(Option::is_none), "{overshooting:?}");
        let held = watch(30, |_, i| if i == 2 { 0.4 } else { 0.2 }, Some(2));
        assert!(held.iter().all(Option::is_none), "{held:?}");
        let small = watch(30, |_, _| 0.3002, None);
        assert!(small.iter().all(Option::is_none), "{small:?}");
        // Both parts held by their supports: they always have an equilibrium.
        let supported = watch_sides(30, |_, _| 0.4, None, [false, false], 1e-3);
        assert!(supported.iter().all(Option::is_none), "{supported:?}");
        // A steady excess where ŝ does not move (a stall with an equilibrium): no slide.
        let still = watch_sides(30, |_, _| 0.4, None, [true, true], 0.0);
        assert!(still.iter().all(Option::is_none), "{still:?}");
        // Side b alone free: its forces count (−F_a, the same excess here).
        let b = Sliding {
            from: 1,
            sides: [false, true],
        };
        assert_eq!(
            watch_sides(12, |_, i| [0.2, 0.4][i.min(1)], None, [false, true], 1e-3)[11],
            Some(b)
        );
    }

    /// The diagnosis names the interface, its sides, the first time point and the part its
    /// supports do not hold.
    #[test]
    fn the_diagnosis_names_the_part_that_slides() {
        let mut model = crate::fixtures::two_blocks_contact();
        assert_eq!(free_sides(&model, 0), [false, false]);
        model.subdomains[1].constrained.fill(false);
        assert_eq!(free_sides(&model, 0), [false, true]);
        let sliding = Sliding {
            from: 2,
            sides: [false, true],
        };
        let text = no_equilibrium(&model, &[(0, sliding)]);
        assert_eq!(
            text,
            "the loads exceed what friction and the supports hold from t = 0.6666666666666666: part [hi] would \
             slide or turn away: its interface 0 (lo | hi) from t = 0.6666666666666666 slips as a whole, carrying \
             more tangential force than friction holds under the normal force at every iteration; `glissade onset \
             <scene> --rule <k>` finds the factor on a load at which it begins"
        );
        // Held in x and y at one point only: it can still turn.
        let sub = &mut model.subdomains[1];
        sub.constrained[0] = true;
        sub.constrained[1] = true;
        assert!(!held_by_supports(&model, &[1]));
        assert!(held_by_supports(&model, &[0]));
    }
}
