//! Where a bake reads its DEM: one file held whole, or many files joined
//! ([`crate::world::mosaic`]) and read a chunk at a time, so that a mosaic of any size is baked
//! in bounded memory.
//!
//! A mosaic is cut into chunks of [`CHUNK`] x [`CHUNK`] samples of the joined grid. A chunk's
//! heights are the join of the files over the chunk and [`FILL_MARGIN`] samples around it, its
//! voids and the gaps between files filled there ([`crate::world::nodata`]), cropped to the
//! chunk: a sample's value depends only on where it lies, never on which part of the bake asks
//! for it, so neighbouring tiles agree however the work is split. Files and filled chunks are
//! kept in small least-recently-used caches whose sizes the memory limit sets.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex};

use lru::LruCache;

use crate::world::dem::{Dem, DemFormat, DemOptions, MAX_NODATA_FRACTION};
use crate::world::dem_grid::DemWindow;
use crate::world::error::WorldError;
use crate::world::mosaic::Layout;

/// What the process needs besides the bake's own data (code, allocator, encoders), bytes.
pub(super) const BASE_BYTES: u64 = 40 << 20;

/// Samples a side of a mosaic's chunk.
pub(super) const CHUNK: usize = 1024;
/// Samples around a chunk that its void filling sees (more than the widest gap between files).
pub(super) const FILL_MARGIN: usize = 256;
/// Most samples a mosaic may have (a bake refuses more than 65,536 cells a side anyway).
const MAX_MOSAIC_SAMPLES: u64 = 1 << 36;

/// A bake's DEM.
pub(super) enum DemSource {
    /// One file, read and filled whole.
    Whole(Dem),
    /// Several files, read in chunks.
    Mosaic(Box<Mosaic>),
}

/// Several DEM files joined and read in chunks (see the module docs).
pub(super) struct Mosaic {
    layout: Layout,
    named: PathBuf,
    chunks: Mutex<LruCache<[usize; 2], Arc<Vec<f32>>>>,
    /// Chunks being made now, each by one thread; the others that need one wait for it on
    /// `made` rather than read its files again.
    making: Mutex<HashSet<[usize; 2]>>,
    made: Condvar,
    /// Voids filled in each chunk, once it has been made.
    filled: Mutex<Vec<Option<u64>>>,
}

/// Refuses a PNG DEM (`header`, `samples` of them) that the memory limit cannot hold while it
/// is decoded: its file, its 16-bit samples and their heights at once, besides the process's
/// own; the limit is named with what it would take.
fn check_whole_png(
    path: &Path,
    header: &Dem,
    samples: u64,
    memory_mib: u64,
) -> Result<(), WorldError> {
    let file = std::fs::metadata(path)
        .map_err(|e| WorldError::io(path, e))?
        .len();
    let need = BASE_BYTES + file + samples * (2 + 4);
    if need <= memory_mib.saturating_mul(1 << 20) {
        return Ok(());
    }
    Err(WorldError::bad_option(
        "--memory-mib",
        memory_mib,
        format!(
            "at least {} to decode this DEM ({}: {}x{} samples; a PNG DEM is decoded whole, its \
             file, 16-bit samples and heights held at once; a GeoTIFF is read in windows), and \
             the rest of the bake's plan, checked once it is decoded, may need more",
            need.div_ceil(1 << 20),
            path.display(),
            header.width,
            header.height
        ),
    ))
}

impl DemSource {
    /// Opens the DEM files: one file small enough for a quarter of `memory_mib` is read whole
    /// (and filled whole), on disk or at an address; a larger one and several are laid out
    /// from their headers and read in chunks.
    pub(super) fn open(
        files: &[PathBuf],
        named: &Path,
        options: &DemOptions,
        memory_mib: u64,
    ) -> Result<DemSource, WorldError> {
        if let [one] = files
            && !crate::world::window::is_remote(one)
        {
            // Held whole: the heights, and the fill's pyramid where there are voids.
            let (header, _) = crate::world::window::Rows::open(one, options, MAX_MOSAIC_SAMPLES)?;
            let samples = u64::from(header.width) * u64::from(header.height);
            let bytes = samples * 4 * 3;
            if header.format == DemFormat::PngSidecar {
                // A PNG is decoded whole: weighed from its header before a sample is decoded.
                check_whole_png(one, &header, samples, memory_mib)?;
            }
            if bytes <= (memory_mib << 20) / 4 || header.format == DemFormat::PngSidecar {
                return Ok(DemSource::Whole(crate::world::mosaic::load_files(
                    files, named, options,
                )?));
            }
        }
        if let [one] = files
            && crate::world::window::is_remote(one)
        {
            // A file at an address small enough for a quarter of the limit: read whole (an .hgt
            // tile in reads of at most 4 MiB, a GeoTIFF a request a strip or tile) rather than a
            // chunk at a time (which reads a row of an .hgt tile or a strip again for each chunk
            // across it), and filled whole, as the same file on disk would be.
            let (mut dem, rows) =
                crate::world::window::Rows::open(one, options, MAX_MOSAIC_SAMPLES)?;
            let samples = u64::from(dem.width) * u64::from(dem.height);
            if samples * 4 * 3 <= (memory_mib << 20) / 4 {
                dem.heights = rows.read([0, dem.height as usize])?;
                dem.fill_nodata(one)?;
                return Ok(DemSource::Whole(dem));
            }
        }
        if files.is_empty() {
            return Err(WorldError::DemMosaic {
                path: named.to_path_buf(),
                problem: "no DEM file given".into(),
            });
        }
        let layout = Layout::open(files, options, MAX_MOSAIC_SAMPLES)?;
        let n = chunks_across(&layout.header);
        Ok(DemSource::Mosaic(Box::new(Mosaic {
            layout,
            named: named.to_path_buf(),
            chunks: Mutex::new(LruCache::new(std::num::NonZeroUsize::MIN)),
            making: Mutex::new(HashSet::new()),
            made: Condvar::new(),
            filled: Mutex::new(vec![None; n[0] * n[1]]),
        })))
    }

    /// The DEM's size, spacing and georeferencing (a mosaic's heights are left empty).
    pub(super) fn header(&self) -> &Dem {
        match self {
            DemSource::Whole(dem) => dem,
            DemSource::Mosaic(m) => &m.layout.header,
        }
    }

    /// Bytes held whatever the caches hold: a whole DEM's heights.
    pub(super) fn resident_bytes(&self) -> u64 {
        match self {
            DemSource::Whole(dem) => dem.heights.len() as u64 * 4,
            DemSource::Mosaic(_) => 0,
        }
    }

    /// Bytes one cached chunk takes and the peak of making one; zero for a whole DEM.
    pub(super) fn cache_unit_bytes(&self) -> [u64; 2] {
        match self {
            DemSource::Whole(_) => [0; 2],
            DemSource::Mosaic(m) => {
                let side = CHUNK + 2 * FILL_MARGIN;
                let region = (side * side) as u64;
                // The joined region (heights and owners), the fill's pyramid (values and
                // weights, a third more) and the rows of one file read for it (a strip or a
                // row of tiles more, decoded as 8-byte patterns and then as heights), with the
                // strip or tile being decoded.
                let rows = (side + m.layout.largest_chunk_rows()) as u64;
                let file = m.layout.widest_read(side) as u64 * rows * (8 + 4)
                    + m.layout.largest_chunk_bytes();
                [
                    (CHUNK * CHUNK * 4) as u64,
                    region * (4 + 2) + region * 8 * 4 / 3 + file,
                ]
            }
        }
    }

    /// Sets how many chunks a mosaic keeps (at least one).
    pub(super) fn set_cache(&self, chunks: usize) {
        if let DemSource::Mosaic(m) = self {
            let n =
                std::num::NonZeroUsize::new(chunks.max(1)).unwrap_or(std::num::NonZeroUsize::MIN);
            lock(&m.chunks).resize(n);
        }
    }

    /// The posts [`DemWindow::sample`] needs for positions in `x` by `y` (metres from the
    /// south-west sample).
    pub(super) fn window(&self, x: [f64; 2], y: [f64; 2]) -> Result<DemWindow<'_>, WorldError> {
        let header = self.header();
        let (cols, rows) = header.posts_for(x, y);
        let width = cols[1] - cols[0];
        let heights = match self {
            DemSource::Whole(dem) => {
                let w = dem.width as usize;
                let mut out = Vec::with_capacity(width * (rows[1] - rows[0]));
                for r in rows[0]..rows[1] {
                    out.extend_from_slice(&dem.heights[r * w + cols[0]..r * w + cols[1]]);
                }
                out
            }
            DemSource::Mosaic(m) => m.window(cols, rows)?,
        };
        Ok(DemWindow {
            dem: header,
            first: [cols[0], rows[0]],
            width,
            heights,
        })
    }

    /// Voids filled so far (a mosaic counts each chunk once it is made).
    pub(super) fn nodata_filled(&self) -> u64 {
        match self {
            DemSource::Whole(dem) => dem.nodata_filled,
            DemSource::Mosaic(m) => lock(&m.filled).iter().flatten().sum(),
        }
    }

    /// A DEM read in chunks: the bytes read from its files so far (headers among them) and
    /// the files' sizes; `None` for one read whole.
    pub(super) fn bytes_read(&self) -> Option<[u64; 2]> {
        match self {
            DemSource::Whole(_) => None,
            DemSource::Mosaic(m) => Some(m.layout.bytes_read()),
        }
    }

    /// Refuses a mosaic more than [`MAX_NODATA_FRACTION`] of which was void (once every chunk
    /// has been made).
    pub(super) fn check_nodata(&self) -> Result<(), WorldError> {
        let header = self.header();
        let total = u64::from(header.width) * u64::from(header.height);
        let nodata = self.nodata_filled();
        match self {
            DemSource::Mosaic(m) if nodata as f64 > MAX_NODATA_FRACTION * total as f64 => {
                Err(WorldError::TooMuchNodata {
                    path: m.named.clone(),
                    nodata,
                    total,
                    max_fraction: MAX_NODATA_FRACTION,
                })
            }
            _ => Ok(()),
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Chunks across and down a grid.
fn chunks_across(header: &Dem) -> [usize; 2] {
    [header.width, header.height].map(|n| (n as usize).div_ceil(CHUNK))
}

impl Mosaic {
    /// Columns `cols` and rows `rows` (from the north, ends exclusive), north first.
    fn window(&self, cols: [usize; 2], rows: [usize; 2]) -> Result<Vec<f32>, WorldError> {
        let (w, h) = (cols[1] - cols[0], rows[1] - rows[0]);
        let mut out = vec![0f32; w * h];
        for cj in rows[0] / CHUNK..rows[1].div_ceil(CHUNK) {
            for ci in cols[0] / CHUNK..cols[1].div_ceil(CHUNK) {
                let chunk = self.chunk([ci, cj])?;
                let cw = self.chunk_size([ci, cj])[0];
                let (c0, c1) = ((ci * CHUNK).max(cols[0]), ((ci + 1) * CHUNK).min(cols[1]));
                let (r0, r1) = ((cj * CHUNK).max(rows[0]), ((cj + 1) * CHUNK).min(rows[1]));
                for r in r0..r1 {
                    let from = (r - cj * CHUNK) * cw + (c0 - ci * CHUNK);
                    let to = (r - rows[0]) * w + (c0 - cols[0]);
                    out[to..to + (c1 - c0)].copy_from_slice(&chunk[from..from + (c1 - c0)]);
                }
            }
        }
        Ok(out)
    }

    fn chunk_size(&self, at: [usize; 2]) -> [usize; 2] {
        let n = [self.layout.header.width, self.layout.header.height];
        [0, 1].map(|a| ((at[a] + 1) * CHUNK).min(n[a] as usize) - at[a] * CHUNK)
    }

    /// Chunk `at` (columns, rows from the north), from the cache or made. A chunk another
    /// thread is making is waited for, not made twice at once.
    fn chunk(&self, at: [usize; 2]) -> Result<Arc<Vec<f32>>, WorldError> {
        {
            let mut making = lock(&self.making);
            loop {
                // Looked up with `making` held, so that a chunk finished between the look and
                // the claim is found, not made again.
                if let Some(c) = lock(&self.chunks).get(&at) {
                    return Ok(c.clone());
                }
                if making.insert(at) {
                    break;
                }
                while making.contains(&at) {
                    making = self
                        .made
                        .wait(making)
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                }
            }
        }
        // Releases the claim however the making ends (an error or a panic too), and wakes
        // the waiters: they take the chunk from the cache, or make it themselves.
        struct Claim<'a>(&'a Mosaic, [usize; 2]);
        impl Drop for Claim<'_> {
            fn drop(&mut self) {
                lock(&self.0.making).remove(&self.1);
                self.0.made.notify_all();
            }
        }
        let _claim = Claim(self, at);
        let chunk = Arc::new(self.make_chunk(at)?);
        lock(&self.chunks).put(at, chunk.clone());
        Ok(chunk)
    }

    /// Joins the files over the chunk and its margin, fills the voids there, keeps the chunk.
    fn make_chunk(&self, at: [usize; 2]) -> Result<Vec<f32>, WorldError> {
        let header = &self.layout.header;
        let n = [header.width as usize, header.height as usize];
        let size = self.chunk_size(at);
        let core = [0, 1].map(|a| [at[a] * CHUNK, at[a] * CHUNK + size[a]]);
        let region = [0, 1].map(|a| {
            [
                core[a][0].saturating_sub(FILL_MARGIN),
                (core[a][1] + FILL_MARGIN).min(n[a]),
            ]
        });
        let mut heights = self.layout.region(region[0], region[1])?;
        let rw = region[0][1] - region[0][0];
        let rh = region[1][1] - region[1][0];
        let voids_in_core = |heights: &[f32]| {
            (core[1][0]..core[1][1])
                .map(|r| {
                    let row = (r - region[1][0]) * rw;
                    heights[row + core[0][0] - region[0][0]..row + core[0][1] - region[0][0]]
                        .iter()
                        .filter(|h| h.is_nan())
                        .count() as u64
                })
                .sum::<u64>()
        };
        let voids = voids_in_core(&heights);
        if heights.iter().all(|h| h.is_nan()) {
            return Err(WorldError::TooMuchNodata {
                path: self.named.clone(),
                nodata: (rw * rh) as u64,
                total: (rw * rh) as u64,
                max_fraction: MAX_NODATA_FRACTION,
            });
        }
        crate::world::nodata::fill_nodata(rw, rh, &mut heights);
        let mut out = Vec::with_capacity(size[0] * size[1]);
        for r in core[1][0]..core[1][1] {
            let row = (r - region[1][0]) * rw;
            out.extend_from_slice(
                &heights[row + core[0][0] - region[0][0]..row + core[0][1] - region[0][0]],
            );
        }
        if let Some((k, &h)) = out.iter().enumerate().find(|(_, h)| {
            let [lo, hi] = crate::world::PLAUSIBLE_HEIGHTS_M;
            !(lo..=hi).contains(&f64::from(**h))
        }) {
            // Blamed on the file that gives the sample, at its own column and row.
            let (column, row) = (
                (core[0][0] + k % size[0]) as u32,
                (core[1][0] + k / size[0]) as u32,
            );
            let (file, column, row) = self
                .layout
                .file_at(column, row)
                .map(|(f, c, r)| (f.to_path_buf(), c, r))
                .unwrap_or_else(|| (self.named.clone(), column, row));
            return Err(WorldError::ImplausibleHeight {
                path: crate::world::dem::sidecar_of(&file).unwrap_or_else(|| file.clone()),
                dem: file,
                column,
                row,
                value: f64::from(h),
                range: crate::world::PLAUSIBLE_HEIGHTS_M,
            });
        }
        let across = chunks_across(header)[0];
        lock(&self.filled)[at[1] * across + at[0]] = Some(voids);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An SRTM3 `.hgt` tile of gentle slopes, too large for a quarter of 64 MiB, so that a
    /// bake reads it in chunks.
    fn chunked_source(dir: &Path) -> DemSource {
        let path = dir.join("N37W123.hgt");
        let side = 1201u32;
        let mut bytes = Vec::with_capacity((side * side * 2) as usize);
        for r in 0..side {
            for c in 0..side {
                bytes.extend_from_slice(&((100 + (r + 2 * c) / 8) as i16).to_be_bytes());
            }
        }
        std::fs::write(&path, bytes).unwrap();
        DemSource::open(
            std::slice::from_ref(&path),
            &path,
            &DemOptions::default(),
            64,
        )
        .unwrap()
    }

    /// Threads that ask for the same chunk at once wait for the one making it rather than
    /// each read its files again: they read what one thread alone reads.
    #[test]
    fn a_chunk_asked_for_at_once_is_made_once() {
        let dir = tempfile::tempdir().unwrap();
        let alone = chunked_source(dir.path());
        let DemSource::Mosaic(alone) = &alone else {
            panic!("the tile should be read in chunks")
        };
        let before = alone.layout.bytes_read()[0];
        let one = alone.chunk([0, 0]).unwrap();
        let read_alone = alone.layout.bytes_read()[0] - before;
        assert!(read_alone > 0);

        let source = chunked_source(dir.path());
        let DemSource::Mosaic(m) = &source else {
            panic!("the tile should be read in chunks")
        };
        let before = m.layout.bytes_read()[0];
        let start = std::sync::Barrier::new(4);
        let chunks: Vec<Arc<Vec<f32>>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(|| {
                        start.wait();
                        m.chunk([0, 0]).unwrap()
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        assert_eq!(
            m.layout.bytes_read()[0] - before,
            read_alone,
            "four threads asking at once read the files once"
        );
        for c in &chunks {
            assert_eq!(**c, *one);
        }
    }
}
