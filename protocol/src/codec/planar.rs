//! Integer planes predicted from their neighbours, then packed: the shared
//! back end of the quantised codecs ([`super::depth`], [`super::motion`]).
//!
//! Each value is predicted by LOCO-I's median edge detector from its left,
//! upper and upper-left neighbours (`a`, `b`, `c`): `min(a, b)` or
//! `max(a, b)` across an edge, `a + b − c` elsewhere. On a plane that is
//! affine in the pixel coordinates (what inverse depth is on a flat surface
//! and motion on a rigid object moving parallel to the image) it is exact
//! where the two gradients differ in sign or one is zero, and off by the
//! smaller gradient where they share a sign: the same residual at every
//! pixel of the plane. Either way flat and rigid regions cost almost
//! nothing. Residuals wrap in `i32` (lossless for any input) and are zigzag
//! mapped to small unsigned values.
//!
//! Most residuals are 0 (84 % of a 1280×720 depth plane of the `dolly`
//! scene; most of the rest is the quantiser's rounding, ±1), so they are
//! packed in two parts: a **significance map** (one bit a value, set where
//! the residual is not 0) and the non-zero residuals alone (zigzag − 1, in
//! byte planes), each compressed with zstd. zstd's literals are coded
//! order-0, one byte at a time: a byte of the map carries eight values'
//! zero/non-zero pattern, which one byte plane of every residual spreads
//! over eight bytes. On that plane, 53 KB a frame against 67 KB for the
//! byte planes of every residual, at the same zstd level (1).
//!
//! Payload: the map's compressed length (`u32`, little-endian), the map's
//! zstd frame (`⌈n/8⌉` bytes, value `i` in bit `i mod 8` of byte `i / 8`,
//! the unused bits 0), the residuals' zstd frame (4 bytes a set bit).

use super::CodecError;

/// The median edge detector's prediction of a value from its left (`a`),
/// upper (`b`) and upper-left (`c`) neighbours: the median of `a`, `b` and
/// `a + b − c`, i.e. `a + b − c` clamped to `[min(a, b), max(a, b)]` (if
/// `c ≥ max(a, b)` the sum is at most `min(a, b)`, if `c ≤ min(a, b)` at
/// least `max(a, b)`). Without branches, which the residuals' signs would
/// defeat; the sum is taken in `i64`, so it never wraps.
fn med(a: i32, b: i32, c: i32) -> i32 {
    let sum = i64::from(a) + i64::from(b) - i64::from(c);
    sum.clamp(i64::from(a.min(b)), i64::from(a.max(b))) as i32
}

/// Walks `values` in order, rows `width` wide, calling `f(i, prediction,
/// value)` with the prediction from the values before it; `f` may write the
/// value (the decoder does), which the next predictions then use.
fn predict_rows(values: &mut [i32], width: usize, mut f: impl FnMut(usize, i32, &mut i32)) {
    for start in (0..values.len()).step_by(width) {
        let (done, rest) = values.split_at_mut(start);
        let len = width.min(rest.len());
        let cur = &mut rest[..len];
        match done.len().checked_sub(width).map(|s| &done[s..]) {
            None => {
                for x in 0..len {
                    let pred = if x == 0 { 0 } else { cur[x - 1] };
                    f(start + x, pred, &mut cur[x]);
                }
            }
            Some(up) => {
                let up = &up[..len];
                f(start, up[0], &mut cur[0]);
                for x in 1..len {
                    let pred = med(cur[x - 1], up[x], up[x - 1]);
                    f(start + x, pred, &mut cur[x]);
                }
            }
        }
    }
}

fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

fn unzigzag(v: u32) -> i32 {
    ((v >> 1) as i32) ^ -((v & 1) as i32)
}

/// Bytes of the significance map of `count` values.
fn map_len(count: usize) -> usize {
    count.div_ceil(8)
}

/// Largest payload [`pack`] writes for `count` values: the length prefix
/// and the two zstd frames at their bounds.
pub(crate) fn max_packed_len(count: u64) -> u64 {
    let bound = super::zstd_compress_bound;
    4u64.saturating_add(bound(count.div_ceil(8)))
        .saturating_add(bound(count.saturating_mul(4)))
}

/// Packs `values` (planes `width` wide, row after row) at zstd `level`.
pub(crate) fn pack(values: &[i32], width: usize, level: i32) -> Result<Vec<u8>, CodecError> {
    let width = width.max(1);
    let mut scratch = values.to_vec();
    let mut residuals = vec![0u32; values.len()];
    predict_rows(&mut scratch, width, |i, pred, value| {
        residuals[i] = zigzag(value.wrapping_sub(pred));
    });
    let nonzero = residuals.iter().filter(|&&z| z != 0).count();
    let mut map = vec![0u8; map_len(values.len())];
    // Byte planes of the non-zero residuals (the high bytes of small
    // residuals are runs of zeros).
    let mut planes = vec![0u8; nonzero * 4];
    let mut k = 0;
    for (i, &z) in residuals.iter().enumerate() {
        if z != 0 {
            map[i / 8] |= 1 << (i % 8);
            for (b, byte) in (z - 1).to_le_bytes().into_iter().enumerate() {
                planes[b * nonzero + k] = byte;
            }
            k += 1;
        }
    }
    let map = super::zstd_compress(&map, level)?;
    let planes = super::zstd_compress(&planes, level)?;
    let map_bytes = u32::try_from(map.len()).map_err(|_| CodecError::WrongLength {
        got: map.len() as u64,
        expected: u64::from(u32::MAX),
    })?;
    let mut out = Vec::with_capacity(4 + map.len() + planes.len());
    out.extend_from_slice(&map_bytes.to_le_bytes());
    out.extend_from_slice(&map);
    out.extend_from_slice(&planes);
    Ok(out)
}

/// Inverse of [`pack`]: exactly `count` values, or an error.
pub(crate) fn unpack(encoded: &[u8], count: usize, width: usize) -> Result<Vec<i32>, CodecError> {
    let width = width.max(1);
    if count.checked_mul(4).is_none() {
        return Err(CodecError::WrongLength {
            got: 0,
            expected: u64::MAX,
        });
    }
    let malformed = CodecError::BadParameters("significance map");
    let (head, rest) = encoded.split_first_chunk::<4>().ok_or(malformed)?;
    let map_bytes = u32::from_le_bytes(*head) as usize;
    if map_bytes > rest.len() {
        return Err(CodecError::BadParameters("significance map"));
    }
    let (map, planes) = rest.split_at(map_bytes);
    let map = super::zstd_decompress(map, map_len(count))?;
    // Bits past the last value are 0, so the set bits count the residuals.
    let spare = map_len(count) * 8 - count;
    if spare > 0 && map.last().is_some_and(|&b| b >> (8 - spare) != 0) {
        return Err(CodecError::BadParameters("significance map"));
    }
    let nonzero: usize = map.iter().map(|b| b.count_ones() as usize).sum();
    let planes = super::zstd_decompress(planes, nonzero * 4)?;
    let (p0, rest) = planes.split_at(nonzero);
    let (p1, rest) = rest.split_at(nonzero);
    let (p2, p3) = rest.split_at(nonzero);
    // The residuals in place (bytes of the map that are 0, most of them,
    // are skipped whole), then the prediction without a branch on them.
    let mut residuals = vec![0i32; count];
    let mut k = 0;
    for (byte, &bits) in map.iter().enumerate() {
        let mut bits = bits;
        while bits != 0 {
            let i = byte * 8 + bits.trailing_zeros() as usize;
            let z = u32::from_le_bytes([p0[k], p1[k], p2[k], p3[k]]);
            residuals[i] = unzigzag(z.wrapping_add(1));
            k += 1;
            bits &= bits - 1;
        }
    }
    let mut values = vec![0i32; count];
    predict_rows(&mut values, width, |i, pred, value| {
        *value = pred.wrapping_add(residuals[i]);
    });
    Ok(values)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn an_affine_plane_costs_almost_nothing() -> Result<(), CodecError> {
        let (w, h) = (64usize, 48usize);
        // Gradients of opposite signs (exact) and of the same sign (a
        // constant residual).
        for (gx, gy) in [(7, -3), (7, 3)] {
            let plane: Vec<i32> = (0..w * h)
                .map(|i| 1000 + gx * (i % w) as i32 + gy * (i / w) as i32)
                .collect();
            let packed = pack(&plane, w, 1)?;
            assert!(
                packed.len() * 50 < plane.len() * 4,
                "{} bytes",
                packed.len()
            );
            assert_eq!(unpack(&packed, plane.len(), w)?, plane);
        }
        Ok(())
    }

    /// A quantised ramp whose slopes are not whole codes: the predictor
    /// is off by the rounding, 0 or ±1, as on a quantised depth plane.
    fn rounded_ramp(w: usize, h: usize) -> Vec<i32> {
        (0..w * h)
            .map(|i| (0.37 * (i % w) as f64 + 0.21 * (i / w) as f64).round() as i32)
            .collect()
    }

    #[test]
    fn the_significance_map_beats_byte_planes_of_every_residual() -> Result<(), CodecError> {
        let (w, h) = (320usize, 180usize);
        let plane = rounded_ramp(w, h);
        let packed = pack(&plane, w, 1)?;
        assert_eq!(unpack(&packed, plane.len(), w)?, plane);
        // The layout before the map: byte planes of every residual.
        let n = plane.len();
        let mut all = vec![0u8; n * 4];
        let mut nonzero = 0;
        predict_rows(&mut plane.clone(), w, |i, pred, value| {
            let z = zigzag(value.wrapping_sub(pred));
            nonzero += usize::from(z != 0);
            for (b, byte) in z.to_le_bytes().into_iter().enumerate() {
                all[b * n + i] = byte;
            }
        });
        assert!(nonzero > n / 20 && nonzero < n / 2, "{nonzero} of {n}");
        let before = super::super::zstd_compress(&all, 1)?.len();
        assert!(
            packed.len() * 10 < before * 9,
            "{} bytes, byte planes {before}",
            packed.len()
        );
        Ok(())
    }

    #[test]
    fn malformed_payloads_are_errors() -> Result<(), CodecError> {
        let (w, h) = (13usize, 7usize);
        let plane = rounded_ramp(w, h);
        let packed = pack(&plane, w, 1)?;
        // Too short for the prefix; a map length past the end; truncated.
        assert!(unpack(&packed[..3], plane.len(), w).is_err());
        let mut long = packed.clone();
        long[..4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(unpack(&long, plane.len(), w).is_err());
        assert!(unpack(&packed[..packed.len() - 1], plane.len(), w).is_err());
        // Another count than was packed.
        assert!(unpack(&packed, plane.len() - 8, w).is_err());
        assert!(unpack(&packed, plane.len() + 8, w).is_err());
        // A set bit past the last value (91 values: 5 spare bits).
        let n = plane.len();
        let mut map = vec![0u8; n.div_ceil(8)];
        if let Some(last) = map.last_mut() {
            *last = 0x80;
        }
        let map = super::super::zstd_compress(&map, 1)?;
        let planes = super::super::zstd_compress(&[0; 4], 1)?;
        let mut stray = (map.len() as u32).to_le_bytes().to_vec();
        stray.extend_from_slice(&map);
        stray.extend_from_slice(&planes);
        assert!(matches!(
            unpack(&stray, n, w),
            Err(CodecError::BadParameters("significance map"))
        ));
        Ok(())
    }

    proptest! {
        /// The clamp is LOCO-I's three cases.
        #[test]
        fn med_is_the_median_edge_detector(a in any::<i32>(), b in any::<i32>(), c in any::<i32>()) {
            let expected = if c >= a.max(b) {
                a.min(b)
            } else if c <= a.min(b) {
                a.max(b)
            } else {
                // c lies strictly between a and b: the result does too.
                a.wrapping_add(b).wrapping_sub(c)
            };
            prop_assert_eq!(med(a, b, c), expected);
        }
    }

    #[test]
    fn zigzag_is_a_bijection_at_the_extremes() {
        for v in [0, 1, -1, i32::MAX, i32::MIN, 12345, -12345] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
        assert_eq!(zigzag(-1), 1);
        assert_eq!(zigzag(1), 2);
    }

    proptest! {
        #[test]
        fn any_plane_round_trips(values in proptest::collection::vec(any::<i32>(), 0..300), width in 1usize..40) {
            let packed = pack(&values, width, 1).unwrap();
            prop_assert_eq!(unpack(&packed, values.len(), width).unwrap(), values);
        }
    }
}
