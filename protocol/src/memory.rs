//! Keeping freed frame-sized buffers in the process's heap, so that the next
//! frame reuses them instead of faulting fresh pages in.
//!
//! Every push and every generation of the CPU frame generator allocates and
//! frees frame-sized buffers (the prepared inputs, the history planes, the
//! background layers, the splat's winners, the generated frame and its f16
//! copy: some 250 MB per gffe frame at 1280×720), and so do the client's
//! decoder and presenter, and the server's readback and encoders. glibc serves allocations above its mmap threshold
//! (128 KiB, adapting up to 32 MiB) with fresh mappings and unmaps them on
//! `free`, so each frame's buffers are faulted in and zeroed again, page by
//! page: `perf` put a fifth of gffe's CPU time at 720p in the kernel's
//! `clear_page` and page-fault handlers. [`retain_freed_memory`] raises the
//! mmap and trim thresholds so that freed blocks stay in the heap for the
//! next frame. The price is that the heap does not shrink below its peak.
//!
//! A process-wide setting: binaries call it once at start-up (the client,
//! whose demo also runs the server in-process, the server, and the
//! benches); libraries never do. It lives here, at the bottom of the
//! crates, so that every binary can reach it.

/// Blocks up to this size come from the heap and stay there when freed
/// (larger than any frame buffer up to 8K × 8K × 16 B).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const RETAIN_UP_TO: libc::c_int = 1 << 30;

/// Keeps freed blocks of up to 1 GiB in the heap (glibc's `mallopt`);
/// `true` if the allocator took the setting, `false` where the C library
/// has no such knob (then nothing changes).
pub fn retain_freed_memory() -> bool {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: `mallopt` only sets allocator parameters; it is called
        // with valid parameter codes, and glibc serialises it against
        // concurrent allocation with the arena locks.
        let ok = unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, RETAIN_UP_TO) == 1
                && libc::mallopt(libc::M_TRIM_THRESHOLD, RETAIN_UP_TO) == 1
        };
        if !ok {
            tracing::debug!("the allocator refused to keep freed blocks");
        }
        ok
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    /// glibc takes the setting (a version that refused it would silently
    /// bring the page faults back).
    #[test]
    fn the_allocator_takes_the_setting() {
        let taken = super::retain_freed_memory();
        assert_eq!(taken, cfg!(all(target_os = "linux", target_env = "gnu")));
    }
}
