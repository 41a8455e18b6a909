//! A Gmsh mesh as the parts of a scene: every physical surface one part of 8-node quadrilaterals,
//! every physical curve a named curve of 3-node edges; the mesh's bytes read from the scene's
//! `[mesh] file` or from the `data` the loader embedded.

use super::parts::{CurveIn, PartIn, PartMesh};
use super::*;
use crate::msh;
use base64::Engine;

/// Gmsh's type of the 8-node quadrangle and of the 3-node line.
const QUA8: u32 = 16;
const LINE3: u32 = 8;

/// How to make Gmsh write what glissade reads, for refusals.
pub(crate) const QUA8_OPTIONS: &str = "Gmsh writes 8-node quadrangles with Mesh.ElementOrder = 2, \
     Mesh.SecondOrderIncomplete = 1 and Mesh.RecombineAll = 1 (with transfinite surfaces, or \
     Mesh.Algorithm = 8 and Mesh.RecombinationAlgorithm = 1 so that no triangle is left)";

impl Ctx<'_> {
    /// The mesh file's bytes: the embedded `data`, or the file next to the scene.
    pub(crate) fn mesh_bytes(&self, mesh: &RawMesh) -> Result<Vec<u8>, SceneError> {
        match &mesh.data {
            Some(data) => base64::engine::general_purpose::STANDARD
                .decode(data.as_bytes())
                .map_err(|e| self.err("mesh.data", format!("is not the base64 of a mesh file: {e}"))),
            None => {
                let path = mesh_path(self.file, &mesh.file);
                // Only a file (a device such as /dev/zero would be read until memory runs out).
                if std::fs::metadata(&path).is_ok_and(|m| !m.is_file()) {
                    return Err(self.err("mesh.file", format!("`{}` is not a regular file", path.display())));
                }
                std::fs::read(&path)
                    .map_err(|e| self.err("mesh.file", format!("cannot read `{}`: {e}", path.display())))
            }
        }
    }

    /// Reads the scene's Gmsh mesh (`bytes`, from [`Self::mesh_bytes`]) into parts and named
    /// curves.
    pub(crate) fn read_part_mesh(&self, mesh: &RawMesh, bytes: &[u8]) -> Result<PartMesh, SceneError> {
        let key = "mesh.file";
        let origin = mesh.file.clone();
        // A mesh from the scene's embedded data is reported under that key.
        let key = if mesh.data.is_some() { "mesh.data" } else { key };
        let m = msh::parse(bytes).map_err(|e| self.err(key, format!("{origin}: {e}")))?;
        // Element types of dimension 2: only 8-node quadrangles.
        let mut other: BTreeMap<u32, (usize, u64)> = BTreeMap::new();
        for e in &m.elements {
            if e.dim == 2 && e.kind != QUA8 {
                other.entry(e.kind).or_insert((0, e.tag)).0 += 1;
            }
        }
        if !other.is_empty() {
            let list: Vec<String> = other
                .iter()
                .map(|(&k, &(n, tag))| format!("{n} × {} (Gmsh type {k}, e.g. element {tag})", msh::type_name(k)))
                .collect();
            return Err(self.err(
                key,
                format!(
                    "{origin}: glissade reads 8-node quadrilaterals (Gmsh type 16) only, and the mesh also has {}: {QUA8_OPTIONS}",
                    list.join(", ")
                ),
            ));
        }
        let name_of = |dim: u8, tag: i32| match m.physical_names.get(&(dim, tag)) {
            Some(n) if !n.is_empty() => n.clone(),
            _ => format!("{}-{tag}", if dim == 2 { "surface" } else { "curve" }),
        };
        // Parts: physical surfaces in order of their tags.
        let mut surfaces: Vec<i32> = m.physical_names.keys().filter(|k| k.0 == 2).map(|k| k.1).collect();
        for e in m.elements.iter().filter(|e| e.dim == 2) {
            for &p in &e.physicals {
                if !surfaces.contains(&p) {
                    surfaces.push(p);
                }
            }
        }
        surfaces.sort_unstable();
        let mut parts: Vec<PartIn> = surfaces
            .iter()
            .map(|&t| PartIn {
                name: name_of(2, t),
                elements: Vec::new(),
                element_tags: Vec::new(),
            })
            .collect();
        let mut orphans = (0, 0u64);
        for e in m.elements.iter().filter(|e| e.dim == 2) {
            match e.physicals.as_slice() {
                [] => {
                    if orphans.0 == 0 {
                        orphans.1 = e.tag;
                    }
                    orphans.0 += 1;
                }
                [p] => {
                    let s = surfaces.iter().position(|x| x == p).unwrap_or(0);
                    let nodes: [usize; 8] = std::array::from_fn(|k| e.nodes[k]);
                    parts[s].elements.push(nodes);
                    parts[s].element_tags.push(e.tag);
                }
                several => {
                    let names: Vec<String> = several.iter().map(|&p| format!("`{}`", name_of(2, p))).collect();
                    return Err(self.err(
                        key,
                        format!(
                            "{origin}: element {} belongs to several physical surfaces ({}): a part is one physical \
                             surface and parts do not overlap",
                            e.tag,
                            names.join(", ")
                        ),
                    ));
                }
            }
        }
        if orphans.0 > 0 {
            return Err(self.err(
                key,
                format!(
                    "{origin}: {} quadrilaterals (e.g. element {}) belong to no physical surface: every part of the \
                     model must be a physical surface (Gmsh: gmsh.model.addPhysicalGroup(2, …, name=…))",
                    orphans.0, orphans.1
                ),
            ));
        }
        parts.retain(|p| !p.elements.is_empty());
        if parts.is_empty() {
            return Err(self.err(
                key,
                format!("{origin}: no physical surface: every part of the model must be a physical surface"),
            ));
        }
        // Named curves: 3-node lines (end, end, middle in Gmsh's order).
        let mut curves: BTreeMap<i32, CurveIn> = BTreeMap::new();
        let curve = |tag: i32| CurveIn {
            name: name_of(1, tag),
            edges: Vec::new(),
            element_tags: Vec::new(),
        };
        for e in m.elements.iter().filter(|e| e.dim == 1) {
            for &p in &e.physicals {
                if e.kind != LINE3 {
                    return Err(self.err(
                        key,
                        format!(
                            "{origin}: curve `{}` has {} elements (Gmsh type {}, e.g. element {}), not 3-node lines: \
                             {QUA8_OPTIONS}",
                            name_of(1, p),
                            msh::type_name(e.kind),
                            e.kind,
                            e.tag
                        ),
                    ));
                }
                let c = curves.entry(p).or_insert_with(|| curve(p));
                c.edges.push([e.nodes[0], e.nodes[2], e.nodes[1]]);
                c.element_tags.push(e.tag);
            }
        }
        // Physical curves without elements are kept (a rule naming one is told it selects
        // nothing); two physical curves of one name are refused.
        for &(_, tag) in m.physical_names.keys().filter(|k| k.0 == 1) {
            curves.entry(tag).or_insert_with(|| curve(tag));
        }
        let mut seen: BTreeMap<&str, i32> = BTreeMap::new();
        for (&tag, CurveIn { name, .. }) in &curves {
            if let Some(other) = seen.insert(name.as_str(), tag) {
                return Err(self.err(
                    key,
                    format!("{origin}: two physical curves are named `{name}` (tags {other} and {tag})"),
                ));
            }
        }
        Ok(PartMesh {
            origin,
            nodes: m.nodes,
            node_tags: m.node_tags,
            parts,
            curves: curves.into_values().collect(),
        })
    }
}

/// The mesh file named in a scene read from `scene_file`: relative to the scene's folder.
pub(crate) fn mesh_path(scene_file: &str, mesh_file: &str) -> std::path::PathBuf {
    let dir = std::path::Path::new(scene_file)
        .parent()
        .unwrap_or_else(|| std::path::Path::new(""));
    dir.join(mesh_file)
}
