//! DEM formats: GeoTIFFs (each sample type, strips and tiles, each compression and predictor,
//! projected and geographic, with nodata) and SRTM `.hgt` tiles, written by hand in the tests,
//! read and bake to the same heights as the same grid given as a 16-bit PNG with a sidecar,
//! within the PNG's quantisation; bad files are refused with errors naming the file, by the
//! library and by the command line.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use verdant::bake::{BakeOptions, bake};
use verdant::world::{
    Dem, DemFormat, DemOptions, TileId, World, WorldError, dem::metres_per_degree,
};

// ---------------------------------------------------------------------------------------------
// A GeoTIFF writer for the tests: every layout, sample type, compression and predictor that the
// reader supports, and the broken variants it must refuse.

#[derive(Clone, Copy, Debug, PartialEq)]
enum Sample {
    I16,
    U16,
    I32,
    F32,
    F64,
}

impl Sample {
    const ALL: [Sample; 5] = [
        Sample::I16,
        Sample::U16,
        Sample::I32,
        Sample::F32,
        Sample::F64,
    ];

    fn bytes(self) -> usize {
        match self {
            Sample::I16 | Sample::U16 => 2,
            Sample::I32 | Sample::F32 => 4,
            Sample::F64 => 8,
        }
    }

    /// TIFF SampleFormat: 1 unsigned, 2 signed, 3 float.
    fn format(self) -> u16 {
        match self {
            Sample::U16 => 1,
            Sample::I16 | Sample::I32 => 2,
            Sample::F32 | Sample::F64 => 3,
        }
    }

    fn is_float(self) -> bool {
        self.format() == 3
    }

    /// The height as this type stores it.
    fn quantise(self, h: f64) -> f64 {
        match self {
            Sample::I16 | Sample::U16 | Sample::I32 => h.round(),
            Sample::F32 => f64::from(h as f32),
            Sample::F64 => h,
        }
    }

    /// The bit pattern of `v` in this type, in the low bits.
    fn bits(self, v: f64) -> u64 {
        match self {
            Sample::I16 => (v as i16) as u16 as u64,
            Sample::U16 => v as u16 as u64,
            Sample::I32 => (v as i32) as u32 as u64,
            Sample::F32 => u64::from((v as f32).to_bits()),
            Sample::F64 => v.to_bits(),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Layout {
    Strips { rows: u32 },
    Tiles { width: u32, height: u32 },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Compression {
    None,
    Deflate,
    Lzw,
    PackBits,
    Zstd,
    /// A code the reader does not support; the data is written uncompressed.
    Other(u16),
}

impl Compression {
    fn code(self) -> u16 {
        match self {
            Compression::None => 1,
            Compression::Lzw => 5,
            Compression::Deflate => 8,
            Compression::PackBits => 32773,
            Compression::Zstd => 50000,
            Compression::Other(c) => c,
        }
    }

    fn compress(self, data: &[u8]) -> Vec<u8> {
        match self {
            Compression::None | Compression::Other(_) => data.to_vec(),
            Compression::Deflate => {
                use std::io::Write;
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
                z.write_all(data).unwrap();
                z.finish().unwrap()
            }
            Compression::Lzw => {
                let mut out = Vec::new();
                let mut encoder =
                    weezl::encode::Encoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8);
                encoder.into_vec(&mut out).encode_all(data).status.unwrap();
                out
            }
            Compression::PackBits => packbits(data),
            Compression::Zstd => {
                ruzstd::encoding::compress_to_vec(data, ruzstd::encoding::CompressionLevel::Fastest)
            }
        }
    }
}

/// PackBits: runs of 3..=128 equal bytes as (1 - n, byte), everything else as literal runs of
/// up to 128 bytes.
fn packbits(data: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut literal: Vec<u8> = Vec::new();
    let flush = |literal: &mut Vec<u8>, out: &mut Vec<u8>| {
        for chunk in literal.chunks(128) {
            out.push((chunk.len() - 1) as u8);
            out.extend_from_slice(chunk);
        }
        literal.clear();
    };
    let mut i = 0;
    while i < data.len() {
        let run = data[i..]
            .iter()
            .take(128)
            .take_while(|&&b| b == data[i])
            .count();
        if run >= 3 {
            flush(&mut literal, &mut out);
            out.push((257 - run) as u8);
            out.push(data[i]);
            i += run;
        } else {
            literal.push(data[i]);
            i += 1;
        }
    }
    flush(&mut literal, &mut out);
    out
}

/// Where the grid lies.
#[derive(Clone, Debug, PartialEq)]
enum Geo {
    /// No GeoTIFF tags at all.
    None,
    /// ModelPixelScale + ModelTiepoint (top-left corner) and a GeoKey directory.
    Scale {
        scale: [f64; 2],
        corner: [f64; 2],
        keys: Vec<[u16; 4]>,
    },
    /// ModelTransformation and a GeoKey directory.
    Matrix { m: [f64; 16], keys: Vec<[u16; 4]> },
}

/// GeoKeys of a projected grid with EPSG code `epsg` in the linear unit `unit` (9001 metre,
/// 9002 foot).
fn projected_keys(epsg: u16, unit: u16) -> Vec<[u16; 4]> {
    vec![
        [1024, 0, 1, 1],
        [1025, 0, 1, 1],
        [3072, 0, 1, epsg],
        [3076, 0, 1, unit],
    ]
}

/// GeoKeys of a geographic grid in degrees, WGS 84.
fn geographic_keys() -> Vec<[u16; 4]> {
    vec![
        [1024, 0, 1, 2],
        [1025, 0, 1, 1],
        [2048, 0, 1, 4326],
        [2054, 0, 1, 9102],
    ]
}

#[derive(Clone, Debug)]
struct TiffSpec {
    sample: Sample,
    layout: Layout,
    compression: Compression,
    predictor: u16,
    big_endian: bool,
    /// Bands (samples per pixel), each holding the same heights.
    bands: u16,
    geo: Geo,
    nodata: Option<String>,
    /// Write the directory before the image data (as cloud-optimised GeoTIFFs do).
    ifd_first: bool,
    /// Width and height written in the directory, if not the grid's own.
    claimed_size: Option<[u32; 2]>,
    /// Tile width and length written in the directory, if not the layout's own.
    claimed_tile: Option<[u32; 2]>,
}

impl TiffSpec {
    fn new(sample: Sample, layout: Layout, compression: Compression) -> TiffSpec {
        TiffSpec {
            sample,
            layout,
            compression,
            predictor: 1,
            big_endian: false,
            bands: 1,
            geo: Geo::Scale {
                scale: CELL,
                corner: [500_000.0, 4_200_000.0],
                keys: projected_keys(32610, 9001),
            },
            nodata: None,
            ifd_first: false,
            claimed_size: None,
            claimed_tile: None,
        }
    }
}

/// One IFD entry: tag, type, count and the value's bytes (in the file's byte order).
struct Entry {
    tag: u16,
    ty: u16,
    count: u32,
    bytes: Vec<u8>,
}

struct Endian(bool);

impl Endian {
    fn u16(&self, v: u16) -> [u8; 2] {
        if self.0 {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }
    fn u32(&self, v: u32) -> [u8; 4] {
        if self.0 {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    }
    /// The low `n` bytes of `v`.
    fn sample(&self, v: u64, n: usize) -> Vec<u8> {
        let le = &v.to_le_bytes()[..n];
        if self.0 {
            le.iter().rev().copied().collect()
        } else {
            le.to_vec()
        }
    }
    fn shorts(&self, tag: u16, v: &[u16]) -> Entry {
        Entry {
            tag,
            ty: 3,
            count: v.len() as u32,
            bytes: v.iter().flat_map(|&x| self.u16(x)).collect(),
        }
    }
    fn longs(&self, tag: u16, v: &[u32]) -> Entry {
        Entry {
            tag,
            ty: 4,
            count: v.len() as u32,
            bytes: v.iter().flat_map(|&x| self.u32(x)).collect(),
        }
    }
    fn doubles(&self, tag: u16, v: &[f64]) -> Entry {
        Entry {
            tag,
            ty: 12,
            count: v.len() as u32,
            bytes: v
                .iter()
                .flat_map(|&x| self.sample(x.to_bits(), 8))
                .collect(),
        }
    }
    fn ascii(&self, tag: u16, s: &str) -> Entry {
        let mut bytes = s.as_bytes().to_vec();
        bytes.push(0);
        Entry {
            tag,
            ty: 2,
            count: bytes.len() as u32,
            bytes,
        }
    }
}

/// Encodes one chunk (a strip or a tile) of `w` samples a row: predictor, then compression.
fn encode_chunk(spec: &TiffSpec, rows: &[Vec<u64>], e: &Endian) -> Vec<u8> {
    let n = spec.sample.bytes();
    let mask = if n == 8 {
        u64::MAX
    } else {
        (1u64 << (8 * n)) - 1
    };
    let bands = usize::from(spec.bands);
    let mut raw = Vec::new();
    for row in rows {
        let mut row: Vec<u64> = row
            .iter()
            .flat_map(|&v| std::iter::repeat_n(v, bands))
            .collect();
        match spec.predictor {
            1 => row.iter().for_each(|&v| raw.extend(e.sample(v, n))),
            2 => {
                for i in (bands..row.len()).rev() {
                    row[i] = row[i].wrapping_sub(row[i - bands]) & mask;
                }
                row.iter().for_each(|&v| raw.extend(e.sample(v, n)));
            }
            3 => {
                // Byte planes, most significant first, then byte differences along the row.
                let count = row.len();
                let mut planes = vec![0u8; count * n];
                for (i, &v) in row.iter().enumerate() {
                    for k in 0..n {
                        planes[k * count + i] = (v >> (8 * (n - 1 - k))) as u8;
                    }
                }
                for i in (1..planes.len()).rev() {
                    planes[i] = planes[i].wrapping_sub(planes[i - 1]);
                }
                raw.extend(planes);
            }
            p => panic!("predictor {p}"),
        }
    }
    spec.compression.compress(&raw)
}

/// Writes `heights` (row 0 north, `width` a row, NaN for nodata written as the nodata value)
/// as a TIFF by `spec`.
fn write_tiff(path: &Path, spec: &TiffSpec, width: u32, height: u32, heights: &[f64]) {
    let e = Endian(spec.big_endian);
    let nodata_value: Option<f64> = spec.nodata.as_ref().map(|s| s.parse().unwrap());
    let bits = |v: f64| -> u64 {
        let v = if v.is_nan() {
            nodata_value.expect("NaN height without nodata")
        } else {
            v
        };
        spec.sample.bits(v)
    };
    let at = |c: u32, r: u32| -> u64 {
        if c < width && r < height {
            bits(heights[(r * width + c) as usize])
        } else {
            0 // tile padding
        }
    };
    let mut chunks: Vec<Vec<u8>> = Vec::new();
    match spec.layout {
        Layout::Strips { rows } => {
            for r0 in (0..height).step_by(rows as usize) {
                let rows: Vec<Vec<u64>> = (r0..(r0 + rows).min(height))
                    .map(|r| (0..width).map(|c| at(c, r)).collect())
                    .collect();
                chunks.push(encode_chunk(spec, &rows, &e));
            }
        }
        Layout::Tiles {
            width: tw,
            height: th,
        } => {
            for ty in 0..height.div_ceil(th) {
                for tx in 0..width.div_ceil(tw) {
                    let rows: Vec<Vec<u64>> = (0..th)
                        .map(|r| (0..tw).map(|c| at(tx * tw + c, ty * th + r)).collect())
                        .collect();
                    chunks.push(encode_chunk(spec, &rows, &e));
                }
            }
        }
    }

    let [cw, ch] = spec.claimed_size.unwrap_or([width, height]);
    let bands = usize::from(spec.bands);
    let mut entries = vec![
        e.longs(256, &[cw]),
        e.longs(257, &[ch]),
        e.shorts(258, &vec![8 * spec.sample.bytes() as u16; bands]),
        e.shorts(259, &[spec.compression.code()]),
        e.shorts(262, &[1]),
        e.shorts(277, &[spec.bands]),
        e.shorts(284, &[1]),
        e.shorts(339, &vec![spec.sample.format(); bands]),
    ];
    if spec.predictor != 1 {
        entries.push(e.shorts(317, &[spec.predictor]));
    }
    let (offsets_tag, counts_tag) = match spec.layout {
        Layout::Strips { rows } => {
            entries.push(e.longs(278, &[rows]));
            (273, 279)
        }
        Layout::Tiles { width, height } => {
            let [width, height] = spec.claimed_tile.unwrap_or([width, height]);
            entries.push(e.longs(322, &[width]));
            entries.push(e.longs(323, &[height]));
            (324, 325)
        }
    };
    let keys = match &spec.geo {
        Geo::None => None,
        Geo::Scale {
            scale,
            corner,
            keys,
        } => {
            entries.push(e.doubles(33550, &[scale[0], scale[1], 0.0]));
            entries.push(e.doubles(33922, &[0.0, 0.0, 0.0, corner[0], corner[1], 0.0]));
            Some(keys)
        }
        Geo::Matrix { m, keys } => {
            entries.push(e.doubles(34264, m));
            Some(keys)
        }
    };
    if let Some(keys) = keys {
        let mut dir = vec![1, 1, 0, keys.len() as u16];
        dir.extend(keys.iter().flatten());
        entries.push(e.shorts(34735, &dir));
    }
    if let Some(nd) = &spec.nodata {
        entries.push(e.ascii(42113, nd));
    }
    let counts: Vec<u32> = chunks.iter().map(|c| c.len() as u32).collect();
    // Offsets are patched below, once the layout is known.
    entries.push(e.longs(offsets_tag, &vec![0; chunks.len()]));
    entries.push(e.longs(counts_tag, &counts));
    entries.sort_by_key(|en| en.tag);

    // Layout: header, then [directory + its values, data] or [data, directory + its values].
    let dir_len = 2 + 12 * entries.len() + 4;
    let values_len: usize = entries
        .iter()
        .filter(|en| en.bytes.len() > 4)
        .map(|en| en.bytes.len().next_multiple_of(2))
        .sum();
    let data_len: usize = chunks.iter().map(Vec::len).sum();
    let (ifd_at, data_at) = if spec.ifd_first {
        (8, 8 + dir_len + values_len)
    } else {
        (8 + data_len.next_multiple_of(2), 8)
    };
    let mut offset = data_at as u32;
    let offsets: Vec<u32> = counts
        .iter()
        .map(|&n| {
            let o = offset;
            offset += n;
            o
        })
        .collect();
    for en in entries.iter_mut().filter(|en| en.tag == offsets_tag) {
        *en = e.longs(offsets_tag, &offsets);
    }

    let mut ifd = Vec::new();
    let mut values = Vec::new();
    ifd.extend(e.u16(entries.len() as u16));
    let values_at = ifd_at + dir_len;
    for en in &entries {
        ifd.extend(e.u16(en.tag));
        ifd.extend(e.u16(en.ty));
        ifd.extend(e.u32(en.count));
        if en.bytes.len() <= 4 {
            let mut inline = en.bytes.clone();
            inline.resize(4, 0);
            ifd.extend(inline);
        } else {
            ifd.extend(e.u32((values_at + values.len()) as u32));
            values.extend(&en.bytes);
            if values.len() % 2 == 1 {
                values.push(0);
            }
        }
    }
    ifd.extend(e.u32(0));

    let mut file = Vec::new();
    file.extend(if spec.big_endian { b"MM\0*" } else { b"II*\0" });
    file.extend(e.u32(ifd_at as u32));
    let data: Vec<u8> = chunks.concat();
    if spec.ifd_first {
        file.extend(&ifd);
        file.extend(&values);
        assert_eq!(file.len(), data_at);
        file.extend(&data);
    } else {
        file.extend(&data);
        file.resize(ifd_at, 0);
        file.extend(&ifd);
        file.extend(&values);
    }
    std::fs::write(path, file).unwrap();
}

// ---------------------------------------------------------------------------------------------
// The test landscape and its PNG twin.

/// Grid size: 65 x 57 samples, cells of 10 m east-west by 12 m north-south.
const SIZE: [u32; 2] = [65, 57];
const CELL: [f64; 2] = [10.0, 12.0];
/// The PNG twin stores height = PNG_OFFSET + PNG_SCALE * value: centimetres from -100 m.
const PNG_OFFSET: f64 = -100.0;
const PNG_SCALE: f64 = 0.01;
/// Half the PNG's quantisation step, and float rounding.
const PNG_TOLERANCE_M: f64 = 0.5 * PNG_SCALE + 1e-4;

/// Hills from about -60 m to 390 m, in metres, at (x east, y north) from the south-west.
fn landscape(x: f64, y: f64) -> f64 {
    120.0 + 180.0 * (x / 170.0).sin() * (y / 230.0).cos() + 0.15 * x
}

/// The landscape's heights as `sample` stores them, row 0 north (uint16 lifted by 100 m).
fn grid(sample: Sample) -> Vec<f64> {
    let [w, h] = SIZE;
    let lift = if sample == Sample::U16 { 100.0 } else { 0.0 };
    (0..h)
        .flat_map(|r| {
            (0..w).map(move |c| {
                let (x, y) = (f64::from(c) * CELL[0], f64::from(h - 1 - r) * CELL[1]);
                sample.quantise(landscape(x, y) + lift)
            })
        })
        .collect()
}

/// Writes `heights` (row 0 north, finite) as a 16-bit PNG with its sidecar; returns the PNG.
fn write_png_twin(
    dir: &Path,
    name: &str,
    size: [u32; 2],
    cell: [f64; 2],
    heights: &[f64],
) -> PathBuf {
    let [w, h] = size;
    let mut img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(w, h);
    for (i, &v) in heights.iter().enumerate() {
        let q = ((v - PNG_OFFSET) / PNG_SCALE).round();
        assert!(
            (0.0..=65535.0).contains(&q),
            "height {v} does not fit the PNG"
        );
        img.put_pixel(i as u32 % w, i as u32 / w, image::Luma([q as u16]));
    }
    let png = dir.join(format!("{name}.png"));
    img.save(&png).unwrap();
    common::write_sidecar(dir, name, size, cell, [PNG_OFFSET, PNG_SCALE]);
    png
}

fn assert_heights_match(label: &str, got: &Dem, want: &Dem, tolerance: f64) {
    assert_eq!(
        [got.width, got.height],
        [want.width, want.height],
        "{label}"
    );
    let worst = got
        .heights
        .iter()
        .zip(&want.heights)
        .map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs())
        .fold(0.0, f64::max);
    assert!(
        worst <= tolerance,
        "{label}: heights differ by up to {worst} m"
    );
}

/// Windows of rows of `path` read on their own (as a bake reads a large or remote file) hold
/// exactly the heights of those rows of the whole file, `dem`; and the header agrees.
fn assert_windows_match(label: &str, path: &Path, dem: &Dem) {
    let (header, rows) = verdant::world::window::Rows::open(path, &DemOptions::default(), 1 << 30)
        .unwrap_or_else(|e| panic!("{label}: {e}"));
    assert_eq!(
        [header.width, header.height],
        [dem.width, dem.height],
        "{label}"
    );
    assert_eq!(
        (
            header.cell_ew_m,
            header.cell_ns_m,
            header.origin,
            &header.crs
        ),
        (dem.cell_ew_m, dem.cell_ns_m, dem.origin, &dem.crs),
        "{label}"
    );
    let (w, h) = (dem.width as usize, dem.height as usize);
    for [a, b] in [[0, 1], [3, 20], [h / 2 - 5, h / 2 + 9], [h - 4, h], [0, h]] {
        let got = rows.read([a, b]).unwrap_or_else(|e| panic!("{label}: {e}"));
        let want = &dem.heights[a * w..b * w];
        assert!(
            got.len() == want.len()
                && got
                    .iter()
                    .zip(want)
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
            "{label}: rows {a}..{b} read on their own differ from the whole file's"
        );
    }
    // Windows of columns of those rows: a tiled file gives just the columns asked for and reads
    // only the tiles that hold them; any other file gives (and reads) whole rows.
    let tiled = rows.reads_column_windows();
    for [a, b] in [[3, 20], [0, h]] {
        let mut bytes = Vec::new();
        for [c0, c1] in [[0, 1], [5, 21], [w / 2 - 3, w / 2 + 4], [w - 2, w], [0, w]] {
            let before = rows.bytes_read();
            let (got, cols) = rows
                .read_window([a, b], Some([c0, c1]))
                .unwrap_or_else(|e| panic!("{label}: {e}"));
            bytes.push(rows.bytes_read() - before);
            assert_eq!(cols, if tiled { [c0, c1] } else { [0, w] }, "{label}");
            let cw = cols[1] - cols[0];
            assert_eq!(got.len(), cw * (b - a), "{label}");
            for r in a..b {
                let want = &dem.heights[r * w + cols[0]..r * w + cols[1]];
                assert!(
                    got[(r - a) * cw..(r - a + 1) * cw]
                        .iter()
                        .zip(want)
                        .all(|(x, y)| x.to_bits() == y.to_bits()),
                    "{label}: row {r} of columns {c0}..{c1} read on their own differs from the \
                     whole file's"
                );
            }
        }
        // The first column alone against every column: a tiled file reads its first tiles
        // only; the others read the same bytes whatever the columns.
        if tiled {
            assert!(bytes[0] < bytes[4], "{label}: {bytes:?} bytes read");
        } else {
            assert_eq!(bytes[0], bytes[4], "{label}: {bytes:?} bytes read");
        }
    }
    // The file as a mosaic of one, windows of it as a chunked bake reads them.
    let layout = verdant::world::mosaic::Layout::open(
        &[path.to_path_buf()],
        &DemOptions::default(),
        1 << 30,
    )
    .unwrap_or_else(|e| panic!("{label}: {e}"));
    for (cols, rows) in [
        ([0, w], [0, h]),
        ([7, 40], [2, 31]),
        ([w - 9, w], [h - 5, h]),
    ] {
        let got = layout
            .region(cols, rows)
            .unwrap_or_else(|e| panic!("{label}: {e}"));
        let want: Vec<f32> = (rows[0]..rows[1])
            .flat_map(|r| dem.heights[r * w + cols[0]..r * w + cols[1]].to_vec())
            .collect();
        assert!(
            got.len() == want.len()
                && got
                    .iter()
                    .zip(&want)
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
            "{label}: the window {cols:?} x {rows:?} of the file as a mosaic differs"
        );
    }
}

/// Three files joined, one offset from the first by whole samples and one on a grid twice as
/// coarse (its heights interpolated onto the joined grid), give the same heights in every
/// window whether the files are tiled (each read only over the window's columns) or striped
/// (read across whole rows).
#[test]
fn a_mosaic_of_tiled_files_joins_like_the_same_files_striped() {
    let dir = tempfile::tempdir().unwrap();
    let [x0, y0] = [500_000.0, 4_200_000.0];
    // Each file: its corner, its cell, its samples.
    let files = [
        ([x0, y0], CELL, SIZE),
        ([x0 + 400.0, y0], CELL, SIZE),
        // Sample centres on every other sample of the first's grid, from its 60th column.
        (
            [x0 + 595.0, y0 + 6.0],
            [2.0 * CELL[0], 2.0 * CELL[1]],
            [33, 29],
        ),
    ];
    let write = |layout: Layout, name: &str| -> Vec<std::path::PathBuf> {
        files
            .iter()
            .enumerate()
            .map(|(k, &(corner, cell, [w, h]))| {
                let heights: Vec<f64> = (0..h)
                    .flat_map(|r| (0..w).map(move |c| (c, r)))
                    .map(|(c, r)| {
                        let x = corner[0] + (f64::from(c) + 0.5) * cell[0];
                        let y = corner[1] - (f64::from(r) + 0.5) * cell[1];
                        landscape(x - x0, y0 - y)
                    })
                    .collect();
                let mut spec = TiffSpec::new(Sample::F32, layout, Compression::Deflate);
                spec.geo = Geo::Scale {
                    scale: cell,
                    corner,
                    keys: projected_keys(32610, 9001),
                };
                let path = dir.path().join(format!("{name}{k}.tif"));
                write_tiff(&path, &spec, w, h, &heights);
                path
            })
            .collect()
    };
    let striped = write(Layout::Strips { rows: 7 }, "striped");
    let tiled = write(
        Layout::Tiles {
            width: 16,
            height: 16,
        },
        "tiled",
    );
    let open = |paths: &[std::path::PathBuf]| {
        verdant::world::mosaic::Layout::open(paths, &DemOptions::default(), 1 << 30).unwrap()
    };
    let (a, b) = (open(&striped), open(&tiled));
    let [w, h] = [a.header.width as usize, a.header.height as usize];
    assert_eq!([w, h], [125, 57]);
    for (cols, rows) in [
        ([0, w], [0, h]),
        ([3, 50], [5, 40]),
        ([45, 70], [0, h]),
        ([58, 125], [10, 57]),
        ([100, 125], [0, 9]),
    ] {
        let (x, y) = (a.region(cols, rows).unwrap(), b.region(cols, rows).unwrap());
        assert!(
            x.len() == y.len() && x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()),
            "the window {cols:?} x {rows:?} differs between the tiled and the striped files"
        );
        assert!(x.iter().all(|v| v.is_finite()), "{cols:?} x {rows:?}");
    }
}

/// A 1-arc-second tile (3601 x 3601, 26 MB) read as a window of all its rows (in reads of at
/// most 4 MiB, over HTTP a request each) holds the whole file's heights, every byte read once.
#[test]
fn a_one_arc_second_tile_read_in_pieces_is_the_whole_file() {
    let dir = tempfile::tempdir().unwrap();
    let hgt = dir.path().join("N37W123.hgt");
    let n = 3601u32;
    let bytes: Vec<u8> = (0..n)
        .flat_map(|r| (0..n).map(move |c| (c, r)))
        .flat_map(|(c, r)| (((c * 7 + r * 13) % 2000) as i16).to_be_bytes())
        .collect();
    std::fs::write(&hgt, &bytes).unwrap();
    let dem = Dem::load(&hgt).unwrap();
    let (_, rows) =
        verdant::world::window::Rows::open(&hgt, &DemOptions::default(), 1 << 30).unwrap();
    let all = rows.read([0, n as usize]).unwrap();
    assert!(
        all.len() == dem.heights.len()
            && all
                .iter()
                .zip(&dem.heights)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
        "the tile read in pieces differs from the whole file"
    );
    assert_eq!(rows.bytes_read(), 8 + bytes.len() as u64);
}

/// A sidecar saved with a byte-order mark (as some Windows editors save JSON) reads as without.
#[test]
fn a_sidecar_with_a_byte_order_mark_reads() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::U16);
    let png = write_png_twin(dir.path(), "plain", SIZE, CELL, &heights);
    let want = Dem::load(&png).unwrap();
    let marked = write_png_twin(dir.path(), "marked", SIZE, CELL, &heights);
    let sidecar = dir.path().join("marked.json");
    let text = std::fs::read_to_string(&sidecar).unwrap();
    std::fs::write(&sidecar, format!("\u{feff}{text}")).unwrap();
    let got = Dem::load(&marked).unwrap();
    assert_heights_match("a sidecar with a byte-order mark", &got, &want, 0.0);
    assert_eq!([got.cell_ew_m, got.cell_ns_m], CELL);
}

/// Bakes `dem` into `dir/name` with small tiles: 20 m cells, 16-cell tiles, two levels.
fn small_bake(dem: &Path, dir: &Path, name: &str, dem_cell: Option<[f64; 2]>) -> World {
    let out = dir.join(name);
    let opts = BakeOptions {
        dem: dem.to_path_buf(),
        dem_cell_size_m: dem_cell,
        out: out.clone(),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        ..Default::default()
    };
    bake(&opts, &mut |_, _, _| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
    World::open(&out).unwrap()
}

/// Largest height difference between the stored tiles of two worlds of the same pyramid.
fn world_height_difference(a: &World, b: &World) -> f64 {
    assert_eq!(a.manifest.pyramid, b.manifest.pyramid);
    assert_eq!(a.manifest.extent_m, b.manifest.extent_m);
    let mut worst = 0.0f64;
    let ids: Vec<TileId> = a.stored_tiles().collect();
    assert!(!ids.is_empty());
    for id in ids {
        let (ta, tb) = (a.load_tile(id).unwrap(), b.load_tile(id).unwrap());
        assert_eq!(ta.heights.len(), tb.heights.len());
        for (x, y) in ta.heights.iter().zip(&tb.heights) {
            worst = worst.max((f64::from(*x) - f64::from(*y)).abs());
        }
    }
    worst
}

// ---------------------------------------------------------------------------------------------
// GeoTIFFs that read.

/// Every supported sample type, in strips and in tiles, uncompressed and with each compression
/// (and the predictors that go with them), reads to the heights of its PNG twin.
#[test]
fn every_sample_type_layout_and_compression_reads_like_the_png() {
    let dir = tempfile::tempdir().unwrap();
    let layouts = [
        Layout::Strips { rows: 7 },
        Layout::Tiles {
            width: 16,
            height: 32,
        },
    ];
    let compressions = [
        Compression::None,
        Compression::Deflate,
        Compression::Lzw,
        Compression::PackBits,
        Compression::Zstd,
    ];
    let mut read = 0;
    for sample in Sample::ALL {
        let heights = grid(sample);
        let twin = write_png_twin(dir.path(), &format!("{sample:?}"), SIZE, CELL, &heights);
        let want = Dem::load(&twin).unwrap();
        for layout in layouts {
            for compression in compressions {
                // The predictor that suits the type where it compresses: horizontal for
                // integers, floating point for floats; none otherwise.
                let predictors: &[u16] = match (compression, sample.is_float()) {
                    (Compression::Deflate | Compression::Lzw | Compression::Zstd, false) => &[1, 2],
                    (Compression::Deflate | Compression::Lzw | Compression::Zstd, true) => &[1, 3],
                    _ => &[1],
                };
                for &predictor in predictors {
                    let mut spec = TiffSpec::new(sample, layout, compression);
                    spec.predictor = predictor;
                    // Big-endian files too, for every other case.
                    spec.big_endian = read % 2 == 1;
                    let label = format!("{spec:?}");
                    let path = dir.path().join(format!("dem{read}.tif"));
                    write_tiff(&path, &spec, SIZE[0], SIZE[1], &heights);
                    let dem = Dem::load(&path).unwrap_or_else(|e| panic!("{label}: {e}"));
                    assert_eq!(dem.format, DemFormat::Geotiff, "{label}");
                    assert_eq!([dem.cell_ew_m, dem.cell_ns_m], CELL, "{label}");
                    assert_eq!(dem.nodata_filled, 0, "{label}");
                    assert!(dem.crs.contains("EPSG:32610"), "{label}: {}", dem.crs);
                    assert_heights_match(&label, &dem, &want, PNG_TOLERANCE_M);
                    assert_windows_match(&label, &path, &dem);
                    read += 1;
                }
            }
        }
    }
    // Per type and layout: uncompressed and PackBits without a predictor, Deflate, LZW and
    // Zstandard without and with one.
    assert_eq!(read, 5 * 2 * (1 + 2 + 2 + 1 + 2));
}

/// A GeoTIFF of each sample type bakes into the same world as its PNG twin.
#[test]
fn geotiffs_bake_to_the_heights_of_the_png_twin() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            Sample::I16,
            Layout::Strips { rows: 1 },
            Compression::Deflate,
            2,
        ),
        (
            Sample::U16,
            Layout::Tiles {
                width: 16,
                height: 16,
            },
            Compression::Lzw,
            2,
        ),
        (
            Sample::I32,
            Layout::Strips { rows: 16 },
            Compression::PackBits,
            1,
        ),
        (
            Sample::F32,
            Layout::Tiles {
                width: 32,
                height: 16,
            },
            Compression::Deflate,
            3,
        ),
        (
            Sample::F64,
            Layout::Strips { rows: 5 },
            Compression::None,
            1,
        ),
    ];
    for (i, (sample, layout, compression, predictor)) in cases.into_iter().enumerate() {
        let heights = grid(sample);
        let twin = write_png_twin(dir.path(), &format!("twin{i}"), SIZE, CELL, &heights);
        let mut spec = TiffSpec::new(sample, layout, compression);
        spec.predictor = predictor;
        let tif = dir.path().join(format!("dem{i}.tif"));
        write_tiff(&tif, &spec, SIZE[0], SIZE[1], &heights);
        let from_png = small_bake(&twin, dir.path(), &format!("png{i}"), None);
        let from_tiff = small_bake(&tif, dir.path(), &format!("tif{i}"), None);
        let diff = world_height_difference(&from_png, &from_tiff);
        // Resampling is linear in the heights: the PNG's rounding carries through unchanged
        // in size (Catmull-Rom overshoots by at most 25%).
        assert!(
            diff <= 1.25 * PNG_TOLERANCE_M,
            "{spec:?}: worlds differ by {diff} m"
        );
        let source = from_tiff
            .manifest
            .source
            .as_ref()
            .expect("[source] in world.toml");
        assert_eq!(source.format, DemFormat::Geotiff);
        assert_eq!(source.file, format!("dem{i}.tif"));
        assert_eq!(source.cell_size_m, CELL);
        assert_eq!(source.samples, SIZE);
        assert_eq!(source.nodata_filled, 0);
        // The PNG world records its source too.
        let png_source = from_png.manifest.source.as_ref().unwrap();
        assert_eq!(png_source.format, DemFormat::PngSidecar);
    }
}

/// A geographic grid within a degree of a pole is refused as one to reproject, one beyond the
/// poles as off the globe; both name the file.
#[test]
fn a_geographic_geotiff_at_a_pole_or_beyond_is_refused_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::F32);
    let step = 1.0 / 3600.0;
    for (corner_lat, needles) in [
        (
            89.97,
            &["89.9", "within a degree of the pole", "reproject"][..],
        ),
        (95.0, &["94.9", "off the globe"][..]),
    ] {
        let mut spec = TiffSpec::new(Sample::F32, Layout::Strips { rows: 8 }, Compression::None);
        spec.geo = Geo::Scale {
            scale: [step, step],
            corner: [10.0, corner_lat],
            keys: geographic_keys(),
        };
        let tif = dir.path().join(format!("pole{corner_lat}.tif"));
        write_tiff(&tif, &spec, SIZE[0], SIZE[1], &heights);
        let e = Dem::load(&tif).unwrap_err().to_string();
        for n in needles
            .iter()
            .chain(&[tif.file_name().unwrap().to_str().unwrap()])
        {
            assert!(e.contains(n), "{n:?} not in {e:?}");
        }
    }
}

/// A geographic grid (degrees) gets its cell sizes in metres at its centre latitude, east-west
/// and north-south apart, and bakes like a PNG twin with those cell sizes.
#[test]
fn a_geographic_geotiff_gets_metres_at_its_centre_latitude() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::F32);
    // One arc-second cells, the top-left corner at 122.5 W, 37.8 N.
    let step = 1.0 / 3600.0;
    let corner = [-122.5, 37.8];
    let mut spec = TiffSpec::new(
        Sample::F32,
        Layout::Tiles {
            width: 16,
            height: 16,
        },
        Compression::Deflate,
    );
    spec.predictor = 3;
    spec.geo = Geo::Scale {
        scale: [step, step],
        corner,
        keys: geographic_keys(),
    };
    let tif = dir.path().join("geographic.tif");
    write_tiff(&tif, &spec, SIZE[0], SIZE[1], &heights);
    let dem = Dem::load(&tif).unwrap();

    // Pixel-is-area: sample centres are half a cell in from the corner.
    let centre_lat = corner[1] - (f64::from(SIZE[1] - 1) / 2.0 + 0.5) * step;
    let [m_ew, m_ns] = metres_per_degree(centre_lat);
    let expected = [step * m_ew, step * m_ns];
    assert!(
        (dem.cell_ew_m - expected[0]).abs() < 1e-9,
        "{} vs {}",
        dem.cell_ew_m,
        expected[0]
    );
    assert!(
        (dem.cell_ns_m - expected[1]).abs() < 1e-9,
        "{} vs {}",
        dem.cell_ns_m,
        expected[1]
    );
    // Near the spherical figures (30.87 m for an arc-second of latitude, times cos(latitude)
    // for longitude) and clearly not square.
    let sphere_ns = 6_371_000.0 * step.to_radians();
    let sphere_ew = sphere_ns * centre_lat.to_radians().cos();
    assert!(
        (dem.cell_ns_m / sphere_ns - 1.0).abs() < 0.005,
        "{}",
        dem.cell_ns_m
    );
    assert!(
        (dem.cell_ew_m / sphere_ew - 1.0).abs() < 0.005,
        "{}",
        dem.cell_ew_m
    );
    assert!(dem.cell_ns_m - dem.cell_ew_m > 5.0);
    assert!(
        dem.crs.contains("EPSG:4326") && dem.crs.contains("geographic"),
        "{}",
        dem.crs
    );
    let [lon, lat] = dem.origin.expect("origin");
    assert!((lon - (corner[0] + 0.5 * step)).abs() < 1e-9, "{lon}");
    assert!(
        (lat - (corner[1] - (f64::from(SIZE[1]) - 0.5) * step)).abs() < 1e-9,
        "{lat}"
    );

    let twin = write_png_twin(dir.path(), "twin", SIZE, expected, &heights);
    assert_heights_match(
        "geographic",
        &dem,
        &Dem::load(&twin).unwrap(),
        PNG_TOLERANCE_M,
    );
    let a = small_bake(&twin, dir.path(), "png", None);
    let b = small_bake(&tif, dir.path(), "tif", None);
    let diff = world_height_difference(&a, &b);
    assert!(diff <= 1.25 * PNG_TOLERANCE_M, "worlds differ by {diff} m");
    let source = b.manifest.source.as_ref().unwrap();
    assert!(source.crs.contains("EPSG:4326"), "{}", source.crs);
    assert_eq!(source.cell_size_m, [dem.cell_ew_m, dem.cell_ns_m]);
}

/// A grid placed by ModelTransformation in feet, stored south row first, reads north-up in
/// metres.
#[test]
fn a_transformation_in_feet_stored_south_up_reads_north_up_in_metres() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::I16);
    let [w, h] = SIZE;
    let south_first: Vec<f64> = (0..h)
        .rev()
        .flat_map(|r| heights[(r * w) as usize..((r + 1) * w) as usize].to_vec())
        .collect();
    let feet = [30.0, 40.0];
    let mut m = [0.0; 16];
    m[0] = feet[0];
    m[3] = 6_000_000.0;
    m[5] = feet[1]; // rows go north
    m[7] = 2_000_000.0;
    m[15] = 1.0;
    let mut spec = TiffSpec::new(Sample::I16, Layout::Strips { rows: 8 }, Compression::Lzw);
    spec.geo = Geo::Matrix {
        m,
        keys: projected_keys(2227, 9002),
    };
    let tif = dir.path().join("feet.tif");
    write_tiff(&tif, &spec, w, h, &south_first);
    let dem = Dem::load(&tif).unwrap();
    assert!((dem.cell_ew_m - 9.144).abs() < 1e-9, "{}", dem.cell_ew_m);
    assert!((dem.cell_ns_m - 12.192).abs() < 1e-9, "{}", dem.cell_ns_m);
    assert!(dem.crs.contains("feet"), "{}", dem.crs);
    let twin = write_png_twin(dir.path(), "twin", SIZE, [9.144, 12.192], &heights);
    assert_heights_match(
        "south-up feet",
        &dem,
        &Dem::load(&twin).unwrap(),
        PNG_TOLERANCE_M,
    );
    // The south-west sample is the first one stored: x and y of the first pixel's centre.
    assert_eq!(dem.origin, Some([6_000_015.0, 2_000_020.0]));
    assert_windows_match("south-up feet", &tif, &dem);

    // Tiled, stored south first and then also east first: windows of columns come out north up
    // and west first.
    spec.layout = Layout::Tiles {
        width: 16,
        height: 16,
    };
    let tiled = dir.path().join("feet_tiled.tif");
    write_tiff(&tiled, &spec, w, h, &south_first);
    let dem_tiled = Dem::load(&tiled).unwrap();
    assert_heights_match("south-up feet, tiled", &dem_tiled, &dem, 0.0);
    assert_windows_match("south-up feet, tiled", &tiled, &dem_tiled);
    let east_first: Vec<f64> = south_first
        .chunks_exact(w as usize)
        .flat_map(|row| row.iter().rev().copied().collect::<Vec<_>>())
        .collect();
    if let Geo::Matrix { m, .. } = &mut spec.geo {
        m[0] = -feet[0]; // columns go west
        m[3] = 6_000_000.0 + feet[0] * f64::from(w);
    }
    let flipped = dir.path().join("feet_east_first.tif");
    write_tiff(&flipped, &spec, w, h, &east_first);
    let dem_flipped = Dem::load(&flipped).unwrap();
    assert_heights_match("south-up, east-first feet, tiled", &dem_flipped, &dem, 0.0);
    assert_windows_match("south-up, east-first feet, tiled", &flipped, &dem_flipped);
}

/// Nodata samples (GDAL_NODATA) are filled from the heights around them and counted; valid
/// samples keep their heights; the world records the count.
#[test]
fn nodata_is_filled_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let [w, h] = SIZE;
    // A 6 x 5 void, a void on the west edge and a single void sample.
    let void = |c: u32, r: u32| {
        ((20..26).contains(&c) && (30..35).contains(&r))
            || (c == 0 && (10..14).contains(&r))
            || (c, r) == (50, 8)
    };
    let voids = 6 * 5 + 4 + 1;
    let cases = [
        (Sample::I16, "-9999", Compression::Deflate),
        (Sample::F32, "-3.4028234663852886e+38", Compression::Lzw),
        (Sample::F64, "nan", Compression::None),
        (Sample::I32, "-32768", Compression::PackBits),
    ];
    for (i, (sample, nodata, compression)) in cases.into_iter().enumerate() {
        let truth = grid(sample);
        let with_voids: Vec<f64> = truth
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                if void(k as u32 % w, k as u32 / w) {
                    f64::NAN
                } else {
                    v
                }
            })
            .collect();
        let mut spec = TiffSpec::new(
            sample,
            Layout::Tiles {
                width: 16,
                height: 16,
            },
            compression,
        );
        spec.nodata = Some(nodata.to_string());
        let tif = dir.path().join(format!("voids{i}.tif"));
        write_tiff(&tif, &spec, w, h, &with_voids);
        let dem = Dem::load(&tif).unwrap_or_else(|e| panic!("{sample:?}: {e}"));
        assert_eq!(dem.nodata_filled, voids, "{sample:?}");
        for (k, (&got, &want)) in dem.heights.iter().zip(&truth).enumerate() {
            let (c, r) = (k as u32 % w, k as u32 / w);
            let err = (f64::from(got) - want).abs();
            if void(c, r) {
                // The hills change by up to about 10 m across the void: filled heights stay
                // within a few metres of the truth.
                assert!(err < 6.0, "{sample:?} void ({c}, {r}): {got} vs {want}");
            } else {
                assert!(err <= 1e-3, "{sample:?} valid ({c}, {r}): {got} vs {want}");
            }
        }
    }
    // Through the baker: the count lands in world.toml and the description.
    let world = small_bake(&dir.path().join("voids0.tif"), dir.path(), "w", None);
    let source = world.manifest.source.as_ref().unwrap();
    assert_eq!(source.nodata_filled, voids);
    assert!(
        world
            .manifest
            .description
            .contains("35 nodata samples filled"),
        "{}",
        world.manifest.description
    );
}

/// A TIFF without geo tags reads when the cell size is given, and the world takes it.
#[test]
fn a_plain_tiff_reads_with_a_cell_size_given() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::U16);
    let mut spec = TiffSpec::new(Sample::U16, Layout::Strips { rows: 4 }, Compression::None);
    spec.geo = Geo::None;
    let tif = dir.path().join("plain.tif");
    write_tiff(&tif, &spec, SIZE[0], SIZE[1], &heights);
    let options = DemOptions {
        cell_size_m: Some(CELL),
    };
    let dem = Dem::load_with(&tif, &options).unwrap();
    assert_eq!([dem.cell_ew_m, dem.cell_ns_m], CELL);
    let twin = write_png_twin(dir.path(), "twin", SIZE, CELL, &heights);
    assert_heights_match("plain", &dem, &Dem::load(&twin).unwrap(), PNG_TOLERANCE_M);
    let world = small_bake(&tif, dir.path(), "w", Some(CELL));
    assert_eq!(world.manifest.source.as_ref().unwrap().cell_size_m, CELL);
}

/// The tiff crate's own encoder (strips, LZW, horizontal predictor) writes a GeoTIFF that
/// reads the same as the hand-written ones.
#[test]
fn a_geotiff_from_the_tiff_encoder_reads() {
    use tiff::encoder::{Compression as C, Predictor, TiffEncoder, colortype::GrayI16};
    use tiff::tags::Tag;
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::I16);
    let data: Vec<i16> = heights.iter().map(|&v| v as i16).collect();
    let tif = dir.path().join("encoder.tif");
    {
        let mut file = std::io::BufWriter::new(std::fs::File::create(&tif).unwrap());
        let mut enc = TiffEncoder::new(&mut file)
            .unwrap()
            .with_compression(C::Lzw)
            .with_predictor(Predictor::Horizontal);
        let mut image = enc.new_image::<GrayI16>(SIZE[0], SIZE[1]).unwrap();
        let d = image.encoder();
        d.write_tag(Tag::ModelPixelScaleTag, &[CELL[0], CELL[1], 0.0][..])
            .unwrap();
        d.write_tag(
            Tag::ModelTiepointTag,
            &[0.0, 0.0, 0.0, 400_000.0, 4_100_000.0, 0.0][..],
        )
        .unwrap();
        let keys: Vec<u16> = [[1, 1, 0, 2], [1024, 0, 1, 1], [3072, 0, 1, 32633]].concat();
        d.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
        image.write_data(&data).unwrap();
    }
    let dem = Dem::load(&tif).unwrap();
    assert_eq!([dem.cell_ew_m, dem.cell_ns_m], CELL);
    assert!(dem.crs.contains("EPSG:32633"), "{}", dem.crs);
    let twin = write_png_twin(dir.path(), "twin", SIZE, CELL, &heights);
    assert_heights_match("encoder", &dem, &Dem::load(&twin).unwrap(), PNG_TOLERANCE_M);
}

// ---------------------------------------------------------------------------------------------
// SRTM .hgt tiles.

/// Writes a 1201 x 1201 (3 arc-second) tile from `f(col, row)`, rows from the north.
fn write_hgt(path: &Path, f: impl Fn(u32, u32) -> i16) {
    let n = 1201;
    let bytes: Vec<u8> = (0..n)
        .flat_map(|r| (0..n).map(move |c| (c, r)))
        .flat_map(|(c, r)| f(c, r).to_be_bytes())
        .collect();
    std::fs::write(path, bytes).unwrap();
}

fn hgt_height(c: u32, r: u32) -> i16 {
    (300.0 + 250.0 * (f64::from(c) / 90.0).sin() * (f64::from(r) / 130.0).cos()).round() as i16
}

/// An SRTM tile reads north-up, its origin and cell size from its name, voids filled, and
/// bakes like its PNG twin.
#[test]
fn an_srtm_tile_reads_and_bakes_like_its_png_twin() {
    let dir = tempfile::tempdir().unwrap();
    let void = |c: u32, r: u32| (600..604).contains(&c) && (100..103).contains(&r);
    let hgt = dir.path().join("S34E151.hgt");
    write_hgt(
        &hgt,
        |c, r| if void(c, r) { -32768 } else { hgt_height(c, r) },
    );
    let dem = Dem::load(&hgt).unwrap();
    assert_eq!(dem.format, DemFormat::SrtmHgt);
    assert_eq!([dem.width, dem.height], [1201, 1201]);
    assert_eq!(dem.origin, Some([151.0, -34.0]));
    assert_eq!(dem.nodata_filled, 12);
    // Three arc-seconds at 33.5 S.
    let [m_ew, m_ns] = metres_per_degree(-33.5);
    assert!(
        (dem.cell_ew_m - m_ew / 1200.0).abs() < 1e-9,
        "{}",
        dem.cell_ew_m
    );
    assert!(
        (dem.cell_ns_m - m_ns / 1200.0).abs() < 1e-9,
        "{}",
        dem.cell_ns_m
    );
    assert!((dem.cell_ns_m - 92.4).abs() < 0.2, "{}", dem.cell_ns_m);
    assert!((dem.cell_ew_m - 77.3).abs() < 0.2, "{}", dem.cell_ew_m);

    // The PNG twin holds the true heights; filled voids stay near them.
    let truth: Vec<f64> = (0..1201u32)
        .flat_map(|r| (0..1201u32).map(move |c| f64::from(hgt_height(c, r))))
        .collect();
    let twin = write_png_twin(
        dir.path(),
        "twin",
        [1201, 1201],
        [dem.cell_ew_m, dem.cell_ns_m],
        &truth,
    );
    let want = Dem::load(&twin).unwrap();
    for (k, (a, b)) in dem.heights.iter().zip(&want.heights).enumerate() {
        let (c, r) = (k as u32 % 1201, k as u32 / 1201);
        let tolerance = if void(c, r) { 3.0 } else { PNG_TOLERANCE_M };
        assert!((a - b).abs() as f64 <= tolerance, "({c}, {r}): {a} vs {b}");
    }
    // Coarse worlds (2 km cells) keep the bake short.
    let bake_coarse = |dem: &Path, name: &str| {
        let out = dir.path().join(name);
        let opts = BakeOptions {
            dem: dem.to_path_buf(),
            out: out.clone(),
            cell_size_m: Some(2000.0),
            tile_cells: 16,
            stored_levels: 1,
            ..Default::default()
        };
        bake(&opts, &mut |_, _, _| {}).unwrap();
        World::open(&out).unwrap()
    };
    let a = bake_coarse(&twin, "png");
    let b = bake_coarse(&hgt, "hgt");
    let diff = world_height_difference(&a, &b);
    assert!(diff <= 1.25 * PNG_TOLERANCE_M, "worlds differ by {diff} m");
    let source = b.manifest.source.as_ref().unwrap();
    assert_eq!(source.format, DemFormat::SrtmHgt);
    assert_eq!(source.origin, Some([151.0, -34.0]));
    assert_eq!(source.nodata_filled, 12);
    // The manifest says where the world came from, and reads back.
    let text = std::fs::read_to_string(dir.path().join("hgt/world.toml")).unwrap();
    assert!(
        text.contains("[source]") && text.contains("format = \"srtm-hgt\""),
        "{text}"
    );
}

/// A world.toml without a [source] table (every world baked before it existed) still opens.
#[test]
fn worlds_without_a_source_table_still_open() {
    let text = std::fs::read_to_string(common::default_world().join("world.toml")).unwrap();
    let start = text
        .find("[source]")
        .expect("the default world records its source");
    let end = text[start..]
        .find("\n\n")
        .map_or(text.len(), |e| start + e + 2);
    let without = format!("{}{}", &text[..start], &text[end..]);
    assert!(!without.contains("[source]"));
    let manifest = verdant::world::Manifest::parse(&without, Path::new("world.toml")).unwrap();
    assert!(manifest.source.is_none());
    let world = World::open(&common::default_world()).unwrap();
    assert_eq!(
        world.manifest.source.as_ref().map(|s| s.format),
        Some(DemFormat::PngSidecar)
    );
}

// ---------------------------------------------------------------------------------------------
// Bad files: refused with an error that names the file and the problem.

/// A bad DEM, what the error must be, and words its message must hold.
struct BadCase {
    file: &'static str,
    write: Box<dyn Fn(&Path)>,
    is: fn(&WorldError) -> bool,
    says: &'static [&'static str],
}

fn tiff_case(
    file: &'static str,
    edit: impl Fn(&mut TiffSpec) + 'static,
    is: fn(&WorldError) -> bool,
    says: &'static [&'static str],
) -> BadCase {
    BadCase {
        file,
        write: Box::new(move |path| {
            let mut spec = TiffSpec::new(
                Sample::I16,
                Layout::Strips { rows: 8 },
                Compression::Deflate,
            );
            edit(&mut spec);
            write_tiff(path, &spec, SIZE[0], SIZE[1], &grid(Sample::I16));
        }),
        is,
        says,
    }
}

/// Writes a TIFF by `spec` and keeps only `keep` of its bytes.
fn truncated(spec: TiffSpec, keep: f64) -> Box<dyn Fn(&Path)> {
    Box::new(move |path| {
        write_tiff(path, &spec, SIZE[0], SIZE[1], &grid(Sample::I16));
        let bytes = std::fs::read(path).unwrap();
        std::fs::write(path, &bytes[..(bytes.len() as f64 * keep) as usize]).unwrap();
    })
}

fn bad_cases() -> Vec<BadCase> {
    let mut rotated = [0.0; 16];
    rotated[0] = 10.0;
    rotated[1] = 2.0;
    rotated[4] = 2.0;
    rotated[5] = -10.0;
    rotated[15] = 1.0;
    let data_first = TiffSpec::new(Sample::I16, Layout::Strips { rows: 8 }, Compression::None);
    let mut directory_first = data_first.clone();
    directory_first.ifd_first = true;
    vec![
        tiff_case(
            "rgb.tif",
            |s| s.bands = 3,
            |e| matches!(e, WorldError::UnsupportedDem { .. }),
            &["3 bands", "single-band"],
        ),
        tiff_case(
            "plain.tif",
            |s| s.geo = Geo::None,
            |e| matches!(e, WorldError::NoGeoreference { .. }),
            &["no GeoTIFF cell size", "--dem-cell-size"],
        ),
        tiff_case(
            "lerc.tif",
            |s| s.compression = Compression::Other(34887),
            |e| matches!(e, WorldError::UnsupportedDem { .. }),
            &["compression LERC (34887)", "Deflate", "Zstandard"],
        ),
        tiff_case(
            "jpeg.tif",
            |s| s.compression = Compression::Other(7),
            |e| matches!(e, WorldError::UnsupportedDem { .. }),
            &["compression JPEG (7)"],
        ),
        tiff_case(
            "huge.tif",
            |s| {
                // One strip, so that the directory is consistent with the size it claims.
                s.layout = Layout::Strips { rows: 150_000 };
                s.claimed_size = Some([200_000, 150_000]);
            },
            |e| matches!(e, WorldError::OutOfRange { .. }),
            &["200000x150000", "at most"],
        ),
        tiff_case(
            "huge-tiles.tif",
            |s| {
                // Tiles the directory says are 4 billion samples a side (each chunk would
                // decode to exabytes): refused before anything is allocated for one.
                // One tile, written as 80 x 64 (the grid is 65 x 57), so that the directory's
                // count of tiles agrees.
                s.layout = Layout::Tiles {
                    width: 80,
                    height: 64,
                };
                s.claimed_tile = Some([0xFFFF_FFF0, 0xFFFF_FFF0]);
                // LZW and Zstandard chunks are decoded by the reader's own code.
                s.compression = Compression::Lzw;
            },
            |e| matches!(e, WorldError::CorruptImage { .. }),
            &[
                "chunks of 4294967280x4294967280 samples",
                "at most 2048 MiB a chunk",
            ],
        ),
        tiff_case(
            "rotated.tif",
            move |s| {
                s.geo = Geo::Matrix {
                    m: rotated,
                    keys: projected_keys(32610, 9001),
                }
            },
            |e| matches!(e, WorldError::UnsupportedDem { .. }),
            &["rotated"],
        ),
        tiff_case(
            "geocentric.tif",
            |s| {
                s.sample = Sample::U16;
                s.geo = Geo::Scale {
                    scale: CELL,
                    corner: [0.0, 0.0],
                    keys: vec![[1024, 0, 1, 3]],
                }
            },
            |e| matches!(e, WorldError::UnsupportedDem { .. }),
            &["model type 3"],
        ),
        tiff_case(
            "no-model-type.tif",
            |s| {
                // Raster type and linear unit, but not whether the grid is projected.
                s.geo = Geo::Scale {
                    scale: CELL,
                    corner: [0.0, 0.0],
                    keys: vec![[1025, 0, 1, 1], [3076, 0, 1, 9001]],
                }
            },
            |e| matches!(e, WorldError::NoGeoreference { .. }),
            &["GeoKey directory lacks its model type", "GTModelTypeGeoKey"],
        ),
        tiff_case(
            "int-float-predictor.tif",
            |s| s.predictor = 3,
            |e| matches!(e, WorldError::UnsupportedDem { .. }),
            &["floating-point predictor on int16"],
        ),
        BadCase {
            file: "cut-directory.tif",
            write: truncated(data_first, 0.6),
            is: |e| matches!(e, WorldError::CorruptImage { .. }),
            says: &["corrupt or truncated TIFF"],
        },
        BadCase {
            file: "cut-data.tif",
            write: truncated(directory_first, 0.6),
            is: |e| matches!(e, WorldError::CorruptImage { .. }),
            says: &["truncated", "ends at byte"],
        },
        BadCase {
            file: "header-only.tif",
            write: Box::new(|p| std::fs::write(p, b"II*\0\x08\0").unwrap()),
            is: |e| matches!(e, WorldError::CorruptImage { .. }),
            says: &["TIFF"],
        },
        BadCase {
            file: "N37W123.hgt",
            write: Box::new(|p| std::fs::write(p, vec![0u8; 1201 * 1201 * 2 - 600]).unwrap()),
            is: |e| matches!(e, WorldError::HgtSize { bytes: 2884202, .. }),
            says: &["2884202 bytes", "1201x1201"],
        },
        BadCase {
            file: "tile.hgt",
            write: Box::new(|p| write_hgt(p, hgt_height)),
            is: |e| matches!(e, WorldError::HgtName { .. }),
            says: &["N37W123.hgt"],
        },
        BadCase {
            file: "N10E010.hgt",
            write: Box::new(|p| write_hgt(p, |c, _| if c < 700 { -32768 } else { 5 })),
            is: |e| matches!(e, WorldError::TooMuchNodata { .. }),
            says: &["are nodata", "58.3%"],
        },
        BadCase {
            file: "notes.dem",
            write: Box::new(|p| std::fs::write(p, "just some text\n").unwrap()),
            is: |e| matches!(e, WorldError::UnknownDemFormat { .. }),
            says: &["not a DEM", "GeoTIFF"],
        },
    ]
}

#[test]
fn bad_dems_are_refused_naming_the_file_and_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    for case in bad_cases() {
        let path = dir.path().join(case.file);
        (case.write)(&path);
        let err = match Dem::load(&path) {
            Ok(_) => panic!("{}: read without an error", case.file),
            Err(e) => e,
        };
        let message = err.to_string();
        assert!((case.is)(&err), "{}: wrong error {err:?}", case.file);
        assert!(
            message.starts_with(&path.display().to_string()),
            "{message}"
        );
        assert_eq!(err.path(), Some(path.as_path()));
        for needle in case.says {
            assert!(
                message.contains(needle),
                "{}: {message:?} lacks {needle:?}",
                case.file
            );
        }
    }
}

fn verdant(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run verdant")
}

/// The command line: each bad file exits with status 1, names the file, writes no world and
/// does not panic.
#[test]
fn cli_refuses_bad_dems_with_status_1_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    for case in bad_cases() {
        let path = dir.path().join(case.file);
        (case.write)(&path);
        let out_dir = dir.path().join("out");
        let out = verdant(
            &[
                "bake",
                "--dem",
                path.to_str().unwrap(),
                "--out",
                out_dir.to_str().unwrap(),
            ],
            dir.path(),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{}: {stderr}", case.file);
        assert!(!stderr.contains("panicked"), "{}: {stderr}", case.file);
        assert!(stderr.contains(case.file), "{}: {stderr}", case.file);
        for needle in case.says {
            assert!(
                stderr.contains(needle),
                "{}: {stderr:?} lacks {needle:?}",
                case.file
            );
        }
        assert!(
            !out_dir.join("world.toml").exists(),
            "{}: wrote a world",
            case.file
        );
    }
}

/// The command line bakes a GeoTIFF, and a plain TIFF with --dem-cell-size, and says what it
/// read.
#[test]
fn cli_bakes_a_geotiff_and_a_plain_tiff_with_a_cell_size() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::F32);
    let geo = dir.path().join("geo.tif");
    let mut spec = TiffSpec::new(
        Sample::F32,
        Layout::Tiles {
            width: 16,
            height: 16,
        },
        Compression::Deflate,
    );
    spec.predictor = 3;
    write_tiff(&geo, &spec, SIZE[0], SIZE[1], &heights);
    let plain = dir.path().join("plain.tif");
    spec.geo = Geo::None;
    write_tiff(&plain, &spec, SIZE[0], SIZE[1], &heights);

    let small = ["--tile-cells", "16", "--levels", "2", "--cell-size", "20"];
    let run = |dem: &Path, name: &str, extra: &[&str]| {
        let world = dir.path().join(name);
        let mut args = vec![
            "bake",
            "--dem",
            dem.to_str().unwrap(),
            "--out",
            world.to_str().unwrap(),
        ];
        args.extend(small);
        args.extend(extra);
        let out = verdant(&args, dir.path());
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{name}: {stderr}");
        // Standard error is no terminal here, as in a batch job's log: the stages are logged a
        // line each.
        for stage in [
            "loaddem",
            "resample",
            "paint",
            "writetiles",
            "writemanifest",
        ] {
            assert!(
                stderr.contains(&format!("bake: {stage} ")),
                "{name}: no line for {stage}: {stderr}"
            );
        }
        (World::open(&world).unwrap(), stdout)
    };
    let (world, stdout) = run(&geo, "geo", &[]);
    assert!(
        stdout.contains("GeoTIFF, 65x57 samples of 10.000 m x 12.000 m"),
        "{stdout}"
    );
    assert_eq!(world.manifest.source.as_ref().unwrap().cell_size_m, CELL);
    let (world, _) = run(&plain, "plain", &["--dem-cell-size", "10,12"]);
    assert_eq!(world.manifest.source.as_ref().unwrap().cell_size_m, CELL);
    let (world, _) = run(&plain, "square", &["--dem-cell-size", "11"]);
    assert_eq!(
        world.manifest.source.as_ref().unwrap().cell_size_m,
        [11.0, 11.0]
    );

    let out = verdant(
        &[
            "bake",
            "--dem",
            plain.to_str().unwrap(),
            "--out",
            "x",
            "--dem-cell-size=-3",
        ],
        dir.path(),
    );
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("\"-3\" is not a positive number of metres"),
        "{stderr}"
    );
}

/// A Web Mercator grid (EPSG:3857, the projection of web map services' exports) has cells of
/// its stated size only at the equator: on the ground they are cos(latitude) as long, taken at
/// the grid's centre.
#[test]
fn a_web_mercator_geotiff_gets_ground_metres_at_its_centre_latitude() {
    let dir = tempfile::tempdir().unwrap();
    let heights = grid(Sample::F32);
    // 10 m Mercator cells around 60 degrees north, where Mercator stretches by 2.
    let r = 6_378_137.0f64;
    let y60 = r * (60f64.to_radians().tan() + 1.0 / 60f64.to_radians().cos()).ln();
    let mut spec = TiffSpec::new(Sample::F32, Layout::Strips { rows: 4 }, Compression::None);
    spec.geo = Geo::Scale {
        scale: [10.0, 10.0],
        corner: [1_000_000.0, y60 + 5.0 * f64::from(SIZE[1])],
        keys: projected_keys(3857, 9001),
    };
    let tif = dir.path().join("mercator.tif");
    write_tiff(&tif, &spec, SIZE[0], SIZE[1], &heights);
    let dem = Dem::load(&tif).unwrap();
    // The centre sample sits half a cell below the middle of the grid's extent.
    let centre_y = y60 + 5.0 * f64::from(SIZE[1]) - (f64::from(SIZE[1] - 1) / 2.0 + 0.5) * 10.0;
    let lat = (centre_y / r).sinh().atan();
    let expected = 10.0 * lat.cos();
    assert!(
        (lat.to_degrees() - 60.0).abs() < 0.01,
        "{}",
        lat.to_degrees()
    );
    assert!(
        (dem.cell_ew_m - expected).abs() < 1e-6,
        "{} vs {expected}",
        dem.cell_ew_m
    );
    assert!(
        (dem.cell_ns_m - expected).abs() < 1e-6,
        "{} vs {expected}",
        dem.cell_ns_m
    );
    assert!((dem.cell_ew_m - 5.0).abs() < 0.01, "{}", dem.cell_ew_m);
    assert!(
        dem.crs.contains("EPSG:3857") && dem.crs.contains("Web Mercator"),
        "{}",
        dem.crs
    );
}

/// Runs `f` on another thread, failing the test if it takes longer than `seconds` (a reader
/// that blocks on a FIFO would never return).
fn within<T: Send + 'static>(seconds: u64, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || tx.send(f()));
    rx.recv_timeout(std::time::Duration::from_secs(seconds))
        .expect("the reader hung")
}

/// A DEM or a sidecar that is a FIFO (or another special file) is refused at once, by name:
/// opening a FIFO would wait for a writer for ever.
#[cfg(unix)]
#[test]
fn special_files_as_dems_or_sidecars_are_refused_without_hanging() {
    let dir = tempfile::tempdir().unwrap();
    let mut cases: Vec<(PathBuf, PathBuf, &str)> = Vec::new();
    for name in ["fifo.tif", "fifo.png", "N37W123.hgt"] {
        let path = dir.path().join(name);
        common::mkfifo(&path);
        cases.push((path.clone(), path, "a FIFO"));
    }
    // A good PNG whose sidecar is a FIFO.
    let png = write_png_twin(dir.path(), "twin", SIZE, CELL, &grid(Sample::F32));
    let sidecar = dir.path().join("twin.json");
    std::fs::remove_file(&sidecar).unwrap();
    common::mkfifo(&sidecar);
    cases.push((png, sidecar, "a FIFO"));
    // A folder named like a DEM.
    let folder = dir.path().join("folder.tif");
    std::fs::create_dir(&folder).unwrap();
    cases.push((folder.clone(), folder, "a folder"));

    for (dem, blamed, kind) in cases {
        let err = within(10, {
            let dem = dem.clone();
            move || Dem::load(&dem).unwrap_err()
        });
        assert!(
            matches!(err, WorldError::NotARegularFile { .. }),
            "{}: {err}",
            dem.display()
        );
        assert_eq!(err.path(), Some(blamed.as_path()), "{err}");
        let text = err.to_string();
        assert!(text.starts_with(&blamed.display().to_string()), "{text}");
        assert!(text.contains(kind), "{text}");

        // The command line says the same, with status 1, and writes nothing.
        let out_dir = dir.path().join("out");
        let run = within(30, {
            let (dem, cwd) = (dem.clone(), dir.path().to_path_buf());
            move || {
                verdant(
                    &["bake", "--dem", dem.to_str().unwrap(), "--out", "out"],
                    &cwd,
                )
            }
        });
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains(&*blamed.to_string_lossy()), "{stderr}");
        assert!(stderr.contains(kind), "{stderr}");
        assert!(!out_dir.exists());
    }
}

/// A GeoTIFF or an SRTM tile carries its own heights and cells: when a bake refuses them (a
/// height beyond a planet's, a cell too fine for the bake), it blames the DEM itself, not a
/// sidecar that does not exist, and gives its figures short.
#[test]
fn implausible_heights_and_cells_of_a_dem_without_a_sidecar_blame_the_dem() {
    let dir = tempfile::tempdir().unwrap();
    let spike = dir.path().join("spike.tif");
    let mut heights = grid(Sample::F32);
    heights[5 * SIZE[0] as usize + 7] = 1e30;
    let spec = TiffSpec::new(Sample::F32, Layout::Strips { rows: 8 }, Compression::None);
    write_tiff(&spike, &spec, SIZE[0], SIZE[1], &heights);
    // Near the pole a cell is under a metre east-west and 93 m north-south.
    let polar = dir.path().join("N89W122.hgt");
    write_hgt(&polar, hgt_height);
    for (dem, says) in [
        (&spike, &["height 1.000e30 m at column 7, row 5"][..]),
        (
            &polar,
            &["its cells = 0.8123 x 93.0", "or pass --cell-size"][..],
        ),
    ] {
        let opts = BakeOptions {
            dem: dem.clone(),
            out: dir.path().join("out"),
            tile_cells: 16,
            stored_levels: 2,
            ..Default::default()
        };
        let err = bake(&opts, &mut |_, _, _| {}).unwrap_err();
        let message = err.to_string();
        assert_eq!(err.path(), Some(dem.as_path()), "{message}");
        assert!(
            !message.contains(".json") && !message.contains("height_offset_m"),
            "{message}"
        );
        for needle in says {
            assert!(message.contains(needle), "{message:?} lacks {needle:?}");
        }
    }
}
