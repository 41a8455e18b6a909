//! Non-matching interfaces (docs/method.md, "Non-matching interfaces"): the interface's own discretisation Γ_h
//! is side a's trace (its pairs are side a's nodes, its weights side a's lumped edge masses), and
//! side b's trace reaches it through the projection Π_b = M_Γ⁻¹ D_b, with
//! D_b[p, j] = ∫_Γ ψ_p N_j^b dΓ integrated exactly segment by segment: side b's edges are
//! intersected with side a's in side a's edge parameter, and each segment is integrated by Gauss
//! on side a's isoparametric edge, the point of side b facing each Gauss point found by its
//! closest point on b's edge. Each row of Π_b is divided by its own sum (∫ ψ_p where side b
//! covers side a, within 1e-6 of side a's lumped weight M_Γ), so that Π_b maps a rigid
//! translation of b to itself exactly.
//!
//! The test functions ψ_p are the dual basis of a's edge (Wohlmuth's biorthogonal multipliers):
//! on each edge ψ = A N with A = D_e M_e⁻¹ (M_e the edge's consistent mass, D_e its row sums), so
//! that ∫ ψ_p N_q = δ_pq ∫ N_p edge by edge. On the end edges of an open interface (where it
//! meets a support or another interface) ψ = N, the lumped projection. Both give, edge by edge,
//! ∫ ψ_p u = u_p ∫ N_p for every affine u and Σ_p ψ_p = 1, so M_Γ⁻¹ D_b reproduces affine fields
//! exactly and a uniform stress crosses any mesh ratio without error (the patch test); side b's
//! nodal forces are Π_bᵀ M_Γ F = D_bᵀ F, the consistent forces of the traction Σ ψ_p F_p.
//!
//! Where the end of an open interface is held by a support of side a or shared with another
//! interface, [`project_with_ends`] leaves its pair out (see there).
//!
//! Why the dual basis inside and not the lumped one everywhere: on the ring press fit meshed on
//! its own (48 against 40 elements around) the lumped projection leaves an oscillation of 0.7 % in
//! the contact pressure and takes 123 iterations against the conforming mesh's 48; the dual one
//! 0.09 % and 49. Why not at the ends: there the dual basis stagnated (the patch test with
//! clamped sides and an offset mesh, η stuck at 2.8e-6), the lumped one converges.

use crate::element::{edge_frame, edge_shape};
use crate::model::Plane;

/// Side b's trace at each pair of a non-matching interface: pair p sees
/// Σ_k `coefs[k]`·u_b(`nodes[k]`) for k in `start[p]..start[p + 1]`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Projection {
    pub start: Vec<usize>,
    pub nodes: Vec<usize>,
    pub coefs: Vec<f64>,
}

impl Projection {
    /// A projection of no pairs yet ([`Projection::push`] adds them).
    pub fn empty() -> Self {
        Projection {
            start: vec![0],
            nodes: Vec::new(),
            coefs: Vec::new(),
        }
    }

    /// Appends the next pair's (node, coefficient) terms.
    pub fn push(&mut self, terms: impl IntoIterator<Item = (usize, f64)>) {
        for (n, c) in terms {
            self.nodes.push(n);
            self.coefs.push(c);
        }
        self.start.push(self.nodes.len());
    }

    /// Number of pairs.
    pub fn n_pairs(&self) -> usize {
        self.start.len() - 1
    }

    /// (node of b, coefficient) of pair p.
    pub fn terms(&self, p: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.start[p]..self.start[p + 1];
        self.nodes[r.clone()].iter().copied().zip(self.coefs[r].iter().copied())
    }

    /// The projection with only the pairs `keep` (in that order).
    pub fn select(&self, keep: &[usize]) -> Self {
        let mut out = Projection::empty();
        for &p in keep {
            out.push(self.terms(p));
        }
        out
    }

    /// The node with the largest coefficient at pair p (a node under the pair's edges: the one a
    /// display names), usize::MAX for a pair without terms.
    pub fn largest_term(&self, p: usize) -> usize {
        self.terms(p)
            .fold(None::<(usize, f64)>, |best, (n, c)| match best {
                Some(b) if b.1 >= c => Some(b),
                _ => Some((n, c)),
            })
            .map_or(usize::MAX, |b| b.0)
    }
}

/// Σ coef·u(node) over `terms`, summed from the first term (so that (a, −1), (b, 1) gives
/// exactly u_b − u_a); 0 without terms.
pub fn combine(terms: impl IntoIterator<Item = (usize, f64)>, u: impl Fn(usize) -> f64) -> f64 {
    let mut terms = terms.into_iter();
    let Some((n, c)) = terms.next() else { return 0.0 };
    terms.fold(c * u(n), |acc, (n, c)| acc + c * u(n))
}

/// Per pair, whether it ends an open interface: it belongs to one of `a_edges` only (edges
/// carrying pair indices).
pub fn end_pairs(a_edges: &[SideEdge], n_pairs: usize) -> Vec<bool> {
    let mut edges_at = vec![0usize; n_pairs];
    for ea in a_edges {
        edges_at[ea.nodes[0]] += 1;
        edges_at[ea.nodes[2]] += 1;
    }
    edges_at.into_iter().map(|n| n == 1).collect()
}

/// Adds `v` to the term of `node` in a sparse row (appended if new).
fn accumulate(row: &mut Vec<(usize, f64)>, node: usize, v: f64) {
    match row.iter_mut().find(|(n, _)| *n == node) {
        Some(e) => e.1 += v,
        None => row.push((node, v)),
    }
}

/// One 3-node edge of a side: its nodes (pair indices on side a, mesh nodes on side b) and
/// coordinates, in the edge's own order.
#[derive(Debug, Clone, Copy)]
pub struct SideEdge {
    pub nodes: [usize; 3],
    pub x: [[f64; 2]; 3],
}

/// Why a projection cannot be built.
#[derive(Debug, Clone, PartialEq)]
pub enum ProjectionError {
    /// Side b does not cover side a at pair `pair` (at `at`): the fraction of its weight covered.
    Uncovered { pair: usize, at: [f64; 2], covered: f64 },
}

impl std::fmt::Display for ProjectionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ProjectionError::Uncovered { at, covered, .. } => write!(
                f,
                "the other side's edges cover only {:.1} % of the interface around ({}, {})",
                100.0 * covered,
                at[0],
                at[1]
            ),
        }
    }
}

impl std::error::Error for ProjectionError {}

/// Gauss–Legendre rule with 5 points on [−1, 1]: exact to degree 9, so the products of two
/// quadratic shape functions on straight edges (degree 4), times the axisymmetric 2πr (degree 5),
/// are integrated exactly.
const GAUSS5: [(f64, f64); 5] = [
    (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
    (-0.538_469_310_105_683, 0.478_628_670_499_366_5),
    (0.0, 0.568_888_888_888_888_9),
    (0.538_469_310_105_683, 0.478_628_670_499_366_5),
    (0.906_179_845_938_664, 0.236_926_885_056_189_1),
];

/// Position and derivative dx/ds of edge `x` at s ([`edge_frame`]'s tangent times |dx/ds|).
fn point(x: &[[f64; 2]; 3], s: f64) -> ([f64; 2], [f64; 2]) {
    let (p, t, jac) = edge_frame(x, s);
    (p, [t[0] * jac, t[1] * jac])
}

/// Lower and upper corners of the box of an edge's nodes.
fn bounding_box(x: &[[f64; 2]; 3]) -> ([f64; 2], [f64; 2]) {
    let lo = [0, 1].map(|c| x.iter().map(|p| p[c]).fold(f64::INFINITY, f64::min));
    let hi = [0, 1].map(|c| x.iter().map(|p| p[c]).fold(f64::NEG_INFINITY, f64::max));
    (lo, hi)
}

/// Side b's interpolation at point `q`: the shape functions of the b edge closest to q at its
/// closest point (nonzero terms only).
fn interpolation(b_edges: &[SideEdge], q: [f64; 2]) -> Vec<(usize, f64)> {
    let mut best: Option<(f64, usize, f64)> = None;
    for (k, eb) in b_edges.iter().enumerate() {
        let s = closest_parameter(&eb.x, q).clamp(-1.0, 1.0);
        let (p, _) = point(&eb.x, s);
        let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
        if best.is_none_or(|b| d < b.0) {
            best = Some((d, k, s));
        }
    }
    let Some((_, k, s)) = best else { return Vec::new() };
    let (n, _) = edge_shape(s);
    b_edges[k]
        .nodes
        .iter()
        .zip(n)
        .filter(|(_, c)| *c != 0.0)
        .map(|(&node, c)| (node, c))
        .collect()
}

/// The parameter s of the point of edge `x` (extended beyond [−1, 1] as the same quadratic
/// curve) closest to `q`: Newton on |x(s) − q|², from the projection on the chord. Exact in one
/// step on a straight edge with a centred middle node.
pub fn closest_parameter(x: &[[f64; 2]; 3], q: [f64; 2]) -> f64 {
    let chord = [x[2][0] - x[0][0], x[2][1] - x[0][1]];
    let l2 = chord[0] * chord[0] + chord[1] * chord[1];
    let mid = [0.5 * (x[0][0] + x[2][0]), 0.5 * (x[0][1] + x[2][1])];
    let mut s = 2.0 * ((q[0] - mid[0]) * chord[0] + (q[1] - mid[1]) * chord[1]) / l2;
    // x''(s) is constant on a quadratic edge: x0 − 2 x1 + x2.
    let dd = [x[0][0] - 2.0 * x[1][0] + x[2][0], x[0][1] - 2.0 * x[1][1] + x[2][1]];
    for _ in 0..30 {
        let (p, d) = point(x, s);
        let r = [p[0] - q[0], p[1] - q[1]];
        let g = r[0] * d[0] + r[1] * d[1];
        let h = d[0] * d[0] + d[1] * d[1] + r[0] * dd[0] + r[1] * dd[1];
        if h <= 0.0 {
            break;
        }
        let step = g / h;
        s -= step;
        if step.abs() <= 1e-15 * (1.0 + s.abs()) {
            break;
        }
    }
    s
}

/// Π_b of an interface whose pairs are side a's nodes: `a_edges` carry pair indices, `b_edges`
/// mesh nodes of b; `weights` are side a's lumped weights per pair (one per pair). A pair whose row
/// sum differs from ∫ ψ_p by more than 1e-6 relative (side b does not cover side a there) is an
/// error; a pair of zero weight (on the axis) gets b's interpolation at its point. Distances
/// along the interface are measured on side a; `plane` gives the measure.
pub fn project(
    a_edges: &[SideEdge],
    weights: &[f64],
    b_edges: &[SideEdge],
    plane: Plane,
    pair_coords: &[[f64; 2]],
) -> Result<Projection, ProjectionError> {
    project_with_ends(
        a_edges,
        weights,
        b_edges,
        plane,
        pair_coords,
        &vec![false; weights.len()],
    )
    .map(|p| p.b)
}

/// Both sides' projections onto Γ_h where some end pairs are left out (`dropped`: the end of an
/// open interface at a support or at another interface, [`project_with_ends`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Projected {
    /// Side a's trace per pair, as (pair index of a's node, coefficient): the pair's own node
    /// alone, except the middle pair of an end edge whose end was dropped: the edge's mean.
    pub a: Projection,
    pub b: Projection,
    /// The pairs' weights ∫ ψ_p: the given weight, or the edge's length (times the measure) for
    /// the middle pair of a modified end edge, and the share of its other edge for a pair whose
    /// end edge was modified.
    pub weights: Vec<f64>,
}

/// [`project`] with end pairs left out of the test space (the crosspoint modification of mortar
/// methods): on an end edge whose end pair is `dropped`, the middle pair's test function is 1 on
/// the whole edge and the other pairs' 0, so that the edge's traction is one constant carried by
/// its middle pair. Side a's trace at that middle pair is then the edge's mean (a combination of
/// its three nodes, exact for affine fields like side b's), its weight the edge's length. The
/// caller leaves out the dropped pairs, and the pairs whose weight comes out 0 (an end pair whose
/// only edge is modified). Without it an
/// end pair held by a support on side a, or shared with another interface, ties two different
/// averages of side b to one point and slows the iteration 3–6×.
pub fn project_with_ends(
    a_edges: &[SideEdge],
    weights: &[f64],
    b_edges: &[SideEdge],
    plane: Plane,
    pair_coords: &[[f64; 2]],
    dropped: &[bool],
) -> Result<Projected, ProjectionError> {
    let n_pairs = weights.len();
    // Side a's rows of the modified end edges: (pair index of a's node, value).
    let mut a_rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n_pairs];
    // Pairs of a modified end edge: their weight is ∫ ψ_p, not the given one.
    let mut on_modified = vec![false; n_pairs];
    // Sparse rows: (node of b, value), merged per pair.
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n_pairs];
    // ∫ ψ_p over a's edges with the rule of the rows (= ∫ N_p: ψ's row sums are N's): what a row
    // sums to where b covers a. (The scene's weights come from 3-point Gauss, which differs by up
    // to 1e-4 on a curved edge of 45°.)
    let mut full = vec![0.0; n_pairs];
    // The pairs that end an open interface belong to one edge only: the edges there keep N.
    let end = end_pairs(a_edges, n_pairs);
    debug_assert!(
        dropped.iter().zip(&end).all(|(&d, &e)| !d || e),
        "only the end pairs of an open interface can be left out"
    );
    for ea in a_edges {
        let dual = !end[ea.nodes[0]] && !end[ea.nodes[2]];
        let modified = (0..3).step_by(2).any(|k| dropped[ea.nodes[k]] && end[ea.nodes[k]]);
        if modified {
            for &q in &ea.nodes {
                on_modified[q] = true;
            }
        }
        // The edge's test functions: ψ = A N with A = D_e M_e⁻¹ (M_e the edge's consistent mass,
        // D_e its row sums), or N itself.
        let mut a_dual = nalgebra::Matrix3::<f64>::identity();
        if dual {
            let mut me = nalgebra::Matrix3::<f64>::zeros();
            for &(g, w) in &GAUSS5 {
                let (p, d) = point(&ea.x, g);
                let jac = (d[0] * d[0] + d[1] * d[1]).sqrt();
                let (na, _) = edge_shape(g);
                for i in 0..3 {
                    for j in 0..3 {
                        me[(i, j)] += na[i] * na[j] * w * jac * plane.measure(p);
                    }
                }
            }
            let de = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::from_fn(|i, _| me.row(i).sum()));
            a_dual = de * me.try_inverse().expect("edge mass");
        }
        // The edge's test functions at s: ψ = A N (dual), N (lumped), or (0, 1, 0) on a modified
        // end edge.
        let psi_at = |s: f64| -> [f64; 3] {
            let (na0, _) = edge_shape(s);
            if modified {
                [0.0, 1.0, 0.0]
            } else if dual {
                std::array::from_fn(|i| (0..3).map(|j| a_dual[(i, j)] * na0[j]).sum())
            } else {
                na0
            }
        };
        for &(g, w) in &GAUSS5 {
            let (p, d) = point(&ea.x, g);
            let (na, _) = edge_shape(g);
            let psi = psi_at(g);
            let dw = w * (d[0] * d[0] + d[1] * d[1]).sqrt() * plane.measure(p);
            for i in 0..3 {
                full[ea.nodes[i]] += psi[i] * dw;
            }
            if modified {
                // Side a's row of the middle pair: ∫ 1·N_q over the edge.
                for (&q, nq) in ea.nodes.iter().zip(na) {
                    accumulate(&mut a_rows[ea.nodes[1]], q, nq * dw);
                }
            }
        }
        let (a_lo, a_hi) = bounding_box(&ea.x);
        for eb in b_edges {
            // Quick rejection: boxes apart by more than the larger of the two edges.
            let (b_lo, b_hi) = bounding_box(&eb.x);
            let margin = (a_hi[0] - a_lo[0])
                .max(a_hi[1] - a_lo[1])
                .max(b_hi[0] - b_lo[0])
                .max(b_hi[1] - b_lo[1]);
            if (0..2).any(|c| b_lo[c] > a_hi[c] + margin || a_lo[c] > b_hi[c] + margin) {
                continue;
            }
            let s0 = closest_parameter(&ea.x, eb.x[0]);
            let s2 = closest_parameter(&ea.x, eb.x[2]);
            let lo = s0.min(s2).max(-1.0);
            let hi = s0.max(s2).min(1.0);
            if hi - lo <= 1e-12 {
                continue;
            }
            let half = 0.5 * (hi - lo);
            for &(g, w) in &GAUSS5 {
                let s = lo + half * (g + 1.0);
                let (p, d) = point(&ea.x, s);
                let jac = (d[0] * d[0] + d[1] * d[1]).sqrt();
                let sb = closest_parameter(&eb.x, p).clamp(-1.0, 1.0);
                let psi = psi_at(s);
                let (nb, _) = edge_shape(sb);
                let dw = w * half * jac * plane.measure(p);
                for i in 0..3 {
                    for (&node_b, nbj) in eb.nodes.iter().zip(nb) {
                        accumulate(&mut rows[ea.nodes[i]], node_b, psi[i] * nbj * dw);
                    }
                }
            }
        }
    }
    let heaviest = full.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let mut out = Projection::empty();
    for (p, row) in rows.iter_mut().enumerate() {
        row.sort_by_key(|e| e.0);
        let sum: f64 = row.iter().map(|e| e.1).sum();
        // A pair of (numerically) zero weight (on the axis of an axisymmetric part) has no row to
        // normalise: side b there is its interpolation at the pair's point (its node on the axis,
        // with coefficient 1, where b has one there).
        if full[p].abs() <= crate::element::AXIS_TOLERANCE * heaviest {
            out.push(interpolation(b_edges, pair_coords[p]));
            continue;
        }
        if (sum - full[p]).abs() > 1e-6 * full[p].abs() {
            return Err(ProjectionError::Uncovered {
                pair: p,
                at: pair_coords[p],
                covered: sum / full[p],
            });
        }
        // Exact zeros (a b node whose shape function vanishes on the segment) are left out.
        out.push(row.iter().filter(|e| e.1 != 0.0).map(|&(n, v)| (n, v / sum)));
    }
    let mut a = Projection::empty();
    let mut new_weights = weights.to_vec();
    for (p, row) in a_rows.iter_mut().enumerate() {
        // Only the middle pair of a modified end edge has a row of its own.
        if row.is_empty() {
            a.push([(p, 1.0)]);
        } else {
            row.sort_by_key(|e| e.0);
            let sum: f64 = row.iter().map(|e| e.1).sum();
            a.push(row.iter().map(|&(q, v)| (q, v / sum)));
        }
        if on_modified[p] {
            new_weights[p] = full[p];
        }
    }
    Ok(Projected {
        a,
        b: out,
        weights: new_weights,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Edges of `nodes` evenly along s ∈ [s0, s1] of the line `at(s)`.
    fn straight(nodes: &[usize], s0: f64, s1: f64, at: impl Fn(f64) -> [f64; 2]) -> Vec<SideEdge> {
        let n = (nodes.len() - 1) / 2;
        (0..n)
            .map(|e| {
                let xs = |k: usize| at(s0 + (s1 - s0) * (2 * e + k) as f64 / (2 * n) as f64);
                SideEdge {
                    nodes: [nodes[2 * e], nodes[2 * e + 1], nodes[2 * e + 2]],
                    x: [xs(0), xs(1), xs(2)],
                }
            })
            .collect()
    }

    /// Side a in 3 edges, side b in 7 on the same segment (and 7:3, 2:5, 4:4): Π_b maps the nodal
    /// values of any affine function on b to its values at a's nodes (to round-off: 1e-14 of the
    /// values), in plane strain along y = 0 and in axisymmetry along the axis at r = 3, where the
    /// measure 2πr is constant along the interface. (Across the radius the measure varies and
    /// the lumped projection reproduces constants only: not asserted.)
    #[test]
    fn projection_reproduces_affine_fields_across_mesh_ratios() {
        for plane in [Plane::Strain, Plane::Axisymmetric] {
            let at = |s: f64| if plane == Plane::Strain { [s, 0.0] } else { [3.0, s] };
            for (na, nb) in [(3, 7), (7, 3), (2, 5), (4, 4)] {
                let a_nodes: Vec<usize> = (0..2 * na + 1).collect();
                let b_nodes: Vec<usize> = (0..2 * nb + 1).collect();
                let a = straight(&a_nodes, 2.0, 5.0, at);
                let b = straight(&b_nodes, 2.0, 5.0, at);
                let mut w = vec![0.0; 2 * na + 1];
                for e in &a {
                    for (k, m) in crate::element::edge_lumped_mass(&e.x, plane).into_iter().enumerate() {
                        w[e.nodes[k]] += m;
                    }
                }
                let sa = |k: usize| 2.0 + 3.0 * k as f64 / (2 * na) as f64;
                let xa: Vec<[f64; 2]> = (0..2 * na + 1).map(|k| at(sa(k))).collect();
                let pr = project(&a, &w, &b, plane, &xa).unwrap();
                let f = |x: f64| 0.7 - 1.3 * x;
                for p in 0..xa.len() {
                    let v: f64 = pr
                        .terms(p)
                        .map(|(n, c)| c * f(2.0 + 3.0 * n as f64 / (2 * nb) as f64))
                        .sum();
                    assert!(
                        (v - f(sa(p))).abs() <= 1e-14 * 8.0,
                        "{plane:?} {na}:{nb} pair {p}: {v} vs {}",
                        f(sa(p))
                    );
                }
            }
        }
    }

    /// Quadratic edges around the circle of radius `r` (`n` edges, middle nodes on the circle),
    /// turned by `turn` rad: node 2k + 1 is the middle of edge k, the ring closed.
    fn ring(n: usize, r: f64, turn: f64) -> Vec<SideEdge> {
        let at = |k: usize| {
            let t = turn + std::f64::consts::PI * k as f64 / n as f64;
            [r * t.cos(), r * t.sin()]
        };
        (0..n)
            .map(|e| SideEdge {
                nodes: [2 * e, 2 * e + 1, (2 * e + 2) % (2 * n)],
                x: [at(2 * e), at(2 * e + 1), at(2 * e + 2)],
            })
            .collect()
    }

    /// Closed rings meshed on their own, coarse (24 against 30 around: edges of 15° whose
    /// 3-point weights differ from the 5-point integrals by 2.5e-6, which the coverage check
    /// once refused): constants cross exactly, and the coordinates to about the distance between
    /// the two discretised circles (a quadratic arc of 15° on R = 30 strays from the circle by
    /// about 3e-4 mm; measured 2.3e-4, asserted 1e-3).
    #[test]
    fn coarse_rings_meshed_on_their_own_project() {
        for plane in [Plane::Strain, Plane::Axisymmetric] {
            let (a, b) = (ring(24, 30.0, 0.0), ring(30, 30.0, 0.1));
            let mut w = vec![0.0; 48];
            for e in &a {
                for (k, m) in crate::element::edge_lumped_mass(&e.x, plane).into_iter().enumerate() {
                    w[e.nodes[k]] += m;
                }
            }
            let xa: Vec<[f64; 2]> = (0..48).map(|k| a[k / 2].x[k % 2]).collect();
            let xb: Vec<[f64; 2]> = (0..60).map(|k| b[k / 2].x[k % 2]).collect();
            // In axisymmetry the ring lies at r > 0: shift it.
            let shift = |v: &[SideEdge]| -> Vec<SideEdge> {
                v.iter()
                    .map(|e| SideEdge {
                        nodes: e.nodes,
                        x: e.x.map(|p| [p[0] + 40.0, p[1]]),
                    })
                    .collect()
            };
            let (a, b) = if plane == Plane::Axisymmetric {
                (shift(&a), shift(&b))
            } else {
                (a, b)
            };
            let pr = project(&a, &w, &b, plane, &xa).unwrap();
            let mut worst = 0.0f64;
            for (p, x_a) in xa.iter().enumerate() {
                let one: f64 = pr.terms(p).map(|(_, c)| c).sum();
                assert!((one - 1.0).abs() <= 1e-13, "{plane:?} pair {p}: {one}");
                let x: f64 = pr.terms(p).map(|(n, c)| c * xb[n][0]).sum();
                worst = worst.max((x - x_a[0]).abs());
            }
            assert!(worst <= 1e-3, "{plane:?}: largest |Π x_b − x_a| {worst:e} mm");
        }
    }

    /// A side b that stops short of side a's end is an error naming where.
    #[test]
    fn an_uncovered_pair_is_refused() {
        let line = |s: f64| [s, 0.0];
        let a = straight(&[0, 1, 2, 3, 4], 0.0, 4.0, line);
        let b = straight(&[0, 1, 2], 0.0, 3.0, line);
        let w = [1.0 / 3.0, 4.0 / 3.0, 2.0 / 3.0, 4.0 / 3.0, 1.0 / 3.0];
        let xa = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0]];
        let err = project(&a, &w, &b, Plane::Strain, &xa).unwrap_err();
        // Pair 2 (x = 2) is the first whose row sum differs from its weight: b's edge stops
        // inside a's second edge, whose shape functions are not covered whole.
        assert!(matches!(err, ProjectionError::Uncovered { pair: 2, .. }), "{err:?}");
        assert!(err.to_string().contains("around (2, 0)"), "{err}");
    }
}
