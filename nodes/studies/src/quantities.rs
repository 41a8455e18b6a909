//! The quantities of interest of a solved variant, per contact interface and time point, from
//! its final fields (s, with the reported statuses, one value per point): what an engineer reads off a
//! joint without summing anything by hand.

use glissade_mechanics::laws::dot;
use glissade_mechanics::model::{Interface, Model, Plane};
use glissade_messages::InterfaceSolution;
use serde::Serialize;

/// Every quantity's name and unit, in the order of [`InterfaceQuantities::values`]. Forces are
/// per unit thickness (plane problems); [`unit`] gives them for a scene's plane.
pub const QUANTITIES: [(&str, &str); 11] = [
    ("normal", "N/mm"),
    ("tangential", "N/mm"),
    ("separated_share", "1"),
    ("stick_share", "1"),
    ("slip_share", "1"),
    ("limit_share", "1"),
    ("grazing_share", "1"),
    ("mean_pressure", "MPa"),
    ("max_pressure", "MPa"),
    ("max_slip", "mm"),
    ("dissipation", "N"),
];

/// The unit of quantity `q` of [`QUANTITIES`] under `plane`: in axisymmetry forces are totals
/// over the circumference (N) and the dissipation is N·mm.
pub fn unit(q: usize, plane: Plane) -> &'static str {
    match (QUANTITIES[q], plane) {
        ((_, "N/mm"), p) => p.force_unit(),
        (("dissipation", _), Plane::Axisymmetric) => "N·mm",
        ((_, u), _) => u,
    }
}

/// The position of quantity `name` in [`QUANTITIES`].
pub fn index_of(name: &str) -> Option<usize> {
    QUANTITIES.iter().position(|(n, _)| *n == name)
}

/// One contact interface's quantities at every time point.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InterfaceQuantities {
    pub interface: usize,
    pub a: String,
    pub b: String,
    /// `values[q][i]`: quantity q of [`QUANTITIES`] at time point i:
    /// - normal, tangential: Σ w·f_n and Σ w·f_t over the pairs (f the traction on side a, w the
    ///   pair's lumped length): the resultant force side b exerts on side a along each pair's
    ///   normal and tangent; normal < 0 in compression;
    /// - the shares of the interface's length in each reported status (0 to 1; separated,
    ///   stick, slip, limit, grazing: `glissade_mechanics::settled`);
    /// - mean_pressure: −Σ w·f_n / Σ w over the pairs in contact (0 with none), max_pressure:
    ///   the largest −f_n;
    /// - max_slip: the largest |[u_t](t) − [u_t](0)| over the pairs in contact at t, [u_t] the
    ///   tangential jump w_b − w_a;
    /// - dissipation: Σ over the steps up to t and the pairs slipping at its end of
    ///   w·|f_t·Δ[u_t]|, the work friction has taken (N·mm per mm of thickness).
    pub values: Vec<Vec<f64>>,
}

/// The quantities of every contact interface of `model` from the final fields `solutions` (in
/// any order; those of perfect interfaces are skipped). Err names a solution whose shape does not
/// fit the model.
pub fn quantities(model: &Model, solutions: &[InterfaceSolution]) -> Result<Vec<InterfaceQuantities>, String> {
    let nt = model.time.n_points();
    let mut out = Vec::new();
    let mut sols: Vec<&InterfaceSolution> = solutions.iter().collect();
    sols.sort_by_key(|s| s.interface);
    for sol in sols {
        let k = sol.interface as usize;
        let itf = model
            .interfaces
            .get(k)
            .ok_or_else(|| format!("a solution of interface {k}; the scene has {}", model.interfaces.len()))?;
        if !itf.is_contact() {
            continue;
        }
        let np = itf.n_pairs();
        if [&sol.f_a, &sol.w_a, &sol.w_b]
            .iter()
            .any(|f| f.rows() != 2 * np || f.cols() != nt)
            || sol.status.len() < np * nt
        {
            return Err(format!("interface {k}: fields not of {} × {nt}", 2 * np));
        }
        out.push(one(model, k, itf, sol));
    }
    Ok(out)
}

fn one(model: &Model, k: usize, itf: &Interface, sol: &InterfaceSolution) -> InterfaceQuantities {
    let nt = model.time.n_points();
    let np = itf.n_pairs();
    let length: f64 = itf.weights.iter().sum();
    let traction = |p: usize, i: usize| [sol.f_a.get(2 * p, i), sol.f_a.get(2 * p + 1, i)];
    let jump_t = |p: usize, i: usize| {
        let j = [
            sol.w_b.get(2 * p, i) - sol.w_a.get(2 * p, i),
            sol.w_b.get(2 * p + 1, i) - sol.w_a.get(2 * p + 1, i),
        ];
        dot(j, itf.tangent(p))
    };
    let mut values = vec![vec![0.0; nt]; QUANTITIES.len()];
    let mut dissipated = 0.0;
    for i in 0..nt {
        let (mut n, mut t, mut shares) = (0.0, 0.0, [0.0; 5]);
        let (mut pressed, mut pressed_length, mut max_p, mut max_slip) = (0.0, 0.0, 0.0f64, 0.0f64);
        for (p, &w) in itf.weights.iter().enumerate() {
            let f = traction(p, i);
            let (f_n, f_t) = (dot(f, itf.normal(p)), dot(f, itf.tangent(p)));
            n += w * f_n;
            t += w * f_t;
            let status = sol.status[i * np + p] as usize;
            if let Some(s) = shares.get_mut(status) {
                *s += w / length;
            }
            // In contact: stick, slip or at the friction limit (not separated, not grazing).
            let closed = matches!(status, 1..=3);
            if closed {
                pressed += -w * f_n;
                pressed_length += w;
            }
            max_p = max_p.max(-f_n);
            if closed {
                max_slip = max_slip.max((jump_t(p, i) - jump_t(p, 0)).abs());
            }
            // Slipping, or on the cone with a slip within the margin.
            if i > 0 && matches!(status, 2 | 3) {
                dissipated += w * (f_t * (jump_t(p, i) - jump_t(p, i - 1))).abs();
            }
        }
        let row = [
            n,
            t,
            shares[0],
            shares[1],
            shares[2],
            shares[3],
            shares[4],
            if pressed_length > 0.0 {
                pressed / pressed_length
            } else {
                0.0
            },
            max_p,
            max_slip,
            dissipated,
        ];
        for (series, v) in values.iter_mut().zip(row) {
            series[i] = v;
        }
    }
    InterfaceQuantities {
        interface: k,
        a: model.subdomains[itf.a].name.clone(),
        b: model.subdomains[itf.b].name.clone(),
        values,
    }
}

/// The share of an interface's closed length (its pairs not separated) that slips, from its
/// slip and separated shares of the whole length; 0 when the whole interface is open.
pub fn closed_slip_share(slip: f64, separated: f64) -> f64 {
    let closed = 1.0 - separated;
    if closed > 1e-12 {
        (slip / closed).min(1.0)
    } else {
        0.0
    }
}

/// The value a plot and the console show of quantity `q` for a variant: over its time points and
/// contact interfaces, the largest in magnitude, with its sign (the peak normal force is its
/// most compressive value).
pub fn peak(all: &[InterfaceQuantities], q: usize) -> f64 {
    all.iter()
        .flat_map(|iq| iq.values[q].iter().copied())
        .fold(f64::NAN, |m, v| if m.is_nan() || v.abs() > m.abs() { v } else { m })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_messages::Field;

    /// Two blocks of 40 mm on a contact interface (y = 20, normal +y out of the lower block),
    /// given uniform tractions: the resultants are traction times length, the mean pressure the
    /// pressure, and a slip rising linearly gives the dissipation Σ f_t·Δslip·L exactly.
    #[test]
    fn uniform_tractions_give_their_resultants_pressure_slip_and_dissipation() {
        let text = include_str!("../../../launch/scenes/two-blocks.toml").replace("N = 40", "N = 4");
        let scene = glissade_scene::load_str(&text, "two-blocks.toml").unwrap();
        let model = &scene.model;
        let itf = &model.interfaces[0];
        let (np, nt) = (itf.n_pairs(), model.time.n_points());
        let length: f64 = itf.weights.iter().sum();
        assert!((length - 40.0).abs() < 1e-9, "{length}");
        assert_eq!(itf.normal(0), [0.0, 1.0]);
        // Traction on side a (the lower block, normal +y): pressure p = 30 MPa is f_n = −30; the
        // tangent is (−1, 0), so f_x = −τ gives f_t = τ = 5 MPa. Side b slides by 0.01·i mm along
        // −x: [u_t] = +0.01·i. Every pair slips from i = 1, sticks at i = 0.
        let f_a = Field::from_fn(2 * np, nt, |r, _| if r % 2 == 0 { -5.0 } else { -30.0 });
        let w_a = Field::zeros(2 * np, nt);
        let w_b = Field::from_fn(2 * np, nt, |r, i| if r % 2 == 0 { -0.01 * i as f64 } else { 0.0 });
        let mut status = vec![2u8; np * nt];
        status[..np].fill(1);
        let sol = InterfaceSolution {
            interface: 0,
            w_a: w_a.clone(),
            w_b: w_b.clone(),
            f_a: f_a.clone(),
            f_b: f_a.clone(),
            w_a_hat: w_a,
            w_b_hat: w_b,
            f_a_hat: f_a.clone(),
            f_b_hat: f_a,
            status,
        };
        let q = quantities(model, &[sol]).unwrap();
        assert_eq!(q.len(), 1);
        let v = |name: &str, i: usize| q[0].values[index_of(name).unwrap()][i];
        // Sums of 40 mm of lumped lengths: exact to round-off.
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        for i in 0..nt {
            assert!(close(v("normal", i), -30.0 * 40.0));
            assert!(close(v("tangential", i), 5.0 * 40.0));
            assert!(close(v("mean_pressure", i), 30.0));
            assert!(close(v("max_pressure", i), 30.0));
            assert!(close(v("max_slip", i), 0.01 * i as f64));
            assert!(close(v("dissipation", i), 5.0 * 0.01 * i as f64 * 40.0));
            let slipping = if i == 0 { 0.0 } else { 1.0 };
            assert!(close(v("slip_share", i), slipping) && close(v("stick_share", i), 1.0 - slipping));
        }
        assert!(close(peak(&q, index_of("normal").unwrap()), -1200.0));
        // Slip over the closed length: half open, the other half slipping, is whole slip.
        assert_eq!(closed_slip_share(0.5, 0.5), 1.0);
        assert_eq!(closed_slip_share(0.25, 0.5), 0.5);
        assert_eq!(closed_slip_share(0.0, 1.0), 0.0);
        let bad = InterfaceSolution {
            interface: 0,
            f_a: Field::zeros(2, nt),
            ..sample_solution(np, nt)
        };
        assert!(quantities(model, &[bad]).unwrap_err().contains("interface 0"));
    }

    fn sample_solution(np: usize, nt: usize) -> InterfaceSolution {
        let z = || Field::zeros(2 * np, nt);
        InterfaceSolution {
            interface: 0,
            w_a: z(),
            w_b: z(),
            f_a: z(),
            f_b: z(),
            w_a_hat: z(),
            w_b_hat: z(),
            f_a_hat: z(),
            f_b_hat: z(),
            status: vec![0; np * nt],
        }
    }
}
