//! The run pipeline as a study's [`Solver`] (`glissade sweep`, docs/studies.md): each variant is
//! run in-process as `glissade run --in-process` runs a scene, from the state of the solved
//! variant the study gives (a given start, [`Prepared::start`]), with every subdomain operator
//! the variant leaves valid reused (docs/studies.md, "How variants are solved"): a friction, gap or load change keeps them all
//! (only the loads' boundary responses W_d are computed again, [`SubdomainSolver::retimed`]); a
//! material change rebuilds the subdomains of that material and those whose search directions
//! it changes.

use crate::output::outcome;
use crate::run::Run;
use crate::runner::{Prepared, RunOptions};
use glissade_deploy::{build_solvers, Plan};
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::SubdomainSolver;
use glissade_messages::InterfaceSolution;
use glissade_scene::LoadedScene;
use glissade_studies::driver::{Solved, Solver};
use glissade_studies::variants::Variant;
use std::path::PathBuf;

/// Operators built for one subdomain, and what they were built for.
struct Built {
    solver: SubdomainSolver,
    /// E and ν of the subdomain and its boundary's search directions k (bits).
    key: Vec<u64>,
}

/// The run pipeline for a study's variants, keeping the operators of the variants before.
#[derive(Default)]
pub struct PipelineSolver {
    /// Per subdomain, the operators last built for it.
    built: Vec<Option<Built>>,
    /// Where each variant's recording goes (`<study>-v<k>.mcap`), when recorded.
    pub recordings: Option<(PathBuf, String)>,
}

impl PipelineSolver {
    /// A solver whose variants record to `<folder>/<study>-v<k>.mcap` when `recordings` is
    /// given (folder, study name).
    pub fn new(recordings: Option<(PathBuf, String)>) -> Self {
        Self {
            built: Vec::new(),
            recordings,
        }
    }

    /// The operators of every participant of `scene`'s `plan`: reused where built before for the
    /// same material and search directions, built otherwise. Says what it did.
    fn operators(&mut self, scene: &LoadedScene, plan: &Plan) -> Result<(Vec<SubdomainSolver>, String), String> {
        let model = &scene.model;
        if self.built.len() != model.subdomains.len() {
            self.built = (0..model.subdomains.len()).map(|_| None).collect();
        }
        let key = |s: usize| {
            let m = model.subdomains[s].material;
            let layout = BoundaryLayout::new(model, s, &plan.k0);
            [m.e.to_bits(), m.nu.to_bits()]
                .into_iter()
                .chain(layout.k.iter().map(|k| k.to_bits()))
                .collect::<Vec<u64>>()
        };
        let keys: Vec<(u32, Vec<u64>)> = plan.participants.iter().map(|&s| (s, key(s as usize))).collect();
        let stale: Vec<u32> = keys
            .iter()
            .filter(|(s, k)| self.built[*s as usize].as_ref().is_none_or(|b| &b.key != k))
            .map(|(s, _)| *s)
            .collect();
        let fresh = build_solvers(model, plan, &stale).map_err(|e| e.to_string())?;
        for ((s, k), solver) in keys.iter().filter(|(s, _)| stale.contains(s)).zip(fresh) {
            self.built[*s as usize] = Some(Built { solver, key: k.clone() });
        }
        let solvers = plan
            .participants
            .iter()
            .filter_map(|&s| self.built[s as usize].as_ref().map(|b| b.solver.retimed(model)))
            .collect();
        let n = plan.participants.len();
        let said = match stale.len() {
            0 => format!("reused for all {n} subdomains"),
            k if k == n => format!("built for all {n} subdomains"),
            k => format!("built for {k} of {n} subdomains, reused for the rest"),
        };
        Ok((solvers, said))
    }
}

impl Solver for PipelineSolver {
    fn solve(
        &mut self,
        variant: &Variant,
        scene: &LoadedScene,
        start: Option<&[InterfaceSolution]>,
        cold: bool,
    ) -> Result<Solved, String> {
        let mut prepared = Prepared {
            solvers: None,
            start: start.map(<[InterfaceSolution]>::to_vec),
        };
        let operators = if cold || scene.model.interfaces.is_empty() {
            "built (cold)".to_string()
        } else {
            let t = std::time::Instant::now();
            let plan = Plan::new(&scene.model).with_scene(scene);
            let (solvers, said) = self.operators(scene, &plan)?;
            prepared.solvers = Some(solvers);
            format!("{said} ({:.2} s)", t.elapsed().as_secs_f64())
        };
        let name = self.recordings.as_ref().map_or_else(
            || format!("v{}", variant.index),
            |(_, study)| format!("{study}-v{}", variant.index),
        );
        let mut opts = RunOptions::new(name.clone());
        opts.keep_state = !cold;
        let path = self
            .recordings
            .as_ref()
            .map(|(dir, _)| dir.join(format!("{name}.mcap")));
        let t = std::time::Instant::now();
        let outcome_of_run = Run::new(scene, &opts)
            .recorded(path.as_deref())
            .prepared(prepared)
            .in_process()
            .map_err(|e| e.to_string())?;
        let wall = t.elapsed().as_secs_f64();
        let r = outcome_of_run.result;
        Ok(Solved {
            verdict_text: outcome(&scene.model, &r),
            verdict: r.verdict.clone(),
            iterations: r.iterations.len(),
            estimate: r.iterations.last().and_then(|i| i.decision.estimate),
            setup_s: wall - r.solve_s,
            solve_s: r.solve_s,
            operators,
            rules: r.boundary,
            interfaces: r.interfaces,
            state: r.state,
        })
    }
}
