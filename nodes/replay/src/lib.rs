//! Replays a glissade recording (MCAP) in Rerun, and streams a running run's view live.
//!
//! Timelines: `iteration` (LATIN iteration) and `time` (physical time, s). Entities:
//! - `subdomains/<name>`: each subdomain's QUA8 mesh (6 triangles per element) as a `Mesh3D` at
//!   z = 0 (Rerun has no 2D mesh), deformed by its displacement times the amplification and
//!   coloured by |u| or the von Mises stress (nodal average of element stresses). Per iteration at
//!   one time point, and at the end of the run at every time point. Displacements: the run's own
//!   full fields when it was run with `--interior`, else recovered exactly from a boundary state
//!   s = (W, F) by one sparse solve per time point: u = (K + Bᵀk M B)⁻¹ (f_d + Bᵀ M (F + k W)),
//!   which holds for any s the linear stage produced and any k. The final state's s is taken from
//!   the interface solutions, so a recording thinned by `full_fields_every` shows it too.
//! - `interfaces/<i>/status`: the contact node pairs coloured separated (grey) / stick (green) /
//!   slip (orange), and `interfaces/<i>/traction`: the traction F̂ on side a as arrows, at every
//!   time point of the final state; `interface_tractions/<i>/{normal,tangential}`: their mean.
//! - `indicators/eta`, `indicators/contact_indicator` (and their log10), `contact/{separated,
//!   stick,slip}` counts per iteration; `contact_over_time/…` status counts per time point.
//!
//! [`replay`] reads a recording in two passes (the colour range and amplification of the final
//! state, then every message); [`View`] takes messages one at a time, as [`replay`] and a live run
//! (`glissade run --rerun`) give them.

pub mod reexecute;
mod states;

use glissade_bus::convert::view;
use glissade_mechanics::condensed::{BoundaryLayout, CondensedOperator};
use glissade_mechanics::element::{elasticity, stress, NODE_XI};
use glissade_mechanics::linear::default_k0;
use glissade_mechanics::local::{InterfaceFields, ReferenceErrors};
use glissade_mechanics::model::Side;
use glissade_mechanics::model::{Model, Plane};
use glissade_messages::{Field, InterfaceSolution, Message, Payload, Stage};
use glissade_recorder::Recording;
use glissade_reference::{solve_reference, ReferenceOptions};
use glissade_scene::load_str;
use nalgebra::SVector;
pub use states::BoundaryStates;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Where the Rerun data goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Sink {
    /// An .rrd file (no display needed).
    Save(PathBuf),
    /// A viewer spawned from the `rerun` executable on PATH.
    Spawn,
    /// A running viewer's gRPC proxy, e.g. `rerun+http://127.0.0.1:9876/proxy`.
    Connect(String),
}

/// The address of a viewer started with `rerun` on this machine (its gRPC proxy).
pub const DEFAULT_VIEWER: &str = "rerun+http://127.0.0.1:9876/proxy";

impl Sink {
    /// `spawn`, `connect` (a viewer at [`DEFAULT_VIEWER`]), a viewer address
    /// (`rerun+http://…`), or a file name ending in `.rrd`.
    pub fn parse(text: &str) -> Result<Self, String> {
        match text {
            "spawn" => Ok(Sink::Spawn),
            "connect" => Ok(Sink::Connect(DEFAULT_VIEWER.into())),
            t if t.starts_with("rerun+http://") || t.starts_with("rerun+https://") => Ok(Sink::Connect(t.into())),
            t if t.ends_with(".rrd") => Ok(Sink::Save(PathBuf::from(t))),
            t => Err(format!(
                "`{t}`: expected spawn, connect, a viewer address rerun+http://host:port/proxy, or a file name ending in .rrd"
            )),
        }
    }
}

/// The field the meshes are coloured by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColorBy {
    /// |u| (mm).
    Displacement,
    /// Von Mises stress (MPa), σ_zz = ν(σ_xx + σ_yy) in plane strain.
    VonMises,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ReplayOptions {
    pub sink: Sink,
    pub color_by: ColorBy,
    /// Displacement amplification; None: the largest displacement drawn as 5 % of the model's size.
    pub amplification: Option<f64>,
    /// Time point of the per-iteration meshes; None: the one with the largest boundary displacement.
    pub time_point: Option<usize>,
    /// Solve the scene with the monolithic Newton reference first and log each iteration's error
    /// against it (contact tractions and jumps, as `glissade report` measures them).
    pub reference: bool,
    /// PGD basis sizes to log: (iteration, subdomain, basis size), e.g. the time-function counts
    /// of a PGD run's mode-form states.
    pub basis_sizes: Vec<(u32, u32, usize)>,
}

/// What a replay logged.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReplaySummary {
    pub messages: u64,
    pub iterations: usize,
    /// Meshes logged (subdomain × frame).
    pub meshes: usize,
    pub time_point: usize,
    pub amplification: f64,
    /// Colour range (min, max) of the chosen field.
    pub color_range: (f64, f64),
    /// Interior displacements came from the recording's `Displacement` messages.
    pub interior_recorded: bool,
    /// (iteration, traction error, jump error) against the reference, when asked for.
    pub errors: Vec<(u32, f64, f64)>,
    /// Wall time of the reference solve (s), when asked for.
    pub reference_s: Option<f64>,
}

#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("{0}")]
    Recording(#[from] glissade_recorder::RecorderError),
    #[error("{path}: {detail}")]
    Content { path: String, detail: String },
    #[error("rerun: {0}")]
    Rerun(String),
}

fn rerr(e: impl std::fmt::Display) -> ReplayError {
    ReplayError::Rerun(e.to_string())
}

/// Displacement recovery of the subdomains (built on first use).
struct Recovery {
    k0: Vec<f64>,
    ops: BTreeMap<u32, CondensedOperator>,
}

impl Recovery {
    fn new(model: &Model) -> Self {
        Self {
            k0: default_k0(model),
            ops: BTreeMap::new(),
        }
    }

    /// u of subdomain `s` at time point `i` from its boundary state (W, F).
    fn displacement(&mut self, model: &Model, s: u32, w: &Field, f: &Field, i: usize) -> Result<Vec<f64>, String> {
        if !self.ops.contains_key(&s) {
            let sub = model
                .subdomains
                .get(s as usize)
                .ok_or_else(|| format!("boundary state of subdomain {s}, which the scene does not have"))?;
            let layout = BoundaryLayout::new(model, s as usize, &self.k0);
            let op = CondensedOperator::with_dense(sub, model.plane, layout, false)
                .map_err(|e| format!("subdomain `{}`: {e}", sub.name))?;
            self.ops.insert(s, op);
        }
        let op = &self.ops[&s];
        let n_b = op.layout.len();
        if w.rows() != n_b || f.rows() != n_b || w.cols() != model.time.n_points() {
            return Err(format!(
                "boundary state of subdomain {s} is {} × {}, the scene gives {n_b} × {}",
                w.rows(),
                w.cols(),
                model.time.n_points()
            ));
        }
        let q: Vec<f64> = (0..n_b).map(|b| f.get(b, i) + op.layout.k[b] * w.get(b, i)).collect();
        let t = model.time.t(i);
        let phi: Vec<f64> = model.subdomains[s as usize]
            .loads
            .iter()
            .map(|l| l.time.eval(t))
            .collect();
        Ok(op.recover(&q, &phi))
    }
}

/// The boundary state (W, F) of subdomain `s` assembled from the interface solutions (the s of
/// the last linear stage, side by side), when every interface of `s` has one.
fn state_from_interfaces(model: &Model, k0: &[f64], s: usize, sols: &[InterfaceSolution]) -> Option<(Field, Field)> {
    let layout = BoundaryLayout::new(model, s, k0);
    let nt = model.time.n_points();
    let n_b = layout.len();
    let (mut w, mut f) = (Field::zeros(n_b, nt), Field::zeros(n_b, nt));
    for slot in &layout.slots {
        let sol = sols.iter().find(|x| x.interface as usize == slot.interface)?;
        let (sw, sf) = match slot.side {
            Side::A => (&sol.w_a, &sol.f_a),
            Side::B => (&sol.w_b, &sol.f_b),
        };
        if sw.rows() != 2 * slot.n_pairs || sw.cols() != nt || sf.rows() != sw.rows() || sf.cols() != nt {
            return None;
        }
        for i in 0..nt {
            for r in 0..2 * slot.n_pairs {
                let k = i * n_b + slot.offset + r;
                w.data[k] = sw.get(r, i);
                f.data[k] = sf.get(r, i);
            }
        }
    }
    Some((w, f))
}

/// Six triangles of a QUA8 element (local node numbers).
const TRIANGLES: [[usize; 3]; 6] = [[0, 4, 7], [4, 1, 5], [5, 2, 6], [6, 3, 7], [4, 5, 7], [5, 6, 7]];

/// The colouring field at every node of subdomain `s` for displacement `u`.
fn nodal_field(model: &Model, s: usize, u: &[f64], by: ColorBy) -> Vec<f64> {
    let sub = &model.subdomains[s];
    let n = sub.mesh.coords.len();
    match by {
        ColorBy::Displacement => (0..n).map(|k| u[2 * k].hypot(u[2 * k + 1])).collect(),
        ColorBy::VonMises => {
            let d = elasticity(sub.material, model.plane);
            let nu = sub.material.nu;
            let mut sum = vec![0.0; n];
            let mut count = vec![0u32; n];
            for el in &sub.mesh.elements {
                let x: [[f64; 2]; 8] = std::array::from_fn(|a| sub.mesh.coords[el[a]]);
                let ue = SVector::<f64, 16>::from_fn(|r, _| u[2 * el[r / 2] + r % 2]);
                for (a, xi) in NODE_XI.iter().enumerate() {
                    let Ok(sig) = stress(&x, &d, &ue, xi[0], xi[1]) else {
                        continue;
                    };
                    let (sx, sy, txy) = (sig[0], sig[1], sig[2]);
                    let sz = match model.plane {
                        Plane::Strain => nu * (sx + sy),
                        Plane::Stress => 0.0,
                    };
                    let vm =
                        (0.5 * ((sx - sy).powi(2) + (sy - sz).powi(2) + (sz - sx).powi(2)) + 3.0 * txy * txy).sqrt();
                    sum[el[a]] += vm;
                    count[el[a]] += 1;
                }
            }
            sum.iter().zip(&count).map(|(s, c)| s / (*c).max(1) as f64).collect()
        }
    }
}

/// Viridis-like colour ramp for v in [lo, hi].
fn color(v: f64, lo: f64, hi: f64) -> rerun::Color {
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

const STATUS_COLORS: [[u8; 3]; 3] = [[150, 150, 150], [40, 170, 60], [240, 130, 20]];
const STATUS_NAMES: [&str; 3] = ["separated", "stick", "slip"];

fn entity_name(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// Logs one subdomain's deformed mesh.
fn log_mesh(
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

fn create_stream(sink: &Sink) -> Result<rerun::RecordingStream, ReplayError> {
    let builder = rerun::RecordingStreamBuilder::new("glissade");
    match sink {
        Sink::Save(p) => builder.save(p),
        Sink::Spawn => builder.spawn(),
        Sink::Connect(url) => builder.connect_grpc_opts(url.clone()),
    }
    .map_err(rerr)
}

/// The diagonal of the model's bounding box (mm).
fn diagonal(model: &Model) -> f64 {
    let b = model.subdomains.iter().flat_map(|s| s.mesh.coords.iter()).fold(
        [f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY],
        |b, x| [b[0].min(x[0]), b[1].max(x[0]), b[2].min(x[1]), b[3].max(x[1])],
    );
    (b[1] - b[0]).hypot(b[3] - b[2])
}

/// The time point with the largest boundary displacement ‖W(:, i)‖.
fn largest_time_point(w: &Field) -> usize {
    (0..w.cols())
        .map(|i| (i, (0..w.rows()).map(|r| w.get(r, i).powi(2)).sum::<f64>()))
        .fold((0, -1.0), |a, b| if b.1 > a.1 { b } else { a })
        .0
}

/// The Rerun view of one run, fed message by message.
pub struct View {
    rec: rerun::RecordingStream,
    model: Model,
    color_by: ColorBy,
    recovery: Recovery,
    /// Fixed colour range; None: each iteration's own range (a live run cannot know the last one).
    range: Option<(f64, f64)>,
    amplification: Option<f64>,
    time_point: Option<usize>,
    diag: f64,
    /// Boundary states of the iteration in progress, logged with its decision.
    pending: BTreeMap<u32, (Field, Field)>,
    /// The last boundary state of each subdomain.
    last_states: BTreeMap<u32, (Field, Field)>,
    /// Mode forms of PGD subdomains (their states arrive as `BoundaryModes`).
    states: BoundaryStates,
    interfaces: Vec<InterfaceSolution>,
    displacements: BTreeMap<u32, Field>,
    last_iteration: i64,
    summary: ReplaySummary,
    /// The reference's interface fields and the errors against them, when asked for.
    errors: Option<(Vec<InterfaceFields>, ReferenceErrors)>,
}

impl View {
    /// Opens the sink and logs the scene. `range` and `amplification` fix the colour range and
    /// the displacement amplification (None: from the first iteration logged, and the colour
    /// range per iteration).
    pub fn new(
        scene_text: &str,
        origin: &str,
        run_id: &str,
        opts: &ReplayOptions,
        range: Option<(f64, f64)>,
    ) -> Result<Self, ReplayError> {
        let scene = load_str(scene_text, origin).map_err(|e| ReplayError::Content {
            path: origin.to_string(),
            detail: e.to_string(),
        })?;
        let model = scene.model;
        let nt = model.time.n_points();
        if let Some(i) = opts.time_point.filter(|&i| i >= nt) {
            return Err(ReplayError::Content {
                path: origin.to_string(),
                detail: format!("time point {i}: the scene has time points 0..{}", nt - 1),
            });
        }
        let diag = diagonal(&model);
        let rec = create_stream(&opts.sink)?;
        rec.log_static(
            "scene",
            &rerun::TextDocument::new(format!(
                "scene `{}`, run `{run_id}`\ncoloured by {}{}\n\n{scene_text}",
                model.name,
                match opts.color_by {
                    ColorBy::Displacement => "|u| (mm)",
                    ColorBy::VonMises => "von Mises stress (MPa)",
                },
                match range {
                    Some((lo, hi)) => format!(", range {lo:.4e} – {hi:.4e}"),
                    None => ", range of each iteration".to_string(),
                }
            )),
        )
        .map_err(rerr)?;
        let mut summary = ReplaySummary::default();
        for &(it, s, modes) in &opts.basis_sizes {
            let name = model
                .subdomains
                .get(s as usize)
                .map(|sd| sd.name.clone())
                .ok_or_else(|| ReplayError::Content {
                    path: origin.to_string(),
                    detail: format!("basis size of subdomain {s}: the scene has {}", model.subdomains.len()),
                })?;
            rec.set_time_sequence("iteration", it as i64);
            rec.disable_timeline("time");
            rec.log(format!("pgd/basis/{name}"), &rerun::Scalars::single(modes as f64))
                .map_err(rerr)?;
        }
        let errors = if opts.reference {
            let t0 = std::time::Instant::now();
            let reference =
                solve_reference(&model, &ReferenceOptions::default()).map_err(|e| ReplayError::Content {
                    path: origin.to_string(),
                    detail: format!("the reference solve failed: {e}"),
                })?;
            summary.reference_s = Some(t0.elapsed().as_secs_f64());
            Some((reference.interfaces, ReferenceErrors::new(&model)))
        } else {
            None
        };
        Ok(Self {
            rec,
            errors,
            recovery: Recovery::new(&model),
            model,
            color_by: opts.color_by,
            range,
            amplification: opts.amplification,
            time_point: opts.time_point,
            diag,
            pending: BTreeMap::new(),
            last_states: BTreeMap::new(),
            states: BoundaryStates::new(),
            interfaces: Vec::new(),
            displacements: BTreeMap::new(),
            last_iteration: 0,
            summary,
        })
    }

    /// Takes one message of the run.
    pub fn message(&mut self, msg: &Message) -> Result<(), ReplayError> {
        self.summary.messages += 1;
        if let Some(state) = self.states.fields(&msg.payload) {
            let (subdomain, w, f) = state.map_err(|detail| ReplayError::Content {
                path: format!("iteration {}", msg.envelope.iteration),
                detail,
            })?;
            if msg.envelope.stage == Stage::Final {
                return Ok(());
            }
            let (subdomain, w, f) = (&subdomain, w.as_ref(), f.as_ref());
            {
                if self.time_point.is_none() {
                    self.time_point = Some(largest_time_point(w));
                }
                let it = msg.envelope.iteration;
                if let Some((e_f, e_w)) = self.errors.as_mut().and_then(|(reference, t)| {
                    t.boundary_state(&self.model.interfaces, *subdomain as usize, view(w), view(f), reference)
                }) {
                    self.summary.errors.push((it, e_f, e_w));
                    let rec = &self.rec;
                    rec.set_time_sequence("iteration", it as i64);
                    rec.disable_timeline("time");
                    for (name, v) in [
                        ("error/traction", e_f),
                        ("error/jump", e_w),
                        ("error/log10_traction", e_f.log10()),
                        ("error/log10_jump", e_w.log10()),
                    ] {
                        if v.is_finite() {
                            rec.log(name, &rerun::Scalars::single(v)).map_err(rerr)?;
                        }
                    }
                }
                self.pending.insert(*subdomain, (w.clone(), f.clone()));
            }
            return Ok(());
        }
        match &msg.payload {
            Payload::Decision(d) => {
                let n = msg.envelope.iteration as i64;
                self.last_iteration = n;
                self.summary.iterations += 1;
                let rec = &self.rec;
                rec.set_time_sequence("iteration", n);
                rec.disable_timeline("time");
                for (name, v) in [
                    ("indicators/eta", d.eta),
                    ("indicators/contact_indicator", d.contact_indicator),
                    ("indicators/log10_eta", d.eta.log10()),
                    ("indicators/log10_contact_indicator", d.contact_indicator.log10()),
                ] {
                    if v.is_finite() {
                        rec.log(name, &rerun::Scalars::single(v)).map_err(rerr)?;
                    }
                }
                for (k, name) in STATUS_NAMES.iter().enumerate() {
                    rec.log(format!("contact/{name}"), &rerun::Scalars::single(d.counts[k] as f64))
                        .map_err(rerr)?;
                }
                self.log_pending(n)?;
            }
            Payload::InterfaceSolution(s) => self.interfaces.push(s.clone()),
            Payload::Displacement { subdomain, u } => {
                self.displacements.insert(*subdomain, u.clone());
            }
            _ => {}
        }
        Ok(())
    }

    /// Each pending boundary state's mesh at the chosen time point, on iteration `n`.
    fn log_pending(&mut self, n: i64) -> Result<(), ReplayError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let pending = std::mem::take(&mut self.pending);
        let i = self.time_point.unwrap_or(0);
        let mut frames = Vec::new();
        for (s, (w, f)) in &pending {
            let u = self
                .recovery
                .displacement(&self.model, *s, w, f, i)
                .map_err(|detail| ReplayError::Content {
                    path: format!("iteration {n}"),
                    detail,
                })?;
            let field = nodal_field(&self.model, *s as usize, &u, self.color_by);
            frames.push((*s, u, field));
        }
        let amplification = *self.amplification.get_or_insert_with(|| {
            let umax = frames
                .iter()
                .flat_map(|(_, u, _)| u.iter())
                .fold(0.0f64, |m, v| m.max(v.abs()));
            if umax > 0.0 {
                0.05 * self.diag / umax
            } else {
                1.0
            }
        });
        let range = self
            .range
            .unwrap_or_else(|| range_of(frames.iter().map(|(_, _, f)| f.as_slice())));
        self.rec.set_time_sequence("iteration", n);
        self.rec.set_duration_secs("time", self.model.time.t(i));
        for (s, u, field) in &frames {
            log_mesh(&self.rec, &self.model, *s as usize, u, field, amplification, range)?;
            self.summary.meshes += 1;
        }
        self.last_states.extend(pending);
        Ok(())
    }

    /// Logs the final state at every time point, flushes the sink and says what was logged.
    pub fn finish(mut self) -> Result<ReplaySummary, ReplayError> {
        let n = self.last_iteration;
        self.log_pending(n)?;
        let model = &self.model;
        let nt = model.time.n_points();
        let final_u = final_displacements(
            model,
            &mut self.recovery,
            &self.interfaces,
            &self.displacements,
            &self.last_states,
        )
        .map_err(|detail| ReplayError::Content {
            path: "final state".into(),
            detail,
        })?;
        let final_fields: BTreeMap<u32, Vec<Vec<f64>>> = final_u
            .iter()
            .map(|(&s, per_time)| {
                (
                    s,
                    per_time
                        .iter()
                        .map(|u| nodal_field(model, s as usize, u, self.color_by))
                        .collect(),
                )
            })
            .collect();
        let range = self
            .range
            .unwrap_or_else(|| range_of(final_fields.values().flatten().map(Vec::as_slice)));
        let amplification = self.amplification.unwrap_or_else(|| {
            let umax = final_u.values().flatten().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            if umax > 0.0 {
                0.05 * self.diag / umax
            } else {
                1.0
            }
        });
        let diag = self.diag;
        let rec = &self.rec;
        for i in 0..nt {
            rec.set_time_sequence("iteration", n);
            rec.set_duration_secs("time", model.time.t(i));
            for (&s, per_time) in &final_u {
                log_mesh(
                    rec,
                    model,
                    s as usize,
                    &per_time[i],
                    &final_fields[&s][i],
                    amplification,
                    range,
                )?;
                self.summary.meshes += 1;
            }
            let mut counts = [0u64; 3];
            for sol in &self.interfaces {
                let Some(itf) = model.interfaces.get(sol.interface as usize) else {
                    return Err(ReplayError::Content {
                        path: "final state".into(),
                        detail: format!("interface {} is not in the scene", sol.interface),
                    });
                };
                let np = itf.n_pairs();
                if sol.w_a_hat.rows() != 2 * np || sol.w_a_hat.cols() != nt || sol.f_a_hat.rows() != 2 * np {
                    return Err(ReplayError::Content {
                        path: "final state".into(),
                        detail: format!(
                            "interface {}: solution is {} × {}, the scene gives {} × {nt}",
                            sol.interface,
                            sol.w_a_hat.rows(),
                            sol.w_a_hat.cols(),
                            2 * np
                        ),
                    });
                }
                let pos: Vec<[f32; 3]> = (0..np)
                    .map(|p| {
                        [
                            (itf.coords[p][0] + amplification * sol.w_a_hat.get(2 * p, i)) as f32,
                            (itf.coords[p][1] + amplification * sol.w_a_hat.get(2 * p + 1, i)) as f32,
                            0.01,
                        ]
                    })
                    .collect();
                if itf.is_contact() && sol.status.len() == np * nt {
                    let status = &sol.status[np * i..np * (i + 1)];
                    for st in status {
                        counts[(*st as usize).min(2)] += 1;
                    }
                    let colors: Vec<rerun::Color> = status
                        .iter()
                        .map(|st| {
                            let c = STATUS_COLORS[(*st as usize).min(2)];
                            rerun::Color::from_rgb(c[0], c[1], c[2])
                        })
                        .collect();
                    let labels: Vec<&str> = status.iter().map(|st| STATUS_NAMES[(*st as usize).min(2)]).collect();
                    rec.log(
                        format!("interfaces/{}/status", sol.interface),
                        &rerun::Points3D::new(pos.clone())
                            .with_colors(colors)
                            .with_labels(labels)
                            .with_show_labels(false)
                            .with_radii([(0.004 * diag) as f32]),
                    )
                    .map_err(rerr)?;
                }
                let fmax = (0..np)
                    .flat_map(|p| (0..nt).map(move |j| (p, j)))
                    .map(|(p, j)| sol.f_a_hat.get(2 * p, j).hypot(sol.f_a_hat.get(2 * p + 1, j)))
                    .fold(0.0f64, f64::max);
                if fmax > 0.0 {
                    let scale = 0.05 * diag / fmax;
                    let vectors: Vec<[f32; 3]> = (0..np)
                        .map(|p| {
                            [
                                (scale * sol.f_a_hat.get(2 * p, i)) as f32,
                                (scale * sol.f_a_hat.get(2 * p + 1, i)) as f32,
                                0.0,
                            ]
                        })
                        .collect();
                    rec.log(
                        format!("interfaces/{}/traction", sol.interface),
                        &rerun::Arrows3D::from_vectors(vectors).with_origins(pos),
                    )
                    .map_err(rerr)?;
                }
                // Mean normal and tangential traction on side a (MPa) as time series.
                let mean = |dir: [f64; 2]| {
                    (0..np)
                        .map(|p| sol.f_a_hat.get(2 * p, i) * dir[0] + sol.f_a_hat.get(2 * p + 1, i) * dir[1])
                        .sum::<f64>()
                        / np.max(1) as f64
                };
                rec.log(
                    format!("interface_tractions/{}/normal", sol.interface),
                    &rerun::Scalars::single(mean(itf.normal)),
                )
                .map_err(rerr)?;
                rec.log(
                    format!("interface_tractions/{}/tangential", sol.interface),
                    &rerun::Scalars::single(mean(itf.tangent)),
                )
                .map_err(rerr)?;
            }
            if self
                .interfaces
                .iter()
                .any(|s| model.interfaces[s.interface as usize].is_contact())
            {
                for (k, name) in STATUS_NAMES.iter().enumerate() {
                    rec.log(
                        format!("contact_over_time/{name}"),
                        &rerun::Scalars::single(counts[k] as f64),
                    )
                    .map_err(rerr)?;
                }
            }
        }
        rec.flush_blocking().map_err(rerr)?;
        self.summary.time_point = self.time_point.unwrap_or(0);
        self.summary.amplification = amplification;
        self.summary.color_range = range;
        self.summary.interior_recorded = !self.displacements.is_empty();
        Ok(self.summary)
    }
}

/// (min, max) over fields; (0, 1) when there is nothing.
fn range_of<'a>(fields: impl Iterator<Item = &'a [f64]>) -> (f64, f64) {
    let (lo, hi) = fields
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    if lo.is_finite() && hi.is_finite() {
        (lo, hi)
    } else {
        (0.0, 1.0)
    }
}

/// Each subdomain's displacement at every time point at the end of the run: recorded
/// (`--interior`), or recovered from its boundary state, taken from the interface solutions or
/// else from its last recorded boundary state.
fn final_displacements(
    model: &Model,
    recovery: &mut Recovery,
    interfaces: &[InterfaceSolution],
    displacements: &BTreeMap<u32, Field>,
    last_states: &BTreeMap<u32, (Field, Field)>,
) -> Result<BTreeMap<u32, Vec<Vec<f64>>>, String> {
    let nt = model.time.n_points();
    let mut out = BTreeMap::new();
    for s in 0..model.subdomains.len() as u32 {
        let n_dofs = model.subdomains[s as usize].n_dofs();
        let per_time: Vec<Vec<f64>> = if let Some(u) = displacements.get(&s) {
            if u.rows() != n_dofs || u.cols() != nt {
                return Err(format!(
                    "displacement of subdomain {s} is {} × {}, the scene gives {n_dofs} × {nt}",
                    u.rows(),
                    u.cols()
                ));
            }
            (0..nt).map(|i| (0..n_dofs).map(|r| u.get(r, i)).collect()).collect()
        } else {
            let in_iteration = model.interfaces.iter().any(|i| i.side_of(s as usize).is_some());
            let state = if in_iteration {
                state_from_interfaces(model, &recovery.k0, s as usize, interfaces)
            } else {
                None
            };
            let Some((w, f)) = state.as_ref().or(last_states.get(&s)) else {
                continue;
            };
            (0..nt)
                .map(|i| recovery.displacement(model, s, w, f, i))
                .collect::<Result<_, _>>()?
        };
        out.insert(s, per_time);
    }
    Ok(out)
}

/// Replays `recording` into the sink of `opts`: the colour range and amplification come from the
/// final state, then every message goes through a [`View`].
pub fn replay(recording: &Recording, opts: &ReplayOptions) -> Result<ReplaySummary, ReplayError> {
    let path = recording.path().display().to_string();
    let content = |detail: String| ReplayError::Content {
        path: path.clone(),
        detail,
    };
    let text = recording
        .scene_text()
        .ok_or_else(|| content("the recording holds no scene (attachment scene.toml)".into()))?;
    let origin = format!("{path} (scene.toml)");
    let model = load_str(text, &origin).map_err(|e| content(e.to_string()))?.model;
    let decode = |m: &glissade_recorder::RecordedMessage<'_>| {
        recording
            .decode(m)
            .map_err(|e| content(format!("message on `{}`: {e}", m.topic)))
    };

    // Pass 1: the final state, and the time point of the per-iteration meshes.
    let mut interfaces = Vec::new();
    let mut displacements = BTreeMap::new();
    let mut last_states = BTreeMap::new();
    let mut first_w = None;
    let mut states = BoundaryStates::new();
    for m in recording.messages() {
        let msg = decode(&m)?;
        if let Some(state) = states.fields(&msg.payload) {
            let (subdomain, w, f) = state.map_err(|e| content(format!("message on `{}`: {e}", m.topic)))?;
            if first_w.is_none() {
                first_w = Some(largest_time_point(&w));
            }
            last_states.insert(subdomain, (w.into_owned(), f.into_owned()));
            continue;
        }
        match msg.payload {
            Payload::InterfaceSolution(s) => interfaces.push(s),
            Payload::Displacement { subdomain, u } => {
                displacements.insert(subdomain, u);
            }
            _ => {}
        }
    }
    let mut recovery = Recovery::new(&model);
    let final_u =
        final_displacements(&model, &mut recovery, &interfaces, &displacements, &last_states).map_err(content)?;
    let mut fields = Vec::new();
    let mut umax = 0.0f64;
    for (&s, per_time) in &final_u {
        for u in per_time {
            umax = u.iter().fold(umax, |m, v| m.max(v.abs()));
            fields.push(nodal_field(&model, s as usize, u, opts.color_by));
        }
    }
    let range = range_of(fields.iter().map(Vec::as_slice));
    let mut opts = opts.clone();
    if opts.time_point.is_none() {
        opts.time_point = first_w;
    }
    if opts.amplification.is_none() && umax > 0.0 {
        opts.amplification = Some(0.05 * diagonal(&model) / umax);
    }

    // Pass 2: every message, as a live run would give them.
    let mut view = View::new(text, &origin, recording.run_id(), &opts, Some(range))?;
    for m in recording.messages() {
        view.message(&decode(&m)?)?;
    }
    view.finish()
}
