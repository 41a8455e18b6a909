//! A variant's scene: the scene's text with the variant's values written in, so that the scene
//! crate builds and checks it exactly as it does a file (the variant's text is what its
//! recording attaches). Comments of the scene do not survive the rewrite.

use crate::study::{Study, Target};
use crate::variants::Variant;
use crate::StudyError;
use toml::{Table, Value};

/// The keys of a boundary rule that hold values (time functions or formulas).
const VALUE_KEYS: [&str; 6] = ["ux", "uy", "tx", "ty", "p", "shear"];

/// The text of `variant`'s scene: `scene_text` with each parameter's value written in.
pub fn variant_text(study: &Study, scene_text: &str, variant: &Variant) -> Result<String, StudyError> {
    let scene = study.scene.display().to_string();
    let mut table: Table = scene_text
        .parse()
        .map_err(|e: toml::de::Error| StudyError::new(&scene, e.message().to_string()))?;
    for (p, &v) in study.parameters.iter().zip(&variant.values) {
        apply(&mut table, &p.target, v).map_err(|problem| StudyError::new(format!("{scene}: {}", p.name), problem))?;
    }
    let body = toml::to_string(&table)
        .map_err(|e| StudyError::new(&scene, format!("cannot write the variant's scene: {e}")))?;
    let values: Vec<String> = study
        .parameters
        .iter()
        .zip(&variant.values)
        .map(|(p, v)| format!("{} = {v}", p.name))
        .collect();
    Ok(format!(
        "# variant {} of study {}: {}\n{body}",
        variant.index,
        study.name,
        values.join(", ")
    ))
}

/// `variant`'s scene, built and checked by the scene crate as a file is, with the study's accuracy
/// when it sets one. The outer error is the study's (it names what the scene lacks); the inner
/// one the variant's (the scene refuses one of its values).
pub fn variant_scene(
    study: &Study,
    scene_text: &str,
    variant: &Variant,
) -> Result<Result<glissade_scene::LoadedScene, glissade_scene::SceneError>, StudyError> {
    let text = variant_text(study, scene_text, variant)?;
    let file = study.scene.display().to_string();
    let overrides = glissade_scene::Overrides {
        accuracy: study.accuracy,
        ..Default::default()
    };
    Ok(glissade_scene::load_str(&text, &file).and_then(|s| s.with_overrides(&file, &overrides)))
}

/// Writes value `v` of `target` into the scene `table`.
fn apply(table: &mut Table, target: &Target, v: f64) -> Result<(), String> {
    match target {
        Target::Friction { rule } => contact_rules(table, *rule, |r| {
            r.insert("friction".into(), Value::Float(v));
        }),
        Target::Gap { rule } => contact_rules(table, *rule, |r| {
            r.insert("gap".into(), Value::Float(v));
        }),
        Target::Scale { rule } => {
            let rules = array(table, "boundary")?;
            let n = rules.len();
            let r = rules
                .get_mut(*rule)
                .and_then(Value::as_table_mut)
                .ok_or_else(|| format!("the scene has {n} boundary rule(s), numbered from 0"))?;
            let mut scaled = 0;
            for key in VALUE_KEYS {
                if let Some(value) = r.get_mut(key) {
                    *value = scale(value, v).map_err(|e| format!("boundary[{rule}].{key}: {e}"))?;
                    scaled += 1;
                }
            }
            if scaled == 0 {
                return Err(format!("boundary[{rule}] has no value to scale"));
            }
            Ok(())
        }
        Target::Young { material } | Target::Poisson { material } => {
            let key = if matches!(target, Target::Young { .. }) {
                "E"
            } else {
                "nu"
            };
            let m = table
                .get_mut("materials")
                .and_then(Value::as_table_mut)
                .and_then(|ms| ms.get_mut(material))
                .and_then(Value::as_table_mut)
                .ok_or_else(|| format!("the scene has no material `{material}`"))?;
            m.insert(key.into(), Value::Float(v));
            Ok(())
        }
    }
}

/// The array of tables `key` of the scene.
fn array<'t>(table: &'t mut Table, key: &str) -> Result<&'t mut Vec<Value>, String> {
    table
        .get_mut(key)
        .and_then(Value::as_array_mut)
        .ok_or_else(|| format!("the scene has no [[{key}]] rule"))
}

/// Calls `f` on contact rule `rule`, or on every contact rule; an error where there is none.
fn contact_rules(table: &mut Table, rule: Option<usize>, mut f: impl FnMut(&mut Table)) -> Result<(), String> {
    let rules = array(table, "interface")?;
    let n = rules.len();
    let is_contact = |r: &Table| r.get("kind").and_then(Value::as_str) == Some("contact");
    match rule {
        Some(k) => {
            let r = rules
                .get_mut(k)
                .and_then(Value::as_table_mut)
                .ok_or_else(|| format!("the scene has {n} interface rule(s), numbered from 0"))?;
            if !is_contact(r) {
                return Err(format!("interface[{k}] is not a contact rule"));
            }
            f(r);
        }
        None => {
            let mut any = false;
            for r in rules
                .iter_mut()
                .filter_map(Value::as_table_mut)
                .filter(|r| is_contact(r))
            {
                f(r);
                any = true;
            }
            if !any {
                return Err("the scene has no contact rule".into());
            }
        }
    }
    Ok(())
}

/// A boundary value times `s`: a number, a formula (string) or a table `{ t = [..], v = [..] }`.
fn scale(value: &Value, s: f64) -> Result<Value, String> {
    match value {
        Value::Integer(i) => Ok(Value::Float(*i as f64 * s)),
        Value::Float(f) => Ok(Value::Float(f * s)),
        Value::String(e) => Ok(Value::String(format!("({s:?})*({e})"))),
        Value::Table(t) => {
            let mut t = t.clone();
            let vs = t
                .get_mut("v")
                .and_then(Value::as_array_mut)
                .ok_or("a table value without `v`")?;
            for x in vs.iter_mut() {
                *x = match x {
                    Value::Integer(i) => Value::Float(*i as f64 * s),
                    Value::Float(f) => Value::Float(*f * s),
                    _ => return Err("a table value whose `v` holds something else than numbers".into()),
                };
            }
            Ok(Value::Table(t))
        }
        other => Err(format!("a {} cannot be scaled", other.type_str())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Study;
    use std::path::Path;

    const SCENE: &str = "name = \"x\"\n[materials.steel]\nE = 210000.0\nnu = 0.3\n\
        [[interface]]\nbetween = [\"a\", \"b\"]\nkind = \"perfect\"\n\
        [[interface]]\nbetween = [\"b\", \"c\"]\nkind = \"contact\"\nfriction = 0.2\n\
        [[boundary]]\nside = \"left\"\nux = 0\nuy = 0\n\
        [[boundary]]\nside = \"top\"\np = \"10*t\"\nshear = { t = [0, 1], v = [0, 2] }\ntx = 3\n";

    fn patched(vary: &str) -> Result<Table, StudyError> {
        let study = Study::from_vary(Path::new("x.toml"), &[vary.into()], None)?;
        let v = crate::variants::variants(&study).remove(0);
        Ok(variant_text(&study, SCENE, &v)?.parse().unwrap())
    }

    #[test]
    fn each_kind_of_parameter_is_written_where_it_belongs() {
        let t = patched("friction=0.35").unwrap();
        assert_eq!(t["interface"][1]["friction"].as_float(), Some(0.35));
        assert!(t["interface"][0].get("friction").is_none());
        let t = patched("interface[1].gap=-0.01").unwrap();
        assert_eq!(t["interface"][1]["gap"].as_float(), Some(-0.01));
        let t = patched("materials.steel.nu=0.25").unwrap();
        assert_eq!(t["materials"]["steel"]["nu"].as_float(), Some(0.25));
        let t = patched("boundary[1].scale=1.5").unwrap();
        let b = &t["boundary"][1];
        assert_eq!(b["p"].as_str(), Some("(1.5)*(10*t)"));
        assert_eq!(b["tx"].as_float(), Some(4.5));
        assert_eq!(b["shear"]["v"][1].as_float(), Some(3.0));
    }

    #[test]
    fn a_parameter_the_scene_lacks_is_named() {
        let e = |v: &str| patched(v).unwrap_err().to_string();
        assert!(e("interface[0].friction=0.1").contains("interface[0] is not a contact rule"));
        assert!(e("interface[5].gap=0").contains("2 interface rule(s)"));
        assert!(e("materials.alu.E=7e4").contains("no material `alu`"));
        assert!(e("boundary[2].scale=2").contains("2 boundary rule(s)"));
    }
}
