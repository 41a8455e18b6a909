//! The recording walk: two passes over a recording, the final state first (colour range: the
//! percentiles of its field at every node and time point; amplification, time point), then every message through a [`View`].

use crate::draw::{largest_time_point, nodal_field};
use crate::legend::{ColourRange, Frame};
use crate::recovery::{final_displacements, Recovery};
use crate::{BoundaryStates, ReplayError, ReplayOptions, ReplaySummary, View};
use glissade_messages::{InterfaceSolution, Message, Overrides, Payload};
use glissade_recorder::{RecordedMessage, Recording};
use glissade_scene::load_with;
use std::collections::BTreeMap;

/// A run's final state as its recording holds it: the scene's model, every subdomain's
/// displacement at every time point (recorded with `--interior`, else recovered from the
/// boundary states) and the last interface solution (ŝ) of each interface.
pub struct FinalState {
    pub model: glissade_mechanics::model::Model,
    /// `u[s][i]`: subdomain s's displacement at time point i (2 values per node).
    pub u: BTreeMap<u32, Vec<Vec<f64>>>,
    pub interfaces: Vec<InterfaceSolution>,
    /// The time point with the largest displacement of the first boundary state, if any.
    first_w: Option<usize>,
    /// Recorded messages that are not the run's.
    pub skipped: Skipped,
}

/// The messages of a recording that are not the run's, which replay and re-execution skip: a
/// recorder before the bus was authenticated kept well-formed messages any process published on
/// the run's keys.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Skipped {
    pub count: u64,
    /// The first one: its position, topic and why it is not the run's.
    pub first: Option<String>,
}

impl Skipped {
    fn add(&mut self, index: usize, topic: &str, why: String) {
        self.count += 1;
        self.first
            .get_or_insert_with(|| format!("message #{index} on `{topic}`: {why}"));
    }

    /// "N message(s) … skipped (the first …)", or None when none was.
    pub fn describe(&self) -> Option<String> {
        self.first.as_ref().map(|first| {
            format!(
                "{} recorded message(s) are not the run's and were skipped (the first, {first})",
                self.count
            )
        })
    }
}

/// The run's messages of `recording`, decoded, with their position in file order: those that
/// decode as the run's, sit on their sender's key and are of a kind their sender sends
/// ([`Message::not_from_its_sender`]); the others are counted in `skipped`. A repeat of a message
/// (same key and bytes) is passed over.
pub fn run_messages<'r>(
    recording: &'r Recording,
    skipped: &'r mut Skipped,
) -> impl Iterator<Item = (usize, RecordedMessage<'r>, Message)> + 'r {
    // A message heard twice (its sender put it again when the launcher said it was lost on the
    // way) is one message, as for every receiver: the repeat is passed over.
    let mut heard = std::collections::HashSet::new();
    recording.messages().enumerate().filter_map(move |(i, m)| {
        if !heard.insert(glissade_messages::message_hash(m.topic, &m.data)) {
            return None;
        }
        let why = match recording.decode(&m) {
            Ok(msg) => match msg.not_from_its_sender(m.topic) {
                None => return Some((i, m, msg)),
                Some(why) => why,
            },
            Err(e) => e.to_string(),
        };
        skipped.add(i, m.topic, why);
        None
    })
}

/// An error about the content of `recording`.
fn content(recording: &Recording, detail: String) -> ReplayError {
    ReplayError::Content {
        path: recording.path().display().to_string(),
        detail,
    }
}

/// The scene text a recording holds, the command-line overrides the run applied to it, and the
/// name the scene is known by in messages.
fn recorded_scene(recording: &Recording) -> Result<(&str, &Overrides, String), ReplayError> {
    let text = recording
        .scene_text()
        .ok_or_else(|| content(recording, "the recording holds no scene (attachment scene.toml)".into()))?;
    let overrides = recording.scene_overrides().ok_or_else(|| {
        content(
            recording,
            "the recording holds no command-line overrides (attachment overrides.json)".into(),
        )
    })?;
    Ok((text, overrides, format!("{} (scene.toml)", recording.path().display())))
}

/// Reads the final state of the run recorded in `recording` (one pass over its messages).
pub fn final_state(recording: &Recording) -> Result<FinalState, ReplayError> {
    let content = |detail: String| content(recording, detail);
    let (text, overrides, origin) = recorded_scene(recording)?;
    let model = load_with(text, &origin, overrides)
        .map_err(|e| content(e.to_string()))?
        .model;
    let mut interfaces: BTreeMap<u32, InterfaceSolution> = BTreeMap::new();
    let mut displacements = BTreeMap::new();
    let mut last_states = BTreeMap::new();
    let mut first_w = None;
    let mut states = BoundaryStates::new(&model);
    let mut skipped = Skipped::default();
    for (_, m, msg) in run_messages(recording, &mut skipped) {
        if let Some(state) = states.fields(&msg) {
            let (subdomain, w, f) = state.map_err(|e| content(format!("message on `{}`: {e}", m.topic)))?;
            if first_w.is_none() {
                first_w = Some(largest_time_point(&w));
            }
            last_states.insert(subdomain, (w.into_owned(), f.into_owned()));
            continue;
        }
        match msg.payload {
            Payload::InterfaceSolution(s) => {
                interfaces.insert(s.interface, s);
            }
            Payload::Displacement { subdomain, u } => {
                displacements.insert(subdomain, u);
            }
            _ => {}
        }
    }
    let mut interfaces: Vec<InterfaceSolution> = interfaces.into_values().collect();
    let mut recovery = Recovery::new(&model);
    // The displacements from each copy's own values (what each subdomain was sent), then the
    // outputs' one value per point.
    let u = final_displacements(&model, &mut recovery, &interfaces, &displacements, &last_states).map_err(content)?;
    crate::as_reported(&model, &mut interfaces);
    Ok(FinalState {
        model,
        u,
        interfaces,
        first_w,
        skipped,
    })
}

/// Replays `recording` into the sink of `opts`: the colour range and amplification come from the
/// final state, then every message goes through a [`View`].
pub fn replay(recording: &Recording, opts: &ReplayOptions) -> Result<ReplaySummary, ReplayError> {
    let (text, overrides, origin) = recorded_scene(recording)?;

    // Pass 1: the final state, and the time point of the per-iteration meshes.
    let FinalState {
        model,
        u: final_u,
        first_w,
        skipped,
        ..
    } = final_state(recording)?;
    let mut fields = Vec::new();
    let mut umax = 0.0f64;
    for (&s, per_time) in &final_u {
        for u in per_time {
            umax = u.iter().fold(umax, |m, v| m.max(v.abs()));
            fields.push(nodal_field(&model, s as usize, u, opts.color_by)?);
        }
    }
    let range = ColourRange::of(fields.iter().map(Vec::as_slice)).unwrap_or(ColourRange::NONE);
    drop(fields);
    let mut opts = opts.clone();
    if opts.time_point.is_none() {
        opts.time_point = first_w;
    }
    if opts.amplification.is_none() && umax > 0.0 {
        opts.amplification = Some(0.05 * Frame::new(&model).diagonal() / umax);
    }

    // Pass 2: every message, as a live run would give them.
    let mut view = View::new(text, overrides, &origin, recording.run_id(), &opts, Some(range))?;
    let mut again = Skipped::default();
    for (_, _, msg) in run_messages(recording, &mut again) {
        view.message(&msg)?;
    }
    let mut summary = view.finish()?;
    summary.skipped = skipped;
    Ok(summary)
}
