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
    /// Fade factor 0 to 1 (blades leaving at a LOD switch shrink away).
    pub fade: f32,
}
const _: () = assert!(std::mem::size_of::<Blade>() == 64);

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
    let side = up.cross(forward).normalize_or_zero();
    let fwd = side.cross(up).normalize_or_zero();
    let dir = |angle: f32| up * angle.cos() + fwd * angle.sin();
    let tip_angle = tilt + bend * 1.2;
    let p3 = dir(tilt) * height;
    let p1 = up * (height / 3.0) + side * (side_curve * 0.15 * height);
    let p2 = p3 - dir(tip_angle) * (height / 3.0) + side * (side_curve * 0.15 * height);
    let p = [Vec3::ZERO, p1, p2, p3];
    let scale = height / bezier_length_estimate(&p).max(1e-6);
    p.map(|q| q * scale)
}

fn lerp(a: Vec3, b: Vec3) -> Vec3 {
    (a + b) * 0.5
}

/// Length of a cubic Bezier: split at the middle, and for each half average the chord and the
/// control polygon.
pub fn bezier_length_estimate(p: &[Vec3; 4]) -> f32 {
    let (p01, p12, p23) = (lerp(p[0], p[1]), lerp(p[1], p[2]), lerp(p[2], p[3]));
    let (a, b) = (lerp(p01, p12), lerp(p12, p23));
    let m = lerp(a, b);
    let half = |q0: Vec3, q1: Vec3, q2: Vec3, q3: Vec3| {
        0.5 * (q0.distance(q3) + q0.distance(q1) + q1.distance(q2) + q2.distance(q3))
    };
    half(p[0], p01, a, m) + half(m, b, p23, p[3])
}

/// A point on the cubic Bezier at `t`.
pub fn bezier(p: &[Vec3; 4], t: f32) -> Vec3 {
    let u = 1.0 - t;
    p[0] * (u * u * u) + p[1] * (3.0 * u * u * t) + p[2] * (3.0 * u * t * t) + p[3] * (t * t * t)
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
    fn an_upright_blade_rises_along_its_growth_direction() {
        let up = Vec3::new(0.0, 0.3, 1.0).normalize();
        let p = blade_curve(up, Vec3::X, 0.5, 0.0, 0.0, 0.0);
        assert!((p[3] - up * 0.5).length() < 1e-5);
    }
}
