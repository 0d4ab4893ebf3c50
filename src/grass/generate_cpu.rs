//! CPU mirror of `shaders/grass_generate.wgsl` (the GPU stage: `grass/generate.rs`):
//! generation and culling of one grass tile's blades, loop for loop like the shader (one loop
//! iteration per shader invocation), written separately from it. Tests run both on the same
//! tile and compare.
//!
//! For each point of a jittered grid at the tile's spacing (low LOD: every other point in each
//! direction, so the low grid is a subset of the high one), and near the camera (high LOD
//! only) the infill points of its cell (its quarters out to one radius, its sixteenths out to a
//! second, each set shrinking away over the outer part of its radius): a hash of the point's
//! global grid index drives every random attribute; density (bilinear) comes from the tile's
//! map; a Voronoi clump of hashed points lends its grass type (the map's at the clump's point,
//! mixed with the second-nearest clump's near their border), facing, colour and height; the
//! growth direction blends between up and the terrain normal by grass type; short grass is
//! split into two blades. Points with no grass are dropped; the rest are culled by distance
//! (with the fade of blades the low grid drops and the dithered fade at the view distance),
//! frustum and occlusion (a Hi-Z pyramid of the terrain's depth).

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3, Vec4};

use crate::grass::Blade;
use crate::hash::{hash_u32, hash3, rand01};
use crate::world::TileData;

/// Per-type constants of generation; mirrors `GrassTypeGpu` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GrassTypeGpu {
    /// Height range, metres.
    pub height: [f32; 2],
    /// Width range, metres.
    pub width: [f32; 2],
    /// How far the growth direction follows the terrain normal (0 = straight up).
    pub growth_blend: f32,
    /// Stiffness 0..1 (stiffer grass moves less in the wind).
    pub stiffness: f32,
    /// Unused.
    pub _pad: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<GrassTypeGpu>() == 32);

/// Frame constants of generation; mirrors `Params` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GenerateParams {
    /// Camera-relative view-projection.
    pub view_proj: [[f32; 4]; 4],
    /// Frustum planes (left, right, bottom, top, near; the sixth is unused), inward normals.
    pub planes: [[f32; 4]; 6],
    /// x: camera altitude (m), y: near plane (m), z, w: Hi-Z width and height (texels).
    pub camera: [f32; 4],
    /// x: grid points a tile edge (high LOD), y: tile cells, z: border samples, w: seed.
    pub grid: [u32; 4],
    /// x: blade spacing (high LOD, m), y: tile edge (m), z: clump cell (m), w: short-grass
    /// height below which a blade is split in two (m).
    pub dims: [f32; 4],
    /// x, y: distances over which the blades the low grid drops fade out (they are gone at y,
    /// the high ring's radius); z, w: dithered fade from z to the view distance w.
    pub ranges: [f32; 4],
    /// Infill near the camera (see [`generate_tile`]): x, y: the band over which the
    /// quarter-spacing points shrink away (gone at y); z, w: the same for the half-spacing
    /// points. No infill where w <= 0.
    pub infill: [f32; 4],
    /// x: horizontal radius of the near blades (see [`TileJob::lod`]); y: the low grid's
    /// widening (see [`widening`]); z: metres toward the fade at the view distance per metre the
    /// camera stands above a blade ([`crate::terrain::far_field::far_distance`]); w: unused.
    pub near: [f32; 4],
    /// x: Hi-Z mip count, y: slot capacity (blades), z: grass type count, w: blade segments,
    /// high LOD in the low 16 bits, low LOD in the high 16.
    pub limits: [u32; 4],
    /// Hi-Z levels: offset (floats), width, height, unused.
    pub hiz_levels: [[u32; 4]; 16],
    /// Per grass type constants.
    pub types: [GrassTypeGpu; 16],
}
const _: () = assert!(std::mem::size_of::<GenerateParams>() == 64 + 96 + 16 * 7 + 256 + 512);

/// One grass tile to generate; mirrors `TileJob` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TileJob {
    /// The tile's south-west corner relative to the camera, metres.
    pub origin: [f32; 2],
    /// Cell size of the tile's data, metres.
    pub cell: f32,
    /// Atlas slot of the tile's data.
    pub layer: u32,
    /// The tile's address at the grass level.
    pub tile_x: u32,
    /// The tile's address at the grass level.
    pub tile_y: u32,
    /// 0 = high LOD, 1 = low LOD (twice the spacing), 2 = the blades of a high-LOD tile within
    /// the near radius (`GenerateParams::near`), which its LOD 0 job then leaves out: drawn with
    /// the most segments.
    pub lod: u32,
    /// Pool slot (within its half) to write to.
    pub slot: u32,
}
const _: () = assert!(std::mem::size_of::<TileJob>() == 32);

/// Counter indices of [`GenerateStats`].
pub mod counter {
    /// Grid points looked at.
    pub const CONSIDERED: usize = 0;
    /// Points with no grass (bare type, zero density or height).
    pub const EMPTY: usize = 1;
    /// Blades culled by distance (including the LOD fade and the dithered view-distance fade).
    pub const DISTANCE: usize = 2;
    /// Blades outside the frustum.
    pub const FRUSTUM: usize = 3;
    /// Blades behind the terrain (Hi-Z).
    pub const OCCLUSION: usize = 4;
    /// Blades written (short grass counts two).
    pub const EMITTED: usize = 5;
    /// Blades that did not fit their slot (clamped, never written out of bounds).
    pub const OVERFLOW: usize = 6;
    /// Blades in the slot's indirect draw.
    pub const DRAWN: usize = 7;
    /// Number of counters a LOD.
    pub const COUNT: usize = 8;
}

/// Counters of one generation, per LOD (index 0 high, 1 low).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GenerateStats {
    /// `counter::*` per LOD.
    pub counts: [[u32; counter::COUNT]; 2],
}

/// A Hi-Z pyramid on the CPU: per mip, the farthest depth (reverse-Z: smallest) of each 2x2
/// block of the level below.
#[derive(Clone, Debug)]
pub struct HiZ {
    /// Mip levels, finest first: (width, height, depths row-major, top row first).
    pub mips: Vec<(u32, u32, Vec<f32>)>,
}

impl HiZ {
    /// A pyramid that occludes nothing.
    pub fn empty(width: u32, height: u32) -> Self {
        Self {
            mips: vec![(width, height, vec![0.0; (width * height) as usize])],
        }
    }

    fn load(&self, mip: usize, x: i32, y: i32) -> f32 {
        let (w, h, d) = &self.mips[mip];
        let x = x.clamp(0, *w as i32 - 1) as u32;
        let y = y.clamp(0, *h as i32 - 1) as u32;
        d[(y * w + x) as usize]
    }
}

/// The result of generating one tile.
#[derive(Clone, Debug, Default)]
pub struct TileBlades {
    /// Blades written (at most the capacity), in grid order.
    pub blades: Vec<Blade>,
    /// Blades the tile wanted to write (may exceed the capacity: the rest are dropped).
    pub wanted: u32,
    /// Counters.
    pub stats: GenerateStats,
}

/// Metres (in the difference of a blade's distances to its two nearest clump points) over
/// which the grass types of two clumps mix.
pub const CLUMP_BLEND_M: f32 = 0.4;

/// The statistics' LOD of a job's: near blades (LOD 2) count as high LOD (0).
pub fn stats_lod(lod: u32) -> usize {
    usize::from(lod == 1)
}

/// Bilinear height and density and the normal at texel position `tp` of `tile`
/// (`tile_height_density` and `tile_normal` in `shaders/shared/tile_texels.wgsl`).
pub(crate) struct Sample {
    pub(crate) height: f32,
    pub(crate) density: f32,
    pub(crate) normal: Vec3,
}

pub(crate) fn sample(tile: &TileData, tp: [f32; 2], cell: f32) -> Sample {
    let s = tile.size as i32;
    let at = |x: i32, y: i32| (y.clamp(0, s - 1) * s + x.clamp(0, s - 1)) as usize;
    let (fx0, fy0) = (tp[0].floor(), tp[1].floor());
    let (ix, iy) = (fx0 as i32, fy0 as i32);
    let (fx, fy) = (tp[0] - fx0, tp[1] - fy0);
    let h = |x: i32, y: i32| tile.heights[at(x, y)];
    let d = |x: i32, y: i32| f32::from(tile.density[at(x, y)]) / 255.0;
    let bil = |f: &dyn Fn(i32, i32) -> f32| {
        let a = f(ix, iy) + (f(ix + 1, iy) - f(ix, iy)) * fx;
        let b = f(ix, iy + 1) + (f(ix + 1, iy + 1) - f(ix, iy + 1)) * fx;
        a + (b - a) * fy
    };
    let (nx, ny) = ((tp[0] + 0.5).floor() as i32, (tp[1] + 0.5).floor() as i32);
    let gx = h(nx - 1, ny) - h(nx + 1, ny);
    let gy = h(nx, ny - 1) - h(nx, ny + 1);
    Sample {
        height: bil(&h),
        density: bil(&d),
        normal: Vec3::new(gx, gy, 2.0 * cell).normalize(),
    }
}

/// How many times its own width a blade of the low grid at `dist` metres from the camera is
/// drawn, in a job of LOD `lod`: in the low ring (LOD 1) `params.near[1]`; in the high ring
/// rising from 1 to that over the band in which the blades the low grid drops shrink away
/// (`params.ranges[0..2]`), so that the blades left keep the cover of those gone.
pub fn widening(params: &GenerateParams, lod: u32, dist: f32) -> f32 {
    let k = params.near[1];
    if lod == 1 {
        return k;
    }
    let [start, end, _, _] = params.ranges;
    let t = ((dist - start) / (end - start).max(1e-3)).clamp(0.0, 1.0);
    1.0 + (k - 1.0) * t
}

/// Generates and culls the blades of one tile, as the shader does.
pub fn generate_tile(
    params: &GenerateParams,
    job: &TileJob,
    tile: &TileData,
    hiz: &HiZ,
) -> TileBlades {
    let g = params.grid[0];
    let seed = params.grid[3];
    let [spacing, tile_m, clump_m, _] = params.dims;
    let [fade_start, fade_end, _, _] = params.ranges;
    let capacity = params.limits[1];
    let type_count = params.limits[2].max(1);
    let lod = stats_lod(job.lod);
    let step = 1 + lod as u32;
    let n = g.div_ceil(step);
    let clumps_per_tile = (tile_m / clump_m).round().max(1.0) as i32;
    let view_proj = Mat4::from_cols_array_2d(&params.view_proj);
    let mut out = TileBlades::default();
    let mut stats = [0u32; counter::COUNT];

    let ctx = PlantContext {
        params,
        job,
        tile,
        hiz,
        view_proj,
        clumps_per_tile,
        type_count,
    };
    for iy in 0..n {
        for ix in 0..n {
            let (gx, gy) = (ix * step, iy * step);
            let gid_x = job.tile_x * g + gx;
            let gid_y = job.tile_y * g + gy;
            let h0 = hash3(gid_x, gid_y, seed);
            let jitter = [
                (rand01(hash_u32(h0 ^ 1)) - 0.5) * 0.9 * spacing,
                (rand01(hash_u32(h0 ^ 2)) - 0.5) * 0.9 * spacing,
            ];
            let cell = [gx as f32, gy as f32];
            // Blades the low grid drops fade out before the ring switch.
            let band = if job.lod != 1 && (gx % 2 == 1 || gy % 2 == 1) {
                [fade_start, fade_end]
            } else {
                [0.0, 0.0]
            };
            let local = [
                (cell[0] + 0.5) * spacing + jitter[0],
                (cell[1] + 0.5) * spacing + jitter[1],
            ];
            let kept = band[1] <= 0.0;
            ctx.plant(local, h0, spacing, band, kept, &mut out, &mut stats);

            // Infill: near the camera, the cell's quarters and sixteenths.
            let [q0, q1, h0_start, h1] = params.infill;
            if job.lod == 1 || h1 <= 0.0 {
                continue;
            }
            let centre = [
                job.origin[0] + (cell[0] + 0.5) * spacing,
                job.origin[1] + (cell[1] + 0.5) * spacing,
            ];
            let reach = (centre[0] * centre[0] + centre[1] * centre[1]).sqrt() - 0.75 * spacing;
            if reach >= h1 {
                continue;
            }
            let stride = if reach < q1 { 1 } else { 2 };
            for j in (0..4u32).step_by(stride) {
                for i in (0..4u32).step_by(stride) {
                    if i == 0 && j == 0 {
                        continue;
                    }
                    let half = i % 2 == 0 && j % 2 == 0;
                    let sub = if half { 0.5 } else { 0.25 } * spacing;
                    let h = hash3(
                        gid_x.wrapping_mul(4).wrapping_add(i),
                        gid_y.wrapping_mul(4).wrapping_add(j),
                        seed ^ 0x1f111,
                    );
                    let offset = |k: u32| {
                        if half {
                            k as f32 * 0.25 + 0.25
                        } else {
                            (k as f32 + 0.5) * 0.25
                        }
                    };
                    let local = [
                        (cell[0] + offset(i)) * spacing
                            + (rand01(hash_u32(h ^ 1)) - 0.5) * 0.9 * sub,
                        (cell[1] + offset(j)) * spacing
                            + (rand01(hash_u32(h ^ 2)) - 0.5) * 0.9 * sub,
                    ];
                    let band = if half { [h0_start, h1] } else { [q0, q1] };
                    ctx.plant(local, h, sub, band, false, &mut out, &mut stats);
                }
            }
        }
    }
    // As the shader's finalize step: what did not fit is counted as overflow.
    let drawn = out.wanted.min(capacity);
    stats[counter::OVERFLOW] = out.wanted - drawn;
    stats[counter::DRAWN] = drawn;
    out.stats.counts[lod] = stats;
    out
}

/// What every blade of a tile's generation shares.
struct PlantContext<'a> {
    params: &'a GenerateParams,
    job: &'a TileJob,
    tile: &'a TileData,
    hiz: &'a HiZ,
    view_proj: Mat4,
    clumps_per_tile: i32,
    type_count: u32,
}

impl PlantContext<'_> {
    /// A blade at `local` (metres from the tile's corner) with its hash `h0`, of a grid of
    /// `spacing`, shrinking away over the distance band `band` (none where `band[1] <= 0`);
    /// `kept`: a point of the low grid, widened (see [`widening`]).
    #[allow(clippy::too_many_arguments)]
    fn plant(
        &self,
        local: [f32; 2],
        h0: u32,
        spacing: f32,
        band: [f32; 2],
        kept: bool,
        out: &mut TileBlades,
        stats: &mut [u32; counter::COUNT],
    ) {
        let Self {
            params,
            job,
            tile,
            hiz,
            view_proj,
            clumps_per_tile,
            type_count,
        } = *self;
        let seed = params.grid[3];
        let border = params.grid[2] as f32;
        let [_, _, clump_m, short_m] = params.dims;
        let [_, _, dither_start, view_dist] = params.ranges;
        let capacity = params.limits[1];
        // A high-LOD tile near the camera has two jobs: the near one takes its blades within
        // the near radius, the other the rest.
        let (hx, hy) = (job.origin[0] + local[0], job.origin[1] + local[1]);
        let horizontal = (hx * hx + hy * hy).sqrt();
        if job.lod != 1 && (horizontal < params.near[0]) != (job.lod == 2) {
            return;
        }
        stats[counter::CONSIDERED] += 1;
        let tp = [border + local[0] / job.cell, border + local[1] / job.cell];
        let s = sample(tile, tp, job.cell);
        // Clump: the nearest of the hashed points of the 3x3 clump cells around, and the
        // second nearest. A clump has the map's grass type at its point: types meet along
        // clump borders, mixed over CLUMP_BLEND_M either side.
        let cx = (local[0] / clump_m).floor() as i32;
        let cy = (local[1] / clump_m).floor() as i32;
        let (mut best, mut second) = (f32::MAX, f32::MAX);
        let mut clump = 0u32;
        let (mut at_best, mut at_second) = ([0.0f32; 2], [0.0f32; 2]);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (ccx, ccy) = (cx + dx, cy + dy);
                let kx = (job.tile_x as i32 * clumps_per_tile + ccx) as u32;
                let ky = (job.tile_y as i32 * clumps_per_tile + ccy) as u32;
                let ch = hash3(kx, ky, seed ^ 0x00c1_0b55);
                let px = (ccx as f32 + 0.5 + 0.8 * (rand01(ch) - 0.5)) * clump_m;
                let py = (ccy as f32 + 0.5 + 0.8 * (rand01(hash_u32(ch ^ 1)) - 0.5)) * clump_m;
                let d2 = (px - local[0]) * (px - local[0]) + (py - local[1]) * (py - local[1]);
                if d2 < best {
                    (second, at_second) = (best, at_best);
                    (best, clump, at_best) = (d2, ch, [px, py]);
                } else if d2 < second {
                    (second, at_second) = (d2, [px, py]);
                }
            }
        }
        let kind_at = |p: [f32; 2]| {
            let size = tile.size as i32;
            let t = |v: f32| ((border + v / job.cell + 0.5).floor() as i32).clamp(0, size - 1);
            u32::from(tile.grass_type[(t(p[1]) * size + t(p[0])) as usize])
        };
        let mut kind = kind_at(at_best);
        let other = kind_at(at_second);
        let edge = second.sqrt() - best.sqrt();
        if other != kind
            && rand01(hash_u32(h0 ^ 15)) < 0.5 * (1.0 - (edge / CLUMP_BLEND_M).clamp(0.0, 1.0))
        {
            kind = other;
        }
        let kind = kind.min(type_count - 1);
        if kind == 0 || s.density <= 0.0 || rand01(hash_u32(h0 ^ 3)) >= s.density {
            stats[counter::EMPTY] += 1;
            return;
        }
        let ty = params.types[kind as usize];

        let clump_height = 0.7 + 0.6 * rand01(hash_u32(clump ^ 2));
        let height = (ty.height[0] + (ty.height[1] - ty.height[0]) * rand01(hash_u32(h0 ^ 4)))
            * clump_height
            * (0.5 + 0.5 * s.density);
        if height <= 0.0 {
            stats[counter::EMPTY] += 1;
            return;
        }
        let width = ty.width[0] + (ty.width[1] - ty.width[0]) * rand01(hash_u32(h0 ^ 9));
        let up = Vec3::Z;
        let growth = (up + (s.normal - up) * ty.growth_blend).normalize();
        let pos = Vec3::new(
            job.origin[0] + local[0],
            job.origin[1] + local[1],
            s.height - params.camera[0],
        );

        // Distance: blades the low grid drops fade out before the ring switch; all blades
        // thin out, dithered, toward the view distance.
        let dist = pos.length();
        let mut fade = 1.0f32;
        if band[1] > 0.0 {
            fade = ((band[1] - dist) / (band[1] - band[0])).clamp(0.0, 1.0);
        }
        // Seen from above, far blades are specks the far field shows better.
        let far_dist =
            crate::terrain::far_field::far_distance(dist, (-pos.z).max(0.0), params.near[2]);
        let far = ((view_dist - far_dist) / (view_dist - dither_start)).clamp(0.0, 1.0);
        if fade <= 0.0 || rand01(hash_u32(h0 ^ 11)) >= far {
            stats[counter::DISTANCE] += 1;
            return;
        }
        let width = if kept {
            width * widening(params, job.lod, dist)
        } else {
            width
        };

        // Frustum: the blade's bounding sphere against each plane.
        let center = pos + growth * (0.5 * height);
        let radius = 0.6 * height + width;
        let mut outside = false;
        for p in &params.planes[..5] {
            let plane = Vec4::from_array(*p);
            if plane.truncate().dot(center) + plane.w < -radius {
                outside = true;
            }
        }
        if outside {
            stats[counter::FRUSTUM] += 1;
            return;
        }

        // Occlusion: the sphere's nearest depth against the farthest terrain depth of the
        // Hi-Z texels that cover its screen footprint.
        if occluded(params, &view_proj, hiz, center, radius) {
            stats[counter::OCCLUSION] += 1;
            return;
        }

        let facing = rand01(hash_u32(clump ^ 3)) * std::f32::consts::TAU
            + (rand01(hash_u32(h0 ^ 5)) - 0.5) * 1.9;
        let tint = Vec3::new(
            0.85 + 0.3 * rand01(hash_u32(clump ^ 4)),
            0.85 + 0.3 * rand01(hash_u32(clump ^ 5)),
            0.85 + 0.3 * rand01(hash_u32(clump ^ 6)),
        ) * 0.5;
        let mut blade = Blade {
            pos: pos.to_array(),
            facing,
            growth: [growth.x, growth.y],
            height: height * fade,
            width: width * fade,
            tilt: 0.1 + 0.5 * rand01(hash_u32(h0 ^ 6)),
            bend: 0.2 + 0.7 * rand01(hash_u32(h0 ^ 7)),
            side_curve: 2.0 * rand01(hash_u32(h0 ^ 8)) - 1.0,
            wind: (0.6 + 0.4 * rand01(hash_u32(h0 ^ 10))) * (1.0 - 0.5 * ty.stiffness),
            hash: h0,
            kind: kind | (job.lod << 8),
            color: crate::grass::blade::pack_rgba8(tint.to_array()),
            fade,
            lean: [0.0; 2],
            sway: 0.0,
            flutter: 0.0,
            moved: [0.0; 4],
        };
        let emit = |b: Blade, out: &mut TileBlades| {
            if out.wanted < capacity {
                out.blades.push(b);
            }
            out.wanted += 1;
        };
        emit(blade, out);
        stats[counter::EMITTED] += 1;
        if height < short_m {
            // Short grass: a second, smaller blade beside the first, turned a quarter.
            blade.pos[0] += (rand01(hash_u32(h0 ^ 12)) - 0.5) * 0.6 * spacing;
            blade.pos[1] += (rand01(hash_u32(h0 ^ 13)) - 0.5) * 0.6 * spacing;
            // The shader's literal, not FRAC_PI_2, so that both round alike.
            #[allow(clippy::approx_constant)]
            let quarter_turn = 1.5708;
            blade.facing += quarter_turn;
            blade.height *= 0.85;
            blade.hash = hash_u32(h0 ^ 14);
            emit(blade, out);
            stats[counter::EMITTED] += 1;
        }
    }
}

fn occluded(
    params: &GenerateParams,
    view_proj: &Mat4,
    hiz: &HiZ,
    center: Vec3,
    radius: f32,
) -> bool {
    sphere_occluded(
        view_proj,
        params.camera,
        params.limits[0],
        hiz,
        center,
        radius,
    )
}

/// Whether a sphere (camera-relative `center`, `radius`) is behind the terrain: its nearest
/// depth against the farthest terrain depth of the Hi-Z texels that cover its screen footprint.
/// `camera` is (unused, near plane, Hi-Z width, Hi-Z height), `mips` the pyramid's levels; as
/// `occluded` in `shaders/grass_generate.wgsl` and `shaders/plants_place.wgsl`.
pub fn sphere_occluded(
    view_proj: &Mat4,
    camera: [f32; 4],
    mips: u32,
    hiz: &HiZ,
    center: Vec3,
    radius: f32,
) -> bool {
    let clip = *view_proj * center.extend(1.0);
    let near = camera[1];
    // Reverse-Z infinite projection: clip.w is the view distance along the axis.
    if clip.w - radius <= near {
        return false;
    }
    let ndc = [clip.x / clip.w, clip.y / clip.w];
    let (w, h) = (camera[2], camera[3]);
    // Footprint half-size in pixels: the projected radius, from the projection's y scale.
    let scale_y = view_proj.col(1)[1].abs().max(view_proj.col(0)[0].abs());
    let r_px = radius * scale_y / (clip.w - radius) * 0.5 * w.max(h);
    let sx = (ndc[0] * 0.5 + 0.5) * w;
    let sy = (0.5 - ndc[1] * 0.5) * h;
    let mips = mips.max(1);
    let footprint = ((2.0 * r_px).ceil() as u32).max(1);
    let mip = (if footprint <= 1 {
        0
    } else {
        32 - (footprint - 1).leading_zeros()
    })
    .min(mips - 1);
    let texel = (1u32 << mip) as f32;
    let x0 = ((sx - r_px) / texel).floor() as i32;
    let y0 = ((sy - r_px) / texel).floor() as i32;
    let x1 = ((sx + r_px) / texel).floor() as i32;
    let y1 = ((sy + r_px) / texel).floor() as i32;
    if x1 - x0 > 1 || y1 - y0 > 1 {
        return false; // footprint larger than the top mip covers in 2x2: keep
    }
    let far = hiz
        .load(mip as usize, x0, y0)
        .min(hiz.load(mip as usize, x1, y0))
        .min(hiz.load(mip as usize, x0, y1))
        .min(hiz.load(mip as usize, x1, y1));
    let nearest_depth = near / (clip.w - radius);
    nearest_depth < far
}
