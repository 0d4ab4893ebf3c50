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
    /// Grass blades considered a frame, both LODs.
    pub grass_considered: Summary,
    /// Grass blades drawn a frame at high LOD.
    pub grass_drawn_high: Summary,
    /// Grass blades drawn a frame at low LOD.
    pub grass_drawn_low: Summary,
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
    /// Summary over all frames.
    pub summary: FlySummary,
    /// Every frame.
    pub frames: Vec<FrameRecord>,
}

impl FlyReport {
    /// A report over `frames`, with its summary computed.
    pub fn new(
        world: String,
        path: String,
        size: (u32, u32),
        adapter: AdapterReport,
        frames: Vec<FrameRecord>,
    ) -> Self {
        Self {
            world,
            path,
            size,
            adapter,
            summary: FlySummary::of(&frames),
            frames,
        }
    }
}
