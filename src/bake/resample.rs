//! Step 1 of the bake: the DEM resampled to square cells at the finest stored level.
//!
//! The finest grid spans the whole root grid plus a margin for the border samples of every
//! coarser level. It is never held whole: [`Grid`] is a window of it (a block, resampled where a
//! part of the bake needs it) or a subsample of it (every `stride`-th sample, for the camera
//! paths and the coarse levels). Global sample `(a, b)` lies at world position
//! `(a - margin, b - margin) * cell`, and its height is a pure function of that position, so
//! every window agrees with every other where they overlap.

use std::sync::OnceLock;

use glam::DVec2;

use crate::world::error::WorldError;
use crate::world::tile::Pyramid;

use super::source::DemSource;

/// The whole finest grid's shape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Shape {
    /// Samples west-east and south-north.
    pub(super) size: [i64; 2],
    /// Samples beyond the root grid on every side.
    pub(super) margin: i64,
    /// Cell size, metres.
    pub(super) cell: f64,
    pub(super) finest: u8,
    /// Levels the renderer derives below the finest stored one: the ground it draws is this
    /// many Catmull-Rom halvings of the finest grid ([`Grid::height`]).
    pub(super) derived: u8,
}

impl Shape {
    pub(super) fn of(pyramid: &Pyramid) -> Shape {
        let finest = pyramid.stored_levels - 1;
        let margin = i64::from(pyramid.border) << finest;
        let tiles = pyramid.tiles_at(finest);
        let size = tiles.map(|n| i64::from(n) * i64::from(pyramid.tile_cells) + 1 + 2 * margin);
        Shape {
            size,
            margin,
            cell: pyramid.cell_size_m(finest),
            finest,
            derived: pyramid.derived_levels,
        }
    }

    /// World position of global sample `(a, b)`, metres.
    pub(super) fn position(&self, a: i64, b: i64) -> DVec2 {
        DVec2::new((a - self.margin) as f64, (b - self.margin) as f64) * self.cell
    }

    /// The global samples of tile `id` (its borders included), inclusive, per axis.
    pub(super) fn tile_span(
        &self,
        pyramid: &Pyramid,
        id: crate::world::tile::TileId,
    ) -> [[i64; 2]; 2] {
        let step = 1i64 << (self.finest - id.level);
        let (cells, border) = (i64::from(pyramid.tile_cells), i64::from(pyramid.border));
        [id.x, id.y].map(|t| {
            let t = i64::from(t);
            [
                (t * cells - border) * step + self.margin,
                ((t + 1) * cells + border) * step + self.margin,
            ]
        })
    }
}

/// A window or a subsample of the finest grid (see the module docs). Local sample `(a, b)` is
/// global sample `origin + (a, b) * stride`.
pub(super) struct Grid {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) origin: [i64; 2],
    pub(super) stride: i64,
    pub(super) shape: Shape,
    pub(super) heights: Vec<f32>,
}

impl Grid {
    /// Resamples the DEM over global samples `span` (inclusive, per axis; clamped to the grid).
    pub(super) fn resample(
        dem: &DemSource,
        shape: Shape,
        span: [[i64; 2]; 2],
    ) -> Result<Grid, WorldError> {
        let span = [0, 1].map(|k| [span[k][0].max(0), span[k][1].min(shape.size[k] - 1)]);
        let (lo, hi) = (
            shape.position(span[0][0], span[1][0]),
            shape.position(span[0][1], span[1][1]),
        );
        let window = dem.window([lo.x, hi.x], [lo.y, hi.y])?;
        let width = (span[0][1] - span[0][0] + 1) as usize;
        let height = (span[1][1] - span[1][0] + 1) as usize;
        let mut heights = Vec::with_capacity(width * height);
        for b in span[1][0]..=span[1][1] {
            let y = (b - shape.margin) as f64 * shape.cell;
            for a in span[0][0]..=span[0][1] {
                let x = (a - shape.margin) as f64 * shape.cell;
                heights.push(window.sample(x, y) as f32);
            }
        }
        Ok(Grid {
            width,
            height,
            origin: [span[0][0], span[1][0]],
            stride: 1,
            shape,
            heights,
        })
    }

    pub(super) fn at(&self, a: usize, b: usize) -> f32 {
        self.heights[b * self.width + a]
    }

    /// Metres between neighbouring local samples.
    pub(super) fn spacing(&self) -> f64 {
        self.shape.cell * self.stride as f64
    }

    /// Local index of global sample `(a, b)`, which must lie on this grid.
    pub(super) fn local(&self, a: i64, b: i64) -> usize {
        let la = (a - self.origin[0]) / self.stride;
        let lb = (b - self.origin[1]) / self.stride;
        lb as usize * self.width + la as usize
    }

    /// Local samples from `p` (metres) to the grid's (0, 0), per axis, before rounding.
    fn offset(&self) -> [i64; 2] {
        [0, 1].map(|k| (self.shape.margin - self.origin[k]) / self.stride)
    }

    /// Index of the sample nearest `p` (metres; clamped to the grid).
    pub(super) fn index_at(&self, p: DVec2) -> usize {
        let s = self.spacing();
        let o = self.offset();
        let a = ((p.x / s).round() as i64 + o[0]).clamp(0, self.width as i64 - 1);
        let b = ((p.y / s).round() as i64 + o[1]).clamp(0, self.height as i64 - 1);
        b as usize * self.width + a as usize
    }

    /// Height at world position `p` of the ground the renderer draws over this grid: the finest
    /// derived level, [`Shape::derived`] Catmull-Rom halvings of the grid (of the subsample's,
    /// `stride` times sparser, as many more), sampled bilinearly; beyond the grid its edge
    /// samples are repeated. Not the grid's bilinear surface: between samples the two differ by
    /// up to an eighth of the cell squared times the curvature (45 m at the meadow of the Santa
    /// Cruz DEM baked at 10 km cells), which put camera paths fitted to it under the ground.
    pub(super) fn height(&self, p: DVec2) -> f64 {
        let s = self.spacing();
        let o = self.offset();
        let halvings = (u32::from(self.shape.derived) + self.stride.trailing_zeros())
            .min(MAX_TABULATED_HALVINGS);
        let basis = halving_basis(halvings);
        let u = p.x / s + o[0] as f64;
        let v = p.y / s + o[1] as f64;
        let (a0, b0) = (u.floor() as i64 - 2, v.floor() as i64 - 2);
        let (last_a, last_b) = (self.width as i64 - 1, self.height as i64 - 1);
        let wx: [f64; 6] =
            std::array::from_fn(|k| basis_at(basis, halvings, u - (a0 + k as i64) as f64));
        let mut sum = 0.0;
        for b in b0..b0 + 6 {
            let wy = basis_at(basis, halvings, v - b as f64);
            if wy == 0.0 {
                continue;
            }
            let row_b = b.clamp(0, last_b) as usize;
            let row: f64 = (a0..a0 + 6)
                .zip(wx)
                .map(|(a, w)| w * f64::from(self.at(a.clamp(0, last_a) as usize, row_b)))
                .sum();
            sum += wy * row;
        }
        sum
    }

    /// Slope at local sample `(a, b)` of a window (stride 1) in degrees, from central
    /// differences (one-sided at the whole grid's edge). Exact where the window holds the
    /// sample's neighbours.
    pub(super) fn slope_deg(&self, a: usize, b: usize) -> f64 {
        let cell = self.shape.cell;
        let d = |lo: i64, hi: i64, get: &dyn Fn(i64) -> f32| {
            f64::from(get(hi) - get(lo)) / ((hi - lo) as f64 * cell)
        };
        let [ga, gb] = [self.origin[0] + a as i64, self.origin[1] + b as i64];
        let clamp = |g: i64, k: usize, n: usize| {
            let lo = self.origin[k].max(0);
            let hi = (self.origin[k] + n as i64 - 1).min(self.shape.size[k] - 1);
            [(g - 1).max(lo), (g + 1).min(hi)]
        };
        let [a0, a1] = clamp(ga, 0, self.width);
        let [b0, b1] = clamp(gb, 1, self.height);
        let local = |g: i64, k: usize| (g - self.origin[k]) as usize;
        let dx = d(a0, a1, &|i| self.at(local(i, 0), b));
        let dy = d(b0, b1, &|j| self.at(a, local(j, 1)));
        (dx * dx + dy * dy).sqrt().atan().to_degrees()
    }

    /// World position of local sample `(a, b)`.
    pub(super) fn position(&self, a: usize, b: usize) -> DVec2 {
        self.shape.position(
            self.origin[0] + a as i64 * self.stride,
            self.origin[1] + b as i64 * self.stride,
        )
    }
}

/// Halvings tabulated at most in [`halving_basis`]: finer levels move no sample's weight by
/// more than 2 millionths.
const MAX_TABULATED_HALVINGS: u32 = 10;

/// The weight of a grid sample in the ground drawn `halvings` Catmull-Rom halvings below the
/// grid (`crate::stream::derive_cpu::WEIGHTS`, the derivation of the finer levels), as a
/// function of the offset from the sample, in cells: its values at every 2^-halvings cells
/// from -3 to 3, beyond which it is 0 (entry `k` at `k / 2^halvings - 3`). The scheme is
/// separable, so a point's height is the sum of the samples times this at both offsets.
fn halving_basis(halvings: u32) -> &'static [f64] {
    const TABLES: usize = MAX_TABULATED_HALVINGS as usize + 1;
    static BASES: [OnceLock<Vec<f64>>; TABLES] = [const { OnceLock::new() }; TABLES];
    BASES[halvings as usize].get_or_init(|| {
        let mid = crate::stream::derive_cpu::WEIGHTS[1].map(f64::from);
        // A unit sample among zeros from -3 to 3 cells, halved again and again: each halving
        // keeps the values and puts the Catmull-Rom midpoint between each two.
        let mut w = vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
        for _ in 0..halvings {
            let at = |i: usize, d: isize| {
                i.checked_add_signed(d)
                    .and_then(|k| w.get(k))
                    .copied()
                    .unwrap_or(0.0)
            };
            let mut next = Vec::with_capacity(2 * w.len() - 1);
            for i in 0..w.len() {
                next.push(w[i]);
                if i + 1 < w.len() {
                    let taps = [at(i, -1), at(i, 0), at(i, 1), at(i, 2)];
                    next.push(mid.iter().zip(taps).map(|(m, t)| m * t).sum());
                }
            }
            w = next;
        }
        w
    })
}

/// [`halving_basis`] at offset `t` cells, linear between its entries (the renderer samples its
/// finest level bilinearly).
fn basis_at(basis: &[f64], halvings: u32, t: f64) -> f64 {
    let f = (t + 3.0) * f64::from(1u32 << halvings);
    if !(f > 0.0 && f < (basis.len() - 1) as f64) {
        return 0.0;
    }
    let k = f.floor() as usize;
    let x = f - k as f64;
    basis[k] * (1.0 - x) + basis[k + 1] * x
}
