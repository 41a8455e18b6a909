//! Foreign-readable exports (`glissade export --foreign`): a run's recording re-encoded as
//! protobuf decodes, every message of it, with Python's `mcap` + `mcap-protobuf-support` alone,
//! and what that reader sees equals the run's summary and the original recording exactly; bad
//! inputs are refused with the file and the problem named, and nothing is written.

use crate::common::{glissade_ok, python_with, scratch};
use glissade_messages::Payload;
use glissade_recorder::Recording;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

fn glissade(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glissade"))
        .args(args)
        .output()
        .unwrap()
}

/// Exit 2 and the error on stderr.
fn fails(args: &[&str]) -> String {
    let o = glissade(args);
    assert_eq!(o.status.code(), Some(2), "glissade {args:?}: {o:?}");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Decodes every message of an export with the protobuf decoder of `mcap-protobuf-support` and
/// prints, as JSON: messages per topic, the schema and message encodings seen, (iteration, η) of
/// every Decision, and the values of the last message on `field_topic` (its `w`) as the hex of
/// their little-endian bytes, and the text attachments by name.
const READER: &str = r#"
import json, struct, sys
from collections import Counter
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

counts, encodings, eta, w, run_ids = Counter(), set(), [], None, set()
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for schema, channel, message, proto in reader.iter_decoded_messages():
        counts[channel.topic] += 1
        encodings.add((schema.encoding, channel.message_encoding))
        run_ids.add(proto.envelope.run_id)
        if schema.name == "glissade.Decision":
            eta.append([proto.envelope.iteration, proto.eta])
        if channel.topic == sys.argv[2]:
            w = struct.pack("<%dd" % len(proto.w.values), *proto.w.values).hex()
    attachments = {a.name: a.data.decode() for a in reader.iter_attachments()}
print(json.dumps({"counts": counts, "encodings": sorted(encodings), "eta": eta, "w": w,
                  "run_ids": sorted(run_ids), "attachments": attachments}))
"#;

#[test]
fn an_export_decodes_with_a_foreign_protobuf_reader() {
    let Some(python) = python_with(&["mcap", "mcap_protobuf"]) else {
        return;
    };
    let dir = scratch("foreign");
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    let out = dir.display().to_string();
    // `--accuracy` at the scene's own value: the same run, with an override to record.
    glissade_ok(&[
        &"run",
        &scene,
        &"--in-process",
        &"--accuracy",
        &"0.001",
        &"--out",
        &out,
        &"--run-id",
        &"x",
    ]);
    let original = dir.join("small-three-layer-x.mcap");
    let foreign = dir.join("foreign");
    let printed = glissade_ok(&[&"export", &original, &"--foreign", &foreign]);
    let export = foreign.join("small-three-layer-x.mcap");
    assert!(
        printed.contains("foreign-readable (protobuf): ") && export.exists(),
        "{printed}"
    );

    // The original, read by glissade's own reader.
    let rec = Recording::open(&original).unwrap();
    let field_topic = "glissade/x/subdomain/0/boundary_state";
    let expected_counts: BTreeMap<String, u64> = rec.channels().iter().map(|c| (c.topic.clone(), c.messages)).collect();
    let last_w = rec
        .messages()
        .filter(|m| m.topic == field_topic)
        .last()
        .map(|m| match rec.decode(&m).unwrap().payload {
            Payload::BoundaryState { w, .. } => w.data.to_vec(),
            p => panic!("{} on {field_topic}", p.field_key()),
        })
        .expect("a boundary state of subdomain 0");

    let o = Command::new(python)
        .args(["-c", READER])
        .arg(&export)
        .arg(field_topic)
        .output()
        .unwrap();
    assert!(o.status.success(), "python: {}", String::from_utf8_lossy(&o.stderr));
    let seen: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();

    let counts: BTreeMap<String, u64> = seen["counts"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(t, n)| (t.clone(), n.as_u64().unwrap()))
        .collect();
    assert_eq!(counts, expected_counts, "every message of every topic, decoded");
    assert_eq!(seen["encodings"], serde_json::json!([["protobuf", "protobuf"]]));
    assert_eq!(seen["run_ids"], serde_json::json!(["x"]));
    // The scene as written and the command line's overrides, beside it.
    let attachments = &seen["attachments"];
    assert_eq!(
        attachments["scene.toml"].as_str(),
        Some(std::fs::read_to_string(&scene).unwrap().as_str())
    );
    let overrides: serde_json::Value =
        serde_json::from_str(attachments["overrides.json"].as_str().expect("overrides.json")).unwrap();
    assert_eq!(
        overrides,
        serde_json::json!({"accuracy": 0.001, "tolerance": null, "max_iterations": null, "record": null})
    );
    assert_eq!(rec.scene_overrides().and_then(|o| o.accuracy), Some(0.001));

    // η per iteration equals the summary's, exactly (both shortest round-trip decimal of the same
    // doubles).
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("small-three-layer-x.summary.json")).unwrap()).unwrap();
    let history: Vec<(u64, f64)> = summary["history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| (h["iteration"].as_u64().unwrap(), h["decision"]["eta"].as_f64().unwrap()))
        .collect();
    let eta: Vec<(u64, f64)> = seen["eta"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p[0].as_u64().unwrap(), p[1].as_f64().unwrap()))
        .collect();
    assert!(history.len() > 5, "{} iterations", history.len());
    assert_eq!(eta, history, "η per iteration");

    // A boundary state's values, bit for bit.
    let hex: String = last_w
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .map(|b| format!("{b:02x}"))
        .collect();
    assert!(!last_w.is_empty());
    assert_eq!(
        seen["w"].as_str().unwrap(),
        hex,
        "w of the last boundary state on {field_topic}"
    );

    // The export keeps what describes the run and says what it is; glissade's reader refuses it.
    let e = glissade_recorder::Recording::open(&export)
        .err()
        .expect("an export is not a recording");
    assert!(e.to_string().contains("foreign-readable export"), "{e}");

    // A second export to the same folder names the file and overwrites nothing.
    let before = std::fs::read(&export).unwrap();
    let err = fails(&[
        "export",
        original.to_str().unwrap(),
        "--foreign",
        foreign.to_str().unwrap(),
    ]);
    assert!(
        err.contains("small-three-layer-x.mcap") && err.contains("already exists; nothing was overwritten"),
        "{err}"
    );
    assert_eq!(std::fs::read(&export).unwrap(), before);
}

/// Files in `dir` (none if it does not exist).
fn listing(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|d| {
            d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_corrupt_or_foreign_input_is_refused_and_nothing_is_written() {
    let dir = scratch("foreign-bad");
    let out = dir.join("out");
    let target = out.to_str().unwrap();

    // Not an MCAP file.
    let text = dir.join("notes.mcap");
    std::fs::write(&text, "not a recording\n").unwrap();
    let err = fails(&["export", text.to_str().unwrap(), "--foreign", target]);
    assert!(err.contains("notes.mcap") && err.contains("not an MCAP file"), "{err}");
    assert!(listing(&out).is_empty(), "{:?}", listing(&out));

    // A recording of another wire schema version: the metadata record's `schema_version` (written
    // before any chunk, so no CRC covers it) changed.
    let scene = format!("{}/launch/scenes/small-three-layer.toml", env!("CARGO_MANIFEST_DIR"));
    glissade_ok(&[&"run", &scene, &"--in-process", &"--out", &dir, &"--run-id", &"v"]);
    let mut bytes = std::fs::read(dir.join("small-three-layer-v.mcap")).unwrap();
    let version = format!("schema_version\x01\0\0\0{}", glissade_messages::SCHEMA_VERSION);
    let at = bytes
        .windows(version.len())
        .position(|w| w == version.as_bytes())
        .expect("the metadata's schema version");
    // The last digit changed: another version of the same length.
    let last = at + version.len() - 1;
    bytes[last] = if bytes[last] == b'3' { b'2' } else { b'3' };
    let other = std::str::from_utf8(&bytes[at + 18..=last]).unwrap().to_string();
    assert_ne!(other, glissade_messages::SCHEMA_VERSION.to_string());
    let old = dir.join("old-v.mcap");
    std::fs::write(&old, &bytes).unwrap();
    let err = fails(&["export", old.to_str().unwrap(), "--foreign", target]);
    assert!(
        err.contains("old-v.mcap")
            && err.contains(&format!("wire schema version {other} "))
            && err.contains("reads version"),
        "{err}"
    );
    assert!(listing(&out).is_empty(), "{:?}", listing(&out));

    // Nothing to export.
    let err = fails(&["export", old.to_str().unwrap()]);
    assert!(err.contains("--foreign <DIR>"), "{err}");
}
