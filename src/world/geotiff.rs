//! GeoTIFF DEMs: the TIFF container is read by the `tiff` crate (strips or tiles; no
//! compression, Deflate, LZW or PackBits; horizontal and floating-point predictors); this module
//! reads the GeoTIFF tags on top of it.
//!
//! - Uncompressed, Deflate, LZW, PackBits or Zstandard chunks.
//! - One band of uint8, int16, uint16, int32, float32 or float64.
//! - Class rasters (land cover, [`open_classes`]): one band of uint8 or uint16 class codes, read
//!   as integers, grayscale or with a colour table (a palette image's indices are its codes; the
//!   colours are not read), of any size, a window at a time: only the strips or tiles that hold
//!   the window are decoded. Their chunks are all decompressed here, since the `tiff` crate
//!   refuses to hand out a palette image's indices. Value rasters (density maps and masks,
//!   [`open_values`]) are read the same way, their samples as a DEM's heights.
//! - A palette image read as heights (a DEM, a density map, a mask) is refused before anything
//!   is decoded: its samples are class indices.
//! - Cell size from `ModelPixelScale` (with `ModelTiepoint` for the origin) or from an unrotated
//!   `ModelTransformation`. Rows are mapped north-up (a grid stored south row first is flipped).
//! - The GeoKey directory says whether the grid is projected (x/y in metres, or in feet, which
//!   are converted) or geographic (degrees: the cell size in metres is taken at the grid's
//!   centre latitude, east-west and north-south apart). Heights in feet (`VerticalUnitsGeoKey`)
//!   are converted to metres.
//! - Nodata from the `GDAL_NODATA` tag; NaN and infinite heights count as nodata too.
//!
//! Zstandard chunks (which the `tiff` crate reads only through the C library) are decompressed
//! here by `ruzstd`, whole, as LZW chunks are, rather than by the `tiff` crate: its streaming LZW
//! reader (weezl 0.1 with `yield_on_full_buffer`) can stop short of a chunk's end when one code
//! decodes to more bytes than a row holds, which happens in the flat, repetitive areas and the
//! padded edge tiles that real DEMs have.

use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use tiff::TiffError;
use tiff::decoder::{ChunkType, Decoder, DecodingResult, Limits};
use tiff::tags::{ByteOrder, Tag};

use super::dem_grid::{Dem, DemFormat, MAX_DEM_SAMPLES, check_grid_size, metres_per_degree};
use super::error::WorldError;

const FORMAT: &str = "GeoTIFF";

// GeoKey ids (GeoTIFF 1.1, section 7).
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const GEOG_ANGULAR_UNITS: u16 = 2054;
const PROJECTED_CS_TYPE: u16 = 3072;
/// EPSG codes of Web (pseudo-) Mercator: 3857, and 3785, its earlier number.
const WEB_MERCATOR: u16 = 3857;
const WEB_MERCATOR_OLD: u16 = 3785;
/// The sphere of Web Mercator, metres.
const WEB_MERCATOR_RADIUS_M: f64 = 6_378_137.0;
const PROJ_LINEAR_UNITS: u16 = 3076;
const PROJ_LINEAR_UNIT_SIZE: u16 = 3077;
const VERTICAL_UNITS: u16 = 4099;

/// Model types.
const MODEL_PROJECTED: u16 = 1;
const MODEL_GEOGRAPHIC: u16 = 2;
/// Raster type: a pixel's value holds at a point (not over an area).
const RASTER_PIXEL_IS_POINT: u16 = 2;
/// Angular unit: degree.
const ANGULAR_DEGREE: u16 = 9102;
/// PhotometricInterpretation of a palette (colour-mapped) image.
const PALETTE: u16 = 3;
/// A code that means "given by another key".
const USER_DEFINED: u16 = 32767;

/// What a GeoTIFF's samples are read as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reading {
    /// Heights (a DEM, or a density map or mask read as one): any sample type read.
    Heights,
    /// Class codes (a land-cover map): unsigned integers of at most 16 bits, grayscale or
    /// indices into a colour table.
    Classes,
}

/// What a GeoTIFF's header says: its size, sample type, compression and chunks.
struct Header {
    width: u32,
    height: u32,
    bits: u16,
    sample: SampleType,
    compression: u16,
    predictor: u16,
    chunks: Vec<(u64, u64)>,
}

/// Reads the header of the TIFF `decoder` reads (of `file_len` bytes), refusing what is not
/// read; `max_samples` bounds its size.
fn read_header<R: Read + Seek>(
    path: &Path,
    decoder: &mut Decoder<R>,
    file_len: u64,
    max_samples: u64,
    reading: Reading,
) -> Result<Header, WorldError> {
    let (width, height) = decoder.dimensions().map_err(|e| tiff_error(path, e))?;
    if width < 2 || height < 2 || u64::from(width) * u64::from(height) > max_samples {
        check_grid_size(path, u64::from(width), u64::from(height))?;
    }

    let mut tag_u16 = |tag: Tag| -> Result<Option<u16>, WorldError> {
        match decoder.find_tag(tag).map_err(|e| tiff_error(path, e))? {
            None => Ok(None),
            Some(v) => v
                .into_u16_vec()
                .ok()
                .and_then(|v| v.first().copied())
                .map(Some)
                .ok_or_else(|| corrupt(path, format!("tag {tag:?} is not a number"))),
        }
    };
    let bands = tag_u16(Tag::SamplesPerPixel)?.unwrap_or(1);
    if bands != 1 {
        let read = match reading {
            Reading::Heights => "only single-band elevation rasters are read",
            Reading::Classes => "a class map is one band of class codes",
        };
        return Err(unsupported(
            path,
            format!("{bands} bands (samples per pixel): {read}"),
        ));
    }
    // A palette image's samples are indices into its colour table: class codes, which only a
    // class map reads; as heights or values they would be nonsense, read without a word.
    let photometric = tag_u16(Tag::PhotometricInterpretation)?;
    if reading == Reading::Heights && photometric == Some(PALETTE) {
        return Err(unsupported(
            path,
            "a palette image (PhotometricInterpretation 3, RGBPalette): its samples are class \
             indices into a colour table, not heights or values (a land-cover map is given \
             with --land-cover; a DEM, a density map or a mask is a grayscale band)"
                .into(),
        ));
    }
    let bits = tag_u16(Tag::BitsPerSample)?.unwrap_or(1);
    let sample_format = tag_u16(Tag::SampleFormat)?.unwrap_or(1);
    let sample = match (reading, sample_format, bits) {
        (_, 1, 8) => SampleType::U8,
        (_, 1, 16) => SampleType::U16,
        (Reading::Heights, 2, 16) => SampleType::I16,
        (Reading::Heights, 2, 32) => SampleType::I32,
        (Reading::Heights, 3, 32) => SampleType::F32,
        (Reading::Heights, 3, 64) => SampleType::F64,
        (Reading::Heights, f, b) => {
            return Err(unsupported(
                path,
                format!(
                    "sample type {}: samples must be uint8, int16, uint16, int32, float32 or \
                     float64",
                    sample_type_name(f, b)
                ),
            ));
        }
        (Reading::Classes, f, b) => {
            return Err(WorldError::LandCover {
                path: path.to_path_buf(),
                what: "land cover",
                problem: format!(
                    "its band is {}: a land-cover map's band holds class codes as unsigned \
                     integers of 8 or 16 bits (uint8 or uint16, grayscale or with a colour \
                     table); convert it to whole class codes first (gdal_translate -ot UInt16, \
                     or -ot Byte for codes up to 255)",
                    sample_type_name(f, b)
                ),
            });
        }
    };
    // A class map is grayscale or colour-mapped; its colour table is not read (the indices are
    // the codes).
    if reading == Reading::Classes && !matches!(photometric, None | Some(0 | 1 | PALETTE)) {
        return Err(unsupported(
            path,
            format!(
                "photometric interpretation {}: a class map is grayscale (0 or 1) or indices \
                 into a colour table (3)",
                photometric.unwrap_or_default()
            ),
        ));
    }
    let compression = tag_u16(Tag::Compression)?.unwrap_or(1);
    if !matches!(compression, 1 | 5 | 8 | 32946 | 32773 | ZSTD) {
        return Err(unsupported(
            path,
            format!(
                "compression {} ({compression}): the baker reads uncompressed, Deflate, LZW, \
                 PackBits and Zstandard TIFFs (gdal_translate -co COMPRESS=DEFLATE converts one)",
                compression_name(compression)
            ),
        ));
    }
    let predictor = tag_u16(Tag::Predictor)?.unwrap_or(1);
    if !matches!(predictor, 1..=3) {
        return Err(unsupported(
            path,
            format!("predictor {predictor}: only none (1), horizontal (2) and floating point (3)"),
        ));
    }
    if predictor == 3 && !sample.is_float() {
        return Err(unsupported(
            path,
            format!("the floating-point predictor on {} samples", sample.name()),
        ));
    }
    let chunks = check_chunks_inside(path, decoder, file_len)?;
    Ok(Header {
        width,
        height,
        bits,
        sample,
        compression,
        predictor,
        chunks,
    })
}

/// The layout of the chunks of the image `decoder` reads.
/// The most bytes one chunk (tile or strip) may decode to: a tile of 16384 x 16384 samples of
/// 8 bytes, or a single strip of 23,000 x 23,000 samples of 4 bytes.
const MAX_CHUNK_BYTES: u64 = 2 << 30;

fn chunk_layout<R: Read + Seek>(
    path: &Path,
    decoder: &mut Decoder<R>,
    h: &Header,
) -> Result<ChunkLayout, WorldError> {
    let (width, height) = (h.width, h.height);
    let chunk_size = match decoder.get_chunk_type() {
        ChunkType::Tile => {
            let mut tag_u32 = |tag: Tag| -> Result<u32, WorldError> {
                decoder
                    .get_tag_u32(tag)
                    .map_err(|e| tiff_error(path, e))
                    .and_then(|v| {
                        if v == 0 {
                            Err(corrupt(path, format!("{tag:?} is 0")))
                        } else {
                            Ok(v)
                        }
                    })
            };
            [tag_u32(Tag::TileWidth)?, tag_u32(Tag::TileLength)?]
        }
        ChunkType::Strip => {
            let rows = match decoder
                .find_tag_unsigned::<u32>(Tag::RowsPerStrip)
                .map_err(|e| tiff_error(path, e))?
            {
                Some(0) | None => height,
                Some(r) => r.min(height),
            };
            [width, rows]
        }
    };
    // A chunk is decoded whole: its size is checked before anything is allocated for it.
    let chunk_bytes =
        u128::from(chunk_size[0]) * u128::from(chunk_size[1]) * u128::from(h.bits / 8);
    if chunk_bytes > u128::from(MAX_CHUNK_BYTES) {
        return Err(corrupt(
            path,
            format!(
                "chunks of {}x{} samples ({chunk_bytes} bytes decoded), at most {} MiB a chunk",
                chunk_size[0],
                chunk_size[1],
                MAX_CHUNK_BYTES >> 20
            ),
        ));
    }
    Ok(ChunkLayout {
        width,
        height,
        chunk_size,
        sample_bytes: usize::from(h.bits / 8),
        big_endian: decoder.byte_order() == ByteOrder::BigEndian,
        predictor: h.predictor,
    })
}

fn limits() -> Limits {
    let mut limits = Limits::default();
    limits.decoding_buffer_size = (MAX_DEM_SAMPLES * 8) as usize;
    limits.ifd_value_size = 64 << 20;
    limits
}

/// Reads a GeoTIFF DEM; nodata samples become NaN.
pub(crate) fn load(path: &Path, cell_override: Option<[f64; 2]>) -> Result<Dem, WorldError> {
    let (file, file_len) = super::format::open_regular(path)?;
    let mut decoder = Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits());
    let header = read_header(
        path,
        &mut decoder,
        file_len,
        MAX_DEM_SAMPLES,
        Reading::Heights,
    )?;
    let Header {
        width,
        height,
        bits: _,
        sample,
        compression,
        predictor: _,
        ref chunks,
    } = header;

    let geo = GeoTags::read(path, &mut decoder)?;
    let values = if compression == 5 || compression == ZSTD {
        let layout = chunk_layout(path, &mut decoder, &header)?;
        let codec = if compression == ZSTD {
            Codec::Zstd
        } else {
            Codec::Lzw
        };
        let bits = decode_chunks(path, &layout, chunks, codec)?;
        sample.typed(bits)
    } else {
        decoder.read_image().map_err(|e| tiff_error(path, e))?
    };
    let mut raw = heights_of(path, values, sample, geo.nodata, geo.vertical_unit_m)?;
    let (w, h) = (width as usize, height as usize);
    if raw.len() != w * h {
        return Err(corrupt(
            path,
            format!("{} samples decoded, {w}x{h} expected", raw.len()),
        ));
    }

    let grid = geo.grid(path, width, height, cell_override.is_some())?;
    north_up(&mut raw, w, grid.flip_rows, grid.flip_cols);
    let [cell_ew_m, cell_ns_m] = cell_override.unwrap_or(grid.cell_m);
    Ok(Dem {
        width,
        height,
        cell_ew_m,
        cell_ns_m,
        heights: raw,
        place: String::new(),
        source: format!(
            "{} GeoTIFF, compression {}",
            sample.name(),
            compression_name(compression)
        ),
        format: DemFormat::Geotiff,
        crs: grid.crs,
        origin: grid.origin,
        pixel_size: grid.pixel_size,
        nodata_filled: 0,
    })
}

/// A GeoTIFF map opened by [`open_classes`] (class codes: a land-cover map) or [`open_values`]
/// (values: a density map or a mask): its size and where it lies, read from its header; its
/// samples are read a window at a time ([`MapTiff::read_classes`], [`MapTiff::read_values`]),
/// only the strips or tiles that hold the window decoded.
pub(crate) struct MapTiff {
    pub width: u32,
    pub height: u32,
    /// The coordinate system's description (empty without georeferencing).
    pub crs: String,
    /// The south-west sample's coordinates, where the file is georeferenced.
    pub origin: Option<[f64; 2]>,
    /// Spacing in the coordinate system's units (x, y), where the file is georeferenced.
    pub pixel_size: Option<[f64; 2]>,
    path: PathBuf,
    reading: Reading,
    layout: ChunkLayout,
    chunks: Vec<(u64, u64)>,
    codec: Codec,
    /// The file's nodata code (`GDAL_NODATA`), where it is a whole number (class codes).
    nodata_code: Option<u64>,
    /// How a sample becomes a value (values).
    to_value: ToHeight,
    flip_rows: bool,
    flip_cols: bool,
}

/// Opens a GeoTIFF of class codes: one band of uint8 or uint16, grayscale or indices into a
/// colour table. Another sample type is refused before anything is decoded, naming it and what
/// is read. A file without (usable) georeferencing is read as a bare grid (no origin or pixel
/// size). The map may be of any size: nothing is decoded until a window is read.
pub(crate) fn open_classes(path: &Path) -> Result<MapTiff, WorldError> {
    open_map(path, Reading::Classes)
}

/// Opens a GeoTIFF of values (a density map or a mask): one band of any sample type a DEM may
/// have, read as a DEM's heights are (nodata, NaN and infinities are no value); a palette image
/// is refused before anything is decoded. Otherwise as [`open_classes`].
pub(crate) fn open_values(path: &Path) -> Result<MapTiff, WorldError> {
    open_map(path, Reading::Heights)
}

fn open_map(path: &Path, reading: Reading) -> Result<MapTiff, WorldError> {
    let (file, file_len) = super::format::open_regular(path)?;
    let mut decoder = Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits());
    // Its size is bounded by the window read, not here.
    let header = read_header(path, &mut decoder, file_len, u64::MAX, reading)?;
    let layout = chunk_layout(path, &mut decoder, &header)?;
    let geo = GeoTags::read(path, &mut decoder)?;
    let (width, height) = (header.width, header.height);
    let grid = match geo.grid(path, width, height, false) {
        Err(WorldError::NoGeoreference { .. }) => geo.grid(path, width, height, true)?,
        other => other?,
    };
    let nodata_code = geo
        .nodata
        .filter(|n| n.fract() == 0.0 && *n >= 0.0 && *n <= f64::from(u32::MAX))
        .map(|n| n as u64);
    Ok(MapTiff {
        width,
        height,
        crs: grid.crs,
        origin: grid.origin,
        pixel_size: grid.pixel_size,
        path: path.to_path_buf(),
        reading,
        layout,
        chunks: header.chunks,
        // The `tiff` crate reads no palette image's indices, so every codec is decoded here.
        codec: Codec::of(header.compression),
        nodata_code,
        to_value: ToHeight::new(header.sample, geo.nodata, geo.vertical_unit_m),
        flip_rows: grid.flip_rows,
        flip_cols: grid.flip_cols,
    })
}

impl MapTiff {
    /// The most bytes reading a window takes beside the window itself: the largest chunk's
    /// bytes as stored, one chunk decoded (a chunk is decoded whole), and a row of it while
    /// its predictor is undone.
    pub(crate) fn chunk_read_bytes(&self) -> u64 {
        let [w, h] = self.layout.chunk_size.map(u64::from);
        let sample = self.layout.sample_bytes as u64;
        let stored = self.chunks.iter().map(|c| c.1).max().unwrap_or(0);
        stored + w * h * sample + w * sample
    }

    /// The class codes of the window of `size` samples (columns, rows) whose north-west sample
    /// is `first` (column from the west, row from the north), row 0 north, west first; `None`
    /// where the file's nodata is (codes are of 8 or 16 bits: 4 bytes a sample are held).
    /// Only the strips or tiles that hold the window are read and decoded, one at a time: what
    /// is held is the window and one chunk. Only for a map opened by [`open_classes`].
    pub(crate) fn read_classes(
        &self,
        first: [usize; 2],
        size: [usize; 2],
    ) -> Result<Vec<Option<u16>>, WorldError> {
        assert_eq!(self.reading, Reading::Classes, "a class map");
        let nodata = self.nodata_code;
        self.read_window(first, size, |v| (Some(v) != nodata).then_some(v as u16))
    }

    /// The values of a window (as [`MapTiff::read_classes`]), each as a DEM's height would be
    /// (NaN where the file's nodata is, or the sample is NaN or infinite), kept as what `keep`
    /// makes of it: what is held is the window of `T` and one chunk. Only for a map opened by
    /// [`open_values`].
    pub(crate) fn read_values<T: Clone + Default>(
        &self,
        first: [usize; 2],
        size: [usize; 2],
        keep: impl Fn(f32) -> T,
    ) -> Result<Vec<T>, WorldError> {
        assert_eq!(self.reading, Reading::Heights, "a map of values");
        let to = self.to_value;
        self.read_window(first, size, |v| keep(to.of_bits(v)))
    }

    /// The window of `size` samples whose north-west sample is `first`, row 0 north, each
    /// sample's bit pattern made into what `each` makes of it.
    fn read_window<T: Clone + Default>(
        &self,
        first: [usize; 2],
        size: [usize; 2],
        each: impl Fn(u64) -> T,
    ) -> Result<Vec<T>, WorldError> {
        let [cols, rows] = [
            [first[0], first[0] + size[0]],
            [first[1], first[1] + size[1]],
        ];
        assert!(
            cols[1] <= self.width as usize && rows[1] <= self.height as usize,
            "a window inside the map"
        );
        let (mut file, _) = super::format::open_regular(&self.path)?;
        let mut read = |offset: u64, count: u64| read_chunk(&self.path, &mut file, offset, count);
        decode_window_north_up(
            &self.path,
            &self.layout,
            &self.chunks,
            self.codec,
            &mut read,
            [self.flip_cols, self.flip_rows],
            [cols, rows],
            each,
        )
    }
}

/// The samples of columns `cols` and rows `rows` (`window`, from the west and the north, ends
/// exclusive) of an image stored east first or south first (`flip`: columns, rows), west first
/// and north first, each sample's bit pattern made into what `each` makes of it. Only the
/// strips or tiles that hold the window are read (by `read(offset, count)`) and decoded, one
/// at a time: what is held is the window and one chunk.
#[allow(clippy::too_many_arguments)]
fn decode_window_north_up<T: Clone + Default>(
    path: &Path,
    layout: &ChunkLayout,
    chunks: &[(u64, u64)],
    codec: Codec,
    read: &mut dyn FnMut(u64, u64) -> Result<Vec<u8>, WorldError>,
    flip: [bool; 2],
    window: [[usize; 2]; 2],
    each: impl Fn(u64) -> T,
) -> Result<Vec<T>, WorldError> {
    let (w, h) = (layout.width as usize, layout.height as usize);
    let [cols, rows] = window;
    // The window as the file stores it.
    let stored_cols = if flip[0] {
        [w - cols[1], w - cols[0]]
    } else {
        cols
    };
    let stored_rows = if flip[1] {
        [h - rows[1], h - rows[0]]
    } else {
        rows
    };
    let ww = cols[1] - cols[0];
    let mut out = vec![T::default(); ww * (rows[1] - rows[0])];
    decode_window(
        path,
        layout,
        chunks,
        codec,
        read,
        [stored_cols, stored_rows],
        &mut |r, c, bits| {
            let at = r * ww + c;
            for (o, &v) in out[at..at + bits.len()].iter_mut().zip(bits) {
                *o = each(v);
            }
        },
    )?;
    north_up(&mut out, ww.max(1), flip[1], flip[0]);
    Ok(out)
}

/// The GeoTIFF tags of the first image.
struct GeoTags {
    pixel_scale: Option<Vec<f64>>,
    tiepoint: Option<Vec<f64>>,
    transformation: Option<Vec<f64>>,
    keys: Option<GeoKeys>,
    nodata: Option<f64>,
    /// Metres per unit of the heights.
    vertical_unit_m: f64,
}

/// The GeoKey directory, with its short values (double and ASCII values are not needed).
struct GeoKeys {
    shorts: Vec<(u16, u16)>,
    doubles: Vec<(u16, f64)>,
}

impl GeoKeys {
    fn short(&self, id: u16) -> Option<u16> {
        self.shorts.iter().find(|(k, _)| *k == id).map(|(_, v)| *v)
    }

    fn double(&self, id: u16) -> Option<f64> {
        self.doubles.iter().find(|(k, _)| *k == id).map(|(_, v)| *v)
    }
}

/// Where the grid lies and how far apart its samples are.
struct GridPlacement {
    cell_m: [f64; 2],
    flip_rows: bool,
    flip_cols: bool,
    crs: String,
    origin: Option<[f64; 2]>,
    /// Spacing in the coordinate system's units (x, y).
    pixel_size: Option<[f64; 2]>,
}

impl GeoTags {
    fn read<R: Read + Seek>(path: &Path, d: &mut Decoder<R>) -> Result<GeoTags, WorldError> {
        let mut doubles = |tag: Tag| -> Result<Option<Vec<f64>>, WorldError> {
            match d.find_tag(tag).map_err(|e| tiff_error(path, e))? {
                None => Ok(None),
                Some(v) => v
                    .into_f64_vec()
                    .map(Some)
                    .map_err(|_| corrupt(path, format!("tag {tag:?} does not hold numbers"))),
            }
        };
        let pixel_scale = doubles(Tag::ModelPixelScaleTag)?;
        let tiepoint = doubles(Tag::ModelTiepointTag)?;
        let transformation = doubles(Tag::ModelTransformationTag)?;
        let double_params = doubles(Tag::GeoDoubleParamsTag)?.unwrap_or_default();
        let directory =
            match d
                .find_tag(Tag::GeoKeyDirectoryTag)
                .map_err(|e| tiff_error(path, e))?
            {
                None => None,
                Some(v) => Some(v.into_u16_vec().map_err(|_| {
                    corrupt(path, "the GeoKey directory does not hold shorts".into())
                })?),
            };
        let keys = directory
            .map(|dir| parse_geokeys(path, &dir, &double_params))
            .transpose()?;
        let nodata = match d
            .find_tag(Tag::GdalNodata)
            .map_err(|e| tiff_error(path, e))?
        {
            None => None,
            Some(v) => {
                let text = v
                    .into_string()
                    .map_err(|_| corrupt(path, "GDAL_NODATA is not text".into()))?;
                let text = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
                Some(text.parse::<f64>().map_err(|_| {
                    corrupt(path, format!("GDAL_NODATA \"{text}\" is not a number"))
                })?)
            }
        };
        let vertical_unit_m = match keys.as_ref().and_then(|k| k.short(VERTICAL_UNITS)) {
            None | Some(9001) => 1.0,
            Some(code) => linear_unit_m(code).ok_or_else(|| {
                unsupported(
                    path,
                    format!(
                        "vertical unit code {code}: metres (9001) and feet (9002, 9003) are read"
                    ),
                )
            })?,
        };
        Ok(GeoTags {
            pixel_scale,
            tiepoint,
            transformation,
            keys,
            nodata,
            vertical_unit_m,
        })
    }

    /// The cell size, orientation and coordinate system. With `have_override`, a TIFF without
    /// (usable) geo tags is fine: the caller gives the cell size.
    fn grid(
        &self,
        path: &Path,
        width: u32,
        height: u32,
        have_override: bool,
    ) -> Result<GridPlacement, WorldError> {
        // Model units per column (x) and per row (y, negative for north-up), and the model
        // coordinates of the raster's (0, 0) corner.
        let affine: Option<([f64; 2], Option<[f64; 2]>)> =
            match (&self.pixel_scale, &self.tiepoint, &self.transformation) {
                (Some(s), tie, _) if s.len() >= 2 => {
                    let origin = tie
                        .as_ref()
                        .filter(|t| t.len() >= 6)
                        .map(|t| [t[3] - t[0] * s[0], t[4] + t[1] * s[1]]);
                    Some(([s[0], -s[1]], origin))
                }
                (_, _, Some(m)) if m.len() >= 16 => {
                    if m[1] != 0.0 || m[4] != 0.0 {
                        return Err(unsupported(
                            path,
                            "a rotated or sheared grid (ModelTransformation with rotation terms): \
                         warp it north-up first (gdalwarp)"
                                .into(),
                        ));
                    }
                    Some(([m[0], m[5]], Some([m[3], m[7]])))
                }
                _ => None,
            };
        let Some((step, corner)) = affine else {
            if have_override {
                return Ok(GridPlacement {
                    cell_m: [1.0, 1.0],
                    flip_rows: false,
                    flip_cols: false,
                    crs: String::new(),
                    origin: None,
                    pixel_size: None,
                });
            }
            return Err(WorldError::NoGeoreference {
                path: path.to_path_buf(),
                problem: "the TIFF has no GeoTIFF cell size (no ModelPixelScale or \
                          ModelTransformation tag)"
                    .into(),
            });
        };
        if !step.iter().all(|s| s.is_finite() && *s != 0.0) {
            return Err(corrupt(
                path,
                format!("the pixel size {} x {} is not usable", step[0], step[1]),
            ));
        }
        let corner = corner.filter(|c| c.iter().all(|v| v.is_finite()));
        let keys = self.keys.as_ref();
        let half = match keys.and_then(|k| k.short(GT_RASTER_TYPE)) {
            Some(RASTER_PIXEL_IS_POINT) => 0.0,
            _ => 0.5,
        };
        let (w, h) = (f64::from(width), f64::from(height));
        // Model coordinates of the sample at raster (column, row).
        let at = |c: [f64; 2], col: f64, row: f64| {
            [c[0] + (col + half) * step[0], c[1] + (row + half) * step[1]]
        };
        let west_col = if step[0] > 0.0 { 0.0 } else { w - 1.0 };
        let south_row = if step[1] < 0.0 { h - 1.0 } else { 0.0 };
        let origin = corner.map(|c| at(c, west_col, south_row));
        let centre = corner.map(|c| at(c, (w - 1.0) / 2.0, (h - 1.0) / 2.0));
        let flip_rows = step[1] > 0.0;
        let flip_cols = step[0] < 0.0;
        let size = [step[0].abs(), step[1].abs()];

        let model = keys.and_then(|k| {
            k.short(GT_MODEL_TYPE).or_else(|| {
                if k.short(PROJECTED_CS_TYPE).is_some() {
                    Some(MODEL_PROJECTED)
                } else if k.short(GEOGRAPHIC_TYPE).is_some() {
                    Some(MODEL_GEOGRAPHIC)
                } else {
                    None
                }
            })
        });
        let place = |cell_m: [f64; 2], crs: String| GridPlacement {
            cell_m,
            flip_rows,
            flip_cols,
            crs,
            origin,
            pixel_size: Some(size),
        };
        match (model, keys) {
            (Some(MODEL_GEOGRAPHIC), Some(k)) => {
                match k.short(GEOG_ANGULAR_UNITS) {
                    None | Some(ANGULAR_DEGREE) => {}
                    Some(code) => {
                        return Err(unsupported(
                            path,
                            format!("angular unit code {code}: only degrees (9102) are read"),
                        ));
                    }
                }
                let crs = match k.short(GEOGRAPHIC_TYPE) {
                    Some(code) if code != USER_DEFINED => {
                        format!("EPSG:{code}, geographic (degrees)")
                    }
                    _ => "geographic (degrees)".into(),
                };
                let Some([_, lat]) = centre else {
                    if have_override {
                        return Ok(place([1.0, 1.0], crs));
                    }
                    return Err(WorldError::NoGeoreference {
                        path: path.to_path_buf(),
                        problem: "the geographic grid has no ModelTiepoint, so its latitude".into(),
                    });
                };
                if !(-90.0..=90.0).contains(&lat) {
                    return Err(corrupt(
                        path,
                        format!("the grid's centre latitude {lat} degrees is off the globe"),
                    ));
                }
                if !(-89.0..=89.0).contains(&lat) {
                    return Err(unsupported(
                        path,
                        format!(
                            "a geographic grid centred at latitude {lat} degrees, within a degree \
                             of the pole, where degrees of longitude shrink too fast to read as \
                             a flat grid: reproject it to metres first (gdalwarp -t_srs with a \
                             polar projection)"
                        ),
                    ));
                }
                let [m_ew, m_ns] = metres_per_degree(lat);
                Ok(place([size[0] * m_ew, size[1] * m_ns], crs))
            }
            (Some(MODEL_PROJECTED), Some(k)) => {
                let (unit_m, unit_name) = match k.short(PROJ_LINEAR_UNITS) {
                    Some(9001) => (1.0, "metres"),
                    Some(USER_DEFINED) => match k.double(PROJ_LINEAR_UNIT_SIZE) {
                        Some(m) if m.is_finite() && m > 0.0 => (m, "user-defined units"),
                        _ => {
                            return Err(corrupt(
                                path,
                                "user-defined linear units without ProjLinearUnitSizeGeoKey".into(),
                            ));
                        }
                    },
                    Some(code) => match linear_unit_m(code) {
                        Some(m) => (m, "feet, converted to metres"),
                        None => {
                            return Err(unsupported(
                                path,
                                format!(
                                    "linear unit code {code}: metres (9001) and feet (9002, 9003) \
                                     are read"
                                ),
                            ));
                        }
                    },
                    None => (1.0, "linear units not stated, taken as metres"),
                };
                let code = k.short(PROJECTED_CS_TYPE);
                // Web Mercator's metres are metres at the equator: on the ground a cell is
                // cos(latitude) as long, taken at the grid's centre.
                if let (Some(WEB_MERCATOR | WEB_MERCATOR_OLD), Some([_, y])) = (code, centre) {
                    let lat = (y * unit_m / WEB_MERCATOR_RADIUS_M).sinh().atan();
                    let scale = unit_m * lat.cos();
                    let crs = format!(
                        "EPSG:{}, Web Mercator ({unit_name}; cells scaled by cos({:.4} deg) to \
                         ground metres at the grid's centre)",
                        code.unwrap_or(WEB_MERCATOR),
                        lat.to_degrees()
                    );
                    return Ok(place([size[0] * scale, size[1] * scale], crs));
                }
                let crs = match code {
                    Some(code) if code != USER_DEFINED => {
                        format!("EPSG:{code}, projected ({unit_name})")
                    }
                    _ => format!("projected ({unit_name})"),
                };
                Ok(place([size[0] * unit_m, size[1] * unit_m], crs))
            }
            (Some(other), Some(_)) if !have_override => Err(unsupported(
                path,
                format!(
                    "model type {other} (neither projected, 1, nor geographic, 2): \
                     reproject the DEM first"
                ),
            )),
            _ if have_override => Ok(place([1.0, 1.0], String::new())),
            (_, Some(_)) => Err(WorldError::NoGeoreference {
                path: path.to_path_buf(),
                problem: "the TIFF's GeoKey directory lacks its model type (GTModelTypeGeoKey, \
                          1024; nor has it a ProjectedCSTypeGeoKey or GeographicTypeGeoKey), \
                          which says whether the grid is in metres, feet or degrees"
                    .into(),
            }),
            (_, None) => Err(WorldError::NoGeoreference {
                path: path.to_path_buf(),
                problem: "the TIFF has a pixel size but no GeoKey directory saying whether it \
                          is in metres, feet or degrees"
                    .into(),
            }),
        }
    }
}

/// Parses the GeoKey directory: a header (version, revision, minor revision, key count) and
/// four shorts per key (id, tag holding the value or 0 for the short itself, count, value or
/// index).
fn parse_geokeys(path: &Path, dir: &[u16], doubles: &[f64]) -> Result<GeoKeys, WorldError> {
    if dir.len() < 4 || dir[0] != 1 {
        return Err(corrupt(
            path,
            "the GeoKey directory lacks its header (version 1)".into(),
        ));
    }
    let count = usize::from(dir[3]);
    let entries = dir.get(4..4 + 4 * count).ok_or_else(|| {
        corrupt(
            path,
            format!("the GeoKey directory announces {count} keys but is shorter"),
        )
    })?;
    let mut keys = GeoKeys {
        shorts: Vec::new(),
        doubles: Vec::new(),
    };
    for e in entries.chunks_exact(4) {
        let (id, location, value) = (e[0], e[1], e[3]);
        match location {
            0 => keys.shorts.push((id, value)),
            34736 => {
                if let Some(&v) = doubles.get(usize::from(value)) {
                    keys.doubles.push((id, v));
                }
            }
            _ => {}
        }
    }
    Ok(keys)
}

/// Metres per unit of the EPSG linear unit `code`, for metres and the feet.
fn linear_unit_m(code: u16) -> Option<f64> {
    match code {
        9001 => Some(1.0),
        9002 => Some(0.3048),
        9003 => Some(1200.0 / 3937.0),
        _ => None,
    }
}

/// A sample type by its TIFF sample format and bits: `uint8`, `float32`, `int32`.
fn sample_type_name(format: u16, bits: u16) -> String {
    let kind = match format {
        1 => "uint",
        2 => "int",
        3 => "float",
        _ => return format!("sample format {format} of {bits} bits"),
    };
    format!("{kind}{bits}")
}

fn compression_name(code: u16) -> &'static str {
    match code {
        1 => "none",
        2 => "CCITT RLE",
        3 | 4 => "CCITT fax",
        5 => "LZW",
        6 | 7 => "JPEG",
        8 | 32946 => "Deflate",
        32773 => "PackBits",
        34712 => "JPEG 2000",
        34887 => "LERC",
        34925 => "LZMA",
        50000 => "Zstandard",
        50001 => "WebP",
        _ => "unknown",
    }
}

/// Refuses a file whose strips or tiles reach past its end (a truncated download), with the
/// chunk named, before any decoding. Returns each chunk's offset and byte count.
fn check_chunks_inside<R: Read + Seek>(
    path: &Path,
    d: &mut Decoder<R>,
    file_len: u64,
) -> Result<Vec<(u64, u64)>, WorldError> {
    let (kind, offsets_tag, counts_tag) = match d.get_chunk_type() {
        ChunkType::Strip => ("strip", Tag::StripOffsets, Tag::StripByteCounts),
        ChunkType::Tile => ("tile", Tag::TileOffsets, Tag::TileByteCounts),
    };
    let mut list = |tag: Tag| -> Result<Vec<u64>, WorldError> {
        d.get_tag_u64_vec(tag).map_err(|e| tiff_error(path, e))
    };
    let offsets = list(offsets_tag)?;
    let counts = list(counts_tag)?;
    for (i, (&o, &n)) in offsets.iter().zip(&counts).enumerate() {
        let end = o.saturating_add(n);
        if end > file_len {
            return Err(corrupt(
                path,
                format!("{kind} {i} ends at byte {end}, but the file has only {file_len} bytes"),
            ));
        }
    }
    if offsets.len() != counts.len() {
        return Err(corrupt(
            path,
            format!(
                "{} {kind} offsets but {} byte counts",
                offsets.len(),
                counts.len()
            ),
        ));
    }
    Ok(offsets.into_iter().zip(counts).collect())
}

/// How the samples of a single-band image lie in its chunks.
struct ChunkLayout {
    width: u32,
    height: u32,
    /// Samples per chunk row and rows per chunk (a tile's size, or the image width and the
    /// rows per strip).
    chunk_size: [u32; 2],
    sample_bytes: usize,
    big_endian: bool,
    predictor: u16,
}

/// Decompresses every LZW chunk whole and undoes its predictor; returns each sample's bit
/// pattern (in the low `sample_bytes` bytes), row 0 first.
/// The TIFF compression code of Zstandard.
const ZSTD: u16 = 50000;

/// The codecs whose chunks are decompressed here, whole.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Codec {
    None,
    Deflate,
    PackBits,
    Lzw,
    Zstd,
}

impl Codec {
    /// The codec of a TIFF compression code that [`read_header`] accepted.
    fn of(compression: u16) -> Codec {
        match compression {
            1 => Codec::None,
            5 => Codec::Lzw,
            8 | 32946 => Codec::Deflate,
            32773 => Codec::PackBits,
            _ => Codec::Zstd,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Codec::None => "uncompressed",
            Codec::Deflate => "Deflate",
            Codec::PackBits => "PackBits",
            Codec::Lzw => "LZW",
            Codec::Zstd => "Zstandard",
        }
    }

    /// The chunk's bytes, at most `limit` of them (a chunk never holds more; a stream that
    /// would is cut there and found short or long by the caller).
    fn decode(self, packed: &[u8], limit: usize) -> Result<Vec<u8>, String> {
        match self {
            Codec::None => Ok(packed[..packed.len().min(limit)].to_vec()),
            Codec::Deflate => {
                miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(packed, limit)
                    .map_err(|e| format!("{:?}", e.status))
            }
            Codec::PackBits => {
                // Grown as the runs come: a chunk's claimed size costs nothing until its
                // bytes are there.
                let mut out = Vec::new();
                let mut i = 0;
                while i < packed.len() && out.len() < limit {
                    let n = packed[i] as i8;
                    i += 1;
                    if n >= 0 {
                        let end = (i + n as usize + 1).min(packed.len());
                        out.extend_from_slice(&packed[i..end]);
                        i = end;
                    } else if n != -128 {
                        let Some(&b) = packed.get(i) else { break };
                        out.extend(std::iter::repeat_n(b, (1 - isize::from(n)) as usize));
                        i += 1;
                    }
                }
                out.truncate(limit);
                Ok(out)
            }
            Codec::Lzw => {
                // Into a buffer of at most the chunk's size, grown as the codes fill it: what
                // they would expand to beyond it (a small file can claim gigabytes) is never
                // produced, and a chunk's claimed size costs nothing until its bytes are there.
                let mut decoder =
                    weezl::decode::Decoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8);
                let mut out = vec![0u8; limit.min(packed.len().saturating_mul(4).max(1 << 16))];
                let (mut input, mut filled) = (packed, 0);
                while filled < limit {
                    if filled == out.len() {
                        out.resize(limit.min(out.len() * 2), 0);
                    }
                    let step = decoder.decode_bytes(input, &mut out[filled..]);
                    input = &input[step.consumed_in..];
                    filled += step.consumed_out;
                    match step.status.map_err(|e| format!("{e:?}"))? {
                        weezl::LzwStatus::Done => break,
                        weezl::LzwStatus::NoProgress => {
                            return Err("the data ends without an end code".into());
                        }
                        weezl::LzwStatus::Ok => {}
                    }
                }
                out.truncate(filled);
                Ok(out)
            }
            Codec::Zstd => {
                let decoder =
                    ruzstd::decoding::StreamingDecoder::new(packed).map_err(|e| e.to_string())?;
                let mut out = Vec::new();
                std::io::Read::read_to_end(&mut decoder.take(limit as u64 + 1), &mut out)
                    .map_err(|e| e.to_string())?;
                Ok(out)
            }
        }
    }
}

/// `count` bytes of `file` from `offset` (a chunk's packed bytes).
fn read_chunk(
    path: &Path,
    file: &mut std::fs::File,
    offset: u64,
    count: u64,
) -> Result<Vec<u8>, WorldError> {
    let mut packed = vec![0u8; count as usize];
    file.seek(SeekFrom::Start(offset))
        .and_then(|_| file.read_exact(&mut packed))
        .map_err(|e| WorldError::io(path, e))?;
    Ok(packed)
}

fn decode_chunks(
    path: &Path,
    layout: &ChunkLayout,
    chunks: &[(u64, u64)],
    codec: Codec,
) -> Result<Vec<u64>, WorldError> {
    let (mut file, _) = super::format::open_regular(path)?;
    let mut read = |offset: u64, count: u64| read_chunk(path, &mut file, offset, count);
    decode_rows(
        path,
        layout,
        chunks,
        codec,
        &mut read,
        [0, layout.height as usize],
    )
}

/// Decodes the chunks that hold image rows `rows` (from the first row stored, end exclusive),
/// their bytes read by `read(offset, count)`; returns those rows' samples' bit patterns (in the
/// low `sample_bytes` bytes), first row first.
fn decode_rows(
    path: &Path,
    layout: &ChunkLayout,
    chunks: &[(u64, u64)],
    codec: Codec,
    read: &mut dyn FnMut(u64, u64) -> Result<Vec<u8>, WorldError>,
    rows: [usize; 2],
) -> Result<Vec<u64>, WorldError> {
    let w = layout.width as usize;
    let mut out = vec![0u64; w * (rows[1] - rows[0])];
    decode_window(
        path,
        layout,
        chunks,
        codec,
        read,
        [[0, w], rows],
        &mut |r, c, bits| {
            let at = r * w + c;
            out[at..at + bits.len()].copy_from_slice(bits);
        },
    )?;
    Ok(out)
}

/// Decodes the chunks that hold the window of image columns `window[0]` and rows `window[1]`
/// (as stored: from the first column and row stored, ends exclusive), one at a time, their
/// bytes read by `read(offset, count)`, and hands each chunk row's part of the window to
/// `put(row, column, samples)` (row and column in the window; each sample's bit pattern in the
/// low `sample_bytes` bytes). A strip is decoded whole (it spans every column); a tile outside
/// the window is not read.
fn decode_window(
    path: &Path,
    layout: &ChunkLayout,
    chunks: &[(u64, u64)],
    codec: Codec,
    read: &mut dyn FnMut(u64, u64) -> Result<Vec<u8>, WorldError>,
    window: [[usize; 2]; 2],
    put: &mut dyn FnMut(usize, usize, &[u64]),
) -> Result<(), WorldError> {
    let [cols, rows] = window;
    let [cw, ch] = layout.chunk_size.map(|v| v as usize);
    let (w, h) = (layout.width as usize, layout.height as usize);
    let across = w.div_ceil(cw);
    let expected = across * h.div_ceil(ch);
    if chunks.len() < expected {
        return Err(corrupt(
            path,
            format!("{} chunks, {expected} expected", chunks.len()),
        ));
    }
    if cols[0] >= cols[1] || rows[0] >= rows[1] {
        return Ok(());
    }
    let b = layout.sample_bytes;
    let mask = if b == 8 {
        u64::MAX
    } else {
        (1u64 << (8 * b)) - 1
    };
    // A chunk row's samples from its first column to the window's last in it (the horizontal
    // predictor sums from the chunk's first column), only the window's kept: a strip spans the
    // image, which may be far wider than the window.
    let mut row: Vec<u64> = Vec::with_capacity(cw.min(cols[1] - cols[0]));
    let mut plane: Vec<u8> = Vec::new();
    for ty in rows[0] / ch..rows[1].div_ceil(ch) {
        for tx in cols[0] / cw..cols[1].div_ceil(cw) {
            let index = ty * across + tx;
            let (offset, count) = chunks[index];
            let (x0, y0) = (tx * cw, ty * ch);
            let packed = read(offset, count)?;
            let chunk_rows = ch.min(h - y0);
            let data = codec
                .decode(&packed, cw * ch * b)
                .map_err(|e| corrupt(path, format!("{} chunk {index}: {e}", codec.name())))?;
            drop(packed);
            if data.len() < chunk_rows * cw * b {
                return Err(corrupt(
                    path,
                    format!(
                        "{} chunk {index} holds {} bytes, {} expected",
                        codec.name(),
                        data.len(),
                        chunk_rows * cw * b
                    ),
                ));
            }
            // The window's columns in this chunk.
            let (xa, xb) = (cols[0].max(x0), cols[1].min(x0 + cw).min(w));
            for (r, bytes) in data.chunks_exact(cw * b).take(chunk_rows).enumerate() {
                let y = y0 + r;
                if y < rows[0] || y >= rows[1] {
                    continue;
                }
                let [from, to] = [xa - x0, xb - x0];
                row.clear();
                if layout.predictor == 3 {
                    // Floating-point predictor: byte differences along the row, over byte
                    // planes (most significant first).
                    plane.clear();
                    plane.extend_from_slice(bytes);
                    for j in 1..plane.len() {
                        plane[j] = plane[j].wrapping_add(plane[j - 1]);
                    }
                    row.extend((from..to).map(|i| {
                        (0..b).fold(0, |acc, k| (acc << 8) | u64::from(plane[k * cw + i]))
                    }));
                } else {
                    let value = |s: &[u8]| {
                        if layout.big_endian {
                            s.iter().fold(0, |acc, &x| (acc << 8) | u64::from(x))
                        } else {
                            s.iter().rev().fold(0, |acc, &x| (acc << 8) | u64::from(x))
                        }
                    };
                    let samples = bytes.chunks_exact(b).map(value);
                    if layout.predictor == 2 {
                        // Each sample is the sum of the differences before it.
                        let mut sum = 0u64;
                        for (i, d) in samples.take(to).enumerate() {
                            sum = sum.wrapping_add(d) & mask;
                            if i >= from {
                                row.push(sum);
                            }
                        }
                    } else {
                        row.extend(samples.skip(from).take(to - from));
                    }
                }
                put(y - rows[0], xa - cols[0], &row);
            }
        }
    }
    Ok(())
}

/// How a sample becomes a height in metres (or a map's value): nodata (the value as the file's
/// own type would hold it, so that a float32 grid with nodata "-3.4028234663852886e+38" matches
/// its samples exactly), NaN and infinities become NaN; the rest is scaled by the vertical unit.
#[derive(Clone, Copy, Debug)]
struct ToHeight {
    sample: SampleType,
    /// The nodata value as a sample of the file's type holds it (none where it cannot).
    nodata: Option<f64>,
    /// Metres per unit.
    vertical: f64,
}

impl ToHeight {
    fn new(sample: SampleType, nodata: Option<f64>, vertical: f64) -> ToHeight {
        let whole_in = |n: f64, lo: f64, hi: f64| n.fract() == 0.0 && (lo..=hi).contains(&n);
        let nodata = nodata.filter(|&n| match sample {
            SampleType::U8 => whole_in(n, 0.0, 255.0),
            SampleType::I16 => whole_in(n, -32768.0, 32767.0),
            SampleType::U16 => whole_in(n, 0.0, 65535.0),
            SampleType::I32 => n.fract() == 0.0 && n.abs() <= 2_147_483_648.0,
            SampleType::F32 | SampleType::F64 => true,
        });
        // A float32 sample equals nodata as float32 (exactly, as float64).
        let nodata = match sample {
            SampleType::F32 => nodata.map(|n| f64::from(n as f32)),
            _ => nodata,
        };
        ToHeight {
            sample,
            nodata,
            vertical,
        }
    }

    /// The height of a sample of value `v`.
    fn height(&self, v: f64) -> f32 {
        if Some(v) == self.nodata || !v.is_finite() {
            f32::NAN
        } else {
            (v * self.vertical) as f32
        }
    }

    /// The height of a sample of bit pattern `bits` (in its low bytes).
    fn of_bits(&self, bits: u64) -> f32 {
        self.height(self.sample.value(bits))
    }
}

/// Heights in metres from decoded samples, as [`ToHeight`] makes them.
fn heights_of(
    path: &Path,
    values: DecodingResult,
    sample: SampleType,
    nodata: Option<f64>,
    vertical: f64,
) -> Result<Vec<f32>, WorldError> {
    let to = ToHeight::new(sample, nodata, vertical);
    let raw: Vec<f32> = match values {
        DecodingResult::U8(v) => v.iter().map(|&x| to.height(f64::from(x))).collect(),
        DecodingResult::I16(v) => v.iter().map(|&x| to.height(f64::from(x))).collect(),
        DecodingResult::U16(v) => v.iter().map(|&x| to.height(f64::from(x))).collect(),
        DecodingResult::I32(v) => v.iter().map(|&x| to.height(f64::from(x))).collect(),
        DecodingResult::F32(v) => v.iter().map(|&x| to.height(f64::from(x))).collect(),
        DecodingResult::F64(v) => v.iter().map(|&x| to.height(x)).collect(),
        _ => {
            return Err(unsupported(
                path,
                format!(
                    "the decoder returned another sample type than the {} declared",
                    sample.name()
                ),
            ));
        }
    };
    Ok(raw)
}

/// A GeoTIFF read a window of rows at a time ([`super::window`]): only the strips or tiles
/// that hold the rows asked for are read and decoded.
pub(crate) struct TiffWindows {
    path: PathBuf,
    layout: ChunkLayout,
    chunks: Vec<(u64, u64)>,
    codec: Codec,
    sample: SampleType,
    nodata: Option<f64>,
    vertical: f64,
    flip_rows: bool,
    flip_cols: bool,
}

/// Opens the GeoTIFF that `reader` reads (`len` bytes; `path` names it in errors) for reading in
/// windows: its header and georeferencing (the returned [`Dem`] holds no heights), up to
/// `max_samples` samples.
pub(crate) fn open_windows<R: Read + Seek>(
    path: &Path,
    reader: R,
    len: u64,
    cell_override: Option<[f64; 2]>,
    max_samples: u64,
) -> Result<(Dem, TiffWindows), WorldError> {
    let mut decoder = Decoder::new(reader)
        .map_err(|e| tiff_error(path, e))?
        .with_limits(limits());
    let header = read_header(path, &mut decoder, len, max_samples, Reading::Heights)?;
    let layout = chunk_layout(path, &mut decoder, &header)?;
    let codec = Codec::of(header.compression);
    let geo = GeoTags::read(path, &mut decoder)?;
    let grid = geo.grid(path, header.width, header.height, cell_override.is_some())?;
    let [cell_ew_m, cell_ns_m] = cell_override.unwrap_or(grid.cell_m);
    let dem = Dem {
        width: header.width,
        height: header.height,
        cell_ew_m,
        cell_ns_m,
        heights: Vec::new(),
        place: String::new(),
        source: format!(
            "{} GeoTIFF, compression {}",
            header.sample.name(),
            compression_name(header.compression)
        ),
        format: DemFormat::Geotiff,
        crs: grid.crs,
        origin: grid.origin,
        pixel_size: grid.pixel_size,
        nodata_filled: 0,
    };
    Ok((
        dem,
        TiffWindows {
            path: path.to_path_buf(),
            layout,
            chunks: header.chunks,
            codec,
            sample: header.sample,
            nodata: geo.nodata,
            vertical: geo.vertical_unit_m,
            flip_rows: grid.flip_rows,
            flip_cols: grid.flip_cols,
        },
    ))
}

impl TiffWindows {
    /// Rows in a strip or a tile.
    pub(crate) fn chunk_rows(&self) -> usize {
        self.layout.chunk_size[1] as usize
    }

    /// Heights of columns `cols` (from the west) of rows `rows` (from the north), ends
    /// exclusive, west first and north first, nodata NaN; the file's bytes read by
    /// `read(offset, count)`. Only the strips or tiles that hold the window are read: a tiled
    /// file's tiles beside it are not.
    pub(crate) fn window(
        &self,
        read: &mut dyn FnMut(u64, u64) -> Result<Vec<u8>, WorldError>,
        cols: [usize; 2],
        rows: [usize; 2],
    ) -> Result<Vec<f32>, WorldError> {
        let (w, h) = (self.layout.width as usize, self.layout.height as usize);
        debug_assert!(cols[0] <= cols[1] && cols[1] <= w && rows[0] <= rows[1] && rows[1] <= h);
        let bits = decode_window_north_up(
            &self.path,
            &self.layout,
            &self.chunks,
            self.codec,
            read,
            [self.flip_cols, self.flip_rows],
            [cols, rows],
            |v| v,
        )?;
        heights_of(
            &self.path,
            self.sample.typed(bits),
            self.sample,
            self.nodata,
            self.vertical,
        )
    }

    /// Samples in one strip or tile, and in a row of one.
    pub(crate) fn chunk_samples(&self) -> [usize; 2] {
        let [w, h] = self.layout.chunk_size.map(|v| v as usize);
        [w * h, w]
    }

    /// Samples a row.
    pub(crate) fn width(&self) -> usize {
        self.layout.width as usize
    }

    /// Whether a window of columns reads less than whole rows: the file is tiled (a strip
    /// spans every column).
    pub(crate) fn is_tiled(&self) -> bool {
        (self.layout.chunk_size[0] as usize) < self.layout.width as usize
    }
}

/// Turns rows of `w` samples stored south first (`flip_rows`) or east first (`flip_cols`)
/// north up and west first, in place.
fn north_up<T>(heights: &mut [T], w: usize, flip_rows: bool, flip_cols: bool) {
    let h = heights.len() / w;
    if flip_rows {
        for r in 0..h / 2 {
            let (north, south) = heights.split_at_mut((h - 1 - r) * w);
            north[r * w..(r + 1) * w].swap_with_slice(&mut south[..w]);
        }
    }
    if flip_cols {
        for row in heights.chunks_exact_mut(w) {
            row.reverse();
        }
    }
}

/// The sample types read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SampleType {
    U8,
    U16,
    I16,
    I32,
    F32,
    F64,
}

impl SampleType {
    fn name(self) -> &'static str {
        match self {
            SampleType::U8 => "uint8",
            SampleType::U16 => "uint16",
            SampleType::I16 => "int16",
            SampleType::I32 => "int32",
            SampleType::F32 => "float32",
            SampleType::F64 => "float64",
        }
    }

    fn is_float(self) -> bool {
        matches!(self, SampleType::F32 | SampleType::F64)
    }

    /// The value of a sample of bit pattern `bits` (in its low bytes).
    fn value(self, bits: u64) -> f64 {
        match self {
            SampleType::U8 => f64::from(bits as u8),
            SampleType::U16 => f64::from(bits as u16),
            SampleType::I16 => f64::from(bits as u16 as i16),
            SampleType::I32 => f64::from(bits as u32 as i32),
            SampleType::F32 => f64::from(f32::from_bits(bits as u32)),
            SampleType::F64 => f64::from_bits(bits),
        }
    }

    /// Bit patterns as the typed samples that the `tiff` crate would have returned.
    fn typed(self, bits: Vec<u64>) -> DecodingResult {
        let it = bits.into_iter();
        match self {
            SampleType::U8 => DecodingResult::U8(it.map(|v| v as u8).collect()),
            SampleType::U16 => DecodingResult::U16(it.map(|v| v as u16).collect()),
            SampleType::I16 => DecodingResult::I16(it.map(|v| v as u16 as i16).collect()),
            SampleType::I32 => DecodingResult::I32(it.map(|v| v as u32 as i32).collect()),
            SampleType::F32 => DecodingResult::F32(it.map(|v| f32::from_bits(v as u32)).collect()),
            SampleType::F64 => DecodingResult::F64(it.map(f64::from_bits).collect()),
        }
    }
}

fn corrupt(path: &Path, message: String) -> WorldError {
    WorldError::CorruptImage {
        path: path.to_path_buf(),
        format: "TIFF",
        message,
    }
}

fn unsupported(path: &Path, problem: String) -> WorldError {
    WorldError::UnsupportedDem {
        path: path.to_path_buf(),
        format: FORMAT,
        problem,
    }
}

fn tiff_error(path: &Path, e: TiffError) -> WorldError {
    match e {
        TiffError::UnsupportedError(u) => unsupported(path, u.to_string()),
        TiffError::LimitsExceeded => WorldError::OutOfRange {
            path: path.to_path_buf(),
            field: "decoded size".into(),
            value: "more than the decoder's limits".into(),
            allowed: format!("at most {MAX_DEM_SAMPLES} samples"),
        },
        other => corrupt(path, other.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::Codec;
    use std::path::Path;
    use tiff::encoder::{Compression, TiffEncoder, colortype};
    use tiff::tags::{Predictor, Tag};

    /// Writes a 23 x 19 GeoTIFF (EPSG:32633, 10 m) of `data` (rows as stored), in strips of 4
    /// rows, with `GDAL_NODATA` `nodata`; with `south_up` its rows are stored south first.
    fn write_map<C: colortype::ColorType>(
        path: &Path,
        data: &[C::Inner],
        nodata: &str,
        compression: Compression,
        predictor: Predictor,
        south_up: bool,
    ) where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let mut file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        let mut enc = TiffEncoder::new(&mut file)
            .unwrap()
            .with_compression(compression)
            .with_predictor(predictor);
        let mut image = enc.new_image::<C>(23, 19).unwrap();
        image.rows_per_strip(4).unwrap();
        let d = image.encoder();
        let (north, step_y) = if south_up {
            (4_000_000.0, 10.0)
        } else {
            (4_000_190.0, -10.0)
        };
        let m = [
            10.0, 0.0, 0.0, 500_000.0, 0.0, step_y, 0.0, north, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            1.0,
        ];
        d.write_tag(Tag::ModelTransformationTag, &m[..]).unwrap();
        let keys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32633];
        d.write_tag(Tag::GeoKeyDirectoryTag, &keys[..]).unwrap();
        d.write_tag(Tag::GdalNodata, nodata).unwrap();
        image.write_data(data).unwrap();
    }

    /// A map of values read a window at a time ([`super::open_values`]) holds at every sample
    /// the height a DEM read whole ([`super::load`], through the `tiff` crate's decoder) holds
    /// there, bit for bit: a density map or a mask reads as a DEM of the same file does. Every
    /// sample type, nodata as the file's type holds it, NaN and infinities, uncompressed and
    /// Deflate (with the horizontal predictor on integers), north-up and south-up, windows whole
    /// and inside.
    #[test]
    fn a_value_maps_window_holds_what_a_dem_read_whole_holds() {
        let dir = tempfile::tempdir().unwrap();
        // Each sample's value from its index: varied, every `every`-th the nodata value, and for
        // floats NaN and infinities among them.
        let values = |every: usize, nodata: f64, scale: f64, float: bool| -> Vec<f64> {
            (0..23 * 19)
                .map(|k| match k % 11 {
                    0 if float => f64::NAN,
                    1 if float => f64::INFINITY,
                    2 if float => f64::NEG_INFINITY,
                    _ if k % every == 0 => nodata,
                    _ => (((k * 37) % 101) as f64 - 50.0) * scale,
                })
                .collect()
        };
        let mut cases = 0;
        for (south_up, deflate) in [(false, false), (true, true), (false, true), (true, false)] {
            let compression = || match deflate {
                true => Compression::Deflate(Default::default()),
                false => Compression::Uncompressed,
            };
            let horizontal = match deflate {
                true => Predictor::Horizontal,
                false => Predictor::None,
            };
            let path = |t: &str| dir.path().join(format!("{t}_{south_up}_{deflate}.tif"));
            let v = values(9, 7.0, 1.0, false);
            let u8s: Vec<u8> = v.iter().map(|&v| v.abs() as u8).collect();
            write_map::<colortype::Gray8>(
                &path("u8"),
                &u8s,
                "7",
                compression(),
                horizontal,
                south_up,
            );
            let v = values(9, -9999.0, 300.0, false);
            let i16s: Vec<i16> = v.iter().map(|&v| v as i16).collect();
            write_map::<colortype::GrayI16>(
                &path("i16"),
                &i16s,
                "-9999",
                compression(),
                horizontal,
                south_up,
            );
            let v = values(7, 65535.0, 600.0, false);
            let u16s: Vec<u16> = v.iter().map(|&v| v.abs() as u16).collect();
            write_map::<colortype::Gray16>(
                &path("u16"),
                &u16s,
                "65535",
                compression(),
                horizontal,
                south_up,
            );
            let v = values(5, f64::from(i32::MIN), 70_000.0, false);
            let i32s: Vec<i32> = v.iter().map(|&v| v as i32).collect();
            write_map::<colortype::GrayI32>(
                &path("i32"),
                &i32s,
                "-2147483648",
                compression(),
                horizontal,
                south_up,
            );
            let v = values(13, f64::from(-f32::MAX), 1.0 / 7.0, true);
            let f32s: Vec<f32> = v.iter().map(|&v| v as f32).collect();
            write_map::<colortype::Gray32Float>(
                &path("f32"),
                &f32s,
                "-3.4028234663852886e+38",
                compression(),
                Predictor::None,
                south_up,
            );
            let v = values(13, -9999.5, 1.0 / 7.0, true);
            write_map::<colortype::Gray64Float>(
                &path("f64"),
                &v,
                "-9999.5",
                compression(),
                Predictor::None,
                south_up,
            );
            for t in ["u8", "i16", "u16", "i32", "f32", "f64"] {
                let p = path(t);
                let dem = super::load(&p, None).unwrap();
                let map = super::open_values(&p).unwrap();
                assert_eq!([map.width, map.height], [23, 19]);
                assert_eq!(map.origin, dem.origin);
                let nodata = dem.heights.iter().filter(|h| h.is_nan()).count();
                assert!(nodata > 20, "{}: {nodata} nodata", p.display());
                for (first, size) in [([0, 0], [23, 19]), ([3, 5], [11, 7]), ([22, 0], [1, 19])] {
                    let got = map.read_values(first, size, |v| v).unwrap();
                    let want: Vec<f32> = (first[1]..first[1] + size[1])
                        .flat_map(|r| {
                            let row = &dem.heights[r * 23..(r + 1) * 23];
                            row[first[0]..first[0] + size[0]].iter().copied()
                        })
                        .collect();
                    let bits = |v: &[f32]| v.iter().map(|h| h.to_bits()).collect::<Vec<_>>();
                    assert_eq!(
                        bits(&got),
                        bits(&want),
                        "{} {first:?} {size:?}",
                        p.display()
                    );
                    cases += 1;
                }
            }
        }
        assert_eq!(cases, 4 * 6 * 3);
    }

    /// A chunk decodes to at most the bytes its tile or strip holds, however far its codes
    /// would expand: 40 MB of zeros packed into a few kilobytes of LZW give the 4 KiB asked
    /// for, not 40 MB (Deflate stops at the limit and refuses the chunk).
    #[test]
    fn a_chunk_decodes_to_at_most_its_size() {
        let lzw_of = |data: &[u8]| {
            let mut packed = Vec::new();
            weezl::encode::Encoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8)
                .into_vec(&mut packed)
                .encode_all(data)
                .status
                .unwrap();
            packed
        };
        let zeros = vec![0u8; 40 << 20];
        let lzw = lzw_of(&zeros);
        assert!(lzw.len() < zeros.len() / 100, "{}", lzw.len());
        let deflate = miniz_oxide::deflate::compress_to_vec_zlib(&zeros, 6);
        assert_eq!(Codec::Lzw.decode(&lzw, 4096).unwrap(), vec![0u8; 4096]);
        // Deflate refuses a chunk that expands past its size.
        let deflated = Codec::Deflate.decode(&deflate, 4096);
        assert!(deflated.is_err(), "{:?}", deflated.map(|v| v.len()));
        // Whole, short and cut-off streams as before: all of a small one, an error for codes
        // that end without their end code.
        let small: Vec<u8> = (0..3000u32).map(|i| (i * 7 % 251) as u8).collect();
        let packed = lzw_of(&small);
        assert_eq!(Codec::Lzw.decode(&packed, 3000).unwrap(), small);
        assert_eq!(Codec::Lzw.decode(&packed, 100_000).unwrap(), small);
        let cut = Codec::Lzw
            .decode(&packed[..packed.len() / 2], 3000)
            .unwrap_err();
        assert!(cut.contains("end code"), "{cut}");
    }
}
