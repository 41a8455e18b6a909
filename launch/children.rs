//! The launcher's child processes: spawning a node or recorder process with its output
//! forwarded under a `[role:index]` prefix, its last lines kept for error messages, killed with
//! the launcher (parent-death signal) and, for node processes, killed when the run's set of
//! children is dropped on any error path.

use crate::error::{IoWhat, Result};
use glissade_messages::Role;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Role of a node process started by hand or by the launcher.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum NodeRole {
    Subdomain,
    Interface,
    Coarse,
}

impl NodeRole {
    /// The message role of the node.
    pub fn role(self) -> Role {
        match self {
            NodeRole::Subdomain => Role::Subdomain,
            NodeRole::Interface => Role::Interface,
            NodeRole::Coarse => Role::Coarse,
        }
    }

    /// The role's chunk in key expressions and node names ([`Role::key`]).
    pub fn key(self) -> &'static str {
        self.role().key()
    }
}

/// A node process of a run: its role and index (`subdomain:1`, `interface:0`, `coarse:0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct NodeName {
    pub role: NodeRole,
    pub index: u32,
}

impl NodeName {
    /// The node's identity in messages and on the bus.
    pub fn id(self) -> glissade_messages::NodeId {
        glissade_messages::NodeId {
            role: self.role.role(),
            index: self.index,
        }
    }
}

impl std::fmt::Display for NodeName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.role.key(), self.index)
    }
}

impl std::str::FromStr for NodeName {
    type Err = String;

    /// `role[:index]` with role `subdomain`, `interface` or `coarse`; the index defaults to 0.
    fn from_str(s: &str) -> Result<Self, String> {
        let (role, index) = s.split_once(':').unwrap_or((s, "0"));
        let role = match role {
            "subdomain" => NodeRole::Subdomain,
            "interface" => NodeRole::Interface,
            "coarse" => NodeRole::Coarse,
            _ => return Err(format!("`{s}`: the role must be subdomain, interface or coarse")),
        };
        let index = index
            .parse()
            .map_err(|_| format!("`{s}`: the index after `:` must be a non-negative integer"))?;
        Ok(Self { role, index })
    }
}

/// One spawned node process.
pub(crate) struct NodeProcess {
    pub(crate) name: NodeName,
    pub(crate) child: Child,
    /// Its `glissade node` arguments (a replacement gets them too, with `--resume`).
    pub(crate) args: Vec<String>,
    /// Its credentials on the run's bus, written to its standard input (`--credentials -`).
    pub(crate) credentials: Option<glissade_zenoh::Credentials>,
    pub(crate) output: ChildOutput,
    /// Exit status once it exited.
    pub(crate) status: Option<ExitStatus>,
    /// Its liveliness token was seen (a token of the same name that disappears before is its
    /// predecessor's).
    pub(crate) token_seen: bool,
    /// When its liveliness token disappeared while it was still running.
    pub(crate) token_lost: Option<Instant>,
}

impl NodeProcess {
    pub(crate) fn last_lines(&self) -> String {
        let lines = self.output.lines();
        if lines.is_empty() {
            "(none)".to_string()
        } else {
            lines.join("\n    ")
        }
    }
}

/// Kills every child still running when dropped (on any error path).
pub(crate) struct Children(pub(crate) Vec<NodeProcess>);

impl Drop for Children {
    fn drop(&mut self) {
        for p in &mut self.0 {
            if let Ok(None) = p.child.try_wait() {
                let _ = p.child.kill();
                let _ = p.child.wait();
            }
        }
    }
}

impl Children {
    /// Waits up to `timeout` for every child to exit (after `stop`); the rest are killed on drop.
    pub(crate) fn wait_all(&mut self, timeout: Duration) {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline && self.0.iter_mut().any(|p| matches!(p.child.try_wait(), Ok(None))) {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Forwards a child's output lines to stderr with a `[prefix]`, keeping its last 10 lines in `last`.
pub(crate) fn forward(
    prefix: String,
    stream: impl std::io::Read + Send + 'static,
    last: Arc<Mutex<Vec<String>>>,
) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(Result::ok) {
            if crate::console::shows_child_line(&line) {
                crate::console::say(&format!("[{prefix}] {line}"));
            }
            if let Ok(mut l) = last.lock() {
                l.push(line);
                let n = l.len();
                if n > 10 {
                    l.drain(..n - 10);
                }
            }
        }
    })
}

/// Longest wait, once a child process has exited, for the threads that read its output to reach
/// its end ([`ChildOutput::settle`]).
const OUTPUT_SETTLE: Duration = Duration::from_secs(2);

/// What the launcher keeps of a spawned child's output: its last lines and the threads of
/// [`forward`] that read them.
pub(crate) struct ChildOutput {
    last_lines: Arc<Mutex<Vec<String>>>,
    readers: Vec<std::thread::JoinHandle<()>>,
}

impl ChildOutput {
    /// Waits (up to [`OUTPUT_SETTLE`]) for the readers of an exited child's output to have read
    /// it all, so that its last lines, its own error among them, are there to quote: the
    /// process's exit can be seen before its last writes are read.
    pub(crate) fn settle(&self) {
        let deadline = Instant::now() + OUTPUT_SETTLE;
        while self.readers.iter().any(|r| !r.is_finished()) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// The last lines read so far (at most 10).
    pub(crate) fn lines(&self) -> Vec<String> {
        self.last_lines.lock().map(|l| l.clone()).unwrap_or_default()
    }
}

/// Starts node process `name` with `args` through `cmd` (the executable, or `srun` running it as
/// a Slurm job step: `crate::starter::Starter::command`): its own process group, killed with the
/// launcher; `credentials`, when given, are written to its standard input.
pub(crate) fn spawn_node(
    mut cmd: Command,
    name: NodeName,
    args: &[String],
    credentials: Option<glissade_zenoh::Credentials>,
) -> Result<NodeProcess> {
    let program = cmd.get_program().to_string_lossy().into_owned();
    cmd.args(args);
    {
        use std::os::unix::process::CommandExt;
        // Its own process group: a Ctrl-C in the terminal reaches the launcher only, which then
        // stops every node through the bus.
        cmd.process_group(0);
    }
    let (child, output) = spawn_child(cmd, &name.to_string(), libc::SIGKILL, credentials.as_ref())
        .what(|| format!("cannot start node process {name} ({program})"))?;
    Ok(NodeProcess {
        name,
        child,
        args: args.to_vec(),
        credentials,
        output,
        status: None,
        token_seen: false,
        token_lost: None,
    })
}

/// Spawns `cmd` with its standard output and error forwarded under `[prefix]` ([`forward`]) and
/// `death_signal` sent to it when the launcher dies (Linux's parent-death signal: no orphans even
/// if the launcher is killed). `credentials`, when given, are its standard input's one line: no
/// other process sees them (a command line or an environment can be read by other users).
/// Returns the child and what is kept of its output.
pub(crate) fn spawn_child(
    mut cmd: Command,
    prefix: &str,
    death_signal: libc::c_int,
    credentials: Option<&glissade_zenoh::Credentials>,
) -> std::io::Result<(Child, ChildOutput)> {
    let stdin = if credentials.is_some() {
        Stdio::piped()
    } else {
        Stdio::null()
    };
    cmd.stdin(stdin).stdout(Stdio::piped()).stderr(Stdio::piped());
    #[cfg(target_os = "linux")]
    // SAFETY: prctl is async-signal-safe; nothing else runs between fork and exec.
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(move || {
            libc::prctl(libc::PR_SET_PDEATHSIG, death_signal);
            Ok(())
        });
    }
    let mut child = cmd.spawn()?;
    if let (Some(c), Some(mut stdin)) = (credentials, child.stdin.take()) {
        use std::io::Write;
        // One short line: it fits in the pipe's buffer, so this does not wait for the child.
        let written = stdin.write_all(c.line().as_bytes());
        drop(stdin);
        if let Err(e) = written {
            let _ = child.kill();
            let _ = child.wait();
            return Err(e);
        }
    }
    let last = Arc::new(Mutex::new(Vec::new()));
    let mut readers = Vec::new();
    if let Some(out) = child.stdout.take() {
        readers.push(forward(prefix.to_string(), out, last.clone()));
    }
    if let Some(err) = child.stderr.take() {
        readers.push(forward(prefix.to_string(), err, last.clone()));
    }
    Ok((
        child,
        ChildOutput {
            last_lines: last,
            readers,
        },
    ))
}
