//! A run across two hosts: two network namespaces joined by a veth pair, each with its own
//! address. The launcher runs in one (its router listening on its veth address) and leaves
//! subdomain node 1 to be started by hand in the other. Creating namespaces needs root; without
//! it the test prints why it skipped.

use crate::common::scratch;
use crate::node_failures::{start_hand_node, Launcher};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// Two network namespaces `a` and `b` joined by a veth pair; deleted on drop.
struct TwoHosts {
    a: String,
    b: String,
    addr_a: String,
}

impl TwoHosts {
    fn create() -> Result<Self, String> {
        // SAFETY: geteuid has no preconditions.
        if unsafe { libc::geteuid() } != 0 {
            return Err("creating network namespaces needs root".into());
        }
        let id = std::process::id() % 100_000;
        let octet = id % 250 + 1;
        let hosts = Self {
            a: format!("glissade-a-{id}"),
            b: format!("glissade-b-{id}"),
            addr_a: format!("10.213.{octet}.1"),
        };
        let addr_b = format!("10.213.{octet}.2");
        let (veth_a, veth_b) = (format!("gla{id}"), format!("glb{id}"));
        let steps: Vec<Vec<String>> = vec![
            vec!["netns".into(), "add".into(), hosts.a.clone()],
            vec!["netns".into(), "add".into(), hosts.b.clone()],
            vec!["link", "add", &veth_a, "type", "veth", "peer", "name", &veth_b]
                .into_iter()
                .map(String::from)
                .collect(),
            vec![
                "link".into(),
                "set".into(),
                veth_a.clone(),
                "netns".into(),
                hosts.a.clone(),
            ],
            vec![
                "link".into(),
                "set".into(),
                veth_b.clone(),
                "netns".into(),
                hosts.b.clone(),
            ],
            vec![
                "-n".into(),
                hosts.a.clone(),
                "addr".into(),
                "add".into(),
                format!("{}/24", hosts.addr_a),
                "dev".into(),
                veth_a.clone(),
            ],
            vec![
                "-n".into(),
                hosts.b.clone(),
                "addr".into(),
                "add".into(),
                format!("{addr_b}/24"),
                "dev".into(),
                veth_b.clone(),
            ],
            vec![
                "-n".into(),
                hosts.a.clone(),
                "link".into(),
                "set".into(),
                veth_a,
                "up".into(),
            ],
            vec![
                "-n".into(),
                hosts.b.clone(),
                "link".into(),
                "set".into(),
                veth_b,
                "up".into(),
            ],
            vec![
                "-n".into(),
                hosts.a.clone(),
                "link".into(),
                "set".into(),
                "lo".into(),
                "up".into(),
            ],
            vec![
                "-n".into(),
                hosts.b.clone(),
                "link".into(),
                "set".into(),
                "lo".into(),
                "up".into(),
            ],
        ];
        for step in steps {
            let out = Command::new("ip")
                .args(&step)
                .output()
                .map_err(|e| format!("cannot run `ip`: {e}"))?;
            if !out.status.success() {
                // Drop removes what was created so far.
                return Err(format!(
                    "`ip {}` failed: {}",
                    step.join(" "),
                    String::from_utf8_lossy(&out.stderr).trim()
                ));
            }
        }
        Ok(hosts)
    }

    /// A command running `program` inside namespace `ns`.
    fn exec(ns: &str, program: &Path) -> Command {
        let mut cmd = Command::new("ip");
        cmd.args(["netns", "exec", ns]).arg(program);
        cmd
    }
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        // Deleting a namespace also deletes its end of the veth pair, and with it the pair.
        for ns in [&self.a, &self.b] {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
        }
    }
}

#[test]
fn run_across_two_network_namespaces() {
    let hosts = match TwoHosts::create() {
        Ok(h) => h,
        Err(reason) => {
            println!("skipped: {reason}");
            return;
        }
    };
    let exe = Path::new(env!("CARGO_BIN_EXE_glissade"));
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    let dir = scratch("two-hosts");
    let (dir_a, dir_local) = (dir.join("a"), dir.join("local"));
    let run_id = format!("two-hosts-{}", std::process::id());
    let endpoint = format!("tcp/{}:17447", hosts.addr_a);
    let mut launcher = Launcher::spawn(
        TwoHosts::exec(&hosts.a, exe)
            .arg("run")
            .arg(&scene)
            .args([
                "--quiet",
                "--run-id",
                &run_id,
                "--listen",
                &endpoint,
                "--remote",
                "subdomain:1",
            ])
            .arg("--out")
            .arg(&dir_a),
    );
    launcher.wait_for_line("on the other machine", Duration::from_secs(120));
    // The node of the other host gets the scene over the bus: no file there, but its credentials,
    // which the launcher wrote into its --out (here the two hosts share the file system).
    let mut node = start_hand_node(TwoHosts::exec(&hosts.b, exe), &run_id, &endpoint, &dir_a, &[]);
    let status = launcher.wait_exit(Duration::from_secs(600));
    let node_status = node.wait_exit(Duration::from_secs(60));
    assert!(status.success(), "launcher: {status}\n{}", launcher.output());
    assert!(node_status.success(), "node: {node_status}\n{}", node.output());
    let credentials = dir_a.join(format!("{run_id}-subdomain-1.credentials"));
    assert!(!credentials.exists(), "the credentials outlive the run");

    let local = Command::new(exe)
        .arg("run")
        .arg(&scene)
        .args(["--in-process", "--quiet", "--run-id", "two-hosts-local", "--out"])
        .arg(&dir_local)
        .output()
        .expect("in-process run");
    assert!(local.status.success(), "{}", String::from_utf8_lossy(&local.stderr));
    let read = |d: &Path, id: &str, what: &str| -> serde_json::Value {
        let p = d.join(format!("small-three-layer-{id}.{what}.json"));
        serde_json::from_str(&std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))).unwrap()
    };
    // The same bits: JSON numbers are written in their shortest exact form and read back exactly.
    assert_eq!(
        read(&dir_a, &run_id, "fields"),
        read(&dir_local, "two-hosts-local", "fields"),
        "interface fields of the two-host run and the in-process run"
    );
    let (s_a, s_local) = (
        read(&dir_a, &run_id, "summary"),
        read(&dir_local, "two-hosts-local", "summary"),
    );
    assert_eq!(s_a["iterations"], s_local["iterations"]);
    assert!(
        s_a["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n == "started by hand: subdomain:1"),
        "{}",
        s_a["nodes"]
    );
    assert_eq!(s_a["eta"], s_local["eta"]);
    println!("two hosts: {} iterations, as in-process", s_a["iterations"]);
}
