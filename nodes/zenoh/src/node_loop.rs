//! The node loop: a node process's nodes on the bus ([`run_nodes`]), from the launcher's start
//! (or from the recorder's log, when the process replaces one that died) until each node is
//! finished and the launcher holds the run's results. The phases, in order: declare what the
//! process listens to and its token ([`Listening`]), wait for the start ([`wait_for_start`]) or
//! resume ([`resume`]), handle messages until the nodes are finished ([`run_until_finished`]),
//! wait for the launcher's `done` ([`wait_for_done`]).

use crate::error::zerr;
use crate::presence::watch_tokens;
use crate::publish::Publishers;
use crate::receive::{batches, message_hash, PayloadBlocks, Received};
use crate::recorder_log::fetch_log;
use crate::shm::ShmLender;
use crate::watch::{Ask, DropOnce, Hook, Responder, Watch};
use crate::TransportError;
use glissade_bus::{take_when_ready, Node};
use glissade_messages::{
    encode, key_matches, topic, BlockLender, BufferPool, DecodeBuffers, Expected, Message, Routes,
};
use rayon::prelude::*;
use std::collections::{HashSet, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::{Session, Wait};

/// What a node process needs to take part in a run.
#[derive(Debug, Clone)]
pub struct NodeRun {
    pub run_id: String,
    pub expected: Expected,
    /// Role and index of this process's liveliness token.
    pub token_role: String,
    pub token_index: u32,
    /// Longest wait for the launcher's start.
    pub start_timeout: Duration,
    /// Longest wait for any message once started.
    pub idle_timeout: Duration,
    /// How long messages are still handled after a peer's token disappeared, before this
    /// process gives up (a peer that finished leaves right after its last messages).
    pub departure_grace: Duration,
    /// The launcher restarts node processes that die: a peer leaving is not fatal here (the
    /// launcher stops the run when it gives up on one); only the launcher's departure is.
    pub supervised: bool,
    /// This process replaces one that died mid-run: it rebuilds its nodes' state from the
    /// recorder's log of the run ([`fetch_log`]) instead of waiting for the launcher's start.
    pub resume: bool,
    /// Longest wait, once this process's nodes are finished, for the launcher's word that it
    /// holds the run's results ([`crate::publish_done`]); past it the process leaves anyway
    /// (logged).
    pub done_timeout: Duration,
}

impl NodeRun {
    /// This process's liveliness token.
    fn own_token(&self) -> String {
        topic::alive(&self.run_id, &self.token_role, self.token_index)
    }

    /// The launcher's liveliness token.
    fn launcher_token(&self) -> String {
        topic::alive(&self.run_id, "launcher", 0)
    }
}

/// What reaches a node process from the bus.
enum Event {
    Data(Box<Received>),
    Start,
    Stop(String),
    /// The launcher holds the run's results: leaving is safe.
    Done,
    /// A liveliness token appeared (true) or disappeared (false).
    Alive(String, bool),
    /// A line for the process's log from its status responder.
    Note(String),
}

/// Runs `nodes` (all hosted by this process) on `session` until each is finished.
///
/// Messages that do not decode for this run (other run, other scene, other schema version,
/// corrupt), repeats of a message already handled, and messages a node refuses while staying
/// unchanged ([`glissade_bus::NodeError::is_rejection`]) are skipped with a reason passed to
/// `log`; any other node error (e.g. a non-finite result) stops the process with that node's
/// error. A peer whose liveliness token disappears while a node here is unfinished stops the
/// process after `departure_grace` ([`TransportError::PeerLeft`]), so does the launcher's stop
/// message ([`TransportError::Stopped`]); `idle_timeout` bounds the wait for any message.
pub fn run_nodes(
    session: &Session,
    run: &NodeRun,
    mut nodes: Vec<Box<dyn Node>>,
    mut log: impl FnMut(&str),
) -> Result<(), TransportError> {
    let (tx, rx) = mpsc::channel::<Event>();
    let subscriptions: Vec<Vec<String>> = nodes.iter().map(|n| n.subscriptions()).collect();
    let mut keys: Vec<String> = subscriptions.iter().flatten().cloned().collect();
    keys.sort();
    keys.dedup();
    // The received fields' buffers: filled by the subscribers' decoding, given back once the
    // nodes have handled their message.
    let buffers = Arc::new(Mutex::new(BufferPool::default()));
    let watch = Watch::new(DropOnce::from_env().map_err(TransportError::Protocol)?);
    let (ask_tx, ask_rx) = mpsc::channel::<Ask>();
    let note_tx = Mutex::new(tx.clone());
    let _responder = Responder::start(
        session,
        run.expected.clone(),
        watch.clone(),
        (ask_tx.clone(), ask_rx),
        move |line| {
            let _ = note_tx
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .send(Event::Note(line));
        },
    );
    let _listening = Listening::declare(session, run, &keys, &buffers, &tx, &ask_tx)?;

    // With shared memory, the nodes write their large fields straight into the pools' blocks.
    let lender = ShmLender::new(session).map(Arc::new);
    if let Some(lender) = &lender {
        let lender: Arc<dyn BlockLender> = lender.clone();
        nodes.iter_mut().for_each(|n| n.lend_fields(lender.clone()));
    }
    let mut handler = Handler {
        session,
        publishers: Publishers::new(session),
        routes: Routes::new(subscriptions),
        buffers,
        seen: HashSet::new(),
        published: HashSet::new(),
        watch,
        touched: Vec::new(),
    };
    let mut inbox = Inbox { rx, pending: None };
    // The process says it is busy while it starts its nodes or rebuilds their state: the
    // launcher's watch then counts it as moving.
    handler.watch.update(&nodes);
    if run.resume {
        handler.watch.busy();
        resume(run, &keys, &mut nodes, &mut handler, &mut log)?;
    } else {
        let early = wait_for_start(run, &inbox.rx)?;
        handler.watch.busy();
        handler.start(&mut nodes)?;
        for batch in batches(early) {
            handler.handle(batch, &mut nodes, &mut log)?;
        }
    }
    handler.watch.update(&nodes);
    let done = run_until_finished(run, &mut nodes, &mut handler, &mut inbox, &mut log)?;
    if !done {
        wait_for_done(run, &mut inbox, &mut log)?;
    }
    if let Some(lender) = lender {
        report_lending(&lender, &mut log);
    }
    Ok(())
}

/// What a node process declares on the bus, in this order (start-up step 2 of the crate doc):
/// a subscriber per key its nodes subscribe to and per control key of the launcher (`start`,
/// `stop`, `done`), a watch on the run's liveliness tokens, then its own token. All of it
/// forwards to the process's channel; all of it is undeclared when dropped (the token first).
struct Listening {
    _token: zenoh::liveliness::LivelinessToken,
    _peers: zenoh::pubsub::Subscriber<()>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl Listening {
    fn declare(
        session: &Session,
        run: &NodeRun,
        keys: &[String],
        buffers: &Arc<Mutex<BufferPool>>,
        tx: &mpsc::Sender<Event>,
        ask: &mpsc::Sender<Ask>,
    ) -> Result<Self, TransportError> {
        let run_id = &run.run_id;
        let mut subscribers = Vec::new();
        for key in keys {
            let (tx, expected, pooled) = (tx.clone(), run.expected.clone(), DecodeBuffers::pooled(buffers.clone()));
            let sub = session
                .declare_subscriber(key.as_str())
                .callback(move |sample| {
                    let key = sample.key_expr().as_str().to_string();
                    let payload = sample.payload();
                    let buffers = PayloadBlocks::holding(pooled.clone(), payload);
                    let _ = tx.send(Event::Data(Box::new(Received::from_payload(
                        key, payload, &expected, buffers,
                    ))));
                })
                .wait()
                .map_err(|e| zerr(&format!("subscribe {key}"), e))?;
            subscribers.push(sub);
        }
        for (key, control) in [
            (topic::start(run_id), 0),
            (topic::stop(run_id), 1),
            (topic::done(run_id), 2),
        ] {
            let tx = tx.clone();
            let sub = session
                .declare_subscriber(key.as_str())
                .callback(move |s| {
                    let _ = tx.send(match control {
                        0 => Event::Start,
                        1 => Event::Stop(String::from_utf8_lossy(&s.payload().to_bytes()).into_owned()),
                        _ => Event::Done,
                    });
                })
                .wait()
                .map_err(|e| zerr(&format!("subscribe {key}"), e))?;
            subscribers.push(sub);
        }
        // The launcher's requests when the run stops moving, answered by the process's
        // responder (`crate::watch`).
        for (key, republish) in [(topic::status_request(run_id), false), (topic::republish(run_id), true)] {
            let ask = Mutex::new(ask.clone());
            let sub = session
                .declare_subscriber(key.as_str())
                .callback(move |s| {
                    let bytes = s.payload().to_bytes();
                    let asked = if republish {
                        Ask::Republish(String::from_utf8_lossy(&bytes).into_owned())
                    } else {
                        match <[u8; 8]>::try_from(bytes.as_ref()) {
                            Ok(round) => Ask::Status(u64::from_le_bytes(round)),
                            Err(_) => return,
                        }
                    };
                    let _ = ask.lock().unwrap_or_else(|e| e.into_inner()).send(asked);
                })
                .wait()
                .map_err(|e| zerr(&format!("subscribe {key}"), e))?;
            subscribers.push(sub);
        }
        let peers = watch_tokens(session, run_id, tx.clone(), Event::Alive)?;
        let token = session
            .liveliness()
            .declare_token(run.own_token().as_str())
            .wait()
            .map_err(|e| zerr("liveliness token", e))?;
        Ok(Self {
            _token: token,
            _peers: peers,
            _subscribers: subscribers,
        })
    }
}

/// The process's channel, and the event of another kind taken from it behind a batch of
/// messages, handled next.
struct Inbox {
    rx: mpsc::Receiver<Event>,
    pending: Option<Event>,
}

impl Inbox {
    /// The event held back, else the next one within `wait`.
    fn next(&mut self, wait: Duration) -> Result<Event, mpsc::RecvTimeoutError> {
        match self.pending.take() {
            Some(event) => Ok(event),
            None => self.rx.recv_timeout(wait),
        }
    }

    /// `first` with the messages already waiting behind it, up to the next event of another
    /// kind (held back, handled next in its turn).
    fn with_waiting(&mut self, first: Box<Received>) -> VecDeque<Box<Received>> {
        let mut waiting = VecDeque::from([first]);
        loop {
            match self.rx.try_recv() {
                Ok(Event::Data(r)) => waiting.push_back(r),
                Ok(other) => {
                    self.pending = Some(other);
                    break;
                }
                Err(_) => break,
            }
        }
        waiting
    }
}

/// Waits for the launcher's start, keeping the data that arrives early (a faster peer may start
/// first); fails on a departure or a stop.
fn wait_for_start(run: &NodeRun, rx: &mpsc::Receiver<Event>) -> Result<VecDeque<Box<Received>>, TransportError> {
    let own_token = run.own_token();
    let start_deadline = Instant::now() + run.start_timeout;
    let mut early = VecDeque::new();
    loop {
        let left = start_deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(Event::Start) => return Ok(early),
            Ok(Event::Stop(reason)) => return Err(TransportError::Stopped(reason)),
            Ok(Event::Alive(key, false)) if key != own_token => {
                return Err(TransportError::PeerLeft {
                    peer: topic::node_of_alive(&key),
                    others: Vec::new(),
                })
            }
            Ok(Event::Data(received)) => early.push_back(received),
            Ok(Event::Alive(..)) | Ok(Event::Done) | Ok(Event::Note(_)) => {}
            Err(_) => {
                return Err(TransportError::Protocol(format!(
                    "the launcher did not start the run within {:?}",
                    run.start_timeout
                )))
            }
        }
    }
}

/// Replaces a process that died: the recorder's log holds every input its nodes handled and
/// every output they published; handling the inputs again rebuilds their state (nodes are
/// deterministic whatever the arrival order of one stage's inputs), and the outputs not yet on
/// the bus are published as they come.
///
/// The log is in the order the recorder heard the messages, which need not be the order in which
/// they could happen: the router forwards each sender's messages on its own, so the recorder can
/// hear an Anderson step before the macro displacements the step's subdomain had received
/// before it sent its partials. A node refuses a message it is not ready for; such a message is
/// held and handed again after every message a node takes ([`take_when_ready`]), so that each
/// input is handled once the node is ready for it, as it was live.
fn resume(
    run: &NodeRun,
    keys: &[String],
    nodes: &mut [Box<dyn Node>],
    handler: &mut Handler,
    log: &mut dyn FnMut(&str),
) -> Result<(), TransportError> {
    let run_id = &run.run_id;
    let own: Vec<String> = nodes.iter().map(|n| topic::sent_by(run_id, n.id())).collect();
    let mut patterns = keys.to_vec();
    patterns.extend(own.iter().cloned());
    let recorded = fetch_log(handler.session, run_id, &patterns, run.start_timeout)?;
    let mut inputs = Vec::new();
    for (key, bytes) in recorded {
        if own.iter().any(|p| key_matches(p, &key)) {
            handler.published.insert(message_hash(&key, &bytes));
        }
        if keys.iter().any(|p| key_matches(p, &key)) {
            inputs.push((key, bytes));
        }
    }
    log(&format!(
        "resuming from the recorder's log: {} input(s) to handle again, {} output(s) already on the bus",
        inputs.len(),
        handler.published.len()
    ));
    handler.start(nodes)?;
    let refused = take_when_ready(inputs, |(key, bytes)| {
        handler.handle_or_refused(Received::from_bytes(key.clone(), bytes, &run.expected), nodes, log)
    })?;
    // Refused to the end: not for this run's nodes after all, or already past (logged as live).
    for (_, why) in refused {
        log(&why);
    }
    log("resumed: state rebuilt, continuing on the bus");
    Ok(())
}

/// Handles messages until every node is finished; true if the launcher's `done` came meanwhile
/// (it may hold every result before a node here has heard the final decision).
fn run_until_finished(
    run: &NodeRun,
    nodes: &mut [Box<dyn Node>],
    handler: &mut Handler,
    inbox: &mut Inbox,
    log: &mut dyn FnMut(&str),
) -> Result<bool, TransportError> {
    let (own_token, launcher_token) = (run.own_token(), run.launcher_token());
    let mut last_message = Instant::now();
    // The peers that left (first first), and when this process gives up on them.
    let mut departed: Vec<String> = Vec::new();
    let mut give_up: Option<Instant> = None;
    let mut done = false;
    while !nodes.iter().all(|n| n.is_finished()) {
        let now = Instant::now();
        if give_up.is_some_and(|t| now >= t) {
            // The launcher's token going with the others means the bus itself went away: name it.
            let first = departed.iter().position(|k| *k == launcher_token).unwrap_or(0);
            let peer = topic::node_of_alive(&departed.remove(first));
            return Err(TransportError::PeerLeft {
                peer,
                others: departed.iter().map(|k| topic::node_of_alive(k)).collect(),
            });
        }
        if now.duration_since(last_message) >= run.idle_timeout {
            return Err(TransportError::Timeout(run.idle_timeout));
        }
        let mut wait = run.idle_timeout - now.duration_since(last_message);
        if let Some(t) = give_up {
            wait = wait.min(t.saturating_duration_since(now));
        }
        match inbox.next(wait) {
            Ok(Event::Data(received)) => {
                last_message = Instant::now();
                // With the messages already waiting behind it, in batches cut at repeats.
                handler.watch.busy();
                for batch in batches(inbox.with_waiting(received)) {
                    let (count, last) = (batch.len(), batch.last().map(|r| (r.key.clone(), r.iteration())));
                    handler.handle(batch, nodes, log)?;
                    handler
                        .watch
                        .handled(count, last.as_ref().map(|(k, i)| (k.as_str(), *i)));
                }
                // Idle again, with the new waits of the nodes that took messages.
                handler.watch.update_touched(nodes, &mut handler.touched);
            }
            Ok(Event::Note(line)) => log(&line),
            Ok(Event::Stop(reason)) => return Err(TransportError::Stopped(reason)),
            Ok(Event::Alive(key, false)) if run.supervised && key != own_token && key != launcher_token => {
                // A note: the launcher says it when it restarts a node, and at the end of a run a
                // peer that got the launcher's `done` may leave before this process has handled
                // the messages still queued for it (its token's removal overtakes them).
                log(&format!(
                    "{}peer {} left the run; waiting for the launcher to restart it",
                    crate::NOTE,
                    topic::node_of_alive(&key)
                ));
            }
            Ok(Event::Alive(key, false)) if key != own_token => {
                give_up.get_or_insert_with(|| Instant::now() + run.departure_grace);
                departed.push(key);
            }
            Ok(Event::Done) => done = true,
            Ok(Event::Alive(..)) | Ok(Event::Start) | Err(_) => {}
        }
    }
    Ok(done)
}

/// A put returns once the message is queued, not delivered: closing the session right after the
/// last one can lose it. Waits (up to `done_timeout`) for the launcher to say it holds the run's
/// results.
fn wait_for_done(run: &NodeRun, inbox: &mut Inbox, log: &mut dyn FnMut(&str)) -> Result<(), TransportError> {
    let launcher_token = run.launcher_token();
    let deadline = Instant::now() + run.done_timeout;
    loop {
        match inbox.next(deadline.saturating_duration_since(Instant::now())) {
            Ok(Event::Done) => return Ok(()),
            Ok(Event::Stop(reason)) => return Err(TransportError::Stopped(reason)),
            Ok(Event::Alive(key, false)) if key == launcher_token => {
                log("the launcher left before it acknowledged the run's results; leaving");
                return Ok(());
            }
            Ok(Event::Note(line)) => log(&line),
            Ok(_) => {}
            Err(_) => {
                log(&format!(
                    "the launcher did not acknowledge the run's results within {:?}; leaving",
                    run.done_timeout
                ));
                return Ok(());
            }
        }
    }
}

/// Logs how many large fields the nodes wrote in place and how many were copied, if any.
fn report_lending(lender: &ShmLender, log: &mut dyn FnMut(&str)) {
    let (lent, refused) = lender.counts();
    if lent + refused > 0 {
        log(&format!(
            "{}shared memory: {lent} large field(s) written in place and sent without a copy, {refused} copied \
             for lack of room{}",
            crate::NOTE,
            if refused > 0 {
                " (every pool full, or no room in /dev/shm for another)"
            } else {
                ""
            }
        ));
    }
}

/// Per node: the messages it refused (index, reason), or the error that ends the run with the
/// index of the message that caused it.
type Outcome = Result<Vec<(usize, String)>, (usize, TransportError)>;

/// Hands the messages that arrive to the process's nodes and publishes what they answer.
struct Handler<'a> {
    session: &'a Session,
    /// Its publishers, one per key this process's nodes publish on.
    publishers: Publishers<'a>,
    /// Which of the nodes each key reaches ([`Routes`]).
    routes: Routes,
    /// The received fields' buffers ([`run_nodes`]).
    buffers: Arc<Mutex<BufferPool>>,
    /// Messages already handled (a replacement process re-sends outputs its predecessor may have
    /// sent: a repeat is dropped).
    seen: HashSet<u64>,
    /// When resuming, this process's outputs already on the bus.
    published: HashSet<u64>,
    /// What the process tells the launcher when the run stops moving, and its last message on
    /// each key.
    watch: Watch,
    /// The nodes that were handed a message since the watch last looked at them.
    touched: Vec<bool>,
}

impl Handler<'_> {
    /// Starts the nodes and publishes their first outputs.
    fn start(&self, nodes: &mut [Box<dyn Node>]) -> Result<(), TransportError> {
        for node in nodes {
            let outs = node.start()?;
            publish_outputs(&self.publishers, node.as_mut(), outs, &self.published, &self.watch)?;
        }
        Ok(())
    }

    /// A batch of messages, as they arrived, none a repeat of another ([`batches`]): each node
    /// handles the ones it subscribes to in arrival order, and the process's nodes do so in
    /// parallel (a process hosting several subdomains uses every core, as the in-process bus
    /// does); a node publishes its replies as it makes them. A node's error stops every node
    /// before its next message, and the error of the earliest message is the one reported.
    fn handle(
        &mut self,
        batch: Vec<Received>,
        nodes: &mut [Box<dyn Node>],
        log: &mut dyn FnMut(&str),
    ) -> Result<(), TransportError> {
        let msgs = self.admit(batch, log);
        let outcomes = self.dispatch(&msgs, nodes);
        let refused = self.settle(msgs, outcomes)?;
        refused.iter().for_each(|why| log(why));
        Ok(())
    }

    /// [`Handler::handle`] of one message whose refusal by a node is returned, not logged: a
    /// message of the recorder's log can come before one it follows (see [`resume`]).
    fn handle_or_refused(
        &mut self,
        received: Received,
        nodes: &mut [Box<dyn Node>],
        log: &mut dyn FnMut(&str),
    ) -> Result<Option<String>, TransportError> {
        let msgs = self.admit(vec![received], log);
        let outcomes = self.dispatch(&msgs, nodes);
        Ok(self.settle(msgs, outcomes)?.into_iter().next())
    }

    /// A handled or ignored message's buffers hold the next ones.
    fn recycle(&self, msg: Message) {
        self.buffers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .recycle(msg.payload)
    }

    /// The messages of `batch` that decoded, arrived on their own key and were not handled
    /// before; the others are logged and dropped.
    fn admit(&self, batch: Vec<Received>, log: &mut dyn FnMut(&str)) -> Vec<(String, u64, Message)> {
        let mut msgs = Vec::with_capacity(batch.len());
        for received in batch {
            let Received { key, hash, message } = received;
            let msg = match message {
                Ok(m) => m,
                Err(e) => {
                    log(&format!("ignored a message on {key}: {e}"));
                    continue;
                }
            };
            if let Some(why) = msg.not_from_its_sender(&key) {
                log(&format!("ignored a message on {key}: {why}"));
                self.recycle(msg);
                continue;
            }
            if self.seen.contains(&hash) {
                log(&format!(
                    "ignored a repeat of the message on {key} (iteration {}, {:?}): already handled",
                    msg.envelope.iteration, msg.envelope.stage
                ));
                self.recycle(msg);
                continue;
            }
            msgs.push((key, hash, msg));
        }
        msgs
    }

    /// Each node handles the messages it subscribes to, in parallel with the others.
    fn dispatch(&mut self, msgs: &[(String, u64, Message)], nodes: &mut [Box<dyn Node>]) -> Vec<Outcome> {
        let deliveries = self.routes.deliveries(msgs.iter().map(|(key, _, _)| key.as_str()));
        self.touched.resize(deliveries.len(), false);
        for (t, d) in self.touched.iter_mut().zip(&deliveries) {
            *t |= !d.is_empty();
        }
        let (publishers, published, watch) = (&self.publishers, &self.published, &self.watch);
        let failed = AtomicBool::new(false);
        nodes
            .par_iter_mut()
            .zip(deliveries.par_iter())
            .map(|(node, mine)| {
                let mut refused = Vec::new();
                for &k in mine {
                    let (key, _, msg) = &msgs[k];
                    if failed.load(Ordering::Relaxed) {
                        break;
                    }
                    let mut handled = || -> Result<(), TransportError> {
                        let outs = node.handle(msg)?;
                        publish_outputs(publishers, node.as_mut(), outs, published, watch)
                    };
                    match handled() {
                        Ok(()) => {}
                        // The node refused this message and is unchanged: it is not the run's (a
                        // damaged or stray copy); the genuine one may still come.
                        Err(TransportError::Node(e)) if e.is_rejection() => {
                            refused.push((k, format!("ignored a message on {key}: {e}")))
                        }
                        Err(e) => {
                            failed.store(true, Ordering::Relaxed);
                            return Err((k, e));
                        }
                    }
                }
                Ok(refused)
            })
            .collect()
    }

    /// Returns the refusals in arrival order, or the earliest message's error if any, and counts
    /// the messages the nodes took as handled.
    fn settle(
        &mut self,
        msgs: Vec<(String, u64, Message)>,
        outcomes: Vec<Outcome>,
    ) -> Result<Vec<String>, TransportError> {
        let mut taken = vec![true; msgs.len()];
        let mut refusals = Vec::new();
        let mut first_error: Option<(usize, TransportError)> = None;
        for outcome in outcomes {
            match outcome {
                Ok(refused) => refusals.extend(refused),
                Err((k, e)) => {
                    if first_error.as_ref().is_none_or(|(first, _)| k < *first) {
                        first_error = Some((k, e));
                    }
                }
            }
        }
        // Logged in arrival order (a stable sort keeps node order within a message).
        refusals.sort_by_key(|(k, _)| *k);
        for (k, _) in &refusals {
            taken[*k] = false;
        }
        if let Some((_, e)) = first_error {
            return Err(e);
        }
        // Only a message the nodes took counts as handled: a refused copy does not hide the
        // genuine one.
        for ((_, hash, msg), taken) in msgs.into_iter().zip(taken) {
            if taken {
                self.seen.insert(hash);
            }
            self.recycle(msg);
        }
        Ok(refusals.into_iter().map(|(_, why)| why).collect())
    }
}

/// Publishes `outs`, a node's outputs, then its further outputs one at a time, each once the one
/// before is out ([`Node::next_output`]), giving each back to the node ([`Node::recycle`]).
fn publish_outputs(
    publishers: &Publishers<'_>,
    node: &mut dyn Node,
    outs: Vec<Message>,
    published: &HashSet<u64>,
    watch: &Watch,
) -> Result<(), TransportError> {
    for mut out in outs {
        publish_new(publishers, &mut out, published, watch)?;
        node.recycle(out);
    }
    while let Some(mut out) = node.next_output() {
        publish_new(publishers, &mut out, published, watch)?;
        node.recycle(out);
    }
    Ok(())
}

/// Publishes `msg` unless it is among the outputs already on the bus (`published`, the hashes
/// of a resumed process's outputs that the recorder holds). Lent field blocks are sent without a
/// copy ([`publish_lent`]). The bytes are kept in `watch` until the next message on the key (a
/// clone: neither a shared block nor an encoded buffer is copied), and the transport's test hook
/// may leave the message out ([`crate::DROP_HOOK`]).
fn publish_new(
    publishers: &Publishers<'_>,
    msg: &mut Message,
    published: &HashSet<u64>,
    watch: &Watch,
) -> Result<(), TransportError> {
    let (sender, iteration) = (msg.envelope.sender, msg.envelope.iteration);
    let hook = watch.hook(msg);
    let keep = |key: &str, bytes: &zenoh::bytes::ZBytes| {
        watch.sent(key, sender, iteration, (hook != Hook::Lose).then(|| bytes.clone()));
        hook == Hook::Publish
    };
    if published.is_empty() {
        return publishers.publish_lent_keeping(msg, keep);
    }
    let (topic, bytes) = (msg.topic(), encode(msg));
    let on_the_bus = published.contains(&message_hash(&topic, &bytes));
    let bytes = zenoh::bytes::ZBytes::from(bytes);
    // Kept even when the predecessor sent it: it can be lost on the way all the same.
    if !keep(&topic, &bytes) || on_the_bus {
        return Ok(());
    }
    publishers.put(&topic, bytes)
}

#[cfg(test)]
mod tests;
