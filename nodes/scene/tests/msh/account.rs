//! The fixtures in the formats Gmsh writes, read as Gmsh's API accounts for them, and the
//! element-type table compared with Gmsh's.

use super::*;
use std::collections::BTreeMap;

#[test]
fn the_four_formats_read_as_gmsh_accounts_for_them() {
    let account = json("two-parts.json");
    // Nodes: tag -> (x, y), as the API gives them (exact doubles).
    let nodes: BTreeMap<u64, [f64; 2]> = account["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .map(|n| (as_u64(&n[0]), [n[1].as_f64().expect("x"), n[2].as_f64().expect("y")]))
        .collect();
    let elements: BTreeSet<ElementKey> = account["elements"]
        .as_array()
        .expect("elements")
        .iter()
        .map(|e| {
            (
                as_u64(&e["kind"]) as u32,
                e["nodes"].as_array().expect("nodes").iter().map(as_u64).collect(),
                as_u64(&e["dim"]) as u8,
                e["entity"].as_i64().expect("entity") as i32,
                e["physicals"]
                    .as_array()
                    .expect("physicals")
                    .iter()
                    .map(|p| p.as_i64().expect("tag") as i32)
                    .collect(),
            )
        })
        .collect();
    let element_tags: BTreeMap<Vec<u64>, u64> = account["elements"]
        .as_array()
        .expect("elements")
        .iter()
        .map(|e| {
            (
                e["nodes"].as_array().expect("nodes").iter().map(as_u64).collect(),
                as_u64(&e["tag"]),
            )
        })
        .collect();
    let counts: BTreeMap<u32, usize> = account["element_counts"]
        .as_object()
        .expect("counts")
        .iter()
        .map(|(k, v)| (k.parse().expect("a type"), as_u64(v) as usize))
        .collect();
    let names: BTreeMap<(u8, i32), String> = account["physical_groups"]
        .as_array()
        .expect("groups")
        .iter()
        .map(|g| {
            (
                (as_u64(&g["dim"]) as u8, g["tag"].as_i64().expect("tag") as i32),
                g["name"].as_str().expect("name").to_string(),
            )
        })
        .collect();
    assert!(
        names.values().any(String::is_empty),
        "the fixture has a physical group without a name"
    );
    assert!(
        elements.iter().any(|e| e.4.len() == 2),
        "the fixture has a curve in two physical groups"
    );

    let size = 4.0;
    let mut read_all = Vec::new();
    for file in FORMATS {
        let m = read(&fixture(file), file);
        assert_eq!(m.nodes.len(), nodes.len(), "{file}: node count");
        assert_eq!(m.node_tags.len(), m.nodes.len(), "{file}");
        for (x, tag) in m.nodes.iter().zip(&m.node_tags) {
            let want = nodes
                .get(tag)
                .unwrap_or_else(|| panic!("{file}: node {tag} unknown to Gmsh"));
            for k in 0..2 {
                // ASCII files hold 16 significant digits; binary ones the doubles, but serde_json
                // (without its float_roundtrip feature) reads the account's to about 1 ulp.
                assert!(
                    (x[k] - want[k]).abs() <= 1e-15 * size,
                    "{file}: node {tag}: {x:?} against {want:?}"
                );
            }
        }
        assert_eq!(
            element_keys(&m),
            elements,
            "{file}: elements, entities and physical groups"
        );
        assert_eq!(m.elements.len(), elements.len(), "{file}: each element once");
        let mut by_type = BTreeMap::new();
        for e in &m.elements {
            *by_type.entry(e.kind).or_insert(0) += 1;
            assert_eq!(msh::type_nodes(e.kind), Some((e.nodes.len(), e.dim)), "{file}");
        }
        assert_eq!(by_type, counts, "{file}: elements per type");
        assert_eq!(m.physical_names, names, "{file}: physical groups and their names");
        let tags: BTreeSet<u64> = m.elements.iter().map(|e| e.tag).collect();
        assert_eq!(tags.len(), m.elements.len(), "{file}: element tags unique");
        if file.contains("4.1") {
            // MSH 4.1 keeps Gmsh's element tags; MSH 2.2 numbers the copies of an element in
            // several physical groups apart, so its tags differ.
            for e in &m.elements {
                let key: Vec<u64> = e.nodes.iter().map(|&i| m.node_tags[i]).collect();
                assert_eq!(element_tags[&key], e.tag, "{file}: tag of element {key:?}");
            }
        }
        read_all.push(m);
    }
    // The binary files hold the same doubles, the ASCII ones the same digits.
    for (a, b) in [(1, 3), (1, 5), (0, 2), (0, 4)] {
        assert_eq!(
            read_all[a].nodes, read_all[b].nodes,
            "{} and {}",
            FORMATS[a], FORMATS[b]
        );
        assert_eq!(read_all[a].node_tags, read_all[b].node_tags);
    }
    assert_eq!(read_all[0].elements, read_all[4].elements);
    assert_eq!(read_all[1].elements, read_all[5].elements);
}

#[test]
fn msh22_writes_an_element_once_per_physical_group_and_the_reader_merges_them() {
    let text = String::from_utf8(fixture("two-parts-2.2.msh")).expect("text");
    let records: usize = section(&text, "Elements")
        .lines()
        .next()
        .expect("count")
        .trim()
        .parse()
        .expect("a count");
    let m = read(text.as_bytes(), "2.2");
    let twice: Vec<_> = m.elements.iter().filter(|e| e.physicals.len() == 2).collect();
    assert!(!twice.is_empty());
    assert_eq!(
        records,
        m.elements.len() + twice.len(),
        "one record per element and physical group"
    );
    let named: BTreeSet<&str> = twice[0]
        .physicals
        .iter()
        .map(|&p| m.physical_names[&(1, p)].as_str())
        .collect();
    assert_eq!(named, BTreeSet::from(["glued", "interface"]));
}

#[test]
fn the_type_table_is_gmsh_s() {
    let kinds = json("element-types.json");
    let mut known = 0;
    for k in kinds.as_array().expect("types") {
        let kind = as_u64(&k["kind"]) as u32;
        let n = as_u64(&k["nodes"]) as usize;
        let dim = as_u64(&k["dim"]) as u8;
        if n == 0 {
            // Polygons, polyhedra and the XFEM types have no fixed number of nodes.
            assert_eq!(msh::type_nodes(kind), None, "type {kind}");
        } else {
            assert_eq!(msh::type_nodes(kind), Some((n, dim)), "type {kind} ({})", k["name"]);
            known += 1;
        }
    }
    assert!(known > 100);
    assert_eq!(msh::type_nodes(200), None);
    assert_eq!(msh::type_name(16), "8-node quadrangle");
    assert_eq!(msh::type_name(10), "9-node quadrangle");
    assert_eq!(msh::type_name(9), "6-node triangle");
    assert_eq!(msh::type_name(8), "3-node line");
    assert_eq!(msh::type_name(1), "2-node line");
    assert_eq!(msh::type_name(15), "1-node point");
    assert_eq!(msh::type_name(23), "15-node triangle of order 4");
    assert_eq!(msh::type_name(24), "15-node triangle of order 5");
    assert_eq!(msh::type_name(200), "unknown element type 200");
}
