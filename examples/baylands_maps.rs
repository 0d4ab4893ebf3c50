//! Draws the land-cover and density maps of the `baylands` world from its DEM: a made-up map
//! (not surveyed land cover) in ESA WorldCover's class codes, twice the DEM's resolution, that
//! puts fields, bare ground, meadows, scrub, woods, roads and the bay where the heights make them
//! plausible.
//!
//! - Water (80): the bay, the samples at sea level (0 m) joined to the crop's north-east corner.
//! - The flat shore (below 15 m): parcels about 300 m by 250 m, turned 30 degrees, each cropland
//!   (40), grassland (30), bare ground (60) or scrub (20) by a hash of the parcel.
//! - The hills: grassland, with woods (10) and scrub (20) in patches of smooth noise.
//! - Roads (50, built-up): one along the foot of the hills, one up into them, 2 samples wide.
//! - The density map: each parcel's own cover (0.55 to 1), smooth noise on the hills, 0 on roads
//!   and water.
//!
//! ```sh
//! cargo run --example baylands_maps -- worlds/baylands/source
//! ```
//! reads `baylands_400.png` there and writes `land_cover.png` and `density.png` beside it.

use std::collections::VecDeque;
use std::path::PathBuf;

/// Map samples per DEM sample, along each axis.
const SCALE: u32 = 2;

fn hash(x: i64, y: i64, k: u64) -> f64 {
    let mut z = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ k.wrapping_mul(0x1656_67B1_9E37_79F9);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in 0..1, one lattice cell per `cell` samples.
fn noise(x: f64, y: f64, cell: f64, k: u64) -> f64 {
    let (px, py) = (x / cell, y / cell);
    let (ix, iy) = (px.floor() as i64, py.floor() as i64);
    let (fx, fy) = (px - px.floor(), py - py.floor());
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let a = hash(ix, iy, k) + (hash(ix + 1, iy, k) - hash(ix, iy, k)) * sx;
    let b = hash(ix, iy + 1, k) + (hash(ix + 1, iy + 1, k) - hash(ix, iy + 1, k)) * sx;
    a + (b - a) * sy
}

/// Distance from `p` to the polyline `line`, in map samples.
fn distance_to(line: &[(f64, f64)], p: (f64, f64)) -> f64 {
    line.windows(2)
        .map(|s| {
            let ((ax, ay), (bx, by)) = (s[0], s[1]);
            let (dx, dy) = (bx - ax, by - ay);
            let t = (((p.0 - ax) * dx + (p.1 - ay) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            ((p.0 - ax - t * dx).powi(2) + (p.1 - ay - t * dy).powi(2)).sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "worlds/baylands/source".into()),
    );
    let dem = image::open(dir.join("baylands_400.png"))?.into_luma16();
    let (dw, dh) = dem.dimensions();
    let (w, h) = (dw * SCALE, dh * SCALE);
    let height = |x: u32, y: u32| f64::from(dem.get_pixel(x / SCALE, y / SCALE)[0]);

    // The bay: sea-level samples joined to the north-east corner (zeros inland are voids of
    // the survey on low land, not water).
    let mut water = vec![false; (w * h) as usize];
    let mut queue = VecDeque::from([(w - 1, 0u32)]);
    while let Some((x, y)) = queue.pop_front() {
        let k = (y * w + x) as usize;
        if water[k] || height(x, y) > 0.0 {
            continue;
        }
        water[k] = true;
        if x > 0 {
            queue.push_back((x - 1, y));
        }
        if x + 1 < w {
            queue.push_back((x + 1, y));
        }
        if y > 0 {
            queue.push_back((x, y - 1));
        }
        if y + 1 < h {
            queue.push_back((x, y + 1));
        }
    }

    // Roads, in map samples (x east, y south from the north-west corner).
    let shore_road = [
        (40.0, 200.0),
        (140.0, 330.0),
        (240.0, 510.0),
        (360.0, 620.0),
        (520.0, 700.0),
        (800.0, 760.0),
    ];
    let hill_road = [(240.0, 510.0), (170.0, 600.0), (60.0, 700.0), (0.0, 720.0)];

    let mut cover = image::GrayImage::new(w, h);
    let mut density = image::GrayImage::new(w, h);
    let (sin, cos) = 30f64.to_radians().sin_cos();
    for y in 0..h {
        for x in 0..w {
            let p = (f64::from(x), f64::from(y));
            let road = distance_to(&shore_road, p).min(distance_to(&hill_road, p)) < 1.0;
            let (class, d) = if water[(y * w + x) as usize] {
                (80u8, 0.0)
            } else if road {
                (50, 0.0)
            } else if height(x, y) < 15.0 {
                // Parcels on a grid turned 30 degrees.
                let (u, v) = (p.0 * cos + p.1 * sin, -p.0 * sin + p.1 * cos);
                let (pu, pv) = ((u / 24.0).floor() as i64, (v / 20.0).floor() as i64);
                let r = hash(pu, pv, 1);
                let d = 0.55 + 0.45 * hash(pu, pv, 2);
                match r {
                    r if r < 0.5 => (40, d),
                    r if r < 0.75 => (30, d),
                    r if r < 0.9 => (60, d),
                    _ => (20, d),
                }
            } else {
                let n = noise(p.0, p.1, 60.0, 3);
                let d = 0.5 + 0.5 * noise(p.0, p.1, 25.0, 4);
                match n {
                    n if n > 0.62 => (10, d),
                    n if n < 0.3 => (20, d),
                    _ => (30, d),
                }
            };
            cover.put_pixel(x, y, image::Luma([class]));
            density.put_pixel(x, y, image::Luma([(d * 255.0).round() as u8]));
        }
    }
    cover.save(dir.join("land_cover.png"))?;
    density.save(dir.join("density.png"))?;
    println!(
        "wrote {w}x{h} land_cover.png and density.png into {}",
        dir.display()
    );
    Ok(())
}
