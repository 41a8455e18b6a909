//! Bad scenes and command lines (issue 9): each of the table's inputs makes the `glissade`
//! binary exit with status 2, print an error that names the problem and where it is (the exact
//! text below), and write nothing into the output folder.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// The scene every bad scene is derived from (two blocks in contact, the GetFEM reference).
const GOOD: &str = include_str!("../../launch/scenes/two-blocks.toml");

/// How a case changes the good scene: replace `from` by `to` (each `from` must occur).
type Edit = (&'static str, &'static str);

struct Case {
    name: &'static str,
    /// Arguments; `{scene}` is the (edited) scene file, `{out}` the output folder.
    args: &'static [&'static str],
    edits: &'static [Edit],
    /// Text the error message must contain: the problem and where it is (`{dir}` as in `args`).
    error: &'static str,
}

const RUN: &[&str] = &["run", "--in-process", "--quiet", "--out", "{out}", "{scene}"];

const CASES: &[Case] = &[
    Case {
        name: "a device as the scene file (read until memory ran out before)",
        args: &["run", "--in-process", "--out", "{out}", "/dev/zero"],
        edits: &[],
        error: "scene file /dev/zero: is not a regular file",
    },
    Case {
        name: "a negative accuracy on the command line",
        args: &["run", "--in-process", "--accuracy", "-1", "--out", "{out}", "{scene}"],
        edits: &[],
        error: "--accuracy -1: {dir}/bad.toml: solver.accuracy: -1 is outside (0, 1)",
    },
    Case {
        name: "an amplification that is not a number",
        args: &["replay", "--amplification", "NaN", "{dir}/no-such.mcap"],
        edits: &[],
        error: "invalid value 'NaN' for '--amplification <AMPLIFICATION>': NaN is not a finite number above 0",
    },
    Case {
        name: "a laminate too large to build here",
        args: &["generate", "laminate", "--plies", "100000", "--per-ply", "100000", "-o", "{out}/huge.toml"],
        edits: &[],
        error: "a laminate of 100000 × 100000 subdomains of 10 × 10 QUA8 needs about 341000.0 GB to be built and \
                checked here",
    },
    Case {
        name: "bench kernels with processes",
        args: &["bench", "--kernels", "baseline", "--processes", "1", "--out", "{out}", "{scene}"],
        edits: &[],
        error: "the argument '--kernels <KERNELS>' cannot be used with '--processes <ROUNDS>'",
    },
    Case {
        name: "scene file missing",
        args: &["run", "--in-process", "--out", "{out}", "{dir}/no-such-scene.toml"],
        edits: &[],
        error: "cannot read scene file {dir}/no-such-scene.toml: No such file or directory",
    },
    Case {
        name: "not TOML",
        args: RUN,
        edits: &[("name = \"two-blocks\"", "name = ")],
        error: "bad.toml: (syntax): line 5, column 8: string values must be quoted",
    },
    Case {
        name: "unknown top-level key",
        args: RUN,
        edits: &[("plane = \"strain\"", "plane = \"strain\"\ncolour = \"red\"")],
        error: "bad.toml: colour: line 7, column 1: unknown field `colour`, expected one of `name`",
    },
    Case {
        name: "wrong type",
        args: RUN,
        edits: &[("N = 40", "N = \"forty\"")],
        error: "bad.toml: time.N: line 10, column 5: invalid type: string \"forty\", expected usize",
    },
    Case {
        name: "an override the scene's rule refuses",
        args: &["report", "--max-iterations", "0", "--out", "{out}", "{scene}"],
        edits: &[],
        error: "--max-iterations 0: {dir}/bad.toml: solver.max_iterations: must be ≥ 1",
    },
    Case {
        name: "an accuracy out of range",
        args: &["run", "--in-process", "--accuracy", "2", "--out", "{out}", "{scene}"],
        edits: &[],
        error: "--accuracy 2: {dir}/bad.toml: solver.accuracy: ",
    },
    Case {
        name: "run id too long",
        args: &["run", "--in-process", "--run-id", "rrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrr", "--out", "{out}", "{scene}"],
        edits: &[],
        error: "--run-id `rrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrrr`: a run id is 1 to 64 letters",
    },
    Case {
        name: "node run id that is a wildcard",
        args: &["node", "subdomain", "--run", "**", "--connect", "tcp/127.0.0.1:9"],
        edits: &[],
        error: "--run `**`: a run id is 1 to 64 letters, digits, `-` or `_`",
    },
    Case {
        name: "scene name that is a path",
        args: RUN,
        edits: &[("name = \"two-blocks\"", "name = \"../../evil/x\"")],
        error: "bad.toml: name: `../../evil/x` is not a file name",
    },
    Case {
        name: "zero time steps",
        args: RUN,
        edits: &[("N = 40", "N = 0")],
        error: "bad.toml: time.N: N = 0: need at least one time step (N ≥ 1)",
    },
    Case {
        name: "incompressible material",
        args: RUN,
        edits: &[("nu = 0.3", "nu = 0.5")],
        error: "bad.toml: materials.steel.nu: ν = 0.5 is outside (−1, 0.5)",
    },
    Case {
        name: "negative Young's modulus",
        args: RUN,
        edits: &[("E = 210000.0", "E = -210000.0")],
        error: "bad.toml: materials.steel.E: E = -210000 must be > 0 (MPa)",
    },
    Case {
        name: "unknown material",
        args: RUN,
        edits: &[(
            "name = \"upper\"\nmaterial = \"steel\"",
            "name = \"upper\"\nmaterial = \"stele\"",
        )],
        error: "bad.toml: block[1].material: unknown material `stele` (defined: steel)",
    },
    Case {
        name: "overlapping blocks",
        args: RUN,
        edits: &[("y = [20.0, 40.0]", "y = [10.0, 40.0]")],
        error: "bad.toml: block[1]: block `upper` overlaps block `lower`",
    },
    Case {
        name: "no elements",
        args: RUN,
        edits: &[("nx = 16\nny = 8\n\n[[block]]", "nx = 0\nny = 8\n\n[[block]]")],
        error: "bad.toml: block[0].nx: nx = 0: need at least one element",
    },
    Case {
        name: "negative friction",
        args: RUN,
        edits: &[("friction = 0.2", "friction = -0.2")],
        error: "bad.toml: interface[0].friction: friction coefficient -0.2 must be a finite number ≥ 0",
    },
    Case {
        name: "interface rule naming an unknown block",
        args: RUN,
        edits: &[("between = [\"lower\", \"upper\"]", "between = [\"lower\", \"uper\"]")],
        error: "bad.toml: interface[0].between: unknown block or subdomain `uper`",
    },
    Case {
        name: "gap formula that does not parse",
        args: RUN,
        edits: &[("friction = 0.2", "friction = 0.2\ngap = \"x^^2\"")],
        error: "bad.toml: interface[0].gap: formula `x^^2`: unexpected character at position 2",
    },
    Case {
        name: "time function that does not parse",
        args: RUN,
        edits: &[("ux = \"0.004*sin(2*pi*t/1)\"", "ux = \"0.004*sin(2*pi*t/1\"")],
        error: "bad.toml: boundary[1].ux: formula `0.004*sin(2*pi*t/1`: expected `)` at position 18",
    },
    Case {
        name: "relaxation above 1",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[solver]\nrelaxation = 1.5\n")],
        error: "bad.toml: solver.relaxation: 1.5 is outside (0, 1]",
    },
    Case {
        name: "search-direction update with α above the stability limit",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[solver]\nsearch_direction_update = true\nalpha = 0.5\n",
        )],
        error: "bad.toml: solver.alpha: 0.5 is above 0.3333 = 2(1 − μ)/(2 − μ) for relaxation μ = 0.8",
    },
    Case {
        name: "macro degree out of range",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[solver]\nmacro_degree = 9\n")],
        error: "bad.toml: solver.macro_degree: 9 is neither \"auto\" nor a degree in 1..=5",
    },
    Case {
        name: "more subdomain nodes than subdomains",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[deployment]\nsubdomain_nodes = 5\n")],
        error: "bad.toml: deployment.subdomain_nodes: 5 nodes for 2 subdomain(s): some nodes would host nothing",
    },
    Case {
        name: "more interface nodes than interfaces",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[deployment]\ninterface_nodes = 2\n")],
        error: "bad.toml: deployment.interface_nodes: 2 nodes for 1 interface(s): some nodes would own nothing",
    },
    Case {
        name: "interface owned by two interface nodes",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[deployment]\ninterface_groups = [[\"lower|upper\"], [0]]\n",
        )],
        error: "bad.toml: deployment.interface_groups[1][0]: interface 0 (lower|upper) is already in group 0",
    },
    Case {
        name: "interface named without its two sides",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[deployment]\ninterface_groups = [[\"lower-upper\"]]\n",
        )],
        error: "bad.toml: deployment.interface_groups[0][0]: `lower-upper`: name an interface as \"A|B\" (blocks or subdomains) or by its index",
    },
    Case {
        name: "unbounded node restarts",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[deployment]\nrestarts = 1000\n")],
        error: "bad.toml: deployment.restarts: 1000: at most 100 (a node that keeps dying will not recover)",
    },
    Case {
        name: "unknown solver key",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[solver]\ntolerence = 1e-6\n")],
        error: "bad.toml: solver.tolerence: line 50, column 1: unknown field `tolerence`, expected one of `k0_factor`",
    },
    Case {
        name: "output folder is a file",
        args: &["run", "--in-process", "--out", "{dir}/a-file", "{scene}"],
        edits: &[],
        error: "output folder {dir}/a-file is a file, not a folder",
    },
    Case {
        name: "run without a scene",
        args: &["run", "--in-process"],
        edits: &[],
        error: "error: the following required arguments were not provided:\n  <SCENE>",
    },
    Case {
        name: "report tolerance not a number",
        args: &["report", "--out", "{out}", "--tolerance", "tiny", "{scene}"],
        edits: &[],
        error: "error: invalid value 'tiny' for '--tolerance <TOLERANCE>': invalid float literal",
    },
    Case {
        name: "report stop-at-error not positive",
        args: &["report", "--out", "{out}", "--stop-at-error=-1e-3", "{scene}"],
        edits: &[],
        error: "error: --stop-at-error -0.001: must be a positive number",
    },
    Case {
        name: "unknown stability case",
        args: &["stability", "--out", "{out}", "--case", "no-such-case"],
        edits: &[],
        error: "error: --case no-such-case: no such case (`glissade stability --list` names them)",
    },
    Case {
        name: "unknown node role",
        args: &["node", "janitor", "--run", "r", "--connect", "tcp/127.0.0.1:9"],
        edits: &[],
        error: "error: invalid value 'janitor' for '<ROLE>'",
    },
    Case {
        name: "unknown command",
        args: &["frobnicate"],
        edits: &[],
        error: "error: unrecognized subcommand 'frobnicate'",
    },
    Case {
        name: "TLS certificate authority file missing",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[network]\ntls = { root_ca = \"certs/ca.pem\", cert = \"a-file\", key = \"a-file\" }\n",
        )],
        error: "bad.toml: network.tls.root_ca: cannot read {dir}/certs/ca.pem: No such file or directory",
    },
    Case {
        name: "TLS file not PEM",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[network]\ntls = { root_ca = \"a-file\", cert = \"a-file\", key = \"a-file\" }\n",
        )],
        error: "bad.toml: network.tls.root_ca: {dir}/a-file is not a PEM file (no -----BEGIN line)",
    },
    Case {
        name: "TLS key missing",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[network]\ntls = { root_ca = \"ca.pem\", cert = \"node.pem\" }\n",
        )],
        error: "bad.toml: network.tls.key: line 50, column 7: missing field `key`",
    },
    Case {
        name: "access control without TLS",
        args: RUN,
        edits: &[("uy = -0.01\n", "uy = -0.01\n\n[network]\nallow = [\"node-a\"]\n")],
        error: "bad.toml: network.allow: access control names processes by their certificates: it needs network.tls",
    },
    Case {
        name: "access control without mutual TLS",
        args: RUN,
        edits: &[(
            "uy = -0.01\n",
            "uy = -0.01\n\n[network]\ntls = { root_ca = \"ca.pem\", cert = \"c.pem\", key = \"k.pem\" }\nallow = [\"node-a\"]\n",
        )],
        error: "bad.toml: network.allow: access control needs network.tls.mutual = true",
    },
    Case {
        name: "node: TLS endpoint without a CA file",
        args: &["node", "subdomain", "--run", "r", "--connect", "tls/127.0.0.1:9"],
        edits: &[],
        error: "endpoint tls/127.0.0.1:9: a TLS endpoint needs the certificate authority's file",
    },
    Case {
        name: "node: TLS certificate without its key",
        args: &["node", "subdomain", "--run", "r", "--connect", "tls/127.0.0.1:9", "--tls-cert", "{dir}/a-file"],
        edits: &[],
        error: "error: the following required arguments were not provided:\n  --tls-key <PEM>",
    },
    Case {
        name: "node: TLS CA file missing",
        args: &["node", "subdomain", "--run", "r", "--connect", "tls/127.0.0.1:9", "--tls-root-ca", "{dir}/ca.pem"],
        edits: &[],
        error: "error: --tls-root-ca {dir}/ca.pem: cannot read it: No such file or directory",
    },
    // Sizes are checked against the machine's memory before any mesh or time grid is built (a
    // 3000 × 3000 block used to be killed by the out-of-memory killer, N = 10⁹ to abort).
    Case {
        name: "a block of 3000 × 3000 elements",
        args: &["check", "{scene}"],
        edits: &[("nx = 16\nny = 8", "nx = 3000\nny = 3000")],
        error: "(size): the scene needs an estimated ",
    },
    Case {
        name: "N = 10⁹ time steps",
        args: &["run", "--in-process", "--out", "{out}", "{scene}"],
        edits: &[("N = 40", "N = 1000000000")],
        error: " GB of space-time fields for N = 1000000000), more than this machine's memory",
    },
    Case {
        name: "a formula nested 100 deep",
        args: &["check", "{scene}"],
        edits: &[("ux = \"0.004*sin(2*pi*t/1)\"", "ux = \"((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((((t))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))))\"")],
        error: "nested more than 64 levels deep",
    },
];

fn files_in(dir: &Path) -> Vec<PathBuf> {
    match std::fs::read_dir(dir) {
        Ok(rd) => rd.filter_map(|e| e.ok().map(|e| e.path())).collect(),
        Err(_) => Vec::new(),
    }
}

#[test]
fn bad_inputs_exit_2_with_a_clear_error_and_write_nothing() {
    assert!(
        CASES.len() >= 20,
        "the issue asks for a table of at least 20 bad inputs"
    );
    let root = crate::common::scratch("bad-input");
    let mut failures = Vec::new();
    for (i, case) in CASES.iter().enumerate() {
        let dir = root.join(format!("case-{i}"));
        let out = dir.join("out");
        std::fs::create_dir_all(&dir).expect("temp dir");
        std::fs::write(dir.join("a-file"), b"not a folder").expect("temp file");
        let mut text = GOOD.to_string();
        for (from, to) in case.edits {
            assert!(text.contains(from), "{}: `{from}` not in the scene", case.name);
            text = text.replacen(from, to, 1);
        }
        let scene = dir.join("bad.toml");
        std::fs::write(&scene, &text).expect("scene file");
        let args: Vec<String> = case
            .args
            .iter()
            .map(|a| {
                a.replace("{scene}", &scene.to_string_lossy())
                    .replace("{out}", &out.to_string_lossy())
                    .replace("{dir}", &dir.to_string_lossy())
            })
            .collect();
        let output = Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args(&args)
            .output()
            .expect("spawn glissade");
        let stderr = String::from_utf8_lossy(&output.stderr);
        let written = files_in(&out);
        let error = case.error.replace("{dir}", &dir.to_string_lossy());
        let ok = output.status.code() == Some(2) && stderr.contains(&error) && written.is_empty();
        if !ok {
            failures.push(format!(
                "{}: status {:?}, files written {written:?}, stderr:\n{stderr}\n(expected: `{}`)",
                case.name,
                output.status.code(),
                error
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n---\n"));
}

/// `RUST_LOG` turns on the log of every process (docs/operations.md, "Logs"); a filter that is not
/// one is bad input like any other: exit 2, the variable and its value named, nothing written.
#[test]
fn a_bad_rust_log_exits_2_and_writes_nothing() {
    let dir = crate::common::scratch("bad-rust-log");
    let scene = dir.join("two-blocks.toml");
    std::fs::write(&scene, GOOD).expect("scene file");
    let out = dir.join("out");
    let output = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .env("RUST_LOG", "zenoh=[")
        .args(["run", "--in-process", "--quiet", "--out"])
        .arg(&out)
        .arg(&scene)
        .output()
        .expect("spawn glissade");
    let stderr = String::from_utf8_lossy(&output.stderr);
    let written = files_in(&out);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("error: RUST_LOG = \"zenoh=[\" is not a tracing filter"),
        "{stderr}"
    );
    assert!(written.is_empty(), "files written: {written:?}");
}

/// A second run with the run id of one whose outputs are in `--out` is refused before solving:
/// exit 2, the files named, and the first run's files left exactly as they were.
#[test]
fn a_run_never_overwrites_an_earlier_runs_outputs() {
    let dir = crate::common::scratch("no-overwrite");
    let scene = dir.join("two-blocks.toml");
    std::fs::write(&scene, GOOD).expect("scene file");
    let out = dir.join("out");
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args(["run", "--in-process", "--quiet", "--run-id", "same", "--out"])
            .arg(&out)
            .arg(&scene)
            .output()
            .expect("spawn glissade")
    };
    let first = run();
    assert_eq!(
        first.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let before: Vec<(PathBuf, Vec<u8>)> = {
        let mut files = files_in(&out);
        files.sort();
        files
            .into_iter()
            .map(|p| (p.clone(), std::fs::read(&p).expect("read")))
            .collect()
    };
    assert!(
        before.iter().any(|(p, _)| p.ends_with("two-blocks-same.summary.json")),
        "{before:?}"
    );
    let second = run();
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("run same of scene `two-blocks` already has outputs there (two-blocks-same.summary.json")
            && stderr.contains("nothing was overwritten"),
        "{stderr}"
    );
    let mut after = files_in(&out);
    after.sort();
    assert_eq!(after, before.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>());
    for (p, bytes) in &before {
        assert_eq!(&std::fs::read(p).expect("read"), bytes, "{} changed", p.display());
    }
}

/// The measuring commands write fixed file names (`<scene>-reference.*`, `<scene>-report.*`,
/// `<scene>-bench.json`, `stability.*`): where one of them is already in `--out`, the command
/// stops before solving anything, exit 2, naming the file, and leaves it as it was.
#[test]
fn the_measuring_commands_never_overwrite_an_earlier_result() {
    let dir = crate::common::scratch("measure-no-overwrite");
    let scene = dir.join("two-blocks.toml");
    std::fs::write(&scene, GOOD).expect("scene file");
    let scene = scene.to_string_lossy().into_owned();
    let cases: [(&[&str], &str); 5] = [
        (&["reference", &scene], "two-blocks-reference.fields.json"),
        (&["report", &scene], "two-blocks-report.svg"),
        (
            &["report", "--variants", "condensed+plain,condensed", &scene],
            "two-blocks-condensed-report.json",
        ),
        (&["bench", &scene], "two-blocks-bench.json"),
        (&["stability", "--case", "base"], "stability.json"),
    ];
    for (i, (args, existing)) in cases.iter().enumerate() {
        let out = dir.join(format!("out-{i}"));
        std::fs::create_dir_all(&out).expect("out");
        let kept = out.join(existing);
        std::fs::write(&kept, b"an earlier result").expect("earlier file");
        let output = Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args(*args)
            .arg("--out")
            .arg(&out)
            .output()
            .expect("spawn glissade");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains(&format!("{} already exists; nothing was overwritten", kept.display())),
            "{args:?}: {stderr}"
        );
        assert_eq!(std::fs::read(&kept).expect("read"), b"an earlier result");
        assert_eq!(files_in(&out), vec![kept], "{args:?}: something was written");
    }
}

/// A recording that is not a regular file is refused before it is read, by `replay` and by
/// `export --foreign` alike: a link to /dev/zero was read until memory ran out (24 GB before it
/// was killed), and a FIFO blocked the reader forever. Each is refused at once (exit 2), the file
/// named, and nothing written.
#[test]
fn a_recording_that_is_not_a_regular_file_is_refused_at_once() {
    let dir = crate::common::scratch("recording-not-a-file");
    let zero = dir.join("zero.mcap");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("symlink");
    let fifo = dir.join("fifo.mcap");
    let c_path = std::ffi::CString::new(fifo.to_string_lossy().as_bytes()).expect("path");
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) }, 0, "mkfifo");
    for (recording, kind) in [(&zero, "a character device"), (&fifo, "a FIFO")] {
        let out = dir.join("out");
        let commands: [Vec<OsString>; 2] = [
            vec![
                "replay".into(),
                "--save".into(),
                out.join("view.rrd").into(),
                recording.into(),
            ],
            vec![
                "export".into(),
                recording.into(),
                "--foreign".into(),
                out.clone().into(),
            ],
        ];
        for args in commands {
            let (output, took) = run_at_most(&args, Duration::from_secs(20));
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
            let error = format!("recording {}: is not a regular file ({kind})", recording.display());
            assert!(stderr.contains(&error), "{args:?}: {stderr}\n(expected: `{error}`)");
            assert!(files_in(&out).is_empty(), "{args:?}: written {:?}", files_in(&out));
            // Refused before anything is read: well within a second but for a loaded machine.
            assert!(took < Duration::from_secs(5), "{args:?}: took {took:?}");
        }
    }
}

/// Runs `glissade` with `args`, killed (and the test failed) after `limit`: its output and how long
/// it took. For the inputs that once hung or ran for minutes before their refusal.
fn run_at_most(args: &[OsString], limit: Duration) -> (std::process::Output, Duration) {
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn glissade");
    while child.try_wait().expect("try_wait").is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?}: still running after {:?}", start.elapsed());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let took = start.elapsed();
    (child.wait_with_output().expect("output"), took)
}

/// A mesh scene with N = 10¹¹ time steps is refused for its size at once, as a block scene is:
/// `check` ran for minutes (trying every divisor of N for the time-coarse grid) before it came to
/// the mesh's size check. Exit 2, the memory named, nothing written.
#[test]
fn a_mesh_scene_with_too_many_time_steps_is_refused_at_once() {
    let dir = crate::common::scratch("mesh-huge-n");
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("launch/scenes");
    let text = std::fs::read_to_string(scenes.join("wedge.toml")).expect("wedge scene");
    let mesh = scenes.join("meshes/wedge.msh");
    for from in ["file = \"meshes/wedge.msh\"", "N = 10\n"] {
        assert!(text.contains(from), "`{from}` not in wedge.toml");
    }
    let text = text
        .replacen(
            "file = \"meshes/wedge.msh\"",
            &format!("file = {:?}", mesh.display().to_string()),
            1,
        )
        .replacen("N = 10\n", "N = 100000000000\n", 1);
    let scene = dir.join("wedge-huge-n.toml");
    std::fs::write(&scene, text).expect("scene file");
    let out = dir.join("out");
    for command in [&["check"][..], &["run", "--in-process", "--out"]] {
        let mut args: Vec<OsString> = command.iter().map(OsString::from).collect();
        if command[0] == "run" {
            args.push(out.clone().into());
        }
        args.push(scene.clone().into());
        let (output, took) = run_at_most(&args, Duration::from_secs(20));
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("wedge-huge-n.toml: (size): the scene needs an estimated ")
                && stderr.contains(" GB of space-time fields for N = 100000000000), more than this machine's memory"),
            "{args:?}: {stderr}"
        );
        assert!(files_in(&out).is_empty(), "{args:?}: written {:?}", files_in(&out));
        // The refusal comes before any work per time point: well within a second but for a
        // loaded machine.
        assert!(took < Duration::from_secs(5), "{args:?}: took {took:?}");
    }
}
