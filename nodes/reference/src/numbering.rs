//! The global numbering: perfect-interface node pairs merged, contact pairs merged across
//! interface copies, and the groups of perfect copies that share a node's interface force.

use crate::NONE;
use glissade_mechanics::model::{Interface, Model};
use std::collections::BTreeMap;

/// Global numbering with perfect-interface node pairs merged.
pub(crate) struct Numbering {
    pub(crate) node_offset: Vec<usize>,
    pub(crate) merged: Vec<usize>,
    pub(crate) n_merged: usize,
}

impl Numbering {
    /// Perfect-interface node pairs merged (contact pairs keep their two nodes; a non-matching
    /// perfect interface is a constraint of its own, [`MergedPair::tie`]).
    pub(crate) fn new(model: &Model) -> Self {
        Self::merging(model, |i| !i.is_contact() && !i.is_non_matching())
    }

    /// The node pairs of every interface `merge` accepts merged (union–find, the smallest id as
    /// root; merged nodes numbered in order of their first node).
    pub(crate) fn merging(model: &Model, merge: impl Fn(&Interface) -> bool) -> Self {
        let mut node_offset = Vec::with_capacity(model.subdomains.len());
        let mut n = 0;
        for s in &model.subdomains {
            node_offset.push(n);
            n += s.mesh.n_nodes();
        }
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(parent: &mut [usize], mut x: usize) -> usize {
            while parent[x] != x {
                parent[x] = parent[parent[x]];
                x = parent[x];
            }
            x
        }
        for itf in model.interfaces.iter().filter(|i| merge(i)) {
            for &(na, nb) in &itf.pairs {
                let ra = find(&mut parent, node_offset[itf.a] + na);
                let rb = find(&mut parent, node_offset[itf.b] + nb);
                if ra != rb {
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
        let mut id = vec![NONE; n];
        let mut merged = vec![0; n];
        let mut n_merged = 0;
        for (x, mx) in merged.iter_mut().enumerate() {
            let r = find(&mut parent, x);
            if id[r] == NONE {
                id[r] = n_merged;
                n_merged += 1;
            }
            *mx = id[r];
        }
        Self {
            node_offset,
            merged,
            n_merged,
        }
    }

    pub(crate) fn node(&self, s: usize, node: usize) -> usize {
        self.merged[self.node_offset[s] + node]
    }

    pub(crate) fn dof(&self, s: usize, d: usize) -> usize {
        2 * self.node(s, d / 2) + d % 2
    }
}

/// One merged contact pair, or the constraint of a pair of a non-matching perfect interface.
pub(crate) struct MergedPair {
    /// The jump is Σ coef·u(node) over these (merged node, coefficient) terms: (a, −1), (b, +1)
    /// on a conforming pair; (a, −1) and side b's projection on a non-matching one.
    pub(crate) terms: Vec<(usize, f64)>,
    pub(crate) normal: [f64; 2],
    pub(crate) tangent: [f64; 2],
    pub(crate) friction: f64,
    pub(crate) gap: f64,
    pub(crate) weight: f64,
    /// E_m · W_m / h_Γ (N/mm); r = r_factor × this.
    pub(crate) r_base: f64,
    /// Free index of each term's x and y (entry 2k + c), or NONE.
    pub(crate) free: Vec<usize>,
    /// A pair of a non-matching perfect interface: its jump is held at zero (both components).
    pub(crate) tie: bool,
}

impl MergedPair {
    /// (component, coefficient) of entry q of [`MergedPair::free`].
    pub(crate) fn entry(&self, q: usize) -> (usize, f64) {
        (q % 2, self.terms[q / 2].1)
    }
}

/// One perfect copy joining two vertices of a group.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PerfectEdge {
    pub(crate) interface: usize,
    pub(crate) pair: usize,
    /// Vertices (in the group) of sides a and b.
    pub(crate) va: usize,
    pub(crate) vb: usize,
    pub(crate) weight: f64,
}

/// A group of subdomain nodes merged through perfect interfaces, with its perfect copies.
pub(crate) struct PerfectGroup {
    /// Unmerged global node ids (node_offset[s] + node) and their subdomain.
    pub(crate) vertices: Vec<(usize, usize, usize)>,
    pub(crate) edges: Vec<PerfectEdge>,
    /// LU of the weighted graph Laplacian + (mean weight)·11ᵀ.
    pub(crate) lu: nalgebra::LU<f64, nalgebra::Dyn, nalgebra::Dyn>,
}

/// Perfect-copy groups: merged nodes with at least one perfect copy, their subdomain nodes and
/// the factorised weighted Laplacian of the copies.
pub(crate) fn perfect_groups(model: &Model, num: &Numbering) -> Vec<PerfectGroup> {
    // merged node -> group index
    let mut group_of: BTreeMap<usize, usize> = BTreeMap::new();
    let mut vertices: Vec<Vec<(usize, usize, usize)>> = Vec::new();
    let mut edges: Vec<Vec<PerfectEdge>> = Vec::new();
    for (ki, itf) in model.interfaces.iter().enumerate() {
        if itf.is_contact() || itf.is_non_matching() {
            continue;
        }
        for (p, &(na, nb)) in itf.pairs.iter().enumerate() {
            let m = num.node(itf.a, na);
            let gi = *group_of.entry(m).or_insert_with(|| {
                vertices.push(Vec::new());
                edges.push(Vec::new());
                vertices.len() - 1
            });
            let mut vertex = |s: usize, node: usize| {
                let id = num.node_offset[s] + node;
                match vertices[gi].iter().position(|v| v.0 == id) {
                    Some(v) => v,
                    None => {
                        vertices[gi].push((id, s, node));
                        vertices[gi].len() - 1
                    }
                }
            };
            let (va, vb) = (vertex(itf.a, na), vertex(itf.b, nb));
            edges[gi].push(PerfectEdge {
                interface: ki,
                pair: p,
                va,
                vb,
                weight: itf.weights[p],
            });
        }
    }
    vertices
        .into_iter()
        .zip(edges)
        .map(|(vertices, edges)| {
            let nv = vertices.len();
            let mean_w = edges.iter().map(|e| e.weight).sum::<f64>() / edges.len() as f64;
            let mut l = nalgebra::DMatrix::<f64>::from_element(nv, nv, mean_w / nv as f64);
            for &PerfectEdge {
                va: a,
                vb: b,
                weight: w,
                ..
            } in &edges
            {
                l[(a, a)] += w;
                l[(b, b)] += w;
                l[(a, b)] -= w;
                l[(b, a)] -= w;
            }
            PerfectGroup {
                vertices,
                edges,
                lu: l.lu(),
            }
        })
        .collect()
}
