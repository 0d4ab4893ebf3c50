//! Cancelling a running bake (or a flight or soak of the tools) from another thread or a
//! signal handler.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// A flag that cancels a running bake, from another thread or a signal handler
/// ([`CancelFlag::shared`] gives the atomic to hand to one). Clones share the flag; two flags
/// are equal when they are the same flag.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Arc<AtomicBool>);

impl CancelFlag {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the bake to stop.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether the bake was asked to stop.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }

    /// The flag itself, for a signal handler to set (e.g. `signal_hook::flag::register`).
    pub fn shared(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.0)
    }

    /// A flag that SIGINT and SIGTERM (Ctrl-C, `kill`) set, for the command line: the first
    /// signal cancels the bake, which then removes its staging folder; a second one ends the
    /// process at once (status 130), and the next bake removes the staging folder it leaves.
    #[cfg(feature = "cli")]
    pub fn on_termination_signals() -> std::io::Result<Self> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let flag = Self::new();
        for signal in [SIGINT, SIGTERM] {
            // Registered first, so that it sees the flag as the previous signal left it.
            signal_hook::flag::register_conditional_shutdown(signal, 130, flag.shared())?;
            signal_hook::flag::register(signal, flag.shared())?;
        }
        Ok(flag)
    }
}

impl PartialEq for CancelFlag {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}
