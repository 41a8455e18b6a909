//! What the sections of a file have given so far: the nodes, their index by tag, the elements
//! and the physical groups; the planarity check once all nodes are read.

use super::parser::Parser;
use super::{MshElement, MshError};
use std::collections::{BTreeMap, HashMap};

/// Largest |z| accepted, relative to the size of the mesh (its bounding box diagonal in x, y).
const PLANAR_TOLERANCE: f64 = 1e-9;

/// What the sections read so far have given.
#[derive(Default)]
pub(super) struct State {
    pub(super) nodes: Vec<[f64; 2]>,
    pub(super) node_tags: Vec<u64>,
    /// z of each node and where it was read, for the check of planarity once all are known.
    pub(super) node_z: Vec<(f64, usize)>,
    index: NodeIndex,
    pub(super) nodes_read: bool,
    pub(super) elements: Vec<MshElement>,
    pub(super) elements_read: bool,
    pub(super) names: BTreeMap<(u8, i32), String>,
    /// MSH 4.1: physical tags of each geometric entity (dimension, tag).
    pub(super) entity_physicals: HashMap<(u8, i32), Vec<i32>>,
}

/// Node tag -> index into the node list: a dense vector when the tags are dense (as Gmsh writes
/// them), else a hash map.
#[derive(Default)]
enum NodeIndex {
    #[default]
    Empty,
    Dense(Vec<usize>),
    Sparse(HashMap<u64, usize>),
}

impl NodeIndex {
    fn get(&self, tag: u64) -> Option<usize> {
        match self {
            NodeIndex::Empty => None,
            NodeIndex::Dense(v) => usize::try_from(tag)
                .ok()
                .and_then(|t| v.get(t))
                .copied()
                .filter(|&i| i != usize::MAX),
            NodeIndex::Sparse(m) => m.get(&tag).copied(),
        }
    }
}

impl State {
    pub(super) fn add_node(&mut self, tag: u64, xyz: [f64; 3], at: usize, p: &Parser) -> Result<(), MshError> {
        if !xyz.iter().all(|c| c.is_finite()) {
            return Err(p.err_at(at, format!("node {tag}: a coordinate is not finite")));
        }
        self.nodes.push([xyz[0], xyz[1]]);
        self.node_tags.push(tag);
        self.node_z.push((xyz[2], at));
        Ok(())
    }

    /// Builds the tag index (refusing a tag given twice) and checks that the mesh is planar.
    pub(super) fn finish_nodes(&mut self, p: &Parser) -> Result<(), MshError> {
        let n = self.node_tags.len();
        let max = self.node_tags.iter().copied().max().unwrap_or(0);
        let duplicate = |tag: u64, i: usize| p.err_at(self.node_z[i].1, format!("node tag {tag} given twice"));
        if max <= 2 * n as u64 + 1024 {
            let mut v = vec![usize::MAX; max as usize + 1];
            for (i, &t) in self.node_tags.iter().enumerate() {
                if v[t as usize] != usize::MAX {
                    return Err(duplicate(t, i));
                }
                v[t as usize] = i;
            }
            self.index = NodeIndex::Dense(v);
        } else {
            let mut m = HashMap::with_capacity(n);
            for (i, &t) in self.node_tags.iter().enumerate() {
                if m.insert(t, i).is_some() {
                    return Err(duplicate(t, i));
                }
            }
            self.index = NodeIndex::Sparse(m);
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for x in &self.nodes {
            for k in 0..2 {
                lo[k] = lo[k].min(x[k]);
                hi[k] = hi[k].max(x[k]);
            }
        }
        let size = if n == 0 {
            0.0
        } else {
            (hi[0] - lo[0]).hypot(hi[1] - lo[1])
        };
        // Plain where that is short, else in exponent form (a damaged binary mesh can hold 1e300).
        let short = |x: f64| {
            if x == 0.0 || (1e-4..1e6).contains(&x.abs()) {
                format!("{x}")
            } else {
                format!("{x:e}")
            }
        };
        for (i, &(z, at)) in self.node_z.iter().enumerate() {
            if z.abs() > PLANAR_TOLERANCE * size {
                return Err(p.err_at(
                    at,
                    format!(
                        "node {} has z = {}: the mesh must lie in the plane z = 0 (|z| at most {PLANAR_TOLERANCE:e} × \
                         the mesh size {})",
                        self.node_tags[i],
                        short(z),
                        short(size)
                    ),
                ));
            }
        }
        self.node_z = Vec::new();
        self.nodes_read = true;
        Ok(())
    }

    pub(super) fn node(&self, element: u64, tag: u64, at: usize, p: &Parser) -> Result<usize, MshError> {
        self.index.get(tag).ok_or_else(|| {
            p.err_at(
                at,
                format!("element {element} refers to node {tag}, which is not in $Nodes"),
            )
        })
    }
}
