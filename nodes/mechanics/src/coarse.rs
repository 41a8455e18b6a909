//! The macro (coarse) problem of the LATIN linear stage (docs/method.md, "Macro problem"):
//! (Σ_E L_E) w̃ = −Σ_E F̂ᴹ_{E,d}, one unknown block per interface (its macro modes), shared by
//! both sides; assembled from the subdomains' homogenized operators, factorised once, one column
//! per time point.
//!
//! Up to [`DENSE_UP_TO`] unknowns the factor is dense (Cholesky); above, sparse (supernodal
//! Cholesky, AMD ordering): a subdomain couples only its own interfaces, so Σ L_E is as sparse as
//! the graph of subdomains, and a dense solve's n² per time point would dominate the iteration
//! from a few hundred subdomains on (on a laminate of 1000 subdomains, 5790 unknowns: 306 ms
//! per iteration dense, 30 ms sparse; docs/performance.md). The two agree to round-off, not bit
//! for bit, so the scenes small enough for the dense factor keep their results.

use crate::assembly::SparseSpd;
use faer::dyn_stack::MemBuffer;
use faer::linalg::solvers::Solve;
use faer::{Mat, MatMut, MatRef, Side};

/// Macro unknowns up to which the macro operator is factorised dense.
pub const DENSE_UP_TO: usize = 600;

/// Errors of the macro problem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MacroError {
    #[error("the macro operator is singular: a rigid-body mode of {what} is not blocked by any prescribed displacement (smallest/largest pivot ratio {ratio:e})")]
    Singular { what: String, ratio: f64 },
    #[error("homogenized operator of subdomain {subdomain} has size {got}, expected {expected}")]
    WrongSize {
        subdomain: usize,
        got: usize,
        expected: usize,
    },
}

/// One subdomain's contribution: for each of its macro slots (interface, number of modes) in
/// order, and its L_E over those columns.
pub struct Contribution<'a> {
    pub subdomain: usize,
    pub interfaces: &'a [(usize, usize)],
    pub l_e: MatRef<'a, f64>,
}

/// How Σ L_E is factorised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Factorisation {
    Dense,
    Sparse,
}

impl Factorisation {
    /// The factorisation used for `n` unknowns.
    pub fn for_size(n: usize) -> Self {
        if n <= DENSE_UP_TO {
            Self::Dense
        } else {
            Self::Sparse
        }
    }
}

enum Factor {
    None,
    Dense(faer::linalg::solvers::Llt<f64>),
    Sparse(SparseSpd),
}

/// The assembled and factorised macro operator.
pub struct MacroProblem {
    /// First unknown of each interface.
    pub offsets: Vec<usize>,
    pub n_modes: Vec<usize>,
    factor: Factor,
    /// Scratch of the solve for the time points' columns, allocated once.
    scratch: Option<MemBuffer>,
    scratch_columns: usize,
    n: usize,
}

impl MacroProblem {
    /// Assembles Σ L_E over the interfaces' shared unknowns and factorises it. `n_modes[i]` is
    /// the number of macro modes of interface i.
    pub fn new(n_modes: &[usize], parts: &[Contribution<'_>]) -> Result<Self, MacroError> {
        let n = n_modes.iter().sum();
        Self::with(n_modes, parts, Factorisation::for_size(n))
    }

    /// As [`MacroProblem::new`], with the factorisation given.
    pub fn with(n_modes: &[usize], parts: &[Contribution<'_>], how: Factorisation) -> Result<Self, MacroError> {
        let mut offsets = Vec::with_capacity(n_modes.len());
        let mut n = 0;
        for &k in n_modes {
            offsets.push(n);
            n += k;
        }
        let mut triplets = Vec::new();
        let mut diagonal = vec![0.0; n];
        for part in parts {
            let map = Self::map(&offsets, part.interfaces);
            if map.len() != part.l_e.nrows() || map.len() != part.l_e.ncols() {
                return Err(MacroError::WrongSize {
                    subdomain: part.subdomain,
                    got: part.l_e.nrows(),
                    expected: map.len(),
                });
            }
            for (c, &gc) in map.iter().enumerate() {
                for (r, &gr) in map.iter().enumerate() {
                    // The lower triangle only (the factorisation reads no more); duplicates add.
                    if gr >= gc {
                        triplets.push((gr, gc, part.l_e[(r, c)]));
                    }
                    if gr == gc {
                        diagonal[gr] += part.l_e[(r, c)];
                    }
                }
            }
        }
        let singular = |ratio| MacroError::Singular {
            what: "the structure".into(),
            ratio,
        };
        let max_diag = diagonal.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
        // A rigid-body mode the prescribed displacements leave free gives a pivot at round-off
        // relative to the operator's scale, which a Cholesky factorisation may still pass.
        let check = |pivots: &mut dyn Iterator<Item = f64>| {
            let ratio = pivots.fold(f64::INFINITY, f64::min) / max_diag;
            if ratio.is_nan() || ratio <= 1e-12 {
                Err(singular(ratio))
            } else {
                Ok(())
            }
        };
        let factor = match (n, how) {
            (0, _) => Factor::None,
            (_, Factorisation::Dense) => {
                let mut l = Mat::<f64>::zeros(n, n);
                for &(r, c, v) in &triplets {
                    l[(r, c)] += v;
                }
                let llt = l.llt(Side::Lower).map_err(|_| singular(0.0))?;
                crate::simd::clear_upper_state();
                let lf = llt.L();
                check(&mut (0..n).map(|i| lf[(i, i)] * lf[(i, i)]))?;
                Factor::Dense(llt)
            }
            (_, Factorisation::Sparse) => {
                let f =
                    SparseSpd::factorize_supernodal(n, &triplets, "the macro operator").map_err(|_| singular(0.0))?;
                check(&mut f.factor_diagonal().into_iter().map(|l| l * l))?;
                Factor::Sparse(f)
            }
        };
        Ok(Self {
            offsets,
            n_modes: n_modes.to_vec(),
            factor,
            scratch: None,
            scratch_columns: 0,
            n,
        })
    }

    fn map(offsets: &[usize], interfaces: &[(usize, usize)]) -> Vec<usize> {
        interfaces
            .iter()
            .flat_map(|&(i, k)| (0..k).map(move |m| offsets[i] + m))
            .collect()
    }

    /// Number of macro unknowns.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Global unknown indices of a subdomain's macro columns.
    pub fn columns_of(&self, interfaces: &[(usize, usize)]) -> Vec<usize> {
        Self::map(&self.offsets, interfaces)
    }

    /// Solves (Σ L_E) w̃ = rhs in place (n × (N+1)); the solve's scratch is allocated on the
    /// first call and kept.
    pub fn solve_in_place(&mut self, rhs: &mut Mat<f64>) {
        match &self.factor {
            Factor::None => {}
            Factor::Dense(llt) => {
                llt.solve_in_place(rhs.as_mut());
                crate::simd::clear_upper_state();
            }
            Factor::Sparse(f) => {
                let scratch = match &mut self.scratch {
                    Some(s) if self.scratch_columns >= rhs.ncols() => s,
                    slot => {
                        self.scratch_columns = rhs.ncols();
                        slot.insert(f.solve_scratch(rhs.ncols()))
                    }
                };
                f.solve_view_in_place_with(rhs.as_mut(), scratch);
            }
        }
    }

    /// The right-hand side of one iteration, rhs = −Σ_E F̂ᴹ_{E,d}, into `rhs` (n × (N+1)):
    /// each subdomain's macro forces (n_m × (N+1)) subtracted over its global unknowns
    /// ([`Self::columns_of`]), subdomain by subdomain in the order given.
    pub fn rhs_into<'a>(rhs: &mut Mat<f64>, forces: impl IntoIterator<Item = (&'a [usize], MatRef<'a, f64>)>) {
        rhs.fill(0.0);
        for (columns, f) in forces {
            for (r, &g) in columns.iter().enumerate() {
                for j in 0..rhs.ncols() {
                    rhs[(g, j)] -= f[(r, j)];
                }
            }
        }
    }

    /// One subdomain's w̃ (n_m × (N+1)): the rows of its global unknowns `columns` of the macro
    /// problem's solution `w` (n × (N+1)).
    pub fn subdomain_part_into(w: MatRef<'_, f64>, columns: &[usize], mut w_tilde: MatMut<'_, f64>) {
        for j in 0..w_tilde.ncols() {
            for (r, &g) in columns.iter().enumerate() {
                w_tilde[(r, j)] = w[(g, j)];
            }
        }
    }

    /// How Σ L_E was factorised (None: no unknowns).
    pub fn factorisation(&self) -> Option<Factorisation> {
        match self.factor {
            Factor::None => None,
            Factor::Dense(_) => Some(Factorisation::Dense),
            Factor::Sparse(_) => Some(Factorisation::Sparse),
        }
    }

    /// Entries of the factor of Σ L_E (its lower triangle, as stored: n(n + 1)/2 when dense).
    pub fn factor_nnz(&self) -> usize {
        match &self.factor {
            Factor::None => 0,
            Factor::Dense(_) => self.n * (self.n + 1) / 2,
            Factor::Sparse(f) => f.nnz_l(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::solvers::Solve;

    /// A deterministic SPD k × k block with entries of order 1 (diagonally dominant).
    fn spd_block(k: usize, seed: usize) -> Mat<f64> {
        let mut m = Mat::from_fn(k, k, |i, j| (((i * 7 + j * 13 + seed * 31) % 17) as f64 - 8.0) / 16.0);
        m = &m + m.transpose();
        for i in 0..k {
            m[(i, i)] = k as f64 + 1.0 + (seed % 5) as f64;
        }
        m
    }

    /// A chain of "subdomains" each coupling interface e − 1 and e (3 modes each), the first one
    /// holding its interface alone: sparse, like a laminate's Σ L_E.
    /// A subdomain's macro slots and its L_E.
    type Part = (Vec<(usize, usize)>, Mat<f64>);

    fn chain(n_itf: usize) -> (Vec<usize>, Vec<Part>) {
        let n_modes = vec![3; n_itf];
        let mut parts = vec![(vec![(0, 3)], spd_block(3, 0))];
        for e in 1..n_itf {
            parts.push((vec![(e - 1, 3), (e, 3)], spd_block(6, e)));
        }
        (n_modes, parts)
    }

    #[test]
    fn the_sparse_solve_matches_a_dense_one() {
        let (n_modes, parts) = chain(40);
        let contributions: Vec<Contribution<'_>> = parts
            .iter()
            .enumerate()
            .map(|(s, (slots, l))| Contribution {
                subdomain: s,
                interfaces: slots,
                l_e: l.as_ref(),
            })
            .collect();
        let mut problem = MacroProblem::with(&n_modes, &contributions, Factorisation::Sparse).unwrap();
        assert_eq!(problem.factorisation(), Some(Factorisation::Sparse));
        let n = problem.n();
        assert_eq!(n, 120);
        let mut dense = Mat::<f64>::zeros(n, n);
        for (slots, l) in &parts {
            let map = problem.columns_of(slots);
            for (r, &gr) in map.iter().enumerate() {
                for (c, &gc) in map.iter().enumerate() {
                    dense[(gr, gc)] += l[(r, c)];
                }
            }
        }
        let rhs = Mat::from_fn(n, 5, |i, j| ((i * 3 + j * 11) % 7) as f64 - 3.0);
        let mut x = rhs.clone();
        problem.solve_in_place(&mut x);
        // Twice: the kept scratch gives the same answer.
        let mut again = rhs.clone();
        problem.solve_in_place(&mut again);
        assert_eq!(x, again);
        let expected = dense.llt(faer::Side::Lower).unwrap().solve(&rhs);
        let mut dense_problem = MacroProblem::with(&n_modes, &contributions, Factorisation::Dense).unwrap();
        let mut by_dense = rhs.clone();
        dense_problem.solve_in_place(&mut by_dense);
        assert_eq!(
            by_dense, expected,
            "the dense macro problem is the dense Cholesky solve"
        );
        assert_eq!(
            MacroProblem::new(&n_modes, &contributions).unwrap().factorisation(),
            Some(Factorisation::Dense)
        );
        // Both are backward-stable Cholesky solves of a well-conditioned (diagonally dominant)
        // system: they agree to a few ulps times the condition number.
        let err = (&x - &expected).norm_max() / expected.norm_max();
        assert!(err < 1e-12, "sparse and dense macro solves differ by {err:e}");
        // A chain's factor has no fill beyond its 3 × 3 blocks' band: far below the dense n².
        assert!(
            problem.factor_nnz() < n * n / 4,
            "{} entries in the factor",
            problem.factor_nnz()
        );
    }

    #[test]
    fn a_free_rigid_mode_is_refused() {
        // Every contribution is a weighted graph Laplacian (off-diagonal −|m_ij|, diagonal the
        // sum of their magnitudes): positive semi-definite with the constant vector in its null
        // space, as Σ L_E is when a rigid mode of the structure is held by nothing.
        let k = 6;
        let m = spd_block(k, 3);
        let l = Mat::from_fn(k, k, |i, j| {
            if i == j {
                (0..k).filter(|&c| c != i).map(|c| m[(i, c)].abs()).sum::<f64>()
            } else {
                -m[(i, j)].abs()
            }
        });
        let slots = [(0, 3), (1, 3)];
        let parts = [Contribution {
            subdomain: 0,
            interfaces: &slots,
            l_e: l.as_ref(),
        }];
        for how in [Factorisation::Dense, Factorisation::Sparse] {
            match MacroProblem::with(&[3, 3], &parts, how) {
                Err(MacroError::Singular { .. }) => {}
                Err(e) => panic!("{how:?}: expected a singular operator, got {e}"),
                Ok(_) => panic!("{how:?}: a singular macro operator was factorised"),
            }
        }
    }
}
