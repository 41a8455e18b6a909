//! Publishing messages: encoded into a buffer of their own, straight into the session's
//! shared-memory pool, or with the shared-memory blocks their fields were written into
//! ([`crate::ShmLender`]) sent as they are.

use crate::error::zerr;
use crate::shm::ShmBlock;
use crate::TransportError;
use glissade_messages::{encode, Message, Piece};
use zenoh::qos::CongestionControl;
use zenoh::{Session, Wait};

/// Publishes one message on its topic, blocking rather than dropping under congestion. With
/// shared memory on ([`crate::set_shared_memory`]), a message of [`SHARED_ENCODING_MIN`] bytes or more is
/// encoded straight into a buffer of the session's shared-memory pool; otherwise, or when the pool
/// has no room, into a buffer of its own, which Zenoh copies into the pool (or sends over the link).
pub fn publish(session: &Session, msg: &Message) -> Result<(), TransportError> {
    publish_with(session, msg, &|key, bytes| put_bytes(session, key, bytes))
}

/// How a message's bytes are put on its key.
type Put<'p> = dyn Fn(&str, zenoh::bytes::ZBytes) -> Result<(), TransportError> + 'p;

fn publish_with(session: &Session, msg: &Message, put: &Put<'_>) -> Result<(), TransportError> {
    let key = msg.topic();
    match encode_shared(session, msg) {
        Some(bytes) => put(&key, bytes),
        None => put(&key, encode(msg).into()),
    }
}

/// A session's publishers, one per key, declared at the key's first message and kept. A put on
/// a key given as a string makes Zenoh match it against every subscription of the session and,
/// in the router, against the declared key expressions, at every message; a declared publisher's
/// key is resolved once (a process hosting 333 subdomains of a 1000-subdomain laminate spent a
/// quarter of its time in that matching).
pub struct Publishers<'s> {
    session: &'s Session,
    declared: std::sync::RwLock<std::collections::HashMap<String, std::sync::Arc<zenoh::pubsub::Publisher<'static>>>>,
}

impl<'s> Publishers<'s> {
    pub fn new(session: &'s Session) -> Self {
        Self {
            session,
            declared: Default::default(),
        }
    }

    /// Puts `bytes` on `key` through its publisher (declared now if it is the key's first
    /// message), blocking rather than dropping under congestion. No lock is held while it puts.
    pub fn put(&self, key: &str, bytes: impl Into<zenoh::bytes::ZBytes>) -> Result<(), TransportError> {
        // A poisoned lock only means another thread panicked while holding it: the map is intact.
        let known = self
            .declared
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(key)
            .cloned();
        let publisher = match known {
            Some(p) => p,
            None => {
                let mut declared = self.declared.write().unwrap_or_else(|e| e.into_inner());
                match declared.entry(key.to_string()) {
                    std::collections::hash_map::Entry::Occupied(o) => o.get().clone(),
                    std::collections::hash_map::Entry::Vacant(v) => v
                        .insert(std::sync::Arc::new(
                            self.session
                                .declare_publisher(key.to_string())
                                .congestion_control(CongestionControl::Block)
                                .wait()
                                .map_err(|e| zerr(&format!("declare a publisher on {key}"), e))?,
                        ))
                        .clone(),
                }
            }
        };
        publisher
            .put(bytes.into())
            .wait()
            .map_err(|e| zerr(&format!("put {key}"), e))
    }

    /// [`publish_lent`] through the declared publishers.
    pub fn publish_lent(&self, msg: &mut Message) -> Result<(), TransportError> {
        publish_lent_with(self.session, msg, &|key, bytes| self.put(key, bytes))
    }

    /// [`Publishers::publish_lent`], showing the bytes to `keep` first (it may hold a clone: a
    /// shared-memory block or an encoded buffer is not copied), which says whether to put them.
    pub(crate) fn publish_lent_keeping(
        &self,
        msg: &mut Message,
        keep: impl Fn(&str, &zenoh::bytes::ZBytes) -> bool,
    ) -> Result<(), TransportError> {
        publish_lent_with(self.session, msg, &|key, bytes| {
            if keep(key, &bytes) {
                self.put(key, bytes)
            } else {
                Ok(())
            }
        })
    }
}

/// Smallest message encoded straight into shared memory: the boundary fields (MBs) and the macro
/// data (tens of kB) are, the small control messages are not.
pub const SHARED_ENCODING_MIN: usize = 64 << 10;

/// `msg` encoded into a buffer of the session's shared-memory pool, or None: shared memory off or
/// not ready yet, a small message, or no room in the pool after collecting the buffers receivers
/// released. Saves the copy of an encoded buffer into the pool that Zenoh makes otherwise.
pub(crate) fn encode_shared(session: &Session, msg: &Message) -> Option<zenoh::bytes::ZBytes> {
    use zenoh::shm::GarbageCollect;
    let len = glissade_messages::encoded_len(msg);
    if len < SHARED_ENCODING_MIN {
        return None;
    }
    let provider = session.get_shm_provider().into_option()?;
    let mut buffer = provider.alloc(len).with_policy::<GarbageCollect>().wait().ok()?;
    // A message's bytes are exactly its encoding (decoding refuses trailing bytes).
    if buffer.len() != len || glissade_messages::encode_into(msg, &mut buffer) != Some(len) {
        return None;
    }
    Some(buffer.into())
}

/// Publishes a message a node made, taking the shared-memory blocks its fields were written
/// into ([`crate::ShmLender`]) out of it: they are sent as they are, without copying their values, and
/// the message keeps its other fields (for the node to reuse, [`Node::recycle`](glissade_bus::Node::recycle)). A message
/// without lent fields is published as [`publish`] does.
pub fn publish_lent(session: &Session, msg: &mut Message) -> Result<(), TransportError> {
    publish_lent_with(session, msg, &|key, bytes| put_bytes(session, key, bytes))
}

fn publish_lent_with(session: &Session, msg: &mut Message, put: &Put<'_>) -> Result<(), TransportError> {
    let mut lent = false;
    msg.payload.fields(|f| lent |= f.data.is_lent());
    if !lent {
        return publish_with(session, msg, put);
    }
    let key = msg.topic();
    let pieces = glissade_messages::encode_pieces(msg);
    let mut blocks = Vec::new();
    msg.payload.fields_mut(|f| blocks.extend(f.data.take_block()));
    let mut out = zenoh::bytes::ZBytes::writer();
    for piece in pieces {
        match piece {
            Piece::Bytes(b) => std::io::Write::write_all(&mut out, &b).expect("writing into memory cannot fail"),
            Piece::Block(at) => {
                let k = blocks
                    .iter()
                    .position(|b| b.values().as_ptr() as usize == at)
                    .ok_or_else(|| TransportError::Protocol(format!("{key}: a field block vanished while encoding")))?;
                // Blocks come from this transport's lender only.
                let shm = blocks.swap_remove(k).into_any().downcast::<ShmBlock>().map_err(|_| {
                    TransportError::Protocol(format!("{key}: a field block not lent by this transport"))
                })?;
                out.append(shm.0.into());
            }
        }
    }
    put(&key, out.finish())
}

pub(crate) fn put_bytes(
    session: &Session,
    key: &str,
    bytes: impl Into<zenoh::bytes::ZBytes>,
) -> Result<(), TransportError> {
    session
        .put(key, bytes)
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| zerr(&format!("put {key}"), e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{boundary_state, received, shm_sessions};
    use crate::{config, free_loopback_port, open};
    use glissade_messages::{decode, Expected};
    use std::sync::mpsc;
    use std::time::{Duration, Instant};

    /// A boundary state of several MB (about the size of one subdomain's field at N = 1000)
    /// crosses the router between two client sessions intact, and decodes.
    #[test]
    fn multi_megabyte_message_arrives_intact() {
        let port = free_loopback_port().unwrap();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let router = open(config("router", std::slice::from_ref(&endpoint), &[], false).unwrap()).unwrap();
        let a = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        let b = open(config("client", &[], std::slice::from_ref(&endpoint), false).unwrap()).unwrap();
        let msg = boundary_state("mb", 1, 320, 1001);
        let (_sub, rx) = received(&b, &msg.topic());
        // Let the subscription reach the router before publishing (pub/sub is not durable).
        std::thread::sleep(Duration::from_millis(500));
        publish(&a, &msg).unwrap();
        let bytes = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        assert!(bytes.len() > 5_000_000, "{} bytes", bytes.len());
        let back = decode(
            &bytes,
            &Expected {
                run_id: "mb".into(),
                scene_fingerprint: 1,
            },
        )
        .unwrap();
        assert_eq!(back, msg);
        drop(router);
    }

    /// With shared memory on, a large message is encoded straight into the session's pool (its
    /// bytes are a shared-memory buffer holding exactly `encode`'s bytes), and arrives through
    /// the router as such and intact; a small message, or a session without shared memory, takes
    /// the encoded-buffer path.
    #[test]
    fn large_messages_are_encoded_into_shared_memory() {
        let [router, a, b, plain] = shm_sessions();
        let msg = boundary_state("shm", 1, 300, 1001);
        // The pool is set up on first use, in the background.
        let deadline = Instant::now() + Duration::from_secs(20);
        let shared = loop {
            if let Some(bytes) = encode_shared(&a, &msg) {
                break bytes;
            }
            assert!(Instant::now() < deadline, "no shared-memory pool within 20 s");
            std::thread::sleep(Duration::from_millis(50));
        };
        assert!(shared.as_shm().is_some(), "not a shared-memory buffer");
        assert_eq!(shared.to_bytes().as_ref(), &encode(&msg)[..]);
        let small = boundary_state("shm", 1, 2, 3);
        assert!(encode(&small).len() < SHARED_ENCODING_MIN);
        assert!(encode_shared(&a, &small).is_none());
        assert!(encode_shared(&plain, &msg).is_none());

        let (tx, rx) = mpsc::channel();
        let _sub = b
            .declare_subscriber(msg.topic())
            .callback(move |s| {
                let _ = tx.send((s.payload().as_shm().is_some(), s.payload().to_bytes().into_owned()));
            })
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(500));
        publish(&a, &msg).unwrap();
        let (in_shm, bytes) = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        assert!(in_shm, "the message did not arrive through shared memory");
        let expected = Expected {
            run_id: "shm".into(),
            scene_fingerprint: 1,
        };
        assert_eq!(decode(&bytes, &expected).unwrap(), msg);
        drop((plain, router));
    }
}
