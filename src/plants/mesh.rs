//! The plant mesh record shared by the procedural generator, the glTF loader and the draw stage.

use bytemuck::{Pod, Zeroable};

/// The alpha test's cut-off of the plants' textures (`shaders/plants_draw.wgsl` discards below
/// it).
pub const ALPHA_CUTOFF: f32 = 0.5;

/// One vertex of a plant mesh, in the plant's own space: metres, z up, the root at the origin,
/// for a plant of scale 1 (the placement scales each instance to its size).
///
/// `wind` carries Crysis' bending channels (GPU Gems 3, ch. 16), painted by the generator or read
/// from a glTF file's `COLOR_0`: r = how freely a leaf's edge flutters (0 stiff .. 1 free), g = a
/// per-leaf phase (0..1), b = how freely the leaf or branch as a whole moves (0 stiff at the stem
/// .. 1 free at its tip), a = baked ambient occlusion (0 dark .. 1 open).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PlantVertex {
    /// Position, metres.
    pub position: [f32; 3],
    /// Unit normal (of the front face; the draw flips it for back faces).
    pub normal: [f32; 3],
    /// The bending channels and ambient occlusion (see the type's docs), each 0..1.
    pub wind: [f32; 4],
    /// Linear albedo (rgb), and in a the leaf's thinness for light passing through (0 opaque,
    /// e.g. a stem, .. 1 a thin petal).
    pub albedo: [f32; 4],
    /// Texture coordinates into the plant's texture (its card image, or a glTF base colour);
    /// meshes without a texture sample a white texel.
    pub uv: [f32; 2],
}
const _: () = assert!(std::mem::size_of::<PlantVertex>() == 64);

/// A triangle mesh of a plant at one level of detail.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlantMesh {
    /// The vertices.
    pub vertices: Vec<PlantVertex>,
    /// Triangles, three indices each, counter-clockwise seen from the front.
    pub indices: Vec<u32>,
}

impl PlantMesh {
    /// Triangles.
    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }

    /// The height of the mesh's highest point above its root, metres (0 when empty).
    pub fn height(&self) -> f32 {
        self.vertices
            .iter()
            .map(|v| v.position[2])
            .fold(0.0, f32::max)
    }

    /// The largest horizontal distance of a vertex from the plant's axis, metres.
    pub fn radius(&self) -> f32 {
        self.vertices
            .iter()
            .map(|v| v.position[0].hypot(v.position[1]))
            .fold(0.0, f32::max)
    }
}

/// An RGBA8 image in sRGB (a card's picture, or a glTF base colour with alpha).
#[derive(Clone, Debug, PartialEq)]
pub struct PlantImage {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Rows from the top, 4 bytes a pixel.
    pub rgba: Vec<u8>,
}
