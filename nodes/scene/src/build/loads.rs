//! Tables, time functions and the `[[boundary]]` rules: prescribed displacements and loads.

use super::*;
use glissade_mechanics::element::edge_load_along;

impl Ctx<'_> {
    /// A piecewise-linear table `{ <abscissa> = [..], <ordinate> = [..] }` with one abscissa name
    /// out of `abscissae`; returns (which abscissa, abscissae, values).
    pub(crate) fn table(
        &self,
        t: &toml::Table,
        key: &str,
        abscissae: &[&str],
        ordinate: &str,
    ) -> Result<(usize, Vec<f64>, Vec<f64>), SceneError> {
        let expected = abscissae
            .iter()
            .map(|a| format!("{{ {a} = [..], {ordinate} = [..] }}"))
            .collect::<Vec<_>>()
            .join(" or ");
        let bad = |why: String| self.err(key, format!("bad table: {why} (expected {expected})"));
        for k in t.keys() {
            if k != ordinate && !abscissae.contains(&k.as_str()) {
                return Err(bad(format!("unknown key `{k}`")));
            }
        }
        let present: Vec<usize> = (0..abscissae.len()).filter(|&i| t.contains_key(abscissae[i])).collect();
        if present.len() != 1 || !t.contains_key(ordinate) {
            return Err(bad("needs exactly one abscissa array and the value array".to_string()));
        }
        let axis = present[0];
        let numbers = |name: &str| -> Result<Vec<f64>, SceneError> {
            let Some(toml::Value::Array(a)) = t.get(name) else {
                return Err(bad(format!("`{name}` is not an array")));
            };
            a.iter()
                .map(|v| match v {
                    toml::Value::Integer(i) => Ok(*i as f64),
                    toml::Value::Float(f) if f.is_finite() => Ok(*f),
                    other => Err(bad(format!(
                        "`{name}` holds {} `{other}`, not a finite number",
                        other.type_str()
                    ))),
                })
                .collect()
        };
        let xs = numbers(abscissae[axis])?;
        let vs = numbers(ordinate)?;
        let a = abscissae[axis];
        if xs.is_empty() {
            return Err(bad(format!("`{a}` is empty")));
        }
        if xs.len() != vs.len() {
            return Err(bad(format!(
                "`{a}` has {} entries but `{ordinate}` has {}",
                xs.len(),
                vs.len()
            )));
        }
        if let Some(k) = (1..xs.len()).find(|&k| xs[k] <= xs[k - 1]) {
            return Err(bad(format!(
                "`{a}` is not strictly increasing: {a}[{k}] = {} ≤ {a}[{}] = {}",
                xs[k],
                k - 1,
                xs[k - 1]
            )));
        }
        Ok((axis, xs, vs))
    }

    pub(crate) fn time_function(
        &self,
        value: &toml::Value,
        key: &str,
        time: TimeGrid,
    ) -> Result<TimeFunction, SceneError> {
        let tf = match value {
            toml::Value::Integer(i) => TimeFunction::Constant(*i as f64),
            toml::Value::Float(f) => TimeFunction::Constant(*f),
            toml::Value::String(s) => {
                TimeFunction::Formula(Expr::parse(s, &["t"]).map_err(|e| self.err(key, e.to_string()))?)
            }
            toml::Value::Table(t) => {
                let (_, ts, vs) = self.table(t, key, &["t"], "v")?;
                TimeFunction::Table { t: ts, v: vs }
            }
            other => {
                return Err(self.err(
                    key,
                    format!(
                        "expected a number, a formula in t (string) or a table {{ t = [..], v = [..] }}, found {}",
                        other.type_str()
                    ),
                ))
            }
        };
        for i in 0..time.n_points() {
            let t = time.t(i);
            let v = tf.eval(t);
            self.check(v.is_finite(), key, || format!("value {v} at t = {t} is not finite"))?;
        }
        Ok(tf)
    }

    /// A boundary value as written: uniform along the boundary (a number, a formula in t or a
    /// table in t), or a formula in x, y (and t).
    pub(crate) fn boundary_value(
        &self,
        value: &toml::Value,
        key: &str,
        time: TimeGrid,
    ) -> Result<BoundaryValue, SceneError> {
        if let toml::Value::String(s) = value {
            if Expr::parse(s, &["t"]).is_err() {
                if let Ok(e) = Expr::parse(s, &["x", "y"]) {
                    return Ok(BoundaryValue::Field { expr: e, timed: false });
                }
                let e = Expr::parse(s, &["x", "y", "t"]).map_err(|e| self.err(key, e.to_string()))?;
                return Ok(BoundaryValue::Field { expr: e, timed: true });
            }
        }
        Ok(BoundaryValue::Uniform(self.time_function(value, key, time)?))
    }

    /// Load cases (pattern, time function) of a field value: `sample(t)` is the full-length
    /// pattern at time t. A field without t is one case; one with t is sampled at every time
    /// point and compressed to its rank (greedy Gram–Schmidt on the time columns down to 1e-13 of
    /// the largest column), each case's time function the table of its coefficients on the grid,
    /// so the loads are exact at the time points to round-off.
    pub(crate) fn field_cases(
        &self,
        time: TimeGrid,
        timed: bool,
        sample: impl Fn(f64) -> Result<Vec<f64>, SceneError>,
    ) -> Result<Vec<(Vec<f64>, TimeFunction)>, SceneError> {
        if !timed {
            return Ok(vec![(sample(0.0)?, TimeFunction::Constant(1.0))]);
        }
        let times: Vec<f64> = (0..time.n_points()).map(|i| time.t(i)).collect();
        let columns = times.iter().map(|&t| sample(t)).collect::<Result<Vec<_>, _>>()?;
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let largest = columns.iter().map(|c| dot(c, c).sqrt()).fold(0.0, f64::max);
        let mut residual = columns.clone();
        let mut basis: Vec<Vec<f64>> = Vec::new();
        loop {
            let (j, norm) = residual
                .iter()
                .enumerate()
                .map(|(j, r)| (j, dot(r, r).sqrt()))
                .fold((0, 0.0), |best, c| if c.1 > best.1 { c } else { best });
            if norm <= 1e-13 * largest || norm == 0.0 || basis.len() == columns.len() {
                break;
            }
            let mut q: Vec<f64> = residual[j].iter().map(|v| v / norm).collect();
            for b in &basis {
                let c = dot(&q, b);
                q.iter_mut().zip(b).for_each(|(x, y)| *x -= c * y);
            }
            let n = dot(&q, &q).sqrt();
            q.iter_mut().for_each(|x| *x /= n);
            for r in &mut residual {
                let c = dot(r, &q);
                r.iter_mut().zip(&q).for_each(|(x, y)| *x -= c * y);
            }
            basis.push(q);
        }
        Ok(basis
            .into_iter()
            .map(|q| {
                let v = columns.iter().map(|c| dot(c, &q)).collect();
                (q, TimeFunction::Table { t: times.clone(), v })
            })
            .collect())
    }

    /// Evaluates a field formula at `x` and time `t`, refusing a value that is not finite.
    fn field_at(&self, expr: &Expr, timed: bool, x: [f64; 2], t: f64, key: &str) -> Result<f64, SceneError> {
        let v = if timed {
            expr.eval(&[x[0], x[1], t])
        } else {
            expr.eval(&x)
        };
        self.check(v.is_finite(), key, || {
            format!("value {v} at (x, y) = ({}, {}), t = {t} is not finite", x[0], x[1])
        })?;
        Ok(v)
    }

    /// Prescribes `cases` (full-length patterns and their time functions) at `dofs` of one
    /// subdomain: a later rule takes the dofs over from an earlier one.
    fn prescribe(sl: &mut SubLoads, rule: usize, dofs: &[usize], cases: Vec<(Vec<f64>, TimeFunction)>) {
        let first = sl.loads.len();
        let last = first + cases.len();
        for &dof in dofs {
            sl.constrained[dof] = true;
            sl.dof_rule[dof] = Some(rule);
            let (p0, p1) = sl.owner[dof];
            for prev in p0..p1 {
                if prev < first {
                    sl.loads[prev].displacement[dof] = 0.0;
                }
            }
            sl.owner[dof] = (first, last);
        }
        for (pattern, time) in cases {
            sl.loads.push(LoadCase {
                force: vec![0.0; pattern.len()],
                displacement: pattern,
                time,
            });
            sl.case_rule.push(rule);
        }
    }

    /// Constraints and load cases of every subdomain from the `[[boundary]]` rules.
    pub(crate) fn boundaries(
        &self,
        raw: &RawScene,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        time: TimeGrid,
    ) -> Result<Vec<SubLoads>, SceneError> {
        let mut out = empty_loads(subs);
        for (r, rule) in raw.boundary.iter().enumerate() {
            let key = format!("boundary[{r}]");
            self.check_boundary_rule(rule, &key)?;
            if let Some(curve) = &rule.curve {
                return Err(self.err(
                    format!("{key}.curve"),
                    format!("`{curve}`: only a scene with a [mesh] has named curves (blocks use side, x, y)"),
                ));
            }
            if rule.side.is_none() && rule.x.is_none() && rule.y.is_none() {
                return Err(self.err(key, "selects no side: give `side`, `x` or `y`"));
            }
            let selected = self.select_sides(rule, names, subs, &key)?;
            // Block sides run in increasing x or y: their outward normal is the side's.
            let targets: BTreeMap<usize, Target> = selected
                .iter()
                .map(|(&s, sides)| {
                    let mesh = &subs[s].mesh;
                    let nodes = sides.iter().flat_map(|&side| mesh.side_nodes(side)).collect();
                    let edges = sides
                        .iter()
                        .flat_map(|&side| {
                            mesh.sides[side as usize]
                                .iter()
                                .map(move |e| (*e, EdgeNormal::Fixed(outward_normal(side))))
                        })
                        .collect();
                    (s, Target { nodes, edges })
                })
                .collect();
            self.apply_rule((r, rule), &key, time, subs, &targets, &mut out)?;
        }
        Ok(drop_empty_cases(out))
    }

    /// The displacements and tractions of one boundary rule on the nodes and edges it selected
    /// in each subdomain.
    fn apply_rule(
        &self,
        (r, rule): (usize, &RawBoundary),
        key: &str,
        time: TimeGrid,
        subs: &[Sub],
        targets: &BTreeMap<usize, Target>,
        out: &mut [SubLoads],
    ) -> Result<(), SceneError> {
        for (c, (comp, value)) in [("ux", &rule.ux), ("uy", &rule.uy)].iter().enumerate() {
            let Some(value) = value else { continue };
            let ckey = format!("{key}.{comp}");
            let bv = self.boundary_value(value, &ckey, time)?;
            for (&s, target) in targets {
                let dofs: Vec<usize> = target.nodes.iter().map(|&node| 2 * node + c).collect();
                let cases = self.displacement_cases(&bv, &ckey, time, &subs[s].mesh, &dofs)?;
                Self::prescribe(&mut out[s], r, &dofs, cases);
            }
        }
        for (comp, value) in [
            ("tx", &rule.tx),
            ("ty", &rule.ty),
            ("p", &rule.p),
            ("shear", &rule.shear),
        ] {
            let Some(value) = value else { continue };
            let ckey = format!("{key}.{comp}");
            let bv = self.boundary_value(value, &ckey, time)?;
            for (&s, target) in targets {
                let cases = self.traction_cases(&bv, comp, &ckey, time, &subs[s].mesh, &target.edges)?;
                for (force, time) in cases {
                    out[s].loads.push(LoadCase {
                        displacement: vec![0.0; force.len()],
                        force,
                        time,
                    });
                    out[s].case_rule.push(r);
                }
            }
        }
        Ok(())
    }

    /// What every boundary rule must say, whatever selects its edges.
    fn check_boundary_rule(&self, rule: &RawBoundary, key: &str) -> Result<(), SceneError> {
        let has_disp = rule.ux.is_some() || rule.uy.is_some();
        let has_trac = rule.tx.is_some() || rule.ty.is_some() || rule.p.is_some() || rule.shear.is_some();
        if has_disp && has_trac {
            return Err(self.err(
                key,
                "a rule prescribes either displacements (ux, uy) or tractions (tx, ty, p, shear), not both",
            ));
        }
        if !has_disp && !has_trac {
            return Err(self.err(key, "prescribes nothing: give ux/uy or tx/ty/p/shear"));
        }
        Ok(())
    }

    /// Cases of a prescribed displacement component at `dofs` of `mesh`.
    fn displacement_cases(
        &self,
        bv: &BoundaryValue,
        key: &str,
        time: TimeGrid,
        mesh: &Mesh,
        dofs: &[usize],
    ) -> Result<Vec<(Vec<f64>, TimeFunction)>, SceneError> {
        let n = 2 * mesh.n_nodes();
        match bv {
            BoundaryValue::Uniform(tf) => {
                let mut pattern = vec![0.0; n];
                for &d in dofs {
                    pattern[d] = 1.0;
                }
                Ok(vec![(pattern, tf.clone())])
            }
            BoundaryValue::Field { expr, timed } => self.field_cases(time, *timed, |t| {
                let mut pattern = vec![0.0; n];
                for &d in dofs {
                    pattern[d] = self.field_at(expr, *timed, mesh.coords[d / 2], t, key)?;
                }
                Ok(pattern)
            }),
        }
    }

    /// Cases of a traction component on `edges` of `mesh`, each edge with its outward normal.
    /// `comp`: tx, ty, p (along −n) or shear (along t = (−n_y, n_x)).
    fn traction_cases(
        &self,
        bv: &BoundaryValue,
        comp: &str,
        key: &str,
        time: TimeGrid,
        mesh: &Mesh,
        edges: &[([usize; 3], EdgeNormal)],
    ) -> Result<Vec<(Vec<f64>, TimeFunction)>, SceneError> {
        let n = 2 * mesh.n_nodes();
        let force = |value: &dyn Fn([f64; 2]) -> f64| -> Vec<f64> {
            let mut force = vec![0.0; n];
            for (e, side_normal) in edges {
                let x = [mesh.coords[e[0]], mesh.coords[e[1]], mesh.coords[e[2]]];
                let f = edge_load_along(&x, self.plane, |p, t| {
                    let normal = match side_normal {
                        EdgeNormal::Fixed(n) => *n,
                        EdgeNormal::Left => [t[1], -t[0]],
                        EdgeNormal::Right => [-t[1], t[0]],
                    };
                    let unit = match comp {
                        "tx" => [1.0, 0.0],
                        "ty" => [0.0, 1.0],
                        "p" => [-normal[0], -normal[1]],
                        _ => [-normal[1], normal[0]],
                    };
                    let v = value(p);
                    [unit[0] * v, unit[1] * v]
                });
                for k in 0..3 {
                    force[2 * e[k]] += f[k][0];
                    force[2 * e[k] + 1] += f[k][1];
                }
            }
            force
        };
        match bv {
            BoundaryValue::Uniform(tf) => Ok(vec![(force(&|_| 1.0), tf.clone())]),
            BoundaryValue::Field { expr, timed } => self.field_cases(time, *timed, |t| {
                // Evaluate once at every Gauss point first, so a non-finite value is an error.
                for (e, _) in edges {
                    let x = [mesh.coords[e[0]], mesh.coords[e[1]], mesh.coords[e[2]]];
                    for &(s, _) in &glissade_mechanics::element::GAUSS3 {
                        let p = glissade_mechanics::element::edge_frame(&x, s).0;
                        self.field_at(expr, *timed, p, t, key)?;
                    }
                }
                let v = |p: [f64; 2]| {
                    if *timed {
                        expr.eval(&[p[0], p[1], t])
                    } else {
                        expr.eval(&p)
                    }
                };
                Ok(force(&v))
            }),
        }
    }

    /// Constraints and load cases of every part of a mesh scene from the `[[boundary]]` rules,
    /// which select named curves.
    pub(crate) fn mesh_boundaries(
        &self,
        raw: &RawScene,
        geometry: &parts::PartGeometry,
        curve_names: &[String],
        subs: &[Sub],
        time: TimeGrid,
    ) -> Result<Vec<SubLoads>, SceneError> {
        let mut out = empty_loads(subs);
        for (r, rule) in raw.boundary.iter().enumerate() {
            let key = format!("boundary[{r}]");
            self.check_boundary_rule(rule, &key)?;
            for (what, given) in [
                ("blocks", rule.blocks.is_some()),
                ("side", rule.side.is_some()),
                ("x", rule.x.is_some()),
                ("y", rule.y.is_some()),
            ] {
                if given {
                    return Err(self.err(
                        format!("{key}.{what}"),
                        "selects block sides: a scene with a [mesh] selects its boundaries by `curve`",
                    ));
                }
            }
            let Some(curve) = &rule.curve else {
                return Err(self.err(key, "selects no boundary: give `curve` (a named curve of the mesh)"));
            };
            let Some(c) = curve_names.iter().position(|n| n == curve) else {
                return Err(self.err(
                    format!("{key}.curve"),
                    format!("unknown curve `{curve}` (the mesh names: {})", curve_names.join(", ")),
                ));
            };
            // A curve inside a part would load (or hold) the part inside, not on its boundary.
            if let Some(inside) = &geometry.curve_inside[c] {
                let [n0, n1, n2] = inside.nodes;
                return Err(self.err(
                    format!("{key}.curve"),
                    format!(
                        "boundary curve `{curve}` element {} (nodes {n0}, {n1}, {n2}) lies on an edge shared by two \
                         elements of part `{}`: a boundary curve must lie on a part's outer boundary",
                        inside.element, subs[inside.part].name
                    ),
                ));
            }
            // Edges of each part on the curve.
            let mut selected: BTreeMap<usize, Vec<[usize; 3]>> = BTreeMap::new();
            for (s, edges) in geometry.boundary.iter().enumerate() {
                for (k, e) in edges.iter().enumerate() {
                    if geometry.edge_curves[s][k].contains(&c) {
                        if geometry.on_interface[s][k] {
                            let x = subs[s].mesh.coords[e.nodes[1]];
                            return Err(self.err(
                                format!("{key}.curve"),
                                format!(
                                    "curve `{curve}` runs between two parts (`{}` and a neighbour, e.g. at ({}, {})): \
                                     boundary conditions go on free boundaries; an interface takes an \
                                     [[interface]] rule",
                                    subs[s].name,
                                    fmt_num(x[0]),
                                    fmt_num(x[1])
                                ),
                            ));
                        }
                        selected.entry(s).or_default().push(e.nodes);
                    }
                }
            }
            if selected.is_empty() {
                return Err(self.err(
                    format!("{key}.curve"),
                    format!("curve `{curve}` is on no part's boundary"),
                ));
            }
            // Each edge from its end of smaller x (smaller y on a vertical edge), as the block
            // mesher's sides run: the same loads to the bit on the same mesh.
            let targets: BTreeMap<usize, Target> = selected
                .iter()
                .map(|(&s, edges)| {
                    let coords = &subs[s].mesh.coords;
                    let mut nodes: Vec<usize> = edges.iter().flatten().copied().collect();
                    nodes.sort_unstable();
                    nodes.dedup();
                    let edges = edges
                        .iter()
                        .map(|e| {
                            if parts::runs_backwards(coords[e[0]], coords[e[2]]) {
                                ([e[2], e[1], e[0]], EdgeNormal::Right)
                            } else {
                                (*e, EdgeNormal::Left)
                            }
                        })
                        .collect();
                    (s, Target { nodes, edges })
                })
                .collect();
            self.apply_rule((r, rule), &key, time, subs, &targets, &mut out)?;
        }
        Ok(drop_empty_cases(out))
    }

    /// Sides selected by a boundary rule, per subdomain (global order).
    pub(crate) fn select_sides(
        &self,
        rule: &RawBoundary,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        key: &str,
    ) -> Result<BTreeMap<usize, Vec<BlockSide>>, SceneError> {
        // (subdomain, only the block's outer sides)
        let mut candidates: BTreeMap<usize, bool> = BTreeMap::new();
        match &rule.blocks {
            None => {
                for s in 0..subs.len() {
                    candidates.insert(s, true);
                }
            }
            Some(list) => {
                for name in list {
                    let (ss, is_block) = self.resolve(names, subs, name, &format!("{key}.blocks"))?;
                    for s in ss {
                        let outer_only = candidates.get(&s).copied().unwrap_or(true) && is_block;
                        candidates.insert(s, outer_only);
                    }
                }
            }
        }
        let mut selected: BTreeMap<usize, Vec<BlockSide>> = BTreeMap::new();
        for (&s, &outer_only) in &candidates {
            let sub = &subs[s];
            for side in BlockSide::ALL {
                if outer_only && !sub.outer[side as usize] {
                    continue;
                }
                if rule.side.is_some_and(|want| want.block_side() != side) {
                    continue;
                }
                let vertical = matches!(side, BlockSide::Left | BlockSide::Right);
                let line = match side {
                    BlockSide::Bottom => sub.y[0],
                    BlockSide::Top => sub.y[1],
                    BlockSide::Left => sub.x[0],
                    BlockSide::Right => sub.x[1],
                };
                if let Some(x) = rule.x {
                    if !vertical || (line - x).abs() > sub.tol {
                        continue;
                    }
                }
                if let Some(y) = rule.y {
                    if vertical || (line - y).abs() > sub.tol {
                        continue;
                    }
                }
                selected.entry(s).or_default().push(side);
            }
        }
        if selected.is_empty() {
            let mut what = Vec::new();
            if let Some(side) = rule.side {
                what.push(format!("side = {}", side.block_side().name()));
            }
            if let Some(x) = rule.x {
                what.push(format!("x = {}", fmt_num(x)));
            }
            if let Some(y) = rule.y {
                what.push(format!("y = {}", fmt_num(y)));
            }
            let among = match &rule.blocks {
                Some(b) => format!(" of {}", b.join(", ")),
                None => String::new(),
            };
            return Err(self.err(key, format!("no outer side{among} matches {}", what.join(", "))));
        }
        Ok(selected)
    }
}

/// The loads without the cases that are zero everywhere (e.g. a prescribed 0): after every rule
/// has been applied, since rules refer to the cases of earlier ones by position.
fn drop_empty_cases(mut out: Vec<SubLoads>) -> Vec<SubLoads> {
    for sl in &mut out {
        let keep: Vec<bool> = sl
            .loads
            .iter()
            .map(|c| c.force.iter().chain(&c.displacement).any(|&v| v != 0.0))
            .collect();
        let mut k = keep.iter();
        sl.loads.retain(|_| *k.next().unwrap_or(&true));
        let mut k = keep.iter();
        sl.case_rule.retain(|_| *k.next().unwrap_or(&true));
    }
    out
}

/// Empty constraints and loads for every subdomain.
fn empty_loads(subs: &[Sub]) -> Vec<SubLoads> {
    subs.iter()
        .map(|s| {
            let n = 2 * s.mesh.n_nodes();
            SubLoads {
                constrained: vec![false; n],
                loads: Vec::new(),
                owner: vec![(0, 0); n],
                dof_rule: vec![None; n],
                case_rule: Vec::new(),
            }
        })
        .collect()
}

/// A boundary value: uniform along the boundary, or a formula in x, y (and t if `timed`).
pub(crate) enum BoundaryValue {
    Uniform(TimeFunction),
    Field { expr: Expr, timed: bool },
}

/// The outward normal of a loaded edge: a block side's, or the isoparametric edge's with the part
/// on the left (or the right) of the edge's node order.
pub(crate) enum EdgeNormal {
    Fixed([f64; 2]),
    Left,
    Right,
}

/// What a boundary rule selected in one subdomain: the nodes (displacements) and the edges with
/// their outward normals (tractions).
pub(crate) struct Target {
    nodes: Vec<usize>,
    edges: Vec<([usize; 3], EdgeNormal)>,
}
