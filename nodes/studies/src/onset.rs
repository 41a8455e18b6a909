//! The load at which a joint slips (`glissade onset`, docs/studies.md): the smallest factor on a
//! boundary rule's values at which a contact interface first slips at a point, and the one at
//! which one slips everywhere (beyond which a part held by friction has no equilibrium), each
//! bracketed by solves to a relative width the user asks. Each trial starts from the last trial
//! that held (converged without slipping everywhere), with the operators reused.
//!
//! A trial is classified by its reported statuses on the interfaces watched (`slip` only counts
//! as slipping: a pair at the friction `limit` does not move beyond the margin, and a pair whose
//! friction capacity f·N is within the margin is `limit` whatever it carries; `grazing` counts as
//! open): it
//! slips at a
//! point if some pair slips at some time point; it slips everywhere if at some time point one
//! interface's whole length slips, or if it did not converge: a part that would slide or spin
//! away has no equilibrium, and the run then stops on that diagnosis (or, where the excess of
//! tangential force is too small to be seen, stalls with every pair slipping); its verdict is
//! kept in the trial's row.

use crate::driver::{Solved, Solver};
use crate::quantities::{index_of, quantities};
use crate::study::{Design, Parameter, Study, Target};
use crate::variants::Variant;
use crate::StudyError;
use glissade_messages::{InterfaceSolution, Verdict};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// What `glissade onset` is asked.
#[derive(Debug, Clone, PartialEq)]
pub struct OnsetRequest {
    /// The boundary rule whose values are scaled (index in file order).
    pub rule: usize,
    /// The interfaces watched (model indices, as `glissade check` lists them); empty: every
    /// contact interface.
    pub interfaces: Vec<usize>,
    /// Stop when (above − below) ≤ bracket · above for both thresholds.
    pub bracket: f64,
    /// The scale factors tried first, from which the brackets grow (×2 / ÷2) until found.
    pub start: f64,
    /// Every trial's accuracy, when set.
    pub accuracy: Option<f64>,
}

/// Most trials one search makes.
pub const MAX_TRIALS: usize = 60;

/// How far from `--start` a bracket may grow (×2 / ÷2 steps): 2²⁰ ≈ 10⁶ either way.
pub const MAX_REACH: f64 = 1_048_576.0;

/// One trial: a scale factor solved.
#[derive(Debug, Clone, Serialize)]
pub struct Trial {
    pub scale: f64,
    /// The trial it started from (None: ŝ = 0).
    pub started_from: Option<usize>,
    pub verdict: String,
    pub converged: bool,
    pub iterations: usize,
    pub seconds: f64,
    /// The first time point (s) at which a watched pair slips, if any.
    pub first_slip_at: Option<f64>,
    /// The first time point (s) at which a watched interface slips over its whole closed length
    /// (every pair not separated slips).
    pub full_slip_at: Option<f64>,
    /// The largest slip share of a watched interface's closed length over the time points.
    pub max_slip_share: f64,
}

impl Trial {
    fn slips_somewhere(&self) -> bool {
        self.first_slip_at.is_some() || !self.converged
    }

    fn slips_everywhere(&self) -> bool {
        self.full_slip_at.is_some() || !self.converged
    }
}

/// A threshold's bracket: the largest scale that held and the smallest that did not.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct Bracket {
    pub below: Option<f64>,
    pub above: Option<f64>,
}

impl Bracket {
    fn update(&mut self, scale: f64, over: bool) {
        if over {
            self.above = Some(self.above.map_or(scale, |a| a.min(scale)));
        } else {
            self.below = Some(self.below.map_or(scale, |b| b.max(scale)));
        }
    }

    /// Found to `width` (relative to the upper end).
    pub fn found(&self, width: f64) -> bool {
        matches!((self.below, self.above), (Some(b), Some(a)) if b < a && a - b <= width * a.abs())
    }

    /// Whether a factor that held lies above one that did not: trials near the threshold whose
    /// statuses disagree with their order (each is only as good as its accuracy).
    pub fn inverted(&self) -> bool {
        matches!((self.below, self.above), (Some(b), Some(a)) if b >= a)
    }

    /// The next scale to try: the middle of the bracket, or beyond its one end (×2 / ÷2).
    fn next(&self) -> f64 {
        match (self.below, self.above) {
            (Some(b), Some(a)) => 0.5 * (a + b),
            (Some(b), None) => 2.0 * b,
            (None, Some(a)) => 0.5 * a,
            (None, None) => 1.0,
        }
    }

    /// The middle of the bracket, when both ends are known.
    pub fn estimate(&self) -> Option<f64> {
        Some(0.5 * (self.below? + self.above?))
    }
}

/// The outcome of a search.
#[derive(Debug, Clone, Serialize)]
pub struct Onset {
    pub rule: String,
    pub interfaces: Vec<usize>,
    pub bracket: f64,
    /// The first slip at a point.
    pub first_slip: Bracket,
    /// Slip over a whole interface (no equilibrium beyond it where a part is held by friction).
    pub full_slip: Bracket,
    pub trials: Vec<Trial>,
    pub seconds: f64,
    /// Why the search stopped short of the bracket, if it did.
    pub unfinished: Option<String>,
    /// Why the first-slip bracket was given up while the full-slip one was searched (a pair slips
    /// at every factor tried down to `--start` / 2²⁰), if it was.
    pub first_slip_unbracketed: Option<String>,
}

/// Searches both thresholds of boundary rule `req.rule` of the scene `scene_text` (read from
/// `scene`), solving each trial with `solver`. `on_trial` sees each trial as it ends.
pub fn onset(
    scene: &Path,
    scene_text: &str,
    req: &OnsetRequest,
    solver: &mut impl Solver,
    mut on_trial: impl FnMut(&Trial),
) -> Result<Onset, StudyError> {
    let t0 = Instant::now();
    let name = format!("boundary[{}].scale", req.rule);
    let study = Study {
        name: scene
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("onset")
            .to_string(),
        scene: scene.to_path_buf(),
        parameters: vec![Parameter {
            name: name.clone(),
            target: Target::Scale { rule: req.rule },
            values: Vec::new(),
        }],
        design: Design::Grid,
        accuracy: req.accuracy,
        report: Vec::new(),
    };
    if !(req.bracket > 0.0 && req.bracket < 1.0) {
        return Err(StudyError::new(
            "--bracket",
            format!("{} is not in (0, 1)", req.bracket),
        ));
    }
    if !(req.start > 0.0 && req.start.is_finite()) {
        return Err(StudyError::new(
            "--start",
            format!("{} is not a positive factor", req.start),
        ));
    }
    let file = scene.display().to_string();
    let share = |q: &str| index_of(q).expect("a share is a quantity");
    let [slip, open, grazing] = ["slip_share", "separated_share", "grazing_share"].map(share);
    let mut out = Onset {
        rule: format!("boundary[{}]", req.rule),
        interfaces: req.interfaces.clone(),
        bracket: req.bracket,
        first_slip: Bracket::default(),
        full_slip: Bracket::default(),
        trials: Vec::new(),
        seconds: 0.0,
        unfinished: None,
        first_slip_unbracketed: None,
    };
    // The state of the last trial that held, and its index.
    let mut held: Option<(usize, Vec<InterfaceSolution>)> = None;
    let mut scale = req.start;
    loop {
        let k = out.trials.len();
        let variant = Variant {
            index: k,
            values: vec![scale],
        };
        let built = crate::patch::variant_scene(&study, scene_text, &variant)?
            .map_err(|e| StudyError::new(format!("{name} = {scale}"), e.to_string()))?;
        let model = &built.model;
        let watched: Vec<usize> = if req.interfaces.is_empty() {
            (0..model.interfaces.len())
                .filter(|&i| model.interfaces[i].is_contact())
                .collect()
        } else {
            req.interfaces.clone()
        };
        if let Some(&bad) = watched
            .iter()
            .find(|&&i| model.interfaces.get(i).is_none_or(|itf| !itf.is_contact()))
        {
            return Err(StudyError::new(
                "--interface",
                format!("{bad} is not a contact interface of the scene (`glissade check` lists them)"),
            ));
        }
        if watched.is_empty() {
            return Err(StudyError::new(&file, "the scene has no contact interface to slip"));
        }
        out.interfaces = watched.clone();
        let t = Instant::now();
        let start = held.as_ref().map(|(_, s)| s.as_slice());
        let solved: Solved = solver
            .solve(&variant, &built, start, false)
            .map_err(|e| StudyError::new(format!("{name} = {scale}"), e))?;
        let q = quantities(model, &solved.interfaces).map_err(|e| StudyError::new(format!("{name} = {scale}"), e))?;
        let nt = model.time.n_points();
        // Per time point, the largest share of a watched interface's closed length (its pairs not
        // separated) that slips: 1 is the whole contact slipping, even where part of it is open.
        let shares: Vec<f64> = (0..nt)
            .map(|i| {
                q.iter()
                    .filter(|iq| watched.contains(&iq.interface))
                    .map(|iq| {
                        let v = |q: usize| iq.values[q][i];
                        // Slipping (beyond the margins); closed: neither open nor grazing.
                        crate::quantities::closed_slip_share(v(slip), v(open) + v(grazing))
                    })
                    .fold(0.0, f64::max)
            })
            .collect();
        let converged = solved.verdict == Verdict::Converged;
        let trial = Trial {
            scale,
            started_from: held.as_ref().map(|(i, _)| *i),
            verdict: solved.verdict_text.clone(),
            converged,
            iterations: solved.iterations,
            seconds: t.elapsed().as_secs_f64(),
            first_slip_at: shares.iter().position(|&s| s > 1e-12).map(|i| model.time.t(i)),
            full_slip_at: shares.iter().position(|&s| s >= 1.0 - 1e-9).map(|i| model.time.t(i)),
            max_slip_share: shares.iter().copied().fold(0.0, f64::max),
        };
        out.first_slip.update(scale, trial.slips_somewhere());
        out.full_slip.update(scale, trial.slips_everywhere());
        if converged && !trial.slips_everywhere() {
            if let Some(state) = solved.state {
                held = Some((k, state));
            }
        }
        on_trial(&trial);
        out.trials.push(trial);
        for (name, b) in [
            ("first slip", &out.first_slip),
            ("slip over a whole interface", &out.full_slip),
        ] {
            if b.inverted() {
                out.unfinished = Some(format!(
                    "inconsistent trials for {name}: factor {} held and {} did not; the statuses near the \
                     threshold are only as good as each trial's accuracy (ask a smaller `--accuracy`)",
                    b.below.unwrap_or(f64::NAN),
                    b.above.unwrap_or(f64::NAN)
                ));
            }
        }
        if out.unfinished.is_some() {
            break;
        }
        let first_done = out.first_slip.found(req.bracket) || out.first_slip_unbracketed.is_some();
        if first_done && out.full_slip.found(req.bracket) {
            break;
        }
        if out.trials.len() >= MAX_TRIALS {
            out.unfinished = Some(format!("{MAX_TRIALS} trials without bracketing both thresholds"));
            break;
        }
        let reach = |f: f64| f.is_finite() && f >= req.start / MAX_REACH && f <= req.start * MAX_REACH;
        // The first-slip bracket first (it lies below the other), then the full-slip one.
        let mut next = if first_done {
            out.full_slip.next()
        } else {
            out.first_slip.next()
        };
        if !first_done && !reach(next) {
            // A pair slips at every factor tried (or none does): give that bracket up, go on with
            // the whole-interface one.
            out.first_slip_unbracketed = Some(format!(
                "the interface {} at every factor tried, {} to {}",
                if out.first_slip.above.is_some() {
                    "slips at a point"
                } else {
                    "never slips"
                },
                req.start / MAX_REACH,
                req.start * MAX_REACH
            ));
            next = out.full_slip.next();
        }
        if !reach(next) {
            out.unfinished = Some(format!(
                "the next factor ({next}) is beyond 2^20 times --start: no interface slips over its whole length \
                 within the factors tried"
            ));
            break;
        }
        scale = next;
    }
    out.seconds = t0.elapsed().as_secs_f64();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bracket_grows_until_it_holds_the_threshold_then_halves() {
        let mut b = Bracket::default();
        assert_eq!(b.next(), 1.0);
        b.update(1.0, false);
        assert_eq!(b.next(), 2.0);
        b.update(2.0, false);
        b.update(4.0, true);
        assert_eq!((b.below, b.above), (Some(2.0), Some(4.0)));
        assert_eq!(b.next(), 3.0);
        assert!(!b.found(0.1));
        b.update(3.9, true);
        b.update(3.8, false);
        assert!(b.found(0.03) && !b.found(0.02));
        let mut d = Bracket::default();
        d.update(1.0, true);
        assert_eq!(d.next(), 0.5);
        // A factor that held above one that did not is never a found bracket.
        let mut e = Bracket::default();
        e.update(1.30, true);
        e.update(1.31, false);
        assert!(e.inverted() && !e.found(0.5));
    }
}
