//! What a run deploys and how its nodes are built: the [`Plan`] of a scene (k₀ and macro bases
//! per interface, the subdomains that take part, whether a coarse node is needed, the linear
//! stage, the interface nodes' groups), the [`Selection`] of nodes one process hosts, and the
//! builders of those nodes (subdomain operators in parallel). The launcher, the node processes,
//! re-execution and the tests all build nodes through here.

use glissade_bus::{Node, RunContext};
use glissade_coarse::CoarseNode;
use glissade_interface::InterfaceNode;
use glissade_mechanics::assembly::AssemblyError;
use glissade_mechanics::condensed::BoundaryLayout;
use glissade_mechanics::linear::{default_k0, macro_bases, LinearStage, SubdomainSolver};
use glissade_mechanics::model::Model;
use glissade_mechanics::pgd::PgdParams;
use glissade_scene::{LoadedScene, Partition};
use glissade_subdomain::{SubdomainNode, SubdomainOptions};
use rayon::prelude::*;
use std::sync::Arc;

/// Why nodes could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    #[error("subdomain `{name}`: {source}")]
    Operator { name: String, source: AssemblyError },
    #[error("node selection: {0}")]
    Selection(String),
}

/// What a scene's run needs: k₀ and macro bases per interface, the subdomains that take part
/// (those with an interface), and whether a coarse node is needed.
#[derive(Debug, Clone)]
pub struct Plan {
    pub k0: Vec<f64>,
    pub bases: Vec<Vec<Vec<f64>>>,
    pub participants: Vec<u32>,
    pub coarse: bool,
    /// The scene's linear stage (resolved per subdomain when `Auto`) and PGD settings.
    pub linear_stage: LinearStage,
    pub pgd: PgdParams,
    /// The interfaces each interface node owns (the scene's deployment; one node owning every
    /// interface by default).
    pub interface_groups: Vec<Vec<usize>>,
    /// Per interface node, the subdomain process that runs it (`interfaces_with_subdomains`), or
    /// None: a process of its own, or a thread of the launcher's.
    pub interface_hosts: Vec<Option<usize>>,
    /// How [`Plan::groups`] splits the participants into processes.
    pub partition: Partition,
    /// Each subdomain's centroid (the mean of its nodes, mm), for [`Partition::Bisection`].
    pub centroids: Vec<[f64; 2]>,
}

impl Plan {
    pub fn new(model: &Model) -> Self {
        let k0 = default_k0(model);
        let bases = macro_bases(model);
        let participants = (0..model.subdomains.len())
            .filter(|&s| model.interfaces.iter().any(|i| i.a == s || i.b == s))
            .map(|s| s as u32)
            .collect();
        Self {
            k0,
            bases,
            participants,
            coarse: model.solver.coarse && !model.interfaces.is_empty(),
            linear_stage: LinearStage::Condensed,
            pgd: PgdParams::default(),
            interface_groups: vec![(0..model.interfaces.len()).collect()],
            interface_hosts: vec![None],
            partition: Partition::Contiguous,
            centroids: model
                .subdomains
                .iter()
                .map(|sub| {
                    let n = sub.mesh.coords.len().max(1) as f64;
                    let (x, y) = sub
                        .mesh
                        .coords
                        .iter()
                        .fold((0.0, 0.0), |(x, y), c| (x + c[0], y + c[1]));
                    // To the nanometre: subdomains of one column or row of a structured layout
                    // then tie exactly unless their sums' rounding straddles a half nanometre.
                    [(x / n * 1e6).round() / 1e6, (y / n * 1e6).round() / 1e6]
                })
                .collect(),
        }
    }

    /// The plan with the scene's linear-stage settings and deployment.
    pub fn with_scene(mut self, scene: &LoadedScene) -> Self {
        self.linear_stage = scene.linear_stage;
        self.pgd = scene.pgd.clone();
        self.partition = scene.deployment.partition;
        if scene.deployment.interfaces_with_subdomains {
            let groups = self.groups(scene.deployment.subdomain_nodes);
            (self.interface_groups, self.interface_hosts) = interfaces_with_subdomains(&scene.model, &groups);
        } else {
            self.interface_groups = scene.deployment.interface_groups(&scene.model);
            self.interface_hosts = vec![None; self.interface_groups.len()];
        }
        self
    }

    /// The interface nodes subdomain process `group` runs (`interfaces_with_subdomains`).
    pub fn interface_nodes_in(&self, group: usize) -> Vec<usize> {
        (0..self.interface_hosts.len())
            .filter(|&k| self.interface_hosts[k] == Some(group))
            .collect()
    }

    /// The linear stage subdomain `s` uses (`Auto` resolved from its boundary size).
    pub fn stage_of(&self, model: &Model, s: usize) -> LinearStage {
        match self.linear_stage {
            LinearStage::Auto => self.linear_stage.resolve(BoundaryLayout::new(model, s, &self.k0).len()),
            other => other,
        }
    }

    /// The participants split into `n` groups, one per subdomain node process, whose sizes differ
    /// by at most one: `n` processes whenever there are at least `n` participants, one per
    /// participant otherwise. [`Partition::Contiguous`]: runs of consecutive participants, the
    /// first groups taking the extra ones. [`Partition::Bisection`]: the participants sorted along
    /// the longer side of the box around their centroids and cut in two, the first part getting
    /// the subdomains of the first ⌊k/2⌋ of the k groups to make, and so on in each part; each
    /// group's subdomains in ascending order.
    pub fn groups(&self, n: usize) -> Vec<Vec<u32>> {
        let p = self.participants.len();
        if p == 0 {
            return Vec::new();
        }
        let n = n.clamp(1, p);
        let (base, extra) = (p / n, p % n);
        let sizes: Vec<usize> = (0..n).map(|g| base + usize::from(g < extra)).collect();
        match self.partition {
            Partition::Contiguous => {
                let mut start = 0;
                sizes
                    .iter()
                    .map(|&len| {
                        start += len;
                        self.participants[start - len..start].to_vec()
                    })
                    .collect()
            }
            Partition::Bisection => {
                assert!(
                    self.participants.iter().all(|&s| (s as usize) < self.centroids.len()),
                    "Plan::centroids must hold every participant's centroid for bisection"
                );
                let mut groups = Vec::with_capacity(n);
                self.bisect(self.participants.clone(), &sizes, &mut groups);
                groups
            }
        }
    }

    /// Recursive coordinate bisection of `subdomains` into groups of `sizes` (summing to their
    /// count), appended to `out` in order. Ties along the cut's axis are broken by the other
    /// coordinate, then by index, so that the groups do not depend on the order of `subdomains`.
    fn bisect(&self, mut subdomains: Vec<u32>, sizes: &[usize], out: &mut Vec<Vec<u32>>) {
        if sizes.len() == 1 {
            subdomains.sort_unstable();
            out.push(subdomains);
            return;
        }
        let c = |s: u32| self.centroids[s as usize];
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &s in &subdomains {
            for d in 0..2 {
                lo[d] = lo[d].min(c(s)[d]);
                hi[d] = hi[d].max(c(s)[d]);
            }
        }
        let axis = usize::from(hi[1] - lo[1] > hi[0] - lo[0]);
        subdomains.sort_unstable_by(|&a, &b| {
            let (ca, cb) = (c(a), c(b));
            ca[axis]
                .total_cmp(&cb[axis])
                .then(ca[1 - axis].total_cmp(&cb[1 - axis]))
                .then(a.cmp(&b))
        });
        let (first, second) = sizes.split_at(sizes.len() / 2);
        let rest = subdomains.split_off(first.iter().sum());
        self.bisect(subdomains, first, out);
        self.bisect(rest, second, out);
    }

    /// The deployment as `glissade check` prints it: per subdomain process of `groups` (this
    /// plan's [`Plan::groups`]), the subdomains it hosts (indices as `glissade node --subdomains`
    /// takes them, runs of consecutive ones as a–b); per interface node, how many interfaces it
    /// owns and where it runs.
    pub fn deployment_lines(&self, groups: &[Vec<u32>]) -> Vec<String> {
        let runs = |s: &[u32]| {
            let mut out: Vec<String> = Vec::new();
            let mut i = 0;
            while i < s.len() {
                let mut j = i;
                while j + 1 < s.len() && s[j + 1] == s[j] + 1 {
                    j += 1;
                }
                out.push(if j > i {
                    format!("{}-{}", s[i], s[j])
                } else {
                    s[i].to_string()
                });
                i = j + 1;
            }
            out.join(", ")
        };
        let mut lines = vec![format!(
            "subdomain processes: {} (partition = \"{}\")",
            groups.len(),
            self.partition.name()
        )];
        for (g, group) in groups.iter().enumerate() {
            lines.push(format!(
                "  subdomain:{g}: {} subdomain(s): {}",
                group.len(),
                runs(group)
            ));
        }
        for (k, (owned, host)) in self.interface_groups.iter().zip(&self.interface_hosts).enumerate() {
            let at = match host {
                Some(g) => format!("in subdomain:{g}'s process"),
                None => "beside the router in the launcher's process, or in a process of its own where the run \
                         restarts nodes, goes through --connect, starts it by hand or sets \
                         interfaces_in_launcher = false"
                    .to_string(),
            };
            lines.push(format!("  interface:{k}: {} interface(s), {at}", owned.len()));
        }
        lines
    }

    /// Nodes used (role × count) and what is left out and why.
    pub fn describe(&self, model: &Model, subdomain_processes: usize) -> (Vec<String>, Vec<String>) {
        let mut names = vec![
            format!(
                "subdomain × {} (in {} process(es))",
                self.participants.len(),
                subdomain_processes
            ),
            format!("interface × {}", self.interface_groups.len()),
        ];
        let mut left_out = Vec::new();
        if self.coarse {
            names.push("coarse × 1".into());
        } else {
            left_out.push("coarse node: the scene switches the coarse problem off".into());
        }
        if model.subdomains.len() > self.participants.len() {
            left_out.push(format!(
                "{} subdomain(s) without interface: not part of the iteration",
                model.subdomains.len() - self.participants.len()
            ));
        }
        (names, left_out)
    }
}

/// The interface nodes of `interfaces_with_subdomains` for the subdomain processes `groups`: node
/// 0 owns the interfaces between subdomains of different processes, then one node per process
/// owns the interfaces between its own subdomains (processes without such an interface have
/// none). When no interface joins two processes, the first process's node is node 0. Returns
/// the groups of interfaces and, per node, the process that runs it (None: node 0 of the
/// interfaces between processes, which runs where interface nodes run without this setting).
pub fn interfaces_with_subdomains(model: &Model, groups: &[Vec<u32>]) -> (Vec<Vec<usize>>, Vec<Option<usize>>) {
    let mut process = vec![usize::MAX; model.subdomains.len()];
    for (g, group) in groups.iter().enumerate() {
        for &s in group {
            process[s as usize] = g;
        }
    }
    let mut between = Vec::new();
    let mut inside = vec![Vec::new(); groups.len()];
    for (i, itf) in model.interfaces.iter().enumerate() {
        let (ga, gb) = (process[itf.a], process[itf.b]);
        if ga == gb {
            inside[ga].push(i);
        } else {
            between.push(i);
        }
    }
    let mut owned = Vec::new();
    let mut hosts = Vec::new();
    if !between.is_empty() {
        owned.push(between);
        hosts.push(None);
    }
    for (g, interfaces) in inside.into_iter().enumerate() {
        if !interfaces.is_empty() {
            owned.push(interfaces);
            hosts.push(Some(g));
        }
    }
    (owned, hosts)
}

/// Which nodes one process hosts.
#[derive(Debug, Clone, PartialEq)]
pub struct Selection {
    pub subdomains: Vec<u32>,
    /// Every interface node of the plan (see [`build_interface_node`] for one of several).
    pub interface: bool,
    pub coarse: bool,
}

/// Interface node `index` of the plan's deployment.
pub fn build_interface_node(
    model: &Arc<Model>,
    ctx: &RunContext,
    plan: &Plan,
    index: usize,
) -> Result<Box<dyn Node>, BuildError> {
    if index >= plan.interface_groups.len() {
        return Err(BuildError::Selection(format!(
            "interface node {index}: the deployment has {} interface node(s), indices 0 to {}",
            plan.interface_groups.len(),
            plan.interface_groups.len() - 1
        )));
    }
    let pgd = plan
        .participants
        .iter()
        .copied()
        .filter(|&s| plan.stage_of(model, s as usize) == LinearStage::Pgd)
        .collect();
    Ok(Box::new(
        InterfaceNode::owning(ctx.clone(), model.clone(), &plan.k0, &plan.interface_groups, index)
            .with_mode_senders(pgd),
    ))
}

impl Selection {
    pub fn everything(plan: &Plan) -> Self {
        Self {
            subdomains: plan.participants.clone(),
            interface: true,
            coarse: plan.coarse,
        }
    }
}

/// Builds the nodes of `selection` (subdomain operators in parallel).
pub fn build_nodes(
    model: &Arc<Model>,
    ctx: &RunContext,
    interior: bool,
    plan: &Plan,
    selection: &Selection,
) -> Result<Vec<Box<dyn Node>>, BuildError> {
    let solvers = build_solvers(model, plan, &selection.subdomains)?;
    build_nodes_with(model, ctx, interior, plan, selection, solvers)
}

/// The linear-stage operators of `subdomains`, built in parallel.
pub fn build_solvers(model: &Model, plan: &Plan, subdomains: &[u32]) -> Result<Vec<SubdomainSolver>, BuildError> {
    for s in subdomains {
        if !plan.participants.contains(s) {
            return Err(BuildError::Selection(format!(
                "subdomain {s} has no interface or does not exist"
            )));
        }
    }
    subdomains
        .par_iter()
        .map(|&s| {
            // A_E only for the condensed stage; the sparse and PGD stages use the sparse factors.
            let dense = plan.stage_of(model, s as usize) == LinearStage::Condensed;
            SubdomainSolver::with_dense(model, s as usize, &plan.k0, &plan.bases, dense).map_err(|source| {
                BuildError::Operator {
                    name: model.subdomains[s as usize].name.clone(),
                    source,
                }
            })
        })
        .collect()
}

/// As [`build_nodes`], with the operators of `selection`'s subdomains already built (in its
/// order).
pub fn build_nodes_with(
    model: &Arc<Model>,
    ctx: &RunContext,
    interior: bool,
    plan: &Plan,
    selection: &Selection,
    solvers: Vec<SubdomainSolver>,
) -> Result<Vec<Box<dyn Node>>, BuildError> {
    debug_assert!(solvers
        .iter()
        .map(|s| s.subdomain as u32)
        .eq(selection.subdomains.iter().copied()));
    let options = SubdomainOptions {
        coarse: plan.coarse,
        relaxation: model.solver.relaxation,
        send_displacement: interior,
        acceleration: model.solver.acceleration,
    };
    let mut nodes: Vec<Box<dyn Node>> = Vec::new();
    for solver in solvers {
        let stage = plan.stage_of(model, solver.subdomain);
        let mut node = SubdomainNode::new(ctx.clone(), model.clone(), solver, options)
            .with_interface_owners(&plan.interface_groups);
        if stage == LinearStage::Pgd {
            node = node.with_pgd(plan.pgd.settings());
        }
        nodes.push(Box::new(node));
    }
    if selection.interface {
        for index in 0..plan.interface_groups.len() {
            nodes.push(build_interface_node(model, ctx, plan, index)?);
        }
    }
    if selection.coarse {
        let n_modes = plan.bases.iter().map(Vec::len).collect();
        nodes.push(Box::new(CoarseNode::new(
            ctx.clone(),
            n_modes,
            plan.participants.clone(),
            model.time.n_points(),
        )));
    }
    Ok(nodes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_mechanics::model::InterfaceKind;

    fn plan_of(participants: usize) -> Plan {
        Plan {
            k0: Vec::new(),
            bases: Vec::new(),
            participants: (0..participants as u32).collect(),
            coarse: false,
            linear_stage: LinearStage::Condensed,
            pgd: PgdParams::default(),
            interface_groups: Vec::new(),
            interface_hosts: Vec::new(),
            partition: Partition::Contiguous,
            centroids: Vec::new(),
        }
    }

    fn sizes(participants: usize, n: usize) -> Vec<usize> {
        let groups = plan_of(participants).groups(n);
        // Contiguous and complete: the groups, in order, are the participants.
        let flat: Vec<u32> = groups.concat();
        assert_eq!(flat, (0..participants as u32).collect::<Vec<_>>());
        groups.iter().map(Vec::len).collect()
    }

    /// As many processes as asked for while there are subdomains for them, sizes within one of
    /// each other (before, 5 subdomains on 4 processes gave 3 processes of 2, 2 and 1).
    #[test]
    fn groups_are_as_many_as_asked_and_balanced() {
        assert_eq!(sizes(18, 3), [6, 6, 6]);
        assert_eq!(sizes(6, 2), [3, 3]);
        assert_eq!(sizes(5, 4), [2, 1, 1, 1]);
        assert_eq!(sizes(7, 3), [3, 2, 2]);
        assert_eq!(sizes(3, 5), [1, 1, 1]);
        assert_eq!(sizes(4, 0), [4]);
        assert!(sizes(0, 3).is_empty());
    }

    /// `interfaces_with_subdomains` on the small three-layer scene: node 0 owns exactly the
    /// interfaces between subdomains of different processes and runs where interface nodes run
    /// otherwise; each other node owns the interfaces inside one process and runs in it; every
    /// interface has one owner. With one process every interface is inside it (its node is node 0);
    /// with a process per subdomain every interface is between two (node 0 alone).
    #[test]
    fn interfaces_follow_their_subdomains() {
        let text = include_str!("../../../launch/scenes/small-three-layer.toml");
        for processes in [1, 2, 3, 6] {
            let text = text.replace(
                "[deployment]\nsubdomain_nodes = 2\n",
                &format!("[deployment]\nsubdomain_nodes = {processes}\ninterfaces_with_subdomains = true\n"),
            );
            let scene = glissade_scene::load_str(&text, "small.toml").unwrap();
            let model = &scene.model;
            let plan = Plan::new(model).with_scene(&scene);
            let groups = plan.groups(processes);
            let process_of = |s: usize| groups.iter().position(|g| g.contains(&(s as u32))).unwrap();
            let (owned, hosts) = (&plan.interface_groups, &plan.interface_hosts);
            println!("{processes} process(es): {owned:?} hosted by {hosts:?}");
            assert_eq!(owned.len(), hosts.len());
            let mut all: Vec<usize> = owned.concat();
            all.sort_unstable();
            assert_eq!(all, (0..model.interfaces.len()).collect::<Vec<_>>(), "a partition");
            for (k, (interfaces, host)) in owned.iter().zip(hosts).enumerate() {
                assert!(!interfaces.is_empty());
                for &i in interfaces {
                    let (pa, pb) = (process_of(model.interfaces[i].a), process_of(model.interfaces[i].b));
                    match host {
                        Some(g) => assert_eq!((pa, pb), (*g, *g), "node {k}, interface {i}"),
                        None => assert!(k == 0 && pa != pb, "node {k}, interface {i}"),
                    }
                }
                assert_eq!(
                    plan.interface_nodes_in(host.unwrap_or(usize::MAX)).contains(&k),
                    host.is_some()
                );
            }
            match processes {
                1 => assert_eq!(hosts, &[Some(0)]),
                6 => assert_eq!(hosts, &[None]),
                _ => assert_eq!(hosts[0], None, "interfaces between processes"),
            }
        }
    }

    /// Bisection on a grid of `cols` × `rows` unit subdomains (row by row, as blocks number
    /// theirs): the groups are balanced, cover every subdomain once, in ascending order.
    fn grid_plan(cols: usize, rows: usize) -> Plan {
        let mut plan = plan_of(cols * rows);
        plan.partition = Partition::Bisection;
        plan.centroids = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| [c as f64 + 0.5, r as f64 + 0.5]))
            .collect();
        plan
    }

    #[test]
    fn bisection_groups_are_balanced_and_complete() {
        for (cols, rows) in [(6, 3), (50, 20), (7, 5), (1, 9), (3, 1)] {
            let plan = grid_plan(cols, rows);
            let p = cols * rows;
            for n in [1, 2, 3, 4, 7, 10, p] {
                let groups = plan.groups(n);
                assert_eq!(groups.len(), n.min(p), "{cols} × {rows}, {n}");
                let mut all = groups.concat();
                all.sort_unstable();
                assert_eq!(
                    all,
                    (0..p as u32).collect::<Vec<_>>(),
                    "{cols} × {rows}, {n}: a partition"
                );
                let (min, max) = groups
                    .iter()
                    .fold((usize::MAX, 0), |(a, b), g| (a.min(g.len()), b.max(g.len())));
                assert!(max - min <= 1, "{cols} × {rows}, {n}: sizes {min} to {max}");
                assert!(groups.iter().all(|g| g.windows(2).all(|w| w[0] < w[1])), "ascending");
            }
        }
        // A laminate of 20 plies of 50 on 10 processes: the cuts go across the 50 columns
        // until a part is taller than wide, then across the plies. Runs of consecutive
        // subdomains (pairs of plies) are joined by 9 × 50 = 450 interfaces, strips of 5 columns
        // through every ply by 9 × 20 = 180; bisection's blocks by 140 (one 15-column part is
        // cut into three across its plies, not along whole plies; an independent
        // re-implementation of the cut counts the same).
        let cut = |groups: &[Vec<u32>]| {
            let mut of = vec![0; 1000];
            for (g, group) in groups.iter().enumerate() {
                for &s in group {
                    of[s as usize] = g;
                }
            }
            let right = (0..1000).filter(|&s| s % 50 < 49 && of[s] != of[s + 1]).count();
            let up = (0..950).filter(|&s| of[s] != of[s + 50]).count();
            right + up
        };
        let mut plan = grid_plan(50, 20);
        assert_eq!(cut(&plan.groups(10)), 140);
        plan.partition = Partition::Contiguous;
        assert_eq!(cut(&plan.groups(10)), 450);
    }

    /// The stratified scene on 3 processes: bisection cuts the 180 × 90 mm stack into three
    /// columns of 60 mm, so that 6 perfect interfaces join two processes (contiguous groups are
    /// the layers, joined by the 12 contact interfaces), and the contact interfaces are each
    /// inside one process.
    #[test]
    fn bisection_of_the_stratified_scene_is_three_columns() {
        let scene = glissade_scene::load_str(include_str!("../../../launch/scenes/stratified.toml"), "s.toml").unwrap();
        let model = &scene.model;
        let mut plan = Plan::new(model);
        let cut = |groups: &[Vec<u32>]| {
            let (owned, hosts) = interfaces_with_subdomains(model, groups);
            assert_eq!(hosts[0], None);
            owned[0].clone()
        };
        plan.partition = Partition::Contiguous;
        let layers = plan.groups(3);
        assert_eq!(layers[1], (6..12).collect::<Vec<u32>>());
        let between = cut(&layers);
        assert_eq!(between.len(), 12);
        assert!(between
            .iter()
            .all(|&i| matches!(model.interfaces[i].kind, InterfaceKind::Contact { .. })));
        plan.partition = Partition::Bisection;
        let columns = plan.groups(3);
        assert_eq!(
            columns,
            [[0, 1, 6, 7, 12, 13], [2, 3, 8, 9, 14, 15], [4, 5, 10, 11, 16, 17]]
        );
        let between = cut(&columns);
        assert_eq!(between.len(), 6);
        assert!(between
            .iter()
            .all(|&i| model.interfaces[i].kind == InterfaceKind::Perfect));
        // The shipped scene asks for it, and `glissade check` shows it.
        assert_eq!(scene.deployment.partition, Partition::Bisection);
        let shipped = Plan::new(model).with_scene(&scene);
        assert_eq!(
            shipped.deployment_lines(&shipped.groups(3)),
            [
                "subdomain processes: 3 (partition = \"bisection\")",
                "  subdomain:0: 6 subdomain(s): 0-1, 6-7, 12-13",
                "  subdomain:1: 6 subdomain(s): 2-3, 8-9, 14-15",
                "  subdomain:2: 6 subdomain(s): 4-5, 10-11, 16-17",
                "  interface:0: 6 interface(s), beside the router in the launcher's process, or in a process of its own \
                 where the run restarts nodes, goes through --connect, starts it by hand or sets \
                 interfaces_in_launcher = false",
                "  interface:1: 7 interface(s), in subdomain:0's process",
                "  interface:2: 7 interface(s), in subdomain:1's process",
                "  interface:3: 7 interface(s), in subdomain:2's process",
            ]
        );
    }
}
