//! `glissade node`: one node process, started by hand, by the launcher or as a Slurm job step.

use super::*;
use crate::cli::{NodeArgs, RoleArg};
use glissade::bus::Joining;
use glissade::children::{NodeName, NodeRole};
use glissade::distributed::Supervision;
use glissade::node_process::run_node_process;

/// Joins the run's bus with the node's credentials (and TLS) and runs its role to the end.
pub(crate) fn node(args: NodeArgs) -> anyhow::Result<ExitCode> {
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
