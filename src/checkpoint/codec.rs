//! The checkpoint payload's binary encoding: the serde derive of
//! [`super::SavedState`] written by `bincode` with fixed-width little-endian
//! integers (`f64` by its bit pattern, so it round-trips exactly, NaN
//! payloads included) and sequences with a `u64` length in front. Decoding
//! is limited to the payload's length and refuses bytes left over, so a
//! damaged payload is an error, not a huge allocation.

use bincode::Options;

/// The payload encoding (decode with `.with_limit(payload length)`).
pub fn options() -> impl Options + Copy {
    bincode::DefaultOptions::new()
        .with_fixint_encoding()
        .with_little_endian()
        .reject_trailing_bytes()
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
        type Values = (
            Vec<f64>,
            f64,
            Option<[u16; 2]>,
            Option<usize>,
            String,
            (usize, bool),
        );
        let values: Values = (
            floats.clone(),
            nan,
            Some([1, 2]),
            None,
            "κ̄ α".to_string(),
            (usize::MAX, true),
        );
        let bytes = options().serialize(&values).unwrap();
        let back: Values = options().deserialize(&bytes).unwrap();
        assert_eq!(
            back.0.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            floats.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(back.1.to_bits(), nan.to_bits());
        assert_eq!(back.2, Some([1, 2]));
        assert_eq!(back.3, None);
        assert_eq!(back.4, "κ̄ α");
        assert_eq!(back.5, (usize::MAX, true));
    }

    #[test]
    fn a_length_beyond_the_payload_is_refused_before_allocating() {
        let bytes = (u64::MAX / 2).to_le_bytes();
        let limited = options().with_limit(bytes.len() as u64);
        assert!(limited.deserialize::<Vec<f64>>(&bytes).is_err());
        let mut cut = options().serialize(&vec![1.0f64, 2.0]).unwrap();
        cut.pop();
        assert!(options().deserialize::<Vec<f64>>(&cut).is_err());
        let mut longer = options().serialize(&vec![1.0f64]).unwrap();
        longer.push(0);
        assert!(options().deserialize::<Vec<f64>>(&longer).is_err());
    }
}
