//! The memory a scene needs, estimated from its text before any mesh or time grid is built, so
//! that a scene too large for the machine is refused instead of being killed mid-run.

use super::Ctx;
use crate::raw::RawScene;
use crate::SceneError;
use std::sync::atomic::{AtomicU64, Ordering};

/// Bytes per boundary value and time point: the subdomain's and its interfaces' space-time
/// fields (s, ŝ, the linear stage's two parts, the relaxed and the previous state, q̂, local
/// directions; W and F each) and the Anderson history (two fields per step of the default window, both
/// sides), with room to spare.
const FIELD_BYTES_PER_VALUE: f64 = 8.0 * (24.0 + 4.0 * crate::DEFAULT_ANDERSON_WINDOW as f64);

/// Bytes per degree of freedom of a subdomain's operators: the sparse stiffness and its
/// Cholesky factor (a banded structured mesh fills in about its bandwidth), with room to spare.
const OPERATOR_BYTES_PER_DOF: f64 = 8.0 * 300.0;

/// The machine's memory in bytes, against which scenes are checked (0: unknown, no check). The
/// `glissade` binary sets it from the operating system at start.
static MACHINE_MEMORY: AtomicU64 = AtomicU64::new(0);

/// Sets the memory scenes are checked against (bytes; 0 switches the check off).
pub fn set_machine_memory(bytes: u64) {
    MACHINE_MEMORY.store(bytes, Ordering::Relaxed);
}

/// What a scene needs, in bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoryEstimate {
    /// Stiffness matrices, their factors and the dense condensed operators.
    pub operators: f64,
    /// Space-time boundary fields and the Anderson history.
    pub fields: f64,
}

impl MemoryEstimate {
    pub fn total(&self) -> f64 {
        self.operators + self.fields
    }
}

/// The estimate from the raw scene: per subdomain of each block (the block's `split` cuts its
/// nx × ny elements), its QUA8 nodes, and as boundary values 2 per node of its perimeter.
pub(crate) fn estimate(raw: &RawScene) -> MemoryEstimate {
    let time_points = raw.time.n_steps as f64 + 1.0;
    let mut e = MemoryEstimate {
        operators: 0.0,
        fields: 0.0,
    };
    for b in &raw.block {
        let [sx, sy] = b.split.unwrap_or([1, 1]).map(|s| s.max(1) as f64);
        let (nx, ny) = ((b.nx as f64 / sx).ceil(), (b.ny as f64 / sy).ceil());
        let nodes = (2.0 * nx + 1.0) * (ny + 1.0) + (nx + 1.0) * ny;
        let boundary_values = 2.0 * 4.0 * (nx + ny);
        let subdomains = sx * sy;
        e.operators += subdomains * (2.0 * nodes * OPERATOR_BYTES_PER_DOF + 8.0 * boundary_values * boundary_values);
        e.fields += subdomains * boundary_values * time_points * FIELD_BYTES_PER_VALUE;
    }
    e
}

/// The estimate of a mesh scene's parts: (nodes, boundary nodes) per part, as for blocks.
pub(crate) fn estimate_parts(parts: &[(usize, usize)], n_steps: usize) -> MemoryEstimate {
    let time_points = n_steps as f64 + 1.0;
    let mut e = MemoryEstimate {
        operators: 0.0,
        fields: 0.0,
    };
    for &(nodes, boundary) in parts {
        let boundary_values = 2.0 * boundary as f64;
        e.operators += 2.0 * nodes as f64 * OPERATOR_BYTES_PER_DOF + 8.0 * boundary_values * boundary_values;
        e.fields += boundary_values * time_points * FIELD_BYTES_PER_VALUE;
    }
    e
}

impl Ctx<'_> {
    /// Refuses a scene whose estimate exceeds `deployment.memory_limit_gb`, or else the machine's
    /// memory (when known).
    pub(crate) fn check_memory(&self, raw: &RawScene) -> Result<(), SceneError> {
        self.check_memory_estimate(raw, estimate(raw))
    }

    /// [`Self::check_memory`] with a given estimate (a mesh scene's, once its parts are known).
    pub(crate) fn check_memory_estimate(&self, raw: &RawScene, e: MemoryEstimate) -> Result<(), SceneError> {
        let (limit, what) = match raw.deployment.memory_limit_gb {
            Some(gb) => {
                self.check(gb > 0.0 && gb.is_finite(), "deployment.memory_limit_gb", || {
                    format!("{gb}: must be a positive number of GB")
                })?;
                (gb * 1e9, "deployment.memory_limit_gb".to_string())
            }
            None => match MACHINE_MEMORY.load(Ordering::Relaxed) {
                0 => return Ok(()),
                m => (m as f64, "this machine's memory".to_string()),
            },
        };
        self.check(e.total() <= limit, "(size)", || {
            format!(
                "the scene needs an estimated {:.1} GB ({:.1} GB of operators for its meshes, {:.1} GB of \
                 space-time fields for N = {}), more than {what} ({:.1} GB): use coarser meshes, fewer time \
                 steps or more subdomains, or set [deployment] memory_limit_gb on a machine with more memory",
                e.total() * 1e-9,
                e.operators * 1e-9,
                e.fields * 1e-9,
                raw.time.n_steps,
                limit * 1e-9
            )
        })
    }
}
