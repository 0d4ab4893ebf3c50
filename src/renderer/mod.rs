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

mod config;
mod error;
mod frame;
mod hole_check;
mod readback;
mod streaming;
mod targets;
mod view;

use hole_check::HoleCheck;
use readback::StatsRing;
use targets::{TargetCheck, check_formats, check_size};

pub use config::{
    ATLAS_SLOTS_PER_LEVEL, ConfigError, DEFAULT_INFILL_M, DEFAULT_LOD_WIDEN, DEFAULT_MESH_STEP,
    ELEVATION_FADE_RANGE, GrassConfig, INFILL_RANGE_M, LOD_FACTOR_RANGE, LOD_WIDEN_RANGE,
    MAX_CARD_REACH, MAX_DEFAULT_ATLAS_SLOTS, MAX_MESH_STEP, MAX_PLANT_LOD_M,
    MIN_DEFAULT_ATLAS_SLOTS, NEAR_RANGE_M, RendererConfig, RendererOptions, SPACING_RANGE_M,
    WIDTH_SCALE_RANGE, default_atlas_slots,
};
pub use error::RendererError;
pub use frame::{FrameInput, FrameStats, MissingTile, WarmUp};
pub use streaming::WARM_UP_STALL;
pub use targets::{
    COLOR_FORMATS, DEPTH_FORMATS, color_format_problem, hiz_bytes, usable_color_formats,
};
pub use view::FrameView;

use std::sync::Arc;
use std::time::Instant;

use glam::{DVec3, Vec2};

use crate::aa::AntiAliasing;
use crate::aa::msaa::Msaa;
use crate::aa::taa::{Taa, TaaSettings};
use crate::features::{Feature, Features};
use crate::gpu::{GpuTimer, Targets};
use crate::grass::{GrassRenderer, TileJob, WindBindings};
use crate::lod::{GrassRings, Ring, TerrainLod};
use crate::stream::{DeriveJob, DeriveStage, TileAtlas, TileService, TileSource};
use crate::terrain::{TerrainRenderer, TileDraw};
use crate::wind::{SwayConfig, SwayField, WindConfig, WindField};
use crate::world::{TileId, World};

/// Frames whose figures can be on their way back at once; a frame recorded while all of them
/// are still on their way gets no figures (counted in [`Renderer::stats_dropped`]).
pub const READBACK_SLOTS: usize = 4;

/// The device limits the renderer needs: WebGPU's defaults, which every desktop adapter
/// offers (its passes bind up to six storage buffers in one stage, more than a downlevel device
/// has). Make the device with `required_limits: adapter.limits()` or these.
pub fn required_limits() -> wgpu::Limits {
    wgpu::Limits::default()
}

/// Refuses a device whose limits fall short of [`required_limits`], naming each limit (a
/// pipeline of the renderer would otherwise fail wgpu's validation as it is made);
/// [`Renderer::new`] checks this first.
pub fn check_device_limits(device: &wgpu::Device) -> Result<(), RendererError> {
    check_limits(&device.limits())
}

fn check_limits(limits: &wgpu::Limits) -> Result<(), RendererError> {
    let mut short = Vec::new();
    required_limits().check_limits_with_fail_fn(limits, false, |name, needed, has| {
        short.push(format!("{name} {has} ({needed} needed)"));
    });
    if short.is_empty() {
        Ok(())
    } else {
        Err(RendererError::DeviceLimits { short })
    }
}

/// Refuses a grass tile of `tile_m` whose grid of `cell_m` needs more workgroups of 8 points
/// a side than the device dispatches (`limit` a dimension).
/// Runs `make`, which allocates GPU memory, turning the device's out-of-memory error into
/// `error(reason)`. An object the device could not allocate is invalid, and using it (a view of
/// the texture, a bind group) raises validation errors: those are taken with the out-of-memory
/// error. A validation error without one is a defect, and panics as wgpu's own handler does.
pub fn catch_out_of_memory<T>(
    device: &wgpu::Device,
    make: impl FnOnce() -> Result<T, RendererError>,
    error: impl FnOnce(String) -> RendererError,
) -> Result<T, RendererError> {
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let made = make();
    let out_of_memory = pollster::block_on(memory.pop());
    let invalid = pollster::block_on(validation.pop());
    if let Some(e) = out_of_memory {
        return Err(error(e.to_string()));
    }
    if let Some(e) = invalid {
        panic!("wgpu error: {e}");
    }
    made
}

/// [`catch_out_of_memory`] for what the target size and the settings size: the error names
/// `what` and the size.
pub fn allocate_at_size<T>(
    device: &wgpu::Device,
    what: &'static str,
    (width, height): (u32, u32),
    make: impl FnOnce() -> Result<T, RendererError>,
) -> Result<T, RendererError> {
    catch_out_of_memory(device, make, |reason| RendererError::DeviceMemory {
        what,
        width,
        height,
        reason,
    })
}

fn check_tile_grid(
    what: &'static str,
    tile_m: f32,
    cell_m: f32,
    limit: u32,
) -> Result<(), RendererError> {
    let grid = (f64::from(tile_m) / f64::from(cell_m)).round().max(1.0);
    let most = u64::from(limit) * 8;
    if grid > most as f64 {
        return Err(RendererError::TileGrid {
            what,
            tile_m,
            cell_m,
            grid: grid as u64,
            most,
        });
    }
    Ok(())
}

/// Level-0 tiles uploaded between flushes of the queue's staged copies when the renderer
/// starts (a world of thousands of roots holds at most this many at once).
const ROOT_UPLOAD_BATCH: u32 = 16;

/// Passes a frame can time: two for each batch of grass jobs (generation and drawing; the
/// most jobs a frame takes, [`crate::grass::renderer::MAX_JOBS`], in batches of
/// [`crate::grass::BATCH_TILES`]), and room for every other stage's. A frame of the truth's
/// content (blades out to nine view distances) has more than 64 passes; a pass past the room
/// would go untimed ([`GpuTimer::untimed`]) and the frame's GPU time fall short.
pub const MAX_TIMED_PASSES: u32 =
    2 * crate::grass::renderer::MAX_JOBS.div_ceil(crate::grass::BATCH_TILES) + 64;

/// Delivered figures kept until taken ([`Renderer::take_stats`]); older ones are dropped.
pub const MAX_READY_STATS: usize = 2 * READBACK_SLOTS;

/// The grass with the wind it bends in.
struct GrassStage {
    renderer: GrassRenderer,
    wind: WindField,
    sway: SwayField,
    /// The plants among the grass (a world with `[[plant_types]]` lower than trees).
    plants: Option<crate::plants::PlantRenderer>,
    /// The trees (a world with tree types), out to the fog.
    trees: Option<crate::plants::PlantRenderer>,
    /// The trees that cast into the shadow map (with the trees and tree shadows).
    casters: Option<crate::plants::PlantRenderer>,
    /// With trees: the depth of their canopy's shade per band of altitude and grass type.
    canopy: Option<crate::plants::shadow::CanopyDepth>,
    /// With trees: the leaves they shed.
    particles: Option<crate::plants::particles::ParticleStage>,
}

/// What [`Renderer::prepare`] worked out for [`Renderer::record`].
struct Prepared {
    input: FrameInput,
    dt: f32,
    derives: Vec<DeriveJob>,
    terrain_tiles: u32,
    grass_jobs: Vec<TileJob>,
    /// The plants' jobs (near and far).
    plant_jobs: Vec<crate::plants::place_cpu::PlantJob>,
    /// The trees' jobs.
    tree_jobs: Vec<crate::plants::place_cpu::PlantJob>,
    /// The shadow casters' jobs, with the frame's cascades (none without tree shadows).
    caster_jobs: Vec<crate::plants::place_cpu::PlantJob>,
    cascades: usize,
    /// The atlas slots the frame reads and the tiles it expects there (terrain draws and
    /// grass jobs), checked against the atlas on the GPU.
    reads: Vec<(u32, TileId)>,
    stats: FrameStats,
    cpu_s: f64,
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
    /// The trees' shadow map (a texel, never drawn, without tree shadows).
    tree_shadow_map: crate::plants::shadow::TreeShadowMap,
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
    /// The last prepared frame's eye and forward direction (for the plant stages' cuts).
    last_view: Option<(DVec3, DVec3)>,
    frame: u64,
    prepared: Option<Prepared>,
    /// Why the last prepare left no frame to record, where it did not (an input that cannot be
    /// drawn, or a change to the renderer after it): [`Renderer::record`]'s error.
    unprepared: Option<RendererError>,
    /// A copy of the depth target after the terrain colour passes, when asked for
    /// ([`Renderer::set_terrain_depth_capture`]).
    terrain_depth: Option<wgpu::Texture>,
    /// The temporal anti-aliasing, when on: the frame is drawn into its texture and resolved
    /// into the caller's colour target.
    taa: Option<Taa>,
    /// The settings a temporal anti-aliasing switched on later starts with.
    taa_settings: TaaSettings,
    /// The multisampling of the grass, when on: terrain and sky are drawn into its texture,
    /// the blades into its multisampled targets, resolved into the caller's.
    msaa: Option<Msaa>,
    /// What checks the caller's targets on each frame.
    target_check: TargetCheck,
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
        check_device_limits(device)?;
        let config = options.config;
        config.validate_for(&world)?;
        let targets = Targets {
            color_format: options.color_format,
            depth_format: options.depth_format,
            width: options.width,
            height: options.height,
        };
        let grass_on = config.grass_rings.is_some();
        check_formats(
            device,
            &targets,
            config.aa == AntiAliasing::Msaa && grass_on,
        )?;
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
        // The atlas is the renderer's largest allocation (slots x side^2 x 8 bytes: 17.8 GB at
        // 2048 slots of 1041-sample tiles): a device that cannot hold it says so here, as an
        // error naming the slots, not as a fatal error of the device.
        let atlas = catch_out_of_memory(
            device,
            || Ok(TileAtlas::new(device, pyramid.samples_per_side(), slots)),
            |reason| {
                let side = u64::from(pyramid.samples_per_side());
                RendererError::AtlasMemory {
                    slots,
                    bytes: u64::from(slots) * side * side * 8,
                    reason,
                }
            },
        )?;
        // The level-0 tiles go to the atlas as they load, the queue's staged copies flushed
        // every few tiles: however many the world has, a few are in memory at once.
        let mut staged = 0;
        let service =
            TileService::start(&pyramid, source.clone(), config.service, |slot, tile| {
                atlas.upload(queue, slot, &tile)?;
                staged += 1;
                if staged % ROOT_UPLOAD_BATCH == 0 {
                    queue.submit(std::iter::empty());
                    let _ = device.poll(wgpu::PollType::wait_indefinitely());
                }
                Ok::<(), RendererError>(())
            })?;
        // Everything else the renderer allocates (targets of the frame's size, the grass's,
        // plants' and trees' pools, the shadow map, the anti-aliasing's targets) is sized by
        // options too: a device that cannot hold it is an error naming them.
        let (width, height) = (targets.width, targets.height);
        let make = move || -> Result<Self, RendererError> {
            let derive = DeriveStage::new(
                device,
                queue,
                &pyramid,
                &config.derive,
                &atlas,
                // Never more a frame than the atlas has slots: a derived tile takes one.
                config.service.derives_per_frame.min(slots),
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
                    // One workgroup of 8 x 8 points a dispatch; a world of huge finest tiles (a
                    // coarse bake) asks for more than a device dispatches.
                    let dispatch = limits.max_compute_workgroups_per_dimension;
                    check_tile_grid("blade", settings.tile_m, settings.spacing_m, dispatch)?;
                    if !world.manifest.plant_types.is_empty() {
                        check_tile_grid("plant", settings.tile_m, config.plants.cell_m, dispatch)?;
                    }
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
                    let set = if world.manifest.plant_types.is_empty() {
                        None
                    } else {
                        // glTF plants come from where the tiles do (a world over HTTP fetches them).
                        let read = |path: &std::path::Path| {
                            crate::plants::gltf::read_from_source(source.as_ref(), &world.dir, path)
                        };
                        Some(crate::plants::PlantSet::build_with(
                            &world.manifest,
                            &world.dir,
                            &read,
                        )?)
                    };
                    let view = settings.view_distance_m;
                    let wind_bindings = crate::plants::renderer::PlantWindBindings {
                        lookup: wind.lookup_uniform(),
                        cells: wind.buffer(),
                        sway: sway.buffer(),
                    };
                    let layer = |layer: crate::plants::PlantLayer,
                                 s: crate::plants::PlantSettings| {
                        let set = set.as_ref()?;
                        (!layer.types(&world.manifest).is_empty()).then(|| {
                            crate::plants::PlantRenderer::new(
                                device,
                                queue,
                                &world.manifest,
                                set,
                                layer,
                                &atlas,
                                &targets,
                                &renderer.hiz,
                                settings.tile_m,
                                s,
                                wind_bindings,
                            )
                        })
                    };
                    let plants = layer(
                        crate::plants::PlantLayer::Plants,
                        crate::plants::PlantSettings {
                            view_m: [0.8 * view, view],
                            seed: settings.seed,
                            ..config.plants
                        },
                    );
                    let trees = layer(
                        crate::plants::PlantLayer::Trees,
                        crate::plants::PlantSettings {
                            seed: settings.seed,
                            ..config.trees.unwrap_or_else(|| {
                                crate::plants::PlantSettings::trees(
                                    settings.tile_m,
                                    world.manifest.sky.fog_distance_m,
                                )
                            })
                        },
                    );
                    // The shadow casters: the trees' own placement within the shadows' reach (and a
                    // little beyond, for the trees just outside that cast into it).
                    let casters = match (&set, &trees, &config.tree_shadows) {
                        (Some(set), Some(t), Some(shadows)) => {
                            Some(crate::plants::PlantRenderer::new_caster(
                                device,
                                queue,
                                &world.manifest,
                                set,
                                &atlas,
                                &targets,
                                &renderer.hiz,
                                settings.tile_m,
                                crate::plants::PlantSettings {
                                    capacity: crate::plants::shadow::CASTER_CAPACITY,
                                    view_m: [shadows.distance_m + 20.0, shadows.distance_m + 40.0],
                                    lod_m: shadows.placement_lod_m(t.settings().band_m),
                                    ..*t.settings()
                                },
                                wind_bindings,
                                shadows.cascades,
                            ))
                        }
                        _ => None,
                    };
                    let canopy = set.as_ref().zip(trees.as_ref()).map(|(set, t)| {
                        crate::plants::shadow::canopy_depth(
                            &world.manifest,
                            set,
                            t.settings().cell_m,
                            crate::terrain::sun_direction(&world.manifest.sky),
                        )
                    });
                    let particles = match (&trees, &config.particles) {
                        (Some(t), Some(p)) => {
                            let colors: Vec<[f32; 3]> = crate::plants::PlantLayer::Trees
                                .types(&world.manifest)
                                .iter()
                                .map(|&i| world.manifest.plant_types[i].color)
                                .collect();
                            // Petals from the plants of the `flower` recipe, in their accent colour.
                            let petals: Vec<Option<[f32; 3]>> = crate::plants::PlantLayer::Plants
                                .types(&world.manifest)
                                .iter()
                                .map(|&i| &world.manifest.plant_types[i])
                                .map(|t| {
                                    let flower = crate::plants::recipe::Recipe::from_name(&t.mesh)
                                        == Some(crate::plants::recipe::Recipe::Flower);
                                    flower.then_some(t.color)
                                })
                                .collect();
                            let flowers =
                                plants
                                    .as_ref()
                                    .map(|f| crate::plants::particles::FlowerSource {
                                        instances: f.instance_buffer(),
                                        args: f.args_buffer(),
                                        capacity: f.settings().capacity,
                                        petals: &petals,
                                    });
                            Some(crate::plants::particles::ParticleStage::new(
                                device,
                                &targets,
                                *p,
                                crate::plants::particles::TreeSource {
                                    instances: t.instance_buffer(),
                                    args: t.args_buffer(),
                                    capacity: t.settings().capacity,
                                    types: t.types(),
                                },
                                flowers,
                                crate::plants::particles::ParticleWind {
                                    lookup: wind.lookup_uniform(),
                                    cells: wind.buffer(),
                                },
                                &colors,
                                &world.manifest.sky,
                            ))
                        }
                        _ => None,
                    };
                    Some(GrassStage {
                        renderer,
                        wind,
                        sway,
                        plants,
                        trees,
                        casters,
                        canopy,
                        particles,
                    })
                }
                None => None,
            };
            let timestamps = device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
            let timer = GpuTimer::new(device, queue, timestamps, MAX_TIMED_PASSES);
            let readback = StatsRing::new(device, timer.capacity_bytes());
            let holes = HoleCheck::new(device, &atlas);
            let taa =
                (config.aa == AntiAliasing::Taa).then(|| Taa::new(device, &targets, config.taa));
            let msaa = (config.aa == AntiAliasing::Msaa && grass.is_some())
                .then(|| Msaa::new(device, &targets));
            let tree_shadow_map = crate::plants::shadow::TreeShadowMap::new(
                device,
                config
                    .tree_shadows
                    .filter(|_| grass.as_ref().is_some_and(|g| g.casters.is_some())),
            );
            // Beyond the map, the canopy's shade on the ground.
            if let (Some(s), Some(tau)) = (
                tree_shadow_map.settings(),
                grass.as_ref().and_then(|g| g.canopy),
            ) {
                terrain.set_canopy(&tau, [0.9 * s.distance_m, s.distance_m]);
            }
            let mut grass = grass;
            if let (Some(g), Some(t)) = (&mut grass, &taa) {
                g.renderer
                    .set_motion_vectors(device, t.settings().blade_motion);
                if let Some(p) = &mut g.particles {
                    p.set_reactive(device, true);
                }
            }
            if let (Some(g), Some(_)) = (&mut grass, &msaa) {
                g.renderer.set_samples(device, crate::aa::msaa::SAMPLES);
                for p in g.plants.iter_mut().chain(g.trees.iter_mut()) {
                    p.set_samples(device, crate::aa::msaa::SAMPLES);
                }
                if let Some(p) = &mut g.particles {
                    p.set_samples(device, crate::aa::msaa::SAMPLES);
                }
            }
            let renderer = Self {
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
                tree_shadow_map,
                targets,
                features: config.features,
                timer,
                readback,
                holes,
                skip_uploads: 0,
                time_s: None,
                last_view: None,
                frame: 0,
                prepared: None,
                unprepared: None,
                terrain_depth: None,
                taa,
                taa_settings: config.taa,
                msaa,
                target_check: TargetCheck::new(device, &targets),
            };
            Ok(renderer)
        };
        allocate_at_size(
            device,
            "the renderer's targets and pools",
            (width, height),
            make,
        )
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

    /// GPU memory of the trees' instance pool, bytes (`None` without trees): fixed when the
    /// renderer is made, whatever the view.
    pub fn tree_pool_bytes(&self) -> Option<u64> {
        self.grass
            .as_ref()
            .and_then(|g| g.trees.as_ref())
            .map(|p| p.pool_bytes())
    }

    /// GPU memory of the trees' shadows, bytes: the shadow map and the casters' instance pool
    /// (`None` without tree shadows); fixed when the renderer is made, whatever the view.
    pub fn tree_shadow_bytes(&self) -> Option<u64> {
        let casters = self.grass.as_ref().and_then(|g| g.casters.as_ref())?;
        Some(casters.pool_bytes() + self.tree_shadow_map.bytes())
    }

    /// The trees' shadow map, with the last prepared frame's cascades.
    pub fn tree_shadow_map(&self) -> &crate::plants::shadow::TreeShadowMap {
        &self.tree_shadow_map
    }

    /// The trees drawn in the last submitted frame, each root relative to that frame's camera,
    /// a tree inside a cross-fade band once per level it is drawn at (for tests and tools:
    /// waits for the GPU; empty without trees).
    pub fn read_tree_instances(&self) -> Vec<crate::plants::place_cpu::PlantInstance> {
        self.read_layer(|g| g.trees.as_ref())
    }

    /// Every instance the plant stage that `stage` picks drew in the last submitted frame.
    fn read_layer(
        &self,
        stage: impl Fn(&GrassStage) -> Option<&crate::plants::PlantRenderer>,
    ) -> Vec<crate::plants::place_cpu::PlantInstance> {
        self.grass
            .as_ref()
            .and_then(stage)
            .map(|t| {
                t.read_instances(&self.device, &self.queue)
                    .into_iter()
                    .flatten()
                    .collect()
            })
            .unwrap_or_default()
    }

    /// The leaves' pool after the last submitted frame, positions relative to that frame's
    /// camera (for tests and tools: waits for the GPU; empty without trees).
    pub fn read_particles(&self) -> Vec<crate::plants::particles_cpu::Particle> {
        self.grass
            .as_ref()
            .and_then(|g| g.particles.as_ref())
            .map(|p| p.read_particles(&self.device, &self.queue))
            .unwrap_or_default()
    }

    /// The trees that cast into the shadow map in the last submitted frame, each root
    /// relative to that frame's camera (for tests and tools: waits for the GPU; empty without
    /// tree shadows).
    pub fn read_shadow_casters(&self) -> Vec<crate::plants::place_cpu::PlantInstance> {
        self.read_layer(|g| g.casters.as_ref())
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
            let size = (self.targets.width, self.targets.height);
            let copy = allocate_at_size(&self.device, "the terrain-only depth", size, || {
                Ok(self.depth_copy())
            })?;
            self.terrain_depth = Some(copy);
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
    ///
    /// A device that cannot hold the method's targets is an error, and the frame keeps the
    /// method it had.
    pub fn set_anti_aliasing(&mut self, aa: AntiAliasing) -> Result<(), RendererError> {
        if aa == self.anti_aliasing() {
            return Ok(());
        }
        let msaa = aa == AntiAliasing::Msaa && self.grass.is_some();
        check_formats(&self.device, &self.targets, msaa)?;
        let size = (self.targets.width, self.targets.height);
        let (taa, msaa) =
            allocate_at_size(&self.device, "the anti-aliasing's targets", size, || {
                let taa = (aa == AntiAliasing::Taa)
                    .then(|| Taa::new(&self.device, &self.targets, self.taa_settings));
                let msaa = (aa == AntiAliasing::Msaa && self.grass.is_some())
                    .then(|| Msaa::new(&self.device, &self.targets));
                Ok((taa, msaa))
            })?;
        self.unprepare("the anti-aliasing was switched");
        self.taa = taa;
        self.msaa = msaa;
        let samples = if self.msaa.is_some() {
            crate::aa::msaa::SAMPLES
        } else {
            1
        };
        let blade_motion = self.blade_motion();
        if let Some(g) = &mut self.grass {
            g.renderer.set_samples(&self.device, samples);
            g.renderer.set_motion_vectors(&self.device, blade_motion);
            for p in g.plants.iter_mut().chain(g.trees.iter_mut()) {
                p.set_samples(&self.device, samples);
            }
            if let Some(p) = &mut g.particles {
                p.set_samples(&self.device, samples);
                p.set_reactive(&self.device, self.taa.is_some());
            }
        }
        Ok(())
    }

    /// Whether the blades write their motion vectors (temporal anti-aliasing with
    /// [`TaaSettings::blade_motion`]).
    fn blade_motion(&self) -> bool {
        self.taa.as_ref().is_some_and(|t| t.settings().blade_motion)
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
    ///
    /// A device that cannot hold the targets at the new size is an error, and the renderer
    /// keeps drawing at the size it had.
    pub fn resize(&mut self, width: u32, height: u32) -> Result<(), RendererError> {
        check_size(&self.device, width, height, self.grass.is_some())?;
        if (width, height) == (self.targets.width, self.targets.height) {
            return Ok(());
        }
        let old = (self.targets.width, self.targets.height);
        let device = self.device.clone();
        let resize_to = |r: &mut Self, (w, h): (u32, u32), what| {
            allocate_at_size(&device, what, (w, h), || {
                r.resize_targets(w, h);
                Ok(())
            })
        };
        let resized = resize_to(self, (width, height), "the renderer's targets");
        self.unprepare("the renderer was resized");
        if resized.is_err() {
            // The targets made at the new size are let go before the old size's are made again.
            resize_to(
                self,
                old,
                "the renderer's targets, made again at the size they had,",
            )?;
        }
        resized
    }

    /// Lets go of a frame prepared for the renderer as it was before `change` (its derivations
    /// are submitted, as for any frame prepared and not recorded): its record is refused,
    /// naming the change, until the next prepare.
    fn unprepare(&mut self, change: &'static str) {
        if self.prepared.is_some() {
            self.flush_unrecorded();
            self.unprepared = Some(RendererError::ChangedAfterPrepare(change));
        }
    }

    /// Makes every target of the frame's size again at `width` x `height`.
    fn resize_targets(&mut self, width: u32, height: u32) {
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
            for p in g.plants.iter_mut().chain(g.trees.iter_mut()) {
                p.resize(&self.device, &g.renderer.hiz);
            }
        }
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
        if let Err(problem) = input.check() {
            self.unprepared = Some(RendererError::FrameInput(problem));
            return;
        }
        self.unprepared = None;
        // The view, once for every stage: the caller's jitter plus the temporal
        // anti-aliasing's.
        let jitter = input.jitter_px + self.taa.as_ref().map_or(Vec2::ZERO, |t| t.next_jitter());
        let view = FrameView::new(
            &input.camera,
            jitter,
            self.targets.width,
            self.targets.height,
        );
        if let Err(problem) = view.check() {
            self.unprepared = Some(RendererError::FrameInput(problem));
            return;
        }
        if let Some(taa) = &mut self.taa {
            taa.prepare(
                &self.queue,
                view.unjittered,
                view.projection,
                view.eye,
                view.forward,
            );
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
        let plant_jobs = self.plant_jobs(&view, &sel.terrain, &grass_jobs);
        let tree_jobs = self.tree_jobs(&view, &sel.terrain);
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
        let sun = crate::terrain::sun_direction(&self.world.manifest.sky);
        self.contact_shadows.prepare(
            queue,
            view.view_proj,
            sun,
            (self.targets.width, self.targets.height),
            self.features.has(Feature::Shadows),
        );
        // The trees' shadows: the cascades of this view, the casters in their box.
        let shadows = self.tree_shadow_map.settings().copied().filter(|_| {
            self.features.has(Feature::Trees) && self.features.has(Feature::TreeShadows)
        });
        let (cascades, caster_box) = match shadows {
            Some(s) => {
                let c = s.cascades(camera.position, view.view_proj.inverse(), sun);
                let b = crate::plants::shadow::TreeShadows::caster_box(&c, sun);
                (c, b)
            }
            None => (Vec::new(), glam::Mat4::IDENTITY),
        };
        let caster_jobs = match shadows {
            Some(s) => self.caster_jobs(
                camera.position,
                &crate::lod::Frustum::from_view_proj(caster_box),
                f64::from(s.distance_m),
            ),
            None => Vec::new(),
        };
        self.tree_shadow_map
            .set(queue, shadows.is_some().then_some(cascades.as_slice()));
        let cut = crate::plants::renderer::is_cut(self.last_view, view.eye, view.forward);
        self.last_view = Some((view.eye, view.forward));
        if let Some(g) = &mut self.grass {
            let ambient_speed = g.wind.config().ambient_at(input.time_s).speed_mps as f32;
            g.renderer
                .set_frame(input.time_s, ambient_speed, self.features, camera.position);
            let last_view_proj = self
                .taa
                .as_ref()
                .map_or(view.unjittered, |t| t.last_view_proj());
            g.renderer.set_motion(dt, view.unjittered, last_view_proj);
            g.renderer.set_camera(
                queue,
                view.view_proj,
                &view.frustum,
                camera.position.z as f32,
                camera.near_m,
            );
            for p in g
                .plants
                .iter_mut()
                .chain(g.trees.iter_mut())
                .chain(g.casters.iter_mut())
            {
                p.set_cut(cut);
            }
            for p in g.plants.iter_mut().chain(g.trees.iter_mut()) {
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
            if let Some(p) = &mut g.particles {
                p.set_frame(queue, camera.position, view.view_proj, dt);
            }
            if let (Some(c), false) = (&mut g.casters, cascades.is_empty()) {
                c.set_shadow_frame(
                    queue,
                    input.time_s,
                    self.features,
                    camera.position,
                    caster_box,
                    &cascades,
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
            plant_jobs,
            tree_jobs,
            caster_jobs,
            cascades: cascades.len(),
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
    ///    then the plants and the trees (`plants_place.wgsl`, `plants_draw.wgsl`) and the
    ///    leaves the trees shed (`particles.wgsl`).
    ///    With multisampling (`aa_msaa.wgsl`), the frame so far is copied into every sample of
    ///    the stage's multisampled targets first, the blades drawn there with alpha to
    ///    coverage, and colour and depth resolved into `color` and `depth` after;
    /// 7. shadows: with trees and the `tree-shadows` feature, the trees' shadow map first (its
    ///    casters placed around the camera and drawn depth-only into each cascade,
    ///    `plants_place.wgsl`, `plants_draw.wgsl`); then each pixel's factor, less than 1 where
    ///    a short ray toward the sun is blocked in the depth buffer (with the `shadows`
    ///    feature) or the trees' map shades its point (compute), then the colour multiplied by
    ///    it (a full-screen pass; both `terrain_contact_shadow.wgsl`);
    /// 8. with temporal anti-aliasing (passes 5-7 then draw into its own texture, with a
    ///    jittered projection): the frame folded into the reprojected history (compute,
    ///    `aa_taa.wgsl`), and the result written into `color`;
    /// 9. the pass timestamps and grass counters copied into the readback ring, mapped when the
    ///    encoder's work is submitted ([`Renderer::stats`]).
    ///
    /// `color` and `depth` must match the renderer's targets: its formats (the colour view may
    /// be the sRGB or plain variant of its texture's format) and size, one sample, each a 2D
    /// view of one mip level and one layer (of a larger texture too), of a texture with
    /// `RENDER_ATTACHMENT` usage (the depth's also `TEXTURE_BINDING`, and `COPY_SRC` with the
    /// terrain-only depth captured). A target that does not is [`RendererError::Target`],
    /// before anything is recorded. A view does not tell its levels, layers or format, so the
    /// first time a pair of views is given wgpu is asked about them under an error scope
    /// (nothing is submitted); the same pair again is not asked about again.
    pub fn record(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) -> Result<(), RendererError> {
        let start = Instant::now();
        self.check_targets(color, depth)?;
        let Some(frame) = self.prepared.take() else {
            return Err(self.unprepared.take().unwrap_or(RendererError::NotPrepared));
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
                .record(&self.device, encoder, depth, &mut self.timer);
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
        // The motion vectors, for the temporal anti-aliasing: cleared, then written by the
        // blades drawn (with `blade_motion`), and marked where the falling leaves are drawn
        // (their pixels' history does not hold them).
        let leaves = self.grass.as_ref().is_some_and(|g| g.particles.is_some());
        let motion_taa = self
            .taa
            .as_ref()
            .filter(|t| t.settings().blade_motion || leaves);
        if let Some(t) = motion_taa {
            t.record_clear_motion(encoder);
        }
        let motion = motion_taa.map(|t| t.motion_view());
        if let Some(g) = &self.grass {
            stats.grass.tiles = g.renderer.record(
                &self.queue,
                encoder,
                &frame.grass_jobs,
                grass_color,
                motion,
                grass_depth,
                &mut self.timer,
            );
            for (p, jobs) in [(&g.plants, &frame.plant_jobs), (&g.trees, &frame.tree_jobs)] {
                if let Some(p) = p
                    && self.features.has(p.layer().feature())
                {
                    p.record(
                        &self.queue,
                        encoder,
                        jobs,
                        grass_color,
                        grass_depth,
                        &mut self.timer,
                    );
                }
            }
            if let Some(p) = &g.particles
                && g.trees.is_some()
                && self.features.has(Feature::Trees)
                && self.features.has(Feature::Particles)
            {
                p.record(encoder, grass_color, motion, grass_depth, &mut self.timer);
            }
        }
        if let Some(msaa) = &self.msaa {
            msaa.record_resolve(encoder, color, depth, &mut self.timer);
        }
        let scene = if self.msaa.is_some() { color } else { scene };
        // 7. Shadows: the trees' shadow map drawn, then the grass's (and everything's) short
        // contact shadows from the depth and the trees' from the map, applied together.
        let tree_shadows = frame.cascades > 0 && self.tree_shadow_map.active();
        if tree_shadows && let Some(c) = self.grass.as_ref().and_then(|g| g.casters.as_ref()) {
            c.record_shadow(
                &self.queue,
                encoder,
                &frame.caster_jobs,
                &self.tree_shadow_map,
                frame.cascades,
                &mut self.timer,
            );
        }
        if self.features.has(Feature::Shadows) || tree_shadows {
            self.contact_shadows.record(
                &self.device,
                encoder,
                scene,
                depth,
                &self.tree_shadow_map,
                &mut self.timer,
            );
        }
        // 8. Temporal anti-aliasing: the frame against its history, into `color`.
        if let Some(taa) = &mut self.taa {
            taa.record(&self.device, encoder, color, depth, &mut self.timer);
        }
        // 9. Figures.
        self.timer.resolve(encoder);
        stats.cpu_ms = (frame.cpu_s + start.elapsed().as_secs_f64()) * 1e3;
        let counters = self.grass.as_ref().map(|g| g.renderer.stats_buffer());
        // The counters of each plant layer that drew this frame.
        let [plants, trees] = self
            .grass
            .as_ref()
            .map_or([None, None], |g| [g.plants.as_ref(), g.trees.as_ref()])
            .map(|layer| {
                layer
                    .filter(|p| self.features.has(p.layer().feature()))
                    .map(|p| (p.stats_buffer(), p.args_buffer()))
            });
        stats.plants = plants.map(|_| Default::default());
        stats.trees = trees.map(|_| Default::default());
        self.readback.record(
            encoder,
            &self.timer,
            counters,
            &self.holes.counter,
            [plants, trees],
            stats,
        );
        Ok(())
    }

    /// Figures of the newest frame that has come back (polling the device without waiting),
    /// whether or not [`Self::take_stats`] has taken it since; `None` before the first has.
    pub fn stats(&mut self) -> Option<&FrameStats> {
        self.collect_stats();
        let r = &self.readback;
        r.ready.back().or(r.taken_last.as_ref())
    }

    /// Every frame's figures that have come back since the last call, oldest first (at most
    /// [`MAX_READY_STATS`]; older ones are dropped). Polls the device without waiting.
    pub fn take_stats(&mut self) -> Vec<FrameStats> {
        self.collect_stats();
        let taken: Vec<FrameStats> = self.readback.ready.drain(..).collect();
        if let Some(last) = taken.last() {
            self.readback.taken_last = Some(last.clone());
        }
        taken
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
}
