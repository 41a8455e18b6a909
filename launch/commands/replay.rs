//! `glissade replay` and `glissade export`: a finished run's recording into Rerun, re-executed
//! node by node, or written in formats other tools read.

use super::*;

pub(crate) fn replay(args: ReplayArgs) -> anyhow::Result<ExitCode> {
    let recording = glissade_recorder::Recording::open(&args.recording)?;
    warn_incomplete(&args.recording, &recording, "replaying");
    if args.node.is_empty() {
        warn_unfinished(&args.recording, &recording);
    }
    if !args.node.is_empty() {
        return reexecute_nodes(&args, &recording);
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
    if let Some(&(sub, it)) = s.incomplete_states.first() {
        eprintln!(
            "warning: {}: {} boundary state(s) left out, some of their parts not recorded (the first: subdomain {sub} \
             at iteration {it})",
            args.recording.display(),
            s.incomplete_states.len()
        );
    }
    for (it, ended, diagnosis) in &s.stalls {
        println!(
            "after iteration {it} the run stopped moving and {}: {diagnosis}",
            if *ended { "was ended" } else { "was set going again" }
        );
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

/// `glissade replay --node`: re-executes each node named (`all`: every recorded node) from its
/// recorded inputs and compares its outputs with the recorded ones, bit for bit.
fn reexecute_nodes(args: &ReplayArgs, recording: &glissade_recorder::Recording) -> anyhow::Result<ExitCode> {
    use glissade_replay::reexecute::{parse_node, recorded_nodes, reexecute};
    let mut nodes = Vec::new();
    for n in &args.node {
        if n == "all" {
            nodes.extend(recorded_nodes(recording)?);
        } else {
            nodes.push(parse_node(n)?);
        }
    }
    let mut differing = 0;
    for (k, id) in nodes.into_iter().enumerate() {
        let r = reexecute(recording, id)?;
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
    Ok(if differing == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(NOT_CONVERGED)
    })
}

/// `glissade export`: `vtu` is the folder of the ParaView series and its time-point stride.
pub(crate) fn export(
    recording: &std::path::Path,
    vtu: Option<(&std::path::Path, usize)>,
    csv: Option<&std::path::Path>,
    foreign: Option<&std::path::Path>,
) -> anyhow::Result<ExitCode> {
    if vtu.is_none() && csv.is_none() && foreign.is_none() {
        anyhow::bail!("nothing to export: give --vtu <DIR>, --csv <DIR>, --foreign <DIR> or several");
    }
    // Everything is read and checked before anything is written: a recording that cannot give
    // what was asked, or a target that exists, leaves no file and no folder behind.
    let rec = glissade_recorder::Recording::open(recording)?;
    if foreign.is_none() {
        // (The foreign export says so itself, with what its file then holds.)
        warn_incomplete(recording, &rec, "exporting");
    }
    warn_unfinished(recording, &rec);
    let fields = if vtu.is_some() || csv.is_some() {
        Some(final_state_to_export(&rec, recording, vtu.map(|v| v.0), csv)?)
    } else {
        None
    };
    if let (Some(dir), Some(name)) = (foreign, recording.file_name()) {
        ensure_absent(dir, &[name.to_string_lossy().into_owned()])?;
    }
    for dir in vtu.iter().map(|v| v.0).chain(csv).chain(foreign) {
        ensure_not_a_file(dir)?;
    }
    for dir in vtu.iter().map(|v| v.0).chain(csv.iter().copied()) {
        ensure_writable(dir)?;
    }
    if let Some(dir) = foreign {
        export_foreign(recording, dir)?;
    }
    let Some((state, stem)) = fields else {
        return Ok(ExitCode::SUCCESS);
    };
    let model = &state.model;
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

/// The final state of `recording` (`rec`) that `export` writes as ParaView files (into `vtu`) or
/// CSV (into `csv`), checked before anything is written: every interface's final solution, every
/// subdomain's displacement for ParaView, no target file already there. Also its file stem.
fn final_state_to_export(
    rec: &glissade_recorder::Recording,
    recording: &std::path::Path,
    vtu: Option<&std::path::Path>,
    csv: Option<&std::path::Path>,
) -> anyhow::Result<(glissade_replay::FinalState, String)> {
    let unfinished = if rec.is_finished() {
        ""
    } else {
        " (the recording is not finished: its run's last fields may not be in it)"
    };
    let state =
        glissade_replay::final_state(rec).map_err(|e| anyhow::anyhow!("{}: {e}{unfinished}", recording.display()))?;
    let model = &state.model;
    if let Some(i) = (0..model.interfaces.len()).find(|&i| !state.interfaces.iter().any(|s| s.interface as usize == i))
    {
        let itf = &model.interfaces[i];
        anyhow::bail!(
            "{}: no final solution of interface {i} ({} | {}) is recorded{unfinished}; nothing was exported",
            recording.display(),
            model.subdomains[itf.a].name,
            model.subdomains[itf.b].name
        );
    }
    if vtu.is_some() {
        if let Some(sub) = (0..model.subdomains.len()).find(|&s| !state.u.contains_key(&(s as u32))) {
            anyhow::bail!(
                "{}: no displacement of subdomain `{}` can be recovered (no boundary state recorded); nothing \
                 was exported",
                recording.display(),
                model.subdomains[sub].name
            );
        }
    }
    if let Some(why) = state.skipped.describe() {
        eprintln!("warning: {}: {why}", recording.display());
    }
    let stem = format!("{}-{}", state.model.name, rec.run_id());
    if let Some(dir) = vtu {
        ensure_absent(dir, &[format!("{stem}.pvd"), format!("{stem}-vtu")])?;
    }
    if let Some(dir) = csv {
        ensure_absent(dir, &[format!("{stem}.interfaces.csv")])?;
    }
    Ok((state, stem))
}

/// `export --foreign`: the recording copied in protobuf into `dir`, said with what it holds.
fn export_foreign(recording: &std::path::Path, dir: &std::path::Path) -> anyhow::Result<()> {
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
    Ok(())
}

/// Says so when `rec` was cut short or has damaged chunks (`doing`: what is done with the rest).
fn warn_incomplete(path: &std::path::Path, rec: &glissade_recorder::Recording, doing: &str) {
    if let Some(why) = rec.truncated() {
        eprintln!("warning: {}: {why}; {doing} what was written", path.display());
    }
    if let Some(why) = rec.damaged() {
        eprintln!("warning: {}: {why}", path.display());
    }
}

/// Says so when `rec` was not finalised (its recorder stopped before the run's end; a cut in its
/// data is reported by the reader itself): what it holds is read all the same.
pub(crate) fn warn_unfinished(path: &std::path::Path, rec: &glissade_recorder::Recording) {
    if !rec.is_finished() && rec.truncated().is_none() {
        eprintln!(
            "warning: {}: not finalised (no summary section: its recorder stopped before the end of the run, \
             or the file was cut); reading the messages it holds",
            path.display()
        );
    }
}
