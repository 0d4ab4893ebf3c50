//! Faults for `verdant soak --faults RATE` on a world on disk: the soak flies a copy of the
//! world whose tile files are broken (removed, truncated, overwritten with garbage, emptied, or
//! replaced by a folder) and restored again while it flies. The world itself is never touched.
//!
//! The rate is the share of the copy's tile files of level 1 and finer that are broken at any
//! moment; each [`FileFaults::step`] restores the broken ones and breaks a fresh random set.
//! Level 0 is left whole: its tiles are loaded once, before the first frame, and stay resident
//! (every other tile is drawn from them while its own is broken).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::tools::fly::write_atomic;

/// How a tile file is broken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileFault {
    /// Removed.
    Missing,
    /// Cut to half its length.
    Truncated,
    /// Overwritten with as many pseudo-random bytes.
    Garbage,
    /// Emptied.
    Empty,
    /// Replaced by a folder of the same name.
    Folder,
}

impl FileFault {
    const ALL: [FileFault; 5] = [
        FileFault::Missing,
        FileFault::Truncated,
        FileFault::Garbage,
        FileFault::Empty,
        FileFault::Folder,
    ];
}

/// What the fault injector did, for `soak.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FileFaultCounts {
    /// Tile files that may be broken (level 1 and finer).
    pub files: u64,
    /// Rounds of faults (each restores the last round's files and breaks a new set).
    pub rounds: u64,
    /// Files removed.
    pub missing: u64,
    /// Files truncated.
    pub truncated: u64,
    /// Files overwritten with garbage.
    pub garbage: u64,
    /// Files emptied.
    pub empty: u64,
    /// Files replaced by a folder.
    pub folder: u64,
    /// Files restored.
    pub restored: u64,
}

impl FileFaultCounts {
    /// Faults injected in all.
    pub fn injected(&self) -> u64 {
        self.missing + self.truncated + self.garbage + self.empty + self.folder
    }
}

/// The file that marks a faulty copy as verdant's own scratch, so that a copy left by an
/// interrupted run is removed by the next.
const COPY_MARKER: &str = ".verdant-faulty-copy";

/// A copy of a world whose tile files are broken and restored.
pub struct FileFaults {
    original: PathBuf,
    copy: PathBuf,
    /// Tile files of level 1 and finer, relative to the world's folder.
    files: Vec<PathBuf>,
    broken: Vec<PathBuf>,
    rate: f64,
    rng: crate::tools::rng::Rng,
    counts: FileFaultCounts,
}

impl FileFaults {
    /// Copies the world in `original` to `copy` (which must not exist) and readies faults at
    /// `rate` (0..=1). Nothing is broken before the first [`FileFaults::step`].
    pub fn new(original: &Path, copy: &Path, rate: f64, seed: u64) -> Result<Self> {
        anyhow::ensure!(
            rate.is_finite() && (0.0..=1.0).contains(&rate),
            "--faults must be in 0..=1, not {rate}"
        );
        let resolved = |p: &Path| std::path::absolute(p).and_then(|p| p.canonicalize());
        if let (Ok(world), Some(Ok(parent))) = (resolved(original), copy.parent().map(resolved))
            && parent.starts_with(&world)
        {
            anyhow::bail!(
                "{}: the faulty copy of the world would go inside the world it copies ({}); \
                 choose an --out outside it",
                copy.display(),
                original.display()
            );
        }
        if copy.join(COPY_MARKER).is_file() {
            // A copy of an earlier run that was stopped before it could remove it (Ctrl-C, a
            // kill): scratch, in a folder this run holds locked.
            std::fs::remove_dir_all(copy).with_context(|| {
                format!(
                    "cannot remove {}, the faulty copy an interrupted run left",
                    copy.display()
                )
            })?;
            log::warn!(
                "removed {}, the faulty copy of the world that an interrupted run left",
                copy.display()
            );
        }
        anyhow::ensure!(
            !copy.exists(),
            "{} exists already and is not a faulty copy of a world that verdant made: the \
             faulty copy goes there; move it away or choose another --out",
            copy.display()
        );
        if let Err(e) = copy_world(original, copy)
            .and_then(|()| std::fs::write(copy.join(COPY_MARKER), b"a faulty copy of a world\n"))
        {
            // A partial copy is this run's own (the folder did not exist): not left behind.
            let _ = std::fs::remove_dir_all(copy);
            return Err(anyhow::Error::new(e).context(format!(
                "cannot copy {} to {} for its faults",
                original.display(),
                copy.display()
            )));
        }
        let mut files = Vec::new();
        let tiles = copy.join("tiles");
        for level in
            std::fs::read_dir(&tiles).with_context(|| format!("cannot list {}", tiles.display()))?
        {
            let level = level?;
            let name = level.file_name().to_string_lossy().into_owned();
            if name == "L0" || !name.starts_with('L') || !level.file_type()?.is_dir() {
                continue;
            }
            for file in std::fs::read_dir(level.path())? {
                let file = file?;
                if file.file_type()?.is_file() {
                    files.push(Path::new("tiles").join(&name).join(file.file_name()));
                }
            }
        }
        // A fixed order, so that a seed picks the same files on every machine.
        files.sort();
        Ok(Self {
            original: original.to_path_buf(),
            copy: copy.to_path_buf(),
            counts: FileFaultCounts {
                files: files.len() as u64,
                ..FileFaultCounts::default()
            },
            files,
            broken: Vec::new(),
            rate,
            rng: crate::tools::rng::Rng(seed ^ 0xfa17_5eed),
        })
    }

    /// The faulty world's folder.
    pub fn world_dir(&self) -> &Path {
        &self.copy
    }

    /// What was done so far.
    pub fn counts(&self) -> &FileFaultCounts {
        &self.counts
    }

    /// Restores the files broken last and breaks a fresh random set: the rate's share of the
    /// files (at least one when the rate is not 0).
    pub fn step(&mut self) -> Result<()> {
        self.restore()?;
        if self.rate == 0.0 || self.files.is_empty() {
            return Ok(());
        }
        let n = ((self.rate * self.files.len() as f64).round() as usize).clamp(1, self.files.len());
        // A partial Fisher-Yates shuffle picks n distinct files.
        let len = self.files.len();
        for i in 0..n {
            let j = i + (self.rng.next() * (len - i) as f64) as usize;
            self.files.swap(i, j.min(len - 1));
        }
        for i in 0..n {
            let kind = FileFault::ALL[(self.rng.next() * 5.0) as usize % 5];
            let rel = self.files[i].clone();
            self.break_file(&rel, kind)?;
            self.broken.push(rel);
        }
        self.counts.rounds += 1;
        Ok(())
    }

    /// Puts every broken file back as it was, each whole at once ([`write_atomic`]), so that a
    /// load never sees a half-restored file.
    pub fn restore(&mut self) -> Result<()> {
        for rel in std::mem::take(&mut self.broken) {
            let at = self.copy.join(&rel);
            match std::fs::symlink_metadata(&at) {
                Ok(m) if m.is_dir() => std::fs::remove_dir_all(&at)?,
                Ok(_) => std::fs::remove_file(&at)?,
                Err(_) => {}
            }
            let bytes = std::fs::read(self.original.join(&rel))
                .with_context(|| format!("cannot restore {}", at.display()))?;
            write_atomic(&at, |w| w.write_all(&bytes))?;
            self.counts.restored += 1;
        }
        Ok(())
    }

    fn break_file(&mut self, rel: &Path, kind: FileFault) -> Result<()> {
        let at = self.copy.join(rel);
        let len = std::fs::metadata(&at)
            .with_context(|| format!("cannot read {}", at.display()))?
            .len() as usize;
        let replace = |bytes: &[u8]| write_atomic(&at, |w| w.write_all(bytes));
        match kind {
            FileFault::Missing => {
                std::fs::remove_file(&at)?;
                self.counts.missing += 1;
            }
            FileFault::Truncated => {
                let bytes = std::fs::read(&at)?;
                replace(&bytes[..len / 2])?;
                self.counts.truncated += 1;
            }
            FileFault::Garbage => {
                let bytes: Vec<u8> = (0..len).map(|_| (self.rng.next() * 256.0) as u8).collect();
                replace(&bytes)?;
                self.counts.garbage += 1;
            }
            FileFault::Empty => {
                replace(&[])?;
                self.counts.empty += 1;
            }
            FileFault::Folder => {
                std::fs::remove_file(&at)?;
                std::fs::create_dir(&at)?;
                self.counts.folder += 1;
            }
        }
        Ok(())
    }
}

impl Drop for FileFaults {
    fn drop(&mut self) {
        // The copy is scratch: it goes with the injector, whatever state it is in.
        let _ = std::fs::remove_dir_all(&self.copy);
    }
}

/// Makes the faulty copy of the world `from` at `to`: its `world.toml` and its `tiles/` copied
/// (the files the faults damage), everything else in the folder (plant files, sources, notes)
/// linked to where it is, never copied: a link to a large folder (or to `/`) costs nothing.
fn copy_world(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(to)?;
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let name = entry.file_name();
        let target = to.join(&name);
        if name == "world.toml" {
            std::fs::copy(entry.path(), &target)?;
        } else if name == "tiles" {
            copy_dir(&entry.path(), &target)?;
        } else {
            link_or_copy(&entry.path(), &target)?;
        }
    }
    Ok(())
}

/// A link at `to` to what `from` leads to (a file or folder read, never written, by a run).
#[cfg(unix)]
fn link_or_copy(from: &Path, to: &Path) -> std::io::Result<()> {
    match from.canonicalize() {
        Ok(real) => std::os::unix::fs::symlink(real, to),
        Err(_) => Ok(()), // a dangling link: nothing to read there
    }
}

#[cfg(not(unix))]
fn link_or_copy(from: &Path, to: &Path) -> std::io::Result<()> {
    match std::fs::metadata(from) {
        Ok(m) if m.is_dir() => copy_dir(from, to),
        Ok(m) if m.is_file() => std::fs::copy(from, to).map(|_| ()),
        _ => Ok(()),
    }
}

/// Copies the folder `from` to `to`, following symlinks (a world whose `tiles/` is a link to
/// another disk is copied whole), at most [`MAX_COPY_DEPTH`] folders deep (a symlink loop ends
/// there with an error).
fn copy_dir(from: &Path, to: &Path) -> std::io::Result<()> {
    copy_dir_within(from, to, MAX_COPY_DEPTH)
}

/// How deep [`copy_dir`] goes: a world is `tiles/L{level}/` deep.
const MAX_COPY_DEPTH: u32 = 8;

fn copy_dir_within(from: &Path, to: &Path, depth: u32) -> std::io::Result<()> {
    if depth == 0 {
        return Err(std::io::Error::other(format!(
            "{}: folders nested deeper than {MAX_COPY_DEPTH} (a symlink loop?)",
            from.display()
        )));
    }
    std::fs::create_dir_all(to)?;
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        let Ok(meta) = std::fs::metadata(entry.path()) else {
            continue;
        };
        if meta.is_dir() {
            copy_dir_within(&entry.path(), &target, depth - 1)?;
        } else if meta.is_file() {
            std::fs::copy(entry.path(), &target)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn world() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz")
    }

    #[test]
    fn faults_break_the_rates_share_and_restore_it_byte_for_byte() {
        let tmp = tempfile::tempdir().unwrap();
        let copy = tmp.path().join("w");
        let mut f = FileFaults::new(&world(), &copy, 0.05, 7).unwrap();
        let files = f.counts().files;
        assert!(files > 100, "{files} tile files");
        let damaged = |f: &FileFaults| {
            f.files
                .iter()
                .filter(|rel| {
                    std::fs::read(copy.join(rel)).ok() != std::fs::read(world().join(rel)).ok()
                })
                .count() as u64
        };
        for round in 1..=4 {
            f.step().unwrap();
            let want = (0.05 * files as f64).round() as u64;
            assert_eq!(damaged(&f), want, "round {round}");
            assert_eq!(f.counts().injected(), want * round);
        }
        let c = f.counts().clone();
        assert!(c.missing > 0 && c.truncated > 0 && c.garbage > 0 && c.empty > 0 && c.folder > 0);
        f.restore().unwrap();
        assert_eq!(damaged(&f), 0);
        // Level 0 is never broken, and the world itself is never touched.
        assert!(f.files.iter().all(|rel| !rel.starts_with("tiles/L0")));
        drop(f);
        assert!(!copy.exists(), "the faulty copy is removed");
    }

    /// A copy left by a run that was stopped before it could remove it is removed by the next
    /// run; a folder of the same name that verdant did not make is refused and kept; a copy
    /// inside the world it copies is refused before anything is copied.
    #[test]
    fn a_left_copy_is_replaced_and_a_foreign_folder_or_a_copy_inside_the_world_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let copy = tmp.path().join("w");
        let first = FileFaults::new(&world(), &copy, 0.5, 1).unwrap();
        // As if the run were killed: the copy stays.
        std::mem::forget(first);
        std::fs::write(copy.join("tiles/L1/0_0.height.exr"), "broken").unwrap();
        let second = FileFaults::new(&world(), &copy, 0.5, 1).unwrap();
        assert_eq!(
            std::fs::read(copy.join("tiles/L1/0_0.height.exr")).unwrap(),
            std::fs::read(world().join("tiles/L1/0_0.height.exr")).unwrap()
        );
        drop(second);
        assert!(!copy.exists());

        std::fs::create_dir(&copy).unwrap();
        std::fs::write(copy.join("mine.txt"), "mine").unwrap();
        let err = FileFaults::new(&world(), &copy, 0.5, 1)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("not a faulty copy"), "{err}");
        assert_eq!(
            std::fs::read_to_string(copy.join("mine.txt")).unwrap(),
            "mine"
        );

        let w = tmp.path().join("world");
        copy_dir(&world(), &w).unwrap();
        let inside = w.join("soak/.world-with-faults");
        std::fs::create_dir_all(inside.parent().unwrap()).unwrap();
        let err = format!("{:#}", FileFaults::new(&w, &inside, 0.5, 1).err().unwrap());
        assert!(err.contains("inside the world it copies"), "{err}");
        assert!(!inside.exists());
    }

    /// Only what the faults damage is copied: a world folder holding (or linking to) a large
    /// folder beside its tiles costs no more disk, and what is there is still read through the
    /// copy.
    #[cfg(unix)]
    #[test]
    fn the_faulty_copy_copies_the_tiles_and_links_the_rest() {
        let tmp = tempfile::tempdir().unwrap();
        let w = tmp.path().join("world");
        copy_dir(&world(), &w).unwrap();
        let big = tmp.path().join("big");
        std::fs::create_dir_all(big.join("a/b")).unwrap();
        let blob = std::fs::File::create(big.join("a/b/blob.bin")).unwrap();
        blob.set_len(64 << 30).unwrap(); // 64 GiB, sparse: a copy would fill the disk
        drop(blob);
        std::os::unix::fs::symlink(&big, w.join("extra")).unwrap();
        std::os::unix::fs::symlink(big.join("a/b/blob.bin"), w.join("blob_link.bin")).unwrap();
        std::fs::create_dir(w.join("plants")).unwrap();
        std::fs::write(w.join("plants/fern.txt"), "a fern").unwrap();
        let copy = tmp.path().join("copy");
        let f = FileFaults::new(&w, &copy, 0.5, 3).unwrap();
        assert!(!copy.join("world.toml").is_symlink());
        assert!(!copy.join("tiles").is_symlink() && copy.join("tiles").is_dir());
        for linked in ["extra", "blob_link.bin", "plants", "source"] {
            assert!(copy.join(linked).is_symlink(), "{linked} was copied");
        }
        assert_eq!(
            std::fs::read_to_string(copy.join("plants/fern.txt")).unwrap(),
            "a fern"
        );
        drop(f);
        // The copy goes; what it linked to stays.
        assert!(!copy.exists());
        assert!(big.join("a/b/blob.bin").is_file());
        assert!(w.join("plants/fern.txt").is_file());
    }

    /// A world whose `tiles/` is a symlink (to another disk, say) is copied whole.
    #[cfg(unix)]
    #[test]
    fn a_world_with_symlinked_tiles_is_copied_whole() {
        let tmp = tempfile::tempdir().unwrap();
        let w = tmp.path().join("world");
        std::fs::create_dir(&w).unwrap();
        std::fs::copy(world().join("world.toml"), w.join("world.toml")).unwrap();
        std::os::unix::fs::symlink(world().join("tiles"), w.join("tiles")).unwrap();
        let faults = FileFaults::new(&w, &tmp.path().join("copy"), 0.5, 1).unwrap();
        assert!(faults.counts().files > 0);
        assert!(tmp.path().join("copy/tiles/L0").is_dir());
    }

    #[test]
    fn a_rate_outside_0_to_1_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        for rate in [-0.1, 1.5, f64::NAN] {
            let e = FileFaults::new(&world(), &tmp.path().join("w"), rate, 1)
                .err()
                .unwrap();
            assert!(e.to_string().contains("0..=1"), "{e}");
        }
    }
}
