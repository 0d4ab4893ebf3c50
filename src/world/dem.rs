//! Digital elevation models, read by [`Dem::load`] in any of three formats, told apart by the
//! file's content (not its name):
//!
//! - **GeoTIFF** (`geotiff.rs`): one band of uint8, int16, uint16, int32, float32 or float64,
//!   strips or tiles, uncompressed, Deflate, LZW, PackBits or Zstandard, with or without a
//!   predictor; the cell size from the GeoTIFF tags, nodata from the `GDAL_NODATA` tag.
//! - **SRTM `.hgt`** (`hgt.rs`): 3601x3601 (1 arc-second) or 1201x1201 (3 arc-second)
//!   big-endian int16 samples, origin from the file name, voids (-32768) as nodata.
//! - **PNG + sidecar**: a 16-bit grayscale PNG (first row = north) and a JSON file of the same
//!   stem giving its size, cell spacing and height scale.
//!
//! A grid in degrees gets its cell size in metres at its centre latitude, east-west and
//! north-south apart ([`metres_per_degree`], on the WGS 84 ellipsoid). Nodata samples are filled
//! from the valid heights around them ([`super::nodata`]); a DEM that is more than half nodata is
//! refused.
//!
//! Samples are points ("posts"): sample `(c, r)` lies `c * cell_ew_m` east and
//! `(height - 1 - r) * cell_ns_m` north of the DEM's south-west sample, so a DEM spans
//! `(width - 1) * cell_ew_m` by `(height - 1) * cell_ns_m` metres.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::error::WorldError;
use super::format::{decode_png, open_regular, read_regular};
use super::nodata::fill_nodata;

// The grid type and the shared limits live in `dem_grid.rs`, below this module and the
// format readers alike; they stay reachable here, where callers have always found them.
pub use super::dem_grid::{Dem, DemFormat, MAX_DEM_SAMPLES, metres_per_degree};

/// Largest fraction of a DEM that may be nodata; more is refused rather than invented.
pub const MAX_NODATA_FRACTION: f64 = 0.5;
/// Largest PNG DEM read, bytes: twice the raw samples of the largest DEM (a compressor never
/// doubles them) and 64 KiB of headers.
pub const MAX_DEM_PNG_BYTES: u64 = 2 * 2 * MAX_DEM_SAMPLES + (64 << 10);
/// Largest DEM sidecar read, bytes.
pub const MAX_SIDECAR_BYTES: u64 = 1 << 20;

/// How to read a DEM.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DemOptions {
    /// Spacing of the samples in metres, east-west and north-south, in place of what the file
    /// says (needed for a TIFF without GeoTIFF tags).
    pub cell_size_m: Option<[f64; 2]>,
}

#[derive(Deserialize)]
struct Sidecar {
    width: u32,
    height: u32,
    cell_size_m: CellSize,
    #[serde(default)]
    height_offset_m: f64,
    #[serde(default = "one")]
    height_scale_m: f64,
    #[serde(default)]
    row_order: Option<String>,
    #[serde(default)]
    place: String,
    #[serde(default)]
    source: String,
}

#[derive(Deserialize)]
struct CellSize {
    east_west: f64,
    north_south: f64,
}

fn one() -> f64 {
    1.0
}

/// The sidecar of a DEM image: the same path with the extension `.json`.
pub fn sidecar_path(png_path: &Path) -> PathBuf {
    png_path.with_extension("json")
}

/// The sidecar of `dem` if it has one: a 16-bit PNG's heights and cells are given by its JSON
/// sidecar, where a GeoTIFF, an SRTM tile or a VRT carries its own.
pub fn sidecar_of(dem: &Path) -> Option<PathBuf> {
    dem.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
        .then(|| sidecar_path(dem))
}

impl Dem {
    /// Loads a DEM in any of the formats read (see the module docs), telling them apart by
    /// content, and fills its nodata samples. The DEM and its sidecar must be regular files (a
    /// FIFO or a device is refused by name rather than read).
    pub fn load(path: &Path) -> Result<Dem, WorldError> {
        Dem::load_with(path, &DemOptions::default())
    }

    /// [`Dem::load`] with options.
    pub fn load_with(path: &Path, options: &DemOptions) -> Result<Dem, WorldError> {
        let mut dem = Dem::load_unfilled(path, options)?;
        dem.fill_nodata(path)?;
        Ok(dem)
    }

    /// Fills the nodata samples (NaN) from the heights around them, counting them in
    /// `nodata_filled`; refuses a DEM with more than [`MAX_NODATA_FRACTION`] nodata, naming
    /// `path`.
    pub(crate) fn fill_nodata(&mut self, path: &Path) -> Result<(), WorldError> {
        let total = self.heights.len() as u64;
        let nodata = self.heights.iter().filter(|h| h.is_nan()).count() as u64;
        if nodata as f64 > MAX_NODATA_FRACTION * total as f64 {
            return Err(WorldError::TooMuchNodata {
                path: path.to_path_buf(),
                nodata,
                total,
                max_fraction: MAX_NODATA_FRACTION,
            });
        }
        self.nodata_filled =
            fill_nodata(self.width as usize, self.height as usize, &mut self.heights);
        Ok(())
    }

    /// Refuses a cell-size option that is not finite and positive, naming `path`.
    pub(crate) fn check_cell_option(path: &Path, options: &DemOptions) -> Result<(), WorldError> {
        if let Some(cell) = options.cell_size_m {
            for (axis, value) in cell.into_iter().enumerate() {
                let field = format!("DEM cell size option [{axis}]");
                if !value.is_finite() {
                    return Err(WorldError::NonFinite {
                        path: path.to_path_buf(),
                        field,
                        value,
                    });
                }
                if value <= 0.0 {
                    return Err(WorldError::NonPositive {
                        path: path.to_path_buf(),
                        field,
                        value,
                    });
                }
            }
        }
        Ok(())
    }

    /// Reads a DEM as its file has it: nodata samples stay NaN.
    pub(crate) fn load_unfilled(path: &Path, options: &DemOptions) -> Result<Dem, WorldError> {
        Dem::check_cell_option(path, options)?;
        let mut dem = match sniff(path)? {
            DemFormat::PngSidecar => Dem::load_png_sidecar(path)?,
            DemFormat::Geotiff => super::geotiff::load(path, options.cell_size_m)?,
            DemFormat::SrtmHgt => super::hgt::load(path, options.cell_size_m)?,
        };
        if let Some([ew, ns]) = options.cell_size_m {
            dem.cell_ew_m = ew;
            dem.cell_ns_m = ns;
        }
        Ok(dem)
    }

    /// A PNG DEM's size, spacing and texts from its sidecar, checked against the PNG's header
    /// (its heights left empty, nothing decoded: a caller can weigh the file before reading
    /// it), with the sidecar's height offset and scale.
    pub(crate) fn png_sidecar_header(png_path: &Path) -> Result<(Dem, [f64; 2]), WorldError> {
        let sidecar_file = sidecar_path(png_path);
        // The PNG first, so that a missing or unreadable DEM is named before its sidecar.
        let (file, _) = open_regular(png_path)?;
        let text = match read_regular(&sidecar_file, MAX_SIDECAR_BYTES) {
            Ok(bytes) => String::from_utf8(bytes).map_err(|e| WorldError::BadSidecar {
                path: sidecar_file.clone(),
                message: format!("not UTF-8 text: {e}"),
            })?,
            Err(WorldError::MissingFile { .. }) => {
                return Err(WorldError::MissingSidecar {
                    path: png_path.to_path_buf(),
                    sidecar: sidecar_file,
                });
            }
            Err(e) => return Err(e),
        };
        let sidecar: Sidecar = serde_json::from_str(&text).map_err(|e| WorldError::BadSidecar {
            path: sidecar_file.clone(),
            message: e.to_string(),
        })?;

        let check = |field: &str, value: f64| -> Result<(), WorldError> {
            if !value.is_finite() {
                Err(WorldError::NonFinite {
                    path: sidecar_file.clone(),
                    field: field.into(),
                    value,
                })
            } else if value <= 0.0 {
                Err(WorldError::NonPositive {
                    path: sidecar_file.clone(),
                    field: field.into(),
                    value,
                })
            } else {
                Ok(())
            }
        };
        check("cell_size_m.east_west", sidecar.cell_size_m.east_west)?;
        check("cell_size_m.north_south", sidecar.cell_size_m.north_south)?;
        check("height_scale_m", sidecar.height_scale_m)?;
        if !sidecar.height_offset_m.is_finite() {
            return Err(WorldError::NonFinite {
                path: sidecar_file,
                field: "height_offset_m".into(),
                value: sidecar.height_offset_m,
            });
        }
        if let Some(order) = &sidecar.row_order
            && !order.contains("north")
        {
            return Err(WorldError::BadSidecar {
                path: sidecar_file,
                message: format!(
                    "row_order \"{order}\": only \"first row is the northern edge\" is supported"
                ),
            });
        }
        for (field, value) in [("width", sidecar.width), ("height", sidecar.height)] {
            if value < 2 {
                return Err(WorldError::OutOfRange {
                    path: sidecar_file,
                    field: field.into(),
                    value: value.to_string(),
                    allowed: "at least 2 samples".into(),
                });
            }
        }

        // The header alone: its size, read without decoding a sample.
        let [width, height] = super::format::png_dimensions(file, png_path)?;
        for (field, side, img) in [
            ("width", sidecar.width, width),
            ("height", sidecar.height, height),
        ] {
            if side != img {
                return Err(WorldError::SidecarMismatch {
                    path: sidecar_file,
                    field,
                    sidecar: side,
                    image: img,
                });
            }
        }
        let dem = Dem {
            width,
            height,
            cell_ew_m: sidecar.cell_size_m.east_west,
            cell_ns_m: sidecar.cell_size_m.north_south,
            heights: Vec::new(),
            place: sidecar.place,
            source: sidecar.source,
            format: DemFormat::PngSidecar,
            crs: String::new(),
            origin: None,
            pixel_size: None,
            nodata_filled: 0,
        };
        Ok((dem, [sidecar.height_offset_m, sidecar.height_scale_m]))
    }

    /// Loads a 16-bit PNG DEM and its sidecar, checking that they agree.
    fn load_png_sidecar(png_path: &Path) -> Result<Dem, WorldError> {
        let (mut dem, [offset, scale]) = Dem::png_sidecar_header(png_path)?;
        let png_bytes = read_regular(png_path, MAX_DEM_PNG_BYTES)?;
        let png = decode_png(
            &png_bytes,
            png_path,
            image::ColorType::L16,
            "16-bit grayscale",
            Some([dem.width, dem.height]),
        )?;
        drop(png_bytes);
        dem.heights = png
            .bytes
            .chunks_exact(2)
            .map(|b| {
                let v = u16::from_ne_bytes([b[0], b[1]]);
                (offset + scale * f64::from(v)) as f32
            })
            .collect();
        Ok(dem)
    }
}

/// Tells a DEM's format from its first bytes, and for `.hgt` tiles (which have no signature)
/// from the name or the size.
fn sniff(path: &Path) -> Result<DemFormat, WorldError> {
    use std::io::Read;
    let (mut file, bytes) = open_regular(path)?;
    let mut head = Vec::with_capacity(8);
    file.by_ref()
        .take(8)
        .read_to_end(&mut head)
        .map_err(|e| WorldError::io(path, e))?;
    if head.starts_with(b"\x89PNG\r\n\x1a\n") {
        return Ok(DemFormat::PngSidecar);
    }
    if [b"II*\0", b"MM\0*", b"II+\0", b"MM\0+"]
        .iter()
        .any(|magic| head.starts_with(*magic))
    {
        return Ok(DemFormat::Geotiff);
    }
    let hgt_name = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("hgt"));
    if hgt_name || super::hgt::side_for_size(bytes).is_some() {
        return Ok(DemFormat::SrtmHgt);
    }
    let found = if head.is_empty() {
        "the file is empty".to_string()
    } else {
        let hex: Vec<String> = head.iter().map(|b| format!("{b:02x}")).collect();
        format!("{bytes} bytes starting with {}", hex.join(" "))
    };
    Err(WorldError::UnknownDemFormat {
        path: path.to_path_buf(),
        found,
    })
}
