//! `verdant check`: every stored tile of a world read as the renderer reads it (each file within
//! its size, decoded, checked against the manifest and against its stamp), and every plant file
//! it names, on disk or over HTTP, so that a world copied, mirrored or edited by hand can be
//! checked before it is flown.

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

/// A tile that cannot be read, and why.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FailedTile {
    /// The tile.
    pub tile: TileId,
    /// Why, as a message naming the file.
    pub error: String,
}

/// A plant type whose file cannot be read, and why.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FailedPlant {
    /// The plant type's name.
    pub plant_type: String,
    /// Why, as a message naming the file.
    pub error: String,
}

/// What a check found.
#[derive(Debug, serde::Serialize)]
pub struct CheckReport {
    /// The world's stored tiles.
    pub tiles: u64,
    /// Tiles read (all of them unless the check was stopped).
    pub checked: u64,
    /// Each tile that cannot be read, with why, coarsest level first.
    pub failed: Vec<FailedTile>,
    /// The plant types drawn from a glTF file of the world's (read first, as the renderer reads
    /// them before its first frame).
    pub plant_files: u64,
    /// Each of those whose file (or a buffer or image it names) cannot be read or is refused.
    pub failed_plants: Vec<FailedPlant>,
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
    // The plant files are read on a thread of their own beside the tiles, so that a cancel
    // does not wait on a server that holds one back.
    let plants: Arc<Mutex<Option<Vec<FailedPlant>>>> = Arc::default();
    {
        let (world, source, plants) = (world.clone(), Arc::clone(&source), Arc::clone(&plants));
        let reader = move || {
            let checked = check_plants(&world, source.as_ref());
            *plants.lock().unwrap_or_else(|e| e.into_inner()) = Some(checked);
        };
        if let Err(source) = std::thread::Builder::new()
            .name("check-plants".into())
            .spawn(reader)
        {
            return Err(WorldError::Threads { source });
        }
    }
    let plants_read = || plants.lock().unwrap_or_else(|e| e.into_inner()).is_some();
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
    while (shared.finished.load(Ordering::Acquire) < started || !plants_read())
        && !cancel.is_cancelled()
    {
        let now = shared.done.load(Ordering::Relaxed);
        if now != shown {
            progress(now, total);
            shown = now;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let interrupted = cancel.is_cancelled();
    let checked = shared.done.load(Ordering::Relaxed);
    // Stopped before the plant files were read: none counted as failed.
    let failed_plants = plants.lock().unwrap_or_else(|e| e.into_inner()).take();
    let plants_read_at_end = failed_plants.is_some();
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
        failed: failed
            .into_iter()
            .map(|(_, tile, error)| FailedTile { tile, error })
            .collect(),
        plant_files: plant_file_types(world).count() as u64,
        failed_plants: failed_plants.unwrap_or_default(),
        stamped: world.manifest.bake_id.is_some(),
        interrupted: interrupted || checked < total || !plants_read_at_end,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The plant types of `world` drawn from a glTF file of its own (not a recipe).
fn plant_file_types(world: &World) -> impl Iterator<Item = &crate::world::PlantType> {
    world
        .manifest
        .plant_types
        .iter()
        .filter(|t| crate::plants::recipe::Recipe::from_name(&t.mesh).is_none())
}

/// Reads the glTF file of each of `world`'s plant types that names one, from `source`, as the
/// renderer does before its first frame (every buffer and image, the checks and the reduced
/// levels): each that fails.
fn check_plants(world: &World, source: &dyn TileSource) -> Vec<FailedPlant> {
    let read =
        |path: &std::path::Path| crate::plants::gltf::read_from_source(source, &world.dir, path);
    plant_file_types(world)
        .filter_map(|t| {
            let e = crate::plants::set::model_with(t, &world.dir, &read).err()?;
            Some(FailedPlant {
                plant_type: t.name.clone(),
                error: e.to_string(),
            })
        })
        .collect()
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
    pub failed: Vec<FailedTile>,
    /// The id the files were stamped with (the manifest's new `bake_id`); `None` where nothing
    /// was written.
    pub bake_id: Option<String>,
    /// Temporaries of tile files that killed or failed writers left in `tiles/` (over a
    /// minute old), removed before the stamping.
    pub temporaries_removed: usize,
    /// Wall-clock time, seconds.
    pub seconds: f64,
}

/// Stamps every tile file of the world in `dir` as a bake would ([`crate::world::format::stamp`]),
/// for a world written by hand or by other tools, or one whose maps were edited by hand.
///
/// Nothing is written unless every tile reads (checked as the renderer checks it, but for the
/// stamps it carries now: those that cannot are listed in the report), no file to be rewritten is
/// a symbolic link (rewriting it would replace the link, its target, perhaps another world's,
/// left as it was) and every folder to be written to takes a file. The id is a fingerprint of the
/// tiles' samples, so stamping a world again that has not changed gives the same id and files.
/// The manifest then loses its `bake_id`, every file is written again stamped, keeping its
/// permissions, and the manifest gets the new id last, each rewrite atomic: a stamping stopped
/// half way (Ctrl-C through `cancel`, a full disk) leaves a world that reads, unchecked, and is
/// a [`WorldError::StampIncomplete`]; stamping it again finishes the work. The manifest's text is
/// kept as it is (comments and all) but for its `bake_id` ([`with_bake_id`]). A stop before
/// anything was written is a [`WorldError::Cancelled`]. `progress(done, total)` counts tiles
/// over both passes.
pub fn stamp_world(
    dir: &std::path::Path,
    cancel: Option<&CancelFlag>,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<StampReport, WorldError> {
    use crate::world::format::{write_atomic, write_tile_with};
    use crate::world::{TileFile, tile_path};
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
    let kinds: Vec<TileFile> = TileFile::ALL
        .into_iter()
        .chain(world.manifest.materials.then_some(TileFile::Material))
        .collect();
    let tiles: Vec<TileId> = world.stored_tiles().collect();
    let total = 2 * tiles.len() as u64;
    let refuse = |path: &std::path::Path, why: String| WorldError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::other(format!(
            "{why}; --stamp rewrites every tile file and world.toml in place: nothing was written"
        )),
    };
    let is_link = |path: &std::path::Path| {
        std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
    };
    if is_link(&manifest_path) {
        return Err(refuse(
            &manifest_path,
            "a symbolic link: stamp the world it leads to, or copy the file in".into(),
        ));
    }
    // A linked tiles/ or level folder would have another world's files rewritten through it.
    let tiles_dir = dir.join("tiles");
    let levels = (0..world.manifest.pyramid.stored_levels).map(|l| tiles_dir.join(format!("L{l}")));
    if let Some(link) = std::iter::once(tiles_dir.clone())
        .chain(levels)
        .find(|p| is_link(p))
    {
        return Err(refuse(
            &link,
            "a symbolic link to a folder: its files may be another world's; copy the folder in, \
             or stamp the world it belongs to"
                .into(),
        ));
    }
    // What a writer killed (or failed) part-way left beside the tiles goes first; a minute
    // old, so that another stamping's write under way is not taken for one (one stalled that
    // long would find its temporary gone and fail, naming the file: nothing is lost).
    let temporaries_removed = crate::world::format::sweep_tile_temporaries(
        &tiles_dir,
        std::time::Duration::from_secs(60),
    );
    progress(0, total);
    // The first pass reads every tile and fingerprints its samples.
    let mut hash = crate::hash::FNV_BASIS;
    let mut failed = Vec::new();
    for (k, &id) in tiles.iter().enumerate() {
        stopped()?;
        if let Some(link) = kinds
            .iter()
            .map(|&kind| tile_path(dir, id, kind))
            .find(|p| is_link(p))
        {
            return Err(refuse(
                &link,
                "a symbolic link: copy the file in, or stamp the world it belongs to".into(),
            ));
        }
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
            Err(e) => failed.push(FailedTile {
                tile: id,
                error: e.to_string(),
            }),
        }
        progress(k as u64 + 1, total);
    }
    let report = |failed, bake_id| StampReport {
        tiles: tiles.len() as u64,
        failed,
        bake_id,
        temporaries_removed,
        seconds: start.elapsed().as_secs_f64(),
    };
    if !failed.is_empty() {
        return Ok(report(failed, None));
    }
    // Every folder written to takes a file (a read-only one would stop the work half way).
    let folders = std::iter::once(dir.to_path_buf()).chain(
        (0..world.manifest.pyramid.stored_levels)
            .map(|level| dir.join("tiles").join(format!("L{level}"))),
    );
    for folder in folders {
        let probe = folder.join(format!(".verdant-stamp-probe.{}", std::process::id()));
        match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&probe)
        {
            Ok(_) => {
                let _ = std::fs::remove_file(&probe);
            }
            Err(e) => return Err(refuse(&folder, format!("cannot write a file here ({e})"))),
        }
    }
    let bake_id = format!("{hash:016x}");
    let text =
        std::fs::read_to_string(&manifest_path).map_err(|e| WorldError::io(&manifest_path, e))?;
    let without = with_bake_id(&text, None, &manifest_path)?;
    let with = with_bake_id(&text, Some(&bake_id), &manifest_path)?;
    let manifest_mode = std::fs::metadata(&manifest_path)
        .map(|m| m.permissions())
        .map_err(|e| WorldError::io(&manifest_path, e))?;
    // A file written again keeps the permissions it had.
    let rewrite_manifest = |text: &str| -> Result<(), WorldError> {
        write_atomic(&manifest_path, text.as_bytes())?;
        std::fs::set_permissions(&manifest_path, manifest_mode.clone())
            .map_err(|e| WorldError::io(&manifest_path, e))
    };
    let pyramid = &world.manifest.pyramid;
    let mut write_pass = || -> Result<(), WorldError> {
        if without != text {
            rewrite_manifest(&without)?;
        }
        // The second pass writes every file again, stamped.
        for (k, &id) in tiles.iter().enumerate() {
            stopped()?;
            let modes = kinds
                .iter()
                .map(|&kind| {
                    let path = tile_path(dir, id, kind);
                    std::fs::metadata(&path)
                        .map(|m| (path.clone(), m.permissions()))
                        .map_err(|e| WorldError::io(&path, e))
                })
                .collect::<Result<Vec<_>, _>>()?;
            let tile = unchecked.load_tile(id)?;
            write_tile_with(dir, pyramid, &tile, Some(hash))?;
            for (path, mode) in modes {
                std::fs::set_permissions(&path, mode).map_err(|e| WorldError::io(&path, e))?;
            }
            progress((tiles.len() + k) as u64 + 1, total);
        }
        rewrite_manifest(&with)
    };
    write_pass().map_err(|source| WorldError::StampIncomplete {
        path: dir.to_path_buf(),
        source: Box::new(source),
    })?;
    Ok(report(Vec::new(), Some(bake_id)))
}

/// A manifest's `text` with its top-level `bake_id` set to `id`, or removed; everything else
/// (comments, layout, line endings) as it was, as `toml_edit` keeps a document. The result is
/// parsed again and refused (naming `path`) unless it says what was meant.
pub fn with_bake_id(
    text: &str,
    id: Option<&str>,
    path: &std::path::Path,
) -> Result<String, WorldError> {
    let syntax = |message: String| WorldError::ManifestSyntax {
        path: path.to_path_buf(),
        message,
    };
    // A byte-order mark and the want of a last line break are kept too.
    let (bom, body) = match text.strip_prefix('\u{feff}') {
        Some(body) => ("\u{feff}", body),
        None => ("", text),
    };
    let mut doc: toml_edit::DocumentMut = body.parse().map_err(|e| syntax(format!("{e}")))?;
    match (id, doc.get_mut("bake_id")) {
        // Rewritten in place, its spacing and comment kept.
        (Some(id), Some(toml_edit::Item::Value(old))) => {
            let decor = old.decor().clone();
            *old = toml_edit::Value::from(id);
            *old.decor_mut() = decor;
        }
        // New: after the manifest's last top-level key, where the baker writes it.
        (Some(id), _) => {
            doc.insert("bake_id", toml_edit::value(id));
        }
        (None, _) => {
            doc.remove("bake_id");
        }
    }
    let mut out = doc.to_string();
    // A file of CRLF lines stays one: the lines the document writes anew end in LF.
    if body.contains("\r\n") && !body.replace("\r\n", "").contains('\n') {
        out = out.replace("\r\n", "\n").replace('\n', "\r\n");
    }
    if !body.is_empty() && !body.ends_with('\n') {
        let trimmed = out.trim_end_matches(['\r', '\n']).len();
        out.truncate(trimmed);
    }
    let out = format!("{bom}{out}");
    let parsed = crate::world::Manifest::parse(&out, path)?;
    if parsed.bake_id.as_deref() != id {
        return Err(syntax(
            "its top-level bake_id could not be rewritten (a manifest is expected to hold it as \
             a key of its own, before its first table)"
                .into(),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::with_bake_id;
    use std::path::Path;

    const MANIFEST: &str = "# A world.\nname = \"w\"\nextent_m = [100.0, 100.0]\nheight_range_m = [0.0, 1.0]\n\n# The pyramid.\n[pyramid]\nroot_tile_size_m = 64.0\nroot_tiles = [2, 2]\ntile_cells = 16\nborder = 2\nstored_levels = 1\nderived_levels = 0\n\n[[grass_types]]\nname = \"bare\"\nground_color = [0.3, 0.3, 0.3]\nbase_color = [0.3, 0.3, 0.3]\ntip_color = [0.3, 0.3, 0.3]\nheight_m = [0.0, 0.0]\nwidth_m = [0.0, 0.0]\nstiffness = 1.0\n";

    /// The bake_id goes in after the last top-level key (where the baker writes it), is
    /// rewritten in place, and comes out again; every other line (comments included) stays as
    /// it was, in a manifest of CRLF lines too, and so does a bake_id's look-alike in a
    /// multi-line string.
    #[test]
    fn a_manifests_bake_id_is_put_in_replaced_and_taken_out_alone() {
        let path = Path::new("w/world.toml");
        let with = with_bake_id(MANIFEST, Some("0123456789abcdef"), path).unwrap();
        assert_eq!(
            with,
            MANIFEST.replace(
                "height_range_m = [0.0, 1.0]\n",
                "height_range_m = [0.0, 1.0]\nbake_id = \"0123456789abcdef\"\n"
            )
        );
        let again = with_bake_id(&with, Some("fedcba9876543210"), path).unwrap();
        assert_eq!(again, with.replace("0123456789abcdef", "fedcba9876543210"));
        assert_eq!(with_bake_id(&again, None, path).unwrap(), MANIFEST);
        // Where a hand put it, with its comment, quoted: rewritten in place.
        let placed = MANIFEST.replace(
            "name = \"w\"\n",
            "name = \"w\"\n\"bake_id\" = \"0123456789abcdef\" # stamped\n",
        );
        let restamped = with_bake_id(&placed, Some("fedcba9876543210"), path).unwrap();
        assert_eq!(
            restamped,
            placed.replace("0123456789abcdef", "fedcba9876543210")
        );
        // A multi-line description holding a line like it is text, kept.
        let described = MANIFEST.replace(
            "name = \"w\"\n",
            "name = \"w\"\ndescription = \"\"\"\nbake_id = \"0000000000000000\"\n[x]\n\"\"\"\n",
        );
        let out = with_bake_id(&described, Some("0123456789abcdef"), path).unwrap();
        assert!(
            out.contains("\"\"\"\nbake_id = \"0000000000000000\"\n[x]\n\"\"\""),
            "{out}"
        );
        assert_eq!(with_bake_id(&out, None, path).unwrap(), described);
        // CRLF lines stay CRLF.
        let crlf = MANIFEST.replace('\n', "\r\n");
        let out = with_bake_id(&crlf, Some("0123456789abcdef"), path).unwrap();
        assert_eq!(out, with.replace('\n', "\r\n"));
        // A byte-order mark and a last line without a break stay as they were.
        let marked = format!("\u{feff}{}", MANIFEST.trim_end());
        let out = with_bake_id(&marked, Some("0123456789abcdef"), path).unwrap();
        assert!(
            out.starts_with('\u{feff}') && out.ends_with("stiffness = 1.0"),
            "{out:?}"
        );
        assert_eq!(with_bake_id(&out, None, path).unwrap(), marked);
        // A bake_id inside a table is the table's (and refused by the manifest).
        let inside = MANIFEST.replace("stiffness = 1.0\n", "stiffness = 1.0\nbake_id = \"x\"\n");
        assert!(with_bake_id(&inside, Some("0123456789abcdef"), path).is_err());
    }
}
