//! Physical contact points: the copies of one node pair that sit on several contact interfaces
//! (a cross-point where perfect interfaces meet a contact, docs/method.md, "Cross-points"), grouped as the reference
//! merges them, and the outputs' one value per point.

use crate::laws::{self, Status};
use crate::model::{Interface, InterfaceKind};
use std::collections::BTreeMap;

/// One contact copy of a physical point: interface `interface`, pair `pair`; `swapped` when the
/// copy's side a is the point's side b (the interface was declared the other way round).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointCopy {
    pub interface: usize,
    pub pair: usize,
    pub swapped: bool,
}

/// The contact copies of one physical point and their summed weight Σ m (mm).
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicalPoint {
    pub copies: Vec<PointCopy>,
    pub weight: f64,
}

impl PhysicalPoint {
    /// Σ m·v over the copies, of the point's side a (`side_b` false) or b, where `value(k, p, b)`
    /// is copy (k, p)'s value on its own side b (true) or a.
    pub fn weighted_sum(
        &self,
        interfaces: &[Interface],
        side_b: bool,
        value: impl Fn(usize, usize, bool) -> f64,
    ) -> f64 {
        self.copies
            .iter()
            .map(|c| interfaces[c.interface].weights[c.pair] * value(c.interface, c.pair, side_b != c.swapped))
            .sum()
    }
}

/// Subdomain nodes merged across perfect interfaces (union–find over (subdomain, node)).
struct Merged {
    id: BTreeMap<(usize, usize), (usize, usize)>,
}

impl Merged {
    fn new(interfaces: &[Interface]) -> Self {
        let mut id: BTreeMap<(usize, usize), (usize, usize)> = BTreeMap::new();
        fn find(id: &mut BTreeMap<(usize, usize), (usize, usize)>, x: (usize, usize)) -> (usize, usize) {
            let mut r = x;
            while let Some(&p) = id.get(&r) {
                if p == r {
                    break;
                }
                r = p;
            }
            // Path compression.
            let mut y = x;
            while let Some(&p) = id.get(&y) {
                if p == y {
                    break;
                }
                id.insert(y, r);
                y = p;
            }
            r
        }
        for itf in interfaces.iter().filter(|i| !i.is_contact() && !i.is_non_matching()) {
            for &(na, nb) in &itf.pairs {
                let (a, b) = ((itf.a, na), (itf.b, nb));
                id.entry(a).or_insert(a);
                id.entry(b).or_insert(b);
                let (ra, rb) = (find(&mut id, a), find(&mut id, b));
                if ra != rb {
                    id.insert(ra.max(rb), ra.min(rb));
                }
            }
        }
        let keys: Vec<(usize, usize)> = id.keys().copied().collect();
        for k in keys {
            let r = find(&mut id, k);
            id.insert(k, r);
        }
        Self { id }
    }

    fn of(&self, node: (usize, usize)) -> (usize, usize) {
        self.id.get(&node).copied().unwrap_or(node)
    }
}

/// The contact node pairs grouped into physical points as the reference merges them: copies whose
/// nodes are merged across perfect interfaces (in either order: a copy declared the other way
/// round is `swapped`) and whose normals agree (opposite where swapped) are one point. Two node
/// pairs at one place whose nodes are not merged (either side of a cut that is itself a contact)
/// stay two points. Every contact pair is in exactly one point; points are in order of their
/// first copy.
pub fn contact_points(interfaces: &[Interface]) -> Vec<PhysicalPoint> {
    let merged = Merged::new(interfaces);
    // Normals agree to 1e-9 (they are computed from node coordinates, round-off apart).
    let q = |v: f64| (v * 1e9).round() as i64;
    // (merged node of side a, of side b, normal) → point.
    type Key = ((usize, usize), (usize, usize), [i64; 2]);
    let mut index: BTreeMap<Key, usize> = BTreeMap::new();
    let mut points: Vec<PhysicalPoint> = Vec::new();
    for (k, itf) in interfaces.iter().enumerate() {
        if !itf.is_contact() {
            continue;
        }
        for (p, &(na, nb)) in itf.pairs.iter().enumerate() {
            // Side b of a non-matching interface is a combination of b's nodes, its own at each
            // pair: never one point with another interface's pair.
            let gb = if itf.is_non_matching() {
                (usize::MAX - k, p)
            } else {
                merged.of((itf.b, nb))
            };
            // Side a is its node, or at the middle of an end edge left out the edge's mean: its
            // own then.
            let ga = match &itf.projection_a {
                Some(pa) if pa.terms(p).count() > 1 => (usize::MAX - k, p + (1 << 40)),
                _ => merged.of((itf.a, na)),
            };
            let n = itf.normals[p];
            let swapped = gb < ga;
            let key = if swapped {
                (gb, ga, [q(-n[0]), q(-n[1])])
            } else {
                (ga, gb, [q(n[0]), q(n[1])])
            };
            let at = *index.entry(key).or_insert_with(|| {
                points.push(PhysicalPoint {
                    copies: Vec::new(),
                    weight: 0.0,
                });
                points.len() - 1
            });
            points[at].copies.push(PointCopy {
                interface: k,
                pair: p,
                // Against the key's order for now; against the first copy's below.
                swapped,
            });
            points[at].weight += itf.weights[p];
        }
    }
    oriented_by_first_copy(&mut points);
    points
}

/// Each point's copies oriented against its first copy's (which then reads `swapped` false):
/// `swapped` held each copy's orientation against one common reference (a key's order, a line's
/// direction) until now.
fn oriented_by_first_copy(points: &mut [PhysicalPoint]) {
    for pt in points {
        let first = pt.copies[0].swapped;
        for c in &mut pt.copies {
            c.swapped = c.swapped != first;
        }
    }
}

/// The contact pairs grouped by place: copies at one place whose normals lie on one line (a copy
/// whose normal is opposite to the first's is `swapped`). This is what the errors against a
/// reference compare, because it is what the discrete problem determines: where copies of one
/// node pair sit on several interfaces ([`contact_points`]) only their summed force is, and where
/// distinct contact pairs at one place close a cycle of node copies (parts cut into sectors at
/// the same angles, contact on the cuts and between the layers: four pairs around each
/// cross-point, all in contact) a force circulating around the cycle changes no node's balance,
/// so each pair's force is not determined either, while the sum over the pairs at that place with
/// one normal is. Away from such places a junction is one pair. Junctions are in order of their
/// first copy.
pub fn junctions(interfaces: &[Interface]) -> Vec<PhysicalPoint> {
    let scale = interfaces.iter().map(|i| i.length).fold(0.0, f64::max).max(1.0);
    let q = |v: f64| (v / (1e-9 * scale)).round() as i64;
    let qn = |v: f64| (v * 1e9).round() as i64;
    let mut index: BTreeMap<[i64; 4], usize> = BTreeMap::new();
    let mut points: Vec<PhysicalPoint> = Vec::new();
    for (k, itf) in interfaces.iter().enumerate() {
        if !itf.is_contact() {
            continue;
        }
        for p in 0..itf.n_pairs() {
            let [x, y] = itf.coords[p];
            let n = itf.normals[p];
            // The normal's line: n or −n, whichever has its first clear component positive.
            let flip = if qn(n[0]) != 0 { n[0] < 0.0 } else { n[1] < 0.0 };
            let line = if flip { [-n[0], -n[1]] } else { n };
            let at = *index.entry([q(x), q(y), qn(line[0]), qn(line[1])]).or_insert_with(|| {
                points.push(PhysicalPoint {
                    copies: Vec::new(),
                    weight: 0.0,
                });
                points.len() - 1
            });
            points[at].copies.push(PointCopy {
                interface: k,
                pair: p,
                // Against the line's direction for now; against the first copy's below.
                swapped: flip,
            });
            points[at].weight += itf.weights[p];
        }
    }
    oriented_by_first_copy(&mut points);
    points
}

/// One interface's final fields as column-major slices (2·n_pairs × (N+1) each): W and F of
/// sides a and b of s, then of ŝ, and the status per (pair, time) at p + n_pairs·i.
pub struct FinalColumns<'a> {
    pub values: [&'a mut [f64]; 8],
    pub status: &'a mut [u8],
}

/// The side-b field of each of the eight values: W_a ↔ W_b, F_a ↔ F_b, of s and of ŝ.
const OTHER_SIDE: [usize; 8] = [1, 0, 3, 2, 5, 4, 7, 6];

/// One value per physical point: where copies of one node pair sit on several contact interfaces
/// ([`contact_points`]), only the sum of their nodal forces is determined (docs/method.md, "Cross-points"), and each
/// copy's own traction carries a share of it that depends on the run. Every copy is given the
/// point's values instead: the weighted means Σ m·v / Σ m of W and F of both sides, of s and of
/// ŝ (a swapped copy's sides exchanged); and, where the copies' statuses differ, the status of the
/// point's ŝ traction (separated without compression, stuck strictly inside the cone, else
/// slipping; the first copy's friction coefficient). `fields` is indexed by interface; a point
/// with a copy whose interface has no fields (None), or fields of another shape than its pairs and
/// the first copy's time points, is left as it is.
pub fn one_value_per_point(interfaces: &[Interface], fields: &mut [Option<FinalColumns<'_>>]) {
    for point in contact_points(interfaces) {
        if point.copies.len() < 2
            || point
                .copies
                .iter()
                .any(|c| fields.get(c.interface).is_none_or(Option::is_none))
        {
            continue;
        }
        let first = point.copies[0];
        let rows0 = 2 * interfaces[first.interface].n_pairs();
        let nt = fields[first.interface]
            .as_ref()
            .map_or(0, |f| f.values[0].len() / rows0.max(1));
        let shaped = point.copies.iter().all(|c| {
            let n = interfaces[c.interface].n_pairs();
            fields[c.interface]
                .as_ref()
                .is_some_and(|f| f.values.iter().all(|v| v.len() == 2 * n * nt) && f.status.len() == n * nt)
        });
        if !shaped {
            continue;
        }
        let at = |k: usize, p: usize, c: usize, i: usize| (2 * p + c) + 2 * interfaces[k].n_pairs() * i;
        for i in 0..nt {
            for c in 0..2 {
                // Value v of the point's side a: each copy's v, or its other side's if swapped.
                let mut means = [0.0; 8];
                for (v, mean) in means.iter_mut().enumerate() {
                    *mean = point
                        .copies
                        .iter()
                        .map(|cp| {
                            let f = fields[cp.interface].as_ref().expect("checked above");
                            let own = if cp.swapped { OTHER_SIDE[v] } else { v };
                            interfaces[cp.interface].weights[cp.pair] * f.values[own][at(cp.interface, cp.pair, c, i)]
                        })
                        .sum::<f64>()
                        / point.weight;
                }
                for cp in &point.copies {
                    let f = fields[cp.interface].as_mut().expect("checked above");
                    for (v, &mean) in means.iter().enumerate() {
                        let own = if cp.swapped { OTHER_SIDE[v] } else { v };
                        f.values[own][at(cp.interface, cp.pair, c, i)] = mean;
                    }
                }
            }
            let status_at = |k: usize, p: usize| p + interfaces[k].n_pairs() * i;
            let s0 =
                fields[first.interface].as_ref().expect("checked above").status[status_at(first.interface, first.pair)];
            let agree = point.copies.iter().all(|cp| {
                fields[cp.interface].as_ref().expect("checked above").status[status_at(cp.interface, cp.pair)] == s0
            });
            if agree {
                continue;
            }
            let itf = &interfaces[first.interface];
            // The first copy's ŝ force of its side a, now the point's (with the first copy's sides).
            let hat = &fields[first.interface].as_ref().expect("checked above").values[6];
            let f = [
                hat[at(first.interface, first.pair, 0, i)],
                hat[at(first.interface, first.pair, 1, i)],
            ];
            let (n, t) = (
                laws::dot(f, itf.normal(first.pair)),
                laws::dot(f, itf.tangent(first.pair)),
            );
            let friction = match &itf.kind {
                InterfaceKind::Contact { friction, .. } => *friction,
                InterfaceKind::Perfect => unreachable!("contact_points holds contact pairs only"),
            };
            // Strictly inside the cone by more than round-off: stuck.
            let status = if n >= 0.0 {
                Status::Separated
            } else if t.abs() < friction * n.abs() * (1.0 - 1e-9) {
                Status::Stick
            } else {
                Status::Slip
            } as u8;
            for cp in &point.copies {
                fields[cp.interface].as_mut().expect("checked above").status[status_at(cp.interface, cp.pair)] = status;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An interface of `n` pairs from subdomain a's nodes `na..` to b's nodes `nb..`, along y = 0
    /// from x0 with unit spacing, normal `normal`, weights `weights`.
    fn itf(
        kind: InterfaceKind,
        (a, na): (usize, usize),
        (b, nb): (usize, usize),
        x0: f64,
        normal: [f64; 2],
        weights: Vec<f64>,
    ) -> Interface {
        let n = weights.len();
        Interface {
            kind,
            a,
            b,
            pairs: (0..n).map(|p| (na + p, nb + p)).collect(),
            coords: (0..n).map(|p| [x0 + p as f64, 0.0]).collect(),
            weights,
            normals: vec![normal; n],
            length: (n - 1) as f64,
            centroid: [x0 + 0.5 * (n - 1) as f64, 0.0],
            projection: None,
            projection_a: None,
        }
    }

    fn contact(n: usize) -> InterfaceKind {
        InterfaceKind::Contact {
            friction: 0.3,
            gap: vec![0.0; n],
        }
    }

    /// Four blocks: 0 | 1 below, 2 | 3 above, contacts 0–2 and 1–3 along y = 0 (x 0..2 and 2..4,
    /// three pairs each), the vertical cuts 0–1 and 2–3 perfect (`cut_kind`) meeting the contact
    /// at x = 2: node 2 of block 0 is node 0 of block 1, node 2 of block 2 node 0 of block 3.
    fn four_blocks(cut: InterfaceKind, upper_right_declared_down: bool) -> Vec<Interface> {
        let up = [0.0, 1.0];
        let right_contact = if upper_right_declared_down {
            itf(contact(3), (3, 0), (1, 0), 2.0, [0.0, -1.0], vec![1.0, 4.0, 1.0])
        } else {
            itf(contact(3), (1, 0), (3, 0), 2.0, up, vec![1.0, 4.0, 1.0])
        };
        let vertical = |a: usize, b: usize| Interface {
            kind: cut.clone(),
            a,
            b,
            pairs: vec![(2, 0)],
            coords: vec![[2.0, 0.0]],
            weights: vec![0.5],
            normals: vec![[1.0, 0.0]],
            length: 1.0,
            centroid: [2.0, 0.0],
            projection: None,
            projection_a: None,
        };
        vec![
            itf(
                contact(3),
                (0, 0),
                (2, 0),
                0.0,
                up,
                vec![1.0 / 3.0, 4.0 / 3.0, 1.0 / 3.0],
            ),
            right_contact,
            vertical(0, 1),
            vertical(2, 3),
        ]
    }

    fn copy(interface: usize, pair: usize, swapped: bool) -> PointCopy {
        PointCopy {
            interface,
            pair,
            swapped,
        }
    }

    /// The copies at the cross-point are one point, with the two weights summed; the other pairs
    /// are points of their own; a copy declared the other way round is one point too, swapped.
    #[test]
    fn copies_merged_across_perfect_cuts_are_one_point() {
        for declared_down in [false, true] {
            let points = contact_points(&four_blocks(InterfaceKind::Perfect, declared_down));
            assert_eq!(points.len(), 5, "3 + 3 pairs, two of them one point");
            let cross: Vec<&PhysicalPoint> = points.iter().filter(|p| p.copies.len() > 1).collect();
            assert_eq!(cross.len(), 1);
            assert_eq!(cross[0].copies, vec![copy(0, 2, false), copy(1, 0, declared_down)]);
            assert!((cross[0].weight - (1.0 / 3.0 + 1.0)).abs() < 1e-15);
        }
        // The copy declared the other way round first: the other copy is the swapped one.
        let mut interfaces = four_blocks(InterfaceKind::Perfect, true);
        interfaces.swap(0, 1);
        let points = contact_points(&interfaces);
        let cross: Vec<&PhysicalPoint> = points.iter().filter(|p| p.copies.len() > 1).collect();
        assert_eq!(cross[0].copies, vec![copy(0, 0, false), copy(1, 2, true)]);
    }

    /// Where the cuts are contacts themselves, the two pairs at x = 2 are distinct physical
    /// pairs (block 0's node can leave block 1's): two points at one place.
    #[test]
    fn pairs_at_one_place_across_a_contact_cut_stay_apart() {
        let points = contact_points(&four_blocks(contact(1), false));
        // 3 + 3 pairs on the horizontal contacts, 1 + 1 on the cuts.
        assert_eq!(points.len(), 8);
        assert!(points.iter().all(|p| p.copies.len() == 1));
    }

    /// Junctions: where the cuts are contacts, the two horizontal pairs at x = 2 are one junction
    /// (their summed force is what is determined), the two cut pairs another; a pair declared the
    /// other way round joins its junction swapped; the other pairs are junctions of one pair.
    #[test]
    fn junctions_join_the_pairs_at_one_place_on_one_line() {
        for declared_down in [false, true] {
            let points = junctions(&four_blocks(contact(1), declared_down));
            assert_eq!(
                points.len(),
                6,
                "3 + 3 + 1 + 1 pairs, two pairs of them one junction each"
            );
            assert_eq!(points[2].copies, vec![copy(0, 2, false), copy(1, 0, declared_down)]);
            assert!((points[2].weight - (1.0 / 3.0 + 1.0)).abs() < 1e-15);
            assert_eq!(points[5].copies, vec![copy(2, 0, false), copy(3, 0, false)]);
        }
    }

    /// Copies of merged nodes whose normals differ (a corner) are not one point.
    #[test]
    fn copies_with_other_normals_stay_apart() {
        let mut interfaces = four_blocks(InterfaceKind::Perfect, false);
        interfaces[1].normals[0] = [std::f64::consts::FRAC_1_SQRT_2, std::f64::consts::FRAC_1_SQRT_2];
        assert!(contact_points(&interfaces).iter().all(|p| p.copies.len() == 1));
    }

    /// Each copy at the cross-point is given the point's weighted mean (sides exchanged for a
    /// copy declared the other way round) and the status of its combined ŝ; the other points are
    /// left alone.
    #[test]
    fn copies_of_one_point_get_its_values() {
        for declared_down in [false, true] {
            let interfaces = four_blocks(InterfaceKind::Perfect, declared_down);
            // One time point; rows x, y per pair; sides a, b of s, then of ŝ (W, W, F, F order).
            // Left copy (pair 2 of interface 0): side a (lower) fx 3, fy −10; side b the opposite.
            // Right copy (pair 0 of interface 1): lower side fx −1, fy −12.
            let side = |lower: [f64; 2], v: usize| -> Vec<f64> {
                // v even: side a; a lower-side value, negated on the upper side for forces.
                let sign = if v.is_multiple_of(2) { 1.0 } else { -1.0 };
                let mut out = vec![0.5, -1.0, 0.5, -1.0, 0.5, -1.0];
                out.splice(0..2, [sign * lower[0], sign * lower[1]]);
                out
            };
            let mut v0: Vec<Vec<f64>> = (0..8)
                .map(|v| {
                    let mut x = side([7.0, 7.0], v);
                    let s = if v.is_multiple_of(2) { 1.0 } else { -1.0 };
                    x[4] = s * 3.0;
                    x[5] = s * -10.0;
                    x
                })
                .collect();
            let mut v1: Vec<Vec<f64>> = (0..8usize)
                .map(|v| {
                    // Declared down, side a is the upper block: its values are the lower side's
                    // negated.
                    let s = if v.is_multiple_of(2) != declared_down {
                        1.0
                    } else {
                        -1.0
                    };
                    let mut x = side([5.0, 5.0], v);
                    x[0] = -s;
                    x[1] = s * -12.0;
                    x
                })
                .collect();
            let (mut s0, mut s1) = (vec![1u8, 1, 2], vec![1u8, 1, 1]);
            {
                fn cols(v: &mut [Vec<f64>]) -> [&mut [f64]; 8] {
                    let mut it = v.iter_mut().map(|x| x.as_mut_slice());
                    std::array::from_fn(|_| it.next().expect("eight"))
                }
                let mut fields = vec![
                    Some(FinalColumns {
                        values: cols(&mut v0),
                        status: &mut s0,
                    }),
                    Some(FinalColumns {
                        values: cols(&mut v1),
                        status: &mut s1,
                    }),
                    None,
                    None,
                ];
                one_value_per_point(&interfaces, &mut fields);
            }
            // Lower side: x (3·1/3 − 1·1) / (4/3) = 0; y (−10/3 − 12) / (4/3) = −11.5.
            for v in 0..8usize {
                let lower = if v.is_multiple_of(2) { 1.0 } else { -1.0 };
                assert_eq!([v0[v][4], v0[v][5]], [0.0, lower * -11.5], "field {v}");
                let s1_sign = if v.is_multiple_of(2) != declared_down {
                    1.0
                } else {
                    -1.0
                };
                assert_eq!([v1[v][0], v1[v][1]], [0.0, s1_sign * -11.5], "field {v}");
                assert_eq!(&v0[v][..4], &side([7.0, 7.0], v)[..4], "other pairs left alone");
                assert_eq!(&v1[v][2..], &side([5.0, 5.0], v)[2..], "other pairs left alone");
            }
            // |t| = 0 < 0.3 · 11.5: the point sticks, though one copy slipped.
            assert_eq!((&s0, &s1), (&vec![1, 1, 1], &vec![1, 1, 1]));
        }
    }
}
