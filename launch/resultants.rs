//! Interface resultants (docs/outputs.md, "Interface resultants"): per interface and time point,
//! the force the interface carries, summed over its node pairs, and on contact interfaces the
//! share of its length that is separated, stuck and slipping. What an engineer plots against
//! the load: the tangential resultant reaching f times the normal one is the joint slipping.

use crate::output::{checked_solution, csv_field, pair_values};
use crate::Result;
use glissade_mechanics::model::Model;
use glissade_messages::InterfaceSolution;
use serde::Serialize;

/// One interface's resultants at every time point. Forces are per unit thickness (N/mm): Σ w·f
/// over the pairs, w the pair's lumped length (mm), f the traction on side a (MPa).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InterfaceResultants {
    pub interface: usize,
    pub a: String,
    pub b: String,
    pub contact: bool,
    /// The force side b exerts on side a, global x and y, per time point (N/mm).
    pub force_a: Vec<[f64; 2]>,
    /// Σ w·f_n (N/mm): negative in compression.
    pub normal: Vec<f64>,
    /// Σ w·f_t (N/mm), along each pair's tangent.
    pub tangential: Vec<f64>,
    /// Contact interfaces: the shares of the interface's length (Σ w) separated, stuck and
    /// slipping, per time point (0 to 1, summing to 1); empty on perfect interfaces.
    pub shares: Vec<[f64; 3]>,
}

/// The resultants of every interface of a run's final solution `interfaces` (s, with the
/// statuses of ŝ), in interface order.
pub fn resultants(model: &Model, interfaces: &[InterfaceSolution]) -> Result<Vec<InterfaceResultants>> {
    let nt = model.time.n_points();
    let mut out = Vec::with_capacity(interfaces.len());
    for sol in interfaces {
        let k = sol.interface as usize;
        let itf = checked_solution(model, sol)?;
        let np = itf.n_pairs();
        let length: f64 = itf.weights.iter().sum();
        let mut r = InterfaceResultants {
            interface: k,
            a: model.subdomains[itf.a].name.clone(),
            b: model.subdomains[itf.b].name.clone(),
            contact: itf.is_contact(),
            force_a: Vec::with_capacity(nt),
            normal: Vec::with_capacity(nt),
            tangential: Vec::with_capacity(nt),
            shares: Vec::new(),
        };
        for i in 0..nt {
            let (mut f, mut n, mut t, mut share) = ([0.0; 2], 0.0, 0.0, [0.0; 3]);
            for (p, &w) in itf.weights.iter().enumerate() {
                let [f_n, f_t, _, _] = pair_values(itf, sol, i, p);
                f[0] += w * sol.f_a.get(2 * p, i);
                f[1] += w * sol.f_a.get(2 * p + 1, i);
                n += w * f_n;
                t += w * f_t;
                if itf.is_contact() {
                    share[sol.status[i * np + p] as usize] += w / length;
                }
            }
            r.force_a.push(f);
            r.normal.push(n);
            r.tangential.push(t);
            if itf.is_contact() {
                r.shares.push(share);
            }
        }
        out.push(r);
    }
    Ok(out)
}

/// The resultants as CSV, one row per interface and time point; units in the header.
pub fn resultants_csv(model: &Model, all: &[InterfaceResultants]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "time_s,interface,a,b,kind,force_a_x_N_per_mm,force_a_y_N_per_mm,normal_N_per_mm,tangential_N_per_mm,separated_share,stick_share,slip_share\n",
    );
    for i in 0..model.time.n_points() {
        let t = model.time.t(i);
        for r in all {
            let kind = if r.contact { "contact" } else { "perfect" };
            let shares = r
                .shares
                .get(i)
                .map_or(",,".to_string(), |[o, st, sl]| format!("{o:?},{st:?},{sl:?}"));
            let _ = writeln!(
                s,
                "{t:?},{},{},{},{kind},{:?},{:?},{:?},{:?},{shares}",
                r.interface,
                csv_field(&r.a),
                csv_field(&r.b),
                r.force_a[i][0],
                r.force_a[i][1],
                r.normal[i],
                r.tangential[i],
            );
        }
    }
    s
}

/// The console's lines for the contact interfaces at the last time point (at most `max`
/// interfaces; the rest counted): normal and tangential resultants, their ratio, the shares.
pub fn console_lines(model: &Model, all: &[InterfaceResultants], max: usize) -> Vec<String> {
    let last = model.time.n_points() - 1;
    let t = model.time.t(last);
    let contact: Vec<&InterfaceResultants> = all.iter().filter(|r| r.contact).collect();
    let mut lines: Vec<String> = contact
        .iter()
        .take(max)
        .map(|r| {
            let (n, tg) = (r.normal[last], r.tangential[last]);
            let [o, st, sl] = r.shares[last];
            let ratio = if n != 0.0 {
                format!("{:.3}", (tg / n).abs())
            } else {
                "—".into()
            };
            format!(
                "interface {} ({} | {}) at t = {t}: N = {n:.4e} N/mm, T = {tg:.4e} N/mm, |T/N| = {ratio}; \
                 {:.0} % separated, {:.0} % stick, {:.0} % slip",
                r.interface,
                r.a,
                r.b,
                100.0 * o,
                100.0 * st,
                100.0 * sl
            )
        })
        .collect();
    if contact.len() > max {
        lines.push(format!(
            "… and {} more contact interfaces (every interface and time point in the resultants CSV)",
            contact.len() - max
        ));
    }
    lines
}

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

/// The rules' forces as CSV, one row per rule and time point; units in the header.
pub fn boundary_csv(model: &Model, all: &[RuleResultants]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "time_s,rule,kind,force_x_N_per_mm,force_y_N_per_mm,moment_N,about_x_mm,about_y_mm,prescribed_ux_mm,prescribed_uy_mm\n",
    );
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:?}"));
    for i in 0..model.time.n_points() {
        let t = model.time.t(i);
        for r in all {
            let kind = match r.kind {
                RuleKind::Support => "support",
                RuleKind::Load => "load",
            };
            let _ = writeln!(
                s,
                "{t:?},{},{kind},{:?},{:?},{:?},{:?},{:?},{},{}",
                csv_field(&r.rule),
                r.force[i][0],
                r.force[i][1],
                r.moment[i],
                r.about[0],
                r.about[1],
                opt(r.displacement[i][0]),
                opt(r.displacement[i][1]),
            );
        }
    }
    s
}

/// The console's lines for the supports at the last time point, with each one's largest
/// reaction over the time points (at most `max` supports; the rest counted).
pub fn boundary_console_lines(model: &Model, all: &[RuleResultants], max: usize) -> Vec<String> {
    let supports: Vec<&RuleResultants> = all.iter().filter(|r| r.kind == RuleKind::Support).collect();
    let last = model.time.n_points() - 1;
    let mut lines: Vec<String> = supports
        .iter()
        .take(max)
        .map(|r| {
            let norm = |f: &[f64; 2]| f[0].hypot(f[1]);
            let peak = (0..r.force.len())
                .max_by(|&a, &b| norm(&r.force[a]).total_cmp(&norm(&r.force[b])))
                .unwrap_or(0);
            let u = match r.displacement[last] {
                [None, None] => String::new(),
                [x, y] => {
                    let c = |v: Option<f64>| v.map_or("free".to_string(), |v| format!("{v:.4e}"));
                    format!("; prescribed u = ({}, {}) mm", c(x), c(y))
                }
            };
            format!(
                "support {} at t = {}: R = ({:.4e}, {:.4e}) N/mm, M = {:.4e} N about ({}, {}){u}; largest |R| {:.4e} N/mm at t = {}",
                r.rule,
                model.time.t(last),
                r.force[last][0],
                r.force[last][1],
                r.moment[last],
                r.about[0],
                r.about[1],
                norm(&r.force[peak]),
                model.time.t(peak)
            )
        })
        .collect();
    if supports.len() > max {
        lines.push(format!(
            "… and {} more supports (every rule and time point in the boundaries CSV)",
            supports.len() - max
        ));
    }
    lines
}
