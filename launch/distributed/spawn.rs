//! Starting a run's node processes: the ones this machine runs (`glissade node …` children of the
//! launcher, each with its credentials on standard input), the recorder process, and the
//! commands, and credentials files, of the nodes left to be started by hand elsewhere.

use super::hosted::HostedNode;
use super::setup::{node_args, SetUp};
use super::READY_TIMEOUT;
use crate::bus::{tls_args, write_credentials, CredentialFiles};
use crate::children::{spawn_node, Children, NodeName};
use crate::error::{Error, Result};
use crate::recording::RecorderProcess;
use crate::runner::RunOptions;
use glissade_scene::LoadedScene;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The processes of a run once started.
pub(super) struct Spawned {
    pub(super) children: Children,
    /// The nodes the launcher runs in its own process.
    pub(super) hosted: Vec<HostedNode>,
    pub(super) recorder: Option<RecorderProcess>,
    /// How long the nodes started by hand may take to be ready.
    pub(super) remote_timeout: Duration,
    /// Credentials files written for the nodes started by hand, removed when dropped.
    _hand_credentials: CredentialFiles,
}

/// `glissade node` arguments with `--supervised` when dead node processes are restarted.
pub(super) fn with_supervision(supervised: bool, mut args: Vec<String>) -> Vec<String> {
    if supervised {
        args.push("--supervised".into());
    }
    args
}

/// Writes the credentials of the nodes `net.remote` names and prints how to start them by hand
/// (every file is written before a word is printed: whoever reads the instructions finds the
/// files they name). Returns the files, removed when the run ends.
fn instruct_remote(
    set_up: &SetUp,
    scene: &LoadedScene,
    opts: &RunOptions,
    net: &super::Network,
    remote_timeout: std::time::Duration,
) -> Result<CredentialFiles> {
    let (run_id, bus) = (&opts.run_id, &set_up.bus);
    let mut hand_credentials = CredentialFiles(Vec::new());
    if net.remote.is_empty() {
        return Ok(hand_credentials);
    }
    let connect: Vec<String> = if net.connect.is_empty() {
        net.listen
            .iter()
            .map(|l| l.replace("/0.0.0.0:", "/<this machine's address>:"))
            .collect()
    } else {
        net.connect.clone()
    };
    // Every credentials file is written before a word is printed: whoever reads the
    // instructions finds the files they name.
    let mut lines = vec![format!(
        "waiting up to {} s for {} node(s) started by hand; on the other machine(s) run:",
        remote_timeout.as_secs(),
        net.remote.len()
    )];
    let mut remote_tls = match &scene.network.tls {
        Some(t) => {
            lines.push(format!(
                "(TLS: copy {} to the other machine(s){})",
                t.root_ca.display(),
                if t.mutual {
                    "; each node presents its own certificate signed by it"
                } else {
                    ""
                }
            ));
            let ca = Path::new(t.root_ca.file_name().unwrap_or(t.root_ca.as_os_str()));
            let identity = (Path::new("<node-cert.pem>"), Path::new("<node-key.pem>"));
            tls_args(ca, t.mutual.then_some(identity))
        }
        None => Vec::new(),
    };
    remote_tls.extend(bus.shared_memory.then(|| "--shared-memory".to_string()));
    let dir = match (&net.credentials, bus.hosting) {
        (Some(d), true) => Some(d),
        (None, true) => {
            return Err(Error::Option {
                option: "--remote".into(),
                why: "nodes started by hand need their credentials written to a folder (none given)".into(),
            })
        }
        (_, false) => None,
    };
    for &r in &net.remote {
        let mut args = remote_tls.clone();
        if let Some(dir) = dir {
            let cr = &bus.credentials[&r.id()];
            let file = write_credentials(dir, run_id, r, cr)?;
            lines.push(format!(
                "(node {r}: copy {} to its machine, readable by its user only; it lets a process speak as {r} in \
                 this run and nothing else)",
                file.display()
            ));
            hand_credentials.0.push(file.clone());
            let name = file.file_name().map(PathBuf::from).unwrap_or(file);
            args.extend(["--credentials".to_string(), name.display().to_string()]);
        }
        lines.push(format!(
            "  glissade {}",
            with_supervision(set_up.supervised, node_args(r, run_id, &connect, opts.interior, &args)).join(" ")
        ));
    }
    for line in lines {
        crate::console::say(&line);
    }
    Ok(hand_credentials)
}

/// Starts the node processes of `set_up` that this machine runs (all but `net.remote`) and the
/// recorder process (writing `recording`, when given), and prints how to start the others.
pub(super) fn spawn(
    set_up: &SetUp,
    scene: &LoadedScene,
    opts: &RunOptions,
    exe: &Path,
    net: &super::Network,
    recording: Option<&Path>,
) -> Result<Spawned> {
    let run_id = &opts.run_id;
    let bus = &set_up.bus;
    let mut children = Children(Vec::new());
    let mut hosted = Vec::with_capacity(set_up.hosted.len());
    if !set_up.hosted.is_empty() {
        // One model for every node this process runs.
        let model = std::sync::Arc::new(scene.model.clone());
        let ctx = glissade_bus::RunContext {
            run_id: run_id.clone(),
            scene_fingerprint: scene.fingerprint,
        };
        for name in &set_up.hosted {
            hosted.push(HostedNode::start_interface(
                &bus.session,
                &model,
                &ctx,
                &set_up.plan,
                name.index,
            )?);
        }
    }
    let own_process = |n: &NodeName| !net.remote.contains(n) && !set_up.hosted.contains(n);
    for &name in set_up.all_nodes.iter().filter(|n| own_process(n)) {
        let args = with_supervision(
            set_up.supervised,
            node_args(name, run_id, &bus.node_connect, opts.interior, &bus.node_args),
        );
        children.0.push(spawn_node(
            net.starter.command(exe, name, set_up.node_counts()),
            name,
            &args,
            bus.credentials.get(&name.id()).cloned(),
        )?);
    }
    let recorder = match recording {
        Some(path) => Some(crate::recording::spawn_recorder_process(
            exe,
            &bus.session,
            run_id,
            &bus.node_connect[0],
            &bus.node_args,
            set_up.recorder_credentials(),
            path,
        )?),
        None => None,
    };
    let remote_timeout = net.remote_timeout.unwrap_or(READY_TIMEOUT);
    let hand_credentials = instruct_remote(set_up, scene, opts, net, remote_timeout)?;
    Ok(Spawned {
        children,
        hosted,
        recorder,
        remote_timeout,
        _hand_credentials: hand_credentials,
    })
}
