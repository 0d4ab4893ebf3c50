//! Tile residency and streaming: the tiles a frame wants, uploads of loaded tiles to the atlas,
//! derivations of child tiles, the warm-up that waits for them all, the grass jobs of the
//! tiles that are resident, and the plants' jobs (the grass tiles', then the far ones read from
//! the terrain's tiles).

use std::time::Instant;

use glam::Vec2;

use super::{FrameView, MissingTile, Renderer, RendererError, WarmUp};
use crate::camera::Camera;
use crate::gpu::GpuTimer;
use crate::grass::TileJob;
use crate::lod::{Ring, select_terrain};
use crate::plants::place_cpu::PlantJob;
use crate::stream::{DeriveJob, ResidencyPlan, Want};
use crate::world::TileId;

/// How long a warm-up waits with nothing loading, uploaded or derived before it gives up.
pub const WARM_UP_STALL: std::time::Duration = std::time::Duration::from_secs(5);

/// The tiles a frame wants, before residency.
pub(super) struct Selection {
    pub(super) terrain: Vec<TileId>,
    pub(super) grass: Vec<(TileId, Ring, f64)>,
    pub(super) wants: Vec<Want>,
}

impl Renderer {
    pub(super) fn select(&mut self, view: &FrameView) -> Selection {
        let camera = &view.camera;
        let frustum = view.frustum;
        let pyramid = &self.world.manifest.pyramid;
        let service = &self.service;
        let range = |id: TileId| service.height_range(id);
        let terrain = select_terrain(pyramid, self.lod, camera.position, &frustum, &range);
        let grass = match &mut self.rings {
            Some(r) => r.update(pyramid, camera.position, &range),
            None => Vec::new(),
        };
        // Priority: distance, doubled for what lies behind the camera.
        let forward = camera.forward();
        let priority = |id: TileId| {
            let b = pyramid.bounds(id);
            let (h0, h1) = range(id);
            let c = glam::DVec3::new(b.center().x, b.center().y, 0.5 * f64::from(h0 + h1));
            let to = c - camera.position;
            let d = to.length().max(1e-3);
            (d * (1.5 - 0.5 * forward.dot(to / d))) as f32
        };
        let wants = terrain
            .iter()
            .copied()
            .chain(grass.iter().map(|g| g.0))
            .map(|id| Want {
                id,
                priority: priority(id),
            })
            .collect();
        Selection {
            terrain,
            grass,
            wants,
        }
    }

    /// Brings every tile `camera` wants into the atlas, waiting for loads and for the GPU: for
    /// the first frame of a run or a teleport, never inside a frame loop. Gives up after
    /// `timeout`; returns whether everything became resident. See [`Renderer::warm_up_report`]
    /// for what is missing when not.
    pub fn warm_up(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<bool, RendererError> {
        Ok(self.warm_up_report(camera, timeout)?.missing.is_empty())
    }

    /// Like [`Renderer::warm_up`], and says which tiles are missing and why. Stops early, without
    /// waiting for `timeout`, once every missing tile is kept out by a failed load (its own or
    /// that of the stored ancestor it is derived from), or when nothing has moved for
    /// [`WARM_UP_STALL`].
    pub fn warm_up_report(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
    ) -> Result<WarmUp, RendererError> {
        self.warm_up_until(camera, timeout, &|| false)
    }

    /// Like [`Renderer::warm_up_report`], and also stops, within a few milliseconds, once
    /// `stop` returns true (a user's Ctrl-C while tiles come slowly over a network): the tiles
    /// not yet resident are then missing, for the reason that the warm-up was stopped.
    pub fn warm_up_until(
        &mut self,
        camera: &Camera,
        timeout: std::time::Duration,
        stop: &dyn Fn() -> bool,
    ) -> Result<WarmUp, RendererError> {
        let start = Instant::now();
        camera.check().map_err(RendererError::FrameInput)?;
        self.flush_unrecorded();
        let mut last_change = Instant::now();
        let mut last_resident = u32::MAX;
        let view = FrameView::new(camera, Vec2::ZERO, self.targets.width, self.targets.height);
        loop {
            let sel = self.select(&view);
            let plan = self.service.update(&sel.wants);
            let busy = !plan.uploads.is_empty() || !plan.derives.is_empty();
            let derives = self.upload(plan);
            self.submit_derives(&derives);
            let stats = self.service.stats();
            if stats.resident == stats.desired {
                let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
                return Ok(WarmUp::default());
            }
            if busy || stats.resident != last_resident || stats.stream.in_flight > 0 {
                last_change = Instant::now();
                last_resident = stats.resident;
            }
            let missing: Vec<TileId> = sel
                .wants
                .iter()
                .map(|w| w.id)
                .filter(|&id| !self.service.is_resident(id))
                .collect();
            let all_failed = missing
                .iter()
                .all(|&id| self.service.blocked_by(id).is_some());
            let stalled = last_change.elapsed() > WARM_UP_STALL;
            let stopped = stop();
            if all_failed || stalled || stopped || start.elapsed() > timeout {
                let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
                let slots = self.service.config().atlas_slots;
                let why_else = if stopped {
                    "the warm-up was stopped before it was resident".to_owned()
                } else if stalled && stats.atlas_used >= slots {
                    // Every slot holds a tile the view wants more: the atlas is too small for
                    // this view, not the loading stuck.
                    format!(
                        "the atlas is full (all {slots} slots hold tiles this view wants more; \
                         it holds {} with their ancestors); give it more slots (--atlas-slots)",
                        stats.held
                    )
                } else if stalled {
                    "nothing was loading".to_owned()
                } else {
                    format!("not resident after {:.0} s", timeout.as_secs_f64())
                };
                let missing = missing
                    .into_iter()
                    .map(|tile| {
                        let reason = match self.service.blocked_by(tile) {
                            Some((t, e)) if t == tile => {
                                format!("failed to load: {}", crate::world::printable(e))
                            }
                            Some((t, e)) => format!(
                                "derived from tile L{} {}_{}, which failed to load: {}",
                                t.level,
                                t.x,
                                t.y,
                                crate::world::printable(e)
                            ),
                            None => why_else.clone(),
                        };
                        MissingTile { tile, reason }
                    })
                    .collect();
                return Ok(WarmUp { missing });
            }
            if !busy {
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
        }
    }

    /// Records and submits derivations on their own (a batch a submission: each batch's jobs
    /// are written to the same buffer), without waiting.
    fn submit_derives(&mut self, derives: &[DeriveJob]) {
        let batch = self.derive.batch().max(1) as usize;
        let mut no_timer = GpuTimer::new(&self.device, &self.queue, false, 0);
        for chunk in derives.chunks(batch) {
            let mut e = self.device.create_command_encoder(&Default::default());
            self.derive
                .record(&self.queue, &mut e, &self.atlas, chunk, &mut no_timer);
            self.queue.submit([e.finish()]);
        }
    }

    /// Derivations of a frame that was prepared and never recorded: the tile service counts
    /// those tiles as resident, so they are derived now.
    pub(super) fn flush_unrecorded(&mut self) {
        if let Some(stale) = self.prepared.take() {
            self.submit_derives(&stale.derives);
        }
    }

    /// Uploads the plan's decoded tiles to the atlas; returns the derivations to record.
    /// A tile that does not fit its slot (its size disagrees with the atlas) is logged and left
    /// out, and the others go on: the slot keeps an identity that the hole check does not
    /// accept, so the tile counts as a hole and is drawn from its ancestor.
    pub(super) fn upload(&mut self, plan: ResidencyPlan) -> Vec<DeriveJob> {
        for (slot, tile) in &plan.uploads {
            if self.skip_uploads > 0 {
                // A fault injected by a test: the slot is given to the tile, its data never
                // reaches the GPU.
                self.skip_uploads -= 1;
                self.atlas.claim(*slot, tile.id);
                continue;
            }
            if let Err(e) = self.atlas.upload(&self.queue, *slot, tile) {
                log::warn!("tile {} left out of the atlas: {e}", tile.id);
            }
        }
        plan.derives
    }

    /// For tests of the hole count: the next `n` uploads are planned (their slots given to
    /// their tiles) but never written to the GPU, as a lost upload would be.
    #[doc(hidden)]
    pub fn skip_next_uploads(&mut self, n: u32) {
        self.skip_uploads = n;
    }

    /// The generation jobs of the grass tiles that have their own data resident and are in view.
    pub(super) fn grass_jobs(
        &self,
        view: &FrameView,
        grass: &[(TileId, Ring, f64)],
    ) -> Vec<TileJob> {
        let pyramid = &self.world.manifest.pyramid;
        let (camera, frustum) = (&view.camera, &view.frustum);
        let near_m = self
            .grass
            .as_ref()
            .map_or(0.0, |g| g.renderer.settings().near_m);
        let mut jobs = Vec::new();
        for &(id, ring, _) in grass {
            let Some((src, slot)) = self.service.draw_source(id) else {
                continue;
            };
            if src != id {
                continue; // no grass until the tile's own data is there
            }
            let b = pyramid.bounds(id);
            let (h0, h1) = self.service.height_range(id);
            let tallest = 1.5f64;
            let min = glam::DVec3::new(b.min.x, b.min.y, f64::from(h0)) - camera.position;
            let max = glam::DVec3::new(b.max.x, b.max.y, f64::from(h1) + tallest) - camera.position;
            if !frustum.intersects_box(min.as_vec3(), max.as_vec3()) {
                continue;
            }
            let rel = b.min - camera.position.truncate();
            let job = TileJob {
                origin: [rel.x as f32, rel.y as f32],
                cell: pyramid.cell_size_m(id.level) as f32,
                layer: slot,
                tile_x: id.x,
                tile_y: id.y,
                lod: u32::from(ring == Ring::Low),
                slot: 0,
            };
            jobs.push(job);
            // A high-LOD tile within the near radius: a second job for its blades there.
            let c = camera.position.truncate();
            let nearest = c.clamp(b.min, b.max) - c;
            if ring == Ring::High && nearest.length() < f64::from(near_m) {
                jobs.push(TileJob { lod: 2, ..job });
            }
        }
        jobs
    }
}

impl Renderer {
    /// The plants' jobs of a frame: one per grass tile of `grass_jobs`, then the far jobs: the
    /// grass-level tiles between the start of the grass's hand-over and the end of the cards'
    /// reach that are in view, each read from the terrain tile of `terrain` that holds it (its
    /// own data, or its nearest resident ancestor's), nearest first. Empty without plants.
    pub(super) fn plant_jobs(
        &self,
        view: &FrameView,
        terrain: &[TileId],
        grass_jobs: &[TileJob],
    ) -> Vec<PlantJob> {
        let (Some(plants), Some(rings)) = (
            self.grass.as_ref().and_then(|g| g.plants.as_ref()),
            self.rings.as_ref(),
        ) else {
            return Vec::new();
        };
        let settings = plants.settings();
        let pyramid = &self.world.manifest.pyramid;
        let level = rings.settings.level;
        let size = pyramid.tile_size_m(level);
        let (inner, outer) = (
            f64::from(settings.view_m[0]),
            f64::from(settings.view_m[1] * settings.card_reach.max(1.0)),
        );
        if outer <= inner {
            return crate::plants::PlantRenderer::plant_jobs(grass_jobs, &[]);
        }
        let eye = view.camera.position;
        // The tallest plant, for the boxes' tops.
        let tallest = 1.5f64;
        let mut far: Vec<(f64, PlantJob)> = Vec::new();
        for &id in terrain {
            if id.level > level {
                continue;
            }
            let Some((src, slot)) = self.service.draw_source(id) else {
                continue;
            };
            let (h0, h1) = self.service.height_range(id);
            let (z0, z1) = (f64::from(h0), f64::from(h1) + tallest);
            let boxed = |b| eye_box(b, [z0, z1], eye);
            if boxed(pyramid.bounds(id)).2 >= outer {
                continue;
            }
            let src_bounds = pyramid.bounds(src);
            let src_cell = pyramid.cell_size_m(src.level);
            let k = 1u32 << (level - id.level);
            // The grass-level tiles inside `id` within reach of the eye.
            let clip = |lo: u32, c: f64| {
                let first = ((c - outer) / size).floor() as i64;
                let last = ((c + outer) / size).floor() as i64;
                (first.max(i64::from(lo)), last.min(i64::from(lo + k) - 1))
            };
            let ((x0, x1), (y0, y1)) = (clip(id.x * k, eye.x), clip(id.y * k, eye.y));
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let (x, y) = (x as u32, y as u32);
                    let sub = TileId::new(level, x, y);
                    let b = pyramid.bounds(sub);
                    let (min, max, near, far_d) = boxed(b);
                    if near >= outer || far_d <= inner {
                        continue;
                    }
                    if !view.frustum.intersects_box(min.as_vec3(), max.as_vec3()) {
                        continue;
                    }
                    let job = job_reading(sub, b, (src_bounds, src_cell, slot), eye);
                    far.push((near, PlantJob { far: 1, ..job }));
                }
            }
        }
        far.sort_by(|a, b| a.0.total_cmp(&b.0));
        let far: Vec<PlantJob> = far.into_iter().map(|f| f.1).collect();
        crate::plants::PlantRenderer::plant_jobs(grass_jobs, &far)
    }
}

impl Renderer {
    /// The trees' jobs of a frame: the terrain's tiles in view out to the trees' reach (the fog),
    /// each read from the tile the terrain draws it from. A tile finer than the grass level
    /// gives way to its grass-level ancestor (one job for all of them), a coarse tile is split
    /// into jobs of at most [`crate::plants::renderer::MAX_TREE_JOB_CELLS`] cells a side.
    /// Every job's cells are cells of the one grid of the trees
    /// ([`crate::plants::PlantSettings::cell_m`]), so that a tree stands where it stands
    /// whichever job places it. Nearest first, at most [`crate::plants::renderer::MAX_JOBS`].
    /// Empty without trees.
    pub(super) fn tree_jobs(&self, view: &FrameView, terrain: &[TileId]) -> Vec<PlantJob> {
        let (Some(trees), Some(rings)) = (
            self.grass.as_ref().and_then(|g| g.trees.as_ref()),
            self.rings.as_ref(),
        ) else {
            return Vec::new();
        };
        let settings = trees.settings();
        let pyramid = &self.world.manifest.pyramid;
        let grass_level = rings.settings.level;
        let per_tile = (pyramid.tile_size_m(grass_level) as f32 / settings.cell_m)
            .round()
            .max(1.0) as u32;
        let most = trees.params().grid[0];
        // The coarsest level whose tiles are jobs whole.
        let job_level =
            grass_level - (most / per_tile).max(1).ilog2().min(u32::from(grass_level)) as u8;
        let outer = f64::from(settings.view_m[1]);
        let eye = view.camera.position;
        let tallest = self.tallest_tree_m();
        let mut seen = std::collections::HashSet::new();
        let mut jobs: Vec<(f64, PlantJob)> = Vec::new();
        for &id in terrain {
            let id = id.ancestor_at(grass_level.min(id.level)).unwrap_or(id);
            if !seen.insert(id) {
                continue;
            }
            let Some((src, slot)) = self.service.draw_source(id) else {
                continue;
            };
            let (h0, h1) = self.service.height_range(id);
            let (z0, z1) = (f64::from(h0), f64::from(h1) + tallest);
            let boxed = |b| eye_box(b, [z0, z1], eye);
            if boxed(pyramid.bounds(id)).2 >= outer {
                continue;
            }
            let src_bounds = pyramid.bounds(src);
            let src_cell = pyramid.cell_size_m(src.level);
            let level = id.level.max(job_level);
            let k = 1u32 << (level - id.level);
            let cells = per_tile << (grass_level - level);
            for y in id.y * k..(id.y + 1) * k {
                for x in id.x * k..(id.x + 1) * k {
                    let sub = TileId::new(level, x, y);
                    let b = pyramid.bounds(sub);
                    let (min, max, near, _) = boxed(b);
                    if near >= outer || !view.frustum.intersects_box(min.as_vec3(), max.as_vec3()) {
                        continue;
                    }
                    let job = job_reading(sub, b, (src_bounds, src_cell, slot), eye);
                    jobs.push((near, PlantJob { cells, ..job }));
                }
            }
        }
        jobs.sort_by(|a, b| a.0.total_cmp(&b.0));
        jobs.into_iter()
            .map(|j| j.1)
            .take(crate::plants::renderer::MAX_JOBS as usize)
            .collect()
    }
}

impl Renderer {
    /// The height of the world's tallest tree, metres (0 without trees): how far above its
    /// ground a tile's trees reach.
    fn tallest_tree_m(&self) -> f64 {
        self.world
            .manifest
            .plant_types
            .iter()
            .filter(|t| t.is_tree())
            .map(|t| f64::from(t.size_m[1]))
            .fold(0.0, f64::max)
    }

    /// The jobs of the trees' shadow casters: every grass-level tile within `distance` (and
    /// the casters' margin) of `eye` whose box meets the cascades' box `frustum`, read from the
    /// tile the terrain would draw it from, nearest first.
    pub(super) fn caster_jobs(
        &self,
        eye: glam::DVec3,
        frustum: &crate::lod::Frustum,
        distance: f64,
    ) -> Vec<PlantJob> {
        let (Some(casters), Some(rings)) = (
            self.grass.as_ref().and_then(|g| g.casters.as_ref()),
            self.rings.as_ref(),
        ) else {
            return Vec::new();
        };
        let settings = casters.settings();
        let pyramid = &self.world.manifest.pyramid;
        let level = rings.settings.level;
        let tile = pyramid.tile_size_m(level);
        let per_tile = (tile as f32 / settings.cell_m).round().max(1.0) as u32;
        let reach = distance + 40.0;
        let tallest = self.tallest_tree_m();
        let origin = pyramid.bounds(TileId::new(level, 0, 0)).min;
        let [cols, rows] = pyramid.tiles_at(level);
        let range = |e: f64, o: f64, n: u32| {
            let a = ((e - reach - o) / tile).floor().max(0.0) as u32;
            let b = (((e + reach - o) / tile).floor().max(0.0) as u32).min(n.saturating_sub(1));
            a..=b
        };
        let mut jobs: Vec<(f64, PlantJob)> = Vec::new();
        for y in range(eye.y, origin.y, rows) {
            for x in range(eye.x, origin.x, cols) {
                let id = TileId::new(level, x, y);
                let Some((src, slot)) = self.service.draw_source(id) else {
                    continue;
                };
                let (h0, h1) = self.service.height_range(id);
                let b = pyramid.bounds(id);
                let (min, max, near, _) = eye_box(b, [f64::from(h0), f64::from(h1) + tallest], eye);
                if near >= reach || !frustum.intersects_box(min.as_vec3(), max.as_vec3()) {
                    continue;
                }
                let src_info = (pyramid.bounds(src), pyramid.cell_size_m(src.level), slot);
                let job = job_reading(id, b, src_info, eye);
                jobs.push((
                    near,
                    PlantJob {
                        cells: per_tile,
                        ..job
                    },
                ));
            }
        }
        jobs.sort_by(|a, b| a.0.total_cmp(&b.0));
        jobs.into_iter()
            .map(|j| j.1)
            .take(crate::plants::renderer::MAX_JOBS as usize)
            .collect()
    }
}

/// The box of ground `b` between heights `z` relative to `eye`: its corners, and the nearest and
/// farthest distance of any of its points from the eye.
fn eye_box(
    b: crate::world::Bounds,
    [z0, z1]: [f64; 2],
    eye: glam::DVec3,
) -> (glam::DVec3, glam::DVec3, f64, f64) {
    let min = glam::DVec3::new(b.min.x, b.min.y, z0) - eye;
    let max = glam::DVec3::new(b.max.x, b.max.y, z1) - eye;
    let near = glam::DVec3::ZERO.clamp(min, max).length();
    let far = min.abs().max(max.abs()).length();
    (min, max, near, far)
}

/// A plant job over tile `id` (bounds `b`) read from the data tile of bounds, cell size and
/// atlas slot `src`: a near job of the grid's size (`far` and `cells` 0), for the caller to set.
fn job_reading(
    id: TileId,
    b: crate::world::Bounds,
    (src_bounds, src_cell, slot): (crate::world::Bounds, f64, u32),
    eye: glam::DVec3,
) -> PlantJob {
    let texel = (b.min - src_bounds.min) / src_cell;
    PlantJob {
        origin: [(b.min.x - eye.x) as f32, (b.min.y - eye.y) as f32],
        texel: [texel.x as f32, texel.y as f32],
        cell: src_cell as f32,
        layer: slot,
        tile_x: id.x,
        tile_y: id.y,
        far: 0,
        cells: 0,
        pad: [0; 2],
    }
}
