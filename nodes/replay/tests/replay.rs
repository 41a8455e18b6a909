//! A recording of the two-blocks scene's shape (boundary states, decisions, interface solutions of
//! the sizes the scene gives) replays into an .rrd that the Rerun CLI of the pinned version
//! accepts (`rerun rrd verify`; skipped with the reason printed when the CLI is absent), whose
//! blueprint opens the expected panels with the structure seen from above, and whose legend
//! states the 2nd–98th percentiles of the final state's von Mises stress.

use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::default_k0;
use glissade_mechanics::post::{nodal_stresses, von_mises};
use glissade_messages::{
    encode, Decision, Envelope, Field, InterfaceSolution, Message, NodeId, Payload, Role, Stage, Verdict,
    SCHEMA_VERSION,
};
use glissade_recorder::{Recorder, RecorderOptions, Recording, RunInfo};
use glissade_replay::blueprint::{CONVERGENCE, CONVERGENCE_VIEW, COUNTS_VIEW, FORCES_VIEW, STRUCTURE_VIEW};
use glissade_replay::rrd::RrdContents;
use glissade_replay::{final_state, replay, ColorBy, ReplayOptions, Sink};
use glissade_scene::load_str;
use std::process::Command;

#[test]
fn replay_writes_an_rrd_the_rerun_cli_accepts() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../launch/scenes/two-blocks.toml"
    ))
    .expect("scene file");
    let scene = load_str(&text, "two-blocks.toml").unwrap();
    let model = &scene.model;
    let nt = model.time.n_points();
    let k0 = default_k0(model);
    let dir = std::env::temp_dir().join(format!("glissade-replay-{}", std::process::id()));
    // A folder left by an earlier run with this process id: its .rrd would be refused.
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mcap = dir.join("two-blocks-r.mcap");
    let run = RunInfo {
        run_id: "r".into(),
        scene_name: model.name.clone(),
        scene_fingerprint: scene.fingerprint,
        scene_text: text.clone(),
        scene_overrides: scene.overrides,
        software: "test".into(),
    };
    let mut rec = Recorder::create(&mcap, &run, &RecorderOptions::default()).unwrap();
    let envelope = |iteration: u32, stage: Stage, role: Role, index: u32| Envelope {
        schema_version: SCHEMA_VERSION,
        run_id: "r".into(),
        scene_fingerprint: scene.fingerprint,
        iteration,
        stage,
        sender: NodeId { role, index },
    };
    let mut put = |m: Message| rec.record(&m.topic(), 0, &encode(&m)).unwrap();
    let iterations = 3;
    for n in 0..iterations {
        for s in 0..model.subdomains.len() {
            let layout = BoundaryLayout::new(model, s, &k0);
            let n_b = layout.len();
            // A boundary displacement growing with time and iteration, and a traction.
            let w = Field::from_fn(n_b, nt, |r, i| {
                1e-3 * (r % 2) as f64 * i as f64 / nt as f64 * (n + 1) as f64
            });
            let f = Field::from_fn(n_b, nt, |r, i| -10.0 * ((r + 1) % 2) as f64 * i as f64 / nt as f64);
            put(Message {
                envelope: envelope(n, Stage::Linear, Role::Subdomain, s as u32),
                payload: Payload::BoundaryState {
                    subdomain: s as u32,
                    to: None,
                    interfaces: layout.slots.iter().map(|sl| sl.interface as u32).collect(),
                    w,
                    f,
                },
            });
        }
        put(Message {
            envelope: envelope(n, Stage::Local, Role::Interface, 0),
            payload: Payload::Decision(Decision {
                eta: 0.1f64.powi(n as i32 + 1),
                contact_indicator: 0.2f64.powi(n as i32 + 1),
                force_error: 0.0,
                jump_error: 0.0,
                counts: [1, 2, 3],
                status_changes: 0,
                direction_updates: vec![],
                force_step: 0.0,
                estimate: None,
                contraction: None,
                pointwise_step: 0.0,
                pointwise_estimate: None,
                verdict: if n + 1 == iterations {
                    Verdict::Converged
                } else {
                    Verdict::Continue
                },
            }),
        });
    }
    for (i, itf) in model.interfaces.iter().enumerate() {
        let np = itf.n_pairs();
        let field = |scale: f64| Field::from_fn(2 * np, nt, |r, t| scale * (r + t) as f64);
        put(Message {
            envelope: envelope(iterations - 1, Stage::Final, Role::Interface, 0),
            payload: Payload::InterfaceSolution(InterfaceSolution {
                interface: i as u32,
                w_a: field(1e-5),
                w_b: field(1e-5),
                f_a: field(-1.0),
                f_b: field(1.0),
                w_a_hat: field(1e-5),
                w_b_hat: field(1e-5),
                f_a_hat: field(-1.0),
                f_b_hat: field(1.0),
                status: (0..np * nt).map(|k| (k % 3) as u8).collect(),
            }),
        });
    }
    rec.finish().unwrap();

    let recording = Recording::open(&mcap).unwrap();
    let rrd = dir.join("two-blocks-r.rrd");
    let summary = replay(
        &recording,
        &ReplayOptions {
            sink: Sink::Save(rrd.clone()),
            color_by: ColorBy::VonMises,
            amplification: None,
            time_point: None,
            reference: false,
            basis_sizes: Vec::new(),
        },
    )
    .unwrap();
    let n_sub = model.subdomains.len();
    assert_eq!(summary.iterations, iterations as usize);
    // One mesh per subdomain and iteration, and per subdomain and time point at the end.
    assert_eq!(summary.meshes, n_sub * iterations as usize + n_sub * nt);
    assert!(!summary.interior_recorded);
    assert!(std::fs::metadata(&rrd).unwrap().len() > 10_000);

    // The colour scale: the 2nd and 98th percentiles of the von Mises stress at every node and
    // time point of the final state, computed here by sorting (numpy's "linear" percentile).
    let state = final_state(&recording).unwrap();
    let mut values: Vec<f64> = state
        .u
        .iter()
        .flat_map(|(&s, per_time)| {
            let sub = &model.subdomains[s as usize];
            per_time.iter().flat_map(|u| {
                nodal_stresses(sub, model.plane, u)
                    .unwrap()
                    .iter()
                    .map(von_mises)
                    .collect::<Vec<_>>()
            })
        })
        .collect();
    values.sort_by(f64::total_cmp);
    let percentile = |p: f64| {
        let h = (values.len() - 1) as f64 * p / 100.0;
        let k = h.floor() as usize;
        values[k] + (h - k as f64) * (values[(k + 1).min(values.len() - 1)] - values[k])
    };
    let (lo, hi) = (percentile(2.0), percentile(98.0));
    let (min, max) = (values[0], values[values.len() - 1]);
    // The scale is narrower than the extremes here (the field is not uniform).
    assert!(min < lo && lo < hi && hi < max, "{min} {lo} {hi} {max}");
    // Same order statistics and the same interpolation formula: equal up to the last bits.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1e-300);
    let r = summary.color_range.expect("a colour range");
    assert!(close(r.lo, lo) && close(r.hi, hi), "{r:?} against {lo} – {hi}");
    assert_eq!((r.min, r.max), (min, max));

    // What the viewer opens: the .rrd read back with Rerun's decoder.
    let c = RrdContents::read(&rrd).unwrap();
    assert_eq!((c.blueprints, c.activations), (1, 1), "{c:?}");
    assert_eq!((c.auto_layout, c.auto_views), (Some(false), Some(false)));
    assert_eq!(c.time_panel_timeline.as_deref(), Some("iteration"));
    assert_eq!(c.views.len(), 4, "{:?}", c.views);
    let structure = c.view(STRUCTURE_VIEW).expect("structure view");
    assert_eq!(structure.class, "3D");
    for q in ["+ /subdomains/**", "+ /interfaces/**", "+ /legend/**"] {
        assert!(structure.contents.iter().any(|c| c == q), "{q}: {structure:?}");
    }
    // The eye straight above the model's middle (x), looking down -z with +y up.
    let (eye, target, up) = structure.eye.expect("the structure view's eye");
    let xs = model.subdomains.iter().flat_map(|s| s.mesh.coords.iter().map(|x| x[0]));
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
    assert_eq!((eye[0], eye[1]), (target[0], target[1]));
    assert_eq!(target[0], (0.5 * (x0 + x1)) as f32);
    assert!(eye[2] > 0.0 && target[2] == 0.0, "{eye:?} {target:?}");
    assert_eq!(up, [0.0, 1.0, 0.0]);
    let convergence = c.view(CONVERGENCE_VIEW).expect("convergence view");
    assert_eq!(convergence.class, "TimeSeries");
    assert_eq!(convergence.contents, CONVERGENCE.map(|e| format!("+ /{e}")));
    assert_eq!(c.view(COUNTS_VIEW).expect("counts view").class, "TimeSeries");
    let forces = c.view(FORCES_VIEW).expect("forces view");
    assert_eq!(forces.class, "TimeSeries");
    assert_eq!(forces.contents, ["+ /resultants/**", "+ /boundary/**"]);
    for e in [
        "legend/strip",
        "legend/ticks",
        "legend/title",
        "legend/range",
        "indicators/log10_eta",
    ] {
        assert!(c.entities.iter().any(|x| x == e), "{e}: {:?}", c.entities);
    }
    assert!(!c.entities.iter().any(|x| x.starts_with("interface_tractions")));
    let stated = |k: &str| {
        c.legend_range
            .get(k)
            .copied()
            .unwrap_or_else(|| panic!("legend/range:{k}"))
    };
    assert_eq!((stated("lower"), stated("upper")), (r.lo, r.hi));
    assert_eq!((stated("min"), stated("max")), (min, max));
    assert_eq!((stated("lower_percentile"), stated("upper_percentile")), (2.0, 98.0));

    match Command::new("rerun").arg("--version").output() {
        Ok(o) if o.status.success() => {
            let version = String::from_utf8_lossy(&o.stdout).to_string();
            let v = Command::new("rerun")
                .args(["rrd", "verify"])
                .arg(&rrd)
                .output()
                .unwrap();
            assert!(
                v.status.success(),
                "`rerun rrd verify` ({version}) rejected the file: {}{}",
                String::from_utf8_lossy(&v.stdout),
                String::from_utf8_lossy(&v.stderr)
            );
            println!("`rerun rrd verify` accepted the .rrd ({})", version.trim());
        }
        _ => println!("skipped `rerun rrd verify`: no `rerun` CLI on PATH (pip install rerun-sdk==0.36.3)"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}
