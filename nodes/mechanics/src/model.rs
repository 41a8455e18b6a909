//! The kernel's description of a problem: meshes, materials, loads, interfaces and the time
//! grid, already validated. Built from a scene file by the `glissade-scene` crate; everything downstream
//! (condensed operators, LATIN laws, monolithic solves) reads only this.

use crate::expr::Expr;
use crate::mesh::Mesh;
use crate::mortar::Projection;

/// Plane strain or plane stress (unit thickness), or axisymmetric: x is the radius r ≥ 0, y the
/// axis z, and every integral carries 2πr (forces are totals over the circumference).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Plane {
    Strain,
    Stress,
    Axisymmetric,
}

impl Plane {
    /// The measure of the third direction at point `p`: 1 mm of thickness in plane strain and
    /// stress, the circumference 2πr in axisymmetry (r = p[0]). Every area and edge integral is
    /// taken against it.
    pub fn measure(self, p: [f64; 2]) -> f64 {
        match self {
            Plane::Strain | Plane::Stress => 1.0,
            Plane::Axisymmetric => std::f64::consts::TAU * p[0],
        }
    }

    /// The unit of a force summed over nodes: per mm of thickness in plane strain and stress, a
    /// total over the circumference in axisymmetry.
    pub fn force_unit(self) -> &'static str {
        match self {
            Plane::Strain | Plane::Stress => "N/mm",
            Plane::Axisymmetric => "N",
        }
    }

    /// [`Self::force_unit`] as it ends a CSV column's name.
    pub fn force_column_unit(self) -> &'static str {
        match self {
            Plane::Strain | Plane::Stress => "N_per_mm",
            Plane::Axisymmetric => "N",
        }
    }
}

/// Isotropic linear elastic material. `e` in MPa.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Material {
    pub e: f64,
    pub nu: f64,
}

impl Material {
    /// The stiffness the default search direction is scaled by: √(2G·M), the geometric mean of
    /// the shear modulus 2G and the P-wave modulus M (M = E(1 − ν)/((1 + ν)(1 − 2ν)) in plane
    /// strain and axisymmetry, E/(1 − ν²) in plane stress). It equals E at ν = 0 and stays within 4 % of E for
    /// 0 ≤ ν ≤ 0.3, but follows the normal stiffness as ν → 0.5 in plane strain, where E alone
    /// underestimates it (M = 167 E at ν = 0.499).
    pub fn interface_modulus(&self, plane: Plane) -> f64 {
        let (e, nu) = (self.e, self.nu);
        let two_g = e / (1.0 + nu);
        let m = match plane {
            Plane::Strain | Plane::Axisymmetric => e * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            Plane::Stress => e / (1.0 - nu * nu),
        };
        (two_g * m).sqrt()
    }
}

/// Time grid t_i = i·T/N, i = 0..N (t_0 is solved too).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimeGrid {
    pub t_end: f64,
    pub n_steps: usize,
}

impl TimeGrid {
    /// Number of time points, N + 1.
    pub fn n_points(&self) -> usize {
        self.n_steps + 1
    }

    /// t_i = i·T/N.
    pub fn t(&self, i: usize) -> f64 {
        self.t_end * i as f64 / self.n_steps as f64
    }

    /// Trapezoid weights w_i of ∫₀ᵀ (dt/2 at both ends, dt inside).
    pub fn trapezoid_weights(&self) -> Vec<f64> {
        let dt = self.t_end / self.n_steps as f64;
        (0..self.n_points())
            .map(|i| if i == 0 || i == self.n_steps { 0.5 * dt } else { dt })
            .collect()
    }
}

/// A scalar function of time φ(t).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum TimeFunction {
    Constant(f64),
    /// A formula in `t` (see [`crate::expr`]).
    Formula(Expr),
    /// Piecewise-linear interpolation of (t, v) samples, constant beyond the ends.
    Table {
        t: Vec<f64>,
        v: Vec<f64>,
    },
}

impl TimeFunction {
    /// φ(t).
    pub fn eval(&self, t: f64) -> f64 {
        match self {
            TimeFunction::Constant(c) => *c,
            TimeFunction::Formula(e) => e.eval(&[t]),
            TimeFunction::Table { t: ts, v } => interpolate(ts, v, t),
        }
    }
}

/// Piecewise-linear interpolation in a table with increasing abscissae, constant beyond the ends.
pub fn interpolate(xs: &[f64], vs: &[f64], x: f64) -> f64 {
    if x <= xs[0] {
        return vs[0];
    }
    let last = xs.len() - 1;
    if x >= xs[last] {
        return vs[last];
    }
    let k = xs.partition_point(|&xi| xi <= x).clamp(1, last);
    let (x0, x1) = (xs[k - 1], xs[k]);
    let s = (x - x0) / (x1 - x0);
    vs[k - 1] * (1.0 - s) + vs[k] * s
}

/// A load case of one subdomain: a spatial pattern times a time function. The pattern is a
/// nodal force vector (consistent edge loads, N) and/or prescribed values at constrained dofs
/// (mm); both are full-length dof vectors of the subdomain.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LoadCase {
    pub force: Vec<f64>,
    pub displacement: Vec<f64>,
    pub time: TimeFunction,
}

/// One elastic part of the decomposition.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Subdomain {
    pub name: String,
    pub mesh: Mesh,
    pub material: Material,
    /// `constrained[dof]`: the dof's displacement is prescribed (imposed strongly).
    pub constrained: Vec<bool>,
    pub loads: Vec<LoadCase>,
}

impl Subdomain {
    pub fn n_dofs(&self) -> usize {
        2 * self.mesh.coords.len()
    }
}

/// What an interface between two subdomains does.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum InterfaceKind {
    /// Displacement continuity and action–reaction.
    Perfect,
    /// Unilateral contact with Coulomb friction `friction` ≥ 0; `gap[p]` is the initial normal
    /// gap g0 (mm) at pair p.
    Contact { friction: f64, gap: Vec<f64> },
}

/// An interface Γ between subdomains `a` and `b`, conforming (node pairs coincide) or
/// non-matching (`projection`: side b's trace is projected onto side a's nodes). Each pair has
/// its own frame (docs/method.md, "Pair frames and weights"): the normal `normals[p]` points out of `a` towards `b`, the tangent
/// is (−n_y, n_x); on a straight interface every pair has the same normal.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Interface {
    pub kind: InterfaceKind,
    pub a: usize,
    pub b: usize,
    /// (node of a, node of b) per pair, ordered along the interface. On a non-matching interface
    /// the node of b is the one with the largest coefficient in the pair's projection (a node
    /// under the pair's edges, not necessarily the nearest): side b's trace is
    /// [`Interface::trace`].
    pub pairs: Vec<(usize, usize)>,
    /// Coordinates of each pair (mm).
    pub coords: Vec<[f64; 2]>,
    /// Lumped edge mass per pair (mm): row sums of the 3-node edge mass L/6, 4L/6, L/6.
    pub weights: Vec<f64>,
    /// Unit normal of each pair, out of `a`: the normalised sum of side a's outward normals at
    /// the node on the isoparametric edges it belongs to.
    pub normals: Vec<[f64; 2]>,
    /// Length L_Γ (mm).
    pub length: f64,
    /// Centroid of the pairs weighted by `weights` (mm).
    pub centroid: [f64; 2],
    /// Non-matching: side b's trace at each pair ([`crate::mortar`]); None when conforming.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projection: Option<Projection>,
    /// Non-matching with an end left out ([`crate::mortar::project_with_ends`]): side a's trace
    /// at each pair (mesh nodes of a); None when it is the pair's node alone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projection_a: Option<Projection>,
}

impl Interface {
    pub fn n_pairs(&self) -> usize {
        self.pairs.len()
    }

    pub fn is_contact(&self) -> bool {
        matches!(self.kind, InterfaceKind::Contact { .. })
    }

    /// Unit normal at pair `p`, out of side a.
    pub fn normal(&self, p: usize) -> [f64; 2] {
        self.normals[p]
    }

    /// Unit tangent at pair `p`: (−n_y, n_x).
    pub fn tangent(&self, p: usize) -> [f64; 2] {
        let n = self.normals[p];
        [-n[1], n[0]]
    }

    /// The normal shared by every pair if the interface is straight (all pair normals equal to
    /// within 1e-9: normals computed from node coordinates carry their round-off over the element
    /// size), else `None`.
    pub fn straight_normal(&self) -> Option<[f64; 2]> {
        let n0 = *self.normals.first()?;
        self.normals
            .iter()
            .all(|n| (n[0] - n0[0]).abs() <= 1e-9 && (n[1] - n0[1]).abs() <= 1e-9)
            .then_some(n0)
    }

    /// A frame for the interface as a whole: the common normal of a straight interface, else
    /// the normalised weighted mean of the pair normals, or (0, 1) when they cancel (a closed
    /// ring). Returns (normal, tangent).
    pub fn mean_frame(&self) -> ([f64; 2], [f64; 2]) {
        let n = self.straight_normal().unwrap_or_else(|| {
            let mut m = [0.0; 2];
            for (w, n) in self.weights.iter().zip(&self.normals) {
                m[0] += w * n[0];
                m[1] += w * n[1];
            }
            let norm = (m[0] * m[0] + m[1] * m[1]).sqrt();
            let total: f64 = self.weights.iter().sum();
            if norm > 0.5 * total {
                [m[0] / norm, m[1] / norm]
            } else {
                [0.0, 1.0]
            }
        });
        (n, [-n[1], n[0]])
    }

    /// Which side of the interface subdomain `s` is (a or b), if any.
    pub fn side_of(&self, s: usize) -> Option<Side> {
        if s == self.a {
            Some(Side::A)
        } else if s == self.b {
            Some(Side::B)
        } else {
            None
        }
    }

    /// Node of side `side` at pair `p` (on a non-matching interface's side b, the node with the
    /// largest coefficient: use [`Interface::trace`] for the trace).
    pub fn node(&self, side: Side, p: usize) -> usize {
        match side {
            Side::A => self.pairs[p].0,
            Side::B => self.pairs[p].1,
        }
    }

    /// Whether side b reaches the pairs through a projection.
    pub fn is_non_matching(&self) -> bool {
        self.projection.is_some()
    }

    /// Side `side`'s trace at pair `p`: (node, coefficient) terms whose weighted sum of nodal
    /// displacements is the side's displacement there; one term (node, 1) on a conforming
    /// interface and on side a (but at the middle pair of a non-matching interface's end edge
    /// whose end was left out: the edge's mean).
    pub fn trace(&self, side: Side, p: usize) -> Vec<(usize, f64)> {
        match (side, &self.projection, &self.projection_a) {
            (Side::B, Some(pr), _) | (Side::A, _, Some(pr)) => pr.terms(p).collect(),
            _ => vec![(self.node(side, p), 1.0)],
        }
    }
}

/// Side of an interface: `A` is the subdomain the normal points out of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    A,
    B,
}

/// Solver parameters of a scene (docs/scenes.md, "[solver]"), already validated.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverParams {
    /// k₀ = k0_factor · E/L_Γ, E the interface modulus √(2G·M) of the two sides ([`crate::linear::default_k0`]).
    pub k0_factor: f64,
    /// Relaxation μ ∈ (0, 1].
    pub relaxation: f64,
    /// Stop when the estimated relative contact-traction error ([`crate::estimate`]) is at most
    /// this (default 1e-3); `None`: the run does not stop on the estimate.
    pub accuracy: Option<f64>,
    /// Also require η ≤ this (if set).
    pub tolerance: Option<f64>,
    /// Also require the contact indicator ≤ this (if set).
    pub contact_tolerance: Option<f64>,
    pub max_iterations: usize,
    /// Stop when η has not decreased by `stagnation_ratio` over `stagnation_window` iterations.
    pub stagnation_window: usize,
    pub stagnation_ratio: f64,
    /// Solve the macro (coarse) problem.
    pub coarse: bool,
    /// Search-direction update (docs/method.md, "Search-direction update"): off by default.
    pub search_direction_update: bool,
    /// Updated directions are k₀(1 − α) (separated: both components; slipping: tangential).
    /// With relaxation μ the relaxed iteration keeps every mode inside the unit disc only for
    /// α ≤ [`SolverParams::alpha_limit`] = 2(1 − μ)/(2 − μ) (1/3 at μ = 0.8: α = 1/3
    /// would sit exactly on the limit): the default is 0.2.
    pub alpha: f64,
    pub i0: f64,
    /// Acceleration of the fixed point (docs/method.md, "Relaxation and Anderson mixing").
    pub acceleration: Acceleration,
    /// Polynomial degree of the macro basis on every interface ([`crate::linear::macro_basis`]);
    /// `None` (the default) chooses per interface ([`crate::linear::macro_degree`]).
    pub macro_degree: Option<usize>,
    /// Start from a solve on a coarser time grid ([`TimeStart`]); None: from ŝ = 0.
    pub time_start: Option<TimeStart>,
    /// Start from ŝ given by the launcher (a study's warm start from a solved variant): iteration 0
    /// waits for its initial directions, as with a time-coarse start. Never set by a scene file.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub given_start: bool,
}

/// Time-coarse start: the scene is first solved on every `coarsening`-th time point (N/c steps,
/// same settings) until η ≤ `tolerance`, and the fine iteration starts from that solve's ŝ,
/// interpolated linearly in time, instead of ŝ = 0. The start changes the path, not the limit:
/// the fixed point of the fine iteration does not depend on where it starts.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimeStart {
    /// c ≥ 2, dividing N.
    pub coarsening: usize,
    /// η at which the coarse solve stops (> 0).
    pub tolerance: f64,
}

/// `solver.accuracy` when a scene does not set it: the estimated relative error of the contact
/// tractions at the stop.
pub const DEFAULT_ACCURACY: f64 = 1e-3;

/// `solver.time_coarsening_tolerance` when a scene sets `time_coarsening` only.
pub const DEFAULT_TIME_START_TOLERANCE: f64 = 1e-4;

impl SolverParams {
    /// Largest α the search-direction update is stable with under relaxation μ: a mode of the
    /// relaxed iteration sits near 1 − μ − μ/(1 − α), which is ≥ −1 iff α ≤ 2(1 − μ)/(2 − μ)
    /// (measured: μ = 0.6 converges at α = 0.55 and diverges at 0.6; the limit is 0.571).
    pub fn alpha_limit(&self) -> f64 {
        let mu = self.relaxation;
        2.0 * (1.0 - mu) / (2.0 - mu)
    }

    /// Whether iteration 0 starts from directions the launcher sends (a time-coarse start or a
    /// given start) instead of ŝ = 0.
    pub fn launcher_start(&self) -> bool {
        self.time_start.is_some() || self.given_start
    }
}

impl Default for SolverParams {
    fn default() -> Self {
        Self {
            k0_factor: 1.0,
            relaxation: 0.8,
            accuracy: Some(DEFAULT_ACCURACY),
            tolerance: None,
            contact_tolerance: None,
            max_iterations: 1000,
            stagnation_window: 50,
            stagnation_ratio: 0.99,
            coarse: true,
            search_direction_update: false,
            alpha: 0.2,
            i0: 0.1,
            acceleration: Acceleration::Anderson {
                window: DEFAULT_ANDERSON_WINDOW,
            },
            macro_degree: None,
            time_start: None,
            given_start: false,
        }
    }
}

/// Anderson window of the default acceleration, and of a scene that turns Anderson acceleration
/// on without `solver.anderson_window`.
pub const DEFAULT_ANDERSON_WINDOW: usize = 5;

/// How the LATIN fixed point s ← G(s) is iterated ([`crate::anderson`]). The default is Anderson
/// mixing over [`DEFAULT_ANDERSON_WINDOW`] iterates: it reaches the same limit in fewer iterations
/// on every scene of this project and every converging case of the stability matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Acceleration {
    /// Plain relaxation s ← μ G(s) + (1 − μ) s.
    None,
    /// Anderson mixing (type II, damping μ) over the last `window` iterates.
    Anderson { window: usize },
}

/// A validated problem.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Model {
    pub name: String,
    pub plane: Plane,
    pub time: TimeGrid,
    pub subdomains: Vec<Subdomain>,
    pub interfaces: Vec<Interface>,
    pub solver: SolverParams,
    /// The scene's boundary rules, in file order, with the dofs and load cases each made: what
    /// reaction forces and load resultants are reported by (empty for a model built otherwise).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub boundary_rules: Vec<BoundaryRule>,
    /// The point the boundary rules' moments are reported about (mm): the scene's
    /// `moment_about`, the origin by default.
    #[serde(default, skip_serializing_if = "is_origin")]
    pub moment_about: [f64; 2],
}

fn is_origin(p: &[f64; 2]) -> bool {
    *p == [0.0, 0.0]
}

/// One boundary rule of the scene as the outputs report it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BoundaryRule {
    /// `boundary[k]`, with its curve for a mesh scene: `boundary[0] (bore)`.
    pub name: String,
    /// Whether it prescribes displacements (else it applies tractions).
    pub prescribes_displacement: bool,
    /// Per subdomain it acts on, what it made there.
    pub parts: Vec<RulePart>,
}

/// What a boundary rule made in one subdomain.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RulePart {
    pub subdomain: usize,
    /// The dofs whose displacement it prescribes (those a later rule took over are the later
    /// rule's).
    pub dofs: Vec<usize>,
    /// Its load cases (indices into the subdomain's `loads`; tractions, or displacements not zero
    /// everywhere).
    pub cases: Vec<usize>,
}
