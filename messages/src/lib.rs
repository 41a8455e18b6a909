//! Wire types of glissade (docs/architecture.md): every message is an [`Envelope`] plus a [`Payload`],
//! encoded with bincode 2 (its own Encode/Decode; the wire form is that of serde's derive
//! through bincode, which the decoder fuzz test checks). Key expressions come only from the
//! functions of this crate ([`topic`](mod@topic)).
//!
//! Encoding: the envelope and the payload are encoded one after the other, so a decoder checks
//! the schema version, the run and the scene before it reads a payload whose layout may differ.
//!
//! One module per concern:
//! - `identity`: who sends and when ([`Role`], [`NodeId`], [`Stage`], [`Envelope`]);
//! - `field`, `values`: fields and their buffers ([`Field`], [`Values`], [`BufferPool`],
//!   [`DecodeBuffers`]);
//! - `payload`: what is sent ([`Payload`] and its structs, [`Message`]);
//! - `overrides`: the command-line settings that travel with the scene text ([`Overrides`]);
//! - [`topic`](mod@topic): every key expression of a run;
//! - `codec`: [`encode`], [`decode`] and their checks ([`DecodeError`], [`Expected`]).

mod codec;
mod field;
mod hash;
mod identity;
mod overrides;
mod payload;
pub mod topic;
mod values;

#[cfg(test)]
mod fixtures;

pub use codec::{
    decode, decode_from_reader, decode_from_slices, encode, encode_into, encode_pieces, encoded_len, peek_envelope,
    DecodeError, Expected, Piece,
};
pub use field::{BufferPool, DecodeBuffers, Field, HoldSource};
pub use hash::{message_hash, message_hash_parts, MESSAGE_HASH_END};
pub use identity::{Envelope, NodeId, Role, Stage};
pub use overrides::{Overrides, RecordOverride};
pub use payload::{
    Awaited, Decision, InterfaceIndicators, InterfaceSolution, LinearStageStats, Message, MessageSeen, Missing,
    NodeStatus, ParticularModes, Payload, StallReport, Verdict,
};
pub use topic::{key_matches, role_field_topic, run_topics, topic, topic_field, Routes};
pub use values::{BlockLender, HeldBlock, ValueBlock, Values};

/// Version of the wire schema; decoding rejects any other. Version 2: `LocalDirections` names the
/// interfaces it covers (several interface nodes), `IndicatorPartials` added. Version 3:
/// `BoundaryModes`, a PGD subdomain's state in mode form. Version 4: the decision carries the step
/// of the contact forces and the error estimate, `InterfaceIndicators` the step's sums. Version 5:
/// `Scene` carries the command-line [`Overrides`] beside the text (the text is the file as written),
/// and `LinearStageStats`, a subdomain's counters of its linear stage (flops, PGD basis, ξ).
/// Version 6: `BoundaryState` names the interfaces whose rows it holds and, when the run has
/// several interface nodes, the one it is for. Version 7: `NodeStatus` (a node's status, asked when
/// a run stops moving) and `Stall` (the launcher's diagnosis). Version 8: the decision carries the
/// pointwise step and estimate (`pointwise_step`, `pointwise_estimate`), `InterfaceIndicators`
/// the largest step and force at one point (`step_max`, `force_max`). Version 9:
/// `InterfaceIndicators` carries the first time point beyond what friction holds where an
/// interface slides and the sides that show it (`sliding_from`, `sliding_sides`), the verdict
/// `NoEquilibrium`.
pub const SCHEMA_VERSION: u32 = 9;
