//! Runs a scene's LATIN iteration with every node in this process (docs/architecture.md): one subdomain
//! node per subdomain, the deployment's interface nodes, one coarse node when the scene needs one, on the
//! in-process bus; subdomain work within a round runs in parallel on all cores.

use glissade_bus::convert::{field_of, mat_of, view};
use glissade_bus::{BusError, HandleTime, InProcessBus, Node, RunContext};
use glissade_deploy::{build_nodes_with, build_solvers, BuildError, Plan, Selection};
use glissade_mechanics::assembly::AssemblyError;
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::{interpolated_directions, SubdomainSolver};
use glissade_mechanics::local::InterfaceFields;
use glissade_mechanics::model::{Model, Side, TimeGrid};
use glissade_messages::{Decision, Field, InterfaceSolution, Message, NodeId, Payload, Role, Stage, Verdict};
use glissade_reference::glued::solve_glued;
use glissade_scene::LoadedScene;
use glissade_subdomain::{LinearStageRecord, LinearStageRecords};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Options of an in-process run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOptions {
    pub run_id: String,
    /// Collect every subdomain's full displacement field at the end.
    pub interior: bool,
    /// Keep the run's own final state ([`RunResult::state`]): what a study's next variant starts
    /// from.
    pub keep_state: bool,
}

impl RunOptions {
    /// Run `run_id`, without the subdomains' displacement fields.
    pub fn new(run_id: impl Into<String>) -> Self {
        Self {
            run_id: run_id.into(),
            interior: false,
            keep_state: false,
        }
    }
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
    /// The iteration loop (s), until every result is held (as processes: until the launcher
    /// holds every final field; the node processes' exit after that is not counted, as an
    /// in-process run's release of its nodes after the loop is not).
    pub solve_s: f64,
    pub iterations: Vec<IterationRecord>,
    pub verdict: Verdict,
    /// s and ŝ of every interface at the stop, each copy of a point given the point's values
    /// ([`glissade_replay::one_value_per_point`]).
    pub interfaces: Vec<InterfaceSolution>,
    /// The same before the copies of a point are given one value: the iteration's own state, from
    /// which a given start ([`Prepared::start`]) resumes it exactly. Kept when asked for
    /// ([`RunOptions::keep_state`]), in-process.
    pub state: Option<Vec<InterfaceSolution>>,
    /// Every boundary rule's force on the parts (supports' reactions, loads' resultants), from
    /// each copy's own fields (before they are given one value per point).
    pub boundary: Vec<crate::boundary::RuleResultants>,
    /// (subdomain, n_dofs × (N+1)) when asked for, or when the scene has no interface.
    pub displacements: Vec<(u32, Field)>,
    pub k0: Vec<f64>,
    /// Nodes the run used: (role, count), and what it left out and why.
    pub nodes: Vec<String>,
    pub left_out: Vec<String>,
}

impl RunResult {
    /// The stopped state of every interface as matrices, in interface order (the form the
    /// reference comparisons of `glissade_mechanics::local` take).
    pub fn interface_fields(&self) -> Vec<InterfaceFields> {
        self.fields_of(|s| [&s.w_a, &s.w_b, &s.f_a, &s.f_b])
    }

    /// The same of ŝ (the last local stage's fields, from which the statuses are decided).
    pub fn interface_hat_fields(&self) -> Vec<InterfaceFields> {
        self.fields_of(|s| [&s.w_a_hat, &s.w_b_hat, &s.f_a_hat, &s.f_b_hat])
    }

    /// W_a, W_b, F_a, F_b of every interface as `pick` takes them from its solution, in
    /// interface order.
    fn fields_of(&self, pick: impl Fn(&InterfaceSolution) -> [&Field; 4]) -> Vec<InterfaceFields> {
        let mut sols: Vec<&InterfaceSolution> = self.interfaces.iter().collect();
        sols.sort_by_key(|s| s.interface);
        sols.into_iter()
            .map(|s| {
                let [w_a, w_b, f_a, f_b] = pick(s).map(mat_of);
                InterfaceFields { w_a, w_b, f_a, f_b }
            })
            .collect()
    }
}

/// The Anderson steps of a run, told apart from its messages: each iteration's `anderson_gram`
/// partials say how many differences the histories hold, and the `anderson_step` sent back says
/// what the subdomains do with them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct AndersonTally {
    /// Mixed steps (coefficients γ sent).
    pub mixed: u32,
    /// Plain relaxation steps taken because the previous mixed step made the residual grow (the
    /// safeguard).
    pub safeguarded: u32,
    /// Restarts of every history (ill-conditioned or non-finite least squares, or a
    /// search-direction update).
    pub restarted: u32,
    /// Plain steps with no stored difference yet (the first iteration).
    pub unmixed: u32,
    #[serde(skip)]
    differences: usize,
}

impl AndersonTally {
    /// Counts `m` if it is one of the Anderson messages.
    pub fn observe(&mut self, m: &Message) {
        match &m.payload {
            Payload::AndersonGram { gram, .. } => self.differences = gram.rows(),
            Payload::AndersonStep { restart: true, .. } => self.restarted += 1,
            Payload::AndersonStep { gamma, .. } if !gamma.is_empty() => self.mixed += 1,
            Payload::AndersonStep { .. } if self.differences > 0 => self.safeguarded += 1,
            Payload::AndersonStep { .. } => self.unmixed += 1,
            _ => {}
        }
    }
}

/// What a run may be given beyond its scene (in-process only): operators already built, and
/// the state to start from.
#[derive(Default)]
pub struct Prepared {
    /// Every participant's operators, in participant order, built for this scene's operators
    /// (its materials and search directions): a time-coarse start's coarse solve, or a study's
    /// variant that changes loads, gaps or friction only ([`SubdomainSolver::retimed`]).
    pub solvers: Option<Vec<SubdomainSolver>>,
    /// A given start: ŝ of every interface (W and F of both sides, on this scene's time grid, in
    /// interface order), e.g. a solved variant of the same scene in a study. Iteration 0 starts
    /// from q̂ = F̂ + k⁻Ŵ of it instead of ŝ = 0; it replaces a time-coarse start.
    pub start: Option<Vec<InterfaceSolution>>,
}

/// Errors of a run.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Build(#[from] BuildError),
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("glued solve: {0}")]
    Glued(AssemblyError),
    #[error("time-coarse start (solver.time_coarsening): {0}")]
    TimeStart(String),
    /// The recording cannot be created or finished (the recorder's error names the file).
    #[error(transparent)]
    Recording(glissade_recorder::RecorderError),
    /// A write failed (e.g. a full disk): the run stopped at the end of that iteration. The
    /// recorder's error is part of the message (not a separate cause, so it is printed once).
    #[error("the run was stopped after {iterations} iteration(s): its recording could not be written: {cause}")]
    RecordingStopped {
        iterations: usize,
        cause: glissade_recorder::RecorderError,
    },
    #[error("given start: {0}")]
    GivenStart(String),
    #[error("{0} is available in-process only")]
    InProcessOnly(&'static str),
}

/// The in-process run behind [`crate::run::Run::in_process`]: `on_iteration` sees each
/// decision and stops the run when it returns false; `observe` sees every message and returns
/// the wall time it spent, left out of the iterations' elapsed times; `log` and `timing` collect
/// the linear-stage records and the handling times; `prepared`: operators already built (a
/// time-coarse start's coarse solve reuses the fine run's) and a given start.
pub(crate) fn run_logged(
    scene: &LoadedScene,
    opts: &RunOptions,
    mut on_iteration: impl FnMut(&IterationRecord) -> bool,
    mut observe: impl FnMut(&Message) -> Duration,
    log: Option<&mut Vec<LinearStageRecord>>,
    timing: Option<&mut Vec<HandleTime>>,
    prepared: Prepared,
) -> Result<RunResult, RunError> {
    let mut model = scene.model.clone();
    if prepared.start.is_some() {
        model.solver.time_start = None;
        model.solver.given_start = true;
    }
    let model = Arc::new(model);
    let t0 = Instant::now();
    if model.interfaces.is_empty() {
        // One part, nothing to iterate: a direct solve.
        return direct_solve(&model, t0);
    }
    let ctx = RunContext {
        run_id: opts.run_id.clone(),
        scene_fingerprint: scene.fingerprint,
    };
    let plan = Plan::new(&model).with_scene(scene);
    let (nodes, names, left_out) = nodes_of(scene, &model, &ctx, &plan, opts.interior, prepared)?;
    let k0 = plan.k0.clone();
    let setup_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let mut iterations = Vec::new();
    let (mut interfaces, mut displacements) = (Vec::new(), Vec::new());
    // The final fields are moved out of the bus once delivered, not copied here.
    let mut bus = InProcessBus::new(nodes)
        .with_timing(timing.is_some())
        .with_iteration_timing(log.is_some())
        .keeping(|m| matches!(m.payload, Payload::InterfaceSolution(_) | Payload::Displacement { .. }));
    let mut observer_time = Duration::ZERO;
    let mut stages = LinearStageRecords::default();
    bus.run(|m| {
        observer_time += observe(m);
        stages.observe(m);
        if let Payload::Decision(d) = &m.payload {
            let rec = IterationRecord {
                iteration: m.envelope.iteration,
                elapsed_s: t1.elapsed().saturating_sub(observer_time).as_secs_f64(),
                decision: d.clone(),
            };
            let keep_going = on_iteration(&rec);
            iterations.push(rec);
            return keep_going;
        }
        true
    })?;
    for m in bus.take_kept() {
        match m.payload {
            Payload::InterfaceSolution(s) => interfaces.push(s),
            Payload::Displacement { subdomain, u } => displacements.push((subdomain, u)),
            _ => {}
        }
    }
    if let Some(times) = timing {
        *times = bus.handle_times();
    }
    if let Some(records) = log {
        *records = stages.records(&bus.iteration_times());
    }
    // Several interface nodes publish their interfaces' solutions in node order.
    interfaces.sort_by_key(|s| s.interface);
    let state = opts.keep_state.then(|| interfaces.clone());
    let boundary = crate::boundary::boundary_resultants(&model, &interfaces, model.moment_about);
    glissade_replay::as_reported(&model, &mut interfaces);
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
        state,
        boundary,
        displacements,
        k0,
        nodes: names,
        left_out,
    })
}

/// A scene of one part, nothing to iterate: the glued solve, as a run's result.
fn direct_solve(model: &Model, t0: Instant) -> Result<RunResult, RunError> {
    let sol = solve_glued(model).map_err(RunError::Glued)?;
    let displacements = sol
        .u
        .iter()
        .enumerate()
        .map(|(s, u)| (s as u32, glissade_bus::convert::field_of(u.as_ref())))
        .collect();
    Ok(RunResult {
        setup_s: t0.elapsed().as_secs_f64(),
        solve_s: 0.0,
        iterations: Vec::new(),
        verdict: Verdict::Converged,
        interfaces: Vec::new(),
        state: None,
        boundary: crate::boundary::boundary_resultants(model, &[], model.moment_about),
        displacements,
        k0: Vec::new(),
        nodes: vec!["none: direct solve".into()],
        left_out: vec![
            "interface, coarse and subdomain nodes: the scene has no interface (one part), solved directly".into(),
        ],
    })
}

/// The nodes of an in-process run (with the launcher's start, a time-coarse or a given one, as a
/// node of its own), what they are and what the run leaves out; `prepared`'s operators where
/// given.
#[allow(clippy::type_complexity)]
fn nodes_of(
    scene: &LoadedScene,
    model: &Arc<Model>,
    ctx: &RunContext,
    plan: &Plan,
    interior: bool,
    prepared: Prepared,
) -> Result<(Vec<Box<dyn Node>>, Vec<String>, Vec<String>), RunError> {
    let selection = Selection::everything(plan);
    let solvers = match prepared.solvers {
        Some(s) => {
            check_prepared(model, plan, &s)?;
            s
        }
        None => build_solvers(model, plan, &selection.subdomains)?,
    };
    let start = match &prepared.start {
        Some(given) => Some((
            "launcher: given start (ŝ of a solved variant)".to_string(),
            given_start(model, ctx, plan, given)?,
        )),
        None => time_start(scene, ctx, plan, Some(&solvers))?.map(|t| (t.describe(), t.messages)),
    };
    let mut nodes = build_nodes_with(model, ctx, interior, plan, &selection, solvers)?;
    let (mut names, left_out) = plan.describe(model, 1);
    if let Some((describe, messages)) = start {
        names.push(describe);
        nodes.push(Box::new(LauncherNode {
            id: launcher_id(),
            out: messages,
        }));
    }
    Ok((nodes, names, left_out))
}

fn launcher_id() -> NodeId {
    NodeId {
        role: Role::Launcher,
        index: 0,
    }
}

/// The coarse solve of a time-coarse start (`solver.time_coarsening`, [`TimeStart`]) and the
/// messages it gives.
#[derive(Debug)]
pub struct TimeStartRun {
    pub coarse_steps: usize,
    pub iterations: usize,
    pub eta: f64,
    pub verdict: Verdict,
    /// Wall time of the coarse solve, setup included.
    pub seconds: f64,
    /// One `local_directions` message per subdomain of the run, from launcher:0 at iteration 0,
    /// stage local (the stage of every `local_directions`): q̂ = F̂ + k⁻Ŵ over its whole
    /// boundary, from the coarse solve's ŝ interpolated linearly in time.
    pub messages: Vec<Message>,
}

impl TimeStartRun {
    /// One line for the run's node list.
    pub fn describe(&self) -> String {
        format!(
            "launcher: time-coarse start, {} steps solved in-process in {:.2} s ({} iterations, η = {:.3e}, {:?})",
            self.coarse_steps, self.seconds, self.iterations, self.eta, self.verdict
        )
    }
}

/// Solves `scene` on its coarse time grid when it asks for a time-coarse start (None otherwise)
/// and builds the fine run's initial local directions. A coarse solve that diverges is an error;
/// one that stops short of its tolerance (iteration cap, stagnation) still gives its state, and
/// its verdict is reported. `fine`: the fine run's operators of every participant, if built,
/// which the coarse solve then reuses on its own time grid ([`SubdomainSolver::retimed`])
/// instead of building them again.
pub fn time_start(
    scene: &LoadedScene,
    ctx: &RunContext,
    plan: &Plan,
    fine: Option<&[SubdomainSolver]>,
) -> Result<Option<TimeStartRun>, RunError> {
    let Some(ts) = scene.model.solver.time_start else {
        return Ok(None);
    };
    let t0 = Instant::now();
    let model = &scene.model;
    let mut coarse = scene.clone();
    coarse.model.time.n_steps = model.time.n_steps / ts.coarsening;
    (coarse.model.solver.accuracy, coarse.model.solver.tolerance) = (None, Some(ts.tolerance));
    coarse.model.solver.contact_tolerance = None;
    coarse.model.solver.time_start = None;
    let opts = RunOptions::new(format!("{}-coarse", ctx.run_id));
    let on_iteration: fn(&IterationRecord) -> bool = |_| true;
    let observe: fn(&Message) -> Duration = |_| Duration::ZERO;
    let prepared = Prepared {
        solvers: fine.map(|f| f.iter().map(|s| s.retimed(&coarse.model)).collect()),
        start: None,
    };
    let r = run_logged(&coarse, &opts, on_iteration, observe, None, None, prepared)?;
    let last = r.iterations.last().map(|i| i.decision.clone());
    let (eta, verdict) = last.map_or((f64::NAN, Verdict::MaxIterations), |d| (d.eta, d.verdict));
    if matches!(verdict, Verdict::Diverged { .. }) || r.interfaces.len() != model.interfaces.len() {
        return Err(RunError::TimeStart(format!(
            "the coarse solve on {} steps ended {verdict:?} after {} iterations (η = {eta:.3e}) without a usable state",
            coarse.model.time.n_steps,
            r.iterations.len()
        )));
    }
    let messages = initial_directions(model, &coarse.model.time, ctx, plan, &r.interfaces);
    Ok(Some(TimeStartRun {
        coarse_steps: coarse.model.time.n_steps,
        iterations: r.iterations.len(),
        eta,
        verdict,
        seconds: t0.elapsed().as_secs_f64(),
        messages,
    }))
}

/// One `local_directions` message per participant of `plan`, from launcher:0 at iteration 0:
/// q̂ = F̂ + k⁻Ŵ over its whole boundary, from `solutions` (ŝ on the grid `grid`, whose points
/// are every c-th point of the run's) interpolated linearly in time.
fn initial_directions(
    model: &Model,
    grid: &TimeGrid,
    ctx: &RunContext,
    plan: &Plan,
    solutions: &[InterfaceSolution],
) -> Vec<Message> {
    plan.participants
        .iter()
        .map(|&s| {
            let layout = BoundaryLayout::new(model, s as usize, &plan.k0);
            let q = interpolated_directions(&model.time, grid, &layout, |k, side| {
                let sol = &solutions[k];
                debug_assert_eq!(sol.interface as usize, k);
                match side {
                    Side::A => (view(&sol.w_a_hat), view(&sol.f_a_hat)),
                    Side::B => (view(&sol.w_b_hat), view(&sol.f_b_hat)),
                }
            });
            Message {
                envelope: ctx.envelope(launcher_id(), 0, Stage::Local),
                payload: Payload::LocalDirections {
                    subdomain: s,
                    interfaces: layout.slots.iter().map(|sl| sl.interface as u32).collect(),
                    q_hat: field_of(q.as_ref()),
                },
            }
        })
        .collect()
}

/// The initial directions of a given start, once `given` is checked against the model: one
/// solution per interface in interface order, Ŵ and F̂ of both sides 2·n_pairs × (N+1), finite.
fn given_start(
    model: &Model,
    ctx: &RunContext,
    plan: &Plan,
    given: &[InterfaceSolution],
) -> Result<Vec<Message>, RunError> {
    let nt = model.time.n_points();
    if given.len() != model.interfaces.len() {
        return Err(RunError::GivenStart(format!(
            "{} interface solution(s) for a scene of {} interface(s)",
            given.len(),
            model.interfaces.len()
        )));
    }
    for (k, (sol, itf)) in given.iter().zip(&model.interfaces).enumerate() {
        let rows = 2 * itf.n_pairs();
        for (name, f) in [
            ("W_a_hat", &sol.w_a_hat),
            ("W_b_hat", &sol.w_b_hat),
            ("F_a_hat", &sol.f_a_hat),
            ("F_b_hat", &sol.f_b_hat),
        ] {
            if sol.interface as usize != k || f.rows() != rows || f.cols() != nt {
                return Err(RunError::GivenStart(format!(
                    "interface {k}: {name} of interface {} is {} × {}, the scene's is {rows} × {nt}",
                    sol.interface,
                    f.rows(),
                    f.cols()
                )));
            }
            if f.data.iter().any(|v| !v.is_finite()) {
                return Err(RunError::GivenStart(format!(
                    "interface {k}: {name} holds a non-finite value"
                )));
            }
        }
    }
    Ok(initial_directions(model, &model.time, ctx, plan, given))
}

/// Operators given to a run must be its participants', in order, on its boundary layout with
/// its search directions.
fn check_prepared(model: &Model, plan: &Plan, solvers: &[SubdomainSolver]) -> Result<(), RunError> {
    let same = solvers.len() == plan.participants.len()
        && solvers.iter().zip(&plan.participants).all(|(s, &p)| {
            s.subdomain == p as usize && s.op.layout.k == BoundaryLayout::new(model, p as usize, &plan.k0).k
        });
    if same {
        Ok(())
    } else {
        Err(RunError::GivenStart(
            "the operators given are not this scene's participants' (subdomains or boundaries differ)".into(),
        ))
    }
}

/// The launcher's part of an in-process run: the messages it publishes at the start (a
/// time-coarse start's initial local directions), as a node of the bus, so that they are
/// observed and recorded like every other message.
struct LauncherNode {
    id: NodeId,
    out: Vec<Message>,
}

impl Node for LauncherNode {
    fn id(&self) -> NodeId {
        self.id
    }

    fn subscriptions(&self) -> Vec<String> {
        Vec::new()
    }

    fn start(&mut self) -> Result<Vec<Message>, glissade_bus::NodeError> {
        Ok(std::mem::take(&mut self.out))
    }

    fn handle(&mut self, _msg: &Message) -> Result<Vec<Message>, glissade_bus::NodeError> {
        Ok(Vec::new())
    }

    fn is_finished(&self) -> bool {
        true
    }
}
