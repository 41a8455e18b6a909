//! Supervision: a node process killed with SIGKILL mid-run is restarted by the launcher, the
//! replacement rebuilds its state from the recorder's log, and the run ends bit-identical to an
//! undisturbed one; a node that keeps dying stops the run after `deployment.restarts` restarts.

use crate::common::{scene, scene_text};
use crate::common::{scratch, Scratch};
use crate::distributed::assert_identical;
use crate::node_failures::processes_with;
use glissade::distributed::Network;
use glissade::run::Run;
use glissade::runner::{IterationRecord, RunOptions, RunResult};
use glissade_scene::LoadedScene;
use std::path::{Path, PathBuf};

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_glissade"))
}

fn small_three_layer(deployment: &str) -> String {
    let text = scene_text("small-three-layer");
    assert!(text.contains("\n[deployment]\n"), "the scene has a deployment section");
    text.replacen("\n[deployment]\n", &format!("\n[deployment]\n{deployment}\n"), 1)
}

/// A scratch folder, a run id, and the recording file of run `name` in that folder (`run.mcap`).
fn recorded_run(name: &str) -> (Scratch, String, PathBuf) {
    let dir = scratch(name);
    let run_id = format!("{name}-{}", std::process::id());
    let recording = dir.join("run.mcap");
    (dir, run_id, recording)
}

/// Runs `sc` as node processes on loopback as run `run_id`, recorded to `recording`, with
/// `on_iteration` seeing each decision as it reaches the launcher.
fn run_recorded<'a>(
    sc: &'a LoadedScene,
    run_id: &str,
    recording: &Path,
    on_iteration: impl FnMut(&IterationRecord) + 'a,
) -> glissade::Result<RunResult> {
    Run::new(sc, &RunOptions::new(run_id))
        .recorded(Some(recording))
        .on_iteration(on_iteration)
        .processes(exe(), &Network::default())
        .map(|o| o.result)
}

/// No process of run `run_id` is left.
fn assert_none_left(run_id: &str) {
    assert!(
        processes_with(run_id, &[]).is_empty(),
        "processes of run {run_id} remain"
    );
}

/// A small xorshift generator: the kill iterations are reproducible from the printed seed.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0 % n
    }
}

/// The one process of run `run_id` that is node `role` (with `--index index`).
fn node_pid(run_id: &str, role: &str, index: &str) -> i32 {
    // The coarse node takes no --index (a run has one).
    let words: &[&str] = if role == "coarse" {
        &["node", role]
    } else {
        &["node", role, "--index", index]
    };
    let pids = processes_with(run_id, words);
    assert_eq!(pids.len(), 1, "node {role}:{index} of run {run_id}: processes {pids:?}");
    pids[0]
}

/// SIGKILL to the one process of run `run_id` that is node `role` (with `--index index`).
fn kill_node(run_id: &str, role: &str, index: &str) -> i32 {
    let pid = node_pid(run_id, role, index);
    // SAFETY: kill(2) on a pid of this test's run.
    unsafe {
        libc::kill(pid, libc::SIGKILL);
    }
    pid
}

/// kill -9 of each node role (subdomain, interface, coarse, and one of several interface nodes)
/// at an iteration drawn by a seeded generator: the launcher restarts the node, which resumes from the recording, and the run's
/// decisions and every interface field are bit-identical to the undisturbed in-process run
/// (itself bit-identical to a multi-process run, tests/it/distributed.rs).
#[test]
fn killed_nodes_are_restarted_and_the_run_ends_bit_identical() {
    let undisturbed = crate::common::run(&scene(&small_three_layer("")));
    let n = undisturbed.iterations.len() as u64;
    assert!(
        n > 6,
        "the scene converges in {n} iterations: too few to kill a node mid-run"
    );
    let seed = 0x9e37_79b9_7f4a_7c15;
    let mut rng = Rng(seed);
    // The fourth case: one of three interface nodes, one that does not decide (it sends its
    // indicator sums to node 0); several interface nodes are bit-identical to one. The last: a
    // subdomain process that also runs the interface node of the interfaces between its own
    // subdomains (`interfaces_with_subdomains`): both resume.
    for (role, index, deployment) in [
        ("subdomain", "1", ""),
        ("interface", "0", ""),
        ("coarse", "0", ""),
        ("interface", "1", "interface_nodes = 3"),
        ("subdomain", "1", "interfaces_with_subdomains = true"),
    ] {
        let sc = scene(&small_three_layer(deployment));
        // Not the last iteration: the kill must land while the run still needs the node.
        let at = 1 + rng.below(n - 3) as u32;
        println!("seed {seed:#x}: kill {role}:{index} at iteration {at} of {n}");
        let with = if deployment.is_empty() { "" } else { "-deployed" };
        let (dir, run_id, recording) = recorded_run(&format!("recovery-{role}-{index}{with}"));
        let mut killed = None;
        let result = run_recorded(&sc, &run_id, &recording, |r| {
            if r.iteration == at && killed.is_none() {
                killed = Some(kill_node(&run_id, role, index));
            }
        })
        .unwrap_or_else(|e| panic!("run with {role}:{index} killed at iteration {at}: {e:#}"));
        let old = killed.expect("the kill iteration was reached");
        assert!(!processes_with(&run_id, &[]).contains(&old));
        assert_none_left(&run_id);
        assert_identical(&undisturbed, &result);
        // The recording of the disturbed run is complete and finalised: every iteration's
        // decision is in it once.
        let rec = glissade_recorder::Recording::open(&dir.join("run.mcap")).expect("recording");
        assert!(rec.is_finished(), "the recording is finalised");
        let decisions = rec.messages().filter(|m| m.topic.ends_with("/decision")).count();
        assert!(
            decisions >= n as usize,
            "{decisions} decisions recorded for {n} iterations"
        );
    }
}

/// A node killed again after its last allowed restart stops the run with an error that says so.
#[test]
fn a_node_that_keeps_dying_stops_the_run_after_its_restarts() {
    let sc = scene(&small_three_layer("restarts = 1"));
    let (_dir, run_id, recording) = recorded_run("recovery-again");
    let mut kills = Vec::new();
    let err = run_recorded(&sc, &run_id, &recording, |r| {
        if (r.iteration == 2 || r.iteration == 5) && kills.len() < 2 {
            kills.push(kill_node(&run_id, "subdomain", "0"));
        }
    })
    .expect_err("the run must stop");
    let msg = format!("{err:#}");
    assert_eq!(kills.len(), 2, "{msg}");
    assert_ne!(kills[0], kills[1], "the second kill hits the replacement");
    assert!(
        msg.contains("node subdomain:0 died again after 1 restart(s) (deployment.restarts = 1)"),
        "{msg}"
    );
    assert_none_left(&run_id);
}

/// A scene whose recording leaves messages out cannot resume a node: the launcher says restarts
/// are off and why, and a node's death stops the run as without supervision.
#[test]
fn restarts_need_a_complete_recording() {
    let text = small_three_layer("") + "\n[recording]\nfull_fields_every = 5\n";
    let sc = scene(&text);
    assert_eq!(
        sc.recording.incomplete().as_deref(),
        Some("recording.full_fields_every = 5 leaves full fields out")
    );
    let (_dir, run_id, recording) = recorded_run("recovery-thinned");
    let mut killed = false;
    let err = run_recorded(&sc, &run_id, &recording, |r| {
        if r.iteration == 2 && !killed {
            kill_node(&run_id, "subdomain", "0");
            killed = true;
        }
    })
    .expect_err("the run must stop");
    assert!(format!("{err:#}").contains("node subdomain:0 failed"), "{err:#}");
    assert_none_left(&run_id);
}

/// Kills at any moment, not only as a decision reaches the launcher: a subdomain process is
/// killed a few milliseconds (seeded, 0–59 ms) after a seeded iteration's decision, so that the
/// kill lands while nodes publish, while the recorder is behind the run, or after the run's
/// end. Every run ends bit-identical to the undisturbed one and leaves no process. Before, a
/// replacement could drop a message the recorder had heard before one it follows (the run
/// stalled), the launcher could restart a peer that had finished instead of the killed process,
/// and a replacement started as the run ended waited for a `done` already sent.
#[test]
fn kills_at_any_moment_end_bit_identical() {
    let sc = scene(&small_three_layer(""));
    let undisturbed = crate::common::run(&sc);
    let n = undisturbed.iterations.len() as u64;
    let seed = 0x1234_5678_9abc_def1;
    let mut rng = Rng(seed);
    for round in 0..30 {
        let at = 1 + rng.below(n - 1) as u32;
        let delay = std::time::Duration::from_millis(rng.below(60));
        let index = if rng.below(2) == 0 { "0" } else { "1" };
        println!("seed {seed:#x}, round {round}: kill subdomain:{index} {delay:?} after iteration {at}");
        let (_dir, run_id, recording) = recorded_run(&format!("recovery-any-{round}"));
        let mut killer = None;
        let result = run_recorded(&sc, &run_id, &recording, |r| {
            if r.iteration == at && killer.is_none() {
                let run_id = run_id.clone();
                killer = Some(std::thread::spawn(move || {
                    std::thread::sleep(delay);
                    // None when the process already left (the run is over).
                    for pid in processes_with(&run_id, &["node", "subdomain", "--index", index]) {
                        // SAFETY: kill(2) on a pid of this test's run.
                        unsafe {
                            libc::kill(pid, libc::SIGKILL);
                        }
                    }
                }));
            }
        })
        .unwrap_or_else(|e| panic!("round {round}: {e:#}"));
        killer.expect("the kill iteration was reached").join().unwrap();
        assert_identical(&undisturbed, &result);
        assert_none_left(&run_id);
    }
}

/// A node process that dies or freezes after the launcher said `done`. At the last decision the
/// coarse node's or a subdomain's process is stopped (SIGSTOP: it has nothing left to send); the
/// test waits until the run's other subdomain, interface and coarse processes have left (they
/// leave only on `done`, so the launcher holds every result), then kills it. In the frozen
/// case it is never resumed: the launcher stops it once its link's lease has run out (the
/// recorder waits for it until then). The same for a kill as the last decision arrives,
/// before `done`. Every case ends bit-identical, the recording finalised, no process left.
#[test]
fn a_node_dying_or_frozen_after_done_costs_nothing() {
    /// What happens to the node process, relative to the launcher's `done`.
    #[derive(Clone, Copy, PartialEq, Debug)]
    enum Fate {
        KilledBefore,
        KilledAfter,
        FrozenAfter,
    }
    let sc = scene(&small_three_layer(""));
    let undisturbed = crate::common::run(&sc);
    let last = undisturbed.iterations.last().expect("iterations").iteration;
    for (round, (role, index, fate)) in [
        ("coarse", "0", Fate::KilledAfter),
        ("subdomain", "1", Fate::KilledAfter),
        ("subdomain", "0", Fate::FrozenAfter),
        ("subdomain", "0", Fate::KilledBefore),
        ("coarse", "0", Fate::KilledBefore),
    ]
    .into_iter()
    .enumerate()
    {
        println!("{role}:{index}: {fate:?}");
        let (dir, run_id, recording) = recorded_run(&format!("recovery-done-{round}"));
        let mut watcher = None;
        let result = run_recorded(&sc, &run_id, &recording, |r| {
            if r.iteration != last || watcher.is_some() {
                return;
            }
            let pid = node_pid(&run_id, role, index);
            if fate == Fate::KilledBefore {
                // SAFETY: kill(2) on a pid of this test's run.
                unsafe { libc::kill(pid, libc::SIGKILL) };
                watcher = Some(std::thread::spawn(move || true));
                return;
            }
            // SAFETY: as above.
            unsafe { libc::kill(pid, libc::SIGSTOP) };
            let run_id = run_id.clone();
            watcher = Some(std::thread::spawn(move || {
                // The other node processes but the recorder (which waits for every node
                // process) leave once the launcher has said `done` (bounded wait).
                let recorder = processes_with(&run_id, &["node", "recorder"]);
                let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
                let others_left = loop {
                    let left = processes_with(&run_id, &["node"])
                        .iter()
                        .all(|p| *p == pid || recorder.contains(p));
                    if left || std::time::Instant::now() > deadline {
                        break left;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(10));
                };
                if fate == Fate::KilledAfter {
                    // SAFETY: as above; the process is stopped, so still there to be killed.
                    unsafe { libc::kill(pid, libc::SIGKILL) };
                }
                others_left
            }));
        })
        .unwrap_or_else(|e| panic!("{role}:{index}, {fate:?}: {e:#}"));
        let others_left = watcher.expect("the last decision was reached").join().unwrap();
        assert!(
            others_left,
            "{role}:{index} stopped: the other node processes did not leave within 30 s"
        );
        assert_identical(&undisturbed, &result);
        assert_none_left(&run_id);
        let rec = glissade_recorder::Recording::open(&dir.join("run.mcap")).expect("recording");
        assert!(rec.is_finished(), "the recording is finalised");
    }
}
