//! Building a [`Model`](glissade_mechanics::model::Model) from the raw scene: materials, blocks meshed
//! into subdomains, names, and (in the child modules) settings, interfaces, loads and the
//! rigid-mode check.

mod axis;
mod gmsh;
mod interfaces;
mod loads;
pub(crate) mod memory;
pub(crate) mod options;
mod parts;
pub(crate) mod rigid;

use crate::raw::*;
use crate::{
    Deployment, Network, Partition, Recording, SceneError, TlsFiles, DEFAULT_ANDERSON_WINDOW, MAX_ANDERSON_WINDOW,
    MAX_MACRO_DEGREE,
};
use glissade_mechanics::element::edge_lumped_mass;
use glissade_mechanics::expr::Expr;
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::mesh::{BlockSide, Mesh};
use glissade_mechanics::model::{
    interpolate, Acceleration, Interface, InterfaceKind, LoadCase, Material, Model, Plane, SolverParams, Subdomain,
    TimeFunction, TimeGrid, TimeStart, DEFAULT_TIME_START_TOLERANCE,
};
use glissade_mechanics::mortar::{end_pairs, project, project_with_ends, Projection, SideEdge};
use glissade_mechanics::pgd::{PgdCriterion, PgdParams};
use std::collections::BTreeMap;

pub(crate) struct Ctx<'a> {
    pub(crate) file: &'a str,
    /// The scene's `plane`: every edge integral (loads, interface weights) is taken against its
    /// measure.
    pub(crate) plane: Plane,
}

pub(crate) struct Built {
    pub(crate) model: Model,
    pub(crate) deployment: Deployment,
    pub(crate) recording: Recording,
    pub(crate) pgd: PgdParams,
    pub(crate) linear_stage: LinearStage,
    /// The bytes of the mesh file the model was built from, when they came from the file (not
    /// from embedded `data`): the loader embeds these very bytes in the scene text.
    pub(crate) mesh_file: Option<Vec<u8>>,
}

/// A subdomain during construction.
pub(crate) struct Sub {
    pub(crate) name: String,
    pub(crate) block: usize,
    pub(crate) x: [f64; 2],
    pub(crate) y: [f64; 2],
    /// `outer[side]`: this side lies on its block's outer boundary.
    pub(crate) outer: [bool; 4],
    /// Geometric tolerance: 1e-9 × the larger dimension of its block.
    pub(crate) tol: f64,
    pub(crate) mesh: Mesh,
    pub(crate) material: Material,
}

/// An interface found geometrically, before rules and pair removal.
pub(crate) struct GeoInterface {
    pub(crate) a: usize,
    pub(crate) b: usize,
    /// Unit normal of each pair, out of a.
    pub(crate) normals: Vec<[f64; 2]>,
    pub(crate) pairs: Vec<(usize, usize)>,
    pub(crate) coords: Vec<[f64; 2]>,
    pub(crate) weights: Vec<f64>,
    pub(crate) length: f64,
    /// Named curves of the mesh (indices) its edges lie on; empty for blocks.
    pub(crate) curves: Vec<usize>,
    /// Non-matching: side b's trace at each pair (pairs are side a's nodes).
    pub(crate) projection: Option<Projection>,
    /// Non-matching: the edges it was projected from (a's carrying pair indices, b's mesh
    /// nodes), to project again once the supports are known.
    pub(crate) sides: Option<(Vec<SideEdge>, Vec<SideEdge>)>,
}

/// Initial gap g0(x, y) of a contact rule.
pub(crate) enum GapSpec {
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
pub(crate) enum KindRule {
    Perfect,
    /// Contact rule `r` (index into the scene's interface rules).
    Contact(usize),
}

/// Loads of one subdomain during construction.
pub(crate) struct SubLoads {
    pub(crate) constrained: Vec<bool>,
    pub(crate) loads: Vec<LoadCase>,
    /// Load cases (a range) currently prescribing each dof (empty: none).
    pub(crate) owner: Vec<(usize, usize)>,
    /// The boundary rule prescribing each dof (the last one to), if any.
    pub(crate) dof_rule: Vec<Option<usize>>,
    /// The boundary rule of each load case (parallel to `loads`).
    pub(crate) case_rule: Vec<usize>,
}

/// A name in the scene: a block (all its subdomains) or one subdomain.
#[derive(Clone, Copy)]
pub(crate) enum NameRef {
    Block(usize),
    Sub(usize),
}

pub(crate) fn fmt_num(v: f64) -> String {
    format!("{v}")
}

pub(crate) fn outward_normal(side: BlockSide) -> [f64; 2] {
    match side {
        BlockSide::Bottom => [0.0, -1.0],
        BlockSide::Right => [1.0, 0.0],
        BlockSide::Top => [0.0, 1.0],
        BlockSide::Left => [-1.0, 0.0],
    }
}

/// Longest scene name (it starts every output file's name, before the 32-character run id).
pub const MAX_NAME_CHARS: usize = 100;

/// Whether `name` can start an output file's name as it is: 1 to [`MAX_NAME_CHARS`] ASCII letters,
/// digits, `-`, `_` or `.`, not starting with `.` (no path, no hidden file).
pub fn is_file_stem(name: &str) -> bool {
    (1..=MAX_NAME_CHARS).contains(&name.len())
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// The default name of a scene read from `file`: its stem with every other character replaced by
/// `_`, cut to [`MAX_NAME_CHARS`] (`scene` if nothing is left).
fn file_stem_name(file: &str) -> String {
    let stem = std::path::Path::new(file)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let clean: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .take(MAX_NAME_CHARS)
        .collect();
    let clean = clean.trim_start_matches('.').to_string();
    if clean.is_empty() {
        "scene".to_string()
    } else {
        clean
    }
}

impl Ctx<'_> {
    pub(crate) fn err(&self, key: impl Into<String>, problem: impl Into<String>) -> SceneError {
        SceneError {
            file: self.file.to_string(),
            key: key.into(),
            problem: problem.into(),
            set_by: None,
        }
    }

    pub(crate) fn check(&self, ok: bool, key: &str, problem: impl FnOnce() -> String) -> Result<(), SceneError> {
        if ok {
            Ok(())
        } else {
            Err(self.err(key, problem()))
        }
    }

    pub(crate) fn build(&self, raw: &RawScene) -> Result<Built, SceneError> {
        // The name starts every output file's name: a file name, never a path.
        let name = match &raw.name {
            Some(n) => {
                self.check(is_file_stem(n), "name", || {
                    format!(
                        "`{}` is not a file name: it starts every output file's name, so it takes \
                         1 to {MAX_NAME_CHARS} letters, digits, `-`, `_` or `.`, not starting with `.`",
                        n.chars().take(80).collect::<String>()
                    )
                })?;
                n.clone()
            }
            None => file_stem_name(self.file),
        };
        self.check_memory(raw)?;
        let plane = self.plane;
        let time = self.time_grid(&raw.time)?;
        let mut solver = self.solver(&raw.solver)?;
        let pgd = self.pgd(raw.solver.pgd.as_ref())?;
        let linear_stage = self.linear_stage(&raw.solver)?;
        let coarsening = self.time_start(&raw.solver)?;
        let recording = self.recording(&raw.recording)?;
        let materials = self.materials(&raw.materials)?;
        let mut mesh_file = None;
        let parts = match &raw.mesh {
            Some(mesh) => {
                if !raw.block.is_empty() {
                    return Err(self.err(
                        "block",
                        "a scene takes its parts either from [[block]] or from a [mesh], not both",
                    ));
                }
                let bytes = self.mesh_bytes(mesh)?;
                let parts = self.read_part_mesh(mesh, &bytes)?;
                if mesh.data.is_none() {
                    mesh_file = Some(bytes);
                }
                Some(parts)
            }
            None => None,
        };
        let (subs, names, geo, mut sub_loads, curve_names) = match parts {
            Some(pm) => self.build_parts(raw, pm, &materials, time)?,
            None => {
                self.blocks(raw, &materials)?;
                let subs = self.subdomains(raw, &materials);
                let names = self.names(raw, &subs)?;
                let mut geo = Vec::new();
                for i in 0..subs.len() {
                    for j in i + 1..subs.len() {
                        if let Some(g) = self.find_interface(&subs, i, j)? {
                            geo.push(g);
                        }
                    }
                }
                let sub_loads = self.boundaries(raw, &names, &subs, time)?;
                (subs, names, geo, sub_loads, Vec::new())
            }
        };
        self.hold_the_axis(&subs, &mut sub_loads, time)?;
        // Only now: choosing the time-coarse grid tries divisors of N, and a mesh scene's size is
        // known (and checked against the memory) once its parts are read: N = 10¹¹ took minutes
        // before its refusal.
        solver.time_start = self.resolve_time_start(coarsening, time.n_steps, linear_stage)?;
        let mut deployment = self.deployment(&raw.deployment, subs.len())?;
        let kinds = self.interface_rules(raw, &names, &subs, &geo, &curve_names)?;
        let gaps = self.gap_specs(raw)?;
        let interfaces = self.finish_interfaces(raw, geo, &kinds, &gaps, &sub_loads)?;
        // The macro problem is on unless a part is held only by contact in one of its rigid
        // motions and Anderson mixing is on: that combination stalls, or keeps the part off its
        // place while the forces have converged (`rigid::part_held_only_by_contact`,
        // docs/scenes.md).
        if matches!(solver.acceleration, Acceleration::Anderson { .. }) {
            let constrained: Vec<&[bool]> = sub_loads.iter().map(|l| l.constrained.as_slice()).collect();
            let coords: Vec<&[[f64; 2]]> = subs.iter().map(|s| s.mesh.coords.as_slice()).collect();
            if let Some(s) = rigid::part_held_only_by_contact(&interfaces, &coords, &constrained, plane) {
                let part = &subs[s].name;
                if raw.solver.coarse == Some(true) {
                    return Err(self.err(
                        "solver.coarse",
                        format!(
                            "`{part}` is held only by contact in one of its rigid-body motions, which the macro \
                             (coarse) problem with Anderson mixing cannot see; leave `coarse` unset or false, or set \
                             acceleration = \"none\""
                        ),
                    ));
                }
                solver.coarse = false;
            }
        }
        self.check_rigid_modes(&subs, &interfaces, &sub_loads)?;
        self.interface_groups(&raw.deployment, &mut deployment, &names, &subs, &interfaces)?;

        let boundary_rules = boundary_rules(raw, &sub_loads);
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
            boundary_rules,
            moment_about: self.moment_about(raw.moment_about)?,
        };
        let mut recording = recording;
        if recording.full_fields_auto
            && crate::settings::full_field_bytes_per_iteration(&model) > crate::settings::AUTO_FULL_FIELD_BYTES
        {
            recording.full_fields_every = crate::settings::AUTO_FULL_FIELDS_EVERY;
        }
        Ok(Built {
            model,
            deployment,
            recording,
            pgd,
            linear_stage,
            mesh_file,
        })
    }

    pub(crate) fn time_grid(&self, t: &RawTime) -> Result<TimeGrid, SceneError> {
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

    pub(crate) fn materials(
        &self,
        raw: &BTreeMap<String, RawMaterial>,
    ) -> Result<BTreeMap<String, Material>, SceneError> {
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
    pub(crate) fn blocks(&self, raw: &RawScene, materials: &BTreeMap<String, Material>) -> Result<(), SceneError> {
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

    pub(crate) fn subdomains(&self, raw: &RawScene, materials: &BTreeMap<String, Material>) -> Vec<Sub> {
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
    pub(crate) fn names(&self, raw: &RawScene, subs: &[Sub]) -> Result<BTreeMap<String, NameRef>, SceneError> {
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
    pub(crate) fn resolve(
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
}

pub(crate) fn block_dimension(b: &RawBlock) -> f64 {
    (b.x[1] - b.x[0]).abs().max((b.y[1] - b.y[0]).abs())
}

/// The boundary rules as the model reports them: per rule, per subdomain, the dofs it prescribes
/// and its load cases.
fn boundary_rules(raw: &RawScene, sub_loads: &[SubLoads]) -> Vec<glissade_mechanics::model::BoundaryRule> {
    use glissade_mechanics::model::{BoundaryRule, RulePart};
    raw.boundary
        .iter()
        .enumerate()
        .map(|(r, rule)| BoundaryRule {
            name: match &rule.curve {
                Some(c) => format!("boundary[{r}] ({c})"),
                None => format!("boundary[{r}]"),
            },
            prescribes_displacement: rule.ux.is_some() || rule.uy.is_some(),
            parts: sub_loads
                .iter()
                .enumerate()
                .map(|(s, l)| RulePart {
                    subdomain: s,
                    dofs: (0..l.dof_rule.len()).filter(|&d| l.dof_rule[d] == Some(r)).collect(),
                    cases: (0..l.case_rule.len()).filter(|&c| l.case_rule[c] == r).collect(),
                })
                .filter(|p| !p.dofs.is_empty() || !p.cases.is_empty())
                .collect(),
        })
        .collect()
}

impl Ctx<'_> {
    /// `moment_about`: a point with finite coordinates (mm), the origin when absent.
    fn moment_about(&self, p: Option<[f64; 2]>) -> Result<[f64; 2], SceneError> {
        let p = p.unwrap_or([0.0, 0.0]);
        self.check(p.iter().all(|v| v.is_finite()), "moment_about", || {
            format!("({}, {}) is not a point with finite coordinates", p[0], p[1])
        })?;
        Ok(p)
    }
}

/// The connected groups of items 0..n joined by `links` (union–find), each in increasing order,
/// the groups ordered by their smallest item.
pub(crate) fn connected_groups(n: usize, links: impl IntoIterator<Item = (usize, usize)>) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (a, b) in links {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb)] = ra.min(rb);
        }
    }
    // Each root is its group's smallest item: the map orders the groups by it.
    let mut groups: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for i in 0..n {
        let r = root(&mut parent, i);
        groups.entry(r).or_default().push(i);
    }
    groups.into_values().collect()
}
