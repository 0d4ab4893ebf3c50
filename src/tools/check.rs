//! `verdant check`: every stored tile of a world read as the renderer reads it (each file within
//! its size, decoded, checked against the manifest and against its stamp), on disk or over
//! HTTP, so that a world copied, mirrored or edited by hand can be checked before it is flown.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::bake::CancelFlag;
use crate::stream::TileSource;
use crate::world::{TileId, World, WorldError};

/// Most tiles read at once ([`CheckOptions::threads`]).
pub const MAX_CHECK_THREADS: usize = 64;

/// How a world is checked.
#[derive(Clone, Debug, Default)]
pub struct CheckOptions {
    /// Tiles read at once, 1..=[`MAX_CHECK_THREADS`] (several hide an HTTP server's latency).
    pub threads: usize,
    /// Stops the check between tiles once set.
    pub cancel: Option<CancelFlag>,
}

/// What a check found.
#[derive(Debug, serde::Serialize)]
pub struct CheckReport {
    /// The world's stored tiles.
    pub tiles: u64,
    /// Tiles read (all of them unless the check was stopped).
    pub checked: u64,
    /// Each tile that cannot be read, with why, coarsest level first.
    pub failed: Vec<(TileId, String)>,
    /// Whether the world's tile files carry stamps that were checked (its manifest has a
    /// `bake_id`).
    pub stamped: bool,
    /// Whether the check was stopped before every tile was read.
    pub interrupted: bool,
    /// Wall-clock time, seconds.
    pub seconds: f64,
}

/// Reads every stored tile of `world` from `source` (its folder, or its server) on
/// `options.threads` threads; `progress(done, total)` is called from the calling thread as tiles
/// are read. Failures are collected, not returned: a check reports every bad tile. Once
/// `options.cancel` is set no tile is asked for again and the check returns at once, marked
/// interrupted: a read still waiting on its server ends on its own thread (an HTTP source sends
/// no further request for it), its outcome not counted.
pub fn check_world(
    world: &World,
    source: Arc<dyn TileSource>,
    options: &CheckOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CheckReport, WorldError> {
    if !(1..=MAX_CHECK_THREADS).contains(&options.threads) {
        return Err(WorldError::bad_option(
            "--threads",
            options.threads,
            format!("1..={MAX_CHECK_THREADS} tiles read at once"),
        ));
    }
    let start = Instant::now();
    let cancel = options.cancel.clone().unwrap_or_default();
    let shared = Arc::new(Shared {
        tiles: world.stored_tiles().collect(),
        next: AtomicUsize::new(0),
        done: AtomicU64::new(0),
        finished: AtomicUsize::new(0),
        failed: Mutex::new(Vec::new()),
        cancelled: cancel.shared(),
    });
    let total = shared.tiles.len() as u64;
    progress(0, total);
    let mut started = 0;
    for k in 0..options.threads {
        let (shared, source) = (Arc::clone(&shared), Arc::clone(&source));
        let worker = move || shared.work(source.as_ref());
        match std::thread::Builder::new()
            .name(format!("check-{k}"))
            .spawn(worker)
        {
            Ok(_) => started += 1,
            Err(_) if started > 0 => break,
            Err(source) => return Err(WorldError::Threads { source }),
        }
    }
    // The calling thread reports progress while the workers read, and leaves them to their last
    // reads once the check is cancelled.
    let mut shown = u64::MAX;
    while shared.finished.load(Ordering::Acquire) < started && !cancel.is_cancelled() {
        let now = shared.done.load(Ordering::Relaxed);
        if now != shown {
            progress(now, total);
            shown = now;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let interrupted = cancel.is_cancelled();
    let checked = shared.done.load(Ordering::Relaxed);
    progress(checked, total);
    let mut failed = shared
        .failed
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    failed.sort_by_key(|&(k, ..)| k);
    Ok(CheckReport {
        tiles: total,
        checked,
        failed: failed.into_iter().map(|(_, id, e)| (id, e)).collect(),
        stamped: world.manifest.bake_id.is_some(),
        interrupted: interrupted || checked < total,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// What [`check_world`]'s workers share.
struct Shared {
    tiles: Vec<TileId>,
    /// The next tile to read.
    next: AtomicUsize,
    /// Tiles read.
    done: AtomicU64,
    /// Workers that have ended.
    finished: AtomicUsize,
    /// (index, tile, why) of each tile that could not be read.
    failed: Mutex<Vec<(usize, TileId, String)>>,
    cancelled: Arc<AtomicBool>,
}

impl Shared {
    fn work(&self, source: &dyn TileSource) {
        while !self.cancelled.load(Ordering::SeqCst) {
            let k = self.next.fetch_add(1, Ordering::Relaxed);
            let Some(&id) = self.tiles.get(k) else { break };
            let result = source.load_cancellable(id, &self.cancelled);
            if self.cancelled.load(Ordering::SeqCst) {
                // A read cut short by the cancel: neither a failure nor a tile read.
                break;
            }
            if let Err(e) = result {
                self.failed
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .push((k, id, e.to_string()));
            }
            self.done.fetch_add(1, Ordering::Relaxed);
        }
        self.finished.fetch_add(1, Ordering::Release);
    }
}

/// What [`stamp_world`] did.
#[derive(Debug, serde::Serialize)]
pub struct StampReport {
    /// The world's stored tiles.
    pub tiles: u64,
    /// Each tile that cannot be read (its files' stamps aside), with why: where there is one,
    /// nothing was written.
    pub failed: Vec<(TileId, String)>,
    /// The id the files were stamped with (the manifest's new `bake_id`); `None` where nothing
    /// was written.
    pub bake_id: Option<String>,
    /// Wall-clock time, seconds.
    pub seconds: f64,
}

/// Stamps every tile file of the world in `dir` as a bake would ([`crate::world::format::stamp`]),
/// for a world written by hand or by other tools, or one whose maps were edited by hand: every
/// tile is read first (checked as the renderer checks it, but for the stamps it carries now), and
/// where one cannot be read nothing is written. The id is a fingerprint of the tiles' samples, so
/// stamping a world again that has not changed gives the same id. The manifest loses its
/// `bake_id` first and gets the new one last, each rewrite atomic: a stamping stopped half way
/// (Ctrl-C through `cancel`, a full disk) leaves a world that reads, unchecked, and stamping it
/// again finishes the work. The manifest's text is kept as it is (comments and all) but for the
/// one `bake_id` line. `progress(done, total)` counts tiles over both passes.
pub fn stamp_world(
    dir: &std::path::Path,
    cancel: Option<&CancelFlag>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<StampReport, WorldError> {
    use crate::world::format::{write_atomic, write_tile_with};
    let start = Instant::now();
    let world = World::open(dir)?;
    let manifest_path = dir.join("world.toml");
    let stopped = || match cancel {
        Some(c) if c.is_cancelled() => Err(WorldError::Cancelled {
            path: dir.to_path_buf(),
        }),
        _ => Ok(()),
    };
    let mut unchecked = world.clone();
    unchecked.manifest.bake_id = None;
    let tiles: Vec<TileId> = world.stored_tiles().collect();
    let total = 2 * tiles.len() as u64;
    progress(0, total);
    // The first pass reads every tile and fingerprints its samples.
    let mut hash = crate::hash::FNV_BASIS;
    let mut failed = Vec::new();
    for (k, &id) in tiles.iter().enumerate() {
        stopped()?;
        match unchecked.load_tile(id) {
            Ok(tile) => {
                for bytes in [
                    &[id.level][..],
                    &id.x.to_le_bytes(),
                    &id.y.to_le_bytes(),
                    bytemuck::cast_slice(&tile.heights),
                    &tile.grass_type,
                    &tile.density,
                    &tile.material,
                ] {
                    hash = crate::hash::fnv1a64(hash, bytes);
                }
            }
            Err(e) => failed.push((id, e.to_string())),
        }
        progress(k as u64 + 1, total);
    }
    let report = |failed, bake_id| StampReport {
        tiles: tiles.len() as u64,
        failed,
        bake_id,
        seconds: start.elapsed().as_secs_f64(),
    };
    if !failed.is_empty() {
        return Ok(report(failed, None));
    }
    let bake_id = format!("{hash:016x}");
    let text =
        std::fs::read_to_string(&manifest_path).map_err(|e| WorldError::io(&manifest_path, e))?;
    let without = with_bake_id(&text, None, &manifest_path)?;
    let with = with_bake_id(&text, Some(&bake_id), &manifest_path)?;
    if without != text {
        write_atomic(&manifest_path, without.as_bytes())?;
    }
    // The second pass writes every file again, stamped.
    let pyramid = &world.manifest.pyramid;
    for (k, &id) in tiles.iter().enumerate() {
        stopped()?;
        let tile = unchecked.load_tile(id)?;
        write_tile_with(dir, pyramid, &tile, Some(hash))?;
        progress((tiles.len() + k) as u64 + 1, total);
    }
    write_atomic(&manifest_path, with.as_bytes())?;
    Ok(report(Vec::new(), Some(bake_id)))
}

/// A manifest's `text` with its top-level `bake_id` line removed, and, with `id`, a new one
/// before its first table; everything else as it was. The result is parsed again and refused
/// (naming `path`) unless it says what was meant.
pub fn with_bake_id(
    text: &str,
    id: Option<&str>,
    path: &std::path::Path,
) -> Result<String, WorldError> {
    let is_table = |line: &str| line.trim_start().starts_with('[');
    let lines: Vec<&str> = text.split_inclusive('\n').collect();
    let first_table = lines
        .iter()
        .position(|l| is_table(l))
        .unwrap_or(lines.len());
    let is_bake_id = |line: &str| {
        line.trim_start()
            .strip_prefix("bake_id")
            .is_some_and(|rest| rest.trim_start().starts_with('='))
    };
    // The new line goes before the comments over the first table (they are the table's).
    let mut at = first_table;
    while at > 0 && lines[at - 1].trim_start().starts_with('#') {
        at -= 1;
    }
    let mut out = String::with_capacity(text.len() + 32);
    let mut put = false;
    let mut skip_blank = false;
    for (k, line) in lines.iter().enumerate() {
        if k < first_table && is_bake_id(line) {
            // The blank line this function puts after it goes with it.
            skip_blank = true;
            continue;
        }
        if std::mem::take(&mut skip_blank) && line.trim().is_empty() {
            continue;
        }
        if k == at
            && let Some(id) = id
        {
            out.push_str(&format!("bake_id = \"{id}\"\n\n"));
            put = true;
        }
        out.push_str(line);
    }
    if let (Some(id), false) = (id, put) {
        if !out.is_empty() && !out.ends_with('\n') {
            out.push('\n');
        }
        out.push_str(&format!("bake_id = \"{id}\"\n"));
    }
    let parsed = crate::world::Manifest::parse(&out, path)?;
    if parsed.bake_id.as_deref() != id {
        return Err(WorldError::ManifestSyntax {
            path: path.to_path_buf(),
            message: "its bake_id line could not be rewritten: a top-level `bake_id = \"...\"` \
                      line is expected before the first table"
                .into(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::with_bake_id;
    use std::path::Path;

    const MANIFEST: &str = "# A world.\nname = \"w\"\nextent_m = [100.0, 100.0]\nheight_range_m = [0.0, 1.0]\n\n# The pyramid.\n[pyramid]\nroot_tile_size_m = 64.0\nroot_tiles = [2, 2]\ntile_cells = 16\nborder = 2\nstored_levels = 1\nderived_levels = 0\n\n[[grass_types]]\nname = \"bare\"\nground_color = [0.3, 0.3, 0.3]\nbase_color = [0.3, 0.3, 0.3]\ntip_color = [0.3, 0.3, 0.3]\nheight_m = [0.0, 0.0]\nwidth_m = [0.0, 0.0]\nstiffness = 1.0\n";

    /// The bake_id line goes in before the first table, replaces one that is there, and comes
    /// out again; every other line (comments included) stays as it was.
    #[test]
    fn a_manifests_bake_id_line_is_put_in_replaced_and_taken_out_alone() {
        let path = Path::new("w/world.toml");
        let with = with_bake_id(MANIFEST, Some("0123456789abcdef"), path).unwrap();
        assert_eq!(
            with,
            MANIFEST.replace(
                "# The pyramid.\n[pyramid]",
                "bake_id = \"0123456789abcdef\"\n\n# The pyramid.\n[pyramid]"
            )
        );
        let again = with_bake_id(&with, Some("fedcba9876543210"), path).unwrap();
        assert_eq!(again, with.replace("0123456789abcdef", "fedcba9876543210"));
        let without = with_bake_id(&again, None, path).unwrap();
        assert_eq!(without, MANIFEST);
        // A manifest the baker wrote: the line where it put it, replaced in place.
        let baked = MANIFEST.replace(
            "\n# The pyramid.",
            "bake_id = \"0123456789abcdef\"\n\n# The pyramid.",
        );
        let restamped = with_bake_id(&baked, Some("fedcba9876543210"), path).unwrap();
        assert_eq!(
            restamped,
            baked.replace("0123456789abcdef", "fedcba9876543210")
        );
        // A bake_id inside a table is the table's (and refused by the manifest), not replaced.
        let inside = MANIFEST.replace("stiffness = 1.0\n", "stiffness = 1.0\nbake_id = \"x\"\n");
        assert!(with_bake_id(&inside, Some("0123456789abcdef"), path).is_err());
    }
}
