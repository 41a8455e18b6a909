//! Sparse assembly of QUA8 stiffness matrices and the sparse Cholesky solver used everywhere.

use crate::element::{self, BadElement};
use crate::mesh::Mesh;
use crate::model::{Material, Plane};
use faer::linalg::solvers::Solve;
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

/// A factorised sparse SPD matrix (faer sparse Cholesky, lower side). The symbolic
/// factorisation can be reused for matrices of the same pattern.
pub struct SparseSpd {
    n: usize,
    llt: Llt<usize, f64>,
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
        let symbolic = SymbolicLlt::try_new(mat.symbolic(), Side::Lower).map_err(|e| AssemblyError::Sparse {
            what: what.to_string(),
            detail: format!("{e:?}"),
        })?;
        let llt = Llt::try_new_with_symbolic(symbolic, mat.as_ref(), Side::Lower).map_err(|e| {
            AssemblyError::NotPositiveDefinite {
                what: what.to_string(),
                detail: format!("{e:?}"),
            }
        })?;
        Ok(Self { n, llt })
    }

    pub fn n(&self) -> usize {
        self.n
    }

    /// Solves in place for every column of `rhs` (n × k).
    pub fn solve_in_place(&self, rhs: &mut Mat<f64>) {
        self.llt.solve_in_place(rhs.as_mut());
    }

    /// Solves in place for every column of a view (n × k).
    pub fn solve_view_in_place(&self, rhs: MatMut<'_, f64>) {
        self.llt.solve_in_place(rhs);
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
