//! A study's tables: one CSV row per variant, time point and contact interface, one JSON
//! document with every variant, and the console's one-screen summary.

use crate::driver::{StudyRun, VariantOutcome};
use crate::quantities::{index_of, peak, unit, QUANTITIES};
use serde_json::{json, Value};
use std::fmt::Write as _;

/// `text` as one field of a CSV row (RFC 4180): as it is, unless it holds a comma, a double quote
/// or a line break (a Gmsh physical name may), then between double quotes with each of its double
/// quotes doubled. Every CSV of the project writes its names through it.
pub fn csv_field(text: &str) -> std::borrow::Cow<'_, str> {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\"")).into()
    } else {
        text.into()
    }
}

/// The CSV: `variant`, each parameter, `verdict`, `iterations`, `started_from`, `time_s`,
/// `interface`, `a`, `b` and every quantity with its unit in the header. A variant without a
/// result has one row with its reason as the verdict and the rest empty.
pub fn csv(run: &StudyRun) -> String {
    let mut s = String::from("variant");
    for p in &run.study.parameters {
        let _ = write!(s, ",{}", csv_field(&p.name));
    }
    s.push_str(",verdict,iterations,started_from,time_s,interface,a,b");
    for (q, (name, _)) in QUANTITIES.iter().enumerate() {
        let unit = unit(q, run.plane).replace('/', "_per_").replace('·', "_");
        let _ = write!(s, ",{name}_{unit}");
    }
    s.push('\n');
    for o in &run.outcomes {
        let mut head = o.variant.index.to_string();
        for v in &o.variant.values {
            let _ = write!(head, ",{v:?}");
        }
        let from = o.started_from.map_or(String::new(), |f| f.to_string());
        match &o.result {
            Err(why) => {
                let _ = writeln!(
                    s,
                    "{head},{},,{from}{}",
                    csv_field(why),
                    ",".repeat(4 + QUANTITIES.len())
                );
            }
            Ok((solved, qs)) => {
                let verdict = csv_field(&solved.verdict_text);
                for (i, t) in o.time.iter().enumerate() {
                    for q in qs {
                        let _ = write!(
                            s,
                            "{head},{verdict},{},{from},{t:?},{},{},{}",
                            solved.iterations,
                            q.interface,
                            csv_field(&q.a),
                            csv_field(&q.b)
                        );
                        for series in &q.values {
                            let _ = write!(s, ",{:?}", series[i]);
                        }
                        s.push('\n');
                    }
                }
            }
        }
    }
    s
}

/// The JSON document: the study (scene, parameters, design), whether it ran cold, its wall
/// time, and per variant its values, verdict, iterations, estimate, times, operators, start and
/// every contact interface's quantities per time point.
pub fn json(run: &StudyRun) -> Value {
    let parameters: Vec<Value> = run
        .study
        .parameters
        .iter()
        .map(|p| json!({ "name": p.name, "values": p.values }))
        .collect();
    let units: serde_json::Map<String, Value> = QUANTITIES
        .iter()
        .enumerate()
        .map(|(q, (n, _))| (n.to_string(), json!(unit(q, run.plane))))
        .collect();
    let variants: Vec<Value> = run.outcomes.iter().map(|o| variant_json(run, o)).collect();
    json!({
        "study": run.study.name,
        "scene": run.study.scene.display().to_string(),
        "cold": run.cold,
        "wall_s": run.wall_s,
        "parameters": parameters,
        "units": units,
        "variants": variants,
    })
}

fn variant_json(run: &StudyRun, o: &VariantOutcome) -> Value {
    let values: serde_json::Map<String, Value> = run
        .study
        .parameters
        .iter()
        .zip(&o.variant.values)
        .map(|(p, v)| (p.name.clone(), json!(v)))
        .collect();
    let mut v = json!({
        "variant": o.variant.index,
        "values": values,
        "started_from": o.started_from,
        "wall_s": o.wall_s,
        "time_s": o.time,
    });
    match &o.result {
        Err(why) => v["error"] = json!(why),
        Ok((s, qs)) => {
            v["verdict"] = json!(s.verdict_text);
            v["converged"] = json!(o.converged());
            v["iterations"] = json!(s.iterations);
            v["estimate"] = json!(s.estimate);
            v["setup_s"] = json!(s.setup_s);
            v["solve_s"] = json!(s.solve_s);
            v["operators"] = json!(s.operators);
            v["boundary_rules"] = json!(s.rules);
            v["interfaces"] = qs
                .iter()
                .map(|q| {
                    let mut m = serde_json::Map::new();
                    m.insert("interface".into(), json!(q.interface));
                    m.insert("a".into(), json!(q.a));
                    m.insert("b".into(), json!(q.b));
                    for ((name, _), series) in QUANTITIES.iter().zip(&q.values) {
                        m.insert(name.to_string(), json!(series));
                    }
                    Value::Object(m)
                })
                .collect();
        }
    }
    v
}

/// A verdict in one or two words (the CSV and JSON have the run's own wording).
fn short(v: &glissade_messages::Verdict) -> &'static str {
    use glissade_messages::Verdict as V;
    match v {
        V::Converged => "Converged",
        V::MaxIterations => "NOT converged: iteration cap",
        V::Stagnated { .. } => "NOT converged: stagnated",
        V::Diverged { .. } => "Diverged",
        V::NoEquilibrium { .. } => "NOT converged: no equilibrium",
        V::Continue => "stopped early",
    }
}

/// The console's summary: one line per variant (its values, verdict, iterations, start, time
/// and the peaks of the reported quantities), then the totals.
pub fn summary(run: &StudyRun) -> Vec<String> {
    let report: Vec<usize> = run.study.report.iter().filter_map(|q| index_of(q)).collect();
    let mut head = String::from("variant");
    for p in &run.study.parameters {
        let _ = write!(head, " | {}", p.name);
    }
    head.push_str(" | iterations | from | s");
    for &q in &report {
        let _ = write!(head, " | peak {} ({})", QUANTITIES[q].0, unit(q, run.plane));
    }
    let _ = write!(head, " | peak support reaction ({}) | verdict", run.plane.force_unit());
    let mut lines = vec![head];
    for o in &run.outcomes {
        let mut l = format!("{:>7}", o.variant.index);
        for v in &o.variant.values {
            let _ = write!(l, " | {v}");
        }
        let from = o.started_from.map_or("cold".to_string(), |f| f.to_string());
        match &o.result {
            Err(why) => {
                let _ = write!(l, " | — | {from} | {:.2} | {why}", o.wall_s);
            }
            Ok((s, qs)) => {
                let _ = write!(l, " | {} | {from} | {:.2}", s.iterations, o.wall_s);
                for &q in &report {
                    let _ = write!(l, " | {:.4e}", peak(qs, q));
                }
                let reaction = s
                    .rules
                    .iter()
                    .filter(|r| r.kind == crate::boundary::RuleKind::Support)
                    .map(|r| r.peak())
                    .fold(0.0, f64::max);
                let _ = write!(l, " | {reaction:.4e} | {}", short(&s.verdict));
            }
        }
        lines.push(l);
    }
    let converged = run.outcomes.iter().filter(|o| o.converged()).count();
    let iterations: usize = run
        .outcomes
        .iter()
        .filter_map(|o| o.result.as_ref().ok())
        .map(|(s, _)| s.iterations)
        .sum();
    lines.push(format!(
        "{} variants ({}), {converged} converged, {iterations} iterations in all, {:.1} s",
        run.outcomes.len(),
        if run.cold {
            "cold: each from ŝ = 0, operators built anew"
        } else {
            "warm: each from its nearest converged variant, operators reused"
        },
        run.wall_s
    ));
    lines
}
