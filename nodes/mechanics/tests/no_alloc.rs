//! No allocation inside the iteration loop: after warm-up iterations, whole LATIN iterations —
//! micro problem 1, macro forces, macro problem, micro problem 2 with the relaxation, the local
//! stage with its indicators and search-direction update, q̂ for the next linear stage — run
//! without one call to the allocator. Counted by a global allocator on the test's own thread.

#[path = "support/latin.rs"]
mod latin;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    /// Allocator calls made on this thread (realloc included).
    static CALLS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    // `try_with`: a thread being torn down has no counter left, and is not the test's.
    let _ = CALLS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc(layout)
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc_zeroed(layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        System.realloc(ptr, layout, new_size)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn calls() -> u64 {
    CALLS.with(|c| c.get())
}

/// Runs `warm_up` iterations (μ = 1 at 0 and 1, relaxed from 2 on; first use of the product
/// kernels' thread-local buffers), then `measured` more, and returns the allocator calls of the
/// setup and of the measured iterations, and whether some interface updated its directions.
fn allocations(scene: &str, search_direction_update: bool, warm_up: usize, measured: usize) -> (u64, u64, bool) {
    allocations_with(scene, search_direction_update, true, warm_up, measured)
}

/// As [`allocations`], with the condensed linear stage (`dense`) or the sparse one.
fn allocations_with(
    scene: &str,
    search_direction_update: bool,
    dense: bool,
    warm_up: usize,
    measured: usize,
) -> (u64, u64, bool) {
    // The model fixtures (tests/fixtures/, kept in step with their scenes by the scene crate).
    let json = match scene {
        "small-three-layer.toml" => include_str!("fixtures/small-three-layer.model.json"),
        other => panic!("no model fixture for {other}"),
    };
    let before_setup = calls();
    let mut model: glissade_mechanics::model::Model = serde_json::from_str(json).expect("a model fixture");
    model.solver.search_direction_update = search_direction_update;
    let mut run = latin::Latin::with_dense(model, dense);
    for _ in 0..warm_up {
        run.iterate();
    }
    let setup = calls() - before_setup;
    let mut eta = Vec::with_capacity(measured);
    let updated_before = run.locals.iter().any(|l| l.directions.is_some());
    let before = calls();
    for _ in 0..measured {
        eta.push(run.iterate().eta());
    }
    let during = calls() - before;
    // The iterations did work: η is finite and moved (a loop that skipped the stages would not
    // change it).
    assert!(eta.iter().all(|e| e.is_finite()), "η {eta:?}");
    assert!(
        eta.first() != eta.last(),
        "η did not change over the measured iterations: {eta:?}"
    );
    let updated = !updated_before && run.locals.iter().any(|l| l.directions.is_some());
    (setup, during, updated)
}

#[test]
fn latin_iterations_do_not_allocate() {
    // small-three-layer: perfect interfaces and two frictional contact interfaces, coarse problem
    // on; 3 warm-up iterations reach the relaxed regime (μ < 1 from iteration 2).
    let (setup, during, _) = allocations("small-three-layer.toml", false, 3, 10);
    // The counter sees this thread's allocations: building the model and operators allocates.
    assert!(
        setup > 100,
        "the counting allocator saw only {setup} calls during the setup"
    );
    assert_eq!(during, 0, "allocator calls during 10 iterations");
}

#[test]
fn iterations_with_the_search_direction_update_do_not_allocate() {
    // With the update on, its directions are stored in buffers allocated with the interface. On
    // small-three-layer the update happens within the 60 measured iterations (asserted).
    let (_, during, updated) = allocations("small-three-layer.toml", true, 3, 60);
    assert!(
        updated,
        "no direction update during the measured iterations: the case does not test it"
    );
    assert_eq!(
        during, 0,
        "allocator calls during 60 iterations with the search-direction update"
    );
}

#[test]
fn sparse_linear_stage_iterations_do_not_allocate() {
    // The sparse linear stage (`linear_stage = "sparse"`): each micro problem is one solve with
    // the sparse factors for all time points, its right-hand sides and the solve's own scratch
    // allocated with the subdomain.
    let (setup, during, _) = allocations_with("small-three-layer.toml", false, false, 3, 10);
    assert!(
        setup > 100,
        "the counting allocator saw only {setup} calls during the setup"
    );
    assert_eq!(
        during, 0,
        "allocator calls during 10 iterations of the sparse linear stage"
    );
}

#[test]
fn pgd_linear_stage_with_the_forcing_criterion_does_not_allocate() {
    // The forcing criterion keeps the previous targets in buffers allocated with the stage: an
    // update on a fixed basis (micro 1 and micro 2, the relaxation in coordinates and the
    // expansion) calls no allocator. Enrichment is off after the warm-up (ξ₀ = ∞).
    use glissade_mechanics::pgd::{PgdCriterion, PgdSettings, PgdStage};
    let json = include_str!("fixtures/small-three-layer.model.json");
    let model: glissade_mechanics::model::Model = serde_json::from_str(json).expect("a model fixture");
    let tw = model.time.trapezoid_weights();
    let mut run = latin::Latin::new(model);
    let solver = &mut run.solvers[0];
    let (n_b, nt, n_m) = (solver.n_boundary(), solver.w_d.ncols(), solver.n_macro());
    let settings = PgdSettings {
        criterion: PgdCriterion::Forcing,
        xi1: 0.1,
        xi2: 0.01,
        macro_modes: false,
        max_new_modes: 2,
    };
    let mut stage = PgdStage::new(solver, &tw, settings);
    let target = |s: f64| faer::Mat::from_fn(n_b, nt, |r, i| ((r * 7 + i * 3) as f64 * 0.37 + s).sin());
    let w_tilde = faer::Mat::from_fn(n_m, nt, |r, i| ((r + i) as f64 * 0.11).cos());
    let (targets, mut w, mut f) = (
        [target(0.0), target(0.5), target(1.0)],
        faer::Mat::<f64>::zeros(n_b, nt),
        faer::Mat::<f64>::zeros(n_b, nt),
    );
    for q in &targets {
        stage.micro1(solver, q.as_ref());
        stage.micro2(solver, w_tilde.as_ref());
    }
    assert!(stage.n_modes() > 0);
    stage.settings.xi1 = f64::INFINITY;
    stage.settings.xi2 = f64::INFINITY;
    let w_d = solver.w_d.clone();
    let before = calls();
    for q in &targets {
        stage.micro1(solver, q.as_ref());
        stage.micro2(solver, w_tilde.as_ref());
        stage.relax_state(0.8);
        stage.expand_into(w_d.as_ref(), w.as_mut(), f.as_mut(), true);
    }
    assert_eq!(calls() - before, 0, "allocator calls during PGD linear stages");
}
