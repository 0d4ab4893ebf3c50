//! CPU mirror of `shaders/derive_child.wgsl`: a child tile derived from its parent, for levels
//! finer than the stored data.
//!
//! Heights: Catmull-Rom (bicubic) upsampling of the parent plus deterministic detail noise,
//! scaled by the local slope and faded to zero toward the tile edges. Every term is a function
//! of the global sample position and of parent samples that neighbouring tiles share, so
//! neighbours derive identical edge and border values. Grass type is taken from one of the
//! nearest parent samples (picked by a hash, so types stay crisp and clump), density is the
//! rounded mean of the nearest parent samples.
//!
//! Written loop for loop like the shader, but independently of it: the tests compare the two.

use crate::world::{Pyramid, TileData, TileId};

/// Settings of derivation (shared by the shader's uniforms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeriveParams {
    /// Seed of the detail noise.
    pub seed: u32,
    /// Detail amplitude, in child cells per unit of slope.
    pub detail: f32,
    /// Cells over which the detail fades in from a tile edge.
    pub window_cells: f32,
}

impl Default for DeriveParams {
    fn default() -> Self {
        Self {
            seed: 0x5eed,
            detail: 0.25,
            window_cells: 4.0,
        }
    }
}

/// The integer hash used by derivation (a 32-bit avalanche hash; identical in WGSL).
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

pub(crate) fn hash4(a: u32, b: u32, c: u32, d: u32) -> u32 {
    hash_u32(a ^ hash_u32(b ^ hash_u32(c ^ hash_u32(d))))
}

/// A hash mapped to [-1, 1) exactly (24 bits).
pub(crate) fn unit(h: u32) -> f32 {
    (h >> 8) as f32 * (1.0 / 16_777_216.0) * 2.0 - 1.0
}

/// Catmull-Rom weights at fraction 0 and one half (the only fractions a 2x upsampling meets).
pub(crate) const WEIGHTS: [[f32; 4]; 2] =
    [[0.0, 1.0, 0.0, 0.0], [-0.0625, 0.5625, 0.5625, -0.0625]];

/// Derives `child` from `parent` (its parent tile). `pyramid.border` must be at least 2.
pub fn derive_child(
    pyramid: &Pyramid,
    parent: &TileData,
    child: TileId,
    params: &DeriveParams,
) -> TileData {
    let s = parent.size as i32;
    let n = pyramid.tile_cells as i32;
    let b = pyramid.border as i32;
    let (qx, qy) = ((child.x & 1) as i32, (child.y & 1) as i32);
    let cell_parent = pyramid.cell_size_m(child.level - 1) as f32;
    let cell_child = pyramid.cell_size_m(child.level) as f32;
    let at = |x: i32, y: i32| -> usize { (y.clamp(0, s - 1) * s + x.clamp(0, s - 1)) as usize };
    let len = (s * s) as usize;
    let mut heights = vec![0.0f32; len];
    let mut grass_type = vec![0u8; len];
    let mut density = vec![0u8; len];
    for j in 0..s {
        for i in 0..s {
            // Position in half parent texels.
            let px2 = b + qx * n + i;
            let py2 = b + qy * n + j;
            let (ix, fx) = (px2 >> 1, (px2 & 1) as usize);
            let (iy, fy) = (py2 >> 1, (py2 & 1) as usize);
            let (wx, wy) = (WEIGHTS[fx], WEIGHTS[fy]);

            let mut rows = [0.0f32; 4];
            for (dy, row) in rows.iter_mut().enumerate() {
                let y = iy - 1 + dy as i32;
                let p = |dx: i32| parent.heights[at(ix - 1 + dx, y)];
                *row = ((wx[0] * p(0) + wx[1] * p(1)) + wx[2] * p(2)) + wx[3] * p(3);
            }
            let mut h = ((wy[0] * rows[0] + wy[1] * rows[1]) + wy[2] * rows[2]) + wy[3] * rows[3];

            let gx = (parent.heights[at(ix + 1, iy)] - parent.heights[at(ix - 1, iy)])
                / (2.0 * cell_parent);
            let gy = (parent.heights[at(ix, iy + 1)] - parent.heights[at(ix, iy - 1)])
                / (2.0 * cell_parent);
            let slope = (gx * gx + gy * gy).sqrt().min(1.5);

            // Global sample coordinates at the child's level.
            let sx = child.x as i32 * n + i - b;
            let sy = child.y as i32 * n + j - b;
            let mx = sx.rem_euclid(n);
            let my = sy.rem_euclid(n);
            let edge = mx.min(n - mx).min(my).min(n - my) as f32;
            let window = (edge / params.window_cells).min(1.0);
            let noise = unit(hash4(
                sx as u32,
                sy as u32,
                u32::from(child.level),
                params.seed,
            ));
            h += noise * (params.detail * cell_child * slope * window);

            let pick = hash4(
                sx as u32,
                sy as u32,
                u32::from(child.level),
                params.seed ^ 0x9e37_79b9,
            );
            let tx = ix + (fx as i32) * (pick & 1) as i32;
            let ty = iy + (fy as i32) * ((pick >> 1) & 1) as i32;

            let mut sum = 0u32;
            for a in 0..=fy as i32 {
                for c in 0..=fx as i32 {
                    sum += u32::from(parent.density[at(ix + c, iy + a)]);
                }
            }
            let count = ((1 + fx) * (1 + fy)) as u32;

            let o = (j * s + i) as usize;
            heights[o] = h;
            grass_type[o] = parent.grass_type[at(tx, ty)];
            density[o] = ((sum + count / 2) / count) as u8;
        }
    }
    TileData {
        id: child,
        size: parent.size,
        heights,
        grass_type,
        density,
    }
}
