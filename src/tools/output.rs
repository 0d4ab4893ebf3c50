//! Output files and folders of the tools. Every file the tools write goes through
//! [`write_atomic`] (whole or not at all), and every output folder is held by an [`OutDir`]
//! (a lock file naming the process) while a run writes into it. Taking the folder checks the
//! files the run will write there ([`Outputs`]): none may be one of the run's inputs, or a file
//! that no run wrote ([`not_an_output`]: a DEM, say).

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output file could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {source}", path.display())]
pub struct WriteError {
    /// The file.
    pub path: PathBuf,
    /// What failed.
    #[source]
    pub source: std::io::Error,
}

/// Writes `file` whole or not at all: `write` fills a temporary file beside it (a hidden name
/// ending in `.tmp`, in the same folder so that the rename is atomic), which is flushed to disk
/// and renamed over `file`. If anything fails (`write` itself, a full disk, the rename), the
/// temporary file is removed and `file` is left as it was: absent, or its old contents.
pub fn write_atomic(
    file: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    let err = |source| WriteError {
        path: file.to_path_buf(),
        source,
    };
    let Some(name) = file.file_name() else {
        return Err(err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a file name",
        )));
    };
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Unique within the process too: frames are written on a thread of their own.
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp",
        name.to_string_lossy(),
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let created = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(err)?;
    let result = (|| {
        let mut w = std::io::BufWriter::new(created);
        write(&mut w)?;
        let f = w
            .into_inner()
            .map_err(std::io::IntoInnerError::into_error)?;
        // A full disk may only say so when the data is flushed: that error surfaces here,
        // before the rename.
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, file)
    })();
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(err(e));
    }
    Ok(())
}

/// How each report and table the tools write begins (by its file name): a file of that name in
/// an output folder that begins otherwise is no earlier run's output ([`not_an_output`]), and
/// is not written over. The JSON reports begin with their first field (serde keeps the
/// structs' order), the tables with their first columns; [`write_json`] and [`write_text`]
/// check in debug builds that what they write begins so.
const BEGINNINGS: &[(&str, &str)] = &[
    ("report.json", "{\n  \"world\": "),
    ("soak.json", "{\n  \"world\": "),
    ("truth.json", "{\n  \"world\": "),
    ("bench_lod.json", "{\n  \"adapter\": "),
    ("bench_blades.json", "{\n  \"adapter\": "),
    ("bench_features.json", "{\n  \"adapter\": "),
    ("aa.json", "{\n  \"adapter\": "),
    ("far_band.csv", "view,band_pixels,"),
    ("dolly.csv", "frame,flip_vs_truth,"),
    ("lod_settings.csv", "setting,high_radius_tiles,"),
    ("blades.csv", "blades,spacing_m,"),
    ("features.csv", "feature,gpu_ms_without,"),
    ("aa_frames.csv", "width,height,method,motion,frame,"),
    ("aa_sequences.csv", "width,height,method,motion,flip_mean,"),
    ("aa_paths.csv", "width,height,method,bound,path,"),
    ("aa_timing.csv", "width,height,method,frame_ms,"),
    ("derive.csv", "method,factor,"),
    ("sway.csv", "preset,integrator,"),
];

/// How the report or table named `name` begins, where it is one of the tools'.
fn beginning_of(name: &str) -> Option<&'static str> {
    BEGINNINGS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, begins)| *begins)
}

/// [`beginning_of`] the file `file` names.
fn beginning_for(file: &Path) -> Option<&'static str> {
    file.file_name()
        .and_then(|n| n.to_str())
        .and_then(beginning_of)
}

/// In debug builds, that `bytes` written as `file` begin as [`BEGINNINGS`] says.
fn debug_check_beginning(file: &Path, bytes: &[u8]) {
    if let Some(begins) = beginning_for(file) {
        debug_assert!(
            bytes.starts_with(begins.as_bytes()),
            "{} begins {:?}, not {begins:?} as output::BEGINNINGS says",
            file.display(),
            String::from_utf8_lossy(&bytes[..bytes.len().min(begins.len() + 16)])
        );
    }
}

/// Writes `value` as pretty JSON through [`write_atomic`]. A file named as one of the tools'
/// reports must begin as `BEGINNINGS` in this module says (checked in debug builds).
pub fn write_json<T: serde::Serialize>(file: &Path, value: &T) -> Result<(), WriteError> {
    let bytes = serde_json::to_vec_pretty(value).map_err(|e| WriteError {
        path: file.to_path_buf(),
        source: e.into(),
    })?;
    debug_check_beginning(file, &bytes);
    write_atomic(file, |w| w.write_all(&bytes))
}

/// Writes `text` (a CSV table, say) through [`write_atomic`].
pub fn write_text(file: &Path, text: &str) -> Result<(), WriteError> {
    debug_check_beginning(file, text.as_bytes());
    write_atomic(file, |w| w.write_all(text.as_bytes()))
}

/// Writes an 8-bit image as a PNG through [`write_atomic`].
pub fn write_png<P, C>(file: &Path, image: &image::ImageBuffer<P, C>) -> Result<(), WriteError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    write_atomic(file, |w| {
        image
            .write_with_encoder(image::codecs::png::PngEncoder::new(w))
            .map_err(|e| match e {
                image::ImageError::IoError(e) => e,
                e => std::io::Error::other(e),
            })
    })
}

/// The file in an output folder that a run holds locked while it writes there; it holds the
/// run's process id and tool, and is removed when the run ends.
pub const LOCK_FILE: &str = ".verdant.lock";

/// Why an output folder could not be taken.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutDirError {
    /// The folder could not be created.
    #[error("cannot create output folder {}: {source}", path.display())]
    Create {
        /// The folder.
        path: PathBuf,
        /// What failed.
        #[source]
        source: std::io::Error,
    },
    /// Its lock file could not be opened or locked.
    #[error("cannot lock output folder {} (its file {LOCK_FILE}): {source}", path.display())]
    Lock {
        /// The folder.
        path: PathBuf,
        /// What failed.
        #[source]
        source: std::io::Error,
    },
    /// Another run writes into it.
    #[error(
        "output folder {} is in use by {}; wait for it or choose another --out",
        path.display(),
        owner_words(*pid, tool)
    )]
    InUse {
        /// The folder.
        path: PathBuf,
        /// The other run's process id, when its lock file says.
        pid: Option<u32>,
        /// The other run's tool (`fly`, `bench lod`, ...), when its lock file says.
        tool: String,
    },
    /// The folder, or a folder above it, is something else: a file, or a symbolic link to
    /// nothing.
    #[error("{}: {what}, so no output folder can be made there; choose another --out", path.display())]
    NotAFolder {
        /// The folder.
        path: PathBuf,
        /// What stands in the way, in words.
        what: String,
    },
    /// A file the run would write in the folder is one that it reads.
    #[error(
        "{}: it is {what}, and {tool} writes a file of this name into its --out, which would \
         replace it; choose another --out",
        file.display()
    )]
    ReplacesInput {
        /// The file.
        file: PathBuf,
        /// What it is to the run, in words (`the DEM this run reads (--dem)`).
        what: String,
        /// The run's tool.
        tool: String,
    },
    /// A file the run would write in the folder is there already, and is no earlier run's
    /// output ([`not_an_output`]).
    #[error(
        "{}: {tool} writes a file of this name into its --out, and this one {why}; a run \
         replaces only an earlier run's output: move the file or choose another --out",
        file.display()
    )]
    NotAnOutput {
        /// The file.
        file: PathBuf,
        /// The run's tool.
        tool: String,
        /// What the file is, in words ([`not_an_output`]).
        why: String,
    },
    /// The folder is one no run writes into: the root of the file system, a world's own folder
    /// or a world's `tiles/`.
    #[error("{}: {why}; choose another --out", path.display())]
    Refused {
        /// The folder.
        path: PathBuf,
        /// What it is.
        why: &'static str,
    },
}

/// The files a run writes into its output folder, and the files it reads. Taking the folder
/// ([`OutDir::create_for`]) refuses, before anything is written, a run that would write over
/// one of its inputs or over a file there that is no earlier run's output ([`not_an_output`]).
pub struct Outputs<'a> {
    writes: Box<dyn Fn(&str) -> bool + 'a>,
    reads: Vec<(String, PathBuf)>,
}

impl<'a> Outputs<'a> {
    /// A run that writes the files named `names`.
    pub fn named(names: &'a [&'a str]) -> Self {
        Self::matching(move |n| names.contains(&n))
    }

    /// A run that writes the files whose names `writes` accepts (numbered frames, say).
    pub fn matching(writes: impl Fn(&str) -> bool + 'a) -> Self {
        Self {
            writes: Box::new(writes),
            reads: Vec::new(),
        }
    }

    /// The run reads `file` too; `what` says what it is to the user (`the DEM this run reads
    /// (--dem)`). It is compared with the files to write by their canonical paths.
    pub fn reading(mut self, what: impl Into<String>, file: &Path) -> Self {
        self.reads.push((what.into(), file.to_path_buf()));
        self
    }
}

/// Why the file at `file`, if there is one, is not a file that a run of verdant may write over:
/// not a regular file, or, by its name, a `.png` that is not an 8-bit RGB or RGBA PNG without
/// a JSON sidecar (what the tools write: a 16-bit or grey PNG, or one with a sidecar, may be a
/// DEM or a map), or a `.json` beside a `.png` of the same name (a DEM's sidecar). A symbolic
/// link is refused whatever it leads to: the run's rename would replace it. `None` where there is no file, or one that may be
/// replaced, or a folder (no file is renamed over a folder: the write fails, naming it). The
/// words follow the file's name: `is not a PNG image`.
pub fn not_an_output(file: &Path) -> Option<String> {
    // A link is the user's: the run's rename would replace it with a file (its target kept).
    if std::fs::symlink_metadata(file).is_ok_and(|m| m.file_type().is_symlink()) {
        return Some(
            "is a symbolic link, which writing the run's output there would replace with a file"
                .into(),
        );
    }
    let meta = match std::fs::metadata(file) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
        Err(e) => return Some(format!("cannot be examined ({e})")),
        Ok(m) => m,
    };
    if meta.is_dir() {
        return None;
    }
    if !meta.is_file() {
        return Some("is not a regular file".into());
    }
    let named = |e: &str| file.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
    if named("png") {
        // The signature, then IHDR: length, "IHDR", width, height, bit depth, colour type.
        let mut head = [0u8; 26];
        let read = File::open(file)
            .and_then(|mut f| f.read_exact(&mut head))
            .is_ok();
        if !(read && head[..8] == *b"\x89PNG\r\n\x1a\n" && &head[12..16] == b"IHDR") {
            return Some("is not a PNG image".into());
        }
        let sidecar = crate::world::dem::sidecar_path(file);
        if sidecar.exists() {
            return Some(format!(
                "has a JSON sidecar, {}: it may be a DEM",
                sidecar.display()
            ));
        }
        let (depth, colour) = (head[24], head[25]);
        if depth != 8 || !matches!(colour, 2 | 6) {
            let colour = match colour {
                0 => "grey",
                2 => "RGB",
                3 => "palette",
                4 => "grey and alpha",
                6 => "RGBA",
                _ => "unknown colour type",
            };
            let a = if depth == 8 { "an" } else { "a" };
            return Some(format!(
                "is {a} {depth}-bit {colour} PNG, where verdant writes 8-bit RGB or RGBA: it \
                 may be a DEM, a map or a picture"
            ));
        }
    } else if named("json") {
        let png = file.with_extension("png");
        if png.is_file() {
            return Some(format!(
                "is the sidecar of {}: it may be a DEM's",
                png.display()
            ));
        }
    }
    // A report or table of the tools' begins as they write it.
    if let Some(begins) = beginning_for(file) {
        let mut head = vec![0u8; begins.len()];
        let read = File::open(file).and_then(|mut f| f.read_exact(&mut head));
        if read.is_err() || head != begins.as_bytes() {
            return Some(format!(
                "does not begin as verdant's {} does ({begins:?}): it is not an earlier run's \
                 output",
                file.file_name().map_or("".into(), |n| n.to_string_lossy()),
            ));
        }
    }
    None
}

/// Refuses a run into `dir` that would write over one of its inputs or over a file that is
/// no earlier run's output. Only the files there are looked at (a folder that is not there
/// holds none), the lock file among them.
fn check_outputs(dir: &Path, tool: &str, outputs: &Outputs) -> Result<(), OutDirError> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    let reads: Vec<(&str, PathBuf)> = outputs
        .reads
        .iter()
        .filter_map(|(what, file)| Some((what.as_str(), file.canonicalize().ok()?)))
        .collect();
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n == LOCK_FILE || (outputs.writes)(n))
        .collect();
    names.sort();
    for name in names {
        let file = dir.join(&name);
        if let Ok(real) = file.canonicalize()
            && let Some((what, _)) = reads.iter().find(|(_, r)| *r == real)
        {
            return Err(OutDirError::ReplacesInput {
                file,
                what: (*what).to_owned(),
                tool: tool.to_owned(),
            });
        }
        // The lock file is no output: `lock_folder` refuses what must not be taken for one.
        if name != LOCK_FILE
            && let Some(why) = not_an_output(&file)
        {
            return Err(OutDirError::NotAnOutput {
                file,
                tool: tool.to_owned(),
                why,
            });
        }
    }
    Ok(())
}

/// What keeps `path` from being a folder, if anything does: the nearest of it and the folders
/// above it that exists (following links) or is a link, when that is not a folder.
fn not_a_folder(path: &Path) -> Option<String> {
    let path = crate::world::format::resolve_lexically(path)
        .ok()
        .flatten()
        .unwrap_or_else(|| path.to_path_buf());
    let nearest = path
        .ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .find(|a| std::fs::symlink_metadata(a).is_ok())?;
    let who = if nearest == path {
        "it".to_owned()
    } else {
        format!("the folder above it, {},", nearest.display())
    };
    match std::fs::metadata(nearest) {
        Ok(m) if m.is_dir() => None,
        Ok(m) => Some(format!(
            "{who} is {}, not a folder",
            crate::world::format::what_file_is(&m)
        )),
        // ELOOP: links that lead to each other, or more of them than the system follows.
        Err(e) if e.raw_os_error() == Some(libc::ELOOP) => {
            let to = std::fs::read_link(nearest).ok()?;
            Some(format!(
                "{who} is a symbolic link to {}, which leads back round to itself (a loop of \
                 links)",
                to.display()
            ))
        }
        Err(_) => {
            let to = std::fs::read_link(nearest).ok()?;
            Some(format!(
                "{who} is a symbolic link to {}, which does not exist",
                to.display()
            ))
        }
    }
}

fn owner_words(pid: Option<u32>, tool: &str) -> String {
    match (pid, tool.is_empty()) {
        (Some(pid), false) => format!("verdant process {pid} ({tool})"),
        (Some(pid), true) => format!("verdant process {pid}"),
        (None, _) => "another verdant process".to_owned(),
    }
}

/// An output folder held by a run. Its lock file ([`LOCK_FILE`]) is locked with an OS file lock
/// for as long as the `OutDir` lives, so that a second run into the same folder is refused
/// instead of mixing its files with this one's; the OS releases the lock when the process ends,
/// however it ends. If the run created the folder (and any of its parents) and fails before
/// writing anything into it, the folders it created are removed again (only while empty), so an
/// early failure leaves no trace: a lock file that could not be written (a full disk) is
/// removed too.
pub struct OutDir {
    path: PathBuf,
    /// The folders this run created, the deepest first: `path` and the parents it lacked.
    created: Vec<PathBuf>,
    /// Folders made only because `path` was spelled through them (`new` of `new/../out`): the
    /// tools write through `path` as given, so they stand while the run does, and go with it
    /// (while empty), kept or not.
    passed_through: Vec<PathBuf>,
    kept: bool,
    lock: Option<File>,
}

impl OutDir {
    /// [`OutDir::create_for`] for the tool named by this process's first argument (the
    /// `verdant` subcommand).
    pub fn create(path: &Path, outputs: &Outputs) -> Result<Self, OutDirError> {
        let tool = std::env::args()
            .nth(1)
            .filter(|a| !a.starts_with('-'))
            .unwrap_or_default();
        Self::create_for(path, &tool, outputs)
    }

    /// Creates `path` (and its parents) where needed and locks it for `tool` (`fly`,
    /// `bench lod`, ...), which a refused second run names. Refused before anything is
    /// written where a file the run writes there (`outputs`) is one of its inputs or no
    /// earlier run's output ([`not_an_output`]).
    pub fn create_for(path: &Path, tool: &str, outputs: &Outputs) -> Result<Self, OutDirError> {
        if let Some(why) = crate::world::format::refused_output(path) {
            return Err(OutDirError::Refused {
                path: path.to_path_buf(),
                why,
            });
        }
        check_outputs(path, tool, outputs)?;
        let created = crate::world::format::missing_folders(path);
        let passed_through = passed_through(path, &created);
        // The folder as resolved first (`new/.` names `new`, which `create_dir_all` of the
        // path as given does not make), then as given (which the tools write through).
        let resolved = crate::world::format::resolve_lexically(path).ok().flatten();
        resolved
            .iter()
            .map(PathBuf::as_path)
            .chain([path])
            .try_for_each(std::fs::create_dir_all)
            .map_err(|source| match not_a_folder(path) {
                Some(what) => OutDirError::NotAFolder {
                    path: path.to_path_buf(),
                    what,
                },
                None => OutDirError::Create {
                    path: path.to_path_buf(),
                    source,
                },
            })?;
        // From here on, dropping `dir` removes a folder this run created.
        let mut dir = Self {
            path: path.to_path_buf(),
            created,
            passed_through,
            kept: false,
            lock: None,
        };
        dir.lock = Some(lock_folder(path, tool)?);
        // With the lock held no other run writes here: a temporary of one of this run's files
        // is a killed run's, never to be renamed into place.
        sweep_temporaries(path, outputs);
        Ok(dir)
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The run succeeded: the folder stays (its lock is let go).
    pub fn keep(mut self) {
        self.kept = true;
    }
}

/// The name of the file that `name` is a [`write_atomic`] temporary of
/// (`.{file}.{pid}-{n}.tmp`), if it is one.
fn temporary_of(name: &str) -> Option<&str> {
    let (file, tag) = name
        .strip_prefix('.')?
        .strip_suffix(".tmp")?
        .rsplit_once('.')?;
    let (pid, n) = tag.split_once('-')?;
    ([pid, n]
        .iter()
        .all(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
        && !file.is_empty())
    .then_some(file)
}

/// Removes from `dir` the temporaries of the files `outputs` writes that a killed run left
/// (regular files alone; what cannot be removed stays).
fn sweep_temporaries(dir: &Path, outputs: &Outputs) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        if temporary_of(name).is_some_and(|f| (outputs.writes)(f))
            && e.file_type().is_ok_and(|t| t.is_file())
        {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Whether `text` is what a run writes into its lock file: its process id and its tool, on one
/// line.
fn is_lock_text(text: &str) -> bool {
    let Some(line) = text.strip_suffix('\n') else {
        return false;
    };
    let (pid, tool) = line.split_once(' ').unwrap_or((line, ""));
    pid.parse::<u32>().is_ok() && !tool.chars().any(char::is_control)
}

/// Takes the lock of `dir` for `tool`. Where the file system has no locks, the lock file is
/// written all the same (and removed when the run ends), but holds nothing. A lock file this
/// run made, or took, is removed again if the run fails to take it (a full disk makes the
/// file, then fails to write it).
fn lock_folder(dir: &Path, tool: &str) -> Result<File, OutDirError> {
    let file = dir.join(LOCK_FILE);
    let failed = |source| OutDirError::Lock {
        path: dir.to_path_buf(),
        source,
    };
    // Never through a symbolic link: the lock is truncated and written, and a link would have
    // that done to whatever file it leads to.
    let not_regular = || {
        failed(std::io::Error::other(
            "it is not a regular file (a symbolic link, a folder or a device); remove it if no \
             run of verdant is writing here",
        ))
    };
    let open = |create_new: bool| {
        let mut options = std::fs::OpenOptions::new();
        options.read(true).write(true).create_new(create_new);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::custom_flags(&mut options, libc::O_NOFOLLOW);
        options.open(&file)
    };
    // A run that lets go of the lock removes the file first: a file locked here after that
    // removal is no longer the folder's lock, and the lock is taken again on the new one.
    for _ in 0..100 {
        if std::fs::symlink_metadata(&file).is_ok_and(|m| !m.is_file()) {
            return Err(not_regular());
        }
        // Whether this run made the file: then it goes again if the run does not take it.
        let opened = match open(false) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => open(true).map(|f| (f, true)),
            r => r.map(|f| (f, false)),
        };
        let (mut f, made) = match opened {
            Ok(o) => o,
            // Made by another run between the two opens: taken as found, again.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            #[cfg(unix)]
            Err(e) if e.raw_os_error() == Some(libc::ELOOP) => return Err(not_regular()),
            Err(e) => return Err(failed(e)),
        };
        let give_up = |e: OutDirError| {
            if made {
                let _ = std::fs::remove_file(&file);
            }
            e
        };
        let meta = f.metadata().map_err(|e| give_up(failed(e)))?;
        if !meta.is_file() {
            return Err(not_regular());
        }
        // A hard link is a regular file that is also another name's: truncated here, that
        // file would be lost too.
        #[cfg(unix)]
        if std::os::unix::fs::MetadataExt::nlink(&meta) > 1 {
            return Err(failed(std::io::Error::other(
                "it has other names (a hard link to another file); remove it if no run of \
                 verdant is writing here",
            )));
        }
        match f.try_lock() {
            Ok(()) => {
                if !same_file(&f, &file) {
                    continue;
                }
            }
            Err(std::fs::TryLockError::WouldBlock) => {
                // Another run's, even if made here: it took it first.
                let mut text = String::new();
                let _ = f.read_to_string(&mut text);
                let mut words = text.split_whitespace();
                let pid = words.next().and_then(|w| w.parse().ok());
                let tool = words.collect::<Vec<_>>().join(" ");
                return Err(OutDirError::InUse {
                    path: dir.to_path_buf(),
                    pid,
                    tool,
                });
            }
            Err(std::fs::TryLockError::Error(e)) if e.kind() == std::io::ErrorKind::Unsupported => {
                log::warn!(
                    "the file system of {} has no file locks: two runs into it would not be told apart",
                    dir.display()
                );
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(give_up(failed(e))),
        }
        // A file found here is taken over only if it is an earlier run's lock (left by a run
        // that was killed): empty, or its process id and tool on one line. Anything else is
        // the user's, which truncating would lose.
        if !made {
            let mut text = String::new();
            let ours = meta.len() <= 256
                && f.read_to_string(&mut text).is_ok()
                && (text.is_empty() || is_lock_text(&text));
            if !ours {
                return Err(failed(std::io::Error::other(
                    "it holds something other than a run's process id and tool, so it is no \
                     lock of verdant's; move it, or choose another --out",
                )));
            }
        }
        if let Err(e) = f
            .set_len(0)
            .and_then(|()| std::io::Seek::rewind(&mut f))
            .and_then(|()| f.write_all(format!("{} {tool}\n", std::process::id()).as_bytes()))
        {
            // Held (or made) here: removed, as a run that ends removes it.
            let _ = std::fs::remove_file(&file);
            return Err(failed(e));
        }
        return Ok(f);
    }
    Err(failed(std::io::Error::other(
        "its lock file kept being replaced",
    )))
}

/// Whether `path` still names the open file `f`.
#[cfg(unix)]
fn same_file(f: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (f.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &File, path: &Path) -> bool {
    path.exists()
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if let Some(lock) = self.lock.take() {
            // Removed while still locked (see `lock_folder`).
            let _ = std::fs::remove_file(self.path.join(LOCK_FILE));
            drop(lock);
        }
        if !self.kept {
            // Keeps each folder that anything was written into, and those above it.
            crate::world::format::remove_empty_folders(&self.created);
        }
        crate::world::format::remove_empty_folders(&self.passed_through);
    }
}

/// The folders that `create_dir_all(path)` makes besides those of the resolved path
/// (`created`): each missing folder that `path` names on the way (`new` of `new/../out`),
/// resolved, the deepest first. None of them exists before the run.
fn passed_through(path: &Path, created: &[PathBuf]) -> Vec<PathBuf> {
    use std::path::Component;
    path.ancestors()
        .filter(|a| matches!(a.components().next_back(), Some(Component::Normal(_))))
        .filter_map(|a| crate::world::format::resolve_lexically(a).ok().flatten())
        .filter(|r| {
            std::fs::symlink_metadata(r).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound)
                && !created.contains(r)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run that writes no file into its folder.
    fn nothing() -> Outputs<'static> {
        Outputs::named(&[])
    }

    /// Passes `left` bytes on, then fails as a full disk does.
    struct FailAfter<'a> {
        inner: &'a mut dyn Write,
        left: usize,
    }

    impl Write for FailAfter<'_> {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            if self.left == 0 {
                return Err(std::io::Error::from(std::io::ErrorKind::StorageFull));
            }
            let n = buf.len().min(self.left);
            self.left -= n;
            self.inner.write(&buf[..n])
        }

        fn flush(&mut self) -> std::io::Result<()> {
            self.inner.flush()
        }
    }

    /// An --out that is a file, lies under a file, or is a link to nothing is refused saying
    /// which (it was the bare OS error "File exists"), and nothing is touched.
    #[test]
    fn an_out_that_is_no_folder_is_refused_saying_what_it_is() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("notes.txt");
        std::fs::write(&file, "mine").unwrap();
        let link = tmp.path().join("dangling");
        std::os::unix::fs::symlink(tmp.path().join("nowhere"), &link).unwrap();
        let (loop1, loop2) = (tmp.path().join("loop1"), tmp.path().join("loop2"));
        std::os::unix::fs::symlink(&loop2, &loop1).unwrap();
        std::os::unix::fs::symlink(&loop1, &loop2).unwrap();
        let fifo = tmp.path().join("pipe");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(made.success());
        let cases = [
            (
                loop1.clone(),
                format!(
                    "it is a symbolic link to {}, which leads back round to itself",
                    loop2.display()
                ),
            ),
            (fifo.clone(), "it is a FIFO, not a folder".to_owned()),
            (file.clone(), "it is a file, not a folder".to_owned()),
            (
                file.join("out"),
                format!("the folder above it, {}, is a file", file.display()),
            ),
            (
                link.clone(),
                format!(
                    "it is a symbolic link to {}, which does not exist",
                    tmp.path().join("nowhere").display()
                ),
            ),
        ];
        for (out, said) in cases {
            let e = OutDir::create_for(&out, "fly", &nothing()).err().unwrap();
            let text = e.to_string();
            assert!(matches!(e, OutDirError::NotAFolder { .. }), "{text}");
            assert!(text.contains(&said) && text.contains("--out"), "{text}");
        }
        assert_eq!(std::fs::read_to_string(&file).unwrap(), "mine");
        assert!(!tmp.path().join("nowhere").exists());
        assert_eq!(
            names(tmp.path()),
            ["dangling", "loop1", "loop2", "notes.txt", "pipe"]
        );
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    /// A report or table of the user's that bears an output's name is refused, and nothing is
    /// written over it; one written as the tools write it is an earlier run's, and replaced.
    #[test]
    fn a_report_or_table_of_the_users_by_an_outputs_name_is_kept() {
        let dir = tempfile::tempdir().unwrap();
        let (report, table) = (
            dir.path().join("report.json"),
            dir.path().join("derive.csv"),
        );
        let outputs = Outputs::named(&["report.json", "derive.csv"]);
        for (file, mine) in [
            (&report, "{\"my\": \"thesis results\"}\n"),
            (&table, "my,own\n1,2\n"),
            (&table, ""),
        ] {
            let _ = std::fs::remove_file(&report);
            let _ = std::fs::remove_file(&table);
            std::fs::write(file, mine).unwrap();
            let e = match OutDir::create_for(dir.path(), "fly", &outputs) {
                Ok(_) => panic!("{} taken over: {mine:?}", file.display()),
                Err(e) => e.to_string(),
            };
            assert!(e.contains(&file.display().to_string()), "{e}");
            assert!(e.contains("does not begin as verdant's"), "{e}");
            assert_eq!(std::fs::read_to_string(file).unwrap(), mine);
        }
        // As the tools write them: taken.
        #[derive(serde::Serialize)]
        struct Report {
            world: String,
        }
        std::fs::remove_file(&table).unwrap();
        write_json(&report, &Report { world: "w".into() }).unwrap();
        write_text(&table, "method,factor,rmse_m\n").unwrap();
        OutDir::create_for(dir.path(), "fly", &outputs).unwrap();
        assert_eq!(beginning_of("report.json"), Some("{\n  \"world\": "));
        assert_eq!(beginning_of("notes.csv"), None);
    }

    /// A killed run's temporaries of the files a run writes are removed when the next run
    /// takes the folder; temporaries of other files, and the user's files, stay.
    #[test]
    fn a_killed_runs_temporaries_of_this_runs_files_are_swept() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            ".derive.csv.4-0.tmp",
            ".frame_00001.png.123-7.tmp",
            ".notes.txt.4-0.tmp",
            ".derive.csv.mine.tmp",
            "derive.csv",
        ] {
            std::fs::write(dir.path().join(name), "x").unwrap();
        }
        // An earlier run's table.
        std::fs::write(dir.path().join("derive.csv"), "method,factor,rmse_m\n").unwrap();
        let outputs = Outputs::matching(|n| n == "derive.csv" || n.starts_with("frame_"));
        let out = OutDir::create_for(dir.path(), "eval derive", &outputs).unwrap();
        out.keep();
        assert_eq!(
            names(dir.path()),
            [".derive.csv.mine.tmp", ".notes.txt.4-0.tmp", "derive.csv"]
        );
        assert_eq!(temporary_of(".a.b.png.1-2.tmp"), Some("a.b.png"));
        assert_eq!(temporary_of("..1-2.tmp"), None);
    }

    #[test]
    fn a_write_that_fails_part_way_leaves_no_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("frame_00003.png");
        // Noise: a PNG far larger than the write buffer.
        let img = image::RgbaImage::from_fn(128, 128, |x, y| {
            let h = (x * 7919 + y * 104_729).wrapping_mul(2_654_435_761);
            image::Rgba([(h >> 24) as u8, (h >> 16) as u8, (h >> 8) as u8, 255])
        });
        let fail = |left| {
            write_atomic(&file, |w| {
                let mut w = FailAfter { inner: w, left };
                img.write_with_encoder(image::codecs::png::PngEncoder::new(&mut w))
                    .map_err(std::io::Error::other)
            })
            .unwrap_err()
        };
        // Failing at once, after some bytes, and after more than the buffer holds.
        for left in [0, 100, 20_000] {
            let e = fail(left);
            assert_eq!(e.path, file);
            assert!(e.to_string().contains("frame_00003.png"), "{e}");
            assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
        }
        // A file already there keeps its contents when a new write fails.
        std::fs::write(&file, b"old frame").unwrap();
        fail(100);
        assert_eq!(std::fs::read(&file).unwrap(), b"old frame");
        assert_eq!(names(dir.path()), ["frame_00003.png"]);
        // And a whole write replaces it.
        write_png(&file, &img).unwrap();
        assert_eq!(image::open(&file).unwrap().to_rgba8(), img);
        assert_eq!(names(dir.path()), ["frame_00003.png"]);
    }

    #[test]
    fn json_and_text_are_written_whole() {
        let dir = tempfile::tempdir().unwrap();
        write_json(
            &dir.path().join("r.json"),
            &serde_json::json!({ "a": [1, 2] }),
        )
        .unwrap();
        write_text(&dir.path().join("t.csv"), "a,b\n1,2\n").unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("r.json")).unwrap())
                .unwrap();
        assert_eq!(v["a"][1], 2);
        assert_eq!(
            std::fs::read_to_string(dir.path().join("t.csv")).unwrap(),
            "a,b\n1,2\n"
        );
        assert_eq!(names(dir.path()), ["r.json", "t.csv"]);
        // Into a folder that does not exist: an error naming the file, nothing created.
        let e = write_text(&dir.path().join("no/t.csv"), "x").unwrap_err();
        assert!(e.to_string().contains("t.csv"), "{e}");
        assert!(!dir.path().join("no").exists());
    }

    #[test]
    fn a_file_named_like_the_lock_is_taken_only_if_it_is_a_runs_lock() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir_all(&out).unwrap();
        // The user's own file of that name: refused, and kept as it was.
        std::fs::write(out.join(LOCK_FILE), "important notes\n").unwrap();
        let e = match OutDir::create_for(&out, "fly", &nothing()) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("a file of the user's was taken for a lock"),
        };
        assert!(
            e.contains(LOCK_FILE) && e.contains("no lock of verdant's"),
            "{e}"
        );
        assert_eq!(
            std::fs::read_to_string(out.join(LOCK_FILE)).unwrap(),
            "important notes\n"
        );
        // A killed run's lock (its process id and tool), or an empty one: taken.
        for stale in ["4242 bench lod\n", "17 \n", ""] {
            std::fs::write(out.join(LOCK_FILE), stale).unwrap();
            let dir = OutDir::create_for(&out, "fly", &nothing()).unwrap();
            let lock = std::fs::read_to_string(out.join(LOCK_FILE)).unwrap();
            assert_eq!(lock, format!("{} fly\n", std::process::id()), "{stale:?}");
            dir.keep();
        }
    }

    #[test]
    fn a_held_output_folder_refuses_a_second_run_until_it_is_let_go() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        let first = OutDir::create_for(&out, "fly", &nothing()).unwrap();
        let lock = std::fs::read_to_string(out.join(LOCK_FILE)).unwrap();
        assert_eq!(lock, format!("{} fly\n", std::process::id()));
        // A second run (another open of the lock file: flock locks are per open file) is
        // refused, naming the folder, the first run's process and tool, and what to do.
        let e = match OutDir::create_for(&out, "bench lod", &nothing()) {
            Err(e) => e,
            Ok(_) => panic!("a second run was let into a held folder"),
        };
        let text = e.to_string();
        assert!(matches!(e, OutDirError::InUse { pid: Some(p), .. } if p == std::process::id()));
        for needle in [
            out.display().to_string(),
            format!("verdant process {} (fly)", std::process::id()),
            "--out".to_owned(),
        ] {
            assert!(text.contains(&needle), "{needle:?} not in {text:?}");
        }
        // The refused run took nothing away: the folder and its lock are the first run's.
        assert!(out.join(LOCK_FILE).exists());
        // Let go (the run failed with nothing written): the folder it made is removed.
        drop(first);
        assert!(!out.exists());
        // Then a second run gets in, and a kept folder loses only its lock file.
        let second = OutDir::create_for(&out, "bench lod", &nothing()).unwrap();
        std::fs::write(out.join("report.json"), "{}").unwrap();
        second.keep();
        assert_eq!(names(&out), ["report.json"]);
        let third = OutDir::create(&out, &nothing()).unwrap();
        drop(third);
        assert_eq!(names(&out), ["report.json"]);
    }

    /// A lock file that is a symbolic link is never followed (the lock is truncated and
    /// written: the file it leads to would be lost), nor is a folder in its place taken: the
    /// run is refused, saying what is wrong, and the link and its target are as they were.
    #[test]
    fn a_lock_file_that_is_not_a_regular_file_is_refused_and_left_alone() {
        let tmp = tempfile::tempdir().unwrap();
        let precious = tmp.path().join("thesis.txt");
        std::fs::write(&precious, "my thesis").unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir(&out).unwrap();
        std::os::unix::fs::symlink(&precious, out.join(LOCK_FILE)).unwrap();
        let dangling = tmp.path().join("out2");
        std::fs::create_dir(&dangling).unwrap();
        std::os::unix::fs::symlink(tmp.path().join("nothing"), dangling.join(LOCK_FILE)).unwrap();
        let folder = tmp.path().join("out3");
        std::fs::create_dir_all(folder.join(LOCK_FILE)).unwrap();
        for dir in [&out, &dangling, &folder] {
            let e = match OutDir::create_for(dir, "eval sway", &nothing()) {
                Err(e) => e.to_string(),
                Ok(_) => panic!(
                    "{}: a run took a lock that is not a regular file",
                    dir.display()
                ),
            };
            assert!(
                e.contains("not a regular file") && e.contains(LOCK_FILE),
                "{e}"
            );
        }
        // A hard link to the file: refused too.
        let linked = tmp.path().join("out4");
        std::fs::create_dir(&linked).unwrap();
        std::fs::hard_link(&precious, linked.join(LOCK_FILE)).unwrap();
        let e = match OutDir::create_for(&linked, "fly", &nothing()) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("a run took a lock that is a hard link"),
        };
        assert!(e.contains("hard link") && e.contains(LOCK_FILE), "{e}");
        assert_eq!(std::fs::read_to_string(&precious).unwrap(), "my thesis");
        assert!(out.join(LOCK_FILE).is_symlink());
        assert!(!tmp.path().join("nothing").exists());
        assert!(folder.join(LOCK_FILE).is_dir());
    }

    /// An output folder spelled through a folder that does not exist (`nn/../outx`) leaves no
    /// `nn` behind, whether the run writes and keeps its folder or fails; a folder of that
    /// name that was there stays.
    #[test]
    fn an_output_folder_spelled_through_a_new_folder_leaves_it_behind_no_more() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("nn/../outx");
        let dir = OutDir::create_for(&out, "fly", &nothing()).unwrap();
        std::fs::write(out.join("report.json"), "{}").unwrap();
        dir.keep();
        assert_eq!(names(tmp.path()), ["outx"]);
        assert_eq!(names(&tmp.path().join("outx")), ["report.json"]);
        drop(OutDir::create_for(&tmp.path().join("mm/../outy"), "fly", &nothing()).unwrap());
        assert_eq!(names(tmp.path()), ["outx"]);
        std::fs::create_dir(tmp.path().join("kept")).unwrap();
        drop(OutDir::create_for(&tmp.path().join("kept/../outz"), "fly", &nothing()).unwrap());
        assert_eq!(names(tmp.path()), ["kept", "outx"]);
    }

    /// An output folder named with a trailing `.` is made and used like the folder itself.
    #[test]
    fn an_output_folder_named_through_a_dot_is_made() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("o6/.");
        let dir = OutDir::create_for(&out, "fly", &nothing()).unwrap();
        std::fs::write(out.join("report.json"), "{}").unwrap();
        dir.keep();
        assert_eq!(names(&tmp.path().join("o6")), ["report.json"]);
    }

    #[test]
    fn a_failed_run_removes_the_parent_folders_it_made_and_only_those() {
        let tmp = tempfile::tempdir().unwrap();
        // zz/yy/out, none of it there: a run that fails with nothing written leaves no zz.
        let out = tmp.path().join("zz/yy/out");
        drop(OutDir::create_for(&out, "fly", &nothing()).unwrap());
        assert!(names(tmp.path()).is_empty(), "{:?}", names(tmp.path()));
        // A parent that was there stays; so do the ones holding something else by then.
        std::fs::create_dir(tmp.path().join("zz")).unwrap();
        let dir = OutDir::create_for(&out, "fly", &nothing()).unwrap();
        std::fs::write(tmp.path().join("zz/yy/note.txt"), "mine").unwrap();
        drop(dir);
        assert_eq!(names(&tmp.path().join("zz/yy")), ["note.txt"]);
        assert!(!out.exists());
        // A kept run keeps them all.
        let kept = tmp.path().join("a/b");
        let dir = OutDir::create_for(&kept, "fly", &nothing()).unwrap();
        dir.keep();
        assert!(kept.is_dir());
    }

    /// A folder is refused, before anything is written, where a file the run writes there is
    /// one of its inputs (however it is spelled) or is no earlier run's output, saying which
    /// and why; an earlier run's outputs (8-bit RGB and RGBA PNGs, text) are replaced as before,
    /// and files the run does not write are not looked at.
    #[test]
    fn a_run_is_refused_where_it_would_write_over_its_input_or_a_users_file() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("out");
        std::fs::create_dir(&out).unwrap();
        image::RgbImage::new(2, 2)
            .save(out.join("chart.png"))
            .unwrap();
        image::RgbaImage::new(2, 2)
            .save(out.join("frame.png"))
            .unwrap();
        std::fs::write(out.join("t.csv"), "a,b\n").unwrap();
        std::fs::write(out.join("r.json"), "{}").unwrap();
        let earlier = ["chart.png", "frame.png", "r.json", "t.csv"];
        OutDir::create_for(&out, "bench lod", &Outputs::named(&earlier))
            .unwrap()
            .keep();
        // An input named through a link to the folder and `..`, and the lock file as an input
        // (which taking the lock would truncate).
        std::os::unix::fs::symlink(&out, tmp.path().join("link")).unwrap();
        std::fs::write(out.join(LOCK_FILE), "my data").unwrap();
        for (written, input) in [
            ("t.csv", tmp.path().join("link/../out/t.csv")),
            ("derive.csv", out.join(LOCK_FILE)),
        ] {
            let e = OutDir::create_for(
                &out,
                "eval derive",
                &Outputs::named(&[written]).reading("the DEM this run reads (--dem)", &input),
            )
            .err()
            .unwrap();
            let text = e.to_string();
            assert!(matches!(e, OutDirError::ReplacesInput { .. }), "{text}");
            let file = out.join(input.file_name().unwrap()).display().to_string();
            for needle in [
                file.as_str(),
                "(--dem)",
                "eval derive",
                "choose another --out",
            ] {
                assert!(text.contains(needle), "{needle:?} not in {text:?}");
            }
        }
        assert_eq!(
            std::fs::read_to_string(out.join(LOCK_FILE)).unwrap(),
            "my data"
        );
        std::fs::remove_file(out.join(LOCK_FILE)).unwrap();
        // Files that no run wrote, each refused saying what it is.
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(2, 2)
            .save(out.join("dem.png"))
            .unwrap();
        image::GrayImage::new(2, 2)
            .save(out.join("map.png"))
            .unwrap();
        image::RgbImage::new(2, 2)
            .save(out.join("shot.png"))
            .unwrap();
        std::fs::write(out.join("shot.json"), "{}").unwrap();
        image::RgbImage::new(2, 2)
            .save(out.join("pic.png"))
            .unwrap();
        std::fs::write(out.join("pic.json"), "{}").unwrap();
        std::fs::write(out.join("notes.png"), "my notes").unwrap();
        std::fs::create_dir(out.join("shots.png")).unwrap();
        // A link to a file an earlier run could have written (the rename would replace it).
        std::fs::write(tmp.path().join("precious.csv"), "a,b\n").unwrap();
        std::os::unix::fs::symlink(tmp.path().join("precious.csv"), out.join("linked.csv"))
            .unwrap();
        let before = names(&out);
        for (name, why) in [
            ("linked.csv", "is a symbolic link"),
            ("dem.png", "is a 16-bit grey PNG"),
            ("map.png", "is an 8-bit grey PNG"),
            ("shot.png", "has a JSON sidecar"),
            ("pic.json", "is the sidecar of"),
            ("notes.png", "is not a PNG image"),
        ] {
            let e = OutDir::create_for(&out, "fly", &Outputs::named(&[name]))
                .err()
                .unwrap();
            let text = e.to_string();
            assert!(matches!(e, OutDirError::NotAnOutput { .. }), "{text}");
            let file = out.join(name).display().to_string();
            for needle in [file.as_str(), why, "fly writes", "--out"] {
                assert!(text.contains(needle), "{needle:?} not in {text:?}");
            }
        }
        // Only the files the run writes are looked at; a folder in an output's place is left to
        // fail the write that meets it (nothing is lost there).
        OutDir::create_for(&out, "fly", &Outputs::named(&["report.json", "shots.png"]))
            .unwrap()
            .keep();
        assert_eq!(names(&out), before);
    }

    #[test]
    fn a_stale_lock_file_does_not_hold_the_folder() {
        // A run that was killed leaves its lock file, but no lock: the OS let go of it.
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join(LOCK_FILE), "4000000000 fly\n").unwrap();
        let dir = OutDir::create_for(tmp.path(), "fly", &nothing()).unwrap();
        let lock = std::fs::read_to_string(tmp.path().join(LOCK_FILE)).unwrap();
        assert_eq!(lock, format!("{} fly\n", std::process::id()));
        dir.keep();
        assert!(names(tmp.path()).is_empty());
    }
}
