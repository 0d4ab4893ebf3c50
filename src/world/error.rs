//! [`WorldError`]: everything that can go wrong opening, reading, writing or baking a world.
//!
//! Every variant that concerns a file carries that file's path, and its message starts with it,
//! so that a user sees at once which file is wrong and how.

use std::path::{Path, PathBuf};

use super::tile::TileId;

/// An error from the world module. Messages start with the file they concern.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WorldError {
    /// Reading, writing, creating or renaming a file or directory failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },

    /// The world directory does not exist (or is not a directory).
    #[error("{}: world directory not found", path.display())]
    MissingWorldDir {
        /// The directory that was asked for.
        path: PathBuf,
    },

    /// A world folder without its world, where a bake into it was stopped while moving its
    /// world in: the staging folder beside it holds the world.
    #[error(
        "{}: {what}: a bake into this folder was stopped while moving its world in, and {} \
         holds it; run the bake into it again (`verdant bake ... --out {}`), which puts the \
         folder right before anything else",
        path.display(),
        staging.display(),
        path.display()
    )]
    InterruptedBake {
        /// The world folder asked for.
        path: PathBuf,
        /// What is missing: its `world.toml` or the folder itself.
        what: &'static str,
        /// The bake's staging folder beside it.
        staging: PathBuf,
    },

    /// A file that the world or the baker needs does not exist.
    #[error("{}: file not found", path.display())]
    MissingFile {
        /// The missing file.
        path: PathBuf,
    },

    /// The manifest is not valid TOML, lacks a field, has a field of the wrong type or has a
    /// field that the format does not know.
    #[error("{}: {message}", path.display())]
    ManifestSyntax {
        /// The manifest file.
        path: PathBuf,
        /// The parser's message, with the line and the field.
        message: String,
    },

    /// A number is NaN or infinite.
    #[error("{}: {field} = {value}: must be a finite number", path.display())]
    NonFinite {
        /// The file holding the number.
        path: PathBuf,
        /// The field, as a dotted path (e.g. `paths[0].keys[3].position_m`).
        field: String,
        /// The value found.
        value: f64,
    },

    /// A size, extent or scale that must be positive is zero or negative.
    #[error("{}: {field} = {value}: must be greater than zero", path.display())]
    NonPositive {
        /// The file holding the value.
        path: PathBuf,
        /// The field.
        field: String,
        /// The value found.
        value: f64,
    },

    /// A speed, time or factor that must not be negative is negative.
    #[error("{}: {field} = {value}: must not be negative", path.display())]
    Negative {
        /// The file holding the value.
        path: PathBuf,
        /// The field.
        field: String,
        /// The value found.
        value: f64,
    },

    /// A size or count lies outside what the format supports.
    #[error("{}: {field} = {value}: must be {allowed}", path.display())]
    OutOfRange {
        /// The file holding the value.
        path: PathBuf,
        /// The field.
        field: String,
        /// The value found, as written.
        value: String,
        /// What is allowed, in words (e.g. `a power of two in 8..=1024`).
        allowed: String,
    },

    /// The pyramid would hold more tiles at its finest stored level than a world may.
    #[error(
        "{}: {field}: {count} tiles at the finest stored level, more than the {max} allowed",
        path.display()
    )]
    TooManyTiles {
        /// The manifest file.
        path: PathBuf,
        /// The fields that multiply to the count.
        field: String,
        /// The number of tiles asked for.
        count: u64,
        /// The most allowed.
        max: u64,
    },

    /// The world's extent reaches beyond the area that its root tiles cover.
    #[error(
        "{}: extent_m[{axis}] = {extent_m} m is larger than the {grid_m} m that the root tiles cover",
        path.display()
    )]
    ExtentBeyondGrid {
        /// The manifest file.
        path: PathBuf,
        /// 0 for x (east), 1 for y (north).
        axis: usize,
        /// The extent asked for.
        extent_m: f64,
        /// What `root_tiles * root_tile_size_m` covers.
        grid_m: f64,
    },

    /// The height range is empty (min = max) or inverted (min > max).
    #[error(
        "{}: height_range_m = [{min}, {max}]: the minimum must be below the maximum",
        path.display()
    )]
    BadHeightRange {
        /// The manifest file.
        path: PathBuf,
        /// The minimum found.
        min: f32,
        /// The maximum found.
        max: f32,
    },

    /// The manifest lists no grass types (at least type 0, bare ground, is needed).
    #[error("{}: grass_types is empty: at least one type (index 0, bare ground) is needed", path.display())]
    NoGrassTypes {
        /// The manifest file.
        path: PathBuf,
    },

    /// A grass type's height or width range is negative or inverted.
    #[error(
        "{}: grass_types[{index}] ({name}).{field} = [{min}, {max}]: must satisfy 0 <= min <= max",
        path.display()
    )]
    BadGrassRange {
        /// The manifest file.
        path: PathBuf,
        /// Index of the grass type.
        index: usize,
        /// Name of the grass type.
        name: String,
        /// `height_m` or `width_m`.
        field: &'static str,
        /// The minimum found.
        min: f32,
        /// The maximum found.
        max: f32,
    },

    /// A camera path has fewer than two keys.
    #[error(
        "{}: camera path \"{name}\": {field} has {keys} key(s): at least 2 are needed (its \
         length is the span of its keys' times)",
        path.display()
    )]
    PathTooShort {
        /// The manifest file.
        path: PathBuf,
        /// The path's name.
        name: String,
        /// The field (e.g. `paths[2].keys`).
        field: String,
        /// The number of keys found.
        keys: usize,
    },

    /// A camera path's keys are not in strictly increasing time order.
    #[error(
        "{}: camera path \"{name}\": {field} = {t_s} does not come after the previous key's \
         {previous_t_s} (keys are listed in increasing time order)",
        path.display()
    )]
    PathKeysOutOfOrder {
        /// The manifest file.
        path: PathBuf,
        /// The path's name.
        name: String,
        /// The field (e.g. `paths[2].keys[3].t_s`).
        field: String,
        /// Index of the offending key.
        index: usize,
        /// Its time.
        t_s: f64,
        /// The time of the key before it.
        previous_t_s: f64,
    },

    /// A camera path's `duration_s` is not the span of its keys' times (which every tool flies).
    #[error(
        "{}: camera path \"{name}\": {field} = {duration_s} does not match its keys, which span \
         {span_s} s (t_s {first_t_s} to {last_t_s}); set {field} = {span_s}, or move the keys",
        path.display()
    )]
    PathDurationMismatch {
        /// The manifest file.
        path: PathBuf,
        /// The path's name.
        name: String,
        /// The field (e.g. `paths[2].duration_s`).
        field: String,
        /// The duration the manifest states, seconds.
        duration_s: f64,
        /// The span of the keys' times, seconds.
        span_s: f64,
        /// The first key's time, seconds.
        first_t_s: f64,
        /// The last key's time, seconds.
        last_t_s: f64,
    },

    /// Two camera paths share a name.
    #[error("{}: camera path name \"{name}\" is used more than once", path.display())]
    DuplicatePath {
        /// The manifest file.
        path: PathBuf,
        /// The repeated name.
        name: String,
    },

    /// Two wind scenes share a name.
    #[error("{}: wind scene name \"{name}\" is used more than once", path.display())]
    DuplicateWindScene {
        /// The manifest file.
        path: PathBuf,
        /// The repeated name.
        name: String,
    },

    /// A wind source refers to a camera path that the manifest does not have.
    #[error("{}: {field} = \"{name}\": no camera path has this name", path.display())]
    UnknownPathRef {
        /// The manifest file.
        path: PathBuf,
        /// The field holding the reference (e.g. `wind_scenes[3].sources[0].path`).
        field: String,
        /// The name referred to.
        name: String,
    },

    /// A camera path's wind key names a wind scene that the manifest does not have.
    #[error(
        "{}: {field} = \"{name}\": no wind scene has this name ({})",
        path.display(),
        crate::world::wind_scenes_held(.available)
    )]
    UnknownWindSceneRef {
        /// The manifest file.
        path: PathBuf,
        /// The field holding the reference (e.g. `paths[5].wind[2].scene`).
        field: String,
        /// The name referred to.
        name: String,
        /// The scenes the world has (see [`crate::world::name_list`]; empty when it has none).
        available: String,
    },

    /// A wind source has both a position and a path, or neither where it needs one.
    #[error("{}: {field} {message}", path.display())]
    WindSourcePlacement {
        /// The manifest file.
        path: PathBuf,
        /// The source (e.g. `wind_scenes[3].sources[0]`).
        field: String,
        /// What is wrong.
        message: String,
    },

    /// A wind source's strength keys are not in strictly increasing time order.
    #[error(
        "{}: {field}[{index}] time {t_s} does not come after the previous key's {previous_t_s}",
        path.display()
    )]
    StrengthKeysOutOfOrder {
        /// The manifest file.
        path: PathBuf,
        /// The keys' field (e.g. `wind_scenes[2].sources[1].strength`).
        field: String,
        /// Index of the offending key.
        index: usize,
        /// Its time.
        t_s: f64,
        /// The time of the key before it.
        previous_t_s: f64,
    },

    /// A tile was asked for that the world does not store.
    #[error("{}: tile {id} is not a stored tile of this world", path.display())]
    TileNotStored {
        /// The world directory.
        path: PathBuf,
        /// The tile asked for.
        id: TileId,
    },

    /// An image or elevation file (EXR, PNG, TIFF or SRTM .hgt) is truncated or corrupt and
    /// cannot be decoded.
    #[error("{}: corrupt or truncated {format} file: {message}", path.display())]
    CorruptImage {
        /// The file.
        path: PathBuf,
        /// `EXR`, `PNG`, `TIFF` or `SRTM .hgt`.
        format: &'static str,
        /// The decoder's message.
        message: String,
    },

    /// An image has other dimensions than expected.
    #[error(
        "{}: expected {}x{} samples, found {}x{}",
        path.display(), expected[0], expected[1], found[0], found[1]
    )]
    WrongDimensions {
        /// The file.
        path: PathBuf,
        /// Expected width, height.
        expected: [u32; 2],
        /// Found width, height.
        found: [u32; 2],
    },

    /// An image has the wrong channels, sample type or bit depth.
    #[error("{}: expected {expected}, found {found}", path.display())]
    WrongLayout {
        /// The file.
        path: PathBuf,
        /// The layout that the format requires.
        expected: String,
        /// The layout found.
        found: String,
    },

    /// A height sample is NaN or infinite.
    #[error(
        "{}: height sample (i={i}, j={j}) is {value}: heights must be finite",
        path.display()
    )]
    NonFiniteHeight {
        /// The file.
        path: PathBuf,
        /// Column, from the west edge.
        i: u32,
        /// Row, from the south edge.
        j: u32,
        /// The value found.
        value: f32,
    },

    /// A height sample lies far outside the manifest's height range.
    #[error(
        "{}: height sample (i={i}, j={j}) is {value} m, outside the world's height range [{}, {}] m",
        path.display(), range[0], range[1]
    )]
    HeightOutOfRange {
        /// The file.
        path: PathBuf,
        /// Column, from the west edge.
        i: u32,
        /// Row, from the south edge.
        j: u32,
        /// The value found.
        value: f32,
        /// The manifest's height range.
        range: [f32; 2],
    },

    /// A grass type index has no grass type in the manifest.
    #[error(
        "{}: grass type index {index} at sample (i={i}, j={j}), but the world has only {count} grass types",
        path.display()
    )]
    GrassTypeOutOfRange {
        /// The file.
        path: PathBuf,
        /// Column, from the west edge.
        i: u32,
        /// Row, from the south edge.
        j: u32,
        /// The index found.
        index: u8,
        /// The number of grass types in the manifest.
        count: usize,
    },

    /// A tile file's stamp names another tile file or another bake than the world's
    /// (`crate::world::format::check_stamp`).
    #[error("{}: {message}", path.display())]
    TileStamp {
        /// The file.
        path: PathBuf,
        /// What the stamp says, and what to do.
        message: String,
    },

    /// `verdant check --stamp` stopped after it began to write (`crate::tools::check::stamp_world`):
    /// the world reads, unchecked, and stamping it again finishes the work.
    #[error(
        "{}: stamping stopped half way: {source}; the world reads as it is, unchecked (its \
         world.toml has no bake_id), and stamping it again finishes the work",
        path.display()
    )]
    StampIncomplete {
        /// The world folder.
        path: PathBuf,
        /// What stopped it.
        #[source]
        source: Box<WorldError>,
    },

    /// In-memory tile data does not fit the pyramid (a caller's mistake, caught before writing).
    #[error("{}: tile data does not fit the pyramid: {message}", path.display())]
    BadTileData {
        /// The file that was to be written.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },

    /// A DEM's JSON sidecar is missing.
    #[error("{}: the DEM's sidecar {} is missing", path.display(), sidecar.display())]
    MissingSidecar {
        /// The DEM image.
        path: PathBuf,
        /// Where the sidecar was looked for.
        sidecar: PathBuf,
    },

    /// A DEM's JSON sidecar cannot be parsed or lacks a field.
    #[error("{}: bad DEM sidecar: {message}", path.display())]
    BadSidecar {
        /// The sidecar file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },

    /// A command-line option of the baker is out of range (no file is to blame).
    #[error("{option} {value}: must be {allowed}")]
    BadOption {
        /// The option, e.g. `--tile-cells`.
        option: &'static str,
        /// The value given.
        value: String,
        /// What is allowed, in words.
        allowed: String,
    },

    /// A DEM's height lies outside the heights of a planet's surface (a wrong offset or scale in
    /// its sidecar, or a broken file).
    #[error(
        "{}: height {} m at column {column}, row {row} of {} {}is outside [{}, {}] m, \
         the heights of a planet's surface{}",
        path.display(), short_number(*value), dem.display(),
        if path == dem { "" } else { "(height_offset_m + height_scale_m x the sample) " },
        range[0], range[1],
        if path == dem { "" } else { ": check height_offset_m and height_scale_m" }
    )]
    ImplausibleHeight {
        /// The sidecar holding the offset and scale, or the DEM itself where it has none.
        path: PathBuf,
        /// The DEM image.
        dem: PathBuf,
        /// Column of the sample, from the west.
        column: u32,
        /// Row of the sample, from the north.
        row: u32,
        /// The height it gives, metres.
        value: f64,
        /// The plausible range, metres.
        range: [f64; 2],
    },

    /// A file to be read is not a regular file (a device, a FIFO, a folder).
    #[error(
        "{}: not a regular file ({kind}); worlds, DEMs and sidecars are read only from regular files",
        path.display()
    )]
    NotARegularFile {
        /// The file.
        path: PathBuf,
        /// What it is instead.
        kind: &'static str,
    },

    /// A file is larger than its format allows for this world.
    #[error("{}: {size} bytes, more than the {max} that this file may hold", path.display())]
    FileTooLarge {
        /// The file.
        path: PathBuf,
        /// Its size, or the bytes read before giving up.
        size: u64,
        /// The most allowed.
        max: u64,
    },

    /// The bake's output folder exists and is not empty.
    #[error(
        "{}: the output folder is not empty; bake into a new folder, or pass --replace to \
         replace the world in it (its world.toml and tiles/; other files are kept)",
        path.display()
    )]
    OutputNotEmpty {
        /// The output folder.
        path: PathBuf,
    },

    /// `--replace` would delete a file or folder in the output folder's `tiles/` that is not a
    /// tile verdant writes (`L{level}/{x}_{y}.height.exr`, `.type.png`, `.density.png`,
    /// `.material.png`): the folder is not a world's, or someone else's files are in it.
    #[error(
        "{}: --replace would delete this, and it is not a tile that verdant writes (tiles/ \
         holds only L<level>/<x>_<y>.height.exr, .type.png, .density.png and .material.png); \
         move it out of {}, or bake into another folder",
        path.display(),
        tiles.display()
    )]
    ForeignInTiles {
        /// The first such file or folder found.
        path: PathBuf,
        /// The output folder's `tiles/`.
        tiles: PathBuf,
    },

    /// `bake --replace` keeps the replaced manifest's plant types and the camera paths a bake
    /// does not write, and they do not fit the new world (or the manifest does not read).
    #[error(
        "{source}\n(bake --replace keeps the plant types, and the camera paths and wind scenes \
         of other names than the bake's, from {}{}: mend them there, or pass --fresh-manifest to \
         bake without them)",
        path.display(),
        if kept.is_empty() { String::new() } else { format!("; in the new manifest {kept}") }
    )]
    Carry {
        /// The replaced manifest.
        path: PathBuf,
        /// Where the kept parts stand in the new manifest (`paths[7] is its path "x"`), for an
        /// error that names them by index; empty where none were placed yet.
        kept: String,
        /// Why its parts do not fit.
        #[source]
        source: Box<WorldError>,
    },

    /// The bake was cancelled (its cancel flag was set, e.g. by SIGINT or SIGTERM) before the
    /// new world was put in place; the output folder was left as it was.
    #[error("{}: bake cancelled; the output folder was left as it was", path.display())]
    Cancelled {
        /// The output folder.
        path: PathBuf,
    },

    /// A sharded bake's finish found a tile file missing from the parts folder of a shard
    /// recorded done, or one that cannot be read (cut short, or another tile's or bake's): the
    /// world would be published without it. The records of the shards with such files are
    /// removed, so that they can be run again.
    #[error(
        "{}: {why} in the parts of the sharded bake in {}, though shard{} {} of {count} {} \
         recorded done; {} record{} removed: run {} again (--shard I/{count}), then \
         --finish-shards {count}",
        path.display(),
        parts.display(),
        if shards.len() == 1 { "" } else { "s" },
        shards.iter().map(u32::to_string).collect::<Vec<_>>().join(", "),
        if shards.len() == 1 { "is" } else { "are" },
        if shards.len() == 1 { "its" } else { "their" },
        if shards.len() == 1 { " is" } else { "s are" },
        if shards.len() == 1 { "it" } else { "them" },
    )]
    ShardTilesMissing {
        /// The first tile file found missing or unreadable.
        path: PathBuf,
        /// What is wrong with it: `missing`, or why it cannot be read.
        why: String,
        /// The parts folder.
        parts: PathBuf,
        /// The shards that lack tile files, each recorded done.
        shards: Vec<u32>,
        /// How many shards the bake has.
        count: u32,
    },

    /// Putting a baked world in place failed, and so did putting the previous world back: its
    /// `world.toml` and `tiles/` are kept in a folder beside the output folder.
    #[error(
        "{}: {source}; the previous world.toml and tiles/ could not be put back and are kept \
         in {}",
        path.display(), kept.display()
    )]
    PublishFailed {
        /// The output folder.
        path: PathBuf,
        /// Where the previous world's files are.
        kept: PathBuf,
        /// The failure that stopped the publishing.
        #[source]
        source: std::io::Error,
    },

    /// A DEM's sidecar disagrees with its image.
    #[error(
        "{}: the sidecar says {field} = {sidecar}, the image has {image}",
        path.display()
    )]
    SidecarMismatch {
        /// The sidecar file.
        path: PathBuf,
        /// `width` or `height`.
        field: &'static str,
        /// The sidecar's value.
        sidecar: u32,
        /// The image's value.
        image: u32,
    },

    /// A DEM file is none of the formats the baker reads (told by its content, not its name).
    #[error(
        "{}: not a DEM that verdant reads ({found}): expected a GeoTIFF, an SRTM .hgt tile \
         (3601x3601 or 1201x1201) or a 16-bit PNG with a JSON sidecar",
        path.display()
    )]
    UnknownDemFormat {
        /// The file.
        path: PathBuf,
        /// What the file looks like, in words (e.g. `starts with bytes 7f 45 4c 46`).
        found: String,
    },

    /// A DEM file uses a feature of its format that the baker does not read (several bands, a
    /// compression or sample type it lacks, a rotated grid, an angular unit other than degrees).
    #[error("{}: unsupported {format}: {problem}", path.display())]
    UnsupportedDem {
        /// The file.
        path: PathBuf,
        /// The format, e.g. `GeoTIFF`.
        format: &'static str,
        /// What is unsupported and what is.
        problem: String,
    },

    /// A DEM does not say how far apart its samples are (a TIFF without GeoTIFF tags), and no
    /// cell size was given to the baker.
    #[error(
        "{}: {problem}, so its cell size is unknown: give it in metres (--dem-cell-size M, \
         or EW,NS, to verdant bake or verdant eval derive)",
        path.display()
    )]
    NoGeoreference {
        /// The file.
        path: PathBuf,
        /// What is missing.
        problem: String,
    },

    /// A file read as an SRTM `.hgt` tile has a size that no SRTM tile has.
    #[error(
        "{}: {bytes} bytes is not the size of an SRTM .hgt tile: expected 25934402 \
         (3601x3601 samples, 1 arc-second) or 2884802 (1201x1201, 3 arc-second)",
        path.display()
    )]
    HgtSize {
        /// The file.
        path: PathBuf,
        /// Its size in bytes.
        bytes: u64,
    },

    /// An SRTM `.hgt` tile's name does not give its origin.
    #[error(
        "{}: an SRTM .hgt tile's name gives its south-west corner, like N37W123.hgt; \
         rename the file, or give its cell size (verdant bake --dem-cell-size)",
        path.display()
    )]
    HgtName {
        /// The file.
        path: PathBuf,
    },

    /// Too much of a DEM is nodata (voids) to fill from the rest.
    #[error(
        "{}: {nodata} of {total} samples ({:.1}%) are nodata, more than the {:.0}% that the \
         baker fills: crop the DEM to the area that has data",
        path.display(),
        100.0 * *nodata as f64 / (*total).max(1) as f64,
        100.0 * max_fraction
    )]
    TooMuchNodata {
        /// The DEM file.
        path: PathBuf,
        /// Nodata samples.
        nodata: u64,
        /// All samples.
        total: u64,
        /// The largest fraction of nodata that is filled.
        max_fraction: f64,
    },

    /// DEM files that cannot be joined into one: another coordinate system, no georeferencing,
    /// overlaps that disagree, a gap between them, a VRT or folder that names no DEM.
    #[error("{}: joining DEM files: {problem}", path.display())]
    DemMosaic {
        /// The file (or VRT, or folder) the problem is with.
        path: PathBuf,
        /// What is wrong, naming the other file where there is one.
        problem: String,
    },

    /// A land-cover map (or a density map, or a mask) that cannot be used: a format, CRS or
    /// extent the baker cannot place on the DEM, or classes its table does not list.
    #[error("{}: {what}: {problem}", path.display())]
    LandCover {
        /// The map.
        path: PathBuf,
        /// Which map it is: `land cover`, `density map` or `mask`.
        what: &'static str,
        /// What is wrong.
        problem: String,
    },

    /// A land-cover table that cannot be used: bad TOML, a grass type the world does not have,
    /// a density out of range, a class listed twice.
    #[error("{}: cover table: {problem}", path.display())]
    CoverTable {
        /// The table (or the built-in table's name).
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },

    /// Not even one of a bake's worker threads could be started.
    #[error(
        "could not start a thread for the bake: {source} (the process's limits on threads or \
         memory: ulimit -u, ulimit -v)"
    )]
    Threads {
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },

    /// A file fetched from a world served over HTTP could not be had: the server said no, the
    /// connection failed or stalled, or the body was cut short (the error names the URL).
    #[error(transparent)]
    Fetch(Box<dyn std::error::Error + Send + Sync + 'static>),
}

/// Variants added for bad options, implausible DEMs, unbounded reads and bake output folders.
impl WorldError {
    /// A bake option (or a value derived from the DEM and the options) is out of range.
    pub(crate) fn bad_option(option: &'static str, value: impl ToString, allowed: String) -> Self {
        WorldError::BadOption {
            option,
            value: value.to_string(),
            allowed,
        }
    }
}

impl WorldError {
    /// The file or directory the error concerns, where it concerns one.
    pub fn path(&self) -> Option<&Path> {
        use WorldError::*;
        match self {
            Io { path, .. }
            | MissingWorldDir { path }
            | InterruptedBake { path, .. }
            | MissingFile { path }
            | ManifestSyntax { path, .. }
            | NonFinite { path, .. }
            | NonPositive { path, .. }
            | Negative { path, .. }
            | DuplicateWindScene { path, .. }
            | UnknownPathRef { path, .. }
            | UnknownWindSceneRef { path, .. }
            | WindSourcePlacement { path, .. }
            | StrengthKeysOutOfOrder { path, .. }
            | OutOfRange { path, .. }
            | TooManyTiles { path, .. }
            | ExtentBeyondGrid { path, .. }
            | BadHeightRange { path, .. }
            | NoGrassTypes { path }
            | BadGrassRange { path, .. }
            | PathTooShort { path, .. }
            | PathKeysOutOfOrder { path, .. }
            | PathDurationMismatch { path, .. }
            | DuplicatePath { path, .. }
            | TileNotStored { path, .. }
            | TileStamp { path, .. }
            | StampIncomplete { path, .. }
            | CorruptImage { path, .. }
            | WrongDimensions { path, .. }
            | WrongLayout { path, .. }
            | NonFiniteHeight { path, .. }
            | HeightOutOfRange { path, .. }
            | GrassTypeOutOfRange { path, .. }
            | BadTileData { path, .. }
            | MissingSidecar { path, .. }
            | BadSidecar { path, .. }
            | SidecarMismatch { path, .. }
            | UnknownDemFormat { path, .. }
            | UnsupportedDem { path, .. }
            | NoGeoreference { path, .. }
            | HgtSize { path, .. }
            | HgtName { path }
            | TooMuchNodata { path, .. }
            | ImplausibleHeight { path, .. }
            | NotARegularFile { path, .. }
            | FileTooLarge { path, .. }
            | OutputNotEmpty { path }
            | ForeignInTiles { path, .. }
            | Carry { path, .. }
            | Cancelled { path }
            | PublishFailed { path, .. }
            | ShardTilesMissing { path, .. }
            | LandCover { path, .. }
            | DemMosaic { path, .. }
            | CoverTable { path, .. } => Some(path),
            BadOption { .. } | Threads { .. } | Fetch(_) => None,
        }
    }

    /// An [`WorldError::Io`] for `path`, or [`WorldError::MissingFile`] where the file is absent.
    pub(crate) fn io(path: &Path, source: std::io::Error) -> WorldError {
        if source.kind() == std::io::ErrorKind::NotFound {
            WorldError::MissingFile {
                path: path.to_path_buf(),
            }
        } else {
            WorldError::Io {
                path: path.to_path_buf(),
                source,
            }
        }
    }
}

/// A number for a message, short whatever its size: at most four decimals, and in scientific
/// notation beyond a million or below a thousandth (a sidecar's 1e300 is not 301 digits).
pub fn short_number(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-3..1e6).contains(&a) {
        let s = format!("{v:.4}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        };
        if s == "-0" { "0".into() } else { s }
    } else {
        format!("{v:.3e}")
    }
}
