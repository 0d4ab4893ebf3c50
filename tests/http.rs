//! Worlds streamed over HTTP: the same images as from the folder (from `verdant serve` and from
//! Python's `http.server`), every server fault counted once and survived, the bound on loads in
//! flight against a slow server, the on-disk cache revalidated with ETags and its damaged
//! entries fetched again, bodies bounded by the largest legal file, options and retries
//! bounded, redirects, and the fault-injecting proxy.

mod common;

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use verdant::RendererConfig;
use verdant::camera::sample_path;
use verdant::stream::http::MAX_TIMEOUT;
use verdant::stream::{
    HttpCacheConfig, HttpError, HttpOptions, HttpSource, Loaded, ServiceConfig, StreamConfig,
    Streamer, TileService, TileSource, Want,
};
use verdant::tools::Scene;
use verdant::tools::fault_proxy::{Fault, FaultProxy};
use verdant::tools::metrics::flip_compare;
use verdant::tools::serve::WorldServer;
use verdant::world::format::max_file_bytes;
use verdant::world::manifest::MAX_MANIFEST_BYTES;
use verdant::world::{TileFile, TileId, World};

/// [`quick_options`] with a disk cache of 16 MiB in `dir`.
fn cached_options(dir: &Path) -> HttpOptions {
    HttpOptions {
        cache: Some(HttpCacheConfig {
            dir: dir.to_path_buf(),
            max_bytes: 16 << 20,
        }),
        ..quick_options()
    }
}

/// Short deadlines keep the fault tests fast.
fn quick_options() -> HttpOptions {
    HttpOptions {
        timeout: Duration::from_secs(1),
        retries: 2,
        backoff: Duration::from_millis(10),
        ..HttpOptions::default()
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
    /// The connection closed without a word.
    Hangup,
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
        (Reply::Hangup, _) => {}
        (Reply::Status(code), _) => {
            stream.write_all(head(&format!("{code} Fault"), 0).as_bytes())?;
        }
        (Reply::Stall, _) => {
            // Long past any deadline a test sets (the thread is left to sleep it out).
            std::thread::sleep(Duration::from_secs(30));
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
    let config = RendererConfig::for_world(&world);
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
    // one keep both cores busy rendering: only the stall (which answers 30 s late) may run
    // into it. (With a 4 s stall and a 4 s deadline, a late answer under load was a 503 that
    // the client retried: extra failed loads.)
    let options = HttpOptions {
        timeout: Duration::from_secs(8),
        ..quick_options()
    };
    let (world, source) = HttpSource::open(&server.url, options).unwrap();
    let source = Arc::new(source);
    let pyramid = world.manifest.pyramid.clone();
    // The service tries a failed tile again after a while (5 s by default): later than this
    // test runs, so that each fault is loaded once here however long the stall takes.
    let config = ServiceConfig {
        fault_retry_s: 60.0,
        ..ServiceConfig::default()
    };
    let (mut service, _) = TileService::new(&pyramid, source.clone(), config).unwrap();
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
            start.elapsed() < Duration::from_secs(45),
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
    assert_eq!(s.stream.failed, 4, "{s:?}");
    // The 404 and the non-tile were not retried; the stall was given up after its deadline,
    // not retried; the 500 was retried (once) and the body cut short tried 1 + 2 times.
    assert_eq!(server.asked("/tiles/L2/0_0.height.exr"), 1);
    assert_eq!(server.asked("/tiles/L1/0_0.type.png"), 1);
    assert_eq!(server.asked("/tiles/L2/2_0.density.png"), 1);
    let flaky_asked = server.asked("/tiles/L2/1_0.type.png");
    let truncated_asked = server.asked("/tiles/L2/3_0.height.exr");
    assert!(flaky_asked >= 2 && truncated_asked >= 3);
    // Those three retries at least. Under load (the tests beside this one keep both cores
    // busy) a connection that this test server drops or answers late is retried too, or the
    // tile is asked again after its first load was given up: every request the server saw is
    // one the client counted.
    let stats = source.stats();
    assert!(
        stats.retries >= 3,
        "{} retries for {flaky_asked} and {truncated_asked} requests",
        stats.retries
    );
    assert!(
        stats.requests >= u64::from(flaky_asked + truncated_asked) + 3,
        "the client counted {} requests; the server saw {flaky_asked} + {truncated_asked} on \
         the retried paths and 3 on the others",
        stats.requests
    );
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
    let mut config = RendererConfig::for_world(&world);
    config.grass_rings = None;
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
    // Each tile failed now failed at least once; a failed tile is loaded again after its wait
    // (5 s, longer than the first failures take here), so a tile may have failed more than once.
    assert!(u64::from(s.faults) <= s.stream.failed, "{s:?}");
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

/// The server sends a file from disk as it goes, never whole into memory: a HEAD of a 16 GiB
/// (sparse) file answers its length at once, and a range of it its bytes; a percent-encoded
/// name is decoded (`my%20plants/`), and `%2e%2e` is still `..`, refused. A world whose
/// manifest is not a regular file, or leads out of the folder, is refused at the start.
#[test]
fn the_server_streams_files_decodes_names_and_checks_its_world_at_the_start() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("files");
    std::fs::create_dir_all(root.join("my plants")).unwrap();
    std::fs::write(root.join("my plants/fern one.txt"), "a fern").unwrap();
    let huge = std::fs::File::create(root.join("huge.bin")).unwrap();
    huge.set_len(16 << 30).unwrap();
    drop(huge);
    let server = WorldServer::start_folder(&root, "127.0.0.1:0").unwrap();
    let ask = |request: String| -> (String, Vec<u8>) {
        let mut s = TcpStream::connect(server.addr()).unwrap();
        s.write_all(request.as_bytes()).unwrap();
        let mut all = Vec::new();
        s.read_to_end(&mut all).unwrap();
        let split = all.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        (
            String::from_utf8_lossy(&all[..split]).into_owned(),
            all[split + 4..].to_vec(),
        )
    };
    let start = Instant::now();
    let (head, body) =
        ask("HEAD /huge.bin HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".into());
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    assert!(head.contains("Content-Length: 17179869184"), "{head}");
    assert!(body.is_empty());
    let (head, body) = ask(
        "GET /huge.bin HTTP/1.1\r\nHost: x\r\nRange: bytes=17179869180-\r\nConnection: close\r\n\r\n"
            .into(),
    );
    assert!(head.starts_with("HTTP/1.1 206"), "{head}");
    assert_eq!(body, [0; 4]);
    assert!(
        start.elapsed() < Duration::from_secs(10),
        "{:?}",
        start.elapsed()
    );
    let get = |path: &str| {
        ask(format!(
            "GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
        ))
    };
    let (head, body) = get("/my%20plants/fern%20one.txt");
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    assert_eq!(body, b"a fern");
    for refused in [
        "/%2e%2e/files/huge.bin",
        "/my%20plants/%2E%2E/huge.bin",
        "/a%00b",
        "/%ff",
    ] {
        let (head, _) = get(refused);
        assert!(head.starts_with("HTTP/1.1 404"), "{refused}: {head}");
    }

    // A manifest that is a folder, or a symlink out of the world: refused before serving.
    let w = dir.path().join("w");
    std::fs::create_dir_all(w.join("world.toml")).unwrap();
    let err = WorldServer::start(&w, "127.0.0.1:0")
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("not a regular file"), "{err}");
    std::fs::remove_dir(w.join("world.toml")).unwrap();
    std::fs::write(dir.path().join("elsewhere.toml"), "name = \"x\"").unwrap();
    std::os::unix::fs::symlink(dir.path().join("elsewhere.toml"), w.join("world.toml")).unwrap();
    let err = WorldServer::start(&w, "127.0.0.1:0")
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("a symlink out of the folder"), "{err}");
    // So is a level of its tiles linked out of it.
    std::fs::remove_file(w.join("world.toml")).unwrap();
    std::fs::write(w.join("world.toml"), "name = \"x\"").unwrap();
    std::fs::create_dir_all(w.join("tiles")).unwrap();
    std::fs::create_dir_all(dir.path().join("L2real")).unwrap();
    std::os::unix::fs::symlink(dir.path().join("L2real"), w.join("tiles/L2")).unwrap();
    let err = WorldServer::start(&w, "127.0.0.1:0")
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("tiles/L2: a symlink out of the folder"),
        "{err}"
    );
}

/// One request to `addr`, answered within 5 s: the answer's head and body.
fn ask_server(addr: std::net::SocketAddr, request: &str) -> (String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s.write_all(request.as_bytes()).unwrap();
    let mut all = Vec::new();
    s.read_to_end(&mut all)
        .unwrap_or_else(|e| panic!("{request:?}: no answer: {e}"));
    let split = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .unwrap_or_else(|| panic!("{request:?}: answered {all:?}"));
    (
        String::from_utf8_lossy(&all[..split]).into_owned(),
        all[split + 4..].to_vec(),
    )
}

/// A file dated 1960, which an HTTP date cannot write, is served without a `Last-Modified` and with an `ETag` of its own, never a panic: asked 20 times (more than the
/// server has workers), it is answered every time, and so is another file after it.
#[test]
fn files_dated_before_1970_are_served_and_cost_no_worker() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let date = |name: &str, body: &str, t: std::time::SystemTime| {
        std::fs::write(root.join(name), body).unwrap();
        let f = std::fs::File::options()
            .write(true)
            .open(root.join(name))
            .unwrap();
        f.set_modified(t).unwrap();
    };
    let epoch = std::time::UNIX_EPOCH;
    date(
        "old.txt",
        "sixties",
        epoch - Duration::from_secs(315_619_200),
    );
    date(
        "older.txt",
        "fifties",
        epoch - Duration::from_secs(500_000_000),
    );
    std::fs::write(root.join("new.txt"), "today").unwrap();
    let server = WorldServer::start_folder(root, "127.0.0.1:0").unwrap();
    let get = |path: &str| {
        ask_server(
            server.addr(),
            &format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"),
        )
    };
    let etag = |head: &str| {
        head.lines()
            .find_map(|l| l.strip_prefix("ETag: "))
            .unwrap_or_else(|| panic!("no ETag: {head}"))
            .to_string()
    };
    for _ in 0..20 {
        let (head, body) = get("/old.txt");
        assert!(head.starts_with("HTTP/1.1 200"), "{head}");
        assert!(!head.contains("Last-Modified"), "{head}");
        assert_eq!(body, b"sixties");
    }
    let (old, _) = get("/old.txt");
    let (older, _) = get("/older.txt");
    assert_ne!(etag(&old), etag(&older), "two pre-1970 files of one length");
    // Revalidation by the tag still works for them; by a date, never.
    let (head, _) = ask_server(
        server.addr(),
        &format!(
            "GET /old.txt HTTP/1.1\r\nHost: x\r\nIf-None-Match: {}\r\n\r\n",
            etag(&old)
        ),
    );
    assert!(head.starts_with("HTTP/1.1 304"), "{head}");
    let (head, _) = ask_server(
        server.addr(),
        "GET /old.txt HTTP/1.1\r\nHost: x\r\nIf-Modified-Since: Sun, 06 Nov 1994 08:49:37 GMT\r\n\r\n",
    );
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    let (head, body) = get("/new.txt");
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    assert!(head.contains("Last-Modified: "), "{head}");
    assert_eq!(body, b"today");
}

/// `Range` as RFC 9110 has it: the unit in any case, another unit or several ranges answered
/// with the whole file (`200`), and only one well-formed range of bytes that misses the file
/// answered `416`.
#[test]
fn the_server_ignores_ranges_it_does_not_serve_and_refuses_only_those_past_the_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("ten.bin"), b"0123456789").unwrap();
    let server = WorldServer::start_folder(dir.path(), "127.0.0.1:0").unwrap();
    let range = |value: &str| {
        ask_server(
            server.addr(),
            &format!("GET /ten.bin HTTP/1.1\r\nHost: x\r\nRange: {value}\r\n\r\n"),
        )
    };
    let (head, body) = range("BYTES=0-1");
    assert!(head.starts_with("HTTP/1.1 206"), "{head}");
    assert!(head.contains("Content-Range: bytes 0-1/10"), "{head}");
    assert_eq!(body, b"01");
    for whole in ["items=0-1", "bytes=0-1,4-5", "bytes=x-y"] {
        let (head, body) = range(whole);
        assert!(head.starts_with("HTTP/1.1 200"), "{whole}: {head}");
        assert!(!head.contains("Content-Range"), "{whole}: {head}");
        assert_eq!(body, b"0123456789", "{whole}");
    }
    let (head, body) = range("bytes=10-");
    assert!(head.starts_with("HTTP/1.1 416"), "{head}");
    assert!(head.contains("Content-Range: bytes */10"), "{head}");
    assert!(body.is_empty());
}

/// What the server holds is bounded whatever its clients do: connections past its workers and
/// queue are answered `503` at once, a client that sends nothing or trickles its request is
/// closed when the head's time is up (and its place freed), a head past its bytes is answered
/// `431` without being read on, a request that is not HTTP `400`, and the server still answers
/// after all of it.
#[test]
fn the_server_holds_its_connections_and_request_heads_within_bounds() {
    use verdant::tools::serve::{MAX_HEAD_BYTES, ServeLimits, WORKERS};
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.txt"), "a").unwrap();
    let head_time = Duration::from_millis(1000);
    let queued = 8;
    let server = WorldServer::start_with(
        dir.path(),
        "127.0.0.1:0",
        ServeLimits {
            head: head_time,
            write: Duration::from_secs(2),
            queued,
        },
    )
    .unwrap();
    let read_all = |s: &mut TcpStream| -> String {
        s.set_nonblocking(false).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut all = Vec::new();
        let _ = s.read_to_end(&mut all);
        String::from_utf8_lossy(&all).into_owned()
    };
    let get = || {
        let mut s = TcpStream::connect(server.addr()).unwrap();
        s.write_all(b"GET /a.txt HTTP/1.1\r\nHost: x\r\n\r\n")
            .unwrap();
        read_all(&mut s)
    };
    assert!(get().starts_with("HTTP/1.1 200 OK"));

    // Idle connections: no more than the workers and the queue are held (which ones depends on
    // how fast the workers take theirs); the rest are turned away at once.
    let extra = 40;
    let mut conns: Vec<TcpStream> = (0..WORKERS + queued + extra)
        .map(|_| TcpStream::connect(server.addr()).unwrap())
        .collect();
    std::thread::sleep(head_time / 4);
    let (mut held, mut refused) = (Vec::new(), 0);
    for mut s in conns.drain(..) {
        s.set_nonblocking(true).unwrap();
        let mut first = [0u8; 64];
        match s.read(&mut first) {
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => held.push(s),
            Ok(n) => {
                let answer = String::from_utf8_lossy(&first[..n]).into_owned() + &read_all(&mut s);
                assert!(
                    answer.starts_with("HTTP/1.1 503 Service Unavailable")
                        && answer.contains("Retry-After: 1"),
                    "{answer}"
                );
                refused += 1;
            }
            Err(e) => panic!("{e}"),
        }
    }
    assert!(held.len() <= WORKERS + queued, "{} held", held.len());
    assert!(refused >= extra, "{refused} refused");
    // The held ones are closed when their time is up, counted from their accept: the queue's
    // with the workers' (not a head's time after them), and the server answers again.
    let start = Instant::now();
    for mut s in held {
        assert_eq!(read_all(&mut s), "", "an idle connection got an answer");
    }
    assert!(start.elapsed() < 2 * head_time, "{:?}", start.elapsed());
    assert!(get().starts_with("HTTP/1.1 200 OK"));

    // A client that trickles its head is closed when its time is up, however it trickles.
    let mut slow = TcpStream::connect(server.addr()).unwrap();
    let start = Instant::now();
    let closed = loop {
        if slow.write_all(b"G").is_err() || start.elapsed() > 4 * head_time {
            break start.elapsed();
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert!(closed <= 3 * head_time, "{closed:?}");

    // A head past its bytes: 431, the rest unread (a gigabyte would otherwise be read).
    let mut big = TcpStream::connect(server.addr()).unwrap();
    big.write_all(b"GET /a.txt HTTP/1.1\r\nX-Big: ").unwrap();
    let filler = vec![b'a'; MAX_HEAD_BYTES];
    let _ = big.write_all(&filler);
    let answer = read_all(&mut big);
    assert!(
        answer.starts_with("HTTP/1.1 431 Request Header Fields Too Large"),
        "{answer}"
    );
    // Too many header lines, and a request that is not HTTP.
    let mut many = TcpStream::connect(server.addr()).unwrap();
    let mut request = String::from("GET /a.txt HTTP/1.1\r\n");
    for i in 0..200 {
        request.push_str(&format!("X-{i}: a\r\n"));
    }
    request.push_str("\r\n");
    many.write_all(request.as_bytes()).unwrap();
    assert!(read_all(&mut many).starts_with("HTTP/1.1 431"));
    let mut junk = TcpStream::connect(server.addr()).unwrap();
    junk.write_all(b"\x16\x03\x01 hello\r\n\r\n").unwrap();
    assert!(read_all(&mut junk).starts_with("HTTP/1.1 400 Bad Request"));
    let mut post = TcpStream::connect(server.addr()).unwrap();
    post.write_all(b"POST /a.txt HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n\r\n")
        .unwrap();
    let answer = read_all(&mut post);
    assert!(
        answer.starts_with("HTTP/1.1 405") && answer.contains("Allow: GET, HEAD"),
        "{answer}"
    );
    assert!(get().starts_with("HTTP/1.1 200 OK"));
}

/// Requests as RFC 9112 has them: a target's query may hold anything (`?u=http://h/x` is not
/// an absolute target), an HTTP/1.1 request without a Host, a request with two and a target
/// that is neither a path nor absolute are 400, bytes past ASCII in a header's value are kept, and a Range under an
/// If-Range of another version is answered whole.
#[test]
fn the_server_reads_requests_as_rfc_9112_has_them() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.txt"), "0123456789").unwrap();
    std::fs::write(dir.path().join("world.toml"), "other").unwrap();
    let server = WorldServer::start_folder(dir.path(), "127.0.0.1:0").unwrap();
    let ask = |request: &[u8]| -> String {
        let mut s = TcpStream::connect(server.addr()).unwrap();
        s.write_all(request).unwrap();
        let mut all = Vec::new();
        let _ = s.read_to_end(&mut all);
        String::from_utf8_lossy(&all).into_owned()
    };
    let answer = ask(b"GET /a.txt?u=http://h/world.toml HTTP/1.1\r\nHost: x\r\n\r\n");
    assert!(
        answer.starts_with("HTTP/1.1 200") && answer.ends_with("0123456789"),
        "{answer}"
    );
    let answer = ask(b"GET http://x/a.txt HTTP/1.1\r\nHost: x\r\n\r\n");
    assert!(answer.ends_with("0123456789"), "{answer}");
    for bad in [
        &b"GET /a.txt HTTP/1.1\r\n\r\n"[..],
        b"GET a.txt HTTP/1.1\r\nHost: x\r\n\r\n",
        b"GET /a.txt HTTP/1.\r\nHost: x\r\n\r\n",
        // Two hosts (RFC 9112, 3.2), in either version.
        b"GET /a.txt HTTP/1.1\r\nHost: x\r\nHost: y\r\n\r\n",
        b"GET /a.txt HTTP/1.0\r\nHost: x\r\nhost: x\r\n\r\n",
    ] {
        let answer = ask(bad);
        assert!(
            answer.starts_with("HTTP/1.1 400"),
            "{}: {answer}",
            String::from_utf8_lossy(bad)
        );
    }
    assert!(ask(b"GET /a.txt HTTP/1.0\r\n\r\n").starts_with("HTTP/1.1 200"));
    let answer = ask(b"GET /a.txt HTTP/1.1\r\nHost: x\r\nX-Name: caf\xe9\r\n\r\n");
    assert!(answer.starts_with("HTTP/1.1 200"), "{answer}");
    // If-Range: the range of the version the client holds, else the whole file.
    let head = ask(b"HEAD /a.txt HTTP/1.1\r\nHost: x\r\n\r\n");
    let etag = head
        .lines()
        .find_map(|l| l.strip_prefix("ETag: "))
        .unwrap()
        .to_owned();
    let ranged = |if_range: &str| {
        ask(format!(
            "GET /a.txt HTTP/1.1\r\nHost: x\r\nRange: bytes=0-1\r\nIf-Range: {if_range}\r\n\r\n"
        )
        .as_bytes())
    };
    let answer = ranged(&etag);
    assert!(
        answer.starts_with("HTTP/1.1 206") && answer.ends_with("\r\n\r\n01"),
        "{answer}"
    );
    for other in [
        "\"stale\"",
        "Thu, 01 Jan 1998 00:00:00 GMT",
        &format!("W/{etag}"),
    ] {
        let answer = ranged(other);
        assert!(
            answer.starts_with("HTTP/1.1 200") && answer.ends_with("0123456789"),
            "{other}: {answer}"
        );
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

/// Socket buffers on the loopback interface: what a server may have written (into the kernel)
/// beyond what the client read before it hung up.
const SOCKET_SLACK: u64 = 16 << 20;

/// The most an endless body sends on one connection, so that a client that reads it all (as
/// the client once did) fails the test rather than the machine.
const ENDLESS_CAP: u64 = 64 << 20;

/// What a [`RawServer`] does with one request: `(path, connection, bytes served so far)`.
type Handler = dyn Fn(&str, &mut TcpStream, &AtomicU64) -> std::io::Result<()> + Send + Sync;

/// A hand-written HTTP/1.1 server whose every answer a handler writes; it counts requests,
/// body bytes written (into the socket) and connections finished.
struct RawServer {
    url: String,
    authority: String,
    asked: Arc<AtomicUsize>,
    served: Arc<AtomicU64>,
    finished: Arc<AtomicUsize>,
}

impl RawServer {
    fn start(
        handler: impl Fn(&str, &mut TcpStream, &AtomicU64) -> std::io::Result<()>
        + Send
        + Sync
        + 'static,
    ) -> RawServer {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let authority = listener.local_addr().unwrap().to_string();
        let (asked, served, finished) = (
            Arc::new(AtomicUsize::new(0)),
            Arc::new(AtomicU64::new(0)),
            Arc::new(AtomicUsize::new(0)),
        );
        let handler: Arc<Handler> = Arc::new(handler);
        let (a, s, f) = (asked.clone(), served.clone(), finished.clone());
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(mut stream) = stream else { continue };
                let (a, s, f, handler) = (a.clone(), s.clone(), f.clone(), handler.clone());
                std::thread::spawn(move || {
                    let mut reader = BufReader::new(stream.try_clone().unwrap());
                    let mut line = String::new();
                    let _ = reader.read_line(&mut line);
                    let path = line.split_whitespace().nth(1).unwrap_or("/").to_string();
                    loop {
                        let mut header = String::new();
                        match reader.read_line(&mut header) {
                            Ok(0) | Err(_) => break,
                            Ok(_) if header.trim().is_empty() => break,
                            Ok(_) => {}
                        }
                    }
                    a.fetch_add(1, Ordering::SeqCst);
                    let _ = handler(&path, &mut stream, &s);
                    let _ = stream.shutdown(std::net::Shutdown::Both);
                    f.fetch_add(1, Ordering::SeqCst);
                });
            }
        });
        RawServer {
            url: format!("http://{authority}/"),
            authority,
            asked,
            served,
            finished,
        }
    }

    /// Waits (up to 5 s) until `n` connections have been answered in all; whether they were.
    fn wait_finished(&self, n: usize) -> bool {
        let start = Instant::now();
        while self.finished.load(Ordering::SeqCst) < n {
            if start.elapsed() > Duration::from_secs(5) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        true
    }
}

/// Writes `head`, then body bytes (in chunks when `chunked`) until the client goes away or
/// [`ENDLESS_CAP`] bytes have been sent, counting them in `served`.
fn endless(
    stream: &mut TcpStream,
    head: &str,
    chunked: bool,
    served: &AtomicU64,
) -> std::io::Result<()> {
    stream.write_all(head.as_bytes())?;
    let block = vec![b'x'; 16 << 10];
    let mut sent = 0;
    while sent < ENDLESS_CAP {
        if chunked {
            write!(stream, "{:x}\r\n", block.len())?;
            stream.write_all(&block)?;
            stream.write_all(b"\r\n")?;
        } else {
            stream.write_all(&block)?;
        }
        sent += block.len() as u64;
        served.fetch_add(block.len() as u64, Ordering::SeqCst);
    }
    Ok(())
}

/// Answers with the default world's file at `path`, or 404.
fn world_file(stream: &mut TcpStream, path: &str) -> std::io::Result<()> {
    match std::fs::read(common::default_world().join(path.trim_start_matches('/'))) {
        Ok(body) => {
            write!(
                stream,
                "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                body.len()
            )?;
            stream.write_all(&body)
        }
        Err(_) => stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n"),
    }
}

/// A `world.toml` announced at 3 GiB is refused by its Content-Length: no body byte is kept, the
/// error names the URL, the size and the limit, and it is not retried.
#[test]
fn a_huge_content_length_is_refused_before_its_body_is_read() {
    let server = RawServer::start(|path, stream, served| match path {
        "/world.toml" => endless(
            stream,
            "HTTP/1.1 200 OK\r\nContent-Length: 3221225472\r\n\r\n",
            false,
            served,
        ),
        _ => world_file(stream, path),
    });
    // A deadline far past the bound below: failing fast is not the deadline at work.
    let options = HttpOptions {
        timeout: Duration::from_secs(20),
        ..quick_options()
    };
    let start = Instant::now();
    let e = HttpSource::open(&server.url, options)
        .unwrap_err()
        .to_string();
    assert!(
        start.elapsed() < Duration::from_secs(3),
        "{:?}",
        start.elapsed()
    );
    let url = format!("{}world.toml", server.url);
    assert!(
        e.contains(&url) && e.contains("3221225472") && e.contains(&MAX_MANIFEST_BYTES.to_string()),
        "{e}"
    );
    assert!(server.wait_finished(1), "the server is still sending");
    assert_eq!(server.asked.load(Ordering::SeqCst), 1, "retried");
    let served = server.served.load(Ordering::SeqCst);
    assert!(served < SOCKET_SLACK, "{served} bytes served");
}

/// Tile bodies without an honest size (announced huge, chunked without end, ended only by a
/// close that never comes) stop at the largest legal file for the world's tile size: the
/// client keeps at most that many bytes and the server is cut off soon after.
#[test]
fn tile_bodies_stop_at_the_largest_legal_tile_file() {
    let server = RawServer::start(|path, stream, served| match path {
        "/tiles/L2/0_0.height.exr" => endless(
            stream,
            "HTTP/1.1 200 OK\r\nContent-Length: 3221225472\r\n\r\n",
            false,
            served,
        ),
        "/tiles/L2/1_0.height.exr" => endless(
            stream,
            "HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n",
            true,
            served,
        ),
        "/tiles/L2/2_0.height.exr" => endless(
            stream,
            "HTTP/1.1 200 OK\r\nConnection: close\r\n\r\n",
            false,
            served,
        ),
        _ => world_file(stream, path),
    });
    let options = HttpOptions {
        timeout: Duration::from_secs(20),
        ..quick_options()
    };
    let (world, source) = HttpSource::open(&server.url, options).unwrap();
    let max = max_file_bytes(TileFile::Height, world.manifest.pyramid.samples_per_side());
    // The default world's 133-sample tiles: 2 * 133² * 4 bytes + 64 KiB.
    assert_eq!(max, 207_048);
    for (x, announced) in [(0, true), (1, false), (2, false)] {
        let id = TileId::new(2, x, 0);
        let url = source.tile_url(id, TileFile::Height);
        let (bytes, served, finished) = (
            source.stats().bytes,
            server.served.load(Ordering::SeqCst),
            server.finished.load(Ordering::SeqCst),
        );
        let start = Instant::now();
        let e = source.load(id).unwrap_err().to_string();
        assert!(
            start.elapsed() < Duration::from_secs(3),
            "{url}: {:?}",
            start.elapsed()
        );
        assert!(e.contains(&url) && e.contains(&max.to_string()), "{e}");
        let kept = source.stats().bytes - bytes;
        if announced {
            assert!(e.contains("Content-Length of 3221225472 bytes"), "{e}");
            assert_eq!(kept, 0, "{url}");
        } else {
            assert!(e.contains("body longer than"), "{e}");
            assert!(kept <= max + 1, "{url}: {kept} bytes read, limit {max}");
        }
        assert!(server.wait_finished(finished + 1), "{url}: still sending");
        let served = server.served.load(Ordering::SeqCst) - served;
        assert!(served < max + SOCKET_SLACK, "{url}: {served} bytes served");
    }
}

/// `HttpOptions` is public: a timeout of any length is refused with the range, never a panic
/// (the deadline is added to an `Instant`).
#[test]
fn a_timeout_of_any_length_is_refused_not_a_panic() {
    let ours = WorldServer::start(&common::default_world(), "127.0.0.1:0").unwrap();
    for timeout in [
        Duration::MAX,
        Duration::from_secs(u64::MAX),
        MAX_TIMEOUT + Duration::from_millis(1),
    ] {
        let options = HttpOptions {
            timeout,
            ..quick_options()
        };
        let e = HttpSource::open(&ours.url(), options)
            .unwrap_err()
            .to_string();
        assert!(e.contains("timeout") && e.contains("1..=3600 s"), "{e}");
    }
    let options = HttpOptions {
        timeout: MAX_TIMEOUT,
        backoff: Duration::MAX,
        ..quick_options()
    };
    HttpSource::open(&ours.url(), options).unwrap();
}

/// The cache's files per URL: `(body, metadata)`.
fn cache_entries(dir: &Path) -> HashMap<String, (PathBuf, PathBuf)> {
    let mut entries = HashMap::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let meta = entry.unwrap().path();
        if meta.extension().is_some_and(|e| e == "meta") {
            let text = std::fs::read_to_string(&meta).unwrap();
            let url = text.lines().next().unwrap().to_string();
            entries.insert(url, (meta.with_extension("body"), meta));
        }
    }
    entries
}

/// A cached `world.toml` or tile file whose body was damaged, or whose metadata was, is not
/// reused: the next open fetches it again in full, succeeds, and rewrites the entry.
#[test]
fn a_damaged_cache_entry_is_fetched_again_and_rewritten() {
    let dir = common::default_world();
    let ours = WorldServer::start(&dir, "127.0.0.1:0").unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let options = cached_options(&cache);
    let id = TileId::new(2, 1, 1);
    let local = World::open(&dir).unwrap();
    let (_, first) = HttpSource::open(&ours.url(), options.clone()).unwrap();
    first.load(id).unwrap();
    let manifest_url = format!("{}world.toml", ours.url());
    let height_url = first.tile_url(id, TileFile::Height);
    let entries = cache_entries(&cache);
    let (manifest_body, manifest_meta) = entries[&manifest_url].clone();
    let (height_body, _) = entries[&height_url].clone();
    let manifest = std::fs::read(dir.join("world.toml")).unwrap();
    let height = std::fs::read(local.tile_path(id, TileFile::Height)).unwrap();
    assert_eq!(std::fs::read(&manifest_body).unwrap(), manifest);

    // Bodies damaged in place, their length kept: not UTF-8, and a flipped sample.
    let mut bad = manifest.clone();
    bad[0] = 0xff;
    std::fs::write(&manifest_body, &bad).unwrap();
    let mut bad = height.clone();
    let mid = bad.len() / 2;
    bad[mid] ^= 0x55;
    std::fs::write(&height_body, &bad).unwrap();
    let (world, second) = HttpSource::open(&ours.url(), options.clone()).unwrap();
    assert_eq!(world.manifest, local.manifest);
    assert_eq!(second.load(id).unwrap(), local.load_tile(id).unwrap());
    // Only the type and density files were revalidated; the two damaged were fetched whole.
    let s = second.stats();
    assert_eq!(s.cache_hits, 2, "{s:?}");
    assert_eq!(std::fs::read(&manifest_body).unwrap(), manifest);
    assert_eq!(std::fs::read(&height_body).unwrap(), height);

    // Metadata damaged: torn.
    let meta = std::fs::read(&manifest_meta).unwrap();
    std::fs::write(&manifest_meta, &meta[..meta.len() / 2]).unwrap();
    let (world, third) = HttpSource::open(&ours.url(), options.clone()).unwrap();
    assert_eq!(world.manifest, local.manifest);
    assert_eq!(third.stats().cache_hits, 0);
    assert_eq!(
        std::fs::read(&manifest_meta).unwrap(),
        meta,
        "not rewritten"
    );
    // Whole again: the next open revalidates it.
    let (_, fourth) = HttpSource::open(&ours.url(), options).unwrap();
    assert_eq!((fourth.stats().cache_hits, fourth.stats().bytes), (1, 0));
}

/// Thirty retries against a server that always answers 500 end within the capped schedule's
/// sum (each wait at most `backoff_max`), after exactly 31 requests.
#[test]
fn many_retries_against_a_failing_server_end_within_their_bound() {
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |_, _| {
        Reply::Status(500)
    });
    let options = HttpOptions {
        retries: 30,
        backoff: Duration::from_millis(5),
        backoff_max: Duration::from_millis(20),
        ..quick_options()
    };
    let waits: Duration = (1..=30).map(|r| options.retry_delay(r)).sum();
    assert_eq!(waits, Duration::from_millis(5 + 10 + 28 * 20));
    let start = Instant::now();
    let e = HttpSource::open(&server.url, options)
        .unwrap_err()
        .to_string();
    let took = start.elapsed();
    assert!(e.contains("HTTP 500") && e.contains("31 attempt(s)"), "{e}");
    assert_eq!(server.asked("/world.toml"), 31);
    assert!(took >= waits, "{took:?}: the retries did not wait");
    assert!(took < waits + Duration::from_secs(5), "{took:?}");
}

/// A server that sends no `ETag` or `Last-Modified` cannot have its files revalidated: the
/// disk cache keeps none of them, and says so once, naming the server.
#[test]
fn a_server_without_validators_is_not_cached_and_it_is_said_once() {
    let logs = warnings();
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |_, _| Reply::File);
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let options = cached_options(&cache);
    let (_, source) = HttpSource::open(&server.url, options).unwrap();
    source.load(TileId::new(2, 1, 1)).unwrap();
    assert_eq!(std::fs::read_dir(&cache).unwrap().count(), 0);
    let said: Vec<String> = logs
        .lock()
        .unwrap()
        .iter()
        .filter(|l| l.contains(&server.url) && l.contains("without an ETag or Last-Modified"))
        .cloned()
        .collect();
    assert_eq!(said.len(), 1, "{said:?}");
}

/// A server that hangs up without a reply is retried, and reported as that, not as an HTTP
/// status (a client library once stood a "503" in for a missing status line).
#[test]
fn a_server_that_hangs_up_is_reported_as_one() {
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |_, _| {
        Reply::Hangup
    });
    let e = HttpSource::open(&server.url, quick_options())
        .unwrap_err()
        .to_string();
    assert!(
        // (`HTTP 503`: the port in the address may hold the digits 503.)
        e.contains("without an HTTP reply")
            && e.contains("3 attempt(s)")
            && !e.contains("HTTP 503"),
        "{e}"
    );
    assert_eq!(server.asked("/world.toml"), 3);
}

/// `verdant fly` says on stderr what it retries, why and when.
#[test]
fn retries_are_announced_on_stderr() {
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |_, _| {
        Reply::Status(500)
    });
    let tmp = tempfile::tempdir().unwrap();
    let start = Instant::now();
    let fly = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["fly", &server.url, "--frames", "1", "--http-retries", "2"])
        .arg("--out")
        .arg(tmp.path().join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&fly.stderr);
    assert!(!fly.status.success(), "{stderr}");
    let url = format!("{}world.toml", server.url);
    // The status's standard reason, not the server's own words for it ("Fault"): the client
    // keeps only the code, and a client is to ignore the reason phrase (RFC 9112 4).
    for line in [
        format!(
            "{url}: HTTP 500 Internal Server Error (after 1 attempt(s)); retry 1 of 2 in 0.2 s"
        ),
        format!(
            "{url}: HTTP 500 Internal Server Error (after 2 attempt(s)); retry 2 of 2 in 0.4 s"
        ),
    ] {
        assert!(stderr.contains(&line), "no {line:?} in:\n{stderr}");
    }
    assert!(stderr.contains("3 attempt(s)"), "{stderr}");
    assert!(start.elapsed() < Duration::from_secs(30));
}

/// Warnings logged in this test binary (installed on first use).
fn warnings() -> &'static Mutex<Vec<String>> {
    struct Capture;
    static LOGS: Mutex<Vec<String>> = Mutex::new(Vec::new());
    static CAPTURE: Capture = Capture;
    impl log::Log for Capture {
        fn enabled(&self, m: &log::Metadata) -> bool {
            m.level() <= log::Level::Warn
        }
        fn log(&self, r: &log::Record) {
            if self.enabled(r.metadata()) {
                LOGS.lock().unwrap().push(r.args().to_string());
            }
        }
        fn flush(&self) {}
    }
    static INSTALL: std::sync::Once = std::sync::Once::new();
    INSTALL.call_once(|| {
        log::set_logger(&CAPTURE).unwrap();
        log::set_max_level(log::LevelFilter::Warn);
    });
    &LOGS
}

/// A world whose files redirect to another host opens, with one warning naming both hosts;
/// a server that redirects without end is given up after five redirects, not retried.
#[test]
fn redirects_are_bounded_and_a_move_to_another_host_is_warned() {
    let logs = warnings();
    let target = WorldServer::start(&common::default_world(), "127.0.0.1:0").unwrap();
    let moved = format!("localhost:{}", target.addr().port());
    let to = moved.clone();
    let server = RawServer::start(move |path, stream, _| {
        write!(
            stream,
            "HTTP/1.1 302 Found\r\nLocation: http://{to}{path}\r\nContent-Length: 0\r\n\r\n"
        )
    });
    let (world, source) = HttpSource::open(&server.url, quick_options()).unwrap();
    let local = World::open(&common::default_world()).unwrap();
    assert_eq!(world.manifest, local.manifest);
    let id = TileId::new(2, 3, 1);
    assert_eq!(source.load(id).unwrap(), local.load_tile(id).unwrap());
    assert_eq!(server.asked.load(Ordering::SeqCst), 4);
    let said: Vec<String> = logs
        .lock()
        .unwrap()
        .iter()
        .filter(|l| l.contains(&server.authority))
        .cloned()
        .collect();
    assert_eq!(said.len(), 1, "{said:?}");
    assert!(said[0].contains(&format!("host {moved}")), "{said:?}");

    // Its byte counter counts the redirects instead, so that each names a new URL.
    let endless = RawServer::start(|_, stream, count| {
        let n = count.fetch_add(1, Ordering::SeqCst);
        write!(
            stream,
            "HTTP/1.1 302 Found\r\nLocation: /world.toml?{n}\r\nContent-Length: 0\r\n\r\n"
        )
    });
    let e = HttpSource::open(&endless.url, quick_options())
        .unwrap_err()
        .to_string();
    assert!(e.contains("world.toml") && e.contains("at most 5"), "{e}");
    assert_eq!(endless.asked.load(Ordering::SeqCst), 6, "{e}");
}

/// A world's address with a query (a signed URL's token) and a fragment, its scheme in upper
/// case: every file's name goes onto the path, the query after it on every request, and the
/// fragment nowhere.
#[test]
fn file_names_go_onto_the_path_and_every_request_keeps_the_query() {
    let asked = Arc::new(Mutex::new(Vec::<String>::new()));
    let a = asked.clone();
    let server = RawServer::start(move |target, stream, _| {
        a.lock().unwrap().push(target.to_string());
        match target
            .strip_suffix("?sig=A%2Fb&x=1")
            .and_then(|p| p.strip_prefix("/Worlds/W/"))
        {
            Some(name) => world_file(stream, name),
            None => stream.write_all(b"HTTP/1.1 403 Forbidden\r\nContent-Length: 0\r\n\r\n"),
        }
    });
    let url = format!("HTTP://{}/Worlds/W?sig=A%2Fb&x=1#view", server.authority);
    let (world, source) = HttpSource::open(&url, quick_options()).unwrap();
    let local = World::open(&common::default_world()).unwrap();
    assert_eq!(world.manifest, local.manifest);
    let id = TileId::new(0, 0, 0);
    assert_eq!(source.load(id).unwrap(), local.load_tile(id).unwrap());
    let name = Path::new("tiles/L0/0_0.type.png");
    assert_eq!(
        source.read_file(name, 1 << 20).unwrap(),
        std::fs::read(common::default_world().join(name)).unwrap()
    );
    let asked = asked.lock().unwrap().clone();
    assert_eq!(asked[0], "/Worlds/W/world.toml?sig=A%2Fb&x=1", "{asked:?}");
    assert_eq!(
        asked[1], "/Worlds/W/tiles/L0/0_0.height.exr?sig=A%2Fb&x=1",
        "{asked:?}"
    );
    assert_eq!(asked.len(), 5, "{asked:?}");
    assert!(
        asked
            .iter()
            .all(|t| t.starts_with("/Worlds/W/") && t.ends_with("?sig=A%2Fb&x=1")),
        "{asked:?}"
    );
    assert_eq!(
        source.base_url(),
        format!("http://{}/Worlds/W/", server.authority)
    );
}

/// Through the proxy at rate 0, every file passes unchanged: from a server under a path (the
/// world at `/santa-cruz/`), with `Last-Modified` revalidation (a `304`) through it.
#[test]
fn the_fault_proxy_at_rate_zero_passes_everything_through() {
    let python = PythonServer::start(&common::root().join("worlds"));
    let upstream = format!("{}santa-cruz/", python.url);
    let proxy = FaultProxy::start(&upstream, 0.0, 1).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let options = HttpOptions {
        cache: Some(HttpCacheConfig {
            dir: tmp.path().join("cache"),
            max_bytes: 16 << 20,
        }),
        ..quick_options()
    };
    let local = World::open(&common::default_world()).unwrap();
    let ids: Vec<TileId> = local.stored_tiles().take(6).collect();
    let (world, source) = HttpSource::open(&proxy.url(), options.clone()).unwrap();
    assert_eq!(world.manifest, local.manifest);
    for &id in &ids {
        assert_eq!(source.load(id).unwrap(), local.load_tile(id).unwrap());
    }
    let (_, again) = HttpSource::open(&proxy.url(), options).unwrap();
    assert_eq!(
        again.load(ids[0]).unwrap(),
        local.load_tile(ids[0]).unwrap()
    );
    assert_eq!((again.stats().cache_hits, again.stats().bytes), (4, 0));
    let c = proxy.counts();
    let requests = 2 * (1 + 3) + 3 * (ids.len() as u64 - 1);
    assert_eq!(
        (c.requests, c.passed, c.faults()),
        (requests, requests, 0),
        "{c:?}"
    );
}

/// A soak with faults of a world over HTTP where no server listens reports what a soak without
/// faults does: the user's address and the connection refused, not the fault proxy's `502` at
/// an address of its own.
#[test]
fn a_soak_with_faults_reports_the_worlds_address_and_its_real_error() {
    let nowhere = TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/", nowhere.local_addr().unwrap());
    drop(nowhere);
    let tmp = tempfile::tempdir().unwrap();
    let soak = |faults| {
        let options = verdant::tools::SoakOptions {
            world: PathBuf::from(&url),
            http: HttpOptions {
                retries: 0,
                ..quick_options()
            },
            out: tmp.path().join(format!("soak-{faults}")),
            faults,
            ..Default::default()
        };
        format!(
            "{:#}",
            verdant::tools::run_soak(&options, &mut |_, _| {}).unwrap_err()
        )
    };
    let (without, with) = (soak(0.0), soak(0.2));
    assert!(
        without.contains(&format!("{url}world.toml")) && without.contains("refused"),
        "{without}"
    );
    assert_eq!(with, without);
}

/// The proxy keeps the query of the world's address (a signed URL's token) on every request it
/// passes upstream.
#[test]
fn the_fault_proxy_keeps_the_query_of_the_worlds_address() {
    let asked = Arc::new(Mutex::new(Vec::<String>::new()));
    let a = asked.clone();
    let server = RawServer::start(move |target, stream, _| {
        a.lock().unwrap().push(target.to_string());
        match target.strip_suffix("?sig=1") {
            Some(name) => world_file(stream, name.trim_start_matches("/w/")),
            None => stream.write_all(b"HTTP/1.1 403 Forbidden\r\nContent-Length: 0\r\n\r\n"),
        }
    });
    let proxy = FaultProxy::start(&format!("{}w?sig=1", server.url), 0.0, 1).unwrap();
    let (world, _) = HttpSource::open(&proxy.url(), quick_options()).unwrap();
    assert_eq!(
        world.manifest,
        World::open(&common::default_world()).unwrap().manifest
    );
    assert_eq!(*asked.lock().unwrap(), ["/w/world.toml?sig=1"]);
}

/// The fault a client error is, by its typed error.
fn fault_of(e: &verdant::world::WorldError) -> Fault {
    let verdant::world::WorldError::Fetch(inner) = e else {
        panic!("not a fetch error: {e}");
    };
    match inner.downcast_ref::<HttpError>() {
        Some(HttpError::Status { status: 500, .. }) => Fault::Status500,
        Some(HttpError::Status {
            status: 503,
            reason,
            ..
        }) if reason == "Service Unavailable" => Fault::Status503,
        Some(HttpError::TimedOut { .. }) => Fault::Stall,
        Some(HttpError::Transport { .. }) => Fault::Reset,
        Some(HttpError::Truncated { .. }) => Fault::ShortBody,
        _ => panic!("not an injected fault: {e}"),
    }
}

/// At rate 1 every tile request faults and the manifest does not (the world opens); the client
/// turns each kind of fault into its own error, as many of each as the proxy counted, and none
/// waits past its deadline.
#[test]
fn every_tile_request_faults_at_rate_one_each_kind_a_named_error() {
    let ours = WorldServer::start(&common::default_world(), "127.0.0.1:0").unwrap();
    let proxy = FaultProxy::start(&ours.url(), 1.0, 5).unwrap();
    let options = HttpOptions {
        timeout: Duration::from_secs(2),
        retries: 0,
        ..quick_options()
    };
    let (world, source) = HttpSource::open(&proxy.url(), options).unwrap();
    assert_eq!(
        world.manifest,
        World::open(&common::default_world()).unwrap().manifest
    );
    let ids: Vec<TileId> = world
        .stored_tiles()
        .filter(|id| id.level == 2)
        .take(20)
        .collect();
    let results: Vec<(Fault, Duration)> = std::thread::scope(|s| {
        let handles: Vec<_> = ids
            .iter()
            .map(|&id| {
                let source = &source;
                s.spawn(move || {
                    let start = Instant::now();
                    let e = source.load(id).unwrap_err();
                    (fault_of(&e), start.elapsed())
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let c = proxy.counts();
    assert_eq!(c.requests, 1 + ids.len() as u64, "{c:?}");
    assert_eq!((c.passed, c.faults()), (1, ids.len() as u64), "{c:?}");
    for kind in Fault::ALL {
        let seen = results.iter().filter(|(f, _)| *f == kind).count() as u64;
        assert!(seen > 0, "no {kind:?} among {} faults: {c:?}", ids.len());
        assert_eq!(seen, c.of(kind), "{kind:?}: {c:?}");
    }
    let slowest = results.iter().map(|(_, t)| *t).max().unwrap();
    assert!(
        slowest < Duration::from_secs(4),
        "{slowest:?} past the 2 s deadline"
    );
    // Stopping the proxy does not wait on its stalls.
    let start = Instant::now();
    drop(proxy);
    assert!(start.elapsed() < Duration::from_secs(2));
}

/// A ranged read sets aside no more than it asked for, and little of that before the bytes
/// come: a server that claims a file of 16 EiB and answers a read of 8 EiB with a matching
/// `Content-Length`, then a few bytes, is a body cut short (the client once reserved the whole
/// `Content-Length` at once: a panic here, an abort for one a little smaller, and memory
/// promised away for one smaller still). A reply longer than asked is refused.
#[test]
fn a_ranged_read_allocates_no_more_than_it_asked_for() {
    use verdant::stream::http::RangeFile;
    const CLAIMED: u64 = u64::MAX;
    const HUGE: u64 = 1 << 63;
    let reads = Arc::new(Mutex::new(HashMap::<String, u32>::new()));
    let server = RawServer::start(move |path, stream, _| {
        let nth = {
            let mut reads = reads.lock().unwrap();
            let n = reads.entry(path.to_string()).or_insert(0);
            *n += 1;
            *n
        };
        if nth == 1 {
            // RangeFile::open asks for the first byte, to learn the length: the length every
            // later answer gives (a file whose length changes between answers is refused as
            // changed, before its body is looked at).
            let total = if path == "/huge" { CLAIMED } else { 100 };
            return write!(
                stream,
                "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-0/{total}\r\n\
                 Content-Length: 1\r\n\r\nx"
            );
        }
        match path {
            "/huge" => {
                write!(
                    stream,
                    "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-{}/{CLAIMED}\r\n\
                     Content-Length: {HUGE}\r\n\r\n",
                    HUGE - 1
                )?;
                stream.write_all(&[7; 1000])
            }
            "/long" => stream.write_all(
                b"HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-9/100\r\n\
                  Content-Length: 20\r\n\r\n01234567890123456789",
            ),
            _ => stream.write_all(
                b"HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-9/100\r\n\
                  Connection: close\r\n\r\n01234567890123456789",
            ),
        }
    });
    let options = HttpOptions {
        retries: 0,
        ..quick_options()
    };
    let huge = RangeFile::open(&format!("{}huge", server.url), options.clone()).unwrap();
    assert_eq!(huge.len(), CLAIMED);
    let e = huge.read_at(0, HUGE).unwrap_err().to_string();
    assert!(e.contains("huge") && e.contains("cut short"), "{e}");
    for longer in ["long", "unsized"] {
        let file = RangeFile::open(&format!("{}{longer}", server.url), options.clone()).unwrap();
        let e = file.read_at(0, 10).unwrap_err().to_string();
        assert!(
            e.contains(longer) && e.contains("more than the 10")
                || e.contains("longer than the 10"),
            "{longer}: {e}"
        );
    }
}

/// A chunked body whose connection closes mid-chunk is a body cut short, retried like one (the
/// client once took the part it had for the whole file).
#[test]
fn a_chunked_body_cut_short_is_retried() {
    let cut = Arc::new(AtomicUsize::new(0));
    let c = cut.clone();
    let server = RawServer::start(move |path, stream, _| {
        if path == "/tiles/L2/1_2.height.exr" && c.fetch_add(1, Ordering::SeqCst) == 0 {
            let body = std::fs::read(common::default_world().join(&path[1..]))?;
            write!(
                stream,
                "HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n{:x}\r\n",
                body.len()
            )?;
            return stream.write_all(&body[..body.len() / 2]);
        }
        world_file(stream, path)
    });
    let (_, source) = HttpSource::open(&server.url, quick_options()).unwrap();
    let id = TileId::new(2, 1, 2);
    let local = World::open(&common::default_world()).unwrap();
    assert_eq!(source.load(id).unwrap(), local.load_tile(id).unwrap());
    assert_eq!(cut.load(Ordering::SeqCst), 2, "cut once, then asked again");
    assert_eq!(source.stats().retries, 1);
}

/// Ctrl-C while `verdant fly` waits for the first frame's tiles from a server that does not
/// answer ends the run at once with its report (no frames, interrupted, status 130), instead of
/// after the warm-up's minute.
#[test]
fn an_interrupted_warm_up_ends_the_fly_at_once() {
    let (tmp, stderr) = interrupted_in_warm_up(&[]);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("out/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["interrupted"], true);
    assert_eq!(report["frames_flown"], 0);
    assert!(
        stderr.contains("interrupted: stopped before the first frame"),
        "{stderr}"
    );
}

/// The same for `verdant fly --truth`, which waited out the warm-up's minute and then failed
/// for the tiles that had not come.
#[test]
fn an_interrupted_warm_up_ends_the_truth_at_once() {
    let (tmp, stderr) = interrupted_in_warm_up(&["--truth", "2"]);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("out/truth.json")).unwrap()).unwrap();
    assert_eq!(report["interrupted"], true);
    assert_eq!(report["frames"].as_array().map(Vec::len), Some(0));
    assert!(
        stderr.contains("interrupted: stopped after 0 of 3 frames"),
        "{stderr}"
    );
}

/// Runs `verdant fly` with `args` over a server whose finer tiles stall, sends SIGINT once the
/// first frame's warm-up waits for one, and checks that the run ended within seconds with
/// status 130 and no panic; returns the temporary folder holding its output folder `out`, and
/// its stderr.
fn interrupted_in_warm_up(args: &[&str]) -> (tempfile::TempDir, String) {
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |path, _| {
        // The level-0 tiles are loaded with the world; the finer ones are the warm-up's.
        if path.starts_with("/tiles/") && !path.starts_with("/tiles/L0/") {
            Reply::Stall
        } else {
            Reply::File
        }
    });
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["fly", &server.url, "--frames", "3", "--size", "16x9"])
        .args(args)
        .arg("--out")
        .arg(&out)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    // Read stderr on a thread: the warm-up's line says the run is waiting for tiles.
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.contains("loading the first frame's tiles") {
                let _ = tx.send(());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    if rx.recv_timeout(Duration::from_secs(120)).is_err() {
        let _ = child.kill();
        panic!("no warm-up within 120 s:\n{}", reader.join().unwrap());
    }
    // A tile request out and stalled: the warm-up is waiting.
    let asked = Instant::now();
    let stalled = |p: &String| p.starts_with("/tiles/") && !p.starts_with("/tiles/L0/");
    while !server.asked.lock().unwrap().keys().any(stalled) {
        assert!(
            asked.elapsed() < Duration::from_secs(60),
            "no tile asked for"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let stopped = Instant::now();
    common::send_sigint(&child);
    let status = child.wait().unwrap();
    let took = stopped.elapsed();
    let stderr = reader.join().unwrap();
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // The tiles stall for 30 s and the warm-up waits up to 60: the stop must not wait for them.
    assert!(took < Duration::from_secs(15), "{took:?}\n{stderr}");
    (tmp, stderr)
}

/// A window the user flies waits for its first frame's tiles only briefly (it waited up to 30 s,
/// not answering, while a slow server sent them): it opens on the tiles that have come, saying
/// how many are still loading.
#[test]
fn the_viewer_opens_its_window_while_a_slow_servers_tiles_load() {
    use std::os::unix::process::CommandExt;
    let server = FaultServer::start(common::default_world(), Duration::ZERO, |path, _| {
        if path.starts_with("/tiles/") && !path.starts_with("/tiles/L0/") {
            Reply::Stall
        } else {
            Reply::File
        }
    });
    let mut child = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 320x240x24"])
        .arg(env!("CARGO_BIN_EXE_verdant"))
        .args(["view", &server.url, "--size", "64x36"])
        .env("RUST_LOG", "verdant=info")
        .process_group(0)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("xvfb-run is needed for the viewer's test (Debian package xvfb)");
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.contains("still loading") {
                let _ = tx.send(());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    // The tiles stall for 30 s, and the old wait was as long: the window must open well before.
    let started = Instant::now();
    let opened = rx.recv_timeout(Duration::from_secs(20));
    let took = started.elapsed();
    let stalled = server
        .asked
        .lock()
        .unwrap()
        .keys()
        .any(|p| p.starts_with("/tiles/") && !p.starts_with("/tiles/L0/"));
    // The whole group: xvfb-run, its X server and the viewer.
    let kill = Command::new("kill")
        .args(["-TERM", "--", &format!("-{}", child.id())])
        .status()
        .unwrap();
    assert!(kill.success());
    let _ = child.wait();
    let stderr = reader.join().unwrap();
    assert!(opened.is_ok(), "no window after {took:?}:\n{stderr}");
    assert!(stalled, "no finer tile was asked for:\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("of the first frame's tiles still loading; they stream in as it draws"),
        "{stderr}"
    );
}

/// Runs `f` on a thread of its own and returns what it returns, failing the test if it takes
/// longer than `limit` (the thread is left behind: a hang must fail the test, not stall it).
fn within<T: Send + 'static>(
    what: &str,
    limit: Duration,
    f: impl FnOnce() -> T + Send + 'static,
) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("{what}: no end within {limit:?}"))
}

/// A cache entry's metadata that is not a regular file (a FIFO, whose opening would wait for a
/// writer for ever, holding the cache's lock) is a damaged entry: dropped, and its file
/// fetched again at once, for the manifest as for a tile's file; the entry is written anew as a
/// regular file.
#[test]
fn a_fifo_in_the_cache_is_dropped_not_opened() {
    let dir = common::default_world();
    let ours = WorldServer::start(&dir, "127.0.0.1:0").unwrap();
    let url = ours.url();
    let tmp = tempfile::tempdir().unwrap();
    let cache = tmp.path().join("cache");
    let options = cached_options(&cache);
    let id = TileId::new(2, 1, 1);
    let local = World::open(&dir).unwrap();
    let (_, first) = HttpSource::open(&url, options.clone()).unwrap();
    first.load(id).unwrap();
    let entries = cache_entries(&cache);
    let manifest_meta = entries[&format!("{url}world.toml")].1.clone();
    let height_meta = entries[&first.tile_url(id, TileFile::Height)].1.clone();
    drop(first);

    // The manifest's metadata a FIFO: the world opens, the manifest fetched again in full.
    std::fs::remove_file(&manifest_meta).unwrap();
    common::mkfifo(&manifest_meta);
    let (u, o) = (url.clone(), options.clone());
    let (world, source) = within("an open over a FIFO", Duration::from_secs(20), move || {
        HttpSource::open(&u, o).unwrap()
    });
    assert_eq!(world.manifest, local.manifest);
    assert_eq!(source.stats().cache_hits, 0);
    assert!(std::fs::symlink_metadata(&manifest_meta).unwrap().is_file());

    // A tile's: the tile loads, its height file fetched again, the two others revalidated.
    std::fs::remove_file(&height_meta).unwrap();
    common::mkfifo(&height_meta);
    let source = Arc::new(source);
    let s = Arc::clone(&source);
    let tile = within("a tile over a FIFO", Duration::from_secs(20), move || {
        s.load(id).unwrap()
    });
    assert_eq!(tile, local.load_tile(id).unwrap());
    assert_eq!(source.stats().cache_hits, 2, "{:?}", source.stats());
    assert!(std::fs::symlink_metadata(&height_meta).unwrap().is_file());
}

/// A burst of idle connections delays the next client by about one head's time at most: a
/// connection's time counts from its accept, not from when a worker takes it, so the idle ones
/// queued behind the workers' are closed at once when a worker reaches them, and a request that
/// has come meanwhile is answered (here 44 idle connections; counted from the worker, the
/// client would wait six heads' times).
#[test]
fn idle_connections_delay_others_by_at_most_one_head_time() {
    use verdant::tools::serve::{ServeLimits, WORKERS};
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.txt"), "a").unwrap();
    let head = Duration::from_millis(800);
    let queued = 40;
    let server = WorldServer::start_with(
        dir.path(),
        "127.0.0.1:0",
        ServeLimits {
            head,
            write: Duration::from_secs(2),
            queued,
        },
    )
    .unwrap();
    let _idle: Vec<TcpStream> = (0..WORKERS + queued - 4)
        .map(|_| TcpStream::connect(server.addr()).unwrap())
        .collect();
    // The workers take theirs; the rest wait in the queue, which has room for one more.
    std::thread::sleep(Duration::from_millis(100));
    let start = Instant::now();
    let mut s = TcpStream::connect(server.addr()).unwrap();
    s.write_all(b"GET /a.txt HTTP/1.0\r\n\r\n").unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut answer = Vec::new();
    let _ = s.read_to_end(&mut answer);
    let took = start.elapsed();
    let answer = String::from_utf8_lossy(&answer);
    assert!(
        answer.starts_with("HTTP/1.1 200") && answer.ends_with("\r\n\r\na"),
        "{answer}"
    );
    assert!(took < 2 * head, "answered after {took:?}");
}

/// A `503` with `Retry-After` (as `verdant serve` sends when its queue is full) is retried
/// after the wait the server asks for rather than the shorter backoff, never longer than the
/// client's longest wait between retries (`backoff_max`).
#[test]
fn a_503_is_retried_after_the_wait_the_server_asks_for() {
    let times = Arc::new(Mutex::new(Vec::<Instant>::new()));
    let t = Arc::clone(&times);
    let server = RawServer::start(move |path, stream, count| {
        t.lock().unwrap().push(Instant::now());
        match count.fetch_add(1, Ordering::SeqCst) {
            0 => stream.write_all(
                b"HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\nContent-Length: 0\r\n\r\n",
            ),
            1 => stream.write_all(
                b"HTTP/1.1 503 Service Unavailable\r\nRetry-After: 3600\r\nContent-Length: 0\r\n\r\n",
            ),
            _ => world_file(stream, path),
        }
    });
    let options = HttpOptions {
        backoff: Duration::from_millis(10),
        backoff_max: Duration::from_millis(1500),
        ..quick_options()
    };
    let (world, _) = HttpSource::open(&server.url, options).unwrap();
    assert_eq!(
        world.manifest.name,
        World::open(&common::default_world()).unwrap().manifest.name
    );
    let times = times.lock().unwrap().clone();
    assert_eq!(times.len(), 3);
    let (first, second) = (times[1] - times[0], times[2] - times[1]);
    assert!(
        first >= Duration::from_secs(1) && first < Duration::from_millis(1400),
        "asked to wait 1 s, waited {first:?}"
    );
    assert!(
        second >= Duration::from_millis(1500) && second < Duration::from_millis(2200),
        "asked to wait an hour, waited {second:?} (the most is 1.5 s)"
    );
}

/// A world's address with spaces and characters past ASCII in its path and query is sent
/// percent-encoded, as its file names are; `%XX` escapes already in it are kept as they are,
/// and a `%` that starts none is encoded.
#[test]
fn an_address_with_spaces_and_non_ascii_is_sent_percent_encoded() {
    let asked = Arc::new(Mutex::new(Vec::<String>::new()));
    let a = asked.clone();
    let folder = "/a%20b/w%C3%B6rld%20x%20%F0%9F%8C%B2/";
    let server = RawServer::start(move |target, stream, _| {
        a.lock().unwrap().push(target.to_string());
        match target
            .strip_suffix("?t=a%20b")
            .and_then(|p| p.strip_prefix(folder))
        {
            Some(name) => world_file(stream, name),
            None => stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n"),
        }
    });
    let local = World::open(&common::default_world()).unwrap();
    let id = TileId::new(0, 0, 0);
    for url in [
        format!("http://{}/a b/wörld x 🌲/?t=a b", server.authority),
        format!("http://{}{folder}?t=a%20b", server.authority),
        format!("http://{}/a%20b/wörld%20x 🌲?t=a b", server.authority),
    ] {
        asked.lock().unwrap().clear();
        let (world, source) = HttpSource::open(&url, quick_options())
            .unwrap_or_else(|e| panic!("{url}: {e}; asked {:?}", asked.lock().unwrap()));
        assert_eq!(world.manifest, local.manifest, "{url}");
        assert_eq!(
            source.load(id).unwrap(),
            local.load_tile(id).unwrap(),
            "{url}"
        );
        assert_eq!(
            source.base_url(),
            format!("http://{}{folder}", server.authority)
        );
        let asked = asked.lock().unwrap().clone();
        assert_eq!(asked[0], format!("{folder}world.toml?t=a%20b"), "{url}");
    }
    asked.lock().unwrap().clear();
    let _ = HttpSource::open(
        &format!("http://{}/100%/", server.authority),
        quick_options(),
    );
    assert_eq!(asked.lock().unwrap()[0], "/100%25/world.toml");
}

/// Two common ways of writing a world's address: naming its `world.toml`, and with dot
/// segments (`./`, `tiles/../`). Each is read as the world's folder (dot segments removed as
/// RFC 3986 5.2.4 has it), and the server removes them from a request's path too, never above
/// its root: a path that climbs out of it, or `%2e%2e` (a name, not a segment), is still 404.
#[test]
fn an_address_naming_world_toml_or_with_dot_segments_is_the_worlds_folder() {
    let dir = common::default_world();
    let ours = WorldServer::start(&dir, "127.0.0.1:0").unwrap();
    let base = ours.url();
    let local = World::open(&dir).unwrap();
    for url in [
        format!("{base}world.toml"),
        format!("{base}./"),
        format!("{base}./world.toml?x=1"),
        format!("{base}tiles/../"),
        format!("{base}tiles/L0/./../.."),
    ] {
        let (world, source) =
            HttpSource::open(&url, quick_options()).unwrap_or_else(|e| panic!("{url}: {e}"));
        assert_eq!(world.manifest, local.manifest, "{url}");
        assert_eq!(source.base_url(), base, "{url}");
    }
    for (path, status) in [
        ("/./world.toml", "200"),
        ("/tiles/L0/../../world.toml", "200"),
        ("/tiles/./L0/0_0.type.png", "200"),
        ("/tiles/L0/..", "404"),
        ("/../world.toml", "404"),
        ("/tiles/../../world.toml", "404"),
        ("/tiles/%2e%2e/world.toml", "404"),
        // A file's path with a slash after it names a folder, not the file.
        ("/world.toml/", "404"),
        ("/world.toml/.", "404"),
        ("/tiles/L0/0_0.type.png/x/..", "404"),
        ("/tiles/L0/0_0.type.png/", "404"),
    ] {
        let (head, _) = ask_server(
            ours.addr(),
            &format!("GET {path} HTTP/1.1\r\nHost: x\r\n\r\n"),
        );
        assert!(
            head.starts_with(&format!("HTTP/1.1 {status}")),
            "{path}: {head}"
        );
    }
}

/// The address `verdant serve` gives is one a client can fetch: listening on every IPv4
/// address it is 127.0.0.1's, on every IPv6 address ::1's, and the world is fetched there,
/// never from "localhost" (which reaches 127.0.0.1, where nothing may listen).
#[test]
fn the_servers_address_is_one_a_client_can_fetch() {
    let dir = common::default_world();
    let any = WorldServer::start(&dir, "0.0.0.0:0").unwrap();
    assert_eq!(
        any.url(),
        format!("http://127.0.0.1:{}/", any.addr().port())
    );
    let (world, _) = HttpSource::open(&any.url(), quick_options()).unwrap();
    assert_eq!(world.manifest, World::open(&dir).unwrap().manifest);
    // Where the machine has IPv6 (this test asks nothing of it where not).
    if TcpListener::bind("[::1]:0").is_ok() {
        for addr in ["[::1]:0", "[::]:0"] {
            let six = WorldServer::start(&dir, addr).unwrap();
            let port = six.addr().port();
            assert_eq!(six.url(), format!("http://[::1]:{port}/"), "{addr}");
            let (world, _) = HttpSource::open(&six.url(), quick_options()).unwrap();
            assert_eq!(
                world.manifest,
                World::open(&dir).unwrap().manifest,
                "{addr}"
            );
        }
    }
}

/// The HTTP error under a world's error.
fn http_error(e: &verdant::world::WorldError) -> &HttpError {
    let verdant::world::WorldError::Fetch(inner) = e else {
        panic!("not a fetch error: {e}");
    };
    inner
        .downcast_ref::<HttpError>()
        .unwrap_or_else(|| panic!("not an HTTP error: {e}"))
}

/// A response head is capped at 64 KiB counted in bytes, whatever ends its lines: a header
/// line of 65,535 bytes ended by a bare LF (which once made the client's budget wrap to no
/// limit at all), then a header line without end, is refused as a head too large within
/// moments, not retried, and the server is cut off after little more than the cap (the
/// client kept no more: an unbounded one grows for as long as the server sends).
#[test]
fn a_head_past_64_kib_is_refused_whatever_ends_its_lines() {
    let server = RawServer::start(|path, stream, served| {
        let line = format!("X-Pad: {}", "a".repeat(65_535 - "X-Pad: ".len()));
        assert_eq!(line.len(), 65_535);
        let head = format!("HTTP/1.1 200 OK\r\n{line}\nX-Endless: ");
        match path {
            "/world.toml" => endless(stream, &head, false, served),
            _ => world_file(stream, path),
        }
    });
    let url = server.url.clone();
    let options = HttpOptions {
        timeout: Duration::from_secs(30),
        ..quick_options()
    };
    let start = Instant::now();
    let e = within("a head without end", Duration::from_secs(20), move || {
        HttpSource::open(&url, options).unwrap_err().to_string()
    });
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "{:?}: {e}",
        start.elapsed()
    );
    assert!(
        e.contains(&format!("{}world.toml", server.url))
            && e.contains("head")
            && e.contains("65536"),
        "{e}"
    );
    assert!(server.wait_finished(1), "the server is still sending");
    assert_eq!(server.asked.load(Ordering::SeqCst), 1, "retried: {e}");
    let served = server.served.load(Ordering::SeqCst);
    assert!(served < SOCKET_SLACK, "{served} bytes served");
}

/// Redirects resolve their `Location` against the URL that sent it, as RFC 3986 5.2 has it: a
/// relative name stays in the folder, `../..` climbs from it, `//host:port/...` keeps the
/// scheme and changes the host, `/path` keeps the host; each of 301, 302, 303, 307 and 308 is
/// followed, and the move to another host is warned of.
#[test]
fn relative_redirects_land_where_rfc_3986_puts_them() {
    let logs = warnings();
    let asked = Arc::new(Mutex::new(Vec::<String>::new()));
    let a = asked.clone();
    let second = RawServer::start(move |target, stream, _| {
        a.lock().unwrap().push(format!("second {target}"));
        match target {
            "/x/world.toml?t=1" => stream.write_all(
                b"HTTP/1.1 308 Permanent Redirect\r\nLocation: /real/./world.toml\r\n\
                  Content-Length: 0\r\n\r\n",
            ),
            "/real/world.toml" => world_file(stream, "/world.toml"),
            _ => stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n"),
        }
    });
    let other = second.authority.clone();
    let a = asked.clone();
    let first = RawServer::start(move |target, stream, _| {
        a.lock().unwrap().push(format!("first {target}"));
        let location = match target {
            "/a/b/world.toml" => "302 Found\r\nLocation: world2.toml".to_string(),
            "/a/b/world2.toml" => "301 Moved Permanently\r\nLocation: ../../w3/world.toml".into(),
            "/w3/world.toml" => "303 See Other\r\nLocation: ?v=2".into(),
            "/w3/world.toml?v=2" => {
                format!("307 Temporary Redirect\r\nLocation: //{other}/x/world.toml?t=1#f")
            }
            _ => return stream.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n"),
        };
        write!(
            stream,
            "HTTP/1.1 {location}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
        )
    });
    let (world, _) = HttpSource::open(&format!("{}a/b/", first.url), quick_options()).unwrap();
    assert_eq!(
        world.manifest,
        World::open(&common::default_world()).unwrap().manifest
    );
    assert_eq!(
        *asked.lock().unwrap(),
        [
            "first /a/b/world.toml",
            "first /a/b/world2.toml",
            "first /w3/world.toml",
            "first /w3/world.toml?v=2",
            "second /x/world.toml?t=1",
            "second /real/world.toml",
        ]
    );
    let said: Vec<String> = logs
        .lock()
        .unwrap()
        .iter()
        .filter(|l| l.contains(&first.authority) && l.contains(&second.authority))
        .cloned()
        .collect();
    assert_eq!(said.len(), 1, "{said:?}");
}

/// A reply cut off right after its status line (no headers' end, no body) is no reply: a
/// transport failure, retried like the others, never an empty file (which the manifest's
/// parser then called a TOML error).
#[test]
fn a_reply_cut_off_after_its_status_line_is_a_transport_failure() {
    let server = RawServer::start(|_, stream, _| stream.write_all(b"HTTP/1.1 200 OK\r\n"));
    let e = HttpSource::open(&server.url, quick_options()).unwrap_err();
    assert!(
        matches!(http_error(&e), HttpError::Transport { attempts: 3, .. }),
        "{e}"
    );
    let text = e.to_string();
    assert!(
        text.contains("closed the connection") && !text.contains("TOML"),
        "{text}"
    );
    assert_eq!(server.asked.load(Ordering::SeqCst), 3);
}

/// Two `Content-Length`s that differ make the body's length unknowable (RFC 9112 6.3): the
/// response is refused, not read by either, and not retried; two that agree are one.
#[test]
fn differing_content_lengths_are_refused() {
    let server = RawServer::start(|path, stream, _| match path {
        "/world.toml" => stream.write_all(
            b"HTTP/1.1 200 OK\r\nContent-Length: 5\r\nContent-Length: 7\r\n\r\nname=\"x\"",
        ),
        _ => world_file(stream, path),
    });
    let e = HttpSource::open(&server.url, quick_options()).unwrap_err();
    assert!(
        matches!(http_error(&e), HttpError::BadResponse { .. }),
        "{e}"
    );
    assert!(
        e.to_string()
            .to_ascii_lowercase()
            .contains("content-length"),
        "{e}"
    );
    assert_eq!(server.asked.load(Ordering::SeqCst), 1);

    let body = std::fs::read(common::default_world().join("world.toml")).unwrap();
    let agreeing = RawServer::start(move |_, stream, _| {
        let n = body.len();
        write!(
            stream,
            "HTTP/1.1 200 OK\r\nContent-Length: {n}\r\nContent-Length: {n}\r\n\r\n"
        )?;
        stream.write_all(&body)
    });
    HttpSource::open(&agreeing.url, quick_options()).unwrap();
}

/// A redirect to where the client cannot go is refused at once, without retries, naming where
/// it pointed: another scheme (`file://`, `ftp://`), `https://` (said to be a redirect, the
/// client being plain HTTP only), and the addresses refused as a world's address is (a
/// bracketed host that is not an IPv6 address, credentials, which are not repeated).
#[test]
fn a_redirect_where_the_client_cannot_go_is_refused_at_once_naming_it() {
    for (location, said) in [
        (
            "file:///etc/passwd",
            vec!["file:///etc/passwd", "not an http://"],
        ),
        (
            "FTP://files.example/w/world.toml",
            vec!["ftp://files.example/w/world.toml"],
        ),
        (
            "https://secure.example/w/world.toml",
            vec![
                "redirect to https://secure.example/w/world.toml",
                "https is not built in",
            ],
        ),
        (
            "http://[::1:8000/world.toml",
            vec!["[::1:8000", "IPv6 host without its closing ]"],
        ),
        (
            "http://me:secret@127.0.0.1:9/world.toml",
            vec!["credentials"],
        ),
    ] {
        let to = location.to_string();
        let server = RawServer::start(move |_, stream, _| {
            write!(
                stream,
                "HTTP/1.1 302 Found\r\nLocation: {to}\r\nContent-Length: 0\r\n\r\n"
            )
        });
        let start = Instant::now();
        let e = HttpSource::open(&server.url, quick_options()).unwrap_err();
        assert!(
            matches!(http_error(&e), HttpError::BadResponse { .. }),
            "{location}: {e}"
        );
        let e = e.to_string();
        for part in said {
            assert!(e.contains(part), "{location}: no {part:?} in {e}");
        }
        assert!(
            e.contains("redirect") && !e.contains("attempt") && !e.contains("secret"),
            "{location}: {e}"
        );
        assert_eq!(server.asked.load(Ordering::SeqCst), 1, "{location}: {e}");
        assert!(
            start.elapsed() < Duration::from_secs(2),
            "{location}: retried"
        );
    }
}

/// A reply that is not the whole file as sent (a 206 part or a 204 to a request without a
/// range, a body in a transfer coding other than chunked, or in a content coding nobody asked
/// for, a 304 to a request that was not conditional, a chunk size that is not a number) is
/// refused at once naming what it was, never taken (and cached) for the file's bytes;
/// and an error after a redirect names the address that answered too.
#[test]
fn a_reply_that_is_not_the_whole_file_is_refused_naming_why() {
    for (reply, said) in [
        (
            "HTTP/1.1 206 Partial Content\r\nContent-Range: bytes 0-4/99\r\nContent-Length: 5\r\nETag: \"x\"\r\n\r\nhello",
            "HTTP 206 to a request for the whole file",
        ),
        (
            "HTTP/1.1 204 No Content\r\nETag: \"x\"\r\n\r\n",
            "HTTP 204 to a request for the whole file",
        ),
        (
            "HTTP/1.1 200 OK\r\nTransfer-Encoding: gzip, chunked\r\nETag: \"x\"\r\n\r\n5\r\nhello\r\n0\r\n\r\n",
            "Transfer-Encoding \"gzip, chunked\": only chunked is read",
        ),
        (
            "HTTP/1.1 200 OK\r\nContent-Encoding: gzip\r\nContent-Length: 5\r\nETag: \"x\"\r\n\r\nhello",
            "Content-Encoding \"gzip\", which was not asked for",
        ),
        (
            // A second header is a second list of codings, not to be missed.
            "HTTP/1.1 200 OK\r\nContent-Encoding: identity\r\nContent-Encoding: gzip\r\nContent-Length: 5\r\nETag: \"x\"\r\n\r\nhello",
            "Content-Encoding \"gzip\", which was not asked for",
        ),
        (
            "HTTP/1.1 304 Not Modified\r\n\r\n",
            "HTTP 304 Not Modified to a request that was not conditional",
        ),
        (
            "HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\nhello\r\n0\r\n\r\n",
            "body not well-formed after 0 bytes",
        ),
    ] {
        let server = RawServer::start(move |_, stream, _| write!(stream, "{reply}"));
        let e = HttpSource::open(&server.url, quick_options()).unwrap_err();
        assert!(
            matches!(http_error(&e), HttpError::BadResponse { .. }),
            "{said}: {e}"
        );
        assert!(e.to_string().contains(said), "{said}: {e}");
        assert_eq!(server.asked.load(Ordering::SeqCst), 1, "{said}: retried");
    }
    // A body cut short at the address a redirect led to: both are named.
    let server = RawServer::start(move |path, stream, _| {
        if path.starts_with("/z/") {
            write!(
                stream,
                "HTTP/1.1 200 OK\r\nContent-Length: 100\r\n\r\nshort"
            )
        } else {
            write!(
                stream,
                "HTTP/1.1 302 Found\r\nLocation: /z/world.toml\r\nContent-Length: 0\r\n\r\n"
            )
        }
    });
    let e = HttpSource::open(&server.url, quick_options())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("world.toml (redirected to ") && e.contains("/z/world.toml)"),
        "{e}"
    );
}
