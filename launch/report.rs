//! The error-against-run-time report (issue "monolithic reference"): the monolithic Newton
//! reference of a scene, then the LATIN run, whose contact tractions and jumps are compared with
//! the reference at every iteration; written as JSON and as an SVG plot. If the reference fails
//! at a time step, the LATIN run is still made and reported (its errors against the reference
//! are then null), with the reference's failure and the number of time points it solved. The report also holds
//! what the linear stage cost per iteration (wall time summed over subdomains), the bytes of the
//! iteration's messages on the bus and, with PGD, every subdomain's basis size per iteration
//! (plotted under the errors).

use crate::run::Run;
use crate::runner::{AndersonTally, RunOptions, RunResult};
use glissade_bus::convert::view;
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::local::{ErrorsAgainstReference, PointwiseError, ReferenceErrors};
use glissade_mechanics::model::{Acceleration, TimeStart, DEFAULT_TIME_START_TOLERANCE};
use glissade_mechanics::pgd::PgdCriterion;
use glissade_messages::{encode, Stage, Verdict};
use glissade_reference::{solve_reference_watched, ReferenceOptions, ReferenceRun};
use glissade_replay::BoundaryStates;
use glissade_scene::LoadedScene;
use glissade_subdomain::LinearStageRecord;
use serde::Serialize;
use std::cell::Cell;
use std::time::Instant;

mod plots;
pub use plots::{linear_ticks, log_ticks, plot_basis_svg, plot_iterations_svg, plot_svg, TimeAxis};

/// One LATIN iteration of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReportPoint {
    pub iteration: u32,
    /// Wall time of the LATIN iteration loop at the end of this iteration (s), error
    /// measurement excluded.
    pub elapsed_s: f64,
    pub eta: f64,
    pub contact_indicator: f64,
    /// Relative space-time error of the contact tractions of s against the reference (NaN,
    /// null in JSON, when the reference failed).
    pub traction_error: f64,
    /// Relative space-time error of the contact jumps of s against the reference (NaN, null in
    /// JSON, when the reference failed).
    pub jump_error: f64,
    /// The largest traction difference of s at one contact point and time point against the
    /// reference, relative to the reference's largest contact traction
    /// (`glissade_mechanics::local::pointwise_traction_error`; NaN, null in JSON, when the
    /// reference failed).
    pub pointwise_error: f64,
    /// Where `pointwise_error` is: interface, pair (numbered from 0) and time point.
    pub pointwise_at: [usize; 3],
    /// The run's own estimate of `traction_error` (`glissade_mechanics::estimate`), when it has one.
    pub estimate: Option<f64>,
    /// The contraction the estimate was made with.
    pub contraction: Option<f64>,
    /// The run's own estimate of `pointwise_error`, when it has one.
    pub pointwise_estimate: Option<f64>,
    /// Relative step of the contact forces since the previous iteration.
    pub force_step: f64,
    /// Wall time of this iteration's linear stages, summed over the subdomains (s): the
    /// in-process bus's time of each subdomain's handling of the stage's inputs
    /// (`glissade_subdomain::LinearStageRecords`).
    pub linear_s: f64,
    /// Floating-point operations of this iteration's linear stages, summed over the subdomains,
    /// as the stages' kernels count them (`SubdomainSolver::flops`, `PgdStage::flops`).
    pub linear_flops: u64,
    /// Bytes of this iteration's messages as encoded on the bus (set-up and final ones excluded).
    pub bus_bytes: u64,
    /// PGD basis size of every subdomain after this iteration's linear stage, frozen macro modes
    /// included (subdomain order; empty without PGD).
    pub basis_sizes: Vec<usize>,
}

/// Time to a contact-traction accuracy.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Accuracy {
    pub threshold: f64,
    /// LATIN wall time, operator setup included (s).
    pub wall_s: Option<f64>,
    pub iterations: Option<u32>,
    /// Linear-stage wall time summed over subdomains and iterations up to it (s).
    pub linear_s: Option<f64>,
    /// Linear-stage floating-point operations summed over subdomains and iterations up to it.
    pub linear_flops: Option<u64>,
    /// Largest PGD basis of a subdomain up to it (0 without PGD).
    pub max_basis: Option<usize>,
}

/// Everything a report holds.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub scene: String,
    pub scene_fingerprint: String,
    pub software_version: String,
    pub build_profile: String,
    pub cores: usize,
    pub reference_s: f64,
    pub reference_newton_iterations: usize,
    pub reference_max_newton_per_step: usize,
    /// Why the reference stopped before the last time point (None: it solved them all; then
    /// the errors of the points are against it).
    pub reference_failure: Option<String>,
    /// Time points the reference solved (all N + 1 unless it failed).
    pub reference_steps_solved: usize,
    /// The errors of the points are over this many first time points: all N + 1, or the ones a
    /// failed reference solved (where at least two), or 0 (no errors).
    pub errors_over_time_points: usize,
    pub latin_setup_s: f64,
    pub latin_solve_s: f64,
    pub latin_verdict: String,
    /// The scene's acceleration (`none`, or `anderson(m)`).
    pub acceleration: String,
    /// Anderson steps of the run: mixed, plain (the safeguard), restarts.
    pub anderson_steps: [u32; 3],
    /// The linear stage (`condensed`, `sparse`, `auto`, or `pgd(criterion, ξ₀,₁/ξ₀,₂, macro modes)`).
    pub linear_stage: String,
    /// Where the iteration started: from ŝ = 0, or a time-coarse start (its coarse solve is in
    /// `latin_setup_s`).
    pub start: String,
    pub points: Vec<ReportPoint>,
    /// (threshold, LATIN wall time incl. setup to reach traction error ≤ threshold, iterations).
    pub time_to_accuracy: Vec<(f64, Option<f64>, Option<u32>)>,
    /// The same thresholds with the linear-stage time and the largest basis.
    pub accuracy: Vec<Accuracy>,
}

/// Solves the reference and runs LATIN (with the scene's solver settings), measuring the error at
/// every iteration. A reference that fails at a time step is not an error here: the LATIN run is
/// made and reported without errors against it, and the returned [`ReferenceRun`] holds the
/// failure and the steps solved.
/// `stop_at` as in [`build_reports`].
pub fn build_report(
    scene: &LoadedScene,
    run_id: &str,
    stop_at: Option<f64>,
) -> crate::Result<(Report, ReferenceRun, RunResult)> {
    build_report_with(scene, run_id, stop_at, &ReferenceOptions::default())
}

/// The reference's steps ([`glissade_reference::solve_reference_steps`]) with a progress line on
/// the terminal: time points solved, of how many, and the last one's Newton iterations (drawn
/// only where stderr is a terminal).
pub fn reference_with_progress(
    model: &glissade_mechanics::model::Model,
    opts: &ReferenceOptions,
) -> std::result::Result<ReferenceRun, glissade_reference::ReferenceError> {
    let bar = indicatif::ProgressBar::new(model.time.n_points() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} [{elapsed}] reference: time point {pos}/{len}  {msg}")
            .expect("valid template"),
    );
    let run = solve_reference_watched(model, opts, &mut |s| {
        bar.set_position(s.solved as u64);
        bar.set_message(format!("{} Newton iterations at the last", s.newton_iterations));
    });
    bar.finish_and_clear();
    run
}

/// [`build_report`] with the reference solved with `reference_options`.
pub fn build_report_with(
    scene: &LoadedScene,
    run_id: &str,
    stop_at: Option<f64>,
    reference_options: &ReferenceOptions,
) -> crate::Result<(Report, ReferenceRun, RunResult)> {
    let t0 = Instant::now();
    let reference = reference_with_progress(&scene.model, reference_options)?;
    let reference_s = t0.elapsed().as_secs_f64();
    let (report, result) = report_against(scene, run_id, &reference, reference_s, stop_at)?;
    Ok((report, reference, result))
}

/// A solver variant of a report comparison: a linear stage and, if given, an acceleration and a
/// start that replace the scene's
/// (`glissade report --variants condensed,condensed+anderson,condensed+anderson+start10,pgd+anderson`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Variant {
    pub stage: LinearStage,
    pub acceleration: Option<Acceleration>,
    pub start: StartChoice,
    /// PGD settings that replace the scene's (only with the PGD stage).
    pub pgd: PgdOverrides,
}

/// PGD settings a report variant sets (`+xi1=…`, `+xi2=…`, `+criterion=…`, `+max_new_modes=…`);
/// None keeps the scene's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PgdOverrides {
    pub xi1: Option<f64>,
    pub xi2: Option<f64>,
    pub criterion: Option<PgdCriterion>,
    pub max_new_modes: Option<usize>,
}

impl PgdOverrides {
    fn is_empty(&self) -> bool {
        *self == Self::default()
    }

    /// Reads one `key=value` part of a variant name into these settings.
    fn set(&mut self, part: &str, key: &str, value: &str) -> Result<(), String> {
        let twice = || format!("`+{part}`: {key} is given twice");
        match key {
            "xi1" | "xi2" => {
                let x = value
                    .parse::<f64>()
                    .ok()
                    .filter(|x| *x > 0.0 && x.is_finite())
                    .ok_or_else(|| format!("`+{part}`: ξ₀ must be a number > 0 (e.g. +{key}=0.1)"))?;
                let slot = if key == "xi1" { &mut self.xi1 } else { &mut self.xi2 };
                if slot.replace(x).is_some() {
                    return Err(twice());
                }
            }
            "criterion" => {
                let c = PgdCriterion::ALL
                    .into_iter()
                    .find(|c| c.key() == value)
                    .ok_or_else(|| {
                        let names: Vec<&str> = PgdCriterion::ALL.iter().map(|c| c.key()).collect();
                        format!("`+{part}`: the criterion is one of {}", names.join(", "))
                    })?;
                if self.criterion.replace(c).is_some() {
                    return Err(twice());
                }
            }
            "max_new_modes" => {
                let m = value
                    .parse::<usize>()
                    .ok()
                    .filter(|m| *m >= 1)
                    .ok_or_else(|| format!("`+{part}`: max_new_modes must be an integer ≥ 1"))?;
                if self.max_new_modes.replace(m).is_some() {
                    return Err(twice());
                }
            }
            _ => {
                return Err(format!(
                    "`+{part}`: `{key}` is not a PGD setting of a variant (xi1, xi2, criterion, max_new_modes)"
                ))
            }
        }
        Ok(())
    }
}

/// Where a report variant's iteration starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartChoice {
    /// As the scene says (`solver.time_coarsening` or ŝ = 0).
    Scene,
    /// From ŝ = 0 whatever the scene says (`+zero`).
    Zero,
    /// A time-coarse start on every c-th time point (`+start<c>`), at the scene's
    /// `time_coarsening_tolerance` if it has one, else the default.
    Coarse(usize),
}

impl From<LinearStage> for Variant {
    fn from(stage: LinearStage) -> Self {
        Self {
            stage,
            acceleration: None,
            start: StartChoice::Scene,
            pgd: PgdOverrides::default(),
        }
    }
}

impl std::str::FromStr for Variant {
    type Err = String;

    /// `<stage>` followed by any of `+anderson` / `+plain` and `+start<c>` / `+zero` (stage:
    /// condensed, sparse, pgd, auto); `+anderson` uses the scene's window if it has one, else
    /// the default window. The PGD stage also takes `+xi1=<ξ₀,₁>`, `+xi2=<ξ₀,₂>`,
    /// `+criterion=<name>` and `+max_new_modes=<m>` (`[solver.pgd]`'s keys), e.g.
    /// `pgd+anderson+criterion=forcing+xi1=0.3`.
    fn from_str(name: &str) -> Result<Self, String> {
        let mut parts = name.split('+');
        let stage = parts.next().unwrap_or_default();
        let Some(stage) = LinearStage::ALL.into_iter().find(|s| s.key() == stage) else {
            return Err(format!(
                "`{stage}` is not a linear stage (condensed, sparse, pgd, auto)"
            ));
        };
        let mut v = Self::from(stage);
        for part in parts {
            let (accel, start) = (v.acceleration.is_some(), v.start != StartChoice::Scene);
            match part {
                "plain" | "anderson" if accel => return Err(format!("`{name}` names two accelerations")),
                "plain" => v.acceleration = Some(Acceleration::None),
                "anderson" => {
                    v.acceleration = Some(Acceleration::Anderson {
                        window: glissade_scene::DEFAULT_ANDERSON_WINDOW,
                    })
                }
                p if start && (p == "zero" || p.starts_with("start")) => {
                    return Err(format!("`{name}` names two starts"))
                }
                "zero" => v.start = StartChoice::Zero,
                p if p.contains('=') => {
                    let (key, value) = p.split_once('=').expect("the arm's guard: p contains '='");
                    v.pgd.set(p, key, value)?
                }
                p if p.starts_with("start") => match p["start".len()..].parse::<usize>() {
                    Ok(c) if c >= 2 => v.start = StartChoice::Coarse(c),
                    _ => {
                        return Err(format!(
                            "`+{p}`: a time-coarse start is `+start<c>` with an integer c ≥ 2 (e.g. +start10)"
                        ))
                    }
                },
                other => {
                    return Err(format!(
                        "`+{other}` is neither an acceleration (+anderson, +plain) nor a start (+start<c>, +zero)"
                    ))
                }
            }
        }
        if !v.pgd.is_empty() && v.stage != LinearStage::Pgd {
            return Err(format!(
                "`{name}`: xi1, xi2, criterion and max_new_modes are PGD settings, for the pgd stage only"
            ));
        }
        Ok(v)
    }
}

/// `scene` with a variant's linear stage, acceleration and start; an error names a start the
/// scene cannot take (c must divide N; not with the PGD stage, as `solver.time_coarsening`).
pub fn variant_scene(scene: &LoadedScene, v: &Variant) -> crate::Result<LoadedScene> {
    let mut sc = scene.clone();
    sc.linear_stage = v.stage;
    match (v.acceleration, scene.model.solver.acceleration) {
        (Some(Acceleration::Anderson { .. }), Acceleration::Anderson { .. }) | (None, _) => {}
        (Some(a), _) => sc.model.solver.acceleration = a,
    }
    let o = &v.pgd;
    let pgd = &mut sc.pgd;
    pgd.xi1 = o.xi1.unwrap_or(pgd.xi1);
    pgd.xi2 = o.xi2.unwrap_or(pgd.xi2);
    pgd.criterion = o.criterion.unwrap_or(pgd.criterion);
    pgd.max_new_modes = o.max_new_modes.unwrap_or(pgd.max_new_modes);
    let solver = &mut sc.model.solver;
    match v.start {
        StartChoice::Scene => {}
        StartChoice::Zero => solver.time_start = None,
        StartChoice::Coarse(c) => {
            let n = sc.model.time.n_steps;
            if !n.is_multiple_of(c) {
                return Err(crate::Error::Option {
                    option: format!("+start{c}"),
                    why: format!("{c} does not divide the scene's N = {n}"),
                });
            }
            solver.time_start = Some(TimeStart {
                coarsening: c,
                tolerance: solver.time_start.map_or(DEFAULT_TIME_START_TOLERANCE, |t| t.tolerance),
            });
        }
    }
    if sc.model.solver.time_start.is_some() && v.stage == LinearStage::Pgd {
        return Err(crate::Error::Option {
            option: "+start".into(),
            why: "a time-coarse start does not go with the PGD stage (use +zero, or another stage)".into(),
        });
    }
    Ok(sc)
}

/// One report per variant against one reference solve (back to back in one process, so their
/// times compare on a shared machine). With `stop_at`, each variant stops at the first iteration
/// whose contact-traction error is at most that (the accuracies below it are then not reached).
/// Every variant is checked before the reference is solved. A reference that fails at a time
/// step is reported as in [`build_report`].
pub fn build_reports(
    scene: &LoadedScene,
    run_id: &str,
    variants: &[Variant],
    stop_at: Option<f64>,
) -> crate::Result<(Vec<Report>, ReferenceRun)> {
    build_reports_with(scene, run_id, variants, stop_at, &ReferenceOptions::default())
}

/// [`build_reports`] with the reference solved with `reference_options`.
pub fn build_reports_with(
    scene: &LoadedScene,
    run_id: &str,
    variants: &[Variant],
    stop_at: Option<f64>,
    reference_options: &ReferenceOptions,
) -> crate::Result<(Vec<Report>, ReferenceRun)> {
    let scenes = variants
        .iter()
        .map(|v| variant_scene(scene, v))
        .collect::<crate::Result<Vec<_>>>()?;
    let t0 = Instant::now();
    let reference = reference_with_progress(&scene.model, reference_options)?;
    let reference_s = t0.elapsed().as_secs_f64();
    let mut reports = Vec::with_capacity(variants.len());
    for sc in &scenes {
        reports.push(report_against(sc, run_id, &reference, reference_s, stop_at)?.0);
    }
    Ok((reports, reference))
}

/// The variant a report ran: its linear stage, its acceleration if any, and its start if not
/// from ŝ = 0.
pub fn variant_name(report: &Report) -> String {
    let mut name = report.linear_stage.clone();
    if report.acceleration != "none" {
        name += &format!(" + {}", report.acceleration);
    }
    if report.start != ZERO_START {
        name += &format!(" + {}", report.start);
    }
    name
}

/// [`Report::start`] of a run from ŝ = 0.
const ZERO_START: &str = "from ŝ = 0";

/// A run's start as a report names it.
fn start_name(model: &glissade_mechanics::model::Model) -> String {
    match model.solver.time_start {
        None => ZERO_START.into(),
        Some(t) => format!("time-coarse start (c = {}, η ≤ {:e})", t.coarsening, t.tolerance),
    }
}

/// The LATIN run of `scene` measured against the reference if it solved every time point.
pub fn report_against(
    scene: &LoadedScene,
    run_id: &str,
    reference: &ReferenceRun,
    reference_s: f64,
    stop_at: Option<f64>,
) -> crate::Result<(Report, RunResult)> {
    let model = &scene.model;
    let solved = reference.solution.newton_iterations.len();
    let compared = compared_time_points(model, reference);
    let complete = (compared > 0).then_some(&reference.solution);
    let mut tracker = ReferenceErrors::over(model, compared.max(1));
    let mut errors: Vec<(u32, ErrorsAgainstReference)> = Vec::new();
    let mut anderson = AndersonTally::default();
    let mut bytes: Vec<u64> = Vec::new();
    let mut states = BoundaryStates::new(model);
    let mut undecodable: Option<String> = None;
    let opts = RunOptions::new(run_id);
    // The smallest traction error measured so far (the observer sets it, the decisions read it).
    let best = Cell::new(f64::INFINITY);
    let outcome = Run::new(scene, &opts)
        .until(|_| stop_at.is_none_or(|e| best.get() > e))
        .observe(|m| {
            let t = Instant::now();
            if !matches!(m.envelope.stage, Stage::Setup | Stage::Final) {
                let it = m.envelope.iteration as usize;
                if bytes.len() <= it {
                    bytes.resize(it + 1, 0);
                }
                bytes[it] += encode(m).len() as u64;
            }
            anderson.observe(m);
            let state = match states.fields(m) {
                Some(Err(e)) => {
                    undecodable.get_or_insert(e);
                    None
                }
                other => other.and_then(Result::ok),
            };
            if let (Some((subdomain, w, f)), Some(reference)) = (state, complete) {
                if let Some(e) = tracker.boundary_state(
                    &model.interfaces,
                    subdomain as usize,
                    view(&w),
                    view(&f),
                    &reference.interfaces,
                ) {
                    errors.push((m.envelope.iteration, e));
                    best.set(best.get().min(e.traction));
                }
            }
            t.elapsed()
        })
        .linear_stages()
        .in_process()?;
    let (result, records) = (outcome.result, outcome.linear_stages);
    if let Some(e) = undecodable {
        return Err(crate::Error::Failed(format!(
            "the run's own boundary state could not be read: {e}"
        )));
    }
    let points = report_points(&result, &records, complete.is_some().then_some(&errors[..]), &bytes);
    let accuracy = accuracies(&points, result.setup_s, &records);
    let time_to_accuracy = accuracy.iter().map(|a| (a.threshold, a.wall_s, a.iterations)).collect();
    let report = Report {
        scene: model.name.clone(),
        scene_fingerprint: format!("{:016x}", scene.fingerprint),
        software_version: env!("CARGO_PKG_VERSION").to_string(),
        build_profile: if cfg!(debug_assertions) { "debug" } else { "release" }.to_string(),
        cores: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        reference_s,
        reference_newton_iterations: reference.solution.newton_iterations.iter().sum(),
        reference_max_newton_per_step: reference.solution.newton_iterations.iter().copied().max().unwrap_or(0),
        reference_failure: reference.failure.as_ref().map(ToString::to_string),
        reference_steps_solved: solved,
        errors_over_time_points: compared,
        latin_setup_s: result.setup_s,
        latin_solve_s: result.solve_s,
        latin_verdict: match (result.verdict.clone(), stop_at) {
            (Verdict::Continue, Some(e)) => format!("stopped at a traction error ≤ {e:e}"),
            (v, _) => format!("{v:?}"),
        },
        acceleration: acceleration_name(model.solver.acceleration),
        // A plain step is a safeguarded one or one taken before any difference was stored.
        anderson_steps: [
            anderson.mixed,
            anderson.safeguarded + anderson.unmixed,
            anderson.restarted,
        ],
        linear_stage: linear_stage_name(scene),
        start: start_name(model),
        points,
        time_to_accuracy,
        accuracy,
    };
    Ok((report, result))
}

/// The time points a report compares: every one of a reference that solved them all, or the
/// ones a failed reference solved where they are at least two (time point 0 alone has no load);
/// else none.
fn compared_time_points(model: &glissade_mechanics::model::Model, reference: &ReferenceRun) -> usize {
    let solved = reference.solution.newton_iterations.len();
    if reference.failure.is_none() {
        model.time.n_points()
    } else if solved >= 2 {
        solved
    } else {
        0
    }
}

/// The acceleration as a report names it.
fn acceleration_name(a: Acceleration) -> String {
    match a {
        Acceleration::None => "none".into(),
        Acceleration::Anderson { window } => format!("anderson({window})"),
    }
}

/// One report point per iteration of `result` with the errors of that iteration against the
/// reference (`errors`, by iteration; None: NaN errors, the reference solved too few time
/// points), its linear stages' time, operations and PGD basis sizes (`records`) and its bus
/// bytes.
fn report_points(
    result: &RunResult,
    records: &[LinearStageRecord],
    errors: Option<&[(u32, ErrorsAgainstReference)]>,
    bytes: &[u64],
) -> Vec<ReportPoint> {
    let pgd = records.iter().any(|r| r.modes > 0);
    result
        .iterations
        .iter()
        .filter_map(|r| {
            let (e_f, e_w, e_max) = match errors {
                Some(errors) => errors
                    .iter()
                    .find(|e| e.0 == r.iteration)
                    .map(|(_, e)| (e.traction, e.jump, e.pointwise))?,
                None => (
                    f64::NAN,
                    f64::NAN,
                    PointwiseError {
                        error: f64::NAN,
                        ..Default::default()
                    },
                ),
            };
            let of_it = || records.iter().filter(|x| x.iteration == r.iteration);
            Some(ReportPoint {
                iteration: r.iteration,
                elapsed_s: r.elapsed_s,
                eta: r.decision.eta,
                contact_indicator: r.decision.contact_indicator,
                traction_error: e_f,
                jump_error: e_w,
                pointwise_error: e_max.error,
                pointwise_at: [e_max.interface, e_max.pair, e_max.time_point],
                estimate: r.decision.estimate,
                contraction: r.decision.contraction,
                pointwise_estimate: r.decision.pointwise_estimate,
                force_step: r.decision.force_step,
                linear_s: of_it().map(|x| x.seconds).sum(),
                linear_flops: of_it().map(|x| x.flops).sum(),
                bus_bytes: bytes.get(r.iteration as usize).copied().unwrap_or(0),
                basis_sizes: if pgd {
                    of_it().map(|x| x.modes).collect()
                } else {
                    Vec::new()
                },
            })
        })
        .collect()
}

/// Time, iterations, linear-stage time and operations and the largest PGD basis to each traction
/// error of 1e-2, 1e-3, 1e-4 (None where never reached); `setup_s` is the operators' set-up.
fn accuracies(points: &[ReportPoint], setup_s: f64, records: &[LinearStageRecord]) -> Vec<Accuracy> {
    // Linear stages before the first reported iteration (the initial one from ŝ = 0) count too.
    let first = points.first().map_or(0, |p| p.iteration);
    let linear_before: f64 = records.iter().filter(|x| x.iteration < first).map(|x| x.seconds).sum();
    let flops_before: u64 = records.iter().filter(|x| x.iteration < first).map(|x| x.flops).sum();
    [1e-2, 1e-3, 1e-4]
        .iter()
        .map(|&th| {
            let hit = points.iter().position(|p| p.traction_error <= th);
            let upto = |k: usize| &points[..=k];
            Accuracy {
                threshold: th,
                wall_s: hit.map(|k| setup_s + points[k].elapsed_s),
                iterations: hit.map(|k| points[k].iteration),
                linear_s: hit.map(|k| linear_before + upto(k).iter().map(|p| p.linear_s).sum::<f64>()),
                linear_flops: hit.map(|k| flops_before + upto(k).iter().map(|p| p.linear_flops).sum::<u64>()),
                max_basis: hit.map(|k| {
                    upto(k)
                        .iter()
                        .flat_map(|p| p.basis_sizes.iter().copied())
                        .max()
                        .unwrap_or(0)
                }),
            }
        })
        .collect()
}

/// The scene's linear stage as the report names it.
pub fn linear_stage_name(scene: &LoadedScene) -> String {
    match scene.linear_stage {
        s @ (LinearStage::Condensed | LinearStage::Sparse | LinearStage::Auto) => s.key().into(),
        LinearStage::Pgd => {
            let p = &scene.pgd;
            format!(
                "pgd({}, ξ₀ = {}/{}, macro modes {}{})",
                p.criterion.key(),
                p.xi1,
                p.xi2,
                if p.macro_modes { "on" } else { "off" },
                if p.max_new_modes == 1 {
                    String::new()
                } else {
                    format!(", ≤ {} new modes", p.max_new_modes)
                }
            )
        }
    }
}

/// Reports of several variants side by side, as two Markdown tables with a row per variant and a
/// column per accuracy (readable in a terminal however many variants there are): iterations and
/// LATIN wall time to each accuracy, then the linear stage's time and GFLOP (10⁹ floating-point
/// operations, summed over subdomains and iterations) to each; then per variant the largest
/// basis, bus bytes, the linear stage's flops per iteration and its rate (flops over linear-stage
/// wall time).
pub fn comparison_table(reports: &[Report]) -> String {
    let thresholds: Vec<f64> = reports
        .first()
        .map_or_else(Vec::new, |r| r.accuracy.iter().map(|a| a.threshold).collect());
    let header = |what: &str| {
        let mut h = format!("| {what} |");
        for t in &thresholds {
            h += &format!(" {t:.0e} |");
        }
        h += "\n|---|";
        h += &"---|".repeat(thresholds.len());
        h + "\n"
    };
    let mut out = header("contact traction error: iterations, LATIN wall time (s)");
    for r in reports {
        out += &format!("| {} |", variant_name(r));
        for a in &r.accuracy {
            match (a.iterations, a.wall_s) {
                (Some(it), Some(t)) => out += &format!(" {it} it, {t:.2} s |"),
                _ => {
                    let best = r.points.iter().map(|p| p.traction_error).fold(f64::INFINITY, f64::min);
                    out += &format!(" not reached (best {best:.1e} in {} iterations) |", r.points.len());
                }
            }
        }
        out += "\n";
    }
    out += "\n";
    out += &header("linear stage to that error: time (s), GFLOP");
    for r in reports {
        out += &format!("| {} |", variant_name(r));
        for a in &r.accuracy {
            match (a.linear_s, a.linear_flops) {
                (Some(l), Some(fl)) => out += &format!(" {l:.2} s, {:.3} GFLOP |", fl as f64 * 1e-9),
                _ => out += " |",
            }
        }
        out += "\n";
    }
    out += "\n";
    for r in reports {
        let n = r.points.len().max(1) as f64;
        let bytes: u64 = r.points.iter().map(|p| p.bus_bytes).sum();
        let basis = r.points.iter().flat_map(|p| p.basis_sizes.iter().copied()).max();
        let flops: u64 = r.points.iter().map(|p| p.linear_flops).sum();
        let linear_s: f64 = r.points.iter().map(|p| p.linear_s).sum();
        out += &format!(
            "{}: setup {:.2} s, {} iterations in {:.2} s ({}), largest basis {}, bus bytes per iteration {:.0}, linear stage {:.4} GFLOP per iteration at {} GFLOP/s ({} build)\n",
            variant_name(r),
            r.latin_setup_s,
            r.points.len(),
            r.latin_solve_s,
            r.latin_verdict,
            basis.map_or("-".to_string(), |b| b.to_string()),
            bytes as f64 / n,
            flops as f64 * 1e-9 / n,
            gflops_per_s(flops, linear_s).map_or("-".to_string(), |g| format!("{g:.2}")),
            r.build_profile
        );
    }
    out
}

/// Floating-point operations per second in units of 10⁹, None without a measured time.
pub fn gflops_per_s(flops: u64, seconds: f64) -> Option<f64> {
    (seconds > 0.0).then(|| flops as f64 * 1e-9 / seconds)
}

/// The linear stage's cost to each accuracy (Markdown table) and the bus bytes per iteration.
pub fn linear_stage_table(report: &Report) -> String {
    let mut out = format!("linear stage: {}\n", report.linear_stage);
    out += "| contact traction error | iterations | LATIN wall time (s) | linear-stage time, summed over subdomains (s) | largest basis |\n|---|---|---|---|---|\n";
    for a in &report.accuracy {
        match (a.wall_s, a.iterations, a.linear_s, a.max_basis) {
            (Some(t), Some(it), Some(l), Some(b)) => {
                out += &format!("| {:.0e} | {it} | {t:.2} | {l:.2} | {b} |\n", a.threshold)
            }
            _ => {
                let best = report
                    .points
                    .iter()
                    .map(|p| p.traction_error)
                    .fold(f64::INFINITY, f64::min);
                out += &format!("| {:.0e} | not reached (best {best:.1e}) | | | |\n", a.threshold)
            }
        }
    }
    let n = report.points.len().max(1) as f64;
    let bytes: u64 = report.points.iter().map(|p| p.bus_bytes).sum();
    out += &format!("bus bytes per iteration (mean): {:.0}\n", bytes as f64 / n);
    out
}

#[cfg(test)]
mod tests {
    use super::{linear_ticks, log_ticks, PgdOverrides, Variant};
    use glissade_mechanics::linear::LinearStage;
    use glissade_mechanics::pgd::PgdCriterion;

    /// PGD settings as variants: parsed, and bad values or misplaced keys rejected with the part
    /// and what it must be.
    #[test]
    fn pgd_variants_parse_and_reject_bad_values() {
        let v: Variant = "pgd+anderson+criterion=forcing+xi1=0.3+xi2=0.02+max_new_modes=3"
            .parse()
            .unwrap();
        assert_eq!(v.stage, LinearStage::Pgd);
        assert!(v.acceleration.is_some());
        assert_eq!(
            v.pgd,
            PgdOverrides {
                xi1: Some(0.3),
                xi2: Some(0.02),
                criterion: Some(PgdCriterion::Forcing),
                max_new_modes: Some(3),
            }
        );
        let err = |name: &str| name.parse::<Variant>().unwrap_err();
        for (name, part) in [
            ("pgd+xi1=0", "ξ₀ must be a number > 0"),
            ("pgd+xi2=-1", "ξ₀ must be a number > 0"),
            ("pgd+xi1=abc", "`+xi1=abc`"),
            ("pgd+xi1=inf", "ξ₀ must be a number > 0"),
            (
                "pgd+criterion=forced",
                "increment, accumulated, increment-svd, forcing, forcing-svd",
            ),
            ("pgd+max_new_modes=0", "an integer ≥ 1"),
            ("pgd+xi1=0.1+xi1=0.2", "given twice"),
            ("pgd+xi3=0.1", "`xi3` is not a PGD setting"),
            ("condensed+xi1=0.1", "for the pgd stage only"),
        ] {
            let e = err(name);
            assert!(e.contains(part), "{name}: `{part}` not in: {e}");
        }
    }

    /// A reference far slower than LATIN does not squeeze LATIN's curves: the time axis spans
    /// LATIN's run, and the reference's time is named at its right edge; where it fits, it is
    /// marked at its place. The pointwise error and estimate are drawn.
    #[test]
    fn the_time_axis_spans_latin_and_names_a_slower_reference() {
        use super::{plot_svg, Report, ReportPoint, TimeAxis};
        let point = |k: u32| ReportPoint {
            iteration: k,
            elapsed_s: 0.1 * (k + 1) as f64,
            eta: 0.5f64.powi(k as i32),
            contact_indicator: 0.5f64.powi(k as i32),
            traction_error: 0.4f64.powi(k as i32),
            jump_error: 0.4f64.powi(k as i32),
            pointwise_error: 0.45f64.powi(k as i32),
            pointwise_at: [0, 0, 0],
            estimate: Some(0.5f64.powi(k as i32)),
            contraction: Some(0.5),
            pointwise_estimate: Some(0.6f64.powi(k as i32)),
            force_step: 0.5f64.powi(k as i32),
            linear_s: 0.05,
            linear_flops: 0,
            bus_bytes: 0,
            basis_sizes: Vec::new(),
        };
        let report = |reference_s: f64| Report {
            scene: "s".into(),
            scene_fingerprint: String::new(),
            software_version: String::new(),
            build_profile: String::new(),
            cores: 1,
            reference_s,
            reference_newton_iterations: 0,
            reference_max_newton_per_step: 0,
            reference_failure: None,
            reference_steps_solved: 1,
            errors_over_time_points: 0,
            latin_setup_s: 0.0,
            latin_solve_s: 1.0,
            latin_verdict: String::new(),
            acceleration: String::new(),
            anderson_steps: [0; 3],
            linear_stage: String::new(),
            start: String::new(),
            points: (0..10).map(point).collect(),
            time_to_accuracy: Vec::new(),
            accuracy: Vec::new(),
        };
        // LATIN ends at 1.0 s: the last point sits at 1/1.05 of the axis (left 80, width 590)
        // whether the reference took 100 s or 0.5 s.
        let last_x = format!("{:.2},", 80.0 + 590.0 / 1.05);
        let slow = plot_svg(&report(100.0), TimeAxis::Linear);
        assert!(slow.contains(&last_x), "{slow}");
        assert!(slow.contains("100.00 s (beyond this axis)"), "{slow}");
        let fast = plot_svg(&report(0.5), TimeAxis::Linear);
        assert!(fast.contains(&last_x) && fast.contains("0.50 s</text>"), "{fast}");
        assert!(slow.contains("largest at a point vs reference") && slow.contains("estimated largest at a point"));
    }

    /// Tick labels are distinct and cover the axis: 0.0137 s used to give 0.00, 0.00, 0.01, ….
    #[test]
    fn tick_labels_are_unique_and_round() {
        for max in [0.0137, 0.9, 1.0, 7.3, 12.5, 260.0, 1.0e4] {
            let ticks = linear_ticks(max);
            let labels: Vec<&str> = ticks.iter().map(|(_, l)| l.as_str()).collect();
            let mut unique = labels.clone();
            unique.dedup();
            assert_eq!(unique, labels, "max {max}: {labels:?}");
            assert!((3..=11).contains(&ticks.len()), "max {max}: {labels:?}");
            assert!(
                ticks.last().unwrap().0 <= max && ticks.last().unwrap().0 >= max / 2.5,
                "max {max}: {labels:?}"
            );
        }
        assert_eq!(
            linear_ticks(0.0137).iter().map(|(_, l)| l.as_str()).collect::<Vec<_>>(),
            ["0.000", "0.005", "0.010"]
        );
        assert_eq!(
            log_ticks(0.05, 20.0)
                .iter()
                .map(|(_, l)| l.as_str())
                .collect::<Vec<_>>(),
            ["1e-1", "1e0", "1e1"]
        );
    }
}
