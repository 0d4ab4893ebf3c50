//! What the command line prints. Every line to standard output goes through [`say!`], which
//! checks the write: `println!` panics when standard output fails (Rust ignores SIGPIPE, so a
//! reader that went away, as `head` does, is a failed write).
//!
//! - Standard output closed by its reader (a broken pipe): the printing ends quietly and the
//!   run goes on to end as it would have (its files are written all the same), as standard
//!   tools do when piped into `head`.
//! - Any other failure (a full disk): the run ends with
//!   `error: writing to standard output: REASON` and status 1.
//!
//! Lines to standard error go through [`note!`], which never panics: with standard error
//! closed or full there is nowhere left to say anything, and the line is dropped.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set once standard output's reader has gone: nothing more is written to it.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// A write to standard output that failed other than by its reader going away.
#[derive(Debug)]
pub(crate) struct StdoutFailed(pub(crate) std::io::Error);

impl std::fmt::Display for StdoutFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "writing to standard output: {}", self.0)
    }
}

impl std::error::Error for StdoutFailed {}

/// The outcome of a write to standard output: a broken pipe is no failure (it notes that the
/// reader has gone, and nothing more is written); any other error is.
pub(crate) fn checked(result: std::io::Result<()>) -> Result<(), StdoutFailed> {
    match result {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            STDOUT_CLOSED.store(true, Ordering::Relaxed);
            Ok(())
        }
        Err(e) => Err(StdoutFailed(e)),
    }
}

/// Writes `args` and a line break to standard output, and flushes it; see [`say!`].
pub(crate) fn say_line(args: std::fmt::Arguments<'_>) -> Result<(), StdoutFailed> {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return Ok(());
    }
    let mut out = std::io::stdout().lock();
    checked(writeln!(out, "{args}").and_then(|()| out.flush()))
}

/// Writes `args` and a line break to standard error, dropping the line if that fails; see
/// [`note!`].
pub(crate) fn note_line(args: std::fmt::Arguments<'_>) {
    let mut err = std::io::stderr().lock();
    let _ = writeln!(err, "{args}").and_then(|()| err.flush());
}

/// `say!("...", args)`: a line to standard output, as `println!` writes it, returning
/// `Err(StdoutFailed)` if the write failed (other than by a broken pipe, which ends the
/// printing quietly).
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::cli::out::say_line(format_args!($($arg)*))
    };
}

/// `note!("...", args)`: a line to standard error, as `eprintln!` writes it, without a panic if
/// standard error is closed or full.
macro_rules! note {
    ($($arg:tt)*) => {
        $crate::cli::out::note_line(format_args!($($arg)*))
    };
}

pub(crate) use {note, say};
