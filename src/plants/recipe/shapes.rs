//! The shapes the recipes are made of: leaves, tubes and a flower's centre, and the random
//! streams that place them.

use std::f32::consts::{PI, TAU};

use glam::Vec3;

use super::{Kind, Part};
use crate::hash::{hash_u32, hash3, rand01};
use crate::plants::mesh::{PlantMesh, PlantVertex};

pub(super) fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// `c` scaled by `k`, kept in 0..=1.
pub(super) fn tint(c: [f32; 3], k: f32) -> [f32; 3] {
    c.map(|x| (x * k).clamp(0.0, 1.0))
}

pub(super) fn rgba(c: [f32; 3], a: f32) -> [f32; 4] {
    [c[0], c[1], c[2], a]
}

/// Thinness (`albedo.a`) of leaves and petals, and of stems and branches.
pub(super) const THIN: f32 = 0.9;
pub(super) const WOODY: f32 = 0.1;

/// A stream of random numbers from the project's hash.
#[derive(Clone, Copy)]
pub(super) struct Rng {
    key: u32,
    n: u32,
}

impl Rng {
    pub(super) fn new(seed: u32, salt: u32) -> Self {
        Rng {
            key: hash3(seed, salt, 0x9e37_79b9),
            n: 0,
        }
    }

    /// An independent stream for element `i`, untouched by what is drawn from others.
    pub(super) fn fork(&self, i: u32) -> Rng {
        Rng {
            key: hash3(self.key, i, 0x85eb_ca6b),
            n: 0,
        }
    }

    /// In [0, 1).
    pub(super) fn f(&mut self) -> f32 {
        self.n += 1;
        rand01(hash_u32(self.key ^ hash_u32(self.n)))
    }

    pub(super) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lerp(lo, hi, self.f())
    }

    /// An integer in `lo..=hi`.
    pub(super) fn count(&mut self, lo: u32, hi: u32) -> u32 {
        (lo + (self.f() * (hi - lo + 1) as f32) as u32).min(hi)
    }

    /// A direction, uniform on the sphere.
    pub(super) fn dir(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let a = self.range(0.0, TAU);
        let r = (1.0 - z * z).sqrt();
        Vec3::new(r * a.cos(), r * a.sin(), z)
    }
}

/// The unit horizontal vector at azimuth `a`.
pub(super) fn azimuth(a: f32) -> Vec3 {
    Vec3::new(a.cos(), a.sin(), 0.0)
}

/// A leaf (or petal, or leaflet): a midrib curving down by `droop` radians from base to tip, and
/// edges cupped up by `cup` times the half width.
pub(super) struct Leaf {
    pub(super) base: Vec3,
    pub(super) dir: Vec3,
    /// Roughly the front's normal; made perpendicular to `dir`.
    pub(super) up: Vec3,
    pub(super) length: f32,
    pub(super) width: f32,
    pub(super) droop: f32,
    pub(super) cup: f32,
    /// Where along the midrib (0..1) the leaf is widest.
    pub(super) widest: f32,
    /// Midrib segments; 1 makes a quad of two triangles folded along the midrib.
    pub(super) segments: u32,
    pub(super) albedo: [f32; 4],
    pub(super) phase: f32,
    /// The bending freedom `wind.b` at the base and at the tip.
    pub(super) b: [f32; 2],
}

#[derive(Default)]
pub(super) struct Builder {
    pub(super) mesh: PlantMesh,
    pub(super) parts: Vec<Part>,
}

impl Builder {
    pub(super) fn push(
        &mut self,
        position: Vec3,
        normal: Vec3,
        wind: [f32; 4],
        albedo: [f32; 4],
        uv: [f32; 2],
    ) -> u32 {
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
    pub(super) fn tri(&mut self, [a, b, c]: [u32; 3], front: Vec3) {
        let p = |i: u32| Vec3::from(self.mesh.vertices[i as usize].position);
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        let t = if face.dot(front) < 0.0 {
            [a, c, b]
        } else {
            [a, b, c]
        };
        self.mesh.indices.extend_from_slice(&t);
    }

    pub(super) fn part(&mut self, kind: Kind, first: usize) {
        let end = self.mesh.vertices.len();
        self.parts.push(Part { kind, first, end });
    }

    pub(super) fn leaf(&mut self, l: &Leaf, kind: Kind) {
        let first = self.mesh.vertices.len();
        let first_index = self.mesh.indices.len();
        let d0 = l.dir.normalize();
        let s = d0
            .cross(l.up)
            .try_normalize()
            .unwrap_or_else(|| d0.any_orthonormal_vector());
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
            let m: Vec<u32> = (0..=n)
                .map(|i| vert(self, i as f32 / n as f32, 0.0))
                .collect();
            for side in [-1.0, 1.0] {
                // Edge points at the inner stations; the base and tip close on the midrib.
                let e: Vec<u32> = (1..n)
                    .map(|i| vert(self, i as f32 / n as f32, side))
                    .collect();
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
    pub(super) fn tube(
        &mut self,
        path: &[Vec3],
        radius: [f32; 2],
        sides: u32,
        albedo: [f32; 4],
        phase: f32,
        b: [f32; 2],
    ) {
        let first = self.mesh.vertices.len();
        let k = path.len();
        let mut u = Vec3::ZERO;
        for i in 0..k {
            let t = (path[(i + 1).min(k - 1)] - path[i.saturating_sub(1)]).normalize();
            // Parallel transport: the ring does not twist along the tube.
            u = if i == 0 {
                t.any_orthonormal_vector()
            } else {
                (u - t * u.dot(t)).normalize()
            };
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
                let q = [
                    ring(i, j),
                    ring(i, j + 1),
                    ring(i + 1, j + 1),
                    ring(i + 1, j),
                ];
                for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                    let front = t
                        .iter()
                        .map(|&i| Vec3::from(self.mesh.vertices[i as usize].normal))
                        .sum();
                    self.tri(t, front);
                }
            }
        }
        self.part(Kind::Stem, first);
    }

    /// A flower's centre: a ring of `sides` with a low cone above and below.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn centre(
        &mut self,
        c: Vec3,
        axis: Vec3,
        radius: f32,
        sides: u32,
        albedo: [f32; 4],
        phase: f32,
        b: f32,
    ) {
        let first = self.mesh.vertices.len();
        let (u, v) = axis.any_orthonormal_pair();
        let wind = [0.0, phase, b, 1.0];
        let top = self.push(c + axis * radius * 0.9, axis, wind, albedo, [0.5, 0.0]);
        let under = self.push(c - axis * radius * 0.5, -axis, wind, albedo, [0.5, 1.0]);
        let ring: Vec<u32> = (0..sides)
            .map(|j| {
                let a = TAU * j as f32 / sides as f32;
                let radial = u * a.cos() + v * a.sin();
                self.push(
                    c + radial * radius,
                    (radial + axis * 0.3).normalize(),
                    wind,
                    albedo,
                    [0.5, 0.5],
                )
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
