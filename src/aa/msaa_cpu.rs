//! CPU mirror of the multisampling stage's rules ([`crate::aa::msaa`],
//! `shaders/aa_msaa.wgsl`, and the blades' coverage in `shaders/grass_draw.wgsl`).

use glam::{Mat4, Vec3};

/// A blade's coverage and the factor its width is drawn at, for a blade `width_m` wide at its
/// root `root` (camera-relative) under `view_proj` on a target `height` pixels tall: a blade
/// narrower than a pixel is drawn a pixel wide (factor 1 / its width in pixels) and covers
/// that share of the pixel; a wider one is drawn as it is, covering its pixels fully.
pub fn blade_coverage(width_m: f32, root: Vec3, view_proj: Mat4, height: f32) -> (f32, f32) {
    let w = (view_proj * root.extend(1.0)).w.max(1e-3);
    // The projection's vertical scale: the view-projection's second row, the view being a
    // rotation, has the length of the projection's own.
    let row = view_proj.row(1);
    let px_per_m = 0.5 * height * Vec3::new(row.x, row.y, row.z).length() / w;
    let px = width_m * px_per_m;
    if px < 1.0 {
        (px.max(0.0), 1.0 / px.max(1e-3))
    } else {
        (1.0, 1.0)
    }
}

/// The resolved depth of a pixel: its nearest sample (reverse-Z: the largest).
pub fn resolve_depth(samples: &[f32]) -> f32 {
    samples.iter().copied().fold(0.0, f32::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use glam::DVec3;

    #[test]
    fn a_blade_keeps_its_width_up_close_and_covers_its_share_of_a_pixel_far_away() {
        let camera = Camera::new(DVec3::ZERO, 0.0, 0.0);
        let (h, fov) = (1080.0f32, 60.0f32);
        let vp = camera.view_proj_relative(16.0 / 9.0);
        // At distance d a pixel is 2 d tan(fov / 2) / h metres tall.
        let pixel_at = |d: f32| 2.0 * d * (fov.to_radians() / 2.0).tan() / h;
        let width = 0.006;
        let near = blade_coverage(width, Vec3::new(2.0, 0.0, 0.0), vp, h);
        assert_eq!(near, (1.0, 1.0));
        let d = 40.0;
        let (cov, widen) = blade_coverage(width, Vec3::new(d, 3.0, -1.0), vp, h);
        let expected = width / pixel_at(d);
        assert!(
            (cov - expected).abs() < 0.01 * expected,
            "{cov} vs {expected}"
        );
        // Drawn a pixel wide.
        assert!((width * widen - pixel_at(d)).abs() < 0.01 * pixel_at(d));
    }

    #[test]
    fn the_resolved_depth_is_the_nearest_sample() {
        assert_eq!(resolve_depth(&[0.1, 0.4, 0.0, 0.2]), 0.4);
        assert_eq!(resolve_depth(&[0.0; 4]), 0.0);
    }
}
