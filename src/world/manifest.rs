//! The world manifest, `worlds/NAME/world.toml`: extent, tile pyramid, height range, grass types,
//! wind and sky defaults, named camera paths and named wind scenes. Parsed with serde, then checked by
//! [`Manifest::validate`] so that a world that asks for too much is refused before anything is
//! loaded.
//!
//! Conventions: positions in metres with x east, y north, z up, from the world's south-west
//! corner; angles in degrees counter-clockwise from east (0 = east, 90 = north), the same for
//! camera yaw, sun azimuth and wind direction; colours are linear RGB in 0..=1.
//!
//! Every number is checked: NaN and infinities are refused, and so is any value beyond the
//! range its field documents (the limits are the `MAX_*` constants of this module), with the
//! field and the range named in the error. The ranges are wide enough for any real world and
//! keep the f32 arithmetic of the renderer exact enough: a wind of 1e30 m/s, say, would
//! otherwise overflow to NaN on the GPU and be drawn as calm.

use std::collections::HashSet;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::features::{Feature, Features};

use super::dem::DemFormat;
use super::error::WorldError;
use super::tile::Pyramid;

/// Most root tiles (x times y) a world may have.
pub const MAX_ROOT_TILES: u64 = 4096;
/// Most tiles a world may have at its finest stored level.
pub const MAX_FINEST_TILES: u64 = 1_000_000;
/// Largest extent a world may have along either axis, metres.
pub const MAX_EXTENT_M: f64 = 10_000_000.0;
/// Largest root tile, metres (`pyramid.root_tile_size_m`).
pub const MAX_ROOT_TILE_M: f64 = 100_000_000.0;
/// Most grass types a world may have: the renderer's table of types holds this many, so a type
/// index beyond it could not be drawn as its own type.
pub const MAX_GRASS_TYPES: usize = 16;
/// Tallest grass blade, metres (`grass_types[].height_m`, `grass_peak.short_m`).
pub const MAX_BLADE_HEIGHT_M: f64 = 10.0;
/// Widest grass blade at its root, metres (`grass_types[].width_m`).
pub const MAX_BLADE_WIDTH_M: f64 = 1.0;
/// Largest sunlight colour component (`sky.sun_color`, which may exceed 1 for intensity);
/// every other colour is in 0..=1.
pub const MAX_SUN_INTENSITY: f64 = 100.0;
/// Fastest wind, metres per second: every wind speed of the manifest (`wind.speed_mps`, a
/// scene's `ambient.speed_mps`, a source's `speed_mps`, and `inflow_mps` either way). Above
/// the strongest gust measured on Earth (113 m/s).
pub const MAX_WIND_SPEED_MPS: f64 = 120.0;
/// Largest wind source strength factor (`strength` keys' second value).
pub const MAX_WIND_STRENGTH: f64 = 10.0;
/// Largest reach of an omni or vortex wind source, metres (`radius_m`).
pub const MAX_WIND_RADIUS_M: f64 = 10_000.0;
/// Largest angle, degrees, either way: wind directions, sun azimuth and camera yaw (a hundred
/// turns: room for the unwrapped yaw of a path that circles, and still exact in f32).
pub const MAX_ANGLE_DEG: f64 = 36_000.0;
/// Longest time, seconds, either way: path durations and key times, wind source start and
/// strength key times, and blends (about eleven and a half days).
pub const MAX_TIME_S: f64 = 1_000_000.0;
/// Farthest position, metres either way along each axis: camera keys and wind sources (twice
/// the largest extent, so that paths may start well outside the world).
pub const MAX_POSITION_M: f64 = 2.0 * MAX_EXTENT_M;
/// Farthest fog distance, metres (`sky.fog_distance_m`).
pub const MAX_FOG_DISTANCE_M: f64 = MAX_EXTENT_M;
/// Largest magnitude of the `[derive]` table's log2 figures (`hurst`, `fit_rms_log2`,
/// `decay_log2`): beyond any fit of f32 heights.
pub const MAX_DERIVE_LOG2: f64 = 300.0;
/// Largest `[source]` coordinate (`origin`, in the DEM's own units) in magnitude.
pub const MAX_SOURCE_COORDINATE: f64 = 1e9;

/// The manifest of a world (`world.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Short name, e.g. `santa-cruz`.
    pub name: String,
    /// What the world is and where its data comes from.
    #[serde(default)]
    pub description: String,
    /// Size of the data area from the SW corner, metres (x, y); may be smaller than the root
    /// grid, whose remainder repeats the data's edge.
    pub extent_m: [f64; 2],
    /// The tile pyramid.
    pub pyramid: Pyramid,
    /// Lowest and highest stored height, metres.
    pub height_range_m: [f32; 2],
    /// Grass types; index 0 is bare ground. Tile type maps index into this list. At least 1
    /// and at most [`MAX_GRASS_TYPES`] (16).
    #[serde(default)]
    pub grass_types: Vec<GrassType>,
    /// Default wind.
    #[serde(default)]
    pub wind: WindDefaults,
    /// Sun, sky and fog.
    #[serde(default)]
    pub sky: Sky,
    /// Named camera paths; the first is the default.
    #[serde(default)]
    pub paths: Vec<CameraPath>,
    /// Named wind scenes: an ambient wind and the wind sources acting in it.
    #[serde(default)]
    pub wind_scenes: Vec<WindScene>,
    /// Which features of the grass model are on (all by default; the command line can switch
    /// more off).
    #[serde(default)]
    pub features: FeatureSwitches,
    /// Where the world's terrain came from (written by the baker; absent in worlds baked
    /// before it was recorded, and in hand-made ones).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<WorldSource>,
    /// How derived levels (finer than the stored data) add detail, fitted by the baker to the
    /// world's own stored pyramid. Absent in worlds baked before the fit: every derived level
    /// then adds detail at [`LEGACY_DETAIL`], as those worlds always did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub derive: Option<DeriveCalibration>,
    /// The densest grass of the finest stored level, which sizes the grass pool; written by the
    /// baker. Without it (older worlds) the renderer reads the finest tiles to estimate it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grass_peak: Option<super::GrassPeak>,
}

/// The `[source]` table: the DEM a world was baked from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSource {
    /// The DEM's file name (without its folder).
    pub file: String,
    /// Its format.
    pub format: DemFormat,
    /// Its coordinate system, in words (e.g. `EPSG:4326, geographic (degrees)`); empty where
    /// the file does not say.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub crs: String,
    /// The DEM's south-west sample in that coordinate system (x or longitude first), where the
    /// file gives it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub origin: Option<[f64; 2]>,
    /// Samples in the DEM, west-east and south-north.
    pub samples: [u32; 2],
    /// Spacing of the DEM's samples in metres, east-west and north-south.
    pub cell_size_m: [f64; 2],
    /// Nodata samples filled from the heights around them.
    #[serde(default)]
    pub nodata_filled: u64,
}

/// Detail amplitude of every derived level in a world whose manifest has no `[derive]` table
/// (child cells per unit of slope): the one value used before worlds were calibrated.
pub const LEGACY_DETAIL: f32 = 0.25;

/// Largest detail amplitude a `[derive]` table may ask for (child cells per unit of slope).
pub const MAX_DETAIL: f32 = 100.0;

/// The `[derive]` table: the detail that each derived level adds to the Catmull-Rom
/// upsampling of its parent, fitted to the world's stored pyramid (see
/// `crate::stream::calibrate`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeriveCalibration {
    /// `fractal`: derived levels add detail at `detail`; `bicubic`: the fit was poor (too few
    /// levels, flat or irregular terrain) and derived levels are plain Catmull-Rom.
    pub method: DeriveMode,
    /// What the fit found, or why it fell back to plain bicubic.
    pub note: String,
    /// Octaves measured: stored levels, and subsamples of the coarsest one, each predicted
    /// from the next coarser.
    pub octaves: u32,
    /// Fitted Hurst exponent: the RMS residual between a level and the Catmull-Rom prediction
    /// from its parent grows by `2^hurst` per octave coarser.
    pub hurst: f64,
    /// RMS deviation of the measured log2 residuals from the fitted line (0 = a perfect
    /// fractal).
    pub fit_rms_log2: f64,
    /// RMS residual at the finest stored level, metres.
    pub residual_rms_m: f64,
    /// Fall (log2) of the amplitude per octave finer with which each derived level's
    /// amplitude, measured as many octaves above the data as it lies below, was carried down
    /// to its own scale (0 on scale-invariant terrain). Informational; absent in worlds baked
    /// before it was recorded.
    #[serde(default)]
    pub decay_log2: f64,
    /// Detail amplitude of each derived level, the first derived level first (child cells per
    /// unit of slope; the roughness-matching amplitude measured per stored octave and
    /// extrapolated). One per derived level; all zero for `bicubic`.
    pub detail: Vec<f32>,
}

/// How derived levels are made.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeriveMode {
    /// Catmull-Rom plus slope-scaled detail noise at the fitted amplitudes.
    Fractal,
    /// Catmull-Rom alone.
    Bicubic,
}

/// The `[features]` table: each feature of the grass model on or off (all on by default). The
/// keys are the feature names of the command line's `--disable`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default, rename_all = "kebab-case")]
pub struct FeatureSwitches {
    /// Wind sources on top of the ambient wind.
    pub wind_sources: bool,
    /// The trail a walker leaves in the grass.
    pub interaction: bool,
    /// Edge flutter and whole-blade sway.
    pub detail_bending: bool,
    /// Light through the blade when the sun is behind it.
    pub translucency: bool,
    /// Specular highlights with per-type gloss.
    pub specular: bool,
    /// Ambient occlusion from root to tip.
    pub ambient_occlusion: bool,
    /// Colour variation from world-space noise at the blade's root.
    pub color_variation: bool,
    /// Ground darkened under dense grass.
    pub ground_darkening: bool,
    /// The terrain beyond the grass shaded with what the blades would show.
    pub far_field: bool,
    /// Sun shadows cast by the terrain.
    pub shadows: bool,
}

impl Default for FeatureSwitches {
    fn default() -> Self {
        Self::from(Features::all())
    }
}

impl From<Features> for FeatureSwitches {
    fn from(f: Features) -> Self {
        Self {
            wind_sources: f.has(Feature::WindSources),
            interaction: f.has(Feature::Interaction),
            detail_bending: f.has(Feature::DetailBending),
            translucency: f.has(Feature::Translucency),
            specular: f.has(Feature::Specular),
            ambient_occlusion: f.has(Feature::AmbientOcclusion),
            color_variation: f.has(Feature::ColorVariation),
            ground_darkening: f.has(Feature::GroundDarkening),
            far_field: f.has(Feature::FarField),
            shadows: f.has(Feature::Shadows),
        }
    }
}

impl From<&FeatureSwitches> for Features {
    fn from(s: &FeatureSwitches) -> Self {
        let on = [
            (Feature::WindSources, s.wind_sources),
            (Feature::Interaction, s.interaction),
            (Feature::DetailBending, s.detail_bending),
            (Feature::Translucency, s.translucency),
            (Feature::Specular, s.specular),
            (Feature::AmbientOcclusion, s.ambient_occlusion),
            (Feature::ColorVariation, s.color_variation),
            (Feature::GroundDarkening, s.ground_darkening),
            (Feature::FarField, s.far_field),
            (Feature::Shadows, s.shadows),
        ];
        on.into_iter()
            .filter(|(_, on)| !on)
            .fold(Features::all(), |f, (feature, _)| f.without(feature))
    }
}

/// One kind of grass (or, at index 0, bare ground). A world has at most [`MAX_GRASS_TYPES`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrassType {
    /// Name, e.g. `meadow`.
    pub name: String,
    /// Colour of the ground under this type (each component in 0..=1).
    pub ground_color: [f32; 3],
    /// Colour at a blade's root (0..=1).
    pub base_color: [f32; 3],
    /// Colour at a blade's tip (0..=1).
    pub tip_color: [f32; 3],
    /// Blade height range, metres (min, max; 0 <= min <= max <= [`MAX_BLADE_HEIGHT_M`]).
    pub height_m: [f32; 2],
    /// Blade width range at the root, metres (min, max; 0 <= min <= max <=
    /// [`MAX_BLADE_WIDTH_M`]).
    pub width_m: [f32; 2],
    /// Resistance to bending in the wind, 0..=1: 0 bends freely, 1 barely moves.
    pub stiffness: f32,
}

/// Default ambient wind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindDefaults {
    /// Direction the wind blows toward, degrees counter-clockwise from east (within
    /// +-[`MAX_ANGLE_DEG`]).
    pub direction_deg: f32,
    /// Mean speed, metres per second, 0..=[`MAX_WIND_SPEED_MPS`] (120).
    pub speed_mps: f32,
    /// Strength of gusts relative to the mean, 0..=1.
    pub gustiness: f32,
}

impl Default for WindDefaults {
    /// A light westerly breeze: from the west-south-west, blowing toward the east-north-east.
    fn default() -> Self {
        WindDefaults {
            direction_deg: 20.0,
            speed_mps: 4.0,
            gustiness: 0.35,
        }
    }
}

/// Most wind sources a wind scene may have (the wind field's uniform holds this many).
pub const MAX_WIND_SOURCES: usize = 8;

/// A named wind scene: the ambient wind and the sources that act in it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindScene {
    /// Name, unique within the world (e.g. `breeze`).
    pub name: String,
    /// The ambient wind: mean direction and speed, and gustiness.
    #[serde(default)]
    pub ambient: WindDefaults,
    /// Wind sources, summed like lights; at most [`MAX_WIND_SOURCES`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<WindSource>,
}

/// A wind source (a "wind motor"), tagged by `kind`.
///
/// Every kind has the same placement and timing fields: `position_m` (a fixed point) or `path`
/// (the name of a camera path of the world: the source follows that path's positions, looping
/// over its duration), `start_s` (the source acts from this scene time on; path and strength
/// times count from it) and `strength` (keys `[time_s, factor]`, strictly increasing in time,
/// linear in between, held before the first and after the last key; empty means a constant 1;
/// with `repeat` the keys repeat with the last key's time as period).
///
/// Ranges: speeds (`speed_mps` 0..=[`MAX_WIND_SPEED_MPS`], `inflow_mps` either way up to it),
/// `radius_m` above 0 and at most [`MAX_WIND_RADIUS_M`], `direction_deg` within
/// +-[`MAX_ANGLE_DEG`], `position_m` within +-[`MAX_POSITION_M`], `start_s` 0..=[`MAX_TIME_S`],
/// strength key times within +-[`MAX_TIME_S`] and factors 0..=[`MAX_WIND_STRENGTH`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum WindSource {
    /// A uniform wind everywhere (placement is ignored).
    Directional {
        /// Direction the wind blows toward, degrees counter-clockwise from east.
        direction_deg: f64,
        /// Speed, metres per second.
        speed_mps: f64,
        /// Fixed position (unused by this kind; allowed for symmetry).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        position_m: Option<[f64; 2]>,
        /// Camera path followed (unused by this kind; allowed for symmetry).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path: Option<String>,
        /// Scene time the source starts acting, seconds.
        #[serde(default)]
        start_s: f64,
        /// Strength keys `[time_s, factor]` from `start_s`.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        strength: Vec<[f64; 2]>,
        /// Whether the strength keys repeat.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        repeat: bool,
    },
    /// A point blowing outward in every direction: `speed_mps` near the centre, falling off as
    /// `(1 - d / radius)^2` to nothing at `radius_m`.
    Omni {
        /// Reach, metres.
        radius_m: f64,
        /// Outward speed at the centre, metres per second.
        speed_mps: f64,
        /// Fixed position, metres (x east, y north).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        position_m: Option<[f64; 2]>,
        /// Name of the camera path the source follows.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path: Option<String>,
        /// Scene time the source starts acting, seconds.
        #[serde(default)]
        start_s: f64,
        /// Strength keys `[time_s, factor]` from `start_s`.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        strength: Vec<[f64; 2]>,
        /// Whether the strength keys repeat.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        repeat: bool,
    },
    /// A whirl about the vertical axis through its centre: tangential `speed_mps` near the
    /// centre, falling off as `(1 - d / radius)^2`, plus an optional radial `inflow_mps`.
    Vortex {
        /// Reach, metres.
        radius_m: f64,
        /// Tangential speed near the centre, metres per second.
        speed_mps: f64,
        /// Turns clockwise seen from above (default: counter-clockwise).
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        clockwise: bool,
        /// Radial speed toward the centre near it, metres per second (negative: outward, as a
        /// rotor's downwash spreading over the ground).
        #[serde(default, skip_serializing_if = "is_zero")]
        inflow_mps: f64,
        /// Fixed position, metres (x east, y north).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        position_m: Option<[f64; 2]>,
        /// Name of the camera path the source follows.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        path: Option<String>,
        /// Scene time the source starts acting, seconds.
        #[serde(default)]
        start_s: f64,
        /// Strength keys `[time_s, factor]` from `start_s`.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        strength: Vec<[f64; 2]>,
        /// Whether the strength keys repeat.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        repeat: bool,
    },
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// Where a wind source is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SourcePlacement<'a> {
    /// Nowhere in particular (directional sources without a position).
    Everywhere,
    /// A fixed point, metres.
    Fixed([f64; 2]),
    /// Following the named camera path.
    Path(&'a str),
}

/// The fields every kind of wind source has: position, path, start time, strength keys and
/// whether they repeat.
type SourceCommon<'a> = (
    &'a Option<[f64; 2]>,
    &'a Option<String>,
    f64,
    &'a [[f64; 2]],
    bool,
);

impl WindSource {
    /// `directional`, `omni` or `vortex`.
    pub fn kind_name(&self) -> &'static str {
        match self {
            WindSource::Directional { .. } => "directional",
            WindSource::Omni { .. } => "omni",
            WindSource::Vortex { .. } => "vortex",
        }
    }

    fn common(&self) -> SourceCommon<'_> {
        match self {
            WindSource::Directional {
                position_m,
                path,
                start_s,
                strength,
                repeat,
                ..
            }
            | WindSource::Omni {
                position_m,
                path,
                start_s,
                strength,
                repeat,
                ..
            }
            | WindSource::Vortex {
                position_m,
                path,
                start_s,
                strength,
                repeat,
                ..
            } => (position_m, path, *start_s, strength, *repeat),
        }
    }

    /// Where the source is (a path takes precedence over a position; validation refuses both).
    pub fn placement(&self) -> SourcePlacement<'_> {
        match self.common() {
            (_, Some(path), ..) => SourcePlacement::Path(path),
            (Some(p), None, ..) => SourcePlacement::Fixed(*p),
            (None, None, ..) => SourcePlacement::Everywhere,
        }
    }

    /// Scene time the source starts acting, seconds.
    pub fn start_s(&self) -> f64 {
        self.common().2
    }

    /// Strength keys `[time_s, factor]`, times from [`Self::start_s`].
    pub fn strength_keys(&self) -> &[[f64; 2]] {
        self.common().3
    }

    /// Whether the strength keys repeat.
    pub fn repeats(&self) -> bool {
        self.common().4
    }

    /// The source's strength factor at `t_s` seconds after its start: linear between keys,
    /// held outside them, 1 without keys, 0 before the start (`t_s < 0`).
    pub fn strength_at(&self, t_s: f64) -> f64 {
        if t_s < 0.0 {
            return 0.0;
        }
        let keys = self.strength_keys();
        let (Some(first), Some(last)) = (keys.first(), keys.last()) else {
            return 1.0;
        };
        let mut t = t_s;
        if self.repeats() && last[0] > 0.0 {
            t = t.rem_euclid(last[0]);
        }
        if t <= first[0] {
            return first[1];
        }
        for w in keys.windows(2) {
            let ([t0, f0], [t1, f1]) = (w[0], w[1]);
            if t <= t1 {
                let u = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
                return f0 + (f1 - f0) * u;
            }
        }
        last[1]
    }
}

/// Sun, sky and fog.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Sky {
    /// Direction toward the sun, degrees counter-clockwise from east (225 = south-west; within
    /// +-[`MAX_ANGLE_DEG`]).
    pub sun_azimuth_deg: f32,
    /// Sun height above the horizon, degrees, -90..=90.
    pub sun_elevation_deg: f32,
    /// Sunlight colour (linear RGB, may exceed 1 for intensity: 0..=[`MAX_SUN_INTENSITY`]).
    pub sun_color: [f32; 3],
    /// Sky colour overhead (0..=1).
    pub sky_color: [f32; 3],
    /// Sky colour at the horizon, also the fog colour (0..=1).
    pub horizon_color: [f32; 3],
    /// Distance at which fog hides the terrain completely, metres (above 0, at most
    /// [`MAX_FOG_DISTANCE_M`]).
    pub fog_distance_m: f32,
}

impl Default for Sky {
    /// Afternoon sun from the south-west, 35 degrees up, a clear blue sky with a pale horizon.
    fn default() -> Self {
        Sky {
            sun_azimuth_deg: 225.0,
            sun_elevation_deg: 35.0,
            sun_color: [1.0, 0.92, 0.78],
            sky_color: [0.26, 0.46, 0.80],
            horizon_color: [0.72, 0.80, 0.88],
            fog_distance_m: 12_000.0,
        }
    }
}

/// A named camera flight.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraPath {
    /// Name, unique within the world.
    pub name: String,
    /// Length of the flight, seconds (above 0, at most [`MAX_TIME_S`]).
    pub duration_s: f64,
    /// Name of the camera path whose positions leave the trail in the grass while this path is
    /// flown (default: this path itself, the camera).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub walker: Option<String>,
    /// Keys in strictly increasing time order.
    pub keys: Vec<CameraKey>,
    /// The wind scenes of the flight: from each key's time on, the wind is that scene (none: the
    /// scene is chosen per run).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub wind: Vec<WindKey>,
}

/// A change of wind scene along a camera path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindKey {
    /// Time from the start of the path, seconds (within +-[`MAX_TIME_S`]); the scene's source
    /// times count from here.
    pub t_s: f64,
    /// Name of a wind scene of the world.
    pub scene: String,
    /// Seconds over which the ambient wind blends from the previous scene's into this one's
    /// (0..=[`MAX_TIME_S`]).
    #[serde(default = "default_wind_blend")]
    pub blend_s: f64,
}

/// Blend between wind scenes on a path by default, seconds.
pub const DEFAULT_WIND_BLEND_S: f64 = 3.0;

fn default_wind_blend() -> f64 {
    DEFAULT_WIND_BLEND_S
}

/// A camera pose at a time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraKey {
    /// Time from the start of the path, seconds (within +-[`MAX_TIME_S`]).
    pub t_s: f64,
    /// Absolute position, metres (x east, y north, z up; each within +-[`MAX_POSITION_M`]).
    pub position_m: [f64; 3],
    /// Heading, degrees counter-clockwise from east (0 looks east, 90 north; within
    /// +-[`MAX_ANGLE_DEG`]).
    pub yaw_deg: f64,
    /// Degrees above the horizontal, -90..=90; negative looks down.
    pub pitch_deg: f64,
}

/// The largest `world.toml` read, bytes.
pub const MAX_MANIFEST_BYTES: u64 = 16 << 20;

impl Manifest {
    /// Reads, parses and validates a manifest file.
    pub fn from_path(path: &Path) -> Result<Manifest, WorldError> {
        let bytes = super::format::read_regular(path, MAX_MANIFEST_BYTES)?;
        let text = String::from_utf8(bytes).map_err(|e| WorldError::ManifestSyntax {
            path: path.to_path_buf(),
            message: format!("not UTF-8 text: {e}"),
        })?;
        Manifest::parse(&text, path)
    }

    /// Parses and validates manifest text; `path` is only used in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Manifest, WorldError> {
        let manifest: Manifest = toml::from_str(text).map_err(|e| WorldError::ManifestSyntax {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        manifest.validate(path)?;
        Ok(manifest)
    }

    /// The manifest as TOML text, as written to `world.toml`.
    pub fn to_toml(&self) -> String {
        // Every field is a plain string, number or array: serialisation cannot fail.
        toml::to_string(self).unwrap_or_default()
    }

    /// The camera path called `name`.
    pub fn path(&self, name: &str) -> Option<&CameraPath> {
        self.paths.iter().find(|p| p.name == name)
    }

    /// The wind scene called `name`.
    pub fn wind_scene(&self, name: &str) -> Option<&WindScene> {
        self.wind_scenes.iter().find(|s| s.name == name)
    }

    /// Checks that every value is finite and within what the format supports; `path` is only
    /// used in error messages.
    pub fn validate(&self, path: &Path) -> Result<(), WorldError> {
        let v = Validator { path };
        let p = &self.pyramid;

        for axis in 0..2 {
            v.positive(&format!("extent_m[{axis}]"), self.extent_m[axis])?;
        }
        v.positive("pyramid.root_tile_size_m", p.root_tile_size_m)?;
        v.at_most(
            "pyramid.root_tile_size_m",
            p.root_tile_size_m,
            MAX_ROOT_TILE_M,
            " m",
        )?;
        for axis in 0..2 {
            if p.root_tiles[axis] == 0 {
                return Err(v.non_positive(&format!("pyramid.root_tiles[{axis}]"), 0.0));
            }
        }
        if !(8..=1024).contains(&p.tile_cells) || !p.tile_cells.is_power_of_two() {
            return Err(v.out_of_range(
                "pyramid.tile_cells",
                p.tile_cells,
                "a power of two in 8..=1024",
            ));
        }
        if p.border > 8 {
            return Err(v.out_of_range("pyramid.border", p.border, "in 0..=8"));
        }
        if !(1..=12).contains(&p.stored_levels) {
            return Err(v.out_of_range("pyramid.stored_levels", p.stored_levels, "in 1..=12"));
        }
        let levels = u32::from(p.stored_levels) + u32::from(p.derived_levels);
        if levels > 24 {
            return Err(v.out_of_range(
                "pyramid.stored_levels + pyramid.derived_levels",
                levels,
                "at most 24",
            ));
        }
        let roots = u64::from(p.root_tiles[0]) * u64::from(p.root_tiles[1]);
        if roots > MAX_ROOT_TILES {
            return Err(WorldError::TooManyTiles {
                path: path.to_path_buf(),
                field: "pyramid.root_tiles".into(),
                count: roots,
                max: MAX_ROOT_TILES,
            });
        }
        for axis in 0..2 {
            // Tile coordinates of the finest level, derived or stored, must fit a u32.
            if u64::from(p.root_tiles[axis]) << (levels - 1) > u64::from(u32::MAX) {
                return Err(v.out_of_range(
                    &format!("pyramid.root_tiles[{axis}]"),
                    p.root_tiles[axis],
                    "small enough that the finest level's tile count fits in 32 bits",
                ));
            }
        }
        let finest = roots << (2 * (u32::from(p.stored_levels) - 1));
        if finest > MAX_FINEST_TILES {
            return Err(WorldError::TooManyTiles {
                path: path.to_path_buf(),
                field: "pyramid.root_tiles and pyramid.stored_levels".into(),
                count: finest,
                max: MAX_FINEST_TILES,
            });
        }
        for axis in 0..2 {
            if self.extent_m[axis] > MAX_EXTENT_M {
                return Err(v.out_of_range(
                    &format!("extent_m[{axis}]"),
                    self.extent_m[axis],
                    "at most 10,000 km (10000000 m)",
                ));
            }
            let grid_m = f64::from(p.root_tiles[axis]) * p.root_tile_size_m;
            // Allow rounding in the last digits of a value written out and read back.
            if self.extent_m[axis] > grid_m * (1.0 + 1e-9) {
                return Err(WorldError::ExtentBeyondGrid {
                    path: path.to_path_buf(),
                    axis,
                    extent_m: self.extent_m[axis],
                    grid_m,
                });
            }
        }

        let [lo, hi] = self.height_range_m;
        v.finite("height_range_m[0]", lo)?;
        v.finite("height_range_m[1]", hi)?;
        if lo >= hi {
            return Err(WorldError::BadHeightRange {
                path: path.to_path_buf(),
                min: lo,
                max: hi,
            });
        }
        let [plo, phi] = super::PLAUSIBLE_HEIGHTS_M;
        if f64::from(lo) < plo || f64::from(hi) > phi {
            return Err(v.out_of_range(
                "height_range_m",
                format!("[{lo}, {hi}]"),
                &format!("within [{plo}, {phi}] m, the heights of a planet's surface"),
            ));
        }

        if self.grass_types.is_empty() {
            return Err(WorldError::NoGrassTypes {
                path: path.to_path_buf(),
            });
        }
        if self.grass_types.len() > MAX_GRASS_TYPES {
            return Err(v.out_of_range(
                "grass_types",
                format!("{} types", self.grass_types.len()),
                &format!(
                    "at most {MAX_GRASS_TYPES} types (the renderer draws {MAX_GRASS_TYPES} kinds \
                     of grass)"
                ),
            ));
        }
        for (index, g) in self.grass_types.iter().enumerate() {
            let field = |f: &str| format!("grass_types[{index}].{f}");
            v.all_within(&field("ground_color"), &g.ground_color, [0.0, 1.0], "")?;
            v.all_within(&field("base_color"), &g.base_color, [0.0, 1.0], "")?;
            v.all_within(&field("tip_color"), &g.tip_color, [0.0, 1.0], "")?;
            v.all_finite(&field("height_m"), &g.height_m)?;
            v.all_finite(&field("width_m"), &g.width_m)?;
            v.within(&field("stiffness"), g.stiffness, [0.0, 1.0], "")?;
            for (name, [min, max], most) in [
                ("height_m", g.height_m, MAX_BLADE_HEIGHT_M),
                ("width_m", g.width_m, MAX_BLADE_WIDTH_M),
            ] {
                if min < 0.0 || min > max {
                    return Err(WorldError::BadGrassRange {
                        path: path.to_path_buf(),
                        index,
                        name: g.name.clone(),
                        field: name,
                        min,
                        max,
                    });
                }
                v.at_most(&format!("{}[1]", field(name)), max, most, " m")?;
            }
        }

        v.validate_ambient("wind", &self.wind)?;
        let s = &self.sky;
        v.angle("sky.sun_azimuth_deg", s.sun_azimuth_deg)?;
        v.within(
            "sky.sun_elevation_deg",
            s.sun_elevation_deg,
            [-90.0, 90.0],
            " degrees",
        )?;
        v.all_within("sky.sun_color", &s.sun_color, [0.0, MAX_SUN_INTENSITY], "")?;
        v.all_within("sky.sky_color", &s.sky_color, [0.0, 1.0], "")?;
        v.all_within("sky.horizon_color", &s.horizon_color, [0.0, 1.0], "")?;
        v.positive("sky.fog_distance_m", s.fog_distance_m)?;
        v.at_most(
            "sky.fog_distance_m",
            s.fog_distance_m,
            MAX_FOG_DISTANCE_M,
            " m",
        )?;
        if let Some(source) = &self.source {
            for axis in 0..2 {
                let field = format!("source.cell_size_m[{axis}]");
                v.positive(&field, source.cell_size_m[axis])?;
                v.at_most(&field, source.cell_size_m[axis], MAX_EXTENT_M, " m")?;
            }
            if let Some(origin) = &source.origin {
                let most = MAX_SOURCE_COORDINATE;
                v.all_within("source.origin", origin, [-most, most], "")?;
            }
        }

        let mut names = HashSet::new();
        for (pi, cam) in self.paths.iter().enumerate() {
            if !names.insert(cam.name.as_str()) {
                return Err(WorldError::DuplicatePath {
                    path: path.to_path_buf(),
                    name: cam.name.clone(),
                });
            }
            let duration = format!("paths[{pi}].duration_s");
            v.positive(&duration, cam.duration_s)?;
            v.at_most(&duration, cam.duration_s, MAX_TIME_S, " s")?;
            if cam.keys.len() < 2 {
                return Err(WorldError::PathTooShort {
                    path: path.to_path_buf(),
                    name: cam.name.clone(),
                    keys: cam.keys.len(),
                });
            }
            for (ki, key) in cam.keys.iter().enumerate() {
                let field = |f: &str| format!("paths[{pi}].keys[{ki}].{f}");
                v.time(&field("t_s"), key.t_s)?;
                v.position(&field("position_m"), &key.position_m)?;
                v.angle(&field("yaw_deg"), key.yaw_deg)?;
                v.within(
                    &field("pitch_deg"),
                    key.pitch_deg,
                    [-90.0, 90.0],
                    " degrees",
                )?;
                if ki > 0 && key.t_s <= cam.keys[ki - 1].t_s {
                    return Err(WorldError::PathKeysOutOfOrder {
                        path: path.to_path_buf(),
                        name: cam.name.clone(),
                        index: ki,
                        t_s: key.t_s,
                        previous_t_s: cam.keys[ki - 1].t_s,
                    });
                }
            }
        }
        self.validate_wind_scenes(&v)?;
        for (pi, cam) in self.paths.iter().enumerate() {
            self.validate_path_wind(&v, pi, cam)?;
        }
        if let Some(g) = &self.grass_peak {
            v.positive("grass_peak.window_m", g.window_m)?;
            v.at_most("grass_peak.window_m", g.window_m, MAX_ROOT_TILE_M, " m")?;
            v.non_negative("grass_peak.short_m", g.short_m)?;
            v.at_most("grass_peak.short_m", g.short_m, MAX_BLADE_HEIGHT_M, " m")?;
            v.finite("grass_peak.density", g.density)?;
            if !(0.0..=2.0).contains(&g.density) {
                return Err(v.out_of_range("grass_peak.density", g.density, "in 0..=2"));
            }
        }
        if let Some(c) = &self.derive {
            self.validate_derive(&v, c)?;
        }
        Ok(())
    }

    fn validate_derive(&self, v: &Validator, c: &DeriveCalibration) -> Result<(), WorldError> {
        let most = MAX_DERIVE_LOG2;
        v.within("derive.hurst", c.hurst, [-most, most], "")?;
        v.non_negative("derive.fit_rms_log2", c.fit_rms_log2)?;
        v.at_most("derive.fit_rms_log2", c.fit_rms_log2, most, "")?;
        v.non_negative("derive.residual_rms_m", c.residual_rms_m)?;
        let [lo, hi] = super::PLAUSIBLE_HEIGHTS_M;
        v.at_most("derive.residual_rms_m", c.residual_rms_m, hi - lo, " m")?;
        v.non_negative("derive.decay_log2", c.decay_log2)?;
        v.at_most("derive.decay_log2", c.decay_log2, most, "")?;
        let levels = usize::from(self.pyramid.derived_levels);
        if c.detail.len() != levels {
            return Err(v.out_of_range(
                "derive.detail",
                format!("{} values", c.detail.len()),
                &format!("one value per derived level ({levels})"),
            ));
        }
        for (i, &d) in c.detail.iter().enumerate() {
            let field = format!("derive.detail[{i}]");
            v.non_negative(&field, d)?;
            if d > MAX_DETAIL {
                return Err(v.out_of_range(&field, d, &format!("at most {MAX_DETAIL}")));
            }
            if c.method == DeriveMode::Bicubic && d != 0.0 {
                return Err(v.out_of_range(&field, d, "0 when derive.method is \"bicubic\""));
            }
        }
        Ok(())
    }

    fn validate_path_wind(
        &self,
        v: &Validator,
        pi: usize,
        cam: &CameraPath,
    ) -> Result<(), WorldError> {
        if let Some(name) = &cam.walker
            && self.path(name).is_none()
        {
            return Err(WorldError::UnknownPathRef {
                path: v.path.to_path_buf(),
                field: format!("paths[{pi}].walker"),
                name: name.clone(),
            });
        }
        for (ki, key) in cam.wind.iter().enumerate() {
            let field = |f: &str| format!("paths[{pi}].wind[{ki}].{f}");
            v.time(&field("t_s"), key.t_s)?;
            v.non_negative(&field("blend_s"), key.blend_s)?;
            v.at_most(&field("blend_s"), key.blend_s, MAX_TIME_S, " s")?;
            if self.wind_scene(&key.scene).is_none() {
                let names: Vec<&str> = self.wind_scenes.iter().map(|s| s.name.as_str()).collect();
                return Err(WorldError::UnknownWindSceneRef {
                    path: v.path.to_path_buf(),
                    field: field("scene"),
                    name: key.scene.clone(),
                    available: names.join(", "),
                });
            }
            if ki > 0 {
                let prev = &cam.wind[ki - 1];
                if key.t_s < prev.t_s + prev.blend_s.max(1e-3) {
                    return Err(v.out_of_range(
                        &field("t_s"),
                        key.t_s,
                        &format!(
                            "at least {} (the previous wind key's t_s + blend_s): a scene \
                             change may not start before the one before it has blended in",
                            prev.t_s + prev.blend_s.max(1e-3)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    fn validate_wind_scenes(&self, v: &Validator) -> Result<(), WorldError> {
        let mut names = HashSet::new();
        for (si, scene) in self.wind_scenes.iter().enumerate() {
            if !names.insert(scene.name.as_str()) {
                return Err(WorldError::DuplicateWindScene {
                    path: v.path.to_path_buf(),
                    name: scene.name.clone(),
                });
            }
            v.validate_ambient(&format!("wind_scenes[{si}].ambient"), &scene.ambient)?;
            if scene.sources.len() > MAX_WIND_SOURCES {
                return Err(v.out_of_range(
                    &format!("wind_scenes[{si}].sources"),
                    format!("{} sources", scene.sources.len()),
                    &format!("at most {MAX_WIND_SOURCES} sources"),
                ));
            }
            for (ci, source) in scene.sources.iter().enumerate() {
                self.validate_wind_source(v, &format!("wind_scenes[{si}].sources[{ci}]"), source)?;
            }
        }
        Ok(())
    }

    fn validate_wind_source(
        &self,
        v: &Validator,
        at: &str,
        source: &WindSource,
    ) -> Result<(), WorldError> {
        let field = |f: &str| format!("{at}.{f}");
        match source {
            WindSource::Directional {
                direction_deg,
                speed_mps,
                ..
            } => {
                v.angle(&field("direction_deg"), *direction_deg)?;
                v.speed(&field("speed_mps"), *speed_mps)?;
            }
            WindSource::Omni {
                radius_m,
                speed_mps,
                ..
            } => {
                v.radius(&field("radius_m"), *radius_m)?;
                v.speed(&field("speed_mps"), *speed_mps)?;
            }
            WindSource::Vortex {
                radius_m,
                speed_mps,
                inflow_mps,
                ..
            } => {
                v.radius(&field("radius_m"), *radius_m)?;
                v.speed(&field("speed_mps"), *speed_mps)?;
                let most = MAX_WIND_SPEED_MPS;
                v.within(&field("inflow_mps"), *inflow_mps, [-most, most], " m/s")?;
            }
        }
        let (position, path_name, start_s, strength, _) = source.common();
        if let Some(p) = position {
            v.position(&field("position_m"), p)?;
        }
        match (position, path_name) {
            (Some(_), Some(_)) => {
                return Err(WorldError::WindSourcePlacement {
                    path: v.path.to_path_buf(),
                    field: at.to_string(),
                    message: "has both position_m and path: give one".into(),
                });
            }
            (None, None) if !matches!(source, WindSource::Directional { .. }) => {
                return Err(WorldError::WindSourcePlacement {
                    path: v.path.to_path_buf(),
                    field: at.to_string(),
                    message: format!("a {} source needs position_m or path", source.kind_name()),
                });
            }
            _ => {}
        }
        if let Some(name) = path_name
            && self.path(name).is_none()
        {
            return Err(WorldError::UnknownPathRef {
                path: v.path.to_path_buf(),
                field: field("path"),
                name: name.clone(),
            });
        }
        v.non_negative(&field("start_s"), start_s)?;
        v.at_most(&field("start_s"), start_s, MAX_TIME_S, " s")?;
        for (ki, key) in strength.iter().enumerate() {
            v.all_finite(&field(&format!("strength[{ki}]")), key)?;
            v.time(&field(&format!("strength[{ki}][0]")), key[0])?;
            let factor = field(&format!("strength[{ki}][1]"));
            v.non_negative(&factor, key[1])?;
            v.at_most(&factor, key[1], MAX_WIND_STRENGTH, "")?;
            if ki > 0 && key[0] <= strength[ki - 1][0] {
                return Err(WorldError::StrengthKeysOutOfOrder {
                    path: v.path.to_path_buf(),
                    field: field("strength"),
                    index: ki,
                    t_s: key[0],
                    previous_t_s: strength[ki - 1][0],
                });
            }
        }
        Ok(())
    }
}

/// Builds validation errors that name the manifest file.
struct Validator<'a> {
    path: &'a Path,
}

impl Validator<'_> {
    fn finite(&self, field: &str, value: impl Into<f64>) -> Result<(), WorldError> {
        let value = value.into();
        if value.is_finite() {
            Ok(())
        } else {
            Err(WorldError::NonFinite {
                path: self.path.to_path_buf(),
                field: field.to_string(),
                value,
            })
        }
    }

    fn all_finite<T: Copy + Into<f64>>(&self, field: &str, values: &[T]) -> Result<(), WorldError> {
        for (i, &x) in values.iter().enumerate() {
            self.finite(&format!("{field}[{i}]"), x)?;
        }
        Ok(())
    }

    fn positive(&self, field: &str, value: impl Into<f64>) -> Result<(), WorldError> {
        let value = value.into();
        self.finite(field, value)?;
        if value > 0.0 {
            Ok(())
        } else {
            Err(self.non_positive(field, value))
        }
    }

    fn non_negative(&self, field: &str, value: impl Into<f64>) -> Result<(), WorldError> {
        let value = value.into();
        self.finite(field, value)?;
        if value >= 0.0 {
            Ok(())
        } else {
            Err(WorldError::Negative {
                path: self.path.to_path_buf(),
                field: field.to_string(),
                value,
            })
        }
    }

    /// Refuses a finite `value` above `most` (`unit` follows the number in the message).
    fn at_most(
        &self,
        field: &str,
        value: impl Into<f64>,
        most: f64,
        unit: &str,
    ) -> Result<(), WorldError> {
        let value = value.into();
        self.finite(field, value)?;
        if value <= most {
            Ok(())
        } else {
            Err(self.out_of_range(
                field,
                number(value),
                &format!("at most {}{unit}", number(most)),
            ))
        }
    }

    /// Refuses a value that is not finite or lies outside `lo..=hi`.
    fn within(
        &self,
        field: &str,
        value: impl Into<f64>,
        [lo, hi]: [f64; 2],
        unit: &str,
    ) -> Result<(), WorldError> {
        let value = value.into();
        self.finite(field, value)?;
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            let allowed = format!("in {}..={}{unit}", number(lo), number(hi));
            Err(self.out_of_range(field, number(value), &allowed))
        }
    }

    fn all_within<T: Copy + Into<f64>>(
        &self,
        field: &str,
        values: &[T],
        range: [f64; 2],
        unit: &str,
    ) -> Result<(), WorldError> {
        for (i, &x) in values.iter().enumerate() {
            self.within(&format!("{field}[{i}]"), x, range, unit)?;
        }
        Ok(())
    }

    fn angle(&self, field: &str, value: impl Into<f64>) -> Result<(), WorldError> {
        self.within(field, value, [-MAX_ANGLE_DEG, MAX_ANGLE_DEG], " degrees")
    }

    fn time(&self, field: &str, value: impl Into<f64>) -> Result<(), WorldError> {
        self.within(field, value, [-MAX_TIME_S, MAX_TIME_S], " s")
    }

    fn position(&self, field: &str, values: &[f64]) -> Result<(), WorldError> {
        self.all_within(field, values, [-MAX_POSITION_M, MAX_POSITION_M], " m")
    }

    fn speed(&self, field: &str, value: impl Into<f64>) -> Result<(), WorldError> {
        let value = value.into();
        self.non_negative(field, value)?;
        self.at_most(field, value, MAX_WIND_SPEED_MPS, " m/s")
    }

    fn radius(&self, field: &str, value: f64) -> Result<(), WorldError> {
        self.positive(field, value)?;
        self.at_most(field, value, MAX_WIND_RADIUS_M, " m")
    }

    /// An ambient wind (`[wind]` or a scene's `ambient`) at `at`.
    fn validate_ambient(&self, at: &str, a: &WindDefaults) -> Result<(), WorldError> {
        self.angle(&format!("{at}.direction_deg"), a.direction_deg)?;
        self.speed(&format!("{at}.speed_mps"), a.speed_mps)?;
        self.within(&format!("{at}.gustiness"), a.gustiness, [0.0, 1.0], "")
    }

    fn non_positive(&self, field: &str, value: f64) -> WorldError {
        WorldError::NonPositive {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            value,
        }
    }

    fn out_of_range(&self, field: &str, value: impl ToString, allowed: &str) -> WorldError {
        WorldError::OutOfRange {
            path: self.path.to_path_buf(),
            field: field.to_string(),
            value: value.to_string(),
            allowed: allowed.to_string(),
        }
    }
}

/// A number as messages show it: plainly, or in exponent form where plain digits would run
/// long (1e30 rather than thirty-one digits).
fn number(x: f64) -> String {
    let a = x.abs();
    if a != 0.0 && !(1e-4..1e9).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}
