//! Scene files: a TOML description of a problem (blocks, materials, interfaces, boundary
//! conditions, time grid) plus solver, PGD, deployment, recording and network settings, parsed,
//! validated and turned into a [`Model`].
//!
//! [`load_str`] parses the text into raw structs (serde, unknown keys rejected everywhere),
//! validates every value, meshes the blocks, finds the interfaces between subdomains and builds
//! the loads. Every problem is reported as a [`SceneError`] `file: key: problem`, where `key` is
//! the TOML key at fault (`materials.steel.nu`, `block[2].nx`, `interface[0].friction`,
//! `boundary[3]`, …; array indices count from 0).
//!
//! Command-line settings ([`Overrides`]: `--accuracy`, `--tolerance`, `--max-iterations`,
//! `--record`) are applied to the loaded scene, not written into its text:
//! [`LoadedScene::with_overrides`] sets the model's and the recording's values, each checked by the
//! rule and reported with the key (`solver.max_iterations`, …) the file's own value gets. The text
//! stays as written and the overrides travel and are recorded beside it; [`load_with`] rebuilds
//! the run's scene from the two, and [`fingerprint_with`] covers both (it is the text's
//! [`fingerprint`] when nothing is overridden).
//!
//! The format itself, every key with its unit, default and constraint, what the builder makes of
//! blocks, interface and boundary rules, and an annotated example, is documented once, in
//! `docs/scenes.md` of the repository; the crate's tests check that the annotated example builds
//! the shipped `launch/scenes/stratified.toml` exactly.

mod build;
pub use build::memory::{set_machine_memory, MemoryEstimate};
pub use build::options::{auto_coarsening, AUTO_COARSENING_MIN_STEPS, AUTO_COARSE_STEPS};
pub use build::rigid::free_motions;
pub use build::{is_file_stem, MAX_NAME_CHARS};
mod diagnostics;
pub mod msh;
mod raw;
mod settings;
#[cfg(test)]
mod tests;

pub use settings::{
    balanced_interface_groups, final_field_bytes, full_field_bytes_per_iteration, Deployment, Network, Partition,
    Recording, TlsFiles, AUTO_FULL_FIELDS_EVERY, AUTO_FULL_FIELD_BYTES,
};

// The command-line overrides are a wire type (defined with the messages): they travel beside the
// scene text in the `scene` message and are recorded beside it; this crate applies them.
pub use glissade_messages::{Overrides, RecordOverride};

use build::Ctx;
use diagnostics::{parse_raw, toml_error};
use glissade_mechanics::linear::LinearStage;
use glissade_mechanics::model::Model;
use glissade_mechanics::pgd::PgdParams;

pub use glissade_mechanics::model::DEFAULT_ANDERSON_WINDOW;
/// Largest `solver.anderson_window` accepted (each iterate kept costs three boundary fields).
pub const MAX_ANDERSON_WINDOW: usize = glissade_mechanics::anderson::MAX_SLOTS;

/// Largest `solver.macro_degree` accepted (2(d + 1) macro modes per interface).
pub const MAX_MACRO_DEGREE: usize = 5;

/// A scene loaded from its text: the validated model plus the settings used by the runtime.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    pub model: Model,
    pub deployment: Deployment,
    pub recording: Recording,
    pub pgd: PgdParams,
    /// How subdomains solve their linear stage.
    pub linear_stage: LinearStage,
    /// [`fingerprint_with`] of `text` and `overrides`.
    pub fingerprint: u64,
    /// The scene text as written (remote nodes get the scene from the bus, recordings attach it);
    /// with a mesh file, the file's bytes are embedded in it.
    pub text: String,
    /// The command-line settings applied to the model and the recording settings on top of
    /// `text` ([`LoadedScene::with_overrides`]); they travel and are recorded with the text.
    pub overrides: Overrides,
    /// How the processes of a run reach each other (`[network]`).
    pub network: Network,
}

/// A problem in a scene file: `file: key: problem`, or `flag: file: key: problem` when a
/// command-line flag set the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}{file}: {key}: {problem}", .set_by.as_ref().map_or(String::new(), |f| format!("{f}: ")))]
pub struct SceneError {
    pub file: String,
    /// The TOML key at fault, e.g. `block[2].nx`; `(syntax)` when no key applies.
    pub key: String,
    pub problem: String,
    /// The command-line flag and value that set the key (`--max-iterations 0`), if one did.
    pub set_by: Option<String>,
}

impl SceneError {
    /// This error, said of the value the command line's `flag` gave.
    fn set_by(mut self, flag: String) -> Self {
        self.set_by = Some(flag);
        self
    }
}

/// FNV-1a 64-bit hash of the bytes of `text` (stable across platforms and runs).
pub fn fingerprint(text: &str) -> u64 {
    fnv1a(0xcbf2_9ce4_8422_2325, text.as_bytes())
}

fn fnv1a(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The fingerprint of a run's scene: of `text` and the command-line `overrides` applied to it.
/// Without overrides it is [`fingerprint`]`(text)`; with some, the FNV-1a hash goes on from the
/// text's over a NUL byte (never in a scene: TOML refuses it) and then, for accuracy, tolerance,
/// max_iterations and record in this order, a 0 byte when absent or a 1 byte and the value's
/// 8 bytes little-endian (f64 bits; the iteration count as u64; record: 0 off, 1 full). Runs of one
/// text with different overrides never share a fingerprint.
pub fn fingerprint_with(text: &str, overrides: &Overrides) -> u64 {
    if overrides.is_none() {
        return fingerprint(text);
    }
    let mut bytes = vec![0u8];
    let mut value = |v: Option<u64>| match v {
        None => bytes.push(0),
        Some(v) => {
            bytes.push(1);
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    };
    value(overrides.accuracy.map(f64::to_bits));
    value(overrides.tolerance.map(f64::to_bits));
    value(overrides.max_iterations.map(|m| m as u64));
    value(overrides.record.map(|r| match r {
        RecordOverride::Off => 0,
        RecordOverride::Full => 1,
    }));
    fnv1a(fingerprint(text), &bytes)
}

/// Parses, validates and builds the scene in `text`; `file` names it in errors and gives the
/// default model name (its file stem).
pub fn load_str(text: &str, file: &str) -> Result<LoadedScene, SceneError> {
    let raw = parse_raw(text, file)?;
    let ctx = Ctx {
        file,
        plane: raw.plane(),
    };
    let built = ctx.build(&raw)?;
    // A scene with a mesh file travels with its mesh: the text gets the bytes the model was
    // built from.
    let embedded;
    let text = match (&raw.mesh, &built.mesh_file) {
        (Some(mesh), Some(bytes)) => {
            embedded = embed_mesh(text, file, &mesh.file, bytes)?;
            embedded.as_str()
        }
        _ => text,
    };
    Ok(LoadedScene {
        model: built.model,
        deployment: built.deployment,
        recording: built.recording,
        pgd: built.pgd,
        linear_stage: built.linear_stage,
        fingerprint: fingerprint(text),
        text: text.to_string(),
        overrides: Overrides::default(),
        network: ctx.network(&raw.network)?,
    })
}

/// The scene of `text` with the command-line `overrides` applied ([`LoadedScene::with_overrides`]):
/// what every process of a run and every reader of a recording rebuilds the run's model with, from
/// the text and the overrides that travel and are recorded together.
pub fn load_with(text: &str, file: &str, overrides: &Overrides) -> Result<LoadedScene, SceneError> {
    let mut scene = load_str(text, file)?;
    if !overrides.is_none() {
        scene.apply(file, overrides)?;
    }
    Ok(scene)
}

/// `text` with `[mesh] data` set to the base64 of the mesh file's `bytes`, so that the scene
/// text alone rebuilds the model (node processes get the text from the bus, recordings attach it).
fn embed_mesh(text: &str, file: &str, mesh_file: &str, bytes: &[u8]) -> Result<String, SceneError> {
    use base64::Engine;
    let mut table: toml::Table = text.parse().map_err(|e| toml_error(text, file, &e, true))?;
    let err = |problem: String| SceneError {
        file: file.to_string(),
        key: "mesh".to_string(),
        problem,
        set_by: None,
    };
    let mesh = table
        .get_mut("mesh")
        .and_then(toml::Value::as_table_mut)
        .ok_or_else(|| err("is not a table".into()))?;
    mesh.insert(
        "data".into(),
        toml::Value::String(base64::engine::general_purpose::STANDARD.encode(bytes)),
    );
    let body = toml::to_string(&table).map_err(|e| err(format!("cannot write the scene back: {e}")))?;
    Ok(format!(
        "# {file} with its mesh file `{mesh_file}` embedded ([mesh] data, base64)\n{body}"
    ))
}

impl LoadedScene {
    /// This scene with the command line's `overrides` applied to its model and recording
    /// settings, each value checked by the rule, and reported with the error, the file's own key
    /// gets (`solver.max_iterations`, …; `file` names the scene). The text stays as written: the
    /// result holds the overrides (on top of any it had), its fingerprint covers both
    /// ([`fingerprint_with`]), and [`load_with`] rebuilds it from the two.
    pub fn with_overrides(&self, file: &str, overrides: &Overrides) -> Result<LoadedScene, SceneError> {
        if overrides.is_none() {
            return Ok(self.clone());
        }
        if !self.overrides.is_none() {
            // Overrides given before: the scene as written with all of them, so that the text and
            // the merged overrides rebuild exactly this scene.
            let mut scene = load_with(&self.text, file, &self.overrides.then(*overrides))?;
            scene.network = self.network.clone();
            return Ok(scene);
        }
        let mut scene = self.clone();
        scene.apply(file, overrides)?;
        Ok(scene)
    }

    /// Sets the overrides of a scene that has none yet.
    fn apply(&mut self, file: &str, overrides: &Overrides) -> Result<(), SceneError> {
        debug_assert!(self.overrides.is_none());
        let ctx = Ctx {
            file,
            plane: self.model.plane,
        };
        let solver = &mut self.model.solver;
        // A refused value is said of the flag that gave it.
        if let Some(a) = overrides.accuracy {
            ctx.check_accuracy(a).map_err(|e| e.set_by(format!("--accuracy {a}")))?;
            solver.accuracy = Some(a);
        }
        if let Some(t) = overrides.tolerance {
            ctx.check_tolerance(t)
                .map_err(|e| e.set_by(format!("--tolerance {t}")))?;
            solver.tolerance = Some(t);
        }
        if let Some(m) = overrides.max_iterations {
            ctx.check_max_iterations(m)
                .map_err(|e| e.set_by(format!("--max-iterations {m}")))?;
            solver.max_iterations = m;
        }
        if let Some(record) = overrides.record {
            let mut recording = self.recording.clone();
            match record {
                RecordOverride::Off => recording.enabled = false,
                RecordOverride::Full => {
                    recording.enabled = true;
                    recording.topics = vec!["**".to_string()];
                    recording.full_fields_every = 1;
                    recording.full_fields_auto = false;
                }
            }
            ctx.check_recording(&recording)?;
            self.recording = recording;
        }
        self.overrides = *overrides;
        self.fingerprint = fingerprint_with(&self.text, overrides);
        Ok(())
    }
}
