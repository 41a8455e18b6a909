//! Where the launcher starts the node processes it starts itself: as its own child processes on
//! this machine, or as Slurm job steps of the allocation it runs in (docs/operations.md, "On a
//! cluster"). Nodes named by `--remote` are started by hand, whichever it is. The supervision,
//! the restarts, the verdicts and the recording do not care which: a node process is a child
//! of the launcher either way (under Slurm, the `srun` that runs it, which passes on its
//! standard input, its output, its exit status and the signals it gets).

use crate::children::{NodeName, NodeRole};
use crate::error::{Error, Result};
use std::path::Path;
use std::process::Command;

/// Where the launcher starts node processes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum Starter {
    /// Child processes on this machine.
    #[default]
    Local,
    /// One Slurm job step per node process (`srun --overlap -N1 -n1`), in the allocation the
    /// launcher runs in, spread over its hosts.
    Slurm(SlurmAllocation),
}

/// The Slurm allocation a launcher runs in (`salloc`, `sbatch`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlurmAllocation {
    pub job_id: String,
    /// Its hosts, in Slurm's order.
    pub hosts: Vec<String>,
}

impl SlurmAllocation {
    /// The allocation this process runs in, from Slurm's environment (`SLURM_JOB_ID`, and
    /// `SLURM_JOB_NODELIST` expanded by `scontrol show hostnames`).
    pub fn from_env() -> Result<Self> {
        let outside = |why: &str| Error::Option {
            option: "--slurm".into(),
            why: format!(
                "{why}: run `glissade run --slurm` inside an allocation (in a batch script, or under \
                 `salloc`), or let `glissade submit` write and submit the batch script"
            ),
        };
        let job_id = std::env::var("SLURM_JOB_ID")
            .map_err(|_| outside("not inside a Slurm allocation (SLURM_JOB_ID is not set)"))?;
        let list = std::env::var("SLURM_JOB_NODELIST").map_err(|_| outside("SLURM_JOB_NODELIST is not set"))?;
        let out = Command::new("scontrol")
            .args(["show", "hostnames", &list])
            .output()
            .map_err(|e| outside(&format!("cannot run `scontrol show hostnames {list}` ({e})")))?;
        if !out.status.success() {
            return Err(outside(&format!(
                "`scontrol show hostnames {list}` failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            )));
        }
        let hosts: Vec<String> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(str::trim)
            .filter(|h| !h.is_empty())
            .map(str::to_string)
            .collect();
        if hosts.is_empty() {
            return Err(outside(&format!("the allocation's node list `{list}` names no host")));
        }
        Ok(Self { job_id, hosts })
    }

    /// The host node process `name` runs on: subdomain nodes go round the hosts in index order,
    /// the interface nodes after them, the coarse node last, so that K hosts share the work as
    /// evenly as whole processes allow.
    pub fn host_of(&self, name: NodeName, subdomain_nodes: u32, interface_nodes: u32) -> &str {
        let ordinal = match name.role {
            NodeRole::Subdomain => name.index,
            NodeRole::Interface => subdomain_nodes + name.index,
            NodeRole::Coarse => subdomain_nodes + interface_nodes + name.index,
        };
        &self.hosts[ordinal as usize % self.hosts.len()]
    }
}

/// How many subdomain and interface node processes a run has (for [`SlurmAllocation::host_of`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct NodeCounts {
    pub subdomain: u32,
    pub interface: u32,
}

impl Starter {
    /// The command that starts `exe` as node process `name`: `exe` itself, or `srun` running it
    /// as a job step on its host (`--overlap`: the steps share the allocation's CPUs, as a run's
    /// processes share one machine's; `--kill-on-bad-exit`: a step whose process fails ends).
    pub(crate) fn command(&self, exe: &Path, name: NodeName, counts: NodeCounts) -> Command {
        match self {
            Starter::Local => Command::new(exe),
            Starter::Slurm(a) => {
                let mut c = Command::new("srun");
                c.args([
                    "--overlap",
                    "--nodes=1",
                    "--ntasks=1",
                    "--overcommit",
                    "--kill-on-bad-exit=1",
                    "--quiet",
                ])
                .arg(format!(
                    "--nodelist={}",
                    a.host_of(name, counts.subdomain, counts.interface)
                ))
                .arg(format!("--job-name=glissade-{name}"))
                .arg(exe);
                c
            }
        }
    }

    /// How many hosts node processes may start on (1 on this machine).
    pub fn hosts(&self) -> usize {
        match self {
            Starter::Local => 1,
            Starter::Slurm(a) => a.hosts.len(),
        }
    }

    /// What the run's node list says of where its processes were started.
    pub fn describe(&self) -> Option<String> {
        match self {
            Starter::Local => None,
            Starter::Slurm(a) => Some(format!(
                "started as job steps of Slurm job {} on {}",
                a.job_id,
                a.hosts.join(", ")
            )),
        }
    }

    /// The name other hosts reach this one by, for the endpoint node processes connect to, when
    /// they may run elsewhere (under Slurm); None for loopback.
    pub(crate) fn advertised_host(&self) -> Result<Option<String>> {
        match self {
            Starter::Local => Ok(None),
            Starter::Slurm(_) => this_host().map(Some),
        }
    }
}

/// This machine's host name.
pub fn this_host() -> Result<String> {
    let mut buf = [0u8; 256];
    // SAFETY: the buffer is valid for its length; gethostname writes at most that many bytes.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    let name = String::from_utf8_lossy(&buf[..end]).into_owned();
    if rc != 0 || name.is_empty() {
        return Err(Error::Failed(format!(
            "cannot read this machine's host name: {}",
            std::io::Error::last_os_error()
        )));
    }
    Ok(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three subdomain nodes, one interface node and the coarse node over two hosts: round
    /// robin in that order.
    #[test]
    fn node_processes_go_round_the_hosts() {
        let a = SlurmAllocation {
            job_id: "7".into(),
            hosts: vec!["n1".into(), "n2".into()],
        };
        let at = |role, index| a.host_of(NodeName { role, index }, 3, 1).to_string();
        assert_eq!(
            [
                at(NodeRole::Subdomain, 0),
                at(NodeRole::Subdomain, 1),
                at(NodeRole::Subdomain, 2),
                at(NodeRole::Interface, 0),
                at(NodeRole::Coarse, 0)
            ],
            ["n1", "n2", "n1", "n2", "n1"]
        );
    }
}
