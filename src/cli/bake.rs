//! `verdant bake`: its options, progress and summary.

use std::path::PathBuf;

use anyhow::{Context, Result};
use indicatif::ProgressBar;

use verdant::bake::ceiling::Ceiling;
use verdant::bake::{BakeOptions, bake};

use super::args::parse_cell_size;
use super::out::{note, say};
use super::progress::bar;
use super::shown;

// The options of `verdant bake`.
#[derive(clap::Args)]
pub(crate) struct BakeArgs {
    /// The DEM: a GeoTIFF, an SRTM .hgt tile, or a 16-bit PNG whose sidecar is the .json of
    /// the same stem (the format is told from the content); or, to join several on their
    /// georeferencing, --dem repeated, a folder of them, or a GDAL VRT mosaic.
    #[arg(long, required = true)]
    pub(crate) dem: Vec<PathBuf>,
    /// Spacing of the DEM's samples in metres, M or EW,NS (each above 0 and at most 1e6), in
    /// place of what the file says (needed for a TIFF without GeoTIFF tags).
    #[arg(long, value_name = "M|EW,NS", value_parser = parse_cell_size)]
    pub(crate) dem_cell_size: Option<[f64; 2]>,
    /// The world folder to write.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// World name (default: the output folder's name).
    #[arg(long)]
    pub(crate) name: Option<String>,
    /// Cell size of the finest stored level, metres (default: from the DEM): at least 0.001
    /// and at least 0.5 / --tile-cells (the finest tiles, where the grass grows, are at least
    /// 0.5 m wide), and at most 65536 cells across the DEM a side.
    #[arg(long)]
    pub(crate) cell_size: Option<f64>,
    /// Cells per tile edge, a power of two in 8..=1024.
    #[arg(long, default_value_t = 128, value_parser = super::args::power_of_two_in(8, 1024))]
    pub(crate) tile_cells: u32,
    /// Stored levels of the tile pyramid, 1..=12 (default: as many as the world needs, at
    /// least 3, for at most 64 level-0 tiles, which a viewer keeps resident).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=12))]
    pub(crate) levels: Option<u8>,
    /// Seed of the grass-painting noise.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Replace the world (world.toml and tiles/) in --out if it exists and is not empty
    /// (otherwise it is refused); its other files are kept.
    #[arg(long)]
    pub(crate) replace: bool,
    /// With --replace: write the baked world.toml alone. Without it, the replaced world.toml's
    /// plant types and its camera paths of names the bake does not write (hand-made ones) are
    /// kept, comments and all, and checked against the new world.
    #[arg(long, requires = "replace")]
    pub(crate) fresh_manifest: bool,
    /// A land-cover map: a GeoTIFF of one uint8 or uint16 band (placed by its georeferencing,
    /// reprojected by EPSG code where its coordinate system is not the DEM's), or a grayscale
    /// PNG that spans the DEM. Its classes choose the grass and the ground's material where it
    /// has data (the procedural rule paints the rest). Needs --cover-table.
    #[arg(long, requires = "cover_table")]
    pub(crate) land_cover: Option<PathBuf>,
    /// What grows on each class of --land-cover: a TOML table, or a built-in one by name
    /// (esa-worldcover, nlcd).
    #[arg(long, requires = "land_cover")]
    pub(crate) cover_table: Option<PathBuf>,
    /// A density map that scales the grass cover: a grayscale PNG spanning the DEM (0 to its
    /// largest value), or a GeoTIFF placed like --land-cover (0..1 floats, or 0..255 or 0..65535
    /// integers), of which only the part over the DEM is read (at most 2^28 samples).
    #[arg(long)]
    pub(crate) density_map: Option<PathBuf>,
    /// A mask: nothing grows where it is not 0 (a PNG spanning the DEM, or a GeoTIFF placed like
    /// --land-cover, of which only the part over the DEM is read, at most 2^28 samples).
    #[arg(long)]
    pub(crate) mask: Option<PathBuf>,
    /// Bake only shard I of N (I from 0 to N-1, e.g. a Kubernetes indexed Job's
    /// JOB_COMPLETION_INDEX) into a parts folder beside --out; --finish-shards N publishes the
    /// world once every shard is done. Re-running a finished shard does nothing.
    #[arg(long, value_name = "I/N", value_parser = parse_shard, conflicts_with = "finish_shards")]
    pub(crate) shard: Option<(u32, u32)>,
    /// Finish a bake of N shards: the tiles that cross shards, then the world moved into --out
    /// with its world.toml last. Refused while any shard is not done.
    #[arg(long, value_name = "N")]
    pub(crate) finish_shards: Option<u32>,
    /// The most memory the bake may hold, MiB, 1..=1048576: it reads a mosaic's files a chunk
    /// at a time and makes the finer levels block by block, so any world bakes within it (a
    /// single DEM file is held whole and counts against it). Default 2048, or less where the
    /// process's address-space limit (ulimit -v) or its control group's memory limit leaves
    /// less.
    #[arg(long, value_name = "MIB", value_parser = super::args::parse_mib)]
    pub(crate) memory_mib: Option<u64>,
}

fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("{s:?}: expected I/N, e.g. 0/4 (shard I of N, I from 0 to N-1)");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (u32, u32) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    // The range is the baker's to check (`ShardStep::check`), with the other options.
    Ok((i, n))
}

/// The bake's memory limit: `asked` (`--memory-mib`), or the default lowered to what an outside
/// limit leaves (`ceiling`), saying so; a limit asked for above it is kept, with a warning.
fn memory_limit(asked: Option<u64>, ceiling: Option<Ceiling>) -> u64 {
    let default = verdant::bake::plan::DEFAULT_MEMORY_MIB;
    let Some(c) = ceiling.filter(|c| c.mib < asked.unwrap_or(default)) else {
        return asked.unwrap_or(default);
    };
    let held = format!(
        "{} of {} MiB leaves this process {} MiB more (it holds {} MiB)",
        c.what,
        c.limit_mib,
        c.limit_mib.saturating_sub(c.used_mib),
        c.used_mib
    );
    match asked {
        None => {
            let mib = c.mib.max(1);
            note!("memory: limit {mib} MiB, not the default {default} MiB: {held}");
            mib
        }
        Some(mib) => {
            note!(
                "warning: --memory-mib {mib} is more than this process can hold: {held}; the \
                 bake may end on a failed allocation (--memory-mib {} fits)",
                c.mib.max(1)
            );
            mib
        }
    }
}

pub(crate) fn bake_world(args: BakeArgs) -> Result<()> {
    let BakeArgs {
        dem,
        dem_cell_size,
        out,
        name,
        cell_size,
        tile_cells,
        levels,
        seed,
        replace,
        fresh_manifest,
        land_cover,
        cover_table,
        density_map,
        mask,
        shard,
        finish_shards,
        memory_mib,
    } = args;
    let shard = match (shard, finish_shards) {
        (Some((index, count)), _) => Some(verdant::bake::ShardStep::Shard { index, count }),
        (None, Some(count)) => Some(verdant::bake::ShardStep::Finish { count }),
        (None, None) => None,
    };
    let memory_mib = memory_limit(memory_mib, verdant::bake::ceiling::process_ceiling());
    let mut dems = dem.into_iter();
    let opts = BakeOptions {
        dem: dems.next().unwrap_or_default(),
        more_dems: dems.collect(),
        dem_cell_size_m: dem_cell_size,
        out,
        name,
        cell_size_m: cell_size,
        tile_cells,
        stored_levels: levels.unwrap_or(0),
        seed,
        replace,
        fresh_manifest,
        land_cover: land_cover.zip(cover_table),
        density_map,
        mask,
        cancel: Some(super::stop_on_signals()?),
        shard,
        memory_mib,
    };
    let mut current: Option<(String, ProgressBar)> = None;
    // Without a terminal (a batch job's log) the bars draw nothing: a line as each stage
    // begins, and one a tenth of its way on where a second has passed since the last line.
    let log_lines = super::progress::lines();
    let mut logged: Option<(String, u64)> = None;
    let started = std::time::Instant::now();
    let mut last_line = started;
    let report = bake(&opts, &mut |stage, done, total| {
        let label = format!("{stage:?}").to_lowercase();
        if log_lines {
            let tenth = (done * 10).checked_div(total).unwrap_or(10);
            let new_stage = logged.as_ref().is_none_or(|(l, _)| l != &label);
            let on = logged.as_ref().is_some_and(|(_, t)| tenth > *t)
                && last_line.elapsed() >= std::time::Duration::from_secs(1);
            if new_stage || on {
                logged = Some((label.clone(), tenth));
                last_line = std::time::Instant::now();
                note!(
                    "bake: {label} {done}/{total} ({:.1} s)",
                    started.elapsed().as_secs_f64()
                );
            }
        }
        if current.as_ref().map(|(l, _)| l != &label).unwrap_or(true) {
            if let Some((_, pb)) = current.take() {
                pb.finish();
            }
            current = Some((label.clone(), bar(total, &label)));
        }
        if let Some((_, pb)) = &current {
            pb.set_length(total);
            pb.set_position(done);
        }
    })
    .map_err(|e| {
        // A bake asked to stop whose request over HTTP, in flight when the signal came, then
        // failed (it ran into its deadline) was stopped all the same: nothing of it was kept.
        // Any other failure (a publish that could not be finished) is said as it is.
        let stopped = opts
            .cancel
            .as_ref()
            .is_some_and(verdant::bake::CancelFlag::is_cancelled);
        if stopped && matches!(e, verdant::world::WorldError::Fetch(_)) {
            log::warn!("while the bake stopped: {e}");
            verdant::world::WorldError::Cancelled {
                path: opts.out.clone(),
            }
        } else {
            e
        }
    })
    .with_context(|| format!("baking {}", shown(&opts.dem)))?;
    if let Some((_, pb)) = current {
        super::progress::end_bar(Some(&pb), false);
    }
    if report.already_done {
        say!(
            "shard already done: nothing to do ({} tiles written by its earlier run)",
            report.tiles_written
        )?;
        return Ok(());
    }
    say!(
        "read {} ({}, {}x{} samples of {:.3} m x {:.3} m, {} nodata samples filled)",
        shown(&opts.dem),
        report.dem_format.name(),
        report.dem_samples[0],
        report.dem_samples[1],
        report.dem_cell_size_m[0],
        report.dem_cell_size_m[1],
        report.nodata_filled
    )?;
    if let Some([read, size]) = report.dem_bytes_read {
        let mib = |b: u64| b as f64 / f64::from(1 << 20);
        say!(
            "read the DEM in chunks: {:.1} MiB of its files' {:.1} MiB ({:.2} times)",
            mib(read),
            mib(size),
            read as f64 / size.max(1) as f64
        )?;
    }
    match opts.shard {
        Some(verdant::bake::ShardStep::Shard { index, count }) => say!(
            "baked shard {index} of {count}: {} tiles into {} in {:.1} s",
            report.tiles_written,
            shown(&verdant::bake::shard::parts_dir(&opts.out)),
            report.seconds
        )?,
        _ => say!(
            "baked {} tiles in {} levels into {} in {:.1} s (bake_id {})",
            report.tiles_written,
            report.levels,
            shown(&opts.out),
            report.seconds,
            report.bake_id
        )?,
    }
    say!(
        "memory: peak {:.0} MiB resident (limit {} MiB, planned {} MiB)",
        report.peak_memory_mib,
        report.memory_limit_mib,
        report.planned_mib
    )?;
    let carried = &report.carried;
    if !carried.is_empty() {
        let list = |names: &[String]| {
            names
                .iter()
                .map(|n| format!("\"{n}\""))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let part = |what: &str, names: &[String]| {
            (!names.is_empty()).then(|| format!("{} {what} ({})", names.len(), list(names)))
        };
        let parts: Vec<String> = [
            part("plant type(s)", &carried.plant_types),
            part("camera path(s)", &carried.paths),
            part("wind scene(s)", &carried.wind_scenes),
        ]
        .into_iter()
        .flatten()
        .collect();
        say!(
            "kept from the replaced world.toml: {}{} (--fresh-manifest drops them)",
            parts.join(", "),
            if carried.rewritten {
                "; written out from the parsed manifest, every field spelt out and their \
                 comments not kept (the old text could not be split by table)"
            } else {
                ""
            }
        )?;
        if !carried.paths_outside.is_empty() {
            log::warn!(
                "kept camera path(s) {} run outside the new world's data area",
                list(&carried.paths_outside)
            );
        }
    }
    if !carried.replaced.is_empty() {
        say!(
            "the bake wrote its own {} over the replaced world.toml's, which differed",
            carried.replaced.join(", ")
        )?;
    }
    Ok(())
}
