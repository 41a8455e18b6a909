//! Runtime choice of the CPU's widest vector extension for the element-wise kernels.
//!
//! The crate is compiled for the baseline of its target (x86-64: SSE2), so that one binary runs
//! on every machine of a distributed run. The kernels defined with
//! [`multiversion!`](crate::multiversion) are compiled three times, for AVX-512, for AVX2 + FMA
//! and for the baseline, and each call runs the copy [`level`] allows: the local stage with its
//! indicator sums, the macro forces, the sum and relaxation, Anderson's record and step (the
//! passes that measurably gained; the others, e.g. micro problem 1's scaling and F₁ = q̂ − k⁻W₁,
//! q̂'s scatter or PGD's residual record, stay at the baseline). What their loops call is
//! `#[inline(always)]` or small enough to be inlined, so that it is compiled into each copy.
//!
//! These kernels' numbers do not depend on the level: Rust never contracts `a * b + c` into a
//! fused multiply-add nor reorders a sum unless asked to, so the wider code makes the same
//! operations in the same order, lane by lane. faer's products choose their own kernels at run
//! time too, and those may round differently on CPUs of different extensions: runs on one
//! machine repeat bit for bit, runs on two different CPUs need not.

/// Which code [`multiversion!`] functions run on this CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Baseline,
    Avx2,
    Avx512,
}

thread_local! {
    static FORCED: std::cell::Cell<Option<Level>> = const { std::cell::Cell::new(None) };
}

/// The process-wide level set by [`set_process_level`] (0: none, else 1 + the level's index).
static PROCESS: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

const LEVELS: [Level; 3] = [Level::Baseline, Level::Avx2, Level::Avx512];

impl Level {
    pub fn name(self) -> &'static str {
        match self {
            Level::Baseline => "baseline",
            Level::Avx2 => "AVX2",
            Level::Avx512 => "AVX-512",
        }
    }
}

/// `level` if the CPU has it, else the widest level below it that it has.
fn capped(level: Level) -> Level {
    match (level, detected()) {
        (Level::Avx512, Level::Avx512) => Level::Avx512,
        (Level::Avx512 | Level::Avx2, Level::Avx512 | Level::Avx2) => Level::Avx2,
        _ => Level::Baseline,
    }
}

/// Runs every thread's kernels at `level` (capped at what the CPU has) from now on, or at
/// [`detected`] again with `None`: for benchmarks that compare the levels in one run.
pub fn set_process_level(level: Option<Level>) {
    let code = level.map_or(0, |l| {
        1 + LEVELS
            .iter()
            .position(|x| *x == capped(l))
            .expect("capped gives one of LEVELS") as u8
    });
    PROCESS.store(code, std::sync::atomic::Ordering::Relaxed);
}

/// The widest extension of this CPU that the kernels use: AVX-512 (F, VL, DQ) with AVX2 and FMA,
/// AVX2 with FMA, or the baseline. Detected by std, which caches it.
pub fn detected() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512vl")
            && std::arch::is_x86_feature_detected!("avx512dq")
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            return Level::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            return Level::Avx2;
        }
    }
    Level::Baseline
}

/// Clears the upper halves of the vector registers (`vzeroupper`) when the CPU has AVX.
///
/// faer's dense products run hand-written AVX-512 kernels that return with the registers' upper
/// halves in use. Until something clears them, every SSE instruction of code compiled for the
/// baseline (this crate's scalar loops, faer's sparse triangular solves) carries a dependency on
/// those upper halves: measured on the 2-core AMD EPYC, the A_E solves of the stratified scene's
/// 18 subdomains took 1.30 s after one faer product against 0.47 s before it, and 0.51 s with
/// this call after the product. Call it after faer routines that multiply dense blocks
/// ([`matmul`] does).
#[inline]
pub fn clear_upper_state() {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx")]
        fn zeroupper() {
            std::arch::x86_64::_mm256_zeroupper()
        }
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX.
            unsafe { zeroupper() }
        }
    }
}

/// faer's [`faer::linalg::matmul::matmul`], then [`clear_upper_state`].
#[inline]
pub fn matmul(
    dst: faer::MatMut<'_, f64>,
    beta: faer::Accum,
    lhs: faer::MatRef<'_, f64>,
    rhs: faer::MatRef<'_, f64>,
    alpha: f64,
    par: faer::Par,
) {
    faer::linalg::matmul::matmul(dst, beta, lhs, rhs, alpha, par);
    clear_upper_state();
}

/// The level the kernels of this thread run at: [`detected`], unless [`with_level`] (this
/// thread) or [`set_process_level`] (every thread) lowered it.
#[inline]
pub fn level() -> Level {
    FORCED
        .with(|f| f.get())
        .unwrap_or_else(|| match PROCESS.load(std::sync::atomic::Ordering::Relaxed) {
            0 => detected(),
            code => LEVELS[code as usize - 1],
        })
}

/// Runs `f` with this thread's kernels at `level`, capped at what the CPU has (a test compares
/// the levels' results; the baseline always runs).
pub fn with_level<R>(level: Level, f: impl FnOnce() -> R) -> R {
    /// Puts the thread's previous level back, also when `f` panics.
    struct Restore(Option<Level>);
    impl Drop for Restore {
        fn drop(&mut self) {
            FORCED.with(|c| c.set(self.0));
        }
    }
    let _restore = Restore(FORCED.with(|c| c.replace(Some(capped(level)))));
    f()
}

/// Defines a function whose body is compiled three times, for AVX-512, for AVX2 + FMA and for
/// the baseline, and runs the copy of [`level`]. Everything the body calls in its loops must be
/// `#[inline(always)]` to be compiled into each copy. Arguments are plain `name: Type` pairs
/// (elided lifetimes only, no generics).
#[macro_export]
macro_rules! multiversion {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) $(-> $ret)? {
            #[inline(always)]
            fn body($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
            fn avx512($($arg: $ty),*) $(-> $ret)? {
                body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            fn avx2($($arg: $ty),*) $(-> $ret)? {
                body($($arg),*)
            }
            match $crate::simd::level() {
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `level` says the CPU has AVX-512 F/VL/DQ, AVX2 and FMA.
                $crate::simd::Level::Avx512 => unsafe { avx512($($arg),*) },
                #[cfg(target_arch = "x86_64")]
                // SAFETY: `level` says the CPU has AVX2 and FMA.
                $crate::simd::Level::Avx2 => unsafe { avx2($($arg),*) },
                _ => body($($arg),*),
            }
        }
    };
}

/// Σ values in 16 interleaved partial sums: a pass that the memory limits, not the latency of
/// one chain of additions (a plain `iter().sum()` adds one value per add latency, about 9 GB/s at
/// 3.5 GHz, below what one core reads). Used to measure the read bandwidth; not multiversioned,
/// so that `--kernels` does not change the measurement (the baseline copy already reads as fast
/// as the AVX-512 one: 26.7 against 25.1 GB/s on one thread of the 2-core EPYC).
pub fn sum(values: &[f64]) -> f64 {
    let mut acc = [0.0f64; 16];
    let chunks = values.chunks_exact(16);
    let tail: f64 = chunks.remainder().iter().sum();
    for c in chunks {
        for l in 0..16 {
            acc[l] += c[l];
        }
    }
    acc.iter().sum::<f64>() + tail
}

/// Σ a[r] b[r] in eight interleaved partial sums, added pairwise at the end: independent chains
/// of additions that vector instructions run side by side (one chain waits on the add's latency
/// at every value). The same operations in the same order at every level.
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            acc[l] += x[l] * y[l];
        }
    }
    ((acc[0] + acc[4]) + (acc[2] + acc[6])) + ((acc[1] + acc[5]) + (acc[3] + acc[7])) + tail
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anderson::{AndersonHistory, AndersonStep};
    use crate::linear::flop_tests::model_and_solver;
    use crate::linear::sum_relax_into;
    use crate::local::{ContactDirections, InterfaceFields, InterfaceLocal};
    use faer::Mat;

    fn random(seed: &mut u64, rows: usize, cols: usize, scale: f64) -> Mat<f64> {
        Mat::from_fn(rows, cols, |_, _| {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            scale * ((*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
        })
    }

    fn bits(m: &Mat<f64>, out: &mut Vec<u64>) {
        for j in 0..m.ncols() {
            out.extend(m.col_as_slice(j).iter().map(|v| v.to_bits()));
        }
    }

    /// Every kernel's outputs, as bits, from the same random inputs: the local stage with its
    /// indicator sums on every interface of small-three-layer (contact with friction and
    /// perfect, two iterations, the second along updated search directions), a subdomain's
    /// macro forces, the sum and relaxation, and Anderson's records (plain and summed) with
    /// mixing steps. Also returns the contact points counted per status.
    fn outputs() -> (Vec<u64>, [u64; 3]) {
        let mut statuses = [0u64; 3];
        let (model, mut solver) = model_and_solver(true);
        let nt = model.time.n_points();
        let weights = model.time.trapezoid_weights();
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut out = Vec::new();
        for (i, itf) in model.interfaces.iter().enumerate() {
            let mut local = InterfaceLocal::new(i, itf, 300.0, nt);
            for first in [true, false] {
                let rows = 2 * itf.n_pairs();
                let s = InterfaceFields {
                    w_a: random(&mut seed, rows, nt, 0.02),
                    w_b: random(&mut seed, rows, nt, 0.02),
                    f_a: random(&mut seed, rows, nt, 20.0),
                    f_b: random(&mut seed, rows, nt, 20.0),
                };
                if !first && itf.is_contact() {
                    let np = itf.n_pairs();
                    let k_n = random(&mut seed, np, nt, 300.0);
                    let k_t = random(&mut seed, np, nt, 300.0);
                    local.directions = Some(ContactDirections {
                        k_n: Mat::from_fn(np, nt, |p, i| 300.0 + k_n[(p, i)]),
                        k_t: Mat::from_fn(np, nt, |p, i| 300.0 + k_t[(p, i)]),
                    });
                }
                let sums = local.local_stage_with_sums(itf, &weights, &s, first);
                for (total, c) in statuses.iter_mut().zip(sums.counts) {
                    *total += c;
                }
                for m in [&local.hat.w_a, &local.hat.w_b, &local.hat.f_a, &local.hat.f_b] {
                    bits(m, &mut out);
                }
                out.extend(format!("{sums:?}").bytes().map(u64::from));
            }
        }
        let n_b = solver.n_boundary();
        let f = random(&mut seed, n_b, nt, 10.0);
        let mut forces = Mat::zeros(solver.n_macro(), nt);
        solver.macro_forces_into(f.as_ref(), forces.as_mut());
        bits(&forces, &mut out);
        let [mut w1, mut f1, w2, f2, mut w, mut f] = std::array::from_fn(|_| random(&mut seed, n_b, nt, 1.0));
        sum_relax_into(
            0.8,
            w1.as_mut(),
            f1.as_mut(),
            w2.as_ref(),
            f2.as_ref(),
            w.as_mut(),
            f.as_mut(),
        );
        for m in [&w1, &f1, &w, &f] {
            bits(m, &mut out);
        }
        let mut history = AndersonHistory::new(3, 0.8, n_b, nt);
        for record in 0..5 {
            let [g_w, g_f, h_w, h_f] = std::array::from_fn(|_| random(&mut seed, n_b, nt, 1.0));
            if record < 2 {
                history.record(&w, &f, &g_w, &g_f);
            } else {
                history.record_sum(&w, &f, [&g_w, &h_w], [&g_f, &h_f]);
            }
            let p = history.partials();
            out.extend(p.gram.iter().chain(&p.projection).map(|v| v.to_bits()));
            out.push(p.residual2.to_bits());
            let gamma = (0..history.len()).map(|i| 0.1 * (i as f64 + 1.0)).collect();
            history.apply(&AndersonStep::Mix(gamma), &mut w, &mut f);
            bits(&w, &mut out);
            bits(&f, &mut out);
        }
        (out, statuses)
    }

    /// The kernels give the same bits at every level this CPU has (Rust neither contracts nor
    /// reorders floating-point operations, so wider vectors only run the same operations side
    /// by side). On a CPU without AVX2 only the baseline runs and the test says so.
    #[test]
    fn kernels_give_the_same_bits_at_every_level() {
        let (base, statuses) = with_level(Level::Baseline, outputs);
        assert!(base.len() > 10_000, "the kernels produced {} values", base.len());
        // Separated, sticking and slipping points all occur: every branch of the contact law ran.
        assert!(statuses.iter().all(|&c| c > 0), "points per status: {statuses:?}");
        let mut compared = Vec::new();
        for level in [Level::Avx2, Level::Avx512] {
            if capped(level) != level {
                continue;
            }
            let (at_level, (bits, _)) = with_level(level, || (self::level(), outputs()));
            assert_eq!(at_level, level);
            assert!(bits == base, "{level:?} differs from the baseline");
            compared.push(level.name());
        }
        eprintln!("compared the baseline with: {compared:?} (detected {:?})", detected());
    }

    #[test]
    fn sum_adds_every_value() {
        for n in [0usize, 1, 15, 16, 17, 1000] {
            let v: Vec<f64> = (0..n).map(|i| i as f64).collect();
            assert_eq!(sum(&v), (n * n.saturating_sub(1) / 2) as f64, "n = {n}");
        }
    }

    #[test]
    fn levels_are_capped_at_the_cpu() {
        let have = detected();
        assert_eq!(with_level(Level::Baseline, level), Level::Baseline);
        assert_eq!(with_level(Level::Avx512, level), have);
        assert_eq!(level(), have);
    }

    /// The crate's `matmul` is faer's product, bit for bit, for every accumulation mode and
    /// shapes with remainders; clearing the registers' upper halves after it changes no value.
    #[test]
    fn matmul_is_faers_product() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for (m, k, n) in [(1, 1, 1), (7, 5, 3), (48, 17, 33), (130, 70, 101)] {
            let a = random(&mut seed, m, k, 2.0);
            let b = random(&mut seed, k, n, 2.0);
            let c0 = random(&mut seed, m, n, 2.0);
            for accum in [faer::Accum::Replace, faer::Accum::Add] {
                let (mut ours, mut faers) = (c0.clone(), c0.clone());
                matmul(ours.as_mut(), accum, a.as_ref(), b.as_ref(), -0.75, faer::Par::Seq);
                faer::linalg::matmul::matmul(faers.as_mut(), accum, a.as_ref(), b.as_ref(), -0.75, faer::Par::Seq);
                let (mut x, mut y) = (Vec::new(), Vec::new());
                bits(&ours, &mut x);
                bits(&faers, &mut y);
                assert_eq!(x, y, "{m} × {k} · {k} × {n}, {accum:?}");
            }
        }
        clear_upper_state();
    }
}
