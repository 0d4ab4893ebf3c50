//! Land cover at bake time (`verdant bake --land-cover MAP --cover-table TABLE`): a raster of
//! classes and a table of what grows on each class, painted in place of the procedural rule
//! wherever the map has a class.
//!
//! - **The map**: a GeoTIFF of one uint8 or uint16 band (ESA WorldCover, NLCD and most
//!   land-cover products), or an 8- or 16-bit grayscale PNG. A georeferenced GeoTIFF is placed
//!   on the DEM by both files' georeferencing, which must be in the same coordinate system (the
//!   EPSG code, or the same words where there is none); its size, resolution and extent are its
//!   own. A PNG, or a GeoTIFF without georeferencing, spans the DEM exactly (first row north).
//!   Each sample of the finest grid takes the class of the map's nearest sample.
//! - **The table**: TOML, `name`, `nodata` (class codes that say "no data here") and one
//!   `[[class]]` per code: `code`, `name`, `grass` (one of the world's grass types, or "none":
//!   nothing grows) and `density` (the grass map's cover there, 0 to 1). Tables for ESA
//!   WorldCover and NLCD ship with verdant (`worlds/cover-tables/`), by the names
//!   `esa-worldcover` and `nlcd`.
//! - Where the map does not reach, or says nodata, the procedural rule paints as before. The
//!   slope rule holds everywhere: no grass on ground steeper than
//!   [`super::paint::MAX_GRASS_SLOPE_DEG`], whatever the class.
//! - **Value maps** ([`ValueMap`]), placed the same way: a density map (0 to 1) scales the
//!   painted cover, a mask (not 0) clears it.

use std::collections::BTreeMap;
use std::path::Path;

use glam::DVec2;
use serde::Deserialize;

use crate::world::dem::Dem;
use crate::world::error::WorldError;
use crate::world::manifest::GrassType;

/// The tables that ship with verdant: name, TOML.
pub const BUILT_IN_TABLES: [(&str, &str); 2] = [
    (
        "esa-worldcover",
        include_str!("../../worlds/cover-tables/esa_worldcover.toml"),
    ),
    ("nlcd", include_str!("../../worlds/cover-tables/nlcd.toml")),
];

/// Largest table read, bytes.
const MAX_TABLE_BYTES: u64 = 1 << 20;
/// Largest map read, samples (as a DEM).
const MAX_MAP_SAMPLES: u64 = crate::world::dem::MAX_DEM_SAMPLES;
/// Unknown classes named in an error at most.
const NAMED_UNKNOWN: usize = 8;

/// A land-cover table: what grows on each class.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CoverTable {
    /// The product it is for.
    pub name: String,
    /// Codes that mean "no data here" (the procedural rule paints there).
    #[serde(default)]
    pub nodata: Vec<u32>,
    /// One per class code.
    #[serde(rename = "class")]
    pub classes: Vec<CoverClass>,
}

/// One class of a [`CoverTable`].
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CoverClass {
    /// The code in the map.
    pub code: u32,
    /// Its name.
    pub name: String,
    /// The grass type that grows there, by name, or "none" (nothing grows).
    pub grass: String,
    /// The grass map's cover there, 0 to 1.
    pub density: f64,
}

impl CoverTable {
    /// Reads the table at `spec`, or, where no such file exists, the built-in table of that
    /// name ([`BUILT_IN_TABLES`]).
    pub fn load(spec: &Path) -> Result<CoverTable, WorldError> {
        let text = if spec.exists() {
            let (mut file, len) = crate::world::format::open_regular(spec)?;
            if len > MAX_TABLE_BYTES {
                return Err(WorldError::FileTooLarge {
                    path: spec.to_path_buf(),
                    size: len,
                    max: MAX_TABLE_BYTES,
                });
            }
            let mut s = String::new();
            std::io::Read::read_to_string(&mut file, &mut s).map_err(|e| table_error(spec, e))?;
            s
        } else {
            let name = spec.to_string_lossy();
            match BUILT_IN_TABLES.iter().find(|(n, _)| *n == name) {
                Some((_, text)) => (*text).to_owned(),
                None => {
                    let names: Vec<&str> = BUILT_IN_TABLES.iter().map(|t| t.0).collect();
                    return Err(table_error(
                        spec,
                        format!(
                            "no such file, and no built-in table of that name ({})",
                            names.join(", ")
                        ),
                    ));
                }
            }
        };
        let table: CoverTable = toml::from_str(&text).map_err(|e| table_error(spec, e))?;
        table.check(spec)?;
        Ok(table)
    }

    /// Refuses a table without classes, a code listed twice (or as both a class and nodata)
    /// and a density that is not a number in 0..=1.
    fn check(&self, path: &Path) -> Result<(), WorldError> {
        if self.classes.is_empty() {
            return Err(table_error(path, "no [[class]] entries"));
        }
        let mut seen = std::collections::BTreeSet::new();
        for c in &self.classes {
            if !seen.insert(c.code) || self.nodata.contains(&c.code) {
                return Err(table_error(
                    path,
                    format!("class {} is listed more than once", c.code),
                ));
            }
            if !(0.0..=1.0).contains(&c.density) {
                return Err(table_error(
                    path,
                    format!(
                        "class {} ({}): density {} must be in 0..=1",
                        c.code, c.name, c.density
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Per class code, the grass type index and the density byte, for a world of
    /// `grass_types`: a grass type the world does not have is refused, naming the class.
    fn resolve(
        &self,
        path: &Path,
        grass_types: &[GrassType],
    ) -> Result<BTreeMap<u32, (u8, u8)>, WorldError> {
        let mut out = BTreeMap::new();
        for c in &self.classes {
            let painted = if c.grass == "none" {
                (0, 0)
            } else {
                let Some(t) = grass_types.iter().position(|g| g.name == c.grass) else {
                    let names: Vec<&str> = grass_types.iter().map(|g| g.name.as_str()).collect();
                    return Err(table_error(
                        path,
                        format!(
                            "class {} ({}) grows \"{}\", which is not one of the world's grass \
                             types ({}, or \"none\")",
                            c.code,
                            c.name,
                            c.grass,
                            names.join(", ")
                        ),
                    ));
                };
                let byte = (c.density * 255.0).round() as u8;
                if byte == 0 { (0, 0) } else { (t as u8, byte) }
            };
            out.insert(c.code, painted);
        }
        Ok(out)
    }
}

fn table_error(path: &Path, problem: impl ToString) -> WorldError {
    WorldError::CoverTable {
        path: path.to_path_buf(),
        problem: problem.to_string(),
    }
}

fn map_error(path: &Path, problem: impl ToString) -> WorldError {
    WorldError::LandCover {
        path: path.to_path_buf(),
        problem: problem.to_string(),
    }
}

/// A land-cover map placed on the DEM, with its table resolved for the world's grass types.
pub struct CoverMap {
    placed: Placed,
    /// Class codes, row 0 north; `None` where the map says nodata.
    codes: Vec<Option<u32>>,
    /// Per code: grass type and density byte.
    painted: BTreeMap<u32, (u8, u8)>,
}

impl CoverMap {
    /// Reads the map at `path`, places it on `dem` and resolves `table` for `grass_types`.
    /// Refuses a map that cannot be placed (another coordinate system, no overlap with the
    /// DEM, a georeferenced map on a DEM without georeferencing) and one that holds codes the
    /// table does not list, naming them.
    pub fn load(
        path: &Path,
        dem: &Dem,
        table: &CoverTable,
        table_path: &Path,
        grass_types: &[GrassType],
    ) -> Result<CoverMap, WorldError> {
        let painted = table.resolve(table_path, grass_types)?;
        let raster = read_map(path)?;
        let placed = Placed::on(&raster, dem, path)?;
        let nodata: std::collections::BTreeSet<u32> = table.nodata.iter().copied().collect();
        let codes: Vec<Option<u32>> = raster
            .values
            .iter()
            .map(|v| {
                v.filter(|v| *v >= 0.0 && v.fract() == 0.0 && *v <= f64::from(u32::MAX))
                    .map(|v| v as u32)
                    .filter(|c| !nodata.contains(c))
            })
            .collect();
        let mut unknown: BTreeMap<u32, usize> = BTreeMap::new();
        for c in codes.iter().flatten() {
            if !painted.contains_key(c) {
                *unknown.entry(*c).or_default() += 1;
            }
        }
        if !unknown.is_empty() {
            let listed: Vec<String> = unknown
                .iter()
                .take(NAMED_UNKNOWN)
                .map(|(c, n)| format!("{c} ({n} samples)"))
                .collect();
            return Err(map_error(
                path,
                format!(
                    "classes the table {} does not list: {}{}",
                    table_path.display(),
                    listed.join(", "),
                    if unknown.len() > NAMED_UNKNOWN {
                        format!(" and {} more", unknown.len() - NAMED_UNKNOWN)
                    } else {
                        String::new()
                    }
                ),
            ));
        }
        Ok(CoverMap {
            placed,
            codes,
            painted,
        })
    }

    /// The grass type and density byte the map paints at world position `p` (metres from the
    /// DEM's south-west sample), or `None` where it does not reach or says nodata.
    pub fn paint_at(&self, p: DVec2) -> Option<(u8, u8)> {
        let code = self.codes[self.placed.index_at(p)?]?;
        self.painted.get(&code).copied()
    }
}

/// A raster placed on the DEM: its size, and world position (metres from the DEM's south-west
/// sample) to its column and row from the south, `column = a.x + b.x * x`, `row = a.y + b.y * y`.
struct Placed {
    width: usize,
    height: usize,
    a: DVec2,
    b: DVec2,
}

impl Placed {
    /// Places `raster` (read from `path`) on `dem` by their georeferencing, or over the whole
    /// DEM where the raster has none; refuses what cannot be placed or does not overlap.
    fn on(raster: &Raster, dem: &Dem, path: &Path) -> Result<Placed, WorldError> {
        let (w, h) = (raster.width as usize, raster.height as usize);
        let [ex, ey] = dem.extent_m();
        let (a, b) = match (
            raster.origin.zip(raster.pixel_size),
            dem.origin.zip(dem.pixel_size),
        ) {
            (None, _) => (
                DVec2::ZERO,
                DVec2::new((w - 1) as f64 / ex.max(1e-9), (h - 1) as f64 / ey.max(1e-9)),
            ),
            (Some(_), None) => {
                return Err(map_error(
                    path,
                    "the map is georeferenced but the DEM is not, so it cannot be placed on it \
                     (a map without georeferencing spans the DEM exactly)",
                ));
            }
            (Some((mo, ms)), Some((d_o, ds))) => {
                if crs_key(&raster.crs) != crs_key(&dem.crs) {
                    return Err(map_error(
                        path,
                        format!(
                            "its coordinate system ({}) is not the DEM's ({}): reproject it to the \
                             DEM's first (gdalwarp -t_srs ... -r near)",
                            or_unstated(&raster.crs),
                            or_unstated(&dem.crs)
                        ),
                    ));
                }
                // World metres -> the DEM's units -> the map's samples.
                let per_m = DVec2::new(ds[0] / dem.cell_ew_m, ds[1] / dem.cell_ns_m);
                let a = (DVec2::from(d_o) - DVec2::from(mo)) / DVec2::from(ms);
                (a, per_m / DVec2::from(ms))
            }
        };
        // The map's extent in world metres against the DEM's.
        let lo = (DVec2::splat(-0.5) - a) / b;
        let hi = (DVec2::new(w as f64 - 0.5, h as f64 - 0.5) - a) / b;
        if hi.x < 0.0 || hi.y < 0.0 || lo.x > ex || lo.y > ey {
            return Err(map_error(
                path,
                format!(
                    "it does not overlap the DEM: it spans {:.0}..{:.0} m east and {:.0}..{:.0} m \
                     north of the DEM's south-west corner, the DEM 0..{ex:.0} and 0..{ey:.0}",
                    lo.x, hi.x, lo.y, hi.y
                ),
            ));
        }
        Ok(Placed {
            width: w,
            height: h,
            a,
            b,
        })
    }

    /// The index (row 0 north) of the sample nearest world position `p`, `None` beyond the map.
    fn index_at(&self, p: DVec2) -> Option<usize> {
        let q = self.a + self.b * p;
        let (c, r) = (q.x.round(), q.y.round());
        if c < 0.0 || r < 0.0 || c >= self.width as f64 || r >= self.height as f64 {
            return None;
        }
        Some((self.height - 1 - r as usize) * self.width + c as usize)
    }
}

/// A map of one value a sample, placed on the DEM: a density map (0 to 1: the grass map's cover
/// is multiplied by it) or a mask (nothing grows where it is not 0).
pub struct ValueMap {
    placed: Placed,
    /// Values row 0 north, scaled to 0..=1 for a density map; `None` where the file says
    /// nodata.
    values: Vec<Option<f64>>,
}

impl ValueMap {
    /// A density map: an 8- or 16-bit grayscale PNG (0 to its largest value), or a GeoTIFF of
    /// values from 0 to 1 (a float band), 0 to 255 or 0 to 65535 (an integer band: which, by its
    /// largest value). Refuses negative values and what [`CoverMap::load`] refuses.
    pub fn density(path: &Path, dem: &Dem) -> Result<ValueMap, WorldError> {
        Self::read(path, dem, |raster| {
            if raster.values.iter().flatten().any(|&v| v < 0.0) {
                return Err(map_error(path, "a density map holds values below 0"));
            }
            let max = raster
                .values
                .iter()
                .flatten()
                .fold(0.0f64, |m, &v| m.max(v));
            let full = if raster.full > 1.0 || max <= 1.0 {
                raster.full
            } else if max <= 255.0 {
                255.0
            } else {
                65535.0
            };
            Ok(Box::new(move |v| (v / full).min(1.0)))
        })
    }

    /// A mask: nothing grows where its value is not 0 (nodata masks nothing).
    pub fn mask(path: &Path, dem: &Dem) -> Result<ValueMap, WorldError> {
        Self::read(path, dem, |_| {
            Ok(Box::new(|v| if v != 0.0 { 1.0 } else { 0.0 }))
        })
    }

    /// Reads the map at `path`, places it on `dem`, and maps each value by what `scale` makes
    /// of the raster.
    fn read(
        path: &Path,
        dem: &Dem,
        scale: impl FnOnce(&Raster) -> Result<Box<dyn Fn(f64) -> f64>, WorldError>,
    ) -> Result<ValueMap, WorldError> {
        let raster = read_map(path)?;
        let placed = Placed::on(&raster, dem, path)?;
        let f = scale(&raster)?;
        let values = raster.values.iter().map(|v| v.map(&f)).collect();
        Ok(ValueMap { placed, values })
    }

    /// The value at world position `p`, `None` beyond the map or where it says nodata.
    pub fn at(&self, p: DVec2) -> Option<f64> {
        self.values[self.placed.index_at(p)?]
    }
}

/// The part of a coordinate system's description that identifies it: its EPSG code where it
/// has one, else the whole description.
fn crs_key(crs: &str) -> &str {
    if crs.starts_with("EPSG:") {
        crs.split([',', ' ']).next().unwrap_or(crs)
    } else {
        crs
    }
}

fn or_unstated(crs: &str) -> &str {
    if crs.is_empty() { "not stated" } else { crs }
}

/// A raster as read: values row 0 north (`None`: the file's nodata), the value that means
/// "full" in its format (255 in an 8-bit PNG, 65535 in a 16-bit one, 1 in a GeoTIFF), and its
/// georeferencing where it has any.
struct Raster {
    width: u32,
    height: u32,
    values: Vec<Option<f64>>,
    full: f64,
    crs: String,
    origin: Option<[f64; 2]>,
    pixel_size: Option<[f64; 2]>,
}

/// Reads a PNG or GeoTIFF class map, told apart by content.
fn read_map(path: &Path) -> Result<Raster, WorldError> {
    let (mut file, _) = crate::world::format::open_regular(path)?;
    let mut magic = [0u8; 8];
    let n = std::io::Read::read(&mut file, &mut magic).map_err(|e| WorldError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    drop(file);
    let magic = &magic[..n];
    if magic.starts_with(b"\x89PNG") {
        return read_png(path);
    }
    if magic.starts_with(b"II*\0") || magic.starts_with(b"MM\0*") {
        // Read as it is; a map without georeferencing with a unit cell (it spans the DEM).
        let g = match crate::world::geotiff::load(path, None) {
            Err(WorldError::NoGeoreference { .. }) => {
                crate::world::geotiff::load(path, Some([1.0, 1.0]))?
            }
            other => other?,
        };
        let values = g
            .heights
            .iter()
            .map(|&v| v.is_finite().then_some(f64::from(v)))
            .collect();
        return Ok(Raster {
            width: g.width,
            height: g.height,
            values,
            full: 1.0,
            crs: g.crs,
            origin: g.origin,
            pixel_size: g.pixel_size,
        });
    }
    Err(map_error(
        path,
        "not a PNG or a TIFF (a map is a GeoTIFF of one band, or a grayscale PNG)",
    ))
}

fn read_png(path: &Path) -> Result<Raster, WorldError> {
    let bytes = std::fs::read(path).map_err(|e| WorldError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let mut reader = image::ImageReader::new(std::io::Cursor::new(&bytes));
    reader.set_format(image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_MAP_SAMPLES * 2);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| WorldError::CorruptImage {
        path: path.to_path_buf(),
        format: "PNG",
        message: e.to_string(),
    })?;
    let (width, height) = (img.width(), img.height());
    if width < 2 || height < 2 || u64::from(width) * u64::from(height) > MAX_MAP_SAMPLES {
        return Err(map_error(
            path,
            format!("{width}x{height} samples: at least 2x2 and at most {MAX_MAP_SAMPLES}"),
        ));
    }
    let (values, full): (Vec<u32>, f64) = match img {
        image::DynamicImage::ImageLuma8(g) => {
            (g.into_raw().into_iter().map(u32::from).collect(), 255.0)
        }
        image::DynamicImage::ImageLuma16(g) => {
            (g.into_raw().into_iter().map(u32::from).collect(), 65535.0)
        }
        other => {
            return Err(map_error(
                path,
                format!(
                    "a {:?} PNG: a map is grayscale, 8 or 16 bits, one value a pixel",
                    other.color()
                ),
            ));
        }
    };
    Ok(Raster {
        width,
        height,
        values: values.into_iter().map(|v| Some(f64::from(v))).collect(),
        full,
        crs: String::new(),
        origin: None,
        pixel_size: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_tables_read_and_resolve_for_the_baked_grass_types() {
        let types = super::super::paint::default_grass_types();
        for (name, _) in BUILT_IN_TABLES {
            let t = CoverTable::load(Path::new(name)).unwrap();
            assert!(t.classes.len() >= 10, "{name}");
            let r = t.resolve(Path::new(name), &types).unwrap();
            assert_eq!(r.len(), t.classes.len());
            // Water grows nothing; grassland grows meadow.
            let water = t.classes.iter().find(|c| c.name.contains("ater")).unwrap();
            assert_eq!(r[&water.code], (0, 0), "{name}");
            let grass = t
                .classes
                .iter()
                .find(|c| c.name.starts_with("Grassland"))
                .unwrap();
            assert_eq!(r[&grass.code].0, 1, "{name}: meadow");
        }
    }

    #[test]
    fn a_bad_table_is_refused_naming_the_problem() {
        let types = super::super::paint::default_grass_types();
        let dir = tempfile::tempdir().unwrap();
        let case = |text: &str| {
            let p = dir.path().join("t.toml");
            std::fs::write(&p, text).unwrap();
            CoverTable::load(&p).and_then(|t| t.resolve(&p, &types).map(|_| ()))
        };
        let class = |code: u32, grass: &str, density: f64| {
            format!(
                "[[class]]\ncode = {code}\nname = \"c{code}\"\ngrass = \"{grass}\"\ndensity = {density}\n"
            )
        };
        let head = "name = \"t\"\n";
        for (text, want) in [
            (format!("{head}{}", class(1, "lawn", 0.5)), "\"lawn\""),
            (
                format!("{head}{}{}", class(1, "meadow", 0.5), class(1, "none", 0.0)),
                "more than once",
            ),
            (format!("{head}{}", class(1, "meadow", 1.5)), "0..=1"),
            (format!("{head}class = []\n"), "no [[class]]"),
            ("name = 3".to_owned(), "cover table"),
        ] {
            let e = case(&text).unwrap_err().to_string();
            assert!(e.contains("t.toml") && e.contains(want), "{e}");
        }
        let e = CoverTable::load(Path::new("no-such-table"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("esa-worldcover, nlcd"), "{e}");
    }
}
