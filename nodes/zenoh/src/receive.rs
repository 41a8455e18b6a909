//! Receiving: a message as it arrived ([`Received`]), decoded where its payload's slices lie
//! (fields read in place from the sender's shared-memory blocks, [`PayloadBlocks`]), its hash to
//! recognise repeats ([`message_hash`]), and the cutting of arrivals into batches without
//! repeats.

pub use glissade_messages::message_hash;
use glissade_messages::{decode, decode_from_slices, DecodeBuffers, DecodeError, Expected, Message};
use glissade_messages::{message_hash_parts, MESSAGE_HASH_END};
use std::collections::HashSet;
use std::sync::Arc;

/// A message as it arrived: its key, its hash ([`message_hash`]: repeats are recognised by it),
/// and the message decoded, or why it was not.
pub(crate) struct Received {
    pub(crate) key: String,
    pub(crate) hash: u64,
    pub(crate) message: Result<Message, DecodeError>,
}

impl Received {
    /// The message's iteration (0 when it did not decode).
    pub(crate) fn iteration(&self) -> u32 {
        self.message.as_ref().map_or(0, |m| m.envelope.iteration)
    }

    pub(crate) fn from_bytes(key: String, bytes: &[u8], expected: &Expected) -> Self {
        Self {
            hash: message_hash(&key, bytes),
            message: decode(bytes, expected),
            key,
        }
    }

    /// Decodes a sample's payload where it lies, fragments and all (a large message over TCP
    /// arrives in many), instead of first copying it into one buffer.
    pub(crate) fn from_payload(
        key: String,
        payload: &zenoh::bytes::ZBytes,
        expected: &Expected,
        buffers: DecodeBuffers,
    ) -> Self {
        Self {
            hash: payload_hash(&key, payload),
            message: decode_payload(payload, expected, buffers),
            key,
        }
    }
}

/// [`message_hash`] of a payload that arrived on `key`, read across its slices (fragments, or the
/// blocks of a message sent with [`crate::publish_lent`]) without joining them.
pub fn payload_hash(key: &str, payload: &zenoh::bytes::ZBytes) -> u64 {
    let slices: Vec<&[u8]> = payload.slices().collect();
    let head: Vec<u8> = slices
        .iter()
        .flat_map(|s| s.iter())
        .take(MESSAGE_HASH_END)
        .copied()
        .collect();
    let mut tail: Vec<u8> = slices
        .iter()
        .rev()
        .flat_map(|s| s.iter().rev())
        .take(MESSAGE_HASH_END)
        .copied()
        .collect();
    tail.reverse();
    message_hash_parts(key, payload.len(), &head, &tail)
}

/// A payload decoded where its slices lie, into `buffers`.
pub fn decode_payload(
    payload: &zenoh::bytes::ZBytes,
    expected: &Expected,
    buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    decode_from_slices(payload.slices(), payload.len(), expected, buffers)
}

/// The blocks of a received payload that its fields may be read from in place: its slices of
/// [`PayloadBlocks::MIN`] bytes or more, 8-byte aligned. Over a link a large message arrives in
/// fragments smaller than that; such slices are the shared-memory blocks a sender wrote its
/// fields into ([`crate::publish_lent`]). A field that keeps one holds the sender's block until the
/// field is dropped (once its node has handled the message).
pub(crate) struct PayloadBlocks {
    payload: zenoh::bytes::ZBytes,
    /// Address, length and index of each block among the payload's slices.
    blocks: Vec<(usize, usize, usize)>,
}

impl PayloadBlocks {
    /// Larger than any batch of a link (64 KiB at most).
    const MIN: usize = 1 << 16;

    pub(crate) fn of(payload: &zenoh::bytes::ZBytes) -> Option<Self> {
        let blocks: Vec<_> = payload
            .slices()
            .enumerate()
            .filter(|(_, s)| s.len() >= Self::MIN && (s.as_ptr() as usize).is_multiple_of(8))
            .map(|(k, s)| (s.as_ptr() as usize, s.len(), k))
            .collect();
        (!blocks.is_empty()).then(|| Self {
            payload: payload.clone(),
            blocks,
        })
    }

    /// `buffers` that read `payload`'s blocks in place, if it has any.
    pub(crate) fn holding(buffers: DecodeBuffers, payload: &zenoh::bytes::ZBytes) -> DecodeBuffers {
        match Self::of(payload) {
            Some(blocks) => buffers.holding(Arc::new(blocks)),
            None => buffers,
        }
    }
}

impl glissade_messages::HoldSource for PayloadBlocks {
    fn hold(&self, at: usize, len: usize) -> Option<Box<dyn glissade_messages::HeldBlock>> {
        let &(_, _, k) = self.blocks.iter().find(|&&(a, n, _)| a == at && n == len)?;
        Some(Box::new(HeldSlice {
            payload: self.payload.clone(),
            k,
        }))
    }
}

/// A field's values read in place: slice `k` of a received payload (kept alive by it).
struct HeldSlice {
    payload: zenoh::bytes::ZBytes,
    k: usize,
}

impl glissade_messages::HeldBlock for HeldSlice {
    fn values(&self) -> &[f64] {
        // Checked aligned and of a whole number of values when the block was taken.
        bytemuck::cast_slice(
            self.payload
                .slices()
                .nth(self.k)
                .expect("slice k was found among this payload's slices, which do not change"),
        )
    }
}

/// Messages in arrival order, cut into batches in which none repeats another (by hash): a repeat
/// starts the next batch, so that it is dropped only if its first copy was taken.
pub(crate) fn batches(received: impl IntoIterator<Item = Box<Received>>) -> Vec<Vec<Received>> {
    let mut out: Vec<Vec<Received>> = Vec::new();
    let mut hashes = HashSet::new();
    for r in received {
        if out.is_empty() || !hashes.insert(r.hash) {
            hashes = HashSet::from([r.hash]);
            out.push(Vec::new());
        }
        out.last_mut()
            .expect("a batch is pushed above when `out` is empty")
            .push(*r);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{boundary_state, test_run};
    use glissade_messages::encode;
    use std::time::Duration;

    /// A payload in many fragments (as a large message arrives over TCP) decodes and hashes as
    /// its bytes do in one piece; damaged, it is refused for the same reason.
    #[test]
    fn a_fragmented_payload_decodes_and_hashes_as_its_bytes() {
        let msg = boundary_state("frag", 3, 40, 101);
        let expected = Expected {
            run_id: "frag".into(),
            scene_fingerprint: 3,
        };
        let fragmented = |bytes: &[u8], size: usize| {
            let mut w = zenoh::bytes::ZBytes::writer();
            for chunk in bytes.chunks(size) {
                w.append(zenoh::bytes::ZBytes::from(chunk.to_vec()));
            }
            w.finish()
        };
        // Fragments smaller than, equal to and larger than the 4 KiB ends the hash reads, of a
        // large message and of one shorter than those ends (its head and tail overlap).
        let small = boundary_state("frag", 3, 3, 20);
        for msg in [&msg, &small] {
            let bytes = encode(msg);
            let key = msg.topic();
            for size in [7, 1000, 4096, 5000, bytes.len()] {
                let z = fragmented(&bytes, size);
                assert_eq!(z.slices().count(), bytes.len().div_ceil(size));
                let (a, b) = (
                    Received::from_payload(key.clone(), &z, &expected, DecodeBuffers::default()),
                    Received::from_bytes(key.clone(), &bytes, &expected),
                );
                assert_eq!(a.hash, b.hash, "fragments of {size}");
                assert_eq!(&a.message.unwrap(), msg);
            }
        }
        let (bytes, key) = (encode(&msg), msg.topic());
        let cut = &bytes[..bytes.len() - 100];
        let (a, b) = (
            Received::from_payload(key.clone(), &fragmented(cut, 1000), &expected, DecodeBuffers::default()),
            Received::from_bytes(key.clone(), cut, &expected),
        );
        assert_eq!(a.hash, b.hash);
        let (ea, eb) = (a.message.unwrap_err(), b.message.unwrap_err());
        assert_eq!(ea, eb, "{ea} / {eb}");
    }

    /// Messages are cut into batches at a repeat: the repeat starts the next batch (its first
    /// copy's fate is known by then).
    #[test]
    fn a_repeat_starts_the_next_batch() {
        let expected = test_run("batches", "interface", Duration::ZERO).expected;
        let received = |bytes: &[u8]| Box::new(Received::from_bytes("k".into(), bytes, &expected));
        let (a, b, c) = (received(&[1]), received(&[2]), received(&[3]));
        let hashes = |batch: &Vec<Received>| batch.iter().map(|r| r.hash).collect::<Vec<_>>();
        let (ha, hb, hc) = (a.hash, b.hash, c.hash);
        let cut = batches([a, b, received(&[1]), c, received(&[2])]);
        assert_eq!(
            cut.iter().map(hashes).collect::<Vec<_>>(),
            vec![vec![ha, hb], vec![ha, hc, hb]]
        );
        assert!(batches(Vec::new()).is_empty());
    }

    #[test]
    fn message_hash_tells_keys_and_bytes_apart() {
        assert_ne!(message_hash("a", &[1, 2]), message_hash("a", &[1, 3]));
        assert_ne!(message_hash("a", &[1, 2]), message_hash("b", &[1, 2]));
    }
}
