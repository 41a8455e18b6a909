//! The report's SVG plots: errors against wall time (`<scene>-report.svg`), the PGD basis sizes
//! per iteration, and η, the errors and basis sizes of several variants against the iterations
//! (`<scene>-iterations.svg`, the paper's Figure 4); their axes' ticks.

use super::{variant_name, Report, ReportPoint};

/// A curve of the plot: name, colour, dash pattern, value per point.
type Series = (
    &'static str,
    &'static str,
    &'static str,
    Box<dyn Fn(&ReportPoint) -> f64>,
);

/// SVG plot of the errors and indicators against wall time (log scale), with the reference's
/// run time marked; with PGD, the basis size of every subdomain against the iterations under it.
pub fn plot_svg(report: &Report, time_axis: TimeAxis) -> String {
    let errors = plot_errors_svg(report, time_axis);
    match plot_basis_svg(report) {
        None => errors,
        Some(basis) => format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"900\" height=\"{}\">\n<svg y=\"0\">{errors}</svg>\n<svg y=\"560\">{basis}</svg>\n</svg>\n",
            560 + 400
        ),
    }
}

/// Basis size per subdomain against the iterations (the PGD run's "Figure 4b"); None without PGD.
pub fn plot_basis_svg(report: &Report) -> Option<String> {
    let n_sub = report.points.iter().map(|p| p.basis_sizes.len()).max().unwrap_or(0);
    if n_sub == 0 {
        return None;
    }
    let (w, h) = (900.0, 400.0);
    let (left, right, top, bottom) = (80.0, 200.0, 40.0, 60.0);
    let it_max = report.points.iter().map(|p| p.iteration).max().unwrap_or(1).max(1) as f64;
    let m_max = report
        .points
        .iter()
        .flat_map(|p| p.basis_sizes.iter().copied())
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let x = |i: f64| left + (w - left - right) * i / it_max;
    let y = |m: f64| top + (h - top - bottom) * (1.0 - m / m_max);
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{}" y="22" font-size="15" text-anchor="middle">{}: PGD basis size per subdomain ({})</text>
<rect x="{left}" y="{top}" width="{}" height="{}" fill="none" stroke="black"/>
"#,
        (left + w - right) / 2.0,
        report.scene,
        report.linear_stage,
        w - left - right,
        h - top - bottom
    );
    for k in 0..=5 {
        let (i, m) = (it_max * k as f64 / 5.0, m_max * k as f64 / 5.0);
        svg += &format!(
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{i:.0}</text><text x=\"{}\" y=\"{}\" text-anchor=\"end\">{m:.0}</text>\n",
            x(i),
            h - bottom + 18.0,
            left - 6.0,
            y(m) + 4.0
        );
    }
    svg += &format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">LATIN iteration</text>\n",
        (left + w - right) / 2.0,
        h - 15.0
    );
    for s in 0..n_sub {
        let colour = COLOURS[s % COLOURS.len()];
        let pts: Vec<String> = report
            .points
            .iter()
            .filter_map(|p| {
                p.basis_sizes
                    .get(s)
                    .map(|&m| format!("{:.2},{:.2}", x(p.iteration as f64), y(m as f64)))
            })
            .collect();
        svg += &format!(
            "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.5\" points=\"{}\"/>\n",
            pts.join(" ")
        );
        let ly = top + 10.0 + 16.0 * s as f64;
        if ly < h - bottom {
            svg += &format!(
                "<line x1=\"{}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{colour}\" stroke-width=\"2\"/><text x=\"{}\" y=\"{}\">subdomain {}</text>\n",
                w - right + 10.0,
                w - right + 30.0,
                w - right + 35.0,
                ly + 4.0,
                s + 1
            );
        }
    }
    svg += "</svg>\n";
    Some(svg)
}

/// Colours of the curves of several reports or subdomains.
const COLOURS: [&str; 10] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
];

/// The paper's Figure 4 from one or several reports of a scene, against the LATIN iterations:
/// (a) η (solid) and the contact-traction error against the reference (dashed) of every report;
/// (b) the PGD basis size of the chosen `subdomains` (1-based, as the scene files number them;
/// those the scene does not have are skipped) of every PGD report, one dash pattern per
/// subdomain. Panel (b) is left out when no report is PGD.
pub fn plot_iterations_svg(reports: &[Report], subdomains: &[usize]) -> String {
    let (ha, hb) = (520.0, 420.0);
    let it_max = reports
        .iter()
        .flat_map(|r| r.points.iter().map(|p| p.iteration))
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let ax = IterationAxis {
        w: 1100.0,
        left: 80.0,
        right: 440.0,
        top: 40.0,
        bottom: 60.0,
        it_max,
    };
    let (w, left, right, top, bottom) = (ax.w, ax.left, ax.right, ax.top, ax.bottom);
    let title = reports.first().map_or("", |r| r.scene.as_str());
    // (a): log axis over every plotted value.
    let values: Vec<f64> = reports
        .iter()
        .flat_map(|r| r.points.iter().flat_map(|p| [p.eta, p.traction_error]))
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    let (lo, hi) = log_decades(&values);
    let ya = |v: f64| top + (ha - top - bottom) * (hi - v.max(1e-300).log10()) / (hi - lo).max(1.0);
    let pgd: Vec<(usize, &Report)> = reports
        .iter()
        .enumerate()
        .filter(|(_, r)| r.points.iter().any(|p| !p.basis_sizes.is_empty()))
        .collect();
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n",
        if pgd.is_empty() { ha } else { ha + hb }
    );
    svg += &format!(
        "<text x=\"{}\" y=\"22\" font-size=\"15\" text-anchor=\"middle\">{title}: (a) η (solid) and contact-traction error against the reference (dashed)</text>\n<rect x=\"{left}\" y=\"{top}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>\n",
        (left + w - right) / 2.0,
        w - left - right,
        ha - top - bottom
    );
    svg += &decade_lines((lo, hi), ya, left, w - right);
    ax.ticks(&mut svg, ha - bottom);
    for (k, r) in reports.iter().enumerate() {
        let colour = COLOURS[k % COLOURS.len()];
        for (dash, f) in [
            ("", (|p: &ReportPoint| p.eta) as fn(&ReportPoint) -> f64),
            ("6,3", |p| p.traction_error),
        ] {
            let pts = r
                .points
                .iter()
                .filter(|p| f(p) > 0.0 && f(p).is_finite())
                .map(|p| format!("{:.2},{:.2}", ax.x(p.iteration as f64), ya(f(p))))
                .collect();
            svg += &polyline(pts, colour, dash);
        }
        let ly = top + 10.0 + 30.0 * k as f64;
        svg += &format!(
            "<line x1=\"{}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{colour}\" stroke-width=\"2\"/><text x=\"{}\" y=\"{}\" font-size=\"10\">{}</text>\n",
            w - right + 8.0,
            w - right + 28.0,
            w - right + 32.0,
            ly + 4.0,
            escape(&short_name(r))
        );
    }
    if !pgd.is_empty() {
        basis_panel(&mut svg, &ax, &pgd, subdomains, (ha, hb));
    }
    svg += "</svg>\n";
    svg
}

/// The iteration axis both panels of [`plot_iterations_svg`] share, and their margins.
struct IterationAxis {
    w: f64,
    left: f64,
    right: f64,
    top: f64,
    bottom: f64,
    it_max: f64,
}

impl IterationAxis {
    fn x(&self, i: f64) -> f64 {
        self.left + (self.w - self.left - self.right) * i / self.it_max
    }

    /// The iteration ticks and the axis' name under a panel whose bottom is at `y0`.
    fn ticks(&self, svg: &mut String, y0: f64) {
        for (i, label) in linear_ticks(self.it_max) {
            svg.push_str(&format!(
                "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{label}</text>\n",
                self.x(i),
                y0 + 18.0
            ));
        }
        svg.push_str(&format!(
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">LATIN iteration</text>\n",
            (self.left + self.w - self.right) / 2.0,
            y0 + 40.0
        ));
    }
}

/// A curve through `pts` ("x,y" each).
fn polyline(pts: Vec<String>, colour: &str, dash: &str) -> String {
    format!(
        "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.6\" stroke-dasharray=\"{dash}\" points=\"{}\"/>\n",
        pts.join(" ")
    )
}

/// Panel (b) of [`plot_iterations_svg`], from `y0` down `hb` (`(y0, hb)`): the PGD basis sizes of
/// the chosen `subdomains` of every PGD report (`pgd`: its index among the reports, for its
/// colour), one dash pattern per subdomain.
fn basis_panel(
    svg: &mut String,
    ax: &IterationAxis,
    pgd: &[(usize, &Report)],
    subdomains: &[usize],
    (y0, hb): (f64, f64),
) {
    let (w, left, right, top, bottom) = (ax.w, ax.left, ax.right, ax.top, ax.bottom);
    let chosen = |r: &Report| -> Vec<usize> {
        let n = r.points.iter().map(|p| p.basis_sizes.len()).max().unwrap_or(0);
        subdomains.iter().copied().filter(|s| (1..=n).contains(s)).collect()
    };
    let m_max = pgd
        .iter()
        .flat_map(|(_, r)| {
            let c = chosen(r);
            r.points.iter().flat_map(move |p| {
                c.iter()
                    .filter_map(|s| p.basis_sizes.get(s - 1).copied())
                    .collect::<Vec<_>>()
            })
        })
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let yb = |m: f64| y0 + top + (hb - top - bottom) * (1.0 - m / m_max);
    let names: Vec<String> = subdomains.iter().map(|s| s.to_string()).collect();
    *svg += &format!(
        "<text x=\"{}\" y=\"{}\" font-size=\"15\" text-anchor=\"middle\">(b) PGD basis size of subdomains {} (dash pattern per subdomain)</text>\n<rect x=\"{left}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"black\"/>\n",
        (left + w - right) / 2.0,
        y0 + 22.0,
        names.join(" and "),
        y0 + top,
        w - left - right,
        hb - top - bottom
    );
    for (m, label) in linear_ticks(m_max) {
        *svg += &format!(
            "<line x1=\"{left}\" y1=\"{0}\" x2=\"{1}\" y2=\"{0}\" stroke=\"#eee\"/><text x=\"{2}\" y=\"{3}\" text-anchor=\"end\">{label}</text>\n",
            yb(m),
            w - right,
            left - 6.0,
            yb(m) + 4.0
        );
    }
    ax.ticks(svg, y0 + hb - bottom);
    const DASHES: [&str; 4] = ["", "6,3", "2,3", "10,3,2,3"];
    let mut row = 0;
    for &(k, r) in pgd {
        let colour = COLOURS[k % COLOURS.len()];
        for (j, s) in chosen(r).into_iter().enumerate() {
            let dash = DASHES[j % DASHES.len()];
            let pts = r
                .points
                .iter()
                .filter_map(|p| {
                    p.basis_sizes
                        .get(s - 1)
                        .map(|&m| format!("{:.2},{:.2}", ax.x(p.iteration as f64), yb(m as f64)))
                })
                .collect();
            *svg += &polyline(pts, colour, dash);
            let ly = y0 + top + 10.0 + 16.0 * row as f64;
            row += 1;
            if ly < y0 + hb - bottom {
                *svg += &format!(
                    "<line x1=\"{}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{colour}\" stroke-width=\"2\" stroke-dasharray=\"{dash}\"/><text x=\"{}\" y=\"{}\" font-size=\"10\">subdomain {s}: {}</text>\n",
                    w - right + 8.0,
                    w - right + 28.0,
                    w - right + 32.0,
                    ly + 4.0,
                    escape(&short_name(r))
                );
            }
        }
    }
}

/// [`variant_name`] without the defaults a legend need not repeat (frozen macro modes off).
fn short_name(report: &Report) -> String {
    variant_name(report).replace(", macro modes off", "")
}

/// Text for an SVG element (`&`, `<`, `>` escaped).
fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// The wall-time axis of the report's plot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TimeAxis {
    #[default]
    Linear,
    /// Logarithmic: the first iterations and the reference apart when they are far apart.
    Log,
}

/// Ticks of a linear axis from 0 to `max`: steps of 1, 2 or 5 × 10ᵏ, at most about 6, each
/// label with as many decimals as the step needs (so no two labels are equal).
pub fn linear_ticks(max: f64) -> Vec<(f64, String)> {
    if !(max > 0.0 && max.is_finite()) {
        return vec![(0.0, "0".into())];
    }
    let raw = max / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    (0..)
        .map(|k| k as f64 * step)
        .take_while(|v| *v <= max * (1.0 + 1e-12))
        .map(|v| (v, format!("{v:.decimals$}")))
        .collect()
}

/// The whole decades (log10, floor and ceiling) a log axis spans to hold `values` (positive and
/// finite), at least one decade and never below 1e-16.
fn log_decades(values: &[f64]) -> (f64, f64) {
    let lo = values
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
        .max(1e-16)
        .log10()
        .floor();
    let hi = values
        .iter()
        .cloned()
        .fold(0.0f64, f64::max)
        .max(10f64.powf(lo + 1.0))
        .log10()
        .ceil();
    (lo, hi)
}

/// Ticks of a logarithmic axis over [lo, hi]: the powers of ten within, labelled `1e<k>`.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<(f64, String)> {
    let (a, b) = (lo.log10().ceil() as i32, hi.log10().floor() as i32);
    (a..=b).map(|k| (10f64.powi(k), format!("1e{k}"))).collect()
}

/// The grid lines and labels of a logarithmic vertical axis at every decade 1e`lo` … 1e`hi`,
/// from `left` to `x_end`, `y` placing a value.
fn decade_lines((lo, hi): (f64, f64), y: impl Fn(f64) -> f64, left: f64, x_end: f64) -> String {
    let mut svg = String::new();
    let mut e = lo;
    while e <= hi + 0.5 {
        let yy = y(10f64.powf(e));
        svg += &format!(
            "<line x1=\"{left}\" y1=\"{yy}\" x2=\"{x_end}\" y2=\"{yy}\" stroke=\"#ddd\"/><text x=\"{}\" y=\"{}\" text-anchor=\"end\">1e{}</text>\n",
            left - 6.0,
            yy + 4.0,
            e as i32
        );
        e += 1.0;
    }
    svg
}

/// The curves of [`plot_errors_svg`]: name, colour and dash pattern (so that curves on top of
/// each other stay apart), and the value of a report point.
fn error_series() -> [Series; 7] {
    [
        (
            "traction error vs reference",
            "#d62728",
            "",
            Box::new(|p| p.traction_error),
        ),
        (
            "estimated traction error",
            "#ff7f0e",
            "8,4",
            Box::new(|p| p.estimate.unwrap_or(f64::NAN)),
        ),
        (
            "largest at a point vs reference",
            "#8c564b",
            "",
            Box::new(|p| p.pointwise_error),
        ),
        (
            "estimated largest at a point",
            "#e377c2",
            "8,4",
            Box::new(|p| p.pointwise_estimate.unwrap_or(f64::NAN)),
        ),
        ("jump error vs reference", "#1f77b4", "2,3", Box::new(|p| p.jump_error)),
        ("η (LATIN indicator)", "#2ca02c", "10,3,2,3", Box::new(|p| p.eta)),
        (
            "contact indicator e_c",
            "#9467bd",
            "4,4",
            Box::new(|p| p.contact_indicator),
        ),
    ]
}

/// The reference's wall time as a vertical dashed line at `xr` (at the right edge, said
/// "beyond this axis", where `beyond`) from `top` to `bottom_y`, named with how the reference
/// ended.
fn reference_line(report: &Report, xr: f64, beyond: bool, (top, bottom_y): (f64, f64)) -> String {
    let reference_label = match report.reference_failure {
        None => "monolithic Newton reference".to_string(),
        Some(_) if report.errors_over_time_points > 0 => format!(
            "monolithic Newton reference FAILED after {} time points (errors over those)",
            report.reference_steps_solved
        ),
        Some(_) => format!(
            "monolithic Newton reference FAILED after {} time points (no errors)",
            report.reference_steps_solved
        ),
    };
    format!(
        "<line x1=\"{xr}\" y1=\"{top}\" x2=\"{xr}\" y2=\"{}\" stroke=\"black\" stroke-dasharray=\"6,4\"/><text x=\"{}\" y=\"{}\" transform=\"rotate(-90 {} {})\">{reference_label}: {:.2} s{}</text>\n",
        bottom_y,
        xr - 6.0,
        top + 240.0,
        xr - 6.0,
        top + 240.0,
        report.reference_s,
        if beyond { " (beyond this axis)" } else { "" }
    )
}

fn plot_errors_svg(report: &Report, time_axis: TimeAxis) -> String {
    let (w, h) = (900.0, 560.0);
    let (left, right, top, bottom) = (80.0, 230.0, 40.0, 60.0);
    let series = error_series();
    let t_of = |p: &ReportPoint| report.latin_setup_s + p.elapsed_s;
    // The axis spans LATIN's run (the reference's time is marked on it where it fits, else named
    // at the right edge): a reference ten times slower would squeeze LATIN's curves into a tenth.
    let latin_max = report.points.iter().map(t_of).fold(0.0, f64::max);
    let t_max = if latin_max > 0.0 { latin_max } else { report.reference_s }.max(1e-9) * 1.05;
    let values: Vec<f64> = report
        .points
        .iter()
        .flat_map(|p| series.iter().map(move |s| (s.3)(p)))
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    let (lo, hi) = log_decades(&values);
    let t_min = report
        .points
        .iter()
        .map(t_of)
        .chain([report.reference_s].into_iter().filter(|&t| t <= t_max))
        .filter(|t| *t > 0.0)
        .fold(t_max, f64::min)
        / 1.5;
    let (t_lo, t_hi) = (10f64.powf(t_min.log10().floor()), 10f64.powf(t_max.log10().ceil()));
    let x = |t: f64| match time_axis {
        TimeAxis::Linear => left + (w - left - right) * t / t_max,
        TimeAxis::Log => left + (w - left - right) * (t.max(t_lo).log10() - t_lo.log10()) / (t_hi / t_lo).log10(),
    };
    let y = |v: f64| top + (h - top - bottom) * (hi - v.max(1e-300).log10()) / (hi - lo).max(1.0);
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{}" y="22" font-size="15" text-anchor="middle">{}: LATIN error against the monolithic reference vs wall time</text>
<rect x="{left}" y="{top}" width="{}" height="{}" fill="none" stroke="black"/>
"#,
        (left + w - right) / 2.0,
        report.scene,
        w - left - right,
        h - top - bottom
    );
    svg += &decade_lines((lo, hi), y, left, w - right);
    let ticks = match time_axis {
        TimeAxis::Linear => linear_ticks(t_max),
        TimeAxis::Log => log_ticks(t_lo, t_hi),
    };
    for (t, label) in ticks {
        let xx = x(t);
        svg += &format!(
            "<line x1=\"{xx}\" y1=\"{top}\" x2=\"{xx}\" y2=\"{}\" stroke=\"#eee\"/><text x=\"{xx}\" y=\"{}\" text-anchor=\"middle\">{label}</text>\n",
            h - bottom,
            h - bottom + 18.0
        );
    }
    svg += &format!(
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">wall time (s{}), operator setup included</text>\n",
        (left + w - right) / 2.0,
        h - 15.0,
        if time_axis == TimeAxis::Log { ", log scale" } else { "" }
    );
    let mid = top + (h - top - bottom) / 2.0;
    svg += &format!(
        "<text x=\"20\" y=\"{mid}\" text-anchor=\"middle\" transform=\"rotate(-90 20 {mid})\">relative error, indicator (log scale)</text>\n"
    );
    let beyond = report.reference_s > t_max;
    let xr = if beyond { w - right } else { x(report.reference_s) };
    svg += &reference_line(report, xr, beyond, (top, h - bottom));
    for (k, (name, color, dash, f)) in series.iter().enumerate() {
        let pts: Vec<String> = report
            .points
            .iter()
            .filter(|p| f(p) > 0.0 && f(p).is_finite())
            .map(|p| format!("{:.2},{:.2}", x(t_of(p)), y(f(p))))
            .collect();
        svg += &format!(
            "<polyline fill=\"none\" stroke=\"{color}\" stroke-width=\"1.8\" stroke-dasharray=\"{dash}\" points=\"{}\"/>\n",
            pts.join(" ")
        );
        let ly = top + 20.0 + 20.0 * k as f64;
        svg += &format!(
            "<line x1=\"{}\" y1=\"{ly}\" x2=\"{}\" y2=\"{ly}\" stroke=\"{color}\" stroke-width=\"2\" stroke-dasharray=\"{dash}\"/><text x=\"{}\" y=\"{}\">{name}</text>\n",
            w - right + 10.0,
            w - right + 40.0,
            w - right + 45.0,
            ly + 4.0
        );
    }
    svg += "</svg>\n";
    svg
}
