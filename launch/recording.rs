//! Recording runs to MCAP (docs/recording.md). Both run modes feed one front-end,
//! [`glissade_recorder::RunRecorder`], which decides what is the run's and keeps the first failed
//! write; what differs is only how messages reach it:
//!
//! - In-process runs: the launcher records every message the in-process bus delivers, encoded as
//!   on the wire and on the key expression it would have over Zenoh.
//! - Multi-process runs: a recorder process (`glissade node recorder`) subscribes to
//!   `glissade/<run>/**` through the launcher's router and writes the file; its own process, so a
//!   recorder that dies leaves the solver running and a file readable up to its last chunk. The
//!   launcher counts the messages of the run it saw and, once every node process has exited,
//!   tells the recorder that count on `glissade/<run>/launcher/0/end`; the recorder finishes once
//!   it has received as many (or fails, naming how many are missing). On the launcher's `stop`
//!   (a failed run), SIGINT/SIGTERM, or the launcher's death (parent-death signal SIGTERM) the
//!   recorder finalises the file with what it has.
//!
//! A scene with `[recording] enabled = false` starts no recorder. The recording file is created
//! before anything is solved, so an unwritable folder fails the run at once, naming the path.

use crate::children::ChildOutput;
use crate::error::{failed, zenoh, Error, IoWhat, Result};
use glissade_messages::run_topics;
use glissade_recorder::{
    log_time_now, recording_file_name, RecorderError, RecorderOptions, RecordingStats, RunInfo, RunRecorder,
};
use glissade_scene::LoadedScene;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// How long the recorder may take, after the stop, to receive the messages still in flight.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(60);
/// Longest silence on the bus the recorder accepts before it gives up on the run.
const IDLE_TIMEOUT: Duration = Duration::from_secs(900);

/// `glissade <version> (<profile>)`.
pub fn software() -> String {
    format!(
        "glissade {} ({})",
        env!("CARGO_PKG_VERSION"),
        if cfg!(debug_assertions) { "debug" } else { "release" }
    )
}

/// What a run's recording will hold, said before it starts: how often full fields are recorded,
/// their size per iteration and the size at the scene's iteration cap (full fields of the
/// iterations recorded in full and the final interface solutions; the small messages, a few kB
/// per iteration, and `--interior` displacements come on top).
pub fn expected_size(scene: &LoadedScene) -> String {
    let model = &scene.model;
    let r = &scene.recording;
    let full = glissade_scene::full_field_bytes_per_iteration(model) as f64;
    let cap = model.solver.max_iterations;
    let recorded_in_full = cap.div_ceil(r.full_fields_every.max(1));
    let at_cap = recorded_in_full as f64 * full + glissade_scene::final_field_bytes(model) as f64;
    let every = match r.full_fields_every {
        1 => "at every iteration".to_string(),
        k => format!(
            "every {k}th iteration{}",
            if r.full_fields_auto {
                " (--record full: all)"
            } else {
                ""
            }
        ),
    };
    let topics = if r.topics.iter().any(|t| t == "**") {
        String::new()
    } else {
        format!(", only {:?}", r.topics)
    };
    let size = |bytes: f64, mb_digits: usize| {
        if bytes < 1e6 {
            format!("{:.0} kB", bytes * 1e-3)
        } else {
            format!("{:.*} MB", mb_digits, bytes * 1e-6)
        }
    };
    format!(
        "full fields {every}{topics}, {} each; at most about {} at the iteration cap ({cap})",
        size(full, 1),
        size(at_cap, 0)
    )
}

/// Where a run's recording goes, or None when the scene switches recording off.
pub fn recording_path(scene: &LoadedScene, run_id: &str, out: &Path) -> Option<PathBuf> {
    scene
        .recording
        .enabled
        .then(|| out.join(recording_file_name(&scene.model.name, run_id)))
}

/// What the recording of run `run_id` of `scene` is of ([`RunInfo`]) and what it keeps
/// ([`RecorderOptions`]: the scene's `[recording]` topics and thinning).
pub fn recorder_settings(scene: &LoadedScene, run_id: &str) -> (RunInfo, RecorderOptions) {
    let info = RunInfo {
        run_id: run_id.to_string(),
        scene_name: scene.model.name.clone(),
        scene_fingerprint: scene.fingerprint,
        scene_text: scene.text.clone(),
        scene_overrides: scene.overrides,
        software: software(),
    };
    let options = RecorderOptions {
        topics: scene.recording.topics.clone(),
        full_fields_every: scene.recording.full_fields_every.min(u32::MAX as usize) as u32,
        ..RecorderOptions::default()
    };
    (info, options)
}

/// Creates the recorder of a run, in either run mode (the file exists and holds the scene when
/// this returns).
pub fn create_recorder(scene: &LoadedScene, run_id: &str, path: &Path) -> Result<RunRecorder, RecorderError> {
    let (info, options) = recorder_settings(scene, run_id);
    RunRecorder::create(path, &info, &options)
}

/// What a recording holds once finished.
#[derive(Debug, Clone)]
pub struct RecordingOutcome {
    pub path: PathBuf,
    pub stats: Option<RecordingStats>,
}

/// The recorder process of a multi-process run, seen from the launcher. Killed when dropped.
pub struct RecorderProcess {
    child: Child,
    /// The recorder's liveliness token is up (it subscribed to the run).
    ready: Arc<AtomicBool>,
    _watch: zenoh::pubsub::Subscriber<()>,
    path: PathBuf,
    output: ChildOutput,
}

impl Drop for RecorderProcess {
    /// SIGTERM (the recorder finalises its file), then SIGKILL if it is still there 5 s later.
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            // SAFETY: plain kill(2) on our own child's pid.
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
            }
            let deadline = Instant::now() + Duration::from_secs(5);
            while matches!(self.child.try_wait(), Ok(None)) && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Starts `exe node recorder` for run `run_id`, connected to `endpoint` (the bus of `session`)
/// with the `--tls-*` arguments `tls`, writing `path`.
pub fn spawn_recorder_process(
    exe: &Path,
    session: &zenoh::Session,
    run_id: &str,
    endpoint: &str,
    tls: &[String],
    credentials: Option<&glissade_zenoh::Credentials>,
    path: &Path,
) -> Result<RecorderProcess> {
    let ready = Arc::new(AtomicBool::new(false));
    let flag = ready.clone();
    let watch = session
        .liveliness()
        .declare_subscriber(glissade_messages::topic::recorder_alive(run_id))
        .history(true)
        .callback(move |s| flag.store(s.kind() == zenoh::sample::SampleKind::Put, Ordering::SeqCst))
        .wait()
        .map_err(|e| zenoh("watch the recorder's liveliness", e))?;
    let mut cmd = Command::new(exe);
    cmd.args(["node", "recorder", "--run", run_id, "--connect", endpoint])
        .args(tls)
        .arg("--file")
        .arg(path);
    // The recorder finalises its file if the launcher dies (SIGTERM, not SIGKILL).
    let (child, output) = crate::children::spawn_child(cmd, "recorder:0", libc::SIGTERM, credentials)
        .what(|| format!("cannot start the recorder process ({})", exe.display()))?;
    Ok(RecorderProcess {
        child,
        ready,
        _watch: watch,
        path: path.to_path_buf(),
        output,
    })
}

impl RecorderProcess {
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The recorder has subscribed to the run (its liveliness token is up).
    pub fn is_ready(&self) -> bool {
        self.ready.load(Ordering::SeqCst)
    }

    fn failure(&mut self) -> Option<String> {
        match self.child.try_wait() {
            Ok(Some(status)) if !status.success() => {
                self.output.settle();
                let lines = self.output.lines().join("\n    ");
                Some(format!(
                    "the recorder process failed ({status}); its last lines:\n    {lines}"
                ))
            }
            _ => None,
        }
    }

    /// Fails when the recorder process has exited with an error (e.g. before the run starts,
    /// when it cannot create the file).
    pub fn check(&mut self) -> Result<()> {
        match self.failure() {
            Some(f) => Err(Error::Failed(f)),
            None => Ok(()),
        }
    }

    /// Tells the recorder the run is over (`seen` messages on the run's key expressions) and waits
    /// for it to finalise the file. Returns what went wrong with the recording, if anything
    /// (the run's results do not depend on it).
    pub fn finish(mut self, session: &zenoh::Session, run_id: &str, seen: u64) -> Option<String> {
        if let Some(f) = self.failure() {
            return Some(format!("{f}; {} holds the chunks written before", self.path.display()));
        }
        if let Err(e) = session
            .put(glissade_messages::topic::end(run_id), seen.to_le_bytes().to_vec())
            .congestion_control(CongestionControl::Block)
            .wait()
        {
            return Some(format!("cannot tell the recorder to stop: {e}"));
        }
        let deadline = Instant::now() + DRAIN_TIMEOUT + Duration::from_secs(30);
        loop {
            match self.child.try_wait() {
                Ok(Some(status)) if status.success() => return None,
                Ok(Some(_)) => {
                    return self
                        .failure()
                        .map(|f| format!("{f}; {} holds the chunks written before", self.path.display()))
                }
                Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
                Ok(None) => return Some("the recorder did not finish within its drain timeout".into()),
                Err(e) => return Some(format!("cannot wait for the recorder: {e}")),
            }
        }
    }
}

static SIGNALLED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    SIGNALLED.store(true, Ordering::SeqCst);
}

/// What the recorder process hears: a message of the run (key, bytes, log time) or a query for
/// its log.
enum Heard {
    /// The payload as Zenoh holds it: in the sender's shared memory, not copied, where it came
    /// that way (most messages are not written: full fields are thinned out).
    Put(String, zenoh::bytes::ZBytes, u64),
    LogQuery(zenoh::query::Query),
}

/// The recorded messages of `path` whose key matches one of `patterns` (newline-separated), in
/// recorded order, encoded with [`glissade_zenoh::encode_log`].
fn log_of(path: &Path, patterns: &str) -> Result<Vec<u8>, String> {
    let patterns: Vec<&str> = patterns.lines().filter(|p| !p.is_empty()).collect();
    let recording = glissade_recorder::Recording::open(path).map_err(|e| e.to_string())?;
    let messages: Vec<(String, Vec<u8>)> = recording
        .messages()
        .filter(|m| patterns.iter().any(|p| glissade_messages::key_matches(p, m.topic)))
        .map(|m| (m.topic.to_string(), m.data.into_owned()))
        .collect();
    crate::console::say(&format!(
        "log query: {} message(s) matching {} pattern(s) served",
        messages.len(),
        patterns.len()
    ));
    Ok(glissade_zenoh::encode_log(&messages))
}

/// What the recorder process declares on the bus: its subscription to the run's keys and its log
/// queryable (both feeding the returned channel), and its liveliness token; dropping it undeclares
/// them.
type Attending = (
    zenoh::pubsub::Subscriber<()>,
    zenoh::query::Queryable<()>,
    zenoh::liveliness::LivelinessToken,
);

/// Subscribes to the run's keys, answers the run's log queries and declares the recorder's
/// liveliness token; what is heard comes through the returned channel.
fn attend(session: &zenoh::Session, run_id: &str) -> Result<(mpsc::Receiver<Heard>, Attending)> {
    let (tx, rx) = mpsc::channel::<Heard>();
    let log_tx = tx.clone();
    let sub = session
        .declare_subscriber(run_topics(run_id))
        .callback(move |s| {
            let _ = tx.send(Heard::Put(
                s.key_expr().as_str().to_string(),
                s.payload().clone(),
                log_time_now(),
            ));
        })
        .wait()
        .map_err(|e| zenoh("subscribe to the run", e))?;
    // A replacement node process asks for the messages it needs to resume; the query goes
    // through the same channel, so every message heard before it is in the file when it is
    // answered.
    let log = session
        .declare_queryable(glissade_messages::topic::log(run_id))
        .callback(move |q| {
            let _ = log_tx.send(Heard::LogQuery(q));
        })
        .wait()
        .map_err(|e| zenoh("declare the log queryable", e))?;
    let token = session
        .liveliness()
        .declare_token(glissade_messages::topic::recorder_alive(run_id))
        .wait()
        .map_err(|e| zenoh("liveliness token", e))?;
    Ok((rx, (sub, log, token)))
}

/// Answers a replacement node process's query for the messages it needs to resume, from the
/// recording so far (flushed first), or says why this recording cannot.
fn answer_log_query(q: &zenoh::query::Query, incomplete: Option<&str>, recorder: &mut RunRecorder, path: &Path) {
    let answer = match incomplete {
        Some(why) => Err(format!("this recording cannot resume a node: {why}")),
        None => recorder.flush().map_err(|e| e.to_string()).and_then(|()| {
            log_of(
                path,
                &String::from_utf8_lossy(&q.payload().map(|p| p.to_bytes()).unwrap_or_default()),
            )
        }),
    };
    let sent = match answer {
        Ok(bytes) => q.reply(q.key_expr().clone(), bytes).wait(),
        Err(why) => {
            crate::console::say(&format!("log query refused: {why}"));
            q.reply_err(why.into_bytes()).wait()
        }
    };
    if let Err(e) = sent {
        crate::console::say(&format!("cannot answer a log query: {e}"));
    }
}

/// Finalises the recording and says what it holds (and what it refused).
fn finish_recording(recorder: RunRecorder, path: &Path) -> Result<()> {
    let finished = recorder.finish()?;
    if let Some(first) = &finished.first_refused {
        crate::console::warn(&format!(
            "{} message(s) on the run's keys were not the run's and were not recorded (the first {first})",
            finished.refused
        ));
    }
    crate::console::say(&format!(
        "{}recorded {} messages on {} channels, {} bytes: {}",
        glissade_zenoh::NOTE,
        finished.stats.messages,
        finished.stats.channels,
        finished.stats.file_bytes,
        path.display()
    ));
    Ok(())
}

/// The `glissade node recorder` process: fetches the scene, creates the file, subscribes to the
/// run, declares its liveliness token, and records until the launcher's stop (or SIGINT/SIGTERM,
/// which finalise the file too).
pub fn run_recorder_process(run_id: &str, bus: &crate::bus::Joining, shared_memory: bool, path: &Path) -> Result<()> {
    // SAFETY: the handler only stores to an atomic.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
    let session = bus.open(shared_memory)?;
    // With the overrides: `--record full` and the iteration cap are the run's, not the file's.
    let (scene, _) = crate::bus::fetch_run_scene(&session, run_id)?;
    let mut recorder = create_recorder(&scene, run_id, path)?;
    crate::console::say(&format!(
        "{}recording to {} (pid {})",
        glissade_zenoh::NOTE,
        path.display(),
        std::process::id()
    ));
    let (rx, _attending) = attend(&session, run_id)?;
    let incomplete = scene.recording.incomplete();
    let (end, stop) = (
        glissade_messages::topic::end(run_id),
        glissade_messages::topic::stop(run_id),
    );
    let mut target: Option<(u64, Instant)> = None;
    let mut last = Instant::now();
    loop {
        if SIGNALLED.load(Ordering::SeqCst) {
            let finished = recorder.finish()?;
            crate::console::say(&format!(
                "interrupted: recording finalised with {} messages: {}",
                finished.stats.messages,
                path.display()
            ));
            return Ok(());
        }
        if recorder.failure().is_some() {
            // `finish` returns the first failed write; the file is readable up to its last chunk.
            return recorder.finish().map(drop).map_err(Error::from);
        }
        if let Some((n, since)) = target {
            if recorder.seen() >= n {
                break;
            }
            if since.elapsed() > DRAIN_TIMEOUT {
                let seen = recorder.seen();
                recorder.finish()?;
                failed!(
                    "received {seen} of the {n} messages the launcher saw within {DRAIN_TIMEOUT:?} after the stop; {} is finalised without the rest",
                    path.display()
                );
            }
        }
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Heard::LogQuery(q)) => answer_log_query(&q, incomplete.as_deref(), &mut recorder, path),
            Ok(Heard::Put(key, payload, t)) => {
                last = Instant::now();
                // Borrowed where the payload is one slice (shared memory, or a message that was
                // not fragmented), copied otherwise.
                let bytes = payload.to_bytes();
                if key == end {
                    let n = <[u8; 8]>::try_from(bytes.as_ref())
                        .map(u64::from_le_bytes)
                        .map_err(|_| Error::Invalid(format!("malformed end message ({} bytes)", bytes.len())))?;
                    target = Some((n, Instant::now()));
                } else if key == stop {
                    let finished = recorder.finish()?;
                    crate::console::say(&format!(
                        "the run was stopped ({}): recording finalised with {} messages: {}",
                        String::from_utf8_lossy(&bytes),
                        finished.stats.messages,
                        path.display()
                    ));
                    return Ok(());
                } else {
                    recorder.heard(&key, &bytes, t);
                }
            }
            Err(mpsc::RecvTimeoutError::Timeout) if last.elapsed() > IDLE_TIMEOUT => {
                recorder.finish()?;
                return Err(Error::Silent {
                    idle: IDLE_TIMEOUT,
                    what: format!("{} is finalised", path.display()),
                });
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => return Err(Error::Failed("the subscriber closed".into())),
        }
    }
    finish_recording(recorder, path)?;
    let _ = session.close().wait();
    Ok(())
}
