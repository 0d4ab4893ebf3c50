//! What the benchmarks share: their options, the image measures, and the frames they capture.
//!
//! Every image error the benchmarks report is measured against the truth
//! ([`crate::tools::truth`]): the same camera at the same time, supersampled K x K in linear light
//! with the most accurate settings (no LOD, 16 blade segments everywhere, blades out to
//! [`crate::tools::truth::REACH_FACTOR`] (nine) times the default view distance, 600 m in the
//! default world). Two measures are reported side by side ([`Measures`]):
//! - **pixel FLIP** (`flip_vs_truth`): NVIDIA's FLIP pixel by pixel; it sees aliasing, blur and
//!   every blade out of place;
//! - **coarse FLIP** (`coarse_flip_vs_truth`): FLIP of both images box-filtered 8 x 8 in linear
//!   light ([`crate::tools::metrics::coarse_flip`]), where single blades are no longer resolved:
//!   a setting that draws another random field of the same grass (another spacing or width)
//!   scores low on it, a change of colour, cover or shading scores high.
//!
//! Where it still helps, the old figure against the renderer's own render without LOD at the
//! same resolution is kept as a column (`flip_vs_no_lod`).
//!
//! The benchmarks themselves: `bench lod` ([`crate::tools::bench_lod`]), `bench features`
//! ([`crate::tools::bench_features`]) and `bench blades` ([`crate::tools::bench_blades`]).

use std::path::PathBuf;

use anyhow::Result;
use serde::Serialize;

use crate::RendererConfig;
use crate::camera::Camera;
use crate::gpu::GpuContext;
use crate::tools::Scene;
use crate::tools::fly::{OptionError, check_range, check_size};
use crate::tools::metrics::{COARSE_FACTOR, COVERAGE_DISTANCE_M, coarse_flip, flip_compare};
use crate::tools::stop::Stop;
use crate::tools::truth::Truth;
use crate::world::World;

/// What `verdant bench lod` is asked to do.
#[derive(Clone, Debug)]
pub struct BenchLodOptions {
    /// The world's folder.
    pub world: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// Image size.
    pub size: (u32, u32),
    /// Frames of the dolly.
    pub dolly_frames: u32,
    /// Untimed frames before each measurement's timed ones (default: by adapter, see
    /// [`crate::tools::timing::FrameCounts::for_adapter`]).
    pub warmup_frames: Option<u32>,
    /// Timed frames of each measurement per round (default: by adapter).
    pub timed_frames: Option<u32>,
    /// Interleaved rounds over the settings (default: by adapter).
    pub rounds: Option<u32>,
    /// Camera path the views are taken from (default: "meadow", else the first path).
    pub path: Option<String>,
    /// Sub-samples a pixel side of the truth the images are measured against (`--truth`,
    /// 1..=8; see [`crate::tools::truth`]).
    pub truth_k: u32,
    /// How far the truth draws blades, in default view distances (`--truth-reach`,
    /// 1..=[`crate::tools::truth::REACH_FACTOR`]; less is quicker, and the far band is then
    /// measured out to this many view distances only).
    pub truth_reach: f64,
    /// Which of `bench lod`'s settings to measure, by name (`--settings`; empty: all of
    /// them). "default" and "no LOD", the references, are always measured.
    pub settings: Vec<String>,
    /// `bench lod --supersample K` (1..=8; 1, the default: off): the settings' images at the
    /// four views (and the far band's) are drawn K x K sub-samples a pixel in linear light, as
    /// the truth is, so that their error against the truth is what each setting draws
    /// differently (its content), not how one sample a pixel aliases it. The timings stay the
    /// setting's own frame.
    pub supersample: u32,
    /// `bench features --aa METHOD`: the anti-aliasing of every variant's frames (None: the
    /// renderer's default).
    pub aa: Option<crate::aa::AntiAliasing>,
    /// `bench lod --flight PATH`: the camera path each setting is also timed along, frame
    /// after frame (`None`: "tour" where the world has it, else the views' own path; `Some("")`:
    /// no flight). A setting's cost can lie where its four still views do not look: a forest
    /// passed on the way, a long view over the hills.
    pub flight: Option<String>,
    /// Frames of the flight, evenly spaced along the whole path (`--flight-frames`,
    /// 2..=[`MAX_FLIGHT_FRAMES`]).
    pub flight_frames: u32,
    /// A flag that ends the run early (Ctrl-C on the command line): at the next frame, setting
    /// or view, what was measured so far is written, the report marked interrupted (see
    /// [`crate::tools::stop`]).
    pub stop: Option<crate::bake::CancelFlag>,
}

/// The most frames of bench lod's flight (`--flight-frames`).
pub const MAX_FLIGHT_FRAMES: u32 = 2000;
/// bench lod's flight's frames by default.
pub const DEFAULT_FLIGHT_FRAMES: u32 = 120;

impl Default for BenchLodOptions {
    fn default() -> Self {
        Self {
            world: PathBuf::from("worlds/santa-cruz"),
            out: PathBuf::from("out/bench-lod"),
            size: (480, 270),
            dolly_frames: 48,
            warmup_frames: None,
            timed_frames: None,
            rounds: None,
            path: None,
            truth_k: crate::tools::truth::DEFAULT_K,
            truth_reach: crate::tools::truth::REACH_FACTOR,
            settings: Vec::new(),
            supersample: 1,
            aa: None,
            flight: None,
            flight_frames: DEFAULT_FLIGHT_FRAMES,
            stop: None,
        }
    }
}

/// The most untimed frames before each measurement (`--warmup-frames`).
pub const MAX_WARMUP_FRAMES: u32 = 100;
/// The most timed frames of each measurement per round (`--timed-frames`); with the warm-up,
/// within the 256 frames that `bench blades` times its floor pass over at once.
pub const MAX_TIMED_FRAMES: u32 = 150;
/// The most interleaved rounds (`--rounds`).
pub const MAX_ROUNDS: u32 = 100;
/// The most frames of the dolly (`--dolly-frames`).
pub const MAX_DOLLY_FRAMES: u32 = 1000;

/// The first item of `items` that comes again later in it: a list option naming one size,
/// method or setting twice would measure it twice and report it as two.
pub fn repeated<T: PartialEq>(items: &[T]) -> Option<&T> {
    items
        .iter()
        .enumerate()
        .find(|(i, a)| items[i + 1..].contains(a))
        .map(|(_, a)| a)
}

/// Checks the timing options of a benchmark: `--warmup-frames` 0..=100, `--timed-frames`
/// 1..=150, `--rounds` 1..=100 (those not given take the adapter's defaults, which lie within).
pub fn check_timing(
    warmup_frames: Option<u32>,
    timed_frames: Option<u32>,
    rounds: Option<u32>,
) -> Result<(), OptionError> {
    if let Some(n) = warmup_frames {
        check_range("--warmup-frames", n, 0..=MAX_WARMUP_FRAMES, "")?;
    }
    if let Some(n) = timed_frames {
        check_range("--timed-frames", n, 1..=MAX_TIMED_FRAMES, "")?;
    }
    if let Some(n) = rounds {
        check_range("--rounds", n, 1..=MAX_ROUNDS, "")?;
    }
    Ok(())
}

impl BenchLodOptions {
    /// Checks the options of `bench lod`: `--size` 1..=16384 pixels a side, `--dolly-frames`
    /// 2..=1000, `--flight-frames` 2..=2000, `--supersample` and `--truth` 1..=8, and the
    /// timing options (see [`check_timing`]).
    pub fn validate(&self) -> Result<(), OptionError> {
        self.validate_features()?;
        check_range("--supersample", self.supersample, 1..=8, "")?;
        check_range(
            "--flight-frames",
            self.flight_frames,
            2..=MAX_FLIGHT_FRAMES,
            "",
        )?;
        check_range(
            "--dolly-frames",
            self.dolly_frames,
            2..=MAX_DOLLY_FRAMES,
            "",
        )
    }

    /// Checks the options `bench features` uses: `--size`, `--truth` 1..=8 and the timing
    /// options (see [`check_timing`]).
    pub fn validate_features(&self) -> Result<(), OptionError> {
        check_size("--size", self.size)?;
        crate::tools::truth::check_k("--truth", self.truth_k)?;
        crate::tools::truth::check_reach("--truth-reach", self.truth_reach)?;
        check_timing(self.warmup_frames, self.timed_frames, self.rounds)
    }
}

pub(crate) use crate::tools::metrics::rgb;

/// Mean pixel FLIP of `b` against `a`.
pub(crate) fn flip(a: &image::RgbaImage, b: &image::RgbaImage) -> Result<f64> {
    Ok(f64::from(flip_compare(&rgb(a), &rgb(b))?.mean))
}

/// An image's error against its reference by both measures of the benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Measures {
    /// Mean pixel FLIP.
    pub flip: f64,
    /// The coarse FLIP ([`crate::tools::metrics::coarse_flip`] with blocks of
    /// [`COARSE_FACTOR`] pixels).
    pub coarse: f64,
}

impl Measures {
    /// `actual` against `reference`.
    pub fn of(reference: &image::RgbaImage, actual: &image::RgbaImage) -> Result<Self> {
        let (r, a) = (rgb(reference), rgb(actual));
        Ok(Self {
            flip: f64::from(flip_compare(&r, &a)?.mean),
            coarse: coarse_flip(&r, &a, COARSE_FACTOR)?,
        })
    }

    /// The mean of each measure over `all` (zero when empty).
    pub fn mean(all: &[Self]) -> Self {
        let n = all.len().max(1) as f64;
        Self {
            flip: all.iter().map(|m| m.flip).sum::<f64>() / n,
            coarse: all.iter().map(|m| m.coarse).sum::<f64>() / n,
        }
    }
}

/// A world's images at one size, drawn by scenes of the benchmark's settings.
pub(crate) struct Bench<'a> {
    pub(crate) ctx: &'a GpuContext,
    pub(crate) world: &'a World,
    pub(crate) size: (u32, u32),
    /// Ends the warm-ups of its frames and truths early (see [`crate::tools::stop`]).
    pub(crate) stop: &'a Stop,
}

impl Bench<'_> {
    /// A scene of `config` at the benchmark's size.
    pub(crate) fn scene(&self, config: RendererConfig) -> Result<Scene> {
        Ok(Scene::new(
            self.ctx,
            self.world.clone(),
            self.size.0,
            self.size.1,
            config,
        )?)
    }

    /// Renders `camera` after bringing its tiles in; returns the image and the stats
    /// ([`crate::tools::stop::Stopped`] if the run was stopped meanwhile).
    pub(crate) fn frame(
        &self,
        scene: &mut Scene,
        camera: &Camera,
    ) -> Result<(image::RgbaImage, crate::renderer::FrameStats)> {
        warm_up(scene, camera, self.stop)?;
        let stats = scene.render(self.ctx, camera)?;
        Ok((scene.read_image(self.ctx)?, stats))
    }

    /// `config`'s frames at the benchmark's size supersampled `k` x `k` in linear light (the
    /// truth's machinery with the setting's own grass).
    pub(crate) fn supersampled(&self, config: RendererConfig, k: u32) -> Result<Truth> {
        Ok(Truth::with_config(
            self.ctx,
            self.world.clone(),
            std::sync::Arc::new(self.world.clone()),
            self.size,
            k,
            config,
        )?
        .with_stop(self.stop.clone()))
    }

    /// The truth at the benchmark's size, K = `k`, on top of `base` (its features and wind; see
    /// [`crate::tools::truth::truth_config`]).
    pub(crate) fn truth(&self, base: &RendererConfig, k: u32, reach: f64) -> Result<Truth> {
        let slots = crate::tools::truth::atlas_slots(self.world, &self.ctx.device);
        let config = crate::tools::truth::truth_config_reaching(self.world, base, slots, reach);
        self.supersampled(config, k)
    }

    /// Like [`Bench::frame`], with the frame's grass coverage (the capture of the terrain-only
    /// depth is on for this frame only).
    pub(crate) fn frame_with_coverage(
        &self,
        scene: &mut Scene,
        camera: &Camera,
    ) -> Result<(image::RgbaImage, crate::renderer::FrameStats, f64)> {
        scene.set_coverage_capture(true)?;
        let (img, stats) = self.frame(scene, camera)?;
        let coverage = scene.coverage(self.ctx, COVERAGE_DISTANCE_M)?.fraction;
        scene.set_coverage_capture(false)?;
        Ok((img, stats, coverage))
    }
}

/// Brings in the tiles `camera` wants, waiting up to [`crate::tools::fly::FIRST_FRAME_WAIT`]
/// or until `stop` is asked for ([`crate::tools::stop::Stopped`]); fails if streaming delivered
/// nothing (see [`crate::tools::fly::check_streaming`]). Tiles still missing otherwise are drawn
/// from their ancestors, as in any frame.
pub(crate) fn warm_up(scene: &mut Scene, camera: &Camera, stop: &Stop) -> Result<()> {
    let report = stop.warm_up(scene, camera, crate::tools::fly::FIRST_FRAME_WAIT)?;
    crate::tools::fly::check_streaming(
        &scene.world().dir,
        &scene.world().manifest.pyramid,
        &scene.service().stats(),
        &report,
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bench_options_out_of_range_name_the_option_and_its_range() {
        let d = BenchLodOptions::default;
        d().validate().unwrap();
        let cases = [
            (
                BenchLodOptions {
                    dolly_frames: 0,
                    ..d()
                },
                "--dolly-frames 0",
                "2..=1000",
            ),
            (
                BenchLodOptions {
                    dolly_frames: u32::MAX,
                    ..d()
                },
                "--dolly-frames 4294967295",
                "2..=1000",
            ),
            (
                BenchLodOptions {
                    size: (0, 0),
                    ..d()
                },
                "--size 0x0",
                "1..=16384",
            ),
            (
                BenchLodOptions {
                    flight_frames: 1,
                    ..d()
                },
                "--flight-frames 1",
                "2..=2000",
            ),
            (
                BenchLodOptions {
                    warmup_frames: Some(101),
                    ..d()
                },
                "--warmup-frames 101",
                "0..=100",
            ),
            (
                BenchLodOptions {
                    timed_frames: Some(0),
                    ..d()
                },
                "--timed-frames 0",
                "1..=150",
            ),
            (
                BenchLodOptions {
                    rounds: Some(0),
                    ..d()
                },
                "--rounds 0",
                "1..=100",
            ),
            (BenchLodOptions { truth_k: 0, ..d() }, "--truth 0", "1..=8"),
            (BenchLodOptions { truth_k: 9, ..d() }, "--truth 9", "1..=8"),
            (
                BenchLodOptions {
                    supersample: 0,
                    ..d()
                },
                "--supersample 0",
                "1..=8",
            ),
        ];
        for (opts, option, range) in cases {
            let e = opts.validate().unwrap_err().to_string();
            assert!(e.contains(option) && e.contains(range), "{e}");
        }
        // `bench features` has no dolly.
        BenchLodOptions {
            dolly_frames: 0,
            ..d()
        }
        .validate_features()
        .unwrap();
        check_timing(
            Some(MAX_WARMUP_FRAMES),
            Some(MAX_TIMED_FRAMES),
            Some(MAX_ROUNDS),
        )
        .unwrap();
    }
}
