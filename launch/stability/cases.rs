//! The cases of the stability matrix: a small base scene (layers of blocks in contact, or two
//! blocks), each case a variation of it with what it expects.

use glissade_reference::ReferenceOptions;
use serde::Serialize;
use std::fmt::Write as _;

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
    /// Stops without converging with this outcome ([`Outcome::kind`]: `max_iterations`, `no_equilibrium`,
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
    out.extend(material_and_load_cases(&base, &conv));
    out.extend(solver_cases(&base, &conv));
    out.extend(geometry_cases(&conv));
    for c in &mut out {
        c.quick = !SLOW.contains(&c.name);
    }
    if quick {
        out.retain(|c| c.quick);
    }
    out
}

/// Cases that vary the base scene's materials, friction and loads.
fn material_and_load_cases(base: &Base, conv: &Expect) -> Vec<Case> {
    let mut out = Vec::new();
    out.push(case(
        "base",
        "nothing: three 40 × 10 mm layers, 8 × 2 QUA8 and 2 subdomains each, E = 130 GPa, ν = 0.2, \
         f = 0.3, p = 100 MPa, end tension and shear, N = 10",
        base,
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

    out
}

/// Cases that vary the solver's settings and the time grid.
fn solver_cases(base: &Base, conv: &Expect) -> Vec<Case> {
    let mut out = Vec::new();
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

    out
}

/// Cases of other geometries: gaps opening and closing between two blocks, thin layers.
fn geometry_cases(conv: &Expect) -> Vec<Case> {
    let mut out = Vec::new();
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

    out
}
