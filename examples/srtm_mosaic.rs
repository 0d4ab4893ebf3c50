//! Writes a mosaic of synthetic but realistic SRTM 1-arc-second `.hgt` tiles (3601 samples a
//! side, adjacent tiles sharing their edge rows) for measuring large bakes: `N x N` tiles whose
//! heights are one continuous landscape of ridges and valleys over longitude and latitude
//! (value noise of seven octaves, 0 to about 1,500 m), so the joins must be seamless.
//!
//! ```sh
//! cargo run --release --example srtm_mosaic -- out/srtm 4     # 16 tiles, 207 million samples
//! /usr/bin/time -v verdant bake --dem out/srtm --out out/big
//! ```
//!
//! With `cog` after the count, the same landscape over the same `N x N` degrees is written as
//! one tiled GeoTIFF instead (`DIR/landscape.tif`: 16-bit samples of 1 arc-second in tiles of
//! 512 x 512, Deflate-compressed, georeferenced in WGS 84 degrees), as a Cloud-Optimised
//! GeoTIFF stores a large DEM:
//!
//! ```sh
//! cargo run --release --example srtm_mosaic -- out/cog 2 cog   # 7201 x 7201 samples
//! verdant bake --dem out/cog/landscape.tif --out out/cog_world
//! ```

use std::io::Write;
use std::path::PathBuf;

fn hash(x: i64, y: i64, k: u64) -> f64 {
    let mut z = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ k.wrapping_mul(0x1656_67B1_9E37_79F9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in 0..1, one lattice cell per unit.
fn noise(x: f64, y: f64, k: u64) -> f64 {
    let (ix, iy) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - x.floor(), y - y.floor());
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let a = hash(ix, iy, k) + (hash(ix + 1, iy, k) - hash(ix, iy, k)) * sx;
    let b = hash(ix, iy + 1, k) + (hash(ix + 1, iy + 1, k) - hash(ix, iy + 1, k)) * sx;
    a + (b - a) * sy
}

/// Height in metres at longitude `lon` and latitude `lat` (degrees): ridged value noise from
/// about 20 km features down to about 150 m.
fn height(lon: f64, lat: f64) -> i16 {
    let (mut sum, mut amp, mut freq) = (0.0, 1.0, 5.0);
    for o in 0..7u64 {
        let n = noise(lon * freq, lat * freq, o);
        sum += amp * (1.0 - (2.0 * n - 1.0).abs());
        amp *= 0.5;
        freq *= 2.0;
    }
    (sum / 2.0 * 1500.0).round() as i16
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().unwrap_or_else(|| "out/srtm".into()));
    let n: i32 = args.next().map_or(Ok(4), |s| s.parse())?;
    std::fs::create_dir_all(&dir)?;
    let (lon0, lat0) = (-123, 37);
    if args.next().as_deref() == Some("cog") {
        let path = dir.join("landscape.tif");
        write_tiled_geotiff(&path, n, lon0, lat0)?;
        println!("wrote {}", path.display());
        return Ok(());
    }
    for j in 0..n {
        for i in 0..n {
            let (lon, lat) = (lon0 + i, lat0 + j);
            let name = format!("N{lat:02}W{:03}.hgt", -lon);
            let mut bytes = Vec::with_capacity(3601 * 3601 * 2);
            for r in 0..3601 {
                let y = f64::from(lat + 1) - f64::from(r) / 3600.0;
                for c in 0..3601 {
                    let x = f64::from(lon) + f64::from(c) / 3600.0;
                    bytes.extend_from_slice(&height(x, y).to_be_bytes());
                }
            }
            std::fs::File::create(dir.join(&name))?.write_all(&bytes)?;
            println!("wrote {}", dir.join(&name).display());
        }
    }
    Ok(())
}

/// Tile edge of the GeoTIFF, samples.
const TILE: u32 = 512;

/// Writes the landscape over `n x n` degrees from (`lon0`, `lat0`) at 1 arc-second as one
/// tiled, Deflate-compressed little-endian GeoTIFF of signed 16-bit heights, north row first.
fn write_tiled_geotiff(
    path: &std::path::Path,
    n: i32,
    lon0: i32,
    lat0: i32,
) -> Result<(), Box<dyn std::error::Error>> {
    let side = (n * 3600 + 1) as u32;
    let across = side.div_ceil(TILE);
    let mut tiles: Vec<Vec<u8>> = Vec::new();
    for ty in 0..across {
        for tx in 0..across {
            let mut raw = Vec::with_capacity((TILE * TILE * 2) as usize);
            for r in ty * TILE..(ty + 1) * TILE {
                for c in tx * TILE..(tx + 1) * TILE {
                    let h = if r < side && c < side {
                        let y = f64::from(lat0 + n) - f64::from(r) / 3600.0;
                        let x = f64::from(lon0) + f64::from(c) / 3600.0;
                        height(x, y)
                    } else {
                        0 // the padding of the last tiles
                    };
                    raw.extend_from_slice(&h.to_le_bytes());
                }
            }
            tiles.push(miniz_oxide::deflate::compress_to_vec_zlib(&raw, 6));
        }
    }
    // Header, tiles, then the directory and the values that do not fit in its entries.
    let mut out: Vec<u8> = b"II*\0\0\0\0\0".to_vec();
    let mut offsets = Vec::with_capacity(tiles.len());
    for t in &tiles {
        offsets.push(u32::try_from(out.len())?);
        out.extend_from_slice(t);
    }
    let counts: Vec<u32> = tiles.iter().map(|t| t.len() as u32).collect();
    // Sample centres on whole arc-seconds: the corner half a sample to the north-west.
    let step = 1.0 / 3600.0;
    let scale = [step, step, 0.0];
    let tie = [
        0.0,
        0.0,
        0.0,
        f64::from(lon0) - step / 2.0,
        f64::from(lat0 + n) + step / 2.0,
        0.0,
    ];
    // Geographic (2), pixels as areas (1), WGS 84 (4326), degrees (9102).
    let keys: [u16; 20] = [
        1, 1, 0, 4, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326, 2054, 0, 1, 9102,
    ];
    enum V {
        Short(Vec<u16>),
        Long(Vec<u32>),
        Double(Vec<f64>),
    }
    let entries: Vec<(u16, V)> = vec![
        (256, V::Long(vec![side])),
        (257, V::Long(vec![side])),
        (258, V::Short(vec![16])),
        (259, V::Short(vec![8])),
        (262, V::Short(vec![1])),
        (277, V::Short(vec![1])),
        (284, V::Short(vec![1])),
        (322, V::Long(vec![TILE])),
        (323, V::Long(vec![TILE])),
        (324, V::Long(offsets)),
        (325, V::Long(counts)),
        (339, V::Short(vec![2])),
        (33550, V::Double(scale.to_vec())),
        (33922, V::Double(tie.to_vec())),
        (34735, V::Short(keys.to_vec())),
    ];
    if out.len() % 2 == 1 {
        out.push(0); // the directory on a word boundary
    }
    let ifd = out.len() as u32;
    out[4..8].copy_from_slice(&ifd.to_le_bytes());
    let mut extra = ifd as usize + 2 + entries.len() * 12 + 4;
    let mut tail: Vec<u8> = Vec::new();
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (tag, value) in &entries {
        let (kind, count, bytes): (u16, usize, Vec<u8>) = match value {
            V::Short(v) => (3, v.len(), v.iter().flat_map(|x| x.to_le_bytes()).collect()),
            V::Long(v) => (4, v.len(), v.iter().flat_map(|x| x.to_le_bytes()).collect()),
            V::Double(v) => (
                12,
                v.len(),
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
        };
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&kind.to_le_bytes());
        out.extend_from_slice(&(count as u32).to_le_bytes());
        if bytes.len() <= 4 {
            let mut inline = bytes.clone();
            inline.resize(4, 0);
            out.extend_from_slice(&inline);
        } else {
            out.extend_from_slice(&(extra as u32).to_le_bytes());
            extra += bytes.len();
            tail.extend_from_slice(&bytes);
        }
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&tail);
    std::fs::write(path, out)?;
    Ok(())
}
