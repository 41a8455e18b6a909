use super::*;
use glissade_messages::{
    encode, Decision, Envelope, Field, Message, NodeId, Overrides, Payload, RecordOverride, Role, Verdict,
};
use std::io::BufRead;

const RUN: &str = "r1";

fn run_info() -> RunInfo {
    RunInfo {
        run_id: RUN.into(),
        scene_name: "tiny".into(),
        scene_fingerprint: 0xabcd,
        scene_text: "name = \"tiny\"\n# a scene\n".into(),
        scene_overrides: Overrides {
            accuracy: Some(1e-4),
            max_iterations: Some(7),
            record: Some(RecordOverride::Full),
            ..Overrides::default()
        },
        software: "glissade test".into(),
    }
}

fn msg(iteration: u32, stage: Stage, sender: NodeId, payload: Payload) -> Message {
    Message {
        envelope: Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: RUN.into(),
            scene_fingerprint: 0xabcd,
            iteration,
            stage,
            sender,
        },
        payload,
    }
}

fn sub(i: u32) -> NodeId {
    NodeId {
        role: Role::Subdomain,
        index: i,
    }
}

const INTERFACE: NodeId = NodeId {
    role: Role::Interface,
    index: 0,
};

/// The messages of one iteration of a two-subdomain run, with values depending on `n`.
fn iteration(n: u32) -> Vec<Message> {
    iteration_of(n, 6)
}

/// As [`iteration`], with boundary states of `rows` × 3 values.
fn iteration_of(n: u32, rows: usize) -> Vec<Message> {
    let mut out = Vec::new();
    for s in 0..2 {
        out.push(msg(
            n,
            Stage::Linear,
            sub(s),
            Payload::BoundaryState {
                subdomain: s,
                to: None,
                interfaces: vec![0],
                w: Field::from_fn(rows, 3, |r, c| {
                    (n * 100 + s * 10) as f64 + r as f64 * 0.1 + c as f64 * 1e-3
                }),
                f: Field::from_fn(rows, 3, |r, c| -(r as f64) * std::f64::consts::PI + c as f64 + n as f64),
            },
        ));
        out.push(msg(
            n + 1,
            Stage::Local,
            INTERFACE,
            Payload::LocalDirections {
                subdomain: s,
                interfaces: vec![0],
                q_hat: Field::from_fn(6, 3, |r, c| (r * c) as f64 / (n + 1) as f64),
            },
        ));
    }
    out.push(msg(
        n,
        Stage::Local,
        INTERFACE,
        Payload::Decision(Decision {
            eta: 1.0 / (n + 1) as f64,
            contact_indicator: 0.5 / (n + 1) as f64,
            force_error: 0.0,
            jump_error: 0.0,
            counts: [1, 2, 3],
            status_changes: n as u64,
            direction_updates: vec![],
            force_step: 0.0,
            estimate: None,
            contraction: None,
            pointwise_step: 0.0,
            pointwise_estimate: None,
            verdict: Verdict::Continue,
        }),
    ));
    out
}

fn record_all(rec: &mut Recorder, msgs: &[Message]) {
    for (k, m) in msgs.iter().enumerate() {
        rec.record(&m.topic(), 1_000 + k as u64, &encode(m)).unwrap();
    }
}

#[test]
fn recording_reads_back_with_channels_schemas_metadata_and_summary() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sub/tiny-r1.mcap");
    let msgs: Vec<Message> = (0..3).flat_map(iteration).collect();
    let mut rec = Recorder::create(&path, &run_info(), &RecorderOptions::default()).unwrap();
    record_all(&mut rec, &msgs);
    let stats = rec.finish().unwrap();
    assert_eq!(stats.messages, msgs.len() as u64);
    assert_eq!(stats.channels, 5);
    assert_eq!(stats.file_bytes, std::fs::metadata(&path).unwrap().len());

    let r = Recording::open(&path).unwrap();
    assert!(r.is_finished() && r.truncated().is_none());
    assert_eq!(r.scene_text(), Some(run_info().scene_text.as_str()));
    assert_eq!(r.scene_overrides(), Some(&run_info().scene_overrides));
    assert_eq!(r.metadata()["run_id"], RUN);
    assert_eq!(r.metadata()["schema_version"], SCHEMA_VERSION.to_string());
    assert_eq!(r.scene_fingerprint(), 0xabcd);
    let topics: Vec<&str> = r.channels().iter().map(|c| c.topic.as_str()).collect();
    assert_eq!(
        topics,
        [
            "glissade/r1/subdomain/0/boundary_state",
            "glissade/r1/interface/0/local_directions/0",
            "glissade/r1/subdomain/1/boundary_state",
            "glissade/r1/interface/0/local_directions/1",
            "glissade/r1/interface/0/decision",
        ]
    );
    for c in r.channels() {
        assert_eq!(c.messages, 3, "{}", c.topic);
        assert_eq!(
            (c.message_encoding.as_str(), c.schema_encoding.as_str()),
            (ENCODING, ENCODING)
        );
        assert_eq!(c.metadata["schema_version"], SCHEMA_VERSION.to_string());
    }
    assert_eq!(r.channels()[0].schema_name, "glissade.BoundaryState");
    assert_eq!(r.channels()[4].schema_name, "glissade.Decision");
    // Same bytes, same order, same log times; decoding gives the messages back.
    let back: Vec<_> = r.messages().collect();
    assert_eq!(back.len(), msgs.len());
    for (k, (b, m)) in back.iter().zip(&msgs).enumerate() {
        assert_eq!(b.topic, m.topic());
        assert_eq!(b.log_time, 1_000 + k as u64);
        assert_eq!(&*b.data, encode(m).as_slice());
        assert_eq!(&r.decode(b).unwrap(), m);
    }
    // The summary section: statistics and indexes.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
    assert_eq!(summary.stats.unwrap().message_count, msgs.len() as u64);
    assert_eq!(summary.channels.len(), 5);
    assert_eq!(summary.schemas.len(), 3);
    let attachments: Vec<&str> = summary.attachment_indexes.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(attachments, [SCENE_ATTACHMENT, OVERRIDES_ATTACHMENT]);
    assert_eq!(summary.metadata_indexes.len(), 1);
    // One chunk per iteration at least (closed at every decision).
    assert!(summary.chunk_indexes.len() >= 3, "{}", summary.chunk_indexes.len());
}

#[test]
fn compressed_recordings_read_back() {
    for compression in [ChunkCompression::Lz4, ChunkCompression::Zstd] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.mcap");
        let msgs: Vec<Message> = (0..2).flat_map(iteration).collect();
        let opts = RecorderOptions {
            compression,
            ..RecorderOptions::default()
        };
        let mut rec = Recorder::create(&path, &run_info(), &opts).unwrap();
        record_all(&mut rec, &msgs);
        rec.finish().unwrap();
        let r = Recording::open(&path).unwrap();
        assert_eq!(r.metadata()["chunk_compression"], compression.name());
        let back: Vec<Vec<u8>> = r.messages().map(|m| m.data.into_owned()).collect();
        assert_eq!(back, msgs.iter().map(encode).collect::<Vec<_>>());
    }
}

/// The iterations of the boundary states recorded in `path`, in recorded order.
fn state_iterations(path: &Path) -> Vec<u32> {
    let r = Recording::open(path).unwrap();
    r.messages()
        .filter(|m| m.topic.ends_with("boundary_state"))
        .map(|m| r.decode(&m).unwrap().envelope.iteration)
        .collect()
}

#[test]
fn topic_selection_and_thinning() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sel.mcap");
    let msgs: Vec<Message> = (0..4).flat_map(iteration).collect();
    let opts = RecorderOptions {
        topics: vec!["interface/*/decision".into(), "subdomain/**".into()],
        full_fields_every: 2,
        ..RecorderOptions::default()
    };
    let mut rec = Recorder::create(&path, &run_info(), &opts).unwrap();
    let mut outcomes = Vec::new();
    for m in &msgs {
        outcomes.push(rec.record(&m.topic(), 0, &encode(m)).unwrap());
    }
    let stats = rec.finish().unwrap();
    // Per iteration: 2 boundary states (kept at even iterations), 2 local directions (not
    // selected), 1 decision.
    assert_eq!(stats.not_selected, 8);
    assert_eq!(stats.thinned, 4);
    assert_eq!(stats.messages, 4 + 4);
    assert_eq!(outcomes.iter().filter(|o| **o == Recorded::Written).count(), 8);
    assert_eq!(state_iterations(&path), [0, 0, 2, 2]);
}

/// The run's front leaves thinned full fields out before encoding or decoding them: heard with a
/// damaged payload behind a valid envelope, a thinned boundary state is counted as thinned (not
/// refused: it is never decoded), while the same damage at a recorded iteration is refused; a
/// thinned message the in-process bus delivers is not written either.
#[test]
fn the_front_leaves_thinned_fields_out_without_decoding_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("front.mcap");
    let opts = RecorderOptions {
        full_fields_every: 2,
        ..RecorderOptions::default()
    };
    let mut rec = RunRecorder::create(&path, &run_info(), &opts).unwrap();
    let damaged = |m: &Message| {
        let mut b = encode(m);
        b.truncate(b.len() - 8);
        assert!(peek_envelope(&b, RUN).is_ok(), "the envelope is intact");
        b
    };
    let thinned = &iteration(1)[0];
    let kept = &iteration(2)[0];
    rec.heard(&thinned.topic(), &damaged(thinned), 1);
    rec.heard(&kept.topic(), &damaged(kept), 2);
    rec.delivered(&iteration(3)[0]);
    rec.delivered(&iteration(4)[0]);
    assert_eq!(rec.seen(), 4);
    let finished = rec.finish().unwrap();
    assert_eq!(finished.refused, 1, "{:?}", finished.first_refused);
    assert!(
        finished
            .first_refused
            .as_deref()
            .is_some_and(|f| f.contains("subdomain/0/boundary_state")),
        "{:?}",
        finished.first_refused
    );
    assert_eq!(finished.stats.thinned, 2);
    assert_eq!(finished.stats.messages, 1, "only iteration 4's state is written");
    assert_eq!(state_iterations(&path), [4]);
}

#[test]
fn bad_messages_and_unwritable_paths_are_errors_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, b"x").unwrap();
    let path = blocker.join("r.mcap");
    let e = Recorder::create(&path, &run_info(), &RecorderOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains(&path.display().to_string()), "{e}");

    let path = dir.path().join("ok.mcap");
    let mut rec = Recorder::create(&path, &run_info(), &RecorderOptions::default()).unwrap();
    let mut other = iteration(0).remove(0);
    other.envelope.run_id = "r2".into();
    let e = rec
        .record("glissade/r1/subdomain/0/boundary_state", 0, &encode(&other))
        .unwrap_err();
    assert!(e.to_string().contains("message of run `r2`"), "{e}");
    let m = &iteration(0)[0];
    let e = rec.record("glissade/r1/subdomain/0", 0, &encode(m)).unwrap_err();
    assert!(e.to_string().contains("not a message key expression"), "{e}");
}

/// A file cut at any length reads back as a prefix of what was recorded: never an error, never a
/// wrong message, and complete up to the last flushed chunk.
#[test]
fn cut_short_files_read_back_as_a_prefix() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.mcap");
    let msgs: Vec<Message> = (0..4).flat_map(iteration).collect();
    let mut rec = Recorder::create(&path, &run_info(), &RecorderOptions::default()).unwrap();
    record_all(&mut rec, &msgs);
    rec.finish().unwrap();
    let full = std::fs::read(&path).unwrap();
    let wire: Vec<Vec<u8>> = msgs.iter().map(encode).collect();
    let mut last_count = 0;
    let mut opened = false;
    for cut in (40..full.len()).step_by(37) {
        // Cut within the metadata or scene attachment written first: not yet a recording.
        let r = match Recording::from_bytes(&path, full[..cut].to_vec()) {
            Ok(r) => r,
            Err(e) => {
                assert!(!opened && cut < 600, "cut at {cut}: {e}");
                assert!(e.to_string().contains("no `glissade` metadata record"), "{e}");
                continue;
            }
        };
        opened = true;
        assert!(!r.is_finished());
        let back: Vec<Vec<u8>> = r.messages().map(|m| m.data.into_owned()).collect();
        assert!(back.len() <= wire.len());
        assert_eq!(back[..], wire[..back.len()], "cut at {cut}");
        assert!(back.len() >= last_count, "a longer prefix never reads fewer messages");
        last_count = back.len();
    }
    assert_eq!(last_count, wire.len());
}

/// Helper process of [`survives_sigkill`]: records iterations forever, printing the number of
/// each iteration once its decision (and so its chunk) is flushed.
#[test]
#[ignore = "helper process of survives_sigkill"]
fn sigkill_helper() {
    let Ok(path) = std::env::var("GLISSADE_RECORDER_SIGKILL_FILE") else {
        return;
    };
    let mut rec = Recorder::create(Path::new(&path), &run_info(), &RecorderOptions::default()).unwrap();
    for n in 0.. {
        record_all(&mut rec, &iteration(n));
        println!("flushed {n}");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// A recorder killed with SIGKILL mid-run leaves a file whose every flushed chunk reads back:
/// every message of every iteration reported flushed before the kill.
#[test]
fn survives_sigkill() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.mcap");
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "tests::sigkill_helper",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("GLISSADE_RECORDER_SIGKILL_FILE", &path)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let mut flushed = None;
    while let Some(Ok(line)) = lines.next() {
        if let Some(n) = line.strip_prefix("flushed ") {
            flushed = Some(n.trim().parse::<u32>().unwrap());
            if flushed >= Some(20) || std::time::Instant::now() > deadline {
                break;
            }
        }
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let flushed = flushed.expect("the helper reported flushed iterations");
    assert!(flushed >= 20, "the helper stopped early at iteration {flushed}");
    let r = Recording::open(&path).unwrap();
    assert!(!r.is_finished());
    let back: Vec<Vec<u8>> = r.messages().map(|m| m.data.into_owned()).collect();
    let expected: Vec<Vec<u8>> = (0..=flushed).flat_map(iteration).map(|m| encode(&m)).collect();
    assert!(back.len() >= expected.len(), "{} < {}", back.len(), expected.len());
    assert_eq!(back[..expected.len()], expected[..]);
    assert_eq!(r.scene_text(), Some(run_info().scene_text.as_str()));
    assert_eq!(r.scene_overrides(), Some(&run_info().scene_overrides));
    // Python `mcap`'s `make_reader` reads the same messages.
    let Some(python) = python_mcap() else { return };
    let crc = back.iter().fold(crc32fast::Hasher::new(), |mut h, w| {
        h.update(w);
        h
    });
    assert_eq!(
        python_reads(python, std::slice::from_ref(&path)),
        [Ok((back.len(), crc.finalize()))],
        "Python mcap"
    );
}

/// A chunk whose bytes changed after it was written (its CRC no longer matches) is reported with
/// its position and skipped: every message read back is one that was recorded, in order, those of
/// the chunks after it included.
#[test]
fn a_damaged_chunk_is_reported_and_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("damaged.mcap");
    let msgs: Vec<Message> = (0..4).flat_map(iteration).collect();
    let options = RecorderOptions {
        chunk_size: 1 << 10,
        ..RecorderOptions::default()
    };
    let mut rec = Recorder::create(&path, &run_info(), &options).unwrap();
    record_all(&mut rec, &msgs);
    rec.finish().unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    let wire: Vec<Vec<u8>> = msgs.iter().map(encode).collect();
    // One byte of the last third's first message, inside its chunk.
    let k = 2 * wire.len() / 3;
    let at = bytes
        .windows(wire[k].len())
        .position(|w| w == wire[k].as_slice())
        .expect("the message's bytes are in the file");
    bytes[at + wire[k].len() / 2] ^= 0x01;
    let r = Recording::from_bytes(&path, bytes).unwrap();
    assert!(r.truncated().is_none() && r.is_finished());
    let why = r.damaged().expect("the damaged chunk is reported");
    assert!(
        why.starts_with("1 damaged chunk(s), their messages skipped: at byte ") && why.contains("CRC"),
        "{why}"
    );
    let back: Vec<Vec<u8>> = r.messages().map(|m| m.data.into_owned()).collect();
    // What is read is the recording without one run of consecutive messages (the damaged
    // chunk's, the k-th among them), the last one included.
    assert!(
        !back.is_empty() && back.len() < wire.len(),
        "{} of {} messages read",
        back.len(),
        wire.len()
    );
    let first_missing = back.iter().zip(&wire).take_while(|(a, b)| a == b).count();
    let skipped = wire.len() - back.len();
    assert!(
        first_missing <= k && k < first_missing + skipped,
        "skipped {first_missing}..{} around {k}",
        first_missing + skipped
    );
    assert_eq!(back[first_missing..], wire[first_missing + skipped..]);
    assert_eq!(back.last(), wire.last());
}

/// A Python interpreter that imports `mcap`, or None (saying why) unless `GLISSADE_REQUIRE_PYTHON`
/// is set (CI), where a missing one fails the test.
fn python_mcap() -> Option<&'static str> {
    let found = ["python3", "python"].into_iter().find(|p| {
        std::process::Command::new(p)
            .args(["-c", "import mcap.reader"])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if found.is_none() {
        assert!(
            std::env::var_os("GLISSADE_REQUIRE_PYTHON").is_none(),
            "GLISSADE_REQUIRE_PYTHON is set but no python3 imports `mcap` (pip install -r .ci/python-requirements.txt)"
        );
        println!("skipped the Python reader: no python3 with the `mcap` package");
    }
    found
}

/// What Python `mcap`'s `make_reader(f).iter_messages(log_time_order=False)` (on a file: the
/// seeking reader, which starts from the footer) yields from each file: the number of messages and
/// the CRC-32 of their bytes in file order, or the error it raised.
fn python_reads(python: &str, files: &[std::path::PathBuf]) -> Vec<Result<(usize, u32), String>> {
    const SCRIPT: &str = r#"
import sys, json, zlib
from mcap.reader import make_reader
for path in sys.argv[1:]:
    try:
        with open(path, "rb") as f:
            n, crc = 0, 0
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
                n += 1
                crc = zlib.crc32(message.data, crc)
        print(json.dumps({"count": n, "crc": crc}))
    except Exception as e:
        print(json.dumps({"error": f"{type(e).__name__}: {e}"}))
"#;
    let out = std::process::Command::new(python)
        .args(["-c", SCRIPT])
        .args(files)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let field = |k: &str| {
                l.split(&format!("\"{k}\": "))
                    .nth(1)
                    .map(|v| v.split([',', '}']).next().unwrap().to_string())
            };
            match field("error") {
                Some(_) => Err(l.to_string()),
                None => Ok((
                    field("count").unwrap().parse().unwrap(),
                    field("crc").unwrap().parse().unwrap(),
                )),
            }
        })
        .collect()
}

/// A recorder killed at any point of any write (simulated: the write it was in keeps none of its
/// bytes or those up to any page boundary it crosses, where the kernel checks for a fatal signal,
/// and nothing after it happens) leaves a file that Python `mcap`'s
/// `make_reader` and [`Recording`] both read, yielding exactly the messages of the chunks whose
/// append completed, in order: never an error, never fewer, never a message of a chunk that was
/// being written. The states include kills inside a chunk's bytes, inside the summary and inside
/// the footer writes of every append, and inside the final summary.
#[test]
fn a_kill_at_any_write_leaves_a_file_python_and_glissade_read_up_to_the_last_complete_chunk() {
    let dir = tempfile::tempdir().unwrap();
    // Boundary states of 2 × 300 × 3 values (14.4 kB): chunks and summaries span pages, so that
    // kills land inside them; small chunks, several per iteration.
    let msgs: Vec<Message> = (0..4).flat_map(|n| iteration_of(n, 300)).collect();
    let wire: Vec<Vec<u8>> = msgs.iter().map(encode).collect();
    let options = RecorderOptions {
        chunk_size: 20_000,
        ..RecorderOptions::default()
    };
    // The writes of an uninterrupted recording, in order.
    let trace = {
        let path = dir.path().join("whole.mcap");
        let mut rec = Recorder::create(&path, &run_info(), &options).unwrap();
        record_all(&mut rec, &msgs);
        rec.finish_inner().unwrap();
        rec.file.trace.clone()
    };
    let offsets: Vec<u64> = trace.iter().map(|t| t.1).collect();
    let trace: Vec<usize> = trace.iter().map(|t| t.0).collect();
    assert!(trace.len() > 40, "{} writes: too few chunks", trace.len());
    let mut files = Vec::new();
    let mut expected = Vec::new();
    // Op 0 creates the file (metadata and scene, no message): kills from op 1 on.
    for (op, &len) in trace.iter().enumerate().skip(1) {
        // Nothing, and every page boundary the write crosses (a kill cuts a write there only).
        let mut cuts = vec![0];
        cuts.extend((1..len).filter(|k| (offsets[op] + *k as u64).is_multiple_of(4096)));
        for bytes in cuts {
            let path = dir.path().join(format!("kill-{op}-{bytes}.mcap"));
            let mut rec = Recorder::create(&path, &run_info(), &options).unwrap();
            rec.file.kill = Some(durable::Kill { ops: op, bytes });
            let mut died = false;
            for (k, m) in msgs.iter().enumerate() {
                if rec.record(&m.topic(), 1_000 + k as u64, &encode(m)).is_err() {
                    died = true;
                    break;
                }
            }
            if !died {
                assert!(rec.finish_inner().is_err(), "kill at op {op} never happened");
            }
            let kept = rec.kept.0 as usize;
            drop(rec);
            files.push(path);
            expected.push((op, bytes, kept));
        }
    }
    // Every state: the Rust reader.
    for (path, &(op, bytes, kept)) in files.iter().zip(&expected) {
        let r = Recording::open(path).unwrap_or_else(|e| panic!("kill at op {op} + {bytes} bytes: {e}"));
        assert!(!r.is_finished(), "kill at op {op} + {bytes} bytes");
        let back: Vec<Vec<u8>> = r.messages().map(|m| m.data.into_owned()).collect();
        assert_eq!(
            back[..],
            wire[..kept],
            "kill at op {op} + {bytes} bytes: glissade's reader"
        );
        assert_eq!(r.scene_text(), Some(run_info().scene_text.as_str()));
        assert_eq!(r.scene_overrides(), Some(&run_info().scene_overrides));
    }
    // Some states hold part of the run, some none of it, some all of it but the summary.
    assert!(expected.iter().any(|e| e.2 == 0) && expected.iter().any(|e| e.2 == wire.len()));
    assert!(expected.iter().any(|e| e.2 > 0 && e.2 < wire.len()));
    let Some(python) = python_mcap() else { return };
    for ((read, &(op, bytes, kept)), path) in python_reads(python, &files).into_iter().zip(&expected).zip(&files) {
        let crc = wire[..kept].iter().fold(crc32fast::Hasher::new(), |mut h, w| {
            h.update(w);
            h
        });
        assert_eq!(
            read,
            Ok((kept, crc.finalize())),
            "kill at op {op} + {bytes} bytes ({}): Python mcap",
            path.display()
        );
    }
    println!("{} kill states read by both readers", files.len());
}
