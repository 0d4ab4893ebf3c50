//! CPU mirror of `shaders/grass_hiz.wgsl` (the GPU stage: [`crate::grass::hiz`]): the Hi-Z
//! pyramid of the terrain's depth.
//!
//! Depth is reverse-Z (1 near, 0 at infinity), so each texel of a coarser level keeps the
//! smallest (farthest) depth of the texels it covers: a blade nearer than that value at every
//! texel of its footprint may be visible, one farther is hidden. A level's texel covers
//! 2x2 texels of the level below, and 3 in a direction where the level below has an odd size,
//! so that no texel is left out.

use crate::grass::HiZ;
pub use crate::grass::hiz::mip_count;

/// Builds the pyramid from a depth image (row-major, top row first).
pub fn build_hiz(width: u32, height: u32, depth: &[f32]) -> HiZ {
    let mut mips = vec![(width, height, depth.to_vec())];
    for _ in 1..mip_count(width, height) {
        let (pw, ph, prev) = mips.last().expect("level 0 exists");
        let (pw, ph) = (*pw, *ph);
        let (w, h) = ((pw / 2).max(1), (ph / 2).max(1));
        let mut out = vec![0.0f32; (w * h) as usize];
        for y in 0..h {
            for x in 0..w {
                let mut m = f32::MAX;
                // The last texel of a row or column takes in the odd one left over.
                let xs = if x == w - 1 && pw % 2 == 1 && pw > 1 {
                    3
                } else {
                    2
                };
                let ys = if y == h - 1 && ph % 2 == 1 && ph > 1 {
                    3
                } else {
                    2
                };
                for dy in 0..ys {
                    for dx in 0..xs {
                        let sx = (2 * x + dx).min(pw - 1);
                        let sy = (2 * y + dy).min(ph - 1);
                        m = m.min(prev[(sy * pw + sx) as usize]);
                    }
                }
                out[(y * w + x) as usize] = m;
            }
        }
        mips.push((w, h, out));
    }
    HiZ { mips }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_level_keeps_the_farthest_depth_it_covers() {
        let (w, h) = (13u32, 7u32);
        let depth: Vec<f32> = (0..w * h)
            .map(|i| 0.1 + ((i * 37) % 101) as f32 / 200.0)
            .collect();
        let hiz = build_hiz(w, h, &depth);
        assert_eq!(hiz.mips.len() as u32, mip_count(w, h));
        let (tw, th, top) = hiz.mips.last().unwrap();
        assert_eq!((*tw, *th), (1, 1));
        let min = depth.iter().copied().fold(f32::MAX, f32::min);
        assert_eq!(top[0], min, "the top level covers every pixel");
        // Level 1, last column: covers columns 10, 11 and 12 of level 0.
        let (w1, _, l1) = &hiz.mips[1];
        let d = &depth;
        let m = (10..13)
            .flat_map(|x| (0..2).map(move |y| d[(y * w + x) as usize]))
            .fold(f32::MAX, f32::min);
        assert_eq!(l1[(w1 - 1) as usize], m);
    }
}
