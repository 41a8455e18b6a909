//! The error-against-run-time report (issue "monolithic reference"): the monolithic Newton
//! reference of a scene, then the LATIN run, whose contact tractions and jumps are compared with
//! the reference at every iteration; written as JSON and as an SVG plot.

use crate::runner::{run_in_process_observed, RunOptions, RunResult};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::default_k0;
use glissade_mechanics::local::{error_against_reference, InterfaceFields};
use glissade_mechanics::model::Acceleration;
use glissade_mechanics::reference::{solve_reference, ReferenceOptions, ReferenceSolution};
use glissade_mechanics::scene::LoadedScene;
use glissade_messages::Payload;
use serde::Serialize;
use std::collections::BTreeSet;
use std::time::Instant;

/// One LATIN iteration of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReportPoint {
    pub iteration: u32,
    /// Wall time of the LATIN iteration loop at the end of this iteration (s), error
    /// measurement excluded.
    pub elapsed_s: f64,
    pub eta: f64,
    pub contact_indicator: f64,
    /// Relative space-time error of the contact tractions of s against the reference.
    pub traction_error: f64,
    /// Relative space-time error of the contact jumps of s against the reference.
    pub jump_error: f64,
}

/// Everything a report holds.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub scene: String,
    pub scene_fingerprint: String,
    pub software_version: String,
    pub build_profile: String,
    pub cores: usize,
    pub reference_s: f64,
    pub reference_newton_iterations: usize,
    pub reference_max_newton_per_step: usize,
    pub latin_setup_s: f64,
    pub latin_solve_s: f64,
    pub latin_verdict: String,
    /// The scene's acceleration (`none`, or `anderson(m)`).
    pub acceleration: String,
    /// Anderson steps of the run: mixed, plain (the safeguard), restarts.
    pub anderson_steps: [u32; 3],
    pub points: Vec<ReportPoint>,
    /// (threshold, LATIN wall time incl. setup to reach traction error ≤ threshold, iterations).
    pub time_to_accuracy: Vec<(f64, Option<f64>, Option<u32>)>,
}

/// Solves the reference and runs LATIN (with the scene's solver settings), measuring the error at
/// every iteration.
pub fn build_report(scene: &LoadedScene, run_id: &str) -> anyhow::Result<(Report, ReferenceSolution, RunResult)> {
    let model = &scene.model;
    let t0 = Instant::now();
    let reference = solve_reference(model, &ReferenceOptions::default())?;
    let reference_s = t0.elapsed().as_secs_f64();

    let k0 = default_k0(model);
    let layouts: Vec<BoundaryLayout> = (0..model.subdomains.len())
        .map(|s| BoundaryLayout::new(model, s, &k0))
        .collect();
    let participants = layouts.iter().filter(|l| !l.is_empty()).count();
    let nt = model.time.n_points();
    let weights = model.time.trapezoid_weights();
    let mut fields: Vec<InterfaceFields> = model
        .interfaces
        .iter()
        .map(|i| InterfaceFields::zeros(i.n_pairs(), nt))
        .collect();
    let mut seen = BTreeSet::new();
    let mut errors: Vec<(u32, f64, f64)> = Vec::new();
    let mut anderson_steps = [0u32; 3];
    let opts = RunOptions {
        run_id: run_id.to_string(),
        interior: false,
    };
    let result = run_in_process_observed(
        scene,
        &opts,
        |_| {},
        |m| {
            let t = Instant::now();
            if let Payload::AndersonStep { gamma, restart } = &m.payload {
                anderson_steps[if *restart {
                    2
                } else if gamma.is_empty() {
                    1
                } else {
                    0
                }] += 1;
            }
            if let Payload::BoundaryState { subdomain, w, f } = &m.payload {
                for slot in &layouts[*subdomain as usize].slots {
                    fields[slot.interface].set_side(slot.side, slot.offset, |r, c| w.get(r, c), |r, c| f.get(r, c));
                }
                seen.insert(*subdomain);
                if seen.len() == participants {
                    let (e_f, e_w) =
                        error_against_reference(&model.interfaces, &fields, &reference.interfaces, &weights);
                    errors.push((m.envelope.iteration, e_f, e_w));
                    seen.clear();
                }
            }
            t.elapsed()
        },
    )?;
    let points: Vec<ReportPoint> = result
        .iterations
        .iter()
        .filter_map(|r| {
            let &(_, e_f, e_w) = errors.iter().find(|e| e.0 == r.iteration)?;
            Some(ReportPoint {
                iteration: r.iteration,
                elapsed_s: r.elapsed_s,
                eta: r.decision.eta,
                contact_indicator: r.decision.contact_indicator,
                traction_error: e_f,
                jump_error: e_w,
            })
        })
        .collect();
    let time_to_accuracy = [1e-2, 1e-3, 1e-4]
        .iter()
        .map(|&th| {
            let hit = points.iter().find(|p| p.traction_error <= th);
            (th, hit.map(|p| result.setup_s + p.elapsed_s), hit.map(|p| p.iteration))
        })
        .collect();
    let report = Report {
        scene: model.name.clone(),
        scene_fingerprint: format!("{:016x}", scene.fingerprint),
        software_version: env!("CARGO_PKG_VERSION").to_string(),
        build_profile: if cfg!(debug_assertions) { "debug" } else { "release" }.to_string(),
        cores: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        reference_s,
        reference_newton_iterations: reference.newton_iterations.iter().sum(),
        reference_max_newton_per_step: reference.newton_iterations.iter().copied().max().unwrap_or(0),
        latin_setup_s: result.setup_s,
        latin_solve_s: result.solve_s,
        latin_verdict: format!("{:?}", result.verdict),
        acceleration: match model.solver.acceleration {
            Acceleration::None => "none".into(),
            Acceleration::Anderson { window } => format!("anderson({window})"),
        },
        anderson_steps,
        points,
        time_to_accuracy,
    };
    Ok((report, reference, result))
}

/// A plotted series: name, colour, value of a point.
type Series = (&'static str, &'static str, Box<dyn Fn(&ReportPoint) -> f64>);

/// SVG plot of the errors and indicators against wall time (log scale), with the reference's
/// run time marked.
pub fn plot_svg(report: &Report) -> String {
    let (w, h) = (900.0, 560.0);
    let (left, right, top, bottom) = (80.0, 200.0, 40.0, 60.0);
    let series: [Series; 4] = [
        ("traction error vs reference", "#d62728", Box::new(|p| p.traction_error)),
        ("jump error vs reference", "#1f77b4", Box::new(|p| p.jump_error)),
        ("η (LATIN indicator)", "#2ca02c", Box::new(|p| p.eta)),
        ("contact indicator e_c", "#9467bd", Box::new(|p| p.contact_indicator)),
    ];
    let t_of = |p: &ReportPoint| report.latin_setup_s + p.elapsed_s;
    let t_max = report
        .points
        .iter()
        .map(t_of)
        .fold(report.reference_s, f64::max)
        .max(1e-9)
        * 1.05;
    let values: Vec<f64> = report
        .points
        .iter()
        .flat_map(|p| series.iter().map(move |s| (s.2)(p)))
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    let lo = values
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
        .max(1e-16)
        .log10()
        .floor();
    let hi = values
        .iter()
        .cloned()
        .fold(0.0f64, f64::max)
        .max(10f64.powf(lo + 1.0))
        .log10()
        .ceil();
    let x = |t: f64| left + (w - left - right) * t / t_max;
    let y = |v: f64| top + (h - top - bottom) * (hi - v.max(1e-300).log10()) / (hi - lo).max(1.0);
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{}" y="22" font-size="15" text-anchor="middle">{}: LATIN error against the monolithic reference vs wall time</text>
<rect x="{left}" y="{top}" width="{}" height="{}" fill="none" stroke="black"/>
"#,
        (left + w - right) / 2.0,
        report.scene,
        w - left - right,
        h - top - bottom
    );
    let mut e = lo;
    while e <= hi + 0.5 {
        let yy = y(10f64.powf(e));
        svg += &format!(
            "<line x1=\"{left}\" y1=\"{yy}\" x2=\"{}\" y2=\"{yy}\" stroke=\"#ddd\"/><text x=\"{}\" y=\"{}\" text-anchor=\"end\">1e{}</text>\n",
            w - right,
            left - 6.0,
            yy + 4.0,
            e as i32
        );
        e += 1.0;
    }
    for k in 0..=5 {
        let t = t_max * k as f64 / 5.0;
        svg += &format!(
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{t:.2}</text>\n",
            x(t),
            h - bottom + 18.0
        );
    }
    svg += &format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">wall time (s), operator setup included</text>\n",
        (left + w - right) / 2.0,
        h - 15.0
    );
    let xr = x(report.reference_s);
    svg += &format!(
        "<line x1=\"{xr}\" y1=\"{top}\" x2=\"{xr}\" y2=\"{}\" stroke=\"black\" stroke-dasharray=\"6,4\"/><text x=\"{}\" y=\"{}\" transform=\"rotate(-90 {} {})\">monolithic Newton reference: {:.2} s</text>\n",
        h - bottom,
        xr - 6.0,
        top + 240.0,
        xr - 6.0,
        top + 240.0,
        report.reference_s
    );
    for (k, (name, color, f)) in series.iter().enumerate() {
        let pts: Vec<String> = report
            .points
            .iter()
            .filter(|p| f(p) > 0.0 && f(p).is_finite())
            .map(|p| format!("{:.2},{:.2}", x(t_of(p)), y(f(p))))
            .collect();
        svg += &format!(
            "<polyline fill=\"none\" stroke=\"{color}\" stroke-width=\"1.8\" points=\"{}\"/>\n",
            pts.join(" ")
        );
        let ly = top + 20.0 + 20.0 * k as f64;
        svg += &format!(
            "<line x1=\"{}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{color}\" stroke-width=\"2\"/><text x=\"{}\" y=\"{}\">{name}</text>\n",
            w - right + 10.0,
            w - right + 30.0,
            w - right + 35.0,
            ly + 4.0
        );
    }
    svg += "</svg>\n";
    svg
}
