//! The `verdant` command line.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::builder::RangedU64ValueParser;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use verdant::bake::{BakeOptions, bake};
use verdant::stream::ServiceConfig;
use verdant::tools::{FlyOptions, FlyProgress, SoakOptions, run_fly, run_soak};

/// Limits of the tile service, shared by the commands that stream.
#[derive(clap::Args, Clone)]
struct StreamArgs {
    /// Ceiling of the CPU cache of decoded tiles, MiB, 1..=1048576 (it must hold at least one
    /// tile).
    #[arg(long, default_value = "64", value_parser = parse_mib)]
    cache_mib: u64,
    /// Slots of the GPU tile atlas (each holds one tile), 2..=4096; more than the world's
    /// level-0 tiles and at most the adapter's texture array layers.
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(2..=4096))]
    atlas_slots: u32,
    /// Tile loads in flight at most, 1..=64.
    #[arg(long, default_value_t = 8, value_parser = RangedU64ValueParser::<usize>::new().range(1..=64))]
    max_loads: usize,
    /// A world over HTTP: deadline of one request, whole seconds, 1..=3600.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=3600))]
    http_timeout_s: u64,
    /// A world over HTTP: retries of a transient failure (connection error, 5xx, a body cut
    /// short), 0..=20, after a wait that doubles from 200 ms up to 5 s.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=20))]
    http_retries: u32,
    /// A world over HTTP: keep fetched tile files in this folder, revalidated with the
    /// server's ETag or Last-Modified.
    #[arg(long)]
    http_cache: Option<PathBuf>,
    /// Ceiling of the --http-cache folder, MiB, 1..=1048576.
    #[arg(long, default_value = "512", value_parser = parse_mib)]
    http_cache_mib: u64,
}

impl StreamArgs {
    fn http(&self) -> verdant::stream::HttpOptions {
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

    fn service(self) -> ServiceConfig {
        let mut c = ServiceConfig {
            // parse_mib has checked that the bytes fit a u64.
            cache_bytes: self.cache_mib << 20,
            atlas_slots: self.atlas_slots,
            ..ServiceConfig::default()
        };
        c.stream.max_in_flight = self.max_loads;
        c
    }
}

/// Streaming open-world terrain with GPU grass.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render PNG frames along a camera path and write report.json.
    Fly(FlyArgs),
    /// Open a window on a world: drag the mouse to look, WASD to fly, Q/E down and up, Shift
    /// faster, the wheel or +/- for speed, P to follow the camera path (N: next path), 1-9 for
    /// the wind scenes, L for the LOD overlay, V for vsync, Esc to quit. Figures in the title.
    View(ViewArgs),
    /// Fly fast with random turns and teleports; check the streaming ceilings, holes and memory.
    /// Writes soak.json and exits non-zero if a check failed.
    Soak(SoakArgs),
    /// Serve a world folder over HTTP (GET and HEAD, content types, ETag and Last-Modified,
    /// conditional GET), for `verdant fly http://HOST:PORT/` and the like. For production, put
    /// the folder behind any ordinary HTTP server, object store or CDN.
    Serve {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: String,
        /// Address to listen on (port 0 picks a free port).
        #[arg(long, default_value = "127.0.0.1:8000")]
        addr: String,
    },
    /// Benchmarks of the renderer.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Measure methods against real data and chart speed against accuracy.
    Eval {
        #[command(subcommand)]
        what: EvalCommand,
    },
    /// Bake a DEM (GeoTIFF, SRTM .hgt, or 16-bit PNG with a JSON sidecar) into a world folder.
    Bake(BakeArgs),
}

// The options of `verdant fly`.
#[derive(clap::Args)]
struct FlyArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    world: String,
    /// Camera path from the world's manifest (default: its first path).
    #[arg(long)]
    path: Option<String>,
    /// Frames to render, spread evenly over the path, 1..=4294967295.
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(1..=MAX_FRAMES))]
    frames: u32,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "640x360", value_parser = parse_size)]
    size: (u32, u32),
    /// Output folder.
    #[arg(long, default_value = "out/fly")]
    out: PathBuf,
    /// Write only report.json, no PNG frames.
    #[arg(long)]
    no_images: bool,
    /// Wind scene of the world's manifest (e.g. calm, breeze, storm, helicopter) for the
    /// whole flight (default: the path's own wind keys if it has any, else breeze).
    #[arg(long)]
    wind: Option<String>,
    /// Features to switch off, comma-separated: wind-sources, interaction,
    /// detail-bending, translucency, specular, ambient-occlusion, color-variation,
    /// ground-darkening, far-field, shadows (on top of the manifest's [features] table).
    #[arg(long, value_delimiter = ',')]
    disable: Vec<verdant::features::Feature>,
    /// Grass features to switch on that the manifest's [features] table switches off,
    /// comma-separated.
    #[arg(long, value_delimiter = ',')]
    enable: Vec<verdant::features::Feature>,
    /// Blade spacing of the near grass grid, metres (default: the renderer's).
    #[arg(long)]
    grass_spacing_m: Option<f32>,
    /// Every grass type's blade width times this (default: the renderer's).
    #[arg(long)]
    grass_width_scale: Option<f32>,
    /// Radii of the grass infill near the camera, HALF,QUARTER metres: blades at half the
    /// spacing out to the first, at a quarter of it out to the second; 0,0 turns it off
    /// (default: the renderer's).
    #[arg(long, value_delimiter = ',')]
    grass_infill_m: Option<Vec<f32>>,
    /// Blade segments NEAR,HIGH,LOW: of the blades near the camera, the rest of the high
    /// ring and the low ring (default: the renderer's).
    #[arg(long, value_delimiter = ',')]
    grass_segments: Option<Vec<u32>>,
    /// Horizontal radius of the blades drawn with the NEAR segments, metres (default: the
    /// renderer's).
    #[arg(long)]
    grass_near_m: Option<f32>,
    /// Terrain mesh: one vertex every this many samples of a tile (1, 2, 4, ...; default:
    /// the renderer's).
    #[arg(long)]
    mesh_step: Option<u32>,
    /// Render the frames as the truth instead: supersampled K x K (1..=8) in linear light, no
    /// LOD, the most blade segments, blades out to 4 times the view distance.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=8))]
    truth: Option<u32>,
    #[command(flatten)]
    stream: StreamArgs,
}

// The options of `verdant view`.
#[derive(clap::Args)]
struct ViewArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    world: String,
    /// Window size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = parse_size)]
    size: (u32, u32),
    /// Present as fast as possible instead of waiting for the display's refresh.
    #[arg(long)]
    no_vsync: bool,
    /// Camera path to start on and follow with P (default: the manifest's first).
    #[arg(long)]
    path: Option<String>,
    /// Follow the camera path from the start.
    #[arg(long)]
    follow: bool,
    /// Render this many frames (a fixed 1/60 s apart) and exit, 1..=4294967295.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=MAX_FRAMES))]
    frames: Option<u32>,
    /// Write the last of --frames N frames to this PNG file.
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// Wind scene to start with (default: the path's wind keys, else breeze).
    #[arg(long)]
    wind: Option<String>,
    #[command(flatten)]
    stream: StreamArgs,
}

// The options of `verdant soak`.
#[derive(clap::Args)]
struct SoakArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    world: String,
    /// Simulated flight time, seconds (0.1 s a frame), 1..=604800 (a week).
    #[arg(long, default_value_t = 60.0, value_parser = float_in(1.0, 604_800.0))]
    seconds: f64,
    /// Camera speed, metres a second, 0..=1000 (and less than a world's width in 20
    /// frames: the camera must stay over the world).
    #[arg(long, default_value_t = 50.0, value_parser = float_in(0.0, 1000.0))]
    speed: f64,
    /// Seed of the turns and teleports.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "320x180", value_parser = parse_size)]
    size: (u32, u32),
    /// Output folder.
    #[arg(long, default_value = "out/soak")]
    out: PathBuf,
    /// Fly without grass and its wind: the streaming system alone.
    #[arg(long)]
    no_grass: bool,
    /// A teleport must reach full detail within this many frames, 1..=100000, or within
    /// the simulated time they stand for (0.1 s each) of wall time, on a machine that
    /// renders faster than that.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    max_recovery_frames: u32,
    /// No frame may take longer than this, milliseconds (wall time), 1..=3600000.
    #[arg(long, default_value_t = 5000.0, value_parser = float_in(1.0, 3_600_000.0))]
    max_stall_ms: f64,
    /// Inject faults while flying, 0..=1 (0: none). A world on disk is flown from a copy
    /// in --out whose tile files (level 1 and finer) are removed, truncated, overwritten
    /// with garbage, emptied or replaced by a folder, this share of them at any moment,
    /// a fresh set every 2 s of flight; a world over HTTP through a proxy that fails this
    /// share of tile requests (errors, stalls, resets, short bodies). The checks stay the
    /// same: broken tiles are drawn from their ancestors (no holes) and retried.
    #[arg(long, default_value_t = 0.0, value_parser = float_in(0.0, 1.0))]
    faults: f64,
    #[command(flatten)]
    stream: StreamArgs,
}

// The options of `verdant bake`.
#[derive(clap::Args)]
struct BakeArgs {
    /// The DEM: a GeoTIFF, an SRTM .hgt tile, or a 16-bit PNG whose sidecar is the .json of
    /// the same stem. The format is told from the content.
    #[arg(long)]
    dem: PathBuf,
    /// Spacing of the DEM's samples in metres, M or EW,NS, in place of what the file says
    /// (needed for a TIFF without GeoTIFF tags).
    #[arg(long, value_name = "M|EW,NS", value_parser = parse_cell_size)]
    dem_cell_size: Option<[f64; 2]>,
    /// The world folder to write.
    #[arg(long)]
    out: PathBuf,
    /// World name (default: the output folder's name).
    #[arg(long)]
    name: Option<String>,
    /// Cell size of the finest stored level, metres (default: from the DEM).
    #[arg(long)]
    cell_size: Option<f64>,
    /// Cells per tile edge (a power of two).
    #[arg(long, default_value_t = 128)]
    tile_cells: u32,
    /// Stored levels of the tile pyramid.
    #[arg(long, default_value_t = 3)]
    levels: u8,
    /// Seed of the grass-painting noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Replace the world (world.toml and tiles/) in --out if it exists and is not empty
    /// (otherwise it is refused); its other files are kept.
    #[arg(long)]
    replace: bool,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// The grass renderers' benchmark: a flat field of one grass type generated in memory,
    /// swept over blade counts; GPU time per pass, ns per blade and per vertex, the ratio to a
    /// bare pass drawing as many vertices, and the image error against no LOD.
    Blades {
        /// Output folder.
        #[arg(long, default_value = "out/bench-blades")]
        out: PathBuf,
        /// Image size, WIDTHxHEIGHT.
        #[arg(long, default_value = "1920x1080", value_parser = parse_size)]
        size: (u32, u32),
        /// Edge of the square field, metres.
        #[arg(long, default_value_t = 200.0)]
        field_m: f64,
        /// Camera position X,Y,Z in metres (x east, y north, z up).
        #[arg(long, default_value = "-20,-20,15", value_parser = parse_vec3)]
        camera: [f64; 3],
        /// The point the camera looks at, X,Y,Z in metres.
        #[arg(long, default_value = "100,100,0", value_parser = parse_vec3)]
        target: [f64; 3],
        /// Vertical field of view, degrees.
        #[arg(long, default_value_t = 45.0)]
        fov_deg: f64,
        /// Blade counts of the sweep, comma-separated.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "100000,300000,1000000,3000000,10000000"
        )]
        counts: Vec<u64>,
        #[command(flatten)]
        timing: TimingArgs,
        #[command(flatten)]
        truth: TruthArgs,
    },
    /// Each grass feature's GPU cost against its contribution to the image (FLIP between the
    /// render with and without it), charted one against the other.
    Features {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: String,
        /// Output folder.
        #[arg(long, default_value = "out/bench-features")]
        out: PathBuf,
        /// Image size, WIDTHxHEIGHT.
        #[arg(long, default_value = "480x270", value_parser = parse_size)]
        size: (u32, u32),
        #[command(flatten)]
        timing: TimingArgs,
        #[command(flatten)]
        truth: TruthArgs,
    },
    /// The LOD transition benchmark: popping across the ring boundary, and GPU time against
    /// image error for a set of LOD settings, charted with the Pareto front.
    Lod {
        /// World folder, or the name of a world under ./worlds.
        #[arg(default_value = "santa-cruz")]
        world: String,
        /// Output folder.
        #[arg(long, default_value = "out/bench-lod")]
        out: PathBuf,
        /// Image size, WIDTHxHEIGHT.
        #[arg(long, default_value = "480x270", value_parser = parse_size)]
        size: (u32, u32),
        /// Frames of the dolly, 2..=1000.
        #[arg(long, default_value_t = 48, value_parser = clap::value_parser!(u32).range(2..=1000))]
        dolly_frames: u32,
        #[command(flatten)]
        timing: TimingArgs,
        #[command(flatten)]
        truth: TruthArgs,
    },
}

/// What the benchmarks measure their images against.
#[derive(clap::Args)]
struct TruthArgs {
    /// Sub-samples a pixel side of the truth (supersampled in linear light), 1..=8.
    #[arg(long, value_name = "K", default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=8))]
    truth: u32,
}

/// How the benchmarks time: interleaved rounds over the settings, each measurement's frames
/// back to back. The defaults give stable figures on a GPU (5 rounds of 20 frames after 5
/// untimed ones) and fewer on a software renderer (2 rounds of 3 after 1).
#[derive(clap::Args, Clone, Copy)]
struct TimingArgs {
    /// Untimed frames before each measurement's timed ones, 0..=100.
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=100))]
    warmup_frames: Option<u32>,
    /// Timed frames of each measurement per round, 1..=150.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=150))]
    timed_frames: Option<u32>,
    /// Interleaved rounds over the settings, 1..=100.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100))]
    rounds: Option<u32>,
}

/// The progress bars of [`stage_bars`], shared with its update function.
type StageBars = std::rc::Rc<std::cell::RefCell<Vec<(String, ProgressBar)>>>;

/// Progress bars for a run of named stages, one bar a stage.
fn stage_bars() -> (StageBars, impl FnMut(&str, u64, u64)) {
    let bars = std::rc::Rc::new(std::cell::RefCell::new(Vec::<(String, ProgressBar)>::new()));
    let inner = bars.clone();
    let update = move |stage: &str, done: u64, total: u64| {
        let mut bars = inner.borrow_mut();
        if bars.last().is_none_or(|(s, _)| s != stage) {
            if let Some((_, pb)) = bars.last() {
                pb.finish();
            }
            bars.push((stage.to_owned(), bar(total, stage)));
        }
        if let Some((_, pb)) = bars.last() {
            pb.set_position(done);
        }
    };
    (bars, update)
}

fn finish_bars(bars: &std::cell::RefCell<Vec<(String, ProgressBar)>>) {
    if let Some((_, pb)) = bars.borrow().last() {
        pb.finish();
    }
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
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

fn bench_features(opts: verdant::tools::BenchLodOptions) -> Result<()> {
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::run_bench_features(&opts, &mut update)?;
    finish_bars(&bars);
    println!(
        "{} [{}], {}x{}",
        r.adapter.name, r.adapter.backend, r.size.0, r.size.1
    );
    println!(
        "{:<18} {:>10} {:>8} {:>10} {:>13}",
        "feature off", "GPU ms", "IQR %", "cost ms", "contribution"
    );
    for f in &r.features {
        println!(
            "{:<18} {:>10.3} {:>8.1} {:>10.3} {:>13.4}{}",
            f.feature,
            f.gpu_ms,
            100.0 * f.timing.spread,
            f.cost_ms,
            f.contribution,
            if f.timing.noisy {
                "  (spread above 10%)"
            } else {
                ""
            }
        );
    }
    println!("wrote {}", opts.out.display());
    Ok(())
}

fn bench_blades(opts: verdant::tools::bench_blades::BenchBladesOptions) -> Result<()> {
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::bench_blades::run_bench_blades(&opts, &mut update)?;
    finish_bars(&bars);
    println!(
        "{} [{}], {}x{}",
        r.adapter.name, r.adapter.backend, r.size.0, r.size.1
    );
    println!(
        "{:>10} {:>9} {:>9} {:>11} {:>9} {:>9} {:>9} {:>8} {:>8} {:>7} {:>7}",
        "blades",
        "drawn hi",
        "drawn lo",
        "vertices",
        "gen ms",
        "draw ms",
        "floor ms",
        "ns/blade",
        "ns/vert",
        "x floor",
        "FLIP"
    );
    for b in &r.results {
        println!(
            "{:>10} {:>9} {:>9} {:>11} {:>9.3} {:>9.3} {:>9.3} {:>8.2} {:>8.3} {:>7.2} {:>7.4}{}",
            b.blades,
            b.drawn[0],
            b.drawn[1],
            b.vertices,
            b.generate.median_ms,
            b.draw.median_ms,
            b.floor.median_ms,
            b.ns_per_blade,
            b.ns_per_vertex,
            b.ratio_to_floor,
            b.flip_vs_no_lod,
            if b.draw.noisy || b.floor.noisy {
                "  (spread above 10%)"
            } else {
                ""
            }
        );
    }
    println!(
        "timing: {} rounds of {} frames after {} untimed, per count; wrote {}",
        r.counts.rounds,
        r.counts.timed,
        r.counts.warmup,
        opts.out.display()
    );
    Ok(())
}

fn bench_lod(opts: verdant::tools::BenchLodOptions) -> Result<()> {
    let (bars, mut update) = stage_bars();
    let r = verdant::tools::run_bench_lod(&opts, &mut update)?;
    finish_bars(&bars);
    println!(
        "{} [{}], {}x{}",
        r.adapter.name, r.adapter.backend, r.size.0, r.size.1
    );
    println!(
        "dolly: largest jump of the error against the truth: {:.4} FLIP on frames with ring switches, {:.4} on frames without",
        r.worst_pop, r.worst_change_without_switch
    );
    let flip = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
    println!(
        "far band ({:.0}-{:.0} m, {} pixels) against the truth's blades out to {:.0} m: {} FLIP with the far field, {} without",
        r.far_band.near_m,
        r.far_band.far_m,
        r.far_band.band_pixels,
        r.far_band.far_m,
        flip(r.far_band.flip_far_field),
        flip(r.far_band.flip_no_far_field)
    );
    println!(
        "{:<16} {:>9} {:>8} {:>10} {:>9} {:>9} {:>10} {:>7}",
        "setting", "GPU ms", "IQR %", "frame ms", "FLIP", "coarse", "blades", "front"
    );
    for s in &r.settings {
        println!(
            "{:<16} {:>9.3} {:>8.1} {:>10.2} {:>9.4} {:>9.4} {:>10.0} {:>7}{}",
            s.setting.name,
            s.gpu.median_ms,
            100.0 * s.gpu.spread,
            s.frame.median_ms,
            s.vs_truth.flip,
            s.vs_truth.coarse,
            s.blades_drawn,
            if s.pareto { "yes" } else { "" },
            if s.gpu.noisy || s.frame.noisy {
                "  (spread above 10%)"
            } else {
                ""
            }
        );
    }
    println!(
        "timing: {} rounds of {} frames after {} untimed, per view and setting",
        r.counts.rounds, r.counts.timed, r.counts.warmup
    );
    println!(
        "on the front against the {k}x{k} truth: {}; by the coarse FLIP: {}",
        r.front.join(", "),
        r.coarse_front.join(", "),
        k = r.truth_k
    );
    println!(
        "default setting {} the Pareto front; wrote {}",
        if r.default_on_front {
            "is on"
        } else {
            "is NOT on"
        },
        opts.out.display()
    );
    Ok(())
}

#[derive(Subcommand)]
enum EvalCommand {
    /// Downsample a DEM by K, derive it back with each method (nearest, bilinear, bicubic,
    /// bicubic + fixed detail, and the calibrated detail fitted to the coarse grid), and chart
    /// height and slope error against time per tile.
    Derive {
        /// The DEM's PNG (16-bit, with its JSON sidecar).
        #[arg(long)]
        dem: PathBuf,
        /// Downsampling factor, a power of two.
        #[arg(long, default_value_t = 4)]
        factor: usize,
        /// Output folder for derive.csv and the charts.
        #[arg(long, default_value = "out/eval-derive")]
        out: PathBuf,
    },
    /// Step the grass sway spring (stiff and soft presets) with explicit Euler, semi-implicit
    /// Euler and the exact solution at frame times from 1/240 s to 1/5 s and at a 0.5 s hitch;
    /// chart error against cost and where each blows up.
    Sway {
        /// Output folder for sway.csv and the charts.
        #[arg(long, default_value = "out/eval-sway")]
        out: PathBuf,
    },
}

fn eval_derive(dem_path: &Path, factor: usize, out: &Path) -> Result<()> {
    use verdant::tools::eval_derive as eval;
    let mut pb: Option<ProgressBar> = None;
    let report = eval::run_derive_eval(dem_path, factor, out, &mut |method, done, total| {
        let pb = pb.get_or_insert_with(|| bar(total, "methods"));
        pb.set_message(method.to_owned());
        pb.set_position(done);
    });
    if let Some(pb) = pb {
        pb.finish();
    }
    let report = report?;
    println!(
        "{:<22} {:>9} {:>9} {:>10} {:>10} {:>9} {:>11}  parameters",
        "method", "RMSE m", "max m", "slope deg", "bias deg", "rough", "ms/tile"
    );
    for r in &report.results {
        println!(
            "{:<22} {:>9.3} {:>9.2} {:>10.3} {:>10.3} {:>9.3} {:>11.4}  {}",
            r.method,
            r.rmse_m,
            r.max_m,
            r.slope_rmse_deg,
            r.slope_bias_deg,
            r.roughness_ratio,
            r.ms_per_tile,
            r.parameters()
        );
    }
    if let Some(fit) = report.calibration() {
        println!("calibration from the coarse grid: {}", fit.note);
    }
    println!(
        "on the joint Pareto front (time, height, slope, flattening, roughness): {}",
        report.front.join(", ")
    );
    println!(
        "runtime method: {} ({} the joint front); wrote derive.csv and charts to {}",
        eval::RUNTIME_METHOD,
        if report.runtime_on_front() {
            "on"
        } else {
            "NOT on"
        },
        out.display()
    );
    Ok(())
}

fn eval_sway(out: &Path) -> Result<()> {
    use verdant::tools::eval_sway as sway;
    use verdant::tools::sway_integrators::{EulerLimits, Integrator, Preset, RENDERER_INTEGRATOR};
    let report = sway::run_sway_eval(out)?;
    for preset in Preset::ALL {
        let spring = preset.spring();
        println!(
            "{} spring (grass stiffness {}): k {:.1} 1/s^2, c {:.2} 1/s ({:.3} Hz, damping ratio {:.2}); \
             explicit Euler stable below {:.1} ms, semi-implicit below {:.1} ms",
            preset.name(),
            preset.grass_stiffness(),
            spring.stiffness,
            spring.damping,
            spring.natural_frequency_hz(),
            spring.damping_ratio(),
            spring.explicit_euler_max_dt() * 1e3,
            spring.semi_implicit_euler_max_dt() * 1e3
        );
    }
    println!(
        "{:<7} {:<14} {:>7} {:>11} {:>11} {:>8}  stable",
        "preset", "integrator", "dt", "RMS rad", "max rad", "ns/step"
    );
    for r in &report.results {
        println!(
            "{:<7} {:<14} {:>7} {:>11.3e} {:>11.3e} {:>8.1}  {}",
            r.preset,
            r.integrator.name(),
            sway::dt_label(r.dt_s),
            r.rms_error,
            r.max_error,
            r.ns_per_step,
            match r.blew_up_at_s {
                None => "yes".to_owned(),
                Some(t) => format!("NO, blew up at {t:.2} s"),
            }
        );
    }
    let names: Vec<&str> = report.stable.iter().map(Integrator::name).collect();
    println!(
        "stable at every step and at the 0.5 s hitch, both presets: {}",
        if names.is_empty() {
            "none".to_owned()
        } else {
            names.join(", ")
        }
    );
    println!(
        "renderer integrator: {} ({}); wrote sway.csv and charts to {}",
        RENDERER_INTEGRATOR.name(),
        if report.renderer_bounded() {
            "bounded in every run above, and exact for wind held over a frame"
        } else {
            "NOT bounded in every run above"
        },
        out.display()
    );
    Ok(())
}

/// Most frames `fly` and `view` render in one run (what they keep per frame is thinned to a
/// bound, so any count runs in bounded memory).
const MAX_FRAMES: i64 = u32::MAX as i64;

/// Most MiB a memory ceiling may name (1 TiB).
const MAX_MIB: u64 = 1 << 20;

/// Parses a size in MiB, 1..=[`MAX_MIB`].
fn parse_mib(s: &str) -> Result<u64, String> {
    let mib: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number of MiB"))?;
    if !(1..=MAX_MIB).contains(&mib) {
        return Err(format!("{mib} MiB is out of range (1..={MAX_MIB} MiB)"));
    }
    Ok(mib)
}

/// A parser of a finite number in `lo..=hi` whose error states the range.
fn float_in(lo: f64, hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    move |s: &str| match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (lo..=hi).contains(&v) => Ok(v),
        Ok(_) => Err(format!("{} is out of range ({lo}..={hi})", s.trim())),
        Err(_) => Err(format!("{s:?} is not a number (expected {lo}..={hi})")),
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
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
fn parse_cell_size(s: &str) -> Result<[f64; 2], String> {
    let parse = |v: &str| -> Result<f64, String> {
        match v.trim().parse::<f64>() {
            Ok(m) if m.is_finite() && m > 0.0 => Ok(m),
            _ => Err(format!("{v:?} is not a positive number of metres")),
        }
    };
    match s.split_once(',') {
        Some((ew, ns)) => Ok([parse(ew)?, parse(ns)?]),
        None => parse(s).map(|m| [m, m]),
    }
}

/// A world argument is a folder, or a name under `./worlds` or the crate's own `worlds`.
fn resolve_world(arg: &str) -> Result<PathBuf> {
    if verdant::stream::http::is_url(arg) {
        // Opened over HTTP by the tools.
        return Ok(PathBuf::from(arg));
    }
    let direct = Path::new(arg);
    if direct.join("world.toml").is_file() {
        return Ok(direct.to_path_buf());
    }
    // A bare name is also looked for under the worlds folders; a path only where it points.
    let bare = direct.components().count() == 1 && !direct.is_absolute();
    let mut candidates: Vec<PathBuf> = Vec::new();
    if bare {
        for c in [
            Path::new("worlds").join(arg),
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("worlds")
                .join(arg),
        ] {
            if c.join("world.toml").is_file() {
                return Ok(c);
            }
            if !candidates.contains(&c) {
                candidates.push(c);
            }
        }
    }
    if direct.is_dir() {
        // Let the world loader say what is missing.
        return Ok(direct.to_path_buf());
    }
    match candidates.first() {
        Some(c) => bail!(
            "no world {arg:?}: neither {} nor {} holds a world.toml",
            direct.display(),
            c.display()
        ),
        None => bail!("no world at {}: no such folder", direct.display()),
    }
}

fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template(
            "{msg:>10} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}

fn fly_truth(opts: FlyOptions, k: u32) -> Result<()> {
    let mut pb: Option<ProgressBar> = None;
    let r = verdant::tools::truth::run_fly_truth(&opts, k, &mut |p| {
        if let FlyProgress::Frame(done, total) = p {
            pb.get_or_insert_with(|| bar(total, "truth"))
                .set_position(done);
        }
    })?;
    println!(
        "{} truth frames ({k}x{k} sub-samples) of {} ({}) at {}x{} in {:.1} s; wrote {}",
        r.frames.len(),
        r.world,
        r.path,
        r.size.0,
        r.size.1,
        r.seconds,
        opts.out.display()
    );
    Ok(())
}

fn fly(opts: FlyOptions) -> Result<()> {
    let mut frames: Option<ProgressBar> = None;
    let report = run_fly(&opts, &mut |p| match p {
        FlyProgress::WarmingUp => eprintln!("loading the first frame's tiles"),
        FlyProgress::WarmUpIncomplete(missing) => {
            eprintln!(
                "warning: not every tile of the first frame became resident; going on, drawing \
                 these from their ancestors:"
            );
            for m in missing {
                eprintln!("  {m}");
            }
        }
        FlyProgress::Frame(done, total) => {
            let pb = frames.get_or_insert_with(|| {
                eprintln!("rendering {total} frames");
                bar(total, "frames")
            });
            pb.set_position(done);
        }
    })?;
    if let Some(pb) = frames {
        pb.finish();
    }
    let s = &report.summary;
    println!(
        "{} frames of {} ({}) on {} [{}]",
        report.frames.len(),
        report.world,
        report.path,
        report.adapter.name,
        report.adapter.backend
    );
    println!(
        "frame time: median {:.2} ms, p99 {:.2} ms; tiles drawn: median {:.0}",
        s.frame_ms.median, s.frame_ms.p99, s.tiles_drawn.median
    );
    println!(
        "tiles resident at their own level: median {:.0}%, holes {}, cache peak {:.1} MiB, atlas peak {} slots",
        100.0 * s.resident_fraction.median,
        s.holes,
        s.cache_peak_bytes as f64 / (1 << 20) as f64,
        s.atlas_peak_slots
    );
    println!(
        "grass blades a frame: considered median {:.0}, drawn median {:.0} high LOD + {:.0} low LOD",
        s.grass_considered.median, s.grass_drawn_high.median, s.grass_drawn_low.median
    );
    println!(
        "grass coverage within {:.0} m: median {:.1}%, mean {:.1}% over {} frames",
        verdant::tools::metrics::COVERAGE_DISTANCE_M,
        100.0 * s.coverage.median,
        100.0 * s.coverage.mean,
        report.coverage.len()
    );
    for (pass, t) in &s.gpu_ms {
        println!("gpu {pass}: median {:.3} ms, p99 {:.3} ms", t.median, t.p99);
    }
    println!("wrote {}", opts.out.join("report.json").display());
    Ok(())
}

fn soak(opts: SoakOptions) -> Result<()> {
    let mut pb: Option<ProgressBar> = None;
    let r = run_soak(&opts, &mut |done, total| {
        pb.get_or_insert_with(|| bar(total, "frames"))
            .set_position(done);
    })?;
    if let Some(pb) = pb {
        pb.finish();
    }
    let mib = |b: u64| b as f64 / 1048576.0;
    println!(
        "{} frames ({:.0} s at {} m/s) on {}: frame p50 {:.1} ms, p99 {:.1} ms",
        r.frames, r.seconds, r.speed_mps, r.adapter.name, r.frame_ms.median, r.frame_ms.p99
    );
    println!(
        "peak RSS {:.1} MiB, growth after warm-up {:.1} MiB; cache peak {:.1} of {:.1} MiB; atlas peak {} of {} slots",
        mib(r.rss_peak_bytes),
        mib(r.rss_growth_bytes),
        mib(r.cache_peak_bytes),
        mib(r.cache_ceiling_bytes),
        r.atlas_peak_slots,
        r.atlas_slots
    );
    println!(
        "loads: {} completed, {} cancelled, {} failed; {} evictions; cache hit rate {:.0}%; \
         full detail {} after a teleport (median of {})",
        r.loads_completed,
        r.loads_cancelled,
        r.loads_failed,
        r.evictions,
        100.0 * r.cache_hit_rate,
        r.full_detail_after_teleport_s
            .map_or("never reached".to_owned(), |s| format!("{s:.1} s")),
        r.teleports.len()
    );
    if let Some(f) = &r.faults {
        let injected = match (&f.files, &f.http) {
            (Some(c), _) => format!("{} tile files broken", c.injected()),
            (_, Some(h)) => format!("{} of {} requests faulted", h.faults(), h.requests),
            _ => "none injected".to_owned(),
        };
        println!(
            "faults at rate {}: {injected}, {} loads failed, {} tiles healed, at most {} \
             desired tiles drawn from an ancestor for a fault",
            f.rate, f.loads_failed, f.tiles_healed, f.fault_blocked_peak
        );
    }
    println!("wrote {}", opts.out.join("soak.json").display());
    if !r.violations.is_empty() {
        for v in r.violations.iter().take(20) {
            eprintln!("violation: {v}");
        }
        bail!("the soak failed {} check(s)", r.violation_count);
    }
    Ok(())
}

impl FlyArgs {
    fn options(self) -> Result<FlyOptions> {
        let FlyArgs {
            world,
            path,
            frames,
            size,
            out,
            no_images,
            wind,
            disable,
            enable,
            grass_spacing_m,
            grass_width_scale,
            grass_infill_m,
            grass_segments,
            grass_near_m,
            mesh_step,
            truth: _,
            stream,
        } = self;
        Ok(FlyOptions {
            world: resolve_world(&world)?,
            http: stream.http(),
            path,
            frames,
            size,
            out,
            write_images: !no_images,
            service: stream.service(),
            wind_scene: wind,
            disable,
            enable,
            grass_spacing_m,
            grass_width_scale,
            grass_infill_m: match grass_infill_m.as_deref() {
                None => None,
                Some(&[half, quarter]) => Some([half, quarter]),
                Some(v) => {
                    anyhow::bail!("--grass-infill-m takes two radii, HALF,QUARTER, not {v:?}")
                }
            },
            grass_segments: match grass_segments.as_deref() {
                None => None,
                Some(&[near, high, low]) => Some([near, high, low]),
                Some(v) => {
                    anyhow::bail!("--grass-segments takes three counts, NEAR,HIGH,LOW, not {v:?}")
                }
            },
            grass_near_m,
            mesh_step,
        })
    }
}

impl SoakArgs {
    fn options(self) -> Result<SoakOptions> {
        let SoakArgs {
            world,
            seconds,
            speed,
            seed,
            size,
            out,
            no_grass,
            max_recovery_frames,
            max_stall_ms,
            faults,
            stream,
        } = self;
        Ok(SoakOptions {
            world: resolve_world(&world)?,
            http: stream.http(),
            seconds,
            speed_mps: speed,
            seed,
            size,
            out,
            service: stream.service(),
            no_grass,
            max_recovery_frames,
            max_stall_ms,
            faults,
            ..SoakOptions::default()
        })
    }
}

fn view(args: ViewArgs) -> Result<()> {
    let ViewArgs {
        world,
        size,
        no_vsync,
        path,
        follow,
        frames,
        screenshot,
        wind,
        stream,
    } = args;
    let summary = verdant::tools::view::run_view(verdant::tools::view::ViewOptions {
        world: resolve_world(&world)?,
        http: stream.http(),
        size,
        vsync: !no_vsync,
        path,
        follow,
        frames,
        screenshot: screenshot.clone(),
        service: stream.service(),
        wind_scene: wind,
    })?;
    println!(
        "{} frames, median {:.1} ms a frame ({:.1} fps) on {}",
        summary.frames,
        summary.median_frame_ms,
        1e3 / summary.median_frame_ms.max(1e-3),
        summary.adapter
    );
    if let Some(file) = screenshot {
        println!("wrote {}", file.display());
    }
    Ok(())
}

fn bake_world(args: BakeArgs) -> Result<()> {
    let BakeArgs {
        dem,
        dem_cell_size,
        out,
        name,
        cell_size,
        tile_cells,
        levels,
        seed,
        replace,
    } = args;
    let opts = BakeOptions {
        dem,
        dem_cell_size_m: dem_cell_size,
        out,
        name,
        cell_size_m: cell_size,
        tile_cells,
        stored_levels: levels,
        seed,
        replace,
        cancel: Some(
            verdant::bake::CancelFlag::on_termination_signals()
                .context("installing the SIGINT and SIGTERM handlers")?,
        ),
    };
    let mut current: Option<(String, ProgressBar)> = None;
    let report = bake(&opts, &mut |stage, done, total| {
        let label = format!("{stage:?}").to_lowercase();
        if current.as_ref().map(|(l, _)| l != &label).unwrap_or(true) {
            if let Some((_, pb)) = current.take() {
                pb.finish();
            }
            current = Some((label.clone(), bar(total, &label)));
        }
        if let Some((_, pb)) = &current {
            pb.set_length(total);
            pb.set_position(done);
        }
    })
    .with_context(|| format!("baking {}", opts.dem.display()))?;
    if let Some((_, pb)) = current {
        pb.finish();
    }
    println!(
        "read {} ({}, {}x{} samples of {:.3} m x {:.3} m, {} nodata samples filled)",
        opts.dem.display(),
        report.dem_format.name(),
        report.dem_samples[0],
        report.dem_samples[1],
        report.dem_cell_size_m[0],
        report.dem_cell_size_m[1],
        report.nodata_filled
    );
    println!(
        "baked {} tiles in {} levels into {} in {:.1} s",
        report.tiles_written,
        report.levels,
        opts.out.display(),
        report.seconds
    );
    Ok(())
}

fn serve(world: &str, addr: &str) -> Result<()> {
    let dir = resolve_world(world)?;
    if verdant::stream::http::is_url(world) {
        bail!("verdant serve serves a world folder, not {world}");
    }
    let server = verdant::tools::serve::WorldServer::start(&dir, addr)?;
    println!("serving {} at {}", dir.display(), server.url());
    server.wait();
    Ok(())
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Fly(args) => match args.truth {
            Some(k) => fly_truth(args.options()?, k),
            None => fly(args.options()?),
        },
        Command::View(args) => view(args),
        Command::Soak(args) => soak(args.options()?),
        Command::Serve { world, addr } => serve(&world, &addr),
        Command::Bench {
            what:
                BenchCommand::Features {
                    world,
                    out,
                    size,
                    timing,
                    truth,
                },
        } => bench_features(verdant::tools::BenchLodOptions {
            world: resolve_world(&world)?,
            out,
            size,
            warmup_frames: timing.warmup_frames,
            timed_frames: timing.timed_frames,
            rounds: timing.rounds,
            truth_k: truth.truth,
            ..Default::default()
        }),
        Command::Bench {
            what:
                BenchCommand::Blades {
                    out,
                    size,
                    field_m,
                    camera,
                    target,
                    fov_deg,
                    counts,
                    timing,
                    truth,
                },
        } => bench_blades(verdant::tools::bench_blades::BenchBladesOptions {
            out,
            size,
            field_m,
            camera_m: camera,
            target_m: target,
            fov_deg,
            counts,
            warmup_frames: timing.warmup_frames,
            timed_frames: timing.timed_frames,
            rounds: timing.rounds,
            truth_k: truth.truth,
        }),
        Command::Bench {
            what:
                BenchCommand::Lod {
                    world,
                    out,
                    size,
                    dolly_frames,
                    timing,
                    truth,
                },
        } => bench_lod(verdant::tools::BenchLodOptions {
            world: resolve_world(&world)?,
            out,
            size,
            dolly_frames,
            warmup_frames: timing.warmup_frames,
            timed_frames: timing.timed_frames,
            rounds: timing.rounds,
            path: None,
            truth_k: truth.truth,
        }),
        Command::Eval {
            what: EvalCommand::Derive { dem, factor, out },
        } => eval_derive(&dem, factor, &out),
        Command::Eval {
            what: EvalCommand::Sway { out },
        } => eval_sway(&out),
        Command::Bake(args) => bake_world(args),
    }
}

/// The error and its causes, joined by ": ", leaving out a cause that the message before it
/// already quotes (typed errors name their file and repeat their source's message).
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_chain(&e));
            ExitCode::FAILURE
        }
    }
}
