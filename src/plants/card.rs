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
const LIGHT: Vec3 = Vec3::new(
    0.0,
    -std::f32::consts::FRAC_1_SQRT_2,
    std::f32::consts::FRAC_1_SQRT_2,
);
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

/// The smallest mip level (texels a side) whose opaque texels the trimmed billboard keeps
/// inside it. Coarser levels are drawn only where the card is under about this many pixels: a
/// texel they pass beyond the outline reaches past it by less than a quarter of a pixel there.
const TRIM_FINEST_SIDE: usize = 8;

/// Most corners of a trimmed billboard.
pub const TRIM_CORNERS: usize = 6;

/// One vertical quad in the x-z plane (facing -y, as [`crossed_cards`]' first), trimmed to the
/// outline of its picture: a convex polygon of at most [`TRIM_CORNERS`] corners holding every
/// point where the alpha test can pass, at any mip level in `levels` down to 8 x 8 texels (each
/// level an RGBA8 square, `levels[0]` the full picture; a texel passing the test reaches one
/// texel around its centre through bilinear filtering). The trees' cards are billboards turned
/// to the camera; trimmed, they cost the rasteriser the crown's outline instead of its box
/// (about half of a conifer's box is empty sky). The corners keep the quad's uv, wind and albedo
/// mapping. Falls back to the whole quad where nothing in `levels` is opaque.
pub fn trimmed_billboard(mesh: &PlantMesh, levels: &[Vec<u8>]) -> PlantMesh {
    let (r, h) = extent(mesh);
    let cut = (super::mesh::ALPHA_CUTOFF * 255.0).ceil() as u8;
    // Points in (u, up) = (u, 1 - v), 0..1 each.
    let mut points = Vec::new();
    for level in levels {
        let side = ((level.len() / 4) as f64).sqrt() as usize;
        if side < TRIM_FINEST_SIDE || side * side * 4 != level.len() {
            continue;
        }
        passing_boxes(level, side, cut, &mut points);
    }
    let mut outline = convex_hull(points);
    if outline.len() < 3 {
        outline = vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
    }
    let outline = reduce_polygon(outline, TRIM_CORNERS);
    let mut card = PlantMesh::default();
    for q in &outline {
        let (u, v) = (q.x, 1.0 - q.y);
        let p = Vec3::X * (r * (2.0 * u - 1.0)) + Vec3::Z * (h * (1.0 - v));
        card.vertices.push(PlantVertex {
            position: p.into(),
            normal: Vec3::NEG_Y.into(),
            wind: [0.0, 0.5, 1.0 - v, 1.0],
            albedo: [1.0, 1.0, 1.0, CARD_THINNESS],
            uv: [u, v],
        });
    }
    // A fan, counter-clockwise from the front as the quads.
    for i in 1..outline.len() as u32 - 1 {
        card.indices.extend([0, i, i + 1]);
    }
    card
}

/// Adds to `points` (as (u, 1 - v)) the corners of every box of a grid over the square RGBA8
/// `level` (`side` texels a side) where the sampler's bilinear filter (clamped to the edge) can
/// reach `cut`. The grid's lines run through the texel centres (and the edges), so each box lies
/// within one bilinear cell, where the filter's largest value is at a corner: a box is kept when
/// any corner passes, and the boxes kept hold every point that passes.
fn passing_boxes(level: &[u8], side: usize, cut: u8, points: &mut Vec<Vec2>) {
    let alpha = |x: usize, y: usize| f32::from(level[(y * side + x) * 4 + 3]);
    // Bilinear alpha at texel-centre coordinate `c` (0 at the first centre), clamped.
    let filtered = |c: Vec2| {
        let c = c.clamp(Vec2::ZERO, Vec2::splat((side - 1) as f32));
        let (x0, y0) = (c.x.floor() as usize, c.y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(side - 1), (y0 + 1).min(side - 1));
        let f = c - Vec2::new(x0 as f32, y0 as f32);
        let top = alpha(x0, y0) * (1.0 - f.x) + alpha(x1, y0) * f.x;
        let bottom = alpha(x0, y1) * (1.0 - f.x) + alpha(x1, y1) * f.x;
        top * (1.0 - f.y) + bottom * f.y
    };
    // Grid lines, in texel-centre coordinates: the edge, the centres with `m` steps between
    // them, the other edge. Fine levels reach a texel at most: whole cells will do.
    let m = if side >= 64 { 1 } else { 4 };
    let mut lines = vec![-0.5f32];
    for i in 0..(side - 1) * m + 1 {
        lines.push(i as f32 / m as f32);
    }
    lines.push(side as f32 - 0.5);
    let values: Vec<f32> = lines
        .iter()
        .flat_map(|&y| lines.iter().map(move |&x| (x, y)))
        .map(|(x, y)| filtered(Vec2::new(x, y)))
        .collect();
    let n = lines.len();
    let to_uv = |x: f32, y: f32| {
        let uv = (Vec2::new(x, y) + 0.5) / side as f32;
        Vec2::new(uv.x, 1.0 - uv.y)
    };
    let cut = f32::from(cut);
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)];
            if corners.iter().any(|&(a, b)| values[b * n + a] >= cut) {
                points.extend(corners.iter().map(|&(a, b)| to_uv(lines[a], lines[b])));
            }
        }
    }
}

/// The convex hull of `points`, counter-clockwise, without collinear points (Andrew's monotone
/// chain).
fn convex_hull(mut points: Vec<Vec2>) -> Vec<Vec2> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let mut hull: Vec<Vec2> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Vec2>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && edge(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// `polygon` (convex, counter-clockwise) cut down to at most `corners` corners, still holding
/// all of it and inside the unit square: each step drops the edge whose neighbours, extended to
/// meet, add the least area. Stops early where no edge can go.
fn reduce_polygon(mut polygon: Vec<Vec2>, corners: usize) -> Vec<Vec2> {
    const SLACK: f32 = 1e-4;
    while polygon.len() > corners.max(3) {
        let n = polygon.len();
        let mut best: Option<(f32, usize, Vec2)> = None;
        for i in 0..n {
            // Edge i runs from a to b; its neighbours come into a and go out of b.
            let (before, a) = (polygon[(i + n - 1) % n], polygon[i]);
            let (b, after) = (polygon[(i + 1) % n], polygon[(i + 2) % n]);
            let (d1, d2) = (a - before, after - b);
            let denom = d1.perp_dot(d2);
            if denom <= 1e-12 {
                continue; // the neighbours do not meet beyond the edge
            }
            let t = (b - a).perp_dot(d2) / denom;
            if t < 0.0 {
                continue;
            }
            let p = a + d1 * t;
            if p.cmplt(Vec2::splat(-SLACK)).any() || p.cmpgt(Vec2::splat(1.0 + SLACK)).any() {
                continue;
            }
            let added = edge(a, p, b).abs() * 0.5;
            if best.is_none_or(|(area, _, _)| added < area) {
                best = Some((added, i, p.clamp(Vec2::ZERO, Vec2::ONE)));
            }
        }
        let Some((_, i, p)) = best else {
            break;
        };
        polygon[i] = p;
        polygon.remove((i + 1) % n);
    }
    polygon
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
        let Some(vs) = t
            .iter()
            .map(|&i| mesh.vertices.get(i as usize))
            .collect::<Option<Vec<_>>>()
        else {
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
                let w = [
                    edge(p[1], p[2], q),
                    edge(p[2], p[0], q),
                    edge(p[0], p[1], q),
                ]
                .map(|e| e / area);
                if w.iter().any(|&w| w < 0.0) {
                    continue;
                }
                let y =
                    w[0] * vs[0].position[1] + w[1] * vs[1].position[1] + w[2] * vs[2].position[1];
                let s = sy * n + sx;
                // The nearest surface wins: the camera is at -y.
                if y >= depth[s] {
                    continue;
                }
                depth[s] = y;
                let mix = |f: &dyn Fn(&PlantVertex) -> Vec3| {
                    f(vs[0]) * w[0] + f(vs[1]) * w[1] + f(vs[2]) * w[2]
                };
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
    PlantImage {
        width: size as u32,
        height: size as u32,
        rgba,
    }
}

/// Twice the signed area of the triangle a, b, c.
fn edge(a: Vec2, b: Vec2, c: Vec2) -> f32 {
    (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)
}

/// Linear 0..1 to an sRGB byte.
fn srgb8(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Gives every uncovered pixel the colour of its nearest covered one (in steps to a neighbour
/// across an edge): a breadth-first flood out of all covered pixels at once.
fn pad_edges(rgb: &mut [[u8; 3]], covered: &[bool], size: usize) {
    let mut done = covered.to_vec();
    let mut queue: std::collections::VecDeque<usize> =
        (0..rgb.len()).filter(|&i| covered[i]).collect();
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

    /// Area of a polygon of uv corners (either winding).
    fn uv_area(card: &PlantMesh) -> f32 {
        let c: Vec<Vec2> = card.vertices.iter().map(|v| Vec2::from(v.uv)).collect();
        (0..c.len())
            .map(|i| c[i].perp_dot(c[(i + 1) % c.len()]))
            .sum::<f32>()
            .abs()
            * 0.5
    }

    #[test]
    fn trimmed_billboards_hold_every_opaque_texel_in_less_than_the_box() {
        use crate::plants::set::{TEXTURE_SIZE, mips, resample};
        for (recipe, most_area) in [(Recipe::Conifer, 0.62), (Recipe::Broadleaf, 0.62)] {
            let p = generate(recipe, 7, [0.1, 0.3, 0.05]);
            let levels = mips(&resample(&p.card_image, TEXTURE_SIZE));
            let card = trimmed_billboard(&p.lods[0], &levels);
            let n = card.vertices.len();
            assert!((3..=TRIM_CORNERS).contains(&n), "{recipe:?}: {n} corners");
            assert_eq!(card.triangles(), n - 2);
            let corners: Vec<Vec2> = card.vertices.iter().map(|v| Vec2::from(v.uv)).collect();
            // Every texel that passes the test, at every level down to 8 x 8, is inside.
            let inside = |q: Vec2| {
                (0..n).all(|i| {
                    let (a, b) = (corners[i], corners[(i + 1) % n]);
                    // Clockwise in uv (v points down): inside is to the right.
                    (b - a).perp_dot(q - a) <= 1e-4
                })
            };
            for level in levels.iter().filter(|l| l.len() >= 8 * 8 * 4) {
                let side = ((level.len() / 4) as f64).sqrt() as usize;
                for (i, t) in level.chunks_exact(4).enumerate() {
                    if t[3] >= 128 {
                        let c = Vec2::new((i % side) as f32 + 0.5, (i / side) as f32 + 0.5)
                            / side as f32;
                        assert!(
                            inside(c),
                            "{recipe:?}: texel {i} of the {side} level is cut"
                        );
                    }
                }
            }
            let area = uv_area(&card);
            assert!(
                area < most_area,
                "{recipe:?}: the billboard covers {area} of its box"
            );
            eprintln!("{recipe:?}: {n} corners, {area:.3} of the box");
            // The corners keep the quad's mapping: position from uv, wind rising with height.
            let (r, h) = (p.lods[0].radius(), p.lods[0].height());
            for v in &card.vertices {
                let [u, w] = v.uv;
                let want = [r * (2.0 * u - 1.0), 0.0, h * (1.0 - w)];
                for (got, want) in v.position.iter().zip(want) {
                    assert!((got - want).abs() < 1e-4 * h.max(r));
                }
                assert!((v.wind[2] - (1.0 - w)).abs() < 1e-6);
            }
        }
        // A picture with nothing opaque keeps the whole quad.
        let empty = vec![vec![0u8; 16 * 16 * 4], vec![0u8; 8 * 8 * 4]];
        let whole = trimmed_billboard(&generate(Recipe::Conifer, 1, [0.1; 3]).lods[0], &empty);
        assert!((uv_area(&whole) - 1.0).abs() < 1e-6);
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
            assert!(
                face.normalize()
                    .dot(Vec3::from(card.vertices[t[0] as usize].normal))
                    > 0.999
            );
        }
    }

    #[test]
    fn a_quad_over_the_frame_covers_every_pixel_with_lit_albedo() {
        let mut m = PlantMesh::default();
        quad(&mut m, [-1.0, 1.0], [0.0, 2.0], 0.0, [0.5, 0.25, 1.0]);
        let img = render_card(&m, 16);
        assert_eq!(
            (img.width, img.height, img.rgba.len()),
            (16, 16, 16 * 16 * 4)
        );
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
        let m = PlantMesh {
            vertices: [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 2.0]]
                .map(|p| vertex(p, [0.2, 0.8, 0.1]))
                .to_vec(),
            indices: vec![0, 1, 2],
        };
        let img = render_card(&m, 32);
        let alpha: Vec<u8> = img.rgba.chunks_exact(4).map(|p| p[3]).collect();
        let covered: f32 = alpha.iter().map(|&a| a as f32 / 255.0).sum();
        assert!(
            (covered / (32.0 * 32.0) - 0.5).abs() < 0.01,
            "covered {covered}"
        );
        assert!(
            alpha.iter().any(|&a| a > 0 && a < 255),
            "no partial pixels on the diagonal"
        );
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
            assert!(
                px[0] > 100 && px[2] == 0,
                "the red quad, nearer the camera at -y: {px:?}"
            );
        }
    }

    #[test]
    fn picture_matches_the_mesh_silhouette() {
        for recipe in Recipe::ALL {
            let p = generate(recipe, 4, [0.7, 0.3, 0.6]);
            let (m, img) = (&p.lods[0], &p.card_image);
            let alpha: Vec<u8> = img.rgba.chunks_exact(4).map(|p| p[3]).collect();
            assert!(
                alpha.iter().any(|&a| a > 200) && alpha.contains(&0),
                "{recipe:?}"
            );
            let rendered =
                alpha.iter().map(|&a| a as f32 / 255.0).sum::<f32>() / alpha.len() as f32;
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
                    let q = Vec2::new(
                        (gx as f32 + 0.5) / grid as f32 * 2.0 * r - r,
                        (gy as f32 + 0.5) / grid as f32 * h,
                    );
                    let hit = tris.iter().any(|&[a, b, c]| {
                        let e = [edge(a, b, q), edge(b, c, q), edge(c, a, q)];
                        e.iter().all(|&e| e >= 0.0) || e.iter().all(|&e| e <= 0.0)
                    });
                    inside += hit as u32;
                }
            }
            let expected = inside as f32 / (grid * grid) as f32;
            assert!(expected > 0.03, "{recipe:?}: silhouette {expected}");
            assert!(
                (rendered / expected - 1.0).abs() < 0.1,
                "{recipe:?}: rendered {rendered}, silhouette {expected}"
            );
        }
    }
}
