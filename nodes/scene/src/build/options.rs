//! The solver, PGD, linear-stage, recording, network and deployment sections.

use super::*;

/// `solver.time_coarsening` as written, before N and the linear stage resolve it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Coarsening {
    /// "auto" (the default), with the coarse solve's tolerance.
    Auto(f64),
    Off,
    Fixed(TimeStart),
}

/// Fewest time steps at which `time_coarsening = "auto"` starts from a coarse solve.
pub const AUTO_COARSENING_MIN_STEPS: usize = 200;
/// Steps of the coarse grid that `"auto"` aims for.
pub const AUTO_COARSE_STEPS: usize = 100;

/// The factor `time_coarsening = "auto"` chooses for N time steps: none below
/// [`AUTO_COARSENING_MIN_STEPS`] (a coarse solve saves few iterations on short grids:
/// docs/accuracy.md), else the divisor c ≥ 2 of N whose coarse grid N/c is nearest to
/// [`AUTO_COARSE_STEPS`] steps (the larger c on a tie), none if N is prime.
pub fn auto_coarsening(n_steps: usize) -> Option<usize> {
    if n_steps < AUTO_COARSENING_MIN_STEPS {
        return None;
    }
    // The divisors in pairs (d, N/d) with d ≤ √N: √N trials, not N (N = 10¹¹ took minutes).
    (1..)
        .take_while(|&d| d <= n_steps / d)
        .filter(|&d| n_steps.is_multiple_of(d))
        .flat_map(|d| [d, n_steps / d])
        .filter(|&c| c >= 2 && c < n_steps)
        .min_by_key(|&c| ((n_steps / c).abs_diff(AUTO_COARSE_STEPS), std::cmp::Reverse(c)))
}

impl Ctx<'_> {
    pub(crate) fn solver(&self, r: &RawSolver) -> Result<SolverParams, SceneError> {
        let d = SolverParams::default();
        let s = SolverParams {
            k0_factor: r.k0_factor.unwrap_or(d.k0_factor),
            relaxation: r.relaxation.unwrap_or(d.relaxation),
            accuracy: r.accuracy.or(d.accuracy),
            tolerance: r.tolerance.or(d.tolerance),
            contact_tolerance: r.contact_tolerance.or(d.contact_tolerance),
            max_iterations: r.max_iterations.unwrap_or(d.max_iterations),
            stagnation_window: r.stagnation_window.unwrap_or(d.stagnation_window),
            stagnation_ratio: r.stagnation_ratio.unwrap_or(d.stagnation_ratio),
            coarse: r.coarse.unwrap_or(d.coarse),
            search_direction_update: r.search_direction_update.unwrap_or(d.search_direction_update),
            alpha: r.alpha.unwrap_or(d.alpha),
            i0: r.i0.unwrap_or(d.i0),
            macro_degree: match &r.macro_degree {
                None => d.macro_degree,
                Some(RawDegree::Name(n)) if n == "auto" => None,
                Some(RawDegree::Degree(k)) if (1..=MAX_MACRO_DEGREE as i64).contains(k) => Some(*k as usize),
                Some(bad) => {
                    let shown = match bad {
                        RawDegree::Degree(k) => k.to_string(),
                        RawDegree::Name(n) => format!("\"{n}\""),
                    };
                    return Err(self.err(
                        "solver.macro_degree",
                        format!("{shown} is neither \"auto\" nor a degree in 1..={MAX_MACRO_DEGREE}"),
                    ));
                }
            },
            acceleration: self.acceleration(r, d.acceleration)?,
            time_start: None,
            given_start: false,
        };
        let positive = |v: f64| v > 0.0 && v.is_finite();
        self.check(positive(s.k0_factor), "solver.k0_factor", || {
            format!("{} must be > 0", s.k0_factor)
        })?;
        self.check(s.relaxation > 0.0 && s.relaxation <= 1.0, "solver.relaxation", || {
            format!("{} is outside (0, 1]", s.relaxation)
        })?;
        if let Some(a) = s.accuracy {
            self.check_accuracy(a)?;
        }
        if let Some(t) = s.tolerance {
            self.check_tolerance(t)?;
        }
        if let Some(c) = s.contact_tolerance {
            self.check(positive(c), "solver.contact_tolerance", || format!("{c} must be > 0"))?;
        }
        self.check_max_iterations(s.max_iterations)?;
        self.check(s.stagnation_window >= 1, "solver.stagnation_window", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(
            s.stagnation_ratio > 0.0 && s.stagnation_ratio <= 1.0,
            "solver.stagnation_ratio",
            || format!("{} is outside (0, 1]", s.stagnation_ratio),
        )?;
        self.check(s.alpha >= 0.0 && s.alpha < 1.0, "solver.alpha", || {
            format!("{} is outside [0, 1) (updated directions are k₀(1 − α) > 0)", s.alpha)
        })?;
        if s.search_direction_update {
            let limit = s.alpha_limit();
            self.check(s.alpha <= limit * (1.0 + 1e-12), "solver.alpha", || {
                format!(
                    "{} is above {limit:.4} = 2(1 − μ)/(2 − μ) for relaxation μ = {}: with the \
                     search-direction update on, the iteration would diverge (lower alpha or the relaxation)",
                    s.alpha, s.relaxation
                )
            })?;
        }
        self.check(positive(s.i0), "solver.i0", || format!("{} must be > 0", s.i0))?;
        Ok(s)
    }

    /// `solver.accuracy`, from the file or the command line.
    pub(crate) fn check_accuracy(&self, a: f64) -> Result<(), SceneError> {
        self.check(a > 0.0 && a < 1.0, "solver.accuracy", || {
            format!("{a} is outside (0, 1) (a relative error of the contact tractions)")
        })
    }

    /// `solver.tolerance`, from the file or the command line.
    pub(crate) fn check_tolerance(&self, t: f64) -> Result<(), SceneError> {
        self.check(t > 0.0 && t.is_finite(), "solver.tolerance", || {
            format!("{t} must be > 0")
        })
    }

    /// `solver.max_iterations`, from the file or the command line.
    pub(crate) fn check_max_iterations(&self, m: usize) -> Result<(), SceneError> {
        self.check(m >= 1, "solver.max_iterations", || "must be ≥ 1".to_string())
    }

    /// `time_coarsening` ("auto" when absent, "off" or c) and its tolerance; resolved against N
    /// and the linear stage in [`Self::build`] ([`Self::resolve_time_start`]).
    pub(crate) fn time_start(&self, r: &RawSolver) -> Result<Coarsening, SceneError> {
        let tolerance = r.time_coarsening_tolerance.unwrap_or(DEFAULT_TIME_START_TOLERANCE);
        self.check(
            tolerance > 0.0 && tolerance.is_finite(),
            "solver.time_coarsening_tolerance",
            || format!("{tolerance} must be > 0"),
        )?;
        match &r.time_coarsening {
            None => Ok(Coarsening::Auto(tolerance)),
            Some(RawDegree::Name(n)) if n == "auto" => Ok(Coarsening::Auto(tolerance)),
            Some(RawDegree::Name(n)) if n == "off" => match r.time_coarsening_tolerance {
                Some(t) => Err(self.err(
                    "solver.time_coarsening_tolerance",
                    format!("{t} is set but solver.time_coarsening is \"off\""),
                )),
                None => Ok(Coarsening::Off),
            },
            Some(RawDegree::Name(n)) => Err(self.err(
                "solver.time_coarsening",
                format!("\"{n}\" is neither \"auto\", \"off\" nor a factor c ≥ 2"),
            )),
            Some(RawDegree::Degree(c)) => {
                self.check(*c >= 2, "solver.time_coarsening", || {
                    format!("{c} must be ≥ 2 (the coarse grid takes every c-th time point)")
                })?;
                Ok(Coarsening::Fixed(TimeStart {
                    coarsening: *c as usize,
                    tolerance,
                }))
            }
        }
    }

    /// The time-coarse start of a scene with `n_steps` steps and linear stage `stage`: a fixed
    /// factor is checked against them; "auto" starts from a coarse solve where it pays
    /// ([`auto_coarsening`]) and from ŝ = 0 elsewhere.
    pub(crate) fn resolve_time_start(
        &self,
        choice: Coarsening,
        n_steps: usize,
        stage: LinearStage,
    ) -> Result<Option<TimeStart>, SceneError> {
        match choice {
            Coarsening::Off => Ok(None),
            Coarsening::Auto(tolerance) => Ok((stage != LinearStage::Pgd)
                .then(|| auto_coarsening(n_steps))
                .flatten()
                .map(|coarsening| TimeStart { coarsening, tolerance })),
            Coarsening::Fixed(ts) => {
                self.check(n_steps.is_multiple_of(ts.coarsening), "solver.time_coarsening", || {
                    format!(
                        "{} does not divide time.N = {n_steps} (the coarse grid takes every {}-th time point)",
                        ts.coarsening, ts.coarsening
                    )
                })?;
                self.check(stage != LinearStage::Pgd, "solver.time_coarsening", || {
                    "is not available with the PGD linear stage (its basis is built from ŝ = 0); \
                     use linear_stage = \"condensed\" or \"sparse\""
                        .to_string()
                })?;
                Ok(Some(ts))
            }
        }
    }

    pub(crate) fn acceleration(&self, r: &RawSolver, default: Acceleration) -> Result<Acceleration, SceneError> {
        let anderson = match r.acceleration {
            Some(a) => a == RawAcceleration::Anderson,
            None => matches!(default, Acceleration::Anderson { .. }),
        };
        if !anderson {
            if let Some(m) = r.anderson_window {
                return Err(self.err(
                    "solver.anderson_window",
                    format!("{m} is set but solver.acceleration is \"none\" (set acceleration = \"anderson\")"),
                ));
            }
            return Ok(Acceleration::None);
        }
        let window = r.anderson_window.unwrap_or(match default {
            Acceleration::Anderson { window } => window,
            Acceleration::None => DEFAULT_ANDERSON_WINDOW,
        });
        self.check(
            (1..=MAX_ANDERSON_WINDOW).contains(&window),
            "solver.anderson_window",
            || format!("{window} is outside 1..={MAX_ANDERSON_WINDOW}"),
        )?;
        Ok(Acceleration::Anderson { window })
    }

    pub(crate) fn pgd(&self, r: Option<&RawPgd>) -> Result<PgdParams, SceneError> {
        let d = PgdParams::default();
        let Some(r) = r else { return Ok(d) };
        let p = PgdParams {
            enabled: r.enabled.unwrap_or(d.enabled),
            xi1: r.xi1.unwrap_or(d.xi1),
            xi2: r.xi2.unwrap_or(d.xi2),
            criterion: match r.criterion {
                None => d.criterion,
                Some(RawCriterion::Increment) => PgdCriterion::Increment,
                Some(RawCriterion::Accumulated) => PgdCriterion::Accumulated,
                Some(RawCriterion::IncrementSvd) => PgdCriterion::IncrementSvd,
                Some(RawCriterion::Forcing) => PgdCriterion::Forcing,
                Some(RawCriterion::ForcingSvd) => PgdCriterion::ForcingSvd,
            },
            macro_modes: r.macro_modes.unwrap_or(d.macro_modes),
            max_new_modes: r.max_new_modes.unwrap_or(d.max_new_modes),
        };
        self.check(p.max_new_modes >= 1, "solver.pgd.max_new_modes", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(p.xi1 > 0.0 && p.xi1.is_finite(), "solver.pgd.xi1", || {
            format!("{} must be > 0", p.xi1)
        })?;
        self.check(p.xi2 > 0.0 && p.xi2.is_finite(), "solver.pgd.xi2", || {
            format!("{} must be > 0", p.xi2)
        })?;
        Ok(p)
    }

    pub(crate) fn linear_stage(&self, r: &RawSolver) -> Result<LinearStage, SceneError> {
        let enabled = r.pgd.as_ref().and_then(|p| p.enabled);
        let stage = match r.linear_stage {
            None if enabled == Some(true) => return Ok(LinearStage::Pgd),
            None => return Ok(LinearStage::Condensed),
            Some(RawLinearStage::Condensed) => LinearStage::Condensed,
            Some(RawLinearStage::Sparse) => LinearStage::Sparse,
            Some(RawLinearStage::Pgd) => LinearStage::Pgd,
            Some(RawLinearStage::Auto) => LinearStage::Auto,
        };
        if let Some(e) = enabled {
            let pgd = stage == LinearStage::Pgd;
            self.check(e == pgd || stage == LinearStage::Auto, "solver.pgd.enabled", || {
                format!("{e} contradicts solver.linear_stage = {stage:?} (set one of them)")
            })?;
        }
        Ok(stage)
    }

    pub(crate) fn recording(&self, r: &RawRecording) -> Result<Recording, SceneError> {
        let d = Recording::default();
        let rec = Recording {
            enabled: r.enabled.unwrap_or(d.enabled),
            topics: r.topics.clone().unwrap_or(d.topics),
            full_fields_every: r.full_fields_every.unwrap_or(d.full_fields_every),
            full_fields_auto: r.full_fields_every.is_none(),
        };
        self.check_recording(&rec)?;
        Ok(rec)
    }

    /// The `[recording]` settings, from the file or with the command line's `--record`.
    pub(crate) fn check_recording(&self, rec: &Recording) -> Result<(), SceneError> {
        self.check(rec.full_fields_every >= 1, "recording.full_fields_every", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(rec.topics.iter().all(|t| !t.is_empty()), "recording.topics", || {
            "topic patterns must not be empty strings".to_string()
        })
    }

    pub(crate) fn network(&self, r: &RawNetwork) -> Result<Network, SceneError> {
        let tls = match &r.tls {
            None => None,
            Some(t) => {
                for (key, value) in [("root_ca", &t.root_ca), ("cert", &t.cert), ("key", &t.key)] {
                    self.check(!value.trim().is_empty(), &format!("network.tls.{key}"), || {
                        "must name a PEM file (relative to the scene file's folder)".to_string()
                    })?;
                }
                Some(TlsFiles {
                    root_ca: t.root_ca.clone().into(),
                    cert: t.cert.clone().into(),
                    key: t.key.clone().into(),
                    mutual: t.mutual.unwrap_or(false),
                })
            }
        };
        if let Some(allow) = &r.allow {
            self.check(tls.is_some(), "network.allow", || {
                "access control names processes by their certificates: it needs network.tls (with mutual = true)"
                    .to_string()
            })?;
            self.check(tls.as_ref().is_some_and(|t| t.mutual), "network.allow", || {
                "access control needs network.tls.mutual = true (a process's common name is known only from the \
                 certificate it presents)"
                    .to_string()
            })?;
            self.check(!allow.is_empty(), "network.allow", || {
                "an empty list would let no process take part (remove the key to turn access control off)".to_string()
            })?;
            for (i, name) in allow.iter().enumerate() {
                self.check(!name.trim().is_empty(), &format!("network.allow[{i}]"), || {
                    "must be a certificate common name, not empty".to_string()
                })?;
                self.check(!allow[..i].contains(name), &format!("network.allow[{i}]"), || {
                    format!("`{name}` is listed twice")
                })?;
            }
        }
        Ok(Network {
            tls,
            allow: r.allow.clone(),
            shared_memory: r.shared_memory,
        })
    }

    pub(crate) fn deployment(&self, r: &RawDeployment, n_subdomains: usize) -> Result<Deployment, SceneError> {
        let d = Deployment::default();
        let dep = Deployment {
            subdomain_nodes: r.subdomain_nodes.unwrap_or(d.subdomain_nodes),
            partition: match r.partition {
                None => d.partition,
                Some(RawPartition::Contiguous) => Partition::Contiguous,
                Some(RawPartition::Bisection) => Partition::Bisection,
            },
            interface_nodes: r
                .interface_nodes
                .or(r.interface_groups.as_ref().map(Vec::len))
                .unwrap_or(d.interface_nodes),
            interface_groups: None,
            restarts: r.restarts.unwrap_or(d.restarts),
            interfaces_in_launcher: r.interfaces_in_launcher.unwrap_or(d.interfaces_in_launcher),
            interfaces_with_subdomains: r.interfaces_with_subdomains.unwrap_or(d.interfaces_with_subdomains),
        };
        if dep.interfaces_with_subdomains {
            let given = [
                ("interface_nodes", r.interface_nodes.is_some()),
                ("interface_groups", r.interface_groups.is_some()),
            ];
            for (key, set) in given {
                self.check(!set, "deployment.interfaces_with_subdomains", || {
                    format!(
                        "excludes deployment.{key}: the interface nodes follow the subdomain processes (one per \
                         process for the interfaces inside it, node 0 for the interfaces between processes)"
                    )
                })?;
            }
        }
        self.check(dep.restarts <= 100, "deployment.restarts", || {
            format!(
                "{}: at most 100 (a node that keeps dying will not recover)",
                dep.restarts
            )
        })?;
        self.check(dep.subdomain_nodes >= 1, "deployment.subdomain_nodes", || {
            "must be ≥ 1".to_string()
        })?;
        self.check(
            dep.subdomain_nodes <= n_subdomains,
            "deployment.subdomain_nodes",
            || {
                format!(
                    "{} nodes for {n_subdomains} subdomain(s): some nodes would host nothing",
                    dep.subdomain_nodes
                )
            },
        )?;
        self.check(dep.interface_nodes >= 1, "deployment.interface_nodes", || {
            "must be ≥ 1".to_string()
        })?;
        Ok(dep)
    }

    /// Checks `interface_nodes` against the interfaces and resolves `interface_groups`: each
    /// group non-empty, every interface in exactly one group.
    pub(crate) fn interface_groups(
        &self,
        r: &RawDeployment,
        dep: &mut Deployment,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        interfaces: &[Interface],
    ) -> Result<(), SceneError> {
        let n = interfaces.len();
        let Some(raw_groups) = &r.interface_groups else {
            return self.check(
                dep.interface_nodes == 1 || dep.interface_nodes <= n,
                "deployment.interface_nodes",
                || {
                    format!(
                        "{} nodes for {n} interface(s): some nodes would own nothing",
                        dep.interface_nodes
                    )
                },
            );
        };
        self.check(
            raw_groups.len() == dep.interface_nodes,
            "deployment.interface_groups",
            || {
                format!(
                    "{} group(s) for interface_nodes = {}: give one group per interface node",
                    raw_groups.len(),
                    dep.interface_nodes
                )
            },
        )?;
        let mut owner: Vec<Option<usize>> = vec![None; n];
        let mut groups = Vec::with_capacity(raw_groups.len());
        for (g, raw) in raw_groups.iter().enumerate() {
            let key = format!("deployment.interface_groups[{g}]");
            self.check(!raw.is_empty(), &key, || {
                "is empty: every interface node must own an interface".into()
            })?;
            let mut group = Vec::new();
            for (e, entry) in raw.iter().enumerate() {
                let key = format!("{key}[{e}]");
                let hits: Vec<usize> = match entry {
                    RawInterfaceRef::Index(i) => {
                        self.check(*i < n, &key, || {
                            format!(
                                "interface {i} does not exist (the scene has {n}, indices 0 to {})",
                                n.saturating_sub(1)
                            )
                        })?;
                        vec![*i]
                    }
                    RawInterfaceRef::Between(text) => {
                        let Some((x, y)) = text.split_once('|') else {
                            return Err(self.err(
                                key,
                                format!(
                                    "`{text}`: name an interface as \"A|B\" (blocks or subdomains) or by its index"
                                ),
                            ));
                        };
                        let (sx, _) = self.resolve(names, subs, x.trim(), &key)?;
                        let (sy, _) = self.resolve(names, subs, y.trim(), &key)?;
                        let hits: Vec<usize> = (0..n)
                            .filter(|&i| {
                                let (a, b) = (interfaces[i].a, interfaces[i].b);
                                (sx.contains(&a) && sy.contains(&b)) || (sx.contains(&b) && sy.contains(&a))
                            })
                            .collect();
                        self.check(!hits.is_empty(), &key, || format!("`{text}` matches no interface"))?;
                        hits
                    }
                };
                for i in hits {
                    if let Some(other) = owner[i] {
                        let itf = &interfaces[i];
                        return Err(self.err(
                            key,
                            format!(
                                "interface {i} ({}|{}) is already in group {other}",
                                subs[itf.a].name, subs[itf.b].name
                            ),
                        ));
                    }
                    owner[i] = Some(g);
                    group.push(i);
                }
            }
            group.sort_unstable();
            groups.push(group);
        }
        let unowned: Vec<String> = (0..n)
            .filter(|&i| owner[i].is_none())
            .map(|i| format!("{i} ({}|{})", subs[interfaces[i].a].name, subs[interfaces[i].b].name))
            .collect();
        self.check(unowned.is_empty(), "deployment.interface_groups", || {
            format!("interface(s) {} are in no group", unowned.join(", "))
        })?;
        dep.interface_groups = Some(groups);
        Ok(())
    }
}
