use super::*;
use crate::plants::mesh::PlantVertex;

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
            Recipe::Broadleaf => 3000,
            Recipe::Conifer => 2000,
        };
        for seed in seeds() {
            let [(l0, _), (l1, _)] = build(recipe, seed, ACCENT);
            let (t0, t1) = (l0.triangles(), l1.triangles());
            assert!(
                t0 <= budget && t0 >= budget / 4,
                "{recipe:?} {seed}: {t0} triangles"
            );
            let reduced = match recipe {
                Recipe::Flower => 24,
                Recipe::Fern => 80,
                Recipe::Bush => 140,
                Recipe::Broadleaf => 450,
                Recipe::Conifer => 120,
            };
            assert!(
                t1 <= reduced && t1 * 5 <= t0,
                "{recipe:?} {seed}: lod 1 {t1} of {t0}"
            );
            // The same silhouette size.
            assert!(
                (l1.height() / l0.height() - 1.0).abs() < 0.15,
                "{recipe:?} {seed}: height {} against {}",
                l1.height(),
                l0.height()
            );
            assert!(
                (l1.radius() / l0.radius() - 1.0).abs() < 0.2,
                "{recipe:?} {seed}: radius {} against {}",
                l1.radius(),
                l0.radius()
            );
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
                    assert!(
                        (n - 1.0).abs() < 1e-3,
                        "{recipe:?} {seed}: normal length {n}"
                    );
                    for c in v.wind.iter().chain(&v.albedo).chain(&v.uv) {
                        assert!((0.0..=1.0).contains(c), "{recipe:?} {seed}: channel {c}");
                    }
                }
                // Each triangle's winding agrees with its vertices' normals (the front).
                for t in m.indices.chunks_exact(3) {
                    let face = (pos(&m, t[1]) - pos(&m, t[0])).cross(pos(&m, t[2]) - pos(&m, t[0]));
                    let n: Vec3 = t
                        .iter()
                        .map(|&i| Vec3::from(m.vertices[i as usize].normal))
                        .sum();
                    assert!(
                        face.dot(n) >= 0.0,
                        "{recipe:?} {seed}: triangle against its normals"
                    );
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
            let low = m
                .vertices
                .iter()
                .map(|v| v.position[2])
                .fold(f32::MAX, f32::min);
            assert!(
                low > -0.05 && low <= 0.01,
                "{recipe:?} {seed}: lowest point {low}"
            );
            // `w` spans the farthest leaf tips: the crown itself is narrower.
            if recipe == Recipe::Bush {
                assert!(
                    h <= 1.0 && (0.8..=1.6).contains(&(w / h)),
                    "bush {seed}: {h} high, {w} wide"
                );
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
                    assert!(
                        vs.iter().all(|v| v.wind[1] == vs[0].wind[1]),
                        "{recipe:?} {seed}: phase"
                    );
                    match p.kind {
                        Kind::Leaf | Kind::Petal => {
                            // Midrib 0, edge 1; thin.
                            assert!(
                                vs.iter().any(|v| v.wind[0] == 0.0)
                                    && vs.iter().any(|v| v.wind[0] == 1.0)
                            );
                            assert!(vs.iter().all(|v| v.albedo[3] >= 0.8));
                        }
                        Kind::Stem => {
                            assert!(vs.iter().all(|v| v.wind[0] == 0.0 && v.albedo[3] == WOODY))
                        }
                        Kind::Centre => {}
                    }
                    if p.kind == Kind::Petal {
                        let k = vs[0].albedo[0] / ACCENT[0];
                        assert!((0.85..1.15).contains(&k), "petal colour {:?}", vs[0].albedo);
                    }
                }
                // Leaves of neighbouring parts flutter out of step.
                let phases: std::collections::HashSet<u32> = parts
                    .iter()
                    .map(|p| m.vertices[p.first].wind[1].to_bits())
                    .collect();
                assert!(
                    phases.len() * 10 >= parts.len() * 9,
                    "{recipe:?} {seed}: phases repeat"
                );
            }
        }
    }
}

/// Mean of `f` over the vertices in the bottom and the top third of the height.
fn thirds(m: &PlantMesh, f: impl Fn(&PlantVertex) -> f32) -> (f32, f32) {
    let h = m.height();
    let mean = |keep: &dyn Fn(f32) -> bool| {
        let vs: Vec<f32> = m
            .vertices
            .iter()
            .filter(|v| keep(v.position[2] / h))
            .map(&f)
            .collect();
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
                assert!(
                    high > low + 0.1,
                    "{recipe:?} {seed} lod {lod}: b {low} .. {high}"
                );
                let (low, high) = thirds(m, |v| v.wind[3]);
                assert!(
                    high > low,
                    "{recipe:?} {seed} lod {lod}: ao {low} .. {high}"
                );
                // A tree's trunk is thicker: its root ring lies further from the axis.
                let near = if recipe.is_tree() { 0.06 } else { 0.03 };
                let root = m
                    .vertices
                    .iter()
                    .filter(|v| Vec3::from(v.position).length() < near);
                assert!(
                    root.clone().count() > 0
                        && root.clone().all(|v| v.wind[2] < 0.1 && v.wind[3] < 0.45)
                );
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
        let counts: std::collections::HashSet<usize> = (0..8)
            .map(|s| build(recipe, s, ACCENT)[0].1.len())
            .collect();
        assert!(
            counts.len() >= 2,
            "{recipe:?}: the same parts for every seed"
        );
    }
    // The accent colours the flower's petals and the fern's and bush's leaves.
    for recipe in Recipe::ALL {
        let [a, b] = [[0.9, 0.1, 0.1], [0.1, 0.1, 0.9]].map(|c| {
            let [(m, _), _] = build(recipe, 9, c);
            m
        });
        assert_eq!(a.indices, b.indices);
        assert!(
            a.vertices
                .iter()
                .zip(&b.vertices)
                .any(|(x, y)| x.albedo[0] > y.albedo[0] + 0.3)
        );
    }
}

#[test]
fn card_matches_the_full_mesh() {
    let p = generate(Recipe::Fern, 3, ACCENT);
    assert_eq!(p.card, crossed_cards(&p.lods[0]));
    assert_eq!(
        (p.card_image.width, p.card_image.height),
        (CARD_SIZE, CARD_SIZE)
    );
    assert!((p.card.height() - p.lods[0].height()).abs() < 1e-6);
    assert!((p.card.radius() - p.lods[0].radius()).abs() < 1e-6);
}

/// The area a mesh covers seen from the side (looking along +y) and from above, square metres:
/// its card picture's coverage times the picture's box (from above, the mesh turned so that its
/// y axis stands up).
fn covered_area(mesh: &PlantMesh) -> [f32; 2] {
    let area = |m: &PlantMesh| {
        let img = crate::plants::card::render_card(m, 96);
        let alpha: f32 = img
            .rgba
            .chunks_exact(4)
            .map(|p| f32::from(p[3]) / 255.0)
            .sum();
        let share = alpha / (img.width * img.height) as f32;
        share * 2.0 * m.radius().max(1e-3) * m.height().max(1e-3)
    };
    let reach = mesh.radius();
    let mut above = mesh.clone();
    for v in &mut above.vertices {
        let [x, y, z] = v.position;
        v.position = [x, z, y + reach];
    }
    [area(mesh), area(&above)]
}

#[test]
fn the_reduced_level_covers_about_what_the_full_mesh_covers() {
    // Where the reduced mesh is drawn a plant is a few pixels: what it covers there is its
    // colour's weight against the ground behind it, so the reduced level keeps the full
    // mesh's cover, from the side and from above, within the spread of the seeds.
    for recipe in Recipe::ALL {
        for seed in seeds() {
            let [(l0, _), (l1, _)] = build(recipe, seed, ACCENT);
            let (full, reduced) = (covered_area(&l0), covered_area(&l1));
            for (view, (f, r)) in ["side", "above"].iter().zip(full.iter().zip(&reduced)) {
                let k = r / f;
                assert!(
                    (0.6..1.4).contains(&k),
                    "{recipe:?} {seed} from {view}: the reduced level covers {r:.3} m2, the full \
                     mesh {f:.3} m2 ({k:.2}x)"
                );
            }
        }
    }
}
