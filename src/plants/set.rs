//! A world's plants ready for the GPU: per type, its meshes at each level of detail (unit
//! height) and its two texture layers (the mesh's texture and the card's picture), built from
//! the manifest's `[[plant_types]]`: recipes generated, glTF files read.

use std::path::{Path, PathBuf};

use crate::plants::place_cpu::LEVELS;
use crate::plants::{PlantImage, PlantMesh};
use crate::world::Manifest;

/// Edge of every plant texture layer, pixels (a card's picture is rendered at this size; a
/// glTF base colour is resampled to it).
pub const TEXTURE_SIZE: u32 = 128;

/// The farthest a plant file's mesh may reach from its root's axis (the file's origin), over
/// its height: a footprint up to 50 times the plant's height (a creeping plant, moss, a water
/// lily's pads) is a plant; one wider is a mis-scaled or mis-placed file, whose every plant
/// would cover the ground for tens of metres around it.
pub const MAX_RADIUS_RATIO: f32 = 25.0;

/// The most triangles of the reduced level of a plant read from a file (drawn from the full
/// mesh's reach to the view distance, where most plants are): about the built-in bush's.
pub const FILE_REDUCED_TRIANGLES: usize = 128;

/// [`FILE_REDUCED_TRIANGLES`] for a tree read from a file (drawn from tens to hundreds of
/// metres, where a tree is still tens of pixels high): about the built-in broadleaf's.
pub const FILE_TREE_REDUCED_TRIANGLES: usize = 512;

/// The most triangles that the full meshes of a plant type read from a file may put around the
/// camera: its full mesh is drawn only as near as keeps its triangles times the plants its
/// highest density places in a full circle of that radius within this
/// ([`PlantModel::full_mesh_reach_m`]).
pub const FULL_MESH_TRIANGLE_BUDGET: f32 = 4.0e6;

/// Twice a triangle's area (on the mesh scaled to unit height) at or below which it counts as
/// degenerate: a sliver of 10 microns by a micron.
const DEGENERATE_AREA: f32 = 1e-11;

/// A plant file that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// The glTF file of a plant type could not be read.
    #[error("plant type {name:?}: {source}")]
    File {
        /// The plant type.
        name: String,
        /// What went wrong, naming the file.
        #[source]
        source: crate::plants::gltf::PlantFileError,
    },
    /// A plant mesh that has no height.
    #[error(
        "plant type {name:?}: the mesh of {file} is flat (no vertex more than 1 µm above its root)"
    )]
    Flat {
        /// The plant type.
        name: String,
        /// The file.
        file: PathBuf,
    },
    /// A plant mesh whose coordinates overflow once it is scaled to unit height.
    #[error(
        "plant type {name:?}: the mesh of {} is not finite once scaled to unit height: it is \
         {height:e} high and a vertex lies {reach:e} from its root, which overflows",
        file.display()
    )]
    NotFinite {
        /// The plant type.
        name: String,
        /// The file.
        file: PathBuf,
        /// The mesh's height in the file's units.
        height: f32,
        /// The largest coordinate of a vertex in the file's units.
        reach: f32,
    },
    /// A plant mesh of which every triangle has no area: nothing would be drawn.
    #[error(
        "plant type {name:?}: every one of the {triangles} triangles of the mesh of {} is \
         degenerate (zero area): nothing would be drawn",
        file.display()
    )]
    Degenerate {
        /// The plant type.
        name: String,
        /// The file.
        file: PathBuf,
        /// Its triangles.
        triangles: usize,
    },
    /// A plant mesh that reaches farther from its root's axis than [`MAX_RADIUS_RATIO`] times
    /// its height.
    #[error(
        "plant type {name:?}: the mesh of {} reaches {ratio:.3e} times its height from its \
         root's axis (the file's origin, y up), more than the limit of {limit} (a footprint of \
         at most {} times the plant's height)",
        file.display(),
        2.0 * limit
    )]
    TooWide {
        /// The plant type.
        name: String,
        /// The file.
        file: PathBuf,
        /// The farthest horizontal distance of a vertex from the axis, over the height.
        ratio: f32,
        /// [`MAX_RADIUS_RATIO`].
        limit: f32,
    },
}

/// One plant type's meshes and pictures.
#[derive(Clone, Debug)]
pub struct PlantModel {
    /// The full mesh, the reduced one and the crossed cards, each about 1 m high.
    pub lods: [PlantMesh; LEVELS],
    /// The meshes' texture (white for recipes, whose colours are in their vertices).
    pub texture: PlantImage,
    /// The cards' picture.
    pub card: PlantImage,
    /// Widest reach from the axis over height (for the culling sphere).
    pub radius_ratio: f32,
    /// The farthest from the camera that the full mesh (`lods[0]`) may be drawn, metres: for a
    /// plant read from a file, the radius within which its full meshes at the type's highest
    /// density stay within [`FULL_MESH_TRIANGLE_BUDGET`] triangles; [`f32::MAX`] for a recipe,
    /// whose meshes are small. The renderer draws no full mesh beyond it: the type's switch to
    /// the reduced level lies half a cross-fade band short of it where that is nearer than the
    /// settings' switch (`crate::plants::renderer::full_mesh_switch`).
    pub full_mesh_reach_m: f32,
}

/// The models of a world's plant types, in manifest order.
#[derive(Clone, Debug, Default)]
pub struct PlantSet {
    /// One per plant type.
    pub models: Vec<PlantModel>,
}

impl PlantSet {
    /// Builds the models of `manifest`'s plant types; glTF files are read relative to `dir`.
    pub fn build(manifest: &Manifest, dir: &Path) -> Result<Self, PlantError> {
        Self::build_with(manifest, dir, &crate::plants::gltf::read_plant_file)
    }

    /// Like [`PlantSet::build`], each glTF file (and the buffers and images it names) read by
    /// `read`, by its path under `dir`: a world over HTTP fetches them from its server.
    pub fn build_with(
        manifest: &Manifest,
        dir: &Path,
        read: &crate::plants::gltf::PlantFileReader<'_>,
    ) -> Result<Self, PlantError> {
        let mut models = Vec::new();
        for t in &manifest.plant_types {
            models.push(model_with(t, dir, read)?);
        }
        Ok(Self { models })
    }
}

fn white() -> PlantImage {
    PlantImage {
        width: 1,
        height: 1,
        rgba: vec![255; 4],
    }
}

/// The model of plant type `t`.
pub fn model(t: &crate::world::PlantType, dir: &Path) -> Result<PlantModel, PlantError> {
    model_with(t, dir, &crate::plants::gltf::read_plant_file)
}

/// Like [`model`], a glTF file read by `read` ([`PlantSet::build_with`]).
pub fn model_with(
    t: &crate::world::PlantType,
    dir: &Path,
    read: &crate::plants::gltf::PlantFileReader<'_>,
) -> Result<PlantModel, PlantError> {
    use crate::plants::recipe::{Recipe, generate};
    let recipe = Recipe::from_name(&t.mesh);
    let mut full_mesh_reach_m = f32::MAX;
    let (lods, texture, card) = match recipe {
        Some(r) => {
            let p = generate(r, t.seed, t.color);
            let [l0, l1] = p.lods;
            ([l0, l1, p.card], white(), p.card_image)
        }
        None => {
            let file = dir.join(&t.mesh);
            let loaded = crate::plants::gltf::load_plant_from(&file, read).map_err(|source| {
                PlantError::File {
                    name: t.name.clone(),
                    source,
                }
            })?;
            let mut mesh = loaded.mesh;
            let h = mesh.height();
            if h.is_nan() || h <= 1e-6 {
                return Err(PlantError::Flat {
                    name: t.name.clone(),
                    file,
                });
            }
            let reach = mesh
                .vertices
                .iter()
                .flat_map(|v| v.position)
                .fold(0.0f32, |m, c| m.max(c.abs()));
            for v in &mut mesh.vertices {
                for c in &mut v.position {
                    *c /= h;
                }
            }
            check_drawable(t, &file, &mesh, h, reach)?;
            // Light through the leaf: the thickness texture (green, 0 thin .. 1 thick) baked
            // into each vertex's thinness.
            if let Some(th) = &loaded.thickness {
                for v in &mut mesh.vertices {
                    let g = f32::from(th.rgba[texel_index(th, v.uv) + 1]) / 255.0;
                    v.albedo[3] = 1.0 - g;
                }
            }
            let texture = loaded.base_color.unwrap_or_else(white);
            let mut textured = mesh.clone();
            // The card's picture shows the texture's colour through the vertex albedo.
            if texture.width > 1 {
                for v in &mut textured.vertices {
                    let c = sample(&texture, v.uv);
                    for (a, c) in v.albedo.iter_mut().zip(c).take(3) {
                        *a *= c;
                    }
                }
            }
            let card = crate::plants::card::render_card(&textured, TEXTURE_SIZE);
            let cards = crate::plants::card::crossed_cards(&mesh);
            let budget = if t.is_tree() {
                FILE_TREE_REDUCED_TRIANGLES
            } else {
                FILE_REDUCED_TRIANGLES
            };
            let reduced = crate::plants::reduce::reduce(&mesh, budget);
            full_mesh_reach_m = full_mesh_reach(mesh.triangles(), t);
            ([mesh, reduced, cards], texture, card)
        }
    };
    let radius_ratio = lods[0].radius() / lods[0].height().max(1e-6);
    let card = resample(&card, TEXTURE_SIZE);
    let mut lods = lods;
    if t.is_tree() {
        // A tree's card is a billboard: one quad, trimmed to the picture's outline.
        lods[2] = crate::plants::card::trimmed_billboard(&lods[0], &mips(&card));
    }
    Ok(PlantModel {
        lods,
        texture: resample(&texture, TEXTURE_SIZE),
        card,
        radius_ratio,
        full_mesh_reach_m,
    })
}

/// Refuses a file's mesh (scaled to unit height; `height` and `reach`, its largest coordinate,
/// in the file's units) that would draw nothing or nothing sane: coordinates that overflowed,
/// no triangle with an area, or a reach from the axis beyond [`MAX_RADIUS_RATIO`].
fn check_drawable(
    t: &crate::world::PlantType,
    file: &Path,
    mesh: &PlantMesh,
    height: f32,
    reach: f32,
) -> Result<(), PlantError> {
    let finite = mesh
        .vertices
        .iter()
        .all(|v| v.position.iter().all(|c| c.is_finite()));
    if !finite {
        return Err(PlantError::NotFinite {
            name: t.name.clone(),
            file: file.to_owned(),
            height,
            reach,
        });
    }
    let p = |i: u32| glam::Vec3::from_array(mesh.vertices[i as usize].position);
    let has_area = mesh
        .indices
        .chunks_exact(3)
        .any(|t| (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length() > DEGENERATE_AREA);
    if !has_area {
        return Err(PlantError::Degenerate {
            name: t.name.clone(),
            file: file.to_owned(),
            triangles: mesh.triangles(),
        });
    }
    // The mesh is of unit height: its radius is the ratio.
    let ratio = mesh.radius();
    if ratio > MAX_RADIUS_RATIO {
        return Err(PlantError::TooWide {
            name: t.name.clone(),
            file: file.to_owned(),
            ratio,
            limit: MAX_RADIUS_RATIO,
        });
    }
    Ok(())
}

/// The radius within which `triangles` a plant of type `t`, at its highest density all around
/// the camera, stay within [`FULL_MESH_TRIANGLE_BUDGET`] (metres; [`f32::MAX`] where the type
/// grows nowhere).
pub fn full_mesh_reach(triangles: usize, t: &crate::world::PlantType) -> f32 {
    let density = t.density.values().copied().fold(0.0f32, f32::max);
    let per_m2 = triangles as f32 * density;
    if per_m2 > 0.0 {
        (FULL_MESH_TRIANGLE_BUDGET / (std::f32::consts::PI * per_m2)).sqrt()
    } else {
        f32::MAX
    }
}

/// The byte index of the texel of `img` nearest `uv` (repeating).
fn texel_index(img: &PlantImage, uv: [f32; 2]) -> usize {
    let x = ((uv[0].rem_euclid(1.0) * img.width as f32) as u32).min(img.width - 1);
    let y = ((uv[1].rem_euclid(1.0) * img.height as f32) as u32).min(img.height - 1);
    ((y * img.width + x) * 4) as usize
}

/// The texel of `img` nearest `uv` (repeating), as linear 0..1 RGBA.
fn sample(img: &PlantImage, uv: [f32; 2]) -> [f32; 4] {
    let i = texel_index(img, uv);
    let lin = |b: u8| (f32::from(b) / 255.0).powf(2.2);
    [
        lin(img.rgba[i]),
        lin(img.rgba[i + 1]),
        lin(img.rgba[i + 2]),
        f32::from(img.rgba[i + 3]) / 255.0,
    ]
}

/// `img` resampled to `size` x `size` (nearest texel: the sizes are powers of two or a single
/// texel, and mipmaps are built from the result).
pub fn resample(img: &PlantImage, size: u32) -> PlantImage {
    if img.width == size && img.height == size {
        return img.clone();
    }
    let mut rgba = Vec::with_capacity((size * size * 4) as usize);
    for y in 0..size {
        for x in 0..size {
            let sx = ((x as u64 * img.width as u64) / size as u64) as u32;
            let sy = ((y as u64 * img.height as u64) / size as u64) as u32;
            let i = ((sy * img.width + sx) * 4) as usize;
            rgba.extend_from_slice(&img.rgba[i..i + 4]);
        }
    }
    PlantImage {
        width: size,
        height: size,
        rgba,
    }
}

/// The share of texels of an RGBA8 level whose alpha, times `scale`, passes the alpha test.
pub fn coverage(rgba: &[u8], scale: f32) -> f32 {
    let texels = rgba.len() / 4;
    if texels == 0 {
        return 0.0;
    }
    let cut = super::mesh::ALPHA_CUTOFF * 255.0;
    let passing = rgba
        .chunks_exact(4)
        .filter(|t| f32::from(t[3]) * scale >= cut)
        .count();
    passing as f32 / texels as f32
}

/// The mip chain of a square RGBA8 sRGB image (`size` a power of two), each level the 2x2
/// mean of the one below in linear light, alpha-weighted so that transparent texels do not
/// darken the edges. Each level's alpha is then scaled so that as many of its texels pass the
/// alpha test as of the full-size image's (Castaño's coverage-preserving mipmaps): without it a
/// sparse crown of leaves averages below the cut-off and a far tree's card thins to a few
/// scattered texels.
pub fn mips(img: &PlantImage) -> Vec<Vec<u8>> {
    let target = coverage(&img.rgba, 1.0);
    let mut levels = vec![img.rgba.clone()];
    // Each level is the mean of the unscaled one below (the image's own mean alpha); the level
    // stored gets the scale that keeps its coverage.
    let mut prev = img.rgba.clone();
    let mut size = img.width;
    let to_lin = |b: u8| (f32::from(b) / 255.0).powf(2.2);
    let to_srgb = |v: f32| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8;
    while size > 1 {
        let half = size / 2;
        let mut next = vec![0u8; (half * half * 4) as usize];
        for y in 0..half {
            for x in 0..half {
                let mut c = [0.0f32; 3];
                let mut a = 0.0f32;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let i = (((2 * y + dy) * size + 2 * x + dx) * 4) as usize;
                    let w = f32::from(prev[i + 3]) / 255.0;
                    for k in 0..3 {
                        c[k] += to_lin(prev[i + k]) * w;
                    }
                    a += w;
                }
                let o = ((y * half + x) * 4) as usize;
                for k in 0..3 {
                    next[o + k] = to_srgb(if a > 0.0 { c[k] / a } else { 0.0 });
                }
                next[o + 3] = ((a / 4.0) * 255.0).round() as u8;
            }
        }
        let mut stored = next.clone();
        let scale = coverage_scale(&next, target);
        if scale != 1.0 {
            for t in stored.chunks_exact_mut(4) {
                t[3] = (f32::from(t[3]) * scale).round().min(255.0) as u8;
            }
        }
        levels.push(stored);
        prev = next;
        size = half;
    }
    levels
}

/// The alpha scale with which `rgba`'s coverage comes nearest `target`: a bisection over
/// 1/16..16 (coverage rises with the scale).
fn coverage_scale(rgba: &[u8], target: f32) -> f32 {
    if target <= 0.0 || (coverage(rgba, 1.0) - target).abs() < 1e-6 {
        return 1.0;
    }
    let (mut lo, mut hi) = (1.0f32 / 16.0, 16.0f32);
    for _ in 0..24 {
        let mid = (lo * hi).sqrt();
        if coverage(rgba, mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let err = |s: f32| (coverage(rgba, s) - target).abs();
    if err(lo) < err(hi) { lo } else { hi }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sparse crown: one texel in three opaque, scattered, in a disc.
    fn sparse_crown(size: u32) -> PlantImage {
        let mut rgba = vec![0u8; (size * size * 4) as usize];
        let c = size as f32 / 2.0;
        for y in 0..size {
            for x in 0..size {
                let (dx, dy) = (x as f32 + 0.5 - c, y as f32 + 0.5 - c);
                let inside = dx * dx + dy * dy < 0.8 * c * c;
                let leaf = crate::hash::hash3(x, y, 5).is_multiple_of(3);
                if inside && leaf {
                    let i = ((y * size + x) * 4) as usize;
                    rgba[i..i + 4].copy_from_slice(&[40, 90, 20, 255]);
                }
            }
        }
        PlantImage {
            width: size,
            height: size,
            rgba,
        }
    }

    #[test]
    fn mips_keep_a_sparse_crowns_coverage_and_colour() {
        let img = sparse_crown(128);
        let levels = mips(&img);
        assert_eq!(levels.len(), 8);
        let base = coverage(&levels[0], 1.0);
        assert!((0.15..0.3).contains(&base), "{base}");
        for (k, level) in levels.iter().enumerate().take(6).skip(1) {
            let c = coverage(level, 1.0);
            assert!(
                (c - base).abs() < 0.3 * base,
                "level {k}: {c:.3} of the texels pass the alpha test, the image {base:.3}"
            );
            // Where there is any leaf the colour stays the leaves'.
            for t in level.chunks_exact(4).filter(|t| t[3] > 0) {
                assert!(t[0].abs_diff(40) <= 2 && t[1].abs_diff(90) <= 2, "{t:?}");
            }
        }
        // The plain 2x2 mean would lose the crown: its alpha averages below the cut-off.
        let mean = |rgba: &[u8]| -> Vec<u8> {
            let (s, h) = (128usize, 64usize);
            let mut out = vec![0u8; h * h * 4];
            for y in 0..h {
                for x in 0..h {
                    let a: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .iter()
                        .map(|(dx, dy)| u32::from(rgba[((2 * y + dy) * s + 2 * x + dx) * 4 + 3]))
                        .sum();
                    out[(y * h + x) * 4 + 3] = (a / 4) as u8;
                }
            }
            out
        };
        assert!(coverage(&mean(&levels[0]), 1.0) < 0.5 * base);
    }

    #[test]
    fn mips_of_an_opaque_image_are_opaque() {
        let img = PlantImage {
            width: 8,
            height: 8,
            rgba: vec![200; 8 * 8 * 4],
        };
        for level in mips(&img) {
            assert!(level.chunks_exact(4).all(|t| t[3] == 200), "{level:?}");
        }
    }
}
