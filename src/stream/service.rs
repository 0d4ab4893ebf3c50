//! The streamer: a service on its own tokio runtime that loads and decodes stored tiles.
//!
//! The frame sends the set of tiles it wants (with priorities) over a bounded channel and polls a
//! second bounded channel for finished tiles; neither side ever waits for the other. Decoding
//! runs on tokio's blocking pool (`spawn_blocking`), at most `max_in_flight` loads at a time, the
//! most urgent first. A tile that leaves the wanted set is cancelled: if its load has not
//! started it never starts, and if it has, its result is dropped and reported as cancelled.
//! A tile whose load failed is reported once and not loaded again by this streamer, even when
//! a want set that the frame sent before it saw the failure names it again (the failed set
//! holds at most the world's tiles), until the frame, having seen the failure, asks for a retry
//! ([`Streamer::want_retrying`]).

use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use tokio::sync::mpsc;
use tokio::task::JoinSet;

use crate::world::{TileData, TileId, World, WorldError};

/// Where the streamer gets tiles from: the world on disk, or a test double.
pub trait TileSource: Send + Sync + 'static {
    /// Loads and decodes one stored tile. Runs on a blocking thread.
    fn load(&self, id: TileId) -> Result<TileData, WorldError>;

    /// Like [`TileSource::load`], for a source that can give up early: the streamer sets
    /// `cancelled` when the tile leaves the wanted set, and a load that then returns an error
    /// counts as cancelled, not failed (an HTTP source sends no more requests for it). The
    /// default ignores the flag.
    fn load_cancellable(&self, id: TileId, cancelled: &AtomicBool) -> Result<TileData, WorldError> {
        let _ = cancelled;
        self.load(id)
    }

    /// Reads another file of the world, `name` relative to its folder (a plant's glTF file, or
    /// a buffer or image that file names), of at most `max` bytes. The default serves none.
    fn read_file(&self, name: &Path, max: u64) -> Result<Vec<u8>, WorldError> {
        let _ = max;
        Err(WorldError::Io {
            path: name.to_path_buf(),
            source: std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "this tile source serves no files besides tiles",
            ),
        })
    }
}

impl TileSource for World {
    fn load(&self, id: TileId) -> Result<TileData, WorldError> {
        self.load_tile(id)
    }

    fn read_file(&self, name: &Path, max: u64) -> Result<Vec<u8>, WorldError> {
        crate::world::format::read_regular(&self.dir.join(name), max)
    }
}

/// Limits of the streamer.
#[derive(Clone, Copy, Debug)]
pub struct StreamConfig {
    /// Loads running at once.
    pub max_in_flight: usize,
    /// Capacity of the request channel (frame to streamer).
    pub request_capacity: usize,
    /// Capacity of the result channel (streamer to frame).
    pub result_capacity: usize,
}

/// Most loads a streamer runs at once ([`StreamConfig::max_in_flight`]).
pub const MAX_LOADS_IN_FLIGHT: usize = 1024;

impl Default for StreamConfig {
    fn default() -> Self {
        Self {
            max_in_flight: 8,
            request_capacity: 4,
            result_capacity: 32,
        }
    }
}

/// A tile wanted by the frame; lower `priority` is loaded first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Want {
    /// The tile.
    pub id: TileId,
    /// Urgency: lower first (e.g. distance to the camera, weighted by view direction).
    pub priority: f32,
}

/// What the streamer hands back.
#[derive(Debug)]
pub enum Loaded {
    /// A decoded tile.
    Tile(Arc<TileData>),
    /// The load failed; the message names the file and the problem.
    Failed {
        /// The tile.
        id: TileId,
        /// What went wrong.
        error: String,
    },
}

/// Counters shared by the streamer and the frame.
#[derive(Debug, Default)]
struct Counters {
    in_flight: AtomicU64,
    completed: AtomicU64,
    cancelled: AtomicU64,
    failed: AtomicU64,
}

/// A snapshot of the streamer's counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StreamStats {
    /// Loads running now.
    pub in_flight: u64,
    /// Loads finished and handed back.
    pub completed: u64,
    /// Loads dropped because their tile left the wanted set.
    pub cancelled: u64,
    /// Loads that failed.
    pub failed: u64,
}

/// What the frame sends the streamer: the tiles it wants now, and failed tiles to try again.
#[derive(Debug, Default)]
struct Request {
    wants: Vec<Want>,
    retry: Vec<TileId>,
}

/// Handle of the streamer service, owned by the frame loop.
pub struct Streamer {
    requests: mpsc::Sender<Request>,
    results: mpsc::Receiver<Loaded>,
    counters: Arc<Counters>,
    pending: Option<Request>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Streamer {
    /// Starts the service on a runtime thread of its own.
    pub fn start(source: Arc<dyn TileSource>, config: StreamConfig) -> std::io::Result<Self> {
        if !(1..=MAX_LOADS_IN_FLIGHT).contains(&config.max_in_flight) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "loads in flight must be in 1..={MAX_LOADS_IN_FLIGHT}, not {}",
                    config.max_in_flight
                ),
            ));
        }
        let (req_tx, req_rx) = mpsc::channel(config.request_capacity.max(1));
        let (res_tx, res_rx) = mpsc::channel(config.result_capacity.max(1));
        let counters = Arc::new(Counters::default());
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .max_blocking_threads(config.max_in_flight.max(1))
            .thread_name("verdant-stream")
            .build()?;
        let service_counters = Arc::clone(&counters);
        let thread = std::thread::Builder::new()
            .name("verdant-streamer".into())
            .spawn(move || {
                runtime.block_on(serve(source, config, req_rx, res_tx, service_counters));
                // Decodes still running are abandoned (their results would be dropped anyway).
                runtime.shutdown_background();
            })?;
        Ok(Self {
            requests: req_tx,
            results: res_rx,
            counters,
            pending: None,
            thread: Some(thread),
        })
    }

    /// Tells the streamer which tiles the frame wants now (replacing the last set). Never
    /// blocks: if the channel is full, the set is sent on a later call.
    pub fn want(&mut self, wants: Vec<Want>) {
        self.want_retrying(wants, Vec::new());
    }

    /// Like [`Streamer::want`], and forgets the failures of the `retry` tiles, so that they are
    /// loaded again when wanted. A retry list not sent yet is kept for the next set.
    pub fn want_retrying(&mut self, wants: Vec<Want>, mut retry: Vec<TileId>) {
        if let Some(unsent) = self.pending.take() {
            retry.extend(unsent.retry);
        }
        self.pending = Some(Request { wants, retry });
        self.flush();
    }

    fn flush(&mut self) {
        if let Some(w) = self.pending.take() {
            match self.requests.try_send(w) {
                Ok(()) => {}
                Err(mpsc::error::TrySendError::Full(w)) => self.pending = Some(w),
                Err(mpsc::error::TrySendError::Closed(_)) => {}
            }
        }
    }

    /// Finished loads, without waiting.
    pub fn poll(&mut self) -> Vec<Loaded> {
        self.flush();
        let mut out = Vec::new();
        while let Ok(l) = self.results.try_recv() {
            out.push(l);
        }
        out
    }

    /// The counters now.
    pub fn stats(&self) -> StreamStats {
        let c = &self.counters;
        StreamStats {
            in_flight: c.in_flight.load(Ordering::Relaxed),
            completed: c.completed.load(Ordering::Relaxed),
            cancelled: c.cancelled.load(Ordering::Relaxed),
            failed: c.failed.load(Ordering::Relaxed),
        }
    }
}

impl Drop for Streamer {
    fn drop(&mut self) {
        // Closing the request channel ends the service loop; in-flight decodes finish on their own.
        let (tx, _) = mpsc::channel(1);
        drop(std::mem::replace(&mut self.requests, tx));
        self.results.close();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

async fn serve(
    source: Arc<dyn TileSource>,
    config: StreamConfig,
    mut requests: mpsc::Receiver<Request>,
    results: mpsc::Sender<Loaded>,
    counters: Arc<Counters>,
) {
    let mut wanted: HashMap<TileId, f32> = HashMap::new();
    // Each running load with the flag that tells it its tile is no longer wanted.
    let mut running: HashMap<TileId, Arc<AtomicBool>> = HashMap::new();
    let mut tasks: JoinSet<(TileId, Result<TileData, WorldError>)> = JoinSet::new();
    // Tiles whose load failed (and was reported): never started again.
    let mut failed: HashSet<TileId> = HashSet::new();
    loop {
        // Start the most urgent wanted tiles that are not running yet.
        if running.len() < config.max_in_flight {
            let mut queue: Vec<(TileId, f32)> = wanted
                .iter()
                .filter(|(id, _)| !running.contains_key(id))
                .map(|(id, p)| (*id, *p))
                .collect();
            queue.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            for (id, _) in queue.into_iter().take(config.max_in_flight - running.len()) {
                let cancelled = Arc::new(AtomicBool::new(false));
                running.insert(id, Arc::clone(&cancelled));
                counters.in_flight.fetch_add(1, Ordering::Relaxed);
                let source = Arc::clone(&source);
                tasks.spawn_blocking(move || {
                    let result = source.load_cancellable(id, &cancelled);
                    (id, result)
                });
            }
        }
        tokio::select! {
            request = requests.recv() => match request {
                Some(Request { wants, retry }) => {
                    for id in &retry {
                        failed.remove(id);
                    }
                    wanted = wants
                        .into_iter()
                        .filter(|w| !failed.contains(&w.id))
                        .map(|w| (w.id, w.priority))
                        .collect();
                    for (id, cancelled) in &running {
                        if !wanted.contains_key(id) {
                            cancelled.store(true, Ordering::Relaxed);
                        }
                    }
                }
                None => break,
            },
            Some(joined) = tasks.join_next(), if !tasks.is_empty() => {
                counters.in_flight.fetch_sub(1, Ordering::Relaxed);
                let Ok((id, result)) = joined else { continue };
                let given_up = running
                    .remove(&id)
                    .is_some_and(|c| c.load(Ordering::Relaxed))
                    && result.is_err();
                if given_up {
                    // Told to stop: not a fault. Still wanted (it came back), it starts again.
                    counters.cancelled.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                if wanted.remove(&id).is_none() {
                    // Left the wanted set while it loaded: dropped, never inserted.
                    counters.cancelled.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                let message = match result {
                    Ok(tile) => {
                        counters.completed.fetch_add(1, Ordering::Relaxed);
                        Loaded::Tile(Arc::new(tile))
                    }
                    Err(e) => {
                        counters.failed.fetch_add(1, Ordering::Relaxed);
                        failed.insert(id);
                        Loaded::Failed { id, error: e.to_string() }
                    }
                };
                if results.send(message).await.is_err() {
                    break;
                }
            }
        }
    }
}
