//! CPU mirror of the far field (`shaders/shared/terrain_shading.wgsl`): the terrain under grass
//! is shaded with what the blades would show there, in the way Ghost of Tsushima carries its
//! grass to the horizon: the grass type's blade colour at a representative height along the
//! blade, the Voronoi clump's tint (faded out where its cells shrink below a few pixels) and
//! the colour variation that the blades get, lit as a far blade is lit (its normal turned to
//! its growth direction), over the ground in proportion to what the grass hides from that
//! view. It lies under the blades drawn as beyond them, so that nothing new shows where the
//! blades thin out before the view distance; seen from above, where blades are specks, the
//! blades thin out sooner ([`far_distance`]).

use glam::{DVec2, Vec2, Vec3};

use crate::hash::{hash_u32, hash3, rand01};

/// The position along a blade (0 root, 1 tip) whose colour the far field shows: seen at a
/// grazing angle a field shows mostly the upper part of its blades.
pub const FAR_T: f32 = 0.4;

/// How much a blade's growth direction leans from the vertical toward the terrain's normal,
/// by its grass type's stiffness (as generation sets it).
pub fn growth_blend(stiffness: f32) -> f32 {
    0.2 + 0.5 * (1.0 - stiffness.clamp(0.0, 1.0))
}

/// Optical depth of the grass layer straight down at full density (see [`cover`]).
pub const COVER_TAU: f32 = 0.25;

/// How much of the ground the far field's grass of density `d` (0..1) hides, seen at an
/// elevation whose sine is `sin_e`: blades stand up, so a grazing view sees only grass and a
/// view from above sees the ground between them (Beer-Lambert through the grass layer).
pub fn cover(d: f32, sin_e: f32) -> f32 {
    1.0 - (-COVER_TAU * d / sin_e.max(0.02)).exp()
}

/// Metres of distance toward the grass's view-distance fade per metre the camera stands above
/// a blade: seen from above, far blades are sub-pixel specks that the far field shows better,
/// so from 50 m up none are drawn.
pub const ELEVATION_DISTANCE: f32 = 3.0;

/// The distance that the grass's fade at the view distance goes by, for a point `dist`
/// metres from the camera and `below_m` metres below it: `dist` plus [`ELEVATION_DISTANCE`]
/// times `below_m`.
pub fn far_distance(dist: f32, below_m: f32) -> f32 {
    dist + ELEVATION_DISTANCE * below_m.max(0.0)
}

/// How much of the clump tint shows at `dist` metres from the camera, for clump cells of
/// `clump_m`: all of it while a cell spans at least two pixel footprints (0.004 of the
/// distance), none once it spans one, so that far clumps do not sparkle. The tint fades toward
/// its mean (1).
pub fn clump_visibility(dist: f32, clump_m: f32) -> f32 {
    (clump_m / (0.004 * dist + 1e-3) - 1.0).clamp(0.0, 1.0)
}

/// The tint (mean 1) of the Voronoi clump around `world` (metres), with clump cells of
/// `clump_m` and the grass `seed`: the clump whose jittered centre is nearest, among the 3x3
/// cells around, as generation picks each blade's clump.
pub fn clump_tint(world: DVec2, clump_m: f32, seed: u32) -> Vec3 {
    let c = (world / f64::from(clump_m)).floor();
    let (cx, cy) = (c.x as i32, c.y as i32);
    let local = (world - c * f64::from(clump_m)).as_vec2();
    let mut best = f32::MAX;
    let mut clump = 0u32;
    for dy in -1..=1 {
        for dx in -1..=1 {
            let (kx, ky) = (cx + dx, cy + dy);
            let ch = hash3(kx as u32, ky as u32, seed ^ 0x00c1_0b55);
            let jitter = Vec2::new(rand01(ch), rand01(hash_u32(ch ^ 1))) - 0.5;
            let centre =
                (Vec2::new(dx as f32, dy as f32) + Vec2::splat(0.5) + 0.8 * jitter) * clump_m;
            let d2 = (centre - local).length_squared();
            if d2 < best {
                best = d2;
                clump = ch;
            }
        }
    }
    Vec3::new(
        0.85 + 0.3 * rand01(hash_u32(clump ^ 4)),
        0.85 + 0.3 * rand01(hash_u32(clump ^ 5)),
        0.85 + 0.3 * rand01(hash_u32(clump ^ 6)),
    )
}

/// The blades' colour variation at `world_mod` (the world position modulo 4096 m, as the wind
/// pass applies it to each blade's root).
pub fn color_variation(world_mod: Vec2) -> Vec3 {
    let v = crate::hash::value_noise(world_mod / 6.0) * 0.6
        + crate::hash::value_noise(world_mod / 1.7) * 0.4;
    let (lo, hi) = (Vec3::new(0.78, 0.86, 0.7), Vec3::new(1.15, 1.1, 0.95));
    lo + (hi - lo) * v
}

/// The blades' shade on each other, as the far field dims its light (fitted so that the far
/// field where the blades end matches their mean colour; see `tests/far_field.rs`).
pub const CANOPY_SHADE: f32 = 0.75;

/// The blades' specular highlights on average, as a fraction of the sun on the far field
/// (fitted as [`CANOPY_SHADE`] is).
pub const SHEEN: f32 = 0.005;

/// The sun and sky that light the far field.
#[derive(Clone, Copy, Debug)]
pub struct Light {
    /// Unit vector toward the sun.
    pub sun_dir: Vec3,
    /// Linear colour of the sun.
    pub sun_color: Vec3,
    /// Linear colour of the sky.
    pub sky_color: Vec3,
    /// Whether blades get ambient occlusion from root to tip.
    pub ambient_occlusion: bool,
    /// Whether blades let the sun through to their back.
    pub translucency: bool,
    /// Whether blades have specular highlights.
    pub specular: bool,
}

/// A far blade's colour `albedo` at position `t` along it, its normal turned to its growth
/// direction `n`, lit by `light` with the fraction `sun_vis` of the sun seen: the mean of the
/// blade's front, lit by the sun, and its back, lit through the blade (a quarter of the sun,
/// tinted as the blade shader tints it) when translucency is on, with the blade's ambient
/// occlusion at `t` and its sky light averaged over both sides, dimmed by [`CANOPY_SHADE`],
/// plus [`SHEEN`] of the sun for the blades' highlights when specular is on.
pub fn light_far_grass(albedo: Vec3, n: Vec3, t: f32, sun_vis: f32, light: &Light) -> Vec3 {
    let diffuse = n.dot(light.sun_dir).max(0.0) * sun_vis;
    let through = if light.translucency {
        Vec3::new(0.9, 1.0, 0.55) * 0.25
    } else {
        Vec3::ZERO
    };
    let ao = if light.ambient_occlusion {
        0.3 + 0.7 * t
    } else {
        1.0
    };
    let sun = light.sun_color * diffuse * 0.5 * (Vec3::ONE + through);
    let ambient = light.sky_color * 0.35 * ao;
    let sheen = if light.specular { SHEEN * diffuse } else { 0.0 };
    albedo * (sun * (0.6 + 0.4 * ao) + ambient) * CANOPY_SHADE + light.sun_color * sheen
}

/// The share of the ground shaded by the trees' canopy of depth `tau` (per grass type at full
/// density, [`crate::plants::shadow::canopy_depth`]) over grass of density `d` (0..1): trees
/// stand in proportion to the density, their shadows overlapping at random.
pub fn tree_canopy_shade(tau: f32, d: f32) -> f32 {
    1.0 - (-tau * d).exp()
}

/// How much of the canopy's shade a point at `dist` metres gets: none within the trees' shadow
/// map, all beyond its fade-out `[start, end]`, linear between.
pub fn tree_canopy_fade_in(dist: f32, [start, end]: [f32; 2]) -> f32 {
    ((dist - start) / (end - start).max(1e-3)).clamp(0.0, 1.0)
}

/// The growth direction of a blade of `growth_blend` on terrain of normal `n`.
pub fn growth_direction(n: Vec3, growth_blend: f32) -> Vec3 {
    (Vec3::Z + (n - Vec3::Z) * growth_blend).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grass_hides_the_ground_seen_at_a_grazing_angle_and_shows_it_from_above() {
        assert!(cover(1.0, 0.03) > 0.99);
        assert!((cover(1.0, 1.0) - 0.221).abs() < 0.01);
        assert_eq!(cover(0.0, 0.03), 0.0);
        assert!(cover(0.5, 0.2) < cover(1.0, 0.2));
    }

    #[test]
    fn the_grass_fade_goes_by_distance_plus_the_height_below_the_camera() {
        assert_eq!(far_distance(100.0, 0.0), 100.0);
        assert_eq!(far_distance(100.0, 10.0), 100.0 + 10.0 * ELEVATION_DISTANCE);
        // A point above the camera is not nearer than it is.
        assert_eq!(far_distance(100.0, -10.0), 100.0);
    }

    #[test]
    fn clump_tints_average_one_and_are_constant_inside_a_clump() {
        let mut sum = Vec3::ZERO;
        let n = 4000;
        for i in 0..n {
            let p = DVec2::new(f64::from(i) * 0.77 + 3.0, f64::from(i % 61) * 1.3 + 5000.0);
            sum += clump_tint(p, 1.6, 0x9a55);
        }
        let mean = sum / n as f32;
        assert!((mean - Vec3::ONE).abs().max_element() < 0.02, "{mean}");
        // Two points a millimetre apart lie in the same clump (almost always).
        let p = DVec2::new(12345.678, 2345.6);
        assert_eq!(clump_tint(p, 1.6, 7), clump_tint(p + 0.001, 1.6, 7));
    }
}
