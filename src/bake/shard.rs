//! Sharded bakes, for a batch engine: `verdant bake ... --shard I/N` writes only shard `I`'s
//! share of the tiles into a parts folder beside the output (`PARENT/.NAME.shards/`), and
//! `verdant bake ... --finish-shards N`, once every shard is done, writes the tiles that cross
//! shards, moves the tiles into the output and writes `world.toml` last, so that a world is never
//! seen half-made.
//!
//! - **The shares.** The tiles of the *split level* (the coarsest level with at least four
//!   tiles a shard, else the finest) are dealt out in row-major runs, `N` runs of nearly equal
//!   length; a shard writes its split-level tiles and every finer tile under them. The few
//!   coarser tiles, which cross shards, are the finish step's.
//! - **Idempotent.** Tiles are written atomically (a temporary file renamed into place), and a
//!   shard records `done/I-of-N.json` last: a killed shard leaves no record, and its re-run
//!   writes its share again; a shard whose record matches its options is not run again. The
//!   record and the folder carry a fingerprint of the bake's options and of its input files
//!   (size and modification time), so that shards of different bakes are never mixed: a parts
//!   folder of another bake is refused, naming it.
//! - **The same world.** Every shard computes the whole bake (the heights, the paint, the
//!   manifest) and writes only its tiles and the manifest, so the sharded world is byte for
//!   byte the unsharded one (`tests/bake_shards.rs`); the finish computes the bake again only
//!   where tiles cross shards, and otherwise publishes the shards' manifest. The heights are
//!   still held whole in memory by each shard.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::world::error::WorldError;
use crate::world::format::{TileFile, tile_path, write_atomic};
use crate::world::tile::{Pyramid, TileId};

use super::{BakeOptions, BakeReport};

/// Most shards a bake is split into.
pub const MAX_SHARDS: u32 = 10_000;

/// What part of a sharded bake a run does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardStep {
    /// Shard `index` (0-based) of `count`: its share of the tiles, into the parts folder.
    Shard {
        /// This shard, `0..count`.
        index: u32,
        /// How many shards.
        count: u32,
    },
    /// The finish: the tiles that cross shards, then the world published whole.
    Finish {
        /// How many shards there were.
        count: u32,
    },
}

impl ShardStep {
    /// The shard count.
    pub fn count(self) -> u32 {
        match self {
            ShardStep::Shard { count, .. } | ShardStep::Finish { count } => count,
        }
    }

    /// Refuses a count outside `1..=MAX_SHARDS` and an index not below the count.
    pub fn check(self) -> Result<(), WorldError> {
        let count = self.count();
        if !(1..=MAX_SHARDS).contains(&count) {
            let option = match self {
                ShardStep::Shard { .. } => "--shard",
                ShardStep::Finish { .. } => "--finish-shards",
            };
            return Err(WorldError::bad_option(
                option,
                count,
                format!("a shard count in 1..={MAX_SHARDS}"),
            ));
        }
        if let ShardStep::Shard { index, count } = self
            && index >= count
        {
            return Err(WorldError::bad_option(
                "--shard",
                format!("{index}/{count}"),
                format!("I/N with I in 0..{count}"),
            ));
        }
        Ok(())
    }
}

/// The parts folder of a sharded bake into `out` (resolved): `PARENT/.NAME.shards`.
pub fn parts_dir(out: &Path) -> PathBuf {
    let name = out
        .file_name()
        .map_or_else(|| "world".into(), |n| n.to_string_lossy().into_owned());
    out.with_file_name(format!(".{name}.shards"))
}

/// The level whose tiles are dealt out: the coarsest with at least four tiles a shard, else the
/// finest stored level.
pub fn split_level(pyramid: &Pyramid, count: u32) -> u8 {
    let finest = pyramid.stored_levels - 1;
    (0..=finest)
        .find(|&l| {
            let [nx, ny] = pyramid.tiles_at(l);
            u64::from(nx) * u64::from(ny) >= 4 * u64::from(count)
        })
        .unwrap_or(finest)
}

/// The shard that writes tile `id`, or `None` for a tile coarser than the split level (the
/// finish step's).
pub fn owner(pyramid: &Pyramid, count: u32, id: TileId) -> Option<u32> {
    let level = split_level(pyramid, count);
    let a = id.ancestor_at(level)?;
    let [nx, ny] = pyramid.tiles_at(level);
    let total = u64::from(nx) * u64::from(ny);
    let k = u64::from(a.y) * u64::from(nx) + u64::from(a.x);
    Some((k * u64::from(count) / total) as u32)
}

/// FNV-1a, 64 bits: a fingerprint that is the same in every build.
/// A fingerprint of what a bake makes: its options (but not where it writes or how it is run)
/// and the size and modification time of every input file.
pub fn fingerprint(opts: &BakeOptions, dem_files: &[PathBuf]) -> Result<String, WorldError> {
    let text = inputs(opts, dem_files, true, None)?;
    Ok(format!(
        "{:016x}",
        crate::hash::fnv1a64(crate::hash::FNV_BASIS, text.as_bytes())
    ))
}

/// The id a bake stamps its tiles with (the manifest's `bake_id`, 16 hexadecimal digits): a
/// fingerprint of what makes the tiles (the [`fingerprint`]'s inputs but the world's name, which
/// is the manifest's alone) and of the crate's version. Every shard of a sharded bake and its
/// finish agree on it without a word between them, and a bake of the same inputs by the same
/// version writes the same tiles, byte for byte.
pub fn bake_id(opts: &BakeOptions, dem_files: &[PathBuf]) -> Result<String, WorldError> {
    Ok(bake_id_of(&input_record(opts, dem_files)?))
}

/// The [`bake_id`] of a bake whose [`input_record`] is `record`.
pub(super) fn bake_id_of(record: &str) -> String {
    let text = format!("{record}version {}\n", env!("CARGO_PKG_VERSION"));
    format!(
        "{:016x}",
        crate::hash::fnv1a64(crate::hash::FNV_BASIS, text.as_bytes())
    )
}

/// The record of a bake's input files as they are now (each one's size and modification time,
/// what [`bake_id`] hashes), for [`check_inputs_unchanged`] at the bake's end.
pub(super) fn input_record(
    opts: &BakeOptions,
    dem_files: &[PathBuf],
) -> Result<String, WorldError> {
    inputs(opts, dem_files, false, None)
}

/// Refuses a bake whose input files changed since `record` was taken at its start: tiles cut
/// from a DEM rewritten half way through mix its two versions, under the id of the first.
/// Names the first file that changed (or went).
pub(super) fn check_inputs_unchanged(
    opts: &BakeOptions,
    dem_files: &[PathBuf],
    record: &str,
) -> Result<(), WorldError> {
    let changed = |path: PathBuf| WorldError::Io {
        path,
        source: std::io::Error::other(
            "changed while the bake read it (its size or modification time is not what it was \
             at the bake's start): nothing was written to the output folder; bake again once it \
             has stopped changing",
        ),
    };
    // A file at an address is not asked for again: a change of it while the bake read it is
    // refused as its ranges are read (`RangeFile`), and after the last read it cannot matter.
    let now = match inputs(opts, dem_files, false, Some(record)) {
        Ok(now) => now,
        Err(e) => {
            return Err(changed(
                e.path().map_or_else(|| opts.dem.clone(), Path::to_path_buf),
            ));
        }
    };
    if now == record {
        return Ok(());
    }
    // Each file's line is "PATH SIZE MTIME": the first that differs names the file.
    let file = |line: &str| line.rsplitn(3, ' ').nth(2).map(PathBuf::from);
    let differs = record
        .lines()
        .zip(now.lines())
        .find(|(a, b)| a != b)
        .and_then(|(a, _)| file(a));
    Err(changed(differs.unwrap_or_else(|| opts.dem.clone())))
}

/// What [`fingerprint`] and [`bake_id`] hash (a file at an address taken from `known`, a
/// record made before, where it is in it): the options that shape the world (its `name` only
/// with `with_name`) and each input file's size and modification time (of a file at an
/// address, its length, `ETag` and `Last-Modified` as its server gives them): the DEM files, the files
/// the user named (a VRT that lists DEMs, a folder's files), a PNG DEM's JSON sidecar (its
/// heights' scale and cells), the land-cover map and table, the density map and the mask. For
/// the [`bake_id`] (`with_name` false) each file is named by its canonical path, so that two
/// spellings of one file (`./dem.png`, `/data/dem.png`) give one id.
fn inputs(
    opts: &BakeOptions,
    dem_files: &[PathBuf],
    with_name: bool,
    known: Option<&str>,
) -> Result<String, WorldError> {
    let name = opts.name.as_deref();
    let mut text = if with_name {
        format!(
            "dem {:?} more {:?} dem_cell {:?} name {:?} cell {:?} tile_cells {} levels {} seed {} \
             cover {:?} density {:?} mask {:?}\n",
            opts.dem,
            opts.more_dems,
            opts.dem_cell_size_m,
            name,
            opts.cell_size_m,
            opts.tile_cells,
            opts.stored_levels,
            opts.seed,
            opts.land_cover,
            opts.density_map,
            opts.mask
        )
    } else {
        // The files are named below, by their canonical paths, each with its role's place in
        // the list; how the user spelled them does not matter.
        format!(
            "dem_cell {:?} cell {:?} tile_cells {} levels {} seed {} cover {} density {} mask {}\n",
            opts.dem_cell_size_m,
            opts.cell_size_m,
            opts.tile_cells,
            opts.stored_levels,
            opts.seed,
            opts.land_cover.is_some(),
            opts.density_map.is_some(),
            opts.mask.is_some()
        )
    };
    let mut inputs: Vec<PathBuf> = dem_files.to_vec();
    for named in std::iter::once(&opts.dem).chain(&opts.more_dems) {
        if named.is_file() && !inputs.contains(named) {
            inputs.push(named.clone());
        }
    }
    let sidecars: Vec<PathBuf> = inputs
        .iter()
        .filter_map(|p| crate::world::dem::sidecar_of(p))
        .filter(|s| s.is_file())
        .collect();
    inputs.extend(sidecars);
    if let Some((map, table)) = &opts.land_cover {
        inputs.push(map.clone());
        if table.is_file() {
            inputs.push(table.clone());
        }
    }
    inputs.extend(opts.density_map.clone());
    inputs.extend(opts.mask.clone());
    for p in &inputs {
        if crate::world::window::is_remote(p) {
            // An address: its length and validators as its server gives them now (one request
            // for its first byte), in place of a size and a modification time; or its line of
            // a record `known` already.
            let start = format!("{} ", p.display());
            if let Some(line) = known.and_then(|k| k.lines().find(|l| l.starts_with(&start))) {
                text.push_str(line);
                text.push('\n');
                continue;
            }
            #[cfg(feature = "http")]
            {
                let url = p.to_string_lossy();
                let file = crate::stream::http::RangeFile::open(&url, Default::default())?;
                text.push_str(&format!("{} {} -\n", p.display(), file.identity()));
            }
            #[cfg(not(feature = "http"))]
            text.push_str(&format!("{}\n", p.display()));
            continue;
        }
        let p = match with_name {
            true => p.clone(),
            false => p.canonicalize().unwrap_or_else(|_| p.clone()),
        };
        let p = p.as_path();
        let meta = std::fs::metadata(p).map_err(|e| WorldError::io(p, e))?;
        let modified = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_nanos());
        text.push_str(&format!("{} {} {modified}\n", p.display(), meta.len()));
    }
    Ok(text)
}

/// The fingerprint record of a bake of `count` shards.
fn record(fingerprint: &str, count: u32) -> String {
    format!("{fingerprint} {count}\n")
}

/// What a finished shard records.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Done {
    fingerprint: String,
    report: BakeReport,
}

/// The parts folder of one sharded bake.
pub(super) struct Parts {
    pub(super) dir: PathBuf,
    fingerprint: String,
    count: u32,
    /// The step this run takes, for its errors' option.
    step: ShardStep,
}

/// The file in a parts folder that holds its bake's fingerprint record ([`Parts::record`]).
pub(super) const FINGERPRINT_FILE: &str = "fingerprint";

impl Parts {
    /// The parts folder for a bake into `out` of `count` shards, checked but not yet made:
    /// refuses one that holds another bake's parts, or files that are not a bake's. Nothing is
    /// written until [`Parts::claim`], so that a bake refused for its input (a DEM read and found
    /// wanting) leaves no parts folder behind to refuse the next, corrected, bake.
    pub(super) fn open(
        out: &Path,
        step: ShardStep,
        fingerprint: String,
    ) -> Result<Parts, WorldError> {
        let parts = Parts {
            dir: parts_dir(out),
            fingerprint,
            count: step.count(),
            step,
        };
        parts.check(false)?;
        Ok(parts)
    }

    /// Makes the parts folder where it does not exist and records this bake's fingerprint in
    /// it, checking again (another shard may have made it since [`Parts::open`]).
    pub(super) fn claim(&self) -> Result<(), WorldError> {
        self.check(true)
    }

    fn check(&self, claim: bool) -> Result<(), WorldError> {
        let dir = &self.dir;
        if claim {
            std::fs::create_dir_all(dir).map_err(|e| WorldError::io(dir, e))?;
        }
        let record = self.record();
        let file = dir.join(FINGERPRINT_FILE);
        match std::fs::read_to_string(&file) {
            Ok(found) if found == record => {}
            Ok(found) => return Err(self.not_ours(&found)),
            Err(_) => {
                // A folder of that name that is not a bake's parts (it holds anything but
                // another shard's fingerprint being written) is the user's: never adopted, so
                // that the finish, which removes the parts folder, removes nothing of theirs.
                let theirs = match std::fs::read_dir(dir) {
                    Ok(entries) => entries
                        .filter_map(Result::ok)
                        .any(|e| !e.file_name().to_string_lossy().starts_with(".fingerprint.")),
                    Err(e) if !claim && e.kind() == std::io::ErrorKind::NotFound => false,
                    Err(e) => return Err(WorldError::io(dir, e)),
                };
                if theirs {
                    return Err(WorldError::bad_option(
                        "--shard",
                        dir.display(),
                        "a folder for the shards' parts: this one exists and holds files that \
                         are not a sharded bake's; move it away"
                            .into(),
                    ));
                }
                if claim {
                    write_atomic(&file, record.as_bytes())?;
                }
            }
        }
        Ok(())
    }

    /// The error for a parts folder whose fingerprint file holds `found`, not this bake's record:
    /// the same bake in another count of shards names the count to use; any other bake says
    /// that its options or input files differ.
    fn not_ours(&self, found: &str) -> WorldError {
        let (option, value, index) = match self.step {
            ShardStep::Shard { index, count } => {
                ("--shard", format!("{index}/{count}"), Some(index))
            }
            ShardStep::Finish { count } => ("--finish-shards", count.to_string(), None),
        };
        let dir = self.dir.display();
        let mut words = found.split_whitespace();
        let (theirs, their_count) = (
            words.next(),
            words.next().and_then(|n| n.parse::<u32>().ok()),
        );
        let allowed = match (theirs, their_count) {
            (Some(f), Some(n)) if f == self.fingerprint => {
                let again = match index {
                    Some(i) if i < n => format!("--shard {i}/{n}"),
                    Some(_) => format!("--shard I/{n} (I from 0 to {})", n - 1),
                    None => format!("--finish-shards {n}"),
                };
                format!(
                    "the shard count of the bake whose parts are in {dir}: this same bake (its \
                     options and input files) was sharded {n} ways there, not {}; run {again}, \
                     or remove the folder to start again in {} shards",
                    self.count, self.count
                )
            }
            _ => format!(
                "the parts of the same bake: {dir} holds the parts of another bake, made with \
                 other options or input files ({}); finish that bake with the options it was \
                 given, or remove the folder",
                found.trim()
            ),
        };
        WorldError::bad_option(option, value, allowed)
    }

    /// What the parts folder's fingerprint file holds.
    pub(super) fn record(&self) -> String {
        record(&self.fingerprint, self.count)
    }

    fn done_path(&self, index: u32) -> PathBuf {
        self.dir
            .join("done")
            .join(format!("{index}-of-{}.json", self.count))
    }

    /// The report of shard `index` if it is done (for this bake).
    pub(super) fn done(&self, index: u32) -> Option<BakeReport> {
        let text = std::fs::read_to_string(self.done_path(index)).ok()?;
        let done: Done = serde_json::from_str(&text).ok()?;
        (done.fingerprint == self.fingerprint).then_some(done.report)
    }

    /// Records shard `index` as done, with its report.
    pub(super) fn mark_done(&self, index: u32, report: &BakeReport) -> Result<(), WorldError> {
        let done = Done {
            fingerprint: self.fingerprint.clone(),
            report: report.clone(),
        };
        let text = serde_json::to_string_pretty(&done).unwrap_or_default();
        write_atomic(&self.done_path(index), text.as_bytes())
    }

    /// Refuses to finish while any shard is not done, naming them.
    pub(super) fn check_all_done(&self) -> Result<(), WorldError> {
        let missing: Vec<String> = (0..self.count)
            .filter(|&i| self.done(i).is_none())
            .map(|i| i.to_string())
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        Err(WorldError::bad_option(
            "--finish-shards",
            self.count,
            format!(
                "every shard done first: shard{} {} of {} not done (run them with --shard I/{})",
                if missing.len() == 1 { "" } else { "s" },
                missing.join(", "),
                self.count,
                self.count
            ),
        ))
    }

    /// Refuses to finish where a shard recorded done lacks any of its tiles' files in the parts
    /// folder (a finish of an older version that was stopped, a file removed by hand): the
    /// world would be published without them. Names the first file missing and every shard
    /// missing one, and removes those shards' records, so that running them again writes
    /// their tiles again.
    ///
    /// Each tile is then read as the renderer reads it (`options`: the finished manifest's
    /// ranges and bake id), on every core: a file cut short, or another tile's or another
    /// bake's (a shared volume's lost write, a part copied from elsewhere), fails the finish
    /// as a missing one does.
    pub(super) fn check_tiles(
        &self,
        pyramid: &Pyramid,
        options: &crate::world::format::ReadOptions,
    ) -> Result<(), WorldError> {
        let kinds: Vec<TileFile> = TileFile::ALL
            .into_iter()
            .chain(options.materials.then_some(TileFile::Material))
            .collect();
        let mut missing = std::collections::BTreeSet::new();
        let mut first = None;
        let mut present = Vec::new();
        for id in super::tiles::stored_tiles(pyramid) {
            let Some(shard) = owner(pyramid, self.count, id) else {
                continue;
            };
            if missing.contains(&shard) {
                continue;
            }
            let absent = kinds
                .iter()
                .map(|&kind| tile_path(&self.dir, id, kind))
                .find(|path| !path.is_file());
            match absent {
                Some(path) => {
                    missing.insert(shard);
                    first.get_or_insert((path, "missing".to_string()));
                }
                None => present.push((id, shard)),
            }
        }
        if first.is_none() {
            // Every file is there: each read whole, in order, the first failure kept.
            let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
            let chunk = present.len().div_ceil(threads).max(1);
            let bad: Vec<(TileId, u32, WorldError)> = std::thread::scope(|scope| {
                let workers: Vec<_> = present
                    .chunks(chunk)
                    .map(|part| {
                        scope.spawn(move || {
                            part.iter()
                                .filter_map(|&(id, shard)| {
                                    crate::world::format::read_tile_with(
                                        &self.dir, pyramid, id, options,
                                    )
                                    .err()
                                    .map(|e| (id, shard, e))
                                })
                                .collect::<Vec<_>>()
                        })
                    })
                    .collect();
                workers
                    .into_iter()
                    .flat_map(|w| w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                    .collect()
            });
            for (id, shard, e) in bad {
                missing.insert(shard);
                if first.is_none() {
                    let path = e
                        .path()
                        .map(Path::to_path_buf)
                        .unwrap_or_else(|| tile_path(&self.dir, id, TileFile::Height));
                    let why = match &e {
                        WorldError::Io { source, .. } => source.to_string(),
                        e => {
                            // The message without the file's name, which leads the error.
                            let text = e.to_string();
                            let shown = format!("{}: ", path.display());
                            text.strip_prefix(&shown).unwrap_or(&text).to_string()
                        }
                    };
                    first = Some((path, format!("cannot be read ({why})")));
                }
            }
        }
        let Some((path, why)) = first else {
            return Ok(());
        };
        for &shard in &missing {
            let _ = std::fs::remove_file(self.done_path(shard));
        }
        Err(WorldError::ShardTilesMissing {
            path,
            why,
            parts: self.dir.clone(),
            shards: missing.into_iter().collect(),
            count: self.count,
        })
    }
}
