//! CPU mirror of `shaders/derive_child.wgsl`: a child tile derived from its parent, for levels
//! finer than the stored data.
//!
//! Heights: Catmull-Rom (bicubic) upsampling of the parent's smooth surface (the parent less
//! its own detail, see [`derive_child`]) plus deterministic detail noise between the parent's
//! samples, scaled by the local slope and by the child level's amplitude (fitted per world by
//! [`calibrate`], stored in the manifest's `[derive]` table) and faded to zero toward the tile
//! edges. Every term is a function
//! of the global sample position and of parent samples that neighbouring tiles share, so
//! neighbours derive identical edge and border values. Grass type is taken from one of the
//! nearest parent samples (picked by a hash, so types stay crisp and clump), density is the
//! rounded mean of the nearest parent samples.
//!
//! Written loop for loop like the shader, but independently of it: the tests compare the two.

use crate::world::{
    DeriveCalibration, DeriveMode, LEGACY_DETAIL, MAX_DETAIL, Manifest, Pyramid, TileData, TileId,
};

/// Most levels a pyramid has, stored and derived (the manifest's limit).
pub const MAX_LEVELS: usize = 24;

/// Settings of derivation (shared by the shader's uniforms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeriveParams {
    /// Seed of the detail noise.
    pub seed: u32,
    /// Detail amplitude of a child at each level (indexed by the child's level), in child cells
    /// per unit of slope. Entries of stored levels are never used.
    pub detail: [f32; MAX_LEVELS],
    /// Cells over which the detail fades in from a tile edge.
    pub window_cells: f32,
}

impl Default for DeriveParams {
    /// [`LEGACY_DETAIL`] at every level: what a world without a `[derive]` table gets.
    fn default() -> Self {
        Self {
            seed: 0x5eed,
            detail: [LEGACY_DETAIL; MAX_LEVELS],
            window_cells: 4.0,
        }
    }
}

impl DeriveParams {
    /// The settings `manifest` asks for: its `[derive]` amplitudes from the first derived
    /// level on (the last one repeated beyond the list), or the default without that table.
    pub fn for_manifest(manifest: &Manifest) -> Self {
        let mut params = Self::default();
        if let Some(c) = &manifest.derive {
            let first = usize::from(manifest.pyramid.stored_levels);
            params.detail = [0.0; MAX_LEVELS];
            for (level, d) in params.detail.iter_mut().enumerate().skip(first) {
                *d = c
                    .detail
                    .get(level - first)
                    .or(c.detail.last())
                    .copied()
                    .unwrap_or(0.0);
            }
        }
        params
    }

    /// The same settings without detail: plain Catmull-Rom.
    pub fn bicubic(&self) -> Self {
        Self {
            detail: [0.0; MAX_LEVELS],
            ..*self
        }
    }

    /// Detail amplitude of a child at `level` (the last entry for levels beyond the table).
    pub fn detail_at(&self, level: u8) -> f32 {
        self.detail[usize::from(level).min(MAX_LEVELS - 1)]
    }
}

/// The integer hash used by derivation (a 32-bit avalanche hash; identical in WGSL).
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

pub(crate) fn hash4(a: u32, b: u32, c: u32, d: u32) -> u32 {
    hash_u32(a ^ hash_u32(b ^ hash_u32(c ^ hash_u32(d))))
}

/// A hash mapped to [-1, 1) exactly (24 bits).
pub(crate) fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0) * 2.0 - 1.0
}

/// Catmull-Rom weights at fraction 0 and one half (the only fractions a 2x upsampling meets).
pub(crate) const WEIGHTS: [[f32; 4]; 2] =
    [[0.0, 1.0, 0.0, 0.0], [-0.0625, 0.5625, 0.5625, -0.0625]];

/// Derives `child` from `parent` (its parent tile). `pyramid.border` must be even and at
/// least 2.
///
/// A derived level is the Catmull-Rom upsampling of its parent's *smooth* surface plus its own
/// detail; the detail is not passed on. The parent's detail, where the parent is itself
/// derived, is recomputed here and taken off the 16 parent samples the child reads: it lies
/// only on the parent's new samples (those between its own parent's), scaled by the slope of
/// the grandparent's surface, which is read off the parent's other samples (they are the
/// grandparent's), and faded to zero over the `border` samples nearest a tile edge, so that
/// every sample it needs is in the tile. A level's RMS height error is thus Catmull-Rom's plus
/// its own detail, however deep it lies below the stored data.
pub fn derive_child(
    pyramid: &Pyramid,
    parent: &TileData,
    child: TileId,
    params: &DeriveParams,
) -> TileData {
    let s = parent.size as i32;
    let n = pyramid.tile_cells as i32;
    let b = pyramid.border as i32;
    let (qx, qy) = ((child.x & 1) as i32, (child.y & 1) as i32);
    let cell_parent = pyramid.cell_size_m(child.level - 1) as f32;
    let cell_child = pyramid.cell_size_m(child.level) as f32;
    let cell_grandparent = 2.0 * cell_parent;
    // Stored levels carry no detail.
    let amplitude = |level: u8| {
        if level < pyramid.stored_levels {
            0.0
        } else {
            params.detail_at(level)
        }
    };
    let parent_level = child.level - 1;
    let parent_amplitude = amplitude(parent_level);
    let child_amplitude = amplitude(child.level);
    let at = |x: i32, y: i32| -> usize { (y.clamp(0, s - 1) * s + x.clamp(0, s - 1)) as usize };
    let window_at = |sx: i32, sy: i32| -> f32 {
        let mx = sx.rem_euclid(n);
        let my = sy.rem_euclid(n);
        let edge = mx.min(n - mx).min(my).min(n - my) - b;
        (edge as f32 / params.window_cells).clamp(0.0, 1.0)
    };
    // Global sample of parent texel (0, 0).
    let (ox, oy) = ((child.x >> 1) as i32 * n - b, (child.y >> 1) as i32 * n - b);
    // The parent's smooth height at texel (x, y): its height less its own detail.
    let smooth = |x: i32, y: i32| -> f32 {
        let (gx, gy) = (ox + x, oy + y);
        let (ex, ey) = (gx & 1, gy & 1);
        let new = ((ex | ey) as f32).min(1.0);
        let (cx, cy) = (x - ex, y - ey);
        let gpx = (parent.heights[at(cx + 2, cy)] - parent.heights[at(cx - 2, cy)])
            / (2.0 * cell_grandparent);
        let gpy = (parent.heights[at(cx, cy + 2)] - parent.heights[at(cx, cy - 2)])
            / (2.0 * cell_grandparent);
        let slope = (gpx * gpx + gpy * gpy).sqrt().min(1.5);
        let noise = unit(hash4(
            gx as u32,
            gy as u32,
            u32::from(parent_level),
            params.seed,
        ));
        let detail = noise * (parent_amplitude * cell_parent * slope * window_at(gx, gy) * new);
        parent.heights[at(x, y)] - detail
    };
    let len = (s * s) as usize;
    let mut heights = vec![0.0f32; len];
    let mut grass_type = vec![0u8; len];
    let mut density = vec![0u8; len];
    for j in 0..s {
        for i in 0..s {
            // Position in half parent texels.
            let px2 = b + qx * n + i;
            let py2 = b + qy * n + j;
            let (ix, fx) = (px2 >> 1, (px2 & 1) as usize);
            let (iy, fy) = (py2 >> 1, (py2 & 1) as usize);
            let (wx, wy) = (WEIGHTS[fx], WEIGHTS[fy]);

            let mut taps = [[0.0f32; 4]; 4];
            for (dy, row) in taps.iter_mut().enumerate() {
                for (dx, tap) in row.iter_mut().enumerate() {
                    *tap = smooth(ix - 1 + dx as i32, iy - 1 + dy as i32);
                }
            }
            let mut rows = [0.0f32; 4];
            for (dy, row) in rows.iter_mut().enumerate() {
                let t = &taps[dy];
                *row = ((wx[0] * t[0] + wx[1] * t[1]) + wx[2] * t[2]) + wx[3] * t[3];
            }
            let mut h = ((wy[0] * rows[0] + wy[1] * rows[1]) + wy[2] * rows[2]) + wy[3] * rows[3];

            let gx = (taps[1][2] - taps[1][0]) / (2.0 * cell_parent);
            let gy = (taps[2][1] - taps[0][1]) / (2.0 * cell_parent);
            let slope = (gx * gx + gy * gy).sqrt().min(1.5);

            // Global sample coordinates at the child's level; detail only between the
            // parent's samples.
            let sx = child.x as i32 * n + i - b;
            let sy = child.y as i32 * n + j - b;
            let new = (((sx | sy) & 1) as f32).min(1.0);
            let noise = unit(hash4(
                sx as u32,
                sy as u32,
                u32::from(child.level),
                params.seed,
            ));
            h += noise * (child_amplitude * cell_child * slope * window_at(sx, sy) * new);

            let pick = hash4(
                sx as u32,
                sy as u32,
                u32::from(child.level),
                params.seed ^ 0x9e37_79b9,
            );
            let tx = ix + (fx as i32) * (pick & 1) as i32;
            let ty = iy + (fy as i32) * ((pick >> 1) & 1) as i32;

            let mut sum = 0u32;
            for a in 0..=fy as i32 {
                for c in 0..=fx as i32 {
                    sum += u32::from(parent.density[at(ix + c, iy + a)]);
                }
            }
            let count = ((1 + fx) * (1 + fy)) as u32;

            let o = (j * s + i) as usize;
            heights[o] = h;
            grass_type[o] = parent.grass_type[at(tx, ty)];
            density[o] = ((sum + count / 2) / count) as u8;
        }
    }
    TileData {
        id: child,
        size: parent.size,
        heights,
        grass_type,
        density,
    }
}

/// A height grid to calibrate from: row-major, north or south row first alike.
#[derive(Clone, Copy, Debug)]
pub struct HeightField<'a> {
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Spacing along a row and between rows, metres.
    pub cell_m: (f64, f64),
    /// Heights, row-major.
    pub heights: &'a [f32],
}

/// What [`calibrate`] measured at one octave: the field subsampled by `2^octave`, against its
/// prediction from the octave above.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OctaveFit {
    /// 0 for the field itself, 1 for every other sample, and so on.
    pub octave: u32,
    /// RMS of truth minus the Catmull-Rom prediction from the (true) octave above, at the
    /// samples the prediction adds, metres.
    pub residual_rms_m: f64,
    /// Detail amplitude (child cells per unit of slope) for which the runtime's detail noise
    /// alone is as rough as the truth (the same spread of the Laplacian).
    pub detail: f32,
    /// Roughness of the field derived by Catmull-Rom alone from this octave's parent (octave
    /// `octave + 1`, that is `octave + 1` steps), relative to the field's own.
    pub bicubic_roughness: f64,
    /// RMS slope of the field at this octave (central differences), rise over run.
    pub slope_rms: f64,
    /// RMS slope of the field derived by Catmull-Rom alone from octave `octave + 1`, relative
    /// to the field's own.
    pub bicubic_slope: f64,
}

/// Octaves [`calibrate`] measures at most, finest first.
pub const FIT_OCTAVES: u32 = 4;
/// Fewest octaves [`calibrate`] fits a line to.
pub const MIN_FIT_OCTAVES: usize = 3;
/// A finest-octave residual below this is a flat world, metres.
pub const FLAT_RESIDUAL_M: f64 = 0.01;
/// Largest RMS deviation (log2) of the residuals from the fitted line that is still a fit.
pub const MAX_FIT_RMS_LOG2: f64 = 0.5;
/// Smallest grid the coarsest measured octave's parent may be, samples a side.
const MIN_OCTAVE_SAMPLES: usize = 12;
/// Samples kept clear of the grid's edges in the statistics (clamping flattens them).
const STATS_MARGIN: usize = 4;

/// One octave of the field, as a grid of its own.
#[derive(Clone, Debug)]
struct Level {
    width: usize,
    height: usize,
    cell: (f64, f64),
    data: Vec<f32>,
}

impl Level {
    /// Every `2^octave`-th sample of the first `width` x `height` samples of `field`.
    fn subsample(field: &HeightField<'_>, octave: u32, width: usize, height: usize) -> Level {
        let step = 1usize << octave;
        let (w, h) = ((width - 1) / step + 1, (height - 1) / step + 1);
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                data.push(field.heights[y * step * field.width + x * step]);
            }
        }
        Level {
            width: w,
            height: h,
            cell: (field.cell_m.0 * step as f64, field.cell_m.1 * step as f64),
            data,
        }
    }

    fn at(&self, x: i64, y: i64) -> f32 {
        let x = x.clamp(0, self.width as i64 - 1) as usize;
        let y = y.clamp(0, self.height as i64 - 1) as usize;
        self.data[y * self.width + x]
    }

    /// Catmull-Rom 2x upsampling, and the runtime's detail noise at amplitude 1 (a hashed
    /// value in [-1, 1) times the child cell times the parent's slope, capped at 1.5, on the
    /// new samples only).
    fn predict(&self, octave: u32, seed: u32) -> (Level, Level) {
        let (w, h) = (2 * self.width - 1, 2 * self.height - 1);
        let cell = (self.cell.0 / 2.0, self.cell.1 / 2.0);
        let cell_child = (0.5 * (cell.0 + cell.1)) as f32;
        let mut smooth = vec![0.0f32; w * h];
        let mut noise = vec![0.0f32; w * h];
        for j in 0..h {
            for i in 0..w {
                let (ix, fx) = ((i >> 1) as i64, i & 1);
                let (iy, fy) = ((j >> 1) as i64, j & 1);
                let (wx, wy) = (WEIGHTS[fx], WEIGHTS[fy]);
                let mut rows = [0.0f32; 4];
                for (dy, row) in rows.iter_mut().enumerate() {
                    let y = iy - 1 + dy as i64;
                    let p = |dx: i64| self.at(ix - 1 + dx, y);
                    *row = ((wx[0] * p(0) + wx[1] * p(1)) + wx[2] * p(2)) + wx[3] * p(3);
                }
                smooth[j * w + i] =
                    ((wy[0] * rows[0] + wy[1] * rows[1]) + wy[2] * rows[2]) + wy[3] * rows[3];
                let gx = f64::from(self.at(ix + 1, iy) - self.at(ix - 1, iy)) / (2.0 * self.cell.0);
                let gy = f64::from(self.at(ix, iy + 1) - self.at(ix, iy - 1)) / (2.0 * self.cell.1);
                let slope = (gx * gx + gy * gy).sqrt().min(1.5) as f32;
                let n = unit(hash4(i as u32, j as u32, 0xca11 ^ octave, seed));
                let new = ((fx | fy) as f32).min(1.0);
                noise[j * w + i] = n * cell_child * slope * new;
            }
        }
        let level = |data| Level {
            width: w,
            height: h,
            cell,
            data,
        };
        (level(smooth), level(noise))
    }

    /// RMS slope (central differences) away from the edges.
    fn slope_rms(&self) -> f64 {
        let g = |x: usize, y: usize| f64::from(self.data[y * self.width + x]);
        let (mut sum, mut count) = (0.0f64, 0.0f64);
        for y in STATS_MARGIN..self.height - STATS_MARGIN {
            for x in STATS_MARGIN..self.width - STATS_MARGIN {
                let gx = (g(x + 1, y) - g(x - 1, y)) / (2.0 * self.cell.0);
                let gy = (g(x, y + 1) - g(x, y - 1)) / (2.0 * self.cell.1);
                sum += gx * gx + gy * gy;
                count += 1.0;
            }
        }
        (sum / count.max(1.0)).sqrt()
    }

    fn laplacian(&self, x: usize, y: usize) -> f64 {
        let g = |x: usize, y: usize| f64::from(self.data[y * self.width + x]);
        let c = g(x, y);
        (g(x + 1, y) + g(x - 1, y) - 2.0 * c) / (self.cell.0 * self.cell.0)
            + (g(x, y + 1) + g(x, y - 1) - 2.0 * c) / (self.cell.1 * self.cell.1)
    }
}

/// RMS of `truth - smooth` at the samples a 2x upsampling adds, and the amplitude `d` for
/// which `d * noise` alone has the spread of the Laplacian of `truth`, both away from the edges.
fn match_roughness(truth: &Level, smooth: &Level, noise: &Level) -> (f64, f32) {
    let (w, h) = (truth.width, truth.height);
    let (mut se, mut n_new) = (0.0f64, 0usize);
    for y in STATS_MARGIN..h - STATS_MARGIN {
        for x in STATS_MARGIN..w - STATS_MARGIN {
            if (x | y) & 1 == 1 {
                let r = f64::from(truth.data[y * w + x] - smooth.data[y * w + x]);
                se += r * r;
                n_new += 1;
            }
        }
    }
    let (var_t, var_n) = (laplacian_variance(truth), laplacian_variance(noise));
    let detail = if var_n > 0.0 {
        (var_t / var_n).sqrt() as f32
    } else {
        0.0
    };
    ((se / n_new.max(1) as f64).sqrt(), detail)
}

/// Variance of the Laplacian of `level` away from its edges.
fn laplacian_variance(level: &Level) -> f64 {
    let (mut sum, mut sum2, mut count) = (0.0f64, 0.0f64, 0.0f64);
    for y in STATS_MARGIN..level.height - STATS_MARGIN {
        for x in STATS_MARGIN..level.width - STATS_MARGIN {
            let l = level.laplacian(x, y);
            sum += l;
            sum2 += l * l;
            count += 1.0;
        }
    }
    let mean = sum / count.max(1.0);
    (sum2 / count.max(1.0) - mean * mean).max(0.0)
}

/// Measures up to `octaves` octaves of `field` (see [`OctaveFit`]), finest first; fewer where
/// the coarsest parent would be smaller than 12 samples a side.
pub fn measure_octaves(field: &HeightField<'_>, octaves: u32, seed: u32) -> Vec<OctaveFit> {
    let fits = |k: u32| {
        let step = 1usize << (k + 1);
        (field.width - 1) / step + 1 >= MIN_OCTAVE_SAMPLES
            && (field.height - 1) / step + 1 >= MIN_OCTAVE_SAMPLES
    };
    let n = (0..octaves).take_while(|&k| fits(k)).count() as u32;
    if n == 0 {
        return Vec::new();
    }
    // Crop so that every octave's grid is exactly twice its parent's.
    let crop = |len: usize| ((len - 1) >> n << n) + 1;
    let (w, h) = (crop(field.width), crop(field.height));
    let truth: Vec<Level> = (0..=n).map(|k| Level::subsample(field, k, w, h)).collect();
    let finest = laplacian_variance(&truth[0]);
    let finest_slope = truth[0].slope_rms();
    (0..n)
        .map(|k| {
            let (predicted, noise) = truth[k as usize + 1].predict(k, seed);
            let (residual_rms_m, detail) = match_roughness(&truth[k as usize], &predicted, &noise);
            // Catmull-Rom from octave k + 1 all the way down to the field.
            let mut smooth = truth[k as usize + 1].clone();
            for j in (0..=k).rev() {
                smooth = smooth.predict(j, seed).0;
            }
            let ratio = (laplacian_variance(&smooth) / finest.max(1e-30)).sqrt();
            let slope_ratio = smooth.slope_rms() / finest_slope.max(1e-30);
            OctaveFit {
                octave: k,
                residual_rms_m,
                detail,
                bicubic_roughness: ratio,
                slope_rms: truth[k as usize].slope_rms(),
                bicubic_slope: slope_ratio,
            }
        })
        .collect()
}

/// Largest deviation (log2) of the per-octave amplitudes from their mean on terrain taken as
/// scale-invariant.
pub const FLAT_TREND_LOG2: f64 = 0.15;

/// Smallest factor between the detail of one derived level and the next. A curve fitted over
/// coarse octaves bends on where the terrain's own trend levels off: on the SRTM DEMs the
/// measured amplitude falls by about a third per octave below 100 m, and no faster.
pub const MIN_LEVEL_STEP: f64 = 2.0 / 3.0;
/// Largest factor between the detail of one derived level and the next.
pub const MAX_LEVEL_STEP: f64 = 1.25;

/// Least-squares polynomial of degree 2 (degree 1 through two points) through `(x, y)`
/// points: its coefficients, constant first.
fn fit_quadratic(points: &[(f64, f64)]) -> [f64; 3] {
    if points.len() < 3 {
        let (slope, intercept, _) = fit_line(points);
        return [intercept, slope, 0.0];
    }
    // Normal equations, solved by Cramer's rule (3 x 3).
    let mut m = [[0.0f64; 3]; 3];
    let mut v = [0.0f64; 3];
    for &(x, y) in points {
        let p = [1.0, x, x * x];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] += p[r] * p[c];
            }
            v[r] += p[r] * y;
        }
    }
    let det = |a: &[[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(&m);
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let mut a = m;
        for r in 0..3 {
            a[r][c] = v[r];
        }
        *o = det(&a) / d;
    }
    out
}

/// Least-squares line through `(x, y)` points: slope, intercept and RMS deviation.
fn fit_line(points: &[(f64, f64)]) -> (f64, f64, f64) {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x / n, b + y / n));
    let sxx: f64 = points.iter().map(|&(x, _)| (x - mx) * (x - mx)).sum();
    let sxy: f64 = points.iter().map(|&(x, y)| (x - mx) * (y - my)).sum();
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let intercept = my - slope * mx;
    let rms = (points
        .iter()
        .map(|&(x, y)| (y - intercept - slope * x).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    (slope, intercept, rms)
}

/// Fits the detail of `derived_levels` levels finer than `field` (a world's finest stored
/// level, or the coarse grid `verdant eval derive` is given) to the field itself.
///
/// Each octave of the field (the field, every other sample, every fourth, ... up to
/// [`FIT_OCTAVES`]) is predicted by Catmull-Rom from the next coarser one. The RMS residual of
/// the prediction grows by `2^H` an octave coarser on fractal terrain: a line through
/// log2(residual) against octave gives the Hurst exponent `H` and, by its deviation, how
/// fractal the terrain is. Per octave, the detail amplitude that makes it exactly as rough as
/// the truth is measured too (see [`OctaveFit::detail`]); the trend of those amplitudes over
/// the octaves (a curve through log2(amplitude)) is continued to each derived level.
///
/// Falls back to plain bicubic (`method = "bicubic"`, every amplitude 0, the reason in
/// `note`) with fewer than [`MIN_FIT_OCTAVES`] octaves, on flat terrain (finest residual
/// under [`FLAT_RESIDUAL_M`]), where the fit is poor (`H` outside 0..=1.5, deviation above
/// [`MAX_FIT_RMS_LOG2`]), or where Catmull-Rom alone is as rough as the data.
pub fn calibrate(field: &HeightField<'_>, derived_levels: u8, seed: u32) -> DeriveCalibration {
    let octaves = measure_octaves(field, FIT_OCTAVES, seed);
    let residual_rms_m = octaves.first().map_or(0.0, |o| o.residual_rms_m);
    let mut table = DeriveCalibration {
        method: DeriveMode::Bicubic,
        note: String::new(),
        octaves: octaves.len() as u32,
        hurst: 0.0,
        fit_rms_log2: 0.0,
        residual_rms_m,
        detail: vec![0.0; usize::from(derived_levels)],
    };
    if octaves.len() < MIN_FIT_OCTAVES {
        table.note = format!(
            "too few levels: {} octaves measurable, {MIN_FIT_OCTAVES} needed; plain bicubic",
            octaves.len()
        );
        return table;
    }
    if residual_rms_m < FLAT_RESIDUAL_M {
        table.note = format!(
            "flat: residual {residual_rms_m:.4} m at the finest level, under \
             {FLAT_RESIDUAL_M} m; plain bicubic"
        );
        return table;
    }
    let points: Vec<(f64, f64)> = octaves
        .iter()
        .map(|o| (f64::from(o.octave), o.residual_rms_m.max(1e-9).log2()))
        .collect();
    let (hurst, _, fit_rms) = fit_line(&points);
    table.hurst = hurst;
    table.fit_rms_log2 = fit_rms;
    if !(0.0..=1.5).contains(&hurst) || fit_rms > MAX_FIT_RMS_LOG2 {
        table.note =
            format!("poor fit: H {hurst:.3}, deviation {fit_rms:.3} (log2); plain bicubic");
        return table;
    }
    let details: Vec<(f64, f64)> = octaves
        .iter()
        .filter(|o| o.detail > 0.0)
        .map(|o| (f64::from(o.octave), f64::from(o.detail).log2()))
        .collect();
    if octaves[0].detail <= 0.0 || octaves[0].bicubic_roughness >= 1.0 || details.len() < 2 {
        table.note =
            format!("H {hurst:.3}, but Catmull-Rom alone is as rough as the data; plain bicubic");
        return table;
    }
    // Amplitude at octave -s (the s-th derived level): the fitted curve continued, each level
    // within a factor [MIN_LEVEL_STEP, MAX_LEVEL_STEP] of the one above.
    // Scale-invariant terrain keeps its amplitude from octave to octave (within
    // FLAT_TREND_LOG2): it is held. Otherwise the curve through the octaves is continued.
    let mean = details.iter().map(|p| p.1).sum::<f64>() / details.len() as f64;
    let flat = details
        .iter()
        .all(|p| (p.1 - mean).abs() <= FLAT_TREND_LOG2);
    let curve = if flat {
        [mean, 0.0, 0.0]
    } else {
        fit_quadratic(&details)
    };
    let log2_detail = |k: f64| curve[0] + curve[1] * k + curve[2] * k * k;
    // The runtime scales its detail by the slope of the smooth (Catmull-Rom) parent, which
    // is less steep than the terrain's own at that level once it lies below the data: as
    // measured that many steps below the octaves, and beyond the deepest measured, less by
    // the terrain's steepening per octave (`2^(1 - H)` on fractal terrain).
    let slopes: Vec<(f64, f64)> = octaves
        .iter()
        .map(|o| (f64::from(o.octave), o.slope_rms.max(1e-12).log2()))
        .collect();
    let steepening = (-fit_line(&slopes).0).clamp(0.0, 1.0);
    let deepest = octaves.len() - 1;
    let parent_slope = |depth: usize| -> f64 {
        match depth {
            0 => 1.0,
            d if d <= deepest + 1 => octaves[d - 1].bicubic_slope,
            d => octaves[deepest].bicubic_slope * (-steepening * (d - deepest - 1) as f64).exp2(),
        }
        .clamp(1e-3, 1.0)
    };
    let mut previous = log2_detail(0.0);
    let finest = previous.exp2();
    for (s, d) in table.detail.iter_mut().enumerate() {
        let next = log2_detail(-(s as f64 + 1.0)).clamp(
            previous + MIN_LEVEL_STEP.log2(),
            previous + MAX_LEVEL_STEP.log2(),
        );
        // The s-th derived level (from 0) is s + 1 Catmull-Rom steps below the data, which
        // carry part of the roughness: the detail adds the rest (as measured that many steps
        // below octave s + 1, or the deepest measured).
        let smooth = octaves[s.min(deepest)].bicubic_roughness.min(1.0);
        let share = (1.0 - smooth * smooth).sqrt();
        let slope = if flat { parent_slope(s) } else { 1.0 };
        *d = ((next.exp2() * share / slope) as f32).min(MAX_DETAIL);
        previous = next;
    }
    table.method = DeriveMode::Fractal;
    table.note = if flat {
        format!(
            "fractal: H {hurst:.3} over {} octaves; scale-invariant detail {finest:.3} held, \
             raised where the smooth parent is less steep than the terrain",
            octaves.len()
        )
    } else {
        format!(
            "fractal: H {hurst:.3} over {} octaves; detail {finest:.3} at the finest level, \
             continued along log2(detail) = {:.3} {:+.3} k {:+.3} k^2 (octave k, negative finer)",
            octaves.len(),
            curve[0],
            curve[1],
            curve[2]
        )
    };
    table
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Vec<f32> {
        (0..width * height)
            .map(|k| f(k % width, k / width))
            .collect()
    }

    #[test]
    fn a_flat_world_falls_back_to_plain_bicubic() {
        // A tilted plane: Catmull-Rom predicts it exactly.
        let heights = field(257, 257, |x, y| 100.0 + 0.5 * x as f32 + 0.25 * y as f32);
        let table = calibrate(
            &HeightField {
                width: 257,
                height: 257,
                cell_m: (10.0, 10.0),
                heights: &heights,
            },
            6,
            1,
        );
        assert_eq!(table.method, DeriveMode::Bicubic);
        assert!(table.note.starts_with("flat"), "{}", table.note);
        assert_eq!(table.detail, vec![0.0; 6]);
    }

    #[test]
    fn too_few_levels_fall_back_to_plain_bicubic() {
        let heights = field(40, 40, |x, y| ((x * 7 + y * 13) % 11) as f32);
        let table = calibrate(
            &HeightField {
                width: 40,
                height: 40,
                cell_m: (10.0, 10.0),
                heights: &heights,
            },
            3,
            1,
        );
        assert_eq!(table.method, DeriveMode::Bicubic);
        assert!(table.note.starts_with("too few levels"), "{}", table.note);
        assert_eq!(table.detail, vec![0.0; 3]);
    }

    #[test]
    fn the_quadratic_fit_is_exact_on_a_parabola() {
        let points: Vec<(f64, f64)> = (0..5)
            .map(|k| {
                let x = f64::from(k);
                (x, 1.5 - 0.25 * x + 0.125 * x * x)
            })
            .collect();
        let c = fit_quadratic(&points);
        for (got, want) in c.iter().zip([1.5, -0.25, 0.125]) {
            assert!((got - want).abs() < 1e-9, "{c:?}");
        }
    }

    #[test]
    fn params_follow_the_manifest_table_or_keep_the_legacy_amplitude() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("worlds")
            .join("santa-cruz")
            .join("world.toml");
        let mut manifest = Manifest::from_path(&path).unwrap();
        manifest.derive = None;
        assert_eq!(
            DeriveParams::for_manifest(&manifest),
            DeriveParams::default()
        );
        let first = manifest.pyramid.stored_levels;
        let levels = usize::from(manifest.pyramid.derived_levels);
        manifest.derive = Some(DeriveCalibration {
            method: DeriveMode::Fractal,
            note: String::new(),
            octaves: 4,
            hurst: 0.7,
            fit_rms_log2: 0.01,
            residual_rms_m: 1.0,
            detail: (0..levels).map(|k| 0.1 * (k + 1) as f32).collect(),
        });
        let p = DeriveParams::for_manifest(&manifest);
        for k in 0..levels {
            assert_eq!(p.detail_at(first + k as u8), 0.1 * (k + 1) as f32);
        }
        // Beyond the table: its last amplitude.
        assert_eq!(p.detail_at(first + levels as u8 + 3), 0.1 * levels as f32);
        assert_eq!(p.bicubic().detail, [0.0; MAX_LEVELS]);
    }
}
