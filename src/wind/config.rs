//! What the wind field computes and the per-frame values it computes from.
//!
//! [`WindConfig`] is a wind scene of the manifest made ready to run (its sources' camera paths
//! resolved) plus the field's grid and time constants. [`FieldDriver`] turns it, a camera, a
//! time and a walker into one frame's [`FieldParams`] (the compute stage's uniform) and
//! [`WindLookup`] (the uniform a shader reading the field binds). Everything that needs f64 is
//! done here, on the CPU: the camera's world cell, the noise windows' offsets and weights, source
//! positions relative to the camera's cell, the decay factors `exp(-dt / tau)`. The GPU stage
//! (`shaders/wind_field.wgsl`, [`super::field`]) and its CPU mirror ([`super::field_cpu`]) both
//! start from the same [`FieldParams`], so the tests compare the per-cell arithmetic alone.

use std::f64::consts::FRAC_PI_2;

use bytemuck::{Pod, Zeroable};
use glam::{DVec2, DVec3};
use thiserror::Error;

use crate::camera::sample_path;
use crate::hash::hash_u32;
use crate::world::{
    CameraPath, MAX_WIND_SOURCES, Manifest, SourcePlacement, WindDefaults, WindKey, WindSource,
};

/// Cells along each side of the field by default.
pub const DEFAULT_CELLS: u32 = 256;
/// Cell size by default, metres (256 cells of 1.25 m cover 320 m around the camera).
pub const DEFAULT_CELL_M: f32 = 1.25;
/// Octaves of the ambient noise.
pub const OCTAVES: usize = 4;
/// Period of each octave's noise lattice, lattice cells: the bounded noise domain.
pub const LATTICE_PERIOD: u32 = 1024;
/// Fraction of a source's radius over which its speed ramps up from zero at the centre, so
/// that omni and vortex sources have no singularity there.
pub const SOURCE_CORE: f32 = 0.05;
/// Seed of the ambient noise by default ("wind" in ASCII).
pub const DEFAULT_SEED: u32 = 0x7769_6e64;
/// Source kinds as the shader numbers them.
pub const KIND_DIRECTIONAL: u32 = 0;
/// Omni source.
pub const KIND_OMNI: u32 = 1;
/// Vortex source.
pub const KIND_VORTEX: u32 = 2;
/// Flag in [`FieldParams::counts`]`[1]`: the trail is on.
pub const FLAG_TRAIL: u32 = 1;
/// Flag in [`FieldParams::counts`]`[1]`: stamp the walker's segment this frame.
pub const FLAG_STAMP: u32 = 2;

/// The ambient wind of a scene. From a manifest, its values lie in the ranges that
/// [`Manifest::validate`] checks (speed 0..=[`crate::world::manifest::MAX_WIND_SPEED_MPS`],
/// direction within +-[`crate::world::manifest::MAX_ANGLE_DEG`]); the field's f32 arithmetic
/// needs no more (far larger speeds overflow it, and the GPU would draw them as calm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmbientWind {
    /// Direction the wind blows toward, degrees counter-clockwise from east.
    pub direction_deg: f64,
    /// Mean speed, metres per second.
    pub speed_mps: f64,
    /// Strength of gusts relative to the mean, 0..=1.
    pub gustiness: f64,
}

impl From<&WindDefaults> for AmbientWind {
    fn from(w: &WindDefaults) -> Self {
        Self {
            direction_deg: f64::from(w.direction_deg),
            speed_mps: f64::from(w.speed_mps),
            gustiness: f64::from(w.gustiness),
        }
    }
}

impl AmbientWind {
    /// Unit vector the wind blows toward.
    pub fn direction(&self) -> DVec2 {
        DVec2::from_angle(self.direction_deg.to_radians())
    }
}

/// A wind source of the manifest with its camera path resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceConfig {
    /// The source as the manifest gives it.
    pub source: WindSource,
    /// The camera path it follows, if any.
    pub path: Option<CameraPath>,
}

impl SourceConfig {
    /// Where the source is at scene time `time_s`: its fixed position, or its path's position
    /// (looping over the whole path, [`CameraPath::length_s`], counted from the source's start);
    /// `None` for a directional source without a position.
    pub fn position_at(&self, time_s: f64) -> Option<DVec2> {
        if let Some(path) = &self.path {
            let local = time_s - self.source.start_s();
            // A validated path spans a positive time; guard the loop all the same.
            let local = match path.length_s() {
                length if length > 0.0 => local.rem_euclid(length),
                _ => 0.0,
            };
            return Some(
                sample_path(path, path.start_s() + local)
                    .position
                    .truncate(),
            );
        }
        match self.source.placement() {
            SourcePlacement::Fixed(p) => Some(DVec2::from_array(p)),
            _ => None,
        }
    }

    /// The strength factor at scene time `time_s` (0 before the source's start).
    pub fn strength_at(&self, time_s: f64) -> f64 {
        self.source.strength_at(time_s - self.source.start_s())
    }
}

/// What can go wrong building a [`WindConfig`] from a manifest.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum WindError {
    /// No wind scene has the name asked for.
    #[error(
        "no wind scene called \"{name}\" ({})",
        crate::world::wind_scenes_held(.available)
    )]
    UnknownScene {
        /// The name asked for.
        name: String,
        /// The scenes the world has, comma-separated (empty when it has none).
        available: String,
    },
    /// A source follows a camera path that the manifest does not have (a manifest that was not
    /// validated).
    #[error(
        "wind scene \"{scene}\": source {index} follows camera path \"{path}\", which the world does not have"
    )]
    UnknownPath {
        /// The scene.
        scene: String,
        /// Index of the source.
        index: usize,
        /// The missing path.
        path: String,
    },
}

/// The wind field's configuration: the scene, the grid and the time constants.
#[derive(Clone, Debug, PartialEq)]
pub struct WindConfig {
    /// Name of the scene this came from (empty for the manifest's default wind).
    pub scene: String,
    /// Cells along each side of the square grid (even, at least 8).
    pub cells: u32,
    /// Cell size, metres.
    pub cell_m: f32,
    /// The ambient wind.
    pub ambient: AmbientWind,
    /// The scene's sources (at most [`MAX_WIND_SOURCES`] are used).
    pub source_list: Vec<SourceConfig>,
    /// Whether sources act (off: the field is the ambient wind alone).
    pub sources: bool,
    /// Whether the walker leaves a trail.
    pub trail: bool,
    /// Time constant with which source wind builds up (target stronger than the cell's wind).
    pub attack_s: f32,
    /// Time constant with which source wind dies down toward the ambient wind.
    pub release_s: f32,
    /// Time constant with which the trail fades.
    pub trail_fade_s: f32,
    /// Radius of the capsule the walker's step stamps, metres.
    pub trail_radius_m: f32,
    /// Longest step that still stamps a capsule, metres; a longer one (a teleport) starts a new
    /// trail at the new position.
    pub trail_max_step_m: f64,
    /// Wavelength of the coarsest ambient noise octave (its lattice spacing), metres.
    pub gust_scale_m: f64,
    /// Time each noise window scrolls before a fresh one (at a hashed offset) replaces it, s.
    pub window_s: f64,
    /// Cross-fade between an old and a new noise window, seconds (less than `window_s`).
    pub blend_s: f64,
    /// Seed of the ambient noise.
    pub seed: u32,
    /// Later scenes the wind changes to, in time order (empty: this one scene all along).
    pub changes: Vec<SceneChange>,
}

/// A change to another wind scene at a time: from `at_s` the scene's sources act (their times
/// counted from `at_s`) and the ambient wind blends into the scene's over `blend_s`.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneChange {
    /// Scene time of the change, seconds.
    pub at_s: f64,
    /// Seconds over which the ambient wind blends from the previous scene's.
    pub blend_s: f64,
    /// Name of the scene.
    pub scene: String,
    /// Its ambient wind.
    pub ambient: AmbientWind,
    /// Its sources.
    pub source_list: Vec<SourceConfig>,
}

/// The scene in effect at a time, as [`WindConfig::scene_at`] finds it.
#[derive(Clone, Copy, Debug)]
pub struct SceneAt<'a> {
    /// Name of the scene.
    pub name: &'a str,
    /// The ambient wind (blended with the previous scene's during a change).
    pub ambient: AmbientWind,
    /// The scene's sources.
    pub sources: &'a [SourceConfig],
    /// Time since the scene began (its sources' clock), seconds.
    pub local_s: f64,
}

impl WindConfig {
    /// A field of the default size and time constants over `ambient`, without sources.
    pub fn new(ambient: AmbientWind) -> Self {
        Self {
            scene: String::new(),
            cells: DEFAULT_CELLS,
            cell_m: DEFAULT_CELL_M,
            ambient,
            source_list: Vec::new(),
            sources: true,
            trail: true,
            attack_s: 0.15,
            release_s: 1.5,
            trail_fade_s: 3.0,
            trail_radius_m: 1.25,
            trail_max_step_m: 10.0,
            gust_scale_m: 48.0,
            window_s: 90.0,
            blend_s: 10.0,
            seed: DEFAULT_SEED,
            changes: Vec::new(),
        }
    }

    /// The configuration of a camera path's wind keys (`keys`, in time order; at least one):
    /// the first key's scene holds from the start, each later one takes over at its time.
    pub fn from_keys(manifest: &Manifest, keys: &[WindKey]) -> Result<Self, WindError> {
        let Some(first) = keys.first() else {
            return Self::from_scene(manifest, None);
        };
        let mut config = Self::from_scene(manifest, Some(&first.scene))?;
        // The first scene's sources count their time from its key.
        if first.t_s != 0.0 {
            config.changes.push(SceneChange {
                at_s: first.t_s,
                blend_s: 0.0,
                scene: config.scene.clone(),
                ambient: config.ambient,
                source_list: std::mem::take(&mut config.source_list),
            });
        }
        for key in &keys[1..] {
            let next = Self::from_scene(manifest, Some(&key.scene))?;
            config.changes.push(SceneChange {
                at_s: key.t_s,
                blend_s: key.blend_s.max(0.0),
                scene: next.scene,
                ambient: next.ambient,
                source_list: next.source_list,
            });
        }
        Ok(config)
    }

    /// The scene in effect at `time_s`.
    pub fn scene_at(&self, time_s: f64) -> SceneAt<'_> {
        let Some(i) = self.changes.iter().rposition(|c| c.at_s <= time_s) else {
            return SceneAt {
                name: &self.scene,
                ambient: self.ambient,
                sources: &self.source_list,
                local_s: time_s,
            };
        };
        let c = &self.changes[i];
        let prev = if i == 0 {
            &self.ambient
        } else {
            &self.changes[i - 1].ambient
        };
        let u = if c.blend_s > 0.0 {
            ((time_s - c.at_s) / c.blend_s).clamp(0.0, 1.0)
        } else {
            1.0
        };
        SceneAt {
            name: &c.scene,
            ambient: blend_ambient(prev, &c.ambient, u),
            sources: &c.source_list,
            local_s: time_s - c.at_s,
        }
    }

    /// The ambient wind at `time_s`.
    pub fn ambient_at(&self, time_s: f64) -> AmbientWind {
        self.scene_at(time_s).ambient
    }

    /// The distance the ambient wind travels from `t0` to `t1` (the integral of its mean wind
    /// vector), metres: what the noise pattern scrolls by. Exact for the piecewise-linear blends
    /// of [`Self::scene_at`], so the pattern moves continuously through a change of scene.
    pub fn drift_between(&self, t0: f64, t1: f64) -> DVec2 {
        let (lo, hi, sign) = if t0 <= t1 {
            (t0, t1, 1.0)
        } else {
            (t1, t0, -1.0)
        };
        // The integral over [lo, hi] of one piece of linear velocity, from `vs` at `s` to `ve`
        // at `e` (constant where the piece is unbounded or empty).
        let piece = |s: f64, e: f64, vs: DVec2, ve: DVec2| -> DVec2 {
            let (a, b) = (lo.max(s), hi.min(e));
            if b <= a {
                return DVec2::ZERO;
            }
            let at = |t: f64| {
                if e - s > 0.0 && (e - s).is_finite() {
                    vs + (ve - vs) * ((t - s) / (e - s))
                } else {
                    vs
                }
            };
            (at(a) + at(b)) * (0.5 * (b - a))
        };
        let mut sum = DVec2::ZERO;
        let mut v = drift_velocity(&self.ambient);
        let mut from = f64::NEG_INFINITY;
        for c in &self.changes {
            let next = drift_velocity(&c.ambient);
            let end = c.at_s + c.blend_s.max(0.0);
            sum += piece(from, c.at_s, v, v) + piece(c.at_s, end, v, next);
            (v, from) = (next, end);
        }
        sum += piece(from, f64::INFINITY, v, v);
        sum * sign
    }

    /// The configuration of the wind scene `scene_name` of `manifest`; without a name, the
    /// scene `breeze` if the world has one, else the manifest's `wind` defaults without sources.
    /// The manifest is taken as validated ([`Manifest::validate`] refuses speeds, strengths,
    /// radii, times and angles beyond their documented ranges).
    pub fn from_scene(manifest: &Manifest, scene_name: Option<&str>) -> Result<Self, WindError> {
        let scene = match scene_name {
            Some(name) => {
                Some(
                    manifest
                        .wind_scene(name)
                        .ok_or_else(|| WindError::UnknownScene {
                            name: name.to_string(),
                            available: crate::world::name_list(
                                manifest.wind_scenes.iter().map(|s| s.name.as_str()),
                            ),
                        })?,
                )
            }
            None => manifest.wind_scene("breeze"),
        };
        let Some(scene) = scene else {
            return Ok(Self::new(AmbientWind::from(&manifest.wind)));
        };
        let mut config = Self::new(AmbientWind::from(&scene.ambient));
        config.scene = scene.name.clone();
        for (index, source) in scene.sources.iter().enumerate() {
            let path = match source.placement() {
                SourcePlacement::Path(name) => Some(manifest.path(name).cloned().ok_or_else(
                    || WindError::UnknownPath {
                        scene: scene.name.clone(),
                        index,
                        path: name.to_string(),
                    },
                )?),
                _ => None,
            };
            config.source_list.push(SourceConfig {
                source: source.clone(),
                path,
            });
        }
        Ok(config)
    }

    /// Cells in the grid (`cells * cells`).
    pub fn cell_count(&self) -> usize {
        (self.cells as usize) * (self.cells as usize)
    }

    /// The world cell holding `world_xy`.
    pub fn world_cell(&self, world_xy: DVec2) -> [i32; 2] {
        let c = (world_xy / f64::from(self.cell_m)).floor();
        // Worlds are at most 10,000 km wide: 8e6 cells of 1.25 m fit an i32 easily.
        [c.x as i32, c.y as i32]
    }

    /// Storage index of world cell `cell` (toroidal: `(i mod n, j mod n)`, Euclidean).
    pub fn storage_index(&self, cell: [i32; 2]) -> usize {
        let n = self.cells as i32;
        (cell[1].rem_euclid(n) * n + cell[0].rem_euclid(n)) as usize
    }
}

/// The ambient wind's mean vector, m/s.
fn drift_velocity(a: &AmbientWind) -> DVec2 {
    a.direction() * a.speed_mps
}

/// `a` blended into `b` by `u` in 0..=1: the mean wind vectors linearly (so the drift integrates
/// exactly), gustiness linearly.
fn blend_ambient(a: &AmbientWind, b: &AmbientWind, u: f64) -> AmbientWind {
    if u >= 1.0 {
        return *b;
    }
    let v = drift_velocity(a).lerp(drift_velocity(b), u);
    let speed = v.length();
    let direction_deg = if speed > 1e-9 {
        v.y.atan2(v.x).to_degrees()
    } else {
        b.direction_deg
    };
    AmbientWind {
        direction_deg,
        speed_mps: speed,
        gustiness: a.gustiness + (b.gustiness - a.gustiness) * u,
    }
}

/// The compute stage's uniform (`Params` in `shaders/wind_field.wgsl`), one frame's worth.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct FieldParams {
    /// The camera's world cell.
    pub origin_cell: [i32; 2],
    /// Cells along each side.
    pub n: u32,
    /// Cell size, metres.
    pub cell_m: f32,
    /// Ambient direction (unit xy), mean speed (m/s), gustiness.
    pub ambient: [f32; 4],
    /// Weight of the new noise window, of the old one; unused, unused.
    pub blend: [f32; 4],
    /// Attack factor `exp(-dt / attack)`, release factor, trail fade factor, trail radius (m).
    pub decay: [f32; 4],
    /// The walker's step: start xy, end xy, metres from the origin cell's south-west corner.
    pub trail: [f32; 4],
    /// Push direction on the step's axis (unit xy), cross-wind fraction, gust gain.
    pub extra: [f32; 4],
    /// Sources in use, flags ([`FLAG_TRAIL`], [`FLAG_STAMP`]), lattice period, noise seed.
    pub counts: [u32; 4],
    /// Lattice cells per metre of each octave.
    pub octave_freq: [f32; 4],
    /// Amplitude of each octave (they sum to 1).
    pub octave_amp: [f32; 4],
    /// Per octave: the new window's lattice position of the origin cell's south-west corner
    /// (xy), the old window's (zw); each reduced modulo the lattice period.
    pub windows: [[f32; 4]; OCTAVES],
    /// The sources in use.
    pub sources: [SourceGpu; MAX_WIND_SOURCES],
}
const _: () = assert!(std::mem::size_of::<FieldParams>() == 208 + 32 * MAX_WIND_SOURCES);

/// One source as the shader sees it (`Source` in `shaders/wind_field.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SourceGpu {
    /// Centre, metres from the origin cell's south-west corner.
    pub center: [f32; 2],
    /// Reach, metres (unused by directional sources).
    pub radius: f32,
    /// [`KIND_DIRECTIONAL`], [`KIND_OMNI`] or [`KIND_VORTEX`].
    pub kind: u32,
    /// Directional: the wind vector (m/s). Omni: outward speed, 0. Vortex: tangential speed
    /// (positive counter-clockwise), inflow speed. All scaled by the strength at this time.
    pub a: [f32; 2],
    /// Unused.
    pub b: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<SourceGpu>() == 32);

/// Per-cell state of the field (`CellState` in `shaders/wind_field.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct CellState {
    /// Source-driven wind, m/s.
    pub source: [f32; 2],
    /// The world cell this storage cell last held ([`CellState::EMPTY_TAG`] at first).
    pub tag: [i32; 2],
}

impl CellState {
    /// Tag of a cell that holds no world cell yet (no world cell has this index).
    pub const EMPTY_TAG: i32 = i32::MIN;
    /// A cell holding nothing.
    pub const EMPTY: CellState = CellState {
        source: [0.0; 2],
        tag: [Self::EMPTY_TAG; 2],
    };
}

/// The uniform a shader that reads the field binds (`WindLookup` in `shaders/shared/wind_lookup.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct WindLookup {
    /// The camera's world cell (the field covers world cells `origin - n/2 ..= origin + n/2 - 1`
    /// on each axis).
    pub origin_cell: [i32; 2],
    /// Cells along each side.
    pub n: u32,
    /// Cell size, metres.
    pub cell_m: f32,
    /// The camera's xy minus its cell's south-west corner, metres (in `0..cell_m`), computed in
    /// f64 before rounding.
    pub camera_offset: [f32; 2],
    /// Padding (uniform structs are 16-byte multiples).
    pub _pad: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<WindLookup>() == 32);

/// Turns a [`WindConfig`] and each frame's camera, time and walker into the frame's uniforms;
/// remembers the walker's last position for the trail.
#[derive(Clone, Debug)]
pub struct FieldDriver {
    config: WindConfig,
    walker_prev: Option<DVec2>,
    push_dir: DVec2,
}

impl FieldDriver {
    /// A driver for `config`, with no walker seen yet.
    pub fn new(config: &WindConfig) -> Self {
        Self {
            config: config.clone(),
            walker_prev: None,
            push_dir: config.ambient.direction(),
        }
    }

    /// The configuration.
    pub fn config(&self) -> &WindConfig {
        &self.config
    }

    /// Adds a change of scene (at or after the last one's time).
    pub fn push_change(&mut self, change: SceneChange) {
        self.config.changes.push(change);
    }

    /// One frame's uniforms: the camera at `camera_world`, scene time `time_s`, `dt_s` since the
    /// last frame (negative or NaN counts as 0), the walker (if any) at `walker_world`.
    pub fn frame(
        &mut self,
        camera_world: DVec3,
        time_s: f64,
        dt_s: f32,
        walker_world: Option<DVec2>,
    ) -> (FieldParams, WindLookup) {
        let c = &self.config;
        let cell = f64::from(c.cell_m);
        let cam = camera_world.truncate();
        let origin = c.world_cell(cam);
        let corner = DVec2::new(f64::from(origin[0]), f64::from(origin[1])) * cell;
        let rel = |p: DVec2| -> [f32; 2] { (p - corner).as_vec2().to_array() };
        let dt = if dt_s.is_finite() {
            f64::from(dt_s.max(0.0))
        } else {
            0.0
        };

        let mut sources = [SourceGpu::default(); MAX_WIND_SOURCES];
        let mut used = 0;
        let now = c.scene_at(time_s);
        if c.sources {
            for s in now.sources.iter().take(MAX_WIND_SOURCES) {
                let strength = s.strength_at(now.local_s);
                if strength <= 0.0 {
                    continue;
                }
                let center = s.position_at(now.local_s).map_or([0.0; 2], rel);
                let g = match &s.source {
                    WindSource::Directional {
                        direction_deg,
                        speed_mps,
                        ..
                    } => SourceGpu {
                        center,
                        radius: 0.0,
                        kind: KIND_DIRECTIONAL,
                        a: (DVec2::from_angle(direction_deg.to_radians()) * speed_mps * strength)
                            .as_vec2()
                            .to_array(),
                        b: [0.0; 2],
                    },
                    WindSource::Omni {
                        radius_m,
                        speed_mps,
                        ..
                    } => SourceGpu {
                        center,
                        radius: *radius_m as f32,
                        kind: KIND_OMNI,
                        a: [(speed_mps * strength) as f32, 0.0],
                        b: [0.0; 2],
                    },
                    WindSource::Vortex {
                        radius_m,
                        speed_mps,
                        clockwise,
                        inflow_mps,
                        ..
                    } => {
                        let sense = if *clockwise { -1.0 } else { 1.0 };
                        SourceGpu {
                            center,
                            radius: *radius_m as f32,
                            kind: KIND_VORTEX,
                            a: [
                                (sense * speed_mps * strength) as f32,
                                (inflow_mps * strength) as f32,
                            ],
                            b: [0.0; 2],
                        }
                    }
                };
                sources[used] = g;
                used += 1;
            }
        }

        // The trail: the walker's step since the last frame, unless it jumped.
        let mut flags = 0;
        let mut step = [0.0f32; 4];
        if c.trail {
            flags |= FLAG_TRAIL;
            match walker_world {
                Some(now) => {
                    let from = match self.walker_prev {
                        Some(prev) if prev.distance(now) <= c.trail_max_step_m => prev,
                        _ => now,
                    };
                    let travel = now - from;
                    if travel.length() > 1e-6 {
                        self.push_dir = travel.normalize();
                    }
                    let (a, b) = (rel(from), rel(now));
                    step = [a[0], a[1], b[0], b[1]];
                    flags |= FLAG_STAMP;
                    self.walker_prev = Some(now);
                }
                None => self.walker_prev = None,
            }
        }

        let factor = |tau: f32| (-dt / f64::from(tau).max(1e-6)).exp() as f32;
        let mut params = ambient_params(c, corner, time_s);
        params.origin_cell = origin;
        params.n = c.cells;
        params.cell_m = c.cell_m;
        params.decay = [
            factor(c.attack_s),
            factor(c.release_s),
            factor(c.trail_fade_s),
            c.trail_radius_m,
        ];
        params.trail = step;
        params.extra[0] = self.push_dir.x as f32;
        params.extra[1] = self.push_dir.y as f32;
        params.counts[0] = used as u32;
        params.counts[1] = flags;
        params.sources = sources;
        let lookup = WindLookup {
            origin_cell: origin,
            n: c.cells,
            cell_m: c.cell_m,
            camera_offset: rel(cam),
            _pad: [0.0; 2],
        };
        (params, lookup)
    }
}

/// The ambient part of a frame's uniform: the ambient wind, the noise octaves and the two
/// noise windows at `time_s` seen from `corner` (the origin cell's south-west corner, metres);
/// everything else zero.
pub fn ambient_params(config: &WindConfig, corner: DVec2, time_s: f64) -> FieldParams {
    let ambient = config.ambient_at(time_s);
    let dir = ambient.direction();
    let (weights, windows) = noise_windows(config, corner, time_s);
    let amp_sum: f64 = (0..OCTAVES).map(|o| 0.5f64.powi(o as i32)).sum();
    FieldParams {
        ambient: [
            dir.x as f32,
            dir.y as f32,
            ambient.speed_mps as f32,
            ambient.gustiness as f32,
        ],
        blend: [weights[0] as f32, weights[1] as f32, 0.0, 0.0],
        extra: [0.0, 0.0, (0.1 + 0.25 * ambient.gustiness) as f32, GUST_GAIN],
        counts: [0, 0, LATTICE_PERIOD, config.seed],
        octave_freq: std::array::from_fn(|o| (2f64.powi(o as i32) / config.gust_scale_m) as f32),
        octave_amp: std::array::from_fn(|o| (0.5f64.powi(o as i32) / amp_sum) as f32),
        windows,
        ..Zeroable::zeroed()
    }
}

/// Gain on the normalised noise before it is clamped to -1..=1 (the sum of octaves rarely
/// reaches its bounds; this spreads it over them).
pub const GUST_GAIN: f32 = 1.6;

/// How much faster than the wind each octave's pattern travels, per octave: fine gusts run
/// ahead of coarse ones, so the pattern evolves as it travels instead of sliding rigidly.
pub const OCTAVE_DRIFT: f64 = 0.2;

/// The two noise windows at `time_s`: weights (new, old) and, per octave, each window's lattice
/// position of `corner`.
///
/// Window `k` starts at time `k * window_s` at a hashed position of the lattice and scrolls with
/// the wind from there; for its first `blend_s` seconds it fades in while window `k - 1` fades
/// out (weights `sin` and `cos` of a smoothstep, so that the sum of two independent noises keeps
/// its variance). Each window scrolls for at most `window_s + blend_s` seconds, so its offset
/// stays small and f32-exact however long the scene runs, and a fresh hashed position means the
/// pattern never repeats.
pub fn noise_windows(
    config: &WindConfig,
    corner: DVec2,
    time_s: f64,
) -> ([f64; 2], [[f32; 4]; OCTAVES]) {
    let period = config.window_s.max(1e-3);
    let blend = config.blend_s.clamp(1e-3, period);
    let k = (time_s / period).floor();
    let tau_new = time_s - k * period;
    let u = (tau_new / blend).clamp(0.0, 1.0);
    let s = u * u * (3.0 - 2.0 * u);
    let weights = [(FRAC_PI_2 * s).sin(), (FRAC_PI_2 * s).cos()];
    let p = f64::from(LATTICE_PERIOD);
    // How far the wind carried each window since it started.
    let drift = [
        config.drift_between(k * period, time_s),
        config.drift_between((k - 1.0) * period, time_s),
    ];
    let mut windows = [[0.0f32; 4]; OCTAVES];
    for (o, w) in windows.iter_mut().enumerate() {
        let freq = 2f64.powi(o as i32) / config.gust_scale_m;
        let speed = 1.0 + OCTAVE_DRIFT * o as f64;
        for (slot, index) in [k, k - 1.0].into_iter().enumerate() {
            let origin = window_origin(index as i64, o as u32, config.seed);
            let q = (corner - drift[slot] * speed) * freq + origin;
            w[slot * 2] = q.x.rem_euclid(p) as f32;
            w[slot * 2 + 1] = q.y.rem_euclid(p) as f32;
        }
    }
    // An f32 rounding of a value just under the period can give the period itself; the lattice
    // wraps it anyway.
    (weights, windows)
}

/// Hashed start of noise window `index` for `octave`, lattice cells in `0..LATTICE_PERIOD`.
fn window_origin(index: i64, octave: u32, seed: u32) -> DVec2 {
    let lo = index as u32;
    let hi = (index >> 32) as u32;
    let h = |salt: u32| hash_u32(lo ^ hash_u32(hi ^ hash_u32(octave ^ hash_u32(seed ^ salt))));
    let unit = |x: u32| f64::from(x) / 4_294_967_296.0;
    DVec2::new(unit(h(0x51)), unit(h(0xa7))) * f64::from(LATTICE_PERIOD)
}
