//! A subdomain's boundary state in PGD mode form (docs/pgd.md, "Messages in mode form"), as the
//! subdomain and every receiver of its messages hold it:
//!
//!   W = P_W φ + Σ_k Z_k λ_k,  F = P_F φ + Σ_k G_k λ_k,
//!
//! with the particular part s₀ = (W_d, −k⁻W_d) in separated form (P_W = the boundary response to
//! each of the subdomain's load cases, P_F = −k⁻ P_W, φ their time functions, n_c of them), the
//! basis pairs (Z_k, G_k) of the subdomain's PGD stage and the state's time functions λ_k(t).
//!
//! The subdomain sends the particular part once, each basis column once (after a compression,
//! which rotates the free modes, the rotated columns again) and λ every iteration: for p modes,
//! about 2 n_b / p times fewer bytes than the full fields W and F. Both sides expand with
//! [`ModeForm::expand_into`] from buffers of the same layout, so the subdomain's own state and a
//! receiver's copy are equal bit for bit.

use crate::simd::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// Why a mode-form update cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModeFormError {
    #[error("modes from column {first} on, but only {held} modes are held")]
    Gap { first: usize, held: usize },
    #[error("{modes} modes for {n_b} boundary entries (at most one mode per entry)")]
    TooMany { modes: usize, n_b: usize },
    #[error("{what} has {got} values, expected {expected}")]
    Size {
        what: &'static str,
        got: usize,
        expected: usize,
    },
}

/// The particular part and the basis of one subdomain's mode form, and the time functions of its
/// last state. Buffers hold up to n_b modes, allocated once.
#[derive(Debug, Clone)]
pub struct ModeForm {
    /// P_W, P_F (n_b × n_c) and φ (n_c × (N+1)).
    particular_w: Mat<f64>,
    particular_f: Mat<f64>,
    phi: Mat<f64>,
    /// Z, G (n_b × n_b): the first p columns are the basis.
    z: Mat<f64>,
    g: Mat<f64>,
    /// λ (n_b × (N+1)): the first p rows are the state's time functions.
    lambda: Mat<f64>,
    p: usize,
}

fn size(what: &'static str, got: usize, expected: usize) -> Result<(), ModeFormError> {
    if got != expected {
        return Err(ModeFormError::Size { what, got, expected });
    }
    Ok(())
}

impl ModeForm {
    /// The particular part from column-major slices: `particular_w` and `particular_f` n_b × n_c,
    /// `phi` n_c × `n_times`; no mode yet.
    pub fn new(
        n_b: usize,
        n_times: usize,
        n_c: usize,
        particular_w: &[f64],
        particular_f: &[f64],
        phi: &[f64],
    ) -> Result<Self, ModeFormError> {
        size("particular W", particular_w.len(), n_b * n_c)?;
        size("particular F", particular_f.len(), n_b * n_c)?;
        size("particular time functions", phi.len(), n_c * n_times)?;
        Ok(Self {
            particular_w: MatRef::from_column_major_slice(particular_w, n_b, n_c).to_owned(),
            particular_f: MatRef::from_column_major_slice(particular_f, n_b, n_c).to_owned(),
            phi: MatRef::from_column_major_slice(phi, n_c, n_times).to_owned(),
            z: Mat::zeros(n_b, n_b),
            g: Mat::zeros(n_b, n_b),
            lambda: Mat::zeros(n_b, n_times),
            p: 0,
        })
    }

    /// Number of boundary entries n_b.
    pub fn n_boundary(&self) -> usize {
        self.z.nrows()
    }

    /// Number of time points N + 1.
    pub fn n_times(&self) -> usize {
        self.lambda.ncols()
    }

    /// Number of load cases n_c of the particular part.
    pub fn n_cases(&self) -> usize {
        self.phi.nrows()
    }

    /// Number of modes held.
    pub fn n_modes(&self) -> usize {
        self.p
    }

    /// The particular part P_W, P_F (n_b × n_c) and φ (n_c × (N+1)).
    pub fn particular(&self) -> (MatRef<'_, f64>, MatRef<'_, f64>, MatRef<'_, f64>) {
        (
            self.particular_w.as_ref(),
            self.particular_f.as_ref(),
            self.phi.as_ref(),
        )
    }

    /// Checks an update ([`ModeForm::update`]) without applying it.
    pub fn check(&self, first: usize, z: &[f64], g: &[f64], lambda: &[f64]) -> Result<usize, ModeFormError> {
        let (n_b, nt) = (self.n_boundary(), self.n_times());
        if first > self.p {
            return Err(ModeFormError::Gap { first, held: self.p });
        }
        if n_b == 0 || !z.len().is_multiple_of(n_b) {
            return Err(ModeFormError::Size {
                what: "Z",
                got: z.len(),
                expected: n_b * (z.len() / n_b.max(1)),
            });
        }
        let new = z.len() / n_b;
        size("G", g.len(), z.len())?;
        let p = first + new;
        if p > n_b {
            return Err(ModeFormError::TooMany { modes: p, n_b });
        }
        size("λ", lambda.len(), p * nt)?;
        Ok(p)
    }

    /// Keeps the first `first` modes, replaces the others by the columns of `z` and `g`
    /// (column-major, n_b rows each) and takes `lambda` (column-major, p × (N+1), p = `first` +
    /// the new columns) as the state's time functions. The sizes are checked first: on error
    /// nothing changes. Values are not: a receiver checks the expanded fields (a diverging run's
    /// non-finite values are reported where they appear in W or F).
    pub fn update(&mut self, first: usize, z: &[f64], g: &[f64], lambda: &[f64]) -> Result<(), ModeFormError> {
        let p = self.check(first, z, g, lambda)?;
        let n_b = self.n_boundary();
        let new = p - first;
        self.z
            .as_mut()
            .subcols_mut(first, new)
            .copy_from(MatRef::from_column_major_slice(z, n_b, new));
        self.g
            .as_mut()
            .subcols_mut(first, new)
            .copy_from(MatRef::from_column_major_slice(g, n_b, new));
        let nt = self.n_times();
        self.lambda
            .as_mut()
            .subrows_mut(0, p)
            .copy_from(MatRef::from_column_major_slice(lambda, p, nt));
        self.p = p;
        Ok(())
    }

    /// W = P_W φ + Z λ and F = P_F φ + G λ (n_b × (N+1) each).
    pub fn expand_into(&self, w: MatMut<'_, f64>, f: MatMut<'_, f64>) {
        self.expand_one(w, &self.particular_w, &self.z);
        self.expand_one(f, &self.particular_f, &self.g);
    }

    /// out = P φ + B λ.
    fn expand_one(&self, mut out: MatMut<'_, f64>, particular: &Mat<f64>, basis: &Mat<f64>) {
        if self.phi.nrows() == 0 {
            out.fill(0.0);
        } else {
            matmul(
                out.as_mut(),
                Accum::Replace,
                particular.as_ref(),
                self.phi.as_ref(),
                1.0,
                Par::Seq,
            );
        }
        if self.p > 0 {
            matmul(
                out.as_mut(),
                Accum::Add,
                basis.as_ref().subcols(0, self.p),
                self.lambda.as_ref().subrows(0, self.p),
                1.0,
                Par::Seq,
            );
        }
    }

    /// Floating-point operations of one [`ModeForm::expand_into`]: two n_b × (n_c + p) by
    /// (n_c + p) × (N+1) products.
    pub fn expand_flops(&self) -> u64 {
        (2 * 2 * self.n_boundary() * (self.n_cases() + self.p) * self.n_times()) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn expansion_is_the_particular_part_plus_the_modes() {
        let (n_b, nt, n_c) = (7, 5, 2);
        let pw = values(n_b * n_c, 1);
        let pf: Vec<f64> = pw.iter().map(|v| -3.0 * v).collect();
        let phi = values(n_c * nt, 2);
        let mut form = ModeForm::new(n_b, nt, n_c, &pw, &pf, &phi).unwrap();
        let (z, g) = (values(n_b * 3, 3), values(n_b * 3, 4));
        let lambda = values(3 * nt, 5);
        form.update(0, &z, &g, &lambda).unwrap();
        // A compression-like update: keep mode 0, replace modes 1.. by one new column.
        let (z1, g1) = (values(n_b, 6), values(n_b, 7));
        let lambda1 = values(2 * nt, 8);
        form.update(1, &z1, &g1, &lambda1).unwrap();
        assert_eq!(form.n_modes(), 2);
        let (mut w, mut f) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
        form.expand_into(w.as_mut(), f.as_mut());
        for i in 0..nt {
            for r in 0..n_b {
                let part = |p: &[f64]| (0..n_c).map(|c| p[c * n_b + r] * phi[i * n_c + c]).sum::<f64>();
                let lam = |m: usize| lambda1[i * 2 + m];
                let we = part(&pw) + z[r] * lam(0) + z1[r] * lam(1);
                let fe = part(&pf) + g[r] * lam(0) + g1[r] * lam(1);
                // Sums of four O(1) products: round-off of a few ulps.
                assert!((w[(r, i)] - we).abs() <= 1e-14, "W[{r}, {i}]");
                assert!((f[(r, i)] - fe).abs() <= 1e-14, "F[{r}, {i}]");
            }
        }
    }

    #[test]
    fn bad_updates_change_nothing_and_say_why() {
        let (n_b, nt) = (4, 3);
        let mut form = ModeForm::new(n_b, nt, 0, &[], &[], &[]).unwrap();
        form.update(0, &values(n_b, 1), &values(n_b, 2), &values(nt, 3))
            .unwrap();
        let e = form.update(2, &values(n_b, 1), &values(n_b, 2), &values(3 * nt, 3));
        assert_eq!(e, Err(ModeFormError::Gap { first: 2, held: 1 }));
        let e = form.update(1, &values(n_b, 1), &values(n_b, 2), &values(nt, 3));
        assert!(
            matches!(
                e,
                Err(ModeFormError::Size {
                    what: "λ",
                    got: 3,
                    expected: 6
                })
            ),
            "{e:?}"
        );
        let e = form.update(0, &values(5 * n_b, 1), &values(5 * n_b, 2), &values(5 * nt, 3));
        assert_eq!(e, Err(ModeFormError::TooMany { modes: 5, n_b }));
        assert_eq!(form.n_modes(), 1, "a refused update changes nothing");
        let e = ModeForm::new(n_b, nt, 1, &values(3, 1), &values(4, 1), &values(3, 1)).unwrap_err();
        assert!(e.to_string().contains("particular W has 3 values, expected 4"), "{e}");
    }
}
