//! Schema records: one per payload type, a text description of the wire layout.

use glissade_messages::SCHEMA_VERSION;

/// (field chunk of the key expression, schema name `glissade.<Payload type>`, payload layout).
pub const PAYLOAD_FIELDS: [(&str, &str, &str); 16] = [
    (
        "scene",
        "glissade.Scene",
        "{ text: String, overrides: Overrides }\n\
         Overrides { accuracy: Option<f64>, tolerance: Option<f64>, max_iterations: Option<u64>, record: Option<RecordOverride> }\n\
         RecordOverride = enum { Off, Full } (u32 variant index); Option = u8 0 (None) or 1 then the value",
    ),
    (
        "homogenized_operator",
        "glissade.HomogenizedOperator",
        "{ subdomain: u32, slots: Vec<(u32, u32)>, l_e: Field }",
    ),
    (
        "macro_forces",
        "glissade.MacroForces",
        "{ subdomain: u32, forces: Field }",
    ),
    (
        "macro_displacements",
        "glissade.MacroDisplacements",
        "{ subdomain: u32, w_tilde: Field }",
    ),
    (
        "boundary_state",
        "glissade.BoundaryState",
        "{ subdomain: u32, w: Field, f: Field }",
    ),
    (
        "boundary_modes",
        "glissade.BoundaryModes",
        "{ subdomain: u32, particular: Option<ParticularModes { w: Field, f: Field, time: Field }>, first_mode: u32, \
         z: Field, g: Field, lambda: Field }",
    ),
    (
        "local_directions",
        "glissade.LocalDirections",
        "{ subdomain: u32, interfaces: Vec<u32>, q_hat: Field }",
    ),
    (
        "anderson_gram",
        "glissade.AndersonGram",
        "{ subdomain: u32, gram: Field, projection: Field, residual2: f64 }",
    ),
    (
        "anderson_step",
        "glissade.AndersonStep",
        "{ gamma: Vec<f64>, restart: bool }",
    ),
    (
        "decision",
        "glissade.Decision",
        "(Decision { eta: f64, contact_indicator: f64, force_error: f64, jump_error: f64, counts: [u64; 3], \
         status_changes: u64, direction_updates: Vec<u32>, force_step: f64, estimate: Option<f64>, \
         contraction: Option<f64>, pointwise_step: f64, pointwise_estimate: Option<f64>, verdict: Verdict })",
    ),
    (
        "interface_solution",
        "glissade.InterfaceSolution",
        "(InterfaceSolution { interface: u32, w_a: Field, w_b: Field, f_a: Field, f_b: Field, w_a_hat: Field, \
         w_b_hat: Field, f_a_hat: Field, f_b_hat: Field, status: Vec<u8> })",
    ),
    ("displacement", "glissade.Displacement", "{ subdomain: u32, u: Field }"),
    (
        "indicator_partials",
        "glissade.IndicatorPartials",
        "{ interfaces: Vec<InterfaceIndicators { interface: u32, eta_num: f64, eta_den: f64, force_num: f64, \
         force_den: f64, jump_num: f64, jump_den: f64, counts: [u64; 3], status_changes: u64, direction_updated: bool, step_num: f64, \
         step_den: f64, step_max: f64, force_max: f64, sliding_from: Option<u32>, sliding_sides: [bool; 2] }>, \
         diverged: Option<String> }",
    ),
    (
        "linear_stage_stats",
        "glissade.LinearStageStats",
        "(LinearStageStats { subdomain: u32, flops: u64, modes: u32, new_modes: u32, dropped_modes: u32, \
         xi1: f64, xi2: f64 })",
    ),
    (
        "status",
        "glissade.NodeStatus",
        "(NodeStatus { round: u64, finished: bool, awaits: Vec<Awaited { from: NodeId, field: String, \
         iteration: u32, to: Option<u32> }>, busy_ms: Option<u64>, handled: u64, last_handled: \
         Option<MessageSeen { key: String, iteration: u32, ms_ago: u64 }>, sent: Vec<MessageSeen> })",
    ),
    (
        "stall",
        "glissade.Stall",
        "(StallReport { silent_ms: u64, missing: Vec<Missing { waiter: NodeId, awaited: Awaited { from: NodeId, \
         field: String, iteration: u32, to: Option<u32> }, sent: bool }>, republished: Vec<String>, ended: bool, \
         diagnosis: String })",
    ),
];

/// Schema name (`glissade.<Payload>`) and schema text of the payload published on key-expression
/// field chunk `field`. A field this table does not describe (a payload type newer than it) gets
/// the schema `glissade.<field>` whose text names the wire schema version only.
pub fn payload_schema(field: &str) -> (String, String) {
    let header = format!(
        "glissade wire schema version {SCHEMA_VERSION}\n\
         encoding: serde + bincode 2 (standard config, little-endian, fixed-width integers)\n"
    );
    let Some((_, name, layout)) = PAYLOAD_FIELDS.iter().find(|(f, _, _)| *f == field) else {
        return (
            format!("glissade.{field}"),
            format!("{header}message = Envelope then the Payload variant published on field `{field}`\n"),
        );
    };
    let ty = name.trim_start_matches("glissade.");
    (
        name.to_string(),
        format!(
            "{header}message = Envelope then Payload::{ty}\n\
             Envelope {{ schema_version: u32, run_id: String, scene_fingerprint: u64, iteration: u32, stage: Stage, sender: NodeId }}\n\
             Stage = enum {{ Setup, Micro1, Macro, Linear, Local, Final }} (u32 variant index)\n\
             NodeId {{ role: Role, index: u32 }}; Role = enum {{ Subdomain, Interface, Coarse, Launcher, Recorder }}\n\
             Payload::{ty} {layout}\n\
             Field {{ rows: u32, cols: u32, data: Vec<f64> }} (column-major: one column per time point)\n\
             Verdict = enum {{ Continue, Converged, MaxIterations, Stagnated {{ detail: String }}, Diverged {{ detail: String }}, NoEquilibrium {{ detail: String }} }}\n"
        ),
    )
}
