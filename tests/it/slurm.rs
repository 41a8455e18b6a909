//! Runs on a Slurm cluster (docs/operations.md, "On a cluster"): `glissade run --slurm` inside
//! an allocation and `glissade submit`, on the one-host cluster CI starts (`.ci/slurm`). The
//! node processes are job steps (their environment says so), the numbers are the in-process
//! run's bit for bit, and `scancel` ends a run as Interrupted with its summary and recording.
//! Without a cluster these tests say so and pass, unless GLISSADE_REQUIRE_SLURM is set (CI sets
//! it after starting the cluster), where they fail.

use crate::common::{glissade_ok, output_file, scene_file, scratch};
use crate::node_failures::processes_with;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// Whether a Slurm cluster answers here with a node ready to run jobs.
fn slurm_ready() -> bool {
    let required = std::env::var_os("GLISSADE_REQUIRE_SLURM").is_some();
    let state = Command::new("sinfo").args(["-h", "-o", "%T"]).output();
    let ready = state.as_ref().is_ok_and(|o| {
        o.status.success()
            && String::from_utf8_lossy(&o.stdout)
                .lines()
                .any(|l| l.starts_with("idle") || l.starts_with("mix"))
    });
    if !ready {
        let why = match &state {
            Err(e) => format!("sinfo cannot run ({e})"),
            Ok(o) => format!("sinfo says `{}`", String::from_utf8_lossy(&o.stdout).trim()),
        };
        assert!(
            !required,
            "GLISSADE_REQUIRE_SLURM is set but no Slurm node is ready: {why}"
        );
        println!("skipped: no Slurm cluster here ({why}); .ci/slurm up starts a one-host one");
    }
    ready
}

/// The in-process run's fields of `scene` (its `fields.json` bytes).
fn in_process_fields(scene: &Path, dir: &Path) -> Vec<u8> {
    let out = dir.join("in-process");
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--no-record",
        &"--quiet",
        &"--out",
        &out,
    ]);
    std::fs::read(output_file(&out, ".fields.json")).unwrap()
}

/// A finished MCAP file ends with its magic.
fn finalised(mcap: &Path) -> bool {
    std::fs::read(mcap).is_ok_and(|b| b.ends_with(b"\x89MCAP0\r\n"))
}

/// The Slurm node a process runs on as a job step of `job` (its environment's
/// `SLURMD_NODENAME`), None if it is not one.
fn step_of(pid: i32, job: &str) -> Option<String> {
    let env = std::fs::read(format!("/proc/{pid}/environ")).unwrap_or_default();
    let vars: Vec<String> = env
        .split(|&b| b == 0)
        .map(|v| String::from_utf8_lossy(v).into_owned())
        .collect();
    let step = vars.iter().any(|v| v.starts_with("SLURM_STEP_ID="))
        && vars.iter().any(|v| *v == format!("SLURM_JOB_ID={job}"));
    if !step {
        return None;
    }
    vars.iter()
        .find_map(|v| v.strip_prefix("SLURMD_NODENAME=").map(str::to_string))
}

/// Waits (up to `limit`) for job `job` to leave the queue.
fn wait_gone(job: &str, limit: Duration) {
    let t = Instant::now();
    loop {
        let q = Command::new("squeue")
            .args(["-h", "-j", job, "-o", "%T"])
            .output()
            .unwrap();
        if String::from_utf8_lossy(&q.stdout).trim().is_empty() {
            return;
        }
        assert!(t.elapsed() < limit, "job {job} still queued after {limit:?}");
        std::thread::sleep(Duration::from_millis(250));
    }
}

/// A submitted job, cancelled when dropped (a failing test leaves no job running).
struct Job(String);

impl Drop for Job {
    fn drop(&mut self) {
        let _ = Command::new("scancel").arg(&self.0).status();
    }
}

/// The job id `glissade submit` printed.
fn job_of(said: &str) -> String {
    said.lines()
        .find_map(|l| l.strip_prefix("submitted Slurm job "))
        .and_then(|l| l.split(':').next())
        .unwrap_or_else(|| panic!("no job id in: {said}"))
        .to_string()
}

/// `glissade run --slurm` under `salloc` on two nodes: converged, its node processes said to be
/// job steps over both, the recording finished, and the fields the in-process run's bit for bit
/// (as local processes are). Outside an allocation `--slurm` is refused, naming what to do, and
/// inside one so is a loopback `--listen`.
#[test]
fn a_run_inside_an_allocation_starts_its_nodes_as_job_steps_and_is_the_in_process_run() {
    if !slurm_ready() {
        return;
    }
    let dir = scratch("slurm-salloc");
    let scene = scene_file(&dir, "small-three-layer");
    let expected = in_process_fields(&scene, &dir);
    let out = dir.join("slurm");
    let run = Command::new("salloc")
        .args([
            "--nodes=2",
            "--ntasks-per-node=1",
            "--overcommit",
            "--time=10",
            "--job-name=glissade-test",
        ])
        .arg(env!("CARGO_BIN_EXE_glissade"))
        .args(["run"])
        .arg(&scene)
        .args(["--slurm", "--quiet", "--run-id", "salloc-run", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let said = format!(
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success() && said.contains("Converged"), "{said}");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(output_file(&out, ".summary.json")).unwrap()).unwrap();
    let nodes = summary["nodes"].to_string();
    assert!(
        nodes.contains("started as job steps of Slurm job") && nodes.contains(" on n1, n2"),
        "{nodes}"
    );
    assert_eq!(std::fs::read(output_file(&out, ".fields.json")).unwrap(), expected);
    assert!(finalised(&output_file(&out, ".mcap")));

    let outside = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(["run"])
        .arg(&scene)
        .args(["--slurm", "--quiet", "--out"])
        .arg(dir.join("outside"))
        .env_remove("SLURM_JOB_ID")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&outside.stderr);
    assert_eq!(outside.status.code(), Some(2), "{err}");
    assert!(
        err.contains("not inside a Slurm allocation") && err.contains("glissade submit"),
        "{err}"
    );

    // Inside one, a loopback --listen is refused: the other hosts' steps could not reach it.
    let loopback = Command::new("salloc")
        .args(["--nodes=2", "--ntasks-per-node=1", "--overcommit", "--time=5"])
        .arg(env!("CARGO_BIN_EXE_glissade"))
        .args(["run"])
        .arg(&scene)
        .args(["--slurm", "--quiet", "--listen", "tcp/127.0.0.1:17447", "--out"])
        .arg(dir.join("loopback"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&loopback.stderr);
    assert_eq!(loopback.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--listen: tcp/127.0.0.1:17447 is this host's loopback"),
        "{err}"
    );
}

/// `glissade submit` writes its batch script beside the outputs and submits it: the job's run
/// converges to the in-process numbers. A second, endless job on two nodes runs its node
/// processes as job steps of the job over both; `scancel` ends it as Interrupted, with the
/// summary written, the recording finished (it opens in `glissade replay`) and no process of the
/// run left.
#[test]
fn a_submitted_run_is_the_in_process_run_and_scancel_interrupts_one() {
    if !slurm_ready() {
        return;
    }
    let dir = scratch("slurm-submit");
    let scene = scene_file(&dir, "small-three-layer");
    let expected = in_process_fields(&scene, &dir);
    let out = dir.join("job");
    let exe = env!("CARGO_BIN_EXE_glissade");
    let said = glissade_ok(&[
        &"submit",
        &scene,
        &"--out",
        &out,
        &"--time",
        &"10",
        &"--run-id",
        &"batch-run",
    ]);
    let job = job_of(&said);
    let _cancel = Job(job.clone());
    let script = std::fs::read_to_string(out.join("small-three-layer-batch-run.sbatch")).unwrap();
    assert!(
        script.contains(" run ") && script.contains("--slurm") && script.contains("#SBATCH --time=10"),
        "{script}"
    );
    wait_gone(&job, Duration::from_secs(300));
    let console = std::fs::read_to_string(out.join(format!("small-three-layer-batch-run.slurm-{job}.out"))).unwrap();
    assert!(console.contains("Converged"), "{console}");
    assert_eq!(
        std::fs::read(output_file(&out, ".fields.json")).unwrap(),
        expected,
        "{console}"
    );

    // An endless run (no stop but the cap), cancelled mid-run.
    let text = std::fs::read_to_string(&scene).unwrap().replace(
        "accuracy = 1e-3\n",
        "tolerance = 1e-300\nmax_iterations = 1000000\nstagnation_window = 1000000\n",
    );
    let endless = dir.join("endless.toml");
    std::fs::write(&endless, text).unwrap();
    let run_id = format!("cancelled-{}", std::process::id());
    let out = dir.join("cancelled");
    let said = Command::new(exe)
        .args(["submit"])
        .arg(&endless)
        .args(["--nodes", "2", "--time", "10", "--run-id", &run_id, "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let job = job_of(&String::from_utf8_lossy(&said.stdout));
    let _cancel_too = Job(job.clone());
    let t = Instant::now();
    let nodes = loop {
        // The node processes themselves (not the `srun` that started each, nor the recorder,
        // which runs beside the launcher); small-three-layer's interface node runs in the
        // launcher's process.
        let nodes: Vec<i32> = ["subdomain", "coarse"]
            .iter()
            .flat_map(|role| processes_with(&run_id, &["node", role]))
            .filter(|p| std::fs::read_to_string(format!("/proc/{p}/comm")).is_ok_and(|c| c.trim() == "glissade"))
            .collect();
        if nodes.len() >= 2 {
            break nodes;
        }
        assert!(
            t.elapsed() < Duration::from_secs(180),
            "the job's node processes did not start"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    // Steps of the job, over both of its nodes.
    let on: std::collections::BTreeSet<String> = nodes
        .iter()
        .map(|&p| step_of(p, &job).unwrap_or_else(|| panic!("process {p} is not a step of job {job}")))
        .collect();
    assert_eq!(on.into_iter().collect::<Vec<_>>(), ["n1", "n2"]);
    std::thread::sleep(Duration::from_secs(2));
    assert!(Command::new("scancel").arg(&job).status().unwrap().success());
    wait_gone(&job, Duration::from_secs(120));
    let console = std::fs::read_to_string(output_file(&out, &format!(".slurm-{job}.out"))).unwrap();
    assert!(console.contains("interrupted after"), "{console}");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(output_file(&out, ".summary.json")).unwrap()).unwrap();
    assert_eq!(summary["interrupted"], serde_json::json!(true), "{console}");
    // The launcher's exit code, as Slurm kept it: 130, as after Ctrl-C.
    let shown = Command::new("scontrol").args(["show", "job", &job]).output().unwrap();
    let shown = String::from_utf8_lossy(&shown.stdout);
    assert!(
        shown.contains("JobState=CANCELLED") && shown.contains("ExitCode=130:0"),
        "{shown}"
    );
    assert!(summary["iterations"].as_u64().unwrap() > 0, "{summary}");
    let mcap = output_file(&out, ".mcap");
    assert!(finalised(&mcap), "{console}");
    // The cancelled run's recording opens in the replay.
    let rrd = dir.join("cancelled.rrd");
    glissade_ok(&[&"replay", &"--save", &rrd, &mcap]);
    assert!(std::fs::metadata(&rrd).is_ok_and(|m| m.len() > 0));
    assert!(
        processes_with(&run_id, &[]).is_empty(),
        "processes of run {run_id} remain"
    );
}

/// A node process that dies in a job ends the run naming it, as a local one does: an endless
/// submitted run without restarts, its subdomain process 1 (a job step) killed with SIGKILL.
#[test]
fn a_node_step_that_dies_ends_the_run_naming_it() {
    if !slurm_ready() {
        return;
    }
    let dir = scratch("slurm-node-death");
    let scene = scene_file(&dir, "small-three-layer");
    let text = std::fs::read_to_string(&scene).unwrap();
    assert!(text.contains("accuracy = 1e-3\n") && text.contains("\n[deployment]\n"));
    let text = text
        .replace(
            "accuracy = 1e-3\n",
            "tolerance = 1e-300\nmax_iterations = 1000000\nstagnation_window = 1000000\n",
        )
        .replace("\n[deployment]\n", "\n[deployment]\nrestarts = 0\n");
    let endless = dir.join("endless.toml");
    std::fs::write(&endless, text).unwrap();
    let run_id = format!("node-death-{}", std::process::id());
    let out = dir.join("out");
    let said = glissade_ok(&[
        &"submit",
        &endless,
        &"--time",
        &"10",
        &"--run-id",
        &run_id,
        &"--out",
        &out,
    ]);
    let job = job_of(&said);
    let _cancel = Job(job.clone());
    let t = Instant::now();
    let victim = loop {
        let found: Vec<i32> = processes_with(&run_id, &["node", "subdomain", "--index", "1"])
            .into_iter()
            .filter(|p| std::fs::read_to_string(format!("/proc/{p}/comm")).is_ok_and(|c| c.trim() == "glissade"))
            .collect();
        if let [p] = found[..] {
            break p;
        }
        assert!(
            t.elapsed() < Duration::from_secs(180),
            "subdomain process 1 did not start"
        );
        std::thread::sleep(Duration::from_millis(200));
    };
    assert!(
        step_of(victim, &job).is_some(),
        "subdomain process 1 is not a step of job {job}"
    );
    std::thread::sleep(Duration::from_secs(2));
    // SAFETY: a plain kill(2) of a process this test found by its command line.
    assert_eq!(unsafe { libc::kill(victim, libc::SIGKILL) }, 0);
    wait_gone(&job, Duration::from_secs(120));
    let console = std::fs::read_to_string(output_file(&out, &format!(".slurm-{job}.out"))).unwrap();
    let error = console
        .lines()
        .find(|l| l.starts_with("error:"))
        .unwrap_or_else(|| panic!("no error line in:\n{console}"));
    assert!(error.contains("node subdomain:1 failed"), "{error}");
    assert!(
        processes_with(&run_id, &[]).is_empty(),
        "processes of run {run_id} remain"
    );
}

/// What would break the batch script is refused before anything is written or submitted (no
/// cluster needed): a `--time` or `--partition` that would add lines to it, an output folder
/// whose path `#SBATCH --output` cannot take.
#[test]
fn submit_refuses_what_would_break_its_batch_script() {
    let dir = scratch("slurm-submit-refusals");
    let scene = scene_file(&dir, "small-three-layer");
    for (args, said) in [
        (
            vec!["--time", "10\n#SBATCH --wrap=x", "--out", "a"],
            "--time `10\n#SBATCH --wrap=x`: only letters, digits",
        ),
        (
            vec!["--partition", "main debug", "--out", "b"],
            "--partition `main debug`: only",
        ),
        (vec!["--out", "with space"], "takes no space, control character or `%`"),
        (vec!["--out", "100%"], "takes no space, control character or `%`"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_glissade"))
            .current_dir(&*dir)
            .arg("submit")
            .arg(&scene)
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(said), "{args:?}: {err}");
        let folder = args[args.iter().position(|a| *a == "--out").unwrap() + 1];
        assert!(!dir.join(folder).exists(), "{args:?}: {folder} was created");
    }
}
