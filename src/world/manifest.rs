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

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::features::{Feature, Features};

use super::dem::DemFormat;
use super::error::WorldError;
use super::tile::Pyramid;

mod scenes;
mod validate;

pub use scenes::{
    CameraKey, CameraPath, DEFAULT_WIND_BLEND_S, MAX_WIND_SOURCES, PATH_DURATION_TOLERANCE_S,
    SourcePlacement, WindDefaults, WindKey, WindScene, WindSource,
};

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
/// Narrowest tile of the finest level (where the grass grows), metres: the trees' placement
/// cells are at least half a metre.
pub const MIN_GRASS_TILE_M: f64 = 0.5;
/// Widest tile of the finest level, metres. The grass's view distance is 4/3 of a tile and its
/// blades are placed a tile at a time: at 1024 m a frame places some 20 times the blades of the
/// default world's 50 m tiles per tile (a world of 3.2 km tiles did not draw its first frame in
/// five minutes on software Vulkan).
pub const MAX_GRASS_TILE_M: f64 = 1024.0;
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
    #[serde(deserialize_with = "exact")]
    pub extent_m: [f64; 2],
    /// The tile pyramid.
    pub pyramid: Pyramid,
    /// Lowest and highest stored height, metres.
    #[serde(deserialize_with = "exact")]
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
    /// Plants beyond grass (flowers, ferns, bushes, a user's glTF plants), at most
    /// [`MAX_PLANT_TYPES`]; none by default.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub plant_types: Vec<PlantType>,
    /// Whether every stored tile has a terrain material map (`{x}_{y}.material.png`, see
    /// [`super::Material`]), baked from a land-cover table that names materials. Without one
    /// (the default, and every world baked before materials) the ground follows the grass types.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub materials: bool,
    /// Which bake wrote the tiles: 16 hexadecimal digits, written by the baker, which stamps
    /// every tile file with its own name and this id (see [`super::format::check_stamp`]), so
    /// that a tile file copied over another, or one left by another bake (a copy, cache or
    /// mirror of an older world), is refused rather than drawn. Absent in worlds baked before
    /// the stamps and in hand-made ones: their files are not checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bake_id: Option<String>,
}

/// Most plant types a world has.
pub const MAX_PLANT_TYPES: usize = 8;
/// The built-in recipes a plant type's `mesh` may name (else a `.gltf` or `.glb` file).
pub const PLANT_RECIPES: [&str; 5] = ["flower", "fern", "bush", "broadleaf", "conifer"];
/// Largest plant, metres (a tall tree).
pub const MAX_PLANT_SIZE_M: f64 = 60.0;
/// The smallest plant a type may give, metres: a centimetre (smaller is no plant to draw).
pub const MIN_PLANT_SIZE_M: f64 = 0.01;
/// A plant type that grows this tall (the top of its height range, metres) is a tree: it is
/// placed on the trees' coarser grid and drawn out to the fog, not among the grass.
pub const TREE_MIN_HEIGHT_M: f32 = 4.0;
/// Most plants per square metre of all types together on one grass type (the placement grid
/// holds at most one plant per 0.5 m cell, the plants module's `PLANT_CELL_M`).
pub const MAX_PLANT_DENSITY: f64 = 4.0;

/// One kind of plant: its mesh, where it grows and how it moves in the wind.
///
/// ```toml
/// [[plant_types]]
/// name = "poppy"
/// mesh = "flower"              # flower, fern, bush, broadleaf or conifer; or a .gltf/.glb file
/// color = [0.75, 0.08, 0.04]   # the recipe's accent (petals, or leaves)
/// size_m = [0.35, 0.6]         # height range
/// density = { meadow = 0.12 }  # plants per square metre, per grass type (by name)
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantType {
    /// Name, e.g. `poppy`.
    pub name: String,
    /// A built-in recipe (`flower`, `fern`, `bush`, and the trees `broadleaf` and `conifer`)
    /// or a glTF 2.0 file (`.gltf` or `.glb`) relative to the manifest's folder.
    pub mesh: String,
    /// The recipe's accent colour, linear (0..=1): a flower's petals, a fern's, bush's or
    /// tree's leaves (a conifer's needles).
    /// A glTF plant keeps its own colours.
    #[serde(deserialize_with = "exact", default = "default_plant_color")]
    pub color: [f32; 3],
    /// Height range, metres (0 < min <= max <= [`MAX_PLANT_SIZE_M`]); a type whose range
    /// reaches [`TREE_MIN_HEIGHT_M`] is a tree.
    #[serde(deserialize_with = "exact")]
    pub size_m: [f32; 2],
    /// Plants per square metre on each grass type, by the grass type's name (types not named
    /// get none). Scaled by the grass map's density where the plant stands.
    pub density: std::collections::BTreeMap<String, f32>,
    /// Steepest ground it grows on, degrees (0..=90).
    #[serde(default = "default_max_slope")]
    pub max_slope_deg: f32,
    /// Altitudes it grows between, metres.
    #[serde(deserialize_with = "exact", default = "default_altitude")]
    pub altitude_m: [f32; 2],
    /// Size of its clumps, metres (1..=1000): the plants gather in patches of about this size.
    #[serde(default = "default_clump")]
    pub clump_m: f32,
    /// The share of the ground its patches cover, 0 (exclusive)..=1 (1: spread evenly). The
    /// mean density stays as given: the patches are denser.
    #[serde(default = "default_cover")]
    pub clump_cover: f32,
    /// Seed of the recipe's shape (a different seed, a different-looking plant).
    #[serde(default)]
    pub seed: u32,
    /// How it moves in the wind.
    #[serde(default)]
    pub wind: PlantWind,
}

impl PlantType {
    /// Whether the type is a tree ([`TREE_MIN_HEIGHT_M`]).
    pub fn is_tree(&self) -> bool {
        self.size_m[1] >= TREE_MIN_HEIGHT_M
    }
}

fn default_plant_color() -> [f32; 3] {
    [0.1, 0.3, 0.05]
}
fn default_max_slope() -> f32 {
    35.0
}
fn default_altitude() -> [f32; 2] {
    [-500.0, 9000.0]
}
fn default_clump() -> f32 {
    8.0
}
fn default_cover() -> f32 {
    1.0
}

/// A plant's wind parameters: God of War's (movement scale, bend, stretch, stiffness, sway
/// spring and damping) and Crysis' amplitudes of main and detail bending.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantWind {
    /// How much of the wind the plant feels, 0..=4.
    pub movement_scale: f32,
    /// Main bending: how far the whole plant leans per m/s of wind, in plant heights, 0..=1.
    pub bend: f32,
    /// How much of its length the bent plant keeps, 0..=1 (1: bends on an arc, no stretch).
    pub stretch: f32,
    /// Resistance to bending, 0..=1: a stiff plant leans less and sways faster.
    pub stiffness: f32,
    /// The sway spring's natural frequency, Hz (0.05..=10).
    pub sway_spring_hz: f32,
    /// The sway's damping ratio (0.01..=2: below 1 it overshoots).
    pub sway_damping: f32,
    /// Scale of the main bending, 0..=4.
    pub main_amplitude: f32,
    /// Scale of the detail bending (leaves and edges), 0..=4.
    pub detail_amplitude: f32,
}

impl Default for PlantWind {
    fn default() -> Self {
        Self {
            movement_scale: 1.0,
            bend: 0.03,
            stretch: 1.0,
            stiffness: 0.5,
            sway_spring_hz: 0.8,
            sway_damping: 0.35,
            main_amplitude: 1.0,
            detail_amplitude: 1.0,
        }
    }
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
    #[serde(
        default,
        deserialize_with = "exact_opt",
        skip_serializing_if = "Option::is_none"
    )]
    pub origin: Option<[f64; 2]>,
    /// Samples in the DEM, west-east and south-north.
    #[serde(deserialize_with = "exact")]
    pub samples: [u32; 2],
    /// Spacing of the DEM's samples in metres, east-west and north-south.
    #[serde(deserialize_with = "exact")]
    pub cell_size_m: [f64; 2],
    /// Nodata samples filled from the heights around them.
    #[serde(default)]
    pub nodata_filled: u64,
    /// The land-cover map the grass was painted from, where one was given (its file name).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub land_cover: String,
    /// The table of what grows on its classes: its product name and file (or built-in name).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub cover_table: String,
    /// The density map that scaled the grass cover, where one was given (its file name).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub density_map: String,
    /// The mask where nothing grows, where one was given (its file name).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub mask: String,
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
    /// `fractal`: derived levels add detail at `detail` (fitted, or, where the data has too
    /// few octaves to fit, from the prior measured on the project's DEMs: `note` says which);
    /// `bicubic`: the fit was poor (too few levels, flat or irregular terrain) and derived
    /// levels are plain Catmull-Rom.
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
    /// Plants among the grass (the world's `[[plant_types]]` lower than trees).
    pub plants: bool,
    /// Trees (the world's `[[plant_types]]` of at least [`TREE_MIN_HEIGHT_M`]).
    pub trees: bool,
    /// The trees' shadows from a shadow map.
    pub tree_shadows: bool,
    /// Leaves shed by the trees, carried by the wind.
    pub particles: bool,
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
            plants: f.has(Feature::Plants),
            trees: f.has(Feature::Trees),
            tree_shadows: f.has(Feature::TreeShadows),
            particles: f.has(Feature::Particles),
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
            (Feature::Plants, s.plants),
            (Feature::Trees, s.trees),
            (Feature::TreeShadows, s.tree_shadows),
            (Feature::Particles, s.particles),
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
    #[serde(deserialize_with = "exact")]
    pub ground_color: [f32; 3],
    /// Colour at a blade's root (0..=1).
    #[serde(deserialize_with = "exact")]
    pub base_color: [f32; 3],
    /// Colour at a blade's tip (0..=1).
    #[serde(deserialize_with = "exact")]
    pub tip_color: [f32; 3],
    /// Blade height range, metres (min, max; 0 <= min <= max <= [`MAX_BLADE_HEIGHT_M`]).
    #[serde(deserialize_with = "exact")]
    pub height_m: [f32; 2],
    /// Blade width range at the root, metres (min, max; 0 <= min <= max <=
    /// [`MAX_BLADE_WIDTH_M`]).
    #[serde(deserialize_with = "exact")]
    pub width_m: [f32; 2],
    /// Resistance to bending in the wind, 0..=1: 0 bends freely, 1 barely moves.
    pub stiffness: f32,
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
    #[serde(deserialize_with = "exact")]
    pub sun_color: [f32; 3],
    /// Sky colour overhead (0..=1).
    #[serde(deserialize_with = "exact")]
    pub sky_color: [f32; 3],
    /// Sky colour at the horizon, also the fog colour (0..=1).
    #[serde(deserialize_with = "exact")]
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

/// Reads a fixed-size array of a manifest, refusing an array of another length (serde's
/// arrays read the first values and ignore any after them: `sun_color = [1, 0.9, 0.8, 99]` was
/// taken for a colour).
pub(crate) fn exact<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    array_of(Vec::<T>::deserialize(d)?)
}

/// [`exact`] for an optional array.
pub(crate) fn exact_opt<'de, D, T, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<Vec<T>>::deserialize(d)?.map(array_of).transpose()
}

/// `values` as an array of `N`, or an error of their count.
fn array_of<T, E: serde::de::Error, const N: usize>(values: Vec<T>) -> Result<[T; N], E> {
    let found = values.len();
    values
        .try_into()
        .map_err(|_| E::invalid_length(found, &format!("an array of {N} values").as_str()))
}

/// The largest `world.toml` read, bytes.
pub const MAX_MANIFEST_BYTES: u64 = 16 << 20;

/// The most characters of the offending line that a TOML error quotes, either side of the
/// error's column.
const TOML_ERROR_QUOTE_CHARS: usize = 60;

/// A TOML parse error of `text` in words: where it is, the offending line quoted around the
/// error's column (at most [`TOML_ERROR_QUOTE_CHARS`] characters each side, control characters
/// escaped) and what is wrong. The parser's own message quotes the whole line, escaped, so that a
/// file of one long line (a damaged or hostile manifest, up to 16 MiB over HTTP) made an error
/// several times its size.
pub fn toml_error(text: &str, e: &toml::de::Error) -> String {
    let message = e.message().trim_end();
    let Some(span) = e.span() else {
        return message.to_owned();
    };
    let start = span.start.min(text.len());
    let start = (0..=start)
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
    let line_no = text[..line_start].matches('\n').count() + 1;
    let before = &text[line_start..start];
    let column = before.chars().count() + 1;
    // The last characters before the error, from this byte on.
    let quoted_from = before
        .char_indices()
        .rev()
        .nth(TOML_ERROR_QUOTE_CHARS - 1)
        .map_or(0, |(i, _)| i);
    let after: String = text[start..line_end]
        .chars()
        .take(TOML_ERROR_QUOTE_CHARS)
        .collect();
    let escape = |s: &str| -> String {
        s.chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_debug().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect()
    };
    let head = escape(&before[quoted_from..]);
    let head = if quoted_from > 0 {
        format!("...{head}")
    } else {
        head
    };
    let tail = escape(&after);
    let tail = if start + after.len() < line_end {
        format!("{tail}...")
    } else {
        tail
    };
    let marker = " ".repeat(head.chars().count());
    format!(
        "TOML parse error at line {line_no}, column {column}\n  |\n  | {head}{tail}\n  | \
         {marker}^\n{message}"
    )
}

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
            message: toml_error(text, &e),
        })?;
        manifest.validate(path)?;
        Ok(manifest)
    }

    /// The manifest as TOML text, as written to `world.toml`.
    pub fn to_toml(&self) -> String {
        // Every field is a plain string, number or array: serialisation cannot fail.
        toml::to_string(self).unwrap_or_default()
    }

    /// The [`Manifest::bake_id`] as a number (`None` where the world has none; a manifest that
    /// passed [`Manifest::validate`] holds a valid one).
    pub fn bake_id_value(&self) -> Option<u64> {
        self.bake_id
            .as_deref()
            .and_then(|id| u64::from_str_radix(id, 16).ok())
    }

    /// The camera path called `name`.
    pub fn path(&self, name: &str) -> Option<&CameraPath> {
        self.paths.iter().find(|p| p.name == name)
    }

    /// The wind scene called `name`.
    pub fn wind_scene(&self, name: &str) -> Option<&WindScene> {
        self.wind_scenes.iter().find(|s| s.name == name)
    }
}

/// Whether `c` is a control character a manifest's text may not hold: any but a tab or a line
/// break (an escape sequence in a world's name would drive the terminal that prints it), and
/// the characters that reorder the text around them (bidirectional marks, embeddings, overrides
/// and isolates: a right-to-left override makes a name read as another one).
pub fn forbidden_control(c: char) -> bool {
    (c.is_control() && !matches!(c, '\t' | '\n' | '\r'))
        || matches!(
            c,
            '\u{061C}' | '\u{200E}' | '\u{200F}' | '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}'
        )
}

/// The most characters a name in a manifest may have (of a world, a camera path, a wind scene,
/// a grass or plant type, and the names a map is keyed by): names are printed in lines and
/// window titles. Other texts (a description, the source's file names, which a bake of
/// thousands of DEM files joins) are not limited.
pub const MAX_NAME_CHARS: usize = 256;

/// `text` with every control character a manifest may not hold ([`forbidden_control`]) replaced
/// by U+FFFD: for texts a bake takes from files (their names, a sidecar's `place`), which are
/// no fault of the user's and should not stop a bake.
pub fn without_control_characters(text: &str) -> String {
    text.chars()
        .map(|c| if forbidden_control(c) { '\u{FFFD}' } else { c })
        .collect()
}

/// The first name of `manifest` longer than [`MAX_NAME_CHARS`], as the field's path and its
/// length.
fn overlong_name(manifest: &Manifest) -> Option<(String, usize)> {
    first_text(manifest, &|field, text, name| {
        let n = text.chars().count();
        (name && n > MAX_NAME_CHARS).then(|| (field.to_owned(), n))
    })
}

/// The first text of `manifest` holding a control character it may not hold
/// ([`forbidden_control`]), as the field's path (`paths[2].name`) and the character.
fn control_character(manifest: &Manifest) -> Option<(String, char)> {
    first_text(manifest, &|field, text, _| {
        text.chars()
            .find(|&c| forbidden_control(c))
            .map(|c| (field.to_owned(), c))
    })
}

/// The first of `manifest`'s texts for which `found(field, text, is_name)` gives something:
/// every string, with its field's path (`paths[2].name`), a name being a `name` field's value
/// or a map's key (a plant's density by grass type's name: `plants[0].density."meadow"`).
fn first_text<T>(manifest: &Manifest, found: &dyn Fn(&str, &str, bool) -> Option<T>) -> Option<T> {
    fn walk<T>(
        v: &serde_json::Value,
        at: &str,
        name: bool,
        found: &dyn Fn(&str, &str, bool) -> Option<T>,
    ) -> Option<T> {
        match v {
            serde_json::Value::String(t) => found(at, t, name),
            serde_json::Value::Array(a) => a
                .iter()
                .enumerate()
                .find_map(|(i, v)| walk(v, &format!("{at}[{i}]"), false, found)),
            serde_json::Value::Object(o) => o.iter().find_map(|(k, v)| {
                found(&format!("{at}.{k:?}"), k, true).or_else(|| {
                    let at = if at.is_empty() {
                        k.clone()
                    } else {
                        format!("{at}.{k}")
                    };
                    walk(v, &at, k == "name", found)
                })
            }),
            _ => None,
        }
    }
    walk(&serde_json::to_value(manifest).ok()?, "", false, found)
}
