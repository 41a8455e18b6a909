//! The protobuf description of glissade's messages (`glissade.proto`, package `glissade`, proto3):
//! one table, from which come both the `google.protobuf.FileDescriptorSet` every schema of an
//! export carries and the `.proto` text attached to it. The encoder (`super::encode`) writes the
//! field numbers of this table; the module's tests decode its bytes with the descriptor.

use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{
    DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto, FileDescriptorProto,
    FileDescriptorSet, OneofDescriptorProto,
};

/// Name of the file descriptor (and of the attachment holding its `.proto` text).
pub const PROTO_FILE: &str = "glissade.proto";
/// Protobuf package of every message and enum.
pub const PACKAGE: &str = "glissade";

/// Type of a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    Double,
    Uint32,
    Uint64,
    Fixed64,
    Bool,
    String,
    /// A message of this package.
    Message(&'static str),
    /// An enum of this package.
    Enum(&'static str),
}

/// How often a field occurs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Card {
    /// Exactly one (messages: at most one, absent when the Rust value is `None`).
    One,
    /// proto3 `optional`: present or not (a Rust `Option` of a scalar).
    Optional,
    /// `repeated` (packed for numbers and enums).
    Repeated,
}

/// One field of a message.
#[derive(Debug, Clone, Copy)]
pub struct FieldDef {
    pub name: &'static str,
    pub number: i32,
    pub ty: Ty,
    pub card: Card,
    pub doc: &'static str,
}

/// One message.
#[derive(Debug, Clone, Copy)]
pub struct MessageDef {
    pub name: &'static str,
    pub doc: &'static str,
    pub fields: &'static [FieldDef],
}

/// One enum: its values in number order from 0.
#[derive(Debug, Clone, Copy)]
pub struct EnumDef {
    pub name: &'static str,
    pub doc: &'static str,
    pub values: &'static [(&'static str, &'static str)],
}

const fn f(name: &'static str, number: i32, ty: Ty, doc: &'static str) -> FieldDef {
    FieldDef {
        name,
        number,
        ty,
        card: Card::One,
        doc,
    }
}

const fn opt(name: &'static str, number: i32, ty: Ty, doc: &'static str) -> FieldDef {
    FieldDef {
        card: Card::Optional,
        ..f(name, number, ty, doc)
    }
}

const fn rep(name: &'static str, number: i32, ty: Ty, doc: &'static str) -> FieldDef {
    FieldDef {
        card: Card::Repeated,
        ..f(name, number, ty, doc)
    }
}

const ENVELOPE: FieldDef = f(
    "envelope",
    1,
    Ty::Message("Envelope"),
    "who sent the message, in which run, iteration and stage",
);
const FIELD: Ty = Ty::Message("Field");
const SUBDOMAIN: &str = "subdomain index";

pub const ENUMS: &[EnumDef] = &[
    EnumDef {
        name: "Stage",
        doc: "Stage of the LATIN iteration a message belongs to.",
        values: &[
            ("STAGE_SETUP", "before the first iteration"),
            ("STAGE_MICRO1", "micro problem 1 and its macro forces"),
            ("STAGE_MACRO", "the macro problem's solution"),
            ("STAGE_LINEAR", "end of a linear stage: the new s"),
            ("STAGE_LOCAL", "local stage results and the stop decision"),
            ("STAGE_FINAL", "final output after the stop decision"),
        ],
    },
    EnumDef {
        name: "Role",
        doc: "Role of a node on the bus.",
        values: &[
            ("ROLE_SUBDOMAIN", ""),
            ("ROLE_INTERFACE", ""),
            ("ROLE_COARSE", ""),
            ("ROLE_LAUNCHER", ""),
            ("ROLE_RECORDER", ""),
        ],
    },
    EnumDef {
        name: "Verdict",
        doc: "How a run ended, or that it goes on.",
        values: &[
            ("VERDICT_CONTINUE", "the run goes on"),
            (
                "VERDICT_CONVERGED",
                "the estimated contact-traction errors (relative L2, and the largest at one point) reached the requested accuracy",
            ),
            ("VERDICT_MAX_ITERATIONS", "the iteration cap was reached"),
            ("VERDICT_STAGNATED", "eta stopped decreasing (verdict_detail says more)"),
            (
                "VERDICT_DIVERGED",
                "eta grew without bound or a value became NaN/Inf (verdict_detail says where)",
            ),
            (
                "VERDICT_NO_EQUILIBRIUM",
                "the loads exceed what friction and the supports hold at some time points (verdict_detail names the interfaces, parts and first time point)",
            ),
        ],
    },
    EnumDef {
        name: "Record",
        doc: "What the command line asked of a run's recording.",
        values: &[
            ("RECORD_OFF", "no recording ([recording] enabled = false)"),
            ("RECORD_FULL", "every message, full fields at every iteration"),
        ],
    },
    EnumDef {
        name: "ContactStatus",
        doc: "Contact status of an interface node pair at a time point.",
        values: &[
            ("CONTACT_SEPARATED", "open gap, no traction"),
            ("CONTACT_STICK", "closed, tangential jump rate zero"),
            ("CONTACT_SLIP", "closed, sliding at the friction limit"),
        ],
    },
];

/// Every message: first one per payload type (`glissade.<Payload>`, the names of
/// [`crate::PAYLOAD_FIELDS`]), each with the `envelope` as field 1, then the messages they embed.
pub const MESSAGES: &[MessageDef] = &[
    MessageDef {
        name: "Scene",
        doc: "The scene file's text (TOML) as written, and the settings given on the command line that the run applied on top of it (each absent when not given).",
        fields: &[
            ENVELOPE,
            f("text", 2, Ty::String, ""),
            opt("accuracy", 3, Ty::Double, "[solver] accuracy (--accuracy)"),
            opt("tolerance", 4, Ty::Double, "[solver] tolerance (--tolerance)"),
            opt(
                "max_iterations",
                5,
                Ty::Uint64,
                "[solver] max_iterations (--max-iterations)",
            ),
            opt("record", 6, Ty::Enum("Record"), "the recording (--record, --no-record)"),
        ],
    },
    MessageDef {
        name: "HomogenizedOperator",
        doc: "L_E of a subdomain over its macro slots, sent once.",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            rep(
                "slots",
                3,
                Ty::Message("MacroSlot"),
                "the macro slots (interface, number of modes), in column order",
            ),
            f("l_e", 4, FIELD, "the homogenized operator L_E"),
        ],
    },
    MessageDef {
        name: "MacroForces",
        doc: "Macro forces after micro problem 1 (n_m x (N+1)).",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            f("forces", 3, FIELD, ""),
        ],
    },
    MessageDef {
        name: "MacroDisplacements",
        doc: "The macro displacements over a subdomain's macro columns (n_m x (N+1)).",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, "subdomain the message is addressed to"),
            f("w_tilde", 3, FIELD, ""),
        ],
    },
    MessageDef {
        name: "BoundaryState",
        doc: "s = (W, F) of a subdomain's boundary after a linear stage: the rows of the interfaces \
              listed, one after the other, x (N+1).",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            f("w", 3, FIELD, "boundary displacements W (mm)"),
            f("f", 4, FIELD, "boundary forces F"),
            rep(
                "interfaces",
                5,
                Ty::Uint32,
                "interfaces whose rows W and F hold, in the order of the subdomain's boundary layout",
            ),
            opt(
                "to",
                6,
                Ty::Uint32,
                "the interface node the rows are for, when the run has several (absent: the whole \
                 boundary, for the run's one interface node)",
            ),
        ],
    },
    MessageDef {
        name: "BoundaryModes",
        doc: "A subdomain's boundary state in PGD mode form: W = P_W phi + sum_k Z_k lambda_k, \
              F = P_F phi + sum_k G_k lambda_k; the receiver keeps its first `first_mode` modes and \
              replaces the rest by the columns of z and g.",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            f(
                "particular",
                3,
                Ty::Message("ParticularModes"),
                "the particular part (in the subdomain's first message only; absent otherwise)",
            ),
            f("first_mode", 4, Ty::Uint32, "modes of the basis kept"),
            f("z", 5, FIELD, "new displacement modes (n_b x new)"),
            f("g", 6, FIELD, "new force modes (n_b x new)"),
            f(
                "lambda",
                7,
                FIELD,
                "the state's time functions ((first_mode + new) x (N+1))",
            ),
        ],
    },
    MessageDef {
        name: "LocalDirections",
        doc: "q_hat = F_hat + k- W_hat on a subdomain's boundary, for the interfaces an interface node owns.",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, "subdomain the message is addressed to"),
            rep(
                "interfaces",
                3,
                Ty::Uint32,
                "interfaces covered, in the order of the subdomain's boundary layout",
            ),
            f("q_hat", 4, FIELD, "their rows one after the other"),
        ],
    },
    MessageDef {
        name: "AndersonGram",
        doc: "A subdomain's share of the Anderson least-squares problem (forces only).",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            f("gram", 3, FIELD, "dr_i . dr_j (k x k), oldest difference first"),
            f("projection", 4, FIELD, "dr_i . r (k x 1)"),
            f("residual2", 5, Ty::Double, "|r|^2"),
        ],
    },
    MessageDef {
        name: "AndersonStep",
        doc: "The mixing step every subdomain takes.",
        fields: &[
            ENVELOPE,
            rep(
                "gamma",
                2,
                Ty::Double,
                "coefficients (oldest difference first); empty for a plain relaxation step",
            ),
            f("restart", 3, Ty::Bool, "the subdomains forget their differences"),
        ],
    },
    MessageDef {
        name: "Decision",
        doc: "Indicators of one iteration and the stop decision.",
        fields: &[
            ENVELOPE,
            f("eta", 2, Ty::Double, "LATIN indicator eta"),
            f(
                "contact_indicator",
                3,
                Ty::Double,
                "contact indicator e_c = max(e_F, e_W)",
            ),
            f("force_error", 4, Ty::Double, "e_F"),
            f("jump_error", 5, Ty::Double, "e_W"),
            f(
                "counts_separated",
                6,
                Ty::Uint64,
                "contact points (pair x time point) separated",
            ),
            f(
                "counts_stuck",
                7,
                Ty::Uint64,
                "contact points (pair x time point) stuck",
            ),
            f(
                "counts_slipping",
                8,
                Ty::Uint64,
                "contact points (pair x time point) slipping",
            ),
            f("status_changes", 9, Ty::Uint64, "contact points whose status changed"),
            rep(
                "direction_updates",
                10,
                Ty::Uint32,
                "contact interfaces whose search direction was updated",
            ),
            f(
                "force_step",
                11,
                Ty::Double,
                "relative step of the contact forces since the previous iteration",
            ),
            opt(
                "estimate",
                12,
                Ty::Double,
                "estimated relative contact-traction error; absent until the iteration shows a contraction",
            ),
            opt(
                "contraction",
                13,
                Ty::Double,
                "the contraction the estimate used; absent likewise",
            ),
            f("verdict", 14, Ty::Enum("Verdict"), ""),
            f(
                "verdict_detail",
                15,
                Ty::String,
                "what stagnated or diverged (empty for the other verdicts)",
            ),
            f(
                "pointwise_step",
                16,
                Ty::Double,
                "largest step of a contact traction at one point and time point since the previous \
                 iteration, relative to the largest contact traction",
            ),
            opt(
                "pointwise_estimate",
                17,
                Ty::Double,
                "estimated largest contact-traction error at one point and time point, relative to the \
                 largest contact traction; absent until the iteration shows a contraction",
            ),
        ],
    },
    MessageDef {
        name: "InterfaceSolution",
        doc: "One interface's fields at the end of a run: s (last linear stage) and s_hat (last local \
              stage), n_pairs x (N+1) each, and the contact status per (pair, time point).",
        fields: &[
            ENVELOPE,
            f("interface", 2, Ty::Uint32, "interface index"),
            f("w_a", 3, FIELD, ""),
            f("w_b", 4, FIELD, ""),
            f("f_a", 5, FIELD, ""),
            f("f_b", 6, FIELD, ""),
            f("w_a_hat", 7, FIELD, ""),
            f("w_b_hat", 8, FIELD, ""),
            f("f_a_hat", 9, FIELD, ""),
            f("f_b_hat", 10, FIELD, ""),
            rep(
                "status",
                11,
                Ty::Enum("ContactStatus"),
                "at index p + n_pairs * i for pair p and time point i",
            ),
        ],
    },
    MessageDef {
        name: "Displacement",
        doc: "Full displacement field of a subdomain (n_dofs x (N+1)), on request at the end.",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            f("u", 3, FIELD, "displacements (mm)"),
        ],
    },
    MessageDef {
        name: "IndicatorPartials",
        doc: "An interface node's share of an iteration's indicators, sent to the deciding interface node.",
        fields: &[
            ENVELOPE,
            rep(
                "interfaces",
                2,
                Ty::Message("InterfaceIndicators"),
                "one per interface the node owns, in interface order",
            ),
            opt(
                "diverged",
                3,
                Ty::String,
                "why the iteration diverged (a non-finite value received); absent otherwise",
            ),
        ],
    },
    MessageDef {
        name: "LinearStageStats",
        doc: "What a subdomain's linear stage of the envelope's iteration did, counted by the subdomain \
              (no time: a bus times the handling of its inputs).",
        fields: &[
            ENVELOPE,
            f("subdomain", 2, Ty::Uint32, SUBDOMAIN),
            f(
                "flops",
                3,
                Ty::Uint64,
                "floating-point operations of the stage, as its kernels count them",
            ),
            f(
                "modes",
                4,
                Ty::Uint32,
                "PGD basis size after the stage, frozen macro modes included (0 without PGD)",
            ),
            f(
                "new_modes",
                5,
                Ty::Uint32,
                "PGD modes added in the stage (micro 1 + micro 2)",
            ),
            f(
                "dropped_modes",
                6,
                Ty::Uint32,
                "PGD modes dropped by the stage's compression",
            ),
            f(
                "xi1",
                7,
                Ty::Double,
                "PGD criterion xi at the end of micro problem 1 (0 without PGD)",
            ),
            f(
                "xi2",
                8,
                Ty::Double,
                "PGD criterion xi at the end of micro problem 2 (0 without PGD)",
            ),
        ],
    },
    MessageDef {
        name: "NodeStatus",
        doc: "A node's status, sent when the launcher asks (a run that stopped moving).",
        fields: &[
            ENVELOPE,
            f("round", 2, Ty::Uint64, "the launcher's request this answers"),
            f("finished", 3, Ty::Bool, ""),
            rep(
                "awaits",
                4,
                Ty::Message("Awaited"),
                "the messages the node waits for (any one moves it on)",
            ),
            opt(
                "busy_ms",
                5,
                Ty::Uint64,
                "the node's process handles messages since this many ms; absent when it waits",
            ),
            f("handled", 6, Ty::Uint64, "messages the node's process handled so far"),
            f("last_handled", 7, Ty::Message("MessageSeen"), "absent before the first"),
            rep(
                "sent",
                8,
                Ty::Message("MessageSeen"),
                "the node's last message on each key it published on",
            ),
        ],
    },
    MessageDef {
        name: "Stall",
        doc: "The launcher's diagnosis of a run that stopped moving.",
        fields: &[
            ENVELOPE,
            f("silent_ms", 2, Ty::Uint64, "how long no message of the run moved"),
            rep("missing", 3, Ty::Message("Missing"), "the messages nodes waited for"),
            rep(
                "republished",
                4,
                Ty::String,
                "keys of the messages whose senders were asked to publish them again",
            ),
            f("ended", 5, Ty::Bool, "the launcher ended the run"),
            f("diagnosis", 6, Ty::String, "in words"),
        ],
    },
    MessageDef {
        name: "Envelope",
        doc: "Header of every message.",
        fields: &[
            f("schema_version", 1, Ty::Uint32, "glissade wire schema version"),
            f("run_id", 2, Ty::String, ""),
            f("scene_fingerprint", 3, Ty::Fixed64, "fingerprint of the scene"),
            f("iteration", 4, Ty::Uint32, "LATIN iteration"),
            f("stage", 5, Ty::Enum("Stage"), ""),
            f("sender", 6, Ty::Message("NodeId"), ""),
        ],
    },
    MessageDef {
        name: "NodeId",
        doc: "A node: its role and index (a subdomain index for subdomain messages).",
        fields: &[f("role", 1, Ty::Enum("Role"), ""), f("index", 2, Ty::Uint32, "")],
    },
    MessageDef {
        name: "Field",
        doc: "A dense matrix: one row per boundary entry (or macro unknown), one column per time point.",
        fields: &[
            f("rows", 1, Ty::Uint32, ""),
            f("cols", 2, Ty::Uint32, ""),
            rep(
                "values",
                3,
                Ty::Double,
                "column-major: row r, column c at values[c * rows + r]",
            ),
        ],
    },
    MessageDef {
        name: "MacroSlot",
        doc: "A macro slot of a subdomain: an interface and its number of macro modes.",
        fields: &[f("interface", 1, Ty::Uint32, ""), f("modes", 2, Ty::Uint32, "")],
    },
    MessageDef {
        name: "ParticularModes",
        doc: "The particular part of a state in mode form: W_d = w phi, -k- W_d = f phi.",
        fields: &[
            f("w", 1, FIELD, "n_b x n_c"),
            f("f", 2, FIELD, "n_b x n_c"),
            f("time", 3, FIELD, "phi, n_c x (N+1)"),
        ],
    },
    MessageDef {
        name: "Awaited",
        doc: "A message a node waits for: sender, kind (key field chunk), iteration, destination chunk.",
        fields: &[
            f("from", 1, Ty::Message("NodeId"), ""),
            f("field", 2, Ty::String, ""),
            f("iteration", 3, Ty::Uint32, ""),
            opt("to", 4, Ty::Uint32, "the key's destination chunk; absent when it has none"),
        ],
    },
    MessageDef {
        name: "MessageSeen",
        doc: "A message as a status names it.",
        fields: &[
            f("key", 1, Ty::String, ""),
            f("iteration", 2, Ty::Uint32, ""),
            f("ms_ago", 3, Ty::Uint64, "how long before the status it was handled or put"),
        ],
    },
    MessageDef {
        name: "Missing",
        doc: "A message a stalled run lacked.",
        fields: &[
            f("waiter", 1, Ty::Message("NodeId"), "the node that waited for it"),
            f("awaited", 2, Ty::Message("Awaited"), ""),
            f("sent", 3, Ty::Bool, "its sender had put it on the bus (it was lost on the way)"),
        ],
    },
    MessageDef {
        name: "InterfaceIndicators",
        doc: "One interface's indicator sums after a local stage.",
        fields: &[
            f("interface", 1, Ty::Uint32, ""),
            f("eta_num", 2, Ty::Double, ""),
            f("eta_den", 3, Ty::Double, ""),
            f("force_num", 4, Ty::Double, ""),
            f("force_den", 5, Ty::Double, ""),
            f("jump_num", 6, Ty::Double, ""),
            f("jump_den", 7, Ty::Double, ""),
            f("counts_separated", 8, Ty::Uint64, ""),
            f("counts_stuck", 9, Ty::Uint64, ""),
            f("counts_slipping", 10, Ty::Uint64, ""),
            f("status_changes", 11, Ty::Uint64, ""),
            f("direction_updated", 12, Ty::Bool, ""),
            f("step_num", 13, Ty::Double, ""),
            f("step_den", 14, Ty::Double, ""),
            f("step_max", 15, Ty::Double, ""),
            f("force_max", 16, Ty::Double, ""),
            opt(
                "sliding_from",
                17,
                Ty::Uint32,
                "the first time point beyond what friction holds, when the interface slides (no equilibrium there); \
                 absent if it does not",
            ),
            f("sliding_side_a", 18, Ty::Bool, "side a's forces showed it: its part would slide or turn away"),
            f("sliding_side_b", 19, Ty::Bool, "side b's forces showed it: its part would slide or turn away"),
        ],
    },
];

fn field_proto(d: &FieldDef, synthetic_oneof: Option<i32>) -> FieldDescriptorProto {
    let (ty, type_name) = match d.ty {
        Ty::Double => (Type::Double, None),
        Ty::Uint32 => (Type::Uint32, None),
        Ty::Uint64 => (Type::Uint64, None),
        Ty::Fixed64 => (Type::Fixed64, None),
        Ty::Bool => (Type::Bool, None),
        Ty::String => (Type::String, None),
        Ty::Message(m) => (Type::Message, Some(format!(".{PACKAGE}.{m}"))),
        Ty::Enum(e) => (Type::Enum, Some(format!(".{PACKAGE}.{e}"))),
    };
    FieldDescriptorProto {
        name: Some(d.name.to_string()),
        number: Some(d.number),
        label: Some(match d.card {
            Card::Repeated => Label::Repeated,
            _ => Label::Optional,
        } as i32),
        r#type: Some(ty as i32),
        type_name,
        json_name: Some(json_name(d.name)),
        oneof_index: synthetic_oneof,
        proto3_optional: synthetic_oneof.map(|_| true),
        ..Default::default()
    }
}

/// protoc's JSON name: lower camel case.
fn json_name(name: &str) -> String {
    let mut out = String::new();
    let mut upper = false;
    for c in name.chars() {
        if c == '_' {
            upper = true;
        } else if upper {
            out.extend(c.to_uppercase());
            upper = false;
        } else {
            out.push(c);
        }
    }
    out
}

fn message_proto(m: &MessageDef) -> DescriptorProto {
    let mut oneofs = Vec::new();
    let field = m
        .fields
        .iter()
        .map(|d| {
            // proto3 `optional`: a synthetic oneof `_<name>` of its own.
            let synthetic = (d.card == Card::Optional).then(|| {
                oneofs.push(OneofDescriptorProto {
                    name: Some(format!("_{}", d.name)),
                    options: None,
                });
                oneofs.len() as i32 - 1
            });
            field_proto(d, synthetic)
        })
        .collect();
    DescriptorProto {
        name: Some(m.name.to_string()),
        field,
        oneof_decl: oneofs,
        ..Default::default()
    }
}

/// `glissade.proto` as a file descriptor.
pub fn file_descriptor() -> FileDescriptorProto {
    FileDescriptorProto {
        name: Some(PROTO_FILE.to_string()),
        package: Some(PACKAGE.to_string()),
        message_type: MESSAGES.iter().map(message_proto).collect(),
        enum_type: ENUMS
            .iter()
            .map(|e| EnumDescriptorProto {
                name: Some(e.name.to_string()),
                value: e
                    .values
                    .iter()
                    .enumerate()
                    .map(|(i, (name, _))| EnumValueDescriptorProto {
                        name: Some(name.to_string()),
                        number: Some(i as i32),
                        options: None,
                    })
                    .collect(),
                ..Default::default()
            })
            .collect(),
        syntax: Some("proto3".to_string()),
        ..Default::default()
    }
}

/// The schema data of every channel of an export: the serialized `FileDescriptorSet` holding
/// `glissade.proto` (it depends on no other file).
pub fn file_descriptor_set_bytes() -> Vec<u8> {
    prost::Message::encode_to_vec(&FileDescriptorSet {
        file: vec![file_descriptor()],
    })
}

/// `glissade.proto` as text, with the documentation of every message, field and enum value.
pub fn proto_source() -> String {
    let mut s = format!(
        "// glissade's messages as protobuf: the encoding of `glissade export --foreign`.\n\
         // Every channel's schema is the message named by the schema (glissade.<Message>).\n\
         syntax = \"proto3\";\n\npackage {PACKAGE};\n"
    );
    let comment = |s: &mut String, indent: &str, doc: &str| {
        if !doc.is_empty() {
            s.push_str(&format!("{indent}// {doc}\n"));
        }
    };
    for e in ENUMS {
        s.push('\n');
        comment(&mut s, "", e.doc);
        s.push_str(&format!("enum {} {{\n", e.name));
        for (i, (name, doc)) in e.values.iter().enumerate() {
            comment(&mut s, "  ", doc);
            s.push_str(&format!("  {name} = {i};\n"));
        }
        s.push_str("}\n");
    }
    for m in MESSAGES {
        s.push('\n');
        comment(&mut s, "", m.doc);
        s.push_str(&format!("message {} {{\n", m.name));
        for d in m.fields {
            comment(&mut s, "  ", d.doc);
            let ty = match d.ty {
                Ty::Double => "double",
                Ty::Uint32 => "uint32",
                Ty::Uint64 => "uint64",
                Ty::Fixed64 => "fixed64",
                Ty::Bool => "bool",
                Ty::String => "string",
                Ty::Message(n) | Ty::Enum(n) => n,
            };
            let label = match d.card {
                Card::One => "",
                Card::Optional => "optional ",
                Card::Repeated => "repeated ",
            };
            s.push_str(&format!("  {label}{ty} {} = {};\n", d.name, d.number));
        }
        s.push_str("}\n");
    }
    s
}
