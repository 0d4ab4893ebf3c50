//! Stored tile files and [`TileData`], the decoded contents of one tile.
//!
//! A stored tile is three files under `worlds/NAME/tiles/L{level}/`:
//! - `{x}_{y}.height.exr`: heights in metres, one `f32` channel named `Y`, ZIP compressed
//!   (lossless);
//! - `{x}_{y}.type.png`: 8-bit grayscale, the grass type index of each sample;
//! - `{x}_{y}.density.png`: 8-bit grayscale, grass density (0..=255 for 0..=1).
//!
//! The maps are written with 8 bits; grayscale maps of 1, 2 or 4 bits are read too, each
//! sample as its own value (a 4-bit sample 3 is type 3, or density 3 of 255), not scaled up
//! to 8 bits as image viewers show them. Palette (indexed-colour) maps are refused: their
//! samples are colours, and whether a map meant the index or the colour cannot be told.
//!
//! All three are `samples_per_side` square and stored with the first row at the NORTH edge, so
//! that they look right in an image viewer. In memory ([`TileData`]) the first row is the SOUTH
//! edge: index `j * size + i`, with `i` growing east and `j` north. Sample `(i, j)` lies at
//! `bounds.min + ((i - border) * cell, (j - border) * cell)`, so neighbouring tiles share their
//! edge and border samples, with identical values.
//!
//! The baker stamps each file with its own name and the bake's id ([`stamp`]), which readers
//! check where the manifest has a `bake_id` ([`check_stamp`]): a file copied over another, or one
//! of another bake, is refused rather than drawn.
//!
//! Files are written to a temporary name and renamed into place, so that an interrupted writer
//! never leaves half a tile. Readers check everything and never panic on bad bytes.

use std::io::Cursor;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use super::error::WorldError;
use super::tile::{Pyramid, TileId};

/// Whether `path` names a file on an HTTP server rather than on disk.
pub fn is_remote(path: &Path) -> bool {
    // The scheme in any case, as URLs have it (`HTTP://host/dem.tif` is remote too).
    path.to_str().is_some_and(|s| {
        let scheme = s.get(..8).unwrap_or(s).to_ascii_lowercase();
        scheme.starts_with("http://") || scheme.starts_with("https://")
    })
}

/// The files of a stored tile: three, and a fourth in worlds with terrain materials.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TileFile {
    /// Heights, `.height.exr`.
    Height,
    /// Grass type indices, `.type.png`.
    Type,
    /// Grass density, `.density.png`.
    Density,
    /// Terrain materials (`crate::world::Material`), `.material.png`: only in worlds whose
    /// manifest says `materials = true`.
    Material,
}

impl TileFile {
    /// The three every tile has, in the order height, type, density.
    pub const ALL: [TileFile; 3] = [TileFile::Height, TileFile::Type, TileFile::Density];

    /// The file's name under a world's `tiles/` folder, as its stamp names it:
    /// `L{level}/{x}_{y}.{kind}`.
    pub fn name_in_tiles(self, id: TileId) -> String {
        format!("L{}/{}_{}.{}", id.level, id.x, id.y, self.suffix())
    }

    fn suffix(self) -> &'static str {
        match self {
            TileFile::Height => "height.exr",
            TileFile::Type => "type.png",
            TileFile::Density => "density.png",
            TileFile::Material => "material.png",
        }
    }
}

/// Whether `name` is a tile file's name, `{x}_{y}.{kind}` ([`tile_path`]).
pub fn is_tile_file_name(name: &str) -> bool {
    let kinds = TileFile::ALL.into_iter().chain([TileFile::Material]);
    kinds.into_iter().any(|k| {
        name.strip_suffix(k.suffix())
            .and_then(|s| s.strip_suffix('.'))
            .and_then(|xy| xy.split_once('_'))
            .is_some_and(|(x, y)| x.parse::<u32>().is_ok() && y.parse::<u32>().is_ok())
    })
}

/// Whether `name` is a temporary file that [`write_atomic`] writes a tile file through
/// (`.{x}_{y}.{kind}.{pid}.tmp`), left where a writer (a bake, `verdant check --stamp`) was killed.
pub fn is_tile_temporary_name(name: &str) -> bool {
    name.strip_prefix('.')
        .and_then(|n| n.strip_suffix(".tmp"))
        .and_then(|n| n.rsplit_once('.'))
        .is_some_and(|(file, pid)| {
            !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()) && is_tile_file_name(file)
        })
}

/// The first entry of `tiles` (a world's `tiles/` folder) that is not what a bake writes there:
/// anything but folders `L{level}` holding regular files named by [`is_tile_file_name`] (or
/// [`is_tile_temporary_name`]: a killed writer's). None
/// when there is none (or `tiles` does not exist, or is a symlink: replacing it removes the link
/// alone).
pub fn first_foreign_in_tiles(tiles: &Path) -> std::io::Result<Option<PathBuf>> {
    match std::fs::symlink_metadata(tiles) {
        Ok(m) if m.file_type().is_symlink() => return Ok(None),
        Ok(m) if !m.is_dir() => return Ok(Some(tiles.to_path_buf())),
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    }
    for level in std::fs::read_dir(tiles)? {
        let level = level?;
        let name = level.file_name();
        let is_level = name
            .to_str()
            .and_then(|n| n.strip_prefix('L'))
            .is_some_and(|n| n.parse::<u8>().is_ok());
        if !is_level || !level.file_type()?.is_dir() {
            return Ok(Some(level.path()));
        }
        for file in std::fs::read_dir(level.path())? {
            let file = file?;
            let named = file
                .file_name()
                .to_str()
                .is_some_and(|n| is_tile_file_name(n) || is_tile_temporary_name(n));
            if !named || !file.file_type()?.is_file() {
                return Ok(Some(file.path()));
            }
        }
    }
    Ok(None)
}

/// Where a tile file lives: `world_dir/tiles/L{level}/{x}_{y}.{kind}`.
pub fn tile_path(world_dir: &Path, id: TileId, kind: TileFile) -> PathBuf {
    world_dir
        .join("tiles")
        .join(format!("L{}", id.level))
        .join(format!("{}_{}.{}", id.x, id.y, kind.suffix()))
}

/// The decoded contents of one tile; see the module docs for the sample layout.
#[derive(Clone, Debug, PartialEq)]
pub struct TileData {
    /// Which tile.
    pub id: TileId,
    /// Samples per edge (`Pyramid::samples_per_side`).
    pub size: u32,
    /// Heights in metres, `size * size`, south row first.
    pub heights: Vec<f32>,
    /// Grass type indices into `Manifest::grass_types`, same layout.
    pub grass_type: Vec<u8>,
    /// Grass density, 0..=255 for 0..=1, same layout.
    pub density: Vec<u8>,
    /// Terrain material bytes (`crate::world::Material`), same layout; empty in a world
    /// without materials (every sample then [`crate::world::Material::Default`]).
    pub material: Vec<u8>,
}

impl TileData {
    /// Height of sample `(i, j)` (column from the west, row from the south).
    pub fn height_at(&self, i: u32, j: u32) -> f32 {
        self.heights[self.index(i, j)]
    }

    /// Index of sample `(i, j)` in the sample vectors.
    pub fn index(&self, i: u32, j: u32) -> usize {
        j as usize * self.size as usize + i as usize
    }

    /// Bytes a tile of `size` samples a side holds in memory, as [`TileData::byte_size`] counts
    /// them.
    pub fn byte_size_for(size: u32) -> u64 {
        std::mem::size_of::<Self>() as u64 + u64::from(size) * u64::from(size) * 6
    }

    /// Bytes this tile holds in memory (samples and the struct itself), for cache budgets.
    pub fn byte_size(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.heights.len() * std::mem::size_of::<f32>()
            + self.grass_type.len()
            + self.density.len()
            + self.material.len()
    }

    /// `material` as a tile holds it: a map of only the default material is no map (as a world
    /// without materials stores it), so that tiles compare equal however they were made.
    pub fn material_map(material: Vec<u8>) -> Vec<u8> {
        if material.iter().all(|&m| m == 0) {
            Vec::new()
        } else {
            material
        }
    }

    /// The material byte of sample `k` (0 where the tile has no material map).
    pub fn material_at(&self, k: usize) -> u8 {
        self.material.get(k).copied().unwrap_or(0)
    }
}

/// What [`read_tile_with`] checks a tile against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadOptions {
    /// The manifest's height range; heights beyond it by more than 1 m + 1 % of its span are
    /// refused.
    pub height_range_m: [f32; 2],
    /// Number of grass types in the manifest; larger type indices are refused.
    pub grass_type_count: usize,
    /// Whether the world's tiles have a material map (the manifest's `materials`), read and
    /// checked then.
    pub materials: bool,
    /// The bake that wrote the world's tiles (the manifest's `bake_id`): each file's stamp is
    /// checked against it and the file's own name ([`check_stamp`]). `None`: not checked.
    pub bake_id: Option<u64>,
}

/// The key of a tile file's stamp: the keyword of a PNG `tEXt` chunk, the name of a text
/// attribute in an EXR header.
pub const STAMP_KEY: &str = "verdant-tile";

/// The stamp the baker writes into a tile file: the file's name under `tiles/`
/// ([`TileFile::name_in_tiles`]) and the bake's id, 16 hexadecimal digits:
/// `L2/3_4.type.png 0123456789abcdef`.
pub fn stamp(id: TileId, kind: TileFile, bake_id: u64) -> String {
    format!("{} {bake_id:016x}", kind.name_in_tiles(id))
}

/// The stamp a tile file's bytes carry: the first, if they carry any and their header can be
/// read ([`read_stamps`]).
pub fn read_stamp(bytes: &[u8], kind: TileFile) -> Option<String> {
    read_stamps(bytes, kind).and_then(|s| s.into_iter().next())
}

/// Every stamp a tile file's bytes carry (a PNG's `tEXt` chunks keyed [`STAMP_KEY`] before its
/// image data; an EXR header's text attribute of that name), or `None` where their header
/// cannot be read (the decoder then says what is wrong with the file).
pub fn read_stamps(bytes: &[u8], kind: TileFile) -> Option<Vec<String>> {
    match kind {
        TileFile::Height => guarded(|| {
            let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false)
                .map_err(|e| e.to_string())?;
            let key = exr::meta::attribute::Text::new_or_none(STAMP_KEY);
            let found = meta
                .headers
                .first()
                .and_then(|h| key.as_ref().and_then(|k| h.own_attributes.other.get(k)));
            Ok(match found {
                Some(exr::meta::attribute::AttributeValue::Text(t)) => vec![t.to_string()],
                // An attribute of the name but of another type stamps nothing.
                _ => Vec::new(),
            })
        })
        .ok(),
        TileFile::Type | TileFile::Density | TileFile::Material => guarded(|| {
            let reader = png::Decoder::new(Cursor::new(bytes))
                .read_info()
                .map_err(|e| e.to_string())?;
            Ok(reader
                .info()
                .uncompressed_latin1_text
                .iter()
                .filter(|t| t.keyword == STAMP_KEY)
                .map(|t| t.text.clone())
                .collect())
        })
        .ok(),
    }
}

/// The longest stamp the baker writes, and more: a level, two coordinates of up to ten digits,
/// the longest suffix and the id.
const MAX_STAMP_BYTES: usize = 80;

/// A stamp as the baker writes it, split into the file's name and the id; `None` for anything
/// else.
fn parse_stamp(stamp: &str) -> Option<(&str, &str)> {
    if stamp.len() > MAX_STAMP_BYTES {
        return None;
    }
    let (name, id) = stamp.split_once(' ')?;
    let name_ok = !name.is_empty() && name.bytes().all(|b| b.is_ascii_graphic());
    let id_ok = id.len() == 16 && id.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'));
    (name_ok && id_ok).then_some((name, id))
}

/// A stamp's text as a message quotes it: escaped (a stamp comes from a file, perhaps a
/// server's, and must not drive the terminal that prints it) and cut short.
fn quoted_stamp(stamp: &str) -> String {
    let cut: String = stamp.chars().take(MAX_STAMP_BYTES).collect();
    let more = if cut.len() < stamp.len() { "..." } else { "" };
    format!("{cut:?}{more}")
}

/// Checks that a tile file's `bytes` are the file `kind` of tile `id` written by the bake
/// `options.bake_id`, by the stamp the baker wrote into it ([`stamp`]): a file that names
/// another tile (copied or renamed over this one) or another bake (left by an older world, as
/// a copy, cache or mirror may hold it), a file without a stamp (edited by hand, or its
/// metadata stripped by a tool or a server's image optimiser) and one with several are refused,
/// naming the file and what was found. Every file of a world without a `bake_id` is taken as it
/// is. `path` names the file in errors.
pub fn check_stamp(
    bytes: &[u8],
    id: TileId,
    kind: TileFile,
    options: &ReadOptions,
    path: &Path,
) -> Result<(), WorldError> {
    let Some(bake_id) = options.bake_id else {
        return Ok(());
    };
    let Some(stamps) = read_stamps(bytes, kind) else {
        return Ok(());
    };
    let refuse = |message: String| {
        Err(WorldError::TileStamp {
            path: path.to_path_buf(),
            message,
        })
    };
    let want = format!("{bake_id:016x}");
    let name = kind.name_in_tiles(id);
    let found = match stamps.as_slice() {
        [] => {
            return refuse(format!(
                "carries no {STAMP_KEY} stamp, though the world's world.toml names the bake \
                 that wrote its tiles (bake_id \"{want}\"): a file edited by hand, or one whose \
                 metadata a tool or server stripped; if the change was meant, `verdant check \
                 WORLD --stamp` records the world as it is now"
            ));
        }
        [one] => one,
        many => {
            return refuse(format!(
                "carries {} {STAMP_KEY} stamps where the baker writes one",
                many.len()
            ));
        }
    };
    let Some((found_name, found_bake)) = parse_stamp(found) else {
        return refuse(format!(
            "its {STAMP_KEY} stamp {} is not \"{name} {want}\" nor any stamp the baker writes",
            quoted_stamp(found)
        ));
    };
    if found_name != name {
        return refuse(format!(
            "holds {found_name} (its {STAMP_KEY} stamp), not {name}: a tile file copied or \
             renamed over another; restore the file, or bake the world again"
        ));
    }
    if found_bake != want {
        return refuse(format!(
            "written by another bake (bake_id \"{found_bake}\") than the world's world.toml \
             (bake_id \"{want}\"): tiles of two bakes mixed, as a copy, cache or mirror of an \
             older world may hold them; copy or bake the world again whole"
        ));
    }
    Ok(())
}

/// Writes the files of `tile` (the material map only where it has one), each through a
/// temporary file renamed into place, without stamps ([`write_tile_with`]).
pub fn write_tile(world_dir: &Path, pyramid: &Pyramid, tile: &TileData) -> Result<(), WorldError> {
    write_tile_with(world_dir, pyramid, tile, None)
}

/// [`write_tile`], each file stamped with its name and `bake_id` where one is given
/// ([`stamp`]), as the baker writes them.
pub fn write_tile_with(
    world_dir: &Path,
    pyramid: &Pyramid,
    tile: &TileData,
    bake_id: Option<u64>,
) -> Result<(), WorldError> {
    let size = pyramid.samples_per_side();
    let n = size as usize * size as usize;
    let height_path = tile_path(world_dir, tile.id, TileFile::Height);
    let bad = |message: String| WorldError::BadTileData {
        path: height_path.clone(),
        message,
    };
    if !pyramid.contains(tile.id) {
        return Err(bad(format!("tile {} is outside the pyramid", tile.id)));
    }
    if tile.size != size
        || tile.heights.len() != n
        || tile.grass_type.len() != n
        || tile.density.len() != n
        || !(tile.material.is_empty() || tile.material.len() == n)
    {
        return Err(bad(format!(
            "expected {size}x{size} samples ({n} per map), found size {} with {} heights, {} types, {} densities, {} materials",
            tile.size,
            tile.heights.len(),
            tile.grass_type.len(),
            tile.density.len(),
            tile.material.len()
        )));
    }
    if let Some(k) = tile.heights.iter().position(|h| !h.is_finite()) {
        return Err(bad(format!(
            "height sample (i={}, j={}) is {}",
            k % size as usize,
            k / size as usize,
            tile.heights[k]
        )));
    }

    let stamp_of = |kind| bake_id.map(|b| stamp(tile.id, kind, b));
    let exr = encode_exr(
        &north_first(&tile.heights, size),
        size,
        stamp_of(TileFile::Height).as_deref(),
    )
    .map_err(|message| bad(format!("EXR encoding failed: {message}")))?;
    write_atomic(&height_path, &exr)?;
    for (kind, data) in [
        (TileFile::Type, &tile.grass_type),
        (TileFile::Density, &tile.density),
        (TileFile::Material, &tile.material),
    ] {
        if data.is_empty() {
            continue;
        }
        let path = tile_path(world_dir, tile.id, kind);
        let png = encode_map(&north_first(data, size), size, stamp_of(kind).as_deref()).map_err(
            |message| WorldError::BadTileData {
                path: path.clone(),
                message: format!("PNG encoding failed: {message}"),
            },
        )?;
        write_atomic(&path, &png)?;
    }
    Ok(())
}

/// Reads and checks a stored tile. Heights are checked against `height_range_m`; grass type
/// indices are not checked and no material map is read (use [`read_tile_with`] for that).
pub fn read_tile(
    world_dir: &Path,
    pyramid: &Pyramid,
    id: TileId,
    height_range_m: [f32; 2],
) -> Result<TileData, WorldError> {
    let options = ReadOptions {
        height_range_m,
        grass_type_count: 256,
        materials: false,
        bake_id: None,
    };
    read_tile_with(world_dir, pyramid, id, &options)
}

/// Reads a stored tile and checks its dimensions, layout, heights and grass type indices.
pub fn read_tile_with(
    world_dir: &Path,
    pyramid: &Pyramid,
    id: TileId,
    options: &ReadOptions,
) -> Result<TileData, WorldError> {
    if !pyramid.is_stored(id) {
        return Err(WorldError::TileNotStored {
            path: world_dir.to_path_buf(),
            id,
        });
    }
    let size = pyramid.samples_per_side();

    let read = |kind| -> Result<(Vec<u8>, PathBuf), WorldError> {
        let path = tile_path(world_dir, id, kind);
        let bytes = read_regular(&path, max_file_bytes(kind, size))?;
        check_stamp(&bytes, id, kind, options, &path)?;
        Ok((bytes, path))
    };
    let (bytes, path) = read(TileFile::Height)?;
    let heights = decode_heights(&bytes, size, options, &path)?;
    let (bytes, path) = read(TileFile::Type)?;
    let grass_type = decode_grass_types(&bytes, size, options, &path)?;
    let (bytes, path) = read(TileFile::Density)?;
    let density = decode_density(&bytes, size, &path)?;
    let material = if options.materials {
        let (bytes, path) = read(TileFile::Material)?;
        decode_material(&bytes, size, &path)?
    } else {
        Vec::new()
    };
    Ok(TileData {
        id,
        size,
        heights,
        grass_type,
        density,
        material,
    })
}

/// Decodes a tile's height file (`size` samples a side) into south-first heights, each finite
/// and within the height range of `options` (with its tolerance). `path` names the file in
/// errors.
pub fn decode_heights(
    bytes: &[u8],
    size: u32,
    options: &ReadOptions,
    path: &Path,
) -> Result<Vec<f32>, WorldError> {
    let path = path.to_path_buf();
    let heights = south_first(&decode_exr(bytes, size, &path)?, size);
    let [lo, hi] = options.height_range_m;
    let tolerance = 1.0 + 0.01 * (hi - lo).abs();
    for (k, &h) in heights.iter().enumerate() {
        let (i, j) = (k as u32 % size, k as u32 / size);
        if !h.is_finite() {
            return Err(WorldError::NonFiniteHeight {
                path,
                i,
                j,
                value: h,
            });
        }
        if h < lo - tolerance || h > hi + tolerance {
            return Err(WorldError::HeightOutOfRange {
                path,
                i,
                j,
                value: h,
                range: options.height_range_m,
            });
        }
    }
    Ok(heights)
}

/// Decodes a tile's grass type map into south-first indices, each below the grass type count
/// of `options`.
pub fn decode_grass_types(
    bytes: &[u8],
    size: u32,
    options: &ReadOptions,
    path: &Path,
) -> Result<Vec<u8>, WorldError> {
    let grass_type = south_first(&decode_png_l8(bytes, size, path)?, size);
    if let Some(k) = grass_type
        .iter()
        .position(|&t| usize::from(t) >= options.grass_type_count)
    {
        return Err(WorldError::GrassTypeOutOfRange {
            path: path.to_path_buf(),
            i: k as u32 % size,
            j: k as u32 / size,
            index: grass_type[k],
            count: options.grass_type_count,
        });
    }
    Ok(grass_type)
}

/// Decodes a tile's material map into south-first material bytes, each a
/// [`crate::world::Material`].
pub fn decode_material(bytes: &[u8], size: u32, path: &Path) -> Result<Vec<u8>, WorldError> {
    let material = south_first(&decode_png_l8(bytes, size, path)?, size);
    if let Some(k) = material
        .iter()
        .position(|&m| usize::from(m) >= crate::world::MATERIAL_COUNT)
    {
        return Err(WorldError::BadTileData {
            path: path.to_path_buf(),
            message: format!(
                "material {} at sample (i={}, j={}) is not one of the {} materials ({})",
                material[k],
                k as u32 % size,
                k as u32 / size,
                crate::world::MATERIAL_COUNT,
                crate::world::Material::names()
            ),
        });
    }
    Ok(material)
}

/// Decodes a tile's density map into south-first densities.
pub fn decode_density(bytes: &[u8], size: u32, path: &Path) -> Result<Vec<u8>, WorldError> {
    Ok(south_first(&decode_png_l8(bytes, size, path)?, size))
}

/// The most bytes a tile file of `size` samples a side may hold: twice its raw samples (a
/// compressor never doubles them) and 64 KiB of headers.
pub fn max_file_bytes(kind: TileFile, size: u32) -> u64 {
    let samples = u64::from(size) * u64::from(size);
    let bytes_per_sample = match kind {
        TileFile::Height => 4,
        TileFile::Type | TileFile::Density | TileFile::Material => 1,
    };
    2 * samples * bytes_per_sample + (64 << 10)
}

/// Reads a regular file of at most `max` bytes. Anything else (a device such as `/dev/zero`
/// behind a symlink, a FIFO, a folder) is refused before it is opened (see [`open_regular`]),
/// and the read stops after `max + 1` bytes, so that no file can make a reader hang or run out
/// of memory.
pub(crate) fn read_regular(path: &Path, max: u64) -> Result<Vec<u8>, WorldError> {
    use std::io::Read;
    let too_large = |size| WorldError::FileTooLarge {
        path: path.to_path_buf(),
        size,
        max,
    };
    let (file, len) = open_regular(path)?;
    if len > max {
        return Err(too_large(len));
    }
    let mut bytes = Vec::with_capacity(len.min(max) as usize);
    file.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| WorldError::io(path, e))?;
    if bytes.len() as u64 > max {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Opens a regular file for reading, with its size. Anything else (a FIFO, whose opening
/// would block until a writer comes; a device; a folder) is refused by name before it is
/// opened, and what was opened is checked again in case the path was swapped meanwhile.
pub(crate) fn open_regular(path: &Path) -> Result<(std::fs::File, u64), WorldError> {
    let not_regular = |kind| WorldError::NotARegularFile {
        path: path.to_path_buf(),
        kind,
    };
    let meta = std::fs::metadata(path).map_err(|e| WorldError::io(path, e))?;
    let kind_of = |m: &std::fs::Metadata| special_kind(m.file_type());
    if !meta.is_file() {
        return Err(not_regular(kind_of(&meta)));
    }
    let file = std::fs::File::open(path).map_err(|e| WorldError::io(path, e))?;
    let opened = file.metadata().map_err(|e| WorldError::io(path, e))?;
    if !opened.is_file() {
        return Err(not_regular(kind_of(&opened)));
    }
    Ok((file, opened.len()))
}

/// What a file that is not a regular file is, in words.
#[cfg(unix)]
fn special_kind(t: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_kind(t: std::fs::FileType) -> &'static str {
    if t.is_dir() {
        "a folder"
    } else {
        "not a regular file"
    }
}

/// What a file that is not a folder is, for errors: "a file", or what [`special_kind`] says.
pub fn what_file_is(m: &std::fs::Metadata) -> &'static str {
    if m.is_file() {
        "a file"
    } else {
        special_kind(m.file_type())
    }
}

/// Writes `bytes` to `path` through a temporary file in the same directory, creating the
/// directory where needed.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WorldError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| WorldError::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let io = |source| WorldError::Io {
        path: path.to_path_buf(),
        source,
    };
    // A file of its own: a killed writer's temporary of the same name goes first, and whatever
    // is at the name then (a link, say) is refused rather than written through.
    let _ = std::fs::remove_file(&tmp);
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(io)?;
    // From here the temporary is this writer's: a write or rename that fails removes it (a
    // full disk left part of a tile beside the tiles).
    std::io::Write::write_all(&mut file, bytes)
        .and_then(|()| {
            drop(file);
            std::fs::rename(&tmp, path)
        })
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            io(e)
        })
}

/// Removes from a world's `tiles/` folder (its `L{level}` folders) the temporaries of tile
/// files ([`is_tile_temporary_name`]) last written more than `older_than` ago: a killed or
/// failed writer's, which no rename will ever put in place. Returns how many it removed.
pub fn sweep_tile_temporaries(tiles: &Path, older_than: std::time::Duration) -> usize {
    let Ok(levels) = std::fs::read_dir(tiles) else {
        return 0;
    };
    let mut removed = 0;
    for level in levels.flatten() {
        if !level.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        let Ok(entries) = std::fs::read_dir(level.path()) else {
            continue;
        };
        for e in entries.flatten() {
            let old = e.metadata().is_ok_and(|m| {
                m.is_file()
                    && m.modified().is_ok_and(|t| {
                        std::time::SystemTime::now()
                            .duration_since(t)
                            .is_ok_and(|age| age >= older_than)
                    })
            });
            if old
                && e.file_name().to_str().is_some_and(is_tile_temporary_name)
                && std::fs::remove_file(e.path()).is_ok()
            {
                removed += 1;
            }
        }
    }
    removed
}

/// Reorders rows between south-first (memory) and north-first (files); its own inverse.
fn flip_rows<T: Copy>(data: &[T], size: u32) -> Vec<T> {
    data.chunks_exact(size as usize)
        .rev()
        .flatten()
        .copied()
        .collect()
}

fn north_first<T: Copy>(data: &[T], size: u32) -> Vec<T> {
    flip_rows(data, size)
}

fn south_first<T: Copy>(data: &[T], size: u32) -> Vec<T> {
    flip_rows(data, size)
}

/// Runs a decoder, turning a panic inside it into an error message.
fn guarded<T>(f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|_| Err("the decoder failed".into()))
}

fn encode_exr(rows_north_first: &[f32], size: u32, stamp: Option<&str>) -> Result<Vec<u8>, String> {
    use exr::prelude::*;
    let channel = AnyChannel::new("Y", FlatSamples::F32(rows_north_first.to_vec()));
    let mut attributes = LayerAttributes::named("height");
    if let Some(stamp) = stamp {
        let text = |s: &str| Text::new_or_none(s).ok_or_else(|| format!("{s:?} is not ASCII"));
        attributes.other.insert(
            text(STAMP_KEY)?,
            exr::meta::attribute::AttributeValue::Text(text(stamp)?),
        );
    }
    let layer = Layer::new(
        (size as usize, size as usize),
        attributes,
        Encoding {
            compression: Compression::ZIP16,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        },
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let mut out = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// Decodes a single-channel f32 EXR of `size x size`, checking the header before the pixels.
fn decode_exr(bytes: &[u8], size: u32, path: &Path) -> Result<Vec<f32>, WorldError> {
    use exr::prelude::*;
    let corrupt = |message: String| WorldError::CorruptImage {
        path: path.to_path_buf(),
        format: "EXR",
        message,
    };
    let meta = guarded(|| {
        MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(|e| e.to_string())
    })
    .map_err(corrupt)?;
    let expected_layout = "one layer with one f32 channel";
    let describe = |h: &exr::meta::header::Header| {
        let channels: Vec<String> = h
            .channels
            .list
            .iter()
            .map(|c| format!("{} {:?}", c.name, c.sample_type))
            .collect();
        format!("channels [{}]", channels.join(", "))
    };
    let [header] = meta.headers.as_slice() else {
        return Err(WorldError::WrongLayout {
            path: path.to_path_buf(),
            expected: expected_layout.into(),
            found: format!("{} layers", meta.headers.len()),
        });
    };
    if header.deep
        || header.channels.list.len() != 1
        || header.channels.list[0].sample_type != SampleType::F32
        || header.channels.list[0].sampling != Vec2(1, 1)
    {
        return Err(WorldError::WrongLayout {
            path: path.to_path_buf(),
            expected: expected_layout.into(),
            found: describe(header),
        });
    }
    let found = header.layer_size;
    if found != Vec2(size as usize, size as usize) {
        return Err(WorldError::WrongDimensions {
            path: path.to_path_buf(),
            expected: [size, size],
            found: [
                u32::try_from(found.0).unwrap_or(u32::MAX),
                u32::try_from(found.1).unwrap_or(u32::MAX),
            ],
        });
    }

    let image = guarded(|| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .all_layers()
            .all_attributes()
            .non_parallel()
            .from_buffered(Cursor::new(bytes))
            .map_err(|e| e.to_string())
    })
    .map_err(corrupt)?;
    let samples = image
        .layer_data
        .into_iter()
        .next()
        .and_then(|layer| layer.channel_data.list.into_iter().next())
        .map(|channel| channel.sample_data);
    match samples {
        Some(FlatSamples::F32(v)) if v.len() == size as usize * size as usize => Ok(v),
        _ => Err(corrupt("pixel data does not match the header".into())),
    }
}

/// Encodes a tile's map: an 8-bit grayscale PNG of `size x size`, carrying `stamp` (in a
/// `tEXt` chunk keyed [`STAMP_KEY`], before the image data) where one is given.
fn encode_map(rows: &[u8], size: u32, stamp: Option<&str>) -> Result<Vec<u8>, String> {
    if rows.len() as u64 != u64::from(size) * u64::from(size) {
        return Err("buffer size does not match the image size".into());
    }
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, size, size);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    // As the image crate's `CompressionType::Best` with adaptive filtering.
    encoder.set_compression(png::Compression::High);
    encoder.set_filter(png::Filter::Adaptive);
    if let Some(stamp) = stamp {
        encoder
            .add_text_chunk(STAMP_KEY.to_owned(), stamp.to_owned())
            .map_err(|e| e.to_string())?;
    }
    let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(rows).map_err(|e| e.to_string())?;
    writer.finish().map_err(|e| e.to_string())?;
    Ok(out)
}

/// A PNG's width and height from its header, read from `file` without decoding a pixel (a
/// caller weighs the image before holding it).
pub(crate) fn png_dimensions(file: std::fs::File, path: &Path) -> Result<[u32; 2], WorldError> {
    guarded(|| {
        png::Decoder::new(std::io::BufReader::new(file))
            .read_header_info()
            .map(|info| [info.width, info.height])
            .map_err(|e| e.to_string())
    })
    .map_err(|message| WorldError::CorruptImage {
        path: path.to_path_buf(),
        format: "PNG",
        message,
    })
}

/// A decoded PNG: its raw bytes in the colour type asked for.
pub(crate) struct DecodedPng {
    pub bytes: Vec<u8>,
}

/// Most pixels a PNG may hold before decoding is refused (a 16k x 16k DEM).
const MAX_PNG_PIXELS: u64 = 16_384 * 16_384;

/// Decodes a PNG, checking that it holds `expected` colour samples of `expected_dims`
/// (where given) before decoding its pixels. For `L8`, grayscale PNGs of 1, 2 or 4 bits are
/// read too, with their own sample values.
pub(crate) fn decode_png(
    bytes: &[u8],
    path: &Path,
    expected_color: image::ColorType,
    expected_layout: &str,
    expected_dims: Option<[u32; 2]>,
) -> Result<DecodedPng, WorldError> {
    use image::ImageDecoder;
    use image::codecs::png::PngDecoder;
    let corrupt = |message: String| WorldError::CorruptImage {
        path: path.to_path_buf(),
        format: "PNG",
        message,
    };
    // The stored colour type and bit depth, which the image decoder's output hides.
    let header = guarded(|| {
        png::Decoder::new(Cursor::new(bytes))
            .read_header_info()
            .map(|info| (info.color_type, info.bit_depth))
            .map_err(|e| e.to_string())
    })
    .map_err(corrupt)?;
    let result = guarded(|| {
        let decoder = match PngDecoder::new(Cursor::new(bytes)) {
            Ok(d) => d,
            Err(image::ImageError::Unsupported(e)) => {
                return Ok(Err(WorldError::WrongLayout {
                    path: path.to_path_buf(),
                    expected: expected_layout.into(),
                    found: e.to_string(),
                }));
            }
            Err(e) => return Err(e.to_string()),
        };
        let (width, height) = decoder.dimensions();
        let color = decoder.color_type();
        if color != expected_color {
            return Ok(Err(WorldError::WrongLayout {
                path: path.to_path_buf(),
                expected: expected_layout.into(),
                found: describe_png(header, color),
            }));
        }
        if let Some(expected) = expected_dims
            && [width, height] != expected
        {
            return Ok(Err(WorldError::WrongDimensions {
                path: path.to_path_buf(),
                expected,
                found: [width, height],
            }));
        }
        if u64::from(width) * u64::from(height) > MAX_PNG_PIXELS {
            return Err(format!(
                "{width}x{height} pixels is more than this reader accepts"
            ));
        }
        let mut buf = vec![0u8; decoder.total_bytes() as usize];
        decoder.read_image(&mut buf).map_err(|e| e.to_string())?;
        if let (png::ColorType::Grayscale, bits @ 1..=4) = (header.0, header.1 as u8) {
            // The decoder scales low-bit samples to 8 bits (by 255 / (2^bits - 1), an integer):
            // undo it, exactly, for the samples' own values.
            let scale = 255 / ((1u8 << bits) - 1);
            buf.iter_mut().for_each(|v| *v /= scale);
        }
        Ok(Ok(DecodedPng { bytes: buf }))
    });
    result.map_err(corrupt)?
}

/// A PNG's stored layout in words, from its header and what the image decoder makes of it (a
/// transparent colour, `tRNS`, adds alpha).
fn describe_png(header: (png::ColorType, png::BitDepth), decoded: image::ColorType) -> String {
    use png::ColorType::*;
    let (color, bits) = (header.0, header.1 as u8);
    let kind = match color {
        Grayscale => "grayscale",
        Rgb => "RGB",
        Indexed => "palette (indexed-colour)",
        GrayscaleAlpha => "grayscale with alpha",
        Rgba => "RGBA",
    };
    let transparent = decoded.has_alpha() && !matches!(color, GrayscaleAlpha | Rgba);
    let trns = if transparent {
        " with a transparent colour (tRNS)"
    } else {
        ""
    };
    format!("{bits}-bit {kind}{trns}")
}

/// The layout of type and density maps, as errors state it.
const MAP_LAYOUT: &str =
    "8-bit grayscale (or 1, 2 or 4 bits, read as their values; no alpha, no palette)";

fn decode_png_l8(bytes: &[u8], size: u32, path: &Path) -> Result<Vec<u8>, WorldError> {
    let png = decode_png(
        bytes,
        path,
        image::ColorType::L8,
        MAP_LAYOUT,
        Some([size, size]),
    )?;
    Ok(png.bytes)
}

/// Why `path` is no place for a run's files, if it is not: the root of the file system, a
/// world's folder (one holding `world.toml`), or anything inside a world's `tiles/`. A run
/// writes `report.json`, frames and tables there by their own names, and a world's files are
/// not to be mixed with them or overwritten.
pub fn refused_output(path: &Path) -> Option<&'static str> {
    let resolved = resolve_lexically(path).ok().flatten()?;
    if resolved.parent().is_none() {
        return Some("the root of the file system");
    }
    if resolved.join("world.toml").is_file() {
        return Some("a world's folder (it holds world.toml)");
    }
    if world_whose_tiles_hold(&resolved).is_some() {
        return Some("inside a world's tiles/");
    }
    None
}

/// The world folder (one holding `world.toml`) whose `tiles/` is `path` or holds it, if any;
/// `path` is resolved first ([`resolve_lexically`]), so that `w/tiles/L0/..` is inside `w`'s.
pub fn world_whose_tiles_hold(path: &Path) -> Option<PathBuf> {
    let resolved = resolve_lexically(path).ok().flatten()?;
    let mut up = resolved.as_path();
    while let Some(parent) = up.parent() {
        if up.file_name().is_some_and(|n| n == "tiles") && parent.join("world.toml").is_file() {
            return Some(parent.to_path_buf());
        }
        up = parent;
    }
    None
}

/// The folders of `path` that do not exist yet, the deepest first (`path` itself included):
/// what `create_dir_all(path)` would make, for [`remove_empty_folders`] to take back.
pub fn missing_folders(path: &Path) -> Vec<PathBuf> {
    // Resolved first, so that `new/../out` and `x/.` name the folders themselves.
    let resolved = resolve_lexically(path)
        .ok()
        .flatten()
        .unwrap_or_else(|| path.to_path_buf());
    resolved
        .ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .take_while(|a| {
            std::fs::symlink_metadata(a).is_err_and(|e| e.kind() == std::io::ErrorKind::NotFound)
        })
        .map(Path::to_path_buf)
        .collect()
}

/// Removes `folders` (the deepest first, as [`missing_folders`] gives them) while they are
/// empty: the first that holds anything is kept, with every folder above it.
pub fn remove_empty_folders(folders: &[PathBuf]) {
    for dir in folders {
        if std::fs::remove_dir(dir).is_err() {
            break;
        }
    }
}

/// `path` made absolute: its longest part that exists canonicalised (symlinks followed), the
/// rest appended with `.` dropped and `..` taken lexically (what does not exist holds no
/// symlinks), so that `missing/../w` is `w` and `w/tiles/..` is `w`. `None` where no part of
/// it exists; an error other than a missing part is returned.
pub fn resolve_lexically(path: &Path) -> std::io::Result<Option<PathBuf>> {
    use std::path::Component;
    let absolute = std::path::absolute(path)?;
    let components: Vec<Component> = absolute.components().collect();
    for n in (1..=components.len()).rev() {
        let prefix: PathBuf = components[..n].iter().collect();
        match prefix.canonicalize() {
            Ok(mut resolved) => {
                for c in &components[n..] {
                    match c {
                        Component::Normal(name) => resolved.push(name),
                        Component::ParentDir => {
                            resolved.pop();
                        }
                        _ => {}
                    }
                }
                return Ok(Some(resolved));
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::{is_tile_file_name, is_tile_temporary_name};

    /// A killed writer's temporary of a tile file is known for one (a `--replace` may remove
    /// it); anything else of the kind is not.
    #[test]
    fn a_tile_files_temporary_is_told_from_other_files() {
        assert!(is_tile_file_name("3_4.type.png"));
        assert!(is_tile_temporary_name(".3_4.type.png.23793.tmp"));
        assert!(is_tile_temporary_name(".0_0.height.exr.1.tmp"));
        for other in [
            "3_4.type.png.23793.tmp",
            ".3_4.type.png..tmp",
            ".3_4.type.png.12a.tmp",
            ".notes.txt.1.tmp",
            ".3_4.type.png.1.tmp.bak",
            "3_4.type.png",
        ] {
            assert!(!is_tile_temporary_name(other), "{other}");
        }
    }

    /// The temporaries of tile files older than the grace go; a fresh one (a write under way)
    /// and every other file stay.
    #[test]
    fn old_temporaries_of_tile_files_are_swept_and_nothing_else() {
        let tmp = tempfile::tempdir().unwrap();
        let tiles = tmp.path().join("tiles");
        let level = tiles.join("L2");
        std::fs::create_dir_all(&level).unwrap();
        let long_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
        for (name, old) in [
            (".0_0.height.exr.4.tmp", true),
            (".1_0.type.png.77.tmp", false),
            (".notes.txt.4.tmp", true),
            ("0_0.height.exr", true),
        ] {
            let path = level.join(name);
            std::fs::write(&path, "x").unwrap();
            if old {
                std::fs::File::options()
                    .write(true)
                    .open(&path)
                    .unwrap()
                    .set_modified(long_ago)
                    .unwrap();
            }
        }
        let swept = super::sweep_tile_temporaries(&tiles, std::time::Duration::from_secs(60));
        assert_eq!(swept, 1);
        let mut left: Vec<String> = std::fs::read_dir(&level)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert_eq!(
            left,
            [".1_0.type.png.77.tmp", ".notes.txt.4.tmp", "0_0.height.exr"]
        );
        assert_eq!(
            super::sweep_tile_temporaries(&tiles, std::time::Duration::ZERO),
            1
        );
    }
}
