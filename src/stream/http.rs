//! Worlds streamed over HTTP: [`HttpSource`], a [`TileSource`] that fetches a world's static
//! files (`world.toml`, `tiles/L{level}/{x}_{y}.{kind}`) from any HTTP server, object store or
//! CDN, and decodes them with the same checks as files on disk.
//!
//! Each load runs on one of the streamer's blocking threads (at most `max_in_flight` at once),
//! so the streamer's priorities, its bound on loads in flight and its cancellation apply
//! unchanged. A request has a deadline ([`HttpOptions::timeout`], at most [`MAX_TIMEOUT`]);
//! transient failures (a connection refused or reset, a 5xx status, a body cut short by its
//! `Content-Length` or mid-chunk) are retried after a wait that doubles from
//! [`HttpOptions::backoff`] up to [`HttpOptions::backoff_max`] (each retry is logged as a
//! warning: what, why and when); anything else (a 4xx status, a stall past the deadline, a
//! body that is not a tile or is too large) fails the load at once, and the streamer counts it
//! as a fault exactly like a corrupt tile on disk.
//!
//! Bodies are streamed and never read past the most that such a file may hold: `world.toml` at
//! most [`MAX_MANIFEST_BYTES`] (16 MiB, as on disk), a tile file at most
//! [`max_file_bytes`](crate::world::format::max_file_bytes) for the world's tile size (twice its
//! raw samples plus 64 KiB of headers: 202 KiB for a height file of the default world's
//! 133-sample tiles). A `Content-Length` beyond the limit is refused before the body is read; a
//! body without one (chunked or ended by closing) is cut off at the limit. Redirects are
//! followed up to [`MAX_REDIRECTS`] hops, with a warning (once per pair of hosts) when they
//! lead to another host.
//!
//! Fetched files can be kept in an on-disk cache bounded in bytes, revalidated with the
//! server's `ETag` or `Last-Modified` (a conditional GET that costs a `304` and no body). Each
//! cached body is checked against the length and FNV-1a checksum in its metadata before use; a
//! damaged entry is dropped and the file fetched again unconditionally.
//!
//! Plain HTTP only (the client, `minreq`, is built without TLS); put a TLS-terminating proxy in
//! front for `https`.

use std::collections::{HashMap, HashSet};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use crate::world::format::{decode_density, decode_grass_types, decode_heights, max_file_bytes};
use crate::world::manifest::MAX_MANIFEST_BYTES;
use crate::world::{Manifest, ReadOptions, TileData, TileFile, TileId, World, WorldError};

use super::service::TileSource;

/// The longest deadline of one request that [`HttpOptions::timeout`] may ask for: one hour.
pub const MAX_TIMEOUT: Duration = Duration::from_secs(3600);

/// The longest wait between retries that [`HttpOptions::backoff_max`] may ask for: one minute.
pub const MAX_BACKOFF: Duration = Duration::from_secs(60);

/// Redirects followed for one file at most; more fail the file.
pub const MAX_REDIRECTS: usize = 5;

/// The most bytes of a response's status line and headers (a server that sends more is
/// refused rather than buffered).
const MAX_HEAD_BYTES: usize = 64 << 10;

/// Why a file of a world over HTTP could not be had. Every variant names the URL (or the
/// option).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HttpError {
    /// The world's address is not a plain `http://` URL.
    #[error("{url}: not a world address: {problem}")]
    BadUrl {
        /// The address given.
        url: String,
        /// What is wrong with it.
        problem: &'static str,
    },
    /// An [`HttpOptions`] field is out of its range.
    #[error("HTTP option {option} = {value}: must be {allowed}")]
    BadOption {
        /// The field.
        option: &'static str,
        /// The value given.
        value: String,
        /// The range allowed, in words.
        allowed: &'static str,
    },
    /// No response: the connection was refused, reset or could not be made.
    #[error("{url}: no response after {attempts} attempt(s): {message}")]
    Transport {
        /// The file's URL.
        url: String,
        /// Requests made.
        attempts: u32,
        /// The client's last error.
        message: String,
    },
    /// The server's answer broke the protocol or the client's bounds: headers too long, a
    /// malformed length, too many redirects.
    #[error("{url}: bad response: {message}")]
    BadResponse {
        /// The file's URL.
        url: String,
        /// What was wrong.
        message: String,
    },
    /// The server did not answer within the deadline.
    #[error("{url}: no complete response within {timeout_s} s")]
    TimedOut {
        /// The file's URL.
        url: String,
        /// The deadline, seconds.
        timeout_s: u64,
    },
    /// The server answered with an error status.
    #[error("{url}: HTTP {status} {reason} (after {attempts} attempt(s))")]
    Status {
        /// The file's URL.
        url: String,
        /// The status code.
        status: i32,
        /// The reason phrase.
        reason: String,
        /// Requests made.
        attempts: u32,
    },
    /// The body was shorter than its `Content-Length` (the connection closed early).
    #[error("{url}: body cut short: {received} of {expected} bytes (after {attempts} attempt(s))")]
    Truncated {
        /// The file's URL.
        url: String,
        /// Bytes announced.
        expected: u64,
        /// Bytes received.
        received: u64,
        /// Requests made.
        attempts: u32,
    },
    /// A chunked body ended (the connection closed) in the middle of a chunk.
    #[error("{url}: chunked body cut short after {received} bytes (after {attempts} attempt(s))")]
    ChunksCutShort {
        /// The file's URL.
        url: String,
        /// Bytes received.
        received: u64,
        /// Requests made.
        attempts: u32,
    },
    /// The response announced (by `Content-Length`) a body larger than any such file may be;
    /// none of it was read.
    #[error("{url}: Content-Length of {size} bytes, more than the {max} that this file may hold")]
    TooLarge {
        /// The file's URL.
        url: String,
        /// Bytes announced.
        size: u64,
        /// The most allowed.
        max: u64,
    },
    /// A body without a `Content-Length` (chunked, or ended by closing) went on past the most
    /// that such a file may hold; reading stopped there.
    #[error("{url}: body longer than the {max} bytes that this file may hold (reading stopped)")]
    BodyTooLong {
        /// The file's URL.
        url: String,
        /// The most allowed.
        max: u64,
    },
    /// The tile left the wanted set: no more requests were sent for it.
    #[error("{url}: cancelled, the tile is no longer wanted")]
    Cancelled {
        /// The file that was not fetched.
        url: String,
    },
    /// The on-disk cache could not be opened.
    #[error("{}: tile cache: {source}", path.display())]
    Cache {
        /// The cache folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl From<HttpError> for WorldError {
    fn from(e: HttpError) -> Self {
        WorldError::Fetch(Box::new(e))
    }
}

/// An on-disk cache of fetched files.
#[derive(Clone, Debug, PartialEq)]
pub struct HttpCacheConfig {
    /// The cache folder (created if missing).
    pub dir: PathBuf,
    /// The most bytes of bodies kept; the least recently used are removed beyond it.
    pub max_bytes: u64,
}

/// How a world is fetched over HTTP.
#[derive(Clone, Debug, PartialEq)]
pub struct HttpOptions {
    /// Deadline of one request (connection, headers and body), whole seconds: rounded up, at
    /// least 1 s, at most [`MAX_TIMEOUT`] (3600 s; more is refused by [`HttpSource::open`]).
    /// Default 10 s.
    pub timeout: Duration,
    /// Retries of a transient failure (connection error, 5xx, body cut short). Default 3.
    pub retries: u32,
    /// Wait before the first retry, doubled before each next one up to `backoff_max`. Default
    /// 200 ms.
    pub backoff: Duration,
    /// The longest wait before a retry, at most [`MAX_BACKOFF`] (60 s). Default 5 s.
    pub backoff_max: Duration,
    /// The on-disk cache of fetched files; none by default.
    pub cache: Option<HttpCacheConfig>,
}

impl Default for HttpOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(10),
            retries: 3,
            backoff: Duration::from_millis(200),
            backoff_max: Duration::from_secs(5),
            cache: None,
        }
    }
}

impl HttpOptions {
    /// Checks the fields whose range is bounded ([`HttpSource::open`] calls it).
    pub fn validate(&self) -> Result<(), HttpError> {
        if self.timeout > MAX_TIMEOUT {
            return Err(HttpError::BadOption {
                option: "timeout",
                value: format!("{} s", self.timeout.as_secs_f64()),
                allowed: "in 1..=3600 s (shorter ones are rounded up to 1 s)",
            });
        }
        if self.backoff_max > MAX_BACKOFF {
            return Err(HttpError::BadOption {
                option: "backoff_max",
                value: format!("{} s", self.backoff_max.as_secs_f64()),
                allowed: "at most 60 s",
            });
        }
        Ok(())
    }

    /// The wait before retry `retry` (1 for the first): `backoff` doubled `retry - 1` times,
    /// never more than `backoff_max`. Total for any `Duration`s (saturating, no panic).
    pub fn retry_delay(&self, retry: u32) -> Duration {
        let doublings = retry.saturating_sub(1).min(31);
        self.backoff
            .saturating_mul(1 << doublings)
            .min(self.backoff_max)
    }

    /// The deadline as minreq takes it: whole seconds, within 1..=3600.
    fn timeout_s(&self) -> u64 {
        let s = self.timeout.min(MAX_TIMEOUT);
        (s.as_secs() + u64::from(s.subsec_nanos() > 0)).max(1)
    }
}

/// Counters of an [`HttpSource`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HttpStats {
    /// Requests sent (each retry is one more).
    pub requests: u64,
    /// Retries after a transient failure.
    pub retries: u64,
    /// Files answered from the cache (a `304`).
    pub cache_hits: u64,
    /// Body bytes received.
    pub bytes: u64,
}

/// Whether a world argument is an HTTP address rather than a folder.
pub fn is_url(s: &str) -> bool {
    let lower = s.get(..8).unwrap_or(s).to_ascii_lowercase();
    lower.starts_with("http://") || lower.starts_with("https://")
}

/// A world's tiles fetched over HTTP; see the module docs.
pub struct HttpSource {
    base: String,
    manifest: Manifest,
    client: Client,
}

/// The requests, their retries, the cache and the counters.
struct Client {
    options: HttpOptions,
    cache: Option<Mutex<DiskCache>>,
    /// Pairs of hosts (from, to) whose redirect has been reported.
    redirects_seen: Mutex<HashSet<(String, String)>>,
    requests: AtomicU64,
    retries: AtomicU64,
    cache_hits: AtomicU64,
    bytes: AtomicU64,
}

impl std::fmt::Debug for HttpSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HttpSource")
            .field("base", &self.base)
            .field("options", &self.client.options)
            .finish_non_exhaustive()
    }
}

impl HttpSource {
    /// Checks the options, fetches and validates `{url}/world.toml` and returns the world
    /// (whose `dir` is the URL, for messages only) and the source of its tiles.
    pub fn open(url: &str, options: HttpOptions) -> Result<(World, HttpSource), WorldError> {
        let lower = url.to_ascii_lowercase();
        if lower.starts_with("https://") {
            return Err(HttpError::BadUrl {
                url: url.into(),
                problem: "https is not built in: serve plain http, or put a TLS proxy in front",
            }
            .into());
        }
        if !lower.starts_with("http://") || url.len() <= "http://".len() {
            return Err(HttpError::BadUrl {
                url: url.into(),
                problem: "expected http://HOST[:PORT]/PATH",
            }
            .into());
        }
        options.validate()?;
        let base = format!("{}/", url.trim_end_matches('/'));
        let cache = match &options.cache {
            Some(c) => Some(Mutex::new(DiskCache::open(c)?)),
            None => None,
        };
        let client = Client {
            options,
            cache,
            redirects_seen: Mutex::new(HashSet::new()),
            requests: AtomicU64::new(0),
            retries: AtomicU64::new(0),
            cache_hits: AtomicU64::new(0),
            bytes: AtomicU64::new(0),
        };
        let manifest_url = format!("{base}world.toml");
        let bytes = client.fetch(&manifest_url, MAX_MANIFEST_BYTES, None)?;
        let path = Path::new(&manifest_url);
        let text = String::from_utf8(bytes).map_err(|e| WorldError::ManifestSyntax {
            path: path.to_path_buf(),
            message: format!("not UTF-8 text: {e}"),
        })?;
        let manifest = Manifest::parse(&text, path)?;
        let world = World {
            dir: PathBuf::from(base.clone()),
            manifest: manifest.clone(),
        };
        Ok((
            world,
            HttpSource {
                base,
                manifest,
                client,
            },
        ))
    }

    /// The world's address, ending in `/`.
    pub fn base_url(&self) -> &str {
        &self.base
    }

    /// The counters now.
    pub fn stats(&self) -> HttpStats {
        let c = &self.client;
        HttpStats {
            requests: c.requests.load(Ordering::Relaxed),
            retries: c.retries.load(Ordering::Relaxed),
            cache_hits: c.cache_hits.load(Ordering::Relaxed),
            bytes: c.bytes.load(Ordering::Relaxed),
        }
    }

    /// The URL of one of a tile's files.
    pub fn tile_url(&self, id: TileId, kind: TileFile) -> String {
        let path = crate::world::tile_path(Path::new(""), id, kind);
        format!("{}{}", self.base, path.to_string_lossy().replace('\\', "/"))
    }
}

impl Client {
    /// Fetches one file of at most `max` bytes (through the cache when there is one),
    /// retrying transient failures.
    fn fetch(
        &self,
        url: &str,
        max: u64,
        cancelled: Option<&AtomicBool>,
    ) -> Result<Vec<u8>, HttpError> {
        let cached = self
            .cache
            .as_ref()
            .and_then(|c| c.lock().ok().and_then(|mut c| c.get(url, max)));
        let is_cancelled = || cancelled.is_some_and(|c| c.load(Ordering::Relaxed));
        let mut attempt = 0;
        loop {
            if is_cancelled() {
                return Err(HttpError::Cancelled { url: url.into() });
            }
            attempt += 1;
            self.requests.fetch_add(1, Ordering::Relaxed);
            match self.fetch_once(url, max, attempt, &cached) {
                Ok(bytes) => return Ok(bytes),
                Err(e) if attempt <= self.options.retries && is_transient(&e) => {
                    self.retries.fetch_add(1, Ordering::Relaxed);
                    let wait = self.options.retry_delay(attempt);
                    log::warn!(
                        "{e}; retry {attempt} of {} in {:.1} s",
                        self.options.retries,
                        wait.as_secs_f64()
                    );
                    // In slices, so that a tile that leaves the wanted set stops waiting.
                    let slice = Duration::from_millis(50);
                    let mut left = wait;
                    while !left.is_zero() && !is_cancelled() {
                        std::thread::sleep(left.min(slice));
                        left = left.saturating_sub(slice);
                    }
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// One request: its response checked and its body read, at most `max` bytes (or the
    /// cached body on a `304`).
    fn fetch_once(
        &self,
        url: &str,
        max: u64,
        attempts: u32,
        cached: &Option<(Validator, Vec<u8>)>,
    ) -> Result<Vec<u8>, HttpError> {
        let timeout_s = self.options.timeout_s();
        let mut request = minreq::get(url)
            .with_timeout(timeout_s)
            .with_max_redirects(MAX_REDIRECTS)
            .with_max_headers_size(MAX_HEAD_BYTES)
            .with_max_status_line_length(MAX_HEAD_BYTES);
        if let Some((validator, _)) = cached {
            request = match validator {
                Validator::ETag(tag) => request.with_header("If-None-Match", tag.as_str()),
                Validator::LastModified(date) => {
                    request.with_header("If-Modified-Since", date.as_str())
                }
            };
        }
        let timed_out = || HttpError::TimedOut {
            url: url.into(),
            timeout_s,
        };
        let mut response = match request.send_lazy() {
            Ok(response) => response,
            Err(minreq::Error::IoError(e)) if is_timeout(&e) => return Err(timed_out()),
            Err(minreq::Error::IoError(e)) => {
                return Err(HttpError::Transport {
                    url: url.into(),
                    attempts,
                    message: e.to_string(),
                });
            }
            Err(e @ minreq::Error::AddressNotFound) => {
                return Err(HttpError::Transport {
                    url: url.into(),
                    attempts,
                    message: e.to_string(),
                });
            }
            Err(e @ minreq::Error::TooManyRedirections) => {
                return Err(HttpError::BadResponse {
                    url: url.into(),
                    message: format!("{e}: at most {MAX_REDIRECTS} are followed"),
                });
            }
            Err(e) => {
                return Err(HttpError::BadResponse {
                    url: url.into(),
                    message: e.to_string(),
                });
            }
        };
        self.note_redirect(url, &response.url);
        if response.status_code == 304
            && let Some((_, body)) = cached
        {
            self.cache_hits.fetch_add(1, Ordering::Relaxed);
            return Ok(body.clone());
        }
        if !(200..300).contains(&response.status_code) {
            return Err(HttpError::Status {
                url: url.into(),
                status: response.status_code,
                reason: response.reason_phrase.clone(),
                attempts,
            });
        }
        // minreq has refused a Content-Length that is not a number; chunked bodies have none.
        let expected = response
            .headers
            .get("content-length")
            .and_then(|v| v.trim().parse::<u64>().ok());
        if let Some(size) = expected
            && size > max
        {
            return Err(HttpError::TooLarge {
                url: url.into(),
                size,
                max,
            });
        }
        let chunked = response
            .headers
            .get("transfer-encoding")
            .is_some_and(|v| v.trim().eq_ignore_ascii_case("chunked"));
        let validator = Validator::from_headers(&response.headers);
        let capacity = expected.unwrap_or(64 << 10).min(max);
        let mut body = Vec::with_capacity(capacity as usize);
        // One byte past the limit tells a body that is too long from one that just fits.
        let read = Read::take(&mut response, max.saturating_add(1)).read_to_end(&mut body);
        self.bytes.fetch_add(body.len() as u64, Ordering::Relaxed);
        match read {
            Ok(_) => {}
            Err(e) if is_timeout(&e) => return Err(timed_out()),
            Err(e) => {
                return Err(HttpError::Transport {
                    url: url.into(),
                    attempts,
                    message: format!("body after {} bytes: {e}", body.len()),
                });
            }
        }
        if body.len() as u64 > max {
            return Err(HttpError::BodyTooLong {
                url: url.into(),
                max,
            });
        }
        // minreq replaces Transfer-Encoding by a Content-Length once it has seen the last
        // chunk, and ends the body without an error when the connection closes mid-chunk.
        if chunked && response.headers.contains_key("transfer-encoding") {
            return Err(HttpError::ChunksCutShort {
                url: url.into(),
                received: body.len() as u64,
                attempts,
            });
        }
        if let Some(expected) = expected
            && (body.len() as u64) < expected
        {
            return Err(HttpError::Truncated {
                url: url.into(),
                expected,
                received: body.len() as u64,
                attempts,
            });
        }
        if let (Some(cache), Some(validator)) = (&self.cache, validator)
            && let Ok(mut cache) = cache.lock()
        {
            cache.put(url, &validator, &body);
        }
        Ok(body)
    }

    /// Warns, once per pair of hosts, that a request for `asked` was redirected to another
    /// host (`answered` is the URL that answered).
    fn note_redirect(&self, asked: &str, answered: &str) {
        let (from, to) = (host_of(asked), host_of(answered));
        if answered.is_empty() || from.eq_ignore_ascii_case(to) {
            return;
        }
        let pair = (from.to_string(), to.to_string());
        if let Ok(mut seen) = self.redirects_seen.lock()
            && seen.insert(pair)
        {
            log::warn!(
                "{asked}: redirected from host {from} to host {to} ({answered}); \
                 further redirects between these hosts are followed silently"
            );
        }
    }
}

/// The `host[:port]` of an `http://` URL.
fn host_of(url: &str) -> &str {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    rest.split(['/', '?', '#']).next().unwrap_or(rest)
}

/// Whether an I/O error is the deadline passing (minreq's own, or a socket timeout).
fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
    )
}

impl TileSource for HttpSource {
    fn load(&self, id: TileId) -> Result<TileData, WorldError> {
        self.load_cancellable(id, &AtomicBool::new(false))
    }

    /// Fetches the three files one after another; once `cancelled` is set, no further request
    /// (file or retry) is sent.
    fn load_cancellable(&self, id: TileId, cancelled: &AtomicBool) -> Result<TileData, WorldError> {
        let pyramid = &self.manifest.pyramid;
        if !pyramid.is_stored(id) {
            return Err(WorldError::TileNotStored {
                path: PathBuf::from(&self.base),
                id,
            });
        }
        let size = pyramid.samples_per_side();
        let options = ReadOptions {
            height_range_m: self.manifest.height_range_m,
            grass_type_count: self.manifest.grass_types.len(),
        };
        let get = |kind| -> Result<(Vec<u8>, String), WorldError> {
            let url = self.tile_url(id, kind);
            let bytes = self
                .client
                .fetch(&url, max_file_bytes(kind, size), Some(cancelled))?;
            Ok((bytes, url))
        };
        let (bytes, url) = get(TileFile::Height)?;
        let heights = decode_heights(&bytes, size, &options, Path::new(&url))?;
        let (bytes, url) = get(TileFile::Type)?;
        let grass_type = decode_grass_types(&bytes, size, &options, Path::new(&url))?;
        let (bytes, url) = get(TileFile::Density)?;
        let density = decode_density(&bytes, size, Path::new(&url))?;
        Ok(TileData {
            id,
            size,
            heights,
            grass_type,
            density,
        })
    }
}

/// Failures worth another try: the connection, the server's own errors, a body cut short.
fn is_transient(e: &HttpError) -> bool {
    match e {
        HttpError::Transport { .. }
        | HttpError::Truncated { .. }
        | HttpError::ChunksCutShort { .. } => true,
        HttpError::Status { status, .. } => (500..600).contains(status),
        _ => false,
    }
}

/// What a cached body is revalidated with.
#[derive(Clone, Debug, PartialEq)]
enum Validator {
    ETag(String),
    LastModified(String),
}

impl Validator {
    fn from_headers(headers: &HashMap<String, String>) -> Option<Validator> {
        if let Some(tag) = headers.get("etag") {
            return Some(Validator::ETag(tag.trim().to_string()));
        }
        headers
            .get("last-modified")
            .map(|d| Validator::LastModified(d.trim().to_string()))
    }

    fn to_line(&self) -> String {
        match self {
            Validator::ETag(t) => format!("etag {t}"),
            Validator::LastModified(d) => format!("last-modified {d}"),
        }
    }

    fn from_line(line: &str) -> Option<Validator> {
        let (kind, value) = line.split_once(' ')?;
        match kind {
            "etag" => Some(Validator::ETag(value.to_string())),
            "last-modified" => Some(Validator::LastModified(value.to_string())),
            _ => None,
        }
    }
}

/// FNV-1a, 64 bits: stable across runs and platforms; enough to name a URL's entry and to
/// catch a damaged body (not an adversary).
fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The most bytes of a cache entry's metadata (a URL, a validator and a checksum).
const MAX_META_BYTES: u64 = 16 << 10;

/// Fetched bodies on disk, one `{key}.body` and `{key}.meta` per URL, the key a hash of the
/// URL. The metadata holds three lines: the URL, the validator, and `fnv1a64 {hex} {length}`
/// of the body. Each is written to a temporary file and renamed into place, the body before
/// its metadata, so that an interrupted write leaves a body that its metadata does not match
/// (and that is dropped) rather than a torn file. The least recently used go first beyond
/// `max_bytes`.
struct DiskCache {
    dir: PathBuf,
    max_bytes: u64,
    bytes: u64,
    clock: u64,
    /// Key to (body bytes, last use).
    entries: HashMap<String, (u64, u64)>,
}

impl DiskCache {
    fn open(config: &HttpCacheConfig) -> Result<DiskCache, HttpError> {
        let err = |source| HttpError::Cache {
            path: config.dir.clone(),
            source,
        };
        std::fs::create_dir_all(&config.dir).map_err(err)?;
        let mut cache = DiskCache {
            dir: config.dir.clone(),
            max_bytes: config.max_bytes,
            bytes: 0,
            clock: 0,
            entries: HashMap::new(),
        };
        for entry in std::fs::read_dir(&config.dir).map_err(err)? {
            let Ok(entry) = entry else { continue };
            let name = entry.file_name().to_string_lossy().into_owned();
            let Some(key) = name.strip_suffix(".body") else {
                continue;
            };
            if let Ok(meta) = entry.metadata() {
                cache.entries.insert(key.to_string(), (meta.len(), 0));
                cache.bytes += meta.len();
            }
        }
        cache.evict(0);
        Ok(cache)
    }

    fn key(url: &str) -> String {
        format!("{:016x}", fnv1a64(url.as_bytes()))
    }

    fn path(&self, key: &str, suffix: &str) -> PathBuf {
        self.dir.join(format!("{key}.{suffix}"))
    }

    /// The cached validator and body of `url` (at most `max` bytes), if its entry is whole; a
    /// damaged entry is removed (with a warning) so that the file is fetched again
    /// unconditionally.
    fn get(&mut self, url: &str, max: u64) -> Option<(Validator, Vec<u8>)> {
        let key = Self::key(url);
        self.entries.get(&key)?;
        match self.read_entry(&key, url, max) {
            Ok(found) => {
                self.clock += 1;
                if let Some(e) = self.entries.get_mut(&key) {
                    e.1 = self.clock;
                }
                Some(found)
            }
            Err(problem) => {
                log::warn!(
                    "{}: cached copy of {url} dropped ({problem}); fetching it again",
                    self.dir.display()
                );
                self.remove(&key);
                None
            }
        }
    }

    fn read_entry(&self, key: &str, url: &str, max: u64) -> Result<(Validator, Vec<u8>), String> {
        let meta_path = self.path(key, "meta");
        let meta_len = std::fs::metadata(&meta_path)
            .map_err(|e| format!("metadata: {e}"))?
            .len();
        if meta_len > MAX_META_BYTES {
            return Err(format!("metadata of {meta_len} bytes"));
        }
        let meta = std::fs::read(&meta_path).map_err(|e| format!("metadata: {e}"))?;
        let meta = String::from_utf8(meta).map_err(|_| "metadata not UTF-8".to_string())?;
        let lines: Vec<&str> = meta.lines().collect();
        let [meta_url, validator, sum] = lines[..] else {
            return Err(format!("metadata has {} lines, not 3", lines.len()));
        };
        if meta_url != url {
            return Err(format!("metadata names {meta_url}"));
        }
        let validator = Validator::from_line(validator).ok_or("no validator in metadata")?;
        let (hash, len) = sum
            .strip_prefix("fnv1a64 ")
            .and_then(|s| s.split_once(' '))
            .and_then(|(h, l)| Some((u64::from_str_radix(h, 16).ok()?, l.parse::<u64>().ok()?)))
            .ok_or("no checksum in metadata")?;
        let body_path = self.path(key, "body");
        let size = std::fs::metadata(&body_path)
            .map_err(|e| format!("body: {e}"))?
            .len();
        if size != len || size > max {
            return Err(format!("body of {size} bytes, {len} expected"));
        }
        let body = std::fs::read(&body_path).map_err(|e| format!("body: {e}"))?;
        if body.len() as u64 != len || fnv1a64(&body) != hash {
            return Err("body does not match its checksum".into());
        }
        Ok((validator, body))
    }

    fn put(&mut self, url: &str, validator: &Validator, body: &[u8]) {
        let size = body.len() as u64;
        if size > self.max_bytes {
            return;
        }
        let key = Self::key(url);
        self.remove(&key);
        self.evict(size);
        let meta = format!(
            "{url}\n{}\nfnv1a64 {:016x} {size}\n",
            validator.to_line(),
            fnv1a64(body)
        );
        let write = |suffix: &str, bytes: &[u8]| {
            let tmp = self.path(&key, &format!("{suffix}.tmp"));
            std::fs::write(&tmp, bytes)
                .and_then(|()| std::fs::rename(&tmp, self.path(&key, suffix)))
        };
        if let Err(e) = write("body", body).and_then(|()| write("meta", meta.as_bytes())) {
            log::warn!("{}: tile cache: {e}", self.dir.display());
            let _ = std::fs::remove_file(self.path(&key, "body"));
            return;
        }
        self.clock += 1;
        self.entries.insert(key, (size, self.clock));
        self.bytes += size;
    }

    fn remove(&mut self, key: &str) {
        if let Some((size, _)) = self.entries.remove(key) {
            self.bytes -= size;
            let _ = std::fs::remove_file(self.path(key, "body"));
            let _ = std::fs::remove_file(self.path(key, "meta"));
        }
    }

    /// Removes the least recently used entries until `incoming` more bytes fit.
    fn evict(&mut self, incoming: u64) {
        while self.bytes + incoming > self.max_bytes {
            let Some(oldest) = self
                .entries
                .iter()
                .min_by_key(|(_, (_, used))| *used)
                .map(|(k, _)| k.clone())
            else {
                break;
            };
            self.remove(&oldest);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_disk_cache_stays_within_its_bytes_and_drops_the_least_recently_used() {
        let tmp = tempfile::tempdir().unwrap();
        let config = HttpCacheConfig {
            dir: tmp.path().join("cache"),
            max_bytes: 250,
        };
        let mut cache = DiskCache::open(&config).unwrap();
        let tag = Validator::ETag("\"a\"".into());
        cache.put("http://h/a", &tag, &[1; 100]);
        cache.put("http://h/b", &tag, &[2; 100]);
        assert!(cache.get("http://h/a", 1000).is_some()); // a is now more recent than b
        cache.put("http://h/c", &tag, &[3; 100]);
        assert!(cache.bytes <= 250);
        assert!(
            cache.get("http://h/b", 1000).is_none(),
            "b was the least recently used"
        );
        assert_eq!(cache.get("http://h/a", 1000).unwrap().1, vec![1; 100]);
        assert_eq!(
            cache.get("http://h/c", 1000).unwrap(),
            (tag.clone(), vec![3; 100])
        );
        cache.put("http://h/huge", &tag, &[0; 300]);
        assert!(cache.get("http://h/huge", 1000).is_none());
        // Reopened, it finds its files and still keeps within its bytes.
        drop(cache);
        let small = HttpCacheConfig {
            max_bytes: 100,
            ..config
        };
        let cache = DiskCache::open(&small).unwrap();
        assert!(cache.bytes <= 100 && cache.entries.len() == 1);
    }

    /// A body that its metadata does not match (a flipped byte, another length, a body larger
    /// than the file may be), and metadata that is torn or from another URL, are each dropped:
    /// both files removed and the bytes no longer counted.
    #[test]
    fn a_damaged_cache_entry_is_dropped() {
        let tmp = tempfile::tempdir().unwrap();
        let config = HttpCacheConfig {
            dir: tmp.path().to_path_buf(),
            max_bytes: 1 << 20,
        };
        let mut cache = DiskCache::open(&config).unwrap();
        let tag = Validator::LastModified("Wed, 21 Oct 2015 07:28:00 GMT".into());
        let url = "http://h/w/world.toml";
        let key = DiskCache::key(url);
        let (body_path, meta_path) = (cache.path(&key, "body"), cache.path(&key, "meta"));
        type Damage = fn(&Path, &Path);
        let damages: [(&str, Damage); 6] = [
            ("a flipped byte", |b, _| {
                let mut bytes = std::fs::read(b).unwrap();
                bytes[3] ^= 0x80;
                std::fs::write(b, bytes).unwrap();
            }),
            ("a shorter body", |b, _| {
                std::fs::write(b, b"name = ").unwrap()
            }),
            ("no body", |b, _| std::fs::remove_file(b).unwrap()),
            ("torn metadata", |_, m| {
                let meta = std::fs::read(m).unwrap();
                std::fs::write(m, &meta[..meta.len() / 2]).unwrap();
            }),
            ("metadata of the old format", |_, m| {
                let meta = std::fs::read_to_string(m).unwrap();
                let two: Vec<&str> = meta.lines().take(2).collect();
                std::fs::write(m, two.join("\n")).unwrap();
            }),
            ("metadata of another URL", |_, m| {
                let meta = std::fs::read_to_string(m).unwrap();
                std::fs::write(m, meta.replace("world.toml", "other.toml")).unwrap();
            }),
        ];
        for (what, damage) in damages {
            cache.put(url, &tag, b"name = \"santa-cruz\"\n");
            assert_eq!(
                cache.get(url, 1000).unwrap(),
                (tag.clone(), b"name = \"santa-cruz\"\n".to_vec()),
                "{what}: whole before"
            );
            damage(&body_path, &meta_path);
            assert!(cache.get(url, 1000).is_none(), "{what}: used");
            assert!(!body_path.exists() && !meta_path.exists(), "{what}: kept");
            assert_eq!((cache.bytes, cache.entries.len()), (0, 0), "{what}");
        }
        // A whole body larger than the file may now be is not used either.
        cache.put(url, &tag, &[b'a'; 100]);
        assert!(cache.get(url, 99).is_none());
        assert!(!body_path.exists());
    }

    /// The wait doubles from the backoff and stops at its ceiling; no `Duration` overflows.
    #[test]
    fn retry_waits_double_up_to_their_ceiling() {
        let options = HttpOptions::default();
        let waits: Vec<u128> = (1..=8)
            .map(|r| options.retry_delay(r).as_millis())
            .collect();
        assert_eq!(waits, [200, 400, 800, 1600, 3200, 5000, 5000, 5000]);
        assert_eq!(options.retry_delay(u32::MAX), Duration::from_secs(5));
        let huge = HttpOptions {
            backoff: Duration::MAX,
            backoff_max: Duration::MAX,
            ..HttpOptions::default()
        };
        assert_eq!(huge.retry_delay(40), Duration::MAX);
        assert!(huge.validate().is_err(), "a ceiling of Duration::MAX");
        let zero = HttpOptions {
            backoff: Duration::ZERO,
            ..HttpOptions::default()
        };
        assert_eq!(zero.retry_delay(30), Duration::ZERO);
    }

    #[test]
    fn timeouts_are_whole_seconds_within_their_range() {
        let with = |timeout| HttpOptions {
            timeout,
            ..HttpOptions::default()
        };
        assert_eq!(with(Duration::ZERO).timeout_s(), 1);
        assert_eq!(with(Duration::from_millis(1500)).timeout_s(), 2);
        assert_eq!(with(MAX_TIMEOUT).timeout_s(), 3600);
        assert!(with(MAX_TIMEOUT).validate().is_ok());
        let e = with(MAX_TIMEOUT + Duration::from_nanos(1))
            .validate()
            .unwrap_err();
        assert!(e.to_string().contains("1..=3600 s"), "{e}");
        // Never more than the range, whatever is asked: minreq adds it to an Instant.
        assert_eq!(with(Duration::MAX).timeout_s(), 3600);
    }

    #[test]
    fn redirect_hosts_are_the_authority_of_the_url() {
        assert_eq!(
            host_of("http://a.example:8080/w/world.toml"),
            "a.example:8080"
        );
        assert_eq!(host_of("http://b.example?x=1"), "b.example");
        assert_eq!(host_of("http://c"), "c");
    }

    #[test]
    fn only_plain_http_addresses_open() {
        for url in [
            "ftp://x/",
            "http://",
            "worlds/santa-cruz",
            "https://example.com/w",
        ] {
            let e = HttpSource::open(url, HttpOptions::default()).unwrap_err();
            assert!(e.to_string().contains(url), "{e}");
        }
        assert!(is_url("HTTP://a/") && is_url("https://a") && !is_url("worlds/x"));
    }
}
