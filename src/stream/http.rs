//! Worlds streamed over HTTP: [`HttpSource`], a [`TileSource`] that fetches a world's static
//! files (`world.toml`, `tiles/L{level}/{x}_{y}.{kind}`) from any HTTP server, object store or
//! CDN, and decodes them with the same checks as files on disk. A file's name goes onto the
//! address's path; a query in the address (a signed URL's token) is kept on every file's URL,
//! a fragment dropped, and the scheme and host are taken in any case.
//!
//! Each load runs on one of the streamer's blocking threads (at most `max_in_flight` at once),
//! so the streamer's priorities, its bound on loads in flight and its cancellation apply
//! unchanged. A request has a deadline ([`HttpOptions::timeout`], at most [`MAX_TIMEOUT`]);
//! transient failures (a connection refused or reset, a 5xx status, a body cut short by its
//! `Content-Length` or mid-chunk) are retried after a wait that doubles from
//! [`HttpOptions::backoff`] up to [`HttpOptions::backoff_max`], or after the wait a `503`'s
//! `Retry-After` asks for where it is longer, again at most `backoff_max` (each retry is logged
//! as a warning: what, why and when); anything else (a 4xx status, a stall past the deadline, a
//! body that is not a tile or is too large) fails the load at once, and the streamer counts it
//! as a fault exactly like a corrupt tile on disk.
//!
//! Bodies are streamed and never read past the most that such a file may hold: `world.toml` at
//! most [`MAX_MANIFEST_BYTES`] (16 MiB, as on disk), a tile file at most
//! [`crate::world::format::max_file_bytes`] for the world's tile size (twice its
//! raw samples plus 64 KiB of headers: 202 KiB for a height file of the default world's
//! 133-sample tiles). A `Content-Length` beyond the limit is refused before the body is read; a
//! body without one (chunked or ended by closing) is cut off at the limit; a response's head
//! (status line and headers) at 64 KiB. Redirects (301, 302, 303, 307, 308) are followed up
//! to [`MAX_REDIRECTS`] hops, each `Location` resolved against the URL that sent it (RFC 3986
//! 5.2) and checked as the world's address is: one to another scheme (`https` among them)
//! or an address with credentials is refused at once, naming it. A move to
//! another host is warned of (once per pair of hosts).
//!
//! Fetched files can be kept in an on-disk cache bounded in bytes, revalidated with the
//! server's `ETag` or `Last-Modified` (a conditional GET that costs a `304` and no body). Each
//! cached body is checked against the length and FNV-1a checksum in its metadata before use; a
//! damaged entry is dropped and the file fetched again unconditionally.
//!
//! Plain HTTP only (the client, `ureq`, is built without TLS); put a TLS-terminating proxy in
//! front for `https`.
//!
//! This module holds the options, the errors and the source; the requests and their bounded
//! reading are in `http/client.rs`, the disk cache in `http/cache.rs`.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::world::format::{
    check_stamp, decode_density, decode_grass_types, decode_heights, decode_material,
    max_file_bytes,
};
use crate::world::manifest::MAX_MANIFEST_BYTES;
use crate::world::{Manifest, ReadOptions, TileData, TileFile, TileId, World, WorldError};

use super::service::TileSource;

mod cache;
mod client;

use cache::DiskCache;
use client::Client;

/// A file on an HTTP server read in byte ranges (a Cloud-Optimised GeoTIFF or an `.hgt` tile a
/// bake reads in windows), with the tile client's deadlines and retries; nothing is cached.
pub struct RangeFile {
    client: client::Client,
    url: String,
    len: u64,
}

impl RangeFile {
    /// Opens `url`: its first byte is asked for, to learn its length (and that the server
    /// answers range requests).
    pub fn open(url: &str, options: HttpOptions) -> Result<RangeFile, WorldError> {
        check_authority(url)?;
        options.validate()?;
        let url = &WorldUrl::normalize(url);
        let client = client::Client::new(options, None);
        client.fetch_range(url, 1, None, Some([0, 1]))?;
        let len = client.range_total.load(Ordering::Relaxed);
        Ok(RangeFile {
            client,
            url: url.to_owned(),
            len,
        })
    }

    /// The file's length in bytes.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Whether the file is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// `count` bytes from `offset` (within the file).
    pub fn read_at(&self, offset: u64, count: u64) -> Result<Vec<u8>, WorldError> {
        if count == 0 {
            return Ok(Vec::new());
        }
        let body = self
            .client
            .fetch_range(&self.url, count, None, Some([offset, count]))?;
        if body.len() as u64 != count {
            return Err(HttpError::Truncated {
                url: self.url.clone(),
                expected: count,
                received: body.len() as u64,
                attempts: 1,
            }
            .into());
        }
        Ok(body)
    }

    /// The file's identity as its server gave it when it was opened, as one word: its length
    /// and a fingerprint of its `ETag` and `Last-Modified` (a bake's record of its inputs).
    pub fn identity(&self) -> String {
        self.client
            .range_identity
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .as_ref()
            .map_or_else(|| self.len.to_string(), client::RangeIdentity::word)
    }

    /// Requests sent, bytes received.
    pub fn stats(&self) -> (u64, u64) {
        (
            self.client.requests.load(Ordering::Relaxed),
            self.client.bytes.load(Ordering::Relaxed),
        )
    }
}

/// The longest deadline of one request that [`HttpOptions::timeout`] may ask for: one hour.
pub const MAX_TIMEOUT: Duration = Duration::from_secs(3600);

/// The longest wait between retries that [`HttpOptions::backoff_max`] may ask for: one minute.
pub const MAX_BACKOFF: Duration = Duration::from_secs(60);

/// Redirects followed for one file at most; more fail the file.
pub const MAX_REDIRECTS: usize = 5;

/// Why a file of a world over HTTP could not be had. Every variant names the URL (or the
/// option).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HttpError {
    /// The world's address is not a plain `http://` URL.
    #[error("{url}: not an address verdant can fetch: {problem}")]
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
    /// The longest wait before a retry, at most [`MAX_BACKOFF`] (60 s), also when a `503`'s
    /// `Retry-After` asks for longer. Default 5 s.
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

    /// The deadline of one request (with its redirects and its body) in whole seconds, within
    /// 1..=3600.
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

/// Refuses an `http://` address whose host is missing or whose port is not a number in
/// 1..=65535, before any request: the HTTP client would otherwise try the wrong port (99999
/// wrapped to 34463) or a lookup of nothing.
fn check_authority(url: &str) -> Result<(), HttpError> {
    let bad = |problem| HttpError::BadUrl {
        url: url.into(),
        problem,
    };
    if url
        .get(..8)
        .is_some_and(|s| s.eq_ignore_ascii_case("https://"))
    {
        return Err(bad(
            "https is not built in (the client speaks plain HTTP only): serve it over plain \
             http, or put a TLS proxy in front",
        ));
    }
    let rest = url.get("http://".len()..).unwrap_or("");
    let authority = rest.split(['/', '?', '#']).next().unwrap_or("");
    if let Some((_, host)) = authority.rsplit_once('@') {
        // Named without the credentials: they are not printed either.
        return Err(HttpError::BadUrl {
            url: format!("http://…@{host}/"),
            problem: "credentials in the address are not sent (the HTTP client does not, and \
                      plain HTTP would carry them in the clear): serve the world at an address \
                      without them",
        });
    }
    let (host, port) = if let Some(v6) = authority.strip_prefix('[') {
        let Some((host, after)) = v6.split_once(']') else {
            return Err(bad("an IPv6 host without its closing ]"));
        };
        if host.parse::<std::net::Ipv6Addr>().is_err() {
            return Err(bad(
                "not an IPv6 address between [ and ]: expected http://[IPv6]:PORT/PATH",
            ));
        }
        // Checked as an address: the host's colons are its own.
        let port = match after {
            "" => None,
            _ => match after.strip_prefix(':') {
                Some(port) => Some(port),
                None => return Err(bad("expected http://[IPv6]:PORT/PATH")),
            },
        };
        return check_port(port).map_err(bad);
    } else {
        match authority.rsplit_once(':') {
            Some((host, port)) => (host, Some(port)),
            None => (authority, None),
        }
    };
    if host.is_empty() {
        return Err(bad("no host: expected http://HOST[:PORT]/PATH"));
    }
    if host.contains(':') {
        // `host:1:2` would be fetched from host's port 80 by the HTTP client.
        return Err(bad(
            "more than one port (a host name holds no ':'): expected http://HOST[:PORT]/PATH",
        ));
    }
    check_port(port).map_err(bad)
}

/// A port as written after a host's `:` (none: the default): digits alone, without leading
/// zeros, in 1..=65535.
fn check_port(port: Option<&str>) -> Result<(), &'static str> {
    // `+80` and `080` parse as 80, but the HTTP client keeps the host's text as written and
    // takes the answer for a redirect.
    match port {
        Some(port)
            if !(port.bytes().all(|b| b.is_ascii_digit())
                && !port.starts_with('0')
                && port.parse::<u16>().is_ok_and(|p| p > 0)) =>
        {
            Err("the port must be a number in 1..=65535, in digits without leading zeros")
        }
        _ => Ok(()),
    }
}

/// Whether a world argument is an HTTP address rather than a folder.
pub fn is_url(s: &str) -> bool {
    crate::world::format::is_remote(std::path::Path::new(s))
}

/// A world's address, split so that a file's name can be joined onto it: the name goes onto
/// the path, and the query (a signed CDN or object-store URL carries its token there) after it.
#[derive(Clone, Debug, PartialEq, Eq)]
struct WorldUrl {
    /// `http://host[:port]/path/`: the scheme and host in lower case, the path as given and
    /// ending in `/`.
    base: String,
    /// `?query` as given, or empty.
    query: String,
}

impl WorldUrl {
    /// Splits `url` (already checked to be `http://` with a host); its fragment, which names
    /// nothing on the server, is dropped. An address that names the world's manifest
    /// (`.../world.toml`) is taken for its folder's.
    fn parse(url: &str) -> WorldUrl {
        let url = Self::normalize(url);
        let (path, query) = url.split_at(url.find('?').unwrap_or(url.len()));
        let path = match path.strip_suffix("/world.toml") {
            Some(folder) if folder.len() > "http://".len() => folder,
            _ => path,
        };
        WorldUrl {
            base: format!("{}/", path.trim_end_matches('/')),
            query: if query == "?" { "" } else { query }.to_string(),
        }
    }

    /// `url` with its scheme and host in lower case (which they are in any case, RFC 3986 6.2.2.1;
    /// the client library refuses an upper-case scheme), its path and query percent-encoded
    /// where they hold what a URL cannot (spaces, characters past ASCII; see [`encode_part`]),
    /// the dot segments of its path removed (`./`, `a/../`: [`remove_dot_segments`]), and
    /// without its fragment.
    fn normalize(url: &str) -> String {
        let url = url.split('#').next().unwrap_or(url);
        let Some((scheme, rest)) = url.split_once("://") else {
            return url.to_string();
        };
        let end = rest.find(['/', '?']).unwrap_or(rest.len());
        let (authority, after) = rest.split_at(end);
        // The user's name and password, if any, keep their case.
        let (user, host) = match authority.rsplit_once('@') {
            Some((user, host)) => (format!("{user}@"), host),
            None => (String::new(), authority),
        };
        let (path, query) = after.split_at(after.find('?').unwrap_or(after.len()));
        format!(
            "{}://{user}{}{}{}",
            scheme.to_ascii_lowercase(),
            host.to_ascii_lowercase(),
            // A dot written as its escape is a dot (RFC 3986 6.2.2.2: an unreserved
            // character's escape is the character), and a dot segment then.
            remove_dot_segments(
                &encode_part(path, b"")
                    .replace("%2E", ".")
                    .replace("%2e", ".")
            ),
            encode_part(query, b"?"),
        )
    }

    /// The URL of the world's file `name` (relative, `/`-separated, already percent-encoded).
    fn join(&self, name: &str) -> String {
        format!("{}{name}{}", self.base, self.query)
    }
}

/// `part` of a URL (its path, or with `also` = `?` its query) with every byte that RFC 3986 3.3
/// does not allow there percent-encoded (a space, a control, each byte of a character past
/// ASCII, a `%` that starts no escape), so that an address written as a folder's name (`a
/// b/wörld/`) is sent as one. What it allows, `%XX` escapes among it, is kept as it is: an
/// address already encoded is unchanged.
fn encode_part(part: &str, also: &[u8]) -> String {
    let bytes = part.as_bytes();
    let mut out = String::with_capacity(part.len());
    for (i, &b) in bytes.iter().enumerate() {
        let escape = b == b'%'
            && bytes.get(i + 1).is_some_and(u8::is_ascii_hexdigit)
            && bytes.get(i + 2).is_some_and(u8::is_ascii_hexdigit);
        let allowed =
            b.is_ascii_alphanumeric() || b"-._~!$&'()*+,;=:@/".contains(&b) || also.contains(&b);
        if escape || allowed {
            out.push(char::from(b));
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// `path` (empty or starting with `/`) without its dot segments, as RFC 3986 5.2.4 has it: a
/// `.` segment goes, a `..` takes the segment before it along (none above the root), and a
/// path that ends in either ends in `/`: `/a/./b/../c` is `/a/c`, `/a/b/..` is `/a/`.
fn remove_dot_segments(path: &str) -> String {
    let Some(rest) = path.strip_prefix('/') else {
        return path.to_string();
    };
    let segments: Vec<&str> = rest.split('/').collect();
    let last = segments.len() - 1;
    let mut out: Vec<&str> = Vec::with_capacity(segments.len());
    for (i, segment) in segments.into_iter().enumerate() {
        match segment {
            "." | ".." => {
                if segment == ".." {
                    out.pop();
                }
                if i == last {
                    out.push("");
                }
            }
            _ => out.push(segment),
        }
    }
    format!("/{}", out.join("/"))
}

/// A world's tiles fetched over HTTP; see the module docs.
pub struct HttpSource {
    url: WorldUrl,
    manifest: Manifest,
    client: Client,
}

impl std::fmt::Debug for HttpSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HttpSource")
            .field("base", &self.url.base)
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
        check_authority(url)?;
        options.validate()?;
        let url = WorldUrl::parse(url);
        let cache = match &options.cache {
            Some(c) => Some(Mutex::new(DiskCache::open(c)?)),
            None => None,
        };
        let client = Client::new(options, cache);
        let manifest_url = url.join("world.toml");
        let bytes = client.fetch(&manifest_url, MAX_MANIFEST_BYTES, None)?;
        let path = Path::new(&manifest_url);
        let text = String::from_utf8(bytes).map_err(|e| WorldError::ManifestSyntax {
            path: path.to_path_buf(),
            message: format!("not UTF-8 text: {e}"),
        })?;
        let manifest = Manifest::parse(&text, path)?;
        let world = World {
            dir: PathBuf::from(&url.base),
            manifest: manifest.clone(),
        };
        Ok((
            world,
            HttpSource {
                url,
                manifest,
                client,
            },
        ))
    }

    /// The world's address, ending in `/`: its scheme and host in lower case, without its query
    /// (which every file's URL carries) or fragment.
    pub fn base_url(&self) -> &str {
        &self.url.base
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
        self.url.join(&format!("tiles/{}", kind.name_in_tiles(id)))
    }
}

/// What a part of a file's address percent-encodes: everything but RFC 3986's unreserved
/// characters (letters, digits, `-`, `.`, `_`, `~`).
const UNRESERVED_KEPT: &percent_encoding::AsciiSet = &percent_encoding::NON_ALPHANUMERIC
    .remove(b'-')
    .remove(b'.')
    .remove(b'_')
    .remove(b'~');

impl TileSource for HttpSource {
    fn load(&self, id: TileId) -> Result<TileData, WorldError> {
        self.load_cancellable(id, &AtomicBool::new(false))
    }

    /// Fetches `{base}{name}{query}`, each part of `name` percent-encoded; a name that leaves
    /// the world's folder (`..`, an absolute path) is refused without a request.
    fn read_file(&self, name: &Path, max: u64) -> Result<Vec<u8>, WorldError> {
        use std::path::Component;
        let mut parts = Vec::new();
        for c in name.components() {
            match c {
                Component::Normal(part) => parts.push(
                    percent_encoding::utf8_percent_encode(&part.to_string_lossy(), UNRESERVED_KEPT)
                        .to_string(),
                ),
                Component::CurDir => {}
                _ => {
                    return Err(WorldError::Io {
                        path: PathBuf::from(format!("{}{}", self.url.base, name.display())),
                        source: std::io::Error::new(
                            std::io::ErrorKind::InvalidInput,
                            "a world's file is named relative to its folder, within it",
                        ),
                    });
                }
            }
        }
        let url = self.url.join(&parts.join("/"));
        Ok(self.client.fetch(&url, max, None)?)
    }

    /// Fetches the tile's files one after another; once `cancelled` is set, no further request
    /// (file or retry) is sent.
    fn load_cancellable(&self, id: TileId, cancelled: &AtomicBool) -> Result<TileData, WorldError> {
        let pyramid = &self.manifest.pyramid;
        if !pyramid.is_stored(id) {
            return Err(WorldError::TileNotStored {
                path: PathBuf::from(&self.url.base),
                id,
            });
        }
        let size = pyramid.samples_per_side();
        let options = ReadOptions {
            height_range_m: self.manifest.height_range_m,
            grass_type_count: self.manifest.grass_types.len(),
            materials: self.manifest.materials,
            bake_id: self.manifest.bake_id_value(),
        };
        let get = |kind| -> Result<(Vec<u8>, String), WorldError> {
            let url = self.tile_url(id, kind);
            let bytes = self
                .client
                .fetch(&url, max_file_bytes(kind, size), Some(cancelled))?;
            check_stamp(&bytes, id, kind, &options, Path::new(&url))?;
            Ok((bytes, url))
        };
        let (bytes, url) = get(TileFile::Height)?;
        let heights = decode_heights(&bytes, size, &options, Path::new(&url))?;
        let (bytes, url) = get(TileFile::Type)?;
        let grass_type = decode_grass_types(&bytes, size, &options, Path::new(&url))?;
        let (bytes, url) = get(TileFile::Density)?;
        let density = decode_density(&bytes, size, Path::new(&url))?;
        let material = if options.materials {
            let (bytes, url) = get(TileFile::Material)?;
            decode_material(&bytes, size, Path::new(&url))?
        } else {
            Vec::new()
        };
        Ok(TileData {
            id,
            size,
            heights,
            grass_type,
            density,
            material,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Addresses with no host or a port outside 1..=65535, a bracketed host that is not an
    /// IPv6 address, and credentials are refused before any request; hosts by name, IPv4 and
    /// IPv6 with or without a port pass.
    #[test]
    fn an_address_without_a_host_or_with_a_bad_port_is_refused() {
        for bad in [
            "http:///",
            "http://:8000/w",
            "http://127.0.0.1:99999/",
            "http://127.0.0.1:0/",
            "http://127.0.0.1:/",
            "http://h:80x/",
            "http://127.0.0.1:8123:9099/",
            "http://127.0.0.1:+44453/",
            "http://127.0.0.1:044453/",
            "http://h::80/",
            "http://[::1",
            "http://[::1]x/",
            "http://[::1]:080/w",
            "http://[host]:8000/w",
            "http://[127.0.0.1]/w",
        ] {
            let err = check_authority(bad).err().map(|e| e.to_string());
            assert!(
                err.as_deref().is_some_and(|e| e.starts_with(bad)),
                "{bad}: {err:?}"
            );
            let open = HttpSource::open(bad, HttpOptions::default()).err().unwrap();
            assert!(
                open.to_string()
                    .contains("not an address verdant can fetch"),
                "{bad}: {open}"
            );
        }
        for good in [
            "http://localhost/",
            "http://example.org:8080/worlds/a?x=1",
            "http://10.0.0.1:65535",
            "http://[::1]/w",
            "http://[::1]:8000/w",
            "http://[2001:db8::7]:80/w",
        ] {
            assert!(check_authority(good).is_ok(), "{good}");
        }
        // Credentials are refused, and not repeated in the message.
        let err = check_authority("http://user:secret@host:1/w")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("credentials") && !err.contains("secret"),
            "{err}"
        );
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
        // Never more than the range, whatever is asked: it is added to an Instant.
        assert_eq!(with(Duration::MAX).timeout_s(), 3600);
    }

    #[test]
    fn file_names_join_the_path_before_the_query_and_the_fragment_goes() {
        for (url, base, query) in [
            ("http://h/w/", "http://h/w/", ""),
            ("http://h/w", "http://h/w/", ""),
            ("http://h", "http://h/", ""),
            ("http://h?x=1", "http://h/", "?x=1"),
            (
                "http://h:8/w/?x=1&sig=A%2Fb",
                "http://h:8/w/",
                "?x=1&sig=A%2Fb",
            ),
            ("http://h/w?", "http://h/w/", ""),
            ("http://h/w#top", "http://h/w/", ""),
            ("http://h/w#a?b", "http://h/w/", ""),
            ("http://h/w?x=1#f", "http://h/w/", "?x=1"),
            (
                "HTTP://Example.ORG:80/Worlds/A/?Sig=XyZ",
                "http://example.org:80/Worlds/A/",
                "?Sig=XyZ",
            ),
            (
                "Http://Me:PassWord@HOST/W",
                "http://Me:PassWord@host/W/",
                "",
            ),
            ("http://[::ABCD]:8/w", "http://[::abcd]:8/w/", ""),
        ] {
            let parsed = WorldUrl::parse(url);
            assert_eq!(
                (parsed.base.as_str(), parsed.query.as_str()),
                (base, query),
                "{url}"
            );
        }
        let url = WorldUrl::parse("HTTP://H/w/?t=1#x");
        assert_eq!(
            url.join("tiles/L0/0_0.height.exr"),
            "http://h/w/tiles/L0/0_0.height.exr?t=1"
        );
    }

    /// What a URL cannot hold is percent-encoded, byte by byte of its UTF-8; what it can, and
    /// escapes already made, are kept.
    #[test]
    fn an_address_is_percent_encoded_where_it_must_be() {
        for (url, normal) in [
            ("http://h/a b/", "http://h/a%20b/"),
            (
                "http://h/w\u{f6}rld/\u{1f332}",
                "http://h/w%C3%B6rld/%F0%9F%8C%B2",
            ),
            ("http://h/a%20b/c%2Fd", "http://h/a%20b/c%2Fd"),
            ("http://h/100%/%4", "http://h/100%25/%254"),
            ("http://h/%zz", "http://h/%25zz"),
            (
                "http://h/a\"b<c>^`{|}",
                "http://h/a%22b%3Cc%3E%5E%60%7B%7C%7D",
            ),
            (
                "http://h/ok-._~!$&'()*+,;=:@/",
                "http://h/ok-._~!$&'()*+,;=:@/",
            ),
            ("http://h/w?q=a b&r=/?x", "http://h/w?q=a%20b&r=/?x"),
            ("http://h/w?x#frag ment", "http://h/w?x"),
            ("http://h/p?q", "http://h/p?q"),
        ] {
            assert_eq!(WorldUrl::normalize(url), normal, "{url}");
        }
    }

    /// Dot segments go as RFC 3986 5.2.4 has it (its examples among these), and an address
    /// naming the world's manifest is its folder's.
    #[test]
    fn dot_segments_are_removed_and_a_manifest_names_its_folder() {
        for (path, without) in [
            ("/a/b/c/./../../g", "/a/g"),
            ("/mid/content=5/../6", "/mid/6"),
            ("/./", "/"),
            ("/.", "/"),
            ("/..", "/"),
            ("/../../a", "/a"),
            ("/a/b/..", "/a/"),
            ("/a/./b/", "/a/b/"),
            ("/a//b/../c", "/a//c"),
            ("/a/.b/..c/", "/a/.b/..c/"),
            ("", ""),
            ("/", "/"),
        ] {
            assert_eq!(remove_dot_segments(path), without, "{path}");
        }
        for (url, base, query) in [
            ("http://h/w/world.toml", "http://h/w/", ""),
            ("http://h/world.toml?t=1", "http://h/", "?t=1"),
            ("http://h/w/./tiles/../world.toml", "http://h/w/", ""),
            ("http://h/w/my-world.toml", "http://h/w/my-world.toml/", ""),
            ("http://h/./", "http://h/", ""),
            ("http://h/w/%2E%2e/v/%2E/", "http://h/v/", ""),
            ("http://h/w/a%2Eb/", "http://h/w/a.b/", ""),
            ("http://h/a/b/../../c/.", "http://h/c/", ""),
        ] {
            let parsed = WorldUrl::parse(url);
            assert_eq!(
                (parsed.base.as_str(), parsed.query.as_str()),
                (base, query),
                "{url}"
            );
        }
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
