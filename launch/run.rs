//! The one way to run a scene: [`Run`] says what the run is (scene, options, recording, what the
//! caller watches and measures) and runs it in this process ([`Run::in_process`]) or as node
//! processes on a Zenoh bus ([`Run::processes`]); [`Outcome`] is what it gives. Both modes give the
//! same iterations and bit-identical fields.
//!
//! The steps of a run, in order (deal.II's setup/assemble/solve/output): the plan and the
//! operators are set up (`glissade_deploy`), the nodes are built and iterated on a bus
//! ([`crate::runner`] in-process, [`crate::distributed`] as processes), and the caller writes the
//! outputs from the [`Outcome`] ([`crate::output`]).

use crate::distributed::{Network, Traffic};
use crate::recording::{create_recorder, RecordingOutcome};
use crate::runner::{run_logged, IterationRecord, Prepared, RunError, RunOptions, RunResult};
use glissade_bus::HandleTime;
use glissade_messages::Message;
use glissade_scene::LoadedScene;
use glissade_subdomain::LinearStageRecord;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A run id nobody can guess: 128 bits from the operating system's random source, in hex.
pub fn random_run_id() -> crate::Result<String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes)
        .map_err(|e| crate::Error::Failed(format!("cannot draw a random run id from the operating system: {e}")))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// What watches every message of an in-process run, returning the wall time it spent.
type Observer<'a> = Box<dyn FnMut(&Message) -> Duration + 'a>;
/// What sees each iteration's decision.
type Watcher<'a> = Box<dyn FnMut(&IterationRecord) + 'a>;
/// What sees each iteration's decision and says whether the run goes on.
type Stopper<'a> = Box<dyn FnMut(&IterationRecord) -> bool + 'a>;

/// A run of a scene, set up step by step, then run in one of the two modes.
///
/// ```no_run
/// # fn f(scene: &glissade_scene::LoadedScene) -> Result<(), glissade::runner::RunError> {
/// use glissade::run::Run;
/// use glissade::runner::RunOptions;
/// let opts = RunOptions::new("r1");
/// let outcome = Run::new(scene, &opts)
///     .on_iteration(|r| println!("iteration {}: η = {:e}", r.iteration, r.decision.eta))
///     .in_process()?;
/// println!("{:?}", outcome.result.verdict);
/// # Ok(()) }
/// ```
pub struct Run<'a> {
    scene: &'a LoadedScene,
    opts: RunOptions,
    recording: Option<PathBuf>,
    on_iteration: Option<Watcher<'a>>,
    /// The caller may stop the run early ([`Run::until`]).
    until: Option<Stopper<'a>>,
    observe: Option<Observer<'a>>,
    linear_stages: bool,
    handle_times: bool,
    prepared: Option<Prepared>,
}

/// What a run gave.
#[derive(Debug)]
pub struct Outcome {
    pub result: RunResult,
    /// Every subdomain's linear-stage records (flops, PGD basis per iteration from its
    /// `linear_stage_stats` messages, and in-process the time the bus spent on its stage; 0 as
    /// processes), sorted by (iteration, subdomain), when asked for with [`Run::linear_stages`].
    pub linear_stages: Vec<LinearStageRecord>,
    /// Every node's handling time summed per (role, message field), when asked for with
    /// [`Run::handle_times`] (what `glissade bench` splits an iteration by).
    pub handle_times: Vec<HandleTime>,
    /// The recording, when the run was recorded ([`Run::recorded`]).
    pub recording: Option<RecordingOutcome>,
    /// What crossed the bus, by message kind (a run as processes).
    pub traffic: Option<Traffic>,
}

impl<'a> Run<'a> {
    /// A run of `scene` with `opts`, unrecorded, watched by no one.
    pub fn new(scene: &'a LoadedScene, opts: &RunOptions) -> Self {
        Self {
            scene,
            opts: opts.clone(),
            recording: None,
            on_iteration: None,
            until: None,
            observe: None,
            linear_stages: false,
            handle_times: false,
            prepared: None,
        }
    }

    /// Runs with operators already built and/or from a given start ([`Prepared`]): what a study
    /// does for its variants. In-process only.
    pub fn prepared(mut self, prepared: Prepared) -> Self {
        self.prepared = Some(prepared);
        self
    }

    /// Records every message of the run to `path` (MCAP), when given. In-process, the launcher
    /// records what the bus delivers and the recorder's time is part of the run's wall time; as
    /// processes, a recorder process does ([`crate::recording`]).
    pub fn recorded(mut self, path: Option<&Path>) -> Self {
        self.recording = path.map(Path::to_path_buf);
        self
    }

    /// `f` sees each iteration's decision as it is made (a second call replaces the first `f`).
    pub fn on_iteration(mut self, f: impl FnMut(&IterationRecord) + 'a) -> Self {
        self.on_iteration = Some(Box::new(f));
        self
    }

    /// `keep_going` sees each iteration's decision (after [`Run::on_iteration`]'s `f`); the run
    /// stops after the first iteration for which it returns false (its verdict is then that
    /// iteration's, usually `Continue`). In-process only.
    pub fn until(mut self, keep_going: impl FnMut(&IterationRecord) -> bool + 'a) -> Self {
        self.until = Some(Box::new(keep_going));
        self
    }

    /// `observe` sees every message of the run (in-process: in publication order; as processes:
    /// every message the launcher receives, in arrival order, e.g. for a live view). In-process,
    /// the wall time it returns is left out of the iterations' elapsed times, so that a report may
    /// measure errors without charging the solver for it; as processes it is not used.
    pub fn observe(mut self, observe: impl FnMut(&Message) -> Duration + 'a) -> Self {
        self.observe = Some(Box::new(observe));
        self
    }

    /// Keeps every subdomain's linear-stage records ([`Outcome::linear_stages`]): timed in-process,
    /// the counters alone as processes.
    pub fn linear_stages(mut self) -> Self {
        self.linear_stages = true;
        self
    }

    /// Times every node's handling per (role, message field) ([`Outcome::handle_times`]).
    /// In-process only.
    pub fn handle_times(mut self) -> Self {
        self.handle_times = true;
        self
    }

    /// Runs every node in this process, on the in-process bus (subdomain work within a round in
    /// parallel on all cores).
    pub fn in_process(self) -> Result<Outcome, RunError> {
        let Run {
            scene,
            opts,
            recording,
            on_iteration: mut watch,
            mut until,
            observe,
            linear_stages,
            handle_times,
            prepared,
        } = self;
        let prepared = prepared.unwrap_or_default();
        let mut on_iteration = |r: &IterationRecord| {
            if let Some(f) = watch.as_mut() {
                f(r);
            }
            until.as_mut().is_none_or(|u| u(r))
        };
        let mut observe: Observer = observe.unwrap_or_else(|| Box::new(|_| Duration::ZERO));
        let mut records = Vec::new();
        let log = linear_stages.then_some(&mut records);
        let mut times = Vec::new();
        let timing = handle_times.then_some(&mut times);
        let (result, recording) = match &recording {
            None => (
                run_logged(scene, &opts, on_iteration, observe, log, timing, prepared)?,
                None,
            ),
            Some(path) => {
                let recorder = create_recorder(scene, &opts.run_id, path).map_err(RunError::Recording)?;
                // The first failed write (e.g. a full disk) stops the run at the end of that
                // iteration.
                let recorder = std::cell::RefCell::new(recorder);
                let keep_going = |r: &IterationRecord| on_iteration(r) && recorder.borrow().failure().is_none();
                let result = run_logged(
                    scene,
                    &opts,
                    keep_going,
                    |m| {
                        let spent = observe(m);
                        recorder.borrow_mut().delivered(m);
                        spent
                    },
                    log,
                    timing,
                    prepared,
                )?;
                let recorder = recorder.into_inner();
                let stopped = recorder.failure().is_some();
                let stats = match recorder.finish() {
                    Ok(finished) => finished.stats,
                    // The write that stopped the run.
                    Err(cause) if stopped => {
                        return Err(RunError::RecordingStopped {
                            iterations: result.iterations.len(),
                            cause,
                        })
                    }
                    Err(e) => return Err(RunError::Recording(e)),
                };
                let outcome = RecordingOutcome {
                    path: path.clone(),
                    stats: Some(stats),
                };
                (result, Some(outcome))
            }
        };
        Ok(Outcome {
            result,
            linear_stages: records,
            handle_times: times,
            recording,
            traffic: None,
        })
    }

    /// Runs the scene as node processes of `exe` (`glissade node …`) on the bus `net` describes
    /// (by default a router hosted by this process on a free loopback port); nodes listed in
    /// `net.remote` are left to be started by hand. A recorded run starts a recorder process.
    pub fn processes(self, exe: &Path, net: &Network) -> crate::Result<Outcome> {
        if self.scene.model.interfaces.is_empty() {
            // Nothing to distribute: the direct solve, in this process (recorded if asked).
            return self.in_process().map_err(crate::Error::from);
        }
        let Run {
            scene,
            opts,
            recording,
            mut on_iteration,
            until,
            observe,
            linear_stages,
            handle_times,
            prepared,
        } = self;
        for (asked, what) in [
            (until.is_some(), "stopping a run early (until)"),
            (handle_times, "handling times"),
            (prepared.is_some(), "operators built before or a given start (prepared)"),
        ] {
            if asked {
                return Err(RunError::InProcessOnly(what).into());
            }
        }
        let observe = observe.map(|mut o| {
            move |m: &Message| {
                o(m);
            }
        });
        let (result, traffic, records) = crate::distributed::run_processes(
            scene,
            &opts,
            exe,
            net,
            recording.as_deref(),
            |r| {
                if let Some(f) = on_iteration.as_mut() {
                    f(r);
                }
            },
            observe,
        )?;
        Ok(Outcome {
            result,
            linear_stages: if linear_stages { records } else { Vec::new() },
            handle_times: Vec::new(),
            recording: recording.map(|path| RecordingOutcome { path, stats: None }),
            traffic: Some(traffic),
        })
    }
}
