//! Multi-process runs (DESIGN §4): the launcher spawns one OS process per node group as the
//! scene's deployment section says, hosts the Zenoh router they connect to, serves them the scene
//! over the bus, forwards their logs with a prefix, watches the run's messages for progress and
//! results, and stops every node when one fails.

use crate::runner::{build_nodes, IterationRecord, Plan, RunOptions, RunResult, Selection};
use anyhow::{bail, Context};
use glissade_bus::RunContext;
use glissade_mechanics::scene::{fingerprint, load_str, LoadedScene};
use glissade_messages::{decode, encode, Expected, Message, NodeId, Payload, Role, Stage, Verdict};
use glissade_zenoh as transport;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How long nodes may take to fetch the scene, build their operators and report ready.
const READY_TIMEOUT: Duration = Duration::from_secs(300);
/// Longest silence on the bus before a run is declared stalled.
const IDLE_TIMEOUT: Duration = Duration::from_secs(600);

/// One spawned node process.
struct NodeProcess {
    name: String,
    child: Child,
    last_lines: Arc<Mutex<Vec<String>>>,
}

/// Kills every child still running when dropped (on any error path).
struct Children(Vec<NodeProcess>);

impl Drop for Children {
    fn drop(&mut self) {
        for p in &mut self.0 {
            if let Ok(None) = p.child.try_wait() {
                let _ = p.child.kill();
                let _ = p.child.wait();
            }
        }
    }
}

/// A free TCP port on the loopback interface.
fn free_port() -> anyhow::Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("cannot bind a loopback port")?;
    Ok(l.local_addr()?.port())
}

fn forward(prefix: String, stream: impl std::io::Read + Send + 'static, last: Arc<Mutex<Vec<String>>>) {
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(Result::ok) {
            eprintln!("[{prefix}] {line}");
            if let Ok(mut l) = last.lock() {
                l.push(line);
                let n = l.len();
                if n > 10 {
                    l.drain(..n - 10);
                }
            }
        }
    });
}

/// Runs `scene` with one process per node group, all on this machine over loopback.
pub fn run_multi_process(
    scene: &LoadedScene,
    opts: &RunOptions,
    exe: &Path,
    mut on_iteration: impl FnMut(&IterationRecord),
) -> anyhow::Result<RunResult> {
    let model = &scene.model;
    if model.interfaces.is_empty() {
        // Nothing to distribute: the in-process direct solve.
        return Ok(crate::runner::run_in_process(scene, opts, on_iteration)?);
    }
    if scene.deployment.interface_nodes != 1 {
        bail!(
            "deployment.interface_nodes = {}: this version runs exactly one interface node",
            scene.deployment.interface_nodes
        );
    }
    let t0 = Instant::now();
    let plan = Plan::new(model);
    let groups = plan.groups(scene.deployment.subdomain_nodes);
    let endpoint = format!("tcp/127.0.0.1:{}", free_port()?);
    let session = transport::open(transport::config(
        "router",
        std::slice::from_ref(&endpoint),
        &[],
        false,
    )?)?;
    let launcher = NodeId {
        role: Role::Launcher,
        index: 0,
    };
    let scene_msg = Message {
        envelope: RunContext {
            run_id: opts.run_id.clone(),
            scene_fingerprint: scene.fingerprint,
        }
        .envelope(launcher, 0, Stage::Setup),
        payload: Payload::Scene {
            text: scene.text.clone(),
        },
    };
    let _queryable = transport::serve_scene(&session, &opts.run_id, encode(&scene_msg))?;
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    let _watch = session
        .declare_subscriber(glissade_messages::run_topics(&opts.run_id))
        .callback(move |s| {
            let _ = tx.send(s.payload().to_bytes().into_owned());
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: subscribe to the run: {e}"))?;

    // Spawn the node processes.
    let mut specs: Vec<(String, Vec<String>, String)> = Vec::new();
    for (g, group) in groups.iter().enumerate() {
        let list = group.iter().map(u32::to_string).collect::<Vec<_>>().join(",");
        specs.push((
            format!("subdomain:{g}"),
            vec!["subdomain".into(), "--subdomains".into(), list],
            transport::alive_key(&opts.run_id, "subdomain", g as u32),
        ));
    }
    specs.push((
        "interface:0".into(),
        vec!["interface".into()],
        transport::alive_key(&opts.run_id, "interface", 0),
    ));
    if plan.coarse {
        specs.push((
            "coarse:0".into(),
            vec!["coarse".into()],
            transport::alive_key(&opts.run_id, "coarse", 0),
        ));
    }
    let mut children = Children(Vec::new());
    for (name, role_args, _) in &specs {
        let mut cmd = Command::new(exe);
        cmd.arg("node")
            .args(role_args)
            .args(["--run", &opts.run_id, "--connect", &endpoint]);
        if role_args[0] == "subdomain" {
            cmd.arg("--index").arg(name.trim_start_matches("subdomain:"));
            if opts.interior {
                cmd.arg("--interior");
            }
        }
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot start node process {name} ({})", exe.display()))?;
        let last = Arc::new(Mutex::new(Vec::new()));
        if let Some(out) = child.stdout.take() {
            forward(name.clone(), out, last.clone());
        }
        if let Some(err) = child.stderr.take() {
            forward(name.clone(), err, last.clone());
        }
        children.0.push(NodeProcess {
            name: name.clone(),
            child,
            last_lines: last,
        });
    }
    let check_children = |children: &mut Children| -> anyhow::Result<()> {
        for p in &mut children.0 {
            if let Some(status) = p.child.try_wait()? {
                if !status.success() {
                    let lines = p.last_lines.lock().map(|l| l.join("\n    ")).unwrap_or_default();
                    bail!("node {} failed ({status}); its last lines:\n    {lines}", p.name);
                }
            }
        }
        Ok(())
    };
    let expected_tokens: Vec<String> = specs.iter().map(|s| s.2.clone()).collect();
    transport::wait_for_nodes(&session, &opts.run_id, &expected_tokens, READY_TIMEOUT, || {
        check_children(&mut children).map_err(|e| transport::TransportError::Protocol(format!("{e:#}")))
    })?;
    let setup_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();

    // Watch the run until every node process has exited.
    let expected = Expected {
        run_id: opts.run_id.clone(),
        scene_fingerprint: scene.fingerprint,
    };
    let (mut iterations, mut interfaces, mut displacements) = (Vec::new(), Vec::new(), Vec::new());
    let mut last_message = Instant::now();
    loop {
        check_children(&mut children)?;
        match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(bytes) => {
                last_message = Instant::now();
                let Ok(m) = decode(&bytes, &expected) else { continue };
                match m.payload {
                    Payload::Decision(d) => {
                        let rec = IterationRecord {
                            iteration: m.envelope.iteration,
                            elapsed_s: t1.elapsed().as_secs_f64(),
                            decision: d,
                        };
                        on_iteration(&rec);
                        iterations.push(rec);
                    }
                    Payload::InterfaceSolution(s) => interfaces.push(s),
                    Payload::Displacement { subdomain, u } => displacements.push((subdomain, u)),
                    _ => {}
                }
            }
            Err(_) => {
                let all_done = children.0.iter_mut().all(|p| matches!(p.child.try_wait(), Ok(Some(_))));
                if all_done {
                    // Drain what is still queued, then stop.
                    while let Ok(bytes) = rx.try_recv() {
                        if let Ok(m) = decode(&bytes, &expected) {
                            match m.payload {
                                Payload::InterfaceSolution(s) => interfaces.push(s),
                                Payload::Displacement { subdomain, u } => displacements.push((subdomain, u)),
                                _ => {}
                            }
                        }
                    }
                    break;
                }
                if last_message.elapsed() > IDLE_TIMEOUT {
                    bail!("no message on the bus for {IDLE_TIMEOUT:?}: the run stalled");
                }
            }
        }
    }
    check_children(&mut children)?;
    interfaces.sort_by_key(|s| s.interface);
    displacements.sort_by_key(|d| d.0);
    let verdict = iterations
        .last()
        .map(|r| r.decision.verdict.clone())
        .unwrap_or(Verdict::MaxIterations);
    let (mut names, left_out) = plan.describe(model, groups.len());
    names.push(format!(
        "processes: {} (+ this launcher hosting the Zenoh router on {endpoint})",
        specs.len()
    ));
    Ok(RunResult {
        setup_s,
        solve_s: t1.elapsed().as_secs_f64(),
        iterations,
        verdict,
        interfaces,
        displacements,
        k0: plan.k0.clone(),
        nodes: names,
        left_out,
    })
}

/// Role of a node process started by hand or by the launcher.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeRole {
    Subdomain,
    Interface,
    Coarse,
}

/// Runs one node process: connects to `connect`, fetches the scene of run `run_id` over the bus,
/// builds its nodes and runs them until the run ends.
pub fn run_node_process(
    role: NodeRole,
    run_id: &str,
    connect: &[String],
    subdomains: &[u32],
    index: u32,
    interior: bool,
) -> anyhow::Result<()> {
    let session = transport::open(transport::config("client", &[], connect, false)?)?;
    let bytes = transport::fetch_scene(&session, run_id, Duration::from_secs(60))?;
    let fp = transport::scene_fingerprint_of(&bytes, run_id)?;
    let expected = Expected {
        run_id: run_id.to_string(),
        scene_fingerprint: fp,
    };
    let msg = decode(&bytes, &expected)?;
    let Payload::Scene { text } = msg.payload else {
        bail!(
            "the launcher's scene query returned a {} message",
            msg.payload.field_key()
        )
    };
    if fingerprint(&text) != fp {
        bail!("the scene received from the bus does not match its fingerprint {fp:016x}");
    }
    let scene = load_str(&text, "<scene from the bus>")?;
    let model = Arc::new(scene.model.clone());
    let plan = Plan::new(&model);
    let selection = match role {
        NodeRole::Subdomain => Selection {
            subdomains: subdomains.to_vec(),
            interface: false,
            coarse: false,
        },
        NodeRole::Interface => Selection {
            subdomains: Vec::new(),
            interface: true,
            coarse: false,
        },
        NodeRole::Coarse => Selection {
            subdomains: Vec::new(),
            interface: false,
            coarse: true,
        },
    };
    let ctx = RunContext {
        run_id: run_id.to_string(),
        scene_fingerprint: fp,
    };
    let nodes = build_nodes(&model, &ctx, interior, &plan, &selection)?;
    let (token_role, token_index) = match role {
        NodeRole::Subdomain => ("subdomain", index),
        NodeRole::Interface => ("interface", 0),
        NodeRole::Coarse => ("coarse", 0),
    };
    let run = transport::NodeRun {
        run_id: run_id.to_string(),
        expected,
        token_role: token_role.to_string(),
        token_index,
        start_timeout: READY_TIMEOUT,
        idle_timeout: IDLE_TIMEOUT,
    };
    transport::run_nodes(&session, &run, nodes, |l| eprintln!("{l}"))?;
    let _ = session.close().wait();
    Ok(())
}
