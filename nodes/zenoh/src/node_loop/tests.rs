//! The node loop on a real bus: a launcher-side router and node processes (threads) as clients.

use super::*;
use crate::presence::{launcher_token, watch_tokens};
use crate::test_support::{displacement, received, test_launcher, test_run, wait_token};
use crate::{config, encode_log, open, publish, publish_done, publish_start};
use glissade_bus::NodeError;
use glissade_messages::{decode, Field, NodeId, Role};

/// A node that publishes one multi-MB message on start and is then finished.
struct OneShot {
    msg: Message,
    done: bool,
}

impl Node for OneShot {
    fn id(&self) -> NodeId {
        self.msg.envelope.sender
    }
    fn subscriptions(&self) -> Vec<String> {
        Vec::new()
    }
    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        self.done = true;
        Ok(vec![self.msg.clone()])
    }
    fn handle(&mut self, _: &Message) -> Result<Vec<Message>, NodeError> {
        Ok(Vec::new())
    }
    fn is_finished(&self) -> bool {
        self.done
    }
}

/// Waits until `ready` holds, or 10 s have passed.
fn wait_until(ready: impl Fn() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !ready() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// A process whose nodes are finished leaves only once the launcher says `done` (its last
/// put may still be queued), and without it only after its bounded wait, saying so.
#[test]
fn finished_process_waits_for_the_launchers_done() {
    let (launcher, endpoint) = test_launcher();
    let run_id = "done";
    let expected = test_run(run_id, "subdomain", Duration::ZERO).expected;
    let msg = displacement(run_id, 0, 3, Field::from_fn(400, 1001, |r, c| (r + 2 * c) as f64));
    let (_sub, rx) = received(&launcher, &msg.topic());
    let (alive_tx, alive_rx) = mpsc::channel::<(String, bool)>();
    let _alive = watch_tokens(&launcher, run_id, alive_tx, |k, up| (k, up)).unwrap();
    let _launcher_token = launcher_token(&launcher, run_id).unwrap();
    let spawn = |done_timeout: Duration| {
        let (endpoint, msg) = (endpoint.clone(), msg.clone());
        std::thread::spawn(move || {
            let session = open(config("client", &[], &[endpoint], false).unwrap()).unwrap();
            let run = test_run(run_id, "subdomain", done_timeout);
            let mut lines = Vec::new();
            let out = run_nodes(&session, &run, vec![Box::new(OneShot { msg, done: false })], |l| {
                lines.push(l.to_string())
            });
            let _ = session.close().wait();
            (out, lines)
        })
    };
    let node_token = topic::alive(run_id, "subdomain", 0);

    // Acknowledged: the node is still there a second after its message arrived, and leaves
    // at once after `done`.
    let node = spawn(Duration::from_secs(60));
    wait_token(&alive_rx, &node_token);
    publish_start(&launcher, run_id).unwrap();
    let bytes = rx.recv_timeout(Duration::from_secs(20)).expect("the node's output");
    assert_eq!(decode(&bytes, &expected).unwrap(), msg);
    std::thread::sleep(Duration::from_secs(1));
    assert!(!node.is_finished(), "the node left before the launcher's done");
    let asked = Instant::now();
    publish_done(&launcher, run_id).unwrap();
    let (out, lines) = node.join().unwrap();
    out.unwrap();
    assert!(asked.elapsed() < Duration::from_secs(10), "{:?}", asked.elapsed());
    assert!(lines.is_empty(), "{lines:?}");

    // Not acknowledged: the node leaves after its bounded wait and says why.
    let node = spawn(Duration::from_millis(500));
    wait_token(&alive_rx, &node_token);
    publish_start(&launcher, run_id).unwrap();
    rx.recv_timeout(Duration::from_secs(20)).expect("the node's output");
    let (out, lines) = node.join().unwrap();
    out.unwrap();
    assert!(
        lines
            .iter()
            .any(|l| l.contains("did not acknowledge the run's results")),
        "{lines:?}"
    );
}

/// A node that, handling its message, waits (up to 10 s) for the other nodes of its process
/// to be handling theirs at the same time, and says whether they were.
struct Meeting {
    id: NodeId,
    topic: String,
    inside: Arc<std::sync::atomic::AtomicUsize>,
    met: Arc<Mutex<Vec<bool>>>,
    done: bool,
}

impl Node for Meeting {
    fn id(&self) -> NodeId {
        self.id
    }
    fn subscriptions(&self) -> Vec<String> {
        vec![self.topic.clone()]
    }
    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        Ok(Vec::new())
    }
    fn handle(&mut self, _: &Message) -> Result<Vec<Message>, NodeError> {
        use std::sync::atomic::Ordering;
        self.inside.fetch_add(1, Ordering::SeqCst);
        wait_until(|| self.inside.load(Ordering::SeqCst) >= 2);
        self.met.lock().unwrap().push(self.inside.load(Ordering::SeqCst) == 2);
        self.done = true;
        Ok(Vec::new())
    }
    fn is_finished(&self) -> bool {
        self.done
    }
}

/// A node that, handling its message, waits (up to 10 s) until `open` is set.
struct Gate {
    topic: String,
    open: Arc<std::sync::atomic::AtomicBool>,
    done: bool,
}

impl Node for Gate {
    fn id(&self) -> NodeId {
        NodeId {
            role: Role::Coarse,
            index: 0,
        }
    }
    fn subscriptions(&self) -> Vec<String> {
        vec![self.topic.clone()]
    }
    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        Ok(Vec::new())
    }
    fn handle(&mut self, _: &Message) -> Result<Vec<Message>, NodeError> {
        wait_until(|| self.open.load(std::sync::atomic::Ordering::SeqCst));
        self.done = true;
        Ok(Vec::new())
    }
    fn is_finished(&self) -> bool {
        self.done
    }
}

/// Two nodes of one process, each waiting inside its `handle` for the other, both see the
/// other there: the process handled their messages in parallel (handled one after the
/// other, the first would wait its 10 s alone). The two messages wait on the process's
/// channel together: sent before the launcher's start, or, after it, while a third node
/// (the gate) holds the process's loop until they are there.
fn nodes_meet(run_id: &str, after_start: bool) {
    let (launcher, endpoint) = test_launcher();
    let message = |index: u32| displacement(run_id, index, 1, Field::zeros(2, 3));
    let (alive_tx, alive_rx) = mpsc::channel::<(String, bool)>();
    let _alive = watch_tokens(&launcher, run_id, alive_tx, |k, up| (k, up)).unwrap();
    let _launcher_token = launcher_token(&launcher, run_id).unwrap();
    let inside = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let met = Arc::new(Mutex::new(Vec::new()));
    let gate = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut nodes: Vec<Box<dyn Node>> = (0..2)
        .map(|i| {
            Box::new(Meeting {
                id: NodeId {
                    role: Role::Interface,
                    index: i,
                },
                topic: message(i).topic(),
                inside: inside.clone(),
                met: met.clone(),
                done: false,
            }) as Box<dyn Node>
        })
        .collect();
    if after_start {
        nodes.push(Box::new(Gate {
            topic: message(2).topic(),
            open: gate.clone(),
            done: false,
        }));
    }
    let run_id_owned = run_id.to_string();
    let node = std::thread::spawn(move || {
        let session = open(config("client", &[], &[endpoint], false).unwrap()).unwrap();
        let run = test_run(&run_id_owned, "interface", Duration::from_millis(200));
        // Two threads, whatever the machine's core count.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let out = pool.install(|| run_nodes(&session, &run, nodes, |_| {}));
        let _ = session.close().wait();
        out
    });
    wait_token(&alive_rx, &topic::alive(run_id, "interface", 0));
    let started = Instant::now();
    if after_start {
        publish_start(&launcher, run_id).unwrap();
        publish(&launcher, &message(2)).unwrap();
        std::thread::sleep(Duration::from_millis(300));
    }
    for i in 0..2 {
        publish(&launcher, &message(i)).unwrap();
    }
    std::thread::sleep(Duration::from_millis(500));
    if after_start {
        gate.store(true, std::sync::atomic::Ordering::SeqCst);
    } else {
        publish_start(&launcher, run_id).unwrap();
    }
    node.join().unwrap().unwrap();
    assert_eq!(
        *met.lock().unwrap(),
        vec![true, true],
        "the nodes did not handle their messages together"
    );
    assert!(started.elapsed() < Duration::from_secs(9), "{:?}", started.elapsed());
}

#[test]
fn a_process_handles_its_nodes_early_messages_in_parallel() {
    nodes_meet("parallel-early", false);
}

#[test]
fn a_process_handles_its_nodes_waiting_messages_in_parallel() {
    nodes_meet("parallel-waiting", true);
}

/// A node that takes the messages on its key in iteration order only (1, 2, …, `last`),
/// refusing the others as not yet its turn, as the solver's nodes do.
struct InOrder {
    topic: String,
    next: u32,
    last: u32,
    taken: Arc<Mutex<Vec<u32>>>,
}

impl Node for InOrder {
    fn id(&self) -> NodeId {
        NodeId {
            role: Role::Interface,
            index: 0,
        }
    }
    fn subscriptions(&self) -> Vec<String> {
        vec![self.topic.clone()]
    }
    fn start(&mut self) -> Result<Vec<Message>, NodeError> {
        Ok(Vec::new())
    }
    fn handle(&mut self, msg: &Message) -> Result<Vec<Message>, NodeError> {
        let it = msg.envelope.iteration;
        if it != self.next {
            return Err(NodeError::rejected(
                self.id(),
                format!("iteration {it} while at {}", self.next),
            ));
        }
        self.taken.lock().unwrap().push(it);
        self.next += 1;
        Ok(Vec::new())
    }
    fn is_finished(&self) -> bool {
        self.next > self.last
    }
}

/// A replacement process resumes from a recorder's log that holds a message before the one it
/// follows (the recorder hears each sender's messages through the router on their own, so its
/// order need not be one the nodes could have seen): the message refused at first is handed
/// again once the earlier one is taken, and the node finishes. Before, the refused message was
/// dropped and the node waited for it until the run stalled.
#[test]
fn a_resumed_process_takes_the_logs_messages_once_it_is_ready_for_them() {
    let (launcher, endpoint) = test_launcher();
    let run_id = "resume-order";
    let at = |iteration| displacement(run_id, 0, iteration, Field::from_fn(3, 2, |r, c| (r + c) as f64));
    // Iterations 3, 1, 2 in the log: 3 waits for 2, which waits for 1.
    let log: Vec<(String, Vec<u8>)> = [3, 1, 2].iter().map(|&i| (at(i).topic(), encode(&at(i)))).collect();
    let served = encode_log(&log);
    let _recorder = launcher
        .declare_queryable(topic::log(run_id))
        .callback(move |q| {
            q.reply(q.key_expr().clone(), served.clone()).wait().unwrap();
        })
        .wait()
        .unwrap();
    let taken = Arc::new(Mutex::new(Vec::new()));
    let node = InOrder {
        topic: at(1).topic(),
        next: 1,
        last: 3,
        taken: taken.clone(),
    };
    let session = open(config("client", &[], &[endpoint], false).unwrap()).unwrap();
    let mut run = test_run(run_id, "interface", Duration::from_millis(200));
    run.resume = true;
    run.supervised = true;
    run.idle_timeout = Duration::from_secs(5);
    let mut lines = Vec::new();
    let out = run_nodes(&session, &run, vec![Box::new(node)], |l| lines.push(l.to_string()));
    out.unwrap_or_else(|e| panic!("{e}: {lines:?}"));
    assert_eq!(*taken.lock().unwrap(), [1, 2, 3]);
    assert!(
        lines.iter().any(|l| l.contains("3 input(s) to handle again")),
        "{lines:?}"
    );
    assert!(!lines.iter().any(|l| l.contains("ignored")), "{lines:?}");
}
