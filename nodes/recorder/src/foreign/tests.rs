//! The protobuf mapping checked through its own descriptor, decoded by an independent decoder
//! (prost-reflect): every payload type has its message, and every payload variant's bytes decode
//! back to the same message, value for value.

use super::*;
use glissade_messages::{
    Awaited, Decision, Envelope, Field, InterfaceIndicators, InterfaceSolution, LinearStageStats, Message, MessageSeen,
    Missing, NodeId, NodeStatus, Overrides, ParticularModes, RecordOverride, Role, Stage, StallReport, Verdict,
};
use prost::Message as _;
use prost_reflect::{DescriptorPool, DynamicMessage, ReflectMessage, Value};
use std::borrow::Cow;

/// In the order of the proto enums' values.
const STAGES: [Stage; 6] = Stage::ALL;
const ROLES: [Role; 5] = [
    Role::Subdomain,
    Role::Interface,
    Role::Coarse,
    Role::Launcher,
    Role::Recorder,
];

fn pool() -> DescriptorPool {
    DescriptorPool::decode(&file_descriptor_set_bytes()[..]).expect("the descriptor set is valid")
}

fn envelope(iteration: u32, stage: Stage, role: Role, index: u32) -> Envelope {
    Envelope {
        schema_version: SCHEMA_VERSION,
        run_id: "run-7".into(),
        scene_fingerprint: 0xfedc_ba98_7654_3210,
        iteration,
        stage,
        sender: NodeId { role, index },
    }
}

fn field(rows: usize, cols: usize, seed: f64) -> Field {
    Field::from_fn(rows, cols, |r, c| {
        seed + r as f64 * 0.25 - c as f64 * std::f64::consts::PI
    })
}

fn decision(estimate: Option<f64>, verdict: Verdict) -> Payload {
    Payload::Decision(Decision {
        eta: 1.25e-3,
        contact_indicator: 3.5e-4,
        force_error: 2e-4,
        jump_error: 3.5e-4,
        counts: [7, 11, 13],
        status_changes: 2,
        direction_updates: vec![0, 3, 300],
        force_step: 0.125,
        estimate,
        contraction: estimate.map(|e| e * 0.5),
        pointwise_step: 0.375,
        pointwise_estimate: estimate.map(|e| e * 4.0),
        verdict,
    })
}

/// One message of every payload variant, and the variants' optional and enum forms.
fn samples() -> Vec<Message> {
    let payloads = vec![
        Payload::Scene {
            text: "name = \"tiny\" # é\n".into(),
            overrides: Overrides::default(),
        },
        Payload::Scene {
            text: String::new(),
            overrides: Overrides {
                accuracy: Some(1e-4),
                tolerance: Some(0.0),
                max_iterations: Some(0),
                record: Some(RecordOverride::Off),
            },
        },
        Payload::Scene {
            text: "x".into(),
            overrides: Overrides {
                max_iterations: Some(usize::MAX),
                record: Some(RecordOverride::Full),
                ..Overrides::default()
            },
        },
        Payload::HomogenizedOperator {
            subdomain: 3,
            slots: vec![(0, 3), (5, 6)],
            l_e: field(9, 9, 1.0),
        },
        Payload::MacroForces {
            subdomain: 1,
            forces: field(9, 4, -2.0),
        },
        Payload::MacroDisplacements {
            subdomain: 2,
            w_tilde: field(9, 4, 0.5),
        },
        Payload::BoundaryState {
            subdomain: 4,
            to: None,
            interfaces: vec![0, 3],
            w: field(6, 3, 1e-3),
            f: field(6, 3, -7.0),
        },
        Payload::BoundaryState {
            subdomain: 4,
            to: Some(2),
            interfaces: vec![3],
            w: field(6, 3, 1e-3),
            f: field(6, 3, -7.0),
        },
        Payload::BoundaryModes {
            subdomain: 1,
            particular: Some(ParticularModes {
                w: field(6, 2, 1.0),
                f: field(6, 2, 2.0),
                time: field(2, 3, 3.0),
            }),
            first_mode: 1,
            z: field(6, 2, 4.0),
            g: field(6, 2, 5.0),
            lambda: field(3, 3, 6.0),
        },
        Payload::BoundaryModes {
            subdomain: 1,
            particular: None,
            first_mode: 3,
            z: Field::zeros(6, 0),
            g: Field::zeros(6, 0),
            lambda: field(3, 3, 6.0),
        },
        Payload::LocalDirections {
            subdomain: 0,
            interfaces: vec![2, 1],
            q_hat: field(8, 3, 9.0),
        },
        Payload::AndersonGram {
            subdomain: 5,
            gram: field(2, 2, 1.5),
            projection: field(2, 1, 2.5),
            residual2: 6.25,
        },
        Payload::AndersonStep {
            gamma: vec![0.5, -0.25],
            restart: true,
        },
        Payload::AndersonStep {
            gamma: vec![],
            restart: false,
        },
        decision(None, Verdict::Continue),
        decision(Some(9.5e-4), Verdict::Converged),
        decision(Some(0.0), Verdict::MaxIterations),
        decision(
            Some(2e-2),
            Verdict::Stagnated {
                detail: "eta flat for 20 iterations".into(),
            },
        ),
        decision(
            None,
            Verdict::Diverged {
                detail: "NaN in interface 3".into(),
            },
        ),
        decision(
            Some(3e-1),
            Verdict::NoEquilibrium {
                detail: "interface 0 slides from t = 0.425".into(),
            },
        ),
        Payload::InterfaceSolution(InterfaceSolution {
            interface: 2,
            w_a: field(4, 3, 1.0),
            w_b: field(4, 3, 2.0),
            f_a: field(4, 3, 3.0),
            f_b: field(4, 3, 4.0),
            w_a_hat: field(4, 3, 5.0),
            w_b_hat: field(4, 3, 6.0),
            f_a_hat: field(4, 3, 7.0),
            f_b_hat: field(4, 3, 8.0),
            status: vec![0, 1, 2, 2, 1, 0, 0, 0, 1, 2, 2, 2],
        }),
        Payload::Displacement {
            subdomain: 6,
            u: field(10, 3, -1.0),
        },
        Payload::IndicatorPartials {
            interfaces: vec![
                InterfaceIndicators {
                    interface: 4,
                    eta_num: 1.0,
                    eta_den: 2.0,
                    force_num: 3.0,
                    force_den: 4.0,
                    jump_num: 5.0,
                    jump_den: 6.0,
                    counts: [1, 2, 3],
                    status_changes: 4,
                    direction_updated: true,
                    step_num: 7.0,
                    step_den: 8.0,
                    step_max: 9.0,
                    force_max: 10.0,
                    sliding_from: Some(0),
                    sliding_sides: [false, true],
                },
                InterfaceIndicators {
                    interface: 5,
                    eta_num: 0.5,
                    eta_den: 0.25,
                    force_num: 0.0,
                    force_den: 1.0,
                    jump_num: 2.0,
                    jump_den: 3.0,
                    counts: [0, 0, 9],
                    status_changes: 0,
                    direction_updated: false,
                    step_num: 0.0,
                    step_den: 1.0,
                    step_max: 0.0,
                    force_max: 2.5,
                    sliding_from: None,
                    sliding_sides: [false, false],
                },
            ],
            diverged: None,
        },
        Payload::IndicatorPartials {
            interfaces: vec![],
            diverged: Some("inf from subdomain 2".into()),
        },
        Payload::LinearStageStats(LinearStageStats {
            subdomain: 3,
            flops: 12_345_678_901_234,
            modes: 17,
            new_modes: 2,
            dropped_modes: 1,
            xi1: 0.0625,
            xi2: -0.0,
        }),
        Payload::LinearStageStats(LinearStageStats::default()),
        Payload::NodeStatus(NodeStatus {
            round: 3,
            finished: false,
            awaits: vec![
                Awaited {
                    from: NodeId {
                        role: Role::Interface,
                        index: 1,
                    },
                    field: "local_directions".into(),
                    iteration: 6,
                    to: Some(2),
                },
                Awaited {
                    from: NodeId {
                        role: Role::Interface,
                        index: 0,
                    },
                    field: "decision".into(),
                    iteration: 5,
                    to: None,
                },
            ],
            busy_ms: None,
            handled: 41,
            last_handled: Some(MessageSeen {
                key: "glissade/r/coarse/0/macro_displacements/2".into(),
                iteration: 5,
                ms_ago: 1200,
            }),
            sent: vec![MessageSeen {
                key: "glissade/r/subdomain/2/boundary_state".into(),
                iteration: 5,
                ms_ago: 1100,
            }],
        }),
        Payload::NodeStatus(NodeStatus {
            round: 0,
            finished: true,
            awaits: vec![],
            busy_ms: Some(0),
            handled: 0,
            last_handled: None,
            sent: vec![],
        }),
        Payload::Stall(StallReport {
            silent_ms: 2500,
            missing: vec![Missing {
                waiter: NodeId {
                    role: Role::Interface,
                    index: 0,
                },
                awaited: Awaited {
                    from: NodeId {
                        role: Role::Interface,
                        index: 1,
                    },
                    field: "indicator_partials".into(),
                    iteration: 5,
                    to: None,
                },
                sent: true,
            }],
            republished: vec!["glissade/r/interface/1/indicator_partials".into()],
            ended: false,
            diagnosis: "interface:0 waits for …".into(),
        }),
    ];
    payloads
        .into_iter()
        .enumerate()
        .map(|(k, payload)| Message {
            envelope: envelope(k as u32 * 3, STAGES[k % 6], ROLES[k % 5], k as u32),
            payload,
        })
        .collect()
}

// A decoder through the descriptor, by field name: what a foreign reader sees.

fn get<'a>(m: &'a DynamicMessage, name: &str) -> Cow<'a, Value> {
    m.get_field_by_name(name)
        .unwrap_or_else(|| panic!("{} has no field `{name}`", m.descriptor().full_name()))
}

fn u32_(m: &DynamicMessage, name: &str) -> u32 {
    get(m, name).as_u32().unwrap()
}

fn u64_(m: &DynamicMessage, name: &str) -> u64 {
    get(m, name).as_u64().unwrap()
}

fn f64_(m: &DynamicMessage, name: &str) -> f64 {
    get(m, name).as_f64().unwrap()
}

fn bool_(m: &DynamicMessage, name: &str) -> bool {
    get(m, name).as_bool().unwrap()
}

fn enum_(m: &DynamicMessage, name: &str) -> i32 {
    get(m, name).as_enum_number().unwrap()
}

fn string(m: &DynamicMessage, name: &str) -> String {
    get(m, name).as_str().unwrap().to_string()
}

fn list(m: &DynamicMessage, name: &str) -> Vec<Value> {
    get(m, name).as_list().unwrap().to_vec()
}

fn message(m: &DynamicMessage, name: &str) -> DynamicMessage {
    get(m, name).as_message().unwrap().clone()
}

fn counts(m: &DynamicMessage) -> [u64; 3] {
    [
        u64_(m, "counts_separated"),
        u64_(m, "counts_stuck"),
        u64_(m, "counts_slipping"),
    ]
}

fn field_of(m: &DynamicMessage, name: &str) -> Field {
    let f = message(m, name);
    Field {
        rows: u32_(&f, "rows"),
        cols: u32_(&f, "cols"),
        data: list(&f, "values").iter().map(|v| v.as_f64().unwrap()).collect(),
    }
}

fn node_of(n: &DynamicMessage) -> NodeId {
    NodeId {
        role: ROLES[enum_(n, "role") as usize],
        index: u32_(n, "index"),
    }
}

fn awaited_of(a: &DynamicMessage) -> Awaited {
    Awaited {
        from: node_of(&message(a, "from")),
        field: string(a, "field"),
        iteration: u32_(a, "iteration"),
        to: a.has_field_by_name("to").then(|| u32_(a, "to")),
    }
}

fn seen_of(s: &DynamicMessage) -> MessageSeen {
    MessageSeen {
        key: string(s, "key"),
        iteration: u32_(s, "iteration"),
        ms_ago: u64_(s, "ms_ago"),
    }
}

fn from_proto(m: &DynamicMessage) -> Message {
    let e = message(m, "envelope");
    let sender = message(&e, "sender");
    let envelope = Envelope {
        schema_version: u32_(&e, "schema_version"),
        run_id: string(&e, "run_id"),
        scene_fingerprint: u64_(&e, "scene_fingerprint"),
        iteration: u32_(&e, "iteration"),
        stage: STAGES[enum_(&e, "stage") as usize],
        sender: NodeId {
            role: ROLES[enum_(&sender, "role") as usize],
            index: u32_(&sender, "index"),
        },
    };
    let u32s = |name: &str| list(m, name).iter().map(|v| v.as_u32().unwrap()).collect::<Vec<_>>();
    let opt_f64 = |name: &str| m.has_field_by_name(name).then(|| f64_(m, name));
    let payload = match m.descriptor().name() {
        "Scene" => Payload::Scene {
            text: string(m, "text"),
            overrides: Overrides {
                accuracy: opt_f64("accuracy"),
                tolerance: opt_f64("tolerance"),
                max_iterations: m
                    .has_field_by_name("max_iterations")
                    .then(|| u64_(m, "max_iterations") as usize),
                record: m.has_field_by_name("record").then(|| match enum_(m, "record") {
                    0 => RecordOverride::Off,
                    1 => RecordOverride::Full,
                    other => panic!("record {other}"),
                }),
            },
        },
        "HomogenizedOperator" => Payload::HomogenizedOperator {
            subdomain: u32_(m, "subdomain"),
            slots: list(m, "slots")
                .iter()
                .map(|s| {
                    let s = s.as_message().unwrap();
                    (u32_(s, "interface"), u32_(s, "modes"))
                })
                .collect(),
            l_e: field_of(m, "l_e"),
        },
        "MacroForces" => Payload::MacroForces {
            subdomain: u32_(m, "subdomain"),
            forces: field_of(m, "forces"),
        },
        "MacroDisplacements" => Payload::MacroDisplacements {
            subdomain: u32_(m, "subdomain"),
            w_tilde: field_of(m, "w_tilde"),
        },
        "BoundaryState" => Payload::BoundaryState {
            subdomain: u32_(m, "subdomain"),
            to: m.has_field_by_name("to").then(|| u32_(m, "to")),
            interfaces: u32s("interfaces"),
            w: field_of(m, "w"),
            f: field_of(m, "f"),
        },
        "BoundaryModes" => Payload::BoundaryModes {
            subdomain: u32_(m, "subdomain"),
            particular: m.has_field_by_name("particular").then(|| {
                let p = message(m, "particular");
                ParticularModes {
                    w: field_of(&p, "w"),
                    f: field_of(&p, "f"),
                    time: field_of(&p, "time"),
                }
            }),
            first_mode: u32_(m, "first_mode"),
            z: field_of(m, "z"),
            g: field_of(m, "g"),
            lambda: field_of(m, "lambda"),
        },
        "LocalDirections" => Payload::LocalDirections {
            subdomain: u32_(m, "subdomain"),
            interfaces: u32s("interfaces"),
            q_hat: field_of(m, "q_hat"),
        },
        "AndersonGram" => Payload::AndersonGram {
            subdomain: u32_(m, "subdomain"),
            gram: field_of(m, "gram"),
            projection: field_of(m, "projection"),
            residual2: f64_(m, "residual2"),
        },
        "AndersonStep" => Payload::AndersonStep {
            gamma: list(m, "gamma").iter().map(|v| v.as_f64().unwrap()).collect(),
            restart: bool_(m, "restart"),
        },
        "Decision" => {
            let detail = string(m, "verdict_detail");
            Payload::Decision(Decision {
                eta: f64_(m, "eta"),
                contact_indicator: f64_(m, "contact_indicator"),
                force_error: f64_(m, "force_error"),
                jump_error: f64_(m, "jump_error"),
                counts: counts(m),
                status_changes: u64_(m, "status_changes"),
                direction_updates: u32s("direction_updates"),
                force_step: f64_(m, "force_step"),
                estimate: opt_f64("estimate"),
                contraction: opt_f64("contraction"),
                pointwise_step: f64_(m, "pointwise_step"),
                pointwise_estimate: opt_f64("pointwise_estimate"),
                verdict: match enum_(m, "verdict") {
                    0 => Verdict::Continue,
                    1 => Verdict::Converged,
                    2 => Verdict::MaxIterations,
                    3 => Verdict::Stagnated { detail },
                    4 => Verdict::Diverged { detail },
                    5 => Verdict::NoEquilibrium { detail },
                    v => panic!("verdict {v}"),
                },
            })
        }
        "InterfaceSolution" => Payload::InterfaceSolution(InterfaceSolution {
            interface: u32_(m, "interface"),
            w_a: field_of(m, "w_a"),
            w_b: field_of(m, "w_b"),
            f_a: field_of(m, "f_a"),
            f_b: field_of(m, "f_b"),
            w_a_hat: field_of(m, "w_a_hat"),
            w_b_hat: field_of(m, "w_b_hat"),
            f_a_hat: field_of(m, "f_a_hat"),
            f_b_hat: field_of(m, "f_b_hat"),
            status: list(m, "status")
                .iter()
                .map(|v| v.as_enum_number().unwrap() as u8)
                .collect(),
        }),
        "Displacement" => Payload::Displacement {
            subdomain: u32_(m, "subdomain"),
            u: field_of(m, "u"),
        },
        "IndicatorPartials" => Payload::IndicatorPartials {
            interfaces: list(m, "interfaces")
                .iter()
                .map(|v| {
                    let i = v.as_message().unwrap();
                    InterfaceIndicators {
                        interface: u32_(i, "interface"),
                        eta_num: f64_(i, "eta_num"),
                        eta_den: f64_(i, "eta_den"),
                        force_num: f64_(i, "force_num"),
                        force_den: f64_(i, "force_den"),
                        jump_num: f64_(i, "jump_num"),
                        jump_den: f64_(i, "jump_den"),
                        counts: counts(i),
                        status_changes: u64_(i, "status_changes"),
                        direction_updated: bool_(i, "direction_updated"),
                        step_num: f64_(i, "step_num"),
                        step_den: f64_(i, "step_den"),
                        step_max: f64_(i, "step_max"),
                        force_max: f64_(i, "force_max"),
                        sliding_from: i.has_field_by_name("sliding_from").then(|| u32_(i, "sliding_from")),
                        sliding_sides: [bool_(i, "sliding_side_a"), bool_(i, "sliding_side_b")],
                    }
                })
                .collect(),
            diverged: m.has_field_by_name("diverged").then(|| string(m, "diverged")),
        },
        "LinearStageStats" => Payload::LinearStageStats(LinearStageStats {
            subdomain: u32_(m, "subdomain"),
            flops: u64_(m, "flops"),
            modes: u32_(m, "modes"),
            new_modes: u32_(m, "new_modes"),
            dropped_modes: u32_(m, "dropped_modes"),
            xi1: f64_(m, "xi1"),
            xi2: f64_(m, "xi2"),
        }),
        "NodeStatus" => Payload::NodeStatus(NodeStatus {
            round: u64_(m, "round"),
            finished: bool_(m, "finished"),
            awaits: list(m, "awaits")
                .iter()
                .map(|v| awaited_of(v.as_message().unwrap()))
                .collect(),
            busy_ms: m.has_field_by_name("busy_ms").then(|| u64_(m, "busy_ms")),
            handled: u64_(m, "handled"),
            last_handled: m
                .has_field_by_name("last_handled")
                .then(|| seen_of(&message(m, "last_handled"))),
            sent: list(m, "sent")
                .iter()
                .map(|v| seen_of(v.as_message().unwrap()))
                .collect(),
        }),
        "Stall" => Payload::Stall(StallReport {
            silent_ms: u64_(m, "silent_ms"),
            missing: list(m, "missing")
                .iter()
                .map(|v| {
                    let x = v.as_message().unwrap();
                    Missing {
                        waiter: node_of(&message(x, "waiter")),
                        awaited: awaited_of(&message(x, "awaited")),
                        sent: bool_(x, "sent"),
                    }
                })
                .collect(),
            republished: list(m, "republished")
                .iter()
                .map(|v| v.as_str().unwrap().to_string())
                .collect(),
            ended: bool_(m, "ended"),
            diagnosis: string(m, "diagnosis"),
        }),
        other => panic!("no payload message {other}"),
    };
    Message { envelope, payload }
}

fn encoded(m: &Message) -> Vec<u8> {
    let mut out = Vec::new();
    encode_into(m, &mut out);
    out
}

/// The descriptor set decodes with prost-types, holds one file `glissade.proto` of package
/// `glissade`, and a message for every payload type the recorder has a schema for, with the
/// envelope as field 1; prost-reflect accepts it (type names resolve, proto3 rules hold).
#[test]
fn every_payload_type_has_a_message_in_the_descriptor_set() {
    let set = prost_types::FileDescriptorSet::decode(&file_descriptor_set_bytes()[..]).unwrap();
    assert_eq!(set.file.len(), 1);
    let file = &set.file[0];
    assert_eq!(
        (file.name(), file.package(), file.syntax()),
        (PROTO_FILE, "glissade", "proto3")
    );
    let pool = pool();
    for (_, name, _) in crate::PAYLOAD_FIELDS {
        let short = name.strip_prefix("glissade.").unwrap();
        let m = file
            .message_type
            .iter()
            .find(|m| m.name() == short)
            .unwrap_or_else(|| panic!("no message {name}"));
        assert_eq!((m.field[0].name(), m.field[0].number()), ("envelope", 1), "{name}");
        assert!(pool.get_message_by_name(name).is_some(), "{name}");
    }
    for m in samples() {
        let name = message_name(&m.payload);
        assert!(crate::PAYLOAD_FIELDS.iter().any(|(_, n, _)| *n == name), "{name}");
        assert_eq!(crate::payload_schema(m.payload.field_key()).0, name);
    }
    let text = proto_source();
    assert!(text.contains("message Decision {") && text.contains("  optional double estimate = 12;"));
    assert!(text.contains("  repeated double values = 3;") && text.contains("  VERDICT_STAGNATED = 3;"));
}

/// Every payload variant (with its options present and absent, every verdict, stage and role)
/// decodes through the descriptor to the same message, with no unknown field.
#[test]
fn every_payload_round_trips_through_the_descriptor() {
    let pool = pool();
    for m in samples() {
        let desc = pool.get_message_by_name(message_name(&m.payload)).unwrap();
        let dm = DynamicMessage::decode(desc, &encoded(&m)[..]).unwrap();
        assert_eq!(dm.unknown_fields().count(), 0, "{}", message_name(&m.payload));
        assert_eq!(from_proto(&dm), m);
    }
}

/// Values are carried bit for bit: −0.0, NaN with a payload, infinities and subnormals; zeros
/// and empty fields are present (not left to the proto3 defaults), and a field's values are one
/// block of little-endian f64 in the bytes.
#[test]
fn values_are_carried_bit_for_bit() {
    let special = [
        -0.0,
        f64::from_bits(0x7ff8_0000_0000_beef),
        f64::INFINITY,
        f64::MIN_POSITIVE / 4.0,
    ];
    let m = Message {
        envelope: envelope(0, Stage::Setup, Role::Subdomain, 0),
        payload: Payload::BoundaryState {
            subdomain: 0,
            to: None,
            interfaces: vec![0],
            w: Field {
                rows: 2,
                cols: 2,
                data: special.to_vec().into(),
            },
            f: Field::zeros(2, 0),
        },
    };
    let bytes = encoded(&m);
    let block: Vec<u8> = special.iter().flat_map(|v| v.to_le_bytes()).collect();
    assert!(bytes.windows(block.len()).any(|w| w == block), "one contiguous block");
    let dm = DynamicMessage::decode(
        pool().get_message_by_name("glissade.BoundaryState").unwrap(),
        &bytes[..],
    )
    .unwrap();
    let w = field_of(&dm, "w");
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&w.data), bits(&special));
    let f = field_of(&dm, "f");
    assert_eq!((f.rows, f.cols, f.data.len()), (2, 0, 0));
    // Iteration 0 and stage Setup (0) written after the fingerprint, not left out as proto3 defaults.
    let fingerprint = 0xfedc_ba98_7654_3210u64.to_le_bytes();
    let at = bytes.windows(8).position(|w| w == fingerprint).unwrap() + 8;
    assert_eq!(bytes[at..at + 4], [4 << 3, 0, 5 << 3, 0], "zeros are written");
}
