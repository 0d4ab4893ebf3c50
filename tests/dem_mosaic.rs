//! Many DEM files as one: adjacent SRTM `.hgt` tiles and a GDAL VRT of GeoTIFF tiles joined on
//! their georeferencing, with no step at the joins, baked into one world; files that do not
//! join are refused, naming them.

use std::path::{Path, PathBuf};

use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::Tag;
use verdant::bake::{BakeOptions, bake};
use verdant::world::DemOptions;
use verdant::world::mosaic::load_dems;

mod common;

/// A smooth landscape over longitude and latitude (degrees), whole metres.
fn landscape(lon: f64, lat: f64) -> i16 {
    (300.0 + 180.0 * (lon * 2.1).sin() * (lat * 1.7).cos() + 60.0 * (lon * 7.3 + lat * 5.1).sin())
        .round() as i16
}

/// Writes the 3-arc-second `.hgt` tile whose south-west corner is (`lon`, `lat`), from
/// [`landscape`]: 1201 samples a side, rows from the north, sharing its edges with its
/// neighbours.
fn write_hgt(dir: &Path, lon: i32, lat: i32) -> PathBuf {
    let name = format!(
        "{}{:02}{}{:03}.hgt",
        if lat >= 0 { 'N' } else { 'S' },
        lat.abs(),
        if lon >= 0 { 'E' } else { 'W' },
        lon.abs()
    );
    let mut bytes = Vec::with_capacity(1201 * 1201 * 2);
    for r in 0..1201 {
        for c in 0..1201 {
            let x = f64::from(lon) + f64::from(c) / 1200.0;
            let y = f64::from(lat + 1) - f64::from(r) / 1200.0;
            bytes.extend_from_slice(&landscape(x, y).to_be_bytes());
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// The largest change between neighbouring samples of `heights` (rows of `w`), along rows and
/// along columns, skipping column `skip_col` and row `skip_row` (the joins) on either side.
fn steps(heights: &[f32], w: usize, h: usize, seam_col: usize, seam_row: usize) -> (f32, f32) {
    let (mut inside, mut seam) = (0.0f32, 0.0f32);
    for r in 0..h {
        for c in 1..w {
            let d = (heights[r * w + c] - heights[r * w + c - 1]).abs();
            if c == seam_col || c == seam_col + 1 {
                seam = seam.max(d);
            } else {
                inside = inside.max(d);
            }
        }
    }
    for r in 1..h {
        for c in 0..w {
            let d = (heights[r * w + c] - heights[(r - 1) * w + c]).abs();
            if r == seam_row || r == seam_row + 1 {
                seam = seam.max(d);
            } else {
                inside = inside.max(d);
            }
        }
    }
    (inside, seam)
}

fn small_bake(dem: &Path, more: Vec<PathBuf>, out: &Path, cell: f64) {
    bake(
        &BakeOptions {
            dem: dem.to_path_buf(),
            more_dems: more,
            out: out.to_path_buf(),
            name: Some("joined".into()),
            cell_size_m: Some(cell),
            tile_cells: 32,
            stored_levels: 2,
            ..Default::default()
        },
        &mut |_, _, _| {},
    )
    .unwrap();
}

#[test]
fn four_adjacent_hgt_tiles_bake_into_one_world_with_no_step_at_the_joins() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("srtm");
    std::fs::create_dir_all(&tiles).unwrap();
    for (lon, lat) in [(-123, 37), (-122, 37), (-123, 38), (-122, 38)] {
        write_hgt(&tiles, lon, lat);
    }
    // The folder, joined: 2401 samples a side over two degrees, every sample the landscape's.
    let dem = load_dems(std::slice::from_ref(&tiles), &DemOptions::default()).unwrap();
    assert_eq!((dem.width, dem.height), (2401, 2401));
    assert_eq!(dem.origin, Some([-123.0, 37.0]));
    assert!(dem.source.starts_with("4 files joined"), "{}", dem.source);
    assert!(dem.crs.contains("4326"), "{}", dem.crs);
    for (c, r) in [(0, 0), (1200, 1200), (1201, 17), (2400, 2400), (600, 1900)] {
        let want = landscape(-123.0 + c as f64 / 1200.0, 39.0 - r as f64 / 1200.0);
        assert_eq!(dem.heights[r * 2401 + c], f32::from(want), "at ({c}, {r})");
    }
    // No step at the joins (column and row 1200): the change across them is within the
    // change between neighbouring samples anywhere else.
    let (inside, seam) = steps(&dem.heights, 2401, 2401, 1200, 1200);
    assert!(
        seam <= inside,
        "step at the joins {seam} m, elsewhere at most {inside} m"
    );
    // Cells in metres at the joined grid's centre latitude (38 degrees N).
    assert!((dem.cell_ns_m - 92.5).abs() < 0.5, "{}", dem.cell_ns_m);
    assert!((dem.cell_ew_m - 73.0).abs() < 0.5, "{}", dem.cell_ew_m);

    // The same files listed one by one bake into one world.
    let files: Vec<PathBuf> = ["N37W123", "N37W122", "N38W123", "N38W122"]
        .iter()
        .map(|n| tiles.join(format!("{n}.hgt")))
        .collect();
    let out = dir.path().join("world");
    small_bake(&files[0], files[1..].to_vec(), &out, 1000.0);
    let world = verdant::World::open(&out).unwrap();
    let [ex, ey] = world.manifest.extent_m;
    assert!((ex - 2400.0 * dem.cell_ew_m).abs() < 1.0, "{ex}");
    assert!((ey - 2400.0 * dem.cell_ns_m).abs() < 1.0, "{ey}");
    let toml = std::fs::read_to_string(out.join("world.toml")).unwrap();
    assert!(toml.contains("4 files joined"), "{toml}");
}

/// GeoKeys: projected, pixel is area, EPSG `epsg`.
fn keys(epsg: u16) -> Vec<u16> {
    [
        [1, 1, 0, 3],
        [1024, 0, 1, 1],
        [1025, 0, 1, 1],
        [3072, 0, 1, epsg],
    ]
    .concat()
}

/// Writes a GeoTIFF tile of `n` x `n` samples of 20 m in EPSG `epsg`, its north-west sample's
/// corner at (`x0`, `y0`), heights from `f` of the sample's centre (plus `offset`).
fn write_tile(path: &Path, epsg: u16, n: u32, x0: f64, y0: f64, offset: f32) {
    write_tile_with(path, epsg, n, 20.0, [x0, y0], offset, None);
}

/// [`write_tile`] with samples of `cell` metres, its north-west corner at `[x0, y0]`, and one
/// sample (column, row from the north) set to a height of its own.
fn write_tile_with(
    path: &Path,
    epsg: u16,
    n: u32,
    cell: f64,
    [x0, y0]: [f64; 2],
    offset: f32,
    spike: Option<(u32, u32, f32)>,
) {
    let data: Vec<f32> = (0..n * n)
        .map(|k| {
            if let Some((sc, sr, h)) = spike
                && k == sr * n + sc
            {
                return h;
            }
            let (c, r) = (f64::from(k % n), f64::from(k / n));
            let (x, y) = (x0 + (c + 0.5) * cell, y0 - (r + 0.5) * cell);
            (100.0 + 40.0 * (x / 300.0).sin() + 25.0 * (y / 170.0).cos()) as f32 + offset
        })
        .collect();
    let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = TiffEncoder::new(&mut file).unwrap();
    let mut image = enc.new_image::<colortype::Gray32Float>(n, n).unwrap();
    let d = image.encoder();
    d.write_tag(Tag::ModelPixelScaleTag, &[cell, cell, 0.0][..])
        .unwrap();
    d.write_tag(Tag::ModelTiepointTag, &[0.0, 0.0, 0.0, x0, y0, 0.0][..])
        .unwrap();
    d.write_tag(Tag::GeoKeyDirectoryTag, &keys(epsg)[..])
        .unwrap();
    image.write_data(&data).unwrap();
}

/// Four 33 x 33 tiles of 20 m in a 2 x 2 grid, sharing their edge samples (640 m apart).
fn write_four(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for (i, j) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let p = dir.join(format!("tile_{i}_{j}.tif"));
        write_tile(
            &p,
            32633,
            33,
            400_000.0 + 640.0 * f64::from(i),
            4_100_000.0 - 640.0 * f64::from(j),
            0.0,
        );
        out.push(p);
    }
    out
}

fn write_vrt(path: &Path, sources: &[&str]) {
    let mut xml = String::from(
        "<VRTDataset rasterXSize=\"65\" rasterYSize=\"65\">\n  <SRS>EPSG:32633</SRS>\n  \
         <VRTRasterBand dataType=\"Float32\" band=\"1\">\n",
    );
    for s in sources {
        xml.push_str(&format!(
            "    <SimpleSource>\n      <SourceFilename relativeToVRT=\"1\">{s}</SourceFilename>\n      \
             <SourceBand>1</SourceBand>\n    </SimpleSource>\n"
        ));
    }
    xml.push_str("  </VRTRasterBand>\n</VRTDataset>\n");
    std::fs::write(path, xml).unwrap();
}

#[test]
fn a_vrt_of_geotiff_tiles_joins_them_with_no_step_and_bakes() {
    let dir = tempfile::tempdir().unwrap();
    write_four(dir.path());
    let vrt = dir.path().join("mosaic.vrt");
    write_vrt(
        &vrt,
        &[
            "tile_0_0.tif",
            "tile_1_0.tif",
            "tile_0_1.tif",
            "tile_1_1.tif",
        ],
    );
    let dem = load_dems(std::slice::from_ref(&vrt), &DemOptions::default()).unwrap();
    assert_eq!((dem.width, dem.height), (65, 65));
    assert_eq!((dem.cell_ew_m, dem.cell_ns_m), (20.0, 20.0));
    let (inside, seam) = steps(&dem.heights, 65, 65, 32, 32);
    assert!(
        seam <= inside,
        "step at the joins {seam} m, elsewhere at most {inside} m"
    );
    // Every sample is the landscape at its centre, whichever tile gave it.
    let whole = dir.path().join("whole.tif");
    write_tile(&whole, 32633, 65, 400_000.0, 4_100_000.0, 0.0);
    let one = verdant::world::Dem::load(&whole).unwrap();
    assert_eq!(dem.origin, one.origin);
    let worst = dem
        .heights
        .iter()
        .zip(&one.heights)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "{worst}");
    let out = dir.path().join("world");
    small_bake(&vrt, Vec::new(), &out, 20.0);
    verdant::World::open(&out).unwrap();
}

#[test]
fn files_that_do_not_join_are_refused_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let four = write_four(dir.path());
    let case = |name: &str, files: Vec<PathBuf>, wants: &[&str]| {
        let e = load_dems(&files, &DemOptions::default())
            .map(|_| ())
            .unwrap_err()
            .to_string();
        for w in wants {
            assert!(e.contains(w), "{name}: {e:?} lacks {w:?}");
        }
        // The baker refuses them too, and writes nothing.
        let out = dir.path().join(format!("out_{name}"));
        let baked = bake(
            &BakeOptions {
                dem: files[0].clone(),
                more_dems: files[1..].to_vec(),
                out: out.clone(),
                ..Default::default()
            },
            &mut |_, _, _| {},
        );
        assert!(baked.is_err(), "{name}");
        assert!(!out.exists(), "{name}: nothing written");
    };
    // Another coordinate system.
    let other = dir.path().join("zone34.tif");
    write_tile(&other, 32634, 33, 400_640.0, 4_100_000.0, 0.0);
    case(
        "crs",
        vec![four[0].clone(), other.clone()],
        &["zone34.tif", "EPSG:32634", "tile_0_0.tif", "EPSG:32633"],
    );
    // Overlapping, 5 m apart.
    let shifted = dir.path().join("shifted.tif");
    write_tile(&shifted, 32633, 33, 400_320.0, 4_100_000.0, 5.0);
    case(
        "overlap",
        vec![four[0].clone(), shifted],
        &[
            "shifted.tif",
            "tile_0_0.tif",
            "differ by more than 1 m",
            "5.0 m",
        ],
    );
    // Far apart.
    let far = dir.path().join("far.tif");
    write_tile(&far, 32633, 33, 410_000.0, 4_100_000.0, 0.0);
    case(
        "gap",
        vec![four[0].clone(), far],
        &["gap", "tile_0_0.tif", "far.tif", "not neighbours"],
    );
    // So far apart that no integer counts the samples between (the count is named, as a
    // number too large).
    for (name, x0, count) in [
        ("beyond", 1e300, "5.000e298 x 33 samples"),
        ("past_u64", 20.0 * 2f64.powi(63), "9.223e18 x 33 samples"),
    ] {
        let beyond = dir.path().join(format!("{name}.tif"));
        write_tile(&beyond, 32633, 33, x0, 4_100_000.0, 0.0);
        case(
            name,
            vec![four[0].clone(), beyond],
            &["tile_0_0.tif", "files joined make", count, "a DEM may have"],
        );
    }
    // A VRT that names more files than a mosaic may join: refused as it is read.
    let many = dir.path().join("many.vrt");
    let names: Vec<String> = (0..5000).map(|i| format!("t{i}.tif")).collect();
    write_vrt(&many, &names.iter().map(String::as_str).collect::<Vec<_>>());
    case(
        "many",
        vec![many],
        &["many.vrt", "names more than 4096 DEM files"],
    );
    // A DEM without georeferencing.
    let png = common::write_dem(
        dir.path(),
        "plain",
        [33, 33],
        [20.0, 20.0],
        [0.0, 1.0],
        |_, _| 100.0,
    );
    case(
        "plain",
        vec![four[0].clone(), png],
        &["plain.png", "no georeferencing"],
    );
    // A VRT that names nothing, and one that is not XML.
    let empty = dir.path().join("empty.vrt");
    write_vrt(&empty, &[]);
    case("empty", vec![empty], &["empty.vrt", "names no source file"]);
    let junk = dir.path().join("junk.vrt");
    std::fs::write(&junk, "not xml at all <").unwrap();
    case("junk", vec![junk], &["junk.vrt", "not a VRT"]);
    // A VRT of VRTs (itself among them).
    let nested = dir.path().join("nested.vrt");
    write_vrt(&nested, &["nested.vrt"]);
    case(
        "nested",
        vec![nested],
        &["nested.vrt", "is itself a VRT", "DEM files"],
    );
    // A folder of DEMs with one that is not a regular file: named, not skipped.
    #[cfg(unix)]
    {
        let folder = dir.path().join("with_fifo");
        std::fs::create_dir(&folder).unwrap();
        std::fs::copy(&four[0], folder.join("tile_0_0.tif")).unwrap();
        let fifo = folder.join("N37W122.hgt");
        common::mkfifo(&fifo);
        case(
            "fifo",
            vec![folder],
            &["N37W122.hgt", "not a regular file (a FIFO)"],
        );
    }
}

#[test]
fn bake_takes_the_dem_repeated_on_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let four = write_four(dir.path());
    let mut args = vec!["bake".to_owned()];
    for f in &four {
        args.extend(["--dem".to_owned(), f.to_str().unwrap().to_owned()]);
    }
    args.extend(
        [
            "--out",
            "w",
            "--cell-size",
            "20",
            "--tile-cells",
            "32",
            "--levels",
            "2",
        ]
        .map(str::to_owned),
    );
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = common::verdant(&args, dir.path());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let world = verdant::World::open(&dir.path().join("w")).unwrap();
    assert_eq!(world.manifest.extent_m, [1280.0, 1280.0]);
}

/// A mosaic of more files than the process may hold open bakes: its files are opened when read
/// and only a few kept open (one descriptor a file ran out at the usual limit of 1024).
#[cfg(unix)]
#[test]
fn a_mosaic_of_more_files_than_open_descriptors_bakes() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("tiles");
    std::fs::create_dir(&tiles).unwrap();
    // 20 x 15 tiles of 5 x 5 samples of 20 m, sharing their edge samples (80 m apart).
    for i in 0..20 {
        for j in 0..15 {
            write_tile(
                &tiles.join(format!("t_{i:02}_{j:02}.tif")),
                32633,
                5,
                400_000.0 + 80.0 * f64::from(i),
                4_100_000.0 - 80.0 * f64::from(j),
                0.0,
            );
        }
    }
    let run = std::process::Command::new("sh")
        .arg("-c")
        .arg(
            "ulimit -n 128 && exec \"$0\" bake --dem tiles --out w --cell-size 20 \
             --tile-cells 16 --levels 2",
        )
        .arg(env!("CARGO_BIN_EXE_verdant"))
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let world = verdant::World::open(&dir.path().join("w")).unwrap();
    assert_eq!(world.manifest.extent_m, [1600.0, 1200.0]);
    let source = world.manifest.source.as_ref().unwrap();
    assert_eq!(source.samples, [81, 61]);
}

/// The peak memory a `verdant bake` run printed, MiB.
fn bake_peak_mib(dir: &Path, out: &str, limit: Option<&str>) -> f64 {
    let mut args = vec![
        "bake",
        "--dem",
        "srtm",
        "--out",
        out,
        "--name",
        "joined",
        "--cell-size",
        "75",
        "--tile-cells",
        "256",
        "--levels",
        "2",
    ];
    if let Some(limit) = limit {
        args.extend(["--memory-mib", limit]);
    }
    let run = common::verdant(&args, dir);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("memory: peak "))
        .unwrap_or_else(|| panic!("no memory line in {stdout}"));
    line.split(' ').next().unwrap().parse().unwrap()
}

/// A mosaic of four tiles (5.8 million samples, 7 million cells of 75 m) bakes within a limit
/// well below what its bake takes when the limit lets it hold the finest grid whole, and into
/// the same tiles.
#[test]
fn a_mosaic_bakes_within_its_memory_limit_into_the_same_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("srtm");
    std::fs::create_dir_all(&tiles).unwrap();
    for (lon, lat) in [(-123, 37), (-122, 37), (-123, 38), (-122, 38)] {
        write_hgt(&tiles, lon, lat);
    }
    let whole = bake_peak_mib(dir.path(), "whole", None);
    let limit = 160.0;
    let bounded = bake_peak_mib(dir.path(), "bounded", Some("160"));
    assert!(
        bounded <= limit,
        "peak {bounded} MiB over the limit of {limit}"
    );
    assert!(
        whole > 1.5 * limit,
        "held whole the bake takes {whole} MiB: the limit of {limit} tests nothing"
    );
    let a = common::read_all_files(&dir.path().join("whole/tiles"));
    let b = common::read_all_files(&dir.path().join("bounded/tiles"));
    assert_eq!(a.len(), b.len());
    assert!(a.len() > 100, "{} tile files", a.len());
    for (name, bytes) in &a {
        assert!(b.get(name) == Some(bytes), "{name:?} differs");
    }
}

/// Every tile of a world baked into `out`, read through its checks (stamps included), for
/// comparing bakes from other inputs sample for sample: their files differ only in the stamps
/// (each bake's id is a fingerprint of its inputs, a DEM's address among them).
fn world_files(
    out: &Path,
) -> std::collections::BTreeMap<verdant::world::TileId, verdant::world::TileData> {
    let world = verdant::World::open(out).unwrap();
    assert!(world.manifest.bake_id.is_some());
    world
        .stored_tiles()
        .map(|id| (id, world.load_tile(id).unwrap()))
        .collect()
}

/// DEMs over HTTP: a GeoTIFF at an `http://` address, and a VRT whose sources are addresses
/// (GDAL's `/vsicurl/` names among them), read with range requests, bake into the same tiles
/// as the same files on disk; a server that does not answer range requests, and an address
/// with no file behind it, are refused naming the address.
#[test]
fn geotiffs_over_http_bake_like_the_files_on_disk() {
    let dir = tempfile::tempdir().unwrap();
    let served = dir.path().join("served");
    std::fs::create_dir_all(&served).unwrap();
    write_four(&served);
    let whole = served.join("whole.tif");
    write_tile(&whole, 32633, 65, 400_000.0, 4_100_000.0, 0.0);
    let server = verdant::tools::serve::WorldServer::start_folder(&served, "127.0.0.1:0").unwrap();
    let url = server.url();
    let url = url.trim_end_matches('/');

    // One GeoTIFF.
    let (local, remote) = (dir.path().join("local"), dir.path().join("remote"));
    small_bake(&whole, Vec::new(), &local, 20.0);
    small_bake(
        Path::new(&format!("{url}/whole.tif")),
        Vec::new(),
        &remote,
        20.0,
    );
    assert_eq!(world_files(&local), world_files(&remote));
    let toml = std::fs::read_to_string(remote.join("world.toml")).unwrap();
    assert!(toml.contains("whole.tif"), "{toml}");

    // A VRT of the four tiles, on disk and over HTTP.
    let names = [
        "tile_0_0.tif",
        "tile_1_0.tif",
        "tile_0_1.tif",
        "tile_1_1.tif",
    ];
    let vrt = dir.path().join("local.vrt");
    let on_disk: Vec<String> = names
        .iter()
        .map(|n| served.join(n).to_str().unwrap().to_owned())
        .collect();
    write_vrt(
        &vrt,
        &on_disk.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    let vrt_http = dir.path().join("http.vrt");
    let addresses: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            if k % 2 == 0 {
                format!("/vsicurl/{url}/{n}")
            } else {
                format!("{url}/{n}")
            }
        })
        .collect();
    write_vrt(
        &vrt_http,
        &addresses.iter().map(String::as_str).collect::<Vec<_>>(),
    );
    let (a, b) = (dir.path().join("vrt_local"), dir.path().join("vrt_http"));
    small_bake(&vrt, Vec::new(), &a, 20.0);
    small_bake(&vrt_http, Vec::new(), &b, 20.0);
    assert_eq!(world_files(&a), world_files(&b));

    // Refusals name the address.
    let missing = format!("{url}/nothing.tif");
    let err = bake(
        &BakeOptions {
            dem: PathBuf::from(&missing),
            out: dir.path().join("never"),
            ..Default::default()
        },
        &mut |_, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains(&missing) && err.contains("404"), "{err}");
    assert!(!dir.path().join("never").exists());

    // A VRT at an address reads its sources beside it, over HTTP, and never a path on this
    // machine that it names.
    write_vrt(&served.join("beside.vrt"), &names);
    let c = dir.path().join("vrt_beside");
    small_bake(
        Path::new(&format!("{url}/beside.vrt")),
        Vec::new(),
        &c,
        20.0,
    );
    assert_eq!(world_files(&a), world_files(&c));
    // Named as a path, or as an absolute path "relative" to the VRT.
    for relative in ["0", "1"] {
        let text = std::fs::read_to_string(served.join("beside.vrt"))
            .unwrap()
            .replacen(
                "relativeToVRT=\"1\">tile_0_0.tif",
                &format!("relativeToVRT=\"{relative}\">/etc/passwd"),
                1,
            );
        std::fs::write(served.join("local.vrt"), text).unwrap();
        let err = bake(
            &BakeOptions {
                dem: PathBuf::from(format!("{url}/local.vrt")),
                out: dir.path().join("never"),
                ..Default::default()
            },
            &mut |_, _, _| {},
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("/etc/passwd") && err.contains("never by a path on this machine"),
            "relativeToVRT={relative}: {err}"
        );
        assert!(!dir.path().join("never").exists());
    }
}

/// A signal while a request for the DEM is in flight stops the bake as a stop (status 130,
/// "cancelled"), once the request's deadline has passed, not as the request's failure.
#[test]
fn a_bake_stopped_while_a_request_hangs_ends_as_stopped() {
    let dir = tempfile::tempdir().unwrap();
    // A server that takes the connection and never answers.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/dem.tif", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for stream in listener.incoming().flatten() {
            held.push(stream);
        }
    });
    let out = dir.path().join("never");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["bake", "--dem", &url, "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let killed = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let start = std::time::Instant::now();
    let status = child.wait().unwrap();
    let mut stderr = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("cancelled"), "{stderr}");
    assert!(start.elapsed() < std::time::Duration::from_secs(30));
    assert!(!out.exists());
}

/// An address verdant cannot fetch is refused for what it is: https (no TLS in this build), and
/// other schemes, which are not taken for files that are not there.
#[test]
fn addresses_of_other_schemes_are_refused_saying_why() {
    let dir = tempfile::tempdir().unwrap();
    for (address, says) in [
        ("https://example.com/dem.tif", "https is not built in"),
        ("HTTPS://example.com/dem.tif", "https is not built in"),
        ("ftp://127.0.0.1/dem.tif", "the scheme ftp://"),
        ("s3://bucket/dem.tif", "the scheme s3://"),
    ] {
        let err = bake(
            &BakeOptions {
                dem: PathBuf::from(address),
                out: dir.path().join("never"),
                ..Default::default()
            },
            &mut |_, _, _| {},
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains(address) && err.contains(says), "{err}");
        assert!(!err.contains("not found"), "{err}");
    }
}

/// A DEM at an address is known by its length and validators as its server gives them: the
/// bake id of the same address changes with the file behind it, and a file replaced while it
/// is read in ranges is refused rather than read as a mix of its two versions.
#[test]
fn a_remote_dem_that_changes_changes_the_bake_id_and_is_refused_mid_read() {
    let dir = tempfile::tempdir().unwrap();
    let served = dir.path().join("served");
    std::fs::create_dir_all(&served).unwrap();
    let tif = served.join("dem.tif");
    write_tile(&tif, 32633, 65, 400_000.0, 4_100_000.0, 0.0);
    let server = verdant::tools::serve::WorldServer::start_folder(&served, "127.0.0.1:0").unwrap();
    let url = format!("{}dem.tif", server.url());
    let opts = BakeOptions {
        dem: PathBuf::from(&url),
        out: dir.path().join("never"),
        ..Default::default()
    };
    let files = vec![PathBuf::from(&url)];
    let id = |opts: &BakeOptions| verdant::bake::shard::bake_id(opts, &files).unwrap();
    let before = id(&opts);
    assert_eq!(id(&opts), before, "the same file, the same id");
    let file = verdant::stream::http::RangeFile::open(&url, Default::default()).unwrap();
    let head = file.read_at(0, 8).unwrap();

    // The same size, other heights, another modification time: another ETag.
    let set_time = |secs: u64| {
        std::fs::File::options()
            .write(true)
            .open(&tif)
            .unwrap()
            .set_modified(std::time::UNIX_EPOCH + std::time::Duration::from_secs(secs))
            .unwrap();
    };
    let len = std::fs::metadata(&tif).unwrap().len();
    write_tile(&tif, 32633, 65, 400_000.0, 4_100_000.0, 7.0);
    assert_eq!(std::fs::metadata(&tif).unwrap().len(), len);
    set_time(1_000_000_000);
    assert_ne!(
        id(&opts),
        before,
        "another file behind the address, another id"
    );
    let err = file.read_at(0, 8).unwrap_err().to_string();
    assert!(
        err.contains(&url) && err.contains("changed while it was read") && err.contains("ETag"),
        "{err}"
    );
    // Read afresh, it reads.
    let again = verdant::stream::http::RangeFile::open(&url, Default::default()).unwrap();
    assert_eq!(again.read_at(0, 8).unwrap(), head);
}

/// A height beyond a planet's in one file of a mosaic is blamed on that file, at its own
/// column and row, not on the first file given.
#[test]
fn an_implausible_height_in_a_mosaic_names_the_file_it_is_in() {
    let dir = tempfile::tempdir().unwrap();
    let mut four = write_four(dir.path());
    // One sample of the south-east tile 300,000 km up.
    write_tile_with(
        &four[3],
        32633,
        33,
        20.0,
        [400_640.0, 4_099_360.0],
        0.0,
        Some((5, 7, 3e8)),
    );
    let err = bake(
        &BakeOptions {
            dem: four.remove(0),
            more_dems: four,
            out: dir.path().join("out"),
            ..Default::default()
        },
        &mut |_, _, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("column 5, row 7 of") && err.contains("tile_1_1.tif is outside"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists());
}

/// Files of one spacing whose grids are offset by part of a cell are refused saying by how much
/// and how to align them (they were called "not neighbours" with a gap between them), and files
/// on the same grid join.
#[test]
fn files_whose_grids_are_offset_by_part_of_a_cell_are_refused_saying_so() {
    let dir = tempfile::tempdir().unwrap();
    let tile = |name: &str, x0: f64, y0: f64| {
        let path = dir.path().join(name);
        write_tile_with(&path, 32633, 64, 10.0, [x0, y0], 0.0, None);
        path
    };
    let a = tile("s_a.tif", 500_000.0, 4_100_000.0);
    let b = tile("s_b.tif", 500_635.0, 4_100_000.0);
    let e = load_dems(&[a.clone(), b], &DemOptions::default())
        .map(|_| ())
        .unwrap_err()
        .to_string();
    for want in [
        "s_b.tif",
        "s_a.tif",
        "offset",
        "0.5 of a cell east-west (5 m)",
        "cannot be joined sample for sample",
        "gdalwarp -tr 10 10 -te 500640 4099360 501270 4100000",
        "-tap",
    ] {
        assert!(e.contains(want), "{e:?} lacks {want:?}");
    }
    assert!(!e.contains("gap"), "{e}");
    // A quarter of a cell north-south, in a file that would otherwise join.
    let c = tile("s_c.tif", 500_630.0, 4_100_002.5);
    let e = load_dems(&[a.clone(), c], &DemOptions::default())
        .map(|_| ())
        .unwrap_err()
        .to_string();
    assert!(e.contains("0.25 of a cell north-south (2.5 m)"), "{e}");
    assert!(!e.contains("east-west"), "{e}");
    // On the same grid, sharing a column, they join.
    let d = tile("s_d.tif", 500_630.0, 4_100_000.0);
    let dem = load_dems(&[a, d], &DemOptions::default()).unwrap();
    assert_eq!((dem.width, dem.height), (127, 64));
}
