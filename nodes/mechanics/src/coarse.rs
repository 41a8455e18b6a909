//! The macro (coarse) problem of the LATIN linear stage (DESIGN §3, Problem 3):
//! (Σ_E L_E) w̃ = −Σ_E F̂ᴹ_{E,d}, one unknown block per interface (its macro modes), shared by
//! both sides; assembled from the subdomains' homogenized operators, factorised once (dense
//! Cholesky), one column per time point.

use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef, Side};

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

/// The assembled and factorised macro operator.
pub struct MacroProblem {
    /// First unknown of each interface.
    pub offsets: Vec<usize>,
    pub n_modes: Vec<usize>,
    llt: faer::linalg::solvers::Llt<f64>,
    n: usize,
}

impl MacroProblem {
    /// Assembles Σ L_E over the interfaces' shared unknowns and factorises it. `n_modes[i]` is
    /// the number of macro modes of interface i.
    pub fn new(n_modes: &[usize], parts: &[Contribution<'_>]) -> Result<Self, MacroError> {
        let mut offsets = Vec::with_capacity(n_modes.len());
        let mut n = 0;
        for &k in n_modes {
            offsets.push(n);
            n += k;
        }
        let mut l = Mat::<f64>::zeros(n, n);
        for part in parts {
            let map = Self::map(&offsets, part.interfaces);
            if map.len() != part.l_e.nrows() || map.len() != part.l_e.ncols() {
                return Err(MacroError::WrongSize {
                    subdomain: part.subdomain,
                    got: part.l_e.nrows(),
                    expected: map.len(),
                });
            }
            for (r, &gr) in map.iter().enumerate() {
                for (c, &gc) in map.iter().enumerate() {
                    l[(gr, gc)] += part.l_e[(r, c)];
                }
            }
        }
        let max_diag = (0..n).map(|i| l[(i, i)].abs()).fold(0.0, f64::max);
        let llt = l.llt(Side::Lower).map_err(|_| MacroError::Singular {
            what: "the structure".into(),
            ratio: 0.0,
        })?;
        crate::simd::clear_upper_state();
        let lf = llt.L();
        let min_pivot = (0..n).map(|i| lf[(i, i)] * lf[(i, i)]).fold(f64::INFINITY, f64::min);
        let ratio = if n == 0 { 1.0 } else { min_pivot / max_diag };
        if ratio.is_nan() || ratio <= 1e-12 {
            return Err(MacroError::Singular {
                what: "the structure".into(),
                ratio,
            });
        }
        Ok(Self {
            offsets,
            n_modes: n_modes.to_vec(),
            llt,
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

    /// Solves (Σ L_E) w̃ = rhs in place (n × (N+1)).
    pub fn solve_in_place(&self, rhs: &mut Mat<f64>) {
        if self.n > 0 {
            self.llt.solve_in_place(rhs.as_mut());
            crate::simd::clear_upper_state();
        }
    }
}
