//! Iteration benchmark: LATIN iterations of a scene (default the stratified scene) run in one
//! thread from the crate's kernels (the calls the nodes make, without messages), timed per stage,
//! with the machine's one-thread dense-product rate and read bandwidth measured in the same run.
//!
//! Run: `cargo bench --bench iteration -- [scene.toml] [points=N+1]
//! [iterations=K] [kernels=baseline|avx2|avx512]` (release build; the element-wise kernels at
//! the CPU's widest vector extension unless `kernels=` lowers it). The first two iterations
//! (μ = 1, first touch of every buffer) are left out of the figures.

#[path = "../nodes/mechanics/tests/support/latin.rs"]
mod latin;

use faer::{Accum, Mat, Par};
use glissade_mechanics::simd::matmul;
use latin::{Latin, STAGES};
use std::time::{Duration, Instant};

// Full boundary fields one plain iteration moves per subdomain, the count `glissade bench` uses
// too, derived call by call where it is defined; this loop makes the same calls
// (`tests/support/latin.rs`), without Anderson acceleration, which it does not run.
use glissade_mechanics::FIELD_PASSES;

/// One-thread GFLOP/s of (m × m) · (m × n), best of repeated timings over ≥ 0.3 s.
fn product_rate(m: usize, n: usize) -> f64 {
    let a = Mat::<f64>::from_fn(m, m, |i, j| 1.0 / (1.0 + (i + 2 * j) as f64));
    let b = Mat::<f64>::from_fn(m, n, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0);
    let mut c = Mat::<f64>::zeros(m, n);
    let mut best = Duration::MAX;
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < 0.3 {
        let t = Instant::now();
        matmul(c.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, Par::Seq);
        best = best.min(t.elapsed());
    }
    std::hint::black_box(&c);
    2.0 * (m * m * n) as f64 / best.as_secs_f64() / 1e9
}

/// One-thread read bandwidth (GB/s) of a 256 MiB buffer, best of three passes.
fn read_bandwidth() -> f64 {
    let n: usize = 32 << 20;
    let buf: Vec<f64> = (0..n).map(|i| (i % 13) as f64).collect();
    let mut best = 0.0f64;
    for _ in 0..3 {
        let t = Instant::now();
        let sum = glissade_mechanics::simd::sum(&buf);
        let s = t.elapsed().as_secs_f64();
        std::hint::black_box(sum);
        best = best.max((n * 8) as f64 / s / 1e9);
    }
    best
}

fn main() {
    let mut scene = format!("{}/launch/scenes/stratified.toml", env!("CARGO_MANIFEST_DIR"));
    let (mut points, mut iterations) = (None, 30usize);
    for arg in std::env::args().skip(1).filter(|a| !a.starts_with("--")) {
        if let Some(v) = arg.strip_prefix("points=") {
            points = Some(v.parse::<usize>().expect("points=N+1, an integer ≥ 2"));
        } else if let Some(v) = arg.strip_prefix("iterations=") {
            iterations = v.parse::<usize>().expect("iterations=K, an integer ≥ 3");
        } else if let Some(v) = arg.strip_prefix("kernels=") {
            use glissade_mechanics::simd::{set_process_level, Level};
            set_process_level(Some(match v {
                "baseline" => Level::Baseline,
                "avx2" => Level::Avx2,
                "avx512" => Level::Avx512,
                _ => panic!("kernels=baseline|avx2|avx512, not `{v}`"),
            }));
        } else {
            scene = arg;
        }
    }
    assert!(iterations >= 3, "iterations=K needs K ≥ 3 (two warm-up iterations)");
    let text = std::fs::read_to_string(&scene).unwrap_or_else(|e| panic!("cannot read {scene}: {e}"));
    let mut model = glissade_scene::load_str(&text, &scene)
        .unwrap_or_else(|e| panic!("{e}"))
        .model;
    if let Some(p) = points {
        assert!(p >= 2, "points=N+1 needs at least 2 time points");
        model.time.n_steps = p - 1;
    }
    let nt = model.time.n_points();
    let t_setup = Instant::now();
    let mut latin = Latin::new(model);
    let setup = t_setup.elapsed();
    for _ in 0..2 {
        latin.iterate();
    }
    latin.stage_time = [Duration::ZERO; 6];
    let t_run = Instant::now();
    let mut last = None;
    for _ in 2..iterations {
        last = Some(latin.iterate());
    }
    let run = t_run.elapsed();
    let timed = (iterations - 2) as f64;
    let ms = |d: Duration| 1e3 * d.as_secs_f64() / timed;

    let sizes: Vec<(usize, usize)> = latin.solvers.iter().map(|s| (s.n_boundary(), s.n_macro())).collect();
    let largest = sizes.iter().map(|x| x.0).max().unwrap_or(0);
    let flops: f64 = sizes
        .iter()
        .map(|&(b, m)| {
            let (b, m, t) = (b as f64, m as f64, nt as f64);
            2.0 * b * b * t + 3.0 * 2.0 * b * m * t
        })
        .sum();
    let bytes: f64 = sizes
        .iter()
        .map(|&(b, m)| 8.0 * (b * b + 2 * b * m + FIELD_PASSES * b * nt) as f64)
        .sum();
    let rate = product_rate(largest, nt);
    let bandwidth = read_bandwidth();
    let linear = latin.stage_time[0] + latin.stage_time[1] + latin.stage_time[3];
    let linear_gflops = flops * timed / linear.as_secs_f64() / 1e9;
    let bound_ms = 1e3 * bytes / (bandwidth * 1e9);
    let per_it = ms(run);

    println!(
        "scene {scene}: {} subdomains (largest boundary {largest}), N + 1 = {nt}, setup {:.2} s; {} iterations timed after 2",
        sizes.len(),
        setup.as_secs_f64(),
        iterations - 2
    );
    if let Some(s) = last {
        println!(
            "last iteration: η = {:.3e}, contact indicator {:.3e}",
            s.eta(),
            s.contact_indicator()
        );
    }
    println!(
        "{:<40} {:>12}",
        format!(
            "stage (one thread, {} kernels)",
            glissade_mechanics::simd::level().name()
        ),
        "ms/iteration"
    );
    for (name, t) in STAGES.iter().zip(latin.stage_time) {
        println!("{name:<40} {:>12.3}", ms(t));
    }
    println!("{:<40} {:>12.3}", "iteration", per_it);
    // The error estimate's share: the interface node sums the step of the contact forces of
    // both sides as they arrive (`force_step_sums`, here against the current forces as the
    // previous ones: the same pass), then fits 20 residuals and 10 steps and, once calibrated,
    // takes a mean over 25 ratios.
    let weights = latin.model.time.trapezoid_weights();
    let t_est = Instant::now();
    let mut sink = 0.0;
    for _ in 0..(iterations - 2) {
        for (itf, f) in latin.model.interfaces.iter().zip(&latin.interface_fields) {
            if itf.is_contact() {
                for side in [&f.f_a, &f.f_b] {
                    let st = glissade_mechanics::local::force_step_sums(
                        &itf.weights,
                        &weights,
                        side.as_ref(),
                        side.as_ref(),
                    );
                    sink += st.num + st.den + st.max_step + st.max_force;
                }
            }
        }
        // A whole estimate's life up to its calibrated stage, every iteration: far more pushes
        // than the one a run makes per iteration, so an upper bound of the estimate's cost.
        let mut e = glissade_mechanics::estimate::ErrorEstimate::default();
        let pushes = glissade_mechanics::estimate::RATE_WINDOW + glissade_mechanics::estimate::CALIBRATION_MIN;
        for k in 0..=pushes {
            sink += e
                .push(
                    0.5f64.powi(k as i32),
                    0.5f64.powi(k as i32),
                    Some(0.5f64.powi(k as i32)),
                )
                .map_or(0.0, |x| x.error);
        }
    }
    std::hint::black_box(sink);
    let est_ms = ms(t_est.elapsed());
    println!(
        "{:<40} {:>12.3}  ({:.2} % of the iteration)",
        "error estimate (force step sums + fit)",
        est_ms,
        100.0 * est_ms / per_it
    );
    println!(
        "linear stage: {:.3e} flop per iteration at {:.2} GFLOP/s; one-thread product {largest}×{largest} · {largest}×{nt} \
         at {:.2} GFLOP/s: {:.0} %",
        flops,
        linear_gflops,
        rate,
        100.0 * linear_gflops / rate
    );
    println!(
        "memory traffic: {:.1} MB per iteration, {:.2} ms at {:.2} GB/s (one thread); iteration = {:.2} × that bound",
        bytes / 1e6,
        bound_ms,
        bandwidth,
        per_it / bound_ms
    );
}
