//! Many DEM files as one: adjacent SRTM `.hgt` tiles or GeoTIFF tiles joined on their
//! georeferencing into one [`Dem`] (`verdant bake --dem A --dem B ...`, a folder of them, or a
//! GDAL VRT mosaic that lists them).
//!
//! - Every file must be georeferenced, in one coordinate system (the same EPSG code).
//! - The joined grid has the finest spacing among the files; a coarser file is sampled
//!   bilinearly onto it (its nodata stays nodata).
//! - **Overlaps**: the first file listed (a folder's in name order, a VRT's in its order) gives
//!   the heights where files overlap; the others must agree with it there within
//!   [`OVERLAP_TOLERANCE_M`] (adjacent SRTM tiles share their edge rows exactly), else the join
//!   is refused naming both files.
//! - **Grids**: files of the same spacing must lie on one grid, a whole number of samples
//!   apart; one offset by part of a cell is refused, with the offset and a `gdalwarp` that puts
//!   it on the other's grid (a coarser file is resampled anyway).
//! - **Gaps**: ground no file covers is nodata, filled like the files' own voids, as long as no
//!   gap runs more than [`MAX_GAP_SAMPLES`] samples along a row or column; a wider one (files
//!   that are not neighbours) is refused, naming where it is.
//! - A VRT's sources are its `SourceFilename`s (relative to the VRT where it says so), joined by
//!   their own georeferencing as `gdalbuildvrt` lays them out; the VRT's own grid and windows
//!   are not read.
//!
//! [`load_dems`] holds the joined heights whole, like a single file's; a bake reads them a
//! window at a time through [`Layout::region`] (see `bake::source`).

use std::path::{Path, PathBuf};

use super::dem::DemOptions;
use super::dem_grid::{Dem, MAX_DEM_SAMPLES, crs_key, metres_per_degree, or_unstated};
use super::error::WorldError;

/// Largest difference between two files' heights where they overlap, metres.
pub const OVERLAP_TOLERANCE_M: f32 = 1.0;
/// Widest gap between files filled as nodata, samples along a row or column.
pub const MAX_GAP_SAMPLES: usize = 16;
/// Most files joined (below `u16::MAX`, the join's record of which file gave a sample).
pub const MAX_MOSAIC_FILES: usize = 4096;
/// Largest VRT read, bytes.
const MAX_VRT_BYTES: u64 = 16 << 20;

fn mosaic_error(path: &Path, problem: impl ToString) -> WorldError {
    WorldError::DemMosaic {
        path: path.to_path_buf(),
        problem: problem.to_string(),
    }
}

/// The scheme of `path` where it is an address that verdant does not fetch (`ftp://`,
/// `s3://`; not `http://` or `https://`, which the HTTP client answers for) and no file of that
/// name exists.
fn other_scheme(path: &Path) -> Option<String> {
    let text = path.to_str()?;
    let (scheme, _) = text.split_once("://")?;
    let is_scheme = scheme.len() >= 2
        && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
        && scheme
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c));
    (is_scheme && !super::window::is_remote(path) && !path.exists())
        .then(|| scheme.to_ascii_lowercase())
}

/// The DEM files that `dems` name: each a file, a folder (its `.hgt`, `.tif`, `.tiff` files and
/// its `.png` files with a `.json` sidecar, in name order) or a GDAL `.vrt` (its sources).
pub fn dem_files(dems: &[PathBuf]) -> Result<Vec<PathBuf>, WorldError> {
    let mut files = Vec::new();
    for d in dems {
        if let Some(scheme) = other_scheme(d) {
            return Err(mosaic_error(
                d,
                format!(
                    "an address with the scheme {scheme}://, which verdant does not fetch: a \
                     DEM is a file, a folder, a .vrt or an http:// address"
                ),
            ));
        }
        if super::window::is_remote(d) && !has_extension(d, "vrt") {
            files.push(d.clone());
        } else if d.is_dir() {
            let entries = std::fs::read_dir(d).map_err(|e| WorldError::io(d, e))?;
            let mut found: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| is_dem_file(p))
                .collect();
            // A file named as a DEM that is not a regular file (a FIFO, a device, a symlink to
            // nothing) is refused by name rather than skipped unseen.
            if let Some(odd) = found.iter().find(|p| !p.is_file()) {
                crate::world::format::open_regular(odd)?;
            }
            found.sort();
            if found.is_empty() {
                return Err(mosaic_error(
                    d,
                    "it is a folder with no DEM file in it (.hgt, .tif, .tiff, or .png with a \
                     .json sidecar)",
                ));
            }
            files.extend(found);
        } else if has_extension(d, "vrt") {
            files.extend(vrt_sources(d)?);
        } else {
            files.push(d.clone());
        }
        if files.len() > MAX_MOSAIC_FILES {
            return Err(mosaic_error(
                d,
                format!("more than {MAX_MOSAIC_FILES} DEM files"),
            ));
        }
    }
    Ok(files)
}

fn has_extension(p: &Path, ext: &str) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

fn is_dem_file(p: &Path) -> bool {
    ["hgt", "tif", "tiff"].iter().any(|e| has_extension(p, e))
        || (has_extension(p, "png") && p.with_extension("json").is_file())
}

/// The source files of a GDAL VRT, in its order, each once.
fn vrt_sources(vrt: &Path) -> Result<Vec<PathBuf>, WorldError> {
    let bytes = if super::window::is_remote(vrt) {
        super::window::read_remote(vrt, MAX_VRT_BYTES)?
    } else {
        super::format::read_regular(vrt, MAX_VRT_BYTES)?
    };
    let text =
        String::from_utf8(bytes).map_err(|e| mosaic_error(vrt, format!("not UTF-8: {e}")))?;
    let doc = roxmltree::Document::parse(&text)
        .map_err(|e| mosaic_error(vrt, format!("not a VRT (XML): {e}")))?;
    let root = doc.root_element();
    if root.tag_name().name() != "VRTDataset" {
        return Err(mosaic_error(
            vrt,
            format!(
                "not a VRT: its root is <{}>, not <VRTDataset>",
                root.tag_name().name()
            ),
        ));
    }
    let base = vrt.parent().unwrap_or(Path::new("."));
    let mut out: Vec<PathBuf> = Vec::new();
    let mut named = std::collections::HashSet::new();
    for node in root
        .descendants()
        .filter(|n| n.has_tag_name("SourceFilename"))
    {
        let name = node.text().unwrap_or("").trim();
        if name.is_empty() {
            return Err(mosaic_error(vrt, "a <SourceFilename> is empty"));
        }
        // GDAL's name for a file read over HTTP.
        let name = name.strip_prefix("/vsicurl/").unwrap_or(name);
        if name.starts_with("/vsi") || (name.contains("://") && !name.starts_with("http://")) {
            return Err(mosaic_error(
                vrt,
                format!(
                    "source {name:?}: only files and plain http:// addresses are read (download \
                     it, or serve it over http://)"
                ),
            ));
        }
        let relative = node.attribute("relativeToVRT") == Some("1");
        if super::window::is_remote(vrt) && !relative && !name.starts_with("http://") {
            // A file served from elsewhere does not choose what is read on this machine.
            return Err(mosaic_error(
                vrt,
                format!(
                    "source {name:?}: a VRT read over http names its sources by http:// \
                     addresses or relative to itself (relativeToVRT=\"1\"), never by a path on \
                     this machine"
                ),
            ));
        }
        let p = if name.starts_with("http://") {
            PathBuf::from(name)
        } else if relative {
            base.join(name)
        } else {
            PathBuf::from(name)
        };
        if super::window::is_remote(vrt) && !super::window::is_remote(&p) {
            // An absolute name "relative" to the VRT is that path on this machine.
            return Err(mosaic_error(
                vrt,
                format!(
                    "source {name:?}: a VRT read over http names its sources by http:// \
                     addresses or relative to itself, never by a path on this machine"
                ),
            ));
        }
        if has_extension(&p, "vrt") {
            return Err(mosaic_error(
                vrt,
                format!(
                    "its source {} is itself a VRT: a VRT's sources are DEM files (.hgt, .tif, \
                     .tiff or .png with a .json sidecar)",
                    p.display()
                ),
            ));
        }
        if named.insert(p.clone()) {
            out.push(p);
        }
        // Told here, not after the whole list is made: a VRT of 16 MiB names 400,000.
        if out.len() > MAX_MOSAIC_FILES {
            return Err(mosaic_error(
                vrt,
                format!("it names more than {MAX_MOSAIC_FILES} DEM files"),
            ));
        }
    }
    if out.is_empty() {
        return Err(mosaic_error(vrt, "the VRT names no source file"));
    }
    Ok(out)
}

/// One file's grid in the shared coordinate system; its heights are read when needed.
struct Part {
    path: PathBuf,
    rows: super::window::Rows,
    width: usize,
    height: usize,
    /// South-west sample and spacing, in the coordinate system.
    origin: [f64; 2],
    size: [f64; 2],
}

impl Part {
    /// The file's height at coordinates `(x, y)` from `heights`, its rows from row `first` (from
    /// the north) on, of its columns `cols`: bilinear between its samples (exact on them), NaN
    /// where a sample used is nodata; `None` outside it.
    fn at(&self, heights: &[f32], first: usize, cols: [usize; 2], x: f64, y: f64) -> Option<f32> {
        let (w, h) = (self.width, self.height);
        let c = (x - self.origin[0]) / self.size[0];
        let r = (y - self.origin[1]) / self.size[1]; // from the south
        const EPS: f64 = 1e-6;
        if c < -EPS || r < -EPS || c > (w - 1) as f64 + EPS || r > (h - 1) as f64 + EPS {
            return None;
        }
        let c = c.clamp(0.0, (w - 1) as f64);
        let r = r.clamp(0.0, (h - 1) as f64);
        let snap = |v: f64| {
            if (v - v.round()).abs() < EPS {
                v.round()
            } else {
                v
            }
        };
        let (c, r) = (snap(c), snap(r));
        let (c0, r0) = (c.floor() as usize, r.floor() as usize);
        let (c1, r1) = ((c0 + 1).min(w - 1), (r0 + 1).min(h - 1));
        let (fc, fr) = ((c - c0 as f64) as f32, (r - r0 as f64) as f32);
        // Rows are stored north first.
        let v =
            |c: usize, r: usize| heights[(h - 1 - r - first) * (cols[1] - cols[0]) + c - cols[0]];
        if fc == 0.0 && fr == 0.0 {
            return Some(v(c0, r0));
        }
        let south = v(c0, r0) * (1.0 - fc) + v(c1, r0) * fc;
        let north = v(c0, r1) * (1.0 - fc) + v(c1, r1) * fc;
        Some(south * (1.0 - fr) + north * fr)
    }
}

/// Loads the DEMs `dems` name ([`dem_files`]) as one [`Dem`]: a single file as
/// [`Dem::load_with`] reads it, several joined (see the module docs). Nodata is filled after the
/// join, so voids and gaps at the seams are filled from both sides.
pub fn load_dems(dems: &[PathBuf], options: &DemOptions) -> Result<Dem, WorldError> {
    let named = dems.first().cloned().unwrap_or_default();
    load_files(&dem_files(dems)?, &named, options)
}

/// Loads DEM files that [`dem_files`] listed as one [`Dem`] (see [`load_dems`]); `named` is
/// what the user gave, for the errors that concern them all.
pub fn load_files(
    files: &[PathBuf],
    named: &Path,
    options: &DemOptions,
) -> Result<Dem, WorldError> {
    match files {
        [] => Err(mosaic_error(named, "no DEM file given")),
        [one] => Dem::load_with(one, options),
        _ => {
            let layout = Layout::open(files, options, MAX_DEM_SAMPLES)?;
            let all = [0, layout.header.width as usize];
            let rows = [0, layout.header.height as usize];
            let heights = layout.region(all, rows)?;
            let mut dem = layout.header.clone();
            dem.heights = heights;
            dem.fill_nodata(named)?;
            Ok(dem)
        }
    }
}

/// Where several DEM files lie on their joined grid, from their headers; the heights of any
/// window of the grid are read from the files by [`Layout::region`].
pub struct Layout {
    parts: Vec<Part>,
    /// The joined grid: its size, spacing and georeferencing; its heights are left empty.
    pub header: Dem,
    /// The joined grid's south-west sample and spacing, in the coordinate system.
    lo: [f64; 2],
    size: [f64; 2],
}

impl Layout {
    /// Reads the files one at a time for their georeferencing (their heights are dropped) and
    /// lays them out on the joined grid; refuses files in different coordinate systems, files
    /// without georeferencing, and a joined grid of more than `max_samples`.
    pub fn open(
        files: &[PathBuf],
        options: &DemOptions,
        max_samples: u64,
    ) -> Result<Layout, WorldError> {
        let mut parts: Vec<Part> = Vec::with_capacity(files.len());
        let mut first: Option<Dem> = None;
        for f in files {
            let (dem, rows) = super::window::Rows::open(f, options, max_samples)?;
            let (Some(origin), Some(size)) = (dem.origin, dem.pixel_size) else {
                return Err(mosaic_error(
                    f,
                    "it has no georeferencing, so it cannot be joined to the other DEM files",
                ));
            };
            if let Some(first) = &first
                && crs_key(&first.crs) != crs_key(&dem.crs)
            {
                return Err(mosaic_error(
                    f,
                    format!(
                        "its coordinate system ({}) is not that of {} ({}): reproject them to \
                         one first (gdalwarp -t_srs ...)",
                        or_unstated(&dem.crs),
                        parts[0].path.display(),
                        or_unstated(&first.crs)
                    ),
                ));
            }
            check_grid_alignment(&parts, f, &dem, origin, size)?;
            parts.push(Part {
                path: f.clone(),
                rows,
                width: dem.width as usize,
                height: dem.height as usize,
                origin,
                size,
            });
            first.get_or_insert(dem);
        }
        let Some(p0) = first else {
            return Err(mosaic_error(Path::new(""), "no DEM file given"));
        };
        // The joined grid: the finest spacing, over every file's extent.
        let fold = |f: &dyn Fn(&Part, usize) -> f64, init: f64, pick: fn(f64, f64) -> f64| {
            [0, 1].map(|a| parts.iter().map(|p| f(p, a)).fold(init, pick))
        };
        let size = fold(&|p, a| p.size[a], f64::INFINITY, f64::min);
        let lo = fold(&|p, a| p.origin[a], f64::INFINITY, f64::min);
        let hi = fold(
            &|p, a| {
                let n = if a == 0 { p.width } else { p.height };
                p.origin[a] + (n - 1) as f64 * p.size[a]
            },
            f64::NEG_INFINITY,
            f64::max,
        );
        // Counted in floating point: files far apart make a count no integer holds.
        let n = [0, 1].map(|a| ((hi[a] - lo[a]) / size[a]).round() + 1.0);
        let fits = n[0] * n[1] <= max_samples as f64 && n.iter().all(|&v| v <= f64::from(u32::MAX));
        if !fits {
            let count = |v: f64| {
                if v < 1e15 {
                    format!("{v:.0}")
                } else {
                    format!("{v:.3e}")
                }
            };
            return Err(mosaic_error(
                &parts[0].path,
                format!(
                    "the {} files joined make {} x {} samples, more than the {max_samples} a \
                     DEM may have",
                    parts.len(),
                    count(n[0]),
                    count(n[1])
                ),
            ));
        }
        // Metres per sample: from the first file, at the joined grid's centre latitude where
        // the coordinates are degrees.
        let mut cell = [
            p0.cell_ew_m / parts[0].size[0] * size[0],
            p0.cell_ns_m / parts[0].size[1] * size[1],
        ];
        if p0.crs.contains("geographic") {
            let [m_ew, m_ns] = metres_per_degree(0.5 * (lo[1] + hi[1]));
            cell = [m_ew * size[0], m_ns * size[1]];
        }
        let names: Vec<String> = parts
            .iter()
            .map(|p| super::window::file_name_of(&p.path))
            .collect();
        let header = Dem {
            width: n[0] as u32,
            height: n[1] as u32,
            cell_ew_m: cell[0],
            cell_ns_m: cell[1],
            heights: Vec::new(),
            place: p0.place.clone(),
            source: format!(
                "{} files joined ({}){}",
                parts.len(),
                names.join(", "),
                if p0.source.is_empty() {
                    String::new()
                } else {
                    format!(": {}", p0.source)
                }
            ),
            format: p0.format,
            crs: p0.crs.clone(),
            origin: Some(lo),
            pixel_size: Some(size),
            nodata_filled: 0,
        };
        Ok(Layout {
            parts,
            header,
            lo,
            size,
        })
    }

    /// The most samples a row that one file's read of a window `side` samples wide holds: a
    /// tiled GeoTIFF's window (the joined grid has the finest spacing of the files, so a window
    /// spans at most one file sample a grid sample, with one more each side for the bilinear
    /// and one for rounding; at least a tile's width), any other file's whole rows.
    pub fn widest_read(&self, side: usize) -> usize {
        self.parts
            .iter()
            .map(|p| match p.rows.chunk_samples() {
                Some([_, tile_w]) if p.rows.reads_column_windows() => {
                    p.width.min((side + 4).max(tile_w))
                }
                _ => p.width,
            })
            .max()
            .unwrap_or(0)
    }

    /// The most bytes a file's strip or tile takes while it is read: its bytes as stored (at
    /// most as many as decoded) and decoded, eight bytes a sample each.
    pub fn largest_chunk_bytes(&self) -> u64 {
        self.parts
            .iter()
            .filter_map(|p| p.rows.chunk_samples())
            .map(|[samples, _]| samples as u64 * 16)
            .max()
            .unwrap_or(0)
    }

    /// Bytes read from the files so far (their headers among them), and the files' sizes.
    pub fn bytes_read(&self) -> [u64; 2] {
        self.parts.iter().fold([0, 0], |[read, size], p| {
            [read + p.rows.bytes_read(), size + p.rows.file_len()]
        })
    }

    /// The most rows a file reads beyond those asked for (a strip's or a tile's rows).
    pub fn largest_chunk_rows(&self) -> usize {
        self.parts
            .iter()
            .map(|p| p.rows.chunk_rows().unwrap_or(p.height))
            .max()
            .unwrap_or(0)
    }

    /// The files whose samples fall in columns `cols` and rows `rows` (from the north, ends
    /// exclusive) of the joined grid.
    pub fn files_in(&self, cols: [usize; 2], rows: [usize; 2]) -> Vec<usize> {
        (0..self.parts.len())
            .filter(|&k| {
                let (c, r) = self.window_of(k);
                let h = self.header.height as usize;
                // The part's rows from the north.
                let rn = [h - 1 - r[1], h - 1 - r[0]];
                c[0] < cols[1] && c[1] >= cols[0] && rn[0] < rows[1] && rn[1] >= rows[0]
            })
            .collect()
    }

    /// File `k`'s columns and rows (from the SOUTH) on the joined grid, inclusive.
    fn window_of(&self, k: usize) -> ([usize; 2], [usize; 2]) {
        let part = &self.parts[k];
        let (w, h) = (self.header.width as usize, self.header.height as usize);
        let (lo, size) = (self.lo, self.size);
        let pw = (part.width - 1) as f64 * part.size[0];
        let ph = (part.height - 1) as f64 * part.size[1];
        let c0 = ((part.origin[0] - lo[0]) / size[0] - 1e-6).ceil().max(0.0) as usize;
        let c1 = (((part.origin[0] + pw - lo[0]) / size[0] + 1e-6).floor() as usize).min(w - 1);
        let r0 = ((part.origin[1] - lo[1]) / size[1] - 1e-6).ceil().max(0.0) as usize;
        let r1 = (((part.origin[1] + ph - lo[1]) / size[1] + 1e-6).floor() as usize).min(h - 1);
        ([c0, c1], [r0, r1])
    }

    /// The file that gives the joined grid's sample at `column` (from the west) and `row` (from
    /// the north), the first listed where files overlap, with the sample's column and row in
    /// that file (nearest); `None` where no file covers it.
    pub fn file_at(&self, column: u32, row: u32) -> Option<(&std::path::Path, u32, u32)> {
        let h = self.header.height as f64;
        let x = self.lo[0] + f64::from(column) * self.size[0];
        let y = self.lo[1] + (h - 1.0 - f64::from(row)) * self.size[1];
        self.parts.iter().find_map(|p| {
            let c = (x - p.origin[0]) / p.size[0];
            let r = (y - p.origin[1]) / p.size[1];
            let inside = |v: f64, n: usize| v > -0.5 && v < n as f64 - 0.5;
            (inside(c, p.width) && inside(r, p.height)).then(|| {
                let from_north = p.height as f64 - 1.0 - r.round();
                (p.path.as_path(), c.round() as u32, from_north as u32)
            })
        })
    }

    /// The joined heights of columns `cols` and rows `rows` (from the north, ends exclusive),
    /// row-major, north first: the first file listed where files overlap, NaN where no file
    /// covers a sample or a file has a void there. `data(k)` gives file `k`'s heights. Refuses
    /// overlaps that disagree and gaps of more than [`MAX_GAP_SAMPLES`] inside the window.
    pub fn region(&self, cols: [usize; 2], rows: [usize; 2]) -> Result<Vec<f32>, WorldError> {
        let (lo, size) = (self.lo, self.size);
        let h = self.header.height as usize;
        let (rw, rh) = (cols[1] - cols[0], rows[1] - rows[0]);
        let mut heights = vec![f32::NAN; rw * rh];
        // The file that gave each sample (u16: at most MAX_MOSAIC_FILES files).
        let mut owner = vec![u16::MAX; rw * rh];
        // Overlaps: per pair (first file, later file), samples that disagree and the worst.
        let mut disagree: Option<(usize, usize, u64, f32)> = None;
        for k in self.files_in(cols, rows) {
            let part = &self.parts[k];
            let ([c0, c1], [r0, r1]) = self.window_of(k);
            // The window's rows from the south: h - rows[1] ..= h - 1 - rows[0].
            let (s0, s1) = ((h - rows[1]).max(r0), (h - 1 - rows[0]).min(r1));
            let (c0, c1) = (c0.max(cols[0]), c1.min(cols[1] - 1));
            if s0 > s1 || c0 > c1 {
                continue;
            }
            // The file's rows those need (from its south, with the next for the bilinear), read.
            let ph = part.height;
            let row_of = |r: usize| (lo[1] + r as f64 * size[1] - part.origin[1]) / part.size[1];
            let south = [
                (row_of(s0).floor().max(0.0) as usize).min(ph - 1),
                (row_of(s1).ceil().max(0.0) as usize + 1).min(ph - 1),
            ];
            let first = ph - 1 - south[1];
            // And its columns (with the next for the bilinear): a tiled GeoTIFF reads only
            // those, any other file its rows whole.
            let pw = part.width;
            let col_of = |c: usize| (lo[0] + c as f64 * size[0] - part.origin[0]) / part.size[0];
            let west = (col_of(c0).floor().max(0.0) as usize).min(pw - 1);
            let east = (col_of(c1).ceil().max(0.0) as usize + 1).min(pw - 1);
            let (values, got) = part
                .rows
                .read_window([first, ph - south[0]], Some([west, east + 1]))?;
            let vw = got[1] - got[0];
            // A file on the joined grid's own spacing, a whole number of samples from its
            // corner (adjacent SRTM tiles): its samples are copied, as `at` would give them.
            let offset = |a: usize| (part.origin[a] - lo[a]) / size[a];
            let aligned =
                part.size == size && (0..2).all(|a| (offset(a) - offset(a).round()).abs() < 1e-9);
            let (dc, dr) = (offset(0).round() as i64, offset(1).round() as i64);
            for r in s0..=s1 {
                let y = lo[1] + r as f64 * size[1];
                for c in c0..=c1 {
                    let v = if aligned {
                        let (pc, pr) = (c as i64 - dc, r as i64 - dr);
                        if pc < 0 || pr < 0 || pc >= part.width as i64 || pr >= ph as i64 {
                            continue;
                        }
                        values[(ph - 1 - pr as usize - first) * vw + pc as usize - got[0]]
                    } else {
                        let x = lo[0] + c as f64 * size[0];
                        let Some(v) = part.at(&values, first, got, x, y) else {
                            continue;
                        };
                        v
                    };
                    let i = (h - 1 - r - rows[0]) * rw + (c - cols[0]);
                    if owner[i] == u16::MAX {
                        owner[i] = k as u16;
                        heights[i] = v;
                    } else if heights[i].is_finite() && v.is_finite() {
                        let d = (heights[i] - v).abs();
                        if d > OVERLAP_TOLERANCE_M {
                            let o = owner[i] as usize;
                            let e = disagree.get_or_insert((o, k, 0, 0.0));
                            if (e.0, e.1) == (o, k) {
                                e.2 += 1;
                                e.3 = e.3.max(d);
                            }
                        }
                    } else if heights[i].is_nan() {
                        // The first file's void: the later file fills it.
                        heights[i] = v;
                    }
                }
            }
        }
        if let Some((a, b, count, worst)) = disagree {
            return Err(mosaic_error(
                &self.parts[b].path,
                format!(
                    "where it overlaps {} their heights differ by more than \
                     {OVERLAP_TOLERANCE_M} m at {count} samples (by up to {worst:.1} m): the \
                     files are not the same data (the first file listed is kept where files \
                     overlap, and the others must agree with it)",
                    self.parts[a].path.display()
                ),
            ));
        }
        // Gaps: runs of samples no file covers, along rows and columns.
        let longest_run = |at: &dyn Fn(usize) -> bool, len: usize| -> (usize, usize) {
            let (mut best, mut best_end, mut run) = (0, 0, 0);
            for k in 0..len {
                if at(k) {
                    run += 1;
                    if run > best {
                        best = run;
                        best_end = k;
                    }
                } else {
                    run = 0;
                }
            }
            (best, best_end)
        };
        let gap = |run, c: usize, r: usize| {
            gap_error(
                &self.parts,
                run,
                lo,
                size,
                [cols[0] + c, h - 1 - (rows[0] + r)],
            )
        };
        for r in 0..rh {
            let (run, end) = longest_run(&|c| owner[r * rw + c] == u16::MAX, rw);
            if run > MAX_GAP_SAMPLES {
                return Err(gap(run, end, r));
            }
        }
        for c in 0..rw {
            let (run, end) = longest_run(&|r| owner[r * rw + c] == u16::MAX, rh);
            if run > MAX_GAP_SAMPLES {
                return Err(gap(run, c, end));
            }
        }
        Ok(heights)
    }
}

/// Largest offset between the grids of two files of the same spacing that is taken as float
/// rounding, in cells.
const MAX_GRID_OFFSET_CELLS: f64 = 1e-3;

/// Refuses file `path` (`dem`, its south-west sample at `origin`, its spacing `size`) where its
/// grid has the spacing of an earlier file's in `parts` but is offset from it by part of a
/// cell: their samples cannot be joined one for one (where they meet, a column or row of the
/// joined grid would fall between them, or each be half the other's), naming both, the offset
/// in cells and in metres, and how to put one on the other's grid.
fn check_grid_alignment(
    parts: &[Part],
    path: &Path,
    dem: &Dem,
    origin: [f64; 2],
    size: [f64; 2],
) -> Result<(), WorldError> {
    let same = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
    let Some(other) = parts
        .iter()
        .find(|p| same(p.size[0], size[0]) && same(p.size[1], size[1]))
    else {
        return Ok(());
    };
    let fraction = [0, 1].map(|a| {
        let cells = (origin[a] - other.origin[a]) / size[a];
        cells - cells.round()
    });
    if fraction.iter().all(|f| f.abs() <= MAX_GRID_OFFSET_CELLS) {
        return Ok(());
    }
    use super::error::short_number;
    let degrees = dem.crs.contains("degrees");
    let metres = [dem.cell_ew_m, dem.cell_ns_m];
    let offsets: Vec<String> = [(0, "east-west"), (1, "north-south")]
        .into_iter()
        .filter(|&(a, _)| fraction[a].abs() > MAX_GRID_OFFSET_CELLS)
        .map(|(a, axis)| {
            let units = if degrees {
                format!("{}°, ", trimmed(fraction[a].abs() * size[a]))
            } else {
                String::new()
            };
            format!(
                "{} of a cell {axis} ({units}{} m)",
                short_number(fraction[a].abs()),
                short_number(fraction[a].abs() * metres[a])
            )
        })
        .collect();
    // The file's bounds (its cells' outer edges) shrunk to the other file's cell edges: what
    // gdalwarp -te needs to resample it onto that grid.
    let n = [dem.width, dem.height].map(|n| f64::from(n - 1));
    let edge = [0, 1].map(|a| other.origin[a] - 0.5 * size[a]);
    let snap = |a: usize, v: f64, up: bool| {
        let k = (v - edge[a]) / size[a];
        let k = if up { k.ceil() } else { k.floor() };
        trimmed(edge[a] + k * size[a])
    };
    let te = [
        snap(0, origin[0] - 0.5 * size[0], true),
        snap(1, origin[1] - 0.5 * size[1], true),
        snap(0, origin[0] + (n[0] + 0.5) * size[0], false),
        snap(1, origin[1] + (n[1] + 0.5) * size[1], false),
    ];
    let name = super::window::file_name_of(path);
    Err(mosaic_error(
        path,
        format!(
            "its grid is offset from that of {} by {}: the files have the same spacing ({} x {} \
             in their coordinate system) but their samples do not line up, so they cannot be \
             joined sample for sample. Resample one onto the other's grid first, e.g. gdalwarp \
             -tr {} {} -te {} -r bilinear {name} aligned_{name}{}",
            other.path.display(),
            offsets.join(" and "),
            trimmed(size[0]),
            trimmed(size[1]),
            trimmed(size[0]),
            trimmed(size[1]),
            te.join(" "),
            if (0..2).all(|a| (edge[a] / size[a] - (edge[a] / size[a]).round()).abs() < 1e-6) {
                " (or -tap in place of -te: that grid's cell edges are whole multiples of the \
                 spacing)"
            } else {
                ""
            },
        ),
    ))
}

/// `v` to nine decimals, without trailing zeros: coordinates in metres or degrees, short.
fn trimmed(v: f64) -> String {
    let s = format!("{v:.9}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

fn gap_error(
    parts: &[Part],
    run: usize,
    lo: [f64; 2],
    size: [f64; 2],
    at: [usize; 2],
) -> WorldError {
    let x = lo[0] + at[0] as f64 * size[0];
    let y = lo[1] + at[1] as f64 * size[1];
    let names: Vec<String> = parts.iter().map(|p| p.path.display().to_string()).collect();
    mosaic_error(
        &parts[0].path,
        format!(
            "no file covers a gap {run} samples long (more than the {MAX_GAP_SAMPLES} filled as \
             nodata) ending at ({x:.6}, {y:.6}) in their coordinate system: the files ({}) are \
             not neighbours",
            names.join(", ")
        ),
    )
}
