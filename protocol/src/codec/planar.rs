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
//! over eight bytes.
//!
//! The prediction runs row by row, but both parts may list the values
//! **column by column**: the encoder keeps the order whose map packs
//! smaller (the map is a thirty-second of the residuals' bytes, and they
//! follow its pattern). Floors, ceilings and walls receding from the
//! camera keep their inverse depth nearly constant along a row and
//! changing down a column, so the rounding that leaves a residual repeats down a column: the column
//! order gives zstd long matches where the row order gives noise. On five
//! scenes' 1280×720 depth planes (`dolly`, `default`, `sun_sweep`, `thin`,
//! `crossing`, two frames each, zstd level 1), against the byte planes of
//! every residual in row order: the map and residuals in row order −7 to
//! −21 %, in column order −30 to −48 % (`dolly` 67 → 53 → 35 KB). Motion
//! differs by scene (the default scene's moving objects pack smaller in
//! rows), hence the choice per payload.
//!
//! Payload: the order (`u8`: 0 rows, 1 columns), the map's compressed
//! length (`u32`, little-endian), the map's zstd frame (`⌈n/8⌉` bytes; the
//! `j`-th value in that order is bit `j mod 8` of byte `j / 8`, where the
//! value in row `y`, column `x` of a plane `w` wide and `h` high is the
//! `(y·w + x)`-th in rows and the `(x·h + y)`-th in columns; the unused
//! bits 0), the residuals' zstd frame (4 bytes a set bit, in the map's
//! order). A plane is whole rows.

use super::CodecError;

/// The median edge detector's prediction of a value from its left (`a`),
/// upper (`b`) and upper-left (`c`) neighbours: the median of `a`, `b` and
/// `a + b − c`, i.e. `min(a, b)` if `c ≥ max(a, b)`, `max(a, b)` if `c ≤
/// min(a, b)`, else `a + b − c`, which then lies strictly between the two
/// and so fits an `i32`: the wrapping sum is exact wherever it is taken.
/// Selects on `i32` lanes, which the encoder's loop vectorises: a clamp
/// of the sum taken in `i64`, which SSE2 compares only by emulation, cost
/// the encoders 1.2–1.4 ms more of a 640×360 frame (`cargo bench -p scene
/// --bench codecs`).
#[inline]
fn med(a: i32, b: i32, c: i32) -> i32 {
    let (lo, hi) = (a.min(b), a.max(b));
    let sum = a.wrapping_add(b).wrapping_sub(c);
    if c >= hi {
        lo
    } else if c <= lo {
        hi
    } else {
        sum
    }
}

/// Walks `values` in order, rows `width` wide, calling `f(i, prediction,
/// value)` with the prediction from the values before it; `f` may write the
/// value (a decoder does), which the next predictions then use. The
/// reference that the encoder's [`residuals`] and the decoder's
/// [`unpredict`] are tested against.
#[cfg(test)]
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

/// `values`, whole rows `width` wide, column by column: element
/// `x·rows + y` is `values[y·width + x]`. A band of rows at a time (small
/// enough to stay in cache while every column's stretch of it is written
/// out in one piece).
fn transpose<T: Copy + Default>(values: &[T], width: usize) -> Vec<T> {
    const BAND: usize = 32;
    if values.is_empty() {
        return Vec::new();
    }
    let rows = values.len() / width;
    let mut out = vec![T::default(); values.len()];
    for y0 in (0..rows).step_by(BAND) {
        let y1 = (y0 + BAND).min(rows);
        let band = &values[y0 * width..y1 * width];
        for (x, column) in out.chunks_exact_mut(rows).enumerate() {
            let down = band[x..].iter().step_by(width);
            for (to, from) in column[y0..y1].iter_mut().zip(down) {
                *to = *from;
            }
        }
    }
    out
}

/// A plane of `count` values `width` wide is whole rows.
fn check_rows(count: usize, width: usize) -> Result<(), CodecError> {
    if count % width == 0 {
        Ok(())
    } else {
        Err(CodecError::BadParameters("plane width"))
    }
}

/// Bytes of the significance map of `count` values.
fn map_len(count: usize) -> usize {
    count.div_ceil(8)
}

/// Largest payload [`pack`] writes for `count` values: the order, the
/// length prefix and the two zstd frames at their bounds.
pub(crate) fn max_packed_len(count: u64) -> u64 {
    let bound = super::zstd_compress_bound;
    5u64.saturating_add(bound(count.div_ceil(8)))
        .saturating_add(bound(count.saturating_mul(4)))
}

/// Packs `values` (planes `width` wide, row after row) at zstd `level`.
pub(crate) fn pack(values: &[i32], width: usize, level: i32) -> Result<Vec<u8>, CodecError> {
    let width = width.max(1);
    check_rows(values.len(), width)?;
    let residuals = residuals(values, width);
    // The order is chosen on the maps alone (a thirty-second of the
    // residuals' bytes): the residuals follow the same pattern.
    let columns = transpose(&residuals, width);
    let by_rows = super::zstd_compress(&significance(&residuals), level)?;
    let by_columns = super::zstd_compress(&significance(&columns), level)?;
    let (order, map, listed) = if by_columns.len() < by_rows.len() {
        (Order::Columns, by_columns, &columns)
    } else {
        (Order::Rows, by_rows, &residuals)
    };
    let planes = super::zstd_compress(&nonzero_planes(listed), level)?;
    payload(order, &map, &planes)
}

/// The zigzagged residuals of `values` (whole rows `width` wide) against
/// the median edge detector, in row order: [`predict_rows`]' predictions,
/// made from `values` as they are (the encoder writes none back), each
/// row collected as it is made, without a copy of the values or a buffer
/// filled first.
fn residuals(values: &[i32], width: usize) -> Vec<u32> {
    let mut residuals = Vec::with_capacity(values.len());
    let mut rows = values.chunks_exact(width.max(1));
    let Some(first) = rows.next() else {
        return residuals;
    };
    let left = |row: &[i32], x: usize| if x == 0 { 0 } else { row[x - 1] };
    residuals.extend((0..first.len()).map(|x| zigzag(first[x].wrapping_sub(left(first, x)))));
    for (up, row) in values.chunks_exact(width.max(1)).zip(rows) {
        residuals.push(zigzag(row[0].wrapping_sub(up[0])));
        // Pairs of neighbours, without an index to check: a loop the
        // compiler vectorises.
        let pairs = row.windows(2).zip(up.windows(2));
        residuals.extend(pairs.map(|(r, u)| zigzag(r[1].wrapping_sub(med(r[0], u[1], u[0])))));
    }
    residuals
}

/// The payload of the compressed `map` and `planes` listed in `order`.
fn payload(order: Order, map: &[u8], planes: &[u8]) -> Result<Vec<u8>, CodecError> {
    let map_bytes = u32::try_from(map.len()).map_err(|_| CodecError::WrongLength {
        got: map.len() as u64,
        expected: u64::from(u32::MAX),
    })?;
    let mut out = Vec::with_capacity(5 + map.len() + planes.len());
    out.push(order as u8);
    out.extend_from_slice(&map_bytes.to_le_bytes());
    out.extend_from_slice(map);
    out.extend_from_slice(planes);
    Ok(out)
}

/// The order a payload lists its values in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Order {
    Rows = 0,
    Columns = 1,
}

/// The significance map of `residuals` (zigzagged) in their order.
fn significance(residuals: &[u32]) -> Vec<u8> {
    let mut map = vec![0u8; map_len(residuals.len())];
    let whole = residuals.chunks_exact(8);
    let rest = whole.remainder();
    for (byte, eight) in map.iter_mut().zip(whole) {
        let mut bits = 0u8;
        for (b, &z) in eight.iter().enumerate() {
            bits |= u8::from(z != 0) << b;
        }
        *byte = bits;
    }
    if let Some(last) = map.last_mut().filter(|_| !rest.is_empty()) {
        *last = rest
            .iter()
            .enumerate()
            .fold(0, |bits, (b, &z)| bits | u8::from(z != 0) << b);
    }
    map
}

/// The byte planes of the non-zero `residuals` (zigzagged), less one, in
/// their order (the high bytes of small residuals are runs of zeros).
fn nonzero_planes(residuals: &[u32]) -> Vec<u8> {
    let nonzero = residuals.iter().filter(|&&z| z != 0).count();
    let mut planes = vec![0u8; nonzero * 4];
    for (k, z) in residuals.iter().filter(|&&z| z != 0).enumerate() {
        for (b, byte) in (z - 1).to_le_bytes().into_iter().enumerate() {
            planes[b * nonzero + k] = byte;
        }
    }
    planes
}

/// Inverse of [`pack`]: exactly `count` values, or an error.
pub(crate) fn unpack(encoded: &[u8], count: usize, width: usize) -> Result<Vec<i32>, CodecError> {
    let width = width.max(1);
    check_rows(count, width)?;
    if count.checked_mul(4).is_none() {
        return Err(CodecError::WrongLength {
            got: 0,
            expected: u64::MAX,
        });
    }
    let malformed = CodecError::BadParameters("significance map");
    let (&order, rest) = encoded.split_first().ok_or(malformed)?;
    let order = match order {
        0 => Order::Rows,
        1 => Order::Columns,
        _ => return Err(CodecError::BadParameters("scan order")),
    };
    let (head, rest) = rest
        .split_first_chunk::<4>()
        .ok_or(CodecError::BadParameters("significance map"))?;
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
    // The residuals in place, in the payload's order (bytes of the map
    // that are 0, most of them, are skipped whole), back to rows, then
    // the prediction without a branch on them.
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
    if order == Order::Columns {
        residuals = transpose(&residuals, count / width);
    }
    Ok(unpredict(&residuals, width))
}

/// The values whose residuals (unzigzagged, row order, whole rows `width`
/// wide) are `residuals`: each the prediction from the values before it
/// plus its residual, as [`predict_rows`] walks them. Two rows at a time:
/// a value waits on its left neighbour's (a chain of a few cycles a
/// value), and the lower row's chain runs beside the upper row's, a value
/// behind it (its upper neighbours are then made).
fn unpredict(residuals: &[i32], width: usize) -> Vec<i32> {
    let width = width.max(1);
    let mut values = vec![0i32; residuals.len()];
    let (Some(first), Some(r0)) = (values.get_mut(..width), residuals.get(..width)) else {
        return values;
    };
    let mut left = 0i32;
    for (v, &r) in first.iter_mut().zip(r0) {
        left = left.wrapping_add(r);
        *v = left;
    }
    let rows = residuals.len() / width;
    let mut y = 1;
    while y < rows {
        let pair = (rows - y).min(2);
        let (done, rest) = values.split_at_mut(y * width);
        let up = &done[(y - 1) * width..];
        let (a, b) = rest.split_at_mut(width);
        let ra = &residuals[y * width..(y + 1) * width];
        a[0] = up[0].wrapping_add(ra[0]);
        if pair == 2 {
            let (b, rb) = (
                &mut b[..width],
                &residuals[(y + 1) * width..(y + 2) * width],
            );
            b[0] = a[0].wrapping_add(rb[0]);
            for x in 1..width {
                a[x] = med(a[x - 1], up[x], up[x - 1]).wrapping_add(ra[x]);
                b[x] = med(b[x - 1], a[x], a[x - 1]).wrapping_add(rb[x]);
            }
        } else {
            for x in 1..width {
                a[x] = med(a[x - 1], up[x], up[x - 1]).wrapping_add(ra[x]);
            }
        }
        y += pair;
    }
    values
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
        let residuals = residuals(&plane, w);
        for (i, z) in residuals.iter().enumerate() {
            for (b, byte) in z.to_le_bytes().into_iter().enumerate() {
                all[b * n + i] = byte;
            }
        }
        let nonzero = residuals.iter().filter(|&&z| z != 0).count();
        assert!(nonzero > n / 20 && nonzero < n / 2, "{nonzero} of {n}");
        let before = super::super::zstd_compress(&all, 1)?.len();
        assert!(
            packed.len() * 10 < before * 9,
            "{} bytes, byte planes {before}",
            packed.len()
        );
        Ok(())
    }

    /// The payload of `plane`'s residuals listed in `order`.
    fn packed_in(plane: &[i32], width: usize, order: Order) -> Result<Vec<u8>, CodecError> {
        let mut residuals = residuals(plane, width);
        if order == Order::Columns {
            residuals = transpose(&residuals, width);
        }
        let map = super::super::zstd_compress(&significance(&residuals), 1)?;
        let planes = super::super::zstd_compress(&nonzero_planes(&residuals), 1)?;
        payload(order, &map, &planes)
    }

    /// Either order decodes to the plane, and the encoder keeps the one
    /// whose map packs smaller.
    #[test]
    fn the_smaller_scan_order_is_kept() -> Result<(), CodecError> {
        let (w, h) = (96usize, 64usize);
        let plane = rounded_ramp(w, h);
        let transposed = transpose(&plane, w);
        for (plane, width) in [(&plane, w), (&transposed, h)] {
            let rows = packed_in(plane, width, Order::Rows)?;
            let columns = packed_in(plane, width, Order::Columns)?;
            assert_eq!(&unpack(&rows, plane.len(), width)?, plane);
            assert_eq!(&unpack(&columns, plane.len(), width)?, plane);
            let map_len = |p: &[u8]| u32::from_le_bytes([p[1], p[2], p[3], p[4]]);
            let kept = if map_len(&columns) < map_len(&rows) {
                columns
            } else {
                rows
            };
            assert_eq!(pack(plane, width, 1)?, kept);
        }
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
        long[1..5].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(unpack(&long, plane.len(), w).is_err());
        let mut order = packed.clone();
        order[0] = 2;
        assert!(matches!(
            unpack(&order, plane.len(), w),
            Err(CodecError::BadParameters("scan order"))
        ));
        assert!(unpack(&packed[..packed.len() - 1], plane.len(), w).is_err());
        // Another count than was packed, or not whole rows.
        assert!(unpack(&packed, plane.len() - w, w).is_err());
        assert!(unpack(&packed, plane.len() + w, w).is_err());
        assert!(matches!(
            unpack(&packed, plane.len() - 1, w),
            Err(CodecError::BadParameters("plane width"))
        ));
        assert!(matches!(
            pack(&plane[1..], w, 1),
            Err(CodecError::BadParameters("plane width"))
        ));
        // A set bit past the last value (91 values: 5 spare bits).
        let n = plane.len();
        let mut map = vec![0u8; n.div_ceil(8)];
        if let Some(last) = map.last_mut() {
            *last = 0x80;
        }
        let map = super::super::zstd_compress(&map, 1)?;
        let planes = super::super::zstd_compress(&[0; 4], 1)?;
        let stray = payload(Order::Rows, &map, &planes)?;
        assert!(matches!(
            unpack(&stray, n, w),
            Err(CodecError::BadParameters("significance map"))
        ));
        Ok(())
    }

    /// The median of `a`, `b` and `a + b − c`, taken in `i64`.
    fn median(a: i32, b: i32, c: i32) -> i64 {
        let (a, b, c) = (i64::from(a), i64::from(b), i64::from(c));
        let mut three = [a, b, a + b - c];
        three.sort_unstable();
        three[1]
    }

    proptest! {
        /// The prediction is the median it is defined as.
        #[test]
        fn med_is_the_median_edge_detector(a in any::<i32>(), b in any::<i32>(), c in any::<i32>()) {
            prop_assert_eq!(i64::from(med(a, b, c)), median(a, b, c));
        }
    }

    /// At the extremes of `i32`, where `a + b − c` leaves it.
    #[test]
    fn med_is_the_median_at_the_extremes() {
        let values = [
            i32::MIN,
            i32::MIN + 1,
            -2,
            -1,
            0,
            1,
            2,
            i32::MAX - 1,
            i32::MAX,
        ];
        for a in values {
            for b in values {
                for c in values {
                    assert_eq!(i64::from(med(a, b, c)), median(a, b, c), "{a} {b} {c}");
                }
            }
        }
    }

    /// The encoder's residuals are each value less [`predict_rows`]'
    /// prediction of it, zigzagged, at every height and narrow widths.
    #[test]
    fn residuals_are_the_values_less_their_predictions() {
        for width in 1..=9usize {
            for rows in 0..=5usize {
                let mut values: Vec<i32> = (0..width * rows)
                    .map(|i| (i as i32).wrapping_mul(-1_640_531_527) >> (i % 29))
                    .collect();
                let mut expected = vec![0u32; values.len()];
                predict_rows(&mut values, width, |i, pred, value| {
                    expected[i] = zigzag(value.wrapping_sub(pred));
                });
                assert_eq!(residuals(&values, width), expected, "{width}×{rows}");
            }
        }
    }

    /// Decoding two rows at a time gives the values [`predict_rows`] gives
    /// one at a time, at every height (an odd last row) and narrow widths.
    #[test]
    fn rows_decoded_in_pairs_are_the_rows_one_by_one() {
        for width in 1..=9usize {
            for rows in 0..=7usize {
                let residuals: Vec<i32> = (0..width * rows)
                    .map(|i| (i as i32).wrapping_mul(-1_640_531_527) >> (i % 29))
                    .collect();
                let mut values = vec![0i32; residuals.len()];
                predict_rows(&mut values, width, |i, pred, value| {
                    *value = pred.wrapping_add(residuals[i]);
                });
                assert_eq!(unpredict(&residuals, width), values, "{width}×{rows}");
            }
        }
    }

    /// Every value lands at its column-major place, at sizes across the
    /// bands of rows it copies by (one band, several, a partial last one).
    #[test]
    fn transposing_moves_each_value_to_its_column_order_place() {
        for width in 1..=19usize {
            for rows in 0..=70usize {
                let values: Vec<u32> = (0..width * rows).map(|i| i as u32 * 7 + 1).collect();
                let out = transpose(&values, width);
                assert_eq!(out.len(), values.len());
                for y in 0..rows {
                    for x in 0..width {
                        assert_eq!(out[x * rows + y], values[y * width + x], "{width}×{rows}");
                    }
                }
            }
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
            let rows = values.len() / width;
            let values = &values[..rows * width];
            let fail = |e: CodecError| TestCaseError::fail(e.to_string());
            let packed = pack(values, width, 1).map_err(fail)?;
            prop_assert_eq!(unpack(&packed, values.len(), width).map_err(fail)?, values);
        }
    }
}
