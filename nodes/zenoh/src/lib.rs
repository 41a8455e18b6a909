//! The Zenoh transport of glissade (docs/architecture.md): runs sans-IO [`Node`](glissade_bus::Node)s over a Zenoh session.
//!
//! Topology (docs/architecture.md, "Over Zenoh"): the launcher opens a session in `router` mode listening
//! on an explicit endpoint (or connects as a client to a `zenohd` router); every node process
//! opens a `client` session connected to that router, with multicast scouting off. Clients route
//! through the router, so every node reaches every other.
//!
//! Start-up without lost messages: Zenoh pub/sub is not durable, so
//! 1. a node process fetches the scene with a query to the launcher's queryable (no race);
//! 2. it declares its subscribers, then a liveliness token `glissade/<run>/alive/<role>/<id>`;
//! 3. the launcher waits until every expected token is alive, then publishes `start`;
//! 4. only then do nodes call [`Node::start`](glissade_bus::Node::start) and publish.
//!
//! End without lost messages: a put returns once the message is queued, so a process that closed
//! its session right after its last put could lose it. A process whose nodes are finished waits
//! (bounded) for the launcher's `done`, published once it holds the final decision and every
//! final output, and only then leaves.
//!
//! Failure: every node process watches the liveliness tokens of the run (the launcher's and every
//! other node's: each node's progress depends on all of them). A token that disappears while this
//! process still has work stops it with an error naming the peer, after a short grace period in
//! which messages already on their way are still handled (a peer that finished normally leaves
//! once its last messages are out). The launcher's `stop` message stops every node at once. Link
//! leases are shortened to [`LEASE`] so a peer that vanishes without closing its connection is
//! noticed within seconds; a killed process closes its connections at once.
//!
//! Every put uses `CongestionControl::Block` (multi-MB fields are never dropped). Every wait is
//! bounded by a timeout.
//!
//! Every key expression used here comes from [`glissade_messages::topic`](mod@glissade_messages::topic). One module per
//! concern:
//! - `config`: session configuration (endpoints, lease, shared memory on or off, TLS, access
//!   control);
//! - `publish`: publishing messages (into the session's shared-memory pool, or as the blocks
//!   their fields were written into);
//! - `shm`: the shared-memory lender and the conditions for shared memory on this machine;
//! - `receive`: decoding received payloads where they lie, hashing them to recognise repeats;
//! - `node_loop`: [`run_nodes`], a node process's nodes on the bus from start to end;
//! - `presence`: liveliness tokens and the watch on them;
//! - `handshake`: the scene query and the launcher's `start`, `stop` and `done`;
//! - `recorder_log`: the recorder's log, from which a replacement process resumes.

mod config;
mod error;
mod handshake;
mod node_loop;
mod presence;
mod publish;
mod receive;
mod recorder_log;
mod shm;
mod watch;

#[cfg(test)]
mod test_support;

/// The start of a node process's informational lines (`glissade run` shows them with `--verbose`);
/// other lines (warnings, errors, `RUST_LOG` logs) are always shown.
pub const NOTE: &str = "note: ";

pub use config::{
    config, free_loopback_port, open, secure_config, set_shared_memory, user_of, Access, Auth, Credentials, Dictionary,
    Member, Tls, LEASE,
};
pub use error::TransportError;
pub use handshake::{fetch_scene, publish_done, publish_start, publish_stop, scene_fingerprint_of, serve_scene};
pub use node_loop::{run_nodes, NodeRun};
pub use presence::{launcher_token, tokens_alive, Presence};
pub use publish::{publish, publish_lent, Publishers, SHARED_ENCODING_MIN};
pub use receive::{decode_payload, message_hash, payload_hash};
pub use recorder_log::{decode_log, encode_log, fetch_log};
pub use shm::{shared_memory_lockable, shared_memory_room, ShmLender};
pub use watch::DROP_HOOK;
