//! Nodes the launcher runs in its own process ([`HostedNode`]) and how any node process takes
//! part in a run ([`node_run`]).

use super::{Supervision, DEPARTURE_GRACE, DONE_TIMEOUT, IDLE_TIMEOUT, READY_TIMEOUT};
use crate::children::{NodeName, NodeRole};
use crate::error::Error;
use glissade_bus::RunContext;
use glissade_deploy::{build_interface_node, Plan};
use glissade_mechanics::model::Model;
use glissade_messages::Expected;
use glissade_zenoh as transport;
use std::sync::Arc;
use std::time::Duration;

/// How node process `name` takes part in the run `expected` names.
pub(crate) fn node_run(name: NodeName, expected: Expected, supervision: Supervision) -> transport::NodeRun {
    transport::NodeRun {
        run_id: expected.run_id.clone(),
        expected,
        token_role: name.role.key().to_string(),
        token_index: name.index,
        start_timeout: READY_TIMEOUT,
        idle_timeout: IDLE_TIMEOUT,
        departure_grace: DEPARTURE_GRACE,
        supervised: supervision.supervised,
        resume: supervision.resume,
        done_timeout: DONE_TIMEOUT,
    }
}

/// An interface node the launcher runs in its own process, on its own session: the router's, so
/// that the fields between it and the subdomain processes cross one socket, not two (node →
/// router → node). It runs in a thread of its own until the run ends, as it would in a process
/// of its own (same node, same node loop, same messages).
pub(crate) struct HostedNode {
    pub(crate) name: NodeName,
    thread: Option<std::thread::JoinHandle<Result<(), String>>>,
    outcome: Option<Result<(), String>>,
}

impl HostedNode {
    /// Builds interface node `index` of the run `ctx` names, of `model` (planned as `plan`), and
    /// starts it on `session`. Its log lines go to the console under `[interface:<index>]`, as a
    /// node process's do.
    pub(crate) fn start_interface(
        session: &zenoh::Session,
        model: &Arc<Model>,
        ctx: &RunContext,
        plan: &Plan,
        index: u32,
    ) -> crate::Result<Self> {
        let name = NodeName {
            role: NodeRole::Interface,
            index,
        };
        let node = build_interface_node(model, ctx, plan, index as usize).map_err(|e| Error::Node {
            node: name.to_string(),
            why: e.to_string(),
        })?;
        let expected = Expected {
            run_id: ctx.run_id.clone(),
            scene_fingerprint: ctx.scene_fingerprint,
        };
        let run = node_run(name, expected, Supervision::default());
        let session = session.clone();
        let prefix = format!("[{name}] ");
        let thread = std::thread::Builder::new()
            .name(format!("node {name}"))
            .spawn(move || {
                let say = |line: &str| {
                    if crate::console::shows_child_line(line) {
                        crate::console::say(&format!("{prefix}{line}"));
                    }
                };
                let outcome = transport::run_nodes(&session, &run, vec![node], say).map_err(|e| e.to_string());
                // What a node process prints when it exits with an error.
                if let Err(e) = &outcome {
                    crate::console::say(&format!("{prefix}error: {e}"));
                }
                outcome
            })
            .map_err(|source| Error::Io {
                what: format!("cannot start node {name} in the launcher's process"),
                source,
            })?;
        Ok(Self {
            name,
            thread: Some(thread),
            outcome: None,
        })
    }

    /// How the node ended, once it has: Ok, or its error.
    pub(crate) fn outcome(&mut self) -> Option<&Result<(), String>> {
        if self.thread.as_ref().is_some_and(|t| t.is_finished()) {
            let thread = self.thread.take().expect("checked just above");
            self.outcome = Some(
                thread
                    .join()
                    .unwrap_or_else(|panic| Err(format!("it panicked: {}", panic_message(panic.as_ref())))),
            );
        }
        self.outcome.as_ref()
    }

    /// Waits up to `timeout` for the node to end (after `stop`).
    pub(crate) fn wait(&mut self, timeout: Duration) {
        let deadline = std::time::Instant::now() + timeout;
        while self.outcome().is_none() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

/// The message of a thread's panic (what `panic!` was given), or "(no message)".
pub(super) fn panic_message(panic: &(dyn std::any::Any + Send)) -> &str {
    panic
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| panic.downcast_ref::<&str>().copied())
        .unwrap_or("(no message)")
}
