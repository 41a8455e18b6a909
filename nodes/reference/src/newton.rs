//! Semi-smooth Newton on the Alart–Curnier augmented Lagrangian, one time step at a time.

use crate::numbering::*;
use crate::sparse::*;
use crate::verify::*;
use crate::{Attempt, LinearSolver, ReferenceError, ReferenceOptions, NONE};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Lu;
use faer::sparse::SparseColMat;
use faer::Mat;
use glissade_mechanics::assembly::stiffness_triplets;
use glissade_mechanics::laws::dot;
use glissade_mechanics::laws::Status;
use glissade_mechanics::model::{InterfaceKind, Model};
use glissade_mechanics::mortar::combine;
use glissade_mechanics::scales::{Scales, ROUND_OFF};
use std::collections::BTreeMap;

/// Variable Jacobian entries of one pair's two rows (u entries at the pair's
/// [`MergedPair::free`] entries).
#[derive(Debug, Clone, Default)]
pub(crate) struct PairJacobian {
    pub(crate) du_n: Vec<f64>,
    pub(crate) dln_n: f64,
    pub(crate) du_t: Vec<f64>,
    pub(crate) dln_t: f64,
    pub(crate) dlt_t: f64,
}

/// λ-diagonal shift of a Newton step whose matrix is singular ([`Problem::newton_step`]). The
/// λ rows are in N and their λ entries dimensionless (1 at a separated pair), next to u entries
/// of r·n ≈ E·w/h: a shift of 1e-6 is far above round-off of the pivots and far below the rest.
const SINGULAR_SHIFT: f64 = 1e-6;

/// State of one time step: merged displacement and λ per merged pair in (n, t) components.
#[derive(Clone)]
pub(crate) struct StepState {
    /// Unknowns: u_free then (λ_n, λ_t) per merged pair.
    pub(crate) x: Vec<f64>,
}

pub(crate) struct Problem<'m> {
    pub(crate) model: &'m Model,
    pub(crate) num: Numbering,
    pub(crate) n_dofs: usize,
    pub(crate) free: Vec<usize>,
    pub(crate) n_free: usize,
    pub(crate) k: Csr,
    /// The scene's scales of the convergence checks.
    pub(crate) scales: Scales,
    /// K_ff is singular: a part (or a rigid motion of one) is held by nothing but contact.
    pub(crate) floating: bool,
    pub(crate) pairs: Vec<MergedPair>,
    /// Per interface and pair: (merged pair, orientation sign) for contact interfaces.
    pub(crate) copies: Vec<Vec<(usize, f64)>>,
    /// Per merged constrained dof: the (subdomain, dof) giving its prescribed value.
    pub(crate) prescribed_source: Vec<(usize, usize)>,
    pub(crate) sub_k: Vec<Csr>,
    pub(crate) groups: Vec<PerfectGroup>,
    pub(crate) solver: StepSolver,
}

impl<'m> Problem<'m> {
    pub(crate) fn new(model: &'m Model, linear_solver: LinearSolver) -> Result<Self, ReferenceError> {
        let num = Numbering::new(model);
        let n_dofs = 2 * num.n_merged;
        let mut constrained = vec![false; n_dofs];
        let mut prescribed_source = vec![(NONE, NONE); n_dofs];
        let mut k_all = Vec::new();
        let mut sub_k = Vec::with_capacity(model.subdomains.len());
        for (s, sub) in model.subdomains.iter().enumerate() {
            for (d, &c) in sub.constrained.iter().enumerate() {
                let g = num.dof(s, d);
                if c && !constrained[g] {
                    constrained[g] = true;
                    prescribed_source[g] = (s, d);
                }
            }
            let t = stiffness_triplets(&sub.mesh, sub.material, model.plane)?;
            k_all.extend(t.iter().map(|&(i, j, v)| (num.dof(s, i), num.dof(s, j), v)));
            sub_k.push(Csr::from_triplets(sub.n_dofs(), t));
        }
        let mut free = vec![NONE; n_dofs];
        let mut n_free = 0;
        for d in 0..n_dofs {
            if !constrained[d] {
                free[d] = n_free;
                n_free += 1;
            }
        }
        let k = Csr::from_triplets(n_dofs, k_all);

        // Merged contact pairs, and the ties of non-matching perfect interfaces.
        let mut pairs: Vec<MergedPair> = Vec::new();
        let mut index: BTreeMap<(usize, usize), usize> = BTreeMap::new();
        let mut copies = vec![Vec::new(); model.interfaces.len()];
        for (ki, itf) in model.interfaces.iter().enumerate() {
            let (friction, gap, tie) = match &itf.kind {
                InterfaceKind::Contact { friction, gap } => (*friction, Some(gap), false),
                InterfaceKind::Perfect if itf.is_non_matching() => (0.0, None, true),
                InterfaceKind::Perfect => continue,
            };
            let g0 = |p: usize| gap.map_or(0.0, |g| g[p]);
            // The largest edge length about a pair (its weight, per unit of the plane's measure:
            // in axisymmetry a weight is ∫ N 2πr ds).
            let h = 1.5
                * itf
                    .weights
                    .iter()
                    .zip(&itf.coords)
                    .map(|(w, x)| w / model.plane.measure(*x))
                    .fold(0.0, f64::max);
            let e_mean = 0.5 * (model.subdomains[itf.a].material.e + model.subdomains[itf.b].material.e);
            for (p, &(na, nb)) in itf.pairs.iter().enumerate() {
                let ga = num.node(itf.a, na);
                let w = itf.weights[p];
                let terms: Vec<(usize, f64)> = itf
                    .trace(glissade_mechanics::model::Side::A, p)
                    .into_iter()
                    .map(|(n, c)| (num.node(itf.a, n), -c))
                    .chain(
                        itf.trace(glissade_mechanics::model::Side::B, p)
                            .into_iter()
                            .map(|(n, c)| (num.node(itf.b, n), c)),
                    )
                    .collect();
                // A conforming pair is one point, merged with its copies on other interfaces.
                let found = if itf.is_non_matching() {
                    None
                } else {
                    let gb = num.node(itf.b, nb);
                    if ga == gb {
                        return Err(ReferenceError::ContactPairGlued { interface: ki, pair: p });
                    }
                    let found = index
                        .get(&(ga, gb))
                        .map(|&m| (m, 1.0))
                        .or_else(|| index.get(&(gb, ga)).map(|&m| (m, -1.0)));
                    if found.is_none() {
                        index.insert((ga, gb), pairs.len());
                    }
                    found
                };
                match found {
                    Some((m, sign)) => {
                        let mp = &mut pairs[m];
                        let bad = |what| ReferenceError::InconsistentCopies {
                            interface: ki,
                            pair: p,
                            what,
                        };
                        if (mp.normal[0] - sign * itf.normals[p][0]).abs()
                            + (mp.normal[1] - sign * itf.normals[p][1]).abs()
                            > 1e-12
                        {
                            return Err(bad("the normal"));
                        }
                        if mp.friction != friction {
                            return Err(bad("the friction coefficient"));
                        }
                        if (mp.gap - g0(p)).abs() > 1e-12 * (1.0 + mp.gap.abs()) {
                            return Err(bad("the initial gap"));
                        }
                        mp.weight += w;
                        mp.r_base += e_mean * w / h;
                        copies[ki].push((m, sign));
                    }
                    None => {
                        copies[ki].push((pairs.len(), 1.0));
                        let fdofs: Vec<usize> = terms
                            .iter()
                            .flat_map(|&(node, _)| [free[2 * node], free[2 * node + 1]])
                            .collect();
                        if fdofs.iter().all(|&d| d == NONE) {
                            return Err(ReferenceError::ConstrainedPair { interface: ki, pair: p });
                        }
                        pairs.push(MergedPair {
                            terms,
                            normal: itf.normal(p),
                            tangent: itf.tangent(p),
                            friction,
                            gap: g0(p),
                            weight: w,
                            r_base: e_mean * w / h,
                            free: fdofs,
                            tie,
                        });
                    }
                }
            }
        }

        let k_ff = factorize_k_ff(&k, &free, n_free)?;
        let floating = k_ff.is_none();
        let solver = match (linear_solver, k_ff) {
            (LinearSolver::Condensed, Some(k_ff)) => StepSolver::Condensed(condensed_solver(k_ff, n_free, &pairs)),
            _ => StepSolver::SparseLu(lu_pattern(&k, &free, n_free, &pairs)?),
        };
        let groups = perfect_groups(model, &num);
        Ok(Self {
            model,
            num,
            n_dofs,
            free,
            n_free,
            scales: Scales::of(model),
            floating,
            k,
            pairs,
            copies,
            prescribed_source,
            sub_k,
            groups,
            solver,
        })
    }

    pub(crate) fn n_unknowns(&self) -> usize {
        self.n_free + 2 * self.pairs.len()
    }

    /// The state step 0 starts from: zero, except where K_ff is singular ([`Self::floating`]): there
    /// every pair with an open initial gap (g0 > 0) starts in contact and stuck,
    /// λ_n = −(F_s + r_max·g0), so that ν = λ_n + r g0 < 0 at u = 0 for every r factor up to
    /// `r_max` (λ_t = 0 is inside the cone). Pairs with g0 ≤ 0 start closed and stuck from zero
    /// already (ν = r g0 ≤ 0, and a tie counts as contact). The first Newton step is then the
    /// linear solve with every pair closed and stuck, regular wherever contact holds every part;
    /// from zero it would be the solve with the open pairs separated, singular for a part held
    /// only by contact across an open gap. Only the start changes, not the discrete problem.
    pub(crate) fn initial_state(&self, r_max: f64) -> StepState {
        let mut x = vec![0.0; self.n_unknowns()];
        if self.floating {
            for (m, mp) in self.pairs.iter().enumerate().filter(|(_, mp)| mp.gap > 0.0) {
                x[self.n_free + 2 * m] = -(self.scales.force + r_max * mp.r_base * mp.gap);
            }
        }
        StepState { x }
    }

    /// Merged load vector f(t) and prescribed values at time `t` (zero at free dofs).
    pub(crate) fn loads(&self, t: f64) -> (Vec<f64>, Vec<f64>) {
        let mut f = vec![0.0; self.n_dofs];
        let mut sub_u: Vec<Vec<f64>> = Vec::with_capacity(self.model.subdomains.len());
        for (s, sub) in self.model.subdomains.iter().enumerate() {
            let mut ud = vec![0.0; sub.n_dofs()];
            for case in &sub.loads {
                let phi = case.time.eval(t);
                for (d, &v) in case.force.iter().enumerate() {
                    if v != 0.0 {
                        f[self.num.dof(s, d)] += v * phi;
                    }
                }
                for (d, &v) in case.displacement.iter().enumerate() {
                    if sub.constrained[d] {
                        ud[d] += v * phi;
                    }
                }
            }
            sub_u.push(ud);
        }
        let prescribed = (0..self.n_dofs)
            .map(|g| {
                let (s, d) = self.prescribed_source[g];
                if s == NONE {
                    0.0
                } else {
                    sub_u[s][d]
                }
            })
            .collect();
        (f, prescribed)
    }

    /// Full merged displacement from the unknowns and the prescribed values.
    pub(crate) fn displacement(&self, x: &[f64], prescribed: &[f64]) -> Vec<f64> {
        (0..self.n_dofs)
            .map(|g| {
                if self.free[g] == NONE {
                    prescribed[g]
                } else {
                    x[self.free[g]]
                }
            })
            .collect()
    }

    /// Σ coef·u over the pair's terms: u_b − u_a on a conforming pair (the same bits).
    pub(crate) fn jump(&self, m: usize, u: &[f64]) -> [f64; 2] {
        let terms = &self.pairs[m].terms;
        [0, 1].map(|c| combine(terms.iter().copied(), |n| u[2 * n + c]))
    }

    /// Equilibrium residual on free dofs and the largest relative violation of the step's
    /// convergence checks, against the scene's scales ([`Scales`]).
    pub(crate) fn residual(&self, x: &[f64], u: &[f64], f: &[f64], slip_prev: &[f64]) -> (Vec<f64>, f64) {
        let mut ku = vec![0.0; self.n_dofs];
        self.k.matvec_into(u, &mut ku);
        let mut r_dof: Vec<f64> = ku.iter().zip(f).map(|(a, b)| a - b).collect();
        // Magnitude of the terms of each residual entry (for its round-off, [`ROUND_OFF`]).
        let mut mag = vec![0.0; self.n_dofs];
        self.k.abs_matvec_into(u, &mut mag);
        for (m, fv) in mag.iter_mut().zip(f) {
            *m += fv.abs();
        }
        for (m, mp) in self.pairs.iter().enumerate() {
            let (ln, lt) = (x[self.n_free + 2 * m], x[self.n_free + 2 * m + 1]);
            let lam = [
                ln * mp.normal[0] + lt * mp.tangent[0],
                ln * mp.normal[1] + lt * mp.tangent[1],
            ];
            for c in 0..2 {
                for &(node, k) in &mp.terms {
                    r_dof[2 * node + c] += k * lam[c];
                    mag[2 * node + c] += (k * lam[c]).abs();
                }
            }
        }
        let (fs, us) = (self.scales.force, self.scales.displacement);
        let mut r = vec![0.0; self.n_unknowns()];
        let mut worst = 0.0f64;
        for (g, &fg) in self.free.iter().enumerate() {
            if fg != NONE {
                r[fg] = r_dof[g];
                let v = (r_dof[g].abs() - ROUND_OFF * mag[g]).max(0.0);
                if v != 0.0 {
                    worst = worst.max(v / fs);
                }
            }
        }
        for (m, mp) in self.pairs.iter().enumerate() {
            let jump = self.jump(m, u);
            let (ln, lt) = (x[self.n_free + 2 * m], x[self.n_free + 2 * m + 1]);
            let gap = dot(jump, mp.normal) + mp.gap;
            let dslip = dot(jump, mp.tangent) - slip_prev[m];
            let sizes = mp.terms.iter().fold(0.0, |acc, &(node, k)| {
                acc + k.abs() * u[2 * node].abs().max(u[2 * node + 1].abs())
            });
            let round = ROUND_OFF * (sizes + mp.gap.abs() + slip_prev[m].abs());
            if mp.tie {
                // A tie: both components of the jump zero, any force.
                let beyond = |v: f64| (v.abs() - round).max(0.0) / us;
                worst = worst.max(beyond(gap)).max(beyond(dot(jump, mp.tangent)));
                continue;
            }
            let v = law_violations(ln, lt, gap, dslip, mp.friction, fs, us, round);
            worst = v.into_iter().fold(worst, f64::max);
        }
        (r, worst)
    }

    /// Largest displacement (mm) and largest nodal force (N: K u at every dof, supports included,
    /// and the contact forces) of a state.
    pub(crate) fn magnitudes(&self, x: &[f64], u: &[f64]) -> (f64, f64) {
        let mut ku = vec![0.0; self.n_dofs];
        self.k.matvec_into(u, &mut ku);
        let f_max = ku.iter().chain(&x[self.n_free..]).fold(0.0f64, |a, v| a.max(v.abs()));
        (u.iter().fold(0.0f64, |a, v| a.max(v.abs())), f_max)
    }

    /// Alart–Curnier residual rows of every pair, written into `r` (rows n_free..), their
    /// Jacobian entries and the statuses.
    pub(crate) fn contact_rows(
        &self,
        x: &[f64],
        u: &[f64],
        slip_prev: &[f64],
        r_factor: f64,
        r: &mut [f64],
    ) -> (Vec<PairJacobian>, Vec<Status>) {
        let mut jac = Vec::with_capacity(self.pairs.len());
        let mut status = Vec::with_capacity(self.pairs.len());
        for (m, mp) in self.pairs.iter().enumerate() {
            let rr = r_factor * mp.r_base;
            let jump = self.jump(m, u);
            let (ln, lt) = (x[self.n_free + 2 * m], x[self.n_free + 2 * m + 1]);
            let gap = dot(jump, mp.normal) + mp.gap;
            let dslip = dot(jump, mp.tangent) - slip_prev[m];
            let nu = ln + rr * gap;
            let tau = mp.friction * (-nu).max(0.0);
            let mu = lt + rr * dslip;
            // ∂(jump·v)/∂u at the pair's entries.
            let grad = |v: [f64; 2]| -> Vec<f64> {
                (0..mp.free.len())
                    .map(|q| {
                        let (c, k) = mp.entry(q);
                        k * v[c]
                    })
                    .collect()
            };
            let (gn, gt) = (grad(mp.normal), grad(mp.tangent));
            let zeros = vec![0.0; mp.free.len()];
            let mut pj = PairJacobian {
                du_n: zeros.clone(),
                du_t: zeros,
                ..PairJacobian::default()
            };
            if mp.tie {
                // C_n = −r (jump·n), C_t = −r (jump·t): the jump held at zero.
                pj.du_n = gn.iter().map(|g| -rr * g).collect();
                pj.du_t = gt.iter().map(|g| -rr * g).collect();
                r[self.n_free + 2 * m] = -rr * dot(jump, mp.normal);
                r[self.n_free + 2 * m + 1] = -rr * dot(jump, mp.tangent);
                jac.push(pj);
                status.push(Status::Stick);
                continue;
            }
            // Row λ_n: C_n = λ_n − min(0, ν).
            let c_n = if nu > 0.0 {
                pj.dln_n = 1.0;
                ln
            } else {
                pj.du_n = gn.iter().map(|g| -rr * g).collect();
                -rr * gap
            };
            // Row λ_t: C_t = λ_t − proj_[−τ, τ](λ_t + rΔs).
            let (c_t, st) = if nu > 0.0 {
                pj.dlt_t = 1.0;
                (lt, Status::Separated)
            } else if mu.abs() <= tau {
                pj.du_t = gt.iter().map(|g| -rr * g).collect();
                (-rr * dslip, Status::Stick)
            } else {
                let sf = mu.signum() * mp.friction;
                pj.du_t = gn.iter().map(|g| sf * rr * g).collect();
                pj.dln_t = sf;
                pj.dlt_t = 1.0;
                (lt + sf * nu, Status::Slip)
            };
            r[self.n_free + 2 * m] = c_n;
            r[self.n_free + 2 * m + 1] = c_t;
            jac.push(pj);
            status.push(st);
        }
        (jac, status)
    }

    /// ψ = ‖[R_u; C]‖² at `x`.
    pub(crate) fn merit(&self, x: &[f64], prescribed: &[f64], f: &[f64], slip_prev: &[f64], r_factor: f64) -> f64 {
        let u = self.displacement(x, prescribed);
        let (mut r, _) = self.residual(x, &u, f, slip_prev);
        self.contact_rows(x, &u, slip_prev, r_factor, &mut r);
        r.iter().map(|v| v * v).sum()
    }

    /// Solves J dx = −r for the Newton correction (in place in `r`). None if a factorisation
    /// fails or the correction is not finite.
    ///
    /// When J is singular (a factorisation fails or the correction is not finite), the step is
    /// solved once more with [`SINGULAR_SHIFT`] added to the λ diagonal of every pair's two rows
    /// (a proximal step in the multipliers). J is singular where the active contact constraints
    /// are linearly dependent: at a cross-point where four contact pairs close a cycle of node
    /// copies (two layers cut into sectors at the same angles, every pair in contact), the four
    /// jumps sum to zero around the cycle, so a force circulating around it changes no node's
    /// balance and the multipliers are determined only up to it. The shifted step keeps the
    /// multipliers near the last iterate along that freedom; the residual and the convergence
    /// checks are the unshifted ones, so a converged step solves the discrete problem exactly.
    /// Only a solve that fails takes the shifted one: every other step is as before, bit for bit.
    pub(crate) fn newton_step(&self, jac: &[PairJacobian], r: &mut [f64], work: &mut NewtonWork) -> Option<()> {
        let r0 = r.to_vec();
        if self.newton_step_shifted(jac, r, work, 0.0).is_some() {
            return Some(());
        }
        r.copy_from_slice(&r0);
        self.newton_step_shifted(jac, r, work, SINGULAR_SHIFT)
    }

    fn newton_step_shifted(
        &self,
        jac: &[PairJacobian],
        r: &mut [f64],
        work: &mut NewtonWork,
        shift: f64,
    ) -> Option<()> {
        let n_free = self.n_free;
        match &self.solver {
            StepSolver::SparseLu(pat) => {
                let values = &mut work.values;
                for (m, (mp, pj)) in self.pairs.iter().zip(jac).enumerate() {
                    let mut o = pat.offset[m];
                    for q in (0..mp.free.len()).filter(|&q| mp.free[q] != NONE) {
                        values[o] = pj.du_n[q];
                        o += 1;
                    }
                    values[o] = pj.dln_n + shift;
                    o += 1;
                    for q in (0..mp.free.len()).filter(|&q| mp.free[q] != NONE) {
                        values[o] = pj.du_t[q];
                        o += 1;
                    }
                    values[o] = pj.dln_t;
                    values[o + 1] = pj.dlt_t + shift;
                }
                let mat = SparseColMat::new_from_argsort(pat.symbolic.clone(), &pat.argsort, values).ok()?;
                let lu = Lu::try_new_with_symbolic(pat.lu_symbolic.clone(), mat.as_ref()).ok()?;
                let mut rhs = Mat::from_fn(r.len(), 1, |i, _| -r[i]);
                lu.solve_in_place(rhs.as_mut());
                glissade_mechanics::simd::clear_upper_state();
                for (i, ri) in r.iter_mut().enumerate() {
                    *ri = rhs[(i, 0)];
                }
            }
            StepSolver::Condensed(cs) => {
                let np2 = 2 * self.pairs.len();
                // a = K_ff⁻¹(−R_u).
                let mut a: Vec<f64> = r[..n_free].iter().map(|v| -v).collect();
                cs.k_ff.solve_vec_in_place(&mut a);
                // rhs = −C − C_u a.
                let mut rhs = Mat::<f64>::zeros(np2, 1);
                for (m, (mp, pj)) in self.pairs.iter().zip(jac).enumerate() {
                    let (rn, rt) = (2 * m, 2 * m + 1);
                    rhs[(rn, 0)] = -r[n_free + rn];
                    rhs[(rt, 0)] = -r[n_free + rt];
                    for (q, &fd) in mp.free.iter().enumerate().filter(|&(_, &fd)| fd != NONE) {
                        rhs[(rn, 0)] -= pj.du_n[q] * a[fd];
                        rhs[(rt, 0)] -= pj.du_t[q] * a[fd];
                    }
                }
                // S = C_λ − C_u Z, built as Sᵀ (a row of S is a contiguous column of Sᵀ: the
                // rows of Zᵀ are added to it in place) and solved transposed.
                let s_t = &mut work.s_t;
                s_t.fill(0.0);
                for (m, (mp, pj)) in self.pairs.iter().zip(jac).enumerate() {
                    let (rn, rt) = (2 * m, 2 * m + 1);
                    s_t[(rn, rn)] += pj.dln_n + shift;
                    s_t[(rn, rt)] += pj.dln_t;
                    s_t[(rt, rt)] += pj.dlt_t + shift;
                    for q in (0..mp.free.len()).filter(|&q| mp.free[q] != NONE) {
                        let (fd, cn, ct) = (mp.free[q], pj.du_n[q], pj.du_t[q]);
                        let z = cs.z_t.col(cs.position[fd]);
                        for (row, c) in [(rn, cn), (rt, ct)] {
                            if c != 0.0 {
                                for (s, &zj) in s_t.col_mut(row).iter_mut().zip(z.iter()) {
                                    *s -= c * zj;
                                }
                            }
                        }
                    }
                }
                let lu = faer::linalg::solvers::PartialPivLu::new(s_t.as_ref());
                lu.solve_transpose_in_place(rhs.as_mut());
                glissade_mechanics::simd::clear_upper_state();
                // Δu = K_ff⁻¹(−R_u − Bᵀ Δλ).
                let mut b: Vec<f64> = r[..n_free].iter().map(|v| -v).collect();
                for (m, mp) in self.pairs.iter().enumerate() {
                    let (dn, dt) = (rhs[(2 * m, 0)], rhs[(2 * m + 1, 0)]);
                    for (q, &fd) in mp.free.iter().enumerate() {
                        if fd != NONE {
                            let (c, k) = mp.entry(q);
                            b[fd] -= k * (mp.normal[c] * dn + mp.tangent[c] * dt);
                        }
                    }
                }
                cs.k_ff.solve_vec_in_place(&mut b);
                r[..n_free].copy_from_slice(&b);
                for i in 0..np2 {
                    r[n_free + i] = rhs[(i, 0)];
                }
            }
        }
        r.iter().all(|v| v.is_finite()).then_some(())
    }

    /// One attempt of a step: Newton from `start` with the attempt's r factor, line search and
    /// iteration budget. Ok((state, iterations, statuses)) or Err((iterations, worst violation)).
    pub(crate) fn newton(
        &self,
        start: &StepState,
        f: &[f64],
        prescribed: &[f64],
        slip_prev: &[f64],
        attempt: &Attempt,
        opts: &ReferenceOptions,
    ) -> Result<(StepState, usize, Vec<Status>), (usize, f64)> {
        let r_factor = attempt.r_factor;
        let mut x = start.x.clone();
        let mut work = NewtonWork::new(&self.solver, self.pairs.len());
        let mut worst = f64::INFINITY;
        // ψ of the last `window` iterates: the Armijo test compares with the largest of them.
        let mut recent: std::collections::VecDeque<f64> = std::collections::VecDeque::with_capacity(attempt.window);
        for it in 0..=attempt.max_iterations {
            let u = self.displacement(&x, prescribed);
            let (mut r, w) = self.residual(&x, &u, f, slip_prev);
            worst = w;
            let (jac, status) = self.contact_rows(&x, &u, slip_prev, r_factor, &mut r);
            if !w.is_finite() {
                return Err((it, w));
            }
            if w <= opts.tolerance {
                return Ok((StepState { x }, it, status));
            }
            if it == attempt.max_iterations {
                break;
            }
            let psi0: f64 = r.iter().map(|v| v * v).sum();
            if recent.len() == attempt.window.max(1) {
                recent.pop_front();
            }
            recent.push_back(psi0);
            let psi_ref = recent.iter().copied().fold(psi0, f64::max);
            if self.newton_step(&jac, &mut r, &mut work).is_none() {
                return Err((it + 1, worst));
            }
            // Backtracking on ψ = ‖[R_u; C]‖² (both in N): the semi-smooth Newton direction is a
            // descent direction of ψ where Φ is differentiable; full steps are taken whenever
            // they pass the Armijo test, so the local quadratic convergence is kept. With a
            // window of 1 the test is monotone (against this iterate's ψ); a longer window
            // (Grippo–Lampariello–Lucidi) lets ψ rise for a while, so that a step may move many
            // pairs across the kinks of their laws at once.
            let mut alpha = 1.0;
            let mut best = (f64::INFINITY, 1.0);
            for _ in 0..=opts.line_search_halvings {
                let trial: Vec<f64> = x.iter().zip(&r).map(|(xi, dx)| xi + alpha * dx).collect();
                let psi = self.merit(&trial, prescribed, f, slip_prev, r_factor);
                if psi < best.0 {
                    best = (psi, alpha);
                }
                if psi <= (1.0 - 1e-4 * alpha) * psi_ref {
                    break;
                }
                alpha *= 0.5;
            }
            let alpha = best.1;
            for (xi, dx) in x.iter_mut().zip(&r) {
                *xi += alpha * dx;
            }
        }
        Err((attempt.max_iterations, worst))
    }
}
