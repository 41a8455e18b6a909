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
    let opts = RunOptions {
        run_id: run_id.clone(),
        interior: args.interior || args.vtu,
        keep_state: false,
    };
    let progress = |r: &IterationRecord| {
        bar.set_position(r.iteration as u64 + 1);
        bar.set_message(glissade::output::progress_line(&sc.model, r));
    };
    let recording = glissade::recording::recording_path(&sc, &run_id, &args.out);
    if let Some(p) = &recording {
        println!(
            "recording to {}: {}",
            p.display(),
            glissade::recording::expected_size(&sc)
        );
    }
    let mut live = LiveView::new(&args, &sc, &run_id)?;
    let watched = live.view.is_some();
    let mut run = Run::new(&sc, &opts)
        .recorded(recording.as_deref())
        .on_iteration(progress);
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
    let linear_stages;
    let mut bus = None;
    let result = if args.in_process {
        let outcome = run.in_process()?;
        linear_stages = glissade::output::linear_stage_totals(&sc, &outcome.linear_stages, true);
        live.finish()?;
        if let Some(st) = outcome.recording.and_then(|o| o.stats) {
            glissade::console::note(&format!(
                "recorded {} messages on {} channels",
                st.messages, st.channels
            ));
        }
        outcome.result
    } else {
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
        match run.processes(&exe, &net) {
            Ok(outcome) => {
                bar.finish_and_clear();
                live.finish()?;
                let traffic = outcome.traffic.unwrap_or_default();
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
                bus = Some(traffic);
                linear_stages = glissade::output::linear_stage_totals(&sc, &outcome.linear_stages, false);
                outcome.result
            }
            Err(e) => {
                bar.finish_and_clear();
                let glissade::Error::Interrupted(interrupted) = e else {
                    return Err(e.into());
                };
                let Interrupted { partial } = &*interrupted;
                let mut s = summary(&sc, partial, &run_id);
                s["verdict"] = serde_json::json!("Interrupted");
                s["interrupted"] = serde_json::json!(true);
                let p = write_json_new(&args.out, &RunFile::Summary.name(&sc.model.name, &run_id), &s)?;
                println!(
                    "scene `{}`: interrupted after {} iterations; every node was stopped\nsummary: {}",
                    sc.model.name,
                    partial.iterations.len(),
                    p.display()
                );
                return Ok(ExitCode::from(INTERRUPTED));
            }
        }
    };
    bar.finish_and_clear();
    let outputs_started = std::time::Instant::now();
    for l in &result.left_out {
        println!("left out: {l}");
    }
    let mut run_summary = summary(&sc, &result, &run_id);
    let resultants = glissade::resultants::resultants(&sc.model, &result.interfaces)?;
    run_summary["interface_resultants"] = serde_json::json!(resultants);
    run_summary["boundary_resultants"] = serde_json::json!(result.boundary);
    run_summary["linear_stages"] = serde_json::json!(linear_stages.iter().map(|t| t.json()).collect::<Vec<_>>());
    if let Some(traffic) = &bus {
        run_summary["bus"] = serde_json::json!(traffic);
    }
    // The files this run wrote, named with the error when a later one cannot be written (a full
    // disk): each is complete, and nothing is left of the one that failed.
    let mut kept: Vec<std::path::PathBuf> = recording.iter().filter(|p| p.is_file()).cloned().collect();
    let summary_path = write_json_new(&args.out, &RunFile::Summary.name(&sc.model.name, &run_id), &run_summary)
        .map_err(|e| with_kept(e.into(), &kept))?;
    kept.push(summary_path.clone());
    let fields_path = write_bytes_new(
        &args.out,
        &RunFile::Fields.name(&sc.model.name, &run_id),
        &glissade::output::json_pieces(&interface_fields(&sc.model, &result.interfaces), "interfaces"),
    )
    .map_err(|e| with_kept(e.into(), &kept))?;
    kept.push(fields_path.clone());
    if args.interior || (sc.model.interfaces.is_empty() && !args.vtu) {
        let p = write_bytes_new(
            &args.out,
            &RunFile::Displacement.name(&sc.model.name, &run_id),
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
    let resultants_csv = glissade::resultants::resultants_csv(&sc.model, &resultants);
    let resultants_path = write_beside(&mut kept, "resultants.csv", resultants_csv.as_bytes())?;
    let boundaries_csv = glissade::resultants::boundary_csv(&sc.model, &result.boundary);
    let boundaries_path = write_beside(&mut kept, "boundaries.csv", boundaries_csv.as_bytes())?;
    let boundaries_svg = glissade::resultants::boundary_svg(&sc.model, &result.boundary);
    write_beside(&mut kept, "boundaries.svg", boundaries_svg.as_bytes())?;
    let csv = if args.csv {
        let table = glissade::output::interface_csv(&sc.model, &result.interfaces)?;
        let path = write_beside(&mut kept, "interfaces.csv", table.as_bytes())?;
        Some(path)
    } else {
        None
    };
    println!(
        "scene `{}`: {}; setup {:.2} s, iterations {:.2} s, outputs {:.2} s ({:.2} s since the command started)",
        sc.model.name,
        glissade::output::outcome(&sc.model, &result),
        result.setup_s,
        result.solve_s,
        outputs_started.elapsed().as_secs_f64(),
        started.elapsed().as_secs_f64()
    );
    for line in glissade::resultants::console_lines(&sc.model, &resultants, 4) {
        println!("{line}");
    }
    if result.verdict != Verdict::Converged {
        for line in glissade::resultants::whole_slip_lines(&sc.model, &resultants, 4) {
            glissade::console::warn(&line);
        }
    }
    for line in glissade::resultants::boundary_console_lines(&sc.model, &result.boundary, 4) {
        println!("{line}");
    }
    for t in &linear_stages {
        // Untimed (as processes), the counters alone are a note (`--verbose`).
        match t.seconds {
            Some(_) => println!("{}", t.line()),
            None => glissade::console::note(&t.line()),
        }
    }
    if let Some(size) = recording
        .as_deref()
        .and_then(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
    {
        let path = recording.as_deref().expect("a recording path").display();
        println!("recording: {path} ({:.1} MB)", size as f64 * 1e-6);
    }
    println!(
        "summary: {}\nfields: {}\nresultants: {}\nboundaries: {}",
        summary_path.display(),
        fields_path.display(),
        resultants_path.display(),
        boundaries_path.display()
    );
    if let Some(path) = &csv {
        println!("csv: {}", path.display());
    }
    if let Some(v) = series {
        println!(
            "paraview: {} ({} files, {:.1} MB)",
            v.pvd.display(),
            v.files,
            v.bytes as f64 * 1e-6
        );
    }
    Ok(match result.verdict {
        Verdict::Converged => ExitCode::SUCCESS,
        _ => ExitCode::from(NOT_CONVERGED),
    })
}

/// The error of an output that could not be written, with the files the run did write.
pub(crate) fn with_kept(e: anyhow::Error, kept: &[std::path::PathBuf]) -> anyhow::Error {
    if kept.is_empty() {
        return e;
    }
    let files: Vec<String> = kept.iter().map(|p| p.display().to_string()).collect();
    anyhow::anyhow!("{e:#}; kept, complete: {}", files.join(", "))
}
