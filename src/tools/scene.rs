//! The headless scene of the tools: offscreen colour and depth targets of a fixed size around a
//! [`Renderer`], with a frame call that waits for the GPU (for runs that read every frame back)
//! and one that does not (for timing runs).

use std::sync::Arc;

use glam::DVec2;

use crate::camera::Camera;
use crate::gpu::{GpuContext, ReadbackError};
use crate::lod::Ring;
use crate::renderer::{
    FrameInput, FrameStats, Renderer, RendererConfig, RendererError, RendererOptions,
};
use crate::stream::{TileAtlas, TileService, TileSource};
use crate::terrain::{COLOR_FORMAT, DEPTH_FORMAT};
use crate::world::{TileId, World};

/// Frames [`Scene::submit_frame`] lets the CPU run ahead of the GPU at most, as an application
/// with double buffering does.
pub const FRAMES_IN_FLIGHT: usize = 2;

/// What stops a scene from being built or drawn.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// The renderer refused.
    #[error(transparent)]
    Renderer(#[from] RendererError),
    /// The image could not be read back.
    #[error(transparent)]
    Readback(#[from] ReadbackError),
    /// A frame's figures did not come back after its GPU work finished.
    #[error("the figures of frame {0} did not come back from the GPU")]
    StatsMissing(u64),
    /// Coverage was asked for without a frame drawn with the capture on.
    #[error(
        "no frame was drawn with the terrain-only depth captured: switch the capture on \
         (Scene::set_coverage_capture) and draw a frame first"
    )]
    NoCapture,
}

/// A world drawn by a [`Renderer`] into offscreen targets (`COLOR_FORMAT`, `DEPTH_FORMAT`).
pub struct Scene {
    renderer: Renderer,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth: wgpu::Texture,
    depth_view: wgpu::TextureView,
    last: Option<(Camera, f64)>,
    /// The camera of the last frame drawn with the terrain-only depth captured.
    captured: Option<Camera>,
    in_flight: std::collections::VecDeque<wgpu::SubmissionIndex>,
    /// Sub-pixel offset of the frames drawn (see [`FrameInput::jitter_px`]).
    jitter_px: glam::Vec2,
}

impl Scene {
    /// A renderer of `world` with `width` x `height` targets (its level-0 tiles are loaded here).
    pub fn new(
        ctx: &GpuContext,
        world: World,
        width: u32,
        height: u32,
        config: RendererConfig,
    ) -> Result<Self, SceneError> {
        let source = Arc::new(world.clone());
        Self::with_source(ctx, world, source, width, height, config)
    }

    /// Like [`Scene::new`], with tiles from `source` instead of the world's files (tests use
    /// this to make loads slow or failing on purpose).
    pub fn with_source(
        ctx: &GpuContext,
        world: World,
        source: Arc<dyn TileSource>,
        width: u32,
        height: u32,
        config: RendererConfig,
    ) -> Result<Self, SceneError> {
        let mut options = RendererOptions::new(&world, COLOR_FORMAT, DEPTH_FORMAT, width, height);
        options.config = config;
        let renderer = Renderer::with_source(&ctx.device, &ctx.queue, world, source, options)?;
        let target = |label, format, usage| {
            crate::gpu::target_texture(&ctx.device, label, format, usage, (width, height))
        };
        let (color, depth, color_view, depth_view) = crate::renderer::allocate_at_size(
            &ctx.device,
            "the frame's colour and depth targets",
            (width, height),
            || {
                let color = target(
                    "color",
                    COLOR_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                );
                let depth = target(
                    "depth",
                    DEPTH_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                );
                let color_view = color.create_view(&Default::default());
                let depth_view = depth.create_view(&Default::default());
                Ok((color, depth, color_view, depth_view))
            },
        )?;
        Ok(Self {
            renderer,
            color_view,
            depth_view,
            depth,
            color,
            last: None,
            captured: None,
            in_flight: std::collections::VecDeque::new(),
            jitter_px: glam::Vec2::ZERO,
        })
    }

    /// The renderer.
    pub fn renderer(&mut self) -> &mut Renderer {
        &mut self.renderer
    }

    /// The world being drawn.
    pub fn world(&self) -> &World {
        self.renderer.world()
    }

    /// Width and height of the targets.
    pub fn size(&self) -> (u32, u32) {
        (self.color.width(), self.color.height())
    }

    /// The tile service (for its figures and residency queries).
    pub fn service(&self) -> &TileService {
        self.renderer.service()
    }

    /// The grass tiles of the last frame and their rings.
    pub fn grass_rings(&self) -> Vec<(TileId, Ring)> {
        self.renderer.grass_rings()
    }

    /// The tile atlas.
    pub fn atlas(&self) -> &TileAtlas {
        self.renderer.atlas()
    }

    /// The name of the wind scene in effect at `time_s`.
    pub fn wind_scene_at(&self, time_s: f64) -> String {
        self.renderer.wind_scene_at(time_s)
    }

    /// Brings every tile `camera` wants into the atlas, waiting (see [`Renderer::warm_up`]).
    pub fn warm_up(
        &mut self,
        _ctx: &GpuContext,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<bool, SceneError> {
        Ok(self.renderer.warm_up(camera, timeout)?)
    }

    /// Like [`Scene::warm_up`], saying which tiles are missing (see
    /// [`Renderer::warm_up_report`]).
    pub fn warm_up_report(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<crate::renderer::WarmUp, SceneError> {
        Ok(self.renderer.warm_up_report(camera, timeout)?)
    }

    /// Like [`Scene::warm_up_report`], stopping early once `stop` returns true (see
    /// [`Renderer::warm_up_until`]).
    pub fn warm_up_until(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<crate::renderer::WarmUp, SceneError> {
        Ok(self.renderer.warm_up_until(camera, timeout, stop)?)
    }

    /// Draws one frame from `camera` at the time of the last frame (the wind stands still).
    pub fn render(&mut self, ctx: &GpuContext, camera: &Camera) -> Result<FrameStats, SceneError> {
        let t = self.last.map_or(0.0, |(_, t)| t);
        self.render_at(ctx, camera, t)
    }

    /// Draws one frame from `camera` at `time_s`, the camera leaving the trail, and waits for
    /// it and its figures.
    pub fn render_at(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
    ) -> Result<FrameStats, SceneError> {
        let walker = camera.position.truncate();
        self.render_frame(ctx, camera, time_s, Some(walker))
    }

    /// Like [`Scene::render_at`], with the trail left by a walker at `walker` (world xy,
    /// metres) instead of the camera; `None` leaves no trail this frame.
    pub fn render_frame(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
    ) -> Result<FrameStats, SceneError> {
        let (frame, submission) = self.submit_frame(ctx, camera, time_s, walker)?;
        let _ = ctx.device.poll(wgpu::PollType::Wait {
            submission_index: Some(submission),
            timeout: None,
        });
        self.renderer
            .take_stats()
            .into_iter()
            .find(|s| s.frame == frame)
            .ok_or(SceneError::StatsMissing(frame))
    }

    /// Prepares, records and submits one frame without waiting for it, unless more than
    /// [`FRAMES_IN_FLIGHT`] frames would then be on the GPU (it waits for the oldest); returns
    /// its number (its figures come back through [`Renderer::take_stats`]) and its submission.
    pub fn submit_frame(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
    ) -> Result<(u64, wgpu::SubmissionIndex), SceneError> {
        let input = FrameInput {
            jitter_px: self.jitter_px,
            camera: *camera,
            time_s,
            walker,
        };
        self.renderer.prepare(&ctx.queue, &input);
        let frame = self.renderer_frame();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.renderer
            .record(&mut encoder, &self.color_view, &self.depth_view)?;
        let submission = ctx.queue.submit([encoder.finish()]);
        self.last = Some((*camera, time_s));
        self.captured = self.renderer.terrain_depth().map(|_| *camera);
        self.in_flight.push_back(submission.clone());
        while self.in_flight.len() > FRAMES_IN_FLIGHT {
            if let Some(oldest) = self.in_flight.pop_front() {
                let _ = ctx.device.poll(wgpu::PollType::Wait {
                    submission_index: Some(oldest),
                    timeout: None,
                });
            }
        }
        Ok((frame, submission))
    }

    /// Shifts the frames drawn from now on by `offset_px` pixels (see
    /// [`FrameInput::jitter_px`]; zero, the default, for none).
    pub fn set_jitter(&mut self, offset_px: glam::Vec2) {
        self.jitter_px = offset_px;
    }

    /// The number of the frame prepared last.
    fn renderer_frame(&self) -> u64 {
        self.renderer.frames_prepared().saturating_sub(1)
    }

    /// Reads the last frame back as an RGBA8 image (sRGB); waits for the GPU.
    pub fn read_image(&self, ctx: &GpuContext) -> Result<image::RgbaImage, SceneError> {
        let pixels = crate::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, &self.color)?;
        let (w, h) = self.size();
        Ok(image::RgbaImage::from_raw(w, h, pixels)
            .expect("readback returns width * height * 4 bytes"))
    }

    /// Reads the last frame's depth back (reverse-Z, row-major, top row first); waits for the
    /// GPU.
    pub fn read_depth(&self, ctx: &GpuContext) -> Result<Vec<f32>, SceneError> {
        let bytes = crate::gpu::read_texture_level(&ctx.device, &ctx.queue, &self.depth, 0, 0)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// Switches the capture of the terrain-only depth on or off (see
    /// [`Renderer::set_terrain_depth_capture`]): on for the frames whose grass coverage is
    /// measured ([`Scene::coverage`]), off for timed ones.
    pub fn set_coverage_capture(&mut self, on: bool) -> Result<(), SceneError> {
        self.renderer.set_terrain_depth_capture(on)?;
        if !on {
            self.captured = None;
        }
        Ok(())
    }

    /// The grass coverage of the last frame (drawn with the capture on): of the pixels where
    /// terrain within `max_distance_m` of the camera (along the view ray) is the nearest surface
    /// in the terrain-only depth, the fraction that something nearer covers in the final depth
    /// (see [`crate::tools::metrics::grass_coverage`]). Reads both depths back; waits for the
    /// GPU.
    pub fn coverage(
        &self,
        ctx: &GpuContext,
        max_distance_m: f32,
    ) -> Result<crate::tools::metrics::Coverage, SceneError> {
        let (Some(camera), Some(terrain)) = (self.captured, self.renderer.terrain_depth()) else {
            return Err(SceneError::NoCapture);
        };
        let read = |t: &wgpu::Texture| -> Result<Vec<f32>, SceneError> {
            let bytes = crate::gpu::read_texture_level(&ctx.device, &ctx.queue, t, 0, 0)?;
            Ok(bytemuck::pod_collect_to_vec(&bytes))
        };
        let (terrain, last) = (read(terrain)?, read(&self.depth)?);
        let (w, h) = self.size();
        let inv = camera.view_proj_relative(w as f32 / h as f32).inverse();
        Ok(crate::tools::metrics::grass_coverage(
            &terrain,
            &last,
            w,
            h,
            inv,
            max_distance_m,
        ))
    }
}
