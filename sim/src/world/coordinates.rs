//! A point of `D` axes in a world file: a list of exactly `D` numbers (serde's own arrays stop short of
//! const-generic lengths).

use serde::de::{Error, SeqAccess, Visitor};
use serde::{Deserializer, Serializer};
use std::fmt;

/// Writes the point as a list.
pub fn serialize<S: Serializer, const D: usize>(point: &[f64; D], serializer: S) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(point)
}

/// Reads a list of exactly `D` numbers.
pub fn deserialize<'de, De: Deserializer<'de>, const D: usize>(deserializer: De) -> Result<[f64; D], De::Error> {
    struct Coordinates<const D: usize>;

    impl<'de, const D: usize> Visitor<'de> for Coordinates<D> {
        type Value = [f64; D];

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "a point of {D} coordinates")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[f64; D], A::Error> {
            let mut point = [0.0; D];
            for (i, x) in point.iter_mut().enumerate() {
                *x = seq.next_element()?.ok_or_else(|| A::Error::invalid_length(i, &self))?;
            }
            match seq.next_element::<f64>()? {
                None => Ok(point),
                Some(_) => Err(A::Error::invalid_length(D + 1, &self)),
            }
        }
    }

    deserializer.deserialize_seq(Coordinates::<D>)
}
