//! The values of a [`crate::Field`]: a vector of its own, or a block of memory a transport lent
//! the field to be written into and sent from without a copy (e.g. a buffer of a shared-memory
//! pool, [`BlockLender`]).

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::any::Any;
use std::fmt;
use std::ops::{Deref, DerefMut};

/// Memory lent by a transport to hold a field's values, which it can then send without copying
/// them. Its values are whatever the memory held until they are written.
pub trait ValueBlock: Send + Sync {
    fn values(&self) -> &[f64];
    fn values_mut(&mut self) -> &mut [f64];
    /// The block as the transport's own type, to send it.
    fn into_any(self: Box<Self>) -> Box<dyn Any>;
}

/// Memory a field's values were received in and are read from where they lie (e.g. a block of
/// the sender's shared-memory pool), held as long as the field is.
pub trait HeldBlock: Send + Sync {
    fn values(&self) -> &[f64];
}

/// Lends [`ValueBlock`]s: a node's fields are written straight into them.
pub trait BlockLender: Send + Sync {
    /// A block of exactly `len` values, or None (no room; the field then takes a vector).
    fn lend(&self, len: usize) -> Option<Box<dyn ValueBlock>>;
}

/// A field's values, column-major. Reads and writes as a slice; [`Clone`], comparison, serde and
/// the wire form do not depend on where the values are.
#[derive(Default)]
pub struct Values(Repr);

enum Repr {
    Owned(Vec<f64>),
    Lent(Box<dyn ValueBlock>),
    /// Read only: a write first copies the values into a vector ([`Values::vec_mut`]).
    Held(Box<dyn HeldBlock>),
}

impl Default for Repr {
    fn default() -> Self {
        Repr::Owned(Vec::new())
    }
}

impl Values {
    /// Values in a lent block.
    pub fn lent(block: Box<dyn ValueBlock>) -> Self {
        Self(Repr::Lent(block))
    }

    /// Values read where they were received.
    pub fn held(block: Box<dyn HeldBlock>) -> Self {
        Self(Repr::Held(block))
    }

    pub fn is_lent(&self) -> bool {
        matches!(self.0, Repr::Lent(_))
    }

    pub fn is_held(&self) -> bool {
        matches!(self.0, Repr::Held(_))
    }

    /// The vector holding the values, to resize them or hand them to a pool: a lent or held
    /// block's values are first copied into one.
    pub fn vec_mut(&mut self) -> &mut Vec<f64> {
        if !matches!(self.0, Repr::Owned(_)) {
            self.0 = Repr::Owned(self.to_vec());
        }
        match &mut self.0 {
            Repr::Owned(v) => v,
            _ => unreachable!("copied into a vector above"),
        }
    }

    /// The vector holding the values, or None for a lent or held block (which goes back to
    /// its lender, or is released to its sender, when dropped, not to a pool).
    pub fn into_vec(self) -> Option<Vec<f64>> {
        match self.0 {
            Repr::Owned(v) => Some(v),
            Repr::Lent(_) | Repr::Held(_) => None,
        }
    }

    /// Takes a lent block out, leaving no values; None (and the values unchanged) otherwise.
    pub fn take_block(&mut self) -> Option<Box<dyn ValueBlock>> {
        match std::mem::take(&mut self.0) {
            Repr::Lent(b) => Some(b),
            other => {
                self.0 = other;
                None
            }
        }
    }
}

impl From<Vec<f64>> for Values {
    fn from(v: Vec<f64>) -> Self {
        Self(Repr::Owned(v))
    }
}

impl FromIterator<f64> for Values {
    fn from_iter<I: IntoIterator<Item = f64>>(iter: I) -> Self {
        Vec::from_iter(iter).into()
    }
}

impl<'a> IntoIterator for &'a Values {
    type Item = &'a f64;
    type IntoIter = std::slice::Iter<'a, f64>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl Deref for Values {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        match &self.0 {
            Repr::Owned(v) => v,
            Repr::Lent(b) => b.values(),
            Repr::Held(b) => b.values(),
        }
    }
}

impl DerefMut for Values {
    /// Held values are first copied into a vector of their own.
    fn deref_mut(&mut self) -> &mut [f64] {
        if let Repr::Held(_) = self.0 {
            return self.vec_mut();
        }
        match &mut self.0 {
            Repr::Owned(v) => v,
            Repr::Lent(b) => b.values_mut(),
            Repr::Held(_) => unreachable!("copied above"),
        }
    }
}

impl Clone for Values {
    /// A copy in a vector of its own (also of a lent block).
    fn clone(&self) -> Self {
        Self(Repr::Owned(self.to_vec()))
    }
}

impl PartialEq for Values {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl PartialEq<Vec<f64>> for Values {
    fn eq(&self, other: &Vec<f64>) -> bool {
        **self == other[..]
    }
}

impl PartialEq<Values> for Vec<f64> {
    fn eq(&self, other: &Values) -> bool {
        self[..] == **other
    }
}

impl fmt::Debug for Values {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&**self, f)
    }
}

impl Serialize for Values {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        (**self).serialize(s)
    }
}

impl<'de> Deserialize<'de> for Values {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Vec::<f64>::deserialize(d).map(Values::from)
    }
}

/// A block in a vector of its own (e.g. a lender in a test, or one without shared memory).
impl ValueBlock for Vec<f64> {
    fn values(&self) -> &[f64] {
        self
    }
    fn values_mut(&mut self) -> &mut [f64] {
        self
    }
    fn into_any(self: Box<Self>) -> Box<dyn Any> {
        self
    }
}

/// Values held in a shared vector.
impl HeldBlock for std::sync::Arc<Vec<f64>> {
    fn values(&self) -> &[f64] {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lent_values_read_write_compare_and_copy_like_owned_ones() {
        let mut lent = Values::lent(Box::new(vec![7.0; 3]));
        lent.copy_from_slice(&[1.0, 2.0, 3.0]);
        let owned = Values::from(vec![1.0, 2.0, 3.0]);
        assert!(lent.is_lent() && !owned.is_lent());
        assert_eq!(lent, owned);
        assert_eq!(format!("{lent:?}"), format!("{owned:?}"));
        let copy = lent.clone();
        assert!(!copy.is_lent(), "a copy holds a vector of its own");
        assert_eq!(copy, vec![1.0, 2.0, 3.0]);
        // A lent block is not a pool's: into_vec refuses it; take_block hands it back.
        let mut taken = lent.clone();
        assert!(taken.take_block().is_none() && taken.len() == 3);
        let mut lent2 = Values::lent(Box::new(vec![4.0]));
        let block = lent2.take_block().expect("a lent block");
        assert_eq!(block.values(), &[4.0]);
        assert!(lent2.is_empty() && !lent2.is_lent());
        assert!(Values::lent(Box::new(vec![1.0])).into_vec().is_none());
        // vec_mut copies a lent block into a vector first.
        let mut grown = Values::lent(Box::new(vec![5.0]));
        grown.vec_mut().push(6.0);
        assert!(!grown.is_lent());
        assert_eq!(grown, vec![5.0, 6.0]);
    }

    /// Held values read like owned ones; a write copies them into a vector of their own first.
    #[test]
    fn held_values_are_read_in_place_and_copied_on_write() {
        let mut held = Values::held(Box::new(std::sync::Arc::new(vec![1.0, 2.0])));
        assert!(held.is_held() && held == vec![1.0, 2.0]);
        let at = held.as_ptr();
        held[1] = 3.0;
        assert!(!held.is_held() && held.as_ptr() != at);
        assert_eq!(held, vec![1.0, 3.0]);
        assert!(Values::held(Box::new(std::sync::Arc::new(vec![1.0])))
            .into_vec()
            .is_none());
    }
}
