//! `glissade sweep`: a study's variants through the run pipeline, then its tables and plots.

use super::{ensure_absent, ensure_writable, ExitCode, NOT_CONVERGED};
use anyhow::Context;
use glissade::study::PipelineSolver;
use glissade_studies::driver::run;
use glissade_studies::study::Study;
use glissade_studies::{plot, table};
use std::path::Path;

/// The study of `path` (a study file, or a scene with `--vary`), with `--accuracy`, its name made
/// fit for file names and run ids (`-cold` added for a cold study).
fn study_of(path: &Path, vary: &[String], cold: bool, accuracy: Option<f64>) -> anyhow::Result<Study> {
    let mut study = if vary.is_empty() {
        Study::read(path)?
    } else {
        Study::from_vary(path, vary, None)?
    };
    if let Some(a) = accuracy {
        if !(a > 0.0 && a < 1.0) {
            anyhow::bail!("--accuracy {a}: must be in (0, 1)");
        }
        study.accuracy = Some(a);
    }
    // The name becomes part of file names and of run ids.
    study.name = study
        .name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(48)
        .collect();
    if cold {
        study.name.push_str("-cold");
    }
    Ok(study)
}

pub(crate) fn sweep(
    path: &Path,
    vary: &[String],
    cold: bool,
    accuracy: Option<f64>,
    record: bool,
    out: &Path,
) -> anyhow::Result<ExitCode> {
    let study = study_of(path, vary, cold, accuracy)?;
    // The scene as a file: its text is what each variant rewrites; a scene that does not load
    // as it is stops the study before any variant.
    let base =
        glissade::load_scene(&study.scene).with_context(|| format!("the study's scene {}", study.scene.display()))?;
    let text =
        std::fs::read_to_string(&study.scene).with_context(|| format!("cannot read {}", study.scene.display()))?;
    ensure_writable(out)?;
    let (csv_name, json_name) = (format!("{}.csv", study.name), format!("{}.json", study.name));
    let mut names = vec![csv_name.clone(), json_name.clone()];
    names.extend(plot::file_names(&study));
    let n = glissade_studies::variants::variants(&study).len();
    if record {
        names.extend((0..n).map(|k| format!("{}-v{k}.mcap", study.name)));
    }
    ensure_absent(out, &names)?;
    eprintln!(
        "study {}: {n} variants of {} ({} subdomains, {} interfaces, N = {}), {}",
        study.name,
        study.scene.display(),
        base.model.subdomains.len(),
        base.model.interfaces.len(),
        base.model.time.n_steps,
        if cold { "cold" } else { "warm-started" }
    );
    let mut solver = PipelineSolver::new(record.then(|| (out.to_path_buf(), study.name.clone())));
    let result = run(&study, &text, &mut solver, cold, |o| {
        let what = match &o.result {
            Ok((s, _)) => format!("{} iterations, {}", s.iterations, s.verdict_text),
            Err(e) => e.clone(),
        };
        let values: Vec<String> = study
            .parameters
            .iter()
            .zip(&o.variant.values)
            .map(|(p, v)| format!("{} = {v}", p.name))
            .collect();
        let from = o
            .started_from
            .map_or("from ŝ = 0".into(), |f| format!("from variant {f}"));
        eprintln!(
            "[{}/{n}] {} ({from}, {:.2} s): {what}",
            o.variant.index + 1,
            values.join(", "),
            o.wall_s
        );
    })?;
    for line in table::summary(&result) {
        println!("{line}");
    }
    glissade::output::write_bytes_new(out, &csv_name, &[table::csv(&result).into_bytes()])?;
    glissade::output::write_json_new(out, &json_name, &table::json(&result))?;
    let plots = plot::plots(&result);
    for (name, svg) in &plots {
        glissade::output::write_bytes_new(out, name, &[svg.clone().into_bytes()])?;
    }
    println!(
        "wrote {csv_name}, {json_name} and {} plots ({}-<quantity>-vs-<parameter>.svg) in {}",
        plots.len(),
        study.name,
        out.display()
    );
    let all = result.outcomes.iter().all(|o| o.converged());
    Ok(if all {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(NOT_CONVERGED)
    })
}

pub(crate) fn onset(scene: &Path, req: glissade_studies::onset::OnsetRequest, out: &Path) -> anyhow::Result<ExitCode> {
    let base = glissade::load_scene(scene)?;
    let text = std::fs::read_to_string(scene).with_context(|| format!("cannot read {}", scene.display()))?;
    let rules = base.model.boundary_rules.len();
    if req.rule >= rules {
        anyhow::bail!(
            "--rule {}: the scene has {rules} boundary rule(s), numbered from 0",
            req.rule
        );
    }
    if let Some(a) = req.accuracy {
        if !(a > 0.0 && a < 1.0) {
            anyhow::bail!("--accuracy {a}: must be in (0, 1)");
        }
    }
    ensure_writable(out)?;
    let name = format!("{}-onset.json", base.model.name);
    ensure_absent(out, std::slice::from_ref(&name))?;
    eprintln!(
        "onset of {}: the factor on its values at which {} first slips at a point, and over its whole length",
        base.model.boundary_rules[req.rule].name,
        if req.interfaces.is_empty() {
            "a contact interface".to_string()
        } else {
            format!("interface {:?}", req.interfaces)
        }
    );
    let mut solver = PipelineSolver::new(None);
    let mut k = 0;
    let result = glissade_studies::onset::onset(scene, &text, &req, &mut solver, |t| {
        k += 1;
        let at = |v: Option<f64>| v.map_or("never".to_string(), |t| format!("from t = {t}"));
        eprintln!(
            "[{k}] factor {:.6}: {} iterations, {:.2} s: slips at a point {}, over a whole interface {}; {}",
            t.scale,
            t.iterations,
            t.seconds,
            at(t.first_slip_at),
            at(t.full_slip_at),
            if t.converged {
                "converged".to_string()
            } else {
                t.verdict.clone()
            }
        );
    })?;
    let line = |what: &str, b: &glissade_studies::onset::Bracket| match (b.below, b.above) {
        (Some(lo), Some(hi)) => format!("{what}: factor between {lo:.6} (held) and {hi:.6} (did not)"),
        (Some(lo), None) => format!("{what}: not reached; held up to factor {lo:.6}"),
        (None, Some(hi)) => format!("{what}: already at factor {hi:.6}, the smallest tried"),
        (None, None) => format!("{what}: no trial"),
    };
    println!("{}", line("first slip at a point", &result.first_slip));
    println!(
        "{}",
        line(
            "slip over a whole interface (no equilibrium beyond it for a part held by friction)",
            &result.full_slip
        )
    );
    let iterations: usize = result.trials.iter().map(|t| t.iterations).sum();
    println!(
        "{} solves, {iterations} iterations, {:.2} s in all",
        result.trials.len(),
        result.seconds
    );
    if let Some(why) = &result.unfinished {
        println!("stopped short of the bracket asked: {why}");
    }
    glissade::output::write_json_new(out, &name, &serde_json::json!(result))?;
    println!("wrote {}", out.join(&name).display());
    Ok(if result.unfinished.is_none() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(NOT_CONVERGED)
    })
}
