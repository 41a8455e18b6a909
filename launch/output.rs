//! Run outputs: the JSON summary and the interface fields, written under an output folder.

use crate::error::{Error, IoWhat, Result};
pub use crate::files::{io_why, rename_new, write_through_partial};
use crate::runner::RunResult;
use glissade_deploy::Plan;
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::local::InterfaceFields;
use glissade_mechanics::model::{Interface, InterfaceKind, Model};
use glissade_mechanics::settled::SETTLED_NAMES;
use glissade_messages::{InterfaceSolution, Verdict};
use glissade_reference::ReferenceSolution;
use glissade_scene::LoadedScene;
use glissade_subdomain::LinearStageRecord;
use serde::Serialize;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Reported status counts (separated, stick, slip, limit, grazing: [`SETTLED_NAMES`]) per time
/// point over all contact interfaces.
pub fn status_counts_per_time(model: &Model, result: &RunResult) -> Vec<[u64; 5]> {
    let nt = model.time.n_points();
    let mut counts = vec![[0u64; 5]; nt];
    for sol in &result.interfaces {
        let itf = &model.interfaces[sol.interface as usize];
        if !itf.is_contact() {
            continue;
        }
        let np = itf.n_pairs();
        for (k, st) in sol.status.iter().enumerate() {
            if let Some(c) = counts[k / np].get_mut(*st as usize) {
                *c += 1;
            }
        }
    }
    counts
}

/// How a run of `n` iterations ended, from its verdict (the first words of [`outcome`]).
fn how_it_ended(verdict: &Verdict, n: usize) -> String {
    match verdict {
        Verdict::Converged => format!("Converged after {n} iterations"),
        Verdict::MaxIterations => format!("NOT converged: stopped at the iteration cap ({n} iterations)"),
        Verdict::Stagnated { detail } => format!("NOT converged: stagnated after {n} iterations ({detail})"),
        Verdict::Diverged { detail } => format!("NOT converged: diverged after {n} iterations ({detail})"),
        Verdict::NoEquilibrium { detail } => {
            format!("NOT converged: no equilibrium, stopped after {n} iterations ({detail})")
        }
        Verdict::Continue => format!("NOT converged: stopped after {n} iterations"),
    }
}

/// What a run's stop means, in one sentence: which of the requested accuracy and tolerances the
/// last iteration met and which it did not. "Converged" only when all are met.
pub fn outcome(model: &Model, result: &RunResult) -> String {
    let n = result.iterations.len();
    let Some(last) = result.iterations.last() else {
        return how_it_ended(&result.verdict, n);
    };
    let d = &last.decision;
    let s = &model.solver;
    // How far s and ŝ are apart (`IndicatorSums::disagreement`): the larger of e_c and η.
    let (name, gap) = if d.contact_indicator >= d.eta {
        ("e_c", d.contact_indicator)
    } else {
        ("η", d.eta)
    };
    // "Converged" with an estimate above the accuracy (or none): the stop at stagnation with s
    // and ŝ agreeing within the accuracy over STAGNATION_AGREEMENT (`StopRule::decide`).
    if let (Verdict::Converged, Some(a)) = (&result.verdict, s.accuracy) {
        let within = |e: Option<f64>| e.is_some_and(|e| e <= a);
        if !(within(d.estimate) && within(d.pointwise_estimate)) {
            use glissade_mechanics::estimate::STAGNATION_AGREEMENT;
            let estimate = d.estimate.map_or("no contracting estimate".to_string(), |e| {
                format!("estimated contact-traction error {e:.2e}")
            });
            return format!(
                "Converged at stagnation after {n} iterations: η stopped falling with the fields written (s) and the \
                 interface laws' (ŝ) agreeing within the accuracy {a:e} over {STAGNATION_AGREEMENT}: {name} = {gap:.2e} \
                 ≤ {:.2e} ({estimate}, which no longer contracts; docs/accuracy.md, \"Stagnation at a small error\")",
                a / STAGNATION_AGREEMENT
            );
        }
    }
    let mut met = Vec::new();
    let mut missed = Vec::new();
    // η and e_c where the scene asks no tolerance of them: shown, but neither met nor missed.
    let mut shown = Vec::new();
    let window = glissade_mechanics::estimate::RATE_WINDOW;
    // The accuracy bounds both estimates: the space-time L2 one and the largest at one point.
    let missing = if n > window {
        format!("(the contact indicator did not decrease over the last {window} iterations)")
    } else {
        format!("yet (it needs {} iterations)", window + 1)
    };
    let estimates = [
        ("estimated contact-traction error", d.estimate),
        ("estimated largest traction error at one point", d.pointwise_estimate),
    ];
    if let (None, None, Some(a)) = (d.estimate, d.pointwise_estimate, s.accuracy) {
        missed.push(format!("no error estimate {missing} for accuracy {a:e}"));
    }
    for (what, value) in estimates
        .into_iter()
        .filter(|_| d.estimate.is_some() || d.pointwise_estimate.is_some())
    {
        match (s.accuracy, value) {
            (Some(a), Some(e)) if e <= a => met.push(format!("{what} {e:.2e} ≤ accuracy {a:e}")),
            (Some(a), Some(e)) => missed.push(format!("{what} {e:.2e} > accuracy {a:e}")),
            (Some(a), None) => missed.push(format!("no {what} {missing} for accuracy {a:e}")),
            (None, Some(e)) => shown.push(format!("{what} {e:.2e}")),
            (None, None) => {}
        }
    }
    // The state written (s) must agree with the interface laws' (ŝ) within the accuracy too
    // (`IndicatorSums::disagreement`: the larger of e_c and η).
    let mut apart = None;
    if let Some(a) = s.accuracy {
        if gap > a {
            apart = Some(name);
            missed.push(format!(
                "the fields written (s) and the interface laws' (ŝ) differ by {name} = {gap:.2e} > accuracy {a:e}"
            ));
        }
    }
    match s.tolerance {
        Some(t) if d.eta <= t => met.push(format!("η = {:.2e} ≤ tolerance {t:e}", d.eta)),
        Some(t) => missed.push(format!("η = {:.2e} > tolerance {t:e}", d.eta)),
        None if apart == Some("η") => {}
        None => shown.push(format!("η = {:.2e}", d.eta)),
    }
    match s.contact_tolerance {
        Some(t) if d.contact_indicator <= t => {
            met.push(format!("e_c = {:.2e} ≤ contact tolerance {t:e}", d.contact_indicator))
        }
        Some(t) => missed.push(format!("e_c = {:.2e} > contact tolerance {t:e}", d.contact_indicator)),
        None if apart == Some("e_c") => {}
        None => shown.push(format!("e_c = {:.2e}", d.contact_indicator)),
    }
    let how = how_it_ended(&result.verdict, n);
    if missed.is_empty() {
        met.extend(shown);
        return format!("{how}: {}", met.join(", "));
    }
    let mut line = format!("{how}: {}", missed.join(", "));
    if !met.is_empty() {
        line += &format!("; met: {}", met.join(", "));
    }
    if !shown.is_empty() {
        line += &format!("; {}", shown.join(", "));
    }
    line
}

/// Seconds left until an estimate `estimate` that contracts by `rate` per iteration reaches
/// `target`, at `per_iteration` seconds an iteration: 0 when it is there, None without a
/// contraction (rate not in (0, 1)).
pub fn time_left(estimate: f64, target: f64, rate: f64, per_iteration: f64) -> Option<f64> {
    if estimate <= target {
        return Some(0.0);
    }
    if !(rate > 0.0 && rate < 1.0) {
        return None;
    }
    Some(((estimate / target).ln() / rate.recip().ln()).ceil() * per_iteration)
}

/// The progress line of `glissade run` after an iteration: the estimated error and its target,
/// η (and its tolerance when set), e_c, stick/slip (and separated) counts, status changes and the
/// time left at the observed rate.
pub fn progress_line(model: &Model, r: &crate::runner::IterationRecord) -> String {
    let d = &r.decision;
    let s = &model.solver;
    let target = |t: Option<f64>| t.map_or(String::new(), |t| format!(" → {t:.0e}"));
    // The larger of the two estimates (L2 and at one point): the one the stop waits for.
    let larger = d.estimate.zip(d.pointwise_estimate).map(|(e, p)| e.max(p));
    let error = larger.map_or("?".to_string(), |e| format!("{e:.2e}"));
    let per_iteration = r.elapsed_s / (r.iteration as f64 + 1.0);
    let left = match (larger, d.contraction, s.accuracy) {
        (Some(e), Some(rate), Some(a)) => time_left(e, a, rate, per_iteration),
        _ => None,
    };
    let left = left.map_or(String::new(), |t| format!("  ~{t:.0} s left"));
    let [separated, stick, slip] = d.counts;
    format!(
        "error ≈ {error}{}  η {:.2e}{}  e_c {:.2e}  stick/slip {stick}/{slip} (separated {separated}, changed {}){left}",
        target(s.accuracy),
        d.eta,
        target(s.tolerance),
        d.contact_indicator,
        d.status_changes,
    )
}

/// What `glissade run` writes besides its recording: `<scene>-<run>.<kind>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunFile {
    Summary,
    Fields,
    Displacement,
}

impl RunFile {
    pub const ALL: [RunFile; 3] = [RunFile::Summary, RunFile::Fields, RunFile::Displacement];

    /// The file's name for run `run_id` of scene `name`.
    pub fn name(self, name: &str, run_id: &str) -> String {
        let kind = match self {
            RunFile::Summary => "summary",
            RunFile::Fields => "fields",
            RunFile::Displacement => "displacement",
        };
        format!("{name}-{run_id}.{kind}.json")
    }
}

/// The files of run `run_id` of scene `name` that already exist in `out` (summary, fields,
/// displacements, CSV, recording, and their partial copies, as regular files; the ParaView series
/// and its folder): a run refuses to start
/// over them.
pub fn existing_outputs(out: &Path, name: &str, run_id: &str) -> Vec<PathBuf> {
    let names = RunFile::ALL
        .map(|f| f.name(name, run_id))
        .into_iter()
        .chain([glissade_recorder::recording_file_name(name, run_id)]);
    let stem = format!("{name}-{run_id}");
    let (pvd, vtu) = series_paths(out, &stem);
    let csv = format!("{stem}.interfaces.csv");
    let resultants = format!("{stem}.resultants.csv");
    let boundaries = format!("{stem}.boundaries.csv");
    let plot = format!("{stem}.boundaries.svg");
    names
        .chain([csv, resultants, boundaries, plot])
        .flat_map(|n| [out.join(&n), out.join(format!(".{n}.partial"))])
        .chain([pvd, vtu])
        .filter(|p| std::fs::symlink_metadata(p).is_ok_and(|m| m.is_file() || m.is_dir()))
        .collect()
}

/// The JSON summary of a run.
pub fn summary(scene: &LoadedScene, result: &RunResult, run_id: &str) -> Value {
    let model = &scene.model;
    let per_time = status_counts_per_time(model, result);
    let last = result.iterations.last();
    json!({
        "scene": model.name,
        "scene_fingerprint": format!("{:016x}", scene.fingerprint),
        "run_id": run_id,
        "software": { "name": "glissade", "version": env!("CARGO_PKG_VERSION"), "profile": if cfg!(debug_assertions) { "debug" } else { "release" } },
        "machine": { "cores": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1) },
        "problem": {
            "subdomains": model.subdomains.len(),
            "interfaces": model.interfaces.len(),
            "contact_interfaces": model.interfaces.iter().filter(|i| i.is_contact()).count(),
            "time_points": model.time.n_points(),
            "dofs": model.subdomains.iter().map(|s| s.n_dofs()).sum::<usize>(),
        },
        "nodes": result.nodes,
        "left_out": result.left_out,
        "verdict": result.verdict,
        "iterations": result.iterations.len(),
        "eta": last.map(|r| r.decision.eta),
        "contact_indicator": last.map(|r| r.decision.contact_indicator),
        "estimated_error": last.and_then(|r| r.decision.estimate),
        "estimated_pointwise_error": last.and_then(|r| r.decision.pointwise_estimate),
        "accuracy": model.solver.accuracy,
        "tolerance": model.solver.tolerance,
        "outcome": outcome(model, result),
        "setup_s": result.setup_s,
        "solve_s": result.solve_s,
        "status_counts_per_time": per_time.iter().enumerate().map(|(i, c)| json!({"t": model.time.t(i), "separated": c[0], "stick": c[1], "slip": c[2], "limit": c[3], "grazing": c[4]})).collect::<Vec<_>>(),
        "history": result.iterations.iter().map(|r| {
            let mut v = json!(r);
            let [separated, stick, slip] = r.decision.counts;
            v["decision"]["counts"] = json!({"separated": separated, "stick": stick, "slip": slip});
            v
        }).collect::<Vec<_>>(),
    })
}

/// Linear-stage totals of one linear stage over a run: summed over its subdomains and iterations.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearStageTotals {
    /// `condensed`, `sparse` or `pgd` (`auto` resolved per subdomain).
    pub stage: &'static str,
    pub subdomains: usize,
    /// Iterations with a linear stage of this kind (the initial one from ŝ = 0 included).
    pub iterations: usize,
    /// Wall time of these linear stages, summed over subdomains and iterations: measured by the
    /// in-process bus; None as processes (each node process's bus does not report its times).
    pub seconds: Option<f64>,
    pub flops: u64,
}

impl LinearStageTotals {
    /// Mean flops of one iteration's linear stages (summed over the subdomains).
    pub fn flops_per_iteration(&self) -> f64 {
        self.flops as f64 / self.iterations.max(1) as f64
    }

    /// Flops over linear-stage wall time, in 10⁹ per second (None without a measured time).
    pub fn gflops_per_s(&self) -> Option<f64> {
        crate::report::gflops_per_s(self.flops, self.seconds?)
    }

    /// One line for the console: flops per iteration and rate.
    pub fn line(&self) -> String {
        format!(
            "linear stage `{}` ({} subdomain(s)): {:.4} GFLOP per iteration over {} iterations, {}, {} GFLOP/s ({} build)",
            self.stage,
            self.subdomains,
            self.flops_per_iteration() * 1e-9,
            self.iterations,
            self.seconds.map_or("time not measured as processes".to_string(), |s| format!("{s:.3} s")),
            self.gflops_per_s().map_or("-".to_string(), |g| format!("{g:.2}")),
            if cfg!(debug_assertions) { "debug" } else { "release" }
        )
    }

    pub fn json(&self) -> Value {
        json!({
            "stage": self.stage,
            "subdomains": self.subdomains,
            "iterations": self.iterations,
            "seconds": self.seconds,
            "flops": self.flops,
            "flops_per_iteration": self.flops_per_iteration(),
            "gflops_per_s": self.gflops_per_s(),
        })
    }
}

/// Linear-stage totals per linear stage (condensed, sparse, pgd; those the run used) from the
/// subdomain nodes' records; `timed`: the records' times were measured (an in-process run).
pub fn linear_stage_totals(scene: &LoadedScene, records: &[LinearStageRecord], timed: bool) -> Vec<LinearStageTotals> {
    let plan = Plan::new(&scene.model).with_scene(scene);
    let names: Vec<&str> = (0..scene.model.subdomains.len())
        .map(|s| match plan.stage_of(&scene.model, s) {
            LinearStage::Auto => LinearStage::Condensed.key(),
            stage => stage.key(),
        })
        .collect();
    let name = |s: u32| names[s as usize];
    let mut out: Vec<LinearStageTotals> = Vec::new();
    for stage in [LinearStage::Condensed, LinearStage::Sparse, LinearStage::Pgd].map(LinearStage::key) {
        let of: Vec<&LinearStageRecord> = records.iter().filter(|r| name(r.subdomain) == stage).collect();
        if of.is_empty() {
            continue;
        }
        let mut subdomains: Vec<u32> = of.iter().map(|r| r.subdomain).collect();
        subdomains.sort_unstable();
        subdomains.dedup();
        let mut iterations: Vec<u32> = of.iter().map(|r| r.iteration).collect();
        iterations.sort_unstable();
        iterations.dedup();
        out.push(LinearStageTotals {
            stage,
            subdomains: subdomains.len(),
            iterations: iterations.len(),
            seconds: timed.then(|| of.iter().map(|r| r.seconds).sum()),
            flops: of.iter().map(|r| r.flops).sum(),
        });
    }
    out
}

/// Interface fields of s (the last linear stage, [`pair_values`]) in each interface's local frame:
/// normal and tangential traction on side a (MPa) and jump [W] = W_b − W_a (mm), per time point
/// and pair; plus each pair's status by name (from the last local stage). docs/outputs.md describes every field.
pub fn interface_fields(model: &Model, interfaces: &[InterfaceSolution]) -> Value {
    interface_fields_upto(model, interfaces, model.time.n_points())
}

/// One interface's entry of `fields.json` over the first `nt` time points: its sides, kind,
/// frame, pairs and weights, the tractions, jumps and statuses per time point and pair, and on a
/// non-matching interface each side's displacement at the pairs.
fn interface_entry(model: &Model, sol: &InterfaceSolution, nt: usize) -> Value {
    let itf = &model.interfaces[sol.interface as usize];
    let np = itf.n_pairs();
    // f_n, f_t, jump_n, jump_t: [quantity][time point][pair].
    let mut values: [Vec<Value>; 4] = std::array::from_fn(|_| Vec::with_capacity(nt));
    for i in 0..nt {
        let mut rows: [Vec<Value>; 4] = std::array::from_fn(|_| Vec::with_capacity(np));
        for p in 0..np {
            for (row, v) in rows.iter_mut().zip(pair_values(itf, sol, i, p)) {
                row.push(Value::from(v));
            }
        }
        for (q, row) in values.iter_mut().zip(rows) {
            q.push(Value::Array(row));
        }
    }
    let kind = match &itf.kind {
        InterfaceKind::Perfect => json!("perfect"),
        InterfaceKind::Contact { friction, .. } => json!({"contact": {"friction": friction}}),
    };
    let (normal, tangent) = itf.mean_frame();
    let mut entry = json!({
        "interface": sol.interface,
        "a": model.subdomains[itf.a].name,
        "b": model.subdomains[itf.b].name,
        "kind": kind,
        "normal": normal,
        "tangent": tangent,
        "coords": itf.coords,
        "weights": itf.weights,
    });
    let [f_n, f_t, jump_n, jump_t] = values;
    for (key, q) in [("f_n", f_n), ("f_t", f_t), ("jump_n", jump_n), ("jump_t", jump_t)] {
        entry[key] = Value::Array(q);
    }
    entry["status"] = Value::Array(if itf.is_contact() {
        (0..nt)
            .map(|i| {
                Value::Array(
                    sol.status[i * np..(i + 1) * np]
                        .iter()
                        .map(|&c| Value::String(status_name(c)))
                        .collect(),
                )
            })
            .collect()
    } else {
        Vec::new()
    });
    if itf.straight_normal().is_none() {
        entry["normals"] = json!(itf.normals);
    }
    if itf.is_non_matching() {
        // Each side's displacement at the pairs (global x, y): side b's through its
        // projection, side a's the node's own (or an end edge's mean).
        for (key, w) in [("u_a", &sol.w_a), ("u_b", &sol.w_b)] {
            entry[key] = Value::Array(
                (0..nt)
                    .map(|i| Value::Array((0..np).map(|p| json!([w.get(2 * p, i), w.get(2 * p + 1, i)])).collect()))
                    .collect(),
            );
        }
    }
    entry
}

/// [`interface_fields`] over the first `n_times` time points only (the steps a failed reference
/// solved; its fields have that many columns).
pub fn interface_fields_upto(model: &Model, interfaces: &[InterfaceSolution], n_times: usize) -> Value {
    use rayon::prelude::*;
    // Interfaces in parallel; every value is computed once and moved into the document (the
    // `json!` macro would serialize a vector into a new one, value by value).
    let items: Vec<Value> = interfaces
        .par_iter()
        .map(|sol| interface_entry(model, sol, n_times))
        .collect();
    let curved = model.interfaces.iter().any(|itf| itf.straight_normal().is_none());
    let mut doc = json!({
        "scene": model.name,
        "units": {
            "times": "s",
            "coords": "mm",
            "weights": "mm (lumped edge length of each pair)",
            "f_n": "MPa: traction on side a along the normal (compression negative)",
            "f_t": "MPa: traction on side a along the tangent",
            "jump_n": "mm: (W_b − W_a)·normal; jump_n + gap ≥ 0, = 0 where in contact (within the accuracy)",
            "jump_t": "mm: (W_b − W_a)·tangent",
            "normal": "unit vector out of side a towards side b; tangent = (−normal_y, normal_x)",
            "status": "per pair (contact interfaces only): separated, stick or slip, decided with a margin tied to the accuracy; limit (on the friction cone within the margin, not moving beyond it) or grazing (gap and contact force both within the margin of zero) where the fields cannot tell (docs/accuracy.md)",
            "u_a": "mm: side a's displacement (x, y) at each pair (non-matching interfaces only)",
            "u_b": "mm: side b's displacement (x, y) projected at each pair (non-matching interfaces only)",
        },
        "times": (0..n_times).map(|i| model.time.t(i)).collect::<Vec<_>>(),
        "interfaces": items,
    });
    if curved {
        doc["units"]["normal"] = json!(
            "unit vector out of side a towards side b (on a curved interface: the interface's mean \
             direction; each pair's own normal is in `normals`, and f_n, f_t, jump_n, jump_t are \
             measured in each pair's frame); tangent = (−normal_y, normal_x)"
        );
    }
    doc
}

/// Each subdomain's displacement per time point, as slices of a run's displacement fields (one
/// column per time point): `u[s][i]`.
pub fn displacement_slices<'a>(
    model: &Model,
    displacements: &'a [(u32, glissade_messages::Field)],
) -> Result<Vec<Vec<&'a [f64]>>> {
    let nt = model.time.n_points();
    (0..model.subdomains.len())
        .map(|s| {
            let sub = &model.subdomains[s];
            let (_, f) = displacements
                .iter()
                .find(|(k, _)| *k as usize == s)
                .ok_or_else(|| Error::ResultMissing {
                    what: format!("displacement of subdomain `{}`", sub.name),
                })?;
            let rows = f.rows();
            if rows != sub.n_dofs() || f.cols() != nt {
                return Err(Error::ResultShape {
                    what: format!("displacement of subdomain `{}` is {rows} × {}", sub.name, f.cols()),
                    scene: format!("{} × {nt}", sub.n_dofs()),
                });
            }
            Ok((0..nt).map(|i| &f.data[i * rows..(i + 1) * rows]).collect())
        })
        .collect()
}

/// The displacement file: per subdomain its mesh (node coordinates, QUA8 connectivity) and its
/// displacement at every time point, `u[i·rows + 2·node + c]` (time point i, component c: 0 x,
/// 1 y). docs/outputs.md.
pub fn displacements(model: &Model, displacements: &[(u32, glissade_messages::Field)]) -> Vec<Vec<u8>> {
    use rayon::prelude::*;
    /// One subdomain's entry, keys in the document's (alphabetical) order.
    #[derive(Serialize)]
    struct Entry<'a> {
        cols: u32,
        coords: &'a [[f64; 2]],
        elements: &'a [[usize; 8]],
        rows: u32,
        subdomain: &'a str,
        u: &'a [f64],
    }
    #[derive(Serialize)]
    struct Units {
        coords: &'static str,
        times: &'static str,
        u: &'static str,
    }
    // The subdomains' entries (most of the bytes) serialized in parallel, then joined in order.
    let entries: Vec<Vec<u8>> = displacements
        .par_iter()
        .map(|(s, f)| {
            let sub = &model.subdomains[*s as usize];
            let entry = Entry {
                cols: f.cols,
                coords: &sub.mesh.coords,
                elements: &sub.mesh.elements,
                rows: f.rows,
                subdomain: &sub.name,
                u: &f.data,
            };
            json_bytes(&entry)
        })
        .collect();
    let times: Vec<f64> = (0..model.time.n_points()).map(|i| model.time.t(i)).collect();
    object_pieces([
        ("displacements", Member::Items(entries)),
        ("layout", Member::Value(json_bytes(&DISPLACEMENT_LAYOUT))),
        ("scene", Member::Value(json_bytes(&model.name))),
        ("times", Member::Value(json_bytes(&times))),
        (
            "units",
            Member::Value(json_bytes(&Units {
                coords: "mm",
                times: "s",
                u: "mm",
            })),
        ),
    ])
}

/// How `displacement.json` lays out `u` and `elements`.
pub const DISPLACEMENT_LAYOUT: &str = "u[i·rows + 2·node + c]: time point i (column), node (0-based, order of coords), component c (0: x, 1: y); elements: 8 nodes each, corners counter-clockwise then mid-sides (VTK quadratic quad order)";

/// The `.pvd` file and the `.vtu` folder of outputs named `stem` in `out`.
pub fn series_paths(out: &Path, stem: &str) -> (PathBuf, PathBuf) {
    (out.join(format!("{stem}.pvd")), out.join(format!("{stem}-vtu")))
}

/// Pair `p` of interface `itf` at time point `i` in the interface's frame: the traction on side a
/// (normal, tangential; MPa) and the jump W_b − W_a (normal, tangential; mm), of s, the last
/// linear stage's state: the state the run's estimate and verdict judge, whose forces balance the
/// parts and whose traces are the parts' displacements (docs/outputs.md).
pub fn pair_values(itf: &Interface, sol: &InterfaceSolution, i: usize, p: usize) -> [f64; 4] {
    glissade_mechanics::settled::in_frame(itf, p, |r| [sol.w_a.get(r, i), sol.w_b.get(r, i), sol.f_a.get(r, i)])
}

/// The name of reported status code `c` ([`SETTLED_NAMES`]), or `invalid status code <c>`.
pub fn status_name(c: u8) -> String {
    SETTLED_NAMES
        .get(c as usize)
        .map_or_else(|| format!("invalid status code {c}"), |s| s.to_string())
}

pub use glissade_studies::table::csv_field;

/// The interface of a final solution `sol`, once its shape is checked against the scene: an
/// interface of the scene, W and F of 2·n_pairs × (N+1), and on a contact interface a status
/// code of [`SETTLED_NAMES`] for every pair and time point (a solution read from a recording may
/// hold anything).
pub fn checked_solution<'m>(model: &'m Model, sol: &InterfaceSolution) -> Result<&'m Interface> {
    let nt = model.time.n_points();
    let itf = model
        .interfaces
        .get(sol.interface as usize)
        .ok_or_else(|| Error::ResultShape {
            what: format!("a solution of interface {}", sol.interface),
            scene: format!("{} interface(s)", model.interfaces.len()),
        })?;
    let np = itf.n_pairs();
    if let Some((name, f)) = [("F_a", &sol.f_a), ("W_a", &sol.w_a), ("W_b", &sol.w_b)]
        .into_iter()
        .find(|(_, f)| f.rows() != 2 * np || f.cols() != nt)
    {
        return Err(Error::ResultShape {
            what: format!("interface {}: {name} is {} × {}", sol.interface, f.rows(), f.cols()),
            scene: format!("{} × {nt}", 2 * np),
        });
    }
    if itf.is_contact() {
        if sol.status.len() < np * nt {
            return Err(Error::ResultShape {
                what: format!("interface {}: {} statuses", sol.interface, sol.status.len()),
                scene: format!("{}", np * nt),
            });
        }
        if let Some(&code) = sol.status[..np * nt]
            .iter()
            .find(|&&c| c as usize >= SETTLED_NAMES.len())
        {
            return Err(Error::ResultShape {
                what: format!("interface {}: status code {code}", sol.interface),
                scene: format!("codes 0 to {}", SETTLED_NAMES.len() - 1),
            });
        }
    }
    Ok(itf)
}

/// The interface fields of s ([`pair_values`]) as CSV: one row per time point and node pair, with the pair's
/// position, the tractions on side a and the jumps in the interface's frame, and the status
/// (`separated`, `stick`, `slip`, `limit`, `grazing`, or `perfect` on a perfect interface); the parts' names quoted
/// where they must be ([`csv_field`]). docs/outputs.md.
pub fn interface_csv(model: &Model, interfaces: &[InterfaceSolution]) -> Result<String> {
    use rayon::prelude::*;
    use std::fmt::Write as _;
    let nt = model.time.n_points();
    // Every solution checked first; then the rows of each time point written in parallel and
    // joined in time order.
    let mut checked = Vec::with_capacity(interfaces.len());
    for sol in interfaces {
        let itf = checked_solution(model, sol)?;
        let statuses: Vec<&str> = if itf.is_contact() {
            sol.status[..itf.n_pairs() * nt]
                .iter()
                .map(|&code| SETTLED_NAMES[code as usize])
                .collect()
        } else {
            Vec::new()
        };
        let names = [itf.a, itf.b].map(|s| csv_field(&model.subdomains[s].name));
        checked.push((sol, itf, statuses, names));
    }
    let rows: Vec<String> = (0..nt)
        .into_par_iter()
        .map(|i| {
            let t = model.time.t(i);
            let mut out = String::new();
            for (sol, itf, statuses, [a, b]) in &checked {
                let np = itf.n_pairs();
                for p in 0..np {
                    let [f_n, f_t, jump_n, jump_t] = pair_values(itf, sol, i, p);
                    let status = if itf.is_contact() {
                        statuses[i * np + p]
                    } else {
                        "perfect"
                    };
                    let [x, y] = itf.coords[p];
                    let _ = writeln!(
                        out,
                        "{t:?},{},{a},{b},{p},{x:?},{y:?},{f_n:?},{f_t:?},{jump_n:?},{jump_t:?},{status}",
                        sol.interface
                    );
                }
            }
            out
        })
        .collect();
    let mut out = String::from("time,interface,a,b,pair,x,y,traction_n,traction_t,jump_n,jump_t,status\n");
    out.reserve(rows.iter().map(String::len).sum());
    for r in &rows {
        out.push_str(r);
    }
    Ok(out)
}

/// Writes `value` as JSON to `dir/name`, creating `dir`, through a partial file (replacing an
/// existing file of that name); returns the path.
pub fn write_json(dir: &Path, name: &str, value: &Value) -> Result<PathBuf> {
    write_json_as(dir, name, value, true)
}

/// As [`write_json`], never over an existing file (a run's outputs).
pub fn write_json_new(dir: &Path, name: &str, value: &Value) -> Result<PathBuf> {
    write_json_as(dir, name, value, false)
}

/// `doc` serialized (compact, as serde_json writes it) in pieces whose concatenation is the
/// document: the items of its top-level array `key` each a piece, serialized in parallel (a
/// run's large documents are mostly one such array: the interfaces of `fields.json`).
pub fn json_pieces(doc: &Value, key: &str) -> Vec<Vec<u8>> {
    use rayon::prelude::*;
    let Value::Object(map) = doc else {
        return vec![json_bytes(doc)];
    };
    object_pieces(map.iter().map(|(name, value)| {
        let member = match value {
            Value::Array(items) if name == key => Member::Items(items.par_iter().map(json_bytes).collect()),
            _ => Member::Value(json_bytes(value)),
        };
        (name.as_str(), member)
    }))
}

/// A member of a JSON object written in pieces ([`object_pieces`]): its value serialized, or the
/// items of its array, each serialized.
enum Member {
    Value(Vec<u8>),
    Items(Vec<Vec<u8>>),
}

/// The object of `members` (in the order given) in pieces whose concatenation is its compact
/// serialization: each array item a piece of its own, the keys and separators between them.
fn object_pieces<'k>(members: impl IntoIterator<Item = (&'k str, Member)>) -> Vec<Vec<u8>> {
    let (mut pieces, mut head) = (Vec::new(), b"{".to_vec());
    for (k, (name, member)) in members.into_iter().enumerate() {
        if k > 0 {
            head.push(b',');
        }
        head.extend_from_slice(&json_bytes(name));
        head.push(b':');
        match member {
            Member::Value(bytes) => head.extend_from_slice(&bytes),
            Member::Items(items) => {
                head.push(b'[');
                pieces.push(std::mem::take(&mut head));
                for (i, item) in items.into_iter().enumerate() {
                    if i > 0 {
                        pieces.push(b",".to_vec());
                    }
                    pieces.push(item);
                }
                head.push(b']');
            }
        }
    }
    head.push(b'}');
    pieces.push(head);
    pieces
}

/// `v` serialized compactly (what serde_json writes).
fn json_bytes<T: Serialize + ?Sized>(v: &T) -> Vec<u8> {
    serde_json::to_vec(v).expect("a document of strings, numbers and arrays serializes")
}

/// As [`write_json_new`], for a document already serialized, in pieces written one after the
/// other, in parallel (each at its place in the file).
pub fn write_bytes_new(dir: &Path, name: &str, pieces: &[Vec<u8>]) -> Result<PathBuf> {
    use rayon::prelude::*;
    use std::os::unix::fs::FileExt;
    std::fs::create_dir_all(dir).what(|| format!("cannot create output folder {}", dir.display()))?;
    let path = dir.join(name);
    let offsets: Vec<u64> = pieces
        .iter()
        .scan(0u64, |at, p| {
            let start = *at;
            *at += p.len() as u64;
            Some(start)
        })
        .collect();
    // Written past the buffer of `w`, which holds nothing and so writes nothing of its own.
    write_through_partial(&path, false, |w| {
        let file = w.get_ref();
        pieces
            .par_iter()
            .zip(&offsets)
            .try_for_each(|(p, &at)| file.write_all_at(p, at))
    })?;
    Ok(path)
}

fn write_json_as(dir: &Path, name: &str, value: &Value, replace: bool) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).what(|| format!("cannot create output folder {}", dir.display()))?;
    let path = dir.join(name);
    write_through_partial(&path, replace, |w| {
        serde_json::to_writer(w, value).map_err(std::io::Error::from)
    })?;
    Ok(path)
}

/// The reference solution's interface fields as [`InterfaceSolution`]s (s = ŝ), so that they are
/// written like a LATIN run's: the statuses decided by the same rule and margins as a run's
/// (`glissade_replay::settle_statuses`, the scene's accuracy, the reference's largest traction),
/// over the time points it solved.
pub fn reference_interfaces(model: &Model, reference: &ReferenceSolution) -> Vec<InterfaceSolution> {
    let mut sols: Vec<InterfaceSolution> = model
        .interfaces
        .iter()
        .enumerate()
        .map(|(i, _)| {
            let status = reference.contact[i]
                .as_ref()
                .map(|c| c.status.iter().map(|s| *s as u8).collect())
                .unwrap_or_default();
            solution_of_fields(i, &reference.interfaces[i], status)
        })
        .collect();
    let nt = reference.interfaces.first().map_or(0, |f| f.f_a.ncols());
    glissade_replay::settle_statuses(model, &mut sols, nt);
    sols
}

/// Interface `i`'s fields `f` as an [`InterfaceSolution`] whose s and ŝ are both `f`.
pub fn solution_of_fields(i: usize, f: &InterfaceFields, status: Vec<u8>) -> InterfaceSolution {
    let field = |m: &faer::Mat<f64>| glissade_bus::convert::field_of(m.as_ref());
    InterfaceSolution {
        interface: i as u32,
        w_a: field(&f.w_a),
        w_b: field(&f.w_b),
        f_a: field(&f.f_a),
        f_b: field(&f.f_b),
        w_a_hat: field(&f.w_a),
        w_b_hat: field(&f.w_b),
        f_a_hat: field(&f.f_a),
        f_b_hat: field(&f.f_b),
        status,
    }
}

#[cfg(test)]
mod tests {
    use super::{csv_field, time_left};

    /// A name with a comma, a double quote or a line break is quoted (RFC 4180), its quotes
    /// doubled; any other is written as it is (the CSV of ordinary names is unchanged).
    #[test]
    fn csv_fields_are_quoted_where_they_must_be() {
        assert_eq!(csv_field("lower"), "lower");
        assert!(matches!(csv_field("sheath.1 <&>"), std::borrow::Cow::Borrowed(_)));
        assert_eq!(csv_field("le,ft"), "\"le,ft\"");
        assert_eq!(csv_field("the \"up\" part"), "\"the \"\"up\"\" part\"");
        assert_eq!(csv_field("two\nlines\r"), "\"two\nlines\r\"");
        assert_eq!(csv_field(""), "");
    }

    /// 1e-2 to 1e-3 at a contraction of 0.5 per iteration: ln 10 / ln 2 = 3.3, so 4 iterations.
    #[test]
    fn time_left_counts_the_iterations_to_the_target_at_the_observed_rate() {
        assert_eq!(time_left(1e-2, 1e-3, 0.5, 0.25), Some(1.0));
        assert_eq!(time_left(1e-4, 1e-3, 0.5, 0.25), Some(0.0));
        assert_eq!(time_left(1e-2, 1e-3, 1.0, 0.25), None);
        assert_eq!(time_left(1e-2, 1e-3, f64::NAN, 0.25), None);
    }

    /// `displacement.json`, written in pieces made in parallel, is byte for byte serde_json's
    /// serialization of the document docs/outputs.md describes (keys in alphabetical order,
    /// non-finite values as null), for every subdomain of a scene and values of every magnitude.
    #[test]
    fn the_displacement_file_is_the_documented_document() {
        use serde_json::json;
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/launch/scenes/small-three-layer.toml");
        let scene = glissade_scene::load_str(&std::fs::read_to_string(path).unwrap(), path).unwrap();
        let model = &scene.model;
        let nt = model.time.n_points();
        let fields: Vec<(u32, glissade_messages::Field)> = model
            .subdomains
            .iter()
            .enumerate()
            .map(|(s, sub)| {
                let mut f = glissade_messages::Field::zeros(sub.n_dofs(), nt);
                for (k, v) in f.data.iter_mut().enumerate() {
                    *v = ((k * 7919 + s * 104729) % 2003) as f64 * 10f64.powi((k % 41) as i32 - 20) - 1e-3;
                }
                f.data[s] = f64::NAN;
                (s as u32, f)
            })
            .collect();
        let written: Vec<u8> = super::displacements(model, &fields).concat();
        let items: Vec<_> = fields
            .iter()
            .map(|(s, f)| {
                let sub = &model.subdomains[*s as usize];
                json!({
                    "subdomain": sub.name,
                    "coords": sub.mesh.coords,
                    "elements": sub.mesh.elements,
                    "rows": f.rows,
                    "cols": f.cols,
                    "u": *f.data,
                })
            })
            .collect();
        let doc = json!({
            "scene": model.name,
            "units": {"times": "s", "coords": "mm", "u": "mm"},
            "layout": super::DISPLACEMENT_LAYOUT,
            "times": (0..nt).map(|i| model.time.t(i)).collect::<Vec<_>>(),
            "displacements": items,
        });
        assert!(written == serde_json::to_vec(&doc).unwrap());
    }

    /// The pieces of a document join into serde_json's serialization of it, with its large array
    /// anywhere among the keys, empty, or missing.
    #[test]
    fn json_pieces_join_into_the_document() {
        use serde_json::json;
        let item = |k: usize| json!({"a \"quoted\" key": k, "x": [k as f64 * 0.1, -1e-300, f64::NAN], "s": "é\n"});
        for doc in [
            json!({"before": 1, "interfaces": (0..7).map(item).collect::<Vec<_>>(), "units": {"u": "mm"}}),
            json!({"interfaces": [], "z": null}),
            json!({"other": [1, 2, 3]}),
            json!([1, 2]),
        ] {
            let pieces = super::json_pieces(&doc, "interfaces");
            assert_eq!(
                String::from_utf8(pieces.concat()).unwrap(),
                serde_json::to_string(&doc).unwrap()
            );
        }
    }
}
