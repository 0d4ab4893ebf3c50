//! CPU mirror of the plant placement (`shaders/plants_place.wgsl`), and the records it shares
//! with the GPU: the frame's constants, the plant types' constants and the instance.
//!
//! Each job (a grass tile in view, or beyond the grass a tile's share of a coarser terrain tile:
//! [`PlantJob`]) is split into cells of [`crate::plants::PLANT_CELL_M`]; a cell holds at most one
//! plant. A hash of the cell's world address jitters its spot and draws a number
//! that picks a type by the types' densities on the grass under it, so that the choice is the
//! same whichever tile or frame asks (no seams, no flicker). Slope, altitude, the hand-over at the
//! view distance, the frustum and the terrain's Hi-Z then cull it; the survivor goes to a level
//! of detail by distance, cross-faded by a dither over a band around each switch.
//!
//! The hand-over: a grass tile's job keeps a plant with the chance that falls from 1 to 0 over
//! the thinning band before the view distance (by the plant's own dithered number); a far job
//! keeps exactly the others, thinned again toward the end of the cards' reach. Each plant near
//! the view distance is therefore placed by one job, whichever side of the band it falls.
//!
//! Crowding: each (type, level) region of the pool counts what it wanted by distance
//! ([`crowd_bin`]); where that was more than fits ([`crowd_fill`]), the next frame thins the
//! region's plants from the distance [`crowd_distances`] finds, each by its own number
//! ([`crowd_keep`]), so that the same plants stay frame after frame and the nearest all stay.

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::grass::{HiZ, TileJob};
use crate::hash::{hash_u32, hash3, rand01};
use crate::world::TileData;

/// Levels of detail of a plant: the full mesh, the reduced mesh, the crossed cards.
pub const LEVELS: usize = 3;
/// Most plant types the stage draws ([`crate::world::MAX_PLANT_TYPES`]).
pub const TYPES: usize = 8;
/// Regions of the instance pool: one per (type, level), `type * LEVELS + level`.
pub const REGIONS: usize = TYPES * LEVELS;

/// Counter indices of the placement's statistics.
pub mod counter {
    /// Cells looked at.
    pub const CONSIDERED: usize = 0;
    /// Cells the draw left without a plant.
    pub const EMPTY: usize = 1;
    /// Plants the slope or altitude limits ruled out.
    pub const RULED_OUT: usize = 2;
    /// Plants thinned out toward the view distance (a grass tile's job) or toward the end of the
    /// cards' reach (a far job).
    pub const DISTANCE: usize = 3;
    /// Plants outside the frustum.
    pub const FRUSTUM: usize = 4;
    /// Plants behind the terrain (Hi-Z).
    pub const OCCLUSION: usize = 5;
    /// Instances that did not fit their region.
    pub const OVERFLOW: usize = 6;
    /// Instances drawn.
    pub const DRAWN: usize = 7;
    /// Instances thinned out because their region was crowded the frame before
    /// ([`super::crowd_distances`]; a plant in a cross-fade counts twice, as it does drawn).
    pub const CROWDED: usize = 8;
    /// Counters.
    pub const COUNT: usize = 9;
}

/// The share of a region's capacity that the thinning of crowded regions aims to fill, so that
/// a view that grows by less than the margin between frames does not overflow.
pub const CROWD_FILL: f32 = 0.95;

/// The instances a crowded region of `capacity` aims to hold: [`CROWD_FILL`] of it, and at
/// least three standard deviations of the thinning's draw below it (each plant is kept by its
/// own number, so the count kept varies about its aim by up to its square root).
pub fn crowd_fill(capacity: u32) -> f32 {
    let c = capacity as f32;
    (CROWD_FILL * c).min(c - 3.0 * c.sqrt()).max(1.0)
}

/// Distance bins of what each region wants, a quarter of an octave each from
/// [`CROWD_NEAR_M`] (the first holds everything nearer): out to 131 km.
pub const CROWD_BINS: usize = 64;
/// The near edge of the second distance bin, metres.
pub const CROWD_NEAR_M: f32 = 2.0;
/// A region's distance from which it thins when nothing crowds it.
pub const UNCROWDED: f32 = f32::MAX;

/// The distance bin of a plant `dist` metres away.
pub fn crowd_bin(dist: f32) -> usize {
    let b = (4.0 * (dist.max(1e-6) / CROWD_NEAR_M).log2()).floor() + 1.0;
    b.clamp(0.0, (CROWD_BINS - 1) as f32) as usize
}

/// The near edge of distance bin `b`, metres (0 for the first).
pub fn crowd_bin_near(b: usize) -> f32 {
    if b == 0 {
        0.0
    } else {
        CROWD_NEAR_M * ((b - 1) as f32 * 0.25).exp2()
    }
}

/// The chance of keeping a plant `dist` metres away in a region crowded from `from_m`: 1 within
/// it, falling beyond as the square of the distance (as the thinning with distance).
pub fn crowd_keep(dist: f32, from_m: f32) -> f32 {
    if dist <= from_m {
        1.0
    } else {
        (from_m / dist) * (from_m / dist)
    }
}

/// Each region's distance from which to thin its plants in the next frame, from what it wanted
/// this frame by distance (`wanted`: instances per region and [`crowd_bin`], `region *
/// CROWD_BINS + bin`, before any thinning for crowding) and the regions' `capacity`:
/// [`UNCROWDED`] where they fit within [`crowd_fill`], else the distance whose thinning ([`crowd_keep`]) would keep no more than that, counting each
/// bin's plants as at its near edge (so that the estimate is never short), found by bisection.
/// The nearest plants of a crowded region are kept, the farthest thinned most. Mirrors
/// `finalize_draws` in the shader.
pub fn crowd_distances(wanted: &[u32], capacity: u32) -> [f32; REGIONS] {
    let fit = crowd_fill(capacity);
    let near: [f32; CROWD_BINS] = std::array::from_fn(crowd_bin_near);
    let mut out = [UNCROWDED; REGIONS];
    for (d, bins) in out.iter_mut().zip(wanted.chunks_exact(CROWD_BINS)) {
        let total: f32 = bins.iter().map(|&n| n as f32).sum();
        if total <= fit {
            continue;
        }
        let kept = |from: f32| -> f32 {
            let mut k = 0.0;
            for (&n, &edge) in bins.iter().zip(&near) {
                k += n as f32 * crowd_keep(edge, from);
            }
            k
        };
        let (mut lo, mut hi) = (0.0f32, near[CROWD_BINS - 1] * 2.0);
        for _ in 0..CROWD_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if kept(mid) <= fit {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        *d = lo;
    }
    out
}

/// Steps of the bisection of [`crowd_distances`].
pub const CROWD_BISECTIONS: u32 = 40;

const SALT_CELL: u32 = 0x9e1a7;
const SALT_CLUMP: u32 = 0x5c1f3;

/// The fewest plants the thinning with distance keeps by default
/// ([`crate::plants::PlantSettings::min_keep`]): at most half go, each survivor grown by at most
/// the square root of 2.
pub const MIN_KEEP: f32 = 0.5;

/// A plant type's constants; mirrors `PlantType` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PlantTypeGpu {
    /// x, y: height range (m); z: cosine of the steepest slope; w: clump cell (m).
    pub size: [f32; 4],
    /// x, y: altitude range (m); z: the share of the ground its clumps cover; w: bounding
    /// radius over height.
    pub limits: [f32; 4],
    /// Plants per square metre on each of 16 grass types.
    pub density: [[f32; 4]; 4],
    /// x: the type's own switch from level 0 to 1 (m; nearer than the settings' for a heavy mesh
    /// read from a file, `crate::plants::renderer::full_mesh_switch`): it switches at the nearer
    /// of this and `PlaceParams::lod`'s; y, z, w unused.
    pub lod: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<PlantTypeGpu>() == 112);

/// The placement's frame constants; mirrors `Params` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PlaceParams {
    /// Camera-relative view-projection.
    pub view_proj: [[f32; 4]; 4],
    /// Frustum planes (left, right, bottom, top, near; the sixth unused), inward normals.
    pub planes: [[f32; 4]; 6],
    /// x: camera altitude (m), y: near plane (m), z, w: Hi-Z width and height (texels).
    pub camera: [f32; 4],
    /// x: cells along a tile edge, y: tile data cells, z: border samples, w: seed.
    pub grid: [u32; 4],
    /// x: cell edge (m), y: tile edge (m), z: start of the thinning toward the view distance
    /// (m), w: the view distance (m).
    pub dims: [f32; 4],
    /// x: switch from level 0 to 1 (m; a type switches at the nearer of this and its own
    /// `PlantTypeGpu::lod`), y: from level 1 to the cards (m), z: width of each cross-fade band
    /// (m); w unused.
    pub lod: [f32; 4],
    /// Far jobs: x: start of their thinning (m), y: the end of the cards' reach (m); z: where
    /// the plants start to thin out with distance, survivors grown to keep the cover (m); w: the
    /// fewest of them the thinning keeps.
    pub cards: [f32; 4],
    /// x: Hi-Z mips, y: instances a region holds, z: plant types, w: grass types.
    pub limits: [u32; 4],
    /// Hi-Z levels: offset (floats), width, height, unused.
    pub hiz_levels: [[u32; 4]; 16],
    /// Per plant type.
    pub types: [PlantTypeGpu; TYPES],
    /// Per region: index count, first index (into the packed, global indices), unused.
    pub meshes: [[u32; 4]; REGIONS],
}
const _: () =
    assert!(std::mem::size_of::<PlaceParams>() == 64 + 96 + 16 * 6 + 256 + 112 * 8 + 16 * 24);

/// One plant to draw; mirrors `PlantInstance` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PlantInstance {
    /// The root relative to the camera, metres.
    pub pos: [f32; 3],
    /// Turn about the vertical, radians.
    pub yaw: f32,
    /// Height, metres (the unit mesh's scale).
    pub scale: f32,
    /// Type in the low 8 bits, level of detail above.
    pub kind: u32,
    /// The cell's hash (phases and variation).
    pub hash: u32,
    /// The share of its pixels drawn in a cross-fade: `f > 0` keeps pixels whose dither is
    /// below `f`, `f < 0` those at or above `-f`; 1 outside a band.
    pub fade: f32,
}
const _: () = assert!(std::mem::size_of::<PlantInstance>() == 32);

impl PlantInstance {
    /// The plant type.
    pub fn plant_type(&self) -> usize {
        (self.kind & 0xff) as usize
    }

    /// The level of detail (0 the full mesh .. 2 the cards).
    pub fn level(&self) -> usize {
        (self.kind >> 8) as usize
    }
}

/// One job of the placement: a grass tile's worth of cells (its address at the grass level), read
/// from a tile's data in the atlas: the grass tile's own (a near job) or a coarser terrain tile
/// that holds it (a far job, which places only beyond the grass's hand-over); mirrors `PlantJob`
/// in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PlantJob {
    /// The job's south-west corner relative to the camera, metres.
    pub origin: [f32; 2],
    /// The job's corner in its data tile, data cells from the tile's own corner (0 for a grass
    /// tile's own data).
    pub texel: [f32; 2],
    /// Cell size of the data tile, metres.
    pub cell: f32,
    /// Atlas slot of the data tile.
    pub layer: u32,
    /// The job's address at the grass level.
    pub tile_x: u32,
    /// The job's address at the grass level.
    pub tile_y: u32,
    /// 0: a grass tile's job (plants up to the view distance); 1: a far job (beyond it).
    pub far: u32,
    /// Cells along the job's edge; 0: the grid's (`PlaceParams::grid[0]`). The job's address
    /// (`tile_x`, `tile_y`) counts jobs of this size, so that a cell's world address, and with
    /// it its plant, is the same whatever the size of the job that places it.
    pub cells: u32,
    /// Padding to 48 bytes.
    pub pad: [u32; 2],
}
const _: () = assert!(std::mem::size_of::<PlantJob>() == 48);

impl PlantJob {
    /// The near job of a grass tile's generation job.
    pub fn near(job: &TileJob) -> Self {
        Self {
            origin: job.origin,
            texel: [0.0; 2],
            cell: job.cell,
            layer: job.layer,
            tile_x: job.tile_x,
            tile_y: job.tile_y,
            far: 0,
            cells: 0,
            pad: [0; 2],
        }
    }
}

/// What one tile's placement produced: every instance (before any region's capacity), the
/// counters (without overflow and drawn, which depend on the whole frame) and what each region
/// wanted before the thinning of crowded regions.
#[derive(Clone, Debug)]
pub struct TilePlants {
    /// Instances in cell order.
    pub instances: Vec<PlantInstance>,
    /// `counter::*`.
    pub stats: [u32; counter::COUNT],
    /// Per region (`type * LEVELS + level`) and distance bin ([`crowd_bin`]), `region *
    /// CROWD_BINS + bin`: the instances that passed every test but the thinning of crowded
    /// regions (what [`crowd_distances`] reads).
    pub wanted: Vec<u32>,
}

impl Default for TilePlants {
    fn default() -> Self {
        Self {
            instances: Vec::new(),
            stats: [0; counter::COUNT],
            wanted: vec![0; REGIONS * CROWD_BINS],
        }
    }
}

/// Value noise in [0, 1) on the lattice of clump cells, salted.
fn clump_noise(c: [i32; 2], f: Vec2, salt: u32) -> f32 {
    let u = f * f * (Vec2::splat(3.0) - 2.0 * f);
    let r = |x: i32, y: i32| rand01(hash3(x as u32, y as u32, salt));
    let (a, b) = (r(c[0], c[1]), r(c[0] + 1, c[1]));
    let (cc, d) = (r(c[0], c[1] + 1), r(c[0] + 1, c[1] + 1));
    let ab = a + (b - a) * u.x;
    let cd = cc + (d - cc) * u.x;
    ab + (cd - ab) * u.y
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// How much denser than its mean type `t` grows at world cell `cell`.
fn clump_factor(params: &PlaceParams, t: usize, cell: [u32; 2]) -> f32 {
    let ty = &params.types[t];
    let cover = ty.limits[2];
    if cover >= 1.0 {
        return 1.0;
    }
    let per = ty.size[3] / params.dims[0];
    let p = (Vec2::new(cell[0] as f32, cell[1] as f32) + 0.5) / per;
    let fl = p.floor();
    let salt = params.grid[3] ^ SALT_CLUMP ^ (t as u32).wrapping_mul(0x3779);
    let n = clump_noise([fl.x as i32, fl.y as i32], p - fl, salt);
    let edge = 1.0 - cover;
    smoothstep(edge - 0.08, edge + 0.08, n) / cover
}

impl PlantJob {
    /// Cells along the job's edge.
    pub fn cells(&self, params: &PlaceParams) -> u32 {
        if self.cells == 0 {
            params.grid[0]
        } else {
            self.cells
        }
    }
}

/// Places and culls the plants of one job (its data tile `tile`), as the shader does in a
/// frame where no region was crowded the frame before.
pub fn place_tile(params: &PlaceParams, job: &PlantJob, tile: &TileData, hiz: &HiZ) -> TilePlants {
    place_tile_crowded(params, &[UNCROWDED; REGIONS], job, tile, hiz)
}

/// Places and culls the plants of one job (its data tile `tile`), as the shader does, each
/// region thinning its plants from the distance `crowded_from` gives it ([`crowd_distances`]
/// of the frame before; [`UNCROWDED`]: none).
pub fn place_tile_crowded(
    params: &PlaceParams,
    crowded_from: &[f32; REGIONS],
    job: &PlantJob,
    tile: &TileData,
    hiz: &HiZ,
) -> TilePlants {
    let mut out = TilePlants::default();
    let n = job.cells(params);
    for gy in 0..n {
        for gx in 0..n {
            place_cell(params, crowded_from, job, tile, hiz, [gx, gy], &mut out);
        }
    }
    out
}

fn place_cell(
    params: &PlaceParams,
    crowded_from: &[f32; REGIONS],
    job: &PlantJob,
    tile: &TileData,
    hiz: &HiZ,
    [gx, gy]: [u32; 2],
    out: &mut TilePlants,
) {
    let stats = &mut out.stats;
    let n = job.cells(params);
    let cell_m = params.dims[0];
    let world_cell = [job.tile_x * n + gx, job.tile_y * n + gy];
    let h0 = hash3(world_cell[0], world_cell[1], params.grid[3] ^ SALT_CELL);
    let jitter = Vec2::new(rand01(hash_u32(h0 ^ 1)), rand01(hash_u32(h0 ^ 2))) - 0.5;
    let local = (Vec2::new(gx as f32, gy as f32) + 0.5 + 0.9 * jitter) * cell_m;

    let border = params.grid[2] as f32;
    let tp = Vec2::splat(border) + Vec2::from_array(job.texel) + local / job.cell;
    // Height, density and normal as the grass's generation samples them.
    let sampled = crate::grass::generate_cpu::sample(tile, tp.to_array(), job.cell);
    let (ground, density) = (sampled.height, sampled.density);
    let origin = Vec2::from_array(job.origin);
    let pos = (origin + local).extend(ground - params.camera[0]);
    let dist = pos.length();
    // The hand-over at the view distance: the grass tile's job keeps the plants whose number is
    // below `near`, a far job the rest (and does not count the others: they are the near job's).
    let [_, _, thin_start, view] = params.dims;
    let near = ((view - dist) / (view - thin_start).max(1e-3)).clamp(0.0, 1.0);
    let handed = rand01(hash_u32(h0 ^ 5));
    if job.far != 0 && handed < near {
        return;
    }
    stats[counter::CONSIDERED] += 1;
    let s = tile.size as i32;
    let (nx, ny) = ((tp.x + 0.5).floor() as i32, (tp.y + 0.5).floor() as i32);
    let texel = (ny.clamp(0, s - 1) * s + nx.clamp(0, s - 1)) as usize;
    let kind = usize::from(tile.grass_type[texel]).min(15);

    let u = rand01(hash_u32(h0 ^ 3));
    let mut acc = 0.0f32;
    let mut chosen = None;
    for t in 0..(params.limits[2] as usize).min(TYPES) {
        let dens = params.types[t].density[kind / 4][kind % 4];
        if dens <= 0.0 {
            continue;
        }
        acc += dens * density * cell_m * cell_m * clump_factor(params, t, world_cell);
        if u < acc {
            chosen = Some(t);
            break;
        }
    }
    let Some(t) = chosen else {
        stats[counter::EMPTY] += 1;
        return;
    };
    let ty = &params.types[t];
    let normal = sampled.normal;
    if normal.z < ty.size[2] || ground < ty.limits[0] || ground > ty.limits[1] {
        stats[counter::RULED_OUT] += 1;
        return;
    }
    let mut scale = ty.size[0] + (ty.size[1] - ty.size[0]) * rand01(hash_u32(h0 ^ 4));
    let kept = if job.far == 0 {
        handed < near
    } else {
        // Beyond the view distance: thinned out toward the end of the cards' reach.
        let [start, end, _, _] = params.cards;
        let reach = ((end - dist) / (end - start).max(1e-3)).clamp(0.0, 1.0);
        rand01(hash_u32(h0 ^ 7)) < reach
    };
    // Beyond `cards[2]` the plants thin out as the square of the distance, each survivor grown
    // to keep the cover.
    let min_keep = params.cards[3];
    let keep = (params.cards[2] * params.cards[2] / (dist * dist).max(1e-6)).clamp(min_keep, 1.0);
    if !kept || rand01(hash_u32(h0 ^ 8)) >= keep {
        stats[counter::DISTANCE] += 1;
        return;
    }
    // The level by distance, cross-faded over a band centred on each switch.
    let [to_1, to_card, band, _] = params.lod;
    let to_1 = to_1.min(ty.lod[0]);
    let half = 0.5 * band;
    let (level, t_band) = if dist < to_1 + half {
        (0u32, (dist - (to_1 - half)) / band.max(1e-3))
    } else if dist < to_card + half {
        (1, (dist - (to_card - half)) / band.max(1e-3))
    } else {
        (2, -1.0)
    };
    let faded = level < 2 && t_band > 0.0;
    let region = t * LEVELS + level as usize;
    // A region crowded the frame before thins from a distance, keeping a plant by its own
    // number (a plant in a cross-fade by the more crowded of its two regions); the survivors
    // grow to keep the cover as the thinning with distance grows them, together by no more
    // than that thinning alone may.
    let from = if faded {
        crowded_from[region].min(crowded_from[region + 1])
    } else {
        crowded_from[region]
    };
    let crowd = crowd_keep(dist, from);
    let crowd_kept = rand01(hash_u32(h0 ^ 9)) < crowd;
    let grown = scale / (keep * crowd).max(min_keep).sqrt();
    // The culling sphere of a crowded region holds the plant however much it grows (so that
    // what the region wants does not follow how crowded it was, only whether it was).
    let reach = if from < UNCROWDED {
        scale / min_keep.sqrt()
    } else {
        grown
    };
    scale = grown;
    let radius = reach * ty.limits[3].max(0.5);
    let center = pos + Vec3::new(0.0, 0.0, 0.5 * reach);
    let outside = params.planes[..5]
        .iter()
        .any(|p| Vec4::from_array(*p).truncate().dot(center) + p[3] < -radius);
    if outside {
        stats[counter::FRUSTUM] += 1;
        return;
    }
    let view_proj = Mat4::from_cols_array_2d(&params.view_proj);
    if crate::grass::generate_cpu::sphere_occluded(
        &view_proj,
        params.camera,
        params.limits[0],
        hiz,
        center,
        radius,
    ) {
        stats[counter::OCCLUSION] += 1;
        return;
    }
    let bin = crowd_bin(dist);
    out.wanted[region * CROWD_BINS + bin] += 1;
    if faded {
        out.wanted[(region + 1) * CROWD_BINS + bin] += 1;
    }
    if !crowd_kept {
        stats[counter::CROWDED] += 1 + u32::from(faded);
        return;
    }
    let mut inst = PlantInstance {
        pos: pos.to_array(),
        yaw: rand01(hash_u32(h0 ^ 6)) * std::f32::consts::TAU,
        scale,
        kind: t as u32,
        hash: h0,
        fade: 1.0,
    };
    if faded {
        inst.fade = 1.0 - t_band;
        inst.kind = t as u32 | (level << 8);
        out.instances.push(inst);
        inst.fade = -(1.0 - t_band);
        inst.kind = t as u32 | ((level + 1) << 8);
        out.instances.push(inst);
    } else {
        inst.kind = t as u32 | (level << 8);
        out.instances.push(inst);
    }
}

/// The cross-fade's 4x4 ordered dither at pixel (`x`, `y`), in 0..1: Bayer's matrix, computed
/// from the bits as `dither` in `shaders/plants_draw.wgsl` computes it.
pub fn dither(x: u32, y: u32) -> f32 {
    let (x, y) = (x & 3, y & 3);
    let a = x ^ y;
    let bayer = ((a & 1) << 3) | ((y & 1) << 2) | (a & 2) | ((y & 2) >> 1);
    (bayer as f32 + 0.5) / 16.0
}

/// The pixels of a plant drawn in a cross-fade at dither value `dither` (0..1): see
/// [`PlantInstance::fade`].
pub fn keeps_pixel(fade: f32, dither: f32) -> bool {
    if fade >= 0.0 {
        dither < fade
    } else {
        dither >= -fade
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dither_is_bayers_matrix() {
        let bayer = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];
        for (y, row) in bayer.iter().enumerate() {
            for (x, &b) in row.iter().enumerate() {
                let want = (b as f32 + 0.5) / 16.0;
                assert_eq!(dither(x as u32, y as u32), want, "({x}, {y})");
                assert_eq!(dither(x as u32 + 4, y as u32 + 8), want);
            }
        }
    }

    #[test]
    fn a_crowded_region_aims_below_its_capacity_by_the_margin() {
        // A large region: 95% of it; a small one: three standard deviations of its draw below.
        assert_eq!(crowd_fill(262_144), 0.95 * 262_144.0);
        assert_eq!(crowd_fill(64), 40.0);
        assert_eq!(crowd_fill(4), 1.0);
    }

    #[test]
    fn the_distance_bins_are_quarter_octaves_from_two_metres() {
        assert_eq!(crowd_bin(0.0), 0);
        assert_eq!(crowd_bin(1.99), 0);
        assert_eq!(crowd_bin(2.0), 1);
        assert_eq!(crowd_bin(4.0), 5);
        assert_eq!(crowd_bin(1e9), CROWD_BINS - 1);
        for b in 1..CROWD_BINS {
            let near = crowd_bin_near(b);
            assert_eq!(crowd_bin(near * 1.0001), b, "bin {b} from {near} m");
            assert_eq!(crowd_bin(near * 0.9999), b - 1, "below bin {b}");
        }
    }

    #[test]
    fn a_crowded_region_thins_its_farthest_plants_to_fit_and_keeps_the_nearest() {
        // 1,000 plants in each bin from 10 m to 1 km in one region; one in each in another.
        let mut wanted = vec![0u32; REGIONS * CROWD_BINS];
        let (first, last) = (crowd_bin(10.0), crowd_bin(1000.0));
        for b in first..=last {
            wanted[b] = 1000;
            wanted[CROWD_BINS + b] = 1;
        }
        let capacity = 16_384;
        let from = crowd_distances(&wanted, capacity);
        assert!(from[1..].iter().all(|&d| d == UNCROWDED));
        let d = from[0];
        assert!(d > 10.0 && d < 1000.0, "{d}");
        // What the thinning keeps of plants spread evenly through each bin: within the fill,
        // and near it (the estimate counts each bin at its near edge).
        let mut kept = 0.0;
        for b in first..=last {
            for i in 0..1000 {
                let t = (i as f32 + 0.5) / 1000.0;
                let dist = crowd_bin_near(b) * (0.25 * t).exp2();
                kept += crowd_keep(dist, d);
            }
        }
        let fill = crowd_fill(capacity);
        assert!(kept <= fill && kept > 0.85 * fill, "kept {kept} of {fill}");
        assert_eq!(crowd_keep(0.5 * d, d), 1.0);
        assert_eq!(crowd_keep(2.0 * d, d), 0.25);
    }

    #[test]
    fn the_two_levels_of_a_cross_fade_draw_every_pixel_once() {
        for k in 1..=16 {
            let f = k as f32 / 16.0;
            for j in 0..64 {
                let dither = (j as f32 + 0.5) / 64.0;
                let near = keeps_pixel(f, dither);
                let far = keeps_pixel(-f, dither);
                assert!(near != far, "fade {f}, dither {dither}");
            }
        }
    }
}
