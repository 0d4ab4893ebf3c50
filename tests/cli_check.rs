//! `verdant check`: every tile of a world read as the renderer reads it, on disk and over HTTP;
//! a tile file copied over another or left by another bake is listed by tile and file, with a
//! non-zero exit.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use verdant::bake::{BakeOptions, bake};
use verdant::tools::serve::WorldServer;
use verdant::world::{TileFile, TileId, tile_path};

/// A small world baked from rolling hills with `seed` into `dir/name`.
fn small_world(dir: &Path, name: &str, seed: u64) -> PathBuf {
    let dem = dir.join("hills.png");
    if !dem.is_file() {
        common::write_dem(
            dir,
            "hills",
            [120, 100],
            [10.0, 10.0],
            [0.0, 0.01],
            |x, y| 200.0 + 40.0 * (x / 200.0).sin() * (y / 300.0).cos(),
        );
    }
    let out = dir.join(name);
    let opts = BakeOptions {
        dem,
        out: out.clone(),
        cell_size_m: Some(20.0),
        tile_cells: 16,
        stored_levels: 2,
        seed,
        ..Default::default()
    };
    bake(&opts, &mut |_, _, _| {}).unwrap();
    out
}

/// The manifest of `world` with a plant type `name` drawn from `plants/fern.gltf`.
fn with_plant_file(world: &Path, name: &str) -> String {
    let grass = verdant::World::open(world).unwrap().manifest.grass_types[1]
        .name
        .clone();
    let mut manifest = std::fs::read_to_string(world.join("world.toml")).unwrap();
    manifest.push_str(&format!(
        "\n[[plant_types]]\nname = \"{name}\"\nmesh = \"plants/fern.gltf\"\n\
         size_m = [0.3, 0.5]\ndensity = {{ \"{grass}\" = 0.2 }}\n"
    ));
    manifest
}

fn check(world: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", world, "--threads", "2"])
        .output()
        .expect("run verdant check")
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn check_passes_a_whole_world_and_lists_copied_and_foreign_tile_files() {
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    let other = small_world(dir.path(), "other", 8);
    let shown = world.to_str().unwrap();

    let out = check(shown);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("of hills read"), "{stdout}");
    assert!(stdout.contains("every tile is whole"), "{stdout}");
    assert!(
        stdout.contains("every file checked against its stamp"),
        "{stdout}"
    );

    // One tile's type map copied over another's, and a density map from the other bake.
    let [a, b, c] = [
        TileId::new(1, 0, 0),
        TileId::new(1, 1, 0),
        TileId::new(0, 0, 0),
    ];
    std::fs::copy(
        tile_path(&world, b, TileFile::Type),
        tile_path(&world, a, TileFile::Type),
    )
    .unwrap();
    std::fs::copy(
        tile_path(&other, c, TileFile::Density),
        tile_path(&world, c, TileFile::Density),
    )
    .unwrap();
    let out = check(shown);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let lines: Vec<&str> = stdout.lines().collect();
    // Coarsest level first.
    assert!(
        lines[0].starts_with("L0/0_0: ") && lines[0].contains("0_0.density.png"),
        "{stdout}"
    );
    assert!(lines[0].contains("another bake"), "{stdout}");
    assert!(
        lines[1].starts_with("L1/0_0: ") && lines[1].contains("holds L1/1_0.type.png"),
        "{stdout}"
    );
    assert!(
        stderr.contains("2 of ") && stderr.contains("tiles of hills cannot be read"),
        "{stderr}"
    );

    // The same as one JSON document on standard output.
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", shown, "--json"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["world"], "hills");
    let failed = doc["report"]["failed"].as_array().unwrap();
    let tiles: Vec<(u64, u64, u64)> = failed
        .iter()
        .map(|f| {
            let t = &f["tile"];
            (
                t["level"].as_u64().unwrap(),
                t["x"].as_u64().unwrap(),
                t["y"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(tiles, [(0, 0, 0), (1, 0, 0)]);
    assert!(
        failed[1]["error"]
            .as_str()
            .unwrap()
            .contains("holds L1/1_0.type.png")
    );
    assert_eq!(doc["report"]["checked"], doc["report"]["tiles"]);

    // The same world served over HTTP: the same two tiles.
    let server = WorldServer::start(&world, "127.0.0.1:0").unwrap();
    let out = check(&server.url());
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stdout.contains(&format!("{}tiles/L1/0_0.type.png", server.url())),
        "{stdout}"
    );
    assert_eq!(
        stdout.lines().filter(|l| l.starts_with('L')).count(),
        2,
        "{stdout}"
    );
}

/// The plant files a world names are read too, as the renderer reads them before its first
/// frame: a world whose every tile is whole but whose glTF plant cannot be read fails the
/// check, naming the plant type and the file (it passed, and every flight then failed).
#[test]
fn check_reads_the_worlds_plant_files() {
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    let plants = world.join("plants");
    std::fs::create_dir_all(&plants).unwrap();
    let fern = verdant::plants::recipe::Recipe::from_name("fern").unwrap();
    let mesh = &verdant::plants::recipe::generate(fern, 1, [0.2, 0.5, 0.1]).lods[0];
    verdant::plants::write_plant_gltf(&plants.join("fern.gltf"), mesh, None).unwrap();
    let manifest = with_plant_file(&world, "my fern");
    std::fs::write(world.join("world.toml"), manifest).unwrap();
    let shown = world.to_str().unwrap();

    let out = check(shown);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(
        stdout.contains("and its plant file of hills read")
            && stdout.contains("every tile and plant file is whole"),
        "{stdout}"
    );

    std::fs::write(plants.join("fern.gltf"), "").unwrap();
    let out = check(shown);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stdout.contains("plant type \"my fern\": ")
            && !stdout.contains("\"my fern\": plant type")
            && stdout.contains("fern.gltf"),
        "{stdout}"
    );
    assert!(
        stderr.contains("1 of 1 plant files of hills cannot be read (every tile is whole"),
        "{stderr}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", shown, "--json"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["report"]["plant_files"], 1);
    assert_eq!(doc["report"]["failed_plants"][0]["plant_type"], "my fern");
}

/// A world without a bake_id (the committed default world, baked before stamps) is read whole,
/// and the check says that it had no stamps to check.
#[test]
fn check_of_a_world_without_stamps_says_so() {
    let out = check(common::default_world().to_str().unwrap());
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("no stamps checked"), "{stdout}");
}

fn stamp(world: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", world.to_str().unwrap(), "--stamp"])
        .output()
        .expect("run verdant check --stamp")
}

/// `check --stamp` records a world's tiles as they are now (a map copied over another on
/// purpose), keeping every line of world.toml but its bake_id; stamping again an unchanged world
/// gives the same id; a tile that cannot be read stops it before anything is written; and a
/// world over HTTP is refused.
#[test]
fn check_stamp_records_a_hand_edited_world_and_writes_nothing_when_a_tile_is_broken() {
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    let manifest = world.join("world.toml");
    let baked = std::fs::read_to_string(&manifest).unwrap();
    let [a, b] = [TileId::new(1, 0, 0), TileId::new(1, 1, 0)];
    std::fs::copy(
        tile_path(&world, b, TileFile::Density),
        tile_path(&world, a, TileFile::Density),
    )
    .unwrap();
    assert_eq!(check(world.to_str().unwrap()).status.code(), Some(1));

    let out = stamp(&world);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    let stamped = std::fs::read_to_string(&manifest).unwrap();
    let id_line = |t: &str| {
        t.lines()
            .find(|l| l.starts_with("bake_id"))
            .map(str::to_owned)
    };
    let (old_id, new_id) = (id_line(&baked).unwrap(), id_line(&stamped).unwrap());
    assert_ne!(old_id, new_id);
    assert_eq!(stamped.replace(&new_id, &old_id), baked);
    assert!(stdout.contains(&new_id["bake_id = ".len()..]), "{stdout}");
    let out = check(world.to_str().unwrap());
    assert!(out.status.success(), "{:?}", text(&out));
    // The copy is what the world holds now: a's density is b's.
    let w = verdant::World::open(&world).unwrap();
    assert_eq!(
        w.load_tile(a).unwrap().density,
        w.load_tile(b).unwrap().density
    );

    assert!(stamp(&world).status.success());
    assert_eq!(std::fs::read_to_string(&manifest).unwrap(), stamped);

    // A truncated file: nothing is written.
    let path = tile_path(&world, b, TileFile::Height);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let before = common::read_all_files(&world);
    let out = stamp(&world);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(stdout.starts_with("L1/1_0: "), "{stdout}");
    assert!(stderr.contains("nothing stamped"), "{stderr}");
    assert_eq!(common::read_all_files(&world), before);

    let refused = |args: &[&str], says: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap();
        let (_, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    };
    refused(
        &["check", "http://127.0.0.1:9/", "--stamp"],
        "--stamp writes the files of a world folder",
    );
    // It writes only where it is pointed: not the default world, nor a name under ./worlds.
    refused(&["check", "--stamp"], "name the world folder to stamp");
    refused(
        &["check", "santa-cruz", "--stamp"],
        "is not looked up for a write",
    );
}

/// `check --stamp` keeps each file's permissions, and refuses (writing nothing) a world whose
/// world.toml or a tile file is a symbolic link: rewriting it would replace the link and leave
/// its target, perhaps another world's, as it was.
#[cfg(unix)]
#[test]
fn check_stamp_keeps_permissions_and_refuses_links() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o7777;
    let set = |p: &Path, m: u32| {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(m)).unwrap();
    };
    let manifest = world.join("world.toml");
    let tile = tile_path(&world, TileId::new(1, 0, 0), TileFile::Type);
    set(&manifest, 0o600);
    set(&tile, 0o440);
    let out = stamp(&world);
    assert!(out.status.success(), "{:?}", text(&out));
    assert_eq!((mode(&manifest), mode(&tile)), (0o600, 0o440));

    let other = small_world(dir.path(), "other", 8);
    for link in [
        manifest.clone(),
        tile_path(&world, TileId::new(0, 0, 0), TileFile::Height),
    ] {
        let before = common::read_all_files(&world);
        let kept = link.with_extension("kept");
        std::fs::rename(&link, &kept).unwrap();
        std::os::unix::fs::symlink(other.join(link.strip_prefix(&world).unwrap()), &link).unwrap();
        let out = stamp(&world);
        let (stdout, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
        assert!(
            stderr.contains("a symbolic link") && stderr.contains("nothing was written"),
            "{stderr}"
        );
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        std::fs::remove_file(&link).unwrap();
        std::fs::rename(&kept, &link).unwrap();
        assert_eq!(common::read_all_files(&world), before);
    }
    // A tiles/ folder linked to another world's: stamping through it would break that world.
    let others = common::read_all_files(&other);
    std::fs::rename(world.join("tiles"), world.join("tiles.kept")).unwrap();
    std::os::unix::fs::symlink(other.join("tiles"), world.join("tiles")).unwrap();
    let out = stamp(&world);
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(stderr.contains("a symbolic link to a folder"), "{stderr}");
    assert_eq!(common::read_all_files(&other), others);
}

/// A server that answers `world.toml` with `manifest` and holds every other request open
/// without an answer; its address.
fn stalling_server(manifest: Vec<u8>) -> String {
    use std::io::{Read, Write};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let manifest = manifest.clone();
            std::thread::spawn(move || {
                let mut head = Vec::new();
                let mut byte = [0u8; 1];
                while !head.ends_with(b"\r\n\r\n") && stream.read(&mut byte).is_ok_and(|n| n == 1) {
                    head.push(byte[0]);
                }
                let line = String::from_utf8_lossy(&head)
                    .lines()
                    .next()
                    .unwrap_or("")
                    .to_owned();
                if line.contains("world.toml") {
                    let _ = write!(
                        stream,
                        "HTTP/1.1 200 OK\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                        manifest.len()
                    );
                    let _ = stream.write_all(&manifest);
                } else {
                    std::thread::sleep(std::time::Duration::from_secs(120));
                }
            });
        }
    });
    format!("http://{addr}/")
}

/// Ctrl-C stops a check at once, reads of tiles and plant files waiting on a server that does
/// not answer included: it says how far it got and exits with status 130, the reads it cut short not listed as failures.
#[test]
fn ctrl_c_stops_a_check_waiting_on_a_silent_server_at_once() {
    use std::io::BufRead;
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    // With a plant file, which the server holds back as it holds the tiles (the check waited
    // out the timeout on it before it began on the tiles).
    let url = stalling_server(with_plant_file(&world, "fern").into_bytes());
    let spawned = std::time::Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", &url, "--threads", "64", "--http-timeout-s", "100"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The first progress line says the check has begun (its reads then wait on the server).
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    stderr.read_line(&mut first).unwrap();
    assert!(first.starts_with("checked 0/"), "{first}");
    std::thread::sleep(std::time::Duration::from_millis(500));
    let sent = std::time::Instant::now();
    common::send_sigint(&child);
    let out = child.wait_with_output().unwrap();
    let waited = sent.elapsed();
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(130), "{stdout}{rest}");
    assert!(
        waited.as_secs_f64() < 10.0,
        "stopped {waited:?} after Ctrl-C"
    );
    // Begun on the tiles at once, the plant file still waiting.
    assert!(
        spawned.elapsed().as_secs_f64() < 30.0,
        "ended {:?} after it started",
        spawned.elapsed()
    );
    assert!(
        stdout.contains("of hills read") && stdout.contains("stopped"),
        "{stdout}"
    );
    assert!(!stdout.lines().any(|l| l.starts_with('L')), "{stdout}");
    assert!(!rest.contains("panicked"), "{rest}");
}

/// A flight over a world with a tile file copied over another draws it from its ancestors and
/// says so in its summary, pointing at `verdant check`.
#[test]
fn a_flight_over_a_tile_that_cannot_be_read_says_so_in_its_summary() {
    let dir = tempfile::tempdir().unwrap();
    let world = small_world(dir.path(), "hills", 7);
    std::fs::copy(
        tile_path(&world, TileId::new(1, 1, 0), TileFile::Type),
        tile_path(&world, TileId::new(1, 0, 0), TileFile::Type),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["fly", world.to_str().unwrap(), "--path", "overview"])
        .args(["--frames", "2", "--size", "32x18", "--no-images"])
        .args(["--out", dir.path().join("fly").to_str().unwrap()])
        .output()
        .unwrap();
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stderr.contains("holds L1/1_0.type.png"), "{stderr}");
    assert!(
        // (A slow machine may retry the load once more within the flight.)
        stdout.contains("tile faults: ")
            && stdout.contains("loads failed, at most ")
            && stdout.contains("tiles a frame drawn from their ancestors instead")
            && stdout.contains("`verdant check`"),
        "{stdout}"
    );
}

/// Ctrl-C stops a flight and a soak at once while they wait for a world's manifest from a
/// server that does not answer (the first signal was taken and the run waited out the
/// request's deadline, 100 s here).
#[test]
fn ctrl_c_stops_a_flight_and_a_soak_waiting_for_the_worlds_manifest() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/", listener.local_addr().unwrap());
    // Accepts every connection, says nothing, and tells of each.
    let (connected, connections) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for stream in listener.incoming().flatten() {
            held.push(stream);
            let _ = connected.send(());
        }
    });
    let dir = tempfile::tempdir().unwrap();
    for (tool, out) in [("fly", "fly"), ("soak", "soak")] {
        let child = Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args([tool, &url, "--http-timeout-s", "100", "--size", "32x18"])
            .args(["--out", dir.path().join(out).to_str().unwrap()])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // The run has asked for the manifest (its signal handler is in place before it opens
        // the world), and waits.
        connections
            .recv_timeout(std::time::Duration::from_secs(120))
            .unwrap_or_else(|_| panic!("{tool} never asked for the world's manifest"));
        std::thread::sleep(std::time::Duration::from_millis(300));
        let sent = std::time::Instant::now();
        common::send_sigint(&child);
        let out = child.wait_with_output().unwrap();
        let waited = sent.elapsed();
        let (stdout, stderr) = text(&out);
        assert_eq!(out.status.code(), Some(130), "{tool}: {stdout}{stderr}");
        assert!(
            waited.as_secs_f64() < 10.0,
            "{tool} stopped {waited:?} after Ctrl-C"
        );
        assert!(
            stderr.contains("stopped while the world was being fetched"),
            "{tool}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{tool}: {stderr}");
    }
}

/// A world named by a bare name is the folder of that name here when there is one, though it
/// holds no world.toml: the check fails naming it, and never reads the world of the same name
/// under the source tree's worlds/ instead.
#[test]
fn a_folder_named_here_is_the_world_named_even_without_its_manifest() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("santa-cruz/tiles")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(["check", "santa-cruz", "--json"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(stderr.contains("santa-cruz/world.toml"), "{stderr}");
    // The world of that name under the source tree is named as not used.
    assert!(stderr.contains("is not used"), "{stderr}");
    assert!(!stdout.contains("\"location\""), "{stdout}");
}

#[test]
#[cfg(unix)]
fn a_world_folder_whose_name_is_not_utf8_is_read_as_bake_wrote_it() {
    use std::ffi::OsStr;
    use std::os::unix::ffi::OsStrExt;
    let dir = tempfile::tempdir().unwrap();
    // A bake writes any name `--out` gives; every command that reads a world takes it.
    let name = OsStr::from_bytes(b"w\xff");
    let world = small_world(dir.path(), "baked", 3);
    std::fs::rename(&world, dir.path().join(name)).unwrap();
    let run = |args: &[&OsStr]| {
        Command::new(env!("CARGO_BIN_EXE_verdant"))
            .args(args)
            .current_dir(dir.path())
            .output()
            .unwrap()
    };
    let out = run(&[
        OsStr::new("check"),
        name,
        OsStr::new("--threads"),
        OsStr::new("2"),
    ]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains("every tile is whole"), "{stdout}");
    let out = run(&[OsStr::new("check"), OsStr::new("--stamp"), name]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}{stderr}");
    // A name that is not there is named, escaped, as any other missing world.
    let out = run(&[OsStr::new("check"), OsStr::from_bytes(b"x\xff")]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("no world \"x\\xFF\""), "{stderr}");
}
