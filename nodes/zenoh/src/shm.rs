//! Shared memory: the lender of blocks that a process's nodes write their large fields into
//! ([`ShmLender`], its own pools), and the conditions for shared memory on this machine (room in
//! `/dev/shm`, the right to lock memory).

use glissade_messages::{BlockLender, ValueBlock};
use std::sync::Mutex;
use zenoh::{Session, Wait};

/// A block of a shared-memory pool holding a field's values ([`ShmLender`]).
pub(crate) struct ShmBlock(pub(crate) zenoh::shm::ZShmMut);

impl ValueBlock for ShmBlock {
    fn values(&self) -> &[f64] {
        bytemuck::cast_slice(&self.0)
    }

    fn values_mut(&mut self) -> &mut [f64] {
        bytemuck::cast_slice_mut(&mut self.0)
    }

    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any> {
        self
    }
}

/// Lends a process's nodes blocks of shared memory to write their large fields into, so that
/// they are sent without a copy ([`crate::publish_lent`]). The blocks come from pools of the lender's
/// own, added one at a time as the nodes' fields need room (an interface node writes every
/// subdomain's local directions before the first is read, 34 MB at N = 1000), up to
/// [`ShmLender::POOLS`] of them. Not from the session's pool: Zenoh's transport copies other
/// messages into that one with a collection that may free a block a receiver still reads (one
/// whose watchdog a starved process missed), and receivers now read blocks in place
/// ([`crate::receive::PayloadBlocks`]). The blocks receivers have released are collected before each lend, so
/// that new blocks reuse memory already written. When no pool has room, a field takes memory of
/// its own and is copied into the session's pool when sent, as without lending.
pub struct ShmLender {
    pools: Mutex<Vec<ShmPool>>,
    /// Blocks lent, and requests refused.
    lent: std::sync::atomic::AtomicUsize,
    refused: std::sync::atomic::AtomicUsize,
}

type ShmPool = zenoh::shm::ShmProvider<zenoh::shm::PosixShmProviderBackend>;

impl ShmLender {
    /// Size of each pool (Zenoh locks a pool's whole segment in memory when it is created, and
    /// every receiver when it maps it: small pools keep that to what the fields need).
    pub const POOL_BYTES: usize = 8 << 20;
    /// Most pools.
    pub const POOLS: usize = 32;

    /// A lender for the nodes of `session`'s process, or None when shared memory is off in it or
    /// this process may not lock the pools' memory ([`shared_memory_lockable`]).
    pub fn new(session: &Session) -> Option<Self> {
        let on = !matches!(session.get_shm_provider(), zenoh::shm::ShmProviderState::Disabled);
        (on && shared_memory_lockable().is_ok()).then(|| Self {
            pools: Mutex::new(Vec::new()),
            lent: Default::default(),
            refused: Default::default(),
        })
    }

    /// Blocks lent so far, and requests refused (no room).
    pub fn counts(&self) -> (usize, usize) {
        use std::sync::atomic::Ordering::Relaxed;
        (self.lent.load(Relaxed), self.refused.load(Relaxed))
    }

    /// Whether `/dev/shm` (where the pools' segments live) has room for twice a pool of `size`
    /// bytes, so that a new pool never takes the last of it.
    fn room_for_a_pool(size: usize) -> bool {
        shared_memory_room().is_some_and(|room| room >= 2 * size as u64)
    }
}

/// Bytes free in `/dev/shm`, where Zenoh's and the lenders' shared-memory pools live; None if it
/// cannot be read (no such file system).
pub fn shared_memory_room() -> Option<u64> {
    let path = c"/dev/shm";
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `path` is a NUL-terminated string and `st` a statvfs to fill.
    let ok = unsafe { libc::statvfs(path.as_ptr(), &mut st) } == 0;
    ok.then(|| (st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
}

/// Ok when this process may lock any amount of memory: Zenoh locks (`mlock`) every
/// shared-memory segment a process creates or maps, and a receiver that cannot map a sender's
/// segment drops its message (Zenoh 1.10.2 logs it at debug level only), which stalls a run.
/// That needs an unlimited `RLIMIT_MEMLOCK` or the `CAP_IPC_LOCK` capability; Err says which
/// limit is in the way.
pub fn shared_memory_lockable() -> Result<(), String> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is an rlimit to fill.
    if unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) } == 0 && lim.rlim_cur == libc::RLIM_INFINITY {
        return Ok(());
    }
    // CAP_IPC_LOCK is capability 14 of the effective set.
    let cap_ipc_lock = std::fs::read_to_string("/proc/self/status").ok().is_some_and(|status| {
        status
            .lines()
            .find_map(|l| l.strip_prefix("CapEff:"))
            .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
            .is_some_and(|caps| caps & (1 << 14) != 0)
    });
    if cap_ipc_lock {
        return Ok(());
    }
    Err(format!(
        "RLIMIT_MEMLOCK is {} KiB and the process lacks CAP_IPC_LOCK: Zenoh locks every shared-memory \
         segment it maps, and a receiver that cannot map one drops the message",
        lim.rlim_cur / 1024
    ))
}

impl BlockLender for ShmLender {
    fn lend(&self, len: usize) -> Option<Box<dyn ValueBlock>> {
        use zenoh::shm::ShmProviderBuilder;
        let bytes = len.checked_mul(8)?;
        let take = |p: &ShmPool| {
            p.garbage_collect();
            p.alloc(bytes).wait().ok()
        };
        let mut pools = self.pools.lock().unwrap_or_else(|e| e.into_inner());
        let mut buffer = pools.iter().find_map(take);
        // A pool for a field larger than the usual pools has room for the allocator's own
        // bookkeeping too (a pool of exactly the field's size could not hold it).
        let size = Self::POOL_BYTES.max(bytes.div_ceil(1 << 20) * (1 << 20) + (1 << 20));
        if buffer.is_none() && pools.len() < Self::POOLS && Self::room_for_a_pool(size) {
            if let Ok(pool) = ShmProviderBuilder::default_backend(size).wait() {
                // A pool that cannot give even the block it was made for is not kept.
                buffer = pool.alloc(bytes).wait().ok();
                if buffer.is_some() {
                    pools.push(pool);
                }
            }
        }
        drop(pools);
        // The pools' layouts are byte-aligned, but their allocator hands out 8-byte aligned
        // blocks: checked here, since a field's values are read in place as f64.
        let block = buffer
            .filter(|b| b.len() == bytes && (b.as_ptr() as usize).is_multiple_of(8))
            .map(|b| Box::new(ShmBlock(b)) as Box<dyn ValueBlock>);
        let counter = if block.is_some() { &self.lent } else { &self.refused };
        counter.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        block
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::publish::encode_shared;
    use crate::publish_lent;
    use crate::receive::{PayloadBlocks, Received};
    use crate::test_support::{boundary_state, shm_sessions};
    use glissade_messages::{decode, encode, DecodeBuffers, Expected, Message, Payload};
    use std::sync::{mpsc, Arc};
    use std::time::{Duration, Instant};

    /// Fields a node wrote into blocks the shared-memory lender lent are sent as those blocks:
    /// they reach another process's session as slices of exactly their size (over the link a
    /// multi-MB message arrives in fragments of at most 64 KiB), the bytes are those of the
    /// message's encoding, the receiver's decoding reads the fields in place (held), and the
    /// sender's message no longer holds them. A field larger than the lender's pools gets a pool
    /// of its own; a session without shared memory has no lender.
    #[test]
    fn lent_fields_are_sent_as_their_shared_memory_blocks() {
        if let Err(why) = shared_memory_lockable() {
            eprintln!("skipped: {why}");
            return;
        }
        let [router, a, b, plain] = shm_sessions();
        assert!(ShmLender::new(&plain).is_none());
        let shm_lender = Arc::new(ShmLender::new(&a).expect("shared memory is on"));
        let lender: Arc<dyn BlockLender> = shm_lender.clone();
        // As in a run, the session's own pool is ready (set up on first use, in the background).
        let deadline = Instant::now() + Duration::from_secs(20);
        while encode_shared(&a, &boundary_state("shm", 1, 300, 30)).is_none() {
            assert!(Instant::now() < deadline, "no shared-memory pool within 20 s");
            std::thread::sleep(Duration::from_millis(50));
        }
        // Blocks larger than a pool, three at once: 3 × 12 MiB.
        let big: Vec<_> = (0..3).map(|_| lender.lend(3 << 19).expect("a block")).collect();
        assert!(big.iter().all(|b| b.values().len() == 3 << 19));
        assert_eq!(shm_lender.counts(), (3, 0));
        drop(big);
        // A pool is added only with room for two in /dev/shm.
        assert!(ShmLender::room_for_a_pool(ShmLender::POOL_BYTES));
        assert!(!ShmLender::room_for_a_pool(1 << 60));

        let (rows, cols) = (300, 1001);
        let expected = boundary_state("shm", 1, rows, cols);
        let mut pool = glissade_bus::convert::FieldPool::default();
        pool.lend_from(lender.clone());
        let Payload::BoundaryState { w, f, .. } = &expected.payload else {
            unreachable!()
        };
        let (w, f) = (glissade_bus::convert::view(w), glissade_bus::convert::view(f));
        let mut msg = Message {
            envelope: expected.envelope.clone(),
            payload: Payload::BoundaryState {
                subdomain: 0,
                to: None,
                interfaces: vec![0],
                w: pool.field_of(w),
                f: pool.field_of(f),
            },
        };
        msg.payload.fields(|f| assert!(f.data.is_lent()));
        assert_eq!(msg, expected);

        let (tx, rx) = mpsc::channel();
        let _sub = b
            .declare_subscriber(expected.topic())
            .callback(move |s| {
                let payload = s.payload();
                let sizes: Vec<usize> = payload.slices().map(|x| x.len()).collect();
                // As a node process decodes it: its fields read in place.
                let exp = Expected {
                    run_id: "shm".into(),
                    scene_fingerprint: 1,
                };
                assert!(PayloadBlocks::of(payload).is_some(), "blocks in the payload");
                let buffers = PayloadBlocks::holding(DecodeBuffers::default(), payload);
                let held = Received::from_payload(s.key_expr().to_string(), payload, &exp, buffers).message;
                let _ = tx.send((sizes, payload.to_bytes().into_owned(), held));
            })
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(500));
        publish_lent(&a, &mut msg).unwrap();
        msg.payload
            .fields(|f| assert!(f.data.is_empty() && !f.data.is_lent(), "the blocks were sent"));
        let (sizes, bytes, held) = rx.recv_timeout(Duration::from_secs(20)).expect("the message arrived");
        let block = rows * cols * 8;
        assert_eq!(sizes.iter().filter(|&&n| n == block).count(), 2, "slices {sizes:?}");
        assert_eq!(bytes, encode(&expected));
        let exp = Expected {
            run_id: "shm".into(),
            scene_fingerprint: 1,
        };
        assert_eq!(decode(&bytes, &exp).unwrap(), expected);
        let held = held.unwrap();
        held.payload
            .fields(|f| assert!(f.data.is_held(), "a field copied out of its block"));
        assert_eq!(held, expected);
        drop((plain, router));
    }
}
