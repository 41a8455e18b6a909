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
//! The format itself, every key with its unit, default and constraint, what the builder makes of
//! blocks, interface and boundary rules, and an annotated example, is documented once, in
//! `docs/scenes.md` of the repository; the crate's tests check that the annotated example builds
//! the shipped `launch/scenes/stratified.toml` exactly.

mod build;
pub use build::memory::{set_machine_memory, MemoryEstimate};
pub use build::options::{auto_coarsening, AUTO_COARSENING_MIN_STEPS, AUTO_COARSE_STEPS};
pub use build::{is_file_stem, MAX_NAME_CHARS};
mod diagnostics;
pub mod msh;
mod raw;
mod settings;
#[cfg(test)]
mod tests;

pub use settings::{
    balanced_interface_groups, final_field_bytes, full_field_bytes_per_iteration, Deployment, Network, Recording,
    TlsFiles, AUTO_FULL_FIELDS_EVERY, AUTO_FULL_FIELD_BYTES,
};

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
    /// [`fingerprint`] of `text`.
    pub fingerprint: u64,
    /// The scene text as given (remote nodes get the scene from the bus).
    pub text: String,
    /// How the processes of a run reach each other (`[network]`).
    pub network: Network,
}

/// A problem in a scene file: `file: key: problem`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {key}: {problem}")]
pub struct SceneError {
    pub file: String,
    /// The TOML key at fault, e.g. `block[2].nx`; `(syntax)` when no key applies.
    pub key: String,
    pub problem: String,
}

/// FNV-1a 64-bit hash of the bytes of `text` (stable across platforms and runs).
pub fn fingerprint(text: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in text.as_bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Parses, validates and builds the scene in `text`; `file` names it in errors and gives the
/// default model name (its file stem).
pub fn load_str(text: &str, file: &str) -> Result<LoadedScene, SceneError> {
    let raw = parse_raw(text, file)?;
    let ctx = Ctx { file };
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
        network: ctx.network(&raw.network)?,
    })
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

/// Scene settings given on the command line, applied by [`LoadedScene::with_overrides`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Overrides {
    pub accuracy: Option<f64>,
    pub tolerance: Option<f64>,
    pub max_iterations: Option<usize>,
    pub record: Option<RecordOverride>,
}

/// What `--record` / `--no-record` ask of the recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordOverride {
    /// No recording (`[recording] enabled = false`).
    Off,
    /// Every message, full fields at every iteration (`enabled = true`, `topics = ["**"]`,
    /// `full_fields_every = 1`).
    Full,
}

impl LoadedScene {
    /// This scene with `[solver] accuracy`, `tolerance` and/or `max_iterations`, and the
    /// recording (`--record`), set as if written in its file: the scene text is rewritten with them (a first comment line says so), so that its
    /// fingerprint, the text that node processes fetch from the bus and the text a recording
    /// attaches all describe the run, not only this process's model. `file` names the scene in
    /// errors and gives the default model name, as in [`load_str`]; the network settings (TLS
    /// paths already resolved against the scene's folder) are kept. An invalid value is the
    /// scene error the file would give.
    pub fn with_overrides(&self, file: &str, overrides: &Overrides) -> Result<LoadedScene, SceneError> {
        if *overrides == Overrides::default() {
            return Ok(self.clone());
        }
        let mut table: toml::Table = self.text.parse().map_err(|e| toml_error(&self.text, file, &e, true))?;
        let err = |key: &str, problem: String| SceneError {
            file: file.to_string(),
            key: key.to_string(),
            problem,
        };
        let solver = table
            .entry("solver")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .ok_or_else(|| err("solver", "is not a table".into()))?;
        let mut said = Vec::new();
        for (key, value) in [("accuracy", overrides.accuracy), ("tolerance", overrides.tolerance)] {
            if let Some(v) = value {
                solver.insert(key.into(), toml::Value::Float(v));
                said.push(format!("[solver] {key} = {v:e}"));
            }
        }
        if let Some(m) = overrides.max_iterations {
            let m = i64::try_from(m).map_err(|_| err("solver.max_iterations", format!("{m} is too large")))?;
            solver.insert("max_iterations".into(), toml::Value::Integer(m));
            said.push(format!("[solver] max_iterations = {m}"));
        }
        if let Some(record) = overrides.record {
            let recording = table
                .entry("recording")
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                .as_table_mut()
                .ok_or_else(|| err("recording", "is not a table".into()))?;
            match record {
                RecordOverride::Off => {
                    recording.insert("enabled".into(), toml::Value::Boolean(false));
                    said.push("[recording] enabled = false".into());
                }
                RecordOverride::Full => {
                    recording.insert("enabled".into(), toml::Value::Boolean(true));
                    recording.insert(
                        "topics".into(),
                        toml::Value::Array(vec![toml::Value::String("**".into())]),
                    );
                    recording.insert("full_fields_every".into(), toml::Value::Integer(1));
                    said.push("[recording] complete".into());
                }
            }
        }
        let body = toml::to_string(&table).map_err(|e| err("(syntax)", format!("cannot write the scene back: {e}")))?;
        let text = format!("# {file} with {} set on the command line\n{body}", said.join(", "));
        let mut scene = load_str(&text, file)?;
        scene.network = self.network.clone();
        Ok(scene)
    }
}
