//! `verdant eval derive`: how well each way of deriving finer terrain from coarser terrain
//! recovers real terrain, and what it costs.
//!
//! A DEM is kept as ground truth, point-sampled down by a factor K (a power of two), then
//! brought back up by repeated 2x derivation with each method, the way the runtime derives child
//! tiles level by level. Heights are compared with the truth (RMSE and maximum, metres), and so
//! are slopes: point by point (RMSE, degrees), on average (the bias of the mean slope, degrees:
//! smoothing flattens terrain, which moves where grass may grow) and as roughness (the spread of
//! the discrete Laplacian relative to the truth's).
//!
//! The calibrated method (the runtime's) fits its per-level detail to the coarse grid alone,
//! as the baker fits a world's to its stored pyramid ([`crate::stream::calibrate()`]): the truth
//! only scores it.

use std::time::Instant;

use crate::stream::derive_cpu::{WEIGHTS, detail_noise, hash4, unit};
use crate::stream::{DeriveParams, HeightField, calibrate};
use crate::world::{Dem, DeriveCalibration, LEGACY_DETAIL};

/// Most 2x steps an evaluation takes (factor 64).
pub const MAX_STEPS: usize = 6;

/// A way of deriving a finer grid from a coarser one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum DeriveMethod {
    /// The nearest coarse sample (the lower one at half positions).
    Nearest,
    /// Bilinear interpolation.
    Bilinear,
    /// Catmull-Rom (bicubic) interpolation.
    Bicubic,
    /// Catmull-Rom plus slope-scaled white detail noise of the given amplitude (child cells
    /// per unit slope) on every sample, each step upsampling the last one's result, detail
    /// included: the runtime's method before calibration, at 0.25.
    InheritedDetail(f32),
    /// Catmull-Rom of the smooth chain plus slope-scaled high-pass detail noise of the given
    /// amplitude between the coarser step's samples, not passed on to the next step (as the
    /// runtime derives child tiles now).
    BicubicDetail(f32),
    /// Catmull-Rom plus slope-scaled detail noise at a fitted amplitude per step (the first
    /// step first), as the runtime derives child tiles of a calibrated world.
    Calibrated([f32; MAX_STEPS]),
    /// A symmetric four-tap interpolation `[-w, 1/2 + w, 1/2 + w, -w]` along each axis
    /// (Catmull-Rom is `w` = 1/16, bilinear `w` = 0), `w` fitted to the coarse grid by
    /// [`fit_kernel`]: a predictor of the mean as cheap as Catmull-Rom.
    Kernel(f32),
}

impl DeriveMethod {
    /// Short name for tables and charts.
    pub fn name(&self) -> String {
        match self {
            Self::Nearest => "nearest".into(),
            Self::Bilinear => "bilinear".into(),
            Self::Bicubic => "bicubic".into(),
            Self::InheritedDetail(a) => format!("inherited detail {a}"),
            Self::BicubicDetail(a) => format!("bicubic+detail {a}"),
            Self::Calibrated(_) => "calibrated".into(),
            Self::Kernel(w) => format!("fitted kernel {w:.3}"),
        }
    }
}

/// A height grid in index space with its (possibly non-square) spacing.
#[derive(Clone, Debug)]
pub struct Grid {
    /// Samples per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Spacing along a row and between rows, metres.
    pub cell: (f64, f64),
    /// Heights, row-major.
    pub data: Vec<f32>,
}

impl Grid {
    fn at(&self, x: i64, y: i64) -> f32 {
        let x = x.clamp(0, self.width as i64 - 1) as usize;
        let y = y.clamp(0, self.height as i64 - 1) as usize;
        self.data[y * self.width + x]
    }

    /// The separable four-tap interpolation with weights `wx` along a row and `wy` across
    /// rows over the samples `ix - 1 ..= ix + 2`, `iy - 1 ..= iy + 2`.
    fn four_tap(&self, ix: i64, iy: i64, wx: [f32; 4], wy: [f32; 4]) -> f32 {
        let mut rows = [0.0f32; 4];
        for (dy, row) in rows.iter_mut().enumerate() {
            let y = iy - 1 + dy as i64;
            let p = |dx: i64| self.at(ix - 1 + dx, y);
            *row = ((wx[0] * p(0) + wx[1] * p(1)) + wx[2] * p(2)) + wx[3] * p(3);
        }
        ((wy[0] * rows[0] + wy[1] * rows[1]) + wy[2] * rows[2]) + wy[3] * rows[3]
    }

    /// Every `k`-th sample in both directions.
    pub fn downsample(&self, k: usize) -> Grid {
        let (w, h) = ((self.width - 1) / k + 1, (self.height - 1) / k + 1);
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                data.push(self.data[y * k * self.width + x * k]);
            }
        }
        Grid {
            width: w,
            height: h,
            cell: (self.cell.0 * k as f64, self.cell.1 * k as f64),
            data,
        }
    }
}

/// Derives `coarse` up by `steps` 2x steps with `method`, as the runtime derives levels.
pub fn derive_steps(coarse: &Grid, method: DeriveMethod, steps: u32, seed: u32) -> Grid {
    let amplitude = |step: u32| match method {
        DeriveMethod::BicubicDetail(a) => Some(a),
        DeriveMethod::Calibrated(a) => Some(a[(step as usize).min(MAX_STEPS - 1)]),
        _ => None,
    };
    if amplitude(0).is_none() {
        let mut fine = coarse.clone();
        for s in 0..steps {
            fine = upsample2x(&fine, method, s + 1, seed);
        }
        return fine;
    }
    // The smooth chain is plain Catmull-Rom; each step adds its own detail to it.
    let mut smooth = coarse.clone();
    let mut fine = coarse.clone();
    for s in 0..steps {
        let next = upsample2x(&smooth, DeriveMethod::Bicubic, s + 1, seed);
        let a = amplitude(s).unwrap_or(0.0);
        let c = (0.5 * (next.cell.0 + next.cell.1)) as f32;
        let mut data = next.data.clone();
        for j in 0..next.height {
            for i in 0..next.width {
                if (i | j) & 1 == 0 {
                    continue;
                }
                let (ix, iy) = ((i >> 1) as i64, (j >> 1) as i64);
                let gx =
                    (smooth.at(ix + 1, iy) - smooth.at(ix - 1, iy)) as f64 / (2.0 * smooth.cell.0);
                let gy =
                    (smooth.at(ix, iy + 1) - smooth.at(ix, iy - 1)) as f64 / (2.0 * smooth.cell.1);
                let slope = (gx * gx + gy * gy).sqrt().min(1.5) as f32;
                data[j * next.width + i] +=
                    detail_noise(i as i32, j as i32, s + 1, seed) * (a * c * slope);
            }
        }
        fine = Grid {
            data,
            ..next.clone()
        };
        smooth = next;
    }
    fine
}

/// One 2x derivation of `coarse` by `method` (for the detail methods: detail on every sample,
/// as [`DeriveMethod::InheritedDetail`]). `level` and `seed` key the detail noise.
pub fn upsample2x(coarse: &Grid, method: DeriveMethod, level: u32, seed: u32) -> Grid {
    let (w, h) = (coarse.width * 2 - 1, coarse.height * 2 - 1);
    let cell = (coarse.cell.0 / 2.0, coarse.cell.1 / 2.0);
    let mut data = vec![0.0f32; w * h];
    for j in 0..h {
        for i in 0..w {
            let (ix, fx) = ((i >> 1) as i64, i & 1);
            let (iy, fy) = ((j >> 1) as i64, j & 1);
            let v = match method {
                DeriveMethod::Nearest => coarse.at(ix, iy),
                DeriveMethod::Kernel(k) => {
                    let weights = [WEIGHTS[0], [-k, 0.5 + k, 0.5 + k, -k]];
                    coarse.four_tap(ix, iy, weights[fx], weights[fy])
                }
                DeriveMethod::Bilinear => {
                    let a = coarse.at(ix, iy) * (1.0 - 0.5 * fx as f32)
                        + coarse.at(ix + 1, iy) * 0.5 * fx as f32;
                    let b = coarse.at(ix, iy + 1) * (1.0 - 0.5 * fx as f32)
                        + coarse.at(ix + 1, iy + 1) * 0.5 * fx as f32;
                    a * (1.0 - 0.5 * fy as f32) + b * 0.5 * fy as f32
                }
                DeriveMethod::Bicubic
                | DeriveMethod::InheritedDetail(_)
                | DeriveMethod::BicubicDetail(_)
                | DeriveMethod::Calibrated(_) => {
                    let mut v = coarse.four_tap(ix, iy, WEIGHTS[fx], WEIGHTS[fy]);
                    let amplitude = match method {
                        DeriveMethod::InheritedDetail(a) | DeriveMethod::BicubicDetail(a) => {
                            Some(a)
                        }
                        DeriveMethod::Calibrated(a) => {
                            Some(a[(level as usize).clamp(1, MAX_STEPS) - 1])
                        }
                        _ => None,
                    };
                    if let Some(amplitude) = amplitude {
                        let gx = (coarse.at(ix + 1, iy) - coarse.at(ix - 1, iy)) as f64
                            / (2.0 * coarse.cell.0);
                        let gy = (coarse.at(ix, iy + 1) - coarse.at(ix, iy - 1)) as f64
                            / (2.0 * coarse.cell.1);
                        let slope = (gx * gx + gy * gy).sqrt().min(1.5) as f32;
                        let c = (0.5 * (cell.0 + cell.1)) as f32;
                        v += unit(hash4(i as u32, j as u32, level, seed)) * (amplitude * c * slope);
                    }
                    v
                }
            };
            data[j * w + i] = v;
        }
    }
    Grid {
        width: w,
        height: h,
        cell,
        data,
    }
}

/// What one method achieved.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MethodResult {
    /// The method's name.
    pub method: String,
    /// Downsampling factor.
    pub factor: usize,
    /// Height RMSE, metres.
    pub rmse_m: f64,
    /// Largest height error, metres.
    pub max_m: f64,
    /// RMSE of the slope angle, degrees.
    pub slope_rmse_deg: f64,
    /// Mean slope of the result minus the truth's, degrees (negative: flattened).
    pub slope_bias_deg: f64,
    /// Spread of the Laplacian relative to the truth's (1 = as rough as the truth); NaN where
    /// the truth has no roughness to compare with (a spread under [`MIN_ROUGHNESS_M`]: a
    /// plane, a constant).
    pub roughness_ratio: f64,
    /// CPU time per derived 133 x 133 tile, milliseconds (median of repeats).
    pub ms_per_tile: f64,
    /// Detail amplitude of each step, first step first (empty: no detail).
    pub detail: Vec<f32>,
    /// For the calibrated method, what was fitted to the coarse grid.
    pub fit: Option<DeriveCalibration>,
}

impl MethodResult {
    /// The fitted or fixed parameters in one short line (empty for plain interpolations).
    pub fn parameters(&self) -> String {
        let detail = self
            .detail
            .iter()
            .map(|d| format!("{d:.3}"))
            .collect::<Vec<_>>()
            .join("/");
        match &self.fit {
            Some(f) => format!(
                "{:?} H={:.3} dev={:.3} octaves={} decay={:.3} detail={detail}",
                f.method, f.hurst, f.fit_rms_log2, f.octaves, f.decay_log2
            )
            .to_lowercase(),
            None if detail.is_empty() => String::new(),
            None => format!("detail={detail}"),
        }
    }
}

/// The DEM as a grid, north row first.
pub fn dem_grid(dem: &Dem) -> Grid {
    Grid {
        width: dem.width as usize,
        height: dem.height as usize,
        cell: (dem.cell_ew_m, dem.cell_ns_m),
        data: dem.heights.clone(),
    }
}

fn slope_deg(g: &Grid, x: i64, y: i64) -> f64 {
    let gx = (g.at(x + 1, y) - g.at(x - 1, y)) as f64 / (2.0 * g.cell.0);
    let gy = (g.at(x, y + 1) - g.at(x, y - 1)) as f64 / (2.0 * g.cell.1);
    (gx * gx + gy * gy).sqrt().atan().to_degrees()
}

fn laplacian(g: &Grid, x: i64, y: i64) -> f64 {
    let c = f64::from(g.at(x, y));
    (f64::from(g.at(x + 1, y)) + f64::from(g.at(x - 1, y)) - 2.0 * c) / (g.cell.0 * g.cell.0)
        + (f64::from(g.at(x, y + 1)) + f64::from(g.at(x, y - 1)) - 2.0 * c) / (g.cell.1 * g.cell.1)
}

/// Evaluates `method` at downsampling `factor` (a power of two) against `truth`.
pub fn evaluate(truth: &Grid, factor: usize, method: DeriveMethod, repeats: usize) -> MethodResult {
    assert!(
        factor.is_power_of_two() && factor >= 2,
        "the factor must be a power of two"
    );
    let coarse = truth.downsample(factor);
    let steps = factor.trailing_zeros();
    let params = DeriveParams::default();
    let mut times = Vec::new();
    let mut fine = coarse.clone();
    for _ in 0..repeats.max(1) {
        let start = Instant::now();
        fine = derive_steps(&coarse, method, steps, params.seed);
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let ms = crate::tools::metrics::Summary::of(&times).median;
    let tiles = (fine.width * fine.height) as f64 / (133.0 * 133.0);

    // Compare away from the edges, where clamping would favour no method.
    let margin = 2 * factor as i64;
    let (mut se, mut max, mut slope_se, mut slope_sum_f, mut slope_sum_t, mut n) =
        (0.0, 0.0f64, 0.0, 0.0, 0.0, 0.0);
    let (mut lap_f, mut lap_t) = (Vec::new(), Vec::new());
    for y in margin..fine.height as i64 - margin {
        for x in margin..fine.width as i64 - margin {
            let e = f64::from(fine.at(x, y)) - f64::from(truth.at(x, y));
            se += e * e;
            max = max.max(e.abs());
            let (sf, st) = (slope_deg(&fine, x, y), slope_deg(truth, x, y));
            slope_se += (sf - st) * (sf - st);
            slope_sum_f += sf;
            slope_sum_t += st;
            lap_f.push(laplacian(&fine, x, y));
            lap_t.push(laplacian(truth, x, y));
            n += 1.0;
        }
    }
    let spread = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
        (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let detail = match method {
        DeriveMethod::InheritedDetail(a) | DeriveMethod::BicubicDetail(a) => {
            vec![a; steps as usize]
        }
        DeriveMethod::Calibrated(a) => a[..(steps as usize).min(MAX_STEPS)].to_vec(),
        _ => Vec::new(),
    };
    MethodResult {
        method: method.name(),
        factor,
        rmse_m: (se / n).sqrt(),
        max_m: max,
        slope_rmse_deg: (slope_se / n).sqrt(),
        slope_bias_deg: (slope_sum_f - slope_sum_t) / n,
        roughness_ratio: roughness_ratio(spread(&lap_f), spread(&lap_t)),
        ms_per_tile: ms / tiles,
        detail,
        fit: None,
    }
}

/// Fits the calibrated method to the coarse grid that `evaluate` derives from (`truth`
/// downsampled by `factor`): the amplitudes of the factor's steps, and the fit itself.
pub fn calibrate_coarse(truth: &Grid, factor: usize) -> (DeriveMethod, DeriveCalibration) {
    let coarse = truth.downsample(factor);
    let steps = (factor.trailing_zeros() as usize).min(MAX_STEPS);
    let fit = calibrate(
        &HeightField {
            width: coarse.width,
            height: coarse.height,
            cell_m: coarse.cell,
            heights: &coarse.data,
        },
        steps as u8,
        DeriveParams::default().seed,
    );
    let mut amplitudes = [0.0f32; MAX_STEPS];
    amplitudes[..steps].copy_from_slice(&fit.detail[..steps]);
    (DeriveMethod::Calibrated(amplitudes), fit)
}

/// Evaluates the calibrated method: fitted to the coarse grid alone, then scored against the
/// truth like every other method.
pub fn evaluate_calibrated(truth: &Grid, factor: usize, repeats: usize) -> MethodResult {
    let (method, fit) = calibrate_coarse(truth, factor);
    let mut r = evaluate(truth, factor, method, repeats);
    r.fit = Some(fit);
    r
}

/// Range [`fit_kernel`] searches for the kernel's outer weight.
pub const KERNEL_RANGE: (f32, f32) = (-0.05, 0.2);

/// RMS of `fine` minus its prediction from every other sample by [`DeriveMethod::Kernel`] at
/// `w`, at the samples the prediction adds, away from the edges.
pub fn kernel_residual(fine: &Grid, w: f32) -> f64 {
    let parent = fine.downsample(2);
    let predicted = upsample2x(&parent, DeriveMethod::Kernel(w), 1, 0);
    let margin = 4;
    let (mut se, mut n) = (0.0f64, 0usize);
    for y in margin..predicted.height.saturating_sub(margin) {
        for x in margin..predicted.width.saturating_sub(margin) {
            if (x | y) & 1 == 1 {
                let e = f64::from(predicted.data[y * predicted.width + x])
                    - f64::from(fine.data[y * fine.width + x]);
                se += e * e;
                n += 1;
            }
        }
    }
    (se / n.max(1) as f64).sqrt()
}

/// The outer weight `w` of [`DeriveMethod::Kernel`] that predicts `coarse` best from every
/// other sample of it (golden-section search over [`KERNEL_RANGE`]), as a baker could fit it
/// to a world's finest stored level.
pub fn fit_kernel(coarse: &Grid) -> f32 {
    let ratio = 0.5 * (5f32.sqrt() - 1.0);
    let (mut a, mut b) = KERNEL_RANGE;
    let mut c = b - ratio * (b - a);
    let mut d = a + ratio * (b - a);
    let (mut fc, mut fd) = (kernel_residual(coarse, c), kernel_residual(coarse, d));
    for _ in 0..30 {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - ratio * (b - a);
            fc = kernel_residual(coarse, c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + ratio * (b - a);
            fd = kernel_residual(coarse, d);
        }
    }
    0.5 * (a + b)
}

/// Evaluates [`DeriveMethod::Kernel`] with its weight fitted to the coarse grid alone.
pub fn evaluate_kernel(truth: &Grid, factor: usize, repeats: usize) -> MethodResult {
    let w = fit_kernel(&truth.downsample(factor));
    evaluate(truth, factor, DeriveMethod::Kernel(w), repeats)
}

/// The fixed methods `verdant eval derive` compares with the calibrated one: the three
/// interpolations and bicubic plus detail at a range of fixed amplitudes.
pub fn methods() -> Vec<DeriveMethod> {
    let mut m = vec![
        DeriveMethod::Nearest,
        DeriveMethod::Bilinear,
        DeriveMethod::Bicubic,
    ];
    m.push(legacy_method());
    m.extend([0.1, 0.25, 0.5, 1.0].map(DeriveMethod::BicubicDetail));
    m
}

/// The runtime's method before calibration: detail 0.25 on every sample, passed on from level
/// to level.
pub fn legacy_method() -> DeriveMethod {
    DeriveMethod::InheritedDetail(LEGACY_DETAIL)
}

/// The least spread of the truth's Laplacian (metres) against which a roughness ratio is
/// measured: a millimetre, below any DEM's quantisation; a smoother truth (a plane, whose
/// Laplacian is rounding noise) has no roughness to be a ratio of.
pub const MIN_ROUGHNESS_M: f64 = 1e-3;

fn roughness_ratio(result: f64, truth: f64) -> f64 {
    if truth >= MIN_ROUGHNESS_M {
        result / truth
    } else {
        f64::NAN
    }
}

/// Name of the runtime's method in a calibrated world (what charts and tables mark).
pub const RUNTIME_METHOD: &str = "calibrated";

/// Indices of the results on the Pareto front of all the measures at once: time per tile,
/// height RMSE, slope RMSE, |slope bias| and roughness error, lower being better in each.
pub fn joint_front(results: &[MethodResult]) -> Vec<usize> {
    let rows: Vec<Vec<f64>> = results
        .iter()
        .map(|r| {
            vec![
                r.ms_per_tile,
                r.rmse_m,
                r.slope_rmse_deg,
                r.slope_bias_deg.abs(),
                // Not measured (a truth without roughness): the same for every method.
                if r.roughness_ratio.is_nan() {
                    0.0
                } else {
                    (1.0 - r.roughness_ratio).abs()
                },
            ]
        })
        .collect();
    crate::tools::metrics::pareto_front_n(&rows)
}

/// A chart of [`write_results`]: its file, its y axis, and the measure it plots.
type ChartSpec = (&'static str, &'static str, fn(&MethodResult) -> f64);

/// The files [`write_results`] writes.
pub const FILES: [&str; 5] = [
    "derive.csv",
    "derive_height.png",
    "derive_slope.png",
    "derive_flattening.png",
    "derive_roughness.png",
];

/// Writes `derive.csv` and the charts `derive_height.png` (height RMSE), `derive_slope.png`
/// (slope RMSE), `derive_flattening.png` (slope bias) and `derive_roughness.png` against time
/// per tile ([`FILES`]) into the output folder `out`. With `interrupted` (an eval stopped
/// before its last method), the charts' titles say that they are partial.
pub fn write_results(
    results: &[MethodResult],
    dem_name: &str,
    out: &crate::tools::fly::OutDir,
    interrupted: bool,
) -> anyhow::Result<()> {
    let out = out.path();
    use std::fmt::Write as _;
    let chosen = RUNTIME_METHOD;
    let front = joint_front(results);
    let mut csv = String::from(
        "method,factor,rmse_m,max_m,slope_rmse_deg,slope_bias_deg,roughness_ratio,ms_per_tile,\
         on_joint_pareto_front,runtime_default,fit,hurst,fit_rms_log2,decay_log2,detail\n",
    );
    for (i, r) in results.iter().enumerate() {
        let fit = r.fit.as_ref();
        let _ = writeln!(
            csv,
            "{},{},{:.4},{:.4},{:.4},{:.4},{},{:.5},{},{},{},{},{},{},{}",
            r.method,
            r.factor,
            r.rmse_m,
            r.max_m,
            r.slope_rmse_deg,
            r.slope_bias_deg,
            // Empty where the truth has no roughness to be a ratio of.
            if r.roughness_ratio.is_nan() {
                String::new()
            } else {
                format!("{:.4}", r.roughness_ratio)
            },
            r.ms_per_tile,
            front.contains(&i),
            r.method == chosen,
            fit.map_or(String::new(), |f| format!("{:?}", f.method).to_lowercase()),
            fit.map_or(String::new(), |f| format!("{:.4}", f.hurst)),
            fit.map_or(String::new(), |f| format!("{:.4}", f.fit_rms_log2)),
            fit.map_or(String::new(), |f| format!("{:.4}", f.decay_log2)),
            r.detail
                .iter()
                .map(|d| format!("{d:.4}"))
                .collect::<Vec<_>>()
                .join(" "),
        );
    }
    crate::tools::fly::write_text(&out.join("derive.csv"), &csv)?;
    let factor = results.first().map_or(0, |r| r.factor);
    let charts: [ChartSpec; 4] = [
        ("derive_height.png", "height RMSE (m)", |r| r.rmse_m),
        ("derive_slope.png", "slope RMSE (degrees)", |r| {
            r.slope_rmse_deg
        }),
        (
            "derive_flattening.png",
            "|mean slope bias| (degrees)",
            |r| r.slope_bias_deg.abs(),
        ),
        ("derive_roughness.png", "roughness error |1 - ratio|", |r| {
            (1.0 - r.roughness_ratio).abs()
        }),
    ];
    for (file, y_label, value) in charts {
        // A measure with no value (roughness against a flat truth) gets no point, and says so.
        let measured = results.iter().any(|r| value(r).is_finite());
        let chart = crate::tools::metrics::Chart {
            title: crate::tools::stop::chart_title(
                format!(
                    "{dem_name}: derived from 1/{factor} resolution{}",
                    if measured {
                        ""
                    } else {
                        " (not measured: the truth has none)"
                    }
                ),
                interrupted,
            ),
            x_label: "CPU time per 133x133 tile (ms)".into(),
            y_label: y_label.into(),
            log_x: true,
            log_y: false,
            points: results
                .iter()
                .filter(|r| value(r).is_finite())
                .map(|r| crate::tools::metrics::ChartPoint {
                    label: match &r.fit {
                        Some(f) => format!("{} (H {:.2})", r.method, f.hurst),
                        None => r.method.clone(),
                    },
                    x: r.ms_per_tile,
                    y: value(r),
                    chosen: r.method == chosen,
                })
                .collect(),
        };
        chart.write_png(&out.join(file), 900, 600)?;
    }
    Ok(())
}

/// What [`run_derive_eval`] found: a result per method (the fixed ones, the fitted kernel, then
/// the calibrated runtime method last) and the names on their joint Pareto front.
pub struct DeriveEvalReport {
    /// One result per method, in the order they were run.
    pub results: Vec<MethodResult>,
    /// Names of the methods on the joint Pareto front ([`joint_front`]).
    pub front: Vec<String>,
    /// Whether the eval was stopped before its last method: `results` holds the methods run.
    pub interrupted: bool,
}

impl DeriveEvalReport {
    /// Whether the runtime's method ([`RUNTIME_METHOD`]) is on the joint front.
    pub fn runtime_on_front(&self) -> bool {
        self.front.iter().any(|n| n == RUNTIME_METHOD)
    }

    /// The calibrated method's fit to the coarse grid, when it ran.
    pub fn calibration(&self) -> Option<&DeriveCalibration> {
        self.results
            .last()
            .filter(|r| r.method == RUNTIME_METHOD)
            .and_then(|r| r.fit.as_ref())
    }
}

/// What the eval says of a DEM whose nodata samples were filled (from the heights around
/// them, as a bake fills them): the methods are scored against those invented heights too.
pub fn filled_note(dem: &Dem, path: &std::path::Path) -> Option<String> {
    if dem.nodata_filled == 0 {
        return None;
    }
    let total = u64::from(dem.width) * u64::from(dem.height);
    Some(format!(
        "{}: {} of its {total} samples ({:.1}%) are nodata, filled from the heights around them; \
         the methods are scored against the filled heights there too (a DEM without nodata \
         measures them against real ground alone)",
        path.display(),
        dem.nodata_filled,
        100.0 * dem.nodata_filled as f64 / total as f64
    ))
}

/// Samples a side a DEM needs for `eval derive --factor factor`: the comparison leaves out
/// `2 * factor` samples at each edge and keeps at least 8 a side between them.
pub fn min_side(factor: usize) -> usize {
    4 * factor + 8
}

/// Runs `eval derive` on the DEM at `dem_path` (read with `dem_options`: a cell size given in
/// place of the file's) downsampled by `factor` and writes its CSV and
/// charts into `out` ([`write_results`]). `progress` hears each method's name before it runs,
/// with the methods done and their total. Refuses a factor that is not a power of two from 2
/// to 64, an `out` where an output would replace the DEM, its sidecar or a file that is no
/// earlier run's output ([`crate::tools::fly::OutDir::create_for`]), a DEM too small for the
/// factor or with heights beyond a planet's surface, and results that are not finite (then
/// nothing is written). Stopped early (`stop`, Ctrl-C on the command line; tested between
/// methods), it writes the methods run so far, the report marked interrupted; stopped before
/// the first method's result, it writes nothing (and a folder it made is removed).
pub fn run_derive_eval(
    dem_path: &std::path::Path,
    dem_options: &crate::world::DemOptions,
    factor: usize,
    out: &std::path::Path,
    stop: &crate::tools::stop::Stop,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> anyhow::Result<DeriveEvalReport> {
    use anyhow::bail;
    if !(factor.is_power_of_two() && (2..=64).contains(&factor)) {
        bail!("--factor must be a power of two from 2 to 64, got {factor}");
    }
    let mut outputs = crate::tools::fly::Outputs::named(&FILES)
        .reading("the DEM this run reads (--dem)", dem_path);
    if let Some(sidecar) = crate::world::dem::sidecar_of(dem_path) {
        outputs = outputs.reading("the sidecar of the DEM this run reads (--dem)", &sidecar);
    }
    // Taken before the work: a run refused for its --out is refused at once.
    let out_dir = crate::tools::fly::OutDir::create_for(out, "eval derive", &outputs)?;
    let dem = Dem::load_with(dem_path, dem_options)?;
    // Heights no planet has (a wrong scale in a sidecar) are refused as the baker refuses them.
    crate::bake::check_dem_heights(&dem, dem_path)?;
    if let Some(note) = filled_note(&dem, dem_path) {
        log::warn!("{note}");
    }
    let side = dem.width.min(dem.height) as usize;
    let needed = min_side(factor);
    if side < needed {
        let fits = (1..=6)
            .map(|k| 1usize << k)
            .filter(|&f| min_side(f) <= side)
            .max();
        bail!(
            "{}: {}x{} samples is too small for --factor {factor}: the comparison leaves out \
             {} samples at each edge and needs at least {needed} samples a side ({})",
            dem_path.display(),
            dem.width,
            dem.height,
            2 * factor,
            match fits {
                Some(f) => format!("use --factor {f} or less"),
                None => "no factor fits this DEM".to_owned(),
            }
        );
    }
    let truth = &dem_grid(&dem);
    // The fixed methods, the fitted kernel, then the runtime's method.
    let mut runs: Vec<(String, Box<dyn Fn() -> MethodResult>)> = Vec::new();
    for m in methods() {
        runs.push((m.name(), Box::new(move || evaluate(truth, factor, m, 5))));
    }
    runs.push((
        "fitted kernel".to_owned(),
        Box::new(move || evaluate_kernel(truth, factor, 5)),
    ));
    runs.push((
        RUNTIME_METHOD.to_owned(),
        Box::new(move || evaluate_calibrated(truth, factor, 5)),
    ));
    let total = runs.len() as u64;
    let mut results = Vec::new();
    for (name, run) in &runs {
        if stop.requested() {
            break;
        }
        progress(name, results.len() as u64, total);
        results.push(run());
    }
    let interrupted = results.len() < runs.len();
    if !interrupted {
        progress(RUNTIME_METHOD, total, total);
    }
    if let Some(r) = results.iter().find(|r| {
        ![r.rmse_m, r.max_m, r.slope_rmse_deg, r.slope_bias_deg]
            .iter()
            .all(|v| v.is_finite())
    }) {
        bail!(
            "{}: method {} gave no finite error at --factor {factor}; nothing written",
            dem_path.display(),
            r.method
        );
    }
    let front = joint_front(&results)
        .into_iter()
        .map(|i| results[i].method.clone())
        .collect();
    if results.is_empty() {
        // Stopped before the first method's result: nothing written.
        return Ok(DeriveEvalReport {
            results,
            front,
            interrupted,
        });
    }
    let name = dem_path
        .file_stem()
        .map_or("DEM".into(), |s| s.to_string_lossy().into_owned());
    write_results(&results, &name, &out_dir, interrupted)?;
    out_dir.keep();
    Ok(DeriveEvalReport {
        results,
        front,
        interrupted,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dem_with_filled_nodata_is_noted_and_one_without_is_not() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("worlds/santa-cruz/source/santa_cruz_1024.png");
        let mut dem = Dem::load(&path).unwrap();
        assert_eq!(dem.nodata_filled, 0);
        assert_eq!(filled_note(&dem, &path), None);
        dem.nodata_filled = 104_858;
        let note = filled_note(&dem, &path).unwrap();
        assert!(note.contains("santa_cruz_1024.png"), "{note}");
        assert!(
            note.contains("104858 of its 1048576 samples (10.0%) are nodata"),
            "{note}"
        );
    }

    fn smooth_grid() -> Grid {
        let (w, h) = (65, 49);
        let data = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f32, (k / w) as f32);
                100.0 + 20.0 * (x * 0.15).sin() + 15.0 * (y * 0.11).cos()
            })
            .collect();
        Grid {
            width: w,
            height: h,
            cell: (10.0, 12.0),
            data,
        }
    }

    #[test]
    fn every_method_keeps_the_coarse_samples() {
        let g = smooth_grid().downsample(2);
        for m in [
            DeriveMethod::Nearest,
            DeriveMethod::Bilinear,
            DeriveMethod::Bicubic,
        ] {
            let f = upsample2x(&g, m, 1, 0);
            for y in 0..g.height {
                for x in 0..g.width {
                    assert_eq!(
                        f.data[(2 * y) * f.width + 2 * x],
                        g.data[y * g.width + x],
                        "{m:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_fitted_kernel_predicts_its_grid_at_least_as_well_as_catmull_rom_and_bilinear() {
        // Rough terrain: a smooth swell plus hashed bumps.
        let mut g = smooth_grid();
        for (k, v) in g.data.iter_mut().enumerate() {
            *v += 3.0 * unit(hash4(k as u32, 7, 1, 2));
        }
        let w = fit_kernel(&g);
        assert!((KERNEL_RANGE.0..=KERNEL_RANGE.1).contains(&w), "{w}");
        let fitted = kernel_residual(&g, w);
        for other in [0.0625, 0.0] {
            assert!(fitted <= kernel_residual(&g, other) + 1e-9, "{w}: {fitted}");
        }
        // Catmull-Rom is the kernel at 1/16.
        let parent = g.downsample(2);
        let (a, b) = (
            upsample2x(&parent, DeriveMethod::Kernel(0.0625), 1, 0),
            upsample2x(&parent, DeriveMethod::Bicubic, 1, 0),
        );
        assert_eq!(a.data, b.data);
    }

    #[test]
    fn calibrated_method_keeps_400_sample_dems_rough_at_bicubic_height_error() {
        // Three 400 x 400 windows of the default world's DEM: at factor 4 the coarse grid
        // (100 samples a side) has three octaves to fit; at factor 8 (50 a side) two, and the
        // amplitudes come from the prior.
        let dem = Dem::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("worlds/santa-cruz/source/santa_cruz_1024.png"),
        )
        .unwrap();
        let full = dem_grid(&dem);
        for (x0, y0) in [(0, 0), (624, 0), (624, 624)] {
            let side = 400;
            let truth = Grid {
                width: side,
                height: side,
                cell: full.cell,
                data: (y0..y0 + side)
                    .flat_map(|y| &full.data[y * full.width + x0..y * full.width + x0 + side])
                    .copied()
                    .collect(),
            };
            for factor in [4, 8] {
                let bicubic = evaluate(&truth, factor, DeriveMethod::Bicubic, 1);
                let r = evaluate_calibrated(&truth, factor, 1);
                let fit = r.fit.as_ref().unwrap();
                let at = format!("window ({x0}, {y0}) factor {factor}: {}", fit.note);
                assert!(
                    (0.8..=1.25).contains(&r.roughness_ratio),
                    "{at}: roughness {:.3} of the truth's",
                    r.roughness_ratio
                );
                assert!(
                    r.rmse_m <= 1.15 * bicubic.rmse_m,
                    "{at}: RMSE {:.3} m, bicubic {:.3} m",
                    r.rmse_m,
                    bicubic.rmse_m
                );
                if factor == 8 {
                    assert!(fit.note.starts_with("fractal from the prior"), "{at}");
                }
            }
        }
    }

    /// A plane has no roughness: no method's roughness is a ratio of it (it was 3e9 of the
    /// plane's rounding noise), and the front is drawn from the other measures.
    #[test]
    fn a_plane_has_no_roughness_ratio() {
        let (w, h) = (65, 49);
        let plane = Grid {
            width: w,
            height: h,
            cell: (30.0, 30.0),
            data: (0..w * h).map(|k| 10.0 * (k % w) as f32).collect(),
        };
        let results: Vec<MethodResult> = [
            DeriveMethod::Bilinear,
            DeriveMethod::Bicubic,
            DeriveMethod::BicubicDetail(0.25),
        ]
        .iter()
        .map(|&m| evaluate(&plane, 4, m, 1))
        .collect();
        for r in &results {
            assert!(
                r.roughness_ratio.is_nan(),
                "{}: {}",
                r.method,
                r.roughness_ratio
            );
        }
        assert!(!joint_front(&results).is_empty());
        // Written as empty cells, not NaN (a chart drew NaN as a roughness error of 0).
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let dir = crate::tools::fly::OutDir::create_for(
            &out,
            "eval derive",
            &crate::tools::fly::Outputs::named(&FILES),
        )
        .unwrap();
        write_results(&results, "plane", &dir, false).unwrap();
        let csv = std::fs::read_to_string(out.join("derive.csv")).unwrap();
        assert!(!csv.to_lowercase().contains("nan"), "{csv}");
        for row in csv.lines().skip(1) {
            assert_eq!(row.split(',').nth(6), Some(""), "{row}");
        }
        assert!(out.join("derive_roughness.png").is_file());
        assert!(
            evaluate(&smooth_grid(), 4, DeriveMethod::Bicubic, 1)
                .roughness_ratio
                .is_finite()
        );
    }

    #[test]
    fn bicubic_beats_bilinear_beats_nearest_on_smooth_terrain() {
        let t = smooth_grid();
        let r: Vec<f64> = [
            DeriveMethod::Nearest,
            DeriveMethod::Bilinear,
            DeriveMethod::Bicubic,
        ]
        .iter()
        .map(|&m| evaluate(&t, 4, m, 1).rmse_m)
        .collect();
        assert!(r[2] < r[1] && r[1] < r[0], "{r:?}");
        let detail = evaluate(&t, 4, DeriveMethod::BicubicDetail(0.25), 1);
        let plain = evaluate(&t, 4, DeriveMethod::Bicubic, 1);
        assert!(detail.roughness_ratio > plain.roughness_ratio);
    }
}
