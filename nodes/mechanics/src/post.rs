//! Post-processing of a subdomain's displacement: nodal stresses (the average, over the elements
//! sharing a node, of each element's stress at that node) and the von Mises stress.

use crate::element::{BadElement, Elasticity, NODE_XI};
use crate::model::{Plane, Subdomain};
use nalgebra::SVector;

/// Stress at a node (MPa): σ_xx, σ_yy, σ_zz, σ_xy. σ_zz = ν(σ_xx + σ_yy) in plane strain, 0 in
/// plane stress; in axisymmetry (x = r, y = z) σ_rr, σ_zz, σ_θθ (the hoop stress), σ_rz.
pub type NodalStress = [f64; 4];

/// Nodal stresses of subdomain `sub` under the displacement `u` (2 values per node, x then y):
/// per node, the average of the stresses of the elements sharing it, each evaluated at the node.
/// Written into `out` (one entry per node); `count` is scratch of the same length.
pub fn nodal_stresses_into(
    sub: &Subdomain,
    plane: Plane,
    u: &[f64],
    out: &mut [NodalStress],
    count: &mut [u32],
) -> Result<(), BadElement> {
    let n = sub.mesh.coords.len();
    assert_eq!(u.len(), 2 * n, "displacement of {} values for {n} nodes", u.len());
    assert_eq!(out.len(), n);
    assert_eq!(count.len(), n);
    let elasticity = Elasticity::new(sub.material, plane);
    out.fill([0.0; 4]);
    count.fill(0);
    for el in &sub.mesh.elements {
        let x: [[f64; 2]; 8] = std::array::from_fn(|a| sub.mesh.coords[el[a]]);
        let ue = SVector::<f64, 16>::from_fn(|r, _| u[2 * el[r / 2] + r % 2]);
        for (a, xi) in NODE_XI.iter().enumerate() {
            let sig = elasticity.stress(&x, &ue, xi[0], xi[1])?;
            let s = &mut out[el[a]];
            for c in 0..4 {
                s[c] += sig[c];
            }
            count[el[a]] += 1;
        }
    }
    for (s, c) in out.iter_mut().zip(count.iter()) {
        let c = (*c).max(1) as f64;
        s.iter_mut().for_each(|v| *v /= c);
    }
    Ok(())
}

/// [`nodal_stresses_into`] into a new vector.
pub fn nodal_stresses(sub: &Subdomain, plane: Plane, u: &[f64]) -> Result<Vec<NodalStress>, BadElement> {
    let n = sub.mesh.coords.len();
    let mut out = vec![[0.0; 4]; n];
    let mut count = vec![0; n];
    nodal_stresses_into(sub, plane, u, &mut out, &mut count)?;
    Ok(out)
}

/// Von Mises stress (MPa) of a stress (σ_xx, σ_yy, σ_zz, σ_xy).
pub fn von_mises(s: &NodalStress) -> f64 {
    let [sx, sy, sz, txy] = *s;
    (0.5 * ((sx - sy).powi(2) + (sy - sz).powi(2) + (sz - sx).powi(2)) + 3.0 * txy * txy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;
    use crate::model::Material;

    fn block(corners: [[f64; 2]; 4], material: Material) -> Subdomain {
        let mesh = Mesh::structured(corners, 3, 2);
        let n = mesh.coords.len();
        Subdomain {
            name: "block".into(),
            mesh,
            material,
            constrained: vec![false; 2 * n],
            loads: Vec::new(),
        }
    }

    /// Patch test: a linear displacement field is reproduced exactly by QUA8 elements, so every
    /// nodal stress is the constant stress of Hooke's law, on a distorted mesh too. Tolerance:
    /// 1e-9 relative to the stress level covers the round-off of the Jacobian inverse.
    #[test]
    fn a_uniform_strain_gives_the_stress_of_hookes_law_at_every_node() {
        let m = Material { e: 210e3, nu: 0.3 };
        let sub = block([[0.0, 0.0], [3.0, 0.2], [2.7, 2.1], [-0.4, 1.8]], m);
        let (exx, eyy, gxy) = (1e-3, -4e-4, 6e-4);
        let u: Vec<f64> = sub
            .mesh
            .coords
            .iter()
            .flat_map(|&[x, y]| [exx * x + 0.5 * gxy * y, eyy * y + 0.5 * gxy * x])
            .collect();
        for plane in [Plane::Strain, Plane::Stress] {
            let (e, nu) = (m.e, m.nu);
            let (sx, sy, sz) = match plane {
                Plane::Strain => {
                    let lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
                    let mu2 = e / (1.0 + nu);
                    let sx = lam * (exx + eyy) + mu2 * exx;
                    let sy = lam * (exx + eyy) + mu2 * eyy;
                    (sx, sy, nu * (sx + sy))
                }
                Plane::Stress => {
                    let c = e / (1.0 - nu * nu);
                    (c * (exx + nu * eyy), c * (eyy + nu * exx), 0.0)
                }
                Plane::Axisymmetric => unreachable!("a plane field"),
            };
            let txy = e / (2.0 * (1.0 + nu)) * gxy;
            let expected = [sx, sy, sz, txy];
            let scale = expected.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for s in nodal_stresses(&sub, plane, &u).unwrap() {
                for c in 0..4 {
                    assert!(
                        (s[c] - expected[c]).abs() < 1e-9 * scale,
                        "{plane:?}: {s:?} vs {expected:?}"
                    );
                }
            }
        }
    }

    /// Axisymmetric patch test: u_r = a·r, u_z = c·z + g·r is a uniform strain state (ε_rr =
    /// ε_θθ = a, ε_zz = c, γ_rz = g) that QUA8 elements reproduce exactly, on a distorted mesh
    /// with nodes on the axis (where the hoop strain is its limit ∂u_r/∂r): every nodal stress is
    /// 3D Hooke's law, σ_θθ in the third slot. Tolerance as above.
    #[test]
    fn a_uniform_axisymmetric_strain_gives_the_stress_of_hookes_law_at_every_node() {
        let m = Material { e: 70e3, nu: 0.33 };
        let sub = block([[0.0, 0.0], [3.0, 0.2], [2.7, 2.1], [0.0, 1.8]], m);
        assert!(sub.mesh.coords.iter().filter(|p| p[0] == 0.0).count() >= 3);
        let (a, c, g) = (1e-3, -4e-4, 6e-4);
        let u: Vec<f64> = sub
            .mesh
            .coords
            .iter()
            .flat_map(|&[r, z]| [a * r, c * z + g * r])
            .collect();
        let (e, nu) = (m.e, m.nu);
        let lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        let mu2 = e / (1.0 + nu);
        let tr = 2.0 * a + c;
        let expected = [
            lam * tr + mu2 * a,
            lam * tr + mu2 * c,
            lam * tr + mu2 * a,
            0.5 * mu2 * g,
        ];
        let scale = expected.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
        for s in nodal_stresses(&sub, Plane::Axisymmetric, &u).unwrap() {
            for k in 0..4 {
                assert!((s[k] - expected[k]).abs() < 1e-9 * scale, "{s:?} vs {expected:?}");
            }
        }
    }

    /// Von Mises of pure shear τ is √3 τ, of uniaxial σ is |σ| (plane stress).
    #[test]
    fn von_mises_of_pure_shear_and_uniaxial_stress() {
        assert!((von_mises(&[0.0, 0.0, 0.0, 2.0]) - 2.0 * 3f64.sqrt()).abs() < 1e-14);
        assert!((von_mises(&[-5.0, 0.0, 0.0, 0.0]) - 5.0).abs() < 1e-14);
    }
}
