//! Validation errors, one per rule: what is refused and with which key.

use super::*;
#[test]
fn rejects_nu_out_of_range() {
    expect_err(
        &replaced("nu = 0.3", "nu = 0.5"),
        "materials.steel.nu",
        "outside (−1, 0.5)",
    );
    expect_err(
        &replaced("nu = 0.3", "nu = -1.0"),
        "materials.steel.nu",
        "outside (−1, 0.5)",
    );
}

#[test]
fn rejects_non_positive_e() {
    expect_err(&replaced("E = 210000.0", "E = 0"), "materials.steel.E", "must be > 0");
}

#[test]
fn rejects_negative_friction() {
    expect_err(
        &replaced("friction = 0.2", "friction = -0.1"),
        "interface[0].friction",
        "must be a finite number ≥ 0",
    );
    expect_err(
        &replaced("friction = 0.2", "friction = inf"),
        "interface[0].friction",
        "friction coefficient inf must be a finite number ≥ 0",
    );
}

#[test]
fn rejects_friction_on_perfect_and_contact_without_friction() {
    expect_err(
        &replaced("kind = \"contact\"", "kind = \"perfect\""),
        "interface[0].friction",
        "contact interfaces only",
    );
    expect_err(
        &replaced("friction = 0.2\n", ""),
        "interface[0].friction",
        "needs `friction`",
    );
}

#[test]
fn rejects_zero_steps_and_non_positive_duration() {
    expect_err(&replaced("N = 4", "N = 0"), "time.N", "N ≥ 1");
    expect_err(&replaced("T = 1.0", "T = 0.0"), "time.T", "> 0");
    expect_err(&replaced("T = 1.0", "T = -2"), "time.T", "> 0");
}

#[test]
fn rejects_bad_element_counts_and_split() {
    expect_err(
        &TWO_BLOCKS
            .replacen("nx = 16", "nx = 0", 2)
            .replacen("nx = 0", "nx = 16", 1),
        "block[1].nx",
        "nx = 0",
    );
    expect_err(&replaced("ny = 8", "ny = 0"), "block[0].ny", "ny = 0");
    expect_err(
        &replaced("ny = 8\n", "ny = 8\nsplit = [3, 1]\n"),
        "block[0].split",
        "must divide",
    );
    expect_err(
        &replaced("ny = 8\n", "ny = 8\nsplit = [0, 1]\n"),
        "block[0].split",
        "must divide",
    );
}

#[test]
fn rejects_empty_extent() {
    expect_err(
        &replaced("x = [0.0, 40.0]", "x = [40.0, 40.0]"),
        "block[0].x",
        "x0 < x1",
    );
    expect_err(&replaced("y = [0.0, 20.0]", "y = [20.0, 0.0]"), "block[0].y", "y0 < y1");
}

#[test]
fn rejects_unknown_material() {
    expect_err(
        &replaced("material = \"steel\"", "material = \"stel\""),
        "block[0].material",
        "unknown material `stel`",
    );
}

#[test]
fn rejects_unknown_names() {
    expect_err(
        &replaced("between = [\"lower\", \"upper\"]", "between = [\"lower\", \"uper\"]"),
        "interface[0].between",
        "unknown block or subdomain `uper`",
    );
    expect_err(
        &replaced("y = 0.0\nux", "blocks = [\"lower.1\"]\ny = 0.0\nux"),
        "boundary[0].blocks",
        "unknown block or subdomain `lower.1`",
    );
}

#[test]
fn rejects_rule_matching_no_interface() {
    let text = replaced("y = [20.0, 40.0]", "y = [20.5, 40.0]").replacen("y = 40.0", "y = 40", 1);
    expect_err(&text, "interface[0].between", "share no edge");
}

#[test]
fn non_matching_sides_need_one_that_ends_whole() {
    // 16 elements against 10 along y = 20: accepted, as a non-matching interface whose pairs are
    // the coarser side's nodes (21 of them), each seeing the finer side through its projection.
    let text = TWO_BLOCKS
        .replacen("nx = 16", "nx = 10", 2)
        .replacen("nx = 10", "nx = 16", 1);
    let model = crate::load_str(&text, "test.toml").unwrap().model;
    assert_eq!(model.interfaces.len(), 1);
    let itf = &model.interfaces[0];
    assert!(itf.is_non_matching());
    assert_eq!(itf.n_pairs(), 21);
    // Shifted by half an element: each side's edges cross an end of the shared segment.
    let shifted = replaced("x = [0.0, 40.0]\ny = [20.0", "x = [1.25, 41.25]\ny = [20.0");
    let e = expect_err(&shifted, "block[1]", "crosses an end of the shared segment");
    assert!(e.problem.contains("`lower`") && e.problem.contains("`upper`"), "{e}");
}

#[test]
fn rejects_overlapping_blocks() {
    let e = expect_err(
        &replaced("y = [20.0, 40.0]", "y = [19.0, 40.0]"),
        "block[1]",
        "overlaps",
    );
    assert!(e.problem.contains("`upper`") && e.problem.contains("`lower`"), "{e}");
}

#[test]
fn rejects_bad_formula() {
    expect_err(
        &replaced("\"0.004*sin(2*pi*t)\"", "\"0.004*sin(2*pi*s)\""),
        "boundary[1].ux",
        "unknown name `s`",
    );
    expect_err(
        &replaced("\"0.004*sin(2*pi*t)\"", "\"ln(t)\""),
        "boundary[1].ux",
        "not finite",
    );
}

#[test]
fn rejects_bad_tables() {
    let with = |t: &str| replaced("uy = -0.01", &format!("uy = {t}"));
    expect_err(
        &with("{ t = [0.0, 1.0], v = [0.0] }"),
        "boundary[1].uy",
        "2 entries but `v` has 1",
    );
    expect_err(
        &with("{ t = [0.0, 0.0], v = [0.0, 1.0] }"),
        "boundary[1].uy",
        "not strictly increasing",
    );
    expect_err(&with("{ t = [], v = [] }"), "boundary[1].uy", "is empty");
    expect_err(
        &with("{ t = [0.0, \"a\"], v = [0.0, 1.0] }"),
        "boundary[1].uy",
        "not a finite number",
    );
    expect_err(&with("{ v = [0.0] }"), "boundary[1].uy", "exactly one abscissa");
    expect_err(&with("[1.0]"), "boundary[1].uy", "found array");
}

#[test]
fn rejects_bad_solver_settings() {
    let with = |s: &str| format!("{TWO_BLOCKS}[solver]\n{s}\n");
    expect_err(&with("relaxation = 0.0"), "solver.relaxation", "outside (0, 1]");
    expect_err(&with("relaxation = 1.5"), "solver.relaxation", "outside (0, 1]");
    expect_err(&with("tolerance = 0.0"), "solver.tolerance", "must be > 0");
    expect_err(&with("tolerance = -1e-6"), "solver.tolerance", "must be > 0");
    expect_err(&with("accuracy = 0.0"), "solver.accuracy", "outside (0, 1)");
    expect_err(&with("accuracy = 1.5"), "solver.accuracy", "outside (0, 1)");
    expect_err(&with("k0_factor = 0"), "solver.k0_factor", "must be > 0");
    expect_err(&with("alpha = 1.0"), "solver.alpha", "outside [0, 1)");
    // 2(1 − 0.8)/(2 − 0.8) = 1/3: 0.34 is above, and accepted only with the update off.
    expect_err(
        &with("search_direction_update = true\nalpha = 0.34"),
        "solver.alpha",
        "above 0.3333 = 2(1 − μ)/(2 − μ) for relaxation μ = 0.8",
    );
    assert!(load(&with("alpha = 0.34")).is_ok());
    assert!(load(&with("search_direction_update = true\nalpha = 0.3333")).is_ok());
    expect_err(
        &format!("{TWO_BLOCKS}[deployment]\nsubdomain_nodes = 3\n"),
        "deployment.subdomain_nodes",
        "3 nodes",
    );
    assert_eq!(load(TWO_BLOCKS).unwrap().deployment.partition, Partition::Contiguous);
    assert_eq!(
        load(&format!("{TWO_BLOCKS}[deployment]\npartition = \"bisection\"\n"))
            .unwrap()
            .deployment
            .partition,
        Partition::Bisection
    );
    expect_err(
        &format!("{TWO_BLOCKS}[deployment]\npartition = \"metis\"\n"),
        "deployment.partition",
        "unknown variant `metis`, expected `contiguous` or `bisection`",
    );
    expect_err(
        &format!("{TWO_BLOCKS}[recording]\nfull_fields_every = 0\n"),
        "recording.full_fields_every",
        "≥ 1",
    );
}

#[test]
fn rejects_free_rigid_modes() {
    // Only ux on y = 0, nothing on top: y-translation and rotation are free.
    let text = replaced("ux = 0.0\nuy = 0.0", "ux = 0.0");
    let text = text.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
    let e = expect_err(&text, "boundary", "y-translation and rotation free");
    assert!(e.problem.contains("[lower, upper]"), "{e}");
    // ux = 0 along y = 0 and uy = 0 along x = 0 leave the rotation about the origin free.
    let text = replaced(
        "ux = 0.0\nuy = 0.0",
        "ux = 0.0\n[[boundary]]\nblocks = [\"lower\"]\nx = 0.0\nuy = 0.0",
    );
    let text = text.split("[[boundary]]\ny = 40.0").next().unwrap().to_string();
    let e = expect_err(&text, "boundary", "rotation free");
    assert!(!e.problem.contains("translation"), "{e}");
    // A second, unconnected block with no support.
    let text = format!(
        "{TWO_BLOCKS}[[block]]\nname = \"loose\"\nmaterial = \"steel\"\nx = [50.0, 60.0]\ny = [5.0, 15.0]\nnx = 2\nny = 2\n"
    );
    let e = expect_err(&text, "boundary", "x-translation, y-translation and rotation free");
    assert!(e.problem.contains("[loose]"), "{e}");
}

#[test]
fn rejects_duplicate_names() {
    expect_err(
        &replaced("name = \"upper\"", "name = \"lower\""),
        "block[1].name",
        "duplicate block name `lower`",
    );
    let text = replaced("ny = 8\n[[block]]", "ny = 8\nsplit = [2, 1]\n[[block]]").replacen(
        "name = \"upper\"",
        "name = \"lower.2\"",
        1,
    );
    expect_err(
        &text.replace("\"upper\"", "\"lower.2\""),
        "block[0].name",
        "`lower.2` generated from block `lower`",
    );
}

#[test]
fn rejects_bad_boundary_rules() {
    expect_err(
        &replaced("uy = -0.01", "uy = -0.01\nty = 1.0"),
        "boundary[1]",
        "not both",
    );
    expect_err(
        &replaced("ux = 0.0\nuy = 0.0\n", ""),
        "boundary[0]",
        "prescribes nothing",
    );
    expect_err(
        &replaced("y = 0.0\n", "y = 5.0\n"),
        "boundary[0]",
        "no outer side matches y = 5",
    );
    expect_err(&replaced("y = 0.0\n", ""), "boundary[0]", "give `side`, `x` or `y`");
}

#[test]
fn toml_errors_name_key_and_position() {
    let e = expect_err(&replaced("N = 4", "N = 4\nsteps = 3"), "time.steps", "line 6, column 1");
    assert!(e.problem.contains("unknown field `steps`"), "{e}");
    let e = expect_err(
        &TWO_BLOCKS
            .replacen("ny = 8", "ny = \"8\"", 2)
            .replacen("ny = \"8\"", "ny = 8", 1),
        "block[1].ny",
        "line 22",
    );
    assert!(e.problem.contains("column"), "{e}");
    let e = load(&replaced("[time]", "[time\n")).unwrap_err();
    assert_eq!(e.key, "(syntax)", "{e}");
    assert!(e.problem.contains("line 3"), "{e}");
    expect_err(
        &replaced("kind = \"contact\"", "kind = \"glue\""),
        "interface[0].kind",
        "glue",
    );
    expect_err(&replaced("T = 1.0\n", ""), "time.T", "missing field");
    expect_err(
        &replaced("[[boundary]]\ny = 0.0", "[[boundary]]\nside = \"middle\""),
        "boundary[0].side",
        "middle",
    );
}
