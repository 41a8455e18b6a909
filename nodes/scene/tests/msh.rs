//! The Gmsh reader on files written by Gmsh itself, compared with Gmsh's own account of them.
//!
//! `tests/fixtures/msh/` holds one small QUA8 mesh in the four formats Gmsh writes (MSH 4.1 and
//! 2.2, ASCII and binary) with what Gmsh's API says of it (`two-parts.json`), the node count and
//! dimension of every element type Gmsh knows (`element-types.json`), written by
//! `launch/scenes/meshes/fixtures.py`: these tests need no Gmsh.

use glissade_scene::msh::{self, Msh, MshError};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

fn fixture(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/msh")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn json(name: &str) -> Value {
    serde_json::from_slice(&fixture(name)).expect("a fixture's JSON")
}

fn read(bytes: &[u8], what: &str) -> Msh {
    msh::parse(bytes).unwrap_or_else(|e| panic!("{what}: {e}"))
}

const FORMATS: [&str; 4] = [
    "two-parts-4.1.msh",
    "two-parts-4.1-binary.msh",
    "two-parts-2.2.msh",
    "two-parts-2.2-binary.msh",
];

/// An element as a comparable value, by node tags: (kind, node tags, dim, entity, physicals sorted).
type ElementKey = (u32, Vec<u64>, u8, i32, Vec<i32>);

fn element_keys(m: &Msh) -> BTreeSet<ElementKey> {
    m.elements
        .iter()
        .map(|e| {
            let mut p = e.physicals.clone();
            p.sort_unstable();
            let tags = e.nodes.iter().map(|&i| m.node_tags[i]).collect();
            (e.kind, tags, e.dim, e.entity, p)
        })
        .collect()
}

fn as_u64(v: &Value) -> u64 {
    v.as_u64().expect("an unsigned integer")
}

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
    // The two binary files hold the same doubles.
    assert_eq!(read_all[1].nodes, read_all[3].nodes);
    assert_eq!(read_all[1].node_tags, read_all[3].node_tags);
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

/// The text of a section of an ASCII file, between its header and end lines.
fn section<'a>(text: &'a str, name: &str) -> &'a str {
    let start = text.find(&format!("${name}\n")).expect("the section") + name.len() + 2;
    let end = text.find(&format!("$End{name}")).expect("its end");
    &text[start..end]
}

/// 1-based line of the first occurrence of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    let at = text.find(needle).unwrap_or_else(|| panic!("'{needle}' in the fixture"));
    1 + text[..at].matches('\n').count()
}

fn error(bytes: &[u8]) -> MshError {
    match msh::parse(bytes) {
        Ok(_) => panic!("the reader accepted a malformed file"),
        Err(e) => e,
    }
}

fn replace_once(text: &str, from: &str, to: &str) -> String {
    assert_eq!(text.matches(from).count(), 1, "'{from}' once in the fixture");
    text.replacen(from, to, 1)
}

#[test]
fn malformed_ascii_files_are_refused_with_their_line() {
    let v41 = String::from_utf8(fixture("two-parts-4.1.msh")).expect("text");
    let v22 = String::from_utf8(fixture("two-parts-2.2.msh")).expect("text");

    // Truncated in $Nodes.
    let cut = &v41[..v41.find("0.6666666666672217").expect("a node")];
    let e = error(cut.as_bytes());
    assert!(e.problem.contains("unexpected end of file"), "{e}");
    assert_eq!(e.location, format!("line {}", 1 + cut.matches('\n').count()), "{e}");

    // A bad number.
    let bad = replace_once(&v41, "1.333333333331575 0 0", "1.3333x3333331575 0 0");
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("bad number '1.3333x3333331575'"), "{e}");
    assert_eq!(e.location, format!("line {}", line_of(&bad, "1.3333x")));
    assert_eq!(
        e.to_string(),
        format!("{} (line {})", e.problem, line_of(&bad, "1.3333x"))
    );

    // An element refers to a node that is not in $Nodes.
    let bad = replace_once(&v41, "\n13 1 7 32 20 9 34 35 22 \n", "\n13 1 7 999 20 9 34 35 22 \n");
    let e = error(bad.as_bytes());
    assert!(
        e.problem.contains("element 13") && e.problem.contains("node 999"),
        "{e}"
    );
    assert_eq!(e.location, format!("line {}", line_of(&bad, "13 1 7 999")));
    let bad = replace_once(&v22, "\n15 16 2 1 1 1 7 32 ", "\n15 16 2 1 1 1 7 999 ");
    let e = error(bad.as_bytes());
    assert!(
        e.problem.contains("element 15") && e.problem.contains("node 999"),
        "{e}"
    );
    assert_eq!(e.location, format!("line {}", line_of(&bad, "15 16 2 1 1 1 7 999")));

    // Versions other than 4.1 and 2.2.
    for version in ["3.0", "4.0", "4", "2.1"] {
        let bad = replace_once(&v41, "4.1 0 8", &format!("{version} 0 8"));
        let e = error(bad.as_bytes());
        assert!(e.problem.contains(&format!("MSH version {version} is not read")), "{e}");
        assert_eq!(e.location, "line 2", "{e}");
    }

    // Not planar: the node's tag is named, and its line.
    let bad = replace_once(
        &v41,
        "0.6666666666672217 0.5000000000009369 0\n",
        "0.6666666666672217 0.5000000000009369 0.001\n",
    );
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("node 32 has z = 0.001"), "{e}");
    assert_eq!(
        e.location,
        format!("line {}", line_of(&bad, "0.5000000000009369 0.001"))
    );
    let bad = replace_once(
        &v22,
        "\n32 0.6666666666672217 0.5000000000009369 0\n",
        "\n32 0.6666666666672217 0.5000000000009369 -1e-3\n",
    );
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("node 32 has z = -0.001"), "{e}");
    // Below 1e-9 of the size: accepted.
    let ok = replace_once(
        &v41,
        "0.6666666666672217 0.5000000000009369 0\n",
        "0.6666666666672217 0.5000000000009369 1e-12\n",
    );
    read(ok.as_bytes(), "z = 1e-12");

    // No $MeshFormat.
    let bad = &v41[v41.find("$PhysicalNames").expect("names")..];
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("missing $MeshFormat"), "{e}");
    assert_eq!(e.location, "line 1");
    let e = error(b"");
    assert!(e.problem.contains("missing $MeshFormat"), "{e}");

    // A node tag given twice.
    let bad = replace_once(&v22, "\n13 2 0.2499999999994184 0\n", "\n12 2 0.2499999999994184 0\n");
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("node tag 12 given twice"), "{e}");
    assert_eq!(e.location, format!("line {}", line_of(&bad, "12 2 0.2499999999994184")));

    // An unknown element type.
    let bad = replace_once(&v41, "2 1 16 6\n", "2 1 300 6\n");
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("element type 300"), "{e}");

    // Counts that do not add up.
    let bad = replace_once(&v41, "8 22 1 22\n", "8 23 1 23\n");
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("announces 23 elements"), "{e}");

    // A section without its end.
    let bad = format!("{v41}$NodeData\n1\n");
    let e = error(bad.as_bytes());
    assert!(
        e.problem.contains("unexpected end of file: $EndNodeData expected"),
        "{e}"
    );
    assert_eq!(e.location, format!("line {}", 1 + bad.matches('\n').count()));

    // Partitioned meshes.
    let bad = replace_once(
        &v41,
        "$Nodes\n",
        "$PartitionedEntities\n2\n0\n$EndPartitionedEntities\n$Nodes\n",
    );
    let e = error(bad.as_bytes());
    assert!(e.problem.contains("partitioned"), "{e}");
}

#[test]
fn unknown_sections_are_skipped_and_sparse_tags_read() {
    let v41 = String::from_utf8(fixture("two-parts-4.1.msh")).expect("text");
    let m = read(v41.as_bytes(), "4.1");
    let with = replace_once(
        &v41,
        "$Nodes\n",
        "$Comments\nnot $Nodes\n$EndNodes is not the end\n$EndComments\n$Nodes\n",
    ) + "$NodeData\n1\n\"u\"\n1\n0.0\n3\n0\n1\n1\n1 0.5\n$EndNodeData\n";
    assert_eq!(read(with.as_bytes(), "with comments"), m);

    // Binary too: a section of binary data that contains '$' and newlines.
    let bin = fixture("two-parts-4.1-binary.msh");
    let m = read(&bin, "4.1 binary");
    let at = find(&bin, b"$Nodes\n");
    let mut with = bin[..at].to_vec();
    with.extend_from_slice(b"$Periodic\n\x01\x00\x00\x00\n$End\n$EndPeriod\x00\n$EndPeriodic\n");
    with.extend_from_slice(&bin[at..]);
    assert_eq!(read(&with, "with $Periodic"), m);

    // Node tags far apart (the hash map instead of the dense index): MSH 2.2 with every node
    // tag multiplied by 1000.
    let v22 = String::from_utf8(fixture("two-parts-2.2.msh")).expect("text");
    let plain = read(v22.as_bytes(), "2.2");
    let mut sparse = String::new();
    let mut part = "";
    for line in v22.lines() {
        let mut words: Vec<String> = line.split(' ').map(str::to_string).collect();
        if line.starts_with('$') {
            part = line;
        } else if part == "$Nodes" && words.len() == 4 {
            words[0] = (words[0].parse::<u64>().expect("a tag") * 1000).to_string();
        } else if part == "$Elements" && words.len() > 3 {
            let first = 3 + words[2].parse::<usize>().expect("ntags");
            for w in &mut words[first..] {
                *w = (w.parse::<u64>().expect("a tag") * 1000).to_string();
            }
        }
        sparse += &words.join(" ");
        sparse.push('\n');
    }
    let m = read(sparse.as_bytes(), "sparse tags");
    assert_eq!(m.nodes, plain.nodes);
    assert_eq!(
        m.node_tags,
        plain.node_tags.iter().map(|t| t * 1000).collect::<Vec<_>>()
    );
    assert_eq!(element_keys(&m).len(), plain.elements.len());
    for (a, b) in m.elements.iter().zip(&plain.elements) {
        assert_eq!(a.nodes, b.nodes);
    }
}

fn find(bytes: &[u8], needle: &[u8]) -> usize {
    bytes
        .windows(needle.len())
        .position(|w| w == needle)
        .expect("in the fixture")
}

#[test]
fn malformed_binary_files_are_refused_with_their_byte_offset() {
    for file in ["two-parts-4.1-binary.msh", "two-parts-2.2-binary.msh"] {
        let bin = fixture(file);
        // Every truncation is an error at the end of the file, never a panic.
        for len in 0..bin.len() - "$EndElements\n".len() {
            let e = error(&bin[..len]);
            if len > 40 {
                assert!(e.problem.contains("unexpected end of file"), "{file} cut at {len}: {e}");
                assert_eq!(e.location, format!("byte offset {len}"), "{file} cut at {len}: {e}");
            }
        }
        let endianness = find(&bin, b" 1 8\n") + 5;
        // Big-endian.
        let mut bad = bin.clone();
        bad[endianness..endianness + 4].copy_from_slice(&[0, 0, 0, 1]);
        let e = error(&bad);
        assert!(e.problem.contains("big-endian"), "{file}: {e}");
        assert_eq!(e.location, format!("byte offset {endianness}"));
        // An int of 8 bytes.
        let mut bad = bin[..endianness + 4].to_vec();
        bad.extend_from_slice(&[0, 0, 0, 0]);
        bad.extend_from_slice(&bin[endianness + 4..]);
        let e = error(&bad);
        assert!(e.problem.contains("int of 4 bytes"), "{file}: {e}");
        // A size_t of 4 bytes.
        let bad = [&bin[..endianness - 2], b"4", &bin[endianness - 1..]].concat();
        let e = error(&bad);
        assert!(e.problem.contains("size_t of 4 bytes"), "{file}: {e}");
        assert_eq!(e.location, "line 2");
    }

    // An unknown node tag in MSH 2.2 binary: the first quadrangle's third node, 32.
    let bin = fixture("two-parts-2.2-binary.msh");
    let m = read(&bin, "2.2 binary");
    let quad = m.elements.iter().find(|e| e.kind == 16).expect("a quadrangle");
    let record: Vec<u8> = [quad.tag as i32, 1, 1]
        .into_iter()
        .chain(quad.nodes.iter().map(|&i| m.node_tags[i] as i32))
        .flat_map(i32::to_le_bytes)
        .collect();
    let at = find(&bin, &record);
    let mut bad = bin.clone();
    let third = at + 4 * (3 + 2);
    bad[third..third + 4].copy_from_slice(&999i32.to_le_bytes());
    let e = error(&bad);
    assert!(
        e.problem.contains(&format!("element {}", quad.tag)) && e.problem.contains("node 999"),
        "{e}"
    );
    assert_eq!(e.location, format!("byte offset {third}"));

    // z != 0 in MSH 4.1 binary: the node 32's z.
    let bin = fixture("two-parts-4.1-binary.msh");
    let m = read(&bin, "4.1 binary");
    let i = m.node_tags.iter().position(|&t| t == 32).expect("node 32");
    let xy: Vec<u8> = m.nodes[i].iter().flat_map(|c| c.to_le_bytes()).collect();
    let z = find(&bin, &xy) + 16;
    let mut bad = bin.clone();
    bad[z..z + 8].copy_from_slice(&0.5f64.to_le_bytes());
    let e = error(&bad);
    assert!(e.problem.contains("node 32 has z = 0.5"), "{e}");
    assert!(e.location.starts_with("byte offset "), "{e}");
}

#[test]
fn every_truncation_of_an_ascii_file_is_an_error_or_the_whole_mesh() {
    for file in ["two-parts-4.1.msh", "two-parts-2.2.msh"] {
        let text = fixture(file);
        let whole = read(&text, file);
        for len in 0..text.len() {
            match msh::parse(&text[..len]) {
                Ok(m) => assert_eq!(m, whole, "{file} cut at {len}"),
                Err(e) => assert!(e.location.starts_with("line "), "{file} cut at {len}: {e}"),
            }
        }
    }
}
