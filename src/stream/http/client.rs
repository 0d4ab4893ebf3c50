//! The requests of an [`super::HttpSource`]: deadlines, retries with backoff, redirects, and
//! bodies read no further than the most a file may hold, through the disk cache.

use std::collections::VecDeque;
use std::io::Read;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use super::cache::{DiskCache, Validator};
use super::{
    HttpError, HttpOptions, MAX_REDIRECTS, WorldUrl, check_authority, remove_dot_segments,
};

/// The most bytes of a response's status line and headers (a server that sends more is
/// refused rather than buffered).
const MAX_HEAD_BYTES: usize = 64 << 10;

/// The most bytes set aside for a body before any of it arrives. Past it the body grows only as
/// its bytes come: a `Content-Length` (or a range asked for) of terabytes costs nothing until
/// the server sends them, and the body never outgrows its `max` in any case.
const MAX_PREALLOCATED: u64 = 1 << 20;

/// The most pairs of hosts whose redirect is remembered as reported; past it the oldest is
/// forgotten (and warned of again if it comes back), so that a server that redirects to ever
/// new hosts does not grow the client.
pub(super) const MAX_REDIRECT_PAIRS: usize = 64;

/// The requests, their retries, the cache and the counters.
pub(super) struct Client {
    pub(super) options: HttpOptions,
    /// The HTTP/1.1 client: no proxy, no pooled connections (a connection per request, as
    /// the servers' fault counts and the retries expect), heads of at most [`MAX_HEAD_BYTES`],
    /// statuses returned rather than made errors, redirects left to [`Client::fetch_once`].
    agent: ureq::Agent,
    pub(super) cache: Option<Mutex<DiskCache>>,
    /// Pairs of hosts (from, to) whose redirect has been reported, oldest first; at most
    /// [`MAX_REDIRECT_PAIRS`].
    pub(super) redirects_seen: Mutex<VecDeque<(String, String)>>,
    pub(super) requests: AtomicU64,
    pub(super) retries: AtomicU64,
    pub(super) cache_hits: AtomicU64,
    pub(super) bytes: AtomicU64,
    /// The whole length of the file the last range request read part of.
    pub(super) range_total: AtomicU64,
    /// What the first range response said of its file: its whole length, its `ETag` and its
    /// `Last-Modified`. Every later range response must say the same: a file replaced while
    /// it is read in ranges would otherwise give parts of two versions.
    pub(super) range_identity: Mutex<Option<RangeIdentity>>,
    /// A file came without a validator and so could not be cached: said once.
    pub(super) uncacheable_told: std::sync::atomic::AtomicBool,
}

impl Client {
    /// A client with these options and this disk cache, its counters at zero.
    pub(super) fn new(options: HttpOptions, cache: Option<Mutex<DiskCache>>) -> Client {
        let config = ureq::Agent::config_builder()
            .proxy(None)
            .http_status_as_error(false)
            .max_redirects(0)
            .max_response_header_size(MAX_HEAD_BYTES)
            .max_idle_connections(0)
            .max_idle_connections_per_host(0)
            .user_agent(concat!("verdant/", env!("CARGO_PKG_VERSION")))
            .build();
        Client {
            options,
            agent: ureq::Agent::new_with_config(config),
            cache,
            redirects_seen: Mutex::new(VecDeque::new()),
            requests: AtomicU64::new(0),
            retries: AtomicU64::new(0),
            cache_hits: AtomicU64::new(0),
            bytes: AtomicU64::new(0),
            range_total: AtomicU64::new(0),
            range_identity: Mutex::new(None),
            uncacheable_told: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// Fetches one file of at most `max` bytes (through the cache when there is one),
    /// retrying transient failures.
    pub(super) fn fetch(
        &self,
        url: &str,
        max: u64,
        cancelled: Option<&AtomicBool>,
    ) -> Result<Vec<u8>, HttpError> {
        self.fetch_range(url, max, cancelled, None)
    }

    /// [`Client::fetch`], or with `range` (first byte, bytes) those bytes of the file by a range
    /// request, which the server must answer with exactly them (`206 Partial Content`); ranges
    /// bypass the disk cache. Returns the body and, for a range, the file's whole length.
    pub(super) fn fetch_range(
        &self,
        url: &str,
        max: u64,
        cancelled: Option<&AtomicBool>,
        range: Option<[u64; 2]>,
    ) -> Result<Vec<u8>, HttpError> {
        let cached = if range.is_some() {
            None
        } else {
            self.cache
                .as_ref()
                .and_then(|c| c.lock().ok().and_then(|mut c| c.get(url, max)))
        };
        let is_cancelled = || cancelled.is_some_and(|c| c.load(Ordering::Relaxed));
        let mut attempt = 0;
        loop {
            if is_cancelled() {
                return Err(HttpError::Cancelled { url: url.into() });
            }
            attempt += 1;
            self.requests.fetch_add(1, Ordering::Relaxed);
            let mut retry_after = None;
            match self.fetch_once(url, max, attempt, &cached, range, &mut retry_after) {
                Ok(bytes) => return Ok(bytes),
                Err(e) if attempt <= self.options.retries && is_transient(&e) => {
                    self.retries.fetch_add(1, Ordering::Relaxed);
                    // A wait the server asked for (a 503's Retry-After) is honoured up to the
                    // longest wait between retries.
                    let backoff = self.options.retry_delay(attempt);
                    let asked = retry_after.map(|a: Duration| a.min(self.options.backoff_max));
                    let wait = asked.map_or(backoff, |a| a.max(backoff));
                    let why = match retry_after {
                        Some(a) => format!(" (the server asked for {} s)", a.as_secs()),
                        None => String::new(),
                    };
                    log::warn!(
                        "{e}; retry {attempt} of {} in {:.1} s{why}",
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
    /// cached body on a `304`), after at most [`MAX_REDIRECTS`] redirects, all within one
    /// deadline. A `503` with a `Retry-After` of seconds sets `retry_after`.
    pub(super) fn fetch_once(
        &self,
        url: &str,
        max: u64,
        attempts: u32,
        cached: &Option<(Validator, Vec<u8>)>,
        range: Option<[u64; 2]>,
        retry_after: &mut Option<Duration>,
    ) -> Result<Vec<u8>, HttpError> {
        let timeout_s = self.options.timeout_s();
        let deadline = Instant::now() + Duration::from_secs(timeout_s);
        let timed_out = || HttpError::TimedOut {
            url: url.into(),
            timeout_s,
        };
        let bad = |message: String| HttpError::BadResponse {
            url: url.into(),
            message,
        };
        // Redirects are followed here rather than by the library: each target is resolved
        // against the URL that sent it (RFC 3986 5.2) and checked as the world's address is,
        // and one that cannot be fetched is refused at once.
        let mut target = url.to_string();
        let mut redirects = 0;
        let mut response = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(timed_out());
            }
            let mut request = self
                .agent
                .get(target.as_str())
                .config()
                .timeout_global(Some(left))
                .build();
            if let Some([first, count]) = range {
                let last = first + count.max(1) - 1;
                request = request.header("Range", format!("bytes={first}-{last}"));
            }
            if let Some((validator, _)) = cached {
                request = match validator {
                    Validator::ETag(tag) => request.header("If-None-Match", tag.as_str()),
                    Validator::LastModified(date) => {
                        request.header("If-Modified-Since", date.as_str())
                    }
                };
            }
            let response = request
                .call()
                .map_err(|e| call_error(&shown(url, &target), attempts, timeout_s, e))?;
            let status = response.status().as_u16();
            if !matches!(status, 301 | 302 | 303 | 307 | 308) {
                break response;
            }
            let Some(location) = response.headers().get("location") else {
                return Err(bad(format!("HTTP {status} redirect without a Location")));
            };
            let next = redirect_target(&target, &String::from_utf8_lossy(location.as_bytes()))
                .map_err(|problem| bad(format!("HTTP {status} redirect to {problem}")))?;
            if redirects == MAX_REDIRECTS {
                return Err(bad(format!(
                    "more than {MAX_REDIRECTS} redirects (the last to {}): at most \
                     {MAX_REDIRECTS} are followed",
                    without_userinfo(&next)
                )));
            }
            redirects += 1;
            target = next;
        };
        self.note_redirect(url, &target);
        // Errors from here on name the address that answered too, where it was redirected.
        let at = shown(url, &target);
        let bad = |message: String| HttpError::BadResponse {
            url: at.clone(),
            message,
        };
        let timed_out = || HttpError::TimedOut {
            url: at.clone(),
            timeout_s,
        };
        let status = response.status().as_u16();
        if status == 304 {
            let Some((_, body)) = cached else {
                return Err(bad(
                    "HTTP 304 Not Modified to a request that was not conditional (nothing was \
                     cached to fall back on)"
                        .into(),
                ));
            };
            self.cache_hits.fetch_add(1, Ordering::Relaxed);
            return Ok(body.clone());
        }
        let header = |name: &str| {
            response
                .headers()
                .get(name)
                .map(|v| String::from_utf8_lossy(v.as_bytes()).trim().to_string())
        };
        if !(200..300).contains(&status) {
            // Seconds only: a date would need the clock of the server, which may be wrong.
            if status == 503 {
                *retry_after = header("retry-after")
                    .and_then(|v| v.parse::<u64>().ok())
                    .map(Duration::from_secs);
            }
            return Err(HttpError::Status {
                url: at.clone(),
                status: i32::from(status),
                // The client library keeps the status, not the server's words for it (which a
                // client is to ignore, RFC 9112 4): its standard reason.
                reason: response
                    .status()
                    .canonical_reason()
                    .unwrap_or("(unknown status)")
                    .to_string(),
                attempts,
            });
        }
        // A whole file comes as a 200 alone: a 206 (a part) or a 204 (nothing) to a request
        // without a range would be taken, and cached, for the file.
        if range.is_none() && status != 200 {
            return Err(bad(format!(
                "HTTP {status} to a request for the whole file (only 200 carries it)"
            )));
        }
        // Chunked is the only transfer coding read: another (gzip, compress) would leave the
        // body coded, taken and cached for the file's bytes.
        let codings: Vec<String> = response
            .headers()
            .get_all("transfer-encoding")
            .iter()
            .map(|v| String::from_utf8_lossy(v.as_bytes()).trim().to_string())
            .collect();
        if let Some(coding) = codings.iter().find(|c| !c.eq_ignore_ascii_case("chunked")) {
            return Err(bad(format!(
                "Transfer-Encoding {coding:?}: only chunked is read (serve the file without \
                 another coding)"
            )));
        }
        // Nothing asked for a coded body (no Accept-Encoding is sent): one sent coded would be
        // taken, and cached, for the file's bytes.
        // Every such header and every coding each lists (a second header is a second list).
        let content_codings: Vec<String> = response
            .headers()
            .get_all("content-encoding")
            .iter()
            .flat_map(|v| {
                String::from_utf8_lossy(v.as_bytes())
                    .split(',')
                    .map(|c| c.trim().to_string())
                    .collect::<Vec<_>>()
            })
            .collect();
        if let Some(coding) = content_codings
            .iter()
            .find(|c| !c.is_empty() && !c.eq_ignore_ascii_case("identity"))
        {
            return Err(bad(format!(
                "Content-Encoding {coding:?}, which was not asked for and is not read"
            )));
        }
        // A range's body is what was asked, whatever the server claims of the file's length.
        let max = match range {
            Some([_, count]) => max.min(count.max(1)),
            None => max,
        };
        if let Some([first, count]) = range {
            if status != 206 {
                return Err(bad(format!(
                    "HTTP {status} to a range request: the server must answer range requests \
                     (206 Partial Content) for a DEM to be read in windows"
                )));
            }
            let (etag, last_modified) = (header("etag"), header("last-modified"));
            // A Last-Modified that is the answer's own date is the time it was made (a script
            // that serves the file), not the file's: no validator.
            let last_modified = last_modified.filter(|m| Some(m) != header("date").as_ref());
            // "bytes FIRST-LAST/TOTAL"
            let header = header("content-range").unwrap_or_default();
            let parsed = header
                .strip_prefix("bytes ")
                .and_then(|r| r.split_once('/'))
                .and_then(|(span, total)| {
                    let (a, b) = span.split_once('-')?;
                    Some((
                        a.parse::<u64>().ok()?,
                        b.parse::<u64>().ok()?,
                        total.parse::<u64>().ok()?,
                    ))
                });
            match parsed {
                Some((a, b, total)) if a == first && b + 1 == first + count.max(1) => {
                    let now = RangeIdentity {
                        total,
                        host: host_of(&target).to_ascii_lowercase(),
                        etag,
                        last_modified,
                    };
                    let mut seen = self
                        .range_identity
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    match &*seen {
                        None => *seen = Some(now),
                        Some(was) => {
                            if let Some(change) = was.change_to(&now) {
                                return Err(bad(format!(
                                    "the file changed while it was read ({change}): its parts \
                                     would mix two versions; read it again once it has stopped \
                                     changing"
                                )));
                            }
                        }
                    }
                    self.range_total.store(total, Ordering::Relaxed);
                }
                _ => {
                    return Err(bad(format!(
                        "Content-Range {header:?} to a request for bytes {first}-{}",
                        first + count.max(1) - 1
                    )));
                }
            }
        }
        // The library has refused a Content-Length that is not a number, and differing ones
        // (RFC 9112 6.3); a chunked or close-delimited body has none.
        let expected = response.body().content_length();
        if let Some(size) = expected
            && size > max
        {
            return Err(HttpError::TooLarge {
                url: at.clone(),
                size,
                max,
            });
        }
        // Every coding is chunked (any other was refused above).
        let chunked = expected.is_none() && !codings.is_empty();
        let validator = Validator::from_headers(response.headers());
        // A body that only the connection's close ends (no length, not chunked) may have been
        // cut short by a reset without a sign of it: read, but not kept in the disk cache.
        let delimited = expected.is_some() || chunked;
        let capacity = expected.unwrap_or(64 << 10).min(max).min(MAX_PREALLOCATED);
        let mut body = Vec::with_capacity(capacity as usize);
        // One byte past the limit tells a body that is too long from one that just fits.
        let read = response
            .body_mut()
            .as_reader()
            .take(max.saturating_add(1))
            .read_to_end(&mut body);
        self.bytes.fetch_add(body.len() as u64, Ordering::Relaxed);
        if let Err(e) = read {
            let received = body.len() as u64;
            let transport = |e: &dyn std::fmt::Display| HttpError::Transport {
                url: at.clone(),
                attempts,
                message: format!("body after {received} bytes: {e}"),
            };
            // The library ends a body early with an error: the connection closed before its
            // `Content-Length` or its last chunk.
            return Err(match ureq::Error::from(e) {
                ureq::Error::Timeout(_) => timed_out(),
                ureq::Error::Io(e) if is_timeout(&e) => timed_out(),
                ureq::Error::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
                    match expected {
                        Some(expected) => HttpError::Truncated {
                            url: at.clone(),
                            expected,
                            received,
                            attempts,
                        },
                        None if chunked => HttpError::ChunksCutShort {
                            url: at.clone(),
                            received,
                            attempts,
                        },
                        None => transport(&e),
                    }
                }
                ureq::Error::Io(e) => transport(&e),
                // A chunk size that is not one: the server's fault, not the connection's.
                ureq::Error::Protocol(e) => {
                    bad(format!("body not well-formed after {received} bytes: {e}"))
                }
                e => transport(&e),
            });
        }
        if body.len() as u64 > max {
            return Err(HttpError::BodyTooLong {
                url: at.clone(),
                max,
            });
        }
        if let Some(expected) = expected
            && (body.len() as u64) < expected
        {
            return Err(HttpError::Truncated {
                url: at.clone(),
                expected,
                received: body.len() as u64,
                attempts,
            });
        }
        match (&self.cache, validator, range) {
            (Some(cache), Some(validator), None) if delimited => {
                if let Ok(mut cache) = cache.lock() {
                    cache.put(url, &validator, &body);
                }
            }
            (Some(_), None, None) if !self.uncacheable_told.swap(true, Ordering::Relaxed) => {
                log::warn!(
                    "{url}: sent without an ETag or Last-Modified, so it cannot be revalidated \
                     and the disk cache does not keep it, nor any other file sent so (said once)"
                );
            }
            _ => {}
        }
        Ok(body)
    }

    /// Warns, once per pair of hosts, that a request for `asked` was redirected to another
    /// host (`answered` is the URL that answered).
    pub(super) fn note_redirect(&self, asked: &str, answered: &str) {
        let (from, to) = (host_of(asked), host_of(answered));
        if answered.is_empty() || from.eq_ignore_ascii_case(to) {
            return;
        }
        let pair = (from.to_string(), to.to_string());
        if let Ok(mut seen) = self.redirects_seen.lock()
            && !seen.contains(&pair)
        {
            if seen.len() >= MAX_REDIRECT_PAIRS {
                seen.pop_front();
            }
            seen.push_back(pair);
            log::warn!(
                "{asked}: redirected from host {from} to host {to} ({answered}); \
                 further redirects between these hosts are followed silently"
            );
        }
    }
}

/// The `host[:port]` of an `http://` URL.
pub(super) fn host_of(url: &str) -> &str {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    rest.split(['/', '?', '#']).next().unwrap_or(rest)
}

/// Whether an I/O error is the deadline passing (a socket timeout).
pub(super) fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
    )
}

/// The error of a request that brought no response (its head, that is).
fn call_error(url: &str, attempts: u32, timeout_s: u64, e: ureq::Error) -> HttpError {
    let transport = |message: String| HttpError::Transport {
        url: url.into(),
        attempts,
        message,
    };
    let bad = |message: String| HttpError::BadResponse {
        url: url.into(),
        message,
    };
    match e {
        ureq::Error::Timeout(_) => HttpError::TimedOut {
            url: url.into(),
            timeout_s,
        },
        ureq::Error::Io(e) if is_timeout(&e) => HttpError::TimedOut {
            url: url.into(),
            timeout_s,
        },
        ureq::Error::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => transport(
            "the server closed the connection without an HTTP reply, or before the end of its \
             status line and headers"
                .into(),
        ),
        ureq::Error::Io(e) => transport(e.to_string()),
        ureq::Error::HostNotFound => transport("no address found for the host".into()),
        e @ (ureq::Error::ConnectionFailed | ureq::Error::BodyStalled) => transport(e.to_string()),
        ureq::Error::LargeResponseHeader(..) => bad(format!(
            "response head (status line and headers) longer than the {MAX_HEAD_BYTES} bytes \
             allowed (reading stopped)"
        )),
        ureq::Error::Protocol(e) if e.to_string().contains("too many headers") => bad(format!(
            "not a well-formed HTTP/1.1 response: {e} (at most {MAX_RESPONSE_HEADERS} headers \
             are read, each on a line of its own)"
        )),
        ureq::Error::Protocol(e) => bad(format!("not a well-formed HTTP/1.1 response: {e}")),
        e => bad(e.to_string()),
    }
}

/// The most headers a response may have (the HTTP library's limit): more is refused as a
/// response that is not well-formed.
const MAX_RESPONSE_HEADERS: usize = 128;

/// `url` as an error names it: with the address it was redirected to, where it was.
fn shown(url: &str, target: &str) -> String {
    if url == target {
        url.to_string()
    } else {
        format!("{url} (redirected to {})", without_userinfo(target))
    }
}

/// Where a redirect from `from` with `Location: location` leads: the location resolved
/// against `from` (RFC 3986 5.2), normalized as the world's address is, and checked to be one
/// that can be fetched; or what is wrong with it, naming it.
fn redirect_target(from: &str, location: &str) -> Result<String, String> {
    let target = WorldUrl::normalize(&resolve_reference(from, location));
    let scheme = target.split_once(':').map_or("", |(s, _)| s);
    if scheme.eq_ignore_ascii_case("https") {
        return Err(format!(
            "{}: https is not built in (the client speaks plain HTTP only): serve the world \
             over http, or put a TLS proxy in front of the server that redirects",
            without_userinfo(&target)
        ));
    }
    if !scheme.eq_ignore_ascii_case("http") {
        return Err(format!(
            "{}, which is not an http:// address (only plain HTTP is fetched)",
            without_userinfo(&target)
        ));
    }
    check_authority(&target).map_err(|e| e.to_string())?;
    Ok(target)
}

/// `url` with the user's name and password in its authority, if any, replaced by `…`.
fn without_userinfo(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    let end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    match rest[..end].rsplit_once('@') {
        Some((_, host)) => format!("{scheme}://…@{host}{}", &rest[end..]),
        None => url.to_string(),
    }
}

/// A URI reference split as RFC 3986 3 has it (its fragment dropped): `scheme:`,
/// `//authority`, the path and `?query`, each part absent or without its delimiter.
struct Parts<'a> {
    scheme: Option<&'a str>,
    authority: Option<&'a str>,
    path: &'a str,
    query: Option<&'a str>,
}

impl<'a> Parts<'a> {
    fn split(reference: &'a str) -> Parts<'a> {
        let r = reference.split('#').next().unwrap_or(reference);
        // A scheme is a letter, then letters, digits, `+`, `-` or `.`, before the first `:`.
        let scheme_end = r.find(':').filter(|&i| {
            i > 0
                && r.as_bytes()[0].is_ascii_alphabetic()
                && r[..i]
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"+-.".contains(&b))
        });
        let (scheme, rest) = match scheme_end {
            Some(i) => (Some(&r[..i]), &r[i + 1..]),
            None => (None, r),
        };
        let (authority, rest) = match rest.strip_prefix("//") {
            Some(after) => {
                let end = after.find(['/', '?']).unwrap_or(after.len());
                (Some(&after[..end]), &after[end..])
            }
            None => (None, rest),
        };
        let (path, query) = match rest.split_once('?') {
            Some((path, query)) => (path, Some(query)),
            None => (rest, None),
        };
        Parts {
            scheme,
            authority,
            path,
            query,
        }
    }
}

/// `reference` (a redirect's `Location`: absolute, `//host/...`, `/path`, `path`, `../path`,
/// `?query` or empty) resolved against the absolute URL `base`, as RFC 3986 5.2.2 has it; the
/// fragment is dropped.
pub(super) fn resolve_reference(base: &str, reference: &str) -> String {
    let b = Parts::split(base);
    let r = Parts::split(reference.trim());
    let (scheme, authority, path, query) = if r.scheme.is_some() {
        (r.scheme, r.authority, remove_dot_segments(r.path), r.query)
    } else if r.authority.is_some() {
        (b.scheme, r.authority, remove_dot_segments(r.path), r.query)
    } else if r.path.is_empty() {
        (
            b.scheme,
            b.authority,
            b.path.to_string(),
            r.query.or(b.query),
        )
    } else if r.path.starts_with('/') {
        (b.scheme, b.authority, remove_dot_segments(r.path), r.query)
    } else {
        // Merged (5.2.3): the base's path up to its last `/`, then the reference's.
        let merged = if b.authority.is_some() && b.path.is_empty() {
            format!("/{}", r.path)
        } else {
            let dir = b.path.rfind('/').map_or("", |i| &b.path[..=i]);
            format!("{dir}{}", r.path)
        };
        (b.scheme, b.authority, remove_dot_segments(&merged), r.query)
    };
    let mut out = String::new();
    if let Some(scheme) = scheme {
        out.push_str(scheme);
        out.push(':');
    }
    if let Some(authority) = authority {
        out.push_str("//");
        out.push_str(authority);
    }
    out.push_str(&path);
    if let Some(query) = query {
        out.push('?');
        out.push_str(query);
    }
    out
}

/// What a range response says of the whole file: see [`Client::range_identity`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct RangeIdentity {
    pub(super) total: u64,
    /// The host that answered (after redirects): validators are compared only between answers
    /// of one host, as mirrors behind a redirector write them each their own way.
    pub(super) host: String,
    pub(super) etag: Option<String>,
    pub(super) last_modified: Option<String>,
}

impl RangeIdentity {
    /// How the file changed from `self` to `now`, if it did: its length, or (from the same
    /// host) its `ETag`, compared weakly (`W/"x"` is `"x"`), or where neither answer has an
    /// `ETag` its `Last-Modified`. A validator that one answer has and the other lacks is not
    /// taken for a change.
    fn change_to(&self, now: &RangeIdentity) -> Option<String> {
        if self.total != now.total {
            return Some(format!(
                "its length was {} bytes, now {}",
                self.total, now.total
            ));
        }
        if self.host != now.host {
            return None;
        }
        let weak = |tag: &str| tag.trim_start_matches("W/").to_owned();
        if let (Some(a), Some(b)) = (&self.etag, &now.etag) {
            return (weak(a) != weak(b)).then(|| format!("its ETag was {a}, now {b}"));
        }
        if let (Some(a), Some(b)) = (&self.last_modified, &now.last_modified) {
            return (a != b).then(|| format!("its Last-Modified was {a}, now {b}"));
        }
        None
    }

    /// The identity as one word without spaces (for a bake's record of its inputs): the
    /// length and a fingerprint of the validators.
    pub(super) fn word(&self) -> String {
        // The ETag where there is one (the Last-Modified beside it adds nothing).
        let text = match &self.etag {
            Some(tag) => format!("etag {}", tag.trim_start_matches("W/")),
            None => format!("modified {}", self.last_modified.as_deref().unwrap_or("")),
        };
        format!(
            "{}:{:016x}",
            self.total,
            crate::hash::fnv1a64(crate::hash::FNV_BASIS, text.as_bytes())
        )
    }
}

/// Failures worth another try: the connection, the server's own errors, a body cut short.
pub(super) fn is_transient(e: &HttpError) -> bool {
    match e {
        HttpError::Transport { .. }
        | HttpError::Truncated { .. }
        | HttpError::ChunksCutShort { .. } => true,
        HttpError::Status { status, .. } => (500..600).contains(status),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn redirect_hosts_are_the_authority_of_the_url() {
        assert_eq!(
            host_of("http://a.example:8080/w/world.toml"),
            "a.example:8080"
        );
        assert_eq!(host_of("http://b.example?x=1"), "b.example");
        assert_eq!(host_of("http://c"), "c");
    }

    /// RFC 3986 5.4's examples of resolving a reference against `http://a/b/c/d;p?q` (those
    /// of its schemes: `g:h` is kept as it is), normal and abnormal, and the fragment dropped.
    #[test]
    fn references_resolve_as_rfc_3986_has_it() {
        let base = "http://a/b/c/d;p?q";
        for (reference, resolved) in [
            ("g:h", "g:h"),
            ("g", "http://a/b/c/g"),
            ("./g", "http://a/b/c/g"),
            ("g/", "http://a/b/c/g/"),
            ("/g", "http://a/g"),
            ("//g", "http://g"),
            ("?y", "http://a/b/c/d;p?y"),
            ("g?y", "http://a/b/c/g?y"),
            ("#s", "http://a/b/c/d;p?q"),
            ("g#s", "http://a/b/c/g"),
            ("g?y#s", "http://a/b/c/g?y"),
            (";x", "http://a/b/c/;x"),
            ("g;x", "http://a/b/c/g;x"),
            ("", "http://a/b/c/d;p?q"),
            (".", "http://a/b/c/"),
            ("./", "http://a/b/c/"),
            ("..", "http://a/b/"),
            ("../", "http://a/b/"),
            ("../g", "http://a/b/g"),
            ("../..", "http://a/"),
            ("../../", "http://a/"),
            ("../../g", "http://a/g"),
            ("../../../g", "http://a/g"),
            ("../../../../g", "http://a/g"),
            ("/./g", "http://a/g"),
            ("/../g", "http://a/g"),
            ("g.", "http://a/b/c/g."),
            (".g", "http://a/b/c/.g"),
            ("g..", "http://a/b/c/g.."),
            ("..g", "http://a/b/c/..g"),
            ("./../g", "http://a/b/g"),
            ("./g/.", "http://a/b/c/g/"),
            ("g/./h", "http://a/b/c/g/h"),
            ("g/../h", "http://a/b/c/h"),
            ("g;x=1/./y", "http://a/b/c/g;x=1/y"),
            ("g;x=1/../y", "http://a/b/c/y"),
            ("g?y/./x", "http://a/b/c/g?y/./x"),
            ("g#s/../x", "http://a/b/c/g"),
            ("http:g", "http:g"),
            ("HTTP://B:80/x/../y", "HTTP://B:80/y"),
        ] {
            assert_eq!(
                resolve_reference(base, reference),
                resolved,
                "{reference:?}"
            );
        }
        // A base without a path merges under the root.
        assert_eq!(
            resolve_reference("http://h:1", "w.toml"),
            "http://h:1/w.toml"
        );
    }

    /// A redirect's target is normalized and checked: only `http://` addresses that the
    /// world's own would pass, each refusal naming the target without its credentials.
    #[test]
    fn redirect_targets_are_checked_as_addresses_are() {
        let from = "http://h:1/w/world.toml";
        assert_eq!(
            redirect_target(from, "../v/a b.toml#x").unwrap(),
            "http://h:1/v/a%20b.toml"
        );
        assert_eq!(
            redirect_target(from, "HTTP://Other:2/x").unwrap(),
            "http://other:2/x"
        );
        assert_eq!(
            redirect_target(from, "http://[::1]:2/x").unwrap(),
            "http://[::1]:2/x"
        );
        for (location, said) in [
            ("http://[zz]:2/x", "not an IPv6 address"),
            (
                "file:///etc/passwd",
                "file:///etc/passwd, which is not an http://",
            ),
            ("https://s/w", "https://s/w: https is not built in"),
            ("ftp://u:pw@f/x", "ftp://…@f/x, which"),
            ("//u:pw@h:3/x", "credentials"),
            ("http:///x", "no host"),
        ] {
            let e = redirect_target(from, location).unwrap_err();
            assert!(e.contains(said) && !e.contains("pw"), "{location}: {e}");
        }
    }

    /// Redirects to ever new hosts keep at most [`MAX_REDIRECT_PAIRS`] pairs, the newest: the
    /// oldest are forgotten first.
    #[test]
    fn the_redirects_remembered_are_bounded() {
        let client = Client::new(HttpOptions::default(), None);
        for i in 0..200 {
            client.note_redirect("http://a/w.toml", &format!("http://b{i}/w.toml"));
            client.note_redirect("http://a/w.toml", "http://a/again");
        }
        let seen = client.redirects_seen.lock().unwrap();
        assert_eq!(seen.len(), MAX_REDIRECT_PAIRS);
        let to: Vec<&str> = seen.iter().map(|(_, to)| to.as_str()).collect();
        let newest: Vec<String> = (200 - MAX_REDIRECT_PAIRS..200)
            .map(|i| format!("b{i}"))
            .collect();
        assert_eq!(to, newest);
        drop(seen);
        // One seen again is not remembered twice.
        client.note_redirect("http://a/x", "http://b199/x");
        assert_eq!(
            client.redirects_seen.lock().unwrap().len(),
            MAX_REDIRECT_PAIRS
        );
    }
}
