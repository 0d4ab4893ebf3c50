//! The frame's records: what a frame is drawn from, what it drew and cost, and what a
//! warm-up could not make resident.

use glam::{DVec2, Vec2};

use crate::camera::Camera;
use crate::gpu::PassTimes;
use crate::grass::GrassStats;
use crate::stream::ResidencyStats;
use crate::world::TileId;

/// What a frame is drawn from.
#[derive(Clone, Copy, Debug)]
pub struct FrameInput {
    /// The camera: a position in world metres (f64) with yaw and pitch, or with the caller's
    /// own view and projection ([`Camera::with_view`]).
    pub camera: Camera,
    /// Seconds since the start: the wind and the sway springs advance by the time since the
    /// last frame (at most 5 s).
    pub time_s: f64,
    /// Where the walker that leaves the trail in the grass is (world xy, metres), or `None` for
    /// no trail this frame (the trail fades).
    pub walker: Option<DVec2>,
    /// Sub-pixel offset of the whole image, in pixels of the target (x right, y down; zero
    /// for none): the projection is shifted by it, so that frames jittered within a pixel
    /// sample the scene at different points of each pixel (supersampling by accumulation).
    pub jitter_px: Vec2,
}

impl FrameInput {
    /// Why this frame cannot be drawn, or `Ok`: its camera ([`Camera::check`]), time, walker
    /// and jitter must be finite.
    pub fn check(&self) -> Result<(), String> {
        self.camera.check()?;
        if !self.time_s.is_finite() {
            return Err(format!("time {} s is not finite", self.time_s));
        }
        if let Some(w) = self.walker
            && !w.is_finite()
        {
            return Err(format!("walker position {w} is not finite"));
        }
        if !self.jitter_px.is_finite() {
            return Err(format!("jitter {} pixels is not finite", self.jitter_px));
        }
        Ok(())
    }

    /// A frame from `camera` at `time_s`, the camera leaving the trail.
    pub fn new(camera: Camera, time_s: f64) -> Self {
        Self {
            camera,
            time_s,
            walker: Some(camera.position.truncate()),
            jitter_px: Vec2::ZERO,
        }
    }
}

/// What one frame drew and what it cost; delivered a frame or two after it was recorded.
#[derive(Clone, Debug, Default)]
pub struct FrameStats {
    /// The frame's number (0 for the first [`Renderer::prepare`](super::Renderer::prepare)).
    pub frame: u64,
    /// Terrain tiles drawn (each from its own data or an ancestor's).
    pub tiles_drawn: u32,
    /// Grass tiles in the high and low rings.
    pub grass_tiles: (u32, u32),
    /// CPU time of prepare and record (tile selection, uploads, recording), milliseconds.
    pub cpu_ms: f64,
    /// GPU time per pass (empty without timestamp queries).
    pub gpu: PassTimes,
    /// The tile service's figures.
    pub residency: ResidencyStats,
    /// Grass: tiles, blades considered, culled by each test and drawn, per LOD.
    pub grass: GrassStats,
    /// Plants: cells considered, plants culled by each test, thinned where crowded and drawn;
    /// `None` when the frame drew none (no plant types, or the `plants` feature off).
    pub plants: Option<crate::plants::PlantStats>,
    /// Trees, as `plants`; `None` when the frame drew none (no tree types, or the `trees`
    /// feature off).
    pub trees: Option<crate::plants::PlantStats>,
}

/// What a warm-up could not make resident.
#[derive(Clone, Debug, Default)]
pub struct WarmUp {
    /// The wanted tiles that are not resident, each with the reason; empty when all are.
    pub missing: Vec<MissingTile>,
}

/// A tile that a warm-up could not make resident.
#[derive(Clone, Debug)]
pub struct MissingTile {
    /// The tile.
    pub tile: TileId,
    /// Why, in words (the failed load's error where there is one).
    pub reason: String,
}

impl WarmUp {
    /// One line per missing tile (at most `max`, then a count of the rest).
    pub fn describe(&self, max: usize) -> Vec<String> {
        let mut lines: Vec<String> = self
            .missing
            .iter()
            .take(max)
            .map(|m| {
                format!(
                    "tile L{} {}_{}: {}",
                    m.tile.level, m.tile.x, m.tile.y, m.reason
                )
            })
            .collect();
        if self.missing.len() > max {
            lines.push(format!("and {} more", self.missing.len() - max));
        }
        lines
    }
}
