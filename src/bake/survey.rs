//! The survey: one pass over the whole finest grid, square by square, that keeps only what the
//! rest of the bake needs of the whole: the height range, the calibration window and the coarse
//! subsample with each of its samples' slopes (see [`super::plan`]).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

use crate::stream::{DeriveParams, HeightField, calibrate};
use crate::world::error::WorldError;
use crate::world::manifest::DeriveCalibration;

use super::BakeStage;
use super::plan::{Plan, SURVEY_SIDE};
use super::resample::Grid;
use super::source::DemSource;

/// What the survey found.
pub(super) struct Survey {
    /// Lowest and highest sample of the whole finest grid (an empty range widened to 1 m).
    pub(super) height_range: [f32; 2],
    /// The derivation fitted on the calibration window.
    pub(super) calibration: DeriveCalibration,
    /// The coarse subsample's heights.
    pub(super) coarse: Grid,
    /// The slope at each of its samples, degrees, measured on the finest grid.
    pub(super) slopes: Vec<f64>,
}

/// One square's findings.
struct Square {
    range: [f32; 2],
    /// Coarse samples: local index, height, slope.
    coarse: Vec<(usize, f32, f64)>,
    /// Calibration rows: index of the first sample in the window, heights.
    calibration: Vec<(usize, Vec<f32>)>,
}

/// Surveys the finest grid (see the module docs); `extent` is the data area, metres.
pub(super) fn survey(
    dem: &DemSource,
    plan: &Plan,
    extent: [f64; 2],
    derived_levels: u8,
    cancelled: &(dyn Fn() -> Result<(), WorldError> + Sync),
    progress: &mut dyn FnMut(BakeStage, u64, u64),
) -> Result<Survey, WorldError> {
    let shape = plan.shape;
    let (first, n) = plan.coarse_grid();
    let stride = plan.stride;
    // The calibration window: the data area, or a window of it centred on the world.
    let m = shape.margin;
    let data = [0, 1].map(|k| {
        let e = extent[k];
        ((e / shape.cell).floor() as i64 + 1).min(shape.size[k] - m)
    });
    // All of it where it fits, else about a square of the samples allowed.
    let cal_w = if data[0] * data[1] <= plan.calibration_samples as i64 {
        data[0]
    } else {
        data[0]
            .min((plan.calibration_samples as f64).sqrt().ceil() as i64)
            .max(1)
    };
    let cal_h = data[1].min(plan.calibration_samples as i64 / cal_w).max(1);
    let cal_at = [m + (data[0] - cal_w) / 2, m + (data[1] - cal_h) / 2];
    let squares = shape.size.map(|s| (s + SURVEY_SIDE - 1) / SURVEY_SIDE);
    let total = (squares[0] * squares[1]) as usize;

    let look = |k: usize| -> Result<Square, WorldError> {
        cancelled()?;
        let (sx, sy) = ((k as i64 % squares[0]), (k as i64 / squares[0]));
        let core = [sx, sy].map(|q| q * SURVEY_SIDE);
        let core = [0, 1].map(|a| [core[a], (core[a] + SURVEY_SIDE).min(shape.size[a]) - 1]);
        let grid = Grid::resample(dem, shape, core.map(|[lo, hi]| [lo - 1, hi + 1]))?;
        let mut sq = Square {
            range: [f32::INFINITY, f32::NEG_INFINITY],
            coarse: Vec::new(),
            calibration: Vec::new(),
        };
        for b in core[1][0]..=core[1][1] {
            for a in core[0][0]..=core[0][1] {
                let h = grid.heights[grid.local(a, b)];
                sq.range = [sq.range[0].min(h), sq.range[1].max(h)];
            }
        }
        // Coarse samples in the core.
        let on = |lo: i64, k: usize| lo + (first[k] - lo).rem_euclid(stride);
        let (a0, b0) = (on(core[0][0], 0), on(core[1][0], 1));
        for b in (b0..=core[1][1]).step_by(stride as usize) {
            for a in (a0..=core[0][1]).step_by(stride as usize) {
                let (la, lb) = ((a - grid.origin[0]) as usize, (b - grid.origin[1]) as usize);
                let local =
                    ((b - first[1]) / stride) as usize * n[0] + ((a - first[0]) / stride) as usize;
                sq.coarse
                    .push((local, grid.at(la, lb), grid.slope_deg(la, lb)));
            }
        }
        // Calibration rows in the core.
        let cols = [
            core[0][0].max(cal_at[0]),
            core[0][1].min(cal_at[0] + cal_w - 1),
        ];
        let rows = [
            core[1][0].max(cal_at[1]),
            core[1][1].min(cal_at[1] + cal_h - 1),
        ];
        if cols[0] <= cols[1] {
            for b in rows[0]..=rows[1] {
                let from = grid.local(cols[0], b);
                let row = grid.heights[from..=from + (cols[1] - cols[0]) as usize].to_vec();
                let at = ((b - cal_at[1]) * cal_w + cols[0] - cal_at[0]) as usize;
                sq.calibration.push((at, row));
            }
        }
        Ok(sq)
    };

    progress(BakeStage::Resample, 0, total as u64);
    let mut coarse = vec![0f32; n[0] * n[1]];
    let mut slopes = vec![0f64; n[0] * n[1]];
    let mut cal = vec![0f32; (cal_w * cal_h) as usize];
    let mut range = [f32::INFINITY, f32::NEG_INFINITY];
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::sync_channel::<Result<Square, WorldError>>(2 * plan.threads);
    let mut first_error = None;
    std::thread::scope(|scope| {
        let started = super::spawn_workers(scope, plan.threads, || {
            let (tx, next, look) = (tx.clone(), &next, &look);
            move || {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    if k >= total {
                        break;
                    }
                    let result = look(k);
                    let failed = result.is_err();
                    if tx.send(result).is_err() || failed {
                        // Stop the others too.
                        next.store(total, Ordering::Relaxed);
                        break;
                    }
                }
            }
        });
        drop(tx);
        if let Err(e) = started {
            first_error = Some(e);
            return;
        }
        let mut done = 0u64;
        for result in rx {
            match result {
                Ok(sq) => {
                    range = [range[0].min(sq.range[0]), range[1].max(sq.range[1])];
                    for (k, h, s) in sq.coarse {
                        coarse[k] = h;
                        slopes[k] = s;
                    }
                    for (at, row) in sq.calibration {
                        cal[at..at + row.len()].copy_from_slice(&row);
                    }
                    done += 1;
                    progress(BakeStage::Resample, done, total as u64);
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
    });
    if let Some(e) = first_error {
        return Err(e);
    }
    dem.check_nodata()?;
    let height_range = if range[0] < range[1] {
        range
    } else {
        [range[0] - 0.5, range[1] + 0.5]
    };
    let calibration = calibrate(
        &HeightField {
            width: cal_w as usize,
            height: cal_h as usize,
            cell_m: (shape.cell, shape.cell),
            heights: &cal,
        },
        derived_levels,
        DeriveParams::default().seed,
    );
    Ok(Survey {
        height_range,
        calibration,
        coarse: Grid {
            width: n[0],
            height: n[1],
            origin: first,
            stride,
            shape,
            heights: coarse,
        },
        slopes,
    })
}
