//! Every numeric option of the command line has a stated range: a value outside it is refused
//! before anything runs, with the option and the range in the message, exit code 2 and no panic.

use std::process::Command;

/// Runs `verdant ARGS` and returns its exit code and stderr.
fn run(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .output()
        .expect("run verdant");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `verdant ARGS` and checks that it was refused with exit code `code`, without a panic,
/// its error saying each of `says`.
fn assert_refused(args: &[&str], code: i32, says: &[&str]) {
    let (got, stderr) = run(args);
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    assert_eq!(got, Some(code), "{args:?} exited {got:?}: {stderr}");
    for s in says {
        assert!(
            stderr.contains(s),
            "{args:?}: the error does not say {s:?}: {stderr}"
        );
    }
}

/// Each case: the arguments, and what the error must say (the option and its range).
const OUT_OF_RANGE: &[(&[&str], &[&str])] = &[
    // A timeout that overflowed the deadline's arithmetic (it panicked).
    (
        &[
            "fly",
            "http://127.0.0.1:9/",
            "--http-timeout-s",
            "18446744073709551615",
        ],
        &["--http-timeout-s", "1..=3600"],
    ),
    (
        &["fly", "--http-timeout-s", "0"],
        &["--http-timeout-s", "1..=3600"],
    ),
    // Loads in flight that left streaming dead (nothing loaded, exit 0).
    (
        &["fly", "--max-loads", "18446744073709551615"],
        &["--max-loads", "1..=64"],
    ),
    (&["soak", "--max-loads", "0"], &["--max-loads", "1..=64"]),
    (&["check", "--threads", "0"], &["--threads", "1..=64"]),
    (&["check", "--threads", "65"], &["--threads", "1..=64"]),
    // Retries whose doubling backoff ran for hours.
    (
        &["fly", "--http-retries", "30"],
        &["--http-retries", "0..=20"],
    ),
    // A soak camera that left the world at once.
    (&["soak", "--speed", "1e300"], &["--speed", "0..=1000"]),
    (&["soak", "--speed", "NaN"], &["--speed", "0..=1000"]),
    (
        &["soak", "--seconds", "inf"],
        &["--seconds", "4.6..=604800"],
    ),
    (&["soak", "--seconds=-5"], &["--seconds", "4.6..=604800"]),
    (
        &["soak", "--seconds", "0.5"],
        &["--seconds", "4.6..=604800"],
    ),
    (
        &["soak", "--seconds", "4.5"],
        &["--seconds", "4.6..=604800"],
    ),
    (
        &["soak", "--max-stall-ms", "0"],
        &["--max-stall-ms", "1..=3600000"],
    ),
    (
        &["soak", "--max-recovery-frames", "0"],
        &["--max-recovery-frames", "1..=100000"],
    ),
    (&["view", "--frames", "0"], &["--frames", "1..=4294967295"]),
    // A DEM cell past 1,000 km would make an extent beyond f64 of a large DEM.
    (
        &[
            "bake",
            "--dem",
            "d.tif",
            "--out",
            "w",
            "--dem-cell-size",
            "1e308",
        ],
        &["--dem-cell-size", "at most 1e6"],
    ),
    (
        &[
            "eval",
            "derive",
            "--dem",
            "d.tif",
            "--dem-cell-size",
            "5,1e7",
        ],
        &["--dem-cell-size", "at most 1e6"],
    ),
    (
        &["fly", "--frames", "4294967296"],
        &["--frames", "1..=4294967295"],
    ),
    (
        &["fly", "--atlas-slots", "1"],
        &["--atlas-slots", "2..=4096"],
    ),
    (
        &["fly", "--cache-mib", "0"],
        &["--cache-mib", "1..=1048576"],
    ),
    (
        &["fly", "--http-cache-mib", "99999999999999"],
        &["--http-cache-mib", "1..=1048576"],
    ),
    (&["fly", "--size", "0x10"], &["--size", "1 to 16384"]),
    (
        &["bench", "lod", "--dolly-frames", "1001"],
        &["--dolly-frames", "2..=1000"],
    ),
    (&["bench", "lod", "--rounds", "0"], &["--rounds", "1..=100"]),
    (
        &["bench", "lod", "--supersample", "9"],
        &["--supersample", "1..=8"],
    ),
    (
        &["bench", "lod", "--flight-frames", "1"],
        &["--flight-frames", "2..=2000"],
    ),
    (
        &["bench", "features", "--timed-frames", "0"],
        &["--timed-frames", "1..=150"],
    ),
    (
        &["bench", "blades", "--warmup-frames", "101"],
        &["--warmup-frames", "0..=100"],
    ),
    (
        &["fly", "--grass-view-m", "5"],
        &["--grass-view-m", "10..=300"],
    ),
    (
        &["fly", "--taa-blade-motion", "--taa-sway-falloff", "17"],
        &["--taa-sway-falloff", "0..=16"],
    ),
    // The sway is measured by the blades' motion vectors: without them the option is refused.
    (&["fly", "--taa-sway-falloff", "4"], &["--taa-blade-motion"]),
    (
        &["bench", "aa", "--taa-sway-falloff", "0,20"],
        &["--taa-sway-falloff", "0..=16"],
    ),
    (
        &["bench", "aa", "--truth-reach", "0.5"],
        &["--truth-reach", "1..=9"],
    ),
    (&["bench", "aa", "--frames", "1"], &["--frames", "2..=600"]),
    (
        &["bench", "aa", "--taa-samples", "16,1"],
        &["--taa-samples", "2..=256"],
    ),
    (
        &["bench", "aa", "--taa-clip", "20"],
        &["--taa-clip", "0.25..=16"],
    ),
    (
        &["bench", "aa", "--sequences", "still,jump"],
        &["--sequences", "still, dolly, pan, teleport"],
    ),
    (
        &["bench", "aa", "--taa-blade-motion", "yes"],
        &["--taa-blade-motion", "neither on nor off"],
    ),
    (
        &["fly", "--taa-samples", "300"],
        &["--taa-samples", "2..=256"],
    ),
    (&["fly", "--taa-clip", "nan"], &["--taa-clip", "0.25..=16"]),
    (&["fly", "--aa", "fxaa"], &["--aa", "off, taa, msaa"]),
    // A negative number is a value like any other, refused by its range.
    (&["soak", "--speed", "-1"], &["--speed", "0..=1000"]),
    (&["fly", "--frames", "-3"], &["--frames", "1..=4294967295"]),
    (
        &["bench", "blades", "--field-m", "5001"],
        &["--field-m", "10..=5000"],
    ),
    (
        &["bench", "blades", "--fov-deg", "170"],
        &["--fov-deg", "between 1 and 170"],
    ),
    (
        &["bake", "--dem", "d.png", "--out", "w", "--levels", "0"],
        &["--levels", "1..=12"],
    ),
    (
        &["bake", "--dem", "d.png", "--out", "w", "--tile-cells", "96"],
        &["--tile-cells", "a power of two in 8..=1024"],
    ),
];

#[test]
fn out_of_range_options_are_refused_with_their_range() {
    for (args, says) in OUT_OF_RANGE {
        assert_refused(args, 2, says);
    }
}

#[test]
fn every_numeric_option_states_its_range_in_its_help() {
    // The options above, as `--help` documents them.
    for (sub, options) in [
        (
            &["fly"][..],
            &[
                "--frames",
                "--max-loads",
                "--http-timeout-s",
                "--http-retries",
                "--atlas-slots",
                "--cache-mib",
                "--http-cache-mib",
                "--grass-spacing-m",
                "--grass-width-scale",
                "--grass-infill-m",
                "--grass-segments",
                "--grass-near-m",
                "--mesh-step",
            ][..],
        ),
        (
            &["soak"][..],
            &[
                "--seconds",
                "--speed",
                "--max-recovery-frames",
                "--max-stall-ms",
            ][..],
        ),
        (
            &["bench", "lod"][..],
            &[
                "--dolly-frames",
                "--warmup-frames",
                "--timed-frames",
                "--rounds",
            ][..],
        ),
        (&["bench", "blades"][..], &["--field-m", "--counts"][..]),
        (
            &["bake"][..],
            &["--tile-cells", "--levels", "--memory-mib"][..],
        ),
        (&["eval", "derive"][..], &["--factor"][..]),
        (&["check"][..], &["--threads"][..]),
    ] {
        let mut args = sub.to_vec();
        args.push("--help");
        let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args(&args)
            .output()
            .unwrap();
        let help = String::from_utf8_lossy(&out.stdout);
        for o in options {
            let at = help
                .find(&format!("{o} "))
                .unwrap_or_else(|| panic!("{sub:?} has no {o}"));
            let entry: String = help[at..].lines().take(4).collect();
            assert!(
                entry.contains("..="),
                "{sub:?} {o}'s help states no range: {entry}"
            );
        }
    }
}

/// The benchmarks measure worlds on disk: an address is refused naming it (it was looked for
/// as a folder, "world directory not found").
#[test]
fn a_benchmark_of_a_world_over_http_is_refused_naming_the_address() {
    for bench in ["lod", "features", "aa"] {
        assert_refused(
            &["bench", bench, "http://127.0.0.1:9/w/"],
            1,
            &["http://127.0.0.1:9/w/: the benchmarks measure a world on disk"],
        );
    }
}

/// A soak whose camera would leave the world within a few frames (it once flew off at
/// 1e300 m/s, loaded nothing and passed) is refused before it flies, with the range for the
/// world; the library checks what the command line's range cannot know.
#[test]
fn a_soak_too_fast_for_its_world_is_refused_by_the_library() {
    let tmp = tempfile::tempdir().unwrap();
    for speed in [1e300, 5.0e4] {
        let opts = verdant::tools::SoakOptions {
            world: std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz"),
            speed_mps: speed,
            out: tmp.path().join("soak"),
            ..Default::default()
        };
        let e = verdant::tools::run_soak(&opts, &mut |_, _| {}).unwrap_err();
        let text = format!("{e:#}");
        assert!(
            text.contains("--speed") && text.contains("m/s for this world"),
            "{text}"
        );
    }
    // A world 1 m across takes at most 0.4 m/s (a frame of 0.1 s may step 4% of it): the range
    // is given as it is checked, not rounded to "0..=0".
    let small = tmp.path().join("small");
    std::fs::create_dir(&small).unwrap();
    let default = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
    let manifest = std::fs::read_to_string(default.join("world.toml")).unwrap();
    let manifest: String = manifest
        .lines()
        .map(|l| match l.starts_with("extent_m = ") {
            true => "extent_m = [1.0, 1.0]".to_string(),
            false => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(small.join("world.toml"), manifest).unwrap();
    std::os::unix::fs::symlink(default.join("tiles"), small.join("tiles")).unwrap();
    let opts = verdant::tools::SoakOptions {
        world: small,
        speed_mps: 0.5,
        out: tmp.path().join("soak"),
        ..Default::default()
    };
    let e = verdant::tools::run_soak(&opts, &mut |_, _| {}).unwrap_err();
    let text = format!("{e:#}");
    assert!(
        text.contains("(a world 1 m across)") && text.contains("it must be in 0..=0.4 m/s"),
        "{text}"
    );
}

/// The grass options and the mesh step have no range of their own on the command line: the
/// library's `RendererConfig::validate` checks them, and fly's error names the option and the
/// range, exits non-zero without a panic, and writes nothing.
#[test]
fn renderer_settings_out_of_range_are_refused_by_the_library_naming_the_option() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("fly");
    let out_arg = out.to_str().unwrap();
    for (args, says) in [
        (
            &["--grass-segments", "5,0,3"][..],
            &["--grass-segments", "1..=64 each"][..],
        ),
        (
            &["--grass-spacing-m", "9"],
            &["--grass-spacing-m", "0.02..=5 m"],
        ),
        (
            &["--grass-infill-m", "5,10"],
            &["--grass-infill-m", "no larger than the half-spacing one"],
        ),
        (&["--mesh-step", "3"], &["--mesh-step", "1..=16"]),
    ] {
        let mut all = vec!["fly", "--frames", "1", "--out", out_arg];
        all.extend_from_slice(args);
        assert_refused(&all, 1, says);
        assert!(!out.exists(), "{args:?} wrote its output folder");
    }
}

/// What the command line cannot check alone is checked before any work, exit code 1, naming
/// the option: a feature both switched off and on, a temporal setting out of range for another
/// (`--taa-min-samples` above `--taa-samples`); and negative coordinates are values, not
/// options (`--camera -5,0,15` reaches the check of `--counts`).
#[test]
fn options_checked_together_name_the_option() {
    for (args, says) in [
        (
            &["fly", "--disable", "plants,shadows", "--enable", "shadows"][..],
            &["--disable and --enable both name shadows"][..],
        ),
        (
            &[
                "bench",
                "aa",
                "--size",
                "32x18",
                "--taa-samples",
                "2",
                "--taa-min-samples",
                "10",
            ][..],
            &["--taa-min-samples", "1..=2"][..],
        ),
        (
            &["fly", "--aa", "off", "--taa-clip", "3"][..],
            &["--taa-clip", "--aa off"][..],
        ),
        (
            &["bench", "aa", "--aa", "off,msaa", "--taa-samples", "24"][..],
            &["--taa-samples", "--aa does not list taa"][..],
        ),
        (
            &["bench", "aa", "--taa-clip", "2,3,2"][..],
            &["--taa-clip lists 2 twice"][..],
        ),
        (
            &["bench", "blades", "--camera", "-5,0,15", "--counts", "1"][..],
            &["--counts 1", "1600..="][..],
        ),
    ] {
        assert_refused(args, 1, says);
    }
    // One option that needs another is a usage error, said by the command line itself.
    assert_refused(
        &["view", "--screenshot", "shot.png"],
        2,
        &["--screenshot", "--frames"],
    );
}
