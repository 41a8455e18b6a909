//! Tables, time functions and the `[[boundary]]` rules: prescribed displacements and loads.

use super::*;

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

    /// Constraints and load cases of every subdomain from the `[[boundary]]` rules.
    pub(crate) fn boundaries(
        &self,
        raw: &RawScene,
        names: &BTreeMap<String, NameRef>,
        subs: &[Sub],
        time: TimeGrid,
    ) -> Result<Vec<SubLoads>, SceneError> {
        let mut out: Vec<SubLoads> = subs
            .iter()
            .map(|s| {
                let n = 2 * s.mesh.n_nodes();
                SubLoads {
                    constrained: vec![false; n],
                    loads: Vec::new(),
                    owner: vec![usize::MAX; n],
                }
            })
            .collect();
        for (r, rule) in raw.boundary.iter().enumerate() {
            let key = format!("boundary[{r}]");
            let disp = [("ux", &rule.ux), ("uy", &rule.uy)];
            let trac = [("tx", &rule.tx), ("ty", &rule.ty), ("p", &rule.p)];
            let has_disp = disp.iter().any(|(_, v)| v.is_some());
            let has_trac = trac.iter().any(|(_, v)| v.is_some());
            if has_disp && has_trac {
                return Err(self.err(
                    key,
                    "a rule prescribes either displacements (ux, uy) or tractions (tx, ty, p), not both",
                ));
            }
            if !has_disp && !has_trac {
                return Err(self.err(key, "prescribes nothing: give ux/uy or tx/ty/p"));
            }
            if rule.side.is_none() && rule.x.is_none() && rule.y.is_none() {
                return Err(self.err(key, "selects no side: give `side`, `x` or `y`"));
            }
            let selected = self.select_sides(rule, names, subs, &key)?;

            for (c, (comp, value)) in disp.iter().enumerate() {
                let Some(value) = value else { continue };
                let tf = self.time_function(value, &format!("{key}.{comp}"), time)?;
                for (&s, sides) in &selected {
                    let sl = &mut out[s];
                    let case = sl.loads.len();
                    let mut pattern = vec![0.0; sl.constrained.len()];
                    for &side in sides {
                        for node in subs[s].mesh.side_nodes(side) {
                            let dof = 2 * node + c;
                            pattern[dof] = 1.0;
                            sl.constrained[dof] = true;
                            let prev = sl.owner[dof];
                            if prev != usize::MAX && prev != case {
                                sl.loads[prev].displacement[dof] = 0.0;
                            }
                            sl.owner[dof] = case;
                        }
                    }
                    sl.loads.push(LoadCase {
                        force: vec![0.0; pattern.len()],
                        displacement: pattern,
                        time: tf.clone(),
                    });
                }
            }
            for (comp, value) in trac {
                let Some(value) = value else { continue };
                let tf = self.time_function(value, &format!("{key}.{comp}"), time)?;
                for (&s, sides) in &selected {
                    let mesh = &subs[s].mesh;
                    let mut force = vec![0.0; 2 * mesh.n_nodes()];
                    for &side in sides {
                        let unit = match comp {
                            "tx" => [1.0, 0.0],
                            "ty" => [0.0, 1.0],
                            _ => {
                                let n = outward_normal(side);
                                [-n[0], -n[1]]
                            }
                        };
                        for e in &mesh.sides[side as usize] {
                            let x = [mesh.coords[e[0]], mesh.coords[e[1]], mesh.coords[e[2]]];
                            let f = edge_load(&x, |_| unit);
                            for k in 0..3 {
                                force[2 * e[k]] += f[k][0];
                                force[2 * e[k] + 1] += f[k][1];
                            }
                        }
                    }
                    out[s].loads.push(LoadCase {
                        displacement: vec![0.0; force.len()],
                        force,
                        time: tf.clone(),
                    });
                }
            }
        }
        for sl in &mut out {
            sl.loads
                .retain(|c| c.force.iter().chain(&c.displacement).any(|&v| v != 0.0));
        }
        Ok(out)
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
