//! Recordings of glissade runs (docs/recording.md): every message of a run written to an MCAP
//! file, and read back.
//!
//! Layout of a recording `<scene>-<run id>.mcap`:
//! - one **channel per key expression** (`glissade/<run>/<role>/<id>/<field>[/<destination>]`),
//!   message encoding `bincode2`, channel metadata naming the codec and the wire schema version;
//! - one **schema per payload type** (`glissade.BoundaryState`, …), encoding `bincode2`, whose
//!   data is a text description of the envelope and payload layout with the schema version;
//! - the payload bytes are exactly the bytes on the wire (envelope + payload, [`glissade_messages::encode`]);
//! - a metadata record `glissade` (run id, scene name and fingerprint, software version, wire
//!   schema version, what was recorded), the scene file as written as an attachment `scene.toml`
//!   and the command-line overrides the run applied to it as an attachment `overrides.json` (the
//!   serde JSON form of [`glissade_messages::Overrides`], every key present, `null` when not
//!   given): the two rebuild the run's model;
//! - chunked; chunk compression none by default (solver fields are full-entropy f64: lz4 and zstd
//!   shrink them by 0.1–5 % at a fraction of the write speed), lz4 or zstd on request;
//! - a summary section (statistics, chunk, attachment and metadata indexes) and footer after
//!   every chunk, replaced by the `mcap` writer's own on [`Recorder::finish`] or drop.
//!
//! Durability: the current chunk is closed and appended to the file at the end of every LATIN
//! iteration (every `Decision` message) and whenever it exceeds the chunk size, with a summary
//! that indexes it ([`durable`]): the file is a complete MCAP file after every chunk, and a
//! recorder killed by SIGKILL (or stopped by a full disk) leaves one that any MCAP reader reads
//! up to its last complete chunk (Python `mcap`'s `make_reader` included), and that
//! [`Recording::open`] reports as not finalised.

mod durable;
pub mod foreign;
mod front;
mod reader;
mod schema;

pub use front::{Finished, RunRecorder};
pub use reader::{ChannelInfo, RecordedMessage, Recording};
pub use schema::{payload_schema, PAYLOAD_FIELDS};

use durable::{DurableFile, Index, Pending};
use glissade_messages::{peek_envelope, Envelope, Overrides, Stage, SCHEMA_VERSION};
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Path, PathBuf};

/// Fields of space-time size that `full_fields_every = k` records only every k-th iteration (and at
/// the end): boundary states, local directions and the macro fields (n × (N + 1) values each).
pub const THINNED_FIELDS: [&str; 4] = [
    "boundary_state",
    "local_directions",
    "macro_forces",
    "macro_displacements",
];

/// Message encoding of every channel and encoding of every schema.
pub const ENCODING: &str = "bincode2";
/// Name of the metadata record describing the run.
pub const METADATA_NAME: &str = "glissade";
/// Name of the attachment holding the scene file.
pub const SCENE_ATTACHMENT: &str = "scene.toml";
/// Name of the attachment holding the command-line overrides applied to the scene (JSON).
pub const OVERRIDES_ATTACHMENT: &str = "overrides.json";
/// Codec description written into channel metadata.
pub const CODEC: &str =
    "serde + bincode 2, standard config, little-endian, fixed-width integers; envelope then payload";

/// Errors of recording and reading.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    #[error("recording {path}: {detail}")]
    Io { path: PathBuf, detail: String },
    #[error("recording {path}: {detail}")]
    Mcap { path: PathBuf, detail: String },
    #[error("recording {path}: message on `{topic}`: {detail}")]
    Message {
        path: PathBuf,
        topic: String,
        detail: String,
    },
    #[error("recording {path}: {detail}")]
    Format { path: PathBuf, detail: String },
}

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ChunkCompression {
    #[default]
    None,
    Lz4,
    Zstd,
}

impl ChunkCompression {
    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            ChunkCompression::None => None,
            ChunkCompression::Lz4 => Some(mcap::Compression::Lz4),
            ChunkCompression::Zstd => Some(mcap::Compression::Zstd),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ChunkCompression::None => "none",
            ChunkCompression::Lz4 => "lz4",
            ChunkCompression::Zstd => "zstd",
        }
    }
}

impl std::str::FromStr for ChunkCompression {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(Self::None),
            "lz4" => Ok(Self::Lz4),
            "zstd" => Ok(Self::Zstd),
            _ => Err(format!("unknown chunk compression `{s}` (none, lz4 or zstd)")),
        }
    }
}

/// What a recording is of: written into its metadata and attachment.
#[derive(Debug, Clone, PartialEq)]
pub struct RunInfo {
    pub run_id: String,
    pub scene_name: String,
    pub scene_fingerprint: u64,
    /// The scene file's text as written.
    pub scene_text: String,
    /// The command-line settings the run applied on top of `scene_text`.
    pub scene_overrides: Overrides,
    /// e.g. `glissade 0.1.0 (release)`.
    pub software: String,
}

/// What to record and how.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderOptions {
    /// Key-expression patterns relative to the run (`**`, `interface/*/decision`, …).
    pub topics: Vec<String>,
    /// Full fields (boundary states, local directions) only every k-th iteration (k ≥ 1).
    pub full_fields_every: u32,
    pub compression: ChunkCompression,
    /// A chunk is closed once it holds this many bytes (and at every iteration's end).
    pub chunk_size: u64,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            topics: vec!["**".into()],
            full_fields_every: 1,
            compression: ChunkCompression::None,
            chunk_size: 4 << 20,
        }
    }
}

/// What [`Recorder::record`] did with a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Recorded {
    Written,
    /// Not among the recorded topics.
    NotSelected,
    /// A full field of an iteration that `full_fields_every` leaves out.
    Thinned,
}

/// Counts of a recording.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordingStats {
    pub messages: u64,
    pub payload_bytes: u64,
    pub not_selected: u64,
    pub thinned: u64,
    pub channels: usize,
    /// File size after finishing.
    pub file_bytes: u64,
}

/// The content of the `overrides.json` attachment.
pub(crate) fn overrides_json(overrides: &Overrides) -> String {
    serde_json::to_string(overrides).expect("overrides are plain numbers and names")
}

/// File name of a run's recording: `<scene>-<run id>.mcap`.
pub fn recording_file_name(scene_name: &str, run_id: &str) -> String {
    format!("{scene_name}-{run_id}.mcap")
}

/// Writes the messages of one run into an MCAP file.
pub struct Recorder {
    /// The `mcap` writer; it writes into `pending`, which [`Recorder::flush`] appends to `file`.
    writer: Option<mcap::Writer<Pending>>,
    pending: Pending,
    file: DurableFile,
    /// What the file's summary indexes.
    index: Index,
    path: PathBuf,
    run_id: String,
    patterns: Vec<String>,
    full_fields_every: u32,
    chunk_size: u64,
    schemas: HashMap<String, u16>,
    channels: HashMap<String, u16>,
    sequence: u32,
    stats: RecordingStats,
    /// Messages per channel and bytes of the chunk not yet appended.
    open_counts: BTreeMap<u16, u64>,
    open_bytes: u64,
    /// The last iteration whose decision was written, and the last one appended to the file.
    last_decision: Option<u32>,
    /// Messages in the file and the last iteration whose decision is in it.
    kept: (u64, Option<u32>),
    /// The first failed write: every later call fails with it, and nothing more is written.
    failed: Option<String>,
}

fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// An I/O error in words, ENOSPC named as such.
fn io_detail(e: &std::io::Error) -> String {
    // ENOSPC on Linux.
    if e.raw_os_error() == Some(28) {
        "no space left on device (ENOSPC)".to_string()
    } else {
        e.to_string()
    }
}

impl Recorder {
    /// Creates the file (and its folder), writes the run's metadata and scene attachment, and a
    /// summary and footer. Any failure names the path.
    pub fn create(path: &Path, run: &RunInfo, options: &RecorderOptions) -> Result<Self, RecorderError> {
        let io = |detail: String| RecorderError::Io {
            path: path.to_path_buf(),
            detail,
        };
        if options.full_fields_every == 0 {
            return Err(io("full_fields_every must be ≥ 1".into()));
        }
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| io(format!("cannot create folder {}: {e}", dir.display())))?;
        }
        let file = File::create(path).map_err(|e| io(format!("cannot create the file: {}", io_detail(&e))))?;
        let mcap_err = |e: mcap::McapError| RecorderError::Mcap {
            path: path.to_path_buf(),
            detail: mcap_detail(&e),
        };
        let pending = Pending::default();
        // Chunks are closed by the recorder (`flush`), each then appended with a new summary.
        let mut writer = mcap::WriteOptions::new()
            .profile("glissade")
            .library(run.software.clone())
            .compression(options.compression.mcap())
            .chunk_size(None)
            .create(pending.clone())
            .map_err(mcap_err)?;
        let mut metadata = BTreeMap::new();
        metadata.insert("run_id".to_string(), run.run_id.clone());
        metadata.insert("scene".to_string(), run.scene_name.clone());
        metadata.insert(
            "scene_fingerprint".to_string(),
            format!("{:016x}", run.scene_fingerprint),
        );
        metadata.insert("software".to_string(), run.software.clone());
        metadata.insert("schema_version".to_string(), SCHEMA_VERSION.to_string());
        metadata.insert("codec".to_string(), CODEC.to_string());
        metadata.insert("topics".to_string(), options.topics.join(", "));
        metadata.insert("full_fields_every".to_string(), options.full_fields_every.to_string());
        metadata.insert("chunk_compression".to_string(), options.compression.name().to_string());
        writer
            .write_metadata(&mcap::records::Metadata {
                name: METADATA_NAME.to_string(),
                metadata,
            })
            .map_err(mcap_err)?;
        let t = now_ns();
        writer
            .attach(&mcap::Attachment {
                log_time: t,
                create_time: t,
                name: SCENE_ATTACHMENT.to_string(),
                media_type: "application/toml".to_string(),
                data: std::borrow::Cow::Borrowed(run.scene_text.as_bytes()),
            })
            .map_err(mcap_err)?;
        writer
            .attach(&mcap::Attachment {
                log_time: t,
                create_time: t,
                name: OVERRIDES_ATTACHMENT.to_string(),
                media_type: "application/json".to_string(),
                data: std::borrow::Cow::Owned(overrides_json(&run.scene_overrides).into_bytes()),
            })
            .map_err(mcap_err)?;
        // A first chunk, holding the schema of decisions (every run has them): a summary with no
        // chunk index makes Python `mcap`'s reader read the data section from the start instead,
        // which fails on a file whose last append was cut.
        let (decision_schema, text) = payload_schema("decision");
        let decision_id = writer
            .add_schema(&decision_schema, ENCODING, text.as_bytes())
            .map_err(mcap_err)?;
        writer.flush().map_err(mcap_err)?;
        let mut index = Index::default();
        index.add_schema(decision_id, &decision_schema, ENCODING, text.as_bytes());
        let file = pending
            .drain(|_, head| {
                index.scan(0, head)?;
                DurableFile::create(file, head, index.tail(head.len() as u64))
            })
            .map_err(|e| io(format!("cannot write: {}", io_detail(&e))))?;
        Ok(Self {
            writer: Some(writer),
            pending,
            file,
            index,
            path: path.to_path_buf(),
            run_id: run.run_id.clone(),
            patterns: options
                .topics
                .iter()
                .map(|p| glissade_messages::topic::within_run(&run.run_id, p))
                .collect(),
            full_fields_every: options.full_fields_every,
            chunk_size: options.chunk_size,
            schemas: HashMap::from([(decision_schema, decision_id)]),
            channels: HashMap::new(),
            sequence: 0,
            stats: RecordingStats::default(),
            open_counts: BTreeMap::new(),
            open_bytes: 0,
            last_decision: None,
            kept: (0, None),
            failed: None,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn stats(&self) -> &RecordingStats {
        &self.stats
    }

    /// Remembers the first failure (later calls fail with it) and returns it.
    fn fail(&mut self, detail: String) -> RecorderError {
        let detail = self.failed.get_or_insert(detail).clone();
        RecorderError::Io {
            path: self.path.clone(),
            detail,
        }
    }

    fn check_failed(&self) -> Result<(), RecorderError> {
        match &self.failed {
            Some(detail) => Err(RecorderError::Io {
                path: self.path.clone(),
                detail: detail.clone(),
            }),
            None => Ok(()),
        }
    }

    /// What the file holds after a failed write: the messages of the chunks appended before.
    fn kept(&self) -> String {
        let (messages, iteration) = self.kept;
        let through = iteration.map_or("no complete iteration".to_string(), |i| format!("iterations 0 to {i}"));
        format!(
            "the file keeps the {messages} messages written before ({through}), a complete MCAP file ({} bytes) \
             that glissade and other MCAP readers read",
            self.file.len()
        )
    }

    fn mcap_failure(&mut self, e: mcap::McapError) -> RecorderError {
        let detail = format!("{}; {}", mcap_detail(&e), self.kept());
        self.fail(detail)
    }

    /// Whether [`Self::record`] leaves out a message of envelope `envelope` on `topic`, so that
    /// a caller need not encode or decode it: a topic not recorded, or a full field of an
    /// iteration that `full_fields_every` thins out (counted as such).
    pub fn leaves_out(&mut self, topic: &str, envelope: &Envelope) -> Option<Recorded> {
        if !self.selects(topic) {
            self.stats.not_selected += 1;
            return Some(Recorded::NotSelected);
        }
        let field = glissade_messages::topic_field(topic)?;
        self.thins(field, envelope).then(|| {
            self.stats.thinned += 1;
            Recorded::Thinned
        })
    }

    fn selects(&self, topic: &str) -> bool {
        self.patterns.iter().any(|p| glissade_messages::key_matches(p, topic))
    }

    /// A full field of an iteration that `full_fields_every` leaves out.
    fn thins(&self, field: &str, envelope: &Envelope) -> bool {
        self.full_fields_every > 1
            && THINNED_FIELDS.contains(&field)
            && envelope.stage != Stage::Final
            && !envelope.iteration.is_multiple_of(self.full_fields_every)
    }

    /// Records the wire bytes `bytes` of a message published on `topic`, logged at `log_time_ns`
    /// (ns since the Unix epoch). The bytes must be a message of this run (its envelope is
    /// checked); a message of another run or of another schema version is an error. After a
    /// failed write every call fails with that write's error.
    pub fn record(&mut self, topic: &str, log_time_ns: u64, bytes: &[u8]) -> Result<Recorded, RecorderError> {
        self.check_failed()?;
        let msg_err = |detail: String| RecorderError::Message {
            path: self.path.clone(),
            topic: topic.to_string(),
            detail,
        };
        if !self.selects(topic) {
            self.stats.not_selected += 1;
            return Ok(Recorded::NotSelected);
        }
        let envelope = peek_envelope(bytes, &self.run_id).map_err(|e| msg_err(e.to_string()))?;
        let Some(field) = glissade_messages::topic_field(topic) else {
            return Err(msg_err(
                "not a message key expression (glissade/<run>/<role>/<id>/<field>)".into(),
            ));
        };
        if self.thins(field, &envelope) {
            self.stats.thinned += 1;
            return Ok(Recorded::Thinned);
        }
        let channel = match self.channels.get(topic) {
            Some(&c) => c,
            None => {
                let writer = self
                    .writer
                    .as_mut()
                    .expect("only finishing takes the writer, and nothing records after it");
                let (schema_name, text) = payload_schema(field);
                let schema = match self.schemas.get(&schema_name) {
                    Some(&s) => s,
                    None => {
                        let s = match writer.add_schema(&schema_name, ENCODING, text.as_bytes()) {
                            Ok(s) => s,
                            Err(e) => return Err(self.mcap_failure(e)),
                        };
                        self.index.add_schema(s, &schema_name, ENCODING, text.as_bytes());
                        self.schemas.insert(schema_name, s);
                        s
                    }
                };
                let mut meta = BTreeMap::new();
                meta.insert("schema_version".to_string(), SCHEMA_VERSION.to_string());
                meta.insert("codec".to_string(), CODEC.to_string());
                let writer = self
                    .writer
                    .as_mut()
                    .expect("only finishing takes the writer, and nothing records after it");
                let c = match writer.add_channel(schema, topic, ENCODING, &meta) {
                    Ok(c) => c,
                    Err(e) => return Err(self.mcap_failure(e)),
                };
                self.index.add_channel(mcap::records::Channel {
                    id: c,
                    schema_id: schema,
                    topic: topic.to_string(),
                    message_encoding: ENCODING.to_string(),
                    metadata: meta,
                });
                self.channels.insert(topic.to_string(), c);
                self.stats.channels = self.channels.len();
                c
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: self.sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        self.sequence = self.sequence.wrapping_add(1);
        let writer = self
            .writer
            .as_mut()
            .expect("only finishing takes the writer, and nothing records after it");
        if let Err(e) = writer.write_to_known_channel(&header, bytes) {
            return Err(self.mcap_failure(e));
        }
        self.stats.messages += 1;
        self.stats.payload_bytes += bytes.len() as u64;
        *self.open_counts.entry(channel).or_default() += 1;
        // Opcode, length and message header, then the bytes.
        self.open_bytes += 31 + bytes.len() as u64;
        if field == "decision" {
            // End of an iteration: make everything so far durable.
            self.last_decision = Some(envelope.iteration);
            self.flush()?;
        } else if self.open_bytes >= self.chunk_size {
            self.flush()?;
        }
        Ok(Recorded::Written)
    }

    /// Closes the current chunk and appends it to the file with a summary that indexes it.
    pub fn flush(&mut self) -> Result<(), RecorderError> {
        self.check_failed()?;
        let writer = self
            .writer
            .as_mut()
            .expect("only finishing takes the writer, and nothing records after it");
        if let Err(e) = writer.flush() {
            return Err(self.mcap_failure(e));
        }
        if self.open_counts.is_empty() {
            return Ok(());
        }
        let (file, index, counts) = (&mut self.file, &mut self.index, &self.open_counts);
        let appended = self.pending.drain(|base, data| {
            debug_assert_eq!(base, file.data_end());
            index.scan(base, data)?;
            index.add_messages(counts);
            file.append(data, index.tail(base + data.len() as u64))
        });
        match appended {
            Ok(()) => {
                self.kept = (self.stats.messages, self.last_decision);
                self.open_counts.clear();
                self.open_bytes = 0;
                Ok(())
            }
            Err(e) => {
                let detail = format!("cannot write: {}; {}", io_detail(&e), self.kept());
                Err(self.fail(detail))
            }
        }
    }

    /// Writes the `mcap` writer's summary section and closes the file.
    pub fn finish(mut self) -> Result<RecordingStats, RecorderError> {
        self.finish_inner()?;
        Ok(self.stats.clone())
    }

    fn finish_inner(&mut self) -> Result<(), RecorderError> {
        if self.writer.is_none() {
            return Ok(());
        }
        if let Err(e) = self.flush() {
            self.writer = None;
            return Err(e);
        }
        let mut writer = self.writer.take().expect("a recorder without a writer returned above");
        if let Err(e) = writer.finish() {
            return Err(self.mcap_failure(e));
        }
        drop(writer);
        let file = &mut self.file;
        let written = self.pending.drain(|_, tail| {
            file.append(
                &[],
                durable::Tail {
                    bytes: tail.to_vec(),
                    summary: 0..0,
                },
            )
        });
        if let Err(e) = written {
            let detail = format!("cannot write the summary: {}; {}", io_detail(&e), self.kept());
            return Err(self.fail(detail));
        }
        self.stats.file_bytes = self.file.len();
        Ok(())
    }
}

impl Drop for Recorder {
    /// Finalises the file (summary section) when a run ends without [`Recorder::finish`], e.g.
    /// on an error path; a failure here can only be told (an error event of the launcher's
    /// console target, which the `glissade` binary prints as "error: …"; once: a failure already
    /// returned by a call is not repeated).
    fn drop(&mut self) {
        let failed_before = self.failed.is_some();
        if let Err(e) = self.finish_inner() {
            if !failed_before {
                tracing::error!(target: "glissade::console", "{e}");
            }
        }
    }
}

/// Nanoseconds since the Unix epoch, the log time of recorded messages.
pub fn log_time_now() -> u64 {
    now_ns()
}

#[cfg(test)]
mod tests;

/// An mcap error with its causes (e.g. "I/O error from writing…: No space left on device").
fn mcap_detail(e: &mcap::McapError) -> String {
    let mut s = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(cause) = source {
        s.push_str(&format!(": {cause}"));
        source = cause.source();
    }
    s
}
