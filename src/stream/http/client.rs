//! The requests of an [`super::HttpSource`]: deadlines, retries with backoff, redirects, and
//! bodies read no further than the most a file may hold, through the disk cache.

use std::collections::VecDeque;
use std::io::Read;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use super::cache::{DiskCache, Validator};
use super::{HttpError, HttpOptions, MAX_REDIRECTS};

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
    /// A file came without a validator and so could not be cached: said once.
    pub(super) uncacheable_told: std::sync::atomic::AtomicBool,
}

impl Client {
    /// A client with these options and this disk cache, its counters at zero.
    pub(super) fn new(options: HttpOptions, cache: Option<Mutex<DiskCache>>) -> Client {
        Client {
            options,
            cache,
            redirects_seen: Mutex::new(VecDeque::new()),
            requests: AtomicU64::new(0),
            retries: AtomicU64::new(0),
            cache_hits: AtomicU64::new(0),
            bytes: AtomicU64::new(0),
            range_total: AtomicU64::new(0),
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
    /// cached body on a `304`). A `503` with a `Retry-After` of seconds sets `retry_after`.
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
        let mut request = minreq::get(url)
            .with_timeout(timeout_s)
            .with_max_redirects(MAX_REDIRECTS)
            .with_max_headers_size(MAX_HEAD_BYTES)
            .with_max_status_line_length(MAX_HEAD_BYTES);
        if let Some([first, count]) = range {
            let last = first + count.max(1) - 1;
            request = request.with_header("Range", format!("bytes={first}-{last}"));
        }
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
        // minreq stands a 503 in for a reply without a status line: the server closed the
        // connection unanswered, or does not speak HTTP. Said so, and retried as a transport
        // failure is.
        if response.status_code == 503
            && response.reason_phrase == "Server did not provide a status line"
        {
            return Err(HttpError::Transport {
                url: url.into(),
                attempts,
                message: "the server closed the connection without an HTTP reply (no status \
                          line: it answered nothing, or not in HTTP)"
                    .into(),
            });
        }
        if !(200..300).contains(&response.status_code) {
            // Seconds only: a date would need the clock of the server, which may be wrong.
            if response.status_code == 503 {
                *retry_after = response
                    .headers
                    .get("retry-after")
                    .and_then(|v| v.trim().parse::<u64>().ok())
                    .map(Duration::from_secs);
            }
            return Err(HttpError::Status {
                url: url.into(),
                status: response.status_code,
                reason: response.reason_phrase.clone(),
                attempts,
            });
        }
        // A range's body is what was asked, whatever the server claims of the file's length.
        let max = match range {
            Some([_, count]) => max.min(count.max(1)),
            None => max,
        };
        if let Some([first, count]) = range {
            let bad = |message: String| HttpError::BadResponse {
                url: url.into(),
                message,
            };
            if response.status_code != 206 {
                return Err(bad(format!(
                    "HTTP {} to a range request: the server must answer range requests \
                     (206 Partial Content) for a DEM to be read in windows",
                    response.status_code
                )));
            }
            // "bytes FIRST-LAST/TOTAL"
            let header = response
                .headers
                .get("content-range")
                .cloned()
                .unwrap_or_default();
            let parsed = header
                .trim()
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
        let capacity = expected.unwrap_or(64 << 10).min(max).min(MAX_PREALLOCATED);
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
        match (&self.cache, validator, range) {
            (Some(cache), Some(validator), None) => {
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

/// Whether an I/O error is the deadline passing (minreq's own, or a socket timeout).
pub(super) fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
    )
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
