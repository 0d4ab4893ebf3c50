//! Step 1 of the bake: the DEM resampled to square cells at the finest stored level, and the
//! derivation calibration fitted to the resulting pyramid.

use std::path::Path;

use glam::DVec2;

use crate::stream::{DeriveParams, HeightField, calibrate};
use crate::world::dem::Dem;
use crate::world::error::WorldError;
use crate::world::manifest::DeriveCalibration;
use crate::world::tile::Pyramid;

use super::BakeStage;

/// Largest finest-level grid the baker will hold in memory, samples.
const MAX_GRID_SAMPLES: u64 = 1 << 30;
/// The finest stored level over the whole root grid, with a margin wide enough for the border
/// samples of every coarser level. Array index `(a, b)` is global sample `(a - margin,
/// b - margin)` at world position `(a - margin, b - margin) * cell`.
pub(super) struct Grid {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) margin: i64,
    pub(super) cell: f64,
    pub(super) finest: u8,
    pub(super) heights: Vec<f32>,
}

impl Grid {
    pub(super) fn resample(
        dem: &Dem,
        pyramid: &Pyramid,
        dem_path: &Path,
        cancelled: &dyn Fn() -> Result<(), WorldError>,
        progress: &mut dyn FnMut(BakeStage, u64, u64),
    ) -> Result<Grid, WorldError> {
        let finest = pyramid.stored_levels - 1;
        let margin = i64::from(pyramid.border) << finest;
        let [nx, ny] = pyramid.tiles_at(finest);
        let cells = |n: u32| i64::from(n) * i64::from(pyramid.tile_cells);
        let width = (cells(nx) + 1 + 2 * margin) as usize;
        let height = (cells(ny) + 1 + 2 * margin) as usize;
        if width as u64 * height as u64 > MAX_GRID_SAMPLES {
            return Err(WorldError::OutOfRange {
                path: dem_path.to_path_buf(),
                field: "finest grid (root grid / cell size)".into(),
                value: format!("{width}x{height} samples"),
                allowed: format!("at most {MAX_GRID_SAMPLES} samples"),
            });
        }
        let cell = pyramid.cell_size_m(finest);
        let mut heights = vec![0f32; width * height];
        let total = height as u64;
        for (b, row) in heights.chunks_exact_mut(width).enumerate() {
            let y = (b as i64 - margin) as f64 * cell;
            for (a, h) in row.iter_mut().enumerate() {
                let x = (a as i64 - margin) as f64 * cell;
                *h = dem.sample(x, y) as f32;
            }
            if b % 64 == 0 || b + 1 == height {
                cancelled()?;
                progress(BakeStage::Resample, b as u64 + 1, total);
            }
        }
        Ok(Grid {
            width,
            height,
            margin,
            cell,
            finest,
            heights,
        })
    }

    pub(super) fn at(&self, a: usize, b: usize) -> f32 {
        self.heights[b * self.width + a]
    }

    /// Fits the detail of the derived levels to the data area of the finest stored level (the
    /// coarser stored levels are its subsamples): see [`calibrate`].
    pub(super) fn calibrate(&self, extent: [f64; 2], derived_levels: u8) -> DeriveCalibration {
        let m = self.margin as usize;
        let samples = |e: f64, n: usize| ((e / self.cell).floor() as usize + 1).min(n - m);
        let (w, h) = (
            samples(extent[0], self.width),
            samples(extent[1], self.height),
        );
        let mut heights = Vec::with_capacity(w * h);
        for b in m..m + h {
            let row = b * self.width + m;
            heights.extend_from_slice(&self.heights[row..row + w]);
        }
        calibrate(
            &HeightField {
                width: w,
                height: h,
                cell_m: (self.cell, self.cell),
                heights: &heights,
            },
            derived_levels,
            DeriveParams::default().seed,
        )
    }

    /// Min and max of all samples; an empty range is widened to 1 m.
    pub(super) fn height_range(&self) -> [f32; 2] {
        let (lo, hi) = self
            .heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            });
        if lo < hi {
            [lo, hi]
        } else {
            [lo - 0.5, hi + 0.5]
        }
    }

    /// Height at world position `p` by bilinear interpolation, clamped to the grid.
    pub(super) fn height_bilinear(&self, p: DVec2) -> f64 {
        let u = (p.x / self.cell + self.margin as f64).clamp(0.0, (self.width - 1) as f64);
        let v = (p.y / self.cell + self.margin as f64).clamp(0.0, (self.height - 1) as f64);
        let (a, b) = (
            (u.floor() as usize).min(self.width - 2),
            (v.floor() as usize).min(self.height - 2),
        );
        let (fu, fv) = (u - a as f64, v - b as f64);
        let h = |a, b| f64::from(self.at(a, b));
        let south = h(a, b) * (1.0 - fu) + h(a + 1, b) * fu;
        let north = h(a, b + 1) * (1.0 - fu) + h(a + 1, b + 1) * fu;
        south * (1.0 - fv) + north * fv
    }

    /// Slope at sample `(a, b)` in degrees, from central differences (one-sided at the grid's
    /// edge).
    pub(super) fn slope_deg(&self, a: usize, b: usize) -> f64 {
        let d = |lo: usize, hi: usize, get: &dyn Fn(usize) -> f32| {
            f64::from(get(hi) - get(lo)) / ((hi - lo) as f64 * self.cell)
        };
        let (a0, a1) = (a.saturating_sub(1), (a + 1).min(self.width - 1));
        let (b0, b1) = (b.saturating_sub(1), (b + 1).min(self.height - 1));
        let dx = d(a0, a1, &|i| self.at(i, b));
        let dy = d(b0, b1, &|j| self.at(a, j));
        (dx * dx + dy * dy).sqrt().atan().to_degrees()
    }

    pub(super) fn position(&self, a: usize, b: usize) -> DVec2 {
        DVec2::new(
            (a as i64 - self.margin) as f64,
            (b as i64 - self.margin) as f64,
        ) * self.cell
    }
}
