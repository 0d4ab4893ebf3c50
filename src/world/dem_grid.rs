//! The decoded DEM grid that every reader of a DEM format produces ([`Dem`]), its sampling,
//! and the checks and geodesy the readers share: `dem.rs` dispatches to the readers
//! (`geotiff.rs`, `hgt.rs` and its own PNG + sidecar), and all of them build on this module.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::WorldError;

/// The part of a coordinate system's description that identifies it: its EPSG code where it
/// has one (`EPSG:32610`), else the whole description.
pub(crate) fn crs_key(crs: &str) -> &str {
    if crs.starts_with("EPSG:") {
        crs.split([',', ' ']).next().unwrap_or(crs)
    } else {
        crs
    }
}

/// A coordinate system's description for messages: "not stated" where it is empty.
pub(crate) fn or_unstated(crs: &str) -> &str {
    if crs.is_empty() { "not stated" } else { crs }
}

/// Most samples a DEM may have (16384 x 16384): its heights alone take 1 GiB.
pub const MAX_DEM_SAMPLES: u64 = 1 << 28;

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
    /// Spacing of the samples in that coordinate system's units (x then y, both positive),
    /// where the file gives them: what places another raster in the same system on this one.
    pub pixel_size: Option<[f64; 2]>,
    /// Nodata samples that were filled from the heights around them.
    pub nodata_filled: u64,
}

impl Dem {
    /// Size of the area the samples span, metres (east-west, north-south).
    pub fn extent_m(&self) -> [f64; 2] {
        [
            f64::from(self.width - 1) * self.cell_ew_m,
            f64::from(self.height - 1) * self.cell_ns_m,
        ]
    }

    /// Height at world position `(x, y)` (metres from the south-west sample) by bicubic
    /// (Catmull-Rom) interpolation in the DEM's grid. Positions beyond the DEM take the height
    /// at the nearest point of its edge.
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        let w = self.width as usize;
        bicubic(self, x, y, |c, r| self.heights[r * w + c])
    }

    /// The posts (columns from the west, rows from the NORTH, end exclusive) that
    /// [`Dem::sample`] reads for positions in `x` by `y` (metres, as for `sample`).
    pub fn posts_for(&self, x: [f64; 2], y: [f64; 2]) -> ([usize; 2], [usize; 2]) {
        let [ex, ey] = self.extent_m();
        let span = |v: [f64; 2], e: f64, cell: f64, n: u32| {
            let lo = (v[0].clamp(0.0, e) / cell).floor() as i64 - 1;
            let hi = (v[1].clamp(0.0, e) / cell).floor() as i64 + 2;
            let n = i64::from(n);
            [
                lo.clamp(0, n - 1) as usize,
                (hi.clamp(0, n - 1) + 1) as usize,
            ]
        };
        let cols = span(x, ex, self.cell_ew_m, self.width);
        let south = span(y, ey, self.cell_ns_m, self.height);
        let h = self.height as usize;
        (cols, [h - south[1], h - south[0]])
    }
}

/// Bicubic (Catmull-Rom) height at `(x, y)` in the grid `dem` describes (its size and
/// spacing; its heights are not read), the posts read through `post(column, row from the
/// north)`, clamped to the grid's edges.
pub(crate) fn bicubic(dem: &Dem, x: f64, y: f64, post: impl Fn(usize, usize) -> f32) -> f64 {
    let [ex, ey] = dem.extent_m();
    let u = x.clamp(0.0, ex) / dem.cell_ew_m;
    let v = y.clamp(0.0, ey) / dem.cell_ns_m;
    let (c0, r0) = (u.floor(), v.floor());
    let (fu, fv) = (u - c0, v - r0);
    let (c0, r0) = (c0 as i64, r0 as i64);
    let wu = catmull_rom_weights(fu);
    let wv = catmull_rom_weights(fv);
    let (w, h) = (i64::from(dem.width), i64::from(dem.height));
    // Column `c` (from the west) and row `r` from the SOUTH, clamped to the edges.
    let at = |c: i64, r: i64| {
        let c = c.clamp(0, w - 1) as usize;
        let r = r.clamp(0, h - 1) as usize;
        f64::from(post(c, h as usize - 1 - r))
    };
    let mut height = 0.0;
    for (dr, wr) in wv.iter().enumerate() {
        let mut row = 0.0;
        for (dc, wc) in wu.iter().enumerate() {
            row += wc * at(c0 + dc as i64 - 1, r0 + dr as i64 - 1);
        }
        height += wr * row;
    }
    height
}

/// A window of a DEM's posts: enough of it to sample positions inside the window exactly as the
/// whole DEM would ([`Dem::posts_for`]).
pub struct DemWindow<'a> {
    /// The whole DEM's size and spacing (its heights need not be held).
    pub dem: &'a Dem,
    /// The window's first column (from the west) and first row (from the north).
    pub first: [usize; 2],
    /// Columns in the window.
    pub width: usize,
    /// Its heights, row-major, north first.
    pub heights: Vec<f32>,
}

impl DemWindow<'_> {
    /// [`Dem::sample`] at `(x, y)`, which must read only posts inside the window.
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        bicubic(self.dem, x, y, |c, r| {
            self.heights[(r - self.first[1]) * self.width + (c - self.first[0])]
        })
    }
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
