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

    pub fn is_lent(&self) -> bool {
        matches!(self.0, Repr::Lent(_))
    }

    /// The vector holding the values, to resize them or hand them to a pool: a lent block's
    /// values are first copied into one.
    pub fn vec_mut(&mut self) -> &mut Vec<f64> {
        if let Repr::Lent(b) = &self.0 {
            self.0 = Repr::Owned(b.values().to_vec());
        }
        match &mut self.0 {
            Repr::Owned(v) => v,
            Repr::Lent(_) => unreachable!("copied into a vector above"),
        }
    }

    /// The vector holding the values, or None for a lent block (which goes back to its lender
    /// when dropped, not to a pool).
    pub fn into_vec(self) -> Option<Vec<f64>> {
        match self.0 {
            Repr::Owned(v) => Some(v),
            Repr::Lent(_) => None,
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
        }
    }
}

impl DerefMut for Values {
    fn deref_mut(&mut self) -> &mut [f64] {
        match &mut self.0 {
            Repr::Owned(v) => v,
            Repr::Lent(b) => b.values_mut(),
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

/// A lent block in a vector of its own, for tests.
#[cfg(test)]
pub(crate) struct TestBlock(pub Vec<f64>);

#[cfg(test)]
impl ValueBlock for TestBlock {
    fn values(&self) -> &[f64] {
        &self.0
    }
    fn values_mut(&mut self) -> &mut [f64] {
        &mut self.0
    }
    fn into_any(self: Box<Self>) -> Box<dyn Any> {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lent_values_read_write_compare_and_copy_like_owned_ones() {
        let mut lent = Values::lent(Box::new(TestBlock(vec![7.0; 3])));
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
        let mut lent2 = Values::lent(Box::new(TestBlock(vec![4.0])));
        let block = lent2.take_block().expect("a lent block");
        assert_eq!(block.values(), &[4.0]);
        assert!(lent2.is_empty() && !lent2.is_lent());
        assert!(Values::lent(Box::new(TestBlock(vec![1.0]))).into_vec().is_none());
        // vec_mut copies a lent block into a vector first.
        let mut grown = Values::lent(Box::new(TestBlock(vec![5.0])));
        grown.vec_mut().push(6.0);
        assert!(!grown.is_lent());
        assert_eq!(grown, vec![5.0, 6.0]);
    }
}
