//! A grass blade: what the generation stage writes for each surviving blade, and the blade's
//! shape (CPU mirror of the shape code in `shaders/grass_draw.wgsl`).

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// One blade in the instance pool; mirrors `Blade` in the grass shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Blade {
    /// Root position relative to the camera, metres.
    pub pos: [f32; 3],
    /// Facing: angle of the blade's plane about its growth direction, radians.
    pub facing: f32,
    /// Growth direction, x and y (z follows: the direction is a unit vector with z > 0).
    pub growth: [f32; 2],
    /// Rest length, metres.
    pub height: f32,
    /// Width at the root, metres.
    pub width: f32,
    /// Lean of the tip away from the growth direction, radians.
    pub tilt: f32,
    /// Extra bend of the upper blade, 0 to 1.
    pub bend: f32,
    /// Sideways curve, -1 to 1.
    pub side_curve: f32,
    /// How much the wind moves the blade, 0 to 1.
    pub wind: f32,
    /// The blade's hash (drives every random attribute).
    pub hash: u32,
    /// Grass type index (bits 0-7) and LOD (bit 8: 1 = low).
    pub kind: u32,
    /// Clump colour tint, RGBA8 (alpha unused).
    pub color: u32,
    /// Fade factor 0 to 1 (blades leaving at a LOD switch shrink away); after the wind pass,
    /// the gust highlight 0 to 1.
    pub fade: f32,
    /// Lean of the tip from the sway and the trail, blade heights (x east, y north); written by
    /// the wind pass.
    pub lean: [f32; 2],
    /// Whole-blade sway from detail bending, -1 to 1 times its amount; written by the wind pass.
    pub sway: f32,
    /// Edge flutter, likewise.
    pub flutter: f32,
    /// How much the lean (x, y), the sway and the flutter changed over the last frame; written
    /// by the wind pass, for the draw's motion vectors.
    pub moved: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<Blade>() == 96);

impl Blade {
    /// The growth direction as a unit vector.
    pub fn growth_dir(&self) -> Vec3 {
        let [x, y] = self.growth;
        Vec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
    }
}

/// The four control points of a blade's cubic Bezier, root first, relative to the root. The
/// curve rises along `up`, leans by `tilt` toward `forward`, bends its upper part by `bend` and
/// curves sideways by `side_curve`; then it is scaled so that its length is `height` (the
/// length estimate splits the curve once and averages chord and control polygon per half,
/// within 1% of the true length for every shape the attributes allow).
pub fn blade_curve(
    up: Vec3,
    forward: Vec3,
    height: f32,
    tilt: f32,
    bend: f32,
    side_curve: f32,
) -> [Vec3; 4] {
    blade_curve_bent(up, forward, height, tilt, bend, side_curve, Vec3::ZERO)
}

/// [`blade_curve`] leaning by `lean` (in blade heights; the shader's wind bend: the sway and
/// trail as a horizontal vector, plus detail sway along the blade's side): the tip moves by
/// the whole lean, the upper control point by 0.6 of it, the lower by 0.15, before the length
/// is restored. Horizontal leans keep every control point above the root.
pub fn blade_curve_bent(
    up: Vec3,
    forward: Vec3,
    height: f32,
    tilt: f32,
    bend: f32,
    side_curve: f32,
    lean: Vec3,
) -> [Vec3; 4] {
    let side = up.cross(forward).normalize_or_zero();
    let fwd = side.cross(up).normalize_or_zero();
    let dir = |angle: f32| up * angle.cos() + fwd * angle.sin();
    let tip_angle = tilt + bend * 1.2;
    let p3 = dir(tilt) * height + lean * height;
    let p1 = up * (height / 3.0) + side * (side_curve * 0.15 * height) + lean * (0.15 * height);
    let p2 = p3 - dir(tip_angle) * (height / 3.0) + side * (side_curve * 0.15 * height)
        - lean * (0.4 * height);
    let p = [Vec3::ZERO, p1, p2, p3];
    let scale = height / bezier_length_estimate(&p).max(1e-6);
    p.map(|q| q * scale)
}

/// A linear RGB colour packed as the blade record's RGBA8 word (alpha 255), as `pack_rgba8` in
/// `shaders/shared/blade.wgsl` packs it.
pub(crate) fn pack_rgba8(c: [f32; 3]) -> u32 {
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u32;
    q(c[0]) | (q(c[1]) << 8) | (q(c[2]) << 16) | (255 << 24)
}

fn lerp(a: Vec3, b: Vec3) -> Vec3 {
    (a + b) * 0.5
}

/// Halves of a cubic Bezier (de Casteljau at the middle).
fn split(p: &[Vec3; 4]) -> ([Vec3; 4], [Vec3; 4]) {
    let (p01, p12, p23) = (lerp(p[0], p[1]), lerp(p[1], p[2]), lerp(p[2], p[3]));
    let (a, b) = (lerp(p01, p12), lerp(p12, p23));
    let m = lerp(a, b);
    ([p[0], p01, a, m], [m, b, p23, p[3]])
}

/// Length of a cubic Bezier: split into quarters, and for each the mean of its chord and its
/// control polygon (within 0.1% for every shape a blade takes, bent by a storm included).
pub fn bezier_length_estimate(p: &[Vec3; 4]) -> f32 {
    let piece = |q: &[Vec3; 4]| {
        0.5 * (q[0].distance(q[3])
            + q[0].distance(q[1])
            + q[1].distance(q[2])
            + q[2].distance(q[3]))
    };
    let (a, b) = split(p);
    let (a0, a1) = split(&a);
    let (b0, b1) = split(&b);
    piece(&a0) + piece(&a1) + piece(&b0) + piece(&b1)
}

/// A point on the cubic Bezier at `t`.
pub fn bezier(p: &[Vec3; 4], t: f32) -> Vec3 {
    let u = 1.0 - t;
    p[0] * (u * u * u) + p[1] * (3.0 * u * u * t) + p[2] * (3.0 * u * t * t) + p[3] * (t * t * t)
}

/// How far a vertex of a blade's strip lies off its curve, times the curve's second derivative
/// across it and the segment's parameter step squared: 3/4 of a chord's sag (a chord of length
/// L on a curve of curvature k sags k L^2 / 8 = |B''| dt^2 / 8 across it), the shift of a
/// parabolic arc's chord that brings it nearest the arc on average (`STRADDLE` in
/// `shaders/grass_draw.wgsl`).
pub const STRIP_STRADDLE: f32 = 3.0 / 32.0;

/// The centre of a blade's strip at parameter `t` (`t = i / segments`, the tip at 1): the
/// curve's point moved out of the curve's bend by [`STRIP_STRADDLE`], so that the strip's
/// chords straddle the curve instead of cutting inside it (near the camera a chord's sag is as
/// large as the blade is wide). The root and the tip stay on the curve.
pub fn strip_centre(p: &[Vec3; 4], t: f32, segments: u32) -> Vec3 {
    let on_curve = bezier(p, t);
    if t <= 0.0 || t >= 1.0 {
        return on_curve;
    }
    // First and second derivatives from the differences of the control points.
    let d = [p[1] - p[0], p[2] - p[1], p[3] - p[2]];
    let u = 1.0 - t;
    let first = 3.0 * (d[0] * (u * u) + d[1] * (2.0 * u * t) + d[2] * (t * t));
    let second = 6.0 * ((d[1] - d[0]) * u + (d[2] - d[1]) * t);
    let along = first.normalize_or_zero();
    let across = second - along * second.dot(along);
    let dt = 1.0 / segments.max(1) as f32;
    on_curve - across * (STRIP_STRADDLE * dt * dt)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn true_length(p: &[Vec3; 4]) -> f32 {
        let n = 4000;
        (0..n)
            .map(|i| bezier(p, i as f32 / n as f32).distance(bezier(p, (i + 1) as f32 / n as f32)))
            .sum()
    }

    #[test]
    fn blade_length_stays_within_one_percent_at_full_bend() {
        let up = Vec3::new(0.2, -0.1, 1.0).normalize();
        let forward = Vec3::X;
        let mut worst = 0.0f32;
        for tilt in [0.0, 0.3, 0.6, 0.9, 1.2, 1.4] {
            for bend in [0.0, 0.5, 1.0] {
                for side in [-1.0, 0.0, 1.0] {
                    let p = blade_curve(up, forward, 0.8, tilt, bend, side);
                    let err = (true_length(&p) - 0.8).abs() / 0.8;
                    worst = worst.max(err);
                }
            }
        }
        assert!(worst < 0.01, "length error {:.3}%", worst * 100.0);
    }

    #[test]
    fn bending_in_a_storm_keeps_length_and_stays_above_the_ground() {
        // Leans up to the strongest sway (1.1 blade heights) plus a full trail push
        // (TRAIL_LEAN, 1.6), in every direction, on flat and sloping ground.
        let mut worst = 0.0f32;
        for up in [Vec3::Z, Vec3::new(0.3, 0.1, 1.0).normalize()] {
            for k in 0..16 {
                let a = k as f32 * std::f32::consts::TAU / 16.0;
                for mag in [0.5, 1.0, 1.5, 2.0, 2.7] {
                    let lean = Vec3::new(a.cos(), a.sin(), 0.0) * mag;
                    for (tilt, bend) in [(0.1, 0.2), (0.6, 0.9), (0.35, 0.5)] {
                        let p = blade_curve_bent(up, Vec3::X, 0.6, tilt, bend, 0.7, lean);
                        worst = worst.max((true_length(&p) - 0.6).abs() / 0.6);
                        for i in 0..=64 {
                            let q = bezier(&p, i as f32 / 64.0);
                            assert!(
                                q.z >= -1e-6,
                                "a point of the blade goes below its root: {q:?}"
                            );
                        }
                    }
                }
            }
        }
        assert!(
            worst < 0.01,
            "length error in a storm {:.3}%",
            worst * 100.0
        );
    }

    #[test]
    fn an_upright_blade_rises_along_its_growth_direction() {
        let up = Vec3::new(0.0, 0.3, 1.0).normalize();
        let p = blade_curve(up, Vec3::X, 0.5, 0.0, 0.0, 0.0);
        assert!((p[3] - up * 0.5).length() < 1e-5);
    }

    /// The share of a blade's area that a strip of `segments` misses: along the dense curve,
    /// how far the strip's centre line lies from the curve, up to the blade's half-width
    /// either side, weighed by its width (which tapers from the root to a point at the tip).
    fn strip_miss(p: &[Vec3; 4], segments: u32, centre: impl Fn(f32) -> Vec3) -> f32 {
        let ts: Vec<f32> = (0..segments)
            .map(|i| i as f32 / segments as f32)
            .chain([1.0])
            .collect();
        let verts: Vec<Vec3> = ts.iter().map(|&t| centre(t)).collect();
        let (width, n) = (0.02 * bezier_length_estimate(p), 2000);
        let (mut miss, mut area) = (0.0, 0.0);
        for k in 0..n {
            let t = (k as f32 + 0.5) / n as f32;
            let c = bezier(p, t);
            let d = verts
                .windows(2)
                .map(|w| {
                    let ab = w[1] - w[0];
                    let s = ((c - w[0]).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
                    c.distance(w[0] + ab * s)
                })
                .fold(f32::INFINITY, f32::min);
            let w = width * (1.0 - t);
            miss += d.min(w);
            area += w;
        }
        miss / area
    }

    #[test]
    fn the_strip_straddles_the_curve_and_misses_less_of_the_blade_than_chords_on_it() {
        let (up, fwd) = (Vec3::Z, Vec3::X);
        let mut shapes = Vec::new();
        for tilt in [0.1, 0.35, 0.6] {
            for bend in [0.2, 0.55, 0.9] {
                for side_curve in [-1.0, 0.0, 0.7] {
                    shapes.push(blade_curve(up, fwd, 0.6, tilt, bend, side_curve));
                }
            }
        }
        // The share it misses at most, of the chords' on the curve (seen: 0.65, 0.52, 0.47).
        for (segments, most) in [(3, 0.7), (5, 0.55), (7, 0.5)] {
            let (mut on, mut straddled) = (0.0, 0.0);
            for p in &shapes {
                // Root and tip stay on the curve.
                assert_eq!(strip_centre(p, 0.0, segments), p[0]);
                assert!(strip_centre(p, 1.0, segments).distance(p[3]) < 1e-6);
                on += strip_miss(p, segments, |t| bezier(p, t));
                straddled += strip_miss(p, segments, |t| strip_centre(p, t, segments));
            }
            let (on, straddled) = (on / shapes.len() as f32, straddled / shapes.len() as f32);
            assert!(
                straddled < most * on,
                "{segments} segments: the straddling strip misses {straddled:.3} of the blade, \
                 chords on the curve {on:.3}"
            );
        }
    }

    #[test]
    fn a_vertex_moves_out_of_the_bend_by_three_quarters_of_the_sag() {
        // A quarter circle of radius 1 (control points at the kappa distance): a chord of
        // angle a sags (1 - cos(a / 2)); the vertex between two chords of 5 moves out by 3/4 of
        // it, away from the circle's centre at (1, 0, 0).
        let k = 0.552_284_8;
        let p = [
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, k),
            Vec3::new(1.0 - k, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
        ];
        let centre = Vec3::new(1.0, 0.0, 0.0);
        let t = 0.4;
        let moved = strip_centre(&p, t, 5).distance(centre) - bezier(&p, t).distance(centre);
        let sag = 1.0 - (std::f32::consts::FRAC_PI_2 / 5.0 / 2.0).cos();
        assert!(
            (moved - 0.75 * sag).abs() < 0.15 * sag,
            "moved out by {moved}, 3/4 of the sag is {}",
            0.75 * sag
        );
    }
}
