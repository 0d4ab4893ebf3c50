//! Digital elevation models in the sidecar format: a 16-bit grayscale PNG (first row = north)
//! and a JSON file of the same stem giving its size, cell spacing and height scale.
//!
//! Samples are points ("posts"): sample `(c, r)` lies `c * cell_ew_m` east and
//! `(height - 1 - r) * cell_ns_m` north of the DEM's south-west sample, so a DEM spans
//! `(width - 1) * cell_ew_m` by `(height - 1) * cell_ns_m` metres.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::error::WorldError;
use super::format::decode_png;

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
    /// Loads a DEM image and its sidecar, checking that they agree.
    pub fn load(png_path: &Path) -> Result<Dem, WorldError> {
        let sidecar_file = sidecar_path(png_path);
        let png_bytes = std::fs::read(png_path).map_err(|e| WorldError::io(png_path, e))?;
        let text = match std::fs::read_to_string(&sidecar_file) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(WorldError::MissingSidecar {
                    path: png_path.to_path_buf(),
                    sidecar: sidecar_file,
                });
            }
            Err(e) => return Err(WorldError::io(&sidecar_file, e)),
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
