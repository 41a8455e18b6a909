//! `glissade generate laminate`: the generated scenes are the scenes they say they are, solve
//! right against the monolithic reference, and run alike in-process and as processes.

use crate::common::{glissade_ok, scene, scene_text, scratch};
use glissade::generate::Laminate;
use glissade_messages::Verdict;

/// The model as JSON with every name blanked (ply names differ from the stratified layers').
fn anonymous(sc: &glissade_scene::LoadedScene) -> serde_json::Value {
    fn blank(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(map) => {
                for (k, x) in map.iter_mut() {
                    if k == "name" {
                        *x = serde_json::Value::Null;
                    } else {
                        blank(x);
                    }
                }
            }
            serde_json::Value::Array(items) => items.iter_mut().for_each(blank),
            _ => {}
        }
    }
    let mut v = serde_json::to_value(&sc.model).unwrap();
    blank(&mut v);
    v
}

#[test]
fn the_laminate_at_the_stratified_parameters_is_the_stratified_scene() {
    // Three plies of six 30 mm subdomains of 20 × 20 QUA8, N = 1000: the generator's loads are
    // the stratified scene's, so the two models must be the same discrete problem, bit for bit
    // (names aside).
    let generated = Laminate {
        plies: 3,
        per_ply: 6,
        elements: 20,
        steps: 1000,
        interfaces_with_subdomains: true,
        partition: glissade_scene::Partition::Bisection,
        ..Laminate::default()
    };
    let text = generated.scene_text().unwrap();
    assert!(
        text.contains("--subdomain-nodes 3 --interfaces-with-subdomains --partition bisection`"),
        "{text}"
    );
    let ours = scene(&text);
    let stratified = scene(&scene_text("stratified"));
    assert_eq!(ours.model.subdomains.len(), 18);
    assert_eq!(ours.model.interfaces.len(), generated.interfaces());
    assert!(
        anonymous(&ours) == anonymous(&stratified),
        "the generated model differs from stratified.toml's"
    );
    // And the same deployment: three processes, each a column of two subdomains through the
    // plies with the interfaces inside it.
    assert_eq!(ours.deployment, stratified.deployment);
}

#[test]
fn a_generated_laminate_matches_the_reference_and_runs_alike_as_processes() {
    // 8 plies of 15 subdomains of 2 × 2 QUA8: 217 interfaces, 651 macro unknowns, so the macro
    // problem is factorised sparse (above DENSE_UP_TO), through the coarse node in-process and
    // as a process.
    let laminate = Laminate {
        plies: 8,
        per_ply: 15,
        elements: 2,
        steps: 6,
        subdomain_nodes: 2,
        ..Laminate::default()
    };
    let sc = scene(&laminate.scene_text().unwrap());
    let unknowns: usize = glissade_mechanics::linear::macro_bases(&sc.model)
        .iter()
        .map(Vec::len)
        .sum();
    assert_eq!(
        glissade_mechanics::coarse::Factorisation::for_size(unknowns),
        glissade_mechanics::coarse::Factorisation::Sparse,
        "{unknowns} macro unknowns"
    );
    let check = glissade::accuracy::check_scene("laminate-8x15", &sc, &Default::default()).unwrap();
    for stop in &check.stops {
        // The stop's promise (docs/accuracy.md): at the stop the true contact-traction error is at most 3× the
        // accuracy asked for.
        let err = stop.true_error.expect("a stop with a true error");
        assert!(
            err <= 3.0 * stop.accuracy,
            "accuracy {:e}: true error {err:e} at iteration {:?}",
            stop.accuracy,
            stop.iteration
        );
    }
    let local = crate::distributed::in_process_equals_processes(&sc, "generate-processes");
    assert_eq!(local.verdict, Verdict::Converged);
    // With the interface nodes in the two subdomain processes (groups that do not follow the
    // plies: a process holds contact interfaces too), the same run bit for bit.
    let with = Laminate {
        interfaces_with_subdomains: true,
        ..laminate
    };
    let sc = scene(&with.scene_text().unwrap());
    assert!(sc.deployment.interfaces_with_subdomains);
    let split = crate::distributed::in_process_equals_processes(&sc, "generate-processes-with");
    crate::distributed::assert_identical(&local, &split);
    // And with the processes' groups cut by bisection: the laminate is 450 mm long and 240 mm
    // high, so the cut is across the plies (7.5 columns of 8 subdomains each side): the same run
    // bit for bit.
    let bisected = Laminate {
        partition: glissade_scene::Partition::Bisection,
        ..with
    };
    let sc = scene(&bisected.scene_text().unwrap());
    let plan = glissade_deploy::Plan::new(&sc.model).with_scene(&sc);
    let groups = plan.groups(2);
    assert!(
        groups.iter().all(|g| g
            .iter()
            .map(|s| s / 15)
            .collect::<std::collections::BTreeSet<_>>()
            .len()
            == 8),
        "each process holds a piece of every ply: {groups:?}"
    );
    let cut = crate::distributed::in_process_equals_processes(&sc, "generate-processes-bisected");
    crate::distributed::assert_identical(&local, &cut);
}

#[test]
fn generate_writes_a_scene_that_checks_and_never_overwrites() {
    let dir = scratch("generate");
    let out = dir.join("lam.toml");
    let printed = glissade_ok(&[
        &"generate",
        &"laminate",
        &"--plies",
        &"5",
        &"--per-ply",
        &"20",
        &"-o",
        &out,
    ]);
    assert!(printed.contains("100 subdomains, 175 interfaces"), "{printed}");
    let checked = glissade_ok(&[&"check", &out]);
    assert!(
        checked.contains("100 subdomains, 175 interfaces (80 contact), 101 time points, 68200 dofs"),
        "{checked}"
    );
    let before = std::fs::read(&out).unwrap();
    let again = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["generate", "laminate", "--plies", "2", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&again.stderr);
    assert!(
        !again.status.success() && stderr.contains("not overwritten"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), before, "an existing scene was changed");
    for (args, expected) in [
        (vec!["--plies", "0"], "plies = 0: must be at least 1"),
        (
            vec!["--plies", "2", "--per-ply", "1", "--subdomain-nodes", "3"],
            "subdomain-nodes = 3: must be at most 2",
        ),
        (vec!["--side=-1"], "side = -1: must be a finite number > 0"),
        (
            vec![
                "--plies",
                "1",
                "--per-ply",
                "1",
                "--subdomain-nodes",
                "1",
                "--interface-nodes",
                "2",
            ],
            "interface-nodes = 2: must be at most 0",
        ),
        (
            vec!["--interface-nodes", "2", "--interfaces-with-subdomains"],
            "the argument '--interface-nodes <INTERFACE_NODES>' cannot be used with '--interfaces-with-subdomains'",
        ),
    ] {
        let bad = dir.join("bad.toml");
        let r = std::process::Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args(["generate", "laminate", "-o"])
            .arg(&bad)
            .args(&args)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!bad.exists(), "{args:?} wrote a file");
    }
}
