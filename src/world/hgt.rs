//! SRTM `.hgt` tiles: a square grid of big-endian int16 heights in metres, first row north,
//! covering one degree of latitude and longitude with one sample of overlap on each side
//! (3601x3601 samples at 1 arc-second, 1201x1201 at 3 arc-seconds). The file has no header:
//! the south-west corner comes from its name (`N37W123.hgt` starts at 37 N, 123 W), and voids
//! are stored as -32768.

use std::path::Path;

use super::dem_grid::{Dem, DemFormat, metres_per_degree};
use super::error::WorldError;

/// The value SRTM stores for a void.
const VOID: i16 = -32768;

/// The samples per side of an `.hgt` tile of `bytes` bytes, if any tile has that size.
pub(crate) fn side_for_size(bytes: u64) -> Option<u32> {
    [3601u32, 1201]
        .into_iter()
        .find(|&n| u64::from(n) * u64::from(n) * 2 == bytes)
}

/// The south-west corner (longitude, latitude in whole degrees) that an `.hgt` tile's name
/// gives: the name starts with `N` or `S`, two digits, `E` or `W` and three digits, in any case
/// (`N37W123.hgt`, `s05e119.SRTMGL1.hgt`).
pub(crate) fn origin_from_name(path: &Path) -> Option<[f64; 2]> {
    let name = path.file_name()?.to_str()?.to_ascii_uppercase();
    let b = name.as_bytes();
    if b.len() < 7 || !b[1..3].iter().chain(&b[4..7]).all(u8::is_ascii_digit) {
        return None;
    }
    let lat: f64 = name[1..3].parse().ok()?;
    let lon: f64 = name[4..7].parse().ok()?;
    let lat = match b[0] {
        b'N' => lat,
        b'S' => -lat,
        _ => return None,
    };
    let lon = match b[3] {
        b'E' => lon,
        b'W' => -lon,
        _ => return None,
    };
    (lat <= 89.0 && (-180.0..=179.0).contains(&lon)).then_some([lon, lat])
}

/// Reads an `.hgt` tile; voids become NaN. Without `cell_override` the name must give the
/// tile's origin (its latitude sets the cell size in metres).
pub(crate) fn load(path: &Path, cell_override: Option<[f64; 2]>) -> Result<Dem, WorldError> {
    use std::io::Read;
    let (file, len) = super::format::open_regular(path)?;
    // The size is checked before reading, so that a huge file is not read at all.
    let Some(side) = side_for_size(len) else {
        return Err(WorldError::HgtSize {
            path: path.to_path_buf(),
            bytes: len,
        });
    };
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(len)
        .read_to_end(&mut bytes)
        .map_err(|e| WorldError::io(path, e))?;
    if bytes.len() as u64 != len {
        return Err(WorldError::HgtSize {
            path: path.to_path_buf(),
            bytes: bytes.len() as u64,
        });
    }
    let mut dem = header(path, side, cell_override)?;
    dem.heights = heights(&bytes);
    Ok(dem)
}

/// Heights from an `.hgt` tile's big-endian samples; voids become NaN.
pub(crate) fn heights(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(2)
        .map(|b| match i16::from_be_bytes([b[0], b[1]]) {
            VOID => f32::NAN,
            h => f32::from(h),
        })
        .collect()
}

/// An `.hgt` tile's grid of `side` samples a side (its heights left empty). Without
/// `cell_override` the name must give the tile's origin (its latitude sets the cell size).
pub(crate) fn header(
    path: &Path,
    side: u32,
    cell_override: Option<[f64; 2]>,
) -> Result<Dem, WorldError> {
    let origin = origin_from_name(path);
    let [cell_ew_m, cell_ns_m] = match (origin, cell_override) {
        (_, Some(cell)) => cell,
        (Some([_, lat]), None) => {
            let spacing_deg = 1.0 / f64::from(side - 1);
            metres_per_degree(lat + 0.5).map(|m| m * spacing_deg)
        }
        (None, None) => {
            return Err(WorldError::HgtName {
                path: path.to_path_buf(),
            });
        }
    };
    let arc_seconds = 3600 / (side - 1);
    Ok(Dem {
        width: side,
        height: side,
        cell_ew_m,
        cell_ns_m,
        heights: Vec::new(),
        place: String::new(),
        source: format!("SRTM {arc_seconds} arc-second tile"),
        format: DemFormat::SrtmHgt,
        crs: "EPSG:4326 (WGS 84), geographic (degrees)".into(),
        origin,
        pixel_size: Some([1.0 / f64::from(side - 1); 2]),
        nodata_filled: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_give_the_south_west_corner() {
        let o = |n: &str| origin_from_name(Path::new(n));
        assert_eq!(o("N37W123.hgt"), Some([-123.0, 37.0]));
        assert_eq!(o("dir/s05e119.SRTMGL1.hgt"), Some([119.0, -5.0]));
        assert_eq!(o("N00E000.hgt"), Some([0.0, 0.0]));
        assert_eq!(o("tile.hgt"), None);
        assert_eq!(o("X37W123.hgt"), None);
        assert_eq!(o("N37W1x3.hgt"), None);
        assert_eq!(o("N95W123.hgt"), None);
    }

    #[test]
    fn only_srtm_sizes_are_tiles() {
        assert_eq!(side_for_size(3601 * 3601 * 2), Some(3601));
        assert_eq!(side_for_size(1201 * 1201 * 2), Some(1201));
        assert_eq!(side_for_size(1201 * 1201 * 2 - 2), None);
        assert_eq!(side_for_size(0), None);
    }
}
