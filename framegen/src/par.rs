//! How the CPU passes split their pixel loops across cores (rayon).
//!
//! Every parallel loop writes each output element from one task and sums
//! only integers, so a pass's result does not depend on the number of
//! threads or on how rayon schedules the tasks (tested in
//! `tests/tests/framegen_parity.rs`).

/// Pixels per parallel task for a `width`-wide image of `n` pixels: whole
/// rows, about 16 K pixels (large enough that scheduling costs nothing, small
/// enough that every core gets several bands at 360p), never 0.
pub fn band(width: usize, n: usize) -> usize {
    let width = width.max(1);
    let rows = (16_384 / width).max(1);
    (rows * width).min(n).max(1)
}

/// `n` copies of `value`, written on all cores: a frame-sized buffer is
/// tens of megabytes, and one core alone fills it at a fraction of the
/// memory bandwidth (heap memory kept by
/// [`crate::memory::retain_freed_memory`] is not zeroed by the kernel).
pub fn filled<T: Copy + Send + Sync>(value: T, n: usize) -> Vec<T> {
    use rayon::prelude::*;
    let mut v = Vec::with_capacity(n);
    v.par_extend(rayon::iter::repeat_n(value, n));
    v
}

#[cfg(test)]
mod tests {
    #[test]
    fn bands_are_whole_rows_and_never_empty() {
        assert_eq!(super::band(1280, 1280 * 720), 12 * 1280);
        assert_eq!(super::band(100_000, 100_000), 100_000);
        assert_eq!(super::band(4, 8), 8);
        assert_eq!(super::band(0, 0), 1);
    }

    #[test]
    fn filled_holds_n_copies() {
        let v = super::filled([1.5f32, -2.0], 100_003);
        assert_eq!(v.len(), 100_003);
        assert!(v.iter().all(|&x| x == [1.5, -2.0]));
        assert!(super::filled(7u8, 0).is_empty());
    }
}
