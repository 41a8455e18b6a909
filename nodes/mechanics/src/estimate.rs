//! The estimate of the contact-traction error that the run computes as it goes (docs/accuracy.md,
//! "Stopping on accuracy").
//!
//! The LATIN iteration is a fixed point sₙ₊₁ = G(sₙ). If it contracts with factor ρ < 1, the
//! distance to the limit s* is bounded by the steps: ‖sₙ − s*‖ ≤ ‖sₙ₊₁ − sₙ‖/(1 − ρ). Neither ρ
//! nor the next step is known; both are read from the iterations so far:
//! - the steps dₖ = ‖Fₖ − Fₖ₋₁‖ / ‖Fₖ‖ of the contact forces
//!   ([`IndicatorSums::force_step`](crate::local::IndicatorSums::force_step)), space-time,
//!   M-weighted, on contact interfaces;
//! - ρ̂ from a least-squares fit of log rₖ against k over the last [`RATE_WINDOW`] iterations,
//!   rₖ the contact indicator e_c (η in a scene without contact): the LATIN residual, smoother
//!   than the steps under Anderson mixing, whose steps are not monotone;
//! - the step entering the bound is the largest of the last [`STEP_WINDOW`] steps, not the last
//!   one: an Anderson step can be far below the distance still to go.
//!
//! The bound: b̂ₙ = maxₖ₌ₙ₋ₘ₊₁…ₙ dₖ / (1 − ρ̂). It exists once the rate window is full and the fit
//! contracts (ρ̂ < 1); before that the run has no estimate and cannot stop on accuracy. The
//! windows were chosen on the shipped scenes against the monolithic reference (docs/accuracy.md):
//! shorter ones stopped the layered scene early with up to 2.6× the requested error.
//!
//! The bound is safe but loose (the window's largest step is ρ⁻⁽ᵐ⁻¹⁾ times the last one on a
//! geometric sequence). With Anderson acceleration the run also has the fixed-point residual
//! ‖G(sₖ) − sₖ‖ of every iteration (the sum of the subdomains' `residual2` partials), which falls
//! as smoothly as the distance to the limit does but at a level that differs from scene to scene.
//! Its level is calibrated against the steps' trend: with tₖ = d̃ₖ / (1 − ρ̂), d̃ₖ the value at k
//! of a least-squares fit of log d over the step window, the **calibrated estimate** is
//!
//!   êₙ = c · ‖rₙ‖ · exp(mean over the last [`CALIBRATION_WINDOW`] iterations of log(tₖ / ‖rₖ‖)),
//!
//! c = [`CALIBRATION_FACTOR`], used once [`CALIBRATION_MIN`] iterations of that window have both
//! values and while the fit contracts; before, and without Anderson, the estimate is the bound.
//! Where the contraction is slow (ρ̂ > [`SLOW_CONTRACTION`]) the estimate is the larger of the two.
//! The constants were chosen on the iterations of every shipped scene and stability case against
//! the reference; docs/accuracy.md has how they were chosen and where the estimate stops early.

/// A run that stagnates with s and ŝ agreeing within the accuracy divided by this factor
/// (max(e_c, η) ≤ accuracy / 30) is "Converged" at stagnation: its estimate no longer contracts,
/// but on every scene of the validation set's calibration part that stagnated, the true
/// contact-traction error at the stagnation was at most 27 times max(e_c, η) (docs/accuracy.md,
/// "Stagnation at a small error").
pub const STAGNATION_AGREEMENT: f64 = 30.0;

/// Iterations in the contraction fit.
pub const RATE_WINDOW: usize = 20;
/// Iterations whose largest step enters the bound.
pub const STEP_WINDOW: usize = 10;
/// Iterations over which the fixed-point residual's level is calibrated against the steps' trend.
pub const CALIBRATION_WINDOW: usize = 25;
/// Iterations of the calibration window that must have both values before the calibration is
/// used.
pub const CALIBRATION_MIN: usize = 18;
/// Factor c of the calibrated estimate.
pub const CALIBRATION_FACTOR: f64 = 2.5;
/// Above this contraction the estimate is at least the bound: 1/(1 − ρ̂) is then too sensitive to
/// ρ̂ for a calibration over past iterations to hold.
pub const SLOW_CONTRACTION: f64 = 0.97;

/// The estimate's state: the steps and residuals of the last iterations (as many as the larger
/// window), the calibration's log-ratios of the last [`CALIBRATION_WINDOW`] iterations, and how
/// many iterations it has seen.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorEstimate {
    pub rate_window: usize,
    pub step_window: usize,
    steps: Vec<f64>,
    residuals: Vec<f64>,
    /// log(tₖ / ‖rₖ‖) where both exist, oldest first.
    ratios: Vec<Option<f64>>,
    seen: usize,
}

/// One iteration's estimate and what it is made of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimated {
    /// The contraction ρ̂ fitted over the rate window.
    pub rate: f64,
    /// The estimated relative contact-traction error of this iteration's s.
    pub error: f64,
    /// Whether `error` is the calibrated estimate (else the bound).
    pub calibrated: bool,
}

impl Estimated {
    /// The exact estimate of an iterate that is the fixed point, or whose contact forces stopped
    /// moving.
    pub const EXACT: Estimated = Estimated {
        rate: 0.0,
        error: 0.0,
        calibrated: false,
    };
}

impl Default for ErrorEstimate {
    fn default() -> Self {
        Self::new(RATE_WINDOW, STEP_WINDOW)
    }
}

/// A least-squares fit of log v against the index: the fitted value at the last index and
/// exp(slope), the factor per index.
fn log_linear_fit(values: &[f64]) -> (f64, f64) {
    let w = values.len() as f64;
    let x_mean = (w - 1.0) / 2.0;
    let y_mean = values.iter().map(|v| v.ln()).sum::<f64>() / w;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, v) in values.iter().enumerate() {
        let dx = k as f64 - x_mean;
        sxy += dx * (v.ln() - y_mean);
        sxx += dx * dx;
    }
    let slope = sxy / sxx;
    ((y_mean + slope * (w - 1.0 - x_mean)).exp(), slope.exp())
}

impl ErrorEstimate {
    /// The bound over these windows, calibrated over [`CALIBRATION_WINDOW`] iterations.
    pub fn new(rate_window: usize, step_window: usize) -> Self {
        assert!(rate_window >= 2 && step_window >= 2, "a fit needs two points");
        let kept = rate_window.max(step_window);
        Self {
            rate_window,
            step_window,
            steps: Vec::with_capacity(kept + 1),
            residuals: Vec::with_capacity(kept + 1),
            ratios: Vec::with_capacity(CALIBRATION_WINDOW + 1),
            seen: 0,
        }
    }

    /// Takes the next iteration's force step dₙ, residual rₙ and, with Anderson acceleration, the
    /// fixed-point residual ‖G(s) − s‖ of the last iterate mixed before this one; returns its
    /// estimate when there is one.
    pub fn push(&mut self, step: f64, residual: f64, fixed_point: Option<f64>) -> Option<Estimated> {
        let fixed_point = fixed_point.filter(|r| *r > 0.0 && r.is_finite());
        let (estimate, ratio) = self.bound(step, residual, fixed_point);
        self.ratios.push(ratio);
        if self.ratios.len() > CALIBRATION_WINDOW {
            self.ratios.remove(0);
        }
        let estimate = estimate?;
        let (known, sum) = self.ratios.iter().flatten().fold((0, 0.0), |(n, s), l| (n + 1, s + l));
        match fixed_point {
            Some(r) if estimate.error > 0.0 && known >= CALIBRATION_MIN => {
                let calibrated = CALIBRATION_FACTOR * r * (sum / known as f64).exp();
                if estimate.rate > SLOW_CONTRACTION && calibrated < estimate.error {
                    return Some(estimate);
                }
                Some(Estimated {
                    rate: estimate.rate,
                    error: calibrated,
                    calibrated: true,
                })
            }
            _ => Some(estimate),
        }
    }

    /// The bound of this iteration, and log(tₙ / ‖rₙ‖) for the calibration where both exist
    /// (`fixed_point` positive and finite, or none).
    fn bound(&mut self, step: f64, residual: f64, fixed_point: Option<f64>) -> (Option<Estimated>, Option<f64>) {
        let kept = self.rate_window.max(self.step_window);
        self.steps.push(step);
        self.residuals.push(residual);
        if self.steps.len() > kept {
            self.steps.remove(0);
            self.residuals.remove(0);
        }
        self.seen += 1;
        // The first step is from s = 0: it measures the solution's size, not a step.
        if self.seen < kept + 1 {
            return (None, None);
        }
        let n = self.steps.len();
        let window = &self.steps[n - self.step_window..];
        let largest = window.iter().cloned().fold(0.0, f64::max);
        if largest == 0.0 {
            // The forces stopped moving exactly (or there are none): nothing is left to go.
            return (Some(Estimated::EXACT), None);
        }
        let recent = &self.residuals[n - self.rate_window..];
        if recent.iter().any(|&r| r <= 0.0 || !r.is_finite()) || !largest.is_finite() {
            return (None, None);
        }
        let (_, rate) = log_linear_fit(recent);
        if rate >= 1.0 {
            return (None, None);
        }
        // The steps' trend: the fitted step at this iteration (the largest where a step is 0).
        let trend = if window.iter().all(|&d| d > 0.0) {
            log_linear_fit(window).0
        } else {
            largest
        } / (1.0 - rate);
        let ratio = fixed_point.map(|r| (trend / r).ln()).filter(|l| l.is_finite());
        let bound = Estimated {
            rate,
            error: largest / (1.0 - rate),
            calibrated: false,
        };
        (Some(bound), ratio)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On an exactly geometric sequence sₙ = s* + ρⁿ (residual and steps both ∝ ρⁿ) the fit
    /// recovers ρ to rounding, and the estimate is the bound with the largest step of the window:
    /// ρ⁻⁽ᵐ⁻¹⁾ · ρⁿ⁻¹(1 − ρ)/(1 − ρ) = ρ^(n−m), above the true distance ρⁿ by ρ⁻ᵐ.
    #[test]
    fn geometric_steps_give_the_bound() {
        let rho: f64 = 0.9;
        let (w, m) = (6, 3);
        let mut e = ErrorEstimate::new(w, m);
        let mut last = None;
        for n in 0..40 {
            let step = if n == 0 { 1.0 } else { rho.powi(n - 1) * (1.0 - rho) };
            last = e.push(step, rho.powi(n), None).map(|est| (n, est));
        }
        let (n, est) = last.expect("an estimate once the windows are full");
        assert!((est.rate - rho).abs() < 1e-12, "{}", est.rate);
        let distance = rho.powi(n);
        assert!(est.error >= distance, "a bound: {} < {distance}", est.error);
        assert!(
            (est.error / (distance * rho.powi(-(m as i32))) - 1.0).abs() < 1e-10,
            "{}",
            est.error
        );
    }

    /// No estimate before the windows are full, nor when the residual grows.
    #[test]
    fn no_estimate_without_contraction() {
        let mut e = ErrorEstimate::new(4, 2);
        for n in 0..4 {
            assert_eq!(
                e.push(0.5f64.powi(n), 0.5f64.powi(n), None),
                None,
                "window not full at {n}"
            );
        }
        assert!(e.push(1.0 / 16.0, 1.0 / 16.0, None).is_some());
        let mut growing = ErrorEstimate::new(4, 2);
        for n in 0..10 {
            assert_eq!(growing.push(0.1, 1.1f64.powi(n), None), None);
        }
    }

    /// A step far above the trend (an Anderson restart) raises the estimate at once and holds it
    /// for the step window.
    #[test]
    fn a_large_step_is_not_hidden() {
        let mut e = ErrorEstimate::new(5, 3);
        for n in 0..10 {
            e.push(0.5f64.powi(n), 0.5f64.powi(n), None);
        }
        let calm = e.push(0.5f64.powi(10), 0.5f64.powi(10), None).expect("estimate").error;
        // The calm estimate rests on the window's largest step 2⁻⁸; the jump's step is 2⁻³.
        let jump = e.push(0.5f64.powi(3), 0.5f64.powi(11), None).expect("estimate").error;
        assert!(jump > 31.9 * calm, "{jump} vs {calm}");
        let held = e.push(0.5f64.powi(12), 0.5f64.powi(12), None).expect("estimate").error;
        // Same step, the rate refitted on one more residual of the same slope.
        assert!(
            (held / jump - 1.0).abs() < 1e-12,
            "the large step is still in the window: {held} vs {jump}"
        );
    }

    /// On a geometric sequence whose fixed-point residual is K ρⁿ, the steps' trend over the
    /// window is the last step itself, ρⁿ⁻¹(1 − ρ)/(1 − ρ) = ρⁿ⁻¹, and log(trend / residual) is the
    /// same every iteration: the calibrated estimate is c ρⁿ⁻¹ whatever K, once
    /// [`CALIBRATION_MIN`] iterations of the window have both values, and the bound before that.
    #[test]
    fn the_calibrated_estimate_is_c_times_the_trend_on_a_geometric_sequence() {
        let rho: f64 = 0.9;
        let (w, m) = (6, 3);
        for k in [1e-3, 1.0, 1e4] {
            let mut e = ErrorEstimate::new(w, m);
            let mut first_calibrated = None;
            for n in 0..60 {
                let step = if n == 0 { 1.0 } else { rho.powi(n - 1) * (1.0 - rho) };
                let Some(est) = e.push(step, rho.powi(n), Some(k * rho.powi(n))) else {
                    continue;
                };
                if est.calibrated {
                    first_calibrated.get_or_insert(n);
                    let want = CALIBRATION_FACTOR * rho.powi(n - 1);
                    assert!(
                        (est.error / want - 1.0).abs() < 1e-9,
                        "n = {n}, K = {k}: {} vs {want}",
                        est.error
                    );
                } else {
                    // The bound, with the largest step of the window: ρ^(n−m).
                    assert!((est.error / rho.powi(n - m as i32) - 1.0).abs() < 1e-9, "n = {n}");
                }
            }
            // Estimates from n = w on; the 18th of them calibrates, at n = w + 17.
            assert_eq!(first_calibrated, Some(w as i32 + CALIBRATION_MIN as i32 - 1), "K = {k}");
        }
    }

    /// The calibrated estimate follows the smooth residual where the steps are noisy (an Anderson
    /// step can be far below the distance still to go): with every other step 20× too small, the
    /// bound jumps with the window's largest step and the trend's fit, the calibrated estimate
    /// falls by the residual's ρ every iteration, to within the log-mean's drift as the window
    /// slides (±½ log 20 / 25 in log, 6 %). Without the residual (no Anderson) it is the bound.
    #[test]
    fn the_calibrated_estimate_follows_the_residual_through_noisy_steps() {
        let rho: f64 = 0.9;
        let mut e = ErrorEstimate::default();
        let mut plain = ErrorEstimate::default();
        let mut last: Option<f64> = None;
        let mut checked = 0;
        for n in 0..120 {
            let noise = if n % 2 == 0 { 1.0 } else { 0.05 };
            let step = rho.powi(n) * noise;
            let est = e.push(step, rho.powi(n), Some(3.0 * rho.powi(n)));
            let bound = plain.push(step, rho.powi(n), None);
            if let (Some(est), Some(bound)) = (est, bound) {
                assert!(!bound.calibrated);
                if est.calibrated {
                    if let Some(prev) = last {
                        let ratio = est.error / prev;
                        assert!((ratio / rho - 1.0).abs() < 0.07, "n = {n}: {ratio}");
                        checked += 1;
                    }
                    last = Some(est.error);
                } else {
                    assert_eq!(est, bound, "n = {n}: the bound until the calibration has enough");
                }
            }
        }
        assert!(checked > 60, "{checked}");
        // A missing residual falls back to the bound for that iteration.
        let step = rho.powi(120);
        let bound = plain.push(step, rho.powi(120), None).expect("bound");
        assert_eq!(e.push(step, rho.powi(120), None), Some(bound));
    }

    /// Where the contraction is slow the estimate is at least the bound. On a geometric sequence
    /// whose residual drops 10× at the last iteration (the calibration, a mean over the window,
    /// still holds the old level), the calibrated value is c · 0.1 · 10^(1/25) ρⁿ⁻¹ ≈ 0.27 ρⁿ⁻¹,
    /// below the bound ρ^(n−m) = ρ^(1−m) ρⁿ⁻¹: at ρ = 0.98 (slow) the estimate is the bound; at
    /// ρ = 0.9 it stays the calibrated value.
    #[test]
    fn a_slow_contraction_keeps_the_bound_as_a_floor() {
        for (rho, slow) in [(0.98f64, true), (0.9, false)] {
            let mut e = ErrorEstimate::default();
            let mut last = None;
            let end = 80;
            for n in 0..=end {
                let step = if n == 0 { 1.0 } else { rho.powi(n - 1) * (1.0 - rho) };
                let level = if n < end { 1.0 } else { 0.1 };
                last = e.push(step, rho.powi(n), Some(level * rho.powi(n)));
            }
            let est = last.expect("an estimate");
            assert_eq!(est.rate > SLOW_CONTRACTION, slow, "{}", est.rate);
            let bound = rho.powi(end - STEP_WINDOW as i32);
            let calibrated = CALIBRATION_FACTOR * 0.1 * 10f64.powf(1.0 / CALIBRATION_WINDOW as f64) * rho.powi(end - 1);
            assert!(
                calibrated < bound,
                "the case needs the calibrated value below the bound"
            );
            let want = if slow { bound } else { calibrated };
            assert_eq!(est.calibrated, !slow, "ρ = {rho}");
            assert!(
                (est.error / want - 1.0).abs() < 1e-9,
                "ρ = {rho}: {} vs {want}",
                est.error
            );
        }
    }
}
