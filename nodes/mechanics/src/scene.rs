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

use crate::element::{edge_load, edge_lumped_mass};
use crate::expr::Expr;
use crate::mesh::{BlockSide, Mesh};
use crate::model::{
    interpolate, Acceleration, Interface, InterfaceKind, LoadCase, Material, Model, Plane, SolverParams, Subdomain,
    TimeFunction, TimeGrid, TimeStart, DEFAULT_TIME_START_TOLERANCE,
};
use serde::Deserialize;
use std::collections::BTreeMap;

pub use crate::model::DEFAULT_ANDERSON_WINDOW;
/// Largest `solver.anderson_window` accepted (each iterate kept costs three boundary fields).
pub const MAX_ANDERSON_WINDOW: usize = crate::anderson::MAX_SLOTS;

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

/// `[network]`: TLS between the processes of a run and access control on its bus.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Network {
    /// `network.tls`; None: plain TCP.
    pub tls: Option<TlsFiles>,
    /// `network.allow`: certificate common names allowed to take part (deny by default); None:
    /// every process the certificate authority vouches for (or any, without TLS).
    pub allow: Option<Vec<String>>,
    /// `network.shared_memory`: processes on one machine pass fields through shared memory
    /// instead of loopback sockets; None (unset): the launcher decides (on when node restarts
    /// are off anyway, see the launcher).
    pub shared_memory: Option<bool>,
}

/// `network.tls`: PEM files, as written until [`Network::resolve_files`] makes them relative to
/// the scene file's folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsFiles {
    /// The certificate authority that signs every certificate of the run.
    pub root_ca: std::path::PathBuf,
    /// The launcher's certificate (its router's, and the one of the nodes it starts).
    pub cert: std::path::PathBuf,
    /// The private key of `cert`.
    pub key: std::path::PathBuf,
    /// Clients must present a certificate signed by `root_ca` (mutual TLS).
    pub mutual: bool,
}

impl Network {
    /// Makes the TLS file paths relative to the folder of `scene_file` (absolute ones stay) and
    /// checks that each is a readable PEM file; errors name the key and the path.
    pub fn resolve_files(&mut self, scene_file: &std::path::Path) -> Result<(), SceneError> {
        let Some(tls) = &mut self.tls else { return Ok(()) };
        let folder = scene_file.parent().unwrap_or(std::path::Path::new(""));
        for (key, path) in [
            ("network.tls.root_ca", &mut tls.root_ca),
            ("network.tls.cert", &mut tls.cert),
            ("network.tls.key", &mut tls.key),
        ] {
            *path = folder.join(&*path);
            let err = |problem: String| SceneError {
                file: scene_file.display().to_string(),
                key: key.to_string(),
                problem,
            };
            let bytes = std::fs::read(&*path).map_err(|e| err(format!("cannot read {}: {e}", path.display())))?;
            if !bytes.windows(11).any(|w| w == b"-----BEGIN ") {
                return Err(err(format!(
                    "{} is not a PEM file (no -----BEGIN line)",
                    path.display()
                )));
            }
        }
        Ok(())
    }
}

/// How the PGD enrichment criterion ξ is measured (DESIGN §3, "Where PGD pays").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PgdCriterion {
    /// ξ relative to the increment δ.
    Increment,
    /// ξ relative to the accumulated correction.
    Accumulated,
    /// Relative to the increment, plus SVD compression of the basis.
    IncrementSvd,
}

/// PGD settings of the linear stage.
#[derive(Debug, Clone, PartialEq)]
pub struct PgdParams {
    pub enabled: bool,
    /// ξ₀ of micro problem 1.
    pub xi1: f64,
    /// ξ₀ of micro problem 2.
    pub xi2: f64,
    pub criterion: PgdCriterion,
    /// The macro modes 𝔼 start the basis, frozen (micro 2 exact).
    pub macro_modes: bool,
    /// New modes per micro problem and iteration, at most.
    pub max_new_modes: usize,
}

impl Default for PgdParams {
    fn default() -> Self {
        Self {
            enabled: false,
            xi1: 0.1,
            xi2: 0.01,
            criterion: PgdCriterion::Increment,
            macro_modes: false,
            max_new_modes: 1,
        }
    }
}

/// The linear stage of the subdomains (DESIGN §3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinearStage {
    /// One dense product with the condensed A_E per micro problem.
    Condensed,
    /// No A_E: each micro problem is one multi-right-hand-side solve with the sparse factors of
    /// K_E + Bᵀk⁻MB for all time points (the paper's baseline).
    Sparse,
    /// PGD on a reduced basis per subdomain ([`crate::pgd`]).
    Pgd,
    /// Chosen per subdomain from its size ([`LinearStage::resolve`]).
    Auto,
}

impl LinearStage {
    pub const ALL: [LinearStage; 4] = [Self::Condensed, Self::Sparse, Self::Pgd, Self::Auto];

    /// The stage's name, as `solver.linear_stage` spells it.
    pub fn key(self) -> &'static str {
        match self {
            Self::Condensed => "condensed",
            Self::Sparse => "sparse",
            Self::Pgd => "pgd",
            Self::Auto => "auto",
        }
    }

    /// The stage a subdomain with n_b boundary entries uses: `Auto` resolves to `Condensed`, the
    /// fastest to a contact-traction error of 1e-3 on every measured case (README "PGD linear
    /// stage", with Anderson, N = 100 and N = 1000): stratified (n_b ≤ 328) condensed 2.18 s and
    /// 14.38 s, PGD 6.73 s and 55.93 s, sparse 29.77 s and 331.96 s; layered (n_b ≈ 960)
    /// condensed 3.61 s and 62.35 s, PGD 18.93 s and 214.58 s, sparse 30.24 s and 938.30 s. The
    /// PGD basis grows to a large fraction of n_b on both (188 of 328, 677 of about 960), so no
    /// boundary size measured favours it; it comes close only to 1e-2 at N = 100.
    pub fn resolve(self, _n_boundary: usize) -> LinearStage {
        match self {
            LinearStage::Auto => LinearStage::Condensed,
            other => other,
        }
    }
}

/// How many node processes of each role a run uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Deployment {
    pub subdomain_nodes: usize,
    pub interface_nodes: usize,
    /// The interfaces each interface node owns (model interface indices, ascending), when the
    /// scene assigns them; None: [`balanced_interface_groups`].
    pub interface_groups: Option<Vec<Vec<usize>>>,
    /// How many times the launcher restarts each node process that dies mid-run.
    pub restarts: usize,
}

impl Default for Deployment {
    fn default() -> Self {
        Self {
            subdomain_nodes: 1,
            interface_nodes: 1,
            interface_groups: None,
            restarts: 3,
        }
    }
}

impl Deployment {
    /// The interfaces each of the `interface_nodes` interface nodes owns: the scene's assignment,
    /// or contiguous groups balanced by pair count. A model without interfaces: one empty group.
    pub fn interface_groups(&self, model: &Model) -> Vec<Vec<usize>> {
        match &self.interface_groups {
            Some(g) => g.clone(),
            None => balanced_interface_groups(model, self.interface_nodes),
        }
    }
}

/// `n` groups of consecutive interfaces (in model order) whose pair counts are as even as a
/// greedy cut can make them: group g ends where the running pair count comes closest to
/// (g + 1)/n of the total; every group gets at least one interface (`n` is clamped to
/// 1..=number of interfaces).
pub fn balanced_interface_groups(model: &Model, n: usize) -> Vec<Vec<usize>> {
    let weights: Vec<f64> = model.interfaces.iter().map(|i| i.n_pairs() as f64).collect();
    let m = weights.len();
    let n = n.clamp(1, m.max(1));
    let total: f64 = weights.iter().sum();
    let mut groups = Vec::with_capacity(n);
    let (mut i, mut sum) = (0, 0.0);
    for g in 0..n {
        let target = total * (g + 1) as f64 / n as f64;
        let later = n - g - 1;
        let mut group = Vec::new();
        while i + later < m {
            let next = sum + weights[i];
            if !group.is_empty() && later > 0 && (next - target).abs() > (sum - target).abs() {
                break;
            }
            group.push(i);
            sum = next;
            i += 1;
        }
        groups.push(group);
    }
    groups
}

/// What the recorder writes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recording {
    pub enabled: bool,
    /// Key-expression patterns (relative to the run) to record.
    pub topics: Vec<String>,
    /// Record full fields every k-th iteration (everything small every iteration).
    pub full_fields_every: usize,
}

impl Recording {
    /// Why a node process cannot resume from this recording (it needs every message), if it
    /// cannot.
    pub fn incomplete(&self) -> Option<String> {
        if !self.enabled {
            Some("recording.enabled = false".into())
        } else if self.topics.iter().all(|t| t != "**") {
            Some(format!("recording.topics = {:?} leaves messages out", self.topics))
        } else if self.full_fields_every > 1 {
            Some(format!(
                "recording.full_fields_every = {} leaves full fields out",
                self.full_fields_every
            ))
        } else {
            None
        }
    }
}

impl Default for Recording {
    fn default() -> Self {
        Self {
            enabled: true,
            topics: vec!["**".to_string()],
            full_fields_every: 1,
        }
    }
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

// ---------------------------------------------------------------------------------------------
// Raw (as written) structures.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<String>,
    plane: Option<RawPlane>,
    time: RawTime,
    #[serde(default)]
    materials: BTreeMap<String, RawMaterial>,
    #[serde(default)]
    block: Vec<RawBlock>,
    #[serde(default)]
    interface: Vec<RawInterface>,
    #[serde(default)]
    boundary: Vec<RawBoundary>,
    #[serde(default)]
    solver: RawSolver,
    #[serde(default)]
    deployment: RawDeployment,
    #[serde(default)]
    recording: RawRecording,
    #[serde(default)]
    network: RawNetwork,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum RawPlane {
    Strain,
    Stress,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTime {
    #[serde(rename = "T")]
    t_end: f64,
    #[serde(rename = "N")]
    n_steps: usize,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    #[serde(rename = "E")]
    e: f64,
    nu: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBlock {
    name: String,
    material: String,
    x: [f64; 2],
    y: [f64; 2],
    nx: usize,
    ny: usize,
    split: Option<[usize; 2]>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum RawKind {
    Perfect,
    Contact,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInterface {
    between: [String; 2],
    kind: RawKind,
    friction: Option<f64>,
    gap: Option<toml::Value>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum RawSide {
    Bottom,
    Right,
    Top,
    Left,
}

impl RawSide {
    fn block_side(self) -> BlockSide {
        match self {
            RawSide::Bottom => BlockSide::Bottom,
            RawSide::Right => BlockSide::Right,
            RawSide::Top => BlockSide::Top,
            RawSide::Left => BlockSide::Left,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBoundary {
    blocks: Option<Vec<String>>,
    side: Option<RawSide>,
    x: Option<f64>,
    y: Option<f64>,
    ux: Option<toml::Value>,
    uy: Option<toml::Value>,
    tx: Option<toml::Value>,
    ty: Option<toml::Value>,
    p: Option<toml::Value>,
}

/// `solver.macro_degree`: a number or "auto".
#[derive(Deserialize, Clone)]
#[serde(untagged)]
enum RawDegree {
    Degree(i64),
    Name(String),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawSolver {
    k0_factor: Option<f64>,
    relaxation: Option<f64>,
    tolerance: Option<f64>,
    contact_tolerance: Option<f64>,
    max_iterations: Option<usize>,
    stagnation_window: Option<usize>,
    stagnation_ratio: Option<f64>,
    coarse: Option<bool>,
    search_direction_update: Option<bool>,
    alpha: Option<f64>,
    i0: Option<f64>,
    macro_degree: Option<RawDegree>,
    acceleration: Option<RawAcceleration>,
    anderson_window: Option<usize>,
    time_coarsening: Option<usize>,
    time_coarsening_tolerance: Option<f64>,
    linear_stage: Option<RawLinearStage>,
    pgd: Option<RawPgd>,
}

#[derive(Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
enum RawLinearStage {
    Condensed,
    Sparse,
    Pgd,
    Auto,
}

#[derive(Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
enum RawAcceleration {
    None,
    Anderson,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
enum RawCriterion {
    Increment,
    Accumulated,
    IncrementSvd,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPgd {
    enabled: Option<bool>,
    xi1: Option<f64>,
    xi2: Option<f64>,
    criterion: Option<RawCriterion>,
    macro_modes: Option<bool>,
    max_new_modes: Option<usize>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawDeployment {
    subdomain_nodes: Option<usize>,
    interface_nodes: Option<usize>,
    interface_groups: Option<Vec<Vec<RawInterfaceRef>>>,
    restarts: Option<usize>,
}

/// An interface in `deployment.interface_groups`: its index, or `"A|B"` (every interface between
/// a subdomain of block or subdomain A and one of B).
#[derive(Deserialize, Clone)]
#[serde(untagged)]
enum RawInterfaceRef {
    Index(usize),
    Between(String),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawNetwork {
    tls: Option<RawTls>,
    allow: Option<Vec<String>>,
    shared_memory: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTls {
    root_ca: String,
    cert: String,
    key: String,
    mutual: Option<bool>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawRecording {
    enabled: Option<bool>,
    topics: Option<Vec<String>>,
    full_fields_every: Option<usize>,
}

// ---------------------------------------------------------------------------------------------
// TOML errors.

fn parse_raw(text: &str, file: &str) -> Result<RawScene, SceneError> {
    // A first pass without a schema separates syntax errors from schema errors.
    if let Err(e) = text.parse::<toml::Table>() {
        return Err(toml_error(text, file, &e, true));
    }
    toml::from_str::<RawScene>(text).map_err(|e| toml_error(text, file, &e, false))
}

fn toml_error(text: &str, file: &str, e: &toml::de::Error, syntax: bool) -> SceneError {
    let message = e.message().trim().replace('\n', "; ");
    let (key, place) = match e.span() {
        Some(span) => {
            let start = span.start.min(text.len());
            let (line, column) = line_column(text, start);
            let key = if syntax { None } else { key_at(text, start) };
            (key, format!("line {line}, column {column}: "))
        }
        None => (None, String::new()),
    };
    // serde names the field in "unknown field `k`" / "missing field `k`".
    let field = ["unknown field `", "missing field `"].iter().find_map(|pre| {
        let rest = message.strip_prefix(pre)?;
        Some(rest[..rest.find('`')?].to_string())
    });
    let key = match (key, field) {
        (Some(k), Some(f)) if k == f || k.ends_with(&format!(".{f}")) => k,
        (Some(k), Some(f)) if message.starts_with("missing") => format!("{k}.{f}"),
        (None, Some(f)) if message.starts_with("missing") => f,
        (Some(k), _) => k,
        (None, _) => "(syntax)".to_string(),
    };
    SceneError {
        file: file.to_string(),
        key,
        problem: format!("{place}{message}"),
    }
}

/// 1-based line and column (in characters) of byte `offset`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text.as_bytes()[..offset];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let line_start = before.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
    let column = String::from_utf8_lossy(&before[line_start..]).chars().count() + 1;
    (line, column)
}

/// Best-effort key path (`block[1].nx`) of the TOML text at byte `offset`: the enclosing table
/// header (array tables indexed from 0) and the key of the line (or of the nearest line above it
/// that starts a key, for values spanning several lines).
fn key_at(text: &str, offset: usize) -> Option<String> {
    let mut array_counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut table = String::new();
    let mut line_key: Option<String> = None;
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        if pos > offset {
            break;
        }
        pos += line.len();
        let t = line.trim();
        if let Some(inner) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            let name = unquote_key(inner);
            let count = {
                let c = array_counts.entry(name.clone()).or_insert(0);
                *c += 1;
                *c
            };
            table = format!("{}[{}]", resolve_table(&name, &array_counts, true), count - 1);
            line_key = None;
        } else if let Some(inner) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
            table = resolve_table(&unquote_key(inner), &array_counts, false);
            line_key = None;
        } else if let Some(k) = line_key_of(t) {
            line_key = Some(k);
        }
    }
    match (table.is_empty(), line_key) {
        (true, None) => None,
        (true, Some(k)) => Some(k),
        (false, None) => Some(table),
        (false, Some(k)) => Some(format!("{table}.{k}")),
    }
}

/// Inserts array-of-tables indices into a dotted table name (`block.foo` → `block[1].foo`).
fn resolve_table(name: &str, array_counts: &BTreeMap<String, usize>, is_array: bool) -> String {
    let parts: Vec<&str> = name.split('.').collect();
    let mut out = String::new();
    for (i, part) in parts.iter().enumerate() {
        if i > 0 {
            out.push('.');
        }
        out.push_str(part);
        let last = i + 1 == parts.len();
        if let Some(&n) = array_counts.get(&parts[..=i].join(".")) {
            // The array table being opened gets its index from the caller.
            if !(last && is_array) {
                out.push_str(&format!("[{}]", n.saturating_sub(1)));
            }
        }
    }
    out
}

fn unquote_key(k: &str) -> String {
    k.split('.')
        .map(|p| p.trim().trim_matches('"').trim_matches('\''))
        .collect::<Vec<_>>()
        .join(".")
}

/// The key of a `key = value` line, if the line starts one.
fn line_key_of(line: &str) -> Option<String> {
    let eq = line.find('=')?;
    let k = line[..eq].trim();
    let ok = !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '"' | '\'' | ' '));
    ok.then(|| unquote_key(k))
}

// ---------------------------------------------------------------------------------------------
// Building.

struct Ctx<'a> {
    file: &'a str,
}

struct Built {
    model: Model,
    deployment: Deployment,
    recording: Recording,
    pgd: PgdParams,
    linear_stage: LinearStage,
}

/// A subdomain during construction.
struct Sub {
    name: String,
    block: usize,
    x: [f64; 2],
    y: [f64; 2],
    /// `outer[side]`: this side lies on its block's outer boundary.
    outer: [bool; 4],
    /// Geometric tolerance: 1e-9 × the larger dimension of its block.
    tol: f64,
    mesh: Mesh,
    material: Material,
}

/// An interface found geometrically, before rules and pair removal.
struct GeoInterface {
    a: usize,
    b: usize,
    /// Normal (0, 1) (a below b) if true, else (1, 0) (a left of b).
    horizontal: bool,
    pairs: Vec<(usize, usize)>,
    coords: Vec<[f64; 2]>,
    weights: Vec<f64>,
    length: f64,
}

/// Initial gap g0(x, y) of a contact rule.
enum GapSpec {
    Constant(f64),
    Formula(Expr),
    /// Table in x (`axis` 0) or y (`axis` 1).
    Table {
        axis: usize,
        xs: Vec<f64>,
        gs: Vec<f64>,
    },
}

impl GapSpec {
    fn eval(&self, p: [f64; 2]) -> f64 {
        match self {
            GapSpec::Constant(g) => *g,
            GapSpec::Formula(e) => e.eval(&p),
            GapSpec::Table { axis, xs, gs } => interpolate(xs, gs, p[*axis]),
        }
    }
}

/// What an interface rule makes of the interfaces it matches.
#[derive(Clone, Copy)]
enum KindRule {
    Perfect,
    /// Contact rule `r` (index into the scene's interface rules).
    Contact(usize),
}

/// Loads of one subdomain during construction.
struct SubLoads {
    constrained: Vec<bool>,
    loads: Vec<LoadCase>,
    /// Load case currently prescribing each dof (usize::MAX: none).
    owner: Vec<usize>,
}

/// A name in the scene: a block (all its subdomains) or one subdomain.
#[derive(Clone, Copy)]
enum NameRef {
    Block(usize),
    Sub(usize),
}

fn fmt_num(v: f64) -> String {
    format!("{v}")
}

fn outward_normal(side: BlockSide) -> [f64; 2] {
    match side {
        BlockSide::Bottom => [0.0, -1.0],
        BlockSide::Right => [1.0, 0.0],
        BlockSide::Top => [0.0, 1.0],
        BlockSide::Left => [-1.0, 0.0],
    }
}

impl Ctx<'_> {
    fn err(&self, key: impl Into<String>, problem: impl Into<String>) -> SceneError {
        SceneError {
            file: self.file.to_string(),
            key: key.into(),
            problem: problem.into(),
        }
    }

    fn check(&self, ok: bool, key: &str, problem: impl FnOnce() -> String) -> Result<(), SceneError> {
        if ok {
            Ok(())
        } else {
            Err(self.err(key, problem()))
        }
    }

    fn build(&self, raw: &RawScene) -> Result<Built, SceneError> {
        let name = match &raw.name {
            Some(n) => n.clone(),
            None => std::path::Path::new(self.file)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scene".to_string()),
        };
        let plane = match raw.plane {
            None | Some(RawPlane::Strain) => Plane::Strain,
            Some(RawPlane::Stress) => Plane::Stress,
        };
        let time = self.time_grid(&raw.time)?;
        let solver = self.solver(&raw.solver)?;
        let pgd = self.pgd(raw.solver.pgd.as_ref())?;
        let linear_stage = self.linear_stage(&raw.solver)?;
        if let Some(ts) = solver.time_start {
            self.check(time.n_steps % ts.coarsening == 0, "solver.time_coarsening", || {
                format!(
                    "{} does not divide time.N = {} (the coarse grid takes every {}-th time point)",
                    ts.coarsening, time.n_steps, ts.coarsening
                )
            })?;
            self.check(linear_stage != LinearStage::Pgd, "solver.time_coarsening", || {
                "is not available with the PGD linear stage (its basis is built from ŝ = 0); \
                 use linear_stage = \"condensed\" or \"sparse\""
                    .to_string()
            })?;
        }
        let recording = self.recording(&raw.recording)?;
        let materials = self.materials(&raw.materials)?;
        self.blocks(raw, &materials)?;
        let subs = self.subdomains(raw, &materials);
        let names = self.names(raw, &subs)?;
        let mut deployment = self.deployment(&raw.deployment, subs.len())?;

        let mut geo = Vec::new();
        for i in 0..subs.len() {
            for j in i + 1..subs.len() {
                if let Some(g) = self.find_interface(&subs, i, j)? {
                    geo.push(g);
                }
            }
        }
        let kinds = self.interface_rules(raw, &names, &subs, &geo)?;
        let gaps = self.gap_specs(raw)?;
        let sub_loads = self.boundaries(raw, &names, &subs, time)?;
        let interfaces = self.finish_interfaces(raw, geo, &kinds, &gaps, &sub_loads)?;
        self.check_rigid_modes(&subs, &interfaces, &sub_loads)?;
        self.interface_groups(&raw.deployment, &mut deployment, &names, &subs, &interfaces)?;

        let subdomains = subs
            .into_iter()
            .zip(sub_loads)
            .map(|(s, l)| Subdomain {
                name: s.name,
                mesh: s.mesh,
                material: s.material,
                constrained: l.constrained,
                loads: l.loads,
            })
            .collect();
        let model = Model {
            name,
            plane,
            time,
            subdomains,
            interfaces,
            solver,
        };
        Ok(Built {
            model,
            deployment,
            recording,
            pgd,
            linear_stage,
        })
    }

    fn time_grid(&self, t: &RawTime) -> Result<TimeGrid, SceneError> {
        self.check(t.t_end > 0.0 && t.t_end.is_finite(), "time.T", || {
            format!("T = {} must be a finite duration > 0 (s)", t.t_end)
        })?;
        self.check(t.n_steps >= 1, "time.N", || {
            "N = 0: need at least one time step (N ≥ 1)".to_string()
        })?;
        Ok(TimeGrid {
            t_end: t.t_end,
            n_steps: t.n_steps,
        })
    }

    fn solver(&self, r: &RawSolver) -> Result<SolverParams, SceneError> {
        let d = SolverParams::default();
        let s = SolverParams {
            k0_factor: r.k0_factor.unwrap_or(d.k0_factor),
            relaxation: r.relaxation.unwrap_or(d.relaxation),
            tolerance: r.tolerance.unwrap_or(d.tolerance),
            contact_tolerance: r.contact_tolerance.or(d.contact_tolerance),
            max_iterations: r.max_iterations.unwrap_or(d.max_iterations),
            stagnation_window: r.stagnation_window.unwrap_or(d.stagnation_window),
            stagnation_ratio: r.stagnation_ratio.unwrap_or(d.stagnation_ratio),
            coarse: r.coarse.unwrap_or(d.coarse),
            search_direction_update: r.search_direction_update.unwrap_or(d.search_direction_update),
            alpha: r.alpha.unwrap_or(d.alpha),
            i0: r.i0.unwrap_or(d.i0),
            macro_degree: match &r.macro_degree {
                None => d.macro_degree,
                Some(RawDegree::Name(n)) if n == "auto" => None,
                Some(RawDegree::Degree(k)) if (1..=MAX_MACRO_DEGREE as i64).contains(k) => Some(*k as usize),
                Some(bad) => {
                    let shown = match bad {
                        RawDegree::Degree(k) => k.to_string(),
                        RawDegree::Name(n) => format!("\"{n}\""),
                    };
                    return Err(self.err(
                        "solver.macro_degree",
                        format!("{shown} is neither \"auto\" nor a degree in 1..={MAX_MACRO_DEGREE}"),
                    ));
                }
            },
            acceleration: self.acceleration(r, d.acceleration)?,
            time_start: self.time_start(r)?,
        };
        let positive = |v: f64| v > 0.0 && v.is_finite();
        self.check(positive(s.k0_factor), "solver.k0_factor", || {
            format!("{} must be > 0", s.k0_factor)
        })?;
        self.check(s.relaxation > 0.0 && s.relaxation <= 1.0, "solver.relaxation", || {
            format!("{} is outside (0, 1]", s.relaxation)
        })?;
        self.check(positive(s.tolerance), "solver.tolerance", || {
            format!("{} must be > 0", s.tolerance)
        })?;
        if let Some(c) = s.contact_tolerance {
            self.check(positive(c), "solver.contact_tolerance", || format!("{c} must be > 0"))?;
        }
        self.check(s.max_iterations >= 1, "solver.max_iterations", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(s.stagnation_window >= 1, "solver.stagnation_window", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(
            s.stagnation_ratio > 0.0 && s.stagnation_ratio <= 1.0,
            "solver.stagnation_ratio",
            || format!("{} is outside (0, 1]", s.stagnation_ratio),
        )?;
        self.check(s.alpha >= 0.0 && s.alpha < 1.0, "solver.alpha", || {
            format!("{} is outside [0, 1) (updated directions are k₀(1 − α) > 0)", s.alpha)
        })?;
        if s.search_direction_update {
            let limit = s.alpha_limit();
            self.check(s.alpha <= limit * (1.0 + 1e-12), "solver.alpha", || {
                format!(
                    "{} is above {limit:.4} = 2(1 − μ)/(2 − μ) for relaxation μ = {}: with the \
                     search-direction update on, the iteration would diverge (lower alpha or the relaxation)",
                    s.alpha, s.relaxation
                )
            })?;
        }
        self.check(positive(s.i0), "solver.i0", || format!("{} must be > 0", s.i0))?;
        Ok(s)
    }

    /// `time_coarsening` and its tolerance; N is checked against the coarsening in [`Self::build`].
    fn time_start(&self, r: &RawSolver) -> Result<Option<TimeStart>, SceneError> {
        let Some(c) = r.time_coarsening else {
            return match r.time_coarsening_tolerance {
                Some(t) => Err(self.err(
                    "solver.time_coarsening_tolerance",
                    format!("{t} is set but solver.time_coarsening is not (set time_coarsening = 5, say)"),
                )),
                None => Ok(None),
            };
        };
        self.check(c >= 2, "solver.time_coarsening", || {
            format!("{c} must be ≥ 2 (the coarse grid takes every c-th time point)")
        })?;
        let tolerance = r.time_coarsening_tolerance.unwrap_or(DEFAULT_TIME_START_TOLERANCE);
        self.check(
            tolerance > 0.0 && tolerance.is_finite(),
            "solver.time_coarsening_tolerance",
            || format!("{tolerance} must be > 0"),
        )?;
        Ok(Some(TimeStart {
            coarsening: c,
            tolerance,
        }))
    }

    fn acceleration(&self, r: &RawSolver, default: Acceleration) -> Result<Acceleration, SceneError> {
        let anderson = match r.acceleration {
            Some(a) => a == RawAcceleration::Anderson,
            None => matches!(default, Acceleration::Anderson { .. }),
        };
        if !anderson {
            if let Some(m) = r.anderson_window {
                return Err(self.err(
                    "solver.anderson_window",
                    format!("{m} is set but solver.acceleration is \"none\" (set acceleration = \"anderson\")"),
                ));
            }
            return Ok(Acceleration::None);
        }
        let window = r.anderson_window.unwrap_or(match default {
            Acceleration::Anderson { window } => window,
            Acceleration::None => DEFAULT_ANDERSON_WINDOW,
        });
        self.check(
            (1..=MAX_ANDERSON_WINDOW).contains(&window),
            "solver.anderson_window",
            || format!("{window} is outside 1..={MAX_ANDERSON_WINDOW}"),
        )?;
        Ok(Acceleration::Anderson { window })
    }

    fn pgd(&self, r: Option<&RawPgd>) -> Result<PgdParams, SceneError> {
        let d = PgdParams::default();
        let Some(r) = r else { return Ok(d) };
        let p = PgdParams {
            enabled: r.enabled.unwrap_or(d.enabled),
            xi1: r.xi1.unwrap_or(d.xi1),
            xi2: r.xi2.unwrap_or(d.xi2),
            criterion: match r.criterion {
                None => d.criterion,
                Some(RawCriterion::Increment) => PgdCriterion::Increment,
                Some(RawCriterion::Accumulated) => PgdCriterion::Accumulated,
                Some(RawCriterion::IncrementSvd) => PgdCriterion::IncrementSvd,
            },
            macro_modes: r.macro_modes.unwrap_or(d.macro_modes),
            max_new_modes: r.max_new_modes.unwrap_or(d.max_new_modes),
        };
        self.check(p.max_new_modes >= 1, "solver.pgd.max_new_modes", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(p.xi1 > 0.0 && p.xi1.is_finite(), "solver.pgd.xi1", || {
            format!("{} must be > 0", p.xi1)
        })?;
        self.check(p.xi2 > 0.0 && p.xi2.is_finite(), "solver.pgd.xi2", || {
            format!("{} must be > 0", p.xi2)
        })?;
        Ok(p)
    }

    fn linear_stage(&self, r: &RawSolver) -> Result<LinearStage, SceneError> {
        let enabled = r.pgd.as_ref().and_then(|p| p.enabled);
        let stage = match r.linear_stage {
            None if enabled == Some(true) => return Ok(LinearStage::Pgd),
            None => return Ok(LinearStage::Condensed),
            Some(RawLinearStage::Condensed) => LinearStage::Condensed,
            Some(RawLinearStage::Sparse) => LinearStage::Sparse,
            Some(RawLinearStage::Pgd) => LinearStage::Pgd,
            Some(RawLinearStage::Auto) => LinearStage::Auto,
        };
        if let Some(e) = enabled {
            let pgd = stage == LinearStage::Pgd;
            self.check(e == pgd || stage == LinearStage::Auto, "solver.pgd.enabled", || {
                format!("{e} contradicts solver.linear_stage = {stage:?} (set one of them)")
            })?;
        }
        Ok(stage)
    }

    fn recording(&self, r: &RawRecording) -> Result<Recording, SceneError> {
        let d = Recording::default();
        let rec = Recording {
            enabled: r.enabled.unwrap_or(d.enabled),
            topics: r.topics.clone().unwrap_or(d.topics),
            full_fields_every: r.full_fields_every.unwrap_or(d.full_fields_every),
        };
        self.check(rec.full_fields_every >= 1, "recording.full_fields_every", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(rec.topics.iter().all(|t| !t.is_empty()), "recording.topics", || {
            "topic patterns must not be empty strings".to_string()
        })?;
        Ok(rec)
    }

    fn network(&self, r: &RawNetwork) -> Result<Network, SceneError> {
        let tls = match &r.tls {
            None => None,
            Some(t) => {
                for (key, value) in [("root_ca", &t.root_ca), ("cert", &t.cert), ("key", &t.key)] {
                    self.check(!value.trim().is_empty(), &format!("network.tls.{key}"), || {
                        "must name a PEM file (relative to the scene file's folder)".to_string()
                    })?;
                }
                Some(TlsFiles {
                    root_ca: t.root_ca.clone().into(),
                    cert: t.cert.clone().into(),
                    key: t.key.clone().into(),
                    mutual: t.mutual.unwrap_or(false),
                })
            }
        };
        if let Some(allow) = &r.allow {
            self.check(tls.is_some(), "network.allow", || {
                "access control names processes by their certificates: it needs network.tls (with mutual = true)"
                    .to_string()
            })?;
            self.check(tls.as_ref().is_some_and(|t| t.mutual), "network.allow", || {
                "access control needs network.tls.mutual = true (a process's common name is known only from the \
                 certificate it presents)"
                    .to_string()
            })?;
            self.check(!allow.is_empty(), "network.allow", || {
                "an empty list would let no process take part (remove the key to turn access control off)".to_string()
            })?;
            for (i, name) in allow.iter().enumerate() {
                self.check(!name.trim().is_empty(), &format!("network.allow[{i}]"), || {
                    "must be a certificate common name, not empty".to_string()
                })?;
                self.check(!allow[..i].contains(name), &format!("network.allow[{i}]"), || {
                    format!("`{name}` is listed twice")
                })?;
            }
        }
        Ok(Network {
            tls,
            allow: r.allow.clone(),
            shared_memory: r.shared_memory,
        })
    }

    fn deployment(&self, r: &RawDeployment, n_subdomains: usize) -> Result<Deployment, SceneError> {
        let d = Deployment::default();
        let dep = Deployment {
            subdomain_nodes: r.subdomain_nodes.unwrap_or(d.subdomain_nodes),
            interface_nodes: r
                .interface_nodes
                .or(r.interface_groups.as_ref().map(Vec::len))
                .unwrap_or(d.interface_nodes),
            interface_groups: None,
            restarts: r.restarts.unwrap_or(d.restarts),
        };
        self.check(dep.restarts <= 100, "deployment.restarts", || {
            format!(
                "{}: at most 100 (a node that keeps dying will not recover)",
                dep.restarts
            )
        })?;
        self.check(dep.subdomain_nodes >= 1, "deployment.subdomain_nodes", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(
            dep.subdomain_nodes <= n_subdomains,
            "deployment.subdomain_nodes",
            || {
                format!(
                    "{} nodes for {n_subdomains} subdomain(s): some nodes would host nothing",
                    dep.subdomain_nodes
                )
            },
        )?;
        self.check(dep.interface_nodes >= 1, "deployment.interface_nodes", || {
            "must be ≥ 1".to_string()
        })?;
        Ok(dep)
    }

    /// Checks `interface_nodes` against the interfaces and resolves `interface_groups`: each
    /// group non-empty, every interface in exactly one group.
    fn interface_groups(
        &self,
        r: &RawDeployment,
        dep: &mut Deployment,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        interfaces: &[Interface],
    ) -> Result<(), SceneError> {
        let n = interfaces.len();
        let Some(raw_groups) = &r.interface_groups else {
            return self.check(
                dep.interface_nodes == 1 || dep.interface_nodes <= n,
                "deployment.interface_nodes",
                || {
                    format!(
                        "{} nodes for {n} interface(s): some nodes would own nothing",
                        dep.interface_nodes
                    )
                },
            );
        };
        self.check(
            raw_groups.len() == dep.interface_nodes,
            "deployment.interface_groups",
            || {
                format!(
                    "{} group(s) for interface_nodes = {}: give one group per interface node",
                    raw_groups.len(),
                    dep.interface_nodes
                )
            },
        )?;
        let mut owner: Vec<Option<usize>> = vec![None; n];
        let mut groups = Vec::with_capacity(raw_groups.len());
        for (g, raw) in raw_groups.iter().enumerate() {
            let key = format!("deployment.interface_groups[{g}]");
            self.check(!raw.is_empty(), &key, || {
                "is empty: every interface node must own an interface".into()
            })?;
            let mut group = Vec::new();
            for (e, entry) in raw.iter().enumerate() {
                let key = format!("{key}[{e}]");
                let hits: Vec<usize> = match entry {
                    RawInterfaceRef::Index(i) => {
                        self.check(*i < n, &key, || {
                            format!(
                                "interface {i} does not exist (the scene has {n}, indices 0 to {})",
                                n.saturating_sub(1)
                            )
                        })?;
                        vec![*i]
                    }
                    RawInterfaceRef::Between(text) => {
                        let Some((x, y)) = text.split_once('|') else {
                            return Err(self.err(
                                key,
                                format!(
                                    "`{text}`: name an interface as \"A|B\" (blocks or subdomains) or by its index"
                                ),
                            ));
                        };
                        let (sx, _) = self.resolve(names, subs, x.trim(), &key)?;
                        let (sy, _) = self.resolve(names, subs, y.trim(), &key)?;
                        let hits: Vec<usize> = (0..n)
                            .filter(|&i| {
                                let (a, b) = (interfaces[i].a, interfaces[i].b);
                                (sx.contains(&a) && sy.contains(&b)) || (sx.contains(&b) && sy.contains(&a))
                            })
                            .collect();
                        self.check(!hits.is_empty(), &key, || format!("`{text}` matches no interface"))?;
                        hits
                    }
                };
                for i in hits {
                    if let Some(other) = owner[i] {
                        let itf = &interfaces[i];
                        return Err(self.err(
                            key,
                            format!(
                                "interface {i} ({}|{}) is already in group {other}",
                                subs[itf.a].name, subs[itf.b].name
                            ),
                        ));
                    }
                    owner[i] = Some(g);
                    group.push(i);
                }
            }
            group.sort_unstable();
            groups.push(group);
        }
        let unowned: Vec<String> = (0..n)
            .filter(|&i| owner[i].is_none())
            .map(|i| format!("{i} ({}|{})", subs[interfaces[i].a].name, subs[interfaces[i].b].name))
            .collect();
        self.check(unowned.is_empty(), "deployment.interface_groups", || {
            format!("interface(s) {} are in no group", unowned.join(", "))
        })?;
        dep.interface_groups = Some(groups);
        Ok(())
    }

    fn materials(&self, raw: &BTreeMap<String, RawMaterial>) -> Result<BTreeMap<String, Material>, SceneError> {
        let mut out = BTreeMap::new();
        for (name, m) in raw {
            self.check(m.e > 0.0 && m.e.is_finite(), &format!("materials.{name}.E"), || {
                format!("E = {} must be > 0 (MPa)", m.e)
            })?;
            self.check(m.nu > -1.0 && m.nu < 0.5, &format!("materials.{name}.nu"), || {
                format!("ν = {} is outside (−1, 0.5)", m.nu)
            })?;
            out.insert(name.clone(), Material { e: m.e, nu: m.nu });
        }
        Ok(out)
    }

    /// Per-block checks: names, material, extents, element counts, split, overlaps.
    fn blocks(&self, raw: &RawScene, materials: &BTreeMap<String, Material>) -> Result<(), SceneError> {
        self.check(!raw.block.is_empty(), "block", || {
            "the scene has no [[block]]".to_string()
        })?;
        for (i, b) in raw.block.iter().enumerate() {
            let key = |k: &str| format!("block[{i}].{k}");
            self.check(!b.name.is_empty(), &key("name"), || "block name is empty".to_string())?;
            if let Some(j) = raw.block[..i].iter().position(|o| o.name == b.name) {
                return Err(self.err(
                    key("name"),
                    format!("duplicate block name `{}` (also block[{j}])", b.name),
                ));
            }
            self.check(materials.contains_key(&b.material), &key("material"), || {
                let known: Vec<&str> = materials.keys().map(String::as_str).collect();
                format!("unknown material `{}` (defined: {})", b.material, known.join(", "))
            })?;
            for (axis, r) in [("x", b.x), ("y", b.y)] {
                self.check(r[0] < r[1] && r[0].is_finite() && r[1].is_finite(), &key(axis), || {
                    format!("{axis} = [{}, {}]: need {axis}0 < {axis}1", r[0], r[1])
                })?;
            }
            self.check(b.nx >= 1, &key("nx"), || {
                "nx = 0: need at least one element".to_string()
            })?;
            self.check(b.ny >= 1, &key("ny"), || {
                "ny = 0: need at least one element".to_string()
            })?;
            let [sx, sy] = b.split.unwrap_or([1, 1]);
            self.check(
                sx >= 1 && sy >= 1 && b.nx % sx == 0 && b.ny % sy == 0,
                &key("split"),
                || format!("split = [{sx}, {sy}] must divide (nx, ny) = ({}, {})", b.nx, b.ny),
            )?;
        }
        for (j, bj) in raw.block.iter().enumerate() {
            for bi in &raw.block[..j] {
                let tol = 1e-9 * block_dimension(bi).max(block_dimension(bj));
                let ox = bi.x[1].min(bj.x[1]) - bi.x[0].max(bj.x[0]);
                let oy = bi.y[1].min(bj.y[1]) - bi.y[0].max(bj.y[0]);
                if ox > tol && oy > tol {
                    return Err(self.err(
                        format!("block[{j}]"),
                        format!("block `{}` overlaps block `{}`", bj.name, bi.name),
                    ));
                }
            }
        }
        Ok(())
    }

    fn subdomains(&self, raw: &RawScene, materials: &BTreeMap<String, Material>) -> Vec<Sub> {
        let mut subs = Vec::new();
        for (bi, b) in raw.block.iter().enumerate() {
            let [sx, sy] = b.split.unwrap_or([1, 1]);
            let (ex, ey) = (b.nx / sx, b.ny / sy);
            let cut = |r: [f64; 2], k: usize, n: usize| {
                if k == n {
                    r[1]
                } else {
                    r[0] + (r[1] - r[0]) * k as f64 / n as f64
                }
            };
            for iy in 0..sy {
                for ix in 0..sx {
                    let x = [cut(b.x, ix, sx), cut(b.x, ix + 1, sx)];
                    let y = [cut(b.y, iy, sy), cut(b.y, iy + 1, sy)];
                    let name = if sx * sy == 1 {
                        b.name.clone()
                    } else {
                        format!("{}.{}", b.name, iy * sx + ix + 1)
                    };
                    let mut outer = [false; 4];
                    outer[BlockSide::Bottom as usize] = iy == 0;
                    outer[BlockSide::Right as usize] = ix + 1 == sx;
                    outer[BlockSide::Top as usize] = iy + 1 == sy;
                    outer[BlockSide::Left as usize] = ix == 0;
                    subs.push(Sub {
                        name,
                        block: bi,
                        x,
                        y,
                        outer,
                        tol: 1e-9 * block_dimension(b),
                        mesh: Mesh::rectangle(x, y, ex, ey),
                        material: materials[&b.material],
                    });
                }
            }
        }
        subs
    }

    /// Name table: block names and generated subdomain names, all distinct.
    fn names(&self, raw: &RawScene, subs: &[Sub]) -> Result<BTreeMap<String, NameRef>, SceneError> {
        let mut names = BTreeMap::new();
        for (i, b) in raw.block.iter().enumerate() {
            names.insert(b.name.clone(), NameRef::Block(i));
        }
        for (s, sub) in subs.iter().enumerate() {
            if sub.name == raw.block[sub.block].name {
                continue;
            }
            if let Some(other) = names.get(&sub.name) {
                let what = match *other {
                    NameRef::Block(j) => format!("block[{j}]"),
                    NameRef::Sub(o) => {
                        format!("a subdomain of block `{}`", raw.block[subs[o].block].name)
                    }
                };
                return Err(self.err(
                    format!("block[{}].name", sub.block),
                    format!(
                        "subdomain name `{}` generated from block `{}` is also the name of {what}",
                        sub.name, raw.block[sub.block].name
                    ),
                ));
            }
            names.insert(sub.name.clone(), NameRef::Sub(s));
        }
        Ok(names)
    }

    /// Subdomains a name stands for, and whether it names a block.
    fn resolve(
        &self,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        name: &str,
        key: &str,
    ) -> Result<(Vec<usize>, bool), SceneError> {
        match names.get(name) {
            Some(NameRef::Block(b)) => Ok(((0..subs.len()).filter(|&s| subs[s].block == *b).collect(), true)),
            Some(NameRef::Sub(s)) => Ok((vec![*s], false)),
            None => Err(self.err(key, format!("unknown block or subdomain `{name}`"))),
        }
    }

    /// The interface between subdomains i < j, if their opposite sides share a segment of
    /// positive length; an error if the meshes do not conform there.
    fn find_interface(&self, subs: &[Sub], i: usize, j: usize) -> Result<Option<GeoInterface>, SceneError> {
        let (si, sj) = (&subs[i], &subs[j]);
        let tol = si.tol.max(sj.tol);
        // (a, b, horizontal): a below / left of b.
        let candidates = [
            (i, j, true, (si.y[1] - sj.y[0]).abs() <= tol),
            (j, i, true, (sj.y[1] - si.y[0]).abs() <= tol),
            (i, j, false, (si.x[1] - sj.x[0]).abs() <= tol),
            (j, i, false, (sj.x[1] - si.x[0]).abs() <= tol),
        ];
        for (a, b, horizontal, touching) in candidates {
            if !touching {
                continue;
            }
            let (sa, sb) = (&subs[a], &subs[b]);
            // `axis`: coordinate along the interface.
            let (axis, side_a, side_b, ra, rb, line) = if horizontal {
                (
                    0,
                    BlockSide::Top,
                    BlockSide::Bottom,
                    sa.x,
                    sb.x,
                    format!("y = {}", fmt_num(sa.y[1])),
                )
            } else {
                (
                    1,
                    BlockSide::Right,
                    BlockSide::Left,
                    sa.y,
                    sb.y,
                    format!("x = {}", fmt_num(sa.x[1])),
                )
            };
            let lo = ra[0].max(rb[0]);
            let hi = ra[1].min(rb[1]);
            if hi - lo <= tol {
                continue;
            }
            let axis_name = if axis == 0 { "x" } else { "y" };
            let key = format!("block[{}]", sa.block.max(sb.block));
            let within = |c: f64| c >= lo - tol && c <= hi + tol;
            // (node, coordinate along, is a corner node) of each side within the overlap.
            let collect = |s: &Sub, side: BlockSide| -> Vec<(usize, f64, bool)> {
                s.mesh
                    .side_nodes(side)
                    .into_iter()
                    .enumerate()
                    .map(|(k, n)| (n, s.mesh.coords[n][axis], k % 2 == 0))
                    .filter(|&(_, c, _)| within(c))
                    .collect()
            };
            let mismatch = |c: f64, why: &str| {
                self.err(
                    key.clone(),
                    format!(
                        "subdomains `{}` and `{}` share the segment {axis_name} ∈ [{}, {}] of the line {line} but their \
                         meshes do not conform: {why} at {axis_name} = {}",
                        sa.name,
                        sb.name,
                        fmt_num(lo),
                        fmt_num(hi),
                        fmt_num(c)
                    ),
                )
            };
            let na = collect(sa, side_a);
            let nb = collect(sb, side_b);
            if na.is_empty() || nb.is_empty() {
                return Err(mismatch(lo, "no node of one side lies on the shared segment"));
            }
            for (k, (&(_, ca, corner_a), &(_, cb, corner_b))) in na.iter().zip(&nb).enumerate() {
                if (ca - cb).abs() > tol {
                    return Err(mismatch(ca.min(cb), "nodes do not coincide"));
                }
                if corner_a != corner_b {
                    return Err(mismatch(ca, "a corner node faces a mid-side node"));
                }
                if (k == 0 || k + 1 == na.len()) && !corner_a {
                    return Err(mismatch(ca, "an element edge crosses the end of the shared segment"));
                }
            }
            if na.len() != nb.len() {
                let k = na.len().min(nb.len());
                let c = if na.len() > k { na[k].1 } else { nb[k].1 };
                return Err(mismatch(c, "a node has no partner"));
            }
            let mut pair_of = vec![usize::MAX; sa.mesh.n_nodes()];
            for (p, &(n, _, _)) in na.iter().enumerate() {
                pair_of[n] = p;
            }
            let mut weights = vec![0.0; na.len()];
            let mut length = 0.0;
            for e in &sa.mesh.sides[side_a as usize] {
                if !(within(sa.mesh.coords[e[0]][axis]) && within(sa.mesh.coords[e[2]][axis])) {
                    continue;
                }
                let x = [sa.mesh.coords[e[0]], sa.mesh.coords[e[1]], sa.mesh.coords[e[2]]];
                for (k, m) in edge_lumped_mass(&x).into_iter().enumerate() {
                    weights[pair_of[e[k]]] += m;
                }
                length += ((x[2][0] - x[0][0]).powi(2) + (x[2][1] - x[0][1]).powi(2)).sqrt();
            }
            return Ok(Some(GeoInterface {
                a,
                b,
                horizontal,
                pairs: na.iter().zip(&nb).map(|(&(n, _, _), &(m, _, _))| (n, m)).collect(),
                coords: na.iter().map(|&(n, _, _)| sa.mesh.coords[n]).collect(),
                weights,
                length,
            }));
        }
        Ok(None)
    }

    /// Kind of each geometric interface after applying the `[[interface]]` rules in order.
    fn interface_rules(
        &self,
        raw: &RawScene,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        geo: &[GeoInterface],
    ) -> Result<Vec<KindRule>, SceneError> {
        let mut kinds = vec![KindRule::Perfect; geo.len()];
        for (r, rule) in raw.interface.iter().enumerate() {
            let key = format!("interface[{r}]");
            let (s0, _) = self.resolve(names, subs, &rule.between[0], &format!("{key}.between"))?;
            let (s1, _) = self.resolve(names, subs, &rule.between[1], &format!("{key}.between"))?;
            let kind = match rule.kind {
                RawKind::Perfect => {
                    if rule.friction.is_some() {
                        return Err(self.err(
                            format!("{key}.friction"),
                            "`friction` applies to contact interfaces only",
                        ));
                    }
                    if rule.gap.is_some() {
                        return Err(self.err(format!("{key}.gap"), "`gap` applies to contact interfaces only"));
                    }
                    KindRule::Perfect
                }
                RawKind::Contact => {
                    let Some(f) = rule.friction else {
                        return Err(self.err(
                            format!("{key}.friction"),
                            "a contact interface needs `friction` (0 for frictionless contact)",
                        ));
                    };
                    self.check(f >= 0.0 && f.is_finite(), &format!("{key}.friction"), || {
                        format!("friction coefficient {f} must be ≥ 0")
                    })?;
                    KindRule::Contact(r)
                }
            };
            let mut matched = false;
            for (g, itf) in geo.iter().enumerate() {
                let hit = (s0.contains(&itf.a) && s1.contains(&itf.b)) || (s0.contains(&itf.b) && s1.contains(&itf.a));
                if hit {
                    kinds[g] = kind;
                    matched = true;
                }
            }
            if !matched {
                return Err(self.err(
                    format!("{key}.between"),
                    format!("`{}` and `{}` share no edge", rule.between[0], rule.between[1]),
                ));
            }
        }
        Ok(kinds)
    }

    fn gap_specs(&self, raw: &RawScene) -> Result<Vec<Option<GapSpec>>, SceneError> {
        raw.interface
            .iter()
            .enumerate()
            .map(|(r, rule)| {
                let key = format!("interface[{r}].gap");
                let Some(v) = &rule.gap else { return Ok(None) };
                let spec = match v {
                    toml::Value::Integer(i) => GapSpec::Constant(*i as f64),
                    toml::Value::Float(f) => GapSpec::Constant(*f),
                    toml::Value::String(s) => {
                        GapSpec::Formula(Expr::parse(s, &["x", "y"]).map_err(|e| self.err(&key, e.to_string()))?)
                    }
                    toml::Value::Table(t) => {
                        let (axis, xs, gs) = self.table(t, &key, &["x", "y"], "g")?;
                        GapSpec::Table { axis, xs, gs }
                    }
                    other => {
                        return Err(self.err(
                            key,
                            format!(
                                "expected a number, a formula in x, y (string) or a table {{ x = [..], g = [..] }}, \
                                 found {}",
                                other.type_str()
                            ),
                        ))
                    }
                };
                Ok(Some(spec))
            })
            .collect()
    }

    /// A piecewise-linear table `{ <abscissa> = [..], <ordinate> = [..] }` with one abscissa name
    /// out of `abscissae`; returns (which abscissa, abscissae, values).
    fn table(
        &self,
        t: &toml::Table,
        key: &str,
        abscissae: &[&str],
        ordinate: &str,
    ) -> Result<(usize, Vec<f64>, Vec<f64>), SceneError> {
        let expected = abscissae
            .iter()
            .map(|a| format!("{{ {a} = [..], {ordinate} = [..] }}"))
            .collect::<Vec<_>>()
            .join(" or ");
        let bad = |why: String| self.err(key, format!("bad table: {why} (expected {expected})"));
        for k in t.keys() {
            if k != ordinate && !abscissae.contains(&k.as_str()) {
                return Err(bad(format!("unknown key `{k}`")));
            }
        }
        let present: Vec<usize> = (0..abscissae.len()).filter(|&i| t.contains_key(abscissae[i])).collect();
        if present.len() != 1 || !t.contains_key(ordinate) {
            return Err(bad("needs exactly one abscissa array and the value array".to_string()));
        }
        let axis = present[0];
        let numbers = |name: &str| -> Result<Vec<f64>, SceneError> {
            let Some(toml::Value::Array(a)) = t.get(name) else {
                return Err(bad(format!("`{name}` is not an array")));
            };
            a.iter()
                .map(|v| match v {
                    toml::Value::Integer(i) => Ok(*i as f64),
                    toml::Value::Float(f) if f.is_finite() => Ok(*f),
                    other => Err(bad(format!(
                        "`{name}` holds {} `{other}`, not a finite number",
                        other.type_str()
                    ))),
                })
                .collect()
        };
        let xs = numbers(abscissae[axis])?;
        let vs = numbers(ordinate)?;
        let a = abscissae[axis];
        if xs.is_empty() {
            return Err(bad(format!("`{a}` is empty")));
        }
        if xs.len() != vs.len() {
            return Err(bad(format!(
                "`{a}` has {} entries but `{ordinate}` has {}",
                xs.len(),
                vs.len()
            )));
        }
        if let Some(k) = (1..xs.len()).find(|&k| xs[k] <= xs[k - 1]) {
            return Err(bad(format!(
                "`{a}` is not strictly increasing: {a}[{k}] = {} ≤ {a}[{}] = {}",
                xs[k],
                k - 1,
                xs[k - 1]
            )));
        }
        Ok((axis, xs, vs))
    }

    fn time_function(&self, value: &toml::Value, key: &str, time: TimeGrid) -> Result<TimeFunction, SceneError> {
        let tf = match value {
            toml::Value::Integer(i) => TimeFunction::Constant(*i as f64),
            toml::Value::Float(f) => TimeFunction::Constant(*f),
            toml::Value::String(s) => {
                TimeFunction::Formula(Expr::parse(s, &["t"]).map_err(|e| self.err(key, e.to_string()))?)
            }
            toml::Value::Table(t) => {
                let (_, ts, vs) = self.table(t, key, &["t"], "v")?;
                TimeFunction::Table { t: ts, v: vs }
            }
            other => {
                return Err(self.err(
                    key,
                    format!(
                        "expected a number, a formula in t (string) or a table {{ t = [..], v = [..] }}, found {}",
                        other.type_str()
                    ),
                ))
            }
        };
        for i in 0..time.n_points() {
            let t = time.t(i);
            let v = tf.eval(t);
            self.check(v.is_finite(), key, || format!("value {v} at t = {t} is not finite"))?;
        }
        Ok(tf)
    }

    /// Constraints and load cases of every subdomain from the `[[boundary]]` rules.
    fn boundaries(
        &self,
        raw: &RawScene,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        time: TimeGrid,
    ) -> Result<Vec<SubLoads>, SceneError> {
        let mut out: Vec<SubLoads> = subs
            .iter()
            .map(|s| {
                let n = 2 * s.mesh.n_nodes();
                SubLoads {
                    constrained: vec![false; n],
                    loads: Vec::new(),
                    owner: vec![usize::MAX; n],
                }
            })
            .collect();
        for (r, rule) in raw.boundary.iter().enumerate() {
            let key = format!("boundary[{r}]");
            let disp = [("ux", &rule.ux), ("uy", &rule.uy)];
            let trac = [("tx", &rule.tx), ("ty", &rule.ty), ("p", &rule.p)];
            let has_disp = disp.iter().any(|(_, v)| v.is_some());
            let has_trac = trac.iter().any(|(_, v)| v.is_some());
            if has_disp && has_trac {
                return Err(self.err(
                    key,
                    "a rule prescribes either displacements (ux, uy) or tractions (tx, ty, p), not both",
                ));
            }
            if !has_disp && !has_trac {
                return Err(self.err(key, "prescribes nothing: give ux/uy or tx/ty/p"));
            }
            if rule.side.is_none() && rule.x.is_none() && rule.y.is_none() {
                return Err(self.err(key, "selects no side: give `side`, `x` or `y`"));
            }
            let selected = self.select_sides(rule, names, subs, &key)?;

            for (c, (comp, value)) in disp.iter().enumerate() {
                let Some(value) = value else { continue };
                let tf = self.time_function(value, &format!("{key}.{comp}"), time)?;
                for (&s, sides) in &selected {
                    let sl = &mut out[s];
                    let case = sl.loads.len();
                    let mut pattern = vec![0.0; sl.constrained.len()];
                    for &side in sides {
                        for node in subs[s].mesh.side_nodes(side) {
                            let dof = 2 * node + c;
                            pattern[dof] = 1.0;
                            sl.constrained[dof] = true;
                            let prev = sl.owner[dof];
                            if prev != usize::MAX && prev != case {
                                sl.loads[prev].displacement[dof] = 0.0;
                            }
                            sl.owner[dof] = case;
                        }
                    }
                    sl.loads.push(LoadCase {
                        force: vec![0.0; pattern.len()],
                        displacement: pattern,
                        time: tf.clone(),
                    });
                }
            }
            for (comp, value) in trac {
                let Some(value) = value else { continue };
                let tf = self.time_function(value, &format!("{key}.{comp}"), time)?;
                for (&s, sides) in &selected {
                    let mesh = &subs[s].mesh;
                    let mut force = vec![0.0; 2 * mesh.n_nodes()];
                    for &side in sides {
                        let unit = match comp {
                            "tx" => [1.0, 0.0],
                            "ty" => [0.0, 1.0],
                            _ => {
                                let n = outward_normal(side);
                                [-n[0], -n[1]]
                            }
                        };
                        for e in &mesh.sides[side as usize] {
                            let x = [mesh.coords[e[0]], mesh.coords[e[1]], mesh.coords[e[2]]];
                            let f = edge_load(&x, |_| unit);
                            for k in 0..3 {
                                force[2 * e[k]] += f[k][0];
                                force[2 * e[k] + 1] += f[k][1];
                            }
                        }
                    }
                    out[s].loads.push(LoadCase {
                        displacement: vec![0.0; force.len()],
                        force,
                        time: tf.clone(),
                    });
                }
            }
        }
        for sl in &mut out {
            sl.loads
                .retain(|c| c.force.iter().chain(&c.displacement).any(|&v| v != 0.0));
        }
        Ok(out)
    }

    /// Sides selected by a boundary rule, per subdomain (global order).
    fn select_sides(
        &self,
        rule: &RawBoundary,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        key: &str,
    ) -> Result<BTreeMap<usize, Vec<BlockSide>>, SceneError> {
        // (subdomain, only the block's outer sides)
        let mut candidates: BTreeMap<usize, bool> = BTreeMap::new();
        match &rule.blocks {
            None => {
                for s in 0..subs.len() {
                    candidates.insert(s, true);
                }
            }
            Some(list) => {
                for name in list {
                    let (ss, is_block) = self.resolve(names, subs, name, &format!("{key}.blocks"))?;
                    for s in ss {
                        let outer_only = candidates.get(&s).copied().unwrap_or(true) && is_block;
                        candidates.insert(s, outer_only);
                    }
                }
            }
        }
        let mut selected: BTreeMap<usize, Vec<BlockSide>> = BTreeMap::new();
        for (&s, &outer_only) in &candidates {
            let sub = &subs[s];
            for side in BlockSide::ALL {
                if outer_only && !sub.outer[side as usize] {
                    continue;
                }
                if rule.side.is_some_and(|want| want.block_side() != side) {
                    continue;
                }
                let vertical = matches!(side, BlockSide::Left | BlockSide::Right);
                let line = match side {
                    BlockSide::Bottom => sub.y[0],
                    BlockSide::Top => sub.y[1],
                    BlockSide::Left => sub.x[0],
                    BlockSide::Right => sub.x[1],
                };
                if let Some(x) = rule.x {
                    if !vertical || (line - x).abs() > sub.tol {
                        continue;
                    }
                }
                if let Some(y) = rule.y {
                    if vertical || (line - y).abs() > sub.tol {
                        continue;
                    }
                }
                selected.entry(s).or_default().push(side);
            }
        }
        if selected.is_empty() {
            let mut what = Vec::new();
            if let Some(side) = rule.side {
                what.push(format!("side = {}", side.block_side().name()));
            }
            if let Some(x) = rule.x {
                what.push(format!("x = {}", fmt_num(x)));
            }
            if let Some(y) = rule.y {
                what.push(format!("y = {}", fmt_num(y)));
            }
            let among = match &rule.blocks {
                Some(b) => format!(" of {}", b.join(", ")),
                None => String::new(),
            };
            return Err(self.err(key, format!("no outer side{among} matches {}", what.join(", "))));
        }
        Ok(selected)
    }

    /// Final interfaces: kinds and gaps, pairs clamped on both sides left out, empty interfaces
    /// dropped, centroids.
    fn finish_interfaces(
        &self,
        raw: &RawScene,
        geo: Vec<GeoInterface>,
        kinds: &[KindRule],
        gaps: &[Option<GapSpec>],
        loads: &[SubLoads],
    ) -> Result<Vec<Interface>, SceneError> {
        let clamped = |s: usize, n: usize| loads[s].constrained[2 * n] && loads[s].constrained[2 * n + 1];
        let mut out = Vec::new();
        for (g, kind) in geo.into_iter().zip(kinds) {
            let keep: Vec<usize> = (0..g.pairs.len())
                .filter(|&p| !(clamped(g.a, g.pairs[p].0) && clamped(g.b, g.pairs[p].1)))
                .collect();
            if keep.is_empty() {
                continue;
            }
            let pairs: Vec<(usize, usize)> = keep.iter().map(|&p| g.pairs[p]).collect();
            let coords: Vec<[f64; 2]> = keep.iter().map(|&p| g.coords[p]).collect();
            let weights: Vec<f64> = keep.iter().map(|&p| g.weights[p]).collect();
            let kind = match *kind {
                KindRule::Perfect => InterfaceKind::Perfect,
                KindRule::Contact(r) => {
                    let friction = raw.interface[r].friction.unwrap_or(0.0);
                    let mut gap = Vec::with_capacity(coords.len());
                    for &c in &coords {
                        let g0 = gaps[r].as_ref().map_or(0.0, |spec| spec.eval(c));
                        self.check(g0.is_finite(), &format!("interface[{r}].gap"), || {
                            format!("gap {g0} at (x, y) = ({}, {}) is not finite", c[0], c[1])
                        })?;
                        gap.push(g0);
                    }
                    InterfaceKind::Contact { friction, gap }
                }
            };
            let total: f64 = weights.iter().sum();
            let mut centroid = [0.0; 2];
            for (w, c) in weights.iter().zip(&coords) {
                centroid[0] += w * c[0] / total;
                centroid[1] += w * c[1] / total;
            }
            let normal = if g.horizontal { [0.0, 1.0] } else { [1.0, 0.0] };
            out.push(Interface {
                kind,
                a: g.a,
                b: g.b,
                pairs,
                coords,
                weights,
                normal,
                tangent: [-normal[1], normal[0]],
                length: g.length,
                centroid,
            });
        }
        Ok(out)
    }

    /// Every group of subdomains connected through interfaces must have its rigid-body modes
    /// blocked by prescribed displacements: the rows [δ_c0, δ_c1, c = 0 ? −(y − ȳ) : (x − x̄)]
    /// over the constrained dofs must have rank 3.
    fn check_rigid_modes(&self, subs: &[Sub], interfaces: &[Interface], loads: &[SubLoads]) -> Result<(), SceneError> {
        let mut parent: Vec<usize> = (0..subs.len()).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        for itf in interfaces {
            let (ra, rb) = (root(&mut parent, itf.a), root(&mut parent, itf.b));
            if ra != rb {
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
        let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for s in 0..subs.len() {
            let r = root(&mut parent, s);
            groups.entry(r).or_default().push(s);
        }
        for members in groups.values() {
            // Constrained (coordinates, component).
            let mut rows: Vec<([f64; 2], usize)> = Vec::new();
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &s in members {
                lo = [lo[0].min(subs[s].x[0]), lo[1].min(subs[s].y[0])];
                hi = [hi[0].max(subs[s].x[1]), hi[1].max(subs[s].y[1])];
                for (d, &c) in loads[s].constrained.iter().enumerate() {
                    if c {
                        rows.push((subs[s].mesh.coords[d / 2], d % 2));
                    }
                }
            }
            let scale = (hi[0] - lo[0]).max(hi[1] - lo[1]);
            let n = rows.len().max(1) as f64;
            let mean = [
                rows.iter().map(|r| r.0[0]).sum::<f64>() / n,
                rows.iter().map(|r| r.0[1]).sum::<f64>() / n,
            ];
            let mut gram = nalgebra::Matrix3::<f64>::zeros();
            for &(p, c) in &rows {
                let row = if c == 0 {
                    nalgebra::Vector3::new(1.0, 0.0, -(p[1] - mean[1]) / scale)
                } else {
                    nalgebra::Vector3::new(0.0, 1.0, (p[0] - mean[0]) / scale)
                };
                gram += row * row.transpose();
            }
            let eig = gram.symmetric_eigenvalues();
            let max = eig.iter().fold(0.0f64, |m, &v| m.max(v));
            let rank = eig.iter().filter(|&&v| v > 1e-10 * max && max > 0.0).count();
            if rank == 3 {
                continue;
            }
            let mut free = Vec::new();
            if !rows.iter().any(|r| r.1 == 0) {
                free.push("x-translation");
            }
            if !rows.iter().any(|r| r.1 == 1) {
                free.push("y-translation");
            }
            if free.len() < 3 - rank {
                free.push("rotation");
            }
            let shown: Vec<&str> = members.iter().take(6).map(|&s| subs[s].name.as_str()).collect();
            let more = if members.len() > shown.len() {
                format!(", … ({} in all)", members.len())
            } else {
                String::new()
            };
            let modes = match free.split_last() {
                Some((last, [])) => last.to_string(),
                Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
                None => String::new(),
            };
            return Err(self.err(
                "boundary",
                format!(
                    "rigid-body motion of subdomains [{}{more}] is not blocked: {modes} free; prescribe displacements \
                     that block it (subdomains connected through interfaces count as one body)",
                    shown.join(", "),
                ),
            ));
        }
        Ok(())
    }
}

fn block_dimension(b: &RawBlock) -> f64 {
    (b.x[1] - b.x[0]).abs().max((b.y[1] - b.y[0]).abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_BLOCKS: &str = r#"
name = "two"
[time]
T = 1.0
N = 4
[materials.steel]
E = 210000.0
nu = 0.3
[[block]]
name = "lower"
material = "steel"
x = [0.0, 40.0]
y = [0.0, 20.0]
nx = 16
ny = 8
[[block]]
name = "upper"
material = "steel"
x = [0.0, 40.0]
y = [20.0, 40.0]
nx = 16
ny = 8
[[interface]]
between = ["lower", "upper"]
kind = "contact"
friction = 0.2
[[boundary]]
y = 0.0
ux = 0.0
uy = 0.0
[[boundary]]
y = 40.0
ux = "0.004*sin(2*pi*t)"
uy = -0.01
"#;

    fn load(text: &str) -> Result<LoadedScene, SceneError> {
        load_str(text, "scenes/test.toml")
    }

    /// Loads `text` expecting an error with key `key` and a problem containing `part`.
    #[track_caller]
    fn expect_err(text: &str, key: &str, part: &str) -> SceneError {
        let Err(e) = load(text) else {
            panic!("scene should be rejected (`{key}`: {part})")
        };
        assert_eq!(e.key, key, "{e}");
        assert!(e.problem.contains(part), "`{part}` not in: {e}");
        assert_eq!(e.file, "scenes/test.toml");
        e
    }

    #[track_caller]
    fn replaced(from: &str, to: &str) -> String {
        assert!(TWO_BLOCKS.contains(from), "{from}");
        TWO_BLOCKS.replacen(from, to, 1)
    }

    /// Command-line overrides of the solver's tolerance and iteration cap go into the scene
    /// text: the text alone (what node processes and recordings get) builds the overridden
    /// model, and its fingerprint is not the original's.
    #[test]
    fn solver_overrides_rewrite_the_scene_text() {
        let s = load(TWO_BLOCKS).unwrap();
        assert_eq!(
            s.with_solver_overrides("scenes/test.toml", None, None).unwrap().text,
            s.text
        );
        let o = s
            .with_solver_overrides("scenes/test.toml", Some(2.5e-9), Some(7))
            .unwrap();
        assert_eq!((o.model.solver.tolerance, o.model.solver.max_iterations), (2.5e-9, 7));
        assert_ne!(o.fingerprint, s.fingerprint);
        assert!(
            o.text
                .starts_with("# scenes/test.toml with [solver] tolerance = 2.5e-9, max_iterations = 7 set"),
            "{}",
            o.text
        );
        let again = load(&o.text).unwrap();
        assert_eq!(
            (again.model.solver.tolerance, again.model.solver.max_iterations),
            (2.5e-9, 7)
        );
        // Everything else is the scene as written.
        assert_eq!(again.model.name, "two");
        let unchanged = |m: &Model| {
            let mut m = m.clone();
            m.solver.tolerance = 0.0;
            m.solver.max_iterations = 0;
            format!("{m:?}")
        };
        assert_eq!(unchanged(&again.model), unchanged(&s.model));
        // A scene with a [solver] table keeps its other keys; an invalid value is the scene's
        // own error.
        let with_solver = load(&format!("{TWO_BLOCKS}[solver]\nrelaxation = 0.5\n")).unwrap();
        let o = with_solver
            .with_solver_overrides("scenes/test.toml", None, Some(3))
            .unwrap();
        assert_eq!((o.model.solver.relaxation, o.model.solver.max_iterations), (0.5, 3));
        let e = s.with_solver_overrides("scenes/test.toml", None, Some(0)).unwrap_err();
        assert_eq!(e.key, "solver.max_iterations", "{e}");
        let e = s
            .with_solver_overrides("scenes/test.toml", Some(-1.0), None)
            .unwrap_err();
        assert_eq!(e.key, "solver.tolerance", "{e}");
    }

    #[test]
    fn two_blocks_has_one_contact_interface() {
        let s = load(TWO_BLOCKS).unwrap();
        let m = &s.model;
        assert_eq!(m.name, "two");
        assert_eq!(m.plane, Plane::Strain);
        assert_eq!(m.subdomains.len(), 2);
        assert_eq!(m.interfaces.len(), 1);
        let itf = &m.interfaces[0];
        assert_eq!((itf.a, itf.b), (0, 1));
        assert_eq!(m.subdomains[itf.a].name, "lower");
        assert_eq!(itf.n_pairs(), 33);
        assert_eq!(itf.normal, [0.0, 1.0]);
        assert_eq!(itf.tangent, [-1.0, 0.0]);
        assert!((itf.weights.iter().sum::<f64>() - 40.0).abs() < 1e-12);
        assert!((itf.length - 40.0).abs() < 1e-12);
        assert!((itf.centroid[0] - 20.0).abs() < 1e-12 && (itf.centroid[1] - 20.0).abs() < 1e-12);
        for (p, &(na, nb)) in itf.pairs.iter().enumerate() {
            let (ca, cb) = (m.subdomains[0].mesh.coords[na], m.subdomains[1].mesh.coords[nb]);
            assert!((ca[0] - cb[0]).abs() < 1e-12 && ca[1] == 20.0 && (cb[1] - 20.0).abs() < 1e-12);
            assert!((ca[0] - 1.25 * p as f64).abs() < 1e-12);
        }
        assert_eq!(
            itf.kind,
            InterfaceKind::Contact {
                friction: 0.2,
                gap: vec![0.0; 33]
            }
        );
        // Lower: both components clamped on y = 0 (two load cases); upper: ux, uy on y = 40.
        let lower = &m.subdomains[0];
        assert_eq!(lower.constrained.iter().filter(|&&c| c).count(), 2 * 33);
        assert_eq!(lower.loads.len(), 2);
        let upper = &m.subdomains[1];
        assert_eq!(upper.loads.len(), 2);
        assert!((upper.loads[0].time.eval(0.25) - 0.004).abs() < 1e-15);
        assert_eq!(upper.loads[1].time.eval(0.5), -0.01);
        assert_eq!(upper.loads[1].displacement.iter().sum::<f64>(), 33.0);
        assert_eq!(s.deployment, Deployment::default());
        assert_eq!(s.recording, Recording::default());
        assert_eq!(s.pgd, PgdParams::default());
        assert_eq!(m.solver, SolverParams::default());
        assert_eq!(s.fingerprint, fingerprint(TWO_BLOCKS));
    }

    #[test]
    fn stratified_scene() {
        let s = load_str(
            include_str!("../../../launch/scenes/stratified.toml"),
            "stratified.toml",
        )
        .unwrap();
        let m = &s.model;
        assert_eq!(m.subdomains.len(), 18);
        assert_eq!(m.subdomains[0].name, "bottom.1");
        assert_eq!(m.subdomains[6].name, "core.1");
        assert_eq!(m.subdomains[17].name, "top.6");
        assert_eq!(m.time.n_steps, 100);
        assert_eq!(m.interfaces.len(), 27);
        let perfect: Vec<&Interface> = m.interfaces.iter().filter(|i| !i.is_contact()).collect();
        let contact: Vec<&Interface> = m.interfaces.iter().filter(|i| i.is_contact()).collect();
        assert_eq!(perfect.len(), 15);
        assert_eq!(contact.len(), 12);
        for i in &perfect {
            assert_eq!(i.normal, [1.0, 0.0]);
            assert_eq!(i.n_pairs(), 41);
            assert!(i.coords.iter().all(|c| c[0] > 0.0));
            assert_eq!(
                m.subdomains[i.b].name.split('.').next(),
                m.subdomains[i.a].name.split('.').next()
            );
        }
        let first = contact[0];
        assert_eq!((first.a, first.b), (0, 6));
        assert_eq!(first.n_pairs(), 40);
        assert!((first.coords[0][0] - 0.75).abs() < 1e-12);
        assert!(contact.iter().filter(|i| i.n_pairs() == 41).count() == 10);
        for i in &contact {
            assert_eq!(
                i.kind,
                InterfaceKind::Contact {
                    friction: 0.3,
                    gap: vec![0.0; i.n_pairs()]
                }
            );
        }
        // Total pressure force on y = 0 at t = 0 (the sine loads vanish): 100 MPa × 180 mm.
        let fy = |range: std::ops::Range<usize>| -> f64 {
            range
                .map(|s| {
                    let sub = &m.subdomains[s];
                    sub.loads
                        .iter()
                        .map(|c| c.time.eval(0.0) * c.force.iter().skip(1).step_by(2).sum::<f64>())
                        .sum::<f64>()
                })
                .sum()
        };
        assert!((fy(0..6) - 18000.0).abs() < 1e-8, "{}", fy(0..6));
        assert!((fy(12..18) + 18000.0).abs() < 1e-8);
        // Axial traction on the core's end only: resultant 6000 N at t = T/4.
        let fx: f64 = (0..18)
            .map(|s| {
                let sub = &m.subdomains[s];
                sub.loads
                    .iter()
                    .map(|c| c.time.eval(2.5) * c.force.iter().step_by(2).sum::<f64>())
                    .sum::<f64>()
            })
            .sum();
        assert!((fx - 6000.0).abs() < 1e-8, "{fx}");
        assert_eq!(s.deployment.subdomain_nodes, 3);
        assert_eq!(m.solver.tolerance, 1e-4);
        assert_eq!((s.pgd.xi1, s.pgd.xi2), (0.1, 0.01));
    }

    #[test]
    fn every_scene_file_loads() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../launch/scenes");
        let mut paths: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        paths.sort();
        assert!(paths.len() >= 5, "{paths:?}");
        for p in paths {
            let text = std::fs::read_to_string(&p).unwrap();
            let s = load_str(&text, &p.display().to_string()).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(
                s.model.name,
                p.file_stem().unwrap().to_string_lossy(),
                "{}",
                p.display()
            );
        }
    }

    #[test]
    fn reference_scenes_match_the_getfem_setup() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../launch/scenes/");
        let read = |f: &str| std::fs::read_to_string(format!("{dir}{f}")).unwrap();
        let h = load_str(&read("hertz-slip.toml"), "hertz-slip.toml").unwrap().model;
        assert_eq!(h.interfaces.len(), 1);
        let itf = &h.interfaces[0];
        assert_eq!(itf.n_pairs(), 81);
        let InterfaceKind::Contact { friction, gap } = &itf.kind else {
            panic!()
        };
        assert_eq!(*friction, 0.3);
        assert!((gap[0] - 2.0).abs() < 1e-12 && gap[40].abs() < 1e-15);
        let top = &h.subdomains[1].loads;
        assert_eq!(top.len(), 2);
        assert!((top[0].time.eval(0.75) - 0.0015).abs() < 1e-15);
        assert!((top[1].time.eval(0.25) + 0.01).abs() < 1e-15);
        let l = load_str(&read("layered.toml"), "layered.toml").unwrap().model;
        assert_eq!(l.subdomains.len(), 3);
        assert_eq!(l.interfaces.len(), 2);
        assert!(l.interfaces.iter().all(|i| i.is_contact() && i.n_pairs() == 240));
        let small = load_str(&read("small-three-layer.toml"), "small-three-layer.toml")
            .unwrap()
            .model;
        assert_eq!(small.subdomains.len(), 6);
        assert_eq!(small.interfaces.iter().filter(|i| !i.is_contact()).count(), 3);
        let contact: Vec<&Interface> = small.interfaces.iter().filter(|i| i.is_contact()).collect();
        assert_eq!(contact.len(), 4);
        assert_eq!((contact[0].a, contact[0].b, contact[0].n_pairs()), (0, 2, 8));
    }

    /// The small three-layer scene's interfaces, in model order: 0 bottom.1|bottom.2 (5 pairs),
    /// 1 bottom.1|core.1 (8), 2 bottom.2|core.2 (9), 3 core.1|core.2 (5), 4 core.1|top.1 (9),
    /// 5 core.2|top.2 (9), 6 top.1|top.2 (5).
    fn three_layers(deployment: &str) -> Result<LoadedScene, SceneError> {
        let text = include_str!("../../../launch/scenes/small-three-layer.toml");
        assert!(text.contains("[deployment]\nsubdomain_nodes = 2\n"));
        let text = text.replace("[deployment]\n", &format!("[deployment]\n{deployment}\n"));
        load(&text)
    }

    #[test]
    fn interface_nodes_own_balanced_or_assigned_groups() {
        let s = three_layers("").unwrap();
        let pairs: Vec<usize> = s.model.interfaces.iter().map(Interface::n_pairs).collect();
        assert_eq!(pairs, [5, 8, 9, 5, 8, 9, 5]);
        assert_eq!(s.deployment.interface_groups(&s.model), [vec![0, 1, 2, 3, 4, 5, 6]]);
        // 49 pairs over 3 nodes: cuts nearest to 16.3 and 32.7 pairs (13 and 35).
        let s = three_layers("interface_nodes = 3").unwrap();
        assert_eq!(s.deployment.interface_groups, None);
        assert_eq!(
            s.deployment.interface_groups(&s.model),
            [vec![0, 1], vec![2, 3, 4], vec![5, 6]]
        );
        assert_eq!(
            balanced_interface_groups(&s.model, 7),
            (0..7).map(|i| vec![i]).collect::<Vec<_>>()
        );
        let s = three_layers(
            "interface_groups = [[\"bottom|core\", \"bottom|bottom\"], [\"top|core\", \"core.1|core.2\", 6]]",
        )
        .unwrap();
        assert_eq!(s.deployment.interface_nodes, 2);
        assert_eq!(
            s.deployment.interface_groups(&s.model),
            [vec![0, 1, 2], vec![3, 4, 5, 6]]
        );
    }

    #[test]
    fn rejects_bad_interface_deployments() {
        let key = "deployment.interface_groups";
        let e = three_layers("interface_nodes = 8").unwrap_err();
        assert_eq!(
            e.to_string(),
            "scenes/test.toml: deployment.interface_nodes: 8 nodes for 7 interface(s): some nodes would own nothing"
        );
        let bad = [
            ("interface_nodes = 0", "deployment.interface_nodes", "must be ≥ 1"),
            (
                "interface_nodes = 3\ninterface_groups = [[0, 1, 2], [3, 4, 5, 6]]",
                key,
                "2 group(s) for interface_nodes = 3",
            ),
            (
                "interface_groups = [[0, 1, 2, 3, 4, 5, 6], []]",
                "deployment.interface_groups[1]",
                "is empty",
            ),
            (
                "interface_groups = [[0, 1, 2, 3, 4, 5, 7]]",
                "deployment.interface_groups[0][6]",
                "interface 7 does not exist (the scene has 7, indices 0 to 6)",
            ),
            (
                "interface_groups = [[0, 1, 2], [3, 4, 5, 6, \"bottom\"]]",
                "deployment.interface_groups[1][4]",
                "`bottom`: name an interface as \"A|B\"",
            ),
            (
                "interface_groups = [[0, 1, 2], [3, \"core|tops\"]]",
                "deployment.interface_groups[1][1]",
                "unknown block or subdomain `tops`",
            ),
            (
                "interface_groups = [[0, 1, 2], [3, \"bottom|top\"]]",
                "deployment.interface_groups[1][1]",
                "`bottom|top` matches no interface",
            ),
            (
                "interface_groups = [[0, \"bottom|core\"], [2, 3, 4, 5, 6]]",
                "deployment.interface_groups[1][0]",
                "interface 2 (bottom.2|core.2) is already in group 0",
            ),
            (
                "interface_groups = [[0, 1, 2], [3, 6]]",
                key,
                "interface(s) 4 (core.1|top.1), 5 (core.2|top.2) are in no group",
            ),
        ];
        for (deployment, k, part) in bad {
            let e = three_layers(deployment).expect_err(deployment);
            assert_eq!(e.key, k, "{deployment}: {e}");
            assert!(e.problem.contains(part), "{deployment}: `{part}` not in {e}");
        }
    }

    #[test]
    fn split_names_interfaces_and_outer_sides() {
        let text = replaced("ny = 8\n[[block]]", "ny = 8\nsplit = [2, 2]\n[[block]]");
        let m = load(&text).unwrap().model;
        let names: Vec<&str> = m.subdomains.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["lower.1", "lower.2", "lower.3", "lower.4", "upper"]);
        // lower: 2 vertical + 2 horizontal perfect ones, 2 contact ones with upper.
        assert_eq!(m.interfaces.len(), 6);
        let vertical = m.interfaces.iter().filter(|i| i.normal == [1.0, 0.0]).count();
        assert_eq!(vertical, 2);
        let contact: Vec<_> = m.interfaces.iter().filter(|i| i.is_contact()).collect();
        assert_eq!(contact.len(), 2);
        assert_eq!((contact[0].a, contact[0].b, contact[0].n_pairs()), (2, 4, 17));
        // The vertical interface lower.1|lower.2 loses its pair at y = 0 (clamped both sides).
        let v = m.interfaces.iter().find(|i| (i.a, i.b) == (0, 1)).unwrap();
        assert_eq!(v.n_pairs(), 8);
        // y = 0 selects only the outer bottom sides.
        assert_eq!(m.subdomains[2].loads.len(), 0);
        assert_eq!(m.subdomains[0].loads.len(), 2);
    }

    #[test]
    fn later_rule_overrides_prescribed_dofs() {
        let text = format!("{TWO_BLOCKS}[[boundary]]\nblocks = [\"upper\"]\nside = \"right\"\nux = 0.5\n");
        let m = load(&text).unwrap().model;
        let upper = &m.subdomains[1];
        assert_eq!(upper.loads.len(), 3);
        let corner = upper.mesh.side_nodes(BlockSide::Right).last().copied().unwrap();
        assert_eq!(upper.loads[0].displacement[2 * corner], 0.0);
        assert_eq!(upper.loads[2].displacement[2 * corner], 1.0);
        assert_eq!(upper.loads[1].displacement[2 * corner + 1], 1.0);
        // A rule whose pattern is entirely overridden disappears.
        let text = format!("{TWO_BLOCKS}[[boundary]]\ny = 40.0\nuy = 0.5\n");
        let m = load(&text).unwrap().model;
        assert_eq!(m.subdomains[1].loads.len(), 2);
        assert_eq!(m.subdomains[1].loads[1].time, TimeFunction::Constant(0.5));
    }

    #[test]
    fn pressure_pushes_against_the_outward_normal() {
        let text = format!("{TWO_BLOCKS}[[boundary]]\nblocks = [\"upper\"]\nside = \"left\"\np = 2\n");
        let m = load(&text).unwrap().model;
        let case = m.subdomains[1].loads.last().unwrap();
        let fx: f64 = case.force.iter().step_by(2).sum();
        let fy: f64 = case.force.iter().skip(1).step_by(2).sum();
        assert!((fx - 20.0).abs() < 1e-12 && fy.abs() < 1e-12);
        assert_eq!(case.time, TimeFunction::Constant(2.0));
    }

    #[test]
    fn gap_forms() {
        let with_gap = |g: &str| replaced("friction = 0.2", &format!("friction = 0.2\ngap = {g}"));
        let gap_of = |text: &str| match &load(text).unwrap().model.interfaces[0].kind {
            InterfaceKind::Contact { gap, .. } => gap.clone(),
            InterfaceKind::Perfect => panic!(),
        };
        let g = gap_of(&with_gap("\"x/100 + y/1000\""));
        assert!((g[32] - 0.42).abs() < 1e-15);
        let g = gap_of(&with_gap("{ x = [0, 40], g = [0.0, 0.4] }"));
        assert!((g[16] - 0.2).abs() < 1e-15);
        let g = gap_of(&with_gap("0.1"));
        assert!(g.iter().all(|&v| v == 0.1));
        expect_err(
            &with_gap("{ x = [0, 40], v = [0.0, 0.4] }"),
            "interface[0].gap",
            "unknown key `v`",
        );
        expect_err(&with_gap("\"t\""), "interface[0].gap", "unknown name `t`");
    }

    #[test]
    fn defaults_and_settings() {
        let text = format!(
            "{}[solver]\nrelaxation = 1\ncontact_tolerance = 1e-3\n[solver.pgd]\nenabled = true\ncriterion = \
             \"increment-svd\"\n[deployment]\nsubdomain_nodes = 2\n[recording]\nenabled = false\nfull_fields_every = 10\n",
            TWO_BLOCKS.replacen("name = \"two\"\n", "plane = \"stress\"\n", 1)
        );
        let s = load(&text).unwrap();
        assert_eq!(s.model.name, "test");
        assert_eq!(s.model.plane, Plane::Stress);
        assert_eq!(s.model.solver.relaxation, 1.0);
        assert_eq!(s.model.solver.contact_tolerance, Some(1e-3));
        assert!(s.pgd.enabled && s.pgd.criterion == PgdCriterion::IncrementSvd);
        assert_eq!(s.deployment.subdomain_nodes, 2);
        assert!(!s.recording.enabled && s.recording.full_fields_every == 10);
    }

    #[test]
    fn module_doc_example_loads() {
        let example: String = include_str!("scene.rs")
            .lines()
            .skip_while(|l| *l != "//! ```toml")
            .skip(1)
            .take_while(|l| *l != "//! ```")
            .map(|l| format!("{}\n", l.strip_prefix("//!").unwrap_or(l).trim_start_matches(' ')))
            .collect();
        assert!(example.contains("[[interface]]"));
        let s = load_str(&example, "doc.toml").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.model.name, "two-blocks");
        assert_eq!(s.model.solver.contact_tolerance, Some(1e-4));
    }

    #[test]
    fn fingerprint_is_fnv1a_64() {
        assert_eq!(fingerprint(""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fingerprint("a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fingerprint("foobar"), 0x8594_4171_f739_67e8);
        assert_ne!(fingerprint("foobar"), fingerprint("foobas"));
        assert_ne!(
            fingerprint(TWO_BLOCKS),
            fingerprint(&TWO_BLOCKS.replacen("0.3", "0.2", 1))
        );
    }

    // --- validation errors, one per rule ---

    #[test]
    fn rejects_nu_out_of_range() {
        expect_err(
            &replaced("nu = 0.3", "nu = 0.5"),
            "materials.steel.nu",
            "outside (−1, 0.5)",
        );
        expect_err(
            &replaced("nu = 0.3", "nu = -1.0"),
            "materials.steel.nu",
            "outside (−1, 0.5)",
        );
    }

    #[test]
    fn rejects_non_positive_e() {
        expect_err(&replaced("E = 210000.0", "E = 0"), "materials.steel.E", "must be > 0");
    }

    #[test]
    fn rejects_negative_friction() {
        expect_err(
            &replaced("friction = 0.2", "friction = -0.1"),
            "interface[0].friction",
            "must be ≥ 0",
        );
    }

    #[test]
    fn rejects_friction_on_perfect_and_contact_without_friction() {
        expect_err(
            &replaced("kind = \"contact\"", "kind = \"perfect\""),
            "interface[0].friction",
            "contact interfaces only",
        );
        expect_err(
            &replaced("friction = 0.2\n", ""),
            "interface[0].friction",
            "needs `friction`",
        );
    }

    #[test]
    fn rejects_zero_steps_and_non_positive_duration() {
        expect_err(&replaced("N = 4", "N = 0"), "time.N", "N ≥ 1");
        expect_err(&replaced("T = 1.0", "T = 0.0"), "time.T", "> 0");
        expect_err(&replaced("T = 1.0", "T = -2"), "time.T", "> 0");
    }

    #[test]
    fn rejects_bad_element_counts_and_split() {
        expect_err(
            &TWO_BLOCKS
                .replacen("nx = 16", "nx = 0", 2)
                .replacen("nx = 0", "nx = 16", 1),
            "block[1].nx",
            "nx = 0",
        );
        expect_err(&replaced("ny = 8", "ny = 0"), "block[0].ny", "ny = 0");
        expect_err(
            &replaced("ny = 8\n", "ny = 8\nsplit = [3, 1]\n"),
            "block[0].split",
            "must divide",
        );
        expect_err(
            &replaced("ny = 8\n", "ny = 8\nsplit = [0, 1]\n"),
            "block[0].split",
            "must divide",
        );
    }

    #[test]
    fn rejects_empty_extent() {
        expect_err(
            &replaced("x = [0.0, 40.0]", "x = [40.0, 40.0]"),
            "block[0].x",
            "x0 < x1",
        );
        expect_err(&replaced("y = [0.0, 20.0]", "y = [20.0, 0.0]"), "block[0].y", "y0 < y1");
    }

    #[test]
    fn rejects_unknown_material() {
        expect_err(
            &replaced("material = \"steel\"", "material = \"stel\""),
            "block[0].material",
            "unknown material `stel`",
        );
    }

    #[test]
    fn rejects_unknown_names() {
        expect_err(
            &replaced("between = [\"lower\", \"upper\"]", "between = [\"lower\", \"uper\"]"),
            "interface[0].between",
            "unknown block or subdomain `uper`",
        );
        expect_err(
            &replaced("y = 0.0\nux", "blocks = [\"lower.1\"]\ny = 0.0\nux"),
            "boundary[0].blocks",
            "unknown block or subdomain `lower.1`",
        );
    }

    #[test]
    fn rejects_rule_matching_no_interface() {
        let text = replaced("y = [20.0, 40.0]", "y = [20.5, 40.0]").replacen("y = 40.0", "y = 40", 1);
        expect_err(&text, "interface[0].between", "share no edge");
    }

    #[test]
    fn rejects_non_conforming_interface() {
        let e = expect_err(
            &TWO_BLOCKS
                .replacen("nx = 16", "nx = 10", 2)
                .replacen("nx = 10", "nx = 16", 1),
            "block[1]",
            "do not conform",
        );
        assert!(e.problem.contains("`lower`") && e.problem.contains("`upper`"), "{e}");
        assert!(e.problem.contains("y = 20") && e.problem.contains("x = 1.25"), "{e}");
        // Shifted by half an element: nodes coincide but corners face mid-side nodes.
        let shifted = replaced("x = [0.0, 40.0]\ny = [20.0", "x = [1.25, 41.25]\ny = [20.0");
        expect_err(&shifted, "block[1]", "corner node faces a mid-side node");
    }

    #[test]
    fn rejects_overlapping_blocks() {
        let e = expect_err(
            &replaced("y = [20.0, 40.0]", "y = [19.0, 40.0]"),
            "block[1]",
            "overlaps",
        );
        assert!(e.problem.contains("`upper`") && e.problem.contains("`lower`"), "{e}");
    }

    #[test]
    fn rejects_bad_formula() {
        expect_err(
            &replaced("\"0.004*sin(2*pi*t)\"", "\"0.004*sin(2*pi*s)\""),
            "boundary[1].ux",
            "unknown name `s`",
        );
        expect_err(
            &replaced("\"0.004*sin(2*pi*t)\"", "\"ln(t)\""),
            "boundary[1].ux",
            "not finite",
        );
    }

    #[test]
    fn rejects_bad_tables() {
        let with = |t: &str| replaced("uy = -0.01", &format!("uy = {t}"));
        expect_err(
            &with("{ t = [0.0, 1.0], v = [0.0] }"),
            "boundary[1].uy",
            "2 entries but `v` has 1",
        );
        expect_err(
            &with("{ t = [0.0, 0.0], v = [0.0, 1.0] }"),
            "boundary[1].uy",
            "not strictly increasing",
        );
        expect_err(&with("{ t = [], v = [] }"), "boundary[1].uy", "is empty");
        expect_err(
            &with("{ t = [0.0, \"a\"], v = [0.0, 1.0] }"),
            "boundary[1].uy",
            "not a finite number",
        );
        expect_err(&with("{ v = [0.0] }"), "boundary[1].uy", "exactly one abscissa");
        expect_err(&with("[1.0]"), "boundary[1].uy", "found array");
    }

    #[test]
    fn rejects_bad_solver_settings() {
        let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
        expect_err(&with("relaxation = 0.0"), "solver.relaxation", "outside (0, 1]");
        expect_err(&with("relaxation = 1.5"), "solver.relaxation", "outside (0, 1]");
        expect_err(&with("tolerance = 0.0"), "solver.tolerance", "must be > 0");
        expect_err(&with("tolerance = -1e-6"), "solver.tolerance", "must be > 0");
        expect_err(&with("k0_factor = 0"), "solver.k0_factor", "must be > 0");
        expect_err(&with("alpha = 1.0"), "solver.alpha", "outside [0, 1)");
        // 2(1 − 0.8)/(2 − 0.8) = 1/3: 0.34 is above, and accepted only with the update off.
        expect_err(
            &with("search_direction_update = true\nalpha = 0.34"),
            "solver.alpha",
            "above 0.3333 = 2(1 − μ)/(2 − μ) for relaxation μ = 0.8",
        );
        assert!(load(&with("alpha = 0.34")).is_ok());
        assert!(load(&with("search_direction_update = true\nalpha = 0.3333")).is_ok());
        expect_err(
            &format!("{TWO_BLOCKS}[deployment]\nsubdomain_nodes = 3\n"),
            "deployment.subdomain_nodes",
            "3 nodes",
        );
        expect_err(
            &format!("{TWO_BLOCKS}[recording]\nfull_fields_every = 0\n"),
            "recording.full_fields_every",
            "≥ 1",
        );
    }

    #[test]
    fn rejects_free_rigid_modes() {
        // Only ux on y = 0, nothing on top: y-translation and rotation are free.
        let text = replaced("ux = 0.0\nuy = 0.0", "ux = 0.0");
        let text = text.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
        let e = expect_err(&text, "boundary", "y-translation and rotation free");
        assert!(e.problem.contains("[lower, upper]"), "{e}");
        // ux = 0 along y = 0 and uy = 0 along x = 0 leave the rotation about the origin free.
        let text = replaced(
            "ux = 0.0\nuy = 0.0",
            "ux = 0.0\n[[boundary]]\nblocks = [\"lower\"]\nx = 0.0\nuy = 0.0",
        );
        let text = text.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
        let e = expect_err(&text, "boundary", "rotation free");
        assert!(!e.problem.contains("translation"), "{e}");
        // A second, unconnected block with no support.
        let text = format!(
            "{TWO_BLOCKS}[[block]]\nname = \"loose\"\nmaterial = \"steel\"\nx = [50.0, 60.0]\ny = [5.0, 15.0]\nnx = 2\nny = 2\n"
        );
        let e = expect_err(&text, "boundary", "x-translation, y-translation and rotation free");
        assert!(e.problem.contains("[loose]"), "{e}");
    }

    #[test]
    fn rejects_duplicate_names() {
        expect_err(
            &replaced("name = \"upper\"", "name = \"lower\""),
            "block[1].name",
            "duplicate block name `lower`",
        );
        let text = replaced("ny = 8\n[[block]]", "ny = 8\nsplit = [2, 1]\n[[block]]").replacen(
            "name = \"upper\"",
            "name = \"lower.2\"",
            1,
        );
        expect_err(
            &text.replace("\"upper\"", "\"lower.2\""),
            "block[0].name",
            "`lower.2` generated from block `lower`",
        );
    }

    #[test]
    fn rejects_bad_boundary_rules() {
        expect_err(
            &replaced("uy = -0.01", "uy = -0.01\nty = 1.0"),
            "boundary[1]",
            "not both",
        );
        expect_err(
            &replaced("ux = 0.0\nuy = 0.0\n", ""),
            "boundary[0]",
            "prescribes nothing",
        );
        expect_err(
            &replaced("y = 0.0\n", "y = 5.0\n"),
            "boundary[0]",
            "no outer side matches y = 5",
        );
        expect_err(&replaced("y = 0.0\n", ""), "boundary[0]", "give `side`, `x` or `y`");
    }

    #[test]
    fn toml_errors_name_key_and_position() {
        let e = expect_err(&replaced("N = 4", "N = 4\nsteps = 3"), "time.steps", "line 6, column 1");
        assert!(e.problem.contains("unknown field `steps`"), "{e}");
        let e = expect_err(
            &TWO_BLOCKS
                .replacen("ny = 8", "ny = \"8\"", 2)
                .replacen("ny = \"8\"", "ny = 8", 1),
            "block[1].ny",
            "line 22",
        );
        assert!(e.problem.contains("column"), "{e}");
        let e = load(&replaced("[time]", "[time\n")).unwrap_err();
        assert_eq!(e.key, "(syntax)", "{e}");
        assert!(e.problem.contains("line 3"), "{e}");
        expect_err(
            &replaced("kind = \"contact\"", "kind = \"glue\""),
            "interface[0].kind",
            "glue",
        );
        expect_err(&replaced("T = 1.0\n", ""), "time.T", "missing field");
        expect_err(
            &replaced("[[boundary]]\ny = 0.0", "[[boundary]]\nside = \"middle\""),
            "boundary[0].side",
            "middle",
        );
    }

    #[test]
    fn linear_stage_keys() {
        let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
        let stage = |s: &str| load(&with(s)).unwrap().linear_stage;
        assert_eq!(load(TWO_BLOCKS).unwrap().linear_stage, LinearStage::Condensed);
        assert_eq!(stage("linear_stage = \"sparse\""), LinearStage::Sparse);
        assert_eq!(stage("linear_stage = \"auto\""), LinearStage::Auto);
        assert_eq!(stage("[solver.pgd]\nenabled = true"), LinearStage::Pgd);
        let s = load(&with(
            "linear_stage = \"pgd\"\n[solver.pgd]\nmacro_modes = true\nmax_new_modes = 3",
        ))
        .unwrap();
        assert_eq!(s.linear_stage, LinearStage::Pgd);
        assert!(s.pgd.macro_modes && s.pgd.max_new_modes == 3);
        expect_err(
            &with("linear_stage = \"sparse\"\n[solver.pgd]\nenabled = true"),
            "solver.pgd.enabled",
            "true contradicts solver.linear_stage = Sparse",
        );
        expect_err(
            &with("[solver.pgd]\nmax_new_modes = 0"),
            "solver.pgd.max_new_modes",
            "must be ≥ 1",
        );
        assert!(load(&with("linear_stage = \"dense\"")).is_err());
    }

    #[test]
    fn time_coarsening_keys() {
        let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
        let n = load(TWO_BLOCKS).unwrap().model.time.n_steps;
        assert_eq!(load(TWO_BLOCKS).unwrap().model.solver.time_start, None);
        assert_eq!(
            load(&with("time_coarsening = 2")).unwrap().model.solver.time_start,
            Some(TimeStart {
                coarsening: 2,
                tolerance: DEFAULT_TIME_START_TOLERANCE
            })
        );
        assert_eq!(
            load(&with(&format!(
                "time_coarsening = {n}\ntime_coarsening_tolerance = 1e-6"
            )))
            .unwrap()
            .model
            .solver
            .time_start,
            Some(TimeStart {
                coarsening: n,
                tolerance: 1e-6
            })
        );
        expect_err(&with("time_coarsening = 1"), "solver.time_coarsening", "must be ≥ 2");
        expect_err(
            &with(&format!("time_coarsening = {}", n + 1)),
            "solver.time_coarsening",
            &format!("does not divide time.N = {n}"),
        );
        expect_err(
            &with("time_coarsening_tolerance = 1e-5"),
            "solver.time_coarsening_tolerance",
            "solver.time_coarsening is not",
        );
        expect_err(
            &with("time_coarsening = 2\ntime_coarsening_tolerance = 0.0"),
            "solver.time_coarsening_tolerance",
            "must be > 0",
        );
        expect_err(
            &with("time_coarsening = 2\nlinear_stage = \"pgd\""),
            "solver.time_coarsening",
            "not available with the PGD linear stage",
        );
        assert!(load(&with("time_coarsening = -2")).is_err());
    }

    #[test]
    fn acceleration_keys() {
        let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
        let a = |s: &str| load(&with(s)).unwrap().model.solver.acceleration;
        assert_eq!(a("acceleration = \"none\""), Acceleration::None);
        // Anderson with the default window unless the scene says otherwise.
        assert_eq!(
            a("tolerance = 1e-6"),
            Acceleration::Anderson {
                window: DEFAULT_ANDERSON_WINDOW
            }
        );
        assert_eq!(a("anderson_window = 3"), Acceleration::Anderson { window: 3 });
        assert_eq!(
            a("acceleration = \"anderson\""),
            Acceleration::Anderson {
                window: DEFAULT_ANDERSON_WINDOW
            }
        );
        assert_eq!(
            a("acceleration = \"anderson\"\nanderson_window = 8"),
            Acceleration::Anderson { window: 8 }
        );
        expect_err(
            &with("acceleration = \"anderson\"\nanderson_window = 0"),
            "solver.anderson_window",
            "0 is outside 1..=50",
        );
        expect_err(
            &with("acceleration = \"anderson\"\nanderson_window = 51"),
            "solver.anderson_window",
            "51 is outside 1..=50",
        );
        expect_err(
            &with("acceleration = \"none\"\nanderson_window = 4"),
            "solver.anderson_window",
            "4 is set but solver.acceleration is \"none\"",
        );
        let e = load(&with("acceleration = \"broyden\"")).unwrap_err();
        assert!(
            e.to_string().contains("broyden") && e.to_string().contains("anderson"),
            "{e}"
        );
    }

    /// `[network]`: TLS files as written, mutual TLS, access control; each inconsistency is
    /// named by its key.
    #[test]
    fn network_section() {
        let net = |lines: &str| format!("{TWO_BLOCKS}\n[network]\n{lines}\n");
        let tls = r#"tls = { root_ca = "tls/ca.pem", cert = "tls/node.pem", key = "tls/node.key" }"#;
        let mutual = r#"tls = { root_ca = "tls/ca.pem", cert = "tls/node.pem", key = "tls/node.key", mutual = true }"#;
        assert_eq!(load(TWO_BLOCKS).unwrap().network, Network::default());
        let s = load(&net(&format!("{mutual}\nallow = [\"node-a\", \"node-b\"]"))).unwrap();
        assert_eq!(
            s.network,
            Network {
                tls: Some(TlsFiles {
                    root_ca: "tls/ca.pem".into(),
                    cert: "tls/node.pem".into(),
                    key: "tls/node.key".into(),
                    mutual: true,
                }),
                allow: Some(vec!["node-a".into(), "node-b".into()]),
                shared_memory: None,
            }
        );
        assert!(!load(&net(tls)).unwrap().network.tls.unwrap().mutual);
        assert_eq!(
            load(&net("shared_memory = true")).unwrap().network.shared_memory,
            Some(true)
        );
        assert_eq!(
            load(&net("shared_memory = false")).unwrap().network.shared_memory,
            Some(false)
        );
        let e = load(&net("shared_memory = \"yes\"")).unwrap_err().to_string();
        assert!(e.contains("shared_memory"), "{e}");
        expect_err(&net("allow = [\"node-a\"]"), "network.allow", "it needs network.tls");
        expect_err(
            &net(&format!("{tls}\nallow = [\"node-a\"]")),
            "network.allow",
            "needs network.tls.mutual = true",
        );
        expect_err(&net(&format!("{mutual}\nallow = []")), "network.allow", "an empty list");
        expect_err(
            &net(&format!("{mutual}\nallow = [\"a\", \"a\"]")),
            "network.allow[1]",
            "`a` is listed twice",
        );
        expect_err(
            &net(&format!("{mutual}\nallow = [\" \"]")),
            "network.allow[0]",
            "not empty",
        );
        expect_err(
            &net(r#"tls = { root_ca = "tls/ca.pem", cert = "", key = "k.pem" }"#),
            "network.tls.cert",
            "must name a PEM file",
        );
        expect_err(
            &net(r#"tls = { root_ca = "tls/ca.pem", cert = "tls/node.pem" }"#),
            "network.tls.key",
            "missing field `key`",
        );
        expect_err(&net("encrypt = true"), "network.encrypt", "unknown field `encrypt`");
    }

    /// TLS paths are relative to the scene file's folder and must be readable PEM files.
    #[test]
    fn network_files_resolve_and_are_checked() {
        let dir = std::env::temp_dir().join(format!("glissade-scene-tls-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("tls")).unwrap();
        let pem = "-----BEGIN CERTIFICATE-----\nMA==\n-----END CERTIFICATE-----\n";
        for f in ["ca.pem", "node.pem", "node.key"] {
            std::fs::write(dir.join("tls").join(f), pem).unwrap();
        }
        std::fs::write(dir.join("tls/plain.txt"), "not a certificate").unwrap();
        let scene_file = dir.join("scene.toml");
        let network = |cert: &str| Network {
            tls: Some(TlsFiles {
                root_ca: "tls/ca.pem".into(),
                cert: cert.into(),
                key: "tls/node.key".into(),
                mutual: false,
            }),
            allow: None,
            shared_memory: None,
        };
        let mut ok = network("tls/node.pem");
        ok.resolve_files(&scene_file).unwrap();
        let t = ok.tls.unwrap();
        assert_eq!(t.root_ca, dir.join("tls/ca.pem"));
        assert_eq!(t.cert, dir.join("tls/node.pem"));
        assert_eq!(t.key, dir.join("tls/node.key"));
        let absolute = dir.join("tls/node.pem");
        let mut abs = network(absolute.to_str().unwrap());
        abs.resolve_files(&scene_file).unwrap();
        assert_eq!(abs.tls.unwrap().cert, absolute);
        let e = network("tls/missing.pem").resolve_files(&scene_file).unwrap_err();
        assert_eq!(e.key, "network.tls.cert");
        assert_eq!(e.file, scene_file.display().to_string());
        assert!(
            e.problem
                .starts_with(&format!("cannot read {}: ", dir.join("tls/missing.pem").display())),
            "{e}"
        );
        let e = network("tls/plain.txt").resolve_files(&scene_file).unwrap_err();
        assert_eq!(e.key, "network.tls.cert");
        assert!(
            e.problem.ends_with("plain.txt is not a PEM file (no -----BEGIN line)"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
