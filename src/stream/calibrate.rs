//! The per-world calibration of derived levels: how much detail noise each level finer than
//! the stored data gets, fitted by the baker to the stored pyramid (the manifest's `[derive]`
//! table) and read back by [`crate::stream::DeriveParams::for_manifest`]. The fit measures how
//! the terrain's roughness changes from octave to octave of the stored data, with the same
//! Catmull-Rom step and detail noise as the derivation ([`crate::stream::derive_cpu`]), and
//! continues that trend below the data. GPU-free.

use crate::stream::derive_cpu::{WEIGHTS, detail_noise};
use crate::world::{DeriveCalibration, DeriveMode, MAX_DETAIL};

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
    /// Detail amplitude (child cells per unit of slope) for which the prediction plus the
    /// runtime's detail is as rough as the truth (the same spread of the Laplacian); 0 where
    /// Catmull-Rom alone is as rough.
    pub detail: f32,
    /// Roughness of the Catmull-Rom prediction alone, relative to the octave's own.
    pub bicubic_roughness: f64,
}

/// Octaves [`calibrate`] measures at most, finest first.
pub const FIT_OCTAVES: u32 = 4;
/// Fewest octaves [`calibrate`] fits a line to.
pub const MIN_FIT_OCTAVES: usize = 3;
/// A finest-octave residual below this is a flat world, metres.
pub const FLAT_RESIDUAL_M: f64 = 0.01;
/// Largest RMS deviation (log2) of the residuals from the fitted line that is still a fit.
pub const MAX_FIT_RMS_LOG2: f64 = 0.5;
/// Largest growth (log2) of the measured amplitude per octave coarser (a line weighted by each
/// octave's samples) on terrain taken as scale-invariant: fractional Brownian surfaces of H 0.3
/// to 0.8 measure 0.00 to 0.18 at factors 4 and 8 of `verdant eval derive`, the SRTM DEMs and
/// their crops 0.32 to 0.69.
pub const SCALE_INVARIANT_TREND_LOG2: f64 = 0.25;
/// Least fall (log2) of the amplitude per octave finer, below the data, on terrain that is not
/// scale-invariant. Such terrain smooths out toward its finest scales, and faster the finer
/// (on the SRTM DEMs the Hurst exponent rises by about 0.2 an octave finer, and the amplitude
/// that a level three steps below 200 m data needs falls by 0.6 to 0.9 an octave on the way
/// down to 25 m), which coarse octaves under-state: the finest measured fall is continued, and
/// at least this.
pub const MIN_DECAY_LOG2: f64 = 0.7;
/// Fewest octaves [`calibrate`] calibrates from the prior with (where fewer than
/// [`MIN_FIT_OCTAVES`] are measurable): two, for a Hurst exponent to check and the finest
/// octave's amplitude to compare with the prior's.
pub const MIN_PRIOR_OCTAVES: usize = 2;
/// Cell size of the project's DEMs, at which the prior's amplitudes were measured, metres: the
/// mean of the SRTM tile N37W123's 24.585 m east-west and 30.888 m north-south.
pub const PRIOR_CELL_M: f64 = 27.74;
/// The prior's amplitude (log2) for a level of [`PRIOR_CELL_M`] cells one step below its data
/// (2^-2.39 = 0.19). Measured as the roughness-matching amplitude ([`detail_at_depth`]) of the
/// project's DEMs at their own resolution: `santa_cruz_1024.png`,
/// `tests/data/east_bay_768.png` and two 1024 x 1024 windows of land of `sf_bay_3601.png`
/// (rows 0-1023 and 2200-3223 of columns 2400-3423), -2.52 to -2.35 at depth 1. The line
/// through their depths 1 to 4 (-2.39 at depth 1, slope [`PRIOR_GROWTH_LOG2`]) is within
/// 0.13 log2 of every measurement.
pub const PRIOR_DETAIL_LOG2: f64 = -2.39;
/// Growth (log2) of the prior's amplitude per step deeper below the data, at the same cell:
/// the slope of that line (the four DEMs measure -2.41, -2.01, -1.72 and -1.36 on average at
/// depths 1 to 4).
pub const PRIOR_GROWTH_LOG2: f64 = 0.34;
/// Fall (log2) of the prior's amplitude per octave finer level: the slope of the same DEMs'
/// amplitudes against log2 of the level's cell, at depths 1 to 4, on the DEMs and their
/// subsamples by 2, 4 and 8 (16 slopes of 0.57 to 0.99, mean 0.71); below [`PRIOR_CELL_M`],
/// where nothing measures it, continued as the fit's least fall [`MIN_DECAY_LOG2`] is.
pub const PRIOR_FALL_LOG2: f64 = 0.7;
/// Largest distance (log2) of the finest octave's measured amplitude from the prior's at its
/// cell for which the prior describes the terrain: 74 crops of 400 x 400 samples of the same
/// DEMs (every 156 samples, at most 2% sea) subsampled by 4 and 8 measure -0.52 to +0.23; the
/// DEMs and their subsamples by 2, 4 and 8, -0.35 to +0.04.
pub const PRIOR_TOLERANCE_LOG2: f64 = 1.0;
/// Smallest grid a measured octave's parent may be, samples a side.
const MIN_OCTAVE_SAMPLES: usize = 12;
/// Samples kept clear of the grid's edges in the statistics (clamping flattens them).
const STATS_MARGIN: usize = 4;
/// Key of the detail noise that the calibration measures with (any level key would do: the
/// noise's statistics do not depend on it).
const CALIBRATION_NOISE: u32 = 0xca11;

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

    fn child(&self, data: Vec<f32>) -> Level {
        Level {
            width: 2 * self.width - 1,
            height: 2 * self.height - 1,
            cell: (self.cell.0 / 2.0, self.cell.1 / 2.0),
            data,
        }
    }

    /// Catmull-Rom 2x upsampling.
    fn upsample(&self) -> Level {
        let (w, h) = (2 * self.width - 1, 2 * self.height - 1);
        let mut data = vec![0.0f32; w * h];
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
                data[j * w + i] =
                    ((wy[0] * rows[0] + wy[1] * rows[1]) + wy[2] * rows[2]) + wy[3] * rows[3];
            }
        }
        self.child(data)
    }

    /// The runtime's detail at amplitude 1 on a child of this level: [`detail_noise`] times
    /// the child cell times this level's slope (capped at 1.5), on the new samples only.
    fn detail(&self, seed: u32) -> Level {
        let (w, h) = (2 * self.width - 1, 2 * self.height - 1);
        let cell_child = (0.25 * (self.cell.0 + self.cell.1)) as f32;
        let mut data = vec![0.0f32; w * h];
        for j in 0..h {
            for i in 0..w {
                if (i | j) & 1 == 0 {
                    continue;
                }
                let (ix, iy) = ((i >> 1) as i64, (j >> 1) as i64);
                let gx = f64::from(self.at(ix + 1, iy) - self.at(ix - 1, iy)) / (2.0 * self.cell.0);
                let gy = f64::from(self.at(ix, iy + 1) - self.at(ix, iy - 1)) / (2.0 * self.cell.1);
                let slope = (gx * gx + gy * gy).sqrt().min(1.5) as f32;
                let n = detail_noise(i as i32, j as i32, CALIBRATION_NOISE, seed);
                data[j * w + i] = n * cell_child * slope;
            }
        }
        self.child(data)
    }

    fn laplacian(&self, x: usize, y: usize) -> f64 {
        let g = |x: usize, y: usize| f64::from(self.data[y * self.width + x]);
        let c = g(x, y);
        (g(x + 1, y) + g(x - 1, y) - 2.0 * c) / (self.cell.0 * self.cell.0)
            + (g(x, y + 1) + g(x, y - 1) - 2.0 * c) / (self.cell.1 * self.cell.1)
    }

    /// Variance of the Laplacian away from the edges.
    fn laplacian_variance(&self) -> f64 {
        let (mut sum, mut sum2, mut count) = (0.0f64, 0.0f64, 0.0f64);
        for y in STATS_MARGIN..self.height - STATS_MARGIN {
            for x in STATS_MARGIN..self.width - STATS_MARGIN {
                let l = self.laplacian(x, y);
                sum += l;
                sum2 += l * l;
                count += 1.0;
            }
        }
        let mean = sum / count.max(1.0);
        (sum2 / count.max(1.0) - mean * mean).max(0.0)
    }
}

/// How `truth` compares with its derivation from `parent` (the smooth surface one level
/// coarser): the RMS of `truth` minus the Catmull-Rom upsampling at the samples it adds, the
/// detail amplitude for which the upsampling plus the runtime's detail is as rough as `truth`
/// (the spread of the Laplacian, the eval's roughness; 0 where the upsampling alone is as
/// rough), and the upsampling's own roughness relative to `truth`'s.
fn match_roughness(truth: &Level, parent: &Level, seed: u32) -> (f64, f32, f64) {
    let smooth = parent.upsample();
    let noise = parent.detail(seed);
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
    let var_t = truth.laplacian_variance();
    let var_s = smooth.laplacian_variance();
    let var_n = noise.laplacian_variance();
    let detail = if var_n > 0.0 {
        ((var_t - var_s).max(0.0) / var_n).sqrt() as f32
    } else {
        0.0
    };
    let roughness = (var_s / var_t.max(1e-30)).sqrt();
    ((se / n_new.max(1) as f64).sqrt(), detail, roughness)
}

/// Whether `field`'s octave `octave` is at least [`MIN_OCTAVE_SAMPLES`] a side.
fn octave_fits(field: &HeightField<'_>, octave: u32) -> bool {
    let step = 1usize << octave;
    (field.width - 1) / step + 1 >= MIN_OCTAVE_SAMPLES
        && (field.height - 1) / step + 1 >= MIN_OCTAVE_SAMPLES
}

/// The samples of `len` that `2^octaves` divides into whole cells.
fn crop(len: usize, octaves: u32) -> usize {
    ((len - 1) >> octaves << octaves) + 1
}

/// Measures up to `octaves` octaves of `field` (see [`OctaveFit`]), finest first; fewer where
/// the coarsest parent would be smaller than 12 samples a side.
pub fn measure_octaves(field: &HeightField<'_>, octaves: u32, seed: u32) -> Vec<OctaveFit> {
    let n = (0..octaves)
        .take_while(|&k| octave_fits(field, k + 1))
        .count() as u32;
    if n == 0 {
        return Vec::new();
    }
    // Crop so that every octave's grid is exactly twice its parent's.
    let (w, h) = (crop(field.width, n), crop(field.height, n));
    let truth: Vec<Level> = (0..=n).map(|k| Level::subsample(field, k, w, h)).collect();
    (0..n)
        .map(|k| {
            let (residual_rms_m, detail, bicubic_roughness) =
                match_roughness(&truth[k as usize], &truth[k as usize + 1], seed);
            OctaveFit {
                octave: k,
                residual_rms_m,
                detail,
                bicubic_roughness,
            }
        })
        .collect()
}

/// The detail amplitude a level `depth` Catmull-Rom steps below `field` would need, measured
/// `depth` octaves up: `field` itself derived from its octave `depth` by `depth` steps, the
/// detail added at the last one only (as the runtime derives levels). `None` where that octave
/// is smaller than 12 samples a side.
pub fn detail_at_depth(field: &HeightField<'_>, depth: u32, seed: u32) -> Option<f32> {
    if depth == 0 || !octave_fits(field, depth) {
        return None;
    }
    let (w, h) = (crop(field.width, depth), crop(field.height, depth));
    let truth = Level::subsample(field, 0, w, h);
    let mut parent = Level::subsample(field, depth, w, h);
    for _ in 1..depth {
        parent = parent.upsample();
    }
    Some(match_roughness(&truth, &parent, seed).1)
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

/// Slope of the weighted least-squares line through `(x, y, weight)` points.
fn fit_line_weighted(points: &[(f64, f64, f64)]) -> f64 {
    let total: f64 = points.iter().map(|p| p.2).sum();
    let mx = points.iter().map(|p| p.0 * p.2).sum::<f64>() / total;
    let my = points.iter().map(|p| p.1 * p.2).sum::<f64>() / total;
    let sxx: f64 = points.iter().map(|p| p.2 * (p.0 - mx) * (p.0 - mx)).sum();
    let sxy: f64 = points.iter().map(|p| p.2 * (p.0 - mx) * (p.1 - my)).sum();
    if sxx > 0.0 { sxy / sxx } else { 0.0 }
}

/// The prior's amplitude (log2) for a level `depth` steps below its data whose cells are
/// `cell_m` (metres): [`PRIOR_DETAIL_LOG2`], growing by [`PRIOR_GROWTH_LOG2`] a step deeper,
/// and falling by [`PRIOR_FALL_LOG2`] an octave finer than [`PRIOR_CELL_M`] (rising an octave
/// coarser).
pub fn prior_detail_log2(depth: u32, cell_m: f64) -> f64 {
    PRIOR_DETAIL_LOG2 + PRIOR_GROWTH_LOG2 * (f64::from(depth) - 1.0)
        - PRIOR_FALL_LOG2 * (PRIOR_CELL_M / cell_m).log2()
}

/// [`calibrate`] where fewer than [`MIN_FIT_OCTAVES`] octaves are measurable (at least
/// [`MIN_PRIOR_OCTAVES`], not flat): the amplitudes come from the prior measured on the
/// project's DEMs ([`prior_detail_log2`] at each derived level's cell), which the grid checks.
/// The grid's own amplitudes are not used: on 400 x 400 crops of those DEMs subsampled by 8
/// (50 samples a side, two octaves), what they measure at 200 to 250 m does not predict what
/// a level three steps finer needs (correlations -0.09 to -0.06 over 74 crops), while that
/// need varies little (0.08 log2 standard deviation). Falls back to plain bicubic where the
/// octaves' `H` is outside 0..=1.5, where Catmull-Rom alone is as rough as the finest octave,
/// or where the finest octave's amplitude is more than [`PRIOR_TOLERANCE_LOG2`] from the
/// prior's at its cell (terrain unlike the prior's).
fn calibrate_from_prior(
    field: &HeightField<'_>,
    octaves: &[OctaveFit],
    mut table: DeriveCalibration,
) -> DeriveCalibration {
    let n = octaves.len();
    let points: Vec<(f64, f64)> = octaves
        .iter()
        .map(|o| (f64::from(o.octave), o.residual_rms_m.max(1e-9).log2()))
        .collect();
    let (hurst, _, fit_rms) = fit_line(&points);
    table.hurst = hurst;
    table.fit_rms_log2 = fit_rms;
    let too_few = format!("{n} octaves measurable, {MIN_FIT_OCTAVES} needed for the fit");
    if !(0.0..=1.5).contains(&hurst) {
        table.note = format!(
            "poor fit: {too_few}, and H {hurst:.3} over them is outside 0..1.5; plain bicubic"
        );
        return table;
    }
    if octaves[0].detail <= 0.0 {
        table.note = format!(
            "{too_few}; H {hurst:.3}, but Catmull-Rom alone is as rough as the data; plain \
             bicubic"
        );
        return table;
    }
    let cell = 0.5 * (field.cell_m.0 + field.cell_m.1);
    let finest = f64::from(octaves[0].detail);
    let expected = prior_detail_log2(1, cell).exp2();
    if (finest.log2() - expected.log2()).abs() > PRIOR_TOLERANCE_LOG2 {
        table.note = format!(
            "unlike the prior's terrain: {too_few}; the finest octave needs amplitude \
             {finest:.3}, the prior {expected:.3} at {cell:.1} m cells (more than \
             {PRIOR_TOLERANCE_LOG2} log2 apart); plain bicubic"
        );
        return table;
    }
    for (s, d) in table.detail.iter_mut().enumerate() {
        let depth = s as u32 + 1;
        let level_cell = cell / f64::from(depth).exp2();
        *d = (prior_detail_log2(depth, level_cell).exp2() as f32).min(MAX_DETAIL);
    }
    table.decay_log2 = PRIOR_FALL_LOG2;
    table.method = DeriveMode::Fractal;
    table.note = format!(
        "fractal from the prior: {too_few}; H {hurst:.3}, finest octave's amplitude {finest:.3} \
         (the prior's {expected:.3}); amplitudes from the prior measured on the project's SRTM \
         DEMs: {:.3} for a level of {PRIOR_CELL_M} m one step below its data, growing \
         {PRIOR_GROWTH_LOG2} log2 a step deeper and falling {PRIOR_FALL_LOG2} log2 an octave \
         finer",
        PRIOR_DETAIL_LOG2.exp2()
    );
    table
}

/// Fits the detail of `derived_levels` levels finer than `field` (a world's finest stored
/// level, or the coarse grid `verdant eval derive` is given) to the field itself.
///
/// 1. Each octave of the field (the field, every other sample, every fourth, ... up to
///    [`FIT_OCTAVES`]) is predicted by Catmull-Rom from the next coarser one. The RMS residual
///    grows by `2^H` an octave coarser on fractal terrain: a line through log2(residual)
///    against octave gives the Hurst exponent `H` and, by its deviation, how fractal the
///    terrain is.
/// 2. Per octave, the amplitude is measured for which the prediction plus the runtime's detail
///    is as rough as the octave (see [`OctaveFit::detail`]); the slope of log2(amplitude)
///    against octave is the terrain's trend of roughness with scale.
/// 3. Per derived level `d` steps below the data, the amplitude is measured one level of the
///    data `d` steps below its own octave `d` ([`detail_at_depth`]): the share of roughness
///    that `d` Catmull-Rom steps keep is in it. It is carried `d` octaves finer: held on
///    scale-invariant terrain (trend at most [`SCALE_INVARIANT_TREND_LOG2`]); otherwise
///    lowered by the finest measured fall per octave, at least [`MIN_DECAY_LOG2`]
///    (`decay_log2`).
///
/// With fewer than [`MIN_FIT_OCTAVES`] octaves (a grid of 45 to 88 samples a side: a DEM of
/// 400 samples subsampled by 8), the amplitudes come from a prior measured on the project's
/// DEMs instead, checked against the finest octave (`calibrate_from_prior`; `method` stays
/// `fractal`, `note` says so and states the prior).
///
/// Falls back to plain bicubic (`method = "bicubic"`, every amplitude 0, the reason in
/// `note`) with fewer than [`MIN_PRIOR_OCTAVES`] octaves, on flat terrain (finest residual
/// under [`FLAT_RESIDUAL_M`]), where the fit is poor (`H` outside 0..=1.5, deviation above
/// [`MAX_FIT_RMS_LOG2`]), where Catmull-Rom alone is as rough as the data, or, from the prior,
/// on terrain unlike the prior's.
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
        decay_log2: 0.0,
        detail: vec![0.0; usize::from(derived_levels)],
    };
    if octaves.len() < MIN_PRIOR_OCTAVES {
        table.note = format!(
            "too few levels: {} octaves measurable, {MIN_FIT_OCTAVES} needed for the fit and \
             {MIN_PRIOR_OCTAVES} for the prior; plain bicubic",
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
    if octaves.len() < MIN_FIT_OCTAVES {
        return calibrate_from_prior(field, &octaves, table);
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
    if octaves[0].detail <= 0.0 || details.len() < 2 {
        table.note =
            format!("H {hurst:.3}, but Catmull-Rom alone is as rough as the data; plain bicubic");
        return table;
    }
    // The trend, weighted by each octave's samples (the coarse octaves are few, and noisy).
    let weighted: Vec<(f64, f64, f64)> = details
        .iter()
        .map(|&(k, a)| (k, a, (-2.0 * k).exp2()))
        .collect();
    let trend = fit_line_weighted(&weighted);
    let scale_invariant = trend <= SCALE_INVARIANT_TREND_LOG2;
    let decay = if scale_invariant {
        0.0
    } else {
        let finest = if octaves[1].detail > 0.0 {
            f64::from(octaves[1].detail).log2() - f64::from(octaves[0].detail).log2()
        } else {
            trend
        };
        finest.max(MIN_DECAY_LOG2)
    };
    table.decay_log2 = decay;
    // Amplitude measured at each depth, log2; depths too deep to measure continue the last
    // two measured (growing by at most 1 an octave).
    let mut measured: Vec<f64> = Vec::new();
    let mut at_data: Vec<Option<f64>> = Vec::new();
    for depth in 1..=u32::from(derived_levels) {
        let value = match detail_at_depth(field, depth, seed) {
            Some(a) if a > 0.0 => Some(f64::from(a).log2()),
            Some(_) => None,
            None => Some(match measured.as_slice() {
                [.., a, b] => b + (b - a).clamp(0.0, 1.0),
                [b] => *b,
                [] => f64::from(octaves[0].detail).log2(),
            }),
        };
        if let Some(v) = value {
            measured.push(v);
        }
        at_data.push(value);
    }
    let deepest = (1..=u32::from(derived_levels))
        .take_while(|&d| octave_fits(field, d))
        .last()
        .unwrap_or(0);
    let continued = if deepest < u32::from(derived_levels) {
        format!(
            "; depths beyond {deepest} continue the amplitudes measured above them (the grid \
             is too small to measure them)"
        )
    } else {
        String::new()
    };
    for (s, (d, a)) in table.detail.iter_mut().zip(&at_data).enumerate() {
        *d = a.map_or(0.0, |a| {
            ((a - decay * (s as f64 + 1.0)).exp2() as f32).min(MAX_DETAIL)
        });
    }
    table.method = DeriveMode::Fractal;
    table.note = if scale_invariant {
        format!(
            "fractal: H {hurst:.3} over {} octaves; scale-invariant (amplitude trend \
             {trend:+.3} log2 an octave), each depth's amplitude held{continued}",
            octaves.len()
        )
    } else {
        format!(
            "fractal: H {hurst:.3} over {} octaves; smoother toward fine scales (amplitude \
             trend {trend:+.3} log2 an octave), each depth's amplitude carried finer falling \
             {decay:.3} log2 an octave{continued}",
            octaves.len()
        )
    };
    table
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::{hash4, unit};

    fn field(width: usize, height: usize, f: impl Fn(usize, usize) -> f32) -> Vec<f32> {
        (0..width * height)
            .map(|k| f(k % width, k / width))
            .collect()
    }

    /// [`calibrate`] on a square grid of `side` samples of 10 m, seed 1.
    fn calibrate_square(heights: &[f32], side: usize, derived_levels: u8) -> DeriveCalibration {
        let field = HeightField {
            width: side,
            height: side,
            cell_m: (10.0, 10.0),
            heights,
        };
        calibrate(&field, derived_levels, 1)
    }

    #[test]
    fn a_flat_world_falls_back_to_plain_bicubic() {
        // A tilted plane: Catmull-Rom predicts it exactly.
        let heights = field(257, 257, |x, y| 100.0 + 0.5 * x as f32 + 0.25 * y as f32);
        let table = calibrate_square(&heights, 257, 6);
        assert_eq!(table.method, DeriveMode::Bicubic);
        assert!(table.note.starts_with("flat"), "{}", table.note);
        assert_eq!(table.detail, vec![0.0; 6]);
    }

    #[test]
    fn too_few_levels_fall_back_to_plain_bicubic() {
        let heights = field(40, 40, |x, y| ((x * 7 + y * 13) % 11) as f32);
        let table = calibrate_square(&heights, 40, 3);
        assert_eq!(table.method, DeriveMode::Bicubic);
        assert!(table.note.starts_with("too few levels"), "{}", table.note);
        assert_eq!(table.detail, vec![0.0; 3]);
    }

    /// Value noise: hashed values at every `2^k`-th sample, bilinear between, summed over
    /// octaves with amplitude `2^(k * hurst)`.
    fn value_noise(width: usize, height: usize, hurst: f32, seed: u32) -> Vec<f32> {
        field(width, height, |x, y| {
            (0..6u32)
                .map(|k| {
                    let step = 1usize << k;
                    let (gx, gy) = (x / step, y / step);
                    let (fx, fy) = (
                        (x % step) as f32 / step as f32,
                        (y % step) as f32 / step as f32,
                    );
                    let v = |i: usize, j: usize| unit(hash4(i as u32, j as u32, k, seed));
                    let top = v(gx, gy) * (1.0 - fx) + v(gx + 1, gy) * fx;
                    let bottom = v(gx, gy + 1) * (1.0 - fx) + v(gx + 1, gy + 1) * fx;
                    (top * (1.0 - fy) + bottom * fy) * (k as f32 * hurst).exp2()
                })
                .sum()
        })
    }

    /// The default world's source DEM (1024 x 1024 samples of 24.585 m x 30.888 m), every
    /// `step`-th sample of its `side`-sample window at (`x0`, `y0`): heights and cell.
    fn santa_cruz(x0: usize, y0: usize, side: usize, step: usize) -> (Vec<f32>, (f64, f64)) {
        let dem = crate::world::Dem::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("worlds/santa-cruz/source/santa_cruz_1024.png"),
        )
        .unwrap();
        let w = dem.width as usize;
        let heights = (y0..y0 + side)
            .step_by(step)
            .flat_map(|y| (x0..x0 + side).step_by(step).map(move |x| (x, y)))
            .map(|(x, y)| dem.heights[y * w + x])
            .collect();
        let k = step as f64;
        (heights, (dem.cell_ew_m * k, dem.cell_ns_m * k))
    }

    fn square(heights: &[f32], cell_m: (f64, f64)) -> HeightField<'_> {
        let side = (heights.len() as f64).sqrt() as usize;
        assert_eq!(side * side, heights.len());
        HeightField {
            width: side,
            height: side,
            cell_m,
            heights,
        }
    }

    #[test]
    fn the_prior_matches_the_dem_it_was_measured_on() {
        // The roughness-matching amplitude of the default world's DEM at its own resolution,
        // one to four steps below it, against the prior's at that cell.
        let (heights, cell) = santa_cruz(0, 0, 1024, 1);
        let field = square(&heights, cell);
        for depth in 1..=4 {
            let measured = f64::from(detail_at_depth(&field, depth, 1).unwrap()).log2();
            let prior = prior_detail_log2(depth, 0.5 * (cell.0 + cell.1));
            assert!(
                (measured - prior).abs() < 0.15,
                "depth {depth}: measured {measured:.3}, prior {prior:.3} (log2)"
            );
        }
    }

    #[test]
    fn two_octaves_take_their_detail_from_the_prior() {
        // A 400-sample window of the default world's DEM, every 8th sample: 50 x 50 samples of
        // about 220 m, two octaves measurable.
        let (heights, cell) = santa_cruz(0, 0, 400, 8);
        let table = calibrate(&square(&heights, cell), 6, 1);
        assert_eq!(table.octaves, 2);
        assert_eq!(table.method, DeriveMode::Fractal, "{}", table.note);
        assert!(
            table.note.starts_with("fractal from the prior"),
            "{}",
            table.note
        );
        assert!(
            table.note.contains("2 octaves measurable"),
            "{}",
            table.note
        );
        assert!((0.0..=1.5).contains(&table.hurst), "{}", table.note);
        assert_eq!(table.decay_log2, PRIOR_FALL_LOG2);
        let mean_cell = 0.5 * (cell.0 + cell.1);
        for (s, &d) in table.detail.iter().enumerate() {
            let depth = s as u32 + 1;
            let want = prior_detail_log2(depth, mean_cell / f64::from(depth).exp2()).exp2();
            assert!((f64::from(d) - want).abs() < 1e-6, "{:?}", table.detail);
        }
        // Three steps below, at the DEM's own cell, the prior asks for about 0.3.
        assert!(
            (0.28..=0.33).contains(&table.detail[2]),
            "{:?}",
            table.detail
        );
        // The amplitudes fall level by level below the data.
        assert!(
            table.detail.windows(2).all(|w| w[1] < w[0]),
            "{:?}",
            table.detail
        );
    }

    #[test]
    fn the_same_terrain_at_finer_cells_is_unlike_the_prior() {
        // The 50 x 50 grid above, said to be of 25 m cells: its amplitudes are those of 220 m
        // SRTM, eight times what 25 m SRTM needs.
        let (heights, _) = santa_cruz(0, 0, 400, 8);
        let table = calibrate(&square(&heights, (25.0, 25.0)), 3, 1);
        assert_eq!(table.method, DeriveMode::Bicubic, "{}", table.note);
        assert!(table.note.starts_with("unlike the prior"), "{}", table.note);
        assert_eq!(table.detail, vec![0.0; 3]);
    }

    #[test]
    fn flat_and_featureless_small_grids_fall_back_to_plain_bicubic() {
        // Two octaves of a level grid and of a tilted plane: flat.
        for plane in [
            field(50, 50, |_, _| 100.0),
            field(50, 50, |x, y| 100.0 + 0.5 * x as f32 + 0.25 * y as f32),
        ] {
            let table = calibrate(&square(&plane, (200.0, 250.0)), 3, 1);
            assert_eq!(table.method, DeriveMode::Bicubic);
            assert!(table.note.starts_with("flat"), "{}", table.note);
            assert_eq!(table.detail, vec![0.0; 3]);
        }
        // Two octaves of white noise: its residual does not grow with scale (H below 0).
        let noise = field(50, 50, |x, y| 100.0 * unit(hash4(x as u32, y as u32, 3, 4)));
        let table = calibrate(&square(&noise, (200.0, 250.0)), 3, 1);
        assert_eq!(table.method, DeriveMode::Bicubic, "{}", table.note);
        assert!(table.note.starts_with("poor fit"), "{}", table.note);
        assert_eq!(table.detail, vec![0.0; 3]);
    }

    #[test]
    fn the_default_worlds_dem_is_fitted_without_the_prior() {
        // Four octaves: the fit, as baked into the default world.
        let (heights, cell) = santa_cruz(0, 0, 1024, 1);
        let table = calibrate(&square(&heights, cell), 1, 1);
        assert_eq!(table.octaves, 4);
        assert!(table.note.starts_with("fractal: H"), "{}", table.note);
    }

    #[test]
    fn levels_too_deep_to_measure_continue_the_measured_ones() {
        // 97 samples: depths 1 to 3 measurable (octave 3 has 13 samples), 4 to 6 not.
        let heights = value_noise(97, 97, 0.6, 9);
        let table = calibrate_square(&heights, 97, 6);
        assert_eq!(table.method, DeriveMode::Fractal, "{}", table.note);
        assert!(table.note.contains("depths beyond 3"), "{}", table.note);
        assert!(
            table.detail.iter().all(|d| d.is_finite() && *d > 0.0),
            "{:?}",
            table.detail
        );
    }
}
