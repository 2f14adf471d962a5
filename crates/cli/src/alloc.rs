//! The C allocator's one setting that this program's memory pattern needs.
//!
//! glibc serves a block of at least its *mmap threshold* from a mapping of its own, returned
//! to the system when freed. The threshold starts at 128 KiB and rises to the size of every
//! such block that is freed (up to 32 MiB). A decoder frees a frame-sized buffer early on, so
//! the frames that a calibration keeps (1.3 MB each at 1280x1024) then come from the heap,
//! between the decoders' short-lived buffers, whose freed space stays resident: a sweep of 120
//! PNG frames peaked at 1.77x the frames' memory, 1.42x with a fixed threshold. Fixing the
//! threshold also stops it from rising.

/// The threshold: blocks of 1 MiB and more (a frame from 1024x1024 pixels up) get their own
/// mapping; smaller ones stay on the heap, where mapping each would cost time.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const MMAP_THRESHOLD: libc::c_int = 1 << 20;

/// Sets the allocator's mmap threshold (glibc on Linux; elsewhere nothing). Call it first in
/// `main`, before any thread starts.
pub fn tune() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[allow(unsafe_code)]
    // SAFETY: mallopt only changes a parameter of the allocator; no thread is running yet.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD);
    }
}
