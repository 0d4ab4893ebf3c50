//! Digital elevation models, read by [`Dem::load`] in any of three formats, told apart by the
//! file's content (not its name):
//!
//! - **GeoTIFF** (`geotiff.rs`): one band of uint8, int16, uint16, int32, float32 or float64,
//!   strips or tiles, uncompressed, Deflate, LZW, PackBits or Zstandard, with or without a
//!   predictor; the cell size from the GeoTIFF tags, nodata from the `GDAL_NODATA` tag.
//! - **SRTM `.hgt`** (`hgt.rs`): 3601x3601 (1 arc-second) or 1201x1201 (3 arc-second)
//!   big-endian int16 samples, origin from the file name, voids (-32768) as nodata.
//! - **PNG + sidecar**: a 16-bit grayscale PNG (first row = north, or south where the
//!   sidecar's `row_order` says so in so many words) and a JSON file of the same stem giving
//!   its size, cell spacing and height scale; a key that looks like a misspelt field is
//!   refused rather than left for the field's default.
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
/// The widest cell a DEM sidecar may give, metres (1,000 km).
pub const MAX_SIDECAR_CELL_M: f64 = 1_000_000.0;

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

/// The sidecar's fields that are read, and those of its `cell_size_m`.
const SIDECAR_FIELDS: [&str; 8] = [
    "width",
    "height",
    "cell_size_m",
    "height_offset_m",
    "height_scale_m",
    "row_order",
    "place",
    "source",
];
const CELL_SIZE_FIELDS: [&str; 2] = ["east_west", "north_south"];
/// Fields of words only: a misspelling of them changes nothing baked, and a key a letter or
/// two from them (`sources`) may well be the file's own, so only their case or separators
/// are taken as a slip.
const SIDECAR_TEXT_FIELDS: [&str; 2] = ["place", "source"];

/// `row_order` of rows stored north first (the documented order, and the default). It may be
/// followed by `, last row is the southern edge`, and is read in any case, with or without
/// `the ` before a clause or a full stop after it.
pub const ROW_ORDER_NORTH_FIRST: &str = "first row is the northern edge";
/// `row_order` of rows stored south first (a bottom-up image), turned north first when read;
/// it may be followed by `, last row is the northern edge`.
pub const ROW_ORDER_SOUTH_FIRST: &str = "first row is the southern edge";

/// Which edge a sidecar's `row_order` says the PNG's first row is: `Some(true)` north,
/// `Some(false)` south, `None` for any other wording (refused: a guess could bake the world
/// upside down).
fn north_first(order: &str) -> Option<bool> {
    let clauses: Vec<String> = order
        .split([',', ';'])
        .map(|clause| {
            let words = clause.split_whitespace().collect::<Vec<_>>().join(" ");
            let words = words.to_lowercase();
            let words = words.trim_end_matches('.');
            words.strip_prefix("the ").unwrap_or(words).to_string()
        })
        .collect();
    let clauses: Vec<&str> = clauses.iter().map(String::as_str).collect();
    match clauses[..] {
        [ROW_ORDER_NORTH_FIRST] | [ROW_ORDER_NORTH_FIRST, "last row is the southern edge"] => {
            Some(true)
        }
        [ROW_ORDER_SOUTH_FIRST] | [ROW_ORDER_SOUTH_FIRST, "last row is the northern edge"] => {
            Some(false)
        }
        _ => None,
    }
}

/// The field among `fields` that `key` (none of them) looks like a slip for: the same name in
/// another case or with other separators, without its unit suffix `_m`, or (for the fields
/// not in [`SIDECAR_TEXT_FIELDS`]) a letter or two away (`height_scale` and `heigth_scale_m`
/// for `height_scale_m`). `None` for a key of its own (`bounds_deg`, `encoding`).
fn look_alike(key: &str, fields: &[&'static str]) -> Option<&'static str> {
    let norm = |s: &str| -> String {
        s.chars()
            .filter(char::is_ascii_alphanumeric)
            .map(|c| c.to_ascii_lowercase())
            .collect()
    };
    let k = norm(key);
    fields.iter().copied().find(|field| {
        let bare = field.strip_suffix("_m").unwrap_or(field);
        [norm(field), norm(bare)].iter().any(|f| {
            let slips = match f.len() {
                _ if SIDECAR_TEXT_FIELDS.contains(field) => 0,
                8.. => 2,
                5.. => 1,
                _ => 0,
            };
            edit_distance(&k, f) <= slips
        })
    })
}

/// Edits (a letter inserted, deleted, replaced, or two neighbours swapped) from `a` to `b`.
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    // Rows i - 2, i - 1 and i of the table of distances between prefixes.
    let mut before: Vec<usize> = vec![0; b.len() + 1];
    let mut last: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut row = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            row[j] = (last[j] + 1).min(row[j - 1] + 1).min(last[j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                row[j] = row[j].min(before[j - 2] + 1);
            }
        }
        before = std::mem::replace(&mut last, row);
    }
    last[b.len()]
}

/// Refuses a sidecar key that looks like a slip for a field ([`look_alike`]): the field would
/// silently take its default (a height scale of 1 for `height_scale`). Other keys are the
/// file's own (provenance: `bounds_deg`, `height_range_m`, ...) and are left alone.
fn check_sidecar_keys(sidecar_file: &Path, text: &str) -> Result<(), WorldError> {
    // A text that is not a JSON object is left to the parser's own message.
    let Ok(serde_json::Value::Object(top)) = serde_json::from_str(text) else {
        return Ok(());
    };
    let cells = match top.get("cell_size_m") {
        Some(serde_json::Value::Object(cells)) => Some(cells),
        _ => None,
    };
    let unknown = top
        .keys()
        .filter(|k| !SIDECAR_FIELDS.contains(&k.as_str()))
        .map(|k| {
            (
                k.clone(),
                look_alike(k, &SIDECAR_FIELDS).map(str::to_string),
            )
        });
    let unknown_cells = cells.into_iter().flat_map(|cells| {
        cells
            .keys()
            .filter(|k| !CELL_SIZE_FIELDS.contains(&k.as_str()))
            .map(|k| {
                (
                    format!("cell_size_m.{k}"),
                    look_alike(k, &CELL_SIZE_FIELDS).map(|f| format!("cell_size_m.{f}")),
                )
            })
    });
    for (key, field) in unknown.chain(unknown_cells) {
        if let Some(field) = field {
            return Err(WorldError::BadSidecar {
                path: sidecar_file.to_path_buf(),
                message: format!(
                    "key \"{key}\" is not a sidecar field: it looks like \"{field}\" misspelt, \
                     which would otherwise be taken as missing (rename the key; the fields read \
                     are width, height, cell_size_m.east_west and .north_south, \
                     height_offset_m, height_scale_m, row_order, place and source)"
                ),
            });
        }
    }
    Ok(())
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
        Dem::png_sidecar_header_rows(png_path).map(|(dem, scale, _)| (dem, scale))
    }

    /// [`Dem::png_sidecar_header`], and whether the PNG's first row is its northern edge.
    fn png_sidecar_header_rows(png_path: &Path) -> Result<(Dem, [f64; 2], bool), WorldError> {
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
        // A byte-order mark, as some editors on Windows save JSON with, is no part of it.
        let text = match text.strip_prefix('\u{feff}') {
            Some(rest) => rest.to_owned(),
            None => text,
        };
        check_sidecar_keys(&sidecar_file, &text)?;
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
        for (field, value) in [
            ("cell_size_m.east_west", sidecar.cell_size_m.east_west),
            ("cell_size_m.north_south", sidecar.cell_size_m.north_south),
        ] {
            check(field, value)?;
            // No DEM's samples lie further apart than a few degrees: a cell of thousands of
            // kilometres is a wrong sidecar, named here rather than by what it breaks later.
            if value > MAX_SIDECAR_CELL_M {
                return Err(WorldError::OutOfRange {
                    path: sidecar_file.clone(),
                    field: field.into(),
                    value: format!("{value:e}"),
                    allowed: format!(
                        "at most {MAX_SIDECAR_CELL_M} m (1,000 km; a degree of latitude is 111 km)"
                    ),
                });
            }
        }
        check("height_scale_m", sidecar.height_scale_m)?;
        if !sidecar.height_offset_m.is_finite() {
            return Err(WorldError::NonFinite {
                path: sidecar_file,
                field: "height_offset_m".into(),
                value: sidecar.height_offset_m,
            });
        }
        let north_first = match &sidecar.row_order {
            None => true,
            Some(order) => north_first(order).ok_or_else(|| WorldError::BadSidecar {
                path: sidecar_file.clone(),
                message: format!(
                    "row_order {order:?}: must be \"{ROW_ORDER_NORTH_FIRST}\" (rows stored \
                     north first) or \"{ROW_ORDER_SOUTH_FIRST}\" (south first), optionally \
                     followed by \", last row is the southern edge\" (or northern): any other \
                     wording could bake the world upside down"
                ),
            })?,
        };
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
        Ok((
            dem,
            [sidecar.height_offset_m, sidecar.height_scale_m],
            north_first,
        ))
    }

    /// Loads a 16-bit PNG DEM and its sidecar, checking that they agree; rows stored south
    /// first are turned north first.
    fn load_png_sidecar(png_path: &Path) -> Result<Dem, WorldError> {
        let (mut dem, [offset, scale], north_first) = Dem::png_sidecar_header_rows(png_path)?;
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
        if !north_first {
            let w = dem.width as usize;
            let h = dem.height as usize;
            for r in 0..h / 2 {
                let (north, south) = dem.heights.split_at_mut((h - 1 - r) * w);
                north[r * w..(r + 1) * w].swap_with_slice(&mut south[..w]);
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `name.png`, 4 x 3 samples whose value is 10 x the row from the top plus the
    /// column, and its sidecar: the documented fields with `extra` merged over them.
    fn write_png_dem(dir: &Path, name: &str, extra: serde_json::Value) -> PathBuf {
        let png = dir.join(format!("{name}.png"));
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(4, 3, |c, r| {
            image::Luma([(10 * r + c) as u16])
        })
        .save(&png)
        .unwrap();
        let mut json = serde_json::json!({
            "width": 4,
            "height": 3,
            "cell_size_m": { "east_west": 10.0, "north_south": 10.0 },
            "height_offset_m": 0.0,
            "height_scale_m": 1.0,
            "bounds_deg": { "north": 1.0, "south": 0.0, "west": 0.0, "east": 1.0 },
            "height_range_m": [0, 22],
            "encoding": "16-bit grayscale PNG",
        });
        for (k, v) in extra.as_object().unwrap() {
            json[k] = v.clone();
        }
        std::fs::write(sidecar_path(&png), json.to_string()).unwrap();
        png
    }

    fn first_column(dem: &Dem) -> Vec<f32> {
        dem.heights.iter().step_by(4).copied().collect()
    }

    #[test]
    fn row_order_is_read_only_in_its_documented_wordings() {
        let dir = tempfile::tempdir().unwrap();
        let load = |order: &str| {
            let png = write_png_dem(dir.path(), "d", serde_json::json!({ "row_order": order }));
            Dem::load(&png)
        };
        for north in [
            "first row is the northern edge",
            "The first row is the northern edge.",
            "first row is the northern edge, last row is the southern edge",
        ] {
            let dem = load(north).unwrap();
            assert_eq!(first_column(&dem), [0.0, 10.0, 20.0], "{north}");
        }
        // Rows stored south first are turned north first.
        for south in [
            "first row is the southern edge",
            "first row is the southern edge, last row is the northern edge",
        ] {
            let dem = load(south).unwrap();
            assert_eq!(first_column(&dem), [20.0, 10.0, 0.0], "{south}");
            assert_eq!(dem.heights[..4], [20.0, 21.0, 22.0, 23.0], "{south}");
        }
        // Anything else could be either: refused, quoting what is read.
        for other in [
            "not north-up",
            "north",
            "south-up",
            "first row is the northern edge, last row is the northern edge",
            "first row is the southern edge, last row is the southern edge",
            "",
        ] {
            let e = load(other).unwrap_err().to_string();
            assert!(e.contains("d.json"), "{other:?}: {e}");
            assert!(e.contains(&format!("{other:?}")), "{other:?}: {e}");
            assert!(e.contains(ROW_ORDER_NORTH_FIRST), "{other:?}: {e}");
            assert!(e.contains(ROW_ORDER_SOUTH_FIRST), "{other:?}: {e}");
        }
    }

    #[test]
    fn a_sidecar_key_that_looks_like_a_field_is_refused_naming_both() {
        let dir = tempfile::tempdir().unwrap();
        let load = |extra: serde_json::Value| {
            let png = write_png_dem(dir.path(), "d", extra);
            Dem::load(&png)
        };
        for (key, field) in [
            ("height_scale", "height_scale_m"),
            ("Height_Scale_M", "height_scale_m"),
            ("heigth_scale_m", "height_scale_m"),
            ("height_scale_ft", "height_scale_m"),
            ("heightOffset", "height_offset_m"),
            ("row-order", "row_order"),
            ("rowOrder", "row_order"),
            ("Width", "width"),
            ("Place", "place"),
        ] {
            let e = load(serde_json::json!({ key: 0.1 }))
                .unwrap_err()
                .to_string();
            for want in ["d.json", &format!("\"{key}\""), &format!("\"{field}\"")] {
                assert!(e.contains(want), "{key}: {e} lacks {want}");
            }
        }
        let e = load(serde_json::json!({
            "cell_size_m": { "east_west": 10.0, "north_south": 10.0, "north_south_m": 30.0 }
        }))
        .unwrap_err()
        .to_string();
        assert!(e.contains("\"cell_size_m.north_south_m\""), "{e}");
        assert!(e.contains("\"cell_size_m.north_south\""), "{e}");
        // Keys of the file's own are left alone.
        let extra = serde_json::json!({
            "file": "d.png", "sources": ["a", "b"], "notes": "x", "scale": 2, "crs": "EPSG:4326"
        });
        let dem = load(extra).unwrap();
        assert_eq!(dem.heights[5], 11.0);
    }

    #[test]
    fn the_shipped_sidecars_have_no_look_alike_keys() {
        for text in [
            include_str!("../../worlds/santa-cruz/source/santa_cruz_1024.json"),
            include_str!("../../worlds/baylands/source/baylands_400.json"),
        ] {
            check_sidecar_keys(Path::new("s.json"), text).unwrap();
            let order = serde_json::from_str::<Sidecar>(text).unwrap().row_order;
            assert_eq!(north_first(&order.unwrap()), Some(true));
        }
    }
}
