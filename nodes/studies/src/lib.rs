//! Design studies (docs/studies.md): many variants of one scene, where the friction or
//! gap of an interface rule, a scale factor on a boundary rule's values, or E or ν of a material
//! vary over a list, a range, a grid of several or a seeded sample.
//!
//! - [`study`]: the study file (TOML) and the one-line `--vary name=from:to:count` form;
//! - [`variants`]: the variants of a design, in an order where each is next to one solved before,
//!   and the solved variant nearest to each;
//! - [`patch`]: each variant's scene, as the scene's text with the varied values written in;
//! - [`driver`]: the loop over the variants, which asks a [`driver::Solver`] (the run pipeline,
//!   given by the launcher) to solve each, warm-started from its nearest solved variant;
//! - [`boundary`]: every boundary rule's force on the parts (supports' reactions, loads'
//!   resultants), from any run's final fields;
//! - [`quantities`]: what the project computes of every variant at every time point (interface
//!   resultants, contact pressures, slip, dissipation);
//! - [`table`] and [`plot`]: the CSV and JSON tables, the console summary and the SVG plots.
//!
//! The crate holds no solver: it depends on the scene and numerics crates only, and the launcher
//! runs each variant through its own pipeline (operators reused, given start).

pub mod boundary;
pub mod driver;
pub mod onset;
pub mod patch;
pub mod plot;
pub mod quantities;
pub mod study;
pub mod table;
pub mod variants;

/// A problem with a study: its file, a `--vary` argument, or a variant's scene. Says where.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{place}: {problem}")]
pub struct StudyError {
    /// The study file and key (`study.toml: vary[1].range`), the flag (`--vary`) or the variant.
    pub place: String,
    pub problem: String,
}

impl StudyError {
    pub fn new(place: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            place: place.into(),
            problem: problem.into(),
        }
    }
}
