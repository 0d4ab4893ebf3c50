//! Bakes with a land-cover map: its classes choose the grass where it has data, placed by the
//! maps' georeferencing whatever their size and extent; bad maps and tables are refused by name.

use std::path::{Path, PathBuf};

use glam::DVec2;
use tiff::encoder::{Compression, TiffEncoder, colortype};
use tiff::tags::Tag;
use verdant::bake::{BakeOptions, bake};
use verdant::world::Material;

mod common;

/// The DEM: 65 x 65 samples of 20 m, UTM zone 33N, its top-left corner at these coordinates.
const DEM_SIZE: u32 = 65;
const DEM_CELL: f64 = 20.0;
const DEM_CORNER: [f64; 2] = [400_000.0, 4_101_300.0];
/// The map: 100 x 60 samples of 10 m, its top-left corner here (east of the DEM's, and
/// reaching past the DEM's east edge).
const MAP_SIZE: [u32; 2] = [100, 60];
const MAP_CELL: f64 = 10.0;
const MAP_CORNER: [f64; 2] = [400_300.0, 4_100_900.0];
/// GeoKeys: projected, pixel is area, EPSG `epsg`; or geographic (degrees) for EPSG:4326.
fn keys(epsg: u16) -> Vec<u16> {
    if epsg == 4326 {
        return [
            [1, 1, 0, 3],
            [1024, 0, 1, 2],
            [1025, 0, 1, 1],
            [2048, 0, 1, 4326],
        ]
        .concat();
    }
    [
        [1, 1, 0, 3],
        [1024, 0, 1, 1],
        [1025, 0, 1, 1],
        [3072, 0, 1, epsg],
    ]
    .concat()
}

/// Writes a one-band GeoTIFF of `data` (rows from the north) with its top-left corner at
/// `corner` and cells of `cell` metres in EPSG `epsg`.
fn write_geotiff<C: colortype::ColorType>(
    path: &Path,
    size: [u32; 2],
    cell: [f64; 2],
    corner: [f64; 2],
    epsg: u16,
    data: &[C::Inner],
) where
    [C::Inner]: tiff::encoder::TiffValue,
{
    write_geotiff_as::<C>(
        path,
        size,
        cell,
        corner,
        epsg,
        data,
        Compression::Uncompressed,
        false,
    );
}

/// [`write_geotiff`] with its chunks compressed by `compression` and, with `palette`, as a
/// colour-mapped image (PhotometricInterpretation 3, RGBPalette, and a ColorMap of as many
/// entries as its samples' bits give), as land-cover products are distributed.
#[allow(clippy::too_many_arguments)]
fn write_geotiff_as<C: colortype::ColorType>(
    path: &Path,
    size: [u32; 2],
    cell: [f64; 2],
    corner: [f64; 2],
    epsg: u16,
    data: &[C::Inner],
    compression: Compression,
    palette: bool,
) where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = TiffEncoder::new(&mut file)
        .unwrap()
        .with_compression(compression);
    let mut image = enc.new_image::<C>(size[0], size[1]).unwrap();
    let d = image.encoder();
    if palette {
        // Red, then green, then blue, 16 bits each: an entry's colour from its index.
        let entries = 1usize << C::BITS_PER_SAMPLE[0];
        let colour_map: Vec<u16> = (0..3)
            .flat_map(|band| (0..entries).map(move |i| ((i * 40503 + band * 9973) % 65536) as u16))
            .collect();
        d.write_tag(Tag::PhotometricInterpretation, 3u16).unwrap();
        d.write_tag(Tag::ColorMap, &colour_map[..]).unwrap();
    }
    d.write_tag(Tag::ModelPixelScaleTag, &[cell[0], cell[1], 0.0][..])
        .unwrap();
    d.write_tag(
        Tag::ModelTiepointTag,
        &[0.0, 0.0, 0.0, corner[0], corner[1], 0.0][..],
    )
    .unwrap();
    d.write_tag(Tag::GeoKeyDirectoryTag, &keys(epsg)[..])
        .unwrap();
    image.write_data(data).unwrap();
}

/// A gently sloping DEM (about 3 degrees: grass everywhere).
fn write_dem(dir: &Path) -> PathBuf {
    let n = DEM_SIZE as usize;
    let heights: Vec<i16> = (0..n * n)
        .map(|k| (100.0 + 0.05 * DEM_CELL * (k % n) as f64).round() as i16)
        .collect();
    let path = dir.join("dem.tif");
    write_geotiff::<colortype::GrayI16>(
        &path,
        [DEM_SIZE; 2],
        [DEM_CELL; 2],
        DEM_CORNER,
        32633,
        &heights,
    );
    path
}

/// The map's class at its column `c` and row `r` (from the north): grassland, water and
/// cropland in thirds west to east, nodata in the ten northern rows.
fn class_at(c: u32, r: u32) -> u8 {
    if r < 10 {
        0
    } else if c < 33 {
        30
    } else if c < 66 {
        80
    } else {
        40
    }
}

fn write_map(dir: &Path, epsg: u16, corner: [f64; 2], extra: Option<u8>) -> PathBuf {
    let [w, h] = MAP_SIZE;
    let mut data: Vec<u8> = (0..h)
        .flat_map(|r| (0..w).map(move |c| class_at(c, r)))
        .collect();
    if let Some(code) = extra {
        data[(30 * w + 5) as usize] = code;
    }
    let path = dir.join(format!("cover_{epsg}.tif"));
    write_geotiff::<colortype::Gray8>(&path, MAP_SIZE, [MAP_CELL; 2], corner, epsg, &data);
    path
}

fn opts(dem: &Path, out: &Path, cover: Option<(PathBuf, PathBuf)>) -> BakeOptions {
    BakeOptions {
        dem: dem.to_path_buf(),
        out: out.to_path_buf(),
        name: Some("cover".into()),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        seed: 5,
        land_cover: cover,
        ..Default::default()
    }
}

/// Every finest-level sample inside the DEM: its world position, its grass type and density,
/// and its material byte.
fn finest_samples(world: &Path) -> Vec<(DVec2, u8, u8, u8)> {
    let terrain = common::Terrain::load(world);
    let p = &terrain.world.manifest.pyramid;
    let level = p.stored_levels - 1;
    let extent = terrain.world.manifest.extent_m;
    let mut out = Vec::new();
    for (id, tile) in &terrain.tiles {
        if id.level != level {
            continue;
        }
        for j in p.border..tile.size - p.border {
            for i in p.border..tile.size - p.border {
                let pos = p.sample_position(*id, i, j);
                if pos.x <= extent[0] && pos.y <= extent[1] {
                    let k = tile.index(i, j);
                    out.push((
                        pos,
                        tile.grass_type[k],
                        tile.density[k],
                        tile.material_at(k),
                    ));
                }
            }
        }
    }
    out.sort_by(|a, b| (a.0.x, a.0.y).partial_cmp(&(b.0.x, b.0.y)).unwrap());
    out
}

#[test]
fn a_land_cover_map_paints_its_classes_where_it_has_data_and_the_rule_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    let map = write_map(dir.path(), 32633, MAP_CORNER, None);
    let with = dir.path().join("with");
    let without = dir.path().join("without");
    bake(
        &opts(
            &dem,
            &with,
            Some((map.clone(), PathBuf::from("esa-worldcover"))),
        ),
        &mut |_, _, _| {},
    )
    .unwrap();
    bake(&opts(&dem, &without, None), &mut |_, _, _| {}).unwrap();
    let a = finest_samples(&with);
    let b = finest_samples(&without);
    assert_eq!(a.len(), b.len());
    // The DEM's south-west sample, in the coordinate system.
    let sw = DVec2::new(
        DEM_CORNER[0] + 0.5 * DEM_CELL,
        DEM_CORNER[1] - (f64::from(DEM_SIZE) - 0.5) * DEM_CELL,
    );
    let (mut by_class, mut by_rule) = ([0; 3], 0);
    for ((pos, t, d, m), (_, t0, d0, m0)) in a.iter().zip(&b) {
        assert_eq!(*m0, 0, "no map, no material");
        let model = sw + *pos;
        let c = (model.x - (MAP_CORNER[0] + 0.5 * MAP_CELL)) / MAP_CELL;
        let r = ((MAP_CORNER[1] - 0.5 * MAP_CELL) - model.y) / MAP_CELL;
        let inside = c > -0.5
            && r > -0.5
            && c < f64::from(MAP_SIZE[0]) - 0.5
            && r < f64::from(MAP_SIZE[1]) - 0.5;
        let near_edge = |x: f64, edges: &[f64]| edges.iter().any(|e| (x - e).abs() < 1.5);
        if !inside || (r.round() as u32) < 10 {
            // Outside the map or where it says nodata: the procedural rule, as without it
            // (away from the map's edges, where the nearest sample is ambiguous).
            if !near_edge(r, &[-0.5, 9.5]) && !near_edge(c, &[-0.5, 99.5]) {
                assert_eq!((t, d, m), (t0, d0, &0), "at {pos}");
                by_rule += 1;
            }
            continue;
        }
        if near_edge(c, &[32.5, 65.5]) || near_edge(r, &[9.5]) {
            continue;
        }
        let (want, k) = match class_at(c.round() as u32, r.round() as u32) {
            30 => ((1, 230, Material::Default), 0), // grassland: meadow at 0.9
            80 => ((0, 0, Material::Water), 1),     // water: nothing grows
            40 => ((2, 204, Material::Crops), 2),   // cropland: tall grass at 0.8, on crops
            other => panic!("class {other}"),
        };
        let want = (want.0, want.1, want.2 as u8);
        assert_eq!(
            (*t, *d, *m),
            want,
            "at {pos} (map column {c:.1}, row {r:.1})"
        );
        by_class[k] += 1;
    }
    assert!(by_class.iter().all(|&n| n > 30), "{by_class:?}");
    assert!(by_rule > 500, "{by_rule} samples painted by the rule");
    // The manifest says where the grass came from.
    let manifest = std::fs::read_to_string(with.join("world.toml")).unwrap();
    assert!(
        manifest.contains("land_cover = \"cover_32633.tif\""),
        "{manifest}"
    );
    assert!(
        manifest.contains("ESA WorldCover (esa-worldcover)"),
        "{manifest}"
    );
    // Its tiles carry materials; the world baked without a map has none.
    assert!(manifest.contains("materials = true"), "{manifest}");
    let plain = std::fs::read_to_string(without.join("world.toml")).unwrap();
    assert!(!plain.contains("materials"), "{plain}");
    assert!(with.join("tiles/L0/0_0.material.png").exists());
    assert!(!without.join("tiles/L0/0_0.material.png").exists());
}

#[test]
fn a_map_in_geographic_coordinates_is_reprojected_onto_a_utm_dem() {
    use proj4rs::Proj;
    use proj4rs::adaptors::transform_xy;
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    let (utm, geo) = (
        Proj::from_epsg_code(32633).unwrap(),
        Proj::from_epsg_code(4326).unwrap(),
    );
    // The DEM's south-west sample in UTM, and the class of a UTM point: grassland, water and
    // cropland in bands 400 m wide west to east, nodata north of the DEM's middle row.
    let sw = DVec2::new(
        DEM_CORNER[0] + 0.5 * DEM_CELL,
        DEM_CORNER[1] - (f64::from(DEM_SIZE) - 0.5) * DEM_CELL,
    );
    let class = |p: DVec2| -> u8 {
        let q = p - sw;
        if q.y > 640.0 {
            0
        } else if q.x < 400.0 {
            30
        } else if q.x < 800.0 {
            80
        } else {
            40
        }
    };
    // The map: 0.0002 degree samples (about 16 m by 22 m there) over the DEM and 100 m around
    // it, its corners found by projecting the DEM's.
    let to_geo = |p: DVec2| {
        let (lon, lat) = transform_xy(&utm, &geo, p.x, p.y).unwrap();
        DVec2::new(lon.to_degrees(), lat.to_degrees())
    };
    let span = (f64::from(DEM_SIZE) - 1.0) * DEM_CELL;
    let corners = [
        DVec2::new(-100.0, -100.0),
        DVec2::new(span + 100.0, -100.0),
        DVec2::new(-100.0, span + 100.0),
        DVec2::new(span + 100.0, span + 100.0),
    ]
    .map(|c| to_geo(sw + c));
    let lo = corners.iter().fold(DVec2::MAX, |a, c| a.min(*c));
    let hi = corners.iter().fold(DVec2::MIN, |a, c| a.max(*c));
    let step = 0.0002;
    let size = [
        ((hi.x - lo.x) / step).ceil() as u32,
        ((hi.y - lo.y) / step).ceil() as u32,
    ];
    let mut data = Vec::new();
    for r in 0..size[1] {
        for c in 0..size[0] {
            let lon = lo.x + (f64::from(c) + 0.5) * step;
            let lat = hi.y - (f64::from(r) + 0.5) * step;
            let (x, y) = transform_xy(&geo, &utm, lon.to_radians(), lat.to_radians()).unwrap();
            data.push(class(DVec2::new(x, y)));
        }
    }
    let map = dir.path().join("cover_4326.tif");
    write_geotiff::<colortype::Gray8>(&map, size, [step; 2], [lo.x, hi.y], 4326, &data);
    let out = dir.path().join("geo");
    bake(
        &opts(&dem, &out, Some((map, PathBuf::from("esa-worldcover")))),
        &mut |_, _, _| {},
    )
    .unwrap();
    let mut seen = [0; 4];
    for (pos, t, d, m) in finest_samples(&out) {
        // Away from the bands' borders by more than a map sample.
        let near = |v: f64, edges: &[f64]| edges.iter().any(|e| (v - e).abs() < 30.0);
        if near(pos.x, &[400.0, 800.0]) || near(pos.y, &[640.0]) {
            continue;
        }
        let (want, k) = match class(sw + pos) {
            0 => {
                seen[3] += 1;
                continue; // nodata: the procedural rule
            }
            30 => ((1, 230, 0), 0),
            80 => ((0, 0, Material::Water as u8), 1),
            40 => ((2, 204, Material::Crops as u8), 2),
            other => panic!("class {other}"),
        };
        assert_eq!((t, d, m), want, "at {pos}");
        seen[k] += 1;
    }
    assert!(seen.iter().all(|&n| n > 100), "{seen:?}");

    // The same map inside a larger one, a code no table lists (77) 150 samples around it, as
    // a DEM lies inside an ESA WorldCover tile: only the window over the DEM is read, and it
    // paints the same.
    let pad = 150;
    let wide = [size[0] + 2 * pad, size[1] + 2 * pad];
    let padded: Vec<u8> = (0..wide[1])
        .flat_map(|r| (0..wide[0]).map(move |c| (r, c)))
        .map(|(r, c)| {
            let (c, r) = (c.wrapping_sub(pad), r.wrapping_sub(pad));
            if c < size[0] && r < size[1] {
                data[(r * size[0] + c) as usize]
            } else {
                77
            }
        })
        .collect();
    let tile = dir.path().join("tile_4326.tif");
    let shift = f64::from(pad) * step;
    write_geotiff::<colortype::Gray8>(
        &tile,
        wide,
        [step; 2],
        [lo.x - shift, hi.y + shift],
        4326,
        &padded,
    );
    let out_tile = dir.path().join("geo_tile");
    bake(
        &opts(
            &dem,
            &out_tile,
            Some((tile, PathBuf::from("esa-worldcover"))),
        ),
        &mut |_, _, _| {},
    )
    .unwrap();
    assert_eq!(finest_samples(&out_tile), finest_samples(&out));
}

/// Bakes, into `dir/name`, the DEM with a PNG map spanning it: grassland in its west half,
/// water in its east half (the boundary at x = 640 m).
fn halves_world(dir: &Path, name: &str) -> PathBuf {
    let dem = write_dem(dir);
    let img = image::GrayImage::from_fn(32, 16, |x, _| image::Luma([if x < 16 { 30 } else { 80 }]));
    let png = dir.join("halves.png");
    img.save(&png).unwrap();
    let out = dir.join(name);
    bake(
        &opts(&dem, &out, Some((png, PathBuf::from("esa-worldcover")))),
        &mut |_, _, _| {},
    )
    .unwrap();
    out
}

#[test]
fn a_png_map_spans_the_dem() {
    let dir = tempfile::tempdir().unwrap();
    let out = halves_world(dir.path(), "w");
    let extent = (f64::from(DEM_SIZE) - 1.0) * DEM_CELL;
    let (mut west, mut east) = (0, 0);
    for (pos, t, d, m) in finest_samples(&out) {
        if pos.x < 0.45 * extent {
            assert_eq!((t, d, m), (1, 230, 0), "at {pos}");
            west += 1;
        } else if pos.x > 0.55 * extent {
            assert_eq!((t, d, m), (0, 0, Material::Water as u8), "at {pos}");
            east += 1;
        }
    }
    assert!(west > 500 && east > 500, "{west} {east}");
}

#[test]
fn bad_maps_and_tables_are_refused_naming_the_file_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    let esa = PathBuf::from("esa-worldcover");
    let lawn = dir.path().join("lawn.toml");
    std::fs::write(
        &lawn,
        "name = \"lawns\"\n[[class]]\ncode = 30\nname = \"lawn\"\ngrass = \"lawn\"\ndensity = 1.0\n",
    )
    .unwrap();
    let cases = [
        (
            // The next zone east: reprojected, it lies 600 km away.
            write_map(dir.path(), 32634, MAP_CORNER, None),
            esa.clone(),
            vec!["cover_32634.tif", "does not overlap", "EPSG:32634"],
        ),
        (
            // A user-defined projection: no EPSG code to reproject it by.
            write_map(dir.path(), 32767, MAP_CORNER, None),
            esa.clone(),
            vec![
                "cover_32767.tif",
                "coordinate system",
                "has no EPSG code",
                "EPSG:32633",
            ],
        ),
        (
            {
                let far = dir.path().join("far");
                std::fs::create_dir_all(&far).unwrap();
                write_map(&far, 32633, [500_000.0, 4_000_000.0], None)
            },
            esa.clone(),
            vec!["cover_32633.tif", "does not overlap"],
        ),
        (
            {
                let odd = dir.path().join("odd");
                std::fs::create_dir_all(&odd).unwrap();
                write_map(&odd, 32633, MAP_CORNER, Some(77))
            },
            esa.clone(),
            vec!["cover_32633.tif", "77 (1 samples)", "does not list"],
        ),
        (
            write_map(dir.path(), 32633, MAP_CORNER, None),
            lawn.clone(),
            vec![
                "lawn.toml",
                "\"lawn\"",
                "not one of the world's grass types",
            ],
        ),
        (
            dir.path().join("missing.tif"),
            esa.clone(),
            vec!["missing.tif"],
        ),
        (
            dem.clone(),
            PathBuf::from("no-such-table"),
            vec!["no-such-table", "esa-worldcover, nlcd"],
        ),
    ];
    for (k, (map, table, wants)) in cases.into_iter().enumerate() {
        let out = dir.path().join(format!("out{k}"));
        let e = match bake(&opts(&dem, &out, Some((map, table))), &mut |_, _, _| {}) {
            Ok(_) => panic!("case {k} baked"),
            Err(e) => e.to_string(),
        };
        for w in wants {
            assert!(e.contains(w), "case {k}: {e:?} lacks {w:?}");
        }
        assert!(!out.exists(), "case {k}: nothing written");
    }
}

/// A map's classes as [`class_at`] lays them out, rows from the north, as `T`.
fn map_codes<T>(of: impl Fn(u8) -> T) -> Vec<T> {
    let [w, h] = MAP_SIZE;
    (0..h)
        .flat_map(|r| (0..w).map(move |c| class_at(c, r)))
        .map(of)
        .collect()
}

#[test]
fn a_palette_map_is_read_by_its_indices_as_class_codes() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    let esa = PathBuf::from("esa-worldcover");
    let gray = write_map(dir.path(), 32633, MAP_CORNER, None);
    let baked = |map: PathBuf, name: &str| {
        let out = dir.path().join(name);
        bake(
            &opts(&dem, &out, Some((map, esa.clone()))),
            &mut |_, _, _| {},
        )
        .unwrap();
        finest_samples(&out)
    };
    let want = baked(gray, "gray");
    // 8-bit indices, Deflate; 16-bit indices, LZW (decompressed by verdant itself); both with
    // a colour table whose colours are nothing like the codes.
    let palette8 = dir.path().join("palette8.tif");
    write_geotiff_as::<colortype::Gray8>(
        &palette8,
        MAP_SIZE,
        [MAP_CELL; 2],
        MAP_CORNER,
        32633,
        &map_codes(|c| c),
        Compression::Deflate(Default::default()),
        true,
    );
    let palette16 = dir.path().join("palette16.tif");
    write_geotiff_as::<colortype::Gray16>(
        &palette16,
        MAP_SIZE,
        [MAP_CELL; 2],
        MAP_CORNER,
        32633,
        &map_codes(u16::from),
        Compression::Lzw,
        true,
    );
    assert_eq!(baked(palette8, "palette8"), want, "8-bit palette");
    assert_eq!(baked(palette16, "palette16"), want, "16-bit palette");

    // A palette PNG spans the DEM as a grayscale one does: its indices are the codes.
    let halves = finest_samples(&halves_world(dir.path(), "halves"));
    let png_path = dir.path().join("halves_palette.png");
    let mut encoder = png::Encoder::new(
        std::io::BufWriter::new(std::fs::File::create(&png_path).unwrap()),
        32,
        16,
    );
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_palette(
        (0..256 * 3)
            .map(|i| (i * 37 % 256) as u8)
            .collect::<Vec<u8>>(),
    );
    let indices: Vec<u8> = (0..16)
        .flat_map(|_| (0..32).map(|x| if x < 16 { 30 } else { 80 }))
        .collect();
    let mut writer = encoder.write_header().unwrap();
    writer.write_image_data(&indices).unwrap();
    writer.finish().unwrap();
    assert_eq!(baked(png_path, "halves_palette"), halves, "palette PNG");
}

/// A float density map holding values past the largest scale (a huge number standing in for an
/// undeclared nodata) is refused naming the file: it painted full grass. (Infinities read as
/// nodata, as in a DEM.)
#[test]
fn a_float_density_map_past_every_scale_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    for (name, value, says) in [
        (
            "huge.tif",
            1e30,
            "the value 1000000015047466200000000000000",
        ),
        ("wide.tif", 70000.0, "the value 70000"),
    ] {
        let path = dir.path().join(name);
        let data = map_codes(|_| value);
        write_geotiff::<colortype::Gray32Float>(
            &path,
            MAP_SIZE,
            [MAP_CELL; 2],
            MAP_CORNER,
            32633,
            &data,
        );
        let out = dir.path().join(format!("out_{name}"));
        let mut o = opts(&dem, &out, None);
        o.density_map = Some(path);
        let e = bake(&o, &mut |_, _, _| {}).unwrap_err().to_string();
        assert!(
            e.contains(name) && e.contains("density map") && e.contains(says),
            "{name}: {e}"
        );
        assert!(!out.exists(), "{name}: nothing written");
    }
}

#[test]
fn a_map_of_floats_or_signed_or_wide_integers_is_refused_naming_its_sample_type() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    // The map placed as `write_map` places it, its samples of type `C`.
    fn typed<C: colortype::ColorType>(dir: &Path, name: &str, data: &[C::Inner]) -> PathBuf
    where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let path = dir.join(name);
        write_geotiff::<C>(&path, MAP_SIZE, [MAP_CELL; 2], MAP_CORNER, 32633, data);
        path
    }
    let d = dir.path();
    let cases = [
        // Whole class codes as floats: they were once read as codes.
        (
            typed::<colortype::Gray32Float>(d, "float32.tif", &map_codes(f32::from)),
            "float32",
        ),
        // Values that are no codes: they were once read as nodata, and the map ignored.
        (
            typed::<colortype::Gray32Float>(d, "negative.tif", &map_codes(|_| -30.0)),
            "float32",
        ),
        (
            typed::<colortype::Gray64Float>(d, "nan.tif", &map_codes(|_| f64::NAN)),
            "float64",
        ),
        (
            typed::<colortype::Gray64Float>(d, "huge.tif", &map_codes(|_| 1e300)),
            "float64",
        ),
        // A code no 16 bits hold (once read through f32 as 2147483648).
        (
            typed::<colortype::GrayI32>(d, "int32.tif", &map_codes(|_| i32::MAX)),
            "int32",
        ),
        (
            typed::<colortype::Gray32>(d, "uint32.tif", &map_codes(u32::from)),
            "uint32",
        ),
        (
            typed::<colortype::GrayI16>(d, "int16.tif", &map_codes(i16::from)),
            "int16",
        ),
    ];
    for (map, sample) in cases {
        let name = map.file_name().unwrap().to_string_lossy().into_owned();
        let out = dir.path().join(format!("out_{name}"));
        let e = match bake(
            &opts(&dem, &out, Some((map, PathBuf::from("esa-worldcover")))),
            &mut |_, _, _| {},
        ) {
            Ok(_) => panic!("{name} baked"),
            Err(e) => e.to_string(),
        };
        for w in [
            name.as_str(),
            "land cover",
            &format!("its band is {sample}"),
            "uint8 or uint16",
            "gdal_translate -ot UInt16",
        ] {
            assert!(e.contains(w), "{name}: {e:?} lacks {w:?}");
        }
        assert!(!out.exists(), "{name}: nothing written");
    }
}

#[test]
fn a_density_map_scales_the_cover_and_a_mask_clears_it() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    let save = |name: &str, f: &dyn Fn(u32, u32) -> u8| {
        let path = dir.path().join(name);
        image::GrayImage::from_fn(64, 64, |x, y| image::Luma([f(x, y)]))
            .save(&path)
            .unwrap();
        path
    };
    // Grassland everywhere; full density in the west, half in the east; a road across the
    // middle (rows 30 to 33 from the north).
    let cover = save("cover.png", &|_, _| 30);
    let density = save("density.png", &|x, _| if x < 32 { 255 } else { 128 });
    let mask = save("road.png", &|_, y| u8::from((30..34).contains(&y)));
    let out = dir.path().join("w");
    let mut o = opts(&dem, &out, Some((cover, PathBuf::from("esa-worldcover"))));
    o.density_map = Some(density);
    o.mask = Some(mask);
    bake(&o, &mut |_, _, _| {}).unwrap();
    // A colour picture given as the density map, or as the mask, is refused as that map.
    let colour = dir.path().join("colour.png");
    image::RgbImage::new(8, 8).save(&colour).unwrap();
    for (map, what) in [
        ("density", "density map: the PNG is 8-bit RGB"),
        ("mask", "mask: the PNG is 8-bit RGB"),
    ] {
        let mut bad = opts(&dem, &dir.path().join("bad"), None);
        match map {
            "density" => bad.density_map = Some(colour.clone()),
            _ => bad.mask = Some(colour.clone()),
        }
        let e = bake(&bad, &mut |_, _, _| {}).unwrap_err().to_string();
        assert!(e.contains("colour.png") && e.contains(what), "{e}");
    }
    let extent = (f64::from(DEM_SIZE) - 1.0) * DEM_CELL;
    let half = (230.0f64 * 128.0 / 255.0).round() as u8;
    let mut seen = [0; 3];
    for (pos, t, d, _) in finest_samples(&out) {
        // The maps' column and row from the north.
        let (c, r) = (pos.x / extent * 63.0, 63.0 - pos.y / extent * 63.0);
        if (c - 31.5).abs() < 1.5 || (r - 29.5).abs() < 1.5 || (r - 33.5).abs() < 1.5 {
            continue;
        }
        let want = if (30.0..34.0).contains(&r.round()) {
            seen[2] += 1;
            (0, 0)
        } else if c < 31.5 {
            seen[0] += 1;
            (1, 230)
        } else {
            seen[1] += 1;
            (1, half)
        };
        assert_eq!((t, d), want, "at {pos} (column {c:.1}, row {r:.1})");
    }
    assert!(seen.iter().all(|&n| n > 20), "{seen:?}");
    let manifest = std::fs::read_to_string(out.join("world.toml")).unwrap();
    assert!(
        manifest.contains("density_map = \"density.png\""),
        "{manifest}"
    );
    assert!(manifest.contains("mask = \"road.png\""), "{manifest}");
}

/// A frame over the boundary of two classes shows them: the meadow's green ground on the
/// grassland half, bare ground on the water half (GPU, software Vulkan in CI; from 60 m the
/// ground's colour shows the grass type, the blades being nearer the camera than that).
#[test]
fn a_frame_over_a_class_boundary_shows_the_grassland_green_and_the_water_as_its_cpu_mirror() {
    use verdant::RendererConfig;
    use verdant::camera::Camera;
    use verdant::tools::Scene;
    let dir = tempfile::tempdir().unwrap();
    let out = halves_world(dir.path(), "w");
    let ctx = common::gpu();
    let world = verdant::World::open(&out).unwrap();
    let config = RendererConfig::for_world(&world);
    let (w, h) = (128u32, 72u32);
    let mut scene = Scene::new(&ctx, world, w, h, config).unwrap();
    // Looking straight down from 60 m over the boundary, north up: west on the left.
    let ground = 100.0 + 640.0 / DEM_CELL;
    let camera = Camera::new(glam::DVec3::new(640.0, 640.0, ground + 60.0), 90.0, -89.0);
    scene
        .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
        .unwrap();
    scene.render(&ctx, &camera).unwrap();
    let image = scene.read_image(&ctx).unwrap();
    // Greenness: green over the mean of red and blue, over a band of columns on each side.
    let green = |x0: u32, x1: u32| {
        let mut sum = 0.0;
        for y in 0..h {
            for x in x0..x1 {
                let [r, g, b, _] = image.get_pixel(x, y).0.map(f64::from);
                sum += g - 0.5 * (r + b);
            }
        }
        sum / f64::from((x1 - x0) * h)
    };
    let (west, east) = (green(0, w / 2 - 8), green(w / 2 + 8, w));
    // The water, pixel by pixel, against the CPU mirror of its shading: where each pixel's ray
    // meets the DEM's plane (z = 100 + x / 20) at least 40 m east of the boundary (the classes'
    // border there is drawn from samples 20 m apart), the Fresnel mix of the sky's reflection
    // and the dark body, fogged.
    let light = verdant::terrain::material::SkyLight::of(&scene.world().manifest.sky);
    let inv = camera.view_proj_relative(w as f32 / h as f32).inverse();
    let to_srgb = |c: f32| 255.0 * verdant::tools::metrics::linear_to_srgb(c);
    let (mut n, mut sum, mut worst) = (0u32, 0.0f32, 0.0f32);
    for y in 0..h {
        for x in 0..w {
            let ndc = glam::Vec2::new(
                (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
            );
            let p = inv * glam::Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
            let v = (p.truncate() / p.w).normalize();
            let d = v.as_dvec3();
            // camera + t d on z = 100 + x / 20.
            let c = camera.position;
            let t = (100.0 + c.x / 20.0 - c.z) / (d.z - d.x / 20.0);
            if c.x + t * d.x < 680.0 {
                continue;
            }
            let want = light.fogged(
                verdant::terrain::material::water_color(v, 1.0, &light),
                v,
                (t * d.length()) as f32,
            );
            let got = image.get_pixel(x, y).0;
            for k in 0..3 {
                let e = (to_srgb(want[k]) - f32::from(got[k])).abs();
                sum += e;
                worst = worst.max(e);
            }
            n += 1;
        }
    }
    let mean = sum / (3 * n.max(1)) as f32;
    eprintln!("water against its CPU mirror: {n} pixels, mean error {mean:.2}, worst {worst:.1}");
    if west <= east + 10.0 || n < 500 || mean > 1.0 || worst > 3.0 {
        let p = common::failure_dir().join("land_cover_boundary.png");
        image.save(&p).unwrap();
        panic!(
            "green west {west:.1} against east {east:.1}; water against its CPU mirror over \
             {n} pixels: mean error {mean:.2}, worst {worst:.1} of 255 (frame in {})",
            p.display()
        );
    }
}

/// The committed world made with a land-cover map: its tiles hold every material its map was
/// drawn with (the bay's water, the parcels' crops and soil, the roads, the hills' default
/// ground), and a frame over the shore from its tour renders on software Vulkan.
#[test]
fn the_baylands_world_carries_its_materials_and_renders() {
    use verdant::RendererConfig;
    use verdant::tools::Scene;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/baylands");
    let terrain = common::Terrain::load(&dir);
    assert!(terrain.world.manifest.materials);
    let mut counts = [0usize; verdant::world::MATERIAL_COUNT];
    for tile in terrain.tiles.values() {
        for &m in &tile.material {
            counts[usize::from(m)] += 1;
        }
    }
    for m in [
        Material::Default,
        Material::Soil,
        Material::Crops,
        Material::Water,
        Material::Road,
    ] {
        assert!(counts[m as usize] > 1000, "{m}: {counts:?}");
    }
    let ctx = common::gpu();
    let world = terrain.world.clone();
    let camera = verdant::camera::sample_path(&world.manifest.paths[0], 0.0);
    let config = RendererConfig::for_world(&world);
    let (w, h) = (96u32, 54u32);
    let mut scene = Scene::new(&ctx, world, w, h, config).unwrap();
    assert!(
        scene
            .warm_up(&ctx, &camera, std::time::Duration::from_secs(60))
            .unwrap()
    );
    scene.render(&ctx, &camera).unwrap();
    let image = scene.read_image(&ctx).unwrap();
    // The lower half is ground (greens and browns), not sky: its blue is below its red or green.
    let (mut ground, mut n) = (0, 0);
    for y in h / 2..h {
        for x in 0..w {
            let [r, g, b, _] = image.get_pixel(x, y).0;
            ground += usize::from(b < r.max(g));
            n += 1;
        }
    }
    if ground * 10 < n * 9 {
        let p = common::failure_dir().join("baylands_tour.png");
        image.save(&p).unwrap();
        panic!("{ground} of {n} ground pixels (frame in {})", p.display());
    }
}

/// Writes the tags a one-band uint8 Deflate GeoTIFF map shares (its size, sample type and
/// compression, and its georeferencing: samples of `cell` m, the top-left corner at `corner`,
/// UTM zone 33N) beside the chunk tags already written, and finishes it.
fn finish_map<W: std::io::Write + std::io::Seek>(
    mut dir: tiff::encoder::DirectoryEncoder<'_, W, tiff::encoder::TiffKindStandard>,
    size: [u32; 2],
    cell: f64,
    corner: [f64; 2],
) {
    dir.write_tag(Tag::ImageWidth, size[0]).unwrap();
    dir.write_tag(Tag::ImageLength, size[1]).unwrap();
    dir.write_tag(Tag::BitsPerSample, 8u16).unwrap();
    dir.write_tag(Tag::Compression, 8u16).unwrap();
    dir.write_tag(Tag::PhotometricInterpretation, 1u16).unwrap();
    dir.write_tag(Tag::SamplesPerPixel, 1u16).unwrap();
    dir.write_tag(Tag::ModelPixelScaleTag, &[cell, cell, 0.0][..])
        .unwrap();
    dir.write_tag(
        Tag::ModelTiepointTag,
        &[0.0, 0.0, 0.0, corner[0], corner[1], 0.0][..],
    )
    .unwrap();
    dir.write_tag(Tag::GeoKeyDirectoryTag, &keys(32633)[..])
        .unwrap();
    dir.finish().unwrap();
}

/// Writes a one-band uint8 GeoTIFF of samples `sample(column, row)` (row 0 north) in square
/// tiles of `tile` samples, each compressed with Deflate, as land-cover products are (ESA
/// WorldCover's tiles are 36000 x 36000 samples in tiles of 1024). A tile that holds the same
/// samples as the one before it is compressed once, so that a large map of one value is small.
fn write_tiled_map(
    path: &Path,
    size: [u32; 2],
    tile: u32,
    cell: f64,
    corner: [f64; 2],
    sample: &dyn Fn(u32, u32) -> u8,
) {
    use std::io::Write;
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = TiffEncoder::new(&mut file).unwrap();
    let mut dir = enc.image_directory().unwrap();
    let (mut offsets, mut counts) = (Vec::new(), Vec::new());
    let (mut last_raw, mut last_packed) = (Vec::new(), Vec::new());
    for ty in 0..size[1].div_ceil(tile) {
        for tx in 0..size[0].div_ceil(tile) {
            let mut raw = Vec::with_capacity((tile * tile) as usize);
            for r in 0..tile {
                for c in 0..tile {
                    let (x, y) = (tx * tile + c, ty * tile + r);
                    let inside = x < size[0] && y < size[1];
                    raw.push(if inside { sample(x, y) } else { 0 });
                }
            }
            if raw != last_raw {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
                z.write_all(&raw).unwrap();
                (last_raw, last_packed) = (raw, z.finish().unwrap());
            }
            offsets.push(dir.write_data(&last_packed[..]).unwrap() as u32);
            counts.push(last_packed.len() as u32);
        }
    }
    dir.write_tag(Tag::TileWidth, tile).unwrap();
    dir.write_tag(Tag::TileLength, tile).unwrap();
    dir.write_tag(Tag::TileOffsets, &offsets[..]).unwrap();
    dir.write_tag(Tag::TileByteCounts, &counts[..]).unwrap();
    finish_map(dir, size, cell, corner);
}

/// A 512 x 512 map whose samples over the DEM (its columns and rows 224..=288) are ESA
/// WorldCover classes in a varied pattern, and beyond 20 samples around them a code no table
/// lists (77): read whole, the map would be refused.
const BIG_MAP: u32 = 512;
const BIG_FOOTPRINT: [u32; 2] = [224, 288];
fn big_map_code(c: u32, r: u32) -> u8 {
    let [lo, hi] = BIG_FOOTPRINT;
    let near = |v: u32| v + 20 >= lo && v <= hi + 20;
    if !near(c) || !near(r) {
        return 77;
    }
    [10, 20, 30, 40, 50, 60, 80, 90, 0][((c / 7 + r / 5) % 9) as usize]
}

/// The big map's top-left corner: its sample (224, 224) is the DEM's north-west sample, with
/// samples of the DEM's size (20 m).
fn big_map_corner() -> [f64; 2] {
    let off = f64::from(BIG_FOOTPRINT[0]) * DEM_CELL;
    [DEM_CORNER[0] - off, DEM_CORNER[1] + off]
}

#[test]
fn a_map_larger_than_the_limit_is_read_by_the_window_over_the_dem() {
    use verdant::bake::cover::{CoverMap, CoverTable, MapWindow};
    let dir = tempfile::tempdir().unwrap();
    let dem_path = write_dem(dir.path());
    let big = dir.path().join("big.tif");
    write_tiled_map(
        &big,
        [BIG_MAP; 2],
        64,
        DEM_CELL,
        big_map_corner(),
        &big_map_code,
    );
    // The same map cropped by hand to 92 x 92 samples around the DEM (in strips, uncompressed).
    let (first, side) = (210u32, 92u32);
    let cropped: Vec<u8> = (first..first + side)
        .flat_map(|r| (first..first + side).map(move |c| big_map_code(c, r)))
        .collect();
    assert!(!cropped.contains(&77));
    let crop = dir.path().join("crop.tif");
    let shift = f64::from(first) * DEM_CELL;
    let [x, y] = big_map_corner();
    write_geotiff::<colortype::Gray8>(
        &crop,
        [side; 2],
        [DEM_CELL; 2],
        [x + shift, y - shift],
        32633,
        &cropped,
    );

    // With a limit of 10,000 samples (the map holds 262,144), it is read by its window: the
    // DEM's footprint and 2 samples around it, 69 x 69 samples, all that is held.
    let dem = verdant::world::Dem::load(&dem_path).unwrap();
    let esa = PathBuf::from("esa-worldcover");
    let table = CoverTable::load(&esa).unwrap();
    let types = verdant::bake::default_grass_types();
    let map = CoverMap::load_within(&big, &dem, &table, &esa, &types, 10_000).unwrap();
    let want = MapWindow {
        map_size: [BIG_MAP; 2],
        first: [222, 222],
        size: [69, 69],
    };
    assert_eq!(map.window(), want);
    // (Read whole it would be refused as well: it holds code 77, which the table lacks.) The
    // map cropped by hand gives the same window, from its strips.
    let crop_window = CoverMap::load_within(&crop, &dem, &table, &esa, &types, 10_000)
        .unwrap()
        .window();
    assert_eq!(crop_window.first, [12, 12]);
    assert_eq!(crop_window.size, want.size);

    // A bake with the whole map paints as one with the map cropped by hand.
    let baked = |map: &Path, name: &str| {
        let out = dir.path().join(name);
        bake(
            &opts(&dem_path, &out, Some((map.to_path_buf(), esa.clone()))),
            &mut |_, _, _| {},
        )
        .unwrap();
        finest_samples(&out)
    };
    let (whole, by_hand) = (baked(&big, "big"), baked(&crop, "crop"));
    assert_eq!(whole, by_hand);
    // And as the crop stored south row first (a ModelTransformation with rows going north):
    // its window is read from the rows as stored.
    let south_up = dir.path().join("crop_south_up.tif");
    {
        let rows: Vec<u8> = cropped
            .chunks(side as usize)
            .rev()
            .flatten()
            .copied()
            .collect();
        let south = y - shift - f64::from(side) * DEM_CELL;
        let m = [
            DEM_CELL,
            0.0,
            0.0,
            x + shift,
            0.0,
            DEM_CELL,
            0.0,
            south,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1.0,
        ];
        let mut file = std::io::BufWriter::new(std::fs::File::create(&south_up).unwrap());
        let mut enc = TiffEncoder::new(&mut file).unwrap();
        let mut image = enc.new_image::<colortype::Gray8>(side, side).unwrap();
        let d = image.encoder();
        d.write_tag(Tag::ModelTransformationTag, &m[..]).unwrap();
        d.write_tag(Tag::GeoKeyDirectoryTag, &keys(32633)[..])
            .unwrap();
        image.write_data(&rows).unwrap();
    }
    assert_eq!(baked(&south_up, "south_up"), whole);
    // The classes painted: water where the map says 80.
    let water = whole
        .iter()
        .filter(|s| s.3 == Material::Water as u8)
        .count();
    assert!(water > 100, "{water} samples of water");
}

#[test]
fn a_window_over_the_limit_is_refused_naming_the_map_the_window_and_how_to_crop_it() {
    use verdant::bake::cover::{CoverMap, CoverTable};
    let dir = tempfile::tempdir().unwrap();
    let dem_path = write_dem(dir.path());
    // 128 x 128 samples of 10 m over the DEM exactly: the window is the whole map.
    let map = dir.path().join("spanning.tif");
    write_tiled_map(&map, [128; 2], 32, 10.0, DEM_CORNER, &|c, _| {
        [30, 80][c as usize % 2]
    });
    let dem = verdant::world::Dem::load(&dem_path).unwrap();
    let esa = PathBuf::from("esa-worldcover");
    let table = CoverTable::load(&esa).unwrap();
    let types = verdant::bake::default_grass_types();
    let e = match CoverMap::load_within(&map, &dem, &table, &esa, &types, 10_000) {
        Ok(m) => panic!("read a window of {:?}", m.window()),
        Err(e) => e.to_string(),
    };
    for w in [
        "spanning.tif",
        "land cover",
        "window of 128x128 samples",
        "of its 128x128",
        "10000",
        "crop the map",
    ] {
        assert!(e.contains(w), "{e:?} lacks {w:?}");
    }
    // Within the limit it is read, whole.
    let m = CoverMap::load_within(&map, &dem, &table, &esa, &types, 128 * 128).unwrap();
    assert_eq!(m.window().size, [128, 128]);
}

#[test]
fn a_palette_geotiff_is_refused_as_a_dem_or_a_density_map() {
    let dir = tempfile::tempdir().unwrap();
    let dem = write_dem(dir.path());
    let n = DEM_SIZE as usize;
    let indices: Vec<u8> = (0..n * n).map(|k| (k % 200) as u8).collect();
    let palette = |name: &str, compression: Compression| {
        let path = dir.path().join(name);
        write_geotiff_as::<colortype::Gray8>(
            &path,
            [DEM_SIZE; 2],
            [DEM_CELL; 2],
            DEM_CORNER,
            32633,
            &indices,
            compression,
            true,
        );
        path
    };
    let lzw = palette("palette_lzw.tif", Compression::Lzw);
    let deflate = palette(
        "palette_deflate.tif",
        Compression::Deflate(Default::default()),
    );
    let cases = [
        (opts(&lzw, &dir.path().join("o1"), None), "palette_lzw.tif"),
        (
            opts(&deflate, &dir.path().join("o2"), None),
            "palette_deflate.tif",
        ),
        (
            BakeOptions {
                density_map: Some(lzw.clone()),
                ..opts(&dem, &dir.path().join("o3"), None)
            },
            "palette_lzw.tif",
        ),
        (
            BakeOptions {
                mask: Some(deflate.clone()),
                ..opts(&dem, &dir.path().join("o4"), None)
            },
            "palette_deflate.tif",
        ),
    ];
    for (k, (o, name)) in cases.into_iter().enumerate() {
        let e = match bake(&o, &mut |_, _, _| {}) {
            Ok(_) => panic!("case {k} baked"),
            Err(e) => e.to_string(),
        };
        for w in [
            name,
            "palette image",
            "class indices",
            "not heights or values",
        ] {
            assert!(e.contains(w), "case {k}: {e:?} lacks {w:?}");
        }
        assert!(!o.out.exists(), "case {k}: nothing written");
    }
}

/// A density map and a mask of 16448 x 16448 samples of 20 m (more than the 2^28 a map is read
/// whole with), tiled, the DEM over their samples 8000..=8064 of each axis. Within 20 samples
/// of the DEM they vary; beyond, they would clear all grass (density 0, mask 1).
const HUGE_MAP: u32 = 16448;
const HUGE_FOOTPRINT: [u32; 2] = [8000, 8064];
fn near_huge_footprint(c: u32, r: u32) -> bool {
    let [lo, hi] = HUGE_FOOTPRINT;
    let near = |v: u32| v + 20 >= lo && v <= hi + 20;
    near(c) && near(r)
}
fn huge_density(c: u32, r: u32) -> u8 {
    if near_huge_footprint(c, r) {
        ((c * 13 + r * 7) % 256) as u8
    } else {
        0
    }
}
fn huge_mask(c: u32, r: u32) -> u8 {
    if near_huge_footprint(c, r) {
        u8::from((8030..8034).contains(&r) || (8040..8042).contains(&c))
    } else {
        1
    }
}

/// The huge density map and mask (tiled, Deflate), and the same cropped by hand to samples
/// 7980..=8084 of each axis (uncompressed strips): density, mask, cropped density, cropped
/// mask.
fn write_huge_maps(dir: &Path) -> [PathBuf; 4] {
    let off = f64::from(HUGE_FOOTPRINT[0]) * DEM_CELL;
    let corner = [DEM_CORNER[0] - off, DEM_CORNER[1] + off];
    let (first, side) = (7980u32, 105u32);
    let shift = f64::from(first) * DEM_CELL;
    let crop_corner = [corner[0] + shift, corner[1] - shift];
    let mut paths = Vec::new();
    for (name, f) in [
        ("density", &huge_density as &dyn Fn(u32, u32) -> u8),
        ("mask", &huge_mask),
    ] {
        let whole = dir.join(format!("huge_{name}.tif"));
        write_tiled_map(&whole, [HUGE_MAP; 2], 512, DEM_CELL, corner, f);
        let cropped: Vec<u8> = (first..first + side)
            .flat_map(|r| (first..first + side).map(move |c| f(c, r)))
            .collect();
        let crop = dir.join(format!("crop_{name}.tif"));
        write_geotiff::<colortype::Gray8>(
            &crop,
            [side; 2],
            [DEM_CELL; 2],
            crop_corner,
            32633,
            &cropped,
        );
        paths.push((whole, crop));
    }
    let [(density, crop_density), (mask, crop_mask)] = <[_; 2]>::try_from(paths).unwrap();
    [density, mask, crop_density, crop_mask]
}

#[test]
fn a_density_map_and_a_mask_larger_than_a_map_read_whole_are_read_by_the_window_over_the_dem() {
    use verdant::bake::cover::{MapWindow, ValueMap};
    let dir = tempfile::tempdir().unwrap();
    let dem_path = write_dem(dir.path());
    let [density, mask, crop_density, crop_mask] = write_huge_maps(dir.path());
    // A bake with the whole maps paints as one with the maps cropped by hand.
    let baked = |maps: Option<(&Path, &Path)>, name: &str| {
        let out = dir.path().join(name);
        let mut o = opts(&dem_path, &out, None);
        if let Some((density, mask)) = maps {
            o.density_map = Some(density.to_path_buf());
            o.mask = Some(mask.to_path_buf());
        }
        bake(&o, &mut |_, _, _| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
        finest_samples(&out)
    };
    let whole = baked(Some((&density, &mask)), "whole");
    let by_hand = baked(Some((&crop_density, &crop_mask)), "by_hand");
    assert_eq!(whole, by_hand);
    // The maps did their work: they scaled and cleared the grass, and left some.
    let plain = baked(None, "plain");
    let changed = whole.iter().zip(&plain).filter(|(a, b)| a != b).count();
    let grown = whole.iter().filter(|s| s.2 > 0).count();
    assert!(
        changed * 2 > whole.len(),
        "{changed} of {} changed",
        whole.len()
    );
    assert!(
        grown * 4 > whole.len(),
        "{grown} of {} grow grass",
        whole.len()
    );

    // Under a limit of 10,000 samples (the maps hold 270 million) each is read by its window:
    // the DEM's footprint and 2 samples around it, 69 x 69 samples, all that is held.
    let dem = verdant::world::Dem::load(&dem_path).unwrap();
    let want = MapWindow {
        map_size: [HUGE_MAP; 2],
        first: [7998, 7998],
        size: [69, 69],
    };
    let maps = [
        ValueMap::density_within(&density, &dem, 10_000).unwrap(),
        ValueMap::mask_within(&mask, &dem, 10_000).unwrap(),
    ];
    let crops = [
        ValueMap::density_within(&crop_density, &dem, 10_000).unwrap(),
        ValueMap::mask_within(&crop_mask, &dem, 10_000).unwrap(),
    ];
    for (map, crop) in maps.iter().zip(&crops) {
        assert_eq!(map.window(), want);
        assert_eq!(crop.window().first, [18, 18]);
        assert_eq!(crop.window().size, want.size);
    }
    // They give the values of the maps cropped by hand at every sample of the DEM, and between.
    let extent = f64::from(DEM_SIZE - 1) * DEM_CELL;
    let mut seen = [0usize; 4];
    for j in 0..2 * DEM_SIZE - 1 {
        for i in 0..2 * DEM_SIZE - 1 {
            let p = DVec2::new(f64::from(i), f64::from(j)) * (DEM_CELL / 2.0);
            assert!(p.x <= extent && p.y <= extent);
            for (k, (map, crop)) in maps.iter().zip(&crops).enumerate() {
                let v = map.at(p);
                assert_eq!(v, crop.at(p), "map {k} at {p}");
                let v = v.unwrap_or_else(|| panic!("map {k} at {p}: no value"));
                seen[2 * k + usize::from(v > 0.5)] += 1;
            }
        }
    }
    // Both maps hold values above and below a half over the DEM.
    assert!(seen.iter().all(|&n| n > 500), "{seen:?}");
}

#[test]
fn a_density_map_or_mask_window_over_the_limit_is_refused_naming_it_the_window_and_how_to_crop() {
    use verdant::bake::cover::ValueMap;
    let dir = tempfile::tempdir().unwrap();
    let dem_path = write_dem(dir.path());
    let dem = verdant::world::Dem::load(&dem_path).unwrap();
    // 128 x 128 samples of 10 m over the DEM exactly: the window is the whole map.
    let map = dir.path().join("spanning.tif");
    write_tiled_map(&map, [128; 2], 32, 10.0, DEM_CORNER, &|c, r| {
        ((c + r) % 256) as u8
    });
    type Read =
        fn(&Path, &verdant::world::Dem, u64) -> Result<ValueMap, verdant::world::WorldError>;
    for (read, what) in [
        (ValueMap::density_within as Read, "density map"),
        (ValueMap::mask_within, "mask"),
    ] {
        let e = match read(&map, &dem, 10_000) {
            Ok(m) => panic!("{what}: read a window of {:?}", m.window()),
            Err(e) => e.to_string(),
        };
        for w in [
            "spanning.tif",
            what,
            "window of 128x128 samples",
            "of its 128x128",
            "10000",
            "crop the map",
        ] {
            assert!(e.contains(w), "{what}: {e:?} lacks {w:?}");
        }
        // Within the limit it is read, whole.
        let m = read(&map, &dem, 128 * 128).unwrap();
        assert_eq!(m.window().size, [128, 128], "{what}");
    }
}

/// Writes a one-band uint8 GeoTIFF `size` samples of `cell` metres whose top-left corner is
/// `corner`, in strips of one row each, every row `value` (Deflate, the one compressed row
/// stored once and named by every strip).
fn write_striped_map(path: &Path, size: [u32; 2], cell: f64, corner: [f64; 2], value: u8) {
    use std::io::Write;
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = TiffEncoder::new(&mut file).unwrap();
    let mut dir = enc.image_directory().unwrap();
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(9));
    z.write_all(&vec![value; size[0] as usize]).unwrap();
    let packed = z.finish().unwrap();
    let offset = dir.write_data(&packed[..]).unwrap() as u32;
    dir.write_tag(Tag::RowsPerStrip, 1u32).unwrap();
    dir.write_tag(Tag::StripOffsets, &vec![offset; size[1] as usize][..])
        .unwrap();
    dir.write_tag(
        Tag::StripByteCounts,
        &vec![packed.len() as u32; size[1] as usize][..],
    )
    .unwrap();
    finish_map(dir, size, cell, corner);
}

#[test]
fn a_map_in_strips_far_wider_than_the_dem_is_read_by_its_window_and_counted_in_the_plan() {
    use verdant::bake::cover::ValueMap;
    let dir = tempfile::tempdir().unwrap();
    let dem_path = write_dem(dir.path());
    let dem = verdant::world::Dem::load(&dem_path).unwrap();
    // 2^24 samples a row (one strip each, 16 MiB decoded), of which the DEM's footprint
    // needs 69; the map starts 4 samples west and north of the DEM's north-west sample.
    let width = 1u32 << 24;
    let corner = [
        DEM_CORNER[0] - 4.0 * DEM_CELL,
        DEM_CORNER[1] + 4.0 * DEM_CELL,
    ];
    let map = dir.path().join("wide.tif");
    write_striped_map(&map, [width, DEM_SIZE + 8], DEM_CELL, corner, 128);
    assert!(std::fs::metadata(&map).unwrap().len() < 2 << 20);
    // The window is the footprint and 2 samples around it; the values are the map's.
    let m = ValueMap::density(&map, &dem).unwrap();
    assert_eq!(m.window().first, [2, 2]);
    assert_eq!(m.window().size, [DEM_SIZE + 4; 2]);
    let extent = f64::from(DEM_SIZE - 1) * DEM_CELL;
    for p in [DVec2::ZERO, DVec2::splat(extent), DVec2::new(extent, 0.0)] {
        assert_eq!(m.at(p), Some(128.0 / 255.0), "at {p}");
    }
    // What the read took beside the window, a strip decoded, is counted: it is at least the
    // strip, and no more than a few of them.
    let strip = u64::from(width);
    assert!(
        (strip..4 * strip).contains(&m.read_bytes()),
        "{} bytes for strips of {strip}",
        m.read_bytes()
    );
    assert_eq!(m.held_bytes(), u64::from(DEM_SIZE + 4).pow(2) * 4);
    // A bake's limit too small for that is refused by the plan, naming the least that plans;
    // that least bakes.
    let mut o = opts(&dem_path, &dir.path().join("out"), None);
    o.density_map = Some(map.clone());
    o.memory_mib = 48;
    let e = bake(&o, &mut |_, _, _| {}).unwrap_err().to_string();
    assert!(
        e.contains("--memory-mib 48") && e.contains("at least"),
        "{e}"
    );
    let need: u64 = e
        .split("at least ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no need named: {e}"));
    assert!(need * (1 << 20) > 48 * (1 << 20) + strip, "{need} MiB: {e}");
    o.memory_mib = need;
    bake(&o, &mut |_, _, _| {}).unwrap_or_else(|e| panic!("at {need} MiB: {e}"));
}
