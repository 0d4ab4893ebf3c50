//! The command line's modules, one a command: its clap arguments, how they become the tool's
//! options, and what it prints. `main.rs` parses and dispatches.

pub(crate) mod args;
pub(crate) mod bake;
pub(crate) mod bench;
pub(crate) mod check;
pub(crate) mod eval;
pub(crate) mod fly;
pub(crate) mod out;
pub(crate) mod progress;
pub(crate) mod serve;
pub(crate) mod soak;
pub(crate) mod view;

/// The flag that Ctrl-C (SIGINT) and SIGTERM set for a long run (a bake, a flight, a soak),
/// which then stops cleanly; a second signal ends the process at once.
pub(crate) fn stop_on_signals() -> anyhow::Result<verdant::bake::CancelFlag> {
    use anyhow::Context;
    verdant::bake::CancelFlag::on_termination_signals()
        .context("installing the SIGINT and SIGTERM handlers")
}

/// A run stopped by Ctrl-C (SIGINT) or SIGTERM after writing what it had: the process exits
/// with status 130, as a shell reports a command ended by SIGINT.
#[derive(Debug)]
pub(crate) struct Interrupted(pub(crate) String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// `text` safe to print to a terminal: every control character but a tab or a line break
/// written as an escape (`\u{1b}`), so that a file's name cannot drive the terminal.
pub(crate) fn terminal_safe(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if verdant::world::manifest::forbidden_control(c) {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// A path as [`terminal_safe`] prints it.
pub(crate) fn shown(path: &std::path::Path) -> String {
    terminal_safe(&path.display().to_string())
}
