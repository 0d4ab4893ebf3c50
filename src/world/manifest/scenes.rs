//! The manifest's named wind scenes (ambient wind and local sources) and camera paths (keys,
//! and the wind scenes a flight switches between).

use serde::{Deserialize, Serialize};

/// Default ambient wind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindDefaults {
    /// Direction the wind blows toward, degrees counter-clockwise from east (within
    /// +-[`MAX_ANGLE_DEG`](super::MAX_ANGLE_DEG)).
    pub direction_deg: f32,
    /// Mean speed, metres per second, 0..=[`MAX_WIND_SPEED_MPS`](super::MAX_WIND_SPEED_MPS) (120).
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
/// Ranges: speeds (`speed_mps` 0..=[`MAX_WIND_SPEED_MPS`](super::MAX_WIND_SPEED_MPS), `inflow_mps` either way up to it),
/// `radius_m` above 0 and at most [`MAX_WIND_RADIUS_M`](super::MAX_WIND_RADIUS_M), `direction_deg` within
/// +-[`MAX_ANGLE_DEG`](super::MAX_ANGLE_DEG), `position_m` within +-[`MAX_POSITION_M`](super::MAX_POSITION_M), `start_s` 0..=[`MAX_TIME_S`](super::MAX_TIME_S),
/// strength key times within +-[`MAX_TIME_S`](super::MAX_TIME_S) and factors 0..=[`MAX_WIND_STRENGTH`](super::MAX_WIND_STRENGTH).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
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

/// A wind source as its table is written: its `kind` and the fields of every kind, each read
/// in place (a value of the wrong shape is named with its field and line, which reading the
/// kinds' variants directly lost), then checked against the kind into a [`WindSource`].
#[derive(Deserialize)]
#[serde(
    deny_unknown_fields,
    expecting = "a wind source: a table with its kind and fields"
)]
struct WrittenWindSource {
    #[serde(deserialize_with = "source_kind")]
    kind: String,
    direction_deg: Option<f64>,
    speed_mps: Option<f64>,
    radius_m: Option<f64>,
    clockwise: Option<bool>,
    inflow_mps: Option<f64>,
    #[serde(default, deserialize_with = "super::exact_opt")]
    position_m: Option<[f64; 2]>,
    path: Option<String>,
    #[serde(default)]
    start_s: f64,
    #[serde(default, deserialize_with = "exact_pairs")]
    strength: Vec<[f64; 2]>,
    #[serde(default)]
    repeat: bool,
}

/// The kinds of wind source.
const SOURCE_KINDS: [&str; 3] = ["directional", "omni", "vortex"];

/// Reads a wind source's `kind`, refusing one that is not a kind where it is written.
fn source_kind<'de, D>(d: D) -> Result<String, D::Error>
where
    D: serde::Deserializer<'de>,
{
    let kind = String::deserialize(d)?;
    if SOURCE_KINDS.contains(&kind.as_str()) {
        Ok(kind)
    } else {
        Err(serde::de::Error::custom(unknown_kind(&kind)))
    }
}

fn unknown_kind(kind: &str) -> String {
    format!("unknown wind source kind {kind:?}: expected \"directional\", \"omni\" or \"vortex\"")
}

/// Reads a wind source's table and checks it against its kind within the table, so that an
/// error names the source's own place in the file (a conversion after the table was read was
/// told at the list's start: the first `[[wind_scenes.sources]]`, or `sources = [`).
impl<'de> Deserialize<'de> for WindSource {
    fn deserialize<D>(d: D) -> Result<Self, D::Error>
    where
        D: serde::Deserializer<'de>,
    {
        struct Table;
        impl<'de> serde::de::Visitor<'de> for Table {
            type Value = WindSource;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a wind source: a table with its kind and fields")
            }
            fn visit_map<A>(self, map: A) -> Result<WindSource, A::Error>
            where
                A: serde::de::MapAccess<'de>,
            {
                let written = WrittenWindSource::deserialize(
                    serde::de::value::MapAccessDeserializer::new(map),
                )?;
                WindSource::try_from(written).map_err(serde::de::Error::custom)
            }
        }
        d.deserialize_map(Table)
    }
}

/// `kind` with its indefinite article: "an omni", "a vortex".
pub(super) fn article(kind: &str) -> String {
    match kind.chars().next() {
        Some('a' | 'e' | 'i' | 'o' | 'u') => format!("an {kind}"),
        _ => format!("a {kind}"),
    }
}

/// Reads a list of `[time, factor]` pairs, refusing a pair of another length ([`super::exact`]).
fn exact_pairs<'de, D>(d: D) -> Result<Vec<[f64; 2]>, D::Error>
where
    D: serde::Deserializer<'de>,
{
    Vec::<Vec<f64>>::deserialize(d)?
        .into_iter()
        .map(super::array_of)
        .collect()
}

impl TryFrom<WrittenWindSource> for WindSource {
    type Error = String;

    fn try_from(w: WrittenWindSource) -> Result<Self, String> {
        let kind = w.kind.as_str();
        let need = |value: Option<f64>, field: &str| {
            value.ok_or_else(|| format!("missing field `{field}` of {} wind source", article(kind)))
        };
        let foreign = |present: bool, field: &str| {
            if present {
                Err(format!(
                    "unknown field `{field}` for {} wind source (it belongs to another kind)",
                    article(kind)
                ))
            } else {
                Ok(())
            }
        };
        let (position_m, path, start_s, strength, repeat) =
            (w.position_m, w.path, w.start_s, w.strength, w.repeat);
        match kind {
            "directional" => {
                foreign(w.radius_m.is_some(), "radius_m")?;
                foreign(w.clockwise.is_some(), "clockwise")?;
                foreign(w.inflow_mps.is_some(), "inflow_mps")?;
                Ok(WindSource::Directional {
                    direction_deg: need(w.direction_deg, "direction_deg")?,
                    speed_mps: need(w.speed_mps, "speed_mps")?,
                    position_m,
                    path,
                    start_s,
                    strength,
                    repeat,
                })
            }
            "omni" => {
                foreign(w.direction_deg.is_some(), "direction_deg")?;
                foreign(w.clockwise.is_some(), "clockwise")?;
                foreign(w.inflow_mps.is_some(), "inflow_mps")?;
                Ok(WindSource::Omni {
                    radius_m: need(w.radius_m, "radius_m")?,
                    speed_mps: need(w.speed_mps, "speed_mps")?,
                    position_m,
                    path,
                    start_s,
                    strength,
                    repeat,
                })
            }
            "vortex" => {
                foreign(w.direction_deg.is_some(), "direction_deg")?;
                Ok(WindSource::Vortex {
                    radius_m: need(w.radius_m, "radius_m")?,
                    speed_mps: need(w.speed_mps, "speed_mps")?,
                    clockwise: w.clockwise.unwrap_or(false),
                    inflow_mps: w.inflow_mps.unwrap_or(0.0),
                    position_m,
                    path,
                    start_s,
                    strength,
                    repeat,
                })
            }
            other => Err(unknown_kind(other)),
        }
    }
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
pub(super) type SourceCommon<'a> = (
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

    pub(super) fn common(&self) -> SourceCommon<'_> {
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

/// A named camera flight.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraPath {
    /// Name, unique within the world.
    pub name: String,
    /// Length of the flight, seconds: the span of the keys' times ([`CameraPath::length_s`],
    /// which is what every tool flies), stated in the manifest for its reader; validation
    /// refuses one that differs from the keys' span by more than
    /// [`PATH_DURATION_TOLERANCE_S`] (and one above [`MAX_TIME_S`](super::MAX_TIME_S)).
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

/// How far a camera path's `duration_s` may differ from its keys' span, seconds (a rounding in
/// the text of the manifest, never a different length).
pub const PATH_DURATION_TOLERANCE_S: f64 = 1e-3;

impl CameraPath {
    /// A path through `keys` (in strictly increasing time order), its `duration_s` their span,
    /// without a walker or wind keys.
    pub fn through(name: impl Into<String>, keys: Vec<CameraKey>) -> Self {
        let mut path = Self {
            name: name.into(),
            duration_s: 0.0,
            walker: None,
            keys,
            wind: Vec::new(),
        };
        path.duration_s = path.length_s();
        path
    }

    /// Time of the first key, seconds (0 for a path without keys, which validation refuses).
    pub fn start_s(&self) -> f64 {
        self.keys.first().map_or(0.0, |k| k.t_s)
    }

    /// Time of the last key, seconds.
    pub fn end_s(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.t_s)
    }

    /// The path's length, seconds: the span of its keys' times, from the first key's to the
    /// last's. Every tool flies a path over this span (`duration_s` states it; validation checks
    /// that they agree).
    pub fn length_s(&self) -> f64 {
        self.end_s() - self.start_s()
    }

    /// The time a `fraction` (0 at the first key, 1 at the last) of the way along the path.
    pub fn time_at(&self, fraction: f64) -> f64 {
        self.start_s() + fraction * self.length_s()
    }
}

/// A change of wind scene along a camera path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindKey {
    /// Time from the start of the path, seconds (within +-[`MAX_TIME_S`](super::MAX_TIME_S)); the scene's source
    /// times count from here.
    pub t_s: f64,
    /// Name of a wind scene of the world.
    pub scene: String,
    /// Seconds over which the ambient wind blends from the previous scene's into this one's
    /// (0..=[`MAX_TIME_S`](super::MAX_TIME_S)).
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
    /// Time from the start of the path, seconds (within +-[`MAX_TIME_S`](super::MAX_TIME_S)).
    pub t_s: f64,
    /// Absolute position, metres (x east, y north, z up; each within +-[`MAX_POSITION_M`](super::MAX_POSITION_M)).
    #[serde(deserialize_with = "super::exact")]
    pub position_m: [f64; 3],
    /// Heading, degrees counter-clockwise from east (0 looks east, 90 north; within
    /// +-[`MAX_ANGLE_DEG`](super::MAX_ANGLE_DEG)).
    pub yaw_deg: f64,
    /// Degrees above the horizontal, -90..=90; negative looks down.
    pub pitch_deg: f64,
}
