//! Subdomains and interfaces of an imported mesh: one subdomain per part (a physical surface of a
//! Gmsh file), the elements checked (orientation, Jacobian, one piece, no duplicate nodes), the
//! interfaces found where two parts share element edges, and the meshes that do not conform along
//! a shared curve refused (docs/scenes.md, "`[mesh]`: parts from a Gmsh file").
//!
//! This file holds the parts' data and their turning into subdomains, names and materials
//! ([`Ctx::build_parts`]); `geometry` checks every part and finds the edges two parts share
//! ([`Ctx::part_geometry`]); `interface` turns the shared edges into interfaces and gives copies
//! of one node pair one normal.

mod geometry;
mod interface;

use super::*;
use interface::harmonise_normals;
use std::collections::HashMap;

/// A mesh cut into parts, as read from a mesh file: global nodes, the parts' QUA8 elements and
/// the named curves' 3-node edges (end, middle, end), all in global node indices.
pub(crate) struct PartMesh {
    /// What the mesh is called in messages (the file name as the scene gives it).
    pub(crate) origin: String,
    pub(crate) nodes: Vec<[f64; 2]>,
    /// The file's tag of each node (for messages).
    pub(crate) node_tags: Vec<u64>,
    pub(crate) parts: Vec<PartIn>,
    /// Named curves (physical curves).
    pub(crate) curves: Vec<CurveIn>,
}

/// A named curve as read from a mesh file: its 3-node edges (end, middle, end; global node
/// indices) and the file's tag of each.
pub(crate) struct CurveIn {
    pub(crate) name: String,
    pub(crate) edges: Vec<[usize; 3]>,
    pub(crate) element_tags: Vec<u64>,
}

/// An element of a named curve that lies on an edge shared by two elements of one part (inside
/// it, not on its boundary): the file's tags of the element and of its nodes (in the file's
/// order: end, end, middle), and the part.
pub(crate) struct CurveInside {
    pub(crate) element: u64,
    pub(crate) nodes: [u64; 3],
    pub(crate) part: usize,
}

pub(crate) struct PartIn {
    pub(crate) name: String,
    /// Corners counter-clockwise or clockwise, then the mid-side nodes (Gmsh's and our order).
    pub(crate) elements: Vec<[usize; 8]>,
    pub(crate) element_tags: Vec<u64>,
}

/// A boundary edge of a part: local nodes (end, middle, end) running with the part on their left.
#[derive(Clone, Copy)]
pub(crate) struct Edge {
    pub(crate) nodes: [usize; 3],
}

/// Subdomains and interfaces built from a [`PartMesh`].
pub(crate) struct PartGeometry {
    /// Per subdomain: its mesh (local numbering).
    pub(crate) meshes: Vec<Mesh>,
    /// Per subdomain: its boundary edges (local nodes, the part on their left).
    pub(crate) boundary: Vec<Vec<Edge>>,
    /// Per subdomain and boundary edge: the named curves the edge lies on.
    pub(crate) edge_curves: Vec<Vec<Vec<usize>>>,
    /// Per named curve: its first element inside a part, if any.
    pub(crate) curve_inside: Vec<Option<CurveInside>>,
    /// Per subdomain and boundary edge: the edge is shared with another part (an interface).
    pub(crate) on_interface: Vec<Vec<bool>>,
    pub(crate) interfaces: Vec<GeoInterface>,
    /// Coincidence tolerance: 1e-9 × the mesh's size.
    pub(crate) tol: f64,
    /// Bounding box of each subdomain: ([x0, x1], [y0, y1]).
    pub(crate) boxes: Vec<([f64; 2], [f64; 2])>,
}

/// Node lookup by position: cells of `cell` mm, the 3 × 3 neighbourhood searched.
struct Grid {
    cell: f64,
    map: HashMap<(i64, i64), Vec<usize>>,
}

impl Grid {
    fn new(cell: f64) -> Self {
        Self {
            cell,
            map: HashMap::new(),
        }
    }
    fn key(&self, x: [f64; 2]) -> (i64, i64) {
        ((x[0] / self.cell).round() as i64, (x[1] / self.cell).round() as i64)
    }
    fn insert(&mut self, x: [f64; 2], v: usize) {
        let k = self.key(x);
        self.map.entry(k).or_default().push(v);
    }
    /// Values stored within the 3 × 3 cells around `x`.
    fn near(&self, x: [f64; 2]) -> impl Iterator<Item = usize> + '_ {
        let (i, j) = self.key(x);
        (-1..=1)
            .flat_map(move |di| (-1..=1).map(move |dj| (i + di, j + dj)))
            .filter_map(|k| self.map.get(&k))
            .flatten()
            .copied()
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Whether the edge from `p` to `q` runs backwards: towards smaller x, or along x = const towards
/// smaller y. Interface chains and loaded edges run forwards, as the block mesher's sides do.
pub(crate) fn runs_backwards(p: [f64; 2], q: [f64; 2]) -> bool {
    let tol = 1e-9 * (p[0] - q[0]).abs().max((p[1] - q[1]).abs());
    if (p[0] - q[0]).abs() > tol {
        q[0] < p[0]
    } else {
        q[1] < p[1]
    }
}

impl Ctx<'_> {
    /// Subdomains, names, interfaces and loads of a mesh scene: one subdomain per part, the
    /// parts' name prefixes (`sheath` for `sheath.1`, `sheath.2`, …) as group names, materials
    /// from `[mesh] materials`, boundaries from named curves.
    #[allow(clippy::type_complexity)]
    pub(crate) fn build_parts(
        &self,
        raw: &RawScene,
        pm: PartMesh,
        materials: &BTreeMap<String, Material>,
        time: TimeGrid,
    ) -> Result<
        (
            Vec<Sub>,
            BTreeMap<String, NameRef>,
            Vec<GeoInterface>,
            Vec<SubLoads>,
            Vec<String>,
        ),
        SceneError,
    > {
        let geometry = self.part_geometry(&pm, raw.mesh.as_ref().and_then(|m| m.match_tolerance))?;
        let sizes: Vec<(usize, usize)> = geometry
            .meshes
            .iter()
            .zip(&geometry.boundary)
            .map(|(m, edges)| (m.n_nodes(), 2 * edges.len()))
            .collect();
        self.check_memory_estimate(raw, memory::estimate_parts(&sizes, time.n_steps))?;
        let mut names: BTreeMap<String, NameRef> = BTreeMap::new();
        for (s, part) in pm.parts.iter().enumerate() {
            if names.insert(part.name.clone(), NameRef::Sub(s)).is_some() {
                return Err(self.err(
                    "mesh.file",
                    format!("{}: two parts are named `{}`", pm.origin, part.name),
                ));
            }
        }
        let prefix = |name: &str| name.rsplit_once('.').map(|(p, _)| p.to_string());
        let mut groups: Vec<String> = Vec::new();
        let mut group_of = Vec::with_capacity(pm.parts.len());
        for part in &pm.parts {
            let g = match prefix(&part.name) {
                Some(p) if !p.is_empty() => p,
                _ => part.name.clone(),
            };
            let index = match groups.iter().position(|x| *x == g) {
                Some(i) => i,
                None => {
                    groups.push(g.clone());
                    groups.len() - 1
                }
            };
            group_of.push(index);
            if g != part.name {
                match names.get(&g) {
                    Some(NameRef::Sub(_)) => {
                        return Err(self.err(
                            "mesh.file",
                            format!(
                                "{}: `{g}` names a part and is also the prefix of part `{}`",
                                pm.origin, part.name
                            ),
                        ))
                    }
                    _ => {
                        names.insert(g, NameRef::Block(index));
                    }
                }
            }
        }
        let Some(mesh) = &raw.mesh else {
            unreachable!("build_parts is called for a [mesh] scene")
        };
        for (key, material) in &mesh.materials {
            self.check(names.contains_key(key), &format!("mesh.materials.{key}"), || {
                let known: Vec<&str> = names.keys().map(String::as_str).collect();
                format!(
                    "no part or name prefix `{key}` in the mesh (it has: {})",
                    known.join(", ")
                )
            })?;
            self.check(
                materials.contains_key(material),
                &format!("mesh.materials.{key}"),
                || {
                    let known: Vec<&str> = materials.keys().map(String::as_str).collect();
                    format!("unknown material `{material}` (defined: {})", known.join(", "))
                },
            )?;
        }
        let curve_names: Vec<String> = pm.curves.iter().map(|c| c.name.clone()).collect();
        let mut subs = Vec::with_capacity(pm.parts.len());
        for (s, (part, mesh_s)) in pm.parts.iter().zip(geometry.meshes.iter()).enumerate() {
            let group = &groups[group_of[s]];
            let Some(material) = mesh.materials.get(&part.name).or_else(|| mesh.materials.get(group)) else {
                return Err(self.err(
                    "mesh.materials",
                    format!(
                        "part `{}` has no material: map it or its prefix `{group}` to one",
                        part.name
                    ),
                ));
            };
            let (x, y) = geometry.boxes[s];
            subs.push(Sub {
                name: part.name.clone(),
                block: group_of[s],
                x,
                y,
                outer: [false; 4],
                tol: geometry.tol,
                mesh: mesh_s.clone(),
                material: materials[material],
            });
        }
        let sub_loads = self.mesh_boundaries(raw, &geometry, &curve_names, &subs, time)?;
        let mut geo = geometry.interfaces;
        harmonise_normals(&mut geo, geometry.tol);
        Ok((subs, names, geo, sub_loads, curve_names))
    }
}
