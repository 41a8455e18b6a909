//! A message as protobuf bytes of its `glissade.<Payload>` message (field numbers of
//! `super::schema`): written straight into one buffer, a field's values as one block of
//! little-endian f64 (a packed `repeated double`). Every scalar is written, zeros included, so that
//! the bytes carry the value exactly (−0.0 too); a `None` is an absent field.

use glissade_messages::{
    Awaited, Decision, Envelope, Field, InterfaceIndicators, Message, MessageSeen, NodeId, Payload, RecordOverride,
    Role, Stage, Verdict,
};
use prost::encoding::{encode_varint, encoded_len_varint};

const VARINT: u64 = 0;
const I64: u64 = 1;
const LEN: u64 = 2;

fn key(out: &mut Vec<u8>, number: u32, wire: u64) {
    encode_varint(((number as u64) << 3) | wire, out);
}

fn key_len(number: u32) -> usize {
    encoded_len_varint((number as u64) << 3)
}

fn uint(out: &mut Vec<u8>, number: u32, v: u64) {
    key(out, number, VARINT);
    encode_varint(v, out);
}

fn double(out: &mut Vec<u8>, number: u32, v: f64) {
    key(out, number, I64);
    out.extend_from_slice(&v.to_le_bytes());
}

fn fixed64(out: &mut Vec<u8>, number: u32, v: u64) {
    key(out, number, I64);
    out.extend_from_slice(&v.to_le_bytes());
}

fn bytes(out: &mut Vec<u8>, number: u32, b: &[u8]) {
    key(out, number, LEN);
    encode_varint(b.len() as u64, out);
    out.extend_from_slice(b);
}

/// A packed `repeated double` (nothing when empty).
fn doubles(out: &mut Vec<u8>, number: u32, v: &[f64]) {
    if v.is_empty() {
        return;
    }
    key(out, number, LEN);
    encode_varint(8 * v.len() as u64, out);
    if cfg!(target_endian = "little") {
        out.extend_from_slice(bytemuck::cast_slice(v));
    } else {
        v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
    }
}

/// A packed repeated varint (uint32, enum), nothing when empty.
fn varints(out: &mut Vec<u8>, number: u32, v: impl Iterator<Item = u64> + Clone) {
    let len: usize = v.clone().map(encoded_len_varint).sum();
    if len == 0 {
        return;
    }
    key(out, number, LEN);
    encode_varint(len as u64, out);
    v.for_each(|x| encode_varint(x, out));
}

/// A small embedded message, written into a buffer of its own first.
fn small(out: &mut Vec<u8>, number: u32, body: impl FnOnce(&mut Vec<u8>)) {
    let mut b = Vec::with_capacity(64);
    body(&mut b);
    bytes(out, number, &b);
}

/// Bytes of a `Field` message's body.
fn field_body_len(f: &Field) -> usize {
    let values = if f.data.is_empty() {
        0
    } else {
        key_len(3) + encoded_len_varint(8 * f.data.len() as u64) + 8 * f.data.len()
    };
    key_len(1) + encoded_len_varint(f.rows as u64) + key_len(2) + encoded_len_varint(f.cols as u64) + values
}

/// Bytes of an embedded `Field` with its key and length.
fn field_len(number: u32, f: &Field) -> usize {
    let body = field_body_len(f);
    key_len(number) + encoded_len_varint(body as u64) + body
}

/// An embedded `Field` (its length computed, not buffered: the values are copied once).
fn field(out: &mut Vec<u8>, number: u32, f: &Field) {
    key(out, number, LEN);
    encode_varint(field_body_len(f) as u64, out);
    uint(out, 1, f.rows as u64);
    uint(out, 2, f.cols as u64);
    doubles(out, 3, &f.data);
}

fn stage(s: Stage) -> u64 {
    match s {
        Stage::Setup => 0,
        Stage::Micro1 => 1,
        Stage::Macro => 2,
        Stage::Linear => 3,
        Stage::Local => 4,
        Stage::Final => 5,
    }
}

fn role(r: Role) -> u64 {
    match r {
        Role::Subdomain => 0,
        Role::Interface => 1,
        Role::Coarse => 2,
        Role::Launcher => 3,
        Role::Recorder => 4,
    }
}

/// (`Verdict` enum value, `verdict_detail`).
fn verdict(v: &Verdict) -> (u64, &str) {
    match v {
        Verdict::Continue => (0, ""),
        Verdict::Converged => (1, ""),
        Verdict::MaxIterations => (2, ""),
        Verdict::Stagnated { detail } => (3, detail),
        Verdict::Diverged { detail } => (4, detail),
        Verdict::NoEquilibrium { detail } => (5, detail),
    }
}

fn envelope(out: &mut Vec<u8>, e: &Envelope) {
    small(out, 1, |b| {
        uint(b, 1, e.schema_version as u64);
        bytes(b, 2, e.run_id.as_bytes());
        fixed64(b, 3, e.scene_fingerprint);
        uint(b, 4, e.iteration as u64);
        uint(b, 5, stage(e.stage));
        node_id(b, 6, e.sender);
    });
}

fn node_id(out: &mut Vec<u8>, number: u32, id: NodeId) {
    small(out, number, |n| {
        uint(n, 1, role(id.role));
        uint(n, 2, id.index as u64);
    });
}

fn awaited(out: &mut Vec<u8>, number: u32, a: &Awaited) {
    small(out, number, |b| {
        node_id(b, 1, a.from);
        bytes(b, 2, a.field.as_bytes());
        uint(b, 3, a.iteration as u64);
        if let Some(to) = a.to {
            uint(b, 4, to as u64);
        }
    });
}

fn seen(out: &mut Vec<u8>, number: u32, s: &MessageSeen) {
    small(out, number, |b| {
        bytes(b, 1, s.key.as_bytes());
        uint(b, 2, s.iteration as u64);
        uint(b, 3, s.ms_ago);
    });
}

fn decision(out: &mut Vec<u8>, d: &Decision) {
    double(out, 2, d.eta);
    double(out, 3, d.contact_indicator);
    double(out, 4, d.force_error);
    double(out, 5, d.jump_error);
    for (k, c) in d.counts.iter().enumerate() {
        uint(out, 6 + k as u32, *c);
    }
    uint(out, 9, d.status_changes);
    varints(out, 10, d.direction_updates.iter().map(|&i| i as u64));
    double(out, 11, d.force_step);
    if let Some(e) = d.estimate {
        double(out, 12, e);
    }
    if let Some(c) = d.contraction {
        double(out, 13, c);
    }
    let (v, detail) = verdict(&d.verdict);
    uint(out, 14, v);
    bytes(out, 15, detail.as_bytes());
    double(out, 16, d.pointwise_step);
    if let Some(e) = d.pointwise_estimate {
        double(out, 17, e);
    }
}

fn indicators(out: &mut Vec<u8>, i: &InterfaceIndicators) {
    uint(out, 1, i.interface as u64);
    for (n, v) in [i.eta_num, i.eta_den, i.force_num, i.force_den, i.jump_num, i.jump_den]
        .into_iter()
        .enumerate()
    {
        double(out, 2 + n as u32, v);
    }
    for (k, c) in i.counts.iter().enumerate() {
        uint(out, 8 + k as u32, *c);
    }
    uint(out, 11, i.status_changes);
    uint(out, 12, i.direction_updated as u64);
    double(out, 13, i.step_num);
    double(out, 14, i.step_den);
    double(out, 15, i.step_max);
    double(out, 16, i.force_max);
    if let Some(t) = i.sliding_from {
        uint(out, 17, t as u64);
    }
    uint(out, 18, i.sliding_sides[0] as u64);
    uint(out, 19, i.sliding_sides[1] as u64);
}

/// Bytes of the message's fields beyond the envelope, to size the buffer once.
fn fields_len(p: &Payload) -> usize {
    let mut n = 0;
    p.fields(|f| n += field_len(15, f));
    n
}

/// Appends the protobuf bytes of `m` (message [`super::message_name`] of its payload) to `out`.
pub fn encode_into(m: &Message, out: &mut Vec<u8>) {
    out.reserve(fields_len(&m.payload) + 256);
    envelope(out, &m.envelope);
    match &m.payload {
        Payload::Scene { text, overrides } => {
            bytes(out, 2, text.as_bytes());
            if let Some(a) = overrides.accuracy {
                double(out, 3, a);
            }
            if let Some(t) = overrides.tolerance {
                double(out, 4, t);
            }
            if let Some(m) = overrides.max_iterations {
                uint(out, 5, m as u64);
            }
            if let Some(r) = overrides.record {
                uint(
                    out,
                    6,
                    match r {
                        RecordOverride::Off => 0,
                        RecordOverride::Full => 1,
                    },
                );
            }
        }
        Payload::HomogenizedOperator { subdomain, slots, l_e } => {
            uint(out, 2, *subdomain as u64);
            for (interface, modes) in slots {
                small(out, 3, |b| {
                    uint(b, 1, *interface as u64);
                    uint(b, 2, *modes as u64);
                });
            }
            field(out, 4, l_e);
        }
        Payload::MacroForces { subdomain, forces } => {
            uint(out, 2, *subdomain as u64);
            field(out, 3, forces);
        }
        Payload::MacroDisplacements { subdomain, w_tilde } => {
            uint(out, 2, *subdomain as u64);
            field(out, 3, w_tilde);
        }
        Payload::BoundaryState {
            subdomain,
            to,
            interfaces,
            w,
            f,
        } => {
            uint(out, 2, *subdomain as u64);
            field(out, 3, w);
            field(out, 4, f);
            varints(out, 5, interfaces.iter().map(|&i| i as u64));
            if let Some(k) = to {
                uint(out, 6, *k as u64);
            }
        }
        Payload::BoundaryModes {
            subdomain,
            particular,
            first_mode,
            z,
            g,
            lambda,
        } => {
            uint(out, 2, *subdomain as u64);
            if let Some(p) = particular {
                key(out, 3, LEN);
                let len = field_len(1, &p.w) + field_len(2, &p.f) + field_len(3, &p.time);
                encode_varint(len as u64, out);
                field(out, 1, &p.w);
                field(out, 2, &p.f);
                field(out, 3, &p.time);
            }
            uint(out, 4, *first_mode as u64);
            field(out, 5, z);
            field(out, 6, g);
            field(out, 7, lambda);
        }
        Payload::LocalDirections {
            subdomain,
            interfaces,
            q_hat,
        } => {
            uint(out, 2, *subdomain as u64);
            varints(out, 3, interfaces.iter().map(|&i| i as u64));
            field(out, 4, q_hat);
        }
        Payload::AndersonGram {
            subdomain,
            gram,
            projection,
            residual2,
        } => {
            uint(out, 2, *subdomain as u64);
            field(out, 3, gram);
            field(out, 4, projection);
            double(out, 5, *residual2);
        }
        Payload::AndersonStep { gamma, restart } => {
            doubles(out, 2, gamma);
            uint(out, 3, *restart as u64);
        }
        Payload::Decision(d) => decision(out, d),
        Payload::InterfaceSolution(s) => {
            uint(out, 2, s.interface as u64);
            for (n, f) in [
                &s.w_a, &s.w_b, &s.f_a, &s.f_b, &s.w_a_hat, &s.w_b_hat, &s.f_a_hat, &s.f_b_hat,
            ]
            .into_iter()
            .enumerate()
            {
                field(out, 3 + n as u32, f);
            }
            varints(out, 11, s.status.iter().map(|&c| c as u64));
        }
        Payload::Displacement { subdomain, u } => {
            uint(out, 2, *subdomain as u64);
            field(out, 3, u);
        }
        Payload::IndicatorPartials { interfaces, diverged } => {
            for i in interfaces {
                small(out, 2, |b| indicators(b, i));
            }
            if let Some(d) = diverged {
                bytes(out, 3, d.as_bytes());
            }
        }
        Payload::LinearStageStats(st) => {
            uint(out, 2, st.subdomain as u64);
            uint(out, 3, st.flops);
            uint(out, 4, st.modes as u64);
            uint(out, 5, st.new_modes as u64);
            uint(out, 6, st.dropped_modes as u64);
            double(out, 7, st.xi1);
            double(out, 8, st.xi2);
        }
        Payload::NodeStatus(st) => {
            uint(out, 2, st.round);
            uint(out, 3, st.finished as u64);
            st.awaits.iter().for_each(|a| awaited(out, 4, a));
            if let Some(b) = st.busy_ms {
                uint(out, 5, b);
            }
            uint(out, 6, st.handled);
            if let Some(h) = &st.last_handled {
                seen(out, 7, h);
            }
            st.sent.iter().for_each(|s| seen(out, 8, s));
        }
        Payload::Stall(r) => {
            uint(out, 2, r.silent_ms);
            for m in &r.missing {
                small(out, 3, |b| {
                    node_id(b, 1, m.waiter);
                    awaited(b, 2, &m.awaited);
                    uint(b, 3, m.sent as u64);
                });
            }
            r.republished.iter().for_each(|k| bytes(out, 4, k.as_bytes()));
            uint(out, 5, r.ended as u64);
            bytes(out, 6, r.diagnosis.as_bytes());
        }
    }
}
