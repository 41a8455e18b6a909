//! The linear stage of the LATIN method on one subdomain (DESIGN §3), on the condensed operator:
//! micro problem 1, W₁ = A_E M q̂ + W_d, F₁ = q̂ − k⁻W₁ with q̂ = F̂ + k⁻Ŵ;
//! macro forces F̂ᴹ_{E,d} = 𝔼ᵀ M F₁; micro problem 2, W₂ = A_E M k⁻ 𝔼 w̃, F₂ = k⁻(𝔼 w̃ − W₂);
//! and the homogenized operator L_E = 𝔼ᵀ M k⁻ 𝔼 − (M k⁻ 𝔼)ᵀ A_E (M k⁻ 𝔼).
//!
//! Fields are column-major matrices, one row per boundary entry, one column per time point.

use crate::assembly::AssemblyError;
use crate::condensed::{BoundaryLayout, CondensedOperator};
use crate::model::{Interface, Model};
use crate::simd::{dot, matmul};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use std::sync::Arc;

/// The linear stage of the subdomains (DESIGN §3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinearStage {
    /// One dense product with the condensed A_E per micro problem.
    Condensed,
    /// No A_E: each micro problem is one multi-right-hand-side solve with the sparse factors of
    /// K_E + Bᵀk⁻MB for all time points (the paper's baseline).
    Sparse,
    /// PGD on a reduced basis per subdomain ([`crate::pgd`]).
    Pgd,
    /// Chosen per subdomain from its size ([`LinearStage::resolve`]).
    Auto,
}

impl LinearStage {
    pub const ALL: [LinearStage; 4] = [Self::Condensed, Self::Sparse, Self::Pgd, Self::Auto];

    /// The stage's name, as `solver.linear_stage` spells it.
    pub fn key(self) -> &'static str {
        match self {
            Self::Condensed => "condensed",
            Self::Sparse => "sparse",
            Self::Pgd => "pgd",
            Self::Auto => "auto",
        }
    }

    /// The stage a subdomain with n_b boundary entries uses: `Auto` resolves to `Condensed`, the
    /// fastest to a contact-traction error of 1e-3 on every measured case (docs/pgd.md, "Three linear
    /// stages, time to accuracy", with Anderson, N = 100 and N = 1000): stratified (n_b ≤ 328) condensed 2.18 s and
    /// 14.38 s, PGD 6.73 s and 55.93 s, sparse 29.77 s and 331.96 s; layered (n_b ≈ 960)
    /// condensed 3.61 s and 62.35 s, PGD 18.93 s and 214.58 s, sparse 30.24 s and 938.30 s. The
    /// PGD basis grows to a large fraction of n_b on both (188 of 328, 677 of about 960), so no
    /// boundary size measured favours it; it comes close only to 1e-2 at N = 100.
    pub fn resolve(self, _n_boundary: usize) -> LinearStage {
        match self {
            LinearStage::Auto => LinearStage::Condensed,
            other => other,
        }
    }
}

/// Default search direction per interface: k₀ = k0_factor · E/L_Γ, with E the geometric mean of
/// the two sides' [`Material::interface_modulus`] √(2G·M) (≈ Young's modulus for ν ≤ 0.3, the
/// neighbour's when both sides share a material) and L_Γ the interface length. MPa/mm.
///
/// [`Material::interface_modulus`]: crate::model::Material::interface_modulus
pub fn default_k0(model: &Model) -> Vec<f64> {
    model
        .interfaces
        .iter()
        .map(|itf| {
            let modulus = |s: usize| model.subdomains[s].material.interface_modulus(model.plane);
            let e = (modulus(itf.a) * modulus(itf.b)).sqrt();
            model.solver.k0_factor * e / itf.length
        })
        .collect()
}

/// Macro basis of an interface (DESIGN §2, §3): the affine fields u(x) = a + B(x − c) restricted
/// to its pairs (c the weighted centroid), in the order translation along t, translation along n,
/// rotation about the centroid, extension along t (s·t, s = (x − c)·t), then — on a curved
/// interface only — extension along n and the symmetric shear, with (t, n) the interface's
/// [`Interface::mean_frame`]. On a straight interface the last two vanish and the first four span
/// the polynomials of degree ≤ 1 in s of both components (the rotation is s·n): the paper's four
/// modes. With `degree` d > 1 the basis also holds (s/ℓ)^j·t and (s/ℓ)^j·n for 2 ≤ j ≤ d (ℓ the
/// half length; on a curved interface s is the arc length from the weighted mean position along
/// the pairs' order): degree 3 holds the traces of a bent slender layer (cubic deflection,
/// quadratic rotation of its sections), which the coarse problem then resolves in one step. Made
/// orthonormal for the lumped mass M by modified Gram–Schmidt (twice), with rank detection:
/// a vector whose norm after orthogonalisation falls below 1e-10 of its norm before (or of √L
/// for the translations, L·√L for the curved-only modes) is dropped, so a straight interface has
/// 1 to 2(d + 1) modes and a curved one up to 2(d + 1) + 2. Entry 2p+c is pair p, component c.
pub fn macro_basis(itf: &Interface, degree: usize) -> Vec<Vec<f64>> {
    let np = itf.n_pairs();
    let g = itf.centroid;
    let curved = itf.straight_normal().is_none();
    let (n, t) = itf.mean_frame();
    let half = 0.5 * itf.length.max(f64::MIN_POSITIVE);
    // Abscissa of each pair: along t on a straight interface, the arc length on a curved one.
    let abscissa: Vec<f64> = if curved {
        arc_abscissa(itf)
    } else {
        itf.coords
            .iter()
            .map(|x| (x[0] - g[0]) * t[0] + (x[1] - g[1]) * t[1])
            .collect()
    };
    let n_raw = 4 + 2 * degree.saturating_sub(1) + if curved { 2 } else { 0 };
    let mut raw = vec![vec![0.0; 2 * np]; n_raw];
    let extra = 4 + 2 * degree.saturating_sub(1);
    for p in 0..np {
        let r = [itf.coords[p][0] - g[0], itf.coords[p][1] - g[1]];
        let s = abscissa[p];
        let (rt, rn) = (r[0] * t[0] + r[1] * t[1], r[0] * n[0] + r[1] * n[1]);
        for c in 0..2 {
            raw[0][2 * p + c] = t[c];
            raw[1][2 * p + c] = n[c];
            raw[3][2 * p + c] = if curved { rt * t[c] } else { s * t[c] };
            for j in 2..=degree {
                let sj = (s / half).powi(j as i32);
                raw[4 + 2 * (j - 2)][2 * p + c] = sj * n[c];
                raw[5 + 2 * (j - 2)][2 * p + c] = sj * t[c];
            }
            if curved {
                raw[extra][2 * p + c] = rn * n[c];
                raw[extra + 1][2 * p + c] = rn * t[c] + rt * n[c];
            }
        }
        raw[2][2 * p] = -r[1];
        raw[2][2 * p + 1] = r[0];
    }
    let dot = |a: &[f64], b: &[f64]| -> f64 { (0..2 * np).map(|e| itf.weights[e / 2] * a[e] * b[e]).sum() };
    let scale = itf.length.max(f64::MIN_POSITIVE);
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(n_raw);
    for (m, mut v) in raw.into_iter().enumerate() {
        let norm0 = dot(&v, &v).sqrt();
        for _ in 0..2 {
            for b in &basis {
                let c = dot(&v, b);
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= c * y);
            }
        }
        let norm = dot(&v, &v).sqrt();
        // Translations have norm √L; the other modes' norms scale differently: compare to the raw
        // norm. The curved-only modes vanish on a nearly straight interface, where their raw norm
        // is round-off too: compare them to the size of an affine field over the interface.
        let reference = if m < 2 {
            scale.sqrt()
        } else if m >= extra {
            norm0.max(scale * scale.sqrt())
        } else {
            norm0
        };
        if norm > 1e-10 * reference && norm > 0.0 {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
        }
    }
    basis
}

/// Arc length of each pair of a curved interface along the pairs' order (chords between
/// consecutive pairs), measured from the weighted mean arc length.
fn arc_abscissa(itf: &Interface) -> Vec<f64> {
    let mut s = Vec::with_capacity(itf.n_pairs());
    let mut acc = 0.0;
    for p in 0..itf.n_pairs() {
        if p > 0 {
            let (a, b) = (itf.coords[p - 1], itf.coords[p]);
            acc += ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        }
        s.push(acc);
    }
    let total: f64 = itf.weights.iter().sum();
    let mean: f64 = s.iter().zip(&itf.weights).map(|(s, w)| s * w).sum::<f64>() / total;
    s.iter_mut().for_each(|v| *v -= mean);
    s
}

/// Slenderness from which `macro_degree = "auto"` gives an interface the degree-5 macro basis.
pub const SLENDER: f64 = 10.0;

/// Degree of an interface's macro basis: the scene's `solver.macro_degree`, or with "auto" 5 when
/// the interface is at least [`SLENDER`] times longer than one of its two subdomains is thick
/// (extent along the interface normal), else 1. Measured on three 100 × 1 mm layers in contact
/// under an end shear (the stability matrix's thin-layer bending case): degree 1 stops at 2000
/// iterations with a traction error of 6e-2, degree 3 converges in 1427, degree 5 in 483 (η ≤
/// 1e-7); a bent slender layer's traces are smooth polynomials of high degree along the interface,
/// which the coarse problem then resolves at once, while a compact subdomain's are not.
pub fn macro_degree(model: &Model, itf: &Interface) -> usize {
    if let Some(d) = model.solver.macro_degree {
        return d;
    }
    // A curved interface gets the affine modes (up to six); the slenderness rule reads the
    // thickness across a straight interface.
    let Some(normal) = itf.straight_normal() else {
        return 1;
    };
    let thickness = |s: usize| {
        let (lo, hi) =
            model.subdomains[s]
                .mesh
                .coords
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    let h = x[0] * normal[0] + x[1] * normal[1];
                    (lo.min(h), hi.max(h))
                });
        hi - lo
    };
    if itf.length >= SLENDER * thickness(itf.a).min(thickness(itf.b)) {
        5
    } else {
        1
    }
}

/// The macro basis of every interface of `model`, of its [`macro_degree`].
pub fn macro_bases(model: &Model) -> Vec<Vec<Vec<f64>>> {
    model
        .interfaces
        .iter()
        .map(|itf| macro_basis(itf, macro_degree(model, itf)))
        .collect()
}

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

/// Column `j` of a matrix with unit row stride (every field here), as a slice.
#[inline(always)]
fn col(m: MatRef<'_, f64>, j: usize) -> &[f64] {
    m.col(j)
        .try_as_col_major()
        .expect("fields have unit row stride")
        .as_slice()
}

#[inline(always)]
fn col_mut<'a>(m: &'a mut MatMut<'_, f64>, j: usize) -> &'a mut [f64] {
    m.rb_mut()
        .col_mut(j)
        .try_as_col_major_mut()
        .expect("fields have unit row stride")
        .as_slice_mut()
}

/// out[r] = d[r] · x[r].
#[inline(always)]
fn scale_into(out: &mut [f64], d: &[f64], x: &[f64]) {
    for ((o, d), x) in out.iter_mut().zip(d).zip(x) {
        *o = d * x;
    }
}

crate::multiversion! {
    /// End of the linear stage: s_new = s₁ + s₂ into (w1, f1), then the relaxation
    /// s ← μ s_new + (1 − μ) s into (w, f), in one pass (compiled for the CPU's widest vector
    /// extension).
    pub fn sum_relax_into(
        mu: f64,
        w1: MatMut<'_, f64>,
        f1: MatMut<'_, f64>,
        w2: MatRef<'_, f64>,
        f2: MatRef<'_, f64>,
        w: MatMut<'_, f64>,
        f: MatMut<'_, f64>,
    ) {
        let (mut w1, mut f1, mut w, mut f) = (w1, f1, w, f);
        for j in 0..w.ncols() {
            for (s1, s2, s) in [
                (col_mut(&mut w1, j), col(w2, j), col_mut(&mut w, j)),
                (col_mut(&mut f1, j), col(f2, j), col_mut(&mut f, j)),
            ] {
                for ((s1, s2), s) in s1.iter_mut().zip(s2).zip(s) {
                    *s1 += s2;
                    *s = mu * *s1 + (1.0 - mu) * *s;
                }
            }
        }
    }
}

/// s_new = s₁ + s₂ into (w1, f1).
pub fn sum_into(mut w1: MatMut<'_, f64>, mut f1: MatMut<'_, f64>, w2: MatRef<'_, f64>, f2: MatRef<'_, f64>) {
    for j in 0..w1.ncols() {
        for (s1, s2) in [(col_mut(&mut w1, j), col(w2, j)), (col_mut(&mut f1, j), col(f2, j))] {
            for (s1, s2) in s1.iter_mut().zip(s2) {
                *s1 += s2;
            }
        }
    }
}

/// The relaxation s ← μ s_new + (1 − μ) s, s_new = (w1, f1), into (w, f).
pub fn relax_into(mu: f64, w1: MatRef<'_, f64>, f1: MatRef<'_, f64>, mut w: MatMut<'_, f64>, mut f: MatMut<'_, f64>) {
    for j in 0..w.ncols() {
        for (s1, s) in [(col(w1, j), col_mut(&mut w, j)), (col(f1, j), col_mut(&mut f, j))] {
            for (s1, s) in s1.iter().zip(s) {
                *s = mu * s1 + (1.0 - mu) * *s;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod flop_tests {
    use super::*;
    /// core.2: loaded on its free end, clamped nowhere, a perfect and two contact interfaces (so
    /// three macro slots).
    const SUB: usize = 3;

    /// The small-three-layer model and the solver of its subdomain core.2 (also the PGD tests').
    pub(crate) fn model_and_solver(dense: bool) -> (Model, SubdomainSolver) {
        let model = crate::fixtures::small_three_layer();
        let k0 = default_k0(&model);
        let bases = macro_bases(&model);
        let solver = SubdomainSolver::with_dense(&model, SUB, &k0, &bases, dense).unwrap();
        (model, solver)
    }

    fn solver(dense: bool) -> SubdomainSolver {
        model_and_solver(dense).1
    }

    fn ramp(n: usize, m: usize) -> Mat<f64> {
        Mat::from_fn(n, m, |i, j| (i as f64 + 1.0).sin() * (j as f64 + 0.5))
    }

    /// Counts of one linear stage: micro 1, macro forces, micro 2.
    fn stage_counts(s: &mut SubdomainSolver) -> [u64; 3] {
        let (n_b, n_m, nt) = (s.n_boundary(), s.n_macro(), s.w_d.ncols());
        let (mut w, mut f, mut mf) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt), Mat::zeros(n_m, nt));
        let mut counts = [0; 3];
        let before = s.flops();
        s.micro1_into(ramp(n_b, nt).as_ref(), w.as_mut(), f.as_mut());
        counts[0] = s.flops() - before;
        s.macro_forces_into(f.as_ref(), mf.as_mut());
        counts[1] = s.flops() - before - counts[0];
        s.micro2_into(ramp(n_m, nt).as_ref(), w.as_mut(), f.as_mut());
        counts[2] = s.flops() - before - counts[0] - counts[1];
        counts
    }

    #[test]
    fn condensed_counts_are_the_formula() {
        let mut s = solver(true);
        // The setup's products are not counted.
        assert_eq!(s.flops(), 0);
        let (n_b, n_m, nt) = (s.n_boundary() as u64, s.n_macro() as u64, s.w_d.ncols() as u64);
        assert!(n_b > 0 && n_m > 0 && nt > 1);
        // Interfaces' rows: n_b is the sum of 2·n_pairs over the slots; each mode's dot product
        // runs over its interface's rows only.
        let mode_rows: u64 = s
            .macro_slots
            .iter()
            .zip(&s.op.layout.slots)
            .map(|(m, slot)| (2 * slot.n_pairs * m.n_modes) as u64)
            .sum();
        assert!(mode_rows < n_b * n_m, "𝔼 is block sparse: {mode_rows} vs {}", n_b * n_m);
        let counts = stage_counts(&mut s);
        // micro 1: M q̂ (n_b), A_E (M q̂) (2 n_b²), F₁ = q̂ − k⁻W₁ (2 n_b), per time point.
        assert_eq!(counts[0], nt * (n_b + 2 * n_b * n_b + 2 * n_b));
        assert_eq!(counts[1], 2 * mode_rows * nt);
        // micro 2: two n_b × n_m by n_m × nt products.
        assert_eq!(counts[2], 4 * n_b * n_m * nt);
        // The counter accumulates: a second stage adds the same again.
        let total = s.flops();
        assert_eq!(stage_counts(&mut s), counts);
        assert_eq!(s.flops(), 2 * total);
    }

    /// A solver moved to another time grid (the time-coarse start's coarse solve) is the solver
    /// built on that grid, bit for bit: its linear stage gives the same fields, dense or sparse.
    #[test]
    fn retimed_is_the_solver_built_on_that_grid() {
        for dense in [true, false] {
            let (model, fine) = model_and_solver(dense);
            let mut coarse_model = model.clone();
            coarse_model.time.n_steps = model.time.n_steps / 2;
            assert!(coarse_model.time.n_steps >= 2);
            let mut moved = fine.retimed(&coarse_model);
            let mut built = SubdomainSolver::with_dense(
                &coarse_model,
                SUB,
                &default_k0(&coarse_model),
                &macro_bases(&coarse_model),
                dense,
            )
            .unwrap();
            // The operator is shared, not rebuilt.
            assert!(Arc::ptr_eq(&moved.op, &fine.op));
            assert_eq!(moved.w_d, built.w_d);
            assert_eq!(moved.load_time, built.load_time);
            assert_eq!(
                (moved.e.clone(), moved.a_mk_e.clone()),
                (built.e.clone(), built.a_mk_e.clone())
            );
            assert_eq!(moved.l_e, built.l_e);
            assert_eq!(moved.w_d.ncols(), coarse_model.time.n_points());
            // The grids differ, so W_d does too (the loads vary in time).
            assert_ne!(moved.w_d.ncols(), fine.w_d.ncols());
            let (a, b) = (stage_fields(&mut moved), stage_fields(&mut built));
            assert!(a == b, "dense {dense}: the linear stage differs");
            assert_eq!(moved.flops(), built.flops());
        }
    }

    /// W₁, F₁, the macro forces, W₂ and F₂ of one linear stage from fixed inputs.
    fn stage_fields(s: &mut SubdomainSolver) -> [Mat<f64>; 5] {
        let (n_b, n_m, nt) = (s.n_boundary(), s.n_macro(), s.w_d.ncols());
        let (mut w1, mut f1, mut mf) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt), Mat::zeros(n_m, nt));
        let (mut w2, mut f2) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
        s.micro1_into(ramp(n_b, nt).as_ref(), w1.as_mut(), f1.as_mut());
        s.macro_forces_into(f1.as_ref(), mf.as_mut());
        s.micro2_into(ramp(n_m, nt).as_ref(), w2.as_mut(), f2.as_mut());
        [w1, f1, mf, w2, f2]
    }

    #[test]
    fn sparse_counts_are_nt_times_the_per_solve_count() {
        let mut s = solver(false);
        assert_eq!(s.flops(), 0);
        let (n_b, n_m, nt) = (s.n_boundary() as u64, s.n_macro() as u64, s.w_d.ncols() as u64);
        let n_free = s.op.n_free() as u64;
        let per_solve = s.op.sparse_response_flops();
        // One solve: at least the diagonal both ways plus the M q scatter of ≤ n_b entries, at
        // most a dense factor's 4·n(n+1)/2 − 2n.
        assert!(
            per_solve > 2 * n_free && per_solve <= 2 * n_free * n_free + 2 * n_b,
            "{per_solve}"
        );
        let counts = stage_counts(&mut s);
        // micro 1: one solve per time point, + W_d (n_b) and F₁ (2 n_b).
        assert_eq!(counts[0], nt * (per_solve + 3 * n_b));
        // micro 2: 𝔼 w̃ (2 n_b n_m), k⁻ (n_b), one solve, F₂ (2 n_b) per time point.
        assert_eq!(counts[2], nt * (2 * n_b * n_m + n_b + per_solve + 2 * n_b));
        // The same macro-force kernel as the condensed stage.
        assert_eq!(counts[1], stage_counts(&mut solver(true))[1]);
        // A boundary response of m columns is m solves.
        let before = s.flops();
        let mut out = Mat::zeros(n_b as usize, 3);
        s.boundary_response_into(ramp(n_b as usize, 3).as_ref(), out.as_mut());
        assert_eq!(s.flops() - before, 3 * per_solve);
    }
}
