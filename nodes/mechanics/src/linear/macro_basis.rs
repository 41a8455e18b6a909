//! The macro basis of an interface (docs/method.md, "The macro space") and the degree each interface gets.

use crate::model::{Interface, Model};

/// Macro basis of an interface (docs/method.md, "The macro space"): the affine fields u(x) = a + B(x − c) restricted
/// to its pairs (c the weighted centroid), in the order translation along t, translation along n,
/// rotation about the centroid, extension along t (s·t, s = (x − c)·t), then — on a curved
/// interface only — extension along n and the symmetric shear, with (t, n) the interface's
/// [`Interface::mean_frame`]. On a straight interface the last two vanish and the first four span
/// the polynomials of degree ≤ 1 in s of both components (the rotation is s·n): the paper's four
/// modes. With `degree` d > 1 the basis also holds (s/ℓ)^j·t and (s/ℓ)^j·n for 2 ≤ j ≤ d (ℓ the
/// half length; on a curved interface s is the arc length from the weighted mean position along
/// the pairs' order): degree 3 holds the traces of a bent slender layer (cubic deflection,
/// quadratic rotation of its sections), which the coarse problem then resolves in one step. Made
/// orthonormal for the lumped mass M by modified Gram–Schmidt (twice), with rank detection:
/// a vector whose norm after orthogonalisation falls below 1e-10 of its norm before (or of √L
/// for the translations, L·√L for the curved-only modes) is dropped, so a straight interface has
/// 1 to 2(d + 1) modes and a curved one up to 2(d + 1) + 2. Entry 2p+c is pair p, component c.
pub fn macro_basis(itf: &Interface, degree: usize) -> Vec<Vec<f64>> {
    let np = itf.n_pairs();
    let g = itf.centroid;
    let curved = itf.straight_normal().is_none();
    let (n, t) = itf.mean_frame();
    let half = 0.5 * itf.length.max(f64::MIN_POSITIVE);
    // Abscissa of each pair: along t on a straight interface, the arc length on a curved one.
    let abscissa: Vec<f64> = if curved {
        arc_abscissa(itf)
    } else {
        itf.coords
            .iter()
            .map(|x| (x[0] - g[0]) * t[0] + (x[1] - g[1]) * t[1])
            .collect()
    };
    let n_raw = 4 + 2 * degree.saturating_sub(1) + if curved { 2 } else { 0 };
    let mut raw = vec![vec![0.0; 2 * np]; n_raw];
    let extra = 4 + 2 * degree.saturating_sub(1);
    for p in 0..np {
        let r = [itf.coords[p][0] - g[0], itf.coords[p][1] - g[1]];
        let s = abscissa[p];
        let (rt, rn) = (r[0] * t[0] + r[1] * t[1], r[0] * n[0] + r[1] * n[1]);
        for c in 0..2 {
            raw[0][2 * p + c] = t[c];
            raw[1][2 * p + c] = n[c];
            raw[3][2 * p + c] = if curved { rt * t[c] } else { s * t[c] };
            for j in 2..=degree {
                let sj = (s / half).powi(j as i32);
                raw[4 + 2 * (j - 2)][2 * p + c] = sj * n[c];
                raw[5 + 2 * (j - 2)][2 * p + c] = sj * t[c];
            }
            if curved {
                raw[extra][2 * p + c] = rn * n[c];
                raw[extra + 1][2 * p + c] = rn * t[c] + rt * n[c];
            }
        }
        raw[2][2 * p] = -r[1];
        raw[2][2 * p + 1] = r[0];
    }
    let dot = |a: &[f64], b: &[f64]| -> f64 { (0..2 * np).map(|e| itf.weights[e / 2] * a[e] * b[e]).sum() };
    let scale = itf.length.max(f64::MIN_POSITIVE);
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(n_raw);
    for (m, mut v) in raw.into_iter().enumerate() {
        let norm0 = dot(&v, &v).sqrt();
        for _ in 0..2 {
            for b in &basis {
                let c = dot(&v, b);
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= c * y);
            }
        }
        let norm = dot(&v, &v).sqrt();
        // Translations have norm √L; the other modes' norms scale differently: compare to the raw
        // norm. The curved-only modes vanish on a nearly straight interface, where their raw norm
        // is round-off too: compare them to the size of an affine field over the interface.
        let reference = if m < 2 {
            scale.sqrt()
        } else if m >= extra {
            norm0.max(scale * scale.sqrt())
        } else {
            norm0
        };
        if norm > 1e-10 * reference && norm > 0.0 {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
        }
    }
    basis
}

/// Arc length of each pair of a curved interface along the pairs' order (chords between
/// consecutive pairs), measured from the weighted mean arc length.
fn arc_abscissa(itf: &Interface) -> Vec<f64> {
    let mut s = Vec::with_capacity(itf.n_pairs());
    let mut acc = 0.0;
    for p in 0..itf.n_pairs() {
        if p > 0 {
            let (a, b) = (itf.coords[p - 1], itf.coords[p]);
            acc += ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        }
        s.push(acc);
    }
    let total: f64 = itf.weights.iter().sum();
    let mean: f64 = s.iter().zip(&itf.weights).map(|(s, w)| s * w).sum::<f64>() / total;
    s.iter_mut().for_each(|v| *v -= mean);
    s
}

/// Slenderness from which `macro_degree = "auto"` gives an interface the degree-5 macro basis.
pub const SLENDER: f64 = 10.0;

/// Degree of an interface's macro basis: the scene's `solver.macro_degree`, or with "auto" 5 when
/// the interface is at least [`SLENDER`] times longer than one of its two subdomains is thick
/// (extent along the interface normal), else 1. Measured on three 100 × 1 mm layers in contact
/// under an end shear (the stability matrix's thin-layer bending case): degree 1 stops at 2000
/// iterations with a traction error of 6e-2, degree 3 converges in 1427, degree 5 in 483 (η ≤
/// 1e-7); a bent slender layer's traces are smooth polynomials of high degree along the interface,
/// which the coarse problem then resolves at once, while a compact subdomain's are not.
pub fn macro_degree(model: &Model, itf: &Interface) -> usize {
    if let Some(d) = model.solver.macro_degree {
        return d;
    }
    // A curved interface gets the affine modes (up to six); the slenderness rule reads the
    // thickness across a straight interface.
    let Some(normal) = itf.straight_normal() else {
        return 1;
    };
    let thickness = |s: usize| {
        let (lo, hi) =
            model.subdomains[s]
                .mesh
                .coords
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    let h = x[0] * normal[0] + x[1] * normal[1];
                    (lo.min(h), hi.max(h))
                });
        hi - lo
    };
    if itf.length >= SLENDER * thickness(itf.a).min(thickness(itf.b)) {
        5
    } else {
        1
    }
}

/// The macro basis of every interface of `model`, of its [`macro_degree`].
pub fn macro_bases(model: &Model) -> Vec<Vec<Vec<f64>>> {
    model
        .interfaces
        .iter()
        .map(|itf| macro_basis(itf, macro_degree(model, itf)))
        .collect()
}
