//! Writes a mosaic of synthetic but realistic SRTM 1-arc-second `.hgt` tiles (3601 samples a
//! side, adjacent tiles sharing their edge rows) for measuring large bakes: `N x N` tiles whose
//! heights are one continuous landscape of ridges and valleys over longitude and latitude
//! (value noise of seven octaves, 0 to about 1,500 m), so the joins must be seamless.
//!
//! ```sh
//! cargo run --release --example srtm_mosaic -- out/srtm 4     # 16 tiles, 207 million samples
//! /usr/bin/time -v verdant bake --dem out/srtm --out out/big
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
