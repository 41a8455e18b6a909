use super::*;
use glissade_bus::convert::field_of;
use glissade_bus::Node;
use glissade_mechanics::local::IndicatorSums;
use glissade_mechanics::model::SolverParams;
use glissade_messages::{Envelope, Field, Message, Payload, Role, Stage, Verdict, SCHEMA_VERSION};
use glissade_scene::load_str;

fn sums(eta: f64, norm: f64) -> IndicatorSums {
    // η² = num / (½ den)
    IndicatorSums {
        eta_num: 0.5 * eta * eta * norm,
        eta_den: norm,
        ..Default::default()
    }
}

#[test]
fn stop_rules() {
    let p = SolverParams {
        accuracy: None,
        tolerance: Some(1e-3),
        max_iterations: 100,
        stagnation_window: 5,
        stagnation_ratio: 0.9,
        ..Default::default()
    };
    let mut r = StopRule::new(&p);
    assert_eq!(r.decide(0, &sums(0.5, 1.0), None), Verdict::Continue);
    assert_eq!(r.decide(1, &sums(1e-4, 1.0), None), Verdict::Converged);

    let mut r = StopRule::new(&p);
    let mut v = Verdict::Continue;
    for n in 0..20 {
        v = r.decide(n, &sums(0.1, 1.0), None);
        if v.is_stop() {
            assert_eq!(n, 10, "stagnation is seen once the history holds two windows");
            break;
        }
    }
    assert!(
        matches!(&v, Verdict::Stagnated { detail } if !detail.contains("alternates")),
        "{v:?}"
    );

    // A period-2 cycle (η = 0.4, 0.3, 0.4, …) is named as such.
    let mut r = StopRule::new(&p);
    let mut v = Verdict::Continue;
    for n in 0..20 {
        v = r.decide(n, &sums(if n % 2 == 0 { 0.4 } else { 0.3 }, 1.0), None);
        if v.is_stop() {
            break;
        }
    }
    assert!(
        matches!(&v, Verdict::Stagnated { detail } if detail.contains("alternates between")),
        "{v:?}"
    );

    let mut r = StopRule::new(&p);
    r.decide(0, &sums(0.5, 1.0), None);
    r.decide(1, &sums(0.5, 1.0), None);
    let v = r.decide(2, &sums(0.5, 1e13), None);
    assert!(
        matches!(&v, Verdict::Diverged { detail } if detail.contains("grew")),
        "{v:?}"
    );

    let mut r = StopRule::new(&SolverParams { max_iterations: 3, ..p });
    assert_eq!(r.decide(0, &sums(0.5, 1.0), None), Verdict::Continue);
    assert_eq!(r.decide(1, &sums(0.4, 1.0), None), Verdict::Continue);
    assert_eq!(r.decide(2, &sums(0.3, 1.0), None), Verdict::MaxIterations);
}

/// With an accuracy the run converges only once the error estimate is at most it: a small η
/// alone does not stop it, and with a tolerance as well both must hold.
#[test]
fn accuracy_stops_on_the_estimate_not_on_eta() {
    // The forces' relative steps and the contact indicator halve every iteration: ρ̂ = ½, and the
    // estimate is the largest of the last 10 steps over 1 − ρ̂: 2⁻⁽ⁿ⁻⁹⁾ · 2 = 2⁻⁽ⁿ⁻¹⁰⁾.
    let step_sums = |eta: f64, n: u32| IndicatorSums {
        step_num: 0.25f64.powi(n as i32),
        step_den: 1.0,
        force_num: 0.25f64.powi(n as i32),
        force_den: 1.0,
        ..sums(eta, 1.0)
    };
    let p = SolverParams {
        accuracy: Some(1e-3),
        tolerance: None,
        max_iterations: 100,
        stagnation_window: 0,
        ..Default::default()
    };
    let mut r = StopRule::new(&p);
    let mut converged_at = None;
    for n in 0..40 {
        // η is tiny from the start: it must not stop the run.
        if r.decide(n, &step_sums(1e-12, n), None) == Verdict::Converged {
            converged_at = Some(n);
            break;
        }
    }
    // 2⁻⁽ⁿ⁻¹⁰⁾ ≤ 1e-3 from n = 20, which is also the first iteration with a full rate window.
    let n = converged_at.expect("converges on the estimate");
    assert_eq!(n, 20);
    let e = r.estimate().expect("an estimate at the stop");
    assert!((e.rate - 0.5).abs() < 1e-12 && e.error <= 1e-3, "{e:?}");

    // Accuracy and tolerance: the estimate is met at 20 but η only at 25.
    let mut r = StopRule::new(&SolverParams {
        tolerance: Some(1e-6),
        ..p.clone()
    });
    let stop = (0..40)
        .find(|&n| r.decide(n, &step_sums(if n < 25 { 1e-3 } else { 1e-7 }, n), None) == Verdict::Converged)
        .expect("converges");
    assert_eq!(stop, 25);

    // The estimate is met from 20 on (as above), but e_F, which falls by 0.9 an iteration from
    // 0.1, is above the accuracy until 0.1 · 0.9ⁿ ≤ 1e-3, n ≥ 44 (a part held off its place by an
    // offset no force shows): no "Converged" before s and ŝ agree within the accuracy.
    let mut r = StopRule::new(&p);
    let stop = (0..60)
        .find(|&n| {
            let mut s = step_sums(1e-12, n);
            s.force_num = (0.1 * 0.9f64.powi(n as i32)).powi(2);
            r.decide(n, &s, None) == Verdict::Converged
        })
        .expect("converges");
    assert_eq!(stop, 44);
    assert!(r.estimate().is_some_and(|e| e.error <= 1e-3));

    // Every contact point separated (e_F = 0, e_c = e_W falling by half an iteration, so the
    // estimate exists early): η = 1e-2 (s's forces not yet 0 where ŝ's are) holds the run until
    // it falls at 30.
    let mut r = StopRule::new(&p);
    let stop = (0..40)
        .find(|&n| {
            let mut s = step_sums(if n < 30 { 1e-2 } else { 1e-6 }, n);
            (s.force_num, s.force_den) = (0.0, 0.0);
            (s.jump_num, s.jump_den) = (0.25f64.powi(n as i32), 1.0);
            r.decide(n, &s, None) == Verdict::Converged
        })
        .expect("converges");
    assert_eq!(stop, 30);

    // Every contact point of ŝ separated, s and ŝ agreeing within the accuracy (e_W halving, η
    // small), but s still carrying contact forces of 0.26 MPa that move by 5 % an iteration, in a
    // scene whose traction scale is 6.3 MPa (a gap the local stage has not found closed yet; a
    // generated two-ply laminate stopped "Converged" at 21 with an estimate of 0 and a true error
    // of 6.6 so): those forces are not round-off, their steps are the estimate's, and the run goes
    // on. Forces of 1e-12 MPa instead are round-off: the estimate is 0 and it stops at 20.
    for (force, stops) in [(0.26, None), (1e-12, Some(20))] {
        let mut r = StopRule::new(&p).with_traction_scale(6.3);
        let stop = (0..40).find(|&n| {
            let mut s = step_sums(1e-6, n);
            (s.force_num, s.force_den) = (0.0, 0.0);
            (s.jump_num, s.jump_den) = (0.25f64.powi(n as i32), 1.0);
            (s.step_num, s.step_den) = (0.05f64.powi(2) * force * force, force * force);
            (s.step_max, s.force_max) = (0.05 * force, force);
            s.counts = [100, 0, 0];
            r.decide(n, &s, None) == Verdict::Converged
        });
        assert_eq!(stop, stops, "forces of {force} MPa");
    }

    // The L2 estimate is met from 20 on (as above), but the largest step at one point is 40 times
    // the L2 step (a corner that converges like the rest, 40 times its share): its estimate,
    // 40 · 2⁻⁽ⁿ⁻¹⁰⁾, is at most 1e-3 from n = 26 (40 · 2⁻¹⁶ = 6.1e-4; at 25, 1.2e-3): no
    // "Converged" before the pointwise estimate meets the accuracy too.
    let mut r = StopRule::new(&p);
    let stop = (0..60)
        .find(|&n| {
            let mut s = step_sums(1e-12, n);
            (s.step_max, s.force_max) = (40.0 * 0.5f64.powi(n as i32), 1.0);
            r.decide(n, &s, None) == Verdict::Converged
        })
        .expect("converges");
    assert_eq!(stop, 26);
    let (e, p_e) = (
        r.estimate().expect("estimate"),
        r.pointwise_estimate().expect("pointwise"),
    );
    assert!(e.error < 1e-4 && p_e.error <= 1e-3 && p_e.error > 5e-4, "{e:?} {p_e:?}");

    // Nothing requested: only the cap stops the run.
    let mut r = StopRule::new(&SolverParams {
        accuracy: None,
        max_iterations: 5,
        ..p
    });
    let verdicts: Vec<Verdict> = (0..5).map(|n| r.decide(n, &step_sums(0.0, n), None)).collect();
    assert_eq!(verdicts[4], Verdict::MaxIterations, "{verdicts:?}");
    assert!(verdicts[..4].iter().all(|v| *v == Verdict::Continue), "{verdicts:?}");
}

/// A block of `n` unit subdomains in a row, clamped at x = 0: interfaces 0 (b.1 | b.2),
/// 1 (b.2 | b.3), …
fn in_a_row(n: usize) -> (Arc<Model>, RunContext) {
    let text = format!(
        "[time]\nT = 1.0\nN = 2\n[materials.m]\nE = 1000.0\nnu = 0.3\n[[block]]\nname = \"b\"\n\
         material = \"m\"\nx = [0.0, {n}.0]\ny = [0.0, 1.0]\nnx = {n}\nny = 1\nsplit = [{n}, 1]\n\
         [[boundary]]\nx = 0.0\nux = 0.0\nuy = 0.0\n"
    );
    let sc = load_str(&text, "row.toml").unwrap();
    let ctx = RunContext {
        run_id: "r".into(),
        scene_fingerprint: sc.fingerprint,
    };
    (Arc::new(sc.model), ctx)
}

fn message(ctx: &RunContext, sender: NodeId, iteration: u32, payload: Payload) -> Message {
    Message {
        envelope: ctx.envelope(sender, iteration, Stage::Linear),
        payload,
    }
}

/// Boundary states of iteration 0 with distinct values per entry, subdomains 0 to 2.
fn states(model: &Model, ctx: &RunContext, k0: &[f64]) -> Vec<Message> {
    (0..3u32)
        .map(|s| {
            let n_b = BoundaryLayout::new(model, s as usize, k0).len();
            let w = Field::from_fn(n_b, 3, |r, c| 1e-3 * ((7 * r + 3 * c + s as usize) % 11) as f64);
            let f = Field::from_fn(n_b, 3, |r, c| ((5 * r + c + 2 * s as usize) % 13) as f64 - 6.0);
            let sender = NodeId {
                role: Role::Subdomain,
                index: s,
            };
            let layout = BoundaryLayout::new(model, s as usize, k0);
            let interfaces = layout.slots.iter().map(|sl| sl.interface as u32).collect();
            let state = Payload::BoundaryState {
                subdomain: s,
                to: None,
                interfaces,
                w,
                f,
            };
            message(ctx, sender, 0, state)
        })
        .collect()
}

/// A whole boundary state cut as its subdomain sends it in a deployment whose interface nodes
/// own `groups`: whole and unaddressed with one interface node, else to each owner of one of its
/// interfaces (ascending) the rows of those, in layout order, addressed.
fn cut(model: &Model, k0: &[f64], groups: &[Vec<usize>], m: &Message) -> Vec<Message> {
    let Payload::BoundaryState { subdomain, w, f, .. } = &m.payload else {
        panic!("a boundary state")
    };
    let layout = BoundaryLayout::new(model, *subdomain as usize, k0);
    let owner = |i: usize| groups.iter().position(|g| g.contains(&i)).unwrap() as u32;
    let mut owners: Vec<u32> = layout.slots.iter().map(|sl| owner(sl.interface)).collect();
    owners.sort_unstable();
    owners.dedup();
    if groups.len() == 1 {
        return vec![m.clone()];
    }
    owners
        .into_iter()
        .map(|to| {
            let mine: Vec<_> = layout.slots.iter().filter(|sl| owner(sl.interface) == to).collect();
            let rows: Vec<usize> = mine
                .iter()
                .flat_map(|sl| sl.offset..sl.offset + 2 * sl.n_pairs)
                .collect();
            let pick = |x: &Field| Field::from_fn(rows.len(), x.cols(), |r, c| x.data[c * x.rows() + rows[r]]);
            Message {
                envelope: m.envelope.clone(),
                payload: Payload::BoundaryState {
                    subdomain: *subdomain,
                    to: Some(to),
                    interfaces: mine.iter().map(|sl| sl.interface as u32).collect(),
                    w: pick(w),
                    f: pick(f),
                },
            }
        })
        .collect()
}

/// What `node` answers to `m`, if it subscribes to its key (as the bus delivers it).
fn deliver(node: &mut InterfaceNode, m: &Message) -> Vec<Message> {
    let key = m.topic();
    if node
        .subscriptions()
        .iter()
        .any(|s| glissade_messages::key_matches(s, &key))
    {
        node.handle(m).unwrap()
    } else {
        Vec::new()
    }
}

#[test]
fn two_interface_nodes_decide_as_one() {
    let (model, ctx) = in_a_row(3);
    assert_eq!(model.interfaces.len(), 2);
    let k0 = vec![1000.0; 2];
    let mut one = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
    let groups = [vec![1], vec![0]];
    let mut n0 = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 0);
    let mut n1 = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 1);
    assert_eq!((n0.participants(), n1.participants()), (&[1, 2][..], &[0, 1][..]));
    let groups_of_one = [vec![0, 1]];
    let (mut single, mut from0, mut from1) = (Vec::new(), Vec::new(), Vec::new());
    let mut parts = Vec::new();
    for m in states(&model, &ctx, &k0) {
        assert_eq!(
            cut(&model, &k0, &groups_of_one, &m),
            std::slice::from_ref(&m),
            "one node: whole states"
        );
        single.extend(deliver(&mut one, &m));
        parts.extend(cut(&model, &k0, &groups, &m));
    }
    // Subdomains 0 and 2 have one interface each, whole states addressed to its owner (interface
    // 0 is node 1's, interface 1 node 0's); subdomain 1 one of each node: its state comes in two
    // parts, to each node the rows of its own interface. Each node hears its own key only.
    let keys: Vec<String> = parts.iter().map(|m| m.topic()).collect();
    assert_eq!(
        keys,
        [
            "glissade/r/subdomain/0/boundary_state/1",
            "glissade/r/subdomain/1/boundary_state/0",
            "glissade/r/subdomain/1/boundary_state/1",
            "glissade/r/subdomain/2/boundary_state/0"
        ]
    );
    assert_eq!(n0.subscriptions()[0], "glissade/r/subdomain/*/boundary_state/0");
    assert_eq!(one.subscriptions()[0], "glissade/r/subdomain/*/boundary_state");
    // A part for the other node is refused, naming both.
    let err = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 0)
        .handle(&parts[2])
        .unwrap_err();
    assert!(
        err.detail.contains(
            "boundary state of subdomain 1 for interface:1 over interfaces [0]; this node takes the rows of [1] for interface:0"
        ),
        "{err}"
    );
    for m in &parts {
        from0.extend(deliver(&mut n0, m));
        from1.extend(deliver(&mut n1, m));
    }
    assert!(from0.is_empty(), "node 0 waits for node 1's indicators");
    let [partials] = &from1[..] else {
        panic!("node 1 sends its indicators only: {from1:?}")
    };
    assert!(
        matches!(&partials.payload, Payload::IndicatorPartials { interfaces, diverged: None }
        if interfaces.len() == 1 && interfaces[0].interface == 0)
    );
    // A share that names node 0's interface is refused, naming it.
    let mut wrong = partials.clone();
    if let Payload::IndicatorPartials { interfaces, .. } = &mut wrong.payload {
        interfaces[0].interface = 1;
    }
    let mut n0_copy = InterfaceNode::owning(ctx.clone(), model.clone(), &k0, &groups, 0);
    for m in &parts {
        deliver(&mut n0_copy, m);
    }
    let err = n0_copy.handle(&wrong).unwrap_err();
    assert!(
        err.detail
            .contains("indicators of interfaces [1] from interface node 1, which owns [0]"),
        "{err}"
    );
    assert!(err.is_rejection(), "{err:?}");
    // A share that says its interface slides from a time point the scene does not have, or as a
    // side shows whose part its supports hold, is refused.
    for (from, sides) in [(99, [true, false]), (1, [true, false]), (1, [false, false])] {
        let mut sliding = partials.clone();
        if let Payload::IndicatorPartials { interfaces, .. } = &mut sliding.payload {
            (interfaces[0].sliding_from, interfaces[0].sliding_sides) = (Some(from), sides);
        }
        let err = n0_copy.handle(&sliding).unwrap_err();
        assert!(err.detail.contains("say it slides from time point Some("), "{err}");
        assert!(err.is_rejection(), "{err:?}");
    }

    from0.extend(n0.handle(partials).unwrap());
    let decision = |out: &[Message]| {
        out.iter()
            .find_map(|m| match &m.payload {
                Payload::Decision(d) => Some(d.clone()),
                _ => None,
            })
            .expect("a decision")
    };
    assert_eq!(decision(&single), decision(&from0));
    assert_eq!(decision(&single).verdict, Verdict::Continue);
    let err = n0.handle(partials).unwrap_err();
    assert!(
        err.detail
            .contains("indicators of iteration 0 from interface node 1 while at iteration 1"),
        "{err}"
    );
    // Node 1 sends its q̂ rows once it has the decision; with node 0's they make the one-node q̂.
    let d = from0
        .iter()
        .find(|m| matches!(m.payload, Payload::Decision(_)))
        .unwrap();
    from1 = n1.handle(d).unwrap();
    let q_of = |out: &[Message], s: u32| -> Vec<(Vec<u32>, Field)> {
        out.iter()
            .filter_map(|m| match &m.payload {
                Payload::LocalDirections {
                    subdomain,
                    interfaces,
                    q_hat,
                } if *subdomain == s => Some((interfaces.clone(), q_hat.clone())),
                _ => None,
            })
            .collect()
    };
    // Subdomain 1 has interface 0 (side b) then interface 1 (side a).
    let [(all, q)] = &q_of(&single, 1)[..] else { panic!() };
    assert_eq!(all, &[0, 1]);
    let [(i0, q0)] = &q_of(&from1, 1)[..] else { panic!() };
    let [(i1, q1)] = &q_of(&from0, 1)[..] else { panic!() };
    assert_eq!((i0, i1), (&vec![0], &vec![1]));
    assert_eq!(q0.rows() + q1.rows(), q.rows());
    let mut joined = Vec::new();
    for c in 0..q.cols() {
        joined.extend((0..q0.rows()).map(|r| q0.get(r, c)));
        joined.extend((0..q1.rows()).map(|r| q1.get(r, c)));
    }
    assert_eq!(joined, q.data, "the pieces are the one-node q̂, bit for bit");
}

#[test]
fn final_solutions_follow_the_decision_one_at_a_time_in_the_same_buffers() {
    // One iteration allowed: the first decision is a stop.
    let (model, ctx) = in_a_row(3);
    let mut capped = (*model).clone();
    capped.solver.max_iterations = 1;
    let model = Arc::new(capped);
    let k0 = vec![1000.0; model.interfaces.len()];
    let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
    let mut out = Vec::new();
    for m in states(&model, &ctx, &k0) {
        out.extend(node.handle(&m).unwrap());
    }
    let [decision] = &out[..] else {
        panic!("the stop's reply is its decision alone: {out:?}")
    };
    assert!(matches!(&decision.payload, Payload::Decision(d) if d.verdict.is_stop()));
    assert!(node.is_finished());
    // Solution p: of interface p, at the final stage, s and ŝ as the node holds them, bit
    // for bit; returns its fields' buffers.
    let check = |node: &InterfaceNode, m: &Message, p: usize| -> Vec<*const f64> {
        let Payload::InterfaceSolution(sol) = &m.payload else {
            panic!("an interface solution: {m:?}")
        };
        assert_eq!((sol.interface, m.envelope.stage), (p as u32, Stage::Final));
        let (s, h) = (&node.fields[p], &node.locals[p].hat);
        let expected = [&s.w_a, &s.w_b, &s.f_a, &s.f_b, &h.w_a, &h.w_b, &h.f_a, &h.f_b].map(|m| field_of(m.as_ref()));
        let got = [
            &sol.w_a,
            &sol.w_b,
            &sol.f_a,
            &sol.f_b,
            &sol.w_a_hat,
            &sol.w_b_hat,
            &sol.f_a_hat,
            &sol.f_b_hat,
        ];
        assert!(got.iter().zip(&expected).all(|(g, e)| *g == e), "interface {p}");
        let mut buffers: Vec<_> = got.iter().map(|f| f.data.as_ptr()).collect();
        buffers.sort();
        buffers
    };
    let first = node.next_output().expect("interface 0's solution");
    let buffers = check(&node, &first, 0);
    node.recycle(first);
    // Once given back, its buffers hold the next solution.
    let second = node.next_output().expect("interface 1's solution");
    assert_eq!(
        check(&node, &second, 1),
        buffers,
        "interface 1's fields reuse interface 0's buffers"
    );
    assert!(node.next_output().is_none(), "two interfaces, two solutions");
}

#[test]
fn nan_stops_the_run_and_names_where() {
    let (model, ctx) = in_a_row(2);
    let k0 = vec![1000.0; model.interfaces.len()];
    let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
    let n_b = BoundaryLayout::new(&model, 1, &k0).len();
    let mut w = Field::zeros(n_b, 3);
    w.data[n_b + 3] = f64::NAN;
    let msg = Message {
        envelope: Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: "r".into(),
            scene_fingerprint: ctx.scene_fingerprint,
            iteration: 0,
            stage: Stage::Linear,
            sender: NodeId {
                role: Role::Subdomain,
                index: 1,
            },
        },
        payload: Payload::BoundaryState {
            subdomain: 1,
            to: None,
            interfaces: vec![0],
            w,
            f: Field::zeros(n_b, 3),
        },
    };
    let out = node.handle(&msg).unwrap();
    let Payload::Decision(d) = &out[0].payload else {
        panic!("expected a decision")
    };
    let Verdict::Diverged { detail } = &d.verdict else {
        panic!("{:?}", d.verdict)
    };
    assert!(detail.contains("subdomain 1 (`b.2`) sent W = NaN"), "{detail}");
    assert!(
        detail.contains("pair 1") && detail.contains("component y") && detail.contains("t_1 = 0.5"),
        "{detail}"
    );
    assert!(node.is_finished());
}

/// A PGD subdomain's state in mode form gives the local stage what the same state as full
/// fields gives it, bit for bit; a mode form without its particular part, a second particular
/// part or modes past those held are refused and change nothing.
#[test]
fn mode_form_states_give_the_full_fields() {
    let (model, ctx) = in_a_row(3);
    let k0 = vec![1000.0; model.interfaces.len()];
    let full = states(&model, &ctx, &k0);
    let sender = |s: u32| NodeId {
        role: Role::Subdomain,
        index: s,
    };
    // Each state as W = P_W φ + Z λ, F = P_F φ + G λ with one load case and two modes whose
    // expansion the full-field node gets.
    let (mut by_modes, mut by_fields) = (Vec::new(), Vec::new());
    for s in 0..3u32 {
        let n_b = BoundaryLayout::new(&model, s as usize, &k0).len();
        let v = |n: usize, k: usize| {
            (0..n)
                .map(|i| ((i * 7 + k * 3 + s as usize) % 13) as f64 - 6.0)
                .collect::<Vec<f64>>()
        };
        let (pw, pf, phi) = (v(n_b, 1), v(n_b, 2), v(3, 3));
        let (z, g, lambda) = (v(2 * n_b, 4), v(2 * n_b, 5), v(2 * 3, 6));
        let mut form = ModeForm::new(n_b, 3, 1, &pw, &pf, &phi).unwrap();
        form.update(0, &z, &g, &lambda).unwrap();
        let (mut w, mut f) = (Mat::zeros(n_b, 3), Mat::zeros(n_b, 3));
        form.expand_into(w.as_mut(), f.as_mut());
        by_fields.push(message(
            &ctx,
            sender(s),
            0,
            Payload::BoundaryState {
                subdomain: s,
                to: None,
                interfaces: BoundaryLayout::new(&model, s as usize, &k0)
                    .slots
                    .iter()
                    .map(|sl| sl.interface as u32)
                    .collect(),
                w: field_of(w.as_ref()),
                f: field_of(f.as_ref()),
            },
        ));
        let col = |data: Vec<f64>, rows: usize| Field {
            rows: rows as u32,
            cols: (data.len() / rows) as u32,
            data: data.into(),
        };
        by_modes.push(message(
            &ctx,
            sender(s),
            0,
            Payload::BoundaryModes {
                subdomain: s,
                particular: Some(glissade_messages::ParticularModes {
                    w: col(pw, n_b),
                    f: col(pf, n_b),
                    time: col(phi, 1),
                }),
                first_mode: 0,
                z: col(z, n_b),
                g: col(g, n_b),
                lambda: col(lambda, 2),
            },
        ));
    }
    assert_eq!(full.len(), 3);
    let mut node = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
    // Refused, nothing changes: no particular part yet, modes past those held.
    let mut orphan = by_modes[0].clone();
    if let Payload::BoundaryModes { particular, .. } = &mut orphan.payload {
        *particular = None;
    }
    let e = node.handle(&orphan).unwrap_err();
    assert!(e.to_string().contains("before its particular part"), "{e}");
    let mut gap = by_modes[0].clone();
    if let Payload::BoundaryModes { first_mode, lambda, .. } = &mut gap.payload {
        *first_mode = 1;
        *lambda = Field::zeros(3, 3);
    }
    let e = node.handle(&gap).unwrap_err();
    assert!(
        e.to_string()
            .contains("modes from column 1 on, but only 0 modes are held"),
        "{e}"
    );
    let mut from_modes = Vec::new();
    for m in &by_modes {
        from_modes.extend(node.handle(m).unwrap());
    }
    let mut reference = InterfaceNode::new(ctx.clone(), model.clone(), &k0);
    let mut from_fields = Vec::new();
    for m in &by_fields {
        from_fields.extend(reference.handle(m).unwrap());
    }
    assert!(!from_fields.is_empty());
    assert_eq!(from_modes, from_fields, "the same local stage, bit for bit");
}

/// Stagnation at a small error is convergence: η flat at 1e-5 (no estimate yet, the contraction
/// window not full) stagnates at iteration 10 with a window of 5; with an accuracy of 1e-3 that is
/// "Converged", s and ŝ agreeing within 1e-3 / 30. Flat at 1e-4 (above 1e-3 / 30), or without an
/// accuracy, it stays "Stagnated".
#[test]
fn stagnation_within_the_accuracy_over_30_is_convergence() {
    let p = SolverParams {
        accuracy: Some(1e-3),
        tolerance: None,
        max_iterations: 100,
        stagnation_window: 5,
        stagnation_ratio: 0.99,
        ..Default::default()
    };
    for (eta, accuracy, converged) in [(1e-5, Some(1e-3), true), (1e-4, Some(1e-3), false), (1e-5, None, false)] {
        let mut r = StopRule::new(&SolverParams {
            accuracy,
            tolerance: accuracy.map_or(Some(1e-9), |_| None),
            ..p.clone()
        });
        let (n, v) = (0..40)
            .map(|n| (n, r.decide(n, &sums(eta, 1.0), None)))
            .find(|(_, v)| v.is_stop())
            .expect("stops");
        assert_eq!(n, 10, "η = {eta}");
        assert_eq!(
            v == Verdict::Converged,
            converged,
            "η = {eta}, accuracy {accuracy:?}: {v:?}"
        );
        if !converged {
            assert!(matches!(v, Verdict::Stagnated { .. }), "{v:?}");
        }
    }
    assert!(stagnated(&[1.0; 11], 5, 0.99) && !stagnated(&[1.0; 10], 5, 0.99));
    assert!(!stagnated(
        &[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.5, 0.5, 0.5, 0.5],
        5,
        0.99
    ));
}
