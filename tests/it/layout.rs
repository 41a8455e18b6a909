//! The layout's rules (README, "Crate map") that the source itself shows: the launcher's modules depend on one
//! another without a cycle, the numerics open no file, and every key expression of a run is built
//! in `messages`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.expect("a directory entry").path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The code of a file without its comment lines.
fn code(path: &Path) -> String {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The first name after each `prefix` in `text` (`prefix` + `a::X` names `a`), and each name of a
/// group (`prefix` + `{a::X, b}` names `a` and `b`).
fn named_after(text: &str, prefix: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (i, _) in text.match_indices(prefix) {
        let rest = &text[i + prefix.len()..];
        let listed: Vec<&str> = match rest.strip_prefix('{') {
            Some(group) => group.split('}').next().unwrap_or("").split(',').collect(),
            None => vec![rest],
        };
        for n in listed {
            let name: String = n
                .trim_start()
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            out.push(name);
        }
    }
    out
}

/// The launcher library's modules (a file or a folder of `launch/`, the binary's own modules
/// left out) and the modules each one names as `crate::<module>`.
fn launcher_modules() -> BTreeMap<String, BTreeSet<String>> {
    let launch = root().join("launch");
    let binary = ["main", "cli", "commands", "log"];
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in sources(&launch) {
        let rel = f.strip_prefix(&launch).expect("under launch/");
        let first = rel.components().next().expect("a component");
        let module = first.as_os_str().to_string_lossy().trim_end_matches(".rs").to_string();
        if binary.contains(&module.as_str()) || module == "lib" || module == "scenes" {
            continue;
        }
        let uses = edges.entry(module.clone()).or_default();
        for name in named_after(&code(&f), "crate::") {
            // The crate root re-exports `error::{Error, Result}`.
            let name = match name.as_str() {
                "Error" | "Result" => "error".to_string(),
                _ => name,
            };
            if !name.is_empty() && name.starts_with(|c: char| c.is_ascii_lowercase()) && name != module {
                uses.insert(name);
            }
        }
    }
    edges
}

/// A cycle through `from` in `edges`, if there is one.
fn cycle(edges: &BTreeMap<String, BTreeSet<String>>, path: &mut Vec<String>) -> Option<Vec<String>> {
    let last = path.last().expect("a start").clone();
    for next in edges.get(&last).into_iter().flatten() {
        if let Some(k) = path.iter().position(|m| m == next) {
            let mut c = path[k..].to_vec();
            c.push(next.clone());
            return Some(c);
        }
        path.push(next.clone());
        if let Some(c) = cycle(edges, path) {
            return Some(c);
        }
        path.pop();
    }
    None
}

#[test]
fn the_launcher_modules_have_no_cycle() {
    let edges = launcher_modules();
    // The walk sees the modules that matter: a run, its processes, the bus, the outputs.
    for m in [
        "run",
        "runner",
        "distributed",
        "bus",
        "recording",
        "output",
        "vtu",
        "error",
    ] {
        assert!(edges.contains_key(m), "module {m} not found: {:?}", edges.keys());
    }
    assert!(edges["run"].contains("distributed") && edges["distributed"].contains("bus"));
    for start in edges.keys() {
        if let Some(c) = cycle(&edges, &mut vec![start.clone()]) {
            panic!("a cycle of launcher modules: {}", c.join(" → "));
        }
    }
    // The check sees a cycle when there is one.
    let mut with_cycle = edges.clone();
    with_cycle.entry("bus".into()).or_default().insert("run".into());
    assert!(cycle(&with_cycle, &mut vec!["run".into()]).is_some());
}

/// The modules of `launch/distributed` (its files but `mod.rs`) and the sibling modules each one
/// names as `super::<module>` (also inside `super::{…}`).
fn distributed_modules() -> BTreeMap<String, BTreeSet<String>> {
    let dir = root().join("launch/distributed");
    let files: Vec<PathBuf> = sources(&dir)
        .into_iter()
        .filter(|f| f.file_name().is_some_and(|n| n != "mod.rs"))
        .collect();
    let names: BTreeSet<String> = files
        .iter()
        .map(|f| f.file_stem().expect("a name").to_string_lossy().into_owned())
        .collect();
    let mut edges = BTreeMap::new();
    for f in &files {
        let module = f.file_stem().expect("a name").to_string_lossy().into_owned();
        let uses = named_after(&code(f), "super::")
            .into_iter()
            .filter(|name| names.contains(name) && *name != module)
            .collect();
        edges.insert(module, uses);
    }
    edges
}

/// The run as processes has no cycle between its own modules (the set-up does not need the
/// supervision that needs it: what both use of the run's messages is `arrival`).
#[test]
fn the_distributed_modules_have_no_cycle() {
    let edges = distributed_modules();
    for m in ["setup", "spawn", "supervise", "arrival"] {
        assert!(edges.contains_key(m), "module {m} not found: {:?}", edges.keys());
    }
    assert!(edges["supervise"].contains("setup") && edges["setup"].contains("arrival"));
    for start in edges.keys() {
        if let Some(c) = cycle(&edges, &mut vec![start.clone()]) {
            panic!("a cycle of launch/distributed modules: {}", c.join(" → "));
        }
    }
}

#[test]
fn the_numerics_open_no_file() {
    let mechanics = root().join("nodes/mechanics/src");
    for f in sources(&mechanics) {
        let text = code(&f);
        for what in ["std::fs", "File::", "std::net", "std::env::var"] {
            assert!(!text.contains(what), "{} uses {what}", f.display());
        }
    }
}

/// Key expressions of a run (`glissade/<run>/…`) are built by `glissade_messages::topic` only:
/// no other source outside tests writes one out.
#[test]
fn every_key_expression_is_built_in_messages() {
    let mut checked = 0;
    for dir in ["launch", "nodes"] {
        for f in sources(&root().join(dir)) {
            let s = f.to_string_lossy();
            if s.contains("/tests/") || s.ends_with("tests.rs") || s.contains("test_support") {
                continue;
            }
            let text = code(&f);
            // Test modules inside a source file are left out.
            let text = text.split("#[cfg(test)]").next().unwrap_or("");
            assert!(
                !text.contains("\"glissade/"),
                "{} writes a key expression out",
                f.display()
            );
            checked += 1;
        }
    }
    assert!(checked > 50, "{checked} files checked");
}
