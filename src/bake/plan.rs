//! How a bake spends its memory limit ([`super::BakeOptions::memory_mib`]).
//!
//! Nothing a bake holds grows with the world beyond what the limit allows:
//!
//! - the **coarse subsample**: every `stride`-th sample of the finest grid, heights, slopes and
//!   paint, from which the camera paths are computed and the coarse levels are cut (the stride
//!   is the smallest power of two whose subsample fits half of what is left; a world small
//!   enough is held whole, `stride` 1, and then every tile is cut from it);
//! - the **blocks**: the finer levels are made block by block, a block being a tile of the
//!   coarsest level the subsample cannot give, resampled and painted with its borders, one
//!   block a thread;
//! - the **calibration sample**: the derivation is fitted on the data area, or on a window of
//!   it centred on the world where the whole would not fit;
//! - the DEM: a single file whole; a mosaic's files and chunks in caches (see
//!   `super::source`);
//! - the maps (land cover, density, mask): the windows of them over the DEM, read before the
//!   plan is made and held to the end, and the most that reading one took (a GeoTIFF's
//!   largest strip or tile, a PNG whole), so that a limit too small for them is refused.

use crate::world::error::WorldError;
use crate::world::tile::Pyramid;

use super::resample::Shape;
use super::source::{BASE_BYTES, DemSource};

/// The default memory limit, MiB.
pub const DEFAULT_MEMORY_MIB: u64 = 2048;
/// Bytes a sample of the coarse subsample takes: height, slope, grass type, density, material.
const COARSE_SAMPLE_BYTES: u64 = 4 + 8 + 3;
/// Bytes a sample of a block takes: height and paint.
const BLOCK_SAMPLE_BYTES: u64 = 4 + 3;
/// Bytes a sample of the calibration window takes, the fit's levels included.
const CALIBRATION_SAMPLE_BYTES: u64 = 40;
/// Samples a side of the survey's squares.
pub(super) const SURVEY_SIDE: i64 = 256;

/// How a bake spends its memory (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Plan {
    pub(super) shape: Shape,
    /// Finest samples between the coarse subsample's samples (a power of two).
    pub(super) stride: i64,
    /// Levels finer than the coarse ones are made in blocks, tiles of this level.
    pub(super) block_level: u8,
    /// Threads making blocks (and surveying).
    pub(super) threads: usize,
    /// Most samples the calibration window may have.
    pub(super) calibration_samples: u64,
    /// Chunks a mosaic keeps cached.
    pub(super) cached: usize,
    /// What the plan expects the bake to hold at most, bytes.
    pub(super) peak_bytes: u64,
}

impl Plan {
    /// Whether tiles of `level` are cut from the coarse subsample.
    pub(super) fn coarse_level(&self, level: u8) -> bool {
        level < self.block_level
    }

    /// The coarse subsample's first global sample per axis and its samples per axis.
    pub(super) fn coarse_grid(&self) -> ([i64; 2], [usize; 2]) {
        coarse_grid(&self.shape, self.stride)
    }

    /// Plans a bake of `pyramid` from `dem`, holding maps of `map_bytes`, within `limit_mib`;
    /// refuses a limit too small for the smallest plan, naming what it would need.
    pub(super) fn new(
        limit_mib: u64,
        pyramid: &Pyramid,
        dem: &DemSource,
        map_bytes: u64,
        data_samples: u64,
    ) -> Result<Plan, WorldError> {
        let plan = |mib: u64| Self::within(mib, pyramid, dem, map_bytes, data_samples);
        if let Some(p) = plan(limit_mib) {
            return Ok(p);
        }
        // The least limit that plans: what the plan picks (the calibration's sample, the
        // subsample's stride) grows with the limit, so the need under this limit is not
        // enough under that one; the least is searched for, and named.
        let most = 1u64 << 20;
        let need = if limit_mib >= most || plan(most).is_none() {
            None
        } else {
            let (mut lo, mut hi) = (limit_mib, most);
            while hi - lo > 1 {
                let mid = lo + (hi - lo) / 2;
                if plan(mid).is_some() {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            Some(hi)
        };
        let what = "its DEM, its maps, a sample of the data area, a subsample of the finest grid \
                    and one block a thread";
        Err(WorldError::bad_option(
            "--memory-mib",
            limit_mib,
            match need {
                Some(need) => {
                    format!("at least {need} for this world and DEM (a bake holds {what} there)")
                }
                None => {
                    format!("more than {most} for this world and DEM (a bake holds {what} there)")
                }
            },
        ))
    }

    /// [`Plan::new`] within `limit_mib`, or `None` where it does not fit.
    fn within(
        limit_mib: u64,
        pyramid: &Pyramid,
        dem: &DemSource,
        map_bytes: u64,
        data_samples: u64,
    ) -> Option<Plan> {
        let shape = Shape::of(pyramid);
        let limit = limit_mib.saturating_mul(1 << 20);
        let cores = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .min(8);
        let [chunk, making] = dem.cache_unit_bytes();
        // The DEM: a whole one, or one chunk being made per thread and a few chunks cached.
        let dem_bytes = |threads: u64| dem.resident_bytes() + threads * making + 4 * chunk;
        let fixed = |threads: u64| BASE_BYTES + dem_bytes(threads) + map_bytes;
        let calibration = |left: u64| {
            (left / 8 / CALIBRATION_SAMPLE_BYTES)
                .min(data_samples)
                .max(1 << 16)
        };
        // The stride: the smallest power of two whose subsample fits half of what is left.
        let finest = shape.finest;
        let left1 = limit.saturating_sub(fixed(1));
        let calibration_samples = calibration(left1);
        let left = left1.saturating_sub(calibration_samples * CALIBRATION_SAMPLE_BYTES);
        let mut stride = 1i64;
        let coarse_bytes = |s: i64| {
            let (_, n) = coarse_grid(&shape, s);
            n[0] as u64 * n[1] as u64 * COARSE_SAMPLE_BYTES
        };
        let coarsest = |s: i64| coarse_grid(&shape, s).1.iter().all(|&n| n >= 2);
        while coarse_bytes(stride) > left / 2 && coarsest(stride * 2) {
            stride *= 2;
        }
        // Levels whose samples are every `stride`-th finest sample or sparser come from the
        // subsample; the finer ones from blocks of the coarsest of them.
        let steps = stride.trailing_zeros() as u8;
        let block_level = (finest + 1).saturating_sub(steps);
        let block_bytes = if block_level < pyramid.stored_levels {
            let id = crate::world::tile::TileId::new(block_level, 0, 0);
            let [a, b] = shape.tile_span(pyramid, id);
            let samples = (a[1] - a[0] + 3) as u64 * (b[1] - b[0] + 3) as u64;
            // The block, its DEM window (at most as fine as the DEM's posts) and a tile's files.
            let header = dem.header();
            let metres = (a[1] - a[0] + 3) as f64 * shape.cell;
            let posts = (metres / header.cell_ew_m + 4.0) * (metres / header.cell_ns_m + 4.0);
            samples * BLOCK_SAMPLE_BYTES + posts as u64 * 4 + (4 << 20)
        } else {
            0
        };
        let used = |threads: u64| {
            fixed(threads)
                + calibration_samples * CALIBRATION_SAMPLE_BYTES
                + coarse_bytes(stride)
                + threads * block_bytes
        };
        let mut threads = cores as u64;
        while threads > 1 && used(threads) > limit {
            threads -= 1;
        }
        let need = used(1);
        if need > limit || (stride > 1 && coarse_bytes(stride) > left / 2) {
            return None;
        }
        let spare = limit - used(threads);
        let cached = match (spare / 2).checked_div(chunk) {
            Some(chunks) => 4 + chunks as usize,
            None => 0,
        };
        let peak_bytes = used(threads) + cached.saturating_sub(4) as u64 * chunk;
        Some(Plan {
            shape,
            stride,
            block_level,
            threads: threads as usize,
            calibration_samples,
            cached,
            peak_bytes,
        })
    }
}

/// The subsample of `shape` every `stride` samples that keeps the world's origin on it: its
/// first global sample per axis and its samples per axis.
fn coarse_grid(shape: &Shape, stride: i64) -> ([i64; 2], [usize; 2]) {
    let first = shape.margin.rem_euclid(stride);
    let n = shape.size.map(|s| {
        if s > first {
            ((s - 1 - first) / stride + 1) as usize
        } else {
            1
        }
    });
    ([first; 2], n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::dem::{Dem, DemFormat};

    /// A DEM header of `n` x `n` samples of `cell` metres (no heights held).
    fn header(n: u32, cell: f64) -> DemSource {
        DemSource::Whole(Dem {
            width: n,
            height: n,
            cell_ew_m: cell,
            cell_ns_m: cell,
            heights: Vec::new(),
            place: String::new(),
            source: String::new(),
            format: DemFormat::SrtmHgt,
            crs: String::new(),
            origin: None,
            pixel_size: None,
            nodata_filled: 0,
        })
    }

    fn pyramid(cells: f64, cell: f64, levels: u8) -> Pyramid {
        let root = cell * 128.0 * f64::from(1u32 << (levels - 1));
        let n = (cells * cell / root).ceil() as u32;
        Pyramid {
            root_tile_size_m: root,
            root_tiles: [n, n],
            tile_cells: 128,
            border: 2,
            stored_levels: levels,
            derived_levels: 6,
        }
    }

    /// However large the world, the plan holds what it expects within the limit, and what it
    /// holds stops growing with the world: the subsample thins, the blocks stay one tile.
    #[test]
    fn the_plan_stays_within_the_limit_whatever_the_world() {
        for limit in [256u64, 2048] {
            let mut last_stride = 0;
            for cells in [1_000.0, 8_000.0, 30_000.0, 65_000.0] {
                let dem = header(cells as u32, 25.0);
                let p = pyramid(cells, 25.0, 3);
                let plan = Plan::new(limit, &p, &dem, 0, (cells * cells) as u64).unwrap();
                assert!(
                    plan.peak_bytes <= limit << 20,
                    "{cells} cells at {limit} MiB: plans {} MiB",
                    plan.peak_bytes >> 20
                );
                assert!(
                    plan.stride >= last_stride,
                    "the subsample thins as the world grows"
                );
                last_stride = plan.stride;
                let (_, n) = plan.coarse_grid();
                assert!(n[0] as u64 * n[1] as u64 * COARSE_SAMPLE_BYTES <= limit << 19);
                if plan.stride > 1 {
                    assert!(
                        plan.block_level < 3,
                        "blocks are made below the coarse levels"
                    );
                }
            }
            assert!(
                last_stride > 1,
                "a 65,000-cell world is not held whole in {limit} MiB"
            );
        }
        // A small world is held whole, every level cut from it.
        let plan = Plan::new(
            2048,
            &pyramid(1000.0, 25.0, 3),
            &header(1000, 25.0),
            0,
            1 << 20,
        )
        .unwrap();
        assert_eq!((plan.stride, plan.block_level), (1, 3));
        assert!(plan.coarse_level(2));
    }

    /// A limit too small for even one block is refused, naming the option and what is needed.
    #[test]
    fn a_limit_too_small_is_refused_naming_what_it_needs() {
        let e = Plan::new(
            8,
            &pyramid(30_000.0, 25.0, 3),
            &header(30_000, 25.0),
            0,
            1 << 20,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("--memory-mib 8") && e.contains("at least"),
            "{e}"
        );
        // The limit it names plans, and one less does not.
        let named: u64 = e
            .split("at least ")
            .nth(1)
            .and_then(|t| t.split(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap();
        let plan = |mib| {
            Plan::new(
                mib,
                &pyramid(30_000.0, 25.0, 3),
                &header(30_000, 25.0),
                0,
                1 << 20,
            )
        };
        assert!(plan(named).is_ok(), "{e}");
        assert!(plan(named - 1).is_err(), "{e}");
    }

    /// The maps' windows count against the limit: they raise the plan's peak by their bytes,
    /// and maps larger than the limit are refused before a tile is made.
    #[test]
    fn the_maps_count_against_the_limit() {
        let (p, dem) = (pyramid(1000.0, 25.0, 3), header(1000, 25.0));
        let without = Plan::new(2048, &p, &dem, 0, 1 << 20).unwrap();
        let with = Plan::new(2048, &p, &dem, 300 << 20, 1 << 20).unwrap();
        assert_eq!(with.peak_bytes, without.peak_bytes + (300 << 20));
        let e = Plan::new(256, &p, &dem, 300 << 20, 1 << 20)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--memory-mib 256") && e.contains("at least") && e.contains("its maps"),
            "{e}"
        );
    }
}
