//! CPU mirror of `shaders/stream_derive.wgsl` (the GPU stage: `stream/derive.rs`): a child
//! tile derived from its parent, for levels finer than the stored data.
//!
//! Heights: Catmull-Rom (bicubic) upsampling of the parent's smooth surface (the parent less
//! its own detail, see [`derive_child`]) plus deterministic high-pass detail noise (see
//! [`detail_noise`]) between the parent's samples, scaled by the local slope and by the child
//! level's amplitude (fitted per world by
//! [`crate::stream::calibrate::calibrate`], stored in the manifest's `[derive]`
//! table) and faded to zero toward the tile edges. Every term is a function of the global
//! sample position and of parent samples that neighbouring tiles share, so
//! neighbours derive identical edge and border values. Grass type and terrain material are taken from one of the
//! nearest parent samples (picked by a hash, so types stay crisp and clump), density is the
//! rounded mean of the nearest parent samples.
//!
//! Written loop for loop like the shader, but independently of it: the tests compare the two.

use crate::world::{LEGACY_DETAIL, Manifest, Pyramid, TileData, TileId};

/// Most levels a pyramid has, stored and derived (the manifest's limit).
pub const MAX_LEVELS: usize = 24;

/// Settings of derivation (shared by the shader's uniforms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeriveParams {
    /// Seed of the detail noise.
    pub seed: u32,
    /// Detail amplitude of a child at each level (indexed by the child's level), in child cells
    /// per unit of slope. Entries of stored levels are never used.
    pub detail: [f32; MAX_LEVELS],
    /// Cells over which the detail fades in from a tile edge.
    pub window_cells: f32,
}

impl Default for DeriveParams {
    /// [`LEGACY_DETAIL`] at every level: what a world without a `[derive]` table gets.
    fn default() -> Self {
        Self {
            seed: 0x5eed,
            detail: [LEGACY_DETAIL; MAX_LEVELS],
            window_cells: 4.0,
        }
    }
}

impl DeriveParams {
    /// The settings `manifest` asks for: its `[derive]` amplitudes from the first derived
    /// level on (the last one repeated beyond the list), or the default without that table.
    pub fn for_manifest(manifest: &Manifest) -> Self {
        let mut params = Self::default();
        if let Some(c) = &manifest.derive {
            let first = usize::from(manifest.pyramid.stored_levels);
            params.detail = [0.0; MAX_LEVELS];
            for (level, d) in params.detail.iter_mut().enumerate().skip(first) {
                *d = c
                    .detail
                    .get(level - first)
                    .or(c.detail.last())
                    .copied()
                    .unwrap_or(0.0);
            }
        }
        params
    }

    /// The same settings without detail: plain Catmull-Rom.
    pub fn bicubic(&self) -> Self {
        Self {
            detail: [0.0; MAX_LEVELS],
            ..*self
        }
    }

    /// Detail amplitude of a child at `level` (the last entry for levels beyond the table).
    pub fn detail_at(&self, level: u8) -> f32 {
        self.detail[usize::from(level).min(MAX_LEVELS - 1)]
    }
}

/// The integer hash used by derivation, as every stage hashes (`crate::hash`).
pub use crate::hash::hash_u32;
pub(crate) use crate::hash::{hash4, unit};

/// Weights of the high-pass filter applied to hashed values along each axis.
const HIGH_PASS: [f32; 3] = [-0.5, 1.0, -0.5];

/// The detail noise at sample `(x, y)` of `level`: hashed values in [-1, 1) filtered by
/// [-1/2, 1, -1/2] along x and then y, scaled by 2/3 so that its variance is the hashed
/// values' own (1/3).
///
/// A high-pass noise makes a surface as rough (the spread of its Laplacian) as white noise does
/// for less height variance: 1.9 times the Laplacian variance per unit of height variance on a
/// derived level's new samples. Noise that is independent of the relief it stands in for adds
/// its whole variance to the height error, so the same roughness costs less accuracy.
pub fn detail_noise(x: i32, y: i32, level: u32, seed: u32) -> f32 {
    let mut sum = 0.0f32;
    for (dy, wy) in HIGH_PASS.iter().enumerate() {
        let mut row = 0.0f32;
        for (dx, wx) in HIGH_PASS.iter().enumerate() {
            let h = hash4(
                (x + dx as i32 - 1) as u32,
                (y + dy as i32 - 1) as u32,
                level,
                seed,
            );
            row += wx * unit(h);
        }
        sum += wy * row;
    }
    sum * (2.0 / 3.0)
}

/// Catmull-Rom weights at fraction 0 and one half (the only fractions a 2x upsampling meets).
pub(crate) const WEIGHTS: [[f32; 4]; 2] =
    [[0.0, 1.0, 0.0, 0.0], [-0.0625, 0.5625, 0.5625, -0.0625]];

/// Derives `child` from `parent` (its parent tile). `pyramid.border` must be even and at
/// least 2.
///
/// A derived level is the Catmull-Rom upsampling of its parent's *smooth* surface plus its own
/// detail; the detail is not passed on. The parent's detail, where the parent is itself
/// derived, is recomputed here and taken off the 16 parent samples the child reads: it lies
/// only on the parent's new samples (those between its own parent's), scaled by the slope of
/// the grandparent's surface, which is read off the parent's other samples (they are the
/// grandparent's), and faded to zero over the `border` samples nearest a tile edge, so that
/// every sample it needs is in the tile. A level's RMS height error is thus Catmull-Rom's plus
/// its own detail, however deep it lies below the stored data.
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
    let cell_grandparent = 2.0 * cell_parent;
    // Stored levels carry no detail.
    let amplitude = |level: u8| {
        if level < pyramid.stored_levels {
            0.0
        } else {
            params.detail_at(level)
        }
    };
    let parent_level = child.level - 1;
    let parent_amplitude = amplitude(parent_level);
    let child_amplitude = amplitude(child.level);
    let at = |x: i32, y: i32| -> usize { (y.clamp(0, s - 1) * s + x.clamp(0, s - 1)) as usize };
    let window_at = |sx: i32, sy: i32| -> f32 {
        let mx = sx.rem_euclid(n);
        let my = sy.rem_euclid(n);
        let edge = mx.min(n - mx).min(my).min(n - my) - b;
        (edge as f32 / params.window_cells).clamp(0.0, 1.0)
    };
    // Global sample of parent texel (0, 0).
    let (ox, oy) = ((child.x >> 1) as i32 * n - b, (child.y >> 1) as i32 * n - b);
    // The parent's smooth height at texel (x, y): its height less its own detail.
    let smooth = |x: i32, y: i32| -> f32 {
        let (gx, gy) = (ox + x, oy + y);
        let (ex, ey) = (gx & 1, gy & 1);
        let new = ((ex | ey) as f32).min(1.0);
        let (cx, cy) = (x - ex, y - ey);
        let gpx = (parent.heights[at(cx + 2, cy)] - parent.heights[at(cx - 2, cy)])
            / (2.0 * cell_grandparent);
        let gpy = (parent.heights[at(cx, cy + 2)] - parent.heights[at(cx, cy - 2)])
            / (2.0 * cell_grandparent);
        let slope = (gpx * gpx + gpy * gpy).sqrt().min(1.5);
        let noise = detail_noise(gx, gy, u32::from(parent_level), params.seed);
        let detail = noise * (parent_amplitude * cell_parent * slope * window_at(gx, gy) * new);
        parent.heights[at(x, y)] - detail
    };
    let len = (s * s) as usize;
    let mut heights = vec![0.0f32; len];
    let mut grass_type = vec![0u8; len];
    let mut density = vec![0u8; len];
    let mut material = vec![0u8; if parent.material.is_empty() { 0 } else { len }];
    for j in 0..s {
        for i in 0..s {
            // Position in half parent texels.
            let px2 = b + qx * n + i;
            let py2 = b + qy * n + j;
            let (ix, fx) = (px2 >> 1, (px2 & 1) as usize);
            let (iy, fy) = (py2 >> 1, (py2 & 1) as usize);
            let (wx, wy) = (WEIGHTS[fx], WEIGHTS[fy]);

            let mut taps = [[0.0f32; 4]; 4];
            for (dy, row) in taps.iter_mut().enumerate() {
                for (dx, tap) in row.iter_mut().enumerate() {
                    *tap = smooth(ix - 1 + dx as i32, iy - 1 + dy as i32);
                }
            }
            let mut rows = [0.0f32; 4];
            for (dy, row) in rows.iter_mut().enumerate() {
                let t = &taps[dy];
                *row = ((wx[0] * t[0] + wx[1] * t[1]) + wx[2] * t[2]) + wx[3] * t[3];
            }
            let mut h = ((wy[0] * rows[0] + wy[1] * rows[1]) + wy[2] * rows[2]) + wy[3] * rows[3];

            let gx = (taps[1][2] - taps[1][0]) / (2.0 * cell_parent);
            let gy = (taps[2][1] - taps[0][1]) / (2.0 * cell_parent);
            let slope = (gx * gx + gy * gy).sqrt().min(1.5);

            // Global sample coordinates at the child's level; detail only between the
            // parent's samples.
            let sx = child.x as i32 * n + i - b;
            let sy = child.y as i32 * n + j - b;
            let new = (((sx | sy) & 1) as f32).min(1.0);
            let noise = detail_noise(sx, sy, u32::from(child.level), params.seed);
            h += noise * (child_amplitude * cell_child * slope * window_at(sx, sy) * new);

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
            if let Some(m) = material.get_mut(o) {
                *m = parent.material[at(tx, ty)];
            }
        }
    }
    TileData {
        id: child,
        size: parent.size,
        heights,
        grass_type,
        density,
        material: TileData::material_map(material),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::{DeriveCalibration, DeriveMode};

    #[test]
    fn params_follow_the_manifest_table_or_keep_the_legacy_amplitude() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("worlds")
            .join("santa-cruz")
            .join("world.toml");
        let mut manifest = Manifest::from_path(&path).unwrap();
        manifest.derive = None;
        assert_eq!(
            DeriveParams::for_manifest(&manifest),
            DeriveParams::default()
        );
        let first = manifest.pyramid.stored_levels;
        let levels = usize::from(manifest.pyramid.derived_levels);
        manifest.derive = Some(DeriveCalibration {
            method: DeriveMode::Fractal,
            note: String::new(),
            octaves: 4,
            hurst: 0.7,
            fit_rms_log2: 0.01,
            residual_rms_m: 1.0,
            decay_log2: 0.5,
            detail: (0..levels).map(|k| 0.1 * (k + 1) as f32).collect(),
        });
        let p = DeriveParams::for_manifest(&manifest);
        for k in 0..levels {
            assert_eq!(p.detail_at(first + k as u8), 0.1 * (k + 1) as f32);
        }
        // Beyond the table: its last amplitude.
        assert_eq!(p.detail_at(first + levels as u8 + 3), 0.1 * levels as f32);
        assert_eq!(p.bicubic().detail, [0.0; MAX_LEVELS]);
    }
}
