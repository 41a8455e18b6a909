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
