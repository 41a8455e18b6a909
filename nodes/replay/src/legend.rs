//! The colour scale of the structure view: its range (percentiles of the field drawn, so that a
//! few stress concentrations do not leave the rest of the model in one colour), the legend strip
//! drawn under the model with labelled ticks, and the frame (model, deformation margin and
//! legend) the eye of the structure view is fitted to.

use crate::draw::color;
use crate::{rerr, ColorBy, ReplayError};
use glissade_mechanics::model::Model;

/// The percentiles (in %) the colour scale spans; values outside take the end colours.
pub const PERCENTILES: (f64, f64) = (2.0, 98.0);

/// The range of the colour scale and the extremes of the values it was taken from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourRange {
    /// The [`PERCENTILES`] of the values: the ends of the scale.
    pub lo: f64,
    pub hi: f64,
    /// The smallest and largest value.
    pub min: f64,
    pub max: f64,
}

impl ColourRange {
    /// The scale of a field without a finite value (e.g. a diverged iteration): 0 – 1, its
    /// extremes NaN, and the legend says so.
    pub const NONE: Self = Self {
        lo: 0.0,
        hi: 1.0,
        min: f64::NAN,
        max: f64::NAN,
    };

    /// The range of the finite values of `fields`; None when there is none.
    ///
    /// Percentile p of n sorted values v: v[h] interpolated linearly at h = (n − 1) p / 100
    /// (numpy's default, "linear").
    pub fn of<'a>(fields: impl Iterator<Item = &'a [f64]>) -> Option<Self> {
        let mut v: Vec<f64> = fields.flatten().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        let n = v.len();
        let mut at = |p: f64| {
            let h = (n - 1) as f64 * p / 100.0;
            let k = h.floor() as usize;
            let (_, &mut a, rest) = v.select_nth_unstable_by(k, f64::total_cmp);
            // The next order statistic is the smallest of those above the k-th.
            let b = rest.iter().copied().fold(f64::INFINITY, f64::min);
            if k + 1 < n {
                a + (h - k as f64) * (b - a)
            } else {
                a
            }
        };
        let (lo, hi) = (at(PERCENTILES.0), at(PERCENTILES.1));
        let (min, max) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(*x), b.max(*x)));
        Some(Self { lo, hi, min, max })
    }
}

/// `lo – hi (2nd–98th percentile of the final state; extremes min – max)`.
impl std::fmt::Display for ColourRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:.4e} – {:.4e} ({}–{} percentile of the final state; extremes {:.4e} – {:.4e})",
            self.lo,
            self.hi,
            ordinal(PERCENTILES.0),
            ordinal(PERCENTILES.1),
            self.min,
            self.max
        )
    }
}

/// The model's bounding box and the space around it the structure view shows.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame {
    /// [x_min, x_max, y_min, y_max] of the undeformed model (mm).
    bounds: [f64; 4],
}

/// Vertical field of view of the viewer's 3D eye (Rerun's default, 55°).
const FOV_Y: f64 = 55.0 * std::f64::consts::PI / 180.0;
/// Width over height of the structure panel the eye is fitted for (it takes about two thirds of
/// a landscape window); a wider panel only adds margin at the sides.
const PANEL_ASPECT: f64 = 1.3;

impl Frame {
    pub(crate) fn new(model: &Model) -> Self {
        let bounds = model.subdomains.iter().flat_map(|s| s.mesh.coords.iter()).fold(
            [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY],
            |b, x| [b[0].min(x[0]), b[1].max(x[0]), b[2].min(x[1]), b[3].max(x[1])],
        );
        Self { bounds }
    }

    /// The diagonal of the model's bounding box (mm).
    pub(crate) fn diagonal(&self) -> f64 {
        let [x0, x1, y0, y1] = self.bounds;
        (x1 - x0).hypot(y1 - y0)
    }

    /// The larger side of the bounding box: the legend's unit.
    fn size(&self) -> f64 {
        let [x0, x1, y0, y1] = self.bounds;
        (x1 - x0).max(y1 - y0)
    }

    /// Room around the model for its deformation (drawn at most 5 % of the diagonal by default).
    fn margin(&self) -> f64 {
        0.06 * self.diagonal()
    }

    /// The legend strip: [x0, x1, y_bottom, y_top].
    fn strip(&self) -> [f64; 4] {
        let [x0, x1, y0, _] = self.bounds;
        let (s, w) = (self.size(), x1 - x0);
        let top = y0 - self.margin() - 0.07 * s;
        [x0 + 0.15 * w, x1 - 0.15 * w, top - 0.035 * s, top]
    }

    /// The eye of the structure view: (position, look target), straight above the middle of the
    /// model and its legend, far enough for both to fill the panel.
    pub(crate) fn eye(&self) -> ([f32; 3], [f32; 3]) {
        let [x0, x1, _, y1] = self.bounds;
        let m = self.margin();
        let bottom = self.strip()[2] - 0.07 * self.size();
        let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y1 + m + bottom));
        let (hx, hy) = (0.5 * (x1 - x0) + m, 0.5 * (y1 + m - bottom));
        let d = 1.05 * hy.max(hx / PANEL_ASPECT) / (0.5 * FOV_Y).tan();
        ([cx as f32, cy as f32, d as f32], [cx as f32, cy as f32, 0.0])
    }
}

/// "2nd", "98th": a percentile as the legend names it.
pub fn ordinal(p: f64) -> String {
    let n = p.round() as i64;
    let suffix = match (n % 10, n % 100) {
        (_, 11..=13) => "th",
        (1, _) => "st",
        (2, _) => "nd",
        (3, _) => "rd",
        _ => "th",
    };
    format!("{n}{suffix}")
}

/// The colour of the legend's labels (dark, readable on the viewer's light background).
const LABEL: [u8; 3] = [40, 40, 40];

/// A value with 3 significant digits, for tick labels.
fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.digits$}")
}

/// Logs the legend (`legend/strip`, `legend/ticks`, `legend/title`) and the range it shows
/// (`legend/range`: `lower`, `upper` (the ends of the scale), `min`, `max`, and the percentiles
/// `lower_percentile`, `upper_percentile`) at the stream's current time, or static.
pub(crate) fn log(
    rec: &rerun::RecordingStream,
    frame: &Frame,
    range: &ColourRange,
    by: ColorBy,
    what: &str,
    is_static: bool,
) -> Result<(), ReplayError> {
    let [x0, x1, yb, yt] = frame.strip();
    let s = frame.size();
    const SEGMENTS: usize = 64;
    let mut positions = Vec::with_capacity(2 * (SEGMENTS + 1));
    let mut colors = Vec::with_capacity(2 * (SEGMENTS + 1));
    for k in 0..=SEGMENTS {
        let f = k as f64 / SEGMENTS as f64;
        let x = (x0 + f * (x1 - x0)) as f32;
        positions.extend([[x, yb as f32, 0.0], [x, yt as f32, 0.0]]);
        let c = color(range.lo + f * (range.hi - range.lo), range.lo, range.hi);
        colors.extend([c, c]);
    }
    let triangles: Vec<[u32; 3]> = (0..SEGMENTS as u32)
        .flat_map(|k| [[2 * k, 2 * k + 2, 2 * k + 1], [2 * k + 1, 2 * k + 2, 2 * k + 3]])
        .collect();
    let ticks: Vec<f64> = (0..=4)
        .map(|k| range.lo + k as f64 / 4.0 * (range.hi - range.lo))
        .collect();
    let tick_at: Vec<[f32; 3]> = (0..=4)
        .map(|k| [(x0 + k as f64 / 4.0 * (x1 - x0)) as f32, (yb - 0.02 * s) as f32, 0.0])
        .collect();
    let (quantity, unit) = match by {
        ColorBy::VonMises => ("von Mises stress", "MPa"),
        ColorBy::Displacement => ("|u|", "mm"),
    };
    let title = if range.min.is_nan() {
        format!("{quantity} ({unit}), {what}: no finite value")
    } else {
        format!(
            "{quantity} ({unit}), {what}: {}–{} percentile; extremes {} – {} in the end colours",
            ordinal(PERCENTILES.0),
            ordinal(PERCENTILES.1),
            short(range.min),
            short(range.max)
        )
    };
    let scalar = |v: f64| [rerun::components::Scalar::from(v)];
    let log = |path: &str, a: &dyn rerun::AsComponents| {
        if is_static {
            rec.log_static(path, a)
        } else {
            rec.log(path, a)
        }
        .map_err(rerr)
    };
    log(
        "legend/strip",
        &rerun::Mesh3D::new(positions)
            .with_triangle_indices(triangles)
            .with_vertex_colors(colors),
    )?;
    log(
        "legend/ticks",
        &rerun::Points3D::new(tick_at)
            .with_labels(ticks.iter().map(|v| short(*v)))
            .with_show_labels(true)
            .with_radii([(0.004 * s) as f32])
            .with_colors([rerun::Color::from_rgb(LABEL[0], LABEL[1], LABEL[2])]),
    )?;
    log(
        "legend/title",
        &rerun::Points3D::new([[(0.5 * (x0 + x1)) as f32, (yt + 0.025 * s) as f32, 0.0]])
            .with_labels([title])
            .with_show_labels(true)
            .with_radii([0.0f32])
            .with_colors([rerun::Color::from_rgb(LABEL[0], LABEL[1], LABEL[2])]),
    )?;
    log(
        "legend/range",
        &rerun::AnyValues::default()
            .with_component::<rerun::components::Scalar>("lower", scalar(range.lo))
            .with_component::<rerun::components::Scalar>("upper", scalar(range.hi))
            .with_component::<rerun::components::Scalar>("min", scalar(range.min))
            .with_component::<rerun::components::Scalar>("max", scalar(range.max))
            .with_component::<rerun::components::Scalar>("lower_percentile", scalar(PERCENTILES.0))
            .with_component::<rerun::components::Scalar>("upper_percentile", scalar(PERCENTILES.1)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate_between_order_statistics() {
        // 0, 1, …, 100 shuffled: percentile p is p itself; 101 values, so h = p exactly.
        let v: Vec<f64> = (0..=100).map(|k| ((k * 37) % 101) as f64).collect();
        let r = ColourRange::of([v.as_slice()].into_iter()).unwrap();
        assert_eq!((r.lo, r.hi, r.min, r.max), (2.0, 98.0, 0.0, 100.0));
        // Two values 0 and 10: h = 0.02 and 0.98 of the way, so 0.2 and 9.8 (up to rounding).
        let r = ColourRange::of([[10.0, f64::NAN, 0.0].as_slice()].into_iter()).unwrap();
        assert!((r.lo - 0.2).abs() < 1e-12 && (r.hi - 9.8).abs() < 1e-12, "{r:?}");
        assert_eq!(ColourRange::of([[f64::NAN].as_slice()].into_iter()), None);
        let r = ColourRange::of([[3.0].as_slice()].into_iter()).unwrap();
        assert_eq!((r.lo, r.hi), (3.0, 3.0));
    }

    #[test]
    fn percentiles_are_named_as_ordinals() {
        let names: Vec<String> = [1.0, 2.0, 3.0, 5.0, 11.0, 12.0, 22.0, 98.0].map(ordinal).into();
        assert_eq!(names, ["1st", "2nd", "3rd", "5th", "11th", "12th", "22nd", "98th"]);
    }

    #[test]
    fn short_labels_keep_three_significant_digits() {
        assert_eq!(short(2333.4), "2333");
        assert_eq!(short(1.1834), "1.18");
        assert_eq!(short(0.012345), "0.0123");
        assert_eq!(short(-45.67), "-45.7");
    }
}
