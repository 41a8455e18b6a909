//! Conversions between wire fields and faer matrices, and the pool that lets a node reuse the
//! buffers of the fields it sends.

use faer::{Mat, MatMut, MatRef};
use glissade_messages::{BlockLender, BufferPool, Field, Message, Values};
use rayon::prelude::*;
use std::sync::Arc;

/// Column `j` of a matrix as a slice, when its rows are contiguous.
fn col(m: MatRef<'_, f64>, j: usize) -> Option<&[f64]> {
    m.col(j).try_as_col_major().map(|c| c.as_slice())
}

/// Appends the columns of `m` to `data` (column-major).
fn extend_columns(data: &mut Vec<f64>, m: MatRef<'_, f64>) {
    data.reserve(m.nrows() * m.ncols());
    for j in 0..m.ncols() {
        match col(m, j) {
            Some(c) => data.extend_from_slice(c),
            None => data.extend((0..m.nrows()).map(|r| m[(r, j)])),
        }
    }
}

/// Writes the columns of `m` over `data` (column-major, as many values).
fn write_columns(data: &mut [f64], m: MatRef<'_, f64>) {
    let rows = m.nrows();
    for j in 0..m.ncols() {
        let out = &mut data[j * rows..(j + 1) * rows];
        match col(m, j) {
            Some(c) => out.copy_from_slice(c),
            None => out.iter_mut().enumerate().for_each(|(r, v)| *v = m[(r, j)]),
        }
    }
}

/// Wire field of a matrix (column-major copy).
pub fn field_of(m: MatRef<'_, f64>) -> Field {
    let mut data = Vec::new();
    extend_columns(&mut data, m);
    Field {
        rows: m.nrows() as u32,
        cols: m.ncols() as u32,
        data: data.into(),
    }
}

/// A wire field seen as a matrix (no copy).
pub fn view(f: &Field) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(&f.data, f.rows(), f.cols())
}

/// Matrix of a wire field.
pub fn mat_of(f: &Field) -> Mat<f64> {
    view(f).to_owned()
}

/// Copies a wire field into a matrix of the same shape.
pub fn copy_into(f: &Field, m: &mut Mat<f64>) {
    m.copy_from(view(f));
}

/// Buffers of fields a node sent, back from the bus once their messages were delivered
/// ([`crate::Node::recycle`]), to hold the same node's next fields: after the first iteration a
/// node's multi-megabyte fields reuse memory instead of being allocated (and their pages faulted
/// in) again. The buffers are a [`BufferPool`] (bounded; a field takes the smallest buffer that
/// fits and is at most twice its size).
#[derive(Default)]
pub struct FieldPool {
    buffers: BufferPool,
    /// Lends the memory of fields of [`FieldPool::LEND_MIN`] values or more, when set: a
    /// transport that then sends them without copying their values ([`FieldPool::lend_from`]).
    lender: Option<Arc<dyn BlockLender>>,
}

impl std::fmt::Debug for FieldPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FieldPool")
            .field("buffers", &self.buffers)
            .field("lender", &self.lender.is_some())
            .finish()
    }
}

impl FieldPool {
    /// Most buffers kept (an interface node sends one field per subdomain it serves).
    pub const CAPACITY: usize = BufferPool::CAPACITY;

    /// Smallest field (in values, 64 KiB) whose memory is asked of the lender: the boundary
    /// fields (MBs) and the macro data (tens of kB) are, small fields are not.
    pub const LEND_MIN: usize = 8 << 10;

    /// From now on, fields of [`Self::LEND_MIN`] values or more are written into blocks `lender`
    /// lends (into pooled vectors when it has none to give).
    pub fn lend_from(&mut self, lender: Arc<dyn BlockLender>) {
        self.lender = Some(lender);
    }

    /// Memory for `len` values: a lent block (whatever it holds) when `lend`, or a pooled vector
    /// (empty).
    fn take(&mut self, len: usize, lend: bool) -> Values {
        let lent = match &self.lender {
            Some(lender) if lend && len >= Self::LEND_MIN => lender.lend(len),
            _ => None,
        };
        match lent {
            Some(block) => Values::lent(block),
            None => self.buffers.take_empty(len).into(),
        }
    }

    /// [`field_of`] into memory [`Self::take`] gives.
    fn copy_of(&mut self, m: MatRef<'_, f64>, lend: bool) -> Field {
        let mut data = self.take(m.nrows() * m.ncols(), lend);
        if data.is_lent() {
            write_columns(&mut data, m);
        } else {
            extend_columns(data.vec_mut(), m);
        }
        Field {
            rows: m.nrows() as u32,
            cols: m.ncols() as u32,
            data,
        }
    }

    /// [`field_of`] into a pooled buffer, never a lent block: for a message its receiver keeps
    /// (e.g. the final solutions, which the launcher holds until the end of the run), whose lent
    /// blocks would stay taken while the next messages need new ones.
    pub fn field_of_unlent(&mut self, m: MatRef<'_, f64>) -> Field {
        self.copy_of(m, false)
    }

    /// [`field_of`] into a pooled buffer (or a lent block).
    pub fn field_of(&mut self, m: MatRef<'_, f64>) -> Field {
        self.copy_of(m, true)
    }

    /// A `rows` × `cols` field in a pooled buffer (or a lent block), filled by `fill` (which
    /// sees it as a matrix of zeros): the field is written in place, with no matrix of its own to
    /// copy from.
    pub fn field_with(&mut self, rows: usize, cols: usize, fill: impl FnOnce(MatMut<'_, f64>)) -> Field {
        let mut data = self.take(rows * cols, true);
        zero(&mut data, rows * cols);
        fill(MatMut::from_column_major_slice_mut(&mut data, rows, cols));
        Field {
            rows: rows as u32,
            cols: cols as u32,
            data,
        }
    }

    /// [`Self::field_with`] for several fields at once: field `i` is `rows[i]` × `cols`, in a
    /// pooled buffer (or a lent block), filled by `fill(i, field)` (which sees a matrix of
    /// zeros). The buffers are taken here in order; the zeroing and the filling (and with them
    /// the first touch of new memory) run in parallel, one field per task.
    pub fn fields_with(
        &mut self,
        rows: &[usize],
        cols: usize,
        fill: impl Fn(usize, MatMut<'_, f64>) + Sync,
    ) -> Vec<Field> {
        let mut data: Vec<Values> = rows.iter().map(|&r| self.take(r * cols, true)).collect();
        data.par_iter_mut()
            .zip(rows.par_iter())
            .enumerate()
            .for_each(|(i, (d, &r))| {
                zero(d, r * cols);
                fill(i, MatMut::from_column_major_slice_mut(d, r, cols));
            });
        data.into_iter()
            .zip(rows)
            .map(|(data, &r)| Field {
                rows: r as u32,
                cols: cols as u32,
                data,
            })
            .collect()
    }

    /// Keeps the field buffers of a delivered message, up to [`Self::CAPACITY`].
    pub fn recycle(&mut self, msg: Message) {
        self.buffers.recycle(msg.payload);
    }

    /// Number of buffers held.
    pub fn len(&self) -> usize {
        self.buffers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.buffers.is_empty()
    }
}

/// `len` zeros in `data` (taken by [`FieldPool::take`]: a lent block of `len` values, or an
/// empty vector).
fn zero(data: &mut Values, len: usize) {
    if data.is_lent() {
        data.fill(0.0);
    } else {
        data.vec_mut().resize(len, 0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glissade_messages::{Envelope, NodeId, Payload, Role, Stage, SCHEMA_VERSION};

    /// Several fields filled in parallel are the fields `field_with` makes one by one, in the
    /// order of `rows`, and reuse the pool's buffers.
    #[test]
    fn fields_with_matches_field_with() {
        let fill = |i: usize, mut m: MatMut<'_, f64>| {
            for c in 0..m.ncols() {
                for r in 0..m.nrows() {
                    m[(r, c)] = (i * 1000 + r * 10 + c) as f64 + 0.25;
                }
            }
        };
        let rows = [3, 0, 7, 5];
        let mut one_by_one = FieldPool::default();
        let expected: Vec<Field> = rows
            .iter()
            .enumerate()
            .map(|(i, &r)| one_by_one.field_with(r, 4, |m| fill(i, m)))
            .collect();
        let mut pool = FieldPool::default();
        let got = pool.fields_with(&rows, 4, fill);
        assert_eq!(got, expected);
        // Given back, the buffers hold the next fields (no new memory for fields that fit).
        let addresses: Vec<*const f64> = got
            .iter()
            .filter(|f| !f.data.is_empty())
            .map(|f| f.data.as_ptr())
            .collect();
        for f in got {
            pool.buffers.put(f.data.into_vec().expect("owned"));
        }
        let again = pool.fields_with(&[3, 7, 5], 4, |_, _| {});
        for f in &again {
            assert!(
                addresses.contains(&f.data.as_ptr()),
                "a new buffer for a field of {} rows",
                f.rows
            );
            assert!(f.data.iter().all(|&v| v == 0.0), "a reused buffer is zeroed");
        }
    }

    /// Lends blocks in vectors of their own, as long as it has some left.
    struct Lender(std::sync::Mutex<usize>);

    impl BlockLender for Lender {
        fn lend(&self, len: usize) -> Option<Box<dyn glissade_messages::ValueBlock>> {
            let mut left = self.0.lock().unwrap();
            // Whatever the memory held: the pool must overwrite or zero all of it.
            (*left > 0).then(|| {
                *left -= 1;
                Box::new(vec![f64::NAN; len]) as Box<dyn glissade_messages::ValueBlock>
            })
        }
    }

    /// With a lender, fields of `LEND_MIN` values or more are written into its blocks (whatever
    /// they held) and are the fields made without one; smaller fields, and fields the lender has
    /// no block for, take vectors; a lent block does not go back to the pool.
    #[test]
    fn lent_fields_are_the_fields_made_without_a_lender() {
        let rows = FieldPool::LEND_MIN / 10 + 1;
        let big = Mat::from_fn(rows, 10, |r, c| (r * 10 + c) as f64 * 0.5);
        let fill = |i: usize, mut m: MatMut<'_, f64>| m[(i, 1)] = 2.0 + i as f64;
        let make = |pool: &mut FieldPool| {
            let mut made = vec![pool.field_of(big.as_ref()), pool.field_of(big.transpose())];
            made.push(pool.field_with(rows, 10, |m| fill(7, m)));
            made.extend(pool.fields_with(&[rows, 3, rows], 10, fill));
            made
        };
        let expected = make(&mut FieldPool::default());
        let mut pool = FieldPool::default();
        pool.lend_from(Arc::new(Lender(std::sync::Mutex::new(4))));
        let got = make(&mut pool);
        assert_eq!(got, expected);
        assert!(!pool.field_of_unlent(big.as_ref()).data.is_lent());
        let lent: Vec<bool> = got.iter().map(|f| f.data.is_lent()).collect();
        // The fifth large field finds the lender out of blocks; the 3-row one is too small.
        assert_eq!(lent, [true, true, true, true, false, false]);
        let mut got = got.into_iter();
        pool.recycle(message(Payload::BoundaryState {
            to: None,
            interfaces: vec![0],
            subdomain: 0,
            w: got.next().unwrap(),
            f: got.nth(3).unwrap(),
        }));
        assert_eq!(
            pool.len(),
            1,
            "the vector goes back to the pool, the lent block does not"
        );
    }

    fn message(payload: Payload) -> Message {
        Message {
            envelope: Envelope {
                schema_version: SCHEMA_VERSION,
                run_id: "r".into(),
                scene_fingerprint: 0,
                iteration: 0,
                stage: Stage::Linear,
                sender: NodeId {
                    role: Role::Subdomain,
                    index: 0,
                },
            },
            payload,
        }
    }

    #[test]
    fn copies_are_column_major_whatever_the_strides() {
        let m = Mat::from_fn(3, 4, |r, c| (10 * r + c) as f64);
        let f = field_of(m.as_ref());
        assert_eq!((f.rows(), f.cols()), (3, 4));
        assert_eq!(f.data[..4], [0.0, 10.0, 20.0, 1.0]);
        assert_eq!(mat_of(&f), m);
        // A transposed view has no contiguous columns: the element-wise path.
        let t = field_of(m.transpose());
        assert_eq!((t.rows(), t.cols()), (4, 3));
        assert_eq!(mat_of(&t), m.transpose().to_owned());
        let mut back = Mat::zeros(3, 4);
        copy_into(&f, &mut back);
        assert_eq!(back, m);
        let mut pool = FieldPool::default();
        assert_eq!(pool.field_of(m.transpose()), t);
    }

    #[test]
    fn a_recycled_buffer_holds_the_next_field_of_its_size() {
        let mut pool = FieldPool::default();
        let big = Mat::from_fn(50, 20, |r, c| (r * c) as f64);
        let small = Mat::from_fn(5, 20, |r, c| (r + c) as f64);
        let w = pool.field_of(big.as_ref());
        let f = pool.field_of(small.as_ref());
        let (w_at, f_at) = (w.data.as_ptr(), f.data.as_ptr());
        pool.recycle(message(Payload::BoundaryState {
            subdomain: 0,
            to: None,
            interfaces: vec![0],
            w,
            f,
        }));
        assert_eq!(pool.len(), 2);
        // The small field takes the small buffer (the smallest that fits), the big one the other.
        let f2 = pool.field_of(small.as_ref());
        let w2 = pool.field_with(50, 20, |mut m| m.copy_from(big.as_ref()));
        assert_eq!((w2.data.as_ptr(), f2.data.as_ptr()), (w_at, f_at));
        assert_eq!((mat_of(&w2), mat_of(&f2)), (big.clone(), small));
        assert!(pool.is_empty());
        // A field larger than any pooled buffer gets a new one, and so does a field less than
        // half the size of every pooled buffer; field_with starts from zeros.
        pool.recycle(message(Payload::MacroForces {
            subdomain: 0,
            forces: f2,
        }));
        let z = pool.field_with(60, 20, |_| {});
        assert!(z.data.iter().all(|&v| v == 0.0) && z.data.len() == 1200);
        let tiny = pool.field_with(2, 20, |_| {});
        assert_ne!(tiny.data.as_ptr(), f_at);
        assert_eq!(pool.len(), 1);
        // Messages without fields give nothing; the pool is bounded.
        pool.recycle(message(Payload::AndersonStep {
            gamma: vec![1.0],
            restart: false,
        }));
        assert_eq!(pool.len(), 1);
        for _ in 0..2 * FieldPool::CAPACITY {
            let w = pool.field_with(2, 2, |_| {});
            let f = field_of(big.as_ref());
            pool.recycle(message(Payload::BoundaryState {
                subdomain: 0,
                to: None,
                interfaces: vec![0],
                w,
                f,
            }));
        }
        assert_eq!(pool.len(), FieldPool::CAPACITY);
    }
}
