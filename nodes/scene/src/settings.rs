//! The runtime sections of a scene: `[network]`, `[deployment]` and `[recording]`. They describe
//! how a run is deployed, not the problem: the launcher and the nodes read them.

use crate::SceneError;
use glissade_mechanics::model::Model;

/// `[network]`: TLS between the processes of a run and access control on its bus.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Network {
    /// `network.tls`; None: plain TCP.
    pub tls: Option<TlsFiles>,
    /// `network.allow`: certificate common names allowed to take part (deny by default); None:
    /// every process the certificate authority vouches for (or any, without TLS).
    pub allow: Option<Vec<String>>,
    /// `network.shared_memory`: processes on one machine pass fields through shared memory
    /// instead of loopback sockets; None (unset): the launcher decides (on when node restarts
    /// are off anyway, see the launcher).
    pub shared_memory: Option<bool>,
}

/// `network.tls`: PEM files, as written until [`Network::resolve_files`] makes them relative to
/// the scene file's folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsFiles {
    /// The certificate authority that signs every certificate of the run.
    pub root_ca: std::path::PathBuf,
    /// The launcher's certificate (its router's, and the one of the nodes it starts).
    pub cert: std::path::PathBuf,
    /// The private key of `cert`.
    pub key: std::path::PathBuf,
    /// Clients must present a certificate signed by `root_ca` (mutual TLS).
    pub mutual: bool,
}

impl Network {
    /// Makes the TLS file paths relative to the folder of `scene_file` (absolute ones stay) and
    /// checks that each is a readable PEM file; errors name the key and the path.
    pub fn resolve_files(&mut self, scene_file: &std::path::Path) -> Result<(), SceneError> {
        let Some(tls) = &mut self.tls else { return Ok(()) };
        let folder = scene_file.parent().unwrap_or(std::path::Path::new(""));
        for (key, path) in [
            ("network.tls.root_ca", &mut tls.root_ca),
            ("network.tls.cert", &mut tls.cert),
            ("network.tls.key", &mut tls.key),
        ] {
            *path = folder.join(&*path);
            let err = |problem: String| SceneError {
                file: scene_file.display().to_string(),
                key: key.to_string(),
                problem,
                set_by: None,
            };
            let bytes = std::fs::read(&*path).map_err(|e| err(format!("cannot read {}: {e}", path.display())))?;
            if !bytes.windows(11).any(|w| w == b"-----BEGIN ") {
                return Err(err(format!(
                    "{} is not a PEM file (no -----BEGIN line)",
                    path.display()
                )));
            }
        }
        Ok(())
    }
}

/// How the subdomains are split into the subdomain node processes' groups.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Partition {
    /// Runs of consecutive subdomains (model order: blocks in the scene's order, each block's
    /// subdomains row by row).
    #[default]
    Contiguous,
    /// Recursive coordinate bisection of the subdomains' centroids: each cut is across the
    /// longer side of the box around the centroids, so that long parts (plies, layers) are cut
    /// into strips across them and fewer interfaces join two processes.
    Bisection,
}

impl Partition {
    /// Its name in a scene's `[deployment] partition` (and `glissade generate --partition`).
    pub fn name(self) -> &'static str {
        match self {
            Partition::Contiguous => "contiguous",
            Partition::Bisection => "bisection",
        }
    }
}

/// How many node processes of each role a run uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Deployment {
    pub subdomain_nodes: usize,
    /// Which subdomains each subdomain node process hosts.
    pub partition: Partition,
    pub interface_nodes: usize,
    /// The interfaces each interface node owns (model interface indices, ascending), when the
    /// scene assigns them; None: [`balanced_interface_groups`].
    pub interface_groups: Option<Vec<Vec<usize>>>,
    /// How many times the launcher restarts each node process that dies mid-run.
    pub restarts: usize,
    /// The launcher runs the interface nodes in its own process, beside the router it hosts,
    /// when no node restarts are possible and they are not started by hand: fields between them
    /// and the subdomain processes then cross one socket instead of two.
    pub interfaces_in_launcher: bool,
    /// Each subdomain process also runs the local stage of the interfaces between its own
    /// subdomains (an interface node of its own); the interfaces between subdomains of different
    /// processes belong to interface node 0. Fields of the interfaces inside a process then never
    /// leave it. Set with neither `interface_nodes` nor `interface_groups` (the deployment's plan
    /// makes the groups).
    pub interfaces_with_subdomains: bool,
}

impl Default for Deployment {
    fn default() -> Self {
        Self {
            subdomain_nodes: 1,
            partition: Partition::Contiguous,
            interface_nodes: 1,
            interface_groups: None,
            restarts: 3,
            interfaces_in_launcher: true,
            interfaces_with_subdomains: false,
        }
    }
}

impl Deployment {
    /// The interfaces each of the `interface_nodes` interface nodes owns: the scene's assignment,
    /// or contiguous groups balanced by pair count. A model without interfaces: one empty group.
    pub fn interface_groups(&self, model: &Model) -> Vec<Vec<usize>> {
        match &self.interface_groups {
            Some(g) => g.clone(),
            None => balanced_interface_groups(model, self.interface_nodes),
        }
    }
}

/// `n` groups of consecutive interfaces (in model order) whose pair counts are as even as a
/// greedy cut can make them: group g ends where the running pair count comes closest to
/// (g + 1)/n of the total; every group gets at least one interface (`n` is clamped to
/// 1..=number of interfaces).
pub fn balanced_interface_groups(model: &Model, n: usize) -> Vec<Vec<usize>> {
    let weights: Vec<f64> = model.interfaces.iter().map(|i| i.n_pairs() as f64).collect();
    let m = weights.len();
    let n = n.clamp(1, m.max(1));
    let total: f64 = weights.iter().sum();
    let mut groups = Vec::with_capacity(n);
    let (mut i, mut sum) = (0, 0.0);
    for g in 0..n {
        let target = total * (g + 1) as f64 / n as f64;
        let later = n - g - 1;
        let mut group = Vec::new();
        while i + later < m {
            let next = sum + weights[i];
            if !group.is_empty() && later > 0 && (next - target).abs() > (sum - target).abs() {
                break;
            }
            group.push(i);
            sum = next;
            i += 1;
        }
        groups.push(group);
    }
    groups
}

/// Full fields (boundary states and local directions) per iteration, in bytes, up to which a
/// scene that does not set `recording.full_fields_every` records them at every iteration.
pub const AUTO_FULL_FIELD_BYTES: u64 = 1_000_000;

/// `recording.full_fields_every` of a scene that does not set it and has more full-field bytes
/// per iteration than [`AUTO_FULL_FIELD_BYTES`].
pub const AUTO_FULL_FIELDS_EVERY: usize = 20;

/// What the recorder writes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recording {
    pub enabled: bool,
    /// Key-expression patterns (relative to the run) to record.
    pub topics: Vec<String>,
    /// Record full fields every k-th iteration (everything small every iteration).
    pub full_fields_every: usize,
    /// The scene does not set `full_fields_every`: it was chosen from the scene's size (1 up to
    /// [`AUTO_FULL_FIELD_BYTES`] of full fields per iteration, else [`AUTO_FULL_FIELDS_EVERY`]).
    pub full_fields_auto: bool,
}

/// Bytes of full fields one iteration of `model` sends: per subdomain its boundary state (W and
/// F) and its local directions, each n_b × (N + 1) doubles, where n_b counts 2 values per node
/// pair on each side of each interface.
pub fn full_field_bytes_per_iteration(model: &glissade_mechanics::model::Model) -> u64 {
    let boundary_values: usize = model.interfaces.iter().map(|i| 2 * 2 * i.n_pairs()).sum();
    3 * 8 * (boundary_values * model.time.n_points()) as u64
}

/// Bytes of the interface solutions a run sends at its end (s and ŝ of every interface: 8 fields
/// of 2 values per pair and time point).
pub fn final_field_bytes(model: &glissade_mechanics::model::Model) -> u64 {
    let pairs: usize = model.interfaces.iter().map(|i| i.n_pairs()).sum();
    8 * 8 * (2 * pairs * model.time.n_points()) as u64
}

impl Recording {
    /// Why a node process cannot resume from this recording (it needs every message), if it
    /// cannot.
    pub fn incomplete(&self) -> Option<String> {
        if !self.enabled {
            Some("recording.enabled = false".into())
        } else if self.topics.iter().all(|t| t != "**") {
            Some(format!("recording.topics = {:?} leaves messages out", self.topics))
        } else if self.full_fields_every > 1 && self.full_fields_auto {
            Some(format!(
                "recording.full_fields_every is unset: this scene's full fields exceed {} MB per iteration, \
                 so they are recorded every {}th iteration only; set it to 1, or run with --record full, \
                 for a complete recording",
                AUTO_FULL_FIELD_BYTES / 1_000_000,
                self.full_fields_every
            ))
        } else if self.full_fields_every > 1 {
            Some(format!(
                "recording.full_fields_every = {} leaves full fields out",
                self.full_fields_every
            ))
        } else {
            None
        }
    }
}

impl Default for Recording {
    fn default() -> Self {
        Self {
            enabled: true,
            topics: vec!["**".to_string()],
            full_fields_every: 1,
            full_fields_auto: true,
        }
    }
}
