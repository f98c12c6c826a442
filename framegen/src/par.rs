//! How the CPU passes split their pixel loops across cores (rayon).
//!
//! Every parallel loop writes each output element from one task and sums
//! only integers, so a pass's result does not depend on the number of
//! threads or on how rayon schedules the tasks (tested in
//! `tests/tests/framegen_parity.rs`).
//!
//! Loops whose pixels cost unevenly (a frame's rows, its bands) cap how
//! much one task takes (`with_max_len`): rayon otherwise splits a loop
//! into about as many pieces as there are threads and splits further only
//! what is stolen, so a core could wait for the last large piece of
//! another (720p on two cores: a core stood idle for 0.9 ms of the shading
//! estimate's 5; push + generation 0.5–0.7 ms faster with the caps,
//! paired).

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
/// [`protocol::memory::retain_freed_memory`] is not zeroed by the kernel).
pub fn filled<T: Copy + Send + Sync>(value: T, n: usize) -> Vec<T> {
    use rayon::prelude::*;
    let mut v = Vec::with_capacity(n);
    v.par_extend(rayon::iter::repeat_n(value, n));
    v
}

/// `n` elements made block by block on all cores, without a pass that
/// writes the whole buffer first: each block of `block` elements (the last
/// one shorter) is filled with `value`, while it is in the cache, and then
/// handed to `make` with its index, which writes what it makes over it.
/// Filling a frame-sized buffer first and writing it again costs a trip
/// through memory for every element (about 1 ms for the 30 MB of a 720p
/// generated frame on two cores).
pub fn blocks<T: Copy + Send + Sync>(
    value: T,
    n: usize,
    block: usize,
    make: impl Fn(usize, &mut [T]) + Sync + Send,
) -> Vec<T> {
    use rayon::prelude::*;
    let mut v = Vec::with_capacity(n);
    v.spare_capacity_mut()[..n]
        .par_chunks_mut(block.max(1))
        .enumerate()
        .for_each(|(k, slots)| make(k, init(slots, value)));
    // SAFETY: the blocks cover the first `n` slots and `init` wrote each
    // of them; a panic in `make` propagates out of `for_each` before this.
    unsafe { v.set_len(n) };
    v
}

/// Four buffers of `n` elements made band by band on all cores, without a
/// pass that writes them first: band `k` (`b` elements, the last one
/// shorter) of each is filled with its `fill` value while it is in the
/// cache, then handed to `make(k, …)`, which writes what it makes over it.
/// For a frame kept as planes (a generated frame, and it packed).
pub fn bands4<A, B, C, D>(
    n: usize,
    b: usize,
    fill: (A, B, C, D),
    make: impl Fn(usize, &mut [A], &mut [B], &mut [C], &mut [D]) + Sync + Send,
) -> (Vec<A>, Vec<B>, Vec<C>, Vec<D>)
where
    A: Copy + Send + Sync,
    B: Copy + Send + Sync,
    C: Copy + Send + Sync,
    D: Copy + Send + Sync,
{
    let b = b.max(1);
    let each = vec![(); n.div_ceil(b)];
    bands4_with(n, b, fill, each, |k, (), a, bb, c, d| make(k, a, bb, c, d))
}

/// [`bands4`] with something of its own for each band: `each[k]` (one per
/// band, `n.div_ceil(b)` of them) is handed to band `k`'s `make` too, so
/// that a band can write other buffers split the same way (the packed
/// frame made alongside a generated one, `pack::resolved`).
///
/// # Panics
///
/// If `each` does not hold one item per band (a caller's mistake: every
/// band must be made for the buffers to be whole).
pub fn bands4_with<P, A, B, C, D>(
    n: usize,
    b: usize,
    fill: (A, B, C, D),
    each: Vec<P>,
    make: impl Fn(usize, P, &mut [A], &mut [B], &mut [C], &mut [D]) + Sync + Send,
) -> (Vec<A>, Vec<B>, Vec<C>, Vec<D>)
where
    P: Send,
    A: Copy + Send + Sync,
    B: Copy + Send + Sync,
    C: Copy + Send + Sync,
    D: Copy + Send + Sync,
{
    use rayon::prelude::*;
    let b = b.max(1);
    assert_eq!(each.len(), n.div_ceil(b), "one item per band");
    let (mut a, mut bb, mut c, mut d) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    (a.spare_capacity_mut()[..n].par_chunks_mut(b))
        .zip(bb.spare_capacity_mut()[..n].par_chunks_mut(b))
        .zip(c.spare_capacity_mut()[..n].par_chunks_mut(b))
        .zip(d.spare_capacity_mut()[..n].par_chunks_mut(b))
        .zip(each)
        .enumerate()
        .with_max_len(1)
        .for_each(|(k, ((((a, bb), c), d), p))| {
            make(
                k,
                p,
                init(a, fill.0),
                init(bb, fill.1),
                init(c, fill.2),
                init(d, fill.3),
            )
        });
    // SAFETY: the bands cover the first `n` slots of each buffer (`each`
    // has one item per band, checked above, so the zip drops none) and
    // `init` wrote every one of them; a panic in `make` propagates out of
    // `for_each` before this.
    unsafe {
        a.set_len(n);
        bb.set_len(n);
        c.set_len(n);
        d.set_len(n);
    }
    (a, bb, c, d)
}

/// `slots` filled with `value`, as the initialised elements they now are.
pub fn init<T: Copy>(slots: &mut [std::mem::MaybeUninit<T>], value: T) -> &mut [T] {
    for slot in slots.iter_mut() {
        slot.write(value);
    }
    // SAFETY: every element was written just above, and `MaybeUninit<T>`
    // has `T`'s layout.
    unsafe { &mut *(slots as *mut [std::mem::MaybeUninit<T>] as *mut [T]) }
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
    fn blocks_are_filled_then_made_in_order() {
        let v = super::blocks(7u32, 10, 4, |k, block| {
            assert!(block.iter().all(|&x| x == 7), "filled first");
            block[0] = k as u32;
        });
        assert_eq!(v, [0, 7, 7, 7, 1, 7, 7, 7, 2, 7]);
        assert!(super::blocks(1u8, 0, 4, |_, _| unreachable!()).is_empty());
    }

    #[test]
    fn filled_holds_n_copies() {
        let v = super::filled([1.5f32, -2.0], 100_003);
        assert_eq!(v.len(), 100_003);
        assert!(v.iter().all(|&x| x == [1.5, -2.0]));
        assert!(super::filled(7u8, 0).is_empty());
    }
}
