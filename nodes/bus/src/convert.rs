//! Conversions between wire fields and faer matrices.

use faer::{Mat, MatRef};
use glissade_messages::Field;

/// Wire field of a matrix (column-major copy).
pub fn field_of(m: MatRef<'_, f64>) -> Field {
    Field::from_fn(m.nrows(), m.ncols(), |r, c| m[(r, c)])
}

/// Matrix of a wire field.
pub fn mat_of(f: &Field) -> Mat<f64> {
    Mat::from_fn(f.rows(), f.cols(), |r, c| f.get(r, c))
}

/// Copies a wire field into a matrix of the same shape.
pub fn copy_into(f: &Field, m: &mut Mat<f64>) {
    let rows = f.rows();
    for c in 0..f.cols() {
        for r in 0..rows {
            m[(r, c)] = f.data[c * rows + r];
        }
    }
}
