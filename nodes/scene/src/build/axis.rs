//! Axisymmetric scenes: x is the radius r ≥ 0, and the axis r = 0 holds u_r = 0.

use super::*;

impl Ctx<'_> {
    /// In axisymmetry: refuses a node at r < 0, and prescribes u_r = 0 at every node on the axis
    /// (within 1e-9 of the scene's size), where the hoop strain u_r/r stays finite only so. A
    /// boundary rule prescribing a radial displacement other than 0 there is refused. Other
    /// planes are left as they are.
    pub(crate) fn hold_the_axis(&self, subs: &[Sub], loads: &mut [SubLoads], time: TimeGrid) -> Result<(), SceneError> {
        if self.plane != Plane::Axisymmetric {
            return Ok(());
        }
        let size = subs
            .iter()
            .flat_map(|s| s.mesh.coords.iter())
            .fold(0.0f64, |m, p| m.max(p[0].abs()).max(p[1].abs()));
        let tol = glissade_mechanics::element::AXIS_TOLERANCE * size;
        for (sub, l) in subs.iter().zip(loads.iter_mut()) {
            for (n, p) in sub.mesh.coords.iter().enumerate() {
                self.check(p[0] >= -tol, "plane", || {
                    format!(
                        "axisymmetric: x is the radius r ≥ 0, but `{}` has a node at (x, y) = ({}, {}); move the \
                         part to r ≥ 0",
                        sub.name, p[0], p[1]
                    )
                })?;
                if p[0] > tol {
                    continue;
                }
                let radial = 2 * n;
                if l.constrained[radial] {
                    let moved = (0..time.n_points()).any(|i| {
                        let t = time.t(i);
                        l.loads
                            .iter()
                            .map(|c| c.displacement[radial] * c.time.eval(t))
                            .sum::<f64>()
                            != 0.0
                    });
                    self.check(!moved, "boundary", || {
                        format!(
                            "axisymmetric: a boundary rule prescribes a radial displacement at (x, y) = ({}, {}) of \
                             `{}`, on the axis, where u_r = 0",
                            p[0], p[1], sub.name
                        )
                    })?;
                }
                l.constrained[radial] = true;
            }
        }
        Ok(())
    }
}
