//! Interfaces found between subdomains, the `[[interface]]` rules, gaps and the final interfaces.

use super::*;

impl Ctx<'_> {
    /// The interface between subdomains i < j, if their opposite sides share a segment of
    /// positive length; an error if the meshes do not conform there.
    pub(crate) fn find_interface(&self, subs: &[Sub], i: usize, j: usize) -> Result<Option<GeoInterface>, SceneError> {
        let (si, sj) = (&subs[i], &subs[j]);
        let tol = si.tol.max(sj.tol);
        // (a, b, horizontal): a below / left of b.
        let candidates = [
            (i, j, true, (si.y[1] - sj.y[0]).abs() <= tol),
            (j, i, true, (sj.y[1] - si.y[0]).abs() <= tol),
            (i, j, false, (si.x[1] - sj.x[0]).abs() <= tol),
            (j, i, false, (sj.x[1] - si.x[0]).abs() <= tol),
        ];
        for (a, b, horizontal, touching) in candidates {
            if !touching {
                continue;
            }
            let (sa, sb) = (&subs[a], &subs[b]);
            // `axis`: coordinate along the interface.
            let (axis, side_a, side_b, ra, rb, line) = if horizontal {
                (
                    0,
                    BlockSide::Top,
                    BlockSide::Bottom,
                    sa.x,
                    sb.x,
                    format!("y = {}", fmt_num(sa.y[1])),
                )
            } else {
                (
                    1,
                    BlockSide::Right,
                    BlockSide::Left,
                    sa.y,
                    sb.y,
                    format!("x = {}", fmt_num(sa.x[1])),
                )
            };
            let lo = ra[0].max(rb[0]);
            let hi = ra[1].min(rb[1]);
            if hi - lo <= tol {
                continue;
            }
            let axis_name = if axis == 0 { "x" } else { "y" };
            let key = format!("block[{}]", sa.block.max(sb.block));
            let within = |c: f64| c >= lo - tol && c <= hi + tol;
            // (node, coordinate along, is a corner node) of each side within the overlap.
            let collect = |s: &Sub, side: BlockSide| -> Vec<(usize, f64, bool)> {
                s.mesh
                    .side_nodes(side)
                    .into_iter()
                    .enumerate()
                    .map(|(k, n)| (n, s.mesh.coords[n][axis], k % 2 == 0))
                    .filter(|&(_, c, _)| within(c))
                    .collect()
            };
            let mismatch = |c: f64, why: &str| {
                self.err(
                    key.clone(),
                    format!(
                        "subdomains `{}` and `{}` share the segment {axis_name} ∈ [{}, {}] of the line {line} but their \
                         meshes do not conform: {why} at {axis_name} = {}",
                        sa.name,
                        sb.name,
                        fmt_num(lo),
                        fmt_num(hi),
                        fmt_num(c)
                    ),
                )
            };
            let na = collect(sa, side_a);
            let nb = collect(sb, side_b);
            if na.is_empty() || nb.is_empty() {
                return Err(mismatch(lo, "no node of one side lies on the shared segment"));
            }
            let conforming = na.len() == nb.len()
                && na
                    .iter()
                    .zip(&nb)
                    .all(|(&(_, ca, corner_a), &(_, cb, corner_b))| (ca - cb).abs() <= tol && corner_a == corner_b);
            if !conforming {
                // Non-matching: the interface's pairs are the nodes of a side whose edges end at
                // both ends of the shared segment (a, or b with the roles swapped).
                let normal = if horizontal { [0.0, 1.0] } else { [1.0, 0.0] };
                let ends_whole = |n: &[(usize, f64, bool)]| {
                    let (first, last) = (n[0], n[n.len() - 1]);
                    first.2 && last.2 && (first.1 - lo).abs() <= tol && (last.1 - hi).abs() <= tol
                };
                // Of two such sides the coarser (fewer nodes on the segment): a finer Γ_h would
                // carry traction modes the other side cannot see, which no iteration settles.
                let (whole_a, whole_b) = (ends_whole(&na), ends_whole(&nb));
                let (pa, pb, ea, eb, sign) = if whole_a && (!whole_b || na.len() <= nb.len()) {
                    (a, b, side_a, side_b, 1.0)
                } else if whole_b {
                    (b, a, side_b, side_a, -1.0)
                } else {
                    return Err(mismatch(
                        lo,
                        "the meshes do not conform and an element edge of each side crosses an end of the shared \
                         segment (a non-matching interface needs one side whose edges end at both ends)",
                    ));
                };
                let g = self
                    .block_non_matching(
                        (&subs[pa], ea),
                        (&subs[pb], eb),
                        axis,
                        [lo, hi],
                        tol,
                        [sign * normal[0], sign * normal[1]],
                    )
                    .map_err(|why| mismatch(lo, &why))?;
                return Ok(Some(GeoInterface { a: pa, b: pb, ..g }));
            }
            for (k, &(_, ca, corner_a)) in na.iter().enumerate() {
                if (k == 0 || k + 1 == na.len()) && !corner_a {
                    return Err(mismatch(ca, "an element edge crosses the end of the shared segment"));
                }
            }
            let mut pair_of = vec![usize::MAX; sa.mesh.n_nodes()];
            for (p, &(n, _, _)) in na.iter().enumerate() {
                pair_of[n] = p;
            }
            let mut weights = vec![0.0; na.len()];
            let mut length = 0.0;
            for e in &sa.mesh.sides[side_a as usize] {
                if !(within(sa.mesh.coords[e[0]][axis]) && within(sa.mesh.coords[e[2]][axis])) {
                    continue;
                }
                let x = [sa.mesh.coords[e[0]], sa.mesh.coords[e[1]], sa.mesh.coords[e[2]]];
                for (k, m) in edge_lumped_mass(&x, self.plane).into_iter().enumerate() {
                    weights[pair_of[e[k]]] += m;
                }
                length += ((x[2][0] - x[0][0]).powi(2) + (x[2][1] - x[0][1]).powi(2)).sqrt();
            }
            let normal = if horizontal { [0.0, 1.0] } else { [1.0, 0.0] };
            return Ok(Some(GeoInterface {
                a,
                b,
                normals: vec![normal; na.len()],
                pairs: na.iter().zip(&nb).map(|(&(n, _, _), &(m, _, _))| (n, m)).collect(),
                coords: na.iter().map(|&(n, _, _)| sa.mesh.coords[n]).collect(),
                weights,
                length,
                curves: Vec::new(),
                projection: None,
                sides: None,
            }));
        }
        Ok(None)
    }

    /// A non-matching interface between block sides: pairs are the nodes of `a`'s side on the
    /// shared segment `range` (whose edges end at both of its ends), side b reaches them through
    /// its projection ([`glissade_mechanics::mortar`]). `a`, `b` in the result are placeholders
    /// for the caller.
    fn block_non_matching(
        &self,
        (sa, side_a): (&Sub, BlockSide),
        (sb, side_b): (&Sub, BlockSide),
        axis: usize,
        [lo, hi]: [f64; 2],
        tol: f64,
        normal: [f64; 2],
    ) -> Result<GeoInterface, String> {
        let within = |c: f64| c >= lo - tol && c <= hi + tol;
        let edges_of = |s: &Sub, side: BlockSide, whole: bool| -> Vec<[usize; 3]> {
            s.mesh.sides[side as usize]
                .iter()
                .filter(|e| {
                    let (c0, c2) = (s.mesh.coords[e[0]][axis], s.mesh.coords[e[2]][axis]);
                    if whole {
                        within(c0) && within(c2)
                    } else {
                        c0.max(c2).min(hi) - c0.min(c2).max(lo) > tol
                    }
                })
                .copied()
                .collect()
        };
        let a_edges = edges_of(sa, side_a, true);
        let b_edges = edges_of(sb, side_b, false);
        let nodes = sa
            .mesh
            .side_nodes(side_a)
            .into_iter()
            .filter(|&n| within(sa.mesh.coords[n][axis]))
            .collect::<Vec<_>>();
        let mut pair_of = std::collections::HashMap::new();
        for (p, &n) in nodes.iter().enumerate() {
            pair_of.insert(n, p);
        }
        let mut weights = vec![0.0; nodes.len()];
        let mut length = 0.0;
        let mut a_side = Vec::with_capacity(a_edges.len());
        for e in &a_edges {
            let x = e.map(|n| sa.mesh.coords[n]);
            for (k, m) in edge_lumped_mass(&x, self.plane).into_iter().enumerate() {
                weights[pair_of[&e[k]]] += m;
            }
            length += ((x[2][0] - x[0][0]).powi(2) + (x[2][1] - x[0][1]).powi(2)).sqrt();
            a_side.push(SideEdge {
                nodes: e.map(|n| pair_of[&n]),
                x,
            });
        }
        let b_side: Vec<SideEdge> = b_edges
            .iter()
            .map(|e| SideEdge {
                nodes: *e,
                x: e.map(|n| sb.mesh.coords[n]),
            })
            .collect();
        let coords: Vec<[f64; 2]> = nodes.iter().map(|&n| sa.mesh.coords[n]).collect();
        let projection = project(&a_side, &weights, &b_side, self.plane, &coords).map_err(|e| e.to_string())?;
        Ok(GeoInterface {
            a: 0,
            b: 0,
            normals: vec![normal; nodes.len()],
            pairs: nodes
                .iter()
                .enumerate()
                .map(|(p, &n)| (n, projection.largest_term(p)))
                .collect(),
            coords,
            weights,
            length,
            curves: Vec::new(),
            projection: Some(projection),
            sides: Some((a_side, b_side)),
        })
    }

    /// Kind of each geometric interface after applying the `[[interface]]` rules in order.
    pub(crate) fn interface_rules(
        &self,
        raw: &RawScene,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        geo: &[GeoInterface],
        curve_names: &[String],
    ) -> Result<Vec<KindRule>, SceneError> {
        let mut kinds = vec![KindRule::Perfect; geo.len()];
        for (r, rule) in raw.interface.iter().enumerate() {
            let key = format!("interface[{r}]");
            // Which interfaces the rule selects: between two names, or along a named curve.
            let selects: Box<dyn Fn(&GeoInterface) -> bool> = match (&rule.between, &rule.curve) {
                (Some(between), None) => {
                    let (s0, _) = self.resolve(names, subs, &between[0], &format!("{key}.between"))?;
                    let (s1, _) = self.resolve(names, subs, &between[1], &format!("{key}.between"))?;
                    Box::new(move |itf: &GeoInterface| {
                        (s0.contains(&itf.a) && s1.contains(&itf.b)) || (s0.contains(&itf.b) && s1.contains(&itf.a))
                    })
                }
                (None, Some(curve)) => {
                    let Some(c) = curve_names.iter().position(|n| n == curve) else {
                        return Err(self.err(
                            format!("{key}.curve"),
                            if curve_names.is_empty() {
                                format!("`{curve}`: only a scene with a [mesh] has named curves")
                            } else {
                                format!("unknown curve `{curve}` (the mesh names: {})", curve_names.join(", "))
                            },
                        ));
                    };
                    Box::new(move |itf: &GeoInterface| itf.curves.contains(&c))
                }
                (Some(_), Some(_)) => {
                    return Err(self.err(key, "give either `between` or `curve`, not both"));
                }
                (None, None) => {
                    return Err(self.err(
                        key,
                        "selects no interface: give `between = [name, name]` (blocks, parts or name prefixes) or \
                         `curve = name` (a named curve of the mesh)",
                    ));
                }
            };
            let kind = match rule.kind {
                RawKind::Perfect => {
                    if rule.friction.is_some() {
                        return Err(self.err(
                            format!("{key}.friction"),
                            "`friction` applies to contact interfaces only",
                        ));
                    }
                    if rule.gap.is_some() {
                        return Err(self.err(format!("{key}.gap"), "`gap` applies to contact interfaces only"));
                    }
                    KindRule::Perfect
                }
                RawKind::Contact => {
                    let Some(f) = rule.friction else {
                        return Err(self.err(
                            format!("{key}.friction"),
                            "a contact interface needs `friction` (0 for frictionless contact)",
                        ));
                    };
                    self.check(f >= 0.0 && f.is_finite(), &format!("{key}.friction"), || {
                        format!("friction coefficient {f} must be a finite number ≥ 0")
                    })?;
                    KindRule::Contact(r)
                }
            };
            let mut matched = false;
            for (g, itf) in geo.iter().enumerate() {
                if selects(itf) {
                    kinds[g] = kind;
                    matched = true;
                }
            }
            if !matched {
                return Err(match (&rule.between, &rule.curve) {
                    (Some(between), _) => self.err(
                        format!("{key}.between"),
                        format!("`{}` and `{}` share no edge", between[0], between[1]),
                    ),
                    (_, curve) => self.err(
                        format!("{key}.curve"),
                        format!("no interface lies on curve `{}`", curve.as_deref().unwrap_or_default()),
                    ),
                });
            }
        }
        Ok(kinds)
    }

    pub(crate) fn gap_specs(&self, raw: &RawScene) -> Result<Vec<Option<GapSpec>>, SceneError> {
        raw.interface
            .iter()
            .enumerate()
            .map(|(r, rule)| {
                let key = format!("interface[{r}].gap");
                let Some(v) = &rule.gap else { return Ok(None) };
                let spec = match v {
                    toml::Value::Integer(i) => GapSpec::Constant(*i as f64),
                    toml::Value::Float(f) => GapSpec::Constant(*f),
                    toml::Value::String(s) => {
                        GapSpec::Formula(Expr::parse(s, &["x", "y"]).map_err(|e| self.err(&key, e.to_string()))?)
                    }
                    toml::Value::Table(t) => {
                        let (axis, xs, gs) = self.table(t, &key, &["x", "y"], "g")?;
                        GapSpec::Table { axis, xs, gs }
                    }
                    other => {
                        return Err(self.err(
                            key,
                            format!(
                                "expected a number, a formula in x, y (string) or a table {{ x = [..], g = [..] }}, \
                                 found {}",
                                other.type_str()
                            ),
                        ))
                    }
                };
                Ok(Some(spec))
            })
            .collect()
    }

    /// Final interfaces: kinds and gaps, pairs clamped on both sides left out (in axisymmetry
    /// also the pairs on the axis: their u_r is held on both sides and their weight, ∫ N 2πr ds,
    /// is zero, so they carry no force), empty interfaces dropped, centroids.
    pub(crate) fn finish_interfaces(
        &self,
        raw: &RawScene,
        geo: Vec<GeoInterface>,
        kinds: &[KindRule],
        gaps: &[Option<GapSpec>],
        loads: &[SubLoads],
    ) -> Result<Vec<Interface>, SceneError> {
        let clamped = |s: usize, n: usize| loads[s].constrained[2 * n] && loads[s].constrained[2 * n + 1];
        let radial_held = |s: usize, n: usize| loads[s].constrained[2 * n];
        let mut out = Vec::new();
        // How many interfaces hold each (subdomain, node): a pair's own node on side a, or a
        // conforming side b's.
        let mut members: std::collections::HashMap<(usize, usize), usize> = std::collections::HashMap::new();
        for g in &geo {
            for &(na, nb) in &g.pairs {
                *members.entry((g.a, na)).or_default() += 1;
                if g.projection.is_none() {
                    *members.entry((g.b, nb)).or_default() += 1;
                }
            }
            // A non-matching interface holds each node of its side b's projections once.
            if let Some(pr) = &g.projection {
                let mut nodes = pr.nodes.clone();
                nodes.sort_unstable();
                nodes.dedup();
                for n in nodes {
                    *members.entry((g.b, n)).or_default() += 1;
                }
            }
        }
        for (mut g, kind) in geo.into_iter().zip(kinds) {
            // A non-matching interface that ends on a support of side a, or where another
            // interface holds its end node, leaves that end pair out (the crosspoint
            // modification, glissade_mechanics::mortar::project_with_ends).
            let mut dropped = vec![false; g.pairs.len()];
            let mut projection_a = None;
            if let Some((a_edges, b_edges)) = &g.sides {
                let end = end_pairs(a_edges, g.pairs.len());
                for (p, d) in dropped.iter_mut().enumerate() {
                    let na = g.pairs[p].0;
                    *d = end[p] && (clamped(g.a, na) || members[&(g.a, na)] > 1);
                }
                if dropped.iter().any(|&d| d) {
                    let pr = project_with_ends(a_edges, &g.weights, b_edges, self.plane, &g.coords, &dropped)
                        .map_err(|e| self.err("interface", format!("a non-matching interface: {e}")))?;
                    let mut a = pr.a;
                    for n in a.nodes.iter_mut() {
                        *n = g.pairs[*n].0;
                    }
                    projection_a = Some(a);
                    g.weights = pr.weights;
                    g.projection = Some(pr.b);
                }
            }
            let heaviest = g.weights.iter().fold(0.0f64, |m, w| m.max(w.abs()));
            // Side b's nodes at pair p: the one facing it, or every node of its projection.
            let b_nodes = |p: usize| -> Vec<usize> {
                match &g.projection {
                    Some(pr) => pr.terms(p).map(|(n, _)| n).collect(),
                    None => vec![g.pairs[p].1],
                }
            };
            let on_axis = |p: usize| {
                self.plane == Plane::Axisymmetric
                    && g.weights[p].abs() <= glissade_mechanics::element::AXIS_TOLERANCE * heaviest
                    && radial_held(g.a, g.pairs[p].0)
                    && b_nodes(p).iter().all(|&n| radial_held(g.b, n))
            };
            let keep: Vec<usize> = (0..g.pairs.len())
                .filter(|&p| {
                    // A pair whose test function is zero everywhere (its only edge is a modified
                    // end edge) carries nothing: left out too.
                    !(dropped[p]
                        || projection_a.is_some() && g.weights[p] == 0.0
                        || on_axis(p)
                        || clamped(g.a, g.pairs[p].0) && b_nodes(p).iter().all(|&n| clamped(g.b, n)))
                })
                .collect();
            if keep.is_empty() {
                continue;
            }
            let pairs: Vec<(usize, usize)> = keep.iter().map(|&p| g.pairs[p]).collect();
            let coords: Vec<[f64; 2]> = keep.iter().map(|&p| g.coords[p]).collect();
            let weights: Vec<f64> = keep.iter().map(|&p| g.weights[p]).collect();
            let normals: Vec<[f64; 2]> = keep.iter().map(|&p| g.normals[p]).collect();
            let kind = match *kind {
                KindRule::Perfect => InterfaceKind::Perfect,
                KindRule::Contact(r) => {
                    let friction = raw.interface[r].friction.unwrap_or(0.0);
                    let mut gap = Vec::with_capacity(coords.len());
                    for &c in &coords {
                        let g0 = gaps[r].as_ref().map_or(0.0, |spec| spec.eval(c));
                        self.check(g0.is_finite(), &format!("interface[{r}].gap"), || {
                            format!("gap {g0} at (x, y) = ({}, {}) is not finite", c[0], c[1])
                        })?;
                        gap.push(g0);
                    }
                    InterfaceKind::Contact { friction, gap }
                }
            };
            let total: f64 = weights.iter().sum();
            let mut centroid = [0.0; 2];
            for (w, c) in weights.iter().zip(&coords) {
                centroid[0] += w * c[0] / total;
                centroid[1] += w * c[1] / total;
            }
            out.push(Interface {
                kind,
                a: g.a,
                b: g.b,
                pairs,
                coords,
                weights,
                normals,
                length: g.length,
                centroid,
                projection: g.projection.as_ref().map(|pr| pr.select(&keep)),
                projection_a: projection_a.as_ref().map(|pr| pr.select(&keep)),
            });
        }
        Ok(out)
    }
}
