//! The QUA8 element: serendipity shape functions, 3×3 Gauss quadrature, isotropic elasticity
//! (plane strain or plane stress, unit thickness) and 3-node edge integrals.

use crate::model::{Material, Plane};
use nalgebra::{SMatrix, SVector};

/// 16 × 16 element stiffness (N/mm), dof order (u_x0, u_y0, u_x1, …).
pub type ElementMatrix = SMatrix<f64, 16, 16>;

/// Reference coordinates of the 8 nodes.
pub const NODE_XI: [[f64; 2]; 8] = [
    [-1.0, -1.0],
    [1.0, -1.0],
    [1.0, 1.0],
    [-1.0, 1.0],
    [0.0, -1.0],
    [1.0, 0.0],
    [0.0, 1.0],
    [-1.0, 0.0],
];

/// 3-point Gauss rule on [−1, 1]: (abscissa, weight).
pub const GAUSS3: [(f64, f64); 3] = [
    (-0.774_596_669_241_483_4, 5.0 / 9.0),
    (0.0, 8.0 / 9.0),
    (0.774_596_669_241_483_4, 5.0 / 9.0),
];

/// Shape functions N_i(ξ, η) and their derivatives ∂N_i/∂ξ, ∂N_i/∂η.
pub fn shape(xi: f64, eta: f64) -> ([f64; 8], [[f64; 2]; 8]) {
    let mut n = [0.0; 8];
    let mut d = [[0.0; 2]; 8];
    for (k, &[a, b]) in NODE_XI.iter().enumerate() {
        if k < 4 {
            n[k] = 0.25 * (1.0 + xi * a) * (1.0 + eta * b) * (xi * a + eta * b - 1.0);
            d[k][0] = 0.25 * a * (1.0 + eta * b) * (2.0 * xi * a + eta * b);
            d[k][1] = 0.25 * b * (1.0 + xi * a) * (xi * a + 2.0 * eta * b);
        } else if a == 0.0 {
            n[k] = 0.5 * (1.0 - xi * xi) * (1.0 + eta * b);
            d[k][0] = -xi * (1.0 + eta * b);
            d[k][1] = 0.5 * b * (1.0 - xi * xi);
        } else {
            n[k] = 0.5 * (1.0 + xi * a) * (1.0 - eta * eta);
            d[k][0] = 0.5 * a * (1.0 - eta * eta);
            d[k][1] = -eta * (1.0 + xi * a);
        }
    }
    (n, d)
}

/// Elasticity matrix D (MPa) for Voigt strains (ε_xx, ε_yy, γ_xy).
pub fn elasticity(m: Material, plane: Plane) -> SMatrix<f64, 3, 3> {
    let (e, nu) = (m.e, m.nu);
    match plane {
        Plane::Strain => {
            let c = e / ((1.0 + nu) * (1.0 - 2.0 * nu));
            SMatrix::<f64, 3, 3>::new(
                c * (1.0 - nu),
                c * nu,
                0.0,
                c * nu,
                c * (1.0 - nu),
                0.0,
                0.0,
                0.0,
                c * (1.0 - 2.0 * nu) / 2.0,
            )
        }
        Plane::Stress => {
            let c = e / (1.0 - nu * nu);
            SMatrix::<f64, 3, 3>::new(c, c * nu, 0.0, c * nu, c, 0.0, 0.0, 0.0, c * (1.0 - nu) / 2.0)
        }
    }
}

/// Error raised for an element whose Jacobian is not positive at a Gauss point.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("element Jacobian det J = {det:e} ≤ 0 at (ξ, η) = ({xi}, {eta}): element is inverted or degenerate")]
pub struct BadElement {
    pub det: f64,
    pub xi: f64,
    pub eta: f64,
}

/// The Jacobian J = ∂x/∂ξ of an element at (ξ, η) (rows ξ, η; columns x, y), its determinant,
/// and the shape derivatives there.
pub fn jacobian(x: &[[f64; 2]; 8], xi: f64, eta: f64) -> ([[f64; 2]; 2], f64, [[f64; 2]; 8]) {
    let (_, d) = shape(xi, eta);
    let mut j = [[0.0; 2]; 2];
    for k in 0..8 {
        for r in 0..2 {
            for c in 0..2 {
                j[r][c] += d[k][r] * x[k][c];
            }
        }
    }
    (j, j[0][0] * j[1][1] - j[0][1] * j[1][0], d)
}

/// Strain–displacement matrix B (3 × 16) and det J at (ξ, η).
pub fn strain_displacement(x: &[[f64; 2]; 8], xi: f64, eta: f64) -> Result<(SMatrix<f64, 3, 16>, f64), BadElement> {
    let (j, det, d) = jacobian(x, xi, eta);
    if det <= 0.0 || !det.is_finite() {
        return Err(BadElement { det, xi, eta });
    }
    let inv = [[j[1][1] / det, -j[0][1] / det], [-j[1][0] / det, j[0][0] / det]];
    let mut b = SMatrix::<f64, 3, 16>::zeros();
    for k in 0..8 {
        let dx = inv[0][0] * d[k][0] + inv[0][1] * d[k][1];
        let dy = inv[1][0] * d[k][0] + inv[1][1] * d[k][1];
        b[(0, 2 * k)] = dx;
        b[(1, 2 * k + 1)] = dy;
        b[(2, 2 * k)] = dy;
        b[(2, 2 * k + 1)] = dx;
    }
    Ok((b, det))
}

/// Element stiffness K_e = Σ_gp Bᵀ D B det J w (3 × 3 Gauss), unit thickness.
pub fn stiffness(x: &[[f64; 2]; 8], d: &SMatrix<f64, 3, 3>) -> Result<ElementMatrix, BadElement> {
    let mut k = ElementMatrix::zeros();
    for &(xi, wx) in &GAUSS3 {
        for &(eta, wy) in &GAUSS3 {
            let (b, det) = strain_displacement(x, xi, eta)?;
            let db = d * b;
            k += b.transpose() * db * (det * wx * wy);
        }
    }
    Ok(k)
}

/// Stress (σ_xx, σ_yy, σ_xy) at (ξ, η) from element nodal displacements `u` (16).
pub fn stress(
    x: &[[f64; 2]; 8],
    d: &SMatrix<f64, 3, 3>,
    u: &SVector<f64, 16>,
    xi: f64,
    eta: f64,
) -> Result<SVector<f64, 3>, BadElement> {
    let (b, _) = strain_displacement(x, xi, eta)?;
    Ok(d * (b * u))
}

/// Quadratic 1D shape functions of a 3-node edge (end, middle, end) at s ∈ [−1, 1], and their derivatives.
pub fn edge_shape(s: f64) -> ([f64; 3], [f64; 3]) {
    (
        [0.5 * s * (s - 1.0), 1.0 - s * s, 0.5 * s * (s + 1.0)],
        [s - 0.5, -2.0 * s, s + 0.5],
    )
}

/// Position and unit tangent (along the edge's node order) of a 3-node edge at s ∈ [−1, 1], and
/// |dx/ds|.
pub fn edge_frame(x: &[[f64; 2]; 3], s: f64) -> ([f64; 2], [f64; 2], f64) {
    let (n, dn) = edge_shape(s);
    let mut p = [0.0; 2];
    let mut tan = [0.0; 2];
    for k in 0..3 {
        for c in 0..2 {
            p[c] += n[k] * x[k][c];
            tan[c] += dn[k] * x[k][c];
        }
    }
    let jac = (tan[0] * tan[0] + tan[1] * tan[1]).sqrt();
    (p, [tan[0] / jac, tan[1] / jac], jac)
}

/// Consistent nodal forces (N) of a traction `traction(position, tangent)` (MPa, global axes) on
/// a 3-node edge (3-point Gauss), the unit tangent taken along the edge's node order: a caller
/// whose edge runs with the body on its left has the outward normal (t_y, −t_x).
pub fn edge_load_along(x: &[[f64; 2]; 3], traction: impl Fn([f64; 2], [f64; 2]) -> [f64; 2]) -> [[f64; 2]; 3] {
    let mut f = [[0.0; 2]; 3];
    for &(s, w) in &GAUSS3 {
        let (n, _) = edge_shape(s);
        let (p, t, jac) = edge_frame(x, s);
        let tr = traction(p, t);
        for k in 0..3 {
            for c in 0..2 {
                f[k][c] += n[k] * tr[c] * jac * w;
            }
        }
    }
    f
}

/// Lumped edge mass of a 3-node edge: L/6, 4L/6, L/6 with L the edge length (mm); for a curved
/// edge the row sums of the consistent mass. DESIGN §2.
pub fn edge_lumped_mass(x: &[[f64; 2]; 3]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for &(s, w) in &GAUSS3 {
        let (n, dn) = edge_shape(s);
        let mut tan = [0.0; 2];
        for k in 0..3 {
            for c in 0..2 {
                tan[c] += dn[k] * x[k][c];
            }
        }
        let jac = (tan[0] * tan[0] + tan[1] * tan[1]).sqrt();
        for k in 0..3 {
            m[k] += n[k] * jac * w;
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_functions_partition_unity_and_kronecker() {
        for (k, &[a, b]) in NODE_XI.iter().enumerate() {
            let (n, _) = shape(a, b);
            for (j, nj) in n.iter().enumerate() {
                assert!((nj - if j == k { 1.0 } else { 0.0 }).abs() < 1e-15);
            }
        }
        let (n, d) = shape(0.3, -0.7);
        assert!((n.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert!(d.iter().map(|g| g[0]).sum::<f64>().abs() < 1e-15);
        assert!(d.iter().map(|g| g[1]).sum::<f64>().abs() < 1e-15);
    }

    #[test]
    fn lumped_edge_mass_is_l6_4l6_l6() {
        let m = edge_lumped_mass(&[[0.0, 0.0], [1.5, 0.0], [3.0, 0.0]]);
        assert!((m[0] - 0.5).abs() < 1e-14 && (m[1] - 2.0).abs() < 1e-14 && (m[2] - 0.5).abs() < 1e-14);
    }
}
