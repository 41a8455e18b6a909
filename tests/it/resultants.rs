//! Interface resultants of a run (docs/outputs.md, "resultants.csv").

use crate::common::{glissade_ok, output_file, scratch};

/// Two blocks side by side in frictional contact on x = 2, the left one clamped on x = 0, both
/// on rollers along y = 0, a pressure p = 10·t on x = 4 over a height of 1 mm: the rollers carry
/// no x force, so the contact carries the whole load, −10·t N/mm normal (compression), checked to
/// 1e-3 of the load (the run's accuracy is 1e-3 of the largest traction) at every time point. The
/// tangential resultant is not zero (the clamped edge holds the left block's Poisson expansion,
/// the right block's is free), but friction bounds it: |T| ≤ f·|N|, f = 0.3; the interface is
/// vertical, so the force on side a is (±N, ±T).
#[test]
fn the_contact_of_two_blocks_pushed_together_carries_the_whole_load() {
    let dir = scratch("resultants");
    let scene = format!("{}/tests/fixtures/side-by-side.toml", env!("CARGO_MANIFEST_DIR"));
    let out = glissade_ok(&[&"run", &scene, &"--in-process", &"--no-record", &"--out", &dir.0]);
    assert!(out.contains("Converged"), "{out}");
    // The console line of the contact interface at t = 1.
    assert!(
        out.lines()
            .any(|l| l.starts_with("interface ") && l.contains("at t = 1: N = -1.00") && l.contains("100 % stick")),
        "{out}"
    );
    let csv_path = output_file(&dir.0, ".resultants.csv");
    assert!(out.contains(&format!("resultants: {}", csv_path.display())), "{out}");
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("time_s,interface,a,b,kind,force_a_x_N_per_mm,force_a_y_N_per_mm,normal_N_per_mm,tangential_N_per_mm,separated_share,stick_share,slip_share,limit_share,grazing_share")
    );
    let mut contact_rows = 0;
    for row in lines {
        let c: Vec<&str> = row.split(',').collect();
        assert_eq!(c.len(), 14, "{row}");
        if c[4] != "contact" {
            continue;
        }
        contact_rows += 1;
        let num = |i: usize| c[i].parse::<f64>().unwrap_or_else(|e| panic!("{row}: column {i}: {e}"));
        let t = num(0);
        assert!((num(7) + 10.0 * t).abs() <= 1e-2, "normal {row}");
        assert!(num(8).abs() <= 0.3 * num(7).abs() + 1e-12, "tangential {row}");
        assert!(num(5).abs() == num(7).abs() && num(6).abs() == num(8).abs(), "{row}");
        let shares = num(9) + num(10) + num(11) + num(12) + num(13);
        assert!((shares - 1.0).abs() <= 1e-12, "shares {row}");
        if t > 0.0 {
            assert!(num(10) > 0.999, "stuck {row}");
        }
    }
    assert_eq!(contact_rows, 5, "one contact interface, N = 4");
    // The same numbers in the summary.
    let summary_path = output_file(&dir.0, ".summary.json");
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(summary_path).unwrap()).unwrap();
    let r = &summary["interface_resultants"];
    let contact = r
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["contact"] == true)
        .expect("the contact interface");
    let n_last = contact["normal"][4].as_f64().unwrap();
    assert!((n_last + 10.0).abs() <= 1e-2, "{n_last}");
}
