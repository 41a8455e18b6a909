//! Checks of a solution against the discrete problem, from per-subdomain displacements and
//! per-interface fields alone.

use crate::sparse::*;
use crate::{ReferenceError, ReferenceSolution};
use faer::Mat;
use glissade_mechanics::assembly::{stiffness_triplets, AssemblyError};
use glissade_mechanics::laws::dot;
use glissade_mechanics::model::{InterfaceKind, Model};
use glissade_mechanics::scales::{Scales, ROUND_OFF};

/// Largest relative violations of the discrete problem by a solution (see [`verify`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Checks {
    /// F_s: the scene's force scale ([`Scales::of`]: from the loads over the whole history, the
    /// prescribed displacements and gaps, never from the solution checked) (N).
    pub force_scale: f64,
    /// U_s: the scene's displacement scale ([`Scales::of`]) (mm).
    pub displacement_scale: f64,
    /// ‖K_s u_s − f_s − Σ interface nodal forces‖ at non-prescribed dofs / F_s.
    pub equilibrium: f64,
    /// |u − u_d| at prescribed dofs / U_s.
    pub prescribed: f64,
    /// |W_side − u_side(node)| on every interface and |W_a − W_b| on perfect ones / U_s.
    pub continuity: f64,
    /// w·|F_a + F_b| / F_s on every interface.
    pub action_reaction: f64,
    /// max(0, −g) / U_s, g = [W]·n + g0.
    pub penetration: f64,
    /// max(0, λ_n) / F_s (λ = w·F_a, tension is positive on side a).
    pub tension: f64,
    /// min(|λ_n|/F_s, |g|/U_s).
    pub complementarity: f64,
    /// max(0, |λ_t| − f|λ_n|) / F_s.
    pub cone: f64,
    /// min(|Δs|/U_s, |λ_t − f|λ_n| sign Δs|/F_s): no slip, or friction on the cone along the slip.
    pub slip_direction: f64,
}

impl Checks {
    /// The largest of all relative violations.
    pub fn max(&self) -> f64 {
        [
            self.equilibrium,
            self.prescribed,
            self.continuity,
            self.action_reaction,
            self.penetration,
            self.tension,
            self.complementarity,
            self.cone,
            self.slip_direction,
        ]
        .into_iter()
        .fold(0.0, f64::max)
    }
}

/// Contact-law violations of one pair: [penetration, tension, complementarity, cone, slip
/// direction], relative to the force scale `fs` (N) and displacement scale `us` (mm). `round`
/// (mm) is the round-off of the gap and the slip increment ([`ROUND_OFF`] times the magnitudes
/// they are computed from): only the part of |g| and |Δs| beyond it counts. A zero scale makes
/// any nonzero violation infinite.
#[allow(clippy::too_many_arguments)]
pub(crate) fn law_violations(
    lam_n: f64,
    lam_t: f64,
    gap: f64,
    dslip: f64,
    friction: f64,
    fs: f64,
    us: f64,
    round: f64,
) -> [f64; 5] {
    let rel = |v: f64, s: f64| if v == 0.0 { 0.0 } else { v / s };
    let beyond = |v: f64| (v - round).max(0.0);
    let limit = friction * lam_n.abs();
    let slip_force = if dslip == 0.0 { 0.0 } else { limit * dslip.signum() };
    [
        rel(beyond(-gap), us),
        rel(lam_n.max(0.0), fs),
        rel(lam_n.abs(), fs).min(rel(beyond(gap.abs()), us)),
        rel((lam_t.abs() - limit).max(0.0), fs),
        rel(beyond(dslip.abs()), us).min(rel((lam_t - slip_force).abs(), fs)),
    ]
}

/// Checks a solution against the discrete problem of `model`, from the per-subdomain
/// displacements and the per-interface fields alone (no merged numbering, no λ unknowns): every
/// subdomain's equilibrium with the interface nodal forces w·F, the prescribed displacements,
/// trace continuity and action–reaction on every interface, and the contact law on every copy of
/// every contact pair. Scales: the scene's ([`Scales::of`], the same as the Newton stop's).
///
/// A solution of implausible size ([`Scales::implausible`]: displacements beyond both 100 times
/// the scene's size and 1e6 times the displacement scale, or internal, support or interface nodal forces beyond 1e6 times the force scale)
/// is an error naming the first such time point, whatever its residuals.
pub fn verify(model: &Model, sol: &ReferenceSolution) -> Result<Checks, ReferenceError> {
    let nt = model.time.n_points();
    let scales = Scales::of(model);
    let mut ch = Checks {
        force_scale: scales.force,
        displacement_scale: scales.displacement,
        ..Checks::default()
    };
    // Largest displacement and nodal force per time point.
    let mut sizes = vec![(0.0f64, 0.0f64); nt];
    let sub_k: Vec<Csr> = model
        .subdomains
        .iter()
        .map(|sub| {
            Ok(Csr::from_triplets(
                sub.n_dofs(),
                stiffness_triplets(&sub.mesh, sub.material, model.plane)?,
            ))
        })
        .collect::<Result<_, AssemblyError>>()?;
    // |K u − f − interface forces| beyond round-off, and the prescribed values, per subdomain and
    // time.
    let mut residuals: Vec<Vec<Vec<f64>>> = Vec::new();
    let mut prescribed_err = 0.0f64;
    for (s, sub) in model.subdomains.iter().enumerate() {
        let mut per_time = Vec::with_capacity(nt);
        for i in 0..nt {
            let t = model.time.t(i);
            let us: Vec<f64> = (0..sub.n_dofs()).map(|d| sol.u[s][(d, i)]).collect();
            let mut r = vec![0.0; sub.n_dofs()];
            sub_k[s].matvec_into(&us, &mut r);
            // Magnitude of the terms of each residual entry (for its round-off).
            let mut mag = vec![0.0; sub.n_dofs()];
            sub_k[s].abs_matvec_into(&us, &mut mag);
            let size = &mut sizes[i];
            size.0 = us.iter().fold(size.0, |a, v| a.max(v.abs()));
            size.1 = r.iter().fold(size.1, |a, v| a.max(v.abs()));
            let mut ud = vec![0.0; sub.n_dofs()];
            for case in &sub.loads {
                let phi = case.time.eval(t);
                for d in 0..sub.n_dofs() {
                    r[d] -= case.force[d] * phi;
                    mag[d] += (case.force[d] * phi).abs();
                    ud[d] += case.displacement[d] * phi;
                }
            }
            for d in (0..sub.n_dofs()).filter(|&d| sub.constrained[d]) {
                prescribed_err = prescribed_err.max((us[d] - ud[d]).abs());
            }
            for (ki, itf) in model.interfaces.iter().enumerate() {
                let Some(side) = itf.side_of(s) else { continue };
                let fl = &sol.interfaces[ki];
                let f = match side {
                    glissade_mechanics::model::Side::A => &fl.f_a,
                    glissade_mechanics::model::Side::B => &fl.f_b,
                };
                for p in 0..itf.n_pairs() {
                    // The side's nodes at the pair: one, or side b's projection.
                    for (node, k) in itf.trace(side, p) {
                        for c in 0..2 {
                            let nf = k * (itf.weights[p] * f[(2 * p + c, i)]);
                            sizes[i].1 = sizes[i].1.max(nf.abs());
                            r[2 * node + c] -= nf;
                            mag[2 * node + c] += nf.abs();
                        }
                    }
                }
            }
            // The part of each residual beyond its round-off.
            per_time.push(
                r.iter()
                    .zip(&mag)
                    .map(|(v, m)| (v.abs() - ROUND_OFF * m).max(0.0))
                    .collect(),
            );
        }
        residuals.push(per_time);
    }
    for (i, &(u_max, f_max)) in sizes.iter().enumerate() {
        if let Some(reason) = scales.implausible(u_max, f_max) {
            return Err(ReferenceError::Implausible {
                step: i,
                time: model.time.t(i),
                reason,
            });
        }
    }
    let (fs, us) = (ch.force_scale, ch.displacement_scale);
    let rel = |v: f64, s: f64| if v == 0.0 { 0.0 } else { v / s };
    ch.prescribed = rel(prescribed_err, us);
    for (s, sub) in model.subdomains.iter().enumerate() {
        for r in &residuals[s] {
            for (d, &v) in r.iter().enumerate() {
                if !sub.constrained[d] {
                    ch.equilibrium = ch.equilibrium.max(rel(v, fs));
                }
            }
        }
    }
    for (ki, itf) in model.interfaces.iter().enumerate() {
        let fl = &sol.interfaces[ki];
        let contact = match &itf.kind {
            InterfaceKind::Contact { friction, gap } => Some((*friction, gap)),
            InterfaceKind::Perfect => None,
        };
        for p in 0..itf.n_pairs() {
            let a_terms = itf.trace(glissade_mechanics::model::Side::A, p);
            let b_terms = itf.trace(glissade_mechanics::model::Side::B, p);
            let w = itf.weights[p];
            let mut slip_prev = 0.0f64;
            for i in 0..nt {
                let g = |m: &Mat<f64>| [m[(2 * p, i)], m[(2 * p + 1, i)]];
                let (wa, wb, fa, fb) = (g(&fl.w_a), g(&fl.w_b), g(&fl.f_a), g(&fl.f_b));
                for c in 0..2 {
                    let trace = |s: usize, terms: &[(usize, f64)]| {
                        glissade_mechanics::mortar::combine(terms.iter().copied(), |n| sol.u[s][(2 * n + c, i)])
                    };
                    let (ua, ub) = (trace(itf.a, &a_terms), trace(itf.b, &b_terms));
                    let mut e = (wa[c] - ua).abs().max((wb[c] - ub).abs());
                    if contact.is_none() {
                        e = e.max((wa[c] - wb[c]).abs());
                    }
                    ch.continuity = ch.continuity.max(rel(e, us));
                    ch.action_reaction = ch.action_reaction.max(rel(w * (fa[c] + fb[c]).abs(), fs));
                }
                if let Some((friction, gap0)) = contact {
                    let jump = [wb[0] - wa[0], wb[1] - wa[1]];
                    let lam = [w * fa[0], w * fa[1]];
                    let slip = dot(jump, itf.tangent(p));
                    let round = ROUND_OFF
                        * (wa[0].abs().max(wa[1].abs())
                            + wb[0].abs().max(wb[1].abs())
                            + gap0[p].abs()
                            + slip_prev.abs());
                    let v = law_violations(
                        dot(lam, itf.normal(p)),
                        dot(lam, itf.tangent(p)),
                        dot(jump, itf.normal(p)) + gap0[p],
                        slip - slip_prev,
                        friction,
                        fs,
                        us,
                        round,
                    );
                    slip_prev = slip;
                    ch.penetration = ch.penetration.max(v[0]);
                    ch.tension = ch.tension.max(v[1]);
                    ch.complementarity = ch.complementarity.max(v[2]);
                    ch.cone = ch.cone.max(v[3]);
                    ch.slip_direction = ch.slip_direction.max(v[4]);
                }
            }
        }
    }
    Ok(ch)
}
