//! The subcommands' bodies, by group: a run ([`run`]), recordings ([`replay`]), the commands that
//! measure (the reference, reports, benches, the stability matrix: [`measure`]); and what they
//! share: exit codes, run ids, the output folder's check and scene loading with overrides.

pub(crate) mod generate;
pub(crate) mod inspect;
pub(crate) mod measure;
pub(crate) mod node;
pub(crate) mod replay;
pub(crate) mod run;
pub(crate) mod soak;
pub(crate) mod study;
pub(crate) mod submit;

pub(crate) use crate::cli::{ColorByArg, ReplayArgs, RunArgs, SubmitArgs};
pub(crate) use anyhow::Context;
pub(crate) use glissade::distributed::{install_interrupt_handler, Interrupted, Network};
pub(crate) use glissade::load_scene;
pub(crate) use glissade::output::{
    interface_fields, reference_interfaces, summary, write_bytes_new, write_json, write_json_new, RunFile,
};
pub(crate) use glissade::report::{build_report_with, linear_stage_table, plot_svg, TimeAxis};
pub(crate) use glissade::run::Run;
pub(crate) use glissade::runner::{IterationRecord, RunOptions};
pub(crate) use glissade::starter::{SlurmAllocation, Starter};
pub(crate) use glissade_messages::Verdict;
pub(crate) use glissade_reference::{verify, Checks, ReferenceError, ReferenceOptions, ReferenceRun};
pub(crate) use glissade_scene::{LoadedScene, Overrides, RecordOverride};
pub(crate) use indicatif::{ProgressBar, ProgressStyle};
pub(crate) use std::process::ExitCode;

/// Exit code of a run, or of a reference solve, that ended without converging (outputs are still
/// written).
pub(crate) const NOT_CONVERGED: u8 = 3;

/// Exit code of a run stopped by Ctrl-C or SIGTERM (128 + SIGINT, as shells report it).
pub(crate) const INTERRUPTED: u8 = 130;

/// A run id nobody can guess: 128 bits from the operating system's random source, in hex. The
/// run's key expressions (`glissade/<run id>/…`) are namespaced by it, so runs on a shared router
/// cannot collide and a client cannot publish into a run by naming it without being told the id.
/// Longest run id: with a scene name of up to 100 characters, every output file name stays
/// well under the 255 bytes file systems allow.
pub(crate) const MAX_RUN_ID_CHARS: usize = 64;

/// A run id becomes a key-expression chunk and part of file names: 1 to 64 letters, digits, `-`
/// or `_` (no wildcard, no path).
pub(crate) fn check_run_id(option: &str, run_id: &str) -> anyhow::Result<()> {
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

/// Refuses an output folder that is a file (before anything is created).
pub(crate) fn ensure_not_a_file(out: &std::path::Path) -> anyhow::Result<()> {
    if out.exists() && !out.is_dir() {
        anyhow::bail!("output folder {} is a file, not a folder", out.display());
    }
    Ok(())
}

pub(crate) fn ensure_writable(out: &std::path::Path) -> anyhow::Result<()> {
    ensure_not_a_file(out)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create output folder {}", out.display()))?;
    let probe = out.join(format!(".probe-{}", std::process::id()));
    std::fs::write(&probe, b"").with_context(|| format!("output folder {} is not writable", out.display()))?;
    let _ = std::fs::remove_file(&probe);
    Ok(())
}

/// Stops before anything is solved or written if one of the files `names` in `out` already
/// exists: the measuring commands and `export` write fixed file names, and what an earlier run
/// wrote there is never overwritten.
pub(crate) fn ensure_absent(out: &std::path::Path, names: &[String]) -> anyhow::Result<()> {
    for name in names {
        let path = out.join(name);
        if std::fs::symlink_metadata(&path).is_ok() {
            anyhow::bail!(
                "{} already exists; nothing was overwritten (use another output folder, or remove it)",
                path.display()
            );
        }
    }
    Ok(())
}

/// The scene with the command line's `--accuracy`, `--tolerance`, `--max-iterations` and
/// `--record` applied (each checked as the scene's own key is, and refused with that key's
/// error, said of the flag), after checking that the output folder is writable (before anything is solved). The
/// overrides stay beside the scene text: node processes get both over the bus, and recordings
/// attach both.
pub(crate) fn load_with_overrides(
    scene: &std::path::Path,
    out: &std::path::Path,
    overrides: &Overrides,
) -> anyhow::Result<glissade_scene::LoadedScene> {
    let sc = load_scene(scene)?.with_overrides(&scene.display().to_string(), overrides)?;
    ensure_writable(out)?;
    Ok(sc)
}

/// A random run id: 128 bits in hex ([`glissade::run::random_run_id`]).
pub(crate) fn default_run_id() -> glissade::Result<String> {
    glissade::run::random_run_id()
}

/// The run id `--run-id` gave, checked, or a new random one.
pub(crate) fn run_id_of(given: Option<&str>) -> anyhow::Result<String> {
    let run_id = match given {
        Some(id) => id.to_string(),
        None => default_run_id()?,
    };
    check_run_id("--run-id", &run_id)?;
    Ok(run_id)
}

/// Refuses, before anything is solved or written, a run id that already has outputs of scene
/// `name` in `out`: nothing is overwritten.
pub(crate) fn ensure_new_run(out: &std::path::Path, name: &str, run_id: &str) -> anyhow::Result<()> {
    let existing = glissade::output::existing_outputs(out, name, run_id);
    if !existing.is_empty() {
        anyhow::bail!(
            "--out {}: run {run_id} of scene `{name}` already has outputs there ({}); nothing was overwritten: \
             choose another --run-id (or leave it out for a new random one) or another --out",
            out.display(),
            existing
                .iter()
                .map(|p| p.file_name().unwrap_or_default().to_string_lossy().into_owned())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}
