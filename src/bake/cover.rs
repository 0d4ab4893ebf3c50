//! Land cover at bake time (`verdant bake --land-cover MAP --cover-table TABLE`): a raster of
//! classes and a table of what grows on each class, painted in place of the procedural rule
//! wherever the map has a class.
//!
//! - **The map**: a GeoTIFF of one uint8 or uint16 band (ESA WorldCover, NLCD and most
//!   land-cover products), or an 8- or 16-bit grayscale PNG; a palette image (a GeoTIFF band with
//!   a colour table, a palette PNG) is read by its indices. Codes are read exactly, as integers;
//!   a band of another sample type (float, signed, 32-bit) is refused, naming it. A georeferenced
//!   GeoTIFF is placed on the DEM by both files' georeferencing (reprojected by their EPSG codes
//!   where their coordinate systems differ); its size, resolution and extent are its own, and
//!   only its window over the DEM's footprint is read (a whole ESA WorldCover tile or NLCD's
//!   CONUS map is given as it is; the window is bounded). A PNG, or a GeoTIFF without
//!   georeferencing, spans the DEM exactly (first row north) and is read whole. Each sample of
//!   the finest grid takes the class of the map's nearest sample.
//! - **The table**: TOML, `name`, `nodata` (class codes that say "no data here") and one
//!   `[[class]]` per code: `code`, `name`, `grass` (one of the world's grass types, or "none":
//!   nothing grows), `density` (the grass map's cover there, 0 to 1) and, optionally,
//!   `material` (the ground: soil, crops, rock, sand, water, road, snow; by default the grass
//!   type's ground, as without a map). Tables for ESA
//!   WorldCover and NLCD ship with verdant (`worlds/cover-tables/`), by the names
//!   `esa-worldcover` and `nlcd`.
//! - Where the map does not reach, or says nodata, the procedural rule paints as before. The
//!   slope rule holds everywhere: no grass on ground steeper than
//!   [`super::paint::MAX_GRASS_SLOPE_DEG`], whatever the class.
//! - **Value maps** ([`ValueMap`]), placed and read the same way (of a georeferenced GeoTIFF
//!   only the window over the DEM): a density map (0 to 1) scales the painted cover, a mask
//!   (not 0) clears it.

use std::collections::BTreeMap;
use std::path::Path;

use glam::DVec2;
use serde::Deserialize;

use crate::world::dem::Dem;
use crate::world::dem_grid::{crs_key, or_unstated};
use crate::world::error::WorldError;
use crate::world::manifest::GrassType;
use crate::world::material::Material;

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
/// Samples read beyond the DEM's footprint on every side of a georeferenced map's window.
const WINDOW_MARGIN: usize = 2;
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
    /// The ground's material there, by name (`crate::world::Material`: soil, crops, rock,
    /// sand, water, road, snow, or default: the grass type's ground); default when absent.
    #[serde(default)]
    pub material: Option<String>,
}

/// What a class paints on a sample: grass type index, density byte and material byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClassPaint {
    /// Index into the world's grass types (0 where nothing grows).
    pub grass_type: u8,
    /// Grass density, 0..=255 (0 where nothing grows).
    pub density: u8,
    /// The ground's material byte (`crate::world::Material`).
    pub material: u8,
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
        let table: CoverTable = toml::from_str(&text)
            .map_err(|e| table_error(spec, crate::world::manifest::toml_error(&text, &e)))?;
        table.check(spec)?;
        Ok(table)
    }

    /// Refuses a table without classes, a code listed twice (or as both a class and nodata),
    /// a density that is not a number in 0..=1 and a material verdant does not know.
    fn check(&self, path: &Path) -> Result<(), WorldError> {
        if self.classes.is_empty() {
            return Err(table_error(path, "no [[class]] entries"));
        }
        let mut seen = std::collections::BTreeSet::new();
        for c in &self.classes {
            if !seen.insert(c.code) {
                return Err(table_error(
                    path,
                    format!("class {} is listed more than once", c.code),
                ));
            }
            if self.nodata.contains(&c.code) {
                return Err(table_error(
                    path,
                    format!(
                        "code {} is listed both in nodata and as a [[class]]: it is one or the \
                         other",
                        c.code
                    ),
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
            if let Some(m) = &c.material
                && Material::from_name(m).is_none()
            {
                return Err(table_error(
                    path,
                    format!(
                        "class {} ({}): material \"{m}\" is not one of verdant's materials ({})",
                        c.code,
                        c.name,
                        Material::names()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Per class code, what it paints, for a world of `grass_types`: a grass type the world
    /// does not have is refused, naming the class.
    fn resolve(
        &self,
        path: &Path,
        grass_types: &[GrassType],
    ) -> Result<BTreeMap<u32, ClassPaint>, WorldError> {
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
            let material = c
                .material
                .as_deref()
                .and_then(Material::from_name)
                .unwrap_or(Material::Default);
            out.insert(
                c.code,
                ClassPaint {
                    grass_type: painted.0,
                    density: painted.1,
                    material: material as u8,
                },
            );
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
        what: "land cover",
        problem: problem.to_string(),
    }
}

/// `e` with a land-cover map's errors said of the map `what` is (a density map, a mask).
fn as_map(e: WorldError, what: &'static str) -> WorldError {
    match e {
        WorldError::LandCover { path, problem, .. } => WorldError::LandCover {
            path,
            what,
            problem,
        },
        e => e,
    }
}

/// The part of a land-cover map that was read: all of it, or of a georeferenced GeoTIFF the
/// window over the DEM's footprint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MapWindow {
    /// The whole map's samples: columns, rows.
    pub map_size: [u32; 2],
    /// The window's north-west sample: column from the west, row from the north.
    pub first: [u32; 2],
    /// The window's samples: columns, rows (what was decoded and is held).
    pub size: [u32; 2],
}

/// A land-cover map placed on the DEM, with its table resolved for the world's grass types.
pub struct CoverMap {
    placed: Placed,
    window: MapWindow,
    /// Class codes (of at most 16 bits), row 0 north; `None` where the map says nodata.
    codes: Vec<Option<u16>>,
    /// Per code: what it paints.
    painted: BTreeMap<u32, ClassPaint>,
    /// The most bytes reading it took beside its codes.
    read_bytes: u64,
}

impl CoverMap {
    /// Whether any class of its table names a material other than the default (the world's
    /// tiles then carry a material map).
    pub fn has_materials(&self) -> bool {
        self.painted
            .values()
            .any(|c| c.material != Material::Default as u8)
    }

    /// Reads the map at `path`, places it on `dem` and resolves `table` for `grass_types`.
    /// Of a georeferenced GeoTIFF only the window over the DEM's footprint is read (a map of
    /// any size: a whole ESA WorldCover tile or NLCD's CONUS), at most 2^28 samples;
    /// see [`CoverMap::load_within`].
    pub fn load(
        path: &Path,
        dem: &Dem,
        table: &CoverTable,
        table_path: &Path,
        grass_types: &[GrassType],
    ) -> Result<CoverMap, WorldError> {
        Self::load_within(path, dem, table, table_path, grass_types, MAX_MAP_SAMPLES)
    }

    /// [`CoverMap::load`] holding at most `max_samples` of the map: the window of a
    /// georeferenced GeoTIFF over the DEM's footprint (and two samples around it), or a
    /// GeoTIFF without georeferencing whole (a PNG map is read whole, at most 2^28 samples).
    /// Refuses a window (or a map read whole) of more samples, naming its size and how to crop
    /// the map; a map whose samples are not unsigned integers of at
    /// most 16 bits (a float or signed band, naming its type), one that cannot be placed
    /// (another coordinate system, no overlap with the DEM, a georeferenced map on a DEM
    /// without georeferencing) and one that holds codes the table does not list where it is
    /// read, naming them.
    pub fn load_within(
        path: &Path,
        dem: &Dem,
        table: &CoverTable,
        table_path: &Path,
        grass_types: &[GrassType],
        max_samples: u64,
    ) -> Result<CoverMap, WorldError> {
        let painted = table.resolve(table_path, grass_types)?;
        let MapRead {
            placed,
            samples: codes,
            window,
            read_bytes,
            ..
        } = read_map(
            path,
            dem,
            max_samples,
            MapKind::Classes,
            // A PNG's samples are of at most 16 bits.
            |v| Some(v as u16),
            |tiff, first, size| tiff.read_classes(first, size),
        )?;
        let nodata: std::collections::BTreeSet<u32> = table.nodata.iter().copied().collect();
        let codes: Vec<Option<u16>> = codes
            .into_iter()
            .map(|c| c.filter(|c| !nodata.contains(&u32::from(*c))))
            .collect();
        let mut unknown: BTreeMap<u32, usize> = BTreeMap::new();
        for &c in codes.iter().flatten() {
            if !painted.contains_key(&u32::from(c)) {
                *unknown.entry(u32::from(c)).or_default() += 1;
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
            window,
            codes,
            painted,
            read_bytes,
        })
    }

    /// The part of the map that was read and is held.
    pub fn window(&self) -> MapWindow {
        self.window
    }

    /// Bytes its window's codes take.
    pub fn held_bytes(&self) -> u64 {
        std::mem::size_of_val(self.codes.as_slice()) as u64
    }

    /// The most bytes reading it took beside what it holds: a GeoTIFF's largest chunk as
    /// stored and decoded, a PNG's file and image.
    pub fn read_bytes(&self) -> u64 {
        self.read_bytes
    }

    /// What the map paints at world position `p` (metres from the DEM's south-west sample), or
    /// `None` where it does not reach or says nodata.
    pub fn paint_at(&self, p: DVec2) -> Option<ClassPaint> {
        let code = self.codes[self.placed.index_at(p)?]?;
        self.painted.get(&u32::from(code)).copied()
    }
}

/// A raster placed on the DEM: its size (or the size of the window of it that was read), and
/// world position (metres from the DEM's south-west sample) to its column and row from the
/// south.
struct Placed {
    width: usize,
    height: usize,
    /// The window's south-west sample in the whole raster: column from the west, row from the
    /// south (`[0, 0]` where it was read whole).
    first: [usize; 2],
    to_raster: ToRaster,
}

/// World position to a raster's column and row (from the south).
enum ToRaster {
    /// In the DEM's coordinate system (or spanning it): `a + b * p`.
    Linear { a: DVec2, b: DVec2 },
    /// In another coordinate system: the column and row at the nodes of a lattice over the
    /// DEM, `step` metres apart from `origin`, `nodes.x` across, interpolated bilinearly
    /// between them (a projection is smooth over a lattice cell; the nodes are exact).
    Lattice {
        origin: DVec2,
        step: f64,
        nodes: [usize; 2],
        at: Vec<DVec2>,
    },
}

/// Lattice cells across the DEM's longer side for a reprojected map.
const LATTICE_CELLS: f64 = 256.0;

impl ToRaster {
    fn map(&self, p: DVec2) -> DVec2 {
        match self {
            ToRaster::Linear { a, b } => *a + *b * p,
            ToRaster::Lattice {
                origin,
                step,
                nodes,
                at,
            } => {
                let g = ((p - *origin) / *step).clamp(
                    DVec2::ZERO,
                    DVec2::new((nodes[0] - 1) as f64, (nodes[1] - 1) as f64),
                );
                let i = (g.x.floor() as usize).min(nodes[0] - 2);
                let j = (g.y.floor() as usize).min(nodes[1] - 2);
                let f = g - DVec2::new(i as f64, j as f64);
                let n = |i: usize, j: usize| at[j * nodes[0] + i];
                let south = n(i, j).lerp(n(i + 1, j), f.x);
                let north = n(i, j + 1).lerp(n(i + 1, j + 1), f.x);
                south.lerp(north, f.y)
            }
        }
    }
}

/// The EPSG code of a coordinate system's description (`EPSG:32610, projected ...`), if any.
fn epsg_code(crs: &str) -> Option<u16> {
    crs_key(crs).strip_prefix("EPSG:")?.parse().ok()
}

/// The lattice that places a raster in coordinate system `raster_crs` (`origin` its
/// south-west sample, `size` its spacing) on `dem` in another: world metres -> the DEM's
/// coordinates -> geographic -> the raster's coordinates -> its samples, by `proj4rs` at every
/// node. `None` with the reason where either system is unknown or a node does not transform.
fn reprojection_lattice(
    raster_crs: &str,
    origin: [f64; 2],
    size: [f64; 2],
    dem: &Dem,
    dem_origin: [f64; 2],
    dem_size: [f64; 2],
) -> Result<ToRaster, String> {
    let proj = |crs: &str| {
        let code = epsg_code(crs).ok_or_else(|| {
            format!(
                "\"{}\" has no EPSG code, so the baker cannot reproject it",
                or_unstated(crs)
            )
        })?;
        proj4rs::Proj::from_epsg_code(code)
            .map_err(|e| format!("EPSG:{code} is not a coordinate system the baker knows ({e})"))
    };
    let (from, to) = (proj(&dem.crs)?, proj(raster_crs)?);
    let [ex, ey] = dem.extent_m();
    let step = ex.max(ey).max(1e-6) / LATTICE_CELLS;
    // One node beyond each edge, so that every sample of the DEM is inside the lattice.
    let origin_m = DVec2::splat(-step);
    let nodes = [
        (ex / step).ceil() as usize + 3,
        (ey / step).ceil() as usize + 3,
    ];
    let per_m = DVec2::new(dem_size[0] / dem.cell_ew_m, dem_size[1] / dem.cell_ns_m);
    let mut at = Vec::with_capacity(nodes[0] * nodes[1]);
    for j in 0..nodes[1] {
        for i in 0..nodes[0] {
            let p = origin_m + DVec2::new(i as f64, j as f64) * step;
            let q = DVec2::from(dem_origin) + p * per_m;
            let radians = |v: DVec2, latlong: bool| {
                if latlong {
                    DVec2::new(v.x.to_radians(), v.y.to_radians())
                } else {
                    v
                }
            };
            let q = radians(q, from.is_latlong());
            let (x, y) = proj4rs::adaptors::transform_xy(&from, &to, q.x, q.y).map_err(|e| {
                format!(
                    "a point of the DEM ({:.0} m east, {:.0} m north of its south-west corner)                      does not transform from {} to {} ({e})",
                    p.x,
                    p.y,
                    crs_key(&dem.crs),
                    crs_key(raster_crs)
                )
            })?;
            let r = if to.is_latlong() {
                DVec2::new(x.to_degrees(), y.to_degrees())
            } else {
                DVec2::new(x, y)
            };
            if !r.is_finite() {
                return Err(format!(
                    "a point of the DEM ({:.0} m east, {:.0} m north of its south-west corner)                      falls off the map's projection",
                    p.x, p.y
                ));
            }
            at.push((r - DVec2::from(origin)) / DVec2::from(size));
        }
    }
    Ok(ToRaster::Lattice {
        origin: origin_m,
        step,
        nodes,
        at,
    })
}

impl Placed {
    /// Places `raster` (read from `path`) on `dem` by their georeferencing, or over the whole
    /// DEM where the raster has none; refuses what cannot be placed or does not overlap.
    fn on(raster: &Georef, dem: &Dem, path: &Path) -> Result<Placed, WorldError> {
        let (w, h) = (raster.width as usize, raster.height as usize);
        let [ex, ey] = dem.extent_m();
        let to_raster = match (
            raster.origin.zip(raster.pixel_size),
            dem.origin.zip(dem.pixel_size),
        ) {
            (None, _) => ToRaster::Linear {
                a: DVec2::ZERO,
                b: DVec2::new((w - 1) as f64 / ex.max(1e-9), (h - 1) as f64 / ey.max(1e-9)),
            },
            (Some(_), None) => {
                return Err(map_error(
                    path,
                    "the map is georeferenced but the DEM is not, so it cannot be placed on it \
                     (a map without georeferencing spans the DEM exactly)",
                ));
            }
            (Some((mo, ms)), Some((d_o, ds))) if crs_key(&raster.crs) != crs_key(&dem.crs) => {
                reprojection_lattice(&raster.crs, mo, ms, dem, d_o, ds).map_err(|why| {
                    map_error(
                        path,
                        format!(
                            "its coordinate system ({}) is not the DEM's ({}), and {why}: \
                             reproject it to the DEM's first (gdalwarp -t_srs ... -r near)",
                            or_unstated(&raster.crs),
                            or_unstated(&dem.crs)
                        ),
                    )
                })?
            }
            (Some((mo, ms)), Some((d_o, ds))) => {
                // World metres -> the DEM's units -> the map's samples.
                let per_m = DVec2::new(ds[0] / dem.cell_ew_m, ds[1] / dem.cell_ns_m);
                let a = (DVec2::from(d_o) - DVec2::from(mo)) / DVec2::from(ms);
                ToRaster::Linear {
                    a,
                    b: per_m / DVec2::from(ms),
                }
            }
        };
        let placed = Placed {
            width: w,
            height: h,
            first: [0, 0],
            to_raster,
        };
        match &placed.to_raster {
            ToRaster::Linear { a, b } => {
                // The map's extent in world metres against the DEM's.
                let lo = (DVec2::splat(-0.5) - *a) / *b;
                let hi = (DVec2::new(w as f64 - 0.5, h as f64 - 0.5) - *a) / *b;
                if hi.x < 0.0 || hi.y < 0.0 || lo.x > ex || lo.y > ey {
                    return Err(map_error(
                        path,
                        format!(
                            "it does not overlap the DEM: it spans {:.0}..{:.0} m east and \
                             {:.0}..{:.0} m north of the DEM's south-west corner, the DEM \
                             0..{ex:.0} and 0..{ey:.0}",
                            lo.x, hi.x, lo.y, hi.y
                        ),
                    ));
                }
            }
            ToRaster::Lattice { at, .. } => {
                let inside = |q: &DVec2| {
                    q.x > -0.5 && q.y > -0.5 && q.x < w as f64 - 0.5 && q.y < h as f64 - 0.5
                };
                if !at.iter().any(inside) {
                    let (lo, hi) = at.iter().fold(
                        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                        |(lo, hi), q| (lo.min(*q), hi.max(*q)),
                    );
                    return Err(map_error(
                        path,
                        format!(
                            "it does not overlap the DEM: reprojected into the map's \
                             coordinate system ({}), the DEM spans its columns {:.0}..{:.0} \
                             and rows {:.0}..{:.0} from the south, the map 0..{w} and 0..{h}",
                            crs_key(&raster.crs),
                            lo.x,
                            hi.x,
                            lo.y,
                            hi.y
                        ),
                    ));
                }
            }
        }
        Ok(placed)
    }

    /// The DEM's footprint on the whole raster, `margin` samples wider on every side and
    /// clamped to it: its first and last columns (from the west) and rows (from the south),
    /// inclusive. Every world position inside the DEM maps to a sample of it. Only for a
    /// raster placed by [`Placed::on`] that overlaps the DEM.
    fn footprint(&self, dem: &Dem, margin: usize) -> [[usize; 2]; 2] {
        let (lo, hi) = match &self.to_raster {
            ToRaster::Linear { a, b } => {
                // Linear: the DEM's corners bound it.
                let [ex, ey] = dem.extent_m();
                let q0 = *a;
                let q1 = *a + *b * DVec2::new(ex, ey);
                (q0.min(q1), q0.max(q1))
            }
            // The lattice reaches a node beyond the DEM's every edge.
            ToRaster::Lattice { at, .. } => at.iter().fold(
                (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                |(lo, hi), q| (lo.min(*q), hi.max(*q)),
            ),
        };
        let m = margin as f64;
        let span = |lo: f64, hi: f64, n: usize| {
            let last = (n - 1) as f64;
            let first = (lo.round() - m).clamp(0.0, last) as usize;
            let end = (hi.round() + m).clamp(0.0, last) as usize;
            [first, end.max(first)]
        };
        [span(lo.x, hi.x, self.width), span(lo.y, hi.y, self.height)]
    }

    /// The raster cut to a window of `size` samples (columns, rows) whose south-west sample is
    /// the whole raster's `first` (column from the west, row from the south): positions map to
    /// the same samples, and beyond the window to none.
    fn window(self, first: [usize; 2], size: [usize; 2]) -> Placed {
        Placed {
            width: size[0],
            height: size[1],
            first,
            ..self
        }
    }

    /// The index (row 0 north) of the sample nearest world position `p`, `None` beyond the map
    /// (or the window of it that was read).
    fn index_at(&self, p: DVec2) -> Option<usize> {
        let q = self.to_raster.map(p);
        // The nearest sample of the whole raster, then its place in the window (exactly: whole
        // numbers).
        let c = q.x.round() - self.first[0] as f64;
        let r = q.y.round() - self.first[1] as f64;
        if c < 0.0 || r < 0.0 || c >= self.width as f64 || r >= self.height as f64 {
            return None;
        }
        Some((self.height - 1 - r as usize) * self.width + c as usize)
    }
}

/// A map of one value a sample, placed on the DEM: a density map (0 to 1: the grass map's cover
/// is multiplied by it) or a mask (nothing grows where it is not 0). Of a georeferenced GeoTIFF
/// only the window over the DEM's footprint is read and held, as of a land-cover map.
pub struct ValueMap {
    placed: Placed,
    window: MapWindow,
    samples: Samples,
    read_bytes: u64,
}

/// A [`ValueMap`]'s samples (of its window), row 0 north.
enum Samples {
    /// A density map's values as read (NaN where the file says nodata), 4 bytes a sample; a
    /// value `v` is `v / full` (at most 1).
    Density { values: Vec<f32>, full: f64 },
    /// A mask's samples, 1 byte each: [`MASK_CLEAR`] where its value is not 0, 0 where it is,
    /// [`MASK_NODATA`] where the file says nodata.
    Mask(Vec<u8>),
}

/// A mask sample whose value is not 0: nothing grows there.
const MASK_CLEAR: u8 = 1;
/// A mask sample where the file says nodata: it masks nothing.
const MASK_NODATA: u8 = 2;

impl ValueMap {
    /// A density map: an 8- or 16-bit grayscale PNG (0 to its largest value), or a GeoTIFF of
    /// values from 0 to 1 (a float band), 0 to 255 or 0 to 65535 (an integer band: which, by the
    /// largest value read). Of a georeferenced GeoTIFF only the window over the DEM's footprint
    /// is read (a map of any size), at most 2^28 samples; see [`ValueMap::density_within`].
    pub fn density(path: &Path, dem: &Dem) -> Result<ValueMap, WorldError> {
        Self::density_within(path, dem, MAX_MAP_SAMPLES)
    }

    /// [`ValueMap::density`] holding at most `max_samples` of the map, read as
    /// [`CoverMap::load_within`] reads a land-cover map (the window of a georeferenced GeoTIFF,
    /// or a map without georeferencing whole). Refuses negative values where it is read, a
    /// window (or a map read whole) of more samples, naming its size and how to crop the map,
    /// and what [`CoverMap::load_within`] refuses of a map's format and placing.
    pub fn density_within(
        path: &Path,
        dem: &Dem,
        max_samples: u64,
    ) -> Result<ValueMap, WorldError> {
        let what = "density map";
        let read = read_map(
            path,
            dem,
            max_samples,
            MapKind::Values,
            |v| v as f32,
            |tiff, first, size| tiff.read_values(first, size, |v| v),
        )
        .map_err(|e| as_map(e, what))?;
        let values = read.samples;
        // NaN (nodata) is neither below 0 nor the largest.
        if values.iter().any(|&v| v < 0.0) {
            return Err(as_map(map_error(path, "it holds values below 0"), what));
        }
        let max = values.iter().fold(0.0f64, |m, &v| m.max(f64::from(v)));
        // Past the largest scale a value has no meaning: a huge number standing in for an
        // undeclared nodata would paint full grass.
        if read.full <= 1.0 && max > 65535.0 {
            return Err(as_map(
                map_error(
                    path,
                    format!(
                        "it holds the value {max} where densities run 0 to 1, 0 to 255 or 0 to \
                         65535 (a nodata value the file does not declare? set GDAL_NODATA)"
                    ),
                ),
                what,
            ));
        }
        let full = if read.full > 1.0 || max <= 1.0 {
            read.full
        } else if max <= 255.0 {
            255.0
        } else {
            65535.0
        };
        Ok(ValueMap {
            placed: read.placed,
            window: read.window,
            samples: Samples::Density { values, full },
            read_bytes: read.read_bytes,
        })
    }

    /// A mask: nothing grows where its value is not 0 (nodata masks nothing). Read as
    /// [`ValueMap::density`] is; see [`ValueMap::mask_within`].
    pub fn mask(path: &Path, dem: &Dem) -> Result<ValueMap, WorldError> {
        Self::mask_within(path, dem, MAX_MAP_SAMPLES)
    }

    /// [`ValueMap::mask`] holding at most `max_samples` of the map, as
    /// [`ValueMap::density_within`].
    pub fn mask_within(path: &Path, dem: &Dem, max_samples: u64) -> Result<ValueMap, WorldError> {
        let clear = |v: f32| {
            if v.is_nan() {
                MASK_NODATA
            } else {
                u8::from(v != 0.0) * MASK_CLEAR
            }
        };
        let read = read_map(
            path,
            dem,
            max_samples,
            MapKind::Values,
            |v| u8::from(v != 0) * MASK_CLEAR,
            |tiff, first, size| tiff.read_values(first, size, clear),
        )
        .map_err(|e| as_map(e, "mask"))?;
        Ok(ValueMap {
            placed: read.placed,
            window: read.window,
            samples: Samples::Mask(read.samples),
            read_bytes: read.read_bytes,
        })
    }

    /// The part of the map that was read and is held.
    pub fn window(&self) -> MapWindow {
        self.window
    }

    /// The most bytes reading it took beside what it holds (as [`CoverMap::read_bytes`]).
    pub fn read_bytes(&self) -> u64 {
        self.read_bytes
    }

    /// Bytes its window's samples take.
    pub fn held_bytes(&self) -> u64 {
        (match &self.samples {
            Samples::Density { values, .. } => std::mem::size_of_val(values.as_slice()),
            Samples::Mask(m) => m.len(),
        }) as u64
    }

    /// The value at world position `p` (a density map's scaled to 0..=1, a mask's 1 where it
    /// clears and 0 where not), `None` beyond the map (or the window of it read) or where it
    /// says nodata.
    pub fn at(&self, p: DVec2) -> Option<f64> {
        let i = self.placed.index_at(p)?;
        match &self.samples {
            Samples::Density { values, full } => {
                let v = values[i];
                (!v.is_nan()).then(|| (f64::from(v) / full).min(1.0))
            }
            Samples::Mask(m) => match m[i] {
                MASK_NODATA => None,
                v => Some(f64::from(v)),
            },
        }
    }
}

/// A raster's size and georeferencing (where it has any), known before its samples are read.
struct Georef {
    width: u32,
    height: u32,
    crs: String,
    origin: Option<[f64; 2]>,
    pixel_size: Option<[f64; 2]>,
}

/// A PNG map as read: its size (and no georeferencing), its samples row 0 north, and the value
/// that means "full" (255 in an 8-bit PNG, 65535 in a 16-bit one).
struct Raster {
    geo: Georef,
    values: Vec<u32>,
    full: f64,
    /// The most bytes reading it took: the file's, the decoded image's and the values'.
    read_bytes: u64,
}

/// The two formats a map may be in, told apart by content.
enum MapFormat {
    Png,
    Tiff,
}

fn map_format(path: &Path) -> Result<MapFormat, WorldError> {
    let (mut file, _) = crate::world::format::open_regular(path)?;
    let mut magic = [0u8; 8];
    let n = std::io::Read::read(&mut file, &mut magic).map_err(|e| WorldError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let magic = &magic[..n];
    if magic.starts_with(b"\x89PNG") {
        Ok(MapFormat::Png)
    } else if magic.starts_with(b"II*\0") || magic.starts_with(b"MM\0*") {
        Ok(MapFormat::Tiff)
    } else {
        Err(map_error(
            path,
            "not a PNG or a TIFF (a map is a GeoTIFF of one band, or a grayscale PNG)",
        ))
    }
}

/// What a map's samples are: class codes (a land-cover map) or values (a density map, a mask).
#[derive(Clone, Copy, PartialEq, Eq)]
enum MapKind {
    Classes,
    Values,
}

/// A map placed on the DEM and the part of it read: its samples (row 0 north) as kept, and the
/// value that means "full" in its format (255 in an 8-bit PNG, 65535 in a 16-bit one, 1 in a
/// GeoTIFF).
struct MapRead<T> {
    placed: Placed,
    samples: Vec<T>,
    window: MapWindow,
    full: f64,
    /// The most bytes reading it took beside its samples as kept.
    read_bytes: u64,
}

/// Reads a map and places it on `dem`: a GeoTIFF of one band (of class codes, `kind`
/// Classes: uint8 or uint16, grayscale or with a colour table; of values: any sample type a DEM
/// may have), or a grayscale PNG (or, of class codes, a palette PNG's indices), its samples kept
/// as `from_png` and `from_tiff` make them. Of a georeferenced GeoTIFF only the window over the
/// DEM's footprint is read (its strips or tiles that hold it decoded, one at a time, by
/// `from_tiff(map, first, size)`), and the window may hold at most `max_samples`; a PNG, or a
/// GeoTIFF without georeferencing, spans the DEM and is read whole (a PNG of at most
/// [`MAX_MAP_SAMPLES`], a GeoTIFF of at most `max_samples`).
fn read_map<T>(
    path: &Path,
    dem: &Dem,
    max_samples: u64,
    kind: MapKind,
    from_png: impl Fn(u32) -> T,
    from_tiff: impl FnOnce(
        &crate::world::geotiff::MapTiff,
        [usize; 2],
        [usize; 2],
    ) -> Result<Vec<T>, WorldError>,
) -> Result<MapRead<T>, WorldError> {
    let tiff = match map_format(path)? {
        MapFormat::Png => {
            let raster = read_png(path, kind == MapKind::Classes)?;
            let placed = Placed::on(&raster.geo, dem, path)?;
            let size = [raster.geo.width, raster.geo.height];
            return Ok(MapRead {
                placed,
                read_bytes: raster.read_bytes,
                samples: raster.values.into_iter().map(from_png).collect(),
                window: MapWindow {
                    map_size: size,
                    first: [0, 0],
                    size,
                },
                full: raster.full,
            });
        }
        MapFormat::Tiff => match kind {
            MapKind::Classes => crate::world::geotiff::open_classes(path)?,
            MapKind::Values => crate::world::geotiff::open_values(path)?,
        },
    };
    let geo = Georef {
        width: tiff.width,
        height: tiff.height,
        crs: tiff.crs.clone(),
        origin: tiff.origin,
        pixel_size: tiff.pixel_size,
    };
    let placed = Placed::on(&geo, dem, path)?;
    let map_size = [geo.width, geo.height];
    let whole = geo.origin.is_none() || geo.pixel_size.is_none();
    let [cols, rows] = if whole {
        [[0, geo.width as usize - 1], [0, geo.height as usize - 1]]
    } else {
        placed.footprint(dem, WINDOW_MARGIN)
    };
    let size = [cols[1] + 1 - cols[0], rows[1] + 1 - rows[0]];
    // The window's north-west sample: rows are counted from the north in the file.
    let first = [cols[0], geo.height as usize - 1 - rows[1]];
    let samples = size[0] as u64 * size[1] as u64;
    if samples > max_samples {
        let [w, h] = map_size;
        let problem = if whole {
            format!(
                "{w}x{h} samples, more than the {max_samples} a map is read with at most: a map \
                 without georeferencing spans the DEM and is read whole; georeference it (only \
                 its part over the DEM is then read) or resample it smaller"
            )
        } else {
            format!(
                "its part over the DEM is a window of {}x{} samples (columns {}..{}, rows {}..{} \
                 from the north of its {w}x{h}), more than the {max_samples} a map is read with \
                 at most: crop the map to the DEM's area first (gdal_translate -projwin, or \
                 gdalwarp -te with -r near), or bake a smaller DEM",
                size[0],
                size[1],
                first[0],
                first[0] + size[0],
                first[1],
                first[1] + size[1],
            )
        };
        return Err(map_error(path, problem));
    }
    let samples = from_tiff(&tiff, first, size)?;
    Ok(MapRead {
        read_bytes: tiff.chunk_read_bytes(),
        placed: placed.window([cols[0], rows[0]], size),
        samples,
        window: MapWindow {
            map_size,
            first: first.map(|v| v as u32),
            size: size.map(|v| v as u32),
        },
        full: 1.0,
    })
}

/// Reads a PNG map as the samples it stores: a grayscale PNG of 1 to 16 bits, or, for a class
/// map (`classes`), a palette PNG's indices too (its colours are not read). "Full" is the
/// largest value of its bit depth.
fn read_png(path: &Path, classes: bool) -> Result<Raster, WorldError> {
    // A regular file (a FIFO or a device is named, not read without end).
    let (mut file, _) = crate::world::format::open_regular(path)?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut file, &mut bytes).map_err(|e| WorldError::io(path, e))?;
    let corrupt = |e: png::DecodingError| WorldError::CorruptImage {
        path: path.to_path_buf(),
        format: "PNG",
        message: e.to_string(),
    };
    let mut decoder = png::Decoder::new_with_limits(
        std::io::Cursor::new(&bytes),
        png::Limits {
            bytes: (MAX_MAP_SAMPLES * 2) as usize,
        },
    );
    // The samples as stored: no palette expanded, no bit depth scaled.
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(corrupt)?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    let (color, bits) = (info.color_type, info.bit_depth as u32);
    let accepted = match color {
        png::ColorType::Grayscale => true,
        png::ColorType::Indexed => classes,
        _ => false,
    };
    if !accepted {
        let kind = match color {
            png::ColorType::Grayscale => "grayscale",
            png::ColorType::Rgb => "RGB",
            png::ColorType::Indexed => "palette (indexed-colour)",
            png::ColorType::GrayscaleAlpha => "grayscale with alpha",
            png::ColorType::Rgba => "RGBA",
        };
        let wanted = if classes {
            "a land-cover map is grayscale (8 or 16 bits) or a palette PNG, one class code a \
             pixel"
        } else {
            "a map is grayscale, 8 or 16 bits, one value a pixel"
        };
        return Err(map_error(
            path,
            format!("the PNG is {bits}-bit {kind}: {wanted}"),
        ));
    }
    if width < 2 || height < 2 || u64::from(width) * u64::from(height) > MAX_MAP_SAMPLES {
        return Err(map_error(
            path,
            format!(
                "{width}x{height} samples: at least 2x2 and at most {MAX_MAP_SAMPLES} (a PNG map \
                 spans the DEM and is read whole: resample it smaller, or give a georeferenced \
                 GeoTIFF, of which only the part over the DEM is read)"
            ),
        ));
    }
    let size = reader.output_buffer_size().ok_or_else(|| {
        map_error(
            path,
            format!("{width}x{height} samples are too many to hold"),
        )
    })?;
    let mut buf = vec![0u8; size];
    let frame = reader.next_frame(&mut buf).map_err(corrupt)?;
    let line = frame.line_size;
    // One sample a pixel: whole bytes (big-endian at 16 bits) or packed, first pixel in the
    // high bits.
    let sample = |row: &[u8], c: usize| -> u32 {
        match bits {
            16 => u32::from(u16::from_be_bytes([row[2 * c], row[2 * c + 1]])),
            8 => u32::from(row[c]),
            b => {
                let per_byte = (8 / b) as usize;
                let shift = 8 - b * (1 + (c % per_byte) as u32);
                u32::from(row[c / per_byte] >> shift) & ((1 << b) - 1)
            }
        }
    };
    let values: Vec<u32> = buf
        .chunks(line)
        .take(height as usize)
        .flat_map(|row| (0..width as usize).map(move |c| sample(row, c)))
        .collect();
    Ok(Raster {
        geo: Georef {
            width,
            height,
            crs: String::new(),
            origin: None,
            pixel_size: None,
        },
        read_bytes: (bytes.len() + buf.len() + 4 * values.len()) as u64,
        values,
        full: f64::from((1u32 << bits) - 1),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A table's syntax error quotes a bounded part of its line (a 1 MiB line of NULs quoted
    /// whole, escaped, made an error of 6 MB).
    #[test]
    fn a_tables_syntax_error_is_bounded() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("t.toml");
        std::fs::write(&file, "\0".repeat((MAX_TABLE_BYTES - 1) as usize)).unwrap();
        let text = CoverTable::load(&file).unwrap_err().to_string();
        assert!(
            text.len() < 1000 && text.contains("t.toml"),
            "{}",
            &text[..1000]
        );
        assert!(text.contains("line 1, column"), "{text}");
    }

    #[test]
    fn the_built_in_tables_read_and_resolve_for_the_baked_grass_types() {
        let types = super::super::paint::default_grass_types();
        for (name, _) in BUILT_IN_TABLES {
            let t = CoverTable::load(Path::new(name)).unwrap();
            assert!(t.classes.len() >= 10, "{name}");
            let r = t.resolve(Path::new(name), &types).unwrap();
            assert_eq!(r.len(), t.classes.len());
            // Water grows nothing and is water; grassland grows meadow.
            let water = t.classes.iter().find(|c| c.name.contains("ater")).unwrap();
            let want = ClassPaint {
                grass_type: 0,
                density: 0,
                material: Material::Water as u8,
            };
            assert_eq!(r[&water.code], want, "{name}");
            let grass = t
                .classes
                .iter()
                .find(|c| c.name.starts_with("Grassland"))
                .unwrap();
            assert_eq!(r[&grass.code].grass_type, 1, "{name}: meadow");
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
            (
                format!("{head}nodata = [1]\n{}", class(1, "meadow", 0.5)),
                "both in nodata and as a [[class]]",
            ),
            (format!("{head}{}", class(1, "meadow", 1.5)), "0..=1"),
            (format!("{head}class = []\n"), "no [[class]]"),
            (
                format!("{head}{}material = \"lava\"\n", class(1, "meadow", 0.5)),
                "material \"lava\" is not one of verdant's materials (default, soil",
            ),
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

    #[test]
    fn the_coordinate_systems_of_land_cover_products_are_known_and_transform_in_radians() {
        use proj4rs::Proj;
        for code in [4326, 4269, 3857, 5070, 32610, 32633, 32733, 26910, 3035] {
            assert!(Proj::from_epsg_code(code).is_ok(), "EPSG:{code}");
        }
        // 45 N on UTM 33N's central meridian (15 E): 0.9996 of the meridian arc, 4,984,944.4 m.
        let (geo, utm) = (
            Proj::from_epsg_code(4326).unwrap(),
            Proj::from_epsg_code(32633).unwrap(),
        );
        assert!(geo.is_latlong() && !utm.is_latlong());
        let (x, y) =
            proj4rs::adaptors::transform_xy(&geo, &utm, 15f64.to_radians(), 45f64.to_radians())
                .unwrap();
        assert!((x - 500_000.0).abs() < 0.01, "{x}");
        assert!((y - 4_982_950.4).abs() < 0.5, "{y}");
        assert_eq!(epsg_code("EPSG:32633, projected (metres)"), Some(32633));
        assert_eq!(epsg_code("projected (metres)"), None);
    }
}
