//! The trees' sun shadows: a cascaded shadow map.
//!
//! Trees, unlike the blades, are persistent instances a few thousand strong near the camera,
//! so they go into a shadow map. A third instance of the plant stage (the trees' placement and
//! draw, [`crate::plants::PlantRenderer::new_caster`]) places the trees within
//! [`TreeShadows::distance_m`] of the camera that can cast into view, culled by the box of the
//! cascades seen from the sun rather than by the camera's frustum (a tree behind the camera
//! casts forward), and draws their depth into one layer per cascade: orthographic views along
//! the sun, each around a slice of the view by distance, its centre snapped to whole texels of
//! the world so that the shadows hold still while the camera moves. The deferred shadow pass
//! (`shaders/terrain_contact_shadow.wgsl`) then looks up every pixel's point in the cascade
//! of its distance (a tent-filtered comparison of 4 x 4 texels) and darkens the terrain, the
//! grass, the plants and the trees themselves alike; the shadows fade out over the last tenth
//! of the distance.
//!
//! CPU mirror of the lookup: [`ShadowUniform::sun_seen`] (a test compares the two on software
//! Vulkan); the casters' placement is the trees' own, mirrored in
//! [`crate::plants::place_cpu`].

use glam::{DVec3, Mat4, Vec3, Vec4};

/// Most cascades a map holds.
pub const MAX_CASCADES: usize = 4;

/// Format of the shadow map (reverse depth: 1 toward the sun, 0 away from it).
pub const SHADOW_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// How far behind the sun-facing side of the cascades' slices a caster may stand, metres:
/// a tree on a ridge toward the sun shades the valley below it.
pub const CASTER_REACH_M: f32 = 1000.0;

/// Instances per (type, level) region of the casters' pool: the trees within the shadows'
/// reach all around the camera (at the default 160 m and one tree a 5 m cell, at most about
/// 4,000 in all).
pub const CASTER_CAPACITY: u32 = 16_384;

/// Settings of the trees' shadows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TreeShadows {
    /// Distance from the camera that the shadows reach, metres (faded out over its last tenth).
    pub distance_m: f32,
    /// Cascades, 1 to [`MAX_CASCADES`].
    pub cascades: u32,
    /// Edge of each cascade's map, texels.
    pub size: u32,
    /// Where the first cascade ends, as a share of the distance; each next one ends as much
    /// farther again in the ratio (logarithmic splits).
    pub split: f32,
    /// How far a receiving point is moved toward the sun before the comparison, in texels of its
    /// cascade (against shadow acne on the leaves that cast).
    pub bias_texels: f32,
    /// The casters' level-of-detail switches NEAR,FAR, metres from the camera: the full mesh
    /// out to NEAR (0: none), the reduced mesh out to FAR (0: none), the card turned to the sun
    /// beyond. A shadow needs less than the tree it falls from.
    pub lod_m: [f32; 2],
}

impl Default for TreeShadows {
    fn default() -> Self {
        Self {
            distance_m: 160.0,
            cascades: 2,
            size: 1024,
            split: 0.25,
            bias_texels: 2.0,
            lod_m: [0.0, 25.0],
        }
    }
}

/// One cascade: the camera-relative view-projection along the sun (x, y to -1..1, depth 1 on
/// the side toward the sun to 0), where its slice of the view ends, and its texel and depth
/// range in metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cascade {
    /// Camera-relative view-projection.
    pub view_proj: Mat4,
    /// Distance from the camera where the cascade's slice ends, metres.
    pub far_m: f32,
    /// Edge of a texel, metres.
    pub texel_m: f32,
    /// Depth range along the sun, metres.
    pub depth_m: f32,
}

/// An orthonormal basis whose z is `sun` (toward the sun).
fn sun_basis(sun: Vec3) -> (Vec3, Vec3, Vec3) {
    let z = sun.normalize();
    let up = if z.z.abs() > 0.99 { Vec3::X } else { Vec3::Z };
    let x = up.cross(z).normalize();
    let y = z.cross(x);
    (x, y, z)
}

/// The camera-relative orthographic view-projection of the box centred on `c` (camera
/// relative) with half-edge `r` across the sun and depth `[lo, hi]` along it (metres from the
/// centre), reverse depth.
fn ortho(basis: (Vec3, Vec3, Vec3), c: Vec3, r: f32, [lo, hi]: [f32; 2]) -> Mat4 {
    let (x, y, z) = basis;
    let h = hi - lo;
    Mat4::from_cols(
        Vec4::new(x.x / r, y.x / r, z.x / h, 0.0),
        Vec4::new(x.y / r, y.y / r, z.y / h, 0.0),
        Vec4::new(x.z / r, y.z / r, z.z / h, 0.0),
        Vec4::new(-x.dot(c) / r, -y.dot(c) / r, (-z.dot(c) - lo) / h, 1.0),
    )
}

impl TreeShadows {
    /// Whether the settings are usable; the error names the setting, its value and its range.
    pub fn validate(&self) -> Result<(), (&'static str, String, String)> {
        let bad = |field, value: String, range: &str| Err((field, value, range.to_owned()));
        if !(self.distance_m.is_finite() && (10.0..=2000.0).contains(&self.distance_m)) {
            return bad(
                "tree_shadows.distance_m",
                self.distance_m.to_string(),
                "10 to 2000 m",
            );
        }
        if !(1..=MAX_CASCADES as u32).contains(&self.cascades) {
            let range = format!("1 to {MAX_CASCADES}");
            return bad("tree_shadows.cascades", self.cascades.to_string(), &range);
        }
        if !(256..=8192).contains(&self.size) {
            return bad(
                "tree_shadows.size",
                self.size.to_string(),
                "256 to 8192 texels",
            );
        }
        if !(self.split > 0.0 && self.split < 1.0) {
            return bad(
                "tree_shadows.split",
                self.split.to_string(),
                "between 0 and 1",
            );
        }
        if !(self.bias_texels.is_finite() && self.bias_texels >= 0.0) {
            let value = self.bias_texels.to_string();
            return bad("tree_shadows.bias_texels", value, "0 or more texels");
        }
        let [near, far] = self.lod_m;
        if !(near >= 0.0 && near <= far && far <= 10_000.0) {
            return bad(
                "tree_shadows.lod_m",
                format!("{near},{far}"),
                "NEAR,FAR with 0 <= NEAR <= FAR <= 10000 m",
            );
        }
        Ok(())
    }

    /// The casters' switches as the placement takes them, for cross-fade bands of `band_m`: a
    /// switch at 0 moved below the camera, band and all, so that no caster takes that level.
    pub fn placement_lod_m(&self, band_m: f32) -> [f32; 2] {
        self.lod_m.map(|m| if m <= 0.0 { -band_m } else { m })
    }

    /// Where cascade `i` ends, metres from the camera.
    pub fn far_m(&self, i: u32) -> f32 {
        let n = self.cascades.max(1);
        if i + 1 >= n {
            return self.distance_m;
        }
        // Logarithmic splits from the first cascade's end to the distance.
        let first = self.distance_m * self.split;
        first * (self.distance_m / first).powf(i as f32 / (n - 1) as f32)
    }

    /// The cascades of a camera at `eye` (world metres) whose camera-relative inverse
    /// view-projection is `inv_view_proj` (reverse-Z), with the sun toward `sun`. Each is the
    /// box around its slice's bounding sphere, its centre snapped to whole texels of a grid
    /// fixed in the world.
    pub fn cascades(&self, eye: DVec3, inv_view_proj: Mat4, sun: Vec3) -> Vec<Cascade> {
        let basis = sun_basis(sun);
        // The directions of the view's four corner rays (any depth: the eye is the origin).
        let corners = [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)].map(|(x, y)| {
            let p = inv_view_proj * Vec4::new(x, y, 0.5, 1.0);
            (p.truncate() / p.w).normalize()
        });
        let mut near = 0.0f32;
        (0..self.cascades.clamp(1, MAX_CASCADES as u32))
            .map(|i| {
                let far = self.far_m(i);
                let points: Vec<Vec3> =
                    corners.iter().flat_map(|d| [*d * near, *d * far]).collect();
                near = far;
                let centre = points.iter().copied().sum::<Vec3>() / points.len() as f32;
                let r = points
                    .iter()
                    .map(|p| p.distance(centre))
                    .fold(0.0f32, f32::max)
                    .max(1.0);
                // A whole number of centimetres, so that the texel is the same every frame
                // while the camera turns.
                let r = (r * 100.0).ceil() / 100.0;
                let texel = 2.0 * r / self.size as f32;
                // The centre snapped to the texel grid across the sun, in world metres.
                let (bx, by, _) = basis;
                let world = centre.as_dvec3() + eye;
                let snap = |axis: Vec3| {
                    let a = axis.as_dvec3();
                    let t = f64::from(texel);
                    ((world.dot(a) / t).round() * t - world.dot(a)) as f32
                };
                let centre = centre + bx * snap(bx) + by * snap(by);
                let depth = [-r - 1.0, r + CASTER_REACH_M];
                Cascade {
                    view_proj: ortho(basis, centre, r, depth),
                    far_m: far,
                    texel_m: texel,
                    depth_m: depth[1] - depth[0],
                }
            })
            .collect()
    }

    /// The box around every cascade's, as a camera-relative view-projection: the trees
    /// inside it (its side toward the sun included) may cast into a cascade.
    pub fn caster_box(cascades: &[Cascade], sun: Vec3) -> Mat4 {
        let basis = sun_basis(sun);
        let (bx, by, bz) = basis;
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for c in cascades {
            let inv = c.view_proj.inverse();
            for corner in [
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 1.0),
                Vec3::new(-1.0, 1.0, 0.0),
                Vec3::new(1.0, -1.0, 1.0),
            ] {
                let p = inv.project_point3(corner);
                let l = Vec3::new(bx.dot(p), by.dot(p), bz.dot(p));
                lo = lo.min(l);
                hi = hi.max(l);
            }
        }
        let mid = (lo + hi) * 0.5;
        let centre = bx * mid.x + by * mid.y + bz * mid.z;
        let r = ((hi.x - lo.x).max(hi.y - lo.y) * 0.5).max(1.0);
        ortho(basis, centre, r, [lo.z - mid.z, hi.z - mid.z])
    }
}

/// The share of a crown's disc (its widest reach about the axis) that its leaves shade.
pub const CROWN_FILL: f32 = 0.6;

/// Most bands of altitude the canopy's shade tells apart (the trees' altitude limits are
/// their edges).
pub const CANOPY_BANDS: usize = 8;

/// The depth of the trees' canopy shade per band of altitude and grass type (see
/// [`canopy_depth`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CanopyDepth {
    /// The bands' edges, metres, rising; unused ones at `f32::MAX`. Band `i` lies between edge
    /// `i - 1` and edge `i`.
    pub edges: [f32; CANOPY_BANDS - 1],
    /// Per band, per grass type, the depth at full grass density.
    pub depth: [[f32; crate::world::MAX_GRASS_TYPES]; CANOPY_BANDS],
}

impl CanopyDepth {
    /// The band holding `altitude_m`.
    pub fn band(&self, altitude_m: f32) -> usize {
        self.edges.iter().filter(|&&e| altitude_m >= e).count()
    }

    /// The depth over grass type `grass` at `altitude_m`.
    pub fn at(&self, grass: usize, altitude_m: f32) -> f32 {
        self.depth[self.band(altitude_m)][grass]
    }

    /// Whether any band of any grass type is shaded.
    pub fn any(&self) -> bool {
        self.depth.iter().flatten().any(|&d| d > 0.0)
    }
}

/// Per band of altitude and grass type, the depth of the trees' canopy shade at full grass
/// density, for the ground beyond the shadow map ([`crate::terrain::far_field::tree_canopy_shade`]
/// turns it into the share of ground in shade, `1 - exp(-depth * density)`). The bands' edges
/// are the tree types' altitude limits (at most [`CANOPY_BANDS`] bands: with more limits, some
/// are left out), and a band counts the types that grow at its middle. Each tree type shades,
/// of the ground its patches cover (its `clump_cover`), the share `1 - exp(-n a)` that trees at
/// random leave in shade: `n` its trees a square metre there (its density, at most one tree in
/// a placement cell of `cell_m` for all types of the band together), `a` the shadow of a crown
/// on the ground, [`CROWN_FILL`] of the disc of the mean height times its type's reach over
/// height, stretched by the sun at `sun` (toward it) as a sphere's shadow is. The types shade
/// independently of one another.
pub fn canopy_depth(
    manifest: &crate::world::Manifest,
    set: &crate::plants::PlantSet,
    cell_m: f32,
    sun: Vec3,
) -> CanopyDepth {
    let mut limits: Vec<f32> = manifest
        .plant_types
        .iter()
        .filter(|t| t.is_tree())
        .flat_map(|t| t.altitude_m)
        .filter(|a| a.is_finite())
        .collect();
    limits.sort_by(f32::total_cmp);
    limits.dedup();
    if limits.len() > CANOPY_BANDS - 1 {
        let n = limits.len();
        limits = (0..CANOPY_BANDS - 1)
            .map(|i| limits[i * (n - 1) / (CANOPY_BANDS - 2)])
            .collect();
    }
    let mut edges = [f32::MAX; CANOPY_BANDS - 1];
    edges[..limits.len()].copy_from_slice(&limits);
    let mut depth = [[0.0f32; crate::world::MAX_GRASS_TYPES]; CANOPY_BANDS];
    for (band, row) in depth.iter_mut().enumerate().take(limits.len() + 1) {
        // The band's middle (a metre beyond its one edge for the first and the last).
        let middle = match (band.checked_sub(1).map(|i| limits[i]), limits.get(band)) {
            (Some(lo), Some(&hi)) => 0.5 * (lo + hi),
            (Some(lo), None) => lo + 1.0,
            (None, Some(&hi)) => hi - 1.0,
            (None, None) => 0.0,
        };
        *row = canopy_depth_at(manifest, set, cell_m, sun, middle);
    }
    CanopyDepth { edges, depth }
}

/// [`canopy_depth`]'s depths at one altitude, per grass type.
fn canopy_depth_at(
    manifest: &crate::world::Manifest,
    set: &crate::plants::PlantSet,
    cell_m: f32,
    sun: Vec3,
    altitude_m: f32,
) -> [f32; crate::world::MAX_GRASS_TYPES] {
    let mut depth = [0.0f32; crate::world::MAX_GRASS_TYPES];
    let stretch = 1.0 / sun.normalize().z.max(0.2);
    for (g, grass) in manifest
        .grass_types
        .iter()
        .take(crate::world::MAX_GRASS_TYPES)
        .enumerate()
    {
        // (trees a square metre, the crown's shadow in square metres, the patches' cover)
        let trees: Vec<(f32, f32, f32)> = manifest
            .plant_types
            .iter()
            .zip(&set.models)
            .filter(|(t, _)| {
                t.is_tree() && (t.altitude_m[0]..=t.altitude_m[1]).contains(&altitude_m)
            })
            .filter_map(|(t, m)| {
                let density = t.density.get(&grass.name).copied().unwrap_or(0.0);
                let r = m.radius_ratio * 0.5 * (t.size_m[0] + t.size_m[1]);
                let shadow = std::f32::consts::PI * r * r * CROWN_FILL * stretch;
                (density > 0.0).then_some((density, shadow, t.clump_cover.clamp(1e-3, 1.0)))
            })
            .collect();
        let chance: f32 = trees.iter().map(|t| t.0 * cell_m * cell_m).sum();
        let scale = if chance > 1.0 { 1.0 / chance } else { 1.0 };
        depth[g] = trees
            .iter()
            .map(|&(n, a, c)| {
                let shaded = c * (1.0 - (-n * scale * a / c).exp());
                -(1.0 - shaded).max(1e-6).ln()
            })
            .sum();
    }
    depth
}

/// The shadow map's uniform (`TreeShadow` in `shaders/terrain_contact_shadow.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ShadowUniform {
    /// Per cascade, its camera-relative view-projection.
    pub matrices: [[[f32; 4]; 4]; MAX_CASCADES],
    /// Per cascade, where its slice ends (m).
    pub far: [f32; 4],
    /// Per cascade, the receiver's bias in depth units.
    pub bias: [f32; 4],
    /// x: cascades (0: no tree shadows this frame), y: the map's edge in texels.
    pub info: [u32; 4],
    /// x: where the shadows start to fade (m), y: where they are gone.
    pub fade: [f32; 4],
}

impl ShadowUniform {
    /// No shadows.
    pub fn off(size: u32) -> Self {
        Self {
            matrices: [Mat4::IDENTITY.to_cols_array_2d(); MAX_CASCADES],
            far: [0.0; 4],
            bias: [0.0; 4],
            info: [0, size, 0, 0],
            fade: [0.0; 4],
        }
    }

    /// The uniform of `cascades` made with `settings`.
    pub fn new(settings: &TreeShadows, cascades: &[Cascade]) -> Self {
        let mut u = Self::off(settings.size);
        for (i, c) in cascades.iter().take(MAX_CASCADES).enumerate() {
            u.matrices[i] = c.view_proj.to_cols_array_2d();
            u.far[i] = c.far_m;
            u.bias[i] = (settings.bias_texels * c.texel_m + 0.05) / c.depth_m;
        }
        u.info[0] = cascades.len().min(MAX_CASCADES) as u32;
        u.fade = [0.9 * settings.distance_m, settings.distance_m, 0.0, 0.0];
        u
    }

    /// The sun's share that reaches the camera-relative point `p`: 1 in full sun, 0 where
    /// every texel of the lookup is nearer the sun. `maps` holds each cascade's depth texels
    /// (row-major, top row first, [`ShadowUniform::info`]'s y on an edge). Mirrors
    /// `tree_sun_seen` in `shaders/terrain_contact_shadow.wgsl` step for step.
    pub fn sun_seen(&self, maps: &[Vec<f32>], p: Vec3) -> f32 {
        let count = self.info[0] as usize;
        if count == 0 {
            return 1.0;
        }
        let dist = p.length();
        if dist >= self.fade[1] {
            return 1.0;
        }
        let mut c = 0;
        while c + 1 < count && dist >= self.far[c] {
            c += 1;
        }
        let s = Mat4::from_cols_array_2d(&self.matrices[c]) * p.extend(1.0);
        let size = self.info[1] as i32;
        let tx = (s.x * 0.5 + 0.5) * size as f32 - 0.5;
        let ty = (0.5 - s.y * 0.5) * size as f32 - 0.5;
        let reference = s.z + self.bias[c];
        let (ix, iy) = (tx.floor(), ty.floor());
        let (fx, fy) = (tx - ix, ty - iy);
        // The tent of three bilinear taps a texel apart: weights 1-f, 1, 1, f over four texels.
        let weights = |f: f32| [1.0 - f, 1.0, 1.0, f];
        let (wx, wy) = (weights(fx), weights(fy));
        let mut lit = 0.0;
        for (j, wyj) in wy.iter().enumerate() {
            for (i, wxi) in wx.iter().enumerate() {
                let x = ix as i32 - 1 + i as i32;
                let y = iy as i32 - 1 + j as i32;
                let texel = if x < 0 || y < 0 || x >= size || y >= size {
                    0.0
                } else {
                    maps[c][(y * size + x) as usize]
                };
                if reference >= texel {
                    lit += wxi * wyj;
                }
            }
        }
        lit /= 9.0;
        let fade =
            ((dist - self.fade[0]) / (self.fade[1] - self.fade[0]).max(1e-3)).clamp(0.0, 1.0);
        lit + (1.0 - lit) * fade
    }
}

/// The shadow map on the GPU: one depth layer per cascade and its uniform.
pub struct TreeShadowMap {
    settings: Option<TreeShadows>,
    texture: wgpu::Texture,
    layers: Vec<wgpu::TextureView>,
    view: wgpu::TextureView,
    uniform: ShadowUniform,
    buffer: wgpu::Buffer,
}

impl TreeShadowMap {
    /// The map of `settings`; with `None`, a single texel that no frame uses (so that the
    /// shadow pass binds the same things either way).
    pub fn new(device: &wgpu::Device, settings: Option<TreeShadows>) -> Self {
        let (size, layers) = settings.map_or((1, 1), |s| (s.size, s.cascades));
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("tree shadow map"),
            size: wgpu::Extent3d {
                width: size,
                height: size,
                depth_or_array_layers: layers,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: SHADOW_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let layer_views = (0..layers)
            .map(|i| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("tree shadow cascade"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: i,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let buffer = crate::gpu::pipeline::buffer(
            device,
            "tree shadow uniform",
            std::mem::size_of::<ShadowUniform>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        Self {
            settings,
            texture,
            layers: layer_views,
            view,
            uniform: ShadowUniform::off(size),
            buffer,
        }
    }

    /// The settings (`None`: the map is never drawn).
    pub fn settings(&self) -> Option<&TreeShadows> {
        self.settings.as_ref()
    }

    /// Sets the frame's cascades (`None`: no tree shadows this frame).
    pub fn set(&mut self, queue: &wgpu::Queue, cascades: Option<&[Cascade]>) {
        self.uniform = match (self.settings, cascades) {
            (Some(s), Some(c)) => ShadowUniform::new(&s, c),
            _ => ShadowUniform::off(self.texture.width()),
        };
        queue.write_buffer(&self.buffer, 0, bytemuck::bytes_of(&self.uniform));
    }

    /// The frame's uniform.
    pub fn uniform(&self) -> &ShadowUniform {
        &self.uniform
    }

    /// Whether this frame has tree shadows.
    pub fn active(&self) -> bool {
        self.uniform.info[0] > 0
    }

    /// The view of cascade `i`'s layer, to draw into.
    pub fn layer(&self, i: usize) -> &wgpu::TextureView {
        &self.layers[i]
    }

    /// Every layer as a 2D array, to read.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.view
    }

    /// The uniform buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// GPU memory of the map, bytes.
    pub fn bytes(&self) -> u64 {
        let s = self.texture.size();
        u64::from(s.width) * u64::from(s.height) * u64::from(s.depth_or_array_layers) * 4
    }

    /// Reads every layer back (for tests and tools: waits for the GPU), row-major.
    pub fn read_layers(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<Vec<f32>>, crate::gpu::ReadbackError> {
        (0..self.texture.depth_or_array_layers())
            .map(|l| {
                crate::gpu::read_texture_layer(device, queue, &self.texture, l)
                    .map(|bytes| bytemuck::pod_collect_to_vec(&bytes))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_canopy_shades_each_band_of_altitude_with_the_trees_that_grow_there() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        let world = crate::world::World::open(&dir).unwrap();
        let set = crate::plants::PlantSet::build(&world.manifest, &world.dir).unwrap();
        let sun = Vec3::new(0.3, 0.2, 0.8);
        let all = canopy_depth(&world.manifest, &set, 5.0, sun);
        // The default world's trees: valley oaks below 90 m, oaks from 90 to 800 m, firs from
        // 250 to 1000 m.
        for e in [90.0, 250.0, 800.0, 1000.0] {
            assert!(all.edges.contains(&e), "{:?}", all.edges);
        }
        let tall = world
            .manifest
            .grass_types
            .iter()
            .position(|g| g.name == "tall grass")
            .unwrap();
        // Each band against the depth of a world holding only the types that grow there.
        let only = |names: &[&str]| {
            let mut m = world.manifest.clone();
            let keep: Vec<bool> = m
                .plant_types
                .iter()
                .map(|t| !t.is_tree() || names.contains(&t.name.as_str()))
                .collect();
            let mut k = keep.iter();
            m.plant_types.retain(|_| *k.next().unwrap());
            let models = set
                .models
                .iter()
                .zip(&keep)
                .filter(|(_, k)| **k)
                .map(|(m, _)| m.clone())
                .collect();
            let s = crate::plants::PlantSet { models };
            canopy_depth(&m, &s, 5.0, sun)
        };
        let valley = only(&["valley oak"]).at(tall, 50.0);
        assert!((all.at(tall, 50.0) - valley).abs() < 1e-6);
        let woods = only(&["oak", "fir"]).at(tall, 500.0);
        assert!((all.at(tall, 500.0) - woods).abs() < 1e-6);
        // The valley's few oaks shade a fortieth of what the mountains' woods do (0.03 against
        // 1.2 over tall grass); above the trees, nothing.
        assert!(valley > 0.0 && valley < 0.05 * woods, "{valley} vs {woods}");
        assert!(all.at(tall, 150.0) < woods);
        assert_eq!(all.at(tall, 1200.0), 0.0);
    }

    fn camera_inv(yaw_deg: f64) -> Mat4 {
        let c = crate::camera::Camera::new(DVec3::new(0.0, 0.0, 2.0), yaw_deg, -10.0);
        c.view_proj_relative(16.0 / 9.0).inverse()
    }

    #[test]
    fn every_point_of_a_slice_is_inside_its_cascade() {
        let s = TreeShadows::default();
        let sun = Vec3::new(-0.5, 0.3, 0.8).normalize();
        let inv = camera_inv(30.0);
        let cascades = s.cascades(DVec3::new(1234.5, -77.25, 300.0), inv, sun);
        assert_eq!(cascades.len(), 2);
        assert!(cascades[0].far_m < cascades[1].far_m);
        assert_eq!(cascades[1].far_m, s.distance_m);
        for (i, c) in cascades.iter().enumerate() {
            let near = if i == 0 { 0.0 } else { cascades[i - 1].far_m };
            for (x, y) in [(-1.0, -1.0), (1.0, 0.3), (0.0, 0.0), (-0.7, 1.0)] {
                let p = inv * Vec4::new(x, y, 0.5, 1.0);
                let d = (p.truncate() / p.w).normalize();
                for t in [near, (near + c.far_m) / 2.0, c.far_m] {
                    let q = c.view_proj.project_point3(d * t);
                    assert!(
                        q.x.abs() <= 1.0 && q.y.abs() <= 1.0 && (0.0..=1.0).contains(&q.z),
                        "cascade {i}: {q}"
                    );
                }
            }
        }
        // A point moved toward the sun is nearer it: its depth grows.
        let c = &cascades[0];
        let p = Vec3::new(5.0, 5.0, 0.0);
        assert!(
            c.view_proj.project_point3(p + sun).z > c.view_proj.project_point3(p).z,
            "depth must grow toward the sun"
        );
    }

    #[test]
    fn cascades_snap_to_the_world_so_shadows_hold_still() {
        let s = TreeShadows::default();
        let sun = Vec3::new(-0.5, 0.3, 0.8).normalize();
        let inv = camera_inv(10.0);
        let eye = DVec3::new(500.0, 500.0, 100.0);
        let a = s.cascades(eye, inv, sun);
        // The camera moved by a fraction of a texel: a fixed world point lands on the same
        // place of the map (to rounding), its camera-relative position shifted.
        let step = DVec3::new(0.013, 0.007, 0.0);
        let b = s.cascades(eye + step, inv, sun);
        let world_point = DVec3::new(520.0, 530.0, 98.0);
        for (ca, cb) in a.iter().zip(&b) {
            assert_eq!(ca.texel_m, cb.texel_m);
            let pa = ca.view_proj.project_point3((world_point - eye).as_vec3());
            let pb = cb
                .view_proj
                .project_point3((world_point - eye - step).as_vec3());
            let texels = (pa.truncate() - pb.truncate()).abs() * s.size as f32 / 2.0;
            let whole = (texels - texels.round()).abs();
            assert!(
                whole.max_element() < 0.02,
                "the map moved by {texels} texels"
            );
        }
    }

    #[test]
    fn the_lookup_is_lit_in_front_of_a_caster_and_shaded_behind_it() {
        let s = TreeShadows {
            cascades: 1,
            size: 256,
            ..Default::default()
        };
        let sun = Vec3::new(0.0, 0.0, 1.0);
        // Looking north (+y).
        let inv = camera_inv(90.0);
        let cascades = s.cascades(DVec3::ZERO, inv, sun);
        let u = ShadowUniform::new(&s, &cascades);
        let c = &cascades[0];
        // A map of one caster: a roof 10 m up over a square of ground around (0, 40).
        let mut map = vec![0.0f32; 256 * 256];
        let roof = |x: f32, y: f32| (x.abs() < 4.0 && (y - 40.0).abs() < 4.0).then_some(10.0);
        let inv_c = c.view_proj.inverse();
        for ty in 0..256 {
            for tx in 0..256 {
                let ndc = Vec3::new(
                    (tx as f32 + 0.5) / 128.0 - 1.0,
                    1.0 - (ty as f32 + 0.5) / 128.0,
                    0.5,
                );
                let p = inv_c.project_point3(ndc);
                if let Some(h) = roof(p.x, p.y) {
                    map[ty * 256 + tx] = c.view_proj.project_point3(Vec3::new(p.x, p.y, h)).z;
                }
            }
        }
        let maps = vec![map];
        let lit = |p: Vec3| u.sun_seen(&maps, p);
        let near = |a: f32, b: f32| (a - b).abs() < 1e-5;
        assert!(near(lit(Vec3::new(0.0, 40.0, 0.0)), 0.0), "under the roof");
        assert!(near(lit(Vec3::new(0.0, 40.0, 11.0)), 1.0), "on top of it");
        assert!(near(lit(Vec3::new(10.0, 40.0, 0.0)), 1.0), "beside it");
        let edge = u.sun_seen(&maps, Vec3::new(4.0, 40.0, 0.0));
        assert!(edge > 0.0 && edge < 1.0, "the edge is soft: {edge}");
        // Beyond the distance, nothing.
        assert_eq!(u.sun_seen(&maps, Vec3::new(0.0, 170.0, 0.0)), 1.0);
        assert_eq!(ShadowUniform::off(256).sun_seen(&maps, Vec3::ZERO), 1.0);
    }

    #[test]
    fn settings_out_of_range_say_which() {
        assert!(TreeShadows::default().validate().is_ok());
        for (s, word) in [
            (
                TreeShadows {
                    cascades: 0,
                    ..Default::default()
                },
                "cascades",
            ),
            (
                TreeShadows {
                    size: 100,
                    ..Default::default()
                },
                "size",
            ),
            (
                TreeShadows {
                    split: 1.0,
                    ..Default::default()
                },
                "split",
            ),
            (
                TreeShadows {
                    distance_m: f32::NAN,
                    ..Default::default()
                },
                "distance",
            ),
            (
                TreeShadows {
                    lod_m: [30.0, 20.0],
                    ..Default::default()
                },
                "lod_m",
            ),
        ] {
            let (field, value, range) = s.validate().unwrap_err();
            assert!(field.contains(word), "{field} = {value}: {range}");
        }
    }
}
