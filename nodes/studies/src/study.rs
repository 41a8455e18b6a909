//! The study file and the one-line form of a varied parameter.
//!
//! ```toml
//! scene = "../scenes/stratified.toml"      # relative to the study file
//! accuracy = 1e-3                           # optional: every variant's solver.accuracy
//! report = ["tangential", "slip_share"]     # optional: the quantities plotted and printed
//!                                           # (default: DEFAULT_REPORT)
//!
//! [[vary]]
//! parameter = "friction"                    # every contact rule's friction
//! values = [0.1, 0.2, 0.3]
//!
//! [[vary]]
//! parameter = "boundary[3].scale"           # a factor on every value of boundary rule 3
//! range = "0.5:1.2:8"                       # 8 values from 0.5 to 1.2
//!
//! [design]                                  # optional: "grid" (every combination, the default)
//! kind = "sample"                           # or a seeded sample, uniform in each range
//! count = 20
//! seed = 1
//! ```

use crate::StudyError;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// What a parameter changes in the scene.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// The friction of contact rule `rule` (an index of `[[interface]]`), or of every contact rule.
    Friction { rule: Option<usize> },
    /// The initial gap g0 (mm, uniform) of contact rule `rule`, or of every contact rule.
    Gap { rule: Option<usize> },
    /// A factor on every value (displacements and tractions) of boundary rule `rule`.
    Scale { rule: usize },
    /// Young's modulus E (MPa) of a material.
    Young { material: String },
    /// Poisson's ratio ν of a material.
    Poisson { material: String },
}

impl Target {
    /// Parses a parameter's name: `friction`, `gap`, `interface[k].friction`,
    /// `interface[k].gap`, `boundary[k].scale`, `materials.<name>.E`, `materials.<name>.nu`.
    pub fn parse(name: &str) -> Result<Target, String> {
        let index = |rest: &str, what: &str| -> Result<(usize, String), String> {
            let (k, field) = rest
                .split_once("].")
                .ok_or_else(|| format!("`{name}`: expected `{what}[k].<field>`"))?;
            let k = k
                .parse::<usize>()
                .map_err(|_| format!("`{name}`: `{k}` is not a rule index (0, 1, …)"))?;
            Ok((k, field.to_string()))
        };
        let known = "friction, gap, interface[k].friction, interface[k].gap, boundary[k].scale, \
                     materials.<name>.E or materials.<name>.nu";
        match name {
            "friction" => return Ok(Target::Friction { rule: None }),
            "gap" => return Ok(Target::Gap { rule: None }),
            _ => {}
        }
        if let Some(rest) = name.strip_prefix("interface[") {
            let (rule, field) = index(rest, "interface")?;
            return match field.as_str() {
                "friction" => Ok(Target::Friction { rule: Some(rule) }),
                "gap" => Ok(Target::Gap { rule: Some(rule) }),
                f => Err(format!(
                    "`{name}`: an interface rule's `{f}` cannot vary (friction or gap)"
                )),
            };
        }
        if let Some(rest) = name.strip_prefix("boundary[") {
            let (rule, field) = index(rest, "boundary")?;
            return match field.as_str() {
                "scale" => Ok(Target::Scale { rule }),
                f => Err(format!(
                    "`{name}`: a boundary rule varies by a factor on its values, `boundary[{rule}].scale`, not `{f}`"
                )),
            };
        }
        if let Some(rest) = name.strip_prefix("materials.") {
            if let Some((material, field)) = rest.rsplit_once('.') {
                return match field {
                    "E" => Ok(Target::Young {
                        material: material.into(),
                    }),
                    "nu" => Ok(Target::Poisson {
                        material: material.into(),
                    }),
                    f => Err(format!("`{name}`: a material's `{f}` cannot vary (E or nu)")),
                };
            }
        }
        Err(format!("`{name}` is not a parameter that can vary: {known}"))
    }

    /// Whether `v` is a value this parameter may take, or why not.
    pub fn check(&self, v: f64) -> Result<(), String> {
        let bad = |why: &str| Err(format!("{v} {why}"));
        if !v.is_finite() {
            return bad("is not finite");
        }
        match self {
            Target::Friction { .. } if v < 0.0 => bad("is negative: a friction coefficient is ≥ 0"),
            Target::Young { .. } if v <= 0.0 => bad("is not > 0: Young's modulus"),
            Target::Poisson { .. } if !(v > -1.0 && v < 0.5) => bad("is outside (−1, 0.5): Poisson's ratio"),
            _ => Ok(()),
        }
    }

    /// Whether changing this parameter leaves every subdomain operator valid (docs/studies.md, "How variants are solved"): a
    /// friction, gap or load change does; a material change does not.
    pub fn keeps_operators(&self) -> bool {
        !matches!(self, Target::Young { .. } | Target::Poisson { .. })
    }
}

/// One varied parameter: its name as written, what it changes and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct Parameter {
    pub name: String,
    pub target: Target,
    pub values: Vec<f64>,
}

/// How the variants are made of the parameters' values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Design {
    /// Every combination (the product of the value lists).
    Grid,
    /// `count` variants, each parameter drawn uniformly between its smallest and largest value,
    /// from a generator seeded with `seed` (the same seed gives the same variants everywhere).
    Sample { count: usize, seed: u64 },
}

/// A study: a scene and what varies.
#[derive(Debug, Clone, PartialEq)]
pub struct Study {
    /// Names the outputs (`<name>.csv`, …): the study file's stem, or the scene's for `--vary`.
    pub name: String,
    pub scene: PathBuf,
    pub parameters: Vec<Parameter>,
    pub design: Design,
    /// Every variant's `solver.accuracy`, when the study sets it.
    pub accuracy: Option<f64>,
    /// The quantities plotted and printed ([`crate::quantities::QUANTITIES`] names).
    pub report: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStudy {
    scene: String,
    accuracy: Option<f64>,
    report: Option<Vec<String>>,
    #[serde(default)]
    vary: Vec<RawVary>,
    design: Option<RawDesign>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVary {
    parameter: String,
    values: Option<Vec<f64>>,
    range: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDesign {
    kind: String,
    count: Option<usize>,
    seed: Option<u64>,
}

/// Most variants a study may have (each is a solve).
pub const MAX_VARIANTS: usize = 10_000;

/// `from:to:count`: `count` ≥ 2 values evenly spaced from `from` to `to`, both included (or
/// `from` alone with count 1), or a comma-separated list `v1,v2,…`.
pub fn parse_values(text: &str) -> Result<Vec<f64>, String> {
    let number = |s: &str| {
        s.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{}` is not a number", s.trim()))
    };
    if text.contains(':') {
        let parts: Vec<&str> = text.split(':').collect();
        let [from, to, count] = parts[..] else {
            return Err(format!("`{text}`: a range is `from:to:count`"));
        };
        let (from, to) = (number(from)?, number(to)?);
        let count: usize = count
            .trim()
            .parse()
            .map_err(|_| format!("`{text}`: the count `{}` is not a whole number ≥ 1", count.trim()))?;
        return match count {
            0 => Err(format!("`{text}`: the count is 0")),
            1 if from == to => Ok(vec![from]),
            1 => Err(format!("`{text}`: one value cannot span {from} to {to}")),
            n if n > MAX_VARIANTS => Err(format!("`{text}`: more than {MAX_VARIANTS} values")),
            n => Ok((0..n)
                .map(|i| {
                    let s = i as f64 / (n - 1) as f64;
                    if i == n - 1 {
                        to
                    } else {
                        // 12 significant digits: 0.1:0.4:4 gives 0.3, not 0.30000000000000004;
                        // and 0 where the step lands on it within round-off of the span.
                        let v = from + s * (to - from);
                        if v.abs() <= 1e-12 * (to - from).abs() {
                            0.0
                        } else {
                            format!("{v:.11e}").parse().unwrap_or(v)
                        }
                    }
                })
                .collect()),
        };
    }
    text.split(',').map(number).collect()
}

impl Study {
    /// Reads the study file at `path`; the scene is relative to the file's folder.
    pub fn read(path: &Path) -> Result<Study, StudyError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| StudyError::new(&file, format!("cannot read: {e}")))?;
        let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("study").to_string();
        let base = path.parent().unwrap_or(Path::new(""));
        Study::parse(&text, &file, &name, base)
    }

    /// Parses a study's `text` (`file` names it in errors; `base` is the folder its scene path is
    /// relative to).
    pub fn parse(text: &str, file: &str, name: &str, base: &Path) -> Result<Study, StudyError> {
        let raw: RawStudy = toml::from_str(text).map_err(|e| {
            let at = e.span().map_or(String::new(), |s| {
                let line = text[..s.start.min(text.len())].lines().count().max(1);
                format!(" (line {line})")
            });
            StudyError::new(format!("{file}{at}"), e.message().to_string())
        })?;
        let place = |key: String| format!("{file}: {key}");
        let mut parameters = Vec::new();
        for (i, v) in raw.vary.iter().enumerate() {
            let target =
                Target::parse(&v.parameter).map_err(|p| StudyError::new(place(format!("vary[{i}].parameter")), p))?;
            let values = match (&v.values, &v.range) {
                (Some(vs), None) => vs.clone(),
                (None, Some(r)) => {
                    parse_values(r).map_err(|p| StudyError::new(place(format!("vary[{i}].range")), p))?
                }
                _ => {
                    return Err(StudyError::new(
                        place(format!("vary[{i}]")),
                        "give either `values = [..]` or `range = \"from:to:count\"`",
                    ))
                }
            };
            parameters.push(Parameter {
                name: v.parameter.clone(),
                target,
                values,
            });
        }
        let design = match &raw.design {
            None => Design::Grid,
            Some(d) => match (d.kind.as_str(), d.count, d.seed) {
                ("grid", None, None) => Design::Grid,
                ("grid", ..) => return Err(StudyError::new(place("design".into()), "a grid takes no count or seed")),
                ("sample", Some(count), seed) if (1..=MAX_VARIANTS).contains(&count) => Design::Sample {
                    count,
                    seed: seed.unwrap_or(0),
                },
                ("sample", ..) => {
                    return Err(StudyError::new(
                        place("design.count".into()),
                        format!("a sample needs a count of variants from 1 to {MAX_VARIANTS}"),
                    ))
                }
                (k, ..) => {
                    return Err(StudyError::new(
                        place("design.kind".into()),
                        format!("`{k}` is not a design: \"grid\" or \"sample\""),
                    ))
                }
            },
        };
        let study = Study {
            name: name.to_string(),
            scene: base.join(&raw.scene),
            parameters,
            design,
            accuracy: raw.accuracy,
            report: raw.report.unwrap_or_else(default_report),
        };
        let places: Vec<String> = (0..study.parameters.len())
            .map(|i| format!("{file}: vary[{i}] ({})", study.parameters[i].name))
            .collect();
        study.validate(file, &places)?;
        Ok(study)
    }

    /// A study of the scene at `scene` from `--vary name=values` arguments (a grid).
    pub fn from_vary(scene: &Path, vary: &[String], accuracy: Option<f64>) -> Result<Study, StudyError> {
        let mut parameters = Vec::new();
        for arg in vary {
            let place = format!("--vary {arg}");
            let (name, values) = arg
                .split_once('=')
                .ok_or_else(|| StudyError::new(&place, "expected `name=from:to:count` or `name=v1,v2,…`"))?;
            let target = Target::parse(name.trim()).map_err(|p| StudyError::new(&place, p))?;
            let values = parse_values(values).map_err(|p| StudyError::new(&place, p))?;
            parameters.push(Parameter {
                name: name.trim().to_string(),
                target,
                values,
            });
        }
        let name = scene
            .file_stem()
            .and_then(|s| s.to_str())
            .map_or("study".to_string(), |s| format!("{s}-sweep"));
        let study = Study {
            name,
            scene: scene.to_path_buf(),
            parameters,
            design: Design::Grid,
            accuracy,
            report: default_report(),
        };
        let places: Vec<String> = vary.iter().map(|a| format!("--vary {a}")).collect();
        study.validate("--vary", &places)?;
        Ok(study)
    }

    /// Checks the study; `places[i]` names where parameter i was given.
    fn validate(&self, file: &str, places: &[String]) -> Result<(), StudyError> {
        if self.parameters.is_empty() {
            return Err(StudyError::new(
                file,
                "nothing varies: add a `[[vary]]` table (or `--vary`)",
            ));
        }
        for (i, p) in self.parameters.iter().enumerate() {
            let place = || StudyError::new(&places[i], "");
            if p.values.is_empty() {
                return Err(StudyError {
                    problem: "has no value".into(),
                    ..place()
                });
            }
            for &v in &p.values {
                p.target.check(v).map_err(|problem| StudyError { problem, ..place() })?;
            }
            if let Some(j) = self.parameters[..i].iter().position(|q| overlap(&q.target, &p.target)) {
                return Err(StudyError {
                    problem: format!("varies what {} varies", places[j]),
                    ..place()
                });
            }
        }
        if let Some(a) = self.accuracy {
            if !(a > 0.0 && a < 1.0) {
                return Err(StudyError::new(
                    format!("{file}: accuracy"),
                    format!("{a} is not in (0, 1)"),
                ));
            }
        }
        for (i, q) in self.report.iter().enumerate() {
            if self.report[..i].contains(q) {
                return Err(StudyError::new(
                    format!("{file}: report"),
                    format!("`{q}` is named twice"),
                ));
            }
            if !crate::quantities::QUANTITIES.iter().any(|(n, _)| n == q) {
                let names: Vec<&str> = crate::quantities::QUANTITIES.iter().map(|(n, _)| *n).collect();
                return Err(StudyError::new(
                    format!("{file}: report"),
                    format!("`{q}` is not a quantity: {}", names.join(", ")),
                ));
            }
        }
        let count = match self.design {
            Design::Grid => self
                .parameters
                .iter()
                .try_fold(1usize, |n, p| n.checked_mul(p.values.len()))
                .unwrap_or(usize::MAX),
            Design::Sample { count, .. } => count,
        };
        let names = crate::plot::file_names(self);
        if let Some(n) = (0..names.len())
            .find(|&k| names[..k].contains(&names[k]))
            .map(|k| &names[k])
        {
            return Err(StudyError::new(
                file,
                format!("two plots would be written to `{n}`: parameter names that differ only in characters other than letters, digits, `-` and `_`"),
            ));
        }
        if count > MAX_VARIANTS {
            return Err(StudyError::new(
                file,
                format!("{count} variants: at most {MAX_VARIANTS}"),
            ));
        }
        Ok(())
    }
}

/// The quantities plotted and printed when a study does not say (the CSV and JSON hold all).
pub const DEFAULT_REPORT: [&str; 4] = ["normal", "tangential", "slip_share", "max_pressure"];

/// Whether two parameters change the same value of the scene: the same target, or every contact
/// rule's friction (gap) and one rule's.
fn overlap(a: &Target, b: &Target) -> bool {
    match (a, b) {
        (Target::Friction { rule: x }, Target::Friction { rule: y })
        | (Target::Gap { rule: x }, Target::Gap { rule: y }) => x.is_none() || y.is_none() || x == y,
        _ => a == b,
    }
}

fn default_report() -> Vec<String> {
    DEFAULT_REPORT.iter().map(|n| n.to_string()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_names_parse_to_their_targets() {
        assert_eq!(Target::parse("friction"), Ok(Target::Friction { rule: None }));
        assert_eq!(Target::parse("interface[2].gap"), Ok(Target::Gap { rule: Some(2) }));
        assert_eq!(Target::parse("boundary[0].scale"), Ok(Target::Scale { rule: 0 }));
        assert_eq!(
            Target::parse("materials.steel.E"),
            Ok(Target::Young {
                material: "steel".into()
            })
        );
        assert_eq!(
            Target::parse("materials.a.b.nu"),
            Ok(Target::Poisson { material: "a.b".into() })
        );
        for bad in [
            "E",
            "interface[x].gap",
            "boundary[1].ux",
            "materials.steel.rho",
            "interface[1]",
        ] {
            assert!(Target::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn ranges_include_both_ends() {
        assert_eq!(parse_values("0.1:0.3:3").unwrap(), vec![0.1, 0.2, 0.3]);
        assert_eq!(parse_values("0.1:0.4:4").unwrap(), vec![0.1, 0.2, 0.3, 0.4]);
        assert_eq!(parse_values("-0.1:0.2:4").unwrap(), vec![-0.1, 0.0, 0.1, 0.2]);
        assert_eq!(parse_values("1:2:2").unwrap(), vec![1.0, 2.0]);
        assert_eq!(parse_values("0.5,1,2").unwrap(), vec![0.5, 1.0, 2.0]);
        assert_eq!(parse_values("3:3:1").unwrap(), vec![3.0]);
        for bad in ["1:2", "1:2:0", "1:2:1", "a:2:3", "1,,2", "1:2:x"] {
            assert!(parse_values(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_study_file_is_read_and_its_mistakes_named() {
        let text = "scene = \"s.toml\"\naccuracy = 1e-3\n[[vary]]\nparameter = \"friction\"\nvalues = [0.1, 0.2]\n\
                    [[vary]]\nparameter = \"boundary[1].scale\"\nrange = \"0.5:1:3\"\n";
        let s = Study::parse(text, "a.toml", "a", Path::new("studies")).unwrap();
        assert_eq!(s.scene, Path::new("studies/s.toml"));
        assert_eq!(s.parameters.len(), 2);
        assert_eq!(s.parameters[1].values, vec![0.5, 0.75, 1.0]);
        assert_eq!(s.design, Design::Grid);
        let err = |t: &str| Study::parse(t, "a.toml", "a", Path::new("")).unwrap_err().to_string();
        assert!(err("scene = \"s\"\n").contains("nothing varies"));
        assert!(
            err("scene = \"s\"\n[[vary]]\nparameter = \"friction\"\nvalues = [-0.1]\n")
                .contains("vary[0] (friction): -0.1 is negative")
        );
        assert!(
            err("scene = \"s\"\n[[vary]]\nparameter = \"friction\"\nrange = \"1:2\"\n")
                .contains("a.toml: vary[0].range")
        );
        assert!(err("scene = \"s\"\n[[vary]]\nparameter = \"friction\"\n").contains("give either"));
        assert!(err("scene = \"s\"\n[[vary]]\nparameter = \"friction\"\nvalues = [1]\n[[vary]]\nparameter = \"friction\"\nvalues = [2]\n").contains("varies what a.toml: vary[0] (friction)"));
        assert!(err("scene = \"s\"\nsurprise = 1\n").contains("unknown field"));
        assert!(
            err("scene = \"s\"\nreport = [\"torque\"]\n[[vary]]\nparameter = \"gap\"\nvalues = [0]\n")
                .contains("`torque` is not a quantity")
        );
        assert!(
            err("scene = \"s\"\n[design]\nkind = \"sample\"\n[[vary]]\nparameter = \"gap\"\nvalues = [0, 1]\n")
                .contains("design.count")
        );
    }

    #[test]
    fn vary_arguments_make_a_grid_study() {
        let s = Study::from_vary(Path::new("x/shrink-fit.toml"), &["friction=0.1:0.3:5".into()], None).unwrap();
        assert_eq!(s.name, "shrink-fit-sweep");
        assert_eq!(s.parameters[0].values.len(), 5);
        let e = Study::from_vary(Path::new("x.toml"), &["friction 0.1".into()], None).unwrap_err();
        assert_eq!(e.place, "--vary friction 0.1");
    }
}
