//! The estimate of the contact-traction error that the run computes as it goes (DESIGN §3,
//! "Stopping on an error estimate").
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
//! Estimate: êₙ = maxₖ₌ₙ₋ₘ₊₁…ₙ dₖ / (1 − ρ̂). It exists once the rate window is full and the fit
//! contracts (ρ̂ < 1); before that the run has no estimate and cannot stop on accuracy. The
//! windows were chosen on the shipped scenes against the monolithic reference (docs/accuracy.md):
//! shorter ones stopped the layered scene early with up to 2.6× the requested error.

/// Iterations in the contraction fit.
pub const RATE_WINDOW: usize = 20;
/// Iterations whose largest step enters the bound.
pub const STEP_WINDOW: usize = 10;

/// The estimate's state: the steps and residuals of the last iterations (as many as the larger
/// window), and how many iterations it has seen.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorEstimate {
    pub rate_window: usize,
    pub step_window: usize,
    steps: Vec<f64>,
    residuals: Vec<f64>,
    seen: usize,
}

/// One iteration's estimate and what it is made of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimated {
    /// The contraction ρ̂ fitted over the rate window.
    pub rate: f64,
    /// The estimated relative contact-traction error of this iteration's s.
    pub error: f64,
}

impl Default for ErrorEstimate {
    fn default() -> Self {
        Self::new(RATE_WINDOW, STEP_WINDOW)
    }
}

impl ErrorEstimate {
    pub fn new(rate_window: usize, step_window: usize) -> Self {
        assert!(
            rate_window >= 2 && step_window >= 1,
            "a contraction fit needs two points"
        );
        let kept = rate_window.max(step_window);
        Self {
            rate_window,
            step_window,
            steps: Vec::with_capacity(kept + 1),
            residuals: Vec::with_capacity(kept + 1),
            seen: 0,
        }
    }

    /// Takes the next iteration's force step dₙ and residual rₙ; returns its estimate when there
    /// is one.
    pub fn push(&mut self, step: f64, residual: f64) -> Option<Estimated> {
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
            return None;
        }
        let n = self.steps.len();
        let largest = self.steps[n - self.step_window..].iter().cloned().fold(0.0, f64::max);
        if largest == 0.0 {
            // The forces stopped moving exactly (or there are none): nothing is left to go.
            return Some(Estimated { rate: 0.0, error: 0.0 });
        }
        let recent = &self.residuals[n - self.rate_window..];
        if recent.iter().any(|&r| r <= 0.0 || !r.is_finite()) || !largest.is_finite() {
            return None;
        }
        let w = self.rate_window as f64;
        let x_mean = (w - 1.0) / 2.0;
        let y_mean = recent.iter().map(|r| r.ln()).sum::<f64>() / w;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for (k, r) in recent.iter().enumerate() {
            let dx = k as f64 - x_mean;
            sxy += dx * (r.ln() - y_mean);
            sxx += dx * dx;
        }
        let rate = (sxy / sxx).exp();
        (rate < 1.0).then(|| Estimated {
            rate,
            error: largest / (1.0 - rate),
        })
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
            last = e.push(step, rho.powi(n)).map(|est| (n, est));
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
            assert_eq!(e.push(0.5f64.powi(n), 0.5f64.powi(n)), None, "window not full at {n}");
        }
        assert!(e.push(1.0 / 16.0, 1.0 / 16.0).is_some());
        let mut growing = ErrorEstimate::new(4, 2);
        for n in 0..10 {
            assert_eq!(growing.push(0.1, 1.1f64.powi(n)), None);
        }
    }

    /// A step far above the trend (an Anderson restart) raises the estimate at once and holds it
    /// for the step window.
    #[test]
    fn a_large_step_is_not_hidden() {
        let mut e = ErrorEstimate::new(5, 3);
        for n in 0..10 {
            e.push(0.5f64.powi(n), 0.5f64.powi(n));
        }
        let calm = e.push(0.5f64.powi(10), 0.5f64.powi(10)).expect("estimate").error;
        // The calm estimate rests on the window's largest step 2⁻⁸; the jump's step is 2⁻³.
        let jump = e.push(0.5f64.powi(3), 0.5f64.powi(11)).expect("estimate").error;
        assert!(jump > 31.9 * calm, "{jump} vs {calm}");
        let held = e.push(0.5f64.powi(12), 0.5f64.powi(12)).expect("estimate").error;
        // Same step, the rate refitted on one more residual of the same slope.
        assert!(
            (held / jump - 1.0).abs() < 1e-12,
            "the large step is still in the window: {held} vs {jump}"
        );
    }
}
