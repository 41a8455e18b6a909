//! Force and displacement scales of a scene, from the scene alone (its loads over the whole time
//! history, its prescribed displacements, gaps, materials and size): what the reference's checks
//! are relative to, the bounds beyond which a solution is implausible, and the traction scale
//! against which a run tells contact forces from round-off.

use crate::model::{InterfaceKind, Model};

/// A solution whose displacement exceeds this many times the scene's size, and also
/// [`LOAD_DISPLACEMENT_BOUND`] times the displacement scale its loads give, is refused: linear
/// elasticity has no meaning there (strains and rotations of order 100) unless the loads
/// themselves ask for it (a scene whose loads are a million times too large gets the linear
/// answer to them, as LATIN does), and a part left floating (a singular stiffness) solves to
/// displacements many decades beyond both.
pub const DISPLACEMENT_BOUND: f64 = 100.0;

/// See [`DISPLACEMENT_BOUND`]: the factor over U_s (a slender part's deflection is up to
/// 4 (L/H)³ times P/E, 4e6 at L/H = 100: the bound over the size holds such parts).
pub const LOAD_DISPLACEMENT_BOUND: f64 = 1e6;

/// A solution whose nodal forces (internal forces K u, reactions, contact forces) exceed this many
/// times the force scale is refused. Internal forces exceed the applied loads by lever arms
/// (about L/H in a slender part under bending: 10 in the laminates of the tests), far below it.
pub const FORCE_BOUND: f64 = 1e6;

/// Relative round-off allowed in a computed residual: a check counts only the part of a violation
/// beyond `ROUND_OFF` times the sum of the magnitudes of the terms it is computed from
/// (Σ_j |K_dj u_j| + |f_d| + |contact forces at d| for an equilibrium row; |u_A| + |u_B| + |g0|
/// (+ the previous slip) for a gap or a slip increment). 8ε is √n ε for the ≤ 64 terms of a row
/// (the usual estimate of the round-off of a sum). Where displacements are dominated by a rigid
/// rotation (a cantilever bent to 30–90 mm under loads of 200 N) the terms of K u cancel to
/// 1e-6 of their magnitude, and the round-off of K u is then above 1e-10 of the loads.
pub const ROUND_OFF: f64 = 8.0 * f64::EPSILON;

/// Strain of the floor of both scales: a scene without any load or prescribed motion (the
/// solution is zero) still has positive scales, E_max·D·1e-12 N and D·1e-12 mm.
const STRAIN_FLOOR: f64 = 1e-12;

/// Scales of one scene (see [`Scales::of`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scales {
    /// F_s (N).
    pub force: f64,
    /// U_s (mm).
    pub displacement: f64,
    /// D: the largest side of the bounding box of every node of the scene (mm).
    pub size: f64,
    /// The thickness forces are per: 1 mm in plane strain and stress; in axisymmetry, where
    /// forces are totals over the circumference, the circumference 2π·r_max at the scene's
    /// largest radius (mm).
    pub thickness: f64,
}

impl Scales {
    /// With P = max over the time points of Σ |f| (every subdomain's nodal loads: the total
    /// applied load, N), U_d = max |prescribed displacement| over the time points and
    /// |g0| over the contact pairs (mm), E_min, E_max the extreme Young moduli and D the scene's
    /// size:
    /// - F_s = max(P, E_max·U_d, 1e-12·E_max·D): the loads, or the force with which a prescribed
    ///   motion or interference of size U_d strains a unit-thickness part (stress E·U_d/D over a
    ///   section of size D);
    /// - U_s = max(U_d, P/E_min, 1e-12·D): the prescribed motion, or the displacement of a part
    ///   of size D under the mean traction P/D (strain P/(D·E_min)).
    ///
    /// In axisymmetry P is a total over the circumference: the forces of a strain are taken over
    /// the thickness 2π·r_max (F_s = max(P, E_max·U_d·t, 1e-12·E_max·D·t), U_s = max(U_d,
    /// P/(E_min·t), 1e-12·D)), so that both scales mean what they mean in a plane problem.
    ///
    /// Maxima over the whole history, so a time point of zero load is checked against the same
    /// (positive) scales as the loaded ones. Neither depends on the solution checked.
    pub fn of(model: &Model) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for sub in &model.subdomains {
            for x in &sub.mesh.coords {
                for c in 0..2 {
                    lo[c] = lo[c].min(x[c]);
                    hi[c] = hi[c].max(x[c]);
                }
            }
        }
        let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.0);
        let thickness = model.plane.measure([hi[0].max(0.0), 0.0]);
        let e_min = model
            .subdomains
            .iter()
            .map(|s| s.material.e)
            .fold(f64::INFINITY, f64::min);
        let e_max = model.subdomains.iter().map(|s| s.material.e).fold(0.0, f64::max);
        let mut load = 0.0f64;
        let mut motion = 0.0f64;
        for i in 0..model.time.n_points() {
            let t = model.time.t(i);
            let mut total = 0.0;
            for sub in &model.subdomains {
                let mut f = vec![0.0; sub.n_dofs()];
                let mut ud = vec![0.0; sub.n_dofs()];
                for case in &sub.loads {
                    let phi = case.time.eval(t);
                    for d in 0..sub.n_dofs() {
                        f[d] += case.force[d] * phi;
                        ud[d] += case.displacement[d] * phi;
                    }
                }
                total += f.iter().map(|v| v.abs()).sum::<f64>();
                for d in (0..sub.n_dofs()).filter(|&d| sub.constrained[d]) {
                    motion = motion.max(ud[d].abs());
                }
            }
            load = load.max(total);
        }
        for itf in &model.interfaces {
            if let InterfaceKind::Contact { gap, .. } = &itf.kind {
                motion = gap.iter().fold(motion, |a, g| a.max(g.abs()));
            }
        }
        Self {
            force: load
                .max(e_max * motion * thickness)
                .max(STRAIN_FLOOR * e_max * size * thickness),
            displacement: motion.max(load / (e_min * thickness)).max(STRAIN_FLOOR * size),
            size,
            thickness,
        }
    }

    /// T_s = F_s / (D·t) (MPa): the traction of the force scale spread over the scene's size (and
    /// its thickness t, [`Self::thickness`]). Contact
    /// tractions below 1e-12 of it are round-off; a run whose local stage finds every contact
    /// point separated takes the forces its linear stage still carries for round-off only below
    /// the accuracy times this ([`crate::model::SolverParams`]' stop rule).
    pub fn traction(&self) -> f64 {
        if self.size > 0.0 {
            self.force / (self.size * self.thickness)
        } else {
            self.force
        }
    }

    /// Why a solution of largest displacement `u_max` (mm) and largest nodal force `f_max` (N)
    /// is implausible (see [`DISPLACEMENT_BOUND`], [`FORCE_BOUND`]; NaN is implausible), or None.
    pub fn implausible(&self, u_max: f64, f_max: f64) -> Option<String> {
        if u_max.is_nan()
            || (u_max > DISPLACEMENT_BOUND * self.size && u_max > LOAD_DISPLACEMENT_BOUND * self.displacement)
        {
            Some(format!(
                "a displacement of {u_max:.3e} mm, beyond {DISPLACEMENT_BOUND} times the scene's size {:.3e} mm \
                 and {LOAD_DISPLACEMENT_BOUND:e} times the displacement its loads give, {:.3e} mm (a singular \
                 stiffness solves to such displacements: a part held by nothing but contact across an open \
                 gap, or by nothing but friction under a load larger than the friction can hold, so that it \
                 slides away as a whole)",
                self.size, self.displacement
            ))
        } else if f_max.is_nan() || f_max > FORCE_BOUND * self.force {
            Some(format!(
                "a nodal force of {f_max:.3e} N, beyond {FORCE_BOUND:e} times the scene's force scale {:.3e} N",
                self.force
            ))
        } else {
            None
        }
    }
}
