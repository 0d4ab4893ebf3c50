//! `verdant bench`: the benchmarks' subcommands, their timing options and the tables they
//! print.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Subcommand;
use verdant::tools::timing::Timing;

use super::args::{float_in, parse_size, parse_vec3, resolve_world};
use super::out::{note, say};
use super::progress::{finish_bars, stage_bars};

#[derive(Subcommand)]
pub(crate) enum BenchCommand {
    /// The grass renderers' benchmark: a flat field of one grass type generated in memory,
    /// swept over blade counts; GPU time per pass, ns per blade and per vertex, the ratio to a
    /// bare pass drawing as many vertices, and the image error against no LOD.
    #[command(allow_negative_numbers = true)]
    Blades {
        /// Output folder.
        #[arg(long, default_value = "out/bench-blades")]
        out: PathBuf,
        /// Image size, WIDTHxHEIGHT, 1..=16384 pixels a side.
        #[arg(long, default_value = "1920x1080", value_parser = parse_size)]
        size: (u32, u32),
        /// Edge of the square field, metres, 10..=5000.
        #[arg(long, default_value_t = 200.0, value_parser = float_in(10.0, 5000.0))]
        field_m: f64,
        /// Camera position X,Y,Z in metres (x east, y north, z up), each within 100 km of the
        /// origin.
        #[arg(long, default_value = "-20,-20,15", value_parser = parse_vec3, allow_hyphen_values = true)]
        camera: [f64; 3],
        /// The point the camera looks at, X,Y,Z in metres, each within 100 km of the origin and
        /// at least 1 cm from --camera.
        #[arg(long, default_value = "100,100,0", value_parser = parse_vec3, allow_hyphen_values = true)]
        target: [f64; 3],
        /// Vertical field of view, degrees, between 1 and 170 (both excluded).
        #[arg(long, default_value_t = 45.0, value_parser = super::args::float_between(1.0, 170.0))]
        fov_deg: f64,
        /// Blade counts of the sweep, comma-separated, 1 to 32 of them, each in the range that
        /// keeps blades 2 cm to 5 m apart in the field (1600..=100000004 in the default 200 m).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "100000,300000,1000000,3000000,10000000"
        )]
        counts: Vec<u64>,
        #[command(flatten)]
        timing: TimingArgs,
        #[command(flatten)]
        truth: TruthSamples,
    },
    /// Each grass feature's GPU cost against its contribution to the image (FLIP between the
    /// render with and without it), charted one against the other.
    #[command(allow_negative_numbers = true)]
    Features {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: std::ffi::OsString,
        /// Output folder.
        #[arg(long, default_value = "out/bench-features")]
        out: PathBuf,
        /// Image size, WIDTHxHEIGHT, 1..=16384 pixels a side.
        #[arg(long, default_value = "480x270", value_parser = parse_size)]
        size: (u32, u32),
        /// Anti-aliasing of every variant's frames: off, taa or msaa (default: the renderer's,
        /// taa).
        #[arg(long)]
        aa: Option<verdant::aa::AntiAliasing>,
        #[command(flatten)]
        timing: TimingArgs,
        #[command(flatten)]
        truth: TruthArgs,
    },
    /// The LOD transition benchmark: popping across the ring boundary, and GPU time against
    /// image error for a set of LOD settings, charted with the Pareto front.
    #[command(allow_negative_numbers = true)]
    Lod {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: std::ffi::OsString,
        /// Output folder.
        #[arg(long, default_value = "out/bench-lod")]
        out: PathBuf,
        /// Image size, WIDTHxHEIGHT, 1..=16384 pixels a side.
        #[arg(long, default_value = "480x270", value_parser = parse_size)]
        size: (u32, u32),
        /// Frames of the dolly, 2..=1000.
        #[arg(long, default_value_t = 48, value_parser = clap::value_parser!(u32).range(2..=1000))]
        dolly_frames: u32,
        /// Only these settings, by name, comma-separated (default: all; "default" and "no LOD"
        /// are always measured).
        #[arg(long, value_delimiter = ',')]
        settings: Vec<String>,
        /// Draw the settings' images at the four views (and the far band's) K x K sub-samples a
        /// pixel, as the truth is, 1..=8 (1: one sample, the frame as it is): their error is
        /// then what each setting draws differently from the truth, not its aliasing. The
        /// timings stay the setting's own frame.
        #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=8))]
        supersample: u32,
        /// The camera path whose start the dolly leaves from and along which the four views
        /// are spread (default: "meadow", else the world's first path).
        #[arg(long, value_name = "PATH")]
        path: Option<String>,
        /// The camera path each setting is also timed along, frame after frame, for the
        /// median and the 99th percentile of its frames' times (default: "tour" where the world
        /// has it, else the views' path; "" for none).
        #[arg(long, value_name = "PATH")]
        flight: Option<String>,
        /// Frames of the flight, evenly spaced along the whole path, 2..=2000.
        #[arg(long, default_value_t = verdant::tools::bench::DEFAULT_FLIGHT_FRAMES, value_parser = clap::value_parser!(u32).range(2..=2000))]
        flight_frames: u32,
        #[command(flatten)]
        timing: TimingArgs,
        #[command(flatten)]
        truth: TruthArgs,
    },
    /// Anti-aliasing against the supersampled truth: sequences of consecutive 60 Hz frames
    /// (still with wind, a dolly, a pan, a teleport) and views along the camera paths, per
    /// method: FLIP against the truth per frame, flicker relative to the truth's, recovery
    /// after the teleport, GPU time; charted with the Pareto front.
    #[command(allow_negative_numbers = true)]
    Aa {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: std::ffi::OsString,
        /// Output folder.
        #[arg(long, default_value = "out/bench-aa")]
        out: PathBuf,
        /// Image sizes, WIDTHxHEIGHT (1..=16384 pixels a side), comma-separated: each is measured in full.
        #[arg(long, default_value = "960x540", value_delimiter = ',', value_parser = parse_size)]
        size: Vec<(u32, u32)>,
        /// Methods, comma-separated (off, taa, msaa).
        #[arg(long, default_value = "off,taa,msaa", value_delimiter = ',', value_parser = parse_method)]
        aa: Vec<verdant::aa::AntiAliasing>,
        /// Measured frames of each sequence, 2..=600.
        #[arg(long, default_value_t = 24, value_parser = clap::value_parser!(u32).range(2..=600))]
        frames: u32,
        /// Frames of the same motion before each sequence's measured ones, and of flight
        /// before each view of the paths, 0..=120.
        #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(0..=120))]
        run_up: u32,
        #[command(flatten)]
        truth: TruthArgs,
        /// The paths part also measures the truth's own sampling error: the truth at twice its
        /// sub-samples a side (8x8 for the 4x4 truth; four times its renders), reported as the
        /// bound truth-8x8. Its FLIP against the truth is about what an exact frame would err.
        #[arg(long)]
        truth_noise: bool,
        /// The camera path whose first view the sequences start from.
        #[arg(long, default_value = "meadow")]
        path: String,
        /// Paths of the views-along-paths part, comma-separated ("" for none).
        #[arg(long, default_value = "meadow,tour,wind-tour", value_delimiter = ',')]
        paths: Vec<String>,
        /// The sequences, comma-separated (still, dolly, pan, teleport).
        #[arg(long, default_value = "still,dolly,pan,teleport", value_delimiter = ',', value_parser = parse_motion)]
        sequences: Vec<verdant::tools::bench_aa::Motion>,
        /// bench lod's settings, by name, comma-separated: each method is measured with each
        /// of them too, reported as METHOD+SETTING (its spaces and slashes as dashes:
        /// taa+segments-7-3-3-view-x1.5); the default's settings are always measured. "truth
        /// content" draws the truth's content (its settings at its reach) at one sample a
        /// pixel: what the scene the truth draws costs, and how each method samples it.
        #[arg(long, value_delimiter = ',')]
        settings: Vec<String>,
        #[command(flatten)]
        taa: Box<TaaLists>,
        #[command(flatten)]
        timing: TimingArgs,
    },
}

/// The temporal method's settings as lists: every combination is measured as a method of its
/// own.
#[derive(clap::Args)]
pub(crate) struct TaaLists {
    /// With taa: the most samples a pixel's history holds, 2..=256, comma-separated (default
    /// 24): every combination with the other --taa-* lists is measured as a method of its
    /// own.
    #[arg(long, value_name = "N,...", value_delimiter = ',', value_parser = clap::value_parser!(u32).range(2..=256))]
    pub(crate) taa_samples: Vec<u32>,
    /// With taa: the history's clip, standard deviations of the neighbourhood, 0.25..=16,
    /// comma-separated (default 2.5).
    #[arg(long, value_name = "SIGMA,...", value_delimiter = ',', value_parser = float_in(0.25, 16.0))]
    pub(crate) taa_clip: Vec<f64>,
    /// With taa: how fast a moving surface's history shortens (at most N / (1 + F x pixels
    /// moved) samples), 0..=16, comma-separated (default 1).
    #[arg(long, value_name = "F,...", value_delimiter = ',', value_parser = float_in(0.0, 16.0))]
    pub(crate) taa_falloff: Vec<f64>,
    /// With taa: the grass blades write their own motion vectors ("on,off" measures both).
    #[arg(long, value_name = "on|off,...", value_delimiter = ',', value_parser = parse_on_off)]
    pub(crate) taa_blade_motion: Vec<bool>,
    /// With taa: the clip's reach around the current sample, in the pixel's own standard
    /// deviations over time, 0..=16, comma-separated (default 0).
    #[arg(long, value_name = "K,...", value_delimiter = ',', value_parser = float_in(0.0, 16.0))]
    pub(crate) taa_pixel_spread: Vec<f64>,
    /// With taa: how much faster a surface's history shortens with its parallax (at most
    /// N / (1 + F x pixels moved + P x pixels of parallax) samples), 0..=16,
    /// comma-separated (default 2).
    #[arg(long, value_name = "P,...", value_delimiter = ',', value_parser = float_in(0.0, 16.0))]
    pub(crate) taa_parallax_falloff: Vec<f64>,
    /// With taa: the fewest samples a moving surface's history keeps, 1..=256 and at most
    /// the history's length, comma-separated (default 1).
    #[arg(long, value_name = "M,...", value_delimiter = ',', value_parser = float_in(1.0, 256.0))]
    pub(crate) taa_min_samples: Vec<f64>,
    /// With taa: the standard deviation (pixels) of the Gaussian that reconstructs the
    /// current frame at each pixel's centre from its 3x3 jittered samples, 0..=2,
    /// comma-separated (default 0.45; 0: each pixel's own sample).
    #[arg(long, value_name = "PX,...", value_delimiter = ',', value_parser = float_in(0.0, 2.0))]
    pub(crate) taa_reconstruct: Vec<f64>,
    /// With taa and the blades' motion vectors: how much faster a blade's history shortens
    /// with its own sway in the wind (at most N / (1 + F x pixels moved + P x pixels of
    /// parallax + S x pixels of sway) samples), 0..=16, comma-separated (default 0; without
    /// the motion vectors it changes nothing).
    #[arg(long, value_name = "S,...", value_delimiter = ',', value_parser = float_in(0.0, 16.0))]
    pub(crate) taa_sway_falloff: Vec<f64>,
}

impl TaaLists {
    /// Refuses a list that names a value twice (naming the option and the value), and any list
    /// given when the methods (`with_taa` false) do not include the temporal one.
    fn check(&self, with_taa: bool) -> Result<()> {
        fn shown<T: std::fmt::Display>(v: &[T]) -> Vec<String> {
            v.iter().map(ToString::to_string).collect()
        }
        let on_off = |v: &[bool]| -> Vec<String> {
            v.iter()
                .map(|&m| if m { "on" } else { "off" }.to_owned())
                .collect()
        };
        let lists = [
            ("--taa-samples", shown(&self.taa_samples)),
            ("--taa-clip", shown(&self.taa_clip)),
            ("--taa-falloff", shown(&self.taa_falloff)),
            ("--taa-blade-motion", on_off(&self.taa_blade_motion)),
            ("--taa-pixel-spread", shown(&self.taa_pixel_spread)),
            ("--taa-parallax-falloff", shown(&self.taa_parallax_falloff)),
            ("--taa-min-samples", shown(&self.taa_min_samples)),
            ("--taa-reconstruct", shown(&self.taa_reconstruct)),
            ("--taa-sway-falloff", shown(&self.taa_sway_falloff)),
        ];
        for (option, values) in &lists {
            if !values.is_empty() && !with_taa {
                anyhow::bail!(
                    "{option} sets the temporal anti-aliasing, and --aa does not list taa: \
                     leave it out, or add taa to --aa"
                );
            }
            if let Some(v) = verdant::tools::bench::repeated(values) {
                anyhow::bail!("{option} lists {v} twice");
            }
        }
        Ok(())
    }
}

/// Parses a sequence's name.
fn parse_motion(s: &str) -> Result<verdant::tools::bench_aa::Motion, String> {
    verdant::tools::bench_aa::Motion::from_name(s)
        .ok_or_else(|| format!("{s:?} is not a sequence (still, dolly, pan, teleport)"))
}

/// `on` or `off`.
fn parse_on_off(s: &str) -> Result<bool, String> {
    match s.trim() {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("{s:?} is neither on nor off")),
    }
}

/// Every combination of the given history lengths, clips, falloffs, motion vectors, pixel
/// spreads, parallax falloffs, fewest samples, reconstructions and sway falloffs (the defaults
/// where none is given).
fn taa_variants(lists: &TaaLists) -> Vec<verdant::aa::taa::TaaSettings> {
    use verdant::aa::taa::TaaSettings;
    /// Every setting of `out` once for each of `values` (the outer lists vary slowest), or
    /// `out` as it is where none is given.
    fn times<T: Copy>(
        out: Vec<TaaSettings>,
        values: &[T],
        set: fn(&mut TaaSettings, T),
    ) -> Vec<TaaSettings> {
        if values.is_empty() {
            return out;
        }
        out.into_iter()
            .flat_map(|s| {
                values.iter().map(move |&v| {
                    let mut s = s;
                    set(&mut s, v);
                    s
                })
            })
            .collect()
    }
    let out = vec![TaaSettings::default()];
    let out = times(out, &lists.taa_samples, |s, n| s.max_samples = n);
    let out = times(out, &lists.taa_clip, |s, c| s.clip_sigma = c as f32);
    let out = times(out, &lists.taa_falloff, |s, f| s.motion_falloff = f as f32);
    let out = times(out, &lists.taa_blade_motion, |s, m| s.blade_motion = m);
    let out = times(out, &lists.taa_pixel_spread, |s, k| {
        s.pixel_spread = k as f32
    });
    let out = times(out, &lists.taa_parallax_falloff, |s, p| {
        s.parallax_falloff = p as f32
    });
    let out = times(out, &lists.taa_min_samples, |s, m| s.min_samples = m as f32);
    let out = times(out, &lists.taa_reconstruct, |s, r| {
        s.reconstruct_px = r as f32
    });
    times(out, &lists.taa_sway_falloff, |s, w| {
        s.sway_falloff = w as f32
    })
}

/// The world folder a benchmark measures: a folder or a world's name, not an address (its
/// tiles are read from disk, so that a network's delays stay out of the figures).
fn world_on_disk(arg: &std::ffi::OsStr) -> anyhow::Result<std::path::PathBuf> {
    if let Some(arg) = arg.to_str().filter(|a| verdant::stream::http::is_url(a)) {
        anyhow::bail!(
            "{arg}: the benchmarks measure a world on disk, not over HTTP (a network's delays \
             would be in their figures): copy the world's folder here, or fly it with `verdant \
             fly {arg}`"
        );
    }
    resolve_world(arg)
}

/// Parses an anti-aliasing method's name.
fn parse_method(s: &str) -> Result<verdant::aa::AntiAliasing, String> {
    s.trim().parse()
}

/// What the benchmarks measure their images against.
#[derive(clap::Args, Clone, Copy)]
pub(crate) struct TruthArgs {
    #[command(flatten)]
    pub(crate) samples: TruthSamples,
    /// How far the truth draws blades, in default view distances, 1..=9 (67 m each in the
    /// default world; less is quicker, and the far band is then measured out to this many view
    /// distances only).
    #[arg(long, value_name = "R", default_value_t = verdant::tools::truth::REACH_FACTOR, value_parser = float_in(1.0, verdant::tools::truth::REACH_FACTOR))]
    pub(crate) truth_reach: f64,
}

/// The truth's sub-samples (all `bench blades` takes: its truth reaches over its whole field).
#[derive(clap::Args, Clone, Copy)]
pub(crate) struct TruthSamples {
    /// Sub-samples a pixel side of the truth (supersampled in linear light), 1..=8.
    #[arg(long, value_name = "K", default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=8))]
    pub(crate) truth: u32,
}

/// How the benchmarks time: interleaved rounds over the settings, each measurement's frames
/// back to back. The defaults give stable figures on a GPU (5 rounds of 20 frames after 5
/// untimed ones) and fewer on a software renderer (2 rounds of 3 after 1).
#[derive(clap::Args, Clone, Copy)]
pub(crate) struct TimingArgs {
    /// Untimed frames before each measurement's timed ones, 0..=100.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=100))]
    pub(crate) warmup_frames: Option<u32>,
    /// Timed frames of each measurement per round, 1..=150.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=150))]
    pub(crate) timed_frames: Option<u32>,
    /// Interleaved rounds over the settings, 1..=100.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100))]
    pub(crate) rounds: Option<u32>,
}

/// `value`, a figure of `timing`, with `decimals` decimals; "-" where a run stopped early did
/// not time it.
fn timed(timing: &Timing, value: f64, decimals: usize) -> String {
    if timing.measured() {
        format!("{value:.decimals$}")
    } else {
        "-".to_owned()
    }
}

/// The last line of a benchmark's summary: where it wrote, and that it is partial if the run
/// was stopped early.
fn wrote(out: &Path, interrupted: bool) -> Result<()> {
    if interrupted {
        say!("wrote {} (partial: the run was interrupted)", out.display())?;
    } else {
        say!("wrote {}", out.display())?;
    }
    Ok(())
}

/// The error that ends a benchmark stopped early (status 130): what `report` (a file in `out`)
/// holds of it, or that nothing was measured (and nothing written).
fn interrupted(measured: bool, out: &Path, report: &str, holds: String) -> anyhow::Error {
    if measured {
        super::Interrupted(format!(
            "stopped part-way; {} describes {holds}",
            out.join(report).display()
        ))
        .into()
    } else {
        super::Interrupted("stopped before the first measurement; nothing written".to_owned())
            .into()
    }
}

pub(crate) fn bench_features(mut opts: verdant::tools::BenchLodOptions) -> Result<()> {
    // Ctrl-C stops the run at the next view or variant, writing what was measured; a second
    // one ends the process at once.
    opts.stop = Some(super::stop_on_signals()?);
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::run_bench_features(&opts, &mut update)?;
    finish_bars(&bars, r.interrupted);
    if r.features.is_empty() {
        return Err(interrupted(false, &opts.out, "", String::new()));
    }
    say_adapter(&r.adapter, r.size)?;
    say!(
        "{:<18} {:>10} {:>8} {:>10} {:>13}",
        "feature off",
        "GPU ms",
        "IQR %",
        "cost ms",
        "contribution"
    )?;
    let full = r.features[0].timing;
    for f in &r.features {
        let t = &f.timing;
        say!(
            "{:<18} {:>10} {:>8} {:>10} {:>13.4}{}",
            f.feature,
            timed(t, f.gpu_ms, 3),
            timed(t, 100.0 * t.spread, 1),
            if full.measured() {
                timed(t, f.cost_ms, 3)
            } else {
                "-".to_owned()
            },
            f.contribution,
            if t.noisy { "  (spread above 10%)" } else { "" }
        )?;
    }
    wrote(&opts.out, r.interrupted)?;
    if r.interrupted {
        let timed = r.features.iter().filter(|f| f.timing.measured()).count();
        return Err(interrupted(
            true,
            &opts.out,
            "bench_features.json",
            format!(
                "the {} variants measured so far ({timed} of them timed)",
                r.features.len()
            ),
        ));
    }
    Ok(())
}

pub(crate) fn bench_blades(
    mut opts: verdant::tools::bench_blades::BenchBladesOptions,
) -> Result<()> {
    // Ctrl-C stops the run at the next blade count or timing, writing what was measured; a
    // second one ends the process at once.
    opts.stop = Some(super::stop_on_signals()?);
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::bench_blades::run_bench_blades(&opts, &mut update)?;
    finish_bars(&bars, r.interrupted);
    if r.results.is_empty() {
        return Err(interrupted(false, &opts.out, "", String::new()));
    }
    say_adapter(&r.adapter, r.size)?;
    say!(
        "{:>10} {:>9} {:>9} {:>11} {:>9} {:>9} {:>9} {:>8} {:>8} {:>7} {:>7} {:>7} {:>7}",
        "blades",
        "drawn hi",
        "drawn lo",
        "vertices",
        "gen ms",
        "draw ms",
        "floor ms",
        "ns/blade",
        "ns/vert",
        "x floor",
        "FLIP",
        "coarse",
        "vs noLOD"
    )?;
    for b in &r.results {
        let t = &b.draw;
        say!(
            "{:>10} {:>9} {:>9} {:>11} {:>9} {:>9} {:>9} {:>8} {:>8} {:>7} {:>7.4} {:>7.4} {:>8.4}{}",
            b.blades,
            b.drawn[0],
            b.drawn[1],
            b.vertices,
            timed(t, b.generate.median_ms, 3),
            timed(t, b.draw.median_ms, 3),
            timed(t, b.floor.median_ms, 3),
            b.ns_per_blade.map_or("-".into(), |v| timed(t, v, 2)),
            b.ns_per_vertex.map_or("-".into(), |v| timed(t, v, 3)),
            b.ratio_to_floor.map_or("-".into(), |v| timed(t, v, 2)),
            b.vs_truth.flip,
            b.vs_truth.coarse,
            b.flip_vs_no_lod,
            if b.draw.noisy || b.floor.noisy {
                "  (spread above 10%)"
            } else {
                ""
            }
        )?;
    }
    for b in r.results.iter().filter(|b| b.overflow > 0) {
        note!(
            "warning: with {} blades in the field, {} blades a frame did not fit the grass pool \
             (the device binds fewer blades a tile than the field needs): that count's figures \
             are of a frame without them (`overflow` in blades.csv and bench_blades.json)",
            b.blades,
            b.overflow
        );
    }
    if let Some(b) = r.results.iter().find(|b| b.drawn == [0, 0]) {
        note!(
            "warning: no blade was drawn with {} blades in the field: the camera (--camera, \
             --target) sees none of it; its times per blade and vertex are left empty",
            b.blades
        );
    }
    say!(
        "FLIP and coarse: against the {k}x{k} truth of the field; vs noLOD: pixel FLIP against the \
         same field with no LOD",
        k = r.truth_k
    )?;
    say!(
        "timing: {} rounds of {} frames after {} untimed, per count",
        r.counts.rounds,
        r.counts.timed,
        r.counts.warmup
    )?;
    wrote(&opts.out, r.interrupted)?;
    if r.interrupted {
        let timed = r.results.iter().filter(|b| b.draw.measured()).count();
        return Err(interrupted(
            true,
            &opts.out,
            "bench_blades.json",
            format!(
                "the {} of {} blade counts measured so far ({timed} of them timed)",
                r.results.len(),
                opts.counts.len()
            ),
        ));
    }
    Ok(())
}

pub(crate) fn bench_lod(mut opts: verdant::tools::BenchLodOptions) -> Result<()> {
    // Ctrl-C stops the run at the next frame, view or setting, writing what was measured; a
    // second one ends the process at once.
    opts.stop = Some(super::stop_on_signals()?);
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::run_bench_lod(&opts, &mut update)?;
    finish_bars(&bars, r.interrupted);
    if r.dolly.is_empty() {
        return Err(interrupted(false, &opts.out, "", String::new()));
    }
    say!(
        "{} [{}], {}x{}, the views along the path {:?}",
        r.adapter.name,
        r.adapter.backend,
        r.size.0,
        r.size.1,
        r.path
    )?;
    let flip = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
    say!(
        "dolly: largest jump of the error against the truth: {} FLIP on frames with ring switches, {} on frames without a switch (-: no such frame)",
        flip(r.worst_pop),
        flip(r.worst_change_without_switch)
    )?;
    if let Some(t) = r.worst_tree_pop {
        say!("dolly: {t:.4} FLIP on frames where trees switched level (and no ring)")?;
    }
    say!(
        "far band ({:.0}-{:.0} m, {} pixels) against the truth's blades out to {:.0} m: {} FLIP with the far field, {} without",
        r.far_band.near_m,
        r.far_band.far_m,
        r.far_band.band_pixels,
        r.far_band.far_m,
        flip(r.far_band.flip_far_field),
        flip(r.far_band.flip_no_far_field)
    )?;
    let unit = if r.adapter.timestamps { "GPU" } else { "frame" };
    say!(
        "{:<16} {:>9} {:>8} {:>10} {:>9} {:>9} {:>9} {:>10} {:>7} {:>11} {:>10}",
        "setting",
        "GPU ms",
        "IQR %",
        "frame ms",
        "FLIP",
        "coarse",
        "FLIP 1x",
        "blades",
        "front",
        "flight med",
        "flight p99"
    )?;
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    for s in &r.settings {
        let t = &s.frame;
        say!(
            "{:<16} {:>9} {:>8} {:>10} {:>9.4} {:>9.4} {:>9.4} {:>10.0} {:>7} {:>11} {:>10}{}",
            s.setting.name,
            timed(t, s.gpu.median_ms, 3),
            timed(t, 100.0 * s.gpu.spread, 1),
            timed(t, s.frame.median_ms, 2),
            s.vs_truth.flip,
            s.vs_truth.coarse,
            s.flip_frame_vs_truth,
            s.blades_drawn,
            if s.pareto { "yes" } else { "" },
            ms(s.flight.map(|f| f.median_ms)),
            ms(s.flight.map(|f| f.p99_ms)),
            if s.gpu.noisy || s.frame.noisy {
                "  (spread above 10%)"
            } else {
                ""
            }
        )?;
    }
    say!(
        "timing: {} rounds of {} frames after {} untimed, per view and setting",
        r.counts.rounds,
        r.counts.timed,
        r.counts.warmup
    )?;
    if r.supersample > 1 {
        say!(
            "the settings' images supersampled {k}x{k} (their content against the truth's; \
             FLIP 1x and the times of their own frames)",
            k = r.supersample
        )?;
    }
    // The fronts are over the settings timed: every setting, unless the run was stopped early.
    if r.settings.iter().any(|s| s.frame.measured()) {
        say!(
            "on the front against the {k}x{k} truth: {}; by the coarse FLIP: {}",
            r.front.join(", "),
            r.coarse_front.join(", "),
            k = r.truth_k
        )?;
    }
    if let Some(p) = &r.flight_path
        && r.settings.iter().any(|s| s.flight.is_some())
    {
        say!(
            "flight: {} frames along the path {p:?} per round ({unit} time per frame, after an \
             untimed flight); on the front of its p99 against the pixel FLIP: {}{}",
            r.flight_frames.unwrap_or(0),
            r.flight_front.join(", "),
            if r.default_on_flight_front == Some(false) {
                " (the default is not on it)"
            } else {
                ""
            }
        )?;
    }
    if let Some(on) = r.default_on_front {
        say!(
            "default setting {} the Pareto front",
            if on { "is on" } else { "is NOT on" }
        )?;
    }
    wrote(&opts.out, r.interrupted)?;
    if r.interrupted {
        let timed = r.settings.iter().filter(|s| s.frame.measured()).count();
        return Err(interrupted(
            true,
            &opts.out,
            "bench_lod.json",
            format!(
                "the {} of {} dolly frames and the {} settings measured so far ({timed} of them \
                 timed)",
                r.dolly.len(),
                opts.dolly_frames,
                r.settings.len()
            ),
        ));
    }
    Ok(())
}

pub(crate) fn bench_aa(mut opts: verdant::tools::bench_aa::BenchAaOptions) -> Result<()> {
    // Ctrl-C stops the run at the next frame, view or timing, writing what was measured; a
    // second one ends the process at once.
    opts.stop = Some(super::stop_on_signals()?);
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::bench_aa::run_bench_aa(&opts, &mut update)?;
    finish_bars(&bars, r.interrupted);
    if r.frames.is_empty() && r.paths.is_empty() {
        return Err(interrupted(false, &opts.out, "", String::new()));
    }
    if let (Some(first), Some(last)) = (r.stale_images.first(), r.stale_images.last()) {
        note!(
            "warning: {} image{} in {} {} an earlier run's, not this one's ({first}{}): this run \
             left {} as {} were",
            r.stale_images.len(),
            if r.stale_images.len() == 1 { "" } else { "s" },
            opts.out.display(),
            if r.stale_images.len() == 1 {
                "is"
            } else {
                "are"
            },
            if first == last {
                String::new()
            } else {
                format!(" .. {last}")
            },
            if r.stale_images.len() == 1 {
                "it"
            } else {
                "them"
            },
            if r.stale_images.len() == 1 {
                "it"
            } else {
                "they"
            },
        );
    }
    say!(
        "{} [{}], against the {}x{} truth",
        r.adapter.name,
        r.adapter.backend,
        r.truth_k,
        r.truth_k
    )?;
    // The method column as wide as its longest name (a setting's is long).
    let w = r
        .timings
        .iter()
        .map(|t| t.method.len())
        .chain(r.paths.iter().map(|p| p.method.len()))
        .max()
        .unwrap_or(0)
        .max(11);
    say!(
        "{:<10} {:<w$} {:<9} {:>8} {:>8} {:>9} {:>7} {:>9}",
        "size",
        "method",
        "sequence",
        "FLIP",
        "coarse",
        "flicker",
        "x truth",
        "recovery"
    )?;
    for s in &r.sequences {
        say!(
            "{:<10} {:<w$} {:<9} {:>8.4} {:>8.4} {:>9} {:>7} {:>9}",
            format!("{}x{}", s.size.0, s.size.1),
            s.method,
            s.motion.name(),
            s.flip_mean,
            s.coarse_flip_mean,
            s.flicker.map_or("-".into(), |f| format!("{f:.2}")),
            s.flicker_ratio.map_or("-".into(), |f| format!("{f:.2}")),
            s.recovery_frames.map_or(String::new(), |n| n.to_string())
        )?;
    }
    // The paths: each method's and each bound's mean over the path's views.
    struct PathRow<'a> {
        size: String,
        method: &'a str,
        path: &'a str,
        bound: bool,
        sums: [f64; 2],
        views: u32,
    }
    let mut rows: Vec<PathRow> = Vec::new();
    for p in &r.paths {
        let size = format!("{}x{}", p.size.0, p.size.1);
        match rows
            .iter_mut()
            .find(|x| x.size == size && x.method == p.method && x.path == p.path)
        {
            Some(x) => {
                x.sums[0] += p.flip;
                x.sums[1] += p.coarse_flip;
                x.views += 1;
            }
            None => rows.push(PathRow {
                size,
                method: &p.method,
                path: &p.path,
                bound: p.bound,
                sums: [p.flip, p.coarse_flip],
                views: 1,
            }),
        }
    }
    for x in rows {
        let n = f64::from(x.views);
        say!(
            "{:<10} {:<w$} path {:<10} FLIP {:.4}, coarse {:.4} over {} views{}",
            x.size,
            x.method,
            x.path,
            x.sums[0] / n,
            x.sums[1] / n,
            x.views,
            if x.bound { " (bound)" } else { "" }
        )?;
    }
    for t in &r.timings {
        say!(
            "{:<10} {:<w$} {} {:.3} ms (IQR {:.1}%), of which anti-aliasing {:.3} ms",
            format!("{}x{}", t.size.0, t.size.1),
            t.method,
            if t.gpu { "GPU" } else { "frame" },
            t.frame.median_ms,
            100.0 * t.frame.spread,
            t.aa_ms
        )?;
    }
    wrote(&opts.out, r.interrupted)?;
    if r.interrupted {
        return Err(interrupted(
            true,
            &opts.out,
            "aa.json",
            format!(
                "the {} frames, {} sequences, {} path views and {} timings measured so far",
                r.frames.len(),
                r.sequences.len(),
                r.paths.len(),
                r.timings.len()
            ),
        ));
    }
    Ok(())
}

/// Runs the benchmark asked for.
pub(crate) fn run(what: BenchCommand) -> Result<()> {
    match what {
        BenchCommand::Features {
            world,
            out,
            size,
            aa,
            timing,
            truth,
        } => bench_features(verdant::tools::BenchLodOptions {
            world: world_on_disk(&world)?,
            out,
            size,
            aa,
            warmup_frames: timing.warmup_frames,
            timed_frames: timing.timed_frames,
            rounds: timing.rounds,
            truth_k: truth.samples.truth,
            truth_reach: truth.truth_reach,
            ..Default::default()
        }),
        BenchCommand::Blades {
            out,
            size,
            field_m,
            camera,
            target,
            fov_deg,
            counts,
            timing,
            truth,
        } => bench_blades(verdant::tools::bench_blades::BenchBladesOptions {
            out,
            size,
            field_m,
            camera_m: camera,
            target_m: target,
            fov_deg,
            counts,
            warmup_frames: timing.warmup_frames,
            timed_frames: timing.timed_frames,
            rounds: timing.rounds,
            truth_k: truth.truth,
            stop: None,
        }),
        BenchCommand::Lod {
            world,
            out,
            size,
            dolly_frames,
            settings,
            supersample,
            path,
            flight,
            flight_frames,
            timing,
            truth,
        } => bench_lod(verdant::tools::BenchLodOptions {
            world: world_on_disk(&world)?,
            out,
            size,
            dolly_frames,
            warmup_frames: timing.warmup_frames,
            timed_frames: timing.timed_frames,
            rounds: timing.rounds,
            path,
            truth_k: truth.samples.truth,
            truth_reach: truth.truth_reach,
            settings,
            supersample,
            aa: None,
            flight,
            flight_frames,
            stop: None,
        }),
        BenchCommand::Aa {
            world,
            out,
            size,
            aa,
            frames,
            run_up,
            truth,
            truth_noise,
            path,
            paths,
            sequences,
            settings,
            taa,
            timing,
        } => {
            taa.check(aa.contains(&verdant::aa::AntiAliasing::Taa))?;
            bench_aa(verdant::tools::bench_aa::BenchAaOptions {
                world: world_on_disk(&world)?,
                out,
                sizes: size,
                methods: aa,
                frames,
                run_up,
                truth_k: truth.samples.truth,
                truth_reach: truth.truth_reach,
                truth_noise,
                path,
                paths: paths.into_iter().filter(|p| !p.is_empty()).collect(),
                motions: sequences,
                taa: taa_variants(&taa),
                settings,
                warmup_frames: timing.warmup_frames,
                timed_frames: timing.timed_frames,
                rounds: timing.rounds,
                stop: None,
            })
        }
    }
}

/// The first line of a benchmark's table: the adapter it ran on and the frame's size.
fn say_adapter(
    adapter: &verdant::tools::report::AdapterReport,
    (width, height): (u32, u32),
) -> Result<()> {
    say!("{} [{}], {width}x{height}", adapter.name, adapter.backend)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Lists {
        #[command(flatten)]
        taa: TaaLists,
    }

    #[test]
    fn every_combination_of_the_taa_lists_with_the_first_list_varying_slowest() {
        let lists = Lists::parse_from([
            "bench",
            "--taa-samples",
            "16,32",
            "--taa-reconstruct",
            "0,0.45,0.6",
        ])
        .taa;
        let v = taa_variants(&lists);
        let got: Vec<(u32, f32)> = v
            .iter()
            .map(|s| (s.max_samples, s.reconstruct_px))
            .collect();
        assert_eq!(
            got,
            [
                (16, 0.0),
                (16, 0.45),
                (16, 0.6),
                (32, 0.0),
                (32, 0.45),
                (32, 0.6)
            ]
        );
        // What no list names keeps the renderer's default.
        let base = verdant::aa::taa::TaaSettings::default();
        assert!(v.iter().all(|s| s.min_samples == base.min_samples
            && s.parallax_falloff == base.parallax_falloff
            && s.clip_sigma == base.clip_sigma));
        let none = taa_variants(&Lists::parse_from(["bench"]).taa);
        assert_eq!(none.len(), 1);
        assert_eq!(none[0].max_samples, base.max_samples);
        // The sway falloff, the last list: varies fastest, and is refused out of range.
        let sway = taa_variants(
            &Lists::parse_from([
                "bench",
                "--taa-blade-motion",
                "off,on",
                "--taa-sway-falloff",
                "0,4",
            ])
            .taa,
        );
        let got: Vec<(bool, f32)> = sway
            .iter()
            .map(|s| (s.blade_motion, s.sway_falloff))
            .collect();
        assert_eq!(got, [(false, 0.0), (false, 4.0), (true, 0.0), (true, 4.0)]);
        assert!(Lists::try_parse_from(["bench", "--taa-sway-falloff", "17"]).is_err());
    }
}
