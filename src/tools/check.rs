//! `verdant check`: every stored tile of a world read as the renderer reads it (each file within
//! its size, decoded, checked against the manifest and against its stamp), on disk or over
//! HTTP, so that a world copied, mirrored or edited by hand can be checked before it is flown.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

use crate::bake::CancelFlag;
use crate::stream::TileSource;
use crate::world::{TileId, World, WorldError};

/// Most tiles read at once ([`CheckOptions::threads`]).
pub const MAX_CHECK_THREADS: usize = 64;

/// How a world is checked.
#[derive(Clone, Debug, Default)]
pub struct CheckOptions {
    /// Tiles read at once, 1..=[`MAX_CHECK_THREADS`] (several hide an HTTP server's latency).
    pub threads: usize,
    /// Stops the check between tiles once set.
    pub cancel: Option<CancelFlag>,
}

/// What a check found.
#[derive(Debug, serde::Serialize)]
pub struct CheckReport {
    /// The world's stored tiles.
    pub tiles: u64,
    /// Tiles read (all of them unless the check was stopped).
    pub checked: u64,
    /// Each tile that cannot be read, with why, coarsest level first.
    pub failed: Vec<(TileId, String)>,
    /// Whether the world's tile files carry stamps that were checked (its manifest has a
    /// `bake_id`).
    pub stamped: bool,
    /// Whether the check was stopped before every tile was read.
    pub interrupted: bool,
    /// Wall-clock time, seconds.
    pub seconds: f64,
}

/// Reads every stored tile of `world` from `source` (its folder, or its server) on
/// `options.threads` threads; `progress(done, total)` is called from the calling thread as tiles
/// are read. Failures are collected, not returned: a check reports every bad tile.
pub fn check_world(
    world: &World,
    source: &dyn TileSource,
    options: &CheckOptions,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<CheckReport, WorldError> {
    if !(1..=MAX_CHECK_THREADS).contains(&options.threads) {
        return Err(WorldError::bad_option(
            "--threads",
            options.threads,
            format!("1..={MAX_CHECK_THREADS} tiles read at once"),
        ));
    }
    let start = Instant::now();
    let tiles: Vec<TileId> = world.stored_tiles().collect();
    let total = tiles.len() as u64;
    let next = AtomicUsize::new(0);
    let done = AtomicU64::new(0);
    let failed = Mutex::new(Vec::new());
    let stopped = || {
        options
            .cancel
            .as_ref()
            .is_some_and(CancelFlag::is_cancelled)
    };
    progress(0, total);
    let finished = AtomicUsize::new(0);
    std::thread::scope(|scope| -> Result<(), WorldError> {
        let work = || {
            loop {
                if stopped() {
                    break;
                }
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(&id) = tiles.get(k) else { break };
                if let Err(e) = source.load(id) {
                    failed
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push((k, id, e.to_string()));
                }
                done.fetch_add(1, Ordering::Relaxed);
            }
            finished.fetch_add(1, Ordering::Release);
        };
        let started = crate::bake::spawn_workers(scope, options.threads, || work)?;
        // The calling thread reports progress while the workers read.
        let mut shown = u64::MAX;
        while finished.load(Ordering::Acquire) < started {
            let now = done.load(Ordering::Relaxed);
            if now != shown {
                progress(now, total);
                shown = now;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        Ok(())
    })?;
    let checked = done.load(Ordering::Relaxed);
    progress(checked, total);
    let mut failed = failed.into_inner().unwrap_or_else(|e| e.into_inner());
    failed.sort_by_key(|&(k, ..)| k);
    Ok(CheckReport {
        tiles: total,
        checked,
        failed: failed.into_iter().map(|(_, id, e)| (id, e)).collect(),
        stamped: world.manifest.bake_id.is_some(),
        interrupted: checked < total,
        seconds: start.elapsed().as_secs_f64(),
    })
}
