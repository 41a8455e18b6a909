//! The solver, acceleration, network, recording and memory settings: their keys, defaults and
//! overrides.

use super::*;
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
    // The divisors are tried up to √N only (N = 10¹¹ tried every number below it), with the
    // choice of trying them all.
    for n in 1..5000usize {
        let every = (2..n)
            .filter(|c| n.is_multiple_of(*c))
            .min_by_key(|&c| ((n / c).abs_diff(AUTO_COARSE_STEPS), std::cmp::Reverse(c)));
        assert_eq!(
            auto_coarsening(n),
            every.filter(|_| n >= AUTO_COARSENING_MIN_STEPS),
            "N = {n}"
        );
    }
    let start = std::time::Instant::now();
    assert_eq!(auto_coarsening(100_000_000_000), Some(1_000_000_000));
    assert!(start.elapsed().as_secs_f64() < 0.5, "{:?}", start.elapsed());
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

/// `--record` sets the scene's recording: off, or complete (every message, full fields at every
/// iteration) whatever the scene says; the text stays as written.
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
    assert_eq!(full.text, thinned.text);
    assert_eq!(full.overrides.record, Some(RecordOverride::Full));
    assert_ne!(full.fingerprint, off.fingerprint);
    assert!(thinned.recording.incomplete().is_some());
    // The text and the overrides rebuild the same recording settings.
    let again = load_with(&full.text, "scenes/test.toml", &full.overrides).unwrap();
    assert_eq!(again.recording, full.recording);
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
