//! Pure numerics of glissade: QUA8 elasticity, condensed subdomain operators, the LATIN laws and
//! indicators, PGD and Anderson acceleration. No I/O, no file format, no transport, no async:
//! every item is testable in-process in milliseconds. Models come from the `glissade-scene`
//! crate; the monolithic reference solvers live in `glissade-reference`.
//!
//! Units: mm, N, MPa, s. Plane strain unless a scene says plane stress; unit thickness.

pub mod anderson;
pub mod assembly;
pub mod coarse;
pub mod condensed;
pub mod element;
pub mod estimate;
pub mod expr;
pub mod laws;
pub mod linear;
pub mod local;
pub mod mesh;
pub mod model;
pub mod modes;
pub mod mortar;
pub mod pgd;
pub mod points;
pub mod post;
pub mod scales;
pub mod settled;
pub mod simd;
pub mod sliding;

/// Passes over full boundary fields (n_b × (N+1)) that one plain iteration makes per subdomain,
/// each the read or the write of one whole field, in the condensed linear stage with the coarse
/// problem and the local stage, call by call in the order the nodes make them (the same as
/// `nodes/mechanics/tests/support/latin.rs`). The interface-side fields count on the subdomain's
/// rows: every row of an interface's fields belongs to one side, that is one subdomain.
///
/// - `SubdomainSolver::micro1_into` (10): 1 reads q̂ and 2 writes M q̂ (`scale_into`, into the
///   scratch block); 3 reads W_d and 4 writes W₁ (`copy_from`); 5 reads M q̂, 6 reads W₁ and
///   7 writes W₁ (the product A_E · M q̂ added into W₁); 8 reads q̂, 9 reads W₁ and 10 writes F₁
///   (F₁ = q̂ − k⁻W₁).
/// - `SubdomainSolver::macro_forces_into` (1): 11 reads F₁ (dot products with the columns of M𝔼).
/// - `SubdomainSolver::micro2_into` (2): 12 writes W₂, 13 writes F₂ (two products with w̃).
/// - `sum_relax_into` (10): for W and for F, reads s₁, s₂ and the previous s, writes s₁ + s₂
///   back into s₁ and writes the relaxed s (14–23).
/// - `InterfaceNode::store` (4), gathering s: 24–25 read W and F, 26–27 write the interface's
///   copies.
/// - `InterfaceLocal::local_stage_with_sums` (4): 28–29 read W and F, 30–31 write Ŵ and F̂; the
///   indicator sums read each time point's columns of W, F, Ŵ and F̂ right after, from cache.
/// - `InterfaceLocal::q_hat_into` (3): 32–33 read Ŵ and F̂, 34 writes q̂.
///
/// Not counted: fields of n_m × (N+1) (macro forces, w̃) and of one value per contact pair
/// (statuses, C_N, 𝒯), the operators (counted apart), and the messages' copies and encoding
/// between the nodes, which the in-process run also makes. Every pass is counted once, as if no
/// field stayed in cache from one call to the next (within a call, a column read again right
/// after it is written, as by the indicator sums, is not counted again).
pub const FIELD_PASSES: usize = 10 + 1 + 2 + 10 + 4 + 4 + 3;

#[cfg(test)]
pub(crate) mod fixtures {
    //! Models for the unit tests, built by the scene crate from scene files and kept as JSON in
    //! `tests/fixtures/` (this crate reads no scene format). The scene crate's test
    //! `model_fixtures_are_what_the_scenes_build` fails when a fixture differs from what its scene
    //! builds today (`GLISSADE_BLESS=1` rewrites them).
    use crate::model::Model;

    fn parse(json: &str) -> Model {
        serde_json::from_str(json).expect("a model fixture of tests/fixtures/")
    }

    /// launch/scenes/small-three-layer.toml.
    pub(crate) fn small_three_layer() -> Model {
        parse(include_str!("../tests/fixtures/small-three-layer.model.json"))
    }

    /// tests/fixtures/two-blocks-contact.toml.
    pub(crate) fn two_blocks_contact() -> Model {
        parse(include_str!("../tests/fixtures/two-blocks-contact.model.json"))
    }
}
