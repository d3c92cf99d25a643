//! [`StopFlag`]: a request to stop training cleanly, from another thread or from Ctrl-C.
//!
//! Training looks at the flag after every optimizer step. Once it is raised, the run drops the
//! epoch it is in, writes the best epoch's weights and checkpoint (a small model keeps them in
//! memory between writes) and `run.json` (`interrupted`), and returns
//! [`VaeError::Interrupted`](crate::VaeError::Interrupted); a resumed run then ends exactly as an
//! uninterrupted one would. Killed instead, a run loses what it learnt since its last write.

use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

/// A shared flag that asks every training holding a clone of it to stop.
///
/// ```
/// use meshvae::StopFlag;
/// let stop = StopFlag::new();
/// let seen_by_training = stop.clone();
/// stop.request();
/// assert!(seen_by_training.is_requested());
/// ```
#[derive(Debug, Clone, Default)]
pub struct StopFlag(Arc<AtomicBool>);

/// The flag [`StopFlag::on_interrupt`] hands out, raised by the signal handler.
static INTERRUPT: OnceLock<StopFlag> = OnceLock::new();

impl StopFlag {
    /// A flag nobody has raised yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the trainings holding this flag to stop after their current step.
    pub fn request(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    pub fn is_requested(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }

    /// The process's flag for Ctrl-C (SIGINT) and SIGTERM, whose handlers this installs on the
    /// first call (Unix; elsewhere the flag is never raised and the signals keep their default
    /// action). The first signal raises the flag; a second one ends the process at once, as if
    /// no handler were installed.
    pub fn on_interrupt() -> Self {
        let mut first = false;
        let flag = INTERRUPT.get_or_init(|| {
            first = true;
            Self::new()
        });
        if first {
            // After the flag is in place, so that the handler always finds it.
            install_handlers();
        }
        flag.clone()
    }
}

#[cfg(unix)]
fn install_handlers() {
    extern "C" fn on_signal(signal: libc::c_int) {
        // Only atomics and async-signal-safe calls here.
        let Some(flag) = INTERRUPT.get() else { return };
        if flag.0.swap(true, Ordering::SeqCst) {
            // SAFETY: SIG_DFL is a valid action and `raise` is async-signal-safe; the default
            // action of SIGINT and SIGTERM ends the process.
            unsafe {
                libc::signal(signal, libc::SIG_DFL);
                libc::raise(signal);
            }
        }
    }
    let handler = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only touches an atomic flag and re-raises the signal.
        unsafe {
            libc::signal(signal, handler);
        }
    }
}

#[cfg(not(unix))]
fn install_handlers() {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raised_flag_is_seen_by_its_clones_only() {
        let (a, b) = (StopFlag::new(), StopFlag::new());
        let a2 = a.clone();
        a.request();
        assert!(a2.is_requested());
        assert!(!b.is_requested());
    }

    #[cfg(unix)]
    #[test]
    fn sigterm_raises_the_interrupt_flag_instead_of_ending_the_process() {
        let flag = StopFlag::on_interrupt();
        assert!(!flag.is_requested());
        // SAFETY: the handler installed above catches the signal.
        unsafe {
            libc::raise(libc::SIGTERM);
        }
        assert!(flag.is_requested());
        assert!(
            StopFlag::on_interrupt().is_requested(),
            "one flag per process"
        );
    }
}
