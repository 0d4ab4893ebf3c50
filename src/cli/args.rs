//! What the commands share: the tile service's options, and parsers of sizes, ranges,
//! vectors and world arguments whose errors state the range.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::builder::RangedU64ValueParser;

use verdant::stream::ServiceConfig;

/// Limits of the tile service, shared by the commands that stream.
#[derive(clap::Args, Clone)]
pub(crate) struct StreamArgs {
    /// Ceiling of the CPU cache of decoded tiles, MiB, 1..=1048576 (it must hold at least one
    /// tile).
    #[arg(long, default_value = "64", value_parser = parse_mib)]
    pub(crate) cache_mib: u64,
    /// Slots of the GPU tile atlas (each holds one tile), 2..=4096; more than the world's
    /// level-0 tiles and at most the adapter's texture array layers (default: sized to the
    /// world, 24 a level of its pyramid besides its level-0 and grass tiles, at least 256 and at
    /// most 2048).
    #[arg(long, value_parser = clap::value_parser!(u32).range(2..=4096))]
    pub(crate) atlas_slots: Option<u32>,
    /// Tile loads in flight at most, 1..=64.
    #[arg(long, default_value_t = 8, value_parser = RangedU64ValueParser::<usize>::new().range(1..=64))]
    pub(crate) max_loads: usize,
    #[command(flatten)]
    pub(crate) http: HttpArgs,
}

/// How a world over HTTP is fetched, shared by the commands that open worlds.
#[derive(clap::Args, Clone)]
pub(crate) struct HttpArgs {
    /// A world over HTTP: deadline of one request, whole seconds, 1..=3600.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=3600))]
    pub(crate) http_timeout_s: u64,
    /// A world over HTTP: retries of a transient failure (connection error, 5xx, a body cut
    /// short), 0..=20, after a wait that doubles from 200 ms up to 5 s.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=20))]
    pub(crate) http_retries: u32,
    /// A world over HTTP: keep fetched tile files in this folder, revalidated with the
    /// server's ETag or Last-Modified.
    #[arg(long)]
    pub(crate) http_cache: Option<PathBuf>,
    /// Ceiling of the --http-cache folder, MiB, 1..=1048576.
    #[arg(long, default_value = "512", value_parser = parse_mib)]
    pub(crate) http_cache_mib: u64,
}

impl HttpArgs {
    pub(crate) fn options(&self) -> verdant::stream::HttpOptions {
        verdant::stream::HttpOptions {
            timeout: std::time::Duration::from_secs(self.http_timeout_s),
            retries: self.http_retries,
            cache: self
                .http_cache
                .as_ref()
                .map(|dir| verdant::stream::HttpCacheConfig {
                    dir: dir.clone(),
                    max_bytes: self.http_cache_mib << 20,
                }),
            ..Default::default()
        }
    }
}

impl StreamArgs {
    pub(crate) fn http(&self) -> verdant::stream::HttpOptions {
        self.http.options()
    }

    pub(crate) fn service(self) -> ServiceConfig {
        let mut c = ServiceConfig {
            // parse_mib has checked that the bytes fit a u64.
            cache_bytes: self.cache_mib << 20,
            atlas_slots: self
                .atlas_slots
                .unwrap_or(verdant::tools::WORLD_ATLAS_SLOTS),
            ..ServiceConfig::default()
        };
        c.stream.max_in_flight = self.max_loads;
        c
    }
}

/// Most frames `fly` and `view` render in one run (what they keep per frame is thinned to a
/// bound, so any count runs in bounded memory).
pub(crate) const MAX_FRAMES: i64 = u32::MAX as i64;

/// Most MiB a memory ceiling may name (1 TiB).
pub(crate) const MAX_MIB: u64 = 1 << 20;

/// Parses a size in MiB, 1..=[`MAX_MIB`].
pub(crate) fn parse_mib(s: &str) -> Result<u64, String> {
    let mib: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number of MiB"))?;
    if !(1..=MAX_MIB).contains(&mib) {
        return Err(format!("{mib} MiB is out of range (1..={MAX_MIB} MiB)"));
    }
    Ok(mib)
}

/// The temporal anti-aliasing's settings (they apply with `--aa taa`).
#[derive(clap::Args, Clone, Copy, Debug, Default)]
pub(crate) struct TaaArgs {
    /// With --aa taa: the most samples a pixel's history holds, 2..=256 (default 24). More
    /// steadies a still view and lags longer behind a moving one.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(2..=256))]
    pub(crate) taa_samples: Option<u32>,
    /// With --aa taa: the history is clipped to the current neighbourhood's mean plus and
    /// minus SIGMA standard deviations, 0.25..=16 (default 2.5). Less drops ghosts sooner and
    /// lets the jitter through.
    #[arg(long, value_name = "SIGMA", value_parser = float_in(0.25, 16.0))]
    pub(crate) taa_clip: Option<f64>,
    /// With --aa taa: the grass blades write their own motion vectors (their wind over the
    /// frame) for the temporal resolve, instead of being reprojected through their depth.
    /// Off by default (at 60 frames a second in a breeze they gain little for their cost).
    #[arg(long)]
    pub(crate) taa_blade_motion: bool,
    /// With --aa taa: the history's clip also reaches the current sample plus and minus K of
    /// the pixel's own standard deviations over time, 0..=16 (default 0: the neighbourhood's
    /// alone). Keeps blades thinner than a pixel that the neighbourhood missed.
    #[arg(long, value_name = "K", value_parser = float_in(0.0, 16.0))]
    pub(crate) taa_pixel_spread: Option<f64>,
    /// With --aa taa: how much faster a surface's history shortens with its parallax (what it
    /// moved beyond the camera's turn), 0..=16: at most N / (1 + pixels moved + P x pixels of
    /// parallax) samples (default 2).
    #[arg(long, value_name = "P", value_parser = float_in(0.0, 16.0))]
    pub(crate) taa_parallax_falloff: Option<f64>,
    /// With --aa taa: the fewest samples a moving surface's history keeps, 1..=256 and at
    /// most --taa-samples (default 1: a surface that moved far leans on its current sample
    /// alone, where a resampled history would only blur it; 2 keeps half a history).
    #[arg(long, value_name = "M", value_parser = float_in(1.0, 256.0))]
    pub(crate) taa_min_samples: Option<f64>,
    /// With --aa taa: reconstruct the current frame at each pixel's centre from its 3x3
    /// jittered samples with a Gaussian of this standard deviation in pixels, 0..=2 (default
    /// 0.45; 0: each pixel's own sample, which lies the jitter away from its centre).
    #[arg(long, value_name = "PX", value_parser = float_in(0.0, 2.0))]
    pub(crate) taa_reconstruct: Option<f64>,
    /// With --aa taa and --taa-blade-motion: how much faster a blade's history shortens with
    /// its own sway in the wind (its motion vector beyond the camera's move), 0..=16: at most
    /// N / (1 + pixels moved + P x pixels of parallax + S x pixels of sway) samples (default 0).
    #[arg(long, value_name = "S", value_parser = float_in(0.0, 16.0), requires = "taa_blade_motion")]
    pub(crate) taa_sway_falloff: Option<f64>,
}

impl TaaArgs {
    /// The first of the temporal method's options given, if any.
    pub(crate) fn first_given(&self) -> Option<&'static str> {
        [
            (self.taa_samples.is_some(), "--taa-samples"),
            (self.taa_clip.is_some(), "--taa-clip"),
            (self.taa_blade_motion, "--taa-blade-motion"),
            (self.taa_pixel_spread.is_some(), "--taa-pixel-spread"),
            (
                self.taa_parallax_falloff.is_some(),
                "--taa-parallax-falloff",
            ),
            (self.taa_min_samples.is_some(), "--taa-min-samples"),
            (self.taa_reconstruct.is_some(), "--taa-reconstruct"),
            (self.taa_sway_falloff.is_some(), "--taa-sway-falloff"),
        ]
        .into_iter()
        .find_map(|(given, name)| given.then_some(name))
    }

    /// The renderer's defaults with what was given.
    pub(crate) fn settings(&self) -> verdant::aa::taa::TaaSettings {
        let mut s = verdant::aa::taa::TaaSettings::default();
        if let Some(n) = self.taa_samples {
            s.max_samples = n;
        }
        if let Some(c) = self.taa_clip {
            s.clip_sigma = c as f32;
        }
        s.blade_motion = self.taa_blade_motion;
        if let Some(k) = self.taa_pixel_spread {
            s.pixel_spread = k as f32;
        }
        if let Some(f) = self.taa_parallax_falloff {
            s.parallax_falloff = f as f32;
        }
        if let Some(m) = self.taa_min_samples {
            s.min_samples = m as f32;
        }
        if let Some(r) = self.taa_reconstruct {
            s.reconstruct_px = r as f32;
        }
        if let Some(w) = self.taa_sway_falloff {
            s.sway_falloff = w as f32;
        }
        s
    }
}

/// A parser of a number `T` for which `ok` holds, whose error states `range` (in words).
fn number_where<T: std::str::FromStr>(
    range: String,
    ok: impl Fn(&T) -> bool + Clone + Send + Sync,
) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync {
    move |s: &str| match s.trim().parse::<T>() {
        Ok(v) if ok(&v) => Ok(v),
        Ok(_) => Err(format!("{} is out of range ({range})", s.trim())),
        Err(_) => Err(format!("{s:?} is not a number (expected {range})")),
    }
}

/// A parser of a finite number in `lo..=hi` whose error states the range.
pub(crate) fn float_in(
    lo: f64,
    hi: f64,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    number_where(format!("{lo}..={hi}"), move |v: &f64| {
        v.is_finite() && (lo..=hi).contains(v)
    })
}

/// A number strictly between `lo` and `hi`.
pub(crate) fn float_between(
    lo: f64,
    hi: f64,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    number_where(
        format!("between {lo} and {hi}, both excluded"),
        move |&v: &f64| v > lo && v < hi,
    )
}

/// A power of two in `lo..=hi`.
pub(crate) fn power_of_two_in(
    lo: u32,
    hi: u32,
) -> impl Fn(&str) -> Result<u32, String> + Clone + Send + Sync {
    number_where(format!("a power of two in {lo}..={hi}"), move |&v: &u32| {
        v.is_power_of_two() && (lo..=hi).contains(&v)
    })
}

pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WIDTHxHEIGHT, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("{v:?} is not a pixel count"))
    };
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!(
            "{w}x{h} is out of range (1 to 16384 pixels a side)"
        ));
    }
    Ok((w, h))
}

/// A DEM cell size: `M` (square) or `EW,NS`, metres, each finite and positive.
pub(crate) fn parse_cell_size(s: &str) -> Result<[f64; 2], String> {
    // Past 1,000 km a cell is no DEM's on this planet (a degree is 111 km), and the DEM's
    // extent could overflow.
    const MAX_CELL_M: f64 = 1e6;
    let parse = |v: &str| -> Result<f64, String> {
        match v.trim().parse::<f64>() {
            Ok(m) if m.is_finite() && m > 0.0 && m <= MAX_CELL_M => Ok(m),
            _ => Err(format!(
                "{v:?} is not a positive number of metres of at most {MAX_CELL_M:e}"
            )),
        }
    };
    match s.split_once(',') {
        Some((ew, ns)) => Ok([parse(ew)?, parse(ns)?]),
        None => parse(s).map(|m| [m, m]),
    }
}

/// Where a world given by a bare name is looked for besides the folder of that name here:
/// under ./worlds, then under the source tree's worlds.
fn named_worlds(arg: &OsStr) -> [PathBuf; 2] {
    [
        Path::new("worlds").join(arg),
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("worlds")
            .join(arg),
    ]
}

/// A world argument is a folder, or a name under `./worlds` or the crate's own `worlds`, or a
/// world's address. A folder's name need not be UTF-8 (a bake writes whatever `--out` names).
pub(crate) fn resolve_world(arg: &OsStr) -> Result<PathBuf> {
    if arg.to_str().is_some_and(verdant::stream::http::is_url) {
        // Opened over HTTP by the tools.
        return Ok(PathBuf::from(arg));
    }
    let direct = Path::new(arg);
    if direct.join("world.toml").is_file() {
        return Ok(direct.to_path_buf());
    }
    // A bare name is also looked for under the worlds folders; a path only where it points.
    // A folder of that name here is the world named, though its world.toml is missing or
    // cannot be read (the loader says which): never another world of the same name.
    let bare = direct.components().count() == 1 && !direct.is_absolute();
    if direct.is_dir() {
        if bare
            && let Some(other) = named_worlds(arg)
                .into_iter()
                .find(|c| c.join("world.toml").is_file())
        {
            log::warn!(
                "{arg:?} is the folder {} here, which holds no readable world.toml; the world \
                 at {} is not used (name its path to use it)",
                direct.display(),
                other.display()
            );
        }
        return Ok(direct.to_path_buf());
    }
    let mut candidates: Vec<PathBuf> = Vec::new();
    if bare {
        for c in named_worlds(arg) {
            if c.join("world.toml").is_file() {
                return Ok(c);
            }
            if !candidates.contains(&c) {
                candidates.push(c);
            }
        }
    }
    match candidates.first() {
        Some(c) => bail!(
            "no world {arg:?}: neither {} nor {} holds a world.toml",
            direct.display(),
            c.display()
        ),
        None if direct.is_file() => bail!(
            "no world at {}: it is a file; a world is the folder that holds world.toml and \
             tiles/{}",
            direct.display(),
            match direct.parent() {
                Some(p) if direct.file_name().is_some_and(|n| n == "world.toml") => {
                    format!(" (here: {})", p.display())
                }
                _ => String::new(),
            }
        ),
        None => bail!("no world at {}: no such folder", direct.display()),
    }
}

pub(crate) fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{s:?} is not X,Y,Z in metres"))?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!(
            "{s:?} is not X,Y,Z in metres (three finite numbers)"
        )),
    }
}
