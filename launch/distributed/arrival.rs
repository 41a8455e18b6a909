//! What the launcher's subscribers pass on of a run's messages ([`Arrival`]), what it keeps of
//! them ([`KEPT`]) and how it counts the run's traffic: shared by the set-up, which subscribes,
//! and the supervision, which reads them.

use super::Traffic;
use glissade_messages::Role;

/// A message as the launcher's subscriber passes it on.
pub(super) struct Arrival {
    pub(super) key: String,
    /// Its size on the bus.
    pub(super) size: usize,
    /// Its envelope says it belongs to the run.
    pub(super) ours: bool,
    /// The message, when the launcher keeps it ([`Arrival::of`]): Zenoh's buffers themselves,
    /// read where they are by the thread that decodes them.
    pub(super) bytes: Option<zenoh::bytes::ZBytes>,
}

impl Arrival {
    /// A message of run `run_id` seen on `key`: Zenoh's buffers are kept (shared, not copied)
    /// only if it is the run's and of a kind the launcher keeps ([`KEPT`]), or `keep_all`; the multi-MB fields in between are only
    /// counted. The launcher's main thread decodes the kept ones straight from those buffers:
    /// a copy made here, on Zenoh's receiving thread, took its memory from that thread's
    /// allocator arena, fresh pages from the kernel for the 141 MB of final solutions at
    /// N = 1000, freed again on the main thread once decoded.
    pub(super) fn of(key: &str, payload: &zenoh::bytes::ZBytes, run_id: &str, keep_all: bool) -> Self {
        // The envelope is the message's first bytes: the first slice holds it unless the
        // message came in tiny fragments, then the whole message is looked at.
        let first = payload.slices().next().unwrap_or(&[]);
        let ours = glissade_messages::peek_envelope(first, run_id).is_ok()
            || (first.len() < payload.len() && glissade_messages::peek_envelope(&payload.to_bytes(), run_id).is_ok());
        let kept = keep_all || KEPT.iter().any(|(_, kind)| *kind == kind_of(key));
        Self {
            key: key.to_string(),
            size: payload.len(),
            ours,
            bytes: (ours && kept).then(|| payload.clone()),
        }
    }
}

/// What the launcher keeps of a run, by sender role and field: the decisions, the final
/// interface solutions and displacements, and the linear stages' counters.
pub(super) const KEPT: [(Role, &str); 7] = [
    (Role::Interface, "decision"),
    (Role::Interface, "interface_solution"),
    (Role::Subdomain, "displacement"),
    (Role::Subdomain, "linear_stage_stats"),
    (Role::Subdomain, "status"),
    (Role::Interface, "status"),
    (Role::Coarse, "status"),
];

/// The field of a key ("?" if it has none).
pub(super) fn kind_of(key: &str) -> &str {
    glissade_messages::topic_field(key).unwrap_or("?")
}

/// Adds a message to the traffic if it belongs to the run (its envelope says so); returns its
/// bytes if the launcher keeps them.
pub(super) fn count<'a>(traffic: &mut Traffic, a: &'a Arrival) -> Option<&'a zenoh::bytes::ZBytes> {
    if !a.ours {
        return None;
    }
    let t = traffic.by_kind.entry(kind_of(&a.key).to_string()).or_default();
    t.messages += 1;
    t.bytes += a.size as u64;
    a.bytes.as_ref()
}
