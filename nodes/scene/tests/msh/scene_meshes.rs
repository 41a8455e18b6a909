//! The meshes of launch/scenes/meshes/: read as Gmsh accounts for them and checked (conformity,
//! orientation, physical groups, curves).

use super::*;
use std::collections::{BTreeMap, HashMap};

fn scene_mesh(name: &str) -> Msh {
    let path = root().join("launch/scenes/meshes").join(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let m = read(&bytes, name);
    // As Gmsh accounts for it.
    let stem = name.trim_end_matches(".msh");
    let account = json(&format!("{stem}.json"));
    assert_eq!(m.nodes.len() as u64, as_u64(&account["nodes"]), "{name}: nodes");
    let mut by_type = BTreeMap::new();
    for e in &m.elements {
        *by_type.entry(e.kind.to_string()).or_insert(0u64) += 1;
    }
    let counts: BTreeMap<String, u64> = account["element_counts"]
        .as_object()
        .expect("counts")
        .iter()
        .map(|(k, v)| (k.clone(), as_u64(v)))
        .collect();
    assert_eq!(by_type, counts, "{name}: elements per type");
    assert_eq!(
        by_type.keys().map(String::as_str).collect::<Vec<_>>(),
        ["16", "8"],
        "{name}: QUA8 and 3-node lines only"
    );
    for g in account["physical_groups"].as_array().expect("groups") {
        let key = (as_u64(&g["dim"]) as u8, g["tag"].as_i64().expect("tag") as i32);
        assert_eq!(
            m.physical_names.get(&key).map(String::as_str),
            g["name"].as_str(),
            "{name}: group {key:?}"
        );
    }
    check_mesh(&m, name);
    m
}

/// The elements of a physical group, by name.
fn group<'a>(m: &'a Msh, dim: u8, name: &str) -> Vec<&'a msh::MshElement> {
    let tag = m
        .physical_names
        .iter()
        .find(|(k, n)| k.0 == dim && n.as_str() == name)
        .unwrap_or_else(|| panic!("physical group {name}"))
        .0
         .1;
    m.elements
        .iter()
        .filter(|e| e.dim == dim && e.physicals.contains(&tag))
        .collect()
}

fn names(m: &Msh, dim: u8) -> BTreeSet<String> {
    m.physical_names
        .iter()
        .filter(|(k, _)| k.0 == dim)
        .map(|(_, n)| n.clone())
        .collect()
}

/// Checks of every glissade mesh: every node used, no two nodes at one place (conformity: the
/// sides of a shared curve have the same nodes), every quadrangle counter-clockwise with its mid
/// nodes between its corners, each in exactly one physical surface, every quadrangle edge in one
/// or two quadrangles, every line element an edge of a quadrangle, and on a curve between two
/// physical surfaces an edge of one quadrangle of each.
fn check_mesh(m: &Msh, name: &str) {
    let (lo, hi) = m.nodes.iter().fold(([f64::MAX; 2], [f64::MIN; 2]), |(lo, hi), x| {
        ([lo[0].min(x[0]), lo[1].min(x[1])], [hi[0].max(x[0]), hi[1].max(x[1])])
    });
    let size = (hi[0] - lo[0]).hypot(hi[1] - lo[1]);
    let mut used = vec![false; m.nodes.len()];
    for e in &m.elements {
        for &n in &e.nodes {
            used[n] = true;
        }
    }
    assert!(used.iter().all(|&u| u), "{name}: every node in an element");
    let mut sorted: Vec<usize> = (0..m.nodes.len()).collect();
    sorted.sort_by(|&a, &b| m.nodes[a][0].total_cmp(&m.nodes[b][0]));
    for (k, &a) in sorted.iter().enumerate() {
        for &b in &sorted[k + 1..] {
            if m.nodes[b][0] - m.nodes[a][0] > 1e-9 * size {
                break;
            }
            let d = (m.nodes[a][0] - m.nodes[b][0]).hypot(m.nodes[a][1] - m.nodes[b][1]);
            assert!(
                d > 1e-9 * size,
                "{name}: nodes {} and {} coincide",
                m.node_tags[a],
                m.node_tags[b]
            );
        }
    }
    let at = |i: usize| m.nodes[i];
    // Edges (corner, corner sorted) -> (mid node, surfaces' physical tags).
    let mut edges: HashMap<(usize, usize), Vec<(usize, i32)>> = HashMap::new();
    for e in m.elements.iter().filter(|e| e.kind == 16) {
        assert_eq!(
            e.physicals.len(),
            1,
            "{name}: element {} in one physical surface",
            e.tag
        );
        let c: Vec<[f64; 2]> = e.nodes[..4].iter().map(|&i| at(i)).collect();
        let area2: f64 = (0..4)
            .map(|k| c[k][0] * c[(k + 1) % 4][1] - c[(k + 1) % 4][0] * c[k][1])
            .sum();
        assert!(area2 > 0.0, "{name}: element {} counter-clockwise", e.tag);
        for k in 0..4 {
            let (a, b, mid) = (e.nodes[k], e.nodes[(k + 1) % 4], e.nodes[4 + k]);
            let (pa, pb, pm) = (at(a), at(b), at(mid));
            // Between its corners: on the segment's perpendicular bisector (straight edges: the
            // middle; arcs: the middle of the arc).
            let da = (pm[0] - pa[0]).hypot(pm[1] - pa[1]);
            let db = (pm[0] - pb[0]).hypot(pm[1] - pb[1]);
            assert!((da - db).abs() < 1e-6 * size, "{name}: element {} mid node {k}", e.tag);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push((mid, e.physicals[0]));
        }
    }
    for (edge, sides) in &edges {
        assert!(sides.len() <= 2, "{name}: edge {edge:?} in {} quadrangles", sides.len());
        assert!(
            sides.iter().all(|s| s.0 == sides[0].0),
            "{name}: edge {edge:?} has one mid node"
        );
    }
    for e in m.elements.iter().filter(|e| e.kind == 8) {
        let (a, b) = (e.nodes[0], e.nodes[1]);
        let sides = edges
            .get(&(a.min(b), a.max(b)))
            .unwrap_or_else(|| panic!("{name}: line {} an edge", e.tag));
        assert_eq!(
            sides[0].0, e.nodes[2],
            "{name}: line {}: its mid node is the quadrangles'",
            e.tag
        );
    }
}

/// The edges (3 nodes) of a curve group, and the physical surfaces on either side of each.
fn sides_of_curve(m: &Msh, curve: &str) -> Vec<BTreeSet<i32>> {
    let mut quads: HashMap<(usize, usize), BTreeSet<i32>> = HashMap::new();
    for e in m.elements.iter().filter(|e| e.kind == 16) {
        for k in 0..4 {
            let (a, b) = (e.nodes[k], e.nodes[(k + 1) % 4]);
            quads.entry((a.min(b), a.max(b))).or_default().insert(e.physicals[0]);
        }
    }
    group(m, 1, curve)
        .iter()
        .map(|e| quads[&(e.nodes[0].min(e.nodes[1]), e.nodes[0].max(e.nodes[1]))].clone())
        .collect()
}

fn surface_tag(m: &Msh, name: &str) -> i32 {
    m.physical_names
        .iter()
        .find(|(k, n)| k.0 == 2 && n.as_str() == name)
        .expect("the surface")
        .0
         .1
}

/// Every node of the group's elements at radius `r` (to 1e-9 of it).
fn on_circle(m: &Msh, curve: &str, r: f64) {
    for e in group(m, 1, curve) {
        for &n in &e.nodes {
            let x = m.nodes[n];
            assert!(
                (x[0].hypot(x[1]) - r).abs() < 1e-9 * r,
                "{curve}: node {} at r = {r}",
                m.node_tags[n]
            );
        }
    }
}

/// The group's line elements form one closed chain (each corner node in exactly two of them).
fn closed_chain(m: &Msh, curve: &str) {
    let lines = group(m, 1, curve);
    let mut degree: HashMap<usize, usize> = HashMap::new();
    for e in &lines {
        *degree.entry(e.nodes[0]).or_default() += 1;
        *degree.entry(e.nodes[1]).or_default() += 1;
    }
    assert!(degree.values().all(|&d| d == 2), "{curve}: closed");
    assert_eq!(
        degree.len(),
        lines.len(),
        "{curve}: one chain or several loops of the same length"
    );
    // One loop: walk it.
    let mut next: HashMap<usize, Vec<usize>> = HashMap::new();
    for e in &lines {
        next.entry(e.nodes[0]).or_default().push(e.nodes[1]);
        next.entry(e.nodes[1]).or_default().push(e.nodes[0]);
    }
    let start = lines[0].nodes[0];
    let (mut prev, mut here, mut steps) = (start, lines[0].nodes[1], 1);
    while here != start {
        let n = &next[&here];
        let to = if n[0] == prev { n[1] } else { n[0] };
        (prev, here, steps) = (here, to, steps + 1);
    }
    assert_eq!(steps, lines.len(), "{curve}: one closed chain");
}

#[test]
fn shrink_fit_meshes() {
    for (level, around, inner, outer) in [(1, 24, 2, 4), (2, 48, 4, 8), (3, 96, 8, 16)] {
        let name = format!("shrink-fit-{level}.msh");
        let m = scene_mesh(&name);
        assert_eq!(names(&m, 2), BTreeSet::from(["inner".into(), "outer".into()]), "{name}");
        assert_eq!(
            names(&m, 1),
            BTreeSet::from(["bore".into(), "fit".into(), "outside".into()]),
            "{name}"
        );
        assert_eq!(group(&m, 2, "inner").len(), around * inner, "{name}");
        assert_eq!(group(&m, 2, "outer").len(), around * outer, "{name}");
        for (curve, r) in [("bore", 20.0), ("fit", 30.0), ("outside", 50.0)] {
            assert_eq!(group(&m, 1, curve).len(), around, "{name}: {curve}");
            on_circle(&m, curve, r);
            closed_chain(&m, curve);
        }
        let both = BTreeSet::from([surface_tag(&m, "inner"), surface_tag(&m, "outer")]);
        assert!(
            sides_of_curve(&m, "fit").iter().all(|s| *s == both),
            "{name}: fit between inner and outer"
        );
        // Radii of every node within the rings.
        for x in &m.nodes {
            let r = x[0].hypot(x[1]);
            assert!((20.0 - 1e-9..=50.0 + 1e-9).contains(&r));
        }
    }
}

#[test]
fn sheath_mesh() {
    let m = scene_mesh("sheath.msh");
    let layers = ["inner", "middle", "outer"];
    let radii = [10.0, 13.0, 16.0, 20.0];
    let want: BTreeSet<String> = layers
        .iter()
        .flat_map(|l| (1..=8).map(move |k| format!("{l}.{k}")))
        .collect();
    assert_eq!(names(&m, 2), want);
    for (j, layer) in layers.iter().enumerate() {
        for k in 1..=8 {
            let elements = group(&m, 2, &format!("{layer}.{k}"));
            assert_eq!(elements.len(), 4 * 3, "{layer}.{k}");
            // Sector k: angles (k - 1) 45 to k 45 degrees; layer j: radii[j] to radii[j + 1].
            for e in elements {
                for &n in &e.nodes {
                    let x = m.nodes[n];
                    let r = x[0].hypot(x[1]);
                    let mut a = x[1].atan2(x[0]).to_degrees();
                    if a < -1e-9 {
                        a += 360.0;
                    }
                    if k == 8 && a < 1e-9 {
                        a = 360.0;
                    }
                    assert!(r > radii[j] - 1e-9 && r < radii[j + 1] + 1e-9, "{layer}.{k}: r = {r}");
                    let sector = ((k - 1) as f64 * 45.0, k as f64 * 45.0);
                    assert!(a > sector.0 - 1e-9 && a < sector.1 + 1e-9, "{layer}.{k}: angle {a}");
                }
            }
        }
    }
    let curves = ["bore", "inner-middle", "middle-outer", "outside"];
    assert_eq!(names(&m, 1), curves.iter().map(|c| c.to_string()).collect());
    for (i, curve) in curves.iter().enumerate() {
        assert_eq!(group(&m, 1, curve).len(), 32, "{curve}");
        on_circle(&m, curve, radii[i]);
        closed_chain(&m, curve);
    }
    // Between layers: one element of each layer, the same sector.
    for (curve, (a, b)) in [
        ("inner-middle", ("inner", "middle")),
        ("middle-outer", ("middle", "outer")),
    ] {
        let pairs: BTreeSet<BTreeSet<i32>> = sides_of_curve(&m, curve).into_iter().collect();
        let want: BTreeSet<BTreeSet<i32>> = (1..=8)
            .map(|k| {
                BTreeSet::from([
                    surface_tag(&m, &format!("{a}.{k}")),
                    surface_tag(&m, &format!("{b}.{k}")),
                ])
            })
            .collect();
        assert_eq!(pairs, want, "{curve}");
    }
}

#[test]
fn stratified_mesh_is_the_block_mesher_s() {
    let m = scene_mesh("stratified.msh");
    let layers = ["bottom", "core", "top"];
    let want: BTreeSet<String> = layers
        .iter()
        .flat_map(|l| (1..=6).map(move |k| format!("{l}.{k}")))
        .collect();
    assert_eq!(names(&m, 2), want);
    let curves = ["clamp", "floor", "roof", "end", "core-end"];
    assert_eq!(names(&m, 1), curves.iter().map(|c| c.to_string()).collect());
    for (curve, count) in [
        ("clamp", 60),
        ("floor", 120),
        ("roof", 120),
        ("end", 60),
        ("core-end", 20),
    ] {
        assert_eq!(group(&m, 1, curve).len(), count, "{curve}");
    }
    let on = |curve: &str, f: &dyn Fn([f64; 2]) -> bool| {
        for e in group(&m, 1, curve) {
            assert!(e.nodes.iter().all(|&n| f(m.nodes[n])), "{curve}");
        }
    };
    on("clamp", &|x| x[0].abs() < 1e-12);
    on("floor", &|x| x[1].abs() < 1e-12);
    on("roof", &|x| (x[1] - 90.0).abs() < 1e-12);
    on("end", &|x| (x[0] - 180.0).abs() < 1e-12);
    on("core-end", &|x| {
        (x[0] - 180.0).abs() < 1e-12 && (30.0..=60.0).contains(&x[1])
    });
    let core_end: Vec<u64> = group(&m, 1, "core-end").iter().map(|e| e.tag).collect();
    let end: BTreeSet<u64> = group(&m, 1, "end").iter().map(|e| e.tag).collect();
    assert!(
        core_end.iter().all(|t| end.contains(t)),
        "core-end's elements are in end"
    );

    // The block mesher's subdomains of launch/scenes/stratified.toml: same elements, same node
    // positions to the bit (stratified.py computes them as the block mesher does and Gmsh writes
    // them as binary doubles), same node order in each element (corners from the bottom-left).
    let path = root().join("launch/scenes/stratified.toml");
    let text = std::fs::read_to_string(&path).expect("the scene");
    let scene = glissade_scene::load_str(&text, "stratified.toml").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.model.subdomains.len(), 18);
    let bits = |x: [f64; 2]| [x[0].to_bits(), x[1].to_bits()];
    for sub in &scene.model.subdomains {
        let ours: BTreeSet<Vec<[u64; 2]>> = group(&m, 2, &sub.name)
            .iter()
            .map(|e| e.nodes.iter().map(|&n| bits(m.nodes[n])).collect())
            .collect();
        let theirs: BTreeSet<Vec<[u64; 2]>> = sub
            .mesh
            .elements
            .iter()
            .map(|e| e.iter().map(|&n| bits(sub.mesh.coords[n])).collect())
            .collect();
        assert_eq!(group(&m, 2, &sub.name).len(), sub.mesh.elements.len(), "{}", sub.name);
        assert_eq!(ours.len(), sub.mesh.elements.len(), "{}: elements distinct", sub.name);
        if let Some(e) = ours.difference(&theirs).next() {
            let at: Vec<[f64; 2]> = e.iter().map(|b| b.map(f64::from_bits)).collect();
            let near = theirs
                .iter()
                .map(|t| {
                    t.iter()
                        .zip(e)
                        .map(|(p, q)| {
                            let (p, q) = (p.map(f64::from_bits), q.map(f64::from_bits));
                            (p[0] - q[0]).abs().max((p[1] - q[1]).abs())
                        })
                        .fold(0.0, f64::max)
                })
                .fold(f64::INFINITY, f64::min);
            panic!(
                "{}: the element with nodes at {at:?} is not a block element bit for bit (nearest one \
                 {near:e} mm off)",
                sub.name
            );
        }
        let nodes: BTreeSet<[u64; 2]> = sub.mesh.coords.iter().map(|&x| bits(x)).collect();
        assert_eq!(nodes.len(), sub.mesh.coords.len());
    }
    // Neighbouring squares share their nodes: one node per position.
    let positions: BTreeSet<[u64; 2]> = m.nodes.iter().map(|&x| bits(x)).collect();
    assert_eq!(positions.len(), m.nodes.len(), "one node per position");
}

/// `plane = "axisymmetric"` treats a Gmsh scene as it treats blocks: the stratified scene from
/// its Gmsh mesh and from blocks, both made axisymmetric (x = r from 0 to 180 mm), hold the same
/// dofs (the axis r = 0 is clamped there already), and give every interface the same total weight
/// ∫ 2πr ds and every subdomain the same total load per case (the sums are taken over nodes
/// numbered differently, and a Gmsh curve's normals come from its edges' tangents: 1e-12 of the
/// case's total for round-off; measured: 8.3e-12 N across the 2827 N of top.1's
/// roof pattern, a unit pressure over π·30²).
#[test]
fn stratified_axisymmetric_from_gmsh_is_the_block_scene() {
    let load = |name: &str| {
        let path = root().join("launch/scenes").join(name);
        let text = std::fs::read_to_string(&path)
            .expect("the scene")
            .replace("plane = \"strain\"", "plane = \"axisymmetric\"");
        assert!(text.contains("plane = \"axisymmetric\""));
        glissade_scene::load_str(&text, &path.to_string_lossy()).unwrap_or_else(|e| panic!("{e}"))
    };
    let (block, gmsh) = (load("stratified.toml"), load("stratified-gmsh.toml"));
    let (b, g) = (&block.model, &gmsh.model);
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0);
    let by_name = |m: &glissade_mechanics::model::Model, name: &str| {
        m.subdomains
            .iter()
            .position(|s| s.name == name)
            .expect("a subdomain of that name")
    };
    for sb in &b.subdomains {
        let sg = &g.subdomains[by_name(g, &sb.name)];
        let held = |s: &glissade_mechanics::model::Subdomain| s.constrained.iter().filter(|&&c| c).count();
        assert_eq!(held(sb), held(sg), "{}", sb.name);
        assert_eq!(sb.loads.len(), sg.loads.len(), "{}", sb.name);
        for (cb, cg) in sb.loads.iter().zip(&sg.loads) {
            let total = |f: &[f64], c: usize| f.iter().skip(c).step_by(2).sum::<f64>();
            let size = (0..2).fold(0.0f64, |m, c| m.max(total(&cb.force, c).abs()));
            for c in 0..2 {
                let (x, y) = (total(&cb.force, c), total(&cg.force, c));
                assert!((x - y).abs() <= 1e-12 * size, "{} component {c}: {x} vs {y}", sb.name);
            }
        }
    }
    assert_eq!(b.interfaces.len(), g.interfaces.len());
    for ib in &b.interfaces {
        let ends = |m: &glissade_mechanics::model::Model, a: usize, b: usize| {
            let mut e = [m.subdomains[a].name.clone(), m.subdomains[b].name.clone()];
            e.sort();
            e
        };
        let ig = g
            .interfaces
            .iter()
            .find(|i| ends(g, i.a, i.b) == ends(b, ib.a, ib.b))
            .expect("the same interface");
        assert_eq!(ib.n_pairs(), ig.n_pairs());
        assert!(close(ib.weights.iter().sum(), ig.weights.iter().sum()));
    }
}
