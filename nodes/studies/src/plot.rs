//! SVG plots of a study: each reported quantity's peak ([`crate::quantities::peak`]) and the
//! iterations against each varied parameter, one line per combination of the other parameters.
//! Written by hand: a handful of lines, markers, ticks and a legend, with no font to measure
//! (plotters' SVG backend needs a font backend to lay out its text).

use crate::driver::StudyRun;
use crate::quantities::{index_of, peak, unit};
use std::fmt::Write as _;

const W: f64 = 640.0;
const H: f64 = 420.0;
const LEFT: f64 = 90.0;
const RIGHT: f64 = 190.0;
const TOP: f64 = 40.0;
const BOTTOM: f64 = 60.0;
const COLOURS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

/// Every plot of `run`: (file name without folder, SVG text). Quantities of `study.report`, then
/// `iterations`, each against each parameter. Variants without a result are left out.
pub fn plots(run: &StudyRun) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut ys: Vec<(String, String, Vec<Option<f64>>)> = run
        .study
        .report
        .iter()
        .filter_map(|q| index_of(q).map(|i| (q, i)))
        .map(|(q, i)| {
            let values = run
                .outcomes
                .iter()
                .map(|o| o.result.as_ref().ok().map(|(_, qs)| peak(qs, i)))
                .collect();
            (q.clone(), format!("peak {q} ({})", unit(i, run.plane)), values)
        })
        .collect();
    ys.push((
        "iterations".into(),
        "LATIN iterations".into(),
        run.outcomes
            .iter()
            .map(|o| o.result.as_ref().ok().map(|(s, _)| s.iterations as f64))
            .collect(),
    ));
    for (p, param) in run.study.parameters.iter().enumerate() {
        for (name, label, values) in &ys {
            let file = file_name(&run.study, name, &param.name);
            out.push((file, plot(run, p, label, values)));
        }
    }
    out
}

/// The file names [`plots`] gives for `study`, in its order.
pub fn file_names(study: &crate::study::Study) -> Vec<String> {
    let quantities = study.report.iter().map(String::as_str).chain(["iterations"]);
    let quantities: Vec<&str> = quantities.collect();
    study
        .parameters
        .iter()
        .flat_map(|p| quantities.iter().map(move |q| file_name(study, q, &p.name)))
        .collect()
}

fn file_name(study: &crate::study::Study, quantity: &str, parameter: &str) -> String {
    format!("{}-{quantity}-vs-{}.svg", study.name, file_safe(parameter))
}

/// `name` with every character but letters, digits, `-` and `_` replaced by `_`.
fn file_safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// Nice tick values covering [lo, hi]: about five, at 1, 2 or 5 times a power of ten.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|s| span / s <= 6.0)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() * step;
    (0..)
        .map(|k| first + k as f64 * step)
        .take_while(|&t| t <= hi + 1e-9 * span)
        .take(12)
        .collect()
}

fn fmt(v: f64) -> String {
    if v == 0.0 || (1e-3..1e4).contains(&v.abs()) {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.2e}")
    }
}

/// One line of a plot: the other parameters' values (bits) and its points (x, y).
type Series = (Vec<u64>, Vec<(f64, f64)>);

/// One plot: `values[k]` (variant k's, None if it has none) against parameter `p`.
fn plot(run: &StudyRun, p: usize, label: &str, values: &[Option<f64>]) -> String {
    let param = &run.study.parameters[p];
    // Series: the variants sharing every other parameter's value, ordered by parameter p.
    let mut series: Vec<Series> = Vec::new();
    for (o, y) in run.outcomes.iter().zip(values) {
        let Some(y) = y.filter(|y| y.is_finite()) else { continue };
        let key: Vec<u64> = o
            .variant
            .values
            .iter()
            .enumerate()
            .filter(|&(k, _)| k != p)
            .map(|(_, v)| v.to_bits())
            .collect();
        let x = o.variant.values[p];
        match series.iter_mut().find(|(k, _)| *k == key) {
            Some((_, pts)) => pts.push((x, y)),
            None => series.push((key, vec![(x, y)])),
        }
    }
    let others: Vec<&str> = run
        .study
        .parameters
        .iter()
        .enumerate()
        .filter(|&(k, _)| k != p)
        .map(|(_, q)| q.name.as_str())
        .collect();
    let lines: Vec<Line> = series
        .into_iter()
        .map(|(key, mut points)| {
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            let label = others
                .iter()
                .zip(&key)
                .map(|(n, v)| format!("{n} = {}", fmt(f64::from_bits(*v))))
                .collect::<Vec<_>>()
                .join(", ");
            Line { label, points }
        })
        .collect();
    let title = format!("{}: {} against {}", run.study.name, label, param.name);
    line_plot(&title, &param.name, label, &lines)
}

/// A line of [`line_plot`]: its legend (none when empty) and its points in drawing order.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// An SVG plot of `lines` (each a polyline with markers, in its own colour), with round ticks
/// on both axes, the axes' labels, a title and a legend of the labelled lines (16 at most).
/// Non-finite points are left out.
pub fn line_plot(title: &str, x_label: &str, y_label: &str, lines: &[Line]) -> String {
    let finite = |&(x, y): &(f64, f64)| x.is_finite() && y.is_finite();
    let all = lines.iter().flat_map(|l| l.points.iter().filter(|p| finite(p)));
    let (mut x0, mut x1, mut y0, mut y1) = all.fold(
        (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY),
        |(a, b, c, d), &(x, y)| (a.min(x), b.max(x), c.min(y), d.max(y)),
    );
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if x1 <= x0 {
        (x0, x1) = (x0 - 0.5 * x0.abs().max(1.0), x1 + 0.5 * x1.abs().max(1.0));
    }
    let pad = if y1 > y0 {
        0.05 * (y1 - y0)
    } else {
        0.5 * y0.abs().max(1.0)
    };
    (y0, y1) = (y0 - pad, y1 + pad);
    let (pw, ph) = (W - LEFT - RIGHT, H - TOP - BOTTOM);
    let sx = |x: f64| LEFT + (x - x0) / (x1 - x0) * pw;
    let sy = |y: f64| TOP + ph - (y - y0) / (y1 - y0) * ph;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">"##
    );
    let _ = writeln!(s, r##"<rect width="{W}" height="{H}" fill="white"/>"##);
    let _ = writeln!(
        s,
        r##"<text x="{}" y="22" text-anchor="middle" font-size="14">{}</text>"##,
        W / 2.0,
        escape(title)
    );
    let _ = writeln!(
        s,
        r##"<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="black"/>"##
    );
    for t in ticks(x0, x1) {
        let x = sx(t);
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="black"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            TOP + ph,
            TOP + ph + 5.0,
            TOP + ph + 18.0,
            fmt(t)
        );
    }
    for t in ticks(y0, y1) {
        let y = sy(t);
        let _ = writeln!(
            s,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{LEFT}" y2="{y:.1}" stroke="black"/><line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            LEFT - 5.0,
            LEFT + pw,
            LEFT - 8.0,
            y + 4.0,
            fmt(t)
        );
    }
    let _ = writeln!(
        s,
        r##"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
        LEFT + pw / 2.0,
        H - 15.0,
        escape(x_label)
    );
    let _ = writeln!(
        s,
        r##"<text transform="translate(18 {:.1}) rotate(-90)" text-anchor="middle">{}</text>"##,
        TOP + ph / 2.0,
        escape(y_label)
    );
    for (k, line) in lines.iter().enumerate() {
        let c = COLOURS[k % COLOURS.len()];
        let pts: Vec<&(f64, f64)> = line.points.iter().filter(|p| finite(p)).collect();
        let path: Vec<String> = pts
            .iter()
            .map(|&&(x, y)| format!("{:.1},{:.1}", sx(x), sy(y)))
            .collect();
        let _ = writeln!(
            s,
            r##"<polyline points="{}" fill="none" stroke="{c}" stroke-width="1.5"/>"##,
            path.join(" ")
        );
        for &&(x, y) in &pts {
            let _ = writeln!(s, r##"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{c}"/>"##, sx(x), sy(y));
        }
        if !line.label.is_empty() && k < 16 {
            let y = TOP + 14.0 * k as f64 + 8.0;
            let _ = writeln!(
                s,
                r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{c}" stroke-width="2"/><text x="{:.1}" y="{:.1}" font-size="10">{}</text>"##,
                W - RIGHT + 10.0,
                W - RIGHT + 28.0,
                W - RIGHT + 32.0,
                y + 3.5,
                escape(&line.label)
            );
        }
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        assert_eq!(ticks(0.0, 1.0), vec![0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]);
        let t = ticks(0.1, 0.3);
        assert!(t.len() >= 3 && t[0] >= 0.1 && *t.last().unwrap() <= 0.3 + 1e-12);
        assert_eq!(fmt(1500.0), "1500");
        assert_eq!(fmt(2.5e-6), "2.50e-6");
    }
}
