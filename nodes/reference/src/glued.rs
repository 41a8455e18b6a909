//! Monolithic linear-elastic solve of a whole model with every interface glued (node pairs
//! merged): the reference for perfect-interface scenes, and the elastic predictor of contact ones.

use faer::Mat;
use glissade_mechanics::assembly::{stiffness_triplets, AssemblyError, SparseSpd};
use glissade_mechanics::model::Model;

/// Global numbering of a model's nodes with interface pairs merged.
#[derive(Debug, Clone)]
pub struct GluedNumbering {
    /// First global (unmerged) node of each subdomain.
    pub node_offset: Vec<usize>,
    /// Merged node of each unmerged global node.
    pub merged: Vec<usize>,
    pub n_merged: usize,
}

impl GluedNumbering {
    /// Merges the node pairs of every interface of `model` (union–find, smallest id as root).
    pub fn new(model: &Model) -> Self {
        let n = crate::numbering::Numbering::merging(model, |_| true);
        Self {
            node_offset: n.node_offset,
            merged: n.merged,
            n_merged: n.n_merged,
        }
    }

    /// Merged dof of dof `d` of subdomain `s`.
    pub fn dof(&self, s: usize, d: usize) -> usize {
        2 * self.merged[self.node_offset[s] + d / 2] + d % 2
    }
}

/// Displacements of every subdomain at every time point: `u[s]` is n_dofs(s) × (N+1), mm.
#[derive(Debug, Clone)]
pub struct GluedSolution {
    pub u: Vec<Mat<f64>>,
}

/// Solves K u = f(t) with prescribed displacements imposed strongly, all interfaces glued, for
/// every time point (by superposition of the load cases).
pub fn solve_glued(model: &Model) -> Result<GluedSolution, AssemblyError> {
    glissade_mechanics::assembly::refuse_non_matching(model)?;
    let num = GluedNumbering::new(model);
    let n = 2 * num.n_merged;
    let mut constrained = vec![false; n];
    let mut k_all = Vec::new();
    for (s, sub) in model.subdomains.iter().enumerate() {
        for (d, &c) in sub.constrained.iter().enumerate() {
            if c {
                constrained[num.dof(s, d)] = true;
            }
        }
        for (i, j, v) in stiffness_triplets(&sub.mesh, sub.material, model.plane)? {
            k_all.push((num.dof(s, i), num.dof(s, j), v));
        }
    }
    let mut free = vec![usize::MAX; n];
    let mut n_free = 0;
    for d in 0..n {
        if !constrained[d] {
            free[d] = n_free;
            n_free += 1;
        }
    }
    // One column per (subdomain, load case): force and prescribed values in merged numbering.
    let cases: Vec<(usize, usize)> = model
        .subdomains
        .iter()
        .enumerate()
        .flat_map(|(s, sub)| (0..sub.loads.len()).map(move |j| (s, j)))
        .collect();
    let mut disp = Mat::<f64>::zeros(n, cases.len());
    let mut rhs = Mat::<f64>::zeros(n_free, cases.len());
    for (c, &(s, j)) in cases.iter().enumerate() {
        let case = &model.subdomains[s].loads[j];
        for d in 0..case.force.len() {
            let g = num.dof(s, d);
            if model.subdomains[s].constrained[d] {
                disp[(g, c)] = case.displacement[d];
            }
            if free[g] != usize::MAX {
                rhs[(free[g], c)] += case.force[d];
            }
        }
    }
    for &(i, j, v) in &k_all {
        if free[i] != usize::MAX && free[j] == usize::MAX {
            for c in 0..cases.len() {
                rhs[(free[i], c)] -= v * disp[(j, c)];
            }
        }
    }
    let k_ff: Vec<(usize, usize, f64)> = k_all
        .iter()
        .filter(|t| free[t.0] != usize::MAX && free[t.1] != usize::MAX)
        .map(|&(i, j, v)| (free[i], free[j], v))
        .collect();
    let factor = SparseSpd::factorize(n_free, &k_ff, "the glued structure")?;
    factor.solve_in_place(&mut rhs);
    let nt = model.time.n_points();
    let phi = Mat::from_fn(cases.len(), nt, |c, i| {
        let (s, j) = cases[c];
        model.subdomains[s].loads[j].time.eval(model.time.t(i))
    });
    let u = model
        .subdomains
        .iter()
        .enumerate()
        .map(|(s, sub)| {
            Mat::from_fn(sub.n_dofs(), nt, |d, i| {
                let g = num.dof(s, d);
                (0..cases.len())
                    .map(|c| {
                        phi[(c, i)]
                            * if free[g] == usize::MAX {
                                disp[(g, c)]
                            } else {
                                rhs[(free[g], c)]
                            }
                    })
                    .sum()
            })
        })
        .collect();
    Ok(GluedSolution { u })
}
