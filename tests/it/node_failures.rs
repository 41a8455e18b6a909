//! A multi-process run without restarts stops within 10 s, naming the node, when any one node is
//! killed, and stops every node when the launcher gets Ctrl-C; no node process of the run remains.

use crate::common::{scene_text, scratch, Scratch};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// The bound on how fast a run stops once a node died.
const STOP_BOUND: Duration = Duration::from_secs(10);

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_glissade"))
}

/// The small three-layer scene with stop rules that never end the run (it runs until stopped).
fn endless_scene(dir: &Path) -> PathBuf {
    let text = scene_text("small-three-layer");
    let solver = "accuracy = 1e-3\n";
    assert!(text.contains(solver), "the scene's solver section changed");
    let text = text.replace(
        solver,
        "tolerance = 1e-300\nmax_iterations = 1000000\nstagnation_window = 1000000\n",
    );
    let path = dir.join("endless.toml");
    std::fs::write(&path, text).expect("write the scene");
    path
}

/// Pids of the processes whose command line contains `needle` and every one of `words`.
pub fn processes_with(needle: &str, words: &[&str]) -> Vec<i32> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir("/proc").expect("/proc").flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<i32>() else {
            continue;
        };
        let Ok(raw) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let args: Vec<String> = raw
            .split(|&b| b == 0)
            .map(|a| String::from_utf8_lossy(a).into_owned())
            .collect();
        if args.iter().any(|a| a == needle) && words.iter().all(|w| args.iter().any(|a| a == w)) {
            out.push(pid);
        }
    }
    out
}

/// A launcher process whose stderr lines arrive on a channel (and are echoed for the log).
pub struct Launcher {
    pub child: Child,
    lines: mpsc::Receiver<String>,
    pub stderr: Vec<String>,
}

impl Launcher {
    pub fn spawn(cmd: &mut Command) -> Self {
        let mut child = cmd
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the launcher");
        let (tx, lines) = mpsc::channel();
        for stream in [
            Box::new(child.stderr.take().unwrap()) as Box<dyn std::io::Read + Send>,
            Box::new(child.stdout.take().unwrap()),
        ] {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    eprintln!("  | {line}");
                    let _ = tx.send(line);
                }
            });
        }
        Self {
            child,
            lines,
            stderr: Vec::new(),
        }
    }

    /// Waits (bounded) for an output line containing `text`.
    pub fn wait_for_line(&mut self, text: &str, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Ok(l) = self.lines.recv_timeout(Duration::from_millis(100)) {
                let hit = l.contains(text);
                self.stderr.push(l);
                if hit {
                    return;
                }
            }
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
        panic!("no line with `{text}` within {timeout:?}");
    }

    /// Waits (bounded) for the launcher to exit; collects the rest of its output.
    pub fn wait_exit(&mut self, timeout: Duration) -> ExitStatus {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait().expect("try_wait") {
                // The output threads end with the pipes.
                while let Ok(l) = self.lines.recv_timeout(Duration::from_millis(500)) {
                    self.stderr.push(l);
                }
                return status;
            }
            if Instant::now() > deadline {
                let _ = self.child.kill();
                let _ = self.child.wait();
                panic!("the launcher did not exit within {timeout:?}");
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    pub fn output(&self) -> String {
        self.stderr.join("\n")
    }
}

/// A test that fails before its launcher exits must not leave the run going (an endless scene
/// runs until stopped): the launcher is killed and reaped, and its nodes follow it (their
/// parent-death signal).
impl Drop for Launcher {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn launch_endless(name: &str) -> (Launcher, String, Scratch) {
    launch_endless_with(name, "", "")
}

/// As [`launch_endless`], with `deployment` lines added to the scene's deployment section and
/// `sections` appended to the scene.
fn launch_endless_with(name: &str, deployment: &str, sections: &str) -> (Launcher, String, Scratch) {
    let dir = scratch(name);
    let scene = endless_scene(&dir);
    if !deployment.is_empty() || !sections.is_empty() {
        let text = std::fs::read_to_string(&scene).expect("read the scene");
        assert!(text.contains("\n[deployment]\n"), "the scene has a deployment section");
        let text = text.replacen("\n[deployment]\n", &format!("\n[deployment]\n{deployment}\n"), 1) + sections;
        std::fs::write(&scene, text).expect("write the scene");
    }
    let run_id = format!("{name}-{}", std::process::id());
    let mut cmd = Command::new(exe());
    cmd.arg("run")
        .arg(&scene)
        .args(["--quiet", "--verbose", "--run-id", &run_id, "--out"])
        .arg(&*dir);
    let mut launcher = Launcher::spawn(&mut cmd);
    launcher.wait_for_line("ready, iterating", Duration::from_secs(180));
    // Let the iteration run for a while: the kill lands mid-run.
    std::thread::sleep(Duration::from_millis(1500));
    (launcher, run_id, dir)
}

fn assert_no_process_left(run_id: &str) {
    let left = processes_with(run_id, &[]);
    assert!(left.is_empty(), "processes of run {run_id} remain: {left:?}");
}

/// Kills node `role` (`--index` `index`, if given) with SIGKILL mid-run.
fn kill_one(role: &str, index: Option<&str>) {
    kill_one_of(role, index, "");
}

/// As [`kill_one`], with `deployment` lines added to the scene's deployment section.
fn kill_one_of(role: &str, index: Option<&str>, deployment: &str) {
    let several = if deployment.is_empty() { "" } else { "-of-several" };
    let name = format!("kill-{role}-{}{several}", index.unwrap_or("0"));
    // Without restarts (tests/it/recovery.rs has the supervised runs).
    let (launcher, run_id, _dir) = launch_endless_with(&name, &format!("restarts = 0\n{deployment}"), "");
    kill_and_expect_stop(launcher, &run_id, role, index);
}

/// Kills node `role` (`--index` `index`, if given) of the running `launcher` with SIGKILL and
/// checks that the run stops within [`STOP_BOUND`], naming the node, and leaves no process.
fn kill_and_expect_stop(mut launcher: Launcher, run_id: &str, role: &str, index: Option<&str>) {
    let mut words = vec!["node", role];
    if let Some(i) = index {
        words.extend(["--index", i]);
    }
    let pids = processes_with(run_id, &words);
    assert_eq!(pids.len(), 1, "one process of node {role}: {pids:?}");
    assert!(
        launcher.child.try_wait().unwrap().is_none(),
        "the run was still going when the node was killed"
    );
    let t = Instant::now();
    // SAFETY: a plain kill(2) of a process this test found by its command line.
    assert_eq!(unsafe { libc::kill(pids[0], libc::SIGKILL) }, 0);
    let status = launcher.wait_exit(Duration::from_secs(60));
    let took = t.elapsed();
    let out = launcher.output();
    let node = format!("{role}:{}", index.unwrap_or("0"));
    println!("killed {node}: the launcher exited with {status} after {took:?}");
    assert!(took < STOP_BOUND, "the run took {took:?} to stop");
    assert_eq!(status.code(), Some(2), "{out}");
    let error = out
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_else(|| panic!("no error line in:\n{out}"));
    assert!(
        error.contains(&format!("node {node} failed")) && error.contains("SIGKILL"),
        "the error names the killed node and its exit status: {error}"
    );
    assert_no_process_left(run_id);
}

/// With shared memory a node process that dies is not restarted (docs/architecture.md, "Node restarts": a
/// killed process's last messages can reach some nodes and not others): with restarts allowed
/// (the default) and the run recorded completely, the launcher says so up front, and a killed
/// node stops the run instead of being restarted.
#[test]
fn with_shared_memory_a_killed_node_stops_the_run_instead_of_restarting() {
    let name = "kill-subdomain-1-shared-memory";
    let (launcher, run_id, dir) = launch_endless_with(name, "", "\n[network]\nshared_memory = true\n");
    let scene = std::fs::read_to_string(dir.join("endless.toml")).expect("read the scene");
    assert!(
        !scene.contains("restarts") && !scene.contains("[recording]"),
        "restarts and recording at their defaults (3, complete): shared memory must be the only reason"
    );
    let said = launcher.output();
    assert!(
        said.contains("node restarts off (network.shared_memory = true"),
        "the launcher says why restarts are off:\n{said}"
    );
    kill_and_expect_stop(launcher, &run_id, "subdomain", Some("1"));
}

#[test]
fn killing_a_subdomain_node_stops_the_run() {
    kill_one("subdomain", Some("1"));
}

/// Without restarts the interface nodes run in the launcher's process unless the scene says
/// otherwise (`interfaces_in_launcher = false`): here they run in processes of their own.
#[test]
fn killing_the_interface_node_stops_the_run() {
    kill_one_of("interface", None, "interfaces_in_launcher = false");
}

/// With three interface nodes, killing one that does not decide (node 1 only sends its
/// indicators to node 0) stops the run naming it; so does killing the deciding node 0.
#[test]
fn killing_one_of_several_interface_nodes_stops_the_run() {
    let processes = "interface_nodes = 3\ninterfaces_in_launcher = false";
    kill_one_of("interface", Some("1"), processes);
    kill_one_of("interface", Some("0"), processes);
}

/// Where no node restarts are possible (here `restarts = 0`) the launcher runs the interface
/// nodes in its own process, beside the router: no interface process runs, the subdomain and
/// coarse processes do, and on Ctrl-C the interface node leaves on the launcher's stop as the
/// node processes do, its lines under its name.
#[test]
fn without_restarts_the_interface_node_runs_in_the_launcher() {
    let (mut launcher, run_id, _dir) = launch_endless_with("hosted-interface", "restarts = 0", "");
    assert!(
        processes_with(&run_id, &["node", "interface"]).is_empty(),
        "an interface process runs"
    );
    for role in ["subdomain", "coarse"] {
        assert!(
            !processes_with(&run_id, &["node", role]).is_empty(),
            "no {role} process runs"
        );
    }
    // SAFETY: a plain kill(2) of the launcher this test started.
    assert_eq!(unsafe { libc::kill(launcher.child.id() as i32, libc::SIGINT) }, 0);
    let status = launcher.wait_exit(Duration::from_secs(60));
    let out = launcher.output();
    assert_eq!(status.code(), Some(130), "{out}");
    assert!(
        out.lines()
            .any(|l| l.starts_with("[interface:0] ") && l.contains("stopped by the launcher")),
        "the interface node says it was stopped:\n{out}"
    );
    assert_no_process_left(&run_id);
}

#[test]
fn killing_the_coarse_node_stops_the_run() {
    kill_one("coarse", None);
}

#[test]
fn ctrl_c_stops_every_node() {
    let (mut launcher, run_id, dir) = launch_endless("interrupt");
    let t = Instant::now();
    // SAFETY: a plain kill(2) of the launcher this test started.
    assert_eq!(unsafe { libc::kill(launcher.child.id() as i32, libc::SIGINT) }, 0);
    let status = launcher.wait_exit(Duration::from_secs(60));
    let took = t.elapsed();
    let out = launcher.output();
    println!("SIGINT: the launcher exited with {status} after {took:?}");
    assert!(took < STOP_BOUND, "the run took {took:?} to stop");
    assert_eq!(status.code(), Some(130), "{out}");
    assert!(out.contains("interrupted after"), "{out}");
    // Every node left on the launcher's stop message rather than being killed.
    assert!(out.contains("stopped by the launcher"), "{out}");
    let summary = std::fs::read_to_string(dir.join(format!("small-three-layer-{run_id}.summary.json")))
        .expect("the summary of the interrupted run");
    let summary: serde_json::Value = serde_json::from_str(&summary).unwrap();
    assert_eq!(summary["interrupted"], serde_json::json!(true));
    assert!(summary["iterations"].as_u64().unwrap() > 0, "{summary}");
    assert_no_process_left(&run_id);
}

/// A launcher killed with SIGKILL takes its node processes with it (they get the parent-death
/// signal, and would otherwise see the launcher's liveliness token disappear).
#[test]
fn killing_the_launcher_leaves_no_node() {
    let (mut launcher, run_id, _dir) = launch_endless("kill-launcher");
    assert!(!processes_with(&run_id, &["node"]).is_empty(), "the nodes run");
    launcher.child.kill().expect("SIGKILL the launcher");
    launcher.wait_exit(Duration::from_secs(60));
    let deadline = Instant::now() + STOP_BOUND;
    while !processes_with(&run_id, &[]).is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_no_process_left(&run_id);
}

/// `cmd` (the glissade executable) started as subdomain node 1 of run `run_id` by hand: it
/// connects to `endpoint` with the credentials the launcher wrote into `out`, and `extra`
/// arguments (those the launcher printed, e.g. `--interior`).
pub fn start_hand_node(mut cmd: Command, run_id: &str, endpoint: &str, out: &Path, extra: &[&str]) -> Launcher {
    cmd.args([
        "node",
        "subdomain",
        "--run",
        run_id,
        "--connect",
        endpoint,
        "--index",
        "1",
    ])
    .args(extra)
    .arg("--credentials")
    .arg(out.join(format!("{run_id}-subdomain-1.credentials")));
    Launcher::spawn(&mut cmd)
}

/// A launcher on a given loopback port that leaves subdomain node 1 to be started by hand, and
/// that node, started here as a separate process (not a child of the launcher).
fn launch_with_hand_started_node(name: &str) -> (Launcher, Launcher, String, Scratch) {
    let dir = scratch(name);
    let scene = endless_scene(&dir);
    let run_id = format!("{name}-{}", std::process::id());
    let port = glissade_zenoh::free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let mut cmd = Command::new(exe());
    cmd.arg("run")
        .arg(&scene)
        .args([
            "--quiet",
            "--verbose",
            "--run-id",
            &run_id,
            "--listen",
            &endpoint,
            "--remote",
            "subdomain:1",
            "--out",
        ])
        .arg(&*dir);
    let mut launcher = Launcher::spawn(&mut cmd);
    launcher.wait_for_line("on the other machine", Duration::from_secs(120));
    let node = start_hand_node(Command::new(exe()), &run_id, &endpoint, &dir, &[]);
    launcher.wait_for_line("ready, iterating", Duration::from_secs(180));
    std::thread::sleep(Duration::from_millis(1500));
    (launcher, node, run_id, dir)
}

/// A node started by hand notices on its own, through the launcher's liveliness token, that
/// the launcher died, and stops within 10 s naming it.
#[test]
fn a_hand_started_node_stops_when_the_launcher_dies() {
    let (mut launcher, mut node, run_id, _dir) = launch_with_hand_started_node("lost-launcher");
    let t = Instant::now();
    launcher.child.kill().expect("SIGKILL the launcher");
    launcher.wait_exit(Duration::from_secs(60));
    let status = node.wait_exit(Duration::from_secs(60));
    let took = t.elapsed();
    println!("the hand-started node exited with {status} after {took:?}");
    assert!(took < STOP_BOUND, "the node took {took:?} to stop");
    assert!(!status.success());
    // Every token goes with the router; the node names the launcher's.
    assert!(
        node.output().contains("error: peer launcher:0 left the run"),
        "{}",
        node.output()
    );
    assert_no_process_left(&run_id);
}

/// The launcher names a node started by hand that died, and stops the others.
#[test]
fn the_launcher_names_a_dead_hand_started_node() {
    let (mut launcher, mut node, run_id, _dir) = launch_with_hand_started_node("lost-remote");
    let t = Instant::now();
    node.child.kill().expect("SIGKILL the node");
    node.wait_exit(Duration::from_secs(60));
    let status = launcher.wait_exit(Duration::from_secs(60));
    let took = t.elapsed();
    let out = launcher.output();
    println!("the launcher exited with {status} after {took:?}");
    assert!(took < STOP_BOUND, "the run took {took:?} to stop");
    assert_eq!(status.code(), Some(2), "{out}");
    let error = out.lines().find(|l| l.starts_with("error:")).expect("an error line");
    assert!(
        error.contains("node subdomain:1 (started by hand elsewhere) left the run"),
        "{error}"
    );
    assert_no_process_left(&run_id);
}

/// On a shared router (a stand-in for `zenohd`, which the launchers connect to), a second
/// launcher with the run id of a running run refuses to start, naming the tokens already alive,
/// and the first run goes on undisturbed.
#[test]
fn a_second_launcher_with_the_same_run_id_refuses_to_start() {
    let dir = scratch("same-run-id");
    let scene = endless_scene(&dir);
    let run_id = format!("same-run-id-{}", std::process::id());
    let endpoint = format!("tcp/127.0.0.1:{}", glissade_zenoh::free_loopback_port().unwrap());
    let _router =
        glissade_zenoh::open(glissade_zenoh::config("router", std::slice::from_ref(&endpoint), &[], false).unwrap())
            .unwrap();
    let mut cmd = Command::new(exe());
    cmd.arg("run")
        .arg(&scene)
        .args([
            "--quiet",
            "--verbose",
            "--run-id",
            &run_id,
            "--connect",
            &endpoint,
            "--out",
        ])
        .arg(&*dir);
    let mut launcher = Launcher::spawn(&mut cmd);
    launcher.wait_for_line("ready, iterating", Duration::from_secs(180));
    let t = Instant::now();
    let second = Command::new(exe())
        .arg("run")
        .arg(&scene)
        .args(["--quiet", "--run-id", &run_id, "--connect", &endpoint, "--out"])
        .arg(dir.join("second"))
        .output()
        .expect("spawn the second launcher");
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "run id {run_id} is already in use on the Zenoh router at {endpoint}"
        )) && stderr.contains(&format!("glissade/{run_id}/alive/launcher/0")),
        "{stderr}"
    );
    assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
    // The first run is still iterating.
    assert!(
        launcher.child.try_wait().expect("try_wait").is_none(),
        "{}",
        launcher.output()
    );
    launcher.child.kill().expect("SIGKILL the launcher");
    launcher.wait_exit(Duration::from_secs(60));
}

/// A node process that stops answering without dying (SIGSTOP) is the one the launcher names,
/// not the peer that noticed it first and left (a stopped subdomain 1 used to be reported as
/// "node subdomain:0 failed"). Its token lapses with the Zenoh lease, so the run stops within
/// the lease plus the usual bound, and leaves no process.
#[test]
fn a_stopped_node_is_named_rather_than_the_peer_that_noticed() {
    let (mut launcher, run_id, _dir) = launch_endless_with("stop-subdomain-1", "restarts = 0\n", "");
    let pids = processes_with(&run_id, &["node", "subdomain", "--index", "1"]);
    assert_eq!(pids.len(), 1, "{pids:?}");
    let t = Instant::now();
    // SAFETY: a plain kill(2) of a process this test found by its command line.
    assert_eq!(unsafe { libc::kill(pids[0], libc::SIGSTOP) }, 0);
    let status = launcher.wait_exit(Duration::from_secs(90));
    let took = t.elapsed();
    let out = launcher.output();
    println!("stopped subdomain:1: the launcher exited with {status} after {took:?}");
    // SAFETY: as above; the stopped process is resumed so that it can be reaped.
    unsafe { libc::kill(pids[0], libc::SIGCONT) };
    assert!(
        took < glissade_zenoh::LEASE + STOP_BOUND,
        "the run took {took:?} to stop"
    );
    assert_eq!(status.code(), Some(2), "{out}");
    let error = out
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_else(|| panic!("no error line in:\n{out}"));
    assert!(
        error.contains("node subdomain:1 stopped answering") && error.contains("before node "),
        "the error names the stopped node: {error}"
    );
    std::thread::sleep(Duration::from_secs(2));
    assert_no_process_left(&run_id);
}
