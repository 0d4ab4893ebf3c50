//! `verdant fly`: its options and the summary it prints.

use std::path::PathBuf;

use anyhow::{Result, bail};

use verdant::renderer::{DEFAULT_MESH_STEP, GrassConfig};
use verdant::tools::{FlyOptions, FlyProgress, run_fly};

use super::args::{MAX_FRAMES, StreamArgs, TaaArgs, float_in, parse_size, resolve_world};
use super::out::{note, say};
use super::progress::TenthsBar;

// The options of `verdant fly`.
#[derive(clap::Args)]
pub(crate) struct FlyArgs {
    /// World folder, the name of a world under ./worlds, or a world's http:// address.
    #[arg(default_value = "santa-cruz")]
    pub(crate) world: std::ffi::OsString,
    /// Camera path from the world's manifest (default: its first path).
    #[arg(long)]
    pub(crate) path: Option<String>,
    /// Frames to render, spread evenly over the path, 1..=4294967295.
    #[arg(long, default_value_t = 240, value_parser = clap::value_parser!(u32).range(1..=MAX_FRAMES))]
    pub(crate) frames: u32,
    /// Image size, WIDTHxHEIGHT, 1..=16384 pixels a side.
    #[arg(long, default_value = "640x360", value_parser = parse_size)]
    pub(crate) size: (u32, u32),
    /// Output folder.
    #[arg(long, default_value = "out/fly")]
    pub(crate) out: PathBuf,
    /// Write only report.json, no PNG frames.
    #[arg(long)]
    pub(crate) no_images: bool,
    /// Wind scene of the world's manifest (e.g. calm, breeze, storm, helicopter) for the
    /// whole flight (default: the path's own wind keys if it has any, else breeze).
    #[arg(long)]
    pub(crate) wind: Option<String>,
    /// Features to switch off, comma-separated: wind-sources, interaction,
    /// detail-bending, translucency, specular, ambient-occlusion, color-variation,
    /// ground-darkening, far-field, shadows, plants, trees, tree-shadows, particles (on top of
    /// the manifest's [features] table).
    #[arg(long, value_delimiter = ',')]
    pub(crate) disable: Vec<verdant::features::Feature>,
    /// Features to switch on that the manifest's [features] table switches off,
    /// comma-separated (the names of --disable).
    #[arg(long, value_delimiter = ',')]
    pub(crate) enable: Vec<verdant::features::Feature>,
    /// Blade spacing of the near grass grid, metres, 0.02..=5 (default: the renderer's).
    #[arg(long)]
    pub(crate) grass_spacing_m: Option<f32>,
    /// Every grass type's blade width times this, 0.05..=20 (default: the renderer's).
    #[arg(long)]
    pub(crate) grass_width_scale: Option<f32>,
    /// Radii of the grass infill near the camera, HALF,QUARTER metres: blades at half the
    /// spacing out to the first, at a quarter of it out to the second, each 0..=100 and
    /// QUARTER no larger than HALF; 0,0 turns it off (default: the renderer's).
    #[arg(long, value_delimiter = ',')]
    pub(crate) grass_infill_m: Option<Vec<f32>>,
    /// Blade segments NEAR,HIGH,LOW: of the blades near the camera, the rest of the high
    /// ring and the low ring, each 1..=64 (default: the renderer's).
    #[arg(long, value_delimiter = ',')]
    pub(crate) grass_segments: Option<Vec<u32>>,
    /// Horizontal radius of the blades drawn with the NEAR segments, metres, 0..=200
    /// (default: the renderer's).
    #[arg(long)]
    pub(crate) grass_near_m: Option<f32>,
    /// How many times as wide the low ring's blades are drawn (the blades the low grid keeps
    /// widen to it as the others fade out), 1..=4 (default: the renderer's).
    #[arg(long)]
    pub(crate) grass_lod_widen: Option<f32>,
    /// Metres toward the blades' fade at the view distance per metre the camera stands above a
    /// blade, 0..=8 (default: the renderer's, 1): from 1 / (1 + K) of the view distance up no
    /// blade is drawn, the far field showing the grass below; 0 fades them by distance alone.
    #[arg(long, value_name = "K")]
    pub(crate) grass_elevation_fade: Option<f32>,
    /// The grass's view distance, metres, 10..=300: the blades end there and the far field
    /// stands in for them beyond; the plants' meshes and cards follow it (default: the
    /// renderer's, four thirds of a grass tile, 67 m in the default world).
    #[arg(long, value_name = "M", value_parser = float_in(10.0, 300.0))]
    pub(crate) grass_view_m: Option<f64>,
    /// Plants' level-of-detail switches NEAR,FAR, metres: the full mesh out to NEAR, the
    /// reduced mesh out to FAR, crossed cards beyond, 0 < NEAR <= FAR <= 10000 (default: the
    /// renderer's, 25,150).
    #[arg(long, value_delimiter = ',')]
    pub(crate) plant_lod_m: Option<Vec<f32>>,
    /// How far plants reach beyond the grass, in view distances: thinning out from the view
    /// distance to this many times it, 1..=16 (1: none beyond the grass; default: the
    /// renderer's, 2).
    #[arg(long)]
    pub(crate) plant_card_reach: Option<f32>,
    /// Beyond this distance, metres, plants thin out as the square of the distance, down to
    /// half of them, the survivors grown to keep the cover, above 0 and at most 10000
    /// (default: the renderer's, 50).
    #[arg(long)]
    pub(crate) plant_thin_m: Option<f32>,
    /// Trees' level-of-detail switches NEAR,FAR, metres: the full mesh out to NEAR, the
    /// reduced mesh out to FAR, crossed cards beyond, to the fog, 0 < NEAR <= FAR <= 10000
    /// (default: the renderer's, 60,300).
    #[arg(long, value_delimiter = ',')]
    pub(crate) tree_lod_m: Option<Vec<f32>>,
    /// Beyond this distance, metres, trees thin out as the square of the distance, down to
    /// --tree-min-keep of them, the survivors grown to keep the cover, above 0 and at most
    /// 10000 (default: the renderer's, 1600).
    #[arg(long)]
    pub(crate) tree_thin_m: Option<f32>,
    /// The fewest trees the thinning keeps, above 0 and at most 1 (default: the renderer's,
    /// 1/6).
    #[arg(long)]
    pub(crate) tree_min_keep: Option<f32>,
    /// How far from the camera the trees' shadows reach, metres (10 to 2000; default 160).
    #[arg(long)]
    pub(crate) tree_shadow_m: Option<f32>,
    /// Edge of each cascade of the trees' shadow map, texels (256 to 8192; default 1024).
    #[arg(long)]
    pub(crate) tree_shadow_size: Option<u32>,
    /// Cascades of the trees' shadow map (1 to 4; default 2).
    #[arg(long)]
    pub(crate) tree_shadow_cascades: Option<u32>,
    /// The shadow casters' level-of-detail switches NEAR,FAR, metres: the full mesh out to
    /// NEAR (0: none), the reduced mesh out to FAR, the card turned to the sun beyond
    /// (default 0,25).
    #[arg(long, value_delimiter = ',')]
    pub(crate) tree_shadow_lod_m: Option<Vec<f32>>,
    /// Terrain mesh: one vertex every this many samples of a tile, a power of two in 1..=16
    /// (default: the renderer's).
    #[arg(long)]
    pub(crate) mesh_step: Option<u32>,
    /// Anti-aliasing: off, taa (temporal: jittered frames folded into a reprojected history;
    /// for consecutive frames, e.g. --frames at 60 a second of the path) or msaa (the grass
    /// multisampled, 4 samples, sub-pixel blades kept as coverage). Default: the renderer's.
    #[arg(long)]
    pub(crate) aa: Option<verdant::aa::AntiAliasing>,
    #[command(flatten)]
    pub(crate) taa: TaaArgs,
    /// Render the frames as the truth instead: supersampled K x K (1..=8) in linear light, no
    /// LOD, 16 blade segments everywhere, blades out to 9 times the view distance (600 m in the
    /// default world).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=8))]
    pub(crate) truth: Option<u32>,
    #[command(flatten)]
    pub(crate) stream: StreamArgs,
}

impl FlyArgs {
    /// With `--truth`, refuses the options that the truth sets itself (its LOD, segments,
    /// reach, plants' and trees' meshes, anti-aliasing), naming the first given: a run would
    /// otherwise take them and draw without them. The grass's spacing, width, infill and
    /// elevation fade, the mesh step, the features and the wind describe the scene and apply.
    pub(crate) fn check_truth_options(&self) -> Result<()> {
        if self.truth.is_none() {
            return Ok(());
        }
        let given = [
            (self.grass_view_m.is_some(), "--grass-view-m"),
            (self.grass_segments.is_some(), "--grass-segments"),
            (self.grass_near_m.is_some(), "--grass-near-m"),
            (self.grass_lod_widen.is_some(), "--grass-lod-widen"),
            (self.plant_lod_m.is_some(), "--plant-lod-m"),
            (self.plant_card_reach.is_some(), "--plant-card-reach"),
            (self.plant_thin_m.is_some(), "--plant-thin-m"),
            (self.tree_lod_m.is_some(), "--tree-lod-m"),
            (self.tree_thin_m.is_some(), "--tree-thin-m"),
            (self.tree_min_keep.is_some(), "--tree-min-keep"),
            (self.tree_shadow_m.is_some(), "--tree-shadow-m"),
            (self.tree_shadow_size.is_some(), "--tree-shadow-size"),
            (
                self.tree_shadow_cascades.is_some(),
                "--tree-shadow-cascades",
            ),
            (self.tree_shadow_lod_m.is_some(), "--tree-shadow-lod-m"),
            (self.aa.is_some(), "--aa"),
        ]
        .into_iter()
        .find_map(|(given, name)| given.then_some(name))
        .or_else(|| self.taa.first_given());
        if let Some(option) = given {
            bail!(
                "{option} does not apply to --truth, which draws its own level of detail, blade \
                 segments, reach, plant and tree meshes and anti-aliasing (its sub-samples): \
                 leave it out (the grass's spacing, width and infill, --mesh-step, the features \
                 and the wind apply)"
            );
        }
        Ok(())
    }

    pub(crate) fn options(self) -> Result<FlyOptions> {
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
            grass_lod_widen,
            grass_elevation_fade,
            grass_view_m,
            plant_lod_m,
            plant_card_reach,
            plant_thin_m,
            tree_lod_m,
            tree_thin_m,
            tree_min_keep,
            tree_shadow_m,
            tree_shadow_size,
            tree_shadow_cascades,
            tree_shadow_lod_m,
            mesh_step,
            aa,
            taa,
            truth: _,
            stream,
        } = self;
        if let (Some(m), Some(option)) = (aa, taa.first_given())
            && m != verdant::aa::AntiAliasing::Taa
        {
            bail!(
                "{option} sets the temporal anti-aliasing, and --aa {} turns it off: leave it \
                 out, or fly with --aa taa",
                m.name()
            );
        }
        if let Some(f) = disable.iter().find(|f| enable.contains(f)) {
            bail!(
                "--disable and --enable both name {}: a feature is switched one way or the other",
                f.name()
            );
        }
        // The renderer's defaults with what was given; RendererConfig::validate checks the
        // ranges.
        let mut grass = GrassConfig::default();
        if let Some(s) = grass_spacing_m {
            grass.spacing_m = s;
        }
        if let Some(w) = grass_width_scale {
            grass.width_scale = w;
        }
        match grass_infill_m.as_deref() {
            None => {}
            Some(&[half, quarter]) => grass.infill_m = [half, quarter],
            Some(v) => bail!("--grass-infill-m takes two radii, HALF,QUARTER, not {v:?}"),
        }
        match grass_segments.as_deref() {
            None => {}
            Some(&[near, high, low]) => grass.segments = [near, high, low],
            Some(v) => bail!("--grass-segments takes three counts, NEAR,HIGH,LOW, not {v:?}"),
        }
        if let Some(r) = grass_near_m {
            grass.near_m = r;
        }
        if let Some(k) = grass_lod_widen {
            grass.lod_widen = k;
        }
        if let Some(k) = grass_elevation_fade {
            grass.elevation_fade = k;
        }
        let plant_lod_m = near_far("--plant-lod-m", plant_lod_m)?
            .unwrap_or(verdant::plants::PlantSettings::default().lod_m);
        let tree_lod_m = near_far("--tree-lod-m", tree_lod_m)?;
        let mut tree_shadows = verdant::plants::shadow::TreeShadows::default();
        if let Some(m) = tree_shadow_m {
            tree_shadows.distance_m = m;
        }
        if let Some(n) = tree_shadow_size {
            tree_shadows.size = n;
        }
        if let Some(n) = tree_shadow_cascades {
            tree_shadows.cascades = n;
        }
        if let Some(m) = near_far("--tree-shadow-lod-m", tree_shadow_lod_m)? {
            tree_shadows.lod_m = m;
        }
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
            grass,
            grass_view_m,
            mesh_step: mesh_step.unwrap_or(DEFAULT_MESH_STEP),
            aa: aa.unwrap_or_default(),
            taa: taa.settings(),
            plant_lod_m,
            plant_card_reach: plant_card_reach
                .unwrap_or(verdant::plants::PlantSettings::default().card_reach),
            plant_thin_m: plant_thin_m.unwrap_or(verdant::plants::PlantSettings::default().thin_m),
            tree_lod_m,
            tree_thin_m,
            tree_min_keep,
            tree_shadows,
            stop: None,
        })
    }
}

/// After an interrupted run that wrote `written` frames into `out`: warns of frames of an
/// earlier, longer run beyond them, which are not this run's and which its `report` (the file
/// name) does not describe.
fn warn_of_frames_beyond(out: &std::path::Path, written: u32, report: &str) {
    let stale = verdant::tools::fly::stale_frames(out, written);
    if let (Some(first), Some(last)) = (stale.first(), stale.last()) {
        note!(
            "warning: {} holds {} frame images of an earlier run beyond the {written} this run \
             wrote ({first} to {last}), which its {report} does not describe",
            out.display(),
            stale.len()
        );
    }
}

/// Warns of what an earlier run left in the output folder `out` beside this run's outputs.
fn warn_of_stale(out: &std::path::Path, p: FlyProgress) {
    match p {
        FlyProgress::StaleFrames(count, first, last) => {
            let which = if count == 1 {
                first
            } else {
                format!("{first} to {last}")
            };
            note!(
                "warning: {} holds {count} frame image{} of an earlier run that this run does not \
                 write ({which}), which this run's report does not describe",
                out.display(),
                if count == 1 { "" } else { "s" }
            );
        }
        FlyProgress::StaleReport(report) => note!(
            "warning: {} holds {report} of an earlier run, which describes frame images this \
             run writes over",
            out.display()
        ),
        _ => {}
    }
}

/// `fly --truth K`: the path's frames rendered as the truth.
pub(crate) fn fly_truth(mut opts: FlyOptions, k: u32) -> Result<()> {
    opts.stop = Some(super::stop_on_signals()?);
    let mut pb = TenthsBar::new("truth", "truth:", "frames");
    let r = verdant::tools::truth::run_fly_truth(&opts, k, &mut |p| match p {
        FlyProgress::WarmingUp => note!("loading the first frame's tiles"),
        FlyProgress::Frame(done, total) => pb.set(done, total),
        p @ (FlyProgress::StaleFrames(..) | FlyProgress::StaleReport(_)) => {
            warn_of_stale(&opts.out, p)
        }
        _ => {}
    })?;
    pb.end(r.interrupted);
    say!(
        "{} truth frames ({k}x{k} sub-samples) of {} ({}) at {}x{} in {:.1} s; wrote {}",
        r.frames.len(),
        r.world,
        r.path,
        r.size.0,
        r.size.1,
        r.seconds,
        opts.out.display()
    )?;
    if r.failed_loads > 0 {
        note!(
            "warning: {} tile loads failed during the run and those tiles were drawn from their \
             ancestors: these frames are not the truth of the world's stored tiles where they \
             show them (failed_loads in {})",
            r.failed_loads,
            opts.out.join("truth.json").display()
        );
    }
    if r.interrupted {
        warn_of_frames_beyond(
            &opts.out,
            u32::try_from(r.frames.len()).unwrap_or(u32::MAX),
            "truth.json",
        );
        return Err(super::Interrupted(format!(
            "stopped after {} of {} frames; {} describes those",
            r.frames.len(),
            opts.frames,
            opts.out.join("truth.json").display()
        ))
        .into());
    }
    Ok(())
}

pub(crate) fn fly(mut opts: FlyOptions) -> Result<()> {
    // Ctrl-C ends the flight after the frame under way, writing what was flown; a second one
    // ends the process at once.
    opts.stop = Some(super::stop_on_signals()?);
    let mut frames: Option<TenthsBar> = None;
    let report = run_fly(&opts, &mut |p| match p {
        FlyProgress::WarmingUp => note!("loading the first frame's tiles"),
        FlyProgress::WarmUpIncomplete(missing) => {
            note!(
                "warning: not every tile of the first frame became resident; going on, drawing \
                 these from their ancestors:"
            );
            for m in missing {
                note!("  {m}");
            }
        }
        p @ (FlyProgress::StaleFrames(..) | FlyProgress::StaleReport(_)) => {
            warn_of_stale(&opts.out, p)
        }
        FlyProgress::Frame(done, total) => {
            frames
                .get_or_insert_with(|| {
                    note!("rendering {total} frames");
                    TenthsBar::new("frames", "fly:", "frames")
                })
                .set(done, total);
        }
    })?;
    if let Some(pb) = &frames {
        pb.end(report.interrupted);
    }
    if report.interrupted {
        let written = if opts.write_images {
            u32::try_from(report.frames_flown).unwrap_or(u32::MAX)
        } else {
            0
        };
        warn_of_frames_beyond(&opts.out, written, "report.json");
    }
    if report.interrupted && report.frames_flown == 0 {
        return Err(super::Interrupted(format!(
            "stopped before the first frame; {} records no frame",
            opts.out.join("report.json").display()
        ))
        .into());
    }
    let s = &report.summary;
    say!(
        "{} frames of {} ({}) on {} [{}]",
        report.frames.len(),
        report.world,
        report.path,
        report.adapter.name,
        report.adapter.backend
    )?;
    say!(
        "frame time: median {:.2} ms, p99 {:.2} ms; tiles drawn: median {:.0}",
        s.frame_ms.median,
        s.frame_ms.p99,
        s.tiles_drawn.median
    )?;
    say!(
        "tiles resident at their own level: median {:.0}%, holes {}, cache peak {:.1} MiB, atlas peak {} slots (a frame held at most {} tiles)",
        100.0 * s.resident_fraction.median,
        s.holes,
        s.cache_peak_bytes as f64 / (1 << 20) as f64,
        s.atlas_peak_slots,
        s.atlas_peak_held
    )?;
    // Tiles that could not be loaded were warned of as they failed, before the frames' lines:
    // the summary says so again, where it is read.
    let faults = report
        .frames
        .iter()
        .map(|f| f.residency.fault_blocked)
        .max()
        .unwrap_or(0);
    let failed_loads = report
        .frames
        .last()
        .map_or(0, |f| f.residency.stream.failed);
    if faults > 0 || failed_loads > 0 {
        say!(
            "tile faults: {failed_loads} loads failed, at most {faults} tiles a frame drawn from \
             their ancestors instead (the warnings above say why; `verdant check` lists them)"
        )?;
    }
    say!(
        "grass blades a frame: considered median {:.0}, drawn median {:.0} high LOD + {:.0} low LOD",
        s.grass_considered.median,
        s.grass_drawn_high.median,
        s.grass_drawn_low.median
    )?;
    if let Some(warning) = verdant::tools::fly::no_terrain_drawn(
        s.tiles_drawn.max as u32,
        "see the camera positions in report.json",
    ) {
        log::warn!("{warning}");
    }
    if s.grass_overflow.max > 0.0 {
        log::warn!(
            "grass: up to {:.0} blades a frame (median {:.0}) did not fit the grass pool and \
             were not drawn: the pool is sized by the world's [grass_peak] density (or, without \
             it, the tiles' densest grass) and capped by the adapter's buffers; a [grass_peak] \
             that understates the grass is mended by re-baking, or by removing the table",
            s.grass_overflow.max,
            s.grass_overflow.median
        );
    }
    // Plants and trees past their pools: thinned where crowded (the farthest first), dropped
    // where a region filled all the same.
    for (layer, crowded, overflow) in [
        ("plants", &s.plants_crowded, &s.plants_overflow),
        ("trees", &s.trees_crowded, &s.trees_overflow),
    ] {
        if crowded.max > 0.0 {
            say!(
                "{layer}: up to {:.0} instances a frame (median {:.0}) thinned out, the farthest \
                 first, where the view wanted more than their pool's regions hold",
                crowded.max,
                crowded.median
            )?;
        }
        if overflow.max > 0.0 {
            log::warn!(
                "{layer}: up to {:.0} instances a frame (median {:.0}) did not fit their pool's \
                 regions and were not drawn (a view that grew past the regions' margin in one \
                 frame)",
                overflow.max,
                overflow.median
            );
        }
    }
    say!(
        "grass coverage within {:.0} m: median {:.1}%, mean {:.1}% over {} frames",
        verdant::tools::metrics::COVERAGE_DISTANCE_M,
        100.0 * s.coverage.median,
        100.0 * s.coverage.mean,
        report.coverage.len()
    )?;
    for (pass, t) in &s.gpu_ms {
        say!("gpu {pass}: median {:.3} ms, p99 {:.3} ms", t.median, t.p99)?;
    }
    say!("wrote {}", opts.out.join("report.json").display())?;
    if report.interrupted {
        return Err(super::Interrupted(format!(
            "stopped after {} of {} frames; {} describes those",
            report.frames_flown,
            opts.frames,
            opts.out.join("report.json").display()
        ))
        .into());
    }
    Ok(())
}

/// The two distances NEAR,FAR of `option`, if given.
fn near_far(option: &str, given: Option<Vec<f32>>) -> Result<Option<[f32; 2]>> {
    match given.as_deref() {
        None => Ok(None),
        Some(&[near, far]) => Ok(Some([near, far])),
        Some(v) => bail!("{option} takes two distances, NEAR,FAR, not {v:?}"),
    }
}
