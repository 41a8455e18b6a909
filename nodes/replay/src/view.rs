//! The Rerun view of one run: the scene, then every message (boundary states, decisions,
//! displacements, interface solutions) logged on the `iteration` and `time` timelines.

use crate::draw::{
    create_stream, largest_time_point, log_mesh, nodal_field, SETTLED_COLORS, SETTLED_NAMES, STATUS_NAMES,
};
use crate::legend::{self, ColourRange, Frame};
use crate::recovery::{final_displacements, Recovery};
use crate::{rerr, BoundaryStates, ColorBy, ReplayError, ReplayOptions, ReplaySummary};
use glissade_bus::convert::view;
use glissade_mechanics::local::{InterfaceFields, ReferenceErrors};
use glissade_mechanics::model::Model;
use glissade_messages::{Field, InterfaceSolution, Message, Overrides, Payload, Stage};
use glissade_reference::{solve_reference, ReferenceOptions};
use glissade_scene::load_with;
use std::collections::BTreeMap;

/// The Rerun view of one run, fed message by message.
pub struct View {
    rec: rerun::RecordingStream,
    model: Model,
    color_by: ColorBy,
    recovery: Recovery,
    /// Fixed colour range; None: each iteration's own range (a live run cannot know the last one).
    range: Option<ColourRange>,
    amplification: Option<f64>,
    time_point: Option<usize>,
    frame: Frame,
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
    /// Opens the sink, sends the layout (the blueprint) and logs the scene: its text as written
    /// with the command-line `overrides` the run applied (the run's model). `range` and
    /// `amplification` fix the colour range (with its legend) and the displacement amplification
    /// (None: from the first iteration logged, and the colour range and legend per iteration,
    /// then the final state's).
    pub fn new(
        scene_text: &str,
        overrides: &Overrides,
        origin: &str,
        run_id: &str,
        opts: &ReplayOptions,
        range: Option<ColourRange>,
    ) -> Result<Self, ReplayError> {
        let scene = load_with(scene_text, origin, overrides).map_err(|e| ReplayError::Content {
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
        let frame = Frame::new(&model);
        let rec = create_stream(&opts.sink)?;
        crate::blueprint::send(&rec, &frame)?;
        rec.log_static("/", &rerun::ViewCoordinates::RIGHT_HAND_Y_UP())
            .map_err(rerr)?;
        if let Some(r) = &range {
            legend::log(&rec, &frame, r, opts.color_by, "final state", true)?;
        }
        rec.log_static(
            "scene",
            &rerun::TextDocument::new(format!(
                "scene `{}`, run `{run_id}`\ncoloured by {}{}\ncommand-line overrides: {overrides}\n\n{scene_text}",
                model.name,
                match opts.color_by {
                    ColorBy::Displacement => "|u| (mm)",
                    ColorBy::VonMises => "von Mises stress (MPa)",
                },
                match range {
                    Some(r) => format!(", colour range {r}"),
                    None => ", colour range of each iteration, then of the final state".to_string(),
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
        let states = BoundaryStates::new(&model);
        Ok(Self {
            rec,
            errors,
            recovery: Recovery::new(&model),
            model,
            color_by: opts.color_by,
            range,
            amplification: opts.amplification,
            time_point: opts.time_point,
            frame,
            pending: BTreeMap::new(),
            last_states: BTreeMap::new(),
            states,
            interfaces: Vec::new(),
            displacements: BTreeMap::new(),
            last_iteration: 0,
            summary,
        })
    }

    /// Takes one message of the run.
    pub fn message(&mut self, msg: &Message) -> Result<(), ReplayError> {
        self.summary.messages += 1;
        if let Some(state) = self.states.fields(msg) {
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
                if let Some(e) = self.errors.as_mut().and_then(|(reference, t)| {
                    t.boundary_state(&self.model.interfaces, *subdomain as usize, view(w), view(f), reference)
                }) {
                    let (e_f, e_w, e_max) = (e.traction, e.jump, e.pointwise.error);
                    self.summary.errors.push((it, e_f, e_w));
                    let rec = &self.rec;
                    rec.set_time_sequence("iteration", it as i64);
                    rec.disable_timeline("time");
                    for (name, v) in [
                        ("error/traction", e_f),
                        ("error/jump", e_w),
                        ("error/log10_traction", e_f.log10()),
                        ("error/log10_jump", e_w.log10()),
                        ("error/pointwise_traction", e_max),
                        ("error/log10_pointwise_traction", e_max.log10()),
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
            Payload::Stall(r) => {
                let n = msg.envelope.iteration;
                self.summary.stalls.push((n, r.ended, r.diagnosis.clone()));
                let rec = &self.rec;
                rec.set_time_sequence("iteration", n as i64);
                rec.disable_timeline("time");
                let (level, what) = if r.ended {
                    (rerun::TextLogLevel::ERROR, "the run stopped moving and was ended")
                } else {
                    (
                        rerun::TextLogLevel::WARN,
                        "the run stopped moving and was set going again",
                    )
                };
                rec.log(
                    "bus/stall",
                    &rerun::TextLog::new(format!("{what}: {}", r.diagnosis)).with_level(level),
                )
                .map_err(rerr)?;
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
            let field = nodal_field(&self.model, *s as usize, &u, self.color_by)?;
            frames.push((*s, u, field));
        }
        let amplification = *self.amplification.get_or_insert_with(|| {
            let umax = frames
                .iter()
                .flat_map(|(_, u, _)| u.iter())
                .fold(0.0f64, |m, v| m.max(v.abs()));
            if umax > 0.0 {
                0.05 * self.frame.diagonal() / umax
            } else {
                1.0
            }
        });
        let range = match self.range {
            Some(r) => r,
            None => {
                // The legend of this iteration's range, on the iteration timeline only (on the
                // `time` timeline, the final state's legend holds).
                let r = ColourRange::of(frames.iter().map(|(_, _, f)| f.as_slice())).unwrap_or(ColourRange::NONE);
                self.rec.set_time_sequence("iteration", n);
                self.rec.disable_timeline("time");
                legend::log(
                    &self.rec,
                    &self.frame,
                    &r,
                    self.color_by,
                    &format!("iteration {n}"),
                    false,
                )?;
                r
            }
        };
        self.rec.set_time_sequence("iteration", n);
        self.rec.set_duration_secs("time", self.model.time.t(i));
        for (s, u, field) in &frames {
            log_mesh(
                &self.rec,
                &self.model,
                *s as usize,
                u,
                field,
                amplification,
                (range.lo, range.hi),
            )?;
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
        // The displacements and the boundary forces from each copy's own values, the interfaces
        // drawn with one value per point, as the run's outputs show them.
        let boundary = glissade_studies::boundary::boundary_resultants(model, &self.interfaces, model.moment_about);
        crate::as_reported(model, &mut self.interfaces);
        // A solution whose shape does not fit is named by the loop below.
        let resultants = glissade_studies::quantities::quantities(model, &self.interfaces).unwrap_or_default();
        let mut final_fields: BTreeMap<u32, Vec<Vec<f64>>> = BTreeMap::new();
        for (&s, per_time) in &final_u {
            let fields = per_time
                .iter()
                .map(|u| nodal_field(model, s as usize, u, self.color_by))
                .collect::<Result<_, _>>()?;
            final_fields.insert(s, fields);
        }
        let range = match self.range {
            Some(r) => r,
            None => {
                let r =
                    ColourRange::of(final_fields.values().flatten().map(Vec::as_slice)).unwrap_or(ColourRange::NONE);
                // At the first time point, so that it holds at every time point of the `time`
                // timeline, and after the iterations' legends on the `iteration` timeline.
                self.rec.set_time_sequence("iteration", n);
                self.rec.set_duration_secs("time", model.time.t(0));
                legend::log(&self.rec, &self.frame, &r, self.color_by, "final state", false)?;
                r
            }
        };
        let amplification = self.amplification.unwrap_or_else(|| {
            let umax = final_u.values().flatten().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            if umax > 0.0 {
                0.05 * self.frame.diagonal() / umax
            } else {
                1.0
            }
        });
        let diag = self.frame.diagonal();
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
                    (range.lo, range.hi),
                )?;
                self.summary.meshes += 1;
            }
            let mut counts = [0u64; 5];
            for sol in &self.interfaces {
                let Some(itf) = model.interfaces.get(sol.interface as usize) else {
                    return Err(ReplayError::Content {
                        path: "final state".into(),
                        detail: format!("interface {} is not in the scene", sol.interface),
                    });
                };
                let np = itf.n_pairs();
                if sol.w_a.rows() != 2 * np || sol.w_a.cols() != nt || sol.f_a.rows() != 2 * np {
                    return Err(ReplayError::Content {
                        path: "final state".into(),
                        detail: format!(
                            "interface {}: solution is {} × {}, the scene gives {} × {nt}",
                            sol.interface,
                            sol.w_a.rows(),
                            sol.w_a.cols(),
                            2 * np
                        ),
                    });
                }
                let pos: Vec<[f32; 3]> = (0..np)
                    .map(|p| {
                        [
                            (itf.coords[p][0] + amplification * sol.w_a.get(2 * p, i)) as f32,
                            (itf.coords[p][1] + amplification * sol.w_a.get(2 * p + 1, i)) as f32,
                            0.01,
                        ]
                    })
                    .collect();
                if itf.is_contact() && sol.status.len() == np * nt {
                    let status = &sol.status[np * i..np * (i + 1)];
                    for st in status {
                        counts[(*st as usize).min(SETTLED_NAMES.len() - 1)] += 1;
                    }
                    let colors: Vec<rerun::Color> = status
                        .iter()
                        .map(|st| {
                            let c = SETTLED_COLORS[(*st as usize).min(SETTLED_NAMES.len() - 1)];
                            rerun::Color::from_rgb(c[0], c[1], c[2])
                        })
                        .collect();
                    let labels: Vec<&str> = status
                        .iter()
                        .map(|st| SETTLED_NAMES[(*st as usize).min(SETTLED_NAMES.len() - 1)])
                        .collect();
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
                    .map(|(p, j)| sol.f_a.get(2 * p, j).hypot(sol.f_a.get(2 * p + 1, j)))
                    .fold(0.0f64, f64::max);
                if fmax > 0.0 {
                    let scale = 0.05 * diag / fmax;
                    let vectors: Vec<[f32; 3]> = (0..np)
                        .map(|p| {
                            [
                                (scale * sol.f_a.get(2 * p, i)) as f32,
                                (scale * sol.f_a.get(2 * p + 1, i)) as f32,
                                0.0,
                            ]
                        })
                        .collect();
                    rec.log(
                        format!("tractions/{}", sol.interface),
                        &rerun::Arrows3D::from_vectors(vectors).with_origins(pos),
                    )
                    .map_err(rerr)?;
                }
            }
            // The interface resultants and the boundary rules' forces, as the run's CSVs hold them.
            for q in &resultants {
                for name in ["normal", "tangential", "slip_share", "limit_share"] {
                    let k = glissade_studies::quantities::index_of(name).expect("a quantity");
                    rec.log(
                        format!("resultants/interface_{}/{name}", q.interface),
                        &rerun::Scalars::single(q.values[k][i]),
                    )
                    .map_err(rerr)?;
                }
            }
            for b in &boundary {
                let path = entity_name(&b.rule);
                for (name, v) in [
                    ("force_x", b.force[i][0]),
                    ("force_y", b.force[i][1]),
                    ("moment", b.moment[i]),
                ] {
                    rec.log(format!("boundary/{path}/{name}"), &rerun::Scalars::single(v))
                        .map_err(rerr)?;
                }
            }
            if self
                .interfaces
                .iter()
                .any(|s| model.interfaces[s.interface as usize].is_contact())
            {
                for (k, name) in SETTLED_NAMES.iter().enumerate() {
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
        self.summary.color_range = Some(range);
        self.summary.interior_recorded = !self.displacements.is_empty();
        self.summary.incomplete_states = self.states.incomplete().to_vec();
        Ok(self.summary)
    }
}

/// A boundary rule's name as one entity path part: letters and digits kept, every run of other
/// characters one `_` (`boundary[0] (bore)` → `boundary_0_bore`).
fn entity_name(rule: &str) -> String {
    let mut out = String::new();
    for c in rule.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c);
        } else if !out.ends_with('_') {
            out.push('_');
        }
    }
    out.trim_matches('_').to_string()
}
