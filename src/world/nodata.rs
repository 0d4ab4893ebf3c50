//! Filling a DEM's nodata samples (voids) from the valid heights around them, by pull-push.
//!
//! **Pull**: the grid is averaged down a pyramid of half-resolution grids. Each coarse sample is
//! the weighted mean of its (up to) four finer samples, with weight 1 for a valid height and 0
//! for a void at the finest level; a coarse weight is the sum of its children's, capped at 1. A
//! few levels up, every sample has some weight, however large the void.
//!
//! **Push**: going back down, a sample with weight below 1 is blended with the bilinear
//! interpolation of the coarser level (already filled): `w * own + (1 - w) * coarse`. At the
//! finest level valid samples have weight 1 and stay exactly as they were; a void takes the
//! interpolated value. A small void therefore gets about the mean of its rim, and a large one a
//! smooth surface that meets the valid heights at its edge. The cost is linear in the number of
//! samples.

/// Replaces every NaN in `heights` (`width * height`, row-major) by a height filled from the
/// valid samples around it, and returns how many were filled. Valid samples are not changed.
/// With no valid sample at all nothing is changed and the count of voids is returned.
pub fn fill_nodata(width: usize, height: usize, heights: &mut [f32]) -> u64 {
    assert_eq!(heights.len(), width * height, "fill_nodata: grid size");
    let voids = heights.iter().filter(|h| h.is_nan()).count() as u64;
    if voids == 0 || voids == heights.len() as u64 {
        return voids;
    }
    let finest = Level {
        width,
        height,
        value: heights
            .iter()
            .map(|&h| if h.is_nan() { 0.0 } else { h })
            .collect(),
        weight: heights
            .iter()
            .map(|h| if h.is_nan() { 0.0 } else { 1.0 })
            .collect(),
    };
    let mut levels = vec![finest];
    loop {
        let last = levels.last().expect("at least the finest level");
        if last.weight.iter().all(|&w| w >= 1.0) || (last.width == 1 && last.height == 1) {
            break;
        }
        let coarser = last.pull();
        levels.push(coarser);
    }
    for k in (0..levels.len() - 1).rev() {
        let (fine, coarse) = levels.split_at_mut(k + 1);
        fine[k].push(&coarse[0]);
    }
    for (h, &v) in heights.iter_mut().zip(&levels[0].value) {
        if h.is_nan() {
            *h = v;
        }
    }
    voids
}

/// One level of the pull-push pyramid.
struct Level {
    width: usize,
    height: usize,
    value: Vec<f32>,
    /// 0 (no data) ..= 1 (fully known).
    weight: Vec<f32>,
}

impl Level {
    /// The level of half the resolution: weighted means of 2x2 blocks (fewer at an odd edge).
    fn pull(&self) -> Level {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut value = vec![0.0; w * h];
        let mut weight = vec![0.0; w * h];
        for j in 0..h {
            for i in 0..w {
                let (mut sum, mut sum_w) = (0.0f64, 0.0f64);
                for b in 2 * j..(2 * j + 2).min(self.height) {
                    for a in 2 * i..(2 * i + 2).min(self.width) {
                        let k = b * self.width + a;
                        sum += f64::from(self.weight[k]) * f64::from(self.value[k]);
                        sum_w += f64::from(self.weight[k]);
                    }
                }
                if sum_w > 0.0 {
                    value[j * w + i] = (sum / sum_w) as f32;
                    weight[j * w + i] = sum_w.min(1.0) as f32;
                }
            }
        }
        Level {
            width: w,
            height: h,
            value,
            weight,
        }
    }

    /// Blends every sample of weight below 1 with `coarse` (the next level, already filled),
    /// leaving the level fully known.
    fn push(&mut self, coarse: &Level) {
        for j in 0..self.height {
            for i in 0..self.width {
                let k = j * self.width + i;
                let w = self.weight[k];
                if w < 1.0 {
                    // The centre of fine sample i lies at (i + 0.5) / 2 - 0.5 in coarse samples.
                    let c = coarse.bilinear(i as f64 * 0.5 - 0.25, j as f64 * 0.5 - 0.25);
                    self.value[k] = w * self.value[k] + (1.0 - w) * c;
                    self.weight[k] = 1.0;
                }
            }
        }
    }

    /// Bilinear interpolation at fractional sample position `(x, y)`, clamped to the level.
    fn bilinear(&self, x: f64, y: f64) -> f32 {
        let x = x.clamp(0.0, (self.width - 1) as f64);
        let y = y.clamp(0.0, (self.height - 1) as f64);
        let (i0, j0) = (x.floor() as usize, y.floor() as usize);
        let (i1, j1) = ((i0 + 1).min(self.width - 1), (j0 + 1).min(self.height - 1));
        let (fx, fy) = ((x - i0 as f64) as f32, (y - j0 as f64) as f32);
        let v = |i: usize, j: usize| self.value[j * self.width + i];
        let south = v(i0, j0) * (1.0 - fx) + v(i1, j0) * fx;
        let north = v(i0, j1) * (1.0 - fx) + v(i1, j1) * fx;
        south * (1.0 - fy) + north * fy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_without_voids_is_unchanged() {
        let mut h: Vec<f32> = (0..35).map(|i| i as f32 * 1.5).collect();
        let before = h.clone();
        assert_eq!(fill_nodata(7, 5, &mut h), 0);
        assert_eq!(h, before);
    }

    #[test]
    fn voids_in_a_flat_grid_take_its_height_and_valid_samples_stay() {
        let (w, hgt) = (33, 21);
        let mut h = vec![42.5f32; w * hgt];
        // A large void touching the east edge, and single voids.
        for j in 3..15 {
            for i in 20..33 {
                h[j * w + i] = f32::NAN;
            }
        }
        h[0] = f32::NAN;
        h[w * hgt - 1] = f32::NAN;
        let expected_voids = 12 * 13 + 2;
        assert_eq!(fill_nodata(w, hgt, &mut h), expected_voids);
        assert!(h.iter().all(|&v| v == 42.5), "{h:?}");
    }

    #[test]
    fn a_void_in_a_slope_is_filled_between_its_rim_heights() {
        let (w, hgt) = (40, 30);
        let f = |i: usize, j: usize| 100.0 + 2.0 * i as f32 + 0.5 * j as f32;
        let mut h: Vec<f32> = (0..w * hgt).map(|k| f(k % w, k / w)).collect();
        let truth = h.clone();
        for j in 10..16 {
            for i in 12..20 {
                h[j * w + i] = f32::NAN;
            }
        }
        assert_eq!(fill_nodata(w, hgt, &mut h), 48);
        for j in 0..hgt {
            for i in 0..w {
                let k = j * w + i;
                let inside = (10..16).contains(&j) && (12..20).contains(&i);
                if inside {
                    // Between the lowest and highest rim heights, and near the plane.
                    assert!((f(11, 9)..=f(20, 16)).contains(&h[k]), "({i},{j}) {}", h[k]);
                    assert!(
                        (h[k] - truth[k]).abs() < 6.0,
                        "({i},{j}) {} vs {}",
                        h[k],
                        truth[k]
                    );
                } else {
                    assert_eq!(h[k], truth[k]);
                }
            }
        }
    }

    #[test]
    fn an_all_void_grid_is_left_alone() {
        let mut h = vec![f32::NAN; 12];
        assert_eq!(fill_nodata(4, 3, &mut h), 12);
        assert!(h.iter().all(|v| v.is_nan()));
    }
}
