//! Helpers shared by the integration tests: GPU, reference images, synthetic DEMs, terrain
//! lookups on baked worlds.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use verdant::gpu::GpuContext;
use verdant::tools::metrics::flip_compare;

use glam::DVec2;
use std::collections::HashMap;
use verdant::world::{CameraPath, TileData, TileId, World};
/// The repository's root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The default world's folder.
pub fn default_world() -> PathBuf {
    root().join("worlds").join("santa-cruz")
}

/// Opens the GPU. A machine with no adapter fails the test: GPU tests never skip.
pub fn gpu() -> GpuContext {
    match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => panic!("GPU tests need an adapter: {e}"),
    }
}

/// Where failing image tests leave their actual and difference images.
pub fn failure_dir() -> PathBuf {
    root().join("target").join("test-images")
}

/// Compares `actual` with `tests/reference/NAME.png` by FLIP. Fails when the mean error exceeds
/// `max_mean` or the 99th percentile exceeds `max_p99`, and then writes `NAME-actual.png` and
/// `NAME-difference.png` under `target/test-images`. A missing reference fails too, unless
/// `VERDANT_UPDATE_REFERENCES=1` asks for the reference to be (re)written; review a new
/// reference image before committing it.
pub fn check_reference(name: &str, actual: &image::RgbaImage, max_mean: f32, max_p99: f32) {
    let reference_path = root()
        .join("tests")
        .join("reference")
        .join(format!("{name}.png"));
    let actual_rgb = image::DynamicImage::ImageRgba8(actual.clone()).to_rgb8();
    if std::env::var("VERDANT_UPDATE_REFERENCES").as_deref() == Ok("1") {
        actual_rgb
            .save(&reference_path)
            .expect("write reference image");
        eprintln!("wrote reference {}", reference_path.display());
        return;
    }
    let dir = failure_dir();
    let write_failure = |diff: Option<&[u8]>| {
        std::fs::create_dir_all(&dir).expect("create failure image folder");
        let actual_file = dir.join(format!("{name}-actual.png"));
        actual_rgb.save(&actual_file).expect("write actual image");
        if let Some(diff) = diff {
            let (w, h) = actual_rgb.dimensions();
            let img = image::RgbImage::from_raw(w, h, diff.to_vec()).expect("difference size");
            img.save(dir.join(format!("{name}-difference.png")))
                .expect("write difference");
        }
        actual_file
    };
    let reference = match image::open(&reference_path) {
        Ok(img) => img.to_rgb8(),
        Err(e) => {
            let file = write_failure(None);
            panic!(
                "missing or unreadable reference {} ({e}); the actual image is {}. \
                 Run with VERDANT_UPDATE_REFERENCES=1 to create it, then review it.",
                reference_path.display(),
                file.display()
            );
        }
    };
    let result = match flip_compare(&reference, &actual_rgb) {
        Ok(r) => r,
        Err(e) => {
            let file = write_failure(None);
            panic!("{name}: {e}; actual image at {}", file.display());
        }
    };
    eprintln!(
        "{name}: FLIP mean {:.4}, p99 {:.4}, max {:.4}",
        result.mean, result.p99, result.max
    );
    if result.mean > max_mean || result.p99 > max_p99 {
        let file = write_failure(Some(&result.difference_rgb));
        panic!(
            "{name}: FLIP mean {:.4} (limit {max_mean}), p99 {:.4} (limit {max_p99}); \
             actual and difference images beside {}",
            result.mean,
            result.p99,
            file.display()
        );
    }
}

/// Copies a folder tree (for tests that damage a copy of a world).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// Writes a 16-bit DEM `name.png` with its sidecar into `dir`: `width x height` samples,
/// row 0 north, height at sample (c, r) = `f(c * cell_ew, (height - 1 - r) * cell_ns)`,
/// stored as `round((h - offset) / scale)`.
pub fn write_dem(
    dir: &Path,
    name: &str,
    [width, height]: [u32; 2],
    [cell_ew, cell_ns]: [f64; 2],
    [offset, scale]: [f64; 2],
    f: impl Fn(f64, f64) -> f64,
) -> PathBuf {
    let mut img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::new(width, height);
    for r in 0..height {
        for c in 0..width {
            let h = f(f64::from(c) * cell_ew, f64::from(height - 1 - r) * cell_ns);
            let v = ((h - offset) / scale).round().clamp(0.0, 65535.0) as u16;
            img.put_pixel(c, r, image::Luma([v]));
        }
    }
    let png = dir.join(format!("{name}.png"));
    img.save(&png).unwrap();
    write_sidecar(
        dir,
        name,
        [width, height],
        [cell_ew, cell_ns],
        [offset, scale],
    );
    png
}

/// Writes only the sidecar `name.json`.
pub fn write_sidecar(
    dir: &Path,
    name: &str,
    [width, height]: [u32; 2],
    [cell_ew, cell_ns]: [f64; 2],
    [offset, scale]: [f64; 2],
) {
    let json = serde_json::json!({
        "file": format!("{name}.png"),
        "width": width,
        "height": height,
        "row_order": "first row is the northern edge",
        "cell_size_m": { "east_west": cell_ew, "north_south": cell_ns },
        "height_offset_m": offset,
        "height_scale_m": scale,
        "place": "a synthetic test landscape",
    });
    std::fs::write(dir.join(format!("{name}.json")), json.to_string()).unwrap();
}

/// All stored tiles of a world, decoded, for lookups across tiles.
pub struct Terrain {
    pub world: World,
    pub tiles: HashMap<TileId, TileData>,
    /// Derived tiles made so far by [`Terrain::drawn_height`].
    derived: std::cell::RefCell<HashMap<TileId, TileData>>,
}

impl Terrain {
    pub fn load(dir: &Path) -> Terrain {
        let world = World::open(dir).unwrap();
        let tiles = world
            .stored_tiles()
            .map(|id| (id, world.load_tile(id).unwrap()))
            .collect();
        Terrain {
            world,
            tiles,
            derived: Default::default(),
        }
    }

    /// Height at `p` by bilinear interpolation in the finest stored level.
    pub fn height(&self, p: DVec2) -> f64 {
        let pyramid = &self.world.manifest.pyramid;
        let id = pyramid.tile_at(pyramid.stored_levels - 1, p);
        self.bilinear(&self.tiles[&id.expect("point inside the world")], p)
    }

    /// Height at `p` of the ground the renderer draws near the camera: the finest derived
    /// level, derived from the stored tiles by the derivation's CPU mirror
    /// (`verdant::stream::derive_child`, with the manifest's detail), sampled bilinearly.
    pub fn drawn_height(&self, p: DVec2) -> f64 {
        let pyramid = &self.world.manifest.pyramid;
        let id = pyramid.tile_at(pyramid.max_level(), p);
        let id = id.expect("point inside the world");
        self.derive(id);
        match self.tiles.get(&id) {
            Some(tile) => self.bilinear(tile, p),
            None => self.bilinear(&self.derived.borrow()[&id], p),
        }
    }

    /// Height at `p` (inside `tile`) by bilinear interpolation between its samples.
    fn bilinear(&self, tile: &TileData, p: DVec2) -> f64 {
        let pyramid = &self.world.manifest.pyramid;
        let cell = pyramid.cell_size_m(tile.id.level);
        let u = (p - pyramid.bounds(tile.id).min) / cell + f64::from(pyramid.border);
        let (i, j) = (u.x.floor() as u32, u.y.floor() as u32);
        let (fu, fv) = (u.x - f64::from(i), u.y - f64::from(j));
        let h = |i, j| f64::from(tile.height_at(i, j));
        let s = h(i, j) * (1.0 - fu) + h(i + 1, j) * fu;
        let n = h(i, j + 1) * (1.0 - fu) + h(i + 1, j + 1) * fu;
        s * (1.0 - fv) + n * fv
    }

    /// Makes tile `id` and the ancestors it needs, where not stored, from their parents (kept
    /// for the next lookups).
    fn derive(&self, id: TileId) {
        if self.tiles.contains_key(&id) || self.derived.borrow().contains_key(&id) {
            return;
        }
        let parent = id.parent().expect("a stored ancestor");
        self.derive(parent);
        let manifest = &self.world.manifest;
        let params = verdant::stream::DeriveParams::for_manifest(manifest);
        let tile = {
            let derived = self.derived.borrow();
            let parent = self.tiles.get(&parent).unwrap_or_else(|| &derived[&parent]);
            verdant::stream::derive_child(&manifest.pyramid, parent, id, &params)
        };
        self.derived.borrow_mut().insert(id, tile);
    }

    /// Clearance of the camera above the terrain (the finest stored level) at `samples` points
    /// per key interval along `path`, with positions interpolated linearly between keys.
    pub fn clearances(&self, path: &CameraPath, samples: usize) -> Vec<f64> {
        clearances(path, samples, |p| self.height(p))
    }

    /// [`Terrain::clearances`] above the ground drawn near the camera
    /// ([`Terrain::drawn_height`]).
    pub fn drawn_clearances(&self, path: &CameraPath, samples: usize) -> Vec<f64> {
        clearances(path, samples, |p| self.drawn_height(p))
    }
}

/// Clearance of the camera above `ground` at `samples` points per key interval along `path`.
fn clearances(path: &CameraPath, samples: usize, ground: impl Fn(DVec2) -> f64) -> Vec<f64> {
    let mut out = Vec::new();
    for w in path.keys.windows(2) {
        let (a, b) = (w[0].position_m, w[1].position_m);
        for s in 0..samples {
            let t = s as f64 / samples as f64;
            let p: [f64; 3] = std::array::from_fn(|k| a[k] + (b[k] - a[k]) * t);
            out.push(p[2] - ground(DVec2::new(p[0], p[1])));
        }
    }
    out
}

/// A tiny deterministic random generator (xorshift64*).
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in 0..1.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A copy of the default world (manifest and tiles) in `dir/world`, for tests that damage it.
pub fn world_copy(dir: &Path) -> PathBuf {
    let w = dir.join("world");
    std::fs::create_dir_all(&w).unwrap();
    std::fs::copy(default_world().join("world.toml"), w.join("world.toml")).unwrap();
    copy_dir(&default_world().join("tiles"), &w.join("tiles"));
    w
}

/// A copy of the default world in `dir` with a camera path `away` that stands 40 km out of it,
/// looking further away: no frame of it draws terrain.
pub fn world_with_a_path_away(dir: &Path) -> PathBuf {
    let world = world_copy(dir);
    let toml = world.join("world.toml");
    let mut text = std::fs::read_to_string(&toml).unwrap();
    text.push_str(
        "\n[[paths]]\nname = \"away\"\nduration_s = 2.0\n\
         [[paths.keys]]\nt_s = 0.0\nposition_m = [-40000.0, -40000.0, 300.0]\nyaw_deg = 225.0\npitch_deg = 0.0\n\
         [[paths.keys]]\nt_s = 2.0\nposition_m = [-40010.0, -40010.0, 300.0]\nyaw_deg = 225.0\npitch_deg = 0.0\n",
    );
    std::fs::write(&toml, text).unwrap();
    world
}

/// The command failed with status 1, without a panic, and its stderr names every needle.
pub fn assert_fails_naming(out: &std::process::Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "expected failure, stderr: {stderr}");
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "panicked: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr should mention {n:?}: {stderr}");
    }
}

/// Runs the `verdant` binary with `args` in `cwd`.
pub fn verdant(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run verdant")
}

/// A small plant: two crossed quads 1 m high, coloured, with Crysis' channels.
pub fn small_plant() -> verdant::plants::PlantMesh {
    let mut vertices = Vec::new();
    let mut indices = Vec::new();
    for (k, (dx, dy)) in [(1.0f32, 0.0f32), (0.0, 1.0)].into_iter().enumerate() {
        let base = vertices.len() as u32;
        for (x, z, u, v) in [
            (-0.3, 0.0, 0.0, 1.0),
            (0.3, 0.0, 1.0, 1.0),
            (0.3, 1.0, 1.0, 0.0),
            (-0.3, 1.0, 0.0, 0.0),
        ] {
            vertices.push(verdant::plants::PlantVertex {
                position: [x * dx, x * dy, z],
                normal: [dy, -dx, 0.0],
                wind: [0.5, 0.25 * k as f32, z, 0.5 + 0.5 * z],
                albedo: [0.9, 0.8, 0.1, 0.5],
                uv: [u, v],
            });
        }
        indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    verdant::plants::PlantMesh { vertices, indices }
}

/// `small_plant()` with its triangles' indices replaced by `indices` (which may draw nothing).
pub fn small_plant_indexed(indices: &[u32]) -> verdant::plants::PlantMesh {
    verdant::plants::PlantMesh {
        indices: indices.to_vec(),
        ..small_plant()
    }
}

/// `small_plant()` with each vertex's position mapped by `f`.
pub fn small_plant_moved(f: impl Fn([f32; 3]) -> [f32; 3]) -> verdant::plants::PlantMesh {
    let mut mesh = small_plant();
    for v in &mut mesh.vertices {
        v.position = f(v.position);
    }
    mesh
}

/// Plant meshes that a glTF file holds and that would draw nothing, or nothing sane: the file's
/// name, the mesh, and a word of the reason the plant type is refused for.
pub fn undrawable_plants() -> Vec<(&'static str, verdant::plants::PlantMesh, &'static str)> {
    vec![
        // A TRIANGLES primitive of two indices: no triangle.
        (
            "two_indices.gltf",
            small_plant_indexed(&[0, 1]),
            "no triangles",
        ),
        // Every triangle's corners on one or two vertices.
        (
            "degenerate.gltf",
            small_plant_indexed(&[0, 0, 0, 1, 1, 1, 2, 2, 3]),
            "degenerate (zero area)",
        ),
        // 2e-6 high and 1e33 wide: past f32's range once scaled to unit height.
        (
            "overflowing.gltf",
            small_plant_moved(|[x, y, z]| [x / 0.3 * 1e33, y, z * 2e-6]),
            "not finite",
        ),
        // 1 m high and 2e6 m wide.
        (
            "wide.gltf",
            small_plant_moved(|[x, y, z]| [x * 1e6 / 0.3, y, z]),
            "times its height",
        ),
    ]
}

/// A plant at the loader's limits: 65,536 vertices and 130,050 triangles ([`dome_plant`] of
/// 256).
pub fn heavy_plant() -> verdant::plants::PlantMesh {
    dome_plant(256)
}

/// A dome 1 m high of `n` x `n` vertices, 2 (n - 1)^2 triangles.
pub fn dome_plant(n: u32) -> verdant::plants::PlantMesh {
    let mut vertices = Vec::with_capacity((n * n) as usize);
    for j in 0..n {
        let z = j as f32 / (n - 1) as f32;
        let r = 0.05 + 0.35 * (std::f32::consts::PI * z).sin();
        for i in 0..n {
            let a = std::f32::consts::TAU * i as f32 / (n - 1) as f32;
            vertices.push(verdant::plants::PlantVertex {
                position: [r * a.cos(), r * a.sin(), z],
                normal: [a.cos(), a.sin(), 0.0],
                wind: [0.5, 0.0, z, 1.0],
                albedo: [0.2, 0.5, 0.1, 0.5],
                uv: [i as f32 / (n - 1) as f32, 1.0 - z],
            });
        }
    }
    let mut indices = Vec::with_capacity(((n - 1) * (n - 1) * 6) as usize);
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            let (b, c, d) = (a + 1, a + n + 1, a + n);
            indices.extend([a, b, c, a, c, d]);
        }
    }
    verdant::plants::PlantMesh { vertices, indices }
}

/// The default world with its plant types replaced by one glTF plant `mesh` on the meadow.
pub fn world_with_plant(dir: &Path, mesh: &str) -> std::path::PathBuf {
    let w = world_copy(dir);
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    let start = manifest
        .find("[[plant_types]]")
        .expect("the world has plants");
    let end = manifest.find("[wind]").expect("a wind table");
    let plant = format!(
        "[[plant_types]]\nname = \"marigold\"\nmesh = \"{mesh}\"\nsize_m = [0.4, 0.6]\n\
         density = {{ meadow = 1.5, \"tall grass\" = 1.5, \"dry grass\" = 1.5 }}\n\n"
    );
    let edited = format!("{}{plant}{}", &manifest[..start], &manifest[end..]);
    std::fs::write(w.join("world.toml"), edited).unwrap();
    w
}

/// A copy of the default world in `dir` whose only plant type is a tree of `mesh` (a recipe),
/// 8-12 m tall, at `density` trees per square metre on every grass type but bare.
pub fn world_with_trees(dir: &Path, mesh: &str, density: f32) -> std::path::PathBuf {
    let w = world_with_plant(dir, mesh);
    let manifest = std::fs::read_to_string(w.join("world.toml")).unwrap();
    let trees = manifest
        .replace("size_m = [0.4, 0.6]", "size_m = [8.0, 12.0]")
        .replace(
            "density = { meadow = 1.5, \"tall grass\" = 1.5, \"dry grass\" = 1.5 }",
            &format!(
                "density = {{ meadow = {density}, \"tall grass\" = {density}, \"dry grass\" = {density} }}"
            ),
        );
    assert_ne!(manifest, trees, "the tree's size and density are set");
    std::fs::write(w.join("world.toml"), trees).unwrap();
    w
}

/// Every file under `dir`: its path relative to `dir`, and its bytes.
pub fn read_all_files(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let rel = path.strip_prefix(dir).unwrap().to_path_buf();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}

/// Makes a FIFO at `path` (`mkfifo`): a file that a reader opening it waits on for a writer.
#[cfg(unix)]
pub fn mkfifo(path: &Path) {
    let status = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("run mkfifo");
    assert!(status.success(), "mkfifo {}", path.display());
}

/// Sends SIGINT (Ctrl-C) to `child`.
pub fn send_sigint(child: &std::process::Child) {
    let kill = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
}
