//! Worlds streamed over HTTP: [`HttpSource`], a [`TileSource`] that fetches a world's static
//! files (`world.toml`, `tiles/L{level}/{x}_{y}.{kind}`) from any HTTP server, object store or
//! CDN, and decodes them with the same checks as files on disk.
//!
//! Each load runs on one of the streamer's blocking threads (at most `max_in_flight` at once),
//! so the streamer's priorities, its bound on loads in flight and its cancellation apply
//! unchanged. A request has a deadline ([`HttpOptions::timeout`]); transient failures (a
//! connection refused or reset, a 5xx status, a body cut short) are retried with doubling
//! backoff; anything else (a 4xx status, a stall past the deadline, a body that is not a tile)
//! fails the load at once, and the streamer counts it as a fault exactly like a corrupt tile on
//! disk. Fetched files can be kept in an on-disk cache bounded in bytes, revalidated with the
//! server's `ETag` or `Last-Modified` (a conditional GET that costs a `304` and no body).
//!
//! Plain HTTP only (the client, `minreq`, is built without TLS); put a TLS-terminating proxy in
//! front for `https`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use crate::world::format::{decode_density, decode_grass_types, decode_heights, max_file_bytes};
use crate::world::manifest::MAX_MANIFEST_BYTES;
use crate::world::{Manifest, ReadOptions, TileData, TileFile, TileId, World, WorldError};

use super::service::TileSource;

/// Why a file of a world over HTTP could not be had. Every variant names the URL.
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
    /// The body is larger than any such file may be.
    #[error("{url}: {size} bytes, more than the {max} that this file may hold")]
    TooLarge {
        /// The file's URL.
        url: String,
        /// Bytes received.
        size: u64,
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
    /// Deadline of one request, whole seconds (rounded up, at least 1 s). Default 10 s.
    pub timeout: Duration,
    /// Retries of a transient failure (connection error, 5xx, body cut short). Default 3.
    pub retries: u32,
    /// Wait before the first retry, doubled before each next one. Default 200 ms.
    pub backoff: Duration,
    /// The on-disk cache of fetched files; none by default.
    pub cache: Option<HttpCacheConfig>,
}

impl Default for HttpOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(10),
            retries: 3,
            backoff: Duration::from_millis(200),
            cache: None,
        }
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
    /// Fetches and validates `{url}/world.toml` and returns the world (whose `dir` is the URL,
    /// for messages only) and the source of its tiles.
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
        let base = format!("{}/", url.trim_end_matches('/'));
        let cache = match &options.cache {
            Some(c) => Some(Mutex::new(DiskCache::open(c)?)),
            None => None,
        };
        let client = Client {
            options,
            cache,
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
    /// Fetches one file (through the cache when there is one), retrying transient failures.
    fn fetch(
        &self,
        url: &str,
        max: u64,
        cancelled: Option<&AtomicBool>,
    ) -> Result<Vec<u8>, HttpError> {
        let cached = self
            .cache
            .as_ref()
            .and_then(|c| c.lock().ok().and_then(|mut c| c.get(url)));
        let timeout_s = self.options.timeout.as_secs_f64().ceil().max(1.0) as u64;
        let mut attempt = 0;
        loop {
            if cancelled.is_some_and(|c| c.load(Ordering::Relaxed)) {
                return Err(HttpError::Cancelled { url: url.into() });
            }
            attempt += 1;
            let mut request = minreq::get(url).with_timeout(timeout_s);
            if let Some((validator, _)) = &cached {
                request = match validator {
                    Validator::ETag(tag) => request.with_header("If-None-Match", tag.as_str()),
                    Validator::LastModified(date) => {
                        request.with_header("If-Modified-Since", date.as_str())
                    }
                };
            }
            self.requests.fetch_add(1, Ordering::Relaxed);
            let outcome = match request.send() {
                Err(minreq::Error::IoError(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                    ) =>
                {
                    return Err(HttpError::TimedOut {
                        url: url.into(),
                        timeout_s,
                    });
                }
                Err(e) => Err(HttpError::Transport {
                    url: url.into(),
                    attempts: attempt,
                    message: e.to_string(),
                }),
                Ok(response) => self.accept(url, response, max, attempt, &cached),
            };
            match outcome {
                Ok(bytes) => return Ok(bytes),
                Err(e) if attempt <= self.options.retries && is_transient(&e) => {
                    self.retries.fetch_add(1, Ordering::Relaxed);
                    let wait = self
                        .options
                        .backoff
                        .saturating_mul(1 << (attempt - 1).min(16));
                    log::debug!("{e}; retrying in {} ms", wait.as_millis());
                    std::thread::sleep(wait);
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Checks one response and returns its body (or the cached one on a `304`).
    fn accept(
        &self,
        url: &str,
        response: minreq::Response,
        max: u64,
        attempts: u32,
        cached: &Option<(Validator, Vec<u8>)>,
    ) -> Result<Vec<u8>, HttpError> {
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
        let expected = response
            .headers
            .get("content-length")
            .and_then(|v| v.trim().parse::<u64>().ok());
        let validator = Validator::from_headers(&response.headers);
        let body = response.into_bytes();
        self.bytes.fetch_add(body.len() as u64, Ordering::Relaxed);
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
        if body.len() as u64 > max {
            return Err(HttpError::TooLarge {
                url: url.into(),
                size: body.len() as u64,
                max,
            });
        }
        if let (Some(cache), Some(validator)) = (&self.cache, validator)
            && let Ok(mut cache) = cache.lock()
        {
            cache.put(url, &validator, &body);
        }
        Ok(body)
    }
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
        HttpError::Transport { .. } | HttpError::Truncated { .. } => true,
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

/// Fetched bodies on disk, one `{key}.body` and `{key}.meta` (the URL and the validator) per
/// URL, the key a hash of the URL; the least recently used go first beyond `max_bytes`.
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
        // FNV-1a, 64 bits: stable across runs and platforms.
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in url.bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        format!("{h:016x}")
    }

    fn get(&mut self, url: &str) -> Option<(Validator, Vec<u8>)> {
        let key = Self::key(url);
        self.entries.get(&key)?;
        let meta = std::fs::read_to_string(self.dir.join(format!("{key}.meta"))).ok()?;
        let mut lines = meta.lines();
        if lines.next()? != url {
            return None;
        }
        let validator = Validator::from_line(lines.next()?)?;
        let body = std::fs::read(self.dir.join(format!("{key}.body"))).ok()?;
        self.clock += 1;
        if let Some(e) = self.entries.get_mut(&key) {
            e.1 = self.clock;
        }
        Some((validator, body))
    }

    fn put(&mut self, url: &str, validator: &Validator, body: &[u8]) {
        let size = body.len() as u64;
        if size > self.max_bytes {
            return;
        }
        let key = Self::key(url);
        self.remove(&key);
        self.evict(size);
        let meta = format!("{url}\n{}\n", validator.to_line());
        let tmp = self.dir.join(format!("{key}.tmp"));
        let written = std::fs::write(&tmp, body)
            .and_then(|()| std::fs::write(self.dir.join(format!("{key}.meta")), meta))
            .and_then(|()| std::fs::rename(&tmp, self.dir.join(format!("{key}.body"))));
        if let Err(e) = written {
            log::warn!("{}: tile cache: {e}", self.dir.display());
            return;
        }
        self.clock += 1;
        self.entries.insert(key, (size, self.clock));
        self.bytes += size;
    }

    fn remove(&mut self, key: &str) {
        if let Some((size, _)) = self.entries.remove(key) {
            self.bytes -= size;
            let _ = std::fs::remove_file(self.dir.join(format!("{key}.body")));
            let _ = std::fs::remove_file(self.dir.join(format!("{key}.meta")));
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
        assert!(cache.get("http://h/a").is_some()); // a is now more recent than b
        cache.put("http://h/c", &tag, &[3; 100]);
        assert!(cache.bytes <= 250);
        assert!(
            cache.get("http://h/b").is_none(),
            "b was the least recently used"
        );
        assert_eq!(cache.get("http://h/a").unwrap().1, vec![1; 100]);
        assert_eq!(
            cache.get("http://h/c").unwrap(),
            (tag.clone(), vec![3; 100])
        );
        cache.put("http://h/huge", &tag, &[0; 300]);
        assert!(cache.get("http://h/huge").is_none());
        // Reopened, it finds its files and still keeps within its bytes.
        drop(cache);
        let small = HttpCacheConfig {
            max_bytes: 100,
            ..config
        };
        let cache = DiskCache::open(&small).unwrap();
        assert!(cache.bytes <= 100 && cache.entries.len() == 1);
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
