//! The stability matrix (`glissade stability`, issue 8): a set of stiff and extreme cases, each
//! built from a small base scene text varied by the case, run in-process with the LATIN solver
//! and, where it can be computed, compared with the monolithic Newton reference
//! ([`solve_reference`]) of the same discrete problem. Every case states what it expects:
//! convergence within a tolerance on η and on the contact traction error against the
//! reference, or a stop with a named diagnosis (max iterations, stagnation, divergence, a scene
//! rejected at validation).
//!
//! Every case runs with η ≤ [`ETA_TOLERANCE`] (unless it states another) and at
//! most [`MAX_ITERATIONS`] iterations; errors against the reference are those of LATIN's s
//! ([`error_against_reference`]: relative space-time norms on contact interfaces). Panics are
//! caught per case and reported as such; non-finite values are flagged per case.
//!
//! Every case runs twice, as stated (plain relaxation) and with Anderson acceleration
//! ([`Case::accelerated`]), against one reference: the row says what acceleration did to the
//! outcome ([`AccelerationEffect`]) and how many Anderson steps were mixed, safeguarded and
//! restarted ([`AndersonTally`]).
//!
//! `glissade stability` runs the whole matrix (most of its time goes to steps-10000 and the thin
//! layers); `--quick` leaves out the [`SLOW`] cases and is what `tests/it/stability.rs` runs.

use crate::run::Run;
use crate::runner::{AndersonTally, RunOptions};
use glissade_mechanics::local::{error_against_reference, InterfaceFields};
use glissade_mechanics::model::Model;
use glissade_messages::Verdict;
use glissade_reference::solve_reference;
use glissade_scene::{load_str, LoadedScene};
use serde::Serialize;
use std::fmt::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

mod cases;
pub use cases::*;

/// Outcome of a case.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Outcome {
    Converged,
    MaxIterations,
    Stagnated {
        detail: String,
    },
    Diverged {
        detail: String,
    },
    /// The loads exceed what friction and the supports hold (the run's `NoEquilibrium`).
    NoEquilibrium {
        detail: String,
    },
    Rejected {
        reason: String,
    },
    /// The run could not be built or failed (not a LATIN verdict).
    Error {
        detail: String,
    },
    /// The case panicked (a bug).
    Panicked {
        detail: String,
    },
}

impl Outcome {
    /// Short name of the outcome.
    pub fn kind(&self) -> &'static str {
        match self {
            Outcome::Converged => "converged",
            Outcome::MaxIterations => "max_iterations",
            Outcome::Stagnated { .. } => "stagnated",
            Outcome::Diverged { .. } => "diverged",
            Outcome::NoEquilibrium { .. } => "no_equilibrium",
            Outcome::Rejected { .. } => "rejected",
            Outcome::Error { .. } => "error",
            Outcome::Panicked { .. } => "panicked",
        }
    }

    /// The detail of a stop ("" for converged and max iterations).
    pub fn detail(&self) -> &str {
        match self {
            Outcome::Converged | Outcome::MaxIterations => "",
            Outcome::Stagnated { detail }
            | Outcome::Diverged { detail }
            | Outcome::NoEquilibrium { detail }
            | Outcome::Error { detail }
            | Outcome::Panicked { detail } => detail,
            Outcome::Rejected { reason } => reason,
        }
    }

    fn text(&self) -> String {
        match self {
            Outcome::Converged => "converged".into(),
            Outcome::MaxIterations => "stopped: max iterations".into(),
            Outcome::Stagnated { detail } => format!("stopped: stagnation ({detail})"),
            Outcome::Diverged { detail } => format!("stopped: divergence ({detail})"),
            Outcome::NoEquilibrium { detail } => format!("stopped: no equilibrium ({detail})"),
            Outcome::Rejected { reason } => format!("rejected at validation: {reason}"),
            Outcome::Error { detail } => format!("error: {detail}"),
            Outcome::Panicked { detail } => format!("PANIC: {detail}"),
        }
    }
}

/// How a case's outcome compares with what it expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Assessment {
    /// Converged within the stated tolerances, or stopped or rejected as expected.
    AsExpected,
    Unexpected,
}

/// One LATIN run of a case (plain or accelerated).
#[derive(Debug, Clone, Serialize)]
pub struct RunRow {
    pub iterations: Option<usize>,
    pub eta: Option<f64>,
    pub contact_indicator: Option<f64>,
    /// Relative contact traction (e_F) and jump (e_W) errors of LATIN's s against the reference
    /// ([`error_against_reference`]); the traction error is `None` where the reference's contact
    /// tractions are all zero.
    pub traction_error: Option<f64>,
    pub jump_error: Option<f64>,
    /// LATIN wall time, operator setup included (s).
    pub latin_s: Option<f64>,
    /// Contact points per reported status (separated, stick, slip, limit, grazing) at the last
    /// time point, at the stop.
    pub final_counts: Option<[u64; 5]>,
    /// Iteration of the first search-direction update, if any.
    pub first_direction_update: Option<u32>,
    /// The Anderson steps of an accelerated run (`None` for the plain run).
    pub anderson_steps: Option<AndersonTally>,
    pub outcome: Outcome,
    /// Every interface field of the run (and of the reference), and every error and time, is finite.
    pub fields_finite: bool,
    /// Every indicator of every iteration (η, e_c, e_F, e_W) is finite.
    pub indicators_finite: bool,
}

impl RunRow {
    fn new() -> Self {
        Self {
            iterations: None,
            eta: None,
            contact_indicator: None,
            traction_error: None,
            jump_error: None,
            latin_s: None,
            final_counts: None,
            first_direction_update: None,
            anderson_steps: None,
            outcome: Outcome::Converged,
            fields_finite: true,
            indicators_finite: true,
        }
    }

    /// Converged to η ≤ `tolerance` with finite values and, where compared with a reference, a
    /// contact traction error ≤ `error` (the jump error where the reference's contact tractions
    /// are all zero).
    pub fn reaches(&self, tolerance: Option<f64>, error: f64) -> bool {
        self.fields_finite
            && self.indicators_finite
            && self.outcome == Outcome::Converged
            && self.eta.zip(tolerance).is_none_or(|(e, t)| e <= t)
            && self.traction_error.or(self.jump_error).is_none_or(|e| e <= error)
    }
}

/// What Anderson acceleration does to a case's outcome, against the plain run (both judged by
/// [`RunRow::reaches`] with the case's error bound, [`ERROR_TOLERANCE`] for the cases expected to
/// stop).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AccelerationEffect {
    /// The same outcome: both reach the reference, or both stop the same way (or are rejected).
    Kept,
    /// The plain run does not reach the reference, the accelerated one does.
    Improved,
    /// Neither reaches the reference, and they stop differently.
    Changed,
    /// The plain run reaches the reference and the accelerated one does not: what the safeguard
    /// must prevent.
    Broke,
}

impl AccelerationEffect {
    fn of(plain: &RunRow, anderson: &RunRow, tolerance: Option<f64>, error: f64) -> Self {
        match (plain.reaches(tolerance, error), anderson.reaches(tolerance, error)) {
            (true, true) => Self::Kept,
            (true, false) => Self::Broke,
            (false, true) => Self::Improved,
            (false, false) if plain.outcome.kind() == anderson.outcome.kind() => Self::Kept,
            (false, false) => Self::Changed,
        }
    }

    /// Short name.
    pub fn kind(self) -> &'static str {
        match self {
            Self::Kept => "kept",
            Self::Improved => "improved",
            Self::Changed => "changed",
            Self::Broke => "broke",
        }
    }
}

/// The result of one case: a row of the table.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    pub case: String,
    pub varies: String,
    pub expect: Expect,
    /// The scene's η tolerance (when the scene loaded).
    pub tolerance: Option<f64>,
    /// The case's scene as stated, with plain relaxation.
    pub plain: RunRow,
    /// The same scene with Anderson acceleration.
    pub anderson: RunRow,
    pub acceleration: AccelerationEffect,
    /// Why an error is missing.
    pub reference_note: Option<String>,
    pub reference_s: Option<f64>,
    /// Reference Newton iterations, all time steps.
    pub reference_newton: Option<usize>,
    /// The plain run ends as the case expects, the accelerated one neither panics nor leaves a
    /// non-finite value, and acceleration does not break a converging case.
    pub assessment: Assessment,
}

fn panic_text(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| e.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}

fn fields_finite(f: &[InterfaceFields]) -> bool {
    f.iter().all(|x| {
        [&x.w_a, &x.w_b, &x.f_a, &x.f_b]
            .iter()
            .all(|m| (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite())))
    })
}

/// Runs one case, plain and accelerated, against one reference (a panic inside a run or the
/// reference is caught and reported as [`Outcome::Panicked`]).
pub fn run_case(case: &Case) -> CaseResult {
    let (mut plain, plain_run) = latin_run(case, &case.scene, false);
    let (mut anderson, anderson_run) = latin_run(case, &case.accelerated, true);
    let mut row = CaseResult {
        case: case.name.into(),
        varies: case.varies.clone(),
        expect: case.expect.clone(),
        tolerance: plain_run.as_ref().and_then(|(sc, _)| sc.model.solver.tolerance),
        plain: RunRow::new(),
        anderson: RunRow::new(),
        acceleration: AccelerationEffect::Kept,
        reference_note: None,
        reference_s: None,
        reference_newton: None,
        assessment: Assessment::Unexpected,
    };
    match (&case.reference, plain_run.as_ref().or(anderson_run.as_ref())) {
        (None, _) => row.reference_note = Some("reference not computed for this case".into()),
        (Some(_), None) => {}
        (Some(opts), Some((sc, _))) => {
            let model = &sc.model;
            let t1 = Instant::now();
            match catch_unwind(AssertUnwindSafe(|| solve_reference(model, opts))) {
                Ok(Ok(reference)) => {
                    row.reference_s = Some(t1.elapsed().as_secs_f64());
                    row.reference_newton = Some(reference.newton_iterations.iter().sum());
                    let finite = fields_finite(&reference.interfaces);
                    for (run, fields) in [(&mut plain, &plain_run), (&mut anderson, &anderson_run)] {
                        run.fields_finite &= finite;
                        if let Some((_, fields)) = fields {
                            let note = compare(run, model, fields, &reference.interfaces);
                            row.reference_note = row.reference_note.take().or(note);
                        }
                    }
                }
                Ok(Err(e)) => row.reference_note = Some(format!("reference failed: {e}")),
                Err(e) => row.reference_note = Some(format!("reference panicked: {}", panic_text(e.as_ref()))),
            }
        }
    }
    let finite = |v: Option<f64>| v.is_none_or(f64::is_finite);
    for run in [&mut plain, &mut anderson] {
        run.fields_finite &= [run.traction_error, run.jump_error, run.latin_s, row.reference_s]
            .into_iter()
            .all(finite);
    }
    let error = match row.expect {
        Expect::Converge { error } => error,
        _ => ERROR_TOLERANCE,
    };
    row.acceleration = AccelerationEffect::of(&plain, &anderson, row.tolerance, error);
    let sound = |r: &RunRow| r.fields_finite && !matches!(r.outcome, Outcome::Panicked { .. });
    row.assessment = if assess(&row.expect, row.tolerance, &plain) == Assessment::AsExpected
        && sound(&anderson)
        && row.acceleration != AccelerationEffect::Broke
    {
        Assessment::AsExpected
    } else {
        Assessment::Unexpected
    };
    row.plain = plain;
    row.anderson = anderson;
    row
}

/// Compares a plain run's outcome with what its case expects.
fn assess(expect: &Expect, tolerance: Option<f64>, run: &RunRow) -> Assessment {
    if !run.fields_finite || matches!(run.outcome, Outcome::Panicked { .. }) {
        return Assessment::Unexpected;
    }
    let met = run.indicators_finite
        && match (expect, &run.outcome) {
            (Expect::Converge { error }, Outcome::Converged) => run.reaches(tolerance, *error),
            (Expect::Stop { outcome, .. }, o) => o.kind() == *outcome,
            (Expect::Rejected { reason }, Outcome::Rejected { reason: r }) => r.contains(reason),
            _ => false,
        };
    if met {
        Assessment::AsExpected
    } else {
        Assessment::Unexpected
    }
}

/// The loaded scene of a run and its interface fields at the stop.
type Stopped = (LoadedScene, Vec<InterfaceFields>);

/// Loads `scene` (a case's text, plain or accelerated) and runs it in-process; the fields are
/// `None` when the scene is rejected or the run fails or panics.
fn latin_run(case: &Case, scene: &str, accelerated: bool) -> (RunRow, Option<Stopped>) {
    let mut row = RunRow::new();
    let sc = match load_str(scene, &format!("{}.toml", case.name)) {
        Ok(sc) => sc,
        Err(e) => {
            row.outcome = Outcome::Rejected { reason: e.to_string() };
            return (row, None);
        }
    };
    let mut tally = accelerated.then(AndersonTally::default);
    let run_id = format!(
        "stability-{}{}",
        case.name.replace(|c: char| !c.is_ascii_alphanumeric(), "-"),
        if accelerated { "-anderson" } else { "" }
    );
    let t0 = Instant::now();
    let result = catch_unwind(AssertUnwindSafe(|| {
        Run::new(&sc, &RunOptions::new(run_id))
            .observe(|m| {
                if let Some(t) = tally.as_mut() {
                    t.observe(m);
                }
                Duration::ZERO
            })
            .in_process()
            .map(|o| o.result)
    }));
    let result = match result {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => {
            row.outcome = Outcome::Error { detail: e.to_string() };
            return (row, None);
        }
        Err(e) => {
            row.outcome = Outcome::Panicked {
                detail: panic_text(e.as_ref()),
            };
            return (row, None);
        }
    };
    row.latin_s = Some(t0.elapsed().as_secs_f64());
    row.anderson_steps = tally;
    row.iterations = Some(result.iterations.len());
    let last = result.iterations.last().map(|r| &r.decision);
    row.eta = last.map(|d| d.eta);
    row.contact_indicator = last.map(|d| d.contact_indicator);
    row.first_direction_update = result
        .iterations
        .iter()
        .find(|r| !r.decision.direction_updates.is_empty())
        .map(|r| r.iteration);
    row.indicators_finite = result.iterations.iter().all(|r| {
        let d = &r.decision;
        [d.eta, d.contact_indicator, d.force_error, d.jump_error]
            .iter()
            .all(|v| v.is_finite())
    });
    row.outcome = match &result.verdict {
        Verdict::Converged => Outcome::Converged,
        Verdict::MaxIterations | Verdict::Continue => Outcome::MaxIterations,
        Verdict::Stagnated { detail } => Outcome::Stagnated { detail: detail.clone() },
        Verdict::Diverged { detail } => Outcome::Diverged { detail: detail.clone() },
        Verdict::NoEquilibrium { detail } => Outcome::NoEquilibrium { detail: detail.clone() },
    };
    let model = &sc.model;
    let nt = model.time.n_points();
    let mut counts = [0u64; 5];
    for sol in &result.interfaces {
        let itf = &model.interfaces[sol.interface as usize];
        if itf.is_contact() {
            let np = itf.n_pairs();
            for st in &sol.status[np * (nt - 1)..] {
                if let Some(c) = counts.get_mut(*st as usize) {
                    *c += 1;
                }
            }
        }
    }
    row.final_counts = Some(counts);
    let fields = result.interface_fields();
    row.fields_finite &= fields_finite(&fields);
    (row, Some((sc, fields)))
}

/// Sets a run's errors against the reference; returns why one is missing.
fn compare(
    run: &mut RunRow,
    model: &Model,
    fields: &[InterfaceFields],
    reference: &[InterfaceFields],
) -> Option<String> {
    if fields.len() != model.interfaces.len() {
        return Some("LATIN returned no interface fields".into());
    }
    let (e_f, e_w) = error_against_reference(&model.interfaces, fields, reference, &model.time.trapezoid_weights());
    run.jump_error = e_w.is_finite().then_some(e_w);
    // A relative error against a zero reference is infinite whenever s is not exactly 0.
    if e_f.is_finite() {
        run.traction_error = Some(e_f);
        return None;
    }
    let f_max = fields
        .iter()
        .zip(&model.interfaces)
        .filter(|(_, i)| i.is_contact())
        .flat_map(|(f, _)| [&f.f_a, &f.f_b])
        .flat_map(|m| (0..m.ncols()).flat_map(move |j| (0..m.nrows()).map(move |i| m[(i, j)].abs())))
        .fold(0.0, f64::max);
    Some(format!(
        "the reference's contact tractions are all 0; max |F| of LATIN = {f_max:.1e} N/mm"
    ))
}

/// Runs every case of the matrix in order; `on_case` sees each row as it is done.
pub fn run_matrix(quick: bool, on_case: impl FnMut(&CaseResult)) -> Vec<CaseResult> {
    run_cases(&cases(quick), on_case)
}

/// Runs the given cases in order (e.g. a selection of [`cases`] by name).
pub fn run_cases(cases: &[Case], mut on_case: impl FnMut(&CaseResult)) -> Vec<CaseResult> {
    cases
        .iter()
        .map(|c| {
            let r = run_case(c);
            on_case(&r);
            r
        })
        .collect()
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("—".into(), |x| format!("{x:.prec$e}"))
}

/// The table as Markdown: the plain run's columns, then the accelerated run's and what
/// acceleration did to the outcome.
pub fn markdown(rows: &[CaseResult]) -> String {
    let mut s = String::from(
        "| case | varies | expected | iterations | final η | traction error | jump error | LATIN (s) | \
         reference (s) | sep/stick/slip/limit/grazing at t = T | outcome | Anderson: iterations | Anderson: final η | \
         Anderson: traction error | Anderson: LATIN (s) | mixed/safeguarded/restarted | acceleration |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let (p, a) = (&r.plain, &r.anderson);
        let expected = match &r.expect {
            Expect::Converge { error } => format!(
                "η ≤ {}{}",
                opt(r.tolerance, 0),
                if r.reference_s.is_some() {
                    format!(", error ≤ {error:.0e}")
                } else {
                    String::new()
                }
            ),
            Expect::Stop { outcome, .. } => format!("stop: {}", outcome.replace('_', " ")),
            Expect::Rejected { .. } => "rejected".into(),
        };
        let mut outcome = p.outcome.text();
        match (r.assessment, &r.expect) {
            (Assessment::AsExpected, Expect::Stop { why, .. }) => {
                let _ = write!(outcome, " — expected: {why}");
            }
            (Assessment::Unexpected, _) => outcome = format!("**unexpected**: {outcome}"),
            _ => {}
        }
        if let Some(n) = &r.reference_note {
            let _ = write!(outcome, " (error: {n})");
        }
        if let Some(i) = p.first_direction_update {
            let _ = write!(outcome, " (directions updated at iteration {i})");
        }
        let iterations = |run: &RunRow| run.iterations.map_or("—".into(), |n| n.to_string());
        let seconds = |run: &RunRow| run.latin_s.map_or("—".into(), |t| format!("{t:.2}"));
        let steps = a.anderson_steps.map_or("—".into(), |t| {
            format!("{}/{}/{}", t.mixed, t.safeguarded, t.restarted)
        });
        let effect = match r.acceleration {
            AccelerationEffect::Kept => match (p.iterations, a.iterations, &a.outcome) {
                (Some(n), Some(m), Outcome::Converged) => format!("kept ({n} → {m} iterations)"),
                _ => format!("kept ({})", a.outcome.kind().replace('_', " ")),
            },
            e => {
                let mut t = format!("{}: {}", e.kind(), a.outcome.text());
                if let (Outcome::Converged, Some(err)) = (&a.outcome, a.traction_error.or(a.jump_error)) {
                    let _ = write!(t, ", error {err:.1e}");
                }
                if e == AccelerationEffect::Broke {
                    t = format!("**{t}**");
                }
                t
            }
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.case,
            r.varies,
            expected,
            iterations(p),
            opt(p.eta, 2),
            opt(p.traction_error, 1),
            opt(p.jump_error, 1),
            seconds(p),
            r.reference_s.map_or("—".into(), |t| format!("{t:.2}")),
            p.final_counts.map_or("—".into(), |c| format!(
                "{}/{}/{}/{}/{}",
                c[0], c[1], c[2], c[3], c[4]
            )),
            outcome.replace('|', "\\|"),
            iterations(a),
            opt(a.eta, 2),
            match (a.traction_error, a.jump_error) {
                (None, Some(e)) => format!("jump {e:.1e}"),
                (e, _) => opt(e, 1),
            },
            seconds(a),
            steps,
            effect.replace('|', "\\|"),
        );
    }
    s
}
