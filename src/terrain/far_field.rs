//! CPU mirror of the far field (`shaders/shared/terrain_shading.wgsl`): the terrain under grass
//! is shaded with what the blades would show there, in the way Ghost of Tsushima carries its
//! grass to the horizon: the grass type's blade colour over the part of its blades that the
//! view sees (their tips at grazing angles, whole blades and the ground between them from
//! above, by the blades' size and density: [`optical_depth`]), the Voronoi clump's tint
//! (faded out where its cells shrink below a few pixels) and the colour variation that the
//! blades get, lit as a far blade is lit (its normal turned to its growth direction), over the
//! ground in proportion to what the grass hides from that view. By default it lies under the
//! blades drawn as beyond them, so that nothing new shows where the blades thin out before the
//! view distance; a renderer can keep the ground bare between its blades instead (the truth
//! does: [`under_blades_fade_in`]). Seen from above, where blades are specks, the blades thin
//! out sooner ([`far_distance`]).

use glam::{DVec2, Vec2, Vec3};

use crate::hash::{hash_u32, hash3, rand01};

/// How much a blade's growth direction leans from the vertical toward the terrain's normal,
/// by its grass type's stiffness (as generation sets it).
pub fn growth_blend(stiffness: f32) -> f32 {
    0.2 + 0.5 * (1.0 - stiffness.clamp(0.0, 1.0))
}

/// The mean projection of a blade's area onto a plane across the view, per unit of its area
/// (Ross's G-function: 0.5 for leaves facing every way): the far field's one fitted constant,
/// found by measuring the truth's far blades on flat fields of each grass type of the default
/// world seen from 1.7 to 80 m up (`examples/far_field_fit.rs`; 0.55 fits all three types
/// within about 5% of luminance).
pub const BLADE_PROJECTION: f32 = 0.55;

/// The blade area index of a grass type at full density: one side of its blades (triangles
/// of its mean width, times `width_scale`, and mean height) per square metre of ground, with a
/// blade every `spacing_m` each way.
pub fn blade_area_index(
    width_m: [f32; 2],
    height_m: [f32; 2],
    width_scale: f32,
    spacing_m: f32,
) -> f32 {
    let w = 0.5 * (width_m[0] + width_m[1]) * width_scale;
    let h = 0.5 * (height_m[0] + height_m[1]);
    0.5 * w * h / (spacing_m * spacing_m).max(1e-6)
}

/// The optical depth of the grass layer along a view whose angle to the ground has the sine
/// `sin_e`, for grass of blade area index `area` at density `d` (0..1): the blades a ray meets
/// on its way from the blades' tips down to the ground.
pub fn optical_depth(area: f32, d: f32, sin_e: f32) -> f32 {
    BLADE_PROJECTION * area * d / sin_e.max(1e-3)
}

/// How much of the ground the grass hides along a view of optical depth `depth` (from
/// [`optical_depth`]): blades stand up, so a grazing view sees only grass and a view from
/// above sees the ground between them (Beer-Lambert through the grass layer).
pub fn cover(depth: f32) -> f32 {
    1.0 - (-depth).exp()
}

/// The error function, to 1.5e-7 (Abramowitz and Stegun 7.1.26).
fn erf(x: f32) -> f32 {
    let s = x.signum();
    let x = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_6
            + t * (-0.284_496_74 + t * (1.421_413_7 + t * (-1.453_152_1 + t * 1.061_405_4))));
    s * (1.0 - poly * (-x * x).exp())
}

/// The mean position along the blades of what a view of optical depth `depth` sees of them,
/// and its mean square (x: `E[t]`, y: `E[t^2]`; 0 root, 1 tip). A blade is a triangle narrowing to
/// its tip, so the blades above the height of position t hide it in proportion to (1 - t)^2:
/// the part seen at 1 - t = s is weighted by s exp(-depth s^2), the blade's width there times
/// the chance of seeing it. Grazing views see the tips; views from above see the blades whole
/// (`E[t]` 1/3, the triangle's own mean).
pub fn visible_moments(depth: f32) -> Vec2 {
    let u = depth.clamp(0.05, 60.0);
    let e = (-u).exp();
    let r = u.sqrt();
    // E[s] and E[s^2] of the density s exp(-u s^2) on 0..1.
    let s1 = (std::f32::consts::PI.sqrt() * erf(r) / (2.0 * r) - e) / (1.0 - e);
    let s2 = 1.0 / u - e / (1.0 - e);
    Vec2::new(1.0 - s1, 1.0 - 2.0 * s1 + s2)
}

/// What the far field's grass of a type shows at a view of optical depth `depth`, before its
/// light: the mean of the blade's colour from `base` (root) to `tip` over the part seen (`[0]`),
/// and the mean of that colour times the position along the blade (`[1]`), which the blades'
/// light needs, since their ambient occlusion rises from root to tip.
pub fn visible_albedo(base: Vec3, tip: Vec3, depth: f32) -> [Vec3; 2] {
    let m = visible_moments(depth);
    [base + (tip - base) * m.x, base * m.x + (tip - base) * m.y]
}

/// Metres of distance toward the grass's view-distance fade per metre the camera stands above
/// a blade, by default (`GrassConfig::elevation_fade`): seen from above, far blades are
/// sub-pixel specks that the far field shows better, so from half the view distance up (33 m
/// by default) none are drawn. It was 3 (none from a quarter of it up) until `bench aa` along
/// the paths found 1 nearer the truth from the helicopter's height and as near elsewhere
/// (docs/anti-aliasing.md, "The far fade's elevation term").
pub const ELEVATION_DISTANCE: f32 = 1.0;

/// The distance that the grass's fade at the view distance goes by, for a point `dist`
/// metres from the camera and `below_m` metres below it: `dist` plus `elevation` (metres per
/// metre, [`ELEVATION_DISTANCE`] by default) times `below_m`.
pub fn far_distance(dist: f32, below_m: f32, elevation: f32) -> f32 {
    dist + elevation * below_m.max(0.0)
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

/// The blades' specular highlights on average, as a fraction of the sun on the far field.
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

impl Light {
    /// The sun and sky of `sky`, every lighting feature of the blades on.
    pub fn of_sky(sky: &crate::world::Sky) -> Self {
        Self {
            sun_dir: crate::terrain::sun_direction(sky),
            sun_color: Vec3::from_array(sky.sun_color),
            sky_color: Vec3::from_array(sky.sky_color),
            ambient_occlusion: true,
            translucency: true,
            specular: true,
        }
    }
}

/// Far blades of the colours `albedo` (from [`visible_albedo`], times any tint) with their
/// normals turned to their growth direction `n`, lit by `light` with the fraction `sun_vis` of
/// the sun seen, as `shaders/grass_draw.wgsl` lights a blade at position t: the mean of the
/// blade's front, lit by the sun, and its back, lit through the blade (a quarter of the sun,
/// tinted as the blade shader tints it) when translucency is on, with the blade's ambient
/// occlusion (0.3 at the root to 1 at the tip) and its sky light averaged over both sides,
/// plus [`SHEEN`] of the sun for the blades' highlights when specular is on.
pub fn light_far_grass(albedo: [Vec3; 2], n: Vec3, sun_vis: f32, light: &Light) -> Vec3 {
    let diffuse = n.dot(light.sun_dir).max(0.0) * sun_vis;
    let through = if light.translucency {
        Vec3::new(0.9, 1.0, 0.55) * 0.25
    } else {
        Vec3::ZERO
    };
    let sun = light.sun_color * diffuse * 0.5 * (Vec3::ONE + through);
    let ambient = light.sky_color * 0.35;
    // The light at t, sun (0.6 + 0.4 ao) + ambient ao with ao = 0.3 + 0.7 t, is a flat part
    // and a part rising with t, which the albedo's moments turn into the mean over the blades.
    let (flat, rising) = if light.ambient_occlusion {
        (sun * 0.72 + ambient * 0.3, sun * 0.28 + ambient * 0.7)
    } else {
        (sun + ambient, Vec3::ZERO)
    };
    let sheen = if light.specular { SHEEN * diffuse } else { 0.0 };
    albedo[0] * flat + albedo[1] * rising + light.sun_color * sheen
}

/// How much of the far field a point shows under blades drawn by a renderer that keeps the
/// ground bare between its blades (the truth): none before the blades' fade to the view
/// distance `[start, end]`, all past it, linear between, by the fade's own distance
/// ([`far_distance`]).
pub fn under_blades_fade_in(far_dist: f32, [start, end]: [f32; 2]) -> f32 {
    ((far_dist - start) / (end - start).max(1e-3)).clamp(0.0, 1.0)
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
        let meadow = blade_area_index([0.04, 0.07], [0.15, 0.35], 1.0, 0.25);
        assert!((meadow - 0.11).abs() < 1e-6, "{meadow}");
        assert!(cover(optical_depth(meadow, 1.0, 0.005)) > 0.99);
        assert!((cover(optical_depth(meadow, 1.0, 1.0)) - 0.0587).abs() < 1e-3);
        assert_eq!(cover(optical_depth(meadow, 0.0, 0.005)), 0.0);
        assert!(optical_depth(meadow, 0.5, 0.2) < optical_depth(meadow, 1.0, 0.2));
    }

    #[test]
    fn the_visible_part_of_the_blades_rises_to_their_tips_at_grazing_views() {
        // Seen from straight above a sparse field: the whole triangle, E[t] = 1/3, E[t^2] = 1/6.
        let whole = visible_moments(0.0);
        assert!((whole.x - 1.0 / 3.0).abs() < 0.01, "{whole}");
        assert!((whole.y - 1.0 / 6.0).abs() < 0.01, "{whole}");
        // Against a numerical integral of s exp(-u s^2) at a few depths.
        for u in [0.3f32, 2.0, 9.0, 40.0] {
            let (mut w, mut m1, mut m2) = (0.0f64, 0.0f64, 0.0f64);
            let n = 20_000;
            for i in 0..n {
                let s = (f64::from(i) + 0.5) / f64::from(n);
                let p = s * (-f64::from(u) * s * s).exp();
                w += p;
                m1 += p * (1.0 - s);
                m2 += p * (1.0 - s) * (1.0 - s);
            }
            let m = visible_moments(u);
            assert!(
                (f64::from(m.x) - m1 / w).abs() < 1e-3,
                "u {u}: {m} vs {}",
                m1 / w
            );
            assert!(
                (f64::from(m.y) - m2 / w).abs() < 1e-3,
                "u {u}: {m} vs {}",
                m2 / w
            );
        }
        // Deeper views see higher up the blades.
        assert!(visible_moments(40.0).x > visible_moments(9.0).x);
        assert!(visible_moments(40.0).x > 0.85);
    }

    #[test]
    fn the_grass_fade_goes_by_distance_plus_the_height_below_the_camera() {
        assert_eq!(far_distance(100.0, 0.0, ELEVATION_DISTANCE), 100.0);
        assert_eq!(
            far_distance(100.0, 10.0, ELEVATION_DISTANCE),
            100.0 + 10.0 * ELEVATION_DISTANCE
        );
        assert_eq!(far_distance(100.0, 10.0, 3.0), 130.0);
        assert_eq!(far_distance(100.0, 10.0, 0.0), 100.0);
        // A point above the camera is not nearer than it is.
        assert_eq!(far_distance(100.0, -10.0, 3.0), 100.0);
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
