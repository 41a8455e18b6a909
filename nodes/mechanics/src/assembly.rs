//! Sparse assembly of QUA8 stiffness matrices and the sparse Cholesky solver used everywhere.

use crate::element::{self, BadElement};
use crate::mesh::Mesh;
use crate::model::{Material, Plane};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{self, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw};
pub use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, MatMut, Par, Side};

/// Errors of assembly and factorisation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssemblyError {
    #[error("element {element}: {source}")]
    BadElement { element: usize, source: BadElement },
    #[error("stiffness matrix of {what} is not positive definite (a rigid-body mode is not blocked or a material is invalid): {detail}")]
    NotPositiveDefinite { what: String, detail: String },
    #[error("sparse matrix of {what} could not be built: {detail}")]
    Sparse { what: String, detail: String },
    #[error(
        "interface {interface} is non-matching (its sides meshed on their own): the monolithic solvers merge or pair \
         coinciding nodes and solve only interfaces whose nodes coincide"
    )]
    NonMatching { interface: usize },
}

/// The first non-matching interface of `model`, as the error of a solver that needs coinciding
/// nodes.
pub fn refuse_non_matching(model: &crate::model::Model) -> Result<(), AssemblyError> {
    match model.interfaces.iter().position(|i| i.is_non_matching()) {
        Some(interface) => Err(AssemblyError::NonMatching { interface }),
        None => Ok(()),
    }
}

/// Element stiffness triplets (row, col, value) of a whole mesh, in global dof numbering
/// (dof 2i = x of node i, 2i+1 = y). Both triangles are emitted.
pub fn stiffness_triplets(
    mesh: &Mesh,
    material: Material,
    plane: Plane,
) -> Result<Vec<(usize, usize, f64)>, AssemblyError> {
    let elasticity = element::Elasticity::new(material, plane);
    let mut out = Vec::with_capacity(mesh.elements.len() * 256);
    for (e, conn) in mesh.elements.iter().enumerate() {
        let x: [[f64; 2]; 8] = std::array::from_fn(|k| mesh.coords[conn[k]]);
        let ke = elasticity
            .stiffness(&x)
            .map_err(|source| AssemblyError::BadElement { element: e, source })?;
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

/// A factorised sparse SPD matrix (faer sparse Cholesky, lower side, AMD ordering).
pub struct SparseSpd {
    n: usize,
    /// Boxed: the structure is large and callers hold factors by value.
    symbolic: Box<SymbolicCholesky<usize>>,
    /// The factor's values, laid out as `symbolic` says.
    values: Vec<f64>,
    /// Entries of the lower triangle of the factor L, diagonal included, as faer stores it (a
    /// supernode's dense block counts whole, explicit zeros and all).
    nnz_l: usize,
}

impl SparseSpd {
    /// Factorises the n × n matrix given by `triplets` (duplicates add; only the lower triangle
    /// is read). `what` names the matrix in errors. faer chooses between its simplicial and
    /// supernodal variants (for 2D QUA8 meshes of a few thousand dofs, simplicial).
    pub fn factorize(n: usize, triplets: &[(usize, usize, f64)], what: &str) -> Result<Self, AssemblyError> {
        Self::factorize_with(n, triplets, what, SupernodalThreshold::AUTO)
    }

    /// As [`SparseSpd::factorize`], always supernodal: the factor's columns are grouped into
    /// dense blocks, so that a solve for many right-hand sides (A_E's n_b columns, a sparse
    /// linear stage's N + 1 time points) runs dense products per block instead of one sparse
    /// sweep per column. On a 20 × 20 QUA8 subdomain (`cargo bench -p glissade-mechanics --bench
    /// kernel`) its 328-column solve is 2.2× faster than the simplicial one and its factorisation
    /// about 2× faster. The same factor to round-off, not bit for bit.
    pub fn factorize_supernodal(n: usize, triplets: &[(usize, usize, f64)], what: &str) -> Result<Self, AssemblyError> {
        Self::factorize_with(n, triplets, what, SupernodalThreshold::FORCE_SUPERNODAL)
    }

    /// As [`SparseSpd::factorize`], with faer's threshold between its simplicial and
    /// supernodal variants.
    pub fn factorize_with(
        n: usize,
        triplets: &[(usize, usize, f64)],
        what: &str,
        threshold: SupernodalThreshold,
    ) -> Result<Self, AssemblyError> {
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
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: threshold,
            ..Default::default()
        };
        let symbolic = cholesky::factorize_symbolic_cholesky(mat.symbolic(), Side::Lower, Default::default(), params)
            .map_err(sparse_error)?;
        let nnz_l = factor_nnz(&symbolic);
        let mut values = vec![0.0; symbolic.len_val()];
        let scratch = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
        symbolic
            .factorize_numeric_llt::<f64>(
                &mut values,
                mat.as_ref(),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut MemBuffer::new(scratch)),
                Default::default(),
            )
            .map_err(|e| AssemblyError::NotPositiveDefinite {
                what: what.to_string(),
                detail: format!("{e:?}"),
            })?;
        crate::simd::clear_upper_state();
        Ok(Self {
            n,
            symbolic: Box::new(symbolic),
            values,
            nnz_l,
        })
    }

    /// Whether the factor is supernodal (else simplicial).
    pub fn is_supernodal(&self) -> bool {
        matches!(self.symbolic.raw(), SymbolicCholeskyRaw::Supernodal(_))
    }

    pub fn n(&self) -> usize {
        self.n
    }

    /// nnz(L): entries of the factor's lower triangle, diagonal included.
    pub fn nnz_l(&self) -> usize {
        self.nnz_l
    }

    /// The diagonal of the factor L (in the factor's own, permuted, order): L_ii² are the
    /// pivots of the elimination.
    pub fn factor_diagonal(&self) -> Vec<f64> {
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(simplicial) => {
                // Each column's entries start with its diagonal.
                simplicial.col_ptr()[..self.n].iter().map(|&p| self.values[p]).collect()
            }
            SymbolicCholeskyRaw::Supernodal(supernodal) => {
                let mut d = Vec::with_capacity(self.n);
                for k in 0..supernodal.n_supernodes() {
                    let cols = supernodal.supernode_end()[k] - supernodal.supernode_begin()[k];
                    let rows = cols + supernodal.supernode(k).pattern().len();
                    // The supernode's block is column-major, `rows` × `cols`, its top square
                    // holding the diagonal.
                    let start = supernodal.col_ptr_for_val()[k];
                    d.extend((0..cols).map(|i| self.values[start + i * rows + i]));
                }
                d
            }
        }
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
        self.solve_view_in_place(rhs.as_mut());
    }

    /// Solves in place for every column of a view (n × k), with scratch of its own.
    pub fn solve_view_in_place(&self, rhs: MatMut<'_, f64>) {
        let mut scratch = self.solve_scratch(rhs.ncols());
        self.solve_view_in_place_with(rhs, &mut scratch);
    }

    /// Scratch for [`SparseSpd::solve_view_in_place_with`] of up to `ncols` right-hand sides,
    /// to allocate once outside a loop.
    pub fn solve_scratch(&self, ncols: usize) -> MemBuffer {
        MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(ncols, Par::Seq))
    }

    /// Solves in place for every column of a view (n × k) without allocating: `scratch` comes
    /// from [`SparseSpd::solve_scratch`] of at least k columns (faer panics on less).
    pub fn solve_view_in_place_with(&self, rhs: MatMut<'_, f64>, scratch: &mut MemBuffer) {
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(scratch),
        );
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
        let supernodal = spd.is_supernodal();
        (spd, supernodal)
    }

    /// Σ 2 ln L_ii = ln det A for a simplicial and a supernodal factor alike: the diagonal is
    /// read where each layout keeps it.
    #[test]
    fn factor_diagonal_gives_the_determinant() {
        // A 2D grid Laplacian plus a shift (SPD), large enough for supernodes.
        let side = 12;
        let n = side * side;
        let mut t = Vec::new();
        for i in 0..side {
            for j in 0..side {
                let p = i * side + j;
                t.push((p, p, 4.5));
                if i > 0 {
                    t.push((p, p - side, -1.0));
                    t.push((p - side, p, -1.0));
                }
                if j > 0 {
                    t.push((p, p - 1, -1.0));
                    t.push((p - 1, p, -1.0));
                }
            }
        }
        let mut dense = Mat::<f64>::zeros(n, n);
        for &(i, j, v) in &t {
            dense[(i, j)] += v;
        }
        let l = dense.llt(Side::Lower).unwrap();
        let log_det: f64 = (0..n).map(|i| 2.0 * l.L()[(i, i)].ln()).sum();
        for spd in [
            SparseSpd::factorize_with(n, &t, "test", SupernodalThreshold::FORCE_SIMPLICIAL).unwrap(),
            SparseSpd::factorize_supernodal(n, &t, "test").unwrap(),
        ] {
            let d = spd.factor_diagonal();
            assert_eq!(d.len(), n);
            let sparse_log_det: f64 = d.iter().map(|x| 2.0 * x.ln()).sum();
            // ln det ≈ 200 here; both sums round n terms of order 1.
            assert!(
                (sparse_log_det - log_det).abs() < 1e-10 * log_det.abs(),
                "supernodal {}: ln det {sparse_log_det} against {log_det}",
                spd.is_supernodal()
            );
        }
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

    #[test]
    fn supernodal_and_simplicial_factors_solve_alike() {
        // The 5-point Laplacian of a 30 × 30 grid plus the identity (SPD, condition ≈ 9): both
        // variants must return the same solutions for several right-hand sides to round-off;
        // 1e-12 relative is ~10⁴ ulps, far below any difference a wrong factor would make.
        let m = 30;
        let n = m * m;
        let mut t = Vec::new();
        for i in 0..m {
            for j in 0..m {
                let k = i * m + j;
                t.push((k, k, 5.0));
                if i > 0 {
                    t.push((k, k - m, -1.0));
                    t.push((k - m, k, -1.0));
                }
                if j > 0 {
                    t.push((k, k - 1, -1.0));
                    t.push((k - 1, k, -1.0));
                }
            }
        }
        let sup = SparseSpd::factorize_supernodal(n, &t, "test").unwrap();
        let simp = SparseSpd::factorize_with(n, &t, "test", SupernodalThreshold::FORCE_SIMPLICIAL).unwrap();
        assert!(sup.is_supernodal() && !simp.is_supernodal());
        let rhs = Mat::<f64>::from_fn(n, 7, |i, c| ((i * 31 + c * 17) % 13) as f64 - 6.0);
        let (mut a, mut b) = (rhs.clone(), rhs.clone());
        sup.solve_in_place(&mut a);
        simp.solve_in_place(&mut b);
        let scale = b.norm_max();
        assert!(scale > 0.1);
        assert!((&a - &b).norm_max() <= 1e-12 * scale, "{}", (&a - &b).norm_max());
        // And it is a solution: the residual of A x = rhs.
        let mut ax = Mat::<f64>::zeros(n, 7);
        for &(i, j, v) in &t {
            for c in 0..7 {
                ax[(i, c)] += v * a[(j, c)];
            }
        }
        let residual = (&ax - &rhs).norm_max();
        assert!(residual <= 1e-12 * scale, "residual {residual}");
    }
}
