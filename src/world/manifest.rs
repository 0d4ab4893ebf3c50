//! The world manifest, `worlds/NAME/world.toml`: extent, tile pyramid, height range, grass types,
//! wind and sky defaults, named camera paths and named wind scenes. Parsed with serde, then checked by
//! [`Manifest::validate`] so that a world that asks for too much is refused before anything is
//! loaded.
//!
//! Conventions: positions in metres with x east, y north, z up, from the world's south-west
//! corner; angles in degrees counter-clockwise from east (0 = east, 90 = north), the same for
//! camera yaw, sun azimuth and wind direction; colours are linear RGB in 0..=1.

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
    /// Grass types; index 0 is bare ground. Tile type maps index into this list.
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

/// One kind of grass (or, at index 0, bare ground).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GrassType {
    /// Name, e.g. `meadow`.
    pub name: String,
    /// Colour of the ground under this type.
    pub ground_color: [f32; 3],
    /// Colour at a blade's root.
    pub base_color: [f32; 3],
    /// Colour at a blade's tip.
    pub tip_color: [f32; 3],
    /// Blade height range, metres (min, max).
    pub height_m: [f32; 2],
    /// Blade width range at the root, metres (min, max).
    pub width_m: [f32; 2],
    /// Resistance to bending in the wind: 0 bends freely, 1 barely moves.
    pub stiffness: f32,
}

/// Default ambient wind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindDefaults {
    /// Direction the wind blows toward, degrees counter-clockwise from east.
    pub direction_deg: f32,
    /// Mean speed, metres per second.
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

impl WindSource {
    /// `directional`, `omni` or `vortex`.
    pub fn kind_name(&self) -> &'static str {
        match self {
            WindSource::Directional { .. } => "directional",
            WindSource::Omni { .. } => "omni",
            WindSource::Vortex { .. } => "vortex",
        }
    }

    fn common(&self) -> (&Option<[f64; 2]>, &Option<String>, f64, &[[f64; 2]], bool) {
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
    /// Direction toward the sun, degrees counter-clockwise from east (225 = south-west).
    pub sun_azimuth_deg: f32,
    /// Sun height above the horizon, degrees.
    pub sun_elevation_deg: f32,
    /// Sunlight colour (linear RGB, may exceed 1 for intensity).
    pub sun_color: [f32; 3],
    /// Sky colour overhead.
    pub sky_color: [f32; 3],
    /// Sky colour at the horizon, also the fog colour.
    pub horizon_color: [f32; 3],
    /// Distance at which fog hides the terrain completely, metres.
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
    /// Length of the flight, seconds.
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
    /// Time from the start of the path, seconds; the scene's source times count from here.
    pub t_s: f64,
    /// Name of a wind scene of the world.
    pub scene: String,
    /// Seconds over which the ambient wind blends from the previous scene's into this one's.
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
    /// Time from the start of the path, seconds.
    pub t_s: f64,
    /// Absolute position, metres (x east, y north, z up).
    pub position_m: [f64; 3],
    /// Heading, degrees counter-clockwise from east (0 looks east, 90 north).
    pub yaw_deg: f64,
    /// Degrees above the horizontal; negative looks down.
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
        for (index, g) in self.grass_types.iter().enumerate() {
            let field = |f: &str| format!("grass_types[{index}].{f}");
            v.all_finite(&field("ground_color"), &g.ground_color)?;
            v.all_finite(&field("base_color"), &g.base_color)?;
            v.all_finite(&field("tip_color"), &g.tip_color)?;
            v.all_finite(&field("height_m"), &g.height_m)?;
            v.all_finite(&field("width_m"), &g.width_m)?;
            v.finite(&field("stiffness"), g.stiffness)?;
            for (name, [min, max]) in [("height_m", g.height_m), ("width_m", g.width_m)] {
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
            }
        }

        v.finite("wind.direction_deg", self.wind.direction_deg)?;
        v.finite("wind.speed_mps", self.wind.speed_mps)?;
        v.finite("wind.gustiness", self.wind.gustiness)?;
        let s = &self.sky;
        v.finite("sky.sun_azimuth_deg", s.sun_azimuth_deg)?;
        v.finite("sky.sun_elevation_deg", s.sun_elevation_deg)?;
        v.all_finite("sky.sun_color", &s.sun_color)?;
        v.all_finite("sky.sky_color", &s.sky_color)?;
        v.all_finite("sky.horizon_color", &s.horizon_color)?;
        v.positive("sky.fog_distance_m", s.fog_distance_m)?;
        if let Some(source) = &self.source {
            v.positive("source.cell_size_m[0]", source.cell_size_m[0])?;
            v.positive("source.cell_size_m[1]", source.cell_size_m[1])?;
            if let Some(origin) = &source.origin {
                v.all_finite("source.origin", origin)?;
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
            v.positive(&format!("paths[{pi}].duration_s"), cam.duration_s)?;
            if cam.keys.len() < 2 {
                return Err(WorldError::PathTooShort {
                    path: path.to_path_buf(),
                    name: cam.name.clone(),
                    keys: cam.keys.len(),
                });
            }
            for (ki, key) in cam.keys.iter().enumerate() {
                let field = |f: &str| format!("paths[{pi}].keys[{ki}].{f}");
                v.finite(&field("t_s"), key.t_s)?;
                v.all_finite(&field("position_m"), &key.position_m)?;
                v.finite(&field("yaw_deg"), key.yaw_deg)?;
                v.finite(&field("pitch_deg"), key.pitch_deg)?;
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
            v.non_negative("grass_peak.short_m", g.short_m)?;
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
        v.finite("derive.hurst", c.hurst)?;
        v.non_negative("derive.fit_rms_log2", c.fit_rms_log2)?;
        v.non_negative("derive.residual_rms_m", c.residual_rms_m)?;
        v.non_negative("derive.decay_log2", c.decay_log2)?;
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
            v.finite(&field("t_s"), key.t_s)?;
            v.non_negative(&field("blend_s"), key.blend_s)?;
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
            let a = &scene.ambient;
            let field = |f: &str| format!("wind_scenes[{si}].ambient.{f}");
            v.finite(&field("direction_deg"), a.direction_deg)?;
            v.non_negative(&field("speed_mps"), a.speed_mps)?;
            v.finite(&field("gustiness"), a.gustiness)?;
            if !(0.0..=1.0).contains(&a.gustiness) {
                return Err(v.out_of_range(&field("gustiness"), a.gustiness, "in 0..=1"));
            }
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
                v.finite(&field("direction_deg"), *direction_deg)?;
                v.non_negative(&field("speed_mps"), *speed_mps)?;
            }
            WindSource::Omni {
                radius_m,
                speed_mps,
                ..
            } => {
                v.positive(&field("radius_m"), *radius_m)?;
                v.non_negative(&field("speed_mps"), *speed_mps)?;
            }
            WindSource::Vortex {
                radius_m,
                speed_mps,
                inflow_mps,
                ..
            } => {
                v.positive(&field("radius_m"), *radius_m)?;
                v.non_negative(&field("speed_mps"), *speed_mps)?;
                v.finite(&field("inflow_mps"), *inflow_mps)?;
            }
        }
        let (position, path_name, start_s, strength, _) = source.common();
        if let Some(p) = position {
            v.all_finite(&field("position_m"), p)?;
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
        for (ki, key) in strength.iter().enumerate() {
            v.all_finite(&field(&format!("strength[{ki}]")), key)?;
            v.non_negative(&field(&format!("strength[{ki}][1]")), key[1])?;
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
