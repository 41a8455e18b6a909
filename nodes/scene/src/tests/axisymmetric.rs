//! `plane = "axisymmetric"`: the axis held, pairs on it left out, weights over the surface of
//! revolution, the axial translation as the only rigid motion, and what is refused.

use super::*;
use glissade_mechanics::model::Plane;

fn axisymmetric(text: &str) -> String {
    text.replacen("name = \"two\"\n", "name = \"two\"\nplane = \"axisymmetric\"\n", 1)
}

/// Two discs stacked on the axis (0 ≤ r ≤ 40) once the top's radial push is moved off the axis:
/// every node on r = 0 has u_r held; the contact interface on z = 20 loses its pair on the axis
/// (weight ∫ N 2πr ds = 0 there) and its weights add up to the disc's area π·40², exactly for
/// straight edges and 3-point Gauss (1e-12 for round-off).
#[test]
fn the_axis_is_held_and_the_weights_sweep_the_disc() {
    let text = axisymmetric(&replaced("ux = \"0.004*sin(2*pi*t)\"\n", ""));
    let s = load(&text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.model.plane, Plane::Axisymmetric);
    for sub in &s.model.subdomains {
        for (n, x) in sub.mesh.coords.iter().enumerate() {
            assert_eq!(sub.constrained[2 * n], x[0] == 0.0 || x[1] == 0.0, "{x:?}");
        }
    }
    let itf = &s.model.interfaces[0];
    assert_eq!(itf.n_pairs(), 32);
    assert!(itf.coords.iter().all(|x| x[0] > 0.0));
    let area = std::f64::consts::PI * 40.0 * 40.0;
    assert!((itf.weights.iter().sum::<f64>() - area).abs() < 1e-12 * area);
}

/// A radial displacement prescribed on the axis, or a node at r < 0, is refused with its place.
#[test]
fn rejects_a_radial_push_on_the_axis_and_negative_radii() {
    let e = expect_err(
        &axisymmetric(TWO_BLOCKS),
        "boundary",
        "prescribes a radial displacement at (x, y) = (0, 40)",
    );
    assert!(e.problem.contains("`upper`"), "{e}");
    let text = axisymmetric(TWO_BLOCKS).replace("x = [0.0, 40.0]", "x = [-10.0, 30.0]");
    let e = expect_err(
        &text,
        "plane",
        "x is the radius r ≥ 0, but `lower` has a node at (x, y) = (-10, 0)",
    );
    assert!(e.problem.contains("move the part to r ≥ 0"), "{e}");
}

/// A ring held only axially (uy = 0 on its base) is held: in axisymmetry a radial motion
/// stretches the hoop and there is no rotation. The same scene in plane strain leaves the
/// x-translation free; with no axial support at all, the axial translation is.
#[test]
fn only_the_axial_translation_is_a_rigid_motion() {
    let ring = TWO_BLOCKS
        .replace("x = [0.0, 40.0]", "x = [10.0, 50.0]")
        .replacen("ux = 0.0\nuy = 0.0", "uy = 0.0", 1);
    let ring = ring.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
    load(&axisymmetric(&ring)).unwrap_or_else(|e| panic!("{e}"));
    expect_err(&ring, "boundary", "x-translation free");
    let loose = axisymmetric(&ring).replacen("uy = 0.0", "p = 1.0", 1);
    let e = expect_err(&loose, "boundary", ": y-translation (along the axis) free;");
    assert!(
        !e.problem.contains("x-translation") && !e.problem.contains("rotation"),
        "{e}"
    );
}

/// The scales of an axisymmetric scene mean what they mean in a plane one: a cylinder
/// 10 ≤ r ≤ 25 mm, 20 mm long, with 100 MPa in its bore has the traction scale of its total load
/// (100 · 2π·10·20 N) over its size and circumference (20 mm · 2π·25 mm), 40 MPa; taken per unit
/// thickness it would be 2π·25 times that. Exact but for round-off.
#[test]
fn an_axisymmetric_scenes_traction_scale_is_a_traction() {
    let text = r#"
plane = "axisymmetric"
[time]
T = 1.0
N = 1
[materials.steel]
E = 210000.0
nu = 0.3
[[block]]
name = "cylinder"
material = "steel"
x = [10.0, 25.0]
y = [0.0, 20.0]
nx = 6
ny = 4
[[boundary]]
y = 0.0
uy = 0.0
[[boundary]]
x = 10.0
p = 100.0
"#;
    let s = load(text).unwrap_or_else(|e| panic!("{e}"));
    let scales = glissade_mechanics::scales::Scales::of(&s.model);
    assert!((scales.traction() - 40.0).abs() < 1e-9 * 40.0, "{}", scales.traction());
}
