//! Procedural plant meshes: flowers, ferns, broadleaf bushes and trees (a broadleaf and a
//! conifer, `trees`), with Crysis' bending channels
//! (GPU Gems 3, ch. 16) painted into their vertices, at two levels of detail plus a far card.
//!
//! Every random choice of a leaf, frond or branch is drawn from a stream of its own (keyed by the
//! seed and the element's number), so both levels of detail describe the same plant: the reduced
//! one keeps every third leaf, enlarged to cover about the same area, and coarser stems.

use std::f32::consts::{PI, TAU};

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::card::{crossed_cards, render_card};
use super::mesh::{PlantImage, PlantMesh};

mod shapes;
mod trees;

use shapes::{Builder, Leaf, Rng, THIN, WOODY, azimuth, lerp, rgba, tint};

/// Side of the card image that [`generate`] renders, pixels.
pub const CARD_SIZE: u32 = 128;

/// The kinds of plant the generator makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Recipe {
    /// A thin stem with 2-4 leaves and a head of 5-8 petals around a centre.
    Flower,
    /// 5-9 fronds arching out from the root, leaflets tapering toward their tips.
    Fern,
    /// Forking branches with leaves clustered toward their ends, about as wide as high.
    Bush,
    /// A broadleaf tree: a trunk forking into limbs, a broad crown of leaf clusters.
    Broadleaf,
    /// A conifer: a trunk to the top, whorls of drooping branches in a cone, sprays of needles.
    Conifer,
}

impl Recipe {
    /// Every recipe, in a fixed order.
    pub const ALL: [Recipe; 5] = [
        Recipe::Flower,
        Recipe::Fern,
        Recipe::Bush,
        Recipe::Broadleaf,
        Recipe::Conifer,
    ];

    /// The recipe's name, as serde writes it ("flower", "fern", "bush", "broadleaf",
    /// "conifer").
    pub fn name(self) -> &'static str {
        match self {
            Recipe::Flower => "flower",
            Recipe::Fern => "fern",
            Recipe::Bush => "bush",
            Recipe::Broadleaf => "broadleaf",
            Recipe::Conifer => "conifer",
        }
    }

    /// The recipe named `name`, if any.
    pub fn from_name(name: &str) -> Option<Recipe> {
        Recipe::ALL.into_iter().find(|r| r.name() == name)
    }

    /// Whether the recipe is a tree (drawn at a tree's size: metres, not decimetres).
    pub fn is_tree(self) -> bool {
        matches!(self, Recipe::Broadleaf | Recipe::Conifer)
    }
}

/// One plant at every level of detail.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantLods {
    /// The full mesh, then a reduced one (about a third of the leaves, the same silhouette size).
    pub lods: [PlantMesh; 2],
    /// The far level: two crossed vertical quads (see [`crossed_cards`]).
    pub card: PlantMesh,
    /// The card's picture, [`CARD_SIZE`] square, rendered from `lods[0]` (see [`render_card`]).
    pub card_image: PlantImage,
}

/// Generates a plant of `recipe`, the same for the same `seed`. The meshes are of unit scale:
/// root at the origin, z up, about 1 m high (a bush 0.7-0.95 m, and about as wide).
///
/// `colour` is the recipe's accent in linear RGB: the petals of a flower, the leaves of a fern or
/// bush (the stems' colour is the recipe's own). Channels are clamped to 0..=1, a non-finite one
/// reads as 0.
///
/// Triangle budgets of `lods[0]`: a flower at most 300, a fern 600, a bush 900, a broadleaf tree
/// 3000, a conifer 2000; of the reduced `lods[1]`, drawn from a few tens of metres to the view
/// distance where most plants are: a flower 24, a fern 80, a bush 140, a broadleaf 450, a
/// conifer 120.
pub fn generate(recipe: Recipe, seed: u32, colour: [f32; 3]) -> PlantLods {
    let [(l0, _), (l1, _)] = build(recipe, seed, colour);
    PlantLods {
        card: crossed_cards(&l0),
        card_image: render_card(&l0, CARD_SIZE),
        lods: [l0, l1],
    }
}

/// What a run of vertices is, for the tests' checks per leaf.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// A leaf, leaflet or bush leaf.
    Leaf,
    /// A flower's petal.
    Petal,
    /// A stem, rachis or branch.
    Stem,
    /// A flower's centre.
    Centre,
}

/// One leaf, petal, stem or centre: its kind and its vertices `first..end`.
// Read by the tests only: the checks that hold per leaf.
#[cfg_attr(not(test), allow(dead_code))]
#[derive(Clone, Copy, Debug)]
struct Part {
    kind: Kind,
    first: usize,
    end: usize,
}

/// Both levels of detail, with their parts, scaled to the recipe's height and with AO baked.
fn build(recipe: Recipe, seed: u32, colour: [f32; 3]) -> [(PlantMesh, Vec<Part>); 2] {
    let colour = colour.map(|c| {
        if c.is_finite() {
            c.clamp(0.0, 1.0)
        } else {
            0.0
        }
    });
    let rng = Rng::new(seed, recipe as u32);
    let mut out = [0, 1].map(|lod| {
        let mut b = Builder::default();
        match recipe {
            Recipe::Flower => flower(&rng, colour, lod, &mut b),
            Recipe::Fern => fern(&rng, colour, lod, &mut b),
            Recipe::Bush => bush(&rng, colour, lod, &mut b),
            Recipe::Broadleaf => trees::broadleaf(&rng, colour, lod, &mut b),
            Recipe::Conifer => trees::conifer(&rng, colour, lod, &mut b),
        }
        (b.mesh, b.parts)
    });
    let (lo, hi) = match recipe {
        Recipe::Flower => (0.9, 1.05),
        Recipe::Fern => (0.85, 1.0),
        Recipe::Bush => (0.7, 0.95),
        Recipe::Broadleaf | Recipe::Conifer => (0.95, 1.05),
    };
    let target = rng.fork(u32::MAX).range(lo, hi);
    // One factor for both levels, so that they keep the same size.
    let scale = target / out[0].0.height().max(1e-3);
    let (height, radius) = (out[0].0.height() * scale, out[0].0.radius() * scale);
    for (mesh, _) in &mut out {
        for v in &mut mesh.vertices {
            v.position = v.position.map(|p| p * scale);
            v.wind[3] = ao(recipe, Vec3::from(v.position), height, radius);
        }
    }
    out
}

/// Baked ambient occlusion: 0.35 at the root (and, in a bush, at its core) rising to 1 outside.
fn ao(recipe: Recipe, p: Vec3, height: f32, radius: f32) -> f32 {
    let z = p.z / height.max(1e-3);
    let r = p.truncate().length() / radius.max(1e-3);
    let open = match recipe {
        // Distance from the crown's core, an ellipsoid low in the bush; the ground shades too.
        Recipe::Bush => {
            let d = Vec3::new(r, 0.0, (z - 0.35) / 0.65).length();
            smoothstep(0.15, 0.9, d) * smoothstep(-0.05, 0.35, z)
        }
        // Distance from the crown's core, an ellipsoid about the forks and above them.
        Recipe::Broadleaf => {
            // The trunk stands in the crown's shade.
            let d = Vec3::new(r, 0.0, (z - 0.62) / 0.4).length();
            smoothstep(0.2, 0.95, d) * smoothstep(-0.05, 0.5, z)
        }
        // Toward the trunk inside the cone, and the top open to the sky.
        Recipe::Conifer => {
            let cone = 0.36 * (1.0 - z) + 0.03;
            let p = p.truncate().length() / (cone * radius / 0.36).max(1e-3);
            smoothstep(0.0, 0.9, p).max(smoothstep(0.75, 1.0, z)) * smoothstep(-0.05, 0.25, z)
        }
        Recipe::Flower | Recipe::Fern => smoothstep(0.0, 0.55, z.max(0.8 * r)),
    };
    0.35 + 0.65 * open
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn flower(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    let green = [0.07, 0.2, 0.035];
    let lean_dir = azimuth(r.range(0.0, TAU));
    let lean = r.range(0.03, 0.14);
    let head_z = r.range(0.78, 0.9);
    let stem = |t: f32| lean_dir * (lean * t * t) + Vec3::Z * (head_z * t);
    let segs = if full { 5 } else { 1 };
    let path: Vec<Vec3> = (0..=segs).map(|i| stem(i as f32 / segs as f32)).collect();
    let stem_b = 0.3;
    b.tube(
        &path,
        [0.008, 0.005],
        if full { 6 } else { 3 },
        rgba(green, WOODY),
        r.f(),
        [0.0, stem_b],
    );

    let leaves = r.count(2, 4);
    let leaf_az = r.range(0.0, TAU);
    for i in 0..leaves {
        let mut lr = rng.fork(10 + i);
        let t = 0.12 + 0.45 * (i as f32 + lr.range(0.0, 0.6)) / leaves as f32;
        let (length, width) = (lr.range(0.18, 0.28), lr.range(0.05, 0.08));
        let el = lr.range(0.5, 1.0);
        let az = leaf_az + 2.4 * i as f32 + lr.range(-0.3, 0.3);
        let leaf = Leaf {
            base: stem(t) + azimuth(az) * 0.008,
            dir: azimuth(az) * el.cos() + Vec3::Z * el.sin(),
            up: Vec3::Z,
            length,
            width,
            droop: lr.range(0.6, 1.1),
            cup: 0.3,
            widest: 0.4,
            segments: 3,
            albedo: rgba(tint([0.08, 0.26, 0.04], lr.range(0.85, 1.15)), THIN),
            phase: lr.f(),
            b: [stem_b * t, 0.9],
        };
        if full {
            b.leaf(&leaf, Kind::Leaf);
        } else if i == 0 {
            b.leaf(
                &Leaf {
                    length: length * 1.15,
                    width: width * 1.5,
                    segments: 1,
                    ..leaf
                },
                Kind::Leaf,
            );
        }
    }

    // The head faces half sideways (40-65 degrees from the vertical, along the stem's lean), as
    // meadow flowers turn to the light: seen from standing height a head facing straight up
    // would be edge-on, a line of a pixel or two.
    let head = stem(1.0);
    let tilt = r.range(40f32.to_radians(), 65f32.to_radians());
    let along = {
        let d = (stem(1.0) - stem(0.95)).truncate();
        if d.length() > 1e-4 {
            d.normalize()
        } else {
            glam::Vec2::X
        }
    };
    let axis = (along.extend(0.0) * tilt.sin() + Vec3::Z * tilt.cos()).normalize();
    let (hu, hv) = axis.any_orthonormal_pair();
    let petals = r.count(5, 8);
    let petal_len = r.range(0.14, 0.2);
    let petal_width = petal_len * r.range(0.45, 0.65);
    // The reduced head has five petals at most, widened to fill the same ring, and a third
    // wider again: its single-quad petals lose the full ones' cupped, overlapping spread (seen
    // from above the reduced head covered 0.6-0.8 of the full one's area without it).
    let shown = if full { petals } else { petals.min(5) };
    let petal_width = petal_width * petals as f32 / shown as f32 * if full { 1.0 } else { 1.35 };
    let opening = r.range(0.25, 0.6);
    let spin = r.range(0.0, TAU);
    for p in 0..shown {
        let mut pr = rng.fork(100 + p);
        let a = spin + TAU * p as f32 / shown as f32 + pr.range(-0.15, 0.15);
        let radial = hu * a.cos() + hv * a.sin();
        let el = opening + pr.range(-0.1, 0.1);
        let petal = Leaf {
            base: head + radial * 0.012 + axis * 0.004,
            dir: radial * el.cos() + axis * el.sin(),
            up: axis,
            length: petal_len * pr.range(0.9, 1.1),
            width: petal_width,
            droop: pr.range(0.2, 0.5),
            cup: 0.35,
            widest: 0.6,
            segments: if full { 4 } else { 1 },
            albedo: rgba(tint(colour, pr.range(0.9, 1.1)), THIN),
            phase: pr.f(),
            b: [stem_b, 1.0],
        };
        // The reduced head keeps a whole ring of petals (a third of a head would not read as a
        // flower), each a folded quad.
        b.leaf(&petal, Kind::Petal);
    }
    let centre = rgba([0.45, 0.28, 0.03], 0.3);
    let (centre_phase, centre_radius) = (r.f(), petal_len * 0.22);
    // The centre is a pixel or less where the reduced mesh is drawn.
    if full {
        b.centre(
            head + axis * 0.006,
            axis,
            centre_radius,
            6,
            centre,
            centre_phase,
            stem_b,
        );
    }
}

fn fern(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    let fronds = r.count(5, 9);
    let az0 = r.range(0.0, TAU);
    let rachis_colour = tint(
        [
            colour[0] * 0.5 + 0.06,
            colour[1] * 0.5 + 0.04,
            colour[2] * 0.5,
        ],
        1.0,
    );
    for k in 0..fronds {
        let mut fr = rng.fork(1 + k);
        let az = az0 + TAU * k as f32 / fronds as f32 + fr.range(-0.25, 0.25);
        let (e0, e1) = (fr.range(1.3, 1.5), fr.range(-0.15, 0.15));
        let len = fr.range(0.9, 1.15);
        let (out, side) = (azimuth(az), azimuth(az + PI / 2.0));
        // The rachis arches: its elevation falls from e0 at the root to e1 at the tip.
        let dir = |t: f32| {
            let e = lerp(e0, e1, t.powf(1.6));
            out * e.cos() + Vec3::Z * e.sin()
        };
        const STEPS: usize = 32;
        let mut curve = vec![Vec3::ZERO; STEPS + 1];
        for i in 0..STEPS {
            curve[i + 1] = curve[i] + dir((i as f32 + 0.5) / STEPS as f32) * (len / STEPS as f32);
        }
        let at = |t: f32| {
            let x = t.clamp(0.0, 1.0) * STEPS as f32;
            let i = (x as usize).min(STEPS - 1);
            curve[i].lerp(curve[i + 1], x - i as f32)
        };
        let up = |t: f32| dir(t).cross(side);
        if !full {
            // The reduced frond: one arching blade, narrower than its leaflets' reach (their
            // gaps leave most of it open: at the full reach the reduced fern covered about twice
            // the full one's area).
            let frond = Leaf {
                base: Vec3::ZERO,
                dir: dir(0.0),
                up: up(0.0),
                length: len,
                width: len * 0.12,
                droop: 0.7 * (e0 - e1),
                cup: 0.1,
                widest: 0.35,
                segments: 3,
                albedo: rgba(tint(colour, fr.range(0.85, 1.1)), THIN),
                phase: fr.f(),
                b: [0.0, 1.0],
            };
            b.leaf(&frond, Kind::Leaf);
            continue;
        }

        // The rachis: a flat ribbon facing up, tapering.
        let first = b.mesh.vertices.len();
        let segs = if full { 4 } else { 2 };
        let phase = fr.f();
        let mut ribbon = Vec::new();
        for i in 0..=segs {
            let t = i as f32 / segs as f32;
            let half = 0.007 * (1.0 - 0.7 * t);
            for s in [-1.0, 1.0] {
                let wind = [0.0, phase, t, 1.0];
                ribbon.push(b.push(
                    at(t) + side * (s * half),
                    up(t),
                    wind,
                    rgba(rachis_colour, WOODY),
                    [0.5 + 0.5 * s, 1.0 - t],
                ));
            }
        }
        for i in 0..segs as usize {
            let t = (i as f32 + 0.5) / segs as f32;
            let q = &ribbon[2 * i..2 * i + 4];
            b.tri([q[0], q[1], q[3]], up(t));
            b.tri([q[0], q[3], q[2]], up(t));
        }
        b.part(Kind::Stem, first);

        // As many pairs as the budget of 600 triangles allows (a ribbon of 8, two per leaflet).
        let pairs = fr.count(11, 14).min((590 / fronds - 8) / 4);
        let longest = len * fr.range(0.17, 0.22);
        let leaf_colour = tint(colour, fr.range(0.85, 1.1));
        for j in 0..pairs {
            let t = 0.12 + 0.85 * (j as f32 + 0.5) / pairs as f32;
            // Longest about a third of the way out, tapering to the tip.
            let taper = (1.0 - t).powf(0.6) * (0.45 + 1.8 * t).min(1.0);
            for (n, s) in [(0, -1.0f32), (1, 1.0)] {
                let mut lr = fr.fork(2 * j + n);
                let toward_tip = lr.range(0.35, 0.6);
                let leaflet = Leaf {
                    base: at(t),
                    dir: side * (s * toward_tip.cos()) + dir(t) * toward_tip.sin(),
                    up: up(t),
                    length: longest * taper * lr.range(0.9, 1.1),
                    width: longest * taper * 0.38,
                    droop: lr.range(0.15, 0.45),
                    cup: 0.2,
                    widest: 0.35,
                    segments: 1,
                    albedo: rgba(tint(leaf_colour, lr.range(0.92, 1.08)), THIN),
                    phase: lr.f(),
                    b: [t, (t + 0.2).min(1.0)],
                };
                if full {
                    b.leaf(&leaflet, Kind::Leaf);
                } else if j % 3 == 1 {
                    let grown = Leaf {
                        length: leaflet.length * 1.6,
                        width: leaflet.width * 2.0,
                        ..leaflet
                    };
                    b.leaf(&grown, Kind::Leaf);
                }
            }
        }
    }
}

fn bush(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let mut r = rng.fork(0);
    let count = r.count(4, 6);
    let az0 = r.range(0.0, TAU);
    // Forks per branch first: the leaves per twig share out a fixed total.
    let forks: Vec<u32> = (0..count).map(|k| rng.fork(1 + k).count(1, 2)).collect();
    let twigs: u32 = forks.iter().map(|&f| 1 << f).sum();
    let per_twig = (250 / twigs).clamp(8, 24);
    for k in 0..count {
        let mut br = rng.fork(1 + k);
        br.count(1, 2); // the fork count drawn above
        let az = az0 + TAU * k as f32 / count as f32 + br.range(-0.3, 0.3);
        let el = br.range(0.95, 1.3);
        let spec = Branch {
            start: azimuth(az) * 0.02,
            dir: azimuth(az) * el.cos() + Vec3::Z * el.sin(),
            len: br.range(0.3, 0.4),
            radius: 0.022,
            level: 0,
            forks: forks[k as usize],
            b: 0.0,
            leaf_len: [0.12, 0.17],
        };
        branch(b, &br.fork(7), &spec, colour, per_twig, lod);
    }
}

struct Branch {
    start: Vec3,
    dir: Vec3,
    len: f32,
    radius: f32,
    level: u32,
    forks: u32,
    /// Bending freedom at the start.
    b: f32,
    /// The leaves' length range.
    leaf_len: [f32; 2],
}

fn branch(b: &mut Builder, rng: &Rng, br: &Branch, colour: [f32; 3], per_twig: u32, lod: usize) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    // Branches bow up a little; the twigs toward the light.
    let bow = Vec3::Z * (br.len * r.range(0.04, 0.1));
    let at = |t: f32| br.start + br.dir * (br.len * t) + bow * (4.0 * t * (1.0 - t));
    let end_b = br.b + (1.0 - br.b) * 0.45;
    let terminal = br.level >= br.forks;
    let segs = if full && br.level == 0 { 2 } else { 1 };
    let bark = rgba(tint([0.1, 0.065, 0.035], r.range(0.85, 1.15)), WOODY);
    let phase = r.f();
    // The reduced level keeps the boughs only (the rest is inside the leaves).
    if full || br.level == 0 {
        let path: Vec<Vec3> = (0..=segs).map(|i| at(i as f32 / segs as f32)).collect();
        b.tube(
            &path,
            [br.radius, br.radius * 0.7],
            3,
            bark,
            phase,
            [br.b, end_b],
        );
    }
    if !terminal {
        let spread = r.range(0.35, 0.7);
        let (u, _) = br.dir.any_orthonormal_pair();
        let turn = r.range(0.0, TAU);
        for (n, s) in [(1, 1.0f32), (2, -1.0)] {
            // Two children splayed apart about a random axis across the parent.
            let across = glam::Quat::from_axis_angle(br.dir, turn) * u;
            let dir = glam::Quat::from_axis_angle(across, s * spread) * br.dir;
            let dir = (dir + Vec3::Z * 0.15).normalize();
            let child = Branch {
                start: at(1.0),
                dir,
                len: br.len * r.range(0.55, 0.7),
                radius: br.radius * 0.6,
                level: br.level + 1,
                forks: br.forks,
                b: end_b,
                leaf_len: br.leaf_len,
            };
            branch(b, &rng.fork(n), &child, colour, per_twig, lod);
        }
    }
    // Leaves clustered toward the twigs' ends, a few along the outer part of the boughs.
    let (leaves, from) = if terminal {
        (per_twig, 0.2)
    } else {
        (per_twig / 3, 0.4)
    };
    let out = Vec3::new(br.dir.x, br.dir.y, 0.0).normalize_or(Vec3::X);
    for i in 0..leaves {
        let mut lr = rng.fork(100 + i);
        let u = (i as f32 + lr.f()) / leaves as f32;
        let t = 1.0 - (1.0 - u).powi(2) * (1.0 - from);
        let dir = (br.dir * 0.5 + lr.dir() * 0.9 + out * 0.3 + Vec3::Z * 0.2).normalize_or(br.dir);
        let length = lr.range(br.leaf_len[0], br.leaf_len[1]);
        let leaf = Leaf {
            base: at(t),
            dir,
            up: (Vec3::Z + lr.dir() * 0.6).normalize_or(Vec3::Z),
            length,
            width: length * lr.range(0.55, 0.7),
            droop: lr.range(0.1, 0.35),
            cup: 0.25,
            widest: 0.45,
            segments: 1,
            albedo: rgba(
                tint(
                    [colour[0] * lr.range(0.9, 1.25), colour[1], colour[2]],
                    lr.range(0.8, 1.15),
                ),
                THIN,
            ),
            phase: lr.f(),
            b: [lerp(br.b, end_b, t), 1.0],
        };
        if full {
            b.leaf(&leaf, Kind::Leaf);
        } else if i % 8 == 0 {
            // One leaf in eight, grown (more across than along, to keep the crown's outline) to
            // keep about its cover (wider, the crowns covered up to 1.5 times the full ones' area
            // from above).
            b.leaf(
                &Leaf {
                    length: length * 1.7,
                    width: leaf.width * 2.3,
                    ..leaf
                },
                Kind::Leaf,
            );
        }
    }
}

#[cfg(test)]
mod tests;
