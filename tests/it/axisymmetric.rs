//! Axisymmetric scenes end to end: the shipped press fit, pushed axially out of its hub, as
//! LATIN solves it in-process and as processes, against the reference and against what friction
//! can hold. (The element and the interface weights are checked against Lamé in the reference
//! crate's tests.)

use crate::common::{glissade_ok, output_file, scene, scene_text, scratch};
use glissade_messages::Verdict;

/// `check` says the plane; the press fit's run: converged; the push on the shaft's top balances the axial friction force
/// on the fit at every time point (the shaft's axial equilibrium, its one rigid motion), and the
/// hub's seat carries the same force back; the radial column and the moments, not resultants in
/// axisymmetry, are empty (NaN); forces are in N (totals over the circumference) as the headers
/// say. Once the whole fit slips the push is f = 0.15 times the normal force. The load rises
/// with the push until then, never beyond.
///
/// Tolerances: the balances hold to round-off of sums over 33 pairs (1e-9 of the capacity, as
/// for the lap joint); the slip limit holds at the accuracy asked (1e-4 of the tractions; the
/// local stage puts slipping pairs exactly on the cone, 1e-6 measured), 1e-5 asserted.
#[test]
fn a_press_fit_pushed_out_of_its_hub_holds_f_times_its_normal_force() {
    press_fit_holds_f_times_its_normal_force("press-fit-axisymmetric");
}

/// The same with the shaft and the hub meshed on their own (16 and 11 elements along the fit: a
/// non-matching interface whose pairs are the hub's nodes, its normal out of the hub): the same
/// balances and limits hold; its frame is turned (normal −r, tangent −z), which leaves the
/// tangential resultant's sign against the push as it is.
#[test]
fn a_press_fit_meshed_on_its_own_holds_f_times_its_normal_force() {
    press_fit_holds_f_times_its_normal_force("press-fit-axisymmetric-nonmatching");
}

fn press_fit_holds_f_times_its_normal_force(name: &str) {
    let dir = scratch(name);
    let scene_path = format!("{}/launch/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let checked = glissade_ok(&[&"check", &scene_path]);
    assert!(checked.contains("plane: axisymmetric (x = r, y = z;"), "{checked}");
    // The hub (11 elements along the fit) carries the pairs of the one meshed on its own.
    assert_eq!(
        checked.contains("interface 0 (`hub` – `shaft`): non-matching, 23 pairs on the nodes of `hub`"),
        name.ends_with("nonmatching"),
        "{checked}"
    );
    let out = glissade_ok(&[&"run", &scene_path, &"--in-process", &"--no-record", &"--out", &dir.0]);
    assert!(out.contains("Converged"), "{out}");
    assert!(out.contains("support boundary[1] at t = 1: R = (—, "), "{out}");
    let text = |ending: &str| std::fs::read_to_string(output_file(&dir.0, ending)).unwrap();
    let boundaries = text(".boundaries.csv");
    let resultants = text(".resultants.csv");
    assert!(
        boundaries.starts_with("time_s,rule,kind,force_x_N,force_y_N,"),
        "{boundaries}"
    );
    assert!(resultants.contains(",normal_N,tangential_N,"), "{resultants}");
    // Meshed on their own, fields.json gives both sides' displacements at the fit's pairs (side
    // b's projected there): their difference is the jump, in each pair's frame (round-off of one
    // subtraction and a dot product on displacements of ~1e-2 mm).
    let fields: serde_json::Value = serde_json::from_str(&text(".fields.json")).unwrap();
    let fit = &fields["interfaces"][0];
    assert_eq!(fit["u_a"].is_array(), name.ends_with("nonmatching"), "{}", fit["a"]);
    if let (Some(u_a), Some(u_b)) = (fit["u_a"].as_array(), fit["u_b"].as_array()) {
        let normals = fit["normals"].as_array().map(|n| n.to_vec());
        let normal = fit["normal"].clone();
        for (i, (ua, ub)) in u_a.iter().zip(u_b).enumerate() {
            for (p, (a, b)) in ua.as_array().unwrap().iter().zip(ub.as_array().unwrap()).enumerate() {
                let n = normals.as_ref().map_or(normal.clone(), |n| n[p].clone());
                let d = [0, 1].map(|c| b[c].as_f64().unwrap() - a[c].as_f64().unwrap());
                let jump_n = d[0] * n[0].as_f64().unwrap() + d[1] * n[1].as_f64().unwrap();
                let want = fit["jump_n"][i][p].as_f64().unwrap();
                assert!(
                    (jump_n - want).abs() <= 1e-15,
                    "time point {i}, pair {p}: {jump_n} against {want}"
                );
            }
        }
    }
    let rows = |csv: &str, keep: &dyn Fn(&[&str]) -> bool| -> Vec<Vec<f64>> {
        csv.lines()
            .skip(1)
            .map(|l| l.split(',').collect::<Vec<_>>())
            .filter(|c| keep(c))
            .map(|c| c.iter().map(|v| v.parse().unwrap_or(f64::NAN)).collect())
            .collect()
    };
    let press = rows(&boundaries, &|c| c[1] == "boundary[1]");
    let seat = rows(&boundaries, &|c| c[1] == "boundary[0]");
    let fit = rows(&resultants, &|c| c[4] == "contact");
    assert_eq!((press.len(), seat.len(), fit.len()), (41, 41, 41));
    let capacity = 0.15 * fit.iter().map(|r| r[7].abs()).fold(0.0, f64::max);
    let (mut gross, mut previous) = (0, 0.0f64);
    for ((p, s), c) in press.iter().zip(&seat).zip(&fit) {
        let (t, push, normal, tangential, slip) = (p[0], p[4], c[7], c[8], c[11]);
        assert!(p[3].is_nan() && p[5].is_nan() && s[3].is_nan(), "t = {t}: {p:?}");
        // The fit's normal is +r out of the shaft when the shaft is side a, its tangent +z: the
        // hub's friction on the shaft along +z balances the press. (Meshed on their own, the hub
        // is side a: normal −r, tangent −z, the hub's friction force along −z, the same sign.)
        assert!(
            (push + tangential).abs() <= 1e-9 * capacity,
            "t = {t}: {push} vs {tangential}"
        );
        assert!((push + s[4]).abs() <= 1e-9 * capacity, "t = {t}: seat {}", s[4]);
        assert!(tangential.abs() <= 0.15 * normal.abs() * (1.0 + 1e-5), "t = {t}");
        if slip >= 1.0 - 1e-9 {
            gross += 1;
            assert!(
                (tangential.abs() - 0.15 * normal.abs()).abs() <= 1e-5 * capacity,
                "t = {t}"
            );
        }
        if t >= 0.2 {
            assert!(
                push.abs() >= previous * (1.0 - 1e-6),
                "t = {t}: {push} after {previous}"
            );
            previous = push.abs();
        }
    }
    assert!(gross >= 10, "the shaft slides out from t ≈ 0.65 ({gross} time points)");
    // The push once the whole fit slips: 35 238 N on the conforming mesh (docs/scenes.md); the
    // mesh meshed on its own within 1 % of it (the discretisation of the fit differs).
    assert!(
        (previous - 35_238.0).abs() <= 0.01 * 35_238.0,
        "push at t = 1: {previous} N against 35 238 N"
    );
    assert!(text(".boundaries.svg").contains("boundary[1]: Ry against uy"));
}

/// LATIN on the axisymmetric press fit against the monolithic reference on the same discrete
/// problem: at each accuracy the run's stop on its estimate (1e-2, 1e-3, 1e-4) the true
/// contact-traction error is within it (the stop on accuracy allows 3×; measured: 1e-4 reached at
/// iteration 43 of 94, final error 2.3e-6); and as processes the run is the in-process one bit
/// for bit.
#[test]
fn the_axisymmetric_press_fit_meets_its_accuracy_and_runs_as_processes() {
    meets_its_accuracy_and_runs_as_processes("press-fit-axisymmetric");
}

/// The same with the shaft and the hub meshed on their own: the reference solves the same
/// non-matching discrete problem (side b through its projection), and LATIN's stops on its
/// estimate are within their accuracy of it.
#[test]
fn the_press_fit_meshed_on_its_own_meets_its_accuracy_and_runs_as_processes() {
    meets_its_accuracy_and_runs_as_processes("press-fit-axisymmetric-nonmatching");
}

fn meets_its_accuracy_and_runs_as_processes(name: &str) {
    let sc = scene(&scene_text(name));
    assert_eq!(sc.model.plane, glissade_mechanics::model::Plane::Axisymmetric);
    let check = glissade::accuracy::check_scene(name, &sc, &Default::default()).unwrap();
    for stop in &check.stops {
        let err = stop.true_error.expect("a stop with a true error");
        assert!(
            err <= stop.accuracy,
            "accuracy {:e}: true error {err:e} at iteration {:?}",
            stop.accuracy,
            stop.iteration
        );
    }
    let local = crate::distributed::in_process_equals_processes(&sc, &format!("{name}-processes"));
    assert_eq!(local.verdict, Verdict::Converged);
}
