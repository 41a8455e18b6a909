//! Interface resultants (docs/outputs.md, "resultants.csv"): per interface and time point,
//! the force the interface carries, summed over its node pairs, and on contact interfaces the
//! share of its length in each reported status (separated, stuck, slipping, at the friction
//! limit, grazing: `glissade_mechanics::settled`). What an engineer plots against
//! the load: the tangential resultant reaching f times the normal one is the joint slipping.

use crate::output::{checked_solution, csv_field, pair_values};
use crate::Result;
use glissade_mechanics::model::Model;
use glissade_mechanics::settled::SETTLED_NAMES;
use glissade_messages::InterfaceSolution;
use serde::Serialize;

pub use crate::boundary::{boundary_resultants, RuleKind, RuleResultants};

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
    /// Contact interfaces: the shares of the interface's length (Σ w) in each reported status
    /// (separated, stick, slip, limit, grazing), per time point (0 to 1, summing to 1); empty on
    /// perfect interfaces.
    pub shares: Vec<[f64; 5]>,
}

/// The resultants of every interface of a run's final solution `interfaces` (s, with the
/// reported statuses), in interface order.
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
            let (mut f, mut n, mut t, mut share) = ([0.0; 2], 0.0, 0.0, [0.0; 5]);
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
    let u = model.plane.force_column_unit();
    let mut s = format!(
        "time_s,interface,a,b,kind,force_a_x_{u},force_a_y_{u},normal_{u},tangential_{u},separated_share,stick_share,slip_share,limit_share,grazing_share\n",
    );
    for i in 0..model.time.n_points() {
        let t = model.time.t(i);
        for r in all {
            let kind = if r.contact { "contact" } else { "perfect" };
            let shares = r.shares.get(i).map_or(",,,,".to_string(), |[o, st, sl, li, gr]| {
                format!("{o:?},{st:?},{sl:?},{li:?},{gr:?}")
            });
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
    let unit = model.plane.force_unit();
    let mut lines: Vec<String> = contact
        .iter()
        .take(max)
        .map(|r| {
            let (n, tg) = (r.normal[last], r.tangential[last]);
            let ratio = if n != 0.0 {
                format!("{:.3}", (tg / n).abs())
            } else {
                "—".into()
            };
            // The shares in words; the statuses within the margins only where there are some.
            let shares: Vec<String> = r.shares[last]
                .iter()
                .zip(SETTLED_NAMES)
                .enumerate()
                .filter(|(k, (v, _))| *k < 3 || **v > 0.0)
                .map(|(_, (v, name))| format!("{:.0} % {name}", 100.0 * v))
                .collect();
            format!(
                "interface {} ({} | {}) at t = {t}: N = {n:.4e} {unit}, T = {tg:.4e} {unit}, |T/N| = {ratio}; {}",
                r.interface,
                r.a,
                r.b,
                shares.join(", ")
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

/// The rules' forces as CSV, one row per rule and time point; units in the header.
pub fn boundary_csv(model: &Model, all: &[RuleResultants]) -> String {
    use std::fmt::Write as _;
    let u = model.plane.force_column_unit();
    let mut s = format!(
        "time_s,rule,kind,force_x_{u},force_y_{u},moment_N,about_x_mm,about_y_mm,prescribed_ux_mm,prescribed_uy_mm\n",
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
    let unit = model.plane.force_unit();
    let mut lines: Vec<String> = supports
        .iter()
        .take(max)
        .map(|r| {
            // In axisymmetry a support's radial force and moment are not resultants (NaN): the
            // axial force alone is said.
            let peak = (0..r.force.len())
                .max_by(|&a, &b| r.magnitude(a).total_cmp(&r.magnitude(b)))
                .unwrap_or(0);
            let value = |v: f64| {
                if v.is_finite() {
                    format!("{v:.4e}")
                } else {
                    "—".to_string()
                }
            };
            let moment = if r.moment[last].is_finite() {
                format!(", M = {:.4e} N about ({}, {})", r.moment[last], r.about[0], r.about[1])
            } else {
                String::new()
            };
            let u = match r.displacement[last] {
                [None, None] => String::new(),
                [x, y] => {
                    let c = |v: Option<f64>| v.map_or("free".to_string(), |v| format!("{v:.4e}"));
                    format!("; prescribed u = ({}, {}) mm", c(x), c(y))
                }
            };
            format!(
                "support {} at t = {}: R = ({}, {}) {unit}{moment}{u}; largest |R| {:.4e} {unit} at t = {}",
                r.rule,
                model.time.t(last),
                value(r.force[last][0]),
                value(r.force[last][1]),
                r.magnitude(peak),
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

/// For a run that did not converge: the contact interfaces that slip over their whole length at
/// some time point (every pair not separated slips), each with the first such time point, said as what it likely means (a part
/// whose loads exceed what friction and its supports hold has no equilibrium, and LATIN then
/// stalls with every pair slipping).
pub fn whole_slip_lines(model: &Model, all: &[InterfaceResultants], max: usize) -> Vec<String> {
    let slipping: Vec<(&InterfaceResultants, usize)> = all
        .iter()
        .filter(|r| r.contact)
        .filter_map(|r| {
            r.shares
                .iter()
                .position(|s| glissade_studies::quantities::closed_slip_share(s[2], s[0] + s[4]) >= 1.0 - 1e-9)
                .map(|i| (r, i))
        })
        .collect();
    let mut lines: Vec<String> = slipping
        .iter()
        .take(max)
        .map(|(r, i)| {
            format!(
                "interface {} ({} | {}) slips over its whole length from t = {}: the loads there may exceed what \
                 friction and the supports hold (no equilibrium: a part would slide or turn away, and the iteration \
                 stalls); `glissade onset <scene> --rule <k>` finds the factor on a load at which it begins",
                r.interface,
                r.a,
                r.b,
                model.time.t(*i)
            )
        })
        .collect();
    if slipping.len() > max {
        lines.push(format!(
            "… and {} more interfaces slipping over their whole length",
            slipping.len() - max
        ));
    }
    lines
}

/// The boundary forces as an SVG plot: the load–displacement curves (each support's reaction
/// against its prescribed displacement, along the component that moves most) when a support's
/// prescribed displacement varies in time, otherwise every rule's force components against time.
pub fn boundary_svg(model: &Model, all: &[RuleResultants]) -> String {
    use glissade_studies::plot::{line_plot, Line};
    let axis = ["x", "y"];
    let mut curves = Vec::new();
    for r in all.iter().filter(|r| r.kind == RuleKind::Support) {
        let range = |c: usize| {
            let v: Vec<f64> = r.displacement.iter().filter_map(|d| d[c]).collect();
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max) - v.iter().copied().fold(f64::INFINITY, f64::min)
        };
        let c = if range(1) > range(0) { 1 } else { 0 };
        if range(c) > 0.0 {
            curves.push(Line {
                label: format!("{}: R{} against u{}", r.rule, axis[c], axis[c]),
                points: r
                    .displacement
                    .iter()
                    .zip(&r.force)
                    .filter_map(|(d, f)| d[c].map(|u| (u, f[c])))
                    .collect(),
            });
        }
    }
    if !curves.is_empty() {
        return line_plot(
            &format!("{}: load–displacement", model.name),
            "prescribed displacement (mm)",
            &format!("reaction ({})", model.plane.force_unit()),
            &curves,
        );
    }
    let times: Vec<f64> = (0..model.time.n_points()).map(|i| model.time.t(i)).collect();
    let lines: Vec<Line> = all
        .iter()
        .flat_map(|r| {
            let times = &times;
            (0..2).map(move |c| Line {
                label: format!("{} F{}", r.rule, axis[c]),
                points: times.iter().zip(&r.force).map(|(&t, f)| (t, f[c])).collect(),
            })
        })
        .collect();
    line_plot(
        &format!("{}: boundary forces (reactions and loads)", model.name),
        "t (s)",
        &format!("force ({})", model.plane.force_unit()),
        &lines,
    )
}
