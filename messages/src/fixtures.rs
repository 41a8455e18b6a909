//! A message and what its receiver expects, for the tests of every module.

use crate::{Envelope, Expected, Field, Message, NodeId, Payload, Role, Stage, SCHEMA_VERSION};

/// Subdomain 2's boundary state (3 × 2 fields) of iteration 3 in run `r1`, scene 7.
pub fn msg() -> Message {
    Message {
        envelope: Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: "r1".into(),
            scene_fingerprint: 7,
            iteration: 3,
            stage: Stage::Linear,
            sender: NodeId {
                role: Role::Subdomain,
                index: 2,
            },
        },
        payload: Payload::BoundaryState {
            subdomain: 2,
            to: None,
            interfaces: vec![4],
            w: Field::from_fn(3, 2, |r, c| (r + 10 * c) as f64),
            f: Field::zeros(3, 2),
        },
    }
}

pub fn expected() -> Expected {
    Expected {
        run_id: "r1".into(),
        scene_fingerprint: 7,
    }
}
