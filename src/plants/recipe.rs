//! Procedural plant meshes: flowers, ferns and broadleaf bushes, with Crysis' bending channels
//! (GPU Gems 3, ch. 16) painted into their vertices, at two levels of detail plus a far card.
//!
//! Every random choice of a leaf, frond or branch is drawn from a stream of its own (keyed by the
//! seed and the element's number), so both levels of detail describe the same plant: the reduced
//! one keeps every third leaf, enlarged to cover about the same area, and coarser stems.

use std::f32::consts::{PI, TAU};

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::card::{crossed_cards, render_card};
use super::mesh::{PlantImage, PlantMesh, PlantVertex};
use crate::hash::{hash_u32, hash3, rand01};

/// Side of the card image that [`generate`] renders, pixels.
pub const CARD_SIZE: u32 = 128;

/// The kinds of plant the generator makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Recipe {
    /// A thin stem with a few leaves and a head of 5-8 petals; about 1 m before scaling.
    Flower,
    /// 5-9 fronds arching out from the root, leaflets tapering toward their tips.
    Fern,
    /// Forking branches with leaves clustered toward their ends, about as wide as high.
    Bush,
}

impl Recipe {
    /// Every recipe, in a fixed order.
    pub const ALL: [Recipe; 3] = [Recipe::Flower, Recipe::Fern, Recipe::Bush];

    /// The recipe's name, as written in settings files ("flower", "fern", "bush").
    pub fn name(self) -> &'static str {
        match self {
            Recipe::Flower => "flower",
            Recipe::Fern => "fern",
            Recipe::Bush => "bush",
        }
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
/// Triangle budgets of `lods[0]`: a flower at most 300, a fern 600, a bush 900; `lods[1]` has
/// about a third of those.
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
    let colour = colour.map(|c| if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 });
    let rng = Rng::new(seed, recipe as u32);
    let mut out = [0, 1].map(|lod| {
        let mut b = Builder::default();
        match recipe {
            Recipe::Flower => flower(&rng, colour, lod, &mut b),
            Recipe::Fern => fern(&rng, colour, lod, &mut b),
            Recipe::Bush => bush(&rng, colour, lod, &mut b),
        }
        (b.mesh, b.parts)
    });
    let (lo, hi) = match recipe {
        Recipe::Flower => (0.9, 1.05),
        Recipe::Fern => (0.85, 1.0),
        Recipe::Bush => (0.7, 0.95),
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
        Recipe::Flower | Recipe::Fern => smoothstep(0.0, 0.55, z.max(0.8 * r)),
    };
    0.35 + 0.65 * open
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// `c` scaled by `k`, kept in 0..=1.
fn tint(c: [f32; 3], k: f32) -> [f32; 3] {
    c.map(|x| (x * k).clamp(0.0, 1.0))
}

fn rgba(c: [f32; 3], a: f32) -> [f32; 4] {
    [c[0], c[1], c[2], a]
}

/// Thinness (`albedo.a`) of leaves and petals, and of stems and branches.
const THIN: f32 = 0.9;
const WOODY: f32 = 0.1;

/// A stream of random numbers from the project's hash.
#[derive(Clone, Copy)]
struct Rng {
    key: u32,
    n: u32,
}

impl Rng {
    fn new(seed: u32, salt: u32) -> Self {
        Rng { key: hash3(seed, salt, 0x9e37_79b9), n: 0 }
    }

    /// An independent stream for element `i`, untouched by what is drawn from others.
    fn fork(&self, i: u32) -> Rng {
        Rng { key: hash3(self.key, i, 0x85eb_ca6b), n: 0 }
    }

    /// In [0, 1).
    fn f(&mut self) -> f32 {
        self.n += 1;
        rand01(hash_u32(self.key ^ hash_u32(self.n)))
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lerp(lo, hi, self.f())
    }

    /// An integer in `lo..=hi`.
    fn count(&mut self, lo: u32, hi: u32) -> u32 {
        (lo + (self.f() * (hi - lo + 1) as f32) as u32).min(hi)
    }

    /// A direction, uniform on the sphere.
    fn dir(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let a = self.range(0.0, TAU);
        let r = (1.0 - z * z).sqrt();
        Vec3::new(r * a.cos(), r * a.sin(), z)
    }
}

/// The unit horizontal vector at azimuth `a`.
fn azimuth(a: f32) -> Vec3 {
    Vec3::new(a.cos(), a.sin(), 0.0)
}

/// A leaf (or petal, or leaflet): a midrib curving down by `droop` radians from base to tip, and
/// edges cupped up by `cup` times the half width.
struct Leaf {
    base: Vec3,
    dir: Vec3,
    /// Roughly the front's normal; made perpendicular to `dir`.
    up: Vec3,
    length: f32,
    width: f32,
    droop: f32,
    cup: f32,
    /// Where along the midrib (0..1) the leaf is widest.
    widest: f32,
    /// Midrib segments; 1 makes a quad of two triangles folded along the midrib.
    segments: u32,
    albedo: [f32; 4],
    phase: f32,
    /// The bending freedom `wind.b` at the base and at the tip.
    b: [f32; 2],
}

#[derive(Default)]
struct Builder {
    mesh: PlantMesh,
    parts: Vec<Part>,
}

impl Builder {
    fn push(&mut self, position: Vec3, normal: Vec3, wind: [f32; 4], albedo: [f32; 4], uv: [f32; 2]) -> u32 {
        self.mesh.vertices.push(PlantVertex {
            position: position.into(),
            normal: normal.into(),
            wind,
            albedo,
            uv,
        });
        (self.mesh.vertices.len() - 1) as u32
    }

    /// A triangle, wound counter-clockwise seen from the side `front` points to.
    fn tri(&mut self, [a, b, c]: [u32; 3], front: Vec3) {
        let p = |i: u32| Vec3::from(self.mesh.vertices[i as usize].position);
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        let t = if face.dot(front) < 0.0 { [a, c, b] } else { [a, b, c] };
        self.mesh.indices.extend_from_slice(&t);
    }

    fn part(&mut self, kind: Kind, first: usize) {
        let end = self.mesh.vertices.len();
        self.parts.push(Part { kind, first, end });
    }

    fn leaf(&mut self, l: &Leaf, kind: Kind) {
        let first = self.mesh.vertices.len();
        let first_index = self.mesh.indices.len();
        let d0 = l.dir.normalize();
        let s = d0.cross(l.up).try_normalize().unwrap_or_else(|| d0.any_orthonormal_vector());
        let n0 = s.cross(d0);
        // Rotating the midrib's direction about `s` toward -n0 as it goes.
        let normal = |t: f32| {
            let a = l.droop * t;
            n0 * a.cos() + d0 * a.sin()
        };
        let midrib = |t: f32| {
            let a = l.droop * t;
            let (along, down) = if l.droop.abs() < 1e-4 {
                (t, 0.0)
            } else {
                (a.sin() / l.droop, (a.cos() - 1.0) / l.droop)
            };
            l.base + (d0 * along + n0 * down) * l.length
        };
        let k = 0.5f32.ln() / l.widest.clamp(0.05, 0.95).ln();
        let width = |t: f32| l.width * (PI * t.powf(k)).sin().max(0.0);
        let mut ts = Vec::new();
        let mut vert = |this: &mut Self, t: f32, side: f32| {
            let half = width(t) * 0.5;
            let p = midrib(t) + s * (side * half) + normal(t) * (l.cup * half * side.abs());
            let wind = [side.abs(), l.phase, lerp(l.b[0], l.b[1], t), 1.0];
            ts.push(t);
            this.push(p, normal(t), wind, l.albedo, [0.5 + 0.5 * side, 1.0 - t])
        };
        let mut tris = Vec::new();
        if l.segments <= 1 {
            let (m0, m1) = (vert(self, 0.0, 0.0), vert(self, 1.0, 0.0));
            for side in [-1.0, 1.0] {
                tris.push([m0, m1, vert(self, l.widest, side)]);
            }
        } else {
            let n = l.segments;
            let m: Vec<u32> = (0..=n).map(|i| vert(self, i as f32 / n as f32, 0.0)).collect();
            for side in [-1.0, 1.0] {
                // Edge points at the inner stations; the base and tip close on the midrib.
                let e: Vec<u32> = (1..n).map(|i| vert(self, i as f32 / n as f32, side)).collect();
                let e = |i: u32| e[i as usize - 1];
                let m = |i: u32| m[i as usize];
                tris.push([m(0), m(1), e(1)]);
                for i in 1..n - 1 {
                    tris.push([m(i), m(i + 1), e(i + 1)]);
                    tris.push([m(i), e(i + 1), e(i)]);
                }
                tris.push([m(n - 1), m(n), e(n - 1)]);
            }
        }
        for t in tris {
            let mid = t.iter().map(|&i| ts[i as usize - first]).sum::<f32>() / 3.0;
            self.tri(t, normal(mid));
        }
        // Smooth normals over the leaf's own faces (its vertices are its own).
        let mut acc = vec![Vec3::ZERO; self.mesh.vertices.len() - first];
        for t in self.mesh.indices[first_index..].chunks_exact(3) {
            let p = |i: u32| Vec3::from(self.mesh.vertices[i as usize].position);
            let face = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
            for &i in t {
                acc[i as usize - first] += face;
            }
        }
        for (j, a) in acc.into_iter().enumerate() {
            let v = &mut self.mesh.vertices[first + j];
            v.normal = a.normalize_or(Vec3::from(v.normal)).into();
        }
        self.part(kind, first);
    }

    /// A tube of `sides` along `path`, its radius and bending freedom going from the first to the
    /// second value of `radius` and `b`.
    #[allow(clippy::too_many_arguments)]
    fn tube(&mut self, path: &[Vec3], radius: [f32; 2], sides: u32, albedo: [f32; 4], phase: f32, b: [f32; 2]) {
        let first = self.mesh.vertices.len();
        let k = path.len();
        let mut u = Vec3::ZERO;
        for i in 0..k {
            let t = (path[(i + 1).min(k - 1)] - path[i.saturating_sub(1)]).normalize();
            // Parallel transport: the ring does not twist along the tube.
            u = if i == 0 { t.any_orthonormal_vector() } else { (u - t * u.dot(t)).normalize() };
            let v = t.cross(u);
            let f = i as f32 / (k - 1) as f32;
            for j in 0..sides {
                let a = TAU * j as f32 / sides as f32;
                let radial = u * a.cos() + v * a.sin();
                let p = path[i] + radial * lerp(radius[0], radius[1], f);
                let wind = [0.0, phase, lerp(b[0], b[1], f), 1.0];
                self.push(p, radial, wind, albedo, [j as f32 / sides as f32, 1.0 - f]);
            }
        }
        let ring = |i: usize, j: u32| (first + i * sides as usize) as u32 + j % sides;
        for i in 0..k - 1 {
            for j in 0..sides {
                let q = [ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)];
                for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                    let front = t.iter().map(|&i| Vec3::from(self.mesh.vertices[i as usize].normal)).sum();
                    self.tri(t, front);
                }
            }
        }
        self.part(Kind::Stem, first);
    }

    /// A flower's centre: a ring of `sides` with a low cone above and below.
    #[allow(clippy::too_many_arguments)]
    fn centre(&mut self, c: Vec3, axis: Vec3, radius: f32, sides: u32, albedo: [f32; 4], phase: f32, b: f32) {
        let first = self.mesh.vertices.len();
        let (u, v) = axis.any_orthonormal_pair();
        let wind = [0.0, phase, b, 1.0];
        let top = self.push(c + axis * radius * 0.9, axis, wind, albedo, [0.5, 0.0]);
        let under = self.push(c - axis * radius * 0.5, -axis, wind, albedo, [0.5, 1.0]);
        let ring: Vec<u32> = (0..sides)
            .map(|j| {
                let a = TAU * j as f32 / sides as f32;
                let radial = u * a.cos() + v * a.sin();
                self.push(c + radial * radius, (radial + axis * 0.3).normalize(), wind, albedo, [0.5, 0.5])
            })
            .collect();
        for j in 0..sides as usize {
            let (r0, r1) = (ring[j], ring[(j + 1) % ring.len()]);
            for apex in [top, under] {
                let p = |i: u32| Vec3::from(self.mesh.vertices[i as usize].position);
                let front = (p(r0) + p(r1) + p(apex)) / 3.0 - c;
                self.tri([r0, r1, apex], front);
            }
        }
        self.part(Kind::Centre, first);
    }
}

fn flower(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    let green = [0.07, 0.2, 0.035];
    let lean_dir = azimuth(r.range(0.0, TAU));
    let lean = r.range(0.03, 0.14);
    let head_z = r.range(0.78, 0.9);
    let stem = |t: f32| lean_dir * (lean * t * t) + Vec3::Z * (head_z * t);
    let segs = if full { 5 } else { 2 };
    let path: Vec<Vec3> = (0..=segs).map(|i| stem(i as f32 / segs as f32)).collect();
    let stem_b = 0.3;
    b.tube(&path, [0.011, 0.007], if full { 6 } else { 4 }, rgba(green, WOODY), r.f(), [0.0, stem_b]);

    let leaves = r.count(2, 4);
    let leaf_az = r.range(0.0, TAU);
    for i in 0..leaves {
        let mut lr = rng.fork(10 + i);
        let t = 0.12 + 0.45 * (i as f32 + lr.range(0.0, 0.6)) / leaves as f32;
        let (length, width) = (lr.range(0.18, 0.28), lr.range(0.04, 0.06));
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
        } else if i % 3 == 0 {
            b.leaf(&Leaf { length: length * 1.15, width: width * 1.5, segments: 1, ..leaf }, Kind::Leaf);
        }
    }

    // The head faces up, tilted a little along the stem's lean.
    let head = stem(1.0);
    let axis = ((stem(1.0) - stem(0.95)).normalize() + Vec3::Z * 1.5).normalize();
    let (hu, hv) = axis.any_orthonormal_pair();
    let petals = r.count(5, 8);
    let petal_len = r.range(0.1, 0.16);
    let petal_width = petal_len * r.range(0.45, 0.65);
    let opening = r.range(0.25, 0.6);
    let spin = r.range(0.0, TAU);
    for p in 0..petals {
        let mut pr = rng.fork(100 + p);
        let a = spin + TAU * p as f32 / petals as f32 + pr.range(-0.15, 0.15);
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
        // Every petal stays at both levels (a third of a head would not read as a flower); the
        // reduced one makes each a folded quad.
        b.leaf(&petal, Kind::Petal);
    }
    let centre = rgba([0.45, 0.28, 0.03], 0.3);
    b.centre(head + axis * 0.006, axis, petal_len * 0.22, if full { 6 } else { 4 }, centre, r.f(), stem_b);
}

fn fern(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    let fronds = r.count(5, 9);
    let az0 = r.range(0.0, TAU);
    let rachis_colour = tint([colour[0] * 0.5 + 0.06, colour[1] * 0.5 + 0.04, colour[2] * 0.5], 1.0);
    for k in 0..fronds {
        let mut fr = rng.fork(1 + k);
        let az = az0 + TAU * k as f32 / fronds as f32 + fr.range(-0.25, 0.25);
        let (e0, e1) = (fr.range(1.0, 1.35), fr.range(-0.3, 0.0));
        let len = fr.range(0.9, 1.15);
        let (out, side) = (azimuth(az), azimuth(az + PI / 2.0));
        // The rachis arches: its elevation falls from e0 at the root to e1 at the tip.
        let dir = |t: f32| {
            let e = lerp(e0, e1, t.powf(0.8));
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

        // The rachis: a flat ribbon facing up, tapering.
        let first = b.mesh.vertices.len();
        let segs = if full { 6 } else { 3 };
        let phase = fr.f();
        let mut ribbon = Vec::new();
        for i in 0..=segs {
            let t = i as f32 / segs as f32;
            let half = 0.007 * (1.0 - 0.7 * t);
            for s in [-1.0, 1.0] {
                let wind = [0.0, phase, t, 1.0];
                ribbon.push(b.push(at(t) + side * (s * half), up(t), wind, rgba(rachis_colour, WOODY), [0.5 + 0.5 * s, 1.0 - t]));
            }
        }
        for i in 0..segs as usize {
            let t = (i as f32 + 0.5) / segs as f32;
            let q = &ribbon[2 * i..2 * i + 4];
            b.tri([q[0], q[1], q[3]], up(t));
            b.tri([q[0], q[3], q[2]], up(t));
        }
        b.part(Kind::Stem, first);

        let pairs = fr.count(9, 12);
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
                    width: longest * taper * 0.32,
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
                    let grown = Leaf { length: leaflet.length * 1.4, width: leaflet.width * 2.0, ..leaflet };
                    b.leaf(&grown, Kind::Leaf);
                }
            }
        }
    }
}

fn bush(rng: &Rng, colour: [f32; 3], lod: usize, b: &mut Builder) {
    let mut r = rng.fork(0);
    let count = r.count(3, 5);
    let az0 = r.range(0.0, TAU);
    // Forks per branch first: the leaves per twig share out a fixed total.
    let forks: Vec<u32> = (0..count).map(|k| rng.fork(1 + k).count(1, 2)).collect();
    let twigs: u32 = forks.iter().map(|&f| 1 << f).sum();
    let per_twig = (230 / twigs).clamp(8, 24);
    for k in 0..count {
        let mut br = rng.fork(1 + k);
        br.count(1, 2); // the fork count drawn above
        let az = az0 + TAU * k as f32 / count as f32 + br.range(-0.3, 0.3);
        let el = br.range(0.85, 1.2);
        let spec = Branch {
            start: azimuth(az) * 0.02,
            dir: azimuth(az) * el.cos() + Vec3::Z * el.sin(),
            len: br.range(0.38, 0.48),
            radius: 0.022,
            level: 0,
            forks: forks[k as usize],
            b: 0.0,
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
}

fn branch(b: &mut Builder, rng: &Rng, br: &Branch, colour: [f32; 3], per_twig: u32, lod: usize) {
    let full = lod == 0;
    let mut r = rng.fork(0);
    // Branches bow up a little; the twigs toward the light.
    let bow = Vec3::Z * (br.len * r.range(0.04, 0.1));
    let at = |t: f32| br.start + br.dir * (br.len * t) + bow * (4.0 * t * (1.0 - t));
    let end_b = br.b + (1.0 - br.b) * 0.45;
    let terminal = br.level >= br.forks;
    let segs = if full && br.level < 2 { 2 } else { 1 };
    let bark = rgba(tint([0.1, 0.065, 0.035], r.range(0.85, 1.15)), WOODY);
    let phase = r.f();
    // The reduced level leaves out the thinnest twigs (inside the leaves).
    if full || br.level < 2 {
        let path: Vec<Vec3> = (0..=segs).map(|i| at(i as f32 / segs as f32)).collect();
        b.tube(&path, [br.radius, br.radius * 0.7], 3, bark, phase, [br.b, end_b]);
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
            };
            branch(b, &rng.fork(n), &child, colour, per_twig, lod);
        }
        return;
    }
    let out = Vec3::new(br.dir.x, br.dir.y, 0.0).normalize_or(Vec3::X);
    for i in 0..per_twig {
        let mut lr = rng.fork(100 + i);
        // Clustered toward the twig's end.
        let t = 1.0 - (1.0 - (i as f32 + lr.f()) / per_twig as f32).powi(2) * 0.8;
        let dir = (br.dir * 0.5 + lr.dir() * 0.9 + out * 0.3 + Vec3::Z * 0.2).normalize_or(br.dir);
        let length = lr.range(0.11, 0.15);
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
            albedo: rgba(tint([colour[0] * lr.range(0.9, 1.25), colour[1], colour[2]], lr.range(0.8, 1.15)), THIN),
            phase: lr.f(),
            b: [lerp(br.b, end_b, t), 1.0],
        };
        if full {
            b.leaf(&leaf, Kind::Leaf);
        } else if i % 3 == 0 {
            b.leaf(&Leaf { length: length * 1.45, width: leaf.width * 1.45, ..leaf }, Kind::Leaf);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ACCENT: [f32; 3] = [0.8, 0.2, 0.5];

    fn seeds() -> impl Iterator<Item = u32> {
        [0u32, 1, 2, 7, 42, 1234, 0xdead_beef].into_iter()
    }

    fn pos(m: &PlantMesh, i: u32) -> Vec3 {
        Vec3::from(m.vertices[i as usize].position)
    }

    #[test]
    fn names_and_serde() {
        for r in Recipe::ALL {
            let json = serde_json::to_string(&r).unwrap();
            assert_eq!(json, format!("\"{}\"", r.name()));
            assert_eq!(serde_json::from_str::<Recipe>(&json).unwrap(), r);
        }
        assert!(serde_json::from_str::<Recipe>("\"Tree\"").is_err());
    }

    #[test]
    fn triangle_budgets_and_reduced_level() {
        for recipe in Recipe::ALL {
            let budget = match recipe {
                Recipe::Flower => 300,
                Recipe::Fern => 600,
                Recipe::Bush => 900,
            };
            for seed in seeds() {
                let [(l0, _), (l1, _)] = build(recipe, seed, ACCENT);
                let (t0, t1) = (l0.triangles(), l1.triangles());
                assert!(t0 <= budget && t0 >= budget / 4, "{recipe:?} {seed}: {t0} triangles");
                let ratio = t1 as f32 / t0 as f32;
                assert!((0.2..=0.5).contains(&ratio), "{recipe:?} {seed}: lod 1 {t1} of {t0}");
                // The same silhouette size.
                assert!((l1.height() / l0.height() - 1.0).abs() < 0.15, "{recipe:?} {seed}: height");
                assert!((l1.radius() / l0.radius() - 1.0).abs() < 0.2, "{recipe:?} {seed}: radius");
            }
        }
    }

    #[test]
    fn meshes_are_well_formed() {
        for recipe in Recipe::ALL {
            for seed in seeds() {
                for (m, parts) in build(recipe, seed, ACCENT) {
                    assert_eq!(m.indices.len() % 3, 0);
                    assert!(m.indices.iter().all(|&i| (i as usize) < m.vertices.len()));
                    for v in &m.vertices {
                        assert!(v.position.iter().all(|p| p.is_finite()));
                        let n = Vec3::from(v.normal).length();
                        assert!((n - 1.0).abs() < 1e-3, "{recipe:?} {seed}: normal length {n}");
                        for c in v.wind.iter().chain(&v.albedo).chain(&v.uv) {
                            assert!((0.0..=1.0).contains(c), "{recipe:?} {seed}: channel {c}");
                        }
                    }
                    // Each triangle's winding agrees with its vertices' normals (the front).
                    for t in m.indices.chunks_exact(3) {
                        let face = (pos(&m, t[1]) - pos(&m, t[0])).cross(pos(&m, t[2]) - pos(&m, t[0]));
                        let n: Vec3 = t.iter().map(|&i| Vec3::from(m.vertices[i as usize].normal)).sum();
                        assert!(face.dot(n) >= 0.0, "{recipe:?} {seed}: triangle against its normals");
                    }
                    // The parts cover every vertex, in order.
                    assert_eq!(parts.first().unwrap().first, 0);
                    assert_eq!(parts.last().unwrap().end, m.vertices.len());
                    assert!(parts.windows(2).all(|w| w[0].end == w[1].first));
                }
            }
        }
    }

    #[test]
    fn size_about_a_metre() {
        for recipe in Recipe::ALL {
            for seed in seeds() {
                let m = &build(recipe, seed, ACCENT)[0].0;
                let (h, w) = (m.height(), 2.0 * m.radius());
                assert!((0.6..=1.3).contains(&h), "{recipe:?} {seed}: height {h}");
                let low = m.vertices.iter().map(|v| v.position[2]).fold(f32::MAX, f32::min);
                assert!(low > -0.05 && low <= 0.01, "{recipe:?} {seed}: lowest point {low}");
                if recipe == Recipe::Bush {
                    assert!(h <= 1.0 && (0.6..=1.5).contains(&(w / h)), "bush {seed}: {h} high, {w} wide");
                }
            }
        }
    }

    #[test]
    fn wind_channels_per_part() {
        for recipe in Recipe::ALL {
            for seed in seeds() {
                for (m, parts) in build(recipe, seed, ACCENT) {
                    for p in &parts {
                        let vs = &m.vertices[p.first..p.end];
                        // One phase per leaf (and per stem).
                        assert!(vs.iter().all(|v| v.wind[1] == vs[0].wind[1]), "{recipe:?} {seed}: phase");
                        match p.kind {
                            Kind::Leaf | Kind::Petal => {
                                // Midrib 0, edge 1; thin.
                                assert!(vs.iter().any(|v| v.wind[0] == 0.0) && vs.iter().any(|v| v.wind[0] == 1.0));
                                assert!(vs.iter().all(|v| v.albedo[3] >= 0.8));
                            }
                            Kind::Stem => assert!(vs.iter().all(|v| v.wind[0] == 0.0 && v.albedo[3] == WOODY)),
                            Kind::Centre => {}
                        }
                        if p.kind == Kind::Petal {
                            let k = vs[0].albedo[0] / ACCENT[0];
                            assert!((0.85..1.15).contains(&k), "petal colour {:?}", vs[0].albedo);
                        }
                    }
                    // Leaves of neighbouring parts flutter out of step.
                    let phases: std::collections::HashSet<u32> =
                        parts.iter().map(|p| m.vertices[p.first].wind[1].to_bits()).collect();
                    assert!(phases.len() * 10 >= parts.len() * 9, "{recipe:?} {seed}: phases repeat");
                }
            }
        }
    }

    /// Mean of `f` over the vertices in the bottom and the top third of the height.
    fn thirds(m: &PlantMesh, f: impl Fn(&PlantVertex) -> f32) -> (f32, f32) {
        let h = m.height();
        let mean = |keep: &dyn Fn(f32) -> bool| {
            let vs: Vec<f32> = m.vertices.iter().filter(|v| keep(v.position[2] / h)).map(&f).collect();
            assert!(!vs.is_empty());
            vs.iter().sum::<f32>() / vs.len() as f32
        };
        (mean(&|z| z < 1.0 / 3.0), mean(&|z| z > 2.0 / 3.0))
    }

    #[test]
    fn bending_rises_and_shade_falls_toward_the_tips() {
        for recipe in Recipe::ALL {
            for seed in seeds() {
                for (lod, (m, _)) in build(recipe, seed, ACCENT).iter().enumerate() {
                    let (low, high) = thirds(m, |v| v.wind[2]);
                    assert!(high > low + 0.1, "{recipe:?} {seed} lod {lod}: b {low} .. {high}");
                    let (low, high) = thirds(m, |v| v.wind[3]);
                    assert!(high > low, "{recipe:?} {seed} lod {lod}: ao {low} .. {high}");
                    let root = m.vertices.iter().filter(|v| Vec3::from(v.position).length() < 0.03);
                    assert!(root.clone().count() > 0 && root.clone().all(|v| v.wind[2] < 0.1 && v.wind[3] < 0.45));
                    let open = m.vertices.iter().map(|v| v.wind[3]).fold(0.0, f32::max);
                    assert!(open > 0.95, "{recipe:?} {seed}: no open vertex");
                }
            }
        }
        // A bush is darker at its core than at its rim, at the same height.
        let m = &build(Recipe::Bush, 3, ACCENT)[0].0;
        let (h, r) = (m.height(), m.radius());
        let at = |p: Vec3| ao(Recipe::Bush, p, h, r);
        assert!(at(Vec3::new(0.0, 0.0, 0.4 * h)) < 0.4 && at(Vec3::new(r, 0.0, 0.4 * h)) > 0.95);
    }

    #[test]
    fn deterministic_and_seeds_differ() {
        for recipe in Recipe::ALL {
            let a = generate(recipe, 5, ACCENT);
            assert_eq!(a, generate(recipe, 5, ACCENT));
            let other = build(recipe, 6, ACCENT);
            assert_ne!(a.lods[0], other[0].0);
            // Leaf counts vary with the seed.
            let counts: std::collections::HashSet<usize> =
                (0..8).map(|s| build(recipe, s, ACCENT)[0].1.len()).collect();
            assert!(counts.len() >= 2, "{recipe:?}: the same parts for every seed");
        }
        // The accent colours the flower's petals and the fern's and bush's leaves.
        for recipe in Recipe::ALL {
            let [a, b] = [[0.9, 0.1, 0.1], [0.1, 0.1, 0.9]].map(|c| {
                let [(m, _), _] = build(recipe, 9, c);
                m
            });
            assert_eq!(a.indices, b.indices);
            assert!(a.vertices.iter().zip(&b.vertices).any(|(x, y)| x.albedo[0] > y.albedo[0] + 0.3));
        }
    }

    #[test]
    fn card_matches_the_full_mesh() {
        let p = generate(Recipe::Fern, 3, ACCENT);
        assert_eq!(p.card, crossed_cards(&p.lods[0]));
        assert_eq!((p.card_image.width, p.card_image.height), (CARD_SIZE, CARD_SIZE));
        assert!((p.card.height() - p.lods[0].height()).abs() < 1e-6);
        assert!((p.card.radius() - p.lods[0].radius()).abs() < 1e-6);
    }
}
