//! The frame: [`Renderer`], verdant's front door.
//!
//! A renderer draws one world into the caller's targets with the caller's device and queue:
//!
//! ```no_run
//! # fn demo(device: &wgpu::Device, queue: &wgpu::Queue, world: verdant::World,
//! #         color: &wgpu::TextureView, depth: &wgpu::TextureView) -> Result<(), verdant::RendererError> {
//! use verdant::{Camera, FrameInput, Renderer, RendererOptions};
//! let options = RendererOptions::new(
//!     &world,
//!     wgpu::TextureFormat::Rgba8UnormSrgb,
//!     wgpu::TextureFormat::Depth32Float,
//!     1280,
//!     720,
//! );
//! let mut renderer = Renderer::new(device, queue, world, options)?;
//! let camera = Camera::new(glam::DVec3::new(9000.0, 12000.0, 600.0), 30.0, -10.0);
//! renderer.prepare(queue, &FrameInput::new(camera, 0.0)); // streaming, uploads: no waits
//! let mut encoder = device.create_command_encoder(&Default::default());
//! renderer.record(&mut encoder, color, depth)?; // every pass of the frame
//! queue.submit([encoder.finish()]);
//! let stats = renderer.stats(); // a frame or two late, never a stall
//! # Ok(()) }
//! ```
//!
//! The depth target must have `RENDER_ATTACHMENT | TEXTURE_BINDING` usage (the Hi-Z pyramid
//! reads it) and one of [`DEPTH_FORMATS`]; the colour target any format that
//! [`crate::shaders::encode_srgb_for`] accepts. Depth is reverse-Z: the renderer clears it to 0
//! and keeps the nearer, greater values, so a caller that draws into the same targets afterwards
//! compares with `Greater`. The order of the frame's passes is [`Renderer::record`], top to
//! bottom.

mod hole_check;
mod readback;
mod view;

use hole_check::HoleCheck;
use readback::StatsRing;

pub use view::FrameView;

use std::sync::Arc;
use std::time::Instant;

use glam::{DVec2, Vec2};

use crate::aa::AntiAliasing;
use crate::aa::msaa::Msaa;
use crate::aa::taa::{Taa, TaaSettings};
use crate::camera::Camera;
use crate::features::{Feature, Features};
use crate::gpu::{GpuTimer, PassTimes, Targets};
use crate::grass::{GrassRenderer, GrassStats, TileJob, WindBindings};
use crate::lod::{GrassRings, Ring, TerrainLod, select_terrain};
use crate::stream::{
    AtlasError, DeriveJob, DeriveStage, ResidencyPlan, ResidencyStats, TileAtlas, TileService,
    TileSource, Want,
};
use crate::terrain::{TerrainRenderer, TileDraw};
use crate::wind::{SwayConfig, SwayField, WindConfig, WindError, WindField};
use crate::world::{TileId, World, WorldError};

mod config;
pub use config::{
    ConfigError, DEFAULT_INFILL_M, DEFAULT_MESH_STEP, GrassConfig, INFILL_RANGE_M,
    LOD_FACTOR_RANGE, MAX_MESH_STEP, NEAR_RANGE_M, RendererConfig, RendererOptions,
    SPACING_RANGE_M, WIDTH_SCALE_RANGE,
};

/// Depth formats the renderer draws into (the Hi-Z pyramid reads them as depth textures).
pub const DEPTH_FORMATS: [wgpu::TextureFormat; 2] = [
    wgpu::TextureFormat::Depth32Float,
    wgpu::TextureFormat::Depth24Plus,
];

/// Frames whose figures can be on their way back at once; a frame recorded while all of them
/// are still on their way gets no figures (counted in [`Renderer::stats_dropped`]).
pub const READBACK_SLOTS: usize = 4;

/// Delivered figures kept until taken ([`Renderer::take_stats`]); older ones are dropped.
pub const MAX_READY_STATS: usize = 2 * READBACK_SLOTS;

/// What stops a renderer from being built or a frame from being recorded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RendererError {
    /// A setting is out of its range ([`RendererConfig::validate`]).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A tile or the manifest could not be read.
    #[error(transparent)]
    World(#[from] WorldError),
    /// A plant type's mesh could not be made.
    #[error(transparent)]
    Plant(#[from] crate::plants::PlantError),
    /// A tile did not fit the atlas.
    #[error(transparent)]
    Atlas(#[from] AtlasError),
    /// The wind scene asked for does not exist or does not fit.
    #[error(transparent)]
    Wind(#[from] WindError),
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
    /// The target size is zero or beyond the adapter's limit.
    #[error("image size {width}x{height} is not supported (1 to {limit} pixels a side)")]
    BadSize {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// The adapter's `max_texture_dimension_2d`.
        limit: u32,
    },
    /// The target size needs a buffer larger than the adapter allows (the grass's Hi-Z pyramid
    /// is one storage buffer bound whole, about 5.3 bytes a pixel).
    #[error(
        "image size {width}x{height} needs a {what} of {bytes} bytes, more than this adapter's \
         {limit_name} of {limit} bytes: choose a smaller size (about {max_pixels} pixels at most)"
    )]
    SizeBeyondLimit {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// The buffer, in words (e.g. `Hi-Z pyramid storage buffer`).
        what: &'static str,
        /// Its size at this target size.
        bytes: u64,
        /// The adapter limit it exceeds (e.g. `max_storage_buffer_binding_size`).
        limit_name: &'static str,
        /// That limit.
        limit: u64,
        /// Roughly the most pixels (width times height) that fit.
        max_pixels: u64,
    },
    /// The CPU tile cache cannot hold a single tile, so no tile could ever be uploaded.
    #[error(
        "a CPU tile cache of {bytes} bytes cannot hold one tile of this world ({tile_bytes} \
         bytes): give it at least {min_mib} MiB"
    )]
    CacheTooSmall {
        /// The cache's ceiling asked for.
        bytes: u64,
        /// Bytes of one decoded tile.
        tile_bytes: u64,
        /// The smallest ceiling in MiB that holds one tile.
        min_mib: u64,
    },
    /// The colour format is not one the renderer draws into.
    #[error(
        "colour format {0:?} is not supported (use an 8-bit RGBA/BGRA format, sRGB or not, \
         Rgb10a2Unorm, Rgba16Unorm, Rgba16Float, Rgba32Float or Rg11b10Ufloat)"
    )]
    ColorFormat(wgpu::TextureFormat),
    /// The depth format is not one the renderer draws into.
    #[error("depth format {0:?} is not supported (use Depth32Float or Depth24Plus)")]
    DepthFormat(wgpu::TextureFormat),
    /// A target given to [`Renderer::record`] does not match the renderer's targets.
    #[error("the {which} target is {found}, but the renderer was made for {expected}")]
    Target {
        /// `"colour"` or `"depth"`.
        which: &'static str,
        /// What the target is.
        found: String,
        /// What the renderer expects.
        expected: String,
    },
    /// [`Renderer::record`] was called without a [`Renderer::prepare`] before it.
    #[error("record was called without prepare: call prepare once before each record")]
    NotPrepared,
    /// The capture of the terrain-only depth was asked for with a depth format whose texels
    /// cannot be copied (use Depth32Float).
    #[error(
        "the terrain-only depth cannot be captured from a {0:?} target: its texels cannot be \
         copied (use Depth32Float)"
    )]
    DepthCapture(wgpu::TextureFormat),
}

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
    /// The frame's number (0 for the first [`Renderer::prepare`]).
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
    /// Plants: cells considered, plants culled by each test and drawn; `None` when the frame
    /// drew none (no plant types, or the `plants` feature off).
    pub plants: Option<crate::plants::PlantStats>,
}

/// How long a warm-up waits with nothing loading, uploaded or derived before it gives up.
pub const WARM_UP_STALL: std::time::Duration = std::time::Duration::from_secs(5);

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

/// The grass with the wind it bends in.
struct GrassStage {
    renderer: GrassRenderer,
    wind: WindField,
    sway: SwayField,
    /// The plants among the grass (a world with `[[plant_types]]`).
    plants: Option<crate::plants::PlantRenderer>,
}

/// What [`Renderer::prepare`] worked out for [`Renderer::record`].
struct Prepared {
    input: FrameInput,
    dt: f32,
    derives: Vec<DeriveJob>,
    terrain_tiles: u32,
    grass_jobs: Vec<TileJob>,
    /// The atlas slots the frame reads and the tiles it expects there (terrain draws and
    /// grass jobs), checked against the atlas on the GPU.
    reads: Vec<(u32, TileId)>,
    stats: FrameStats,
    cpu_s: f64,
}

/// The tiles a frame wants, before residency.
struct Selection {
    terrain: Vec<TileId>,
    grass: Vec<(TileId, Ring, f64)>,
    wants: Vec<Want>,
}

/// A world's terrain and grass, drawn into the caller's targets. See the module docs.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    world: World,
    service: TileService,
    atlas: TileAtlas,
    derive: DeriveStage,
    terrain: TerrainRenderer,
    contact_shadows: crate::terrain::contact_shadow::ContactShadowPass,
    lod: TerrainLod,
    rings: Option<GrassRings>,
    grass: Option<GrassStage>,
    mesh_step: u32,
    targets: Targets,
    features: Features,
    timer: GpuTimer,
    readback: StatsRing,
    holes: HoleCheck,
    skip_uploads: u32,
    time_s: Option<f64>,
    frame: u64,
    prepared: Option<Prepared>,
    /// A copy of the depth target after the terrain colour passes, when asked for
    /// ([`Renderer::set_terrain_depth_capture`]).
    terrain_depth: Option<wgpu::Texture>,
    /// The temporal anti-aliasing, when on: the frame is drawn into its texture and resolved
    /// into the caller's colour target.
    taa: Option<Taa>,
    /// The multisampling of the grass, when on: terrain and sky are drawn into its texture,
    /// the blades into its multisampled targets, resolved into the caller's.
    msaa: Option<Msaa>,
}

impl Renderer {
    /// A renderer of `world` for targets of `options`' formats and size. Starts the tile
    /// service (the level-0 tiles are loaded here, waiting for them) and builds every pipeline.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        world: World,
        options: RendererOptions,
    ) -> Result<Self, RendererError> {
        let source = Arc::new(world.clone());
        Self::with_source(device, queue, world, source, options)
    }

    /// Like [`Renderer::new`], with tiles from `source` instead of the world's files (another
    /// store, or loads made slow or failing on purpose in tests).
    pub fn with_source(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        world: World,
        source: Arc<dyn TileSource>,
        options: RendererOptions,
    ) -> Result<Self, RendererError> {
        let config = options.config;
        config.validate()?;
        let targets = Targets {
            color_format: options.color_format,
            depth_format: options.depth_format,
            width: options.width,
            height: options.height,
        };
        check_formats(&targets)?;
        let grass_on = config.grass_rings.is_some();
        check_size(device, targets.width, targets.height, grass_on)?;
        let limits = device.limits();
        let pyramid = world.manifest.pyramid.clone();
        let [nx, ny] = pyramid.tiles_at(0);
        let slots = config.service.atlas_slots;
        // The terrain's G-buffer names a slot in 12 bits.
        let most = limits
            .max_texture_array_layers
            .min(crate::terrain::GBUFFER_MAX_SLOTS);
        if slots > most || slots <= nx * ny {
            return Err(RendererError::AtlasSlots {
                slots,
                roots: nx * ny,
                limit: most,
            });
        }
        let tile_bytes = crate::world::TileData::byte_size_for(pyramid.samples_per_side());
        if config.service.cache_bytes < tile_bytes {
            return Err(RendererError::CacheTooSmall {
                bytes: config.service.cache_bytes,
                tile_bytes,
                min_mib: tile_bytes.div_ceil(1 << 20),
            });
        }
        let atlas = TileAtlas::new(device, pyramid.samples_per_side(), slots);
        let (service, plan) = TileService::new(&pyramid, source, config.service)?;
        for (slot, tile) in &plan.uploads {
            atlas.upload(queue, *slot, tile)?;
        }
        let derive = DeriveStage::new(
            device,
            queue,
            &pyramid,
            &config.derive,
            &atlas,
            config.service.derives_per_frame,
        );
        let mut terrain = TerrainRenderer::new(
            device,
            &world.manifest,
            &atlas,
            &targets,
            4096,
            config.mesh_step,
        );
        terrain.set_features(config.features);
        terrain.set_grass(config.grass_settings(&world).as_ref());
        let contact_shadows = crate::terrain::contact_shadow::ContactShadowPass::new(
            device,
            &targets,
            crate::terrain::contact_shadow::ContactShadows::default(),
        );
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
                let wind = WindField::new(device, queue, &wind_config);
                let sway = SwayField::new(
                    device,
                    SwayConfig::from_manifest(&world.manifest),
                    wind_config.cells,
                    wind.buffer(),
                );
                sway.reset(queue);
                let capacity = match config.grass.capacity {
                    Some(c) => c,
                    None => crate::grass::estimate_capacity(&world, &settings)?,
                };
                let renderer = GrassRenderer::new(
                    device,
                    queue,
                    &world.manifest,
                    &atlas,
                    &targets,
                    settings,
                    capacity,
                    WindBindings {
                        lookup: wind.lookup_uniform(),
                        cells: wind.buffer(),
                        sway: sway.buffer(),
                    },
                );
                renderer.commit_pool(device, queue);
                let plants = if world.manifest.plant_types.is_empty() {
                    None
                } else {
                    let set = crate::plants::PlantSet::build(&world.manifest, &world.dir)?;
                    let [_, view] = [
                        settings.view_distance_m - settings.far_fade_m,
                        settings.view_distance_m,
                    ];
                    Some(crate::plants::PlantRenderer::new(
                        device,
                        queue,
                        &world.manifest,
                        &set,
                        &atlas,
                        &targets,
                        &renderer.hiz,
                        settings.tile_m,
                        crate::plants::PlantSettings {
                            view_m: [0.8 * view, view],
                            seed: settings.seed,
                            ..config.plants
                        },
                        crate::plants::renderer::PlantWindBindings {
                            lookup: wind.lookup_uniform(),
                            cells: wind.buffer(),
                        },
                    ))
                };
                Some(GrassStage {
                    renderer,
                    wind,
                    sway,
                    plants,
                })
            }
            None => None,
        };
        let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let timer = GpuTimer::new(device, queue, timestamps, 64);
        let readback = StatsRing::new(device, timer.capacity_bytes());
        let holes = HoleCheck::new(device, &atlas);
        let taa = (config.aa == AntiAliasing::Taa)
            .then(|| Taa::new(device, &targets, TaaSettings::default()));
        let msaa = (config.aa == AntiAliasing::Msaa && grass.is_some())
            .then(|| Msaa::new(device, &targets));
        let mut grass = grass;
        if let (Some(g), Some(_)) = (&mut grass, &msaa) {
            g.renderer.set_samples(device, crate::aa::msaa::SAMPLES);
            if let Some(p) = &mut g.plants {
                p.set_samples(device, crate::aa::msaa::SAMPLES);
            }
        }
        Ok(Self {
            device: device.clone(),
            queue: queue.clone(),
            lod: TerrainLod {
                lod_factor: config.lod_factor,
                max_level: pyramid.max_level(),
            },
            rings: config.grass_rings.map(GrassRings::new),
            grass,
            mesh_step: config.mesh_step,
            world,
            service,
            atlas,
            derive,
            terrain,
            contact_shadows,
            targets,
            features: config.features,
            timer,
            readback,
            holes,
            skip_uploads: 0,
            time_s: None,
            frame: 0,
            prepared: None,
            terrain_depth: None,
            taa,
            msaa,
        })
    }

    /// The world being drawn.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// Frames prepared so far (the next frame's number).
    pub fn frames_prepared(&self) -> u64 {
        self.frame
    }

    /// The targets' formats and size.
    pub fn targets(&self) -> Targets {
        self.targets
    }

    /// The tile service (for its figures and residency queries).
    pub fn service(&self) -> &TileService {
        &self.service
    }

    /// The tile atlas.
    pub fn atlas(&self) -> &TileAtlas {
        &self.atlas
    }

    /// GPU memory of the plants' instance pool, bytes (`None` without plants): fixed when the
    /// renderer is made, whatever the view.
    pub fn plant_pool_bytes(&self) -> Option<u64> {
        self.grass
            .as_ref()
            .and_then(|g| g.plants.as_ref())
            .map(|p| p.pool_bytes())
    }

    /// The grass tiles of the last frame and their rings.
    pub fn grass_rings(&self) -> Vec<(TileId, Ring)> {
        self.rings.as_ref().map_or(Vec::new(), |r| r.current())
    }

    /// The name of the wind scene in effect at `time_s` (empty for the manifest's default wind
    /// or without grass).
    pub fn wind_scene_at(&self, time_s: f64) -> String {
        self.grass.as_ref().map_or(String::new(), |g| {
            g.wind.config().scene_at(time_s).name.to_owned()
        })
    }

    /// Shows (or hides) the overlay of tile levels (a hue per level) and grass rings (circles
    /// at the high and low rings' radii) on the terrain.
    pub fn set_overlay(&mut self, on: bool) {
        let radii = self.rings.as_ref().map_or([0.0; 2], |r| {
            let s = &r.settings;
            [s.high_radius_m as f32, s.low_radius_m as f32]
        });
        self.terrain.set_overlay(on, radii);
    }

    /// Changes the wind to the manifest's scene `name` from `time_s` on, the ambient wind
    /// blending over `blend_s` seconds (`time_s` at or after the last change's).
    pub fn change_wind_scene(
        &mut self,
        name: &str,
        time_s: f64,
        blend_s: f64,
    ) -> Result<(), RendererError> {
        let Some(g) = &mut self.grass else {
            return Ok(());
        };
        let next = WindConfig::from_scene(&self.world.manifest, Some(name))?;
        g.wind.change_scene(crate::wind::SceneChange {
            at_s: time_s,
            blend_s,
            scene: next.scene,
            ambient: next.ambient,
            source_list: next.source_list,
        });
        Ok(())
    }

    /// Switches the capture of the terrain-only depth on or off (off by default, costing
    /// nothing). While on, each [`Renderer::record`] copies the depth target after the terrain
    /// colour passes, before any grass, into a texture of the renderer's
    /// ([`Renderer::terrain_depth`]); the depth target then needs `COPY_SRC` usage as well.
    /// Refused for a depth format that cannot be copied (Depth24Plus).
    pub fn set_terrain_depth_capture(&mut self, on: bool) -> Result<(), RendererError> {
        let format = self.targets.depth_format;
        if !on {
            self.terrain_depth = None;
        } else if format
            .block_copy_size(Some(wgpu::TextureAspect::DepthOnly))
            .is_none()
        {
            return Err(RendererError::DepthCapture(format));
        } else if self.terrain_depth.is_none() {
            self.terrain_depth = Some(self.depth_copy());
        }
        Ok(())
    }

    /// The terrain-only depth of the last frame recorded with the capture on (see
    /// [`Renderer::set_terrain_depth_capture`]); `None` while it is off.
    pub fn terrain_depth(&self) -> Option<&wgpu::Texture> {
        self.terrain_depth.as_ref()
    }

    fn depth_copy(&self) -> wgpu::Texture {
        crate::gpu::target_texture(
            &self.device,
            "terrain-only depth",
            self.targets.depth_format,
            wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
            (self.targets.width, self.targets.height),
        )
    }

    /// Switches anti-aliasing to `aa` from the next frame (a temporal method starts its
    /// history from scratch).
    pub fn set_anti_aliasing(&mut self, aa: AntiAliasing) {
        if aa == self.anti_aliasing() {
            return;
        }
        self.taa = (aa == AntiAliasing::Taa)
            .then(|| Taa::new(&self.device, &self.targets, TaaSettings::default()));
        self.msaa = (aa == AntiAliasing::Msaa && self.grass.is_some())
            .then(|| Msaa::new(&self.device, &self.targets));
        let samples = if self.msaa.is_some() {
            crate::aa::msaa::SAMPLES
        } else {
            1
        };
        if let Some(g) = &mut self.grass {
            g.renderer.set_samples(&self.device, samples);
            if let Some(p) = &mut g.plants {
                p.set_samples(&self.device, samples);
            }
        }
    }

    /// How the frame is anti-aliased (multisampling asked for without grass is off: it
    /// multisamples the blades only).
    pub fn anti_aliasing(&self) -> AntiAliasing {
        if self.taa.is_some() {
            AntiAliasing::Taa
        } else if self.msaa.is_some() {
            AntiAliasing::Msaa
        } else {
            AntiAliasing::Off
        }
    }

    /// Follows a resize of the targets (the next frame draws at the new size).
    pub fn resize(&mut self, width: u32, height: u32) -> Result<(), RendererError> {
        check_size(&self.device, width, height, self.grass.is_some())?;
        if (width, height) == (self.targets.width, self.targets.height) {
            return Ok(());
        }
        self.targets.width = width;
        self.targets.height = height;
        if self.terrain_depth.is_some() {
            self.terrain_depth = Some(self.depth_copy());
        }
        self.terrain.resize(&self.device, width, height);
        self.contact_shadows.resize(&self.device, width, height);
        if let Some(taa) = &mut self.taa {
            taa.resize(&self.device, width, height);
        }
        if let Some(msaa) = &mut self.msaa {
            msaa.resize(&self.device, width, height);
        }
        if let Some(g) = &mut self.grass {
            g.renderer.resize(&self.device, &self.queue, width, height);
            if let Some(p) = &mut g.plants {
                p.resize(&self.device, &g.renderer.hiz);
            }
        }
        Ok(())
    }

    fn select(&mut self, view: &FrameView) -> Selection {
        let camera = &view.camera;
        let frustum = view.frustum;
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
        let wants = terrain
            .iter()
            .copied()
            .chain(grass.iter().map(|g| g.0))
            .map(|id| Want {
                id,
                priority: priority(id),
            })
            .collect();
        Selection {
            terrain,
            grass,
            wants,
        }
    }

    /// Brings every tile `camera` wants into the atlas, waiting for loads and for the GPU: for
    /// the first frame of a run or a teleport, never inside a frame loop. Gives up after
    /// `timeout`; returns whether everything became resident. See [`Renderer::warm_up_report`]
    /// for what is missing when not.
    pub fn warm_up(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<bool, RendererError> {
        Ok(self.warm_up_report(camera, timeout)?.missing.is_empty())
    }

    /// Like [`Renderer::warm_up`], and says which tiles are missing and why. Stops early, without
    /// waiting for `timeout`, once every missing tile is kept out by a failed load (its own or
    /// that of the stored ancestor it is derived from), or when nothing has moved for
    /// [`WARM_UP_STALL`].
    pub fn warm_up_report(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<WarmUp, RendererError> {
        let start = Instant::now();
        self.flush_unrecorded();
        let mut last_change = Instant::now();
        let mut last_resident = u32::MAX;
        let view = FrameView::new(camera, Vec2::ZERO, self.targets.width, self.targets.height);
        loop {
            let sel = self.select(&view);
            let plan = self.service.update(&sel.wants);
            let busy = !plan.uploads.is_empty() || !plan.derives.is_empty();
            let derives = self.upload(plan);
            self.submit_derives(&derives);
            let stats = self.service.stats();
            if stats.resident == stats.desired {
                let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
                return Ok(WarmUp::default());
            }
            if busy || stats.resident != last_resident || stats.stream.in_flight > 0 {
                last_change = Instant::now();
                last_resident = stats.resident;
            }
            let missing: Vec<TileId> = sel
                .wants
                .iter()
                .map(|w| w.id)
                .filter(|&id| !self.service.is_resident(id))
                .collect();
            let all_failed = missing
                .iter()
                .all(|&id| self.service.blocked_by(id).is_some());
            let stalled = last_change.elapsed() > WARM_UP_STALL;
            if all_failed || stalled || start.elapsed() > timeout {
                let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
                let why_else = if stalled {
                    "nothing was loading".to_owned()
                } else {
                    format!("not resident after {:.0} s", timeout.as_secs_f64())
                };
                let missing = missing
                    .into_iter()
                    .map(|tile| {
                        let reason = match self.service.blocked_by(tile) {
                            Some((t, e)) if t == tile => format!("failed to load: {e}"),
                            Some((t, e)) => format!(
                                "derived from tile L{} {}_{}, which failed to load: {e}",
                                t.level, t.x, t.y
                            ),
                            None => why_else.clone(),
                        };
                        MissingTile { tile, reason }
                    })
                    .collect();
                return Ok(WarmUp { missing });
            }
            if !busy {
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
        }
    }

    /// Records and submits derivations on their own (a batch a submission: each batch's jobs
    /// are written to the same buffer), without waiting.
    fn submit_derives(&mut self, derives: &[DeriveJob]) {
        let batch = self.derive.batch().max(1) as usize;
        let mut no_timer = GpuTimer::new(&self.device, &self.queue, false, 0);
        for chunk in derives.chunks(batch) {
            let mut e = self.device.create_command_encoder(&Default::default());
            self.derive
                .record(&self.queue, &mut e, &self.atlas, chunk, &mut no_timer);
            self.queue.submit([e.finish()]);
        }
    }

    /// Derivations of a frame that was prepared and never recorded: the tile service counts
    /// those tiles as resident, so they are derived now.
    fn flush_unrecorded(&mut self) {
        if let Some(stale) = self.prepared.take() {
            self.submit_derives(&stale.derives);
        }
    }

    /// Uploads the plan's decoded tiles to the atlas; returns the derivations to record.
    /// A tile that does not fit its slot (its size disagrees with the atlas) is logged and left
    /// out, and the others go on: the slot keeps an identity that the hole check does not
    /// accept, so the tile counts as a hole and is drawn from its ancestor.
    fn upload(&mut self, plan: ResidencyPlan) -> Vec<DeriveJob> {
        for (slot, tile) in &plan.uploads {
            if self.skip_uploads > 0 {
                // A fault injected by a test: the slot is given to the tile, its data never
                // reaches the GPU.
                self.skip_uploads -= 1;
                self.atlas.claim(*slot, tile.id);
                continue;
            }
            if let Err(e) = self.atlas.upload(&self.queue, *slot, tile) {
                log::warn!("tile {:?} left out of the atlas: {e}", tile.id);
            }
        }
        plan.derives
    }

    /// For tests of the hole count: the next `n` uploads are planned (their slots given to
    /// their tiles) but never written to the GPU, as a lost upload would be.
    #[doc(hidden)]
    pub fn skip_next_uploads(&mut self, n: u32) {
        self.skip_uploads = n;
    }

    /// Gets the frame of `input` ready: collects figures of earlier frames that have come back,
    /// selects the tiles the camera needs, plans residency with the tile service (loads are
    /// requested, finished ones uploaded), and writes the frame's uniforms. Never waits for the
    /// GPU or for loads: a tile that is not resident is drawn from its nearest resident
    /// ancestor.
    pub fn prepare(&mut self, queue: &wgpu::Queue, input: &FrameInput) {
        let start = Instant::now();
        self.collect_stats();
        self.flush_unrecorded();
        // The view, once for every stage: the caller's jitter plus the temporal
        // anti-aliasing's.
        let jitter = input.jitter_px + self.taa.as_ref().map_or(Vec2::ZERO, |t| t.next_jitter());
        let view = FrameView::new(
            &input.camera,
            jitter,
            self.targets.width,
            self.targets.height,
        );
        if let Some(taa) = &mut self.taa {
            taa.prepare(&self.queue, view.unjittered, view.eye, view.forward);
        }
        let camera = view.camera;
        let dt = self
            .time_s
            .map_or(0.0, |last| (input.time_s - last).clamp(0.0, 5.0)) as f32;
        self.time_s = Some(input.time_s);
        let sel = self.select(&view);
        let plan = self.service.update(&sel.wants);
        let residency = self.service.stats();
        let derives = self.upload(plan);

        let pyramid = &self.world.manifest.pyramid;
        let eye = camera.position.truncate();
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
        // The root tiles (always resident) carry the long shadow rays.
        let [rx, ry] = pyramid.root_tiles;
        let roots: Option<Vec<(u32, TileId)>> = (0..ry)
            .flat_map(|y| (0..rx).map(move |x| TileId::new(0, x, y)))
            .take(crate::terrain::MAX_ROOT_TILES + 1)
            .map(|id| match self.service.draw_source(id) {
                Some((src, slot)) if src == id => Some((slot, id)),
                _ => None,
            })
            .collect();
        let roots = roots.filter(|r| r.len() <= crate::terrain::MAX_ROOT_TILES);
        let root_slots: Option<Vec<u32>> = roots.as_ref().map(|r| r.iter().map(|p| p.0).collect());
        self.terrain.set_root_slots(root_slots.as_deref());
        let terrain_tiles = self
            .terrain
            .prepare(queue, view.view_proj, camera.position, &draws);
        let grass_jobs = self.grass_jobs(&view, &sel.grass);
        let grass_level = self.rings.as_ref().map_or(0, |r| r.settings.level);
        let reads: Vec<(u32, TileId)> = sel
            .terrain
            .iter()
            .filter_map(|&id| self.service.draw_source(id).map(|(src, slot)| (slot, src)))
            .chain(
                grass_jobs
                    .iter()
                    .map(|j| (j.layer, TileId::new(grass_level, j.tile_x, j.tile_y))),
            )
            .chain(roots.into_iter().flatten())
            .collect();
        self.contact_shadows.prepare(
            queue,
            view.view_proj,
            crate::terrain::sun_direction(&self.world.manifest.sky),
            (self.targets.width, self.targets.height),
        );
        if let Some(g) = &mut self.grass {
            let ambient_speed = g.wind.config().ambient_at(input.time_s).speed_mps as f32;
            g.renderer
                .set_frame(input.time_s, ambient_speed, self.features, camera.position);
            g.renderer.set_camera(
                queue,
                view.view_proj,
                &view.frustum,
                camera.position.z as f32,
                camera.near_m,
            );
            if let Some(p) = &mut g.plants {
                p.set_frame(
                    queue,
                    input.time_s,
                    self.features,
                    camera.position,
                    view.view_proj,
                    &view.frustum,
                    camera.near_m,
                );
            }
        }
        let high = sel.grass.iter().filter(|g| g.1 == Ring::High).count() as u32;
        self.prepared = Some(Prepared {
            input: *input,
            dt,
            derives,
            terrain_tiles,
            grass_jobs,
            reads,
            stats: FrameStats {
                frame: self.frame,
                tiles_drawn: terrain_tiles,
                grass_tiles: (high, sel.grass.len() as u32 - high),
                residency,
                ..Default::default()
            },
            cpu_s: start.elapsed().as_secs_f64(),
        });
        self.frame += 1;
    }

    /// Records every pass of the prepared frame into `encoder`, drawing into `color` and
    /// `depth` (cleared here); submits nothing and waits for nothing. The frame, top to bottom:
    ///
    /// 1. child tiles derived from their parents (compute, `stream_derive.wgsl`);
    /// 2. the wind field and the sway springs (compute, `wind_field.wgsl`, `wind_sway.wgsl`);
    /// 3. the terrain's G-buffer pass (`terrain_gbuffer.wgsl`): its depth, and per pixel where in the
    ///    atlas its ground is;
    /// 4. the Hi-Z pyramid from that depth (compute, `grass_hiz.wgsl`);
    /// 5. the terrain's colour and the sky, deferred: every pixel's shading, terrain and sky,
    ///    with the terrain's shadows (compute, `terrain_shade.wgsl`), then its composite into
    ///    the colour target (`terrain_composite.wgsl`);
    /// 6. grass in batches of 4 jobs (a tile, or a near tile's blades within the near radius):
    ///    generation and culling, then the wind on each blade (compute, `grass_generate.wgsl`,
    ///    `grass_wind.wgsl`), then one indirect draw per job (`grass_draw.wgsl`);
    ///    With multisampling (`aa_msaa.wgsl`), the frame so far is copied into every sample of
    ///    the stage's multisampled targets first, the blades drawn there with alpha to
    ///    coverage, and colour and depth resolved into `color` and `depth` after;
    /// 7. contact shadows, with the `shadows` feature: each pixel's factor, less than 1 where a
    ///    short ray toward the sun is blocked in the depth buffer (compute), then the colour
    ///    multiplied by it (a full-screen pass; both `terrain_contact_shadow.wgsl`);
    /// 8. with temporal anti-aliasing (passes 5-7 then draw into its own texture, with a
    ///    jittered projection): the frame folded into the reprojected history (compute,
    ///    `aa_taa.wgsl`), and the result written into `color`;
    /// 9. the pass timestamps and grass counters copied into the readback ring, mapped when the
    ///    encoder's work is submitted ([`Renderer::stats`]).
    pub fn record(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RendererError> {
        let start = Instant::now();
        self.check_targets(color, depth)?;
        let Some(frame) = self.prepared.take() else {
            return Err(RendererError::NotPrepared);
        };
        self.timer.begin_frame();

        // 1. Child tiles.
        if !frame.derives.is_empty() {
            self.derive.record(
                &self.queue,
                encoder,
                &self.atlas,
                &frame.derives,
                &mut self.timer,
            );
        }
        // Every atlas read of the frame against what its slot holds on the GPU.
        let cpu_holes = self
            .holes
            .record(&self.queue, encoder, &self.atlas, &frame.reads);
        // 2. Wind and sway.
        if let Some(g) = &mut self.grass {
            let camera = &frame.input.camera;
            g.wind.update(
                &self.queue,
                encoder,
                camera.position,
                frame.input.time_s,
                frame.dt,
                frame.input.walker,
                &mut self.timer,
            );
            let lookup = g.wind.lookup();
            g.sway
                .update(&self.queue, encoder, &lookup, frame.dt, &mut self.timer);
        }
        // 3. Terrain: depth and G-buffer.
        self.terrain
            .record_gbuffer(encoder, depth, frame.terrain_tiles, &mut self.timer);
        // 4. Hi-Z.
        if let Some(g) = &mut self.grass {
            g.renderer
                .hiz
                .record(&self.device, encoder, depth.texture(), &mut self.timer);
        }
        // With anti-aliasing the terrain and sky are drawn into its texture: temporal
        // anti-aliasing resolves the whole frame into `color` (8.), multisampling copies it
        // into its multisampled targets for the grass and resolves those into `color` (6.).
        let target = match (&self.taa, &self.msaa) {
            (Some(t), _) => Some(t.scene_view().clone()),
            (_, Some(m)) => Some(m.scene_view().clone()),
            _ => None,
        };
        let scene = target.as_ref().unwrap_or(color);
        // 5. Terrain colour and sky: shading (compute), composite into the frame.
        self.terrain
            .record_shade(&self.device, encoder, scene, depth, &mut self.timer);
        if let Some(copy) = &self.terrain_depth {
            encoder.copy_texture_to_texture(
                depth.texture().as_image_copy(),
                copy.as_image_copy(),
                copy.size(),
            );
        }
        // 6. Grass (multisampled: into every sample of the frame so far, then resolved).
        let mut stats = frame.stats;
        stats.residency.holes += cpu_holes;
        if let Some(msaa) = &mut self.msaa {
            msaa.record_expand(&self.device, encoder, depth, &mut self.timer);
        }
        let (grass_color, grass_depth) = match &self.msaa {
            Some(m) => (m.color_view(), m.depth_view()),
            None => (scene, depth),
        };
        if let Some(g) = &self.grass {
            stats.grass.tiles = g.renderer.record(
                &self.queue,
                encoder,
                &frame.grass_jobs,
                grass_color,
                grass_depth,
                &mut self.timer,
            );
            if let Some(p) = &g.plants
                && self.features.has(Feature::Plants)
            {
                p.record(
                    &self.queue,
                    encoder,
                    &frame.grass_jobs,
                    grass_color,
                    grass_depth,
                    &mut self.timer,
                );
            }
        }
        if let Some(msaa) = &self.msaa {
            msaa.record_resolve(encoder, color, depth, &mut self.timer);
        }
        let scene = if self.msaa.is_some() { color } else { scene };
        // 7. Contact shadows: the grass's (and everything's) short shadows, from the depth.
        if self.features.has(Feature::Shadows) {
            self.contact_shadows
                .record(&self.device, encoder, scene, depth, &mut self.timer);
        }
        // 8. Temporal anti-aliasing: the frame against its history, into `color`.
        if let Some(taa) = &mut self.taa {
            taa.record(&self.device, encoder, color, depth, &mut self.timer);
        }
        // 9. Figures.
        self.timer.resolve(encoder);
        stats.cpu_ms = (frame.cpu_s + start.elapsed().as_secs_f64()) * 1e3;
        let counters = self.grass.as_ref().map(|g| g.renderer.stats_buffer());
        let plants = self
            .grass
            .as_ref()
            .and_then(|g| g.plants.as_ref())
            .filter(|_| self.features.has(Feature::Plants))
            .map(|p| p.stats_buffer());
        if plants.is_some() {
            stats.plants = Some(Default::default());
        }
        self.readback.record(
            encoder,
            &self.timer,
            counters,
            &self.holes.counter,
            plants,
            stats,
        );
        Ok(())
    }

    /// Figures of the newest frame that has come back (polling the device without waiting);
    /// `None` before the first has.
    pub fn stats(&mut self) -> Option<&FrameStats> {
        self.collect_stats();
        self.readback.ready.back()
    }

    /// Every frame's figures that have come back since the last call, oldest first (at most
    /// [`MAX_READY_STATS`]; older ones are dropped). Polls the device without waiting.
    pub fn take_stats(&mut self) -> Vec<FrameStats> {
        self.collect_stats();
        self.readback.ready.drain(..).collect()
    }

    /// Frames recorded whose figures were lost: all readback slots were still on their way
    /// back (the GPU is more than [`READBACK_SLOTS`] frames behind, or an encoder was not
    /// submitted), a mapping failed, or [`MAX_READY_STATS`] newer figures came back before
    /// they were taken. Every recorded frame's figures are delivered or counted here.
    pub fn stats_dropped(&self) -> u64 {
        self.readback.dropped
    }

    fn collect_stats(&mut self) {
        let _ = self.device.poll(wgpu::PollType::Poll);
        self.readback.collect(&self.timer);
    }

    fn check_targets(
        &self,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RendererError> {
        let t = &self.targets;
        let size = |tex: &wgpu::Texture| (tex.width(), tex.height());
        let describe = |tex: &wgpu::Texture| {
            format!(
                "{}x{} {:?} with {:?}",
                tex.width(),
                tex.height(),
                tex.format(),
                tex.usage()
            )
        };
        let c = color.texture();
        if size(c) != (t.width, t.height) {
            return Err(RendererError::Target {
                which: "colour",
                found: describe(c),
                expected: format!("{}x{}", t.width, t.height),
            });
        }
        let d = depth.texture();
        let mut usage =
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        if self.terrain_depth.is_some() {
            usage |= wgpu::TextureUsages::COPY_SRC;
        }
        if size(d) != (t.width, t.height)
            || d.format() != t.depth_format
            || !d.usage().contains(usage)
        {
            return Err(RendererError::Target {
                which: "depth",
                found: describe(d),
                expected: format!(
                    "{}x{} {:?} with {:?}",
                    t.width, t.height, t.depth_format, usage
                ),
            });
        }
        Ok(())
    }

    /// The generation jobs of the grass tiles that have their own data resident and are in view.
    fn grass_jobs(&self, view: &FrameView, grass: &[(TileId, Ring, f64)]) -> Vec<TileJob> {
        let pyramid = &self.world.manifest.pyramid;
        let (camera, frustum) = (&view.camera, &view.frustum);
        let near_m = self
            .grass
            .as_ref()
            .map_or(0.0, |g| g.renderer.settings().near_m);
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
            let rel = b.min - camera.position.truncate();
            let job = TileJob {
                origin: [rel.x as f32, rel.y as f32],
                cell: pyramid.cell_size_m(id.level) as f32,
                layer: slot,
                tile_x: id.x,
                tile_y: id.y,
                lod: u32::from(ring == Ring::Low),
                slot: 0,
            };
            jobs.push(job);
            // A high-LOD tile within the near radius: a second job for its blades there.
            let c = camera.position.truncate();
            let nearest = c.clamp(b.min, b.max) - c;
            if ring == Ring::High && nearest.length() < f64::from(near_m) {
                jobs.push(TileJob { lod: 2, ..job });
            }
        }
        jobs
    }
}

fn check_formats(targets: &Targets) -> Result<(), RendererError> {
    if crate::shaders::encode_srgb_for(targets.color_format).is_none() {
        return Err(RendererError::ColorFormat(targets.color_format));
    }
    if !DEPTH_FORMATS.contains(&targets.depth_format) {
        return Err(RendererError::DepthFormat(targets.depth_format));
    }
    Ok(())
}

/// Refuses a target size that the adapter cannot serve: beyond its largest 2D texture, or (with
/// grass) a Hi-Z pyramid larger than the largest storage buffer binding or buffer. Checked here,
/// against this device's limits, so that no wgpu validation error can follow.
fn check_size(
    device: &wgpu::Device,
    width: u32,
    height: u32,
    grass: bool,
) -> Result<(), RendererError> {
    let limits = device.limits();
    let limit = limits.max_texture_dimension_2d;
    if width == 0 || height == 0 || width > limit || height > limit {
        return Err(RendererError::BadSize {
            width,
            height,
            limit,
        });
    }
    if grass {
        let bytes = hiz_bytes(width, height);
        let (limit_name, limit) =
            if limits.max_storage_buffer_binding_size <= limits.max_buffer_size {
                (
                    "max_storage_buffer_binding_size",
                    limits.max_storage_buffer_binding_size,
                )
            } else {
                ("max_buffer_size", limits.max_buffer_size)
            };
        if bytes > limit {
            let pixels = u64::from(width) * u64::from(height);
            return Err(RendererError::SizeBeyondLimit {
                width,
                height,
                what: "Hi-Z pyramid storage buffer",
                bytes,
                limit_name,
                limit,
                max_pixels: (pixels as f64 * limit as f64 / bytes as f64) as u64,
            });
        }
    }
    Ok(())
}

/// Bytes of the Hi-Z pyramid of a `width` x `height` target (f32 levels down to 1x1).
pub fn hiz_bytes(width: u32, height: u32) -> u64 {
    (0..crate::grass::hiz::mip_count(width, height))
        .map(|m| u64::from((width >> m).max(1)) * u64::from((height >> m).max(1)) * 4)
        .sum()
}
