//! `glissade run`: a scene in-process or as node processes, its progress, its live Rerun view
//! and its outputs.

use super::*;

/// The live Rerun view of `run --rerun`, fed every message of the run; its first failure is kept
/// and reported when the run ends (the run itself does not depend on the view).
pub(crate) struct LiveView {
    view: Option<glissade_replay::View>,
    failure: Option<glissade_replay::ReplayError>,
    /// The .rrd file the view is written to (None: streamed to a viewer).
    file: Option<std::path::PathBuf>,
}

impl LiveView {
    fn new(args: &RunArgs, sc: &LoadedScene, run_id: &str) -> anyhow::Result<Self> {
        let mut file = None;
        let view = match &args.rerun {
            Some(sink) => {
                let sink = glissade_replay::Sink::parse(sink).map_err(|e| anyhow::anyhow!("--rerun {e}"))?;
                if let glissade_replay::Sink::Save(path) = &sink {
                    file = Some(path.clone());
                }
                let opts = glissade_replay::ReplayOptions {
                    sink,
                    color_by: glissade_replay::ColorBy::VonMises,
                    amplification: None,
                    time_point: None,
                    reference: false,
                    basis_sizes: Vec::new(),
                };
                let origin = args.scene.display().to_string();
                Some(glissade_replay::View::new(
                    &sc.text,
                    &sc.overrides,
                    &origin,
                    run_id,
                    &opts,
                    None,
                )?)
            }
            None => None,
        };
        Ok(Self {
            view,
            failure: None,
            file,
        })
    }

    fn message(&mut self, m: &glissade_messages::Message) {
        if let (Some(v), None) = (self.view.as_mut(), &self.failure) {
            if let Err(e) = v.message(m) {
                self.failure = Some(e);
            }
        }
    }

    fn finish(&mut self) -> anyhow::Result<()> {
        if let Some(e) = self.failure.take() {
            anyhow::bail!("--rerun: {e}");
        }
        if let Some(v) = self.view.take() {
            let s = v.finish()?;
            match &self.file {
                Some(f) => println!(
                    "rerun: {} iterations, {} meshes written to {}",
                    s.iterations,
                    s.meshes,
                    f.display()
                ),
                None => println!("rerun: {} iterations, {} meshes streamed", s.iterations, s.meshes),
            }
        }
        Ok(())
    }
}

pub(crate) fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    let started = std::time::Instant::now();
    glissade::console::set_verbose(args.verbose);
    let overrides = Overrides {
        accuracy: args.solver.accuracy,
        max_iterations: args.solver.max_iterations,
        record: match (args.no_record, args.record) {
            (true, _) | (false, Some(crate::cli::RecordArg::Off)) => Some(RecordOverride::Off),
            (false, Some(crate::cli::RecordArg::Full)) => Some(RecordOverride::Full),
            (false, None) => None,
        },
        ..Default::default()
    };
    let run_id = run_id_of(args.run_id.as_deref())?;
    // Fails before solving if the outputs cannot be written.
    let sc = load_with_overrides(&args.scene, &args.out, &overrides)?;
    ensure_new_run(&args.out, &sc.model.name, &run_id)?;
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(sc.model.solver.max_iterations as u64)
    };
    bar.set_style(ProgressStyle::with_template("{spinner} [{elapsed}] it {pos}  {msg}").expect("valid template"));
    bar.set_message(format!(
        "building operators of {} subdomains",
        sc.model.subdomains.len()
    ));
    let recording = glissade::recording::recording_path(&sc, &run_id, &args.out);
    if let Some(p) = &recording {
        println!(
            "recording to {}: {}",
            p.display(),
            glissade::recording::expected_size(&sc)
        );
    }
    let solved = match solve(&args, &sc, &run_id, &bar, recording.as_deref())? {
        Ok(solved) => solved,
        Err(code) => return Ok(code),
    };
    bar.finish_and_clear();
    let outputs_started = std::time::Instant::now();
    let result = &solved.result;
    for l in &result.left_out {
        println!("left out: {l}");
    }
    let resultants = glissade::resultants::resultants(&sc.model, &result.interfaces)?;
    let written = write_outputs(&args, &sc, &run_id, &solved, &resultants, recording.as_deref())?;
    println!(
        "scene `{}`: {}; setup {:.2} s, iterations {:.2} s, outputs {:.2} s ({:.2} s since the command started)",
        sc.model.name,
        glissade::output::outcome(&sc.model, result),
        result.setup_s,
        result.solve_s,
        outputs_started.elapsed().as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
    print_results(&sc, &solved, &resultants, recording.as_deref(), &written);
    Ok(match result.verdict {
        Verdict::Converged => ExitCode::SUCCESS,
        _ => ExitCode::from(NOT_CONVERGED),
    })
}

/// A solved run: its result, the totals of its linear stages and, as processes, its traffic.
struct Solved {
    result: glissade::runner::RunResult,
    linear_stages: Vec<glissade::output::LinearStageTotals>,
    bus: Option<glissade::distributed::Traffic>,
}

/// Solves the scene in-process or as processes, with the progress bar and the live view. Ok(Err)
/// is the exit code of a run interrupted as processes (its summary written).
fn solve(
    args: &RunArgs,
    sc: &LoadedScene,
    run_id: &str,
    bar: &ProgressBar,
    recording: Option<&std::path::Path>,
) -> anyhow::Result<Result<Solved, ExitCode>> {
    let opts = RunOptions {
        run_id: run_id.to_string(),
        interior: args.interior || args.vtu,
        keep_state: false,
    };
    let progress = |r: &IterationRecord| {
        bar.set_position(r.iteration as u64 + 1);
        bar.set_message(glissade::output::progress_line(&sc.model, r));
    };
    let mut live = LiveView::new(args, sc, run_id)?;
    let watched = live.view.is_some();
    let mut run = Run::new(sc, &opts).recorded(recording).on_iteration(progress);
    if watched {
        run = run.observe(|m| {
            let t0 = std::time::Instant::now();
            live.message(m);
            t0.elapsed()
        });
    }
    // Linear-stage totals per linear stage: the counters of every run's `linear_stage_stats`
    // messages; their time in-process only (the in-process bus times the stages).
    let run = run.linear_stages();
    if args.in_process {
        let outcome = run.in_process()?;
        let linear_stages = glissade::output::linear_stage_totals(sc, &outcome.linear_stages, true);
        live.finish()?;
        if let Some(st) = outcome.recording.and_then(|o| o.stats) {
            glissade::console::note(&format!(
                "recorded {} messages on {} channels",
                st.messages, st.channels
            ));
        }
        return Ok(Ok(Solved {
            result: outcome.result,
            linear_stages,
            bus: None,
        }));
    }
    let exe = std::env::current_exe().context("cannot locate the glissade executable to spawn nodes")?;
    install_interrupt_handler()?;
    let net = Network {
        listen: args.listen.clone(),
        connect: args.connect.clone(),
        remote: args.remote.clone(),
        remote_timeout: Some(std::time::Duration::from_secs(args.remote_timeout)),
        credentials: Some(args.out.clone()),
        starter: if args.slurm {
            Starter::Slurm(SlurmAllocation::from_env()?)
        } else {
            Starter::Local
        },
    };
    let done = run.processes(&exe, &net);
    bar.finish_and_clear();
    match done {
        Ok(outcome) => {
            live.finish()?;
            let traffic = outcome.traffic.unwrap_or_default();
            note_traffic(&traffic);
            Ok(Ok(Solved {
                result: outcome.result,
                linear_stages: glissade::output::linear_stage_totals(sc, &outcome.linear_stages, false),
                bus: Some(traffic),
            }))
        }
        Err(glissade::Error::Interrupted(interrupted)) => {
            let Interrupted { partial } = &*interrupted;
            let mut s = summary(sc, partial, run_id);
            s["verdict"] = serde_json::json!("Interrupted");
            s["interrupted"] = serde_json::json!(true);
            let p = write_json_new(&args.out, &RunFile::Summary.name(&sc.model.name, run_id), &s)?;
            println!(
                "scene `{}`: interrupted after {} iterations; every node was stopped\nsummary: {}",
                sc.model.name,
                partial.iterations.len(),
                p.display()
            );
            Ok(Err(ExitCode::from(INTERRUPTED)))
        }
        Err(e) => Err(e.into()),
    }
}

/// The bus traffic of a run as processes, per kind of message, as notes (`--verbose`).
fn note_traffic(traffic: &glissade::distributed::Traffic) {
    if traffic.counted == glissade::distributed::Counted::Kept {
        glissade::console::note(
            "bus: only the messages the launcher keeps are counted: an unrecorded run's fields do not reach \
             it (through a router outside its process, or with the interface nodes in the subdomain \
             processes)",
        );
    }
    let per = traffic.iterations.max(1) as f64;
    for (kind, t) in &traffic.by_kind {
        let rate = if t.messages >= traffic.iterations {
            format!("{:.0} bytes per iteration", t.bytes as f64 / per)
        } else {
            "set-up or final, not per iteration".to_string()
        };
        glissade::console::note(&format!(
            "bus: {kind}: {} message(s), {} bytes ({rate})",
            t.messages, t.bytes
        ));
    }
}

/// The files a run wrote beside its recording.
struct Written {
    summary: std::path::PathBuf,
    fields: std::path::PathBuf,
    resultants: std::path::PathBuf,
    boundaries: std::path::PathBuf,
    csv: Option<std::path::PathBuf>,
    series: Option<glissade::vtu::Series>,
}

/// Writes the run's outputs, each new: the summary, the interface fields, the displacements
/// where asked, the ParaView series, the resultants and boundary forces (CSV and SVG) and the
/// interface CSV. Where one cannot be written (a full disk), the error names the files already
/// written: each is complete, and nothing is left of the one that failed.
fn write_outputs(
    args: &RunArgs,
    sc: &LoadedScene,
    run_id: &str,
    solved: &Solved,
    resultants: &[glissade::resultants::InterfaceResultants],
    recording: Option<&std::path::Path>,
) -> anyhow::Result<Written> {
    let result = &solved.result;
    let mut run_summary = summary(sc, result, run_id);
    run_summary["interface_resultants"] = serde_json::json!(resultants);
    run_summary["boundary_resultants"] = serde_json::json!(result.boundary);
    run_summary["linear_stages"] = serde_json::json!(solved.linear_stages.iter().map(|t| t.json()).collect::<Vec<_>>());
    if let Some(traffic) = &solved.bus {
        run_summary["bus"] = serde_json::json!(traffic);
    }
    let mut kept: Vec<std::path::PathBuf> = recording
        .iter()
        .filter(|p| p.is_file())
        .map(|p| p.to_path_buf())
        .collect();
    let summary_path = write_json_new(&args.out, &RunFile::Summary.name(&sc.model.name, run_id), &run_summary)
        .map_err(|e| with_kept(e.into(), &kept))?;
    kept.push(summary_path.clone());
    let fields_path = write_bytes_new(
        &args.out,
        &RunFile::Fields.name(&sc.model.name, run_id),
        &glissade::output::json_pieces(&interface_fields(&sc.model, &result.interfaces), "interfaces"),
    )
    .map_err(|e| with_kept(e.into(), &kept))?;
    kept.push(fields_path.clone());
    if args.interior || (sc.model.interfaces.is_empty() && !args.vtu) {
        let p = write_bytes_new(
            &args.out,
            &RunFile::Displacement.name(&sc.model.name, run_id),
            &glissade::output::displacements(&sc.model, &result.displacements),
        )
        .map_err(|e| with_kept(e.into(), &kept))?;
        println!("displacements: {}", p.display());
        kept.push(p);
    }
    let series = if args.vtu {
        let u = glissade::output::displacement_slices(&sc.model, &result.displacements)?;
        let stem = format!("{}-{run_id}", sc.model.name);
        let v = glissade::vtu::write_series(
            &sc.model,
            &u,
            &result.interfaces,
            &args.out,
            &stem,
            args.vtu_every as usize,
        )
        .map_err(|e| with_kept(e.into(), &kept))?;
        kept.push(v.pvd.clone());
        Some(v)
    } else {
        None
    };
    // A file beside the others, `<scene>-<run>.<suffix>`, written new and kept.
    let write_beside = |kept: &mut Vec<std::path::PathBuf>, suffix: &str, bytes: &[u8]| {
        let path = args.out.join(format!("{}-{run_id}.{suffix}", sc.model.name));
        glissade::vtu::write_new_file(&path, bytes).map_err(|e| with_kept(e.into(), kept))?;
        kept.push(path.clone());
        anyhow::Ok(path)
    };
    let resultants_csv = glissade::resultants::resultants_csv(&sc.model, resultants);
    let resultants_path = write_beside(&mut kept, "resultants.csv", resultants_csv.as_bytes())?;
    let boundaries_csv = glissade::resultants::boundary_csv(&sc.model, &result.boundary);
    let boundaries_path = write_beside(&mut kept, "boundaries.csv", boundaries_csv.as_bytes())?;
    let boundaries_svg = glissade::resultants::boundary_svg(&sc.model, &result.boundary);
    write_beside(&mut kept, "boundaries.svg", boundaries_svg.as_bytes())?;
    let csv = if args.csv {
        let table = glissade::output::interface_csv(&sc.model, &result.interfaces)?;
        Some(write_beside(&mut kept, "interfaces.csv", table.as_bytes())?)
    } else {
        None
    };
    Ok(Written {
        summary: summary_path,
        fields: fields_path,
        resultants: resultants_path,
        boundaries: boundaries_path,
        csv,
        series,
    })
}

/// The console's account of a finished run: the contact interfaces' resultants (and, not
/// converged, those slipping over their whole length), the supports' forces, the linear stages,
/// and where each output is.
fn print_results(
    sc: &LoadedScene,
    solved: &Solved,
    resultants: &[glissade::resultants::InterfaceResultants],
    recording: Option<&std::path::Path>,
    written: &Written,
) {
    let result = &solved.result;
    for line in glissade::resultants::console_lines(&sc.model, resultants, 4) {
        println!("{line}");
    }
    // A run stopped on no equilibrium has said which interfaces slide, and from when.
    if !matches!(result.verdict, Verdict::Converged | Verdict::NoEquilibrium { .. }) {
        for line in glissade::resultants::whole_slip_lines(&sc.model, resultants, 4) {
            glissade::console::warn(&line);
        }
    }
    for line in glissade::resultants::boundary_console_lines(&sc.model, &result.boundary, 4) {
        println!("{line}");
    }
    for t in &solved.linear_stages {
        // Untimed (as processes), the counters alone are a note (`--verbose`).
        match t.seconds {
            Some(_) => println!("{}", t.line()),
            None => glissade::console::note(&t.line()),
        }
    }
    if let Some((path, size)) = recording.and_then(|p| std::fs::metadata(p).ok().map(|m| (p, m.len()))) {
        println!("recording: {} ({:.1} MB)", path.display(), size as f64 * 1e-6);
    }
    println!(
        "summary: {}\nfields: {}\nresultants: {}\nboundaries: {}",
        written.summary.display(),
        written.fields.display(),
        written.resultants.display(),
        written.boundaries.display()
    );
    if let Some(path) = &written.csv {
        println!("csv: {}", path.display());
    }
    if let Some(v) = &written.series {
        println!(
            "paraview: {} ({} files, {:.1} MB)",
            v.pvd.display(),
            v.files,
            v.bytes as f64 * 1e-6
        );
    }
}

/// The error of an output that could not be written, with the files the run did write.
pub(crate) fn with_kept(e: anyhow::Error, kept: &[std::path::PathBuf]) -> anyhow::Error {
    if kept.is_empty() {
        return e;
    }
    let files: Vec<String> = kept.iter().map(|p| p.display().to_string()).collect();
    anyhow::anyhow!("{e:#}; kept, complete: {}", files.join(", "))
}
