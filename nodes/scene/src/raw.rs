//! The scene as written: serde structs, unknown keys rejected everywhere.

use glissade_mechanics::mesh::BlockSide;
use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScene {
    pub(crate) name: Option<String>,
    pub(crate) plane: Option<RawPlane>,
    /// The point boundary forces' moments are taken about (mm).
    pub(crate) moment_about: Option<[f64; 2]>,
    pub(crate) time: RawTime,
    #[serde(default)]
    pub(crate) materials: BTreeMap<String, RawMaterial>,
    #[serde(default)]
    pub(crate) block: Vec<RawBlock>,
    pub(crate) mesh: Option<RawMesh>,
    #[serde(default)]
    pub(crate) interface: Vec<RawInterface>,
    #[serde(default)]
    pub(crate) boundary: Vec<RawBoundary>,
    #[serde(default)]
    pub(crate) solver: RawSolver,
    #[serde(default)]
    pub(crate) deployment: RawDeployment,
    #[serde(default)]
    pub(crate) recording: RawRecording,
    #[serde(default)]
    pub(crate) network: RawNetwork,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawPlane {
    Strain,
    Stress,
    Axisymmetric,
}

impl RawScene {
    /// The scene's `plane` (plane strain unless it says otherwise).
    pub(crate) fn plane(&self) -> glissade_mechanics::model::Plane {
        use glissade_mechanics::model::Plane;
        match self.plane {
            None | Some(RawPlane::Strain) => Plane::Strain,
            Some(RawPlane::Stress) => Plane::Stress,
            Some(RawPlane::Axisymmetric) => Plane::Axisymmetric,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTime {
    #[serde(rename = "T")]
    pub(crate) t_end: f64,
    #[serde(rename = "N")]
    pub(crate) n_steps: usize,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMaterial {
    #[serde(rename = "E")]
    pub(crate) e: f64,
    pub(crate) nu: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawBlock {
    pub(crate) name: String,
    pub(crate) material: String,
    pub(crate) x: [f64; 2],
    pub(crate) y: [f64; 2],
    pub(crate) nx: usize,
    pub(crate) ny: usize,
    pub(crate) split: Option<[usize; 2]>,
}

/// `[mesh]`: the parts come from a Gmsh file instead of blocks.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMesh {
    /// The mesh file, relative to the scene's folder.
    pub(crate) file: String,
    /// The file's bytes in base64, written by the loader so that the scene text travels with its
    /// mesh (to node processes, into recordings).
    pub(crate) data: Option<String>,
    /// Material of the parts: a part's name or a name prefix shared by parts (`sheath` for
    /// `sheath.1`, `sheath.2`, …) → material.
    #[serde(default)]
    pub(crate) materials: BTreeMap<String, String>,
    /// Distance (mm) within which boundary edges of two parts that share no nodes face each
    /// other: a non-matching interface.
    pub(crate) match_tolerance: Option<f64>,
}

#[derive(Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawKind {
    Perfect,
    Contact,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawInterface {
    pub(crate) between: Option<[String; 2]>,
    /// A named curve of the mesh: the interfaces whose edges lie on it.
    pub(crate) curve: Option<String>,
    pub(crate) kind: RawKind,
    pub(crate) friction: Option<f64>,
    pub(crate) gap: Option<toml::Value>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawSide {
    Bottom,
    Right,
    Top,
    Left,
}

impl RawSide {
    pub(crate) fn block_side(self) -> BlockSide {
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
pub(crate) struct RawBoundary {
    pub(crate) blocks: Option<Vec<String>>,
    /// A named curve of the mesh.
    pub(crate) curve: Option<String>,
    pub(crate) side: Option<RawSide>,
    pub(crate) x: Option<f64>,
    pub(crate) y: Option<f64>,
    pub(crate) ux: Option<toml::Value>,
    pub(crate) uy: Option<toml::Value>,
    pub(crate) tx: Option<toml::Value>,
    pub(crate) ty: Option<toml::Value>,
    pub(crate) p: Option<toml::Value>,
    /// Tangential traction along the boundary (counter-clockwise around the part).
    pub(crate) shear: Option<toml::Value>,
}

/// `solver.macro_degree` and `solver.time_coarsening`: a number or a name ("auto", "off").
#[derive(Deserialize, Clone)]
#[serde(untagged)]
pub(crate) enum RawDegree {
    Degree(i64),
    Name(String),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSolver {
    pub(crate) k0_factor: Option<f64>,
    pub(crate) relaxation: Option<f64>,
    pub(crate) accuracy: Option<f64>,
    pub(crate) tolerance: Option<f64>,
    pub(crate) contact_tolerance: Option<f64>,
    pub(crate) max_iterations: Option<usize>,
    pub(crate) stagnation_window: Option<usize>,
    pub(crate) stagnation_ratio: Option<f64>,
    pub(crate) coarse: Option<bool>,
    pub(crate) search_direction_update: Option<bool>,
    pub(crate) alpha: Option<f64>,
    pub(crate) i0: Option<f64>,
    pub(crate) macro_degree: Option<RawDegree>,
    pub(crate) acceleration: Option<RawAcceleration>,
    pub(crate) anderson_window: Option<usize>,
    pub(crate) time_coarsening: Option<RawDegree>,
    pub(crate) time_coarsening_tolerance: Option<f64>,
    pub(crate) linear_stage: Option<RawLinearStage>,
    pub(crate) pgd: Option<RawPgd>,
}

#[derive(Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum RawLinearStage {
    Condensed,
    Sparse,
    Pgd,
    Auto,
}

#[derive(Deserialize, Clone, Copy, PartialEq)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum RawAcceleration {
    None,
    Anderson,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum RawPartition {
    Contiguous,
    Bisection,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
pub(crate) enum RawCriterion {
    Increment,
    Accumulated,
    IncrementSvd,
    Forcing,
    ForcingSvd,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPgd {
    pub(crate) enabled: Option<bool>,
    pub(crate) xi1: Option<f64>,
    pub(crate) xi2: Option<f64>,
    pub(crate) criterion: Option<RawCriterion>,
    pub(crate) macro_modes: Option<bool>,
    pub(crate) max_new_modes: Option<usize>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawDeployment {
    pub(crate) subdomain_nodes: Option<usize>,
    pub(crate) partition: Option<RawPartition>,
    pub(crate) interface_nodes: Option<usize>,
    pub(crate) interface_groups: Option<Vec<Vec<RawInterfaceRef>>>,
    pub(crate) restarts: Option<usize>,
    pub(crate) interfaces_in_launcher: Option<bool>,
    pub(crate) interfaces_with_subdomains: Option<bool>,
    pub(crate) memory_limit_gb: Option<f64>,
}

/// An interface in `deployment.interface_groups`: its index, or `"A|B"` (every interface between
/// a subdomain of block or subdomain A and one of B).
#[derive(Deserialize, Clone)]
#[serde(untagged)]
pub(crate) enum RawInterfaceRef {
    Index(usize),
    Between(String),
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawNetwork {
    pub(crate) tls: Option<RawTls>,
    pub(crate) allow: Option<Vec<String>>,
    pub(crate) shared_memory: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTls {
    pub(crate) root_ca: String,
    pub(crate) cert: String,
    pub(crate) key: String,
    pub(crate) mutual: Option<bool>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRecording {
    pub(crate) enabled: Option<bool>,
    pub(crate) topics: Option<Vec<String>>,
    pub(crate) full_fields_every: Option<usize>,
}
