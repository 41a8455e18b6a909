//! TOML errors located: file, key, line and column.

use crate::raw::RawScene;
use crate::SceneError;
use std::collections::BTreeMap;

pub(crate) fn parse_raw(text: &str, file: &str) -> Result<RawScene, SceneError> {
    // A first pass without a schema separates syntax errors from schema errors.
    if let Err(e) = text.parse::<toml::Table>() {
        return Err(toml_error(text, file, &e, true));
    }
    toml::from_str::<RawScene>(text).map_err(|e| toml_error(text, file, &e, false))
}

pub(crate) fn toml_error(text: &str, file: &str, e: &toml::de::Error, syntax: bool) -> SceneError {
    let message = e.message().trim().replace('\n', "; ");
    let (key, place) = match e.span() {
        Some(span) => {
            let start = span.start.min(text.len());
            let (line, column) = line_column(text, start);
            let key = if syntax { None } else { key_at(text, start) };
            (key, format!("line {line}, column {column}: "))
        }
        None => (None, String::new()),
    };
    // serde names the field in "unknown field `k`" / "missing field `k`".
    let field = ["unknown field `", "missing field `"].iter().find_map(|pre| {
        let rest = message.strip_prefix(pre)?;
        Some(rest[..rest.find('`')?].to_string())
    });
    let key = match (key, field) {
        (Some(k), Some(f)) if k == f || k.ends_with(&format!(".{f}")) => k,
        (Some(k), Some(f)) if message.starts_with("missing") => format!("{k}.{f}"),
        (None, Some(f)) if message.starts_with("missing") => f,
        (Some(k), _) => k,
        (None, _) => "(syntax)".to_string(),
    };
    SceneError {
        file: file.to_string(),
        key,
        problem: format!("{place}{message}"),
        set_by: None,
    }
}

/// 1-based line and column (in characters) of byte `offset`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text.as_bytes()[..offset];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let line_start = before.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
    let column = String::from_utf8_lossy(&before[line_start..]).chars().count() + 1;
    (line, column)
}

/// Best-effort key path (`block[1].nx`) of the TOML text at byte `offset`: the enclosing table
/// header (array tables indexed from 0) and the key of the line (or of the nearest line above it
/// that starts a key, for values spanning several lines).
fn key_at(text: &str, offset: usize) -> Option<String> {
    let mut array_counts: BTreeMap<String, usize> = BTreeMap::new();
    let mut table = String::new();
    let mut line_key: Option<String> = None;
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        if pos > offset {
            break;
        }
        pos += line.len();
        let t = line.trim();
        if let Some(inner) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            let name = unquote_key(inner);
            let count = {
                let c = array_counts.entry(name.clone()).or_insert(0);
                *c += 1;
                *c
            };
            table = format!("{}[{}]", resolve_table(&name, &array_counts, true), count - 1);
            line_key = None;
        } else if let Some(inner) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
            table = resolve_table(&unquote_key(inner), &array_counts, false);
            line_key = None;
        } else if let Some(k) = line_key_of(t) {
            line_key = Some(k);
        }
    }
    match (table.is_empty(), line_key) {
        (true, None) => None,
        (true, Some(k)) => Some(k),
        (false, None) => Some(table),
        (false, Some(k)) => Some(format!("{table}.{k}")),
    }
}

/// Inserts array-of-tables indices into a dotted table name (`block.foo` → `block[1].foo`).
fn resolve_table(name: &str, array_counts: &BTreeMap<String, usize>, is_array: bool) -> String {
    let parts: Vec<&str> = name.split('.').collect();
    let mut out = String::new();
    for (i, part) in parts.iter().enumerate() {
        if i > 0 {
            out.push('.');
        }
        out.push_str(part);
        let last = i + 1 == parts.len();
        if let Some(&n) = array_counts.get(&parts[..=i].join(".")) {
            // The array table being opened gets its index from the caller.
            if !(last && is_array) {
                out.push_str(&format!("[{}]", n.saturating_sub(1)));
            }
        }
    }
    out
}

fn unquote_key(k: &str) -> String {
    k.split('.')
        .map(|p| p.trim().trim_matches('"').trim_matches('\''))
        .collect::<Vec<_>>()
        .join(".")
}

/// The key of a `key = value` line, if the line starts one.
fn line_key_of(line: &str) -> Option<String> {
    let eq = line.find('=')?;
    let k = line[..eq].trim();
    let ok = !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '"' | '\'' | ' '));
    ok.then(|| unquote_key(k))
}
