//! The recording walk: two passes over a recording, the final state first (colour range,
//! amplification, time point), then every message through a [`View`].

use crate::draw::{diagonal, largest_time_point, nodal_field, range_of};
use crate::recovery::{final_displacements, Recovery};
use crate::{BoundaryStates, ReplayError, ReplayOptions, ReplaySummary, View};
use glissade_messages::Payload;
use glissade_recorder::Recording;
use glissade_scene::load_str;
use std::collections::BTreeMap;

/// Replays `recording` into the sink of `opts`: the colour range and amplification come from the
/// final state, then every message goes through a [`View`].
pub fn replay(recording: &Recording, opts: &ReplayOptions) -> Result<ReplaySummary, ReplayError> {
    let path = recording.path().display().to_string();
    let content = |detail: String| ReplayError::Content {
        path: path.clone(),
        detail,
    };
    let text = recording
        .scene_text()
        .ok_or_else(|| content("the recording holds no scene (attachment scene.toml)".into()))?;
    let origin = format!("{path} (scene.toml)");
    let model = load_str(text, &origin).map_err(|e| content(e.to_string()))?.model;
    let decode = |m: &glissade_recorder::RecordedMessage<'_>| {
        recording
            .decode(m)
            .map_err(|e| content(format!("message on `{}`: {e}", m.topic)))
    };

    // Pass 1: the final state, and the time point of the per-iteration meshes.
    let mut interfaces = Vec::new();
    let mut displacements = BTreeMap::new();
    let mut last_states = BTreeMap::new();
    let mut first_w = None;
    let mut states = BoundaryStates::new();
    for m in recording.messages() {
        let msg = decode(&m)?;
        if let Some(state) = states.fields(&msg.payload) {
            let (subdomain, w, f) = state.map_err(|e| content(format!("message on `{}`: {e}", m.topic)))?;
            if first_w.is_none() {
                first_w = Some(largest_time_point(&w));
            }
            last_states.insert(subdomain, (w.into_owned(), f.into_owned()));
            continue;
        }
        match msg.payload {
            Payload::InterfaceSolution(s) => interfaces.push(s),
            Payload::Displacement { subdomain, u } => {
                displacements.insert(subdomain, u);
            }
            _ => {}
        }
    }
    let mut recovery = Recovery::new(&model);
    let final_u =
        final_displacements(&model, &mut recovery, &interfaces, &displacements, &last_states).map_err(content)?;
    let mut fields = Vec::new();
    let mut umax = 0.0f64;
    for (&s, per_time) in &final_u {
        for u in per_time {
            umax = u.iter().fold(umax, |m, v| m.max(v.abs()));
            fields.push(nodal_field(&model, s as usize, u, opts.color_by));
        }
    }
    let range = range_of(fields.iter().map(Vec::as_slice));
    let mut opts = opts.clone();
    if opts.time_point.is_none() {
        opts.time_point = first_w;
    }
    if opts.amplification.is_none() && umax > 0.0 {
        opts.amplification = Some(0.05 * diagonal(&model) / umax);
    }

    // Pass 2: every message, as a live run would give them.
    let mut view = View::new(text, &origin, recording.run_id(), &opts, Some(range))?;
    for m in recording.messages() {
        view.message(&decode(&m)?)?;
    }
    view.finish()
}
