//! Residency: which tiles hold a slot of the GPU tile atlas, what to upload or derive next, and
//! which resident tile stands in for one that is not resident yet.
//!
//! This is the frame's side of the tile service. It owns the streamer and the CPU cache and plans
//! the atlas's contents; the caller carries the plan out on the GPU (uploads and derivations).
//! The atlas has a fixed number of slots and the cache a fixed number of bytes: neither grows,
//! however the camera moves. Level-0 tiles stay resident for good, so every tile always has a
//! resident ancestor to be drawn from: never a hole.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::stream::DeriveJob;
use crate::stream::{
    CacheStats, Loaded, StreamConfig, StreamStats, Streamer, TileCache, TileSource, Want,
};
use crate::world::{Pyramid, TileData, TileId};

/// Limits of the tile service.
#[derive(Clone, Copy, Debug)]
pub struct ServiceConfig {
    /// Slots of the GPU tile atlas.
    pub atlas_slots: u32,
    /// Ceiling of the CPU cache of decoded tiles, bytes.
    pub cache_bytes: u64,
    /// Stored tiles uploaded to the atlas a frame, at most.
    pub uploads_per_frame: u32,
    /// Tiles derived a frame, at most.
    pub derives_per_frame: u32,
    /// The streamer's limits.
    pub stream: StreamConfig,
    /// A tile whose load failed is drawn from its ancestor and loaded again (when still wanted)
    /// after this long, seconds; the wait doubles with each failure of the same tile, up to
    /// [`ServiceConfig::fault_retry_max_s`]. A fault that heals (a server back up, a file
    /// restored) so heals on screen too.
    pub fault_retry_s: f64,
    /// The longest wait before a failed tile is loaded again, seconds.
    pub fault_retry_max_s: f64,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            atlas_slots: 256,
            cache_bytes: 64 << 20,
            uploads_per_frame: 16,
            derives_per_frame: 32,
            stream: StreamConfig::default(),
            fault_retry_s: 5.0,
            fault_retry_max_s: 120.0,
        }
    }
}

/// A resident tile.
#[derive(Clone, Copy, Debug)]
struct Slot {
    index: u32,
    last_used: u64,
    min_h: f32,
    max_h: f32,
}

/// What the GPU must do this frame to carry out the plan.
#[derive(Default)]
pub struct ResidencyPlan {
    /// Stored tiles to write into their slots.
    pub uploads: Vec<(u32, Arc<TileData>)>,
    /// Tiles to derive from their parents.
    pub derives: Vec<DeriveJob>,
}

/// Residency figures of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResidencyStats {
    /// Tiles the frame wanted.
    pub desired: u32,
    /// Of those, resident at their own level.
    pub resident: u32,
    /// Of those, drawn from an ancestor instead.
    pub from_ancestor: u32,
    /// Wanted tiles with no resident ancestor at all (a hole; should stay 0).
    pub holes: u32,
    /// Atlas slots in use.
    pub atlas_used: u32,
    /// Atlas slots in all.
    pub atlas_slots: u32,
    /// Tiles the frame holds in the atlas: the wanted ones and all their ancestors (a frame
    /// needs at least this many slots to draw every wanted tile at its own level).
    #[serde(default)]
    pub held: u32,
    /// Atlas evictions so far.
    pub evictions: u64,
    /// Tiles uploaded this frame.
    pub uploaded: u32,
    /// Tiles derived this frame.
    pub derived: u32,
    /// Tiles whose last load failed, drawn from an ancestor until a retry loads them (each
    /// logged once).
    pub faults: u32,
    /// Desired tiles drawn from an ancestor because their own load, or the load of the stored
    /// tile they derive from, failed (counted in `from_ancestor` too).
    #[serde(default)]
    pub fault_blocked: u32,
    /// Tiles that loaded after failing, so far.
    #[serde(default)]
    pub faults_healed: u64,
    /// Desired tiles resident at their own level, as a fraction (1 when none are desired).
    pub resident_fraction: f64,
    /// The streamer's counters.
    pub stream: StreamStats,
    /// The CPU cache's counters.
    pub cache: CacheStats,
}

/// A tile whose last load failed.
#[derive(Debug)]
struct Failure {
    error: String,
    /// Failed loads in a row.
    attempts: u32,
    /// When it may be loaded again.
    retry_at: Instant,
    /// Its retry was sent to the streamer; the load's outcome is awaited.
    retrying: bool,
}

/// The wait before the `attempts`-th retry of a failed tile: `first` doubled per earlier
/// failure, at most `max`.
pub fn fault_retry_delay(first_s: f64, max_s: f64, attempts: u32) -> Duration {
    let s = first_s * 2f64.powi(attempts.saturating_sub(1).min(64) as i32);
    Duration::from_secs_f64(s.min(max_s).clamp(0.0, 1e9))
}

/// The tile service's frame side.
pub struct TileService {
    pyramid: Pyramid,
    config: ServiceConfig,
    streamer: Streamer,
    cache: TileCache,
    slots: Vec<Option<TileId>>,
    resident: HashMap<TileId, Slot>,
    failed: HashMap<TileId, Failure>,
    healed: u64,
    frame: u64,
    evictions: u64,
    last: ResidencyStats,
}

impl TileService {
    /// Starts the streamer and makes the level-0 tiles resident (loaded here, once, before the
    /// first frame). The returned plan uploads them; [`Self::start`] hands each to the caller
    /// as it is loaded instead, so that they are never all in memory at once.
    pub fn new(
        pyramid: &Pyramid,
        source: Arc<dyn TileSource>,
        config: ServiceConfig,
    ) -> Result<(Self, ResidencyPlan), crate::world::WorldError> {
        let mut plan = ResidencyPlan::default();
        let service = Self::start(pyramid, source, config, |slot, tile| {
            plan.uploads.push((slot, tile));
            Ok::<(), crate::world::WorldError>(())
        })?;
        Ok((service, plan))
    }

    /// [`Self::new`], each level-0 tile given to `upload` with its atlas slot as soon as it is
    /// loaded (and dropped after, unless `upload` keeps it).
    pub fn start<E: From<crate::world::WorldError>>(
        pyramid: &Pyramid,
        source: Arc<dyn TileSource>,
        config: ServiceConfig,
        mut upload: impl FnMut(u32, Arc<TileData>) -> Result<(), E>,
    ) -> Result<Self, E> {
        let [nx, ny] = pyramid.tiles_at(0);
        let roots = nx * ny;
        // Level 0 stays resident for good: the atlas needs a slot more than it.
        if config.atlas_slots <= roots {
            return Err(crate::world::WorldError::bad_option(
                "atlas slots",
                config.atlas_slots,
                format!("more than the world's {roots} level-0 tiles"),
            )
            .into());
        }
        let mut slots = vec![None; config.atlas_slots as usize];
        let mut resident = HashMap::new();
        for y in 0..ny {
            for x in 0..nx {
                let id = TileId::new(0, x, y);
                let tile = Arc::new(source.load(id).map_err(E::from)?);
                let index = y * nx + x;
                let (min_h, max_h) = height_range(&tile);
                slots[index as usize] = Some(id);
                resident.insert(
                    id,
                    Slot {
                        index,
                        last_used: 0,
                        min_h,
                        max_h,
                    },
                );
                upload(index, tile)?;
            }
        }
        let streamer =
            Streamer::start(source, config.stream).map_err(|e| crate::world::WorldError::Io {
                path: "tile streamer".into(),
                source: e,
            })?;
        Ok(Self {
            pyramid: pyramid.clone(),
            config,
            streamer,
            cache: TileCache::new(config.cache_bytes),
            slots,
            resident,
            failed: HashMap::new(),
            healed: 0,
            frame: 0,
            evictions: 0,
            last: ResidencyStats::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ServiceConfig {
        &self.config
    }

    /// Plans this frame: takes finished loads, picks what to upload and derive for the `wants`
    /// (most urgent first) and tells the streamer what to load next. Never waits.
    pub fn update(&mut self, wants: &[Want]) -> ResidencyPlan {
        self.frame += 1;
        let now = Instant::now();
        let (first_s, max_s) = (self.config.fault_retry_s, self.config.fault_retry_max_s);
        for loaded in self.streamer.poll() {
            match loaded {
                Loaded::Tile(tile) => {
                    if let Some(f) = self.failed.remove(&tile.id) {
                        self.healed += 1;
                        log::info!("tile {} loaded after {} failed loads", tile.id, f.attempts);
                    }
                    self.cache.insert(tile);
                }
                Loaded::Failed { id, error } => match self.failed.get_mut(&id) {
                    None => {
                        log::warn!(
                            "tile {id} failed to load, drawing its ancestor instead: {}",
                            crate::world::printable(&error)
                        );
                        self.failed.insert(
                            id,
                            Failure {
                                error,
                                attempts: 1,
                                retry_at: now + fault_retry_delay(first_s, max_s, 1),
                                retrying: false,
                            },
                        );
                    }
                    // A retry failed: wait longer.
                    Some(f) if f.retrying => {
                        f.attempts += 1;
                        f.retrying = false;
                        f.retry_at = now + fault_retry_delay(first_s, max_s, f.attempts);
                        log::info!(
                            "tile {id} failed again ({} times), next try in {:.0} s: {}",
                            f.attempts,
                            (f.retry_at - now).as_secs_f64(),
                            crate::world::printable(&error)
                        );
                        f.error = error;
                    }
                    Some(_) => {}
                },
            }
        }
        // Failed tiles whose wait is over are loaded again when wanted.
        let mut retry = Vec::new();
        for (id, f) in &mut self.failed {
            if !f.retrying && f.retry_at <= now {
                f.retrying = true;
                retry.push(*id);
            }
        }

        let mut order: Vec<Want> = wants.to_vec();
        order.sort_by(|a, b| a.priority.total_cmp(&b.priority).then(a.id.cmp(&b.id)));

        // Wanted tiles and all their ancestors keep their slots this frame.
        let mut protect: HashSet<TileId> = HashSet::new();
        for w in &order {
            let mut t = Some(w.id);
            while let Some(id) = t {
                if !protect.insert(id) {
                    break;
                }
                t = id.parent();
            }
        }
        for w in &order {
            self.touch(w.id);
        }

        let mut plan = ResidencyPlan::default();
        let mut stream_wants = Vec::new();
        let mut seen = HashSet::new();
        let mut fresh: HashSet<TileId> = HashSet::new();
        let mut work: Vec<Want> = order.iter().rev().copied().collect();
        while let Some(w) = work.pop() {
            let id = w.id;
            if !seen.insert(id)
                || self.resident.contains_key(&id)
                || self.failed.get(&id).is_some_and(|f| !f.retrying)
            {
                continue;
            }
            if self.pyramid.is_stored(id) {
                if plan.uploads.len() as u32 >= self.config.uploads_per_frame {
                    if !self.cache.contains(id) {
                        stream_wants.push(w);
                    }
                    continue;
                }
                match self.cache.get(id) {
                    Some(tile) => {
                        if let Some(index) = self.take_slot(&protect) {
                            self.place(id, index, height_range(&tile));
                            fresh.insert(id);
                            plan.uploads.push((index, tile));
                        }
                    }
                    None => stream_wants.push(w),
                }
            } else {
                let Some(parent) = id.parent() else { continue };
                match self.resident.get(&parent) {
                    // A parent placed this frame is not on the GPU until the frame's uploads
                    // and derivations have run: derive from it next frame.
                    Some(p) if !fresh.contains(&parent) => {
                        if plan.derives.len() as u32 >= self.config.derives_per_frame {
                            continue;
                        }
                        let (parent_slot, range) = (p.index, (p.min_h, p.max_h));
                        if let Some(index) = self.take_slot(&protect) {
                            // Detail noise adds at most about a cell to the parent's range.
                            let margin = self.pyramid.cell_size_m(id.level) as f32;
                            self.place(id, index, (range.0 - margin, range.1 + margin));
                            fresh.insert(id);
                            plan.derives.push(DeriveJob {
                                child: id,
                                parent_slot,
                                child_slot: index,
                            });
                        }
                    }
                    Some(_) => {}
                    None => work.push(Want {
                        id: parent,
                        priority: w.priority,
                    }),
                }
            }
        }
        self.streamer.want_retrying(stream_wants, retry);

        let mut stats = ResidencyStats {
            desired: wants.len() as u32,
            atlas_slots: self.config.atlas_slots,
            atlas_used: self.resident.len() as u32,
            held: protect.len() as u32,
            evictions: self.evictions,
            uploaded: plan.uploads.len() as u32,
            derived: plan.derives.len() as u32,
            faults: self.failed.len() as u32,
            faults_healed: self.healed,
            stream: self.streamer.stats(),
            cache: self.cache.stats(),
            ..Default::default()
        };
        for w in wants {
            match self.draw_source(w.id) {
                Some((src, _)) if src == w.id => stats.resident += 1,
                Some(_) => {
                    stats.from_ancestor += 1;
                    if self.blocked_by(w.id).is_some() {
                        stats.fault_blocked += 1;
                    }
                }
                None => stats.holes += 1,
            }
        }
        stats.resident_fraction = if wants.is_empty() {
            1.0
        } else {
            f64::from(stats.resident) / wants.len() as f64
        };
        self.last = stats;
        plan
    }

    /// Figures of the last [`Self::update`].
    pub fn stats(&self) -> ResidencyStats {
        self.last
    }

    /// The resident tile to draw `id` from: itself, or its nearest resident ancestor, with its
    /// atlas slot. `None` only if not even its level-0 ancestor is resident.
    pub fn draw_source(&self, id: TileId) -> Option<(TileId, u32)> {
        let mut t = Some(id);
        while let Some(cur) = t {
            if let Some(s) = self.resident.get(&cur) {
                return Some((cur, s.index));
            }
            t = cur.parent();
        }
        None
    }

    /// Height range of `id` from its own data or its nearest resident ancestor's.
    pub fn height_range(&self, id: TileId) -> (f32, f32) {
        let mut t = Some(id);
        while let Some(cur) = t {
            if let Some(s) = self.resident.get(&cur) {
                return (s.min_h, s.max_h);
            }
            t = cur.parent();
        }
        (-1.0e4, 1.0e5)
    }

    /// The failed tile that keeps `id` from becoming resident, with its error: `id` itself or
    /// the ancestor it would be derived from (through non-resident tiles), if its load failed.
    /// `None` while nothing on that chain has failed.
    pub fn blocked_by(&self, id: TileId) -> Option<(TileId, &str)> {
        let mut t = Some(id);
        while let Some(cur) = t {
            if self.resident.contains_key(&cur) {
                return None;
            }
            if let Some(f) = self.failed.get(&cur) {
                return Some((cur, &f.error));
            }
            if self.pyramid.is_stored(cur) {
                return None;
            }
            t = cur.parent();
        }
        None
    }

    /// Whether `id` holds an atlas slot.
    pub fn is_resident(&self, id: TileId) -> bool {
        self.resident.contains_key(&id)
    }

    fn touch(&mut self, id: TileId) {
        let frame = self.frame;
        let mut t = Some(id);
        while let Some(cur) = t {
            if let Some(s) = self.resident.get_mut(&cur) {
                s.last_used = frame;
            }
            t = cur.parent();
        }
    }

    fn place(&mut self, id: TileId, index: u32, (min_h, max_h): (f32, f32)) {
        self.slots[index as usize] = Some(id);
        self.resident.insert(
            id,
            Slot {
                index,
                last_used: self.frame,
                min_h,
                max_h,
            },
        );
    }

    /// A free slot, or the least recently used one whose tile is neither protected nor level 0.
    fn take_slot(&mut self, protect: &HashSet<TileId>) -> Option<u32> {
        if let Some(i) = self.slots.iter().position(Option::is_none) {
            return Some(i as u32);
        }
        let victim = self
            .resident
            .iter()
            .filter(|(id, _)| id.level > 0 && !protect.contains(id))
            .min_by_key(|(id, s)| (s.last_used, std::cmp::Reverse(id.level), **id))
            .map(|(id, s)| (*id, s.index))?;
        self.resident.remove(&victim.0);
        self.slots[victim.1 as usize] = None;
        self.evictions += 1;
        Some(victim.1)
    }
}

fn height_range(tile: &TileData) -> (f32, f32) {
    tile.heights
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &h| (lo.min(h), hi.max(h)))
}
