//! The memory allocator of the `phi` binary and its examples: mimalloc, with its purge of freed
//! memory off.
//!
//! A training step of a thesis-size GNS allocates and frees `[E, 128]` buffers of tens of MiB
//! hundreds of times. glibc maps every block over its mmap threshold (at most 32 MiB) afresh, so
//! the kernel zeroes every page of it again: about a third of such a step. mimalloc keeps freed
//! memory in its arenas; with its default purge (freed memory handed back to the kernel after a
//! delay) the pages are zeroed again as well, so the purge is off unless the environment sets
//! `MIMALLOC_PURGE_DELAY` (milliseconds; mimalloc reads it at process start).
//!
//! A binary opts in with
//! ```ignore
//! #[global_allocator]
//! static ALLOCATOR: phi::allocator::Allocator = phi::allocator::Allocator;
//! ```
//! and calls [`configure`] first thing in `main`.

/// The global allocator type of the binaries.
pub use mimalloc::MiMalloc as Allocator;

/// The environment variable that sets mimalloc's purge delay (and so leaves it as it is here).
pub(crate) const PURGE_DELAY_VARIABLE: &str = "MIMALLOC_PURGE_DELAY";

/// `mi_option_purge_delay`, the index of the purge delay among mimalloc's options (v3's
/// `mi_option_t`; `libmimalloc-sys` does not name it). A test pins it to the environment
/// variable.
const PURGE_DELAY_OPTION: libmimalloc_sys::mi_option_t = 15;

/// Turns mimalloc's purge off, unless [`PURGE_DELAY_VARIABLE`] sets it.
pub fn configure() {
    if std::env::var_os(PURGE_DELAY_VARIABLE).is_none() {
        set_purge_delay(-1);
    }
}

/// mimalloc's purge delay in milliseconds (−1: never purge).
#[cfg(test)]
fn purge_delay() -> i64 {
    // SAFETY: reading an option is thread-safe, and the index is in range.
    unsafe { libmimalloc_sys::mi_option_get(PURGE_DELAY_OPTION) as i64 }
}

fn set_purge_delay(milliseconds: i64) {
    // SAFETY: setting an option stores one integer, and the index is in range.
    unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY_OPTION, milliseconds as _) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The child of [`the_option_index_is_the_purge_delay`]: run there with the variable set.
    #[test]
    #[ignore = "run by the_option_index_is_the_purge_delay in a child process"]
    fn child_reads_the_purge_delay_from_the_environment() {
        assert_eq!(std::env::var(PURGE_DELAY_VARIABLE).as_deref(), Ok("4321"));
        assert_eq!(purge_delay(), 4321);
        configure();
        assert_eq!(purge_delay(), 4321, "configure overrode the environment");
    }

    /// mimalloc reads `MIMALLOC_PURGE_DELAY` into the option this module sets: a child test
    /// process started with the variable reads it back through [`PURGE_DELAY_OPTION`].
    #[test]
    fn the_option_index_is_the_purge_delay() {
        let child = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "allocator::tests::child_reads_the_purge_delay_from_the_environment",
                "--ignored",
            ])
            .env(PURGE_DELAY_VARIABLE, "4321")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&child.stdout);
        assert!(child.status.success(), "the child test failed:\n{stdout}");
        assert!(
            stdout.contains("1 passed"),
            "the child ran no test:\n{stdout}"
        );
    }

    /// Without the variable, `configure` turns the purge off.
    #[test]
    fn configure_turns_the_purge_off() {
        if std::env::var_os(PURGE_DELAY_VARIABLE).is_some() {
            return; // the environment decides; the child test covers that case
        }
        configure();
        assert_eq!(purge_delay(), -1);
    }
}
