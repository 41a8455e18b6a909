//! `glissade bench <scene>`: where an iteration's time goes, against what the machine can do.
//!
//! Three measurements in one process, one after the other:
//! - the machine: the dense-product rate of faer on the shape of the linear stage (A_E times the
//!   n_b × (N+1) block of the largest subdomain, one thread, then both threads on independent
//!   products as the in-process run does) and the memory bandwidth (a 512 MiB buffer read by all
//!   threads);
//! - the run: the scene in-process with every node's handling time summed per (role, message
//!   field), i.e. per stage of the iteration;
//! - two models of one iteration: the flops of the condensed linear stage (counted from the
//!   products it makes) and the bytes its passes move when no boundary field stays in cache from
//!   one pass to the next (every operator read once, every boundary field read or written once per
//!   pass listed in [`FIELD_PASSES`], and with Anderson acceleration per pass its record and its
//!   mixing step make, counted from the run's own Gram and step messages:
//!   [`anderson_record_passes`], [`anderson_step_passes`]; fusing passes would lower it, cache hits
//!   between passes make the real traffic lower). Their ratios to the measured rates give the
//!   compute and memory-traffic bounds the iteration time is compared to.

use crate::distributed::Network;
use crate::error::failed;
use crate::run::Run;
use crate::runner::{RunOptions, RunResult};
use faer::{Accum, Mat, Par};
use glissade_bus::HandleTime;
use glissade_deploy::Plan;
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::simd::matmul;
use glissade_messages::{Payload, Role};
use glissade_scene::LoadedScene;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

/// Passes over full boundary fields that one plain iteration makes per subdomain
/// ([`glissade_mechanics::FIELD_PASSES`], derived call by call there).
pub use glissade_mechanics::FIELD_PASSES;

/// Passes over full boundary fields that a subdomain's Anderson record makes beyond the plain
/// iteration's, when it holds `k` stored differences after the record (its `AndersonGram` is
/// k × k). `AndersonHistory::record_sum` replaces `sum_relax_into` (10 passes): it reads s (2) and
/// s₁ and s₂ (4), writes the new iterate's s + μr (2) and r_F (1), and reads the r_F of the k
/// iterates before it, whose differences with each other and with the new one are the stored Δr_F
/// of the Gram column (formed in cache, column by column): 9 + k − 10 = k − 1 (k ≥ 1: a record
/// that sends partials has stored a difference). Iterations 0 and 1, which record without
/// partials, are counted as plain ones.
pub fn anderson_record_passes(k: usize) -> usize {
    k.saturating_sub(1)
}

/// Passes over full boundary fields of a subdomain's mixing step with `g` coefficients
/// (`AndersonHistory::apply`; 0 for a plain or restart step): it reads the s + μr of the g + 1
/// iterates whose differences are the D_W and D_F it mixes (2g + 2), and writes s (2).
pub fn anderson_step_passes(g: usize) -> usize {
    4 + 2 * g
}

/// What the machine does, measured.
#[derive(Debug, Clone, Serialize)]
pub struct MachineRates {
    pub threads: usize,
    /// The product measured: rows × inner × columns.
    pub product_shape: [usize; 3],
    pub gflops_one_thread: f64,
    pub gflops_all_threads: f64,
    /// Read bandwidth of a buffer far larger than the caches, all threads (GB/s, 1e9 bytes).
    pub read_gb_s: f64,
}

/// One stage of the split.
#[derive(Debug, Clone, Serialize)]
pub struct StageTime {
    pub role: String,
    pub field: String,
    pub what: String,
    pub calls: u64,
    /// Per iteration, summed over the nodes doing it (CPU time when they run in parallel).
    pub ms_per_iteration: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// The vector extension the element-wise kernels ran with ([`glissade_mechanics::simd`]).
    pub kernels: &'static str,
    pub scene: String,
    pub subdomains: usize,
    pub largest_boundary: usize,
    pub time_points: usize,
    pub linear_stage: String,
    pub iterations: usize,
    pub setup_s: f64,
    pub solve_s: f64,
    pub wall_ms_per_iteration: f64,
    pub stages: Vec<StageTime>,
    pub machine: MachineRates,
    /// Flops of the condensed linear stage per iteration (None for the sparse and PGD stages,
    /// whose work is not a fixed count of dense products).
    pub linear_flops_per_iteration: Option<f64>,
    /// Linear-stage rate: its flops over the CPU time of micro 1 and micro 2 (GFLOP/s), and that
    /// rate over the one-thread product rate.
    pub linear_gflops: Option<f64>,
    pub linear_fraction_of_peak: Option<f64>,
    /// Passes over full boundary fields per iteration and subdomain, mean over the run:
    /// [`FIELD_PASSES`] and, with Anderson acceleration, its records' and steps'.
    pub field_passes: f64,
    /// Bytes one iteration's passes move from memory (no cache reuse between passes), and that
    /// over the read bandwidth (ms).
    pub bytes_per_iteration: f64,
    pub memory_bound_ms: f64,
    /// Measured wall time per iteration over the memory-traffic bound.
    pub wall_over_memory_bound: f64,
}

/// What a (role, field) handling is, in the method's words.
fn stage_name(role: Role, field: &str) -> &'static str {
    match (role, field) {
        (Role::Subdomain, "local_directions") => "micro problem 1 (and macro forces)",
        (Role::Subdomain, "macro_displacements") => "micro problem 2 and relaxation",
        (Role::Subdomain, "homogenized_operator") => "setup: macro operator received",
        (Role::Subdomain, "anderson_step") => "Anderson mixing",
        (Role::Subdomain, "decision") => "stop decision",
        (Role::Coarse, "macro_forces") => "macro problem",
        (Role::Coarse, "homogenized_operator") => "setup: macro operator assembly",
        (Role::Interface, "boundary_state" | "boundary_modes") => "local stage and indicators",
        (Role::Interface, "anderson_gram") => "Anderson least-squares",
        (Role::Interface, "indicator_partials") => "indicator reduction",
        _ => "other",
    }
}

/// GFLOP/s of `C = A B` (A m × m, B m × n) on `threads` independent products at once.
fn product_rate(m: usize, n: usize, threads: usize) -> f64 {
    let a = Mat::<f64>::from_fn(m, m, |i, j| 1.0 / (1.0 + (i + 2 * j) as f64));
    let b = Mat::<f64>::from_fn(m, n, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0);
    let mut cs: Vec<Mat<f64>> = (0..threads).map(|_| Mat::zeros(m, n)).collect();
    let flops = 2.0 * (m * m * n) as f64;
    let mut reps = 1usize;
    loop {
        let t = Instant::now();
        cs.par_iter_mut().for_each(|c| {
            for _ in 0..reps {
                matmul(c.as_mut(), Accum::Replace, a.as_ref(), b.as_ref(), 1.0, Par::Seq);
            }
        });
        let s = t.elapsed().as_secs_f64();
        if s > 0.3 {
            std::hint::black_box(&cs);
            return flops * (reps * threads) as f64 / s / 1e9;
        }
        reps *= 2;
    }
}

/// Read bandwidth (GB/s) of a 512 MiB buffer summed by all threads, each in 16 partial sums
/// ([`glissade_mechanics::simd::sum`]: one chain of additions would measure the add's latency,
/// about 9 GB/s per thread, not the memory); best of three passes.
fn read_bandwidth() -> f64 {
    let n: usize = 64 << 20; // f64s
    let buf: Vec<f64> = (0..n).map(|i| (i % 13) as f64).collect();
    let chunk = n.div_ceil(rayon::current_num_threads().max(1));
    let mut best = 0.0f64;
    for _ in 0..3 {
        let t = Instant::now();
        let sum: f64 = buf.par_chunks(chunk).map(glissade_mechanics::simd::sum).sum();
        let s = t.elapsed().as_secs_f64();
        std::hint::black_box(sum);
        best = best.max((n * 8) as f64 / s / 1e9);
    }
    best
}

/// Measures the machine on the product shape (m × m) · (m × n).
pub fn machine_rates(m: usize, n: usize) -> MachineRates {
    let threads = rayon::current_num_threads().max(1);
    MachineRates {
        threads,
        product_shape: [m, m, n],
        gflops_one_thread: product_rate(m, n, 1),
        gflops_all_threads: product_rate(m, n, threads),
        read_gb_s: read_bandwidth(),
    }
}

/// Boundary sizes, macro sizes and linear stages of the subdomains that iterate.
fn subdomain_sizes(model: &glissade_mechanics::model::Model, plan: &Plan) -> Vec<(usize, usize, LinearStage)> {
    plan.participants
        .iter()
        .map(|&s| {
            let s = s as usize;
            let n_b = BoundaryLayout::new(model, s, &plan.k0).len();
            let n_m: usize = model
                .interfaces
                .iter()
                .enumerate()
                .filter(|(_, itf)| itf.a == s || itf.b == s)
                .map(|(i, _)| plan.bases[i].len())
                .sum();
            (n_b, n_m, plan.stage_of(model, s))
        })
        .collect()
}

/// The floating-point operations of one iteration's condensed linear stages (None where a
/// subdomain has another stage), over `nt` time points, `coarse`: with the coarse problem.
fn linear_flops(sizes: &[(usize, usize, LinearStage)], nt: usize, coarse: bool) -> Option<f64> {
    let all_condensed = sizes.iter().all(|x| x.2 == LinearStage::Condensed);
    all_condensed.then(|| {
        sizes
            .iter()
            .map(|&(n_b, n_m, _)| {
                let (b, m, t) = (n_b as f64, n_m as f64, nt as f64);
                // micro 1: A_E (M q̂); with the coarse problem also 𝔼ᵀ M F₁ and, in micro 2,
                // (A_E M k⁻ 𝔼) w̃ and 𝔼 w̃.
                2.0 * b * b * t + if coarse { 3.0 * 2.0 * b * m * t } else { 0.0 }
            })
            .sum::<f64>()
    })
}

/// Runs the benchmark of `scene`.
pub fn bench(scene: &LoadedScene, run_id: &str) -> crate::Result<BenchReport> {
    let model = &scene.model;
    if model.interfaces.is_empty() {
        return Err(crate::Error::NoInterface {
            scene: model.name.clone(),
            consequence: "there is no iteration to benchmark",
        });
    }
    let plan = Plan::new(model).with_scene(scene);
    let nt = model.time.n_points();
    let sizes = subdomain_sizes(model, &plan);
    let largest = sizes.iter().map(|x| x.0).max().unwrap_or(0);
    // Anderson's passes beyond the plain iteration's, summed over the run: per subdomain for its
    // records, and for every subdomain for each step (all of them take it).
    let mut record_passes = vec![0usize; model.subdomains.len()];
    let mut step_passes = 0usize;
    let opts = RunOptions::new(run_id);
    let outcome = Run::new(scene, &opts)
        .observe(|m| {
            match &m.payload {
                Payload::AndersonGram { subdomain, gram, .. } => {
                    if let Some(p) = record_passes.get_mut(*subdomain as usize) {
                        *p += anderson_record_passes(gram.rows());
                    }
                }
                Payload::AndersonStep { gamma, .. } => step_passes += anderson_step_passes(gamma.len()),
                _ => {}
            }
            Duration::ZERO
        })
        .handle_times()
        .in_process()?;
    let (result, times): (_, Vec<HandleTime>) = (outcome.result, outcome.handle_times);
    let machine = machine_rates(largest, nt);
    let iterations = result.iterations.len().max(1);
    let per_it = |s: f64| 1e3 * s / iterations as f64;
    let stages: Vec<StageTime> = times
        .iter()
        .map(|t| StageTime {
            role: t.role.key().into(),
            field: t.field.clone(),
            what: stage_name(t.role, &t.field).into(),
            calls: t.calls,
            ms_per_iteration: per_it(t.seconds),
        })
        .collect();
    let linear_flops = linear_flops(&sizes, nt, plan.coarse);
    let linear_cpu_s: f64 = times
        .iter()
        .filter(|t| t.role == Role::Subdomain && matches!(t.field.as_str(), "local_directions" | "macro_displacements"))
        .map(|t| t.seconds)
        .sum();
    let linear_gflops = linear_flops.map(|f| f * iterations as f64 / linear_cpu_s.max(1e-12) / 1e9);
    let passes: Vec<f64> = plan
        .participants
        .iter()
        .map(|&s| {
            let extra = record_passes[s as usize] + if record_passes[s as usize] > 0 { step_passes } else { 0 };
            FIELD_PASSES as f64 + extra as f64 / iterations as f64
        })
        .collect();
    let bytes: f64 = sizes
        .iter()
        .zip(&passes)
        .map(|(&(n_b, n_m, stage), &p)| {
            let operator = if stage == LinearStage::Condensed { n_b * n_b } else { 0 };
            8.0 * ((operator + 2 * n_b * n_m) as f64 + p * (n_b * nt) as f64)
        })
        .sum();
    let field_passes = passes.iter().sum::<f64>() / passes.len().max(1) as f64;
    let memory_bound_ms = 1e3 * bytes / (machine.read_gb_s * 1e9);
    let wall_ms = per_it(result.solve_s);
    Ok(BenchReport {
        scene: model.name.clone(),
        subdomains: sizes.len(),
        largest_boundary: largest,
        time_points: nt,
        linear_stage: format!("{:?}", scene.linear_stage).to_lowercase(),
        iterations: result.iterations.len(),
        setup_s: result.setup_s,
        solve_s: result.solve_s,
        wall_ms_per_iteration: wall_ms,
        stages,
        linear_flops_per_iteration: linear_flops,
        linear_gflops,
        linear_fraction_of_peak: linear_gflops.map(|g| g / machine.gflops_one_thread),
        field_passes,
        bytes_per_iteration: bytes,
        memory_bound_ms,
        wall_over_memory_bound: wall_ms / memory_bound_ms,
        machine,
        kernels: glissade_mechanics::simd::level().name(),
    })
}

/// The report as text.
pub fn render(r: &BenchReport) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "scene {}: {} subdomains (largest boundary {} dofs), N + 1 = {} time points, linear stage {}",
        r.scene, r.subdomains, r.largest_boundary, r.time_points, r.linear_stage
    );
    let _ = writeln!(
        s,
        "machine: {} threads, element-wise kernels {}; dense product {}×{} · {}×{}: {:.1} GFLOP/s on one thread, {:.1} on all; read bandwidth {:.1} GB/s",
        r.machine.threads,
        r.kernels,
        r.machine.product_shape[0],
        r.machine.product_shape[1],
        r.machine.product_shape[1],
        r.machine.product_shape[2],
        r.machine.gflops_one_thread,
        r.machine.gflops_all_threads,
        r.machine.read_gb_s
    );
    let _ = writeln!(
        s,
        "run: setup {:.3} s, {} iterations in {:.3} s: {:.2} ms per iteration (wall)",
        r.setup_s, r.iterations, r.solve_s, r.wall_ms_per_iteration
    );
    let _ = writeln!(
        s,
        "\n| node ← message | stage | calls | ms per iteration (summed over nodes) |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|");
    for st in &r.stages {
        let _ = writeln!(
            s,
            "| {} ← {} | {} | {} | {:.3} |",
            st.role, st.field, st.what, st.calls, st.ms_per_iteration
        );
    }
    let _ = writeln!(s);
    match (r.linear_flops_per_iteration, r.linear_gflops, r.linear_fraction_of_peak) {
        (Some(f), Some(g), Some(p)) => {
            let _ = writeln!(
                s,
                "linear stage: {:.3e} flop per iteration at {:.1} GFLOP/s = {:.0} % of the one-thread product rate",
                f,
                g,
                100.0 * p
            );
        }
        _ => {
            let _ = writeln!(
                s,
                "linear stage: no flop count (only the condensed stage is a fixed set of products)"
            );
        }
    }
    let _ = writeln!(
        s,
        "memory traffic: {:.1} MB per iteration ({:.1} boundary-field passes from memory per subdomain, {} of them the plain \
         iteration's, + operators), {:.2} ms at {:.1} GB/s; measured iteration = {:.1} × that bound",
        r.bytes_per_iteration / 1e6,
        r.field_passes,
        FIELD_PASSES,
        r.memory_bound_ms,
        r.machine.read_gb_s,
        r.wall_over_memory_bound
    );
    s
}

/// One round of [`compare_processes`]: the wall time (s) of the same run from its first
/// iteration to its end (for processes: until the launcher holds every result), in-process, as
/// processes over loopback TCP (with TLS if the scene asks for it), and as processes through
/// shared memory; and the set-up before that first iteration (`*_setup_s`: operators, a
/// time-coarse start's coarse solve, for processes also starting them and their bus), so that
/// set-up + iterations is the time a user waits for the result. `*_iteration_ms`: the median
/// time of one iteration from the third on (decision to decision; none for a run of fewer than
/// three), what an iteration costs once the first ones have faulted in their memory.
#[derive(Debug, Clone, Serialize)]
pub struct ProcessRound {
    pub in_process_s: f64,
    pub tcp_s: f64,
    pub shared_memory_s: f64,
    pub in_process_setup_s: f64,
    pub tcp_setup_s: f64,
    pub shared_memory_setup_s: f64,
    pub in_process_iteration_ms: Option<f64>,
    pub tcp_iteration_ms: Option<f64>,
    pub shared_memory_iteration_ms: Option<f64>,
}

impl ProcessRound {
    /// Set-up + iterations in-process, over TCP and through shared memory.
    pub fn totals(&self) -> [f64; 3] {
        [
            self.in_process_setup_s + self.in_process_s,
            self.tcp_setup_s + self.tcp_s,
            self.shared_memory_setup_s + self.shared_memory_s,
        ]
    }
}

/// The scene as processes against in-process, in alternating rounds (so that a drift of the
/// machine's speed shows in every column alike).
#[derive(Debug, Clone, Serialize)]
pub struct ProcessComparison {
    pub scene: String,
    pub iterations: usize,
    /// The scene's links are TLS (`[network] tls`): in both process columns.
    pub tls: bool,
    pub rounds: Vec<ProcessRound>,
    /// Medians over the rounds of each round's ratio to its in-process time (iterations).
    pub tcp_over_in_process: f64,
    pub shared_memory_over_in_process: f64,
    /// The same with the set-up: set-up + iterations against in-process set-up + iterations.
    pub tcp_total_over_in_process: f64,
    pub shared_memory_total_over_in_process: f64,
    /// Medians of each round's ratio of the median iteration from the third on (none for a run
    /// of fewer than three iterations).
    pub tcp_iteration_over_in_process: Option<f64>,
    pub shared_memory_iteration_over_in_process: Option<f64>,
}

/// The median time (ms) of an iteration from the third on, decision to decision, from the times
/// (s since the loop's start) at which each iteration's decision was made.
fn steady_iteration_ms(decided_s: &[f64]) -> Option<f64> {
    let times: Vec<f64> = decided_s.windows(2).skip(1).map(|w| 1e3 * (w[1] - w[0])).collect();
    (!times.is_empty()).then(|| median(times))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Gives the memory this process has freed back to the kernel. glibc keeps freed memory in its
/// arenas for reuse; after an in-process run at N = 1000 that is gigabytes, which the node
/// processes of the next run then cannot have: they take pages the kernel has not used yet, and
/// on a virtual machine the first touch of such a page is far slower than of one used before
/// (measured: the node processes of a shared-memory run after an in-process run in the same
/// bench spent ~3.6 s of CPU clearing pages, against ~0.4 s when run on their own). Each run of
/// the comparison thus starts from the free memory a run of its own would find.
fn give_back_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only walks glibc's own free lists; no other state is involved.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Runs `scene` `rounds` times in-process, as processes over TCP and as processes through shared
/// memory (node processes started from `exe`, the launcher's router on a loopback port, no
/// recording), one after the other in each round. Every run must be the same run: the same
/// iterations and bit-identical decisions, or this is an error. `run_id` names each run. The
/// memory each run frees is given back to the kernel before the next ([`give_back_freed_memory`]).
pub fn compare_processes(
    scene: &LoadedScene,
    exe: &Path,
    rounds: usize,
    mut run_id: impl FnMut() -> crate::Result<String>,
) -> crate::Result<ProcessComparison> {
    if rounds < 1 {
        return Err(crate::Error::Option {
            option: "--rounds 0".into(),
            why: "at least one round".into(),
        });
    }
    if scene.model.interfaces.is_empty() {
        return Err(crate::Error::NoInterface {
            scene: scene.model.name.clone(),
            consequence: "it runs in one process only",
        });
    }
    // The first run's decisions, as text (every value written out exactly, so the comparison is
    // bit for bit, NaN and the sign of zero included): every other run must repeat them.
    let mut reference: Option<Vec<String>> = None;
    let mut same_run = |what: &str, r: RunResult| -> crate::Result<(f64, f64, Option<f64>)> {
        let decisions: Vec<String> = r.iterations.iter().map(|i| format!("{:?}", i.decision)).collect();
        match &reference {
            None => reference = Some(decisions),
            Some(first) => {
                if let Some(k) = (0..first.len().max(decisions.len())).find(|&k| first.get(k) != decisions.get(k)) {
                    failed!(
                        "the run {what} is not the first in-process run: its decision of iteration {k} is {} where the first \
                         run's is {} ({} against {} iterations)",
                        decisions.get(k).map_or("missing", String::as_str),
                        first.get(k).map_or("missing", String::as_str),
                        decisions.len(),
                        first.len()
                    );
                }
            }
        }
        let decided: Vec<f64> = r.iterations.iter().map(|i| i.elapsed_s).collect();
        Ok((r.setup_s, r.solve_s, steady_iteration_ms(&decided)))
    };
    let mut out = Vec::with_capacity(rounds);
    for _ in 0..rounds {
        let opts = |id: String| RunOptions::new(id);
        give_back_freed_memory();
        let in_process = same_run("in-process", Run::new(scene, &opts(run_id()?)).in_process()?.result)?;
        let mut times = [(0.0, 0.0, None); 2];
        for (t, shm) in times.iter_mut().zip([false, true]) {
            give_back_freed_memory();
            let mut sc = scene.clone();
            sc.network.shared_memory = Some(shm);
            let r = Run::new(&sc, &opts(run_id()?))
                .processes(exe, &Network::default())?
                .result;
            *t = same_run(if shm { "through shared memory" } else { "over TCP" }, r)?;
        }
        out.push(ProcessRound {
            in_process_s: in_process.1,
            tcp_s: times[0].1,
            shared_memory_s: times[1].1,
            in_process_setup_s: in_process.0,
            tcp_setup_s: times[0].0,
            shared_memory_setup_s: times[1].0,
            in_process_iteration_ms: in_process.2,
            tcp_iteration_ms: times[0].2,
            shared_memory_iteration_ms: times[1].2,
        });
    }
    let ratio = |f: fn(&ProcessRound) -> f64| median(out.iter().map(|r| f(r) / r.in_process_s).collect());
    let total_ratio = |k: usize| median(out.iter().map(|r| r.totals()[k] / r.totals()[0]).collect());
    let iteration_ratio = |f: fn(&ProcessRound) -> Option<f64>| {
        let ratios: Option<Vec<f64>> = out.iter().map(|r| Some(f(r)? / r.in_process_iteration_ms?)).collect();
        ratios.map(median)
    };
    Ok(ProcessComparison {
        scene: scene.model.name.clone(),
        iterations: reference.map_or(0, |d| d.len()),
        tls: scene.network.tls.is_some(),
        tcp_over_in_process: ratio(|r| r.tcp_s),
        shared_memory_over_in_process: ratio(|r| r.shared_memory_s),
        tcp_total_over_in_process: total_ratio(1),
        shared_memory_total_over_in_process: total_ratio(2),
        tcp_iteration_over_in_process: iteration_ratio(|r| r.tcp_iteration_ms),
        shared_memory_iteration_over_in_process: iteration_ratio(|r| r.shared_memory_iteration_ms),
        rounds: out,
    })
}

/// The comparison as text: one row per round, then the median ratios.
pub fn render_processes(c: &ProcessComparison) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\nprocesses against in-process, {} iterations, wall time from the first iteration to the end of the run (s; \
         processes: until the launcher holds every result):\n",
        c.iterations
    );
    let link = if c.tls { "TCP with TLS" } else { "TCP" };
    // The head of each of the three tables.
    let head =
        format!("| round | in-process | processes, {link} | processes, shared memory |\n|---:|---:|---:|---:|\n");
    s.push_str(&head);
    for (i, r) in c.rounds.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.2} ({:.2}×) | {:.2} ({:.2}×) |",
            i + 1,
            r.in_process_s,
            r.tcp_s,
            r.tcp_s / r.in_process_s,
            r.shared_memory_s,
            r.shared_memory_s / r.in_process_s
        );
    }
    let _ = writeln!(
        s,
        "median ratio to in-process: {link} {:.2}×, shared memory {:.2}×",
        c.tcp_over_in_process, c.shared_memory_over_in_process
    );
    let _ = writeln!(
        s,
        "\nthe same runs, set-up + iterations (s; the set-up: operators, a time-coarse start's coarse solve, and for \
         processes starting them and their bus):\n"
    );
    s.push_str(&head);
    for (i, r) in c.rounds.iter().enumerate() {
        let [t0, t1, t2] = r.totals();
        let _ = writeln!(
            s,
            "| {} | {:.2} + {:.2} | {:.2} + {:.2} ({:.2}×) | {:.2} + {:.2} ({:.2}×) |",
            i + 1,
            r.in_process_setup_s,
            r.in_process_s,
            r.tcp_setup_s,
            r.tcp_s,
            t1 / t0,
            r.shared_memory_setup_s,
            r.shared_memory_s,
            t2 / t0
        );
    }
    let _ = writeln!(
        s,
        "median ratio to in-process, set-up + iterations: {link} {:.2}×, shared memory {:.2}×",
        c.tcp_total_over_in_process, c.shared_memory_total_over_in_process
    );
    if let (Some(tcp), Some(shm)) = (
        c.tcp_iteration_over_in_process,
        c.shared_memory_iteration_over_in_process,
    ) {
        let _ = writeln!(
            s,
            "\nthe same runs, median iteration from the 3rd on (ms, decision to decision: without the first \
             iterations' faulting in of new memory and the end of the run):\n"
        );
        s.push_str(&head);
        for (i, r) in c.rounds.iter().enumerate() {
            if let (Some(a), Some(b), Some(m)) = (
                r.in_process_iteration_ms,
                r.tcp_iteration_ms,
                r.shared_memory_iteration_ms,
            ) {
                let _ = writeln!(
                    s,
                    "| {} | {a:.1} | {b:.1} ({:.2}×) | {m:.1} ({:.2}×) |",
                    i + 1,
                    b / a,
                    m / a
                );
            }
        }
        let _ = writeln!(
            s,
            "median ratio to in-process, iteration from the 3rd on: {link} {tcp:.2}×, shared memory {shm:.2}×"
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::steady_iteration_ms;

    /// Iterations decided at 0.5, 0.8, 0.9, 1.0, 1.3 and 1.35 s: from the third on they took
    /// 100, 100, 300 and 50 ms, median 100 ms; the first two (500 and 300 ms) do not count.
    #[test]
    fn steady_iteration_is_the_median_from_the_third_on() {
        let ms = steady_iteration_ms(&[0.5, 0.8, 0.9, 1.0, 1.3, 1.35]).unwrap();
        assert!((ms - 100.0).abs() < 1e-9, "{ms}");
        assert!((steady_iteration_ms(&[0.5, 0.8, 1.0]).unwrap() - 200.0).abs() < 1e-9);
        assert_eq!(steady_iteration_ms(&[0.5, 0.8]), None);
        assert_eq!(steady_iteration_ms(&[]), None);
    }
}
