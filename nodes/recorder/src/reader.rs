//! Reading recordings back: channels, metadata, the scene, and the messages in file order.

use crate::{RecorderError, METADATA_NAME, OVERRIDES_ATTACHMENT, SCENE_ATTACHMENT};
use glissade_messages::{decode, DecodeError, Expected, Message, Overrides};
use mcap::read::{ChunkFlattener, Options};
use mcap::records::Record;
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One channel of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub schema_name: String,
    pub schema_encoding: String,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
    /// Messages of this channel found in the file.
    pub messages: u64,
}

/// One recorded message: its channel's topic, its log time and its wire bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedMessage<'a> {
    pub topic: &'a str,
    pub channel: u16,
    pub sequence: u32,
    /// ns since the Unix epoch.
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Cow<'a, [u8]>,
}

/// A chunk whose records do not match its CRC: its byte range in the file and the two CRCs.
struct DamagedChunk {
    start: usize,
    end: usize,
    why: String,
}

/// Every uncompressed chunk whose records do not match its CRC (compressed chunks are checked by
/// the reader as they are decompressed). Walks the records' framing (opcode, length) from the
/// magic to the data end or the first incomplete record.
fn damaged_chunks(bytes: &[u8]) -> Vec<DamagedChunk> {
    let mut out = Vec::new();
    let mut pos = mcap::MAGIC.len();
    while let Some((end, damage)) = check_record(bytes, pos) {
        if let Some(why) = damage {
            out.push(DamagedChunk { start: pos, end, why });
        }
        pos = end;
    }
    out
}

/// The end of the record at `pos` and, for an uncompressed chunk whose CRC does not match, why;
/// None at the data end or an incomplete record.
fn check_record(bytes: &[u8], pos: usize) -> Option<(usize, Option<String>)> {
    const CHUNK: u8 = 0x06;
    const DATA_END: u8 = 0x0F;
    let u64_at = |at: usize| -> Option<u64> { Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?)) };
    let u32_at = |at: usize| -> Option<u32> { Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?)) };
    let (&op, len) = (bytes.get(pos)?, u64_at(pos + 1)?);
    let body = pos + 9;
    let end = body.checked_add(usize::try_from(len).ok()?)?;
    if end > bytes.len() || op == DATA_END {
        return None;
    }
    if op == CHUNK {
        // start time, end time, uncompressed size (8 bytes each), CRC, compression, records.
        let crc = u32_at(body + 24)?;
        let name_len = u32_at(body + 28)? as usize;
        let records_len = usize::try_from(u64_at(body + 32 + name_len)?).ok()?;
        let records_at = body + 40 + name_len;
        let records = bytes.get(records_at..records_at.checked_add(records_len)?)?;
        if name_len == 0 && crc != 0 {
            let computed = crc32fast::hash(records);
            if computed != crc {
                return Some((end, Some(format!("CRC {computed:08x}, recorded {crc:08x}"))));
            }
        }
    }
    Some((end, None))
}

/// The end of the last record the summary of a file with a footer indexes (chunks with their
/// message indexes, attachments, metadata), if it has a summary and that end is within the file.
fn indexed_end(bytes: &[u8]) -> Option<usize> {
    let summary = mcap::Summary::read(bytes).ok()??;
    let chunks = summary
        .chunk_indexes
        .iter()
        .map(|c| c.chunk_start_offset + c.chunk_length + c.message_index_length);
    let attachments = summary.attachment_indexes.iter().map(|a| a.offset + a.length);
    let metadata = summary.metadata_indexes.iter().map(|m| m.offset + m.length);
    let end = chunks.chain(attachments).chain(metadata).max()?;
    usize::try_from(end).ok().filter(|&e| e <= bytes.len())
}

/// What a file that is not a regular file is, in words.
fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if meta.is_dir() {
        "a folder"
    } else {
        "not a file"
    }
}

/// A recording loaded in memory and indexed in one pass.
pub struct Recording {
    path: PathBuf,
    bytes: Vec<u8>,
    channels: Vec<ChannelInfo>,
    metadata: BTreeMap<String, String>,
    scene_text: Option<String>,
    /// The command-line overrides applied to the scene (attachment `overrides.json`).
    scene_overrides: Option<Overrides>,
    /// Log and create time of the scene attachment.
    scene_times: (u64, u64),
    /// The file ends with a summary and the closing magic.
    finished: bool,
    /// Why reading stopped before the data end (a file cut short, e.g. by a killed recorder).
    truncated: Option<String>,
    /// The chunks whose CRC did not match, skipped with their records.
    damaged: Option<String>,
    expected: Expected,
}

impl Recording {
    /// Reads and indexes a recording. A file cut short (recorder killed) is accepted: everything
    /// up to the last complete record is available and [`Recording::truncated`] says where
    /// reading stopped.
    ///
    /// Only a regular file (after following links) is read, and no more of it than its size when
    /// opened: a device such as /dev/zero was read until memory ran out, and a FIFO blocked the
    /// reader forever (the check comes before opening, which would block on a FIFO).
    pub fn open(path: &Path) -> Result<Self, RecorderError> {
        use std::io::Read;
        let io = |detail: String| RecorderError::Io {
            path: path.to_path_buf(),
            detail,
        };
        let regular = |meta: &std::fs::Metadata| -> Result<u64, RecorderError> {
            if meta.is_file() {
                Ok(meta.len())
            } else {
                Err(io(format!(
                    "is not a regular file ({}): a recording is an .mcap file a run wrote",
                    file_kind(meta)
                )))
            }
        };
        regular(&std::fs::metadata(path).map_err(|e| io(format!("cannot read: {e}")))?)?;
        let file = std::fs::File::open(path).map_err(|e| io(format!("cannot read: {e}")))?;
        // What was opened may not be what was looked at (the name replaced in between).
        let len = regular(&file.metadata().map_err(|e| io(format!("cannot read: {e}")))?)?;
        let capacity =
            usize::try_from(len).map_err(|_| io(format!("is {len} bytes, more than this machine can address")))?;
        let mut bytes = Vec::new();
        bytes.try_reserve_exact(capacity).map_err(|_| {
            io(format!(
                "is {} MiB, more than this machine's memory can hold",
                len >> 20
            ))
        })?;
        // A file that grows while it is read is read as it was when opened.
        file.take(len)
            .read_to_end(&mut bytes)
            .map_err(|e| io(format!("cannot read: {e}")))?;
        Self::from_bytes(path, bytes)
    }

    /// As [`Recording::open`], from bytes already read (`path` names them in errors). Uncompressed
    /// chunks whose CRC does not match their records are skipped with their messages (and
    /// messages on channels declared in them), and [`Recording::damaged`] names them; reading
    /// goes on after them.
    pub fn from_bytes(path: &Path, mut bytes: Vec<u8>) -> Result<Self, RecorderError> {
        let footer = mcap::read::footer(&bytes).ok();
        // The `mcap` writer's own summary has summary offsets; the one the recorder writes after
        // every chunk has none (crate::durable).
        let finished = footer.is_some_and(|f| f.summary_offset_start != 0);
        // A recording that was not finalised holds what its summary indexes: what a reader that
        // starts from the footer reads. (Bytes past that are an append its recorder did not finish.)
        let mut unfinished = None;
        if footer.is_some() && !finished {
            if let Some(end) = indexed_end(&bytes) {
                unfinished = Some(format!(
                    "not finalised (its recorder stopped before the end of the run): read up to byte {end}, the \
                     end of the last chunk its summary indexes"
                ));
                bytes.truncate(end);
            }
        }
        let bad = damaged_chunks(&bytes);
        let damaged = (!bad.is_empty()).then(|| {
            let at: Vec<String> = bad.iter().map(|c| format!("byte {} ({})", c.start, c.why)).collect();
            format!(
                "{} damaged chunk(s), their messages skipped: at {}",
                bad.len(),
                at.join(", ")
            )
        });
        for c in bad.iter().rev() {
            bytes.drain(c.start..c.end);
        }
        let format = |detail: String| RecorderError::Format {
            path: path.to_path_buf(),
            detail,
        };
        let mut channels: BTreeMap<u16, ChannelInfo> = BTreeMap::new();
        let mut schemas: BTreeMap<u16, (String, String)> = BTreeMap::new();
        let mut metadata = BTreeMap::new();
        let mut scene_text = None;
        let mut scene_overrides = None;
        let mut scene_times = (0, 0);
        let mut truncated = None;
        let records = ChunkFlattener::new_with_options(&bytes, Options::IgnoreEndMagic | Options::ValidateChunkCrcs)
            .map_err(|e| format(format!("not an MCAP file: {e}")))?;
        for (records, record) in records.enumerate() {
            let record = match record {
                Ok(r) => r,
                Err(e) => {
                    if bytes.len() < 8 || !bytes.starts_with(mcap::MAGIC) {
                        return Err(format(format!("not an MCAP file: {e}")));
                    }
                    // A cut file or a damaged chunk (its CRC does not match): everything before it
                    // is read, nothing from it on.
                    truncated = Some(format!("{e} (after {records} records)"));
                    break;
                }
            };
            match record {
                Record::Schema { header, .. } => {
                    schemas.insert(header.id, (header.name, header.encoding));
                }
                Record::Channel(c) => {
                    let (schema_name, schema_encoding) = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                    channels.entry(c.id).or_insert(ChannelInfo {
                        id: c.id,
                        topic: c.topic,
                        schema_name,
                        schema_encoding,
                        message_encoding: c.message_encoding,
                        metadata: c.metadata,
                        messages: 0,
                    });
                }
                Record::Message { header, .. } => match channels.get_mut(&header.channel_id) {
                    Some(c) => c.messages += 1,
                    // Its channel was declared in a damaged chunk: skipped with it.
                    None if damaged.is_some() => {}
                    None => return Err(format(format!("message on unknown channel {}", header.channel_id))),
                },
                Record::Metadata(m) if m.name == METADATA_NAME => metadata = m.metadata,
                Record::Attachment { header, data, .. } if header.name == SCENE_ATTACHMENT => {
                    scene_times = (header.log_time, header.create_time);
                    scene_text = Some(
                        String::from_utf8(data.into_owned())
                            .map_err(|_| format("the scene attachment is not UTF-8".into()))?,
                    );
                }
                Record::Attachment { header, data, .. } if header.name == OVERRIDES_ATTACHMENT => {
                    scene_overrides = Some(serde_json::from_slice(&data).map_err(|e| {
                        format(format!(
                            "the attachment {OVERRIDES_ATTACHMENT} is not the overrides' JSON: {e}"
                        ))
                    })?);
                }
                Record::DataEnd(_) => break,
                _ => {}
            }
        }
        if unfinished.is_some() {
            // Reading stopped at the end of the indexed records, not at a damaged one.
            truncated = unfinished;
        }
        if metadata.is_empty() {
            return Err(format(format!(
                "no `{METADATA_NAME}` metadata record: not a glissade recording"
            )));
        }
        if let Some(of) = metadata.get(crate::foreign::EXPORT_OF) {
            return Err(format(format!(
                "a foreign-readable export (protobuf) of `{of}`, for other MCAP tools; glissade reads the \
                 original recording"
            )));
        }
        let fingerprint = metadata
            .get("scene_fingerprint")
            .and_then(|s| u64::from_str_radix(s, 16).ok())
            .ok_or_else(|| format("metadata: missing or malformed scene_fingerprint".into()))?;
        let run_id = metadata
            .get("run_id")
            .cloned()
            .ok_or_else(|| format("metadata: missing run_id".into()))?;
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
            channels: channels.into_values().collect(),
            metadata,
            scene_text,
            scene_overrides,
            scene_times,
            finished,
            truncated,
            damaged,
            expected: Expected {
                run_id,
                scene_fingerprint: fingerprint,
            },
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Channels in id order, with their message counts.
    pub fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    /// The `glissade` metadata record (run_id, scene, scene_fingerprint, software, schema_version, …).
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    pub fn run_id(&self) -> &str {
        &self.expected.run_id
    }

    pub fn scene_fingerprint(&self) -> u64 {
        self.expected.scene_fingerprint
    }

    /// The scene file recorded with the run.
    pub fn scene_text(&self) -> Option<&str> {
        self.scene_text.as_deref()
    }

    /// The command-line settings the run applied on top of [`Recording::scene_text`] (attachment
    /// `overrides.json`): the two rebuild the run's model (`glissade_scene::load_with`). None
    /// when the recording holds no such attachment.
    pub fn scene_overrides(&self) -> Option<&Overrides> {
        self.scene_overrides.as_ref()
    }

    /// Log and create time (ns since the Unix epoch) of the scene attachment; zeros without one.
    pub fn scene_times(&self) -> (u64, u64) {
        self.scene_times
    }

    /// The file was finalised (summary section and closing magic present).
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// Why reading stopped early: a file cut short (e.g. by a killed recorder).
    pub fn truncated(&self) -> Option<&str> {
        self.truncated.as_deref()
    }

    /// The chunks whose CRC did not match their content, skipped with their messages: where they
    /// are and both CRCs.
    pub fn damaged(&self) -> Option<&str> {
        self.damaged.as_deref()
    }

    /// Every message in file order (up to the point where a cut-short file stops reading; without
    /// the messages of damaged chunks, and of channels declared in them).
    pub fn messages(&self) -> impl Iterator<Item = RecordedMessage<'_>> + '_ {
        let topics: BTreeMap<u16, &str> = self.channels.iter().map(|c| (c.id, c.topic.as_str())).collect();
        ChunkFlattener::new_with_options(&self.bytes, Options::IgnoreEndMagic | Options::ValidateChunkCrcs)
            .into_iter()
            .flatten()
            .map_while(Result::ok)
            .take_while(|r| !matches!(r, Record::DataEnd(_)))
            .filter_map(move |r| match r {
                Record::Message { header, data } => Some(RecordedMessage {
                    topic: topics.get(&header.channel_id).copied()?,
                    channel: header.channel_id,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data,
                }),
                _ => None,
            })
    }

    /// Decodes a recorded message with the checks of the wire codec (this recording's run and
    /// scene, schema version, sizes).
    pub fn decode(&self, m: &RecordedMessage<'_>) -> Result<Message, DecodeError> {
        decode(&m.data, &self.expected)
    }
}
