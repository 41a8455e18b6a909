//! Sparse algebra of the Newton systems: a row-compressed matrix for products, the fixed LU
//! pattern of the whole Jacobian, and the condensed (Schur complement) solver.

use crate::numbering::*;
use crate::{ReferenceError, NONE};
use faer::sparse::linalg::solvers::SymbolicLu;
use faer::sparse::{Argsort, Pair, SymbolicSparseColMat};
use faer::Mat;
use glissade_mechanics::assembly::{AssemblyError, SparseSpd};

/// Row-compressed sparse matrix with summed duplicates (for products only).
pub(crate) struct Csr {
    pub(crate) row_ptr: Vec<usize>,
    pub(crate) col: Vec<usize>,
    pub(crate) val: Vec<f64>,
}

impl Csr {
    pub(crate) fn from_triplets(n: usize, mut t: Vec<(usize, usize, f64)>) -> Self {
        t.sort_by_key(|e| (e.0, e.1));
        let mut row_ptr = vec![0; n + 1];
        let mut col = Vec::with_capacity(t.len() / 2);
        let mut val: Vec<f64> = Vec::with_capacity(t.len() / 2);
        let mut last = (NONE, NONE);
        for (i, j, v) in t {
            if (i, j) == last {
                if let Some(x) = val.last_mut() {
                    *x += v;
                }
            } else {
                col.push(j);
                val.push(v);
                row_ptr[i + 1] += 1;
                last = (i, j);
            }
        }
        for i in 0..n {
            row_ptr[i + 1] += row_ptr[i];
        }
        Self { row_ptr, col, val }
    }

    /// y = A x.
    pub(crate) fn matvec_into(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let r = self.row_ptr[i]..self.row_ptr[i + 1];
            *yi = self.col[r.clone()]
                .iter()
                .zip(&self.val[r])
                .map(|(&j, &v)| v * x[j])
                .sum();
        }
    }

    /// y = |A| |x| (entry by entry: y_i = Σ_j |a_ij x_j|), the magnitude whose round-off bounds
    /// that of A x.
    pub(crate) fn abs_matvec_into(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            let r = self.row_ptr[i]..self.row_ptr[i + 1];
            *yi = self.col[r.clone()]
                .iter()
                .zip(&self.val[r])
                .map(|(&j, &v)| (v * x[j]).abs())
                .sum();
        }
    }
}

/// Fixed pattern of the whole Jacobian for the sparse LU.
pub(crate) struct LuPattern {
    pub(crate) symbolic: SymbolicSparseColMat<usize>,
    pub(crate) argsort: Argsort<usize>,
    pub(crate) lu_symbolic: SymbolicLu<usize>,
    /// Values with the fixed part filled in (K_ff, Bᵀ).
    pub(crate) fixed: Vec<f64>,
    /// Offset of each pair's variable entries.
    pub(crate) offset: Vec<usize>,
}

/// Factorised K_ff and the contact-dof rows of Z = K_ff⁻¹ Bᵀ.
pub(crate) struct CondensedSolver {
    pub(crate) k_ff: SparseSpd,
    /// Row of `z_t` (column) of each free dof of a contact pair, NONE elsewhere.
    pub(crate) position: Vec<usize>,
    /// Zᵀ restricted to contact dofs: (2·n_pairs) × n_contact_dofs.
    pub(crate) z_t: Mat<f64>,
}

pub(crate) enum StepSolver {
    Condensed(CondensedSolver),
    SparseLu(LuPattern),
}

/// Scratch of the Newton iterations of one step.
pub(crate) struct NewtonWork {
    /// `SparseLu`: the Jacobian's values, fixed part filled in.
    pub(crate) values: Vec<f64>,
    /// `Condensed`: Sᵀ, the transposed Schur complement.
    pub(crate) s_t: Mat<f64>,
}

impl NewtonWork {
    pub(crate) fn new(solver: &StepSolver, n_pairs: usize) -> Self {
        match solver {
            StepSolver::SparseLu(pat) => Self {
                values: pat.fixed.clone(),
                s_t: Mat::new(),
            },
            StepSolver::Condensed(_) => Self {
                values: Vec::new(),
                s_t: Mat::zeros(2 * n_pairs, 2 * n_pairs),
            },
        }
    }
}

/// The fixed Jacobian pattern for the sparse LU: K_ff, the coupling Bᵀ (fixed values), then per
/// pair the λ_n row (u entries, λ_n) and the λ_t row (u entries, λ_n, λ_t).
pub(crate) fn lu_pattern(
    k: &Csr,
    free: &[usize],
    n_free: usize,
    pairs: &[MergedPair],
) -> Result<LuPattern, ReferenceError> {
    let n_unknowns = n_free + 2 * pairs.len();
    let mut idx: Vec<Pair<usize, usize>> = Vec::new();
    let mut fixed = Vec::new();
    for (i, &fi) in free.iter().enumerate() {
        if fi == NONE {
            continue;
        }
        for q in k.row_ptr[i]..k.row_ptr[i + 1] {
            let fj = free[k.col[q]];
            if fj != NONE {
                idx.push(Pair { row: fi, col: fj });
                fixed.push(k.val[q]);
            }
        }
    }
    for (m, mp) in pairs.iter().enumerate() {
        let (ln, lt) = (n_free + 2 * m, n_free + 2 * m + 1);
        for (q, &fd) in mp.free.iter().enumerate() {
            if fd == NONE {
                continue;
            }
            let (c, k) = mp.entry(q);
            idx.push(Pair { row: fd, col: ln });
            fixed.push(k * mp.normal[c]);
            idx.push(Pair { row: fd, col: lt });
            fixed.push(k * mp.tangent[c]);
        }
    }
    let mut offset = Vec::with_capacity(pairs.len());
    for (m, mp) in pairs.iter().enumerate() {
        let (ln, lt) = (n_free + 2 * m, n_free + 2 * m + 1);
        offset.push(idx.len());
        for &fd in mp.free.iter().filter(|&&d| d != NONE) {
            idx.push(Pair { row: ln, col: fd });
        }
        idx.push(Pair { row: ln, col: ln });
        for &fd in mp.free.iter().filter(|&&d| d != NONE) {
            idx.push(Pair { row: lt, col: fd });
        }
        idx.push(Pair { row: lt, col: ln });
        idx.push(Pair { row: lt, col: lt });
    }
    fixed.resize(idx.len(), 0.0);
    let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n_unknowns, n_unknowns, &idx)
        .map_err(|e| ReferenceError::Sparse(format!("{e:?}")))?;
    let lu_symbolic = SymbolicLu::try_new(symbolic.as_ref()).map_err(|e| ReferenceError::Sparse(format!("{e:?}")))?;
    Ok(LuPattern {
        symbolic,
        argsort,
        lu_symbolic,
        fixed,
        offset,
    })
}

/// Factorises K_ff (sparse Cholesky). `None` if K_ff is not positive definite: a part, or a
/// rigid motion of one, is held by nothing but contact.
pub(crate) fn factorize_k_ff(k: &Csr, free: &[usize], n_free: usize) -> Result<Option<SparseSpd>, ReferenceError> {
    let mut k_ff = Vec::new();
    for (i, &fi) in free.iter().enumerate() {
        if fi == NONE {
            continue;
        }
        for q in k.row_ptr[i]..k.row_ptr[i + 1] {
            let fj = free[k.col[q]];
            if fj != NONE && fi >= fj {
                k_ff.push((fi, fj, k.val[q]));
            }
        }
    }
    match SparseSpd::factorize(n_free, &k_ff, "the free stiffness of the reference solve") {
        Ok(f) => Ok(Some(f)),
        Err(AssemblyError::NotPositiveDefinite { .. }) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// Computes the contact-dof rows of Z = K_ff⁻¹ Bᵀ (in blocks of columns) from the factors of
/// K_ff.
pub(crate) fn condensed_solver(k_ff: SparseSpd, n_free: usize, pairs: &[MergedPair]) -> CondensedSolver {
    let mut position = vec![NONE; n_free];
    let mut contact_dofs = Vec::new();
    for mp in pairs {
        for &fd in mp.free.iter().filter(|&&d| d != NONE) {
            if position[fd] == NONE {
                position[fd] = contact_dofs.len();
                contact_dofs.push(fd);
            }
        }
    }
    let np2 = 2 * pairs.len();
    let mut z_t = Mat::<f64>::zeros(np2, contact_dofs.len());
    const BLOCK: usize = 32;
    for first in (0..np2).step_by(BLOCK) {
        let cols = BLOCK.min(np2 - first);
        let mut rhs = Mat::<f64>::zeros(n_free, cols);
        for j in 0..cols {
            let (m, comp) = ((first + j) / 2, (first + j) % 2);
            let mp = &pairs[m];
            let v = if comp == 0 { mp.normal } else { mp.tangent };
            for (q, &fd) in mp.free.iter().enumerate() {
                if fd != NONE {
                    let (c, k) = mp.entry(q);
                    rhs[(fd, j)] += k * v[c];
                }
            }
        }
        k_ff.solve_in_place(&mut rhs);
        for j in 0..cols {
            for (pos, &fd) in contact_dofs.iter().enumerate() {
                z_t[(first + j, pos)] = rhs[(fd, j)];
            }
        }
    }
    CondensedSolver { k_ff, position, z_t }
}
