//! Grass coverage: of the pixels where the terrain near the camera is the nearest surface in
//! the terrain-only depth, the fraction that a blade covers in the final depth.

use glam::{Mat4, Vec4};
use serde::{Deserialize, Serialize};

/// The distance limit of the coverage the tools report, metres.
pub const COVERAGE_DISTANCE_M: f32 = 30.0;

/// A pixel counts as covered when its final depth is greater (nearer, reverse-Z) than its
/// terrain-only depth by more than this share of the terrain-only depth: a surface at least
/// 0.01% of the distance in front of the terrain (3 mm at 30 m), far above the rounding of f32
/// depth and below any blade.
pub const COVERAGE_EPSILON: f32 = 1e-4;

/// Grass coverage of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Coverage {
    /// Covered pixels over pixels considered, in [0, 1]; 0 when none were considered.
    pub fraction: f64,
    /// Pixels considered: terrain in the terrain-only depth, within the distance limit.
    pub pixels: u64,
    /// Of those, pixels with something (a blade) nearer in the final depth.
    pub covered: u64,
}

/// The grass coverage of a `width` x `height` frame from its terrain-only depth (`terrain`) and
/// final depth (`final_depth`), both reverse-Z (1 at the near plane, 0 at infinity), rows top
/// first. `inv_view_proj` unprojects a pixel's clip-space position to the camera-relative
/// position it shows: the inverse of the camera-relative view-projection
/// ([`crate::camera::Camera::view_proj_relative`]), or of the projection alone (the view is a
/// rotation about the eye, which keeps distances). A pixel is considered when its terrain-only
/// depth is not the far plane (0) and the terrain it shows lies within `max_distance_m` of the
/// eye, the distance being the length of the view ray from the eye to that point (not its
/// view-space depth). It is covered when its final depth is nearer than the terrain-only depth
/// by more than [`COVERAGE_EPSILON`] of it.
pub fn grass_coverage(
    terrain: &[f32],
    final_depth: &[f32],
    width: u32,
    height: u32,
    inv_view_proj: Mat4,
    max_distance_m: f32,
) -> Coverage {
    let n = (width as usize) * (height as usize);
    assert!(
        terrain.len() >= n && final_depth.len() >= n,
        "depth buffers smaller than {width}x{height}"
    );
    let (mut pixels, mut covered) = (0u64, 0u64);
    for y in 0..height {
        let ndc_y = 1.0 - 2.0 * (y as f32 + 0.5) / height as f32;
        for x in 0..width {
            let i = (y * width + x) as usize;
            let t = terrain[i];
            if t <= 0.0 || !t.is_finite() {
                continue; // far plane: sky
            }
            let ndc_x = 2.0 * (x as f32 + 0.5) / width as f32 - 1.0;
            let p = inv_view_proj * Vec4::new(ndc_x, ndc_y, t, 1.0);
            if p.w.abs() <= f32::MIN_POSITIVE {
                continue;
            }
            let distance = (p.truncate() / p.w).length();
            if distance.is_nan() || distance > max_distance_m {
                continue;
            }
            pixels += 1;
            if final_depth[i] > t * (1.0 + COVERAGE_EPSILON) {
                covered += 1;
            }
        }
    }
    let fraction = if pixels == 0 {
        0.0
    } else {
        covered as f64 / pixels as f64
    };
    Coverage {
        fraction,
        pixels,
        covered,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::camera::rh::proj::directx::perspective_infinite_reverse;

    const W: u32 = 16;
    const H: u32 = 8;

    fn inv_proj() -> Mat4 {
        perspective_infinite_reverse(60f32.to_radians(), W as f32 / H as f32, 0.5).inverse()
    }

    /// Reverse-Z depth of a point at view-space depth `z_m` (near plane 0.5 m).
    fn depth_at(z_m: f32) -> f32 {
        0.5 / z_m
    }

    #[test]
    fn all_covered_and_none_covered() {
        let terrain = vec![depth_at(10.0); (W * H) as usize];
        let grass = vec![depth_at(9.5); (W * H) as usize];
        let all = grass_coverage(&terrain, &grass, W, H, inv_proj(), 30.0);
        assert_eq!(all.pixels, u64::from(W * H));
        assert_eq!((all.covered, all.fraction), (all.pixels, 1.0));
        let none = grass_coverage(&terrain, &terrain, W, H, inv_proj(), 30.0);
        assert_eq!(none.pixels, u64::from(W * H));
        assert_eq!((none.covered, none.fraction), (0, 0.0));
    }

    #[test]
    fn far_plane_pixels_are_not_considered() {
        let mut terrain = vec![depth_at(10.0); (W * H) as usize];
        let mut grass = vec![depth_at(9.0); (W * H) as usize];
        // The top half is sky; grass drawn in front of the sky does not count.
        for i in 0..(W * H / 2) as usize {
            terrain[i] = 0.0;
            grass[i] = 0.9;
        }
        // Half of the bottom half covered.
        let bottom = (W * H / 2) as usize..(W * H * 3 / 4) as usize;
        grass[bottom.clone()].copy_from_slice(&terrain[bottom]);
        let c = grass_coverage(&terrain, &grass, W, H, inv_proj(), 30.0);
        assert_eq!(c.pixels, u64::from(W * H / 2));
        assert_eq!(c.covered, u64::from(W * H / 4));
        assert!((c.fraction - 0.5).abs() < 1e-12);
        let sky = vec![0.0; (W * H) as usize];
        assert_eq!(
            grass_coverage(&sky, &grass, W, H, inv_proj(), 30.0),
            Coverage::default()
        );
    }

    #[test]
    fn terrain_beyond_the_limit_is_not_considered() {
        // Left half at 15 m view depth (under 24 m along any ray), right half at 40 m; only
        // the left half counts.
        let mut terrain = vec![0.0; (W * H) as usize];
        for y in 0..H {
            for x in 0..W {
                terrain[(y * W + x) as usize] = depth_at(if x < W / 2 { 15.0 } else { 40.0 });
            }
        }
        let none = grass_coverage(&terrain, &terrain, W, H, inv_proj(), 30.0);
        assert_eq!(none.pixels, u64::from(W * H / 2));
        let grass = vec![1.0; (W * H) as usize];
        let all = grass_coverage(&terrain, &grass, W, H, inv_proj(), 30.0);
        assert_eq!(
            (all.pixels, all.covered),
            (u64::from(W * H / 2), u64::from(W * H / 2))
        );
    }

    #[test]
    fn distance_is_along_the_view_ray() {
        // At 29 m view depth the corner pixels lie beyond 30 m along their rays (the half
        // field of view is 30 degrees vertically, more across), the centre ones within.
        let terrain = vec![depth_at(29.0); (W * H) as usize];
        let c = grass_coverage(&terrain, &terrain, W, H, inv_proj(), 30.0);
        assert!(c.pixels > 0 && c.pixels < u64::from(W * H), "{c:?}");
        let corner = grass_coverage(&terrain[..1], &terrain[..1], 1, 1, inv_proj(), 30.0);
        assert_eq!(corner.pixels, 1, "the centre of a 1x1 frame is on the axis");
    }
}
