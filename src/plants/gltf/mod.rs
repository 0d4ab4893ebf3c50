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
//!   bending channels of [`PlantVertex::wind`](super::PlantVertex::wind) (r edge flutter,
//!   g phase, b leaf or branch freedom, a ambient occlusion; RGB or RGBA, float or normalised
//!   integers). Without it a vertex gets r 0, g 0, b = its height over the mesh's height, a 1.
//! - albedo: the material's `baseColorFactor` rgb (linear); albedo.a (thinness) is 0.5.
//! - the base colour texture (`pbrMetallicRoughness.baseColorTexture`) and the thickness texture
//!   (`KHR_materials_volume.thicknessTexture`, thickness in its green channel) of the first
//!   material that has one, decoded from PNG to RGBA8; from a file beside the glTF, a data URI
//!   or a buffer view.
//!
//! Limits: at most [`MAX_PLANT_VERTICES`] vertices and [`MAX_PLANT_TRIANGLES`] triangles after
//! merging, textures at most [`MAX_TEXTURE_SIZE`] pixels a side, a JSON of at most
//! [`MAX_PLANT_JSON_BYTES`] besides its strings' contents and whitespace. Buffers and images
//! are read from data URIs, the binary chunk, or files in the glTF file's folder or below it
//! (never through `..`). Any input, however malformed, gives a [`PlantFileError`] naming the
//! file, never a panic.
//!
//! The loader is in `load.rs` (the scene's primitives, the mesh, the textures), the file's
//! opening and the reading of its buffers, views and accessors in `accessor.rs`, the
//! document's check in `validate.rs`; [`write_plant_gltf`] (`write.rs`) writes a plant back as
//! glTF (the tests make their plant files with it).

mod accessor;
mod load;
mod validate;
mod write;

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

use thiserror::Error;

use super::mesh::{PlantImage, PlantMesh};

pub use write::write_plant_gltf;

/// The most vertices a plant may have after its primitives are merged.
pub const MAX_PLANT_VERTICES: usize = 65_536;
/// The most triangles a plant may have after its primitives are merged.
pub const MAX_PLANT_TRIANGLES: usize = 131_072;
/// The largest width and height of a plant's texture, pixels.
pub const MAX_TEXTURE_SIZE: u32 = 4096;
/// The most bytes a plant's glTF file, or a buffer or image file it names, may hold: room for
/// the most vertices and triangles and a texture of the largest size many times over. A file
/// that is not a regular file (a FIFO, a device) is refused before it is opened.
pub const MAX_PLANT_FILE_BYTES: u64 = 256 << 20;
/// The most bytes all the buffers of a plant's file may hold together (as their files and data
/// URIs hold them, and as the file declares them): a file listing many buffers, or many large
/// ones, is refused before it makes the loader hold more. Buffers naming the same file (or data
/// URI, or the binary chunk) share one read and count once.
pub const MAX_PLANT_BUFFER_BYTES: u64 = 256 << 20;
/// The most bytes the JSON of a plant's file (a `.gltf` file, or a `.glb`'s JSON chunk) may
/// hold besides the contents of its strings and its whitespace, checked before it is parsed.
/// Parsed, each of these bytes can cost some 64 bytes of memory (`{},` is a node of about
/// 190): at 4 MiB a file of empty nodes peaks at about 260 MiB, as much as one plant file may
/// hold. A plant's document is far smaller (10,000 nodes, each named, moved and turned, take
/// about 1 MiB). Strings cost about their own size and are left to [`MAX_PLANT_FILE_BYTES`]:
/// the data URIs of a `.gltf` with its buffers and images inside it do not count.
pub const MAX_PLANT_JSON_BYTES: u64 = 4 << 20;

/// Reads a file of a plant (its glTF file, or a buffer or image beside it): a regular file of
/// at most [`MAX_PLANT_FILE_BYTES`], the reason otherwise in words.
pub fn read_plant_file(path: &Path) -> Result<Vec<u8>, io::Error> {
    crate::world::format::read_regular(path, MAX_PLANT_FILE_BYTES).map_err(plant_file_io_error)
}

/// Reads a plant's file (its glTF file, or a buffer or image that file names) by its path under
/// the world's folder `dir`, from the world's tile source: its folder, or its server.
pub fn read_from_source(
    source: &dyn crate::stream::TileSource,
    dir: &Path,
    path: &Path,
) -> Result<Vec<u8>, io::Error> {
    let name = path.strip_prefix(dir).unwrap_or(path);
    source
        .read_file(name, MAX_PLANT_FILE_BYTES)
        .map_err(plant_file_io_error)
}

/// A world's error reading a plant's file, as the I/O error [`PlantFileError::Read`] gives
/// after the file's name: the reason alone, without the path again.
pub fn plant_file_io_error(e: crate::world::WorldError) -> io::Error {
    use crate::world::WorldError;
    match e {
        WorldError::NotARegularFile { kind, .. } => {
            io::Error::other(format!("not a regular file ({kind})"))
        }
        WorldError::FileTooLarge { size, max, .. } => io::Error::other(format!(
            "{size} bytes, more than the {max} that a plant's file may hold"
        )),
        WorldError::Io { source, .. } => source,
        WorldError::MissingFile { .. } => io::Error::from(io::ErrorKind::NotFound),
        e => io::Error::other(e.to_string()),
    }
}
/// The thinness (albedo.a) given to every vertex of a loaded plant.
pub const DEFAULT_THINNESS: f32 = 0.5;

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
    /// Triangle primitives with `POSITION` were found, but none draws a triangle (each has
    /// fewer than three indices, or vertices when it has no indices).
    #[error(
        "plant file {} has no triangles: its triangle primitives hold fewer than three indices \
         (or vertices) each, so nothing would be drawn",
        path.display()
    )]
    NoTriangles {
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
    /// The file's JSON holds more than [`MAX_PLANT_JSON_BYTES`] besides its strings' contents
    /// and whitespace; it is refused before it is parsed.
    #[error(
        "plant file {}: its JSON holds {bytes} bytes besides its strings' contents and \
         whitespace, more than the limit of {limit} (MAX_PLANT_JSON_BYTES)",
        path.display()
    )]
    JsonTooLarge {
        /// The glTF file.
        path: PathBuf,
        /// The JSON's bytes outside its strings, whitespace left out.
        bytes: u64,
        /// [`MAX_PLANT_JSON_BYTES`].
        limit: u64,
    },
    /// A buffer or image names a file the loader does not read: one outside the glTF file's
    /// folder (a `..` segment, percent-encoded or not), an absolute path, a scheme, or a name
    /// with a backslash. Every URI of the file is checked before anything is read.
    #[error("plant file {}: the URI {uri:?} is refused: {reason}", path.display())]
    BadUri {
        /// The glTF file.
        path: PathBuf,
        /// The URI as the file gives it.
        uri: String,
        /// Why.
        reason: String,
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
    /// The file's buffers together hold (or declare) more than [`MAX_PLANT_BUFFER_BYTES`].
    #[error(
        "plant file {}: its buffers hold {bytes} bytes or more together, more than the limit of \
         {limit} (MAX_PLANT_BUFFER_BYTES) for all the buffers of a plant",
        path.display()
    )]
    BuffersTooLarge {
        /// The glTF file.
        path: PathBuf,
        /// Bytes of the buffers read or declared when the limit was passed.
        bytes: u64,
        /// [`MAX_PLANT_BUFFER_BYTES`].
        limit: u64,
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
    load_plant_from(path, &read_plant_file)
}

/// Reads a plant's file by its path: [`read_plant_file`] for files on disk, or a world's other
/// store (a world over HTTP fetches its plants like its tiles).
pub type PlantFileReader<'r> = dyn Fn(&Path) -> Result<Vec<u8>, io::Error> + 'r;

/// Like [`load_plant`], with the glTF file and the buffers and images it names read by `read`
/// (each by its path: `path`, or the name the file gives joined to `path`'s folder).
pub fn load_plant_from(
    path: &Path,
    read: &PlantFileReader<'_>,
) -> Result<LoadedPlant, PlantFileError> {
    let bytes = read(path).map_err(|source| PlantFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    accessor::Loader::new(path, &bytes, read)?.load()
}
