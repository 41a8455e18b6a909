//! Pure numerics of glissade: QUA8 elasticity, condensed subdomain operators, the LATIN laws and
//! indicators, and monolithic reference solves. No I/O, no transport, no async: every item is
//! testable in-process in milliseconds.
//!
//! Units: mm, N, MPa, s. Plane strain unless a scene says plane stress; unit thickness.

pub mod anderson;
pub mod assembly;
pub mod coarse;
pub mod condensed;
pub mod element;
pub mod expr;
pub mod laws;
pub mod linear;
pub mod local;
pub mod mesh;
pub mod model;
pub mod modes;
pub mod monolithic;
pub mod pgd;
pub mod reference;
pub mod scene;
pub mod simd;
