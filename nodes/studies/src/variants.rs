//! The variants of a study's design, in the order they are solved, and for each the solved
//! variant it starts from.

use crate::study::{Design, Study};

/// One variant: its number (in solving order, from 0) and one value per parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub index: usize,
    pub values: Vec<f64>,
}

/// The variants of `study` in solving order. A grid is walked as a snake (a reflected
/// mixed-radix Gray code): each variant differs from the one before in one parameter, by one
/// step of its list, so that each has a solved neighbour. A sample is drawn from `seed` and then
/// ordered greedily, each variant the nearest unsolved one to those before.
pub fn variants(study: &Study) -> Vec<Variant> {
    let values: Vec<Vec<f64>> = match study.design {
        Design::Grid => {
            let counts: Vec<usize> = study.parameters.iter().map(|p| p.values.len()).collect();
            snake(&counts)
                .into_iter()
                .map(|idx| idx.iter().zip(&study.parameters).map(|(&i, p)| p.values[i]).collect())
                .collect()
        }
        Design::Sample { count, seed } => {
            let mut rng = SplitMix64(seed);
            let drawn: Vec<Vec<f64>> = (0..count)
                .map(|_| {
                    study
                        .parameters
                        .iter()
                        .map(|p| {
                            let (lo, hi) = bounds(&p.values);
                            lo + rng.unit() * (hi - lo)
                        })
                        .collect()
                })
                .collect();
            greedy_order(study, drawn)
        }
    };
    values
        .into_iter()
        .enumerate()
        .map(|(index, values)| Variant { index, values })
        .collect()
}

/// The smallest and largest of `values`.
fn bounds(values: &[f64]) -> (f64, f64) {
    values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
        (lo.min(v), hi.max(v))
    })
}

/// Index tuples of the product of `counts` in reflected Gray order (the first index slowest).
fn snake(counts: &[usize]) -> Vec<Vec<usize>> {
    let Some((&n, rest)) = counts.split_first() else {
        return vec![Vec::new()];
    };
    let inner = snake(rest);
    let mut out = Vec::with_capacity(n * inner.len());
    for i in 0..n {
        let mut block: Vec<Vec<usize>> = inner
            .iter()
            .map(|t| std::iter::once(i).chain(t.iter().copied()).collect())
            .collect();
        if i % 2 == 1 {
            block.reverse();
        }
        out.extend(block);
    }
    out
}

/// `drawn` reordered: the first as drawn, then each time the nearest to any already placed
/// (each candidate's distance to the placed ones kept up to date: n² distances in all).
fn greedy_order(study: &Study, drawn: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    let n = drawn.len();
    let mut placed = vec![false; n];
    let mut nearest = vec![f64::INFINITY; n];
    let mut order = Vec::with_capacity(n);
    let mut last = 0;
    for step in 0..n {
        if step > 0 {
            last = (0..n)
                .filter(|&i| !placed[i])
                .min_by(|&a, &b| nearest[a].total_cmp(&nearest[b]).then(a.cmp(&b)))
                .unwrap_or(0);
        }
        placed[last] = true;
        order.push(last);
        for i in (0..n).filter(|&i| !placed[i]) {
            nearest[i] = nearest[i].min(distance(study, &drawn[last], &drawn[i]));
        }
    }
    let mut drawn: Vec<Option<Vec<f64>>> = drawn.into_iter().map(Some).collect();
    order.into_iter().filter_map(|i| drawn[i].take()).collect()
}

/// The distance between two variants' values, each parameter measured in its own span (its
/// largest minus its smallest value; 1 where it has one value).
pub fn distance(study: &Study, a: &[f64], b: &[f64]) -> f64 {
    study
        .parameters
        .iter()
        .zip(a.iter().zip(b))
        .map(|(p, (x, y))| {
            let (lo, hi) = bounds(&p.values);
            let span = if hi > lo { hi - lo } else { 1.0 };
            ((x - y) / span).powi(2)
        })
        .sum::<f64>()
        .sqrt()
}

/// Of the variants `solved` (those with a state to start from), the nearest to `v`; the earliest
/// solved among equally near ones.
pub fn nearest<'a>(study: &Study, v: &Variant, solved: impl IntoIterator<Item = &'a Variant>) -> Option<&'a Variant> {
    solved
        .into_iter()
        .map(|s| (distance(study, &s.values, &v.values), s))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.index.cmp(&b.1.index)))
        .map(|(_, s)| s)
}

/// SplitMix64 (Steele, Lea and Flood 2014): a small generator whose sequence is fixed by its
/// seed on every platform, which is all a seeded sample (and the validation set's scenes) need.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::{Parameter, Target};

    fn study(lists: &[Vec<f64>], design: Design) -> Study {
        Study {
            name: "s".into(),
            scene: "s.toml".into(),
            parameters: lists
                .iter()
                .enumerate()
                .map(|(i, v)| Parameter {
                    name: format!("interface[{i}].friction"),
                    target: Target::Friction { rule: Some(i) },
                    values: v.clone(),
                })
                .collect(),
            design,
            accuracy: None,
            report: Vec::new(),
        }
    }

    /// Every combination once, and each variant one step from the one before in one parameter.
    #[test]
    fn a_grid_is_walked_one_step_at_a_time() {
        let s = study(
            &[vec![1.0, 2.0, 3.0], vec![10.0, 20.0], vec![0.5, 0.6, 0.7, 0.8]],
            Design::Grid,
        );
        let v = variants(&s);
        assert_eq!(v.len(), 24);
        let mut seen: Vec<Vec<u64>> = v
            .iter()
            .map(|x| x.values.iter().map(|f| f.to_bits()).collect())
            .collect();
        seen.sort();
        seen.dedup();
        assert_eq!(seen.len(), 24);
        for w in v.windows(2) {
            let changed: Vec<usize> = (0..3).filter(|&k| w[0].values[k] != w[1].values[k]).collect();
            assert_eq!(changed.len(), 1, "{:?} → {:?}", w[0].values, w[1].values);
            let p = &s.parameters[changed[0]].values;
            let at = |x: f64| p.iter().position(|&y| y == x).unwrap();
            assert_eq!(at(w[0].values[changed[0]]).abs_diff(at(w[1].values[changed[0]])), 1);
        }
        assert_eq!(
            v.iter().map(|x| x.index).collect::<Vec<_>>(),
            (0..24).collect::<Vec<_>>()
        );
    }

    /// A seeded sample is the same for the same seed, stays within each parameter's bounds, and
    /// differs for another seed.
    #[test]
    fn a_sample_is_fixed_by_its_seed() {
        let s = study(
            &[vec![0.1, 0.3], vec![-1.0, 1.0]],
            Design::Sample { count: 12, seed: 7 },
        );
        let (a, b) = (variants(&s), variants(&s));
        assert_eq!(a, b);
        assert!(a
            .iter()
            .all(|v| (0.1..=0.3).contains(&v.values[0]) && (-1.0..=1.0).contains(&v.values[1])));
        let other = variants(&study(
            &[vec![0.1, 0.3], vec![-1.0, 1.0]],
            Design::Sample { count: 12, seed: 8 },
        ));
        assert_ne!(a, other);
    }

    #[test]
    fn the_nearest_solved_variant_is_measured_in_each_parameters_span() {
        let s = study(&[vec![0.1, 0.2, 0.3], vec![0.0, 100.0]], Design::Grid);
        let solved = [
            Variant {
                index: 0,
                values: vec![0.1, 50.0],
            },
            Variant {
                index: 1,
                values: vec![0.3, 60.0],
            },
        ];
        // 0.2 apart in friction (a span of 0.2) is as far as 100 in the other (a span of 100).
        let v = Variant {
            index: 2,
            values: vec![0.1, 100.0],
        };
        assert_eq!(nearest(&s, &v, &solved).unwrap().index, 0);
        let v = Variant {
            index: 2,
            values: vec![0.3, 0.0],
        };
        assert_eq!(nearest(&s, &v, &solved).unwrap().index, 1);
        assert!(nearest(&s, &v, &[]).is_none());
    }
}
