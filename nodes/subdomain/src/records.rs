//! The launcher's view of a run's linear stages: one [`LinearStageRecord`] per subdomain and
//! iteration, put together from what the subdomain said (its `LinearStageStats` message: flops,
//! PGD basis, ξ) and what the bus measured (its handling of the inputs that ran the stage,
//! [`IterationTime`]). The node itself reads no clock.

use glissade_bus::IterationTime;
use glissade_messages::{LinearStageStats, Message, Payload, Role};
use std::collections::BTreeMap;

/// The fields of the messages whose handling by a subdomain node is its linear stage of their
/// iteration: q̂ (micro problem 1 and the macro forces), w̃ (micro problem 2, the relaxation or
/// the Anderson record, the state sent) and the Anderson step (the mixing, the state sent). At
/// iteration 0 the node's start counts too (micro problem 1 from ŝ = 0).
pub const LINEAR_STAGE_INPUTS: [&str; 3] = ["local_directions", "macro_displacements", "anderson_step"];

/// What one linear stage of one subdomain did: its wall time and the counters it sent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinearStageRecord {
    pub subdomain: u32,
    pub iteration: u32,
    /// Wall time of the stage: the bus's time of the subdomain node's handling of the stage's
    /// inputs ([`LINEAR_STAGE_INPUTS`], and at iteration 0 its start); 0 when nothing timed it.
    pub seconds: f64,
    /// Floating-point operations of the stage, as its kernels count them
    /// ([`LinearStageStats::flops`]).
    pub flops: u64,
    /// PGD basis size after the stage (0 without PGD), frozen macro modes included.
    pub modes: usize,
    /// Modes added in this stage (micro 1 + micro 2) and dropped by compression.
    pub new_modes: usize,
    pub dropped_modes: usize,
    /// ξ at the end of micro 1 and micro 2.
    pub xi1: f64,
    pub xi2: f64,
}

impl LinearStageRecord {
    /// The record of the stage of `iteration` whose counters are `stats`, timed `seconds`.
    pub fn new(iteration: u32, stats: &LinearStageStats, seconds: f64) -> Self {
        Self {
            subdomain: stats.subdomain,
            iteration,
            seconds,
            flops: stats.flops,
            modes: stats.modes as usize,
            new_modes: stats.new_modes as usize,
            dropped_modes: stats.dropped_modes as usize,
            xi1: stats.xi1,
            xi2: stats.xi2,
        }
    }
}

/// Collects the `LinearStageStats` of a run's messages ([`Self::observe`]), then joins them with
/// the bus's handling times ([`Self::records`]).
#[derive(Debug, Clone, Default)]
pub struct LinearStageRecords {
    /// (iteration, counters) in the order observed.
    stats: Vec<(u32, LinearStageStats)>,
}

impl LinearStageRecords {
    /// Keeps `m`'s counters if it is a subdomain's `LinearStageStats`.
    pub fn observe(&mut self, m: &Message) {
        if let (Payload::LinearStageStats(s), Role::Subdomain) = (&m.payload, m.envelope.sender.role) {
            self.stats.push((m.envelope.iteration, *s));
        }
    }

    /// Whether subdomain `subdomain`'s counters of iteration `iteration` were observed.
    pub fn has(&self, iteration: u32, subdomain: u32) -> bool {
        self.stats
            .iter()
            .any(|(it, s)| *it == iteration && s.subdomain == subdomain)
    }

    /// One record per counters' message observed, sorted by (iteration, subdomain), each with the
    /// time `times` give its stage (0 where they give none, e.g. without timing).
    pub fn records(&self, times: &[IterationTime]) -> Vec<LinearStageRecord> {
        let mut seconds: BTreeMap<(u32, u32), f64> = BTreeMap::new();
        for t in times.iter().filter(|t| t.node.role == Role::Subdomain) {
            let counts = match t.field.as_deref() {
                None => t.iteration == 0,
                Some(f) => LINEAR_STAGE_INPUTS.contains(&f),
            };
            if counts {
                *seconds.entry((t.node.index, t.iteration)).or_default() += t.seconds;
            }
        }
        let mut records: Vec<LinearStageRecord> = self
            .stats
            .iter()
            .map(|(it, s)| {
                let t = seconds.get(&(s.subdomain, *it)).copied().unwrap_or(0.0);
                LinearStageRecord::new(*it, s, t)
            })
            .collect();
        records.sort_by_key(|r| (r.iteration, r.subdomain));
        records
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_bus::RunContext;
    use glissade_messages::{NodeId, Stage};

    fn subdomain(index: u32) -> NodeId {
        NodeId {
            role: Role::Subdomain,
            index,
        }
    }

    fn time(node: NodeId, iteration: u32, field: Option<&str>, seconds: f64) -> IterationTime {
        IterationTime {
            node,
            iteration,
            field: field.map(str::to_string),
            calls: 1,
            seconds,
        }
    }

    /// A stage's time is its subdomain's handling of that iteration's q̂, w̃ and Anderson step
    /// (and its start at iteration 0), nothing else: not the decision (the displacement field at
    /// the stop), not another node's, not another iteration's.
    #[test]
    fn a_record_joins_the_counters_and_the_stage_inputs_times() {
        let ctx = RunContext {
            run_id: "r".into(),
            scene_fingerprint: 1,
        };
        let stats = |s: u32, it: u32, flops: u64| Message {
            envelope: ctx.envelope(subdomain(s), it, Stage::Linear),
            payload: Payload::LinearStageStats(LinearStageStats {
                subdomain: s,
                flops,
                modes: 3 + it,
                new_modes: 1,
                dropped_modes: 0,
                xi1: 0.5,
                xi2: 0.25,
            }),
        };
        let mut collected = LinearStageRecords::default();
        for m in [stats(1, 1, 30), stats(0, 1, 20), stats(1, 0, 10), stats(0, 0, 5)] {
            collected.observe(&m);
        }
        let interface = NodeId {
            role: Role::Interface,
            index: 0,
        };
        let times = [
            time(subdomain(0), 0, None, 1.0),
            time(subdomain(0), 0, Some("macro_displacements"), 2.0),
            time(subdomain(0), 0, Some("decision"), 100.0),
            time(subdomain(0), 1, Some("local_directions"), 4.0),
            time(subdomain(0), 1, Some("anderson_step"), 8.0),
            time(subdomain(0), 1, Some("decision"), 100.0),
            time(subdomain(1), 0, None, 16.0),
            time(subdomain(1), 1, Some("local_directions"), 32.0),
            time(interface, 1, Some("boundary_state"), 100.0),
        ];
        let r = collected.records(&times);
        let got: Vec<(u32, u32, f64, u64, usize)> = r
            .iter()
            .map(|r| (r.iteration, r.subdomain, r.seconds, r.flops, r.modes))
            .collect();
        assert_eq!(
            got,
            [
                (0, 0, 3.0, 5, 3),
                (0, 1, 16.0, 10, 3),
                (1, 0, 12.0, 20, 4),
                (1, 1, 32.0, 30, 4)
            ]
        );
        assert_eq!((r[0].xi1, r[0].xi2, r[0].new_modes), (0.5, 0.25, 1));
        // Without times: the counters, untimed.
        assert!(collected.records(&[]).iter().all(|r| r.seconds == 0.0));
    }
}
