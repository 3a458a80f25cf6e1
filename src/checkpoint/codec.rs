//! The checkpoint's little-endian binary codec: every value is written as
//! fixed-width little-endian bytes (`f64` by its bit pattern, so it
//! round-trips exactly, NaN payloads included), sequences with a `u64`
//! length in front. Decoding never trusts a length further than the bytes
//! that are left, so a damaged payload is an error, not a huge allocation.

/// Appends values to a byte buffer.
#[derive(Default)]
pub struct Writer {
    bytes: Vec<u8>,
}

impl Writer {
    /// The bytes written so far.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    /// Append raw bytes.
    fn raw(&mut self, bytes: &[u8]) {
        self.bytes.extend_from_slice(bytes);
    }

    /// Append any encodable value.
    pub fn put<T: Codec>(&mut self, value: &T) {
        value.encode(self);
    }
}

/// Reads values back in the order they were written.
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

/// Why a payload could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} at byte {at}")]
pub struct DecodeError {
    /// What was wrong.
    pub what: &'static str,
    /// Offset in the payload where it was found.
    pub at: usize,
}

impl<'a> Reader<'a> {
    /// A reader over `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn fail<T>(&self, what: &'static str) -> Result<T, DecodeError> {
        Err(DecodeError { what, at: self.at })
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        if self.remaining() < N {
            return self.fail("payload ends inside a value");
        }
        let mut out = [0u8; N];
        out.copy_from_slice(&self.bytes[self.at..self.at + N]);
        self.at += N;
        Ok(out)
    }

    /// Read any decodable value.
    pub fn get<T: Codec>(&mut self) -> Result<T, DecodeError> {
        T::decode(self)
    }

    /// A sequence length, refused when the bytes left could not hold it
    /// (every element takes at least `min_size` bytes).
    fn length(&mut self, min_size: usize) -> Result<usize, DecodeError> {
        let n = u64::from_le_bytes(self.take()?);
        let n = usize::try_from(n).or_else(|_| self.fail("sequence length overflows"))?;
        if n.saturating_mul(min_size.max(1)) > self.remaining() {
            return self.fail("sequence longer than the payload");
        }
        Ok(n)
    }

    /// Fail unless every byte was read.
    pub fn finish(self) -> Result<(), DecodeError> {
        if self.remaining() == 0 {
            Ok(())
        } else {
            self.fail("bytes left after the last value")
        }
    }
}

/// A value with a fixed little-endian encoding.
pub trait Codec: Sized {
    /// Smallest encoded size in bytes (bounds sequence lengths on decoding).
    const MIN_SIZE: usize;
    /// Append the encoding of `self`.
    fn encode(&self, w: &mut Writer);
    /// Read a value written by [`Codec::encode`].
    fn decode(r: &mut Reader) -> Result<Self, DecodeError>;
}

macro_rules! number {
    ($($t:ty),*) => {$(
        impl Codec for $t {
            const MIN_SIZE: usize = std::mem::size_of::<$t>();
            fn encode(&self, w: &mut Writer) {
                w.raw(&self.to_le_bytes());
            }
            fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
                Ok(<$t>::from_le_bytes(r.take()?))
            }
        }
    )*};
}

number!(u8, u16, u32, u64);

impl Codec for f64 {
    const MIN_SIZE: usize = 8;
    fn encode(&self, w: &mut Writer) {
        w.raw(&self.to_bits().to_le_bytes());
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(f64::from_bits(u64::from_le_bytes(r.take()?)))
    }
}

impl Codec for usize {
    const MIN_SIZE: usize = 8;
    fn encode(&self, w: &mut Writer) {
        (*self as u64).encode(w);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        let v = u64::decode(r)?;
        usize::try_from(v).or_else(|_| r.fail("index overflows usize"))
    }
}

impl Codec for bool {
    const MIN_SIZE: usize = 1;
    fn encode(&self, w: &mut Writer) {
        u8::from(*self).encode(w);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        match u8::decode(r)? {
            0 => Ok(false),
            1 => Ok(true),
            _ => r.fail("invalid boolean"),
        }
    }
}

impl Codec for String {
    const MIN_SIZE: usize = 8;
    fn encode(&self, w: &mut Writer) {
        self.len().encode(w);
        w.raw(self.as_bytes());
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        let n = r.length(1)?;
        let bytes = r.bytes[r.at..r.at + n].to_vec();
        r.at += n;
        String::from_utf8(bytes).or_else(|_| r.fail("invalid UTF-8 text"))
    }
}

impl<T: Codec, const N: usize> Codec for [T; N] {
    const MIN_SIZE: usize = N * T::MIN_SIZE;
    fn encode(&self, w: &mut Writer) {
        self.iter().for_each(|v| v.encode(w));
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        let values: Vec<T> = (0..N).map(|_| T::decode(r)).collect::<Result<_, _>>()?;
        values
            .try_into()
            .or_else(|_| r.fail("array of the wrong length"))
    }
}

impl<T: Codec> Codec for Vec<T> {
    const MIN_SIZE: usize = 8;
    fn encode(&self, w: &mut Writer) {
        self.len().encode(w);
        self.iter().for_each(|v| v.encode(w));
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        let n = r.length(T::MIN_SIZE)?;
        (0..n).map(|_| T::decode(r)).collect()
    }
}

impl<T: Codec> Codec for Option<T> {
    const MIN_SIZE: usize = 1;
    fn encode(&self, w: &mut Writer) {
        self.is_some().encode(w);
        if let Some(v) = self {
            v.encode(w);
        }
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok(if bool::decode(r)? {
            Some(T::decode(r)?)
        } else {
            None
        })
    }
}

impl<A: Codec, B: Codec> Codec for (A, B) {
    const MIN_SIZE: usize = A::MIN_SIZE + B::MIN_SIZE;
    fn encode(&self, w: &mut Writer) {
        self.0.encode(w);
        self.1.encode(w);
    }
    fn decode(r: &mut Reader) -> Result<Self, DecodeError> {
        Ok((A::decode(r)?, B::decode(r)?))
    }
}

/// 64-bit FNV-1a hash (the scene fingerprint of a checkpoint).
pub fn fnv1a64(parts: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for part in parts {
        // the length first, so ("ab", "c") and ("a", "bc") differ
        for b in (part.len() as u64).to_le_bytes().iter().chain(part.iter()) {
            h ^= u64::from(*b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_bit_exactly() {
        let floats = vec![0.1, -0.0, f64::MIN_POSITIVE / 3.0, f64::INFINITY, 1e300];
        let nan = f64::from_bits(0x7ff8_dead_beef_0001);
        let mut w = Writer::default();
        w.put(&floats);
        w.put(&nan);
        w.put(&Some([1u16, 2]));
        w.put(&None::<usize>);
        w.put(&"κ̄ α".to_string());
        w.put(&(usize::MAX, true));
        let bytes = w.into_bytes();
        let mut r = Reader::new(&bytes);
        let back: Vec<f64> = r.get().unwrap();
        assert_eq!(
            back.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            floats.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(r.get::<f64>().unwrap().to_bits(), nan.to_bits());
        assert_eq!(r.get::<Option<[u16; 2]>>().unwrap(), Some([1, 2]));
        assert_eq!(r.get::<Option<usize>>().unwrap(), None);
        assert_eq!(r.get::<String>().unwrap(), "κ̄ α");
        assert_eq!(r.get::<(usize, bool)>().unwrap(), (usize::MAX, true));
        r.finish().unwrap();
    }

    #[test]
    fn a_length_beyond_the_payload_is_refused_before_allocating() {
        let mut w = Writer::default();
        w.put(&(u64::MAX / 2));
        let bytes = w.into_bytes();
        let err = Reader::new(&bytes).get::<Vec<f64>>().unwrap_err();
        assert_eq!(err.what, "sequence longer than the payload");
        let cut = {
            let mut w = Writer::default();
            w.put(&vec![1.0f64, 2.0]);
            let mut b = w.into_bytes();
            b.pop();
            b
        };
        assert!(Reader::new(&cut).get::<Vec<f64>>().is_err());
    }
}
