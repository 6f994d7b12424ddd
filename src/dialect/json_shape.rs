//! The JSON shape of mavlink2rest for the generated dialect (used through
//! `build.rs::json_shape`, which points the generated types here when the
//! crate's `serde` feature is on).
//!
//! Owns two field shapes the generated derives would get wrong for Cockpit:
//! bitflags as `{"bits":N}` (Cockpit reads `base_mode.bits` and sends
//! `base_mode:{bits:…}`) and char arrays as arrays of one-character strings
//! padded with `"\u0000"` (Cockpit sends `param_id` that way). Enums keep the
//! generated `{"type":"NAME"}` and messages `{"type":"HEARTBEAT", …}`.
//! Never panics on input: a wrong shape is a deserialisation error.

/// A bitflags value on the wire of mavlink2rest: `{"bits":N}`. Unknown bits
/// are kept, as the binary parser keeps them.
#[cfg(feature = "serde")]
#[derive(serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bits<T> {
    pub bits: T,
}

/// `Serialize`/`Deserialize` for a generated bitflags type as [`Bits`].
macro_rules! bits_serde {
    ($name:ident, $bits:ty) => {
        #[cfg(feature = "serde")]
        impl ::serde::Serialize for $name {
            fn serialize<S: ::serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                ::serde::Serialize::serialize(
                    &crate::dialect::json_shape::Bits::<$bits> { bits: self.bits() },
                    s,
                )
            }
        }
        #[cfg(feature = "serde")]
        impl<'de> ::serde::Deserialize<'de> for $name {
            fn deserialize<D: ::serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                let b: crate::dialect::json_shape::Bits<$bits> =
                    ::serde::Deserialize::deserialize(d)?;
                Ok(Self::from_bits_retain(b.bits))
            }
        }
    };
}
pub(crate) use bits_serde;

/// A MAVLink `char[N]` as an array of N one-character strings (bytes as
/// Latin-1, NUL padding kept); read back from such an array (shorter ones
/// are padded with NUL) or from a plain string.
#[cfg(feature = "serde")]
pub mod chars {
    use std::fmt;

    use mavlink_core::types::CharArray;
    use serde::de::{self, SeqAccess, Visitor};
    use serde::ser::SerializeSeq as _;
    use serde::{Deserializer, Serializer};

    pub fn serialize<S: Serializer, const N: usize>(
        value: &CharArray<N>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(N))?;
        for &b in value.iter() {
            seq.serialize_element(&char::from(b))?;
        }
        seq.end()
    }

    pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(
        d: D,
    ) -> Result<CharArray<N>, D::Error> {
        d.deserialize_any(CharsVisitor::<N>)
    }

    struct CharsVisitor<const N: usize>;

    fn byte_of<E: de::Error>(s: &str) -> Result<u8, E> {
        let mut it = s.chars();
        match (it.next(), it.next()) {
            (Some(c), None) => u8::try_from(u32::from(c))
                .map_err(|_| E::custom(format!("character {c:?} is not a MAVLink char (0..=255)"))),
            _ => Err(E::custom(format!(
                "{s:?} is not one character: a MAVLink char array is an array of one-character strings"
            ))),
        }
    }

    impl<'de, const N: usize> Visitor<'de> for CharsVisitor<N> {
        type Value = CharArray<N>;

        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(
                f,
                "at most {N} one-character strings, or a string of at most {N} bytes"
            )
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
            let mut data = [0u8; N];
            let mut i = 0;
            while let Some(s) = seq.next_element::<std::borrow::Cow<'de, str>>()? {
                let slot = data
                    .get_mut(i)
                    .ok_or_else(|| de::Error::invalid_length(i + 1, &self))?;
                *slot = byte_of(&s)?;
                i += 1;
            }
            Ok(CharArray::new(data))
        }

        fn visit_str<E: de::Error>(self, s: &str) -> Result<Self::Value, E> {
            if s.len() > N {
                return Err(E::invalid_length(s.len(), &self));
            }
            let mut data = [0u8; N];
            data[..s.len()].copy_from_slice(s.as_bytes());
            Ok(CharArray::new(data))
        }
    }
}
