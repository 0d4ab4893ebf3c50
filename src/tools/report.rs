//! The fly-through report, `report.json`.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::gpu::GpuContext;
use crate::grass::GrassStats;
use crate::stream::ResidencyStats;
use crate::tools::metrics::Summary;

/// The adapter a run used.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AdapterReport {
    /// Adapter name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)` or `NVIDIA H100 80GB HBM3`.
    pub name: String,
    /// Backend, e.g. `Vulkan`.
    pub backend: String,
    /// Device type: discrete GPU, CPU, ...
    pub device_type: String,
    /// Driver name and version.
    pub driver: String,
    /// Whether per-pass GPU times were measured.
    pub timestamps: bool,
}

impl AdapterReport {
    /// Describes the context's adapter.
    pub fn of(ctx: &GpuContext) -> Self {
        Self {
            name: ctx.info.name.clone(),
            backend: format!("{:?}", ctx.info.backend),
            device_type: format!("{:?}", ctx.info.device_type),
            driver: format!("{} {}", ctx.info.driver, ctx.info.driver_info)
                .trim()
                .to_owned(),
            timestamps: ctx.timestamps,
        }
    }
}

/// One rendered frame.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame number from 0.
    pub index: u32,
    /// Time on the camera path, seconds.
    pub t_s: f64,
    /// Camera position, metres.
    pub camera_m: [f64; 3],
    /// Position of whoever leaves the trail in the grass (the camera or the path's walker), xy
    /// metres.
    pub walker_m: [f64; 2],
    /// The wind scene in effect (empty: the manifest's default wind).
    pub wind_scene: String,
    /// Wall time of the frame, milliseconds: with images, the whole frame (record, submit,
    /// GPU, readback); without, the time between frames submitted at most two ahead of the
    /// GPU, as an application sees it.
    pub frame_ms: f64,
    /// CPU time to select tiles and record and submit the frame, milliseconds.
    pub cpu_ms: f64,
    /// GPU time of each pass, milliseconds (empty without timestamp queries).
    pub gpu_ms: BTreeMap<String, f64>,
    /// Terrain tiles drawn.
    pub tiles_drawn: u32,
    /// Grass tiles in the high-LOD ring.
    pub grass_tiles_high: u32,
    /// Grass tiles in the low-LOD ring.
    pub grass_tiles_low: u32,
    /// Tile service figures: tiles desired, resident, drawn from an ancestor, loads in flight,
    /// completed and cancelled, cache bytes and hit rate, atlas slots, evictions.
    pub residency: ResidencyStats,
    /// Grass: tiles, blades considered, culled by each test (distance, frustum, occlusion),
    /// overflowing and drawn, each per LOD (high, low).
    pub grass: GrassStats,
    /// Plants: cells considered, plants culled by each test, thinned where crowded,
    /// overflowing and drawn (absent when the frame drew none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plants: Option<crate::plants::PlantStats>,
    /// Trees, as `plants` (absent when the frame drew none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trees: Option<crate::plants::PlantStats>,
    /// With images, the wait for this frame's tiles before it was drawn, milliseconds (0 when
    /// the camera moved too little since the last frame to need one; see `fly`'s docs).
    #[serde(default)]
    pub tile_wait_ms: f64,
    /// Tiles still missing when that wait ended (0: the frame is at full detail).
    #[serde(default)]
    pub tiles_missing_after_wait: u32,
}

impl FrameRecord {
    /// Fills in the renderer's figures of the frame.
    pub fn fill(&mut self, stats: crate::renderer::FrameStats) {
        self.cpu_ms = stats.cpu_ms;
        self.gpu_ms = stats.gpu.into_iter().collect();
        self.tiles_drawn = stats.tiles_drawn;
        self.grass_tiles_high = stats.grass_tiles.0;
        self.grass_tiles_low = stats.grass_tiles.1;
        self.residency = stats.residency;
        self.grass = stats.grass;
        self.plants = stats.plants;
        self.trees = stats.trees;
    }
}

/// Summary statistics over all frames.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FlySummary {
    /// Whole-frame wall time.
    pub frame_ms: Summary,
    /// CPU time a frame.
    pub cpu_ms: Summary,
    /// GPU time a frame, per pass.
    pub gpu_ms: BTreeMap<String, Summary>,
    /// Tiles drawn a frame.
    pub tiles_drawn: Summary,
    /// Fraction of desired tiles resident at their own level.
    pub resident_fraction: Summary,
    /// Desired tiles with nothing to draw them from, summed over frames (0 unless broken).
    pub holes: u64,
    /// Most bytes the CPU tile cache held.
    pub cache_peak_bytes: u64,
    /// Most atlas slots in use.
    pub atlas_peak_slots: u32,
    /// Most tiles a frame held: wanted and their ancestors (the atlas slots the path needs to
    /// draw every wanted tile at its own level).
    #[serde(default)]
    pub atlas_peak_held: u32,
    /// Grass blades considered a frame, both LODs.
    pub grass_considered: Summary,
    /// Grass blades drawn a frame at high LOD.
    pub grass_drawn_high: Summary,
    /// Grass blades drawn a frame at low LOD.
    pub grass_drawn_low: Summary,
    /// Grass blades a frame, both LODs, that passed every test but did not fit their tile's
    /// slot of the pool (0 unless the world's `[grass_peak]` understates its grass).
    #[serde(default)]
    pub grass_overflow: Summary,
    /// Grass coverage over the frames of `coverage` (see [`CoverageRecord`]).
    #[serde(default)]
    pub coverage: Summary,
    /// Plant instances drawn a frame (all types and levels; a plant in a cross-fade counts
    /// twice), over the frames that drew plants.
    #[serde(default)]
    pub plants_drawn: Summary,
    /// Plant instances a frame that did not fit their region of the pool.
    #[serde(default)]
    pub plants_overflow: Summary,
    /// Plant instances a frame thinned out because their region of the pool was crowded the
    /// frame before.
    #[serde(default)]
    pub plants_crowded: Summary,
    /// Tree instances drawn a frame (all types and levels; a tree in a cross-fade counts
    /// twice), over the frames that drew trees.
    #[serde(default)]
    pub trees_drawn: Summary,
    /// Tree instances a frame that did not fit their region of the pool.
    #[serde(default)]
    pub trees_overflow: Summary,
    /// Tree instances a frame thinned out because their region of the pool was crowded the
    /// frame before.
    #[serde(default)]
    pub trees_crowded: Summary,
}

/// The grass coverage of one frame: of the pixels where terrain within
/// [`crate::tools::metrics::COVERAGE_DISTANCE_M`] of the camera (along the view ray) is the
/// nearest surface in the terrain-only depth, the fraction that a blade covers in the final
/// depth. Measured on frames apart from the timed ones.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct CoverageRecord {
    /// The frame (its number in `frames`).
    pub index: u32,
    /// Time on the camera path, seconds.
    pub t_s: f64,
    /// Covered pixels over pixels considered, in [0, 1] (0 when none were considered).
    pub coverage: f64,
    /// Pixels considered: near terrain in the terrain-only depth.
    pub pixels: u64,
    /// Of those, pixels a blade covers.
    pub covered: u64,
}

/// Everything `report.json` holds.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FlyReport {
    /// The world's name.
    pub world: String,
    /// The camera path flown.
    pub path: String,
    /// Image width and height.
    pub size: (u32, u32),
    /// The adapter.
    pub adapter: AdapterReport,
    /// Summary over the frames kept in `frames` (every frame unless the run was longer than
    /// [`MAX_REPORT_FRAMES`]); `holes`, `cache_peak_bytes` and `atlas_peak_slots` cover every
    /// frame flown.
    pub summary: FlySummary,
    /// Frames flown.
    #[serde(default)]
    pub frames_flown: u64,
    /// Whether the flight was stopped before its last frame ([`crate::tools::FlyOptions::stop`],
    /// Ctrl-C): the report covers the frames flown.
    #[serde(default)]
    pub interrupted: bool,
    /// Every how many frames one is kept in `frames`: 1, unless the run was longer than
    /// [`MAX_REPORT_FRAMES`] frames (then the kept frames are an evenly spaced sample).
    #[serde(default)]
    pub frame_stride: u64,
    /// Tiles of the first frame that the warm-up could not make resident, and why.
    #[serde(default)]
    pub warm_up_missing: Vec<String>,
    /// The frames, at most [`MAX_REPORT_FRAMES`] of them (see `frame_stride`).
    pub frames: Vec<FrameRecord>,
    /// Grass coverage of the frames it was measured on: every frame written as an image (at
    /// most [`MAX_REPORT_FRAMES`], evenly spaced), or without images up to
    /// [`crate::tools::fly::COVERAGE_FRAMES`] evenly spaced frames drawn again after the flight.
    #[serde(default)]
    pub coverage: Vec<CoverageRecord>,
}

/// Most per-frame records a fly-through keeps in memory and in `report.json`: about 2 KiB
/// each, so at most about 32 MiB whatever `--frames` asks for. Longer runs keep an evenly
/// spaced sample ([`Thinned`]).
pub const MAX_REPORT_FRAMES: usize = 16_384;

/// What a fly-through tallies over every frame, kept or not.
#[derive(Clone, Copy, Debug, Default)]
pub struct FlyTotals {
    /// Holes summed over frames.
    pub holes: u64,
    /// Most bytes the CPU tile cache held.
    pub cache_peak_bytes: u64,
    /// Most atlas slots in use.
    pub atlas_peak_slots: u32,
    /// Most tiles a frame held (wanted and their ancestors).
    pub atlas_peak_held: u32,
}

impl FlyTotals {
    /// Adds a frame.
    pub fn add(&mut self, f: &FrameRecord) {
        self.holes += u64::from(f.residency.holes);
        self.cache_peak_bytes = self.cache_peak_bytes.max(f.residency.cache.peak_bytes);
        self.atlas_peak_slots = self.atlas_peak_slots.max(f.residency.atlas_used);
        self.atlas_peak_held = self.atlas_peak_held.max(f.residency.held);
    }
}

impl FlyReport {
    /// A report over the kept `frames`, with its summary computed (the tallies of `totals`
    /// cover every frame flown).
    pub fn new(
        world: String,
        path: String,
        size: (u32, u32),
        adapter: AdapterReport,
        frames: Thinned<FrameRecord>,
        totals: FlyTotals,
    ) -> Self {
        let mut summary = FlySummary::of(frames.items());
        summary.holes = totals.holes;
        summary.cache_peak_bytes = totals.cache_peak_bytes;
        summary.atlas_peak_slots = totals.atlas_peak_slots;
        summary.atlas_peak_held = totals.atlas_peak_held;
        Self {
            world,
            path,
            size,
            adapter,
            summary,
            frames_flown: frames.seen(),
            interrupted: false,
            frame_stride: frames.stride(),
            warm_up_missing: Vec::new(),
            frames: frames.into_items(),
            coverage: Vec::new(),
        }
    }
}

/// An evenly spaced sample of a run's per-frame records, bounded in memory: it keeps every
/// record until it holds `cap`, then every other one, then every fourth, and so on (always
/// the records whose index is a multiple of [`Thinned::stride`]). However long the run, it
/// never holds more than `cap` records.
#[derive(Clone, Debug)]
pub struct Thinned<T> {
    items: Vec<T>,
    stride: u64,
    cap: usize,
    seen: u64,
}

impl<T> Thinned<T> {
    /// An empty sample holding at most `cap` records (at least 2).
    pub fn new(cap: usize) -> Self {
        Self {
            items: Vec::new(),
            stride: 1,
            cap: cap.max(2),
            seen: 0,
        }
    }

    /// Offers the next record (records are numbered from 0 in the order offered).
    pub fn push(&mut self, item: T) {
        if self.seen.is_multiple_of(self.stride) {
            if self.items.len() == self.cap {
                // Keep the records at even positions: indices that are multiples of 2 * stride.
                let mut k = 0;
                self.items.retain(|_| {
                    k += 1;
                    (k - 1) % 2 == 0
                });
                self.stride *= 2;
            }
            if self.seen.is_multiple_of(self.stride) {
                self.items.push(item);
            }
        }
        self.seen += 1;
    }

    /// The kept records, oldest first.
    pub fn items(&self) -> &[T] {
        &self.items
    }

    /// Takes the kept records.
    pub fn into_items(self) -> Vec<T> {
        self.items
    }

    /// Every how many records one is kept.
    pub fn stride(&self) -> u64 {
        self.stride
    }

    /// Records offered so far.
    pub fn seen(&self) -> u64 {
        self.seen
    }
}

#[cfg(test)]
mod tests {
    use super::Thinned;

    #[test]
    fn thinned_keeps_an_even_sample_within_its_cap() {
        let mut t = Thinned::new(8);
        for i in 0..1000u64 {
            t.push(i);
            assert!(t.items().len() <= 8, "{} records held", t.items().len());
            assert!(t.items().iter().all(|&v| v % t.stride() == 0));
        }
        assert_eq!(t.seen(), 1000);
        assert_eq!(t.stride(), 128);
        assert_eq!(t.items(), &[0, 128, 256, 384, 512, 640, 768, 896]);
        let mut small = Thinned::new(8);
        for i in 0..5u64 {
            small.push(i);
        }
        assert_eq!((small.items(), small.stride()), (&[0, 1, 2, 3, 4][..], 1));
    }
}
