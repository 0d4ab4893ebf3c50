//! The CPU paths that bound streaming and frame preparation (see `benches/README.md`).
//!
//! `cargo bench` runs them all; `cargo bench -- derive` one group.

use std::hint::black_box;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use verdant::Camera;
use verdant::lod::{Frustum, GrassRings, RingSettings, TerrainLod, select_terrain};
use verdant::stream::{
    DeriveParams, Loaded, StreamConfig, Streamer, TileCache, Want, derive_child,
};
use verdant::world::{TileData, TileId, World};

fn world() -> World {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("worlds/santa-cruz");
    World::open(&dir).expect("the default world")
}

/// A tile of the finest stored level near the middle of the world.
fn finest_tile(world: &World) -> TileId {
    let p = &world.manifest.pyramid;
    let level = p.stored_levels - 1;
    let [nx, ny] = p.tiles_at(level);
    TileId::new(level, nx / 2, ny / 2)
}

/// Child-tile derivation, the CPU mirror of `shaders/stream_derive.wgsl`: one child of a stored
/// tile, and one of a derived tile (two levels below the data).
fn derive(c: &mut Criterion) {
    let world = world();
    let p = world.manifest.pyramid.clone();
    let params = DeriveParams::for_manifest(&world.manifest);
    let parent_id = finest_tile(&world);
    let parent = world.load_tile(parent_id).unwrap();
    let child_id = parent_id.children()[0];
    let child = derive_child(&p, &parent, child_id, &params);
    let mut g = c.benchmark_group("derive");
    g.throughput(Throughput::Elements(u64::from(p.samples_per_side().pow(2))));
    g.bench_function("child of a stored tile", |b| {
        b.iter(|| derive_child(&p, black_box(&parent), child_id, &params))
    });
    g.bench_function("child of a derived tile", |b| {
        b.iter(|| derive_child(&p, black_box(&child), child_id.children()[3], &params))
    });
    g.finish();
}

/// LOD selection and the grass rings' update for a camera flying at 50 m/s, 0.1 s a frame, low
/// over the world (the soak's flight).
fn lod(c: &mut Criterion) {
    let world = world();
    let p = world.manifest.pyramid.clone();
    let lod = TerrainLod {
        lod_factor: 1.0,
        max_level: p.max_level(),
    };
    let range = |_: TileId| (0.0f32, 1000.0f32);
    let camera_at = |i: u32| {
        let t = f64::from(i) * 0.1;
        DVec3::new(2000.0 + 50.0 * t, 3000.0 + 20.0 * t, 120.0)
    };
    let camera = Camera::new(DVec3::ZERO, 22.0, -6.0);
    let frustum = Frustum::from_view_proj(camera.view_proj_relative(16.0 / 9.0));
    let mut g = c.benchmark_group("lod");
    let mut i = 0u32;
    g.bench_function("terrain selection", |b| {
        b.iter(|| {
            i = (i + 1) % 2000;
            select_terrain(&p, lod, camera_at(i), &frustum, &range)
        })
    });
    let mut rings = GrassRings::new(RingSettings::for_pyramid(&p));
    let mut j = 0u32;
    g.bench_function("grass ring update", |b| {
        b.iter(|| {
            j = (j + 1) % 2000;
            rings.update(&p, camera_at(j), &range)
        })
    });
    g.finish();
}

/// Decoding stored tiles: the EXR heights and the PNG maps, from the default world's files, and
/// a PNG map alone.
fn decode(c: &mut Criterion) {
    let world = world();
    let id = finest_tile(&world);
    let mut g = c.benchmark_group("decode");
    g.throughput(Throughput::Elements(1));
    g.bench_function("stored tile (EXR heights, PNG type and density)", |b| {
        b.iter(|| world.load_tile(black_box(id)).unwrap())
    });
    let type_map = world.tile_path(id, verdant::world::TileFile::Type);
    g.bench_function("PNG type map alone", |b| {
        b.iter(|| image::open(black_box(&type_map)).unwrap())
    });
    g.finish();
}

/// The byte-bounded cache under a streaming access pattern: a window of tiles sliding over the
/// world, each frame asking for the window (hits) and the tiles entering it (misses, inserted).
fn cache(c: &mut Criterion) {
    let world = world();
    let size = world.manifest.pyramid.samples_per_side();
    let tile = |x: u32, y: u32| {
        let n = (size * size) as usize;
        Arc::new(TileData {
            id: TileId::new(8, x, y),
            size,
            heights: vec![0.0; n],
            grass_type: vec![1; n],
            density: vec![255; n],
            material: Vec::new(),
        })
    };
    let one = tile(0, 0).byte_size() as u64;
    let mut g = c.benchmark_group("cache");
    g.throughput(Throughput::Elements(64));
    // A ceiling of 48 tiles under a window of 8 x 8 that slides one column a frame.
    let mut cache = TileCache::new(48 * one);
    let mut frame = 0u32;
    g.bench_function("sliding window of 64 tiles, 48 fit", |b| {
        b.iter(|| {
            frame += 1;
            for y in 0..8 {
                for x in frame..frame + 8 {
                    let id = TileId::new(8, x, y);
                    if cache.get(id).is_none() {
                        cache.insert(tile(x, y));
                    }
                }
            }
        })
    });
    g.finish();
}

/// The streamer's throughput from disk: every tile of the finest stored level loaded and
/// decoded, with 1, 4 and 8 loads in flight (tiles a second).
fn streamer(c: &mut Criterion) {
    let world = Arc::new(world());
    let p = world.manifest.pyramid.clone();
    let level = p.stored_levels - 1;
    let [nx, ny] = p.tiles_at(level);
    let wants: Vec<Want> = (0..ny)
        .flat_map(|y| (0..nx).map(move |x| TileId::new(level, x, y)))
        .enumerate()
        .map(|(i, id)| Want {
            id,
            priority: i as f32,
        })
        .collect();
    let mut g = c.benchmark_group("streamer");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(10));
    g.throughput(Throughput::Elements(wants.len() as u64));
    for loads in [1usize, 4, 8] {
        g.bench_with_input(
            BenchmarkId::new("finest level from disk, loads in flight", loads),
            &loads,
            |b, &loads| {
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        let config = StreamConfig {
                            max_in_flight: loads,
                            ..StreamConfig::default()
                        };
                        let mut s = Streamer::start(world.clone(), config).unwrap();
                        let start = Instant::now();
                        // As the frame does: ask for what is still missing.
                        let mut missing = wants.clone();
                        while !missing.is_empty() {
                            s.want(missing.clone());
                            let got = s.poll();
                            if got.is_empty() {
                                std::thread::sleep(Duration::from_micros(200));
                            }
                            for loaded in got {
                                let id = match loaded {
                                    Loaded::Tile(t) => t.id,
                                    Loaded::Failed { id, error } => panic!("{id:?}: {error}"),
                                };
                                missing.retain(|w| w.id != id);
                            }
                        }
                        total += start.elapsed();
                    }
                    total
                })
            },
        );
    }
    g.finish();
}

criterion_group!(benches, derive, lod, decode, cache, streamer);
criterion_main!(benches);
