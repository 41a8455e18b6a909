//! Fuzzing of the decoder (issue 9): 100 000 inputs in all, none may panic, and the decoder never
//! returns a wrong result: whatever it accepts is exactly the encoding of the message it returns
//! (the encoding is canonical: fixed-width integers, length-prefixed strings and vectors), and
//! that message passed the run, scene, schema and size checks.
//!
//! Inputs: valid messages of every payload kind with random contents, then damaged the ways a bus
//! or a disk damages bytes (bit flips, overwritten bytes, truncation, extension, a cut-and-splice
//! of two messages), and plain random bytes. Every valid message's encoding is also checked to be
//! serde's form through bincode, the wire form of the recordings.

use glissade_messages::{
    decode, decode_from_reader, decode_from_slices, encode, encode_pieces, Awaited, BufferPool, Decision,
    DecodeBuffers, Envelope, Expected, Field, HeldBlock, HoldSource, InterfaceIndicators, InterfaceSolution, Message,
    MessageSeen, Missing, NodeId, NodeStatus, Overrides, Payload, Piece, RecordOverride, Role, Stage, StallReport,
    Values, Verdict, SCHEMA_VERSION,
};
use proptest::prelude::*;
use std::sync::{Arc, Mutex};

const RUN: &str = "fuzz-run";
const SCENE: u64 = 0x5eed_cafe_f00d_0001;

fn expected() -> Expected {
    Expected {
        run_id: RUN.into(),
        scene_fingerprint: SCENE,
    }
}

fn field() -> impl Strategy<Value = Field> {
    (0u32..5, 0u32..4).prop_flat_map(|(r, c)| {
        proptest::collection::vec(any::<f64>(), (r * c) as usize).prop_map(move |data| Field {
            rows: r,
            cols: c,
            data: data.into(),
        })
    })
}

/// Every payload kind: `prop_oneof!` takes at most ten arms unboxed, so the two Anderson payloads,
/// the mode-form state, the linear-stage counters and the stall's two payloads form groups of
/// their own, drawn in proportion (of 16 kinds).
fn payload() -> impl Strategy<Value = Payload> {
    prop_oneof![
        10 => other_payload().boxed(),
        2 => anderson_payload().boxed(),
        1 => boundary_modes().boxed(),
        1 => linear_stage_stats().boxed(),
        2 => stall_payload().boxed()
    ]
}

fn node_id() -> impl Strategy<Value = NodeId> {
    (0usize..5, any::<u32>()).prop_map(|(role, index)| NodeId {
        role: [
            Role::Subdomain,
            Role::Interface,
            Role::Coarse,
            Role::Launcher,
            Role::Recorder,
        ][role],
        index,
    })
}

fn awaited() -> impl Strategy<Value = Awaited> {
    (node_id(), ".{0,12}", any::<u32>(), proptest::option::of(any::<u32>())).prop_map(|(from, field, iteration, to)| {
        Awaited {
            from,
            field,
            iteration,
            to,
        }
    })
}

fn seen() -> impl Strategy<Value = MessageSeen> {
    (".{0,20}", any::<u32>(), any::<u64>()).prop_map(|(key, iteration, ms_ago)| MessageSeen { key, iteration, ms_ago })
}

/// A node's status and the launcher's stall report: any values (nothing sized).
fn stall_payload() -> impl Strategy<Value = Payload> {
    prop_oneof![
        (
            any::<u64>(),
            any::<bool>(),
            proptest::collection::vec(awaited(), 0..3),
            proptest::option::of(any::<u64>()),
            any::<u64>(),
            proptest::option::of(seen()),
            proptest::collection::vec(seen(), 0..3)
        )
            .prop_map(|(round, finished, awaits, busy_ms, handled, last_handled, sent)| {
                Payload::NodeStatus(NodeStatus {
                    round,
                    finished,
                    awaits,
                    busy_ms,
                    handled,
                    last_handled,
                    sent,
                })
            }),
        (
            any::<u64>(),
            proptest::collection::vec((node_id(), awaited(), any::<bool>()), 0..3),
            proptest::collection::vec(".{0,20}", 0..3),
            any::<bool>(),
            ".{0,40}"
        )
            .prop_map(|(silent_ms, missing, republished, ended, diagnosis)| {
                Payload::Stall(StallReport {
                    silent_ms,
                    missing: missing
                        .into_iter()
                        .map(|(waiter, awaited, sent)| Missing { waiter, awaited, sent })
                        .collect(),
                    republished,
                    ended,
                    diagnosis,
                })
            }),
    ]
}

/// A subdomain's linear-stage counters: any values (no field, nothing sized).
fn linear_stage_stats() -> impl Strategy<Value = Payload> {
    (
        any::<u32>(),
        any::<u64>(),
        any::<[u32; 3]>(),
        any::<f64>(),
        any::<f64>(),
    )
        .prop_map(|(subdomain, flops, [modes, new_modes, dropped_modes], xi1, xi2)| {
            Payload::LinearStageStats(glissade_messages::LinearStageStats {
                subdomain,
                flops,
                modes,
                new_modes,
                dropped_modes,
                xi1,
                xi2,
            })
        })
}

/// A PGD subdomain's state in mode form, valid as sent (λ has first_mode + new rows, G the shape
/// of Z, a particular part whose time functions have one row per load case): the damage comes
/// later.
fn boundary_modes() -> impl Strategy<Value = Payload> {
    (any::<u32>(), 0u32..4, 0u32..4, 0u32..3, 0u32..3, 0u32..3, any::<bool>()).prop_flat_map(
        |(subdomain, n_b, nt, first, new, n_c, with_particular)| {
            let lambda_rows = first + new;
            let values = |n: u32| proptest::collection::vec(any::<f64>(), n as usize);
            (
                values(n_b * new),
                values(n_b * new),
                values(lambda_rows * nt),
                values(n_b * n_c),
                values(n_b * n_c),
                values(n_c * nt),
            )
                .prop_map(move |(z, g, lambda, pw, pf, time)| {
                    let f = |rows: u32, cols: u32, data: Vec<f64>| Field {
                        rows,
                        cols,
                        data: data.into(),
                    };
                    Payload::BoundaryModes {
                        subdomain,
                        particular: with_particular.then(|| glissade_messages::ParticularModes {
                            w: f(n_b, n_c, pw),
                            f: f(n_b, n_c, pf),
                            time: f(n_c, nt, time),
                        }),
                        first_mode: first,
                        z: f(n_b, new, z),
                        g: f(n_b, new, g),
                        lambda: f(lambda_rows, nt, lambda),
                    }
                })
        },
    )
}

/// The Anderson payloads: Gram partials (square Gram matrix, k × 1 projection) and steps.
fn anderson_payload() -> impl Strategy<Value = Payload> {
    prop_oneof![
        (any::<u32>(), 0usize..5, any::<f64>()).prop_flat_map(|(subdomain, k, residual2)| {
            (
                proptest::collection::vec(any::<f64>(), k * k),
                proptest::collection::vec(any::<f64>(), k),
            )
                .prop_map(move |(gram, projection)| Payload::AndersonGram {
                    subdomain,
                    gram: Field {
                        rows: k as u32,
                        cols: k as u32,
                        data: gram.into(),
                    },
                    projection: Field {
                        rows: k as u32,
                        cols: 1,
                        data: projection.into(),
                    },
                    residual2,
                })
        }),
        (proptest::collection::vec(any::<f64>(), 0..6), any::<bool>())
            .prop_map(|(gamma, restart)| Payload::AndersonStep { gamma, restart }),
    ]
}

/// Command-line overrides, each present or not.
fn overrides() -> impl Strategy<Value = Overrides> {
    let record = prop_oneof![Just(RecordOverride::Off), Just(RecordOverride::Full)];
    (
        proptest::option::of(any::<f64>()),
        proptest::option::of(any::<f64>()),
        proptest::option::of(any::<usize>()),
        proptest::option::of(record),
    )
        .prop_map(|(accuracy, tolerance, max_iterations, record)| Overrides {
            accuracy,
            tolerance,
            max_iterations,
            record,
        })
}

/// The payload kinds other than Anderson's.
fn other_payload() -> impl Strategy<Value = Payload> {
    let verdict = prop_oneof![
        Just(Verdict::Continue),
        Just(Verdict::Converged),
        Just(Verdict::MaxIterations),
        ".{0,12}".prop_map(|detail| Verdict::Stagnated { detail }),
        ".{0,12}".prop_map(|detail| Verdict::Diverged { detail }),
        ".{0,12}".prop_map(|detail| Verdict::NoEquilibrium { detail }),
    ];
    prop_oneof![
        (".{0,40}", overrides()).prop_map(|(text, overrides)| Payload::Scene { text, overrides }),
        (
            any::<u32>(),
            proptest::collection::vec((any::<u32>(), any::<u32>()), 0..4),
            field()
        )
            .prop_map(|(subdomain, slots, l_e)| Payload::HomogenizedOperator { subdomain, slots, l_e }),
        (any::<u32>(), field()).prop_map(|(subdomain, forces)| Payload::MacroForces { subdomain, forces }),
        (any::<u32>(), field()).prop_map(|(subdomain, w_tilde)| Payload::MacroDisplacements { subdomain, w_tilde }),
        (
            any::<u32>(),
            proptest::option::of(any::<u32>()),
            proptest::collection::vec(any::<u32>(), 0..4),
            field()
        )
            .prop_map(|(subdomain, to, interfaces, w)| Payload::BoundaryState {
                subdomain,
                to,
                interfaces,
                f: Field {
                    data: w.data.iter().map(|x| -x).collect(),
                    ..w.clone()
                },
                w,
            }),
        (any::<u32>(), proptest::collection::vec(any::<u32>(), 0..4), field()).prop_map(
            |(subdomain, interfaces, q_hat)| Payload::LocalDirections {
                subdomain,
                interfaces,
                q_hat
            }
        ),
        (
            any::<f64>(),
            any::<f64>(),
            any::<[u64; 3]>(),
            proptest::collection::vec(any::<u32>(), 0..3),
            verdict
        )
            .prop_map(|(eta, contact_indicator, counts, direction_updates, verdict)| {
                Payload::Decision(Decision {
                    eta,
                    contact_indicator,
                    force_error: eta,
                    jump_error: contact_indicator,
                    counts,
                    status_changes: counts[0],
                    direction_updates,
                    force_step: contact_indicator,
                    estimate: Some(eta).filter(|_| counts[1] % 2 == 0),
                    contraction: None,
                    pointwise_step: eta,
                    pointwise_estimate: Some(contact_indicator).filter(|_| counts[2] % 2 == 0),
                    verdict,
                })
            }),
        (any::<u32>(), field(), proptest::collection::vec(0u8..3, 0..6)).prop_map(|(interface, f, status)| {
            Payload::InterfaceSolution(InterfaceSolution {
                interface,
                w_a: f.clone(),
                w_b: f.clone(),
                f_a: f.clone(),
                f_b: f.clone(),
                w_a_hat: f.clone(),
                w_b_hat: f.clone(),
                f_a_hat: f.clone(),
                f_b_hat: f,
                status,
            })
        }),
        (any::<u32>(), field()).prop_map(|(subdomain, u)| Payload::Displacement { subdomain, u }),
        (
            proptest::collection::vec(
                (
                    any::<u32>(),
                    any::<[f64; 6]>(),
                    any::<[u64; 3]>(),
                    any::<u64>(),
                    any::<bool>()
                ),
                0..4
            ),
            proptest::option::of(".{0,12}")
        )
            .prop_map(|(entries, diverged)| Payload::IndicatorPartials {
                interfaces: entries
                    .into_iter()
                    .map(
                        |(interface, v, counts, status_changes, direction_updated)| InterfaceIndicators {
                            interface,
                            eta_num: v[0],
                            eta_den: v[1],
                            force_num: v[2],
                            force_den: v[3],
                            jump_num: v[4],
                            jump_den: v[5],
                            counts,
                            status_changes,
                            direction_updated,
                            step_num: v[0],
                            step_den: v[5],
                            step_max: v[1],
                            force_max: v[4],
                            sliding_from: direction_updated.then_some(interface / 2),
                            sliding_sides: [direction_updated, interface % 2 == 0],
                        }
                    )
                    .collect(),
                diverged,
            }),
    ]
}

fn message() -> impl Strategy<Value = Message> {
    (any::<u32>(), 0usize..6, node_id(), payload()).prop_map(|(iteration, stage, sender, payload)| Message {
        envelope: Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: RUN.into(),
            scene_fingerprint: SCENE,
            iteration,
            stage: Stage::ALL[stage],
            sender,
        },
        payload,
    })
}

/// A way bytes get damaged.
#[derive(Debug, Clone)]
enum Damage {
    FlipBit(usize, u8),
    Overwrite(usize, u8),
    Truncate(usize),
    Extend(Vec<u8>),
    Splice(usize, usize),
}

fn damage() -> impl Strategy<Value = Vec<Damage>> {
    proptest::collection::vec(
        prop_oneof![
            (any::<usize>(), 0u8..8).prop_map(|(i, b)| Damage::FlipBit(i, b)),
            (any::<usize>(), any::<u8>()).prop_map(|(i, v)| Damage::Overwrite(i, v)),
            any::<usize>().prop_map(Damage::Truncate),
            proptest::collection::vec(any::<u8>(), 1..9).prop_map(Damage::Extend),
            (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Damage::Splice(a, b)),
        ],
        1..4,
    )
}

fn apply(mut bytes: Vec<u8>, other: &[u8], damage: &[Damage]) -> Vec<u8> {
    for d in damage {
        let n = bytes.len().max(1);
        match d {
            Damage::FlipBit(i, b) => {
                if let Some(x) = bytes.get_mut(i % n) {
                    *x ^= 1 << b;
                }
            }
            Damage::Overwrite(i, v) => {
                if let Some(x) = bytes.get_mut(i % n) {
                    *x = *v;
                }
            }
            Damage::Truncate(k) => bytes.truncate(k % n),
            Damage::Extend(extra) => bytes.extend_from_slice(extra),
            Damage::Splice(a, b) => {
                let cut = a % n;
                let from = b % other.len().max(1);
                bytes.truncate(cut);
                bytes.extend_from_slice(other.get(from..).unwrap_or(&[]));
            }
        }
    }
    bytes
}

thread_local! {
    /// Buffers of the messages the reader decoder accepted, for the next ones.
    static POOL: Arc<Mutex<BufferPool>> = Arc::new(Mutex::new(BufferPool::default()));
}

/// Where the values of `m`'s non-empty fields lie in its encoding (start, end), as a sender that
/// wrote them into blocks of their own sends them ([`encode_pieces`]).
fn value_blocks(m: &Message) -> Vec<(usize, usize)> {
    let mut lent = m.clone();
    lent.payload
        .fields_mut(|f| f.data = Values::lent(Box::new(f.data.to_vec())));
    let mut sizes = std::collections::HashMap::new();
    lent.payload.fields(|f| {
        sizes.insert(f.data.as_ptr() as usize, 8 * f.data.len());
    });
    let (mut at, mut blocks) = (0, Vec::new());
    for piece in encode_pieces(&lent) {
        match piece {
            Piece::Bytes(b) => at += b.len(),
            Piece::Block(addr) => {
                blocks.push((at, at + sizes[&addr]));
                at += sizes[&addr];
            }
        }
    }
    blocks
}

/// Holds the blocks it was given (values in vectors of their own).
struct Blocks(Vec<Arc<Vec<f64>>>);

impl HoldSource for Blocks {
    fn hold(&self, at: usize, len: usize) -> Option<Box<dyn HeldBlock>> {
        let b = self
            .0
            .iter()
            .find(|b| b.as_ptr() as usize == at && 8 * b.len() == len)?;
        Some(Box::new(b.clone()))
    }
}

/// `bytes` decoded from slices cut at `blocks` (start, end), those slices being blocks a field
/// may hold (when they are a whole number of values).
fn decode_held(bytes: &[u8], blocks: &[(usize, usize)]) -> Result<Message, glissade_messages::DecodeError> {
    let n = bytes.len();
    let (mut held, mut cuts, mut last) = (Vec::new(), Vec::new(), 0);
    for &(a, b) in blocks {
        let (a, b) = (a.clamp(last, n), b.clamp(last, n));
        cuts.push((last, a, false));
        let whole = (b - a) % 8 == 0;
        if whole {
            held.push(Arc::new(
                bytes[a..b]
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
                    .collect::<Vec<f64>>(),
            ));
        }
        cuts.push((a, b, whole));
        last = b;
    }
    cuts.push((last, n, false));
    let mut blocks_held = held.iter();
    let slices: Vec<&[u8]> = cuts
        .iter()
        .map(|&(a, b, whole)| match whole {
            true => bytemuck::cast_slice(&blocks_held.next().unwrap()[..]),
            false => &bytes[a..b],
        })
        .collect();
    let holding = DecodeBuffers::default().holding(Arc::new(Blocks(held.clone())));
    decode_from_slices(slices, n, &expected(), holding)
}

/// Decoding `bytes` does not panic, and an accepted message is exactly what the bytes encode.
/// `blocks` (start, end): where the undamaged message's field values lay; read from slices cut
/// there, with those slices as blocks a field may hold, it takes and refuses what `decode` does.
fn check(bytes: &[u8], blocks: &[(usize, usize)]) -> Result<(), TestCaseError> {
    // Decoding into buffers of earlier cases' messages (with their old values), as a node
    // process does, takes and refuses what decoding into new buffers does, with the same error.
    let sliced = decode(bytes, &expected());
    let pooled = POOL.with(|p| DecodeBuffers::pooled(p.clone()));
    match (&sliced, decode_from_reader(bytes, bytes.len(), &expected(), pooled)) {
        (Ok(a), Ok(b)) => {
            prop_assert_eq!(encode(a), encode(&b));
            POOL.with(|p| p.lock().unwrap().recycle(b.payload));
        }
        (Err(a), Err(b)) => prop_assert_eq!(a, &b),
        (a, b) => prop_assert!(false, "new buffers: {:?}; pooled buffers: {:?}", a, b),
    }
    match (&sliced, decode_held(bytes, blocks)) {
        (Ok(a), Ok(b)) => prop_assert_eq!(encode(a), encode(&b)),
        (Err(a), Err(b)) => prop_assert_eq!(a, &b),
        (a, b) => prop_assert!(false, "one buffer: {:?}; slices with held blocks: {:?}", a, b),
    }
    if let Ok(m) = sliced {
        prop_assert_eq!(&m.envelope.run_id, RUN);
        prop_assert_eq!(m.envelope.scene_fingerprint, SCENE);
        prop_assert_eq!(m.envelope.schema_version, SCHEMA_VERSION);
        prop_assert_eq!(
            encode(&m),
            bytes,
            "accepted bytes are not the encoding of the decoded message"
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 60_000, failure_persistence: None, ..ProptestConfig::default() })]

    /// 60 000 damaged messages.
    #[test]
    fn damaged_messages_never_panic_nor_decode_wrongly(m in message(), other in message(), d in damage()) {
        let bytes = encode(&m);
        // The wire form is serde's derive through bincode, whatever the codec's own code does
        // (recordings written with either read the same).
        let config = bincode::config::standard().with_little_endian().with_fixed_int_encoding();
        let mut serde_form = bincode::serde::encode_to_vec(&m.envelope, config).unwrap();
        serde_form.extend(bincode::serde::encode_to_vec(&m.payload, config).unwrap());
        prop_assert_eq!(&bytes, &serde_form, "the wire form changed");
        // The undamaged message round-trips (NaN payloads compare by bytes, not by value).
        let back = decode(&bytes, &expected()).expect("a valid message decodes");
        prop_assert_eq!(encode(&back), bytes.clone());
        // Read from its blocks, every non-empty field is held, not copied.
        let blocks = value_blocks(&m);
        let held = decode_held(&bytes, &blocks).expect("a valid message decodes from its blocks");
        let mut copied = 0;
        held.payload.fields(|f| copied += usize::from(!f.data.is_empty() && !f.data.is_held()));
        prop_assert_eq!(copied, 0);
        prop_assert_eq!(encode(&held), bytes.clone());
        check(&apply(bytes, &encode(&other), &d), &blocks)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40_000, failure_persistence: None, ..ProptestConfig::default() })]

    /// 40 000 random byte strings, half of them behind a valid envelope so that the payload
    /// decoder sees them too.
    #[test]
    fn random_bytes_never_panic(prefix in any::<bool>(), tail in proptest::collection::vec(any::<u8>(), 0..200)) {
        let mut bytes = Vec::new();
        if prefix {
            let env = encode(&Message {
                envelope: Envelope {
                    schema_version: SCHEMA_VERSION,
                    run_id: RUN.into(),
                    scene_fingerprint: SCENE,
                    iteration: 1,
                    stage: Stage::Linear,
                    sender: NodeId { role: Role::Subdomain, index: 0 },
                },
                payload: Payload::Scene { text: String::new(), overrides: Overrides::default() },
            });
            // The envelope without its empty Scene payload (variant index u32, length u64, and the
            // four absent overrides, a byte each).
            bytes.extend_from_slice(&env[..env.len() - 16]);
        }
        bytes.extend_from_slice(&tail);
        check(&bytes, &[])?;
    }
}
