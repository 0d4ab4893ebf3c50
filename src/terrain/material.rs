//! CPU mirror of the terrain materials' shading (`shaders/shared/terrain_shading.wgsl`): the
//! albedo of each [`Material`] (crops' furrows faded out as they shrink toward a pixel), the
//! water's colour (the sky mirrored by Schlick's Fresnel term over a dark body), the sky and the
//! fog. `tests/land_cover.rs` renders water and ground of known materials on software Vulkan and
//! compares the pixels with these.

use glam::{Vec2, Vec3};

use crate::world::Material;

/// Bare soil (also the ground under thin grass).
pub const SOIL: Vec3 = Vec3::new(0.33, 0.27, 0.19);
/// Bare rock.
pub const ROCK: Vec3 = Vec3::new(0.25, 0.23, 0.20);
/// Tilled soil of crops, between the furrows' light and dark.
pub const CROP_SOIL: Vec3 = Vec3::new(0.30, 0.23, 0.15);
/// Sand.
pub const SAND: Vec3 = Vec3::new(0.55, 0.47, 0.33);
/// A paved road.
pub const ROAD: Vec3 = Vec3::new(0.11, 0.11, 0.115);
/// Snow.
pub const SNOW: Vec3 = Vec3::new(0.82, 0.86, 0.92);
/// The bed seen through water, and how much of the light it sends back up.
pub const WATER_BODY: Vec3 = Vec3::new(0.015, 0.035, 0.04);
/// Furrow spacing of crops, metres (rows run north-south).
pub const CROP_ROW_M: f32 = 1.2;
/// Reflectance of water seen head-on (Schlick's F0).
pub const WATER_F0: f32 = 0.02;

/// The sky and sun that light the terrain (the manifest's, linear).
#[derive(Clone, Copy, Debug)]
pub struct SkyLight {
    /// Unit vector toward the sun.
    pub sun_dir: Vec3,
    /// Colour of the sun.
    pub sun_color: Vec3,
    /// Colour of the sky at the zenith.
    pub sky_color: Vec3,
    /// Colour of the sky at the horizon (and of the fog).
    pub horizon_color: Vec3,
    /// Distance of 95% fog, metres.
    pub fog_distance_m: f32,
}

impl SkyLight {
    /// The light of a manifest's sky.
    pub fn of(sky: &crate::world::Sky) -> SkyLight {
        SkyLight {
            sun_dir: super::sun_direction(sky),
            sun_color: Vec3::from_array(sky.sun_color),
            sky_color: Vec3::from_array(sky.sky_color),
            horizon_color: Vec3::from_array(sky.horizon_color),
            fog_distance_m: sky.fog_distance_m,
        }
    }

    /// The fog's colour seen along the unit direction `dir`: the horizon's, warmed toward the
    /// sun.
    pub fn fog_color(&self, dir: Vec3) -> Vec3 {
        let sun_amount = dir.dot(self.sun_dir).max(0.0).powf(8.0);
        self.horizon_color.lerp(self.sun_color, 0.35 * sun_amount)
    }

    /// The sky's colour along the unit direction `dir`, the sun's disc included.
    pub fn sky(&self, dir: Vec3) -> Vec3 {
        let up = dir.z.clamp(0.0, 1.0);
        let sun = dir.dot(self.sun_dir);
        self.fog_color(dir).lerp(self.sky_color, up.powf(0.6))
            + self.sun_color * smoothstep(0.9995, 0.9999, sun)
    }

    /// `color` seen `dist` metres away along `dir` through the fog (95% at the fog distance).
    pub fn fogged(&self, color: Vec3, dir: Vec3, dist: f32) -> Vec3 {
        let x = dist / self.fog_distance_m;
        color.lerp(self.fog_color(dir), 1.0 - (-3.0 * x * x).exp())
    }
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The albedo of `material` (not water, whose colour is [`water_color`]) at world position
/// `world` (metres) for a pixel footprint of `ground_footprint` metres along the ground:
/// crops' furrows, a cosine across x of [`CROP_ROW_M`], fade out as they shrink below two
/// pixels. The default material has no albedo of its own (the grass type's ground): soil.
pub fn albedo(material: Material, world: Vec2, ground_footprint: f32) -> Vec3 {
    match material {
        Material::Default | Material::Soil | Material::Water => SOIL,
        Material::Crops => {
            let vis = (CROP_ROW_M / (2.0 * ground_footprint) - 1.0).clamp(0.0, 1.0);
            let row = 0.5 + 0.5 * (std::f32::consts::TAU * world.x / CROP_ROW_M).cos();
            CROP_SOIL * (1.0 + 0.35 * vis * (row - 0.5))
        }
        Material::Rock => ROCK,
        Material::Sand => SAND,
        Material::Road => ROAD,
        Material::Snow => SNOW,
    }
}

/// Water seen along the unit direction `v` (from the camera): a flat surface that mirrors the
/// sky by Schlick's Fresnel term ([`WATER_F0`] head-on) over a dark body lit by the fraction
/// `sun_vis` of the sun and by the sky's dome; before the fog.
pub fn water_color(v: Vec3, sun_vis: f32, light: &SkyLight) -> Vec3 {
    let cos_v = (-v.z).clamp(0.0, 1.0);
    let fresnel = WATER_F0 + (1.0 - WATER_F0) * (1.0 - cos_v).powi(5);
    let mirrored = Vec3::new(v.x, v.y, v.z.abs());
    let dome = light.sky_color.lerp(light.horizon_color, 0.5);
    let body = WATER_BODY * (light.sun_color * light.sun_dir.z.max(0.0) * sun_vis + 0.45 * dome);
    body.lerp(light.sky(mirrored), fresnel)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn light() -> SkyLight {
        SkyLight::of(&crate::world::Sky::default())
    }

    #[test]
    fn water_is_dark_from_above_and_mirrors_the_sky_at_a_grazing_angle() {
        let l = light();
        let down = water_color(-Vec3::Z, 1.0, &l);
        assert!(down.max_element() < 0.1, "{down}");
        let grazing = Vec3::new(1.0, 0.0, -0.02).normalize();
        let c = water_color(grazing, 1.0, &l);
        let sky = l.sky(Vec3::new(grazing.x, grazing.y, 0.02));
        assert!((c - sky).length() < 0.15 * sky.length(), "{c} vs {sky}");
        // Shade darkens only the body.
        assert!(water_color(-Vec3::Z, 0.0, &l).length() < down.length());
    }

    #[test]
    fn crop_furrows_fade_out_before_they_alias() {
        let near = |x: f32| albedo(Material::Crops, Vec2::new(x, 0.0), 0.05);
        assert!(near(0.0).x > near(0.5 * CROP_ROW_M).x);
        let far = |x: f32| albedo(Material::Crops, Vec2::new(x, 0.0), CROP_ROW_M);
        assert_eq!(far(0.0), far(0.5 * CROP_ROW_M));
    }
}
