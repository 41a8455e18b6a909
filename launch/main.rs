//! The `glissade` command line. It parses arguments, loads the scene and hands over to the
//! library (`glissade::runner`, `glissade::output`); errors are reported once, here.

mod cli;
mod commands;
mod log;

use clap::Parser;
use cli::{Cli, Command, KernelsArg};
use commands::generate::generate;
use commands::inspect::{check, monolithic};
use commands::measure::{bench, reference, reference_options, report_command, stability, validate};
use commands::node::node;
use commands::replay::{export, replay};
use commands::run::run;
use commands::study::{onset, sweep};
use commands::submit::submit;
use std::process::ExitCode;

fn main() -> ExitCode {
    keep_freed_memory();
    // Scenes too large for this machine are refused before anything is built.
    glissade_scene::set_machine_memory(glissade::machine_memory().unwrap_or(0));
    let cli = Cli::parse();
    if let Err(e) = log::install() {
        eprintln!("error: {e:#}");
        return ExitCode::from(2);
    }
    if let Err(e) = glissade::start_compute_threads() {
        eprintln!("error: cannot start the compute threads: {e}");
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
        Command::Submit(args) => submit(&args),
        Command::Check { scene } => check(&scene),
        Command::Reference {
            scene,
            out,
            newton_iterations,
        } => reference(&scene, &out, &reference_options(newton_iterations)),
        Command::Report(args) => report_command(args),
        Command::Validate { part, seeds, out } => validate(part, seeds, &out),
        Command::Sweep {
            study,
            vary,
            cold,
            accuracy,
            record,
            out,
        } => sweep(&study, &vary, cold, accuracy, record, &out),
        Command::Onset {
            scene,
            rule,
            interface,
            bracket,
            start,
            accuracy,
            out,
        } => onset(
            &scene,
            glissade_studies::onset::OnsetRequest {
                rule,
                interfaces: interface,
                bracket,
                start,
                accuracy,
            },
            &out,
        ),
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
        Command::Soak {
            scene,
            out,
            runs,
            parallel,
            busy,
            timeout,
            no_record,
        } => commands::soak::soak(commands::soak::SoakArgs {
            scene,
            out,
            runs,
            parallel,
            busy,
            timeout: std::time::Duration::from_secs(timeout),
            no_record,
        }),
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
        Command::Node(args) => node(args),
        Command::Generate(args) => generate(args),
        Command::Monolithic { scene } => monolithic(&scene),
    }
}
