//! Every key expression of a run (docs/architecture.md), built here and nowhere else. All of a run's keys
//! are under `glissade/<run>/` ([`run_topics`]):
//!
//! - messages: `<role>/<id>/<field>[/<destination subdomain>]` ([`topic`], [`role_field_topic`]);
//! - the launcher's control keys: `launcher/0/scene` (queryable), `launcher/0/start`,
//!   `launcher/0/stop`, `launcher/0/done`, `launcher/0/end`, and when a run stops moving
//!   `launcher/0/status_request` and `launcher/0/republish` ([`scene`], [`start`], [`stop`],
//!   [`done`], [`end`], [`status_request`], [`republish`]);
//! - liveliness tokens: `alive/<role>/<id>` for the nodes and the launcher ([`alive`]), and
//!   `recording/alive` for the recorder, which is an observer, not a node ([`recorder_alive`]);
//! - the recorder's log queryable: `recorder/0/log` ([`log`]).
//!
//! A key expression's chunks are separated by `/`; `*` matches one chunk, `**` any number
//! ([`key_matches`]).

use crate::{Awaited, NodeId, Payload, Role};
use std::fmt::Display;

/// `glissade/<run>/<rest>`: a key (or key expression) of run `run_id`, e.g. a recorder's topic
/// pattern `subdomain/*/boundary_state`.
pub fn within_run(run_id: &str, rest: impl Display) -> String {
    format!("glissade/{run_id}/{rest}")
}

/// `glissade/<run>/<role>/<id>/<field>[/<destination subdomain>]`.
pub fn topic(run_id: &str, sender: NodeId, payload: &Payload) -> String {
    let base = within_run(
        run_id,
        format_args!("{}/{}/{}", sender.role.key(), sender.index, payload.field_key()),
    );
    match payload.destination() {
        Some(d) => format!("{base}/{d}"),
        None => base,
    }
}

/// The field chunk of a key `glissade/<run>/<role>/<id>/<field>[/<destination>]` (None if the key
/// has fewer chunks).
pub fn topic_field(topic: &str) -> Option<&str> {
    topic.split('/').nth(4)
}

/// Everything of one run: `glissade/<run>/**`.
pub fn run_topics(run_id: &str) -> String {
    within_run(run_id, "**")
}

/// Key expression of one field from any sender of a role, optionally for one destination.
pub fn role_field_topic(run_id: &str, role: Role, field: &str, destination: Option<u32>) -> String {
    match destination {
        Some(d) => within_run(run_id, format_args!("{}/*/{field}/{d}", role.key())),
        None => within_run(run_id, format_args!("{}/*/{field}", role.key())),
    }
}

/// Key of one field from one sender (no destination): `glissade/<run>/<role>/<id>/<field>`.
pub fn sender_field_topic(run_id: &str, sender: NodeId, field: &str) -> String {
    within_run(run_id, format_args!("{}/{}/{field}", sender.role.key(), sender.index))
}

/// Key expression of every subdomain's linear-stage counters (`LinearStageStats`) in run
/// `run_id`: `glissade/<run>/subdomain/*/linear_stage_stats` (what a report or a replay reads;
/// no node takes them).
pub fn linear_stage_stats(run_id: &str) -> String {
    role_field_topic(run_id, Role::Subdomain, "linear_stage_stats", None)
}

/// Everything node `id` publishes: `glissade/<run>/<role>/<id>/**`.
pub fn sent_by(run_id: &str, id: NodeId) -> String {
    within_run(run_id, format_args!("{}/{}/**", id.role.key(), id.index))
}

/// The keys node `id` may speak on in run `run_id` (publish, reply, declare a queryable or a
/// liveliness token): everything it publishes ([`sent_by`]) and its liveliness token ([`alive`],
/// [`recorder_alive`] for the recorder).
pub fn own_keys(run_id: &str, id: NodeId) -> Vec<String> {
    let token = match id.role {
        Role::Recorder => recorder_alive(run_id),
        role => alive(run_id, role.key(), id.index),
    };
    vec![sent_by(run_id, id), token]
}

/// `glissade/<run>/launcher/0/<what>`.
fn launcher(run_id: &str, what: &str) -> String {
    within_run(run_id, format_args!("{}/0/{what}", Role::Launcher.key()))
}

/// Key of the scene queryable of a run (the launcher's).
pub fn scene(run_id: &str) -> String {
    launcher(run_id, "scene")
}

/// Key the launcher publishes on once every node is ready.
pub fn start(run_id: &str) -> String {
    launcher(run_id, "start")
}

/// Key the launcher publishes on to stop every node of a run, and the recorder (a failed or
/// interrupted run; payload: the reason, UTF-8).
pub fn stop(run_id: &str) -> String {
    launcher(run_id, "stop")
}

/// Key the launcher publishes on once it holds the run's results (the final decision and every
/// final output): node processes leave only then.
pub fn done(run_id: &str) -> String {
    launcher(run_id, "done")
}

/// Key on which the launcher tells the recorder that the run is over, with the number of
/// messages of the run it saw (u64, little-endian).
pub fn end(run_id: &str) -> String {
    launcher(run_id, "end")
}

/// Key the launcher publishes on to ask every node for its status ([`crate::NodeStatus`];
/// payload: the request's round, u64 little-endian), when the run stops moving.
pub fn status_request(run_id: &str) -> String {
    launcher(run_id, "status_request")
}

/// Key the launcher publishes on to ask a node to put its last message on a key again (payload:
/// the key, UTF-8): a message its receiver lacks although its sender put it on the bus.
pub fn republish(run_id: &str) -> String {
    launcher(run_id, "republish")
}

/// Every node's status: `glissade/<run>/*/*/status`.
pub fn statuses(run_id: &str) -> String {
    within_run(run_id, "*/*/status")
}

/// The key of an awaited message: `glissade/<run>/<role>/<id>/<field>[/<to>]`.
pub fn awaited(run_id: &str, a: &Awaited) -> String {
    let base = sender_field_topic(run_id, a.from, &a.field);
    match a.to {
        Some(d) => format!("{base}/{d}"),
        None => base,
    }
}

/// Liveliness token of a node (the launcher's is role `launcher`, index 0):
/// `glissade/<run>/alive/<role>/<index>`.
pub fn alive(run_id: &str, role: &str, index: u32) -> String {
    within_run(run_id, format_args!("alive/{role}/{index}"))
}

/// Every liveliness token of a run's nodes and launcher.
pub fn alive_all(run_id: &str) -> String {
    within_run(run_id, "alive/**")
}

/// `role:index` of a liveliness key (`glissade/<run>/alive/<role>/<index>`).
pub fn node_of_alive(key: &str) -> String {
    let mut chunks = key.rsplit('/');
    match (chunks.next(), chunks.next()) {
        (Some(index), Some(role)) => format!("{role}:{index}"),
        _ => key.to_string(),
    }
}

/// Liveliness token of the recorder process. Not under the nodes' `alive/**` ([`alive_all`]):
/// the recorder is an observer, and a recorder that dies must not stop the nodes.
pub fn recorder_alive(run_id: &str) -> String {
    within_run(run_id, "recording/alive")
}

/// Key of the recorder's log queryable of a run: the recorded messages whose key matches one of
/// the query's patterns, in recorded order.
pub fn log(run_id: &str) -> String {
    within_run(run_id, format_args!("{}/0/log", Role::Recorder.key()))
}

/// Does key `key` match the key expression `expr` (`*`: one chunk, `**`: any number of chunks)?
pub fn key_matches(expr: &str, key: &str) -> bool {
    fn rec(mut e: std::str::Split<'_, char>, mut k: std::str::Split<'_, char>) -> bool {
        loop {
            match (e.next(), k.clone().next()) {
                (None, None) => return true,
                (Some("**"), _) => {
                    // `**` takes no more chunks, or one more and stays.
                    loop {
                        if rec(e.clone(), k.clone()) {
                            return true;
                        }
                        if k.next().is_none() {
                            return false;
                        }
                    }
                }
                (Some("*"), Some(_)) => {
                    k.next();
                }
                (Some(a), Some(b)) if a == b => {
                    k.next();
                }
                _ => return false,
            }
        }
    }
    rec(expr.split('/'), key.split('/'))
}

/// Which of a fixed list of subscribers (each a list of key expressions) a key reaches,
/// remembered per key: a run's messages use the same few keys every iteration, so each key is
/// matched once rather than once per message (with a thousand subscribers, matching every
/// message against every subscription was most of an iteration). A new key is matched only
/// against the expressions whose last chunk is that key's last chunk or a wildcard (a thousand
/// subdomains' keys against a thousand nodes' expressions, one by one, took seconds of set-up).
#[derive(Debug, Clone)]
pub struct Routes {
    subscriptions: Vec<Vec<String>>,
    /// (subscriber, expression) of every expression ending in a literal chunk, by that chunk.
    by_last: std::collections::HashMap<String, Vec<(usize, usize)>>,
    /// (subscriber, expression) of every expression ending in `*` or `**`.
    wild: Vec<(usize, usize)>,
    known: std::collections::HashMap<String, Vec<usize>>,
}

impl Routes {
    /// Keys remembered at most; past it a key is matched each time (keys come from the run's
    /// nodes, but a key expression with `**` may let a foreign key in).
    const MAX_KEYS: usize = 1 << 18;

    pub fn new(subscriptions: Vec<Vec<String>>) -> Self {
        let mut by_last: std::collections::HashMap<String, Vec<(usize, usize)>> = std::collections::HashMap::new();
        let mut wild = Vec::new();
        for (j, subs) in subscriptions.iter().enumerate() {
            for (e, expr) in subs.iter().enumerate() {
                match expr.rsplit('/').next() {
                    Some(last) if last != "*" && last != "**" => {
                        by_last.entry(last.to_string()).or_default().push((j, e))
                    }
                    _ => wild.push((j, e)),
                }
            }
        }
        Self {
            subscriptions,
            by_last,
            wild,
            known: std::collections::HashMap::new(),
        }
    }

    /// The subscribers `key` reaches, in order.
    fn match_key(&self, key: &str, into: &mut Vec<usize>) {
        into.clear();
        let last = key.rsplit('/').next().unwrap_or(key);
        let candidates = self
            .by_last
            .get(last)
            .map_or(&[][..], Vec::as_slice)
            .iter()
            .chain(&self.wild);
        into.extend(
            candidates
                .filter(|&&(j, e)| key_matches(&self.subscriptions[j][e], key))
                .map(|&(j, _)| j),
        );
        into.sort_unstable();
        into.dedup();
    }

    /// For each subscriber, the positions in `keys` of the keys it receives, in order.
    pub fn deliveries<'a>(&mut self, keys: impl IntoIterator<Item = &'a str>) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); self.subscriptions.len()];
        let mut scratch = Vec::new();
        for (k, key) in keys.into_iter().enumerate() {
            let to: &[usize] = if let Some(to) = self.known.get(key) {
                to
            } else {
                self.match_key(key, &mut scratch);
                if self.known.len() < Self::MAX_KEYS {
                    self.known.insert(key.to_string(), scratch.clone());
                }
                &scratch
            };
            for &j in to {
                out[j].push(k);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixtures::msg;

    #[test]
    fn message_topics_and_matching() {
        let m = msg();
        assert_eq!(m.topic(), "glissade/r1/subdomain/2/boundary_state");
        assert!(key_matches(
            &role_field_topic("r1", Role::Subdomain, "boundary_state", None),
            &m.topic()
        ));
        assert!(key_matches(&run_topics("r1"), &m.topic()));
        assert!(!key_matches(&run_topics("r2"), &m.topic()));
        assert!(key_matches(
            "glissade/r1/*/*/local_directions/4",
            "glissade/r1/interface/0/local_directions/4"
        ));
        assert!(!key_matches(
            "glissade/r1/*/*/local_directions/4",
            "glissade/r1/interface/0/local_directions/40"
        ));
        for (expr, key, expected) in [
            ("a/**", "a", true),
            ("a/**", "a/b/c", true),
            ("a/**/c", "a/c", true),
            ("a/**/c", "a/b/b/c", true),
            ("a/**/c", "a/b/b/d", false),
            ("**", "x/y", true),
            ("a/*", "a", false),
            ("a/*", "a/b/c", false),
            ("a/*/c", "a/b/c", true),
            ("a/b", "a/b/c", false),
            ("a/b/c", "a/b", false),
            ("*/**/z", "y/z", true),
            ("*/**/z", "z", false),
        ] {
            assert_eq!(key_matches(expr, key), expected, "{expr} ~ {key}");
        }
    }

    #[test]
    fn routes_deliver_each_key_to_its_subscribers_in_order() {
        let mut routes = Routes::new(vec![
            vec!["r/a/*".into()],
            vec!["r/**".into()],
            vec!["r/b/1".into(), "r/a/2".into()],
            vec![],
        ]);
        let keys = ["r/a/1", "r/b/1", "r/a/2", "r/a/1", "s/a/1"];
        let expected = vec![vec![0, 2, 3], vec![0, 1, 2, 3], vec![1, 2], vec![]];
        assert_eq!(routes.deliveries(keys), expected);
        // Two expressions of one subscriber matching one key deliver it once; an expression
        // ending in a literal chunk is found by it.
        let mut twice = Routes::new(vec![vec!["x/*/c".into(), "x/b/*".into()], vec!["x/**/c".into()]]);
        assert_eq!(
            twice.deliveries(["x/b/c", "x/b/d", "x/c"]),
            vec![vec![0, 1], vec![0, 2]]
        );
        // The second time from what it remembers: the same answer.
        assert_eq!(routes.deliveries(keys), expected);
    }

    /// The wire format of every key of a run, as the processes of other builds expect it.
    #[test]
    fn every_key_of_a_run() {
        let sender = NodeId {
            role: Role::Interface,
            index: 1,
        };
        let directions = Payload::LocalDirections {
            subdomain: 4,
            interfaces: vec![],
            q_hat: crate::Field::zeros(0, 0),
        };
        assert_eq!(
            topic("r", sender, &directions),
            "glissade/r/interface/1/local_directions/4"
        );
        assert_eq!(
            role_field_topic("r", Role::Coarse, "macro_displacements", Some(3)),
            "glissade/r/coarse/*/macro_displacements/3"
        );
        assert_eq!(
            role_field_topic("r", Role::Interface, "decision", None),
            "glissade/r/interface/*/decision"
        );
        assert_eq!(
            topic_field("glissade/r/interface/1/local_directions/4"),
            Some("local_directions")
        );
        assert_eq!(topic_field("glissade/r/interface/1"), None);
        assert_eq!(run_topics("r"), "glissade/r/**");
        assert_eq!(
            within_run("r", "subdomain/*/boundary_state"),
            "glissade/r/subdomain/*/boundary_state"
        );
        assert_eq!(sent_by("r", sender), "glissade/r/interface/1/**");
        assert_eq!(scene("r"), "glissade/r/launcher/0/scene");
        assert_eq!(start("r"), "glissade/r/launcher/0/start");
        assert_eq!(stop("r"), "glissade/r/launcher/0/stop");
        assert_eq!(done("r"), "glissade/r/launcher/0/done");
        assert_eq!(end("r"), "glissade/r/launcher/0/end");
        assert_eq!(alive("r", "subdomain", 2), "glissade/r/alive/subdomain/2");
        assert_eq!(alive_all("r"), "glissade/r/alive/**");
        assert!(key_matches(&alive_all("r"), &alive("r", "launcher", 0)));
        assert!(!key_matches(&alive_all("r"), &recorder_alive("r")));
        assert_eq!(node_of_alive(&alive("r", "subdomain", 2)), "subdomain:2");
        assert_eq!(node_of_alive("x"), "x");
        assert_eq!(recorder_alive("r"), "glissade/r/recording/alive");
        assert_eq!(log("r"), "glissade/r/recorder/0/log");
        let recorder = NodeId {
            role: Role::Recorder,
            index: 0,
        };
        assert!(own_keys("r", recorder).iter().any(|k| key_matches(k, &log("r"))));
        assert!(own_keys("r", recorder).contains(&recorder_alive("r")));
        let sub = NodeId {
            role: Role::Subdomain,
            index: 2,
        };
        assert_eq!(
            own_keys("r", sub),
            ["glissade/r/subdomain/2/**", "glissade/r/alive/subdomain/2"]
        );
    }
}
