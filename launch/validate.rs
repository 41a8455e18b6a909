//! The validation set (`glissade validate`, docs/accuracy.md#the-validation-set): scenes no one
//! tuned for, generated from seeds, split by seed into a calibration part (even seeds: the only
//! scenes a default, an estimate or a rule may be tuned on) and a held-out part (odd seeds: the
//! scenes they are reported on). Each scene is a laminate of blocks (2–8 plies, stiffness contrast
//! 1–1000, f from 0 to 1, closed, open or interfering plies, loads that ramp, hold, reverse or
//! return to zero, pressure on or off, plane strain or stress, N from 10 to 1000) or a variant of
//! a shipped Gmsh geometry (the wedge in its V-groove, the shrink fit of two rings, the
//! three-layer sheath) with its own friction, loads, plane and N.

use crate::accuracy::{check_scene_against, check_statuses, AccuracyCheck, StatusCheck, MARGIN_FACTORS};
use glissade_reference::ReferenceOptions;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// Which part of the set a seed belongs to: fixed by the seed alone, before any tuning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Part {
    Calibration,
    HeldOut,
}

impl Part {
    pub fn of(seed: u64) -> Self {
        if seed.is_multiple_of(2) {
            Part::Calibration
        } else {
            Part::HeldOut
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Part::Calibration => "calibration",
            Part::HeldOut => "held-out",
        }
    }
}

/// The Gmsh meshes the geometry variants use, written beside the generated scenes.
pub const MESHES: [(&str, &str); 3] = [
    ("wedge.msh", include_str!("scenes/meshes/wedge.msh")),
    ("shrink-fit-1.msh", include_str!("scenes/meshes/shrink-fit-1.msh")),
    ("sheath.msh", include_str!("scenes/meshes/sheath.msh")),
];

/// One generated scene: its scene file's text, the meshes it reads (file names of [`MESHES`]),
/// and what was drawn, in words.
#[derive(Debug, Clone, PartialEq)]
pub struct Generated {
    pub seed: u64,
    pub name: String,
    pub family: &'static str,
    pub toml: String,
    pub meshes: Vec<&'static str>,
    pub drawn: String,
}

/// SplitMix64: a small, well-mixed generator, so that a seed's scene is the same everywhere.
struct Draw(glissade_studies::variants::SplitMix64);

impl Draw {
    fn next(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        self.0.unit()
    }

    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Log-uniform in [lo, hi].
    fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.unit()).exp()
    }

    /// Integer uniform in lo..=hi.
    fn int(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next() % (hi - lo + 1) as u64) as usize
    }

    fn pick<'a, T>(&mut self, of: &'a [T]) -> &'a T {
        &of[self.int(0, of.len() - 1)]
    }

    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
}

/// A load's history over t in [0, 1], scaled by an amplitude: (name, times, values).
const HISTORIES: [History; 4] = [
    ("ramp", &[0.0, 1.0], &[0.0, 1.0]),
    ("ramp-hold", &[0.0, 0.5, 1.0], &[0.0, 1.0, 1.0]),
    ("ramp-reverse", &[0.0, 0.4, 1.0], &[0.0, 1.0, -1.0]),
    ("ramp-unload", &[0.0, 0.4, 0.6, 1.0], &[0.0, 1.0, 1.0, 0.0]),
];

fn history(t: &[f64], v: &[f64], amplitude: f64) -> String {
    let list = |xs: &[f64], scale: f64| {
        xs.iter()
            .map(|x| format!("{:.6}", x * scale))
            .collect::<Vec<_>>()
            .join(", ")
    };
    format!("{{ t = [{}], v = [{}] }}", list(t, 1.0), list(v, amplitude))
}

/// N from 10 to 1000, log-uniform.
fn steps(d: &mut Draw) -> usize {
    d.log_uniform(10.0, 1000.0).round() as usize
}

/// The scene of `seed`.
pub fn generate(seed: u64) -> Generated {
    let mut d = Draw(glissade_studies::variants::SplitMix64(seed ^ 0x6C61_7469_6E5F_7631));
    if d.chance(0.75) {
        laminate(seed, &mut d)
    } else {
        geometry(seed, &mut d)
    }
}

fn laminate(seed: u64, d: &mut Draw) -> Generated {
    let plies = d.int(2, 8);
    let thickness = d.uniform(1.0, 5.0);
    let length = d.uniform(20.0, 120.0);
    let split = d.int(1, 4);
    let nx = split * d.int(2, 4);
    let contrast = d.log_uniform(1.0, 1000.0);
    let nu = *d.pick(&[0.3, 0.33, 0.45]);
    let friction = if d.chance(0.1) { 0.0 } else { d.uniform(0.0, 1.0) };
    let plane = *d.pick(&["strain", "stress"]);
    let n = steps(d);
    let (hname, ht, hv) = *d.pick(&HISTORIES);
    let shear = d.log_uniform(1.0, 30.0);
    let pressure = d.chance(0.5).then(|| d.log_uniform(1.0, 100.0));
    let tension = d.chance(0.3).then(|| d.log_uniform(1.0, 30.0));
    let mut gaps = Vec::new();
    for _ in 1..plies {
        let u = d.unit();
        gaps.push(if u < 0.6 {
            0.0
        } else if u < 0.8 {
            d.log_uniform(1e-4, 1e-2)
        } else {
            -d.log_uniform(1e-4, 1e-3)
        });
    }
    let name = format!("validation-{seed:04}");
    let mut s = String::new();
    let _ = writeln!(s, "# Generated by `glissade validate` from seed {seed} (laminate).");
    let _ = writeln!(s, "name = \"{name}\"\nplane = \"{plane}\"\n");
    let _ = writeln!(s, "[time]\nT = 1.0\nN = {n}\n");
    let _ = writeln!(s, "[materials.stiff]\nE = 210000.0\nnu = {nu}\n");
    let _ = writeln!(s, "[materials.soft]\nE = {:.6}\nnu = {nu}\n", 210000.0 / contrast);
    for p in 0..plies {
        let material = if p % 2 == 0 { "stiff" } else { "soft" };
        let _ = writeln!(
            s,
            "[[block]]\nname = \"ply{p}\"\nmaterial = \"{material}\"\nx = [0.0, {length:.6}]\ny = [{:.6}, {:.6}]\nnx = {nx}\nny = 2\nsplit = [{split}, 1]\n",
            p as f64 * thickness,
            (p + 1) as f64 * thickness
        );
    }
    for (p, g) in gaps.iter().enumerate() {
        let _ = writeln!(
            s,
            "[[interface]]\nbetween = [\"ply{p}\", \"ply{}\"]\nkind = \"contact\"\nfriction = {friction:.6}\ngap = {g:.6e}\n",
            p + 1
        );
    }
    let _ = writeln!(s, "[[boundary]]\nx = 0.0\nux = 0.0\nuy = 0.0\n");
    let _ = writeln!(s, "[[boundary]]\nx = {length:.6}\nty = {}\n", history(ht, hv, -shear));
    if let Some(t) = tension {
        let _ = writeln!(
            s,
            "[[boundary]]\nx = {length:.6}\nblocks = [\"ply0\"]\ntx = {}\n",
            history(ht, hv, t)
        );
    }
    if let Some(p) = pressure {
        let top = plies as f64 * thickness;
        let _ = writeln!(s, "[[boundary]]\ny = 0.0\np = {p:.6}\n");
        let _ = writeln!(s, "[[boundary]]\ny = {top:.6}\np = {p:.6}\n");
    }
    let drawn = format!(
        "laminate: {plies} plies of {length:.0} × {thickness:.1} mm ({split} subdomains, {nx} × 2 QUA8 each), contrast {contrast:.0}, ν {nu}, f {friction:.2}, gaps [{}] mm, shear {shear:.1} MPa {hname}{}{}, plane {plane}, N {n}",
        gaps.iter().map(|g| format!("{g:.1e}")).collect::<Vec<_>>().join(", "),
        tension.map_or(String::new(), |t| format!(", tension {t:.1} MPa on ply0")),
        pressure.map_or(", no pressure".to_string(), |p| format!(", pressure {p:.1} MPa")),
    );
    Generated {
        seed,
        name,
        family: "laminate",
        toml: s,
        meshes: Vec::new(),
        drawn,
    }
}

fn geometry(seed: u64, d: &mut Draw) -> Generated {
    let friction = if d.chance(0.1) { 0.0 } else { d.uniform(0.0, 1.0) };
    let plane = *d.pick(&["strain", "stress"]);
    let n = d.log_uniform(10.0, 200.0).round() as usize;
    let (hname, ht, hv) = *d.pick(&HISTORIES);
    let name = format!("validation-{seed:04}");
    let mut s = String::new();
    let which = d.int(0, 2);
    let _ = writeln!(
        s,
        "# Generated by `glissade validate` from seed {seed} (Gmsh geometry)."
    );
    let _ = writeln!(s, "name = \"{name}\"\nplane = \"{plane}\"\n");
    let _ = writeln!(s, "[time]\nT = 1.0\nN = {n}\n");
    let h = (hname, ht, hv);
    let (family, mesh, drawn) = match which {
        0 => wedge(&mut s, d, friction, h),
        1 => shrink_fit(&mut s, d, friction, h),
        _ => sheath(&mut s, d, friction, h),
    };
    Generated {
        seed,
        name,
        family,
        toml: s,
        meshes: vec![mesh],
        drawn: format!("{drawn}, f {friction:.2}, plane {plane}, N {n}"),
    }
}

/// A load history of [`HISTORIES`]: its name, times and values.
type History = (&'static str, &'static [f64], &'static [f64]);

/// The wedge in its V-groove: a pressure rising with t, a lean following the history. Writes its part of the scene into `s`; returns (family, mesh, what was drawn).
fn wedge(s: &mut String, d: &mut Draw, friction: f64, h: History) -> (&'static str, &'static str, String) {
    let (hname, ht, hv) = h;
    let p = d.log_uniform(5.0, 100.0);
    let lean = d.uniform(0.0, 2.0);
    let _ = writeln!(s, "[materials.steel]\nE = 210000.0\nnu = 0.3\n");
    let _ = writeln!(
        s,
        "[mesh]\nfile = \"wedge.msh\"\nmaterials = {{ base = \"steel\", wedge = \"steel\" }}\n"
    );
    let _ = writeln!(
        s,
        "[[interface]]\nbetween = [\"base\", \"wedge\"]\nkind = \"contact\"\nfriction = {friction:.6}\n"
    );
    let _ = writeln!(s, "[[boundary]]\ncurve = \"base-bottom\"\nux = 0.0\nuy = 0.0\n");
    // The pressure rises with t (it must hold the wedge in the groove at every time
    // point); the lean follows the drawn history.
    let _ = writeln!(s, "[[boundary]]\ncurve = \"wedge-top\"\np = \"{p:.6}*(0.2 + 0.8*t)\"\n");
    let _ = writeln!(
        s,
        "[[boundary]]\ncurve = \"wedge-top\"\ntx = {}\n",
        history(ht, hv, lean * 0.1 * p)
    );
    (
        "wedge",
        "wedge.msh",
        format!("wedge: pressure {p:.1} MPa rising, lean {lean:.2} {hname}"),
    )
}

/// The shrink fit of two rings: an interference and a shear on the outside following the history. Writes its part of the scene into `s`; returns (family, mesh, what was drawn).
fn shrink_fit(s: &mut String, d: &mut Draw, friction: f64, h: History) -> (&'static str, &'static str, String) {
    let (hname, ht, hv) = h;
    let interference = d.log_uniform(2e-3, 2e-2);
    let shear = d.log_uniform(0.2, 5.0);
    let _ = writeln!(s, "[materials.steel]\nE = 210000.0\nnu = 0.3\n");
    let _ = writeln!(
        s,
        "[mesh]\nfile = \"shrink-fit-1.msh\"\nmaterials = {{ inner = \"steel\", outer = \"steel\" }}\n"
    );
    let _ = writeln!(
        s,
        "[[interface]]\ncurve = \"fit\"\nkind = \"contact\"\nfriction = {friction:.6}\ngap = {:.6e}\n",
        -interference
    );
    let _ = writeln!(s, "[[boundary]]\ncurve = \"bore\"\nux = 0.0\nuy = 0.0\n");
    let _ = writeln!(
        s,
        "[[boundary]]\ncurve = \"outside\"\nshear = {}\n",
        history(ht, hv, shear)
    );
    (
        "shrink-fit",
        "shrink-fit-1.msh",
        format!("shrink fit: interference {interference:.1e} mm, shear {shear:.2} MPa {hname}"),
    )
}

/// The three-layer sheath: an outer layer softer by a drawn contrast, a pressure rising with t and a shear following the history. Writes its part of the scene into `s`; returns (family, mesh, what was drawn).
fn sheath(s: &mut String, d: &mut Draw, friction: f64, h: History) -> (&'static str, &'static str, String) {
    let (hname, ht, hv) = h;
    let p = d.log_uniform(2.0, 50.0);
    let shear = d.log_uniform(0.1, 3.0);
    let contrast = d.log_uniform(1.0, 100.0);
    let _ = writeln!(s, "[materials.aluminium]\nE = 70000.0\nnu = 0.33\n");
    let _ = writeln!(s, "[materials.steel]\nE = 210000.0\nnu = 0.3\n");
    let _ = writeln!(s, "[materials.polymer]\nE = {:.6}\nnu = 0.4\n", 70000.0 / contrast);
    let _ = writeln!(s, "[mesh]\nfile = \"sheath.msh\"\nmaterials = {{ inner = \"aluminium\", middle = \"steel\", outer = \"polymer\" }}\n");
    for curve in ["inner-middle", "middle-outer"] {
        let _ = writeln!(
            s,
            "[[interface]]\ncurve = \"{curve}\"\nkind = \"contact\"\nfriction = {friction:.6}\n"
        );
    }
    let _ = writeln!(s, "[[boundary]]\ncurve = \"bore\"\nux = 0.0\nuy = 0.0\n");
    let _ = writeln!(s, "[[boundary]]\ncurve = \"outside\"\np = \"{p:.6}*(0.2 + 0.8*t)\"\n");
    let _ = writeln!(
        s,
        "[[boundary]]\ncurve = \"outside\"\nshear = {}\n",
        history(ht, hv, shear)
    );
    (
        "sheath",
        "sheath.msh",
        format!("sheath: outer modulus 70000/{contrast:.0}, pressure {p:.1} MPa rising, shear {shear:.2} MPa {hname}"),
    )
}

/// One scene's validation: its check (where each accuracy stops and the true error there), or
/// why it could not be checked; and the wall time of the reference and LATIN together.
#[derive(Debug, Clone, Serialize)]
pub struct Validated {
    pub seed: u64,
    pub part: Part,
    pub family: &'static str,
    pub drawn: String,
    pub check: Result<AccuracyCheck, String>,
    /// The reported statuses of a run at accuracy [`STATUS_ACCURACY`] against the reference's, or
    /// why that run could not be made (None: the accuracy check itself failed).
    pub statuses: Option<Result<StatusCheck, String>>,
    pub seconds: f64,
}

/// The accuracy at which the statuses are compared with the reference's.
pub const STATUS_ACCURACY: f64 = 1e-3;

/// Writes the scene of `seed` and its meshes into `dir` (created) and checks it: the reference,
/// then one LATIN run past the smallest accuracy ([`check_scene`]).
pub fn validate_seed(seed: u64, dir: &Path, reference: &ReferenceOptions) -> crate::Result<Validated> {
    let g = generate(seed);
    let io = |what: String| move |source| crate::Error::Io { what, source };
    std::fs::create_dir_all(dir).map_err(io(format!("cannot create {}", dir.display())))?;
    for m in &g.meshes {
        let (_, text) = MESHES.iter().find(|(n, _)| n == m).expect("a mesh of MESHES");
        let path = dir.join(m);
        if !path.exists() {
            std::fs::write(&path, text).map_err(io(format!("cannot write {}", path.display())))?;
        }
    }
    let path = dir.join(format!("{}.toml", g.name));
    std::fs::write(&path, &g.toml).map_err(io(format!("cannot write {}", path.display())))?;
    let t0 = std::time::Instant::now();
    let mut statuses = None;
    let check = crate::load_scene(&path)
        .and_then(|sc| {
            // A reference that fails is an error here: the check needs every time point.
            let t_reference = std::time::Instant::now();
            let solution = glissade_reference::solve_reference(&sc.model, reference)?;
            let reference_s = t_reference.elapsed().as_secs_f64();
            let check = check_scene_against(&g.name, &sc, solution.clone(), reference_s)?;
            // A status check that cannot be made does not undo the accuracy check: it is said.
            statuses = Some(check_statuses(&sc, &solution, STATUS_ACCURACY).map_err(|e| crate::error::chain(&e)));
            Ok(check)
        })
        .map_err(|e| crate::error::chain(&e));
    Ok(Validated {
        seed,
        part: Part::of(seed),
        family: g.family,
        drawn: g.drawn,
        check,
        statuses,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// What one accuracy's stop is on one scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Stopped with a true error within the accuracy.
    Within,
    /// Stopped with a true error above the accuracy, at most twice it.
    Within2x,
    /// Stopped with a true error more than twice the accuracy.
    Beyond,
    /// Never stopped ("NOT converged"), though the true error went below the accuracy.
    FalseNotConverged,
    /// Never stopped, and the true error never went below the accuracy either.
    NotConverged,
    /// A stop whose true error is undefined (no contact force in the reference).
    Undefined,
}

/// The outcome of accuracy stop `st`.
pub fn outcome(st: &crate::accuracy::AccuracyStop) -> Outcome {
    match (st.iteration, st.true_error) {
        (Some(_), None) => Outcome::Undefined,
        (Some(_), Some(e)) if e <= st.accuracy => Outcome::Within,
        (Some(_), Some(e)) if e <= 2.0 * st.accuracy => Outcome::Within2x,
        (Some(_), Some(_)) => Outcome::Beyond,
        (None, _) if st.first_reached.is_some() => Outcome::FalseNotConverged,
        (None, _) => Outcome::NotConverged,
    }
}

/// The validation as a markdown table (one row per scene and accuracy) and its summary per
/// accuracy.
pub fn markdown(results: &[Validated]) -> String {
    let mut s = String::from(
        "| seed | part | scene | accuracy | stop iteration | true error at the stop | true / accuracy | first iteration with true error ≤ accuracy | seconds (reference and runs) |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    let opt = |v: Option<u32>| v.map_or("—".to_string(), |v| v.to_string());
    for v in results {
        match &v.check {
            Ok(c) => {
                for st in &c.stops {
                    let _ = writeln!(
                        s,
                        "| {} | {} | {} | {:.0e} | {} | {} | {} | {} | {:.1} |",
                        v.seed,
                        v.part.name(),
                        v.drawn,
                        st.accuracy,
                        opt(st.iteration),
                        match outcome(st) {
                            Outcome::Undefined => "undefined (no contact force in the reference)".to_string(),
                            _ => st.true_error.map_or("—".into(), |e| format!("{e:.2e}")),
                        },
                        st.ratio().map_or("—".into(), |r| format!("{r:.2}")),
                        opt(st.first_reached),
                        v.seconds,
                    );
                }
            }
            Err(e) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | — | not checked: {} | | | | {:.1} |",
                    v.seed,
                    v.part.name(),
                    v.drawn,
                    e.replace('|', "/").replace('\n', " "),
                    v.seconds
                );
            }
        }
    }
    s.push('\n');
    s += &summary(results);
    s
}

/// Per accuracy: of the scenes checked, the share whose stop is within the accuracy, within 2×,
/// the worst ratio, the false "NOT converged"; and the scenes that could not be checked.
pub fn summary(results: &[Validated]) -> String {
    let mut s = String::new();
    let checked: Vec<&AccuracyCheck> = results.iter().filter_map(|v| v.check.as_ref().ok()).collect();
    let failed = results.len() - checked.len();
    for a in crate::accuracy::ACCURACIES {
        let stops: Vec<&crate::accuracy::AccuracyStop> = checked
            .iter()
            .filter_map(|c| c.stops.iter().find(|st| st.accuracy == a))
            .collect();
        let count = |o: Outcome| stops.iter().filter(|st| outcome(st) == o).count();
        let (within, within2, beyond) = (count(Outcome::Within), count(Outcome::Within2x), count(Outcome::Beyond));
        let stopped = within + within2 + beyond;
        let worst = stops
            .iter()
            .filter_map(|st| st.iteration.and(st.ratio()))
            .fold(0.0, f64::max);
        let pct = |n: usize, of: usize| if of == 0 { 0.0 } else { 100.0 * n as f64 / of as f64 };
        let _ = writeln!(
            s,
            "- accuracy {a:.0e}: {stopped} of {} scenes stopped \"Converged\"; true error ≤ accuracy in {within} ({:.0} %), \
             ≤ 2× in {} ({:.0} %), worst {worst:.2}×; \"NOT converged\" with a true error that went below the accuracy: {} \
             ({:.0} %); \"NOT converged\" and never below it: {}; undefined (no contact force): {}",
            stops.len(),
            pct(within, stopped),
            within + within2,
            pct(within + within2, stopped),
            count(Outcome::FalseNotConverged),
            pct(count(Outcome::FalseNotConverged), stops.len()),
            count(Outcome::NotConverged),
            count(Outcome::Undefined),
        );
    }
    let _ = writeln!(
        s,
        "- not checked (the reference or the run failed): {failed} of {}",
        results.len()
    );
    // A scene the reference solved has an equilibrium at every time point: a run of it stopped
    // on no equilibrium is a false diagnosis.
    let no_equilibrium: Vec<u64> = results
        .iter()
        .filter(|v| v.check.as_ref().is_ok_and(|c| c.verdict.starts_with("NoEquilibrium")))
        .map(|v| v.seed)
        .collect();
    let _ = writeln!(
        s,
        "- runs stopped on no equilibrium though the reference solved every time point: {} {no_equilibrium:?}",
        no_equilibrium.len()
    );
    s += &status_summary(results);
    s
}

/// Per margin factor, over the runs at [`STATUS_ACCURACY`] that converged: the share of the
/// pair-time points decided in both (outside the margins) whose statuses agree with the
/// reference's, the scenes below 99 % of agreement, and the share of pair-time points within a
/// margin (limit or grazing in either).
pub fn status_summary(results: &[Validated]) -> String {
    let mut s = String::new();
    let checks: Vec<(u64, &StatusCheck)> = results
        .iter()
        .filter_map(|v| match &v.statuses {
            Some(Ok(c)) if c.converged => Some((v.seed, c)),
            _ => None,
        })
        .collect();
    let failed: Vec<String> = results
        .iter()
        .filter_map(|v| match &v.statuses {
            Some(Err(e)) => Some(format!("{}: {e}", v.seed)),
            _ => None,
        })
        .collect();
    if !failed.is_empty() {
        let _ = writeln!(
            s,
            "- statuses not compared (the run at 1e-3 or the comparison failed): {}",
            failed.join("; ")
        );
    }
    for (j, factor) in MARGIN_FACTORS.iter().enumerate() {
        let (mut agree, mut decided, mut within, mut below) = (0usize, 0usize, 0usize, Vec::new());
        for (seed, c) in &checks {
            let Some((_, a)) = c.agreement.get(j) else {
                continue;
            };
            agree += a.agree;
            decided += a.agree + a.disagree;
            within += a.within_margin;
            if a.share() < 0.99 {
                below.push(format!("{seed} ({:.1} %)", 100.0 * a.share()));
            }
        }
        let pct = |n: usize, of: usize| if of == 0 { 100.0 } else { 100.0 * n as f64 / of as f64 };
        let _ = writeln!(
            s,
            "- statuses at accuracy {STATUS_ACCURACY:.0e}, margin factor {factor}: over {} converged runs, {:.2} % of the \
             {decided} pair-time points decided in both agree with the reference; {:.1} % of all are within a margin \
             (limit or grazing); scenes below 99 %: {}",
            checks.len(),
            pct(agree, decided),
            pct(within, decided + within),
            if below.is_empty() { "none".to_string() } else { below.join(", ") },
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first 120 seeds: every scene loads (the scene checks pass: rigid modes blocked,
    /// selections that select, meshes found), both parts hold half of them, every family is
    /// drawn, and the laminates spread over the ranges the set promises.
    #[test]
    fn every_seed_makes_a_scene_that_loads() {
        let dir = std::env::temp_dir().join(format!("glissade-validate-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (m, text) in MESHES {
            std::fs::write(dir.join(m), text).unwrap();
        }
        let (mut held_out, mut families) = (0, std::collections::BTreeSet::new());
        let (mut plies, mut steps) = (std::collections::BTreeSet::new(), Vec::new());
        for seed in 0..120 {
            let g = generate(seed);
            assert_eq!(g, generate(seed), "seed {seed}: the same scene every time");
            let path = dir.join(format!("{}.toml", g.name));
            std::fs::write(&path, &g.toml).unwrap();
            let sc = crate::load_scene(&path).unwrap_or_else(|e| panic!("seed {seed}: {e}\n{}", g.toml));
            held_out += usize::from(Part::of(seed) == Part::HeldOut);
            families.insert(g.family);
            steps.push(sc.model.time.n_points() - 1);
            if g.family == "laminate" {
                plies.insert(g.toml.matches("[[block]]").count());
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(held_out, 60);
        assert_eq!(families.len(), 4, "{families:?}");
        assert!(plies.contains(&2) && plies.contains(&8), "{plies:?}");
        assert!(
            steps.iter().any(|&n| n < 20) && steps.iter().any(|&n| n > 500),
            "{steps:?}"
        );
    }
}
