//! Passes over whole boundary fields (n_b × (N+1), column-major, unit row stride): column
//! slices, and the sum of the two micro problems' solutions with the relaxation that ends the
//! linear stage.

use faer::reborrow::ReborrowMut;
use faer::{MatMut, MatRef};

/// Column `j` of a matrix with unit row stride (every field here), as a slice.
#[inline(always)]
pub(super) fn col(m: MatRef<'_, f64>, j: usize) -> &[f64] {
    m.col(j)
        .try_as_col_major()
        .expect("fields have unit row stride")
        .as_slice()
}

#[inline(always)]
pub(super) fn col_mut<'a>(m: &'a mut MatMut<'_, f64>, j: usize) -> &'a mut [f64] {
    m.rb_mut()
        .col_mut(j)
        .try_as_col_major_mut()
        .expect("fields have unit row stride")
        .as_slice_mut()
}

/// out[r] = d[r] · x[r].
#[inline(always)]
pub(super) fn scale_into(out: &mut [f64], d: &[f64], x: &[f64]) {
    for ((o, d), x) in out.iter_mut().zip(d).zip(x) {
        *o = d * x;
    }
}

crate::multiversion! {
    /// End of the linear stage: s_new = s₁ + s₂ into (w1, f1), then the relaxation
    /// s ← μ s_new + (1 − μ) s into (w, f), in one pass (compiled for the CPU's widest vector
    /// extension).
    pub fn sum_relax_into(
        mu: f64,
        w1: MatMut<'_, f64>,
        f1: MatMut<'_, f64>,
        w2: MatRef<'_, f64>,
        f2: MatRef<'_, f64>,
        w: MatMut<'_, f64>,
        f: MatMut<'_, f64>,
    ) {
        let (mut w1, mut f1, mut w, mut f) = (w1, f1, w, f);
        for j in 0..w.ncols() {
            for (s1, s2, s) in [
                (col_mut(&mut w1, j), col(w2, j), col_mut(&mut w, j)),
                (col_mut(&mut f1, j), col(f2, j), col_mut(&mut f, j)),
            ] {
                for ((s1, s2), s) in s1.iter_mut().zip(s2).zip(s) {
                    *s1 += s2;
                    *s = mu * *s1 + (1.0 - mu) * *s;
                }
            }
        }
    }
}

/// s_new = s₁ + s₂ into (w1, f1).
pub fn sum_into(mut w1: MatMut<'_, f64>, mut f1: MatMut<'_, f64>, w2: MatRef<'_, f64>, f2: MatRef<'_, f64>) {
    for j in 0..w1.ncols() {
        for (s1, s2) in [(col_mut(&mut w1, j), col(w2, j)), (col_mut(&mut f1, j), col(f2, j))] {
            for (s1, s2) in s1.iter_mut().zip(s2) {
                *s1 += s2;
            }
        }
    }
}

/// The relaxation s ← μ s_new + (1 − μ) s, s_new = (w1, f1), into (w, f).
pub fn relax_into(mu: f64, w1: MatRef<'_, f64>, f1: MatRef<'_, f64>, mut w: MatMut<'_, f64>, mut f: MatMut<'_, f64>) {
    for j in 0..w.ncols() {
        for (s1, s) in [(col(w1, j), col_mut(&mut w, j)), (col(f1, j), col_mut(&mut f, j))] {
            for (s1, s) in s1.iter().zip(s) {
                *s = mu * s1 + (1.0 - mu) * *s;
            }
        }
    }
}
