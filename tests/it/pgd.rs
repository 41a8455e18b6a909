//! The three linear stages (condensed A_E, sparse factors, PGD) on whole runs: the sparse stage
//! gives the condensed stage's iterates, and PGD converges to the same limit.

use crate::common::{rel_max, run, scene, scene_text};
use glissade::report::{build_reports, comparison_table, plot_svg, Variant};
use glissade::run::Run;
use glissade::runner::RunResult;
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::local::error_against_reference;
use glissade_mechanics::model::Acceleration;
use glissade_mechanics::pgd::{PgdCriterion, PgdParams};
use glissade_messages::Verdict;
use glissade_scene::LoadedScene;

fn scene_file(name: &str) -> LoadedScene {
    let path = format!("{}/launch/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    scene(&std::fs::read_to_string(path).expect("scene file"))
}

/// Every field of every interface at the stop, concatenated (s and ŝ of both sides).
fn all_fields(r: &RunResult) -> Vec<f64> {
    let mut v = Vec::new();
    let mut sols: Vec<_> = r.interfaces.iter().collect();
    sols.sort_by_key(|s| s.interface);
    for s in sols {
        for f in [
            &s.w_a, &s.w_b, &s.f_a, &s.f_b, &s.w_a_hat, &s.w_b_hat, &s.f_a_hat, &s.f_b_hat,
        ] {
            for j in 0..f.cols() {
                for i in 0..f.rows() {
                    v.push(f.get(i, j));
                }
            }
        }
    }
    v
}

#[test]
fn sparse_stage_gives_the_condensed_iterates() {
    let mut sc = scene_file("small-three-layer");
    (sc.model.solver.accuracy, sc.model.solver.tolerance) = (None, Some(1e-300));
    sc.model.solver.contact_tolerance = None;
    sc.model.solver.max_iterations = 30;
    sc.model.solver.stagnation_window = 1000;
    let condensed = run(&sc);
    sc.linear_stage = LinearStage::Sparse;
    let sparse = run(&sc);
    assert_eq!(condensed.iterations.len(), 30);
    assert_eq!(sparse.iterations.len(), condensed.iterations.len());
    // Same operator, applied by a dense product with A_E = B K̃⁻¹Bᵀ or by sparse solves: the
    // iterates differ by round-off only, amplified little over 30 contracting iterations.
    let d = rel_max(&all_fields(&sparse), &all_fields(&condensed));
    println!("sparse vs condensed after 30 iterations: {d:.2e}");
    assert!(d <= 1e-10, "{d:e}");
    for (a, b) in sparse.iterations.iter().zip(&condensed.iterations) {
        let (ea, eb) = (a.decision.eta, b.decision.eta);
        assert!(
            (ea - eb).abs() <= 1e-10 * eb,
            "iteration {}: η {ea:e} vs {eb:e}",
            a.iteration
        );
    }
}

/// Runs `sc` to η ≤ `tolerance` without PGD (condensed) and with it; returns the space-time
/// relative differences of the contact tractions and jumps (forces of cross-point copies summed:
/// only their sum is determined) and the iteration counts.
fn same_limit(sc: LoadedScene, pgd: PgdParams, tolerance: f64) -> (f64, f64) {
    same_limit_with(sc, pgd, tolerance, Acceleration::None)
}

/// [`same_limit`] with the PGD run accelerated by `acceleration` (the exact run stays plain).
fn same_limit_with(mut sc: LoadedScene, pgd: PgdParams, tolerance: f64, acceleration: Acceleration) -> (f64, f64) {
    sc.model.solver.acceleration = Acceleration::None;
    (sc.model.solver.accuracy, sc.model.solver.tolerance) = (None, Some(tolerance));
    sc.model.solver.contact_tolerance = None;
    sc.model.solver.max_iterations = 20_000;
    sc.model.solver.stagnation_window = 20_000;
    sc.linear_stage = LinearStage::Condensed;
    let exact = run(&sc);
    assert_eq!(exact.verdict, Verdict::Converged);
    sc.linear_stage = LinearStage::Pgd;
    sc.pgd = pgd.clone();
    sc.model.solver.acceleration = acceleration;
    let with_pgd = run(&sc);
    assert_eq!(
        with_pgd.verdict,
        Verdict::Converged,
        "{:?}",
        with_pgd.iterations.last().map(|r| &r.decision)
    );
    let weights = sc.model.time.trapezoid_weights();
    let (e_f, e_w) = error_against_reference(
        &sc.model.interfaces,
        &with_pgd.interface_fields(),
        &exact.interface_fields(),
        &weights,
    );
    println!(
        "{} at η ≤ {tolerance:e}, PGD {:?} ξ₀ = ({}, {}) macro_modes {} {acceleration:?}: {} iterations without PGD, {} with; contact tractions differ by {e_f:.2e}, jumps by {e_w:.2e}",
        sc.model.name,
        pgd.criterion,
        pgd.xi1,
        pgd.xi2,
        pgd.macro_modes,
        exact.iterations.len(),
        with_pgd.iterations.len()
    );
    (e_f, e_w)
}

/// PGD with the default settings (increment criterion, ξ₀ = 0.1 / 0.01, no frozen macro modes).
fn default_pgd() -> PgdParams {
    PgdParams::default()
}

// Same limit. Every PGD state is admissible (each pair (Z, G) is, to round-off) and with the
// increment criterion a stationary iterate has λ unchanged, so ‖δ‖ = ‖residual‖, ξ = 1 > ξ₀ and the
// basis is enriched until the residual is round-off: a fixed point of the PGD iteration is a fixed
// point of the exact one. What differs is the path, so two runs stopped at the same η differ by
// about their distances to the limit, which η underestimates. Measured (release, contact
// tractions, space-time, copies summed): at η ≤ 1e-7, 2.0e-6 on hertz-slip and 7.4e-6 on
// two-blocks, over the 1e-6, because plain LATIN itself stopped at η ≤ 1e-7 is that far
// from its limit; at η ≤ 1e-10, 1.2e-9 and 6.9e-9; at η ≤ 1e-12, 1.2e-11 and 6.6e-11: the
// difference falls with η as each run's distance to the limit does. So the tests stop at
// η ≤ 1e-10 and ask for 1e-7 (the 1e-6 with a margin of ten that still fails a PGD run
// whose limit is off: the accumulated criterion stalls at η = 5e-2 on hertz-slip).

#[test]
fn pgd_keeps_the_hertz_slip_limit() {
    let (e_f, e_w) = same_limit(scene_file("hertz-slip"), default_pgd(), 1e-10);
    assert!(e_f <= 1e-7 && e_w <= 1e-7, "tractions {e_f:e}, jumps {e_w:e}");
}

#[test]
fn pgd_keeps_the_two_blocks_limit() {
    let (e_f, e_w) = same_limit(scene_file("two-blocks"), default_pgd(), 1e-10);
    assert!(e_f <= 1e-7 && e_w <= 1e-7, "tractions {e_f:e}, jumps {e_w:e}");
}

/// The other criteria and frozen macro modes keep the limit too (measured at η ≤ 1e-10:
/// increment-svd 7.7e-10 on hertz-slip, frozen macro modes 2.6e-9 on two-blocks).
#[test]
fn pgd_variants_keep_the_limit() {
    let svd = PgdParams {
        criterion: PgdCriterion::IncrementSvd,
        ..default_pgd()
    };
    let (e_f, e_w) = same_limit(scene_file("hertz-slip"), svd, 1e-10);
    assert!(
        e_f <= 1e-7 && e_w <= 1e-7,
        "increment-svd: tractions {e_f:e}, jumps {e_w:e}"
    );
    let frozen = PgdParams {
        macro_modes: true,
        ..default_pgd()
    };
    let (e_f, e_w) = same_limit(scene_file("two-blocks"), frozen, 1e-10);
    assert!(
        e_f <= 1e-7 && e_w <= 1e-7,
        "macro modes: tractions {e_f:e}, jumps {e_w:e}"
    );
}

/// PGD with Anderson acceleration. The least-squares problem is the one without PGD (the forces of
/// the expanded states and images), and what is mixed with its coefficients is the time functions
/// of the state on the subdomain's basis (the state is held and sent in mode form): the iterates
/// and images all lie in the span of the current basis (it only grows between compressions, and a
/// compression rotates the stored coordinates with it), so this is the same affine combination
/// (the coefficients sum to one) as mixing the expanded fields, and the mixed state is admissible
/// like every PGD state. The fixed point is the one of the PGD iteration, hence of the exact one
/// (see above), so the same limit and the same tolerance apply. Measured (test profile) at
/// η ≤ 1e-10: see the printed line.
#[test]
fn pgd_with_anderson_keeps_the_limit() {
    let anderson = Acceleration::Anderson { window: 5 };
    for name in ["two-blocks", "hertz-slip"] {
        let (e_f, e_w) = same_limit_with(scene_file(name), default_pgd(), 1e-10, anderson);
        assert!(e_f <= 1e-7 && e_w <= 1e-7, "{name}: tractions {e_f:e}, jumps {e_w:e}");
    }
}

/// The forcing criterion (residual against the target's own step), at a loose ξ₀,₁ = 1 and with
/// Anderson: a stationary target's residual is enriched to round-off, so its fixed point is the
/// exact one too (`glissade_mechanics::pgd` module docs); same tolerance as above.
#[test]
fn pgd_forcing_keeps_the_limit() {
    let forcing = PgdParams {
        criterion: PgdCriterion::Forcing,
        xi1: 1.0,
        ..default_pgd()
    };
    let anderson = Acceleration::Anderson { window: 5 };
    for name in ["two-blocks", "hertz-slip"] {
        let (e_f, e_w) = same_limit_with(scene_file(name), forcing.clone(), 1e-10, anderson);
        assert!(e_f <= 1e-7 && e_w <= 1e-7, "{name}: tractions {e_f:e}, jumps {e_w:e}");
    }
    let (e_f, e_w) = same_limit(scene_file("hertz-slip"), forcing, 1e-10);
    assert!(e_f <= 1e-7 && e_w <= 1e-7, "plain: tractions {e_f:e}, jumps {e_w:e}");
}

/// Stratified (18 subdomains, N = 100). Measured (release): contact tractions differ by 9.4e-5
/// at η ≤ 1e-7, 2.1e-6 at η ≤ 1e-9, 2.1e-7 at η ≤ 1e-10 and 2.3e-8 at η ≤ 1e-11 (PGD 857, 1095
/// and 1408 iterations, plain 1176, 1685 and 2206): the same limit, approached more slowly in η
/// than on the small scenes (η underestimates the traction error by about 10³ here), so the
/// issue's 1e-6 needs η ≤ 1e-10. About ten minutes in a release build on a loaded 2-core machine:
/// `cargo test --release --test integration pgd_keeps_the_stratified_limit -- --ignored`.
#[test]
#[ignore = "about ten minutes in release; run as documented above"]
fn pgd_keeps_the_stratified_limit() {
    let text = scene_text("stratified").replace("\nN = 1000\n", "\nN = 100\n");
    let (e_f, e_w) = same_limit(scene(&text), default_pgd(), 1e-10);
    assert!(e_f <= 1e-6 && e_w <= 1e-6, "tractions {e_f:e}, jumps {e_w:e}");
}

/// `glissade report --variants`: one reference, one report per stage, with the PGD basis
/// size per subdomain and iteration and the bus bytes per iteration.
#[test]
fn reports_compare_linear_stages() {
    let mut sc = scene_file("two-blocks");
    // Every variant runs the 30 iterations: no stop on accuracy or η.
    (sc.model.solver.accuracy, sc.model.solver.tolerance) = (None, Some(1e-300));
    sc.model.solver.max_iterations = 30;
    sc.model.solver.acceleration = Acceleration::None;
    let mut variants = [LinearStage::Condensed, LinearStage::Pgd].map(Variant::from).to_vec();
    variants.push("pgd+anderson".parse().expect("a variant"));
    let (reports, _) = build_reports(&sc, "pgd-report", &variants, None).expect("reports");
    let (c, p, pa) = (&reports[0], &reports[1], &reports[2]);
    // The third variant replaces the scene's plain relaxation by Anderson mixing: every iteration
    // from iteration 2 on (iterations 0 and 1 only record) takes one Anderson step (mixed,
    // safeguarded or restarted).
    assert_eq!(
        (c.acceleration.as_str(), pa.acceleration.as_str()),
        ("none", "anderson(5)")
    );
    assert_eq!(pa.anderson_steps.iter().sum::<u32>() as usize, pa.points.len() - 2);
    assert!(pa.anderson_steps[0] > 0, "{:?}", pa.anderson_steps);
    assert!(comparison_table(&reports).contains("pgd(increment"));
    assert!(comparison_table(&reports).contains(" + anderson(5) | "));
    for bad in ["dense", "pgd+nesterov", "condensed+"] {
        assert!(bad.parse::<Variant>().is_err(), "{bad}");
    }
    assert_eq!(c.linear_stage, "condensed");
    assert!(p.linear_stage.starts_with("pgd(increment"), "{}", p.linear_stage);
    assert_eq!(c.points.len(), 30);
    assert!(c.points.iter().all(|x| x.basis_sizes.is_empty()));
    assert!(c.points.iter().all(|x| x.linear_s >= 0.0 && x.linear_s.is_finite()));
    // Both blocks take part; without compression a basis only grows, by at most one mode per
    // micro problem (max_new_modes = 1, micro 1 and 2).
    assert!(p.points.iter().all(|x| x.basis_sizes.len() == 2));
    for w in p.points.windows(2) {
        for (a, b) in w[0].basis_sizes.iter().zip(&w[1].basis_sizes) {
            assert!(b >= a && b - a <= 2, "{:?} → {:?}", w[0].basis_sizes, w[1].basis_sizes);
        }
    }
    assert!(p.points.last().unwrap().basis_sizes.iter().all(|&m| m > 2));
    // PGD subdomains send their state in mode form: the time functions of at most 2 + 2n modes
    // at iteration n (plus each new mode once), against two full fields of n_b rows without PGD;
    // the other messages are the same. Fewer bytes at every iteration while the basis stays
    // below 2 n_b modes, as here (at most 62 modes after 30 iterations).
    for (x, y) in c.points.iter().zip(&p.points) {
        assert!(y.bus_bytes > 0);
        assert!(
            y.bus_bytes < x.bus_bytes,
            "iteration {}: {} against {}",
            x.iteration,
            y.bus_bytes,
            x.bus_bytes
        );
    }
    assert!(plot_svg(p, Default::default()).contains("PGD basis size per subdomain"));
    assert!(!plot_svg(c, Default::default()).contains("PGD basis size per subdomain"));
}

/// `glissade report --stop-at-error e`: each run stops at the first iteration whose traction
/// error is at most e, with the same iterates as the run that goes on (the solver is
/// deterministic, so the errors agree bit for bit).
#[test]
fn reports_stop_at_an_accuracy() {
    let mut sc = scene_file("two-blocks");
    sc.model.solver.max_iterations = 60;
    let variants = [Variant::from(LinearStage::Condensed)];
    let (full, _) = build_reports(&sc, "stop-full", &variants, None).expect("report");
    let full = &full[0];
    assert!(full.points.len() > 20, "{} iterations", full.points.len());
    // An accuracy the run reaches about a third of the way in.
    let e = full.points[full.points.len() / 3].traction_error;
    let k = full.points.iter().position(|p| p.traction_error <= e).expect("reached");
    let (stopped, _) = build_reports(&sc, "stop-early", &variants, Some(e)).expect("report");
    let stopped = &stopped[0];
    assert_eq!(stopped.points.len(), k + 1, "{}", stopped.latin_verdict);
    for (a, b) in stopped.points.iter().zip(&full.points) {
        assert_eq!((a.iteration, a.traction_error), (b.iteration, b.traction_error));
    }
    assert!(
        stopped.latin_verdict.starts_with("stopped at a traction error"),
        "{}",
        stopped.latin_verdict
    );
}

/// Flops of the three linear stages in the report and the run summary: condensed and sparse
/// make the same products and solves every iteration (their counts per iteration are the
/// formulas of the solver's kernels, from n_b, n_m, N + 1 and nnz(L)); PGD's vary with its basis.
#[test]
fn reports_count_linear_stage_flops() {
    use glissade::output::linear_stage_totals;
    use glissade::runner::RunOptions;
    use glissade_deploy::Plan;
    use glissade_mechanics::linear::SubdomainSolver;

    let mut sc = scene_file("two-blocks");
    sc.model.solver.max_iterations = 8;
    sc.model.solver.acceleration = Acceleration::None;
    let variants = [LinearStage::Condensed, LinearStage::Sparse, LinearStage::Pgd].map(Variant::from);
    let (reports, _) = build_reports(&sc, "flops", &variants, None).expect("reports");
    let model = &sc.model;
    let plan = Plan::new(model).with_scene(&sc);
    assert!(
        plan.coarse,
        "two-blocks runs the coarse problem: micro 2 and the macro forces count"
    );
    // One iteration's flops of every subdomain, from the kernels' formulas.
    let expected = |dense: bool| -> u64 {
        plan.participants
            .iter()
            .map(|&s| {
                let solver = SubdomainSolver::with_dense(model, s as usize, &plan.k0, &plan.bases, dense).unwrap();
                let (n_b, n_m, nt) = (
                    solver.n_boundary() as u64,
                    solver.n_macro() as u64,
                    model.time.n_points() as u64,
                );
                let mode_rows: u64 = solver
                    .macro_slots
                    .iter()
                    .zip(&solver.op.layout.slots)
                    .map(|(m, slot)| (2 * slot.n_pairs * m.n_modes) as u64)
                    .sum();
                let macro_forces = 2 * mode_rows * nt;
                if dense {
                    // M q̂ and A_E (M q̂), F₁; the macro forces; two n_b × n_m products.
                    nt * (n_b + 2 * n_b * n_b + 2 * n_b) + macro_forces + 4 * n_b * n_m * nt
                } else {
                    let solve = solver.op.sparse_response_flops();
                    nt * (solve + 3 * n_b) + macro_forces + nt * (2 * n_b * n_m + n_b + solve + 2 * n_b)
                }
            })
            .sum()
    };
    let (c, s, p) = (&reports[0], &reports[1], &reports[2]);
    assert_eq!(
        (c.linear_stage.as_str(), s.linear_stage.as_str()),
        ("condensed", "sparse")
    );
    assert_eq!(c.points.len(), 8);
    for (r, dense) in [(c, true), (s, false)] {
        let per_iteration = expected(dense);
        assert!(per_iteration > 0);
        for x in &r.points {
            assert_eq!(
                x.linear_flops, per_iteration,
                "{} iteration {}",
                r.linear_stage, x.iteration
            );
        }
    }
    assert!(p.points.iter().all(|x| x.linear_flops > 0));
    // PGD's count is not a constant: enrichment (a rank-one fit and a boundary response per
    // mode) comes and goes.
    let pgd_counts: Vec<u64> = p.points.iter().map(|x| x.linear_flops).collect();
    assert!(pgd_counts.iter().any(|&f| f != pgd_counts[0]), "{pgd_counts:?}");
    // Up to an accuracy: the flops of the iterations up to it, and the table prints them.
    for r in &reports {
        for a in &r.accuracy {
            if let (Some(it), Some(fl)) = (a.iterations, a.linear_flops) {
                let upto: u64 = r
                    .points
                    .iter()
                    .filter(|x| x.iteration <= it)
                    .map(|x| x.linear_flops)
                    .sum();
                assert_eq!(fl, upto, "{} to {:e}", r.linear_stage, a.threshold);
            }
        }
    }
    let table = comparison_table(&reports);
    assert!(
        table.contains("| linear stage to that error: time (s), GFLOP |") && table.contains("\n| condensed | "),
        "{table}"
    );
    let per_it = format!("linear stage {:.4} GFLOP per iteration", expected(true) as f64 * 1e-9);
    assert!(table.contains(&per_it), "{table}");

    // The run summary's totals: the sum of the records, under the stage's name.
    let mut sparse = sc.clone();
    sparse.linear_stage = LinearStage::Sparse;
    let opts = RunOptions::new("flops");
    let (result, records) = Run::new(&sparse, &opts)
        .linear_stages()
        .in_process()
        .map(|o| (o.result, o.linear_stages))
        .expect("run");
    let totals = linear_stage_totals(&sparse, &records, true);
    assert_eq!(totals.len(), 1);
    let t = &totals[0];
    assert_eq!((t.stage, t.subdomains), ("sparse", plan.participants.len()));
    // Every iteration has a linear stage (iteration 0's from ŝ = 0 included).
    assert_eq!(t.iterations, result.iterations.len());
    assert_eq!(t.flops, expected(false) * t.iterations as u64);
    assert_eq!(t.flops, records.iter().map(|r| r.flops).sum::<u64>());
    assert!(t.json()["flops"].as_u64() == Some(t.flops));
}

/// A PGD subdomain's messages in mode form (docs/pgd.md, "Messages in mode form"): the particular part in its first message
/// only, each basis column once (the `increment` criterion only adds modes, so every message
/// starts where the subdomain's previous one stopped and carries only the modes added since), and
/// the time functions every iteration. The state they describe is the one the interface node
/// works on: the run reaches the same limit as without PGD (the tests above). Bytes against the
/// same states sent as full fields (`BoundaryState` of the expanded W and F): printed.
#[test]
fn pgd_messages_carry_each_mode_once() {
    use glissade::runner::RunOptions;
    use glissade_messages::{encode, Message, Payload};
    use std::collections::BTreeMap;
    let mut sc = scene_file("small-three-layer");
    sc.linear_stage = LinearStage::Pgd;
    sc.pgd = default_pgd();
    let mut held: BTreeMap<u32, usize> = BTreeMap::new();
    let (mut modes_bytes, mut full_bytes, mut messages, mut columns) = (0usize, 0usize, 0usize, 0usize);
    let mut states = glissade_replay::BoundaryStates::new(&sc.model);
    let k = vec![1.0; sc.model.interfaces.len()];
    let opts = RunOptions::new("modes");
    let (result, records) = Run::new(&sc, &opts)
        .observe(|m| {
            match &m.payload {
                Payload::BoundaryState { subdomain, .. } => panic!("PGD subdomain {subdomain} sent full fields"),
                Payload::BoundaryModes {
                    subdomain,
                    particular,
                    first_mode,
                    z,
                    lambda,
                    ..
                } => {
                    let before = held.get(subdomain).copied();
                    assert_eq!(
                        particular.is_some(),
                        before.is_none(),
                        "particular part in the first message only"
                    );
                    assert_eq!(
                        *first_mode as usize,
                        before.unwrap_or(0),
                        "subdomain {subdomain}: only new modes"
                    );
                    assert_eq!(lambda.rows(), *first_mode as usize + z.cols());
                    held.insert(*subdomain, lambda.rows());
                    messages += 1;
                    columns += z.cols();
                    modes_bytes += encode(m).len();
                    let (s, w, f) = states.fields(m).expect("a state").expect("expands");
                    let full = Message {
                        envelope: m.envelope.clone(),
                        payload: Payload::BoundaryState {
                            subdomain: s,
                            to: None,
                            interfaces: glissade_mechanics::condensed::BoundaryLayout::new(&sc.model, s as usize, &k)
                                .slots
                                .iter()
                                .map(|sl| sl.interface as u32)
                                .collect(),
                            w: w.into_owned(),
                            f: f.into_owned(),
                        },
                    };
                    full_bytes += encode(&full).len();
                }
                _ => {}
            }
            std::time::Duration::ZERO
        })
        .linear_stages()
        .in_process()
        .map(|o| (o.result, o.linear_stages))
        .expect("run");
    assert_eq!(result.verdict, Verdict::Converged);
    // Every subdomain ends with the basis its linear stage holds: the modes went over the bus once.
    let last = records.iter().map(|r| r.iteration).max().expect("records");
    for r in records.iter().filter(|r| r.iteration == last) {
        assert_eq!(held.get(&r.subdomain), Some(&r.modes), "subdomain {}", r.subdomain);
    }
    assert_eq!(columns, held.values().sum::<usize>());
    println!(
        "{messages} mode-form states, {columns} basis columns in all: {modes_bytes} bytes against {full_bytes} as full fields ({:.2}x fewer)",
        full_bytes as f64 / modes_bytes as f64
    );
    assert!(modes_bytes < full_bytes);
}
