//! `verdant bench aa`: anti-aliasing against the truth, in motion.
//!
//! Each method ([`AntiAliasing`]) renders sequences of consecutive 60 Hz frames from the
//! camera path's first view (default: "meadow"): **still** (the camera holds, the wind blows),
//! a **dolly** forward at [`DOLLY_MPS`], a **pan** at [`PAN_DEG_PER_S`], and a **teleport**
//! (half the frames at one view, then a jump of [`TELEPORT_M`] along the view). Every sequence
//! starts with untimed run-up frames along the same motion (a temporal method has a history
//! when measuring starts; the truth steps through them too, so both see the same wind and sway).
//! The same frames are rendered as the truth ([`crate::tools::truth`]: k x k sub-samples in
//! linear light, the most accurate grass). Per frame: FLIP against the truth (aliasing, blur
//! and ghosting all raise it). Per sequence: flicker, the mean absolute change between
//! consecutive frames (0..255), over the truth's; after the teleport, the frames until FLIP is
//! back within 10% of its steady value (the mean of the sequence's last quarter).
//!
//! The **paths** part measures what a user flies: at four times spread along each named path
//! (default: meadow, tour, wind-tour), FLIP against the truth after the run-up's frames of
//! flight along the path, every renderer started afresh for it (a frame carries state into the
//! next, and the sequences would leave theirs in the truth and the methods only), and beside
//! the methods two bounds ([`Bound`]) that say where their error comes from: the default frame
//! supersampled like the truth (what the frame draws differently from the truth, which no
//! anti-aliasing removes) and the truth's grass at 2 x 2 sub-samples (what four samples a pixel
//! leave of the aliasing); with `--truth-noise` a third, the truth at twice its sub-samples a
//! side (the truth's own sampling error). Speed: GPU time per frame of each method (timestamp
//! queries; the wall time without them), timed in interleaved rounds at the still view (see
//! [`crate::tools::timing`]). Outputs: `aa_frames.csv` (every frame), `aa_sequences.csv`,
//! `aa_paths.csv`, `aa.json`, per size a chart of error against GPU time with the Pareto
//! front (`aa_WxH.png`), and the last frame of each sequence, each method's and the truth's,
//! to look at (`WxH_SEQUENCE_METHOD.png`, `WxH_SEQUENCE_truth.png`). With bench lod's settings
//! named (`--settings`), each method is measured with each of them too, as a method of its own
//! (`METHOD+SETTING`, [`setting_label`]). The tables are written after each sequence and path
//! as well as at the end ([`write_tables`]): a run that fails part-way keeps what it measured.
//! A run stopped early ([`BenchAaOptions::stop`], Ctrl-C) writes every output with what it
//! measured, `aa.json` marked `interrupted`.

use std::path::PathBuf;

use anyhow::{Result, bail};
use glam::{DVec2, DVec3};
use image::RgbaImage;
use serde::Serialize;

use crate::RendererConfig;
use crate::aa::AntiAliasing;
use crate::aa::taa::TaaSettings;
use crate::camera::{Camera, sample_path};
use crate::gpu::GpuContext;
use crate::tools::Scene;
use crate::tools::fly::{OutDir, Outputs, write_json, write_png, write_text};
use crate::tools::metrics::{COARSE_FACTOR, coarse_flip, flip_compare, rgb};
use crate::tools::metrics::{Chart, ChartPoint};
use crate::tools::report::AdapterReport;
use crate::tools::stop::{Stop, caught, chart_title};
use crate::tools::timing::{FrameCounts, Timing, frame_ms, ramp_up, run_frames};
use crate::tools::truth::Truth;
use crate::world::{CameraPath, World};

/// Frame time of the sequences: consecutive frames at 60 Hz.
pub const DT_S: f64 = 1.0 / 60.0;
/// Speed of the dolly, metres a second (a brisk run).
pub const DOLLY_MPS: f64 = 7.4;
/// Turn rate of the pan, degrees a second.
pub const PAN_DEG_PER_S: f64 = 30.0;
/// How far the teleport jumps along the view, metres (past any method's cut threshold).
pub const TELEPORT_M: f64 = 60.0;
/// The most frames of a sequence (`--frames`).
pub const MAX_FRAMES: u32 = 600;
/// The most run-up frames (`--run-up`).
pub const MAX_RUN_UP: u32 = 120;

/// Options of `bench aa`.
#[derive(Clone, Debug)]
pub struct BenchAaOptions {
    /// The world's folder.
    pub world: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// Image sizes, each measured in full.
    pub sizes: Vec<(u32, u32)>,
    /// The methods compared.
    pub methods: Vec<AntiAliasing>,
    /// Measured frames of each sequence.
    pub frames: u32,
    /// Untimed frames before each sequence's measured ones.
    pub run_up: u32,
    /// Sub-samples per side of the truth.
    pub truth_k: u32,
    /// How far the truth draws blades, in default view distances (1..=[`crate::tools::truth::REACH_FACTOR`]).
    pub truth_reach: f64,
    /// Whether the paths part also measures the truth's own sampling error
    /// ([`Bound::TruthFiner`]: the truth at twice its sub-samples a side, four times its
    /// renders), with 2..=[`crate::tools::truth::MAX_K`] / 2 sub-samples a side of the truth.
    pub truth_noise: bool,
    /// The path whose first view the sequences start from.
    pub path: String,
    /// The paths of the paths part (none: skip it).
    pub paths: Vec<String>,
    /// The sequences measured, in report order.
    pub motions: Vec<Motion>,
    /// The temporal method's settings: each is measured as a method of its own (named
    /// `taa` when there is one, else by its samples, clip and falloff, `taa-n32-c2.5-f0.25`,
    /// `-mv` added with the blades' motion vectors).
    pub taa: Vec<TaaSettings>,
    /// bench lod's settings ([`crate::tools::bench_lod::lod_settings`]), by name: each method
    /// is measured with each of them too, as a method of its own named `METHOD+SETTING`
    /// ([`setting_label`]); the renderer's default settings are always measured.
    /// [`TRUTH_CONTENT`] among them is the truth's content at one sample a pixel.
    pub settings: Vec<String>,
    /// Untimed frames before each timing measurement (default: by adapter).
    pub warmup_frames: Option<u32>,
    /// Timed frames per measurement and round (default: by adapter).
    pub timed_frames: Option<u32>,
    /// Interleaved rounds (default: by adapter).
    pub rounds: Option<u32>,
    /// A flag that ends the run early (Ctrl-C on the command line): at the next frame, view or
    /// timing, what was measured so far is written, the report marked interrupted (see
    /// [`crate::tools::stop`]).
    pub stop: Option<crate::bake::CancelFlag>,
}

impl Default for BenchAaOptions {
    fn default() -> Self {
        Self {
            world: PathBuf::from("worlds/santa-cruz"),
            out: PathBuf::from("out/bench-aa"),
            sizes: vec![(960, 540)],
            methods: AntiAliasing::ALL.to_vec(),
            frames: 24,
            run_up: 16,
            truth_k: 4,
            truth_reach: crate::tools::truth::REACH_FACTOR,
            truth_noise: false,
            path: "meadow".into(),
            paths: vec!["meadow".into(), "tour".into(), "wind-tour".into()],
            motions: Motion::ALL.to_vec(),
            taa: vec![TaaSettings::default()],
            settings: Vec::new(),
            warmup_frames: None,
            timed_frames: None,
            rounds: None,
            stop: None,
        }
    }
}

impl BenchAaOptions {
    /// Checks the ranges: frames 2..=600, run-up 0..=120, at least one method and size, the
    /// timing options as every benchmark's.
    pub fn validate(&self) -> Result<()> {
        if !(2..=MAX_FRAMES).contains(&self.frames) {
            bail!("--frames {} must be in 2..={MAX_FRAMES}", self.frames);
        }
        if self.run_up > MAX_RUN_UP {
            bail!("--run-up {} must be in 0..={MAX_RUN_UP}", self.run_up);
        }
        if self.methods.is_empty() {
            bail!("--aa names no method");
        }
        if self.motions.is_empty() {
            bail!("--sequences names no sequence");
        }
        if self.taa.is_empty() {
            bail!("no temporal settings given");
        }
        if self.sizes.is_empty() {
            bail!("--size names no size");
        }
        use crate::tools::bench::repeated;
        if let Some((w, h)) = repeated(&self.sizes) {
            bail!("--size lists {w}x{h} twice");
        }
        if let Some(m) = repeated(&self.methods) {
            bail!("--aa lists {} twice", m.name());
        }
        if let Some(m) = repeated(&self.motions) {
            bail!("--sequences lists {} twice", m.name());
        }
        if let Some(p) = repeated(&self.paths) {
            bail!("--paths lists {p:?} twice");
        }
        if let Some(s) = repeated(&self.settings) {
            bail!("--settings lists {s:?} twice");
        }
        for t in &self.taa {
            t.validate()
                .map_err(crate::tools::fly::SettingError::from)?;
        }
        if repeated(&self.taa).is_some() {
            bail!("the --taa-* lists give one temporal setting twice: a value is listed twice");
        }
        crate::tools::truth::check_k("--truth", self.truth_k)?;
        crate::tools::truth::check_reach("--truth-reach", self.truth_reach)?;
        if self.truth_noise && self.truth_k < 2 {
            bail!(
                "--truth-noise draws the truth at twice its sub-samples a side: at --truth 1 that \
                 is the bound truth-2x2 already"
            );
        }
        if self.truth_noise && 2 * self.truth_k > crate::tools::truth::MAX_K {
            bail!(
                "--truth-noise draws the truth at twice its sub-samples a side: --truth {} would \
                 need {}, more than {}",
                self.truth_k,
                2 * self.truth_k,
                crate::tools::truth::MAX_K
            );
        }
        if self.truth_noise && self.paths.is_empty() {
            bail!("--truth-noise is measured on the paths' views, and --paths names none");
        }
        crate::tools::bench::check_timing(self.warmup_frames, self.timed_frames, self.rounds)?;
        Ok(())
    }

    /// The renderers measured: each method, the temporal one once per settings, with the name
    /// it is reported under.
    pub fn variants(&self) -> Vec<(String, AntiAliasing, TaaSettings)> {
        let mut out = Vec::new();
        for &m in &self.methods {
            if m == AntiAliasing::Taa && self.taa.len() > 1 {
                for t in &self.taa {
                    let name = format!(
                        "{}-n{}-c{}-f{}{}{}{}{}{}{}",
                        m.name(),
                        t.max_samples,
                        t.clip_sigma,
                        t.motion_falloff,
                        if t.blade_motion { "-mv" } else { "" },
                        if t.pixel_spread > 0.0 {
                            format!("-s{}", t.pixel_spread)
                        } else {
                            String::new()
                        },
                        if t.parallax_falloff > 0.0 {
                            format!("-p{}", t.parallax_falloff)
                        } else {
                            String::new()
                        },
                        if t.min_samples == 2.0 {
                            String::new()
                        } else {
                            format!("-l{}", t.min_samples)
                        },
                        if t.reconstruct_px > 0.0 {
                            format!("-r{}", t.reconstruct_px)
                        } else {
                            String::new()
                        },
                        if t.sway_falloff > 0.0 {
                            format!("-w{}", t.sway_falloff)
                        } else {
                            String::new()
                        }
                    );
                    out.push((name, m, *t));
                }
            } else {
                out.push((m.name().to_string(), m, self.taa[0]));
            }
        }
        out
    }
}

/// A bench lod setting's name as it is written after a method's (`taa+segments-7-3-3-view-x1.5`):
/// every character but letters, digits and dots a dash, so that it fits file names and CSV
/// cells.
pub fn setting_label(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

/// The motions of the sequences.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Motion {
    /// The camera holds, the wind blows.
    Still,
    /// Forward along the view, level, at [`DOLLY_MPS`].
    Dolly,
    /// Turning left at [`PAN_DEG_PER_S`].
    Pan,
    /// Still, then a jump of [`TELEPORT_M`] along the view half-way.
    Teleport,
}

impl Motion {
    /// Every motion, in report order.
    pub const ALL: [Motion; 4] = [Motion::Still, Motion::Dolly, Motion::Pan, Motion::Teleport];

    /// The motion named `name` (as in reports).
    pub fn from_name(name: &str) -> Option<Motion> {
        Motion::ALL.into_iter().find(|m| m.name() == name.trim())
    }

    /// The name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Motion::Still => "still",
            Motion::Dolly => "dolly",
            Motion::Pan => "pan",
            Motion::Teleport => "teleport",
        }
    }

    /// The camera and time of frame `i` (negative: run-up) of a sequence of `frames` measured
    /// frames from `start` at `t0`.
    pub fn frame(self, start: &Camera, t0: f64, i: i64, frames: u32) -> (Camera, f64) {
        let t = i as f64 * DT_S;
        let mut c = *start;
        let fwd = start.forward();
        let level = DVec3::new(fwd.x, fwd.y, 0.0).normalize_or_zero();
        match self {
            Motion::Still => {}
            Motion::Dolly => c.position += level * DOLLY_MPS * t,
            Motion::Pan => c.yaw_deg += PAN_DEG_PER_S * t,
            Motion::Teleport => {
                if i >= i64::from(frames / 2) {
                    c.position += level * TELEPORT_M;
                }
            }
        }
        (c, t0 + t)
    }
}

/// One measured frame.
#[derive(Clone, Debug, Serialize)]
pub struct AaFrame {
    /// Image size.
    pub size: (u32, u32),
    /// The method.
    pub method: String,
    /// The sequence.
    pub motion: Motion,
    /// Frame of the sequence (0: the first measured).
    pub frame: u32,
    /// Mean FLIP against the truth.
    pub flip: f64,
    /// The coarse FLIP against the truth (at the scale where single blades are no longer
    /// resolved: [`crate::tools::metrics::coarse_flip`]).
    pub coarse_flip: f64,
    /// Mean absolute change from the previous frame, 0..255 (0 on the first).
    pub change: f64,
    /// The truth's change from its previous frame.
    pub truth_change: f64,
}

/// One sequence of one method.
#[derive(Clone, Debug, Serialize)]
pub struct AaSequence {
    /// Image size.
    pub size: (u32, u32),
    /// The method.
    pub method: String,
    /// The sequence.
    pub motion: Motion,
    /// Mean FLIP against the truth over its frames.
    pub flip_mean: f64,
    /// Mean coarse FLIP against the truth over its frames.
    pub coarse_flip_mean: f64,
    /// Mean change between consecutive frames (0..255); `None` where no frame was measured
    /// (a teleport sequence of two frames: the jump's frame is left out).
    pub flicker: Option<f64>,
    /// The truth's.
    pub truth_flicker: Option<f64>,
    /// `flicker / truth_flicker`.
    pub flicker_ratio: Option<f64>,
    /// Teleport only: frames after the jump until FLIP stays within 10% of its steady value
    /// (the mean over the last quarter); 0 when the first frame after the jump already is.
    pub recovery_frames: Option<u32>,
}

/// One view of the paths part.
#[derive(Clone, Debug, Serialize)]
pub struct AaPathView {
    /// Image size.
    pub size: (u32, u32),
    /// The method, or the bound (see [`Bound`]).
    pub method: String,
    /// Whether `method` names a bound rather than a method.
    pub bound: bool,
    /// The path.
    pub path: String,
    /// Time along it, seconds.
    pub t_s: f64,
    /// FLIP against the truth.
    pub flip: f64,
    /// The coarse FLIP against the truth.
    pub coarse_flip: f64,
}

/// What the paths part measures beside the methods, to say where their error comes from: two
/// renders of the same views that no real-time method is (three with `--truth-noise`), each
/// drawn as the truth is (sub-samples averaged in linear light, stepped through the same
/// frames).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bound {
    /// The default frame's settings (LOD, segments, view distance, far field, plants' levels)
    /// supersampled K x K like the truth: a perfect anti-aliasing of what the default frame
    /// draws. Its error is what the frame draws differently from the truth; no anti-aliasing
    /// method of that frame gets below it.
    DefaultSupersampled,
    /// The truth's settings with 2 x 2 sub-samples: the exact grass at four full samples a
    /// pixel. Its error is what four samples a pixel leave of the aliasing.
    Truth2x2,
    /// The truth itself at twice its sub-samples a side (8 x 8 for the 4 x 4 truth), placed
    /// elsewhere in the pixel than the truth's: its error against the truth is the truth's own
    /// sampling error, about what an exact frame would err against the truth (a little more:
    /// its own sampling error, a quarter of the truth's variance, is in it). No frame gets
    /// much below it. Measured with `--truth-noise` only: it is four times the truth's renders.
    TruthFiner,
}

impl Bound {
    /// The two measured unless asked for more, in report order.
    pub const ALL: [Bound; 2] = [Bound::DefaultSupersampled, Bound::Truth2x2];

    /// The bounds measured, in report order: [`Self::ALL`], and with `truth_noise`
    /// [`Bound::TruthFiner`] after them.
    pub fn measured(truth_noise: bool) -> Vec<Bound> {
        let mut v = Self::ALL.to_vec();
        if truth_noise {
            v.push(Bound::TruthFiner);
        }
        v
    }

    /// The name in reports (`k`: the truth's sub-samples a side).
    pub fn name(self, k: u32) -> String {
        match self {
            Bound::DefaultSupersampled => format!("default-{k}x{k}"),
            Bound::Truth2x2 => "truth-2x2".into(),
            Bound::TruthFiner => format!("truth-{0}x{0}", 2 * k),
        }
    }

    /// The bound's settings and sub-samples a side, the truth's being `k` x `k` with blades
    /// out to `reach` view distances and `atlas_slots` slots.
    pub fn config(
        self,
        world: &World,
        k: u32,
        reach: f64,
        atlas_slots: u32,
    ) -> (RendererConfig, u32) {
        let base = RendererConfig::for_world(world);
        match self {
            Bound::DefaultSupersampled => (
                RendererConfig {
                    aa: AntiAliasing::Off,
                    ..base
                },
                k,
            ),
            Bound::Truth2x2 | Bound::TruthFiner => (
                crate::tools::truth::truth_config_reaching(world, &base, atlas_slots, reach),
                if self == Bound::Truth2x2 { 2 } else { 2 * k },
            ),
        }
    }

    fn renderer(
        self,
        ctx: &GpuContext,
        world: &World,
        size: (u32, u32),
        k: u32,
        reach: f64,
    ) -> Result<Truth> {
        let slots = crate::tools::truth::atlas_slots(world, &ctx.device);
        let (config, k) = self.config(world, k, reach, slots);
        supersampled(ctx, world, size, k, config)
    }
}

/// A method's speed at one size.
#[derive(Clone, Debug, Serialize)]
pub struct AaTiming {
    /// Image size.
    pub size: (u32, u32),
    /// The method.
    pub method: String,
    /// GPU time per frame over all passes (the wall time without timestamp queries).
    pub frame: Timing,
    /// GPU time of the anti-aliasing's own passes (0 for none; without timestamps, 0).
    pub aa_ms: f64,
    /// Whether the figures are GPU times.
    pub gpu: bool,
}

/// The timing of the methods at one size under way: each method's name, frame times and
/// anti-aliasing times (milliseconds) over the rounds run.
struct TimingSamples {
    size: (u32, u32),
    methods: Vec<(String, Vec<f64>, Vec<f64>)>,
}

impl TimingSamples {
    /// The timings of the methods timed in a round at least (every method, unless the run was
    /// stopped in the first round); `gpu`: the figures are GPU times.
    fn timings(self, gpu: bool) -> impl Iterator<Item = AaTiming> {
        let size = self.size;
        self.methods
            .into_iter()
            .filter(|(_, frame, _)| !frame.is_empty())
            .map(move |(method, frame, aa)| AaTiming {
                size,
                method,
                frame: Timing::of(&frame),
                aa_ms: if gpu { Timing::of(&aa).median_ms } else { 0.0 },
                gpu,
            })
    }
}

/// Everything `bench aa` measured.
#[derive(Clone, Debug, Serialize)]
pub struct BenchAaReport {
    /// The adapter.
    pub adapter: AdapterReport,
    /// Sub-samples per side of the truth.
    pub truth_k: u32,
    /// How far the truth draws blades, in default view distances (1..=[`crate::tools::truth::REACH_FACTOR`]).
    pub truth_reach: f64,
    /// Every measured frame.
    pub frames: Vec<AaFrame>,
    /// Every sequence.
    pub sequences: Vec<AaSequence>,
    /// The paths part.
    pub paths: Vec<AaPathView>,
    /// Speed.
    pub timings: Vec<AaTiming>,
    /// The bench lod settings measured besides the default (`--settings`).
    pub settings: Vec<crate::tools::bench_lod::LodSetting>,
    /// Whether the truth's content was measured as a setting too ([`TRUTH_CONTENT`]).
    pub truth_content: bool,
    /// Timing frame counts.
    pub counts: FrameCounts,
    /// Whether the run was stopped before its end (Ctrl-C; [`BenchAaOptions::stop`]): the
    /// report holds what was measured until then (the frames of a sequence cut short are in
    /// `frames`, not in `sequences`; a method timed in no round has no timing).
    pub interrupted: bool,
    /// Images of bench aa's in the output folder that this run did not write (an earlier
    /// run's, of other sizes, sequences or methods, or that a stopped run did not reach), by
    /// name, in order.
    pub stale_images: Vec<String>,
}

impl BenchAaReport {
    /// Whether any frame or path view of `size` was measured (a chart of it is drawn).
    pub fn measured(&self, size: (u32, u32)) -> bool {
        self.frames.iter().any(|f| f.size == size) || self.paths.iter().any(|p| p.size == size)
    }
}

/// Whether `name` is one of the images bench aa writes: a chart (`aa_960x540.png`) or a
/// sequence's last frame (`960x540_dolly_taa.png`).
fn is_bench_aa_image(name: &str) -> bool {
    let size = |s: &str| {
        s.split_once('x').is_some_and(|(w, h)| {
            [w, h]
                .iter()
                .all(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        })
    };
    let Some(stem) = name.strip_suffix(".png") else {
        return false;
    };
    if let Some(chart) = stem.strip_prefix("aa_") {
        return size(chart);
    }
    stem.split_once('_').is_some_and(|(wh, rest)| {
        size(wh)
            && rest.split_once('_').is_some_and(|(motion, what)| {
                Motion::from_name(motion).is_some() && !what.is_empty()
            })
    })
}

/// The images of bench aa's in `out` other than those named in `written` (this run's): an
/// earlier run's, by name.
pub fn stale_images(out: &std::path::Path, written: &[String]) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(out) else {
        return Vec::new();
    };
    let mut stale: Vec<String> = entries
        .filter_map(|e| {
            let name = e.ok()?.file_name().into_string().ok()?;
            (is_bench_aa_image(&name) && !written.contains(&name)).then_some(name)
        })
        .collect();
    stale.sort();
    stale
}

/// Pixel FLIP and coarse FLIP of `actual` against `reference`.
fn flips(reference: &RgbaImage, actual: &RgbaImage) -> Result<(f64, f64)> {
    let (reference, actual) = (rgb(reference), rgb(actual));
    Ok((
        f64::from(flip_compare(&reference, &actual)?.mean),
        coarse_flip(&reference, &actual, COARSE_FACTOR)?,
    ))
}

/// Mean absolute difference of the RGB channels, 0..255.
pub fn mean_change(a: &RgbaImage, b: &RgbaImage) -> f64 {
    let total: u64 = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| (0..3).map(|c| u64::from(p[c].abs_diff(q[c]))).sum::<u64>())
        .sum();
    total as f64 / (3 * u64::from(a.width()) * u64::from(a.height())).max(1) as f64
}

/// Frames after the jump (at `jump`) until the error stays within 10% of the steady value
/// (the mean of the last quarter of `flips`).
pub fn recovery_frames(flips: &[f64], jump: usize) -> Option<u32> {
    if jump >= flips.len() {
        return None;
    }
    let tail = (flips.len() - jump).div_ceil(4).max(1);
    let steady = flips[flips.len() - tail..].iter().sum::<f64>() / tail as f64;
    let bound = steady * 1.1;
    let last_bad = flips[jump..].iter().rposition(|&f| f > bound);
    Some(last_bad.map_or(0, |i| i as u32 + 1))
}

/// The name of the setting (`--settings`) that draws the truth's content at one sample a
/// pixel: every setting of the truth's at its reach (blades at full density and the most
/// segments out to it, every plant's and tree's mesh, no far field under the blades), so that
/// the methods are measured on the scene the truth draws, and its GPU time says what drawing
/// that scene costs.
pub const TRUTH_CONTENT: &str = "truth content";

/// The renderer's settings drawing the truth's content out to `reach` view distances, at one
/// sample a pixel ([`TRUTH_CONTENT`]).
fn truth_content_config(ctx: &GpuContext, world: &World, reach: f64) -> RendererConfig {
    let slots = crate::tools::truth::atlas_slots(world, &ctx.device);
    let base = RendererConfig::for_world(world);
    crate::tools::truth::truth_config_reaching(world, &base, slots, reach)
}

/// The truth of [`crate::tools::truth`] at `size` (k x k sub-samples in linear light, the most
/// accurate grass, blades out to `reach` view distances): what every method is measured
/// against.
fn truth_for(
    ctx: &GpuContext,
    world: &World,
    size: (u32, u32),
    k: u32,
    reach: f64,
) -> Result<Truth> {
    supersampled(ctx, world, size, k, truth_content_config(ctx, world, reach))
}

/// A renderer of `world`'s frames at `size` drawn with `config`, k x k sub-samples each
/// averaged in linear light (the truth's machinery, whatever the settings).
fn supersampled(
    ctx: &GpuContext,
    world: &World,
    size: (u32, u32),
    k: u32,
    config: RendererConfig,
) -> Result<Truth> {
    Truth::with_config(
        ctx,
        world.clone(),
        std::sync::Arc::new(world.clone()),
        size,
        k,
        config,
    )
}

/// Steps the truth's wind, sway and trail through a frame that is not measured (its tiles
/// brought in first, unless `stop` is asked for meanwhile: [`crate::tools::stop::Stopped`]).
fn advance(
    truth: &mut Truth,
    ctx: &GpuContext,
    camera: &Camera,
    time_s: f64,
    walker: Option<DVec2>,
    stop: &Stop,
) -> Result<()> {
    stop.warm_up(truth.scene(), camera, crate::tools::fly::FIRST_FRAME_WAIT)?;
    truth.advance(ctx, camera, time_s, walker)
}

/// Renders one frame of `scene`, its tiles brought in first (unless `stop` is asked for
/// meanwhile: [`crate::tools::stop::Stopped`]).
fn frame(
    ctx: &GpuContext,
    scene: &mut Scene,
    camera: &Camera,
    time_s: f64,
    stop: &Stop,
) -> Result<RgbaImage> {
    stop.warm_up(scene, camera, crate::tools::fly::FIRST_FRAME_WAIT)?;
    scene.render_frame(ctx, camera, time_s, Some(camera.position.truncate()))?;
    Ok(scene.read_image(ctx)?)
}

/// Runs the benchmark; `progress`
/// hears each step's name, steps done and steps in all.
pub fn run_bench_aa(
    opts: &BenchAaOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<BenchAaReport> {
    opts.validate()?;
    let world = World::open(&opts.world)?;
    let start_path = crate::tools::camera_path(&world, &opts.world, Some(&opts.path))?;
    let paths: Vec<CameraPath> = opts
        .paths
        .iter()
        .map(|n| crate::tools::camera_path(&world, &opts.world, Some(n)))
        .collect::<Result<_>>()?;
    // The default's settings, then each named one (the default named too is measured once),
    // then the truth's content where it is named.
    let truth_content = opts.settings.iter().any(|n| n == TRUTH_CONTENT);
    let named: Vec<String> = opts
        .settings
        .iter()
        .filter(|n| n.as_str() != "default" && n.as_str() != TRUTH_CONTENT)
        .cloned()
        .collect();
    let settings = crate::tools::bench_lod::named_settings(
        &crate::tools::bench_lod::lod_settings(&world),
        &named,
    )?;
    // Its tables and report, a chart per size and the last frames of each size and motion.
    let charts: Vec<String> = opts
        .sizes
        .iter()
        .map(|s| format!("aa_{}x{}.png", s.0, s.1))
        .collect();
    let last_frames: Vec<String> = opts
        .sizes
        .iter()
        .flat_map(|s| {
            opts.motions
                .iter()
                .map(move |m| format!("{}x{}_{}_", s.0, s.1, m.name()))
        })
        .collect();
    let out_dir = OutDir::create_for(
        &opts.out,
        "bench aa",
        &Outputs::matching(|n| {
            [
                "aa.json",
                "aa_frames.csv",
                "aa_sequences.csv",
                "aa_paths.csv",
                "aa_timing.csv",
            ]
            .contains(&n)
                || charts.iter().any(|c| c == n)
                || (n.ends_with(".png") && last_frames.iter().any(|p| n.starts_with(p.as_str())))
        }),
    )?;
    let ctx = GpuContext::new()?;
    let stop = Stop::new(opts.stop.clone());
    let mut configs = vec![(String::new(), RendererConfig::for_world(&world))];
    for s in &settings {
        configs.push((format!("+{}", setting_label(&s.name)), s.config(&world)));
    }
    if truth_content {
        configs.push((
            format!("+{}", setting_label(TRUTH_CONTENT)),
            truth_content_config(&ctx, &world, opts.truth_reach),
        ));
    }
    let gpu = ctx.timestamps;
    let counts = FrameCounts::for_adapter(&ctx.adapter.get_info()).with(
        opts.warmup_frames,
        opts.timed_frames,
        opts.rounds,
    );
    let t0 = start_path.start_s();
    let start = sample_path(&start_path, t0);
    let mut frames = Vec::new();
    let mut sequences = Vec::new();
    // The last frames' images this run wrote, by name (the rest of bench aa's in the folder are
    // an earlier run's).
    let mut written: Vec<String> = Vec::new();
    let mut path_views = Vec::new();
    let mut timings = Vec::new();
    // The sequence under way (a list of frames per method) and the timing under way: kept by a
    // run stopped part-way.
    let mut sequence: Vec<Vec<AaFrame>> = Vec::new();
    let mut timing: Option<TimingSamples> = None;
    // Stopped (Ctrl-C) between frames, views or timings, what was measured is reported: the
    // frames of a sequence cut short among every frame, but not as a sequence; the views of a
    // path measured; each method's timing over the rounds it was timed, if any.
    let interrupted = caught((|| -> Result<()> {
        for &size in &opts.sizes {
            let mut reference = truth_for(&ctx, &world, size, opts.truth_k, opts.truth_reach)?
                .with_stop(stop.clone());
            let make_scenes = || -> Result<Vec<(String, Scene)>> {
                opts.variants()
                    .into_iter()
                    .flat_map(|(name, m, taa)| {
                        configs.iter().map(move |(suffix, config)| {
                            let mut config = config.clone();
                            config.aa = m;
                            config.taa = taa;
                            (format!("{name}{suffix}"), config)
                        })
                    })
                    .map(|(name, config)| {
                        Ok((
                            name,
                            Scene::new(&ctx, world.clone(), size.0, size.1, config)?,
                        ))
                    })
                    .collect()
            };
            let mut scenes = make_scenes()?;
            for &motion in &opts.motions {
                // Every method and the truth step through the same frames together.
                let mut truth_prev: Option<RgbaImage> = None;
                let mut prev: Vec<Option<RgbaImage>> = vec![None; scenes.len()];
                sequence = vec![Vec::new(); scenes.len()];
                let first = -i64::from(opts.run_up);
                for i in first..i64::from(opts.frames) {
                    stop.check()?;
                    let (camera, t) = motion.frame(&start, t0, i, opts.frames);
                    let walker = Some(camera.position.truncate());
                    let truth_img = if i >= 0 {
                        Some(reference.render(&ctx, &camera, t, walker)?)
                    } else {
                        advance(&mut reference, &ctx, &camera, t, walker, &stop)?;
                        None
                    };
                    // The frame's figures, kept once every method has drawn it.
                    let mut measured = Vec::new();
                    for (m, (method, scene)) in scenes.iter_mut().enumerate() {
                        let img = frame(&ctx, scene, &camera, t, &stop)?;
                        if let Some(truth_img) = &truth_img {
                            let change = prev[m].as_ref().map_or(0.0, |p| mean_change(p, &img));
                            let truth_change = truth_prev
                                .as_ref()
                                .map_or(0.0, |p| mean_change(p, truth_img));
                            let (flip, coarse_flip) = flips(truth_img, &img)?;
                            measured.push(AaFrame {
                                size,
                                method: method.clone(),
                                motion,
                                frame: i as u32,
                                flip,
                                coarse_flip,
                                change,
                                truth_change,
                            });
                        }
                        // From the first measured frame on, as the truth's: the first's change is
                        // 0 for both (it was the method's change from the run-up's last frame).
                        if truth_img.is_some() {
                            prev[m] = Some(img);
                        }
                    }
                    for (m, f) in measured.into_iter().enumerate() {
                        sequence[m].push(f);
                    }
                    if truth_img.is_some() {
                        truth_prev = truth_img;
                    }
                    progress(
                        &format!("{}x{} {}", size.0, size.1, motion.name()),
                        (i - first + 1) as u64,
                        (i64::from(opts.frames) - first) as u64,
                    );
                }
                for (m, (method, _)) in scenes.iter().enumerate() {
                    let f = &sequence[m];
                    let n = f.len() as f64;
                    // The teleport's jump is a change of view, not flicker: its frame is left
                    // out.
                    let jump = (opts.frames / 2) as usize;
                    let moved = |x: &AaFrame| {
                        x.frame > 0 && !(motion == Motion::Teleport && x.frame as usize == jump)
                    };
                    let changes: Vec<&AaFrame> = f.iter().filter(|x| moved(x)).collect();
                    let k = changes.len() as f64;
                    let measured = |of: fn(&AaFrame) -> f64| {
                        (!changes.is_empty())
                            .then(|| changes.iter().map(|x| of(x)).sum::<f64>() / k)
                    };
                    let flicker = measured(|x| x.change);
                    let truth_flicker = measured(|x| x.truth_change);
                    let frame_flips: Vec<f64> = f.iter().map(|x| x.flip).collect();
                    let mean = |of: fn(&AaFrame) -> f64| f.iter().map(of).sum::<f64>() / n.max(1.0);
                    sequences.push(AaSequence {
                        size,
                        method: method.clone(),
                        motion,
                        flip_mean: mean(|x| x.flip),
                        coarse_flip_mean: mean(|x| x.coarse_flip),
                        flicker,
                        truth_flicker,
                        flicker_ratio: flicker.zip(truth_flicker).map(|(f, t)| f / t.max(1e-9)),
                        recovery_frames: (motion == Motion::Teleport)
                            .then(|| recovery_frames(&frame_flips, jump))
                            .flatten(),
                    });
                }
                // The last frame of the sequence, each method's and the truth's, to look at.
                let mut write_last = |what: &str, img: &RgbaImage| -> Result<()> {
                    let name = format!("{}x{}_{}_{what}.png", size.0, size.1, motion.name());
                    write_png(&opts.out.join(&name), img)?;
                    written.push(name);
                    Ok(())
                };
                if let Some(img) = &truth_prev {
                    write_last("truth", img)?;
                }
                for (m, (method, _)) in scenes.iter().enumerate() {
                    if let Some(img) = &prev[m] {
                        write_last(method, img)?;
                    }
                }
                frames.extend(std::mem::take(&mut sequence).into_iter().flatten());
                write_tables(&opts.out, &frames, &sequences, &path_views)?;
            }
            // The paths: four views spread along each, reached by flight along it; the bounds
            // step through the same frames as the truth. Every renderer starts them fresh, as
            // the bounds do: a frame carries state into the next (the wind field's attack and
            // release, the walker's fading trail, the sway springs), and the sequences left
            // theirs in the truth and the methods.
            let (mut reference, mut bounds): (Truth, Vec<(Bound, Truth)>) = if paths.is_empty() {
                (reference, Vec::new())
            } else {
                drop(reference);
                scenes.clear();
                scenes = make_scenes()?;
                let truth = truth_for(&ctx, &world, size, opts.truth_k, opts.truth_reach)?
                    .with_stop(stop.clone());
                let bounds = Bound::measured(opts.truth_noise)
                    .into_iter()
                    .map(|b| {
                        Ok((
                            b,
                            b.renderer(&ctx, &world, size, opts.truth_k, opts.truth_reach)?
                                .with_stop(stop.clone()),
                        ))
                    })
                    .collect::<Result<_>>()?;
                (truth, bounds)
            };
            for path in &paths {
                for j in 0..4 {
                    let t_view = path.time_at(0.125 + 0.25 * f64::from(j));
                    for r in (0..=opts.run_up).rev() {
                        stop.check()?;
                        let t = t_view - f64::from(r) * DT_S;
                        let camera = sample_path(path, t);
                        let walker = Some(crate::camera::walker_at(&world.manifest, path, t));
                        let truth_img = if r == 0 {
                            Some(reference.render(&ctx, &camera, t, walker)?)
                        } else {
                            advance(&mut reference, &ctx, &camera, t, walker, &stop)?;
                            None
                        };
                        // The view's figures, kept once every bound and method has drawn it.
                        let mut measured = Vec::new();
                        for (bound, renderer) in bounds.iter_mut() {
                            if let Some(truth_img) = &truth_img {
                                let img = renderer.render(&ctx, &camera, t, walker)?;
                                let (flip, coarse_flip) = flips(truth_img, &img)?;
                                measured.push(AaPathView {
                                    size,
                                    method: bound.name(opts.truth_k),
                                    bound: true,
                                    path: path.name.clone(),
                                    t_s: t,
                                    flip,
                                    coarse_flip,
                                });
                            } else {
                                advance(renderer, &ctx, &camera, t, walker, &stop)?;
                            }
                        }
                        for (method, scene) in scenes.iter_mut() {
                            stop.warm_up(scene, &camera, crate::tools::fly::FIRST_FRAME_WAIT)?;
                            scene.render_frame(&ctx, &camera, t, walker)?;
                            if let Some(truth_img) = &truth_img {
                                let img = scene.read_image(&ctx)?;
                                let (flip, coarse_flip) = flips(truth_img, &img)?;
                                measured.push(AaPathView {
                                    size,
                                    method: method.clone(),
                                    bound: false,
                                    path: path.name.clone(),
                                    t_s: t,
                                    flip,
                                    coarse_flip,
                                });
                            }
                        }
                        path_views.extend(measured);
                    }
                }
                write_tables(&opts.out, &frames, &sequences, &path_views)?;
                progress(&format!("path {}", path.name), 1, 1);
            }
            drop(bounds);
            drop(reference);
            // Speed: interleaved rounds at the still view.
            let samples = &mut timing
                .insert(TimingSamples {
                    size,
                    methods: scenes
                        .iter()
                        .map(|(method, _)| (method.clone(), Vec::new(), Vec::new()))
                        .collect(),
                })
                .methods;
            if let Some((_, scene)) = scenes.first_mut() {
                ramp_up(&ctx, scene, &start, t0, Some(start.position.truncate()))?;
            }
            for round in 0..counts.rounds {
                for (m, (_, scene)) in scenes.iter_mut().enumerate() {
                    stop.check()?;
                    stop.warm_up(scene, &start, crate::tools::fly::FIRST_FRAME_WAIT)?;
                    let walker = Some(start.position.truncate());
                    for (stats, wall) in
                        run_frames(&ctx, scene, &start, t0, walker, counts.warmup, counts.timed)?
                    {
                        samples[m].1.push(frame_ms(&stats, wall, gpu));
                        samples[m].2.push(
                            stats
                                .gpu
                                .iter()
                                .filter(|(n, _)| n.starts_with("taa") || n.starts_with("msaa"))
                                .map(|(_, ms)| ms)
                                .sum(),
                        );
                    }
                }
                progress("timing", u64::from(round) + 1, u64::from(counts.rounds));
            }
            timings.extend(timing.take().into_iter().flat_map(|t| t.timings(gpu)));
        }
        Ok(())
    })())?;
    // What a stopped run was measuring: the frames of the sequence cut short, and the methods
    // timed in the rounds it ran.
    frames.extend(sequence.into_iter().flatten());
    timings.extend(timing.into_iter().flat_map(|t| t.timings(gpu)));
    let mut report = BenchAaReport {
        adapter: AdapterReport::of(&ctx),
        truth_k: opts.truth_k,
        truth_reach: opts.truth_reach,
        frames,
        sequences,
        paths: path_views,
        timings,
        settings,
        truth_content,
        counts,
        interrupted,
        stale_images: Vec::new(),
    };
    if report.frames.is_empty() && report.paths.is_empty() {
        // Stopped before the first frame was measured: nothing written (an earlier run's files
        // stay as they were).
        return Ok(report);
    }
    // The charts are written after the report: those of the sizes measured are this run's.
    written.extend(
        opts.sizes
            .iter()
            .filter(|&&s| report.measured(s))
            .map(|s| format!("aa_{}x{}.png", s.0, s.1)),
    );
    report.stale_images = stale_images(&opts.out, &written);
    write_outputs(opts, &report)?;
    out_dir.keep();
    Ok(report)
}

/// Writes the per-frame, per-sequence and per-path tables (`aa_frames.csv`, `aa_sequences.csv`,
/// `aa_paths.csv`) into `out`: at the end, and after each sequence and path as the run goes, so
/// that a run stopped part-way keeps what it measured.
pub fn write_tables(
    out: &std::path::Path,
    frames: &[AaFrame],
    sequences: &[AaSequence],
    paths: &[AaPathView],
) -> Result<()> {
    use std::fmt::Write as _;
    let mut csv =
        String::from("width,height,method,motion,frame,flip,change,truth_change,coarse_flip\n");
    for f in frames {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{:.5},{:.4},{:.4},{:.5}",
            f.size.0,
            f.size.1,
            f.method,
            f.motion.name(),
            f.frame,
            f.flip,
            f.change,
            f.truth_change,
            f.coarse_flip
        );
    }
    write_text(&out.join("aa_frames.csv"), &csv)?;
    let mut csv = String::from(
        "width,height,method,motion,flip_mean,flicker,truth_flicker,flicker_ratio,recovery_frames,\
         coarse_flip_mean\n",
    );
    // Empty where nothing was measured.
    let cell = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for s in sequences {
        let _ = writeln!(
            csv,
            "{},{},{},{},{:.5},{},{},{},{},{:.5}",
            s.size.0,
            s.size.1,
            s.method,
            s.motion.name(),
            s.flip_mean,
            cell(s.flicker),
            cell(s.truth_flicker),
            cell(s.flicker_ratio),
            s.recovery_frames.map_or(String::new(), |n| n.to_string()),
            s.coarse_flip_mean
        );
    }
    write_text(&out.join("aa_sequences.csv"), &csv)?;
    let mut csv = String::from("width,height,method,bound,path,t_s,flip,coarse_flip\n");
    for p in paths {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{:.3},{:.5},{:.5}",
            p.size.0, p.size.1, p.method, p.bound, p.path, p.t_s, p.flip, p.coarse_flip
        );
    }
    write_text(&out.join("aa_paths.csv"), &csv)?;
    Ok(())
}

fn write_outputs(opts: &BenchAaOptions, r: &BenchAaReport) -> Result<()> {
    use std::fmt::Write as _;
    write_tables(&opts.out, &r.frames, &r.sequences, &r.paths)?;
    let mut csv =
        String::from("width,height,method,frame_ms,q1_ms,q3_ms,spread,noisy,frames,aa_ms,gpu\n");
    for t in &r.timings {
        let _ = writeln!(
            csv,
            "{},{},{},{:.4},{:.4},{:.4},{:.4},{},{},{:.4},{}",
            t.size.0,
            t.size.1,
            t.method,
            t.frame.median_ms,
            t.frame.q1_ms,
            t.frame.q3_ms,
            t.frame.spread,
            t.frame.noisy,
            t.frame.frames,
            t.aa_ms,
            t.gpu
        );
    }
    write_text(&opts.out.join("aa_timing.csv"), &csv)?;
    write_json(&opts.out.join("aa.json"), r)?;
    // A chart per size measured (every size, unless the run was stopped early).
    for &size in opts.sizes.iter().filter(|&&s| r.measured(s)) {
        let points = r
            .timings
            .iter()
            .filter(|t| t.size == size)
            .map(|t| {
                let errors: Vec<f64> = r
                    .sequences
                    .iter()
                    .filter(|s| s.size == size && s.method == t.method)
                    .map(|s| s.flip_mean)
                    .collect();
                ChartPoint {
                    label: t.method.clone(),
                    x: t.frame.median_ms,
                    y: errors.iter().sum::<f64>() / errors.len().max(1) as f64,
                    chosen: t.method == AntiAliasing::default().name(),
                }
            })
            .collect();
        Chart {
            title: chart_title(
                format!(
                    "Anti-aliasing at {}x{}: error against the {}x{} truth and cost",
                    size.0, size.1, r.truth_k, r.truth_k
                ),
                r.interrupted,
            ),
            x_label: if r.timings.first().is_some_and(|t| t.gpu) {
                "GPU time per frame (ms)".into()
            } else {
                "frame time (ms)".into()
            },
            y_label: "mean FLIP vs truth over the sequences".into(),
            log_x: false,
            log_y: false,
            points,
        }
        .write_png(
            &opts.out.join(format!("aa_{}x{}.png", size.0, size.1)),
            900,
            600,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An earlier run's images are told apart from this run's by the names this run wrote, and
    /// from the user's own files by their names.
    #[test]
    fn an_earlier_runs_images_are_found_and_nothing_else() {
        for name in [
            "aa_960x540.png",
            "960x540_dolly_taa.png",
            "1920x1080_teleport_truth.png",
            "960x540_still_+segments_9_3_3.png",
        ] {
            assert!(is_bench_aa_image(name), "{name}");
        }
        for name in [
            "aa.json",
            "aa_frames.csv",
            "aa_960.png",
            "aa_x540.png",
            "960x540_walk_taa.png",
            "960x540_dolly_.png",
            "960x540_dolly_taa.jpg",
            "frame_00001.png",
            "holiday.png",
        ] {
            assert!(!is_bench_aa_image(name), "{name}");
        }
        let dir = tempfile::tempdir().unwrap();
        for name in ["aa_1920x1080.png", "1920x1080_pan_msaa.png", "notes.png"] {
            std::fs::write(dir.path().join(name), b"old").unwrap();
        }
        std::fs::write(dir.path().join("960x540_pan_taa.png"), b"new").unwrap();
        assert_eq!(
            stale_images(dir.path(), &["960x540_pan_taa.png".to_string()]),
            ["1920x1080_pan_msaa.png", "aa_1920x1080.png"]
        );
    }

    #[test]
    fn recovery_counts_the_frames_until_the_error_settles() {
        let flips = [0.05, 0.05, 0.30, 0.12, 0.06, 0.05, 0.05, 0.05];
        // Jump at frame 2; steady = mean of the last quarter of frames 2.. (2 frames) = 0.05;
        // 0.06 is still more than 10% above it.
        assert_eq!(recovery_frames(&flips, 2), Some(3));
        assert_eq!(recovery_frames(&[0.05; 8], 4), Some(0));
        assert_eq!(recovery_frames(&[0.05; 8], 8), None);
    }

    #[test]
    fn the_bounds_are_the_default_supersampled_and_the_truth_at_two_by_two() {
        let world = World::open(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz"),
        )
        .unwrap();
        let default = RendererConfig::for_world(&world);
        let (c, k) = Bound::DefaultSupersampled.config(&world, 4, 4.0, 985);
        // The default frame as it is, only without anti-aliasing: its sub-samples are that.
        assert_eq!(k, 4);
        assert_eq!(c.aa, AntiAliasing::Off);
        assert_eq!(c.grass.segments, default.grass.segments);
        let reach = |c: &RendererConfig| c.grass_rings.map(|r| (r.high_radius_m, r.low_radius_m));
        assert_eq!(reach(&c), reach(&default));
        assert_eq!(c.plants.lod_m, default.plants.lod_m);
        let (c, k) = Bound::Truth2x2.config(&world, 4, 4.0, 985);
        let truth = crate::tools::truth::truth_config_reaching(&world, &default, 985, 4.0);
        assert_eq!(k, 2);
        assert_eq!(c.grass.segments, truth.grass.segments);
        assert_eq!(reach(&c), reach(&truth));
        assert_eq!(c.plants.lod_m, truth.plants.lod_m);
        assert_ne!(reach(&c), reach(&default));
        assert_eq!(Bound::DefaultSupersampled.name(4), "default-4x4");
        assert_eq!(Bound::Truth2x2.name(4), "truth-2x2");
        // The truth's own sampling error: the truth's settings at twice its sub-samples a side,
        // measured only when asked for.
        let (c, k) = Bound::TruthFiner.config(&world, 4, 4.0, 985);
        assert_eq!(k, 8);
        assert_eq!(c.grass.segments, truth.grass.segments);
        assert_eq!(reach(&c), reach(&truth));
        assert_eq!(c.plants.lod_m, truth.plants.lod_m);
        assert_eq!(Bound::TruthFiner.name(4), "truth-8x8");
        assert_eq!(Bound::TruthFiner.name(2), "truth-4x4");
        assert_eq!(Bound::measured(false), Bound::ALL);
        assert_eq!(Bound::measured(true).last(), Some(&Bound::TruthFiner));
    }

    #[test]
    fn the_truths_noise_needs_room_for_twice_its_sub_samples_and_a_path() {
        let mut opts = BenchAaOptions {
            truth_noise: true,
            ..BenchAaOptions::default()
        };
        assert!(opts.validate().is_ok());
        opts.truth_k = 8;
        let e = opts.validate().unwrap_err().to_string();
        assert!(e.contains("--truth 8") && e.contains("16"), "{e}");
        opts.truth_k = 1;
        let e = opts.validate().unwrap_err().to_string();
        assert!(e.contains("--truth 1") && e.contains("truth-2x2"), "{e}");
        opts.truth_k = 4;
        opts.paths.clear();
        let e = opts.validate().unwrap_err().to_string();
        assert!(e.contains("--truth-noise") && e.contains("--paths"), "{e}");
        opts.truth_noise = false;
        assert!(opts.validate().is_ok());
    }

    #[test]
    fn a_list_naming_one_thing_twice_is_refused_naming_the_option_and_the_thing() {
        let ok = BenchAaOptions::default();
        assert!(ok.validate().is_ok());
        let cases: [(BenchAaOptions, &str); 6] = [
            (
                BenchAaOptions {
                    sizes: vec![(64, 36), (96, 54), (64, 36)],
                    ..BenchAaOptions::default()
                },
                "--size lists 64x36 twice",
            ),
            (
                BenchAaOptions {
                    methods: vec![AntiAliasing::Taa, AntiAliasing::Off, AntiAliasing::Taa],
                    ..BenchAaOptions::default()
                },
                "--aa lists taa twice",
            ),
            (
                BenchAaOptions {
                    motions: vec![Motion::Pan, Motion::Pan],
                    ..BenchAaOptions::default()
                },
                "--sequences lists pan twice",
            ),
            (
                BenchAaOptions {
                    paths: vec!["tour".into(), "meadow".into(), "tour".into()],
                    ..BenchAaOptions::default()
                },
                "--paths lists \"tour\" twice",
            ),
            (
                BenchAaOptions {
                    settings: vec!["no LOD".into(), "no LOD".into()],
                    ..BenchAaOptions::default()
                },
                "--settings lists \"no LOD\" twice",
            ),
            (
                BenchAaOptions {
                    taa: vec![TaaSettings::default(); 2],
                    ..BenchAaOptions::default()
                },
                "--taa-* lists",
            ),
        ];
        for (opts, needle) in cases {
            let e = opts.validate().unwrap_err().to_string();
            assert!(e.contains(needle), "{needle:?} not in {e:?}");
        }
        assert_eq!(crate::tools::bench::repeated(&[1, 2, 3]), None);
        assert_eq!(crate::tools::bench::repeated(&[1, 2, 3, 2, 1]), Some(&1));
    }

    #[test]
    fn each_temporal_setting_is_a_method_of_its_own_named_by_its_settings() {
        let base = TaaSettings::default();
        let mut opts = BenchAaOptions::default();
        let names = |o: &BenchAaOptions| -> Vec<String> {
            o.variants().into_iter().map(|(n, _, _)| n).collect()
        };
        assert_eq!(names(&opts), ["off", "taa", "msaa"]);
        opts.taa = vec![
            TaaSettings {
                max_samples: 32,
                ..base
            },
            TaaSettings {
                blade_motion: true,
                motion_falloff: 0.5,
                sway_falloff: 4.0,
                ..base
            },
        ];
        let v = opts.variants();
        let n: Vec<&str> = v.iter().map(|(n, _, _)| n.as_str()).collect();
        assert_eq!(
            n,
            [
                "off",
                "taa-n32-c2.5-f1-p2-l1-r0.45",
                &format!("taa-n{}-c2.5-f0.5-mv-p2-l1-r0.45-w4", base.max_samples),
                "msaa"
            ]
        );
        assert_eq!(v[1].2.max_samples, 32);
        assert!(v[2].2.blade_motion && v[2].1 == AntiAliasing::Taa);
        // Names fit file names and CSV cells.
        assert!(n.iter().all(|s| !s.contains([',', ':', '/', ' '])));
        opts.motions.clear();
        assert!(opts.validate().is_err());
        assert_eq!(Motion::from_name(" pan"), Some(Motion::Pan));
        assert_eq!(Motion::from_name("jump"), None);
    }

    #[test]
    fn a_settings_label_fits_file_names_and_csv_cells() {
        assert_eq!(
            setting_label("segments 7/3/3 view x1.5"),
            "segments-7-3-3-view-x1.5"
        );
        assert_eq!(setting_label("no LOD"), "no-LOD");
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        let world = World::open(&dir).unwrap();
        for s in crate::tools::bench_lod::lod_settings(&world) {
            let l = setting_label(&s.name);
            assert!(!l.contains([',', ':', '/', ' ', '+']), "{l}");
        }
    }

    #[test]
    fn change_is_the_mean_absolute_difference_over_rgb() {
        let a = RgbaImage::from_pixel(4, 2, image::Rgba([10, 20, 30, 255]));
        let b = RgbaImage::from_pixel(4, 2, image::Rgba([13, 20, 24, 0]));
        assert!((mean_change(&a, &b) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn motions_move_the_camera_as_named() {
        let start = Camera::new(DVec3::new(0.0, 0.0, 2.0), 0.0, -10.0);
        let (c, t) = Motion::Dolly.frame(&start, 5.0, 60, 24);
        assert!((c.position.x - DOLLY_MPS).abs() < 1e-9 && (t - 6.0).abs() < 1e-12);
        let (c, _) = Motion::Pan.frame(&start, 0.0, -30, 24);
        assert!((c.yaw_deg + PAN_DEG_PER_S / 2.0).abs() < 1e-9);
        let (c, _) = Motion::Teleport.frame(&start, 0.0, 11, 24);
        assert_eq!(c.position, start.position);
        let (c, _) = Motion::Teleport.frame(&start, 0.0, 12, 24);
        assert!((c.position.x - TELEPORT_M).abs() < 1e-9);
        let (c, t) = Motion::Still.frame(&start, 1.0, 30, 24);
        assert_eq!(c, start);
        assert!((t - 1.5).abs() < 1e-12);
    }
}
