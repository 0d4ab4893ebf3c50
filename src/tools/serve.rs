//! `verdant serve`: a small static file server for a world folder, for trying worlds over HTTP
//! locally. It answers `GET` and `HEAD` with the file's content type, an `ETag` and a
//! `Last-Modified`, and a conditional `GET` (`If-None-Match`, `If-Modified-Since`) whose file
//! has not changed with `304 Not Modified`; a `Range` request (one range of bytes) gets `206
//! Partial Content` with those bytes. Production puts the world folder behind any ordinary HTTP
//! server, object store or CDN instead.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, bail};

/// Requests answered at once.
pub const WORKERS: usize = 8;
/// Connections accepted and waiting for a worker, by default; one past these is answered `503
/// Service Unavailable` (with `Retry-After`) and closed at once.
pub const QUEUED: usize = 64;
/// The most bytes of a request's line and headers; more is answered `431`.
pub const MAX_HEAD_BYTES: usize = 64 * 1024;
/// The most header lines of a request; more is answered `431`.
pub const MAX_HEADERS: usize = 100;

/// The server's limits in time and waiting connections.
#[derive(Clone, Copy, Debug)]
pub struct ServeLimits {
    /// The longest a client may take to send its request's head, from the moment its
    /// connection is accepted (a client that sends nothing, or trickles, is closed after it;
    /// one whose time passed while it waited for a worker is closed at once, unless its whole
    /// head has come meanwhile), so that idle connections hold the others back by about this
    /// long at most, however many of them wait.
    pub head: Duration,
    /// The longest one write of the answer may wait on a client that does not read.
    pub write: Duration,
    /// Connections accepted and waiting for a worker (at least 1; [`QUEUED`] by default).
    pub queued: usize,
}

impl Default for ServeLimits {
    fn default() -> Self {
        Self {
            head: Duration::from_secs(10),
            write: Duration::from_secs(30),
            queued: QUEUED,
        }
    }
}

/// A running server; dropping it stops it.
pub struct WorldServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    acceptor: Option<std::thread::JoinHandle<()>>,
    workers: Vec<std::thread::JoinHandle<()>>,
}

impl WorldServer {
    /// Serves the folder `root` (which must hold a `world.toml`) on `addr` (port 0 picks a free
    /// one) from worker threads of its own.
    pub fn start(root: &Path, addr: &str) -> Result<WorldServer> {
        let manifest = root.join("world.toml");
        let Ok(meta) = std::fs::metadata(&manifest) else {
            bail!("{}: no world.toml: not a world folder", root.display());
        };
        if !meta.is_file() {
            bail!(
                "{}: not a regular file; a world's manifest is served only from one",
                manifest.display()
            );
        }
        let server = WorldServer::start_folder(root, addr)?;
        // What the server would answer for it: a manifest that is a symlink out of the folder
        // is not followed, and the world would be served without it.
        let real_root = root
            .canonicalize()
            .with_context(|| root.display().to_string())?;
        // The manifest, the tiles' folder and its levels' folders (a level linked to another
        // disk would be answered 404 file by file).
        let levels = std::fs::read_dir(root.join("tiles"))
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| Path::new("tiles").join(e.file_name()));
        for name in [PathBuf::from("world.toml"), PathBuf::from("tiles")]
            .into_iter()
            .chain(levels)
        {
            if let Ok(real) = root.join(&name).canonicalize()
                && !real.starts_with(&real_root)
            {
                bail!(
                    "{}: a symlink out of the folder, which the server does not follow; copy \
                     it into the world",
                    root.join(name).display()
                );
            }
        }
        Ok(server)
    }

    /// Serves any folder `root` on `addr`: a world's source files (DEMs a bake reads over
    /// HTTP in byte ranges) as well as a world.
    pub fn start_folder(root: &Path, addr: &str) -> Result<WorldServer> {
        WorldServer::start_with(root, addr, ServeLimits::default())
    }

    /// [`Self::start_folder`] with limits of the caller's.
    ///
    /// What the server holds is bounded whatever its clients do: [`WORKERS`] threads answer
    /// requests, one more accepts connections into a queue of `limits.queued` (a connection
    /// past it is answered `503` and closed), a request's head is read within `limits.head` of
    /// its connection's accept and at most [`MAX_HEAD_BYTES`], and every connection is closed
    /// after its one answer.
    pub fn start_with(root: &Path, addr: &str, limits: ServeLimits) -> Result<WorldServer> {
        let root = Arc::new(
            root.canonicalize()
                .with_context(|| format!("{}: cannot open", root.display()))?,
        );
        let listener =
            TcpListener::bind(addr).map_err(|e| anyhow::anyhow!("cannot listen on {addr}: {e}"))?;
        let addr = listener
            .local_addr()
            .context("the server has no IP address")?;
        // Each connection carries the deadline of its head, counted from its accept.
        let (tx, rx) = sync_channel::<(TcpStream, Instant)>(limits.queued.max(1));
        let rx = Arc::new(Mutex::new(rx));
        let workers = (0..WORKERS)
            .map(|_| {
                let (rx, root) = (Arc::clone(&rx), Arc::clone(&root));
                std::thread::spawn(move || {
                    work(&rx, |(stream, deadline)| {
                        serve_connection(&root, stream, deadline, limits)
                    });
                })
            })
            .collect();
        let stop = Arc::new(AtomicBool::new(false));
        let acceptor = {
            let stop = Arc::clone(&stop);
            std::thread::spawn(move || accept(&listener, &tx, limits.head, &stop))
        };
        Ok(WorldServer {
            addr,
            stop,
            acceptor: Some(acceptor),
            workers,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The world's URL, one a client can fetch: `http://ADDR/`, with 127.0.0.1 for a server
    /// that listens on every IPv4 address (`0.0.0.0`) and `[::1]` for every IPv6 one (`[::]`).
    pub fn url(&self) -> String {
        format!("http://{}/", fetchable(self.addr))
    }

    /// Serves until the process ends.
    pub fn wait(mut self) {
        if let Some(a) = self.acceptor.take() {
            let _ = a.join();
        }
    }
}

impl Drop for WorldServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        // The acceptor wakes on a connection of its own, sees the flag and drops the queue's
        // sender; the workers end when the queue is empty.
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
        if let Some(a) = self.acceptor.take() {
            let _ = a.join();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

/// `addr` as a client reaches it: the loopback address of its family for an unspecified one
/// (an address to listen on, not to fetch).
fn fetchable(addr: SocketAddr) -> SocketAddr {
    match addr.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => (Ipv4Addr::LOCALHOST, addr.port()).into(),
        IpAddr::V6(ip) if ip.is_unspecified() => (Ipv6Addr::LOCALHOST, addr.port()).into(),
        _ => addr,
    }
}

/// Accepts connections into the workers' queue until `stop`, each with the deadline of its
/// request's head (`head` from now); a connection the queue has no room for is answered `503`
/// and closed here. An accept that fails (out of file descriptors) is logged and retried after
/// a pause: the server goes on.
fn accept(
    listener: &TcpListener,
    queue: &SyncSender<(TcpStream, Instant)>,
    head: Duration,
    stop: &AtomicBool,
) {
    let mut told = false;
    loop {
        let stream = listener.accept();
        if stop.load(Ordering::SeqCst) {
            return;
        }
        match stream {
            // However long the head time (a limit of years stands for none), a deadline.
            Ok((stream, _)) => match queue.try_send((stream, deadline_after(head))) {
                Ok(()) => {}
                Err(TrySendError::Full((mut stream, _))) => {
                    let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
                    let _ = stream.write_all(
                        b"HTTP/1.1 503 Service Unavailable\r\nRetry-After: 1\r\n\
                          Content-Length: 0\r\nConnection: close\r\n\r\n",
                    );
                    let _ = stream.shutdown(Shutdown::Both);
                }
                Err(TrySendError::Disconnected(_)) => return,
            },
            Err(e) => {
                if !told {
                    log::warn!("serve: cannot accept a connection ({e}); trying again");
                    told = true;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

/// Answers connections from `queue` with `answer` until the queue's sender is gone. A panic in
/// answering one connection is caught and logged, and the worker goes on with the next: a
/// request that trips a bug must not take a worker (of only [`WORKERS`]) with it.
fn work<T>(queue: &Mutex<Receiver<T>>, answer: impl Fn(T) -> std::io::Result<()>) {
    loop {
        // The lock is held only while waiting for the next connection; a worker that panicked
        // while holding it does not poison it (the panic is caught outside the lock).
        let next = match queue.lock() {
            Ok(rx) => rx.recv(),
            Err(_) => return,
        };
        let Ok(connection) = next else { return };
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| answer(connection))) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => log::debug!("serve: {e}"),
            Err(panic) => {
                let what = panic
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| panic.downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "a panic without a message".into());
                log::error!(
                    "serve: answering a connection panicked ({what}); it was closed and the \
                     worker goes on"
                );
            }
        }
    }
}

/// A request's line and headers.
struct Head {
    method: String,
    target: String,
    headers: Vec<(String, String)>,
}

impl Head {
    /// The value of the first header of `name` (any case).
    fn value(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

/// Why a request's head was not read.
enum HeadError {
    /// Not HTTP: answered `400`.
    Bad,
    /// Past [`MAX_HEAD_BYTES`] or [`MAX_HEADERS`]: answered `431`.
    TooLarge,
    /// The client closed, or took longer than its time: nothing is answered.
    Gone(std::io::Error),
}

/// Reads a request's head by `deadline` and within [`MAX_HEAD_BYTES`].
fn read_head(stream: &TcpStream, deadline: Instant) -> Result<Head, HeadError> {
    let mut reader = BufReader::new(Deadline { stream, deadline }).take(MAX_HEAD_BYTES as u64);
    let mut lines = Vec::new();
    loop {
        let mut line = Vec::new();
        let n = reader
            .read_until(b'\n', &mut line)
            .map_err(HeadError::Gone)?;
        if n == 0 || !line.ends_with(b"\n") {
            return Err(if reader.limit() == 0 {
                HeadError::TooLarge
            } else {
                HeadError::Gone(std::io::ErrorKind::UnexpectedEof.into())
            });
        }
        while matches!(line.last(), Some(b'\n' | b'\r')) {
            line.pop();
        }
        if line.is_empty() {
            if lines.is_empty() {
                continue; // blank lines before a request line are allowed (RFC 9112, 2.2)
            }
            break;
        }
        if lines.len() > MAX_HEADERS {
            return Err(HeadError::TooLarge);
        }
        // Bytes past ASCII in a header's value (obs-text, RFC 9110 5.5) are kept, not refused.
        lines.push(String::from_utf8_lossy(&line).into_owned());
    }
    let mut parts = lines[0].split(' ');
    let (Some(method), Some(target), Some(version), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Err(HeadError::Bad);
    };
    let origin_form = target.starts_with('/');
    let absolute_form = target.starts_with("http://") || target.starts_with("https://");
    if method.is_empty()
        || !matches!(version, "HTTP/1.0" | "HTTP/1.1")
        || !(origin_form || absolute_form)
    {
        return Err(HeadError::Bad);
    }
    let mut headers = Vec::with_capacity(lines.len() - 1);
    for line in &lines[1..] {
        let (name, value) = line.split_once(':').ok_or(HeadError::Bad)?;
        if name.is_empty() || name.contains([' ', '\t']) {
            return Err(HeadError::Bad);
        }
        headers.push((name.to_string(), value.trim().to_string()));
    }
    // An HTTP/1.1 request names its host, and no request names two (RFC 9112, 3.2).
    let hosts = headers
        .iter()
        .filter(|(n, _)| n.eq_ignore_ascii_case("Host"))
        .count();
    if hosts > 1 || (version == "HTTP/1.1" && hosts == 0) {
        return Err(HeadError::Bad);
    }
    Ok(Head {
        method: method.to_string(),
        target: target.to_string(),
        headers,
    })
}

/// A stream read with one deadline for the whole of what is read through it. Past the
/// deadline only what has already come is read, without waiting for more: a connection that
/// waited in the queue past its time is answered if its request is there, else closed at once.
struct Deadline<'s> {
    stream: &'s TcpStream,
    deadline: Instant,
}

impl Read for Deadline<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        let mut stream = self.stream;
        if left.is_zero() {
            stream.set_nonblocking(true)?;
            let read = stream.read(buf);
            stream.set_nonblocking(false)?;
            return match read {
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    Err(std::io::ErrorKind::TimedOut.into())
                }
                read => read,
            };
        }
        stream.set_read_timeout(Some(left))?;
        stream.read(buf)
    }
}

/// An answer's status line and headers, ahead of its body.
struct Answer {
    status: u16,
    headers: Vec<(&'static str, String)>,
}

impl Answer {
    fn new(status: u16) -> Self {
        Self {
            status,
            headers: Vec::new(),
        }
    }

    fn with(mut self, name: &'static str, value: impl Into<String>) -> Self {
        self.headers.push((name, value.into()));
        self
    }

    /// Writes the head, with `Content-Length: length` (none for a `304`) and `Connection:
    /// close`.
    fn write_head(&self, out: &mut impl Write, length: u64) -> std::io::Result<()> {
        let mut head = format!("HTTP/1.1 {} {}\r\n", self.status, reason(self.status));
        for (name, value) in &self.headers {
            head.push_str(&format!("{name}: {value}\r\n"));
        }
        // A clock set before 1970 (or past 9999) sends no Date rather than a panic.
        if let Some(now) = http_date(SystemTime::now()) {
            head.push_str(&format!("Date: {now}\r\n"));
        }
        if self.status != 304 {
            head.push_str(&format!("Content-Length: {length}\r\n"));
        }
        head.push_str("Connection: close\r\n\r\n");
        out.write_all(head.as_bytes())
    }

    /// Writes the head and `body` (none for `HEAD`).
    fn send(&self, out: &mut impl Write, body: &[u8], head_only: bool) -> std::io::Result<()> {
        self.write_head(out, body.len() as u64)?;
        if !head_only {
            out.write_all(body)?;
        }
        out.flush()
    }
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        206 => "Partial Content",
        304 => "Not Modified",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        416 => "Range Not Satisfiable",
        431 => "Request Header Fields Too Large",
        503 => "Service Unavailable",
        _ => "",
    }
}

/// Answers the one request of a connection, whose head must have come by `deadline`, then
/// closes it.
fn serve_connection(
    root: &Path,
    stream: TcpStream,
    deadline: Instant,
    limits: ServeLimits,
) -> std::io::Result<()> {
    stream.set_write_timeout(Some(limits.write))?;
    let mut out = std::io::BufWriter::new(&stream);
    let result = match read_head(&stream, deadline) {
        Ok(head) => answer(root, &head, &mut out),
        Err(HeadError::Bad) => Answer::new(400).send(&mut out, b"bad request\n", false),
        Err(HeadError::TooLarge) => {
            Answer::new(431).send(&mut out, b"request head too large\n", false)
        }
        Err(HeadError::Gone(e)) => Err(e),
    };
    drop(out);
    let _ = stream.shutdown(Shutdown::Both);
    result
}

/// The content type of a world's file.
pub fn content_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()) {
        Some("toml") => "application/toml",
        Some("png") => "image/png",
        Some("exr") => "image/x-exr",
        Some("json") => "application/json",
        Some("md") => "text/markdown; charset=utf-8",
        Some("txt") => "text/plain; charset=utf-8",
        Some("tif" | "tiff") => "image/tiff",
        _ => "application/octet-stream",
    }
}

/// The file under `root` that a request path names, if it names one inside it.
fn resolve(root: &Path, url: &str) -> Option<PathBuf> {
    let raw = url.split(['?', '#']).next().unwrap_or("");
    // A path whose last segment is empty or a dot segment names a folder, never a file
    // (`/world.toml/` and `/world.toml/.` are not `/world.toml`: an alias of every file would
    // confuse caches in front of the server).
    if matches!(raw.rsplit('/').next(), Some("" | "." | "..")) {
        return None;
    }
    // Dot segments as written (`/./world.toml`, `/tiles/L0/../../world.toml`) are removed
    // first (RFC 3986 5.2.4), but never above the root: a path that climbs out is refused.
    let mut segments = Vec::new();
    for segment in raw.split('/') {
        match segment {
            "" | "." => {}
            ".." => {
                segments.pop()?;
            }
            _ => segments.push(segment),
        }
    }
    let raw = segments.join("/");
    // Percent-encoded names (a plant file `my%20fern.gltf`) are decoded then, and checked
    // like any other: `%2e%2e` is a name, `..`, and refused; a NUL never reaches the file
    // system.
    let path = percent_encoding::percent_decode_str(&raw)
        .decode_utf8()
        .ok()?
        .into_owned();
    let relative = Path::new(path.trim_start_matches('/'));
    if path.contains('\0')
        || relative
            .components()
            .any(|c| !matches!(c, Component::Normal(_)))
    {
        return None;
    }
    let file = root.join(relative);
    // Symlinks out of the folder are not followed.
    let real = file.canonicalize().ok()?;
    (real.starts_with(root) && real.is_file()).then_some(real)
}

fn answer(root: &Path, request: &Head, out: &mut impl Write) -> std::io::Result<()> {
    let head_only = request.method == "HEAD";
    if !head_only && request.method != "GET" {
        return Answer::new(405)
            .with("Allow", "GET, HEAD")
            .send(out, b"", false);
    }
    // An absolute target (`http://host/path`, as a proxy sends) is read as its path; a target
    // that starts with `/` is a path whatever its query holds.
    let target = match request
        .target
        .strip_prefix("http://")
        .or_else(|| request.target.strip_prefix("https://"))
    {
        Some(rest) => &rest[rest.find('/').unwrap_or(rest.len())..],
        None => request.target.as_str(),
    };
    let Some(file) = resolve(root, target) else {
        return Answer::new(404).send(out, b"not found\n", head_only);
    };
    let meta = std::fs::metadata(&file)?;
    let modified = meta.modified().unwrap_or(UNIX_EPOCH);
    let etag = entity_tag(meta.len(), modified);
    // None for a file dated before 1970 or from the year 10000 on, which HTTP dates cannot
    // write: such a file has no Last-Modified, and If-Modified-Since is not asked of it.
    let last_modified = http_date(modified);
    // If-None-Match wins over If-Modified-Since (RFC 9110, 13.2.2).
    let not_modified = match request.value("If-None-Match") {
        Some(tags) => tags
            .split(',')
            .any(|t| t.trim() == "*" || t.trim().trim_start_matches("W/") == etag),
        None => {
            last_modified.is_some()
                && request
                    .value("If-Modified-Since")
                    .and_then(|d| httpdate::parse_http_date(d).ok())
                    .is_some_and(|since| truncate_to_seconds(modified) <= since)
        }
    };
    if not_modified {
        let mut answer = Answer::new(304).with("ETag", etag);
        if let Some(date) = last_modified {
            answer = answer.with("Last-Modified", date);
        }
        return answer.send(out, b"", true);
    }
    let len = meta.len();
    // If-Range (RFC 9110, 13.1.5): the range only of the version the client holds (its tag,
    // or its date when the file has one); another version is sent whole.
    let range = request
        .value("Range")
        .filter(|_| match request.value("If-Range") {
            None => true,
            Some(tag) if tag.trim_start().starts_with('"') => tag.trim() == etag,
            Some(date) => last_modified.as_deref() == Some(date.trim()),
        });
    let (status, span) = match range.map(|r| byte_range(r, len)) {
        None | Some(RangeAsk::Whole) => (200, None),
        Some(RangeAsk::Part(span)) => (206, Some(span)),
        Some(RangeAsk::Unsatisfiable) => {
            return Answer::new(416)
                .with("Content-Range", format!("bytes */{len}"))
                .send(out, b"", false);
        }
    };
    // The body is read from the file as it is sent (never whole into memory, and not at all
    // for HEAD), with a Content-Length.
    let [first, last] = span.unwrap_or([0, len.saturating_sub(1)]);
    let length = if len == 0 { 0 } else { last - first + 1 };
    let mut answer = Answer::new(status)
        .with("Content-Type", content_type(&file))
        .with("Accept-Ranges", "bytes");
    if let Some([first, last]) = span {
        answer = answer.with("Content-Range", format!("bytes {first}-{last}/{len}"));
    }
    answer = answer.with("ETag", etag);
    if let Some(date) = last_modified {
        answer = answer.with("Last-Modified", date);
    }
    let mut reader = std::fs::File::open(&file)?;
    answer.write_head(out, length)?;
    if !head_only {
        std::io::Seek::seek(&mut reader, std::io::SeekFrom::Start(first))?;
        std::io::copy(&mut reader.take(length), out)?;
    }
    out.flush()
}

/// What a `Range` header asks of a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RangeAsk {
    /// Nothing the server acts on: another unit than bytes (which RFC 9110, 14.2, says to
    /// ignore), several ranges (which the server may answer whole), or a header that is not a
    /// range: answered `200` with the whole file.
    Whole,
    /// The bytes (first, last, inclusive): answered `206`.
    Part([u64; 2]),
    /// One range of bytes, well formed, that misses the file (it starts at or past its end,
    /// or is a suffix of 0 bytes): answered `416`.
    Unsatisfiable,
}

/// What the `Range` header `value` asks of a file of `len` bytes (RFC 9110, 14.1 and 14.2): one
/// range `bytes=A-B`, `bytes=A-` or `bytes=-N`, its unit in any case.
fn byte_range(value: &str, len: u64) -> RangeAsk {
    let Some((unit, spec)) = value.trim().split_once('=') else {
        return RangeAsk::Whole;
    };
    if !unit.eq_ignore_ascii_case("bytes") || spec.contains(',') {
        return RangeAsk::Whole;
    }
    let Some((a, b)) = spec.trim().split_once('-') else {
        return RangeAsk::Whole;
    };
    // Digits only (`parse` would take `+5`); a number too large for u64 is past any file.
    let number = |s: &str| {
        (!s.is_empty() && s.bytes().all(|c| c.is_ascii_digit()))
            .then(|| s.parse::<u64>().unwrap_or(u64::MAX))
    };
    let (first, last) = match (number(a.trim()), number(b.trim())) {
        // A suffix: the last N bytes, the whole file if it is shorter.
        (None, Some(n)) if a.trim().is_empty() => {
            if n == 0 || len == 0 {
                return RangeAsk::Unsatisfiable;
            }
            (len.saturating_sub(n), len - 1)
        }
        (Some(first), None) if b.trim().is_empty() => (first, u64::MAX),
        // A last byte before the first is an invalid range, ignored like other invalid ones.
        (Some(first), Some(last)) if first <= last => (first, last),
        _ => return RangeAsk::Whole,
    };
    if first >= len {
        return RangeAsk::Unsatisfiable;
    }
    RangeAsk::Part([first, last.min(len - 1)])
}

/// `t` as an HTTP date (`Sun, 06 Nov 1994 08:49:37 GMT`), or `None` outside what `httpdate`
/// writes (it panics on those): before 1970, or from the year 10000 on.
fn http_date(t: SystemTime) -> Option<String> {
    // 10000-01-01T00:00:00Z, in seconds from the epoch: the first instant httpdate refuses.
    const YEAR_10000_S: u64 = 253_402_300_800;
    let since = t.duration_since(UNIX_EPOCH).ok()?;
    (since.as_secs() < YEAR_10000_S).then(|| httpdate::fmt_http_date(t))
}

/// The `ETag` of a file of `len` bytes modified at `modified`: its length and its time in
/// nanoseconds from the epoch, signed (`-` before it for a file dated before 1970), so that
/// every time has its own tag.
fn entity_tag(len: u64, modified: SystemTime) -> String {
    match modified.duration_since(UNIX_EPOCH) {
        Ok(after) => format!("\"{len:x}-{:x}\"", after.as_nanos()),
        Err(before) => format!("\"{len:x}--{:x}\"", before.duration().as_nanos()),
    }
}

fn truncate_to_seconds(t: SystemTime) -> SystemTime {
    let s = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    UNIX_EPOCH + std::time::Duration::from_secs(s)
}

/// `head` from now, or a year from now where that is later (or past what an `Instant` holds).
fn deadline_after(head: Duration) -> Instant {
    const YEAR: Duration = Duration::from_secs(365 * 24 * 3600);
    let now = Instant::now();
    now.checked_add(head.min(YEAR)).unwrap_or(now)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A head time of any length gives a deadline: `Duration::MAX` (no limit, as a caller
    /// may write it) panicked in the thread that accepts connections, which then accepted none.
    #[test]
    fn any_head_time_gives_a_deadline() {
        let now = Instant::now();
        for head in [Duration::ZERO, Duration::from_secs(10), Duration::MAX] {
            let at = deadline_after(head);
            assert!(at >= now + head.min(Duration::from_secs(3600)), "{head:?}");
        }
    }

    #[test]
    fn ranges_are_read_as_rfc_9110_writes_them() {
        use RangeAsk::{Part, Unsatisfiable, Whole};
        for (value, asked) in [
            ("bytes=0-0", Part([0, 0])),
            ("bytes=2-5", Part([2, 5])),
            ("bytes=7-", Part([7, 9])),
            ("bytes=-3", Part([7, 9])),
            ("bytes=-30", Part([0, 9])),
            ("bytes=4-100", Part([4, 9])),
            ("bytes=4-99999999999999999999999", Part([4, 9])),
            // The unit is case-insensitive.
            ("BYTES=0-1", Part([0, 1])),
            ("Bytes=3-", Part([3, 9])),
            // One well-formed range of bytes that misses the file.
            ("bytes=10-12", Unsatisfiable),
            ("bytes=10-", Unsatisfiable),
            ("bytes=99999999999999999999999-", Unsatisfiable),
            ("bytes=-0", Unsatisfiable),
            // Another unit, several ranges, or no range at all: ignored, the whole file.
            ("items=0-1", Whole),
            ("bytes=0-1,4-5", Whole),
            ("bytes=a-b", Whole),
            ("bytes=5-2", Whole),
            ("bytes=+1-2", Whole),
            ("bytes=-", Whole),
            ("bytes=3", Whole),
            ("bytes", Whole),
        ] {
            assert_eq!(byte_range(value, 10), asked, "{value}");
        }
        assert_eq!(byte_range("bytes=0-0", 0), Unsatisfiable);
        assert_eq!(byte_range("bytes=-1", 0), Unsatisfiable);
        assert_eq!(byte_range("items=0-0", 0), Whole);
    }

    #[test]
    fn times_http_dates_cannot_write_have_no_date_and_tags_of_their_own() {
        let at = |s: i64| {
            if s >= 0 {
                UNIX_EPOCH + Duration::from_secs(s as u64)
            } else {
                UNIX_EPOCH - Duration::from_secs(s.unsigned_abs())
            }
        };
        assert_eq!(
            http_date(at(784_111_777)).as_deref(),
            Some("Sun, 06 Nov 1994 08:49:37 GMT")
        );
        assert_eq!(
            http_date(at(253_402_300_799)).as_deref(),
            Some("Fri, 31 Dec 9999 23:59:59 GMT")
        );
        for s in [-1, -315_619_200, 253_402_300_800, 300_000_000_000] {
            assert_eq!(http_date(at(s)), None, "{s}");
        }
        let tags: std::collections::HashSet<String> = [-315_619_200, -1, 0, 1, 253_402_300_800]
            .into_iter()
            .map(|s| entity_tag(10, at(s)))
            .collect();
        assert_eq!(tags.len(), 5, "{tags:?}");
        assert_eq!(entity_tag(10, at(-1)), "\"a--3b9aca00\"");
    }

    /// A worker whose answer panics goes on with the next connection: every connection after
    /// a panic is still answered, by one worker.
    #[test]
    fn a_worker_survives_a_panic_in_an_answer() {
        let (tx, rx) = sync_channel::<u32>(32);
        for n in 0..20 {
            tx.send(n).unwrap();
        }
        drop(tx);
        let answered = Mutex::new(Vec::new());
        work(&Mutex::new(rx), |n| {
            assert!(n % 2 == 0, "connection {n} trips a bug");
            answered.lock().unwrap().push(n);
            Ok(())
        });
        let evens: Vec<u32> = (0..20).step_by(2).collect();
        assert_eq!(answered.into_inner().unwrap(), evens);
    }
}
