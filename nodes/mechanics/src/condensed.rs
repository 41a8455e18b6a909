//! The condensed boundary operator of a subdomain (docs/method.md, "Linear stage"):
//! A_E = B (K_E + Bᵀ k⁻ M B)⁻¹ Bᵀ, a dense SPD n_b × n_b matrix built once from a sparse Cholesky
//! factorisation, and the boundary responses to the subdomain's own loads (W_d patterns).
//!
//! Prescribed displacements are imposed strongly: constrained dofs are eliminated, so A_E has
//! zero rows and columns at constrained boundary entries and W_d carries their prescribed values.

use crate::assembly::{stiffness_triplets, triplet_matvec, AssemblyError, SparseSpd};
use crate::model::{Model, Plane, Side, Subdomain};
use faer::reborrow::ReborrowMut;
use faer::{Mat, MatMut, MatRef};

/// Where each boundary entry of a subdomain lives. The boundary vector stacks, interface by
/// interface (in the model's interface order), the x and y traces of that interface's node copies
/// (docs/method.md, "Cross-points": one copy of a node per interface). An entry is a combination of subdomain dofs:
/// one dof with coefficient 1 on a conforming interface, side b's projection on a non-matching
/// one ([`crate::mortar`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BoundaryLayout {
    /// Entry b is Σ coefs[k]·u[dofs[k]] for k in start[b]..start[b + 1] (n_b + 1 starts).
    pub start: Vec<usize>,
    pub dofs: Vec<usize>,
    pub coefs: Vec<f64>,
    /// Diagonal of the lumped interface mass M (mm) per entry.
    pub mass: Vec<f64>,
    /// Search direction k⁻ (MPa/mm) per entry.
    pub k: Vec<f64>,
    /// The interfaces of this subdomain, in boundary order.
    pub slots: Vec<InterfaceSlot>,
}

/// One interface's block of a subdomain's boundary vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InterfaceSlot {
    pub interface: usize,
    pub side: Side,
    /// First boundary entry of this interface (entry 2p + c is pair p, component c).
    pub offset: usize,
    pub n_pairs: usize,
}

impl BoundaryLayout {
    /// Layout of subdomain `s` of `model`, with k⁻ = `k_interface[i]` on interface i.
    pub fn new(model: &Model, s: usize, k_interface: &[f64]) -> Self {
        let mut start = vec![0];
        let mut dofs = Vec::new();
        let mut coefs = Vec::new();
        let mut mass = Vec::new();
        let mut k = Vec::new();
        let mut slots = Vec::new();
        for (i, itf) in model.interfaces.iter().enumerate() {
            let Some(side) = itf.side_of(s) else { continue };
            slots.push(InterfaceSlot {
                interface: i,
                side,
                offset: mass.len(),
                n_pairs: itf.n_pairs(),
            });
            for p in 0..itf.n_pairs() {
                let trace = itf.trace(side, p);
                for c in 0..2 {
                    for &(node, coef) in &trace {
                        dofs.push(2 * node + c);
                        coefs.push(coef);
                    }
                    start.push(dofs.len());
                    mass.push(itf.weights[p]);
                    k.push(k_interface[i]);
                }
            }
        }
        Self {
            start,
            dofs,
            coefs,
            mass,
            k,
            slots,
        }
    }

    /// n_b, the length of the boundary vector.
    pub fn len(&self) -> usize {
        self.mass.len()
    }

    pub fn is_empty(&self) -> bool {
        self.mass.is_empty()
    }

    /// (dof, coefficient) terms of entry b.
    pub fn terms(&self, b: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.start[b]..self.start[b + 1];
        self.dofs[r.clone()].iter().copied().zip(self.coefs[r].iter().copied())
    }

    /// Entry b of the trace of a full displacement vector u: Σ coef·u[dof].
    pub fn trace_of(&self, u: impl Fn(usize) -> f64, b: usize) -> f64 {
        crate::mortar::combine(self.terms(b), u)
    }

    /// Per slot, the interface node that owns its interface: the one whose group (`groups`, by
    /// node index) holds it. None when an interface has no owner.
    pub fn owners(&self, groups: &[Vec<usize>]) -> Option<Vec<u32>> {
        self.slots
            .iter()
            .map(|sl| groups.iter().position(|g| g.contains(&sl.interface)).map(|g| g as u32))
            .collect()
    }

    /// How this subdomain's state is shared among the interface nodes that own its interfaces
    /// (`groups`: the interfaces of each node): one part per node owning one of them, in node
    /// order, each the rows of that node's interfaces in layout order. None when one of its
    /// interfaces has no owner. The subdomain cuts its state this way and each node reads its
    /// part this way: one rule for both.
    pub fn parts(&self, groups: &[Vec<usize>]) -> Option<Vec<StatePart>> {
        let owners = self.owners(groups)?;
        let mut nodes = owners.clone();
        nodes.sort_unstable();
        nodes.dedup();
        Some(
            nodes
                .into_iter()
                .map(|node| {
                    let mut rows = 0;
                    let at = self
                        .slots
                        .iter()
                        .zip(&owners)
                        .map(|(sl, &owner)| {
                            (owner == node).then(|| {
                                rows += 2 * sl.n_pairs;
                                rows - 2 * sl.n_pairs
                            })
                        })
                        .collect();
                    StatePart { node, at, rows }
                })
                .collect(),
        )
    }
}

/// The rows of a subdomain's state that one interface node receives ([`BoundaryLayout::parts`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StatePart {
    /// The interface node.
    pub node: u32,
    /// Per slot of the layout, its first row in the part; None for the slots of the interfaces
    /// of other nodes.
    pub at: Vec<Option<usize>>,
    /// The part's rows.
    pub rows: usize,
}

impl StatePart {
    /// The part's interfaces, in layout order.
    pub fn interfaces(&self, layout: &BoundaryLayout) -> Vec<u32> {
        self.slots(layout).map(|sl| sl.interface as u32).collect()
    }

    /// The part's rows in the whole state: (first row, rows) per interface, in layout order.
    pub fn ranges(&self, layout: &BoundaryLayout) -> Vec<(usize, usize)> {
        self.slots(layout).map(|sl| (sl.offset, 2 * sl.n_pairs)).collect()
    }

    fn slots<'l>(&'l self, layout: &'l BoundaryLayout) -> impl Iterator<Item = &'l InterfaceSlot> {
        layout
            .slots
            .iter()
            .zip(&self.at)
            .filter(|(_, at)| at.is_some())
            .map(|(sl, _)| sl)
    }
}

/// Condensed operator of one subdomain and its load responses.
pub struct CondensedOperator {
    n_dofs: usize,
    /// Free-dof index of each subdomain dof (usize::MAX when constrained).
    free: Vec<usize>,
    factor: SparseSpd,
    /// A_E (n_b × n_b, mm/N).
    pub a: Mat<f64>,
    /// Boundary trace of the response to each load case (n_b × n_cases), mm per unit φ.
    pub load_boundary: Mat<f64>,
    /// Full displacement response to each load case (n_dofs × n_cases), mm per unit φ.
    pub load_full: Mat<f64>,
    pub layout: BoundaryLayout,
}

impl CondensedOperator {
    /// Assembles K_E + Bᵀ k⁻ M B on the free dofs, factorises it, and builds A_E and the load responses.
    pub fn new(sub: &Subdomain, plane: Plane, layout: BoundaryLayout) -> Result<Self, AssemblyError> {
        Self::with_dense(sub, plane, layout, true)
    }

    /// As [`CondensedOperator::new`]; with `dense` false A_E is not built (`a` is 0 × 0) and
    /// boundary responses come from the sparse factors ([`CondensedOperator::sparse_response_into`]).
    pub fn with_dense(
        sub: &Subdomain,
        plane: Plane,
        layout: BoundaryLayout,
        dense: bool,
    ) -> Result<Self, AssemblyError> {
        let n_dofs = sub.n_dofs();
        let k_full = stiffness_triplets(&sub.mesh, sub.material, plane)?;
        let mut free = vec![usize::MAX; n_dofs];
        let mut n_free = 0;
        for (d, f) in free.iter_mut().enumerate() {
            if !sub.constrained[d] {
                *f = n_free;
                n_free += 1;
            }
        }
        let mut trip: Vec<(usize, usize, f64)> = k_full
            .iter()
            .filter(|&&(i, j, _)| free[i] != usize::MAX && free[j] != usize::MAX)
            .map(|&(i, j, v)| (free[i], free[j], v))
            .collect();
        // Bᵀ k⁻ M B: one diagonal term per entry of a conforming interface; the outer product of
        // the entry's free terms on a non-matching one.
        for b in 0..layout.len() {
            let km = layout.k[b] * layout.mass[b];
            for (di, ci) in layout.terms(b) {
                for (dj, cj) in layout.terms(b) {
                    if free[di] != usize::MAX && free[dj] != usize::MAX {
                        trip.push((free[di], free[dj], ci * cj * km));
                    }
                }
            }
        }
        // Supernodal: A_E's n_b columns (and the sparse linear stage's N + 1) are solved at once.
        let factor =
            SparseSpd::factorize_supernodal(n_free, &trip, &format!("subdomain `{}` (K_E + Bᵀk⁻MB)", sub.name))?;

        // A_E: solve for each distinct free boundary dof, then expand to the copies.
        let n_b = layout.len();
        let mut col_of_dof = vec![usize::MAX; n_dofs];
        let mut unique = Vec::new();
        for &d in &layout.dofs {
            if free[d] != usize::MAX && col_of_dof[d] == usize::MAX {
                col_of_dof[d] = unique.len();
                unique.push(d);
            }
        }
        let n_cols = if dense { unique.len() } else { 0 };
        let mut x = Mat::<f64>::zeros(n_free, n_cols);
        for (c, &d) in unique.iter().take(n_cols).enumerate() {
            x[(free[d], c)] = 1.0;
        }
        factor.solve_in_place(&mut x);
        let n_a = if dense { n_b } else { 0 };
        // A_E = B X with X = K̃⁻¹ Bᵀ: entry (r, c) sums the terms of r and c over free dofs
        // (a conforming entry: the one term, times 1).
        let a = Mat::from_fn(n_a, n_a, |r, c| {
            let mut v = 0.0;
            for (dr, cr) in layout.terms(r) {
                for (dc, cc) in layout.terms(c) {
                    if free[dr] != usize::MAX && free[dc] != usize::MAX {
                        v += cr * cc * x[(free[dr], col_of_dof[dc])];
                    }
                }
            }
            v
        });

        // Load responses: K̃_ff u_f = f_f − K_fd u_d.
        let n_cases = sub.loads.len();
        let mut load_full = Mat::<f64>::zeros(n_dofs, n_cases);
        let mut load_boundary = Mat::<f64>::zeros(n_b, n_cases);
        let mut ku = vec![0.0; n_dofs];
        for (j, case) in sub.loads.iter().enumerate() {
            triplet_matvec(&k_full, &case.displacement, &mut ku);
            let mut rhs = Mat::<f64>::zeros(n_free, 1);
            for d in 0..n_dofs {
                if free[d] != usize::MAX {
                    rhs[(free[d], 0)] = case.force[d] - ku[d];
                }
            }
            // A non-matching entry mixing free and prescribed dofs couples them through
            // Bᵀ k⁻ M B as K does: its prescribed part moves to the right-hand side too (a
            // conforming entry is one dof, free or prescribed, and adds nothing here).
            for b in 0..n_b {
                let prescribed: f64 = layout
                    .terms(b)
                    .filter(|&(d, _)| free[d] == usize::MAX)
                    .map(|(d, c)| c * case.displacement[d])
                    .sum();
                if prescribed != 0.0 {
                    let km = layout.k[b] * layout.mass[b];
                    for (d, c) in layout.terms(b) {
                        if free[d] != usize::MAX {
                            rhs[(free[d], 0)] -= c * km * prescribed;
                        }
                    }
                }
            }
            factor.solve_in_place(&mut rhs);
            for d in 0..n_dofs {
                load_full[(d, j)] = if free[d] == usize::MAX {
                    case.displacement[d]
                } else {
                    rhs[(free[d], 0)]
                };
            }
            for b in 0..n_b {
                load_boundary[(b, j)] = layout.trace_of(|d| load_full[(d, j)], b);
            }
        }
        Ok(Self {
            n_dofs,
            free,
            factor,
            a,
            load_boundary,
            load_full,
            layout,
        })
    }

    pub fn n_dofs(&self) -> usize {
        self.n_dofs
    }

    /// Number of free dofs (the order of K_E + Bᵀk⁻MB).
    pub fn n_free(&self) -> usize {
        self.factor.n()
    }

    /// Floating-point operations of [`CondensedOperator::sparse_response_into`] per column:
    /// the right-hand side M q on the free boundary entries (a multiply and an add each) and one
    /// forward and backward substitution ([`SparseSpd::solve_flops`]).
    pub fn sparse_response_flops(&self) -> u64 {
        let free_boundary = self.layout.dofs.iter().filter(|&&d| self.free[d] != usize::MAX).count();
        // Each free term is a multiply and an add (M q then its share), counted once as before.
        2 * free_boundary as u64 + self.factor.solve_flops()
    }

    /// Scratch of the sparse solves of [`CondensedOperator::sparse_response_into`] for up to
    /// `ncols` columns.
    pub fn sparse_scratch(&self, ncols: usize) -> faer::dyn_stack::MemBuffer {
        self.factor.solve_scratch(ncols)
    }

    /// w = B (K_E + Bᵀk⁻MB)⁻¹ Bᵀ M q (= A_E M q) for every column of q (n_b × m, N/mm²), by one
    /// multi-right-hand-side solve with the sparse factors; `rhs` is caller-owned scratch of at
    /// least n_free × m, `scratch` that of the solve ([`CondensedOperator::sparse_scratch`] of at
    /// least m columns). Constrained boundary entries get 0 (as A_E's zero rows).
    pub fn sparse_response_into(
        &self,
        q: MatRef<'_, f64>,
        rhs: MatMut<'_, f64>,
        mut w: MatMut<'_, f64>,
        scratch: &mut faer::dyn_stack::MemBuffer,
    ) {
        let m = q.ncols();
        let mut rhs = rhs.subcols_mut(0, m);
        rhs.fill(0.0);
        let layout = &self.layout;
        let free = &self.free;
        for j in 0..m {
            for b in 0..layout.len() {
                let mq = layout.mass[b] * q[(b, j)];
                for (d, c) in layout.terms(b) {
                    if free[d] != usize::MAX {
                        rhs[(free[d], j)] += c * mq;
                    }
                }
            }
        }
        self.factor.solve_view_in_place_with(rhs.rb_mut(), scratch);
        for j in 0..m {
            // Constrained terms count 0 (A_E's zero rows).
            for b in 0..layout.len() {
                w[(b, j)] = layout.trace_of(|d| if free[d] == usize::MAX { 0.0 } else { rhs[(free[d], j)] }, b);
            }
        }
    }

    /// Full displacement field u = Σ_j φ_j u_j + (K_E + Bᵀk⁻MB)⁻¹ Bᵀ M q for a boundary
    /// right-hand side q (n_b; N/mm², i.e. F̂ + k⁻(Ŵ + W̃ᴹ), or F + k⁻W at a solution) and load
    /// factors φ_j.
    pub fn recover(&self, q: &[f64], load_factors: &[f64]) -> Vec<f64> {
        let mut rhs = Mat::<f64>::zeros(self.factor.n(), 1);
        for (b, &qb) in q.iter().enumerate() {
            let mq = self.layout.mass[b] * qb;
            for (d, c) in self.layout.terms(b) {
                if self.free[d] != usize::MAX {
                    rhs[(self.free[d], 0)] += c * mq;
                }
            }
        }
        self.factor.solve_in_place(&mut rhs);
        (0..self.n_dofs)
            .map(|d| {
                let loads: f64 = load_factors
                    .iter()
                    .enumerate()
                    .map(|(j, phi)| phi * self.load_full[(d, j)])
                    .sum();
                loads
                    + if self.free[d] == usize::MAX {
                        0.0
                    } else {
                        rhs[(self.free[d], 0)]
                    }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(pairs: &[(usize, usize)]) -> BoundaryLayout {
        let mut offset = 0;
        let slots = pairs
            .iter()
            .map(|&(interface, n_pairs)| {
                let sl = InterfaceSlot {
                    interface,
                    side: Side::A,
                    offset,
                    n_pairs,
                };
                offset += 2 * n_pairs;
                sl
            })
            .collect();
        BoundaryLayout {
            start: (0..=offset).collect(),
            dofs: (0..offset).collect(),
            coefs: vec![1.0; offset],
            mass: vec![1.0; offset],
            k: vec![1.0; offset],
            slots,
        }
    }

    /// Interfaces 4, 7 and 9 of 3, 2 and 5 pairs, owned by nodes 1, 0 and 1: node 0 gets rows
    /// 6..10 of the state as its rows 0..4, node 1 rows 0..6 and 10..20 as its rows 0..16; a node
    /// owning every interface gets the whole state in layout order; an interface without an owner
    /// leaves the state whole (None).
    #[test]
    fn parts_cut_the_state_by_owner_in_layout_order() {
        let l = layout(&[(4, 3), (7, 2), (9, 5)]);
        let parts = l.parts(&[vec![7, 1], vec![4, 9]]).unwrap();
        assert_eq!(
            parts,
            vec![
                StatePart {
                    node: 0,
                    at: vec![None, Some(0), None],
                    rows: 4
                },
                StatePart {
                    node: 1,
                    at: vec![Some(0), None, Some(6)],
                    rows: 16
                },
            ]
        );
        assert_eq!(parts[0].interfaces(&l), [7]);
        assert_eq!(parts[0].ranges(&l), [(6, 4)]);
        assert_eq!(parts[1].interfaces(&l), [4, 9]);
        assert_eq!(parts[1].ranges(&l), [(0, 6), (10, 10)]);
        let one = l.parts(&[vec![], vec![9, 7, 4]]).unwrap();
        assert_eq!(one.len(), 1);
        assert_eq!((one[0].node, one[0].rows), (1, l.len()));
        assert_eq!(one[0].at, l.slots.iter().map(|sl| Some(sl.offset)).collect::<Vec<_>>());
        assert_eq!(l.parts(&[vec![4], vec![7]]), None);
    }
}
