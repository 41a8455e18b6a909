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
        let mut parent: Vec<usize> = (0..subs.len()).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for itf in interfaces {
            let (ra, rb) = (root(&mut parent, itf.a), root(&mut parent, itf.b));
            if ra != rb {
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
        let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for s in 0..subs.len() {
            let r = root(&mut parent, s);
            groups.entry(r).or_default().push(s);
        }
        for members in groups.values() {
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
            let scale = (hi[0] - lo[0]).max(hi[1] - lo[1]);
            let n = rows.len().max(1) as f64;
            let mean = [
                rows.iter().map(|r| r.0[0]).sum::<f64>() / n,
                rows.iter().map(|r| r.0[1]).sum::<f64>() / n,
            ];
            let mut gram = nalgebra::Matrix3::<f64>::zeros();
            for &(p, c) in &rows {
                let row = if c == 0 {
                    nalgebra::Vector3::new(1.0, 0.0, -(p[1] - mean[1]) / scale)
                } else {
                    nalgebra::Vector3::new(0.0, 1.0, (p[0] - mean[0]) / scale)
                };
                gram += row * row.transpose();
            }
            let eig = gram.symmetric_eigenvalues();
            let max = eig.iter().fold(0.0f64, |m, &v| m.max(v));
            let rank = eig.iter().filter(|&&v| v > 1e-10 * max && max > 0.0).count();
            if rank == 3 {
                continue;
            }
            let mut free = Vec::new();
            if !rows.iter().any(|r| r.1 == 0) {
                free.push("x-translation");
            }
            if !rows.iter().any(|r| r.1 == 1) {
                free.push("y-translation");
            }
            if free.len() < 3 - rank {
                free.push("rotation");
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

/// A subdomain whose whole boundary hold is contact along which one of its rigid-body motions
/// slips: it has no prescribed displacement, every interface of it is a contact interface, and a
/// rigid motion a + ω × (x − x̄) has no normal component at any of their pairs (the rows
/// [n_x, n_y, ((x − x̄) n_y − (y − ȳ) n_x)/ℓ], weighted by the pair weights, have rank < 3). The
/// outer ring of a shrink fit is one (its rotation about the centre of the fit). Returns the
/// first such subdomain.
///
/// Why it matters (docs/scenes.md, `solver.coarse`): at an iterate where the whole contact slips
/// at a time point, that rigid motion changes neither the local stage's forces (slip: F̂·t =
/// f|C_N|) nor the part's forces (the macro correction moves a free part rigidly, F₂ = 0), so
/// the force residual Anderson mixing minimises does not see it. On the shrink fit, LATIN with
/// the macro problem and Anderson mixing then holds whole time points in slip with the outer ring
/// turned (0.17 mm at the fit on mesh 2) and stalls at a 1e-2 traction error; plain relaxation
/// leaves such states, and with the macro problem converges to the reference.
pub(crate) fn part_slipping_rigidly(interfaces: &[Interface], constrained: &[&[bool]]) -> Option<usize> {
    (0..constrained.len()).find(|&s| {
        let own: Vec<&Interface> = interfaces.iter().filter(|i| i.side_of(s).is_some()).collect();
        if own.is_empty() || constrained[s].iter().any(|&c| c) || !own.iter().all(|i| i.is_contact()) {
            return false;
        }
        let pairs = || {
            own.iter()
                .flat_map(|i| (0..i.n_pairs()).map(move |p| (i.coords[p], i.normals[p], i.weights[p])))
        };
        let total: f64 = pairs().map(|(_, _, w)| w).sum();
        let mean = pairs().fold([0.0; 2], |m, (x, _, w)| {
            [m[0] + w * x[0] / total, m[1] + w * x[1] / total]
        });
        let scale = pairs()
            .map(|(x, _, _)| (x[0] - mean[0]).hypot(x[1] - mean[1]))
            .fold(0.0, f64::max)
            .max(f64::MIN_POSITIVE);
        let mut gram = nalgebra::Matrix3::<f64>::zeros();
        for (x, n, w) in pairs() {
            let (dx, dy) = ((x[0] - mean[0]) / scale, (x[1] - mean[1]) / scale);
            let row = nalgebra::Vector3::new(n[0], n[1], dx * n[1] - dy * n[0]);
            gram += w * row * row.transpose();
        }
        let eig = gram.symmetric_eigenvalues();
        let max = eig.iter().fold(0.0f64, |m, &v| m.max(v));
        // A rank-3 hold (two flanks, a polygon) gives a ratio of order 1e-2 or more; the normals
        // of a circle computed from node coordinates carry round-off of ~1e-9 (squared here).
        eig.iter().any(|&v| v <= 1e-9 * max)
    })
}
