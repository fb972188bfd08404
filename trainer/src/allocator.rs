//! Allocator settings for training. Every tensor op of the CPU backend allocates a fresh output buffer, and
//! at these sizes (2 MB for 4,000 x 128 floats, 134 MB for the paper's 65,536 x 512) glibc's defaults hand
//! the memory back to the kernel on free (`munmap`, or trimming the top of the heap) and fault it in again
//! on the next allocation. Keeping it in the process doubles the iteration rate of the shipped network and
//! gives the paper's 1.4-1.6x (`trainer bench`, measured with the same settings through `GLIBC_TUNABLES`).

/// Allocations up to this size come from the heap, not from a fresh `mmap` (glibc's default adapts up to
/// 32 MiB).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD: i32 = 256 << 20;
/// Extra memory requested whenever the heap grows, so that growth is rare.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const TOP_PAD: i32 = 256 << 20;
/// Free memory at the top of the heap is returned to the kernel only beyond this.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const TRIM_THRESHOLD: i32 = 1 << 30;

/// Applies the settings once per process (a no-op where the C library is not glibc). The process then keeps
/// up to about 1 GiB of freed memory for reuse.
pub fn tune_for_training() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        ONCE.call_once(|| {
            for (name, option, value) in [
                ("M_MMAP_THRESHOLD", libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD),
                ("M_TOP_PAD", libc::M_TOP_PAD, TOP_PAD),
                ("M_TRIM_THRESHOLD", libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD),
            ] {
                // SAFETY: mallopt only changes glibc's allocator parameters (under its own lock); no memory is touched.
                if unsafe { libc::mallopt(option, value) } != 1 {
                    tracing::warn!(option = name, value, "mallopt refused an allocator setting; training runs slower");
                }
            }
        });
    }
}
