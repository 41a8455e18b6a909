//! ParaView and CSV outputs read by foreign readers: `glissade run --vtu --csv` and
//! `glissade export`, read back with Python's `meshio` and `csv` and compared with the run's
//! JSON outputs.

use crate::common::{glissade_ok, python_with, scratch};
use std::path::Path;
use std::process::Command;

/// Reads a run's `.pvd`, every `.vtu` it lists (meshio) and its CSV, and compares them with the
/// run's `fields.json` and `displacement.json` (when given). Prints one JSON object: the largest
/// differences and what was read.
const CHECK: &str = r#"
import sys, json, csv, os
import xml.etree.ElementTree as ET
import numpy as np
import meshio

pvd, fields_path, disp_path, csv_path = sys.argv[1:5]
fields = json.load(open(fields_path))
times = fields["times"]
sets = ET.parse(pvd).getroot().find("Collection").findall("DataSet")
base = os.path.dirname(pvd)
by_time = {}
for d in sets:
    by_time.setdefault(float(d.get("timestep")), {})[d.get("part")] = os.path.join(base, d.get("file"))
out = {"time_points": len(by_time), "datasets": len(sets), "times_equal": sorted(by_time) == sorted(times)}
disp = json.load(open(disp_path))["displacements"] if disp_path != "-" else None
d_u = d_f = d_vm = 0.0
u_scale = f_scale = 0.0
status_mismatch = 0
clamped = 0
d_normal = 0.0
d_sides = 0.0
curved = False
codes = {"separated": 0, "stick": 1, "slip": 2, "limit": 3, "grazing": 4}
for i, t in enumerate(times):
    parts = by_time[t]
    solid = meshio.read(parts["0"])
    assert [c.type for c in solid.cells] == ["quad8"], [c.type for c in solid.cells]
    u = solid.point_data["displacement"]
    s = solid.point_data["stress"]
    sx, sy, sz, txy = s[:, 0], s[:, 1], s[:, 2], s[:, 3]
    vm = np.sqrt(0.5 * ((sx - sy) ** 2 + (sy - sz) ** 2 + (sz - sx) ** 2) + 3 * txy ** 2)
    d_vm = max(d_vm, float(np.max(np.abs(vm - solid.point_data["von_mises"]))) / max(1e-300, float(np.max(vm))))
    if disp is not None:
        k = 0
        for sub in disp:
            rows = sub["rows"]
            col = np.array(sub["u"][i * rows:(i + 1) * rows]).reshape(-1, 2)
            n = col.shape[0]
            d_u = max(d_u, float(np.max(np.abs(u[k:k + n, :2] - col))))
            u_scale = max(u_scale, float(np.max(np.abs(col))))
            k += n
        assert k == u.shape[0], (k, u.shape)
    itf = meshio.read(parts["1"])
    assert [c.type for c in itf.cells] == ["line3"], [c.type for c in itf.cells]
    pd = itf.point_data
    k = 0
    for f in fields["interfaces"]:
        np_ = len(f["coords"])
        for key, name in [("f_n", "traction_n"), ("f_t", "traction_t"), ("jump_n", "jump_n"), ("jump_t", "jump_t")]:
            d_f = max(d_f, float(np.max(np.abs(pd[name][k:k + np_] - np.array(f[key][i])))))
        f_scale = max(f_scale, max(abs(v) for v in f["f_n"][i]))
        normals = np.array(f.get("normals", [f["normal"]] * np_))
        d_normal = max(d_normal, float(np.max(np.abs(pd["normal"][k:k + np_, :2] - normals))))
        curved = curved or "normals" in f
        # Each side's displacement at the pairs: their difference is the jump, in each pair's frame.
        du = pd["displacement_b"][k:k + np_, :2] - pd["displacement_a"][k:k + np_, :2]
        tangents = np.stack([-normals[:, 1], normals[:, 0]], axis=1)
        d_sides = max(d_sides, float(np.max(np.abs(np.sum(du * normals, axis=1) - np.array(f["jump_n"][i])))))
        d_sides = max(d_sides, float(np.max(np.abs(np.sum(du * tangents, axis=1) - np.array(f["jump_t"][i])))))
        st = pd["status"][k:k + np_]
        expected = [codes[w] for w in f["status"][i]] if f["status"] else [-1] * np_
        status_mismatch += int(np.sum(st != np.array(expected)))
        k += np_
        while k < len(pd["status"]) and pd["status"][k] == -2:
            clamped += 1
            k += 1
    assert k == itf.points.shape[0], (k, itf.points.shape)
rows = list(csv.DictReader(open(csv_path)))
d_csv = 0.0
k = 0
for i, t in enumerate(times):
    for f in fields["interfaces"]:
        for p in range(len(f["coords"])):
            r = rows[k]
            k += 1
            assert float(r["time"]) == t and int(r["interface"]) == f["interface"] and int(r["pair"]) == p
            for key, name in [("f_n", "traction_n"), ("f_t", "traction_t"), ("jump_n", "jump_n"), ("jump_t", "jump_t")]:
                d_csv = max(d_csv, abs(float(r[name]) - f[key][i][p]))
            w = f["status"][i][p] if f["status"] else "perfect"
            status_mismatch += int(r["status"] != w)
out.update(csv_rows=len(rows), expected_rows=k, d_u=d_u, u_scale=u_scale, d_f=d_f, d_csv=d_csv,
           f_scale=f_scale, d_vm=d_vm, status_mismatch=status_mismatch, clamped_points=clamped,
           d_normal=d_normal, d_sides=d_sides, curved=curved)
print(json.dumps(out))
"#;

fn run_check(python: &str, pvd: &Path, fields: &Path, displacement: Option<&Path>, csv: &Path) -> serde_json::Value {
    let o = Command::new(python)
        .args(["-c", CHECK])
        .arg(pvd)
        .arg(fields)
        .arg(displacement.map_or("-".into(), |p| p.display().to_string()))
        .arg(csv)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "python check failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = String::from_utf8_lossy(&o.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| panic!("python printed {text}: {e}"))
}

/// The VTU series, the CSV and the JSON outputs of one run of the stratified scene carry the same
/// doubles: VTU stores them raw, JSON and CSV in shortest round-trip decimal, so they agree to
/// 1e-12 (the issue's bar; in practice exactly). The layers' interfaces end at x = 0, where both
/// sides are clamped, so the clamped-point case is exercised.
#[test]
fn a_runs_paraview_series_and_csv_equal_its_json_outputs() {
    let Some(python) = python_with(&["meshio", "numpy"]) else {
        return;
    };
    let dir = scratch("vtu-run");
    // The stratified scene (18 subdomains, 27 interfaces) at N = 30 instead of 1000.
    let text = std::fs::read_to_string(format!("{}/launch/scenes/stratified.toml", env!("CARGO_MANIFEST_DIR")))
        .unwrap()
        .replace("N = 1000", "N = 30");
    let scene = dir.join("stratified.toml").display().to_string();
    std::fs::write(&scene, text).unwrap();
    let out = dir.display().to_string();
    let printed = glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--interior",
        &"--vtu",
        &"--csv",
        &"--out",
        &out,
        &"--run-id",
        &"v",
    ]);
    assert!(printed.contains("paraview: "), "{printed}");
    let stem = dir.join("stratified-v");
    let r = run_check(
        python,
        &stem.with_extension("pvd"),
        &stem.with_extension("fields.json"),
        Some(&stem.with_extension("displacement.json")),
        &stem.with_extension("interfaces.csv"),
    );
    println!("{r}");
    // N = 30: 31 time points, a solid and an interface dataset each.
    assert_eq!(r["time_points"], 31);
    assert_eq!(r["datasets"], 62);
    assert_eq!(r["times_equal"], true);
    assert_eq!(r["csv_rows"], r["expected_rows"]);
    assert_eq!(r["status_mismatch"], 0);
    assert!(r["clamped_points"].as_u64().unwrap() > 0, "{r}");
    let f = |k: &str| r[k].as_f64().unwrap();
    assert!(f("u_scale") > 0.0 && f("f_scale") > 0.0);
    assert!(f("d_u") <= 1e-12 * f("u_scale"), "{r}");
    assert!(f("d_f") <= 1e-12 * f("f_scale"), "{r}");
    assert!(f("d_csv") <= 1e-12 * f("f_scale"), "{r}");
    // von Mises as recomputed from the stress array: the same formula in numpy, round-off only.
    assert!(f("d_vm") <= 1e-12, "{r}");

    // Refuses to write over the series of the same run.
    let o = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["run", &scene, "--in-process", "--vtu", "--out", &out, "--run-id", "v"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("stratified-v.pvd") && err.contains("nothing was overwritten"),
        "{err}"
    );
}

/// A curved scene's series (the shrink fit: a closed circular contact interface, per-pair
/// normals) reads in meshio like a block scene's, with the same doubles as its JSON outputs and
/// each pair's own normal.
#[test]
fn a_curved_scenes_paraview_series_reads_in_meshio() {
    let Some(python) = python_with(&["meshio", "numpy"]) else {
        return;
    };
    let dir = scratch("vtu-curved");
    let scene = format!("{}/launch/scenes/shrink-fit.toml", env!("CARGO_MANIFEST_DIR"));
    let out = dir.display().to_string();
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--interior",
        &"--vtu",
        &"--csv",
        &"--no-record",
        &"--out",
        &out,
        &"--run-id",
        &"c",
    ]);
    let stem = dir.join("shrink-fit-c");
    let r = run_check(
        python,
        &stem.with_extension("pvd"),
        &stem.with_extension("fields.json"),
        Some(&stem.with_extension("displacement.json")),
        &stem.with_extension("interfaces.csv"),
    );
    println!("{r}");
    assert_eq!(r["time_points"], 11);
    assert_eq!(r["times_equal"], true);
    assert_eq!(r["curved"], true);
    assert_eq!(r["csv_rows"], r["expected_rows"]);
    assert_eq!(r["status_mismatch"], 0);
    let f = |k: &str| r[k].as_f64().unwrap();
    assert!(f("u_scale") > 0.0 && f("f_scale") > 0.0);
    assert!(f("d_u") <= 1e-12 * f("u_scale"), "{r}");
    assert!(f("d_f") <= 1e-12 * f("f_scale"), "{r}");
    assert!(f("d_normal") <= 1e-15, "{r}");
    // Differences of the sides' displacements against the jumps computed from the same numbers:
    // round-off of one subtraction and a dot product on displacements of ~1e-2 mm.
    assert!(f("d_sides") <= 1e-15, "{r}");
    assert!(f("d_vm") <= 1e-12, "{r}");
}

/// `glissade export` of a recording made without `--interior` recovers the displacements from
/// the recorded boundary states; they equal the interior displacements of a run of the same
/// scene (in-process runs are deterministic) to the recovery's sparse-solve round-off, 1e-9 of
/// the largest displacement; the interface fields are the recorded ones, exactly.
#[test]
fn export_of_a_recording_equals_the_runs_own_outputs() {
    let Some(python) = python_with(&["meshio", "numpy"]) else {
        return;
    };
    let dir = scratch("vtu-export");
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    let out = dir.display().to_string();
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--interior",
        &"--out",
        &out,
        &"--run-id",
        &"a",
    ]);
    glissade_ok(&[&"run", &scene, &"--in-process", &"--out", &out, &"--run-id", &"b"]);
    let exported = dir.join("exported");
    let ex = exported.display().to_string();
    let rec = dir.join("small-three-layer-b.mcap").display().to_string();
    let printed = glissade_ok(&[&"export", &rec, &"--vtu", &ex, &"--csv", &ex]);
    assert!(printed.contains("paraview: ") && printed.contains("csv: "), "{printed}");
    let r = run_check(
        python,
        &exported.join("small-three-layer-b.pvd"),
        &dir.join("small-three-layer-b.fields.json"),
        Some(&dir.join("small-three-layer-a.displacement.json")),
        &exported.join("small-three-layer-b.interfaces.csv"),
    );
    println!("{r}");
    assert_eq!(r["time_points"], 11);
    assert_eq!(r["status_mismatch"], 0);
    let f = |k: &str| r[k].as_f64().unwrap();
    assert!(f("d_u") <= 1e-9 * f("u_scale"), "{r}");
    assert!(f("d_f") <= 1e-12 * f("f_scale"), "{r}");

    // Every 4th time point and the last: 0, 4, 8, 10.
    let thinned = dir.join("thinned");
    glissade_ok(&[
        &"export",
        &rec,
        &"--vtu",
        &thinned.display().to_string(),
        &"--vtu-every",
        &"4",
    ]);
    let pvd = std::fs::read_to_string(thinned.join("small-three-layer-b.pvd")).unwrap();
    let steps: Vec<&str> = pvd
        .lines()
        .filter(|l| l.contains("part=\"0\""))
        .filter_map(|l| l.split("timestep=\"").nth(1)?.split('"').next())
        .collect();
    assert_eq!(steps, ["0.0", "0.4", "0.8", "1.0"], "{pvd}");

    // A second export into the same folder overwrites nothing.
    let o = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["export", &rec, "--vtu", &ex])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("nothing was overwritten"));
}

/// Part names hold what a Gmsh physical name may: commas, double quotes, `<` and `&`. The CSV
/// quotes them (RFC 4180: Python's `csv` reads 12 fields in every row, and the names back as they
/// were; a part `le,ft` gave rows of 13 fields under a header of 12), and the ParaView series,
/// which names parts by their index only, stays well-formed XML.
#[test]
fn part_names_with_commas_quotes_and_markup_are_escaped_in_the_outputs() {
    let Some(python) = python_with(&[]) else {
        return;
    };
    let dir = scratch("vtu-names");
    let (lower, upper) = (r#"le,ft "low" <&>"#, r#"up"per, & <b>"#);
    let text = include_str!("../../launch/scenes/two-blocks.toml")
        .replacen("N = 40", "N = 4", 1)
        .replacen("name = \"lower\"", &format!("name = '{lower}'"), 1)
        .replacen("name = \"upper\"", &format!("name = '{upper}'"), 1)
        .replacen(
            "between = [\"lower\", \"upper\"]",
            &format!("between = ['{lower}', '{upper}']"),
            1,
        );
    for name in [lower, upper] {
        assert_eq!(
            text.matches(&format!("'{name}'")).count(),
            2,
            "{name} not set in the scene"
        );
    }
    let scene = dir.join("names.toml");
    std::fs::write(&scene, text).unwrap();
    let out = dir.display().to_string();
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--quiet",
        &"--vtu",
        &"--csv",
        &"--no-record",
        &"--out",
        &out,
        &"--run-id",
        &"n",
    ]);
    let stem = dir.join("two-blocks-n");
    const READ: &str = r#"
import sys, csv, json, os
import xml.etree.ElementTree as ET
csv_path, pvd = sys.argv[1:3]
with open(csv_path, newline="") as f:
    rows = list(csv.reader(f))
sets = ET.parse(pvd).getroot().find("Collection").findall("DataSet")
base = os.path.dirname(pvd)
for d in sets:
    text = open(os.path.join(base, d.get("file")), "rb").read()
    # The XML before the raw appended data (binary, not text) parses.
    head = text[: text.index(b"<AppendedData")] + b"</VTKFile>"
    ET.fromstring(head)
print(json.dumps({
    "header": rows[0],
    "widths": sorted(set(len(r) for r in rows)),
    "names": sorted(set((r[2], r[3]) for r in rows[1:])),
    "rows": len(rows) - 1,
    "datasets": len(sets),
}))
"#;
    let o = Command::new(python)
        .args(["-c", READ])
        .arg(stem.with_extension("interfaces.csv"))
        .arg(stem.with_extension("pvd"))
        .output()
        .unwrap();
    assert!(o.status.success(), "python: {}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["header"].as_array().unwrap().len(), 12, "{r}");
    assert_eq!(r["widths"], serde_json::json!([12]), "{r}");
    assert_eq!(r["names"], serde_json::json!([[lower, upper]]), "{r}");
    // 5 time points of the interface's 33 node pairs; a solid and an interface dataset each.
    assert_eq!(r["rows"], 5 * 33, "{r}");
    assert_eq!(r["datasets"], 10, "{r}");
}
