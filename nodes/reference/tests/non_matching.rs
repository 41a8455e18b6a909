//! The monolithic reference on non-matching interfaces: the same discrete problem as LATIN's
//! (side b through its projection, a pair of a perfect interface a constraint of its own). The
//! patch test: blocks meshed on their own under one uniform strain give that strain's stress in
//! every element to round-off, for a perfect and for a stuck contact interface, and the solution
//! passes the reference's own checks.

use glissade_mechanics::element::{Elasticity, NODE_XI};
use glissade_reference::{solve_reference, verify, ReferenceOptions};
use nalgebra::SVector;

const E: f64 = 200000.0;
const NU: f64 = 0.3;

/// The exact stress (σ_xx, σ_yy, σ_zz, σ_xy) of the patch's uniform strain, plane strain.
fn exact_stress() -> [f64; 4] {
    let c = E / ((1.0 + NU) * (1.0 - 2.0 * NU));
    let (sxx, syy) = (
        c * ((1.0 - NU) * 1e-4 + NU * -5e-4),
        c * (NU * 1e-4 + (1.0 - NU) * -5e-4),
    );
    [sxx, syy, NU * (sxx + syy), E / (2.0 * (1.0 + NU)) * 2e-4]
}

/// The lower part (y ∈ [0, 5]) in `lower` elements, the upper (y ∈ [5, 10]) in blocks of
/// `upper` = [(x1, nx), …] side by side; top and bottom given u = (1e-4 x + 2e-4 y, −5e-4 y)·t,
/// the lateral sides that too, or (`traction`) the uniform stress's tractions.
fn patch(lower: usize, upper: &[(f64, usize)], contact: bool, traction: bool) -> String {
    let mut s = format!(
        "[time]\nT = 1.0\nN = 1\n[materials.steel]\nE = {E}\nnu = {NU}\n[[block]]\nname = \"low\"\nmaterial = \"steel\"\n\
         x = [0.0, 10.0]\ny = [0.0, 5.0]\nnx = {lower}\nny = 2\n"
    );
    let mut x0 = 0.0;
    for (k, &(x1, nx)) in upper.iter().enumerate() {
        s += &format!(
            "[[block]]\nname = \"up{k}\"\nmaterial = \"steel\"\nx = [{x0}, {x1}]\ny = [5.0, 10.0]\nnx = {nx}\nny = 3\n"
        );
        if contact {
            s += &format!("[[interface]]\nbetween = [\"low\", \"up{k}\"]\nkind = \"contact\"\nfriction = 0.3\n");
        }
        x0 = x1;
    }
    let lateral: &[&str] = if traction {
        let [sxx, _, _, sxy] = exact_stress();
        s += &format!("[[boundary]]\nx = 0.0\ntx = \"{}*t\"\nty = \"{}*t\"\n", -sxx, -sxy);
        s += &format!("[[boundary]]\nx = 10.0\ntx = \"{sxx}*t\"\nty = \"{sxy}*t\"\n");
        &[]
    } else {
        &["x = 0.0", "x = 10.0"]
    };
    for rule in lateral.iter().chain(&["y = 0.0", "y = 10.0"]) {
        s += &format!("[[boundary]]\n{rule}\nux = \"(1e-4*x + 2e-4*y)*t\"\nuy = \"(-5e-4*y)*t\"\n");
    }
    s
}

/// The reference's largest relative stress error over every element's nodes and centre at t = 1.
fn stress_error(text: &str) -> f64 {
    let model = glissade_scene::load_str(text, "patch.toml")
        .unwrap_or_else(|e| panic!("{e}"))
        .model;
    assert!(model.interfaces.iter().any(|i| i.is_non_matching()));
    let sol = solve_reference(&model, &ReferenceOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let checks = verify(&model, &sol).unwrap_or_else(|e| panic!("{e}"));
    // As the other reference tests: every relative violation within the solver's tolerance.
    assert!(checks.max() <= 1e-10, "{checks:?}");
    let c = E / ((1.0 + NU) * (1.0 - 2.0 * NU));
    let (sxx, syy) = (
        c * ((1.0 - NU) * 1e-4 + NU * -5e-4),
        c * (NU * 1e-4 + (1.0 - NU) * -5e-4),
    );
    let exact = [sxx, syy, NU * (sxx + syy), E / (2.0 * (1.0 + NU)) * 2e-4];
    let scale = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut worst = 0.0f64;
    for (s, sub) in model.subdomains.iter().enumerate() {
        let el = Elasticity::new(sub.material, model.plane);
        for conn in &sub.mesh.elements {
            let x = conn.map(|n| sub.mesh.coords[n]);
            let u = SVector::<f64, 16>::from_fn(|k, _| sol.u[s][(2 * conn[k / 2] + k % 2, 1)]);
            for xi in NODE_XI.iter().chain(&[[0.0, 0.0]]) {
                let st = el.stress(&x, &u, xi[0], xi[1]).unwrap();
                for k in 0..4 {
                    worst = worst.max((st[k] - exact[k]).abs() / scale);
                }
            }
        }
    }
    worst
}

/// 1:3, offset (the upper part in two blocks of one element over a lower part of three) and a
/// T-junction (two upper blocks of 3 over a lower part of 8), a perfect and a stuck contact
/// interface, the lateral sides clamped or loaded: the stresses of the exact affine field to
/// round-off of the direct solves (measured below 1e-12; asserted 1e-10). Loaded lateral sides
/// leave an end pair of a one-element side a with nothing to carry (its only edge is modified at
/// the cut): left out, it must not become a constraint of weight 0.
#[test]
fn the_reference_passes_the_patch_test_across_non_matching_meshes() {
    for traction in [false, true] {
        for contact in [false, true] {
            for (lower, upper) in [
                (4, vec![(10.0, 12)]),
                (3, vec![(5.0, 1), (10.0, 1)]),
                (8, vec![(5.0, 3), (10.0, 3)]),
            ] {
                let err = stress_error(&patch(lower, &upper, contact, traction));
                println!(
                    "lower {lower}, upper {upper:?}, contact {contact}, traction {traction}: stress error {err:.2e}"
                );
                assert!(
                    err <= 1e-10,
                    "lower {lower}, upper {upper:?}, contact {contact}, traction {traction}: {err:e}"
                );
            }
        }
    }
}
