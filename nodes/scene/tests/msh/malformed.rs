//! Malformed files refused with their line (ASCII) or byte offset (binary), sections skipped,
//! sparse tags read, and every truncation of a file refused.

use super::*;
use glissade_scene::msh::MshError;

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
