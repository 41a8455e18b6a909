//! Who sends a message and where in the iteration it belongs: [`Role`], [`NodeId`], [`Stage`],
//! and the [`Envelope`] that heads every message.

use serde::{Deserialize, Serialize};

/// Role of a node on the bus.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, bincode::Encode, bincode::Decode,
)]
pub enum Role {
    Subdomain,
    Interface,
    Coarse,
    Launcher,
    Recorder,
}

impl Role {
    /// The role's chunk in key expressions.
    pub fn key(self) -> &'static str {
        match self {
            Role::Subdomain => "subdomain",
            Role::Interface => "interface",
            Role::Coarse => "coarse",
            Role::Launcher => "launcher",
            Role::Recorder => "recorder",
        }
    }
}

/// Sender of a message: its role and index (a subdomain index for subdomain messages).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, bincode::Encode, bincode::Decode,
)]
pub struct NodeId {
    pub role: Role,
    pub index: u32,
}

impl std::fmt::Display for NodeId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.role.key(), self.index)
    }
}

/// Stage of the LATIN iteration a message belongs to.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, bincode::Encode, bincode::Decode,
)]
pub enum Stage {
    Setup,
    /// Micro problem 1 and its macro forces.
    Micro1,
    /// The macro problem's solution.
    Macro,
    /// End of a linear stage: the new s.
    Linear,
    /// Local stage results and the stop decision.
    Local,
    /// Final output after the stop decision.
    Final,
}

impl Stage {
    /// Every stage, in the order of the enum (and of the foreign schema's values).
    pub const ALL: [Stage; 6] = [
        Stage::Setup,
        Stage::Micro1,
        Stage::Macro,
        Stage::Linear,
        Stage::Local,
        Stage::Final,
    ];
}

/// Header of every message.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct Envelope {
    pub schema_version: u32,
    pub run_id: String,
    pub scene_fingerprint: u64,
    pub iteration: u32,
    pub stage: Stage,
    pub sender: NodeId,
}
