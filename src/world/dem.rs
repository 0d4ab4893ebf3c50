//! Digital elevation models, read by [`Dem::load`] in any of three formats, told apart by the
//! file's content (not its name):
//!
//! - **GeoTIFF** (`geotiff.rs`): one band of int16, uint16, int32, float32 or float64,
//!   strips or tiles, uncompressed, Deflate, LZW or PackBits, with or without a predictor; the
//!   cell size from the GeoTIFF tags, nodata from the `GDAL_NODATA` tag.
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

use serde::{Deserialize, Serialize};

use super::error::WorldError;
use super::format::{decode_png, open_regular, read_regular};
use super::nodata::fill_nodata;

/// Most samples a DEM may have (16384 x 16384): its heights alone take 1 GiB.
pub const MAX_DEM_SAMPLES: u64 = 1 << 28;
/// Largest fraction of a DEM that may be nodata; more is refused rather than invented.
pub const MAX_NODATA_FRACTION: f64 = 0.5;
/// Largest PNG DEM read, bytes: twice the raw samples of the largest DEM (a compressor never
/// doubles them) and 64 KiB of headers.
pub const MAX_DEM_PNG_BYTES: u64 = 2 * 2 * MAX_DEM_SAMPLES + (64 << 10);
/// Largest DEM sidecar read, bytes.
pub const MAX_SIDECAR_BYTES: u64 = 1 << 20;

/// The file formats a DEM is read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
#[non_exhaustive]
pub enum DemFormat {
    /// A 16-bit grayscale PNG with a JSON sidecar.
    PngSidecar,
    /// A GeoTIFF.
    Geotiff,
    /// An SRTM `.hgt` tile.
    SrtmHgt,
}

impl DemFormat {
    /// The format's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            DemFormat::PngSidecar => "PNG + JSON sidecar",
            DemFormat::Geotiff => "GeoTIFF",
            DemFormat::SrtmHgt => "SRTM .hgt",
        }
    }
}

/// How to read a DEM.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DemOptions {
    /// Spacing of the samples in metres, east-west and north-south, in place of what the file
    /// says (needed for a TIFF without GeoTIFF tags).
    pub cell_size_m: Option<[f64; 2]>,
}

/// A loaded DEM: heights in metres, row 0 at the north edge.
#[derive(Clone, Debug, PartialEq)]
pub struct Dem {
    /// Samples per row (west to east).
    pub width: u32,
    /// Rows (north to south).
    pub height: u32,
    /// Spacing of samples east-west, metres.
    pub cell_ew_m: f64,
    /// Spacing of samples north-south, metres.
    pub cell_ns_m: f64,
    /// Heights in metres, `width * height`, row 0 = north.
    pub heights: Vec<f32>,
    /// Where the data shows, from the sidecar's `place` (may be empty).
    pub place: String,
    /// Where the data comes from, from the sidecar's `source` (may be empty).
    pub source: String,
    /// The file format it was read from.
    pub format: DemFormat,
    /// Its coordinate system, in words (e.g. `EPSG:4326, geographic (degrees)`); empty where
    /// the file does not say.
    pub crs: String,
    /// The south-west sample's coordinates in that coordinate system (x/longitude first), where
    /// the file gives them.
    pub origin: Option<[f64; 2]>,
    /// Nodata samples that were filled from the heights around them.
    pub nodata_filled: u64,
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

impl Dem {
    /// Loads a DEM in any of the formats read (see the module docs), telling them apart by
    /// content, and fills its nodata samples. The DEM and its sidecar must be regular files (a
    /// FIFO or a device is refused by name rather than read).
    pub fn load(path: &Path) -> Result<Dem, WorldError> {
        Dem::load_with(path, &DemOptions::default())
    }

    /// [`Dem::load`] with options.
    pub fn load_with(path: &Path, options: &DemOptions) -> Result<Dem, WorldError> {
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
        let mut dem = match sniff(path)? {
            DemFormat::PngSidecar => Dem::load_png_sidecar(path)?,
            DemFormat::Geotiff => super::geotiff::load(path, options.cell_size_m)?,
            DemFormat::SrtmHgt => super::hgt::load(path, options.cell_size_m)?,
        };
        if let Some([ew, ns]) = options.cell_size_m {
            dem.cell_ew_m = ew;
            dem.cell_ns_m = ns;
        }
        let total = dem.heights.len() as u64;
        let nodata = dem.heights.iter().filter(|h| h.is_nan()).count() as u64;
        if nodata as f64 > MAX_NODATA_FRACTION * total as f64 {
            return Err(WorldError::TooMuchNodata {
                path: path.to_path_buf(),
                nodata,
                total,
                max_fraction: MAX_NODATA_FRACTION,
            });
        }
        dem.nodata_filled = fill_nodata(dem.width as usize, dem.height as usize, &mut dem.heights);
        Ok(dem)
    }

    /// Loads a 16-bit PNG DEM and its sidecar, checking that they agree.
    fn load_png_sidecar(png_path: &Path) -> Result<Dem, WorldError> {
        let sidecar_file = sidecar_path(png_path);
        let png_bytes = read_regular(png_path, MAX_DEM_PNG_BYTES)?;
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

        let png = decode_png(
            &png_bytes,
            png_path,
            image::ColorType::L16,
            "16-bit grayscale",
            None,
        )?;
        for (field, side, img) in [
            ("width", sidecar.width, png.width),
            ("height", sidecar.height, png.height),
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
        let heights = png
            .bytes
            .chunks_exact(2)
            .map(|b| {
                let v = u16::from_ne_bytes([b[0], b[1]]);
                (sidecar.height_offset_m + sidecar.height_scale_m * f64::from(v)) as f32
            })
            .collect();
        Ok(Dem {
            width: png.width,
            height: png.height,
            cell_ew_m: sidecar.cell_size_m.east_west,
            cell_ns_m: sidecar.cell_size_m.north_south,
            heights,
            place: sidecar.place,
            source: sidecar.source,
            format: DemFormat::PngSidecar,
            crs: String::new(),
            origin: None,
            nodata_filled: 0,
        })
    }

    /// Size of the area the samples span, metres (east-west, north-south).
    pub fn extent_m(&self) -> [f64; 2] {
        [
            f64::from(self.width - 1) * self.cell_ew_m,
            f64::from(self.height - 1) * self.cell_ns_m,
        ]
    }

    /// Height at sample column `c` (from the west) and row `r` from the SOUTH, clamped to the
    /// DEM's edges.
    fn post(&self, c: i64, r: i64) -> f64 {
        let c = c.clamp(0, i64::from(self.width) - 1) as usize;
        let r = r.clamp(0, i64::from(self.height) - 1) as usize;
        let row_from_north = self.height as usize - 1 - r;
        f64::from(self.heights[row_from_north * self.width as usize + c])
    }

    /// Height at world position `(x, y)` (metres from the south-west sample) by bicubic
    /// (Catmull-Rom) interpolation in the DEM's grid. Positions beyond the DEM take the height
    /// at the nearest point of its edge.
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        let [ex, ey] = self.extent_m();
        let u = x.clamp(0.0, ex) / self.cell_ew_m;
        let v = y.clamp(0.0, ey) / self.cell_ns_m;
        let (c0, r0) = (u.floor(), v.floor());
        let (fu, fv) = (u - c0, v - r0);
        let (c0, r0) = (c0 as i64, r0 as i64);
        let wu = catmull_rom_weights(fu);
        let wv = catmull_rom_weights(fv);
        let mut h = 0.0;
        for (dr, wr) in wv.iter().enumerate() {
            let mut row = 0.0;
            for (dc, wc) in wu.iter().enumerate() {
                row += wc * self.post(c0 + dc as i64 - 1, r0 + dr as i64 - 1);
            }
            h += wr * row;
        }
        h
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

/// Refuses a grid too small to bake or too large to hold, before anything is allocated.
pub(crate) fn check_grid_size(path: &Path, width: u64, height: u64) -> Result<(), WorldError> {
    if width < 2 || height < 2 || width.saturating_mul(height) > MAX_DEM_SAMPLES {
        return Err(WorldError::OutOfRange {
            path: path.to_path_buf(),
            field: "grid size".into(),
            value: format!("{width}x{height} samples"),
            allowed: format!("at least 2x2 and at most {MAX_DEM_SAMPLES} samples (16384x16384)"),
        });
    }
    Ok(())
}

/// Metres per degree of longitude (east-west) and of latitude (north-south) at latitude
/// `lat_deg`, on the WGS 84 ellipsoid (the datum differences between common geographic
/// coordinate systems change these by far less than a millimetre per degree).
pub fn metres_per_degree(lat_deg: f64) -> [f64; 2] {
    const A: f64 = 6_378_137.0;
    const F: f64 = 1.0 / 298.257_223_563;
    let e2 = F * (2.0 - F);
    let phi = lat_deg.to_radians();
    let s = 1.0 - e2 * phi.sin().powi(2);
    // Radii of curvature in the prime vertical and in the meridian.
    let n = A / s.sqrt();
    let m = A * (1.0 - e2) / (s * s.sqrt());
    let rad = std::f64::consts::PI / 180.0;
    [n * phi.cos() * rad, m * rad]
}

/// Catmull-Rom weights of the four posts around a fraction `t` in 0..1.
fn catmull_rom_weights(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metres_per_degree_matches_the_published_wgs84_figures() {
        // Length of a degree on the WGS 84 ellipsoid, as tabulated in geodesy references
        // (latitude, longitude degree lengths in metres).
        for (lat, lon_m, lat_m) in [
            (0.0, 111_320.0, 110_574.0),
            (45.0, 78_847.0, 111_132.0),
            (60.0, 55_800.0, 111_412.0),
        ] {
            let [ew, ns] = metres_per_degree(lat);
            assert!((ew - lon_m).abs() < 2.0, "{lat}: {ew}");
            assert!((ns - lat_m).abs() < 2.0, "{lat}: {ns}");
        }
        assert_eq!(metres_per_degree(-37.5), metres_per_degree(37.5));
    }

    #[test]
    fn grid_sizes_beyond_the_limit_are_refused() {
        let p = Path::new("big.tif");
        assert!(check_grid_size(p, 16384, 16384).is_ok());
        assert!(check_grid_size(p, 2, 2).is_ok());
        for (w, h) in [(16385, 16384), (1, 100), (100, 1), (1 << 40, 1 << 40)] {
            let e = check_grid_size(p, w, h).unwrap_err();
            assert!(e.to_string().starts_with("big.tif: grid size"), "{e}");
        }
    }
}
