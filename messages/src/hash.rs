//! How a repeat of a message is recognised: a 64-bit hash of its key and bytes
//! ([`message_hash`]). Node processes drop a message whose hash they have handled, the launcher
//! keeps a result once, and recording readers pass over a repeat: one definition for all.

use std::hash::{Hash, Hasher};

/// Bytes of each end of a message that [`message_hash`] reads.
pub const MESSAGE_HASH_END: usize = 4096;

/// A 64-bit hash of a message's key and bytes (its envelope and up to 4 KiB at each end, and its
/// length: a re-sent message is byte-identical, since nodes are deterministic).
pub fn message_hash(key: &str, bytes: &[u8]) -> u64 {
    let n = bytes.len();
    message_hash_parts(
        key,
        n,
        &bytes[..n.min(MESSAGE_HASH_END)],
        &bytes[n.saturating_sub(MESSAGE_HASH_END)..],
    )
}

/// [`message_hash`] of a message of `len` bytes from its first and last (up to)
/// [`MESSAGE_HASH_END`] bytes, for a message held in pieces.
pub fn message_hash_parts(key: &str, len: usize, head: &[u8], tail: &[u8]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    key.hash(&mut h);
    len.hash(&mut h);
    head.hash(&mut h);
    tail.hash(&mut h);
    h.finish()
}
