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
//! - `interfaces/<i>/status`: the contact node pairs coloured by their reported status,
//!   separated (grey) / stick (green) / slip (orange) / limit (yellow) / grazing (light blue), and `tractions/<i>`: the traction F of s on side a as arrows, at every time point
//!   of the final state; `legend/…`: the colour scale (the final state's 2nd–98th percentiles).
//! - The layout: a blueprint sent before any data (`blueprint`).
//! - `indicators/eta`, `indicators/contact_indicator` (and their log10), `contact/{separated,
//!   stick,slip}` counts per iteration (the local stage's); `contact_over_time/…` the reported
//!   status counts per time point.
//!
//! [`replay`] reads a recording in two passes (the colour range and amplification of the final
//! state, then every message); [`View`] takes messages one at a time, as [`replay`] and a live run
//! (`glissade run --rerun`) give them.

pub mod blueprint;
mod draw;
mod legend;
mod recovery;
pub mod reexecute;
pub mod rrd;
mod states;
mod view;
mod walk;

pub use legend::{ordinal, ColourRange, PERCENTILES};
pub use states::{as_reported, one_value_per_point, settle_statuses, BoundaryStates};
use std::path::PathBuf;
pub use view::View;
pub use walk::{final_state, replay, run_messages, FinalState, Skipped};

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
    /// Recorded messages that are not the run's, skipped.
    pub skipped: Skipped,
    pub iterations: usize,
    /// Meshes logged (subdomain × frame).
    pub meshes: usize,
    pub time_point: usize,
    pub amplification: f64,
    /// Colour range of the chosen field: the final state's percentiles [`PERCENTILES`] and
    /// extremes.
    pub color_range: Option<ColourRange>,
    /// Interior displacements came from the recording's `Displacement` messages.
    pub interior_recorded: bool,
    /// (iteration, traction error, jump error) against the reference, when asked for.
    pub errors: Vec<(u32, f64, f64)>,
    /// Wall time of the reference solve (s), when asked for.
    pub reference_s: Option<f64>,
    /// (subdomain, iteration) of the boundary states left out because some of their parts are
    /// not in the recording.
    pub incomplete_states: Vec<(u32, u32)>,
    /// The launcher's reports of the run stopping to move (`Stall`): the iteration of the last
    /// decision before it, whether the run was ended there, and the diagnosis.
    pub stalls: Vec<(u32, bool, String)>,
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
