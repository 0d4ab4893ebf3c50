//! The streaming soak test: a camera that flies fast with random turns and teleports, while the
//! tile service's ceilings, holes and the process's memory are watched.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

use crate::camera::Camera;
use crate::gpu::GpuContext;
use crate::renderer::RendererConfig;
use crate::tools::metrics::Summary;
use crate::tools::report::Thinned;
use crate::tools::rng::Rng;
use crate::tools::{AdapterReport, Scene, write_json};
use crate::world::error::short_number;
use crate::world::{TileData, TileId, World};

/// What `verdant soak` is asked to do.
#[derive(Clone, Debug)]
pub struct SoakOptions {
    /// The world's folder, or its `http://` address.
    pub world: PathBuf,
    /// How a world over HTTP is fetched.
    pub http: crate::stream::HttpOptions,
    /// Simulated flight time, seconds.
    pub seconds: f64,
    /// Camera speed, metres a second.
    pub speed_mps: f64,
    /// Seed of the turns and teleports.
    pub seed: u64,
    /// Output folder for `soak.json`.
    pub out: PathBuf,
    /// Image size.
    pub size: (u32, u32),
    /// Simulated time a frame, seconds.
    pub dt_s: f64,
    /// Simulated time between teleports, seconds.
    pub teleport_every_s: f64,
    /// Frames after a teleport before holes count as failures.
    pub settle_frames: u32,
    /// Share of the run (at least 3 s) before memory is expected to stay flat.
    pub warmup_fraction: f64,
    /// Limits of the tile service; `atlas_slots` [`super::WORLD_ATLAS_SLOTS`] sizes the atlas to
    /// the world.
    pub service: crate::stream::ServiceConfig,
    /// Fly without grass (and so without its wind): the streaming system alone.
    pub no_grass: bool,
    /// How the frames are anti-aliased.
    pub aa: crate::aa::AntiAliasing,
    /// Resident memory may grow this much after the warm-up, bytes (allocator noise); see
    /// [`SoakReport::rss_growth_bytes`].
    pub rss_tolerance_bytes: u64,
    /// A teleport must reach full detail (every desired tile resident at its own level) within
    /// this many frames, where the run flies that long after it.
    pub max_recovery_frames: u32,
    /// No frame may take longer than this wall time, milliseconds (a stall).
    pub max_stall_ms: f64,
    /// Faults injected while the soak flies, 0..=1 (0: none). On a world on disk, the share of
    /// its tile files (level 1 and finer) broken at any moment in a copy of the world that the
    /// soak flies ([`crate::tools::faults`]); over HTTP, the share of tile requests that a
    /// proxy in front of the server fails.
    pub faults: f64,
    /// Simulated time between rounds of file faults (each restores the last round's files and
    /// breaks a fresh set), seconds.
    pub fault_period_s: f64,
    /// A flag that ends the soak early (Ctrl-C on the command line): the frames flown are
    /// checked and reported, the report marked [`SoakReport::interrupted`].
    pub stop: Option<crate::bake::CancelFlag>,
}

impl Default for SoakOptions {
    fn default() -> Self {
        Self {
            world: PathBuf::from("worlds/santa-cruz"),
            http: crate::stream::HttpOptions::default(),
            seconds: 60.0,
            speed_mps: 50.0,
            seed: 1,
            out: PathBuf::from("out/soak"),
            size: (320, 180),
            dt_s: 0.1,
            teleport_every_s: 10.0,
            settle_frames: 10,
            warmup_fraction: 0.25,
            rss_tolerance_bytes: 12 << 20,
            max_recovery_frames: 50,
            max_stall_ms: 5000.0,
            service: crate::stream::ServiceConfig {
                atlas_slots: super::WORLD_ATLAS_SLOTS,
                ..Default::default()
            },
            no_grass: false,
            aa: crate::aa::AntiAliasing::default(),
            faults: 0.0,
            fault_period_s: 2.0,
            stop: None,
        }
    }
}

/// One teleport and how long the streamer took to catch up.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TeleportRecord {
    /// Frame of the jump.
    pub frame: u32,
    /// Where to.
    pub to_m: [f64; 3],
    /// Frames until every desired tile was resident at its own level (None: not before the
    /// next teleport or the end).
    pub frames_to_full_detail: Option<u32>,
    /// The same in wall-clock seconds.
    pub seconds_to_full_detail: Option<f64>,
}

/// Everything `soak.json` holds.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SoakReport {
    /// The world's name.
    pub world: String,
    /// The adapter.
    pub adapter: AdapterReport,
    /// Frames flown.
    pub frames: u32,
    /// Simulated seconds flown.
    pub seconds: f64,
    /// Camera speed, metres a second.
    pub speed_mps: f64,
    /// Seed.
    pub seed: u64,
    /// Whole-frame wall time, milliseconds.
    pub frame_ms: Summary,
    /// Peak resident memory of the process, bytes.
    pub rss_peak_bytes: u64,
    /// Resident memory just after the warm-up (the window's 10th percentile), bytes.
    pub rss_after_warmup_bytes: u64,
    /// Growth of the resident memory's floor (10th percentile) that went on through the run,
    /// less the CPU cache's own growth (which its ceiling bounds), bytes: twice the lesser of
    /// the two halves' growth (`rss_growth_halves_bytes`), which for a steady leak is its
    /// growth from just after the warm-up to the last quarter; a single step that then holds
    /// (a driver's buffer or a shader compiled late, as software Vulkan's heaps show) lies in
    /// one half only and counts nothing.
    pub rss_growth_bytes: u64,
    /// Growth of the resident memory's floor, less the cache's, from the window just after the
    /// warm-up to a window midway, and from there to the last quarter, bytes (negative where it
    /// fell).
    #[serde(default)]
    pub rss_growth_halves_bytes: [i64; 2],
    /// Ceiling of the CPU tile cache, bytes.
    pub cache_ceiling_bytes: u64,
    /// Most bytes the cache held.
    pub cache_peak_bytes: u64,
    /// Atlas slots.
    pub atlas_slots: u32,
    /// Most atlas slots in use.
    pub atlas_peak_slots: u32,
    /// Frames after a teleport's settle time with a hole.
    pub holes_after_settle: u32,
    /// Most grass blades drawn in a frame (0 without grass).
    #[serde(default)]
    pub grass_blades_drawn_peak: u64,
    /// Most plant and tree instances drawn in a frame (0 without them).
    #[serde(default)]
    pub plants_drawn_peak: u64,
    /// Most tree instances drawn in a frame (0 without trees).
    #[serde(default)]
    pub trees_drawn_peak: u64,
    /// Plant and tree instances that did not fit their pool's regions, over all frames (the
    /// pools are fixed: a view that wants more drops the rest).
    #[serde(default)]
    pub plants_overflow_total: u64,
    /// Plant and tree instances thinned out because their pool's region was crowded the frame
    /// before, over all frames (the pools are fixed: a view that wants more than fits thins its
    /// farther plants in the next frame, the same ones frame after frame).
    #[serde(default)]
    pub plants_crowded_total: u64,
    /// Longest frame, wall time, milliseconds.
    #[serde(default)]
    pub longest_frame_ms: f64,
    /// The bound on frames to full detail after a teleport.
    #[serde(default)]
    pub max_recovery_frames: u32,
    /// The bound on a frame's wall time, milliseconds.
    #[serde(default)]
    pub max_stall_ms: f64,
    /// Loads completed, cancelled and failed.
    pub loads_completed: u64,
    /// Loads dropped because their tiles left the desired set.
    pub loads_cancelled: u64,
    /// Loads that failed.
    pub loads_failed: u64,
    /// Atlas evictions.
    pub evictions: u64,
    /// Cache hit rate over the run.
    pub cache_hit_rate: f64,
    /// Median fraction of desired tiles resident at their own level.
    pub resident_fraction_median: f64,
    /// Resident memory every 10 frames: (frame, bytes, CPU cache bytes); at most
    /// [`MAX_SOAK_RECORDS`] entries, evenly spaced over longer runs.
    pub rss_timeline: Vec<(u32, u64, u64)>,
    /// Teleports and the time to full detail after each; at most [`MAX_SOAK_RECORDS`], evenly
    /// spaced over longer runs.
    pub teleports: Vec<TeleportRecord>,
    /// Median wall time to full detail after a teleport (over `teleports`), seconds.
    pub full_detail_after_teleport_s: Option<f64>,
    /// What went wrong; empty when the soak passed. At most [`MAX_SOAK_VIOLATIONS`] are listed.
    pub violations: Vec<String>,
    /// Violations in all, listed or not.
    #[serde(default)]
    pub violation_count: u64,
    /// Frames whose camera was over the world.
    #[serde(default)]
    pub frames_over_world: u32,
    /// The faults injected and what they did (None without `--faults`).
    #[serde(default)]
    pub faults: Option<SoakFaults>,
    /// Whether the soak was stopped before its last frame ([`SoakOptions::stop`], Ctrl-C):
    /// `frames` and `seconds` are what was flown, and the checks cover those.
    #[serde(default)]
    pub interrupted: bool,
}

/// The faults of a soak with `--faults`, and what the tile service made of them.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SoakFaults {
    /// The rate asked for.
    pub rate: f64,
    /// Tile files broken and restored (a world on disk).
    pub files: Option<crate::tools::faults::FileFaultCounts>,
    /// Requests through the fault proxy and the faults it injected (a world over HTTP).
    #[serde(default)]
    pub http: Option<crate::tools::fault_proxy::FaultCounts>,
    /// Tile loads that failed (each drawn from its ancestor, then retried).
    pub loads_failed: u64,
    /// Tiles that loaded after failing.
    pub tiles_healed: u64,
    /// Most desired tiles drawn from an ancestor because of a fault, in a frame.
    pub fault_blocked_peak: u32,
}

/// Most per-frame samples a soak keeps for its medians and memory windows (an evenly spaced
/// sample beyond that, [`Thinned`]): 40 bytes each, so at most 2.5 MiB whatever the run's
/// length. Also the most `rss_timeline` entries and `teleports` kept.
pub const MAX_SOAK_RECORDS: usize = 65_536;

/// Most violations listed in `soak.json` (all are counted).
pub const MAX_SOAK_VIOLATIONS: usize = 1000;

/// The percentile of a memory window taken as its floor.
const FLOOR_PERCENTILE: f64 = 0.1;

/// One frame's figures that the soak keeps for its summary.
#[derive(Clone, Copy, Debug)]
struct FrameSample {
    frame: u32,
    frame_ms: f64,
    resident_fraction: f64,
    rss: u64,
    cache_bytes: u64,
    /// No teleport's reload is under way: the streamer has caught up with the last teleport
    /// and `settle_frames` more have passed.
    settled: bool,
}

/// The fewest settled frames (no teleport's reload under way) a memory window is measured on;
/// with fewer, the window's every frame counts.
const MIN_SETTLED_FRAMES: usize = 5;

/// The frames of the memory check: the window just after the warm-up, one midway between it
/// and the last quarter of the run (as long, where the frames between allow), and the last
/// quarter, as frame ranges; `None` when the run is too short for them to be apart.
fn memory_windows(frames: u32, warmup_frames: u32) -> Option<[std::ops::Range<u32>; 3]> {
    let len = (frames / 10).max(1);
    let early = warmup_frames..warmup_frames + len;
    let late = frames - frames / 4..frames;
    if early.end >= late.start || late.is_empty() {
        return None;
    }
    // Centred between the two windows' centres, within the frames between them.
    let mid_len = len.min(late.start - early.end);
    let centre = (early.start + early.end + late.start + late.end) / 4;
    let start = centre
        .saturating_sub(mid_len / 2)
        .clamp(early.end, late.start - mid_len);
    Some([early, start..start + mid_len, late])
}

/// The memory growth that went on through a soak, from the floors (resident size and cache
/// bytes) of its three memory windows: the growth of each half, less the cache's, and twice
/// the lesser of the two, at least 0. A steady leak grows in both halves, and twice the lesser
/// is its whole growth; a step that then holds grows in one.
fn sustained_growth(floors: [(f64, f64); 3]) -> ([f64; 2], f64) {
    let half = |a: (f64, f64), b: (f64, f64)| (b.0 - a.0) - (b.1 - a.1);
    let halves = [half(floors[0], floors[1]), half(floors[1], floors[2])];
    (halves, (2.0 * halves[0].min(halves[1])).max(0.0))
}

/// The shortest soak, seconds, with the default frame time and warm-up: the least `soak
/// --seconds` takes ([`shortest_soak_s`] of the defaults; a test keeps the two equal).
pub const MIN_SOAK_S: f64 = 4.6;

/// The shortest `--seconds` whose memory windows fall after the warm-up and apart, to a tenth
/// of a second, rounded up (so that the value suggested runs).
fn shortest_soak_s(opts: &SoakOptions) -> f64 {
    let runs = |s: f64| {
        let (f, w) = soak_frames(opts, s);
        memory_windows(f as u32, w).is_some()
    };
    let mut tenths = 1u32;
    while !runs(f64::from(tenths) / 10.0) && tenths < 10 * 604_800 {
        tenths += 1;
    }
    f64::from(tenths) / 10.0
}

/// Frames of a soak of `seconds` and its warm-up.
fn soak_frames(opts: &SoakOptions, seconds: f64) -> (f64, u32) {
    let frames = (seconds / opts.dt_s).ceil();
    let warmup = ((seconds * opts.warmup_fraction).max(3.0) / opts.dt_s) as u32;
    (frames, warmup)
}

/// The violations of a soak: all counted, the first [`MAX_SOAK_VIOLATIONS`] listed.
#[derive(Default)]
struct Violations {
    listed: Vec<String>,
    count: u64,
}

impl Violations {
    fn push(&mut self, v: String) {
        self.count += 1;
        if self.listed.len() < MAX_SOAK_VIOLATIONS {
            self.listed.push(v);
        }
    }
}

/// A teleport must reach full detail within `bound` frames, where the run flew that long after
/// it (up to `end`, the next teleport or the end of the run, `end_s` seconds of wall time after
/// it). A machine that renders faster than the simulated time a frame stands for (`dt_s`) gets
/// the wall time those frames stand for instead, `bound * dt_s`: loads over a network take
/// wall time (an HTTP retry waits 200 ms), which 50 frames of 2 ms on a GPU do not give them.
fn check_recovery(
    t: &TeleportRecord,
    (end, end_s): (u32, f64),
    bound: u32,
    dt_s: f64,
    violations: &mut Violations,
) {
    let bound_s = f64::from(bound) * dt_s;
    match (t.frames_to_full_detail, t.seconds_to_full_detail) {
        (Some(f), Some(s)) if f > bound && s > bound_s => violations.push(format!(
            "teleport at frame {}: full detail after {f} frames and {s:.2} s, more than {bound} \
             frames and {bound_s:.1} s",
            t.frame
        )),
        (None, _) if end - t.frame > bound && end_s > bound_s => violations.push(format!(
            "teleport at frame {}: not at full detail {} frames and {end_s:.2} s later (bound \
             {bound} frames or {bound_s:.1} s)",
            t.frame,
            end - t.frame
        )),
        _ => {}
    }
}

/// Resident set size of this process, bytes (Linux; 0 elsewhere).
pub fn resident_bytes() -> u64 {
    release_free_memory();
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<u64>().ok())
        .map_or(0, |pages| pages * 4096)
}

/// Hands the allocator's free pages back to the system, so that the resident size read next
/// counts the memory the program holds rather than what the allocator keeps for reuse. glibc
/// keeps freed memory in per-thread arenas and raises its thresholds for returning it after
/// large frees; lavapipe's device memory and each frame's scratch come from the same heap, so
/// without this a burst of uploads after a teleport can lift the resident size's floor by tens
/// of MiB for the rest of a run, which reads as a leak. Elsewhere a no-op.
fn release_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `malloc_trim` takes no pointers and may be called from any thread at any time.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Ground height from the level-0 tiles, for keeping the camera above the terrain.
struct Ground {
    tiles: Vec<TileData>,
    world: World,
}

impl Ground {
    fn new(world: &World, source: &dyn crate::stream::TileSource) -> Result<Self> {
        let [nx, ny] = world.manifest.pyramid.tiles_at(0);
        let mut tiles = Vec::new();
        for y in 0..ny {
            for x in 0..nx {
                tiles.push(source.load(TileId::new(0, x, y))?);
            }
        }
        Ok(Self {
            tiles,
            world: world.clone(),
        })
    }

    fn height(&self, p: DVec2) -> f64 {
        let pyr = &self.world.manifest.pyramid;
        let Some(id) = pyr.tile_at(0, p) else {
            return 0.0;
        };
        let [nx, _] = pyr.tiles_at(0);
        let tile = &self.tiles[(id.y * nx + id.x) as usize];
        let b = pyr.bounds(id);
        let cell = pyr.cell_size_m(0);
        let u = (p - b.min) / cell + f64::from(pyr.border);
        let (i, j) = (u.x.floor(), u.y.floor());
        let (fx, fy) = (u.x - i, u.y - j);
        let max = f64::from(tile.size - 2);
        let (i, j) = (i.clamp(0.0, max) as u32, j.clamp(0.0, max) as u32);
        let h = |a: u32, b: u32| f64::from(tile.height_at(a, b));
        let low = h(i, j) * (1.0 - fx) + h(i + 1, j) * fx;
        let high = h(i, j + 1) * (1.0 - fx) + h(i + 1, j + 1) * fx;
        low * (1.0 - fy) + high * fy
    }
}

/// Runs a soak and writes `soak.json`. The report's `violations` list what failed.
pub fn run_soak(opts: &SoakOptions, progress: &mut dyn FnMut(u64, u64)) -> Result<SoakReport> {
    anyhow::ensure!(
        opts.seconds > 0.0 && opts.seconds.is_finite(),
        "--seconds must be positive"
    );
    anyhow::ensure!(
        opts.speed_mps >= 0.0 && opts.speed_mps.is_finite(),
        "--speed must not be negative"
    );
    anyhow::ensure!(opts.dt_s > 0.0, "the frame step must be positive");
    anyhow::ensure!(
        opts.faults.is_finite() && (0.0..=1.0).contains(&opts.faults),
        "--faults must be in 0..=1, not {}",
        opts.faults
    );
    anyhow::ensure!(
        opts.fault_period_s.is_finite() && opts.fault_period_s >= opts.dt_s,
        "the fault period must be at least a frame ({} s), not {}",
        opts.dt_s,
        opts.fault_period_s
    );
    let (frames_f, warmup_frames) = soak_frames(opts, opts.seconds);
    anyhow::ensure!(
        frames_f <= f64::from(u32::MAX),
        "--seconds {} is {frames_f} frames of {} s, more than a soak counts (at most {:.0} s)",
        opts.seconds,
        opts.dt_s,
        f64::from(u32::MAX) * opts.dt_s
    );
    if memory_windows(frames_f as u32, warmup_frames).is_none() {
        let min_s = shortest_soak_s(opts);
        anyhow::bail!(
            "--seconds {} is too short for the memory check: the warm-up alone takes {:.1} s; \
             use --seconds {:.1} or more",
            opts.seconds,
            f64::from(warmup_frames) * opts.dt_s,
            min_s
        );
    }
    // The faulty copy of the world is not among them: it is checked where it is made.
    let out_dir = crate::tools::output::OutDir::create(
        &opts.out,
        &crate::tools::output::Outputs::named(&["soak.json"]),
    )?;
    let is_url = opts.world.to_str().is_some_and(crate::stream::http::is_url);
    // With faults on a world on disk, the soak flies a copy whose files it breaks.
    let mut file_faults = if opts.faults > 0.0 && !is_url {
        Some(crate::tools::faults::FileFaults::new(
            &opts.world,
            &opts.out.join(".world-with-faults"),
            opts.faults,
            opts.seed,
        )?)
    } else {
        None
    };
    // Over HTTP, through a proxy that fails a share of tile requests (level 0 spared: the tile
    // service loads it once, before the first frame, and keeps it). The world is opened at the
    // user's address first, so that a server that is not there, or serves no world, is reported
    // as without --faults (that address and the real error), not as the proxy's 502 at an
    // address of its own.
    let proxy = if opts.faults > 0.0 && is_url {
        crate::tools::open_world_until(&opts.world, &opts.http, opts.stop.as_ref())?;
        Some(crate::tools::fault_proxy::FaultProxy::start_with(
            &opts.world.to_string_lossy(),
            crate::tools::fault_proxy::FaultOptions {
                rate: opts.faults,
                seed: opts.seed,
                spared: vec!["tiles/L0/".into()],
                // Enough for every load in flight and a request of the manifest's; the proxy
                // lives in this process, so its threads count in the memory the soak checks.
                workers: 2 * opts.service.stream.max_in_flight,
                ..Default::default()
            },
        )?)
    } else {
        None
    };
    let location = match (&file_faults, &proxy) {
        (Some(f), _) => f.world_dir().to_path_buf(),
        (_, Some(p)) => PathBuf::from(p.url()),
        _ => opts.world.clone(),
    };
    let (world, source) = crate::tools::open_world_until(&location, &opts.http, opts.stop.as_ref())
        .map_err(|e| match &proxy {
            Some(p) => e.context(format!(
                "{}: through the soak's fault proxy at {}",
                opts.world.display(),
                p.url()
            )),
            None => e,
        })?;
    let [ex, ey] = world.manifest.extent_m;
    // The pull toward the middle keeps the camera over the world only while a frame's step is
    // well inside the margin it turns at.
    // Down to the 1/10,000 m/s the error names (a hair over it taken as on it: 0.04 x 1 m /
    // 0.1 s is 0.39999...), so that the speed named is one the check takes.
    let most_speed = (0.04 * ex.min(ey) / opts.dt_s * 1e4 + 1e-6).floor() / 1e4;
    anyhow::ensure!(
        opts.speed_mps <= most_speed,
        "--speed {} m/s would leave {} (a world {} m across) within a few frames: it must be \
         in 0..={} m/s for this world",
        opts.speed_mps,
        world.manifest.name,
        short_number(ex.min(ey)),
        most_speed
    );
    let ground = Ground::new(&world, source.as_ref())?;
    let ctx = GpuContext::new()?;
    let mut config = RendererConfig::for_world(&world);
    config.service = super::service_over(opts.service, &config);
    config.aa = opts.aa;
    if opts.no_grass {
        config.grass_rings = None;
    }
    let name = world.manifest.name.clone();
    let stored_levels = world.manifest.pyramid.stored_levels;
    let (width, height) = opts.size;
    let mut scene = Scene::with_source(&ctx, world, source, width, height, config.clone())?;

    let planned = frames_f as u32;
    // The frames flown: all planned, or those before a stop.
    let mut frames = planned;
    let teleport_every = ((opts.teleport_every_s / opts.dt_s).round() as u32).max(1);
    let mut rng = Rng(opts.seed);
    let random_spot =
        |rng: &mut Rng| DVec2::new((0.1 + 0.8 * rng.next()) * ex, (0.1 + 0.8 * rng.next()) * ey);
    let mut pos = random_spot(&mut rng);
    let mut yaw = rng.next() * 360.0;
    let mut turn_rate = 0.0;
    // Everything kept per frame is bounded: see MAX_SOAK_RECORDS and MAX_SOAK_VIOLATIONS.
    let mut samples: Thinned<FrameSample> = Thinned::new(MAX_SOAK_RECORDS);
    let mut teleports: Thinned<TeleportRecord> = Thinned::new(MAX_SOAK_RECORDS);
    let mut current_teleport: Option<TeleportRecord> = None;
    let mut teleport_start = (0u32, Instant::now());
    let mut rss_peak = 0u64;
    let mut longest_frame_ms = 0.0f64;
    let mut blades_peak = 0u64;
    let (mut plants_peak, mut trees_peak, mut plants_overflow) = (0u64, 0u64, 0u64);
    let mut plants_crowded = 0u64;
    let (mut cache_peak, mut atlas_peak, mut holes_after_settle) = (0u64, 0u32, 0u32);
    let mut violations = Violations::default();
    let mut rss_timeline: Thinned<(u32, u64, u64)> = Thinned::new(MAX_SOAK_RECORDS);
    let mut last = None;
    let slots = config.service.atlas_slots;
    let ceiling = config.service.cache_bytes;
    let fault_every = ((opts.fault_period_s / opts.dt_s).round() as u32).max(1);
    let mut fault_blocked_peak = 0u32;
    let mut frames_over_world = 0u32;

    for frame in 0..planned {
        if opts.stop.as_ref().is_some_and(|s| s.is_cancelled()) {
            frames = frame;
            break;
        }
        let t = f64::from(frame) * opts.dt_s;
        if let Some(f) = file_faults.as_mut()
            && frame % fault_every == 0
        {
            f.step()?;
        }
        if frame > 0 && frame % teleport_every == 0 {
            pos = random_spot(&mut rng);
            yaw = rng.next() * 360.0;
            let since_last_s = teleport_start.1.elapsed().as_secs_f64();
            teleport_start = (frame, Instant::now());
            if let Some(done) = current_teleport.take() {
                check_recovery(
                    &done,
                    (frame, since_last_s),
                    opts.max_recovery_frames,
                    opts.dt_s,
                    &mut violations,
                );
                teleports.push(done);
            }
            current_teleport = Some(TeleportRecord {
                frame,
                to_m: [pos.x, pos.y, 0.0],
                frames_to_full_detail: None,
                seconds_to_full_detail: None,
            });
        }
        // Random turns, and a pull toward the middle near the world's edge.
        if frame % 20 == 0 {
            turn_rate = (rng.next() - 0.5) * 60.0;
        }
        let centre = DVec2::new(ex / 2.0, ey / 2.0);
        let margin = 0.08 * ex.min(ey);
        if pos.x < margin || pos.y < margin || pos.x > ex - margin || pos.y > ey - margin {
            let to_centre = centre - pos;
            yaw = to_centre.y.atan2(to_centre.x).to_degrees();
        }
        yaw += turn_rate * opts.dt_s;
        let heading = DVec2::new(yaw.to_radians().cos(), yaw.to_radians().sin());
        pos += heading * opts.speed_mps * opts.dt_s;
        let agl = 60.0 + 40.0 * (t * 0.3).sin();
        let eye = DVec3::new(pos.x, pos.y, ground.height(pos) + agl);
        if let Some(tp) = current_teleport.as_mut()
            && tp.frame == frame
        {
            tp.to_m[2] = eye.z;
        }
        let camera = Camera::new(eye, yaw, -12.0);
        if (0.0..=ex).contains(&pos.x) && (0.0..=ey).contains(&pos.y) {
            frames_over_world += 1;
        }

        let start = Instant::now();
        let stats = scene.render_at(&ctx, &camera, t)?;
        ctx.wait_idle();
        let ms = start.elapsed().as_secs_f64() * 1e3;
        longest_frame_ms = longest_frame_ms.max(ms);
        let drawn = u64::from(stats.grass.drawn[0]) + u64::from(stats.grass.drawn[1]);
        blades_peak = blades_peak.max(drawn);
        for (p, peak) in [
            (stats.plants, &mut plants_peak),
            (stats.trees, &mut trees_peak),
        ] {
            if let Some(p) = p {
                *peak = (*peak).max(u64::from(p.drawn));
                plants_overflow += u64::from(p.overflow);
                plants_crowded += u64::from(p.crowded);
            }
        }
        if ms > opts.max_stall_ms {
            violations.push(format!(
                "frame {frame}: took {ms:.0} ms, longer than the {:.0} ms a frame may stall",
                opts.max_stall_ms
            ));
        }
        let r = &stats.residency;
        cache_peak = cache_peak.max(r.cache.bytes);
        atlas_peak = atlas_peak.max(r.atlas_used);
        if r.cache.bytes > ceiling {
            violations.push(format!(
                "frame {frame}: CPU cache holds {} bytes, ceiling {ceiling}",
                r.cache.bytes
            ));
        }
        if r.atlas_used > slots {
            violations.push(format!(
                "frame {frame}: {} atlas slots in use of {slots}",
                r.atlas_used
            ));
        }
        if r.holes > 0 && frame >= teleport_start.0 + opts.settle_frames {
            holes_after_settle += 1;
            violations.push(format!(
                "frame {frame}: {} desired tiles had nothing to draw them from",
                r.holes
            ));
        }
        fault_blocked_peak = fault_blocked_peak.max(r.fault_blocked);
        // Full detail: every desired tile resident at its own level, but for those whose data
        // is broken now (drawn from an ancestor until a retry loads them).
        if let Some(tp) = current_teleport.as_mut()
            && tp.frames_to_full_detail.is_none()
            && r.resident + r.fault_blocked == r.desired
        {
            tp.frames_to_full_detail = Some(frame - tp.frame);
            tp.seconds_to_full_detail = Some(teleport_start.1.elapsed().as_secs_f64());
        }
        let rss = resident_bytes();
        rss_peak = rss_peak.max(rss);
        if frame % 10 == 0 {
            rss_timeline.push((frame, rss, r.cache.bytes));
        }
        let settled = current_teleport.as_ref().is_none_or(|tp| {
            tp.frames_to_full_detail
                .is_some_and(|f| frame >= tp.frame + f + opts.settle_frames)
        });
        samples.push(FrameSample {
            frame,
            frame_ms: ms,
            resident_fraction: r.resident_fraction,
            rss,
            cache_bytes: r.cache.bytes,
            settled,
        });
        last = Some(stats.residency);
        progress(u64::from(frame) + 1, u64::from(planned));
    }
    let interrupted = frames < planned;
    if interrupted {
        violations.push(format!(
            "the soak was stopped after {frames} of {planned} frames: its checks cover those \
             alone"
        ));
    }
    if let Some(done) = current_teleport.take() {
        let since_last_s = teleport_start.1.elapsed().as_secs_f64();
        check_recovery(
            &done,
            (frames, since_last_s),
            opts.max_recovery_frames,
            opts.dt_s,
            &mut violations,
        );
        teleports.push(done);
    }
    // Memory growth: the resident size's floor just after the warm-up, midway, and over the last
    // quarter of the run; a leak grows in both halves. The floor (the 10th percentile of each
    // window), because drivers allocate and free scratch memory in bursts: on lavapipe the resident
    // size swings by 40 MiB between frames, enough to move a window's median by as much under load,
    // while a leak lifts the floor. The CPU cache's own growth is taken out, since it has its
    // ceiling. Frames while a teleport's reload is under way (up to MIN_SETTLED_FRAMES of them kept
    // when a window has too few others) are left out: the burst of uploads, decodes and derivations
    // holds transient memory that the allocator may keep a while, which is not a leak. A single
    // step that holds afterwards is not one either: software Vulkan's process has stepped up once
    // by 23-41 MiB at a frame that differs from run to run, after `malloc_trim`, and stayed flat
    // (docs/anti-aliasing.md, "The temporal method as the default").
    // A soak stopped early may be too short for them: the memory is then not checked.
    let windows = memory_windows(frames, warmup_frames);
    let [early, mid, late] = windows.clone().unwrap_or([0..0, 0..0, 0..0]);
    let window = |range: &std::ops::Range<u32>| {
        let all: Vec<&FrameSample> = samples
            .items()
            .iter()
            .filter(|s| range.contains(&s.frame))
            .collect();
        let settled: Vec<&FrameSample> = all.iter().copied().filter(|s| s.settled).collect();
        let part = if settled.len() >= MIN_SETTLED_FRAMES {
            settled
        } else {
            all
        };
        let rss: Vec<f64> = part.iter().map(|p| p.rss as f64).collect();
        let cache: Vec<f64> = part.iter().map(|p| p.cache_bytes as f64).collect();
        let floor =
            |v: &[f64]| crate::tools::metrics::percentile(v, FLOOR_PERCENTILE).unwrap_or(0.0);
        (floor(&rss), floor(&cache))
    };
    let floors = [window(&early), window(&mid), window(&late)];
    let rss_after_warmup = floors[0].0 as u64;
    let (halves, growth) = sustained_growth(floors);
    let rss_growth = growth as u64;
    let mib = |b: f64| b / 1048576.0;
    if windows.is_none() {
        // Stopped before the memory's windows were flown: the stop's violation says so.
    } else if floors.iter().any(|f| f.0 <= 0.0) {
        violations.push(format!(
            "resident memory could not be measured after the warm-up (frames {}..{}, {}..{} and \
             {}..{}): the memory check cannot pass without it",
            early.start, early.end, mid.start, mid.end, late.start, late.end
        ));
    } else if rss_growth > opts.rss_tolerance_bytes {
        violations.push(format!(
            "resident memory kept growing after the warm-up: by {:.1} MiB to frame {} and {:.1} \
             MiB more to the last quarter, {:.1} MiB at that rate (tolerance {:.1} MiB)",
            mib(halves[0]),
            mid.start,
            mib(halves[1]),
            mib(growth),
            mib(opts.rss_tolerance_bytes as f64)
        ));
    }
    let last = last.unwrap_or_default();
    // A soak that never flew over the world, or never loaded a tile, checked nothing.
    if f64::from(frames_over_world) < 0.9 * f64::from(frames) {
        violations.push(format!(
            "the camera was over the world in only {frames_over_world} of {frames} frames: \
             the soak checked little of its streaming"
        ));
    }
    if stored_levels > 1 && last.stream.completed == 0 {
        violations.push(format!(
            "no tile was loaded in {frames} frames ({} loads failed): the soak checked nothing \
             of its streaming",
            last.stream.failed
        ));
    }
    if let Some(f) = file_faults.as_mut() {
        f.restore()?;
    }
    let faults = (opts.faults > 0.0).then(|| SoakFaults {
        rate: opts.faults,
        files: file_faults.as_ref().map(|f| f.counts().clone()),
        http: proxy.as_ref().map(|p| p.counts()),
        loads_failed: last.stream.failed,
        tiles_healed: last.faults_healed,
        fault_blocked_peak,
    });
    drop(file_faults);
    // A soak with faults that met none checked nothing of them. Over HTTP, the client's
    // retries may absorb every fault (then no load fails): the proxy's count is what was met.
    if let Some(f) = &faults {
        let met = match &f.http {
            Some(h) => h.faults(),
            None => f.loads_failed,
        };
        if met == 0 {
            violations.push(format!(
                "faults at rate {} were asked for, but the soak met none (fly longer or raise \
                 --faults)",
                f.rate
            ));
        }
    }
    let teleports = teleports.into_items();
    let detail: Vec<f64> = teleports
        .iter()
        .filter_map(|t| t.seconds_to_full_detail)
        .collect();
    let report = SoakReport {
        world: name,
        adapter: AdapterReport::of(&ctx),
        frames,
        seconds: if interrupted {
            f64::from(frames) * opts.dt_s
        } else {
            opts.seconds
        },
        speed_mps: opts.speed_mps,
        seed: opts.seed,
        frame_ms: Summary::of(
            &samples
                .items()
                .iter()
                .map(|s| s.frame_ms)
                .collect::<Vec<_>>(),
        ),
        rss_peak_bytes: rss_peak,
        rss_after_warmup_bytes: rss_after_warmup,
        rss_growth_bytes: rss_growth,
        rss_growth_halves_bytes: halves.map(|h| h as i64),
        cache_ceiling_bytes: ceiling,
        cache_peak_bytes: cache_peak.max(last.cache.peak_bytes),
        atlas_slots: slots,
        atlas_peak_slots: atlas_peak,
        holes_after_settle,
        grass_blades_drawn_peak: blades_peak,
        plants_drawn_peak: plants_peak,
        trees_drawn_peak: trees_peak,
        plants_overflow_total: plants_overflow,
        plants_crowded_total: plants_crowded,
        longest_frame_ms,
        max_recovery_frames: opts.max_recovery_frames,
        max_stall_ms: opts.max_stall_ms,
        loads_completed: last.stream.completed,
        loads_cancelled: last.stream.cancelled,
        loads_failed: last.stream.failed,
        evictions: last.evictions,
        cache_hit_rate: last.cache.hit_rate(),
        resident_fraction_median: Summary::of(
            &samples
                .items()
                .iter()
                .map(|s| s.resident_fraction)
                .collect::<Vec<_>>(),
        )
        .median,
        full_detail_after_teleport_s: (!detail.is_empty()).then(|| Summary::of(&detail).median),
        rss_timeline: rss_timeline.into_items(),
        teleports,
        violation_count: violations.count,
        violations: violations.listed,
        frames_over_world,
        faults,
        interrupted,
    };
    write_json(&opts.out.join("soak.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shortest soak that a too-short one is told to use runs, and a tenth of a second
    /// less does not.
    #[test]
    fn the_shortest_soak_suggested_runs() {
        for dt_s in [1.0 / 60.0, 1.0 / 30.0, 0.05] {
            let opts = SoakOptions {
                dt_s,
                ..SoakOptions::default()
            };
            let runs = |s: f64| {
                let (f, w) = soak_frames(&opts, s);
                memory_windows(f as u32, w).is_some()
            };
            let s = shortest_soak_s(&opts);
            assert!(runs(s), "{s} s at {dt_s} s a frame");
            let before = ((s * 10.0).round() - 1.0) / 10.0;
            assert!(
                !runs(before),
                "{s} s at {dt_s} s a frame is not the shortest"
            );
        }
    }

    fn teleport(frames: Option<u32>, seconds: Option<f64>) -> TeleportRecord {
        TeleportRecord {
            frame: 100,
            to_m: [0.0; 3],
            frames_to_full_detail: frames,
            seconds_to_full_detail: seconds,
        }
    }

    fn violations(t: &TeleportRecord, end: (u32, f64)) -> u64 {
        let mut v = Violations::default();
        check_recovery(t, end, 50, 0.1, &mut v);
        v.count
    }

    #[test]
    fn the_shortest_soak_is_the_one_the_command_line_takes() {
        assert_eq!(shortest_soak_s(&SoakOptions::default()), MIN_SOAK_S);
        let (frames, warmup) = soak_frames(&SoakOptions::default(), MIN_SOAK_S);
        assert!(memory_windows(frames as u32, warmup).is_some());
    }

    #[test]
    fn memory_windows_lie_after_the_warm_up_in_order_and_apart() {
        let [early, mid, late] = memory_windows(200, 50).unwrap();
        assert_eq!((early.clone(), late.clone()), (50..70, 150..200));
        assert!(early.end <= mid.start && mid.end <= late.start, "{mid:?}");
        assert_eq!(mid.len(), early.len());
        // A short run's middle window is as long as the frames between allow.
        let [early, mid, late] = memory_windows(50, 30).unwrap();
        assert_eq!((early, mid, late), (30..35, 35..38, 38..50));
        // The warm-up runs into the last quarter.
        assert!(memory_windows(40, 30).is_none());
        assert!(memory_windows(44, 30).is_none());
    }

    #[test]
    fn a_steady_leak_counts_and_a_step_that_holds_does_not() {
        const MIB: f64 = 1048576.0;
        let flat = |rss: f64| (rss * MIB, 0.0);
        // Flat.
        assert_eq!(
            sustained_growth([flat(400.0), flat(400.5), flat(401.0)]).1,
            1.0 * MIB
        );
        // A steady leak of 20 MiB from window to window: 40 MiB over the run.
        let (halves, growth) = sustained_growth([flat(400.0), flat(420.0), flat(440.0)]);
        assert_eq!((halves, growth), ([20.0 * MIB, 20.0 * MIB], 40.0 * MIB));
        // A leak that slows still counts twice its lesser half.
        assert_eq!(
            sustained_growth([flat(400.0), flat(430.0), flat(440.0)]).1,
            20.0 * MIB
        );
        // One step of 38 MiB, held, in either half.
        assert_eq!(
            sustained_growth([flat(438.0), flat(437.5), flat(479.0)]).1,
            0.0
        );
        assert_eq!(
            sustained_growth([flat(400.0), flat(438.0), flat(438.0)]).1,
            0.0
        );
        // The cache's growth is its ceiling's business.
        let cached = |rss: f64, cache: f64| (rss * MIB, cache * MIB);
        let (halves, growth) =
            sustained_growth([cached(400.0, 1.0), cached(410.0, 11.0), cached(420.0, 21.0)]);
        assert_eq!((halves, growth), ([0.0, 0.0], 0.0));
    }

    #[test]
    fn recovery_is_bounded_by_frames_or_the_time_they_stand_for() {
        // Within 50 frames: passes however long it took (a slow software renderer).
        assert_eq!(violations(&teleport(Some(40), Some(30.0)), (200, 60.0)), 0);
        // More frames, but within the 5 s they stand for (a fast GPU waiting on a network).
        assert_eq!(violations(&teleport(Some(300), Some(0.8)), (500, 2.0)), 0);
        // Beyond both.
        assert_eq!(violations(&teleport(Some(300), Some(6.0)), (500, 8.0)), 1);
        // Never reached: a violation only once the run flew past both bounds.
        assert_eq!(violations(&teleport(None, None), (200, 3.0)), 0);
        assert_eq!(violations(&teleport(None, None), (140, 9.0)), 0);
        assert_eq!(violations(&teleport(None, None), (200, 9.0)), 1);
    }
}
