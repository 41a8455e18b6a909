//! A full disk, for real: `glissade run --out` on a small tmpfs mounted in a private mount
//! namespace (`unshare --mount`, as root: the tmpfs exists only for that command and vanishes
//! with it). Sizes are chosen from an unconstrained run's files so that each writer fails first:
//! the recording, the JSON outputs, the ParaView series, the CSV. Every time the run stops at
//! that write with an error naming the file and "no space left on device", says what it kept,
//! leaves no partial file, and what it kept is complete (the recording: a valid MCAP file that
//! glissade and Python `mcap` read alike, up to its last chunk).

use crate::common::{scene_file, scratch};
use crate::recording::{by_topic, python_read, read_back};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const RUN_ID: &str = "disk";
const PAGE: u64 = 4096;

/// Pages a file of `bytes` bytes takes on a tmpfs.
fn pages(bytes: u64) -> u64 {
    bytes.div_ceil(PAGE)
}

/// What a run on a full disk did: its exit code, both streams, and the files it left (copied
/// out of the tmpfs before it vanished), by name.
struct Outcome {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    left: PathBuf,
    files: Vec<String>,
}

/// `glissade run <extra> --run-id disk --out <tmpfs>/out <scene>` with a tmpfs of `pages` pages,
/// its outputs copied to `keep`. Fails the test, saying why, when the tmpfs cannot be mounted
/// (the test needs root and mount namespaces; CI has both).
fn run_on_tmpfs(pages: u64, dir: &Path, tag: &str, scene: &Path, extra: &[&str]) -> Outcome {
    let mount = dir.join(format!("mnt-{tag}"));
    let keep = dir.join(format!("left-{tag}"));
    std::fs::create_dir_all(&mount).unwrap();
    std::fs::create_dir_all(&keep).unwrap();
    const SCRIPT: &str = r#"
mount -t tmpfs -o size="$1"k tmpfs "$2" || { echo "cannot mount a tmpfs on $2" >&2; exit 97; }
shift 2
keep="$1"; out="$2"; shift 2
"$@" --out "$out"
code=$?
cp -a "$out/." "$keep/" 2>/dev/null
exit $code
"#;
    let out_dir = mount.join("out");
    let mut cmd = Command::new("unshare");
    cmd.args(["--mount", "sh", "-c", SCRIPT, "sh"])
        .arg((pages * PAGE / 1024).to_string())
        .arg(&mount)
        .arg(&keep)
        .arg(&out_dir)
        .arg(env!("CARGO_BIN_EXE_glissade"))
        .args(["run", "--quiet", "--run-id", RUN_ID])
        .args(extra)
        .arg(scene);
    let child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run `unshare` (util-linux) for the full-disk test: {e}"));
    let out = wait_output(child, Duration::from_secs(300));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_ne!(
        out.status.code(),
        Some(97),
        "the full-disk test needs a tmpfs in a private mount namespace (root, `unshare --mount`): {stderr}"
    );
    assert!(
        !stderr.contains("unshare failed") && !stderr.contains("unshare: "),
        "the full-disk test needs `unshare --mount` (root): {stderr}"
    );
    let mut files = Vec::new();
    for e in walk(&keep) {
        files.push(e.strip_prefix(&keep).unwrap().to_string_lossy().into_owned());
    }
    files.sort();
    Outcome {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr,
        left: keep,
        files,
    }
}

/// Waits for `child` at most `timeout` (killing it then), with its output.
fn wait_output(mut child: std::process::Child, timeout: Duration) -> std::process::Output {
    let deadline = Instant::now() + timeout;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the run on a full disk did not end within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Every file under `dir` (folders descended), hidden ones included.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.push(p.clone());
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

impl Outcome {
    fn context(&self) -> String {
        format!(
            "exit {:?}\nfiles left: {:?}\nstdout:\n{}\nstderr:\n{}",
            self.code, self.files, self.stdout, self.stderr
        )
    }

    /// Exit 2, an error naming `file` and the full disk; no partial file left.
    fn failed_on(&self, file: &str) {
        let c = self.context();
        assert_eq!(self.code, Some(2), "{c}");
        let error = &self.stderr[self.stderr.find("error:").unwrap_or_else(|| panic!("no error: {c}"))..];
        assert!(error.contains(file), "the error does not name {file}: {c}");
        assert!(error.contains("no space left on device"), "{c}");
        assert!(
            !self.files.iter().any(|f| f.contains("partial")),
            "a partial file is left: {c}"
        );
    }

    fn has(&self, name: &str) -> bool {
        self.files.iter().any(|f| f == name)
    }
}

/// The recording a run on a full disk left: glissade's reader and Python's read the same
/// messages, which are per channel a prefix of the unconstrained run's (all of them when
/// `complete`).
fn check_recording(path: &Path, reference: &BTreeMap<String, Vec<Vec<u8>>>, complete: bool, context: &str) {
    let (r, msgs) = read_back(path);
    let ours = by_topic(msgs);
    let n: usize = ours.values().map(Vec::len).sum();
    let total: usize = reference.values().map(Vec::len).sum();
    assert!(n > 0, "nothing recorded: {context}");
    for (topic, list) in &ours {
        assert_eq!(list[..], reference[topic][..list.len()], "{topic}: {context}");
    }
    if complete {
        assert!(r.is_finished() && n == total, "{n} of {total} messages: {context}");
    } else {
        assert!(!r.is_finished() && n < total, "{n} of {total} messages: {context}");
    }
    if let Some((theirs, _)) = python_read(path) {
        assert_eq!(
            by_topic(theirs),
            ours,
            "the Python reader reads other messages: {context}"
        );
    }
}

#[test]
fn a_full_disk_stops_the_run_at_the_first_failed_write_and_keeps_what_was_written() {
    let dir = scratch("full-disk");
    let scene = scene_file(&dir, "small-three-layer");
    // The files of an unconstrained run (same scene, same run id: same sizes).
    let free = dir.join("free");
    let child = Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args([
            "run",
            "--in-process",
            "--quiet",
            "--vtu",
            "--csv",
            "--run-id",
            RUN_ID,
            "--out",
        ])
        .arg(&free)
        .arg(&scene)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let out = wait_output(child, Duration::from_secs(300));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stem = format!("small-three-layer-{RUN_ID}");
    let size = |name: &str| std::fs::metadata(free.join(name)).unwrap().len();
    let rec = format!("{stem}.mcap");
    let (summary, fields, csv, pvd) = (
        format!("{stem}.summary.json"),
        format!("{stem}.fields.json"),
        format!("{stem}.interfaces.csv"),
        format!("{stem}.pvd"),
    );
    let vtu_pages: u64 = walk(&free.join(format!("{stem}-vtu")))
        .iter()
        .map(|p| pages(std::fs::metadata(p).unwrap().len()))
        .sum();
    let reference = by_topic(read_back(&free.join(&rec)).1);
    let fields_text = std::fs::read(free.join(&fields)).unwrap();
    let (p_rec, p_summary, p_fields) = (pages(size(&rec)), pages(size(&summary)), pages(size(&fields)));
    // The JSON outputs must each take several pages for the cuts below to fall inside them.
    assert!(p_summary >= 2 && p_fields >= 2 && pages(size(&csv)) >= 2 && vtu_pages >= 4);

    let in_process =
        |pages: u64, tag: &str| run_on_tmpfs(pages, &dir, tag, &scene, &["--in-process", "--vtu", "--csv"]);

    // 1. The recording fails first (half its size), in process: the run stops there, exit 2,
    // nothing else written, the recording kept up to its last complete chunk.
    let o = in_process(p_rec / 2, "rec");
    o.failed_on(&rec);
    let c = o.context();
    assert!(
        o.stderr.contains("the run was stopped after") && o.stderr.contains("the file keeps the"),
        "{c}"
    );
    assert_eq!(o.files, std::slice::from_ref(&rec), "{c}");
    check_recording(&o.left.join(&rec), &reference, false, &c);

    // The same as node processes: the recorder process stops at its first failed write, saying
    // so; the run goes on (its results do not depend on the recording) and names it.
    let o = run_on_tmpfs(p_rec / 2, &dir, "rec-processes", &scene, &[]);
    let c = o.context();
    assert!(
        o.stderr.contains("no space left on device") && o.stderr.contains("the file keeps the"),
        "{c}"
    );
    assert!(
        !o.files.iter().any(|f| f.contains("partial")),
        "a partial file is left: {c}"
    );
    check_recording(&o.left.join(&rec), &reference, false, &c);
    // Whatever else the run could write is complete.
    for name in [&summary, &fields] {
        if o.has(name) {
            let text = std::fs::read(o.left.join(name)).unwrap();
            serde_json::from_slice::<serde_json::Value>(&text).unwrap_or_else(|e| panic!("{name}: {e}: {c}"));
        }
    }

    // 2. The fields file fails (one page short): the recording and the summary are kept,
    // complete, and named.
    let o = in_process(p_rec + p_summary + p_fields - 1, "fields");
    o.failed_on(&fields);
    let c = o.context();
    assert!(
        o.stderr.contains("kept, complete:") && o.stderr.contains(&summary),
        "{c}"
    );
    assert_eq!(o.files, [rec.clone(), summary.clone()], "{c}");
    check_recording(&o.left.join(&rec), &reference, true, &c);
    serde_json::from_slice::<serde_json::Value>(&std::fs::read(o.left.join(&summary)).unwrap()).unwrap();

    // 3. The ParaView series fails halfway: nothing of it is kept.
    let before_vtu = p_rec + p_summary + p_fields;
    let o = in_process(before_vtu + vtu_pages / 2, "vtu");
    o.failed_on(&format!("{stem}-vtu/"));
    let c = o.context();
    assert!(
        o.stderr.contains("the ParaView series") && o.stderr.contains(&fields),
        "{c}"
    );
    assert_eq!(o.files, [fields.clone(), rec.clone(), summary.clone()], "{c}");
    assert_eq!(std::fs::read(o.left.join(&fields)).unwrap(), fields_text, "{c}");

    // 4. The CSV fails (one page short): everything before it kept.
    let before_csv = before_vtu + vtu_pages + pages(size(&pvd));
    let o = in_process(before_csv + pages(size(&csv)) - 1, "csv");
    o.failed_on(&csv);
    let c = o.context();
    assert!(o.has(&pvd) && o.has(&fields) && o.has(&summary) && o.has(&rec), "{c}");
    assert!(!o.has(&csv), "{c}");
    assert_eq!(std::fs::read(o.left.join(&fields)).unwrap(), fields_text, "{c}");
}
