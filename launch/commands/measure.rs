//! The commands that measure: `reference` (the monolithic Newton solve), `report` (LATIN's error
//! against it), `bench` and `stability`.

use super::*;

/// What a user can do about a reference that did not converge at a time step.
pub(crate) const REFERENCE_HINT: &str = "hint: the reference solves the same discrete problem as LATIN, step by step; \
a step it cannot solve usually has many contact pairs at the edge of their law (gaps or stick margins near zero). \
The steps solved are written. \
A larger --newton-iterations may get through the step (into another --out, or once the partial file is moved away: \
nothing is overwritten); \
a different time discretisation (N) changes the problem but may avoid it. Please report the scene.";

/// The reference's options for `--newton-iterations n`: n per attempt, 20 n for the non-monotone
/// one (the defaults for n = 50).
pub(crate) fn reference_options(newton_iterations: u32) -> ReferenceOptions {
    let n = newton_iterations as usize;
    ReferenceOptions {
        max_newton_iterations: n,
        nonmonotone_iterations: 20 * n,
        ..ReferenceOptions::default()
    }
}

/// "k Newton iterations", or that the reference failed and after how many time points.
pub(crate) fn reference_outcome(report: &glissade::report::Report, n_points: usize) -> String {
    match report.reference_failure {
        None => format!("{} Newton iterations", report.reference_newton_iterations),
        Some(_) if report.errors_over_time_points > 0 => format!(
            "FAILED after {} of {n_points} time points; the errors are over those {} time points only",
            report.reference_steps_solved, report.errors_over_time_points
        ),
        Some(_) => format!(
            "FAILED after {} of {n_points} time points; no errors against it",
            report.reference_steps_solved
        ),
    }
}

/// The file of the time points a failed reference solved.
fn partial_name(scene: &str) -> String {
    format!("{scene}-reference-partial.fields.json")
}

/// Writes the interface fields of the time points a failed reference solved, prints its error
/// and the hint; the exit code of a reference failure.
pub(crate) fn reference_failed(
    model: &glissade_mechanics::model::Model,
    run: &ReferenceRun,
    error: &ReferenceError,
    out: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    let solved = run.solution.newton_iterations.len();
    // Never over an earlier partial file (of this command or of `report`): then the steps solved
    // are said but not written.
    let written = glissade::output::write_json_new(
        out,
        &partial_name(&model.name),
        &glissade::output::interface_fields_upto(model, &reference_interfaces(model, &run.solution), solved),
    );
    eprintln!("error: reference: {error}");
    eprintln!("{REFERENCE_HINT}");
    match written {
        Ok(f) => eprintln!(
            "reference: {solved} of {} time points solved, written to {} (PARTIAL)",
            model.time.n_points(),
            f.display()
        ),
        Err(e) => eprintln!(
            "reference: {solved} of {} time points solved, NOT written: {e}",
            model.time.n_points()
        ),
    }
    Ok(ExitCode::from(NOT_CONVERGED))
}

pub(crate) fn reference(
    scene: &std::path::Path,
    out: &std::path::Path,
    opts: &ReferenceOptions,
) -> anyhow::Result<ExitCode> {
    let sc = load_scene(scene)?;
    ensure_writable(out)?;
    let stem = format!("{}-reference", sc.model.name);
    ensure_absent(out, &[format!("{stem}.summary.json"), format!("{stem}.fields.json")])?;
    let t0 = std::time::Instant::now();
    let run = glissade::report::reference_with_progress(&sc.model, opts)?;
    if let Some(e) = &run.failure {
        return reference_failed(&sc.model, &run, e, out);
    }
    let sol = run.solution;
    let wall = t0.elapsed().as_secs_f64();
    let checks = verify(&sc.model, &sol)?;
    let total: usize = sol.newton_iterations.iter().sum();
    let max = sol.newton_iterations.iter().copied().max().unwrap_or(0);
    let summary = serde_json::json!({
        "scene": sc.model.name,
        "scene_fingerprint": format!("{:016x}", sc.fingerprint),
        "solver": "monolithic incremental semi-smooth Newton (Alart–Curnier)",
        "software": { "name": "glissade", "version": env!("CARGO_PKG_VERSION"), "profile": if cfg!(debug_assertions) { "debug" } else { "release" } },
        "wall_s": wall,
        "newton_iterations_per_step": sol.newton_iterations,
        "newton_iterations_total": total,
        "r_factor_used": sol.r_factor_used,
        "checks": checks_json(&checks),
    });
    let s = write_json(out, &format!("{stem}.summary.json"), &summary)?;
    let f = write_json(
        out,
        &format!("{stem}.fields.json"),
        &interface_fields(&sc.model, &reference_interfaces(&sc.model, &sol)),
    )?;
    println!(
        "scene `{}`: reference solved {} time points in {wall:.2} s, {total} Newton iterations (max {max} per step)",
        sc.model.name,
        sc.model.time.n_points()
    );
    println!("{}", checks_line(&checks));
    println!("summary: {}\nfields: {}", s.display(), f.display());
    Ok(ExitCode::SUCCESS)
}

/// The reference's residual checks by name, in [`Checks`]' order: the two scales, then the
/// largest relative violations.
fn checks_by_name(c: &Checks) -> [(&'static str, f64); 11] {
    [
        ("force_scale", c.force_scale),
        ("displacement_scale", c.displacement_scale),
        ("equilibrium", c.equilibrium),
        ("prescribed", c.prescribed),
        ("continuity", c.continuity),
        ("action_reaction", c.action_reaction),
        ("penetration", c.penetration),
        ("tension", c.tension),
        ("complementarity", c.complementarity),
        ("cone", c.cone),
        ("slip_direction", c.slip_direction),
    ]
}

/// The checks as a JSON object of numbers (the scales in N and mm, the rest relative to them).
fn checks_json(c: &Checks) -> serde_json::Value {
    checks_by_name(c)
        .into_iter()
        .map(|(k, v)| (k.to_string(), serde_json::json!(v)))
        .collect::<serde_json::Map<_, _>>()
        .into()
}

/// One line for the console: the largest relative violation of each law, then the scales.
fn checks_line(c: &Checks) -> String {
    let by_name = checks_by_name(c);
    let violations: Vec<String> = by_name[2..]
        .iter()
        .map(|(k, v)| format!("{} {v:.1e}", k.replace('_', " ")))
        .collect();
    format!(
        "checks (largest violation, relative): {}; scales: forces {:.4e} N, displacements {:.4e} mm",
        violations.join(", "),
        c.force_scale,
        c.displacement_scale
    )
}

pub(crate) fn bench(
    scene: &std::path::Path,
    out: &std::path::Path,
    max_iterations: Option<usize>,
    processes: Option<u32>,
) -> anyhow::Result<ExitCode> {
    let overrides = Overrides {
        max_iterations,
        ..Default::default()
    };
    let sc = load_with_overrides(scene, out, &overrides)?;
    let name = format!("{}-bench.json", sc.model.name);
    ensure_absent(out, std::slice::from_ref(&name))?;
    let run_id = default_run_id()?;
    let report = glissade::bench::bench(&sc, &run_id)?;
    print!("{}", glissade::bench::render(&report));
    // Written before the process rounds, so that a failing round loses nothing already measured.
    let mut json = serde_json::to_value(&report)?;
    let mut j = write_json(out, &name, &json)?;
    if let Some(rounds) = processes {
        let exe = std::env::current_exe().context("the path of this program, to start node processes")?;
        let c = glissade::bench::compare_processes(&sc, &exe, rounds as usize, default_run_id)?;
        print!("{}", glissade::bench::render_processes(&c));
        json["processes"] = serde_json::to_value(&c)?;
        j = write_json(out, &name, &json)?;
    }
    println!("bench: {}", j.display());
    Ok(ExitCode::SUCCESS)
}

/// The plots of `glissade report`.
pub(crate) struct Plots {
    pub(crate) time_axis: TimeAxis,
    /// Subdomains (from 1) whose basis sizes the iterations plot shows.
    pub(crate) basis_subdomains: Vec<usize>,
}

/// Writes `<scene>-iterations.svg` (η, traction error and basis sizes against the iterations).
pub(crate) fn write_iterations_plot(
    out: &std::path::Path,
    name: &str,
    reports: &[glissade::report::Report],
    plots: &Plots,
) -> anyhow::Result<std::path::PathBuf> {
    let path = out.join(format!("{name}-iterations.svg"));
    std::fs::write(
        &path,
        glissade::report::plot_iterations_svg(reports, &plots.basis_subdomains),
    )
    .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

pub(crate) fn report(
    scene: &std::path::Path,
    out: &std::path::Path,
    overrides: &Overrides,
    stop_at: Option<f64>,
    reference_options: &ReferenceOptions,
    plots: &Plots,
) -> anyhow::Result<ExitCode> {
    let time_axis = plots.time_axis;
    let sc = load_with_overrides(scene, out, overrides)?;
    let name = &sc.model.name;
    ensure_absent(
        out,
        &[
            format!("{name}-report.json"),
            format!("{name}-report.svg"),
            format!("{name}-iterations.svg"),
        ],
    )?;
    let run_id = default_run_id()?;
    let (report, reference, _) = build_report_with(&sc, &run_id, stop_at, reference_options)?;
    let j = write_json(out, &format!("{name}-report.json"), &serde_json::to_value(&report)?)?;
    let svg_path = out.join(format!("{name}-report.svg"));
    std::fs::write(&svg_path, plot_svg(&report, time_axis))
        .with_context(|| format!("cannot write {}", svg_path.display()))?;
    println!(
        "scene `{name}`: reference {:.2} s ({}); LATIN setup {:.2} s + {:.2} s, {} iterations, {}",
        report.reference_s,
        reference_outcome(&report, sc.model.time.n_points()),
        report.latin_setup_s,
        report.latin_solve_s,
        report.points.len(),
        report.latin_verdict
    );
    let [mixed, plain, restarts] = report.anderson_steps;
    println!(
        "acceleration: {} ({mixed} mixed steps, {plain} safeguarded plain steps, {restarts} restarts)",
        report.acceleration
    );
    println!("| contact traction error | LATIN wall time (s) | iterations | / reference time |");
    println!("|---|---|---|---|");
    for (th, t, it) in &report.time_to_accuracy {
        match (t, it) {
            (Some(t), Some(it)) => println!("| {th:.0e} | {t:.2} | {it} | {:.2} |", t / report.reference_s),
            _ => println!("| {th:.0e} | not reached | | |"),
        }
    }
    print!("{}", linear_stage_table(&report));
    let it_path = write_iterations_plot(out, name, std::slice::from_ref(&report), plots)?;
    println!(
        "report: {}\nplot: {}\nplot against the iterations: {}",
        j.display(),
        svg_path.display(),
        it_path.display()
    );
    match &reference.failure {
        Some(e) => {
            if report.errors_over_time_points > 0 {
                println!(
                    "ERRORS OVER THE FIRST {} OF {} TIME POINTS ONLY: the reference failed at the next (see below); the LATIN run above is complete",
                    report.errors_over_time_points,
                    sc.model.time.n_points()
                );
            } else {
                println!("NO ERRORS AGAINST THE REFERENCE: it failed (see below); the LATIN run above is complete");
            }
            reference_failed(&sc.model, &reference, e, out)
        }
        None => Ok(ExitCode::SUCCESS),
    }
}

/// `glissade report --variants a,b,…`: one reference, one LATIN run per variant.
pub(crate) fn report_variants(
    scene: &std::path::Path,
    out: &std::path::Path,
    overrides: &Overrides,
    names: &[String],
    stop_at: Option<f64>,
    reference_options: &ReferenceOptions,
    plots: &Plots,
) -> anyhow::Result<ExitCode> {
    let time_axis = plots.time_axis;
    let variants = names
        .iter()
        .map(|n| {
            n.parse::<glissade::report::Variant>()
                .map_err(|e| anyhow::anyhow!("--variants: {e}"))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let sc = load_with_overrides(scene, out, overrides)?;
    let scene_name = &sc.model.name;
    let mut targets: Vec<String> = names
        .iter()
        .flat_map(|stage| {
            [
                format!("{scene_name}-{stage}-report.json"),
                format!("{scene_name}-{stage}-report.svg"),
            ]
        })
        .collect();
    targets.push(format!("{scene_name}-iterations.svg"));
    ensure_absent(out, &targets)?;
    // In-process runs only: the run id names nothing on a network.
    let run_id = format!("{}-report", sc.model.name);
    let (reports, reference) =
        glissade::report::build_reports_with(&sc, &run_id, &variants, stop_at, reference_options)?;
    let name = &sc.model.name;
    println!(
        "scene `{name}`: reference {:.2} s ({}), N = {}",
        reports[0].reference_s,
        reference_outcome(&reports[0], sc.model.time.n_points()),
        sc.model.time.n_points() - 1
    );
    print!("{}", glissade::report::comparison_table(&reports));
    for (r, stage) in reports.iter().zip(names) {
        let j = write_json(out, &format!("{name}-{stage}-report.json"), &serde_json::to_value(r)?)?;
        let svg_path = out.join(format!("{name}-{stage}-report.svg"));
        std::fs::write(&svg_path, plot_svg(r, time_axis))
            .with_context(|| format!("cannot write {}", svg_path.display()))?;
        println!("report: {}\nplot: {}", j.display(), svg_path.display());
    }
    let it_path = write_iterations_plot(out, name, &reports, plots)?;
    println!("plot against the iterations: {}", it_path.display());
    match &reference.failure {
        Some(e) => {
            println!("NO ERRORS AGAINST THE REFERENCE: it failed (see below); the LATIN runs above are complete");
            reference_failed(&sc.model, &reference, e, out)
        }
        None => Ok(ExitCode::SUCCESS),
    }
}

/// `glissade stability --accuracy`: the stop on accuracy checked on every converging case.
pub(crate) fn stability_accuracy(
    cases: &[glissade::stability::Case],
    out: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    use glissade::accuracy::{check_cases, markdown, summary};
    let results = check_cases(cases, |r| match r {
        Ok(c) => eprintln!(
            "{}: {}",
            c.name,
            c.stops
                .iter()
                .map(|s| format!(
                    "{:.0e} → {}",
                    s.accuracy,
                    s.ratio().map_or("not reached".into(), |r| format!("{r:.2}×"))
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        Err(e) => eprintln!("{e}"),
    });
    let (mut checks, mut failures) = (Vec::new(), Vec::new());
    for r in results {
        match r {
            Ok(c) => checks.push(c),
            Err(f) => failures.push(f),
        }
    }
    let mut table = markdown(&checks);
    table += &format!("\n{}\n", summary(&checks));
    for f in &failures {
        table += &format!("\nnot checked: {f}\n");
    }
    let md = out.join("stability-accuracy.md");
    std::fs::write(&md, &table).with_context(|| format!("cannot write {}", md.display()))?;
    let j = write_json(
        out,
        "stability-accuracy.json",
        &serde_json::json!({ "checks": checks, "not_checked": failures }),
    )?;
    println!("{table}");
    println!("table: {}\njson: {}", md.display(), j.display());
    Ok(if failures.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(NOT_CONVERGED)
    })
}

pub(crate) fn stability(
    quick: bool,
    only: &[String],
    list: bool,
    accuracy: bool,
    out: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    use glissade::stability::{cases, markdown, run_cases, Assessment, RunRow};
    let mut selected = cases(quick && only.is_empty());
    if list {
        for c in &selected {
            println!("{:<44} {}", c.name, c.varies);
        }
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(unknown) = only.iter().find(|n| !selected.iter().any(|c| c.name == n.as_str())) {
        anyhow::bail!("--case {unknown}: no such case (`glissade stability --list` names them)");
    }
    if !only.is_empty() {
        selected.retain(|c| only.iter().any(|n| n == c.name));
    }
    ensure_writable(out)?;
    let stem = if accuracy { "stability-accuracy" } else { "stability" };
    ensure_absent(out, &[format!("{stem}.md"), format!("{stem}.json")])?;
    if accuracy {
        return stability_accuracy(&selected, out);
    }
    let rows = run_cases(&selected, |r| {
        let ended = |row: &RunRow| match row.iterations {
            Some(n) => format!("{} after {n} iterations", row.outcome.kind()),
            None => row.outcome.kind().to_string(),
        };
        eprintln!(
            "{}: {}, with Anderson {} (acceleration {}; {})",
            r.case,
            ended(&r.plain),
            ended(&r.anderson),
            r.acceleration.kind(),
            match r.assessment {
                Assessment::AsExpected => "as expected",
                Assessment::Unexpected => "NOT as expected",
            }
        );
    });
    let table = markdown(&rows);
    let md = out.join("stability.md");
    std::fs::write(&md, &table).with_context(|| format!("cannot write {}", md.display()))?;
    let j = write_json(out, "stability.json", &serde_json::to_value(&rows)?)?;
    println!("{table}");
    println!("table: {}\njson: {}", md.display(), j.display());
    // Exit 3 when a case does not end as expected.
    Ok(if rows.iter().all(|r| r.assessment != Assessment::Unexpected) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(NOT_CONVERGED)
    })
}

/// `glissade validate`: the stop on accuracy on the generated validation set.
pub(crate) fn validate(
    part: crate::cli::PartArg,
    seeds: std::ops::Range<u64>,
    out: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    use crate::cli::PartArg;
    use glissade::validate::{markdown, validate_seed, Part};
    let (stem, keep): (&str, fn(Part) -> bool) = match part {
        PartArg::HeldOut => ("validation-held-out", |p| p == Part::HeldOut),
        PartArg::Calibration => ("validation-calibration", |p| p == Part::Calibration),
        PartArg::All => ("validation-all", |_| true),
    };
    ensure_writable(out)?;
    ensure_absent(out, &[format!("{stem}.md"), format!("{stem}.json")])?;
    let scenes = out.join("scenes");
    let chosen: Vec<u64> = seeds.filter(|&s| keep(Part::of(s))).collect();
    let mut results = Vec::with_capacity(chosen.len());
    for (k, &seed) in chosen.iter().enumerate() {
        let v = validate_seed(seed, &scenes, &Default::default())?;
        let line = match &v.check {
            Ok(c) => c
                .stops
                .iter()
                .map(|s| {
                    format!(
                        "{:.0e} → {}",
                        s.accuracy,
                        match (s.iteration, s.ratio()) {
                            (Some(i), Some(r)) => format!("{r:.2}× at {i}"),
                            (Some(i), None) => format!("stop at {i}"),
                            (None, _) => "NOT converged".into(),
                        }
                    )
                })
                .collect::<Vec<_>>()
                .join(", "),
            Err(e) => format!("not checked: {e}"),
        };
        eprintln!(
            "[{}/{}] seed {seed} ({}, {:.1} s): {line}",
            k + 1,
            chosen.len(),
            v.family,
            v.seconds
        );
        results.push(v);
    }
    let table = markdown(&results);
    let md = out.join(format!("{stem}.md"));
    std::fs::write(&md, &table).with_context(|| format!("cannot write {}", md.display()))?;
    let j = write_json(out, &format!("{stem}.json"), &serde_json::to_value(&results)?)?;
    print!("{}", glissade::validate::summary(&results));
    println!(
        "table: {}\njson: {}\nscenes: {}",
        md.display(),
        j.display(),
        scenes.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// `glissade report`: its arguments checked, then one report or a comparison of variants.
pub(crate) fn report_command(args: crate::cli::ReportArgs) -> anyhow::Result<ExitCode> {
    let overrides = Overrides {
        accuracy: args.accuracy,
        tolerance: args.tolerance,
        max_iterations: args.max_iterations,
        record: None,
    };
    let ropts = reference_options(args.newton_iterations);
    if let Some(e) = args.stop_at_error {
        if !(e > 0.0 && e.is_finite()) {
            anyhow::bail!("--stop-at-error {e}: must be a positive number");
        }
    }
    let plots = Plots {
        time_axis: if args.log_time { TimeAxis::Log } else { TimeAxis::Linear },
        basis_subdomains: args.basis_subdomains.iter().map(|&s| s as usize).collect(),
    };
    if args.variants.is_empty() {
        report(&args.scene, &args.out, &overrides, args.stop_at_error, &ropts, &plots)
    } else {
        report_variants(
            &args.scene,
            &args.out,
            &overrides,
            &args.variants,
            args.stop_at_error,
            &ropts,
            &plots,
        )
    }
}
