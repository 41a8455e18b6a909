//! Runs a scene's LATIN iteration with every node in this process (DESIGN §4): one subdomain
//! node per subdomain, one interface node, one coarse node when the scene needs one, on the
//! in-process bus; subdomain work within a round runs in parallel on all cores.

use glissade_bus::{BusError, InProcessBus, Node, RunContext};
use glissade_coarse::CoarseNode;
use glissade_interface::InterfaceNode;
use glissade_mechanics::assembly::AssemblyError;
use glissade_mechanics::linear::{default_k0, macro_basis, SubdomainSolver};
use glissade_mechanics::monolithic::solve_glued;
use glissade_mechanics::scene::LoadedScene;
use glissade_messages::{Decision, Field, InterfaceSolution, Message, Payload, Verdict};
use glissade_subdomain::{SubdomainNode, SubdomainOptions};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Options of an in-process run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    pub run_id: String,
    /// Collect every subdomain's full displacement field at the end.
    pub interior: bool,
}

/// One LATIN iteration as seen by the launcher.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct IterationRecord {
    pub iteration: u32,
    /// Wall time since the start of the iteration loop (s).
    pub elapsed_s: f64,
    pub decision: Decision,
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Building operators (s).
    pub setup_s: f64,
    /// The iteration loop (s).
    pub solve_s: f64,
    pub iterations: Vec<IterationRecord>,
    pub verdict: Verdict,
    /// s and ŝ of every interface at the stop.
    pub interfaces: Vec<InterfaceSolution>,
    /// (subdomain, n_dofs × (N+1)) when asked for, or when the scene has no interface.
    pub displacements: Vec<(u32, Field)>,
    pub k0: Vec<f64>,
    /// Nodes the run used: (role, count), and what it left out and why.
    pub nodes: Vec<String>,
    pub left_out: Vec<String>,
}

/// Errors of a run.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("subdomain `{name}`: {source}")]
    Operator { name: String, source: AssemblyError },
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("glued solve: {0}")]
    Glued(AssemblyError),
}

/// Runs `scene` in-process. `on_iteration` sees each iteration's decision as it is made.
pub fn run_in_process(
    scene: &LoadedScene,
    opts: &RunOptions,
    on_iteration: impl FnMut(&IterationRecord),
) -> Result<RunResult, RunError> {
    run_in_process_observed(scene, opts, on_iteration, |_| Duration::ZERO)
}

/// As [`run_in_process`], and `observe` sees every message of the run in publication order. It
/// returns the wall time it spent, which is left out of the iterations' elapsed times (so a
/// report may measure errors without charging the solver for it).
pub fn run_in_process_observed(
    scene: &LoadedScene,
    opts: &RunOptions,
    mut on_iteration: impl FnMut(&IterationRecord),
    mut observe: impl FnMut(&Message) -> Duration,
) -> Result<RunResult, RunError> {
    let model = Arc::new(scene.model.clone());
    let t0 = Instant::now();
    if model.interfaces.is_empty() {
        // One part, nothing to iterate: a direct solve.
        let sol = solve_glued(&model).map_err(RunError::Glued)?;
        let displacements = sol
            .u
            .iter()
            .enumerate()
            .map(|(s, u)| (s as u32, glissade_bus::convert::field_of(u.as_ref())))
            .collect();
        return Ok(RunResult {
            setup_s: t0.elapsed().as_secs_f64(),
            solve_s: 0.0,
            iterations: Vec::new(),
            verdict: Verdict::Converged,
            interfaces: Vec::new(),
            displacements,
            k0: Vec::new(),
            nodes: vec!["none: direct solve".into()],
            left_out: vec![
                "interface, coarse and subdomain nodes: the scene has no interface (one part), solved directly".into(),
            ],
        });
    }
    let ctx = RunContext {
        run_id: opts.run_id.clone(),
        scene_fingerprint: scene.fingerprint,
    };
    let k0 = default_k0(&model);
    let bases: Vec<Vec<Vec<f64>>> = model.interfaces.iter().map(macro_basis).collect();
    let interface_node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
    let participants: Vec<u32> = interface_node.participants().to_vec();
    let coarse = model.solver.coarse;
    let solvers: Vec<SubdomainSolver> = participants
        .par_iter()
        .map(|&s| {
            SubdomainSolver::new(&model, s as usize, &k0, &bases).map_err(|source| RunError::Operator {
                name: model.subdomains[s as usize].name.clone(),
                source,
            })
        })
        .collect::<Result<_, _>>()?;
    let options = SubdomainOptions {
        coarse,
        relaxation: model.solver.relaxation,
        send_displacement: opts.interior,
    };
    let mut nodes: Vec<Box<dyn Node>> = Vec::new();
    let mut left_out = Vec::new();
    let n_sub = solvers.len();
    for solver in solvers {
        nodes.push(Box::new(SubdomainNode::new(
            ctx.clone(),
            model.clone(),
            solver,
            options,
        )));
    }
    nodes.push(Box::new(interface_node));
    let mut names = vec![format!("subdomain × {n_sub}"), "interface × 1".to_string()];
    if coarse {
        let n_modes = bases.iter().map(Vec::len).collect();
        nodes.push(Box::new(CoarseNode::new(
            ctx,
            n_modes,
            participants.clone(),
            model.time.n_points(),
        )));
        names.push("coarse × 1".into());
    } else {
        left_out.push("coarse node: the scene switches the coarse problem off".into());
    }
    if model.subdomains.len() > participants.len() {
        left_out.push(format!(
            "{} subdomain(s) without interface: not part of the iteration",
            model.subdomains.len() - participants.len()
        ));
    }
    let setup_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let mut iterations = Vec::new();
    let mut interfaces = Vec::new();
    let mut displacements = Vec::new();
    let mut bus = InProcessBus::new(nodes);
    let mut observer_time = Duration::ZERO;
    bus.run(|m| {
        observer_time += observe(m);
        match &m.payload {
            Payload::Decision(d) => {
                let rec = IterationRecord {
                    iteration: m.envelope.iteration,
                    elapsed_s: t1.elapsed().saturating_sub(observer_time).as_secs_f64(),
                    decision: d.clone(),
                };
                on_iteration(&rec);
                iterations.push(rec);
            }
            Payload::InterfaceSolution(s) => interfaces.push(s.clone()),
            Payload::Displacement { subdomain, u } => displacements.push((*subdomain, u.clone())),
            _ => {}
        }
        true
    })?;
    let verdict = iterations
        .last()
        .map(|r| r.decision.verdict.clone())
        .unwrap_or(Verdict::MaxIterations);
    Ok(RunResult {
        setup_s,
        solve_s: t1.elapsed().saturating_sub(observer_time).as_secs_f64(),
        iterations,
        verdict,
        interfaces,
        displacements,
        k0,
        nodes: names,
        left_out,
    })
}
