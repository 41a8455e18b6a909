//! Anderson acceleration of the LATIN fixed point (DESIGN §3, "Acceleration").
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
//! plain Euclidean norm of the force part F only (DESIGN measured that weighting W like η gains
//! nothing).
//!
//! The state is spread over subdomains, so the work is split in two:
//! - [`AndersonHistory`] (one per subdomain, buffers allocated once) keeps the differences
//!   D_i = Δs_i + μ Δr_i (W and F) and Δr_i (F only) in a ring of m slots, and gives its share of
//!   the least-squares problem as [`GramPartials`]: the k × k Gram matrix Δr_iᵀΔr_j (kept up to
//!   date one new column per iteration), the projections Δr_iᵀ r_n and ‖r_n‖²;
//! - [`AndersonCoordinator`] (one node) gets the partials summed over every subdomain in a fixed
//!   order and returns the [`AndersonStep`]: the coefficients γ, a plain relaxation step when the
//!   last mixed step made the residual grow (the safeguard), or a restart of every history when
//!   the least-squares problem is ill-conditioned.

use crate::simd::dot;
use faer::{Mat, MatMut, MatRef};

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

/// One part's history: ring buffers of m differences, allocated once.
pub struct AndersonHistory {
    window: usize,
    mu: f64,
    rows: usize,
    cols: usize,
    /// D_i = Δ(s + μ r): W and F parts, per slot.
    d_w: Vec<Mat<f64>>,
    d_f: Vec<Mat<f64>>,
    /// Δr_i, F part, per slot.
    dr_f: Vec<Mat<f64>>,
    /// Δr_iᵀΔr_j by slot (window × window).
    gram: Vec<f64>,
    /// Δr_iᵀ r_n by slot and ‖r_n‖², of the last recorded iterate (computed by `record` in the
    /// same pass over the columns as the differences).
    projection: Vec<f64>,
    residual2: f64,
    /// s + μ r and r_F of the last recorded iterate.
    p_w: Mat<f64>,
    p_f: Mat<f64>,
    r_f: Mat<f64>,
    has_last: bool,
    len: usize,
    next: usize,
    /// Slot the last record wrote its difference to (None: it stored none).
    last_slot: Option<usize>,
    /// Coordinates mixed beside the state ([`AndersonHistory::with_coordinates`]).
    coords: Option<Coordinates>,
}

/// Coordinates of the state on a basis of its own (a PGD state's time functions), mixed with the
/// same coefficients as the state and not part of the least-squares problem: D_i and s + μ r in
/// coordinates. A slot's rows past `rows[slot]` (`p_rows`) are zeros: a basis only grows between
/// compressions, and a compression rotates every stored coordinate.
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
        let z = || Mat::<f64>::zeros(rows, cols);
        Self {
            window,
            mu,
            rows,
            cols,
            d_w: (0..window).map(|_| z()).collect(),
            d_f: (0..window).map(|_| z()).collect(),
            dr_f: (0..window).map(|_| z()).collect(),
            gram: vec![0.0; window * window],
            projection: vec![0.0; window],
            residual2: 0.0,
            p_w: z(),
            p_f: z(),
            r_f: z(),
            has_last: false,
            len: 0,
            next: 0,
            last_slot: None,
            coords: None,
        }
    }

    /// Also keeps coordinates of up to `capacity` rows (× the state's columns) beside the state:
    /// [`Self::record_coordinates`], [`Self::apply_coordinates`], [`Self::rotate_coordinates`].
    pub fn with_coordinates(mut self, capacity: usize) -> Self {
        let z = || Mat::<f64>::zeros(capacity, self.cols);
        self.coords = Some(Coordinates {
            d: (0..self.window).map(|_| z()).collect(),
            rows: vec![0; self.window],
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
        let c = self.coords.as_mut().expect("history without coordinates");
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
        let c = self.coords.as_ref().expect("history without coordinates");
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

    /// Slot of the i-th stored difference, oldest first.
    #[inline(always)]
    fn slot(&self, i: usize) -> usize {
        (self.next + self.window - self.len + i) % self.window
    }

    /// Records the iterate s = (s_w, s_f) and its image g = G(s): stores s + μ r and r_F
    /// (r = g − s) and, from the second call on, their differences with the previous call's. The
    /// new column of the Gram matrix, the projections Δr_iᵀ r_n and ‖r_n‖² are summed in the same
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
        let (slot, push) = (pass.slot, pass.push);
        for j in 0..self.cols {
            let (sw, gw, hw) = (s_w.col_as_slice(j), g_w[0].col_as_slice(j), g_w[1].col_as_slice(j));
            let pw = self.p_w.col_as_slice_mut(j);
            if push {
                let dw = self.d_w[slot].col_as_slice_mut(j);
                for r in 0..self.rows {
                    let p = sw[r] + mu * (image(gw, hw, r) - sw[r]);
                    dw[r] = p - pw[r];
                    pw[r] = p;
                }
            } else {
                for r in 0..self.rows {
                    pw[r] = sw[r] + mu * (image(gw, hw, r) - sw[r]);
                }
            }
            let (sf, gf, hf) = (s_f.col_as_slice(j), g_f[0].col_as_slice(j), g_f[1].col_as_slice(j));
            let pf = self.p_f.col_as_slice_mut(j);
            let rf = self.r_f.col_as_slice_mut(j);
            if push {
                let df = self.d_f[slot].col_as_slice_mut(j);
                let drf = self.dr_f[slot].col_as_slice_mut(j);
                for r in 0..self.rows {
                    let res = image(gf, hf, r) - sf[r];
                    let p = sf[r] + mu * res;
                    df[r] = p - pf[r];
                    drf[r] = res - rf[r];
                    pf[r] = p;
                    rf[r] = res;
                }
            } else {
                for r in 0..self.rows {
                    let res = image(gf, hf, r) - sf[r];
                    pf[r] = sf[r] + mu * res;
                    rf[r] = res;
                }
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
        let (slot, push) = (pass.slot, pass.push);
        for j in 0..self.cols {
            let new = r_f.col_as_slice(j);
            let rf = self.r_f.col_as_slice_mut(j);
            if push {
                let drf = self.dr_f[slot].col_as_slice_mut(j);
                for r in 0..self.rows {
                    drf[r] = new[r] - rf[r];
                    rf[r] = new[r];
                }
            } else {
                rf.copy_from_slice(new);
            }
            self.accumulate_column(j, &mut pass);
        }
        self.end_record(&pass);
    }

    /// The stored slots oldest first (the first `len` entries; the rest 0).
    fn stored_slots(&self) -> [usize; MAX_SLOTS] {
        std::array::from_fn(|i| if i < self.len { self.slot(i) } else { 0 })
    }

    /// Starts a record's pass: advances the ring if the record stores a difference (it has a
    /// previous iterate), and returns the slot it writes, the stored slots and empty sums.
    fn begin_record(&mut self) -> RecordPass {
        let slot = self.next;
        let push = self.has_last;
        if push {
            self.len = (self.len + 1).min(self.window);
            self.next = (self.next + 1) % self.window;
        }
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

    /// Adds column j's share of the new Gram column Δr_newᵀΔr_i, the projections Δr_iᵀ r and ‖r‖².
    #[inline(always)]
    fn accumulate_column(&self, j: usize, pass: &mut RecordPass) {
        let (drf, rf) = (self.dr_f[pass.slot].col_as_slice(j), self.r_f.col_as_slice(j));
        for (i, &other) in pass.slots[..pass.n_slots].iter().enumerate() {
            let d_other = self.dr_f[other].col_as_slice(j);
            pass.gram_new[i] += dot(drf, d_other);
            pass.projection[i] += dot(d_other, rf);
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
            self.gram[slot * self.window + other] = pass.gram_new[i];
            self.gram[other * self.window + slot] = pass.gram_new[i];
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
                p.gram[j * k + i] = self.gram[self.slot(j) * self.window + si];
            }
            p.projection[i] = self.projection[si];
        }
        p.residual2 = self.residual2;
        p
    }

    /// Forgets every stored difference (the last iterate stays, so the next record starts anew).
    pub fn restart(&mut self) {
        self.len = 0;
        self.next = 0;
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
        // stays in cache over the k differences).
        for j in 0..self.cols {
            for (s, p, d) in [(&mut *s_w, &self.p_w, &self.d_w), (&mut *s_f, &self.p_f, &self.d_f)] {
                let x = s.col_as_slice_mut(j);
                x.copy_from_slice(p.col_as_slice(j));
                for (i, &g) in gamma.iter().enumerate() {
                    for (x, d) in x.iter_mut().zip(d[self.slot(i)].col_as_slice(j)) {
                        *x -= g * d;
                    }
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

/// Statistics of a run's mixing steps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AndersonCounts {
    pub mixed: u32,
    pub safeguarded: u32,
    pub restarts: u32,
}

/// The global step: sums of partials in, coefficients out.
#[derive(Debug, Clone)]
pub struct AndersonCoordinator {
    max_condition: f64,
    last_residual2: Option<f64>,
    last_mixed: bool,
    pub counts: AndersonCounts,
}

impl AndersonCoordinator {
    pub fn new(max_condition: f64) -> Self {
        Self {
            max_condition,
            last_residual2: None,
            last_mixed: false,
            counts: AndersonCounts::default(),
        }
    }

    /// The step for the summed partials `p`. `map_changed` (e.g. after a search-direction update)
    /// restarts the histories: differences taken before belong to another fixed-point map.
    pub fn decide(&mut self, p: &GramPartials, map_changed: bool) -> AndersonStep {
        let grew = self.last_mixed && self.last_residual2.is_some_and(|r| p.residual2 > r);
        let step = if map_changed || !p.residual2.is_finite() {
            AndersonStep::Restart
        } else if grew || p.k == 0 {
            AndersonStep::Plain
        } else {
            match solve_least_squares(p, self.max_condition) {
                Some(gamma) => AndersonStep::Mix(gamma),
                None => AndersonStep::Restart,
            }
        };
        match &step {
            AndersonStep::Mix(_) => self.counts.mixed += 1,
            AndersonStep::Plain if grew => self.counts.safeguarded += 1,
            AndersonStep::Restart => self.counts.restarts += 1,
            AndersonStep::Plain => {}
        }
        self.last_mixed = matches!(step, AndersonStep::Mix(_));
        self.last_residual2 = Some(p.residual2);
        step
    }
}

/// γ solving the normal equations (Δrᵀ Δr) γ = Δrᵀ r, or None when the Gram matrix scaled to a
/// unit diagonal has a condition number above `max_condition` (or a zero or non-finite entry).
pub fn solve_least_squares(p: &GramPartials, max_condition: f64) -> Option<Vec<f64>> {
    let k = p.k;
    if p.gram.iter().chain(&p.projection).any(|v| !v.is_finite()) {
        return None;
    }
    let d: Vec<f64> = (0..k).map(|i| p.gram[i * k + i]).collect();
    if d.iter().any(|&v| v <= 0.0) {
        return None;
    }
    let s: Vec<f64> = d.iter().map(|v| 1.0 / v.sqrt()).collect();
    let h = nalgebra::DMatrix::from_fn(k, k, |i, j| s[i] * p.gram[j * k + i] * s[j]);
    let eig = nalgebra::SymmetricEigen::new(h.clone());
    let (lo, hi) = eig
        .eigenvalues
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo <= 0.0 || hi / lo > max_condition {
        return None;
    }
    let b = nalgebra::DVector::from_fn(k, |i, _| s[i] * p.projection[i]);
    let y = h.cholesky()?.solve(&b);
    Some((0..k).map(|i| s[i] * y[i]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// G(x) = A x + c on x = (W, F) stacked as one vector, W first.
    struct Linear {
        a: Vec<Vec<f64>>,
        c: Vec<f64>,
        n_w: usize,
    }

    impl Linear {
        fn n(&self) -> usize {
            self.c.len()
        }

        fn apply(&self, w: &Mat<f64>, f: &Mat<f64>) -> (Mat<f64>, Mat<f64>) {
            let x: Vec<f64> = (0..self.n_w)
                .map(|i| w[(i, 0)])
                .chain((0..f.nrows()).map(|i| f[(i, 0)]))
                .collect();
            let y: Vec<f64> = (0..self.n()).map(|i| self.c[i] + dot(&self.a[i], &x)).collect();
            let nf = self.n() - self.n_w;
            (
                Mat::from_fn(self.n_w, 1, |i, _| y[i]),
                Mat::from_fn(nf, 1, |i, _| y[self.n_w + i]),
            )
        }

        /// The exact fixed point (I − A) x = c by Gaussian elimination.
        fn fixed_point(&self) -> Vec<f64> {
            let n = self.n();
            let m = nalgebra::DMatrix::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 } - self.a[i][j]);
            let x = m.lu().solve(&nalgebra::DVector::from_column_slice(&self.c)).unwrap();
            x.iter().copied().collect()
        }
    }

    /// A deterministic pseudo-random number in [−1, 1).
    fn rnd(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    /// A linear map with spectral radius ≤ `rho` (a random matrix scaled by its ∞-norm).
    fn contraction(n: usize, n_w: usize, rho: f64, seed: u64) -> Linear {
        let mut s = seed;
        let mut a: Vec<Vec<f64>> = (0..n).map(|_| (0..n).map(|_| rnd(&mut s)).collect()).collect();
        let norm = a
            .iter()
            .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        a.iter_mut().flatten().for_each(|v| *v *= rho / norm);
        let c = (0..n).map(|_| rnd(&mut s)).collect();
        Linear { a, c, n_w }
    }

    /// Runs the mixed (window Some(m)) or plain (None) iteration from 0 until ‖r‖ ≤ tol; returns
    /// the state, the number of G evaluations and the mixing counts.
    fn run(g: &Linear, mu: f64, window: Option<usize>, tol: f64, max: usize) -> (Vec<f64>, usize, AndersonCounts) {
        let nf = g.n() - g.n_w;
        let mut w = Mat::<f64>::zeros(g.n_w, 1);
        let mut f = Mat::<f64>::zeros(nf, 1);
        let mut history = window.map(|m| {
            // W and F of one part must share a shape: pad the shorter one with zeros.
            let rows = g.n_w.max(nf);
            AndersonHistory::new(m, mu, rows, 1)
        });
        let mut coord = AndersonCoordinator::new(MAX_CONDITION);
        let pad = |m: &Mat<f64>, rows: usize| Mat::from_fn(rows, 1, |i, _| if i < m.nrows() { m[(i, 0)] } else { 0.0 });
        for it in 1..=max {
            let (gw, gf) = g.apply(&w, &f);
            let r: f64 = (0..g.n_w)
                .map(|i| (gw[(i, 0)] - w[(i, 0)]).powi(2))
                .chain((0..nf).map(|i| (gf[(i, 0)] - f[(i, 0)]).powi(2)))
                .sum::<f64>()
                .sqrt();
            if r <= tol {
                let x = (0..g.n_w)
                    .map(|i| w[(i, 0)])
                    .chain((0..nf).map(|i| f[(i, 0)]))
                    .collect();
                return (x, it, coord.counts);
            }
            match history.as_mut() {
                None => {
                    for i in 0..g.n_w {
                        w[(i, 0)] += mu * (gw[(i, 0)] - w[(i, 0)]);
                    }
                    for i in 0..nf {
                        f[(i, 0)] += mu * (gf[(i, 0)] - f[(i, 0)]);
                    }
                }
                Some(h) => {
                    let rows = g.n_w.max(nf);
                    let (mut sw, mut sf) = (pad(&w, rows), pad(&f, rows));
                    h.record(&sw, &sf, &pad(&gw, rows), &pad(&gf, rows));
                    let step = coord.decide(&h.partials(), false);
                    h.apply(&step, &mut sw, &mut sf);
                    w = Mat::from_fn(g.n_w, 1, |i, _| sw[(i, 0)]);
                    f = Mat::from_fn(nf, 1, |i, _| sf[(i, 0)]);
                }
            }
        }
        panic!("no convergence in {max} evaluations");
    }

    #[test]
    fn same_fixed_point_as_plain_relaxation() {
        // W is a third of the state and enters the least squares only through its effect on F.
        let g = contraction(30, 10, 0.95, 7);
        let exact = g.fixed_point();
        let (plain, n_plain, _) = run(&g, 0.8, None, 1e-12, 5000);
        let (mixed, n_mixed, counts) = run(&g, 0.8, Some(5), 1e-12, 5000);
        let err = |x: &[f64]| x.iter().zip(&exact).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        // ‖x − x*‖ ≤ ‖r‖ / (1 − ρ) = 1e-12 / 0.05 for both.
        assert!(
            err(&plain) < 1e-10 && err(&mixed) < 1e-10,
            "{} {}",
            err(&plain),
            err(&mixed)
        );
        assert!(counts.mixed > 0);
        assert!(n_mixed < n_plain, "Anderson {n_mixed} vs plain {n_plain} evaluations");
    }

    #[test]
    fn a_linear_problem_of_dimension_at_most_m_converges_in_m_plus_one_steps() {
        for (d, m, mu) in [(4, 4, 1.0), (5, 6, 0.8), (6, 6, 0.5)] {
            // Spectral radius up to 0.9 (plain relaxation would need hundreds of steps).
            let g = contraction(d, 0, 0.9, 11 + d as u64);
            let r0 = g.c.iter().map(|v| v * v).sum::<f64>().sqrt();
            // ≤ m + 1 steps = m + 2 evaluations of G (the last one only measures the residual).
            // The tolerance 1e-9 ‖r₀‖ leaves round-off of the normal equations room (cond ≤ 1e10).
            let (_, evals, counts) = run(&g, mu, Some(m), 1e-9 * r0, m + 2);
            assert!(evals <= m + 2, "d = {d}, m = {m}: {evals} evaluations");
            assert_eq!(counts.restarts, 0);
        }
    }

    #[test]
    fn split_parts_sum_to_the_whole() {
        // The coordinator sees the sum of the parts' partials: cutting the state changes nothing
        // but the order of the additions.
        let (rows, m) = (6, 3);
        let mut seed = 3;
        let states: Vec<(Mat<f64>, Mat<f64>)> = (0..5)
            .map(|_| {
                (
                    Mat::from_fn(rows, 2, |_, _| rnd(&mut seed)),
                    Mat::from_fn(rows, 2, |_, _| rnd(&mut seed)),
                )
            })
            .collect();
        let mut whole = AndersonHistory::new(m, 0.7, rows, 2);
        let mut parts = [
            AndersonHistory::new(m, 0.7, rows, 1),
            AndersonHistory::new(m, 0.7, rows, 1),
        ];
        let col = |x: &Mat<f64>, j: usize| Mat::from_fn(rows, 1, |r, _| x[(r, j)]);
        for k in 0..4 {
            let (s, g) = (&states[k], &states[k + 1]);
            whole.record(&s.0, &s.1, &g.0, &g.1);
            for (j, p) in parts.iter_mut().enumerate() {
                p.record(&col(&s.0, j), &col(&s.1, j), &col(&g.0, j), &col(&g.1, j));
            }
        }
        let w = whole.partials();
        let mut sum = parts[0].partials();
        sum.add(&parts[1].partials());
        assert_eq!(w.k, m, "the ring keeps the last m of 3 differences");
        for (a, b) in w
            .gram
            .iter()
            .chain(&w.projection)
            .zip(sum.gram.iter().chain(&sum.projection))
        {
            assert!((a - b).abs() <= 1e-14 * a.abs().max(1.0), "{a} vs {b}");
        }
        // And the Gram matrix kept column by column equals the one recomputed from scratch.
        let mut fresh = AndersonHistory::new(m, 0.7, rows, 2);
        for k in 1..4 {
            let (s, g) = (&states[k], &states[k + 1]);
            fresh.record(&s.0, &s.1, &g.0, &g.1);
        }
        let f = fresh.partials();
        assert_eq!(f.k, 2);
        assert_eq!(
            &w.gram[4..6],
            &f.gram[0..2],
            "newest two differences, same Gram entries"
        );
    }

    #[test]
    fn safeguard_falls_back_to_plain_when_the_mixed_step_made_the_residual_grow() {
        let mut c = AndersonCoordinator::new(MAX_CONDITION);
        let p = |r2: f64| GramPartials {
            k: 1,
            // Powers of 2 so that γ = 2/4 comes out exact.
            gram: vec![4.0],
            projection: vec![2.0],
            residual2: r2,
        };
        assert_eq!(c.decide(&p(1.0), false), AndersonStep::Mix(vec![0.5]));
        // The mixed step's residual is larger: plain step.
        assert_eq!(c.decide(&p(1.5), false), AndersonStep::Plain);
        // After a plain step growth is not the mixing's doing: mix again.
        assert_eq!(c.decide(&p(2.0), false), AndersonStep::Mix(vec![0.5]));
        // Decreasing after a mixed step: keep mixing.
        assert_eq!(c.decide(&p(1.0), false), AndersonStep::Mix(vec![0.5]));
        assert_eq!(
            c.counts,
            AndersonCounts {
                mixed: 3,
                safeguarded: 1,
                restarts: 0
            }
        );
    }

    #[test]
    fn restart_when_ill_conditioned_not_finite_or_the_map_changed() {
        let mut c = AndersonCoordinator::new(MAX_CONDITION);
        // Two nearly parallel differences: scaled Gram [[1, 1−ε], [1−ε, 1]], condition ≈ 2/ε.
        let eps = 1e-12;
        let nearly = GramPartials {
            k: 2,
            gram: vec![1.0, 1.0 - eps, 1.0 - eps, 1.0],
            projection: vec![1.0, 1.0],
            residual2: 1.0,
        };
        assert_eq!(c.decide(&nearly, false), AndersonStep::Restart);
        // Same with a comfortable angle: solved.
        let fine = GramPartials {
            gram: vec![1.0, 0.5, 0.5, 1.0],
            ..nearly.clone()
        };
        let AndersonStep::Mix(g) = c.decide(&fine, false) else {
            panic!("expected a mixed step")
        };
        // [[1, .5], [.5, 1]] γ = [1, 1] → γ = [2/3, 2/3].
        assert!(g.iter().all(|v| (v - 2.0 / 3.0).abs() < 1e-14), "{g:?}");
        assert_eq!(c.decide(&fine, true), AndersonStep::Restart);
        let nan = GramPartials {
            residual2: f64::NAN,
            ..fine.clone()
        };
        assert_eq!(c.decide(&nan, false), AndersonStep::Restart);
        assert_eq!(c.counts.restarts, 3);

        // A history told to restart forgets its differences but not its last iterate.
        let z = Mat::<f64>::zeros(2, 1);
        let one = Mat::<f64>::from_fn(2, 1, |_, _| 1.0);
        let two = Mat::<f64>::from_fn(2, 1, |_, _| 2.0);
        let mut h = AndersonHistory::new(3, 1.0, 2, 1);
        h.record(&z, &z, &one, &one);
        h.record(&one, &one, &two, &two);
        assert_eq!(h.len(), 1);
        let (mut w, mut f) = (one.clone(), one.clone());
        h.apply(&AndersonStep::Restart, &mut w, &mut f);
        assert!(h.is_empty());
        assert_eq!((w[(0, 0)], f[(1, 0)]), (2.0, 2.0), "a plain step s + μ r");
        h.record(&two, &two, &two, &two);
        assert_eq!(h.len(), 1, "the next record forms a difference with the kept iterate");
    }

    /// Coordinates mixed beside the state give the state the fields mix to: fields W = B_W λ,
    /// F = B_F λ of coordinates λ on a basis that grows (new coordinates start at 0) and is once
    /// rotated (B U, Uᵀ λ: the same fields), under the fixed point λ ↦ A λ + c. Recording the
    /// force residuals alone gives the same sums and steps, bit for bit.
    #[test]
    fn coordinates_mix_as_the_fields_do() {
        let (n, cols, cap, window, mu) = (9, 3, 6, 3, 0.8);
        let mut seed = 77u64;
        let mut r = |rows: usize, c: usize| Mat::<f64>::from_fn(rows, c, |_, _| rnd(&mut seed));
        let (b_w, b_f) = (r(n, cap), r(n, cap));
        let a = r(cap, cap) * 0.1;
        let c = r(cap, cols);
        let mut history = AndersonHistory::new(window, mu, n, cols).with_coordinates(cap);
        // The same iterates recorded by their force residuals alone.
        let mut by_residual = AndersonHistory::new(window, mu, n, cols).with_coordinates(cap);
        let mut coordinator = AndersonCoordinator::new(MAX_CONDITION);
        let mut basis = (b_w.clone(), b_f.clone());
        let mut lam = Mat::<f64>::zeros(2, cols);
        for it in 0..12 {
            // The basis grows by one coordinate at iterations 3 and 6, and rotates at 8.
            let p = lam.nrows();
            if it == 3 || it == 6 {
                let mut grown = Mat::<f64>::zeros(p + 1, cols);
                grown.as_mut().subrows_mut(0, p).copy_from(&lam);
                lam = grown;
            }
            let p = lam.nrows();
            if it == 8 {
                let q = r(p, p).qr().compute_Q();
                history.rotate_coordinates(0, p, q.as_ref());
                by_residual.rotate_coordinates(0, p, q.as_ref());
                lam = q.transpose() * &lam;
                basis = (basis.0.as_ref().subcols(0, p) * &q, basis.1.as_ref().subcols(0, p) * &q);
            }
            let fields = |l: &Mat<f64>| {
                let p = l.nrows();
                (basis.0.as_ref().subcols(0, p) * l, basis.1.as_ref().subcols(0, p) * l)
            };
            let image = a.as_ref().subrows(0, p).subcols(0, p) * &lam + c.as_ref().subrows(0, p);
            let (s_w, s_f) = fields(&lam);
            let (g_w, g_f) = fields(&image);
            history.record(&s_w, &s_f, &g_w, &g_f);
            history.record_coordinates(lam.as_ref(), image.as_ref());
            by_residual.record_residual(&(&g_f - &s_f));
            by_residual.record_coordinates(lam.as_ref(), image.as_ref());
            assert_eq!(by_residual.partials(), history.partials(), "iteration {it}: same sums");
            let step = coordinator.decide(&history.partials(), false);
            let (mut w, mut f) = (s_w.clone(), s_f.clone());
            history.apply(&step, &mut w, &mut f);
            // A restart step restarts a history once: apply_coordinates on `history` repeats it.
            let mut next = Mat::<f64>::zeros(p, cols);
            history.apply_coordinates(&step, next.as_mut());
            let mut again = Mat::<f64>::zeros(p, cols);
            by_residual.apply_coordinates(&step, again.as_mut());
            assert!(again == next, "iteration {it}: same coordinates");
            let (nw, nf) = fields(&next);
            let scale = w.norm_max().max(f.norm_max());
            // The same affine combination, one evaluated on coordinates and mapped, the other on
            // the mapped vectors: round-off of sums of a few O(1) terms.
            assert!((&nw - &w).norm_max() <= 1e-12 * scale, "iteration {it}: W");
            assert!((&nf - &f).norm_max() <= 1e-12 * scale, "iteration {it}: F");
            lam = next;
        }
        assert!(coordinator.counts.mixed > 3, "{:?}", coordinator.counts);
    }
}
