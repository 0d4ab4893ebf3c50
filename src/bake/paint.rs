//! Step 2 of the bake: grass type and density painted on the finest grid, and the grass
//! types a baked world lists.

use std::path::Path;

use glam::DVec2;

use crate::world::error::WorldError;
use crate::world::manifest::{GrassType, Manifest};

use super::BakeStage;
use super::cancel::CancelFlag;
use super::resample::Grid;

/// Steepest slope that carries grass, degrees.
pub const MAX_GRASS_SLOPE_DEG: f64 = 35.0;

/// A starter set of plant types for a baked world's grass types (`meadow`, `tall grass`, `dry
/// grass`): two flowers, a fern and a bush, about one plant per 1.5 m2 of meadow. The baker does
/// not write them yet (see the README's Plants section); `verdant::world::Manifest::plant_types`
/// takes them as they are.
pub fn default_plant_types() -> Vec<crate::world::PlantType> {
    use crate::world::{PlantType, PlantWind};
    #[allow(clippy::too_many_arguments)]
    let plant = |name: &str,
                 mesh: &str,
                 color: [f32; 3],
                 size_m: [f32; 2],
                 density: &[(&str, f32)],
                 (max_slope_deg, clump_m, clump_cover): (f32, f32, f32),
                 seed: u32,
                 wind: PlantWind| PlantType {
        name: name.into(),
        mesh: mesh.into(),
        color,
        size_m,
        density: density.iter().map(|&(g, d)| (g.to_string(), d)).collect(),
        max_slope_deg,
        altitude_m: [-500.0, 9000.0],
        clump_m,
        clump_cover,
        seed,
        wind,
    };
    let flower = |hz: f32, damping: f32| PlantWind {
        bend: 0.045,
        stiffness: 0.3,
        sway_spring_hz: hz,
        sway_damping: damping,
        detail_amplitude: 1.2,
        ..PlantWind::default()
    };
    vec![
        plant(
            "poppy",
            "flower",
            [0.8, 0.1, 0.03],
            [0.35, 0.65],
            &[("meadow", 0.45), ("dry grass", 0.12)],
            (35.0, 8.0, 0.5),
            1,
            flower(1.2, 0.25),
        ),
        plant(
            "cornflower",
            "flower",
            [0.22, 0.3, 0.85],
            [0.4, 0.7],
            &[("meadow", 0.3), ("tall grass", 0.1)],
            (35.0, 10.0, 0.45),
            2,
            flower(1.0, 0.3),
        ),
        plant(
            "fern",
            "fern",
            [0.12, 0.3, 0.05],
            [0.5, 0.9],
            &[("meadow", 0.06), ("tall grass", 0.25)],
            (40.0, 12.0, 0.4),
            3,
            PlantWind {
                bend: 0.03,
                stiffness: 0.4,
                sway_spring_hz: 0.9,
                sway_damping: 0.4,
                ..PlantWind::default()
            },
        ),
        plant(
            "bush",
            "bush",
            [0.1, 0.24, 0.04],
            [0.7, 1.4],
            &[("meadow", 0.05), ("tall grass", 0.05), ("dry grass", 0.04)],
            (30.0, 20.0, 0.35),
            4,
            PlantWind {
                bend: 0.012,
                stiffness: 0.75,
                sway_spring_hz: 1.6,
                sway_damping: 0.5,
                detail_amplitude: 0.8,
                ..PlantWind::default()
            },
        ),
    ]
}

/// The grass types of a baked world: 0 bare rock, 1 meadow, 2 tall grass, 3 dry grass. The
/// widths are chosen for coverage at the least cost: on an H100 at 1920x1080, doubling them
/// from 2-3.5 cm (meadow) took the meadow's coverage within 30 m from 19% to 33% for 0.4 ms
/// more grass time, where halving the spacing to reach as much would have cost 4 times the
/// blades.
pub fn default_grass_types() -> Vec<GrassType> {
    vec![
        GrassType {
            name: "bare".into(),
            ground_color: [0.30, 0.27, 0.23],
            base_color: [0.30, 0.27, 0.23],
            tip_color: [0.30, 0.27, 0.23],
            height_m: [0.0, 0.0],
            width_m: [0.0, 0.0],
            stiffness: 1.0,
        },
        GrassType {
            name: "meadow".into(),
            ground_color: [0.10, 0.16, 0.05],
            base_color: [0.04, 0.14, 0.02],
            tip_color: [0.22, 0.45, 0.08],
            height_m: [0.15, 0.35],
            width_m: [0.04, 0.07],
            stiffness: 0.6,
        },
        GrassType {
            name: "tall grass".into(),
            ground_color: [0.09, 0.13, 0.05],
            base_color: [0.05, 0.12, 0.02],
            tip_color: [0.32, 0.42, 0.10],
            height_m: [0.5, 1.1],
            width_m: [0.05, 0.09],
            stiffness: 0.35,
        },
        GrassType {
            name: "dry grass".into(),
            ground_color: [0.28, 0.21, 0.10],
            base_color: [0.25, 0.18, 0.06],
            tip_color: [0.70, 0.52, 0.22],
            height_m: [0.25, 0.6],
            width_m: [0.03, 0.06],
            stiffness: 0.5,
        },
    ]
}
/// The maps a bake paints from besides the procedural rule (see [`super::cover`]).
#[derive(Default)]
pub(super) struct PaintMaps<'a> {
    /// Land cover: its classes choose grass type and density.
    pub(super) cover: Option<&'a super::cover::CoverMap>,
    /// Density, 0 to 1: scales the painted cover.
    pub(super) density: Option<&'a super::cover::ValueMap>,
    /// Mask: nothing grows where it is not 0.
    pub(super) mask: Option<&'a super::cover::ValueMap>,
}

/// The finest grid with grass painted on it.
pub(super) struct Painted {
    pub(super) grid: Grid,
    pub(super) grass_type: Vec<u8>,
    pub(super) density: Vec<u8>,
    /// Terrain material bytes, where the land-cover table names materials; else empty.
    pub(super) material: Vec<u8>,
    /// The bake's cancel flag, which the long searches for camera paths check as they go.
    pub(super) cancel: Option<CancelFlag>,
}

impl Painted {
    /// Whether the bake was cancelled: a search then ends early, its result unused.
    pub(super) fn cancelled(&self) -> bool {
        self.cancel.as_ref().is_some_and(CancelFlag::is_cancelled)
    }

    /// Index of the painted sample nearest `p` (metres; clamped to the grid).
    pub(super) fn index_at(&self, p: DVec2) -> usize {
        self.grid.index_at(p)
    }
}

impl Grid {
    /// Paints every sample: from the land-cover map where it has a class there (the slope rule
    /// still holds), by the procedural rule elsewhere; then the density map scales the cover and
    /// the mask clears it. The class's material is the ground's (the mask leaves it).
    /// `slope_deg` gives each sample's slope (measured on the finest grid).
    pub(super) fn paint(
        self,
        height_range: [f32; 2],
        seed: u64,
        maps: &PaintMaps<'_>,
        slope_deg: &dyn Fn(&Grid, usize, usize) -> f64,
        cancelled: &dyn Fn() -> Result<(), WorldError>,
        progress: &mut dyn FnMut(BakeStage, u64, u64),
    ) -> Result<Painted, WorldError> {
        let n = self.width * self.height;
        let mut grass_type = vec![0u8; n];
        let mut density = vec![0u8; n];
        let with_materials = maps.cover.is_some_and(|c| c.has_materials());
        let mut material = vec![0u8; if with_materials { n } else { 0 }];
        let span = f64::from(height_range[1] - height_range[0]);
        for b in 0..self.height {
            for a in 0..self.width {
                let altitude = (f64::from(self.at(a, b) - height_range[0]) / span).clamp(0.0, 1.0);
                let (slope, p) = (slope_deg(&self, a, b), self.position(a, b));
                let class = maps.cover.and_then(|c| c.paint_at(p));
                let (t, d) = match class {
                    Some(_) if slope > MAX_GRASS_SLOPE_DEG => (0, 0),
                    Some(c) => (c.grass_type, c.density),
                    None => paint_sample(slope, altitude, p, seed),
                };
                if let (Some(m), Some(c)) = (material.get_mut(b * self.width + a), class) {
                    *m = c.material;
                }
                let masked = maps.mask.and_then(|m| m.at(p)).is_some_and(|v| v != 0.0);
                let d = match maps.density.and_then(|m| m.at(p)) {
                    _ if masked => 0,
                    Some(v) => (f64::from(d) * v).round() as u8,
                    None => d,
                };
                let t = if d == 0 { 0 } else { t };
                grass_type[b * self.width + a] = t;
                density[b * self.width + a] = d;
            }
            if b % 64 == 0 || b + 1 == self.height {
                cancelled()?;
                progress(BakeStage::Paint, b as u64 + 1, self.height as u64);
            }
        }
        Ok(Painted {
            grid: self,
            grass_type,
            density,
            material,
            cancel: None,
        })
    }
}
/// Grass type and density byte of one sample from its slope (degrees), altitude (0 at the
/// world's lowest point, 1 at its highest) and position (for the noise).
pub(super) fn paint_sample(slope_deg: f64, altitude: f64, p: DVec2, seed: u64) -> (u8, u8) {
    if slope_deg > MAX_GRASS_SLOPE_DEG {
        return (0, 0);
    }
    // Large patches (a couple of km) decide how dry the ground is; small ones (a few hundred m)
    // break up the cover and place tall grass.
    let broad = fbm(p / 1800.0, seed, 3);
    let patch = fbm(p / 300.0, seed.wrapping_add(1), 3);
    let speckle = fbm(p / 90.0, seed.wrapping_add(2), 2);
    // Rocky outcrops on steep-ish ground.
    if slope_deg > 27.0 && patch > 0.58 {
        return (0, 0);
    }
    let dryness = 1.1 * altitude + 0.9 * (broad - 0.5) + 0.25 * slope_deg / MAX_GRASS_SLOPE_DEG;
    let kind = if dryness > 0.72 {
        3
    } else if patch > 0.56 && slope_deg < 18.0 {
        2
    } else {
        1
    };
    let steepness = smoothstep(18.0, MAX_GRASS_SLOPE_DEG, slope_deg);
    let cover = (0.55 + 0.45 * speckle) * (1.0 - steepness) * if kind == 3 { 0.8 } else { 1.0 };
    let byte = (cover.clamp(0.0, 1.0) * 255.0).round() as u8;
    if byte == 0 { (0, 0) } else { (kind, byte) }
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// A hash of a lattice point to 0..1.
fn lattice(ix: i64, iy: i64, seed: u64) -> f64 {
    let mut z = seed
        ^ (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in 0..1 with one lattice cell per unit.
fn value_noise(p: DVec2, seed: u64) -> f64 {
    let f = p.floor();
    let (ix, iy) = (f.x as i64, f.y as i64);
    let t = p - f;
    let s = t * t * (DVec2::splat(3.0) - 2.0 * t);
    let v00 = lattice(ix, iy, seed);
    let v10 = lattice(ix + 1, iy, seed);
    let v01 = lattice(ix, iy + 1, seed);
    let v11 = lattice(ix + 1, iy + 1, seed);
    let south = v00 + (v10 - v00) * s.x;
    let north = v01 + (v11 - v01) * s.x;
    south + (north - south) * s.y
}

/// Fractal sum of `octaves` value noises, normalised to 0..1.
pub(super) fn fbm(p: DVec2, seed: u64, octaves: u32) -> f64 {
    let (mut sum, mut norm, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0);
    for o in 0..octaves {
        sum += amp * value_noise(p * freq, seed.wrapping_add(u64::from(o) * 0x1000_0001));
        norm += amp;
        amp *= 0.5;
        freq *= 2.03;
    }
    sum / norm
}
/// Refuses painted grass type indices beyond the types the manifest lists: the painter and
/// [`default_grass_types`] must agree, or the renderer would draw an unknown index as another
/// type.
pub(super) fn check_painted_types(
    painted: &Painted,
    manifest: &Manifest,
    manifest_path: &Path,
) -> Result<(), WorldError> {
    let count = manifest.grass_types.len();
    match painted
        .grass_type
        .iter()
        .position(|&t| usize::from(t) >= count)
    {
        None => Ok(()),
        Some(k) => Err(WorldError::BadTileData {
            path: manifest_path.to_path_buf(),
            message: format!(
                "grass type index {} painted at sample {k}, but the world has only {count} \
                 grass types",
                painted.grass_type[k]
            ),
        }),
    }
}
