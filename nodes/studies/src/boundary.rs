//! The force of every boundary rule on the parts (docs/outputs.md, "boundaries.csv"): a
//! support's reaction, a load's resultant, their moments and the prescribed displacement beside
//! them, from a run's final fields. Computed by both run modes before the copies of a point are
//! given one value (the launcher writes them to the boundaries CSV and plot, the replay draws them
//! in Rerun, studies report them per variant).

use glissade_mechanics::model::{Model, Plane};
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

impl RuleResultants {
    /// |force| at time point `i`, of the components that are defined (in axisymmetry a support's
    /// radial force is NaN: its axial force alone).
    pub fn magnitude(&self, i: usize) -> f64 {
        let defined = |v: f64| if v.is_finite() { v } else { 0.0 };
        let f = self.force[i];
        defined(f[0]).hypot(defined(f[1]))
    }

    /// The largest [`Self::magnitude`] over the time points (N/mm; N in axisymmetry).
    pub fn peak(&self) -> f64 {
        (0..self.force.len()).map(|i| self.magnitude(i)).fold(0.0, f64::max)
    }
}

/// Force and moment sums of nodal forces: (Fx, Fy, M about a point).
#[derive(Clone, Copy, Default)]
struct Wrench([f64; 3]);

impl Wrench {
    /// `self` += `scale` · `w`.
    fn add_scaled(&mut self, w: &Wrench, scale: f64) {
        for (a, b) in self.0.iter_mut().zip(w.0) {
            *a += scale * b;
        }
    }

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
    let times: Vec<f64> = (0..nt).map(|i| model.time.t(i)).collect();
    // Per subdomain and load case: φ at every time point, and the force and moment of its
    // pattern (the case's nodal forces are the pattern times φ).
    let phi: Vec<Vec<Vec<f64>>> = model
        .subdomains
        .iter()
        .map(|sub| {
            sub.loads
                .iter()
                .map(|c| times.iter().map(|&t| c.time.eval(t)).collect())
                .collect()
        })
        .collect();
    let patterns: Vec<Vec<Wrench>> = model
        .subdomains
        .iter()
        .map(|sub| {
            sub.loads
                .iter()
                .map(|c| {
                    let mut w = Wrench::default();
                    for (n, x) in sub.mesh.coords.iter().enumerate() {
                        w.add(*x, [c.force[2 * n], c.force[2 * n + 1]], about);
                    }
                    w
                })
                .collect()
        })
        .collect();
    // The wrench of load cases `cases` of subdomain `s` at time point i.
    let loads_of = |s: usize, cases: &mut dyn Iterator<Item = usize>| -> Vec<Wrench> {
        let mut out = vec![Wrench::default(); nt];
        for c in cases {
            for (i, w) in out.iter_mut().enumerate() {
                w.add_scaled(&patterns[s][c], phi[s][c][i]);
            }
        }
        out
    };
    // Per subdomain and time point: its loads' and its interfaces' forces.
    let mut others: Vec<Vec<Wrench>> = (0..model.subdomains.len())
        .map(|s| loads_of(s, &mut (0..model.subdomains[s].loads.len())))
        .collect();
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
    // Per entry of `out`: Σ and count of the prescribed displacement of each component.
    let mut prescribed = Vec::new();
    type Prescribed = Vec<(Vec<[f64; 2]>, [usize; 2])>;
    let entry = |out: &mut Vec<RuleResultants>, prescribed: &mut Prescribed, rule: String, kind: RuleKind| -> usize {
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
        prescribed.push((vec![[0.0; 2]; nt], [0; 2]));
        out.len() - 1
    };
    let add = |r: &mut RuleResultants, wrenches: &[Wrench], sign: f64| {
        for (i, w) in wrenches.iter().enumerate() {
            r.force[i][0] += sign * w.0[0];
            r.force[i][1] += sign * w.0[1];
            r.moment[i] += sign * w.0[2];
        }
    };
    // Loads: their own nodal forces.
    for rule in model.boundary_rules.iter().filter(|r| !r.prescribes_displacement) {
        let k = entry(&mut out, &mut prescribed, rule.name.clone(), RuleKind::Load);
        for part in &rule.parts {
            out[k].subdomains.push(model.subdomains[part.subdomain].name.clone());
            add(
                &mut out[k],
                &loads_of(part.subdomain, &mut part.cases.iter().copied()),
                1.0,
            );
        }
    }
    // Supports: each subdomain's reaction, to the support (or supports) holding it, and the
    // displacement they prescribe there.
    for (s, own) in others.iter().enumerate() {
        let held: Vec<(&str, &[usize])> = model
            .boundary_rules
            .iter()
            .filter(|r| r.prescribes_displacement)
            .filter_map(|r| {
                let part = r.parts.iter().find(|p| p.subdomain == s && !p.dofs.is_empty())?;
                Some((r.name.as_str(), part.dofs.as_slice()))
            })
            .collect();
        if held.is_empty() {
            continue;
        }
        let name = held.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(" + ");
        let k = entry(&mut out, &mut prescribed, name, RuleKind::Support);
        out[k].subdomains.push(model.subdomains[s].name.clone());
        add(&mut out[k], own, -1.0);
        let sub = &model.subdomains[s];
        let (sum, count) = &mut prescribed[k];
        for &dof in held.iter().flat_map(|(_, dofs)| dofs.iter()) {
            for (i, total) in sum.iter_mut().enumerate() {
                total[dof % 2] += sub
                    .loads
                    .iter()
                    .zip(&phi[s])
                    .map(|(c, f)| c.displacement[dof] * f[i])
                    .sum::<f64>();
            }
            count[dof % 2] += 1;
        }
    }
    // A support's prescribed displacement beside its reaction: the mean over its dofs.
    for (r, (sum, count)) in out.iter_mut().zip(&prescribed) {
        if r.kind == RuleKind::Support {
            for (d, total) in r.displacement.iter_mut().zip(sum) {
                for c in 0..2 {
                    d[c] = (count[c] > 0).then(|| total[c] / count[c] as f64);
                }
            }
        }
    }
    if model.plane == Plane::Axisymmetric {
        // Only the axial force balances over a subdomain (its one rigid motion): a support's
        // radial reaction and every moment are not resultants there, and are left out (NaN). A
        // load's radial column stays the total of its radial nodal forces, ∫ t_r 2πr ds.
        for r in &mut out {
            r.moment.fill(f64::NAN);
            if r.kind == RuleKind::Support {
                r.force.iter_mut().for_each(|f| f[0] = f64::NAN);
            }
        }
    }
    out
}
