//! Scene generators: scenes too large to write by hand, written as ordinary scene files
//! (`glissade generate`, docs/scenes.md#generated-scenes).

use std::fmt::Write as _;

/// A laminate of plies stacked along y, each ply cut into square subdomains along x: the
/// stratified scene's loads and contact on any number of plies. Perfect interfaces within a ply,
/// Coulomb contact between plies, clamped at x = 0, pressure on the bottom and top faces, an
/// axial traction on every other ply's free end and a shear over the whole free end.
#[derive(Debug, Clone, PartialEq)]
pub struct Laminate {
    /// Plies (≥ 1).
    pub plies: usize,
    /// Subdomains along each ply (≥ 1).
    pub per_ply: usize,
    /// QUA8 elements along each side of a subdomain (≥ 1).
    pub elements: usize,
    /// Side of a subdomain (mm).
    pub side: f64,
    /// Time steps N.
    pub steps: usize,
    /// Coulomb friction coefficient between plies.
    pub friction: f64,
    /// Subdomain node processes of a multi-process run.
    pub subdomain_nodes: usize,
    /// Interface node processes of a multi-process run.
    pub interface_nodes: usize,
    /// The interface nodes follow the subdomain processes (`[deployment]
    /// interfaces_with_subdomains`) instead of `interface_nodes`.
    pub interfaces_with_subdomains: bool,
    /// Which subdomains each subdomain process hosts (`[deployment] partition`).
    pub partition: glissade_scene::Partition,
}

/// A generator's parameters that cannot make a scene.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GenerateError {
    #[error("{what} = {value}: must be at least {min}")]
    TooSmall {
        what: &'static str,
        value: usize,
        min: usize,
    },
    #[error("{what} = {value}: must be a finite number {range}")]
    OutOfRange {
        what: &'static str,
        value: f64,
        range: &'static str,
    },
    #[error("{what} = {value}: must be at most {max} ({why})")]
    TooLarge {
        what: &'static str,
        value: usize,
        max: usize,
        why: &'static str,
    },
}

impl Default for Laminate {
    /// The 1000-subdomain laminate: 20 plies of 50 subdomains of 10 × 10 QUA8, N = 100.
    fn default() -> Self {
        Self {
            plies: 20,
            per_ply: 50,
            elements: 10,
            side: 30.0,
            steps: 100,
            friction: 0.3,
            subdomain_nodes: 3,
            interface_nodes: 1,
            interfaces_with_subdomains: false,
            partition: glissade_scene::Partition::Contiguous,
        }
    }
}

impl Laminate {
    /// Number of subdomains.
    pub fn subdomains(&self) -> usize {
        self.plies * self.per_ply
    }

    /// Number of interfaces: perfect ones within the plies, contact ones between them.
    pub fn interfaces(&self) -> usize {
        self.plies * (self.per_ply - 1) + (self.plies - 1) * self.per_ply
    }

    fn check(&self) -> Result<(), GenerateError> {
        for (what, value) in [
            ("plies", self.plies),
            ("per-ply", self.per_ply),
            ("elements", self.elements),
            ("steps", self.steps),
        ] {
            if value < 1 {
                return Err(GenerateError::TooSmall { what, value, min: 1 });
            }
        }
        if !(self.side.is_finite() && self.side > 0.0) {
            return Err(GenerateError::OutOfRange {
                what: "side",
                value: self.side,
                range: "> 0 (mm)",
            });
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(GenerateError::OutOfRange {
                what: "friction",
                value: self.friction,
                range: "≥ 0",
            });
        }
        // A process count is at least 1 and at most `max`, except that one is always allowed (the
        // scene's [deployment] rule: one interface node even on a scene without interfaces).
        let processes = |what, value: usize, max: usize, why| {
            if value < 1 {
                Err(GenerateError::TooSmall { what, value, min: 1 })
            } else if value > max.max(1) {
                Err(GenerateError::TooLarge { what, value, max, why })
            } else {
                Ok(())
            }
        };
        processes(
            "subdomain-nodes",
            self.subdomain_nodes,
            self.subdomains(),
            "one subdomain per process at most",
        )?;
        processes(
            "interface-nodes",
            self.interface_nodes,
            self.interfaces(),
            "one interface per process at least",
        )?;
        Ok(())
    }

    /// The scene file's text (TOML with comments).
    pub fn scene_text(&self) -> Result<String, GenerateError> {
        self.check()?;
        let (p, s, e, a) = (self.plies, self.per_ply, self.elements, self.side);
        let length = s as f64 * a;
        let height = p as f64 * a;
        let mut t = String::new();
        // `write!` to a String cannot fail.
        let _ = writeln!(
            t,
            "# Generated by `glissade generate laminate --plies {p} --per-ply {s} --elements {e} --side {a} \
             --steps {n} --friction {f} --subdomain-nodes {sn} {inn}{part}`.\n\
             # A laminate of {p} plies of {a} mm stacked along y, each ply cut into {s} subdomains of\n\
             # {a} × {a} mm meshed with {e} × {e} QUA8: {subs} subdomains, {ifs} interfaces (perfect within a\n\
             # ply, Coulomb contact f = {f} between plies). The stratified scene's loads: clamped at x = 0,\n\
             # 100 MPa on the bottom and top faces, an axial traction on every other ply's end (plies 2, 4, …)\n\
             # and a shear over the whole end. Units: mm, N, MPa, s.\n",
            n = self.steps,
            f = self.friction,
            sn = self.subdomain_nodes,
            inn = if self.interfaces_with_subdomains {
                "--interfaces-with-subdomains".to_string()
            } else {
                format!("--interface-nodes {}", self.interface_nodes)
            },
            part = match self.partition {
                glissade_scene::Partition::Contiguous => String::new(),
                other => format!(" --partition {}", other.name()),
            },
            subs = self.subdomains(),
            ifs = self.interfaces(),
        );
        let _ = writeln!(
            t,
            "name = \"laminate-{p}x{s}\"\nplane = \"strain\"\n\n[time]\nT = 10.0\nN = {}\n\n[materials.layer]\nE = 130000.0\nnu = 0.2\n",
            self.steps
        );
        for k in 0..p {
            let _ = writeln!(
                t,
                "[[block]]\nname = \"ply{}\"\nmaterial = \"layer\"\nx = [0.0, {length:?}]\ny = [{:?}, {:?}]\nnx = {}\nny = {e}\nsplit = [{s}, 1]\n",
                k + 1,
                k as f64 * a,
                (k + 1) as f64 * a,
                s * e,
            );
        }
        for k in 1..p {
            let _ = writeln!(
                t,
                "[[interface]]\nbetween = [\"ply{k}\", \"ply{}\"]\nkind = \"contact\"\nfriction = {:?}\n",
                k + 1,
                self.friction
            );
        }
        let _ = writeln!(
            t,
            "[[boundary]]\nx = 0.0\nux = 0.0\nuy = 0.0\n\n[[boundary]]\ny = 0.0\np = 100.0\n\n[[boundary]]\ny = {height:?}\np = 100.0\n"
        );
        // The stratified scene's end tension on its core (200 MPa · sin 2πt/T): here on the even plies.
        let tensioned: Vec<String> = (2..=p).step_by(2).map(|k| format!("\"ply{k}\"")).collect();
        if !tensioned.is_empty() {
            let _ = writeln!(
                t,
                "[[boundary]]\nblocks = [{}]\nx = {length:?}\ntx = \"200*sin(2*pi*t/10)\"\n",
                tensioned.join(", ")
            );
        }
        // The stratified scene's end shear stress (1500/90 MPa · sin 4πt/T) over the whole end.
        let _ = writeln!(
            t,
            "[[boundary]]\nx = {length:?}\nty = \"1500/90*sin(4*pi*t/10)\"\n\n[solver]\naccuracy = 1e-3\nrelaxation = 0.8\nalpha = 0.3333333333333333\ni0 = 0.1\n\n[deployment]\nsubdomain_nodes = {}\n{}{}",
            self.subdomain_nodes,
            match self.partition {
                glissade_scene::Partition::Contiguous => String::new(),
                other => format!("partition = \"{}\"\n", other.name()),
            },
            if self.interfaces_with_subdomains {
                "interfaces_with_subdomains = true".to_string()
            } else {
                format!("interface_nodes = {}", self.interface_nodes)
            }
        );
        Ok(t)
    }
}
