//! A user's plant from a glTF 2.0 file (`.gltf` with external or data-URI buffers, or `.glb`),
//! read into one [`PlantMesh`] with its base colour and thickness textures.
//!
//! What is read:
//!
//! - every triangle primitive (`TRIANGLES`, `TRIANGLE_STRIP`, `TRIANGLE_FAN`) of every mesh
//!   reachable from the default scene's nodes (the first scene when none is named, every mesh
//!   when the file has no scene), with the node transforms applied. Points and lines are skipped
//!   with a warning; so are primitives without `POSITION`.
//! - glTF is y-up, plant space z-up (x east, y north): a point (x, y, z) of the file becomes
//!   (x, -z, y); normals likewise. The file's origin stays the plant's root.
//! - `POSITION` is required; `NORMAL` is optional (smooth normals are computed when absent);
//!   `TEXCOORD_0` is optional ((0, 0) when absent); `COLOR_0` is optional and carries the
//!   bending channels of [`PlantVertex::wind`] (r edge flutter, g phase, b leaf or branch
//!   freedom, a ambient occlusion; RGB or RGBA, float or normalised integers). Without it a
//!   vertex gets r 0, g 0, b = its height over the mesh's height, a 1.
//! - albedo: the material's `baseColorFactor` rgb (linear); albedo.a (thinness) is 0.5.
//! - the base colour texture (`pbrMetallicRoughness.baseColorTexture`) and the thickness texture
//!   (`KHR_materials_volume.thicknessTexture`, thickness in its green channel) of the first
//!   material that has one, decoded from PNG to RGBA8; from a file beside the glTF, a data URI
//!   or a buffer view.
//!
//! Limits: at most [`MAX_PLANT_VERTICES`] vertices and [`MAX_PLANT_TRIANGLES`] triangles after
//! merging, textures at most [`MAX_TEXTURE_SIZE`] pixels a side. Any input, however malformed,
//! gives a [`PlantFileError`] naming the file, never a panic.

use std::cell::OnceCell;
use std::fmt;
use std::io::{self, Cursor};
use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{Mat3, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;
use gltf::{Gltf, Semantic};
use image::ImageDecoder as _;
use percent_encoding::{AsciiSet, NON_ALPHANUMERIC, percent_decode_str, utf8_percent_encode};
use serde_json::json;
use thiserror::Error;

use super::mesh::{PlantImage, PlantMesh, PlantVertex};

/// The most vertices a plant may have after its primitives are merged.
pub const MAX_PLANT_VERTICES: usize = 65_536;
/// The most triangles a plant may have after its primitives are merged.
pub const MAX_PLANT_TRIANGLES: usize = 131_072;
/// The largest width and height of a plant's texture, pixels.
pub const MAX_TEXTURE_SIZE: u32 = 4096;
/// The thinness (albedo.a) given to every vertex of a loaded plant.
pub const DEFAULT_THINNESS: f32 = 0.5;

/// Node visits after which a scene is refused: a cycle, or a hierarchy that instances itself
/// exponentially, would otherwise never end.
const MAX_NODE_VISITS: usize = 65_536;

/// A plant read from a glTF file.
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedPlant {
    /// All triangle primitives merged, in plant space (z up).
    pub mesh: PlantMesh,
    /// The base colour texture (sRGB, alpha for cut-outs), when the file has one.
    pub base_color: Option<PlantImage>,
    /// The `KHR_materials_volume` thickness texture (thickness in green), when the file has one.
    pub thickness: Option<PlantImage>,
}

/// Which of a plant's textures an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlantTexture {
    /// `pbrMetallicRoughness.baseColorTexture`.
    BaseColor,
    /// `KHR_materials_volume.thicknessTexture`.
    Thickness,
}

impl fmt::Display for PlantTexture {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::BaseColor => "base colour",
            Self::Thickness => "thickness",
        })
    }
}

/// Why a plant file could not be loaded. Every message names the file.
#[derive(Debug, Error)]
pub enum PlantFileError {
    /// The file is missing or unreadable.
    #[error("cannot read plant file {}: {source}", path.display())]
    Read {
        /// The glTF file.
        path: PathBuf,
        /// The reason.
        #[source]
        source: io::Error,
    },
    /// The file is not glTF 2.0 (or breaks its rules).
    #[error("plant file {} is not valid glTF 2.0: {reason}", path.display())]
    NotGltf {
        /// The glTF file.
        path: PathBuf,
        /// The parser's reason.
        reason: String,
    },
    /// No triangle primitive with `POSITION` was found.
    #[error(
        "plant file {} has no triangle mesh with POSITION reachable from its scene",
        path.display()
    )]
    NoMesh {
        /// The glTF file.
        path: PathBuf,
    },
    /// More than [`MAX_PLANT_VERTICES`] vertices.
    #[error(
        "plant file {} has {count} vertices, more than the limit of {limit}",
        path.display()
    )]
    TooManyVertices {
        /// The glTF file.
        path: PathBuf,
        /// Vertices in all primitives together.
        count: usize,
        /// [`MAX_PLANT_VERTICES`].
        limit: usize,
    },
    /// More than [`MAX_PLANT_TRIANGLES`] triangles.
    #[error(
        "plant file {} has {count} triangles, more than the limit of {limit}",
        path.display()
    )]
    TooManyTriangles {
        /// The glTF file.
        path: PathBuf,
        /// Triangles in all primitives together.
        count: usize,
        /// [`MAX_PLANT_TRIANGLES`].
        limit: usize,
    },
    /// A texture could not be read or decoded.
    #[error("plant file {}: the {texture} texture does not decode: {reason}", path.display())]
    Texture {
        /// The glTF file.
        path: PathBuf,
        /// Which texture.
        texture: PlantTexture,
        /// Why.
        reason: String,
    },
    /// A texture is larger than [`MAX_TEXTURE_SIZE`] on a side.
    #[error(
        "plant file {}: the {texture} texture is {width}x{height} pixels, larger than the limit of {limit}x{limit}",
        path.display()
    )]
    TextureTooLarge {
        /// The glTF file.
        path: PathBuf,
        /// Which texture.
        texture: PlantTexture,
        /// Its width, pixels.
        width: u32,
        /// Its height, pixels.
        height: u32,
        /// [`MAX_TEXTURE_SIZE`].
        limit: u32,
    },
    /// A buffer's data could not be read.
    #[error("plant file {}: buffer {buffer} is missing: {reason}", path.display())]
    BufferMissing {
        /// The glTF file.
        path: PathBuf,
        /// The buffer's index.
        buffer: usize,
        /// Why (the file or data URI and the reason).
        reason: String,
    },
    /// A buffer holds fewer bytes than the file says, or than a view or accessor reads.
    #[error(
        "plant file {}: buffer {buffer} is too short: it holds {len} bytes, {needed} are needed",
        path.display()
    )]
    BufferTooShort {
        /// The glTF file.
        path: PathBuf,
        /// The buffer's index.
        buffer: usize,
        /// Bytes it holds.
        len: usize,
        /// Bytes needed.
        needed: usize,
    },
    /// A primitive's index refers past its vertices.
    #[error(
        "plant file {}: mesh {mesh} primitive {primitive} has index {index}, out of range for its {vertices} vertices",
        path.display()
    )]
    IndexOutOfRange {
        /// The glTF file.
        path: PathBuf,
        /// The mesh's index.
        mesh: usize,
        /// The primitive's index within the mesh.
        primitive: usize,
        /// The offending index.
        index: u32,
        /// Vertices of the primitive.
        vertices: usize,
    },
    /// A primitive's data does not fit the rules (types, counts, strides, finite values).
    #[error("plant file {}: mesh {mesh} primitive {primitive}: {problem}", path.display())]
    BadPrimitive {
        /// The glTF file.
        path: PathBuf,
        /// The mesh's index.
        mesh: usize,
        /// The primitive's index within the mesh.
        primitive: usize,
        /// What is wrong.
        problem: String,
    },
}

/// Reads a plant from a glTF 2.0 file (`.gltf` or `.glb`); see the module docs for what is read
/// and the limits.
pub fn load_plant(path: &Path) -> Result<LoadedPlant, PlantFileError> {
    let bytes = std::fs::read(path).map_err(|source| PlantFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    Loader::new(path, &bytes)?.load()
}

/// A triangle primitive to read, with the transform from its node's space to plant space.
struct Instance<'a> {
    mesh: usize,
    primitive: gltf::Primitive<'a>,
    transform: Mat4,
}

/// A problem inside an accessor, before the primitive it belongs to is known.
enum AccessorError {
    Plant(PlantFileError),
    Bad(String),
}

impl From<PlantFileError> for AccessorError {
    fn from(e: PlantFileError) -> Self {
        Self::Plant(e)
    }
}

struct Loader<'p> {
    path: &'p Path,
    gltf: Gltf,
    /// Buffer data by index, read when first needed.
    buffers: Vec<OnceCell<Vec<u8>>>,
}

impl<'p> Loader<'p> {
    fn new(path: &'p Path, bytes: &[u8]) -> Result<Self, PlantFileError> {
        let not_gltf = |reason: String| PlantFileError::NotGltf {
            path: path.to_owned(),
            reason,
        };
        // The glb reader subtracts the header's size from its length field unchecked.
        if bytes.starts_with(b"glTF") {
            let length = bytes
                .get(8..12)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            match length {
                None => return Err(not_gltf("the binary header is cut short".into())),
                Some(n) if n < 12 => {
                    return Err(not_gltf(format!(
                        "the binary header gives a length of {n} bytes"
                    )));
                }
                Some(_) => {}
            }
        }
        let gltf =
            Gltf::from_slice_without_validation(bytes).map_err(|e| not_gltf(e.to_string()))?;
        validate(&gltf).map_err(not_gltf)?;
        let buffers = vec![OnceCell::new(); gltf.buffers().len()];
        Ok(Self {
            path,
            gltf,
            buffers,
        })
    }

    fn load(self) -> Result<LoadedPlant, PlantFileError> {
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
                let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, axes)).collect();
                let mut visits = 0usize;
                while let Some((node, parent)) = stack.pop() {
                    visits += 1;
                    if visits > MAX_NODE_VISITS {
                        return Err(PlantFileError::NotGltf {
                            path: self.path.to_owned(),
                            reason: format!(
                                "the scene's node hierarchy has a cycle or more than {MAX_NODE_VISITS} node instances"
                            ),
                        });
                    }
                    let local = Mat4::from_cols_array_2d(&node.transform().matrix());
                    let world = parent * local;
                    if let Some(mesh) = node.mesh() {
                        meshes.push((mesh, world));
                    }
                    for child in node.children() {
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

    /// The data of a buffer, read when first asked for.
    fn buffer(&self, index: usize) -> Result<&[u8], PlantFileError> {
        if self.buffers.get(index).is_some_and(|b| b.get().is_none()) {
            let buffer =
                self.gltf
                    .buffers()
                    .nth(index)
                    .ok_or_else(|| PlantFileError::BufferMissing {
                        path: self.path.to_owned(),
                        buffer: index,
                        reason: "no such buffer".into(),
                    })?;
            let missing = |reason: String| PlantFileError::BufferMissing {
                path: self.path.to_owned(),
                buffer: index,
                reason,
            };
            let data = match buffer.source() {
                gltf::buffer::Source::Bin => self
                    .gltf
                    .blob
                    .clone()
                    .ok_or_else(|| missing("the file has no binary chunk".into()))?,
                gltf::buffer::Source::Uri(uri) => read_uri(self.path, uri).map_err(missing)?,
            };
            if data.len() < buffer.length() {
                return Err(PlantFileError::BufferTooShort {
                    path: self.path.to_owned(),
                    buffer: index,
                    len: data.len(),
                    needed: buffer.length(),
                });
            }
            let _ = self.buffers[index].set(data);
        }
        Ok(self
            .buffers
            .get(index)
            .and_then(|b| b.get())
            .map_or(&[], Vec::as_slice))
    }

    /// The bytes of a buffer view, checked against its buffer.
    fn view_bytes(&self, view: &gltf::buffer::View) -> Result<&[u8], PlantFileError> {
        let index = view.buffer().index();
        let path = self.path.to_owned();
        let (start, length) = (view.offset(), view.length());
        let data = self.buffer(index)?;
        let end = start.saturating_add(length);
        data.get(start..end).ok_or(PlantFileError::BufferTooShort {
            path,
            buffer: index,
            len: data.len(),
            needed: end,
        })
    }

    /// An accessor's values, component by component, as f32 (integers normalised to 0..1 or
    /// -1..1 when the accessor says so or `normalize` asks).
    fn read_accessor(
        &self,
        acc: &gltf::Accessor,
        name: &str,
        dims: &[Dimensions],
        normalize: bool,
    ) -> Result<Vec<f32>, AccessorError> {
        let dimensions = acc.dimensions();
        if !dims.contains(&dimensions) {
            return Err(AccessorError::Bad(format!(
                "{name} must be {}, not {dimensions:?}",
                dims.iter()
                    .map(|d| format!("{d:?}"))
                    .collect::<Vec<_>>()
                    .join(" or ")
            )));
        }
        let normalize = normalize || acc.normalized();
        let data_type = acc.data_type();
        let components = dimensions.multiplicity();
        let component_size = data_type.size();
        let element = components * component_size;
        let count = acc.count();
        // The vertex and triangle limits were checked against counts before; this guards the
        // allocation of an accessor that no limit counted.
        if count > MAX_PLANT_TRIANGLES * 3 {
            return Err(AccessorError::Bad(format!(
                "{name} has {count} entries, more than any plant within the limits needs"
            )));
        }
        let mut values = vec![0.0f32; count * components];
        if count == 0 {
            return Ok(values);
        }
        if let Some(view) = acc.view() {
            let stride = view.stride().unwrap_or(element);
            if stride < element {
                return Err(AccessorError::Bad(format!(
                    "{name}'s byte stride {stride} is less than its element size {element}"
                )));
            }
            let offset = acc.offset();
            let bytes = self.view_bytes(&view)?;
            let needed = stride
                .checked_mul(count - 1)
                .and_then(|x| x.checked_add(offset))
                .and_then(|x| x.checked_add(element));
            if needed.is_none_or(|needed| needed > bytes.len()) {
                return Err(AccessorError::Bad(format!(
                    "{name} reads past the end of buffer view {} ({} bytes)",
                    view.index(),
                    bytes.len()
                )));
            }
            for i in 0..count {
                let at = offset + i * stride;
                for c in 0..components {
                    values[i * components + c] =
                        component(&bytes[at + c * component_size..], data_type, normalize);
                }
            }
        }
        if let Some(sparse) = acc.sparse() {
            let sc = sparse.count();
            if sc > count {
                return Err(AccessorError::Bad(format!(
                    "{name} has {sc} sparse entries, more than its {count} entries"
                )));
            }
            let indices = sparse.indices();
            let index_size = indices.index_type().size();
            let index_type = match indices.index_type() {
                gltf::accessor::sparse::IndexType::U8 => DataType::U8,
                gltf::accessor::sparse::IndexType::U16 => DataType::U16,
                gltf::accessor::sparse::IndexType::U32 => DataType::U32,
            };
            let index_offset = indices.offset();
            let index_bytes = self.view_bytes(&indices.view())?.to_vec();
            let vals = sparse.values();
            let value_offset = vals.offset();
            let value_bytes = self.view_bytes(&vals.view())?;
            let fits = |offset: usize, size: usize, len: usize| {
                sc.checked_mul(size)
                    .and_then(|x| x.checked_add(offset))
                    .is_some_and(|end| end <= len)
            };
            if !fits(index_offset, index_size, index_bytes.len())
                || !fits(value_offset, element, value_bytes.len())
            {
                return Err(AccessorError::Bad(format!(
                    "{name}'s sparse data reads past the end of its buffer views"
                )));
            }
            for k in 0..sc {
                let target = component(
                    &index_bytes[index_offset + k * index_size..],
                    index_type,
                    false,
                );
                let target = target as usize;
                if target >= count {
                    return Err(AccessorError::Bad(format!(
                        "{name} has sparse index {target}, out of range for its {count} entries"
                    )));
                }
                let at = value_offset + k * element;
                for c in 0..components {
                    values[target * components + c] = component(
                        &value_bytes[at + c * component_size..],
                        data_type,
                        normalize,
                    );
                }
            }
        }
        Ok(values)
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
            (None, Some(uri)) => read_uri(self.path, uri).map_err(&fail)?,
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

/// Checks the document as the gltf crate would, except for rules this loader does not rely on:
/// `POSITION`'s `min` and `max` (often left out by exporters), a primitive without `POSITION`
/// (skipped instead), and application-specific attribute names (ignored).
fn validate(gltf: &Gltf) -> Result<(), String> {
    use gltf::json::validation::{Error, Validate};
    let root = gltf.as_json();
    // gltf-json's own check of POSITION looks its accessor up unchecked: check the index first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &primitive.attributes {
                if index.value() >= root.accessors.len() {
                    let name = match semantic {
                        gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        gltf::json::validation::Checked::Invalid => "?".into(),
                    };
                    return Err(format!(
                        "meshes[{m}].primitives[{p}].attributes[\"{name}\"]: accessor {} does not exist",
                        index.value()
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| {
        let path = path().to_string();
        let tolerated = path.contains(".attributes[")
            && (path.ends_with("[\"POSITION\"].min")
                || path.ends_with("[\"POSITION\"].max")
                || (path.ends_with("[\"POSITION\"]") && error == Error::Missing)
                || (path.ends_with(']') && error == Error::Invalid));
        if !tolerated {
            errors.push(format!("{path}: {error}"));
        }
    });
    if errors.is_empty() {
        Ok(())
    } else {
        let more = if errors.len() > 3 {
            format!(" (and {} more)", errors.len() - 3)
        } else {
            String::new()
        };
        errors.truncate(3);
        Err(format!("{}{more}", errors.join("; ")))
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

/// One component at the start of `bytes` (the caller has checked there are enough).
fn component(bytes: &[u8], data_type: DataType, normalize: bool) -> f32 {
    let b = |n: usize| bytes.get(n).copied().unwrap_or(0);
    match data_type {
        DataType::I8 => {
            let v = b(0) as i8 as f32;
            if normalize { (v / 127.0).max(-1.0) } else { v }
        }
        DataType::U8 => {
            let v = b(0) as f32;
            if normalize { v / 255.0 } else { v }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes([b(0), b(1)]) as f32;
            if normalize {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes([b(0), b(1)]) as f32;
            if normalize { v / 65535.0 } else { v }
        }
        DataType::U32 => u32::from_le_bytes([b(0), b(1), b(2), b(3)]) as f32,
        DataType::F32 => f32::from_le_bytes([b(0), b(1), b(2), b(3)]),
    }
}

/// The bytes a glTF URI names: a base64 data URI, or a file relative to the glTF file.
fn read_uri(gltf_path: &Path, uri: &str) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((header, data)) = rest.split_once(',') else {
            return Err("a data URI without a comma".into());
        };
        if !header.ends_with(";base64") {
            return Err("a data URI that is not base64".into());
        }
        return base64::engine::general_purpose::STANDARD
            .decode(data)
            .map_err(|e| format!("a data URI with bad base64: {e}"));
    }
    let name = percent_decode_str(uri)
        .decode_utf8()
        .map_err(|_| format!("{uri:?} is not UTF-8 once percent-decoded"))?;
    // Only files beside the glTF file (or below it); no schemes, no absolute paths.
    let relative = Path::new(name.as_ref());
    if name.contains(':') || relative.is_absolute() {
        return Err(format!("{uri:?} is not a relative file name"));
    }
    let file = gltf_path.parent().unwrap_or(Path::new(".")).join(relative);
    std::fs::read(&file).map_err(|e| format!("cannot read {}: {e}", file.display()))
}

/// Characters kept as they are in a written URI (RFC 3986's unreserved set).
const URI_KEEP: &AsciiSet = &NON_ALPHANUMERIC
    .remove(b'-')
    .remove(b'_')
    .remove(b'.')
    .remove(b'~');

/// Writes a plant as a `.gltf` file with one base64 data-URI buffer: positions, normals, uvs,
/// `COLOR_0` (the wind channels, RGBA float) and u32 indices, converted from plant space (z up)
/// back to glTF's y up. The material's `baseColorFactor` is the first vertex's albedo. When
/// `base_color` is given it is written as a PNG beside the file (`<stem>_base_color.png`) and
/// named as the material's base colour texture.
///
/// An empty mesh, an index past the vertices, or an image whose bytes do not match its size is
/// refused with [`io::ErrorKind::InvalidInput`].
pub fn write_plant_gltf(
    path: &Path,
    mesh: &PlantMesh,
    base_color: Option<&PlantImage>,
) -> io::Result<()> {
    let invalid = |m: String| io::Error::new(io::ErrorKind::InvalidInput, m);
    if mesh.vertices.is_empty() || mesh.indices.is_empty() {
        return Err(invalid("a plant mesh needs vertices and triangles".into()));
    }
    let n = mesh.vertices.len();
    if let Some(&i) = mesh.indices.iter().find(|&&i| i as usize >= n) {
        return Err(invalid(format!(
            "index {i} is out of range for {n} vertices"
        )));
    }
    // Plant (x, y, z) z-up -> glTF (x, z, -y) y-up.
    let to_gltf = |v: [f32; 3]| [v[0], v[2], -v[1]];
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut push_view = |bin: &mut Vec<u8>, data: &[u8], target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(data);
        views.push(
            json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len(), "target": target}),
        );
        views.len() - 1
    };
    const ARRAY_BUFFER: u32 = 34962;
    const ELEMENT_ARRAY_BUFFER: u32 = 34963;
    let positions: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| to_gltf(v.position)).collect();
    let normals: Vec<[f32; 3]> = mesh.vertices.iter().map(|v| to_gltf(v.normal)).collect();
    let uvs: Vec<[f32; 2]> = mesh.vertices.iter().map(|v| v.uv).collect();
    let colors: Vec<[f32; 4]> = mesh.vertices.iter().map(|v| v.wind).collect();
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    for p in &positions {
        for k in 0..3 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    let v_pos = push_view(&mut bin, bytemuck::cast_slice(&positions), ARRAY_BUFFER);
    let v_nrm = push_view(&mut bin, bytemuck::cast_slice(&normals), ARRAY_BUFFER);
    let v_uv = push_view(&mut bin, bytemuck::cast_slice(&uvs), ARRAY_BUFFER);
    let v_col = push_view(&mut bin, bytemuck::cast_slice(&colors), ARRAY_BUFFER);
    let v_idx = push_view(
        &mut bin,
        bytemuck::cast_slice(&mesh.indices),
        ELEMENT_ARRAY_BUFFER,
    );
    const FLOAT: u32 = 5126;
    const UNSIGNED_INT: u32 = 5125;
    let albedo = mesh.vertices[0].albedo;
    let mut material = json!({
        "pbrMetallicRoughness": {
            "baseColorFactor": [albedo[0], albedo[1], albedo[2], 1.0],
            "metallicFactor": 0.0,
        },
        "doubleSided": true,
    });
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "verdant"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 3},
            "indices": 4,
            "material": 0,
            "mode": 4,
        }]}],
        "accessors": [
            {"bufferView": v_pos, "componentType": FLOAT, "count": n, "type": "VEC3", "min": min, "max": max},
            {"bufferView": v_nrm, "componentType": FLOAT, "count": n, "type": "VEC3"},
            {"bufferView": v_uv, "componentType": FLOAT, "count": n, "type": "VEC2"},
            {"bufferView": v_col, "componentType": FLOAT, "count": n, "type": "VEC4"},
            {"bufferView": v_idx, "componentType": UNSIGNED_INT, "count": mesh.indices.len(), "type": "SCALAR"},
        ],
        "bufferViews": views,
        "buffers": [{
            "byteLength": bin.len(),
            "uri": format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&bin)
            ),
        }],
    });
    if let Some(img) = base_color {
        let rgba = image::RgbaImage::from_raw(img.width, img.height, img.rgba.clone()).ok_or_else(
            || {
                invalid(format!(
                    "the base colour image has {} bytes, not {}x{}x4",
                    img.rgba.len(),
                    img.width,
                    img.height
                ))
            },
        )?;
        let stem = path
            .file_stem()
            .map_or_else(|| "plant".into(), |s| s.to_string_lossy().into_owned());
        let name = format!("{stem}_base_color.png");
        let png_path = path.with_file_name(&name);
        rgba.save_with_format(&png_path, image::ImageFormat::Png)
            .map_err(io::Error::other)?;
        material["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
        doc["textures"] = json!([{"source": 0}]);
        doc["images"] = json!([{"uri": utf8_percent_encode(&name, URI_KEEP).to_string()}]);
    }
    doc["materials"] = json!([material]);
    let text = serde_json::to_string_pretty(&doc).map_err(io::Error::other)?;
    std::fs::write(path, text)
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

    #[test]
    fn normalised_components() {
        assert_eq!(component(&[255], DataType::U8, true), 1.0);
        assert_eq!(component(&[0x80], DataType::I8, true), -1.0);
        assert_eq!(component(&[0xff, 0xff], DataType::U16, true), 1.0);
        assert_eq!(component(&[7, 0, 0, 0], DataType::U32, false), 7.0);
    }
}
