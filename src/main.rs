//! The `verdant` command line: parses the arguments and hands each command to its module
//! under `cli/`.

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};

mod cli;

use cli::bake::BakeArgs;
use cli::bench::BenchCommand;
use cli::check::CheckArgs;
use cli::eval::EvalCommand;
use cli::fly::FlyArgs;
use cli::out::note;
use cli::soak::SoakArgs;
use cli::view::ViewArgs;

/// Streaming open-world terrain with GPU grass.
#[derive(Parser)]
#[command(version, about, allow_negative_numbers = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render PNG frames along a camera path and write report.json.
    #[command(allow_negative_numbers = true)]
    Fly(Box<FlyArgs>),
    /// Open a window on a world: drag the mouse to look, WASD to fly, Q/E down and up, Shift
    /// faster, the wheel or +/- for speed, P to follow the camera path (N: next path), 1-9 for
    /// the wind scenes, L for the LOD overlay, T for the anti-aliasing, V for vsync, Esc to
    /// quit. Figures in the title.
    #[command(allow_negative_numbers = true)]
    View(ViewArgs),
    /// Fly fast with random turns and teleports; check the streaming ceilings, holes and memory.
    /// Writes soak.json and exits non-zero if a check failed.
    #[command(allow_negative_numbers = true)]
    Soak(SoakArgs),
    /// Serve a world folder over HTTP (GET and HEAD, content types, ETag and Last-Modified,
    /// conditional GET), for `verdant fly http://HOST:PORT/` and the like. For production, put
    /// the folder behind any ordinary HTTP server, object store or CDN.
    #[command(allow_negative_numbers = true)]
    Serve {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: std::ffi::OsString,
        /// Address to listen on (port 0 picks a free port).
        #[arg(long, default_value = "127.0.0.1:8000")]
        addr: String,
    },
    /// Benchmarks of the renderer.
    ///
    /// Ctrl-C (or SIGTERM) stops a benchmark at its next frame, view or setting: what it
    /// measured so far is written (the JSON report marked "interrupted": true, the charts'
    /// titles "partial") and it exits with status 130; a second Ctrl-C ends it at once.
    #[command(allow_negative_numbers = true)]
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Measure methods against real data and chart speed against accuracy.
    ///
    /// Ctrl-C (or SIGTERM) stops an evaluation after the method or run under way: those done
    /// are written (the charts' titles "partial") and it exits with status 130; a second
    /// Ctrl-C ends it at once.
    #[command(allow_negative_numbers = true)]
    Eval {
        #[command(subcommand)]
        what: EvalCommand,
    },
    /// Bake a DEM (GeoTIFF, SRTM .hgt, or 16-bit PNG with a JSON sidecar) into a world folder.
    #[command(allow_negative_numbers = true)]
    Bake(BakeArgs),
    /// Read every stored tile of a world as the renderer reads it, on disk or over HTTP: each
    /// file decoded and checked against the manifest and against the stamp its bake wrote into
    /// it (which tile, which bake), and every plant file the world names, loaded as the
    /// renderer loads it. Lists the tiles and plant files that cannot be read and exits non-zero
    /// if there is one.
    ///
    /// Ctrl-C (or SIGTERM) stops the check: it says how far it got and exits with status 130.
    Check(CheckArgs),
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Fly(args) => match args.truth {
            Some(k) => {
                args.check_truth_options()?;
                cli::fly::fly_truth(args.options()?, k)
            }
            None => cli::fly::fly(args.options()?),
        },
        Command::View(args) => cli::view::view(args),
        Command::Soak(args) => cli::soak::soak(args.options()?),
        Command::Serve { world, addr } => cli::serve::serve(&world, &addr),
        Command::Bench { what } => cli::bench::run(what),
        Command::Eval { what } => cli::eval::run(what),
        Command::Bake(args) => cli::bake::bake_world(args),
        Command::Check(args) => cli::check::check(args),
    }
}

/// The error and its causes, joined by ": ", leaving out a cause that the message before it
/// already quotes (typed errors name their file and repeat their source's message).
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

/// Whether `e` ends a run that Ctrl-C (SIGINT) or SIGTERM stopped: a run that wrote what it
/// had, or a bake that was cancelled and removed what it had begun.
fn interrupted(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause.downcast_ref::<cli::Interrupted>().is_some()
            || cause
                .downcast_ref::<verdant::tools::stop::Stopped>()
                .is_some()
            || matches!(
                cause.downcast_ref::<verdant::world::WorldError>(),
                Some(verdant::world::WorldError::Cancelled { .. })
            )
    })
}

fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        // --help, --version and `help`: on standard output, checked, as every line the tool
        // prints (clap's own printing ignores a failed write and exits 0).
        Err(e) if !e.use_stderr() => {
            let printed = e
                .print()
                .and_then(|()| std::io::Write::flush(&mut std::io::stdout()));
            return match cli::out::checked(printed) {
                Ok(()) => ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(1)),
                Err(failed) => {
                    note!("error: {failed}");
                    ExitCode::FAILURE
                }
            };
        }
        // A bad argument: clap's error on standard error, status 2.
        Err(e) => e.exit(),
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if let Some(failed) = e
                .chain()
                .find_map(|c| c.downcast_ref::<cli::out::StdoutFailed>())
            {
                // Standard output is gone whatever the run was doing: said alone.
                note!("error: {failed}");
                return ExitCode::FAILURE;
            }
            if interrupted(&e) {
                note!("interrupted: {}", cli::terminal_safe(&error_chain(&e)));
                return ExitCode::from(130);
            }
            // A file's name in the message must not drive the terminal.
            note!("error: {}", cli::terminal_safe(&error_chain(&e)));
            ExitCode::FAILURE
        }
    }
}
