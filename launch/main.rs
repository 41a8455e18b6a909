//! The `glissade` command line. It parses arguments, loads the scene and hands over to the
//! library (`glissade::runner`, `glissade::output`); errors are reported once, here.

mod cli;

use anyhow::Context;
use clap::Parser;
use cli::{Cli, ColorByArg, Command, GenerateKind, KernelsArg, ReplayArgs, RoleArg, RunArgs};
use glissade::bus::Joining;
use glissade::children::{NodeName, NodeRole};
use glissade::distributed::{install_interrupt_handler, run_distributed_observed, Interrupted, Network, Supervision};
use glissade::load_scene;
use glissade::node_process::run_node_process;
use glissade::output::{interface_fields, reference_interfaces, summary, write_json, write_json_new, RunFile};
use glissade::report::{build_report_with, linear_stage_table, plot_svg, TimeAxis};
use glissade::runner::{IterationRecord, RunOptions};
use glissade_messages::Verdict;
use glissade_reference::glued::solve_glued;
use glissade_reference::{solve_reference_steps, verify, ReferenceError, ReferenceOptions, ReferenceRun};
use glissade_scene::LoadedScene;
use glissade_scene::{Overrides, RecordOverride};
use indicatif::{ProgressBar, ProgressStyle};
use std::process::ExitCode;

/// The live Rerun view of `run --rerun`, fed every message of the run; its first failure is kept
/// and reported when the run ends (the run itself does not depend on the view).
struct LiveView {
    view: Option<glissade_replay::View>,
    failure: Option<glissade_replay::ReplayError>,
}

impl LiveView {
    fn new(args: &RunArgs, sc: &LoadedScene, run_id: &str) -> anyhow::Result<Self> {
        let view = match &args.rerun {
            Some(sink) => {
                let sink = glissade_replay::Sink::parse(sink).map_err(|e| anyhow::anyhow!("--rerun {e}"))?;
                let opts = glissade_replay::ReplayOptions {
                    sink,
                    color_by: glissade_replay::ColorBy::VonMises,
                    amplification: None,
                    time_point: None,
                    reference: false,
                    basis_sizes: Vec::new(),
                };
                let origin = args.scene.display().to_string();
                Some(glissade_replay::View::new(&sc.text, &origin, run_id, &opts, None)?)
            }
            None => None,
        };
        Ok(Self { view, failure: None })
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
            println!("rerun: {} iterations, {} meshes streamed", s.iterations, s.meshes);
        }
        Ok(())
    }
}

/// Exit code of a run, or of a reference solve, that ended without converging (outputs are still
/// written).
const NOT_CONVERGED: u8 = 3;

/// What a user can do about a reference that did not converge at a time step.
const REFERENCE_HINT: &str = "hint: the reference solves the same discrete problem as LATIN, step by step; \
a step it cannot solve usually has many contact pairs at the edge of their law (gaps or stick margins near zero). \
The steps solved are written. \
A larger --newton-iterations may get through the step; \
a different time discretisation (N) changes the problem but may avoid it. Please report the scene.";

/// The reference's options for `--newton-iterations n`: n per attempt, 20 n for the non-monotone
/// one (the defaults for n = 50).
fn reference_options(newton_iterations: u32) -> ReferenceOptions {
    let n = newton_iterations as usize;
    ReferenceOptions {
        max_newton_iterations: n,
        nonmonotone_iterations: 20 * n,
        ..ReferenceOptions::default()
    }
}

/// "k Newton iterations", or that the reference failed and after how many time points.
fn reference_outcome(report: &glissade::report::Report, n_points: usize) -> String {
    match report.reference_failure {
        None => format!("{} Newton iterations", report.reference_newton_iterations),
        Some(_) => format!(
            "FAILED after {} of {n_points} time points; no errors against it",
            report.reference_steps_solved
        ),
    }
}

/// Writes the interface fields of the time points a failed reference solved, prints its error
/// and the hint; the exit code of a reference failure.
fn reference_failed(
    model: &glissade_mechanics::model::Model,
    run: &ReferenceRun,
    error: &ReferenceError,
    out: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    let solved = run.solution.newton_iterations.len();
    let f = write_json(
        out,
        &format!("{}-reference-partial.fields.json", model.name),
        &glissade::output::interface_fields_upto(model, &reference_interfaces(model, &run.solution), solved),
    )?;
    eprintln!("error: reference: {error}");
    eprintln!("{REFERENCE_HINT}");
    eprintln!(
        "reference: {solved} of {} time points solved, written to {} (PARTIAL)",
        model.time.n_points(),
        f.display()
    );
    Ok(ExitCode::from(NOT_CONVERGED))
}
/// Exit code of a run stopped by Ctrl-C or SIGTERM (128 + SIGINT, as shells report it).
const INTERRUPTED: u8 = 130;

fn main() -> ExitCode {
    keep_freed_memory();
    // Scenes too large for this machine are refused before anything is built.
    glissade_scene::set_machine_memory(glissade::machine_memory().unwrap_or(0));
    let cli = Cli::parse();
    if let Err(e) = log_if_asked() {
        eprintln!("error: {e:#}");
        return ExitCode::from(2);
    }
    match dispatch(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// With `RUST_LOG` set (tracing's filter syntax, e.g. `zenoh=warn` or
/// `zenoh_transport=debug`), prints the log lines of this process and its libraries (Zenoh) to
/// stderr. Node processes inherit the variable, and the launcher forwards their lines. Without
/// it nothing is installed and nothing is logged.
fn log_if_asked() -> anyhow::Result<()> {
    let Some(filter) = std::env::var_os("RUST_LOG") else {
        return Ok(());
    };
    let filter = filter
        .into_string()
        .map_err(|v| anyhow::anyhow!("RUST_LOG = {v:?} is not UTF-8"))?;
    // Zenoh logs a session's whole configuration, the bus password among it, at debug level
    // when it opens: that module is held at info whatever RUST_LOG asks.
    let filter = tracing_subscriber::EnvFilter::try_new(&filter)
        .map_err(|e| anyhow::anyhow!("RUST_LOG = {filter:?} is not a tracing filter: {e}"))?
        .add_directive("zenoh::api::session=info".parse().expect("a valid directive"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(false)
        .try_init()
        .map_err(|e| anyhow::anyhow!("cannot install the log for RUST_LOG: {e}"))
}

/// Makes the allocator keep the memory a process frees for its next allocations instead of
/// handing it back to the kernel. By default glibc maps every block of 128 KiB or more on its own
/// and unmaps it when freed (the threshold only grows after such a free), and trims the heap's top
/// past 128 KiB: an encoded message (a few MB) or a solution field then lands in new pages at every
/// use, and each new page costs a fault and its clearing (in a virtual machine, often a fault
/// of the host as well). Blocks below 32 MiB (glibc's largest threshold) now come from the heap,
/// and up to 1 GiB free at its top is kept. A process's resident memory stays at its peak.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets allocator parameters; it is called before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

fn dispatch(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Run(args) => run(args),
        Command::Check { scene } => {
            let sc = load_scene(&scene)?;
            let m = &sc.model;
            println!(
                "scene `{}` ({:016x}): {} subdomains, {} interfaces ({} contact), {} time points, {} dofs",
                m.name,
                sc.fingerprint,
                m.subdomains.len(),
                m.interfaces.len(),
                m.interfaces.iter().filter(|i| i.is_contact()).count(),
                m.time.n_points(),
                m.subdomains.iter().map(|s| s.n_dofs()).sum::<usize>()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Reference {
            scene,
            out,
            newton_iterations,
        } => reference(&scene, &out, &reference_options(newton_iterations)),
        Command::Report {
            scene,
            out,
            accuracy,
            tolerance,
            max_iterations,
            variants,
            stop_at_error,
            newton_iterations,
            log_time,
            basis_subdomains,
        } => {
            let overrides = Overrides {
                accuracy,
                tolerance,
                max_iterations,
                record: None,
            };
            let ropts = reference_options(newton_iterations);
            if let Some(e) = stop_at_error {
                if !(e > 0.0 && e.is_finite()) {
                    anyhow::bail!("--stop-at-error {e}: must be a positive number");
                }
            }
            let plots = Plots {
                time_axis: if log_time { TimeAxis::Log } else { TimeAxis::Linear },
                basis_subdomains: basis_subdomains.iter().map(|&s| s as usize).collect(),
            };
            if variants.is_empty() {
                report(&scene, &out, &overrides, stop_at_error, &ropts, &plots)
            } else {
                report_variants(&scene, &out, &overrides, &variants, stop_at_error, &ropts, &plots)
            }
        }
        Command::Stability {
            quick,
            only,
            list,
            accuracy,
            out,
        } => stability(quick, &only, list, accuracy, &out),
        Command::Bench {
            scene,
            out,
            max_iterations,
            processes,
            kernels,
        } => {
            use glissade_mechanics::simd::{set_process_level, Level};
            set_process_level(kernels.map(|k| match k {
                KernelsArg::Baseline => Level::Baseline,
                KernelsArg::Avx2 => Level::Avx2,
                KernelsArg::Avx512 => Level::Avx512,
            }));
            bench(&scene, &out, max_iterations, processes)
        }
        Command::Replay(args) => replay(args),
        Command::Export {
            recording,
            vtu,
            vtu_every,
            csv,
            foreign,
        } => export(
            &recording,
            vtu.as_deref().map(|d| (d, vtu_every as usize)),
            csv.as_deref(),
            foreign.as_deref(),
        ),
        Command::Node(args) => {
            check_run_id("--run", &args.run)?;
            let tls = glissade::bus::node_tls(
                args.tls_root_ca.as_deref(),
                args.tls_cert.as_deref(),
                args.tls_key.as_deref(),
            )?;
            let credentials = |id| glissade::bus::node_credentials(args.credentials.as_deref(), id);
            let role = match args.role {
                RoleArg::Subdomain => NodeRole::Subdomain,
                RoleArg::Interface => NodeRole::Interface,
                RoleArg::Coarse => NodeRole::Coarse,
                RoleArg::Recorder => {
                    let Some(file) = &args.file else {
                        anyhow::bail!("a recorder node needs --file <recording.mcap>");
                    };
                    let credentials = credentials(glissade::bus::RECORDER)?;
                    let bus = Joining {
                        connect: &args.connect,
                        tls: tls.as_ref(),
                        credentials: credentials.as_ref(),
                    };
                    glissade::recording::run_recorder_process(&args.run, &bus, args.shared_memory, file)?;
                    return Ok(ExitCode::SUCCESS);
                }
            };
            let credentials = credentials(
                NodeName {
                    role,
                    index: args.index,
                }
                .id(),
            )?;
            let bus = Joining {
                connect: &args.connect,
                tls: tls.as_ref(),
                credentials: credentials.as_ref(),
            };
            run_node_process(
                role,
                &args.run,
                &bus,
                &args.subdomains,
                args.index,
                Supervision {
                    interior: args.interior,
                    supervised: args.supervised,
                    resume: args.resume,
                    shared_memory: args.shared_memory,
                },
            )?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Generate(args) => {
            let GenerateKind::Laminate = args.kind;
            let laminate = glissade::generate::Laminate {
                plies: args.plies,
                per_ply: args.per_ply,
                elements: args.elements,
                side: args.side,
                steps: args.steps,
                friction: args.friction,
                subdomain_nodes: args.subdomain_nodes,
                interface_nodes: args.interface_nodes,
            };
            let text = laminate.scene_text()?;
            // Check what was generated as any scene is checked, before writing it.
            glissade_scene::load_str(&text, &args.out.display().to_string())
                .context("the generated scene does not load (a bug in the generator)")?;
            let mut file = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&args.out)
                .with_context(|| {
                    format!(
                        "cannot create {} (an existing file is not overwritten)",
                        args.out.display()
                    )
                })?;
            std::io::Write::write_all(&mut file, text.as_bytes())
                .with_context(|| format!("cannot write {}", args.out.display()))?;
            println!(
                "{}: laminate of {} plies × {} subdomains ({} subdomains, {} interfaces), {} × {} QUA8 each, N = {}",
                args.out.display(),
                laminate.plies,
                laminate.per_ply,
                laminate.subdomains(),
                laminate.interfaces(),
                laminate.elements,
                laminate.elements,
                laminate.steps
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Monolithic { scene } => {
            let sc = load_scene(&scene)?;
            let t0 = std::time::Instant::now();
            let sol = solve_glued(&sc.model).context("glued solve")?;
            let umax = sol
                .u
                .iter()
                .flat_map(|u| (0..u.ncols()).flat_map(move |j| (0..u.nrows()).map(move |i| u[(i, j)].abs())))
                .fold(0.0, f64::max);
            println!("scene `{}`: glued linear-elastic solve of {} subdomains, {} time points in {:.3} s; max |u_i| = {umax:.6e} mm",
                sc.model.name, sc.model.subdomains.len(), sc.model.time.n_points(), t0.elapsed().as_secs_f64());
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// A run id nobody can guess: 128 bits from the operating system's random source, in hex. The
/// run's key expressions (`glissade/<run id>/…`) are namespaced by it, so runs on a shared router
/// cannot collide and a client cannot publish into a run by naming it without being told the id.
/// Longest run id: with a scene name of up to 100 characters, every output file name stays
/// well under the 255 bytes file systems allow.
const MAX_RUN_ID_CHARS: usize = 64;

/// A run id becomes a key-expression chunk and part of file names: 1 to 64 letters, digits, `-`
/// or `_` (no wildcard, no path).
fn check_run_id(option: &str, run_id: &str) -> anyhow::Result<()> {
    let ok = (1..=MAX_RUN_ID_CHARS).contains(&run_id.len())
        && run_id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if !ok {
        anyhow::bail!(
            "{option} `{}`: a run id is 1 to {MAX_RUN_ID_CHARS} letters, digits, `-` or `_` (it becomes a \
             key-expression chunk and part of file names)",
            run_id.chars().take(80).collect::<String>()
        );
    }
    Ok(())
}

fn default_run_id() -> anyhow::Result<String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes)
        .map_err(|e| anyhow::anyhow!("cannot draw a random run id from the operating system: {e}"))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

fn run(args: RunArgs) -> anyhow::Result<ExitCode> {
    glissade::console::set_verbose(args.verbose);
    let overrides = Overrides {
        accuracy: args.accuracy,
        record: match (args.no_record, args.record) {
            (true, _) | (false, Some(cli::RecordArg::Off)) => Some(RecordOverride::Off),
            (false, Some(cli::RecordArg::Full)) => Some(RecordOverride::Full),
            (false, None) => None,
        },
        ..Default::default()
    };
    let run_id = match args.run_id.clone() {
        Some(id) => id,
        None => default_run_id()?,
    };
    check_run_id("--run-id", &run_id)?;
    // Fails before solving if the outputs cannot be written.
    let sc = load_with_overrides(&args.scene, &args.out, &overrides)?;
    let existing = glissade::output::existing_outputs(&args.out, &sc.model.name, &run_id);
    if !existing.is_empty() {
        anyhow::bail!(
            "--out {}: run {run_id} of scene `{}` already has outputs there ({}); nothing was overwritten: \
             choose another --run-id (or leave it out for a new random one) or another --out",
            args.out.display(),
            sc.model.name,
            existing
                .iter()
                .map(|p| p.file_name().unwrap_or_default().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
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
    // Linear-stage totals per linear stage: in process only (a node process keeps its records).
    let mut linear_stages = None;
    let mut bus = None;
    let result = if args.in_process {
        let (result, records, outcome) =
            glissade::recording::run_in_process_recorded_logged(&sc, &opts, recording.as_deref(), progress, |m| {
                let t0 = std::time::Instant::now();
                live.message(m);
                t0.elapsed()
            })?;
        linear_stages = Some(glissade::output::linear_stage_totals(&sc, &records));
        live.finish()?;
        if let Some(st) = outcome.and_then(|o| o.stats) {
            glissade::console::note(&format!(
                "recorded {} messages on {} channels",
                st.messages, st.channels
            ));
        }
        result
    } else {
        let exe = std::env::current_exe().context("cannot locate the glissade executable to spawn nodes")?;
        install_interrupt_handler()?;
        let net = Network {
            listen: args.listen.clone(),
            connect: args.connect.clone(),
            remote: args.remote.clone(),
            remote_timeout: Some(std::time::Duration::from_secs(args.remote_timeout)),
            recording: recording.clone(),
            credentials: Some(args.out.clone()),
        };
        let observe = live
            .view
            .is_some()
            .then_some(|m: &glissade_messages::Message| live.message(m));
        match run_distributed_observed(&sc, &opts, &exe, &net, progress, observe) {
            Ok((result, traffic)) => {
                bar.finish_and_clear();
                live.finish()?;
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
                result
            }
            Err(e) => {
                bar.finish_and_clear();
                let Some(Interrupted { partial }) = e.downcast_ref::<Interrupted>() else {
                    return Err(e);
                };
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
    for l in &result.left_out {
        println!("left out: {l}");
    }
    let mut run_summary = summary(&sc, &result, &run_id);
    run_summary["linear_stages"] = match &linear_stages {
        Some(totals) => serde_json::json!(totals.iter().map(|t| t.json()).collect::<Vec<_>>()),
        None => {
            serde_json::json!("not measured: a multi-process run's subdomain nodes keep their linear-stage records")
        }
    };
    if let Some(traffic) = &bus {
        run_summary["bus"] = serde_json::json!(traffic);
    }
    // The files this run wrote, named with the error when a later one cannot be written (a full
    // disk): each is complete, and nothing is left of the one that failed.
    let mut kept: Vec<std::path::PathBuf> = recording.iter().filter(|p| p.is_file()).cloned().collect();
    let summary_path = write_json_new(&args.out, &RunFile::Summary.name(&sc.model.name, &run_id), &run_summary)
        .map_err(|e| with_kept(e, &kept))?;
    kept.push(summary_path.clone());
    let fields_path = write_json_new(
        &args.out,
        &RunFile::Fields.name(&sc.model.name, &run_id),
        &interface_fields(&sc.model, &result.interfaces),
    )
    .map_err(|e| with_kept(e, &kept))?;
    kept.push(fields_path.clone());
    if args.interior || (sc.model.interfaces.is_empty() && !args.vtu) {
        let p = write_json_new(
            &args.out,
            &RunFile::Displacement.name(&sc.model.name, &run_id),
            &glissade::output::displacements(&sc.model, &result.displacements),
        )
        .map_err(|e| with_kept(e, &kept))?;
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
        .map_err(|e| with_kept(e, &kept))?;
        kept.push(v.pvd.clone());
        Some(v)
    } else {
        None
    };
    println!(
        "scene `{}`: {}; setup {:.2} s, iterations {:.2} s",
        sc.model.name,
        glissade::output::outcome(&sc.model, &result),
        result.setup_s,
        result.solve_s
    );
    for t in linear_stages.iter().flatten() {
        println!("{}", t.line());
    }
    if let Some(size) = recording
        .as_deref()
        .and_then(|p| std::fs::metadata(p).ok())
        .map(|m| m.len())
    {
        let path = recording.as_deref().expect("a recording path").display();
        println!("recording: {path} ({:.1} MB)", size as f64 * 1e-6);
    }
    println!("summary: {}\nfields: {}", summary_path.display(), fields_path.display());
    if args.csv {
        let path = args.out.join(format!("{}-{run_id}.interfaces.csv", sc.model.name));
        glissade::vtu::write_new_file(
            &path,
            glissade::output::interface_csv(&sc.model, &result.interfaces)?.as_bytes(),
        )
        .map_err(|e| with_kept(e, &kept))?;
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
fn with_kept(e: anyhow::Error, kept: &[std::path::PathBuf]) -> anyhow::Error {
    if kept.is_empty() {
        return e;
    }
    let files: Vec<String> = kept.iter().map(|p| p.display().to_string()).collect();
    anyhow::anyhow!("{e:#}; kept, complete: {}", files.join(", "))
}

fn replay(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    let recording = glissade_recorder::Recording::open(&args.recording)?;
    if let Some(why) = recording.truncated() {
        eprintln!(
            "warning: {}: {why}; replaying what was written",
            args.recording.display()
        );
    }
    if let Some(why) = recording.damaged() {
        eprintln!("warning: {}: {why}", args.recording.display());
    }
    if !args.node.is_empty() {
        use glissade_replay::reexecute::{parse_node, recorded_nodes, reexecute};
        let mut nodes = Vec::new();
        for n in &args.node {
            if n == "all" {
                nodes.extend(recorded_nodes(&recording)?);
            } else {
                nodes.push(parse_node(n)?);
            }
        }
        let mut differing = 0;
        for (k, id) in nodes.into_iter().enumerate() {
            let r = reexecute(&recording, id)?;
            if let (0, Some(why)) = (k, r.skipped.describe()) {
                eprintln!("warning: {}: {why}", args.recording.display());
            }
            match &r.mismatch {
                None => println!(
                    "node {id}: {} outputs bit-identical to the recording ({} bytes; {} recorded inputs)",
                    r.outputs, r.bytes, r.inputs
                ),
                Some(m) => {
                    differing += 1;
                    println!("node {id}: differs from the recording: {m}");
                }
            }
        }
        return Ok(if differing == 0 {
            ExitCode::SUCCESS
        } else {
            ExitCode::from(NOT_CONVERGED)
        });
    }
    let sink = if args.spawn {
        glissade_replay::Sink::Spawn
    } else if let Some(url) = args.connect {
        glissade_replay::Sink::Connect(url)
    } else {
        let p = args.save.unwrap_or_else(|| args.recording.with_extension("rrd"));
        glissade_replay::Sink::Save(p)
    };
    // PGD runs: the basis sizes are the mode-form states' time-function counts.
    let basis_sizes = match glissade_replay::reexecute::recorded_basis_sizes(&recording)? {
        Some(b) => {
            println!(
                "PGD basis sizes: {} linear stages, from the recorded mode-form states",
                b.len()
            );
            b
        }
        None => Vec::new(),
    };
    let opts = glissade_replay::ReplayOptions {
        sink: sink.clone(),
        basis_sizes,
        color_by: match args.color_by {
            ColorByArg::VonMises => glissade_replay::ColorBy::VonMises,
            ColorByArg::Displacement => glissade_replay::ColorBy::Displacement,
        },
        amplification: args.amplification,
        time_point: args.time_point,
        reference: args.reference,
    };
    let t0 = std::time::Instant::now();
    let s = glissade_replay::replay(&recording, &opts)?;
    if let Some(why) = s.skipped.describe() {
        eprintln!("warning: {}: {why}", args.recording.display());
    }
    let range = s
        .color_range
        .map_or_else(|| "no colour range".to_string(), |r| format!("colour range {r}"));
    println!(
        "replayed {} messages: {} iterations, {} meshes (time point {}, displacements × {:.3e}, {range}) in {:.2} s",
        s.messages,
        s.iterations,
        s.meshes,
        s.time_point,
        s.amplification,
        t0.elapsed().as_secs_f64()
    );
    if let (Some(t), Some(&(it, e_f, e_w))) = (s.reference_s, s.errors.last()) {
        println!(
            "error against the reference (solved in {t:.2} s), iteration {it}: tractions {e_f:.3e}, jumps {e_w:.3e}"
        );
    }
    if let glissade_replay::Sink::Save(p) = sink {
        println!("rerun: {} (open with `rerun {}`)", p.display(), p.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// `glissade export`: `vtu` is the folder of the ParaView series and its time-point stride.
fn export(
    recording: &std::path::Path,
    vtu: Option<(&std::path::Path, usize)>,
    csv: Option<&std::path::Path>,
    foreign: Option<&std::path::Path>,
) -> anyhow::Result<ExitCode> {
    if vtu.is_none() && csv.is_none() && foreign.is_none() {
        anyhow::bail!("nothing to export: give --vtu <DIR>, --csv <DIR>, --foreign <DIR> or several");
    }
    for dir in vtu.iter().map(|v| v.0).chain(csv.iter().copied()) {
        ensure_writable(dir)?;
    }
    if let Some(dir) = foreign {
        let e = glissade_recorder::foreign::export(recording, dir, &glissade::recording::software())?;
        if let Some(why) = &e.source_truncated {
            eprintln!(
                "warning: {}: {why}; the export holds the messages before it",
                recording.display()
            );
        }
        if let Some(why) = &e.source_damaged {
            eprintln!("warning: {}: {why}; the export holds the others", recording.display());
        }
        println!(
            "foreign-readable (protobuf): {} ({} messages on {} channels, {:.1} MB)",
            e.path.display(),
            e.messages,
            e.channels,
            e.bytes as f64 * 1e-6
        );
        if vtu.is_none() && csv.is_none() {
            return Ok(ExitCode::SUCCESS);
        }
    }
    let rec = glissade_recorder::Recording::open(recording)?;
    let state = glissade_replay::final_state(&rec)?;
    if let Some(why) = state.skipped.describe() {
        eprintln!("warning: {}: {why}", recording.display());
    }
    let model = &state.model;
    let stem = format!("{}-{}", model.name, rec.run_id());
    if let Some((dir, every)) = vtu {
        let u: Vec<Vec<&[f64]>> = (0..model.subdomains.len() as u32)
            .map(|s| {
                state
                    .u
                    .get(&s)
                    .map(|per_time| per_time.iter().map(Vec::as_slice).collect())
                    .with_context(|| {
                        format!(
                            "{}: no displacement of subdomain `{}` can be recovered (no boundary state recorded)",
                            recording.display(),
                            model.subdomains[s as usize].name
                        )
                    })
            })
            .collect::<anyhow::Result<_>>()?;
        let v = glissade::vtu::write_series(model, &u, &state.interfaces, dir, &stem, every)?;
        println!(
            "paraview: {} ({} files, {:.1} MB)",
            v.pvd.display(),
            v.files,
            v.bytes as f64 * 1e-6
        );
    }
    if let Some(dir) = csv {
        let path = dir.join(format!("{stem}.interfaces.csv"));
        let text = glissade::output::interface_csv(model, &state.interfaces)?;
        glissade::vtu::write_new_file(&path, text.as_bytes())?;
        println!("csv: {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

fn ensure_writable(out: &std::path::Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create output folder {}", out.display()))?;
    let probe = out.join(format!(".probe-{}", std::process::id()));
    std::fs::write(&probe, b"").with_context(|| format!("output folder {} is not writable", out.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

fn reference(scene: &std::path::Path, out: &std::path::Path, opts: &ReferenceOptions) -> anyhow::Result<ExitCode> {
    let sc = load_scene(scene)?;
    ensure_writable(out)?;
    let t0 = std::time::Instant::now();
    let run = solve_reference_steps(&sc.model, opts)?;
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
        "checks": format!("{checks:?}"),
    });
    let stem = format!("{}-reference", sc.model.name);
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
    println!("checks: {checks:?}");
    println!("summary: {}\nfields: {}", s.display(), f.display());
    Ok(ExitCode::SUCCESS)
}

/// The scene with the command line's `--accuracy`, `--tolerance` and `--max-iterations` applied,
/// after checking them and that the output folder is writable (before anything is solved).
fn load_with_overrides(
    scene: &std::path::Path,
    out: &std::path::Path,
    overrides: &Overrides,
) -> anyhow::Result<glissade_scene::LoadedScene> {
    let sc = load_scene(scene)?;
    if let Some(tolerance) = overrides.tolerance {
        if !(tolerance > 0.0 && tolerance.is_finite()) {
            anyhow::bail!("--tolerance {tolerance}: must be a positive number");
        }
    }
    if let Some(accuracy) = overrides.accuracy {
        if !(accuracy > 0.0 && accuracy < 1.0) {
            anyhow::bail!("--accuracy {accuracy}: must be a relative error in (0, 1)");
        }
    }
    if overrides.max_iterations == Some(0) {
        anyhow::bail!("--max-iterations 0: must be at least 1");
    }
    ensure_writable(out)?;
    // Into the scene text, not only this process's model: node processes (`bench --processes`)
    // build their model from the text.
    Ok(sc.with_overrides(&scene.display().to_string(), overrides)?)
}

fn bench(
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
    let run_id = default_run_id()?;
    let report = glissade::bench::bench(&sc, &run_id)?;
    print!("{}", glissade::bench::render(&report));
    let name = format!("{}-bench.json", sc.model.name);
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
struct Plots {
    time_axis: TimeAxis,
    /// Subdomains (from 1) whose basis sizes the iterations plot shows.
    basis_subdomains: Vec<usize>,
}

/// Writes `<scene>-iterations.svg` (η, traction error and basis sizes against the iterations).
fn write_iterations_plot(
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

fn report(
    scene: &std::path::Path,
    out: &std::path::Path,
    overrides: &Overrides,
    stop_at: Option<f64>,
    reference_options: &ReferenceOptions,
    plots: &Plots,
) -> anyhow::Result<ExitCode> {
    let time_axis = plots.time_axis;
    let sc = load_with_overrides(scene, out, overrides)?;
    let run_id = default_run_id()?;
    let (report, reference, _) = build_report_with(&sc, &run_id, stop_at, reference_options)?;
    let name = &sc.model.name;
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
            println!("NO ERRORS AGAINST THE REFERENCE: it failed (see below); the LATIN run above is complete");
            reference_failed(&sc.model, &reference, e, out)
        }
        None => Ok(ExitCode::SUCCESS),
    }
}

/// `glissade report --variants a,b,…`: one reference, one LATIN run per variant.
fn report_variants(
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
fn stability_accuracy(cases: &[glissade::stability::Case], out: &std::path::Path) -> anyhow::Result<ExitCode> {
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

fn stability(
    quick: bool,
    only: &[String],
    list: bool,
    accuracy: bool,
    out: &std::path::Path,
) -> anyhow::Result<ExitCode> {
    use glissade::stability::{cases, markdown, run_cases, Assessment};
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
    if accuracy {
        return stability_accuracy(&selected, out);
    }
    let rows = run_cases(&selected, |r| {
        let its = |n: Option<usize>| n.map_or("—".into(), |n| n.to_string());
        eprintln!(
            "{}: {} after {} iterations, with Anderson {} after {} ({}; {:?})",
            r.case,
            r.plain.outcome.kind(),
            its(r.plain.iterations),
            r.anderson.outcome.kind(),
            its(r.anderson.iterations),
            r.acceleration.kind(),
            r.assessment
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
