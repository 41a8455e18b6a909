//! Scene files: a TOML description of a problem (blocks, materials, interfaces, boundary
//! conditions, time grid) plus solver, PGD, deployment and recording settings, parsed, validated
//! and turned into a [`Model`].
//!
//! [`load_str`] parses the text into raw structs (serde, unknown keys rejected everywhere),
//! validates every value, meshes the blocks, finds the interfaces between subdomains and builds
//! the loads. Every problem is reported as a [`SceneError`] `file: key: problem`, where `key` is
//! the TOML key at fault (`materials.steel.nu`, `block[2].nx`, `interface[0].friction`,
//! `boundary[3]`, …; array indices count from 0).
//!
//! # Format
//!
//! ```toml
//! name = "two-blocks"        # optional; default: the file stem
//! plane = "strain"           # "strain" (default) | "stress"
//!
//! [time]
//! T = 1.0                    # > 0, s
//! N = 40                     # ≥ 1; time points t_i = i·T/N, i = 0..N
//!
//! [materials.steel]
//! E = 210000.0               # > 0, MPa
//! nu = 0.3                   # in (−1, 0.5)
//!
//! [[block]]                  # an axis-aligned rectangle meshed with nx × ny QUA8 elements
//! name = "lower"
//! material = "steel"
//! x = [0.0, 40.0]            # x0 < x1, mm
//! y = [0.0, 20.0]
//! nx = 16                    # ≥ 1
//! ny = 8
//! split = [1, 1]             # optional: subdomains along x and y; must divide nx and ny
//!
//! [[block]]
//! name = "upper"
//! material = "steel"
//! x = [0.0, 40.0]
//! y = [20.0, 40.0]
//! nx = 16
//! ny = 8
//!
//! [[interface]]              # rules for shared edges, applied in order (a later rule wins);
//! between = ["lower", "upper"]  # edges that no rule matches are "perfect"
//! kind = "contact"           # "perfect" | "contact"
//! friction = 0.2             # contact only, required, ≥ 0
//! gap = "x^2/(2*100)"        # contact only, optional (default 0): formula in x, y (mm), or a
//!                            # table { x = [..], g = [..] } or { y = [..], g = [..] }
//!
//! [[boundary]]
//! y = 0.0                    # sides lying on the line y = 0
//! ux = 0.0
//! uy = 0.0
//!
//! [[boundary]]
//! blocks = ["upper"]         # optional: block or subdomain names; default all blocks
//! side = "top"               # optional: bottom | right | top | left
//! ux = "0.004*sin(2*pi*t)"   # formula in t
//! uy = { t = [0.0, 0.5, 1.0], v = [0.0, -0.01, -0.01] }   # piecewise-linear table
//!
//! [solver]                   # every key optional; defaults = model::SolverParams::default()
//! k0_factor = 1.0            # > 0: k₀ = k0_factor · √(2G·M) / L_Γ (≈ E / L_Γ for ν ≤ 0.3)
//! relaxation = 0.8           # in (0, 1]
//! tolerance = 1e-6           # > 0
//! contact_tolerance = 1e-4   # optional, > 0
//! max_iterations = 1000      # ≥ 1
//! stagnation_window = 50     # ≥ 1
//! stagnation_ratio = 0.99    # in (0, 1]
//! coarse = true
//! search_direction_update = false
//! alpha = 0.2                # in [0, 1); with the update on, ≤ 2(1 − μ)/(2 − μ), μ = relaxation
//! i0 = 0.1                   # > 0
//! macro_degree = "auto"      # or 1..=5: macro modes per interface = polynomials of this degree
//!                            # in the abscissa, both components (1 = rigid + extension); "auto":
//!                            # 5 on slender interfaces (length ≥ 10 × a side's thickness), else 1
//! acceleration = "anderson"  # "anderson" (Anderson mixing, damping = relaxation: the default; same
//!                            # limit, fewer iterations on contact scenes) | "none" (plain relaxation)
//! anderson_window = 5        # 1..=50: iterates mixed (only with acceleration = "anderson")
//! time_coarsening = 5        # optional, ≥ 2, divides time.N: first solve on every 5th time
//!                            # point and start from that solve's ŝ, interpolated in time
//!                            # (model::TimeStart; not with the PGD stage); default: from ŝ = 0
//! time_coarsening_tolerance = 1e-4  # η at which that coarse solve stops (> 0)
//! linear_stage = "condensed" # "condensed" (dense A_E) | "sparse" (sparse factors, all time points
//!                            # in one multi-right-hand-side solve: the paper's baseline) | "pgd" |
//!                            # "auto" (LinearStage::Auto); default "pgd" when solver.pgd.enabled
//!
//! [solver.pgd]
//! enabled = false            # true = linear_stage "pgd" (contradicting linear_stage is an error)
//! xi1 = 0.1                  # > 0
//! xi2 = 0.01                 # > 0
//! criterion = "increment"    # "increment" | "accumulated" | "increment-svd" (pgd module docs)
//! macro_modes = false        # true: the macro modes start the basis, frozen: micro 2 exact
//! max_new_modes = 1          # ≥ 1: new modes per micro problem and iteration
//!
//! [deployment]
//! subdomain_nodes = 1        # 1 ≤ n ≤ number of subdomains
//! interface_nodes = 1        # 1 ≤ n ≤ number of interfaces; without interface_groups each node
//!                            # owns a run of consecutive interfaces, balanced by pair count
//! interface_groups = [["lower|upper"]]  # optional: the interfaces each node owns, one list
//!                            # per node (its length is interface_nodes), e.g. [[0, 2], ["a|b"]];
//!                            # an entry is an interface index (model order, as `glissade check`
//!                            # counts them) or "A|B": every interface between block or subdomain
//!                            # A and block or subdomain B. Every interface in exactly one group.
//! restarts = 3               # 0 ≤ n ≤ 100: times the launcher restarts a node process that
//!                            # died mid-run (it resumes from the recording, which must then be
//!                            # complete: enabled, topics ["**"], full_fields_every = 1)
//!
//! [recording]
//! enabled = true
//! topics = ["**"]
//! full_fields_every = 1      # ≥ 1
//! ```
//!
//! # Meaning
//!
//! - **Subdomains.** A block with `split = [sx, sy]` becomes sx·sy subdomains of
//!   (nx/sx) × (ny/sy) elements, named `block.k`, k = 1.. left to right, then bottom to top
//!   (just `block` when split = [1, 1]). Global subdomain order: blocks in file order, each
//!   block's subdomains in that order. Blocks must not overlap.
//! - **Interfaces.** Two subdomains whose opposite sides lie on one line with an overlap of
//!   positive length share an interface; the nodes of both sides within the overlap must coincide
//!   (conforming meshes; tolerance 1e-9 × the larger block dimension). Side `a` is the subdomain
//!   below (normal (0, 1)) or to the left (normal (1, 0)); pairs are ordered by increasing x
//!   (resp. y); pair weights are the lumped edge masses of side `a`. An `[[interface]]` rule
//!   matches the interfaces between a subdomain named (or contained in the block named) by
//!   `between[0]` and one of `between[1]`, in either order; a rule matching nothing is an error.
//! - **Boundary rules.** A rule selects sides: of each named block, the sides of its subdomains
//!   lying on the block's outer boundary; of each named subdomain, its own sides. `side`, `x`
//!   and `y` then keep the sides of that orientation, lying on that line. A rule either
//!   prescribes displacements (`ux`, `uy`, mm) or applies tractions (`tx`, `ty`, MPa, global
//!   axes) and/or a pressure `p` (MPa, traction = −p·n_out). Each value is a time function: a
//!   number, a formula string in `t`, or a table `{ t = [..], v = [..] }` (piecewise linear,
//!   constant beyond the ends). Each (rule, component) is one [`LoadCase`] per subdomain it
//!   touches; a later rule prescribing a dof overrides earlier ones. Edges no rule selects are
//!   free.
//! - **Pairs left out** (DESIGN §2): an interface pair whose two nodes have both displacement
//!   components prescribed is dropped (its force is a support reaction); an interface left
//!   without pairs is dropped.
//! - **Rigid-body modes.** In every group of subdomains connected through interfaces (of any
//!   kind) the prescribed displacements must block both translations and the rotation.

mod build;
mod diagnostics;
mod raw;
mod settings;
#[cfg(test)]
mod tests;

pub use settings::{balanced_interface_groups, Deployment, Network, Recording, TlsFiles};

use build::Ctx;
use diagnostics::{parse_raw, toml_error};
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::model::Model;
use glissade_mechanics::pgd::PgdParams;

pub use glissade_mechanics::model::DEFAULT_ANDERSON_WINDOW;
/// Largest `solver.anderson_window` accepted (each iterate kept costs three boundary fields).
pub const MAX_ANDERSON_WINDOW: usize = glissade_mechanics::anderson::MAX_SLOTS;

/// Largest `solver.macro_degree` accepted (2(d + 1) macro modes per interface).
pub const MAX_MACRO_DEGREE: usize = 5;

/// A scene loaded from its text: the validated model plus the settings used by the runtime.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    pub model: Model,
    pub deployment: Deployment,
    pub recording: Recording,
    pub pgd: PgdParams,
    /// How subdomains solve their linear stage.
    pub linear_stage: LinearStage,
    /// [`fingerprint`] of `text`.
    pub fingerprint: u64,
    /// The scene text as given (remote nodes get the scene from the bus).
    pub text: String,
    /// How the processes of a run reach each other (`[network]`).
    pub network: Network,
}

/// A problem in a scene file: `file: key: problem`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {key}: {problem}")]
pub struct SceneError {
    pub file: String,
    /// The TOML key at fault, e.g. `block[2].nx`; `(syntax)` when no key applies.
    pub key: String,
    pub problem: String,
}

/// FNV-1a 64-bit hash of the bytes of `text` (stable across platforms and runs).
pub fn fingerprint(text: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in text.as_bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Parses, validates and builds the scene in `text`; `file` names it in errors and gives the
/// default model name (its file stem).
pub fn load_str(text: &str, file: &str) -> Result<LoadedScene, SceneError> {
    let raw = parse_raw(text, file)?;
    let ctx = Ctx { file };
    let built = ctx.build(&raw)?;
    Ok(LoadedScene {
        model: built.model,
        deployment: built.deployment,
        recording: built.recording,
        pgd: built.pgd,
        linear_stage: built.linear_stage,
        fingerprint: fingerprint(text),
        text: text.to_string(),
        network: ctx.network(&raw.network)?,
    })
}

impl LoadedScene {
    /// This scene with `[solver] tolerance` and/or `max_iterations` set as if written in its
    /// file: the scene text is rewritten with them (a first comment line says so), so that its
    /// fingerprint, the text that node processes fetch from the bus and the text a recording
    /// attaches all describe the run, not only this process's model. `file` names the scene in
    /// errors and gives the default model name, as in [`load_str`]; the network settings (TLS
    /// paths already resolved against the scene's folder) are kept. An invalid value is the
    /// scene error the file would give.
    pub fn with_solver_overrides(
        &self,
        file: &str,
        tolerance: Option<f64>,
        max_iterations: Option<usize>,
    ) -> Result<LoadedScene, SceneError> {
        if tolerance.is_none() && max_iterations.is_none() {
            return Ok(self.clone());
        }
        let mut table: toml::Table = self.text.parse().map_err(|e| toml_error(&self.text, file, &e, true))?;
        let err = |key: &str, problem: String| SceneError {
            file: file.to_string(),
            key: key.to_string(),
            problem,
        };
        let solver = table
            .entry("solver")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .ok_or_else(|| err("solver", "is not a table".into()))?;
        let mut said = Vec::new();
        if let Some(t) = tolerance {
            solver.insert("tolerance".into(), toml::Value::Float(t));
            said.push(format!("tolerance = {t:e}"));
        }
        if let Some(m) = max_iterations {
            let m = i64::try_from(m).map_err(|_| err("solver.max_iterations", format!("{m} is too large")))?;
            solver.insert("max_iterations".into(), toml::Value::Integer(m));
            said.push(format!("max_iterations = {m}"));
        }
        let body = toml::to_string(&table).map_err(|e| err("(syntax)", format!("cannot write the scene back: {e}")))?;
        let text = format!(
            "# {file} with [solver] {} set on the command line\n{body}",
            said.join(", ")
        );
        let mut scene = load_str(&text, file)?;
        scene.network = self.network.clone();
        Ok(scene)
    }
}
