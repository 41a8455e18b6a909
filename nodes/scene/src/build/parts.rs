//! Subdomains and interfaces of an imported mesh: one subdomain per part (a physical surface of a
//! Gmsh file), the elements checked (orientation, Jacobian, one piece, no duplicate nodes), the
//! interfaces found where two parts share element edges, and the meshes that do not conform along
//! a shared curve refused (DESIGN §2, "Curved and inclined interfaces").

use super::*;
use glissade_mechanics::element::{edge_frame, jacobian, GAUSS3};
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
    /// Named curves: name and edges.
    pub(crate) curves: Vec<(String, Vec<[usize; 3]>)>,
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

/// Element sides as (end, middle, end) local positions, counter-clockwise.
const SIDES: [[usize; 3]; 4] = [[0, 4, 1], [1, 5, 2], [2, 6, 3], [3, 7, 0]];

/// A clockwise element in counter-clockwise order: the same nodes, mirrored.
fn reversed(e: [usize; 8]) -> [usize; 8] {
    [e[0], e[3], e[2], e[1], e[7], e[6], e[5], e[4]]
}

/// det J of an element at the 3 × 3 Gauss points, with the points.
fn jacobians(x: &[[f64; 2]; 8]) -> [(f64, f64, f64); 9] {
    std::array::from_fn(|g| {
        let (xi, eta) = (GAUSS3[g / 3].0, GAUSS3[g % 3].0);
        (jacobian(x, xi, eta).1, xi, eta)
    })
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

/// The point of the quadratic edge `x` nearest to `p` and its distance (sampled, then Newton).
fn distance_to_edge(x: &[[f64; 2]; 3], p: [f64; 2]) -> f64 {
    let mut best = (f64::INFINITY, 0.0);
    for k in 0..=20 {
        let s = -1.0 + 0.1 * k as f64;
        let d = dist(edge_frame(x, s).0, p);
        if d < best.0 {
            best = (d, s);
        }
    }
    let mut s = best.1;
    for _ in 0..4 {
        let (q, t, jac) = edge_frame(x, s);
        let step = ((p[0] - q[0]) * t[0] + (p[1] - q[1]) * t[1]) / jac;
        s = (s + step).clamp(-1.0, 1.0);
    }
    dist(edge_frame(x, s).0, p).min(best.0)
}

impl Ctx<'_> {
    /// Checks every part and builds the subdomains' meshes, boundaries and interfaces.
    pub(crate) fn part_geometry(&self, m: &PartMesh) -> Result<PartGeometry, SceneError> {
        let key = "mesh.file";
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for x in &m.nodes {
            lo = [lo[0].min(x[0]), lo[1].min(x[1])];
            hi = [hi[0].max(x[0]), hi[1].max(x[1])];
        }
        let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f64::MIN_POSITIVE);
        let tol = 1e-9 * size;
        let at = |x: [f64; 2]| format!("({}, {})", fmt_num(x[0]), fmt_num(x[1]));
        let node_tag = |n: usize| m.node_tags[n];

        let mut meshes = Vec::with_capacity(m.parts.len());
        let mut boundary = Vec::with_capacity(m.parts.len());
        let mut globals: Vec<Vec<usize>> = Vec::with_capacity(m.parts.len());
        let mut boxes = Vec::with_capacity(m.parts.len());
        for part in &m.parts {
            let who = format!("{}: part `{}`", m.origin, part.name);
            if part.elements.is_empty() {
                return Err(self.err(key, format!("{who} has no 8-node quadrilateral")));
            }
            // Orientation: a part whose elements all run clockwise is mirrored; an element whose
            // Jacobian is not of one strict sign at every Gauss point is refused.
            let mut elements = Vec::with_capacity(part.elements.len());
            // The part's orientation is its majority's: the elements running the other way are
            // the inverted ones.
            let clockwise_count = part
                .elements
                .iter()
                .filter(|el| {
                    let x: [[f64; 2]; 8] = std::array::from_fn(|k| m.nodes[el[k]]);
                    jacobians(&x)[4].0 < 0.0
                })
                .count();
            let mut clockwise = (0..part.elements.len())
                .find(|&e| {
                    let x: [[f64; 2]; 8] = std::array::from_fn(|k| m.nodes[part.elements[e][k]]);
                    (jacobians(&x)[4].0 < 0.0) == (2 * clockwise_count > part.elements.len())
                })
                .map(|e| (2 * clockwise_count > part.elements.len(), e));
            for (e, (el, &tag)) in part.elements.iter().zip(&part.element_tags).enumerate() {
                let x: [[f64; 2]; 8] = std::array::from_fn(|k| m.nodes[el[k]]);
                let area = {
                    let d = |a: usize, b: usize| dist(x[a], x[b]);
                    (d(0, 2) * d(1, 3)).max(f64::MIN_POSITIVE)
                };
                let dets = jacobians(&x);
                let negative = dets.iter().all(|d| d.0 < -1e-12 * area);
                let positive = dets.iter().all(|d| d.0 > 1e-12 * area);
                if !(negative || positive) {
                    let worst = dets
                        .iter()
                        .copied()
                        .min_by(|a, b| (a.0 * if negative { -1.0 } else { 1.0 }).total_cmp(&b.0))
                        .unwrap_or((0.0, 0.0, 0.0));
                    let bad = dets
                        .iter()
                        .find(|d| d.0.abs() <= 1e-12 * area || d.0.signum() != dets[0].0.signum());
                    let (det, xi, eta) = bad.copied().unwrap_or(worst);
                    return Err(self.err(
                        key,
                        format!(
                            "{who}: element {tag} is inverted or degenerate: det J = {det:.3e} at the Gauss point \
                             (ξ, η) = ({xi:.3}, {eta:.3}) (its Jacobian must keep one strict sign over the element; \
                             corner nodes {}, {}, {}, {})",
                            node_tag(el[0]),
                            node_tag(el[1]),
                            node_tag(el[2]),
                            node_tag(el[3])
                        ),
                    ));
                }
                match clockwise {
                    None => clockwise = Some((negative, e)),
                    Some((cw, first)) if cw != negative => {
                        return Err(self.err(
                            key,
                            format!(
                                "{who}: element {tag} is inverted: it runs {} while element {} of the same part \
                                 runs {}",
                                if negative { "clockwise" } else { "counter-clockwise" },
                                part.element_tags[first],
                                if cw { "clockwise" } else { "counter-clockwise" }
                            ),
                        ))
                    }
                    _ => {}
                }
                elements.push(if negative { reversed(*el) } else { *el });
            }
            // Local numbering row by row: by y (on a grid of 1e-6 of the mesh's size), then x; a
            // rectangle meshed by Gmsh is then numbered as the block mesher numbers it.
            let mut global: Vec<usize> = elements.iter().flatten().copied().collect();
            global.sort_unstable();
            global.dedup();
            let row = |n: usize| (m.nodes[n][1] / (1e-6 * size)).round() as i64;
            global.sort_by(|&p, &q| row(p).cmp(&row(q)).then(m.nodes[p][0].total_cmp(&m.nodes[q][0])));
            let local: HashMap<usize, usize> = global.iter().enumerate().map(|(i, &n)| (n, i)).collect();
            let local_elements: Vec<[usize; 8]> = elements.iter().map(|el| el.map(|n| local[&n])).collect();
            let coords: Vec<[f64; 2]> = global.iter().map(|&n| m.nodes[n]).collect();
            // Duplicate nodes: two nodes of the part at one position.
            let mut grid = Grid::new(10.0 * tol);
            for (i, &x) in coords.iter().enumerate() {
                if let Some(j) = grid.near(x).find(|&j| dist(coords[j], x) <= tol) {
                    return Err(self.err(
                        key,
                        format!(
                            "{who}: nodes {} and {} are duplicates (both at {}): merge them (Gmsh: \
                             Geometry.Tolerance and Coherence, or Mesh.SaveAll = 0 without duplicated entities)",
                            node_tag(global[j]),
                            node_tag(global[i]),
                            at(x)
                        ),
                    ));
                }
                grid.insert(x, i);
            }
            // One piece: elements connected through shared edges (parts touching at a node only
            // are hinges, not one body).
            let mut parent: Vec<usize> = (0..local_elements.len()).collect();
            fn root(parent: &mut [usize], mut i: usize) -> usize {
                while parent[i] != i {
                    parent[i] = parent[parent[i]];
                    i = parent[i];
                }
                i
            }
            let mut owner: HashMap<(usize, usize), usize> = HashMap::new();
            for (e, el) in local_elements.iter().enumerate() {
                for side in SIDES {
                    let (a, b) = (el[side[0]], el[side[2]]);
                    match owner.get(&(a.min(b), a.max(b))) {
                        None => {
                            owner.insert((a.min(b), a.max(b)), e);
                        }
                        Some(&o) => {
                            let (ra, rb) = (root(&mut parent, o), root(&mut parent, e));
                            if ra != rb {
                                parent[ra.max(rb)] = ra.min(rb);
                            }
                        }
                    }
                }
            }
            if let Some(e) = (0..local_elements.len()).find(|&e| root(&mut parent, e) != 0) {
                return Err(self.err(
                    key,
                    format!(
                        "{who} is in several pieces: element {} is not connected to element {} (a subdomain \
                         is one connected part: give each piece its own physical surface)",
                        part.element_tags[e], part.element_tags[0]
                    ),
                ));
            }
            // Boundary edges: element sides used once.
            let mut count: HashMap<(usize, usize), usize> = HashMap::new();
            for el in &local_elements {
                for side in SIDES {
                    let (a, b) = (el[side[0]], el[side[2]]);
                    *count.entry((a.min(b), a.max(b))).or_default() += 1;
                }
            }
            let mut edges = Vec::new();
            for el in &local_elements {
                for side in SIDES {
                    let (a, b) = (el[side[0]], el[side[2]]);
                    if count[&(a.min(b), a.max(b))] == 1 {
                        edges.push(Edge {
                            nodes: [el[side[0]], el[side[1]], el[side[2]]],
                        });
                    }
                }
            }
            // A boundary that passes twice through a node: the part touches itself there.
            let mut starts: HashMap<usize, usize> = HashMap::new();
            for e in &edges {
                *starts.entry(e.nodes[0]).or_default() += 1;
            }
            if let Some((&n, _)) = starts.iter().filter(|(_, &c)| c > 1).min_by_key(|(&n, _)| n) {
                return Err(self.err(
                    key,
                    format!(
                        "{who} touches itself at node {} {}: its boundary passes twice through that node \
                         (a hinge); mesh it so that the part is joined along edges there, or make two parts",
                        node_tag(global[n]),
                        at(coords[n])
                    ),
                ));
            }
            let (mut blo, mut bhi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for x in &coords {
                blo = [blo[0].min(x[0]), blo[1].min(x[1])];
                bhi = [bhi[0].max(x[0]), bhi[1].max(x[1])];
            }
            boxes.push(([blo[0], bhi[0]], [blo[1], bhi[1]]));
            meshes.push(Mesh {
                coords,
                elements: local_elements,
                sides: Vec::new(),
            });
            boundary.push(edges);
            globals.push(global);
        }

        // Boundary edges of every part by the position of their middle node.
        let mut by_mid = Grid::new(10.0 * tol);
        let mut edge_ids = Vec::new();
        for (s, edges) in boundary.iter().enumerate() {
            for (k, e) in edges.iter().enumerate() {
                by_mid.insert(meshes[s].coords[e.nodes[1]], edge_ids.len());
                edge_ids.push((s, k));
            }
        }
        let x_of = |s: usize, n: usize| meshes[s].coords[n];
        let edge_x = |s: usize, e: &Edge| -> [[f64; 2]; 3] { e.nodes.map(|n| x_of(s, n)) };
        // Matched edges per part pair (a < b): (edge of a, edge of b).
        let mut matched: BTreeMap<(usize, usize), Vec<(usize, usize)>> = BTreeMap::new();
        let mut is_matched: Vec<Vec<bool>> = boundary.iter().map(|e| vec![false; e.len()]).collect();
        for (id, &(s, k)) in edge_ids.iter().enumerate() {
            let e = &boundary[s][k];
            let x = edge_x(s, e);
            for other in by_mid.near(x[1]) {
                let (t, j) = edge_ids[other];
                if other <= id || t == s {
                    continue;
                }
                let f = &boundary[t][j];
                let y = edge_x(t, f);
                if dist(x[1], y[1]) > tol {
                    continue;
                }
                // The neighbour runs the other way along the shared edge.
                if dist(x[0], y[2]) > tol || dist(x[2], y[0]) > tol {
                    let p = if dist(x[0], y[2]) > tol { x[0] } else { x[2] };
                    return Err(self.err(
                        key,
                        format!(
                            "{}: parts `{}` and `{}` do not conform along their shared curve near {}: their element \
                             edges share a middle node but not their ends (mesh both parts with the same nodes on \
                             the shared curve)",
                            m.origin,
                            m.parts[s].name,
                            m.parts[t].name,
                            at(p)
                        ),
                    ));
                }
                is_matched[s][k] = true;
                is_matched[t][j] = true;
                let (a, b, ea, eb) = if s < t { (s, t, k, j) } else { (t, s, j, k) };
                matched.entry((a, b)).or_default().push((ea, eb));
            }
        }
        // Non-conforming contact: a node of an unmatched boundary edge on another part's unmatched
        // boundary edge.
        let mut loose: Vec<(usize, usize, [f64; 2], [f64; 2])> = Vec::new(); // (part, edge, box lo, hi)
        for (s, edges) in boundary.iter().enumerate() {
            for (k, e) in edges.iter().enumerate() {
                if is_matched[s][k] {
                    continue;
                }
                let x = edge_x(s, e);
                let lo = [
                    x.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min),
                    x.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min),
                ];
                let hi = [
                    x.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max),
                    x.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max),
                ];
                loose.push((s, k, lo, hi));
            }
        }
        // Cells as large as the largest loose edge: an edge's centre is then in a cell next to
        // the cell of any point on it.
        let cell = loose
            .iter()
            .fold(tol, |c, l| c.max(l.3[0] - l.2[0]).max(l.3[1] - l.2[1]));
        let mut loose_grid = Grid::new(cell);
        for (i, l) in loose.iter().enumerate() {
            loose_grid.insert([0.5 * (l.2[0] + l.3[0]), 0.5 * (l.2[1] + l.3[1])], i);
        }
        let near_tol = 1e-7 * size;
        for &(s, k, _, _) in &loose {
            for (own, &n) in boundary[s][k].nodes.iter().enumerate() {
                let p = x_of(s, n);
                for other in loose_grid.near(p) {
                    let (t, j, lo, hi) = loose[other];
                    if t == s
                        || p[0] < lo[0] - near_tol
                        || p[0] > hi[0] + near_tol
                        || p[1] < lo[1] - near_tol
                        || p[1] > hi[1] + near_tol
                    {
                        continue;
                    }
                    let y = edge_x(t, &boundary[t][j]);
                    // Edges meeting end to end (at a corner of both) conform; an end on the other's
                    // middle node, or a middle node on its end, is half an element off.
                    if own != 1 && (dist(y[0], p) <= tol || dist(y[2], p) <= tol) {
                        continue;
                    }
                    if distance_to_edge(&y, p) <= near_tol {
                        return Err(self.err(
                            key,
                            format!(
                                "{}: parts `{}` and `{}` touch along a curve near {} but their meshes do not conform \
                                 there: node {} of `{}` lies on an element edge of `{}` that has no node there \
                                 (mesh both parts with the same nodes on the shared curve: one curve entity shared \
                                 by both surfaces)",
                                m.origin,
                                m.parts[s].name,
                                m.parts[t].name,
                                at(p),
                                node_tag(globals[s][n]),
                                m.parts[s].name,
                                m.parts[t].name
                            ),
                        ));
                    }
                }
            }
        }

        // Named curves: which boundary edges lie on them (by middle node position).
        let mut edge_curves: Vec<Vec<Vec<usize>>> = boundary.iter().map(|e| vec![Vec::new(); e.len()]).collect();
        for (c, (_, edges)) in m.curves.iter().enumerate() {
            for e in edges {
                let mid = m.nodes[e[1]];
                for id in by_mid.near(mid) {
                    let (s, k) = edge_ids[id];
                    let x = edge_x(s, &boundary[s][k]);
                    let ends = [m.nodes[e[0]], m.nodes[e[2]]];
                    let same = dist(x[1], mid) <= tol
                        && ((dist(x[0], ends[0]) <= tol && dist(x[2], ends[1]) <= tol)
                            || (dist(x[0], ends[1]) <= tol && dist(x[2], ends[0]) <= tol));
                    if same && !edge_curves[s][k].contains(&c) {
                        edge_curves[s][k].push(c);
                    }
                }
            }
        }

        let mut interfaces = Vec::with_capacity(matched.len());
        for ((a, b), edges) in matched {
            let itf = part_interface(&meshes, &boundary, &edge_curves, a, b, &edges).map_err(|n| {
                self.err(
                    key,
                    format!(
                        "{}: part `{}`: the edges of its interface with `{}` give no normal at node {} {}: an \
                         edge's middle node is too far from the middle of its ends (its tangent vanishes or turns \
                         back at the node)",
                        m.origin,
                        m.parts[a].name,
                        m.parts[b].name,
                        node_tag(globals[a][n]),
                        at(meshes[a].coords[n])
                    ),
                )
            })?;
            interfaces.push(itf);
        }
        Ok(PartGeometry {
            meshes,
            boundary,
            edge_curves,
            on_interface: is_matched,
            interfaces,
            tol,
            boxes,
        })
    }
}

/// The interface of parts a < b from their matched edges: pairs ordered along chains of a's
/// edges, weights and normals from a's isoparametric edges.
fn part_interface(
    meshes: &[Mesh],
    boundary: &[Vec<Edge>],
    edge_curves: &[Vec<Vec<usize>>],
    a: usize,
    b: usize,
    edges: &[(usize, usize)],
) -> Result<GeoInterface, usize> {
    let ea: Vec<Edge> = edges.iter().map(|&(k, _)| boundary[a][k]).collect();
    // Node of b facing each node of a's matched edges.
    let mut partner: HashMap<usize, usize> = HashMap::new();
    for &(k, j) in edges {
        let (x, y) = (boundary[a][k].nodes, boundary[b][j].nodes);
        partner.insert(x[0], y[2]);
        partner.insert(x[1], y[1]);
        partner.insert(x[2], y[0]);
    }
    // Chains: a's edges run with a on their left, end to start.
    let mut by_start: HashMap<usize, usize> = HashMap::new();
    let mut ends = std::collections::HashSet::new();
    for (i, e) in ea.iter().enumerate() {
        by_start.insert(e.nodes[0], i);
        ends.insert(e.nodes[2]);
    }
    let mut used = vec![false; ea.len()];
    let mut order: Vec<usize> = Vec::with_capacity(2 * ea.len() + 1);
    let mut starts: Vec<usize> = (0..ea.len()).filter(|&i| !ends.contains(&ea[i].nodes[0])).collect();
    starts.sort_by_key(|&i| ea[i].nodes[0]);
    // Closed loops after the open chains, each from its lowest node.
    let mut rest: Vec<usize> = (0..ea.len()).collect();
    rest.sort_by_key(|&i| ea[i].nodes[0]);
    for first in starts.into_iter().chain(rest) {
        if used[first] {
            continue;
        }
        let closed = ends.contains(&ea[first].nodes[0]);
        let chain_start = order.len();
        let mut i = first;
        order.push(ea[i].nodes[0]);
        loop {
            used[i] = true;
            order.push(ea[i].nodes[1]);
            let end = ea[i].nodes[2];
            match by_start.get(&end) {
                Some(&next) if !used[next] => {
                    order.push(end);
                    i = next;
                }
                _ => {
                    if !closed {
                        order.push(end);
                    }
                    break;
                }
            }
        }
        // An open chain runs from its end of smaller x (of smaller y where both ends share x):
        // along +x or +y on a straight interface, as the block scenes order their pairs.
        if !closed {
            let (p, q) = (
                meshes[a].coords[order[chain_start]],
                meshes[a].coords[order[order.len() - 1]],
            );
            if runs_backwards(p, q) {
                order[chain_start..].reverse();
            }
        }
    }
    let mut pair_of: HashMap<usize, usize> = HashMap::new();
    for (p, &n) in order.iter().enumerate() {
        pair_of.entry(n).or_insert(p);
    }
    let np = pair_of.len();
    let mut nodes = vec![usize::MAX; np];
    for (&n, &p) in &pair_of {
        nodes[p] = n;
    }
    let mut weights = vec![0.0; np];
    let mut normal_sum = vec![[0.0; 2]; np];
    let mut length = 0.0;
    let mut curves: Vec<usize> = Vec::new();
    // Edges in the pairs' order, each along it (the block scenes sum their weights and length so,
    // and the same sums give the same bits).
    // (middle pair, nodes along the pairs' order, reversed from a's own way round).
    let mut ordered: Vec<(usize, [usize; 3], bool)> = edges
        .iter()
        .map(|&(k, _)| {
            let n = boundary[a][k].nodes;
            let (p0, p2) = (pair_of[&n[0]], pair_of[&n[2]]);
            // The edge closing a loop runs from the last pair to the first: keep its way.
            let reversed = p0.abs_diff(p2) == 2 && p2 < p0;
            let along = if reversed { [n[2], n[1], n[0]] } else { n };
            (pair_of[&n[1]], along, reversed)
        })
        .collect();
    ordered.sort_by_key(|e| e.0);
    for &(k, _) in edges {
        for &c in &edge_curves[a][k] {
            if !curves.contains(&c) {
                curves.push(c);
            }
        }
    }
    for &(_, e, reversed) in &ordered {
        let x = e.map(|n| meshes[a].coords[n]);
        let m = edge_lumped_mass(&x);
        // The edge's outward normal out of a: (t_y, −t_x) for a's own way round, reversed if the
        // edge runs the other way here.
        let sign = if reversed { -1.0 } else { 1.0 };
        for (j, &n) in e.iter().enumerate() {
            let p = pair_of[&n];
            weights[p] += m[j];
            let (_, t, _) = edge_frame(&x, -1.0 + j as f64);
            normal_sum[p][0] += sign * t[1];
            normal_sum[p][1] -= sign * t[0];
        }
        // A straight edge (middle node at the chord's middle) measures its chord, as the block
        // mesher's edges do; a curved one its arc (Gauss).
        let chord = ((x[2][0] - x[0][0]).powi(2) + (x[2][1] - x[0][1]).powi(2)).sqrt();
        let middle = [0.5 * (x[0][0] + x[2][0]) - x[1][0], 0.5 * (x[0][1] + x[2][1]) - x[1][1]];
        let straight = middle[0].abs().max(middle[1].abs()) <= 1e-12 * chord;
        length += if straight { chord } else { m.iter().sum::<f64>() };
    }
    // Each edge adds a unit normal at its node: a sum far below one means edges that turn back
    // (or a tangent that vanishes, a NaN).
    let mut normals = Vec::with_capacity(np);
    for (p, n) in normal_sum.iter().enumerate() {
        let l = (n[0] * n[0] + n[1] * n[1]).sqrt();
        if l.is_nan() || l <= 1e-6 {
            return Err(nodes[p]);
        }
        normals.push([n[0] / l, n[1] / l]);
    }
    Ok(GeoInterface {
        a,
        b,
        normals,
        pairs: nodes.iter().map(|&n| (n, partner[&n])).collect(),
        coords: nodes.iter().map(|&n| meshes[a].coords[n]).collect(),
        weights,
        length,
        curves,
    })
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
        let geometry = self.part_geometry(&pm)?;
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
        let curve_names: Vec<String> = pm.curves.iter().map(|(n, _)| n.clone()).collect();
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

/// Copies of one node pair in several interfaces (where a curve of contact is cut by the parts'
/// boundaries) get one normal: the normalised sum of the copies' normals that point the same way
/// to within 30°, so that the copies obey one contact law and the monolithic reference can merge
/// them. Copies across the cut (a perpendicular interface's end) keep their own normal.
fn harmonise_normals(geo: &mut [GeoInterface], tol: f64) {
    let mut grid = Grid::new(10.0 * tol);
    let mut ids = Vec::new();
    for (k, g) in geo.iter().enumerate() {
        for p in 0..g.pairs.len() {
            grid.insert(g.coords[p], ids.len());
            ids.push((k, p));
        }
    }
    let cos30 = 0.866;
    let mut updates = Vec::new();
    for &(k, p) in &ids {
        let n0 = geo[k].normals[p];
        let mut sum = [0.0; 2];
        let mut copies = 0;
        for other in grid.near(geo[k].coords[p]) {
            let (j, q) = ids[other];
            if dist(geo[j].coords[q], geo[k].coords[p]) > tol {
                continue;
            }
            let n = geo[j].normals[q];
            let d = n[0] * n0[0] + n[1] * n0[1];
            if d.abs() >= cos30 {
                let sign = d.signum();
                sum[0] += sign * n[0];
                sum[1] += sign * n[1];
                copies += 1;
            }
        }
        if copies > 1 {
            let l = (sum[0] * sum[0] + sum[1] * sum[1]).sqrt();
            updates.push((k, p, [sum[0] / l, sum[1] / l]));
        }
    }
    for (k, p, n) in updates {
        geo[k].normals[p] = n;
    }
}
