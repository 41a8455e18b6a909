//! The reference where contact pairs close a cycle of node copies: the sheath with contact on its
//! radial cuts (launch/scenes/sheath-cuts.toml). At every point where a cut meets a layer circle
//! four contact pairs (two cuts, two arcs) join four node copies in a cycle, so with every pair
//! in contact the active constraints are linearly dependent and the Newton matrix is singular:
//! before the shifted step (`Problem::newton_step`) every attempt of step 1 stopped at its first
//! solve (a NaN correction), worst violation 1.0.

use glissade_mechanics::model::Model;
use glissade_reference::{solve_reference, verify};
use std::collections::{BTreeMap, BTreeSet};

fn sheath_cuts() -> Model {
    let path = format!("{}/../../launch/scenes/sheath-cuts.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("shipped scene");
    match glissade_scene::load_str(&text, &path) {
        Ok(s) => s.model,
        Err(e) => panic!("{e}"),
    }
}

/// Independent cycles of the graph whose vertices are node copies (subdomain, node) and whose
/// edges are contact pairs: edges − vertices + connected components.
fn contact_cycles(model: &Model) -> usize {
    let mut edges = BTreeSet::new();
    for itf in model.interfaces.iter().filter(|i| i.is_contact()) {
        for &(na, nb) in &itf.pairs {
            let (a, b) = ((itf.a, na), (itf.b, nb));
            edges.insert(if a < b { (a, b) } else { (b, a) });
        }
    }
    let mut vertex = BTreeMap::new();
    for &(a, b) in &edges {
        for v in [a, b] {
            let n = vertex.len();
            vertex.entry(v).or_insert(n);
        }
    }
    let mut parent: Vec<usize> = (0..vertex.len()).collect();
    fn root(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    let mut cycles = 0;
    for (a, b) in &edges {
        let (ra, rb) = (root(&mut parent, vertex[a]), root(&mut parent, vertex[b]));
        if ra == rb {
            cycles += 1;
        } else {
            parent[ra] = rb;
        }
    }
    cycles
}

#[test]
fn the_reference_solves_contact_pairs_closing_cycles() {
    let model = sheath_cuts();
    assert!(model.interfaces.iter().all(|i| i.is_contact()));
    // 8 cuts per layer boundary circle (r = 13, r = 16), one cycle each.
    assert_eq!(contact_cycles(&model), 16);
    let sol = solve_reference(&model, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    // Every check of the discrete problem (equilibrium of every subdomain with its copies'
    // forces, action–reaction, the contact law at every copy) within the Newton tolerance, as
    // for the other shipped scenes (reference.rs).
    let checks = verify(&model, &sol).unwrap_or_else(|e| panic!("{e}"));
    println!("Newton iterations per step {:?}; {checks:?}", sol.newton_iterations);
    assert!(checks.max() <= 1e-10, "{checks:?}");
    // The cycles' pairs carry load: not every pair separated.
    let stuck = sol
        .contact
        .iter()
        .flatten()
        .flat_map(|c| c.status.iter())
        .filter(|s| **s != glissade_mechanics::laws::Status::Separated)
        .count();
    assert!(stuck > 0);
    // The glued sheath has no such cycle (its cuts are perfect: their copies are merged).
    let glued = {
        let path = format!("{}/../../launch/scenes/sheath.toml", env!("CARGO_MANIFEST_DIR"));
        glissade_scene::load_str(&std::fs::read_to_string(&path).unwrap(), &path)
            .unwrap()
            .model
    };
    assert_eq!(contact_cycles(&glued), 0);
}
