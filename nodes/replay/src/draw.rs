//! What the Rerun logging draws with: a subdomain's deformed mesh coloured by a nodal field,
//! the colour ramp and the contact status colours, the recording stream of a sink, and the time
//! point a view is drawn at.

use crate::{rerr, ColorBy, ReplayError, Sink};
use glissade_mechanics::model::Model;
use glissade_mechanics::post::{nodal_stresses, von_mises};
use glissade_messages::Field;

/// Six triangles of a QUA8 element (local node numbers).
const TRIANGLES: [[usize; 3]; 6] = [[0, 4, 7], [4, 1, 5], [5, 2, 6], [6, 3, 7], [4, 5, 7], [5, 6, 7]];

/// The colouring field at every node of subdomain `s` for displacement `u`.
pub(crate) fn nodal_field(model: &Model, s: usize, u: &[f64], by: ColorBy) -> Result<Vec<f64>, ReplayError> {
    let sub = &model.subdomains[s];
    let n = sub.mesh.coords.len();
    Ok(match by {
        ColorBy::Displacement => (0..n).map(|k| u[2 * k].hypot(u[2 * k + 1])).collect(),
        ColorBy::VonMises => nodal_stresses(sub, model.plane, u)
            .map_err(|e| ReplayError::Content {
                path: format!("subdomain `{}`", sub.name),
                detail: format!("stress: {e}"),
            })?
            .iter()
            .map(von_mises)
            .collect(),
    })
}

/// Viridis-like colour ramp for v in [lo, hi] (the end colours outside).
pub(crate) fn color(v: f64, lo: f64, hi: f64) -> rerun::Color {
    const STOPS: [[f32; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let s = if hi > lo {
        ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.0
    } as f32
        * 4.0;
    let k = (s.floor() as usize).min(3);
    let f = s - k as f32;
    let c: [u8; 3] = std::array::from_fn(|j| (STOPS[k][j] * (1.0 - f) + STOPS[k + 1][j] * f).round() as u8);
    rerun::Color::from_rgb(c[0], c[1], c[2])
}

/// Colours of the reported statuses (separated grey, stick green, slip orange, limit yellow,
/// grazing light blue).
pub(crate) const SETTLED_COLORS: [[u8; 3]; 5] = [
    [150, 150, 150],
    [40, 170, 60],
    [240, 130, 20],
    [230, 210, 40],
    [120, 190, 230],
];
pub(crate) use glissade_mechanics::laws::STATUS_NAMES;
pub(crate) use glissade_mechanics::settled::SETTLED_NAMES;

fn entity_name(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// Logs one subdomain's deformed mesh.
pub(crate) fn log_mesh(
    rec: &rerun::RecordingStream,
    model: &Model,
    s: usize,
    u: &[f64],
    field: &[f64],
    amplification: f64,
    range: (f64, f64),
) -> Result<(), ReplayError> {
    let sub = &model.subdomains[s];
    let positions: Vec<[f32; 3]> = sub
        .mesh
        .coords
        .iter()
        .enumerate()
        .map(|(k, x)| {
            [
                (x[0] + amplification * u[2 * k]) as f32,
                (x[1] + amplification * u[2 * k + 1]) as f32,
                0.0,
            ]
        })
        .collect();
    let triangles: Vec<[u32; 3]> = sub
        .mesh
        .elements
        .iter()
        .flat_map(|el| {
            TRIANGLES
                .iter()
                .map(move |t| [el[t[0]] as u32, el[t[1]] as u32, el[t[2]] as u32])
        })
        .collect();
    let colors: Vec<rerun::Color> = field.iter().map(|v| color(*v, range.0, range.1)).collect();
    rec.log(
        format!("subdomains/{}", entity_name(&sub.name)),
        &rerun::Mesh3D::new(positions)
            .with_triangle_indices(triangles)
            .with_vertex_colors(colors),
    )
    .map_err(rerr)
}

pub(crate) fn create_stream(sink: &Sink) -> Result<rerun::RecordingStream, ReplayError> {
    if *sink == Sink::Spawn {
        no_display().map_or(Ok(()), Err)?;
    }
    if let Sink::Save(p) = sink {
        // A file that exists is never overwritten (it may be the recording itself, or a view
        // kept from an earlier replay).
        if std::fs::symlink_metadata(p).is_ok() {
            return Err(ReplayError::Content {
                path: p.display().to_string(),
                detail: "already exists; nothing was overwritten (name another .rrd file, or remove this one)"
                    .to_string(),
            });
        }
    }
    let builder = rerun::RecordingStreamBuilder::new("glissade");
    match sink {
        Sink::Save(p) => builder.save(p),
        Sink::Spawn => builder.spawn(),
        Sink::Connect(url) => builder.connect_grpc_opts(url.clone()),
    }
    .map_err(rerr)
}

/// Why a spawned viewer could not show anything here: on Linux, neither `DISPLAY` nor
/// `WAYLAND_DISPLAY` is set (a viewer would wait for a display that never comes).
fn no_display() -> Option<ReplayError> {
    let set = |v: &str| std::env::var_os(v).is_some_and(|x| !x.is_empty());
    (cfg!(target_os = "linux") && !set("DISPLAY") && !set("WAYLAND_DISPLAY")).then(|| {
        ReplayError::Rerun(
            "no display to spawn a viewer on (DISPLAY and WAYLAND_DISPLAY are unset): write the view to a \
             file with --save <f.rrd> (or --rerun <f.rrd> on `run`) and open it with `rerun <f.rrd>` where \
             there is a display, or stream it to a running viewer with --connect"
                .to_string(),
        )
    })
}

/// The time point with the largest boundary displacement ‖W(:, i)‖.
pub(crate) fn largest_time_point(w: &Field) -> usize {
    (0..w.cols())
        .map(|i| (i, (0..w.rows()).map(|r| w.get(r, i).powi(2)).sum::<f64>()))
        .fold((0, -1.0), |a, b| if b.1 > a.1 { b } else { a })
        .0
}
