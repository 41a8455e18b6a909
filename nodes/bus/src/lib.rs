//! Nodes and buses. A [`Node`] is a sans-IO state machine: it consumes messages and returns the
//! messages it publishes; it never blocks, reads a clock or touches a socket. A bus moves
//! messages between nodes: [`InProcessBus`] runs every node in one process, delivering in rounds
//! (all messages of a round are handled, nodes in parallel on a rayon pool, outputs collected in
//! node order), so a run is deterministic whatever the thread count.

use glissade_messages::{key_matches, Envelope, Field, Message, NodeId, Stage, SCHEMA_VERSION};
use rayon::prelude::*;

pub mod convert;

/// What every node of a run shares: its run id and the scene fingerprint.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunContext {
    pub run_id: String,
    pub scene_fingerprint: u64,
}

impl RunContext {
    pub fn envelope(&self, sender: NodeId, iteration: u32, stage: Stage) -> Envelope {
        Envelope {
            schema_version: SCHEMA_VERSION,
            run_id: self.run_id.clone(),
            scene_fingerprint: self.scene_fingerprint,
            iteration,
            stage,
            sender,
        }
    }
}

/// A failure inside a node, named by the node.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{node}: {detail}")]
pub struct NodeError {
    pub node: NodeId,
    pub detail: String,
}

impl NodeError {
    pub fn new(node: NodeId, detail: impl std::fmt::Display) -> Self {
        Self {
            node,
            detail: detail.to_string(),
        }
    }
}

/// A participant of a run.
pub trait Node: Send {
    fn id(&self) -> NodeId;
    /// Key expressions this node consumes.
    fn subscriptions(&self) -> Vec<String>;
    /// Messages published when the run starts.
    fn start(&mut self) -> Result<Vec<Message>, NodeError>;
    /// Consumes one message and returns the messages it publishes in reply.
    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError>;
    /// The node has nothing more to do.
    fn is_finished(&self) -> bool;
}

/// Errors of a bus run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BusError {
    #[error(transparent)]
    Node(#[from] NodeError),
    #[error("no message in flight but nodes {0} are not finished (a node waits for an input that never came)")]
    Stalled(String),
}

/// Runs nodes in one process.
pub struct InProcessBus {
    nodes: Vec<Box<dyn Node>>,
    subscriptions: Vec<Vec<String>>,
}

impl InProcessBus {
    pub fn new(nodes: Vec<Box<dyn Node>>) -> Self {
        let subscriptions = nodes.iter().map(|n| n.subscriptions()).collect();
        Self { nodes, subscriptions }
    }

    /// Runs until no message is in flight. `observe` sees every message once, in publication order
    /// (the recorder's and the progress display's view); returning false from it aborts the run.
    pub fn run(&mut self, mut observe: impl FnMut(&Message) -> bool) -> Result<(), BusError> {
        let mut queue = Vec::new();
        for node in &mut self.nodes {
            queue.extend(node.start()?);
        }
        while !queue.is_empty() {
            for m in &queue {
                if !observe(m) {
                    return Ok(());
                }
            }
            let topics: Vec<String> = queue.iter().map(Message::topic).collect();
            let queue_ref = &queue;
            let results: Vec<Result<Vec<Message>, NodeError>> = self
                .nodes
                .par_iter_mut()
                .zip(self.subscriptions.par_iter())
                .map(|(node, subs)| {
                    let mut out = Vec::new();
                    for (m, topic) in queue_ref.iter().zip(&topics) {
                        if subs.iter().any(|s| key_matches(s, topic)) {
                            out.extend(node.handle(m)?);
                        }
                    }
                    Ok(out)
                })
                .collect();
            let mut next = Vec::new();
            for r in results {
                next.extend(r?);
            }
            queue = next;
        }
        let unfinished: Vec<String> = self
            .nodes
            .iter()
            .filter(|n| !n.is_finished())
            .map(|n| n.id().to_string())
            .collect();
        if unfinished.is_empty() {
            Ok(())
        } else {
            Err(BusError::Stalled(unfinished.join(", ")))
        }
    }

    /// The nodes, e.g. to read their final state.
    pub fn into_nodes(self) -> Vec<Box<dyn Node>> {
        self.nodes
    }
}

/// Checks that a field has the expected shape; names the field in the error.
pub fn expect_shape(node: NodeId, what: &str, f: &Field, rows: usize, cols: usize) -> Result<(), NodeError> {
    if f.rows() != rows || f.cols() != cols {
        return Err(NodeError::new(
            node,
            format!("{what} has shape {} × {}, expected {rows} × {cols}", f.rows(), f.cols()),
        ));
    }
    Ok(())
}
