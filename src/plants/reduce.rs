//! The reduced level of a plant read from a file: the file's mesh simplified by vertex
//! clustering (Rossignac and Borrel) to a triangle budget.
//!
//! The mesh's box is cut into cubic cells; the vertices of a cell merge into one, the vertex of
//! the cell nearest the mean of its vertices (so that its position, normal, uv and channels are
//! all one vertex's of the file); a triangle whose corners fall in fewer than three cells
//! vanishes, and of the triangles joining the same three cells one is kept. The finest grid
//! whose result fits the budget is found by bisection on the cells along the box's longest
//! edge. Robust on any input (no topology is assumed: plants are loose leaves, cards and
//! stems), at the price of thin parts narrower than a cell: those go, which a plant a few
//! tens of metres away, a few pixels high, does not miss.

use std::collections::{HashMap, HashSet};

use glam::Vec3;

use crate::plants::mesh::PlantMesh;

/// Most cells along the longest edge of the box that the bisection tries.
const MAX_CELLS: u32 = 1024;

/// `mesh` simplified to at most `max_triangles` triangles: `mesh` itself when it has no more,
/// else the vertex clustering on the finest grid that fits. Every vertex of the result is a
/// vertex of `mesh`. Never empty when `mesh` has a triangle of non-zero area and the budget is
/// at least one: when no grid keeps one (a mesh of a few large triangles folded into one
/// cell cannot happen above one cell a side, but the guarantee does not lean on that), the
/// largest triangles of `mesh` are kept instead.
pub fn reduce(mesh: &PlantMesh, max_triangles: usize) -> PlantMesh {
    if mesh.triangles() <= max_triangles {
        return mesh.clone();
    }
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for v in &mesh.vertices {
        let p = Vec3::from_array(v.position);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let extent = (hi - lo).max_element();
    let mut best: Option<PlantMesh> = None;
    if extent.is_finite() && extent > 0.0 {
        // The largest cell count whose result fits (the count of triangles kept grows with the
        // cells, not strictly: bisection finds one that fits, near the largest).
        let (mut a, mut b) = (1u32, MAX_CELLS);
        while a <= b {
            let cells = a + (b - a) / 2;
            let m = cluster(mesh, lo, extent / cells as f32, cells);
            if m.triangles() <= max_triangles {
                a = cells + 1;
                if m.triangles() > 0 {
                    best = Some(m);
                }
            } else {
                b = cells - 1;
            }
        }
    }
    best.unwrap_or_else(|| largest_triangles(mesh, max_triangles))
}

/// The vertex clustering of `mesh` on cubic cells of edge `cell` from corner `lo`, `cells` a
/// side at most.
fn cluster(mesh: &PlantMesh, lo: Vec3, cell: f32, cells: u32) -> PlantMesh {
    let last = cells.saturating_sub(1) as f32;
    let key = |p: Vec3| -> u64 {
        let c = ((p - lo) / cell)
            .floor()
            .clamp(Vec3::ZERO, Vec3::splat(last));
        (c.x as u64) | ((c.y as u64) << 21) | ((c.z as u64) << 42)
    };
    // Each vertex's cluster, numbered in the order the vertices first reach them.
    let mut ids: HashMap<u64, u32> = HashMap::new();
    let mut cluster_of = Vec::with_capacity(mesh.vertices.len());
    let mut sums: Vec<(Vec3, u32)> = Vec::new();
    for v in &mesh.vertices {
        let p = Vec3::from_array(v.position);
        let next = ids.len() as u32;
        let id = *ids.entry(key(p)).or_insert(next);
        if id == next {
            sums.push((Vec3::ZERO, 0));
        }
        sums[id as usize].0 += p;
        sums[id as usize].1 += 1;
        cluster_of.push(id);
    }
    // Each cluster's vertex: the one nearest the mean of its vertices.
    let mut chosen: Vec<Option<(f32, u32)>> = vec![None; sums.len()];
    for (i, v) in mesh.vertices.iter().enumerate() {
        let c = cluster_of[i] as usize;
        let mean = sums[c].0 / sums[c].1 as f32;
        let d = Vec3::from_array(v.position).distance_squared(mean);
        if chosen[c].is_none_or(|(best, _)| d < best) {
            chosen[c] = Some((d, i as u32));
        }
    }
    let mut out = PlantMesh::default();
    let mut out_index: Vec<Option<u32>> = vec![None; sums.len()];
    let mut seen: HashSet<[u32; 3]> = HashSet::new();
    for t in mesh.indices.chunks_exact(3) {
        let c = [t[0], t[1], t[2]].map(|i| cluster_of[i as usize]);
        if c[0] == c[1] || c[1] == c[2] || c[0] == c[2] {
            continue;
        }
        let mut sorted = c;
        sorted.sort_unstable();
        if !seen.insert(sorted) {
            continue;
        }
        for k in c {
            let slot = &mut out_index[k as usize];
            let index = *slot.get_or_insert_with(|| {
                let (_, v) = chosen[k as usize].expect("every cluster has a vertex");
                out.vertices.push(mesh.vertices[v as usize]);
                out.vertices.len() as u32 - 1
            });
            out.indices.push(index);
        }
    }
    out
}

/// The `max_triangles` triangles of `mesh` of largest area, in their order in `mesh`.
fn largest_triangles(mesh: &PlantMesh, max_triangles: usize) -> PlantMesh {
    let p = |i: u32| Vec3::from_array(mesh.vertices[i as usize].position);
    let mut by_area: Vec<(f32, usize)> = mesh
        .indices
        .chunks_exact(3)
        .enumerate()
        .map(|(k, t)| ((p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length(), k))
        .filter(|(a, _)| *a > 0.0)
        .collect();
    by_area.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    by_area.truncate(max_triangles);
    by_area.sort_by_key(|&(_, k)| k);
    let mut out = PlantMesh::default();
    let mut remap: HashMap<u32, u32> = HashMap::new();
    for (_, k) in by_area {
        for &i in &mesh.indices[3 * k..3 * k + 3] {
            let index = *remap.entry(i).or_insert_with(|| {
                out.vertices.push(mesh.vertices[i as usize]);
                out.vertices.len() as u32 - 1
            });
            out.indices.push(index);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plants::mesh::PlantVertex;

    /// An upright sheet 1 m wide and 1 m high in the x-z plane, `n` x `n` quads.
    fn sheet(n: u32) -> PlantMesh {
        let mut mesh = PlantMesh::default();
        for j in 0..=n {
            for i in 0..=n {
                let (x, z) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32);
                mesh.vertices.push(PlantVertex {
                    position: [x, 0.0, z],
                    normal: [0.0, -1.0, 0.0],
                    wind: [0.0, 0.0, z, 1.0],
                    albedo: [0.2, 0.6, 0.1, 0.5],
                    uv: [x + 0.5, 1.0 - z],
                });
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                let (b, c, d) = (a + 1, a + n + 2, a + n + 1);
                mesh.indices.extend([a, b, c, a, c, d]);
            }
        }
        mesh
    }

    /// Twice the area of the mesh's triangles seen from the side (along y).
    fn side_area(mesh: &PlantMesh) -> f32 {
        let p = |i: u32| {
            let v = mesh.vertices[i as usize].position;
            glam::Vec2::new(v[0], v[2])
        };
        mesh.indices
            .chunks_exact(3)
            .map(|t| (p(t[1]) - p(t[0])).perp_dot(p(t[2]) - p(t[0])).abs())
            .sum::<f32>()
            * 0.5
    }

    #[test]
    fn a_mesh_within_the_budget_is_kept_as_it_is() {
        let mesh = sheet(8);
        assert_eq!(mesh.triangles(), 128);
        assert_eq!(reduce(&mesh, 128), mesh);
    }

    #[test]
    fn a_dense_sheet_keeps_its_outline_within_the_budget() {
        let mesh = sheet(180);
        assert_eq!(mesh.triangles(), 64_800);
        for budget in [128, 512] {
            let r = reduce(&mesh, budget);
            assert!(
                r.triangles() <= budget && r.triangles() >= budget / 4,
                "{budget}: {} triangles",
                r.triangles()
            );
            // Every vertex is one of the sheet's, whole.
            for v in &r.vertices {
                assert!(mesh.vertices.contains(v), "{v:?}");
            }
            assert!(r.indices.iter().all(|&i| (i as usize) < r.vertices.len()));
            // The sheet's height and width, and most of its area, less a cell at the edges.
            assert!(r.height() > 0.85 && r.height() <= 1.0, "{}", r.height());
            assert!(
                r.radius() > 0.4 && r.radius() <= 0.5 + 1e-6,
                "{}",
                r.radius()
            );
            let area = side_area(&r);
            assert!((0.7..=1.0 + 1e-4).contains(&area), "{budget}: area {area}");
        }
    }

    #[test]
    fn no_triangle_is_kept_twice_and_the_result_is_the_same_every_time() {
        // Two sheets on top of each other, the second wound the other way.
        let mut mesh = sheet(60);
        let n = mesh.vertices.len() as u32;
        let second = sheet(60);
        mesh.vertices.extend(second.vertices);
        mesh.indices.extend(
            second
                .indices
                .chunks_exact(3)
                .flat_map(|t| [t[0] + n, t[2] + n, t[1] + n]),
        );
        let r = reduce(&mesh, 200);
        assert!(r.triangles() <= 200 && r.triangles() > 0);
        let mut seen = HashSet::new();
        for t in r.indices.chunks_exact(3) {
            let p = |i: u32| r.vertices[i as usize].position.map(f32::to_bits);
            let mut key = [p(t[0]), p(t[1]), p(t[2])];
            key.sort_unstable();
            assert!(seen.insert(key), "{key:?} twice");
        }
        assert_eq!(reduce(&mesh, 200), r);
    }

    #[test]
    fn a_budget_no_grid_meets_keeps_the_largest_triangles() {
        // Two cells a side already keep two triangles of this sheet (and one cell none): with
        // a budget of one, the largest triangle is kept, the first of equals.
        let mesh = sheet(4);
        let r = reduce(&mesh, 1);
        assert_eq!(r.triangles(), 1);
        let first: Vec<_> = mesh.indices[..3]
            .iter()
            .map(|&i| mesh.vertices[i as usize])
            .collect();
        let kept: Vec<_> = r.indices.iter().map(|&i| r.vertices[i as usize]).collect();
        assert_eq!(kept, first);
        // A larger triangle among them is the one kept.
        let mut mesh = mesh;
        let base = mesh.vertices.len() as u32;
        for p in [[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 1.0]] {
            mesh.vertices.push(PlantVertex {
                position: p,
                ..mesh.vertices[0]
            });
        }
        mesh.indices.extend([base, base + 1, base + 2]);
        let r = reduce(&mesh, 1);
        assert_eq!(r.triangles(), 1);
        assert_eq!(r.height(), 1.0);
        assert_eq!(side_area(&r), 0.5);
    }
}
