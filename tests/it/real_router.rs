//! A run through a Zenoh router outside the launcher's process (`glissade run --connect`): a
//! router of the same Zenoh version (1.10.2), here Eclipse's Python package in router mode,
//! which is the same Rust core `zenohd` runs (docs/operations.md has the run through `zenohd`).

use crate::common::{python_with, scratch};
use crate::node_failures::Launcher;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

const ROUTER: &str = r#"
import sys, time, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"router"')
conf.insert_json5("listen/endpoints", '["' + sys.argv[1] + '"]')
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
print("router listening on", sys.argv[1], flush=True)
while True:
    time.sleep(1)
"#;

#[test]
fn a_run_through_a_router_of_its_own_gives_the_in_process_bits() {
    let Some(python) = python_with(&["zenoh"]) else {
        return;
    };
    let dir = scratch("real-router");
    let script = dir.join("router.py");
    std::fs::write(&script, ROUTER).unwrap();
    let endpoint = format!("tcp/127.0.0.1:{}", glissade_zenoh::free_loopback_port().unwrap());
    // Killed and reaped on drop, also when the test fails.
    let mut router = Launcher::spawn(Command::new(python).arg(&script).arg(&endpoint));
    router.wait_for_line("router listening", Duration::from_secs(60));

    let exe = Path::new(env!("CARGO_BIN_EXE_glissade"));
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    let run = |extra: &[&str], id: &str| {
        let out = Command::new(exe)
            .arg("run")
            .arg(&scene)
            .args(["--quiet", "--no-record", "--run-id", id, "--out"])
            .arg(dir.join(id))
            .args(extra)
            .output()
            .expect("glissade runs");
        assert!(
            out.status.success(),
            "{id}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let p = dir.join(id).join(format!("small-three-layer-{id}.fields.json"));
        std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let through_router = run(&["--connect", &endpoint], "via-router");
    let in_process = run(&["--in-process"], "in-process");
    assert!(
        router.child.try_wait().unwrap().is_none(),
        "the router died:\n{}",
        router.output()
    );
    // JSON numbers are written in their shortest exact form: equal bytes are equal bits.
    assert!(
        through_router == in_process,
        "interface fields through the router differ from in-process"
    );
    // Unrecorded, through a router outside its process, the launcher subscribes to what it
    // keeps only: the fields go from their sender to their receivers and not to it.
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("via-router").join("small-three-layer-via-router.summary.json")).unwrap(),
    )
    .unwrap();
    let bus = &summary["bus"];
    assert_eq!(bus["counted"], "kept", "{bus}");
    let kinds: Vec<&str> = bus["by_kind"].as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(kinds, ["decision", "interface_solution", "linear_stage_stats"], "{bus}");
    assert_eq!(bus["by_kind"]["decision"]["messages"], summary["iterations"], "{bus}");
}
