//! Interfaces from the edges two parts share: pairs ordered along chains of edges, weights,
//! length and normals; and one normal for the copies of a node pair in several interfaces.

use super::*;
use glissade_mechanics::element::edge_frame;

/// The interface of parts a < b from their matched edges: pairs ordered along chains of a's
/// edges, weights (against `plane`'s measure) and normals from a's isoparametric edges.
pub(super) fn part_interface(
    meshes: &[Mesh],
    boundary: &[Vec<Edge>],
    edge_curves: &[Vec<Vec<usize>>],
    a: usize,
    b: usize,
    edges: &[(usize, usize)],
    plane: Plane,
) -> Result<GeoInterface, usize> {
    // Node of b facing each node of a's matched edges.
    let mut partner: HashMap<usize, usize> = HashMap::new();
    for &(k, j) in edges {
        let (x, y) = (boundary[a][k].nodes, boundary[b][j].nodes);
        partner.insert(x[0], y[2]);
        partner.insert(x[1], y[1]);
        partner.insert(x[2], y[0]);
    }
    let a_edges: Vec<usize> = edges.iter().map(|&(k, _)| k).collect();
    let mut g = chain_interface(meshes, boundary, a, b, &a_edges, plane)?;
    for pair in g.pairs.iter_mut() {
        pair.1 = partner[&pair.0];
    }
    for &(k, _) in edges {
        for &c in &edge_curves[a][k] {
            if !g.curves.contains(&c) {
                g.curves.push(c);
            }
        }
    }
    Ok(g)
}

/// The non-matching interface of part a's edges `a_edges` with part b's edges `b_edges` that face
/// them (docs/method.md, "Non-matching interfaces"): the pairs are a's nodes, b reaches them through its
/// projection; the named curves are those of both sides' edges. Err: a node of a without a
/// normal (as [`part_interface`]) or a's edges not covered by b's.
pub(super) fn part_interface_non_matching(
    meshes: &[Mesh],
    boundary: &[Vec<Edge>],
    edge_curves: &[Vec<Vec<usize>>],
    (a, a_edges): (usize, &[usize]),
    (b, b_edges): (usize, &[usize]),
    plane: Plane,
) -> Result<GeoInterface, NonMatchingError> {
    let mut g = chain_interface(meshes, boundary, a, b, a_edges, plane).map_err(NonMatchingError::Normal)?;
    let pair_of: HashMap<usize, usize> = g.pairs.iter().enumerate().map(|(p, &(n, _))| (n, p)).collect();
    let side = |s: usize, e: usize, nodes: [usize; 3]| glissade_mechanics::mortar::SideEdge {
        nodes,
        x: boundary[s][e].nodes.map(|n| meshes[s].coords[n]),
    };
    let a_side: Vec<_> = a_edges
        .iter()
        .map(|&k| side(a, k, boundary[a][k].nodes.map(|n| pair_of[&n])))
        .collect();
    let b_side: Vec<_> = b_edges.iter().map(|&j| side(b, j, boundary[b][j].nodes)).collect();
    let projection = glissade_mechanics::mortar::project(&a_side, &g.weights, &b_side, plane, &g.coords)
        .map_err(NonMatchingError::Projection)?;
    for (p, pair) in g.pairs.iter_mut().enumerate() {
        pair.1 = projection.largest_term(p);
    }
    g.projection = Some(projection);
    g.sides = Some((a_side, b_side));
    for (s, edges) in [(a, a_edges), (b, b_edges)] {
        for &k in edges {
            for &c in &edge_curves[s][k] {
                if !g.curves.contains(&c) {
                    g.curves.push(c);
                }
            }
        }
    }
    Ok(g)
}

/// Why a non-matching interface could not be built.
pub(super) enum NonMatchingError {
    /// Node of a without a normal.
    Normal(usize),
    Projection(glissade_mechanics::mortar::ProjectionError),
}

/// Pairs (a's nodes, b's left at usize::MAX), weights, normals, length of a's edges `a_edges`
/// ordered in chains.
fn chain_interface(
    meshes: &[Mesh],
    boundary: &[Vec<Edge>],
    a: usize,
    b: usize,
    a_edges: &[usize],
    plane: Plane,
) -> Result<GeoInterface, usize> {
    let ea: Vec<Edge> = a_edges.iter().map(|&k| boundary[a][k]).collect();
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
    // Edges in the pairs' order, each along it (the block scenes sum their weights and length so,
    // and the same sums give the same bits).
    // (middle pair, nodes along the pairs' order, reversed from a's own way round).
    let mut ordered: Vec<(usize, [usize; 3], bool)> = a_edges
        .iter()
        .map(|&k| {
            let n = boundary[a][k].nodes;
            let (p0, p2) = (pair_of[&n[0]], pair_of[&n[2]]);
            // The edge closing a loop runs from the last pair to the first: keep its way.
            let reversed = p0.abs_diff(p2) == 2 && p2 < p0;
            let along = if reversed { [n[2], n[1], n[0]] } else { n };
            (pair_of[&n[1]], along, reversed)
        })
        .collect();
    ordered.sort_by_key(|e| e.0);
    for &(_, e, reversed) in &ordered {
        let x = e.map(|n| meshes[a].coords[n]);
        let m = edge_lumped_mass(&x, plane);
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
        // mesher's edges do; a curved one its arc (Gauss: the plane weights' sum, whatever the
        // plane, as the length is a length in axisymmetry too).
        let chord = ((x[2][0] - x[0][0]).powi(2) + (x[2][1] - x[0][1]).powi(2)).sqrt();
        let middle = [0.5 * (x[0][0] + x[2][0]) - x[1][0], 0.5 * (x[0][1] + x[2][1]) - x[1][1]];
        let straight = middle[0].abs().max(middle[1].abs()) <= 1e-12 * chord;
        length += if straight {
            chord
        } else {
            edge_lumped_mass(&x, Plane::Strain).iter().sum::<f64>()
        };
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
        pairs: nodes.iter().map(|&n| (n, usize::MAX)).collect(),
        coords: nodes.iter().map(|&n| meshes[a].coords[n]).collect(),
        weights,
        length,
        curves: Vec::new(),
        projection: None,
        sides: None,
    })
}

/// Copies of one node pair in several interfaces (where a curve of contact is cut by the parts'
/// boundaries) get one normal: the normalised sum of the copies' normals that point the same way
/// to within 30°, so that the copies obey one contact law and the monolithic reference can merge
/// them. Copies across the cut (a perpendicular interface's end) keep their own normal.
pub(super) fn harmonise_normals(geo: &mut [GeoInterface], tol: f64) {
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
