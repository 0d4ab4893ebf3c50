//! `verdant bench lod`: the LOD transition benchmark, measured against the truth.
//!
//! Every image is compared with the truth at the same camera and time
//! ([`crate::tools::truth`]: supersampled K x K, no LOD, 16 segments everywhere, blades out to nine
//! times the default view distance, 600 m in the default world) by pixel FLIP and by the coarse FLIP (see [`crate::tools::bench`]);
//! the old figure against the renderer's own render without LOD at the same resolution is kept
//! as a column.
//!
//! (a) Popping: a camera dolly over the meadow crosses the high/low ring boundary of many grass
//! tiles. Each frame is rendered with the default LOD settings and compared with its truth (and
//! with the no-LOD render). A pop would show as a jump of that error on a frame where tiles
//! switch ring; the jumps on frames without switches are the noise floor. In a world with trees
//! the dolly also counts the trees whose levels of detail changed each frame (the renderer's
//! tree instances read back): the jumps on frames where trees switched and no grass tile did are
//! the trees' popping.
//! (b) Speed against accuracy: for a set of LOD settings (ring radii, blade spacing, segments,
//! infill, width, view distance), GPU time per frame against the error to the truth, with the
//! Pareto front of each measure; the default setting is marked, and the report names the
//! settings on each front. The images are captured first; then the settings are timed in
//! interleaved rounds, each measurement's frames back to back with nothing in between (see
//! [`crate::tools::timing`]): a median with its interquartile range per view, a setting whose
//! spread is above 10% flagged. Each setting is also timed along a flight (the "tour" path by
//! default, `--flight`): its frames, evenly spaced along the whole path, one after the other
//! after an untimed flight that streamed the path's tiles in; the median and the 99th
//! percentile of their GPU times, with a third front of the p99 against the pixel FLIP. A
//! setting's cost can lie where the four still views do not look: the trees' mesh switches at
//! twice the default's cost 0.02 ms there and 5.7 ms at the tour's p99, where it starts in a
//! forest.
//! (c) The far field: beyond the view distance the terrain is shaded with what the grass would
//! show there. The truth draws real blades out to [`FAR_BAND_FACTOR`] times the default view
//! distance; the default setting is compared with it, with the far field on and off, by the mean
//! pixel FLIP over the band of pixels whose surface (in the truth's depth) lies between the view
//! distance and that factor times it.

use anyhow::{Context, Result, bail};
use glam::DVec3;
use serde::Serialize;

use crate::RendererConfig;
use crate::camera::{Camera, sample_path};
use crate::gpu::GpuContext;
use crate::lod::RingSettings;
use crate::tools::bench::{Bench, BenchLodOptions, Measures, flip, rgb};
use crate::tools::fly::{OutDir, Outputs, write_text};
use crate::tools::metrics::{
    Chart, ChartPoint, LineChart, Series, Summary, band_mask, flip_error_map, masked_mean,
    pareto_front, ray_distances,
};
use crate::tools::stop::{Stop, caught, chart_title};
use crate::tools::timing::{FrameCounts, Timing, frame_ms, ramp_up, run_flight, run_frames};
use crate::tools::{AdapterReport, Scene, write_json};
use crate::world::World;

/// One LOD setting: every parameter of the grass that the benchmark varies (each a column of
/// `lod_settings.csv`, so that a candidate default can be read off the front).
#[derive(Clone, Debug, Serialize)]
pub struct LodSetting {
    /// Name in tables and charts.
    pub name: String,
    /// High-LOD ring radius, in grass tile edges.
    pub high_radius_tiles: f64,
    /// View distance (low-LOD ring radius), in grass tile edges.
    pub view_distance_tiles: f64,
    /// Blade spacing of the high-LOD grid, metres.
    pub spacing_m: f32,
    /// Blade segments near the camera, in the rest of the high ring and in the low ring.
    pub segments: [u32; 3],
    /// Horizontal radius of the blades drawn with the near segments, metres.
    pub near_m: f32,
    /// Radii of the grass infill near the camera, metres (half and quarter spacing).
    pub infill_m: [f32; 2],
    /// Every grass type's blade width times this.
    pub width_scale: f32,
    /// How many times as wide the low ring's blades are drawn (`GrassConfig::lod_widen`).
    pub lod_widen: f32,
    /// Metres toward the blades' fade per metre the camera stands above them
    /// (`GrassConfig::elevation_fade`).
    pub elevation_fade: f32,
    /// The plants' switches from the full mesh to the reduced one and from that to the cards,
    /// metres.
    pub plant_lod_m: [f32; 2],
    /// How far the plants' far jobs (their cards) reach, in view distances
    /// (`PlantSettings::card_reach`).
    pub plant_card_reach: f32,
    /// Where the plants start to thin out with distance, metres (`PlantSettings::thin_m`).
    pub plant_thin_m: f32,
    /// The trees' switches, metres (`None`: the renderer's; a world without trees).
    pub tree_lod_m: Option<[f32; 2]>,
    /// Where the trees start to thin out with distance, metres (`None`: the renderer's; a world
    /// without trees).
    pub tree_thin_m: Option<f32>,
}

impl LodSetting {
    /// Whether `other` draws the same as this: every parameter equal, whatever the names.
    pub fn same_as(&self, other: &LodSetting) -> bool {
        let key = |s: &LodSetting| {
            (
                s.high_radius_tiles,
                s.view_distance_tiles,
                s.spacing_m,
                s.segments,
                s.near_m,
                s.infill_m,
                s.width_scale,
                s.lod_widen,
                s.elevation_fade,
                (s.plant_lod_m, s.plant_card_reach, s.plant_thin_m),
                s.tree_lod_m,
                s.tree_thin_m,
            )
        };
        key(self) == key(other)
    }

    /// A setting of the renderer's near radius, infill and blade width.
    pub fn new(name: &str, high: f64, view: f64, spacing_m: f32, segments: [u32; 3]) -> Self {
        Self {
            name: name.into(),
            high_radius_tiles: high,
            view_distance_tiles: view,
            spacing_m,
            segments,
            near_m: 12.0,
            infill_m: crate::renderer::DEFAULT_INFILL_M,
            width_scale: 1.0,
            lod_widen: crate::renderer::DEFAULT_LOD_WIDEN,
            elevation_fade: crate::terrain::far_field::ELEVATION_DISTANCE,
            plant_lod_m: crate::plants::PlantSettings::default().lod_m,
            plant_card_reach: crate::plants::PlantSettings::default().card_reach,
            plant_thin_m: crate::plants::PlantSettings::default().thin_m,
            tree_lod_m: None,
            tree_thin_m: None,
        }
    }

    /// The same setting with the trees thinning out from `tree_thin_m` metres.
    pub fn with_tree_thin(mut self, tree_thin_m: f32) -> Self {
        self.tree_thin_m = Some(tree_thin_m);
        self
    }

    /// The same setting with the trees' level-of-detail switches at `tree_lod_m`.
    pub fn with_tree_lod(mut self, tree_lod_m: [f32; 2]) -> Self {
        self.tree_lod_m = Some(tree_lod_m);
        self
    }

    /// The same setting with the plants' level-of-detail switches at `plant_lod_m`.
    pub fn with_plant_lod(mut self, plant_lod_m: [f32; 2]) -> Self {
        self.plant_lod_m = plant_lod_m;
        self
    }

    /// The same setting with the plants' cards reaching `card_reach` view distances, the
    /// instance pool's regions grown with the area they reach (as far as a pool can be bound).
    pub fn with_plant_card_reach(mut self, card_reach: f32) -> Self {
        self.plant_card_reach = card_reach;
        self
    }

    /// The same setting with the plants thinning out from `thin_m` metres.
    pub fn with_plant_thin(mut self, thin_m: f32) -> Self {
        self.plant_thin_m = thin_m;
        self
    }

    /// The same setting with blades `width_scale` times as wide.
    pub fn with_width(mut self, width_scale: f32) -> Self {
        self.width_scale = width_scale;
        self
    }

    /// The same setting with the low ring's blades `lod_widen` times as wide.
    pub fn with_lod_widen(mut self, lod_widen: f32) -> Self {
        self.lod_widen = lod_widen;
        self
    }

    /// The same setting with `elevation_fade` metres toward the blades' fade per metre the
    /// camera stands above them.
    pub fn with_elevation_fade(mut self, elevation_fade: f32) -> Self {
        self.elevation_fade = elevation_fade;
        self
    }

    /// The same setting with the infill radii `infill_m`.
    pub fn with_infill(mut self, infill_m: [f32; 2]) -> Self {
        self.infill_m = infill_m;
        self
    }

    /// The same setting with the near segments out to `near_m`.
    pub fn with_near(mut self, near_m: f32) -> Self {
        self.near_m = near_m;
        self
    }

    /// The scene configuration of this setting for `world`.
    pub fn config(&self, world: &World) -> RendererConfig {
        let mut c = RendererConfig::for_world(world);
        let base = RingSettings::for_pyramid(&world.manifest.pyramid);
        let size = world.manifest.pyramid.tile_size_m(base.level);
        c.grass_rings = Some(RingSettings {
            high_radius_m: self.high_radius_tiles * size,
            low_radius_m: self.view_distance_tiles * size,
            ..base
        });
        c.grass.spacing_m = self.spacing_m;
        c.grass.segments = self.segments;
        c.grass.near_m = self.near_m;
        c.grass.infill_m = self.infill_m;
        c.grass.width_scale = self.width_scale;
        c.grass.lod_widen = self.lod_widen;
        c.grass.elevation_fade = self.elevation_fade;
        c.plants.lod_m = self.plant_lod_m;
        let default_reach = c.plants.card_reach;
        c.plants.card_reach = self.plant_card_reach;
        if self.plant_card_reach > default_reach {
            // The cards' ring grows as the square of its reach: so do the regions, within
            // what a pool can bind.
            let k = (self.plant_card_reach / default_reach).powi(2);
            let types = crate::plants::PlantLayer::Plants.types(&world.manifest);
            c.plants.capacity = ((c.plants.capacity as f32 * k) as u32)
                .min(crate::plants::renderer::max_capacity(types.len() as u32));
        }
        c.plants.thin_m = self.plant_thin_m;
        if self.plant_lod_m[0] >= crate::renderer::MAX_PLANT_LOD_M {
            // No level of detail for the plants: no thinning with distance either.
            c.plants.thin_m = crate::renderer::MAX_PLANT_LOD_M;
        }
        if let Some(trees) = c.tree_settings(world) {
            c.trees = Some(crate::plants::PlantSettings {
                lod_m: self.tree_lod_m.unwrap_or(trees.lod_m),
                thin_m: self.tree_thin_m.unwrap_or(trees.thin_m),
                ..trees
            });
        }
        c
    }
}

/// The settings the benchmark compares; the first is the renderer's default, and "no LOD" (every
/// tile high LOD with the near segments, out to the default view distance) is the reference of
/// the old `flip_vs_no_lod` figure.
pub fn lod_settings(world: &World) -> Vec<LodSetting> {
    let d = RendererConfig::for_world(world);
    let rings = d
        .grass_rings
        .unwrap_or_else(|| RingSettings::for_pyramid(&world.manifest.pyramid));
    let size = world.manifest.pyramid.tile_size_m(rings.level);
    let (h, v) = (rings.high_radius_m / size, rings.low_radius_m / size);
    let (s, seg, infill) = (d.grass.spacing_m, d.grass.segments, d.grass.infill_m);
    let new = |name: &str, high: f64, view: f64, spacing: f32, segments: [u32; 3]| {
        LodSetting::new(name, high, view, spacing, segments)
            .with_near(d.grass.near_m)
            .with_infill(infill)
            .with_width(d.grass.width_scale)
            .with_lod_widen(d.grass.lod_widen)
            .with_elevation_fade(d.grass.elevation_fade)
            .with_plant_lod(d.plants.lod_m)
            .with_plant_card_reach(d.plants.card_reach)
            .with_plant_thin(d.plants.thin_m)
    };
    let plant_lod = d.plants.lod_m;
    let mut all = vec![
        new("default", h, v, s, seg),
        new("near ring x0.5", h * 0.5, v, s, seg),
        new("near ring x2", h * 2.0, v, s, seg),
        new("view x0.67", h, v * 2.0 / 3.0, s, seg),
        new("view x1.33", h, v * 4.0 / 3.0, s, seg),
        // The view distance before it was shortened to four thirds of a tile (100 m in the
        // default world).
        new("view x1.5", h, v * 1.5, s, seg),
        new("spacing x1.4", h, v, s * 1.4, seg),
        new("spacing x0.8", h, v, s * 0.8, seg),
        new("segments 7/3/3", h, v, s, [7, 3, 3]),
        new("segments 7/7/3", h, v, s, [7, 7, 3]),
        new("segments 9/3/3", h, v, s, [9, 3, 3]),
        // The default before its view distance was shortened to pay for two more near segments
        // (7 near segments, 100 m in the default world).
        new("segments 7/3/3 view x1.5", h, v * 1.5, s, [7, 3, 3]),
        new("segments 11/3/3", h, v, s, [11, 3, 3]),
        new("segments 5/3/2", h, v, s, [5, 3, 2]),
        new("segments 3/2/1", h, v, s, [3, 2, 1]),
        new("infill off", h, v, s, seg).with_infill([0.0; 2]),
        new("infill x0.8", h, v, s, seg).with_infill(infill.map(|r| 0.8 * r)),
        new("infill x1.2", h, v, s, seg).with_infill(infill.map(|r| 1.2 * r)),
        new("width x0.67", h, v, s, seg).with_width(2.0 / 3.0),
        new("width x1.5", h, v, s, seg).with_width(1.5),
        new("low ring widened x2", h, v, s, seg).with_lod_widen(2.0),
        new("low ring widened x3", h, v, s, seg).with_lod_widen(3.0),
        // The far fade's elevation term as it was (3), and none (blades fade by distance alone).
        new("elevation fade x3", h, v, s, seg).with_elevation_fade(3.0 * d.grass.elevation_fade),
        new("elevation fade x0", h, v, s, seg).with_elevation_fade(0.0),
        new("plants lod x0.5", h, v, s, seg).with_plant_lod(plant_lod.map(|m| 0.5 * m)),
        new("plants lod x2", h, v, s, seg).with_plant_lod(plant_lod.map(|m| 2.0 * m)),
        // The plants' cards out to twice and to 4.5 times their default reach (twice the view
        // distance: 4.5 times is the truth's reach of nine view distances), and their thinning
        // with distance from twice its default distance, and none.
        new("plant cards x2", h, v, s, seg).with_plant_card_reach(2.0 * d.plants.card_reach),
        new("plant cards x4.5", h, v, s, seg).with_plant_card_reach(4.5 * d.plants.card_reach),
        new("plants thin x2", h, v, s, seg).with_plant_thin(2.0 * d.plants.thin_m),
        new("plants thin off", h, v, s, seg).with_plant_thin(crate::renderer::MAX_PLANT_LOD_M),
        new("plant cards x4.5 thin off", h, v, s, seg)
            .with_plant_card_reach(4.5 * d.plants.card_reach)
            .with_plant_thin(crate::renderer::MAX_PLANT_LOD_M),
        // Every plant its full mesh out to the view distance.
        // (Its blades that the low grid would drop fade out before the view distance, as they
        // always have: nothing widens for them.)
        new("no LOD", v, v, s, [seg[0]; 3])
            .with_plant_lod([crate::renderer::MAX_PLANT_LOD_M; 2])
            .with_lod_widen(1.0),
    ];
    // A world with trees: their switches at half and twice the default's, and their thinning
    // from half and twice the default's distance.
    if world.manifest.plant_types.iter().any(|t| t.is_tree())
        && let Some(trees) = d.tree_settings(world)
    {
        let at = all.len() - 1;
        for (name, k) in [("trees lod x0.5", 0.5f32), ("trees lod x2", 2.0)] {
            let lod = trees.lod_m.map(|m| k * m);
            all.insert(at, new(name, h, v, s, seg).with_tree_lod(lod));
        }
        for (name, k) in [("trees thin x0.5", 0.5f32), ("trees thin x2", 2.0)] {
            let at = all.len() - 1;
            all.insert(at, new(name, h, v, s, seg).with_tree_thin(k * trees.thin_m));
        }
    }
    // A setting that draws what the default draws (as "segments 9/3/3" does while those are
    // the default's) would be the default's twin: measured twice, the two differ by the timing's
    // noise alone, and one would put the other off the front.
    let default = all.remove(0);
    all.retain(|s| !s.same_as(&default));
    all.insert(0, default);
    all
}

/// The settings of `all` named in `names` (all of them where `names` is empty), "default" and
/// "no LOD" always among them; a name that is not a setting is refused, listing them.
pub fn chosen_settings(all: Vec<LodSetting>, names: &[String]) -> Result<Vec<LodSetting>> {
    named_settings(&all, names)?;
    Ok(all
        .into_iter()
        .filter(|s| {
            names.is_empty() || s.name == "default" || s.name == "no LOD" || names.contains(&s.name)
        })
        .collect())
}

/// The settings of `all` named in `names`, in the order named and each once; a name that is
/// not a setting is refused, listing them.
pub fn named_settings(all: &[LodSetting], names: &[String]) -> Result<Vec<LodSetting>> {
    let mut out: Vec<LodSetting> = Vec::new();
    for name in names {
        let Some(setting) = all.iter().find(|s| &s.name == name) else {
            let known: Vec<&str> = all.iter().map(|s| s.name.as_str()).collect();
            bail!(
                "--settings: no setting {name:?}; the settings are: {}",
                known.join(", ")
            );
        };
        if !out.iter().any(|s| &s.name == name) {
            out.push(setting.clone());
        }
    }
    Ok(out)
}

/// Result of one setting.
#[derive(Clone, Debug, Serialize)]
pub struct SettingResult {
    /// The setting.
    pub setting: LodSetting,
    /// GPU time per frame over all passes (mean over the views of their medians and
    /// quartiles; the largest spread), milliseconds; zero without timestamps.
    pub gpu: Timing,
    /// Wall time per frame, frames back to back, milliseconds.
    pub frame: Timing,
    /// Mean error against the truth over the views, by both measures.
    pub vs_truth: Measures,
    /// Mean pixel FLIP of the setting's own frames (one sample a pixel) against the truth: the
    /// same as `vs_truth.flip` unless `--supersample` measured supersampled images, when the
    /// difference is what one sample a pixel adds to what the setting draws.
    pub flip_frame_vs_truth: f64,
    /// Mean pixel FLIP against the "no LOD" setting's render over the views (the old figure;
    /// `None` in a run stopped before the no-LOD setting's images were captured).
    pub flip_vs_no_lod: Option<f64>,
    /// Blades drawn per frame (median).
    pub blades_drawn: f64,
    /// Grass coverage within [`crate::tools::metrics::COVERAGE_DISTANCE_M`] (see
    /// [`crate::tools::metrics::grass_coverage`]), mean over the views, measured on the
    /// captured frames, not the timed ones.
    pub coverage: f64,
    /// On the Pareto front of time against pixel FLIP against the truth.
    pub pareto: bool,
    /// On the Pareto front of time against the coarse FLIP against the truth.
    pub pareto_coarse: bool,
    /// GPU time per frame along the flight (wall time without timestamps); `None` without a
    /// flight, or in a run stopped before this setting's flight was timed.
    pub flight: Option<FlightTiming>,
    /// On the Pareto front of the flight's p99 against pixel FLIP against the truth.
    pub pareto_flight: bool,
}

/// A setting's time per frame along the flight, over every round's frames, milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FlightTiming {
    /// Median.
    pub median_ms: f64,
    /// 99th percentile: the frames where the setting costs most.
    pub p99_ms: f64,
    /// Largest.
    pub max_ms: f64,
    /// Frames measured.
    pub frames: usize,
}

impl FlightTiming {
    /// The timing of `samples`, milliseconds (all zero when there are none).
    pub fn of(samples: &[f64]) -> Self {
        let s = Summary::of(samples);
        Self {
            median_ms: s.median,
            p99_ms: s.p99,
            max_ms: s.max,
            frames: samples.len(),
        }
    }
}

/// One frame of the dolly.
#[derive(Clone, Debug, Serialize)]
pub struct DollyFrame {
    /// Frame.
    pub frame: u32,
    /// Error of the LOD frame against the truth, by both measures.
    pub vs_truth: Measures,
    /// Pixel FLIP of the LOD frame against the no-LOD frame (the old figure).
    pub flip_vs_no_lod: f64,
    /// FLIP change from the previous LOD frame.
    pub change_lod: f64,
    /// FLIP change from the previous no-LOD frame.
    pub change_no_lod: f64,
    /// How much the pixel FLIP against the truth moved since the previous frame: a pop shows
    /// as a jump.
    pub jump: f64,
    /// Grass tiles that changed ring this frame.
    pub ring_switches: u32,
    /// Trees in view in this frame and the last whose levels of detail changed (the set of
    /// levels a tree is drawn at: one, or two inside a cross-fade band).
    pub tree_switches: u32,
}

/// The levels of detail each tree of `instances` (roots relative to `eye`) is drawn at, a bit
/// per level, by its root's world position to the centimetre.
pub fn tree_levels(
    instances: &[crate::plants::place_cpu::PlantInstance],
    eye: DVec3,
) -> std::collections::HashMap<(i64, i64), u8> {
    let mut out = std::collections::HashMap::new();
    for i in instances {
        let x = ((eye.x + f64::from(i.pos[0])) * 100.0).round() as i64;
        let y = ((eye.y + f64::from(i.pos[1])) * 100.0).round() as i64;
        *out.entry((x, y)).or_insert(0u8) |= 1 << (i.kind >> 8).min(7);
    }
    out
}

/// Trees of `now` also in `before` whose levels changed.
pub fn tree_switches(
    before: &std::collections::HashMap<(i64, i64), u8>,
    now: &std::collections::HashMap<(i64, i64), u8>,
) -> u32 {
    now.iter()
        .filter(|(k, v)| before.get(k).is_some_and(|b| b != *v))
        .count() as u32
}

/// How far the truth draws real blades, in default view distances: the far band's end.
pub const FAR_BAND_FACTOR: f64 = crate::tools::truth::REACH_FACTOR;

/// The far band at one view: the default setting against the truth over the pixels whose
/// surface lies between the view distance and [`FAR_BAND_FACTOR`] times it.
#[derive(Clone, Debug, Serialize)]
pub struct FarBandView {
    /// The view (0-based, of the four along the path).
    pub view: u32,
    /// Pixels in the band.
    pub band_pixels: u64,
    /// Mean pixel FLIP over the band with the far field on (`None` when the band is empty).
    pub flip_far_field: Option<f64>,
    /// The same with the far field switched off.
    pub flip_no_far_field: Option<f64>,
}

/// The far band over the views.
#[derive(Clone, Debug, Serialize)]
pub struct FarBand {
    /// Where the band starts: the default view distance, metres along the view ray.
    pub near_m: f64,
    /// Where it ends: [`FAR_BAND_FACTOR`] times that, the truth's view distance.
    pub far_m: f64,
    /// Pixels in the band, all views together.
    pub band_pixels: u64,
    /// Mean pixel FLIP against the truth over the band's pixels of all views, far field on
    /// (`None` if none).
    pub flip_far_field: Option<f64>,
    /// The same, far field off.
    pub flip_no_far_field: Option<f64>,
    /// Each view.
    pub views: Vec<FarBandView>,
}

/// Everything `bench_lod.json` holds.
#[derive(Clone, Debug, Serialize)]
pub struct BenchLodReport {
    /// The adapter.
    pub adapter: AdapterReport,
    /// Image size.
    pub size: (u32, u32),
    /// The camera path the dolly leaves from and the four views lie along.
    pub path: String,
    /// Sub-samples a pixel side of the truth.
    pub truth_k: u32,
    /// Sub-samples a pixel side of the settings' measured images (1: the frame as it is).
    pub supersample: u32,
    /// The dolly.
    pub dolly: Vec<DollyFrame>,
    /// Largest jump of the LOD run's pixel FLIP against the truth on a frame where grass tiles
    /// switched ring: the popping, as a number (`None` without such frames: a dolly that
    /// crossed no ring).
    pub worst_pop: Option<f64>,
    /// The same on frames where trees switched level and no grass tile ring (`None` without
    /// such frames: a world without trees).
    pub worst_tree_pop: Option<f64>,
    /// The same on frames without switches of either (the noise floor of the measure; `None`
    /// when every frame had one).
    pub worst_change_without_switch: Option<f64>,
    /// The settings (of a run stopped early, those whose images were captured, with the rounds
    /// timed so far: none where `frame.frames` is 0).
    pub settings: Vec<SettingResult>,
    /// Whether the default setting is on the Pareto front of pixel FLIP against the truth
    /// (`None` in a run stopped before it was timed).
    pub default_on_front: Option<bool>,
    /// Whether it is on the front of the coarse FLIP (`None` as above).
    pub default_on_coarse_front: Option<bool>,
    /// The settings on the front of pixel FLIP against the truth, fastest first.
    pub front: Vec<String>,
    /// The settings on the front of the coarse FLIP against the truth, fastest first.
    pub coarse_front: Vec<String>,
    /// The camera path of the flight (`None`: no flight).
    pub flight_path: Option<String>,
    /// Frames of each flight (`None`: no flight).
    pub flight_frames: Option<u32>,
    /// The settings on the front of the flight's p99 time against pixel FLIP, fastest first
    /// (empty without a flight).
    pub flight_front: Vec<String>,
    /// Whether the default setting is on that front (`None` without a flight, or in a run
    /// stopped before the default's flight was timed).
    pub default_on_flight_front: Option<bool>,
    /// The frame counts of the timings.
    pub counts: FrameCounts,
    /// The far field against the truth's real blades out to [`FAR_BAND_FACTOR`] times the view
    /// distance (no views in a run stopped before the default setting's images).
    pub far_band: FarBand,
    /// Whether the run was stopped before its end (Ctrl-C; [`BenchLodOptions::stop`]): the
    /// report holds what was measured until then.
    pub interrupted: bool,
}

/// The files [`run_bench_lod`] writes into its output folder.
const FILES: [&str; 9] = [
    "bench_lod.json",
    "dolly.csv",
    "dolly.png",
    "lod_settings.csv",
    "lod_settings.png",
    "lod_settings_coarse.png",
    "lod_coverage.png",
    "far_band.csv",
    "lod_settings_flight.png",
];

/// Runs the benchmark and writes `bench_lod.json`, `dolly.csv`, `dolly.png`, `lod_settings.csv`,
/// `lod_settings.png`, `lod_settings_coarse.png`, `lod_coverage.png`, `far_band.csv` and, with a
/// flight, `lod_settings_flight.png` into `opts.out`. Stopped early ([`BenchLodOptions::stop`]),
/// it writes them with what was measured so far, the report marked interrupted; stopped before
/// the dolly's first frame, it writes nothing.
pub fn run_bench_lod(
    opts: &BenchLodOptions,
    progress: &mut dyn FnMut(&str, u64, u64),
) -> Result<BenchLodReport> {
    opts.validate()?;
    let world = World::open(&opts.world)?;
    let path = match &opts.path {
        Some(n) => crate::tools::camera_path(&world, &opts.world, Some(n)).context("--path")?,
        None => match world
            .manifest
            .path("meadow")
            .or(world.manifest.paths.first())
        {
            Some(p) => p.clone(),
            None => bail!("world {} has no camera paths", opts.world.display()),
        },
    };
    let flight = flight_path(&world, &opts.world, &opts.flight, &path)?;
    let out_dir = OutDir::create_for(&opts.out, "bench lod", &Outputs::named(&FILES))?;
    let ctx = GpuContext::new()?;
    let stop = Stop::new(opts.stop.clone());
    let bench = Bench {
        ctx: &ctx,
        world: &world,
        size: opts.size,
        stop: &stop,
    };
    let settings = chosen_settings(lod_settings(&world), &opts.settings)?;
    let no_lod = settings
        .iter()
        .find(|s| s.name == "no LOD")
        .expect("the no-LOD setting")
        .clone();
    let no_lod_index = settings
        .iter()
        .position(|s| s.name == no_lod.name)
        .expect("the no-LOD setting");
    // The four views along the path, and the far band between the default view distance and
    // the truth's reach.
    let views: Vec<Camera> = [0.1, 0.35, 0.6, 0.85]
        .iter()
        .map(|u| sample_path(&path, path.time_at(*u)))
        .collect();
    let tile_m = world
        .manifest
        .pyramid
        .tile_size_m(RingSettings::for_pyramid(&world.manifest.pyramid).level);
    let near_m = settings[0].view_distance_tiles * tile_m;
    let far_m = opts.truth_reach.min(FAR_BAND_FACTOR) * near_m;
    let counts = FrameCounts::for_adapter(&ctx.info).with(
        opts.warmup_frames,
        opts.timed_frames,
        opts.rounds,
    );
    let n_views = views.len();
    let total = settings.len() as u64;
    let steps = u64::from(counts.rounds) * total;

    // What the stages measure; a run stopped early (Ctrl-C) reports what they hold by then.
    let mut dolly = Vec::new();
    let (mut truths, mut masks, mut no_far_field) = (Vec::new(), Vec::new(), Vec::new());
    // Per setting whose images were all captured, in the settings' order: its scene (kept for
    // the timings), its images and their figures.
    let mut scenes = Vec::new();
    let mut images = Vec::new();
    let mut partial = Vec::new();
    // The far band and the settings' FLIP against no LOD, once every setting's images are in
    // (the images are then let go before the timings).
    let mut references: Option<(FarBand, Vec<Option<f64>>)> = None;
    let mut gpu_samples = vec![vec![Vec::new(); n_views]; settings.len()];
    let mut wall_samples = vec![vec![Vec::new(); n_views]; settings.len()];
    let mut flight_samples = vec![Vec::new(); settings.len()];
    let interrupted = caught((|| -> Result<()> {
        // Every frame of the benchmark is drawn at time 0 (`Scene::render` keeps the last
        // frame's time), the camera leaving the trail: so is the truth.
        let mut truth = bench.truth(
            &RendererConfig::for_world(&world),
            opts.truth_k,
            opts.truth_reach,
        )?;

        // (a) The dolly: forward along the path's direction, from where the path starts.
        let start = sample_path(&path, path.start_s());
        let ring_m = settings[0].high_radius_tiles * tile_m;
        // Far enough that tiles ahead cross the high/low boundary during the dolly.
        let step = 1.5 * ring_m / f64::from(opts.dolly_frames);
        let mut lod_scene = bench.scene(settings[0].config(&world))?;
        let mut full_scene = bench.scene(no_lod.config(&world))?;
        let mut prev: Option<(image::RgbaImage, image::RgbaImage)> = None;
        let mut prev_rings: Option<Vec<(crate::world::TileId, crate::lod::Ring)>> = None;
        let mut prev_trees: Option<std::collections::HashMap<(i64, i64), u8>> = None;
        for f in 0..opts.dolly_frames {
            stop.check()?;
            let fwd = start.forward();
            let horizontal = DVec3::new(fwd.x, fwd.y, 0.0).normalize_or_zero();
            let mut cam = start;
            cam.position += horizontal * step * f64::from(f);
            let (a, _) = bench.frame(&mut lod_scene, &cam)?;
            let rings = lod_scene.grass_rings();
            let trees = tree_levels(&lod_scene.renderer().read_tree_instances(), cam.position);
            let (b, _) = bench.frame(&mut full_scene, &cam)?;
            let t = truth.render(&ctx, &cam, 0.0, Some(cam.position.truncate()))?;
            let switches = match &prev_rings {
                Some(p) => rings
                    .iter()
                    .filter(|r| p.iter().any(|q| q.0 == r.0 && q.1 != r.1))
                    .count() as u32,
                None => 0,
            };
            let (change_lod, change_no_lod) = match &prev {
                Some((pa, pb)) => (flip(pa, &a)?, flip(pb, &b)?),
                None => (0.0, 0.0),
            };
            let vs_truth = Measures::of(&t, &a)?;
            let jump = dolly.last().map_or(0.0, |d: &DollyFrame| {
                (vs_truth.flip - d.vs_truth.flip).abs()
            });
            dolly.push(DollyFrame {
                frame: f,
                vs_truth,
                flip_vs_no_lod: flip(&b, &a)?,
                change_lod,
                change_no_lod,
                jump,
                ring_switches: switches,
                tree_switches: prev_trees.as_ref().map_or(0, |p| tree_switches(p, &trees)),
            });
            prev = Some((a, b));
            prev_rings = Some(rings);
            prev_trees = Some(trees);
            progress("dolly", u64::from(f) + 1, u64::from(opts.dolly_frames));
        }
        drop((lod_scene, full_scene));

        // (b) and (c): the truth at the four views, with the far band's masks from its depth,
        // and the default without the far field.
        let (w, h) = opts.size;
        for (i, v) in views.iter().enumerate() {
            stop.check()?;
            truths.push(truth.render(&ctx, v, 0.0, Some(v.position.truncate()))?);
            let depth = truth.read_depth(&ctx)?;
            let inv = v.view_proj_relative(w as f32 / h as f32).inverse();
            let distances = ray_distances(&depth, w, h, inv);
            masks.push(band_mask(&distances, near_m as f32, far_m as f32));
            progress("truth", i as u64 + 1, views.len() as u64);
        }
        drop(truth);
        let mut config = settings[0].config(&world);
        config.features = config.features.without(crate::features::Feature::FarField);
        // With the truth's blades out to the view distance only (`--truth-reach 1`) the band is
        // empty, and the default without the far field is not drawn.
        if far_m > near_m {
            if opts.supersample > 1 {
                let mut ss = bench.supersampled(config, opts.supersample)?;
                for v in &views {
                    stop.check()?;
                    no_far_field.push(ss.render(&ctx, v, 0.0, Some(v.position.truncate()))?);
                }
            } else {
                let mut scene = Scene::new(&ctx, world.clone(), w, h, config)?;
                for v in &views {
                    stop.check()?;
                    no_far_field.push(bench.frame(&mut scene, v)?.0);
                }
            }
        }
        progress("far band", 1, 1);
        // Images first, every setting's scene kept for the timings.
        for (k, s) in settings.iter().enumerate() {
            let mut scene = bench.scene(s.config(&world))?;
            let (mut measures, mut blades, mut coverage) = (Vec::new(), Vec::new(), Vec::new());
            let mut own = Vec::new();
            let mut frame_flips = Vec::new();
            // With --supersample, the images measured are the setting's frames supersampled;
            // the blades drawn and the coverage stay the frame's own.
            let mut ss = if opts.supersample > 1 {
                Some(bench.supersampled(s.config(&world), opts.supersample)?)
            } else {
                None
            };
            for (v, t) in views.iter().zip(&truths) {
                stop.check()?;
                let (mut img, stats, c) = bench.frame_with_coverage(&mut scene, v)?;
                let frame = Measures::of(t, &img)?;
                frame_flips.push(frame.flip);
                measures.push(match &mut ss {
                    Some(ss) => {
                        img = ss.render(&ctx, v, 0.0, Some(v.position.truncate()))?;
                        Measures::of(t, &img)?
                    }
                    None => frame,
                });
                blades.push(f64::from(stats.grass.drawn[0] + stats.grass.drawn[1]));
                coverage.push(c);
                own.push(img);
            }
            scenes.push(scene);
            images.push(own);
            partial.push((measures, blades, coverage, frame_flips));
            progress("images", k as u64 + 1, total);
        }
        references = Some(reference_figures(
            (near_m, far_m),
            (&truths, &masks),
            &images,
            &no_far_field,
            no_lod_index,
        )?);
        (truths, masks, images, no_far_field) = Default::default();

        // Then the timings, in interleaved rounds.
        if let Some(scene) = scenes.first_mut() {
            ramp_up(
                &ctx,
                scene,
                &views[0],
                0.0,
                Some(views[0].position.truncate()),
            )?;
        }
        for round in 0..counts.rounds {
            for (k, scene) in scenes.iter_mut().enumerate() {
                // A setting's views are timed together: a round stopped part-way leaves the
                // settings it reached with one round more than the others.
                stop.check()?;
                for (vi, v) in views.iter().enumerate() {
                    let walker = Some(v.position.truncate());
                    for (stats, wall) in
                        run_frames(&ctx, scene, v, 0.0, walker, counts.warmup, counts.timed)?
                    {
                        gpu_samples[k][vi].push(frame_ms(&stats, wall, true));
                        wall_samples[k][vi].push(wall);
                    }
                }
                progress("timing", u64::from(round) * total + k as u64 + 1, steps);
            }
        }
        if let Some(fp) = &flight {
            let shots = flight_shots(fp, opts.flight_frames);
            // One untimed flight each, every frame's tiles waited for: the timed ones find the
            // path streamed in (as far as the tile cache holds it).
            for (k, scene) in scenes.iter_mut().enumerate() {
                for (camera, _, _) in &shots {
                    stop.warm_up(scene, camera, FLIGHT_TILE_WAIT)?;
                }
                run_flight(&ctx, scene, &shots)?;
                progress("flight", k as u64 + 1, total + steps);
            }
            for round in 0..counts.rounds {
                for (k, scene) in scenes.iter_mut().enumerate() {
                    stop.check()?;
                    for (stats, wall) in run_flight(&ctx, scene, &shots)? {
                        flight_samples[k].push(frame_ms(&stats, wall, ctx.timestamps));
                    }
                    progress(
                        "flight",
                        total + u64::from(round) * total + k as u64 + 1,
                        total + steps,
                    );
                }
            }
        }
        Ok(())
    })())?;
    drop(scenes);
    let worst_pop = dolly
        .iter()
        .skip(1)
        .filter(|d| d.ring_switches > 0)
        .map(|d| d.jump)
        .reduce(f64::max);
    let worst_tree_pop = dolly
        .iter()
        .skip(1)
        .filter(|d| d.tree_switches > 0 && d.ring_switches == 0)
        .map(|d| d.jump)
        .reduce(f64::max);
    let worst_change_without_switch = dolly
        .iter()
        .skip(1)
        .filter(|d| d.ring_switches == 0 && d.tree_switches == 0)
        .map(|d| d.jump)
        .reduce(f64::max);
    // Stopped before every setting's images were in: the far band and the FLIP against no LOD
    // of what was captured.
    let (far_band, vs_no_lod) = match references {
        Some(r) => r,
        None => reference_figures(
            (near_m, far_m),
            (&truths, &masks),
            &images,
            &no_far_field,
            no_lod_index,
        )?,
    };
    drop((truths, masks, images, no_far_field));
    let mut results = Vec::new();
    for (k, s) in settings.iter().enumerate().take(partial.len()) {
        let (measures, blades, coverage, frame_flips) = &partial[k];
        let timing = |samples: &[Vec<f64>]| {
            Timing::over_views(&samples.iter().map(|v| Timing::of(v)).collect::<Vec<_>>())
        };
        let frame = timing(&wall_samples[k]);
        results.push(SettingResult {
            setting: s.clone(),
            gpu: if ctx.timestamps {
                timing(&gpu_samples[k])
            } else {
                Timing::default()
            },
            frame,
            vs_truth: Measures::mean(measures),
            flip_frame_vs_truth: frame_flips.iter().sum::<f64>() / frame_flips.len().max(1) as f64,
            flip_vs_no_lod: vs_no_lod[k],
            blades_drawn: Summary::of(blades).median,
            coverage: coverage.iter().sum::<f64>() / coverage.len() as f64,
            pareto: false,
            pareto_coarse: false,
            // A run stopped before this setting's flight was timed has none.
            flight: (flight.is_some() && !flight_samples[k].is_empty())
                .then(|| FlightTiming::of(&flight_samples[k])),
            pareto_flight: false,
        });
    }
    // Time is GPU time when the adapter has timestamps, else wall time.
    let time = |r: &SettingResult| {
        if ctx.timestamps {
            r.gpu.median_ms
        } else {
            r.frame.median_ms
        }
    };
    // The fronts are over the settings timed (all of them, unless the run was stopped early).
    let front_of = |time: &dyn Fn(&SettingResult) -> Option<f64>,
                    error: &dyn Fn(&SettingResult) -> f64| {
        let timed: Vec<usize> = (0..results.len())
            .filter(|&i| time(&results[i]).is_some())
            .collect();
        let xy: Vec<(f64, f64)> = timed
            .iter()
            .map(|&i| (time(&results[i]).unwrap_or(0.0), error(&results[i])))
            .collect();
        let mut front = pareto_front(&xy);
        front.sort_by(|&a, &b| xy[a].0.total_cmp(&xy[b].0));
        front.into_iter().map(|i| timed[i]).collect::<Vec<usize>>()
    };
    let views_time = |r: &SettingResult| r.frame.measured().then(|| time(r));
    let front = front_of(&views_time, &|r| r.vs_truth.flip);
    let coarse_front = front_of(&views_time, &|r| r.vs_truth.coarse);
    let flight_front = if flight.is_some() {
        front_of(&|r| r.flight.map(|f| f.p99_ms), &|r| r.vs_truth.flip)
    } else {
        Vec::new()
    };
    for &i in &front {
        results[i].pareto = true;
    }
    for &i in &coarse_front {
        results[i].pareto_coarse = true;
    }
    for &i in &flight_front {
        results[i].pareto_flight = true;
    }
    let names = |front: &[usize]| -> Vec<String> {
        front
            .iter()
            .map(|&i| results[i].setting.name.clone())
            .collect()
    };
    let (front, coarse_front, flight_front) =
        (names(&front), names(&coarse_front), names(&flight_front));
    let default = results.first();
    let timed_default = default.filter(|r| r.frame.measured());
    let report = BenchLodReport {
        adapter: AdapterReport::of(&ctx),
        size: opts.size,
        path: path.name.clone(),
        truth_k: opts.truth_k,
        supersample: opts.supersample,
        worst_pop,
        worst_tree_pop,
        worst_change_without_switch,
        default_on_front: timed_default.map(|r| r.pareto),
        default_on_coarse_front: timed_default.map(|r| r.pareto_coarse),
        front,
        coarse_front,
        flight_path: flight.as_ref().map(|p| p.name.clone()),
        flight_frames: flight.as_ref().map(|_| opts.flight_frames),
        default_on_flight_front: default
            .filter(|r| r.flight.is_some())
            .map(|r| r.pareto_flight),
        flight_front,
        counts,
        interrupted,
        dolly,
        settings: results,
        far_band,
    };
    if report.dolly.is_empty() {
        // Stopped before the dolly's first frame: nothing measured, nothing written (an
        // earlier run's files stay as they were).
        return Ok(report);
    }
    write_outputs(opts, &report, ctx.timestamps)?;
    write_far_band(opts, &report.far_band)?;
    write_json(&opts.out.join("bench_lod.json"), &report)?;
    out_dir.keep();
    Ok(report)
}

/// The far band's figures and each captured setting's mean pixel FLIP against the no-LOD
/// setting over the views (`None` where the no-LOD setting's images were not captured, in a
/// run stopped early); the band is empty unless the truths and the default's images are all in.
fn reference_figures(
    (near_m, far_m): (f64, f64),
    (truths, masks): (&[image::RgbaImage], &[Vec<bool>]),
    images: &[Vec<image::RgbaImage>],
    no_far_field: &[image::RgbaImage],
    no_lod_index: usize,
) -> Result<(FarBand, Vec<Option<f64>>)> {
    let band = match images.first() {
        Some(default) => far_band((near_m, far_m), truths, masks, default, no_far_field)?,
        None => far_band((near_m, far_m), &[], &[], &[], &[])?,
    };
    let mut vs_no_lod = Vec::new();
    for own in images {
        vs_no_lod.push(match images.get(no_lod_index) {
            Some(reference) => {
                let mut flips = Vec::new();
                for (r, a) in reference.iter().zip(own) {
                    flips.push(flip(r, a)?);
                }
                Some(flips.iter().sum::<f64>() / flips.len().max(1) as f64)
            }
            None => None,
        });
    }
    Ok((band, vs_no_lod))
}

/// The longest bench lod waits for a flight frame's tiles in its untimed flight.
const FLIGHT_TILE_WAIT: std::time::Duration = std::time::Duration::from_secs(30);

/// The flight's path: `asked` by name (`Some("")`: none), else "tour" where the world has it,
/// else the views' own path.
fn flight_path(
    world: &World,
    location: &std::path::Path,
    asked: &Option<String>,
    views: &crate::world::CameraPath,
) -> Result<Option<crate::world::CameraPath>> {
    match asked.as_deref() {
        Some("") => Ok(None),
        Some(name) => Ok(Some(
            crate::tools::camera_path(world, location, Some(name)).context("--flight")?,
        )),
        None => Ok(Some(world.manifest.path("tour").unwrap_or(views).clone())),
    }
}

/// The flight's frames: `frames` cameras evenly spaced along the whole of `path`, each drawn at
/// time 0 (as every frame of the benchmark) with the trail at the camera.
pub fn flight_shots(
    path: &crate::world::CameraPath,
    frames: u32,
) -> Vec<(Camera, f64, Option<glam::DVec2>)> {
    let last = f64::from(frames.max(2) - 1);
    (0..frames)
        .map(|i| {
            let camera = sample_path(path, path.time_at(f64::from(i) / last));
            (camera, 0.0, Some(camera.position.truncate()))
        })
        .collect()
}

/// The far band's figures from the truth's images and band masks, and the default setting's
/// images with the far field on and off (all in the order of the views).
fn far_band(
    (near_m, far_m): (f64, f64),
    truths: &[image::RgbaImage],
    masks: &[Vec<bool>],
    with: &[image::RgbaImage],
    without: &[image::RgbaImage],
) -> Result<FarBand> {
    let mut views = Vec::new();
    let (mut sum_with, mut sum_without, mut pixels) = (0.0, 0.0, 0u64);
    for (i, (t, mask)) in truths.iter().zip(masks).enumerate() {
        let band_pixels = mask.iter().filter(|&&m| m).count() as u64;
        let (with, without) = match without.get(i) {
            Some(without) if band_pixels > 0 => {
                let r = rgb(t);
                (
                    masked_mean(&flip_error_map(&r, &rgb(&with[i]))?, mask),
                    masked_mean(&flip_error_map(&r, &rgb(without))?, mask),
                )
            }
            _ => (None, None),
        };
        if let (Some(a), Some(b)) = (with, without) {
            sum_with += a * band_pixels as f64;
            sum_without += b * band_pixels as f64;
            pixels += band_pixels;
        }
        views.push(FarBandView {
            view: i as u32,
            band_pixels,
            flip_far_field: with,
            flip_no_far_field: without,
        });
    }
    let mean = |sum: f64| (pixels > 0).then(|| sum / pixels as f64);
    Ok(FarBand {
        near_m,
        far_m,
        band_pixels: pixels,
        flip_far_field: mean(sum_with),
        flip_no_far_field: mean(sum_without),
        views,
    })
}

/// Writes `far_band.csv`: one row a view, empty FLIP cells where the band is empty.
fn write_far_band(opts: &BenchLodOptions, band: &FarBand) -> Result<()> {
    let cell = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.6}"));
    let mut csv = String::from("view,band_pixels,flip_far_field,flip_no_far_field\n");
    for v in &band.views {
        csv.push_str(&format!(
            "{},{},{},{}\n",
            v.view,
            v.band_pixels,
            cell(v.flip_far_field),
            cell(v.flip_no_far_field)
        ));
    }
    write_text(&opts.out.join("far_band.csv"), &csv)?;
    Ok(())
}

/// Writes the dolly's and the settings' tables and charts; the figures a run stopped early did
/// not time are empty cells, and its settings without them are left off the charts of time.
fn write_outputs(opts: &BenchLodOptions, report: &BenchLodReport, gpu: bool) -> Result<()> {
    use std::fmt::Write as _;
    let (dolly, results) = (&report.dolly, &report.settings);
    let title = |t: &str| chart_title(t, report.interrupted);
    let mut csv = String::from(
        "frame,flip_vs_truth,coarse_flip_vs_truth,jump,flip_vs_no_lod,change_lod,change_no_lod,\
         ring_switches,tree_switches\n",
    );
    for d in dolly {
        let _ = writeln!(
            csv,
            "{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{},{}",
            d.frame,
            d.vs_truth.flip,
            d.vs_truth.coarse,
            d.jump,
            d.flip_vs_no_lod,
            d.change_lod,
            d.change_no_lod,
            d.ring_switches,
            d.tree_switches
        );
    }
    write_text(&opts.out.join("dolly.csv"), &csv)?;
    let line =
        |f: &dyn Fn(&DollyFrame) -> f64| dolly.iter().map(|d| (f64::from(d.frame), f(d))).collect();
    LineChart {
        title: title("LOD dolly across the ring boundary"),
        x_label: "frame".into(),
        y_label: "FLIP".into(),
        log_x: false,
        log_y: false,
        series: vec![
            Series {
                name: "LOD vs the truth (pixel FLIP)".into(),
                points: line(&|d| d.vs_truth.flip),
            },
            Series {
                name: "LOD vs the truth (coarse FLIP)".into(),
                points: line(&|d| d.vs_truth.coarse),
            },
            Series {
                name: "jump of the pixel FLIP".into(),
                points: line(&|d| d.jump),
            },
            Series {
                name: "LOD vs no LOD".into(),
                points: line(&|d| d.flip_vs_no_lod),
            },
            Series {
                name: "ring switches / 1000".into(),
                points: line(&|d| f64::from(d.ring_switches) / 1000.0),
            },
        ],
    }
    .write_png(&opts.out.join("dolly.png"), 900, 600)?;

    let mut csv = String::from(
        "setting,high_radius_tiles,view_distance_tiles,spacing_m,segments_near,segments_high,\
         segments_low,near_m,infill_half_m,infill_quarter_m,width_scale,lod_widen,elevation_fade,plant_lod_near_m,\
         plant_lod_far_m,plant_card_reach,plant_thin_m,tree_lod_near_m,tree_lod_far_m,tree_thin_m,gpu_ms,gpu_q1_ms,\
         gpu_q3_ms,gpu_spread,frame_ms,frame_spread,noisy,frames,flip_vs_truth,\
         coarse_flip_vs_truth,flip_frame_vs_truth,flip_vs_no_lod,blades_drawn,coverage,pareto,pareto_coarse,\
         flight_median_ms,flight_p99_ms,flight_max_ms,flight_frames,pareto_flight\n",
    );
    for r in results {
        let s = &r.setting;
        // Every figure of the views' timings is the frames' (and, with timestamps, the GPU's).
        let t = &r.frame;
        let flight = |f: fn(&FlightTiming) -> String| r.flight.as_ref().map_or(String::new(), f);
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.5},{:.5},{:.5},{},{:.0},{:.4},{},{},{},{},{},{},{}",
            s.name,
            s.high_radius_tiles,
            s.view_distance_tiles,
            s.spacing_m,
            s.segments[0],
            s.segments[1],
            s.segments[2],
            s.near_m,
            s.infill_m[0],
            s.infill_m[1],
            s.width_scale,
            s.lod_widen,
            s.elevation_fade,
            s.plant_lod_m[0],
            s.plant_lod_m[1],
            s.plant_card_reach,
            s.plant_thin_m,
            s.tree_lod_m.map_or(String::new(), |m| m[0].to_string()),
            s.tree_lod_m.map_or(String::new(), |m| m[1].to_string()),
            s.tree_thin_m.map_or(String::new(), |m| m.to_string()),
            t.cell(r.gpu.median_ms, 4),
            t.cell(r.gpu.q1_ms, 4),
            t.cell(r.gpu.q3_ms, 4),
            t.cell(r.gpu.spread, 4),
            t.cell(r.frame.median_ms, 3),
            t.cell(r.frame.spread, 4),
            if !t.measured() {
                String::new()
            } else if gpu {
                r.gpu.noisy.to_string()
            } else {
                r.frame.noisy.to_string()
            },
            r.frame.frames,
            r.vs_truth.flip,
            r.vs_truth.coarse,
            r.flip_frame_vs_truth,
            r.flip_vs_no_lod
                .map_or(String::new(), |f| format!("{f:.5}")),
            r.blades_drawn,
            r.coverage,
            r.pareto,
            r.pareto_coarse,
            flight(|f| format!("{:.4}", f.median_ms)),
            flight(|f| format!("{:.4}", f.p99_ms)),
            flight(|f| format!("{:.4}", f.max_ms)),
            flight(|f| f.frames.to_string()),
            r.pareto_flight
        );
    }
    write_text(&opts.out.join("lod_settings.csv"), &csv)?;
    let x_label = if gpu {
        "GPU time per frame (ms)"
    } else {
        "frame time (ms)"
    };
    let time = |r: &SettingResult| {
        if gpu {
            r.gpu.median_ms
        } else {
            r.frame.median_ms
        }
    };
    let chart = |heading: &str, y_label: &str, y: &dyn Fn(&SettingResult) -> f64| Chart {
        title: title(heading),
        x_label: x_label.into(),
        y_label: y_label.into(),
        log_x: true,
        log_y: false,
        points: results
            .iter()
            .filter(|r| r.frame.measured())
            .map(|r| ChartPoint {
                label: if (gpu && r.gpu.noisy) || (!gpu && r.frame.noisy) {
                    format!("{} (noisy)", r.setting.name)
                } else {
                    r.setting.name.clone()
                },
                x: time(r),
                y: y(r),
                chosen: r.setting.name == "default",
            })
            .collect(),
    };
    let k = opts.truth_k;
    chart(
        "Grass LOD settings: speed against accuracy (pixel FLIP)",
        &format!("pixel FLIP against the {k}x{k} truth"),
        &|r| r.vs_truth.flip,
    )
    .write_png(&opts.out.join("lod_settings.png"), 900, 600)?;
    chart(
        "Grass LOD settings: speed against accuracy (coarse FLIP, 8x8 blocks)",
        &format!("coarse FLIP against the {k}x{k} truth"),
        &|r| r.vs_truth.coarse,
    )
    .write_png(&opts.out.join("lod_settings_coarse.png"), 900, 600)?;
    // Coverage against cost: the ground a view of the near meadow leaves bare, so that lower
    // is better on both axes, as on the charts above.
    chart(
        "Grass LOD settings: ground left bare against speed",
        "1 - grass coverage within 30 m",
        &|r| 1.0 - r.coverage,
    )
    .write_png(&opts.out.join("lod_coverage.png"), 900, 600)?;
    // The flight's worst frames against the error: the cost a setting has where the four
    // views do not look.
    if report.flight_path.is_some() {
        let mut c = chart(
            "Grass LOD settings along the flight: 99th percentile frame against accuracy",
            &format!("pixel FLIP against the {k}x{k} truth"),
            &|r| r.vs_truth.flip,
        );
        c.x_label = format!(
            "{} time of the flight's 99th percentile frame (ms)",
            if gpu { "GPU" } else { "wall" }
        );
        c.points = results
            .iter()
            .filter_map(|r| {
                Some(ChartPoint {
                    label: r.setting.name.clone(),
                    x: r.flight?.p99_ms,
                    y: r.vs_truth.flip,
                    chosen: r.setting.name == "default",
                })
            })
            .collect();
        c.write_png(&opts.out.join("lod_settings_flight.png"), 900, 600)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {

    #[test]
    fn a_tree_switches_when_its_levels_change_and_not_when_it_comes_into_view() {
        use crate::plants::place_cpu::PlantInstance;
        let tree = |x: f32, level: u32| PlantInstance {
            pos: [x, 5.0, 0.0],
            yaw: 0.0,
            scale: 10.0,
            kind: level << 8,
            hash: 0,
            fade: 1.0,
        };
        let eye = DVec3::new(1000.0, 2000.0, 50.0);
        let a = tree_levels(&[tree(10.0, 0), tree(20.0, 1), tree(30.0, 1)], eye);
        // The camera moved 1 m east: the same trees, relative positions 1 m less; the first
        // now in a band (both levels), the third gone, a fourth come into view.
        let eye2 = eye + DVec3::X;
        let b = tree_levels(
            &[tree(9.0, 0), tree(9.0, 1), tree(19.0, 1), tree(39.0, 2)],
            eye2,
        );
        assert_eq!(a.len(), 3);
        assert_eq!(b[&(101_000, 200_500)], 0b11);
        assert_eq!(tree_switches(&a, &b), 1);
        assert_eq!(tree_switches(&a, &a), 0);
    }

    use super::*;

    #[test]
    fn chosen_settings_keep_the_references_and_refuse_unknown_names() {
        let s = |n: &str| LodSetting::new(n, 1.0, 2.0, 0.1, [5, 3, 2]);
        let all = vec![
            s("default"),
            s("spacing x0.8"),
            s("width x1.5"),
            s("no LOD"),
        ];
        let names = |v: &[&str]| v.iter().map(|n| n.to_string()).collect::<Vec<_>>();
        let picked = chosen_settings(all.clone(), &names(&["width x1.5"])).unwrap();
        let picked: Vec<&str> = picked.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(picked, ["default", "width x1.5", "no LOD"]);
        assert_eq!(chosen_settings(all.clone(), &[]).unwrap().len(), 4);
        let e = chosen_settings(all.clone(), &names(&["width x9"]))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("\"width x9\"") && e.contains("spacing x0.8"),
            "{e}"
        );
        // Named: in the order named, each once, and nothing else.
        let named = named_settings(&all, &names(&["no LOD", "spacing x0.8", "no LOD"])).unwrap();
        let named: Vec<&str> = named.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(named, ["no LOD", "spacing x0.8"]);
        assert!(named_settings(&all, &[]).unwrap().is_empty());
        assert!(named_settings(&all, &names(&["spacing x0.8", "nothing"])).is_err());
    }

    #[test]
    fn no_setting_is_the_defaults_twin() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        let world = World::open(&dir).unwrap();
        let all = lod_settings(&world);
        assert_eq!(all[0].name, "default");
        // The default's own segments (9/3/3) are not measured a second time under their name.
        let seg = RendererConfig::for_world(&world).grass.segments;
        let twin = format!("segments {}/{}/{}", seg[0], seg[1], seg[2]);
        assert!(!all.iter().any(|s| s.name == twin), "{twin} measured twice");
        for s in &all[1..] {
            assert!(
                !s.same_as(&all[0]),
                "{} draws what the default draws",
                s.name
            );
        }
        // Any other difference keeps a setting.
        let mut other = all[0].clone();
        other.tree_thin_m = Some(1.0);
        assert!(!other.same_as(&all[0]));
    }

    #[test]
    fn the_flight_is_the_tour_unless_asked_and_an_unknown_path_is_refused_naming_the_paths() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        let mut world = World::open(&dir).unwrap();
        let meadow = world.manifest.path("meadow").unwrap().clone();
        let name = |asked: Option<&str>, w: &World| {
            flight_path(w, &dir, &asked.map(String::from), &meadow)
                .unwrap()
                .map(|p| p.name)
        };
        assert_eq!(name(None, &world).as_deref(), Some("tour"));
        assert_eq!(
            name(Some("wind-tour"), &world).as_deref(),
            Some("wind-tour")
        );
        assert_eq!(name(Some(""), &world), None);
        let err = format!(
            "{:#}",
            flight_path(&world, &dir, &Some("nowhere".into()), &meadow).unwrap_err()
        );
        for says in ["--flight", "\"nowhere\"", "tour", "meadow", "wind-tour"] {
            assert!(err.contains(says), "{err}");
        }
        // A world without a tour flies the views' path.
        world.manifest.paths.retain(|p| p.name != "tour");
        assert_eq!(name(None, &world).as_deref(), Some("meadow"));
        // The shots run evenly over the whole path, its first and last keys included.
        let shots = flight_shots(&meadow, 5);
        assert_eq!(shots.len(), 5);
        let (first, last) = (&meadow.keys[0], &meadow.keys[meadow.keys.len() - 1]);
        let at = |t| crate::camera::sample_path(&meadow, t).position;
        assert_eq!(shots[0].0.position, at(first.t_s));
        assert_eq!(shots[4].0.position, at(last.t_s));
        assert_eq!(shots[2].0.position, at(0.5 * (first.t_s + last.t_s)));
        assert!(shots.iter().all(|s| s.1 == 0.0));
    }

    #[test]
    fn a_world_with_trees_gets_the_trees_lod_settings() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        let mut world = World::open(&dir).unwrap();
        let names =
            |w: &World| -> Vec<String> { lod_settings(w).into_iter().map(|s| s.name).collect() };
        // The default world has trees; without them there are no tree settings.
        assert!(names(&world).iter().any(|n| n == "trees lod x0.5"));
        world.manifest.plant_types.retain(|t| !t.is_tree());
        assert!(!names(&world).iter().any(|n| n.starts_with("trees")));
        let mut oak = world.manifest.plant_types[0].clone();
        oak.size_m = [8.0, 12.0];
        world.manifest.plant_types.push(oak);
        let settings = lod_settings(&world);
        let half = settings
            .iter()
            .find(|s| s.name == "trees lod x0.5")
            .unwrap();
        let default = RendererConfig::for_world(&world)
            .tree_settings(&world)
            .unwrap();
        assert_eq!(half.tree_lod_m, Some(default.lod_m.map(|m| 0.5 * m)));
        let trees = half.config(&world).trees.unwrap();
        assert_eq!(trees.lod_m, default.lod_m.map(|m| 0.5 * m));
        assert_eq!(trees.min_keep, default.min_keep);
        assert_eq!(trees.thin_m, default.thin_m);
        let thin = settings
            .iter()
            .find(|s| s.name == "trees thin x0.5")
            .unwrap()
            .config(&world)
            .trees
            .unwrap();
        assert_eq!(thin.thin_m, 0.5 * default.thin_m);
        assert_eq!(thin.lod_m, default.lod_m);
        assert_eq!(settings.last().unwrap().name, "no LOD");
    }

    /// The plants' cards reach farther with a pool grown for the ring they cover (within what a
    /// pool can bind), and their thinning can move or go; the default keeps the renderer's.
    #[test]
    fn the_plant_card_and_thinning_settings_reach_the_plant_stage() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
        let world = World::open(&dir).unwrap();
        let settings = lod_settings(&world);
        let config = |name: &str| {
            settings
                .iter()
                .find(|s| s.name == name)
                .unwrap_or_else(|| panic!("no setting {name:?}"))
                .config(&world)
                .plants
        };
        let d = RendererConfig::for_world(&world).plants;
        assert_eq!(config("default"), d);
        let far = config("plant cards x4.5");
        assert_eq!(far.card_reach, 4.5 * d.card_reach);
        assert!(far.capacity > 4 * d.capacity, "{} regions", far.capacity);
        let types = crate::plants::PlantLayer::Plants.types(&world.manifest);
        assert!(far.capacity <= crate::plants::renderer::max_capacity(types.len() as u32));
        assert_eq!(far.thin_m, d.thin_m);
        assert_eq!(config("plants thin x2").thin_m, 2.0 * d.thin_m);
        assert_eq!(config("plants thin x2").card_reach, d.card_reach);
        let both = config("plant cards x4.5 thin off");
        assert_eq!(both.thin_m, crate::renderer::MAX_PLANT_LOD_M);
        assert_eq!(both.card_reach, far.card_reach);
        // Not the default's twin: each is measured.
        for name in ["plant cards x2", "plants thin off"] {
            assert!(
                !settings
                    .iter()
                    .find(|s| s.name == name)
                    .unwrap()
                    .same_as(&settings[0])
            );
        }
    }
}
