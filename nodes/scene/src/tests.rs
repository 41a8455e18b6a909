//! The format's checks: what loads, what is refused and with which key.

use super::*;
use glissade_mechanics::mesh::BlockSide;
use glissade_mechanics::model::{
    Acceleration, Interface, InterfaceKind, Plane, SolverParams, TimeFunction, TimeStart, DEFAULT_ACCURACY,
    DEFAULT_TIME_START_TOLERANCE,
};
use glissade_mechanics::pgd::PgdCriterion;

const TWO_BLOCKS: &str = r#"
name = "two"
[time]
T = 1.0
N = 4
[materials.steel]
E = 210000.0
nu = 0.3
[[block]]
name = "lower"
material = "steel"
x = [0.0, 40.0]
y = [0.0, 20.0]
nx = 16
ny = 8
[[block]]
name = "upper"
material = "steel"
x = [0.0, 40.0]
y = [20.0, 40.0]
nx = 16
ny = 8
[[interface]]
between = ["lower", "upper"]
kind = "contact"
friction = 0.2
[[boundary]]
y = 0.0
ux = 0.0
uy = 0.0
[[boundary]]
y = 40.0
ux = "0.004*sin(2*pi*t)"
uy = -0.01
"#;

fn load(text: &str) -> Result<LoadedScene, SceneError> {
    load_str(text, "scenes/test.toml")
}

/// Loads `text` expecting an error with key `key` and a problem containing `part`.
#[track_caller]
fn expect_err(text: &str, key: &str, part: &str) -> SceneError {
    let Err(e) = load(text) else {
        panic!("scene should be rejected (`{key}`: {part})")
    };
    assert_eq!(e.key, key, "{e}");
    assert!(e.problem.contains(part), "`{part}` not in: {e}");
    assert_eq!(e.file, "scenes/test.toml");
    e
}

#[track_caller]
fn replaced(from: &str, to: &str) -> String {
    assert!(TWO_BLOCKS.contains(from), "{from}");
    TWO_BLOCKS.replacen(from, to, 1)
}

/// Command-line overrides of the solver's tolerance and iteration cap go into the scene
/// text: the text alone (what node processes and recordings get) builds the overridden
/// model, and its fingerprint is not the original's.
#[test]
fn solver_overrides_rewrite_the_scene_text() {
    let s = load(TWO_BLOCKS).unwrap();
    assert_eq!(
        s.with_overrides("scenes/test.toml", &Overrides::default())
            .unwrap()
            .text,
        s.text
    );
    let o = s
        .with_overrides(
            "scenes/test.toml",
            &Overrides {
                accuracy: Some(1e-4),
                tolerance: Some(2.5e-9),
                max_iterations: Some(7),
                record: None,
            },
        )
        .unwrap();
    let solver = &o.model.solver;
    assert_eq!(
        (solver.accuracy, solver.tolerance, solver.max_iterations),
        (Some(1e-4), Some(2.5e-9), 7)
    );
    assert_ne!(o.fingerprint, s.fingerprint);
    assert!(
        o.text.starts_with(
            "# scenes/test.toml with [solver] accuracy = 1e-4, [solver] tolerance = 2.5e-9, [solver] max_iterations = 7 set"
        ),
        "{}",
        o.text
    );
    let again = load(&o.text).unwrap();
    assert_eq!(
        (again.model.solver.tolerance, again.model.solver.max_iterations),
        (Some(2.5e-9), 7)
    );
    // Everything else is the scene as written.
    assert_eq!(again.model.name, "two");
    let unchanged = |m: &Model| {
        let mut m = m.clone();
        (m.solver.accuracy, m.solver.tolerance) = (None, None);
        m.solver.max_iterations = 0;
        format!("{m:?}")
    };
    assert_eq!(unchanged(&again.model), unchanged(&s.model));
    // A scene with a [solver] table keeps its other keys; an invalid value is the scene's
    // own error.
    let with_solver = load(&format!("{TWO_BLOCKS}[solver]\nrelaxation = 0.5\n")).unwrap();
    let o = with_solver
        .with_overrides(
            "scenes/test.toml",
            &Overrides {
                max_iterations: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!((o.model.solver.relaxation, o.model.solver.max_iterations), (0.5, 3));
    let e = s
        .with_overrides(
            "scenes/test.toml",
            &Overrides {
                max_iterations: Some(0),
                ..Default::default()
            },
        )
        .unwrap_err();
    assert_eq!(e.key, "solver.max_iterations", "{e}");
    let e = s
        .with_overrides(
            "scenes/test.toml",
            &Overrides {
                tolerance: Some(-1.0),
                ..Default::default()
            },
        )
        .unwrap_err();
    assert_eq!(e.key, "solver.tolerance", "{e}");
}

#[test]
fn two_blocks_has_one_contact_interface() {
    let s = load(TWO_BLOCKS).unwrap();
    let m = &s.model;
    assert_eq!(m.name, "two");
    assert_eq!(m.plane, Plane::Strain);
    assert_eq!(m.subdomains.len(), 2);
    assert_eq!(m.interfaces.len(), 1);
    let itf = &m.interfaces[0];
    assert_eq!((itf.a, itf.b), (0, 1));
    assert_eq!(m.subdomains[itf.a].name, "lower");
    assert_eq!(itf.n_pairs(), 33);
    assert_eq!(itf.normals, vec![[0.0, 1.0]; itf.n_pairs()]);
    assert_eq!(itf.tangent(0), [-1.0, 0.0]);
    assert!((itf.weights.iter().sum::<f64>() - 40.0).abs() < 1e-12);
    assert!((itf.length - 40.0).abs() < 1e-12);
    assert!((itf.centroid[0] - 20.0).abs() < 1e-12 && (itf.centroid[1] - 20.0).abs() < 1e-12);
    for (p, &(na, nb)) in itf.pairs.iter().enumerate() {
        let (ca, cb) = (m.subdomains[0].mesh.coords[na], m.subdomains[1].mesh.coords[nb]);
        assert!((ca[0] - cb[0]).abs() < 1e-12 && ca[1] == 20.0 && (cb[1] - 20.0).abs() < 1e-12);
        assert!((ca[0] - 1.25 * p as f64).abs() < 1e-12);
    }
    assert_eq!(
        itf.kind,
        InterfaceKind::Contact {
            friction: 0.2,
            gap: vec![0.0; 33]
        }
    );
    // Lower: both components clamped on y = 0 (two load cases); upper: ux, uy on y = 40.
    let lower = &m.subdomains[0];
    assert_eq!(lower.constrained.iter().filter(|&&c| c).count(), 2 * 33);
    assert_eq!(lower.loads.len(), 2);
    let upper = &m.subdomains[1];
    assert_eq!(upper.loads.len(), 2);
    assert!((upper.loads[0].time.eval(0.25) - 0.004).abs() < 1e-15);
    assert_eq!(upper.loads[1].time.eval(0.5), -0.01);
    assert_eq!(upper.loads[1].displacement.iter().sum::<f64>(), 33.0);
    assert_eq!(s.deployment, Deployment::default());
    assert_eq!(s.recording, Recording::default());
    assert_eq!(s.pgd, PgdParams::default());
    assert_eq!(m.solver, SolverParams::default());
    assert_eq!(s.fingerprint, fingerprint(TWO_BLOCKS));
}

#[test]
fn stratified_scene() {
    let s = load_str(
        include_str!("../../../launch/scenes/stratified.toml"),
        "stratified.toml",
    )
    .unwrap();
    let m = &s.model;
    assert_eq!(m.subdomains.len(), 18);
    assert_eq!(m.subdomains[0].name, "bottom.1");
    assert_eq!(m.subdomains[6].name, "core.1");
    assert_eq!(m.subdomains[17].name, "top.6");
    assert_eq!(m.time.n_steps, 1000);
    // The paper's N = 1000 starts from a coarse solve on every 10th time point ("auto").
    assert_eq!(
        m.solver.time_start,
        Some(TimeStart {
            coarsening: 10,
            tolerance: DEFAULT_TIME_START_TOLERANCE
        })
    );
    assert_eq!(m.interfaces.len(), 27);
    let perfect: Vec<&Interface> = m.interfaces.iter().filter(|i| !i.is_contact()).collect();
    let contact: Vec<&Interface> = m.interfaces.iter().filter(|i| i.is_contact()).collect();
    assert_eq!(perfect.len(), 15);
    assert_eq!(contact.len(), 12);
    for i in &perfect {
        assert_eq!(i.straight_normal(), Some([1.0, 0.0]));
        assert_eq!(i.n_pairs(), 41);
        assert!(i.coords.iter().all(|c| c[0] > 0.0));
        assert_eq!(
            m.subdomains[i.b].name.split('.').next(),
            m.subdomains[i.a].name.split('.').next()
        );
    }
    let first = contact[0];
    assert_eq!((first.a, first.b), (0, 6));
    assert_eq!(first.n_pairs(), 40);
    assert!((first.coords[0][0] - 0.75).abs() < 1e-12);
    assert!(contact.iter().filter(|i| i.n_pairs() == 41).count() == 10);
    for i in &contact {
        assert_eq!(
            i.kind,
            InterfaceKind::Contact {
                friction: 0.3,
                gap: vec![0.0; i.n_pairs()]
            }
        );
    }
    // Total pressure force on y = 0 at t = 0 (the sine loads vanish): 100 MPa × 180 mm.
    let fy = |range: std::ops::Range<usize>| -> f64 {
        range
            .map(|s| {
                let sub = &m.subdomains[s];
                sub.loads
                    .iter()
                    .map(|c| c.time.eval(0.0) * c.force.iter().skip(1).step_by(2).sum::<f64>())
                    .sum::<f64>()
            })
            .sum()
    };
    assert!((fy(0..6) - 18000.0).abs() < 1e-8, "{}", fy(0..6));
    assert!((fy(12..18) + 18000.0).abs() < 1e-8);
    // Axial traction on the core's end only: resultant 6000 N at t = T/4.
    let fx: f64 = (0..18)
        .map(|s| {
            let sub = &m.subdomains[s];
            sub.loads
                .iter()
                .map(|c| c.time.eval(2.5) * c.force.iter().step_by(2).sum::<f64>())
                .sum::<f64>()
        })
        .sum();
    assert!((fx - 6000.0).abs() < 1e-8, "{fx}");
    assert_eq!(s.deployment.subdomain_nodes, 3);
    assert_eq!((m.solver.accuracy, m.solver.tolerance), (Some(DEFAULT_ACCURACY), None));
    assert_eq!((s.pgd.xi1, s.pgd.xi2), (0.1, 0.01));
}

#[test]
fn every_scene_file_loads() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../launch/scenes");
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    assert!(paths.len() >= 5, "{paths:?}");
    for p in paths {
        let text = std::fs::read_to_string(&p).unwrap();
        let s = load_str(&text, &p.display().to_string()).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            s.model.name,
            p.file_stem().unwrap().to_string_lossy(),
            "{}",
            p.display()
        );
    }
}

#[test]
fn reference_scenes_match_the_getfem_setup() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../launch/scenes/");
    let read = |f: &str| std::fs::read_to_string(format!("{dir}{f}")).unwrap();
    let h = load_str(&read("hertz-slip.toml"), "hertz-slip.toml").unwrap().model;
    assert_eq!(h.interfaces.len(), 1);
    let itf = &h.interfaces[0];
    assert_eq!(itf.n_pairs(), 81);
    let InterfaceKind::Contact { friction, gap } = &itf.kind else {
        panic!()
    };
    assert_eq!(*friction, 0.3);
    assert!((gap[0] - 2.0).abs() < 1e-12 && gap[40].abs() < 1e-15);
    let top = &h.subdomains[1].loads;
    assert_eq!(top.len(), 2);
    assert!((top[0].time.eval(0.75) - 0.0015).abs() < 1e-15);
    assert!((top[1].time.eval(0.25) + 0.01).abs() < 1e-15);
    let l = load_str(&read("layered.toml"), "layered.toml").unwrap().model;
    assert_eq!(l.subdomains.len(), 3);
    assert_eq!(l.interfaces.len(), 2);
    assert!(l.interfaces.iter().all(|i| i.is_contact() && i.n_pairs() == 240));
    let small = load_str(&read("small-three-layer.toml"), "small-three-layer.toml")
        .unwrap()
        .model;
    assert_eq!(small.subdomains.len(), 6);
    assert_eq!(small.interfaces.iter().filter(|i| !i.is_contact()).count(), 3);
    let contact: Vec<&Interface> = small.interfaces.iter().filter(|i| i.is_contact()).collect();
    assert_eq!(contact.len(), 4);
    assert_eq!((contact[0].a, contact[0].b, contact[0].n_pairs()), (0, 2, 8));
}

/// The small three-layer scene's interfaces, in model order: 0 bottom.1|bottom.2 (5 pairs),
/// 1 bottom.1|core.1 (8), 2 bottom.2|core.2 (9), 3 core.1|core.2 (5), 4 core.1|top.1 (9),
/// 5 core.2|top.2 (9), 6 top.1|top.2 (5).
fn three_layers(deployment: &str) -> Result<LoadedScene, SceneError> {
    let text = include_str!("../../../launch/scenes/small-three-layer.toml");
    assert!(text.contains("[deployment]\nsubdomain_nodes = 2\n"));
    let text = text.replace("[deployment]\n", &format!("[deployment]\n{deployment}\n"));
    load(&text)
}

#[test]
fn interface_nodes_own_balanced_or_assigned_groups() {
    let s = three_layers("").unwrap();
    let pairs: Vec<usize> = s.model.interfaces.iter().map(Interface::n_pairs).collect();
    assert_eq!(pairs, [5, 8, 9, 5, 8, 9, 5]);
    assert_eq!(s.deployment.interface_groups(&s.model), [vec![0, 1, 2, 3, 4, 5, 6]]);
    // 49 pairs over 3 nodes: cuts nearest to 16.3 and 32.7 pairs (13 and 35).
    let s = three_layers("interface_nodes = 3").unwrap();
    assert_eq!(s.deployment.interface_groups, None);
    assert_eq!(
        s.deployment.interface_groups(&s.model),
        [vec![0, 1], vec![2, 3, 4], vec![5, 6]]
    );
    assert_eq!(
        balanced_interface_groups(&s.model, 7),
        (0..7).map(|i| vec![i]).collect::<Vec<_>>()
    );
    let s =
        three_layers("interface_groups = [[\"bottom|core\", \"bottom|bottom\"], [\"top|core\", \"core.1|core.2\", 6]]")
            .unwrap();
    assert_eq!(s.deployment.interface_nodes, 2);
    assert_eq!(
        s.deployment.interface_groups(&s.model),
        [vec![0, 1, 2], vec![3, 4, 5, 6]]
    );
}

#[test]
fn rejects_bad_interface_deployments() {
    let key = "deployment.interface_groups";
    let e = three_layers("interface_nodes = 8").unwrap_err();
    assert_eq!(
        e.to_string(),
        "scenes/test.toml: deployment.interface_nodes: 8 nodes for 7 interface(s): some nodes would own nothing"
    );
    let bad = [
        ("interface_nodes = 0", "deployment.interface_nodes", "must be ≥ 1"),
        (
            "interface_nodes = 3\ninterface_groups = [[0, 1, 2], [3, 4, 5, 6]]",
            key,
            "2 group(s) for interface_nodes = 3",
        ),
        (
            "interface_groups = [[0, 1, 2, 3, 4, 5, 6], []]",
            "deployment.interface_groups[1]",
            "is empty",
        ),
        (
            "interface_groups = [[0, 1, 2, 3, 4, 5, 7]]",
            "deployment.interface_groups[0][6]",
            "interface 7 does not exist (the scene has 7, indices 0 to 6)",
        ),
        (
            "interface_groups = [[0, 1, 2], [3, 4, 5, 6, \"bottom\"]]",
            "deployment.interface_groups[1][4]",
            "`bottom`: name an interface as \"A|B\"",
        ),
        (
            "interface_groups = [[0, 1, 2], [3, \"core|tops\"]]",
            "deployment.interface_groups[1][1]",
            "unknown block or subdomain `tops`",
        ),
        (
            "interface_groups = [[0, 1, 2], [3, \"bottom|top\"]]",
            "deployment.interface_groups[1][1]",
            "`bottom|top` matches no interface",
        ),
        (
            "interface_groups = [[0, \"bottom|core\"], [2, 3, 4, 5, 6]]",
            "deployment.interface_groups[1][0]",
            "interface 2 (bottom.2|core.2) is already in group 0",
        ),
        (
            "interface_groups = [[0, 1, 2], [3, 6]]",
            key,
            "interface(s) 4 (core.1|top.1), 5 (core.2|top.2) are in no group",
        ),
    ];
    for (deployment, k, part) in bad {
        let e = three_layers(deployment).expect_err(deployment);
        assert_eq!(e.key, k, "{deployment}: {e}");
        assert!(e.problem.contains(part), "{deployment}: `{part}` not in {e}");
    }
}

#[test]
fn split_names_interfaces_and_outer_sides() {
    let text = replaced("ny = 8\n[[block]]", "ny = 8\nsplit = [2, 2]\n[[block]]");
    let m = load(&text).unwrap().model;
    let names: Vec<&str> = m.subdomains.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["lower.1", "lower.2", "lower.3", "lower.4", "upper"]);
    // lower: 2 vertical + 2 horizontal perfect ones, 2 contact ones with upper.
    assert_eq!(m.interfaces.len(), 6);
    let vertical = m
        .interfaces
        .iter()
        .filter(|i| i.straight_normal() == Some([1.0, 0.0]))
        .count();
    assert_eq!(vertical, 2);
    let contact: Vec<_> = m.interfaces.iter().filter(|i| i.is_contact()).collect();
    assert_eq!(contact.len(), 2);
    assert_eq!((contact[0].a, contact[0].b, contact[0].n_pairs()), (2, 4, 17));
    // The vertical interface lower.1|lower.2 loses its pair at y = 0 (clamped both sides).
    let v = m.interfaces.iter().find(|i| (i.a, i.b) == (0, 1)).unwrap();
    assert_eq!(v.n_pairs(), 8);
    // y = 0 selects only the outer bottom sides.
    assert_eq!(m.subdomains[2].loads.len(), 0);
    assert_eq!(m.subdomains[0].loads.len(), 2);
}

#[test]
fn later_rule_overrides_prescribed_dofs() {
    let text = format!("{TWO_BLOCKS}[[boundary]]\nblocks = [\"upper\"]\nside = \"right\"\nux = 0.5\n");
    let m = load(&text).unwrap().model;
    let upper = &m.subdomains[1];
    assert_eq!(upper.loads.len(), 3);
    let corner = upper.mesh.side_nodes(BlockSide::Right).last().copied().unwrap();
    assert_eq!(upper.loads[0].displacement[2 * corner], 0.0);
    assert_eq!(upper.loads[2].displacement[2 * corner], 1.0);
    assert_eq!(upper.loads[1].displacement[2 * corner + 1], 1.0);
    // A rule whose pattern is entirely overridden disappears.
    let text = format!("{TWO_BLOCKS}[[boundary]]\ny = 40.0\nuy = 0.5\n");
    let m = load(&text).unwrap().model;
    assert_eq!(m.subdomains[1].loads.len(), 2);
    assert_eq!(m.subdomains[1].loads[1].time, TimeFunction::Constant(0.5));
}

#[test]
fn pressure_pushes_against_the_outward_normal() {
    let text = format!("{TWO_BLOCKS}[[boundary]]\nblocks = [\"upper\"]\nside = \"left\"\np = 2\n");
    let m = load(&text).unwrap().model;
    let case = m.subdomains[1].loads.last().unwrap();
    let fx: f64 = case.force.iter().step_by(2).sum();
    let fy: f64 = case.force.iter().skip(1).step_by(2).sum();
    assert!((fx - 20.0).abs() < 1e-12 && fy.abs() < 1e-12);
    assert_eq!(case.time, TimeFunction::Constant(2.0));
}

#[test]
fn gap_forms() {
    let with_gap = |g: &str| replaced("friction = 0.2", &format!("friction = 0.2\ngap = {g}"));
    let gap_of = |text: &str| match &load(text).unwrap().model.interfaces[0].kind {
        InterfaceKind::Contact { gap, .. } => gap.clone(),
        InterfaceKind::Perfect => panic!(),
    };
    let g = gap_of(&with_gap("\"x/100 + y/1000\""));
    assert!((g[32] - 0.42).abs() < 1e-15);
    let g = gap_of(&with_gap("{ x = [0, 40], g = [0.0, 0.4] }"));
    assert!((g[16] - 0.2).abs() < 1e-15);
    let g = gap_of(&with_gap("0.1"));
    assert!(g.iter().all(|&v| v == 0.1));
    expect_err(
        &with_gap("{ x = [0, 40], v = [0.0, 0.4] }"),
        "interface[0].gap",
        "unknown key `v`",
    );
    expect_err(&with_gap("\"t\""), "interface[0].gap", "unknown name `t`");
}

#[test]
fn defaults_and_settings() {
    let text = format!(
        "{}[solver]\nrelaxation = 1\ncontact_tolerance = 1e-3\n[solver.pgd]\nenabled = true\ncriterion = \
         \"increment-svd\"\n[deployment]\nsubdomain_nodes = 2\n[recording]\nenabled = false\nfull_fields_every = 10\n",
        TWO_BLOCKS.replacen("name = \"two\"\n", "plane = \"stress\"\n", 1)
    );
    let s = load(&text).unwrap();
    assert_eq!(s.model.name, "test");
    assert_eq!(s.model.plane, Plane::Stress);
    assert_eq!(s.model.solver.relaxation, 1.0);
    assert_eq!(s.model.solver.contact_tolerance, Some(1e-3));
    assert!(s.pgd.enabled && s.pgd.criterion == PgdCriterion::IncrementSvd);
    assert_eq!(s.deployment.subdomain_nodes, 2);
    assert!(!s.recording.enabled && s.recording.full_fields_every == 10);
}

/// The annotated example of docs/scenes.md is the shipped stratified scene with comments: it
/// loads, and builds the same model and settings, so the page cannot drift from the format.
#[test]
fn documented_example_is_the_stratified_scene() {
    let page = include_str!("../../../docs/scenes.md");
    let example: String = page
        .lines()
        .skip_while(|l| !l.starts_with("## Annotated example"))
        .skip_while(|l| *l != "```toml")
        .skip(1)
        .take_while(|l| *l != "```")
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(
        example.contains("[[interface]]"),
        "no annotated example in docs/scenes.md"
    );
    let documented = load_str(&example, "docs/scenes.md").unwrap_or_else(|e| panic!("{e}"));
    let shipped = load_str(
        include_str!("../../../launch/scenes/stratified.toml"),
        "stratified.toml",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(format!("{:?}", documented.model), format!("{:?}", shipped.model));
    assert_eq!(documented.deployment, shipped.deployment);
    assert_eq!(documented.recording, shipped.recording);
    assert_eq!(documented.pgd, shipped.pgd);
    assert_eq!(documented.linear_stage, shipped.linear_stage);
    assert_eq!(documented.network, shipped.network);
}

#[test]
fn fingerprint_is_fnv1a_64() {
    assert_eq!(fingerprint(""), 0xcbf2_9ce4_8422_2325);
    assert_eq!(fingerprint("a"), 0xaf63_dc4c_8601_ec8c);
    assert_eq!(fingerprint("foobar"), 0x8594_4171_f739_67e8);
    assert_ne!(fingerprint("foobar"), fingerprint("foobas"));
    assert_ne!(
        fingerprint(TWO_BLOCKS),
        fingerprint(&TWO_BLOCKS.replacen("0.3", "0.2", 1))
    );
}

// --- validation errors, one per rule ---

#[test]
fn rejects_nu_out_of_range() {
    expect_err(
        &replaced("nu = 0.3", "nu = 0.5"),
        "materials.steel.nu",
        "outside (−1, 0.5)",
    );
    expect_err(
        &replaced("nu = 0.3", "nu = -1.0"),
        "materials.steel.nu",
        "outside (−1, 0.5)",
    );
}

#[test]
fn rejects_non_positive_e() {
    expect_err(&replaced("E = 210000.0", "E = 0"), "materials.steel.E", "must be > 0");
}

#[test]
fn rejects_negative_friction() {
    expect_err(
        &replaced("friction = 0.2", "friction = -0.1"),
        "interface[0].friction",
        "must be a finite number ≥ 0",
    );
    expect_err(
        &replaced("friction = 0.2", "friction = inf"),
        "interface[0].friction",
        "friction coefficient inf must be a finite number ≥ 0",
    );
}

#[test]
fn rejects_friction_on_perfect_and_contact_without_friction() {
    expect_err(
        &replaced("kind = \"contact\"", "kind = \"perfect\""),
        "interface[0].friction",
        "contact interfaces only",
    );
    expect_err(
        &replaced("friction = 0.2\n", ""),
        "interface[0].friction",
        "needs `friction`",
    );
}

#[test]
fn rejects_zero_steps_and_non_positive_duration() {
    expect_err(&replaced("N = 4", "N = 0"), "time.N", "N ≥ 1");
    expect_err(&replaced("T = 1.0", "T = 0.0"), "time.T", "> 0");
    expect_err(&replaced("T = 1.0", "T = -2"), "time.T", "> 0");
}

#[test]
fn rejects_bad_element_counts_and_split() {
    expect_err(
        &TWO_BLOCKS
            .replacen("nx = 16", "nx = 0", 2)
            .replacen("nx = 0", "nx = 16", 1),
        "block[1].nx",
        "nx = 0",
    );
    expect_err(&replaced("ny = 8", "ny = 0"), "block[0].ny", "ny = 0");
    expect_err(
        &replaced("ny = 8\n", "ny = 8\nsplit = [3, 1]\n"),
        "block[0].split",
        "must divide",
    );
    expect_err(
        &replaced("ny = 8\n", "ny = 8\nsplit = [0, 1]\n"),
        "block[0].split",
        "must divide",
    );
}

#[test]
fn rejects_empty_extent() {
    expect_err(
        &replaced("x = [0.0, 40.0]", "x = [40.0, 40.0]"),
        "block[0].x",
        "x0 < x1",
    );
    expect_err(&replaced("y = [0.0, 20.0]", "y = [20.0, 0.0]"), "block[0].y", "y0 < y1");
}

#[test]
fn rejects_unknown_material() {
    expect_err(
        &replaced("material = \"steel\"", "material = \"stel\""),
        "block[0].material",
        "unknown material `stel`",
    );
}

#[test]
fn rejects_unknown_names() {
    expect_err(
        &replaced("between = [\"lower\", \"upper\"]", "between = [\"lower\", \"uper\"]"),
        "interface[0].between",
        "unknown block or subdomain `uper`",
    );
    expect_err(
        &replaced("y = 0.0\nux", "blocks = [\"lower.1\"]\ny = 0.0\nux"),
        "boundary[0].blocks",
        "unknown block or subdomain `lower.1`",
    );
}

#[test]
fn rejects_rule_matching_no_interface() {
    let text = replaced("y = [20.0, 40.0]", "y = [20.5, 40.0]").replacen("y = 40.0", "y = 40", 1);
    expect_err(&text, "interface[0].between", "share no edge");
}

#[test]
fn rejects_non_conforming_interface() {
    let e = expect_err(
        &TWO_BLOCKS
            .replacen("nx = 16", "nx = 10", 2)
            .replacen("nx = 10", "nx = 16", 1),
        "block[1]",
        "do not conform",
    );
    assert!(e.problem.contains("`lower`") && e.problem.contains("`upper`"), "{e}");
    assert!(e.problem.contains("y = 20") && e.problem.contains("x = 1.25"), "{e}");
    // Shifted by half an element: nodes coincide but corners face mid-side nodes.
    let shifted = replaced("x = [0.0, 40.0]\ny = [20.0", "x = [1.25, 41.25]\ny = [20.0");
    expect_err(&shifted, "block[1]", "corner node faces a mid-side node");
}

#[test]
fn rejects_overlapping_blocks() {
    let e = expect_err(
        &replaced("y = [20.0, 40.0]", "y = [19.0, 40.0]"),
        "block[1]",
        "overlaps",
    );
    assert!(e.problem.contains("`upper`") && e.problem.contains("`lower`"), "{e}");
}

#[test]
fn rejects_bad_formula() {
    expect_err(
        &replaced("\"0.004*sin(2*pi*t)\"", "\"0.004*sin(2*pi*s)\""),
        "boundary[1].ux",
        "unknown name `s`",
    );
    expect_err(
        &replaced("\"0.004*sin(2*pi*t)\"", "\"ln(t)\""),
        "boundary[1].ux",
        "not finite",
    );
}

#[test]
fn rejects_bad_tables() {
    let with = |t: &str| replaced("uy = -0.01", &format!("uy = {t}"));
    expect_err(
        &with("{ t = [0.0, 1.0], v = [0.0] }"),
        "boundary[1].uy",
        "2 entries but `v` has 1",
    );
    expect_err(
        &with("{ t = [0.0, 0.0], v = [0.0, 1.0] }"),
        "boundary[1].uy",
        "not strictly increasing",
    );
    expect_err(&with("{ t = [], v = [] }"), "boundary[1].uy", "is empty");
    expect_err(
        &with("{ t = [0.0, \"a\"], v = [0.0, 1.0] }"),
        "boundary[1].uy",
        "not a finite number",
    );
    expect_err(&with("{ v = [0.0] }"), "boundary[1].uy", "exactly one abscissa");
    expect_err(&with("[1.0]"), "boundary[1].uy", "found array");
}

#[test]
fn rejects_bad_solver_settings() {
    let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
    expect_err(&with("relaxation = 0.0"), "solver.relaxation", "outside (0, 1]");
    expect_err(&with("relaxation = 1.5"), "solver.relaxation", "outside (0, 1]");
    expect_err(&with("tolerance = 0.0"), "solver.tolerance", "must be > 0");
    expect_err(&with("tolerance = -1e-6"), "solver.tolerance", "must be > 0");
    expect_err(&with("accuracy = 0.0"), "solver.accuracy", "outside (0, 1)");
    expect_err(&with("accuracy = 1.5"), "solver.accuracy", "outside (0, 1)");
    expect_err(&with("k0_factor = 0"), "solver.k0_factor", "must be > 0");
    expect_err(&with("alpha = 1.0"), "solver.alpha", "outside [0, 1)");
    // 2(1 − 0.8)/(2 − 0.8) = 1/3: 0.34 is above, and accepted only with the update off.
    expect_err(
        &with("search_direction_update = true\nalpha = 0.34"),
        "solver.alpha",
        "above 0.3333 = 2(1 − μ)/(2 − μ) for relaxation μ = 0.8",
    );
    assert!(load(&with("alpha = 0.34")).is_ok());
    assert!(load(&with("search_direction_update = true\nalpha = 0.3333")).is_ok());
    expect_err(
        &format!("{TWO_BLOCKS}[deployment]\nsubdomain_nodes = 3\n"),
        "deployment.subdomain_nodes",
        "3 nodes",
    );
    expect_err(
        &format!("{TWO_BLOCKS}[recording]\nfull_fields_every = 0\n"),
        "recording.full_fields_every",
        "≥ 1",
    );
}

#[test]
fn rejects_free_rigid_modes() {
    // Only ux on y = 0, nothing on top: y-translation and rotation are free.
    let text = replaced("ux = 0.0\nuy = 0.0", "ux = 0.0");
    let text = text.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
    let e = expect_err(&text, "boundary", "y-translation and rotation free");
    assert!(e.problem.contains("[lower, upper]"), "{e}");
    // ux = 0 along y = 0 and uy = 0 along x = 0 leave the rotation about the origin free.
    let text = replaced(
        "ux = 0.0\nuy = 0.0",
        "ux = 0.0\n[[boundary]]\nblocks = [\"lower\"]\nx = 0.0\nuy = 0.0",
    );
    let text = text.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
    let e = expect_err(&text, "boundary", "rotation free");
    assert!(!e.problem.contains("translation"), "{e}");
    // A second, unconnected block with no support.
    let text = format!(
        "{TWO_BLOCKS}[[block]]\nname = \"loose\"\nmaterial = \"steel\"\nx = [50.0, 60.0]\ny = [5.0, 15.0]\nnx = 2\nny = 2\n"
    );
    let e = expect_err(&text, "boundary", "x-translation, y-translation and rotation free");
    assert!(e.problem.contains("[loose]"), "{e}");
}

#[test]
fn rejects_duplicate_names() {
    expect_err(
        &replaced("name = \"upper\"", "name = \"lower\""),
        "block[1].name",
        "duplicate block name `lower`",
    );
    let text = replaced("ny = 8\n[[block]]", "ny = 8\nsplit = [2, 1]\n[[block]]").replacen(
        "name = \"upper\"",
        "name = \"lower.2\"",
        1,
    );
    expect_err(
        &text.replace("\"upper\"", "\"lower.2\""),
        "block[0].name",
        "`lower.2` generated from block `lower`",
    );
}

#[test]
fn rejects_bad_boundary_rules() {
    expect_err(
        &replaced("uy = -0.01", "uy = -0.01\nty = 1.0"),
        "boundary[1]",
        "not both",
    );
    expect_err(
        &replaced("ux = 0.0\nuy = 0.0\n", ""),
        "boundary[0]",
        "prescribes nothing",
    );
    expect_err(
        &replaced("y = 0.0\n", "y = 5.0\n"),
        "boundary[0]",
        "no outer side matches y = 5",
    );
    expect_err(&replaced("y = 0.0\n", ""), "boundary[0]", "give `side`, `x` or `y`");
}

#[test]
fn toml_errors_name_key_and_position() {
    let e = expect_err(&replaced("N = 4", "N = 4\nsteps = 3"), "time.steps", "line 6, column 1");
    assert!(e.problem.contains("unknown field `steps`"), "{e}");
    let e = expect_err(
        &TWO_BLOCKS
            .replacen("ny = 8", "ny = \"8\"", 2)
            .replacen("ny = \"8\"", "ny = 8", 1),
        "block[1].ny",
        "line 22",
    );
    assert!(e.problem.contains("column"), "{e}");
    let e = load(&replaced("[time]", "[time\n")).unwrap_err();
    assert_eq!(e.key, "(syntax)", "{e}");
    assert!(e.problem.contains("line 3"), "{e}");
    expect_err(
        &replaced("kind = \"contact\"", "kind = \"glue\""),
        "interface[0].kind",
        "glue",
    );
    expect_err(&replaced("T = 1.0\n", ""), "time.T", "missing field");
    expect_err(
        &replaced("[[boundary]]\ny = 0.0", "[[boundary]]\nside = \"middle\""),
        "boundary[0].side",
        "middle",
    );
}

#[test]
fn linear_stage_keys() {
    let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
    let stage = |s: &str| load(&with(s)).unwrap().linear_stage;
    assert_eq!(load(TWO_BLOCKS).unwrap().linear_stage, LinearStage::Condensed);
    assert_eq!(stage("linear_stage = \"sparse\""), LinearStage::Sparse);
    assert_eq!(stage("linear_stage = \"auto\""), LinearStage::Auto);
    assert_eq!(stage("[solver.pgd]\nenabled = true"), LinearStage::Pgd);
    let s = load(&with(
        "linear_stage = \"pgd\"\n[solver.pgd]\nmacro_modes = true\nmax_new_modes = 3",
    ))
    .unwrap();
    assert_eq!(s.linear_stage, LinearStage::Pgd);
    assert!(s.pgd.macro_modes && s.pgd.max_new_modes == 3);
    expect_err(
        &with("linear_stage = \"sparse\"\n[solver.pgd]\nenabled = true"),
        "solver.pgd.enabled",
        "true contradicts solver.linear_stage = Sparse",
    );
    expect_err(
        &with("[solver.pgd]\nmax_new_modes = 0"),
        "solver.pgd.max_new_modes",
        "must be ≥ 1",
    );
    assert!(load(&with("linear_stage = \"dense\"")).is_err());
    let s = load(&with("[solver.pgd]\nenabled = true\ncriterion = \"forcing\"\nxi1 = 3")).unwrap();
    assert!(s.pgd.criterion == PgdCriterion::Forcing && s.pgd.xi1 == 3.0);
    expect_err(
        &with("[solver.pgd]\ncriterion = \"forced\""),
        "solver.pgd.criterion",
        "forcing",
    );
    expect_err(&with("[solver.pgd]\nxi1 = 0"), "solver.pgd.xi1", "must be > 0");
}

#[test]
fn time_coarsening_keys() {
    let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
    let n = load(TWO_BLOCKS).unwrap().model.time.n_steps;
    assert_eq!(load(TWO_BLOCKS).unwrap().model.solver.time_start, None);
    assert_eq!(
        load(&with("time_coarsening = 2")).unwrap().model.solver.time_start,
        Some(TimeStart {
            coarsening: 2,
            tolerance: DEFAULT_TIME_START_TOLERANCE
        })
    );
    assert_eq!(
        load(&with(&format!(
            "time_coarsening = {n}\ntime_coarsening_tolerance = 1e-6"
        )))
        .unwrap()
        .model
        .solver
        .time_start,
        Some(TimeStart {
            coarsening: n,
            tolerance: 1e-6
        })
    );
    expect_err(&with("time_coarsening = 1"), "solver.time_coarsening", "must be ≥ 2");
    expect_err(
        &with(&format!("time_coarsening = {}", n + 1)),
        "solver.time_coarsening",
        &format!("does not divide time.N = {n}"),
    );
    expect_err(
        &with("time_coarsening = \"off\"\ntime_coarsening_tolerance = 1e-5"),
        "solver.time_coarsening_tolerance",
        "solver.time_coarsening is \"off\"",
    );
    expect_err(&with("time_coarsening = \"fine\""), "solver.time_coarsening", "neither");
    expect_err(
        &with("time_coarsening = 2\ntime_coarsening_tolerance = 0.0"),
        "solver.time_coarsening_tolerance",
        "must be > 0",
    );
    expect_err(
        &with("time_coarsening = 2\nlinear_stage = \"pgd\""),
        "solver.time_coarsening",
        "not available with the PGD linear stage",
    );
    assert!(load(&with("time_coarsening = -2")).is_err());
}

/// `time_coarsening = "auto"` (the default) starts from a coarse solve of about 100 steps from
/// N = 200 on, never with the PGD stage; "off" never does.
#[test]
fn automatic_time_coarsening() {
    assert_eq!(auto_coarsening(100), None);
    assert_eq!(auto_coarsening(199), None);
    assert_eq!(auto_coarsening(200), Some(2));
    assert_eq!(auto_coarsening(400), Some(4));
    assert_eq!(auto_coarsening(1000), Some(10));
    assert_eq!(auto_coarsening(1500), Some(15));
    assert_eq!(auto_coarsening(1024), Some(8), "128 coarse steps is the nearest to 100");
    assert_eq!(auto_coarsening(401), None, "a prime N has no coarse grid");
    let at = |n: usize, extra: &str| {
        let text = TWO_BLOCKS.replacen("N = 4", &format!("N = {n}"), 1);
        assert!(TWO_BLOCKS.contains("\nN = 4\n"), "the two-blocks text sets N = 4");
        load(&format!("{text}[solver]\n{extra}\n"))
            .unwrap()
            .model
            .solver
            .time_start
    };
    assert_eq!(at(4, ""), None);
    assert_eq!(
        at(1000, ""),
        Some(TimeStart {
            coarsening: 10,
            tolerance: DEFAULT_TIME_START_TOLERANCE
        })
    );
    assert_eq!(
        at(1000, "time_coarsening = \"auto\"\ntime_coarsening_tolerance = 2e-5"),
        Some(TimeStart {
            coarsening: 10,
            tolerance: 2e-5
        })
    );
    assert_eq!(at(1000, "time_coarsening = \"off\""), None);
    assert_eq!(at(1000, "linear_stage = \"pgd\""), None);
}

#[test]
fn acceleration_keys() {
    let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
    let a = |s: &str| load(&with(s)).unwrap().model.solver.acceleration;
    assert_eq!(a("acceleration = \"none\""), Acceleration::None);
    // Anderson with the default window unless the scene says otherwise.
    assert_eq!(
        a("tolerance = 1e-6"),
        Acceleration::Anderson {
            window: DEFAULT_ANDERSON_WINDOW
        }
    );
    assert_eq!(a("anderson_window = 3"), Acceleration::Anderson { window: 3 });
    assert_eq!(
        a("acceleration = \"anderson\""),
        Acceleration::Anderson {
            window: DEFAULT_ANDERSON_WINDOW
        }
    );
    assert_eq!(
        a("acceleration = \"anderson\"\nanderson_window = 8"),
        Acceleration::Anderson { window: 8 }
    );
    expect_err(
        &with("acceleration = \"anderson\"\nanderson_window = 0"),
        "solver.anderson_window",
        "0 is outside 1..=50",
    );
    expect_err(
        &with("acceleration = \"anderson\"\nanderson_window = 51"),
        "solver.anderson_window",
        "51 is outside 1..=50",
    );
    expect_err(
        &with("acceleration = \"none\"\nanderson_window = 4"),
        "solver.anderson_window",
        "4 is set but solver.acceleration is \"none\"",
    );
    let e = load(&with("acceleration = \"broyden\"")).unwrap_err();
    assert!(
        e.to_string().contains("broyden") && e.to_string().contains("anderson"),
        "{e}"
    );
}

/// `[network]`: TLS files as written, mutual TLS, access control; each inconsistency is
/// named by its key.
#[test]
fn network_section() {
    let net = |lines: &str| format!("{TWO_BLOCKS}\n[network]\n{lines}\n");
    let tls = r#"tls = { root_ca = "tls/ca.pem", cert = "tls/node.pem", key = "tls/node.key" }"#;
    let mutual = r#"tls = { root_ca = "tls/ca.pem", cert = "tls/node.pem", key = "tls/node.key", mutual = true }"#;
    assert_eq!(load(TWO_BLOCKS).unwrap().network, Network::default());
    let s = load(&net(&format!("{mutual}\nallow = [\"node-a\", \"node-b\"]"))).unwrap();
    assert_eq!(
        s.network,
        Network {
            tls: Some(TlsFiles {
                root_ca: "tls/ca.pem".into(),
                cert: "tls/node.pem".into(),
                key: "tls/node.key".into(),
                mutual: true,
            }),
            allow: Some(vec!["node-a".into(), "node-b".into()]),
            shared_memory: None,
        }
    );
    assert!(!load(&net(tls)).unwrap().network.tls.unwrap().mutual);
    assert_eq!(
        load(&net("shared_memory = true")).unwrap().network.shared_memory,
        Some(true)
    );
    assert_eq!(
        load(&net("shared_memory = false")).unwrap().network.shared_memory,
        Some(false)
    );
    let e = load(&net("shared_memory = \"yes\"")).unwrap_err().to_string();
    assert!(e.contains("shared_memory"), "{e}");
    expect_err(&net("allow = [\"node-a\"]"), "network.allow", "it needs network.tls");
    expect_err(
        &net(&format!("{tls}\nallow = [\"node-a\"]")),
        "network.allow",
        "needs network.tls.mutual = true",
    );
    expect_err(&net(&format!("{mutual}\nallow = []")), "network.allow", "an empty list");
    expect_err(
        &net(&format!("{mutual}\nallow = [\"a\", \"a\"]")),
        "network.allow[1]",
        "`a` is listed twice",
    );
    expect_err(
        &net(&format!("{mutual}\nallow = [\" \"]")),
        "network.allow[0]",
        "not empty",
    );
    expect_err(
        &net(r#"tls = { root_ca = "tls/ca.pem", cert = "", key = "k.pem" }"#),
        "network.tls.cert",
        "must name a PEM file",
    );
    expect_err(
        &net(r#"tls = { root_ca = "tls/ca.pem", cert = "tls/node.pem" }"#),
        "network.tls.key",
        "missing field `key`",
    );
    expect_err(&net("encrypt = true"), "network.encrypt", "unknown field `encrypt`");
}

/// TLS paths are relative to the scene file's folder and must be readable PEM files.
#[test]
fn network_files_resolve_and_are_checked() {
    let dir = std::env::temp_dir().join(format!("glissade-scene-tls-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("tls")).unwrap();
    let pem = "-----BEGIN CERTIFICATE-----\nMA==\n-----END CERTIFICATE-----\n";
    for f in ["ca.pem", "node.pem", "node.key"] {
        std::fs::write(dir.join("tls").join(f), pem).unwrap();
    }
    std::fs::write(dir.join("tls/plain.txt"), "not a certificate").unwrap();
    let scene_file = dir.join("scene.toml");
    let network = |cert: &str| Network {
        tls: Some(TlsFiles {
            root_ca: "tls/ca.pem".into(),
            cert: cert.into(),
            key: "tls/node.key".into(),
            mutual: false,
        }),
        allow: None,
        shared_memory: None,
    };
    let mut ok = network("tls/node.pem");
    ok.resolve_files(&scene_file).unwrap();
    let t = ok.tls.unwrap();
    assert_eq!(t.root_ca, dir.join("tls/ca.pem"));
    assert_eq!(t.cert, dir.join("tls/node.pem"));
    assert_eq!(t.key, dir.join("tls/node.key"));
    let absolute = dir.join("tls/node.pem");
    let mut abs = network(absolute.to_str().unwrap());
    abs.resolve_files(&scene_file).unwrap();
    assert_eq!(abs.tls.unwrap().cert, absolute);
    let e = network("tls/missing.pem").resolve_files(&scene_file).unwrap_err();
    assert_eq!(e.key, "network.tls.cert");
    assert_eq!(e.file, scene_file.display().to_string());
    assert!(
        e.problem
            .starts_with(&format!("cannot read {}: ", dir.join("tls/missing.pem").display())),
        "{e}"
    );
    let e = network("tls/plain.txt").resolve_files(&scene_file).unwrap_err();
    assert_eq!(e.key, "network.tls.cert");
    assert!(
        e.problem.ends_with("plain.txt is not a PEM file (no -----BEGIN line)"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The scene name starts every output file's name: a path, a hidden name or an overlong one is
/// refused at the key `name`; a file stem that is no file name is cleaned instead.
#[test]
fn scene_names_are_file_names() {
    let named = |n: &str| TWO_BLOCKS.replacen("name = \"two\"", &format!("name = {n:?}"), 1);
    assert!(TWO_BLOCKS.contains("name = \"two\""));
    for bad in [
        "../../evil/x",
        "/abs/x",
        "",
        ".",
        ".hidden",
        "a b",
        "x/y",
        "a\\b",
        &"n".repeat(101),
    ] {
        expect_err(&named(bad), "name", "is not a file name");
    }
    for good in ["two", "ply-4_v2.1", &"n".repeat(100)] {
        assert_eq!(load(&named(good)).unwrap().model.name, good);
    }
    let unnamed = TWO_BLOCKS.replacen("name = \"two\"\n", "", 1);
    let from = |file: &str| load_str(&unnamed, file).unwrap().model.name;
    assert_eq!(from("scenes/my scene (v2).toml"), "my_scene__v2_");
    assert_eq!(from("scenes/.hidden.toml"), "hidden");
    assert_eq!(from("scenes/..toml"), "scene");
    assert_eq!(from("scenes/two-blocks.toml"), "two-blocks");
}

/// `--record` rewrites the scene's [recording] table: off, or complete (every message, full
/// fields at every iteration) whatever the scene says.
#[test]
fn record_overrides_switch_the_recording_off_or_make_it_complete() {
    let thinned = load(&format!(
        "{TWO_BLOCKS}[recording]\ntopics = [\"interface/*/decision\"]\nfull_fields_every = 4\n"
    ))
    .unwrap();
    let with = |r| {
        thinned
            .with_overrides(
                "scenes/test.toml",
                &Overrides {
                    record: Some(r),
                    ..Default::default()
                },
            )
            .unwrap()
    };
    let off = with(RecordOverride::Off);
    assert!(!off.recording.enabled);
    let full = with(RecordOverride::Full);
    assert_eq!(full.recording.incomplete(), None, "{:?}", full.recording);
    assert!(
        full.text.contains("[recording] complete set on the command line"),
        "{}",
        full.text
    );
    assert!(thinned.recording.incomplete().is_some());
}

/// A scene that does not set `recording.full_fields_every` records full fields at every
/// iteration while they are at most 1 MB an iteration, and every 20th above: two-blocks (N = 4)
/// is small; the same blocks at N = 20000 are 24 bytes × 20001 time points × the boundary values,
/// above 1 MB.
#[test]
fn full_fields_every_follows_the_scenes_size_unless_set() {
    let small = load(TWO_BLOCKS).unwrap();
    assert!(crate::full_field_bytes_per_iteration(&small.model) <= crate::AUTO_FULL_FIELD_BYTES);
    assert_eq!(
        (small.recording.full_fields_every, small.recording.full_fields_auto),
        (1, true)
    );
    assert_eq!(small.recording.incomplete(), None);
    let long = load(&TWO_BLOCKS.replace("N = 4\n", "N = 20000\n")).unwrap();
    assert_eq!(long.model.time.n_points(), 20001);
    assert!(crate::full_field_bytes_per_iteration(&long.model) > crate::AUTO_FULL_FIELD_BYTES);
    assert_eq!(long.recording.full_fields_every, crate::AUTO_FULL_FIELDS_EVERY);
    let why = long.recording.incomplete().expect("thinned");
    assert!(why.contains("--record full"), "{why}");
    let set = load(&format!(
        "{}[recording]\nfull_fields_every = 1\n",
        TWO_BLOCKS.replace("N = 4\n", "N = 20000\n")
    ))
    .unwrap();
    assert_eq!(
        (set.recording.full_fields_every, set.recording.full_fields_auto),
        (1, false)
    );
}

/// `deployment.memory_limit_gb` bounds the estimated memory of a scene before anything is
/// built: two-blocks needs a few MB (so 1 MB refuses it, naming the estimate and the limit) and
/// a 3000 × 3000 block about 130 GB of operators alone (2 dofs × 27 M nodes × 2.4 kB).
#[test]
fn the_memory_limit_refuses_a_scene_that_would_not_fit() {
    let with_limit = |text: &str, gb: f64| load(&format!("{text}[deployment]\nmemory_limit_gb = {gb}\n"));
    assert!(with_limit(TWO_BLOCKS, 1.0).is_ok());
    let e = with_limit(TWO_BLOCKS, 0.001).unwrap_err();
    assert_eq!(e.key, "(size)");
    assert!(
        e.problem.contains("more than deployment.memory_limit_gb (0.0 GB)"),
        "{e}"
    );
    let huge = TWO_BLOCKS
        .replacen("nx = ", "nx = 3000 #", 1)
        .replacen("ny = ", "ny = 3000 #", 1);
    let e = with_limit(&huge, 100.0).unwrap_err();
    assert!(e.problem.contains("GB of operators for its meshes"), "{e}");
    let estimate: f64 = e
        .problem
        .split("estimated ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((100.0..1000.0).contains(&estimate), "{e}");
    let e = with_limit(TWO_BLOCKS, -1.0).unwrap_err();
    assert_eq!(e.key, "deployment.memory_limit_gb");
}
