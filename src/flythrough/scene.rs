//! A world made ready to draw: its tiles in the atlas, the terrain renderer and the targets.

use std::collections::HashMap;
use std::time::Instant;

use glam::DVec2;

use crate::flythrough::Camera;
use crate::gpu::{AtlasError, GpuContext, GpuTimer, PassTimes, ReadbackError, TileAtlas};
use crate::lod::{Frustum, TerrainLod, select_terrain};
use crate::terrain::{COLOR_FORMAT, DEPTH_FORMAT, TerrainRenderer, TileDraw};
use crate::world::{TileId, World, WorldError};

/// What stops a scene from being built or drawn.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// A tile or the manifest could not be read.
    #[error(transparent)]
    World(#[from] WorldError),
    /// A tile did not fit the atlas.
    #[error(transparent)]
    Atlas(#[from] AtlasError),
    /// The image could not be read back.
    #[error(transparent)]
    Readback(#[from] ReadbackError),
    /// The world has more stored tiles than the device's texture arrays can hold.
    #[error(
        "the world has {tiles} stored tiles but the adapter's texture arrays hold at most {limit} layers"
    )]
    TooManyTiles {
        /// Stored tiles.
        tiles: usize,
        /// The adapter's `max_texture_array_layers`.
        limit: u32,
    },
    /// The image size is zero or beyond the adapter's limit.
    #[error("image size {width}x{height} is not supported (1 to {limit} pixels a side)")]
    BadSize {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// The adapter's `max_texture_dimension_2d`.
        limit: u32,
    },
}

#[derive(Clone, Copy, Debug)]
struct Resident {
    layer: u32,
    min_h: f32,
    max_h: f32,
}

/// What one frame drew and what it cost.
#[derive(Clone, Debug)]
pub struct FrameStats {
    /// Terrain tiles drawn.
    pub tiles_drawn: u32,
    /// CPU time to select tiles and record and submit the frame, milliseconds.
    pub cpu_ms: f64,
    /// GPU time per pass (empty without timestamp queries).
    pub gpu: PassTimes,
}

/// A world on the GPU, with colour and depth targets of a fixed size.
pub struct Scene {
    /// The world being drawn.
    pub world: World,
    resident: HashMap<TileId, Resident>,
    renderer: TerrainRenderer,
    lod: TerrainLod,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    timer: GpuTimer,
    width: u32,
    height: u32,
    _atlas: TileAtlas,
}

impl Scene {
    /// Loads every stored tile of `world` into an atlas and prepares `width` x `height` targets.
    /// `progress(done, total)` is called as tiles load.
    pub fn new(
        ctx: &GpuContext,
        world: World,
        width: u32,
        height: u32,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<Self, SceneError> {
        let limits = ctx.device.limits();
        let max_dim = limits.max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max_dim || height > max_dim {
            return Err(SceneError::BadSize {
                width,
                height,
                limit: max_dim,
            });
        }
        let ids: Vec<TileId> = world.stored_tiles().collect();
        if ids.len() > limits.max_texture_array_layers as usize {
            return Err(SceneError::TooManyTiles {
                tiles: ids.len(),
                limit: limits.max_texture_array_layers,
            });
        }
        let pyramid = &world.manifest.pyramid;
        let atlas = TileAtlas::new(&ctx.device, pyramid.samples_per_side(), ids.len() as u32);
        let mut resident = HashMap::with_capacity(ids.len());
        let total = ids.len() as u64;
        for (layer, id) in ids.iter().enumerate() {
            let tile = world.load_tile(*id)?;
            atlas.upload(&ctx.queue, layer as u32, &tile)?;
            let (min_h, max_h) = tile
                .heights
                .iter()
                .fold((f32::MAX, f32::MIN), |(lo, hi), &h| (lo.min(h), hi.max(h)));
            resident.insert(
                *id,
                Resident {
                    layer: layer as u32,
                    min_h,
                    max_h,
                },
            );
            progress(layer as u64 + 1, total);
        }
        let max_level = pyramid.stored_levels.saturating_sub(1);
        let renderer = TerrainRenderer::new(&ctx.device, &world.manifest, &atlas, 4096);
        let target = |label, format, usage| {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = target(
            "color",
            COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = target(
            "depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        Ok(Self {
            world,
            resident,
            renderer,
            lod: TerrainLod {
                lod_factor: 2.0,
                max_level,
            },
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
            timer: GpuTimer::new(&ctx.device, &ctx.queue, ctx.timestamps, 8),
            width,
            height,
            _atlas: atlas,
        })
    }

    /// Width and height of the targets.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The terrain tiles a camera needs this frame.
    pub fn select(&self, camera: &Camera) -> Vec<TileId> {
        let aspect = self.width as f32 / self.height as f32;
        let frustum = Frustum::from_view_proj(camera.view_proj_relative(aspect));
        let resident = &self.resident;
        select_terrain(
            &self.world.manifest.pyramid,
            self.lod,
            camera.position,
            &frustum,
            &|id| {
                resident
                    .get(&id)
                    .map_or((-1e4, 1e5), |r| (r.min_h, r.max_h))
            },
        )
    }

    /// Draws one frame from `camera` and waits for its GPU times.
    pub fn render(&mut self, ctx: &GpuContext, camera: &Camera) -> FrameStats {
        let start = Instant::now();
        let pyramid = &self.world.manifest.pyramid;
        let eye = DVec2::new(camera.position.x, camera.position.y);
        let draws: Vec<TileDraw> = self
            .select(camera)
            .into_iter()
            .filter_map(|id| {
                let r = self.resident.get(&id)?;
                let morph_start = self.lod.morph_start(pyramid, id.level);
                Some(TileDraw::new(pyramid, id, id, r.layer, eye, morph_start))
            })
            .collect();
        let aspect = self.width as f32 / self.height as f32;
        let tiles = self.renderer.prepare(&ctx.queue, camera, aspect, &draws);

        self.timer.begin_frame();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("terrain"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: self.timer.render_pass("terrain"),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.renderer.draw(&mut pass, tiles);
        }
        self.timer.resolve(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        let gpu = self.timer.read(&ctx.device);
        FrameStats {
            tiles_drawn: tiles,
            cpu_ms,
            gpu,
        }
    }

    /// Reads the last frame back as an RGBA8 image (sRGB).
    pub fn read_image(&self, ctx: &GpuContext) -> Result<image::RgbaImage, SceneError> {
        let pixels = crate::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, &self.color)?;
        Ok(image::RgbaImage::from_raw(self.width, self.height, pixels)
            .expect("readback returns width * height * 4 bytes"))
    }
}
