//! What every bench binary of this crate does around its groups.

/// Runs `benches` (a `criterion_group!`) as the client runs, with freed
/// memory kept for reuse (see `protocol::memory`), then criterion's
/// summary.
pub fn main(benches: fn()) {
    protocol::memory::retain_freed_memory();
    benches();
    criterion::Criterion::default()
        .configure_from_args()
        .final_summary();
}
