//! Recordings (MCAP): what the recorder writes is every message of the run, byte for byte, read
//! back by the project's reader and by an independent one (the Python `mcap` package); the
//! multi-process recorder records the same messages as the in-process one; a recorder killed with
//! SIGKILL leaves every chunk it wrote readable.

use crate::common::{scene, scene_text, scratch, Scratch};
use glissade::run::Run;
use glissade::runner::RunOptions;
use glissade_recorder::Recording;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A fresh empty folder under the system's temporary folder, removed when dropped.
fn temp_dir(tag: &str) -> Scratch {
    scratch(&format!("recording-{tag}"))
}

/// (topic, wire bytes) of every message of an in-process run, in publication order.
fn bus_messages(text: &str, run_id: &str) -> Messages {
    let sc = scene(text);
    let mut out = Vec::new();
    Run::new(&sc, &RunOptions::new(run_id))
        .observe(|m| {
            out.push((m.topic(), glissade_messages::encode(m)));
            Duration::ZERO
        })
        .in_process()
        .map(|o| o.result)
        .unwrap();
    out
}

/// Messages per topic, in order.
pub(crate) fn by_topic(messages: impl IntoIterator<Item = (String, Vec<u8>)>) -> BTreeMap<String, Vec<Vec<u8>>> {
    let mut map: BTreeMap<String, Vec<Vec<u8>>> = BTreeMap::new();
    for (t, b) in messages {
        map.entry(t).or_default().push(b);
    }
    map
}

pub(crate) fn read_back(path: &Path) -> (Recording, Messages) {
    let r = Recording::open(path).unwrap();
    let msgs = r
        .messages()
        .map(|m| (m.topic.to_string(), m.data.into_owned()))
        .collect();
    (r, msgs)
}

/// (topic, wire bytes) of messages in order.
pub(crate) type Messages = Vec<(String, Vec<u8>)>;

/// Reads a recording with the Python `mcap` package; None (with the reason printed) when Python
/// or the package is missing. Returns (topic, bytes) in file order and the summary's per-topic counts.
pub(crate) fn python_read(path: &Path) -> Option<(Messages, BTreeMap<String, u64>)> {
    const SCRIPT: &str = r#"
import sys, struct
from mcap.reader import make_reader
out = open(sys.argv[2], "wb")
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    summary = reader.get_summary()
    counts = summary.statistics.channel_message_counts
    for cid, ch in summary.channels.items():
        t = ch.topic.encode()
        out.write(b"C" + struct.pack("<H", len(t)) + t + struct.pack("<Q", counts.get(cid, 0)))
    for schema, channel, message in reader.iter_messages(log_time_order=False):
        t = channel.topic.encode()
        out.write(b"M" + struct.pack("<H", len(t)) + t + struct.pack("<Q", len(message.data)) + message.data)
out.close()
"#;
    let python = crate::common::python_with(&["mcap"])?;
    let dump = path.with_extension("python-dump");
    let o = Command::new(python)
        .args(["-c", SCRIPT])
        .arg(path)
        .arg(&dump)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "python mcap reader failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let bytes = std::fs::read(&dump).unwrap();
    let (mut messages, mut counts, mut k) = (Vec::new(), BTreeMap::new(), 0);
    let u16_at = |k: usize| u16::from_le_bytes([bytes[k], bytes[k + 1]]) as usize;
    let u64_at = |k: usize| u64::from_le_bytes(bytes[k..k + 8].try_into().unwrap());
    while k < bytes.len() {
        let tag = bytes[k];
        let tl = u16_at(k + 1);
        let topic = String::from_utf8(bytes[k + 3..k + 3 + tl].to_vec()).unwrap();
        let n = u64_at(k + 3 + tl);
        k += 3 + tl + 8;
        if tag == b'C' {
            counts.insert(topic, n);
        } else {
            messages.push((topic, bytes[k..k + n as usize].to_vec()));
            k += n as usize;
        }
    }
    Some((messages, counts))
}

/// An in-process run's recording holds every message of the bus with its topic, in order,
/// byte for byte: read back by our reader and by the Python `mcap` package.
#[test]
fn in_process_recording_reads_back_with_both_readers() {
    let text = scene_text("small-three-layer");
    let sc = scene(&text);
    let dir = temp_dir("in-process");
    let path = dir.join("small.mcap");
    let opts = RunOptions::new("rec-1");
    let (result, outcome) = Run::new(&sc, &opts)
        .recorded(Some(&path))
        .in_process()
        .map(|o| (o.result, o.recording))
        .unwrap();
    let stats = outcome.unwrap().stats.unwrap();
    let bus = bus_messages(&text, "rec-1");
    assert!(result.iterations.len() > 5, "{} iterations", result.iterations.len());
    assert_eq!(stats.messages, bus.len() as u64);

    let (r, ours) = read_back(&path);
    assert!(r.is_finished() && r.truncated().is_none());
    assert_eq!(r.scene_text(), Some(text.as_str()));
    assert_eq!(r.metadata()["scene"], "small-three-layer");
    assert!(r.metadata()["software"].starts_with("glissade "));
    assert_eq!(ours, bus, "our reader: every message, in order, byte for byte");
    let topics = by_topic(bus.clone());
    assert_eq!(r.channels().len(), topics.len(), "one channel per key expression");
    for c in r.channels() {
        assert_eq!(c.messages, topics[&c.topic].len() as u64, "{}", c.topic);
        assert!(c.schema_name.starts_with("glissade."), "{}", c.schema_name);
        assert_eq!(c.message_encoding, "bincode2");
    }
    for m in r.messages() {
        r.decode(&m).unwrap();
    }

    if let Some((theirs, counts)) = python_read(&path) {
        assert_eq!(theirs, bus, "the Python reader: every message, in order, byte for byte");
        let expected: BTreeMap<String, u64> = topics.iter().map(|(t, v)| (t.clone(), v.len() as u64)).collect();
        assert_eq!(counts, expected, "per-channel counts of the summary section");
        println!(
            "the Python mcap reader read {} messages on {} channels",
            theirs.len(),
            counts.len()
        );
    }
}

/// Recording off: no file; topic restriction: only the selected channels; an unwritable folder:
/// an error naming the path, before anything is solved.
#[test]
fn recording_off_restricted_and_unwritable() {
    let dir = temp_dir("options");
    let text = scene_text("small-three-layer");
    let opts = RunOptions::new("rec-2");
    let off = scene(&format!("{text}\n[recording]\nenabled = false\n"));
    assert_eq!(glissade::recording::recording_path(&off, "rec-2", &dir), None);

    let only = scene(&format!(
        "{text}\n[recording]\ntopics = [\"interface/*/decision\", \"interface/*/interface_solution\"]\n"
    ));
    let path = glissade::recording::recording_path(&only, "rec-2", &dir).unwrap();
    assert_eq!(path, dir.join("small-three-layer-rec-2.mcap"));
    let (result, _) = Run::new(&only, &opts)
        .recorded(Some(&path))
        .in_process()
        .map(|o| (o.result, o.recording))
        .unwrap();
    let (r, msgs) = read_back(&path);
    let topics: Vec<&str> = r.channels().iter().map(|c| c.topic.as_str()).collect();
    assert_eq!(
        topics,
        [
            "glissade/rec-2/interface/0/decision",
            "glissade/rec-2/interface/0/interface_solution"
        ]
    );
    assert_eq!(r.channels()[0].messages, result.iterations.len() as u64);
    assert_eq!(r.channels()[1].messages, only.model.interfaces.len() as u64);
    assert_eq!(msgs.len(), result.iterations.len() + only.model.interfaces.len());

    let blocker = dir.join("a-file");
    std::fs::write(&blocker, b"x").unwrap();
    let bad = blocker.join("sub").join("r.mcap");
    let mut solved = false;
    let e = Run::new(&only, &opts)
        .recorded(Some(&bad))
        .on_iteration(|_| solved = true)
        .in_process()
        .map(|o| (o.result, o.recording))
        .unwrap_err();
    assert!(format!("{e:#}").contains(&bad.display().to_string()), "{e:#}");
    assert!(!solved, "the error comes before any iteration");
}

/// Runs `glissade run` as processes with recording into `dir`; returns the child.
fn spawn_run(scene_path: &Path, dir: &Path, run_id: &str) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_glissade"))
        // --verbose: the recorder's notes (its pid) are shown.
        .args(["run", "--quiet", "--verbose", "--run-id", run_id, "--out"])
        .arg(dir)
        .arg(scene_path)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits for a child with a bound; kills it on timeout.
fn wait_bounded(child: &mut std::process::Child, timeout: Duration) -> std::process::ExitStatus {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the run did not end within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The recorder process of a multi-process run records exactly the messages of the in-process
/// run (per channel, in order, byte for byte: the runs are bit-identical).
#[test]
fn multi_process_recording_matches_in_process() {
    let dir = temp_dir("multi");
    let text = scene_text("small-three-layer");
    let scene_path = dir.join("small-three-layer.toml");
    std::fs::write(&scene_path, &text).unwrap();
    let mut child = spawn_run(&scene_path, &dir, "rec-3");
    let status = wait_bounded(&mut child, Duration::from_secs(300));
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(status.success(), "{status}: {err}");
    let (r, msgs) = read_back(&dir.join("small-three-layer-rec-3.mcap"));
    assert!(r.is_finished(), "{err}");
    assert_eq!(by_topic(msgs), by_topic(bus_messages(&text, "rec-3")));
}

/// A folder `tag` holding `long.toml`: the small three-layer scene run to 400 iterations, long
/// enough for a signal to land mid-run. Returns (folder, scene path, scene text).
fn long_run_scene(tag: &str) -> (Scratch, PathBuf, String) {
    let dir = temp_dir(tag);
    let text = scene_text("small-three-layer").replace(
        "accuracy = 1e-3",
        "tolerance = 1e-300\nmax_iterations = 400\nstagnation_window = 1000",
    );
    let scene_path = dir.join("long.toml");
    std::fs::write(&scene_path, &text).unwrap();
    (dir, scene_path, text)
}

/// SIGKILL of the recorder process mid-run: the run goes on and says what happened; the file
/// holds every chunk written before the kill (at least everything a copy taken just before the
/// kill holds), and what it holds is the run's messages, per channel a prefix of the full run's.
/// Python `mcap`'s `make_reader` reads it (from its footer) and yields exactly the same messages,
/// and its summary's statistics count them.
#[test]
fn recording_survives_sigkill_of_the_recorder() {
    let (dir, scene_path, text) = long_run_scene("sigkill");
    let mut child = spawn_run(&scene_path, &dir, "rec-4");
    let path = dir.join("small-three-layer-rec-4.mcap");
    // The recorder announces its pid; forward the rest of stderr to a buffer.
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let deadline = Instant::now() + Duration::from_secs(300);
    let mut pid = None;
    let mut log = Vec::new();
    while pid.is_none() && Instant::now() < deadline {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) {
            if let Some(rest) = line.split("(pid ").nth(1) {
                pid = rest.trim_end_matches(')').parse::<i32>().ok();
            }
            log.push(line);
        }
    }
    let pid = pid.unwrap_or_else(|| panic!("the recorder did not announce itself: {log:?}"));
    // Wait until a few chunks are on disk, copy the file, kill.
    let before = loop {
        assert!(Instant::now() < deadline, "the recording did not grow: {log:?}");
        let n = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        if n > 200_000 {
            break std::fs::read(&path).unwrap();
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    // SAFETY: kill(2) of the recorder process this test's child started.
    let killed = unsafe { libc::kill(pid, libc::SIGKILL) };
    assert_eq!(killed, 0);
    let status = wait_bounded(&mut child, Duration::from_secs(300));
    while let Ok(line) = rx.recv_timeout(Duration::from_millis(200)) {
        log.push(line);
    }
    let mut out = String::new();
    std::io::Read::read_to_string(child.stdout.as_mut().unwrap(), &mut out).unwrap();
    assert_eq!(
        status.code(),
        Some(3),
        "max iterations, not a failure of the run: {log:?}"
    );
    assert!(
        out.contains("left out: recording: the recorder process failed"),
        "{out}"
    );

    let snapshot = Recording::from_bytes(&path, before).unwrap();
    let n_before = snapshot.messages().count();
    let (r, msgs) = read_back(&path);
    assert!(!r.is_finished());
    assert!(msgs.len() >= n_before && n_before > 0, "{} < {n_before}", msgs.len());
    let full = by_topic(bus_messages(&text, "rec-4"));
    let total: usize = full.values().map(Vec::len).sum();
    assert!(
        msgs.len() < total,
        "the kill landed after the run: {} of {total}",
        msgs.len()
    );
    assert!(
        r.truncated().is_some_and(|t| t.starts_with("not finalised")),
        "{:?}",
        r.truncated()
    );
    let ours = by_topic(msgs);
    for (topic, list) in &ours {
        assert_eq!(list[..], full[topic][..list.len()], "{topic}");
    }
    if let Some((theirs, mut counts)) = python_read(&path) {
        assert_eq!(by_topic(theirs), ours, "the Python reader reads other messages");
        // The summary lists every channel created so far, some with no message in its chunks.
        counts.retain(|_, n| *n > 0);
        let our_counts: BTreeMap<String, u64> = ours.iter().map(|(t, l)| (t.clone(), l.len() as u64)).collect();
        assert_eq!(counts, our_counts, "summary statistics of the Python reader");
    }
}

/// SIGTERM to the launcher mid-run: every node stops, the launcher exits 130, and the recording is
/// finalised (summary section written): the project's reader and the Python `mcap` package both
/// open it, agree per channel on counts and bytes, and what it holds is a prefix of the run.
#[test]
fn sigterm_leaves_a_finalised_recording_both_readers_open() {
    let (dir, scene_path, text) = long_run_scene("sigterm");
    let mut child = spawn_run(&scene_path, &dir, "rec-5");
    let path = dir.join("small-three-layer-rec-5.mcap");
    let deadline = Instant::now() + Duration::from_secs(300);
    while std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0) < 200_000 {
        assert!(Instant::now() < deadline, "the recording did not grow");
        assert!(child.try_wait().unwrap().is_none(), "the run ended before the signal");
        std::thread::sleep(Duration::from_millis(5));
    }
    // SAFETY: kill(2) of the launcher this test started.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let status = wait_bounded(&mut child, Duration::from_secs(60));
    let mut err = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(130), "interrupted: {err}");

    let (r, msgs) = read_back(&path);
    assert!(r.is_finished(), "no summary section after SIGTERM: {err}");
    let full = by_topic(bus_messages(&text, "rec-5"));
    let total: usize = full.values().map(Vec::len).sum();
    assert!(
        msgs.len() < total,
        "the signal landed after the run: {} of {total}",
        msgs.len()
    );
    let ours = by_topic(msgs);
    for (topic, list) in &ours {
        assert_eq!(list[..], full[topic][..list.len()], "{topic}");
    }
    if let Some((theirs, counts)) = python_read(&path) {
        assert_eq!(by_topic(theirs), ours, "the Python reader reads other messages");
        let our_counts: BTreeMap<String, u64> = ours.iter().map(|(t, l)| (t.clone(), l.len() as u64)).collect();
        assert_eq!(counts, our_counts, "summary statistics of the Python reader");
    }
}

/// A full disk (the recording file on `/dev/full`, where every write fails with ENOSPC): both an
/// in-process and a multi-process run fail before solving, exit 2, name the recording's path and
/// the cause, and write no summary or fields file.
#[test]
fn a_full_disk_fails_the_run_before_solving() {
    if !Path::new("/dev/full").exists() {
        println!("skipped: no /dev/full on this system");
        return;
    }
    let dir = temp_dir("disk-full");
    let scene_path = dir.join("small-three-layer.toml");
    std::fs::write(&scene_path, scene_text("small-three-layer")).unwrap();
    for (run_id, in_process) in [("full-1", true), ("full-2", false)] {
        let file = dir.join(format!("small-three-layer-{run_id}.mcap"));
        std::os::unix::fs::symlink("/dev/full", &file).unwrap();
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_glissade"));
        // --verbose: a run that started would say `iterating`.
        cmd.args(["run", "--quiet", "--verbose", "--run-id", run_id, "--out"])
            .arg(&dir);
        if in_process {
            cmd.arg("--in-process");
        }
        let out = cmd.arg(&scene_path).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        // The launcher's error (its last lines: the recorder's own error, multi-process).
        let error = stderr
            .find("\nerror:")
            .or(stderr.starts_with("error:").then_some(0))
            .map_or("", |i| &stderr[i..]);
        assert!(
            error.contains(&file.display().to_string()) && stderr.contains("no space left on device"),
            "in-process {in_process}: {stderr}"
        );
        assert!(!stderr.contains("iterating"), "the run started: {stderr}");
        let written: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(run_id) && !n.ends_with(".mcap"))
            .collect();
        assert!(written.is_empty(), "outputs written: {written:?}");
    }
}

/// What a run records by default is what debugging a run needs: every small message, and on a
/// scene with more than 1 MB of full fields per iteration (32 subdomains, N = 50: 5.3 MB) full
/// fields every 20th iteration and the final interface solutions. The default recording is then
/// at most a tenth of the complete one (`--record full`: 5.3 MB at every iteration; the sizes
/// measured are in docs/recording.md); the start line says what will be recorded, `--no-record`
/// writes none.
#[test]
fn the_default_recording_of_a_large_scene_is_a_tenth_of_a_complete_one() {
    let dir = temp_dir("defaults");
    let scene = format!("{}/tests/fixtures/thirty-two-blocks.toml", env!("CARGO_MANIFEST_DIR"));
    let run = |run_id: &str, extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args(["run", "--in-process", "--quiet", "--run-id", run_id, "--out"])
            .arg(&dir)
            .arg(&scene)
            .args(extra)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
        stdout
    };
    let said = run("default", &[]);
    assert!(
        said.contains("full fields every 20th iteration (--record full: all)"),
        "{said}"
    );
    run("full", &["--record", "full"]);
    let size = |id: &str| {
        std::fs::metadata(dir.join(format!("thirty-two-blocks-{id}.mcap")))
            .unwrap()
            .len()
    };
    let (default, full) = (size("default"), size("full"));
    assert!(10 * default <= full, "default {default} bytes, complete {full} bytes");
    let said = run("none", &["--no-record"]);
    assert!(!said.contains(".mcap"), "{said}");
    assert!(!dir.join("thirty-two-blocks-none.mcap").exists());
}
