//! The loop over a study's variants: each variant's scene is built from the scene's text, solved
//! by the caller's [`Solver`] (the run pipeline) from the state of the nearest solved variant
//! (or from ŝ = 0 when cold), and its quantities computed. A variant that fails is reported with
//! its reason and the study goes on.

use crate::patch::variant_scene;
use crate::quantities::{quantities, InterfaceQuantities};
use crate::study::Study;
use crate::variants::{nearest, variants, Variant};
use crate::StudyError;
use glissade_mechanics::model::Plane;
use glissade_messages::{Field, InterfaceSolution, Verdict};
use glissade_scene::LoadedScene;
use std::time::Instant;

/// What the run pipeline gives of one variant.
#[derive(Debug, Clone)]
pub struct Solved {
    pub verdict: Verdict,
    /// The verdict as the run command words it.
    pub verdict_text: String,
    pub iterations: usize,
    /// The estimated contact-traction error at the stop.
    pub estimate: Option<f64>,
    /// Building operators (s) and the iterations (s).
    pub setup_s: f64,
    pub solve_s: f64,
    /// Which operators were built for the variant and which reused.
    pub operators: String,
    /// The final fields, one value per point (what outputs show).
    pub interfaces: Vec<InterfaceSolution>,
    /// The iteration's own final state, from which another variant starts; None if not kept.
    pub state: Option<Vec<InterfaceSolution>>,
    /// Every boundary rule's force on the parts (supports' reactions, loads' resultants), as the
    /// run's boundaries CSV holds them.
    pub rules: Vec<crate::boundary::RuleResultants>,
}

/// Solves one variant: the launcher's run pipeline.
pub trait Solver {
    /// Solves `scene` (variant `variant`'s), starting from `start` (the state of a solved
    /// variant of the same scene) when given, else from ŝ = 0. `cold`: the study runs every
    /// variant as a separate run would, operators built anew.
    fn solve(
        &mut self,
        variant: &Variant,
        scene: &LoadedScene,
        start: Option<&[InterfaceSolution]>,
        cold: bool,
    ) -> Result<Solved, String>;
}

/// One variant's outcome.
#[derive(Debug, Clone)]
pub struct VariantOutcome {
    pub variant: Variant,
    /// The solved variant it started from (None: from ŝ = 0).
    pub started_from: Option<usize>,
    /// The solve and the quantities, or why the variant has none.
    pub result: Result<(Solved, Vec<InterfaceQuantities>), String>,
    /// The time points (s).
    pub time: Vec<f64>,
    /// Wall time of the variant, its scene's build included (s).
    pub wall_s: f64,
}

impl VariantOutcome {
    pub fn converged(&self) -> bool {
        matches!(&self.result, Ok((s, _)) if s.verdict == Verdict::Converged)
    }
}

/// A study's outcome.
#[derive(Debug, Clone)]
pub struct StudyRun {
    pub study: Study,
    /// The scene's plane (the units of its forces), as its first variant that loads says.
    pub plane: Plane,
    pub cold: bool,
    pub outcomes: Vec<VariantOutcome>,
    pub wall_s: f64,
}

/// States kept to start variants from: the most recent converged ones (each is Ŵ and F̂ of every
/// interface: a grid walked as a snake finds its nearest among the last few).
pub const KEPT_STATES: usize = 16;

/// Runs every variant of `study` on the scene text `scene_text` with `solver`, in the order of
/// [`variants`]: warm (each from the nearest converged variant among the last [`KEPT_STATES`]) or
/// `cold` (each from ŝ = 0, operators built anew). `on_variant` sees each outcome as it comes.
pub fn run(
    study: &Study,
    scene_text: &str,
    solver: &mut impl Solver,
    cold: bool,
    mut on_variant: impl FnMut(&VariantOutcome),
) -> Result<StudyRun, StudyError> {
    let t0 = Instant::now();
    let mut kept: Vec<(Variant, Vec<InterfaceSolution>)> = Vec::new();
    let mut outcomes = Vec::new();
    let mut plane = None;
    for variant in variants(study) {
        let t = Instant::now();
        // A study file that names what the scene lacks is the study's error, found at the first
        // variant; a value the scene refuses is the variant's.
        let scene = variant_scene(study, scene_text, &variant)?;
        let time: Vec<f64> = scene
            .as_ref()
            .map(|s| (0..s.model.time.n_points()).map(|i| s.model.time.t(i)).collect())
            .unwrap_or_default();
        let from = if cold {
            None
        } else {
            nearest(study, &variant, kept.iter().map(|(v, _)| v)).map(|v| v.index)
        };
        let start = from
            .and_then(|f| kept.iter().find(|(v, _)| v.index == f))
            .map(|(_, s)| s.as_slice());
        if let Ok(scene) = &scene {
            plane.get_or_insert(scene.model.plane);
        }
        let result = match scene {
            Err(e) => Err(format!("scene refused: {e}")),
            Ok(scene) => solver.solve(&variant, &scene, start, cold).and_then(|mut solved| {
                let q = quantities(&scene.model, &solved.interfaces)?;
                if let (Some(state), Verdict::Converged, false) = (solved.state.take(), &solved.verdict, cold) {
                    kept.push((variant.clone(), hat_only(state)));
                    if kept.len() > KEPT_STATES {
                        kept.remove(0);
                    }
                }
                Ok((solved, q))
            }),
        };
        let outcome = VariantOutcome {
            variant,
            started_from: from,
            result,
            time,
            wall_s: t.elapsed().as_secs_f64(),
        };
        on_variant(&outcome);
        outcomes.push(outcome);
    }
    Ok(StudyRun {
        study: study.clone(),
        plane: plane.unwrap_or(Plane::Strain),
        cold,
        outcomes,
        wall_s: t0.elapsed().as_secs_f64(),
    })
}

/// A state with s dropped: a start reads ŝ only.
fn hat_only(state: Vec<InterfaceSolution>) -> Vec<InterfaceSolution> {
    let empty = || Field::zeros(0, 0);
    state
        .into_iter()
        .map(|s| InterfaceSolution {
            w_a: empty(),
            w_b: empty(),
            f_a: empty(),
            f_b: empty(),
            status: Vec::new(),
            ..s
        })
        .collect()
}
