//! How the benchmarks time frames: frames of one measurement run back to back with nothing
//! else in between (at most two ahead of the GPU, their figures taken as they come back), the
//! settings measured in interleaved rounds so that drift touches all alike, and each figure a
//! median with its interquartile range. Image metrics are computed from frames captured apart
//! from the timed ones.

use anyhow::{Result, bail};
use glam::DVec2;
use serde::Serialize;

use crate::camera::Camera;
use crate::gpu::GpuContext;
use crate::renderer::FrameStats;
use crate::tools::Scene;

/// A measurement whose interquartile range is above this share of its median is flagged.
pub const NOISY_SPREAD: f64 = 0.10;

/// A timing: median and quartiles of per-frame times, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Timing {
    /// Median, milliseconds.
    pub median_ms: f64,
    /// First quartile, milliseconds.
    pub q1_ms: f64,
    /// Third quartile, milliseconds.
    pub q3_ms: f64,
    /// Interquartile range over the median.
    pub spread: f64,
    /// Frames measured.
    pub frames: usize,
    /// Whether the spread is above [`NOISY_SPREAD`].
    pub noisy: bool,
}

impl Timing {
    /// The timing of `samples` (milliseconds; non-finite ones are ignored).
    pub fn of(samples: &[f64]) -> Self {
        let q = |p| crate::tools::metrics::percentile(samples, p).unwrap_or(0.0);
        let (q1, median, q3) = (q(0.25), q(0.5), q(0.75));
        let spread = if median > 0.0 {
            (q3 - q1) / median
        } else {
            0.0
        };
        Self {
            median_ms: median,
            q1_ms: q1,
            q3_ms: q3,
            spread,
            frames: samples.iter().filter(|x| x.is_finite()).count(),
            noisy: spread > NOISY_SPREAD,
        }
    }

    /// Whether any frame was timed: a run stopped before it timed a setting has none, and its
    /// figures are zero.
    pub fn measured(&self) -> bool {
        self.frames > 0
    }

    /// `value`, one of this timing's figures or one computed from them, as a CSV cell with
    /// `decimals` decimals; an empty cell when nothing was timed ([`Timing::measured`]).
    pub fn cell(&self, value: f64, decimals: usize) -> String {
        if self.measured() {
            format!("{value:.decimals$}")
        } else {
            String::new()
        }
    }

    /// One figure for several views of a setting: the mean of their medians and quartiles, the
    /// largest of their spreads.
    pub fn over_views(views: &[Timing]) -> Self {
        if views.is_empty() {
            return Self::default();
        }
        let n = views.len() as f64;
        let mean = |f: &dyn Fn(&Timing) -> f64| views.iter().map(f).sum::<f64>() / n;
        let spread = views.iter().map(|t| t.spread).fold(0.0, f64::max);
        Self {
            median_ms: mean(&|t| t.median_ms),
            q1_ms: mean(&|t| t.q1_ms),
            q3_ms: mean(&|t| t.q3_ms),
            spread,
            frames: views.iter().map(|t| t.frames).sum(),
            noisy: spread > NOISY_SPREAD,
        }
    }
}

/// Frame counts of a benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct FrameCounts {
    /// Untimed frames before each measurement's timed ones.
    pub warmup: u32,
    /// Timed frames of each measurement in a round.
    pub timed: u32,
    /// Rounds over all the settings.
    pub rounds: u32,
}

impl FrameCounts {
    /// Defaults that give stable figures on a GPU (5 rounds of 20 frames after 5 untimed
    /// ones, 100 timed frames a measurement), and fewer on a software renderer, where a frame
    /// takes a large part of a second.
    pub fn for_adapter(info: &wgpu::AdapterInfo) -> Self {
        if info.device_type == wgpu::DeviceType::Cpu {
            Self {
                warmup: 1,
                timed: 3,
                rounds: 2,
            }
        } else {
            Self {
                warmup: 5,
                timed: 20,
                rounds: 5,
            }
        }
    }

    /// These counts with any of `warmup`, `timed` and `rounds` that are given put in.
    pub fn with(self, warmup: Option<u32>, timed: Option<u32>, rounds: Option<u32>) -> Self {
        Self {
            warmup: warmup.unwrap_or(self.warmup),
            timed: timed.unwrap_or(self.timed).max(1),
            rounds: rounds.unwrap_or(self.rounds).max(1),
        }
    }
}

/// One frame's time for the benchmarks: its total GPU time over all passes when the adapter
/// has timestamps, else the wall time from the previous frame.
pub fn frame_ms(stats: &FrameStats, wall_ms: f64, timestamps: bool) -> f64 {
    if timestamps {
        stats.gpu.iter().map(|(_, ms)| ms).sum()
    } else {
        wall_ms
    }
}

/// Renders `warmup + timed` frames of `camera` at `time_s` back to back (at most
/// [`crate::tools::scene::FRAMES_IN_FLIGHT`] ahead of the GPU) and returns the timed frames' figures with their wall
/// time from the previous frame, milliseconds.
pub fn run_frames(
    ctx: &GpuContext,
    scene: &mut Scene,
    camera: &Camera,
    time_s: f64,
    walker: Option<DVec2>,
    warmup: u32,
    timed: u32,
) -> Result<Vec<(FrameStats, f64)>> {
    run_shots(ctx, scene, warmup, timed, |_| (*camera, time_s, walker))
}

/// Renders a flight, the cameras of `shots` one after the other, back to back as
/// [`run_frames`] renders one view, and returns every frame's figures with its wall time from
/// the previous frame, milliseconds.
pub fn run_flight(
    ctx: &GpuContext,
    scene: &mut Scene,
    shots: &[(Camera, f64, Option<DVec2>)],
) -> Result<Vec<(FrameStats, f64)>> {
    run_shots(ctx, scene, 0, shots.len() as u32, |i| shots[i as usize])
}

/// `warmup + timed` frames back to back, frame `i` drawn as `shot(i)` says (camera, time,
/// walker); the timed frames' figures.
fn run_shots(
    ctx: &GpuContext,
    scene: &mut Scene,
    warmup: u32,
    timed: u32,
    shot: impl Fn(u32) -> (Camera, f64, Option<DVec2>),
) -> Result<Vec<(FrameStats, f64)>> {
    let total = warmup + timed;
    let mut first_timed = None;
    let mut walls = Vec::with_capacity(total as usize);
    let mut out = Vec::with_capacity(timed as usize);
    let mut last = std::time::Instant::now();
    for i in 0..total {
        let (camera, time_s, walker) = shot(i);
        let (frame, _) = scene.submit_frame(ctx, &camera, time_s, walker)?;
        if i == warmup {
            first_timed = Some(frame);
        }
        let now = std::time::Instant::now();
        walls.push((frame, (now - last).as_secs_f64() * 1e3));
        last = now;
        collect(scene, first_timed, &walls, &mut out);
    }
    ctx.wait_idle();
    collect(scene, first_timed, &walls, &mut out);
    if out.len() != timed as usize {
        bail!(
            "{} of {timed} timed frames' figures came back from the GPU",
            out.len()
        );
    }
    Ok(out)
}

/// Wall time, milliseconds, that the benchmarks render untimed on a GPU before their first
/// timed measurement: a GPU that sat idle (while the truth was read back, or the images were
/// measured on the CPU) runs its first frames at low clocks, and a first measurement of a few
/// frames would read slow (bench aa's `off` once read 16.7 ms for 4.05).
pub const RAMP_MS: f64 = 1500.0;

/// Renders `camera` back to back, untimed, for [`RAMP_MS`] of wall time on a GPU so that its
/// clocks have risen before the first timed measurement; nothing on a software renderer, which
/// has no clocks to raise. Returns the frames rendered.
pub fn ramp_up(
    ctx: &GpuContext,
    scene: &mut Scene,
    camera: &Camera,
    time_s: f64,
    walker: Option<DVec2>,
) -> Result<u32> {
    if ctx.info.device_type == wgpu::DeviceType::Cpu {
        return Ok(0);
    }
    let start = std::time::Instant::now();
    let mut frames = 0;
    while start.elapsed().as_secs_f64() * 1e3 < RAMP_MS {
        frames += run_frames(ctx, scene, camera, time_s, walker, 0, 10)?.len() as u32;
    }
    Ok(frames)
}

fn collect(
    scene: &mut Scene,
    first_timed: Option<u64>,
    walls: &[(u64, f64)],
    out: &mut Vec<(FrameStats, f64)>,
) {
    for stats in scene.renderer().take_stats() {
        if first_timed.is_some_and(|f| stats.frame >= f) {
            let wall = walls
                .iter()
                .find(|(f, _)| *f == stats.frame)
                .map_or(0.0, |w| w.1);
            out.push((stats, wall));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_series_is_not_flagged_and_a_noisy_one_is() {
        let steady: Vec<f64> = (0..100).map(|i| 4.0 + 0.01 * f64::from(i % 7)).collect();
        let t = Timing::of(&steady);
        assert!((t.median_ms - 4.03).abs() < 0.02, "{t:?}");
        assert!(t.spread < 0.02 && !t.noisy, "{t:?}");
        assert_eq!(t.frames, 100);
        // Every other frame at half clock: the kind of series a GPU gives when it idles
        // between frames.
        let noisy: Vec<f64> = (0..100)
            .map(|i| if i % 2 == 0 { 4.0 } else { 6.5 })
            .collect();
        let n = Timing::of(&noisy);
        assert!(n.noisy && n.spread > NOISY_SPREAD, "{n:?}");
        // A noisy view makes the setting noisy, whatever the others.
        let both = Timing::over_views(&[t, n]);
        assert!(both.noisy);
        assert!((both.median_ms - (t.median_ms + n.median_ms) / 2.0).abs() < 1e-9);
        assert_eq!(both.frames, 200);
    }

    #[test]
    fn quartiles_of_a_known_series() {
        let t = Timing::of(&[1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!((t.q1_ms, t.median_ms, t.q3_ms), (2.0, 3.0, 4.0));
        assert!((t.spread - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(Timing::of(&[]).frames, 0);
    }
}
