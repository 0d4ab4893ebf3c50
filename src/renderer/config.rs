//! The renderer's settings: [`RendererConfig`] (grouped: streaming, levels of detail, the
//! grass's [`GrassConfig`], wind, features), checked once by [`RendererConfig::validate`], and
//! [`RendererOptions`] (the caller's targets with those settings).
//!
//! Every front end builds a [`RendererConfig`] (from [`RendererConfig::for_world`], changing
//! what its user asked for) and hands it to [`crate::Renderer::new`], which refuses a value out
//! of its range with a [`ConfigError`] naming the field and the range before anything is built;
//! the front ends do not check these ranges themselves.

use crate::aa::AntiAliasing;
use crate::features::Features;
use crate::grass::GrassSettings;
use crate::lod::RingSettings;
use crate::stream::{DeriveParams, ServiceConfig};
use crate::world::{WindKey, World};

/// Settings of the engine: streaming limits, levels of detail, grass, wind and features.
#[derive(Clone, Debug)]
pub struct RendererConfig {
    /// Limits of the tile service (atlas slots, cache bytes, loads in flight, budgets).
    pub service: ServiceConfig,
    /// Terrain tiles split while the camera is nearer than this many tile edges
    /// ([`LOD_FACTOR_RANGE`]).
    pub lod_factor: f64,
    /// Derivation of child tiles.
    pub derive: DeriveParams,
    /// Grass rings, or none to ask for no grass tiles (no grass, no wind); their level is
    /// checked against the world's pyramid by [`RendererConfig::validate_for`].
    pub grass_rings: Option<RingSettings>,
    /// The grass's settings: blade spacing, width, infill, segments, pool capacity.
    pub grass: GrassConfig,
    /// Terrain grid vertices every this many samples (1 = every sample): a power of two, at
    /// most [`MAX_MESH_STEP`].
    pub mesh_step: u32,
    /// The wind scene of the manifest (default: `breeze`, else the manifest's wind); when
    /// `None` and `wind_keys` is not empty, the scenes of those keys in turn.
    pub wind_scene: Option<String>,
    /// Changes of wind scene over time (a camera path's `wind` keys).
    pub wind_keys: Vec<WindKey>,
    /// The switched-on features of the grass model.
    pub features: Features,
    /// How the frame is anti-aliased: temporally by default ([`AntiAliasing::Taa`], for
    /// consecutive frames; a single frame, or the first after a cut, is its current sample
    /// alone); [`AntiAliasing::Off`] draws one sample at each pixel's centre.
    pub aa: AntiAliasing,
    /// The temporal anti-aliasing's settings (with `aa` at [`AntiAliasing::Taa`]).
    pub taa: crate::aa::taa::TaaSettings,
    /// The plant stage's settings (its view distance and seed follow the grass's).
    pub plants: crate::plants::PlantSettings,
    /// The trees' settings (`None`: [`crate::plants::PlantSettings::trees`] for the world's
    /// grass tiles and fog; the seed follows the grass's).
    pub trees: Option<crate::plants::PlantSettings>,
    /// The trees' shadow map (`None`: no tree shadows, and no map's memory).
    pub tree_shadows: Option<crate::plants::shadow::TreeShadows>,
    /// The leaves the trees shed (`None`: none, and no pool).
    pub particles: Option<crate::plants::particles::ParticleSettings>,
}

/// The grass's own settings, the same for every world (what follows from the world, like the
/// grass tile's size and the ring radii, is worked out by [`RendererConfig::grass_settings`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrassConfig {
    /// Blade spacing of the high-LOD grid, metres ([`SPACING_RANGE_M`]; the low-LOD grid has
    /// twice this).
    pub spacing_m: f32,
    /// Every grass type's blade width times this (the manifest's widths at 1;
    /// [`WIDTH_SCALE_RANGE`]).
    pub width_scale: f32,
    /// Radii of the grass infill near the camera, metres (see [`GrassSettings::infill_m`]):
    /// each in [`INFILL_RANGE_M`], the quarter-spacing radius no larger than the half-spacing
    /// one.
    pub infill_m: [f32; 2],
    /// Blade segments near the camera, in the rest of the high ring and in the low ring, each
    /// in 1..=[`GrassSettings::MAX_SEGMENTS`].
    pub segments: [u32; 3],
    /// Horizontal radius of the blades drawn with the most segments, metres
    /// ([`NEAR_RANGE_M`]).
    pub near_m: f32,
    /// How many times as wide the blades of the low-LOD grid are drawn in the low ring
    /// ([`LOD_WIDEN_RANGE`]; see [`GrassSettings::lod_widen`]): a quarter of the blades keeping
    /// the ground's cover. 1 ([`DEFAULT_LOD_WIDEN`]) draws them at their own width.
    pub lod_widen: f32,
    /// Metres toward the blades' fade at the view distance per metre the camera stands above a
    /// blade ([`ELEVATION_FADE_RANGE`]; [`crate::terrain::far_field::ELEVATION_DISTANCE`] by
    /// default): from 1 / (1 + this) of the view distance up no blade is drawn, the far field
    /// showing the grass below; 0 fades them by their distance alone.
    pub elevation_fade: f32,
    /// Blades a slot of the grass pool holds (at least 1); `None`: enough for the world's
    /// densest grass tile (found by reading its finest stored tiles).
    pub capacity: Option<u32>,
    /// Whether the far field lies under the blades too (the default), filling the gaps between
    /// them with what the grass shows from afar, or only where the blades fade out at the view
    /// distance, the ground bare between them (the truth's way: see
    /// [`GrassSettings::far_field_under_blades`]).
    pub far_field_under_blades: bool,
}

/// Default radii of the grass infill near the camera (half and quarter spacing), metres.
pub const DEFAULT_INFILL_M: [f32; 2] = [20.0, 10.0];

/// Default terrain mesh step: a vertex every second sample.
pub const DEFAULT_MESH_STEP: u32 = 2;

/// Blade spacing, metres.
pub const SPACING_RANGE_M: std::ops::RangeInclusive<f32> = 0.02..=5.0;
/// The low grid's widening in the low ring.
pub const LOD_WIDEN_RANGE: std::ops::RangeInclusive<f32> = 1.0..=4.0;
/// The default widening of the low grid's blades in the low ring: none. Widened, the low ring
/// comes nearer the truth's cover, but its blades then meet the far field at the view distance
/// with a colour step the eye sees (the far field was fitted to the unwidened blades).
pub const DEFAULT_LOD_WIDEN: f32 = 1.0;
/// Metres toward the blades' fade per metre the camera stands above them.
pub const ELEVATION_FADE_RANGE: std::ops::RangeInclusive<f32> = 0.0..=8.0;
/// Blade width scale.
pub const WIDTH_SCALE_RANGE: std::ops::RangeInclusive<f32> = 0.05..=20.0;
/// Each infill radius, metres.
pub const INFILL_RANGE_M: std::ops::RangeInclusive<f32> = 0.0..=100.0;
/// Radius of the near blades, metres.
pub const NEAR_RANGE_M: std::ops::RangeInclusive<f32> = 0.0..=200.0;
/// Terrain LOD factor, tile edges.
pub const LOD_FACTOR_RANGE: std::ops::RangeInclusive<f64> = 0.25..=8.0;
/// Largest terrain mesh step, samples.
pub const MAX_MESH_STEP: u32 = 16;

/// The most grass tiles the rings may reach ([`RendererConfig::validate_for`]): the square of
/// tiles around the camera within the low ring and its hysteresis, as far as the world goes.
/// The truth's reach in the default world is 625 of them, `bench blades`' largest field 10,000;
/// a ring of 10,000 km selected all 393,216 of a large world each frame (1.8 s of CPU) and drew
/// none of them, the pool holding far fewer.
pub const MAX_RING_TILES: u64 = 16_384;
/// Atlas slots [`RendererConfig::for_world`] gives a frame's terrain a level of the pyramid (at
/// LOD factor 1). A frame holds the tiles it draws and their ancestors; along the default
/// world's paths (9 levels) the most was 135, along a 10 km-cell bake's (18 levels) 350: 15 and
/// 19.4 a level, grass tiles and level-0 tiles included.
pub const ATLAS_SLOTS_PER_LEVEL: u32 = 24;
/// The fewest atlas slots [`RendererConfig::for_world`] gives a world.
pub const MIN_DEFAULT_ATLAS_SLOTS: u32 = 256;
/// The most atlas slots [`RendererConfig::for_world`] gives a world: the texture array layers
/// of desktop GPUs (an adapter with fewer refuses more, naming the limit).
pub const MAX_DEFAULT_ATLAS_SLOTS: u32 = 2048;

/// Atlas slots enough for the frames of a world of `pyramid` at terrain LOD factor `lod_factor`: its
/// level-0 tiles, its grass rings' tiles and [`ATLAS_SLOTS_PER_LEVEL`] a level of its pyramid
/// (times the square of `lod_factor` above 1: a tile splits within that many tile edges of the
/// camera), within [`MIN_DEFAULT_ATLAS_SLOTS`]..=[`MAX_DEFAULT_ATLAS_SLOTS`]. Each slot holds one
/// tile (`samples_per_side^2 x 8` bytes of GPU memory: 133 KiB in the default world).
pub fn default_atlas_slots(pyramid: &crate::world::Pyramid, lod_factor: f64) -> u32 {
    let [nx, ny] = pyramid.tiles_at(0);
    let roots = u64::from(nx) * u64::from(ny);
    let grass = u64::from(RingSettings::for_pyramid(pyramid).most_tiles(pyramid));
    let scale = if lod_factor.is_finite() {
        lod_factor.clamp(1.0, *LOD_FACTOR_RANGE.end())
    } else {
        1.0
    };
    let per_level = (f64::from(ATLAS_SLOTS_PER_LEVEL) * scale * scale).ceil() as u64;
    let levels = u64::from(pyramid.level_count());
    let want = roots + 1 + grass + per_level * levels;
    want.clamp(
        u64::from(MIN_DEFAULT_ATLAS_SLOTS),
        u64::from(MAX_DEFAULT_ATLAS_SLOTS),
    ) as u32
}

impl Default for GrassConfig {
    fn default() -> Self {
        Self {
            spacing_m: crate::grass::DEFAULT_SPACING_M,
            width_scale: crate::grass::DEFAULT_WIDTH_SCALE,
            infill_m: DEFAULT_INFILL_M,
            // Picked from bench lod's front against the truth: 7 near segments erred 0.0578
            // where 5 erred 0.0626, for 0.24 ms at 960x540 (NVIDIA H200), the front's knee; 9
            // came with the shorter view distance (DEFAULT_VIEW_TILES), which pays for them.
            segments: [9, 3, 3],
            near_m: 12.0,
            lod_widen: DEFAULT_LOD_WIDEN,
            elevation_fade: crate::terrain::far_field::ELEVATION_DISTANCE,
            capacity: None,
            far_field_under_blades: true,
        }
    }
}

/// A setting of [`RendererConfig`] out of its range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("renderer setting {field} = {value} is out of range: it must be {range}")]
pub struct ConfigError {
    /// The setting, as its field is spelt (e.g. `grass.segments`).
    pub field: &'static str,
    /// The value given.
    pub value: String,
    /// What it must be, with its range and unit.
    pub range: String,
}

impl ConfigError {
    fn new(field: &'static str, value: impl std::fmt::Debug, range: impl Into<String>) -> Self {
        Self {
            field,
            value: format!("{value:?}"),
            range: range.into(),
        }
    }
}

/// The farthest switch between the plants' levels of detail, metres.
pub const MAX_PLANT_LOD_M: f32 = 10_000.0;

/// The farthest the plants' cards reach, in view distances ([`crate::plants::PlantSettings`]).
pub const MAX_CARD_REACH: f32 = 16.0;

/// `value` must lie in `range` (NaN never does); `unit` follows the range in the error.
fn check<T>(
    field: &'static str,
    value: T,
    range: &std::ops::RangeInclusive<T>,
    unit: &str,
) -> Result<(), ConfigError>
where
    T: PartialOrd + std::fmt::Debug + std::fmt::Display,
{
    if range.contains(&value) {
        Ok(())
    } else {
        Err(ConfigError::new(
            field,
            value,
            format!("in {}..={}{unit}", range.start(), range.end()),
        ))
    }
}

/// The longest wait before a failed tile is loaded again, seconds
/// (`service.fault_retry_s`, `service.fault_retry_max_s`; about 31 years).
const MAX_FAULT_RETRY_S: f64 = 1e9;

/// Checks the plants' (`trees` false) or the trees' settings, each field named with its
/// layer's prefix: `capacity` in 1..=[`crate::plants::renderer::max_capacity`]`(1)`,
/// `0 < near <= far <=` [`MAX_PLANT_LOD_M`], `band_m` 0..=[`MAX_PLANT_LOD_M`], the cards'
/// reach 1 to [`MAX_CARD_REACH`] view distances, `thin_m` above 0 and at most
/// [`MAX_PLANT_LOD_M`], `min_keep` above 0 and at most 1, `cell_m`
/// [`crate::plants::PLANT_CELL_M`] to 64 m; the trees' `view_m` (the plants' follows the
/// grass's) `0 <= START <= END`, END above 0 and at most
/// [`crate::world::manifest::MAX_FOG_DISTANCE_M`].
fn validate_plants(s: &crate::plants::PlantSettings, trees: bool) -> Result<(), ConfigError> {
    macro_rules! field {
        ($name:literal) => {
            if trees {
                concat!("trees.", $name)
            } else {
                concat!("plants.", $name)
            }
        };
    }
    // More than a region of one type's pool holds is never honoured (a layer of more types
    // holds fewer a region, and is given that many).
    let most = crate::plants::renderer::max_capacity(1);
    check(field!("capacity"), s.capacity, &(1..=most), " instances")?;
    let [near, far] = s.lod_m;
    if !(near > 0.0 && near <= far && far <= MAX_PLANT_LOD_M) {
        return Err(ConfigError::new(
            field!("lod_m"),
            s.lod_m,
            format!("NEAR,FAR with 0 < NEAR <= FAR <= {MAX_PLANT_LOD_M} m"),
        ));
    }
    check(field!("band_m"), s.band_m, &(0.0..=MAX_PLANT_LOD_M), " m")?;
    if !(1.0..=MAX_CARD_REACH).contains(&s.card_reach) {
        return Err(ConfigError::new(
            field!("card_reach"),
            s.card_reach,
            format!("1 to {MAX_CARD_REACH} view distances"),
        ));
    }
    if !(s.thin_m > 0.0 && s.thin_m <= MAX_PLANT_LOD_M) {
        return Err(ConfigError::new(
            field!("thin_m"),
            s.thin_m,
            format!("above 0, at most {MAX_PLANT_LOD_M} m"),
        ));
    }
    if !(s.min_keep > 0.0 && s.min_keep <= 1.0) {
        return Err(ConfigError::new(
            field!("min_keep"),
            s.min_keep,
            "above 0, at most 1",
        ));
    }
    let cell = crate::plants::PLANT_CELL_M;
    if !(s.cell_m >= cell && s.cell_m <= 64.0) {
        return Err(ConfigError::new(
            field!("cell_m"),
            s.cell_m,
            format!("{cell} to 64 m"),
        ));
    }
    if trees {
        let [start, end] = s.view_m;
        let most = crate::world::manifest::MAX_FOG_DISTANCE_M as f32;
        if !(start >= 0.0 && start <= end && end > 0.0 && end <= most) {
            return Err(ConfigError::new(
                "trees.view_m",
                s.view_m,
                format!("START,END with 0 <= START <= END, 0 < END <= {most} m"),
            ));
        }
    }
    Ok(())
}

impl RendererConfig {
    /// Defaults for `world`: among them an atlas of [`default_atlas_slots`] slots, sized to its
    /// pyramid.
    pub fn for_world(world: &World) -> Self {
        Self {
            service: ServiceConfig {
                atlas_slots: default_atlas_slots(&world.manifest.pyramid, 1.0),
                ..ServiceConfig::default()
            },
            lod_factor: 1.0,
            derive: DeriveParams::for_manifest(&world.manifest),
            grass_rings: Some(RingSettings::for_pyramid(&world.manifest.pyramid)),
            grass: GrassConfig::default(),
            mesh_step: DEFAULT_MESH_STEP,
            wind_scene: None,
            wind_keys: Vec::new(),
            features: Features::from(&world.manifest.features),
            aa: AntiAliasing::default(),
            taa: Default::default(),
            plants: Default::default(),
            trees: None,
            tree_shadows: Some(Default::default()),
            particles: Some(Default::default()),
        }
    }

    /// Checks every setting against its range, stated in the error: `lod_factor` in
    /// [`LOD_FACTOR_RANGE`], `mesh_step` a power of two in 1..=[`MAX_MESH_STEP`], the tile
    /// service's per-frame budgets (uploads and derives at least 1 each) and
    /// its waits before a failed tile is loaded again (0..=1e9 s each), the grass rings' radii
    /// (finite, the high radius and the low one above 0, the high one allowed past the low one,
    /// the hysteresis at least 0), the plants' and the trees' settings (pool regions of
    /// 1..=[`crate::plants::renderer::max_capacity`]`(1)` instances, level-of-detail switches
    /// `0 < near <= far <=` [`MAX_PLANT_LOD_M`] with cross-fade bands of
    /// 0..=[`MAX_PLANT_LOD_M`] m, cards' reach 1 to [`MAX_CARD_REACH`] view distances, the start
    /// of their thinning with distance above 0 and at most [`MAX_PLANT_LOD_M`], the fewest kept
    /// above 0 and at most 1, placement cells of [`crate::plants::PLANT_CELL_M`] to 64 m, the
    /// trees' view distances `0 <= START <= END`, END above 0 and at most
    /// [`crate::world::manifest::MAX_FOG_DISTANCE_M`]), the temporal anti-aliasing's history
    /// (2..=256 samples, its clip 0.25..=16 standard deviations, its motion falloff 0..=16) and
    /// [`GrassConfig::validate`].
    /// NaN and infinities are out of every range. What depends on the world is checked by
    /// [`RendererConfig::validate_for`] (the rings' level), and what depends on the adapter
    /// (atlas slots, cache size) by [`crate::Renderer::new`].
    pub fn validate(&self) -> Result<(), ConfigError> {
        check("lod_factor", self.lod_factor, &LOD_FACTOR_RANGE, "")?;
        if !(self.mesh_step.is_power_of_two() && self.mesh_step <= MAX_MESH_STEP) {
            return Err(ConfigError::new(
                "mesh_step",
                self.mesh_step,
                format!("a power of two in 1..={MAX_MESH_STEP}"),
            ));
        }
        check(
            "service.uploads_per_frame",
            self.service.uploads_per_frame,
            &(1..=u32::MAX),
            "",
        )?;
        // Any number: a frame derives at most as many tiles as the atlas has slots (a derived
        // tile takes one), and the derivation's staging textures have a layer for each of
        // those (`Renderer::new` holds the slots to the adapter's texture array layers).
        check(
            "service.derives_per_frame",
            self.service.derives_per_frame,
            &(1..=u32::MAX),
            "",
        )?;
        check(
            "service.fault_retry_s",
            self.service.fault_retry_s,
            &(0.0..=MAX_FAULT_RETRY_S),
            " s",
        )?;
        check(
            "service.fault_retry_max_s",
            self.service.fault_retry_max_s,
            &(0.0..=MAX_FAULT_RETRY_S),
            " s",
        )?;
        if let Some(r) = &self.grass_rings {
            // A high ring reaching past the view distance is allowed: every grass tile in view
            // is then high LOD (the truth's renders draw so). How far a ring may reach depends
            // on the world's grass tiles ([`Self::validate_for`]).
            for (field, value) in [
                ("grass_rings.high_radius_m", r.high_radius_m),
                ("grass_rings.low_radius_m", r.low_radius_m),
            ] {
                if !(value.is_finite() && value > 0.0) {
                    return Err(ConfigError::new(field, value, "finite and above 0 m"));
                }
            }
            if !(r.hysteresis_m.is_finite() && r.hysteresis_m >= 0.0) {
                return Err(ConfigError::new(
                    "grass_rings.hysteresis_m",
                    r.hysteresis_m,
                    "finite and at least 0 m",
                ));
            }
        }
        validate_plants(&self.plants, false)?;
        if let Some(t) = &self.trees {
            validate_plants(t, true)?;
        }
        self.taa.validate()?;
        let checked = [
            self.tree_shadows.map(|s| s.validate()),
            self.particles.map(|p| p.validate()),
        ];
        if let Some(Err((field, value, range))) = checked.into_iter().flatten().find(Result::is_err)
        {
            return Err(ConfigError {
                field,
                value,
                range,
            });
        }
        self.grass.validate()
    }

    /// [`Self::validate`], then what depends on `world` (its pyramid), which
    /// [`crate::Renderer::new`] checks: the grass rings' `level` one of the pyramid's, its
    /// finest (the default) or at most [`crate::lod::MAX_GRASS_LEVELS_UP`] levels coarser
    /// (above the finest there is no data; a coarser grass tile generates four times the blades
    /// a level, all of them every frame).
    pub fn validate_for(&self, world: &World) -> Result<(), ConfigError> {
        self.validate()?;
        if let Some(r) = &self.grass_rings {
            let pyramid = &world.manifest.pyramid;
            let finest = pyramid.max_level();
            let coarsest = finest.saturating_sub(crate::lod::MAX_GRASS_LEVELS_UP);
            if !(coarsest..=finest).contains(&r.level) {
                return Err(ConfigError::new(
                    "grass_rings.level",
                    r.level,
                    format!(
                        "in {coarsest}..={finest}: the world's finest level ({} m grass tiles) \
                         or at most {} levels coarser ({} m)",
                        pyramid.tile_size_m(finest),
                        crate::lod::MAX_GRASS_LEVELS_UP,
                        pyramid.tile_size_m(coarsest),
                    ),
                ));
            }
            let tile_m = pyramid.tile_size_m(r.level);
            let reach = r.low_radius_m + r.hysteresis_m;
            let side = 2.0 * (reach / tile_m).ceil() + 1.0;
            let [nx, ny] = pyramid.tiles_at(r.level).map(f64::from);
            let tiles = side.min(nx) * side.min(ny);
            if tiles > MAX_RING_TILES as f64 {
                // The radius that reaches that many, in a world as wide as this one.
                let half = ((MAX_RING_TILES as f64).sqrt() - 1.0) / 2.0;
                return Err(ConfigError::new(
                    "grass_rings.low_radius_m",
                    r.low_radius_m,
                    format!(
                        "small enough that the rings reach at most {MAX_RING_TILES} of the \
                         world's {tile_m} m grass tiles (with the hysteresis of {} m they reach \
                         {tiles}): about {} m at most",
                        r.hysteresis_m,
                        (half.floor() * tile_m - r.hysteresis_m).max(0.0)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The trees' settings for `world`: [`Self::trees`], else
    /// [`crate::plants::PlantSettings::trees`] for its grass tiles and fog. `None` without
    /// grass rings.
    pub fn tree_settings(&self, world: &World) -> Option<crate::plants::PlantSettings> {
        let grass = self.grass_settings(world)?;
        Some(self.trees.unwrap_or_else(|| {
            crate::plants::PlantSettings::trees(grass.tile_m, world.manifest.sky.fog_distance_m)
        }))
    }

    /// Grass settings that follow the rings: blades the low grid drops fade out over the outer
    /// 30% of the high ring, and all blades thin out, dithered, over the last 20% of the view
    /// distance. `None` without grass rings.
    pub fn grass_settings(&self, world: &World) -> Option<GrassSettings> {
        let rings = self.grass_rings?;
        let g = &self.grass;
        Some(GrassSettings {
            spacing_m: g.spacing_m,
            width_scale: g.width_scale,
            tile_m: world.manifest.pyramid.tile_size_m(rings.level) as f32,
            high_radius_m: rings.high_radius_m as f32,
            lod_fade_m: 0.3 * rings.high_radius_m as f32,
            infill_m: g.infill_m,
            view_distance_m: rings.low_radius_m as f32,
            far_fade_m: 0.2 * rings.low_radius_m as f32,
            clump_m: 1.6,
            short_m: crate::world::grass_density::SHORT_GRASS_M,
            seed: 0x9a55,
            segments: g.segments,
            near_m: g.near_m,
            lod_widen: g.lod_widen,
            elevation_fade: g.elevation_fade,
            far_field_under_blades: g.far_field_under_blades,
        })
    }
}

impl crate::aa::taa::TaaSettings {
    /// Checks every setting of the temporal method against its range, stated in the error:
    /// `max_samples` 2..=256, `clip_sigma` 0.25..=16, the falloffs and `pixel_spread` 0..=16,
    /// `min_samples` 1..=`max_samples`, `reconstruct_px` 0..=2, `cut_zoom` 1..=1e6.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check("taa.max_samples", self.max_samples, &(2..=256), "")?;
        check("taa.clip_sigma", self.clip_sigma, &(0.25..=16.0), "")?;
        check("taa.motion_falloff", self.motion_falloff, &(0.0..=16.0), "")?;
        check("taa.pixel_spread", self.pixel_spread, &(0.0..=16.0), "")?;
        check(
            "taa.parallax_falloff",
            self.parallax_falloff,
            &(0.0..=16.0),
            "",
        )?;
        check("taa.sway_falloff", self.sway_falloff, &(0.0..=16.0), "")?;
        check(
            "taa.min_samples",
            self.min_samples,
            &(1.0..=self.max_samples as f32),
            " (at most taa.max_samples)",
        )?;
        check(
            "taa.reconstruct_px",
            self.reconstruct_px,
            &(0.0..=2.0),
            " pixels",
        )?;
        check("taa.cut_zoom", self.cut_zoom, &(1.0..=1e6), " times")?;
        Ok(())
    }
}

impl GrassConfig {
    /// Checks every grass setting against its range, stated in the error: `spacing_m` in
    /// [`SPACING_RANGE_M`], `width_scale` in [`WIDTH_SCALE_RANGE`], each of `infill_m` in
    /// [`INFILL_RANGE_M`] with the second no larger than the first, each of `segments` in
    /// 1..=[`GrassSettings::MAX_SEGMENTS`], `near_m` in [`NEAR_RANGE_M`], `lod_widen` in
    /// [`LOD_WIDEN_RANGE`], `capacity` at least 1.
    pub fn validate(&self) -> Result<(), ConfigError> {
        check("grass.spacing_m", self.spacing_m, &SPACING_RANGE_M, " m")?;
        check(
            "grass.width_scale",
            self.width_scale,
            &WIDTH_SCALE_RANGE,
            "",
        )?;
        let [half, quarter] = self.infill_m;
        if !(INFILL_RANGE_M.contains(&half) && INFILL_RANGE_M.contains(&quarter)) {
            return Err(ConfigError::new(
                "grass.infill_m",
                self.infill_m,
                format!(
                    "in {}..={} m each",
                    INFILL_RANGE_M.start(),
                    INFILL_RANGE_M.end()
                ),
            ));
        }
        if quarter > half {
            return Err(ConfigError::new(
                "grass.infill_m",
                self.infill_m,
                "HALF,QUARTER with the quarter-spacing radius no larger than the half-spacing one",
            ));
        }
        let most = GrassSettings::MAX_SEGMENTS;
        if !self.segments.iter().all(|s| (1..=most).contains(s)) {
            return Err(ConfigError::new(
                "grass.segments",
                self.segments,
                format!("in 1..={most} each"),
            ));
        }
        check("grass.near_m", self.near_m, &NEAR_RANGE_M, " m")?;
        check("grass.lod_widen", self.lod_widen, &LOD_WIDEN_RANGE, "")?;
        check(
            "grass.elevation_fade",
            self.elevation_fade,
            &ELEVATION_FADE_RANGE,
            " m a metre",
        )?;
        if let Some(c) = self.capacity {
            check("grass.capacity", c, &(1..=u32::MAX), " blades")?;
        }
        Ok(())
    }
}

/// The caller's targets and the engine's settings.
#[derive(Clone, Debug)]
pub struct RendererOptions {
    /// Format of the colour target.
    pub color_format: wgpu::TextureFormat,
    /// Format of the depth target (one of [`super::DEPTH_FORMATS`]).
    pub depth_format: wgpu::TextureFormat,
    /// Width of the targets in pixels.
    pub width: u32,
    /// Height of the targets in pixels.
    pub height: u32,
    /// Settings of the engine.
    pub config: RendererConfig,
}

impl RendererOptions {
    /// Targets of these formats and size, and the defaults of `world`.
    pub fn new(
        world: &World,
        color_format: wgpu::TextureFormat,
        depth_format: wgpu::TextureFormat,
        width: u32,
        height: u32,
    ) -> Self {
        Self {
            color_format,
            depth_format,
            width,
            height,
            config: RendererConfig::for_world(world),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn world() -> World {
        World::open(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz"))
            .unwrap()
    }

    #[test]
    fn the_default_atlas_grows_with_the_pyramids_levels() {
        let world = world();
        let p = world.manifest.pyramid.clone();
        // The default world (9 levels) keeps the 256 slots its paths were measured with.
        assert_eq!(p.level_count(), 9);
        assert_eq!(RendererConfig::for_world(&world).service.atlas_slots, 256);
        // A world of 18 levels held 350 tiles along its wind tour: it gets room for them.
        let deep = crate::world::Pyramid {
            derived_levels: 15,
            ..p.clone()
        };
        let [nx, ny] = deep.tiles_at(0);
        let grass = RingSettings::for_pyramid(&deep).most_tiles(&deep);
        let slots = default_atlas_slots(&deep, 1.0);
        assert_eq!(slots, nx * ny + 1 + grass + 18 * ATLAS_SLOTS_PER_LEVEL);
        assert!(slots >= 400, "{slots}");
        // Twice the LOD factor splits tiles within twice the distance: four times the slots a level.
        let wide = default_atlas_slots(&deep, 2.0);
        assert_eq!(wide, nx * ny + 1 + grass + 18 * 4 * ATLAS_SLOTS_PER_LEVEL);
        // A factor below 1 keeps the slots of 1; NaN too. The bounds hold.
        assert_eq!(default_atlas_slots(&deep, 0.25), slots);
        assert_eq!(default_atlas_slots(&deep, f64::NAN), slots);
        let deepest = crate::world::Pyramid {
            derived_levels: 200,
            ..p
        };
        assert_eq!(default_atlas_slots(&deepest, 8.0), MAX_DEFAULT_ATLAS_SLOTS);
    }

    #[test]
    fn every_setting_out_of_range_names_its_field_and_range() {
        let base = RendererConfig::for_world(&world());
        base.validate().unwrap();
        let with = |f: &dyn Fn(&mut RendererConfig)| {
            let mut c = base.clone();
            f(&mut c);
            c
        };
        let cases: Vec<(RendererConfig, &str, &str)> = vec![
            (with(&|c| c.lod_factor = 0.0), "lod_factor", "0.25..=8"),
            (with(&|c| c.lod_factor = f64::NAN), "lod_factor", "0.25..=8"),
            (
                with(&|c| c.mesh_step = 3),
                "mesh_step",
                "power of two in 1..=16",
            ),
            (
                with(&|c| c.mesh_step = 0),
                "mesh_step",
                "power of two in 1..=16",
            ),
            (
                with(&|c| c.service.derives_per_frame = 0),
                "service.derives_per_frame",
                "1..=4294967295",
            ),
            (
                with(&|c| c.service.uploads_per_frame = 0),
                "service.uploads_per_frame",
                "1..=4294967295",
            ),
            (
                with(&|c| c.grass_rings.as_mut().unwrap().high_radius_m = 0.0),
                "grass_rings.high_radius_m",
                "above 0 m",
            ),
            (
                with(&|c| c.grass_rings.as_mut().unwrap().low_radius_m = f64::INFINITY),
                "grass_rings.low_radius_m",
                "finite",
            ),
            (
                with(&|c| c.grass_rings.as_mut().unwrap().low_radius_m = 0.0),
                "grass_rings.low_radius_m",
                "above 0 m",
            ),
            (
                with(&|c| c.grass_rings.as_mut().unwrap().hysteresis_m = -1.0),
                "grass_rings.hysteresis_m",
                "at least 0 m",
            ),
            (
                with(&|c| c.grass_rings.as_mut().unwrap().hysteresis_m = f64::NAN),
                "grass_rings.hysteresis_m",
                "finite",
            ),
            (
                with(&|c| c.grass.spacing_m = 0.01),
                "grass.spacing_m",
                "0.02..=5 m",
            ),
            (
                with(&|c| c.grass.width_scale = f32::NAN),
                "grass.width_scale",
                "0.05..=20",
            ),
            (
                with(&|c| c.grass.infill_m = [101.0, 0.0]),
                "grass.infill_m",
                "0..=100 m each",
            ),
            (
                with(&|c| c.grass.infill_m = [10.0, 20.0]),
                "grass.infill_m",
                "no larger than the half-spacing one",
            ),
            (
                with(&|c| c.grass.segments = [5, 65, 3]),
                "grass.segments",
                "1..=64 each",
            ),
            (
                with(&|c| c.grass.segments = [0, 3, 3]),
                "grass.segments",
                "1..=64 each",
            ),
            (
                with(&|c| c.grass.near_m = -1.0),
                "grass.near_m",
                "0..=200 m",
            ),
            (
                with(&|c| c.grass.capacity = Some(0)),
                "grass.capacity",
                "1..=4294967295 blades",
            ),
            (
                with(&|c| c.taa.max_samples = 1),
                "taa.max_samples",
                "2..=256",
            ),
            (
                with(&|c| c.taa.clip_sigma = f32::NAN),
                "taa.clip_sigma",
                "0.25..=16",
            ),
            (
                with(&|c| c.taa.cut_zoom = 0.5),
                "taa.cut_zoom",
                "1..=1000000 times",
            ),
            (
                with(&|c| c.taa.min_samples = 0.5),
                "taa.min_samples",
                "1..=24 (at most taa.max_samples)",
            ),
            (
                with(&|c| {
                    c.taa.max_samples = 4;
                    c.taa.min_samples = 5.0;
                }),
                "taa.min_samples",
                "1..=4 (at most taa.max_samples)",
            ),
            (
                with(&|c| c.taa.reconstruct_px = 2.5),
                "taa.reconstruct_px",
                "0..=2 pixels",
            ),
            (
                with(&|c| c.taa.sway_falloff = -1.0),
                "taa.sway_falloff",
                "0..=16",
            ),
        ];
        for (config, field, range) in cases {
            let e = config.validate().unwrap_err();
            assert_eq!(e.field, field, "{e}");
            let text = e.to_string();
            assert!(text.contains(field) && text.contains(range), "{text}");
        }
    }

    #[test]
    fn settings_that_new_and_prepare_rely_on_are_refused() {
        // Each of these passed before and then panicked or hung in `Renderer::new` or
        // `prepare` (or went silently into the shaders).
        let world = world();
        let base = RendererConfig::for_world(&world);
        let trees = base.tree_settings(&world).unwrap();
        let with = |f: &dyn Fn(&mut RendererConfig)| {
            let mut c = base.clone();
            f(&mut c);
            c
        };
        let with_trees = |f: &dyn Fn(&mut crate::plants::PlantSettings)| {
            let mut c = base.clone();
            let mut t = trees;
            f(&mut t);
            c.trees = Some(t);
            c
        };
        let most = crate::plants::renderer::max_capacity(1);
        assert_eq!(most, 1_398_096, "README.md states this figure");
        let capacity = format!("in 1..={most} instances");
        let cases: Vec<(RendererConfig, &str, &str)> = vec![
            (
                with(&|c| c.service.fault_retry_s = f64::NAN),
                "service.fault_retry_s",
                "in 0..=1000000000 s",
            ),
            (
                with(&|c| c.service.fault_retry_max_s = -1.0),
                "service.fault_retry_max_s",
                "in 0..=1000000000 s",
            ),
            (
                with(&|c| c.plants.capacity = u32::MAX),
                "plants.capacity",
                &capacity,
            ),
            (
                with(&|c| c.plants.capacity = 0),
                "plants.capacity",
                &capacity,
            ),
            (
                with_trees(&|t| t.capacity = u32::MAX),
                "trees.capacity",
                &capacity,
            ),
            (
                with(&|c| c.plants.cell_m = 0.0),
                "plants.cell_m",
                "0.5 to 64 m",
            ),
            (
                with(&|c| c.plants.cell_m = 1e-3),
                "plants.cell_m",
                "0.5 to 64 m",
            ),
            (
                with(&|c| c.plants.cell_m = f32::NAN),
                "plants.cell_m",
                "0.5 to 64 m",
            ),
            (
                with(&|c| c.plants.band_m = f32::NAN),
                "plants.band_m",
                "in 0..=10000 m",
            ),
            (
                with(&|c| c.plants.band_m = -50.0),
                "plants.band_m",
                "in 0..=10000 m",
            ),
            (
                with(&|c| c.plants.min_keep = 0.0),
                "plants.min_keep",
                "above 0, at most 1",
            ),
            (
                with_trees(&|t| t.band_m = 1e30),
                "trees.band_m",
                "in 0..=10000 m",
            ),
            (
                with_trees(&|t| t.card_reach = f32::NAN),
                "trees.card_reach",
                "1 to 16 view distances",
            ),
            (
                with_trees(&|t| t.view_m = [f32::NAN; 2]),
                "trees.view_m",
                "0 <= START <= END",
            ),
            (
                with_trees(&|t| t.view_m = [200.0, 100.0]),
                "trees.view_m",
                "0 <= START <= END",
            ),
            (
                with_trees(&|t| t.view_m = [0.0, f32::INFINITY]),
                "trees.view_m",
                "0 < END <=",
            ),
            (
                with_trees(&|t| t.cell_m = 0.1),
                "trees.cell_m",
                "0.5 to 64 m",
            ),
        ];
        for (config, field, range) in cases {
            let e = config.validate().unwrap_err();
            assert_eq!(e.field, field, "{e}");
            let text = e.to_string();
            assert!(text.contains(field) && text.contains(range), "{text}");
        }
        // The bounds themselves are taken.
        let mut c = with_trees(&|t| {
            t.capacity = most;
            t.band_m = MAX_PLANT_LOD_M;
            t.view_m = [0.0, 1.0];
            t.cell_m = 64.0;
        });
        c.plants.capacity = 1;
        c.plants.band_m = 0.0;
        c.plants.cell_m = crate::plants::PLANT_CELL_M;
        c.plants.min_keep = 1.0;
        c.service.derives_per_frame = u32::MAX;
        c.service.fault_retry_s = 0.0;
        c.service.fault_retry_max_s = MAX_FAULT_RETRY_S;
        c.validate().unwrap();
        // The plants' view distance follows the grass's: its own is not looked at.
        with(&|c| c.plants.view_m = [f32::NAN; 2])
            .validate()
            .unwrap();
    }

    #[test]
    fn the_rings_level_is_the_worlds_finest_or_a_little_coarser() {
        let world = world();
        let base = RendererConfig::for_world(&world);
        base.validate_for(&world).unwrap();
        let finest = world.manifest.pyramid.max_level();
        assert_eq!(finest, 8);
        let at = |level: u8| {
            let mut c = base.clone();
            c.grass_rings.as_mut().unwrap().level = level;
            c
        };
        at(finest - crate::lod::MAX_GRASS_LEVELS_UP)
            .validate_for(&world)
            .unwrap();
        for level in [0, finest - 3, finest + 1, 200] {
            let c = at(level);
            // The world-free checks cannot tell.
            c.validate().unwrap();
            let e = c.validate_for(&world).unwrap_err();
            assert_eq!(e.field, "grass_rings.level", "{e}");
            assert_eq!(e.value, level.to_string());
            let text = e.to_string();
            let want = "in 6..=8: the world's finest level (50 m grass tiles) \
                        or at most 2 levels coarser (200 m)";
            assert!(text.contains(want), "{text}");
        }
        // Without grass there is no level to check; the world-free checks still run.
        let mut c = at(200);
        c.grass_rings = None;
        c.validate_for(&world).unwrap();
        c.lod_factor = f64::NAN;
        assert_eq!(c.validate_for(&world).unwrap_err().field, "lod_factor");
    }

    /// Rings reach at most MAX_RING_TILES of the world's grass tiles (a ring of 10,000 km
    /// selected every grass tile of the world each frame, 1.8 s of CPU, and drew none); the
    /// truth's reach is well within it.
    #[test]
    fn the_rings_reach_a_bounded_number_of_grass_tiles() {
        let world = world();
        let base = RendererConfig::for_world(&world);
        let truth = crate::tools::truth::truth_config(&world, &base, 256);
        truth.validate_for(&world).unwrap();
        // A high ring past the view distance draws every tile in view high: allowed.
        let mut c = base.clone();
        c.grass_rings.as_mut().unwrap().high_radius_m = 1e7;
        c.validate_for(&world).unwrap();
        for low in [1e7, 3200.0] {
            let mut c = base.clone();
            c.grass_rings.as_mut().unwrap().low_radius_m = low;
            c.validate().unwrap();
            let e = c.validate_for(&world).unwrap_err();
            assert_eq!(e.field, "grass_rings.low_radius_m", "{e}");
            assert!(
                e.to_string()
                    .contains("at most 16384 of the world's 50 m grass tiles"),
                "{e}"
            );
        }
    }

    #[test]
    fn the_range_bounds_are_taken_and_no_grass_skips_the_grass_checks() {
        let base = RendererConfig::for_world(&world());
        let mut c = base.clone();
        c.lod_factor = 8.0;
        c.mesh_step = 16;
        c.grass.spacing_m = 0.02;
        c.grass.width_scale = 20.0;
        c.grass.infill_m = [0.0, 0.0];
        c.grass.segments = [GrassSettings::MAX_SEGMENTS, 1, 1];
        c.grass.near_m = 200.0;
        c.grass.capacity = Some(1);
        c.taa.max_samples = 256;
        c.taa.clip_sigma = 0.25;
        c.taa.min_samples = 256.0;
        c.taa.reconstruct_px = 2.0;
        c.taa.sway_falloff = 16.0;
        c.validate().unwrap();
        let mut c = base;
        c.grass_rings = None;
        c.validate().unwrap();
    }

    #[test]
    fn grass_settings_carry_the_grass_config_and_the_world_s_rings() {
        let world = world();
        let mut c = RendererConfig::for_world(&world);
        c.grass.segments = [7, 4, 2];
        c.grass.spacing_m = 0.3;
        let s = c.grass_settings(&world).unwrap();
        assert_eq!(s.segments, [7, 4, 2]);
        assert_eq!(s.spacing_m, 0.3);
        let rings = c.grass_rings.unwrap();
        assert_eq!(
            s.tile_m,
            world.manifest.pyramid.tile_size_m(rings.level) as f32
        );
        c.grass_rings = None;
        assert!(c.grass_settings(&world).is_none());
    }
}
