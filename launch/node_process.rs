//! A node process (`glissade node subdomain|interface|coarse`): joins the run's bus, fetches the
//! scene (its text and the launcher's command-line overrides) over it, builds its nodes as the scene's deployment says and runs them until the run
//! ends.

use crate::bus::Joining;
use crate::children::{NodeName, NodeRole};
use crate::distributed::Supervision;
use crate::error::Error;
use crate::runner::RunError;
use glissade_bus::RunContext;
use glissade_deploy::{build_interface_node, build_nodes, Plan, Selection};
use glissade_zenoh as transport;
use std::sync::Arc;
use zenoh::Wait;

/// Runs one node process: joins the bus, fetches the scene of run `run_id` over it, builds its
/// nodes and runs them until the run ends. A subdomain node hosts the subdomains of group `index`
/// of the scene's deployment; `subdomains`, when given, must name the same ones.
pub fn run_node_process(
    role: NodeRole,
    run_id: &str,
    bus: &Joining,
    subdomains: &[u32],
    index: u32,
    supervision: Supervision,
) -> crate::Result<()> {
    let interior = supervision.interior;
    let name = NodeName { role, index };
    if role == NodeRole::Coarse && index != 0 {
        return Err(Error::Node {
            node: name.to_string(),
            why: "a run has one coarse node, index 0".into(),
        });
    }
    let session = bus.open(supervision.shared_memory)?;
    let (scene, expected) = crate::bus::fetch_run_scene(&session, run_id)?;
    let fp = expected.scene_fingerprint;
    let model = Arc::new(scene.model.clone());
    let plan = Plan::new(&model).with_scene(&scene);
    let selection = match role {
        NodeRole::Subdomain => {
            let groups = plan.groups(scene.deployment.subdomain_nodes);
            let Some(group) = groups.get(index as usize) else {
                return Err(Error::Node {
                    node: name.to_string(),
                    why: format!(
                        "the scene's deployment has {} subdomain node(s), indices 0 to {}",
                        groups.len(),
                        groups.len().saturating_sub(1)
                    ),
                });
            };
            if !subdomains.is_empty() && subdomains != group.as_slice() {
                return Err(Error::Node {
                    node: name.to_string(),
                    why: format!("--subdomains {subdomains:?} differ from the deployment's group {index}, {group:?}"),
                });
            }
            Selection {
                subdomains: group.clone(),
                interface: false,
                coarse: false,
            }
        }
        NodeRole::Interface => Selection {
            subdomains: Vec::new(),
            interface: false,
            coarse: false,
        },
        NodeRole::Coarse => Selection {
            subdomains: Vec::new(),
            interface: false,
            coarse: true,
        },
    };
    if role == NodeRole::Coarse && !plan.coarse {
        return Err(Error::Node {
            node: name.to_string(),
            why: "the scene needs no coarse node (its coarse problem is off)".into(),
        });
    }
    let ctx = RunContext {
        run_id: run_id.to_string(),
        scene_fingerprint: fp,
    };
    let mut nodes = build_nodes(&model, &ctx, interior, &plan, &selection).map_err(RunError::from)?;
    if role == NodeRole::Subdomain {
        // The interface nodes of the interfaces between this process's subdomains
        // (`deployment.interfaces_with_subdomains`).
        for k in plan.interface_nodes_in(index as usize) {
            nodes.push(build_interface_node(&model, &ctx, &plan, k).map_err(|e| Error::Node {
                node: name.to_string(),
                why: e.to_string(),
            })?);
        }
    }
    if role == NodeRole::Interface {
        if let Some(Some(g)) = plan.interface_hosts.get(index as usize) {
            return Err(Error::Node {
                node: name.to_string(),
                why: format!(
                    "interface node {index} runs in subdomain process {g} (deployment.interfaces_with_subdomains)"
                ),
            });
        }
        nodes.push(
            build_interface_node(&model, &ctx, &plan, index as usize).map_err(|e| Error::Node {
                node: name.to_string(),
                why: e.to_string(),
            })?,
        );
    }
    let run = crate::distributed::node_run(name, expected, supervision);
    let outcome = transport::run_nodes(&session, &run, nodes, crate::console::say);
    let _ = session.close().wait();
    Ok(outcome?)
}
