//! Means over a band of distances: which pixels show a surface between two distances from the
//! camera, and the mean of a per-pixel error over them.

use glam::{Mat4, Vec4};

/// Distance from the eye, along the view ray, of the surface each pixel of a `width` x
/// `height` reverse-Z depth buffer (1 at the near plane, 0 at infinity, rows top first)
/// shows; infinite where the depth is the far plane (sky). `inv_view_proj` unprojects a
/// pixel's clip-space position to the camera-relative position it shows (the inverse of
/// [`crate::camera::Camera::view_proj_relative`]), as in [`super::grass_coverage`].
pub fn ray_distances(depth: &[f32], width: u32, height: u32, inv_view_proj: Mat4) -> Vec<f32> {
    let n = (width as usize) * (height as usize);
    assert!(
        depth.len() >= n,
        "depth buffer smaller than {width}x{height}"
    );
    let mut out = Vec::with_capacity(n);
    for y in 0..height {
        let ndc_y = 1.0 - 2.0 * (y as f32 + 0.5) / height as f32;
        for x in 0..width {
            let d = depth[(y * width + x) as usize];
            if d <= 0.0 || !d.is_finite() {
                out.push(f32::INFINITY);
                continue;
            }
            let ndc_x = 2.0 * (x as f32 + 0.5) / width as f32 - 1.0;
            let p = inv_view_proj * Vec4::new(ndc_x, ndc_y, d, 1.0);
            let distance = if p.w.abs() <= f32::MIN_POSITIVE {
                f32::INFINITY
            } else {
                (p.truncate() / p.w).length()
            };
            out.push(if distance.is_nan() {
                f32::INFINITY
            } else {
                distance
            });
        }
    }
    out
}

/// The pixels whose distance (see [`ray_distances`]) lies in `[near_m, far_m]`.
pub fn band_mask(distances: &[f32], near_m: f32, far_m: f32) -> Vec<bool> {
    distances
        .iter()
        .map(|&d| d >= near_m && d <= far_m)
        .collect()
}

/// Mean of `values` over the pixels `mask` selects; `None` when it selects none.
pub fn masked_mean(values: &[f32], mask: &[bool]) -> Option<f64> {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (&v, &m) in values.iter().zip(mask) {
        if m {
            sum += f64::from(v);
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as f64)
}

/// Mean linear luminance (Rec. 709 weights) of the sRGB8 `image` over the pixels `mask`
/// selects (row-major, one per pixel); `None` when it selects none.
pub fn masked_luminance(image: &image::RgbaImage, mask: &[bool]) -> Option<f64> {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (p, &m) in image.pixels().zip(mask) {
        if m {
            let l = |c: u8| f64::from(super::decode_srgb8(c));
            sum += 0.2126 * l(p[0]) + 0.7152 * l(p[1]) + 0.0722 * l(p[2]);
            n += 1;
        }
    }
    (n > 0).then(|| sum / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn luminance_is_linear_and_counts_only_the_masked_pixels() {
        let mut img = image::RgbaImage::new(2, 1);
        img.put_pixel(0, 0, image::Rgba([255, 255, 255, 255]));
        // sRGB 188 is about 0.5 in linear light.
        img.put_pixel(1, 0, image::Rgba([188, 188, 188, 255]));
        let white = masked_luminance(&img, &[true, false]).unwrap();
        assert!((white - 1.0).abs() < 1e-6, "{white}");
        let grey = masked_luminance(&img, &[false, true]).unwrap();
        assert!((grey - 0.5).abs() < 0.01, "{grey}");
        let both = masked_luminance(&img, &[true, true]).unwrap();
        assert!((both - 0.5 * (white + grey)).abs() < 1e-9);
        assert_eq!(masked_luminance(&img, &[false, false]), None);
    }

    #[test]
    fn distances_follow_the_ray_and_the_band_selects_them() {
        // Reverse-Z, infinite far plane: depth = near / view depth on the axis.
        let proj = glam::camera::rh::proj::directx::perspective_infinite_reverse(1.0, 1.0, 0.5);
        let inv = proj.inverse();
        // The centre pixel of a 1x1 buffer looks straight down the axis.
        let d = ray_distances(&[0.5 / 40.0], 1, 1, inv);
        assert!((d[0] - 40.0).abs() < 1e-2, "{d:?}");
        let sky = ray_distances(&[0.0], 1, 1, inv);
        assert!(sky[0].is_infinite());
        // Off axis the distance along the ray is longer than the view depth.
        let d = ray_distances(&[0.5 / 40.0; 4], 2, 2, inv);
        assert!(d.iter().all(|&x| x > 40.0), "{d:?}");
        let mask = band_mask(&[10.0, 50.0, 200.0, f32::INFINITY], 40.0, 160.0);
        assert_eq!(mask, vec![false, true, false, false]);
        assert_eq!(masked_mean(&[1.0, 0.25, 1.0, 1.0], &mask), Some(0.25));
        assert_eq!(masked_mean(&[1.0], &[false]), None);
    }
}
