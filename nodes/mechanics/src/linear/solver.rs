//! One subdomain's linear stage (docs/method.md, "Linear stage"): [`SubdomainSolver`] builds A_E, W_d, 𝔼 and L_E
//! once, then solves micro problem 1, the macro forces and micro problem 2 at every iteration.

use super::fields::{col, col_mut, scale_into};
use crate::assembly::AssemblyError;
use crate::condensed::{BoundaryLayout, CondensedOperator};
use crate::model::Model;
use crate::simd::{dot, matmul};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use std::sync::Arc;

/// The time functions φ of subdomain `s`'s load cases on `model`'s time grid (n_c × (N+1)) and
/// W_d = (boundary response to each load case) φ (n_b × (N+1)).
fn load_responses(model: &Model, s: usize, op: &CondensedOperator) -> (Mat<f64>, Mat<f64>) {
    let sub = &model.subdomains[s];
    let nt = model.time.n_points();
    let phi = Mat::from_fn(sub.loads.len(), nt, |j, i| sub.loads[j].time.eval(model.time.t(i)));
    let mut w_d = Mat::<f64>::zeros(op.layout.len(), nt);
    if !sub.loads.is_empty() {
        matmul(
            w_d.as_mut(),
            Accum::Replace,
            op.load_boundary.as_ref(),
            phi.as_ref(),
            1.0,
            Par::Seq,
        );
    }
    (phi, w_d)
}

/// Columns of one interface's macro modes in a subdomain's 𝔼.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MacroSlot {
    pub interface: usize,
    pub first_col: usize,
    pub n_modes: usize,
}

/// Everything one subdomain needs for its linear stages, built once.
pub struct SubdomainSolver {
    pub subdomain: usize,
    /// The condensed operator (shared by [`SubdomainSolver::retimed`] copies: it does not depend
    /// on time).
    pub op: Arc<CondensedOperator>,
    /// W_d: boundary displacement due to the subdomain's own loads (n_b × (N+1)).
    pub w_d: Mat<f64>,
    /// Time functions φ of the subdomain's load cases (n_c × (N+1)): W_d = (boundary response to
    /// each load case) φ.
    pub load_time: Mat<f64>,
    /// 𝔼: the macro basis vectors of this subdomain's interfaces as columns (n_b × n_m).
    pub e: Mat<f64>,
    /// A_E M k⁻ 𝔼 (n_b × n_m).
    pub a_mk_e: Mat<f64>,
    /// A_Eᵀ stored column-major (0 × 0 without A_E): its transpose is A_E entry for entry, laid
    /// out by rows, which makes the product kernel pack A_E into its own contiguous buffer. Read
    /// in place (column-major), measured on the stratified scene (n_b = 246, 101 time points),
    /// the product took 0.7 to 2.5 ms depending on where A_E sat in memory (0.2 to 0.7 ms for
    /// copies of it elsewhere), and 0.23 ms packed.
    a_rows: Mat<f64>,
    /// M 𝔼 (n_b × n_m): the macro forces are its columns' dot products with F.
    m_e: Mat<f64>,
    /// k⁻(𝔼 − A_E M k⁻ 𝔼) (n_b × n_m): F₂ of micro problem 2 is one product with it.
    f2_of_w: Mat<f64>,
    /// L_E (n_m × n_m, N/mm).
    pub l_e: Mat<f64>,
    pub macro_slots: Vec<MacroSlot>,
    /// Whether A_E is built (condensed linear stage); without it, boundary responses come from
    /// the sparse factors of K_E + Bᵀk⁻MB (the paper's baseline linear stage).
    dense: bool,
    /// Scratch M q (n_b × (N+1)), allocated once.
    scratch: Mat<f64>,
    /// Scratch right-hand sides of the sparse solves (n_free × (N+1); 0 × 0 when dense).
    sparse_rhs: Mat<f64>,
    /// Scratch of the sparse solves themselves (for N + 1 columns; for none when dense).
    sparse_scratch: faer::dyn_stack::MemBuffer,
    /// Floating-point operations of the linear-stage kernels called since construction
    /// ([`SubdomainSolver::flops`]).
    flops: u64,
}

impl SubdomainSolver {
    /// Builds A_E, W_d, 𝔼, A_E M k⁻ 𝔼 and L_E for subdomain `s`. `bases[i]` is the macro basis of interface i.
    pub fn new(model: &Model, s: usize, k_interface: &[f64], bases: &[Vec<Vec<f64>>]) -> Result<Self, AssemblyError> {
        Self::with_dense(model, s, k_interface, bases, true)
    }

    /// As [`SubdomainSolver::new`]; with `dense` false A_E is not built and every boundary
    /// response (micro problems 1 and 2, A_E M k⁻ 𝔼 for L_E) is one multi-right-hand-side solve
    /// with the sparse factors: the same numbers to round-off, at the cost of the sparse solves.
    pub fn with_dense(
        model: &Model,
        s: usize,
        k_interface: &[f64],
        bases: &[Vec<Vec<f64>>],
        dense: bool,
    ) -> Result<Self, AssemblyError> {
        let sub = &model.subdomains[s];
        let layout = BoundaryLayout::new(model, s, k_interface);
        let op = CondensedOperator::with_dense(sub, model.plane, layout, dense)?;
        let layout = &op.layout;
        let n_b = layout.len();
        let nt = model.time.n_points();
        let (phi, w_d) = load_responses(model, s, &op);
        let mut macro_slots = Vec::new();
        let mut n_m = 0;
        for slot in &layout.slots {
            let k = bases[slot.interface].len();
            macro_slots.push(MacroSlot {
                interface: slot.interface,
                first_col: n_m,
                n_modes: k,
            });
            n_m += k;
        }
        let mut e = Mat::<f64>::zeros(n_b, n_m);
        for (slot, ms) in layout.slots.iter().zip(&macro_slots) {
            for (m, v) in bases[slot.interface].iter().enumerate() {
                for (r, x) in v.iter().enumerate() {
                    e[(slot.offset + r, ms.first_col + m)] = *x;
                }
            }
        }
        let mk_e = Mat::from_fn(n_b, n_m, |r, c| layout.mass[r] * layout.k[r] * e[(r, c)]);
        let mut a_mk_e = Mat::<f64>::zeros(n_b, n_m);
        let width = nt.max(n_m).max(1);
        let mut sparse_rhs = Mat::<f64>::zeros(if dense { 0 } else { op.n_free() }, if dense { 0 } else { width });
        let mut sparse_scratch = op.sparse_scratch(if dense { 0 } else { width });
        if dense {
            matmul(
                a_mk_e.as_mut(),
                Accum::Replace,
                op.a.as_ref(),
                mk_e.as_ref(),
                1.0,
                Par::Seq,
            );
        } else {
            let k_e = Mat::from_fn(n_b, n_m, |r, c| layout.k[r] * e[(r, c)]);
            op.sparse_response_into(k_e.as_ref(), sparse_rhs.as_mut(), a_mk_e.as_mut(), &mut sparse_scratch);
        }
        let a_rows = op.a.transpose().to_owned();
        let mut l_e = Mat::<f64>::zeros(n_m, n_m);
        matmul(
            l_e.as_mut(),
            Accum::Replace,
            e.transpose(),
            mk_e.as_ref(),
            1.0,
            Par::Seq,
        );
        matmul(
            l_e.as_mut(),
            Accum::Add,
            mk_e.transpose(),
            a_mk_e.as_ref(),
            -1.0,
            Par::Seq,
        );
        let m_e = Mat::from_fn(n_b, n_m, |r, c| layout.mass[r] * e[(r, c)]);
        let f2_of_w = Mat::from_fn(n_b, n_m, |r, c| layout.k[r] * (e[(r, c)] - a_mk_e[(r, c)]));
        // Symmetrise away round-off.
        for i in 0..n_m {
            for j in 0..i {
                let v = 0.5 * (l_e[(i, j)] + l_e[(j, i)]);
                l_e[(i, j)] = v;
                l_e[(j, i)] = v;
            }
        }
        Ok(Self {
            subdomain: s,
            op: Arc::new(op),
            w_d,
            load_time: phi,
            e,
            a_mk_e,
            a_rows,
            m_e,
            f2_of_w,
            l_e,
            macro_slots,
            dense,
            scratch: Mat::zeros(n_b, width),
            sparse_rhs,
            sparse_scratch,
            flops: 0,
        })
    }

    /// This solver on the time grid of `model`, the same model otherwise (a time-coarse start's
    /// coarse solve): the condensed operator is shared and 𝔼, A_E M k⁻ 𝔼 and L_E are copied, as
    /// none depends on time; W_d, the load time functions and the scratch are built for
    /// `model.time`. The same numbers as [`SubdomainSolver::with_dense`] on `model`, without
    /// its factorisation and boundary solves.
    pub fn retimed(&self, model: &Model) -> Self {
        let (load_time, w_d) = load_responses(model, self.subdomain, &self.op);
        let width = model.time.n_points().max(self.e.ncols()).max(1);
        let n_b = self.n_boundary();
        Self {
            subdomain: self.subdomain,
            op: self.op.clone(),
            w_d,
            load_time,
            e: self.e.clone(),
            a_mk_e: self.a_mk_e.clone(),
            a_rows: self.a_rows.clone(),
            m_e: self.m_e.clone(),
            f2_of_w: self.f2_of_w.clone(),
            l_e: self.l_e.clone(),
            macro_slots: self.macro_slots.clone(),
            dense: self.dense,
            scratch: Mat::zeros(n_b, width),
            sparse_rhs: if self.dense {
                Mat::zeros(0, 0)
            } else {
                Mat::zeros(self.op.n_free(), width)
            },
            sparse_scratch: self.op.sparse_scratch(if self.dense { 0 } else { width }),
            flops: 0,
        }
    }

    /// Floating-point operations made by [`SubdomainSolver::micro1_into`],
    /// [`SubdomainSolver::macro_forces_into`], [`SubdomainSolver::micro2_into`] and
    /// [`SubdomainSolver::boundary_response_into`] since construction (the setup is not
    /// counted), each kernel adding the exact count of what it runs: a dense product of an
    /// m × k by a k × n matrix 2mkn, a sparse multi-right-hand-side solve
    /// [`CondensedOperator::sparse_response_flops`] per column, an element-wise pass one flop per
    /// multiply, add or subtract of each entry. Copies count nothing.
    pub fn flops(&self) -> u64 {
        self.flops
    }

    /// Whether the linear stage uses the dense A_E (else the sparse factors).
    pub fn is_dense(&self) -> bool {
        self.dense
    }

    /// out = A_E M q for every column of q (n_b × m, m ≤ N+1): a dense product with A_E, or one
    /// multi-right-hand-side sparse solve when A_E is not built. No load term.
    pub fn boundary_response_into(&mut self, q: MatRef<'_, f64>, mut out: MatMut<'_, f64>) {
        // In blocks of the scratch width.
        let width = self.scratch.ncols();
        let mut j0 = 0;
        while j0 < q.ncols() {
            let m = width.min(q.ncols() - j0);
            self.boundary_response_block(q.subcols(j0, m), out.rb_mut().subcols_mut(j0, m));
            j0 += m;
        }
    }

    /// A_E (M q) into `out` (replacing or adding to it), through the scratch block (q has at
    /// most its width of columns).
    fn dense_response(&mut self, q: MatRef<'_, f64>, out: MatMut<'_, f64>, accum: Accum) {
        let (m, n_b) = (q.ncols(), self.n_boundary() as u64);
        // M q, then A_E (M q).
        self.flops += m as u64 * (n_b + 2 * n_b * n_b);
        let layout = &self.op.layout;
        let mut mq = self.scratch.as_mut().subcols_mut(0, m);
        for j in 0..m {
            scale_into(col_mut(&mut mq, j), &layout.mass, col(q, j));
        }
        matmul(
            out,
            accum,
            self.a_rows.transpose(),
            self.scratch.as_ref().subcols(0, m),
            1.0,
            Par::Seq,
        );
    }

    fn boundary_response_block(&mut self, q: MatRef<'_, f64>, out: MatMut<'_, f64>) {
        let m = q.ncols();
        if self.dense {
            self.dense_response(q, out, Accum::Replace);
        } else {
            self.flops += m as u64 * self.op.sparse_response_flops();
            self.op
                .sparse_response_into(q, self.sparse_rhs.as_mut(), out, &mut self.sparse_scratch);
        }
    }

    pub fn n_boundary(&self) -> usize {
        self.op.layout.len()
    }

    pub fn n_macro(&self) -> usize {
        self.e.ncols()
    }

    /// Micro problem 1: W₁ = A_E M q̂ + W_d, F₁ = q̂ − k⁻ W₁.
    pub fn micro1_into(&mut self, q_hat: MatRef<'_, f64>, mut w1: MatMut<'_, f64>, mut f1: MatMut<'_, f64>) {
        let nt = q_hat.ncols();
        let n_b = self.n_boundary() as u64;
        // F₁ = q̂ − k⁻W₁: a multiply and a subtract per entry.
        self.flops += 2 * n_b * nt as u64;
        if self.dense {
            // W_d + A_E (M q̂).
            w1.copy_from(self.w_d.as_ref());
            self.dense_response(q_hat, w1.rb_mut(), Accum::Add);
        } else {
            // The sparse response, then + W_d.
            self.flops += nt as u64 * (self.op.sparse_response_flops() + n_b);
            self.op
                .sparse_response_into(q_hat, self.sparse_rhs.as_mut(), w1.rb_mut(), &mut self.sparse_scratch);
            for j in 0..nt {
                for (w, d) in col_mut(&mut w1, j).iter_mut().zip(self.w_d.col_as_slice(j)) {
                    *w += d;
                }
            }
        }
        let k = &self.op.layout.k;
        for j in 0..nt {
            let (q, w, f) = (col(q_hat, j), col(w1.rb(), j), col_mut(&mut f1, j));
            for (((f, q), k), w) in f.iter_mut().zip(q).zip(k).zip(w) {
                *f = q - k * w;
            }
        }
    }

    /// Macro forces 𝔼ᵀ M F (n_m × (N+1)): per interface and time point, the dot products of its
    /// modes (columns of the stored M𝔼, on the interface's rows: 𝔼 is zero elsewhere) with its
    /// rows of F. A handful of modes per interface is too thin a product for the matrix kernel
    /// (measured 0.7 GFLOP/s on the stratified scene at N = 1000).
    pub fn macro_forces_into(&mut self, f: MatRef<'_, f64>, mut out: MatMut<'_, f64>) {
        // A dot product of an interface's 2·n_pairs rows per mode and time point.
        let per_col: usize = self
            .macro_slots
            .iter()
            .zip(&self.op.layout.slots)
            .map(|(ms, slot)| 2 * (2 * slot.n_pairs) * ms.n_modes)
            .sum();
        self.flops += (per_col * f.ncols()) as u64;
        macro_forces_kernel(
            self.m_e.as_ref(),
            &self.macro_slots,
            &self.op.layout.slots,
            f,
            out.rb_mut(),
        );
    }

    /// Micro problem 2: W₂ = A_E M k⁻ 𝔼 w̃, F₂ = k⁻(𝔼 w̃ − W₂), for w̃ (n_m × (N+1)): two
    /// products, with A_E M k⁻ 𝔼 and the stored k⁻(𝔼 − A_E M k⁻ 𝔼). Without A_E, W₂ comes from
    /// one sparse solve with right-hand side Bᵀ M k⁻ 𝔼 w̃ for all time points.
    pub fn micro2_into(&mut self, w_tilde: MatRef<'_, f64>, mut w2: MatMut<'_, f64>, mut f2: MatMut<'_, f64>) {
        let (n_b, n_m, nt) = (self.n_boundary() as u64, self.n_macro() as u64, w_tilde.ncols() as u64);
        if !self.dense {
            // 𝔼 w̃, k⁻(𝔼 w̃), the sparse response, then F₂ = k⁻(𝔼 w̃ − W₂).
            self.flops += nt * (2 * n_b * n_m + n_b + self.op.sparse_response_flops() + 2 * n_b);
            let nt = w_tilde.ncols();
            matmul(f2.rb_mut(), Accum::Replace, self.e.as_ref(), w_tilde, 1.0, Par::Seq);
            let layout = &self.op.layout;
            let mut k_e_w = self.scratch.as_mut().subcols_mut(0, nt);
            for j in 0..nt {
                scale_into(col_mut(&mut k_e_w, j), &layout.k, col(f2.rb(), j));
            }
            self.op.sparse_response_into(
                self.scratch.as_ref().subcols(0, nt),
                self.sparse_rhs.as_mut(),
                w2.rb_mut(),
                &mut self.sparse_scratch,
            );
            let k = &self.op.layout.k;
            for j in 0..nt {
                let (w, f) = (col(w2.rb(), j), col_mut(&mut f2, j));
                for ((f, k), w) in f.iter_mut().zip(k).zip(w) {
                    *f = k * (*f - w);
                }
            }
            return;
        }
        // Two n_b × n_m by n_m × (N+1) products.
        self.flops += 2 * (2 * n_b * n_m * nt);
        matmul(
            w2.rb_mut(),
            Accum::Replace,
            self.a_mk_e.as_ref(),
            w_tilde,
            1.0,
            Par::Seq,
        );
        matmul(f2, Accum::Replace, self.f2_of_w.as_ref(), w_tilde, 1.0, Par::Seq);
    }
}

crate::multiversion! {
    /// [`SubdomainSolver::macro_forces_into`]'s dot products, compiled for the CPU's widest
    /// vector extension.
    fn macro_forces_kernel(
        m_e: MatRef<'_, f64>,
        macro_slots: &[MacroSlot],
        slots: &[crate::condensed::InterfaceSlot],
        f: MatRef<'_, f64>,
        out: MatMut<'_, f64>,
    ) {
        let mut out = out;
        for j in 0..f.ncols() {
            let (fj, oj) = (col(f, j), col_mut(&mut out, j));
            for (ms, slot) in macro_slots.iter().zip(slots) {
                let rows = slot.offset..slot.offset + 2 * slot.n_pairs;
                for (m, o) in oj[ms.first_col..ms.first_col + ms.n_modes].iter_mut().enumerate() {
                    *o = dot(&col(m_e, ms.first_col + m)[rows.clone()], &fj[rows.clone()]);
                }
            }
        }
    }
}
