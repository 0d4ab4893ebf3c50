//! Publishing a bake: the staging folder beside the output folder, the safe replacement of
//! `world.toml` and `tiles/`, the clean-up of killed bakes' staging folders, and cancellation.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, SystemTime};

use crate::world::error::WorldError;

/// A flag that cancels a running bake, from another thread or a signal handler
/// ([`CancelFlag::shared`] gives the atomic to hand to one). Clones share the flag; two flags
/// are equal when they are the same flag.
#[derive(Clone, Debug, Default)]
pub struct CancelFlag(Arc<AtomicBool>);

impl CancelFlag {
    /// A flag that is not set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the bake to stop.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether the bake was asked to stop.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }

    /// The flag itself, for a signal handler to set (e.g. `signal_hook::flag::register`).
    pub fn shared(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.0)
    }

    /// A flag that SIGINT and SIGTERM (Ctrl-C, `kill`) set, for the command line: the first
    /// signal cancels the bake, which then removes its staging folder; a second one ends the
    /// process at once (status 130), and the next bake removes the staging folder it leaves.
    #[cfg(feature = "cli")]
    pub fn on_termination_signals() -> std::io::Result<Self> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        let flag = Self::new();
        for signal in [SIGINT, SIGTERM] {
            // Registered first, so that it sees the flag as the previous signal left it.
            signal_hook::flag::register_conditional_shutdown(signal, 130, flag.shared())?;
            signal_hook::flag::register(signal, flag.shared())?;
        }
        Ok(flag)
    }
}

impl PartialEq for CancelFlag {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}
/// Refuses an output folder that exists and is not empty, unless it is to be replaced; and a
/// folder to be replaced whose `tiles/` holds anything that is not a tile verdant writes (the
/// replaced `tiles/` is deleted whole).
pub(super) fn check_out(out: &Path, replace: bool) -> Result<(), WorldError> {
    match std::fs::symlink_metadata(out) {
        Ok(m) if m.file_type().is_symlink() && std::fs::metadata(out).is_err() => {
            return Err(WorldError::bad_option(
                "--out",
                out.display(),
                "a folder, or a symlink to one (this one points to nothing)".into(),
            ));
        }
        Ok(_) if !out.is_dir() => {
            return Err(WorldError::bad_option(
                "--out",
                out.display(),
                "a folder (this is a file)".into(),
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
/// A staging folder without a lock file belongs to a bake that is just starting, unless it was
/// last changed longer ago than this (folders of older versions, which had no lock).
const UNLOCKED_STAGING_GRACE: Duration = Duration::from_secs(60);

/// A world being baked in a staging folder beside its output folder,
/// `PARENT/.NAME.baking.PID-N/`: `lock` (locked while the bake runs), `world/` (the new world)
/// and, while [`Staging::publish`] runs, `previous/` (the world it replaces). Publishing moves
/// `world.toml` and `tiles/` alone into the output folder, so that no other file of that folder
/// is ever moved; the staging folder is removed when the bake ends, however it ends.
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
    /// Creates the staging folder beside `out` (resolved by [`resolve_out`]), first removing
    /// the staging folders of killed bakes into the same output folder.
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
        remove_stale_staging(parent, &name);
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

    /// Moves the baked world into the output folder: the replaced world's `world.toml` and
    /// `tiles/` (if any) aside into the staging folder, then the new `tiles/` and, last, the new
    /// `world.toml` in. Nothing else in the output folder is touched. If a step fails, what was
    /// moved is moved back.
    pub(super) fn publish(mut self) -> Result<(), WorldError> {
        check_out(&self.out, self.replace)?;
        let created = !self.out.exists();
        std::fs::create_dir_all(&self.out).map_err(|e| WorldError::io(&self.out, e))?;
        let previous = self.dir.join(STAGING_PREVIOUS);
        std::fs::create_dir(&previous).map_err(|e| WorldError::io(&previous, e))?;
        // Each move done, as (where it is now, where it came from).
        let mut moved: Vec<(PathBuf, PathBuf)> = Vec::new();
        let mut step = |from: PathBuf, to: PathBuf| -> Result<(), (PathBuf, std::io::Error)> {
            std::fs::rename(&from, &to).map_err(|e| (from.clone(), e))?;
            moved.push((to, from));
            Ok(())
        };
        // The old manifest goes first and the new one comes last, so that the folder never
        // holds a manifest over tiles it does not describe.
        let mut result = Ok(());
        for name in ["world.toml", "tiles"] {
            let old = self.out.join(name);
            if result.is_ok() && old.symlink_metadata().is_ok() {
                result = step(old, previous.join(name));
            }
        }
        for name in ["tiles", "world.toml"] {
            if result.is_ok() {
                result = step(self.world.join(name), self.out.join(name));
            }
        }
        let Err((failed, source)) = result else {
            return Ok(());
        };
        let restored = moved
            .iter()
            .rev()
            .all(|(now, was)| std::fs::rename(now, was).is_ok());
        if restored {
            if created {
                let _ = std::fs::remove_dir(&self.out);
            }
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
            let _ = std::fs::remove_dir_all(&self.dir);
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

/// Removes the staging folders of bakes into `parent/name` that no running bake holds: those
/// whose lock file can be locked (its bake was killed), and those without one that were last
/// changed over [`UNLOCKED_STAGING_GRACE`] ago. Best effort: a folder that cannot be removed
/// is left for the next bake.
fn remove_stale_staging(parent: &Path, name: &str) {
    let prefix = format!(".{name}.baking.");
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for entry in entries.flatten() {
        if !entry.file_name().to_string_lossy().starts_with(&prefix)
            || !entry.file_type().is_ok_and(|t| t.is_dir())
        {
            continue;
        }
        let dir = entry.path();
        let lock = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(dir.join(STAGING_LOCK));
        let stale = match &lock {
            Ok(file) => file.try_lock().is_ok(),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|changed| {
                    SystemTime::now()
                        .duration_since(changed)
                        .is_ok_and(|age| age > UNLOCKED_STAGING_GRACE)
                }),
            Err(_) => false,
        };
        if stale {
            // Removed while the lock is held, so that no bake can take the folder meanwhile.
            let _ = std::fs::remove_dir_all(&dir);
        }
        drop(lock);
    }
}
