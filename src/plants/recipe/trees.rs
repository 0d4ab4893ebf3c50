//! Trees: a broadleaf (a short trunk forking into limbs that fork twice more, leaf clusters at
//! the twigs) and a conifer (a trunk to the top with whorls of drooping branches shortening
//! upward, sprays of needles along them), with Crysis' bending channels: the trunk stiff
//! (`b` 0 at the root), each branch freer toward its tip, each leaf or spray with a phase of its
//! own and edges that flutter.
//!
//! A tree is generated at unit height like every recipe; the world's `size_m` makes it a tree.
//! Its leaves are clusters: a quad folded along its midrib stands for a spray of leaves or
//! needles a metre or so long on a tree of 12 m.

use std::f32::consts::TAU;

use glam::Vec3;

use super::shapes::{Builder, Leaf, Rng, THIN, WOODY, azimuth, lerp, rgba, tint};
use super::{Branch, Kind, branch};

/// The colour of bark.
const BARK: [f32; 3] = [0.09, 0.065, 0.045];

/// A broadleaf tree: a trunk to about a third of the height, 5-7 limbs from its top that fork
/// twice, about 1300 leaf clusters toward the twigs' ends (the reduced level: the trunk,
/// the limbs and one cluster in eight, grown).
pub(super) fn broadleaf(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    let lean_dir = azimuth(r.range(0.0, TAU));
    let lean = r.range(0.0, 0.05);
    let fork_z = r.range(0.3, 0.4);
    let trunk = |t: f32| lean_dir * (lean * t * t) + Vec3::Z * (fork_z * t);
    let segs = if full { 4 } else { 2 };
    let path: Vec<Vec3> = (0..=segs).map(|i| trunk(i as f32 / segs as f32)).collect();
    let bark = rgba(tint(BARK, r.range(0.85, 1.15)), WOODY);
    b.tube(
        &path,
        [0.045, 0.032],
        if full { 7 } else { 4 },
        bark,
        r.f(),
        [0.0, 0.04],
    );
    let limbs = r.count(5, 7);
    let az0 = r.range(0.0, TAU);
    // Two forks a limb: four twigs with a share of leaves each, and the limb and its two
    // branches a third of a share each: about 1300 clusters in all.
    let per_twig = 1300 / (5 * limbs);
    for k in 0..limbs {
        let mut lr = rng.fork(1 + k);
        let az = az0 + TAU * k as f32 / limbs as f32 + lr.range(-0.3, 0.3);
        // Steeper limbs in the middle of the crown, wider ones low.
        let el = lr.range(0.4, 0.9);
        let start = trunk(lr.range(0.78, 1.0));
        let spec = Branch {
            start,
            dir: azimuth(az) * el.cos() + Vec3::Z * el.sin(),
            len: lr.range(0.34, 0.42),
            radius: 0.026,
            level: 0,
            forks: 2,
            b: 0.06,
            leaf_len: [0.1, 0.14],
        };
        branch(b, &lr.fork(7), &spec, colour, per_twig.max(8), lod);
    }
}

/// A conifer: a trunk to the top, 13-16 whorls of 4-5 branches from a sixth of the height up,
/// the lowest reaching about a third of the height out and each higher one shorter (a cone),
/// drooping a little; along each branch sprays of needles (the reduced level: the trunk and
/// three broad sprays a whorl).
pub(super) fn conifer(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    let lean_dir = azimuth(r.range(0.0, TAU));
    let lean = r.range(0.0, 0.025);
    let trunk = |t: f32| lean_dir * (lean * t * t) + Vec3::Z * t;
    let segs = if full { 6 } else { 2 };
    let path: Vec<Vec3> = (0..=segs).map(|i| trunk(i as f32 / segs as f32)).collect();
    let bark = rgba(tint(BARK, r.range(0.8, 1.1)), WOODY);
    b.tube(
        &path,
        [0.022, 0.003],
        if full { 6 } else { 3 },
        bark,
        r.f(),
        [0.0, 0.3],
    );
    let whorls = r.count(13, 16);
    let spread = r.range(0.3, 0.36);
    for w in 0..whorls {
        let mut wr = rng.fork(1 + w);
        let t = 0.16 + 0.8 * (w as f32 + wr.range(0.0, 0.5)) / whorls as f32;
        let reach = spread * (1.0 - t).powf(0.9) + 0.03;
        let count = wr.count(4, 5);
        let az0 = wr.range(0.0, TAU);
        // The branches of a high whorl are thinner and freer.
        let b0 = 0.1 + 0.3 * t;
        let b1 = 0.45 + 0.55 * t;
        for k in 0..count {
            let mut br = wr.fork(1 + k);
            let az = az0 + TAU * k as f32 / count as f32 + br.range(-0.35, 0.35);
            let out = azimuth(az);
            let el = br.range(-0.25, 0.05);
            let len = reach * br.range(0.85, 1.1);
            let start = trunk(t);
            // The branch sags toward its tip.
            let at = |s: f32| {
                start + (out * el.cos() + Vec3::Z * el.sin()) * (len * s)
                    - Vec3::Z * (0.12 * len * s * s)
            };
            let phase = br.f();
            if full {
                b.tube(
                    &[at(0.0), at(0.5), at(1.0)],
                    [0.004 + 0.01 * reach, 0.0015],
                    3,
                    bark,
                    phase,
                    [b0, b1],
                );
            }
            let needles = rgba(
                tint(
                    [colour[0], colour[1] * br.range(0.9, 1.1), colour[2]],
                    br.range(0.8, 1.15),
                ),
                THIN,
            );
            let side = out.cross(Vec3::Z);
            let sprays: &[(f32, f32)] = if full {
                &[
                    (0.05, 0.0),
                    (0.3, 1.0),
                    (0.3, -1.0),
                    (0.6, 1.0),
                    (0.6, -1.0),
                ]
            } else if k % 2 == 0 {
                &[(0.0, 0.0)]
            } else {
                &[]
            };
            for (i, &(s, turn)) in sprays.iter().enumerate() {
                let mut sr = br.fork(10 + i as u32);
                let dir = (at((s + 0.3).min(1.0)) - at(s)).normalize_or(out) + side * (0.5 * turn);
                let (length, width) = if full {
                    (len * sr.range(0.42, 0.5), len * sr.range(0.4, 0.5))
                } else {
                    // One spray for a whorl's five, as wide as their fan (narrower, the reduced
                    // fir covered 0.6-0.75 of the full one's area).
                    (len * 1.05, len * 1.3)
                };
                b.leaf(
                    &Leaf {
                        base: at(s),
                        dir: dir.normalize_or(out),
                        up: (Vec3::Z + sr.dir() * 0.3).normalize_or(Vec3::Z),
                        length,
                        width,
                        droop: sr.range(0.15, 0.35),
                        cup: -0.15,
                        widest: 0.4,
                        segments: 1,
                        albedo: needles,
                        phase: sr.f(),
                        b: [lerp(b0, b1, s), b1],
                    },
                    Kind::Leaf,
                );
            }
        }
    }
}
