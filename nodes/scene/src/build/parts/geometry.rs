//! The checks of every part of an imported mesh (orientation, Jacobian, one piece, no duplicate
//! nodes, no hinge) and the matching of the boundary edges two parts share, with the refusal of
//! meshes that do not conform along a shared curve.

use super::interface::{part_interface, part_interface_non_matching, NonMatchingError};
use super::*;
use glissade_mechanics::element::{edge_frame, jacobian, GAUSS3};

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

/// The point of the quadratic edge `x` nearest to `p` and its distance (sampled, then Newton).
/// A part's boundary edge not matched node by node: (part, edge, box lo, box hi).
type Loose = (usize, usize, [f64; 2], [f64; 2]);

/// The boundary edges not matched yet, and a grid of their centres whose cells are as large as
/// the largest of them plus `reach`: an edge's centre is then in a cell next to the cell of any
/// point within `reach` of it.
fn loose_edges(
    boundary: &[Vec<Edge>],
    is_matched: &[Vec<bool>],
    edge_x: &dyn Fn(usize, &Edge) -> [[f64; 2]; 3],
    reach: f64,
) -> (Vec<Loose>, Grid) {
    let mut loose = Vec::new();
    for (s, edges) in boundary.iter().enumerate() {
        for (k, e) in edges.iter().enumerate() {
            if !is_matched[s][k] {
                let (lo, hi) = edge_box(&edge_x(s, e));
                loose.push((s, k, lo, hi));
            }
        }
    }
    let cell = reach
        + loose
            .iter()
            .fold(reach, |c, l| c.max(l.3[0] - l.2[0]).max(l.3[1] - l.2[1]));
    let mut grid = Grid::new(cell);
    for (i, l) in loose.iter().enumerate() {
        grid.insert([0.5 * (l.2[0] + l.3[0]), 0.5 * (l.2[1] + l.3[1])], i);
    }
    (loose, grid)
}

/// Bounding box of an edge's three nodes.
fn edge_box(x: &[[f64; 2]; 3]) -> ([f64; 2], [f64; 2]) {
    let lo = [
        x.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min),
        x.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min),
    ];
    let hi = [
        x.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max),
        x.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max),
    ];
    (lo, hi)
}

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
    /// `match_tolerance`: the scene's `mesh.match_tolerance` (mm), the distance within which two
    /// parts' boundary edges without common nodes face each other (a non-matching interface);
    /// 1e-4 × the mesh's size by default.
    pub(crate) fn part_geometry(&self, m: &PartMesh, match_tolerance: Option<f64>) -> Result<PartGeometry, SceneError> {
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
        // The edges inside each part (shared by two of its elements): (part, end, middle, end).
        let mut inner_edges: Vec<(usize, [[f64; 2]; 3])> = Vec::new();
        for (s, part) in m.parts.iter().enumerate() {
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
                    // Where the sign changes, both signs are named (a positive det J alone reads as
                    // no fault).
                    let (d0, xi0, eta0) = dets[0];
                    let at = if det.abs() > 1e-12 * area && det.signum() != d0.signum() {
                        format!(
                            "det J = {d0:.3e} at the Gauss point (ξ, η) = ({xi0:.3}, {eta0:.3}) but {det:.3e} at \
                             ({xi:.3}, {eta:.3})"
                        )
                    } else {
                        format!("det J = {det:.3e} at the Gauss point (ξ, η) = ({xi:.3}, {eta:.3})")
                    };
                    return Err(self.err(
                        key,
                        format!(
                            "{who}: element {tag} is inverted or degenerate: {at} (its Jacobian must keep one \
                             strict sign over the element; corner nodes {}, {}, {}, {})",
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
            let mut owner: HashMap<(usize, usize), usize> = HashMap::new();
            let mut joined = Vec::new();
            for (e, el) in local_elements.iter().enumerate() {
                for side in SIDES {
                    let (a, b) = (el[side[0]], el[side[2]]);
                    match owner.get(&(a.min(b), a.max(b))) {
                        None => {
                            owner.insert((a.min(b), a.max(b)), e);
                        }
                        Some(&o) => joined.push((o, e)),
                    }
                }
            }
            // The first element not connected to element 0: the smallest of the second group.
            if let Some(e) = crate::build::connected_groups(local_elements.len(), joined)
                .get(1)
                .map(|g| g[0])
            {
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
                    } else if a < b && !m.curves.is_empty() {
                        // Once per inner edge (its two elements run along it in opposite ways).
                        inner_edges.push((s, side.map(|k| coords[el[k]])));
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
                // The neighbour runs the other way along the shared edge. Edges that share only
                // their middle node (meshes of different sizes whose middles happen to meet) are
                // not matched here: they face each other as a non-matching interface, or are
                // refused below.
                if dist(x[0], y[2]) > tol || dist(x[2], y[0]) > tol {
                    continue;
                }
                is_matched[s][k] = true;
                is_matched[t][j] = true;
                let (a, b, ea, eb) = if s < t { (s, t, k, j) } else { (t, s, j, k) };
                matched.entry((a, b)).or_default().push((ea, eb));
            }
        }
        // Parts meshed on their own: an unmatched boundary edge whose three nodes lie within
        // `match_tol` of another part's unmatched boundary edges faces that part.
        let match_tol = match_tolerance.unwrap_or(1e-4 * size);
        if !(match_tol.is_finite() && match_tol > 0.0) {
            return Err(self.err(
                "mesh.match_tolerance",
                format!("{match_tol} mm: the distance within which parts face each other must be a finite number > 0"),
            ));
        }
        // ((part, its edges), (other part, its edges)) per pair of parts facing each other.
        let mut facing_groups: Vec<[(usize, Vec<usize>); 2]> = Vec::new();
        {
            let (loose, grid) = loose_edges(&boundary, &is_matched, &edge_x, tol.max(match_tol));
            // (a < b) → (edges of a facing b, edges of b facing a).
            let mut facing: BTreeMap<(usize, usize), (Vec<usize>, Vec<usize>)> = BTreeMap::new();
            for &(s, k, _, _) in &loose {
                let x = edge_x(s, &boundary[s][k]);
                // The parts whose loose edges hold each node, within match_tol.
                let holders = |p: [f64; 2]| -> Vec<usize> {
                    let mut parts: Vec<usize> = grid
                        .near(p)
                        .filter_map(|o| {
                            let (t, j, lo, hi) = loose[o];
                            let inside = p[0] >= lo[0] - match_tol
                                && p[0] <= hi[0] + match_tol
                                && p[1] >= lo[1] - match_tol
                                && p[1] <= hi[1] + match_tol;
                            (t != s && inside && distance_to_edge(&edge_x(t, &boundary[t][j]), p) <= match_tol)
                                .then_some(t)
                        })
                        .collect();
                    parts.sort_unstable();
                    parts.dedup();
                    parts
                };
                let (h0, h1, h2) = (holders(x[0]), holders(x[1]), holders(x[2]));
                // An edge that does not face one part along its length but has a node inside
                // another part's edge (away from that edge's ends) crosses the end of the curve
                // they share: the interface would stop short of it.
                let facing_one = h0.iter().any(|t| h1.contains(t) && h2.contains(t));
                if !facing_one {
                    // (node, the part whose edge holds it inside).
                    let inside_edge = x.iter().find_map(|&p| {
                        grid.near(p).find_map(|o| {
                            let (t, j, _, _) = loose[o];
                            let y = edge_x(t, &boundary[t][j]);
                            (t != s
                                && distance_to_edge(&y, p) <= match_tol
                                && dist(y[0], p) > match_tol
                                && dist(y[2], p) > match_tol)
                                .then_some((p, t))
                        })
                    });
                    if let (Some((p, t)), false) = (inside_edge, !h0.is_empty() && !h1.is_empty() && !h2.is_empty()) {
                        return Err(self.err(
                            key,
                            format!(
                                "{}: parts `{}` and `{}` do not conform near {}: an element edge of `{}` crosses the \
                                 end of the curve they share (its node there lies inside an edge of `{}`, the rest of \
                                 it off `{}`; mesh both parts so that their edges end at the same points there, or \
                                 share their nodes)",
                                m.origin,
                                m.parts[s].name,
                                m.parts[t].name,
                                at(p),
                                m.parts[s].name,
                                m.parts[t].name,
                                m.parts[t].name
                            ),
                        ));
                    }
                }
                if !h0.is_empty()
                    && !h1.is_empty()
                    && !h2.is_empty()
                    && !h0.iter().any(|t| h1.contains(t) && h2.contains(t))
                {
                    let mut others: Vec<&str> = h0
                        .iter()
                        .chain(&h1)
                        .chain(&h2)
                        .map(|&t| m.parts[t].name.as_str())
                        .collect();
                    others.sort_unstable();
                    others.dedup();
                    return Err(self.err(
                        key,
                        format!(
                            "{}: an element edge of part `{}` near {} faces the parts {} at once: a non-matching \
                             interface joins two parts, so the parts on either side of a curve they share must \
                             end at the same points (or share their nodes there)",
                            m.origin,
                            m.parts[s].name,
                            at(x[1]),
                            others
                                .iter()
                                .map(|n| format!("`{n}`"))
                                .collect::<Vec<_>>()
                                .join(" and ")
                        ),
                    ));
                }
                for t in h0 {
                    if h1.contains(&t) && h2.contains(&t) {
                        let entry = facing.entry((s.min(t), s.max(t))).or_default();
                        if s < t {
                            entry.0.push(k);
                        } else {
                            entry.1.push(k);
                        }
                    }
                }
            }
            for ((p, q), (ep, eq)) in facing {
                if ep.is_empty() || eq.is_empty() {
                    continue;
                }
                for (s, edges) in [(p, &ep), (q, &eq)] {
                    for &k in edges {
                        is_matched[s][k] = true;
                    }
                }
                facing_groups.push([(p, ep), (q, eq)]);
            }
        }
        // Non-conforming contact: a node of an unmatched boundary edge on another part's unmatched
        // boundary edge.
        let near_tol = 1e-7 * size;
        let (loose, loose_grid) = loose_edges(&boundary, &is_matched, &edge_x, tol.max(near_tol));
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

        // Named curves: which boundary edges lie on them (by middle node position), and which of
        // their elements lie inside a part instead.
        let on_curve_edge = |x: &[[f64; 2]; 3], e: &[usize; 3]| {
            let ends = [m.nodes[e[0]], m.nodes[e[2]]];
            dist(x[1], m.nodes[e[1]]) <= tol
                && ((dist(x[0], ends[0]) <= tol && dist(x[2], ends[1]) <= tol)
                    || (dist(x[0], ends[1]) <= tol && dist(x[2], ends[0]) <= tol))
        };
        let mut inner_by_mid = Grid::new(10.0 * tol);
        for (i, (_, x)) in inner_edges.iter().enumerate() {
            inner_by_mid.insert(x[1], i);
        }
        let mut edge_curves: Vec<Vec<Vec<usize>>> = boundary.iter().map(|e| vec![Vec::new(); e.len()]).collect();
        let mut curve_inside = Vec::with_capacity(m.curves.len());
        for (c, curve) in m.curves.iter().enumerate() {
            let mut inside = None;
            for (e, &tag) in curve.edges.iter().zip(&curve.element_tags) {
                let mid = m.nodes[e[1]];
                for id in by_mid.near(mid) {
                    let (s, k) = edge_ids[id];
                    if on_curve_edge(&edge_x(s, &boundary[s][k]), e) && !edge_curves[s][k].contains(&c) {
                        edge_curves[s][k].push(c);
                    }
                }
                if inside.is_none() {
                    inside = inner_by_mid
                        .near(mid)
                        .find(|&i| on_curve_edge(&inner_edges[i].1, e))
                        .map(|i| CurveInside {
                            element: tag,
                            nodes: [e[0], e[2], e[1]].map(node_tag),
                            part: inner_edges[i].0,
                        });
                }
            }
            curve_inside.push(inside);
        }

        // The non-matching interfaces of the parts that face each other.
        let mut non_matching: Vec<GeoInterface> = Vec::new();
        for [(p, ep), (q, eq)] in facing_groups {
            // The coarser side carries the interface (docs/method.md, "Non-matching interfaces"): the other, if it is not
            // covered.
            let sides = if ep.len() <= eq.len() {
                [((p, &ep), (q, &eq)), ((q, &eq), (p, &ep))]
            } else {
                [((q, &eq), (p, &ep)), ((p, &ep), (q, &eq))]
            };
            let mut built = None;
            let mut why = String::new();
            for ((a, ea), (b, eb)) in sides {
                match part_interface_non_matching(&meshes, &boundary, &edge_curves, (a, ea), (b, eb), self.plane) {
                    Ok(g) => {
                        built = Some(g);
                        break;
                    }
                    Err(NonMatchingError::Normal(n)) => {
                        why = format!(
                            "no normal at node {} {}",
                            node_tag(globals[a][n]),
                            at(meshes[a].coords[n])
                        );
                    }
                    Err(NonMatchingError::Projection(e)) => {
                        if why.is_empty() {
                            why = e.to_string();
                        }
                    }
                }
            }
            let Some(g) = built else {
                return Err(self.err(
                    key,
                    format!(
                        "{}: parts `{}` and `{}` face each other along a curve but their meshes match neither \
                         node by node nor as a non-matching interface: {why} (a non-matching interface needs \
                         one side whose edges the other's cover from end to end)",
                        m.origin, m.parts[p].name, m.parts[q].name
                    ),
                ));
            };
            non_matching.push(g);
        }

        let mut interfaces = Vec::with_capacity(matched.len());
        for ((a, b), edges) in matched {
            let itf = part_interface(&meshes, &boundary, &edge_curves, a, b, &edges, self.plane).map_err(|n| {
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
        interfaces.extend(non_matching);
        Ok(PartGeometry {
            meshes,
            boundary,
            edge_curves,
            curve_inside,
            on_interface: is_matched,
            interfaces,
            tol,
            boxes,
        })
    }
}
