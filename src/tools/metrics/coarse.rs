//! Linear light and the coarse FLIP: image error at the scale where single grass blades are no
//! longer resolved.
//!
//! Pixel FLIP compares two images pixel by pixel. Two renders of the same meadow whose blades
//! stand in different places (another blade spacing or width draws another random field of the
//! same grass) differ at almost every blade edge, so pixel FLIP punishes a different draw of the
//! same statistics as much as a wrong colour. The **coarse FLIP** does not: both images are
//! box-filtered by [`COARSE_FACTOR`] in each direction in linear light (each block of
//! `COARSE_FACTOR` x `COARSE_FACTOR` pixels becomes its mean colour, edge blocks the mean of the
//! pixels they have), then compared by FLIP at its default viewing distance: the frame seen at an
//! eighth of its size, where single blades are no longer resolved. (Seen at the large image's
//! size instead, the blocks' residual noise would sit at the eye's most sensitive frequencies.)
//! What remains is the grass's colour, cover and shading averaged over a few blades: another
//! draw of the same grass scores low (a field of half green, half ground pixels drawn with
//! another seed: 0.09 against 0.34 by pixel FLIP), a shift of colour or of cover scores as high
//! as in pixel FLIP (0.52 on both for the same field in another green).

use super::ImageCompareError;

/// Pixels a side of the blocks the coarse FLIP averages (8: at the benchmarks' sizes a block
/// holds several blades of the near meadow).
pub const COARSE_FACTOR: u32 = 8;

/// The sRGB transfer function's inverse for each 8-bit code: linear light in 0..=1.
fn decode_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

/// sRGB-encoded `v` (0..=1) to linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light `v` (clamped to 0..=1) to sRGB-encoded 0..=1.
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The 8-bit sRGB code `c` in linear light.
pub fn decode_srgb8(c: u8) -> f32 {
    decode_table()[usize::from(c)]
}

/// Linear light `v` as the nearest 8-bit sRGB code.
pub fn encode_srgb8(v: f32) -> u8 {
    (linear_to_srgb(v) * 255.0).round() as u8
}

/// `image` box-filtered by `factor` in each direction in linear light: each block of `factor` x
/// `factor` pixels becomes the mean of its pixels' linear colours, encoded back to sRGB (the
/// blocks of the right and bottom edges hold fewer pixels). A factor of 0 is taken as 1.
pub fn box_filter_linear(image: &image::RgbImage, factor: u32) -> image::RgbImage {
    let blocks = Blocks::of(image, factor);
    image::RgbImage::from_fn(blocks.width, blocks.height, |x, y| {
        let i = (y * blocks.width + x) as usize;
        image::Rgb(blocks.mean[i].map(encode_srgb8))
    })
}

/// The blocks of `factor` x `factor` pixels of an image (those of the right and bottom edges
/// hold fewer), with each one's mean and standard deviation of linear light per channel.
pub(super) struct Blocks {
    /// The block side, pixels (at least 1).
    pub factor: u32,
    /// Blocks a row.
    pub width: u32,
    /// Rows of blocks.
    pub height: u32,
    /// Mean linear colour of each block, row by row.
    pub mean: Vec<[f32; 3]>,
    /// Standard deviation of each block's linear colour, per channel.
    pub spread: Vec<[f32; 3]>,
}

impl Blocks {
    /// The blocks of `image` (a factor of 0 taken as 1).
    pub fn of(image: &image::RgbImage, factor: u32) -> Self {
        let f = factor.max(1);
        let (w, h) = image.dimensions();
        let (bw, bh) = (w.div_ceil(f), h.div_ceil(f));
        let mut sums = vec![[0.0f64; 3]; (bw * bh) as usize];
        let mut squares = vec![[0.0f64; 3]; (bw * bh) as usize];
        let mut counts = vec![0u32; (bw * bh) as usize];
        for (x, y, p) in image.enumerate_pixels() {
            let i = ((y / f) * bw + x / f) as usize;
            for c in 0..3 {
                let v = f64::from(decode_srgb8(p[c]));
                sums[i][c] += v;
                squares[i][c] += v * v;
            }
            counts[i] += 1;
        }
        let n = |i: usize| f64::from(counts[i].max(1));
        let mean: Vec<[f32; 3]> = (0..sums.len())
            .map(|i| sums[i].map(|s| (s / n(i)) as f32))
            .collect();
        let spread = (0..sums.len())
            .map(|i| {
                std::array::from_fn(|c| {
                    let m = sums[i][c] / n(i);
                    (squares[i][c] / n(i) - m * m).max(0.0).sqrt() as f32
                })
            })
            .collect();
        Self {
            factor: f,
            width: bw,
            height: bh,
            mean,
            spread,
        }
    }

    /// The block that holds pixel (`x`, `y`).
    pub fn index(&self, x: u32, y: u32) -> usize {
        ((y / self.factor) * self.width + x / self.factor) as usize
    }
}

/// The coarse FLIP of `actual` against `reference` (see the module docs): the mean FLIP of the
/// two images box-filtered by `factor` in linear light, at FLIP's default viewing distance (as
/// [`super::flip_compare`]). 0 for identical images, up to 1.
pub fn coarse_flip(
    reference: &image::RgbImage,
    actual: &image::RgbImage,
    factor: u32,
) -> Result<f64, ImageCompareError> {
    super::same_size(reference, actual)?;
    let f = factor.max(1);
    let (r, a) = (
        box_filter_linear(reference, f),
        box_filter_linear(actual, f),
    );
    let (w, h) = r.dimensions();
    let error = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, r.as_raw()),
        nv_flip::FlipImageRgb8::with_data(w, h, a.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    Ok(f64::from(nv_flip::FlipPool::from_image(&error).mean()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field of "blades": each pixel grass-tip green or the dark ground between blades, half
    /// of each, drawn from `seed`.
    fn field(seed: u64, w: u32, h: u32, tint: [u8; 3]) -> image::RgbImage {
        let mut rng = crate::tools::rng::Rng(seed);
        image::RgbImage::from_fn(w, h, |_, _| {
            if rng.next() < 0.5 {
                image::Rgb(tint)
            } else {
                image::Rgb([20, 30, 10])
            }
        })
    }

    #[test]
    fn srgb_round_trips_and_averages_in_linear_light() {
        for c in 0..=255u8 {
            assert_eq!(encode_srgb8(decode_srgb8(c)), c);
        }
        // Half black, half white averages to half the light: 188 in sRGB, not 128.
        let edge = image::RgbImage::from_fn(8, 8, |x, _| {
            image::Rgb(if x < 4 { [0; 3] } else { [255; 3] })
        });
        let mean = box_filter_linear(&edge, 8);
        assert_eq!(mean.dimensions(), (1, 1));
        assert_eq!(mean.get_pixel(0, 0).0, [188; 3]);
        // Edge blocks average the pixels they have.
        let odd = image::RgbImage::from_pixel(10, 9, image::Rgb([77, 0, 255]));
        let small = box_filter_linear(&odd, 8);
        assert_eq!(small.dimensions(), (2, 2));
        assert!(small.pixels().all(|p| p.0 == [77, 0, 255]));
    }

    #[test]
    fn another_draw_of_the_same_grass_scores_low_and_a_colour_shift_high() {
        let (w, h) = (256, 160);
        let green = [90, 160, 40];
        let a = field(1, w, h, green);
        let b = field(2, w, h, green);
        let pixel = |x: &image::RgbImage, y: &image::RgbImage| {
            f64::from(super::super::flip_compare(x, y).unwrap().mean)
        };
        let coarse =
            |x: &image::RgbImage, y: &image::RgbImage| coarse_flip(x, y, COARSE_FACTOR).unwrap();
        // Another random field of the same statistics: high pixel by pixel, low coarse.
        let (p_draw, c_draw) = (pixel(&a, &b), coarse(&a, &b));
        assert!(p_draw > 0.2, "pixel FLIP of another draw {p_draw}");
        assert!(c_draw < 0.12, "coarse FLIP of another draw {c_draw}");
        assert!(c_draw < p_draw / 3.0, "{c_draw} against {p_draw}");
        // The same draw in another colour: high on both.
        let shifted = field(1, w, h, [160, 120, 40]);
        let (p_shift, c_shift) = (pixel(&a, &shifted), coarse(&a, &shifted));
        assert!(p_shift > 0.3, "pixel FLIP of a colour shift {p_shift}");
        assert!(c_shift > 0.3, "coarse FLIP of a colour shift {c_shift}");
        assert!(c_shift > 4.0 * c_draw, "{c_shift} against {c_draw}");
        // Identical images score zero; sizes must agree.
        assert_eq!(coarse(&a, &a), 0.0);
        assert!(coarse_flip(&a, &field(1, 8, 8, green), 8).is_err());
    }
}
