//! The force of every boundary rule on the parts (docs/outputs.md, "boundaries.csv"): a
//! support's reaction, a load's resultant, their moments and the prescribed displacement beside
//! them, from a run's final fields. Computed by both run modes before the copies of a point are
//! given one value (the launcher writes them to the boundaries CSV and plot, the replay draws them
//! in Rerun, studies report them per variant).

use glissade_mechanics::model::Model;
use glissade_messages::InterfaceSolution;
use serde::Serialize;

/// What a boundary rule is to the parts: a support (it prescribes displacements, the force is its
/// reaction) or a load (it applies tractions, the force is their resultant).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RuleKind {
    Support,
    Load,
}

/// One boundary rule's force on the parts at every time point (docs/outputs.md, "Reactions and
/// loads"). Several supports holding one subdomain together share its reaction (how it splits
/// between them is not known without the subdomain's interior field): they are one entry, named
/// `boundary[i] + boundary[j]`, for those subdomains.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RuleResultants {
    pub rule: String,
    pub kind: RuleKind,
    /// The subdomains it acts on.
    pub subdomains: Vec<String>,
    /// The force on the parts per time point, global x and y (N/mm): a support's reaction, a
    /// load's resultant.
    pub force: Vec<[f64; 2]>,
    /// Its moment about `about` per time point (N·mm/mm), counter-clockwise positive.
    pub moment: Vec<f64>,
    pub about: [f64; 2],
    /// A support's prescribed displacement per time point, the mean over the dofs it prescribes
    /// of each component (mm); None for a component it does not prescribe, or for a load.
    pub displacement: Vec<[Option<f64>; 2]>,
}

/// Force and moment sums of nodal forces: (Fx, Fy, M about a point).
#[derive(Clone, Copy, Default)]
struct Wrench([f64; 3]);

impl Wrench {
    fn add(&mut self, x: [f64; 2], f: [f64; 2], about: [f64; 2]) {
        self.0[0] += f[0];
        self.0[1] += f[1];
        self.0[2] += (x[0] - about[0]) * f[1] - (x[1] - about[1]) * f[0];
    }
}

/// The forces of every boundary rule of `model` from a run's final fields `interfaces` (s, each
/// copy's own values: before the copies of a point are given one value), moments about `about`.
///
/// A load's resultant is the sum of its consistent nodal forces. A support's reaction follows
/// from each subdomain's equilibrium, which the linear stage's s satisfies exactly: the forces on
/// a subdomain (its loads, its interfaces' w·F, its supports' reactions) sum to zero in force and
/// moment, so the reaction on a subdomain is minus the sum of the others, and is its support's.
/// Solutions whose shape does not fit the model are left out (the outputs' own check names them).
pub fn boundary_resultants(model: &Model, interfaces: &[InterfaceSolution], about: [f64; 2]) -> Vec<RuleResultants> {
    let nt = model.time.n_points();
    let ns = model.subdomains.len();
    // Per subdomain and time point: its loads' and its interfaces' forces.
    let mut others = vec![vec![Wrench::default(); nt]; ns];
    let phi = |c: &glissade_mechanics::model::LoadCase| -> Vec<f64> {
        (0..nt).map(|i| c.time.eval(model.time.t(i))).collect()
    };
    for (s, sub) in model.subdomains.iter().enumerate() {
        for c in &sub.loads {
            if c.force.iter().all(|&f| f == 0.0) {
                continue;
            }
            let phi = phi(c);
            for (n, x) in sub.mesh.coords.iter().enumerate() {
                let f = [c.force[2 * n], c.force[2 * n + 1]];
                if f != [0.0, 0.0] {
                    for (i, w) in others[s].iter_mut().enumerate() {
                        w.add(*x, [f[0] * phi[i], f[1] * phi[i]], about);
                    }
                }
            }
        }
    }
    for sol in interfaces {
        let Some(itf) = model.interfaces.get(sol.interface as usize) else {
            continue;
        };
        let np = itf.n_pairs();
        let fits = |f: &glissade_messages::Field| f.rows() == 2 * np && f.cols() == nt;
        if !fits(&sol.f_a) || !fits(&sol.f_b) {
            continue;
        }
        for (s, f) in [(itf.a, &sol.f_a), (itf.b, &sol.f_b)] {
            for (i, w) in others[s].iter_mut().enumerate() {
                for (p, (&wp, x)) in itf.weights.iter().zip(&itf.coords).enumerate() {
                    w.add(*x, [wp * f.get(2 * p, i), wp * f.get(2 * p + 1, i)], about);
                }
            }
        }
    }
    let mut out: Vec<RuleResultants> = Vec::new();
    let entry = |out: &mut Vec<RuleResultants>, rule: String, kind: RuleKind| -> usize {
        if let Some(k) = out.iter().position(|r| r.rule == rule) {
            return k;
        }
        out.push(RuleResultants {
            rule,
            kind,
            subdomains: Vec::new(),
            force: vec![[0.0; 2]; nt],
            moment: vec![0.0; nt],
            about,
            displacement: vec![[None; 2]; nt],
        });
        out.len() - 1
    };
    // Loads: their own nodal forces.
    for rule in model.boundary_rules.iter().filter(|r| !r.prescribes_displacement) {
        let k = entry(&mut out, rule.name.clone(), RuleKind::Load);
        for part in &rule.parts {
            let sub = &model.subdomains[part.subdomain];
            out[k].subdomains.push(sub.name.clone());
            let mut w = vec![Wrench::default(); nt];
            for &c in &part.cases {
                let case = &sub.loads[c];
                let phi = phi(case);
                for (n, x) in sub.mesh.coords.iter().enumerate() {
                    let f = [case.force[2 * n], case.force[2 * n + 1]];
                    for (i, wi) in w.iter_mut().enumerate() {
                        wi.add(*x, [f[0] * phi[i], f[1] * phi[i]], about);
                    }
                }
            }
            for (i, wi) in w.iter().enumerate() {
                out[k].force[i][0] += wi.0[0];
                out[k].force[i][1] += wi.0[1];
                out[k].moment[i] += wi.0[2];
            }
        }
    }
    // Supports: each subdomain's reaction, to the support (or supports) holding it.
    for (s, own) in others.iter().enumerate() {
        let holding: Vec<&glissade_mechanics::model::BoundaryRule> = model
            .boundary_rules
            .iter()
            .filter(|r| r.prescribes_displacement && r.parts.iter().any(|p| p.subdomain == s && !p.dofs.is_empty()))
            .collect();
        if holding.is_empty() {
            continue;
        }
        let name = holding.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(" + ");
        let k = entry(&mut out, name, RuleKind::Support);
        out[k].subdomains.push(model.subdomains[s].name.clone());
        for (i, w) in own.iter().enumerate() {
            out[k].force[i][0] -= w.0[0];
            out[k].force[i][1] -= w.0[1];
            out[k].moment[i] -= w.0[2];
        }
    }
    // A support's prescribed displacement beside its reaction.
    for r in out.iter_mut().filter(|r| r.kind == RuleKind::Support) {
        let rules: Vec<&glissade_mechanics::model::BoundaryRule> = model
            .boundary_rules
            .iter()
            .filter(|b| r.rule.split(" + ").any(|n| n == b.name))
            .collect();
        for (i, d) in r.displacement.iter_mut().enumerate() {
            let t = model.time.t(i);
            let (mut sum, mut count) = ([0.0; 2], [0usize; 2]);
            for part in rules.iter().flat_map(|b| &b.parts) {
                let sub = &model.subdomains[part.subdomain];
                if !r.subdomains.contains(&sub.name) {
                    continue;
                }
                for &dof in &part.dofs {
                    let u: f64 = sub.loads.iter().map(|c| c.displacement[dof] * c.time.eval(t)).sum();
                    sum[dof % 2] += u;
                    count[dof % 2] += 1;
                }
            }
            for k in 0..2 {
                d[k] = (count[k] > 0).then(|| sum[k] / count[k] as f64);
            }
        }
    }
    out
}
