//! The local stage on whole interfaces, the search-direction update and the convergence
//! indicators (docs/method.md, "Local stage", "Search-direction update" and "Indicators").
//!
//! Interface fields are stored per side as (2·n_pairs) × (N+1) column-major matrices: entry
//! 2p + c is pair p, component c (global x, y); column i is time point t_i.

use crate::laws::{self, ContactPoint, PairState, Status};
use crate::model::{Interface, InterfaceKind, SolverParams};
use crate::points::{junctions, PhysicalPoint, PointCopy};
use crate::sliding::{Sliding, SlidingWatch};
use faer::reborrow::ReborrowMut;
use faer::{Mat, MatMut, MatRef};

/// Traces W and forces F of both sides of an interface over all time points (mm, N/mm).
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceFields {
    pub w_a: Mat<f64>,
    pub w_b: Mat<f64>,
    pub f_a: Mat<f64>,
    pub f_b: Mat<f64>,
}

impl InterfaceFields {
    pub fn zeros(n_pairs: usize, n_times: usize) -> Self {
        let z = || Mat::zeros(2 * n_pairs, n_times);
        Self {
            w_a: z(),
            w_b: z(),
            f_a: z(),
            f_b: z(),
        }
    }

    /// Column i of (W_A, W_B, F_A, F_B).
    #[inline(always)]
    fn columns(&self, i: usize) -> [&[f64]; 4] {
        [
            self.w_a.col_as_slice(i),
            self.w_b.col_as_slice(i),
            self.f_a.col_as_slice(i),
            self.f_b.col_as_slice(i),
        ]
    }

    /// Column i of (W_A, W_B, F_A, F_B), to write.
    #[inline(always)]
    fn columns_mut(&mut self, i: usize) -> [&mut [f64]; 4] {
        [
            self.w_a.col_as_slice_mut(i),
            self.w_b.col_as_slice_mut(i),
            self.f_a.col_as_slice_mut(i),
            self.f_b.col_as_slice_mut(i),
        ]
    }
}

impl InterfaceFields {
    /// One side's trace and force, to write.
    pub fn side_mut(&mut self, side: crate::model::Side) -> (&mut Mat<f64>, &mut Mat<f64>) {
        match side {
            crate::model::Side::A => (&mut self.w_a, &mut self.f_a),
            crate::model::Side::B => (&mut self.w_b, &mut self.f_b),
        }
    }

    /// Writes one side's trace and force from a subdomain's boundary fields (n_b × (N+1)), rows
    /// `offset..offset + 2·n_pairs`.
    pub fn set_side(&mut self, side: crate::model::Side, offset: usize, w: MatRef<'_, f64>, f: MatRef<'_, f64>) {
        let (to_w, to_f) = self.side_mut(side);
        let rows = to_w.nrows();
        to_w.copy_from(w.subrows(offset, rows));
        to_f.copy_from(f.subrows(offset, rows));
    }
}

/// Each LATIN iteration's error against a reference ([`error_against_reference`]), from the
/// subdomains' boundary states s = (W, F) as they come: once every subdomain with a boundary has
/// sent its state, the iteration's interface fields are complete and their errors are returned.
pub struct ReferenceErrors {
    layouts: Vec<crate::condensed::BoundaryLayout>,
    participants: usize,
    fields: Vec<InterfaceFields>,
    seen: std::collections::BTreeSet<usize>,
    weights: Vec<f64>,
}

impl ReferenceErrors {
    pub fn new(model: &crate::model::Model) -> Self {
        Self::over(model, model.time.n_points())
    }

    /// Errors over the first `time_points` time points only (at least 1, at most all): against a
    /// reference that solved those and failed at the next. The space-time norms take the
    /// trapezoid weights of that shorter grid.
    pub fn over(model: &crate::model::Model, time_points: usize) -> Self {
        let k0 = crate::linear::default_k0(model);
        let layouts: Vec<crate::condensed::BoundaryLayout> = (0..model.subdomains.len())
            .map(|s| crate::condensed::BoundaryLayout::new(model, s, &k0))
            .collect();
        let nt = model.time.n_points();
        let k = time_points.clamp(1, nt);
        let mut weights = model.time.trapezoid_weights();
        weights.truncate(k);
        if k < nt && k > 1 {
            // The shorter grid's last point is an end point: half its step.
            weights[k - 1] = 0.5 * (model.time.t(k - 1) - model.time.t(k - 2));
        }
        Self {
            participants: layouts.iter().filter(|l| !l.is_empty()).count(),
            layouts,
            fields: model
                .interfaces
                .iter()
                .map(|i| InterfaceFields::zeros(i.n_pairs(), nt))
                .collect(),
            seen: Default::default(),
            weights,
        }
    }

    /// Takes subdomain `subdomain`'s boundary state (W, F); returns its errors against
    /// `reference` once the iteration's states are all in.
    pub fn boundary_state(
        &mut self,
        interfaces: &[Interface],
        subdomain: usize,
        w: MatRef<'_, f64>,
        f: MatRef<'_, f64>,
        reference: &[InterfaceFields],
    ) -> Option<ErrorsAgainstReference> {
        for slot in &self.layouts.get(subdomain)?.slots {
            self.fields[slot.interface].set_side(slot.side, slot.offset, w, f);
        }
        self.seen.insert(subdomain);
        if self.seen.len() < self.participants {
            return None;
        }
        self.seen.clear();
        let (traction, jump) = error_against_reference(interfaces, &self.fields, reference, &self.weights);
        Some(ErrorsAgainstReference {
            traction,
            jump,
            pointwise: pointwise_traction_error_over(interfaces, &self.fields, reference, self.weights.len()),
        })
    }
}

/// One iterate's errors against a reference ([`ReferenceErrors::boundary_state`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorsAgainstReference {
    /// e_F of [`error_against_reference`].
    pub traction: f64,
    /// e_W of [`error_against_reference`].
    pub jump: f64,
    /// [`pointwise_traction_error`].
    pub pointwise: PointwiseError,
}

/// The largest traction difference at one point of the contact interfaces and where it is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointwiseError {
    /// max over physical contact points, time points, components (x, y) and sides of |t − t_ref|, relative to the largest |t_ref| over the same (0 where the reference has no
    /// contact force and s none either; infinite where only the reference has none).
    pub error: f64,
    /// Where the largest difference is: an interface and pair of its group, and the time point.
    pub interface: usize,
    pub pair: usize,
    pub time_point: usize,
}

/// The nodal forces Σ m·F of the pairs of one junction ([`junctions`]) at time point
/// `i`, component `c`: s's on the point's sides a and b, then the reference's.
fn group_forces(
    interfaces: &[Interface],
    point: &PhysicalPoint,
    s: &[InterfaceFields],
    reference: &[InterfaceFields],
    i: usize,
    c: usize,
) -> [f64; 4] {
    let force = |x: &[InterfaceFields], k: usize, p: usize, b: bool| {
        let f = if b { &x[k].f_b } else { &x[k].f_a };
        f[(2 * p + c, i)]
    };
    [
        point.weighted_sum(interfaces, false, |k, p, b| force(s, k, p, b)),
        point.weighted_sum(interfaces, true, |k, p, b| force(s, k, p, b)),
        point.weighted_sum(interfaces, false, |k, p, b| force(reference, k, p, b)),
        point.weighted_sum(interfaces, true, |k, p, b| force(reference, k, p, b)),
    ]
}

/// The pointwise counterpart of e_F ([`error_against_reference`]): at each physical contact
/// point g (a junction, [`junctions`]: one pair, or the pairs at one place whose summed force
/// is what is determined) the traction t_g = Σ m·F / Σ m of each side, and the largest
/// |t_g − t_g,ref| over points, time points, components (x, y) and sides relative to the largest
/// |t_g,ref|.
pub fn pointwise_traction_error(
    interfaces: &[Interface],
    s: &[InterfaceFields],
    reference: &[InterfaceFields],
) -> PointwiseError {
    pointwise_traction_error_over(interfaces, s, reference, usize::MAX)
}

/// [`pointwise_traction_error`] over the first `time_points` time points only.
pub fn pointwise_traction_error_over(
    interfaces: &[Interface],
    s: &[InterfaceFields],
    reference: &[InterfaceFields],
    time_points: usize,
) -> PointwiseError {
    let (mut worst, mut scale) = (PointwiseError::default(), 0.0f64);
    for point in junctions(interfaces) {
        let Some(&PointCopy {
            interface: k0,
            pair: p0,
            ..
        }) = point.copies.first()
        else {
            continue;
        };
        let m_g = point.weight;
        for i in 0..s.get(k0).map_or(0, |x| x.f_a.ncols()).min(time_points) {
            for c in 0..2 {
                let [n_a, n_b, r_a, r_b] = group_forces(interfaces, &point, s, reference, i, c);
                let d = (n_a - r_a).abs().max((n_b - r_b).abs()) / m_g;
                scale = scale.max(r_a.abs().max(r_b.abs()) / m_g);
                if d > worst.error || d.is_nan() {
                    worst = PointwiseError {
                        error: d,
                        interface: k0,
                        pair: p0,
                        time_point: i,
                    };
                }
            }
        }
    }
    worst.error = if worst.error == 0.0 {
        0.0
    } else if scale > 0.0 {
        worst.error / scale
    } else {
        f64::INFINITY
    };
    worst
}

/// Error of interface fields `s` against a reference solution of the same discrete problem, on
/// contact interfaces (docs/accuracy.md): relative space-time norms
/// (trapezoid weights w_i):
/// - e_F over the contact forces: per junction g (see [`junctions`]; a single pair away from
///   cross-points) the nodal forces M·F of both sides are summed, since only their sum is
///   determined where copies of a pair, or pairs closing a cycle, meet at one place; e_F² = Σ_i w_i Σ_g |N_g − N_g,ref|²/m_g / Σ_i w_i Σ_g |N_g,ref|²/m_g, which is the
///   M-weighted traction norm where g is one pair;
/// - e_W = ‖[W] − [W]_ref‖ / (‖[W]_ref‖² + ½‖W_ref‖²)^½ over every copy's jump (M-weighted;
///   scaled like e_W of [`IndicatorSums`], so that it stays defined when every point sticks).
///
/// Returns (e_F, e_W).
pub fn error_against_reference(
    interfaces: &[Interface],
    s: &[InterfaceFields],
    reference: &[InterfaceFields],
    time_weights: &[f64],
) -> (f64, f64) {
    let (mut f_num, mut f_den, mut w_num, mut w_den) = (0.0, 0.0, 0.0, 0.0);
    let sq = |v: f64| v * v;
    for point in junctions(interfaces) {
        let m_g = point.weight;
        for (i, &wt) in time_weights.iter().enumerate() {
            for c in 0..2 {
                let [n_a, n_b, r_a, r_b] = group_forces(interfaces, &point, s, reference, i, c);
                for &PointCopy {
                    interface: k, pair: p, ..
                } in &point.copies
                {
                    let (x, r, m) = (&s[k], &reference[k], interfaces[k].weights[p]);
                    let e = 2 * p + c;
                    let jump = x.w_b[(e, i)] - x.w_a[(e, i)];
                    let jump_ref = r.w_b[(e, i)] - r.w_a[(e, i)];
                    w_num += wt * m * sq(jump - jump_ref);
                    w_den += wt * m * (sq(jump_ref) + 0.5 * (sq(r.w_a[(e, i)]) + sq(r.w_b[(e, i)])));
                }
                f_num += wt * (sq(n_a - r_a) + sq(n_b - r_b)) / m_g;
                f_den += wt * (sq(r_a) + sq(r_b)) / m_g;
            }
        }
    }
    (ratio(f_num, f_den), ratio(w_num, w_den))
}

/// The larger of `m` and `v`, NaN if `v` is (a maximum that carries a NaN on).
fn nan_max(m: f64, v: f64) -> f64 {
    if v > m || v.is_nan() {
        v
    } else {
        m
    }
}

/// The step of one interface side's forces since the previous iteration, summed as the sides
/// arrive ([`force_step_sums`], combined with [`StepSums::add`]): the terms of
/// [`IndicatorSums::step_num`], [`IndicatorSums::step_den`], [`IndicatorSums::step_max`] and
/// [`IndicatorSums::force_max`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepSums {
    /// Σ_i w_i Σ_p m_p |Fₙ − Fₙ₋₁|².
    pub num: f64,
    /// Σ_i w_i Σ_p m_p |Fₙ|².
    pub den: f64,
    /// max over pairs, time points and components of |Fₙ − Fₙ₋₁| (a traction).
    pub max_step: f64,
    /// max over pairs, time points and components of |Fₙ|.
    pub max_force: f64,
}

impl StepSums {
    pub fn add(&mut self, o: &StepSums) {
        self.num += o.num;
        self.den += o.den;
        self.max_step = nan_max(self.max_step, o.max_step);
        self.max_force = nan_max(self.max_force, o.max_force);
    }
}

/// One side's share of the force step ([`StepSums`]): `old` and `new` are that side's forces
/// (2·n_pairs × (N+1)), `pair_weights` the lumped mass of each pair and `time_weights` the
/// trapezoid weights. A NaN step or force makes the maxima NaN.
pub fn force_step_sums(
    pair_weights: &[f64],
    time_weights: &[f64],
    old: MatRef<'_, f64>,
    new: MatRef<'_, f64>,
) -> StepSums {
    let mut out = StepSums::default();
    for (i, &wt) in time_weights.iter().enumerate() {
        let (o, n) = (
            old.col(i)
                .try_as_col_major()
                .expect("the interfaces' force fields have unit row stride"),
            new.col(i)
                .try_as_col_major()
                .expect("the interfaces' force fields have unit row stride"),
        );
        let (o, n) = (o.as_slice(), n.as_slice());
        let (mut col_num, mut col_den, mut col_step, mut col_force) = (0.0, 0.0, 0.0f64, 0.0f64);
        for (e, (&a, &b)) in o.iter().zip(n).enumerate() {
            let m = pair_weights[e / 2];
            col_num += m * (b - a) * (b - a);
            col_den += m * b * b;
            col_step = nan_max(col_step, (b - a).abs());
            col_force = nan_max(col_force, b.abs());
        }
        out.num += wt * col_num;
        out.den += wt * col_den;
        out.max_step = nan_max(out.max_step, col_step);
        out.max_force = nan_max(out.max_force, col_force);
    }
    out
}

/// Search directions k⁺ of a contact interface, per pair and time point (n_pairs × (N+1)).
#[derive(Debug, Clone, PartialEq)]
pub struct ContactDirections {
    pub k_n: Mat<f64>,
    pub k_t: Mat<f64>,
}

/// Additive partial sums of the indicators; combine over interfaces with [`IndicatorSums::add`],
/// then read the ratios.
///
/// - LATIN indicator (eq. 10): η² = Σ‖s − ŝ‖² / (½ Σ(‖s‖² + ‖ŝ‖²)), with
///   ‖s‖² = Σ_i w_i (k⁻ Wᵢᵀ M Wᵢ + (k⁻)⁻¹ Fᵢᵀ M Fᵢ) over both sides of every interface.
/// - Contact indicator, independent of k: on contact interfaces only,
///   e_F² = Σ_i w_i Σ_sides (F − F̂)ᵀM(F − F̂) / Σ_i w_i Σ_sides F̂ᵀMF̂ (tractions) and
///   e_W² = Σ_i w_i ([W] − [Ŵ])ᵀM([W] − [Ŵ]) / Σ_i w_i ([Ŵ]ᵀM[Ŵ] + ½Σ_sides ŴᵀMŴ) (jumps, scaled
///   by the jump and the displacement of the interface so that it stays defined when everything
///   sticks), and e_c = max(e_F, e_W). M is the lumped interface mass, w_i the trapezoid weights;
///   no search direction enters, so e_c measures the distance between s and ŝ in physical units
///   alone. A ratio whose numerator and denominator are both zero (no load) is 0.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct IndicatorSums {
    pub eta_num: f64,
    pub eta_den: f64,
    pub force_num: f64,
    pub force_den: f64,
    pub jump_num: f64,
    pub jump_den: f64,
    /// Contact points (pair × time) per status: separated, stick, slip.
    pub counts: [u64; 3],
    /// Contact points whose status changed since the previous local stage.
    pub status_changes: u64,
    /// Step of the interface forces since the previous iteration, on contact interfaces (on
    /// every interface of a scene without contact): Σ_i w_i Σ_sides (Fₙ − Fₙ₋₁)ᵀM(Fₙ − Fₙ₋₁)
    /// ([`force_step_sums`]); the error estimate of [`crate::estimate`] is built on it.
    pub step_num: f64,
    /// Σ_i w_i Σ_sides FₙᵀMFₙ over the same interfaces.
    pub step_den: f64,
    /// The pointwise step: max over the same interfaces' pairs, time points, components (x, y)
    /// and sides of |Fₙ − Fₙ₋₁| (a traction); the pointwise estimate is built on it. Each copy
    /// of a node pair at a cross-point counts on its own (the traction its interface writes).
    pub step_max: f64,
    /// max |Fₙ| over the same.
    pub force_max: f64,
}

fn ratio(num: f64, den: f64) -> f64 {
    if num == 0.0 {
        0.0
    } else {
        (num / den).sqrt()
    }
}

impl IndicatorSums {
    pub fn add(&mut self, o: &IndicatorSums) {
        self.eta_num += o.eta_num;
        self.eta_den += o.eta_den;
        self.force_num += o.force_num;
        self.force_den += o.force_den;
        self.jump_num += o.jump_num;
        self.jump_den += o.jump_den;
        for k in 0..3 {
            self.counts[k] += o.counts[k];
        }
        self.status_changes += o.status_changes;
        self.step_num += o.step_num;
        self.step_den += o.step_den;
        self.step_max = nan_max(self.step_max, o.step_max);
        self.force_max = nan_max(self.force_max, o.force_max);
    }

    /// dₙ = ‖Fₙ − Fₙ₋₁‖ / ‖Fₙ‖: the relative step of the interface forces (contact interfaces)
    /// at this iteration.
    pub fn force_step(&self) -> f64 {
        if self.step_den == 0.0 {
            return 0.0;
        }
        ratio(self.step_num, self.step_den)
    }

    /// The pointwise step of the forces: [`Self::step_max`] relative to [`Self::force_max`]
    /// (0 where nothing moved or no force is left, as [`Self::force_step`]).
    pub fn pointwise_step(&self) -> f64 {
        if self.step_max == 0.0 || self.force_max == 0.0 {
            0.0
        } else {
            self.step_max / self.force_max
        }
    }

    /// η of eq. (10).
    pub fn eta(&self) -> f64 {
        ratio(self.eta_num, 0.5 * self.eta_den)
    }

    /// e_F: relative distance between F and F̂ on contact interfaces. When ŝ has no contact
    /// force anywhere (every point separated) there is nothing to be relative to: e_F is 0 and η
    /// alone measures how far F is from 0.
    pub fn force_error(&self) -> f64 {
        if self.force_den == 0.0 {
            return 0.0;
        }
        ratio(self.force_num, self.force_den)
    }

    /// e_W: relative distance between [W] and [Ŵ] on contact interfaces.
    pub fn jump_error(&self) -> f64 {
        ratio(self.jump_num, self.jump_den)
    }

    /// e_c = max(e_F, e_W).
    pub fn contact_indicator(&self) -> f64 {
        self.force_error().max(self.jump_error())
    }

    /// How far s (the state a run writes) is from ŝ (the state that obeys the interface laws),
    /// relative: max(e_c, η), e_c on the contact interfaces, η over every interface (the perfect
    /// ones too, and contact interfaces whose every point is separated, where e_F is 0). A run is
    /// "Converged" on accuracy a only while this is at most a too: the estimate follows the
    /// contraction of s's forces, and a motion of s that changes no force (a part held only by
    /// contact, off its place) is seen here only.
    pub fn disagreement(&self) -> f64 {
        self.contact_indicator().max(self.eta())
    }
}

crate::multiversion! {
    /// [`InterfaceLocal::march`], compiled for the CPU's widest vector extension.
    fn local_stage_kernel(
        local: &mut InterfaceLocal,
        itf: &Interface,
        s: &InterfaceFields,
        sums: Option<(&[f64], &mut IndicatorSums)>,
    ) {
        local.march(itf, s, sums);
    }
}

/// [`add_column_sums`] of time point i when the sums are wanted (`sums`: the time weights and
/// the sums so far).
#[inline(always)]
fn column_sums(
    sums: &mut Option<(&[f64], &mut IndicatorSums)>,
    itf: &Interface,
    k: f64,
    s: &InterfaceFields,
    hat: &InterfaceFields,
    i: usize,
) {
    if let Some((weights, out)) = sums.as_mut() {
        let n = 2 * itf.n_pairs();
        add_column_sums(
            out,
            &itf.weights,
            k,
            weights[i],
            itf.is_contact(),
            s.columns(i),
            hat.columns(i),
            n,
        );
    }
}

/// Adds time point i's share of the indicator sums of one interface: `s` and `h` are column i of
/// (W_A, W_B, F_A, F_B) of s and ŝ, `n` = 2·n_pairs entries each, `wt` the time weight of t_i,
/// `pair_weights` the lumped mass of each pair.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_column_sums(
    out: &mut IndicatorSums,
    pair_weights: &[f64],
    k: f64,
    wt: f64,
    contact: bool,
    s: [&[f64]; 4],
    h: [&[f64]; 4],
    n: usize,
) {
    let sq = |x: f64| x * x;
    let [sw_a, sw_b, sf_a, sf_b] = s;
    let [hw_a, hw_b, hf_a, hf_b] = h;
    let (sw_a, sw_b, sf_a, sf_b) = (&sw_a[..n], &sw_b[..n], &sf_a[..n], &sf_b[..n]);
    let (hw_a, hw_b, hf_a, hf_b) = (&hw_a[..n], &hw_b[..n], &hf_a[..n], &hf_b[..n]);
    for e in 0..n {
        let m = pair_weights[e / 2] * wt;
        let dw = sq(sw_a[e] - hw_a[e]) + sq(sw_b[e] - hw_b[e]);
        let df = sq(sf_a[e] - hf_a[e]) + sq(sf_b[e] - hf_b[e]);
        out.eta_num += m * (k * dw + df / k);
        let sw = sq(sw_a[e]) + sq(sw_b[e]) + sq(hw_a[e]) + sq(hw_b[e]);
        let sf = sq(sf_a[e]) + sq(sf_b[e]) + sq(hf_a[e]) + sq(hf_b[e]);
        out.eta_den += m * (k * sw + sf / k);
        if contact {
            out.force_num += m * df;
            out.force_den += m * (sq(hf_a[e]) + sq(hf_b[e]));
            let jump = sw_b[e] - sw_a[e];
            let jump_hat = hw_b[e] - hw_a[e];
            out.jump_num += m * sq(jump - jump_hat);
            out.jump_den += m * (sq(jump_hat) + 0.5 * (sq(hw_a[e]) + sq(hw_b[e])));
        }
    }
}

/// Local-stage state of one interface: the last ŝ, contact statuses, and the search directions.
#[derive(Debug, Clone)]
pub struct InterfaceLocal {
    pub index: usize,
    /// k₀ (MPa/mm): k⁻, and k⁺ where no update applies.
    pub k0: f64,
    pub hat: InterfaceFields,
    /// Status per (pair, time) at index p + n_pairs·i (contact interfaces only).
    pub status: Vec<Status>,
    prev_status: Vec<Status>,
    /// [Ŵ]·t of the current time point per pair, carried to the next one (contact only).
    slip: Vec<f64>,
    /// C_N and 𝒯 = |C_T| − f|C_N| of the last two local stages (paper eq. 6), contact only.
    c_n: Mat<f64>,
    c_t: Mat<f64>,
    prev_c_n: Mat<f64>,
    prev_c_t: Mat<f64>,
    have_prev: bool,
    pub directions: Option<ContactDirections>,
    /// Storage of the updated directions, allocated with the interface (contact only), so that
    /// the update inside the iteration loop does not allocate.
    spare: Option<ContactDirections>,
    /// Whether the loads slide the interface away at some time point ([`crate::sliding`]).
    watch: SlidingWatch,
    /// What the watch found after the last [`Self::local_iteration`]: none, or the first time
    /// point beyond what friction holds and the sides that showed it.
    pub sliding: Option<Sliding>,
}

impl InterfaceLocal {
    pub fn new(index: usize, itf: &Interface, k0: f64, n_times: usize) -> Self {
        let np = itf.n_pairs();
        let (ns, nc) = if itf.is_contact() {
            (np * n_times, (np, n_times))
        } else {
            (0, (0, 0))
        };
        Self {
            index,
            k0,
            hat: InterfaceFields::zeros(np, n_times),
            status: vec![Status::Stick; ns],
            prev_status: vec![Status::Stick; ns],
            slip: vec![0.0; if itf.is_contact() { np } else { 0 }],
            c_n: Mat::zeros(nc.0, nc.1),
            c_t: Mat::zeros(nc.0, nc.1),
            prev_c_n: Mat::zeros(nc.0, nc.1),
            prev_c_t: Mat::zeros(nc.0, nc.1),
            have_prev: false,
            directions: None,
            spare: itf.is_contact().then(|| ContactDirections {
                k_n: Mat::zeros(np, n_times),
                k_t: Mat::zeros(np, n_times),
            }),
            watch: SlidingWatch::new(if itf.is_contact() { n_times } else { 0 }),
            sliding: None,
        }
    }

    /// Runs the local stage: ŝ from s along E⁺, pair by pair; contact marches in time (the slip of
    /// t_{i−1} enters t_i) only when friction is positive. Time points are visited in order and
    /// pairs within a time point, so that every pass reads and writes whole columns.
    pub fn local_stage(&mut self, itf: &Interface, s: &InterfaceFields) {
        local_stage_kernel(self, itf, s, None);
    }

    /// [`Self::local_stage`] and then [`Self::indicator_sums`] in one pass over the time points:
    /// each column of s and ŝ is summed as soon as ŝ's column is written, while both are in
    /// cache, instead of in a second pass that reads all eight fields again. The sums are added
    /// in the same order, so they are the same bit for bit. Compiled for the CPU's widest vector
    /// extension ([`crate::simd`]).
    pub fn local_stage_with_sums(
        &mut self,
        itf: &Interface,
        time_weights: &[f64],
        s: &InterfaceFields,
        first: bool,
    ) -> IndicatorSums {
        assert_eq!(time_weights.len(), s.w_a.ncols(), "one time weight per time point");
        let mut out = IndicatorSums::default();
        local_stage_kernel(self, itf, s, Some((time_weights, &mut out)));
        self.add_status_counts(&mut out, first);
        out
    }

    /// The local stage; with `sums`, adds each time point's indicator sums once ŝ's column is
    /// written (time order, so in the order [`Self::indicator_sums`] adds them).
    #[inline(always)]
    fn march(&mut self, itf: &Interface, s: &InterfaceFields, mut sums: Option<(&[f64], &mut IndicatorSums)>) {
        let k0 = self.k0;
        let np = itf.n_pairs();
        let nt = s.w_a.ncols();
        match &itf.kind {
            InterfaceKind::Perfect => {
                let k = k0;
                for i in 0..nt {
                    let [w_a, w_b, f_a, f_b] = s.columns(i);
                    let [h_wa, h_wb, h_fa, h_fb] = self.hat.columns_mut(i);
                    let n = 2 * np;
                    let (w_a, w_b, f_a, f_b) = (&w_a[..n], &w_b[..n], &f_a[..n], &f_b[..n]);
                    let (h_wa, h_wb, h_fa, h_fb) = (&mut h_wa[..n], &mut h_wb[..n], &mut h_fa[..n], &mut h_fb[..n]);
                    // laws::perfect, component by component.
                    for e in 0..n {
                        let w = 0.5 * (w_a[e] + w_b[e]) - 0.5 / k * (f_a[e] + f_b[e]);
                        let f = f_a[e] + k * (w - w_a[e]);
                        h_wa[e] = w;
                        h_wb[e] = w;
                        h_fa[e] = f;
                        h_fb[e] = -f;
                    }
                    column_sums(&mut sums, itf, k0, s, &self.hat, i);
                }
            }
            InterfaceKind::Contact { friction, gap } => {
                std::mem::swap(&mut self.prev_status, &mut self.status);
                std::mem::swap(&mut self.prev_c_n, &mut self.c_n);
                std::mem::swap(&mut self.prev_c_t, &mut self.c_t);
                self.slip.fill(0.0);
                for i in 0..nt {
                    let [w_a, w_b, f_a, f_b] = s.columns(i);
                    let [h_wa, h_wb, h_fa, h_fb] = self.hat.columns_mut(i);
                    let (c_n, c_t) = (self.c_n.col_as_slice_mut(i), self.c_t.col_as_slice_mut(i));
                    let status = &mut self.status[np * i..np * (i + 1)];
                    let k = self
                        .directions
                        .as_ref()
                        .map(|d| (d.k_n.col_as_slice(i), d.k_t.col_as_slice(i)));
                    for (p, (&gap_p, slip)) in gap.iter().zip(self.slip.iter_mut()).enumerate().take(np) {
                        let (k_n, k_t) = match k {
                            Some((k_n, k_t)) => (k_n[p], k_t[p]),
                            None => (self.k0, self.k0),
                        };
                        let point = ContactPoint {
                            k_n,
                            k_t,
                            normal: itf.normal(p),
                            tangent: itf.tangent(p),
                            gap: gap_p,
                            friction: *friction,
                            slip_prev: if *friction > 0.0 { *slip } else { 0.0 },
                        };
                        let (x, y) = (2 * p, 2 * p + 1);
                        let state = PairState {
                            w_a: [w_a[x], w_a[y]],
                            w_b: [w_b[x], w_b[y]],
                            f_a: [f_a[x], f_a[y]],
                            f_b: [f_b[x], f_b[y]],
                        };
                        let r = laws::contact(&point, &state);
                        *slip = r.slip;
                        [h_wa[x], h_wa[y]] = r.hat.w_a;
                        [h_wb[x], h_wb[y]] = r.hat.w_b;
                        [h_fa[x], h_fa[y]] = r.hat.f_a;
                        [h_fb[x], h_fb[y]] = [-r.hat.f_a[0], -r.hat.f_a[1]];
                        status[p] = r.status;
                        c_n[p] = r.c_n;
                        c_t[p] = r.c_t_excess;
                    }
                    column_sums(&mut sums, itf, k0, s, &self.hat, i);
                }
            }
        }
    }

    /// Which sides' parts no support holds in every rigid motion ([`crate::sliding::free_sides`]):
    /// the sides whose forces in s the sliding watch reads. Neither (the default): it never
    /// says the interface slides.
    pub fn watch_sides(&mut self, free: [bool; 2]) {
        self.watch.sides = free;
    }

    /// One iteration's local stage on this interface, as the interface node runs it:
    /// [`Self::local_stage_with_sums`] (`first` at iteration 0), then, when `solver` asks for it,
    /// [`Self::update_directions`]. Returns the indicator sums and whether the directions were
    /// updated.
    pub fn local_iteration(
        &mut self,
        itf: &Interface,
        solver: &SolverParams,
        time_weights: &[f64],
        s: &InterfaceFields,
        first: bool,
    ) -> (IndicatorSums, bool) {
        let sums = self.local_stage_with_sums(itf, time_weights, s, first);
        let mut watch = std::mem::replace(&mut self.watch, SlidingWatch::new(0));
        self.sliding = watch.observe(itf, self, s);
        self.watch = watch;
        let updated = solver.search_direction_update && self.update_directions(itf, solver.alpha, solver.i0);
        (sums, updated)
    }

    /// Search-direction update (paper eq. 6, docs/method.md, "Search-direction update"), done once per contact interface: when the
    /// stagnation ratios I_N = ‖C_N − C_N,prev‖/‖C_N,prev‖ and I_T (same on 𝒯) are both below
    /// `i0`, set k_N = k_T = k₀(1 − α) at separated points and k_T = k₀(1 − α) at slipping ones.
    /// Returns true when the update happened at this call.
    pub fn update_directions(&mut self, itf: &Interface, alpha: f64, i0: f64) -> bool {
        if !itf.is_contact() || self.directions.is_some() {
            return false;
        }
        if !self.have_prev {
            self.have_prev = true;
            return false;
        }
        let rel = |a: &Mat<f64>, b: &Mat<f64>| {
            let (mut num, mut den) = (0.0, 0.0);
            for i in 0..a.ncols() {
                for p in 0..a.nrows() {
                    num += (a[(p, i)] - b[(p, i)]).powi(2);
                    den += b[(p, i)].powi(2);
                }
            }
            if num == 0.0 {
                0.0
            } else {
                (num / den).sqrt()
            }
        };
        let (i_n, i_t) = (rel(&self.c_n, &self.prev_c_n), rel(&self.c_t, &self.prev_c_t));
        if !(i_n < i0 && i_t < i0) {
            return false;
        }
        let np = itf.n_pairs();
        let nt = self.c_n.ncols();
        let low = self.k0 * (1.0 - alpha);
        let Some(mut d) = self.spare.take() else {
            return false;
        };
        debug_assert_eq!((d.k_n.nrows(), d.k_n.ncols()), (np, nt), "directions shape");
        d.k_n.fill(self.k0);
        d.k_t.fill(self.k0);
        for i in 0..nt {
            for p in 0..np {
                match self.status[p + np * i] {
                    Status::Separated => {
                        d.k_n[(p, i)] = low;
                        d.k_t[(p, i)] = low;
                    }
                    Status::Slip => d.k_t[(p, i)] = low,
                    Status::Stick => {}
                }
            }
        }
        self.directions = Some(d);
        true
    }

    /// Indicator partial sums of this interface for s (the last linear stage) and ŝ (this local stage).
    pub fn indicator_sums(
        &self,
        itf: &Interface,
        time_weights: &[f64],
        s: &InterfaceFields,
        first: bool,
    ) -> IndicatorSums {
        assert_eq!(time_weights.len(), s.w_a.ncols(), "one time weight per time point");
        let mut out = IndicatorSums::default();
        let mut sums = Some((time_weights, &mut out));
        for i in 0..time_weights.len() {
            column_sums(&mut sums, itf, self.k0, s, &self.hat, i);
        }
        self.add_status_counts(&mut out, first);
        out
    }

    /// Counts the contact points per status and, after the first local stage, those whose status
    /// changed.
    fn add_status_counts(&self, out: &mut IndicatorSums, first: bool) {
        for (k, st) in self.status.iter().enumerate() {
            out.counts[*st as usize] += 1;
            if !first && *st != self.prev_status[k] {
                out.status_changes += 1;
            }
        }
    }

    /// q̂ = F̂ + k⁻Ŵ of one side, written into rows `offset..offset + 2·n_pairs` of `out`.
    pub fn q_hat_into(&self, side_a: bool, mut out: MatMut<'_, f64>, offset: usize) {
        let (w, f) = if side_a {
            (&self.hat.w_a, &self.hat.f_a)
        } else {
            (&self.hat.w_b, &self.hat.f_b)
        };
        let k = self.k0;
        for i in 0..w.ncols() {
            let q = &mut out
                .rb_mut()
                .col_mut(i)
                .try_as_col_major_mut()
                .expect("q̂ has unit row stride")
                .as_slice_mut()[offset..offset + w.nrows()];
            for ((q, f), w) in q.iter_mut().zip(f.col_as_slice(i)).zip(w.col_as_slice(i)) {
                *q = f + k * w;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pointwise step is the largest change of one entry over every pair, component and time
    /// point (whatever its weight), the force scale the largest entry; the sums keep their
    /// weighted meaning, and combining sides takes the maxima.
    #[test]
    fn force_step_sums_keep_the_largest_entry() {
        let old = Mat::<f64>::from_fn(4, 3, |r, c| (r + 3 * c) as f64);
        let mut new = old.clone();
        new[(3, 1)] += 5.0; // pair 1, y, time point 1: |Δ| = 5
        new[(0, 2)] -= 2.0; // pair 0, x, time point 2: |Δ| = 2
        let (pairs, times) = ([0.5, 0.25], [0.5, 1.0, 0.5]);
        let st = force_step_sums(&pairs, &times, old.as_ref(), new.as_ref());
        assert_eq!(st.max_step, 5.0);
        assert_eq!(st.max_force, 11.0); // entry (3, 1) = 3 + 3 + 5
        assert_eq!(st.num, 1.0 * 0.25 * 25.0 + 0.5 * 0.5 * 4.0);
        let mut both = st;
        both.add(&StepSums {
            num: 1.0,
            den: 2.0,
            max_step: 7.0,
            max_force: 3.0,
        });
        assert_eq!((both.max_step, both.max_force, both.num), (7.0, 11.0, st.num + 1.0));
        let mut nan = new.clone();
        nan[(1, 0)] = f64::NAN;
        assert!(force_step_sums(&pairs, &times, old.as_ref(), nan.as_ref())
            .max_step
            .is_nan());
    }

    /// The largest traction difference against a reference, relative to the reference's largest
    /// traction, and where it is.
    #[test]
    fn pointwise_error_finds_the_worst_point() {
        let model = crate::fixtures::two_blocks_contact();
        let itf = &model.interfaces[0];
        let nt = model.time.n_points();
        let mut reference = InterfaceFields::zeros(itf.n_pairs(), nt);
        for i in 0..nt {
            for p in 0..itf.n_pairs() {
                reference.f_a[(2 * p, i)] = -10.0 * (i as f64 + 1.0);
                reference.f_b[(2 * p, i)] = 10.0 * (i as f64 + 1.0);
            }
        }
        let mut s = reference.clone();
        assert_eq!(
            pointwise_traction_error(&model.interfaces, &[s.clone()], &[reference.clone()]).error,
            0.0
        );
        let (p, i) = (itf.n_pairs() - 1, nt - 1);
        s.f_b[(2 * p + 1, i)] += 0.5; // a traction's y component on side b off by 0.5
        let e = pointwise_traction_error(&model.interfaces, &[s], &[reference.clone()]);
        assert!((e.error - 0.5 / (10.0 * nt as f64)).abs() < 1e-15, "{e:?}");
        assert_eq!((e.interface, e.pair, e.time_point), (0, p, i));
        let zero = InterfaceFields::zeros(itf.n_pairs(), nt);
        assert_eq!(
            pointwise_traction_error(&model.interfaces, &[reference], &[zero]).error,
            f64::INFINITY
        );
    }

    /// The contact indicator reads only s, ŝ, M and the time weights: evaluating it on the same
    /// pair (s, ŝ) with k₀ and 100 k₀ gives the same value, while η changes.
    #[test]
    fn contact_indicator_does_not_depend_on_k() {
        let model = crate::fixtures::two_blocks_contact();
        let itf = &model.interfaces[0];
        let nt = model.time.n_points();
        let mut s = InterfaceFields::zeros(itf.n_pairs(), nt);
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for m in [&mut s.w_a, &mut s.w_b] {
            for j in 0..nt {
                for r in 0..m.nrows() {
                    m[(r, j)] = 0.01 * rnd();
                }
            }
        }
        for m in [&mut s.f_a, &mut s.f_b] {
            for j in 0..nt {
                for r in 0..m.nrows() {
                    m[(r, j)] = 10.0 * rnd();
                }
            }
        }
        let w = model.time.trapezoid_weights();
        let mut a = InterfaceLocal::new(0, itf, 250.0, nt);
        a.local_stage(itf, &s);
        let sums_a = a.indicator_sums(itf, &w, &s, true);
        // Same ŝ, read with another k.
        let mut b = InterfaceLocal::new(0, itf, 25_000.0, nt);
        b.hat = a.hat.clone();
        let sums_b = b.indicator_sums(itf, &w, &s, true);
        assert!(sums_a.contact_indicator() > 0.0);
        assert_eq!(sums_a.contact_indicator(), sums_b.contact_indicator());
        assert_eq!(sums_a.force_error(), sums_b.force_error());
        assert_eq!(sums_a.jump_error(), sums_b.jump_error());
        assert!(
            (sums_a.eta() - sums_b.eta()).abs() > 1e-3 * sums_a.eta(),
            "η depends on k"
        );

        // The fused pass gives the same ŝ, statuses and sums as the local stage followed by the
        // indicator pass, bit for bit (same operations, same order), on a second iteration too
        // (status changes counted against the first).
        let mut fused = InterfaceLocal::new(0, itf, 250.0, nt);
        let mut apart = InterfaceLocal::new(0, itf, 250.0, nt);
        for (round, first) in [(0, true), (1, false)] {
            if round == 1 {
                for m in [&mut s.f_a, &mut s.f_b] {
                    for j in 0..nt {
                        for r in 0..m.nrows() {
                            m[(r, j)] += 5.0 * rnd();
                        }
                    }
                }
            }
            let one = fused.local_stage_with_sums(itf, &w, &s, first);
            apart.local_stage(itf, &s);
            let two = apart.indicator_sums(itf, &w, &s, first);
            assert_eq!(fused.hat, apart.hat);
            assert_eq!(fused.status, apart.status);
            assert_eq!(format!("{one:?}"), format!("{two:?}"));
            assert!(one.eta_num > 0.0 && one.force_num > 0.0 && one.jump_num > 0.0);
        }
        assert!(fused.local_stage_with_sums(itf, &w, &s, false).status_changes == 0);

        // And on a perfect interface.
        let mut glued = itf.clone();
        glued.kind = InterfaceKind::Perfect;
        let mut fused = InterfaceLocal::new(0, &glued, 250.0, nt);
        let mut apart = InterfaceLocal::new(0, &glued, 250.0, nt);
        let one = fused.local_stage_with_sums(&glued, &w, &s, true);
        apart.local_stage(&glued, &s);
        assert_eq!(fused.hat, apart.hat);
        assert_eq!(
            format!("{one:?}"),
            format!("{:?}", apart.indicator_sums(&glued, &w, &s, true))
        );
        assert!(one.eta_num > 0.0 && one.force_num == 0.0);
    }
}
