//! The command line's modules, one a command: its clap arguments, how they become the tool's
//! options, and what it prints. `main.rs` parses and dispatches.

pub(crate) mod args;
pub(crate) mod bake;
pub(crate) mod bench;
pub(crate) mod eval;
pub(crate) mod fly;
pub(crate) mod progress;
pub(crate) mod serve;
pub(crate) mod soak;
pub(crate) mod view;
