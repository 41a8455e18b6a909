//! The solution per interface and subdomain from the merged unknowns (module docs of the crate:
//! "Output").

use crate::newton::*;
use crate::numbering::*;
use crate::sparse::*;
use crate::{ContactSolution, LinearSolver, ReferenceSolution};
use faer::Mat;
use glissade_mechanics::laws::Status;
use glissade_mechanics::local::InterfaceFields;
use glissade_mechanics::mortar::combine;

pub(crate) type StepOutput = (Vec<f64>, Vec<f64>, Vec<Status>, Vec<f64>);

pub(crate) fn postprocess(
    pb: &Problem<'_>,
    states: Vec<StepOutput>,
    newton_iterations: Vec<usize>,
    r_factor_used: Vec<f64>,
) -> ReferenceSolution {
    let model = pb.model;
    let nt = states.len();
    let mut u_out: Vec<Mat<f64>> = model.subdomains.iter().map(|s| Mat::zeros(s.n_dofs(), nt)).collect();
    let mut fields: Vec<InterfaceFields> = model
        .interfaces
        .iter()
        .map(|itf| InterfaceFields::zeros(itf.n_pairs(), nt))
        .collect();
    let linear_solver = match pb.solver {
        StepSolver::Condensed(_) => LinearSolver::Condensed,
        StepSolver::SparseLu(_) => LinearSolver::SparseLu,
    };
    let mut contact: Vec<Option<ContactSolution>> = model
        .interfaces
        .iter()
        .map(|itf| {
            itf.is_contact().then(|| ContactSolution {
                lambda: Mat::zeros(2 * itf.n_pairs(), nt),
                jump: Mat::zeros(2 * itf.n_pairs(), nt),
                status: vec![Status::Separated; itf.n_pairs() * nt],
            })
        })
        .collect();
    let n_nodes_all: usize = model.subdomains.iter().map(|s| s.mesh.coords.len()).sum();
    for (i, (u, x, status, _)) in states.iter().enumerate() {
        // Subdomain displacements and interface residual forces K_s u_s − f_s.
        let t = model.time.t(i);
        let mut node_force = vec![[0.0f64; 2]; n_nodes_all];
        for (s, sub) in model.subdomains.iter().enumerate() {
            let us: Vec<f64> = (0..sub.n_dofs()).map(|d| u[pb.num.dof(s, d)]).collect();
            for (d, &v) in us.iter().enumerate() {
                u_out[s][(d, i)] = v;
            }
            let mut r = vec![0.0; sub.n_dofs()];
            pb.sub_k[s].matvec_into(&us, &mut r);
            for case in &sub.loads {
                let phi = case.time.eval(t);
                for (rd, &fv) in r.iter_mut().zip(&case.force) {
                    *rd -= fv * phi;
                }
            }
            for (node, nf) in node_force[pb.num.node_offset[s]..][..sub.mesh.coords.len()]
                .iter_mut()
                .enumerate()
            {
                *nf = [r[2 * node], r[2 * node + 1]];
            }
        }
        // Contact copies: equal traction λ_m / W_m on every copy; the pairs of a non-matching
        // perfect interface likewise (each its own constraint), side b's force spread over its
        // projection's nodes.
        for (ki, itf) in model.interfaces.iter().enumerate() {
            if pb.copies[ki].is_empty() {
                continue;
            }
            let np = itf.n_pairs();
            for (p, &(m, sign)) in pb.copies[ki].iter().enumerate() {
                let mp = &pb.pairs[m];
                let (ln, lt) = (x[pb.n_free + 2 * m], x[pb.n_free + 2 * m + 1]);
                let traction = [
                    sign * (ln * mp.normal[0] + lt * mp.tangent[0]) / mp.weight,
                    sign * (ln * mp.normal[1] + lt * mp.tangent[1]) / mp.weight,
                ];
                let w = itf.weights[p];
                let a_terms: Vec<(usize, f64)> = itf
                    .trace(glissade_mechanics::model::Side::A, p)
                    .into_iter()
                    .map(|(n, k)| (pb.num.node_offset[itf.a] + n, k))
                    .collect();
                let b_terms: Vec<(usize, f64)> = itf
                    .trace(glissade_mechanics::model::Side::B, p)
                    .into_iter()
                    .map(|(n, k)| (pb.num.node_offset[itf.b] + n, k))
                    .collect();
                let fl = &mut fields[ki];
                for c in 0..2 {
                    let trace =
                        |terms: &[(usize, f64)]| combine(terms.iter().copied(), |n| u[2 * pb.num.merged[n] + c]);
                    let (wa, wb) = (trace(&a_terms), trace(&b_terms));
                    fl.w_a[(2 * p + c, i)] = wa;
                    fl.w_b[(2 * p + c, i)] = wb;
                    fl.f_a[(2 * p + c, i)] = traction[c];
                    fl.f_b[(2 * p + c, i)] = -traction[c];
                    if let Some(cs) = contact[ki].as_mut() {
                        cs.lambda[(2 * p + c, i)] = w * traction[c];
                        cs.jump[(2 * p + c, i)] = wb - wa;
                    }
                    for &(n, k) in &a_terms {
                        node_force[n][c] -= k * (w * traction[c]);
                    }
                    for &(n, k) in &b_terms {
                        node_force[n][c] += k * (w * traction[c]);
                    }
                }
                if let Some(cs) = contact[ki].as_mut() {
                    cs.status[p + np * i] = status[m];
                }
            }
        }
        // Perfect copies: minimum-M-norm distribution of what is left at each group's nodes.
        for g in &pb.groups {
            let nv = g.vertices.len();
            for c in 0..2 {
                let rv: Vec<f64> = g.vertices.iter().map(|v| node_force[v.0][c]).collect();
                let mean = rv.iter().sum::<f64>() / nv as f64;
                let b = nalgebra::DVector::from_iterator(nv, rv.iter().map(|v| v - mean));
                let phi = g.lu.solve(&b).unwrap_or_else(|| nalgebra::DVector::zeros(nv));
                for &PerfectEdge {
                    interface: ki,
                    pair: p,
                    va: a,
                    vb: bv,
                    weight: w,
                } in &g.edges
                {
                    let force = w * (phi[a] - phi[bv]);
                    let fl = &mut fields[ki];
                    fl.f_a[(2 * p + c, i)] = force / w;
                    fl.f_b[(2 * p + c, i)] = -force / w;
                    let itf = &model.interfaces[ki];
                    let (na, nb) = itf.pairs[p];
                    fl.w_a[(2 * p + c, i)] = u[pb.num.dof(itf.a, 2 * na + c)];
                    fl.w_b[(2 * p + c, i)] = u[pb.num.dof(itf.b, 2 * nb + c)];
                }
            }
        }
    }
    ReferenceSolution {
        u: u_out,
        interfaces: fields,
        contact,
        newton_iterations,
        r_factor_used,
        linear_solver,
    }
}
