//! The rigid-mode check: every body's rigid-body motion blocked.

use super::*;

impl Ctx<'_> {
    /// Every group of subdomains connected through interfaces must have its rigid-body modes
    /// blocked by prescribed displacements: the rows [δ_c0, δ_c1, c = 0 ? −(y − ȳ) : (x − x̄)]
    /// over the constrained dofs must have rank 3.
    pub(crate) fn check_rigid_modes(
        &self,
        subs: &[Sub],
        interfaces: &[Interface],
        loads: &[SubLoads],
    ) -> Result<(), SceneError> {
        let groups = connected_groups(subs.len(), interfaces.iter().map(|i| (i.a, i.b)));
        for members in &groups {
            // Constrained (coordinates, component).
            let mut rows: Vec<([f64; 2], usize)> = Vec::new();
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &s in members {
                lo = [lo[0].min(subs[s].x[0]), lo[1].min(subs[s].y[0])];
                hi = [hi[0].max(subs[s].x[1]), hi[1].max(subs[s].y[1])];
                for (d, &c) in loads[s].constrained.iter().enumerate() {
                    if c {
                        rows.push((subs[s].mesh.coords[d / 2], d % 2));
                    }
                }
            }
            let rank = blocked_rigid_modes(&rows, (hi[0] - lo[0]).max(hi[1] - lo[1]), self.plane);
            if rank == 3 {
                continue;
            }
            let mut free = Vec::new();
            if self.plane == Plane::Axisymmetric {
                // Its one rigid motion.
                free.push("y-translation (along the axis)");
            } else {
                if !rows.iter().any(|r| r.1 == 0) {
                    free.push("x-translation");
                }
                if !rows.iter().any(|r| r.1 == 1) {
                    free.push("y-translation");
                }
                if free.len() < 3 - rank {
                    free.push("rotation");
                }
            }
            let shown: Vec<&str> = members.iter().take(6).map(|&s| subs[s].name.as_str()).collect();
            let more = if members.len() > shown.len() {
                format!(", … ({} in all)", members.len())
            } else {
                String::new()
            };
            let modes = match free.split_last() {
                Some((last, [])) => last.to_string(),
                Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
                None => String::new(),
            };
            return Err(self.err(
                "boundary",
                format!(
                    "rigid-body motion of subdomains [{}{more}] is not blocked: {modes} free; prescribe displacements \
                     that block it (subdomains connected through interfaces count as one body)",
                    shown.join(", "),
                ),
            ));
        }
        Ok(())
    }
}

/// A subdomain held only by contact in some rigid-body motion: every interface of it is a contact
/// interface, and its own prescribed displacements leave a rigid motion a + ω × (x − x̄) free (the
/// rows [δ_c0, δ_c1, c = 0 ? −(y − ȳ) : (x − x̄)] over its constrained dofs have rank < 3). The
/// outer ring of a shrink fit is one (its rotation about the centre of the fit), and so is a block
/// pushed against its neighbour whose only support is a roller along the push. Returns the first
/// such subdomain.
///
/// Why it matters (docs/scenes.md, `solver.coarse`): once the macro problem balances the macro
/// forces, a rigid motion of such a part changes no force after a linear stage (the macro
/// correction moves a free part rigidly, F₂ = 0, and the part's forces balance its loads whatever
/// its position), so the force residual Anderson mixing minimises does not see it. On the shrink
/// fit, LATIN with the macro problem and Anderson mixing then holds whole time points in slip with
/// the outer ring turned (0.17 mm at the fit on mesh 2) and stalls at a 1e-2 traction error; on two
/// blocks side by side, the pushed block keeps a rigid offset along the push that opens or closes
/// the contact (15 % of the contact pressure in ŝ after 25 iterations, η 0.1 oscillating) while the
/// forces of s are exact. Plain relaxation, or Anderson mixing without the macro problem, leaves
/// such states.
pub(crate) fn part_held_only_by_contact(
    interfaces: &[Interface],
    coords: &[&[[f64; 2]]],
    constrained: &[&[bool]],
    plane: Plane,
) -> Option<usize> {
    (0..constrained.len()).find(|&s| {
        let own: Vec<&Interface> = interfaces.iter().filter(|i| i.side_of(s).is_some()).collect();
        if own.is_empty() || !own.iter().all(|i| i.is_contact()) {
            return false;
        }
        let rows: Vec<([f64; 2], usize)> = constrained[s]
            .iter()
            .enumerate()
            .filter(|(_, &c)| c)
            .map(|(d, _)| (coords[s][d / 2], d % 2))
            .collect();
        let (lo, hi) = coords[s]
            .iter()
            .fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), x| {
                ([lo[0].min(x[0]), lo[1].min(x[1])], [hi[0].max(x[0]), hi[1].max(x[1])])
            });
        blocked_rigid_modes(&rows, (hi[0] - lo[0]).max(hi[1] - lo[1]), plane) < 3
    })
}

/// How many of the three rigid-body motions the constrained dofs `rows` (coordinates, component)
/// block: [`rigid_modes`] of the rows along the axes.
fn blocked_rigid_modes(rows: &[([f64; 2], usize)], scale: f64, plane: Plane) -> usize {
    let along: Vec<([f64; 2], [f64; 2])> = rows
        .iter()
        .map(|&(p, c)| (p, if c == 0 { [1.0, 0.0] } else { [0.0, 1.0] }))
        .collect();
    rigid_modes(&along, scale, plane).0
}

/// A rigid motion: (translation, rotation in rad per unit of the body's size).
type FreeMotion = ([f64; 2], f64);

/// How many of the three rigid-body motions the constraints `rows` (a point and the direction
/// the motion is held along there) block: the rank of the rows [d_x, d_y, (p − p̄) × d / scale]
/// (p̄ the points' mean, `scale` the body's size), eigenvalues of their Gram matrix below 1e-10
/// of the largest counted as zero; and a motion left free, if any, as (translation, rotation
/// about p̄ in rad per unit of `scale`), the eigenvector of the smallest eigenvalue. In
/// axisymmetry the only rigid motion is the axial translation (a radial one stretches the hoop,
/// and there is no rotation): the radial translation and the rotation count as blocked, the axial
/// one as blocked by any row with an axial component.
fn rigid_modes(rows: &[([f64; 2], [f64; 2])], scale: f64, plane: Plane) -> (usize, Option<FreeMotion>, [f64; 2]) {
    let n = rows.len().max(1) as f64;
    let mean = [
        rows.iter().map(|r| r.0[0]).sum::<f64>() / n,
        rows.iter().map(|r| r.0[1]).sum::<f64>() / n,
    ];
    if plane == Plane::Axisymmetric {
        let largest = rows.iter().fold(0.0f64, |m, r| m.max(r.1[0].abs()).max(r.1[1].abs()));
        let axial = rows.iter().any(|r| r.1[1].abs() > 1e-10 * largest);
        return if axial {
            (3, None, mean)
        } else {
            (2, Some(([0.0, 1.0], 0.0)), mean)
        };
    }
    let mut gram = nalgebra::Matrix3::<f64>::zeros();
    for &(p, d) in rows {
        let cross = ((p[0] - mean[0]) * d[1] - (p[1] - mean[1]) * d[0]) / scale;
        let row = nalgebra::Vector3::new(d[0], d[1], cross);
        gram += row * row.transpose();
    }
    let eig = gram.symmetric_eigen();
    let max = eig.eigenvalues.iter().fold(0.0f64, |m, &v| m.max(v));
    let rank = eig
        .eigenvalues
        .iter()
        .filter(|&&v| v > 1e-10 * max && max > 0.0)
        .count();
    let free = (rank < 3).then(|| {
        let k = (0..3)
            .min_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]))
            .unwrap_or(0);
        let v = eig.eigenvectors.column(k);
        ([v[0], v[1]], v[2])
    });
    (rank, free, mean)
}

/// The warnings of `glissade check` for parts whose rigid motion in some direction is held by
/// nothing but frictionless contact pushing along its normals, or not at all: a part is a group
/// of subdomains joined by perfect interfaces; it is held by its prescribed displacements, by the
/// normals of its contact pairs, and by their tangents where the friction is not zero. A load with
/// a component along the motion left free has no equilibrium (the part would slide away), and a
/// run of it stalls.
pub fn free_motions(model: &glissade_mechanics::model::Model) -> Vec<String> {
    let perfect = model.interfaces.iter().filter(|i| !i.is_contact()).map(|i| (i.a, i.b));
    let parts = connected_groups(model.subdomains.len(), perfect);
    let mut warnings = Vec::new();
    for members in &parts {
        let mut rows: Vec<([f64; 2], [f64; 2])> = Vec::new();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut frictionless = Vec::new();
        for &s in members {
            let sub = &model.subdomains[s];
            for x in &sub.mesh.coords {
                lo = [lo[0].min(x[0]), lo[1].min(x[1])];
                hi = [hi[0].max(x[0]), hi[1].max(x[1])];
            }
            for (d, &c) in sub.constrained.iter().enumerate() {
                if c {
                    rows.push((sub.mesh.coords[d / 2], if d % 2 == 0 { [1.0, 0.0] } else { [0.0, 1.0] }));
                }
            }
        }
        for (k, itf) in model.interfaces.iter().enumerate() {
            let glissade_mechanics::model::InterfaceKind::Contact { friction, .. } = &itf.kind else {
                continue;
            };
            if members.contains(&itf.a) == members.contains(&itf.b) {
                continue;
            }
            for p in 0..itf.n_pairs() {
                rows.push((itf.coords[p], itf.normal(p)));
                if *friction > 0.0 {
                    rows.push((itf.coords[p], itf.tangent(p)));
                }
            }
            if *friction == 0.0 {
                frictionless.push(k);
            }
        }
        let scale = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let (rank, free, centre) = rigid_modes(&rows, scale, model.plane);
        let Some((t, w)) = free.filter(|_| rank < 3) else {
            continue;
        };
        let names: Vec<&str> = members
            .iter()
            .take(6)
            .map(|&s| model.subdomains[s].name.as_str())
            .collect();
        let motion = if w.abs() < 1e-6 {
            let n = t[0].hypot(t[1]);
            format!("a translation along ({:.3}, {:.3})", t[0] / n, t[1] / n)
        } else if t[0].hypot(t[1]) < 1e-6 {
            format!("a rotation about ({:.4}, {:.4})", centre[0], centre[1])
        } else {
            // v = t + ω × (x − p̄) vanishes at p̄ + (−t_y, t_x)·scale/ω.
            let c = [centre[0] - t[1] * scale / w, centre[1] + t[0] * scale / w];
            format!("a rotation about ({:.4}, {:.4})", c[0], c[1])
        };
        let by = if frictionless.is_empty() {
            "nothing".to_string()
        } else {
            format!("nothing but frictionless contact (interfaces {frictionless:?}) pushing along its normals")
        };
        warnings.push(format!(
            "part [{}{}] is held in {motion} by {by}: a load with a component along it has no equilibrium",
            names.join(", "),
            if members.len() > names.len() {
                format!(", … ({} in all)", members.len())
            } else {
                String::new()
            }
        ));
    }
    warnings
}
