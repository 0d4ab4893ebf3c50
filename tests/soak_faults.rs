//! Soaks with faults (`verdant soak --faults RATE`), short: a world on disk whose tile files are
//! broken and restored while the camera flies, and the same world over HTTP through a proxy
//! that fails tile requests. The soak's checks hold as without faults: ceilings, flat memory,
//! full detail after the teleport (tiles blocked by a fault drawn from their ancestors), no
//! holes; and the faults were met.

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

/// Soaks measure their own memory and frame times: one at a time.
static SOAKS: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Every file under `dir` with its bytes' FNV-1a hash.
fn hashes(dir: &Path) -> BTreeMap<String, u64> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let e = e.unwrap();
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            } else {
                let h = std::fs::read(e.path())
                    .unwrap()
                    .iter()
                    .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
                        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
                    });
                out.insert(e.path().strip_prefix(dir).unwrap().display().to_string(), h);
            }
        }
    }
    out
}

/// Runs a soak of `seconds` of `world` without grass at 64x36 with faults at `rate`, and
/// returns its report.
fn soak(world: &str, seconds: &str, rate: &str, extra: &[&str], dir: &Path) -> serde_json::Value {
    let mut args = vec![
        "soak",
        world,
        "--seconds",
        seconds,
        "--seed",
        "5",
        "--size",
        "64x36",
        "--no-grass",
        "--faults",
        rate,
        "--out",
        "soak",
    ];
    args.extend_from_slice(extra);
    let out = Command::new(env!("CARGO_BIN_EXE_verdant"))
        .args(&args)
        .current_dir(dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "soak failed: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    serde_json::from_str(&std::fs::read_to_string(dir.join("soak/soak.json")).unwrap()).unwrap()
}

/// The checks every soak with faults must pass, whatever injected them.
fn assert_held(r: &serde_json::Value, frames: u64) {
    assert_eq!(r["violations"].as_array().unwrap().len(), 0, "{r}");
    assert_eq!(r["holes_after_settle"], 0);
    assert_eq!(r["frames"], frames);
    assert_eq!(r["frames_over_world"], frames);
    assert!(r["loads_completed"].as_u64().unwrap() > 0);
    let t = &r["teleports"][0];
    assert!(
        t["frames_to_full_detail"].as_u64().is_some_and(|f| f <= 50),
        "the teleport reached full detail late or never: {t}"
    );
}

#[test]
fn a_soak_with_broken_tile_files_on_disk_holds_its_checks_and_leaves_the_world_alone() {
    let _serial = SOAKS.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    let world = common::default_world();
    let before = hashes(&world);
    // 10% of the finer tile files broken at any moment, a fresh set every 2 s.
    let r = soak(world.to_str().unwrap(), "12", "0.1", &[], tmp.path());
    assert_held(&r, 120);
    let f = &r["faults"];
    let files = &f["files"];
    assert!(files["rounds"].as_u64().unwrap() >= 6, "{f}");
    let injected: u64 = ["missing", "truncated", "garbage", "empty", "folder"]
        .iter()
        .map(|k| files[k].as_u64().unwrap())
        .sum();
    let per_round = (files["files"].as_f64().unwrap() * 0.1).round() as u64;
    assert_eq!(
        injected,
        files["rounds"].as_u64().unwrap() * per_round,
        "{f}"
    );
    assert_eq!(
        files["restored"], injected,
        "every broken file was restored"
    );
    assert!(
        f["loads_failed"].as_u64().unwrap() > 0,
        "no fault was met: {f}"
    );
    // The faults went to a copy, which is gone; the world itself is byte for byte as it was.
    assert!(!tmp.path().join("soak/.world-with-faults").exists());
    assert_eq!(hashes(&world), before, "the soak changed the world's files");
}

#[test]
fn a_soak_over_http_through_a_faulty_proxy_holds_its_checks() {
    let _serial = SOAKS.lock().unwrap_or_else(|e| e.into_inner());
    let tmp = tempfile::tempdir().unwrap();
    let server =
        verdant::tools::serve::WorldServer::start(&common::default_world(), "127.0.0.1:0").unwrap();
    // A deadline of 1 s, so that a stalled request fails (and its tile is drawn from its
    // ancestor) within the teleport's recovery bound on software Vulkan. 16 s, so that the
    // memory windows lie after the HTTP threads' (client and proxy) first use.
    let r = soak(
        &server.url(),
        "16",
        "0.1",
        &["--http-timeout-s", "1"],
        tmp.path(),
    );
    assert_held(&r, 160);
    let h = &r["faults"]["http"];
    let faults: u64 = [
        "status_500",
        "status_503",
        "stalls",
        "resets",
        "short_bodies",
    ]
    .iter()
    .map(|k| h[k].as_u64().unwrap())
    .sum();
    assert!(faults > 0, "the proxy injected nothing: {h}");
    assert_eq!(
        h["requests"].as_u64().unwrap(),
        h["passed"].as_u64().unwrap() + faults,
        "{h}"
    );
}
