//! Whether the stop on accuracy keeps its promise (docs/accuracy.md, "Stopping on accuracy"):
//! for a run followed past its stop against the monolithic reference, the iteration at which the
//! run's own estimate first reached each accuracy (where a run asking for it stops) and the true
//! contact-traction error there.

use crate::report::{report_against, Report};
use glissade_reference::{solve_reference, ReferenceOptions, ReferenceRun};
use glissade_scene::LoadedScene;
use serde::Serialize;
use std::time::Instant;

/// The accuracies checked.
pub const ACCURACIES: [f64; 3] = [1e-2, 1e-3, 1e-4];

/// Where a run asking for `accuracy` stops, and how accurate it is there.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AccuracyStop {
    pub accuracy: f64,
    /// First iteration whose estimate is at most the accuracy (None: never within the run).
    pub iteration: Option<u32>,
    pub estimate: Option<f64>,
    /// The true relative contact-traction error there, against the reference (None where it is
    /// undefined: a reference without any contact force, against which any nonzero round-off
    /// force is an infinite relative error).
    pub true_error: Option<f64>,
    /// First iteration whose true error is at most the accuracy.
    pub first_reached: Option<u32>,
}

impl AccuracyStop {
    /// The true error at the stop over the accuracy.
    pub fn ratio(&self) -> Option<f64> {
        self.true_error.map(|e| e / self.accuracy)
    }
}

/// One scene's or case's check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AccuracyCheck {
    pub name: String,
    pub stops: Vec<AccuracyStop>,
    /// Over the iterations with an estimate and a true error below 1e-2 (and above 0): how many,
    /// the share whose estimate is within a factor 3 of the true error, and the share below it.
    pub compared: usize,
    pub within_3x: f64,
    pub underestimated: f64,
    /// Every iteration's (true error, estimate, force step, contact indicator), to study the
    /// estimate offline.
    pub trace: Vec<(f64, Option<f64>, f64, f64)>,
    /// How the run followed past its stop ended (the report's `latin_verdict`).
    pub verdict: String,
}

/// The check of one report (a run followed past its stop), whose run stagnates as
/// `stagnation` = (window, ratio) says.
pub fn check_report(name: &str, report: &Report, stagnation: (usize, f64)) -> AccuracyCheck {
    use glissade_interface::stagnated;
    use glissade_mechanics::estimate::STAGNATION_AGREEMENT;
    let stops = ACCURACIES
        .iter()
        .map(|&a| {
            // Where a run asking for `a` stops: both estimates and the agreement of s and ŝ
            // within it (`StopRule::decide`).
            let at = report
                .points
                .iter()
                .find(|p| {
                    p.estimate.is_some_and(|e| e <= a)
                        && p.pointwise_estimate.is_some_and(|e| e <= a)
                        && p.contact_indicator.max(p.eta) <= a
                })
                .or_else(|| {
                    // Else the stop at stagnation, where the run stagnated (its last point) with
                    // s and ŝ agreeing within a / STAGNATION_AGREEMENT (`StopRule::decide`).
                    let last = report.points.last()?;
                    let etas: Vec<f64> = report.points.iter().map(|p| p.eta).collect();
                    (stagnated(&etas, stagnation.0, stagnation.1)
                        && last.contact_indicator.max(last.eta) <= a / STAGNATION_AGREEMENT)
                        .then_some(last)
                });
            AccuracyStop {
                accuracy: a,
                iteration: at.map(|p| p.iteration),
                estimate: at.and_then(|p| p.estimate),
                true_error: at.map(|p| p.traction_error).filter(|e| e.is_finite()),
                first_reached: report
                    .points
                    .iter()
                    .find(|p| p.traction_error <= a)
                    .map(|p| p.iteration),
            }
        })
        .collect();
    let ratios: Vec<f64> = report
        .points
        .iter()
        .filter(|p| p.traction_error > 0.0 && p.traction_error < 1e-2 && p.traction_error.is_finite())
        .filter_map(|p| p.estimate.map(|e| e / p.traction_error))
        .collect();
    let share = |f: &dyn Fn(f64) -> bool| {
        if ratios.is_empty() {
            0.0
        } else {
            ratios.iter().filter(|&&r| f(r)).count() as f64 / ratios.len() as f64
        }
    };
    AccuracyCheck {
        name: name.to_string(),
        verdict: report.latin_verdict.clone(),
        stops,
        compared: ratios.len(),
        within_3x: share(&|r| (1.0 / 3.0..=3.0).contains(&r)),
        underestimated: share(&|r| r < 1.0),
        trace: report
            .points
            .iter()
            .map(|p| (p.traction_error, p.estimate, p.force_step, p.contact_indicator))
            .collect(),
    }
}

/// Solves the reference of `scene` and runs it past the smallest accuracy checked (accuracy
/// 1e-5, the scene's other stop rules and iteration cap kept), then checks it.
pub fn check_scene(name: &str, scene: &LoadedScene, reference: &ReferenceOptions) -> crate::Result<AccuracyCheck> {
    let t0 = Instant::now();
    // A reference that fails is an error here: the check needs every time point.
    let solution = solve_reference(&scene.model, reference)?;
    check_scene_against(name, scene, solution, t0.elapsed().as_secs_f64())
}

/// [`check_scene`] against a reference already solved (in `reference_s` seconds).
pub fn check_scene_against(
    name: &str,
    scene: &LoadedScene,
    solution: glissade_reference::ReferenceSolution,
    reference_s: f64,
) -> crate::Result<AccuracyCheck> {
    let mut sc = scene.clone();
    sc.model.solver.accuracy = Some(ACCURACIES[ACCURACIES.len() - 1] * 0.1);
    let solved = ReferenceRun {
        solution,
        failure: None,
    };
    let (report, _) = report_against(&sc, &format!("accuracy-{name}"), &solved, reference_s, None)?;
    Ok(check_report(
        name,
        &report,
        (sc.model.solver.stagnation_window, sc.model.solver.stagnation_ratio),
    ))
}

/// The margin factors the status check compares (m_T = factor · accuracy · T_max,
/// `glissade_mechanics::settled`; 0: no margin at all).
pub const MARGIN_FACTORS: [f64; 5] = [0.0, 0.5, 1.0, 2.0, 4.0];

/// A run's reported statuses against the reference's, judged with the same margins.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusCheck {
    /// The accuracy the run stopped at.
    pub accuracy: f64,
    /// Whether it ended "Converged" (the margins assume it did).
    pub converged: bool,
    /// Per factor of [`MARGIN_FACTORS`], the comparison with the margins of that factor.
    pub agreement: Vec<(f64, glissade_mechanics::settled::Agreement)>,
}

/// Runs `scene` in-process to `accuracy` and compares its reported statuses with those of the
/// reference `solution` under each margin factor of [`MARGIN_FACTORS`].
pub fn check_statuses(
    scene: &LoadedScene,
    solution: &glissade_reference::ReferenceSolution,
    accuracy: f64,
) -> crate::Result<StatusCheck> {
    let mut sc = scene.clone();
    sc.model.solver.accuracy = Some(accuracy);
    let opts = crate::runner::RunOptions::new(crate::run::random_run_id()?);
    let result = crate::run::Run::new(&sc, &opts).in_process()?.result;
    let run = result.interface_hat_fields();
    Ok(StatusCheck {
        accuracy,
        converged: result.verdict == glissade_messages::Verdict::Converged,
        agreement: MARGIN_FACTORS
            .iter()
            .map(|&f| {
                (
                    f,
                    glissade_mechanics::settled::agreement(&sc.model, &run, &solution.interfaces, f, accuracy),
                )
            })
            .collect(),
    })
}

/// The checks as a markdown table: one row per scene and accuracy.
pub fn markdown(checks: &[AccuracyCheck]) -> String {
    let mut s = String::from(
        "| scene or case | accuracy | stop iteration | true error at the stop | true / accuracy | estimate / true | first iteration with true error ≤ accuracy |\n|---|---|---|---|---|---|---|\n",
    );
    let opt = |v: Option<u32>| v.map_or("—".to_string(), |v| v.to_string());
    for c in checks {
        for st in &c.stops {
            s += &format!(
                "| {} | {:.0e} | {} | {} | {} | {} | {} |\n",
                c.name,
                st.accuracy,
                opt(st.iteration),
                match (st.iteration, st.true_error) {
                    (Some(_), None) => "undefined (no contact force in the reference)".to_string(),
                    (_, e) => e.map_or("—".into(), |e| format!("{e:.2e}")),
                },
                st.ratio().map_or("—".into(), |r| format!("{r:.2}")),
                st.estimate.zip(st.true_error).map_or("—".into(), |(e, t)| if t > 0.0 {
                    format!("{:.1}", e / t)
                } else {
                    "—".into()
                }),
                opt(st.first_reached),
            );
        }
    }
    s
}

/// The summary of many checks: stops that exist, how many of them are within the accuracy, the
/// largest true/accuracy ratio, and the estimate's sharpness over every compared iteration.
pub fn summary(checks: &[AccuracyCheck]) -> String {
    let ratios: Vec<f64> = checks
        .iter()
        .flat_map(|c| c.stops.iter().filter_map(|s| s.ratio()))
        .collect();
    let within = ratios.iter().filter(|&&r| r <= 1.0).count();
    let worst = ratios.iter().cloned().fold(0.0, f64::max);
    let compared: usize = checks.iter().map(|c| c.compared).sum();
    let weighted = |f: &dyn Fn(&AccuracyCheck) -> f64| {
        checks.iter().map(|c| f(c) * c.compared as f64).sum::<f64>() / compared.max(1) as f64
    };
    format!(
        "{within} of {} stops within the requested accuracy, the worst at {worst:.2}× it; over {compared} iterations \
         below 1e-2 the estimate was within 3× of the true error in {:.0} % and below it in {:.0} %",
        ratios.len(),
        100.0 * weighted(&|c| c.within_3x),
        100.0 * weighted(&|c| c.underestimated),
    )
}

/// [`check_scene`] on every case of the stability matrix that is expected to converge and has a
/// reference, with the default solver (its accelerated scene); `on_check` sees each as it is
/// done. A case whose reference or run fails is reported by name, not skipped silently.
pub fn check_cases(
    cases: &[crate::stability::Case],
    mut on_check: impl FnMut(&Result<AccuracyCheck, String>),
) -> Vec<Result<AccuracyCheck, String>> {
    use crate::stability::Expect;
    cases
        .iter()
        .filter(|c| matches!(c.expect, Expect::Converge { .. }))
        .filter_map(|c| {
            let opts = c.reference.as_ref()?;
            let checked = glissade_scene::load_str(&c.accelerated, &format!("{}.toml", c.name))
                .map_err(crate::Error::from)
                .and_then(|sc| check_scene(c.name, &sc, opts))
                .map_err(|e| format!("{}: {}", c.name, crate::error::chain(&e)));
            on_check(&checked);
            Some(checked)
        })
        .collect()
}
