//! Where an image's error lies by scale: what is left of it when the render is given the
//! reference's content at scales of a block and coarser, and what a texture of the reference's
//! own statistics does to it.
//!
//! Pixel FLIP of a frame against the truth mixes errors of every size: a field's colour a few
//! percent off over tens of pixels, and single blades standing elsewhere. [`with_block_means_of`]
//! keeps a render's detail within each block of `factor` x `factor` pixels and takes the block's
//! mean colour from the reference (in linear light): the FLIP of that image is the error the
//! render would have if everything it draws at the block's scale and coarser were right, so the
//! fall from the render's own FLIP is the part that lies at that scale and coarser.
//! [`with_block_spread_of`] asks the other question: a render that lacks a texture (a far field
//! flat where the truth's blades mottle it) given random detail of the reference's own spread in
//! each block. Another draw of the same statistics is what a far field could add without drawing
//! the blades; if that raises pixel FLIP, the texture's part of the error cannot be taken away
//! that way.

use super::coarse::{Blocks, decode_srgb8, encode_srgb8};
use super::{ImageCompareError, same_size};

/// `actual` with each `factor` x `factor` block's mean colour taken from `reference`, in linear
/// light: each pixel moved by the difference of the two blocks' means (clamped to the displayable
/// range). A factor of 1 gives `reference` itself; the blocks of the right and bottom edges hold
/// fewer pixels.
pub fn with_block_means_of(
    actual: &image::RgbImage,
    reference: &image::RgbImage,
    factor: u32,
) -> Result<image::RgbImage, ImageCompareError> {
    same_size(reference, actual)?;
    let (a, r) = (Blocks::of(actual, factor), Blocks::of(reference, factor));
    let mut out = actual.clone();
    for (x, y, p) in out.enumerate_pixels_mut() {
        let i = a.index(x, y);
        for c in 0..3 {
            let v = decode_srgb8(p[c]) - a.mean[i][c] + r.mean[i][c];
            p[c] = encode_srgb8(v);
        }
    }
    Ok(out)
}

/// `actual` with random detail added in each `factor` x `factor` block, as much as the
/// reference's block holds beyond the render's own: each pixel moves by one standard normal
/// number (the same for the three channels, as a blade's tip is brighter in all three) times
/// the square root of the difference of the two blocks' variances, per channel, in linear light.
/// Where the render's block already varies as much, it is left alone. `seed` chooses the draw.
pub fn with_block_spread_of(
    actual: &image::RgbImage,
    reference: &image::RgbImage,
    factor: u32,
    seed: u64,
) -> Result<image::RgbImage, ImageCompareError> {
    same_size(reference, actual)?;
    let (a, r) = (Blocks::of(actual, factor), Blocks::of(reference, factor));
    let mut rng = crate::tools::rng::Rng(seed);
    let mut out = actual.clone();
    for (x, y, p) in out.enumerate_pixels_mut() {
        let i = a.index(x, y);
        // Box-Muller: a standard normal number from two uniform ones.
        let (u1, u2) = (rng.next().max(f64::MIN_POSITIVE), rng.next());
        let n = ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32;
        for c in 0..3 {
            let extra = (r.spread[i][c].powi(2) - a.spread[i][c].powi(2))
                .max(0.0)
                .sqrt();
            p[c] = encode_srgb8(decode_srgb8(p[c]) + n * extra);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field of "blades" in blocks: each pixel `tint` or dark ground, drawn from `seed`, with
    /// the share of tint changing from block to block of 8 pixels.
    fn field(seed: u64, w: u32, h: u32, tint: [u8; 3]) -> image::RgbImage {
        let mut rng = crate::tools::rng::Rng(seed);
        image::RgbImage::from_fn(w, h, |x, y| {
            let share = 0.2 + 0.6 * f64::from((x / 8 + 3 * (y / 8)) % 5) / 4.0;
            if rng.next() < share {
                image::Rgb(tint)
            } else {
                image::Rgb([20, 30, 10])
            }
        })
    }

    fn flip(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
        f64::from(super::super::flip_compare(a, b).unwrap().mean)
    }

    #[test]
    fn the_reference_block_means_replace_the_renders_and_keep_its_detail() {
        let (w, h) = (67, 45);
        let truth = field(1, w, h, [90, 160, 40]);
        let render = field(2, w, h, [70, 120, 40]);
        // Blocks of one pixel: the reference itself.
        assert_eq!(with_block_means_of(&render, &truth, 1).unwrap(), truth);
        // Identical images are left alone.
        assert_eq!(with_block_means_of(&truth, &truth, 8).unwrap(), truth);
        // Each block now has the reference's mean (to the rounding of 8-bit codes).
        let fixed = with_block_means_of(&render, &truth, 8).unwrap();
        let (f, t) = (Blocks::of(&fixed, 8), Blocks::of(&truth, 8));
        for i in 0..t.mean.len() {
            for c in 0..3 {
                assert!((f.mean[i][c] - t.mean[i][c]).abs() < 0.01, "block {i}");
            }
        }
        // The render's colour and cover at the blocks' scale were its error, so it falls; the
        // other draw's detail is left.
        let (before, after) = (flip(&truth, &render), flip(&truth, &fixed));
        assert!(after < 0.8 * before, "{after} against {before}");
        assert!(after > 0.05, "{after}");
        assert!(with_block_means_of(&render, &field(1, 8, 8, [0; 3]), 8).is_err());
    }

    #[test]
    fn a_flat_render_gets_the_references_spread_and_a_textured_one_is_left_alone() {
        let (w, h) = (64, 48);
        let truth = field(1, w, h, [90, 160, 40]);
        // The truth's block means, flat.
        let means = Blocks::of(&truth, 8);
        let flat = image::RgbImage::from_fn(w, h, |x, y| {
            image::Rgb(means.mean[means.index(x, y)].map(encode_srgb8))
        });
        let textured = with_block_spread_of(&flat, &truth, 8, 7).unwrap();
        let (got, want) = (Blocks::of(&textured, 8), Blocks::of(&truth, 8));
        for i in 0..want.spread.len() {
            let (g, t) = (got.spread[i][1], want.spread[i][1]);
            assert!(
                (g - t).abs() < 0.35 * t + 0.01,
                "block {i}: {g} against {t}"
            );
        }
        // The same seed, the same draw; a render as varied as the truth is left as it is.
        assert_eq!(with_block_spread_of(&flat, &truth, 8, 7).unwrap(), textured);
        assert_eq!(with_block_spread_of(&truth, &truth, 8, 7).unwrap(), truth);
    }
}
