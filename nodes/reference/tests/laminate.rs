//! The reference on the 4-ply laminates of issues 32 and 55 (fixtures/laminate*.toml: pressed,
//! without pressure, unloading to zero), and how a step that does not converge is reported.

use glissade_mechanics::model::Model;
use glissade_reference::*;
use std::time::Instant;

fn model_of(text: &str, file: &str) -> Model {
    match glissade_scene::load_str(text, file) {
        Ok(sc) => sc.model,
        Err(e) => panic!("{e}"),
    }
}

fn laminate() -> Model {
    model_of(include_str!("fixtures/laminate.toml"), "laminate.toml")
}

fn laminate_no_pressure() -> Model {
    model_of(
        include_str!("fixtures/laminate-no-pressure.toml"),
        "laminate-no-pressure.toml",
    )
}

fn laminate_unload() -> Model {
    model_of(include_str!("fixtures/laminate-unload.toml"), "laminate-unload.toml")
}

/// Solves with the default options, prints iterations and time, and checks the solution against
/// the discrete problem at the solver's tolerance.
fn converges_and_verifies(model: &Model) -> ReferenceSolution {
    let start = Instant::now();
    let sol = solve_reference(model, &ReferenceOptions::default()).unwrap_or_else(|e| panic!("{}: {e}", model.name));
    let elapsed = start.elapsed().as_secs_f64();
    let checks = verify(model, &sol).unwrap_or_else(|e| panic!("{}: {e}", model.name));
    println!(
        "{}: Newton iterations per step {:?} (total {}, max {}), solve {elapsed:.2} s",
        model.name,
        sol.newton_iterations,
        sol.newton_iterations.iter().sum::<usize>(),
        sol.newton_iterations.iter().max().copied().unwrap_or(0),
    );
    println!("{}: {checks:?}", model.name);
    assert_eq!(sol.newton_iterations.len(), model.time.n_points());
    assert!(checks.max() <= 1e-10, "{}: {checks:?}", model.name);
    sol
}

#[test]
fn laminate_reference_converges() {
    converges_and_verifies(&laminate());
}

/// The laminate that unloads to zero: every time point solved, the last one (t = 1,
/// no load at all) included, by the first attempt.
#[test]
fn laminate_unloading_to_zero_solves_every_time_point() {
    let model = laminate_unload();
    let sol = converges_and_verifies(&model);
    let last = model.time.n_points() - 1;
    let load_at = |i: usize| {
        let t = model.time.t(i);
        model
            .subdomains
            .iter()
            .flat_map(|s| {
                s.loads
                    .iter()
                    .map(move |c| c.force.iter().map(|f| (f * c.time.eval(t)).abs()).sum::<f64>())
            })
            .sum::<f64>()
    };
    assert_eq!(load_at(last), 0.0);
    assert!(load_at(25) > 199.0);
    let u_at = |i: usize| sol.u.iter().map(|u| u.col(i).norm_max()).fold(0.0, f64::max);
    let contact_at = |i: usize| {
        sol.contact
            .iter()
            .flatten()
            .map(|c| c.lambda.col(i).norm_max())
            .fold(0.0, f64::max)
    };
    println!(
        "largest |u| (mm) and contact force (N): held (t = 0.5) {:.3e}, {:.3e}; unloaded (t = 1) {:.3e}, {:.3e}",
        u_at(25),
        contact_at(25),
        u_at(last),
        contact_at(last)
    );
    // Unloaded, the plies slide back to the state they started from: the measured solution at
    // t = 1 is zero to round-off (1e-16 mm, 1e-16 N; 1e-18 of the held state's 83 mm), so every
    // pair sits at λ = 0, g = 0, the degenerate corner of its law. 1e-9 of the held state leaves
    // room for round-off and none for a state that kept part of the load's deformation.
    assert!(u_at(last) <= 1e-9 * u_at(25) && contact_at(last) <= 1e-9 * contact_at(25));
    // Solved by the first (monotone, 50 iterations) attempt: the step at zero load was the one
    // that no attempt solved in 1250 iterations when the checks were relative to the step's own
    // (vanishing) forces and displacements.
    assert!(
        sol.newton_iterations[last] <= ReferenceOptions::default().max_newton_iterations,
        "{:?}",
        sol.newton_iterations
    );
}

#[test]
fn laminate_without_pressure_reference_converges() {
    converges_and_verifies(&laminate_no_pressure());
}

/// Without the non-monotone attempt the fixture fails at its first loaded step: it still
/// exercises what the non-monotone attempt is for.
#[test]
fn laminate_without_pressure_needs_the_nonmonotone_attempt() {
    let model = laminate_no_pressure();
    let opts = ReferenceOptions {
        nonmonotone_iterations: 0,
        ..ReferenceOptions::default()
    };
    let run = solve_reference_steps(&model, &opts).expect("set-up");
    match run.failure {
        Some(ReferenceError::NotConverged { step, ref tried, .. }) => {
            assert_eq!(step, 1);
            assert_eq!(tried.len(), 1 + opts.fallback_r_factors.len());
            assert!(tried.iter().all(|a| a.attempt.window == 1));
        }
        other => panic!("expected a failure at step 1, got {other:?}"),
    }
}

/// A step that no attempt solves: the error names the step, every attempt tried with its
/// iterations and worst violation; the steps before it are kept.
#[test]
fn reference_failure_reports_what_was_tried_and_keeps_the_steps_solved() {
    let model = model_of(
        include_str!("../../../launch/scenes/small-three-layer.toml"),
        "small-three-layer.toml",
    );
    // Step 0 converges in 2 iterations, step 1 needs 5.
    let opts = ReferenceOptions {
        max_newton_iterations: 2,
        fallback_r_factors: vec![10.0],
        nonmonotone_window: 4,
        nonmonotone_iterations: 1,
        ..ReferenceOptions::default()
    };
    let run = solve_reference_steps(&model, &opts).expect("set-up");
    let Some(error) = run.failure.clone() else {
        panic!("expected a failure; iterations {:?}", run.solution.newton_iterations);
    };
    let ReferenceError::NotConverged {
        step,
        time,
        ref tried,
        violation,
        tolerance,
    } = error
    else {
        panic!("unexpected error {error}");
    };
    assert_eq!(step, 1);
    assert_eq!(time, model.time.t(1));
    assert_eq!(tolerance, 1e-10);
    let attempts: Vec<Attempt> = tried.iter().map(|a| a.attempt).collect();
    assert_eq!(attempts, opts.attempts());
    assert_eq!(
        attempts,
        vec![
            Attempt {
                r_factor: 1.0,
                window: 1,
                max_iterations: 2
            },
            Attempt {
                r_factor: 1.0,
                window: 4,
                max_iterations: 1
            },
            Attempt {
                r_factor: 10.0,
                window: 1,
                max_iterations: 2
            },
        ]
    );
    assert!(tried.iter().all(|a| a.violation > tolerance));
    assert_eq!(
        violation,
        tried.iter().map(|a| a.violation).fold(f64::INFINITY, f64::min)
    );
    let text = error.to_string();
    println!("{text}");
    for part in [
        "time step 1 (t = 0.1)",
        "did not converge in 5 iterations",
        "r factor 1, monotone line search, 2 iterations",
        "r factor 1, non-monotone line search over 4 iterates, 1 iterations",
        "r factor 10, monotone line search, 2 iterations",
    ] {
        assert!(text.contains(part), "`{part}` not in: {text}");
    }
    // The steps solved: time point 0 only, one column per field.
    assert_eq!(run.solution.newton_iterations.len(), 1);
    assert!(run.solution.u.iter().all(|u| u.ncols() == 1));
    assert!(run.solution.interfaces.iter().all(|f| f.f_a.ncols() == 1));
    assert_eq!(solve_reference(&model, &opts), Err(error));
}
