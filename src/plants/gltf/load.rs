//! The loader: the scene's triangle primitives gathered with their transforms, read into one
//! mesh in plant space, and the plant's textures decoded.

use std::io::Cursor;

use glam::{Mat3, Mat4, Vec3};
use gltf::Semantic;
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use image::ImageDecoder as _;

use super::accessor::{AccessorError, Loader, read_uri};
use super::{
    DEFAULT_THINNESS, LoadedPlant, MAX_PLANT_TRIANGLES, MAX_PLANT_VERTICES, MAX_TEXTURE_SIZE,
    PlantFileError, PlantTexture,
};
use crate::plants::mesh::{PlantImage, PlantMesh, PlantVertex};

/// Node instances after which a scene is refused: a cycle, or a hierarchy that instances itself
/// exponentially, would otherwise never end (or fill memory with the nodes still to visit).
const MAX_NODE_VISITS: usize = 65_536;

/// A triangle primitive to read, with the transform from its node's space to plant space.
struct Instance<'a> {
    mesh: usize,
    primitive: gltf::Primitive<'a>,
    transform: Mat4,
}

impl Loader<'_> {
    pub(super) fn load(self) -> Result<LoadedPlant, PlantFileError> {
        let instances = self.instances()?;
        let path = self.path.to_owned();

        // Counts first, so that a huge file is refused before anything is allocated for it.
        let mut vertex_count = 0usize;
        let mut triangle_count = 0usize;
        for inst in &instances {
            let Some(positions) = inst.primitive.get(&Semantic::Positions) else {
                continue;
            };
            let n = positions.count();
            let elements = inst.primitive.indices().map_or(n, |a| a.count());
            vertex_count = vertex_count.saturating_add(n);
            triangle_count =
                triangle_count.saturating_add(triangles_of(inst.primitive.mode(), elements));
        }
        if vertex_count > MAX_PLANT_VERTICES {
            return Err(PlantFileError::TooManyVertices {
                path,
                count: vertex_count,
                limit: MAX_PLANT_VERTICES,
            });
        }
        if triangle_count > MAX_PLANT_TRIANGLES {
            return Err(PlantFileError::TooManyTriangles {
                path,
                count: triangle_count,
                limit: MAX_PLANT_TRIANGLES,
            });
        }

        let mut mesh = PlantMesh::default();
        // Vertices painted from COLOR_0 keep their channels; the others get b from height.
        let mut painted = Vec::new();
        let mut base_color = None;
        let mut thickness = None;
        for inst in &instances {
            let had_color = self.read_primitive(inst, &mut mesh)?;
            painted.resize(mesh.vertices.len(), had_color);
            let material = inst.primitive.material();
            let base = material.pbr_metallic_roughness().base_color_texture();
            pick_texture(
                &mut base_color,
                base.map(|t| t.texture().index()),
                PlantTexture::BaseColor,
            );
            let thick = material.volume().and_then(|v| v.thickness_texture());
            pick_texture(
                &mut thickness,
                thick.map(|t| t.texture().index()),
                PlantTexture::Thickness,
            );
        }
        if mesh.vertices.is_empty() {
            return Err(PlantFileError::NoMesh { path });
        }
        if mesh.indices.is_empty() {
            return Err(PlantFileError::NoTriangles { path });
        }
        let height = mesh.height();
        for (v, painted) in mesh.vertices.iter_mut().zip(painted) {
            if !painted {
                let b = if height > 0.0 {
                    (v.position[2] / height).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                v.wind = [0.0, 0.0, b, 1.0];
            }
        }

        let base_color = match base_color {
            Some(t) => Some(self.texture(t, PlantTexture::BaseColor)?),
            None => None,
        };
        let thickness = match thickness {
            Some(t) => Some(self.texture(t, PlantTexture::Thickness)?),
            None => None,
        };
        Ok(LoadedPlant {
            mesh,
            base_color,
            thickness,
        })
    }

    /// The triangle primitives of the scene, each with its node's transform into plant space.
    fn instances(&self) -> Result<Vec<Instance<'_>>, PlantFileError> {
        // glTF y-up to plant z-up: (x, y, z) -> (x, -z, y).
        let axes = Mat4::from_cols_array(&[
            1.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 1.0, 0.0, //
            0.0, -1.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        ]);
        let mut meshes = Vec::new();
        let scene = self
            .gltf
            .default_scene()
            .or_else(|| self.gltf.scenes().next());
        match scene {
            None => {
                for mesh in self.gltf.meshes() {
                    meshes.push((mesh, axes));
                }
            }
            Some(scene) => {
                // Every node instance is counted as it is queued, so that the queue too stays
                // within the bound: a node listing itself (or a node that lists it) thousands of
                // times as a child would otherwise grow it by thousands a visit.
                let too_many = || PlantFileError::NotGltf {
                    path: self.path.to_owned(),
                    reason: format!(
                        "the scene's node hierarchy has a cycle or more than {MAX_NODE_VISITS} \
                         node instances"
                    ),
                };
                let mut queued = 0usize;
                let mut stack: Vec<(gltf::Node, Mat4)> = Vec::new();
                for node in scene.nodes() {
                    queued += 1;
                    if queued > MAX_NODE_VISITS {
                        return Err(too_many());
                    }
                    stack.push((node, axes));
                }
                while let Some((node, parent)) = stack.pop() {
                    let local = Mat4::from_cols_array_2d(&node.transform().matrix());
                    let world = parent * local;
                    if let Some(mesh) = node.mesh() {
                        meshes.push((mesh, world));
                    }
                    for child in node.children() {
                        queued += 1;
                        if queued > MAX_NODE_VISITS {
                            return Err(too_many());
                        }
                        stack.push((child, world));
                    }
                }
                // Depth-first with a stack visits children in reverse: restore the file's order.
                meshes.reverse();
            }
        }
        let mut out = Vec::new();
        for (mesh, transform) in meshes {
            for primitive in mesh.primitives() {
                let (m, p) = (mesh.index(), primitive.index());
                if !matches!(
                    primitive.mode(),
                    Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
                ) {
                    log::warn!(
                        "{}: mesh {m} primitive {p} is {:?}, not triangles: skipped",
                        self.path.display(),
                        primitive.mode()
                    );
                    continue;
                }
                if primitive.get(&Semantic::Positions).is_none() {
                    log::warn!(
                        "{}: mesh {m} primitive {p} has no POSITION: skipped",
                        self.path.display()
                    );
                    continue;
                }
                out.push(Instance {
                    mesh: m,
                    primitive,
                    transform,
                });
            }
        }
        Ok(out)
    }

    /// Appends one primitive to `out`; returns whether it had `COLOR_0`.
    fn read_primitive(&self, inst: &Instance, out: &mut PlantMesh) -> Result<bool, PlantFileError> {
        let prim = &inst.primitive;
        let (mesh_i, prim_i) = (inst.mesh, prim.index());
        let path = self.path;
        let bad = |problem: String| PlantFileError::BadPrimitive {
            path: path.to_owned(),
            mesh: mesh_i,
            primitive: prim_i,
            problem,
        };
        let lift = |e: AccessorError| match e {
            AccessorError::Plant(e) => e,
            AccessorError::Bad(problem) => bad(problem),
        };

        let Some(pos_acc) = prim.get(&Semantic::Positions) else {
            return Ok(false);
        };
        let positions = self
            .read_accessor(&pos_acc, "POSITION", &[Dimensions::Vec3], false)
            .map_err(lift)?;
        let n = positions.len() / 3;
        let attribute =
            |semantic: Semantic, name: &str, dims: &[Dimensions], normalize: bool| match prim
                .get(&semantic)
            {
                None => Ok(None),
                Some(acc) => {
                    if acc.count() != n {
                        return Err(bad(format!(
                            "{name} has {} entries but POSITION has {n}",
                            acc.count()
                        )));
                    }
                    let components = acc.dimensions().multiplicity();
                    let values = self
                        .read_accessor(&acc, name, dims, normalize)
                        .map_err(lift)?;
                    Ok(Some((values, components)))
                }
            };
        let normals = attribute(Semantic::Normals, "NORMAL", &[Dimensions::Vec3], false)?;
        let uvs = attribute(
            Semantic::TexCoords(0),
            "TEXCOORD_0",
            &[Dimensions::Vec2],
            false,
        )?;
        // Colours stored as integers are always normalised (the spec requires it of COLOR_n).
        let colors = attribute(
            Semantic::Colors(0),
            "COLOR_0",
            &[Dimensions::Vec3, Dimensions::Vec4],
            true,
        )?;

        let elements: Vec<u32> = match prim.indices() {
            Some(acc) => {
                if !matches!(
                    acc.data_type(),
                    DataType::U8 | DataType::U16 | DataType::U32
                ) {
                    return Err(bad(format!(
                        "indices must be unsigned integers, not {:?}",
                        acc.data_type()
                    )));
                }
                let values = self
                    .read_accessor(&acc, "indices", &[Dimensions::Scalar], false)
                    .map_err(lift)?;
                // Exact through f32 below 2^24, far above the vertex limit; larger indices are
                // out of range whatever their rounding.
                values.into_iter().map(|v| v as u32).collect()
            }
            None => (0..n as u32).collect(),
        };
        if let Some(&index) = elements.iter().find(|&&i| i as usize >= n) {
            return Err(PlantFileError::IndexOutOfRange {
                path: self.path.to_owned(),
                mesh: mesh_i,
                primitive: prim_i,
                index,
                vertices: n,
            });
        }
        let mut triangles = triangle_list(prim.mode(), &elements);

        let transform = inst.transform;
        let linear = Mat3::from_mat4(transform);
        // Mirroring transforms turn counter-clockwise faces clockwise.
        let mirrored = linear.determinant() < 0.0;
        if mirrored {
            for t in triangles.chunks_exact_mut(3) {
                t.swap(1, 2);
            }
        }
        let normal_matrix = linear.inverse().transpose();

        let base = out.vertices.len();
        let albedo = prim.material().pbr_metallic_roughness().base_color_factor();
        for i in 0..n {
            let p = transform.transform_point3(Vec3::from_slice(&positions[i * 3..i * 3 + 3]));
            if !p.is_finite() {
                return Err(bad(format!("vertex {i} has a position that is not finite")));
            }
            let normal = match &normals {
                Some((values, _)) => {
                    let n = normal_matrix * Vec3::from_slice(&values[i * 3..i * 3 + 3]);
                    n.try_normalize().unwrap_or(Vec3::Z).to_array()
                }
                None => [0.0, 0.0, 1.0],
            };
            let uv = match &uvs {
                Some((values, _)) => [
                    finite_or(values[i * 2], 0.0),
                    finite_or(values[i * 2 + 1], 0.0),
                ],
                None => [0.0, 0.0],
            };
            let wind = match &colors {
                Some((values, c)) => {
                    let v = &values[i * c..i * c + c];
                    let a = if *c == 4 { v[3] } else { 1.0 };
                    [v[0], v[1], v[2], a].map(|x| finite_or(x, 0.0).clamp(0.0, 1.0))
                }
                None => [0.0; 4],
            };
            out.vertices.push(PlantVertex {
                position: p.to_array(),
                normal,
                wind,
                albedo: [
                    finite_or(albedo[0], 1.0).max(0.0),
                    finite_or(albedo[1], 1.0).max(0.0),
                    finite_or(albedo[2], 1.0).max(0.0),
                    DEFAULT_THINNESS,
                ],
                uv,
            });
        }
        if normals.is_none() {
            smooth_normals(&mut out.vertices[base..], &triangles);
        }
        out.indices
            .extend(triangles.iter().map(|&i| i + base as u32));
        Ok(colors.is_some())
    }

    /// Decodes one of the plant's textures (an index into the file's textures).
    fn texture(&self, index: usize, which: PlantTexture) -> Result<PlantImage, PlantFileError> {
        let path = self.path.to_owned();
        let fail = |reason: String| PlantFileError::Texture {
            path: path.clone(),
            texture: which,
            reason,
        };
        let json = self.gltf.as_json();
        let image_index = json
            .textures
            .get(index)
            .map(|t| t.source.value())
            .ok_or_else(|| fail(format!("texture {index} does not exist")))?;
        let image = json
            .images
            .get(image_index)
            .ok_or_else(|| fail(format!("image {image_index} does not exist")))?;
        if let Some(mime) = &image.mime_type
            && mime.0 != "image/png"
        {
            return Err(fail(format!(
                "image {image_index} is {}; only PNG textures are read",
                mime.0
            )));
        }
        let bytes = match (&image.buffer_view, &image.uri) {
            (Some(view), _) => {
                let view =
                    self.gltf.views().nth(view.value()).ok_or_else(|| {
                        fail(format!("buffer view {} does not exist", view.value()))
                    })?;
                self.view_bytes(&view)?.to_vec()
            }
            (None, Some(uri)) => read_uri(self.path, uri, self.read).map_err(&fail)?,
            (None, None) => {
                return Err(fail(format!(
                    "image {image_index} has neither uri nor bufferView"
                )));
            }
        };
        let decoder = image::codecs::png::PngDecoder::new(Cursor::new(&bytes[..]))
            .map_err(|e| fail(format!("image {image_index} is not a readable PNG: {e}")))?;
        let (width, height) = decoder.dimensions();
        if width > MAX_TEXTURE_SIZE || height > MAX_TEXTURE_SIZE {
            return Err(PlantFileError::TextureTooLarge {
                path: self.path.to_owned(),
                texture: which,
                width,
                height,
                limit: MAX_TEXTURE_SIZE,
            });
        }
        let decoded = image::DynamicImage::from_decoder(decoder)
            .map_err(|e| fail(format!("image {image_index} is not a readable PNG: {e}")))?;
        Ok(PlantImage {
            width,
            height,
            rgba: decoded.to_rgba8().into_raw(),
        })
    }
}

/// Keeps the first texture any primitive names; warns when a later one names another.
fn pick_texture(chosen: &mut Option<usize>, texture: Option<usize>, which: PlantTexture) {
    match (*chosen, texture) {
        (None, Some(t)) => *chosen = Some(t),
        (Some(c), Some(t)) if c != t => {
            log::warn!("plant materials name several {which} textures: only texture {c} is used")
        }
        _ => {}
    }
}

/// Triangles a primitive of `elements` indices draws.
fn triangles_of(mode: Mode, elements: usize) -> usize {
    match mode {
        Mode::Triangles => elements / 3,
        Mode::TriangleStrip | Mode::TriangleFan => elements.saturating_sub(2),
        _ => 0,
    }
}

/// Strips and fans as a list of triangles, counter-clockwise.
fn triangle_list(mode: Mode, elements: &[u32]) -> Vec<u32> {
    match mode {
        Mode::TriangleStrip => elements
            .windows(3)
            .enumerate()
            .flat_map(|(i, w)| {
                if i % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[1], w[0], w[2]]
                }
            })
            .collect(),
        Mode::TriangleFan => {
            if elements.len() < 3 {
                return Vec::new();
            }
            elements[1..]
                .windows(2)
                .flat_map(|w| [elements[0], w[0], w[1]])
                .collect()
        }
        _ => elements[..elements.len() / 3 * 3].to_vec(),
    }
}

/// Area-weighted vertex normals from the triangles (local indices into `vertices`).
fn smooth_normals(vertices: &mut [PlantVertex], triangles: &[u32]) {
    let mut sums = vec![Vec3::ZERO; vertices.len()];
    for t in triangles.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize);
        let p = |i: usize| Vec3::from_array(vertices[i].position);
        let face = (p(b) - p(a)).cross(p(c) - p(a));
        for i in [a, b, c] {
            sums[i] += face;
        }
    }
    for (v, sum) in vertices.iter_mut().zip(sums) {
        v.normal = sum.try_normalize().unwrap_or(Vec3::Z).to_array();
    }
}

fn finite_or(x: f32, fallback: f32) -> f32 {
    if x.is_finite() { x } else { fallback }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_become_counter_clockwise_lists() {
        assert_eq!(
            triangle_list(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![0, 1, 2, 2, 1, 3]
        );
        assert_eq!(
            triangle_list(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![0, 1, 2, 0, 2, 3]
        );
        assert_eq!(triangle_list(Mode::Triangles, &[0, 1, 2, 3]), vec![0, 1, 2]);
        assert_eq!(triangles_of(Mode::TriangleFan, 1), 0);
    }
}
