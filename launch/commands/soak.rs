//! `glissade soak`: many runs of one scene as processes, in a row or several at once, beside
//! busy loops that keep the machine's cores loaded, each checked against the scene's in-process
//! run: converged to the same bits, set going again after a stall, ended by a stall's diagnosis,
//! failed, or hung (killed at the time limit). Writes `soak.json` and exits non-zero unless every
//! run converged to the in-process run's numbers.

use super::*;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What `glissade soak` was asked.
pub(crate) struct SoakArgs {
    pub scene: PathBuf,
    pub out: PathBuf,
    pub runs: u32,
    pub parallel: u32,
    pub busy: u32,
    pub timeout: Duration,
    pub no_record: bool,
}

/// How one run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
enum Outcome {
    /// Converged to the in-process run's interface fields, bit for bit.
    Same,
    /// Ended (exit 0 or 3) with other fields or another verdict.
    Different,
    /// Ended by the launcher's stall diagnosis.
    Stalled,
    /// Failed otherwise.
    Failed,
    /// Still running at the time limit: killed.
    Hung,
}

#[derive(Debug, Clone, serde::Serialize)]
struct RunRecord {
    run: u32,
    outcome: Outcome,
    seconds: f64,
    /// Stalls the launcher recovered from in this run.
    recovered_stalls: usize,
    /// The run's last console lines when it did not converge to the same numbers, or its
    /// warnings about the stalls it recovered from.
    #[serde(skip_serializing_if = "Option::is_none")]
    said: Option<String>,
}

/// Spins on one core until told to stop.
fn busy_loops(n: u32, stop: &Arc<AtomicBool>) -> Vec<std::thread::JoinHandle<()>> {
    (0..n)
        .map(|_| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut x = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
                }
            })
        })
        .collect()
}

fn child(exe: &Path, scene: &Path, out: &Path, extra: &[&str], log: &Path) -> anyhow::Result<Child> {
    let log = std::fs::File::create(log).with_context(|| format!("cannot create {}", log.display()))?;
    Command::new(exe)
        .arg("run")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .args(extra)
        .stdout(log.try_clone()?)
        .stderr(log)
        .stdin(Stdio::null())
        .spawn()
        .with_context(|| format!("cannot start {}", exe.display()))
}

/// Waits for `c` up to `timeout`; None when it is still running then (it is killed).
fn wait(c: &mut Child, timeout: Duration) -> anyhow::Result<Option<std::process::ExitStatus>> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(status) = c.try_wait()? {
            return Ok(Some(status));
        }
        if Instant::now() >= deadline {
            // SIGINT first: the launcher stops its nodes and finalises what it wrote.
            // SAFETY: kill(2) on the pid of our own child.
            unsafe { libc::kill(c.id() as libc::pid_t, libc::SIGINT) };
            std::thread::sleep(Duration::from_secs(10));
            let _ = c.kill();
            let _ = c.wait();
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The one file in `dir` whose name ends with `suffix`.
fn file_ending(dir: &Path, suffix: &str) -> Option<PathBuf> {
    std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.to_string_lossy().ends_with(suffix))
}

/// Writes `soak.json` (the counts of each outcome, the run times, every run's record) and prints
/// the counts.
fn write_summary(args: &SoakArgs, records: &[RunRecord], wall_s: f64, soak_json: &Path) -> anyhow::Result<()> {
    let count = |o: Outcome| records.iter().filter(|r| r.outcome == o).count();
    let mut seconds: Vec<f64> = records.iter().map(|r| r.seconds).collect();
    seconds.sort_by(f64::total_cmp);
    let median = seconds.get(seconds.len() / 2).copied().unwrap_or(0.0);
    let max = seconds.last().copied().unwrap_or(0.0);
    let recovered: usize = records.iter().map(|r| r.recovered_stalls).sum();
    let runs_recovered = records.iter().filter(|r| r.recovered_stalls > 0).count();
    let summary = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "runs": records.len(),
        "parallel": args.parallel,
        "busy_loops": args.busy,
        "cores": std::thread::available_parallelism().map_or(0, |n| n.get()),
        "recorded": !args.no_record,
        "same_as_in_process": count(Outcome::Same),
        "different": count(Outcome::Different),
        "ended_by_a_stall": count(Outcome::Stalled),
        "failed": count(Outcome::Failed),
        "hung": count(Outcome::Hung),
        "stalls_recovered": recovered,
        "runs_with_a_stall_recovered": runs_recovered,
        "median_s": median,
        "max_s": max,
        "wall_s": wall_s,
        "runs_detail": records,
    });
    write_json_new(&args.out, "soak.json", &summary)?;
    println!(
        "soak: {} of {} runs converged to the in-process run's numbers; {} different, {} ended by a stall, {} failed, \
         {} hung; {recovered} stall(s) recovered in {runs_recovered} run(s); median {median:.1} s, longest {max:.1} s \
         ({})",
        count(Outcome::Same),
        records.len(),
        count(Outcome::Different),
        count(Outcome::Stalled),
        count(Outcome::Failed),
        count(Outcome::Hung),
        soak_json.display()
    );
    Ok(())
}

/// Run `k` of the soak as processes, its outcome against the in-process run's fields
/// `expected`; its outputs and log removed where it agrees (the log kept where it recovered from a
/// stall).
fn one_run(exe: &Path, args: &SoakArgs, k: u32, expected: &[u8], extra: &[&str]) -> anyhow::Result<RunRecord> {
    let out = args.out.join(format!("run-{k}"));
    let log = args.out.join(format!("run-{k}.log"));
    let started = Instant::now();
    let mut c = child(exe, &args.scene, &out, extra, &log)?;
    let status = wait(&mut c, args.timeout)?;
    let seconds = started.elapsed().as_secs_f64();
    let said = std::fs::read_to_string(&log).unwrap_or_default();
    let recovered_stalls = said.matches("stopped moving and was set going again").count();
    let same = file_ending(&out, ".fields.json")
        .and_then(|f| std::fs::read(f).ok())
        .is_some_and(|f| f == expected);
    let outcome = match status {
        None => Outcome::Hung,
        Some(s) if s.success() && same => Outcome::Same,
        Some(s) if s.success() || s.code() == Some(NOT_CONVERGED.into()) => Outcome::Different,
        Some(_) if said.contains("the run stopped moving") => Outcome::Stalled,
        Some(_) => Outcome::Failed,
    };
    let keep = outcome != Outcome::Same;
    if !keep {
        // The outputs agree: only the log of a run that recovered from a stall
        // is kept.
        let _ = std::fs::remove_dir_all(&out);
        if recovered_stalls == 0 {
            let _ = std::fs::remove_file(&log);
        }
    }
    let tail: Vec<&str> = said.lines().rev().take(8).collect();
    let warnings = said
        .lines()
        .filter(|l| l.contains("stopped moving and was set going again"))
        .collect::<Vec<_>>()
        .join("\n");
    let record = RunRecord {
        run: k,
        outcome,
        seconds,
        recovered_stalls,
        said: if keep {
            Some(tail.into_iter().rev().collect::<Vec<_>>().join("\n"))
        } else {
            (recovered_stalls > 0).then_some(warnings)
        },
    };
    println!(
        "run {k}: {:?} in {seconds:.1} s{}",
        record.outcome,
        if recovered_stalls > 0 {
            format!(" ({recovered_stalls} stall(s) recovered)")
        } else {
            String::new()
        }
    );
    Ok(record)
}

pub(crate) fn soak(args: SoakArgs) -> anyhow::Result<ExitCode> {
    let exe = std::env::current_exe().context("cannot find this program's path")?;
    ensure_not_a_file(&args.out)?;
    load_scene(&args.scene)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let soak_json = args.out.join("soak.json");
    if soak_json.exists() {
        anyhow::bail!("{} exists: give another --out", soak_json.display());
    }
    install_interrupt_handler()?;
    // The in-process run on an idle machine: the numbers every run must reproduce.
    let reference = args.out.join("in-process");
    let mut c = child(
        &exe,
        &args.scene,
        &reference,
        &["--in-process", "--no-record"],
        &args.out.join("in-process.log"),
    )?;
    let status = wait(&mut c, args.timeout)?;
    let fields = file_ending(&reference, ".fields.json")
        .filter(|_| status.is_some_and(|s| s.success()))
        .ok_or_else(|| {
            anyhow::anyhow!(
                "the in-process run did not converge: see {}",
                args.out.join("in-process.log").display()
            )
        })?;
    let expected = std::fs::read(&fields)?;
    println!(
        "soak: {} runs of {} as processes, {} at once, beside {} busy loop(s) (this machine has {} cores), each \
         checked against the in-process run",
        args.runs,
        args.scene.display(),
        args.parallel,
        args.busy,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    let stop = Arc::new(AtomicBool::new(false));
    let loops = busy_loops(args.busy, &stop);
    let next = AtomicUsize::new(0);
    let records = Mutex::new(Vec::new());
    let t0 = Instant::now();
    let extra: Vec<&str> = if args.no_record { vec!["--no-record"] } else { vec![] };
    let result = std::thread::scope(|s| -> anyhow::Result<()> {
        let workers: Vec<_> = (0..args.parallel)
            .map(|_| {
                s.spawn(|| -> anyhow::Result<()> {
                    loop {
                        let k = next.fetch_add(1, Ordering::SeqCst) as u32;
                        if k >= args.runs || glissade::distributed::interrupted() {
                            return Ok(());
                        }
                        let record = one_run(&exe, &args, k, &expected, &extra)?;
                        records.lock().unwrap_or_else(|e| e.into_inner()).push(record);
                    }
                })
            })
            .collect();
        for w in workers {
            w.join().map_err(|_| anyhow::anyhow!("a soak worker panicked"))??;
        }
        Ok(())
    });
    stop.store(true, Ordering::Relaxed);
    for l in loops {
        let _ = l.join();
    }
    result?;
    let mut records = records.into_inner().unwrap_or_else(|e| e.into_inner());
    records.sort_by_key(|r| r.run);
    write_summary(&args, &records, t0.elapsed().as_secs_f64(), &soak_json)?;
    let count = |o: Outcome| records.iter().filter(|r| r.outcome == o).count();
    Ok(
        if count(Outcome::Same) == records.len() && records.len() == args.runs as usize {
            ExitCode::SUCCESS
        } else {
            ExitCode::from(2)
        },
    )
}
