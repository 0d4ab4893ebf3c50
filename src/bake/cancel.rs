//! Cancelling a running bake (or a flight or soak of the tools) from another thread or a
//! signal handler.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

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
    /// Signals within 250 ms of the first are that same request: a supervisor that
    /// signals the process and then its group (GNU `timeout`, some process managers) sends one
    /// stop twice, microseconds apart.
    #[cfg(feature = "cli")]
    pub fn on_termination_signals() -> std::io::Result<Self> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let flag = Self::new();
        let start = std::time::Instant::now();
        // When the first signal came, in nanoseconds after `start`, plus one (0: none yet).
        let first = Arc::new(AtomicU64::new(0));
        for signal in [SIGINT, SIGTERM] {
            let (set, first) = (flag.shared(), Arc::clone(&first));
            let action = move || {
                let now = start.elapsed().as_nanos() as u64 + 1;
                match stop_signal(&first, now) {
                    StopSignal::First => set.store(true, Ordering::SeqCst),
                    StopSignal::SameStop => {}
                    StopSignal::Second => signal_hook::low_level::exit(130),
                }
            };
            // SAFETY: the action reads a monotonic clock (clock_gettime), touches atomics and
            // at most calls `_exit`: all async-signal-safe; it allocates and locks nothing.
            unsafe { signal_hook::low_level::register(signal, action) }?;
        }
        Ok(flag)
    }
}

/// How soon after a stop signal another one counts as the same stop rather than a second,
/// ending the process at once (see [`CancelFlag::on_termination_signals`]): far shorter than
/// a person presses Ctrl-C twice.
#[cfg_attr(not(feature = "cli"), allow(dead_code))]
const SAME_STOP: std::time::Duration = std::time::Duration::from_millis(250);

/// What a stop signal (SIGINT, SIGTERM) does.
#[cfg_attr(not(feature = "cli"), allow(dead_code))]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StopSignal {
    /// The first: the run is asked to stop.
    First,
    /// Within [`SAME_STOP`] of the first: the same request again.
    SameStop,
    /// A second request: the process ends at once.
    Second,
}

/// Sorts a stop signal that came at `now` (nanoseconds from any fixed instant, plus one),
/// `first` holding when the first came (0 until then; this sets it). Signal-safe: atomics only.
#[cfg_attr(not(feature = "cli"), allow(dead_code))]
fn stop_signal(first: &AtomicU64, now: u64) -> StopSignal {
    match first.compare_exchange(0, now, Ordering::SeqCst, Ordering::SeqCst) {
        Ok(_) => StopSignal::First,
        Err(at) if now.saturating_sub(at) <= SAME_STOP.as_nanos() as u64 => StopSignal::SameStop,
        Err(_) => StopSignal::Second,
    }
}

impl PartialEq for CancelFlag {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A signal within 250 ms of the first (a supervisor signalling the process and then its
    /// group) repeats the stop; a later one is a second Ctrl-C and ends the process.
    #[test]
    fn a_stop_signal_soon_after_the_first_is_the_same_stop() {
        let ms = |t: u64| t * 1_000_000 + 1;
        let first = AtomicU64::new(0);
        assert_eq!(stop_signal(&first, ms(1_000)), StopSignal::First);
        assert_eq!(stop_signal(&first, ms(1_000)), StopSignal::SameStop);
        assert_eq!(stop_signal(&first, ms(1_249)), StopSignal::SameStop);
        assert_eq!(stop_signal(&first, ms(1_251)), StopSignal::Second);
        // Still measured from the first, not from the one before.
        assert_eq!(stop_signal(&first, ms(5_000)), StopSignal::Second);
        // A first signal in the process's first nanosecond is still recorded as the first.
        let first = AtomicU64::new(0);
        assert_eq!(stop_signal(&first, 1), StopSignal::First);
        assert_eq!(stop_signal(&first, ms(100)), StopSignal::SameStop);
    }
}
