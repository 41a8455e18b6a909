//! The `glissade` command line. It parses arguments, loads the scene and hands over to the
//! library (`glissade::runner`, `glissade::output`); errors are reported once, here.

mod cli;
mod commands;
mod log;

use anyhow::Context;
use clap::Parser;
use cli::{Cli, Command, GenerateKind, KernelsArg, RoleArg};
use commands::check_run_id;
use commands::measure::{bench, reference, reference_options, report, report_variants, stability, validate, Plots};
use commands::replay::{export, replay};
use commands::run::run;
use commands::study::{onset, sweep};
use commands::submit::submit;
use glissade::bus::Joining;
use glissade::children::{NodeName, NodeRole};
use glissade::distributed::Supervision;
use glissade::load_scene;
use glissade::node_process::run_node_process;
use glissade::report::TimeAxis;
use glissade_reference::glued::solve_glued;
use glissade_scene::Overrides;
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
            let plane = match m.plane {
                glissade_mechanics::model::Plane::Strain => "strain (unit thickness",
                glissade_mechanics::model::Plane::Stress => "stress (unit thickness",
                glissade_mechanics::model::Plane::Axisymmetric => {
                    "axisymmetric (x = r, y = z; totals over the circumference"
                }
            };
            println!("plane: {plane}; forces in {})", m.plane.force_unit());
            for (i, itf) in m.interfaces.iter().enumerate() {
                if let Some(projection) = &itf.projection {
                    println!(
                        "interface {i} (`{}` – `{}`): non-matching, {} pairs on the nodes of `{}`, `{}` projected onto \
                         them ({} terms)",
                        m.subdomains[itf.a].name,
                        m.subdomains[itf.b].name,
                        itf.n_pairs(),
                        m.subdomains[itf.a].name,
                        m.subdomains[itf.b].name,
                        projection.nodes.len()
                    );
                    let mut b_nodes = projection.nodes.clone();
                    b_nodes.sort_unstable();
                    b_nodes.dedup();
                    if itf.n_pairs() > b_nodes.len() {
                        glissade::console::warn(&format!(
                            "interface {i}: its pairs are the finer side's nodes ({} against {} of `{}`: the coarser \
                             side's edges do not cover the interface from end to end); traction modes the coarser \
                             side cannot see may keep the iteration from settling (docs/method.md, \
                             \"Non-matching interfaces\")",
                            itf.n_pairs(),
                            b_nodes.len(),
                            m.subdomains[itf.b].name
                        ));
                    }
                }
            }
            // How a run as processes deploys it: which subdomains each process hosts, which
            // interfaces each interface node owns.
            let plan = glissade_deploy::Plan::new(m).with_scene(&sc);
            for line in plan.deployment_lines(&plan.groups(sc.deployment.subdomain_nodes)) {
                println!("{line}");
            }
            for warning in glissade_scene::free_motions(m) {
                glissade::console::warn(&warning);
            }
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
            let done = run_node_process(
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
            );
            match done {
                Ok(()) => Ok(ExitCode::SUCCESS),
                // The launcher stopped the run (interrupted, or a run it ended): not this node's
                // error, so it is not said as one; the exit status stays that of a node that did
                // not finish.
                Err(glissade::Error::Transport(glissade_zenoh::TransportError::Stopped(why))) => {
                    eprintln!("note: stopped by the launcher: {why}");
                    Ok(ExitCode::from(2))
                }
                Err(e) => Err(e.into()),
            }
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
                interfaces_with_subdomains: args.interfaces_with_subdomains,
                partition: match args.partition {
                    cli::PartitionArg::Contiguous => glissade_scene::Partition::Contiguous,
                    cli::PartitionArg::Bisection => glissade_scene::Partition::Bisection,
                },
            };
            // Checking the scene below builds its meshes here: about 100 bytes per node of the
            // subdomains' QUA8 meshes (measured 28 kB per subdomain of 10 × 10 elements at 1000
            // and 4000 subdomains). A laminate whose meshes this machine cannot hold is refused
            // before anything is built.
            let e = args.elements as f64;
            let need = args.plies as f64 * args.per_ply as f64 * (3.0 * e * e + 4.0 * e + 1.0) * 100.0;
            if let Some(have) = glissade::machine_memory() {
                if need > 0.8 * have as f64 {
                    anyhow::bail!(
                        "a laminate of {} × {} subdomains of {} × {} QUA8 needs about {:.1} GB to be built and checked \
                         here, and this machine has {:.1} GB: fewer plies, subdomains or elements",
                        laminate.plies,
                        laminate.per_ply,
                        args.elements,
                        args.elements,
                        need * 1e-9,
                        have as f64 * 1e-9
                    );
                }
            }
            let text = laminate.scene_text()?;
            // Check what was generated as any scene is checked, before writing it; but not against
            // this machine's memory for a run (the scene may be meant for a larger one): only its
            // meshes, which the check builds here, had to fit (above).
            glissade_scene::set_machine_memory(0);
            glissade_scene::load_str(&text, &args.out.display().to_string())
                .context("the generated scene does not load (a bug in the generator)")?;
            let mut file = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&args.out)
                .map_err(|e| {
                    let also = if e.kind() == std::io::ErrorKind::AlreadyExists {
                        " (an existing file is not overwritten)"
                    } else {
                        ""
                    };
                    anyhow::anyhow!("cannot create {}: {e}{also}", args.out.display())
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
