//! Fuzzing of the nodes' input handling (issue 9, "bad messages"). A run of the small three-layer
//! scene, with Anderson acceleration, the coarse problem and two interface nodes (so that every
//! payload a node takes occurs: operators, macro forces and displacements, boundary states, Gram
//! partials and steps, indicator partials, decisions, local directions), and one without the
//! coarse problem nor acceleration (PGD linear stage, search-direction updates, displacements at
//! the stop), are driven by hand round by round as the in-process bus does. Around every genuine delivery the receiving node gets bad
//! messages: before it, mutants of the genuine message (another iteration, stage, sender or
//! recipient, fields of the wrong shape, NaN/∞ values, Anderson payloads of the wrong size) and
//! messages of earlier rounds (replays, messages addressed to other nodes); after it, the same
//! message again and byte-damaged copies of it passed through the decoder (bit flips, overwritten
//! bytes, truncation).
//!
//! Every bad message must be refused (`Err` naming the problem: a rejection, or for non-finite
//! values a failure), or ignored without output; none may panic; and the run, continued with the
//! genuine messages only, must publish bit for bit what the undisturbed run publishes: a refused
//! message leaves the node as it was.

use crate::common::scene_text;
use glissade_bus::{Node, NodeError, RunContext};
use glissade_deploy::{build_nodes, Plan, Selection};
use glissade_messages::{decode, encode, key_matches, Expected, Field, Message, NodeId, Payload, Role, Stage};
use glissade_scene::{load_str, LoadedScene};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

const RUN: &str = "fuzz-nodes";
/// The scene's Anderson window (set below).
const WINDOW: u32 = 3;
/// Bad messages per genuine delivery: mutants before it, damaged copies after it.
const BEFORE: usize = 200;
const AFTER: usize = 100;

/// The small three-layer scene with `solver` keys added (a tolerance the run does not reach, so
/// that it ends at max_iterations) and `deployment` keys.
fn scene(solver: &str, deployment: &str) -> LoadedScene {
    let text = scene_text("small-three-layer");
    let fuzzed = text
        .replace(
            "accuracy = 1e-3\n",
            &format!("tolerance = 1e-14\nmax_iterations = 8\n{solver}"),
        )
        .replace("[deployment]\n", &format!("[deployment]\n{deployment}"));
    assert_ne!(fuzzed, text, "the scene's [solver] and [deployment] tables moved");
    load_str(&fuzzed, "small-three-layer.toml").unwrap_or_else(|e| panic!("{e}"))
}

fn nodes(scene: &LoadedScene, interior: bool) -> (Vec<Box<dyn Node>>, Expected) {
    let model = Arc::new(scene.model.clone());
    let ctx = RunContext {
        run_id: RUN.into(),
        scene_fingerprint: scene.fingerprint,
    };
    let plan = Plan::new(&model).with_scene(scene);
    let nodes = build_nodes(&model, &ctx, interior, &plan, &Selection::everything(&plan)).expect("nodes");
    let expected = Expected {
        run_id: RUN.into(),
        scene_fingerprint: scene.fingerprint,
    };
    (nodes, expected)
}

/// A deterministic generator (SplitMix64), so that a failure replays.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// What a bad message must get.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Want {
    /// A rejection naming one of these words (or, when empty, any rejection), or no output.
    Refused(&'static [&'static str]),
    /// A failure naming the non-finite value, before the node changed anything.
    NonFinite,
    /// After the genuine delivery: anything but an accepted message.
    NotAccepted,
}

#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    inputs: u64,
    rejected: u64,
    failed: u64,
    ignored: u64,
    undecodable: u64,
    /// Damaged copies whose damage raised the envelope's iteration number: not fed.
    relabelled: u64,
}

struct Fuzzer {
    rng: Rng,
    expected: Expected,
    stats: Stats,
}

const STAGES: [Stage; 6] = Stage::ALL;
const ROLES: [Role; 5] = [
    Role::Subdomain,
    Role::Interface,
    Role::Coarse,
    Role::Launcher,
    Role::Recorder,
];

/// A field of another shape, or one that holds fewer or more values than it declares.
fn misshapen(f: &Field, rng: &mut Rng) -> Field {
    let mut g = f.clone();
    match rng.below(5) {
        0 => {
            g.rows += 1;
            g.data = vec![0.5; g.rows() * g.cols()].into();
        }
        1 => {
            g.cols += 1 + rng.below(3) as u32;
            g.data = vec![0.5; g.rows() * g.cols()].into();
        }
        2 if g.rows > 0 => {
            g.rows -= 1;
            g.data = vec![0.5; g.rows() * g.cols()].into();
        }
        3 if !g.data.is_empty() => {
            g.data.vec_mut().pop();
        }
        _ => g.data.vec_mut().push(1.0),
    }
    g
}

/// The field with one value NaN or ±∞ (None when it is empty).
fn non_finite(f: &Field, rng: &mut Rng) -> Option<Field> {
    let mut g = f.clone();
    let k = rng.below(g.data.len());
    *g.data.get_mut(k)? = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][rng.below(3)];
    Some(g)
}

impl Fuzzer {
    /// Feeds one bad message and checks the node's answer.
    fn feed(&mut self, node: &mut dyn Node, bad: &Message, want: Want, what: &str) {
        self.stats.inputs += 1;
        let id = node.id();
        let answer = catch_unwind(AssertUnwindSafe(|| node.handle(bad)))
            .unwrap_or_else(|_| panic!("{id} panicked on {what}: {}", describe(bad)));
        match answer {
            Ok(out) => {
                assert!(
                    out.is_empty() && want != Want::NonFinite,
                    "{id} accepted {what} ({}) and published {:?}",
                    describe(bad),
                    out.iter().map(Message::topic).collect::<Vec<_>>()
                );
                self.stats.ignored += 1;
            }
            Err(e) => self.check_error(&e, bad, want, what),
        }
    }

    fn check_error(&mut self, e: &NodeError, bad: &Message, want: Want, what: &str) {
        let context = || format!("{what} ({}): {e}", describe(bad));
        if e.is_rejection() {
            self.stats.rejected += 1;
            assert!(
                want != Want::NonFinite,
                "non-finite values refused as a rejection: {}",
                context()
            );
            if let Want::Refused(words) = want {
                assert!(
                    words.is_empty() || words.iter().any(|w| e.detail.contains(w)),
                    "the rejection does not name the problem ({words:?}): {}",
                    context()
                );
            }
        } else {
            self.stats.failed += 1;
            assert!(
                matches!(want, Want::NonFinite | Want::NotAccepted) && e.detail.contains("not finite"),
                "a failure where a rejection was due: {}",
                context()
            );
        }
        assert!(!e.detail.is_empty(), "an error without detail: {}", context());
    }

    /// Bad messages before `m` reaches `node`: mutants of `m` and messages of earlier rounds.
    fn before(&mut self, node: &mut dyn Node, m: &Message, earlier: &[Message]) {
        for _ in 0..BEFORE {
            if let Some((bad, want, what)) = self.mutant(m, earlier) {
                self.feed(node, &bad, want, what);
            }
        }
    }

    /// Bad messages after `m` reached `node`: `m` again, and byte-damaged copies of it through
    /// the decoder.
    fn after(&mut self, node: &mut dyn Node, m: &Message) {
        self.feed(node, m, Want::NotAccepted, "a duplicate");
        let bytes = encode(m);
        for _ in 0..AFTER {
            let mut b = bytes.clone();
            for _ in 0..1 + self.rng.below(3) {
                let n = b.len().max(1);
                match self.rng.below(4) {
                    0 => b.truncate(self.rng.below(n)),
                    1 => {
                        let (i, v) = (self.rng.below(n), self.rng.next() as u8);
                        if let Some(x) = b.get_mut(i) {
                            *x = v;
                        }
                    }
                    _ => {
                        let (i, bit) = (self.rng.below(n), self.rng.below(8));
                        if let Some(x) = b.get_mut(i) {
                            *x ^= 1 << bit;
                        }
                    }
                }
            }
            match decode(&b, &self.expected) {
                Err(_) => {
                    self.stats.inputs += 1;
                    self.stats.undecodable += 1;
                }
                // A copy relabelled to a later iteration, e.g. a state of iteration 6 relabelled
                // 7 while the node waits for the states of iteration 7, is what a genuine message
                // of that iteration looks like: no check of the node can tell it from one (the
                // transport's checksums rule such damage out). It is not fed. One relabelled to
                // an earlier iteration is, and must be refused.
                Ok(d) if d.envelope.iteration > m.envelope.iteration => {
                    self.stats.inputs += 1;
                    self.stats.relabelled += 1;
                }
                Ok(d) => self.feed(node, &d, Want::NotAccepted, "a damaged copy"),
            }
        }
    }

    /// A bad variant of `m` (or a message of an earlier round) and what it must get.
    fn mutant(&mut self, m: &Message, earlier: &[Message]) -> Option<(Message, Want, &'static str)> {
        let mut bad = m.clone();
        let env = &mut bad.envelope;
        let rng = &mut self.rng;
        let it = env.iteration;
        Some(match rng.below(9) {
            0 => {
                let shifts = [1, 2, 1000, u32::MAX - it, it.wrapping_neg()];
                env.iteration = it.wrapping_add(shifts[rng.below(shifts.len())].max(1));
                if env.iteration == it {
                    env.iteration = it + 1;
                }
                (bad, Want::Refused(&["iteration"]), "another iteration")
            }
            1 => {
                let other: Vec<Stage> = STAGES.into_iter().filter(|s| *s != env.stage).collect();
                env.stage = other[rng.below(other.len())];
                (bad, Want::Refused(&["stage"]), "another stage")
            }
            2 => {
                let other: Vec<Role> = ROLES.into_iter().filter(|r| *r != env.sender.role).collect();
                env.sender.role = other[rng.below(other.len())];
                (bad, Want::Refused(&["sent by"]), "another sender role")
            }
            3 => {
                // Local directions are taken only from the interface node that owns the
                // interface; every other payload from its one sender.
                env.sender.index = env.sender.index.wrapping_add([1, 2, 7, 1 << 31][rng.below(4)]);
                (
                    bad,
                    Want::Refused(&["sent by", "interface node", "owns", "does not own"]),
                    "another sender index",
                )
            }
            4 => {
                let shift = [1u32, 2, 3, 6, 99, u32::MAX][rng.below(6)];
                let target = match &mut bad.payload {
                    Payload::HomogenizedOperator { subdomain, .. }
                    | Payload::MacroForces { subdomain, .. }
                    | Payload::MacroDisplacements { subdomain, .. }
                    | Payload::BoundaryState { subdomain, .. }
                    | Payload::BoundaryModes { subdomain, .. }
                    | Payload::LocalDirections { subdomain, .. }
                    | Payload::AndersonGram { subdomain, .. } => subdomain,
                    _ => return None,
                };
                *target = target.wrapping_add(shift);
                (
                    bad,
                    Want::Refused(&["addressed to", "sent by", "unknown subdomain", "no interface"]),
                    "another subdomain in the payload",
                )
            }
            5 => {
                let r = &mut *rng;
                match &mut bad.payload {
                    Payload::HomogenizedOperator { slots, l_e, .. } => match r.below(3) {
                        0 if !slots.is_empty() => {
                            let k = r.below(slots.len());
                            slots[k].1 += 1;
                        }
                        1 if !slots.is_empty() => {
                            let k = r.below(slots.len());
                            slots.push(slots[k]);
                        }
                        _ => *l_e = misshapen(l_e, r),
                    },
                    // Rows of other interfaces, or for another interface node.
                    Payload::BoundaryState { to, interfaces, w, .. } => match r.below(4) {
                        0 => interfaces.push(99),
                        1 if !interfaces.is_empty() => {
                            let k = r.below(interfaces.len());
                            interfaces.push(interfaces[k]);
                        }
                        2 => *to = Some(to.map_or(1, |k| k.wrapping_add(1 + r.below(3) as u32))),
                        _ => *w = misshapen(w, r),
                    },
                    Payload::MacroForces { forces: f, .. }
                    | Payload::MacroDisplacements { w_tilde: f, .. }
                    | Payload::BoundaryModes { lambda: f, .. } => *f = misshapen(f, r),
                    Payload::LocalDirections { interfaces, q_hat, .. } => match r.below(4) {
                        0 => interfaces.push(99),
                        1 => {
                            let k = r.below(interfaces.len());
                            interfaces.push(interfaces[k]);
                        }
                        2 if interfaces.len() > 1 => {
                            interfaces.pop();
                        }
                        _ => *q_hat = misshapen(q_hat, r),
                    },
                    Payload::AndersonGram { gram, projection, .. } => match r.below(3) {
                        0 => *gram = misshapen(gram, r),
                        1 => *projection = misshapen(projection, r),
                        _ => {
                            let k = WINDOW as usize + 1;
                            *gram = Field::from_fn(k, k, |i, j| (i == j) as u8 as f64);
                            *projection = Field::zeros(k, 1);
                        }
                    },
                    Payload::AndersonStep { gamma, restart: false } if !gamma.is_empty() => gamma.push(0.25),
                    Payload::IndicatorPartials {
                        interfaces,
                        diverged: None,
                    } if !interfaces.is_empty() => match r.below(3) {
                        0 => {
                            interfaces.pop();
                        }
                        1 => interfaces.push(interfaces[0].clone()),
                        _ => interfaces[0].interface = interfaces[0].interface.wrapping_add(1 + r.below(9) as u32),
                    },
                    _ => return None,
                }
                (
                    bad,
                    Want::Refused(&[
                        "shape",
                        "declares",
                        "modes",
                        "twice",
                        "differences",
                        "window",
                        "coefficients",
                        "interface",
                    ]),
                    "a payload of the wrong size",
                )
            }
            6 => {
                let r = &mut *rng;
                match &mut bad.payload {
                    Payload::HomogenizedOperator { l_e: f, .. }
                    | Payload::MacroForces { forces: f, .. }
                    | Payload::MacroDisplacements { w_tilde: f, .. }
                    | Payload::LocalDirections { q_hat: f, .. } => *f = non_finite(f, r)?,
                    Payload::AndersonStep { gamma, restart: false } if !gamma.is_empty() => {
                        let k = r.below(gamma.len());
                        gamma[k] = f64::NAN;
                    }
                    // Boundary states and Gram partials with NaN stop the run by design (a
                    // diverged verdict naming where, an Anderson restart): only their bad copies
                    // after the genuine one are fed.
                    _ => return None,
                }
                (bad, Want::NonFinite, "non-finite values")
            }
            7 if !earlier.is_empty() => (
                earlier[rng.below(earlier.len())].clone(),
                Want::Refused(&[]),
                "a message of an earlier round",
            ),
            _ => {
                bad.payload = Payload::Scene {
                    text: "[time]\nT = 1.0".into(),
                    overrides: Default::default(),
                };
                (
                    bad,
                    Want::Refused(&["does not take"]),
                    "a payload the node does not take",
                )
            }
        })
    }
}

/// A message in a line: topic, iteration, stage, sender.
fn describe(m: &Message) -> String {
    let e = &m.envelope;
    format!(
        "{} iteration {} stage {:?} from {}",
        m.topic(),
        e.iteration,
        e.stage,
        e.sender
    )
}

/// Drives the nodes round by round as the in-process bus does (every message of a round to every
/// subscriber, nodes in order), with bad messages around every delivery when fuzzing. Returns
/// every published message, encoded, in publication order.
fn run(mut nodes: Vec<Box<dyn Node>>, mut fuzz: Option<&mut Fuzzer>) -> Vec<Vec<u8>> {
    let subs: Vec<Vec<String>> = nodes.iter().map(|n| n.subscriptions()).collect();
    let mut queue = Vec::new();
    for node in &mut nodes {
        queue.extend(node.start().expect("start"));
    }
    let mut published = queue.clone();
    // Messages of earlier rounds: every subscriber has them.
    let mut delivered = 0;
    while !queue.is_empty() {
        let topics: Vec<String> = queue.iter().map(Message::topic).collect();
        let mut next = Vec::new();
        for (node, subs) in nodes.iter_mut().zip(&subs) {
            for (m, topic) in queue.iter().zip(&topics) {
                if !subs.iter().any(|s| key_matches(s, topic)) {
                    continue;
                }
                if let Some(f) = fuzz.as_deref_mut() {
                    f.before(node.as_mut(), m, &published[..delivered]);
                }
                let id = node.id();
                next.extend(
                    node.handle(m)
                        .unwrap_or_else(|e| panic!("{id} refused the genuine {}: {e}", describe(m))),
                );
                if let Some(f) = fuzz.as_deref_mut() {
                    f.after(node.as_mut(), m);
                }
            }
        }
        delivered = published.len();
        published.extend(next.iter().cloned());
        queue = next;
    }
    let unfinished: Vec<NodeId> = nodes.iter().filter(|n| !n.is_finished()).map(|n| n.id()).collect();
    assert!(unfinished.is_empty(), "nodes {unfinished:?} did not finish");
    published.iter().map(encode).collect()
}

/// Runs `scene` undisturbed and fuzzed (seed `seed`), checks that the run publishes every payload
/// kind of `kinds` and that the fuzzed run publishes the same bytes; returns the fuzz counts.
fn fuzz_run(scene: &LoadedScene, interior: bool, kinds: &[&str], seed: u64) -> Stats {
    let (clean_nodes, expected) = nodes(scene, interior);
    let clean = run(clean_nodes, None);
    let decoded: Vec<Message> = clean.iter().map(|b| decode(b, &expected).expect("decodes")).collect();
    for key in kinds {
        assert!(
            decoded.iter().any(|m| m.payload.field_key() == *key),
            "the run publishes no {key}"
        );
    }
    let (fuzzed_nodes, _) = nodes(scene, interior);
    let mut fuzz = Fuzzer {
        rng: Rng(seed),
        expected,
        stats: Stats::default(),
    };
    let disturbed = run(fuzzed_nodes, Some(&mut fuzz));
    assert_eq!(
        disturbed.len(),
        clean.len(),
        "the disturbed run published another number of messages"
    );
    for (k, (a, b)) in disturbed.iter().zip(&clean).enumerate() {
        assert!(
            a == b,
            "message {k} ({}) of the disturbed run differs",
            describe(&decoded[k])
        );
    }
    let s = fuzz.stats;
    eprintln!(
        "node fuzz: {} inputs, 0 panics, {} rejected, {} failed (non-finite values, node unchanged), \
         {} ignored without output, {} refused by the decoder, {} relabelled to a later iteration (not fed); {} \
         genuine messages, run bit-identical",
        s.inputs,
        s.rejected,
        s.failed,
        s.ignored,
        s.undecodable,
        s.relabelled,
        clean.len()
    );
    assert_eq!(
        s.inputs,
        s.rejected + s.failed + s.ignored + s.undecodable + s.relabelled
    );
    s
}

/// Anderson acceleration, the coarse problem, two interface nodes: every payload a node takes.
#[test]
fn bad_messages_are_refused_and_leave_nodes_unchanged() {
    let scene = scene(
        &format!("acceleration = \"anderson\"\nanderson_window = {WINDOW}\n"),
        "interface_nodes = 2\n",
    );
    let kinds = [
        "homogenized_operator",
        "macro_forces",
        "macro_displacements",
        "boundary_state",
        "local_directions",
        "anderson_gram",
        "anderson_step",
        "indicator_partials",
        "decision",
    ];
    let s = fuzz_run(&scene, false, &kinds, 0x9_1ad_e5e);
    assert!(s.inputs >= 100_000, "{} inputs", s.inputs);
}

/// The other paths: no coarse problem (micro problem 1 ends the linear stage), the PGD linear
/// stage, search-direction updates, one interface node, displacements sent at the stop.
#[test]
fn bad_messages_are_refused_without_coarse_problem_nor_acceleration() {
    let scene = scene(
        "coarse = false\nlinear_stage = \"pgd\"\nsearch_direction_update = true\nacceleration = \"none\"\n",
        "",
    );
    let kinds = ["boundary_modes", "local_directions", "decision", "displacement"];
    let s = fuzz_run(&scene, true, &kinds, 0x5eed_0002);
    assert!(s.inputs >= 30_000, "{} inputs", s.inputs);
}
