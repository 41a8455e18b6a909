//! The linear stage of the LATIN method on one subdomain (docs/method.md, "Linear stage"), on the condensed operator:
//! micro problem 1, W₁ = A_E M q̂ + W_d, F₁ = q̂ − k⁻W₁ with q̂ = F̂ + k⁻Ŵ;
//! macro forces F̂ᴹ_{E,d} = 𝔼ᵀ M F₁; micro problem 2, W₂ = A_E M k⁻ 𝔼 w̃, F₂ = k⁻(𝔼 w̃ − W₂);
//! and the homogenized operator L_E = 𝔼ᵀ M k⁻ 𝔼 − (M k⁻ 𝔼)ᵀ A_E (M k⁻ 𝔼).
//!
//! Fields are column-major matrices, one row per boundary entry, one column per time point.
//!
//! - [`LinearStage`] and the default search direction [`default_k0`] (this file);
//! - `macro_basis`: the macro basis of an interface and its degree;
//! - `solver`: [`SubdomainSolver`], the micro and macro problems of one subdomain;
//! - `fields`: passes over whole boundary fields (the sum and relaxation ending the stage);
//! - `start`: [`interpolated_directions`], the initial directions of a run started from a known ŝ;
//! - `state`: [`SubdomainFields`], one subdomain's fields and the stage's steps on them, as the
//!   subdomain node and the crate's one-thread iteration call them.

mod fields;
#[cfg(test)]
pub(crate) mod flop_tests;
mod macro_basis;
mod solver;
mod start;
mod state;

pub use fields::{relax_into, sum_into, sum_relax_into};
pub use macro_basis::{macro_bases, macro_basis, macro_degree, SLENDER};
pub use solver::{MacroSlot, SubdomainSolver};
pub use start::interpolated_directions;
pub use state::{relaxation_at, LinearEnd, SubdomainFields};

use crate::model::Model;

/// The linear stage of the subdomains (docs/method.md, "Linear stage").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinearStage {
    /// One dense product with the condensed A_E per micro problem.
    Condensed,
    /// No A_E: each micro problem is one multi-right-hand-side solve with the sparse factors of
    /// K_E + Bᵀk⁻MB for all time points (the paper's baseline).
    Sparse,
    /// PGD on a reduced basis per subdomain ([`crate::pgd`]).
    Pgd,
    /// Chosen per subdomain from its size ([`LinearStage::resolve`]).
    Auto,
}

impl LinearStage {
    pub const ALL: [LinearStage; 4] = [Self::Condensed, Self::Sparse, Self::Pgd, Self::Auto];

    /// The stage's name, as `solver.linear_stage` spells it.
    pub fn key(self) -> &'static str {
        match self {
            Self::Condensed => "condensed",
            Self::Sparse => "sparse",
            Self::Pgd => "pgd",
            Self::Auto => "auto",
        }
    }

    /// The stage a subdomain with n_b boundary entries uses: `Auto` resolves to `Condensed`, the
    /// fastest to a contact-traction error of 1e-3 on every measured case (docs/pgd.md, "Three linear
    /// stages, time to accuracy", with Anderson, N = 100 and N = 1000): stratified (n_b ≤ 328) condensed 2.18 s and
    /// 14.38 s, PGD 6.73 s and 55.93 s, sparse 29.77 s and 331.96 s; layered (n_b ≈ 960)
    /// condensed 3.61 s and 62.35 s, PGD 18.93 s and 214.58 s, sparse 30.24 s and 938.30 s. The
    /// PGD basis grows to a large fraction of n_b on both (188 of 328, 677 of about 960), so no
    /// boundary size measured favours it; it comes close only to 1e-2 at N = 100.
    pub fn resolve(self, _n_boundary: usize) -> LinearStage {
        match self {
            LinearStage::Auto => LinearStage::Condensed,
            other => other,
        }
    }
}

/// Default search direction per interface: k₀ = k0_factor · E/L_Γ, with E the geometric mean of
/// the two sides' [`Material::interface_modulus`] √(2G·M) (≈ Young's modulus for ν ≤ 0.3, the
/// neighbour's when both sides share a material) and L_Γ the interface length. MPa/mm.
///
/// [`Material::interface_modulus`]: crate::model::Material::interface_modulus
pub fn default_k0(model: &Model) -> Vec<f64> {
    model
        .interfaces
        .iter()
        .map(|itf| {
            let modulus = |s: usize| model.subdomains[s].material.interface_modulus(model.plane);
            let e = (modulus(itf.a) * modulus(itf.b)).sqrt();
            model.solver.k0_factor * e / itf.length
        })
        .collect()
}
