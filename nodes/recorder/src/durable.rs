//! The recording file, a complete MCAP file after every chunk.
//!
//! The `mcap` writer writes into memory ([`Pending`]); whenever a chunk is closed, the recorder
//! appends its bytes to the file together with a summary section and footer indexing every chunk
//! so far ([`Index::tail`]), replacing the previous ones. An MCAP reader that starts from the
//! footer (Python `mcap`'s `make_reader` on a file does: it never falls back to reading the data
//! section when the footer is bad) so finds a valid summary whatever moment the recorder is
//! killed at, and reads every chunk whose append completed.
//!
//! The append ([`DurableFile::append`]) is ordered so that the file's last 37 bytes are a footer
//! pointing at an intact summary after every write, whatever part of that write reached the file.
//! (Linux copies a write into the page cache page by page and checks for a fatal signal, and
//! allocates space, before each page: a SIGKILL or a full disk cuts a write at a page boundary of
//! the file, or fails it whole.)
//! 1. a footer pointing at the current summary (and the closing magic) is written beyond every
//!    byte the next steps touch, at a 64-byte-aligned end, so that it never spans two pages: the
//!    file grows by a hole and ends with a valid footer;
//! 2. a copy of the current summary is written just before that footer;
//! 3. the footer is pointed at the copy (29 bytes in place);
//! 4. the new chunk and the new summary and footer are written over the old summary;
//! 5. the file is cut after the new footer.
//!
//! After step 5 the file is byte for byte what the `mcap` writer writes; after `finish` the summary
//! is the writer's own (with statistics and summary offsets). An intermediate summary has no
//! summary offsets (footer `summary_offset_start` 0): that marks a recording that was not
//! finalised.

use binrw::BinWriterExt;
use mcap::records::{self, op};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, Cursor, Seek, SeekFrom, Write};
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::sync::{Arc, Mutex};

/// Footer record (opcode, length, 20 bytes) and closing magic.
const FOOTER_RECORD: usize = 1 + 8 + 20;
const FOOTER_AND_MAGIC: usize = FOOTER_RECORD + 8;

/// What the `mcap` writer wrote since the last append, in memory; positions are file offsets
/// (`base` is the file offset of the first byte held).
#[derive(Clone, Default)]
pub(crate) struct Pending(Arc<Mutex<Buffer>>);

#[derive(Default)]
struct Buffer {
    bytes: Vec<u8>,
    base: u64,
    pos: u64,
}

impl Pending {
    fn lock(&self) -> std::sync::MutexGuard<'_, Buffer> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Hands the bytes held and their file offset to `f`, then empties the buffer, which then
    /// starts where they end (also when `f` fails: a failed append ends the recording).
    pub(crate) fn drain<R>(&self, f: impl FnOnce(u64, &[u8]) -> R) -> R {
        let mut b = self.lock();
        let r = f(b.base, &b.bytes);
        b.base += b.bytes.len() as u64;
        b.pos = b.base;
        b.bytes.clear();
        r
    }
}

impl Write for Pending {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut b = self.lock();
        let at = (b.pos - b.base) as usize;
        let end = at + buf.len();
        if at == b.bytes.len() {
            b.bytes.extend_from_slice(buf);
        } else {
            if end > b.bytes.len() {
                b.bytes.resize(end, 0);
            }
            b.bytes[at..end].copy_from_slice(buf);
        }
        b.pos += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Seek for Pending {
    /// Within the bytes held only: the writer seeks back into the chunk it writes, never into
    /// what was appended to the file.
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let mut b = self.lock();
        let end = b.base + b.bytes.len() as u64;
        let target = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => end.checked_add_signed(d),
            SeekFrom::Current(d) => b.pos.checked_add_signed(d),
        };
        match target {
            Some(p) if (b.base..=end).contains(&p) => {
                b.pos = p;
                Ok(p)
            }
            _ => Err(io::Error::other(format!(
                "seek to {to:?} outside the bytes not yet appended ({}..{end})",
                b.base
            ))),
        }
    }
}

/// A summary section and footer to write after the data section.
pub(crate) struct Tail {
    /// DataEnd, summary records, (summary offsets,) footer, magic.
    pub bytes: Vec<u8>,
    /// The summary records (what a copy holds), within `bytes`.
    pub summary: Range<usize>,
}

/// What the summary of the file says: every schema and channel, the chunks, attachments and
/// metadata records appended, and the statistics of the messages in those chunks.
#[derive(Default)]
pub(crate) struct Index {
    schemas: BTreeMap<u16, (String, String, Vec<u8>)>,
    channels: BTreeMap<u16, records::Channel>,
    chunks: Vec<records::ChunkIndex>,
    attachments: Vec<records::AttachmentIndex>,
    metadata: Vec<records::MetadataIndex>,
    counts: BTreeMap<u16, u64>,
}

fn le_u64(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

fn bad(detail: String) -> io::Error {
    io::Error::other(detail)
}

impl Index {
    pub(crate) fn add_schema(&mut self, id: u16, name: &str, encoding: &str, data: &[u8]) {
        self.schemas
            .insert(id, (name.to_string(), encoding.to_string(), data.to_vec()));
    }

    pub(crate) fn add_channel(&mut self, channel: records::Channel) {
        self.channels.insert(channel.id, channel);
    }

    /// Messages per channel in the chunks about to be appended.
    pub(crate) fn add_messages(&mut self, counts: &BTreeMap<u16, u64>) {
        for (&c, &n) in counts {
            *self.counts.entry(c).or_default() += n;
        }
    }

    /// Indexes the records of `bytes`, which start at file offset `base` (with the leading magic
    /// when `base` is 0): chunks with their message indexes, attachments, metadata.
    pub(crate) fn scan(&mut self, base: u64, bytes: &[u8]) -> io::Result<()> {
        let mut pos = if base == 0 { mcap::MAGIC.len() } else { 0 };
        while pos < bytes.len() {
            let opcode = bytes[pos];
            let len = le_u64(bytes, pos + 1).ok_or_else(|| bad(format!("record header cut at {pos}")))?;
            let body = pos + 9;
            let end = usize::try_from(len)
                .ok()
                .and_then(|l| body.checked_add(l))
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| bad(format!("record at {} runs past the bytes written", base + pos as u64)))?;
            let offset = base + pos as u64;
            let length = (end - pos) as u64;
            let parse = || mcap::parse_record(opcode, &bytes[body..end]).map_err(|e| bad(e.to_string()));
            match opcode {
                op::CHUNK => {
                    let mcap::records::Record::Chunk { header, .. } = parse()? else {
                        unreachable!("a chunk opcode parses as a chunk")
                    };
                    self.chunks.push(records::ChunkIndex {
                        message_start_time: header.message_start_time,
                        message_end_time: header.message_end_time,
                        chunk_start_offset: offset,
                        chunk_length: length,
                        message_index_offsets: BTreeMap::new(),
                        message_index_length: 0,
                        compression: header.compression,
                        compressed_size: header.compressed_size,
                        uncompressed_size: header.uncompressed_size,
                    });
                }
                op::MESSAGE_INDEX => {
                    let channel = bytes
                        .get(body..body + 2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]]))
                        .ok_or_else(|| bad(format!("message index at {offset} is empty")))?;
                    let chunk = self
                        .chunks
                        .last_mut()
                        .ok_or_else(|| bad(format!("message index at {offset} before any chunk")))?;
                    chunk.message_index_offsets.insert(channel, offset);
                    chunk.message_index_length += length;
                }
                op::METADATA => {
                    let mcap::records::Record::Metadata(m) = parse()? else {
                        unreachable!("a metadata opcode parses as metadata")
                    };
                    self.metadata.push(records::MetadataIndex {
                        offset,
                        length,
                        name: m.name,
                    });
                }
                op::ATTACHMENT => {
                    let mcap::records::Record::Attachment { header, data, .. } = parse()? else {
                        unreachable!("an attachment opcode parses as an attachment")
                    };
                    self.attachments.push(records::AttachmentIndex {
                        offset,
                        length,
                        log_time: header.log_time,
                        create_time: header.create_time,
                        data_size: data.len() as u64,
                        name: header.name,
                        media_type: header.media_type,
                    });
                }
                _ => {}
            }
            pos = end;
        }
        Ok(())
    }

    fn statistics(&self) -> records::Statistics {
        let times = self
            .chunks
            .iter()
            .filter(|c| c.message_end_time > 0 || c.message_start_time > 0);
        records::Statistics {
            message_count: self.counts.values().sum(),
            schema_count: self.schemas.len() as u16,
            channel_count: self.channels.len() as u32,
            attachment_count: self.attachments.len() as u32,
            metadata_count: self.metadata.len() as u32,
            chunk_count: self.chunks.len() as u32,
            message_start_time: times.clone().map(|c| c.message_start_time).min().unwrap_or(0),
            message_end_time: times.map(|c| c.message_end_time).max().unwrap_or(0),
            channel_message_counts: self.counts.clone(),
        }
    }

    /// DataEnd, the summary (schemas, channels, statistics, chunk, attachment and metadata
    /// indexes), a footer and the closing magic, for a data section ending at file offset `at`.
    pub(crate) fn tail(&self, at: u64) -> Tail {
        let mut b = Vec::with_capacity(4096);
        record(&mut b, op::DATA_END, &records::DataEnd { data_section_crc: 0 });
        let start = b.len();
        for (&id, (name, encoding, data)) in &self.schemas {
            let mut body = Vec::new();
            Cursor::new(&mut body)
                .write_le(&records::SchemaHeader {
                    id,
                    name: name.clone(),
                    encoding: encoding.clone(),
                })
                .expect("writing a record into a Vec never fails");
            body.extend_from_slice(&(data.len() as u32).to_le_bytes());
            body.extend_from_slice(data);
            frame(&mut b, op::SCHEMA, &body);
        }
        for c in self.channels.values() {
            record(&mut b, op::CHANNEL, c);
        }
        record(&mut b, op::STATISTICS, &self.statistics());
        for c in &self.chunks {
            record(&mut b, op::CHUNK_INDEX, c);
        }
        for a in &self.attachments {
            record(&mut b, op::ATTACHMENT_INDEX, a);
        }
        for m in &self.metadata {
            record(&mut b, op::METADATA_INDEX, m);
        }
        let end = b.len();
        b.extend_from_slice(&footer(at + start as u64));
        b.extend_from_slice(mcap::MAGIC);
        Tail {
            bytes: b,
            summary: start..end,
        }
    }
}

fn frame(out: &mut Vec<u8>, opcode: u8, body: &[u8]) {
    out.push(opcode);
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
}

fn record<T>(out: &mut Vec<u8>, opcode: u8, r: &T)
where
    T: for<'a> binrw::BinWrite<Args<'a> = ()>,
{
    let mut body = Vec::new();
    Cursor::new(&mut body)
        .write_le(r)
        .expect("writing a record into a Vec never fails");
    frame(out, opcode, &body);
}

/// A footer record whose summary starts at `summary_start` (no summary offsets, no CRC).
fn footer(summary_start: u64) -> [u8; FOOTER_RECORD] {
    let mut f = [0u8; FOOTER_RECORD];
    f[0] = op::FOOTER;
    f[1..9].copy_from_slice(&20u64.to_le_bytes());
    f[9..17].copy_from_slice(&summary_start.to_le_bytes());
    f
}

/// Where a simulated kill stops the writes to the file (tests): after `ops` complete writes or
/// truncations, `bytes` bytes of the next write.
#[cfg(test)]
#[derive(Debug, Clone, Copy)]
pub(crate) struct Kill {
    pub ops: usize,
    pub bytes: usize,
}

/// The recording file: data section, then a summary and footer ([`Tail`]) that index it.
pub(crate) struct DurableFile {
    file: File,
    /// Where the data section ends (the tail's DataEnd record starts).
    data_end: u64,
    tail: Vec<u8>,
    summary: Range<usize>,
    #[cfg(test)]
    pub(crate) kill: Option<Kill>,
    /// Writes and truncations done (tests count them to place a simulated kill), and the length
    /// of each (0 for a truncation).
    #[cfg(test)]
    pub(crate) ops: usize,
    #[cfg(test)]
    pub(crate) trace: Vec<(usize, u64)>,
}

impl DurableFile {
    /// Writes `head` (magic, header, first records) and `tail` to the empty `file`.
    pub(crate) fn create(file: File, head: &[u8], tail: Tail) -> io::Result<Self> {
        let mut me = Self {
            file,
            data_end: head.len() as u64,
            tail: Vec::new(),
            summary: 0..0,
            #[cfg(test)]
            kill: None,
            #[cfg(test)]
            ops: 0,
            #[cfg(test)]
            trace: Vec::new(),
        };
        let mut all = head.to_vec();
        all.extend_from_slice(&tail.bytes);
        me.write_at(&all, 0)?;
        me.tail = tail.bytes;
        me.summary = tail.summary;
        Ok(me)
    }

    /// The file's length.
    pub(crate) fn len(&self) -> u64 {
        self.data_end + self.tail.len() as u64
    }

    /// Where the data section ends: `data` of the next [`DurableFile::append`] goes there.
    pub(crate) fn data_end(&self) -> u64 {
        self.data_end
    }

    fn write_at(&mut self, buf: &[u8], at: u64) -> io::Result<()> {
        #[cfg(test)]
        {
            self.ops += 1;
            self.trace.push((buf.len(), at));
            if let Some(k) = self.kill.filter(|k| self.ops > k.ops) {
                // The write the kill interrupts keeps its first bytes; nothing after it happens.
                if self.ops == k.ops + 1 {
                    self.file.write_all_at(&buf[..k.bytes.min(buf.len())], at)?;
                }
                return Err(io::Error::other(SIMULATED_KILL));
            }
        }
        self.file.write_all_at(buf, at)
    }

    fn set_len(&mut self, len: u64) -> io::Result<()> {
        #[cfg(test)]
        {
            self.ops += 1;
            self.trace.push((0, len));
            if self.kill.is_some_and(|k| self.ops > k.ops) {
                return Err(io::Error::other(SIMULATED_KILL));
            }
        }
        self.file.set_len(len)
    }

    /// Appends `data` (complete records) to the data section and replaces the tail by `tail`
    /// (built for a data section ending at `data_end() + data.len()`), in the order the module
    /// documentation gives. On failure the file is put back as it was (the previous data section
    /// and tail) when possible; it is a valid MCAP file either way.
    pub(crate) fn append(&mut self, data: &[u8], tail: Tail) -> io::Result<()> {
        let old_len = self.len();
        match self.steps(data, &tail) {
            Ok(()) => {
                self.data_end += data.len() as u64;
                self.tail = tail.bytes;
                self.summary = tail.summary;
                Ok(())
            }
            Err(e) => {
                #[cfg(test)]
                if e.to_string() == SIMULATED_KILL {
                    return Err(e);
                }
                // The old tail goes back over the blocks it had (no new space needed) and the
                // file back to its old length.
                let restored = self
                    .file
                    .write_all_at(&self.tail, self.data_end)
                    .and_then(|()| self.file.set_len(old_len));
                match restored {
                    Ok(()) => Err(e),
                    Err(r) => Err(io::Error::new(
                        e.kind(),
                        format!("{e} (and putting the previous summary back failed: {r}; the footer points at a copy of it)"),
                    )),
                }
            }
        }
    }

    fn steps(&mut self, data: &[u8], tail: &Tail) -> io::Result<()> {
        let t = self.data_end;
        let old_len = self.len();
        let new_len = t + (data.len() + tail.bytes.len()) as u64;
        let summary = self.tail[self.summary.clone()].to_vec();
        let end = (old_len.max(new_len) + (summary.len() + FOOTER_AND_MAGIC) as u64).next_multiple_of(64);
        let footer_at = end - FOOTER_AND_MAGIC as u64;
        let copy_at = footer_at - summary.len() as u64;
        // 1. The file ends with a footer pointing at the current summary.
        let mut first = footer(t + self.summary.start as u64).to_vec();
        first.extend_from_slice(mcap::MAGIC);
        self.write_at(&first, footer_at)?;
        // 2., 3. A copy of the current summary, and the footer pointing at it.
        self.write_at(&summary, copy_at)?;
        self.write_at(&footer(copy_at), footer_at)?;
        // 4. The new records and tail over the old tail.
        self.write_at(data, t)?;
        self.write_at(&tail.bytes, t + data.len() as u64)?;
        // 5. The file ends with the new tail.
        self.set_len(new_len)
    }
}

#[cfg(test)]
const SIMULATED_KILL: &str = "simulated kill";
