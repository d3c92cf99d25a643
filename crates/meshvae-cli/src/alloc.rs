//! The allocator: mimalloc, told to keep the memory a training step frees for the next step.
//!
//! A step allocates and frees the same large tensors every time (the gradients of the mesh VAE
//! of Tan et al. are 310 MB each). mimalloc hands freed memory back to the OS a second later, and
//! the kernel zero-fills those pages again when a later step touches them: 9 % of that
//! network's CPU time, 2 % of SpiralNet++'s (docs/benchmarks.md). Keeping it changes no number
//! and the peak memory by under 2 %.

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's `mi_option_purge_delay` (milliseconds before freed memory goes back to the OS;
/// -1: never), the 16th entry of its option enum in versions 2 and 3 alike; the sys crate
/// names no constant for it.
const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Call first thing in `main`.
pub(crate) fn keep_freed_memory() {
    // SAFETY: sets one of mimalloc's global options; any value is valid, and it takes effect
    // for memory freed from now on.
    unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY, -1) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_option_set_is_the_purge_delay() {
        // SAFETY: reads and sets mimalloc's global options.
        unsafe {
            // mimalloc 3's default for the purge delay, 1,000 ms: the index names the option
            // meant (its neighbours default to 1 and 0).
            assert_eq!(libmimalloc_sys::mi_option_get(PURGE_DELAY), 1000);
            keep_freed_memory();
            assert_eq!(libmimalloc_sys::mi_option_get(PURGE_DELAY), -1);
        }
    }
}
