//! Anderson acceleration of the LATIN fixed point (docs/method.md, "Relaxation and Anderson mixing").
//!
//! The LATIN iteration is a fixed point s ← G(s): s = (W, F) is the boundary state after a
//! linear stage, G the local stage followed by the next linear stage. Plain relaxation takes
//! s_{n+1} = s_n + μ r_n with the residual r_n = G(s_n) − s_n. Anderson mixing of type II over
//! the last m iterates takes
//!
//! s_{n+1} = s_n + μ r_n − Σ_i γ_i (Δs_i + μ Δr_i),   γ = argmin ‖r_n − Σ_i γ_i Δr_i‖,
//!
//! with Δs_i, Δr_i the differences of consecutive iterates and residuals. A fixed point of the
//! mixed iteration is one of G, so the limit is the plain run's. The least-squares norm is the
//! plain Euclidean norm of the force part F only (weighting W as η does was
//! measured to gain nothing).
//!
//! The state is spread over subdomains, so the work is split in two:
//! - [`AndersonHistory`] (one per subdomain, buffers allocated once) keeps the last m + 1
//!   iterates' s + μ r (W and F) and r (F only) in a ring, whose consecutive differences are the
//!   D_i = Δs_i + μ Δr_i and Δr_i (formed on the fly: a record writes one iterate, not the three
//!   differences and the three fields they are taken from), and gives its share of
//!   the least-squares problem as [`GramPartials`]: the k × k Gram matrix Δr_iᵀΔr_j (kept up to
//!   date one new column per iteration), the projections Δr_iᵀ r_n and ‖r_n‖²;
//! - [`AndersonCoordinator`] (one node) gets the partials summed over every subdomain in a fixed
//!   order and returns the [`AndersonStep`]: the coefficients γ, a plain relaxation step when the
//!   last mixed step made the residual grow (the safeguard), or a restart of every history when
//!   the least-squares problem is ill-conditioned.

use crate::simd::dot;
use faer::{Mat, MatMut, MatRef};

mod coordinator;
#[cfg(test)]
mod tests;

pub use coordinator::{solve_least_squares, AndersonCoordinator, AndersonCounts};

/// Largest condition number of the Gram matrix, scaled to a unit diagonal, that the coordinator
/// solves; above it the histories restart. The Gram matrix squares the condition of the
/// differences, so this allows differences conditioned up to 1e5 and keeps the normal equations
/// at ≥ 5 significant digits, which is all a mixing step needs.
pub const MAX_CONDITION: f64 = 1e10;

/// Largest window a history keeps (the scene accepts `anderson_window` ≤ 50).
pub const MAX_SLOTS: usize = 50;

/// Shares of one part of the state in the least-squares problem, oldest difference first.
#[derive(Debug, Clone, PartialEq)]
pub struct GramPartials {
    /// Number of stored differences k.
    pub k: usize,
    /// Δr_iᵀΔr_j, k × k, column-major.
    pub gram: Vec<f64>,
    /// Δr_iᵀ r_n, length k.
    pub projection: Vec<f64>,
    /// ‖r_n‖².
    pub residual2: f64,
}

impl GramPartials {
    pub fn zeros(k: usize) -> Self {
        Self {
            k,
            gram: vec![0.0; k * k],
            projection: vec![0.0; k],
            residual2: 0.0,
        }
    }

    /// Adds another part's shares (same k).
    pub fn add(&mut self, other: &GramPartials) {
        assert_eq!(self.k, other.k, "partials over different histories");
        self.gram.iter_mut().zip(&other.gram).for_each(|(a, b)| *a += b);
        self.projection
            .iter_mut()
            .zip(&other.projection)
            .for_each(|(a, b)| *a += b);
        self.residual2 += other.residual2;
    }
}

/// What every part does with its state this iteration.
#[derive(Debug, Clone, PartialEq)]
pub enum AndersonStep {
    /// s ← s + μ r − Σ γ_i D_i (γ oldest first).
    Mix(Vec<f64>),
    /// s ← s + μ r: the previous mixed step made the residual grow.
    Plain,
    /// s ← s + μ r and every history forgets its differences: the least-squares problem is
    /// ill-conditioned (or not finite, or the fixed-point map changed).
    Restart,
}

/// One part's history: a ring of the last m + 1 iterates, allocated once.
///
/// Slot t of the ring holds one iterate's s + μ r (W and F) and r_F. A stored difference is named
/// by the slot of its newer iterate t: D = p[t] − p[t − 1] and Δr = r_F[t] − r_F[t − 1] (slots
/// modulo m + 1), each computed where it is used, so its value is the one a stored difference
/// would hold.
pub struct AndersonHistory {
    window: usize,
    /// Slots of the ring: window + 1.
    ring: usize,
    mu: f64,
    rows: usize,
    cols: usize,
    /// s + μ r, W and F parts, and r_F, per slot.
    p_w: Vec<Mat<f64>>,
    p_f: Vec<Mat<f64>>,
    r_f: Vec<Mat<f64>>,
    /// Δr_iᵀΔr_j by difference (ring × ring).
    gram: Vec<f64>,
    /// Δr_iᵀ r_n by difference and ‖r_n‖², of the last recorded iterate (computed by `record` in
    /// the same pass over the columns as the iterate).
    projection: Vec<f64>,
    residual2: f64,
    /// One column of every stored Δr_i, formed in a record's pass (window × rows).
    dr_column: Vec<f64>,
    has_last: bool,
    len: usize,
    /// Slot of the last recorded iterate.
    newest: usize,
    /// The difference the last record stored (None: it stored none).
    last_slot: Option<usize>,
    /// Coordinates mixed beside the state ([`AndersonHistory::with_coordinates`]).
    coords: Option<Coordinates>,
}

/// Coordinates of the state on a basis of its own (a PGD state's time functions), mixed with the
/// same coefficients as the state and not part of the least-squares problem: D_i (stored, by the
/// ring slot that names the difference) and s + μ r in coordinates. A slot's rows past
/// `rows[slot]` (`p_rows`) are zeros: a basis only grows between compressions, and a compression
/// rotates every stored coordinate.
struct Coordinates {
    d: Vec<Mat<f64>>,
    rows: Vec<usize>,
    p: Mat<f64>,
    p_rows: usize,
}

/// One record's pass over the columns ([`AndersonHistory::begin_record`]): the slot it writes,
/// whether it stores a difference, the stored slots it sums against (the first `n_slots`), and
/// the sums so far.
struct RecordPass {
    slot: usize,
    push: bool,
    slots: [usize; MAX_SLOTS],
    n_slots: usize,
    gram_new: [f64; MAX_SLOTS],
    projection: [f64; MAX_SLOTS],
    residual2: f64,
}

impl AndersonHistory {
    /// A history of `window` ≥ 1 differences of states with W and F of `rows` × `cols`, mixed with
    /// damping `mu`.
    pub fn new(window: usize, mu: f64, rows: usize, cols: usize) -> Self {
        assert!(
            (1..=MAX_SLOTS).contains(&window),
            "Anderson window must be in 1..={MAX_SLOTS}"
        );
        let ring = window + 1;
        let z = || (0..ring).map(|_| Mat::<f64>::zeros(rows, cols)).collect();
        Self {
            window,
            ring,
            mu,
            rows,
            cols,
            p_w: z(),
            p_f: z(),
            r_f: z(),
            gram: vec![0.0; ring * ring],
            projection: vec![0.0; ring],
            residual2: 0.0,
            dr_column: vec![0.0; window * rows],
            has_last: false,
            len: 0,
            newest: 0,
            last_slot: None,
            coords: None,
        }
    }

    /// Also keeps coordinates of up to `capacity` rows (× the state's columns) beside the state:
    /// [`Self::record_coordinates`], [`Self::apply_coordinates`], [`Self::rotate_coordinates`].
    pub fn with_coordinates(mut self, capacity: usize) -> Self {
        let z = || Mat::<f64>::zeros(capacity, self.cols);
        self.coords = Some(Coordinates {
            d: (0..self.ring).map(|_| z()).collect(),
            rows: vec![0; self.ring],
            p: z(),
            p_rows: 0,
        });
        self
    }

    /// Records the coordinates of the iterate (`state`) and of its image (`image`), both
    /// p × cols, right after [`Self::record`] or [`Self::record_sum`] recorded the same iterate's
    /// fields: stores s + μ r in coordinates and its difference with the previous record's (whose
    /// rows past its own p count as zeros).
    pub fn record_coordinates(&mut self, state: MatRef<'_, f64>, image: MatRef<'_, f64>) {
        let (mu, last_slot) = (self.mu, self.last_slot);
        let c = self
            .coords
            .as_mut()
            .expect("called on a history built with_coordinates (a caller's bug otherwise)");
        let rows = state.nrows();
        assert!(rows <= c.p.nrows() && rows >= c.p_rows, "coordinates rows");
        assert_eq!(
            (image.nrows(), image.ncols(), state.ncols()),
            (rows, self.cols, self.cols)
        );
        for j in 0..self.cols {
            for r in 0..rows {
                let p = state[(r, j)] + mu * (image[(r, j)] - state[(r, j)]);
                if let Some(slot) = last_slot {
                    let old = if r < c.p_rows { c.p[(r, j)] } else { 0.0 };
                    c.d[slot][(r, j)] = p - old;
                }
                c.p[(r, j)] = p;
            }
        }
        if let Some(slot) = last_slot {
            c.rows[slot] = rows;
        }
        c.p_rows = rows;
    }

    /// Writes the next iterate's coordinates into `out` (p × cols, p of the last record) for
    /// `step`, with the coefficients [`Self::apply`] mixes the fields with; a restart forgets the
    /// differences here (do not call [`Self::apply`] for the same step as well).
    pub fn apply_coordinates(&mut self, step: &AndersonStep, mut out: MatMut<'_, f64>) {
        let gamma = self.begin_step(step);
        let slots = self.stored_slots();
        let c = self
            .coords
            .as_ref()
            .expect("called on a history built with_coordinates (a caller's bug otherwise)");
        assert_eq!((out.nrows(), out.ncols()), (c.p_rows, self.cols), "coordinates shape");
        for j in 0..self.cols {
            for r in 0..c.p_rows {
                let mut x = c.p[(r, j)];
                for (i, &g) in gamma.iter().enumerate() {
                    let s = slots[i];
                    if r < c.rows[s] {
                        x -= g * c.d[s][(r, j)];
                    }
                }
                out[(r, j)] = x;
            }
        }
    }

    /// A change of basis of coordinates `first .. first + old`: every stored coordinate's rows
    /// there become Uᵀ times them (`u` is old × keep), in rows `first .. first + keep`.
    pub fn rotate_coordinates(&mut self, first: usize, old: usize, u: MatRef<'_, f64>) {
        let Some(c) = self.coords.as_mut() else {
            return;
        };
        let keep = u.ncols();
        assert_eq!(u.nrows(), old, "rotation rows");
        let mats = c.d.iter_mut().zip(c.rows.iter_mut()).chain([(&mut c.p, &mut c.p_rows)]);
        for (mat, rows) in mats {
            if *rows <= first {
                continue;
            }
            let avail = (*rows - first).min(old);
            let rotated = u.subrows(0, avail).transpose() * mat.as_ref().subrows(first, avail);
            mat.as_mut().subrows_mut(first, keep).copy_from(&rotated);
            *rows = first + keep;
        }
    }

    /// Number of stored differences.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The i-th stored difference (the slot of its newer iterate), oldest first.
    #[inline(always)]
    fn slot(&self, i: usize) -> usize {
        (self.newest + 1 + self.ring - self.len + i) % self.ring
    }

    /// The slot before `slot` in the ring: the older iterate of difference `slot`.
    #[inline(always)]
    fn before(&self, slot: usize) -> usize {
        (slot + self.ring - 1) % self.ring
    }

    /// Records the iterate s = (s_w, s_f) and its image g = G(s): stores s + μ r and r_F
    /// (r = g − s) in the ring's next slot, which from the second call on adds their differences
    /// with the previous call's to the stored ones (the oldest dropped past m). The new column of
    /// the Gram matrix, the projections Δr_iᵀ r_n and ‖r_n‖² are summed in the same
    /// pass, column by column while the column is in cache (each dot product is the sum over
    /// columns of the columns' dot products, as [`Self::partials`] reports them).
    pub fn record(&mut self, s_w: &Mat<f64>, s_f: &Mat<f64>, g_w: &Mat<f64>, g_f: &Mat<f64>) {
        record_kernel(self, s_w, s_f, [g_w, g_w], [g_f, g_f], false);
    }

    /// [`Self::record`] with the image given in two parts, G(s) = g + h (s₁ + s₂ of the linear
    /// stage), added on the fly instead of in a pass of its own.
    pub fn record_sum(&mut self, s_w: &Mat<f64>, s_f: &Mat<f64>, g_w: [&Mat<f64>; 2], g_f: [&Mat<f64>; 2]) {
        record_kernel(self, s_w, s_f, g_w, g_f, true);
    }

    #[inline(always)]
    fn record_with<const SUM: bool>(
        &mut self,
        s_w: &Mat<f64>,
        s_f: &Mat<f64>,
        g_w: [&Mat<f64>; 2],
        g_f: [&Mat<f64>; 2],
    ) {
        for m in [s_w, s_f, g_w[0], g_w[1], g_f[0], g_f[1]] {
            assert_eq!((m.nrows(), m.ncols()), (self.rows, self.cols), "state shape");
        }
        let image = |a: &[f64], b: &[f64], r: usize| if SUM { a[r] + b[r] } else { a[r] };
        let mu = self.mu;
        let mut pass = self.begin_record();
        let slot = pass.slot;
        for j in 0..self.cols {
            let (sw, gw, hw) = (s_w.col_as_slice(j), g_w[0].col_as_slice(j), g_w[1].col_as_slice(j));
            let pw = self.p_w[slot].col_as_slice_mut(j);
            for r in 0..self.rows {
                pw[r] = sw[r] + mu * (image(gw, hw, r) - sw[r]);
            }
            let (sf, gf, hf) = (s_f.col_as_slice(j), g_f[0].col_as_slice(j), g_f[1].col_as_slice(j));
            let pf = self.p_f[slot].col_as_slice_mut(j);
            let rf = self.r_f[slot].col_as_slice_mut(j);
            for r in 0..self.rows {
                let res = image(gf, hf, r) - sf[r];
                pf[r] = sf[r] + mu * res;
                rf[r] = res;
            }
            self.accumulate_column(j, &mut pass);
        }
        self.end_record(&pass);
    }

    /// Records an iterate whose state is mixed in coordinates only ([`Self::record_coordinates`],
    /// [`Self::apply_coordinates`]; never [`Self::apply`] after it): its force residual
    /// r_F = G(s)_F − s_F alone, for the least-squares problem, in one pass that also sums the
    /// new Gram column, the projections and ‖r_F‖².
    pub fn record_residual(&mut self, r_f: &Mat<f64>) {
        assert_eq!((r_f.nrows(), r_f.ncols()), (self.rows, self.cols), "residual shape");
        let mut pass = self.begin_record();
        for j in 0..self.cols {
            self.r_f[pass.slot]
                .col_as_slice_mut(j)
                .copy_from_slice(r_f.col_as_slice(j));
            self.accumulate_column(j, &mut pass);
        }
        self.end_record(&pass);
    }

    /// The stored slots oldest first (the first `len` entries; the rest 0).
    fn stored_slots(&self) -> [usize; MAX_SLOTS] {
        std::array::from_fn(|i| if i < self.len { self.slot(i) } else { 0 })
    }

    /// Starts a record's pass: advances the ring if the record stores a difference (it has a
    /// previous iterate; the slot it writes then held the oldest iterate, which only the dropped
    /// difference used, or none), and returns the slot it writes, the stored differences and
    /// empty sums.
    fn begin_record(&mut self) -> RecordPass {
        let push = self.has_last;
        if push {
            self.len = (self.len + 1).min(self.window);
            self.newest = (self.newest + 1) % self.ring;
        }
        let slot = self.newest;
        RecordPass {
            slot,
            push,
            slots: self.stored_slots(),
            n_slots: if push { self.len } else { 0 },
            gram_new: [-0.0; MAX_SLOTS],
            projection: [-0.0; MAX_SLOTS],
            residual2: -0.0,
        }
    }

    /// Adds column j's share of the new Gram column Δr_newᵀΔr_i, the projections Δr_iᵀ r and ‖r‖²
    /// (column j of the new iterate written): forms column j of every stored Δr_i, newest last,
    /// then takes the dot products.
    #[inline(always)]
    fn accumulate_column(&mut self, j: usize, pass: &mut RecordPass) {
        let rows = self.rows;
        let n = pass.n_slots;
        for (i, &other) in pass.slots[..n].iter().enumerate() {
            let (newer, older) = (
                self.r_f[other].col_as_slice(j),
                self.r_f[self.before(other)].col_as_slice(j),
            );
            let d = &mut self.dr_column[i * rows..(i + 1) * rows];
            for r in 0..rows {
                d[r] = newer[r] - older[r];
            }
        }
        let rf = self.r_f[pass.slot].col_as_slice(j);
        if n > 0 {
            let drf = &self.dr_column[(n - 1) * rows..n * rows];
            for i in 0..n {
                let d_other = &self.dr_column[i * rows..(i + 1) * rows];
                pass.gram_new[i] += dot(drf, d_other);
                pass.projection[i] += dot(d_other, rf);
            }
        }
        pass.residual2 += dot(rf, rf);
    }

    /// Stores a record's sums.
    fn end_record(&mut self, pass: &RecordPass) {
        let slot = pass.slot;
        self.has_last = true;
        self.last_slot = pass.push.then_some(slot);
        self.residual2 = pass.residual2;
        for (i, &other) in pass.slots[..pass.n_slots].iter().enumerate() {
            self.gram[slot * self.ring + other] = pass.gram_new[i];
            self.gram[other * self.ring + slot] = pass.gram_new[i];
            self.projection[other] = pass.projection[i];
        }
    }

    /// This part's shares of the least-squares problem of the last recorded iterate.
    pub fn partials(&self) -> GramPartials {
        let k = self.len;
        let mut p = GramPartials::zeros(k);
        for i in 0..k {
            let si = self.slot(i);
            for j in 0..k {
                p.gram[j * k + i] = self.gram[self.slot(j) * self.ring + si];
            }
            p.projection[i] = self.projection[si];
        }
        p.residual2 = self.residual2;
        p
    }

    /// Forgets every stored difference (the last iterate stays, so the next record starts anew).
    pub fn restart(&mut self) {
        self.len = 0;
    }

    /// The coefficients of `step` (none for a plain step), after forgetting the differences on a
    /// restart.
    fn begin_step<'s>(&mut self, step: &'s AndersonStep) -> &'s [f64] {
        if let AndersonStep::Restart = step {
            self.restart();
        }
        match step {
            AndersonStep::Mix(gamma) => {
                assert_eq!(gamma.len(), self.len, "one coefficient per stored difference");
                gamma
            }
            AndersonStep::Plain | AndersonStep::Restart => &[],
        }
    }

    /// Writes the next iterate into (s_w, s_f) for `step` (of the last recorded iterate).
    pub fn apply(&mut self, step: &AndersonStep, s_w: &mut Mat<f64>, s_f: &mut Mat<f64>) {
        let gamma = self.begin_step(step);
        apply_kernel(self, gamma, s_w, s_f);
    }

    #[inline(always)]
    fn apply_with(&self, gamma: &[f64], s_w: &mut Mat<f64>, s_f: &mut Mat<f64>) {
        // s = s + μ r − Σ γ_i D_i, oldest difference first, column by column (the column of s
        // stays in cache over the k differences), D_i = p[t] − p[t − 1] formed on the fly.
        for j in 0..self.cols {
            for (s, p) in [(&mut *s_w, &self.p_w), (&mut *s_f, &self.p_f)] {
                let x = s.col_as_slice_mut(j);
                x.copy_from_slice(p[self.newest].col_as_slice(j));
                let mut older = p[self.before(self.slot(0))].col_as_slice(j);
                for (i, &g) in gamma.iter().enumerate() {
                    let newer = p[self.slot(i)].col_as_slice(j);
                    for ((x, a), b) in x.iter_mut().zip(newer).zip(older) {
                        *x -= g * (a - b);
                    }
                    older = newer;
                }
            }
        }
    }
}

crate::multiversion! {
    /// [`AndersonHistory::record`] (`sum` false) or [`AndersonHistory::record_sum`], compiled for
    /// the CPU's widest vector extension.
    fn record_kernel(
        h: &mut AndersonHistory,
        s_w: &Mat<f64>,
        s_f: &Mat<f64>,
        g_w: [&Mat<f64>; 2],
        g_f: [&Mat<f64>; 2],
        sum: bool,
    ) {
        if sum {
            h.record_with::<true>(s_w, s_f, g_w, g_f);
        } else {
            h.record_with::<false>(s_w, s_f, g_w, g_f);
        }
    }
}

crate::multiversion! {
    /// The pass of [`AndersonHistory::apply`], compiled for the CPU's widest vector extension.
    fn apply_kernel(h: &AndersonHistory, gamma: &[f64], s_w: &mut Mat<f64>, s_f: &mut Mat<f64>) {
        h.apply_with(gamma, s_w, s_f);
    }
}
