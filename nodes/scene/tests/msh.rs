//! The Gmsh reader on files written by Gmsh itself, compared with Gmsh's own account of them.
//!
//! `tests/fixtures/msh/` holds one small QUA8 mesh in the four formats Gmsh writes (MSH 4.1 and
//! 2.2, ASCII and binary; and MSH 4.1 with parametric coordinates) with what Gmsh's API says of it (`two-parts.json`), the node count and
//! dimension of every element type Gmsh knows (`element-types.json`), and Gmsh's account of each
//! shipped mesh of `launch/scenes/meshes/` (`<mesh>.json`). All were written by the scripts of
//! `launch/scenes/meshes/`: these tests need no Gmsh.

use glissade_scene::msh::{self, Msh, MshError};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

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

/// The four formats, then MSH 4.1 with the nodes' parametric coordinates (ASCII, binary).
const FORMATS: [&str; 6] = [
    "two-parts-4.1.msh",
    "two-parts-4.1-binary.msh",
    "two-parts-2.2.msh",
    "two-parts-2.2-binary.msh",
    "two-parts-4.1-parametric.msh",
    "two-parts-4.1-parametric-binary.msh",
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

// ---------------------------------------------------------------------------------------------
// The meshes of launch/scenes/meshes/.

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
