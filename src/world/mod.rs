//! The world, GPU-free: tile addressing ([`TileId`], [`Pyramid`]), the manifest
//! ([`Manifest`], `world.toml`), the stored tile files ([`TileData`]), DEM loading (GeoTIFF,
//! SRTM `.hgt`, PNG + sidecar; nodata filling); the baker that turns a DEM into a world is
//! `crate::bake`.
//! [`grass_density`] works out the densest grass that sizes the grass pool (the manifest's
//! `grass_peak`), and [`fuzz`] holds the checks that the decoders are fuzzed against.
//!
//! A world is a directory:
//! ```text
//! worlds/NAME/world.toml                         the manifest
//! worlds/NAME/tiles/L{level}/{x}_{y}.height.exr  heights (f32)
//! worlds/NAME/tiles/L{level}/{x}_{y}.type.png    grass type index (8-bit)
//! worlds/NAME/tiles/L{level}/{x}_{y}.density.png grass density (8-bit)
//! worlds/NAME/tiles/L{level}/{x}_{y}.material.png terrain material (8-bit; only in worlds
//!                                                 whose manifest says `materials = true`)
//! ```

pub mod dem;
pub(crate) mod dem_grid;
pub mod error;
pub mod format;
pub mod fuzz;
pub(crate) mod geotiff;
pub mod grass_density;
mod hgt;
pub mod manifest;
pub mod material;
pub mod mosaic;
pub mod nodata;
pub mod tile;
pub mod window;

use std::path::{Path, PathBuf};

pub use dem::{Dem, DemFormat, DemOptions};
pub use error::WorldError;
pub use format::{
    ReadOptions, TileData, TileFile, check_stamp, read_tile, read_tile_with, tile_path, write_tile,
    write_tile_with,
};
pub use grass_density::GrassPeak;
pub use manifest::{
    CameraKey, CameraPath, DEFAULT_WIND_BLEND_S, DeriveCalibration, DeriveMode, FeatureSwitches,
    GrassType, LEGACY_DETAIL, MAX_DETAIL, MAX_GRASS_TYPES, MAX_PLANT_DENSITY, MAX_PLANT_SIZE_M,
    MAX_PLANT_TYPES, MAX_WIND_SOURCES, Manifest, PATH_DURATION_TOLERANCE_S, PLANT_RECIPES,
    PlantType, PlantWind, Sky, SourcePlacement, TREE_MIN_HEIGHT_M, WindDefaults, WindKey,
    WindScene, WindSource, WorldSource,
};
pub use material::{MATERIAL_COUNT, Material};
pub use tile::{Bounds, Pyramid, TileId};

/// Heights a world may hold, metres: Earth's surface spans about -10,935 m (the Challenger
/// Deep) to 8,849 m (Everest); a height beyond this range is a wrong offset or scale.
pub const PLAUSIBLE_HEIGHTS_M: [f64; 2] = [-12_000.0, 10_000.0];

/// Names listed in a message: the first dozen, then how many more (a manifest may name
/// thousands of paths or scenes, and an error line should stay readable).
pub fn name_list<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    const SHOWN: usize = 12;
    let names: Vec<&str> = names.into_iter().collect();
    let mut text = names
        .iter()
        .take(SHOWN)
        .map(|n| format!("{n:?}"))
        .collect::<Vec<_>>()
        .join(", ");
    if names.len() > SHOWN {
        text.push_str(&format!(" and {} more", names.len() - SHOWN));
    }
    text
}

/// `text` as one line safe to print or log: every control character (line breaks and tabs
/// among them) and every character that reorders the text around it written as its escape
/// (`\u{1b}`), so that an error quoting what a file or a server said cannot drive the
/// terminal, forge a line, or read as another text.
pub fn printable(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() || manifest::forbidden_control(c) {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// What a message says of the wind scenes a world has, given their [`name_list`]: the list, or,
/// where it is empty, that the world has none and where a scene is declared.
pub fn wind_scenes_held(available: &str) -> String {
    if available.is_empty() {
        "the world has no wind scenes: a scene is a [[wind_scenes]] table of the world's \
         world.toml"
            .to_owned()
    } else {
        format!("the world has: {available}")
    }
}

/// An opened world: its directory and its validated manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct World {
    /// The world directory (holding `world.toml` and `tiles/`).
    pub dir: PathBuf,
    /// The manifest.
    pub manifest: Manifest,
}

impl World {
    /// Opens the world in `dir`: reads and validates `dir/world.toml`.
    pub fn open(dir: &Path) -> Result<World, WorldError> {
        let interrupted = |what| {
            interrupted_bake(dir).map(|staging| WorldError::InterruptedBake {
                path: dir.to_path_buf(),
                what,
                staging,
            })
        };
        if !dir.is_dir() {
            return Err(interrupted("no such folder").unwrap_or_else(|| {
                WorldError::MissingWorldDir {
                    path: dir.to_path_buf(),
                }
            }));
        }
        let manifest_path = dir.join("world.toml");
        let manifest = match Manifest::from_path(&manifest_path) {
            Err(WorldError::MissingFile { path }) if path == manifest_path => {
                return Err(
                    interrupted("no world.toml").unwrap_or(WorldError::MissingFile { path })
                );
            }
            other => other?,
        };
        Ok(World {
            dir: dir.to_path_buf(),
            manifest,
        })
    }

    /// Reads a stored tile, checked against the manifest's height range and grass types.
    pub fn load_tile(&self, id: TileId) -> Result<TileData, WorldError> {
        let options = ReadOptions {
            height_range_m: self.manifest.height_range_m,
            grass_type_count: self.manifest.grass_types.len(),
            materials: self.manifest.materials,
            bake_id: self.manifest.bake_id_value(),
        };
        read_tile_with(&self.dir, &self.manifest.pyramid, id, &options)
    }

    /// Every stored tile, level by level (coarsest first), rows south to north, west to east.
    pub fn stored_tiles(&self) -> impl Iterator<Item = TileId> + '_ {
        let pyramid = &self.manifest.pyramid;
        (0..pyramid.stored_levels).flat_map(move |level| {
            let [nx, ny] = pyramid.tiles_at(level);
            (0..ny).flat_map(move |y| (0..nx).map(move |x| TileId::new(level, x, y)))
        })
    }

    /// The path to one of a tile's files.
    pub fn tile_path(&self, id: TileId, kind: TileFile) -> PathBuf {
        tile_path(&self.dir, id, kind)
    }
}

/// The file a bake's staging folder holds while it moves its world into the output folder.
pub(crate) const PUBLISH_JOURNAL: &str = "publishing.json";

/// The staging folder of a bake into `dir` that was stopped while moving its world in
/// (`.NAME.baking.*` beside it, holding [`PUBLISH_JOURNAL`]), if there is one.
fn interrupted_bake(dir: &Path) -> Option<PathBuf> {
    let name = dir.file_name()?.to_string_lossy().into_owned();
    let parent = match dir.parent() {
        Some(p) if p.as_os_str().is_empty() => Path::new("."),
        Some(p) => p,
        None => return None,
    };
    let prefix = format!(".{name}.baking.");
    std::fs::read_dir(parent)
        .ok()?
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path())
        .find(|p| p.join(PUBLISH_JOURNAL).is_file())
        .map(|p| match dir.parent() {
            Some(q) if q.as_os_str().is_empty() => PathBuf::from(p.file_name().unwrap_or_default()),
            _ => p,
        })
}

#[cfg(test)]
mod tests {
    /// Control characters, line breaks and bidirectional overrides come out as escapes; the
    /// rest (names in any script) as it was.
    #[test]
    fn printable_text_is_one_line_that_cannot_drive_a_terminal() {
        let text = "L2/0_0.type.png: \u{1b}]0;title\u{7}\r\nforged\tline \u{202e}abc wörld 山";
        let out = super::printable(text);
        assert_eq!(
            out,
            "L2/0_0.type.png: \\u{1b}]0;title\\u{7}\\r\\nforged\\tline \\u{202e}abc wörld 山"
        );
        assert!(!out.chars().any(|c| c.is_control()));
    }

    #[test]
    fn a_name_list_shows_a_dozen_and_counts_the_rest() {
        assert_eq!(super::name_list(["tour", "meadow"]), "\"tour\", \"meadow\"");
        let many: Vec<String> = (0..40_000).map(|i| format!("p{i}")).collect();
        let text = super::name_list(many.iter().map(String::as_str));
        assert!(text.starts_with("\"p0\", \"p1\""), "{text}");
        assert!(text.ends_with("\"p11\" and 39988 more"), "{text}");
        assert!(text.len() < 120, "{text}");
    }
}
