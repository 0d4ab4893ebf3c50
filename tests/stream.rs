//! The tile service without a GPU: ceilings, cancellation, priorities and faults.

mod common;

use std::collections::HashSet;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glam::DVec3;
use verdant::lod::{Frustum, TerrainLod, select_terrain};
use verdant::stream::{
    Loaded, ServiceConfig, StreamConfig, Streamer, TileCache, TileService, TileSource, Want,
};
use verdant::world::{TileData, TileId, World, WorldError};

fn world() -> World {
    World::open(&common::default_world()).expect("open the default world")
}

/// A source that delays chosen tiles and counts loads.
struct SlowSource {
    world: World,
    slow: HashSet<TileId>,
    delay: Duration,
    loads: AtomicU32,
}

impl TileSource for SlowSource {
    fn load(&self, id: TileId) -> Result<TileData, WorldError> {
        self.loads.fetch_add(1, Ordering::SeqCst);
        if self.slow.contains(&id) {
            std::thread::sleep(self.delay);
        }
        self.world.load_tile(id)
    }
}

fn wait_for(mut f: impl FnMut() -> bool, what: &str) {
    let start = Instant::now();
    while !f() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn tiles_that_leave_the_wanted_set_while_loading_are_not_inserted() {
    let slow_tile = TileId::new(2, 5, 7);
    let fast_tile = TileId::new(2, 1, 1);
    let source = Arc::new(SlowSource {
        world: world(),
        slow: [slow_tile].into(),
        delay: Duration::from_millis(300),
        loads: AtomicU32::new(0),
    });
    let mut streamer = Streamer::start(source.clone(), StreamConfig::default()).unwrap();
    streamer.want(vec![Want {
        id: slow_tile,
        priority: 1.0,
    }]);
    wait_for(|| streamer.stats().in_flight == 1, "the slow load to start");
    // The camera moved on: the slow tile is no longer wanted, another one is.
    streamer.want(vec![Want {
        id: fast_tile,
        priority: 1.0,
    }]);
    let mut got = Vec::new();
    wait_for(
        || {
            got.extend(streamer.poll());
            let s = streamer.stats();
            s.cancelled == 1 && s.completed == 1
        },
        "the cancellation and the fast load",
    );
    std::thread::sleep(Duration::from_millis(50));
    got.extend(streamer.poll());
    let ids: Vec<TileId> = got
        .iter()
        .map(|l| match l {
            Loaded::Tile(t) => t.id,
            Loaded::Failed { id, .. } => panic!("unexpected failure of {id:?}"),
        })
        .collect();
    assert_eq!(
        ids,
        vec![fast_tile],
        "the cancelled tile must not come back"
    );
}

#[test]
fn the_most_urgent_tiles_load_first() {
    let source = Arc::new(SlowSource {
        world: world(),
        slow: HashSet::new(),
        delay: Duration::ZERO,
        loads: AtomicU32::new(0),
    });
    let config = StreamConfig {
        max_in_flight: 1,
        ..StreamConfig::default()
    };
    let mut streamer = Streamer::start(source, config).unwrap();
    let wants: Vec<Want> = (0..6)
        .map(|i| Want {
            id: TileId::new(2, i, 0),
            priority: 10.0 - i as f32,
        })
        .collect();
    streamer.want(wants);
    let mut order = Vec::new();
    wait_for(
        || {
            for l in streamer.poll() {
                if let Loaded::Tile(t) = l {
                    order.push(t.id.x);
                }
            }
            order.len() == 6
        },
        "six loads",
    );
    // One load at a time, lowest priority value first.
    assert_eq!(order, vec![5, 4, 3, 2, 1, 0]);
}

#[test]
fn cache_never_passes_its_ceiling() {
    let w = world();
    let tile = Arc::new(w.load_tile(TileId::new(2, 0, 0)).unwrap());
    let size = tile.byte_size() as u64;
    let mut cache = TileCache::new(size * 3 + size / 2);
    for x in 0..10 {
        let mut t = (*tile).clone();
        t.id = TileId::new(2, x, 0);
        assert!(cache.insert(Arc::new(t)));
        assert!(cache.stats().bytes <= cache.ceiling_bytes());
    }
    let s = cache.stats();
    assert_eq!(s.tiles, 3);
    assert_eq!(s.evictions, 7);
    // Least recently used goes first: the last three stay.
    assert!(cache.get(TileId::new(2, 9, 0)).is_some());
    assert!(cache.get(TileId::new(2, 6, 0)).is_none());
    assert!(s.peak_bytes <= cache.ceiling_bytes());
}

/// Runs the frame side of the tile service for a scripted camera that jumps across the world,
/// carrying out each plan on the CPU (derived tiles need no data here), and checks the ceilings
/// every frame.
#[test]
fn ceilings_hold_when_the_camera_jumps_across_the_world() {
    let w = world();
    let pyramid = w.manifest.pyramid.clone();
    let config = ServiceConfig {
        atlas_slots: 48,
        cache_bytes: 3 << 20,
        uploads_per_frame: 8,
        derives_per_frame: 8,
        stream: StreamConfig::default(),
        ..ServiceConfig::default()
    };
    let (mut service, _) = TileService::new(&pyramid, Arc::new(w.clone()), config).unwrap();
    let lod = TerrainLod {
        lod_factor: 1.5,
        max_level: pyramid.max_level(),
    };
    let [ex, ey] = w.manifest.extent_m;
    let mut rng = common::Rng(7);
    let mut peak_cache = 0;
    let mut peak_atlas = 0;
    let mut eye = DVec3::new(ex / 2.0, ey / 2.0, 400.0);
    for frame in 0..400 {
        if frame % 40 == 0 {
            eye = DVec3::new(rng.unit() * ex, rng.unit() * ey, 150.0 + 400.0 * rng.unit());
        } else {
            eye.x += 30.0;
        }
        let tiles = select_terrain(&pyramid, lod, eye, &Frustum::everything(), &|id| {
            service.height_range(id)
        });
        let wants: Vec<Want> = tiles
            .iter()
            .map(|&id| Want {
                id,
                priority: id.level as f32,
            })
            .collect();
        service.update(&wants);
        let s = service.stats();
        assert!(
            s.cache.bytes <= config.cache_bytes,
            "frame {frame}: cache {} bytes",
            s.cache.bytes
        );
        assert!(
            s.atlas_used <= config.atlas_slots,
            "frame {frame}: {} slots",
            s.atlas_used
        );
        assert_eq!(
            s.holes, 0,
            "frame {frame}: a tile had nothing to draw it from"
        );
        peak_cache = peak_cache.max(s.cache.peak_bytes);
        peak_atlas = peak_atlas.max(s.atlas_used);
        std::thread::sleep(Duration::from_millis(1));
    }
    let s = service.stats();
    assert!(
        s.evictions > 0,
        "the scripted flight should have needed evictions"
    );
    assert!(
        s.cache.evictions > 0,
        "the scripted flight should have filled the cache"
    );
    assert!(peak_cache <= config.cache_bytes && peak_atlas <= config.atlas_slots);
}

/// A copy of the default world's manifest and tiles in `parent/world`, to break files of.
fn world_copy(parent: &std::path::Path) -> std::path::PathBuf {
    let dir = parent.join("world");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(
        common::default_world().join("world.toml"),
        dir.join("world.toml"),
    )
    .unwrap();
    common::copy_dir(&common::default_world().join("tiles"), &dir.join("tiles"));
    dir
}

/// The level-0 tiles are handed over one by one as they load, each held by nothing else
/// (the service keeps none of them), so that a world of thousands of roots is never in memory
/// at once; a load that fails ends the start with its error.
#[test]
fn level_0_tiles_are_handed_over_as_they_load() {
    let w = World::open(&common::default_world()).unwrap();
    let pyramid = w.manifest.pyramid.clone();
    let [nx, ny] = pyramid.tiles_at(0);
    let mut seen = Vec::new();
    let service = TileService::start(
        &pyramid,
        Arc::new(w),
        ServiceConfig::default(),
        |slot, tile| {
            seen.push((slot, Arc::strong_count(&tile)));
            Ok::<(), WorldError>(())
        },
    )
    .unwrap();
    assert_eq!(seen.len() as u32, nx * ny);
    assert!(seen.iter().all(|&(_, refs)| refs == 1), "{seen:?}");
    for (x, y) in (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))) {
        assert!(service.is_resident(TileId::new(0, x, y)));
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = world_copy(tmp.path());
    std::fs::remove_file(dir.join("tiles/L0/0_0.height.exr")).unwrap();
    let w = World::open(&dir).unwrap();
    let mut calls = 0;
    let e = TileService::start(&pyramid, Arc::new(w), ServiceConfig::default(), |_, _| {
        calls += 1;
        Ok::<(), WorldError>(())
    })
    .err()
    .unwrap();
    assert!(e.to_string().contains("0_0.height.exr"), "{e}");
    assert_eq!(calls, 0);
}

/// A missing and a corrupt tile file: the frame loop keeps going, the tiles are drawn from
/// their ancestors, and each fault is reported once.
#[test]
fn missing_and_corrupt_tiles_fall_back_to_their_ancestors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = world_copy(tmp.path());
    let (missing, corrupt) = (TileId::new(2, 3, 4), TileId::new(1, 2, 2));
    std::fs::remove_file(dir.join("tiles/L2/3_4.height.exr")).unwrap();
    std::fs::write(dir.join("tiles/L1/2_2.density.png"), b"not a png at all").unwrap();
    let w = World::open(&dir).unwrap();
    let pyramid = w.manifest.pyramid.clone();
    let (mut service, _) =
        TileService::new(&pyramid, Arc::new(w), ServiceConfig::default()).unwrap();
    let wants: Vec<Want> = [missing, corrupt, TileId::new(2, 0, 0)]
        .iter()
        .map(|&id| Want { id, priority: 1.0 })
        .collect();
    let faults = Arc::new(Mutex::new(0));
    let start = Instant::now();
    loop {
        service.update(&wants);
        let s = service.stats();
        assert_eq!(s.holes, 0);
        *faults.lock().unwrap() = s.faults;
        if s.faults == 2 && service.is_resident(TileId::new(2, 0, 0)) {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "faults not seen: {s:?}"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    // The broken tiles are drawn from their nearest resident ancestors.
    assert_eq!(service.draw_source(missing).unwrap().0.level, 0);
    assert_eq!(
        service.draw_source(corrupt).unwrap().0,
        TileId::new(0, 1, 1)
    );
    // Asking again does not load (or log) them again.
    for _ in 0..50 {
        service.update(&wants);
        std::thread::sleep(Duration::from_millis(1));
    }
    let s = service.stats();
    assert_eq!(s.faults, 2);
    assert_eq!(
        s.stream.failed, 2,
        "each broken tile is loaded and reported once"
    );
}

/// A source whose every load fails at once, counting loads.
struct BrokenSource {
    loads: AtomicU32,
}

impl TileSource for BrokenSource {
    fn load(&self, id: TileId) -> Result<TileData, WorldError> {
        self.loads.fetch_add(1, Ordering::SeqCst);
        Err(WorldError::MissingFile {
            path: std::path::PathBuf::from(format!(
                "tiles/L{}/{}_{}.height.exr",
                id.level, id.x, id.y
            )),
        })
    }
}

#[test]
fn a_failed_tile_is_not_loaded_again_when_a_stale_want_set_names_it() {
    let source = Arc::new(BrokenSource {
        loads: AtomicU32::new(0),
    });
    let mut streamer = Streamer::start(source.clone(), StreamConfig::default()).unwrap();
    let broken = TileId::new(2, 3, 4);
    let want = vec![Want {
        id: broken,
        priority: 1.0,
    }];
    streamer.want(want.clone());
    wait_for(|| streamer.stats().failed == 1, "the load to fail");
    // The frame has not polled the failure yet: its next want set still names the tile.
    streamer.want(want.clone());
    streamer.want(want);
    std::thread::sleep(Duration::from_millis(100));
    let failures: Vec<Loaded> = streamer.poll();
    assert_eq!(failures.len(), 1, "reported once");
    assert!(matches!(failures[0], Loaded::Failed { id, .. } if id == broken));
    assert_eq!(source.loads.load(Ordering::SeqCst), 1, "loaded once");
    assert_eq!(streamer.stats().failed, 1);
}

/// A tile file broken and then restored: the tile is drawn from its ancestor while broken, loaded
/// again after the retry wait (which doubles with each failure), and resident once restored.
#[test]
fn a_failed_tile_is_retried_and_heals_once_its_file_is_restored() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = world_copy(tmp.path());
    let broken = TileId::new(2, 3, 4);
    let file = dir.join("tiles/L2/3_4.height.exr");
    let good = std::fs::read(&file).unwrap();
    std::fs::write(&file, &good[..good.len() / 2]).unwrap();
    let w = World::open(&dir).unwrap();
    let pyramid = w.manifest.pyramid.clone();
    let config = ServiceConfig {
        fault_retry_s: 0.05,
        fault_retry_max_s: 0.2,
        ..ServiceConfig::default()
    };
    let (mut service, _) = TileService::new(&pyramid, Arc::new(w), config).unwrap();
    let wants = vec![Want {
        id: broken,
        priority: 1.0,
    }];
    let step = |service: &mut TileService| {
        service.update(&wants);
        let s = service.stats();
        assert_eq!(s.holes, 0, "{s:?}");
        std::thread::sleep(Duration::from_millis(2));
        s
    };
    // Broken: it fails, is retried, and fails again; meanwhile its ancestor draws it.
    let start = Instant::now();
    while step(&mut service).stream.failed < 3 {
        assert!(start.elapsed() < Duration::from_secs(30), "no retries");
    }
    let s = service.stats();
    assert_eq!(s.faults, 1, "one tile is failed: {s:?}");
    assert_eq!(
        s.fault_blocked, 1,
        "the wanted tile is blocked by its fault"
    );
    assert!(!service.is_resident(broken));
    assert!(service.blocked_by(broken).is_some());
    // Restored: the next retry loads it.
    std::fs::write(&file, &good).unwrap();
    while !service.is_resident(broken) {
        step(&mut service);
        assert!(start.elapsed() < Duration::from_secs(30), "never healed");
    }
    let s = step(&mut service);
    assert_eq!(
        (s.faults, s.fault_blocked, s.faults_healed),
        (0, 0, 1),
        "{s:?}"
    );
    assert_eq!(s.resident, 1);
}

#[test]
fn the_retry_wait_doubles_up_to_its_ceiling() {
    use verdant::stream::fault_retry_delay;
    let d = |n| fault_retry_delay(5.0, 120.0, n).as_secs_f64();
    assert_eq!(
        [d(1), d(2), d(3), d(5), d(6), d(1000)],
        [5.0, 10.0, 20.0, 80.0, 120.0, 120.0]
    );
}

#[test]
fn a_streamer_refuses_zero_or_absurd_loads_in_flight() {
    for n in [0, verdant::stream::MAX_LOADS_IN_FLIGHT + 1, usize::MAX] {
        let config = StreamConfig {
            max_in_flight: n,
            ..StreamConfig::default()
        };
        let err = Streamer::start(Arc::new(world()), config)
            .err()
            .expect("refused");
        assert!(err.to_string().contains("1..=1024"), "{err}");
    }
}

#[test]
fn an_atlas_no_larger_than_level_0_is_refused_not_a_panic() {
    let w = world();
    let pyramid = w.manifest.pyramid.clone();
    let [nx, ny] = pyramid.tiles_at(0);
    let config = ServiceConfig {
        atlas_slots: nx * ny,
        ..ServiceConfig::default()
    };
    let e = TileService::new(&pyramid, Arc::new(w), config)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("level-0 tiles"), "{e}");
}
