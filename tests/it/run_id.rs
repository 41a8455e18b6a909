//! Run ids: when none is given, the launcher draws 128 random bits, so a run's key expressions
//! (`glissade/<run id>/…`) and output files cannot be guessed or collide with another run's.

use std::collections::BTreeSet;
use std::process::Command;

fn generated_ids(runs: usize) -> Vec<String> {
    let dir = crate::common::scratch("run-id");
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/launch/scenes/two-blocks.toml");
    for _ in 0..runs {
        let out = Command::new(env!("CARGO_BIN_EXE_glissade"))
            .args(["run", scene, "--in-process", "--quiet", "--out"])
            .arg(&dir)
            .output()
            .expect("spawn glissade");
        assert!(
            out.status.success(),
            "run failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let mut ids: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().into_string().unwrap();
            name.strip_prefix("two-blocks-")?
                .strip_suffix(".summary.json")
                .map(str::to_string)
        })
        .collect();
    ids.sort();
    ids
}

#[test]
fn generated_run_ids_are_128_random_bits() {
    let ids = generated_ids(2);
    assert_eq!(ids.len(), 2, "one summary per run: {ids:?}");
    for id in &ids {
        // 16 bytes in lower-case hex.
        assert_eq!(id.len(), 32, "run id `{id}` is not 128 bits in hex");
        assert!(
            id.chars().all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase()),
            "run id `{id}`"
        );
    }
    let distinct: BTreeSet<_> = ids.iter().collect();
    assert_eq!(distinct.len(), 2, "two runs drew the same id: {ids:?}");
}
