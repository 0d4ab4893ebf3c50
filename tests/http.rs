//! Worlds streamed over HTTP: the same images as from the folder (from `verdant serve` and from
//! Python's `http.server`), every server fault counted once and survived, the bound on loads in
//! flight against a slow server, and the on-disk cache revalidated with ETags.

mod common;

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use verdant::camera::sample_path;
use verdant::stream::{
    HttpCacheConfig, HttpOptions, HttpSource, Loaded, ServiceConfig, StreamConfig, Streamer,
    TileService, TileSource, Want,
};
use verdant::tools::metrics::flip_compare;
use verdant::tools::serve::WorldServer;
use verdant::tools::{Scene, SceneConfig};
use verdant::world::{TileId, World};

/// Short deadlines keep the fault tests fast.
fn quick_options() -> HttpOptions {
    HttpOptions {
        timeout: Duration::from_secs(1),
        retries: 2,
        backoff: Duration::from_millis(10),
        cache: None,
    }
}

/// What the fault server does with one request (`path`, and how many times it was asked).
#[derive(Clone, Copy, Debug)]
enum Reply {
    /// The file, as it is.
    File,
    /// An error status, no body.
    Status(u16),
    /// Nothing until long past the client's deadline.
    Stall,
    /// The full Content-Length announced, half the body sent, the connection closed.
    Truncated,
    /// A 200 whose body is not an image.
    Garbage,
}

/// A hand-written HTTP/1.1 server over a world folder that injects faults, delays every
/// response and counts concurrent requests.
struct FaultServer {
    url: String,
    peak: Arc<AtomicUsize>,
    asked: Arc<Mutex<HashMap<String, u32>>>,
}

impl FaultServer {
    fn start(
        root: PathBuf,
        delay: Duration,
        reply: impl Fn(&str, u32) -> Reply + Send + Sync + 'static,
    ) -> FaultServer {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}/", listener.local_addr().unwrap());
        let peak = Arc::new(AtomicUsize::new(0));
        let now = Arc::new(AtomicUsize::new(0));
        let asked = Arc::new(Mutex::new(HashMap::new()));
        let reply = Arc::new(reply);
        let (p, a) = (Arc::clone(&peak), Arc::clone(&asked));
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(stream) = stream else { continue };
                let (root, now, peak, asked, reply) = (
                    root.clone(),
                    Arc::clone(&now),
                    Arc::clone(&p),
                    Arc::clone(&a),
                    Arc::clone(&reply),
                );
                std::thread::spawn(move || {
                    let counter = Concurrency {
                        now: &now,
                        peak: &peak,
                    };
                    let _ = answer(stream, &root, delay, &asked, reply.as_ref(), &counter);
                });
            }
        });
        FaultServer { url, peak, asked }
    }

    fn asked(&self, path: &str) -> u32 {
        self.asked.lock().unwrap().get(path).copied().unwrap_or(0)
    }
}

/// Requests being served at once: from a request's arrival (its head read) until its answer
/// starts, so that a client that has its answer and sends the next request is never counted
/// twice while the server closes the first connection.
struct Concurrency<'a> {
    now: &'a AtomicUsize,
    peak: &'a AtomicUsize,
}

fn answer(
    mut stream: TcpStream,
    root: &Path,
    delay: Duration,
    asked: &Mutex<HashMap<String, u32>>,
    reply: &(dyn Fn(&str, u32) -> Reply + Send + Sync),
    counter: &Concurrency<'_>,
) -> std::io::Result<()> {
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let path = line.split_whitespace().nth(1).unwrap_or("/").to_string();
    loop {
        let mut header = String::new();
        if reader.read_line(&mut header)? == 0 || header.trim().is_empty() {
            break;
        }
    }
    let n = {
        let mut asked = asked.lock().unwrap();
        let n = asked.entry(path.clone()).or_insert(0);
        *n += 1;
        *n
    };
    let running = counter.now.fetch_add(1, Ordering::SeqCst) + 1;
    counter.peak.fetch_max(running, Ordering::SeqCst);
    std::thread::sleep(delay);
    let body = std::fs::read(root.join(path.trim_start_matches('/')));
    counter.now.fetch_sub(1, Ordering::SeqCst);
    let head = |status: &str, len: usize| {
        format!("HTTP/1.1 {status}\r\nContent-Length: {len}\r\nConnection: close\r\n\r\n")
    };
    match (reply(&path, n), body) {
        (Reply::Status(code), _) => {
            stream.write_all(head(&format!("{code} Fault"), 0).as_bytes())?;
        }
        (Reply::Stall, _) => {
            std::thread::sleep(Duration::from_secs(4));
            stream.write_all(head("503 Too Late", 0).as_bytes())?;
        }
        (Reply::Garbage, _) => {
            let body = b"<html>this is not a tile</html>";
            stream.write_all(head("200 OK", body.len()).as_bytes())?;
            stream.write_all(body)?;
        }
        (_, Err(_)) => stream.write_all(head("404 Not Found", 0).as_bytes())?,
        (Reply::Truncated, Ok(body)) => {
            stream.write_all(head("200 OK", body.len()).as_bytes())?;
            stream.write_all(&body[..body.len() / 2])?;
        }
        (Reply::File, Ok(body)) => {
            stream.write_all(head("200 OK", body.len()).as_bytes())?;
            stream.write_all(&body)?;
        }
    }
    stream.flush()?;
    let _ = stream.shutdown(std::net::Shutdown::Both);
    Ok(())
}

/// Python's `http.server` on the default world; killed when dropped.
struct PythonServer {
    child: Child,
    url: String,
}

impl PythonServer {
    fn start(root: &Path) -> PythonServer {
        let found = Command::new("sh")
            .args(["-c", "command -v python3"])
            .output()
            .is_ok_and(|o| o.status.success());
        assert!(
            found,
            "python3 is not on PATH: this test serves the world with Python's http.server \
             (a server that verdant did not write); install python3"
        );
        let mut child = Command::new("python3")
            .args(["-u", "-m", "http.server", "0", "--bind", "127.0.0.1"])
            .arg("--directory")
            .arg(root)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start python3 -m http.server");
        // "Serving HTTP on 127.0.0.1 port 41234 (http://127.0.0.1:41234/) ..."
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let mut line = String::new();
        out.read_line(&mut line).unwrap();
        let url = line
            .split(['(', ')'])
            .find(|s| s.starts_with("http://"))
            .unwrap_or_else(|| panic!("no address in http.server's first line: {line:?}"))
            .to_string();
        PythonServer { child, url }
    }
}

impl Drop for PythonServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Renders `frames` frames along the world's first camera path, every tile loaded before each
/// frame, and returns the images.
fn fly(world: World, source: Arc<dyn TileSource>, frames: u32) -> Vec<image::RgbImage> {
    let ctx = common::gpu();
    let path = world.manifest.paths[0].clone();
    let config = SceneConfig::for_world(&world);
    let mut scene = Scene::with_source(&ctx, world, source, 96, 54, config).unwrap();
    let (t0, t1) = (path.keys[0].t_s, path.keys[path.keys.len() - 1].t_s);
    (0..frames)
        .map(|f| {
            let t = t0 + (t1 - t0) * f64::from(f) / f64::from(frames);
            let camera = sample_path(&path, t);
            assert!(
                scene
                    .warm_up(&ctx, &camera, Duration::from_secs(60))
                    .unwrap()
            );
            let stats = scene.render_at(&ctx, &camera, 1.0).unwrap();
            assert_eq!(stats.residency.holes, 0);
            image::DynamicImage::ImageRgba8(scene.read_image(&ctx).unwrap()).to_rgb8()
        })
        .collect()
}

fn assert_same_images(what: &str, reference: &[image::RgbImage], actual: &[image::RgbImage]) {
    assert_eq!(reference.len(), actual.len());
    for (f, (r, a)) in reference.iter().zip(actual).enumerate() {
        if r == a {
            continue;
        }
        let flip = flip_compare(r, a).unwrap();
        // The same tiles and the same frame on the same adapter: only GPU rounding may differ.
        assert!(
            flip.mean < 1e-3,
            "{what}, frame {f}: FLIP mean {} against the folder's image",
            flip.mean
        );
    }
}

#[test]
fn a_fly_through_over_http_renders_what_the_folder_renders() {
    let dir = common::default_world();
    let world = World::open(&dir).unwrap();
    let local = fly(world.clone(), Arc::new(world), 3);

    let ours = WorldServer::start(&dir, "127.0.0.1:0").unwrap();
    let (world, source) = HttpSource::open(&ours.url(), HttpOptions::default()).unwrap();
    assert_eq!(world.manifest, World::open(&dir).unwrap().manifest);
    let source = Arc::new(source);
    let images = fly(world, source.clone(), 3);
    assert!(source.stats().requests > 0 && source.stats().retries == 0);
    assert_same_images("verdant serve", &local, &images);

    let python = PythonServer::start(&dir);
    let (world, source) = HttpSource::open(&python.url, HttpOptions::default()).unwrap();
    let images = fly(world, Arc::new(source), 3);
    assert_same_images("python3 -m http.server", &local, &images);
}

/// Each kind of server fault is one counted fault (the tile is drawn from an ancestor, never a
/// hole), a 500 followed by success is retried and loads, and the loop never waits on the
/// server.
#[test]
fn server_faults_are_counted_once_and_leave_no_hole() {
    let not_found = TileId::new(2, 0, 0);
    let flaky = TileId::new(2, 1, 0);
    let stalled = TileId::new(2, 2, 0);
    let truncated = TileId::new(2, 3, 0);
    let garbage = TileId::new(1, 0, 0);
    let healthy = TileId::new(2, 0, 1);
    let server = FaultServer::start(
        common::default_world(),
        Duration::ZERO,
        |path, n| match path {
            "/tiles/L2/0_0.height.exr" => Reply::Status(404),
            "/tiles/L2/1_0.type.png" if n == 1 => Reply::Status(500),
            "/tiles/L2/2_0.density.png" => Reply::Stall,
            "/tiles/L2/3_0.height.exr" => Reply::Truncated,
            "/tiles/L1/0_0.type.png" => Reply::Garbage,
            _ => Reply::File,
        },
    );
    // A deadline long enough that no healthy request misses it while the tests beside this
    // one keep both cores busy rendering: only the stall may run into it.
    let options = HttpOptions {
        timeout: Duration::from_secs(4),
        ..quick_options()
    };
    let (world, source) = HttpSource::open(&server.url, options).unwrap();
    let source = Arc::new(source);
    let pyramid = world.manifest.pyramid.clone();
    let (mut service, _) =
        TileService::new(&pyramid, source.clone(), ServiceConfig::default()).unwrap();
    let wants: Vec<Want> = [not_found, flaky, stalled, truncated, garbage, healthy]
        .iter()
        .map(|&id| Want { id, priority: 1.0 })
        .collect();
    let start = Instant::now();
    loop {
        let frame = Instant::now();
        service.update(&wants);
        assert!(
            frame.elapsed() < Duration::from_millis(500),
            "a frame waited on the server"
        );
        let s = service.stats();
        assert_eq!(s.holes, 0, "a tile had nothing to draw it from");
        if s.faults == 4 && service.is_resident(flaky) && service.is_resident(healthy) {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "faults not seen: {s:?}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    for id in [not_found, stalled, truncated, garbage] {
        assert!(!service.is_resident(id));
        assert!(service.draw_source(id).unwrap().0.level < id.level);
    }
    // Asked again, the broken tiles are not fetched (or counted) again.
    for _ in 0..40 {
        service.update(&wants);
        std::thread::sleep(Duration::from_millis(2));
    }
    let s = service.stats();
    assert_eq!(s.faults, 4);
    assert_eq!(s.stream.failed, 4);
    // The 500 was retried once; the 404 and the non-tile were not retried; the body cut short
    // was tried 1 + 2 times; the stall was given up after its deadline, not retried.
    assert_eq!(server.asked("/tiles/L2/1_0.type.png"), 2);
    assert_eq!(server.asked("/tiles/L2/0_0.height.exr"), 1);
    assert_eq!(server.asked("/tiles/L1/0_0.type.png"), 1);
    assert_eq!(server.asked("/tiles/L2/3_0.height.exr"), 3);
    assert_eq!(server.asked("/tiles/L2/2_0.density.png"), 1);
    // Those three retries at least: a connection that this test server drops under load is a
    // transient failure too, and is retried like one.
    let retries = source.stats().retries;
    assert!(retries > 2, "{retries} retries");
}

/// The same faults on tiles all over the world, on the GPU: every frame draws without a hole
/// and the run finishes.
#[test]
fn a_flight_over_a_failing_server_draws_every_frame_without_a_hole() {
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |path, n| {
        if !path.starts_with("/tiles/L1") && !path.starts_with("/tiles/L2") {
            return Reply::File;
        }
        let h = path
            .bytes()
            .fold(7u32, |h, b| h.wrapping_mul(31) ^ u32::from(b));
        match h % 6 {
            0 => Reply::Status(404),
            1 if n == 1 => Reply::Status(500),
            2 => Reply::Stall,
            3 => Reply::Truncated,
            4 => Reply::Garbage,
            _ => Reply::File,
        }
    });
    let (world, source) = HttpSource::open(&server.url, quick_options()).unwrap();
    let ctx = common::gpu();
    let path = world.manifest.paths[0].clone();
    let mut config = SceneConfig::for_world(&world);
    config.grass = None;
    let mut scene = Scene::with_source(&ctx, world, Arc::new(source), 64, 36, config).unwrap();
    let start = Instant::now();
    for f in 0..30 {
        let t = path.keys[0].t_s + f64::from(f) * 0.5;
        let stats = scene.render_at(&ctx, &sample_path(&path, t), t).unwrap();
        assert_eq!(stats.residency.holes, 0, "frame {f} has a hole");
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(start.elapsed() < Duration::from_secs(60));
    let s = scene.service().stats();
    assert!(s.faults > 0, "no tile failed: {s:?}");
    assert_eq!(u64::from(s.faults), s.stream.failed);
}

#[test]
fn loads_in_flight_stay_within_the_bound_against_a_slow_server() {
    let server = FaultServer::start(
        common::default_world(),
        Duration::from_millis(100),
        |_, _| Reply::File,
    );
    let (world, source) = HttpSource::open(&server.url, quick_options()).unwrap();
    let config = StreamConfig {
        max_in_flight: 3,
        ..StreamConfig::default()
    };
    let mut streamer = Streamer::start(Arc::new(source), config).unwrap();
    let wants: Vec<Want> = world
        .stored_tiles()
        .filter(|id| id.level == 2)
        .take(12)
        .map(|id| Want {
            id,
            priority: id.x as f32,
        })
        .collect();
    streamer.want(wants.clone());
    let mut loaded = 0;
    let start = Instant::now();
    while loaded < wants.len() {
        for l in streamer.poll() {
            assert!(matches!(l, Loaded::Tile(_)), "{l:?}");
            loaded += 1;
        }
        assert!(streamer.stats().in_flight <= 3);
        assert!(start.elapsed() < Duration::from_secs(30), "loads stalled");
        std::thread::sleep(Duration::from_millis(5));
    }
    let peak = server.peak.load(Ordering::SeqCst);
    assert!(peak <= 3, "{peak} requests at once, bound 3");
    assert!(
        peak >= 2,
        "the loads never overlapped ({peak}): the bound was not exercised"
    );
}

#[test]
fn a_second_source_revalidates_its_disk_cache_with_etags() {
    let ours = WorldServer::start(&common::default_world(), "127.0.0.1:0").unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let options = HttpOptions {
        cache: Some(HttpCacheConfig {
            dir: tmp.path().join("cache"),
            max_bytes: 16 << 20,
        }),
        ..quick_options()
    };
    let id = TileId::new(2, 1, 1);
    let (_, first) = HttpSource::open(&ours.url(), options.clone()).unwrap();
    let tile = first.load(id).unwrap();
    assert_eq!(first.stats().cache_hits, 0);
    let (_, second) = HttpSource::open(&ours.url(), options).unwrap();
    assert_eq!(second.load(id).unwrap(), tile);
    // The manifest and the three files: each a 304 without a body.
    let s = second.stats();
    assert_eq!((s.cache_hits, s.bytes), (4, 0), "{s:?}");
    let local = World::open(&common::default_world()).unwrap();
    assert_eq!(local.load_tile(id).unwrap(), tile);
}

#[test]
fn the_server_answers_with_content_types_and_conditional_gets() {
    let ours = WorldServer::start(&common::default_world(), "127.0.0.1:0").unwrap();
    let get = |path: &str, extra: &str| -> (String, Vec<u8>) {
        let mut s = TcpStream::connect(ours.addr()).unwrap();
        write!(
            s,
            "GET {path} HTTP/1.1\r\nHost: x\r\n{extra}Connection: close\r\n\r\n"
        )
        .unwrap();
        let mut all = Vec::new();
        s.read_to_end(&mut all).unwrap();
        let split = all.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        (
            String::from_utf8_lossy(&all[..split]).into_owned(),
            all[split + 4..].to_vec(),
        )
    };
    let (head, body) = get("/world.toml", "");
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    assert!(head.contains("Content-Type: application/toml"), "{head}");
    assert_eq!(
        body,
        std::fs::read(common::default_world().join("world.toml")).unwrap()
    );
    let (head, _) = get("/tiles/L0/0_0.height.exr", "");
    assert!(head.contains("Content-Type: image/x-exr"), "{head}");
    let (head, _) = get("/tiles/L0/0_0.type.png", "");
    assert!(head.contains("Content-Type: image/png"), "{head}");
    let field = |name: &str| {
        head.lines()
            .find_map(|l| {
                let (k, v) = l.split_once(": ")?;
                k.eq_ignore_ascii_case(name).then(|| v.to_string())
            })
            .unwrap()
    };
    let (etag, modified) = (field("etag"), field("last-modified"));
    let (head, body) = get(
        "/tiles/L0/0_0.type.png",
        &format!("If-None-Match: {etag}\r\n"),
    );
    assert!(head.starts_with("HTTP/1.1 304"), "{head}");
    assert!(body.is_empty());
    let (head, _) = get(
        "/tiles/L0/0_0.type.png",
        &format!("If-Modified-Since: {modified}\r\n"),
    );
    assert!(head.starts_with("HTTP/1.1 304"), "{head}");
    let (head, _) = get("/tiles/L0/0_0.type.png", "If-None-Match: \"other\"\r\n");
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    for outside in ["/../Cargo.toml", "/tiles/../../Cargo.toml", "/nothing.png"] {
        let (head, _) = get(outside, "");
        assert!(head.starts_with("HTTP/1.1 404"), "{outside}: {head}");
    }
}

/// `verdant serve` in one process and `verdant fly http://...` in another, as the README says;
/// an address where nothing listens is refused with a message that names it.
#[test]
fn verdant_fly_flies_a_world_from_verdant_serve() {
    let bin = env!("CARGO_BIN_EXE_verdant");
    let mut serve = Command::new(bin)
        .args(["serve", "santa-cruz", "--addr", "127.0.0.1:0"])
        .current_dir(common::root())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(serve.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line.split_whitespace().last().unwrap_or("").to_string();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("fly");
    let fly = Command::new(bin)
        .args([
            "fly",
            &url,
            "--frames",
            "2",
            "--size",
            "64x36",
            "--http-timeout-s",
            "1",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let _ = serve.kill();
    let _ = serve.wait();
    assert!(
        fly.status.success(),
        "serve said {line:?}; fly: {}",
        String::from_utf8_lossy(&fly.stderr)
    );
    assert!(out.join("report.json").is_file() && out.join("frame_00001.png").is_file());

    let nowhere = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/world", nowhere.local_addr().unwrap());
    drop(nowhere);
    let fly = Command::new(bin)
        .args(["fly", &url, "--frames", "1", "--http-retries", "1"])
        .arg("--out")
        .arg(tmp.path().join("none"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&fly.stderr);
    assert!(!fly.status.success());
    assert!(
        stderr.contains(&format!("{url}/world.toml")) && stderr.contains("2 attempt(s)"),
        "{stderr}"
    );
}

/// A tile that leaves the wanted set while its files are being fetched sends no more requests:
/// its later files are never asked for, and it counts as cancelled, not failed.
#[test]
fn a_cancelled_tile_sends_no_more_requests() {
    let server = FaultServer::start(
        common::default_world(),
        Duration::from_millis(400),
        |_, _| Reply::File,
    );
    let (_, source) = HttpSource::open(&server.url, quick_options()).unwrap();
    let config = StreamConfig {
        max_in_flight: 2,
        ..StreamConfig::default()
    };
    let mut streamer = Streamer::start(Arc::new(source), config).unwrap();
    let want = |ids: &[TileId]| -> Vec<Want> {
        ids.iter().map(|&id| Want { id, priority: 1.0 }).collect()
    };
    let (dropped, kept) = (TileId::new(2, 5, 5), TileId::new(2, 6, 6));
    streamer.want(want(&[dropped]));
    // Its height file is on the way (400 ms); then it leaves the wanted set.
    let start = Instant::now();
    while server.asked("/tiles/L2/5_5.height.exr") == 0 {
        streamer.poll();
        assert!(start.elapsed() < Duration::from_secs(10), "never asked");
        std::thread::sleep(Duration::from_millis(5));
    }
    streamer.want(want(&[kept]));
    let mut got = Vec::new();
    while got.is_empty() || streamer.stats().in_flight > 0 {
        for l in streamer.poll() {
            match l {
                Loaded::Tile(t) => got.push(t.id),
                Loaded::Failed { id, error } => panic!("{id:?} failed: {error}"),
            }
        }
        assert!(start.elapsed() < Duration::from_secs(20), "loads stalled");
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(got, vec![kept]);
    let s = streamer.stats();
    assert_eq!((s.cancelled, s.failed, s.completed), (1, 0, 1), "{s:?}");
    assert_eq!(server.asked("/tiles/L2/5_5.type.png"), 0);
    assert_eq!(server.asked("/tiles/L2/5_5.density.png"), 0);
    assert_eq!(server.asked("/tiles/L2/6_6.density.png"), 1);
}
