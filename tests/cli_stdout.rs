//! What the command line prints when standard output fails: a full disk ends the run with
//! `error: writing to standard output: REASON` and status 1; a reader that went away (a broken
//! pipe, as `head` leaves) ends the printing quietly and the run ends as it would have. Never
//! a panic.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// `/dev/full`: every write to it fails with "No space left on device".
fn dev_full() -> std::fs::File {
    std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .expect("open /dev/full")
}

/// Runs `verdant ARGS` in `cwd` with standard output on `/dev/full`.
fn run_into_full(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(dev_full())
        .stderr(Stdio::piped())
        .output()
        .expect("run verdant")
}

/// Runs `verdant ARGS` in `cwd` with standard output a pipe whose reader is gone before the
/// run prints anything.
fn run_into_closed_pipe(args: &[&str], cwd: &Path) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run verdant");
    drop(child.stdout.take());
    child.wait_with_output().expect("wait for verdant")
}

/// The run failed with status 1 and said that standard output could not be written, without a
/// panic.
fn assert_stdout_error(what: &str, out: &Output) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{what} panicked: {stderr}");
    assert_eq!(out.status.code(), Some(1), "{what}: {stderr}");
    assert!(
        stderr.contains("error: writing to standard output: No space left on device"),
        "{what}: the error does not name standard output and the reason: {stderr}"
    );
}

/// A small DEM in `dir`, and the bake arguments that make a world of it at `dir/NAME`.
fn small_dem(dir: &Path) -> PathBuf {
    common::write_dem(dir, "hills", [48, 40], [20.0, 25.0], [0.0, 0.5], |x, y| {
        200.0 + 80.0 * (x / 300.0).sin() * (y / 400.0).cos()
    })
}

fn bake_args<'a>(dem: &'a Path, out: &'a str) -> Vec<&'a str> {
    vec![
        "bake",
        "--dem",
        dem.to_str().unwrap(),
        "--out",
        out,
        "--tile-cells",
        "16",
        "--levels",
        "2",
    ]
}

#[test]
fn bake_into_a_full_stdout_fails_saying_so() {
    let tmp = tempfile::tempdir().unwrap();
    let dem = small_dem(tmp.path());
    let out = run_into_full(&bake_args(&dem, "w"), tmp.path());
    assert_stdout_error("bake > /dev/full", &out);
    // The summary is printed after the bake: the world is whole.
    assert!(tmp.path().join("w/world.toml").is_file());
}

#[test]
fn bake_into_a_closed_pipe_succeeds_quietly() {
    let tmp = tempfile::tempdir().unwrap();
    let dem = small_dem(tmp.path());
    let out = run_into_closed_pipe(&bake_args(&dem, "w"), tmp.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("panicked"),
        "bake | (closed) panicked: {stderr}"
    );
    assert_eq!(out.status.code(), Some(0), "bake | (closed): {stderr}");
    assert!(
        !stderr.contains("error"),
        "a broken pipe is no error: {stderr}"
    );
    assert!(tmp.path().join("w/world.toml").is_file());
}

#[test]
fn help_and_version_into_a_full_stdout_fail_saying_so() {
    let tmp = tempfile::tempdir().unwrap();
    for args in [
        &["--help"][..],
        &["-h"],
        &["--version"],
        &["bake", "--help"],
        &["help", "fly"],
    ] {
        let out = run_into_full(args, tmp.path());
        assert_stdout_error(&format!("verdant {} > /dev/full", args.join(" ")), &out);
    }
}

#[test]
fn help_into_a_closed_pipe_succeeds_quietly() {
    let tmp = tempfile::tempdir().unwrap();
    for args in [&["--help"][..], &["--version"]] {
        let out = run_into_closed_pipe(args, tmp.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
        assert!(stderr.is_empty(), "{args:?}: {stderr}");
    }
}

/// Help and errors on the arguments are as they were: the help on standard output with status
/// 0, a bad argument refused on standard error with status 2.
#[test]
fn help_and_bad_arguments_keep_their_output_and_status() {
    let tmp = tempfile::tempdir().unwrap();
    let help = common::verdant(&["--help"], tmp.path());
    assert_eq!(help.status.code(), Some(0));
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(text.starts_with("Streaming open-world terrain"), "{text}");
    assert!(text.contains("Usage: verdant"), "{text}");
    let version = common::verdant(&["--version"], tmp.path());
    assert_eq!(version.status.code(), Some(0));
    assert_eq!(
        String::from_utf8_lossy(&version.stdout),
        format!("verdant {}\n", env!("CARGO_PKG_VERSION"))
    );
    // A bad argument with standard output full: still clap's error, status 2.
    let bad = run_into_full(&["fly", "--no-such-option"], tmp.path());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--no-such-option"), "{stderr}");
    assert!(!stderr.contains("writing to standard output"), "{stderr}");
    // No subcommand: clap's help on standard error, status 2.
    let none = run_into_full(&[], tmp.path());
    assert_eq!(none.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&none.stderr).contains("Usage: verdant"));
}

/// `serve` prints its address and then serves until stopped: with standard output full it
/// stops at once, saying why.
#[test]
fn serve_into_a_full_stdout_fails_saying_so() {
    let tmp = tempfile::tempdir().unwrap();
    let world = common::default_world();
    let mut child = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["serve", world.to_str().unwrap(), "--addr", "127.0.0.1:0"])
        .current_dir(tmp.path())
        .stdin(Stdio::null())
        .stdout(dev_full())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run verdant serve");
    let deadline = Instant::now() + Duration::from_secs(30);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            child.kill().unwrap();
            let out = child.wait_with_output().unwrap();
            panic!(
                "serve went on serving with its standard output full: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    assert_stdout_error("serve > /dev/full", &out);
}
