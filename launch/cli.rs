//! The command line: every subcommand and option of `glissade` (clap). `glissade <command>
//! --help` prints these docs.

use clap::{Parser, Subcommand};
use glissade::children::NodeName;
use std::path::PathBuf;

/// Quasi-static 2D frictional contact between many elastic parts, by the mixed multiscale LATIN
/// domain decomposition method.
#[derive(Parser)]
#[command(name = "glissade", version, about, long_about = None)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand)]
pub(crate) enum Command {
    /// Solve a scene with the LATIN method and write its summary and interface fields.
    Run(RunArgs),
    /// Validate a scene and print what it contains.
    Check {
        /// Scene file (TOML).
        scene: PathBuf,
    },
    /// Solve a scene monolithically with every interface glued (linear elastic) and print a summary.
    Monolithic {
        /// Scene file (TOML).
        scene: PathBuf,
    },
    /// Solve a scene with the monolithic incremental Newton contact solver (the reference) and
    /// write its summary and interface fields.
    Reference {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Folder for the outputs.
        #[arg(long, default_value = "recordings")]
        out: PathBuf,
        /// Newton iterations of the reference per attempt of a time step (the non-monotone attempt
        /// gets 20 times as many).
        #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..))]
        newton_iterations: u32,
    },
    /// Run the reference and the LATIN solver, and write the error-against-run-time report
    /// (`<scene>-report.json` and `<scene>-report.svg`).
    Report(ReportArgs),
    /// Run a scene in-process and split an iteration's time by stage, against the machine's
    /// measured dense-product rate and memory bandwidth (`<scene>-bench.json`; use a release build).
    Bench {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Folder for the outputs.
        #[arg(long, default_value = "recordings")]
        out: PathBuf,
        /// LATIN iteration cap (overrides the scene's).
        #[arg(long)]
        max_iterations: Option<usize>,
        /// Then run the scene this many rounds in-process, as processes over TCP and as processes
        /// through shared memory (alternating, no recording) and report the ratios.
        #[arg(long, value_name = "ROUNDS", value_parser = clap::value_parser!(u32).range(1..))]
        processes: Option<u32>,
        /// Vector extension of the element-wise kernels (default: the widest this CPU has; a
        /// wider one than the CPU has falls back to the widest it has, and the report says which
        /// ran). Results are the same bit for bit at every level. In-process only: node
        /// processes pick their own, so it does not go with --processes.
        #[arg(long, value_enum, conflicts_with = "processes")]
        kernels: Option<KernelsArg>,
    },
    /// Load a recording into Rerun (an .rrd file by default, or a live viewer), or re-execute
    /// nodes from their recorded inputs and check their outputs bit for bit (`--node`).
    Replay(ReplayArgs),
    /// Write a finished run's results from its recording in formats other tools read: a ParaView
    /// time series (`--vtu`), a CSV of the interface fields (`--csv`), and a copy of the recording
    /// any MCAP tool decodes (`--foreign`, protobuf).
    Export {
        /// Recording (MCAP) of a run.
        recording: PathBuf,
        /// Folder for a ParaView time series: `<scene>-<run>.pvd` and `<scene>-<run>-vtu/`.
        #[arg(long, value_name = "DIR")]
        vtu: Option<PathBuf>,
        /// With --vtu: only every k-th time point (and the last).
        #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        vtu_every: u32,
        /// Folder for `<scene>-<run>.interfaces.csv`: one row per interface node pair and time point.
        #[arg(long, value_name = "DIR")]
        csv: Option<PathBuf>,
        /// Folder for `<recording's file name>`: the recording with every message as protobuf
        /// (schemas as FileDescriptorSets, `glissade.proto` attached), for Foxglove, `mcap cat
        /// --json` or Python's mcap-protobuf-support (docs/recording.md).
        #[arg(long, value_name = "DIR")]
        foreign: Option<PathBuf>,
    },
    /// Start one node process by hand (on another machine): it connects to the launcher's Zenoh
    /// endpoint and receives the scene over the bus.
    Node(NodeArgs),
    /// Run a scene as processes many times, several at once, beside busy loops that load the
    /// machine's cores, and count how the runs end against the scene's in-process run (same
    /// numbers, stalls recovered or ended, failures, hangs); writes `<out>/soak.json`
    /// (docs/operations.md#soak).
    Soak {
        /// Scene file (TOML).
        scene: PathBuf,
        /// Folder for the runs' outputs (those that converge to the same numbers are deleted)
        /// and `soak.json`.
        #[arg(long, default_value = "recordings/soak")]
        out: PathBuf,
        /// Runs in all.
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..))]
        runs: u32,
        /// Runs at once.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
        parallel: u32,
        /// Busy loops (threads spinning on a core) beside the runs.
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=256))]
        busy: u32,
        /// A run still going after this many seconds is counted as hung and stopped.
        #[arg(long, default_value_t = 120, value_parser = clap::value_parser!(u64).range(1..))]
        timeout: u64,
        /// Record nothing (the runs record as the scene says otherwise).
        #[arg(long)]
        no_record: bool,
    },
    /// Write a generated scene file: `laminate`, plies of square subdomains in frictional contact
    /// (docs/scenes.md#generated-scenes), e.g. the 1000-subdomain laminate.
    Generate(GenerateArgs),
    /// Run the stability matrix of stiff and extreme cases and write the table
    /// (`stability.md`, `stability.json`).
    Stability {
        /// Only the reduced, fast subset of the test suite.
        #[arg(long)]
        quick: bool,
        /// Only the named case (repeatable; `glissade stability --list` names them).
        #[arg(long = "case", value_name = "NAME")]
        only: Vec<String>,
        /// List the cases and what each varies, without running them.
        #[arg(long)]
        list: bool,
        /// Instead of the matrix, check the stop on accuracy on every converging case: where the
        /// default solver's estimate first reaches 1e-2, 1e-3 and 1e-4, and the true error there
        /// (`stability-accuracy.md`, `stability-accuracy.json`).
        #[arg(long)]
        accuracy: bool,
        /// Folder for the outputs.
        #[arg(long, default_value = "recordings")]
        out: PathBuf,
    },
    /// Solve many variants of one scene (docs/studies.md): the friction or gap of an interface
    /// rule, a factor on a boundary rule's values, E or ν of a material, over lists, ranges, a
    /// grid or a seeded sample; each variant warm-started from the nearest solved one, with the
    /// operators it leaves valid reused. Writes `<study>.csv`, `<study>.json` and SVG plots of each
    /// quantity against each parameter; exit code 3 when a variant did not converge.
    Sweep {
        /// Study file (TOML); with `--vary`, the scene file itself.
        study: PathBuf,
        /// A parameter and its values, `name=from:to:count` or `name=v1,v2,…` (repeat for a
        /// grid), e.g. `--vary friction=0.1:0.3:5 --vary boundary[1].scale=0.5,1,1.5`.
        #[arg(long)]
        vary: Vec<String>,
        /// Run every variant from ŝ = 0 with operators built anew, as separate runs would (to
        /// measure what the warm starts gain); outputs are named `<study>-cold.*`.
        #[arg(long)]
        cold: bool,
        /// Every variant's accuracy (overrides the study's and the scene's `solver.accuracy`).
        #[arg(long, allow_negative_numbers = true)]
        accuracy: Option<f64>,
        /// Record every variant (`<study>-v<k>.mcap`).
        #[arg(long)]
        record: bool,
        /// Folder for the outputs.
        #[arg(long, default_value = "studies")]
        out: PathBuf,
    },
    /// Submit a run to Slurm (docs/operations.md, "On a cluster"): writes a batch script that
    /// runs `glissade run <scene> --slurm` (its node processes as job steps of the job) into the
    /// output folder, submits it with sbatch and prints the job id and where the outputs will be.
    Submit(SubmitArgs),
    /// The load at which a joint slips (docs/studies.md, "Slip onset"): the smallest factor on
    /// a boundary rule's values at which a contact interface first slips at a point, and the one
    /// at which one slips over its whole length (beyond it a part held by friction has no
    /// equilibrium), each bracketed by warm-started solves; writes `<scene>-onset.json`.
    Onset {
        /// Scene file (TOML).
        scene: PathBuf,
        /// The boundary rule whose values are scaled (its index in the file, from 0).
        #[arg(long)]
        rule: usize,
        /// A contact interface to watch (as `glissade check` numbers them; repeat for several);
        /// every contact interface by default.
        #[arg(long)]
        interface: Vec<usize>,
        /// Relative width of each bracket at the end.
        #[arg(long, default_value_t = 1e-2)]
        bracket: f64,
        /// The first factor tried (the brackets grow from it by ×2 or ÷2).
        #[arg(long, default_value_t = 1.0)]
        start: f64,
        /// Every trial's accuracy (overrides the scene's `solver.accuracy`).
        #[arg(long, allow_negative_numbers = true)]
        accuracy: Option<f64>,
        /// Folder for the outputs.
        #[arg(long, default_value = "studies")]
        out: PathBuf,
    },
    /// Check the stop on accuracy on generated scenes no one tuned for (docs/accuracy.md, "The
    /// validation set"): per seed, a laminate or a Gmsh geometry, its reference, and one run past
    /// the smallest accuracy; where each accuracy (1e-2, 1e-3, 1e-4) stops and the true error
    /// there (`validation-<part>.md`, `validation-<part>.json`, the scenes in `scenes/`).
    Validate {
        /// Which part of the set: `held-out` (odd seeds: report on these), `calibration` (even
        /// seeds: tune only on these) or `all`.
        #[arg(long, value_enum, default_value = "held-out")]
        part: PartArg,
        /// Seeds, as `first..end` (end excluded); each part takes its own seeds of the range.
        #[arg(long, default_value = "0..200", value_parser = parse_seeds)]
        seeds: std::ops::Range<u64>,
        /// Folder for the outputs.
        #[arg(long, default_value = "validation")]
        out: PathBuf,
    },
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum PartArg {
    HeldOut,
    Calibration,
    All,
}

/// `first..end` with first < end.
fn parse_seeds(text: &str) -> Result<std::ops::Range<u64>, String> {
    let (a, b) = text
        .split_once("..")
        .ok_or_else(|| format!("{text:?}: expected first..end, e.g. 0..200"))?;
    let num = |v: &str| {
        v.trim()
            .parse::<u64>()
            .map_err(|e| format!("{text:?}: {v:?} is not a seed ({e})"))
    };
    let (a, b) = (num(a)?, num(b)?);
    if a >= b {
        return Err(format!("{text:?}: the range is empty (end is excluded)"));
    }
    Ok(a..b)
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum RecordArg {
    Full,
    Off,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum KernelsArg {
    Baseline,
    Avx2,
    Avx512,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum RoleArg {
    Subdomain,
    Interface,
    Coarse,
    /// Records every message of the run to the MCAP file `--file`.
    Recorder,
}

/// `glissade report`'s arguments.
#[derive(clap::Args)]
pub(crate) struct ReportArgs {
    /// Scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Folder for the outputs.
    #[arg(long, default_value = "recordings")]
    pub(crate) out: PathBuf,
    /// LATIN stops once its estimated contact-traction error is at most this (overrides the
    /// scene's `solver.accuracy`).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) accuracy: Option<f64>,
    /// LATIN also waits for η ≤ this (overrides the scene's `solver.tolerance`).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) tolerance: Option<f64>,
    /// LATIN iteration cap (overrides the scene's).
    #[arg(long)]
    pub(crate) max_iterations: Option<usize>,
    /// Compare solver variants against one reference solve: linear stages, each optionally
    /// with `+anderson` or `+plain` and with `+start<c>` (a time-coarse start on every c-th
    /// time point) or `+zero` (from ŝ = 0), e.g.
    /// `condensed+plain,condensed+anderson,condensed+anderson+start10,pgd+anderson` or
    /// `condensed,sparse,pgd` (writes `<scene>-<variant>-report.json` / `.svg` each, and
    /// prints a comparison table). The PGD stage also takes the `[solver.pgd]` settings
    /// `+xi1=<ξ₀,₁>`, `+xi2=<ξ₀,₂>`, `+criterion=<increment|accumulated|increment-svd|forcing|forcing-svd>`
    /// and `+max_new_modes=<m>`, e.g. `pgd+anderson+criterion=forcing+xi1=0.3`.
    #[arg(long, alias = "linear-stages", value_delimiter = ',')]
    pub(crate) variants: Vec<String>,
    /// Subdomains (numbered from 1) whose PGD basis sizes `<scene>-iterations.svg` plots
    /// against the iterations, under η and the traction error of every variant (the paper's
    /// Figure 4).
    #[arg(long, value_delimiter = ',', default_values_t = [7, 12], value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) basis_subdomains: Vec<u32>,
    /// Stop each run at the first iteration whose contact-traction error against the
    /// reference is at most this (e.g. 1e-3), instead of at the tolerance or iteration cap.
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) stop_at_error: Option<f64>,
    /// Newton iterations of the reference per attempt of a time step (the non-monotone attempt
    /// gets 20 times as many).
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) newton_iterations: u32,
    /// Plot the wall time on a logarithmic axis.
    #[arg(long)]
    pub(crate) log_time: bool,
}

#[derive(clap::Args)]
pub(crate) struct NodeArgs {
    /// Role of the node.
    pub(crate) role: RoleArg,
    /// Run id of the run to join (printed by the launcher).
    #[arg(long)]
    pub(crate) run: String,
    /// Zenoh endpoint(s) to connect to, e.g. tcp/192.168.1.10:7447 (repeatable).
    #[arg(long, required = true)]
    pub(crate) connect: Vec<String>,
    /// Subdomains hosted (subdomain role), e.g. 0,1,2; default: group `--index` of the scene's
    /// deployment (given, they must be that group).
    #[arg(long, value_delimiter = ',')]
    pub(crate) subdomains: Vec<u32>,
    /// Index of this node process among those of its role (subdomain nodes: 0, 1, …).
    #[arg(long, default_value_t = 0)]
    pub(crate) index: u32,
    /// Send the full displacement fields at the end (subdomain role).
    #[arg(long)]
    pub(crate) interior: bool,
    /// The MCAP file to write (recorder role).
    #[arg(long)]
    pub(crate) file: Option<PathBuf>,
    /// The launcher restarts node processes that die: a peer leaving does not stop this one.
    #[arg(long)]
    pub(crate) supervised: bool,
    /// Replace a node process that died mid-run: rebuild its state from the recorder's log
    /// instead of waiting for the start (the launcher passes it when it restarts a node).
    #[arg(long)]
    pub(crate) resume: bool,
    /// TLS (`--connect tls/…`): the certificate authority of the run (PEM), which signed the
    /// launcher's certificate.
    #[arg(long, value_name = "PEM")]
    pub(crate) tls_root_ca: Option<PathBuf>,
    /// Mutual TLS: this node's certificate (PEM), signed by `--tls-root-ca`; its common name must
    /// be in the scene's `network.allow` when the scene has one.
    #[arg(long, value_name = "PEM", requires = "tls_key")]
    pub(crate) tls_cert: Option<PathBuf>,
    /// Mutual TLS: the private key of `--tls-cert` (PEM).
    #[arg(long, value_name = "PEM", requires = "tls_cert")]
    pub(crate) tls_key: Option<PathBuf>,
    /// This node's credentials on the run's bus: the file the launcher wrote for it (readable by
    /// its owner only), or `-` to read the line from standard input. Needed to join a run whose
    /// launcher hosts the router (docs/operations.md).
    #[arg(long, value_name = "FILE")]
    pub(crate) credentials: Option<PathBuf>,
    /// Exchange fields with processes on this machine through shared memory (the launcher passes
    /// it when the scene says `network.shared_memory = true`, or leaves it unset and node
    /// restarts are off anyway).
    #[arg(long)]
    pub(crate) shared_memory: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum ColorByArg {
    /// Von Mises stress (MPa).
    VonMises,
    /// Displacement magnitude |u| (mm).
    Displacement,
}

#[derive(clap::Args)]
pub(crate) struct ReplayArgs {
    /// Recording (MCAP) of a run.
    pub(crate) recording: PathBuf,
    /// Write the Rerun data to this .rrd file (the default: the recording's name with .rrd).
    #[arg(long, conflicts_with_all = ["spawn", "connect", "node"])]
    pub(crate) save: Option<PathBuf>,
    /// Start a Rerun viewer (the `rerun` executable on PATH) and stream to it.
    #[arg(long, conflicts_with_all = ["connect", "node"])]
    pub(crate) spawn: bool,
    /// Stream to a running Rerun viewer (default address rerun+http://127.0.0.1:9876/proxy).
    #[arg(long, num_args = 0..=1, default_missing_value = glissade_replay::DEFAULT_VIEWER, value_name = "URL", conflicts_with = "node")]
    pub(crate) connect: Option<String>,
    /// Field the meshes are coloured by.
    #[arg(long, value_enum, default_value = "von-mises")]
    pub(crate) color_by: ColorByArg,
    /// Displacement amplification of the drawn meshes (default: the largest displacement drawn
    /// as 5 % of the model's size).
    #[arg(long, allow_negative_numbers = true, value_parser = positive_finite)]
    pub(crate) amplification: Option<f64>,
    /// Time point of the per-iteration meshes (default: the one with the largest boundary
    /// displacement).
    #[arg(long)]
    pub(crate) time_point: Option<usize>,
    /// Solve the scene with the monolithic Newton reference first and log each iteration's error
    /// against it (`error/traction`, `error/jump`), as `glissade report` measures it.
    #[arg(long, conflicts_with = "node")]
    pub(crate) reference: bool,
    /// Re-execute this node (`subdomain:<i>`, `interface:0`, `coarse:0`, or `all`) from its
    /// recorded inputs and check that its outputs are bit-identical (repeatable).
    #[arg(long, value_name = "ROLE:ID")]
    pub(crate) node: Vec<String>,
}

/// The solver settings a run's command line may override.
#[derive(clap::Args)]
pub(crate) struct SolverOverrideArgs {
    /// Stop once the estimated contact-traction error is at most this (overrides the scene's
    /// `solver.accuracy`, default 1e-3).
    #[arg(long, allow_negative_numbers = true)]
    pub(crate) accuracy: Option<f64>,
    /// Iteration cap (overrides the scene's `solver.max_iterations`, default 1000).
    #[arg(long)]
    pub(crate) max_iterations: Option<usize>,
}

#[derive(clap::Args)]
pub(crate) struct SubmitArgs {
    /// Scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Folder for the outputs, the batch script and the job's console (on a file system every
    /// host of the job sees).
    #[arg(long, default_value = "recordings")]
    pub(crate) out: PathBuf,
    /// Hosts to spread the node processes over (`sbatch --nodes`).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) nodes: u32,
    /// Time limit of the job, in a form sbatch takes (`30`, `2:00:00`, `1-00:00:00`).
    #[arg(long)]
    pub(crate) time: Option<String>,
    /// Partition to submit to (the cluster's default when not given).
    #[arg(long)]
    pub(crate) partition: Option<String>,
    /// Run id (default: 128 random bits in hex, chosen now so that the outputs' names are known).
    #[arg(long)]
    pub(crate) run_id: Option<String>,
    #[command(flatten)]
    pub(crate) solver: SolverOverrideArgs,
    /// Record nothing.
    #[arg(long)]
    pub(crate) no_record: bool,
}

#[derive(clap::Args)]
pub(crate) struct RunArgs {
    /// Scene file (TOML).
    pub(crate) scene: PathBuf,
    /// Run every node in this process instead of one process per node group (the default:
    /// Zenoh on loopback, the launcher hosting the router, no router to install).
    #[arg(long)]
    pub(crate) in_process: bool,
    /// Folder for the outputs.
    #[arg(long, default_value = "recordings")]
    pub(crate) out: PathBuf,
    /// Run id (namespaces the run's messages and output files); default: 128 random bits in hex,
    /// so that nobody on a shared router can guess the run's key expressions.
    #[arg(long)]
    pub(crate) run_id: Option<String>,
    #[command(flatten)]
    pub(crate) solver: SolverOverrideArgs,
    /// Also write every subdomain's displacement field.
    #[arg(long)]
    pub(crate) interior: bool,
    /// What to record, whatever the scene's [recording] says: `full` (every message, full
    /// fields at every iteration: what node restarts and `replay --node` need) or `off`.
    #[arg(long, value_enum, value_name = "full|off")]
    pub(crate) record: Option<RecordArg>,
    /// Record nothing (the same as --record off).
    #[arg(long, conflicts_with = "record")]
    pub(crate) no_record: bool,
    /// Also write a ParaView time series: `<scene>-<run>.pvd` and the folder `<scene>-<run>-vtu/`
    /// (subdomains with displacement and stresses, interfaces with tractions, jumps and status;
    /// docs/outputs.md).
    #[arg(long)]
    pub(crate) vtu: bool,
    /// With --vtu: only every k-th time point (and the last).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub(crate) vtu_every: u32,
    /// Also write `<scene>-<run>.interfaces.csv`: the interface fields, one row per node pair and
    /// time point (docs/outputs.md).
    #[arg(long)]
    pub(crate) csv: bool,
    /// No progress bar.
    #[arg(long)]
    pub(crate) quiet: bool,
    /// Also print how the run is set up and goes: how fields travel, node restarts, node
    /// readiness, each node process's notes, the bytes on the bus per message kind.
    #[arg(long, short)]
    pub(crate) verbose: bool,
    /// Zenoh endpoint(s) the launcher's router listens on, e.g. tcp/0.0.0.0:7447, for nodes
    /// started on other machines (default: a free loopback port). Repeatable.
    #[arg(long, conflicts_with_all = ["in_process", "connect"])]
    pub(crate) listen: Vec<String>,
    /// Connect to this Zenoh router (e.g. zenohd) instead of hosting one. Repeatable.
    #[arg(long, conflicts_with = "in_process")]
    pub(crate) connect: Vec<String>,
    /// Nodes the launcher does not start, to be started by hand with `glissade node`, e.g.
    /// subdomain:1,interface (role[:index]).
    #[arg(long, value_delimiter = ',', conflicts_with = "in_process")]
    pub(crate) remote: Vec<NodeName>,
    /// Start the node processes as Slurm job steps of the allocation this command runs in (in a
    /// batch script or under salloc), spread over its hosts, the router listening on this host's
    /// name (docs/operations.md, "On a cluster").
    #[arg(long, conflicts_with = "in_process")]
    pub(crate) slurm: bool,
    /// Longest wait for the nodes of --remote to be ready (s).
    #[arg(long, default_value_t = 300)]
    pub(crate) remote_timeout: u64,
    /// Stream the run's Rerun view as it goes (in-process, or from the launcher of a
    /// multi-process run): to a spawned viewer (`spawn`, the default), a running one (`connect`
    /// or its rerun+http://… address), or an .rrd file.
    #[arg(long, num_args = 0..=1, default_missing_value = "spawn", value_name = "SINK")]
    pub(crate) rerun: Option<String>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum GenerateKind {
    /// Plies stacked along y, each cut into square subdomains along x; perfect interfaces within
    /// a ply, Coulomb contact between plies, the stratified scene's loads.
    Laminate,
}

#[derive(clap::Args)]
pub(crate) struct GenerateArgs {
    /// What to generate.
    pub(crate) kind: GenerateKind,
    /// The scene file to write (refused if it exists).
    #[arg(long, short)]
    pub(crate) out: PathBuf,
    /// Plies.
    #[arg(long, default_value_t = 20)]
    pub(crate) plies: usize,
    /// Subdomains along each ply.
    #[arg(long, default_value_t = 50)]
    pub(crate) per_ply: usize,
    /// QUA8 elements along each side of a subdomain.
    #[arg(long, default_value_t = 10)]
    pub(crate) elements: usize,
    /// Side of a subdomain (mm).
    #[arg(allow_negative_numbers = true, long, default_value_t = 30.0)]
    pub(crate) side: f64,
    /// Time steps N.
    #[arg(long, default_value_t = 100)]
    pub(crate) steps: usize,
    /// Coulomb friction coefficient between plies.
    #[arg(allow_negative_numbers = true, long, default_value_t = 0.3)]
    pub(crate) friction: f64,
    /// Subdomain node processes of a multi-process run.
    #[arg(long, default_value_t = 3)]
    pub(crate) subdomain_nodes: usize,
    /// Interface node processes of a multi-process run.
    #[arg(long, default_value_t = 1)]
    pub(crate) interface_nodes: usize,
    /// The interface nodes follow the subdomain processes: each runs the interfaces inside its
    /// group, interface node 0 those between groups (`[deployment] interfaces_with_subdomains`).
    #[arg(long, conflicts_with = "interface_nodes")]
    pub(crate) interfaces_with_subdomains: bool,
    /// Which subdomains each subdomain process hosts (`[deployment] partition`): runs of
    /// consecutive subdomains (whole plies when the processes divide the plies evenly), or
    /// recursive coordinate bisection (pieces cut across the plies, fewer interfaces between
    /// processes).
    #[arg(long, value_enum, default_value_t = PartitionArg::Contiguous)]
    pub(crate) partition: PartitionArg,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum PartitionArg {
    Contiguous,
    Bisection,
}

/// A finite number above zero (`--amplification`).
fn positive_finite(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        Ok(x) => Err(format!("{x} is not a finite number above 0")),
        Err(e) => Err(format!("not a number: {e}")),
    }
}
