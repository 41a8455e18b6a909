//! Kernel benchmark: one 30 × 30 mm subdomain of 20 × 20 QUA8 (E = 130 000 MPa, ν = 0.2, plane
//! strain) with all four sides as interfaces (n_b = 2·4·41 = 328, lumped edge weights,
//! k⁻ = E/30). Times assembly, sparse factorisation, A_E construction and the linear stage's
//! dense product A_E · (M q) for N + 1 = 1001 time points, and compares the latter's flop rate with
//! the machine's dense matrix-product rate.
//!
//! Run: `cargo bench -p glissade-mechanics --bench kernel` (release build). Every timed section
//! is repeated and the minimum is reported.

use std::hint::black_box;
use std::time::{Duration, Instant};

use faer::{Accum, Mat, Par};
use glissade_mechanics::assembly::{stiffness_triplets, SparseSpd, SupernodalThreshold};
use glissade_mechanics::condensed::{BoundaryLayout, CondensedOperator, InterfaceSlot};
use glissade_mechanics::element;
use glissade_mechanics::mesh::{BlockSide, Mesh};
use glissade_mechanics::model::{Material, Plane, Side, Subdomain};
use glissade_mechanics::simd::matmul;

/// Minimum wall time of `runs` calls of `f` (after one warm-up call).
fn min_time<T>(runs: usize, mut f: impl FnMut() -> T) -> Duration {
    black_box(f());
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            black_box(f());
            start.elapsed()
        })
        .min()
        .unwrap_or_default()
}

/// Boundary layout with every side of the block as one interface (one copy of each corner per side).
fn four_side_layout(mesh: &Mesh, k: f64) -> BoundaryLayout {
    let (mut dofs, mut mass, mut ks, mut slots) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (interface, side) in BlockSide::ALL.into_iter().enumerate() {
        let nodes = mesh.side_nodes(side);
        let mut w = vec![0.0; nodes.len()];
        for (e, edge) in mesh.sides[side as usize].iter().enumerate() {
            let x: [[f64; 2]; 3] = std::array::from_fn(|j| mesh.coords[edge[j]]);
            for (j, m) in element::edge_lumped_mass(&x, Plane::Strain).into_iter().enumerate() {
                w[2 * e + j] += m;
            }
        }
        slots.push(InterfaceSlot {
            interface,
            side: Side::A,
            offset: dofs.len(),
            n_pairs: nodes.len(),
        });
        for (p, &node) in nodes.iter().enumerate() {
            for c in 0..2 {
                dofs.push(2 * node + c);
                mass.push(w[p]);
                ks.push(k);
            }
        }
    }
    let n_b = dofs.len();
    BoundaryLayout {
        start: (0..=n_b).collect(),
        dofs,
        coefs: vec![1.0; n_b],
        mass,
        k: ks,
        slots,
    }
}

fn gflops(flops: f64, t: Duration) -> f64 {
    flops / t.as_secs_f64() / 1e9
}

fn main() {
    let material = Material { e: 130_000.0, nu: 0.2 };
    let plane = Plane::Strain;
    let mesh = Mesh::rectangle([0.0, 30.0], [0.0, 30.0], 20, 20);
    let n_dofs = 2 * mesh.n_nodes();
    let layout = four_side_layout(&mesh, material.e / 30.0);
    let n_b = layout.len();
    assert_eq!(n_b, 328);
    let sub = Subdomain {
        name: "bench".into(),
        mesh: mesh.clone(),
        material,
        constrained: vec![false; n_dofs],
        loads: Vec::new(),
    };
    let n_t = 1001;

    // Assembly.
    let t_assembly = min_time(10, || stiffness_triplets(&mesh, material, plane).expect("valid mesh"));

    // Factorisation of K + Bᵀ k M B (no constrained dofs: the k⁻ terms block rigid modes),
    // symbolic + numeric, as `CondensedOperator::new` does.
    let mut triplets = stiffness_triplets(&mesh, material, plane).expect("valid mesh");
    for (b, &d) in layout.dofs.iter().enumerate() {
        triplets.push((d, d, layout.k[b] * layout.mass[b]));
    }
    let t_factor = min_time(10, || {
        SparseSpd::factorize_supernodal(n_dofs, &triplets, "bench").expect("SPD")
    });
    let factor = SparseSpd::factorize_supernodal(n_dofs, &triplets, "bench").expect("SPD");

    // A_E construction (assembly + factorisation + n_b-column solve + gather).
    let t_condense = min_time(5, || {
        CondensedOperator::new(&sub, plane, layout.clone()).expect("operator")
    });
    let op = CondensedOperator::new(&sub, plane, layout.clone()).expect("operator");

    // Linear stage as one dense product: W = A_E · (M q), n_b × n_b times n_b × 1001.
    let mq = Mat::<f64>::from_fn(n_b, n_t, |i, j| ((i * 7 + j * 13) % 17) as f64 / 17.0 - 0.5);
    let mut w = Mat::<f64>::zeros(n_b, n_t);
    let flops_apply = 2.0 * (n_b * n_b * n_t) as f64;

    // Baseline: the same linear stage as 1001 sparse solves (forward/backward with the factors).
    let mut rhs = Mat::<f64>::zeros(n_dofs, n_t);
    let t_sparse = min_time(5, || {
        rhs.fill(0.0);
        for (b, &d) in layout.dofs.iter().enumerate() {
            for j in 0..n_t {
                rhs[(d, j)] += layout.mass[b] * mq[(b, j)];
            }
        }
        factor.solve_in_place(&mut rhs);
        rhs[(0, 0)]
    });

    // The same factorisation and solve with faer's simplicial variant (its own choice for this
    // matrix, `SparseSpd::factorize`) against the supernodal one the condensed operator uses.
    let simplicial =
        || SparseSpd::factorize_with(n_dofs, &triplets, "bench", SupernodalThreshold::FORCE_SIMPLICIAL).expect("SPD");
    let t_factor_simplicial = min_time(10, simplicial);
    let factor_simplicial = simplicial();
    assert!(factor.is_supernodal() && !factor_simplicial.is_supernodal());
    // The same n_b-column solve as A_E's with the simplicial factor (faer's sparse sweeps,
    // baseline SSE code), right after a small dense product: faer's own product (its AVX-512
    // kernels leave the vector registers' upper halves in use, and SSE code then runs with a
    // dependency on them) against the crate's `matmul`, which clears them
    // (`simd::clear_upper_state`). Interleaved, min over rounds.
    let small_a = Mat::<f64>::from_fn(64, 64, |i, j| ((i + j) % 5) as f64);
    let small_b = Mat::<f64>::from_fn(64, 8, |i, j| ((i * j) % 3) as f64);
    let mut small_c = Mat::<f64>::zeros(64, 8);
    let mut cols = Mat::<f64>::zeros(n_dofs, n_b);
    let mut solve_after = |clear: bool| {
        min_time(5, || {
            // faer's product, then (the crate's `matmul`) the registers' upper halves cleared.
            faer::linalg::matmul::matmul(
                small_c.as_mut(),
                Accum::Replace,
                small_a.as_ref(),
                small_b.as_ref(),
                1.0,
                Par::Seq,
            );
            if clear {
                glissade_mechanics::simd::clear_upper_state();
            }
            cols.fill(0.0);
            for (c, &d) in layout.dofs.iter().enumerate() {
                cols[(d, c)] = 1.0;
            }
            factor_simplicial.solve_in_place(&mut cols);
            cols[(0, 0)]
        })
    };
    let (mut t_dirty, mut t_clean) = (Duration::MAX, Duration::MAX);
    for _ in 0..5 {
        t_dirty = t_dirty.min(solve_after(false));
        t_clean = t_clean.min(solve_after(true));
    }
    let mut t_solve_simplicial = Duration::MAX;
    let mut t_solve_supernodal = Duration::MAX;
    for _ in 0..5 {
        for (f, t) in [
            (&factor_simplicial, &mut t_solve_simplicial),
            (&factor, &mut t_solve_supernodal),
        ] {
            *t = (*t).min(min_time(3, || {
                cols.fill(0.0);
                for (c, &d) in layout.dofs.iter().enumerate() {
                    cols[(d, c)] = 1.0;
                }
                f.solve_in_place(&mut cols);
                cols[(0, 0)]
            }));
        }
    }

    // Machine's dense product rate: 1000 × 1000 × 1000, sequential.
    let n = 1000;
    let a = Mat::<f64>::from_fn(n, n, |i, j| ((i + 3 * j) % 11) as f64 - 5.0);
    let b = Mat::<f64>::from_fn(n, n, |i, j| ((2 * i + j) % 7) as f64 - 3.0);
    let mut c = Mat::<f64>::zeros(n, n);
    // The two products are timed interleaved (min over rounds), so that both see the same machine
    // state (frequency, other processes) and their ratio is meaningful on a shared machine.
    let (mut t_apply, mut t_peak) = (Duration::MAX, Duration::MAX);
    for _ in 0..15 {
        t_apply = t_apply.min(min_time(5, || {
            matmul(w.as_mut(), Accum::Replace, op.a.as_ref(), mq.as_ref(), 1.0, Par::Seq);
            w[(0, 0)]
        }));
        t_peak = t_peak.min(min_time(1, || {
            matmul(c.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, Par::Seq);
            c[(0, 0)]
        }));
    }
    let flops_peak = 2.0 * (n * n * n) as f64;

    let (rate_apply, rate_peak) = (gflops(flops_apply, t_apply), gflops(flops_peak, t_peak));
    let ms = |t: Duration| t.as_secs_f64() * 1e3;
    println!(
        "subdomain 30 × 30 mm, 20 × 20 QUA8: {} nodes, {n_dofs} dofs, n_b = {n_b}, N + 1 = {n_t}",
        mesh.n_nodes()
    );
    println!("{:<46} {:>10} {:>10}", "section (min of runs)", "ms", "GFLOP/s");
    println!(
        "{:<46} {:>10.3} {:>10}",
        "assembly (stiffness_triplets)",
        ms(t_assembly),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        "factorisation (SparseSpd::factorize_supernodal)",
        ms(t_factor),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        "A_E construction (CondensedOperator::new)",
        ms(t_condense),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10.2}",
        format!("A_E · (M q), {n_b}×{n_b} · {n_b}×{n_t}, Par::Seq"),
        ms(t_apply),
        rate_apply
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        format!("same by {n_t} sparse solves (baseline)"),
        ms(t_sparse),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10.2}",
        "dense 1000³ matmul, Par::Seq",
        ms(t_peak),
        rate_peak
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        format!("{n_b}-column simplicial solve after faer's matmul"),
        ms(t_dirty),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        format!("{n_b}-column simplicial solve after simd::matmul"),
        ms(t_clean),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        "factorisation, faer's simplicial variant",
        ms(t_factor_simplicial),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        format!("{n_b}-column solve, simplicial"),
        ms(t_solve_simplicial),
        ""
    );
    println!(
        "{:<46} {:>10.3} {:>10}",
        format!("{n_b}-column solve, supernodal"),
        ms(t_solve_supernodal),
        ""
    );
    println!("A_E product rate / dense peak rate = {:.2}", rate_apply / rate_peak);
    println!(
        "sparse-solve linear stage / A_E product time = {:.1}×",
        t_sparse.as_secs_f64() / t_apply.as_secs_f64()
    );
    println!(
        "solve after faer's matmul / after simd::matmul (upper halves cleared) = {:.2}×",
        t_dirty.as_secs_f64() / t_clean.as_secs_f64()
    );
    println!(
        "{n_b}-column solve simplicial / supernodal = {:.2}×",
        t_solve_simplicial.as_secs_f64() / t_solve_supernodal.as_secs_f64()
    );
}
