//! `glissade generate`: scenes written by a generator, checked before they are written.

use super::*;
use crate::cli::{GenerateArgs, GenerateKind, PartitionArg};

/// Writes the generated scene to `args.out` (never over an existing file), once it loads.
pub(crate) fn generate(args: GenerateArgs) -> anyhow::Result<ExitCode> {
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
            PartitionArg::Contiguous => glissade_scene::Partition::Contiguous,
            PartitionArg::Bisection => glissade_scene::Partition::Bisection,
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
