//! Measurements: percentiles of timings, image error by FLIP (pixel by pixel, and the coarse
//! FLIP of [`coarse_flip`], which does not punish another random draw of the same grass), grass
//! coverage, where an error lies by scale ([`with_block_means_of`], [`with_block_spread_of`]),
//! and speed-against-accuracy charts.

mod band;
mod chart;
mod coarse;
mod coverage;
mod scale;

pub use band::{band_mask, masked_luminance, masked_mean, ray_distances};

pub use chart::{Chart, ChartError, ChartPoint, LineChart, Series, pareto_front, pareto_front_n};
pub use coarse::{
    COARSE_FACTOR, box_filter_linear, coarse_flip, decode_srgb8, encode_srgb8, linear_to_srgb,
    srgb_to_linear,
};
pub use coverage::{COVERAGE_DISTANCE_M, COVERAGE_EPSILON, Coverage, grass_coverage};
pub use scale::{with_block_means_of, with_block_spread_of};

use thiserror::Error;

/// The RGB channels of `img` (what the FLIP measures compare).
pub fn rgb(img: &image::RgbaImage) -> image::RgbImage {
    image::DynamicImage::ImageRgba8(img.clone()).to_rgb8()
}

/// The `q`-quantile (0..=1) of `values` by linear interpolation between order statistics.
/// `None` when there are no finite values.
pub fn percentile(values: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    Some(v[lo] + (v[hi] - v[lo]) * (pos - lo as f64))
}

/// Median, 99th percentile and mean of a series.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// 50th percentile.
    pub median: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Arithmetic mean.
    pub mean: f64,
    /// Largest value.
    pub max: f64,
}

impl Summary {
    /// Summarises `values`; all zero when empty.
    pub fn of(values: &[f64]) -> Self {
        if values.is_empty() {
            return Self::default();
        }
        Self {
            median: percentile(values, 0.5).unwrap_or(0.0),
            p99: percentile(values, 0.99).unwrap_or(0.0),
            mean: values.iter().sum::<f64>() / values.len() as f64,
            max: values.iter().copied().fold(f64::MIN, f64::max),
        }
    }
}

/// Why two images could not be compared.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ImageCompareError {
    /// The images differ in size.
    #[error("image sizes differ: reference {reference:?}, actual {actual:?}")]
    SizeMismatch {
        /// Width and height of the reference.
        reference: (u32, u32),
        /// Width and height of the actual image.
        actual: (u32, u32),
    },
}

/// Two images to compare must be of one size.
fn same_size(
    reference: &image::RgbImage,
    actual: &image::RgbImage,
) -> Result<(), ImageCompareError> {
    if reference.dimensions() == actual.dimensions() {
        Ok(())
    } else {
        Err(ImageCompareError::SizeMismatch {
            reference: reference.dimensions(),
            actual: actual.dimensions(),
        })
    }
}

/// The FLIP error of an image against its reference.
#[derive(Clone, Debug)]
pub struct FlipResult {
    /// Mean FLIP error over all pixels (0 = identical, 1 = as different as can be).
    pub mean: f32,
    /// 99th percentile of the per-pixel error.
    pub p99: f32,
    /// Largest per-pixel error.
    pub max: f32,
    /// The error map coloured with the magma map, RGB8, for a difference image.
    pub difference_rgb: Vec<u8>,
}

/// Compares two RGB8 images of the same size with NVIDIA's FLIP at the default viewing distance.
pub fn flip_compare(
    reference: &image::RgbImage,
    actual: &image::RgbImage,
) -> Result<FlipResult, ImageCompareError> {
    same_size(reference, actual)?;
    let (w, h) = reference.dimensions();
    let r = nv_flip::FlipImageRgb8::with_data(w, h, reference.as_raw());
    let a = nv_flip::FlipImageRgb8::with_data(w, h, actual.as_raw());
    let error = nv_flip::flip(r, a, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    let mut pool = nv_flip::FlipPool::from_image(&error);
    Ok(FlipResult {
        mean: pool.mean(),
        p99: pool.get_percentile(0.99, true),
        max: pool.max_value(),
        difference_rgb: error.apply_color_lut(&nv_flip::magma_lut()).to_vec(),
    })
}

/// The per-pixel FLIP error map of an image against its reference (0..=1, row-major, top row
/// first): what [`flip_compare`] pools into its mean, for means over part of the image (see
/// [`masked_mean`]).
pub fn flip_error_map(
    reference: &image::RgbImage,
    actual: &image::RgbImage,
) -> Result<Vec<f32>, ImageCompareError> {
    same_size(reference, actual)?;
    let (w, h) = reference.dimensions();
    let r = nv_flip::FlipImageRgb8::with_data(w, h, reference.as_raw());
    let a = nv_flip::FlipImageRgb8::with_data(w, h, actual.as_raw());
    Ok(nv_flip::flip(r, a, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_interpolate() {
        let v = [4.0, 1.0, 3.0, 2.0];
        assert_eq!(percentile(&v, 0.0), Some(1.0));
        assert_eq!(percentile(&v, 1.0), Some(4.0));
        assert_eq!(percentile(&v, 0.5), Some(2.5));
        assert_eq!(percentile(&[], 0.5), None);
        let s = Summary::of(&v);
        assert_eq!((s.median, s.mean, s.max), (2.5, 2.5, 4.0));
    }

    #[test]
    fn flip_sees_identical_and_different_images() {
        let a = image::RgbImage::from_fn(32, 32, |x, y| {
            image::Rgb([(x * 8) as u8, (y * 8) as u8, 90])
        });
        let same = flip_compare(&a, &a).unwrap();
        assert_eq!(same.mean, 0.0);
        let mut b = a.clone();
        for p in b.pixels_mut().take(300) {
            *p = image::Rgb([255, 255, 255]);
        }
        let diff = flip_compare(&a, &b).unwrap();
        assert!(diff.mean > 0.05, "mean {}", diff.mean);
        let small = image::RgbImage::new(8, 8);
        assert!(flip_compare(&a, &small).is_err());
        // The map pools to the same mean, and its mean over the changed pixels is larger.
        let map = flip_error_map(&a, &b).unwrap();
        assert_eq!(map.len(), 32 * 32);
        let all = map.iter().map(|&e| f64::from(e)).sum::<f64>() / map.len() as f64;
        assert!(
            (all - f64::from(diff.mean)).abs() < 1e-3,
            "{all} {}",
            diff.mean
        );
        let changed: Vec<bool> = (0..map.len()).map(|i| i < 300).collect();
        assert!(masked_mean(&map, &changed).unwrap() > all);
        assert!(flip_error_map(&a, &small).is_err());
    }
}
