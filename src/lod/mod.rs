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

    /// The planes (left, right, bottom, top, near) as `(normal, offset)`, normals inward.
    pub fn planes(&self) -> [Vec4; 5] {
        self.planes
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

/// Which ring a grass tile is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Ring {
    /// Near the camera: blades at full density and detail.
    High,
    /// Beyond the high ring: blades at twice the spacing.
    Low,
}

/// The grass's default view distance in grass tiles (67 m in the default world, whose grass tiles
/// are 50 m wide): beyond it the far field stands in for the blades. It was 3 tiles until `bench
/// lod` against the truth found two as accurate for 10% less of the frame's time, and 2 until the
/// blades ending at two thirds of that paid for 9 near segments instead of 7 and still cost 3%
/// less, nearer the truth on the meadow and the tour and farther on the wind tour
/// (docs/anti-aliasing.md, "A shorter view distance" and "Nine near segments and a 67 m view as the
/// default").
pub const DEFAULT_VIEW_TILES: f64 = 4.0 / 3.0;

/// The coarsest grass tiles, in levels above the pyramid's finest level (where
/// [`RingSettings::for_pyramid`] puts them; [`crate::RendererConfig::validate_for`]): each level
/// up doubles a grass tile's edge and quadruples the blades it generates a frame (and a pool
/// slot holds), every one of them generated whatever the view distance. Two levels up the
/// default world's grass tiles are 200 m wide, 16 times the blades of its 50 m tiles.
pub const MAX_GRASS_LEVELS_UP: u8 = 2;

/// Settings of the grass rings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RingSettings {
    /// Quadtree level of grass tiles: the pyramid's finest by default, at most
    /// [`MAX_GRASS_LEVELS_UP`] levels coarser
    /// ([`crate::RendererConfig::validate_for`]).
    pub level: u8,
    /// Tiles nearer than this (3D distance to the tile's box) are high LOD, metres.
    pub high_radius_m: f64,
    /// Tiles nearer than this are low LOD; beyond it there is no grass, metres.
    pub low_radius_m: f64,
    /// A tile leaves a ring only once it is this much beyond the ring's radius, metres.
    pub hysteresis_m: f64,
}

impl RingSettings {
    /// Rings for `pyramid`: grass tiles at the finest level, radii in proportion to the tile size
    /// ([`DEFAULT_VIEW_TILES`] tiles of view distance).
    pub fn for_pyramid(pyramid: &Pyramid) -> Self {
        let level = pyramid.max_level();
        let size = pyramid.tile_size_m(level);
        Self {
            level,
            high_radius_m: 1.0 * size,
            low_radius_m: DEFAULT_VIEW_TILES * size,
            hysteresis_m: 0.1 * size,
        }
    }

    /// The most grass tiles these rings hold at once: every tile within the low radius (plus
    /// the hysteresis) of the camera, counted as the square of tiles around it.
    pub fn most_tiles(&self, pyramid: &Pyramid) -> u32 {
        let size = pyramid.tile_size_m(self.level);
        let reach = self.low_radius_m + self.hysteresis_m;
        let side = (2.0 * (reach / size).ceil() + 1.0).min(f64::from(u16::MAX)) as u32;
        side * side
    }
}

/// The grass tiles around the camera and their rings, with hysteresis: a tile keeps its ring
/// until the camera is clearly past the boundary, so hovering there flips nothing.
#[derive(Clone, Debug)]
pub struct GrassRings {
    /// The settings.
    pub settings: RingSettings,
    current: std::collections::HashMap<TileId, Ring>,
}

impl GrassRings {
    /// No tiles yet.
    pub fn new(settings: RingSettings) -> Self {
        Self {
            settings,
            current: Default::default(),
        }
    }

    /// The tiles of the last update and their rings.
    pub fn current(&self) -> Vec<(TileId, Ring)> {
        let mut v: Vec<(TileId, Ring)> = self.current.iter().map(|(k, r)| (*k, *r)).collect();
        v.sort_by_key(|t| t.0);
        v
    }

    /// Updates the rings for a camera at `eye`; `height_range(tile)` bounds a tile's heights.
    /// Returns the grass tiles and their rings, nearest first.
    pub fn update(
        &mut self,
        pyramid: &Pyramid,
        eye: DVec3,
        height_range: &dyn Fn(TileId) -> (f32, f32),
    ) -> Vec<(TileId, Ring, f64)> {
        let s = self.settings;
        let reach = s.low_radius_m + s.hysteresis_m;
        let p = glam::DVec2::new(eye.x, eye.y);
        let size = pyramid.tile_size_m(s.level);
        let [nx, ny] = pyramid.tiles_at(s.level);
        let cell = |v: f64, n: u32| ((v / size).floor().max(0.0) as i64).min(i64::from(n) - 1);
        let (x0, x1) = (cell(p.x - reach, nx), cell(p.x + reach, nx));
        let (y0, y1) = (cell(p.y - reach, ny), cell(p.y + reach, ny));
        let mut next = std::collections::HashMap::new();
        let mut out = Vec::new();
        for y in y0..=y1 {
            for x in x0..=x1 {
                let id = TileId::new(s.level, x as u32, y as u32);
                let b = pyramid.bounds(id);
                let (h0, h1) = height_range(id);
                let min = DVec3::new(b.min.x, b.min.y, f64::from(h0));
                let max = DVec3::new(b.max.x, b.max.y, f64::from(h1));
                let d = (eye.clamp(min, max) - eye).length();
                let before = self.current.get(&id).copied();
                let high = d < s.high_radius_m
                    || (before == Some(Ring::High) && d < s.high_radius_m + s.hysteresis_m);
                let low =
                    d < s.low_radius_m || (before.is_some() && d < s.low_radius_m + s.hysteresis_m);
                let ring = if high {
                    Ring::High
                } else if low {
                    Ring::Low
                } else {
                    continue;
                };
                next.insert(id, ring);
                out.push((id, ring, d));
            }
        }
        self.current = next;
        out.sort_by(|a, b| a.2.total_cmp(&b.2).then(a.0.cmp(&b.0)));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;

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
    fn rings_hold_their_tiles_at_the_boundary() {
        let p = pyramid();
        let settings = RingSettings {
            level: 3,
            high_radius_m: 100.0,
            low_radius_m: 300.0,
            hysteresis_m: 20.0,
        };
        let mut rings = GrassRings::new(settings);
        let flat = |_| (0.0, 0.0);
        // Tile (3, 2, 0) at level 3 spans x in [256, 384]: the camera hovers 101 to 111 m west of it, inside the hysteresis band.
        let id = TileId::new(3, 2, 0);
        let ring_of = |r: &[(TileId, Ring, f64)]| r.iter().find(|t| t.0 == id).map(|t| t.1);
        let at = |x: f64| DVec3::new(x, 10.0, 0.0);
        assert_eq!(
            ring_of(&rings.update(&p, at(160.0), &flat)),
            Some(Ring::High)
        );
        for k in 0..20 {
            let x = if k % 2 == 0 { 145.0 } else { 155.0 };
            assert_eq!(
                ring_of(&rings.update(&p, at(x), &flat)),
                Some(Ring::High),
                "flipped at {x}"
            );
        }
        assert_eq!(
            ring_of(&rings.update(&p, at(130.0), &flat)),
            Some(Ring::Low)
        );
        for k in 0..20 {
            let x = if k % 2 == 0 { 145.0 } else { 155.0 };
            assert_eq!(
                ring_of(&rings.update(&p, at(x), &flat)),
                Some(Ring::Low),
                "flipped at {x}"
            );
        }
        assert_eq!(
            ring_of(&rings.update(&p, at(170.0), &flat)),
            Some(Ring::High)
        );
        assert_eq!(ring_of(&rings.update(&p, at(-200.0), &flat)), None);
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
