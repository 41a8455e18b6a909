//! The stop decision's rule (docs/method.md, "Indicators and stopping"): accuracy on the error estimate, tolerances, max
//! iterations, stagnation, divergence.

use glissade_mechanics::estimate::{ErrorEstimate, Estimated, STAGNATION_AGREEMENT};
use glissade_mechanics::local::IndicatorSums;
use glissade_messages::Verdict;

/// The stop rules of docs/method.md, "Indicators and stopping": converged when the estimated contact-traction error (relative
/// space-time L2, and the largest at one point relative to the largest traction) and the
/// disagreement between s and ŝ ([`IndicatorSums::disagreement`]) are at most the accuracy and
/// η, e_c at most their tolerances (each where set); else max iterations, stagnation, divergence.
#[derive(Debug, Clone, PartialEq)]
pub struct StopRule {
    pub accuracy: Option<f64>,
    pub tolerance: Option<f64>,
    pub contact_tolerance: Option<f64>,
    pub max_iterations: usize,
    pub stagnation_window: usize,
    pub stagnation_ratio: f64,
    /// Diverged when Σ(‖s‖² + ‖ŝ‖²) exceeds this factor times its value at iteration 1.
    pub growth_limit: f64,
    history: Vec<f64>,
    first_norm: Option<f64>,
    estimate: ErrorEstimate,
    last: Option<Estimated>,
    /// The same estimate made on the pointwise steps ([`IndicatorSums::pointwise_step`]).
    pointwise: ErrorEstimate,
    last_pointwise: Option<Estimated>,
    /// The scene's traction scale T_s ([`glissade_mechanics::scales::Scales::traction`], MPa):
    /// with every contact point of ŝ separated, s's contact forces are round-off only below the
    /// accuracy times this. 0 (unknown): never taken for round-off.
    pub traction_scale: f64,
}

impl StopRule {
    pub fn new(p: &glissade_mechanics::model::SolverParams) -> Self {
        Self {
            accuracy: p.accuracy,
            tolerance: p.tolerance,
            contact_tolerance: p.contact_tolerance,
            max_iterations: p.max_iterations,
            stagnation_window: p.stagnation_window,
            stagnation_ratio: p.stagnation_ratio,
            growth_limit: 1e12,
            history: Vec::new(),
            first_norm: None,
            estimate: ErrorEstimate::default(),
            last: None,
            pointwise: ErrorEstimate::default(),
            last_pointwise: None,
            traction_scale: 0.0,
        }
    }

    /// The rule with the scene's traction scale ([`Self::traction_scale`]).
    pub fn with_traction_scale(mut self, traction_scale: f64) -> Self {
        self.traction_scale = traction_scale;
        self
    }

    /// The error estimate of the last decided iteration, if the iteration showed a contraction.
    pub fn estimate(&self) -> Option<Estimated> {
        self.last
    }

    /// The pointwise error estimate of the last decided iteration (the largest contact-traction
    /// error at one point and time point, relative to the largest traction), if it has one.
    pub fn pointwise_estimate(&self) -> Option<Estimated> {
        self.last_pointwise
    }

    /// Verdict after the local stage of iteration `n` (0-based); `fixed_point` is the
    /// fixed-point residual ‖G(s) − s‖ of the last Anderson step (none without Anderson).
    pub fn decide(&mut self, n: u32, sums: &IndicatorSums, fixed_point: Option<f64>) -> Verdict {
        let eta = sums.eta();
        self.history.push(eta);
        let residual = match sums.contact_indicator() {
            r if r > 0.0 => r,
            _ => eta,
        };
        // Every contact point of ŝ separated: ŝ has no contact force. Where s's contact forces
        // are also below the accuracy times the scene's traction scale, they are round-off
        // (relative to nothing): their step carries no information, the tractions are zero. Where
        // s still carries forces above that (a contact the local stage has not found yet, the
        // linear stage pressing two parts together), their steps are the estimate's as anywhere.
        let separated = sums.counts[0] > 0 && sums.counts[1] + sums.counts[2] == 0;
        let negligible = sums.force_max <= self.accuracy.unwrap_or(f64::EPSILON) * self.traction_scale;
        let (step, pointwise) = if separated && negligible {
            (0.0, 0.0)
        } else {
            (sums.force_step(), sums.pointwise_step())
        };
        self.last = self.estimate.push(step, residual, fixed_point);
        self.last_pointwise = self.pointwise.push(pointwise, residual, fixed_point);
        if eta == 0.0 {
            // s = ŝ exactly: this iterate is the fixed point (e.g. a scene without load).
            self.last = Some(Estimated::EXACT);
            self.last_pointwise = Some(Estimated::EXACT);
        }
        if !eta.is_finite() || !sums.contact_indicator().is_finite() {
            return Verdict::Diverged {
                detail: format!("indicator is not finite at iteration {n} (η = {eta})"),
            };
        }
        if n == 1 {
            self.first_norm = Some(sums.eta_den);
        }
        if let Some(first) = self.first_norm {
            if first > 0.0 && sums.eta_den > self.growth_limit * first {
                return Verdict::Diverged {
                    detail: format!(
                        "the solution's norm grew {:.1e}-fold since iteration 1 (iteration {n})",
                        sums.eta_den / first
                    ),
                };
            }
        }
        // The estimate follows s's forces; s must also agree with ŝ (the interface laws) within
        // the accuracy (max(e_c, η)), or a motion that changes no force would pass unseen.
        let within = |e: Option<Estimated>, a: f64| e.is_some_and(|e| e.error <= a);
        let accurate = self
            .accuracy
            .is_none_or(|a| within(self.last, a) && within(self.last_pointwise, a) && sums.disagreement() <= a);
        let eta_ok = self.tolerance.is_none_or(|t| eta <= t);
        let contact_ok = self.contact_tolerance.is_none_or(|t| sums.contact_indicator() <= t);
        let asked = self.accuracy.is_some() || self.tolerance.is_some() || self.contact_tolerance.is_some();
        if asked && accurate && eta_ok && contact_ok {
            return Verdict::Converged;
        }
        if n as usize + 1 >= self.max_iterations {
            return Verdict::MaxIterations;
        }
        let w = self.stagnation_window;
        if let Some((recent, before)) = stagnation(&self.history, w, self.stagnation_ratio) {
            // Stagnation at a small error is convergence: s and ŝ agree within the accuracy over
            // STAGNATION_AGREEMENT (which bounds the true error within the accuracy on the
            // validation set's calibration part), the tolerances asked are met.
            if self
                .accuracy
                .is_some_and(|a| sums.disagreement() <= a / STAGNATION_AGREEMENT)
                && eta_ok
                && contact_ok
            {
                return Verdict::Converged;
            }
            let k = self.history.len();
            let mut detail = format!(
                "min η over the last {w} iterations is {recent:.3e}, not below {} × the earlier minimum {before:.3e}",
                self.stagnation_ratio
            );
            if let Some((a, b)) = period_two(&self.history[k - w..]) {
                detail.push_str(&format!(
                    "; η alternates between {a:.3e} and {b:.3e}: the iteration has a mode at −1 \
                     (an undamped cycle; lower solver.relaxation below 1)"
                ));
            }
            return Verdict::Stagnated { detail };
        }
        Verdict::Continue
    }
}

/// Whether η's history (one value per iteration, the last one the current) has stagnated: it
/// holds more than two windows of `window` iterations, and the smallest η of the last window is
/// above `ratio` times the smallest before it. `window` 0: never.
pub fn stagnated(history: &[f64], window: usize, ratio: f64) -> bool {
    stagnation(history, window, ratio).is_some()
}

/// [`stagnated`], with the two minima it compared: (the last window's, the one before it).
fn stagnation(history: &[f64], window: usize, ratio: f64) -> Option<(f64, f64)> {
    let k = history.len();
    if window == 0 || k <= 2 * window {
        return None;
    }
    let recent = history[k - window..].iter().cloned().fold(f64::INFINITY, f64::min);
    let before = history[..k - window].iter().cloned().fold(f64::INFINITY, f64::min);
    (recent > ratio * before).then_some((recent, before))
}

/// The two values η alternates between when the window is a period-2 cycle: its successive
/// differences alternate in sign throughout, and every two-step change |η_k − η_{k−2}| is below a
/// tenth of the smallest one-step change (the cycle may drift slowly, it does not converge).
fn period_two(window: &[f64]) -> Option<(f64, f64)> {
    if window.len() < 4 {
        return None;
    }
    let steps: Vec<f64> = window.windows(2).map(|p| p[1] - p[0]).collect();
    let alternating = steps.windows(2).all(|d| d[0] * d[1] < 0.0);
    let smallest_step = steps.iter().fold(f64::INFINITY, |m, d| m.min(d.abs()));
    let largest_drift = window.windows(3).fold(0.0f64, |m, p| m.max((p[2] - p[0]).abs()));
    let k = window.len();
    (alternating && largest_drift <= 0.1 * smallest_step).then_some((window[k - 2], window[k - 1]))
}
