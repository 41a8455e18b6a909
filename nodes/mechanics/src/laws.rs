//! The local stage of the LATIN method (docs/method.md, "Local stage"): interface laws solved point-wise, per node
//! pair and time point, along the search direction E⁺:
//! F̂_E − F_E = k⁺ (Ŵ_E − W_E) on each side, k⁺ = k_N P_N + k_T P_T (2 × 2, symmetric, positive).
//!
//! Convention: F is the force per unit length acting ON a subdomain; n points out of side A
//! towards side B; t = (−n_y, n_x); the jump is [W] = W_B − W_A.

/// Contact status of a pair at one time point.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Status {
    Separated = 0,
    Stick = 1,
    Slip = 2,
}

/// Names of the statuses, by code (`Status as usize`): what outputs and views call them.
pub const STATUS_NAMES: [&str; 3] = ["separated", "stick", "slip"];

/// Input of a pair: traces and forces of both sides at one time point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairState {
    pub w_a: [f64; 2],
    pub w_b: [f64; 2],
    pub f_a: [f64; 2],
    pub f_b: [f64; 2],
}

/// Output of a pair: (Ŵ_A, Ŵ_B, F̂_A); F̂_B = −F̂_A always.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairHat {
    pub w_a: [f64; 2],
    pub w_b: [f64; 2],
    pub f_a: [f64; 2],
}

/// a·b of two plane vectors (a normal or tangent with a jump or a force).
#[inline(always)]
pub fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// Perfect interface with isotropic k⁺ = k (MPa/mm):
/// Ŵ_A = Ŵ_B = ½(W_A + W_B) − ½k⁻¹(F_A + F_B), F̂_A = F_A + k(Ŵ − W_A).
#[inline]
pub fn perfect(k: f64, s: &PairState) -> PairHat {
    let mut w = [0.0; 2];
    let mut f = [0.0; 2];
    for c in 0..2 {
        w[c] = 0.5 * (s.w_a[c] + s.w_b[c]) - 0.5 / k * (s.f_a[c] + s.f_b[c]);
        f[c] = s.f_a[c] + k * (w[c] - s.w_a[c]);
    }
    PairHat { w_a: w, w_b: w, f_a: f }
}

/// Parameters of the contact law at one pair and time point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactPoint {
    /// Normal search direction k_N (MPa/mm).
    pub k_n: f64,
    /// Tangential search direction k_T (MPa/mm).
    pub k_t: f64,
    pub normal: [f64; 2],
    pub tangent: [f64; 2],
    /// Initial normal gap g0 (mm).
    pub gap: f64,
    /// Coulomb coefficient f ≥ 0.
    pub friction: f64,
    /// Tangential jump [Ŵ]·t of this local stage at the previous time point (0 before t_0).
    pub slip_prev: f64,
}

/// Result of the contact law at one point: the local solution, its status, and the indicator
/// quantities C_N and 𝒯 = |C_T| − f|C_N| used by the search-direction update (paper eq. 6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactResult {
    pub hat: PairHat,
    pub status: Status,
    pub c_n: f64,
    pub c_t_excess: f64,
    /// [Ŵ]·t, the tangential jump to carry to the next time point.
    pub slip: f64,
}

/// Unilateral contact with Coulomb friction, backward Euler on the slip increment (docs/method.md, "Local stage"):
/// C_N = ½k_N([W]·n + g0) + ½(F_A − F_B)·n, C_T = ½k_T([W]·t − ĝ_T(t_{i−1})) + ½(F_A − F_B)·t;
/// C_N > 0 → separation, F̂ = 0; else F̂_A·n = C_N and stick (|C_T| < f|C_N|: F̂_A·t = C_T) or
/// slip (F̂_A·t = f|C_N| sign C_T); then Ŵ from E⁺ on each side.
#[inline(always)]
pub fn contact(p: &ContactPoint, s: &PairState) -> ContactResult {
    let (n, t) = (p.normal, p.tangent);
    let jump = [s.w_b[0] - s.w_a[0], s.w_b[1] - s.w_a[1]];
    let df = [s.f_a[0] - s.f_b[0], s.f_a[1] - s.f_b[1]];
    let c_n = 0.5 * p.k_n * (dot(jump, n) + p.gap) + 0.5 * dot(df, n);
    let c_t = 0.5 * p.k_t * (dot(jump, t) - p.slip_prev) + 0.5 * dot(df, t);
    let (f_n, f_t, status) = if c_n > 0.0 {
        (0.0, 0.0, Status::Separated)
    } else {
        let limit = p.friction * c_n.abs();
        if c_t.abs() < limit {
            (c_n, c_t, Status::Stick)
        } else {
            (c_n, limit * c_t.signum(), Status::Slip)
        }
    };
    let f_a = [f_n * n[0] + f_t * t[0], f_n * n[1] + f_t * t[1]];
    // Ŵ = W + k⁺⁻¹ (F̂ − F) on each side, with k⁺⁻¹ = k_N⁻¹ P_N + k_T⁻¹ P_T.
    let apply_inv = |d: [f64; 2]| {
        let (dn, dt) = (dot(d, n) / p.k_n, dot(d, t) / p.k_t);
        [dn * n[0] + dt * t[0], dn * n[1] + dt * t[1]]
    };
    let da = apply_inv([f_a[0] - s.f_a[0], f_a[1] - s.f_a[1]]);
    let db = apply_inv([-f_a[0] - s.f_b[0], -f_a[1] - s.f_b[1]]);
    let w_a = [s.w_a[0] + da[0], s.w_a[1] + da[1]];
    let w_b = [s.w_b[0] + db[0], s.w_b[1] + db[1]];
    let slip = dot([w_b[0] - w_a[0], w_b[1] - w_a[1]], t);
    ContactResult {
        hat: PairHat { w_a, w_b, f_a },
        status,
        c_n,
        c_t_excess: c_t.abs() - p.friction * c_n.abs(),
        slip,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn state() -> impl Strategy<Value = PairState> {
        let v = || prop::array::uniform2(-1.0f64..1.0);
        (v(), v(), v(), v()).prop_map(|(w_a, w_b, f_a, f_b)| PairState {
            w_a: [w_a[0] * 1e-2, w_a[1] * 1e-2],
            w_b: [w_b[0] * 1e-2, w_b[1] * 1e-2],
            f_a: [f_a[0] * 100.0, f_a[1] * 100.0],
            f_b: [f_b[0] * 100.0, f_b[1] * 100.0],
        })
    }

    /// Residual of E⁺ on side A and B, relative to the force scale.
    fn search_direction_residual(p: &ContactPoint, s: &PairState, h: &PairHat) -> f64 {
        let (n, t) = (p.normal, p.tangent);
        let side = |f_hat: [f64; 2], f: [f64; 2], w_hat: [f64; 2], w: [f64; 2]| {
            let df = [f_hat[0] - f[0], f_hat[1] - f[1]];
            let dw = [w_hat[0] - w[0], w_hat[1] - w[1]];
            (dot(df, n) - p.k_n * dot(dw, n)).abs() + (dot(df, t) - p.k_t * dot(dw, t)).abs()
        };
        side(h.f_a, s.f_a, h.w_a, s.w_a) + side([-h.f_a[0], -h.f_a[1]], s.f_b, h.w_b, s.w_b)
    }

    fn unit(theta: f64) -> ([f64; 2], [f64; 2]) {
        let n = [theta.cos(), theta.sin()];
        (n, [-n[1], n[0]])
    }

    // Tolerances: all quantities are O(100) N/mm² (forces) and O(1e4 × 1e-2) for k·w, so round-off
    // of a few operations is ~1e-13 absolute; 1e-9 leaves margin without hiding a wrong formula
    // (a missing ½ gives errors O(1)).
    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn perfect_satisfies_law_and_direction(s in state(), k in 1e2f64..1e5) {
            let h = perfect(k, &s);
            prop_assert_eq!(h.w_a, h.w_b);
            let p = ContactPoint { k_n: k, k_t: k, normal: [0.0, 1.0], tangent: [-1.0, 0.0], gap: 0.0, friction: 0.0, slip_prev: 0.0 };
            prop_assert!(search_direction_residual(&p, &s, &h) < 1e-9);
        }

        #[test]
        fn contact_satisfies_law_and_direction(
            s in state(), theta in 0.0f64..6.3, kn in 1e2f64..1e5, kt in 1e2f64..1e5,
            gap in prop_oneof![Just(0.0), -1e-2f64..1e-2], friction in prop_oneof![Just(0.0), 0.0f64..2.0],
            slip_prev in prop_oneof![Just(0.0), -1e-2f64..1e-2],
        ) {
            let (normal, tangent) = unit(theta);
            let p = ContactPoint { k_n: kn, k_t: kt, normal, tangent, gap, friction, slip_prev };
            let r = contact(&p, &s);
            let h = r.hat;
            prop_assert!(search_direction_residual(&p, &s, &h) < 1e-9);
            let jump = [h.w_b[0] - h.w_a[0], h.w_b[1] - h.w_a[1]];
            let gap_hat = dot(jump, normal) + gap;
            let (f_n, f_t) = (dot(h.f_a, normal), dot(h.f_a, tangent));
            let slip_inc = dot(jump, tangent) - slip_prev;
            prop_assert!((r.slip - dot(jump, tangent)).abs() < 1e-15);
            match r.status {
                Status::Separated => {
                    prop_assert!(f_n == 0.0 && f_t == 0.0);
                    prop_assert!(gap_hat > -1e-12);
                }
                Status::Stick => {
                    prop_assert!(f_n <= 0.0);
                    prop_assert!(gap_hat.abs() < 1e-12, "gap {}", gap_hat);
                    prop_assert!(slip_inc.abs() < 1e-12, "slip {}", slip_inc);
                    prop_assert!(f_t.abs() <= friction * f_n.abs() + 1e-12);
                }
                Status::Slip => {
                    prop_assert!(f_n <= 0.0);
                    prop_assert!(gap_hat.abs() < 1e-12);
                    prop_assert!((f_t.abs() - friction * f_n.abs()).abs() < 1e-9);
                    // Friction on A drags it along the relative motion of B: same sign as the slip increment.
                    prop_assert!(f_t * slip_inc >= -1e-12, "f_t {} slip {}", f_t, slip_inc);
                }
            }
        }
    }

    #[test]
    fn each_status_is_reached() {
        let p = ContactPoint {
            k_n: 1e3,
            k_t: 1e3,
            normal: [0.0, 1.0],
            tangent: [-1.0, 0.0],
            gap: 0.0,
            friction: 0.3,
            slip_prev: 0.0,
        };
        let open = PairState {
            w_a: [0.0, 0.0],
            w_b: [0.0, 0.01],
            f_a: [0.0; 2],
            f_b: [0.0; 2],
        };
        assert_eq!(contact(&p, &open).status, Status::Separated);
        let pressed = PairState {
            w_a: [0.0, 0.0],
            w_b: [0.0, -0.01],
            f_a: [0.0; 2],
            f_b: [0.0; 2],
        };
        assert_eq!(contact(&p, &pressed).status, Status::Stick);
        let sheared = PairState {
            w_a: [0.0, 0.0],
            w_b: [0.01, -0.01],
            f_a: [0.0; 2],
            f_b: [0.0; 2],
        };
        assert_eq!(contact(&p, &sheared).status, Status::Slip);
        // A gap of 0.02 keeps the pressed pair open.
        let gapped = ContactPoint { gap: 0.02, ..p };
        assert_eq!(contact(&gapped, &pressed).status, Status::Separated);
    }
}
