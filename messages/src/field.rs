//! Fields and their buffers: [`Field`] (a dense column-major matrix, and its wire form), the
//! [`BufferPool`] that keeps field buffers for reuse, and the [`DecodeBuffers`] a decoder takes
//! them from (or reads fields in place from, [`HoldSource`]). The values themselves are in
//! `values.rs`.

use crate::{DecodeError, HeldBlock, Payload, Values};
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};

/// A dense column-major matrix: one row per boundary entry (or macro unknown), one column per
/// time point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Field {
    pub rows: u32,
    pub cols: u32,
    pub data: Values,
}

impl Field {
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows: rows as u32,
            cols: cols as u32,
            data: vec![0.0; rows * cols].into(),
        }
    }

    /// Builds a field from `f(row, col)`.
    pub fn from_fn(rows: usize, cols: usize, f: impl Fn(usize, usize) -> f64) -> Self {
        let mut data = Vec::with_capacity(rows * cols);
        for c in 0..cols {
            for r in 0..rows {
                data.push(f(r, c));
            }
        }
        Self {
            rows: rows as u32,
            cols: cols as u32,
            data: data.into(),
        }
    }

    #[inline]
    pub fn get(&self, r: usize, c: usize) -> f64 {
        self.data[c * self.rows as usize + r]
    }

    pub fn rows(&self) -> usize {
        self.rows as usize
    }

    pub fn cols(&self) -> usize {
        self.cols as usize
    }

    /// First (row, col, value) that is NaN or infinite.
    pub fn first_non_finite(&self) -> Option<(usize, usize, f64)> {
        let r = self.rows as usize;
        self.data
            .iter()
            .position(|v| !v.is_finite())
            .map(|k| (k % r.max(1), k / r.max(1), self.data[k]))
    }

    pub(crate) fn check(&self, what: &str) -> Result<(), DecodeError> {
        let expected = self.rows as u64 * self.cols as u64;
        if expected != self.data.len() as u64 {
            return Err(DecodeError::WrongSize {
                field: what.to_string(),
                rows: self.rows,
                cols: self.cols,
                len: self.data.len(),
            });
        }
        Ok(())
    }
}

/// Buffers of fields to hold new fields: a node's sent fields once delivered, or a receiver's
/// decoded fields once handled, so that multi-megabyte fields reuse memory instead of being
/// allocated (and their pages faulted in) at every iteration. At most [`BufferPool::CAPACITY`]
/// buffers are kept; a field takes the smallest one that fits and is at most twice its size (a
/// small field does not take a big field's buffer).
#[derive(Debug, Default)]
pub struct BufferPool {
    free: Vec<Vec<f64>>,
}

impl BufferPool {
    /// Most buffers kept (an interface node sends and receives one field per subdomain it serves).
    pub const CAPACITY: usize = 64;

    /// The pooled buffer for `len` values, if one fits.
    fn best(&mut self, len: usize) -> Option<Vec<f64>> {
        let i = self
            .free
            .iter()
            .enumerate()
            .filter(|(_, b)| (len..=2 * len).contains(&b.capacity()))
            .min_by_key(|(_, b)| b.capacity())
            .map(|(i, _)| i)?;
        Some(self.free.swap_remove(i))
    }

    /// An empty buffer with room for `len` values: pooled, or new.
    pub fn take_empty(&mut self, len: usize) -> Vec<f64> {
        match self.best(len) {
            Some(mut b) => {
                b.clear();
                b
            }
            None => Vec::with_capacity(len),
        }
    }

    /// A buffer of `len` values whatever they are, for a caller that overwrites them all: pooled
    /// (its old values, written only where it was shorter), or new (zeros).
    pub fn take_any(&mut self, len: usize) -> Vec<f64> {
        match self.best(len) {
            Some(mut b) => {
                b.truncate(len);
                b.resize(len, 0.0);
                b
            }
            None => vec![0.0; len],
        }
    }

    /// Keeps a buffer, if there is room.
    pub fn put(&mut self, buffer: Vec<f64>) {
        if self.free.len() < Self::CAPACITY && buffer.capacity() > 0 {
            self.free.push(buffer);
        }
    }

    /// Keeps the field buffers of a message's payload (delivered, or handled), up to the bound.
    pub fn recycle(&mut self, payload: Payload) {
        payload.into_buffers(|b| self.put(b));
    }

    /// Number of buffers held.
    pub fn len(&self) -> usize {
        self.free.len()
    }

    pub fn is_empty(&self) -> bool {
        self.free.is_empty()
    }
}

/// Where the decoder takes the buffers of the fields it decodes (bincode's decoding context):
/// a shared [`BufferPool`], or none (new buffers).
#[derive(Clone, Default)]
pub struct DecodeBuffers {
    pool: Option<Arc<Mutex<BufferPool>>>,
    /// Bytes of the payload being decoded: no field may claim more values than they hold (set by
    /// the decoder before it reads the payload).
    pub(crate) payload_bytes: usize,
    /// Blocks of the payload that a field's values may be read from in place ([`Self::holding`]).
    held: Option<Arc<dyn HoldSource>>,
}

impl std::fmt::Debug for DecodeBuffers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DecodeBuffers")
            .field("pool", &self.pool)
            .field("payload_bytes", &self.payload_bytes)
            .field("held", &self.held.is_some())
            .finish()
    }
}

/// Blocks of a received payload that fields may keep and read in place instead of copying them
/// ([`DecodeBuffers::holding`]), e.g. the shared-memory blocks a sender wrote fields into.
pub trait HoldSource: Send + Sync {
    /// The block whose bytes start at address `at` and are exactly `len` long, 8-byte aligned,
    /// if the payload has one.
    fn hold(&self, at: usize, len: usize) -> Option<Box<dyn HeldBlock>>;
}

impl DecodeBuffers {
    pub fn pooled(pool: Arc<Mutex<BufferPool>>) -> Self {
        Self {
            pool: Some(pool),
            ..Self::default()
        }
    }

    /// With `source`, a field whose values are exactly one of its blocks is read in place
    /// (held, [`Values::held`]) when the decoder reads from memory ([`crate::decode_from_slices`]).
    pub fn holding(mut self, source: Arc<dyn HoldSource>) -> Self {
        self.held = Some(source);
        self
    }

    /// Refuses a field of `len` values that the payload is too short to hold (a damaged length),
    /// before its buffer is allocated.
    fn check(&self, len: usize) -> Result<(), bincode::error::DecodeError> {
        if len.saturating_mul(8) > self.payload_bytes {
            return Err(bincode::error::DecodeError::OtherString(format!(
                "a field declares {len} values but the payload holds {} bytes",
                self.payload_bytes
            )));
        }
        Ok(())
    }

    /// A buffer for a field of `len` values.
    fn take(&self, len: usize) -> Vec<f64> {
        match &self.pool {
            // A poisoned pool (a panic while it was held) still holds valid buffers.
            Some(pool) => pool.lock().unwrap_or_else(|e| e.into_inner()).take_any(len),
            None => vec![0.0; len],
        }
    }
}

// The wire form of a field is that of serde's derive (rows, cols, the value count as a u64, the
// values as little-endian f64: `config` is little-endian), written and read here as one block of
// bytes instead of value by value: on a little-endian machine the values' memory is their wire
// form (elsewhere, value by value).
impl bincode::Encode for Field {
    fn encode<E: bincode::enc::Encoder>(&self, e: &mut E) -> Result<(), bincode::error::EncodeError> {
        use bincode::enc::write::Writer;
        self.rows.encode(e)?;
        self.cols.encode(e)?;
        self.data.len().encode(e)?;
        if cfg!(target_endian = "little") {
            e.writer().write(bytemuck::cast_slice(&self.data))
        } else {
            self.data.iter().try_for_each(|v| v.encode(e))
        }
    }
}

impl bincode::Decode<DecodeBuffers> for Field {
    fn decode<D: bincode::de::Decoder<Context = DecodeBuffers>>(
        d: &mut D,
    ) -> Result<Self, bincode::error::DecodeError> {
        use bincode::de::read::Reader;
        let rows = u32::decode(d)?;
        let cols = u32::decode(d)?;
        let len = usize::decode(d)?;
        // Checked against the payload's size and counted against the codec's limit before
        // anything is allocated.
        d.context().check(len)?;
        d.claim_container_read::<f64>(len)?;
        if cfg!(target_endian = "little") && len > 0 {
            if let Some(source) = d.context().held.clone() {
                let bytes = len * 8;
                let at = d.reader().peek_read(bytes).map(|b| b.as_ptr() as usize);
                if let Some(block) = at.and_then(|at| source.hold(at, bytes)) {
                    d.reader().consume(bytes);
                    return Ok(Field {
                        rows,
                        cols,
                        data: Values::held(block),
                    });
                }
            }
        }
        let mut data = d.context().take(len);
        if cfg!(target_endian = "little") {
            d.reader().read(bytemuck::cast_slice_mut(&mut data))?;
        } else {
            for v in &mut data {
                *v = f64::decode(d)?;
            }
        }
        Ok(Field {
            rows,
            cols,
            data: data.into(),
        })
    }
}

bincode::impl_borrow_decode_with_context!(Field, DecodeBuffers);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::config;
    use crate::fixtures::{expected, msg};
    use crate::{decode, decode_from_reader, encode};

    #[test]
    fn a_pooled_decode_reuses_the_buffers_of_handled_messages() {
        let m = msg();
        let bytes = encode(&m);
        let pool = Arc::new(Mutex::new(BufferPool::default()));
        let decode_pooled = || {
            decode_from_reader(
                &bytes[..],
                bytes.len(),
                &expected(),
                DecodeBuffers::pooled(pool.clone()),
            )
            .unwrap()
        };
        let first = decode_pooled();
        assert_eq!(first, m);
        // Handled: its buffers go back, dirty (and one longer than the field it will hold); the
        // next message's fields are decoded into them.
        let mut dirty = first.payload;
        if let Payload::BoundaryState { w, .. } = &mut dirty {
            w.data.iter_mut().for_each(|v| *v = f64::NAN);
            w.data.vec_mut().push(f64::NAN);
        }
        let at: Vec<*const f64> = match &dirty {
            Payload::BoundaryState { w, f, .. } => vec![w.data.as_ptr(), f.data.as_ptr()],
            _ => unreachable!(),
        };
        pool.lock().unwrap().recycle(dirty);
        assert_eq!(pool.lock().unwrap().len(), 2);
        let second = decode_pooled();
        assert_eq!(second, m);
        match &second.payload {
            Payload::BoundaryState { w, f, .. } => {
                let mut now = vec![w.data.as_ptr(), f.data.as_ptr()];
                now.sort();
                let mut before = at.clone();
                before.sort();
                assert_eq!(now, before);
            }
            _ => unreachable!(),
        }
        assert!(pool.lock().unwrap().is_empty());
    }

    #[test]
    fn a_damaged_field_length_is_refused_before_anything_is_allocated() {
        let m = msg();
        let mut bytes = encode(&m);
        // The payload: variant (u32), subdomain (u32), `to` (None: one byte), `interfaces` (length
        // u64 and one u32), then w's rows and cols (u32 each) and its value count (u64): claim
        // 2^27 or 2^28 values (1 or 2 GiB) in a message of under 200 bytes.
        let envelope = bincode::serde::encode_to_vec(&m.envelope, config()).unwrap().len();
        let at = envelope + 4 + 4 + 1 + (8 + 4) + 4 + 4;
        assert_eq!(bytes[at..at + 8], 6u64.to_le_bytes());
        for claim in [1u64 << 27, 1 << 28] {
            bytes[at..at + 8].copy_from_slice(&claim.to_le_bytes());
            let e = decode(&bytes, &expected()).unwrap_err();
            let said = format!(
                "a field declares {claim} values but the payload holds {} bytes",
                bytes.len() - envelope
            );
            assert!(e.to_string().contains(&said), "{e}");
        }
    }
}
