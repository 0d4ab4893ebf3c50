//! The far level of detail: two crossed vertical cards carrying a picture of the plant, rendered
//! from its mesh on the CPU at start-up.
//!
//! Both the cards and the picture are framed to the same box: `-radius..radius` across (the
//! mesh's largest distance from its axis, so that the plant fits whichever way it faces) and
//! `0..height` up, so the picture's uv 0..1 lands on the plant's own outline.

use glam::{Vec2, Vec3};

use super::mesh::{PlantImage, PlantMesh, PlantVertex};

/// `albedo.a` of the cards: a card stands for a whole plant, leaves and stems together.
const CARD_THINNESS: f32 = 0.6;

/// Samples per pixel along each axis (4 x 4 supersampling).
const SUPERSAMPLE: u32 = 4;

/// The light of the card picture: from the front (the camera looks along +y) and above.
const LIGHT: Vec3 = Vec3::new(0.0, -std::f32::consts::FRAC_1_SQRT_2, std::f32::consts::FRAC_1_SQRT_2);
const AMBIENT: f32 = 0.35;
const DIRECT: f32 = 0.65;

/// The card box of a mesh: half width and height, metres (at least a millimetre each, so that an
/// empty or flat mesh still frames a box).
fn extent(mesh: &PlantMesh) -> (f32, f32) {
    (mesh.radius().max(1e-3), mesh.height().max(1e-3))
}

/// Two vertical quads crossing at the plant's axis, one in the x-z plane and one in the y-z
/// plane, each `2 * mesh.radius()` wide and `mesh.height()` tall, rooted at the origin.
///
/// uv covers the picture of [`render_card`] (u = 0 on the left, v = 0 at the top). The card sways
/// as a whole: `wind.b` rises from 0 at the ground to 1 at the top, `wind.r` (edge flutter) is 0,
/// the phase one value, AO 1 (the picture has the mesh's AO in it). Albedo is white, the picture
/// gives the colour; `albedo.a` is 0.6. The draw is two-sided, so each quad is two triangles.
pub fn crossed_cards(mesh: &PlantMesh) -> PlantMesh {
    let (r, h) = extent(mesh);
    let mut card = PlantMesh::default();
    // Each quad's right-hand direction as seen from its front, and its front normal: the x-z
    // quad is seen from -y like the picture, the y-z quad from +x.
    for (right, normal) in [(Vec3::X, Vec3::NEG_Y), (Vec3::Y, Vec3::X)] {
        let first = card.vertices.len() as u32;
        for (u, v) in [(0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.0)] {
            let p = right * (r * (2.0 * u - 1.0)) + Vec3::Z * (h * (1.0 - v));
            card.vertices.push(PlantVertex {
                position: p.into(),
                normal: normal.into(),
                wind: [0.0, 0.5, 1.0 - v, 1.0],
                albedo: [1.0, 1.0, 1.0, CARD_THINNESS],
                uv: [u, v],
            });
        }
        // Bottom-left, bottom-right, top-right, top-left: counter-clockwise from the front.
        card.indices.extend([0, 1, 2, 0, 2, 3].map(|i| first + i));
    }
    card
}

/// Renders `mesh` from the side into a `size` x `size` sRGB RGBA8 picture for
/// [`crossed_cards`]: orthographic, looking along +y with x to the right and z up, framed to the
/// card's box (so the picture is stretched to a square; the card stretches it back).
///
/// Colour is the albedo lit by a soft fixed light, `albedo * (0.35 * ao + 0.65 * |n.l|)` with
/// `l` from the front and above (both faces of a leaf are lit alike, as the draw is two-sided);
/// alpha is coverage, anti-aliased by 4 x 4 samples per pixel with a depth test. Transparent
/// pixels take the colour of the nearest covered pixel, so that bilinear filtering and mipmaps
/// do not bleed black into the outline. A `size` of 0 gives an empty picture.
pub fn render_card(mesh: &PlantMesh, size: u32) -> PlantImage {
    let (r, h) = extent(mesh);
    let n = (size * SUPERSAMPLE) as usize;
    // Sample space: x across from the left edge, y down from the top, in samples.
    let scale = Vec2::new(n as f32 / (2.0 * r), n as f32 / h);
    let project = |v: &PlantVertex| Vec2::new(v.position[0] + r, h - v.position[2]) * scale;
    let mut depth = vec![f32::INFINITY; n * n];
    let mut colour = vec![Vec3::ZERO; n * n];
    for t in mesh.indices.chunks_exact(3) {
        let Some(vs) = t.iter().map(|&i| mesh.vertices.get(i as usize)).collect::<Option<Vec<_>>>() else {
            continue;
        };
        let p = [project(vs[0]), project(vs[1]), project(vs[2])];
        let area = edge(p[0], p[1], p[2]);
        if area.abs() < 1e-12 || !area.is_finite() {
            continue; // seen edge-on
        }
        let lo = p[0].min(p[1]).min(p[2]).floor().max(Vec2::ZERO);
        let hi = p[0].max(p[1]).max(p[2]).ceil().min(Vec2::splat(n as f32));
        for sy in lo.y as usize..hi.y as usize {
            for sx in lo.x as usize..hi.x as usize {
                let q = Vec2::new(sx as f32 + 0.5, sy as f32 + 0.5);
                let w = [edge(p[1], p[2], q), edge(p[2], p[0], q), edge(p[0], p[1], q)].map(|e| e / area);
                if w.iter().any(|&w| w < 0.0) {
                    continue;
                }
                let y = w[0] * vs[0].position[1] + w[1] * vs[1].position[1] + w[2] * vs[2].position[1];
                let s = sy * n + sx;
                // The nearest surface wins: the camera is at -y.
                if y >= depth[s] {
                    continue;
                }
                depth[s] = y;
                let mix = |f: &dyn Fn(&PlantVertex) -> Vec3| f(vs[0]) * w[0] + f(vs[1]) * w[1] + f(vs[2]) * w[2];
                let normal = mix(&|v| Vec3::from(v.normal)).normalize_or_zero();
                let albedo = mix(&|v| Vec3::new(v.albedo[0], v.albedo[1], v.albedo[2]));
                let ao = mix(&|v| Vec3::splat(v.wind[3])).x;
                colour[s] = albedo * (AMBIENT * ao + DIRECT * normal.dot(LIGHT).abs());
            }
        }
    }

    // Resolve each pixel's samples: the mean colour of those covered, alpha their share.
    let size = size as usize;
    let ss = SUPERSAMPLE as usize;
    let mut covered = vec![false; size * size];
    let mut rgb = vec![[0u8; 3]; size * size];
    let mut alpha = vec![0u8; size * size];
    for py in 0..size {
        for px in 0..size {
            let (mut sum, mut hits) = (Vec3::ZERO, 0);
            for sy in py * ss..(py + 1) * ss {
                for sx in px * ss..(px + 1) * ss {
                    if depth[sy * n + sx].is_finite() {
                        sum += colour[sy * n + sx];
                        hits += 1;
                    }
                }
            }
            if hits > 0 {
                let i = py * size + px;
                covered[i] = true;
                rgb[i] = (sum / hits as f32).to_array().map(srgb8);
                alpha[i] = (hits as f32 / (ss * ss) as f32 * 255.0).round() as u8;
            }
        }
    }
    pad_edges(&mut rgb, &covered, size);
    let mut rgba = Vec::with_capacity(size * size * 4);
    for (c, a) in rgb.iter().zip(&alpha) {
        rgba.extend_from_slice(&[c[0], c[1], c[2], *a]);
    }
    PlantImage { width: size as u32, height: size as u32, rgba }
}

/// Twice the signed area of the triangle a, b, c.
fn edge(a: Vec2, b: Vec2, c: Vec2) -> f32 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// Linear 0..1 to an sRGB byte.
fn srgb8(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0).round() as u8
}

/// Gives every uncovered pixel the colour of its nearest covered one (in steps to a neighbour
/// across an edge): a breadth-first flood out of all covered pixels at once.
fn pad_edges(rgb: &mut [[u8; 3]], covered: &[bool], size: usize) {
    let mut done = covered.to_vec();
    let mut queue: std::collections::VecDeque<usize> = (0..rgb.len()).filter(|&i| covered[i]).collect();
    while let Some(i) = queue.pop_front() {
        let (x, y) = (i % size, i / size);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < size).then(|| i + 1),
            (y > 0).then(|| i - size),
            (y + 1 < size).then(|| i + size),
        ];
        for j in neighbours.into_iter().flatten() {
            if !done[j] {
                done[j] = true;
                rgb[j] = rgb[i];
                queue.push_back(j);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plants::recipe::{Recipe, generate};

    fn vertex(p: [f32; 3], albedo: [f32; 3]) -> PlantVertex {
        PlantVertex {
            position: p,
            normal: [0.0, -1.0, 0.0],
            wind: [0.0, 0.0, 0.0, 1.0],
            albedo: [albedo[0], albedo[1], albedo[2], 0.9],
            uv: [0.0, 0.0],
        }
    }

    /// A quad in the plane y = `y` over x in `x`, z in `z`.
    fn quad(m: &mut PlantMesh, x: [f32; 2], z: [f32; 2], y: f32, albedo: [f32; 3]) {
        let first = m.vertices.len() as u32;
        for (a, b) in [(x[0], z[0]), (x[1], z[0]), (x[1], z[1]), (x[0], z[1])] {
            m.vertices.push(vertex([a, y, b], albedo));
        }
        m.indices.extend([0, 1, 2, 0, 2, 3].map(|i| first + i));
    }

    fn pixel(img: &PlantImage, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * img.width + x) * 4) as usize;
        img.rgba[i..i + 4].try_into().unwrap()
    }

    #[test]
    fn cards_span_the_mesh() {
        let p = generate(Recipe::Bush, 11, [0.2, 0.5, 0.1]);
        let (m, card) = (&p.lods[0], &p.card);
        let (r, h) = (m.radius(), m.height());
        assert_eq!((card.vertices.len(), card.triangles()), (8, 4));
        for v in &card.vertices {
            let [x, y, z] = v.position;
            // Each corner is on the axis in one direction and at the mesh's radius in the other.
            assert!(x.abs().min(y.abs()) < 1e-6 && (x.abs().max(y.abs()) - r).abs() < 1e-6);
            assert!(z.abs() < 1e-6 || (z - h).abs() < 1e-6);
            assert!((v.uv[1] - (1.0 - z / h)).abs() < 1e-6, "v is 0 at the top");
            assert!((v.wind[2] - z / h).abs() < 1e-6 && v.wind[0] == 0.0 && v.wind[3] == 1.0);
            assert_eq!(v.albedo, [1.0, 1.0, 1.0, 0.6]);
        }
        // u follows x on the x-z card, as in the picture.
        for v in &card.vertices[..4] {
            assert!((v.uv[0] - (v.position[0] + r) / (2.0 * r)).abs() < 1e-6);
        }
        // Wound counter-clockwise from the front.
        for t in card.indices.chunks_exact(3) {
            let p = |i: u32| Vec3::from(card.vertices[i as usize].position);
            let face = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
            assert!(face.normalize().dot(Vec3::from(card.vertices[t[0] as usize].normal)) > 0.999);
        }
    }

    #[test]
    fn a_quad_over_the_frame_covers_every_pixel_with_lit_albedo() {
        let mut m = PlantMesh::default();
        quad(&mut m, [-1.0, 1.0], [0.0, 2.0], 0.0, [0.5, 0.25, 1.0]);
        let img = render_card(&m, 16);
        assert_eq!((img.width, img.height, img.rgba.len()), (16, 16, 16 * 16 * 4));
        // n = -y, l from the front and above: |n.l| = 1/sqrt 2; AO 1.
        let light = AMBIENT + DIRECT * std::f32::consts::FRAC_1_SQRT_2;
        let want = [0.5, 0.25, 1.0].map(|a| srgb8(a * light));
        for px in img.rgba.chunks_exact(4) {
            assert_eq!(px, [want[0], want[1], want[2], 255]);
        }
        assert_eq!(srgb8(0.5), 188);
        assert_eq!(render_card(&m, 0).rgba.len(), 0);
    }

    #[test]
    fn coverage_is_antialiased_and_padded() {
        // A right triangle over the frame's lower-left half: half the picture, with a diagonal
        // of partly covered pixels.
        let mut m = PlantMesh::default();
        m.vertices = vec![vertex([-1.0, 0.0, 0.0], [0.2, 0.8, 0.1]), vertex([1.0, 0.0, 0.0], [0.2, 0.8, 0.1]), vertex([-1.0, 0.0, 2.0], [0.2, 0.8, 0.1])];
        m.indices = vec![0, 1, 2];
        let img = render_card(&m, 32);
        let alpha: Vec<u8> = img.rgba.chunks_exact(4).map(|p| p[3]).collect();
        let covered: f32 = alpha.iter().map(|&a| a as f32 / 255.0).sum();
        assert!((covered / (32.0 * 32.0) - 0.5).abs() < 0.01, "covered {covered}");
        assert!(alpha.iter().any(|&a| a > 0 && a < 255), "no partial pixels on the diagonal");
        assert_eq!(pixel(&img, 0, 31)[3], 255);
        assert_eq!(pixel(&img, 31, 0)[3], 0);
        // Transparent pixels carry the covered colour, not black.
        let inside = pixel(&img, 0, 31);
        assert_eq!(pixel(&img, 31, 0)[..3], inside[..3]);
    }

    #[test]
    fn the_nearer_surface_wins() {
        for flip in [false, true] {
            let mut m = PlantMesh::default();
            let mut quads = [(-0.5, [1.0, 0.0, 0.0]), (0.5, [0.0, 0.0, 1.0])];
            if flip {
                quads.reverse();
            }
            for (y, c) in quads {
                quad(&mut m, [-1.0, 1.0], [0.0, 1.0], y, c);
            }
            let px = pixel(&render_card(&m, 8), 4, 4);
            assert!(px[0] > 100 && px[2] == 0, "the red quad, nearer the camera at -y: {px:?}");
        }
    }

    #[test]
    fn picture_matches_the_mesh_silhouette() {
        for recipe in Recipe::ALL {
            let p = generate(recipe, 4, [0.7, 0.3, 0.6]);
            let (m, img) = (&p.lods[0], &p.card_image);
            let alpha: Vec<u8> = img.rgba.chunks_exact(4).map(|p| p[3]).collect();
            assert!(alpha.iter().any(|&a| a > 200) && alpha.contains(&0), "{recipe:?}");
            let rendered = alpha.iter().map(|&a| a as f32 / 255.0).sum::<f32>() / alpha.len() as f32;
            // The silhouette's share of the card box, by point-in-triangle tests on another grid.
            let (r, h) = (m.radius(), m.height());
            let tris: Vec<[Vec2; 3]> = m
                .indices
                .chunks_exact(3)
                .map(|t| {
                    [t[0], t[1], t[2]].map(|i| {
                        let p = m.vertices[i as usize].position;
                        Vec2::new(p[0], p[2])
                    })
                })
                .collect();
            let grid = 150;
            let mut inside = 0;
            for gy in 0..grid {
                for gx in 0..grid {
                    let q = Vec2::new((gx as f32 + 0.5) / grid as f32 * 2.0 * r - r, (gy as f32 + 0.5) / grid as f32 * h);
                    let hit = tris.iter().any(|&[a, b, c]| {
                        let e = [edge(a, b, q), edge(b, c, q), edge(c, a, q)];
                        e.iter().all(|&e| e >= 0.0) || e.iter().all(|&e| e <= 0.0)
                    });
                    inside += hit as u32;
                }
            }
            let expected = inside as f32 / (grid * grid) as f32;
            assert!(expected > 0.1, "{recipe:?}: silhouette {expected}");
            assert!((rendered / expected - 1.0).abs() < 0.1, "{recipe:?}: rendered {rendered}, silhouette {expected}");
        }
    }
}
