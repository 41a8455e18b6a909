//! Wire types of glissade (DESIGN §4): every message is an [`Envelope`] plus a [`Payload`],
//! encoded with bincode 2 (its own Encode/Decode; the wire form is that of serde's derive
//! through bincode, which the decoder fuzz test checks). Key expressions come only from the
//! functions of this crate.
//!
//! Encoding: the envelope and the payload are encoded one after the other, so a decoder checks
//! the schema version, the run and the scene before it reads a payload whose layout may differ.

use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};

mod values;
pub use values::{BlockLender, HeldBlock, ValueBlock, Values};

/// Version of the wire schema; decoding rejects any other. Version 2: `LocalDirections` names the
/// interfaces it covers (several interface nodes), `IndicatorPartials` added. Version 3:
/// `BoundaryModes`, a PGD subdomain's state in mode form.
pub const SCHEMA_VERSION: u32 = 3;

/// Role of a node on the bus.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, bincode::Encode, bincode::Decode,
)]
pub enum Role {
    Subdomain,
    Interface,
    Coarse,
    Launcher,
    Recorder,
}

impl Role {
    /// The role's chunk in key expressions.
    pub fn key(self) -> &'static str {
        match self {
            Role::Subdomain => "subdomain",
            Role::Interface => "interface",
            Role::Coarse => "coarse",
            Role::Launcher => "launcher",
            Role::Recorder => "recorder",
        }
    }
}

/// Sender of a message: its role and index (a subdomain index for subdomain messages).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, bincode::Encode, bincode::Decode,
)]
pub struct NodeId {
    pub role: Role,
    pub index: u32,
}

impl std::fmt::Display for NodeId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.role.key(), self.index)
    }
}

/// Stage of the LATIN iteration a message belongs to.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, bincode::Encode, bincode::Decode,
)]
pub enum Stage {
    Setup,
    /// Micro problem 1 and its macro forces.
    Micro1,
    /// The macro problem's solution.
    Macro,
    /// End of a linear stage: the new s.
    Linear,
    /// Local stage results and the stop decision.
    Local,
    /// Final output after the stop decision.
    Final,
}

/// Header of every message.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct Envelope {
    pub schema_version: u32,
    pub run_id: String,
    pub scene_fingerprint: u64,
    pub iteration: u32,
    pub stage: Stage,
    pub sender: NodeId,
}

/// A dense column-major matrix: one row per boundary entry (or macro unknown), one column per
/// time point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Field {
    pub rows: u32,
    pub cols: u32,
    pub data: Values,
}

impl Field {
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows: rows as u32,
            cols: cols as u32,
            data: vec![0.0; rows * cols].into(),
        }
    }

    /// Builds a field from `f(row, col)`.
    pub fn from_fn(rows: usize, cols: usize, f: impl Fn(usize, usize) -> f64) -> Self {
        let mut data = Vec::with_capacity(rows * cols);
        for c in 0..cols {
            for r in 0..rows {
                data.push(f(r, c));
            }
        }
        Self {
            rows: rows as u32,
            cols: cols as u32,
            data: data.into(),
        }
    }

    #[inline]
    pub fn get(&self, r: usize, c: usize) -> f64 {
        self.data[c * self.rows as usize + r]
    }

    pub fn rows(&self) -> usize {
        self.rows as usize
    }

    pub fn cols(&self) -> usize {
        self.cols as usize
    }

    /// First (row, col, value) that is NaN or infinite.
    pub fn first_non_finite(&self) -> Option<(usize, usize, f64)> {
        let r = self.rows as usize;
        self.data
            .iter()
            .position(|v| !v.is_finite())
            .map(|k| (k % r.max(1), k / r.max(1), self.data[k]))
    }

    fn check(&self, what: &str) -> Result<(), DecodeError> {
        let expected = self.rows as u64 * self.cols as u64;
        if expected != self.data.len() as u64 {
            return Err(DecodeError::WrongSize {
                field: what.to_string(),
                rows: self.rows,
                cols: self.cols,
                len: self.data.len(),
            });
        }
        Ok(())
    }
}

/// Buffers of fields to hold new fields: a node's sent fields once delivered, or a receiver's
/// decoded fields once handled, so that multi-megabyte fields reuse memory instead of being
/// allocated (and their pages faulted in) at every iteration. At most [`BufferPool::CAPACITY`]
/// buffers are kept; a field takes the smallest one that fits and is at most twice its size (a
/// small field does not take a big field's buffer).
#[derive(Debug, Default)]
pub struct BufferPool {
    free: Vec<Vec<f64>>,
}

impl BufferPool {
    /// Most buffers kept (an interface node sends and receives one field per subdomain it serves).
    pub const CAPACITY: usize = 64;

    /// The pooled buffer for `len` values, if one fits.
    fn best(&mut self, len: usize) -> Option<Vec<f64>> {
        let i = self
            .free
            .iter()
            .enumerate()
            .filter(|(_, b)| (len..=2 * len).contains(&b.capacity()))
            .min_by_key(|(_, b)| b.capacity())
            .map(|(i, _)| i)?;
        Some(self.free.swap_remove(i))
    }

    /// An empty buffer with room for `len` values: pooled, or new.
    pub fn take_empty(&mut self, len: usize) -> Vec<f64> {
        match self.best(len) {
            Some(mut b) => {
                b.clear();
                b
            }
            None => Vec::with_capacity(len),
        }
    }

    /// A buffer of `len` values whatever they are, for a caller that overwrites them all: pooled
    /// (its old values, written only where it was shorter), or new (zeros).
    pub fn take_any(&mut self, len: usize) -> Vec<f64> {
        match self.best(len) {
            Some(mut b) => {
                b.truncate(len);
                b.resize(len, 0.0);
                b
            }
            None => vec![0.0; len],
        }
    }

    /// Keeps a buffer, if there is room.
    pub fn put(&mut self, buffer: Vec<f64>) {
        if self.free.len() < Self::CAPACITY && buffer.capacity() > 0 {
            self.free.push(buffer);
        }
    }

    /// Keeps the field buffers of a message's payload (delivered, or handled), up to the bound.
    pub fn recycle(&mut self, payload: Payload) {
        payload.into_buffers(|b| self.put(b));
    }

    /// Number of buffers held.
    pub fn len(&self) -> usize {
        self.free.len()
    }

    pub fn is_empty(&self) -> bool {
        self.free.is_empty()
    }
}

/// Where the decoder takes the buffers of the fields it decodes (bincode's decoding context):
/// a shared [`BufferPool`], or none (new buffers).
#[derive(Clone, Default)]
pub struct DecodeBuffers {
    pool: Option<Arc<Mutex<BufferPool>>>,
    /// Bytes of the payload being decoded: no field may claim more values than they hold (set by
    /// the decoder before it reads the payload).
    payload_bytes: usize,
    /// Blocks of the payload that a field's values may be read from in place ([`Self::holding`]).
    held: Option<Arc<dyn HoldSource>>,
}

impl std::fmt::Debug for DecodeBuffers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DecodeBuffers")
            .field("pool", &self.pool)
            .field("payload_bytes", &self.payload_bytes)
            .field("held", &self.held.is_some())
            .finish()
    }
}

/// Blocks of a received payload that fields may keep and read in place instead of copying them
/// ([`DecodeBuffers::holding`]), e.g. the shared-memory blocks a sender wrote fields into.
pub trait HoldSource: Send + Sync {
    /// The block whose bytes start at address `at` and are exactly `len` long, 8-byte aligned,
    /// if the payload has one.
    fn hold(&self, at: usize, len: usize) -> Option<Box<dyn HeldBlock>>;
}

impl DecodeBuffers {
    pub fn pooled(pool: Arc<Mutex<BufferPool>>) -> Self {
        Self {
            pool: Some(pool),
            ..Self::default()
        }
    }

    /// With `source`, a field whose values are exactly one of its blocks is read in place
    /// (held, [`Values::held`]) when the decoder reads from memory ([`decode_from_slices`]).
    pub fn holding(mut self, source: Arc<dyn HoldSource>) -> Self {
        self.held = Some(source);
        self
    }

    /// Refuses a field of `len` values that the payload is too short to hold (a damaged length),
    /// before its buffer is allocated.
    fn check(&self, len: usize) -> Result<(), bincode::error::DecodeError> {
        if len.saturating_mul(8) > self.payload_bytes {
            return Err(bincode::error::DecodeError::OtherString(format!(
                "a field declares {len} values but the payload holds {} bytes",
                self.payload_bytes
            )));
        }
        Ok(())
    }

    /// A buffer for a field of `len` values.
    fn take(&self, len: usize) -> Vec<f64> {
        match &self.pool {
            // A poisoned pool (a panic while it was held) still holds valid buffers.
            Some(pool) => pool.lock().unwrap_or_else(|e| e.into_inner()).take_any(len),
            None => vec![0.0; len],
        }
    }
}

// The wire form of a field is that of serde's derive (rows, cols, the value count as a u64, the
// values as little-endian f64: `config` is little-endian), written and read here as one block of
// bytes instead of value by value: on a little-endian machine the values' memory is their wire
// form (elsewhere, value by value).
impl bincode::Encode for Field {
    fn encode<E: bincode::enc::Encoder>(&self, e: &mut E) -> Result<(), bincode::error::EncodeError> {
        use bincode::enc::write::Writer;
        self.rows.encode(e)?;
        self.cols.encode(e)?;
        self.data.len().encode(e)?;
        if cfg!(target_endian = "little") {
            e.writer().write(bytemuck::cast_slice(&self.data))
        } else {
            self.data.iter().try_for_each(|v| v.encode(e))
        }
    }
}

impl bincode::Decode<DecodeBuffers> for Field {
    fn decode<D: bincode::de::Decoder<Context = DecodeBuffers>>(
        d: &mut D,
    ) -> Result<Self, bincode::error::DecodeError> {
        use bincode::de::read::Reader;
        let rows = u32::decode(d)?;
        let cols = u32::decode(d)?;
        let len = usize::decode(d)?;
        // Checked against the payload's size and counted against the codec's limit before
        // anything is allocated.
        d.context().check(len)?;
        d.claim_container_read::<f64>(len)?;
        if cfg!(target_endian = "little") && len > 0 {
            if let Some(source) = d.context().held.clone() {
                let bytes = len * 8;
                let at = d.reader().peek_read(bytes).map(|b| b.as_ptr() as usize);
                if let Some(block) = at.and_then(|at| source.hold(at, bytes)) {
                    d.reader().consume(bytes);
                    return Ok(Field {
                        rows,
                        cols,
                        data: Values::held(block),
                    });
                }
            }
        }
        let mut data = d.context().take(len);
        if cfg!(target_endian = "little") {
            d.reader().read(bytemuck::cast_slice_mut(&mut data))?;
        } else {
            for v in &mut data {
                *v = f64::decode(d)?;
            }
        }
        Ok(Field {
            rows,
            cols,
            data: data.into(),
        })
    }
}

bincode::impl_borrow_decode_with_context!(Field, DecodeBuffers);

/// How a run ended, or that it goes on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub enum Verdict {
    Continue,
    /// η (and the contact indicator, if required) reached the tolerance.
    Converged,
    MaxIterations,
    /// η stopped decreasing.
    Stagnated {
        detail: String,
    },
    /// η grew without bound or a value became NaN/Inf; the detail names where.
    Diverged {
        detail: String,
    },
}

impl Verdict {
    pub fn is_stop(&self) -> bool {
        !matches!(self, Verdict::Continue)
    }
}

/// Indicators of one iteration and the stop decision (interface node → everyone).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct Decision {
    /// LATIN indicator η (eq. 10).
    pub eta: f64,
    /// Contact indicator e_c = max(e_F, e_W) (independent of k).
    pub contact_indicator: f64,
    pub force_error: f64,
    pub jump_error: f64,
    /// Contact points (pair × time) separated, stuck, slipping.
    pub counts: [u64; 3],
    pub status_changes: u64,
    /// Contact interfaces whose search direction was updated at this iteration.
    pub direction_updates: Vec<u32>,
    pub verdict: Verdict,
}

/// One interface's indicator sums after a local stage (the terms of η, e_F, e_W and the contact
/// counts, DESIGN §3) and whether its search direction was updated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
pub struct InterfaceIndicators {
    pub interface: u32,
    pub eta_num: f64,
    pub eta_den: f64,
    pub force_num: f64,
    pub force_den: f64,
    pub jump_num: f64,
    pub jump_den: f64,
    pub counts: [u64; 3],
    pub status_changes: u64,
    pub direction_updated: bool,
}

/// The particular part s₀ = (W_d, −k⁻W_d) of a subdomain's state in separated form: the boundary
/// responses to its load cases and their time functions, W_d = `w` φ, −k⁻W_d = `f` φ.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[bincode(decode_context = "DecodeBuffers")]
pub struct ParticularModes {
    /// n_b × n_c each.
    pub w: Field,
    pub f: Field,
    /// φ, n_c × (N+1).
    pub time: Field,
}

/// One interface's fields at the end of a run: s (last linear stage) and ŝ (last local stage),
/// and the contact status per (pair, time) at index p + n_pairs·i (0 separated, 1 stick, 2 slip).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[bincode(decode_context = "DecodeBuffers")]
pub struct InterfaceSolution {
    pub interface: u32,
    pub w_a: Field,
    pub w_b: Field,
    pub f_a: Field,
    pub f_b: Field,
    pub w_a_hat: Field,
    pub w_b_hat: Field,
    pub f_a_hat: Field,
    pub f_b_hat: Field,
    pub status: Vec<u8>,
}

/// The payloads of DESIGN §4.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, bincode::Encode, bincode::Decode)]
#[bincode(decode_context = "DecodeBuffers")]
pub enum Payload {
    /// The scene file's text, so that remote nodes need no file.
    Scene {
        text: String,
    },
    /// L_E of a subdomain over its macro slots (interface, number of modes), sent once.
    HomogenizedOperator {
        subdomain: u32,
        slots: Vec<(u32, u32)>,
        l_e: Field,
    },
    /// F̂ᴹ_{E,d} = 𝔼ᵀ M F₁ (n_m × (N+1)) after micro problem 1.
    MacroForces {
        subdomain: u32,
        forces: Field,
    },
    /// w̃ over the subdomain's macro columns (n_m × (N+1)).
    MacroDisplacements {
        subdomain: u32,
        w_tilde: Field,
    },
    /// s = (W, F) of a subdomain's boundary after a linear stage (n_b × (N+1) each).
    BoundaryState {
        subdomain: u32,
        w: Field,
        f: Field,
    },
    /// s = (W, F) of a subdomain's boundary after a linear stage, in PGD mode form (DESIGN §3–4):
    /// W = P_W φ + Σ_k Z_k λ_k, F = P_F φ + Σ_k G_k λ_k. The receiver keeps the particular part
    /// (in the subdomain's first message only) and the basis: it keeps its first `first_mode`
    /// modes and replaces the rest by the columns of `z` and `g` (n_b × new: new modes, or the
    /// free modes a compression rotated). `lambda` is the state's time functions, p × (N+1) with
    /// p = `first_mode` + new.
    BoundaryModes {
        subdomain: u32,
        particular: Option<ParticularModes>,
        first_mode: u32,
        z: Field,
        g: Field,
        lambda: Field,
    },
    /// q̂ = F̂ + k⁻Ŵ on a subdomain's boundary: all the linear stage needs from the local stage.
    /// One interface node sends the rows of the interfaces it owns: `interfaces` in the order of
    /// the subdomain's boundary layout, `q_hat` their rows one after the other. The subdomain
    /// starts its linear stage once every interface of its boundary is covered.
    LocalDirections {
        subdomain: u32,
        interfaces: Vec<u32>,
        q_hat: Field,
    },
    /// A subdomain's share of the Anderson least-squares problem after its linear stage (DESIGN §3
    /// "Acceleration"), over its k stored residual differences Δr_i (oldest first), forces only:
    /// `gram` Δr_iᵀΔr_j (k × k), `projection` Δr_iᵀ r (k × 1), `residual2` ‖r‖².
    AndersonGram {
        subdomain: u32,
        gram: Field,
        projection: Field,
        residual2: f64,
    },
    /// The mixing step every subdomain takes (summed Gram matrix solved by the interface node):
    /// coefficients γ (oldest difference first), or empty for a plain relaxation step; `restart`
    /// tells the subdomains to forget their differences.
    AndersonStep {
        gamma: Vec<f64>,
        restart: bool,
    },
    Decision(Decision),
    InterfaceSolution(InterfaceSolution),
    /// Full displacement field of a subdomain (n_dofs × (N+1)), on request at the end.
    Displacement {
        subdomain: u32,
        u: Field,
    },
    /// An interface node's share of an iteration's indicators, sent to the deciding interface
    /// node (index 0) when the run has several: one entry per interface it owns, in interface
    /// order, or the reason the iteration diverged (a non-finite value received).
    IndicatorPartials {
        interfaces: Vec<InterfaceIndicators>,
        diverged: Option<String>,
    },
}

/// The fields of a payload (`$p`), in wire order, each passed to `$visit` as `&` or `&mut`.
macro_rules! for_each_field {
    ($p:expr, $visit:ident, $($r:tt)+) => {{
        let mut $visit = $visit;
        match $p {
            Payload::Scene { .. }
            | Payload::AndersonStep { .. }
            | Payload::Decision(_)
            | Payload::IndicatorPartials { .. } => {}
            Payload::HomogenizedOperator { l_e, .. } => $visit(l_e),
            Payload::MacroForces { forces, .. } => $visit(forces),
            Payload::MacroDisplacements { w_tilde, .. } => $visit(w_tilde),
            Payload::BoundaryState { w, f, .. } => {
                $visit(w);
                $visit(f);
            }
            Payload::BoundaryModes {
                particular,
                z,
                g,
                lambda,
                ..
            } => {
                if let Some(p) = particular {
                    $visit($($r)+ p.w);
                    $visit($($r)+ p.f);
                    $visit($($r)+ p.time);
                }
                $visit(z);
                $visit(g);
                $visit(lambda);
            }
            Payload::LocalDirections { q_hat, .. } => $visit(q_hat),
            Payload::AndersonGram { gram, projection, .. } => {
                $visit(gram);
                $visit(projection);
            }
            Payload::InterfaceSolution(s) => {
                for f in [
                    $($r)+ s.w_a,
                    $($r)+ s.w_b,
                    $($r)+ s.f_a,
                    $($r)+ s.f_b,
                    $($r)+ s.w_a_hat,
                    $($r)+ s.w_b_hat,
                    $($r)+ s.f_a_hat,
                    $($r)+ s.f_b_hat,
                ] {
                    $visit(f);
                }
            }
            Payload::Displacement { u, .. } => $visit(u),
        }
    }};
}

impl Payload {
    /// The field chunk of the key expression.
    pub fn field_key(&self) -> &'static str {
        match self {
            Payload::Scene { .. } => "scene",
            Payload::HomogenizedOperator { .. } => "homogenized_operator",
            Payload::MacroForces { .. } => "macro_forces",
            Payload::MacroDisplacements { .. } => "macro_displacements",
            Payload::BoundaryState { .. } => "boundary_state",
            Payload::BoundaryModes { .. } => "boundary_modes",
            Payload::LocalDirections { .. } => "local_directions",
            Payload::AndersonGram { .. } => "anderson_gram",
            Payload::AndersonStep { .. } => "anderson_step",
            Payload::Decision(_) => "decision",
            Payload::InterfaceSolution(_) => "interface_solution",
            Payload::Displacement { .. } => "displacement",
            Payload::IndicatorPartials { .. } => "indicator_partials",
        }
    }

    /// Hands the value buffer of every field of the payload to `keep`, e.g. back to its sender's
    /// pool once the message is delivered (other contents are dropped).
    pub fn into_buffers(mut self, mut keep: impl FnMut(Vec<f64>)) {
        // A lent block goes back to its lender when dropped, not to a pool.
        self.fields_mut(|f| {
            if let Some(v) = std::mem::take(&mut f.data).into_vec() {
                keep(v)
            }
        });
    }

    /// Calls `visit` on every field of the payload, in wire order.
    pub fn fields(&self, visit: impl FnMut(&Field)) {
        for_each_field!(self, visit, &);
    }

    /// Calls `visit` on every field of the payload, in wire order, to change it.
    pub fn fields_mut(&mut self, visit: impl FnMut(&mut Field)) {
        for_each_field!(self, visit, &mut);
    }

    /// Subdomain a payload is addressed to, for payloads with one recipient subdomain.
    pub fn destination(&self) -> Option<u32> {
        match self {
            Payload::MacroDisplacements { subdomain, .. } | Payload::LocalDirections { subdomain, .. } => {
                Some(*subdomain)
            }
            _ => None,
        }
    }

    fn check(&self) -> Result<(), DecodeError> {
        match self {
            Payload::Scene { .. } => Ok(()),
            Payload::HomogenizedOperator { l_e, .. } => l_e.check("l_e"),
            Payload::MacroForces { forces, .. } => forces.check("forces"),
            Payload::MacroDisplacements { w_tilde, .. } => w_tilde.check("w_tilde"),
            Payload::BoundaryState { w, f, .. } => {
                w.check("w")?;
                f.check("f")?;
                if (w.rows, w.cols) != (f.rows, f.cols) {
                    return Err(DecodeError::WrongSize {
                        field: "f (differs from w)".into(),
                        rows: f.rows,
                        cols: f.cols,
                        len: f.data.len(),
                    });
                }
                Ok(())
            }
            Payload::BoundaryModes {
                particular,
                first_mode,
                z,
                g,
                lambda,
                ..
            } => {
                z.check("z")?;
                g.check("g")?;
                lambda.check("lambda")?;
                if (g.rows, g.cols) != (z.rows, z.cols) {
                    return Err(DecodeError::WrongSize {
                        field: format!("g (z is {} × {})", z.rows, z.cols),
                        rows: g.rows,
                        cols: g.cols,
                        len: g.data.len(),
                    });
                }
                if lambda.rows as u64 != *first_mode as u64 + z.cols as u64 {
                    return Err(DecodeError::WrongSize {
                        field: format!("lambda (first mode {first_mode} + {} new modes)", z.cols),
                        rows: lambda.rows,
                        cols: lambda.cols,
                        len: lambda.data.len(),
                    });
                }
                if let Some(pm) = particular {
                    pm.w.check("particular.w")?;
                    pm.f.check("particular.f")?;
                    pm.time.check("particular.time")?;
                    if (pm.f.rows, pm.f.cols) != (pm.w.rows, pm.w.cols) || pm.time.rows != pm.w.cols {
                        return Err(DecodeError::WrongSize {
                            field: format!(
                                "particular part (w {} × {}, f {} × {})",
                                pm.w.rows, pm.w.cols, pm.f.rows, pm.f.cols
                            ),
                            rows: pm.time.rows,
                            cols: pm.time.cols,
                            len: pm.time.data.len(),
                        });
                    }
                }
                Ok(())
            }
            Payload::LocalDirections { q_hat, .. } => q_hat.check("q_hat"),
            Payload::IndicatorPartials { .. } => Ok(()),
            Payload::AndersonGram { gram, projection, .. } => {
                gram.check("gram")?;
                projection.check("projection")?;
                if gram.rows != gram.cols || (projection.rows, projection.cols) != (gram.rows, 1) {
                    return Err(DecodeError::WrongSize {
                        field: format!("projection (gram is {} × {})", gram.rows, gram.cols),
                        rows: projection.rows,
                        cols: projection.cols,
                        len: projection.data.len(),
                    });
                }
                Ok(())
            }
            Payload::AndersonStep { .. } => Ok(()),
            Payload::Decision(_) => Ok(()),
            Payload::InterfaceSolution(s) => {
                for (name, f) in [
                    ("w_a", &s.w_a),
                    ("w_b", &s.w_b),
                    ("f_a", &s.f_a),
                    ("f_b", &s.f_b),
                    ("w_a_hat", &s.w_a_hat),
                    ("w_b_hat", &s.w_b_hat),
                    ("f_a_hat", &s.f_a_hat),
                    ("f_b_hat", &s.f_b_hat),
                ] {
                    f.check(name)?;
                }
                Ok(())
            }
            Payload::Displacement { u, .. } => u.check("u"),
        }
    }
}

/// A message: envelope + payload.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub envelope: Envelope,
    pub payload: Payload,
}

impl Message {
    /// The key expression this message is published on.
    pub fn topic(&self) -> String {
        topic(&self.envelope.run_id, self.envelope.sender, &self.payload)
    }
}

/// `glissade/<run>/<role>/<id>/<field>[/<destination subdomain>]`.
pub fn topic(run_id: &str, sender: NodeId, payload: &Payload) -> String {
    let base = format!(
        "glissade/{run_id}/{}/{}/{}",
        sender.role.key(),
        sender.index,
        payload.field_key()
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
    format!("glissade/{run_id}/**")
}

/// Key expression of one field from any sender of a role, optionally for one destination.
pub fn role_field_topic(run_id: &str, role: Role, field: &str, destination: Option<u32>) -> String {
    match destination {
        Some(d) => format!("glissade/{run_id}/{}/*/{field}/{d}", role.key()),
        None => format!("glissade/{run_id}/{}/*/{field}", role.key()),
    }
}

/// Does key `key` match the key expression `expr` (`*`: one chunk, `**`: any number of chunks)?
pub fn key_matches(expr: &str, key: &str) -> bool {
    fn rec(e: &[&str], k: &[&str]) -> bool {
        match (e.first(), k.first()) {
            (None, None) => true,
            (Some(&"**"), _) => rec(&e[1..], k) || (!k.is_empty() && rec(e, &k[1..])),
            (Some(&"*"), Some(_)) => rec(&e[1..], &k[1..]),
            (Some(a), Some(b)) if a == b => rec(&e[1..], &k[1..]),
            _ => false,
        }
    }
    let e: Vec<&str> = expr.split('/').collect();
    let k: Vec<&str> = key.split('/').collect();
    rec(&e, &k)
}

/// Why bytes could not be accepted as a message of this run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("schema version {got} is not this build's {expected}")]
    SchemaVersion { got: u32, expected: u32 },
    #[error("message of run `{got}`, expected run `{expected}`")]
    OtherRun { got: String, expected: String },
    #[error("message of scene {got:016x}, expected scene {expected:016x}")]
    OtherScene { got: u64, expected: u64 },
    #[error("{0} trailing bytes after the payload")]
    TrailingBytes(usize),
    #[error("field `{field}` declares {rows} × {cols} values but holds {len}")]
    WrongSize {
        field: String,
        rows: u32,
        cols: u32,
        len: usize,
    },
    #[error("malformed {part}: {detail}")]
    Malformed { part: &'static str, detail: String },
}

/// What a receiver expects of every message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Expected {
    pub run_id: String,
    pub scene_fingerprint: u64,
}

fn config() -> impl bincode::config::Config {
    bincode::config::standard()
        .with_little_endian()
        .with_fixed_int_encoding()
        .with_limit::<{ 1 << 31 }>()
}

/// Encodes envelope then payload.
pub fn encode(msg: &Message) -> Vec<u8> {
    // Sized first, then written once into a buffer of that size: a multi-MB field is copied
    // once, not regrown and moved as it is written.
    let mut out = Vec::with_capacity(encoded_len(msg));
    bincode::encode_into_std_write(&msg.envelope, &mut out, config()).expect("encoding into a Vec cannot fail");
    bincode::encode_into_std_write(&msg.payload, &mut out, config()).expect("encoding into a Vec cannot fail");
    out
}

/// The size of [`encode`]'s bytes, without encoding.
pub fn encoded_len(msg: &Message) -> usize {
    let mut size = bincode::enc::write::SizeWriter::default();
    bincode::encode_into_writer(&msg.envelope, &mut size, config()).expect("sizing cannot fail");
    bincode::encode_into_writer(&msg.payload, &mut size, config()).expect("sizing cannot fail");
    size.bytes_written
}

/// Writes [`encode`]'s bytes into `out` (a buffer the caller already has, e.g. in shared memory)
/// and returns how many; None if `out` is shorter than [`encoded_len`].
pub fn encode_into(msg: &Message, out: &mut [u8]) -> Option<usize> {
    let n = bincode::encode_into_slice(&msg.envelope, out, config()).ok()?;
    let m = bincode::encode_into_slice(&msg.payload, &mut out[n..], config()).ok()?;
    Some(n + m)
}

/// A part of a message's encoding ([`encode_pieces`]).
#[derive(Debug, PartialEq)]
pub enum Piece {
    /// Encoded bytes.
    Bytes(Vec<u8>),
    /// The values of the field whose lent block ([`Values::lent`]) starts at this address, in
    /// their wire form: the block's memory itself.
    Block(usize),
}

/// [`encode`]'s bytes in pieces, with the values of every lent field block named by its address
/// instead of copied, so that a transport can send the blocks themselves: concatenated (each
/// block as its values' bytes), the pieces are [`encode`]'s bytes. On a big-endian machine,
/// where values are encoded one by one, there is no block piece.
pub fn encode_pieces(msg: &Message) -> Vec<Piece> {
    let mut blocks = Vec::new();
    msg.payload.fields(|f| {
        if f.data.is_lent() && !f.data.is_empty() {
            let bytes: &[u8] = bytemuck::cast_slice(&f.data);
            blocks.push((bytes.as_ptr() as usize, bytes.len()));
        }
    });
    let mut w = PieceWriter {
        blocks,
        pieces: Vec::new(),
        current: Vec::with_capacity(256),
    };
    bincode::encode_into_writer(&msg.envelope, &mut w, config()).expect("encoding into a Vec cannot fail");
    bincode::encode_into_writer(&msg.payload, &mut w, config()).expect("encoding into a Vec cannot fail");
    if !w.current.is_empty() {
        w.pieces.push(Piece::Bytes(w.current));
    }
    w.pieces
}

/// Collects [`encode_pieces`]: a write of exactly a lent block's bytes (a field's values, which
/// [`Field`]'s encoding writes in one piece) becomes a block piece.
struct PieceWriter {
    blocks: Vec<(usize, usize)>,
    pieces: Vec<Piece>,
    current: Vec<u8>,
}

impl bincode::enc::write::Writer for PieceWriter {
    fn write(&mut self, bytes: &[u8]) -> Result<(), bincode::error::EncodeError> {
        let at = (bytes.as_ptr() as usize, bytes.len());
        if !bytes.is_empty() && self.blocks.contains(&at) {
            if !self.current.is_empty() {
                self.pieces.push(Piece::Bytes(std::mem::take(&mut self.current)));
            }
            self.pieces.push(Piece::Block(at.0));
        } else {
            self.current.extend_from_slice(bytes);
        }
        Ok(())
    }
}

/// A decoding error of `part` ("envelope" or "payload").
fn malformed(part: &'static str) -> impl Fn(bincode::error::DecodeError) -> DecodeError {
    move |e| DecodeError::Malformed {
        part,
        detail: e.to_string(),
    }
}

/// Reads the envelope at the start of `r`, checking the schema version and the run.
fn read_envelope<R: Source>(r: &mut Bounded<R>, run_id: &str) -> Result<Envelope, DecodeError> {
    let envelope: Envelope = bincode::decode_from_reader(r, config()).map_err(malformed("envelope"))?;
    if envelope.schema_version != SCHEMA_VERSION {
        return Err(DecodeError::SchemaVersion {
            got: envelope.schema_version,
            expected: SCHEMA_VERSION,
        });
    }
    if envelope.run_id != run_id {
        return Err(DecodeError::OtherRun {
            got: envelope.run_id,
            expected: run_id.to_string(),
        });
    }
    Ok(envelope)
}

/// Decodes only the envelope, checking the schema version and the run (for a receiver that
/// learns the scene fingerprint from the scene message itself).
pub fn peek_envelope(bytes: &[u8], run_id: &str) -> Result<Envelope, DecodeError> {
    read_envelope(
        &mut Bounded {
            inner: IoSource(bytes),
            left: bytes.len(),
        },
        run_id,
    )
}

/// Decodes and checks a message: schema version, run, scene, trailing bytes, field sizes.
pub fn decode(bytes: &[u8], expected: &Expected) -> Result<Message, DecodeError> {
    decode_from_reader(bytes, bytes.len(), expected, DecodeBuffers::default())
}

/// [`decode`] from a reader holding exactly `len` bytes (e.g. a transport's fragmented payload,
/// read where it lies instead of first being copied into one buffer), the fields' buffers taken
/// from `buffers`: the same checks, the same errors.
pub fn decode_from_reader(
    reader: impl std::io::Read,
    len: usize,
    expected: &Expected,
    buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    decode_bounded(
        Bounded {
            inner: IoSource(reader),
            left: len,
        },
        expected,
        buffers,
    )
}

/// [`decode_from_reader`] of a payload that lies in memory in `slices` (`len` bytes in all, e.g.
/// the fragments or pieces a transport received), read where they lie: a field whose values are
/// a block of `buffers`' hold source ([`DecodeBuffers::holding`]) keeps it instead of copying it.
pub fn decode_from_slices<'a>(
    slices: impl IntoIterator<Item = &'a [u8]>,
    len: usize,
    expected: &Expected,
    buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    let inner = Slices {
        slices: slices.into_iter().collect(),
        k: 0,
        at: 0,
    };
    decode_bounded(Bounded { inner, left: len }, expected, buffers)
}

fn decode_bounded<R: Source>(
    mut r: Bounded<R>,
    expected: &Expected,
    mut buffers: DecodeBuffers,
) -> Result<Message, DecodeError> {
    let envelope = read_envelope(&mut r, &expected.run_id)?;
    if envelope.scene_fingerprint != expected.scene_fingerprint {
        return Err(DecodeError::OtherScene {
            got: envelope.scene_fingerprint,
            expected: expected.scene_fingerprint,
        });
    }
    buffers.payload_bytes = r.left;
    let mut decoder = bincode::de::DecoderImpl::new(&mut r, config(), buffers);
    let payload = <Payload as bincode::Decode<DecodeBuffers>>::decode(&mut decoder).map_err(malformed("payload"))?;
    if r.left != 0 {
        return Err(DecodeError::TrailingBytes(r.left));
    }
    payload.check()?;
    Ok(Message { envelope, payload })
}

/// A reader of `left` more bytes, that refuses a read past them before reading
/// (`UnexpectedEnd`, with the bytes missing, as bincode's slice reader words it).
struct Bounded<R> {
    inner: R,
    left: usize,
}

/// What [`Bounded`] reads from: bytes in order, and where they lie in memory, a look at the next
/// ones without copying them.
trait Source: std::io::Read {
    /// The next `n` bytes, if they lie together in memory.
    fn peek(&self, n: usize) -> Option<&[u8]>;
    /// Moves past `n` bytes [`Source::peek`] showed.
    fn skip(&mut self, n: usize);
}

/// A [`Source`] over any reader: no look ahead.
struct IoSource<R>(R);

impl<R: std::io::Read> std::io::Read for IoSource<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl<R: std::io::Read> Source for IoSource<R> {
    fn peek(&self, _: usize) -> Option<&[u8]> {
        None
    }

    fn skip(&mut self, _: usize) {
        unreachable!("nothing was peeked")
    }
}

/// A [`Source`] over a payload's slices in memory, one after the other (e.g. the fragments a
/// transport received, or the pieces of a message sent with its fields' blocks).
struct Slices<'a> {
    slices: Vec<&'a [u8]>,
    /// The current slice and the position in it.
    k: usize,
    at: usize,
}

impl std::io::Read for Slices<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let mut n = 0;
        while n < buf.len() && self.k < self.slices.len() {
            let rest = &self.slices[self.k][self.at..];
            let m = rest.len().min(buf.len() - n);
            buf[n..n + m].copy_from_slice(&rest[..m]);
            n += m;
            self.advance(m);
        }
        Ok(n)
    }
}

impl Slices<'_> {
    /// Moves `n` bytes on within the current slice, to the next slice at its end.
    fn advance(&mut self, n: usize) {
        self.at += n;
        if self.at == self.slices[self.k].len() {
            (self.k, self.at) = (self.k + 1, 0);
        }
    }
}

impl Source for Slices<'_> {
    fn peek(&self, n: usize) -> Option<&[u8]> {
        self.slices.get(self.k).and_then(|s| s[self.at..].get(..n))
    }

    fn skip(&mut self, n: usize) {
        self.advance(n);
    }
}

impl<R: Source> bincode::de::read::Reader for Bounded<R> {
    fn read(&mut self, bytes: &mut [u8]) -> Result<(), bincode::error::DecodeError> {
        if bytes.len() > self.left {
            return Err(bincode::error::DecodeError::UnexpectedEnd {
                additional: bytes.len() - self.left,
            });
        }
        self.inner
            .read_exact(bytes)
            .map_err(|inner| bincode::error::DecodeError::Io {
                inner,
                additional: bytes.len(),
            })?;
        self.left -= bytes.len();
        Ok(())
    }

    fn peek_read(&mut self, n: usize) -> Option<&[u8]> {
        if n > self.left {
            return None;
        }
        self.inner.peek(n)
    }

    fn consume(&mut self, n: usize) {
        self.inner.skip(n);
        self.left -= n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg() -> Message {
        Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: "r1".into(),
                scene_fingerprint: 7,
                iteration: 3,
                stage: Stage::Linear,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: 2,
                },
            },
            payload: Payload::BoundaryState {
                subdomain: 2,
                w: Field::from_fn(3, 2, |r, c| (r + 10 * c) as f64),
                f: Field::zeros(3, 2),
            },
        }
    }

    fn expected() -> Expected {
        Expected {
            run_id: "r1".into(),
            scene_fingerprint: 7,
        }
    }

    /// The values of lent fields are named in place by [`encode_pieces`], not copied, and the
    /// pieces put together are [`encode`]'s bytes; without lent fields there is one piece.
    #[test]
    fn pieces_put_together_are_the_encoding() {
        let plain = msg();
        assert_eq!(encode_pieces(&plain), vec![Piece::Bytes(encode(&plain))]);
        let mut lent = msg();
        let Payload::BoundaryState { w, f, .. } = &mut lent.payload else {
            unreachable!()
        };
        for field in [w, f] {
            field.data = Values::lent(Box::new(field.data.to_vec()));
        }
        let Payload::BoundaryState { w, f, .. } = &lent.payload else {
            unreachable!()
        };
        let at = |f: &Field| f.data.as_ptr() as usize;
        let pieces = encode_pieces(&lent);
        assert!(
            matches!(&pieces[..], [Piece::Bytes(_), Piece::Block(a), Piece::Bytes(_), Piece::Block(b)] if *a == at(w) && *b == at(f)),
            "{pieces:?}"
        );
        let mut joined = Vec::new();
        for p in &pieces {
            match p {
                Piece::Bytes(b) => joined.extend_from_slice(b),
                Piece::Block(a) => {
                    let field = if *a == at(w) { w } else { f };
                    joined.extend_from_slice(bytemuck::cast_slice(&field.data));
                }
            }
        }
        assert_eq!(joined, encode(&plain));
        assert_eq!(encode(&lent), encode(&plain), "a lent field encodes as an owned one");
    }

    /// A hold source over one block of values.
    struct OneBlock(Arc<Vec<f64>>);

    impl HoldSource for OneBlock {
        fn hold(&self, at: usize, len: usize) -> Option<Box<dyn HeldBlock>> {
            (at == self.0.as_ptr() as usize && len == 8 * self.0.len())
                .then(|| Box::new(self.0.clone()) as Box<dyn HeldBlock>)
        }
    }

    /// Decoding a payload from its slices reads a field whose values are exactly a block of the
    /// hold source in place and copies the others; the message and the refusals are those of
    /// [`decode`].
    #[test]
    fn a_field_that_is_a_held_block_is_read_in_place() {
        let m = msg();
        let Payload::BoundaryState { w, .. } = &m.payload else {
            unreachable!()
        };
        let block = Arc::new(w.data.to_vec());
        let bytes = encode(&m);
        let w_bytes: &[u8] = bytemuck::cast_slice(&block[..]);
        let at = bytes
            .windows(w_bytes.len())
            .position(|x| x == w_bytes)
            .expect("w's values");
        let end = at + w_bytes.len();
        let slices = [&bytes[..at], w_bytes, &bytes[end..]];
        let holding = || DecodeBuffers::default().holding(Arc::new(OneBlock(block.clone())));
        let got = decode_from_slices(slices, bytes.len(), &expected(), holding()).unwrap();
        assert_eq!(got, m);
        let Payload::BoundaryState { w, f, .. } = &got.payload else {
            unreachable!()
        };
        assert!(w.data.is_held() && w.data.as_ptr() == block.as_ptr(), "w read in place");
        assert!(!f.data.is_held(), "f is no block of the source");
        // Without a hold source, or from other slices, the values are copied.
        let copied = decode_from_slices(slices, bytes.len(), &expected(), DecodeBuffers::default()).unwrap();
        copied.payload.fields(|f| assert!(!f.data.is_held()));
        let other = bytes[at..end].to_vec();
        let apart = decode_from_slices(
            [&bytes[..at], &other, &bytes[end..]],
            bytes.len(),
            &expected(),
            holding(),
        );
        apart.unwrap().payload.fields(|f| assert!(!f.data.is_held()));
        // Cut short after the block: refused as decode refuses it.
        let short = [&bytes[..at], w_bytes, &bytes[end..bytes.len() - 1]];
        assert_eq!(
            decode_from_slices(short, bytes.len() - 1, &expected(), holding()).unwrap_err(),
            decode(&bytes[..bytes.len() - 1], &expected()).unwrap_err()
        );
    }

    #[test]
    fn round_trip_and_topic() {
        let m = msg();
        let bytes = encode(&m);
        assert_eq!(decode(&bytes, &expected()).unwrap(), m);
        // The wire format: the envelope's bincode encoding, then the payload's.
        let mut parts = bincode::serde::encode_to_vec(&m.envelope, config()).unwrap();
        parts.extend(bincode::serde::encode_to_vec(&m.payload, config()).unwrap());
        assert_eq!(bytes, parts);
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
    }

    #[test]
    fn encoding_into_a_given_buffer_writes_the_same_bytes() {
        let m = msg();
        let bytes = encode(&m);
        assert_eq!(encoded_len(&m), bytes.len());
        // A buffer with room to spare (a shared-memory chunk may be rounded up): the same bytes
        // at its start, and the count of them.
        let mut out = vec![0xAA_u8; bytes.len() + 5];
        assert_eq!(encode_into(&m, &mut out), Some(bytes.len()));
        assert_eq!(&out[..bytes.len()], &bytes[..]);
        assert!(out[bytes.len()..].iter().all(|&b| b == 0xAA));
        // One byte short: refused, not truncated.
        assert_eq!(encode_into(&m, &mut vec![0u8; bytes.len() - 1]), None);
    }

    #[test]
    fn rejections_say_why() {
        let m = msg();
        let bytes = encode(&m);
        let e = decode(
            &bytes,
            &Expected {
                run_id: "other".into(),
                scene_fingerprint: 7,
            },
        )
        .unwrap_err();
        assert!(matches!(e, DecodeError::OtherRun { .. }), "{e}");
        let e = decode(
            &bytes,
            &Expected {
                run_id: "r1".into(),
                scene_fingerprint: 8,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("scene"), "{e}");
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(decode(&longer, &expected()).unwrap_err(), DecodeError::TrailingBytes(1));
        let e = decode(&bytes[..bytes.len() - 3], &expected()).unwrap_err();
        assert!(matches!(e, DecodeError::Malformed { part: "payload", .. }), "{e}");
        let mut v2 = m.clone();
        v2.envelope.schema_version = SCHEMA_VERSION + 1;
        let e = decode(&encode(&v2), &expected()).unwrap_err();
        assert!(matches!(e, DecodeError::SchemaVersion { .. }), "{e}");
        let mut bad = m.clone();
        if let Payload::BoundaryState { w, .. } = &mut bad.payload {
            w.data.vec_mut().pop();
        }
        let e = decode(&encode(&bad), &expected()).unwrap_err();
        assert!(
            e.to_string().contains("field `w` declares 3 × 2 values but holds 5"),
            "{e}"
        );
    }

    #[test]
    fn a_pooled_decode_reuses_the_buffers_of_handled_messages() {
        let m = msg();
        let bytes = encode(&m);
        let pool = Arc::new(Mutex::new(BufferPool::default()));
        let decode_pooled = || {
            decode_from_reader(
                &bytes[..],
                bytes.len(),
                &expected(),
                DecodeBuffers::pooled(pool.clone()),
            )
            .unwrap()
        };
        let first = decode_pooled();
        assert_eq!(first, m);
        // Handled: its buffers go back, dirty (and one longer than the field it will hold); the
        // next message's fields are decoded into them.
        let mut dirty = first.payload;
        if let Payload::BoundaryState { w, .. } = &mut dirty {
            w.data.iter_mut().for_each(|v| *v = f64::NAN);
            w.data.vec_mut().push(f64::NAN);
        }
        let at: Vec<*const f64> = match &dirty {
            Payload::BoundaryState { w, f, .. } => vec![w.data.as_ptr(), f.data.as_ptr()],
            _ => unreachable!(),
        };
        pool.lock().unwrap().recycle(dirty);
        assert_eq!(pool.lock().unwrap().len(), 2);
        let second = decode_pooled();
        assert_eq!(second, m);
        match &second.payload {
            Payload::BoundaryState { w, f, .. } => {
                let mut now = vec![w.data.as_ptr(), f.data.as_ptr()];
                now.sort();
                let mut before = at.clone();
                before.sort();
                assert_eq!(now, before);
            }
            _ => unreachable!(),
        }
        assert!(pool.lock().unwrap().is_empty());
    }

    #[test]
    fn a_damaged_field_length_is_refused_before_anything_is_allocated() {
        let m = msg();
        let mut bytes = encode(&m);
        // The payload: variant (u32), subdomain (u32), then w's rows and cols (u32 each) and its
        // value count (u64): claim 2^27 or 2^28 values (1 or 2 GiB) in a message of under 200
        // bytes.
        let envelope = bincode::serde::encode_to_vec(&m.envelope, config()).unwrap().len();
        let at = envelope + 4 + 4 + 4 + 4;
        assert_eq!(bytes[at..at + 8], 6u64.to_le_bytes());
        for claim in [1u64 << 27, 1 << 28] {
            bytes[at..at + 8].copy_from_slice(&claim.to_le_bytes());
            let e = decode(&bytes, &expected()).unwrap_err();
            let said = format!(
                "a field declares {claim} values but the payload holds {} bytes",
                bytes.len() - envelope
            );
            assert!(e.to_string().contains(&said), "{e}");
        }
    }

    #[test]
    fn into_buffers_hands_back_every_field() {
        let lengths = |p: Payload| {
            let mut v = Vec::new();
            p.into_buffers(|b| v.push(b.len()));
            v
        };
        assert_eq!(lengths(msg().payload), [6, 6]);
        let modes = Payload::BoundaryModes {
            subdomain: 2,
            particular: Some(ParticularModes {
                w: Field::zeros(3, 1),
                f: Field::zeros(3, 1),
                time: Field::zeros(1, 2),
            }),
            first_mode: 0,
            z: Field::zeros(3, 2),
            g: Field::zeros(3, 2),
            lambda: Field::zeros(2, 2),
        };
        assert_eq!(lengths(modes), [3, 3, 2, 6, 6, 4]);
        let directions = Payload::LocalDirections {
            subdomain: 0,
            interfaces: vec![1],
            q_hat: Field::zeros(4, 5),
        };
        assert_eq!(lengths(directions), [20]);
        assert!(lengths(Payload::Scene { text: "x".into() }).is_empty());
    }

    #[test]
    fn mode_form_sizes_are_checked() {
        let mut m = msg();
        let modes = |first_mode: u32, lambda_rows: usize, g_cols: usize| Payload::BoundaryModes {
            subdomain: 2,
            particular: Some(ParticularModes {
                w: Field::zeros(3, 1),
                f: Field::zeros(3, 1),
                time: Field::zeros(1, 2),
            }),
            first_mode,
            z: Field::zeros(3, 2),
            g: Field::zeros(3, g_cols),
            lambda: Field::zeros(lambda_rows, 2),
        };
        m.payload = modes(1, 3, 2);
        assert_eq!(decode(&encode(&m), &expected()).unwrap(), m);
        assert_eq!(m.topic(), "glissade/r1/subdomain/2/boundary_modes");
        m.payload = modes(1, 2, 2);
        let e = decode(&encode(&m), &expected()).unwrap_err();
        assert!(e.to_string().contains("lambda (first mode 1 + 2 new modes)"), "{e}");
        m.payload = modes(1, 3, 1);
        let e = decode(&encode(&m), &expected()).unwrap_err();
        assert!(e.to_string().contains("g (z is 3 × 2)"), "{e}");
        m.payload = modes(1, 3, 2);
        if let Payload::BoundaryModes {
            particular: Some(p), ..
        } = &mut m.payload
        {
            p.time = Field::zeros(2, 2);
        }
        let e = decode(&encode(&m), &expected()).unwrap_err();
        assert!(e.to_string().contains("particular part"), "{e}");
    }
}
