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
//! nothing. Residuals wrap in `i32` (lossless for any input), are zigzag
//! mapped to small unsigned values, split into byte planes and compressed
//! with zstd (as [`super::Codec::Zstd`] does for floats).

use super::CodecError;

/// The median edge detector's prediction of a value from its left (`a`),
/// upper (`b`) and upper-left (`c`) neighbours.
fn med(a: i32, b: i32, c: i32) -> i32 {
    if c >= a.max(b) {
        a.min(b)
    } else if c <= a.min(b) {
        a.max(b)
    } else {
        // c lies strictly between a and b, so a + b − c does too: no overflow.
        a.wrapping_add(b).wrapping_sub(c)
    }
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

/// Packs `values` (planes `width` wide, row after row) at zstd `level`.
pub(crate) fn pack(values: &[i32], width: usize, level: i32) -> Result<Vec<u8>, CodecError> {
    let width = width.max(1);
    let n = values.len();
    // Written straight into byte planes (the layout `zstd_pack` shuffles
    // floats into): the high bytes of small residuals are runs of zeros.
    let mut planes = vec![0u8; n * 4];
    let mut scratch = values.to_vec();
    predict_rows(&mut scratch, width, |i, pred, value| {
        let residual = zigzag(value.wrapping_sub(pred)).to_le_bytes();
        for (b, byte) in residual.into_iter().enumerate() {
            planes[b * n + i] = byte;
        }
    });
    super::zstd_compress(&planes, level)
}

/// Inverse of [`pack`]: exactly `count` values, or an error.
pub(crate) fn unpack(encoded: &[u8], count: usize, width: usize) -> Result<Vec<i32>, CodecError> {
    let width = width.max(1);
    let expected = count.checked_mul(4).ok_or(CodecError::WrongLength {
        got: 0,
        expected: u64::MAX,
    })?;
    let planes = super::zstd_decompress(encoded, expected)?;
    let (p0, rest) = planes.split_at(count);
    let (p1, rest) = rest.split_at(count);
    let (p2, p3) = rest.split_at(count);
    let mut values = vec![0i32; count];
    predict_rows(&mut values, width, |i, pred, value| {
        let residual = u32::from_le_bytes([p0[i], p1[i], p2[i], p3[i]]);
        *value = pred.wrapping_add(unzigzag(residual));
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
