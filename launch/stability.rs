//! The stability matrix (`glissade stability`, issue 8): a set of stiff and extreme cases, each
//! built from a small base scene text varied by the case, run in-process with the LATIN solver
//! and, where it can be computed, compared with the monolithic Newton reference
//! ([`solve_reference`]) of the same discrete problem. Every case states what it expects:
//! convergence within a tolerance on η and on the contact traction error against the
//! reference, or a stop with a named diagnosis (max iterations, stagnation, divergence, a scene
//! rejected at validation).
//!
//! Every case runs with η ≤ [`ETA_TOLERANCE`] (unless it states another) and at
//! most [`MAX_ITERATIONS`] iterations; errors against the reference are those of LATIN's s
//! ([`error_against_reference`]: relative space-time norms on contact interfaces). Panics are
//! caught per case and reported as such; non-finite values are flagged per case.
//!
//! Every case runs twice, as stated (plain relaxation) and with Anderson acceleration
//! ([`Case::accelerated`]), against one reference: the row says what acceleration did to the
//! outcome ([`AccelerationEffect`]) and how many Anderson steps were mixed, safeguarded and
//! restarted ([`AndersonTally`]).
//!
//! `glissade stability` runs the whole matrix (most of its time goes to steps-10000 and the thin
//! layers); `--quick` leaves out the [`SLOW`] cases and is what `tests/it/stability.rs` runs.

use crate::runner::{run_in_process_observed, AndersonTally, RunOptions};
use glissade_mechanics::local::{error_against_reference, InterfaceFields};
use glissade_mechanics::model::Model;
use glissade_messages::Verdict;
use glissade_reference::{solve_reference, ReferenceOptions};
use glissade_scene::{load_str, LoadedScene};
use serde::Serialize;
use std::fmt::Write as _;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

/// One layer of the base scene: a block spanning the whole length.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    pub name: &'static str,
    /// Young modulus (MPa).
    pub e: f64,
    pub nu: f64,
    /// Thickness (mm).
    pub h: f64,
    /// Elements across the thickness.
    pub ny: usize,
}

/// The base scene of the matrix and its variations: layers stacked from y = 0 over a length
/// `length`, contact between neighbouring layers, boundary rules and solver settings as TOML.
#[derive(Debug, Clone, PartialEq)]
pub struct Base {
    pub name: String,
    pub plane: &'static str,
    pub length: f64,
    /// Elements along x per layer.
    pub nx: usize,
    /// Subdomains along x per layer (divides `nx`).
    pub split: usize,
    pub layers: Vec<Layer>,
    pub friction: f64,
    /// Initial gap of every contact interface (formula in x, y), if any.
    pub gap: Option<String>,
    /// `[[boundary]]` rules, as TOML text.
    pub boundary: String,
    pub t_end: f64,
    pub n_steps: usize,
    /// `[solver]` lines (`key = value`).
    pub solver: Vec<String>,
}

/// End loads of the small three-layer scene (`launch/scenes/small-three-layer.toml`): the end
/// tension resultant on the core and the shear resultant over the whole end (N).
const TENSION: f64 = 6000.0 * 40.0 / 180.0;
const SHEAR: f64 = 1500.0 * 40.0 / 180.0;

impl Base {
    /// The small three-layer scene (launch/scenes/small-three-layer.toml): three 40 × 10 mm
    /// layers of 8 × 2 QUA8, two subdomains per layer, Coulomb contact f = 0.3 between layers,
    /// clamped at x = 0, pressure 100 MPa on top and bottom, end tension on the core, end shear;
    /// T = 1 s, N = 10; η ≤ [`ETA_TOLERANCE`], at most [`MAX_ITERATIONS`] iterations.
    pub fn three_layers() -> Self {
        let layer = |name| Layer {
            name,
            e: 130_000.0,
            nu: 0.2,
            h: 10.0,
            ny: 2,
        };
        let mut b = Self {
            name: "base".into(),
            plane: "strain",
            length: 40.0,
            nx: 8,
            split: 2,
            layers: vec![layer("bottom"), layer("core"), layer("top")],
            friction: 0.3,
            gap: None,
            boundary: String::new(),
            t_end: 1.0,
            n_steps: 10,
            solver: vec![
                format!("tolerance = {ETA_TOLERANCE:e}"),
                format!("max_iterations = {MAX_ITERATIONS}"),
            ],
        };
        b.set_loads(100.0, TENSION, SHEAR, "sin(2*pi*t)", "sin(4*pi*t)");
        b
    }

    /// Boundary rules of the three-layer scene: clamp at x = 0, pressure `p` (MPa) on top and
    /// bottom, end tension of resultant `tension` (N) on the core times `tension_t(t)`, end shear
    /// of resultant `shear` (N) over the whole end times `shear_t(t)`.
    pub fn set_loads(&mut self, p: f64, tension: f64, shear: f64, tension_t: &str, shear_t: &str) {
        let height: f64 = self.layers.iter().map(|l| l.h).sum();
        let core = &self.layers[self.layers.len() / 2];
        let mut s = String::from("[[boundary]]\nx = 0.0\nux = 0.0\nuy = 0.0\n\n");
        if p != 0.0 {
            let _ = write!(
                s,
                "[[boundary]]\ny = 0.0\np = {p:e}\n\n[[boundary]]\ny = {height:?}\np = {p:e}\n\n"
            );
        }
        if tension != 0.0 {
            let _ = write!(
                s,
                "[[boundary]]\nblocks = [\"{}\"]\nx = {:?}\ntx = \"{:e}*{tension_t}\"\n\n",
                core.name,
                self.length,
                tension / core.h
            );
        }
        if shear != 0.0 {
            let _ = write!(
                s,
                "[[boundary]]\nx = {:?}\nty = \"{:e}*{shear_t}\"\n\n",
                self.length,
                shear / height
            );
        }
        self.boundary = s;
    }

    /// Sets (or adds) one `[solver]` line.
    pub fn solver_set(&mut self, key: &str, value: &str) {
        self.solver.retain(|l| l.split('=').next().map(str::trim) != Some(key));
        self.solver.push(format!("{key} = {value}"));
    }

    /// The scene text.
    pub fn to_toml(&self) -> String {
        let mut s = format!(
            "name = \"{}\"\nplane = \"{}\"\n\n[time]\nT = {:?}\nN = {}\n\n",
            // A scene name is a file name: the case's `thin-layers-1:100` becomes `thin-layers-1-100`.
            self.name.replace(':', "-"),
            self.plane,
            self.t_end,
            self.n_steps
        );
        for l in &self.layers {
            let _ = write!(s, "[materials.{}]\nE = {:e}\nnu = {:?}\n\n", l.name, l.e, l.nu);
        }
        let mut y = 0.0;
        for l in &self.layers {
            let _ = write!(
                s,
                "[[block]]\nname = \"{0}\"\nmaterial = \"{0}\"\nx = [0.0, {1:?}]\ny = [{2:?}, {3:?}]\nnx = {4}\nny = {5}\nsplit = [{6}, 1]\n\n",
                l.name,
                self.length,
                y,
                y + l.h,
                self.nx,
                l.ny,
                self.split
            );
            y += l.h;
        }
        for w in self.layers.windows(2) {
            let _ = write!(
                s,
                "[[interface]]\nbetween = [\"{}\", \"{}\"]\nkind = \"contact\"\nfriction = {:?}\n",
                w[0].name, w[1].name, self.friction
            );
            if let Some(g) = &self.gap {
                let _ = writeln!(s, "gap = \"{g}\"");
            }
            s.push('\n');
        }
        s += &self.boundary;
        s += "[solver]\n";
        for l in &self.solver {
            s += l;
            s.push('\n');
        }
        s
    }
}

/// What a case expects.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Expect {
    /// Converges (η ≤ the scene's tolerance) and, where a reference exists, the contact traction
    /// error of s against it is ≤ `error` (the jump error where the reference's contact
    /// tractions are all zero, so that a relative traction error is undefined).
    Converge { error: f64 },
    /// Stops without converging with this outcome ([`Outcome::kind`]: `max_iterations`,
    /// `stagnated`, `diverged`), for the reason given.
    Stop { outcome: &'static str, why: &'static str },
    /// The scene is rejected at validation with a reason containing `reason`.
    Rejected { reason: &'static str },
}

/// One case of the matrix.
#[derive(Debug, Clone)]
pub struct Case {
    pub name: &'static str,
    /// What the case varies with respect to the base.
    pub varies: String,
    pub scene: String,
    /// The same scene with Anderson acceleration on (`acceleration = "anderson"` in its `[solver]`,
    /// the default window).
    pub accelerated: String,
    pub expect: Expect,
    /// Options of the monolithic reference; `None`: not computed.
    pub reference: Option<ReferenceOptions>,
    /// Part of the `--quick` subset.
    pub quick: bool,
}

/// Outcome of a case.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Outcome {
    Converged,
    MaxIterations,
    Stagnated {
        detail: String,
    },
    Diverged {
        detail: String,
    },
    Rejected {
        reason: String,
    },
    /// The run could not be built or failed (not a LATIN verdict).
    Error {
        detail: String,
    },
    /// The case panicked (a bug).
    Panicked {
        detail: String,
    },
}

impl Outcome {
    /// Short name of the outcome.
    pub fn kind(&self) -> &'static str {
        match self {
            Outcome::Converged => "converged",
            Outcome::MaxIterations => "max_iterations",
            Outcome::Stagnated { .. } => "stagnated",
            Outcome::Diverged { .. } => "diverged",
            Outcome::Rejected { .. } => "rejected",
            Outcome::Error { .. } => "error",
            Outcome::Panicked { .. } => "panicked",
        }
    }

    /// The detail of a stop ("" for converged and max iterations).
    pub fn detail(&self) -> &str {
        match self {
            Outcome::Converged | Outcome::MaxIterations => "",
            Outcome::Stagnated { detail }
            | Outcome::Diverged { detail }
            | Outcome::Error { detail }
            | Outcome::Panicked { detail } => detail,
            Outcome::Rejected { reason } => reason,
        }
    }

    fn text(&self) -> String {
        match self {
            Outcome::Converged => "converged".into(),
            Outcome::MaxIterations => "stopped: max iterations".into(),
            Outcome::Stagnated { detail } => format!("stopped: stagnation ({detail})"),
            Outcome::Diverged { detail } => format!("stopped: divergence ({detail})"),
            Outcome::Rejected { reason } => format!("rejected at validation: {reason}"),
            Outcome::Error { detail } => format!("error: {detail}"),
            Outcome::Panicked { detail } => format!("PANIC: {detail}"),
        }
    }
}

/// How a case's outcome compares with what it expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Assessment {
    /// Converged within the stated tolerances, or stopped or rejected as expected.
    AsExpected,
    Unexpected,
}

/// One LATIN run of a case (plain or accelerated).
#[derive(Debug, Clone, Serialize)]
pub struct RunRow {
    pub iterations: Option<usize>,
    pub eta: Option<f64>,
    pub contact_indicator: Option<f64>,
    /// Relative contact traction (e_F) and jump (e_W) errors of LATIN's s against the reference
    /// ([`error_against_reference`]); the traction error is `None` where the reference's contact
    /// tractions are all zero.
    pub traction_error: Option<f64>,
    pub jump_error: Option<f64>,
    /// LATIN wall time, operator setup included (s).
    pub latin_s: Option<f64>,
    /// Contact points (separated, stuck, slipping) at the last time point, at the stop.
    pub final_counts: Option<[u64; 3]>,
    /// Iteration of the first search-direction update, if any.
    pub first_direction_update: Option<u32>,
    /// The Anderson steps of an accelerated run (`None` for the plain run).
    pub anderson_steps: Option<AndersonTally>,
    pub outcome: Outcome,
    /// Every interface field of the run (and of the reference), and every error and time, is finite.
    pub fields_finite: bool,
    /// Every indicator of every iteration (η, e_c, e_F, e_W) is finite.
    pub indicators_finite: bool,
}

impl RunRow {
    fn new() -> Self {
        Self {
            iterations: None,
            eta: None,
            contact_indicator: None,
            traction_error: None,
            jump_error: None,
            latin_s: None,
            final_counts: None,
            first_direction_update: None,
            anderson_steps: None,
            outcome: Outcome::Converged,
            fields_finite: true,
            indicators_finite: true,
        }
    }

    /// Converged to η ≤ `tolerance` with finite values and, where compared with a reference, a
    /// contact traction error ≤ `error` (the jump error where the reference's contact tractions
    /// are all zero).
    pub fn reaches(&self, tolerance: Option<f64>, error: f64) -> bool {
        self.fields_finite
            && self.indicators_finite
            && self.outcome == Outcome::Converged
            && self.eta.zip(tolerance).is_none_or(|(e, t)| e <= t)
            && self.traction_error.or(self.jump_error).is_none_or(|e| e <= error)
    }
}

/// What Anderson acceleration does to a case's outcome, against the plain run (both judged by
/// [`RunRow::reaches`] with the case's error bound, [`ERROR_TOLERANCE`] for the cases expected to
/// stop).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AccelerationEffect {
    /// The same outcome: both reach the reference, or both stop the same way (or are rejected).
    Kept,
    /// The plain run does not reach the reference, the accelerated one does.
    Improved,
    /// Neither reaches the reference, and they stop differently.
    Changed,
    /// The plain run reaches the reference and the accelerated one does not: what the safeguard
    /// must prevent.
    Broke,
}

impl AccelerationEffect {
    fn of(plain: &RunRow, anderson: &RunRow, tolerance: Option<f64>, error: f64) -> Self {
        match (plain.reaches(tolerance, error), anderson.reaches(tolerance, error)) {
            (true, true) => Self::Kept,
            (true, false) => Self::Broke,
            (false, true) => Self::Improved,
            (false, false) if plain.outcome.kind() == anderson.outcome.kind() => Self::Kept,
            (false, false) => Self::Changed,
        }
    }

    /// Short name.
    pub fn kind(self) -> &'static str {
        match self {
            Self::Kept => "kept",
            Self::Improved => "improved",
            Self::Changed => "changed",
            Self::Broke => "broke",
        }
    }
}

/// The result of one case: a row of the table.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    pub case: String,
    pub varies: String,
    pub expect: Expect,
    /// The scene's η tolerance (when the scene loaded).
    pub tolerance: Option<f64>,
    /// The case's scene as stated, with plain relaxation.
    pub plain: RunRow,
    /// The same scene with Anderson acceleration.
    pub anderson: RunRow,
    pub acceleration: AccelerationEffect,
    /// Why an error is missing.
    pub reference_note: Option<String>,
    pub reference_s: Option<f64>,
    /// Reference Newton iterations, all time steps.
    pub reference_newton: Option<usize>,
    /// The plain run ends as the case expects, the accelerated one neither panics nor leaves a
    /// non-finite value, and acceleration does not break a converging case.
    pub assessment: Assessment,
}

/// Two blocks 40 × 10 mm (8 × 2 QUA8) with initial gap `gap` (formula in x, mm) and the given
/// boundary rules: for the gap cases.
fn two_blocks(gap: &str, boundary: &str) -> Base {
    let mut b = Base::three_layers();
    b.layers.truncate(2);
    b.layers[0].name = "lower";
    b.layers[1].name = "upper";
    b.split = 1;
    b.gap = Some(gap.into());
    b.boundary = boundary.into();
    b
}

/// Three 100 × 1 mm layers (aspect ratio 1:100) of 50 × 1 QUA8, one subdomain each, under the
/// base's pressure and the base's end tension on the core scaled by the length (the same ratio to
/// the friction capacity f·p·L), and an end shear of resultant `shear` (N).
fn thin_layers(shear: f64) -> Base {
    let mut b = Base::three_layers();
    b.length = 100.0;
    b.nx = 50;
    b.split = 1;
    for l in &mut b.layers {
        l.h = 1.0;
        l.ny = 1;
    }
    b.set_loads(100.0, TENSION * 2.5, shear, "sin(2*pi*t)", "sin(4*pi*t)");
    b
}

/// Number of the iterations allowed in every case (each scene's `solver.max_iterations`).
pub const MAX_ITERATIONS: usize = 2000;

/// η tolerance of every case. η underestimates the contact traction error against the reference
/// by one to two orders of magnitude (measured on this matrix: at η ≤ 1e-6 the error reaches
/// 2.7e-4), so the matrix asks η ≤ 1e-7 for an error ≤ 1e-4.
pub const ETA_TOLERANCE: f64 = 1e-7;

/// Bound on the contact traction error against the reference.
pub const ERROR_TOLERANCE: f64 = 1e-4;

/// Cases left out of the `--quick` subset: the slowest (in the debug test profile: steps-10000
/// 40 s, the thin layers 5 and 10 s; everything else together about 10 s).
pub const SLOW: [&str; 4] = [
    "steps-10000",
    "thin-layers-1:100",
    "thin-layers-1:100-bending",
    "thin-layers-1:100-bending-degree-1",
];

fn case(name: &'static str, varies: &str, b: &Base, expect: Expect) -> Case {
    let mut b = b.clone();
    b.name = name.into();
    b.solver_set("acceleration", "\"none\"");
    let scene = b.to_toml();
    b.solver_set("acceleration", "\"anderson\"");
    Case {
        name,
        varies: varies.into(),
        scene,
        accelerated: b.to_toml(),
        expect,
        reference: Some(ReferenceOptions::default()),
        quick: true,
    }
}

/// Why a case with k₀ far off its best value stops at the iteration cap: LATIN's contraction
/// per iteration tends to 1 as k₀ → 0 or ∞.
const FAR_K0: &str = "the LATIN contraction per iteration tends to 1 when k₀ is far from the \
                      interface stiffness: η still decreases at the cap, too slowly for stagnation";

/// The cases of the matrix; with `quick`, the reduced subset of the test suite.
pub fn cases(quick: bool) -> Vec<Case> {
    let conv = Expect::Converge { error: ERROR_TOLERANCE };
    let base = Base::three_layers();
    let mut out = Vec::new();
    out.push(case(
        "base",
        "nothing: three 40 × 10 mm layers, 8 × 2 QUA8 and 2 subdomains each, E = 130 GPa, ν = 0.2, \
         f = 0.3, p = 100 MPa, end tension and shear, N = 10",
        &base,
        conv.clone(),
    ));

    let mut b = base.clone();
    b.layers[1].e *= 1e6;
    out.push(case(
        "stiffness-ratio-1e6",
        "core E × 1e6 (ratio 1e6 across both contact interfaces)",
        &b,
        conv.clone(),
    ));

    let mut b = base.clone();
    b.layers.iter_mut().for_each(|l| l.nu = 0.499);
    // The contraction per iteration is close to 1 here, so η underestimates the error ~3500-fold:
    // at η ≤ 1e-7 the traction error is 3.5e-4, at η ≤ 1e-8 4e-5.
    b.solver_set("tolerance", "1e-8");
    out.push(case("nu-0.499", "ν = 0.499, plane strain (η ≤ 1e-8)", &b, conv.clone()));

    let mut b = base.clone();
    b.layers.iter_mut().for_each(|l| l.nu = 0.5);
    out.push(case(
        "nu-0.5",
        "ν = 0.5 (incompressible: outside the displacement formulation)",
        &b,
        Expect::Rejected {
            reason: "outside (−1, 0.5)",
        },
    ));

    for (name, f) in [("friction-0", 0.0), ("friction-5", 5.0)] {
        let mut b = base.clone();
        b.friction = f;
        out.push(case(name, &format!("f = {f}"), &b, conv.clone()));
    }

    let mut b = base.clone();
    b.set_loads(100.0, 3.0 * TENSION, 0.0, "t", "t");
    out.push(case(
        "all-slip",
        "end tension on the core × 3 (1.7 × the friction capacity 2fpL), ramped, no shear: every \
         contact point slips at t = T, the clamp at x = 0 holds",
        &b,
        conv.clone(),
    ));

    for (name, s) in [("pressure-1e-6", 1e-6), ("pressure-1e6", 1e6)] {
        let mut b = base.clone();
        b.set_loads(100.0 * s, TENSION, SHEAR, "sin(2*pi*t)", "sin(4*pi*t)");
        out.push(case(
            name,
            &format!("pressure × {s:e}, end loads unchanged"),
            &b,
            conv.clone(),
        ));
    }
    let mut b = base.clone();
    b.set_loads(100.0 * 1e6, TENSION * 1e6, SHEAR * 1e6, "sin(2*pi*t)", "sin(4*pi*t)");
    out.push(case("all-loads-1e6", "every load × 1e6", &b, conv.clone()));

    let mut b = base.clone();
    b.set_loads(0.0, 0.0, 0.0, "t", "t");
    out.push(case("zero-load", "no load at all (clamp only)", &b, conv.clone()));

    for (name, k, expect) in [
        (
            "k0-x1e-3",
            1e-3,
            Expect::Stop {
                outcome: "max_iterations",
                why: FAR_K0,
            },
        ),
        ("k0-x0.3", 0.3, conv.clone()),
        ("k0-x3", 3.0, conv.clone()),
        ("k0-x10", 10.0, conv.clone()),
        (
            "k0-x1e3",
            1e3,
            Expect::Stop {
                outcome: "max_iterations",
                why: FAR_K0,
            },
        ),
    ] {
        let mut b = base.clone();
        b.solver_set("k0_factor", &format!("{k:e}"));
        out.push(case(name, &format!("k₀ × {k} (solver.k0_factor)"), &b, expect));
    }

    let mut b = base.clone();
    b.solver_set("relaxation", "1.0");
    out.push(case(
        "relaxation-1",
        "μ = 1 (solver.relaxation: no relaxation)",
        &b,
        Expect::Stop {
            outcome: "stagnated",
            why: "without relaxation the iteration is only non-expansive: with the coarse problem, \
                  a subdomain without prescribed displacement (here the right-hand ones) gives a \
                  mode at −1 and η cycles with period 2; any μ < 1 converges (0.95: 129 iterations)",
        },
    ));
    let mut b = base.clone();
    b.solver_set("relaxation", "0.3");
    out.push(case("relaxation-0.3", "μ = 0.3 (solver.relaxation)", &b, conv.clone()));

    let mut b = base.clone();
    b.solver_set("search_direction_update", "true");
    b.solver_set("alpha", "0.5");
    out.push(case(
        "direction-update-alpha-0.5",
        "search-direction update with α = 0.5 (k⁺ = k₀/2 at slipping points), μ = 0.8",
        &b,
        Expect::Rejected { reason: "solver.alpha" },
    ));
    let mut b = base.clone();
    b.solver_set("search_direction_update", "true");
    b.solver_set("alpha", "0.5");
    b.solver_set("relaxation", "0.6");
    out.push(case(
        "direction-update-alpha-0.5-relaxation-0.6",
        "α = 0.5 with μ = 0.6, inside the limit 2(1 − μ)/(2 − μ) = 0.571",
        &b,
        conv.clone(),
    ));

    for (name, on) in [("direction-update-on", true), ("direction-update-off", false)] {
        let mut b = base.clone();
        b.solver_set("search_direction_update", &on.to_string());
        out.push(case(
            name,
            &format!("search-direction update {}", if on { "on" } else { "off" }),
            &b,
            conv.clone(),
        ));
    }

    let mut b = base.clone();
    b.n_steps = 1;
    b.set_loads(100.0, TENSION, SHEAR, "t", "t");
    out.push(case("steps-1", "N = 1 (end loads ramped t/T)", &b, conv.clone()));

    let mut b = base.clone();
    b.nx = 4;
    b.split = 1;
    b.layers.iter_mut().for_each(|l| l.ny = 1);
    b.n_steps = 10_000;
    out.push(case(
        "steps-10000",
        "N = 10 000, on 4 × 1 QUA8 and one subdomain per layer",
        &b,
        conv.clone(),
    ));

    let gap_open = two_blocks(
        "0.01",
        "[[boundary]]\ny = 0.0\nux = 0.0\nuy = 0.0\n\n[[boundary]]\ny = 20.0\nux = 0.0\nuy = 0.0\n\n\
         [[boundary]]\nx = 40.0\np = \"50*t\"\n\n",
    );
    out.push(case(
        "gap-open",
        "two blocks clamped at y = 0 and y = 20, initial gap 0.01 mm, end pressure 50 MPa: \
             separation everywhere",
        &gap_open,
        conv.clone(),
    ));
    let b = two_blocks(
        "0.01",
        "[[boundary]]\ny = 0.0\nux = 0.0\nuy = 0.0\n\n[[boundary]]\ny = 20.0\nux = \"0.002*t\"\n\
         uy = \"-0.005*t\"\n\n",
    );
    out.push(case(
        "gap-open-rigid",
        "two blocks, initial gap 0.01 mm, no load: the upper block translated by \
             (0.002, −0.005) mm without touching (zero stress)",
        &b,
        conv.clone(),
    ));
    let closing = two_blocks(
        "x^2/(2*100)",
        "[[boundary]]\ny = 0.0\nux = 0.0\nuy = 0.0\n\n[[boundary]]\ny = 20.0\n\
         ux = \"0.002*max(0, 2*t - 1)\"\nuy = \"-0.01*min(1, 2*t)\"\n\n",
    );
    out.push(case(
        "gap-closing",
        "two blocks, parabolic gap x²/200 mm closed from x = 0 by a 0.01 mm push, then sheared",
        &closing,
        conv.clone(),
    ));
    let mut b = closing.clone();
    b.solver_set("search_direction_update", "true");
    out.push(case(
        "gap-closing-direction-update",
        "gap-closing with the search-direction update on",
        &b,
        conv.clone(),
    ));

    out.push(case(
        "thin-layers-1:100",
        "three 100 × 1 mm layers (aspect ratio 1:100), 50 × 1 QUA8 each, pressure and end tension",
        &thin_layers(0.0),
        conv.clone(),
    ));
    let mut b = thin_layers(10.0);
    // Slow contraction again: η underestimates the traction error ~5000-fold here (5.5e-4 at
    // η ≤ 1e-7), so this case asks η ≤ 1e-8.
    b.solver_set("tolerance", "1e-8");
    out.push(case(
        "thin-layers-1:100-bending",
        "as thin-layers-1:100 plus an end shear of 10 N (bending of the 3 mm stack), η ≤ 1e-8",
        &b,
        conv.clone(),
    ));
    b.solver_set("macro_degree", "1");
    out.push(case(
        "thin-layers-1:100-bending-degree-1",
        "thin-layers-1:100-bending with the paper's macro basis (solver.macro_degree = 1)",
        &b,
        Expect::Stop {
            outcome: "max_iterations",
            why: "rigid + extension macro modes hold no bending of a slender layer, and a scalar k₀ \
                  cannot match it both across (E/h) and along (E·h/L², 1e4 times softer): the \
                  iteration crawls (η 2.5e-5 after 2000 iterations, k₀ × 0.1 to × 10 no better); \
                  the default macro_degree = \"auto\" gives such interfaces degree 5",
        },
    ));

    for c in &mut out {
        c.quick = !SLOW.contains(&c.name);
    }
    if quick {
        out.retain(|c| c.quick);
    }
    out
}

fn panic_text(e: &(dyn std::any::Any + Send)) -> String {
    e.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| e.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".into())
}

fn fields_finite(f: &[InterfaceFields]) -> bool {
    f.iter().all(|x| {
        [&x.w_a, &x.w_b, &x.f_a, &x.f_b]
            .iter()
            .all(|m| (0..m.ncols()).all(|j| (0..m.nrows()).all(|i| m[(i, j)].is_finite())))
    })
}

/// Runs one case, plain and accelerated, against one reference (a panic inside a run or the
/// reference is caught and reported as [`Outcome::Panicked`]).
pub fn run_case(case: &Case) -> CaseResult {
    let (mut plain, plain_run) = latin_run(case, &case.scene, false);
    let (mut anderson, anderson_run) = latin_run(case, &case.accelerated, true);
    let mut row = CaseResult {
        case: case.name.into(),
        varies: case.varies.clone(),
        expect: case.expect.clone(),
        tolerance: plain_run.as_ref().and_then(|(sc, _)| sc.model.solver.tolerance),
        plain: RunRow::new(),
        anderson: RunRow::new(),
        acceleration: AccelerationEffect::Kept,
        reference_note: None,
        reference_s: None,
        reference_newton: None,
        assessment: Assessment::Unexpected,
    };
    match (&case.reference, plain_run.as_ref().or(anderson_run.as_ref())) {
        (None, _) => row.reference_note = Some("reference not computed for this case".into()),
        (Some(_), None) => {}
        (Some(opts), Some((sc, _))) => {
            let model = &sc.model;
            let t1 = Instant::now();
            match catch_unwind(AssertUnwindSafe(|| solve_reference(model, opts))) {
                Ok(Ok(reference)) => {
                    row.reference_s = Some(t1.elapsed().as_secs_f64());
                    row.reference_newton = Some(reference.newton_iterations.iter().sum());
                    let finite = fields_finite(&reference.interfaces);
                    for (run, fields) in [(&mut plain, &plain_run), (&mut anderson, &anderson_run)] {
                        run.fields_finite &= finite;
                        if let Some((_, fields)) = fields {
                            let note = compare(run, model, fields, &reference.interfaces);
                            row.reference_note = row.reference_note.take().or(note);
                        }
                    }
                }
                Ok(Err(e)) => row.reference_note = Some(format!("reference failed: {e}")),
                Err(e) => row.reference_note = Some(format!("reference panicked: {}", panic_text(e.as_ref()))),
            }
        }
    }
    let finite = |v: Option<f64>| v.is_none_or(f64::is_finite);
    for run in [&mut plain, &mut anderson] {
        run.fields_finite &= [run.traction_error, run.jump_error, run.latin_s, row.reference_s]
            .into_iter()
            .all(finite);
    }
    let error = match row.expect {
        Expect::Converge { error } => error,
        _ => ERROR_TOLERANCE,
    };
    row.acceleration = AccelerationEffect::of(&plain, &anderson, row.tolerance, error);
    let sound = |r: &RunRow| r.fields_finite && !matches!(r.outcome, Outcome::Panicked { .. });
    row.assessment = if assess(&row.expect, row.tolerance, &plain) == Assessment::AsExpected
        && sound(&anderson)
        && row.acceleration != AccelerationEffect::Broke
    {
        Assessment::AsExpected
    } else {
        Assessment::Unexpected
    };
    row.plain = plain;
    row.anderson = anderson;
    row
}

/// Compares a plain run's outcome with what its case expects.
fn assess(expect: &Expect, tolerance: Option<f64>, run: &RunRow) -> Assessment {
    if !run.fields_finite || matches!(run.outcome, Outcome::Panicked { .. }) {
        return Assessment::Unexpected;
    }
    let met = run.indicators_finite
        && match (expect, &run.outcome) {
            (Expect::Converge { error }, Outcome::Converged) => run.reaches(tolerance, *error),
            (Expect::Stop { outcome, .. }, o) => o.kind() == *outcome,
            (Expect::Rejected { reason }, Outcome::Rejected { reason: r }) => r.contains(reason),
            _ => false,
        };
    if met {
        Assessment::AsExpected
    } else {
        Assessment::Unexpected
    }
}

/// The loaded scene of a run and its interface fields at the stop.
type Stopped = (LoadedScene, Vec<InterfaceFields>);

/// Loads `scene` (a case's text, plain or accelerated) and runs it in-process; the fields are
/// `None` when the scene is rejected or the run fails or panics.
fn latin_run(case: &Case, scene: &str, accelerated: bool) -> (RunRow, Option<Stopped>) {
    let mut row = RunRow::new();
    let sc = match load_str(scene, &format!("{}.toml", case.name)) {
        Ok(sc) => sc,
        Err(e) => {
            row.outcome = Outcome::Rejected { reason: e.to_string() };
            return (row, None);
        }
    };
    let mut tally = accelerated.then(AndersonTally::default);
    let run_id = format!(
        "stability-{}{}",
        case.name.replace(|c: char| !c.is_ascii_alphanumeric(), "-"),
        if accelerated { "-anderson" } else { "" }
    );
    let t0 = Instant::now();
    let result = catch_unwind(AssertUnwindSafe(|| {
        run_in_process_observed(
            &sc,
            &RunOptions {
                run_id,
                interior: false,
            },
            |_| {},
            |m| {
                if let Some(t) = tally.as_mut() {
                    t.observe(m);
                }
                Duration::ZERO
            },
        )
    }));
    let result = match result {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => {
            row.outcome = Outcome::Error { detail: e.to_string() };
            return (row, None);
        }
        Err(e) => {
            row.outcome = Outcome::Panicked {
                detail: panic_text(e.as_ref()),
            };
            return (row, None);
        }
    };
    row.latin_s = Some(t0.elapsed().as_secs_f64());
    row.anderson_steps = tally;
    row.iterations = Some(result.iterations.len());
    let last = result.iterations.last().map(|r| &r.decision);
    row.eta = last.map(|d| d.eta);
    row.contact_indicator = last.map(|d| d.contact_indicator);
    row.first_direction_update = result
        .iterations
        .iter()
        .find(|r| !r.decision.direction_updates.is_empty())
        .map(|r| r.iteration);
    row.indicators_finite = result.iterations.iter().all(|r| {
        let d = &r.decision;
        [d.eta, d.contact_indicator, d.force_error, d.jump_error]
            .iter()
            .all(|v| v.is_finite())
    });
    row.outcome = match &result.verdict {
        Verdict::Converged => Outcome::Converged,
        Verdict::MaxIterations | Verdict::Continue => Outcome::MaxIterations,
        Verdict::Stagnated { detail } => Outcome::Stagnated { detail: detail.clone() },
        Verdict::Diverged { detail } => Outcome::Diverged { detail: detail.clone() },
    };
    let model = &sc.model;
    let nt = model.time.n_points();
    let mut counts = [0u64; 3];
    for sol in &result.interfaces {
        let itf = &model.interfaces[sol.interface as usize];
        if itf.is_contact() {
            let np = itf.n_pairs();
            for st in &sol.status[np * (nt - 1)..] {
                counts[*st as usize] += 1;
            }
        }
    }
    row.final_counts = Some(counts);
    let fields = result.interface_fields();
    row.fields_finite &= fields_finite(&fields);
    (row, Some((sc, fields)))
}

/// Sets a run's errors against the reference; returns why one is missing.
fn compare(
    run: &mut RunRow,
    model: &Model,
    fields: &[InterfaceFields],
    reference: &[InterfaceFields],
) -> Option<String> {
    if fields.len() != model.interfaces.len() {
        return Some("LATIN returned no interface fields".into());
    }
    let (e_f, e_w) = error_against_reference(&model.interfaces, fields, reference, &model.time.trapezoid_weights());
    run.jump_error = e_w.is_finite().then_some(e_w);
    // A relative error against a zero reference is infinite whenever s is not exactly 0.
    if e_f.is_finite() {
        run.traction_error = Some(e_f);
        return None;
    }
    let f_max = fields
        .iter()
        .zip(&model.interfaces)
        .filter(|(_, i)| i.is_contact())
        .flat_map(|(f, _)| [&f.f_a, &f.f_b])
        .flat_map(|m| (0..m.ncols()).flat_map(move |j| (0..m.nrows()).map(move |i| m[(i, j)].abs())))
        .fold(0.0, f64::max);
    Some(format!(
        "the reference's contact tractions are all 0; max |F| of LATIN = {f_max:.1e} N/mm"
    ))
}

/// Runs every case of the matrix in order; `on_case` sees each row as it is done.
pub fn run_matrix(quick: bool, on_case: impl FnMut(&CaseResult)) -> Vec<CaseResult> {
    run_cases(&cases(quick), on_case)
}

/// Runs the given cases in order (e.g. a selection of [`cases`] by name).
pub fn run_cases(cases: &[Case], mut on_case: impl FnMut(&CaseResult)) -> Vec<CaseResult> {
    cases
        .iter()
        .map(|c| {
            let r = run_case(c);
            on_case(&r);
            r
        })
        .collect()
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("—".into(), |x| format!("{x:.prec$e}"))
}

/// The table as Markdown: the plain run's columns, then the accelerated run's and what
/// acceleration did to the outcome.
pub fn markdown(rows: &[CaseResult]) -> String {
    let mut s = String::from(
        "| case | varies | expected | iterations | final η | traction error | jump error | LATIN (s) | \
         reference (s) | sep/stick/slip at t = T | outcome | Anderson: iterations | Anderson: final η | \
         Anderson: traction error | Anderson: LATIN (s) | mixed/safeguarded/restarted | acceleration |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let (p, a) = (&r.plain, &r.anderson);
        let expected = match &r.expect {
            Expect::Converge { error } => format!(
                "η ≤ {}{}",
                opt(r.tolerance, 0),
                if r.reference_s.is_some() {
                    format!(", error ≤ {error:.0e}")
                } else {
                    String::new()
                }
            ),
            Expect::Stop { outcome, .. } => format!("stop: {}", outcome.replace('_', " ")),
            Expect::Rejected { .. } => "rejected".into(),
        };
        let mut outcome = p.outcome.text();
        match (r.assessment, &r.expect) {
            (Assessment::AsExpected, Expect::Stop { why, .. }) => {
                let _ = write!(outcome, " — expected: {why}");
            }
            (Assessment::Unexpected, _) => outcome = format!("**unexpected**: {outcome}"),
            _ => {}
        }
        if let Some(n) = &r.reference_note {
            let _ = write!(outcome, " (error: {n})");
        }
        if let Some(i) = p.first_direction_update {
            let _ = write!(outcome, " (directions updated at iteration {i})");
        }
        let iterations = |run: &RunRow| run.iterations.map_or("—".into(), |n| n.to_string());
        let seconds = |run: &RunRow| run.latin_s.map_or("—".into(), |t| format!("{t:.2}"));
        let steps = a.anderson_steps.map_or("—".into(), |t| {
            format!("{}/{}/{}", t.mixed, t.safeguarded, t.restarted)
        });
        let effect = match r.acceleration {
            AccelerationEffect::Kept => match (p.iterations, a.iterations, &a.outcome) {
                (Some(n), Some(m), Outcome::Converged) => format!("kept ({n} → {m} iterations)"),
                _ => format!("kept ({})", a.outcome.kind().replace('_', " ")),
            },
            e => {
                let mut t = format!("{}: {}", e.kind(), a.outcome.text());
                if let (Outcome::Converged, Some(err)) = (&a.outcome, a.traction_error.or(a.jump_error)) {
                    let _ = write!(t, ", error {err:.1e}");
                }
                if e == AccelerationEffect::Broke {
                    t = format!("**{t}**");
                }
                t
            }
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.case,
            r.varies,
            expected,
            iterations(p),
            opt(p.eta, 2),
            opt(p.traction_error, 1),
            opt(p.jump_error, 1),
            seconds(p),
            r.reference_s.map_or("—".into(), |t| format!("{t:.2}")),
            p.final_counts
                .map_or("—".into(), |c| format!("{}/{}/{}", c[0], c[1], c[2])),
            outcome.replace('|', "\\|"),
            iterations(a),
            opt(a.eta, 2),
            match (a.traction_error, a.jump_error) {
                (None, Some(e)) => format!("jump {e:.1e}"),
                (e, _) => opt(e, 1),
            },
            seconds(a),
            steps,
            effect.replace('|', "\\|"),
        );
    }
    s
}
