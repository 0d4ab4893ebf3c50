//! DEM files read a window of rows at a time, so that a bake never holds a whole large file:
//! an SRTM `.hgt` tile by seeking to its rows, a GeoTIFF (striped or tiled, a Cloud-Optimised
//! GeoTIFF among them) by reading and decoding only the strips or tiles that hold the rows. A
//! file may also be an `http://` address: its header and its chunks are then read with range
//! requests, with the tile client's deadlines and retries. PNG DEMs are read whole each time
//! (they are small: a PNG has no index to read a part of it by). A file on disk is opened when
//! read, and only the [`MAX_OPEN_DEM_FILES`] read last are kept open, so that a mosaic of
//! thousands of files stays within the process's limit of open files.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::dem::{Dem, DemOptions};
use super::error::WorldError;

pub use super::format::is_remote;

/// The name of the file `path` names: its last part, and for an address its path's last part
/// without the query (a signed URL's token) or the fragment.
pub fn file_name_of(path: &Path) -> String {
    if is_remote(path) {
        let text = path.to_string_lossy();
        let no_query = text.split(['?', '#']).next().unwrap_or("");
        return no_query.rsplit('/').next().unwrap_or("").to_owned();
    }
    path.file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// The whole of a remote file of at most `max` bytes (a VRT).
pub(crate) fn read_remote(path: &Path, max: u64) -> Result<Vec<u8>, WorldError> {
    let src = open_source(path)?;
    if src.len() > max {
        return Err(WorldError::FileTooLarge {
            path: path.to_path_buf(),
            size: src.len(),
            max,
        });
    }
    src.read_at(0, src.len())
}

/// Bytes of a file, local or remote, read at any offset.
trait ReadAt: Send + Sync {
    fn read_at(&self, offset: u64, count: u64) -> Result<Vec<u8>, WorldError>;
    fn len(&self) -> u64;
}

/// A [`ReadAt`] that counts the bytes read through it into a counter its [`Rows`] shares.
struct Counted {
    inner: Box<dyn ReadAt>,
    bytes: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl ReadAt for Counted {
    fn read_at(&self, offset: u64, count: u64) -> Result<Vec<u8>, WorldError> {
        let out = self.inner.read_at(offset, count)?;
        self.bytes
            .fetch_add(out.len() as u64, std::sync::atomic::Ordering::Relaxed);
        Ok(out)
    }
    fn len(&self) -> u64 {
        self.inner.len()
    }
}

/// A file on disk, opened when read: its handle is kept in [`HANDLES`] while it is among the
/// most recently read, so that a mosaic of thousands of files holds a bounded number open (one
/// each overran the usual limit of 1024 descriptors a process).
struct LocalFile {
    path: PathBuf,
    /// Its key in [`HANDLES`].
    id: u64,
    len: u64,
}

/// Most local DEM files held open at once (besides those being read this moment).
pub const MAX_OPEN_DEM_FILES: usize = 64;

/// The open handles of the most recently read [`LocalFile`]s, by their ids.
static HANDLES: std::sync::Mutex<Option<lru::LruCache<u64, std::sync::Arc<std::fs::File>>>> =
    std::sync::Mutex::new(None);

/// The next [`LocalFile`]'s id.
static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Runs `f` on the handle cache (created on first use), even after a panic elsewhere.
fn with_handles<T>(
    f: impl FnOnce(&mut lru::LruCache<u64, std::sync::Arc<std::fs::File>>) -> T,
) -> T {
    let mut guard = HANDLES
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let cache = guard.get_or_insert_with(|| {
        lru::LruCache::new(
            std::num::NonZeroUsize::new(MAX_OPEN_DEM_FILES).unwrap_or(std::num::NonZeroUsize::MIN),
        )
    });
    f(cache)
}

impl LocalFile {
    /// Opens `path` (a regular file), keeping its handle among the recent ones.
    fn open(path: &Path) -> Result<LocalFile, WorldError> {
        let (file, len) = super::format::open_regular(path)?;
        let id = NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        with_handles(|h| h.put(id, std::sync::Arc::new(file)));
        Ok(LocalFile {
            path: path.to_path_buf(),
            id,
            len,
        })
    }

    /// The file's handle: the kept one, or the file opened again (and kept) where it was let
    /// go; refused if the file's length changed meanwhile.
    fn handle(&self) -> Result<std::sync::Arc<std::fs::File>, WorldError> {
        if let Some(file) = with_handles(|h| h.get(&self.id).cloned()) {
            return Ok(file);
        }
        let (file, len) = super::format::open_regular(&self.path)?;
        if len != self.len {
            return Err(WorldError::io(
                &self.path,
                std::io::Error::other(format!(
                    "it holds {len} bytes now, not the {} it held when it was first read: it \
                     changed while it was read",
                    self.len
                )),
            ));
        }
        let file = std::sync::Arc::new(file);
        with_handles(|h| h.put(self.id, std::sync::Arc::clone(&file)));
        Ok(file)
    }
}

impl Drop for LocalFile {
    fn drop(&mut self) {
        with_handles(|h| h.pop(&self.id));
    }
}

impl ReadAt for LocalFile {
    fn read_at(&self, offset: u64, count: u64) -> Result<Vec<u8>, WorldError> {
        use std::os::unix::fs::FileExt;
        let mut buf = vec![0u8; count as usize];
        let file = self.handle()?;
        file.read_exact_at(&mut buf, offset).map_err(|e| {
            // Within the length it had when it was opened: the file was cut short since.
            match file.metadata() {
                Ok(m) if e.kind() == std::io::ErrorKind::UnexpectedEof && m.len() != self.len => {
                    WorldError::io(
                        &self.path,
                        std::io::Error::other(format!(
                            "it holds {} bytes now, not the {} it held when it was first read: \
                             it changed while it was read",
                            m.len(),
                            self.len
                        )),
                    )
                }
                _ => WorldError::io(&self.path, e),
            }
        })?;
        Ok(buf)
    }
    fn len(&self) -> u64 {
        self.len
    }
}

#[cfg(feature = "http")]
impl ReadAt for crate::stream::http::RangeFile {
    fn read_at(&self, offset: u64, count: u64) -> Result<Vec<u8>, WorldError> {
        crate::stream::http::RangeFile::read_at(self, offset, count)
    }
    fn len(&self) -> u64 {
        crate::stream::http::RangeFile::len(self)
    }
}

fn open_source(path: &Path) -> Result<Box<dyn ReadAt>, WorldError> {
    if is_remote(path) {
        #[cfg(feature = "http")]
        {
            let url = path.to_string_lossy();
            let file = crate::stream::http::RangeFile::open(&url, Default::default())?;
            return Ok(Box::new(file));
        }
        #[cfg(not(feature = "http"))]
        return Err(WorldError::DemMosaic {
            path: path.to_path_buf(),
            problem: "this build reads no HTTP addresses (the http feature is off)".into(),
        });
    }
    Ok(Box::new(LocalFile::open(path)?))
}

/// Bytes of a [`ReadAt`] as [`Read`] + [`Seek`], in blocks, for the TIFF decoder's many small
/// reads of a header.
struct Blocks<'a> {
    src: &'a dyn ReadAt,
    pos: u64,
    block: Option<(u64, Vec<u8>)>,
}

/// Bytes a block of [`Blocks`] reads at once.
const BLOCK: u64 = 64 << 10;

impl Read for Blocks<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let len = self.src.len();
        if self.pos >= len || buf.is_empty() {
            return Ok(0);
        }
        let start = self.pos / BLOCK * BLOCK;
        if self.block.as_ref().is_none_or(|(at, _)| *at != start) {
            let bytes = self
                .src
                .read_at(start, BLOCK.min(len - start))
                .map_err(std::io::Error::other)?;
            self.block = Some((start, bytes));
        }
        let (_, bytes) = self.block.as_ref().expect("just read");
        let from = (self.pos - start) as usize;
        let n = buf.len().min(bytes.len() - from);
        buf[..n].copy_from_slice(&bytes[from..from + n]);
        self.pos += n as u64;
        Ok(n)
    }
}

impl Seek for Blocks<'_> {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let len = self.src.len() as i128;
        let pos = match to {
            SeekFrom::Start(p) => i128::from(p),
            SeekFrom::End(d) => len + i128::from(d),
            SeekFrom::Current(d) => i128::from(self.pos) + i128::from(d),
        };
        if pos < 0 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "seek before the start",
            ));
        }
        self.pos = pos as u64;
        Ok(self.pos)
    }
}

/// The most bytes of an `.hgt` tile read at once (over HTTP, in one request).
const HGT_READ_BYTES: usize = 4 << 20;

/// A DEM file opened for reading in windows of rows.
pub struct Rows {
    path: PathBuf,
    kind: Kind,
    /// The file's size, bytes.
    len: u64,
    /// Bytes read from the file so far, its header among them.
    read: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

enum Kind {
    Png(DemOptions),
    Hgt {
        src: Box<dyn ReadAt>,
        side: usize,
    },
    Tiff {
        src: Box<dyn ReadAt>,
        tiff: super::geotiff::TiffWindows,
    },
}

impl Rows {
    /// Opens `path` (a file or an `http://` address): its header and georeferencing (the
    /// returned [`Dem`] holds no heights). The format is told from the content (and, for an
    /// `.hgt` tile, from its size); a grid of more than `max_samples` is refused.
    pub fn open(
        path: &Path,
        options: &DemOptions,
        max_samples: u64,
    ) -> Result<(Dem, Rows), WorldError> {
        Dem::check_cell_option(path, options)?;
        let read = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
        let src: Box<dyn ReadAt> = Box::new(Counted {
            inner: open_source(path)?,
            bytes: read.clone(),
        });
        let file_len = src.len();
        let head = src.read_at(0, 8.min(src.len()))?;
        let (mut dem, kind) = if head.starts_with(b"\x89PNG\r\n\x1a\n") {
            if is_remote(path) {
                return Err(WorldError::DemMosaic {
                    path: path.to_path_buf(),
                    problem: "a PNG DEM is read from disk only: over HTTP a DEM is a GeoTIFF \
                              (Cloud-Optimised or not) or an .hgt tile"
                        .into(),
                });
            }
            // The header and sidecar alone: the samples are decoded when they are read.
            let (dem, _) = Dem::png_sidecar_header(path)?;
            (dem, Kind::Png(options.clone()))
        } else if [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"]
            .iter()
            .any(|magic| head.starts_with(*magic))
        {
            let len = src.len();
            let (dem, tiff) = {
                let reader = Blocks {
                    src: src.as_ref(),
                    pos: 0,
                    block: None,
                };
                super::geotiff::open_windows(path, reader, len, options.cell_size_m, max_samples)?
            };
            (dem, Kind::Tiff { src, tiff })
        } else {
            let len = src.len();
            let Some(side) = super::hgt::side_for_size(len) else {
                return Err(
                    if path
                        .extension()
                        .is_some_and(|e| e.eq_ignore_ascii_case("hgt"))
                    {
                        WorldError::HgtSize {
                            path: path.to_path_buf(),
                            bytes: len,
                        }
                    } else {
                        let hex: Vec<String> = head.iter().map(|b| format!("{b:02x}")).collect();
                        WorldError::UnknownDemFormat {
                            path: path.to_path_buf(),
                            found: format!("{len} bytes starting with {}", hex.join(" ")),
                        }
                    },
                );
            };
            let dem = super::hgt::header(path, side, options.cell_size_m)?;
            (
                dem,
                Kind::Hgt {
                    src,
                    side: side as usize,
                },
            )
        };
        if let Some([ew, ns]) = options.cell_size_m {
            dem.cell_ew_m = ew;
            dem.cell_ns_m = ns;
        }
        Ok((
            dem,
            Rows {
                path: path.to_path_buf(),
                kind,
                len: file_len,
                read,
            },
        ))
    }

    /// Heights of rows `rows` (from the north, end exclusive), every column, nodata NaN.
    pub fn read(&self, rows: [usize; 2]) -> Result<Vec<f32>, WorldError> {
        self.read_window(rows, None).map(|(heights, _)| heights)
    }

    /// Heights of rows `rows` (from the north, end exclusive) over at least columns `cols`
    /// (from the west, end exclusive; `None`: every column), nodata NaN, with the columns
    /// they span: `cols` itself from a tiled GeoTIFF, whose tiles beside the window are not
    /// read; every column from any other file, whose rows are read whole anyway (an `.hgt`
    /// tile's rows lie whole one after the other, a strip spans every column, a PNG is read
    /// whole).
    pub fn read_window(
        &self,
        rows: [usize; 2],
        cols: Option<[usize; 2]>,
    ) -> Result<(Vec<f32>, [usize; 2]), WorldError> {
        match &self.kind {
            Kind::Png(options) => {
                let dem = Dem::load_unfilled(&self.path, options)?;
                self.read
                    .fetch_add(self.len, std::sync::atomic::Ordering::Relaxed);
                let w = dem.width as usize;
                let heights = dem
                    .heights
                    .get(rows[0] * w..rows[1] * w)
                    .map(<[f32]>::to_vec)
                    .ok_or_else(|| WorldError::DemMosaic {
                        path: self.path.clone(),
                        problem: format!(
                            "it has {} rows now, not the {} it had when the bake began",
                            dem.height, rows[1]
                        ),
                    })?;
                Ok((heights, [0, w]))
            }
            Kind::Hgt { src, side } => {
                // In reads of at most HGT_READ_BYTES (a row at least): over HTTP each is one
                // request, which must end within the client's deadline.
                let row_bytes = side * 2;
                let per_read = (HGT_READ_BYTES / row_bytes).max(1);
                let mut heights = Vec::with_capacity((rows[1] - rows[0]) * side);
                for first in (rows[0]..rows[1]).step_by(per_read) {
                    let n = per_read.min(rows[1] - first);
                    let bytes = src.read_at((first * row_bytes) as u64, (n * row_bytes) as u64)?;
                    heights.extend(super::hgt::heights(&bytes));
                }
                Ok((heights, [0, *side]))
            }
            Kind::Tiff { src, tiff } => {
                let w = tiff.width();
                let cols = match cols {
                    Some(c) if tiff.is_tiled() => [c[0].min(w), c[1].min(w)],
                    _ => [0, w],
                };
                let heights = tiff.window(&mut |o, n| src.read_at(o, n), cols, rows)?;
                Ok((heights, cols))
            }
        }
    }

    /// Bytes read from the file so far (its header among them; a PNG's whole file each time
    /// it is read).
    pub fn bytes_read(&self) -> u64 {
        self.read.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The file's size, bytes.
    pub fn file_len(&self) -> u64 {
        self.len
    }

    /// A GeoTIFF's samples in one strip or tile and in a row of one; `None` for other files
    /// (read a row at a time, or whole).
    pub fn chunk_samples(&self) -> Option<[usize; 2]> {
        match &self.kind {
            Kind::Tiff { tiff, .. } => Some(tiff.chunk_samples()),
            _ => None,
        }
    }

    /// Whether [`Rows::read_window`] reads only the columns asked for (a tiled GeoTIFF).
    pub fn reads_column_windows(&self) -> bool {
        matches!(&self.kind, Kind::Tiff { tiff, .. } if tiff.is_tiled())
    }

    /// Rows read at once beyond those asked for: a strip's or a tile's; `None` for a PNG,
    /// which is read whole.
    pub fn chunk_rows(&self) -> Option<usize> {
        match &self.kind {
            Kind::Png(_) => None,
            Kind::Hgt { .. } => Some(0),
            Kind::Tiff { tiff, .. } => Some(tiff.chunk_rows()),
        }
    }
}

#[cfg(test)]
mod tests {
    /// A file cut short after it was opened is said to have changed while it was read, not
    /// as a bare "failed to fill whole buffer".
    #[test]
    fn a_file_cut_short_while_it_is_read_is_said_to_have_changed() {
        use super::ReadAt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("N37W123.hgt");
        std::fs::write(&path, [7u8; 100]).unwrap();
        let file = super::LocalFile::open(&path).unwrap();
        assert_eq!(file.read_at(50, 10).unwrap(), [7u8; 10]);
        std::fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_len(10)
            .unwrap();
        let e = file.read_at(50, 10).unwrap_err().to_string();
        assert!(
            e.contains("N37W123.hgt") && e.contains("changed while it was read"),
            "{e}"
        );
    }

    #[test]
    fn an_address_is_remote_in_any_case_of_its_scheme() {
        use std::path::Path;
        for remote in ["http://h/d.tif", "HTTP://h/d.tif", "Https://h/d.tif"] {
            assert!(super::is_remote(Path::new(remote)), "{remote}");
        }
        for local in ["dem/http.tif", "http:/d.tif", "d.tif", ""] {
            assert!(!super::is_remote(Path::new(local)), "{local}");
        }
        for (path, name) in [
            ("http://h/a/N37W123.hgt?sig=SECRET%2Fb#x", "N37W123.hgt"),
            ("HTTP://h/d.tif#frag", "d.tif"),
            ("dem/d?.tif", "d?.tif"),
        ] {
            assert_eq!(super::file_name_of(Path::new(path)), name, "{path}");
        }
    }
}
