//! Publishing a bake: the staging folder beside the output folder, the safe replacement of
//! `world.toml` and `tiles/`, and the clean-up of killed bakes' staging folders.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

use crate::world::error::WorldError;

/// Refuses an output folder that exists and is not empty, unless it is to be replaced; and a
/// folder to be replaced whose `tiles/` holds anything that is not a tile verdant writes (the
/// replaced `tiles/` is deleted whole).
pub(super) fn check_out(out: &Path, replace: bool) -> Result<(), WorldError> {
    if let Some(world) = crate::world::format::world_whose_tiles_hold(out) {
        return Err(WorldError::bad_option(
            "--out",
            out.display(),
            format!(
                "a folder outside a world's tiles/ (this one is inside {}'s tiles/, which a \
                 world's files would be mixed into); bake into another folder",
                world.display()
            ),
        ));
    }
    if let Some(parent) = mounted_apart(out) {
        return Err(WorldError::bad_option(
            "--out",
            out.display(),
            format!(
                "a folder on its parent folder's file system (this one is where another file \
                 system is mounted: the world is staged beside it, in {}, and could not be \
                 moved in at the end); bake into a folder inside it, such as {}",
                parent.display(),
                out.join("world").display()
            ),
        ));
    }
    match std::fs::symlink_metadata(out) {
        Ok(m) if m.file_type().is_symlink() && std::fs::metadata(out).is_err() => {
            return Err(WorldError::bad_option(
                "--out",
                out.display(),
                "a folder, or a symlink to one (this one points to nothing)".into(),
            ));
        }
        Ok(_) if !out.is_dir() => {
            let what =
                std::fs::metadata(out).map_or("a file", |m| crate::world::format::what_file_is(&m));
            return Err(WorldError::bad_option(
                "--out",
                out.display(),
                format!("a folder (this is {what})"),
            ));
        }
        _ => {}
    }
    match std::fs::read_dir(out) {
        Ok(mut entries) => {
            if entries.next().is_some() && !replace {
                return Err(WorldError::OutputNotEmpty {
                    path: out.to_path_buf(),
                });
            }
            let manifest = out.join("world.toml");
            if std::fs::symlink_metadata(&manifest).is_ok()
                && let Some(why) = not_a_manifest(&manifest)
            {
                return Err(WorldError::bad_option(
                    "--replace",
                    manifest.display(),
                    format!(
                        "a world's manifest to replace (this is not one: {why}); move it away, \
                         or bake into another folder"
                    ),
                ));
            }
            let tiles = out.join("tiles");
            match crate::world::format::first_foreign_in_tiles(&tiles) {
                Ok(None) => {}
                Ok(Some(path)) => return Err(WorldError::ForeignInTiles { path, tiles }),
                Err(e) => return Err(WorldError::io(&tiles, e)),
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(WorldError::io(out, e)),
    }
}
/// Why `path` is not a world's manifest, as far as replacing it goes; `None` for a regular
/// file of at most [`crate::world::manifest::MAX_MANIFEST_BYTES`] with a `[pyramid]` table (one
/// that an older or newer version wrote, or that no longer validates, is still a world's, and
/// so is one damaged by hand that still has its `[pyramid]` header).
fn not_a_manifest(path: &Path) -> Option<String> {
    let bytes = match crate::world::format::read_regular(
        path,
        crate::world::manifest::MAX_MANIFEST_BYTES,
    ) {
        Ok(bytes) => bytes,
        Err(WorldError::MissingFile { .. }) => {
            return Some("a symlink to nothing".into());
        }
        Err(WorldError::NotARegularFile { .. }) => return Some("not a regular file".into()),
        Err(WorldError::FileTooLarge { size, max, .. }) => {
            return Some(format!("{size} bytes, more than a manifest's {max}"));
        }
        Err(e) => return Some(e.to_string()),
    };
    let text = String::from_utf8_lossy(&bytes);
    match text.parse::<toml::Table>() {
        Ok(t) if t.get("pyramid").is_some_and(toml::Value::is_table) => None,
        Ok(_) => Some("no [pyramid] table".into()),
        Err(_) if text.lines().any(|l| l.trim() == "[pyramid]") => None,
        Err(e) => Some(format!(
            "not TOML: {}",
            e.to_string().lines().next().unwrap_or_default()
        )),
    }
}

/// The folder the staging folder would go in (the parent of `out` resolved by
/// [`resolve_out`]) where `out` is a mount point, on another file system than it: a folder
/// cannot be moved across file systems, so the world could not be published there.
fn mounted_apart(out: &Path) -> Option<PathBuf> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let path = resolve_out(out).ok()?;
        let parent = path.parent()?;
        let (here, above) = (
            std::fs::metadata(&path).ok()?,
            std::fs::metadata(parent).ok()?,
        );
        // A bind mount is on the same device as its parent, and a folder cannot be moved into
        // it either: it is known by the mount table.
        (here.is_dir() && (here.dev() != above.dev() || is_mount_point(&path)))
            .then(|| parent.to_path_buf())
    }
    #[cfg(not(unix))]
    {
        let _ = out;
        None
    }
}

/// Whether `path` (resolved) is where a file system is mounted, by the process's mount table
/// (`/proc/self/mountinfo`; false where there is none).
#[cfg(unix)]
fn is_mount_point(path: &Path) -> bool {
    let Ok(table) = std::fs::read_to_string("/proc/self/mountinfo") else {
        return false;
    };
    table.lines().any(|line| {
        line.split(' ')
            .nth(4)
            .is_some_and(|at| Path::new(&unescape_mount_path(at)) == path)
    })
}

/// A mount table's path with its octal escapes (`\040` for a space) undone.
#[cfg(unix)]
fn unescape_mount_path(text: &str) -> std::ffi::OsString {
    use std::os::unix::ffi::OsStringExt;
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let octal = bytes
            .get(i + 1..i + 4)
            .filter(|d| bytes[i] == b'\\' && d.iter().all(|b| (b'0'..=b'7').contains(b)))
            .map(|d| d.iter().fold(0u32, |v, b| v * 8 + u32::from(b - b'0')));
        match octal {
            Some(v) if v <= 0xff => {
                out.push(v as u8);
                i += 4;
            }
            _ => {
                out.push(bytes[i]);
                i += 1;
            }
        }
    }
    std::ffi::OsString::from_vec(out)
}

/// `out` made absolute, without `.` or `..` components or a trailing slash: the longest part
/// that exists is canonicalised (symlinks followed) and the rest appended. The staging folder
/// goes beside this path, so that it is never inside the output folder however `--out` is
/// spelled (`.`, `..`, `w/`, `w/sub/..`).
pub(super) fn resolve_out(out: &Path) -> Result<PathBuf, WorldError> {
    let not_a_folder = || {
        WorldError::bad_option(
            "--out",
            format!("\"{}\"", out.display()),
            "a folder other than the root of the file system".into(),
        )
    };
    if out.as_os_str().is_empty() {
        return Err(not_a_folder());
    }
    let Some(path) =
        crate::world::format::resolve_lexically(out).map_err(|e| WorldError::io(out, e))?
    else {
        return Err(not_a_folder());
    };
    if path.file_name().is_none() || path.parent().is_none() {
        return Err(not_a_folder());
    }
    Ok(path)
}
/// The lock file in a staging folder, locked while its bake runs.
const STAGING_LOCK: &str = "lock";
/// The folder in a staging folder that the new world is written to.
const STAGING_WORLD: &str = "world";
/// The folder in a staging folder that the replaced world is moved to while the new one goes in.
const STAGING_PREVIOUS: &str = "previous";
/// The record of a publish in a staging folder ([`Journal`]), written before its first move.
const STAGING_JOURNAL: &str = crate::world::PUBLISH_JOURNAL;
/// Where a published sharded bake's parts folder goes, to be removed with the staging folder.
const STAGING_SPENT_PARTS: &str = "parts";
/// A staging folder without a lock file belongs to a bake that is just starting, unless it was
/// last changed longer ago than this (folders of older versions, which had no lock).
const UNLOCKED_STAGING_GRACE: Duration = Duration::from_secs(60);

/// What a publish records in its staging folder before it moves anything: what the next bake
/// needs to put right a publish whose bake was killed ([`remove_stale_staging`]). The moves
/// themselves are always the same ([`moves`]); which of them were done is told by where the
/// files are.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
struct Journal {
    /// The fingerprint record of the sharded bake whose parts folder's `tiles/` are the new
    /// tiles ([`super::shard::parts_dir`]); `None`: the new tiles are in the staging folder.
    parts: Option<String>,
    /// Whether the publish created the output folder.
    created: bool,
}

/// The moves of a publish into `out` from the staging folder `dir`, in order, each as
/// (from, to): the replaced world's `world.toml` and `tiles/` aside into `previous/` (where it
/// has them), the new `tiles/` in, and the new `world.toml` in, last. Each is one rename, and
/// each is done exactly when its `to` exists and its `from` does not, taken from the last move
/// back (see [`undo`]); once the last is done, the world is published.
fn moves(out: &Path, dir: &Path, journal: &Journal) -> [(PathBuf, PathBuf); 4] {
    let previous = dir.join(STAGING_PREVIOUS);
    let world = dir.join(STAGING_WORLD);
    let new_tiles = match journal.parts {
        Some(_) => super::shard::parts_dir(out).join("tiles"),
        None => world.join("tiles"),
    };
    [
        (out.join("world.toml"), previous.join("world.toml")),
        (out.join("tiles"), previous.join("tiles")),
        (new_tiles, out.join("tiles")),
        (world.join("world.toml"), out.join("world.toml")),
    ]
}

/// Whether anything (a symlink included) is at `path`.
fn exists(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok()
}

/// Whether the move `from` -> `to` of a publish is done, once every later move is undone.
fn is_moved((from, to): &(PathBuf, PathBuf)) -> bool {
    exists(to) && !exists(from)
}

/// Moves back what an unfinished publish moved, the last move first: afterwards the output
/// folder holds what it held before the publish (and the new tiles are where they came from).
/// Returns the indices (in [`moves`]) of the moves undone, or the move that could not be.
fn undo(moves: &[(PathBuf, PathBuf); 4]) -> Result<Vec<usize>, (PathBuf, std::io::Error)> {
    let mut undone = Vec::new();
    for (k, step) in moves.iter().enumerate().rev() {
        if is_moved(step) {
            let (from, to) = step;
            std::fs::rename(to, from).map_err(|e| (to.clone(), e))?;
            undone.push(k);
        }
    }
    Ok(undone)
}

/// Removes a sharded bake's parts folder once its world is published (moved into the staging
/// folder `dir`, which is removed whole later), if it is still the one whose fingerprint record
/// is `record`.
fn spend_parts(out: &Path, dir: &Path, record: &str) {
    let parts = super::shard::parts_dir(out);
    let file = parts.join(super::shard::FINGERPRINT_FILE);
    if std::fs::read_to_string(file).is_ok_and(|found| found == record)
        && std::fs::rename(&parts, dir.join(STAGING_SPENT_PARTS)).is_err()
    {
        let _ = std::fs::remove_dir_all(&parts);
    }
}

/// Removes the staging folder `dir` of a bake into `out`: first renamed to a name that no bake
/// looks into (`.NAME.removing.*`), so that a removal cut short never leaves a staging folder
/// half there for the next bake to misread.
fn discard(out: &Path, dir: &Path) {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let name = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let doomed = dir.with_file_name(format!(".{name}.removing.{}-{n}", std::process::id()));
    let target = match std::fs::rename(dir, &doomed) {
        Ok(()) => doomed,
        Err(_) => dir.to_path_buf(),
    };
    let _ = std::fs::remove_dir_all(target);
}

/// Whether `file_name` is that of a staging folder (`kind` "baking") or of one being removed
/// ("removing") of a bake into the folder named `name`: `.NAME.baking.PID-N` (`.NAME.baking.PID`
/// in older versions), and not one of another folder whose name starts with it
/// (`.NAME.baking.x.baking.PID-N`, of `NAME.baking.x`).
fn is_staging_name(file_name: &str, name: &str, kind: &str) -> bool {
    file_name
        .strip_prefix(&format!(".{name}.{kind}."))
        .is_some_and(|rest| {
            !rest.is_empty()
                && [".baking.", ".removing.", ".previous."]
                    .iter()
                    .all(|other| !rest.contains(other))
        })
}

/// A world being baked in a staging folder beside its output folder,
/// `PARENT/.NAME.baking.PID-N/`: `lock` (locked while the bake runs), `world/` (the new world)
/// and, while [`Staging::publish`] runs, `publishing.json` (its [`Journal`]) and `previous/`
/// (the world it replaces). Publishing moves `world.toml` and `tiles/` alone into the output
/// folder, so that no other file of that folder is ever moved; the staging folder is removed
/// when the bake ends, however it ends, and a bake killed while publishing is put right by the
/// next bake into the same folder ([`remove_stale_staging`]).
pub(super) struct Staging {
    pub(super) out: PathBuf,
    pub(super) dir: PathBuf,
    pub(super) world: PathBuf,
    pub(super) replace: bool,
    /// Held for the lock's sake: a bake that is killed releases it with its process.
    pub(super) _lock: std::fs::File,
    /// Leave the staging folder in place (it holds the only copy of the replaced world).
    pub(super) keep: bool,
    /// The folders above the output that this bake created, the deepest first: removed again,
    /// while empty, when the bake ends without a world in them.
    pub(super) parents_made: Vec<PathBuf>,
}

impl Staging {
    /// Creates the staging folder beside `out` (resolved by [`resolve_out`]), first putting
    /// right the staging folders of killed bakes into the same output folder
    /// ([`remove_stale_staging`], whose notes are logged as warnings).
    pub(super) fn begin(out: &Path, shown: &Path, replace: bool) -> Result<Self, WorldError> {
        check_out(out, replace)?;
        let (Some(name), Some(parent)) = (out.file_name(), out.parent()) else {
            return Err(WorldError::bad_option(
                "--out",
                shown.display(),
                "a folder other than the root of the file system".into(),
            ));
        };
        let name = name.to_string_lossy();
        let parents_made = crate::world::format::missing_folders(parent);
        std::fs::create_dir_all(parent).map_err(|e| WorldError::io(parent, e))?;
        for note in remove_stale_staging(out) {
            log::warn!("{note}");
        }
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir = parent.join(format!(".{name}.baking.{}-{n}", std::process::id()));
        if let Err(e) = std::fs::create_dir(&dir) {
            crate::world::format::remove_empty_folders(&parents_made);
            return Err(WorldError::io(&dir, e));
        }
        let lock = match lock_staging(&dir) {
            Ok(lock) => lock,
            Err(e) => {
                let _ = std::fs::remove_dir_all(&dir);
                crate::world::format::remove_empty_folders(&parents_made);
                return Err(e);
            }
        };
        let staging = Self {
            out: out.to_path_buf(),
            world: dir.join(STAGING_WORLD),
            dir,
            replace,
            _lock: lock,
            keep: false,
            parents_made,
        };
        std::fs::create_dir(&staging.world).map_err(|e| WorldError::io(&staging.world, e))?;
        Ok(staging)
    }

    /// The folder the new world is written to.
    pub(super) fn world(&self) -> &Path {
        &self.world
    }

    /// Moves the baked world into the output folder ([`moves`]): the replaced world's
    /// `world.toml` and `tiles/` (if any) aside into the staging folder, then the new `tiles/`
    /// and, last, the new `world.toml` in. The new tiles come from the staging folder, or with
    /// `parts` (the fingerprint record of a sharded bake's parts folder) from the parts folder,
    /// which is removed once the world is in: a finish that fails before then leaves the
    /// shards' tiles where they were. Nothing else in the output folder is touched. If a step
    /// fails, what was moved is moved back; if the bake is killed meanwhile, the next bake into
    /// the same folder does that ([`remove_stale_staging`]).
    pub(super) fn publish(mut self, parts: Option<&str>) -> Result<(), WorldError> {
        check_out(&self.out, self.replace)?;
        let journal = Journal {
            parts: parts.map(str::to_owned),
            created: !self.out.exists(),
        };
        let remove_created = |out: &Path| {
            if journal.created {
                let _ = std::fs::remove_dir(out);
            }
        };
        std::fs::create_dir_all(&self.out).map_err(|e| WorldError::io(&self.out, e))?;
        let text = serde_json::to_string(&journal).unwrap_or_default();
        let prepared =
            crate::world::format::write_atomic(&self.dir.join(STAGING_JOURNAL), text.as_bytes())
                .and_then(|()| {
                    let previous = self.dir.join(STAGING_PREVIOUS);
                    std::fs::create_dir(&previous).map_err(|e| WorldError::io(&previous, e))
                });
        if let Err(e) = prepared {
            remove_created(&self.out);
            return Err(e);
        }
        let moves = moves(&self.out, &self.dir, &journal);
        // The old manifest goes first and the new one comes last, so that the folder never
        // holds a manifest over tiles it does not describe.
        let mut result = Ok(());
        for (k, (from, to)) in moves.iter().enumerate() {
            // The replaced world's files are moved aside only where it has them.
            if k < 2 && !exists(from) {
                continue;
            }
            if let Err(e) = std::fs::rename(from, to) {
                result = Err((from.clone(), e));
                break;
            }
        }
        let Err((failed, source)) = result else {
            if let Some(record) = parts {
                spend_parts(&self.out, &self.dir, record);
            }
            return Ok(());
        };
        if undo(&moves).is_ok() {
            remove_created(&self.out);
            return Err(WorldError::io(&failed, source));
        }
        // The previous world is in the staging folder: keep it, under a name that no later
        // bake removes.
        self.keep = true;
        let kept = self.dir.with_file_name(
            self.dir
                .file_name()
                .map(|n| n.to_string_lossy().replacen(".baking.", ".previous.", 1))
                .unwrap_or_default(),
        );
        let kept = match std::fs::rename(&self.dir, &kept) {
            Ok(()) => kept,
            Err(_) => self.dir.clone(),
        };
        Err(WorldError::PublishFailed {
            path: self.out.clone(),
            kept,
            source,
        })
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.keep {
            discard(&self.out, &self.dir);
            // A published world is in them, so they stay.
            crate::world::format::remove_empty_folders(&self.parents_made);
        }
    }
}

/// Creates and locks the lock file of the staging folder `dir`. It is locked under another
/// name and then renamed, so that no other bake ever finds it unlocked.
fn lock_staging(dir: &Path) -> Result<std::fs::File, WorldError> {
    let path = dir.join(STAGING_LOCK);
    let new = dir.join(format!("{STAGING_LOCK}.new"));
    let file = std::fs::File::create_new(&new).map_err(|e| WorldError::io(&new, e))?;
    file.lock().map_err(|e| WorldError::io(&new, e))?;
    std::fs::rename(&new, &path).map_err(|e| WorldError::io(&path, e))?;
    Ok(file)
}

/// Puts right and removes the staging folders of bakes into `out` (resolved) that no running
/// bake holds: those whose lock file can be locked (its bake was killed), and those without one
/// that were last changed over [`UNLOCKED_STAGING_GRACE`] ago. A bake killed while publishing
/// ([`Staging::publish`]) is put right first ([`recover_publish`]): the folder gets back the
/// world it held, or where the new `world.toml` was already in, the publish is finished. Best
/// effort: a folder that cannot be put right or removed is left for the next bake. Returns a
/// note, for the user, of each thing put right or left.
pub(super) fn remove_stale_staging(out: &Path) -> Vec<String> {
    let (Some(name), Some(parent)) = (out.file_name(), out.parent()) else {
        return Vec::new();
    };
    let name = name.to_string_lossy();
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Vec::new();
    };
    let mut notes = Vec::new();
    for entry in entries.flatten() {
        let file_name = entry.file_name().to_string_lossy().into_owned();
        if !entry.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        if is_staging_name(&file_name, &name, "removing") {
            // A removal that was cut short: nothing in it is read any more. Only a folder
            // named as `discard` names one (`.NAME.removing.PID-N`) and holding only a staging
            // folder's entries: a folder of the user's of a name like it is left alone.
            let numbered = file_name
                .strip_prefix(&format!(".{name}.removing."))
                .and_then(|n| n.split_once('-'))
                .is_some_and(|(pid, n)| {
                    [pid, n]
                        .iter()
                        .all(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
                });
            if numbered && holds_only_staging_entries(&entry.path()) {
                let _ = std::fs::remove_dir_all(entry.path());
            }
            continue;
        }
        if !is_staging_name(&file_name, &name, "baking") {
            continue;
        }
        let dir = entry.path();
        let lock = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(dir.join(STAGING_LOCK));
        let stale = match &lock {
            Ok(file) => file.try_lock().is_ok(),
            // Without a lock, only a folder of a staging folder's own entries (or none), as a
            // bake killed before it made its lock leaves: a folder of that name holding
            // anything else is not one, and is left alone.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                holds_only_staging_entries(&dir)
                    && entry
                        .metadata()
                        .and_then(|m| m.modified())
                        .is_ok_and(|changed| {
                            SystemTime::now()
                                .duration_since(changed)
                                .is_ok_and(|age| age > UNLOCKED_STAGING_GRACE)
                        })
            }
            Err(_) => false,
        };
        if stale {
            // Put right and removed while the lock is held, so that no bake can take the
            // folder meanwhile.
            match recover_publish(out, &dir) {
                Ok(note) => {
                    notes.extend(note);
                    discard(out, &dir);
                }
                Err(note) => notes.push(note),
            }
        }
        drop(lock);
    }
    notes
}

/// Whether every entry of the folder `dir` is one a staging folder holds ([`STAGING_LOCK`]
/// and its first name, [`STAGING_WORLD`], [`STAGING_PREVIOUS`], [`STAGING_JOURNAL`], [`STAGING_SPENT_PARTS`], or a
/// journal's temporary, as a killed write of it leaves one); false where it cannot be read.
fn holds_only_staging_entries(dir: &Path) -> bool {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return false;
    };
    entries.into_iter().all(|e| {
        e.is_ok_and(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            [
                STAGING_LOCK,
                STAGING_WORLD,
                STAGING_PREVIOUS,
                STAGING_JOURNAL,
                STAGING_SPENT_PARTS,
            ]
            .contains(&name.as_str())
                // The lock as it is made, before its rename (`lock_staging`).
                || name == format!("{STAGING_LOCK}.new")
                || (name.starts_with(&format!(".{STAGING_JOURNAL}")) && name.ends_with(".tmp"))
        })
    })
}

/// Puts right the output folder `out` after a bake killed while publishing from the staging
/// folder `dir` (one that holds a [`Journal`], or `previous/` where an older version wrote
/// none): where the new `world.toml` is in, the world is published and what is left is the
/// publish's own clean-up (the spent parts folder of a sharded bake); otherwise every move done
/// is undone ([`undo`]), so that the folder holds the world it held before and a sharded bake's
/// tiles are back in its parts folder. Returns a note of what was done (none where nothing
/// was moved), or, where a move could not be undone, a note saying so: the staging folder,
/// which then holds part of a world, is to be kept.
fn recover_publish(out: &Path, dir: &Path) -> Result<Option<String>, String> {
    let journal = match std::fs::read_to_string(dir.join(STAGING_JOURNAL)) {
        Ok(text) => serde_json::from_str(&text).unwrap_or_default(),
        Err(_) if exists(&dir.join(STAGING_PREVIOUS)) => Journal::default(),
        Err(_) => return Ok(None),
    };
    let moves = moves(out, dir, &journal);
    if is_moved(&moves[3]) {
        if let Some(record) = &journal.parts {
            spend_parts(out, dir, record);
        }
        return Ok(Some(format!(
            "{}: a bake was killed just after moving its world in; its clean-up is done now \
             (the world it replaced is removed, as that bake would have)",
            out.display()
        )));
    }
    let undone = undo(&moves).map_err(|(path, e)| {
        format!(
            "{}: a bake was killed while moving its world in, and {} could not be moved back \
             ({e}); {} is kept, with the world it replaced in previous/",
            out.display(),
            path.display(),
            dir.display()
        )
    })?;
    // What of the replaced world could not go back (a world.toml put into the folder by hand
    // since stands where it would go) stays with the staging folder, which is kept.
    let previous = dir.join(STAGING_PREVIOUS);
    if std::fs::read_dir(&previous).is_ok_and(|mut e| e.next().is_some()) {
        return Err(format!(
            "{}: a bake was killed while moving its world in, and what it had moved aside of the \
             world it replaced was not put back (the folder holds files of those names now); \
             {} is kept, with that world in previous/: move what you want of it back by hand, \
             then remove the folder",
            out.display(),
            dir.display()
        ));
    }
    if journal.created {
        // Removed only while empty.
        let _ = std::fs::remove_dir(out);
    }
    if undone.is_empty() {
        return Ok(None);
    }
    let what: Vec<String> = undone
        .iter()
        .map(|k| match (k, &journal.parts) {
            (0, _) => "put the previous world.toml back".to_string(),
            (1, _) => "put the previous tiles/ back".to_string(),
            (2, Some(_)) => format!(
                "moved the shards' tiles back into {}",
                super::shard::parts_dir(out).display()
            ),
            (2, None) => "took the new tiles/ out".to_string(),
            _ => "took the new world.toml out".to_string(),
        })
        .collect();
    Ok(Some(format!(
        "{}: a bake was killed while moving its world in; {}: the folder holds what it held \
         before that bake",
        out.display(),
        what.join(", ")
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    const OLD_MANIFEST: &str = "[pyramid] # old";
    const NEW_MANIFEST: &str = "[pyramid] # new";
    const RECORD: &str = "0123456789abcdef 2\n";

    fn write(path: &Path, text: &str) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }

    fn read(path: &Path) -> String {
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
    }

    /// The folder `base/w` as a bake killed while publishing leaves it: the old world (if
    /// `old_world`) and `notes.txt` in it, the staging folder `.w.baking.4242-0` holding the
    /// new world (its tiles there, or in the parts folder where `sharded`), its record (unless
    /// `journal` is false, as older versions wrote none) and `previous/`, and the first `done`
    /// of the publish's moves done. Returns the output folder, the staging folder and whether
    /// anything was moved.
    fn killed_publish(
        base: &Path,
        sharded: bool,
        old_world: bool,
        journal: bool,
        done: usize,
    ) -> (PathBuf, PathBuf, bool) {
        let out = base.join("w");
        std::fs::create_dir_all(&out).unwrap();
        write(&out.join("notes.txt"), "mine");
        if old_world {
            write(&out.join("world.toml"), OLD_MANIFEST);
            write(&out.join("tiles/L0/0_0.type.png"), "old tile");
        }
        let dir = base.join(".w.baking.4242-0");
        write(&dir.join(STAGING_LOCK), "");
        write(&dir.join(STAGING_WORLD).join("world.toml"), NEW_MANIFEST);
        let record = Journal {
            parts: sharded.then(|| RECORD.to_string()),
            created: !old_world,
        };
        if sharded {
            let parts = super::super::shard::parts_dir(&out);
            write(&parts.join(super::super::shard::FINGERPRINT_FILE), RECORD);
            write(&parts.join("done/0-of-2.json"), "{}");
            write(&parts.join("tiles/L0/0_0.type.png"), "new tile");
        } else {
            write(&dir.join("world/tiles/L0/0_0.type.png"), "new tile");
        }
        if journal {
            write(
                &dir.join(STAGING_JOURNAL),
                &serde_json::to_string(&record).unwrap(),
            );
        }
        std::fs::create_dir(dir.join(STAGING_PREVIOUS)).unwrap();
        let mut moved = false;
        for (k, (from, to)) in moves(&out, &dir, &record).iter().enumerate().take(done) {
            if k < 2 && !exists(from) {
                continue;
            }
            std::fs::rename(from, to).unwrap();
            moved = true;
        }
        (out, dir, moved)
    }

    /// A bake killed at any point of its publish is put right by the next: before the new
    /// manifest is in, the folder gets back the world it held (and a sharded bake's parts
    /// folder its tiles); after, the new world stays. The replaced world is never lost, and
    /// the folder's other files are never touched.
    #[test]
    fn a_publish_killed_at_any_move_is_put_right() {
        for sharded in [false, true] {
            for old_world in [true, false] {
                for journal in [true, false] {
                    if sharded && !journal {
                        // Older versions moved the shards' tiles into the staging folder.
                        continue;
                    }
                    for done in 0..=4 {
                        let case = format!(
                            "sharded {sharded}, old world {old_world}, record {journal}, \
                             {done} moves done"
                        );
                        let tmp = tempfile::tempdir().unwrap();
                        let base = tmp.path().canonicalize().unwrap();
                        let (out, dir, moved) =
                            killed_publish(&base, sharded, old_world, journal, done);
                        let parts = super::super::shard::parts_dir(&out);
                        let notes = remove_stale_staging(&out);
                        assert!(!dir.exists(), "{case}: the staging folder is removed");
                        assert_eq!(notes.len(), usize::from(moved), "{case}: {notes:?}");
                        assert_eq!(read(&out.join("notes.txt")), "mine", "{case}");
                        let left: Vec<String> = std::fs::read_dir(&base)
                            .unwrap()
                            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                            .filter(|n| n.starts_with(".w."))
                            .collect();
                        if done == 4 {
                            assert_eq!(read(&out.join("world.toml")), NEW_MANIFEST, "{case}");
                            assert_eq!(
                                read(&out.join("tiles/L0/0_0.type.png")),
                                "new tile",
                                "{case}"
                            );
                            assert!(left.is_empty(), "{case}: {left:?}");
                            continue;
                        }
                        if old_world {
                            assert_eq!(read(&out.join("world.toml")), OLD_MANIFEST, "{case}");
                            assert_eq!(
                                read(&out.join("tiles/L0/0_0.type.png")),
                                "old tile",
                                "{case}"
                            );
                        } else {
                            assert!(!out.join("world.toml").exists(), "{case}");
                            assert!(!out.join("tiles").exists(), "{case}");
                        }
                        if sharded {
                            assert_eq!(
                                read(&parts.join("tiles/L0/0_0.type.png")),
                                "new tile",
                                "{case}: the shards' tiles are back in their parts folder"
                            );
                            assert_eq!(left, [".w.shards"], "{case}");
                        } else {
                            assert!(left.is_empty(), "{case}: {left:?}");
                        }
                    }
                }
            }
        }
    }

    /// A publish killed after moving the old world aside, into whose folder a world.toml was
    /// put by hand since: the old manifest cannot go back, so the staging folder that holds it
    /// is kept, and said to be, not removed with it.
    #[test]
    fn a_replaced_world_that_cannot_go_back_is_kept() {
        for done in 1..=3 {
            let tmp = tempfile::tempdir().unwrap();
            let base = tmp.path().canonicalize().unwrap();
            let (out, dir, _) = killed_publish(&base, false, true, true, done);
            let previous = dir.join(STAGING_PREVIOUS).join("world.toml");
            assert_eq!(read(&previous), OLD_MANIFEST, "{done} moves done");
            write(&out.join("world.toml"), "by hand");
            let notes = remove_stale_staging(&out);
            assert_eq!(read(&previous), OLD_MANIFEST, "{done} moves done");
            assert_eq!(read(&out.join("world.toml")), "by hand");
            assert!(
                notes.len() == 1 && notes[0].contains("is kept, with that world in previous/"),
                "{done} moves done: {notes:?}"
            );
        }
    }

    /// A sharded bake's publish that fails leaves the shards' tiles in their parts folder and
    /// the output folder as it was; one that succeeds removes the parts folder.
    #[test]
    fn a_failed_publish_of_shards_leaves_their_tiles_in_the_parts_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().canonicalize().unwrap().join("w");
        write(&out.join("world.toml"), OLD_MANIFEST);
        write(&out.join("tiles/L0/0_0.type.png"), "old tile");
        let parts = super::super::shard::parts_dir(&out);
        write(&parts.join(super::super::shard::FINGERPRINT_FILE), RECORD);
        write(&parts.join("tiles/L0/0_0.type.png"), "new tile");
        // The new world lacks its manifest: the last move fails.
        let staging = Staging::begin(&out, &out, true).unwrap();
        let err = staging.publish(Some(RECORD)).unwrap_err();
        assert!(err.to_string().contains("world.toml"), "{err}");
        assert_eq!(read(&parts.join("tiles/L0/0_0.type.png")), "new tile");
        assert_eq!(read(&out.join("world.toml")), OLD_MANIFEST);
        assert_eq!(read(&out.join("tiles/L0/0_0.type.png")), "old tile");

        let staging = Staging::begin(&out, &out, true).unwrap();
        write(&staging.world().join("world.toml"), NEW_MANIFEST);
        staging.publish(Some(RECORD)).unwrap();
        assert_eq!(read(&out.join("world.toml")), NEW_MANIFEST);
        assert_eq!(read(&out.join("tiles/L0/0_0.type.png")), "new tile");
        assert!(!parts.exists());
        let left = std::fs::read_dir(out.parent().unwrap()).unwrap().count();
        assert_eq!(left, 1, "only the output folder is left");
    }

    /// A folder named like a staging folder that has no lock is removed once it is over the
    /// grace's age only where it holds nothing but a staging folder's own entries: one holding
    /// anything else is someone's, and stays.
    #[test]
    fn an_unlocked_folder_named_like_staging_is_removed_only_if_it_is_one() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().canonicalize().unwrap().join("w");
        write(&out.join("world.toml"), OLD_MANIFEST);
        let theirs = tmp.path().join(".w.baking.12345-0");
        write(&theirs.join("notes.txt"), "notes");
        let killed = tmp.path().join(".w.baking.12346-0");
        std::fs::create_dir_all(killed.join(STAGING_WORLD)).unwrap();
        // Killed between making its lock and renaming it.
        write(&killed.join(format!("{STAGING_LOCK}.new")), "");
        let long_ago = SystemTime::now() - UNLOCKED_STAGING_GRACE * 2;
        for dir in [&theirs, &killed] {
            std::fs::File::open(dir)
                .unwrap()
                .set_modified(long_ago)
                .unwrap();
        }
        remove_stale_staging(&out);
        assert_eq!(read(&theirs.join("notes.txt")), "notes");
        assert!(!killed.exists());
    }

    /// A removal cut short is finished only where the folder is one: named as a removal names
    /// it and holding a staging folder's entries alone. A folder of the user's named like one
    /// stays, with what it holds.
    #[test]
    fn a_folder_named_like_a_removal_is_removed_only_if_it_is_one() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().canonicalize().unwrap().join("w");
        write(&out.join("world.toml"), OLD_MANIFEST);
        let mine = tmp.path().join(".w.removing.mine");
        std::fs::create_dir_all(mine.join(STAGING_WORLD)).unwrap();
        let theirs = tmp.path().join(".w.removing.12-3");
        write(&theirs.join("thesis.tex"), "precious");
        let dotted = tmp.path().join(".w.removing.old.12-5");
        std::fs::create_dir_all(dotted.join(STAGING_WORLD)).unwrap();
        let cut_short = tmp.path().join(".w.removing.12-4");
        write(
            &cut_short.join(STAGING_WORLD).join("world.toml"),
            NEW_MANIFEST,
        );
        write(&cut_short.join(STAGING_LOCK), "");
        remove_stale_staging(&out);
        assert!(mine.join(STAGING_WORLD).is_dir());
        assert_eq!(read(&theirs.join("thesis.tex")), "precious");
        assert!(dotted.join(STAGING_WORLD).is_dir());
        assert!(!cut_short.exists());
    }

    /// A mount point is known from the mount table, its escapes undone; a plain folder is not
    /// one.
    #[cfg(target_os = "linux")]
    #[test]
    fn mount_points_are_read_from_the_mount_table() {
        assert!(is_mount_point(Path::new("/proc")));
        let tmp = tempfile::tempdir().unwrap();
        assert!(!is_mount_point(&tmp.path().canonicalize().unwrap()));
        assert_eq!(
            unescape_mount_path("/mnt/my\\040disk\\134x\\9"),
            std::ffi::OsString::from("/mnt/my disk\\x\\9")
        );
    }

    /// Only the staging folders of the output folder itself are taken for its own, not those
    /// of a folder whose name begins with its name.
    #[test]
    fn staging_names_belong_to_one_output_folder() {
        assert!(is_staging_name(".w.baking.12-0", "w", "baking"));
        assert!(is_staging_name(".w.removing.12-3", "w", "removing"));
        assert!(!is_staging_name(".w.baking.x.baking.12-0", "w", "baking"));
        assert!(is_staging_name(".w.baking.12", "w", "baking"));
        assert!(!is_staging_name(".w.baking.x.removing.12-0", "w", "baking"));
        assert!(!is_staging_name(".w.baking.", "w", "baking"));
        assert!(!is_staging_name(".w.previous.12-0", "w", "baking"));
    }
}
