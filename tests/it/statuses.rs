//! The reported statuses (docs/accuracy.md, "Stick, slip or open"): stick, slip or separated
//! decided from the converged fields with a margin tied to the accuracy, limit or grazing where
//! the fields cannot tell.

use crate::common::{glissade_ok, output_file, rings, run, scene, scene_text, scratch};
use glissade_mechanics::settled::{agreement, Settled, MARGIN_FACTOR, SETTLED_NAMES};
use glissade_messages::Verdict;

/// The shipped lap joint pulled to 0.04 mm at t = 0.4, held there to t = 0.6 and released, N =
/// 120, at accuracy 1e-3 (the joint of issue 55: the local stage's own statuses changed from
/// one time point of the hold to the next, 12, 5, 11, 0 … pairs slipping under a constant load).
fn held_lap_joint() -> String {
    let text = scene_text("lap-joint")
        .replace("N = 40", "N = 120")
        .replace(
            "ux = { t = [0.0, 0.5, 1.0], v = [0.0, 0.04, 0.0] }",
            "ux = { t = [0.0, 0.4, 0.6, 1.0], v = [0.0, 0.04, 0.04, 0.0] }",
        )
        .replace("accuracy = 1e-4", "accuracy = 1e-3");
    assert!(text.contains("N = 120") && text.contains("0.04, 0.04") && text.contains("1e-3"));
    text
}

/// Against the reference Newton solve of the same discrete problem, judged with the same margins:
/// the statuses agree at every pair-time point that both decide (the issue asks ≥ 99 %; 100 %
/// measured, 1545 points), and most are decided (1545 of 2057 measured; at least half asked, so
/// that a margin swallowing everything fails). During the hold, the joint at its capacity (the
/// pull held at f·N) has every pair on the friction cone without moving: all 17 pairs are
/// "limit", the same at each of the 24 time points, where the local stage's statuses flickered.
#[test]
fn a_held_joint_reports_what_the_reference_does_and_no_flicker() {
    let sc = scene(&held_lap_joint());
    let model = &sc.model;
    let result = run(&sc);
    assert_eq!(result.verdict, Verdict::Converged);
    let reference = glissade_reference::solve_reference(model, &Default::default()).expect("the reference solves it");
    let a = agreement(
        model,
        &result.interface_hat_fields(),
        &reference.interfaces,
        MARGIN_FACTOR,
        1e-3,
    );
    let total = a.agree + a.disagree + a.within_margin;
    assert_eq!(total, 17 * 121);
    assert!(a.share() >= 0.99, "{a:?}");
    assert!(2 * (a.agree + a.disagree) >= total, "most points decided: {a:?}");

    let np = model.interfaces[0].n_pairs();
    let status = &result.interfaces[0].status;
    // The hold: t = 0.4 (time point 48, still pulled) to 0.6 (72); from 49 on the joint stands.
    for i in 49..=72 {
        assert!(
            status[i * np..(i + 1) * np].iter().all(|&s| s == Settled::Limit as u8),
            "time point {i}: {:?}",
            &status[i * np..(i + 1) * np]
        );
    }
    // While pulled beyond the capacity the whole overlap moves: slip, decided.
    assert!(status[47 * np..48 * np].iter().all(|&s| s == Settled::Slip as u8));
}

/// The statuses written are the reported ones, by name, in fields.json, the CSV and the
/// resultants' shares; the summary counts them.
#[test]
fn the_outputs_name_the_statuses_within_the_margins() {
    let dir = scratch("statuses-outputs");
    let path = dir.0.join("lap-hold.toml");
    std::fs::write(&path, held_lap_joint()).unwrap();
    let out = glissade_ok(&[
        &"run",
        &path,
        &"--in-process",
        &"--no-record",
        &"--csv",
        &"--out",
        &dir.0,
    ]);
    assert!(out.contains("Converged"), "{out}");
    let fields: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(output_file(&dir.0, ".fields.json")).unwrap()).unwrap();
    let at = |i: usize| -> Vec<String> {
        fields["interfaces"][0]["status"][i]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_str().unwrap().to_string())
            .collect()
    };
    assert!(at(60).iter().all(|s| s == "limit"), "{:?}", at(60));
    assert!(at(10).iter().all(|s| s == "stick"), "{:?}", at(10));
    let resultants = std::fs::read_to_string(output_file(&dir.0, ".resultants.csv")).unwrap();
    let header = resultants.lines().next().unwrap();
    assert!(header.ends_with("slip_share,limit_share,grazing_share"), "{header}");
    let contact: Vec<Vec<&str>> = resultants
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| c[4] == "contact")
        .collect();
    assert_eq!(contact.len(), 121);
    // limit_share 1 (a sum of weights over the length: to round-off), grazing_share 0 during the
    // hold.
    let share = |c: &str| c.parse::<f64>().unwrap();
    assert!((share(contact[60][12]) - 1.0).abs() < 1e-12, "{:?}", contact[60]);
    assert_eq!(share(contact[60][13]), 0.0, "{:?}", contact[60]);
    let csv = std::fs::read_to_string(output_file(&dir.0, ".interfaces.csv")).unwrap();
    assert!(csv.lines().any(|l| l.ends_with(",limit")));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(output_file(&dir.0, ".summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status_counts_per_time"][60]["limit"], 17);
    assert!(SETTLED_NAMES.contains(&"grazing"));
}

/// The rings' slip load in closed form (Lamé, plane strain): the contact pressures p₁₃ and p₁₆ of
/// the three rings solved for the interference (u_r = A r + B/r per ring, the bore fixed, the
/// outside free, u continuous at r = 16, jumping by 0.01 at r = 13), and the torque the shear τ
/// puts on r = 20, carried through each circle r as a shear τ·20²/r². Each circle slips as a
/// whole when that reaches f·p: τ* = f·p·r²/400. Returns (τ* at r = 13, τ* at r = 16).
fn rings_slip_loads() -> (f64, f64) {
    let (e, nu, f) = (210000.0, 0.3, 0.2);
    let (lambda, mu) = (e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)));
    let sigma = |r: f64| [2.0 * (lambda + mu), -2.0 * mu / (r * r)];
    // Unknowns A₁ B₁ A₂ B₂ A₃ B₃ p₁₃ p₁₆.
    let mut m = nalgebra::SMatrix::<f64, 8, 8>::zeros();
    let mut rhs = nalgebra::SVector::<f64, 8>::zeros();
    let mut set = |row: usize, at: &[(usize, f64)]| {
        for &(k, v) in at {
            m[(row, k)] += v;
        }
    };
    set(0, &[(0, 10.0), (1, 0.1)]);
    for (row, ring, r, p) in [(1, 0, 13.0, 6), (2, 1, 13.0, 6), (3, 1, 16.0, 7), (4, 2, 16.0, 7)] {
        let [a, b] = sigma(r);
        set(row, &[(2 * ring, a), (2 * ring + 1, b), (p, 1.0)]);
    }
    let [a, b] = sigma(20.0);
    set(5, &[(4, a), (5, b)]);
    set(6, &[(2, 13.0), (3, 1.0 / 13.0), (0, -13.0), (1, -1.0 / 13.0)]);
    rhs[6] = 0.01;
    set(7, &[(4, 16.0), (5, 1.0 / 16.0), (2, -16.0), (3, -1.0 / 16.0)]);
    let x = m.lu().solve(&rhs).expect("the Lamé system is regular");
    (f * x[6] * 169.0 / 400.0, f * x[7] * 256.0 / 400.0)
}

/// Below the closed-form slip load no point may be reported slipping: twisted to 0.98 of the load
/// at which the outer circle slips (τ* = 3.036 MPa there, 4.869 at r = 13), every pair of both
/// fits at every time point is stick or, near the top, limit (within the margin of the cone: the
/// mesh's pressure matches Lamé's to its discretisation), none slip. Twisted to 1.05 of it, the
/// outer ring has no equilibrium from t = 1 (3.19·t > 3.036 from t = 0.952; time points every
/// 0.25): the run says so within 30 iterations (15 measured), naming the outer ring's eight
/// sectors and not the middle ring's.
#[test]
fn rings_slip_at_the_closed_form_load_and_not_below() {
    let (at13, at16) = rings_slip_loads();
    // p₁₃ = 57.63 and p₁₆ = 23.71 MPa: the outer circle slips first.
    assert!(
        (at13 - 4.8695).abs() < 1e-3 && (at16 - 3.0355).abs() < 1e-3,
        "{at13} {at16}"
    );
    let sc = rings(&format!("{}*t", 0.98 * at16));
    let result = run(&sc);
    assert_eq!(result.verdict, Verdict::Converged);
    for (k, sol) in result.interfaces.iter().enumerate() {
        let slipping = sol.status.iter().filter(|&&s| s == Settled::Slip as u8).count();
        assert_eq!(slipping, 0, "interface {k}: {:?}", sol.status);
        assert!(sol
            .status
            .iter()
            .all(|&s| s == Settled::Stick as u8 || s == Settled::Limit as u8));
    }

    let over = rings(&format!("{}*t", 1.05 * at16));
    let result = run(&over);
    let Verdict::NoEquilibrium { detail } = &result.verdict else {
        panic!("{:?}", result.verdict);
    };
    // The outer ring turns; the middle one, held at r = 13 below its capacity, passes its twist on.
    assert!(
        detail.starts_with(
            "the loads exceed what friction and the supports hold from t = 1: part [outer.1, outer.2, outer.3, \
             outer.4, …] (8 subdomains) would slide or turn away: its interfaces 18 (middle.1 | outer.1) from t = 1"
        ) && !detail.contains("part [middle"),
        "{detail}"
    );
    assert!(result.iterations.len() <= 30, "{} iterations", result.iterations.len());
}
