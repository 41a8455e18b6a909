//! The commands that look at a scene without running LATIN: `check` (what it holds and how a run
//! deploys it) and `monolithic` (the glued linear-elastic solve).

use super::*;
use glissade_reference::glued::solve_glued;
use std::path::Path;

/// `glissade check <scene>`: the scene's size, its plane, its non-matching interfaces, how a run
/// as processes deploys it, and the rigid motions nothing but frictionless contact holds.
pub(crate) fn check(scene: &Path) -> anyhow::Result<ExitCode> {
    let sc = load_scene(scene)?;
    let m = &sc.model;
    println!(
        "scene `{}` ({:016x}): {} subdomains, {} interfaces ({} contact), {} time points, {} dofs",
        m.name,
        sc.fingerprint,
        m.subdomains.len(),
        m.interfaces.len(),
        m.interfaces.iter().filter(|i| i.is_contact()).count(),
        m.time.n_points(),
        m.subdomains.iter().map(|s| s.n_dofs()).sum::<usize>()
    );
    let plane = match m.plane {
        glissade_mechanics::model::Plane::Strain => "strain (unit thickness",
        glissade_mechanics::model::Plane::Stress => "stress (unit thickness",
        glissade_mechanics::model::Plane::Axisymmetric => "axisymmetric (x = r, y = z; totals over the circumference",
    };
    println!("plane: {plane}; forces in {})", m.plane.force_unit());
    for (i, itf) in m.interfaces.iter().enumerate() {
        if let Some(projection) = &itf.projection {
            println!(
                "interface {i} (`{}` – `{}`): non-matching, {} pairs on the nodes of `{}`, `{}` projected onto \
                 them ({} terms)",
                m.subdomains[itf.a].name,
                m.subdomains[itf.b].name,
                itf.n_pairs(),
                m.subdomains[itf.a].name,
                m.subdomains[itf.b].name,
                projection.nodes.len()
            );
            let mut b_nodes = projection.nodes.clone();
            b_nodes.sort_unstable();
            b_nodes.dedup();
            if itf.n_pairs() > b_nodes.len() {
                glissade::console::warn(&format!(
                    "interface {i}: its pairs are the finer side's nodes ({} against {} of `{}`: the coarser \
                     side's edges do not cover the interface from end to end); traction modes the coarser \
                     side cannot see may keep the iteration from settling (docs/method.md, \
                     \"Non-matching interfaces\")",
                    itf.n_pairs(),
                    b_nodes.len(),
                    m.subdomains[itf.b].name
                ));
            }
        }
    }
    // How a run as processes deploys it: which subdomains each process hosts, which
    // interfaces each interface node owns.
    let plan = glissade_deploy::Plan::new(m).with_scene(&sc);
    for line in plan.deployment_lines(&plan.groups(sc.deployment.subdomain_nodes)) {
        println!("{line}");
    }
    for warning in glissade_scene::free_motions(m) {
        glissade::console::warn(&warning);
    }
    Ok(ExitCode::SUCCESS)
}

/// `glissade monolithic <scene>`: every interface glued, one linear-elastic solve.
pub(crate) fn monolithic(scene: &Path) -> anyhow::Result<ExitCode> {
    let sc = load_scene(scene)?;
    let t0 = std::time::Instant::now();
    let sol = solve_glued(&sc.model).context("glued solve")?;
    let umax = sol
        .u
        .iter()
        .flat_map(|u| (0..u.ncols()).flat_map(move |j| (0..u.nrows()).map(move |i| u[(i, j)].abs())))
        .fold(0.0, f64::max);
    println!(
        "scene `{}`: glued linear-elastic solve of {} subdomains, {} time points in {:.3} s; max |u_i| = {umax:.6e} mm",
        sc.model.name,
        sc.model.subdomains.len(),
        sc.model.time.n_points(),
        t0.elapsed().as_secs_f64()
    );
    Ok(ExitCode::SUCCESS)
}
