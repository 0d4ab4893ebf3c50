//! Level-of-detail selection: which terrain tiles a camera needs, at which level.
//!
//! A quadtree walk from the level-0 tiles: a tile is split into its four children while the
//! camera is closer to it than `lod_factor` times its edge length, down to the finest level
//! available. Tiles outside the view frustum are dropped before they are split.

use glam::{DVec3, Mat4, Vec3, Vec4};

use crate::world::{Pyramid, TileId};

/// The planes of a view frustum in camera-relative space, normals pointing inwards.
#[derive(Clone, Copy, Debug)]
pub struct Frustum {
    planes: [Vec4; 5],
}

impl Frustum {
    /// Extracts the side and near planes of a (reverse-Z, infinite) view-projection matrix.
    pub fn from_view_proj(m: Mat4) -> Self {
        let r = |i: usize| m.row(i);
        let planes = [
            r(3) + r(0),
            r(3) - r(0),
            r(3) + r(1),
            r(3) - r(1),
            r(3) - r(2),
        ]
        .map(|p| {
            let n = p.truncate().length();
            if n > 0.0 { p / n } else { p }
        });
        Self { planes }
    }

    /// A frustum that rejects nothing.
    pub fn everything() -> Self {
        Self {
            planes: [Vec4::ZERO; 5],
        }
    }

    /// Whether any part of the box `[min, max]` may be inside.
    pub fn intersects_box(&self, min: Vec3, max: Vec3) -> bool {
        self.planes.iter().all(|p| {
            let n = p.truncate();
            let v = Vec3::select(n.cmpge(Vec3::ZERO), max, min);
            n.dot(v) + p.w >= 0.0
        })
    }
}

/// Settings of the terrain quadtree.
#[derive(Clone, Copy, Debug)]
pub struct TerrainLod {
    /// A tile is split while the camera is nearer than this many tile edges.
    pub lod_factor: f64,
    /// The finest level to select.
    pub max_level: u8,
}

impl TerrainLod {
    /// Distance at which a tile of `level` starts morphing toward its parent's grid. The morph
    /// ends at 1.25 times this, at twice the split distance: the nearest a coarser neighbour can
    /// be.
    pub fn morph_start(&self, pyramid: &Pyramid, level: u8) -> f32 {
        (1.6 * self.lod_factor * pyramid.tile_size_m(level)) as f32
    }
}

/// Selects terrain tiles for a camera at `eye`. `height_range(tile)` bounds a tile's heights,
/// `frustum` is in camera-relative space. The result covers every visible part of the world
/// exactly once, coarse to fine.
pub fn select_terrain(
    pyramid: &Pyramid,
    lod: TerrainLod,
    eye: DVec3,
    frustum: &Frustum,
    height_range: &dyn Fn(TileId) -> (f32, f32),
) -> Vec<TileId> {
    let mut out = Vec::new();
    let [nx, ny] = pyramid.tiles_at(0);
    let mut stack: Vec<TileId> = (0..ny)
        .flat_map(|y| (0..nx).map(move |x| TileId::new(0, x, y)))
        .collect();
    stack.reverse();
    while let Some(id) = stack.pop() {
        let b = pyramid.bounds(id);
        let (h0, h1) = height_range(id);
        let min = DVec3::new(b.min.x, b.min.y, f64::from(h0));
        let max = DVec3::new(b.max.x, b.max.y, f64::from(h1));
        // A little slack below for the skirts.
        let skirt = pyramid.cell_size_m(id.level);
        let rel_min = (min - eye - DVec3::new(0.0, 0.0, skirt)).as_vec3();
        let rel_max = (max - eye).as_vec3();
        if !frustum.intersects_box(rel_min, rel_max) {
            continue;
        }
        let nearest = eye.clamp(min, max);
        let distance = (nearest - eye).length();
        let size = pyramid.tile_size_m(id.level);
        if id.level < lod.max_level && distance < lod.lod_factor * size {
            let mut children = id.children();
            children.reverse();
            stack.extend(children);
        } else {
            out.push(id);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flythrough::Camera;

    fn pyramid() -> Pyramid {
        Pyramid {
            root_tile_size_m: 1024.0,
            root_tiles: [2, 2],
            tile_cells: 16,
            border: 2,
            stored_levels: 4,
            derived_levels: 0,
        }
    }

    #[test]
    fn selection_covers_the_world_once_and_is_finest_near_the_eye() {
        let p = pyramid();
        let cam = Camera::new(DVec3::new(100.0, 100.0, 50.0), 45.0, -89.0);
        let f = Frustum::everything();
        let tiles = select_terrain(
            &p,
            TerrainLod {
                lod_factor: 1.5,
                max_level: 3,
            },
            cam.position,
            &f,
            &|_| (0.0, 10.0),
        );
        let area: f64 = tiles.iter().map(|t| p.tile_size_m(t.level).powi(2)).sum();
        assert!(
            (area - 2048.0 * 2048.0).abs() < 1e-6,
            "tiles overlap or leave gaps"
        );
        let under = tiles
            .iter()
            .find(|t| p.bounds(**t).contains(glam::DVec2::new(100.0, 100.0)))
            .unwrap();
        assert_eq!(under.level, 3);
        let far = tiles
            .iter()
            .find(|t| p.bounds(**t).contains(glam::DVec2::new(2000.0, 2000.0)))
            .unwrap();
        assert!(far.level < 3);
    }

    #[test]
    fn frustum_rejects_what_is_behind() {
        let cam = Camera::new(DVec3::ZERO, 0.0, 0.0);
        let f = Frustum::from_view_proj(cam.view_proj_relative(1.0));
        assert!(f.intersects_box(Vec3::new(10.0, -1.0, -1.0), Vec3::new(11.0, 1.0, 1.0)));
        assert!(!f.intersects_box(Vec3::new(-11.0, -1.0, -1.0), Vec3::new(-10.0, 1.0, 1.0)));
        assert!(!f.intersects_box(Vec3::new(10.0, 50.0, -1.0), Vec3::new(11.0, 60.0, 1.0)));
    }
}
