//! The QUA8 element: serendipity shape functions, 3×3 Gauss quadrature, isotropic elasticity
//! (plane strain or plane stress of unit thickness, or axisymmetric with 2πr in every integral)
//! and 3-node edge integrals.

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

/// Elasticity matrix D (MPa) for Voigt strains (ε_xx, ε_yy, γ_xy); in axisymmetry its in-plane
/// block (ε_rr, ε_zz, γ_rz), the plane-strain one ([`elasticity_axisymmetric`] has the hoop
/// strain too).
pub fn elasticity(m: Material, plane: Plane) -> SMatrix<f64, 3, 3> {
    let (e, nu) = (m.e, m.nu);
    match plane {
        Plane::Strain | Plane::Axisymmetric => {
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

/// Elasticity matrix D (MPa) of axisymmetry for strains (ε_rr, ε_zz, γ_rz, ε_θθ).
pub fn elasticity_axisymmetric(m: Material) -> SMatrix<f64, 4, 4> {
    let (e, nu) = (m.e, m.nu);
    let c = e / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let (a, b, g) = (c * (1.0 - nu), c * nu, c * (1.0 - 2.0 * nu) / 2.0);
    SMatrix::<f64, 4, 4>::new(a, b, 0.0, b, b, a, 0.0, b, 0.0, 0.0, g, 0.0, b, b, 0.0, a)
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

/// A point within this fraction of its element's size (or, for the scene builder, of the scene's
/// size) from r = 0 is on the axis: its u_r is held and its hoop strain is ∂u_r/∂r.
pub const AXIS_TOLERANCE: f64 = 1e-9;

/// Axisymmetric strain–displacement matrix B (4 × 16: ε_rr, ε_zz, γ_rz, ε_θθ = u_r/r), det J
/// and the radius r at (ξ, η). On the axis (r = 0, where u_r = 0) the hoop strain is its limit
/// ∂u_r/∂r; quadrature points are never there.
pub fn strain_displacement_axisymmetric(
    x: &[[f64; 2]; 8],
    xi: f64,
    eta: f64,
) -> Result<(SMatrix<f64, 4, 16>, f64, f64), BadElement> {
    let (b3, det) = strain_displacement(x, xi, eta)?;
    let (n, _) = shape(xi, eta);
    let r: f64 = (0..8).map(|k| n[k] * x[k][0]).sum();
    let mut b = SMatrix::<f64, 4, 16>::zeros();
    b.fixed_view_mut::<3, 16>(0, 0).copy_from(&b3);
    let scale = element_size(x);
    for k in 0..8 {
        b[(3, 2 * k)] = if r > AXIS_TOLERANCE * scale {
            n[k] / r
        } else {
            b3[(0, 2 * k)]
        };
    }
    Ok((b, det, r))
}

/// The largest coordinate extent of an element (mm), the scale "on the axis" is judged at.
fn element_size(x: &[[f64; 2]; 8]) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in x {
        for c in 0..2 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    (hi[0] - lo[0]).max(hi[1] - lo[1])
}

/// Isotropic elasticity of one material under a plane, built once for all the elements of a
/// part: the element stiffness and the stresses, in the plane or with the hoop strain.
#[derive(Debug, Clone, Copy)]
pub enum Elasticity {
    /// Plane strain or stress: D on (ε_xx, ε_yy, γ_xy); σ_zz = ν(σ_xx + σ_yy) with `nu_zz =
    /// Some(ν)` (plane strain), 0 with None (plane stress).
    Plane { d: SMatrix<f64, 3, 3>, nu_zz: Option<f64> },
    /// Axisymmetry: D on (ε_rr, ε_zz, γ_rz, ε_θθ).
    Axisymmetric(SMatrix<f64, 4, 4>),
}

impl Elasticity {
    pub fn new(material: Material, plane: Plane) -> Self {
        match plane {
            Plane::Axisymmetric => Elasticity::Axisymmetric(elasticity_axisymmetric(material)),
            Plane::Strain => Elasticity::Plane {
                d: elasticity(material, plane),
                nu_zz: Some(material.nu),
            },
            Plane::Stress => Elasticity::Plane {
                d: elasticity(material, plane),
                nu_zz: None,
            },
        }
    }

    /// Element stiffness: [`stiffness`] in plane strain or stress, Σ_gp Bᵀ D B det J w 2πr with
    /// the hoop strain in axisymmetry.
    pub fn stiffness(&self, x: &[[f64; 2]; 8]) -> Result<ElementMatrix, BadElement> {
        let d = match self {
            Elasticity::Plane { d, .. } => return stiffness(x, d),
            Elasticity::Axisymmetric(d) => d,
        };
        let mut k = ElementMatrix::zeros();
        for &(xi, wx) in &GAUSS3 {
            for &(eta, wy) in &GAUSS3 {
                let (b, det, r) = strain_displacement_axisymmetric(x, xi, eta)?;
                let db = d * b;
                k += b.transpose() * db * (det * wx * wy * Plane::Axisymmetric.measure([r, 0.0]));
            }
        }
        Ok(k)
    }

    /// Stress (σ_xx, σ_yy, σ_zz, σ_xy) at (ξ, η) from element nodal displacements `u` (16): σ_zz
    /// is ν(σ_xx + σ_yy) in plane strain, 0 in plane stress, and in axisymmetry the hoop stress
    /// σ_θθ (x = r, y = z).
    pub fn stress(&self, x: &[[f64; 2]; 8], u: &SVector<f64, 16>, xi: f64, eta: f64) -> Result<[f64; 4], BadElement> {
        match self {
            Elasticity::Plane { d, nu_zz } => {
                let s = stress(x, d, u, xi, eta)?;
                let sz = nu_zz.map_or(0.0, |nu| nu * (s[0] + s[1]));
                Ok([s[0], s[1], sz, s[2]])
            }
            Elasticity::Axisymmetric(d) => {
                let (b, _, _) = strain_displacement_axisymmetric(x, xi, eta)?;
                let s = d * (b * u);
                Ok([s[0], s[1], s[3], s[2]])
            }
        }
    }
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

/// Consistent nodal forces (N; in axisymmetry totals over the circumference) of a traction
/// `traction(position, tangent)` (MPa, global axes) on a 3-node edge (3-point Gauss, against
/// [`Plane::measure`]), the unit tangent taken along the edge's node order: a caller whose edge
/// runs with the body on its left has the outward normal (t_y, −t_x).
pub fn edge_load_along(
    x: &[[f64; 2]; 3],
    plane: Plane,
    traction: impl Fn([f64; 2], [f64; 2]) -> [f64; 2],
) -> [[f64; 2]; 3] {
    let mut f = [[0.0; 2]; 3];
    for &(s, w) in &GAUSS3 {
        let (n, _) = edge_shape(s);
        let (p, t, jac) = edge_frame(x, s);
        let tr = traction(p, t);
        let measure = plane.measure(p);
        for k in 0..3 {
            for c in 0..2 {
                f[k][c] += n[k] * tr[c] * jac * w * measure;
            }
        }
    }
    f
}

/// Lumped edge mass of a 3-node edge: L/6, 4L/6, L/6 with L the edge length (mm); for a curved
/// edge the row sums of the consistent mass; in axisymmetry the row sums of ∫ N_i N_j 2πr ds
/// (mm²). docs/method.md, "The interface mass".
pub fn edge_lumped_mass(x: &[[f64; 2]; 3], plane: Plane) -> [f64; 3] {
    let mut m = [0.0; 3];
    for &(s, w) in &GAUSS3 {
        let (n, _) = edge_shape(s);
        let (p, _, jac) = edge_frame(x, s);
        let measure = plane.measure(p);
        for k in 0..3 {
            m[k] += n[k] * jac * w * measure;
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

    /// An axisymmetric element off the axis has one zero-energy mode, the axial translation: a
    /// radial one stretches the hoop. Its stiffness is symmetric. Tolerances: round-off of sums
    /// of 9 Gauss terms of size ‖K‖.
    #[test]
    fn an_axisymmetric_element_moves_freely_along_the_axis_only() {
        let x: [[f64; 2]; 8] = std::array::from_fn(|k| {
            let [a, b] = NODE_XI[k];
            [5.0 + 1.5 * (a + 1.0) + 0.2 * b, 2.0 * (b + 1.0) + 0.1 * a]
        });
        let k = Elasticity::new(Material { e: 210e3, nu: 0.3 }, Plane::Axisymmetric)
            .stiffness(&x)
            .unwrap();
        let norm = k.norm();
        assert!((k - k.transpose()).norm() < 1e-12 * norm);
        let axial = SVector::<f64, 16>::from_fn(|r, _| (r % 2) as f64);
        let radial = SVector::<f64, 16>::from_fn(|r, _| ((r + 1) % 2) as f64);
        assert!((k * axial).norm() < 1e-10 * norm);
        assert!((k * radial).norm() > 1e-3 * norm);
        let eig = k.symmetric_eigenvalues();
        let zero = eig.iter().filter(|v| v.abs() < 1e-9 * norm).count();
        assert_eq!(zero, 1, "{eig:?}");
    }

    /// In axisymmetry an edge's weights are ∫ N_i 2πr ds: a radial edge from r = 1 to 3 has the
    /// annulus' area π(3² − 1²) in all; straight edges make them exact for 3-point Gauss.
    #[test]
    fn axisymmetric_edge_weights_sum_to_the_surface_they_sweep() {
        let m = edge_lumped_mass(&[[1.0, 4.0], [2.0, 4.0], [3.0, 4.0]], Plane::Axisymmetric);
        let area = std::f64::consts::PI * (9.0 - 1.0);
        assert!((m.iter().sum::<f64>() - area).abs() < 1e-12 * area);
        // ∫ N_0 2πr dr over [1, 3]: the end at r = 1 carries less than the one at r = 3.
        assert!(m[0] < m[2]);
        let f = edge_load_along(&[[2.0, 0.0], [2.0, 1.0], [2.0, 3.0]], Plane::Axisymmetric, |_, _| {
            [1.0, 0.0]
        });
        let total: f64 = f.iter().map(|v| v[0]).sum();
        assert!((total - std::f64::consts::TAU * 2.0 * 3.0).abs() < 1e-12);
    }

    #[test]
    fn lumped_edge_mass_is_l6_4l6_l6() {
        let m = edge_lumped_mass(&[[0.0, 0.0], [1.5, 0.0], [3.0, 0.0]], Plane::Strain);
        assert!((m[0] - 0.5).abs() < 1e-14 && (m[1] - 2.0).abs() < 1e-14 && (m[2] - 0.5).abs() < 1e-14);
    }
}
