//! The format's checks: what loads, what is refused and with which key.

use super::*;
use glissade_mechanics::mesh::BlockSide;
use glissade_mechanics::model::{
    Acceleration, Interface, InterfaceKind, Plane, SolverParams, TimeFunction, TimeStart, DEFAULT_ACCURACY,
    DEFAULT_TIME_START_TOLERANCE,
};
use glissade_mechanics::pgd::PgdCriterion;

mod axisymmetric;
mod rejections;
mod settings;

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

/// Command-line overrides of the solver's accuracy, tolerance and iteration cap set the model as
/// the same keys in the file would, leave the text as written and change the fingerprint; the
/// text and the overrides (what node processes and recordings get) rebuild the same scene, and an
/// invalid value is the error the file's key gives.
#[test]
fn solver_overrides_set_the_model_and_keep_the_text() {
    const FILE: &str = "scenes/test.toml";
    let s = load(TWO_BLOCKS).unwrap();
    assert!(s.overrides.is_none());
    let same = s.with_overrides(FILE, &Overrides::default()).unwrap();
    assert_eq!((&same.text, same.fingerprint), (&s.text, s.fingerprint));
    assert_eq!(
        s.fingerprint,
        fingerprint(TWO_BLOCKS),
        "no overrides: the text's fingerprint"
    );
    assert_eq!(
        fingerprint_with(TWO_BLOCKS, &Overrides::default()),
        fingerprint(TWO_BLOCKS)
    );
    let overrides = Overrides {
        accuracy: Some(1e-4),
        tolerance: Some(2.5e-9),
        max_iterations: Some(7),
        record: None,
    };
    let o = s.with_overrides(FILE, &overrides).unwrap();
    assert_eq!(o.text, s.text, "the text stays as written");
    assert_eq!(o.overrides, overrides);
    let solver = &o.model.solver;
    assert_eq!(
        (solver.accuracy, solver.tolerance, solver.max_iterations),
        (Some(1e-4), Some(2.5e-9), 7)
    );
    // As if written in the file: the same model, everything else as written.
    let written = load(&format!(
        "{TWO_BLOCKS}[solver]\naccuracy = 1e-4\ntolerance = 2.5e-9\nmax_iterations = 7\n"
    ))
    .unwrap();
    assert_eq!(format!("{:?}", o.model), format!("{:?}", written.model));
    assert_eq!(o.recording, s.recording);
    // The fingerprint covers the overrides: another value, another fingerprint.
    assert_ne!(o.fingerprint, s.fingerprint);
    assert_eq!(o.fingerprint, fingerprint_with(&s.text, &overrides));
    let eight = Overrides {
        max_iterations: Some(8),
        ..overrides
    };
    assert_ne!(fingerprint_with(&s.text, &eight), o.fingerprint);
    let only_accuracy = Overrides {
        accuracy: Some(1e-4),
        ..Default::default()
    };
    let only_tolerance = Overrides {
        tolerance: Some(1e-4),
        ..Default::default()
    };
    assert_ne!(
        fingerprint_with(&s.text, &only_accuracy),
        fingerprint_with(&s.text, &only_tolerance)
    );
    // (text, overrides) round-trip, the overrides through their serde form too.
    let json = serde_json::to_string(&o.overrides).unwrap();
    let back: Overrides = serde_json::from_str(&json).unwrap();
    assert_eq!(back, overrides);
    let again = load_with(&o.text, FILE, &back).unwrap();
    assert_eq!(format!("{:?}", again.model), format!("{:?}", o.model));
    assert_eq!((again.fingerprint, &again.overrides), (o.fingerprint, &o.overrides));
    assert_eq!(again.recording, o.recording);
    // Overrides on top of overrides: the later win, and the text with both rebuilds the result.
    let later = Overrides {
        max_iterations: Some(9),
        ..Default::default()
    };
    let twice = o.with_overrides(FILE, &later).unwrap();
    assert_eq!(
        (twice.model.solver.accuracy, twice.model.solver.max_iterations),
        (Some(1e-4), 9)
    );
    assert_eq!(twice.overrides, overrides.then(later));
    assert_eq!(
        twice.fingerprint,
        load_with(&s.text, FILE, &twice.overrides).unwrap().fingerprint
    );
    // A scene with a [solver] table keeps its other keys.
    let with_solver = load(&format!("{TWO_BLOCKS}[solver]\nrelaxation = 0.5\n")).unwrap();
    let o = with_solver
        .with_overrides(
            FILE,
            &Overrides {
                max_iterations: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!((o.model.solver.relaxation, o.model.solver.max_iterations), (0.5, 3));
    // An invalid value is the error the file's own key gives, from either entry point, said of
    // the flag that gave it.
    for (bad, written, flag) in [
        (
            Overrides {
                max_iterations: Some(0),
                ..Default::default()
            },
            "max_iterations = 0",
            "--max-iterations 0",
        ),
        (
            Overrides {
                tolerance: Some(-1.0),
                ..Default::default()
            },
            "tolerance = -1.0",
            "--tolerance -1",
        ),
        (
            Overrides {
                accuracy: Some(1.5),
                ..Default::default()
            },
            "accuracy = 1.5",
            "--accuracy 1.5",
        ),
    ] {
        let from_file = load(&format!("{TWO_BLOCKS}[solver]\n{written}\n")).unwrap_err();
        assert!(from_file.key.starts_with("solver."), "{from_file}");
        assert_eq!(from_file.set_by, None);
        let said = SceneError {
            set_by: Some(flag.to_string()),
            ..from_file.clone()
        };
        assert_eq!(s.with_overrides(FILE, &bad).unwrap_err(), said);
        assert_eq!(load_with(TWO_BLOCKS, FILE, &bad).unwrap_err(), said);
        assert_eq!(said.to_string(), format!("{flag}: {from_file}"));
    }
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
        include_str!("../../../../launch/scenes/stratified.toml"),
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
    let text = include_str!("../../../../launch/scenes/small-three-layer.toml");
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
    assert!(
        s.deployment.interfaces_in_launcher,
        "by default, where the launcher can"
    );
    assert!(
        !three_layers("interfaces_in_launcher = false")
            .unwrap()
            .deployment
            .interfaces_in_launcher
    );
    assert!(!s.deployment.interfaces_with_subdomains, "off by default");
    assert!(
        three_layers("interfaces_with_subdomains = true")
            .unwrap()
            .deployment
            .interfaces_with_subdomains
    );
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
        (
            "interfaces_with_subdomains = true\ninterface_nodes = 2",
            "deployment.interfaces_with_subdomains",
            "excludes deployment.interface_nodes: the interface nodes follow the subdomain processes",
        ),
        (
            "interfaces_with_subdomains = true\ninterface_groups = [[0, 1, 2], [3, 4, 5, 6]]",
            "deployment.interfaces_with_subdomains",
            "excludes deployment.interface_groups",
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
    let page = include_str!("../../../../docs/scenes.md");
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
        include_str!("../../../../launch/scenes/stratified.toml"),
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
