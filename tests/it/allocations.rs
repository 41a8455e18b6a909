//! The iteration loop allocates no field-sized buffer: every node writes its outgoing fields into
//! buffers the bus hands back once delivered (`glissade_bus::convert::FieldPool`), and works in
//! matrices allocated when it is built. Counted by the test binary's allocator: allocations whose
//! size is a whole number of time series of this test's scene (a multiple of N + 1 = 173 values,
//! counted in a process that runs this test alone). Two runs that differ only in their iteration
//! count must make the same number of them.

use crate::common::{scene, scene_text};
use glissade::run::Run;
use glissade::runner::RunOptions;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

/// Bytes of one watched time series (0: counting off).
static WATCH: AtomicUsize = AtomicUsize::new(0);
static COUNT: AtomicU64 = AtomicU64::new(0);

pub struct Counting;

fn count(size: usize) {
    let w = WATCH.load(Ordering::Relaxed);
    // At least two rows: one time series alone (a row of a time grid, a time-function vector)
    // is not a field.
    if w != 0 && size >= 2 * w && size.is_multiple_of(w) {
        COUNT.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every call forwards to the system allocator unchanged; the counter has no effect on
// the memory handed out.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count(new_size);
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

const N: usize = 172;

/// Field-sized allocations of an in-process run of the small three-layer scene (6 subdomains,
/// coarse problem, Anderson) capped at `iterations`.
fn field_allocations(iterations: u32) -> (u64, usize) {
    let text = scene_text("small-three-layer").replace("N = 10\n", &format!("N = {N}\n"));
    let mut sc = scene(&text);
    assert_eq!(sc.model.time.n_points(), N + 1);
    (sc.model.solver.accuracy, sc.model.solver.tolerance) = (None, Some(1e-300));
    sc.model.solver.max_iterations = iterations as usize;
    sc.model.solver.stagnation_window = 100_000;
    let opts = RunOptions::new("allocations");
    COUNT.store(0, Ordering::Relaxed);
    WATCH.store((N + 1) * std::mem::size_of::<f64>(), Ordering::Relaxed);
    let result = Run::new(&sc, &opts).in_process().map(|o| o.result);
    WATCH.store(0, Ordering::Relaxed);
    let result = result.expect("run");
    (COUNT.load(Ordering::Relaxed), result.iterations.len())
}

/// Set in the child process that counts (the test binary run again for this test alone, so that
/// no other test allocates meanwhile).
const CHILD: &str = "GLISSADE_COUNT_ALLOCATIONS";

#[test]
fn iterations_allocate_no_field_sized_buffer() {
    if std::env::var_os(CHILD).is_none() {
        let out = std::process::Command::new(std::env::current_exe().expect("test binary"))
            .args([
                "--exact",
                "allocations::iterations_allocate_no_field_sized_buffer",
                "--test-threads=1",
                "--nocapture",
            ])
            .env(CHILD, "1")
            .output()
            .expect("run the test binary again");
        let text = String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "the counting run failed:\n{text}");
        assert!(text.contains("1 passed"), "the counting run ran no test:\n{text}");
        for line in text.lines().filter(|l| l.starts_with("field-sized allocations")) {
            eprintln!("{line}");
        }
        return;
    }
    // One-time initialisations (thread pools, lazily built tables) happen in a first run.
    field_allocations(2);
    let (short, n_short) = field_allocations(8);
    let (long, n_long) = field_allocations(24);
    eprintln!("field-sized allocations: {short} in {n_short} iterations, {long} in {n_long}");
    assert_eq!((n_short, n_long), (8, 24), "both runs reach their cap");
    assert!(short > 0, "the counter sees the run's fields");
    // Setup and the first iterations fill the pools; later iterations reuse them, so the longer
    // run makes exactly as many. With the bus's recycling switched off, the same two runs made
    // 613 and 1093: 30 per iteration (each subdomain's W, F and macro forces, each q̂, each w̃).
    assert_eq!(
        long, short,
        "{short} field-sized allocations in {n_short} iterations, {long} in {n_long}"
    );
}
