//! A world made ready to draw: the tile service feeding the atlas, the derivation stage, the
//! terrain renderer and the targets.

use std::sync::Arc;
use std::time::Instant;

use glam::DVec2;

use crate::features::{Feature, Features};
use crate::flythrough::Camera;
use crate::gpu::{
    AtlasError, DeriveStage, GpuContext, GpuTimer, PassTimes, ReadbackError, TileAtlas,
};
use crate::grass::{GrassRenderer, GrassSettings, GrassStats, TileJob, WindBindings};
use crate::lod::{Frustum, GrassRings, Ring, RingSettings, TerrainLod, select_terrain};
use crate::stream::{
    DeriveParams, ResidencyPlan, ResidencyStats, ServiceConfig, TileService, TileSource, Want,
};
use crate::terrain::{COLOR_FORMAT, DEPTH_FORMAT, TerrainRenderer, TileDraw};
use crate::wind::{SwayConfig, SwayField, WindConfig, WindError, WindField};
use crate::world::{TileId, WindKey, World, WorldError};

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
    /// The wind scene asked for does not exist or does not fit.
    #[error(transparent)]
    Wind(#[from] WindError),
    /// The image could not be read back.
    #[error(transparent)]
    Readback(#[from] ReadbackError),
    /// The atlas slot count does not fit the adapter or the world.
    #[error(
        "an atlas of {slots} slots does not fit: it needs more slots than the world's {roots} \
         level-0 tiles and at most the adapter's {limit} texture array layers"
    )]
    AtlasSlots {
        /// Slots asked for.
        slots: u32,
        /// Level-0 tiles of the world (always resident).
        roots: u32,
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

/// Settings of a scene.
#[derive(Clone, Debug)]
pub struct SceneConfig {
    /// Limits of the tile service (atlas slots, cache bytes, loads in flight, budgets).
    pub service: ServiceConfig,
    /// Terrain tiles split while the camera is nearer than this many tile edges.
    pub lod_factor: f64,
    /// Derivation of child tiles.
    pub derive: DeriveParams,
    /// Grass rings, or none to ask for no grass tiles.
    pub grass: Option<RingSettings>,
    /// Terrain grid vertices every this many samples (1 = every sample).
    pub mesh_step: u32,
    /// Blade spacing of the high-LOD grass grid, metres.
    pub grass_spacing_m: f32,
    /// Blade segments at high and low LOD.
    pub grass_segments: [u32; 2],
    /// The wind scene of the manifest (default: `breeze`, else the manifest's wind); when
    /// `None` and `wind_keys` is not empty, the scenes of those keys in turn.
    pub wind_scene: Option<String>,
    /// Changes of wind scene over time (a camera path's `wind` keys).
    pub wind_keys: Vec<WindKey>,
    /// The switched-on features of the grass model.
    pub features: Features,
}

impl SceneConfig {
    /// Grass settings that follow the rings: blades the low grid drops fade out over the outer
    /// 30% of the high ring, and all blades thin out, dithered, over the last 20% of the view
    /// distance.
    pub fn grass_settings(&self, world: &World) -> Option<GrassSettings> {
        let rings = self.grass?;
        Some(GrassSettings {
            spacing_m: self.grass_spacing_m,
            tile_m: world.manifest.pyramid.tile_size_m(rings.level) as f32,
            high_radius_m: rings.high_radius_m as f32,
            lod_fade_m: 0.3 * rings.high_radius_m as f32,
            view_distance_m: rings.low_radius_m as f32,
            far_fade_m: 0.2 * rings.low_radius_m as f32,
            clump_m: 1.6,
            short_m: 0.3,
            seed: 0x9a55,
            segments: self.grass_segments,
        })
    }
}

impl SceneConfig {
    /// Defaults for `world`.
    pub fn for_world(world: &World) -> Self {
        Self {
            service: ServiceConfig::default(),
            lod_factor: 1.0,
            derive: DeriveParams::for_manifest(&world.manifest),
            grass: Some(RingSettings::for_pyramid(&world.manifest.pyramid)),
            mesh_step: 2,
            grass_spacing_m: 0.25,
            grass_segments: [7, 3],
            wind_scene: None,
            wind_keys: Vec::new(),
            features: Features::from(&world.manifest.features),
        }
    }
}

/// What one frame drew and what it cost.
#[derive(Clone, Debug)]
pub struct FrameStats {
    /// Terrain tiles drawn (each from its own data or an ancestor's).
    pub tiles_drawn: u32,
    /// Grass tiles in the high and low rings.
    pub grass_tiles: (u32, u32),
    /// CPU time to select tiles and record and submit the frame, milliseconds.
    pub cpu_ms: f64,
    /// GPU time per pass (empty without timestamp queries).
    pub gpu: PassTimes,
    /// The tile service's figures.
    pub residency: ResidencyStats,
    /// Grass: tiles, blades considered, culled by each test and drawn, per LOD.
    pub grass: GrassStats,
}

/// The grass with the wind it bends in.
struct GrassStage {
    renderer: GrassRenderer,
    wind: WindField,
    sway: SwayField,
}

/// A world on the GPU, with colour and depth targets of a fixed size.
pub struct Scene {
    /// The world being drawn.
    pub world: World,
    service: TileService,
    atlas: TileAtlas,
    derive: DeriveStage,
    renderer: TerrainRenderer,
    lod: TerrainLod,
    rings: Option<GrassRings>,
    grass: Option<GrassStage>,
    mesh_step: u32,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    timer: GpuTimer,
    time_s: Option<f64>,
    features: Features,
    width: u32,
    height: u32,
}

/// The tiles a frame wants, before residency.
struct Selection {
    terrain: Vec<TileId>,
    grass: Vec<(TileId, Ring, f64)>,
    wants: Vec<Want>,
}

impl Scene {
    /// Starts the tile service for `world` (its level-0 tiles are loaded here) and prepares
    /// `width` x `height` targets.
    pub fn new(
        ctx: &GpuContext,
        world: World,
        width: u32,
        height: u32,
        config: SceneConfig,
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
        config: SceneConfig,
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
        let pyramid = world.manifest.pyramid.clone();
        let [nx, ny] = pyramid.tiles_at(0);
        let slots = config.service.atlas_slots;
        if slots > limits.max_texture_array_layers || slots <= nx * ny {
            return Err(SceneError::AtlasSlots {
                slots,
                roots: nx * ny,
                limit: limits.max_texture_array_layers,
            });
        }
        let atlas = TileAtlas::new(&ctx.device, pyramid.samples_per_side(), slots);
        let (service, plan) = TileService::new(&pyramid, source, config.service)?;
        for (slot, tile) in &plan.uploads {
            atlas.upload(&ctx.queue, *slot, tile)?;
        }
        let derive = DeriveStage::new(
            &ctx.device,
            &ctx.queue,
            &pyramid,
            &config.derive,
            &atlas,
            config.service.derives_per_frame.max(1),
        );
        let mut renderer =
            TerrainRenderer::new(&ctx.device, &world.manifest, &atlas, 4096, config.mesh_step);
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
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        renderer.set_features(config.features);
        let grass = match config.grass_settings(&world) {
            Some(settings) => {
                let mut wind_config = match &config.wind_scene {
                    None if !config.wind_keys.is_empty() => {
                        WindConfig::from_keys(&world.manifest, &config.wind_keys)?
                    }
                    scene => WindConfig::from_scene(&world.manifest, scene.as_deref())?,
                };
                wind_config.sources = config.features.has(Feature::WindSources);
                wind_config.trail = config.features.has(Feature::Interaction);
                let wind = WindField::new(&ctx.device, &ctx.queue, &wind_config);
                let sway = SwayField::new(
                    &ctx.device,
                    SwayConfig::from_manifest(&world.manifest),
                    wind_config.cells,
                    wind.buffer(),
                );
                sway.reset(&ctx.queue);
                let capacity = crate::grass::estimate_capacity(&world, &settings)?;
                let g = GrassRenderer::new(
                    &ctx.device,
                    &ctx.queue,
                    &world.manifest,
                    &atlas,
                    &depth,
                    settings,
                    capacity,
                    WindBindings {
                        lookup: wind.lookup_uniform(),
                        cells: wind.buffer(),
                        sway: sway.buffer(),
                    },
                );
                g.commit_pool(&ctx.device, &ctx.queue);
                Some(GrassStage {
                    renderer: g,
                    wind,
                    sway,
                })
            }
            None => None,
        };
        Ok(Self {
            lod: TerrainLod {
                lod_factor: config.lod_factor,
                max_level: pyramid.max_level(),
            },
            rings: config.grass.map(GrassRings::new),
            grass,
            mesh_step: config.mesh_step,
            world,
            service,
            atlas,
            derive,
            renderer,
            color_view: color.create_view(&Default::default()),
            depth_view: depth.create_view(&Default::default()),
            color,
            timer: GpuTimer::new(&ctx.device, &ctx.queue, ctx.timestamps, 64),
            time_s: None,
            features: config.features,
            width,
            height,
        })
    }

    /// Width and height of the targets.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The tile service (for its figures and residency queries).
    pub fn service(&self) -> &TileService {
        &self.service
    }

    /// The grass tiles of the last frame and their rings.
    pub fn grass_rings(&self) -> Vec<(TileId, Ring)> {
        self.rings.as_ref().map_or(Vec::new(), |r| r.current())
    }

    /// The tile atlas.
    pub fn atlas(&self) -> &TileAtlas {
        &self.atlas
    }

    fn select(&mut self, camera: &Camera) -> Selection {
        let aspect = self.width as f32 / self.height as f32;
        let frustum = Frustum::from_view_proj(camera.view_proj_relative(aspect));
        let pyramid = &self.world.manifest.pyramid;
        let service = &self.service;
        let range = |id: TileId| service.height_range(id);
        let terrain = select_terrain(pyramid, self.lod, camera.position, &frustum, &range);
        let grass = match &mut self.rings {
            Some(r) => r.update(pyramid, camera.position, &range),
            None => Vec::new(),
        };
        // Priority: distance, doubled for what lies behind the camera.
        let forward = camera.forward();
        let priority = |id: TileId| {
            let b = pyramid.bounds(id);
            let (h0, h1) = range(id);
            let c = glam::DVec3::new(b.center().x, b.center().y, 0.5 * f64::from(h0 + h1));
            let to = c - camera.position;
            let d = to.length().max(1e-3);
            (d * (1.5 - 0.5 * forward.dot(to / d))) as f32
        };
        let mut wants: Vec<Want> = terrain
            .iter()
            .map(|&id| Want {
                id,
                priority: priority(id),
            })
            .collect();
        wants.extend(grass.iter().map(|&(id, _, _)| Want {
            id,
            priority: priority(id),
        }));
        Selection {
            terrain,
            grass,
            wants,
        }
    }

    /// Brings every tile `camera` wants into the atlas, waiting for loads (for tests and the
    /// first frame of a run, never inside the frame loop). Gives up after `timeout`; returns
    /// whether everything became resident.
    pub fn warm_up(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<bool, SceneError> {
        let start = Instant::now();
        loop {
            let sel = self.select(camera);
            let plan = self.service.update(&sel.wants);
            let busy = !plan.uploads.is_empty() || !plan.derives.is_empty();
            self.apply(ctx, plan, None)?;
            let stats = self.service.stats();
            if stats.resident == stats.desired {
                ctx.wait_idle();
                return Ok(true);
            }
            if start.elapsed() > timeout {
                return Ok(false);
            }
            if !busy {
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
        }
    }

    /// Uploads and derivations of a plan; derivations go into `encoder`, or a submission of
    /// their own.
    fn apply(
        &mut self,
        ctx: &GpuContext,
        plan: ResidencyPlan,
        encoder: Option<&mut wgpu::CommandEncoder>,
    ) -> Result<(), SceneError> {
        for (slot, tile) in &plan.uploads {
            self.atlas.upload(&ctx.queue, *slot, tile)?;
        }
        if plan.derives.is_empty() {
            return Ok(());
        }
        match encoder {
            Some(e) => {
                self.derive
                    .record(&ctx.queue, e, &self.atlas, &plan.derives, &mut self.timer);
            }
            None => {
                let mut e = ctx.device.create_command_encoder(&Default::default());
                let mut no_timer = GpuTimer::new(&ctx.device, &ctx.queue, false, 0);
                self.derive.record(
                    &ctx.queue,
                    &mut e,
                    &self.atlas,
                    &plan.derives,
                    &mut no_timer,
                );
                ctx.queue.submit([e.finish()]);
            }
        }
        Ok(())
    }

    /// Draws one frame from `camera` at the time of the last frame (the wind stands still).
    pub fn render(&mut self, ctx: &GpuContext, camera: &Camera) -> Result<FrameStats, SceneError> {
        let t = self.time_s.unwrap_or(0.0);
        self.render_at(ctx, camera, t)
    }

    /// Draws one frame from `camera` at `time_s` seconds (the wind and the sway advance by the
    /// time since the last frame, at most 5 s) and waits for its GPU times; the camera leaves
    /// the trail in the grass. Tiles that are not resident yet are drawn from their nearest
    /// resident ancestor.
    pub fn render_at(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
    ) -> Result<FrameStats, SceneError> {
        let walker = DVec2::new(camera.position.x, camera.position.y);
        self.render_frame(ctx, camera, time_s, Some(walker))
    }

    /// The name of the wind scene in effect at `time_s` (empty for the manifest's default wind
    /// or without grass).
    pub fn wind_scene_at(&self, time_s: f64) -> String {
        self.grass.as_ref().map_or(String::new(), |g| {
            g.wind.config().scene_at(time_s).name.to_owned()
        })
    }

    /// Like [`Scene::render_at`], with the trail left by a walker at `walker` (world xy,
    /// metres) instead of the camera; `None` leaves no trail this frame (the trail fades).
    pub fn render_frame(
        &mut self,
        ctx: &GpuContext,
        camera: &Camera,
        time_s: f64,
        walker: Option<DVec2>,
    ) -> Result<FrameStats, SceneError> {
        let start = Instant::now();
        let dt = self
            .time_s
            .map_or(0.0, |last| (time_s - last).clamp(0.0, 5.0)) as f32;
        self.time_s = Some(time_s);
        let sel = self.select(camera);
        let plan = self.service.update(&sel.wants);
        let residency = self.service.stats();

        let pyramid = &self.world.manifest.pyramid;
        let eye = DVec2::new(camera.position.x, camera.position.y);
        let draws: Vec<TileDraw> = sel
            .terrain
            .iter()
            .filter_map(|&id| {
                let (src, slot) = self.service.draw_source(id)?;
                let morph_start = self.lod.morph_start(pyramid, id.level);
                Some(TileDraw::new(
                    pyramid,
                    id,
                    src,
                    slot,
                    eye,
                    morph_start,
                    self.mesh_step,
                ))
            })
            .collect();
        let aspect = self.width as f32 / self.height as f32;
        let tiles = self.renderer.prepare(&ctx.queue, camera, aspect, &draws);

        // Grass tiles whose own data is resident, and whose box is in view.
        let grass_jobs = self.grass_jobs(camera, &sel.grass);
        let view_proj = camera.view_proj_relative(aspect);
        if let Some(g) = &mut self.grass {
            let ambient_speed = g.wind.config().ambient_at(time_s).speed_mps as f32;
            g.renderer
                .set_frame(time_s, ambient_speed, self.features, camera.position);
            g.renderer.set_camera(
                &ctx.queue,
                view_proj,
                camera.position.z as f32,
                camera.near_m,
            );
        }

        self.timer.begin_frame();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.apply(ctx, plan, Some(&mut encoder))?;
        if let Some(g) = &mut self.grass {
            g.wind.update(
                &ctx.queue,
                &mut encoder,
                camera.position,
                time_s,
                dt,
                walker,
                &mut self.timer,
            );
            let lookup = g.wind.lookup();
            g.sway
                .update(&ctx.queue, &mut encoder, &lookup, dt, &mut self.timer);
        }
        let color_attachment = |load| {
            Some(wgpu::RenderPassColorAttachment {
                view: &self.color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load,
                    store: wgpu::StoreOp::Store,
                },
            })
        };
        let depth_attachment = |load| {
            Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            })
        };
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("terrain depth"),
                color_attachments: &[],
                depth_stencil_attachment: depth_attachment(wgpu::LoadOp::Clear(0.0)),
                timestamp_writes: self.timer.render_pass("terrain_depth"),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.renderer.draw_depth(&mut pass, tiles);
        }
        if let Some(g) = &self.grass {
            g.renderer.hiz.record(&mut encoder, &mut self.timer);
        }
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("terrain"),
                color_attachments: &[color_attachment(wgpu::LoadOp::Clear(wgpu::Color::BLACK))],
                depth_stencil_attachment: depth_attachment(wgpu::LoadOp::Load),
                timestamp_writes: self.timer.render_pass("terrain"),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            self.renderer.draw(&mut pass, tiles);
        }
        let grass_tiles = match &self.grass {
            Some(g) => g.renderer.record(
                &ctx.queue,
                &mut encoder,
                &grass_jobs,
                &self.color_view,
                &self.depth_view,
                &mut self.timer,
            ),
            None => [0, 0],
        };
        self.timer.resolve(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        let gpu = self.timer.read(&ctx.device);
        let grass = match &self.grass {
            Some(g) => g.renderer.read_stats(&ctx.device, grass_tiles),
            None => GrassStats::default(),
        };
        let high = sel.grass.iter().filter(|g| g.1 == Ring::High).count() as u32;
        Ok(FrameStats {
            tiles_drawn: tiles,
            grass_tiles: (high, sel.grass.len() as u32 - high),
            cpu_ms,
            gpu,
            residency,
            grass,
        })
    }

    /// The generation jobs of the grass tiles that have their own data resident and are in view.
    fn grass_jobs(&self, camera: &Camera, grass: &[(TileId, Ring, f64)]) -> Vec<TileJob> {
        let pyramid = &self.world.manifest.pyramid;
        let aspect = self.width as f32 / self.height as f32;
        let frustum = Frustum::from_view_proj(camera.view_proj_relative(aspect));
        let mut jobs = Vec::new();
        for &(id, ring, _) in grass {
            let Some((src, slot)) = self.service.draw_source(id) else {
                continue;
            };
            if src != id {
                continue; // no grass until the tile's own data is there
            }
            let b = pyramid.bounds(id);
            let (h0, h1) = self.service.height_range(id);
            let tallest = 1.5f64;
            let min = glam::DVec3::new(b.min.x, b.min.y, f64::from(h0)) - camera.position;
            let max = glam::DVec3::new(b.max.x, b.max.y, f64::from(h1) + tallest) - camera.position;
            if !frustum.intersects_box(min.as_vec3(), max.as_vec3()) {
                continue;
            }
            let rel = b.min - DVec2::new(camera.position.x, camera.position.y);
            jobs.push(TileJob {
                origin: [rel.x as f32, rel.y as f32],
                cell: pyramid.cell_size_m(id.level) as f32,
                layer: slot,
                tile_x: id.x,
                tile_y: id.y,
                lod: u32::from(ring == Ring::Low),
                slot: 0,
            });
        }
        jobs
    }

    /// Reads the last frame back as an RGBA8 image (sRGB).
    pub fn read_image(&self, ctx: &GpuContext) -> Result<image::RgbaImage, SceneError> {
        let pixels = crate::gpu::read_texture_rgba8(&ctx.device, &ctx.queue, &self.color)?;
        Ok(image::RgbaImage::from_raw(self.width, self.height, pixels)
            .expect("readback returns width * height * 4 bytes"))
    }
}
