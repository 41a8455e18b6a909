//! Foreign-readable copies of recordings (`glissade export --foreign`): the same channels, topics,
//! log and publish times, scene and overrides attachments and `glissade` metadata, with every message re-encoded
//! as protobuf (message encoding `protobuf`; each schema, encoding `protobuf`, a serialized
//! `google.protobuf.FileDescriptorSet` of `glissade.proto`, named by its message
//! `glissade.<Payload>`), so that any MCAP tool decodes it: Foxglove, `mcap cat --json`, Python's
//! `mcap-protobuf-support`. A field's values are a packed `repeated double`: one block of
//! little-endian f64, as in the wire format.
//!
//! The recording itself is unchanged (its bincode messages are what `glissade replay --node`
//! re-executes bit for bit); the export is a derived file, written to `<name>.partial` and renamed,
//! never over an existing file.

mod encode;
pub mod schema;

pub use encode::encode_into;
pub use schema::{file_descriptor_set_bytes, proto_source, PROTO_FILE};

use crate::{mcap_detail, RecorderError, Recording, METADATA_NAME, OVERRIDES_ATTACHMENT, SCENE_ATTACHMENT};
use glissade_messages::{decode_from_reader, BufferPool, DecodeBuffers, Expected, Payload, SCHEMA_VERSION};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Message encoding of every channel of an export, and encoding of every schema.
pub const ENCODING: &str = "protobuf";
/// Metadata key naming the recording a file is a foreign-readable export of.
pub const EXPORT_OF: &str = "foreign_export_of";
/// Codec description of an export (metadata `codec`; the original's moves to `source_codec`).
pub const CODEC: &str = "protobuf (proto3, glissade.proto): each schema is a serialized \
                         google.protobuf.FileDescriptorSet naming its message glissade.<Payload>";

/// The protobuf message (and schema) name of a payload: `glissade.<Payload type>`, the name of
/// the recording's bincode schema too ([`crate::PAYLOAD_FIELDS`]).
pub fn message_name(p: &Payload) -> &'static str {
    let field = p.field_key();
    crate::PAYLOAD_FIELDS
        .iter()
        .find(|(f, _, _)| *f == field)
        .map(|(_, name, _)| *name)
        .unwrap_or_else(|| panic!("PAYLOAD_FIELDS has no schema for payload `{field}`"))
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    pub path: PathBuf,
    pub messages: u64,
    pub channels: usize,
    /// Size of the written file.
    pub bytes: u64,
    /// Why the source recording's readable part ends early (cut short): the export holds the
    /// messages before that point, and its metadata says so.
    pub source_truncated: Option<String>,
    /// The source's damaged chunks: the export holds every other message, and its metadata says so.
    pub source_damaged: Option<String>,
}

/// Writes `<dir>/<file name of source>`, the foreign-readable copy of recording `source`
/// (`software` names this program in the copy's metadata). The source is read and checked
/// first (an MCAP glissade recording of this build's wire schema version); nothing is written
/// when it is not, nor over an existing file, and a failure part-way removes the partial file.
pub fn export(source: &Path, dir: &Path, software: &str) -> Result<Exported, RecorderError> {
    let rec = Recording::open(source)?;
    let format = |detail: String| RecorderError::Format {
        path: source.to_path_buf(),
        detail,
    };
    let version = rec
        .metadata()
        .get("schema_version")
        .map(String::as_str)
        .unwrap_or("none");
    if version != SCHEMA_VERSION.to_string() {
        return Err(format(format!(
            "recorded with wire schema version {version} by {}; this build reads version {SCHEMA_VERSION} \
             only: export it with the glissade version that recorded it",
            rec.metadata()
                .get("software")
                .map(String::as_str)
                .unwrap_or("an unknown program")
        )));
    }
    let name = source
        .file_name()
        .ok_or_else(|| format("not a file name".into()))?
        .to_string_lossy()
        .into_owned();
    let target = dir.join(&name);
    let exists = |p: &Path| -> Result<(), RecorderError> {
        match std::fs::symlink_metadata(p) {
            Ok(_) => Err(RecorderError::Io {
                path: p.to_path_buf(),
                detail: "already exists; nothing was overwritten".into(),
            }),
            Err(_) => Ok(()),
        }
    };
    exists(&target)?;
    std::fs::create_dir_all(dir).map_err(|e| RecorderError::Io {
        path: dir.to_path_buf(),
        detail: format!("cannot create the folder: {e}"),
    })?;
    let partial = dir.join(format!(".{name}.partial"));
    let written = write(&rec, &name, &partial, software).and_then(|stats| {
        exists(&target)?;
        std::fs::rename(&partial, &target).map_err(|e| RecorderError::Io {
            path: target.clone(),
            detail: format!("cannot move {} here: {e}", partial.display()),
        })?;
        Ok(stats)
    });
    match written {
        Ok((messages, channels, bytes)) => Ok(Exported {
            path: target,
            messages,
            channels,
            bytes,
            source_truncated: rec.truncated().map(str::to_string),
            source_damaged: rec.damaged().map(str::to_string),
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&partial);
            Err(e)
        }
    }
}

/// Writes the export of `rec` (file name `name`) to `path`: (messages, channels, file bytes).
fn write(rec: &Recording, name: &str, path: &Path, software: &str) -> Result<(u64, usize, u64), RecorderError> {
    let mcap_err = |e: mcap::McapError| RecorderError::Mcap {
        path: path.to_path_buf(),
        detail: mcap_detail(&e),
    };
    let file = File::create(path).map_err(|e| RecorderError::Io {
        path: path.to_path_buf(),
        detail: format!("cannot create the file: {e}"),
    })?;
    let mut writer = mcap::WriteOptions::new()
        .profile("glissade")
        .library(software.to_string())
        .compression(None)
        .chunk_size(Some(4 << 20))
        .create(BufWriter::with_capacity(1 << 20, file))
        .map_err(mcap_err)?;
    let mut metadata = rec.metadata().clone();
    if let Some(codec) = metadata.remove("codec") {
        metadata.insert("source_codec".into(), codec);
    }
    metadata.insert("codec".into(), CODEC.into());
    metadata.insert(EXPORT_OF.into(), name.to_string());
    metadata.insert("exported_by".into(), software.to_string());
    if let Some(why) = rec.truncated() {
        metadata.insert("source_truncated".into(), why.to_string());
    }
    if let Some(why) = rec.damaged() {
        metadata.insert("source_damaged".into(), why.to_string());
    }
    writer
        .write_metadata(&mcap::records::Metadata {
            name: METADATA_NAME.to_string(),
            metadata,
        })
        .map_err(mcap_err)?;
    if let Some(text) = rec.scene_text() {
        let (log_time, create_time) = rec.scene_times();
        writer
            .attach(&mcap::Attachment {
                log_time,
                create_time,
                name: SCENE_ATTACHMENT.to_string(),
                media_type: "application/toml".to_string(),
                data: std::borrow::Cow::Borrowed(text.as_bytes()),
            })
            .map_err(mcap_err)?;
    }
    if let Some(overrides) = rec.scene_overrides() {
        let (log_time, create_time) = rec.scene_times();
        writer
            .attach(&mcap::Attachment {
                log_time,
                create_time,
                name: OVERRIDES_ATTACHMENT.to_string(),
                media_type: "application/json".to_string(),
                data: std::borrow::Cow::Owned(crate::overrides_json(overrides).into_bytes()),
            })
            .map_err(mcap_err)?;
    }
    let proto = proto_source();
    writer
        .attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: PROTO_FILE.to_string(),
            media_type: "text/x-protobuf".to_string(),
            data: std::borrow::Cow::Borrowed(proto.as_bytes()),
        })
        .map_err(mcap_err)?;

    let descriptor = file_descriptor_set_bytes();
    let expected = Expected {
        run_id: rec.run_id().to_string(),
        scene_fingerprint: rec.scene_fingerprint(),
    };
    let pool = Arc::new(Mutex::new(BufferPool::default()));
    let mut schemas: HashMap<&'static str, u16> = HashMap::new();
    let mut channels: HashMap<u16, u16> = HashMap::new();
    let mut meta = BTreeMap::new();
    meta.insert("schema_version".to_string(), SCHEMA_VERSION.to_string());
    meta.insert("codec".to_string(), CODEC.to_string());
    let mut out = Vec::new();
    let mut messages = 0u64;
    for (index, m) in rec.messages().enumerate() {
        let msg = decode_from_reader(
            &m.data[..],
            m.data.len(),
            &expected,
            DecodeBuffers::pooled(pool.clone()),
        )
        .map_err(|e| RecorderError::Message {
            path: rec.path().to_path_buf(),
            topic: m.topic.to_string(),
            detail: format!("message #{index}: {e}"),
        })?;
        let schema_name = message_name(&msg.payload);
        let channel = match channels.get(&m.channel) {
            Some(&c) => c,
            None => {
                let schema = match schemas.get(schema_name) {
                    Some(&s) => s,
                    None => {
                        let s = writer
                            .add_schema(schema_name, ENCODING, &descriptor)
                            .map_err(mcap_err)?;
                        schemas.insert(schema_name, s);
                        s
                    }
                };
                let c = writer.add_channel(schema, m.topic, ENCODING, &meta).map_err(mcap_err)?;
                channels.insert(m.channel, c);
                c
            }
        };
        out.clear();
        encode_into(&msg, &mut out);
        pool.lock().unwrap_or_else(|e| e.into_inner()).recycle(msg.payload);
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: m.sequence,
                    log_time: m.log_time,
                    publish_time: m.publish_time,
                },
                &out,
            )
            .map_err(mcap_err)?;
        messages += 1;
    }
    writer.finish().map_err(mcap_err)?;
    let mut inner = writer.into_inner();
    std::io::Write::flush(&mut inner).map_err(|e| RecorderError::Io {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    let file = inner.into_inner().map_err(|e| RecorderError::Io {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    file.sync_all().map_err(|e| RecorderError::Io {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    let bytes = file.metadata().map(|m| m.len()).unwrap_or(0);
    Ok((messages, channels.len(), bytes))
}

#[cfg(test)]
mod tests;
