//! The global step on one node: the partials summed over every subdomain in, the
//! [`AndersonStep`] out (mixing coefficients, the safeguard's plain step, or a restart).

use super::{AndersonStep, GramPartials};

/// Statistics of a run's mixing steps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AndersonCounts {
    pub mixed: u32,
    pub safeguarded: u32,
    pub restarts: u32,
}

/// The global step: sums of partials in, coefficients out.
#[derive(Debug, Clone)]
pub struct AndersonCoordinator {
    max_condition: f64,
    last_residual2: Option<f64>,
    last_mixed: bool,
    pub counts: AndersonCounts,
}

impl AndersonCoordinator {
    pub fn new(max_condition: f64) -> Self {
        Self {
            max_condition,
            last_residual2: None,
            last_mixed: false,
            counts: AndersonCounts::default(),
        }
    }

    /// ‖r‖² = ‖G(s) − s‖² (force part) summed over the parts of the last step's partials: the
    /// fixed-point residual of the last iterate mixed, which the error estimate calibrates.
    pub fn last_residual2(&self) -> Option<f64> {
        self.last_residual2
    }

    /// The step for every part's `partials` (the same k), summed from zero in the order given (a
    /// fixed order, so that the sum is the same bit for bit on every run): [`Self::decide`] on
    /// the sum.
    pub fn step<'a>(
        &mut self,
        partials: impl IntoIterator<Item = &'a GramPartials>,
        map_changed: bool,
    ) -> AndersonStep {
        let mut partials = partials.into_iter().peekable();
        let mut sum = GramPartials::zeros(partials.peek().map_or(0, |p| p.k));
        for p in partials {
            sum.add(p);
        }
        self.decide(&sum, map_changed)
    }

    /// The step for the summed partials `p`. `map_changed` (e.g. after a search-direction update)
    /// restarts the histories: differences taken before belong to another fixed-point map.
    pub fn decide(&mut self, p: &GramPartials, map_changed: bool) -> AndersonStep {
        let grew = self.last_mixed && self.last_residual2.is_some_and(|r| p.residual2 > r);
        let step = if map_changed || !p.residual2.is_finite() {
            AndersonStep::Restart
        } else if grew || p.k == 0 {
            AndersonStep::Plain
        } else {
            match solve_least_squares(p, self.max_condition) {
                Some(gamma) => AndersonStep::Mix(gamma),
                None => AndersonStep::Restart,
            }
        };
        match &step {
            AndersonStep::Mix(_) => self.counts.mixed += 1,
            AndersonStep::Plain if grew => self.counts.safeguarded += 1,
            AndersonStep::Restart => self.counts.restarts += 1,
            AndersonStep::Plain => {}
        }
        self.last_mixed = matches!(step, AndersonStep::Mix(_));
        self.last_residual2 = Some(p.residual2);
        step
    }
}

/// γ solving the normal equations (Δrᵀ Δr) γ = Δrᵀ r, or None when the Gram matrix scaled to a
/// unit diagonal has a condition number above `max_condition` (or a zero or non-finite entry).
pub fn solve_least_squares(p: &GramPartials, max_condition: f64) -> Option<Vec<f64>> {
    let k = p.k;
    if p.gram.iter().chain(&p.projection).any(|v| !v.is_finite()) {
        return None;
    }
    let d: Vec<f64> = (0..k).map(|i| p.gram[i * k + i]).collect();
    if d.iter().any(|&v| v <= 0.0) {
        return None;
    }
    let s: Vec<f64> = d.iter().map(|v| 1.0 / v.sqrt()).collect();
    let h = nalgebra::DMatrix::from_fn(k, k, |i, j| s[i] * p.gram[j * k + i] * s[j]);
    let eig = nalgebra::SymmetricEigen::new(h.clone());
    let (lo, hi) = eig
        .eigenvalues
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo <= 0.0 || hi / lo > max_condition {
        return None;
    }
    let b = nalgebra::DVector::from_fn(k, |i, _| s[i] * p.projection[i]);
    let y = h.cholesky()?.solve(&b);
    Some((0..k).map(|i| s[i] * y[i]).collect())
}
