//! Encoding and decoding of messages: [`encode`] (and its variants into a given buffer or in
//! [`Piece`]s), [`decode`] (from bytes, a reader or slices in memory), with the checks of
//! docs/architecture.md: schema version, run, scene ([`Expected`]), trailing bytes and field sizes, each
//! refusal a [`DecodeError`] that says why.

use crate::{DecodeBuffers, Envelope, Message, Payload, SCHEMA_VERSION};

/// Why bytes could not be accepted as a message of this run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("schema version {got} is not this build's {expected}")]
    SchemaVersion { got: u32, expected: u32 },
    #[error("message of run `{got}`, expected run `{expected}`")]
    OtherRun { got: String, expected: String },
    #[error("message of scene {got:016x}, expected scene {expected:016x}")]
    OtherScene { got: u64, expected: u64 },
    #[error("{0} trailing bytes after the payload")]
    TrailingBytes(usize),
    #[error("field `{field}` declares {rows} × {cols} values but holds {len}")]
    WrongSize {
        field: String,
        rows: u32,
        cols: u32,
        len: usize,
    },
    #[error("malformed {part}: {detail}")]
    Malformed { part: &'static str, detail: String },
}

/// What a receiver expects of every message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Expected {
    pub run_id: String,
    pub scene_fingerprint: u64,
}

pub(crate) fn config() -> impl bincode::config::Config {
    bincode::config::standard()
        .with_little_endian()
        .with_fixed_int_encoding()
        .with_limit::<{ 1 << 31 }>()
}

/// Encodes envelope then payload.
pub fn encode(msg: &Message) -> Vec<u8> {
    // Sized first, then written once into a buffer of that size: a multi-MB field is copied
    // once, not regrown and moved as it is written.
    let mut out = Vec::with_capacity(encoded_len(msg));
    bincode::encode_into_std_write(&msg.envelope, &mut out, config()).expect("writing into a Vec never fails");
    bincode::encode_into_std_write(&msg.payload, &mut out, config()).expect("writing into a Vec never fails");
    out
}

/// The size of [`encode`]'s bytes, without encoding.
pub fn encoded_len(msg: &Message) -> usize {
    let mut size = bincode::enc::write::SizeWriter::default();
    bincode::encode_into_writer(&msg.envelope, &mut size, config()).expect("a size writer never fails");
    bincode::encode_into_writer(&msg.payload, &mut size, config()).expect("a size writer never fails");
    size.bytes_written
}

/// Writes [`encode`]'s bytes into `out` (a buffer the caller already has, e.g. in shared memory)
/// and returns how many; None if `out` is shorter than [`encoded_len`].
pub fn encode_into(msg: &Message, out: &mut [u8]) -> Option<usize> {
    let n = bincode::encode_into_slice(&msg.envelope, out, config()).ok()?;
    let m = bincode::encode_into_slice(&msg.payload, &mut out[n..], config()).ok()?;
    Some(n + m)
}

/// A part of a message's encoding ([`encode_pieces`]).
#[derive(Debug, PartialEq)]
pub enum Piece {
    /// Encoded bytes.
    Bytes(Vec<u8>),
    /// The values of the field whose lent block ([`crate::Values::lent`]) starts at this address, in
    /// their wire form: the block's memory itself.
    Block(usize),
}

/// [`encode`]'s bytes in pieces, with the values of every lent field block named by its address
/// instead of copied, so that a transport can send the blocks themselves: concatenated (each
/// block as its values' bytes), the pieces are [`encode`]'s bytes. On a big-endian machine,
/// where values are encoded one by one, there is no block piece.
pub fn encode_pieces(msg: &Message) -> Vec<Piece> {
    let mut blocks = Vec::new();
    msg.payload.fields(|f| {
        if f.data.is_lent() && !f.data.is_empty() {
            let bytes: &[u8] = bytemuck::cast_slice(&f.data);
            blocks.push((bytes.as_ptr() as usize, bytes.len()));
        }
    });
    let mut w = PieceWriter {
        blocks,
        pieces: Vec::new(),
        current: Vec::with_capacity(256),
    };
    bincode::encode_into_writer(&msg.envelope, &mut w, config()).expect("the piece writer never fails");
    bincode::encode_into_writer(&msg.payload, &mut w, config()).expect("the piece writer never fails");
    if !w.current.is_empty() {
        w.pieces.push(Piece::Bytes(w.current));
    }
    w.pieces
}

/// Collects [`encode_pieces`]: a write of exactly a lent block's bytes (a field's values, which
/// [`crate::Field`]'s encoding writes in one piece) becomes a block piece.
struct PieceWriter {
    blocks: Vec<(usize, usize)>,
    pieces: Vec<Piece>,
    current: Vec<u8>,
}

impl bincode::enc::write::Writer for PieceWriter {
    fn write(&mut self, bytes: &[u8]) -> Result<(), bincode::error::EncodeError> {
        let at = (bytes.as_ptr() as usize, bytes.len());
        if !bytes.is_empty() && self.blocks.contains(&at) {
            if !self.current.is_empty() {
                self.pieces.push(Piece::Bytes(std::mem::take(&mut self.current)));
            }
            self.pieces.push(Piece::Block(at.0));
        } else {
            self.current.extend_from_slice(bytes);
        }
        Ok(())
    }
}

/// A decoding error of `part` ("envelope" or "payload").
fn malformed(part: &'static str) -> impl Fn(bincode::error::DecodeError) -> DecodeError {
    move |e| DecodeError::Malformed {
        part,
        detail: e.to_string(),
    }
}

/// Reads the envelope at the start of `r`, checking the schema version and the run.
fn read_envelope<R: Source>(r: &mut Bounded<R>, run_id: &str) -> Result<Envelope, DecodeError> {
    let envelope: Envelope = bincode::decode_from_reader(r, config()).map_err(malformed("envelope"))?;
    if envelope.schema_version != SCHEMA_VERSION {
        return Err(DecodeError::SchemaVersion {
            got: envelope.schema_version,
            expected: SCHEMA_VERSION,
        });
    }
    if envelope.run_id != run_id {
        return Err(DecodeError::OtherRun {
            got: envelope.run_id,
            expected: run_id.to_string(),
        });
    }
    Ok(envelope)
}

/// Decodes only the envelope, checking the schema version and the run (for a receiver that
/// learns the scene fingerprint from the scene message itself).
pub fn peek_envelope(bytes: &[u8], run_id: &str) -> Result<Envelope, DecodeError> {
    read_envelope(
        &mut Bounded {
            inner: IoSource(bytes),
            left: bytes.len(),
        },
        run_id,
    )
}

/// Decodes and checks a message: schema version, run, scene, trailing bytes, field sizes.
pub fn decode(bytes: &[u8], expected: &Expected) -> Result<Message, DecodeError> {
    decode_from_reader(bytes, bytes.len(), expected, DecodeBuffers::default())
}

/// [`decode`] from a reader holding exactly `len` bytes (e.g. a transport's fragmented payload,
/// read where it lies instead of first being copied into one buffer), the fields' buffers taken
/// from `buffers`: the same checks, the same errors.
pub fn decode_from_reader(
    reader: impl std::io::Read,
    len: usize,
    expected: &Expected,
    buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    decode_bounded(
        Bounded {
            inner: IoSource(reader),
            left: len,
        },
        expected,
        buffers,
    )
}

/// [`decode_from_reader`] of a payload that lies in memory in `slices` (`len` bytes in all, e.g.
/// the fragments or pieces a transport received), read where they lie: a field whose values are
/// a block of `buffers`' hold source ([`DecodeBuffers::holding`]) keeps it instead of copying it.
pub fn decode_from_slices<'a>(
    slices: impl IntoIterator<Item = &'a [u8]>,
    len: usize,
    expected: &Expected,
    buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    let inner = Slices {
        slices: slices.into_iter().collect(),
        k: 0,
        at: 0,
    };
    decode_bounded(Bounded { inner, left: len }, expected, buffers)
}

fn decode_bounded<R: Source>(
    mut r: Bounded<R>,
    expected: &Expected,
    mut buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    let envelope = read_envelope(&mut r, &expected.run_id)?;
    if envelope.scene_fingerprint != expected.scene_fingerprint {
        return Err(DecodeError::OtherScene {
            got: envelope.scene_fingerprint,
            expected: expected.scene_fingerprint,
        });
    }
    buffers.payload_bytes = r.left;
    let mut decoder = bincode::de::DecoderImpl::new(&mut r, config(), buffers);
    let payload = <Payload as bincode::Decode<DecodeBuffers>>::decode(&mut decoder).map_err(malformed("payload"))?;
    if r.left != 0 {
        return Err(DecodeError::TrailingBytes(r.left));
    }
    payload.check()?;
    Ok(Message { envelope, payload })
}

/// A reader of `left` more bytes, that refuses a read past them before reading
/// (`UnexpectedEnd`, with the bytes missing, as bincode's slice reader words it).
struct Bounded<R> {
    inner: R,
    left: usize,
}

/// What [`Bounded`] reads from: bytes in order, and where they lie in memory, a look at the next
/// ones without copying them.
trait Source: std::io::Read {
    /// The next `n` bytes, if they lie together in memory.
    fn peek(&self, n: usize) -> Option<&[u8]>;
    /// Moves past `n` bytes [`Source::peek`] showed.
    fn skip(&mut self, n: usize);
}

/// A [`Source`] over any reader: no look ahead.
struct IoSource<R>(R);

impl<R: std::io::Read> std::io::Read for IoSource<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl<R: std::io::Read> Source for IoSource<R> {
    fn peek(&self, _: usize) -> Option<&[u8]> {
        None
    }

    fn skip(&mut self, _: usize) {
        unreachable!("nothing was peeked")
    }
}

/// A [`Source`] over a payload's slices in memory, one after the other (e.g. the fragments a
/// transport received, or the pieces of a message sent with its fields' blocks).
struct Slices<'a> {
    slices: Vec<&'a [u8]>,
    /// The current slice and the position in it.
    k: usize,
    at: usize,
}

impl std::io::Read for Slices<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut n = 0;
        while n < buf.len() && self.k < self.slices.len() {
            let rest = &self.slices[self.k][self.at..];
            let m = rest.len().min(buf.len() - n);
            buf[n..n + m].copy_from_slice(&rest[..m]);
            n += m;
            self.advance(m);
        }
        Ok(n)
    }
}

impl Slices<'_> {
    /// Moves `n` bytes on within the current slice, to the next slice at its end.
    fn advance(&mut self, n: usize) {
        self.at += n;
        if self.at == self.slices[self.k].len() {
            (self.k, self.at) = (self.k + 1, 0);
        }
    }
}

impl Source for Slices<'_> {
    fn peek(&self, n: usize) -> Option<&[u8]> {
        self.slices.get(self.k).and_then(|s| s[self.at..].get(..n))
    }

    fn skip(&mut self, n: usize) {
        self.advance(n);
    }
}

impl<R: Source> bincode::de::read::Reader for Bounded<R> {
    fn read(&mut self, bytes: &mut [u8]) -> Result<(), bincode::error::DecodeError> {
        if bytes.len() > self.left {
            return Err(bincode::error::DecodeError::UnexpectedEnd {
                additional: bytes.len() - self.left,
            });
        }
        self.inner
            .read_exact(bytes)
            .map_err(|inner| bincode::error::DecodeError::Io {
                inner,
                additional: bytes.len(),
            })?;
        self.left -= bytes.len();
        Ok(())
    }

    fn peek_read(&mut self, n: usize) -> Option<&[u8]> {
        if n > self.left {
            return None;
        }
        self.inner.peek(n)
    }

    fn consume(&mut self, n: usize) {
        self.inner.skip(n);
        self.left -= n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::{expected, msg};
    use crate::{Field, HeldBlock, HoldSource, Values};
    use std::sync::Arc;

    /// The values of lent fields are named in place by [`encode_pieces`], not copied, and the
    /// pieces put together are [`encode`]'s bytes; without lent fields there is one piece.
    #[test]
    fn pieces_put_together_are_the_encoding() {
        let plain = msg();
        assert_eq!(encode_pieces(&plain), vec![Piece::Bytes(encode(&plain))]);
        let mut lent = msg();
        let Payload::BoundaryState { w, f, .. } = &mut lent.payload else {
            unreachable!()
        };
        for field in [w, f] {
            field.data = Values::lent(Box::new(field.data.to_vec()));
        }
        let Payload::BoundaryState { w, f, .. } = &lent.payload else {
            unreachable!()
        };
        let at = |f: &Field| f.data.as_ptr() as usize;
        let pieces = encode_pieces(&lent);
        assert!(
            matches!(&pieces[..], [Piece::Bytes(_), Piece::Block(a), Piece::Bytes(_), Piece::Block(b)] if *a == at(w) && *b == at(f)),
            "{pieces:?}"
        );
        let mut joined = Vec::new();
        for p in &pieces {
            match p {
                Piece::Bytes(b) => joined.extend_from_slice(b),
                Piece::Block(a) => {
                    let field = if *a == at(w) { w } else { f };
                    joined.extend_from_slice(bytemuck::cast_slice(&field.data));
                }
            }
        }
        assert_eq!(joined, encode(&plain));
        assert_eq!(encode(&lent), encode(&plain), "a lent field encodes as an owned one");
    }

    /// A hold source over one block of values.
    struct OneBlock(Arc<Vec<f64>>);

    impl HoldSource for OneBlock {
        fn hold(&self, at: usize, len: usize) -> Option<Box<dyn HeldBlock>> {
            (at == self.0.as_ptr() as usize && len == 8 * self.0.len())
                .then(|| Box::new(self.0.clone()) as Box<dyn HeldBlock>)
        }
    }

    /// Decoding a payload from its slices reads a field whose values are exactly a block of the
    /// hold source in place and copies the others; the message and the refusals are those of
    /// [`decode`].
    #[test]
    fn a_field_that_is_a_held_block_is_read_in_place() {
        let m = msg();
        let Payload::BoundaryState { w, .. } = &m.payload else {
            unreachable!()
        };
        let block = Arc::new(w.data.to_vec());
        let bytes = encode(&m);
        let w_bytes: &[u8] = bytemuck::cast_slice(&block[..]);
        let at = bytes
            .windows(w_bytes.len())
            .position(|x| x == w_bytes)
            .expect("w's values");
        let end = at + w_bytes.len();
        let slices = [&bytes[..at], w_bytes, &bytes[end..]];
        let holding = || DecodeBuffers::default().holding(Arc::new(OneBlock(block.clone())));
        let got = decode_from_slices(slices, bytes.len(), &expected(), holding()).unwrap();
        assert_eq!(got, m);
        let Payload::BoundaryState { w, f, .. } = &got.payload else {
            unreachable!()
        };
        assert!(w.data.is_held() && w.data.as_ptr() == block.as_ptr(), "w read in place");
        assert!(!f.data.is_held(), "f is no block of the source");
        // Without a hold source, or from other slices, the values are copied.
        let copied = decode_from_slices(slices, bytes.len(), &expected(), DecodeBuffers::default()).unwrap();
        copied.payload.fields(|f| assert!(!f.data.is_held()));
        let other = bytes[at..end].to_vec();
        let apart = decode_from_slices(
            [&bytes[..at], &other, &bytes[end..]],
            bytes.len(),
            &expected(),
            holding(),
        );
        apart.unwrap().payload.fields(|f| assert!(!f.data.is_held()));
        // Cut short after the block: refused as decode refuses it.
        let short = [&bytes[..at], w_bytes, &bytes[end..bytes.len() - 1]];
        assert_eq!(
            decode_from_slices(short, bytes.len() - 1, &expected(), holding()).unwrap_err(),
            decode(&bytes[..bytes.len() - 1], &expected()).unwrap_err()
        );
    }

    #[test]
    fn round_trip() {
        let m = msg();
        let bytes = encode(&m);
        assert_eq!(decode(&bytes, &expected()).unwrap(), m);
        // The wire format: the envelope's bincode encoding, then the payload's.
        let mut parts = bincode::serde::encode_to_vec(&m.envelope, config()).unwrap();
        parts.extend(bincode::serde::encode_to_vec(&m.payload, config()).unwrap());
        assert_eq!(bytes, parts);
    }

    #[test]
    fn encoding_into_a_given_buffer_writes_the_same_bytes() {
        let m = msg();
        let bytes = encode(&m);
        assert_eq!(encoded_len(&m), bytes.len());
        // A buffer with room to spare (a shared-memory chunk may be rounded up): the same bytes
        // at its start, and the count of them.
        let mut out = vec![0xAA_u8; bytes.len() + 5];
        assert_eq!(encode_into(&m, &mut out), Some(bytes.len()));
        assert_eq!(&out[..bytes.len()], &bytes[..]);
        assert!(out[bytes.len()..].iter().all(|&b| b == 0xAA));
        // One byte short: refused, not truncated.
        assert_eq!(encode_into(&m, &mut vec![0u8; bytes.len() - 1]), None);
    }

    #[test]
    fn rejections_say_why() {
        let m = msg();
        let bytes = encode(&m);
        let e = decode(
            &bytes,
            &Expected {
                run_id: "other".into(),
                scene_fingerprint: 7,
            },
        )
        .unwrap_err();
        assert!(matches!(e, DecodeError::OtherRun { .. }), "{e}");
        let e = decode(
            &bytes,
            &Expected {
                run_id: "r1".into(),
                scene_fingerprint: 8,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("scene"), "{e}");
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode(&longer, &expected()).unwrap_err(), DecodeError::TrailingBytes(1));
        let e = decode(&bytes[..bytes.len() - 3], &expected()).unwrap_err();
        assert!(matches!(e, DecodeError::Malformed { part: "payload", .. }), "{e}");
        let mut v2 = m.clone();
        v2.envelope.schema_version = SCHEMA_VERSION + 1;
        let e = decode(&encode(&v2), &expected()).unwrap_err();
        assert!(matches!(e, DecodeError::SchemaVersion { .. }), "{e}");
        let mut bad = m.clone();
        if let Payload::BoundaryState { w, .. } = &mut bad.payload {
            w.data.vec_mut().pop();
        }
        let e = decode(&encode(&bad), &expected()).unwrap_err();
        assert!(
            e.to_string().contains("field `w` declares 3 × 2 values but holds 5"),
            "{e}"
        );
    }
}
