//! Sparse assembly of QUA8 stiffness matrices and the sparse Cholesky solver used everywhere.

use crate::element::{self, BadElement};
use crate::mesh::Mesh;
use crate::model::{Material, Plane};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::cholesky::{self, SymbolicCholesky, SymbolicCholeskyRaw};
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, MatMut, Side};

/// Errors of assembly and factorisation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssemblyError {
    #[error("element {element}: {source}")]
    BadElement { element: usize, source: BadElement },
    #[error("stiffness matrix of {what} is not positive definite (a rigid-body mode is not blocked or a material is invalid): {detail}")]
    NotPositiveDefinite { what: String, detail: String },
    #[error("sparse matrix of {what} could not be built: {detail}")]
    Sparse { what: String, detail: String },
}

/// Element stiffness triplets (row, col, value) of a whole mesh, in global dof numbering
/// (dof 2i = x of node i, 2i+1 = y). Both triangles are emitted.
pub fn stiffness_triplets(
    mesh: &Mesh,
    material: Material,
    plane: Plane,
) -> Result<Vec<(usize, usize, f64)>, AssemblyError> {
    let d = element::elasticity(material, plane);
    let mut out = Vec::with_capacity(mesh.elements.len() * 256);
    for (e, conn) in mesh.elements.iter().enumerate() {
        let x: [[f64; 2]; 8] = std::array::from_fn(|k| mesh.coords[conn[k]]);
        let ke = element::stiffness(&x, &d).map_err(|source| AssemblyError::BadElement { element: e, source })?;
        for a in 0..16 {
            let ga = 2 * conn[a / 2] + a % 2;
            for b in 0..16 {
                let gb = 2 * conn[b / 2] + b % 2;
                out.push((ga, gb, ke[(a, b)]));
            }
        }
    }
    Ok(out)
}

/// y = K x for a matrix given as triplets (duplicates add).
pub fn triplet_matvec(triplets: &[(usize, usize, f64)], x: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    for &(i, j, v) in triplets {
        y[i] += v * x[j];
    }
}

/// nnz(L) of a symbolic Cholesky factorisation: the simplicial pattern's entries, or per
/// supernode of s columns and p rows below them the trapezoid s(s + 1)/2 + p·s.
fn factor_nnz(structure: &SymbolicCholesky<usize>) -> usize {
    match structure.raw() {
        SymbolicCholeskyRaw::Simplicial(simplicial) => simplicial.len_val(),
        SymbolicCholeskyRaw::Supernodal(supernodal) => (0..supernodal.n_supernodes())
            .map(|k| {
                let s = supernodal.supernode_end()[k] - supernodal.supernode_begin()[k];
                let p = supernodal.supernode(k).pattern().len();
                s * (s + 1) / 2 + p * s
            })
            .sum(),
    }
}

/// A factorised sparse SPD matrix (faer sparse Cholesky, lower side). The symbolic
/// factorisation can be reused for matrices of the same pattern.
pub struct SparseSpd {
    n: usize,
    llt: Llt<usize, f64>,
    /// Entries of the lower triangle of the factor L, diagonal included, as faer stores it (a
    /// supernode's dense block counts whole, explicit zeros and all).
    nnz_l: usize,
}

impl SparseSpd {
    /// Factorises the n × n matrix given by `triplets` (duplicates add; only the lower triangle
    /// is read). `what` names the matrix in errors.
    pub fn factorize(n: usize, triplets: &[(usize, usize, f64)], what: &str) -> Result<Self, AssemblyError> {
        let lower: Vec<Triplet<usize, usize, f64>> = triplets
            .iter()
            .filter(|t| t.0 >= t.1)
            .map(|&(i, j, v)| Triplet::new(i, j, v))
            .collect();
        let mat =
            SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &lower).map_err(|e| AssemblyError::Sparse {
                what: what.to_string(),
                detail: format!("{e:?}"),
            })?;
        let sparse_error = |e: faer::sparse::FaerError| AssemblyError::Sparse {
            what: what.to_string(),
            detail: format!("{e:?}"),
        };
        let symbolic = SymbolicLlt::try_new(mat.symbolic(), Side::Lower).map_err(sparse_error)?;
        // `Llt` does not expose its symbolic structure: the same analysis (same defaults, AMD
        // ordering, deterministic) run once more gives the factor's pattern.
        let structure =
            cholesky::factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, Default::default(), Default::default())
                .map_err(sparse_error)?;
        let nnz_l = factor_nnz(&structure);
        let llt = Llt::try_new_with_symbolic(symbolic, mat.as_ref(), Side::Lower).map_err(|e| {
            AssemblyError::NotPositiveDefinite {
                what: what.to_string(),
                detail: format!("{e:?}"),
            }
        })?;
        crate::simd::clear_upper_state();
        Ok(Self { n, llt, nnz_l })
    }

    pub fn n(&self) -> usize {
        self.n
    }

    /// nnz(L): entries of the factor's lower triangle, diagonal included.
    pub fn nnz_l(&self) -> usize {
        self.nnz_l
    }

    /// Floating-point operations of one right-hand side's forward and backward substitutions:
    /// each off-diagonal entry of L one multiply and one add per sweep, each diagonal entry one
    /// division per sweep, 4·nnz(L) − 2n (faer's supernodal solve makes exactly these, as a
    /// dense triangular solve and a product per supernode). The permutations are copies.
    pub fn solve_flops(&self) -> u64 {
        (4 * self.nnz_l - 2 * self.n) as u64
    }

    /// Solves in place for every column of `rhs` (n × k).
    pub fn solve_in_place(&self, rhs: &mut Mat<f64>) {
        self.llt.solve_in_place(rhs.as_mut());
        crate::simd::clear_upper_state();
    }

    /// Solves in place for every column of a view (n × k).
    pub fn solve_view_in_place(&self, rhs: MatMut<'_, f64>) {
        self.llt.solve_in_place(rhs);
        crate::simd::clear_upper_state();
    }

    /// Solves for one right-hand side, in place.
    pub fn solve_vec_in_place(&self, rhs: &mut [f64]) {
        let mut m = Mat::from_fn(self.n, 1, |i, _| rhs[i]);
        self.solve_in_place(&mut m);
        for (i, r) in rhs.iter_mut().enumerate() {
            *r = m[(i, 0)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn factor_of(n: usize, triplets: &[(usize, usize, f64)]) -> (SparseSpd, bool) {
        let spd = SparseSpd::factorize(n, triplets, "test").unwrap();
        let lower: Vec<_> = triplets
            .iter()
            .filter(|t| t.0 >= t.1)
            .map(|&(i, j, v)| Triplet::new(i, j, v))
            .collect();
        let mat = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &lower).unwrap();
        let s =
            cholesky::factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, Default::default(), Default::default())
                .unwrap();
        (spd, matches!(s.raw(), SymbolicCholeskyRaw::Supernodal(_)))
    }

    #[test]
    fn tridiagonal_factor_has_no_fill() {
        // A path graph: any elimination order AMD picks (leaves first) makes no fill, so L has
        // the n diagonal and n − 1 off-diagonal entries.
        let n = 7;
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 4.0));
            if i > 0 {
                t.push((i, i - 1, -1.0));
                t.push((i - 1, i, -1.0));
            }
        }
        let (spd, supernodal) = factor_of(n, &t);
        assert!(!supernodal, "a 7 × 7 tridiagonal matrix is factored simplicially");
        assert_eq!(spd.nnz_l(), 2 * n - 1);
        assert_eq!(spd.solve_flops(), (4 * (2 * n - 1) - 2 * n) as u64);
    }

    #[test]
    fn dense_factor_counts_its_whole_lower_triangle() {
        // A dense SPD matrix (n + 1 on the diagonal, 1 elsewhere): L is full whatever the
        // ordering, n(n + 1)/2 entries; faer factors it with supernodes.
        let n = 120;
        let t: Vec<_> = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j, if i == j { n as f64 + 1.0 } else { 1.0 })))
            .collect();
        let (spd, supernodal) = factor_of(n, &t);
        assert!(supernodal, "a dense 120 × 120 matrix is factored with supernodes");
        assert_eq!(spd.nnz_l(), n * (n + 1) / 2);
        // Forward and backward: n(n − 1) multiply-adds and n divisions each.
        assert_eq!(spd.solve_flops(), 2 * (n * (n - 1) + n) as u64);
    }
}
