//! Full boundary fields from a run's messages: a `BoundaryState` as it was sent, a PGD
//! subdomain's `BoundaryModes` expanded from the mode form its earlier messages built
//! ([`ModeForm`], the same expansion the interface node makes).

use faer::Mat;
use glissade_mechanics::modes::ModeForm;
use glissade_messages::{Field, Payload};
use std::borrow::Cow;
use std::collections::BTreeMap;

/// The mode forms of the PGD subdomains seen so far.
#[derive(Default)]
pub struct BoundaryStates {
    forms: BTreeMap<u32, ModeForm>,
}

/// A subdomain's boundary state: (subdomain, W, F), each n_b × (N+1).
pub type State<'a> = (u32, Cow<'a, Field>, Cow<'a, Field>);

impl BoundaryStates {
    pub fn new() -> Self {
        Self::default()
    }

    /// The subdomain and full (W, F) of a boundary-state message, None for other payloads, or why
    /// a mode-form message cannot be expanded (no particular part before it, sizes that do not fit
    /// the held modes). Messages must come in the order the subdomain sent them.
    pub fn fields<'a>(&mut self, payload: &'a Payload) -> Option<Result<State<'a>, String>> {
        match payload {
            Payload::BoundaryState { subdomain, w, f } => Some(Ok((*subdomain, Cow::Borrowed(w), Cow::Borrowed(f)))),
            Payload::BoundaryModes {
                subdomain,
                particular,
                first_mode,
                z,
                g,
                lambda,
            } => Some(self.expand(*subdomain, particular.as_ref(), *first_mode as usize, z, g, lambda)),
            _ => None,
        }
    }

    fn expand<'a>(
        &mut self,
        s: u32,
        particular: Option<&glissade_messages::ParticularModes>,
        first: usize,
        z: &Field,
        g: &Field,
        lambda: &Field,
    ) -> Result<State<'a>, String> {
        let at = |e: String| format!("boundary modes of subdomain {s}: {e}");
        if let Some(pm) = particular {
            let form = ModeForm::new(
                pm.w.rows(),
                pm.time.cols(),
                pm.time.rows(),
                &pm.w.data,
                &pm.f.data,
                &pm.time.data,
            )
            .map_err(|e| at(e.to_string()))?;
            self.forms.insert(s, form);
        }
        let form = self
            .forms
            .get_mut(&s)
            .ok_or_else(|| at("mode form before its particular part".into()))?;
        if z.rows() != form.n_boundary() || lambda.cols() != form.n_times() {
            return Err(at(format!(
                "modes of {} entries and time functions of {} time points, expected {} and {}",
                z.rows(),
                lambda.cols(),
                form.n_boundary(),
                form.n_times()
            )));
        }
        form.update(first, &z.data, &g.data, &lambda.data)
            .map_err(|e| at(e.to_string()))?;
        let (n_b, nt) = (form.n_boundary(), form.n_times());
        let (mut w, mut f) = (Mat::zeros(n_b, nt), Mat::zeros(n_b, nt));
        form.expand_into(w.as_mut(), f.as_mut());
        let field = |m: &Mat<f64>| Field::from_fn(n_b, nt, |r, c| m[(r, c)]);
        Ok((s, Cow::Owned(field(&w)), Cow::Owned(field(&f))))
    }
}
