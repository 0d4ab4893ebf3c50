//! [`FaultProxy`]: an HTTP/1.1 proxy on `127.0.0.1` in front of a world server that injects
//! faults into requests for tile files, for soak tests of worlds over HTTP.
//!
//! Each request for a file under `tiles/` faults with probability `rate`, chosen from a hash of
//! the seed, the request's path and how many times that path has been asked before: the same
//! seed makes the same choices for the same requests whatever order threads take them in, and
//! a retry of a faulted file may succeed. A fault is one of [`Fault`]: an error status (500 or
//! 503), a stall (the connection held without an answer until the client hangs up, at most
//! [`FaultOptions::stall`]), a reset (half a response head, then the connection closed with
//! the request unread, which the kernel turns into a TCP reset) or a short body (the upstream
//! answer's head and `Content-Length`, half its body, then a close). Everything else (the
//! manifest, other files, tile requests not chosen) passes through unchanged, validators and
//! `304 Not Modified` included.
//!
//! Bounded: connections are served by a fixed pool of [`FaultOptions::workers`] threads from a
//! queue of twice as many; when both are full, new connections wait in the kernel's backlog.
//! Requests are counted for at most [`MAX_ASKED_PATHS`] paths.

use std::collections::{HashMap, VecDeque};
use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

/// The most bytes of a request's head (request line and headers).
const MAX_REQUEST_HEAD: usize = 64 << 10;

/// How long a client may take to send its request head.
const REQUEST_HEAD_TIMEOUT: Duration = Duration::from_secs(10);

/// How long the upstream server may take to connect, or between reads and writes.
const UPSTREAM_TIMEOUT: Duration = Duration::from_secs(30);

/// The most bytes of an upstream body held for a short-body fault (a tile file is far smaller).
const MAX_HELD_BODY: usize = 16 << 20;

/// The most tile paths whose requests the proxy counts (for the choice of each request's
/// fault); past it the path asked first is forgotten, and its next request counts as its first
/// again. A soak asks the same few thousand files over and over; a client that asks ever new
/// paths does not grow the proxy.
pub const MAX_ASKED_PATHS: usize = 16 << 10;

/// The longest stall allowed, and so the longest client deadline a stall outlasts: one hour.
pub const MAX_STALL: Duration = Duration::from_secs(3600);

/// The most worker threads.
pub const MAX_WORKERS: usize = 1024;

/// One kind of injected fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fault {
    /// `500 Internal Server Error`, no body.
    Status500,
    /// `503 Service Unavailable`, no body.
    Status503,
    /// No answer until the client hangs up (its deadline) or [`FaultOptions::stall`] passes.
    Stall,
    /// Half a response head, then a TCP reset.
    Reset,
    /// The upstream head with its `Content-Length`, half the body, then a close.
    ShortBody,
}

impl Fault {
    /// Every kind, in the order the choice indexes them.
    pub const ALL: [Fault; 5] = [
        Fault::Status500,
        Fault::Status503,
        Fault::Stall,
        Fault::Reset,
        Fault::ShortBody,
    ];
}

/// What a [`FaultProxy`] injects and how it is bounded.
#[derive(Clone, Debug, PartialEq)]
pub struct FaultOptions {
    /// Share of tile requests that fault, in 0..=1.
    pub rate: f64,
    /// Seed of the choice of faulted requests and of their kind.
    pub seed: u64,
    /// The longest a stall holds its connection, at most [`MAX_STALL`]; a stall ends earlier
    /// when the client hangs up. Default 60 s (longer than any usual client deadline).
    pub stall: Duration,
    /// Threads serving connections, in 1..=[`MAX_WORKERS`]. Default 32; a stall holds one.
    pub workers: usize,
    /// Tile paths (relative to the world, e.g. `tiles/L0/`) that never fault, by prefix. The
    /// soak spares level 0, which the tile service loads once before the first frame.
    pub spared: Vec<String>,
}

impl Default for FaultOptions {
    fn default() -> Self {
        Self {
            rate: 0.0,
            seed: 0,
            stall: Duration::from_secs(60),
            workers: 32,
            spared: Vec::new(),
        }
    }
}

/// Requests seen by a [`FaultProxy`] and what was done with them. `requests` is `passed` plus
/// the faults plus `upstream_errors`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FaultCounts {
    /// Requests whose head was read.
    pub requests: u64,
    /// Answered without a fault: forwarded upstream and its answer passed back (or, for a
    /// method other than GET and HEAD, refused with `405`).
    pub passed: u64,
    /// Answered `500`.
    pub status_500: u64,
    /// Answered `503`.
    pub status_503: u64,
    /// Held without an answer.
    pub stalls: u64,
    /// Reset mid-head.
    pub resets: u64,
    /// Sent a body shorter than its `Content-Length`.
    pub short_bodies: u64,
    /// Not faulted, but the upstream server could not be reached (answered `502`).
    pub upstream_errors: u64,
}

impl FaultCounts {
    /// Requests that were given a fault.
    pub fn faults(&self) -> u64 {
        self.status_500 + self.status_503 + self.stalls + self.resets + self.short_bodies
    }

    /// Requests given fault `kind`.
    pub fn of(&self, kind: Fault) -> u64 {
        match kind {
            Fault::Status500 => self.status_500,
            Fault::Status503 => self.status_503,
            Fault::Stall => self.stalls,
            Fault::Reset => self.resets,
            Fault::ShortBody => self.short_bodies,
        }
    }

    fn count(&mut self, kind: Fault) {
        match kind {
            Fault::Status500 => self.status_500 += 1,
            Fault::Status503 => self.status_503 += 1,
            Fault::Stall => self.stalls += 1,
            Fault::Reset => self.resets += 1,
            Fault::ShortBody => self.short_bodies += 1,
        }
    }
}

/// The upstream world server: where to connect, what to call it, the path of the world.
struct Upstream {
    addrs: Vec<SocketAddr>,
    /// `host[:port]`, for the `Host` header.
    authority: String,
    /// The world's path, starting and ending with `/`.
    base: String,
    /// The world address's query without its `?` (a signed URL's token), sent on every request
    /// after the client's own; empty if none.
    query: String,
}

impl Upstream {
    fn parse(url: &str) -> Result<Upstream> {
        let rest = url
            .get(..7)
            .filter(|s| s.eq_ignore_ascii_case("http://"))
            .map(|_| &url[7..])
            .with_context(|| {
                format!("{url}: the upstream must be a plain http://HOST[:PORT]/PATH/")
            })?;
        let rest = rest.split('#').next().unwrap_or(rest);
        let (rest, query) = rest.split_once('?').unwrap_or((rest, ""));
        let (authority, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
        if authority.is_empty() {
            bail!("{url}: the upstream address has no host");
        }
        let has_port = authority
            .rsplit_once(':')
            .is_some_and(|(_, p)| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit()));
        let target = if has_port {
            authority.to_string()
        } else {
            format!("{authority}:80")
        };
        let addrs: Vec<SocketAddr> = target
            .to_socket_addrs()
            .with_context(|| format!("{url}: cannot resolve {authority}"))?
            .collect();
        if addrs.is_empty() {
            bail!("{url}: {authority} has no address");
        }
        let base = format!("/{}/", path.trim_matches('/')).replace("//", "/");
        Ok(Upstream {
            addrs,
            authority: authority.to_string(),
            base,
            query: query.to_string(),
        })
    }

    fn connect(&self) -> std::io::Result<TcpStream> {
        let mut last = None;
        for addr in &self.addrs {
            match TcpStream::connect_timeout(addr, UPSTREAM_TIMEOUT) {
                Ok(s) => {
                    s.set_read_timeout(Some(UPSTREAM_TIMEOUT))?;
                    s.set_write_timeout(Some(UPSTREAM_TIMEOUT))?;
                    return Ok(s);
                }
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| std::io::Error::other("no address")))
    }
}

/// What the workers share.
struct Shared {
    upstream: Upstream,
    options: FaultOptions,
    stop: AtomicBool,
    counts: Mutex<FaultCounts>,
    /// Times each path has been asked, so that each request of a path has its own choice.
    asked: Mutex<AskedPaths>,
}

/// Times each tile path has been asked, for at most [`MAX_ASKED_PATHS`] paths.
#[derive(Default)]
struct AskedPaths {
    counts: HashMap<String, u64>,
    /// The paths in `counts`, first asked first: the next to forget at the front.
    order: VecDeque<String>,
}

impl AskedPaths {
    /// Counts one more request of `path` and returns its number (1 for the first).
    fn ask(&mut self, path: &str) -> u64 {
        if let Some(n) = self.counts.get_mut(path) {
            *n += 1;
            return *n;
        }
        if self.order.len() >= MAX_ASKED_PATHS
            && let Some(oldest) = self.order.pop_front()
        {
            self.counts.remove(&oldest);
        }
        self.order.push_back(path.to_string());
        self.counts.insert(path.to_string(), 1);
        1
    }
}

/// A running fault-injecting proxy; see the module docs. Dropping it stops it (stalls end,
/// queued connections are closed) and joins its threads.
pub struct FaultProxy {
    addr: SocketAddr,
    shared: Arc<Shared>,
    acceptor: Option<JoinHandle<()>>,
    workers: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for FaultProxy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaultProxy")
            .field("addr", &self.addr)
            .field("options", &self.shared.options)
            .finish_non_exhaustive()
    }
}

impl FaultProxy {
    /// Starts a proxy of the world at `upstream` (`http://host:port/base/`) that faults a
    /// share `rate` (0..=1) of tile requests, chosen by `seed`; other options default.
    pub fn start(upstream: &str, rate: f64, seed: u64) -> Result<FaultProxy> {
        Self::start_with(
            upstream,
            FaultOptions {
                rate,
                seed,
                ..FaultOptions::default()
            },
        )
    }

    /// Starts a proxy of the world at `upstream` with `options`.
    pub fn start_with(upstream: &str, options: FaultOptions) -> Result<FaultProxy> {
        if !(0.0..=1.0).contains(&options.rate) {
            bail!("fault rate {}: must be in 0..=1", options.rate);
        }
        if options.stall > MAX_STALL {
            bail!(
                "fault stall of {} s: must be at most {} s",
                options.stall.as_secs_f64(),
                MAX_STALL.as_secs()
            );
        }
        if !(1..=MAX_WORKERS).contains(&options.workers) {
            bail!(
                "fault proxy workers {}: must be in 1..={MAX_WORKERS}",
                options.workers
            );
        }
        let upstream = Upstream::parse(upstream)?;
        let listener = TcpListener::bind("127.0.0.1:0").context("fault proxy: cannot listen")?;
        let addr = listener.local_addr()?;
        let workers = options.workers;
        let shared = Arc::new(Shared {
            upstream,
            options,
            stop: AtomicBool::new(false),
            counts: Mutex::new(FaultCounts::default()),
            asked: Mutex::new(AskedPaths::default()),
        });
        let (tx, rx) = sync_channel::<TcpStream>(2 * workers);
        let rx = Arc::new(Mutex::new(rx));
        let workers = (0..workers)
            .map(|_| {
                let (shared, rx) = (Arc::clone(&shared), Arc::clone(&rx));
                std::thread::spawn(move || work(&shared, &rx))
            })
            .collect();
        let stop = Arc::clone(&shared);
        let acceptor = std::thread::spawn(move || {
            for conn in listener.incoming() {
                if stop.stop.load(Ordering::SeqCst) {
                    break;
                }
                match conn {
                    // Blocks while the queue is full: the backlog holds the rest.
                    Ok(conn) => {
                        if tx.send(conn).is_err() {
                            break;
                        }
                    }
                    // Out of descriptors, say: wait rather than spin.
                    Err(_) => std::thread::sleep(Duration::from_millis(10)),
                }
            }
        });
        Ok(FaultProxy {
            addr,
            shared,
            acceptor: Some(acceptor),
            workers,
        })
    }

    /// The proxy's world address, `http://127.0.0.1:PORT/`, to open the world at.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// What it has done so far.
    pub fn counts(&self) -> FaultCounts {
        *self.shared.counts.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Drop for FaultProxy {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        // Wakes the acceptor from `accept`; it then sees the flag and drops the queue's sender,
        // which ends the workers once they have closed what is queued.
        if TcpStream::connect_timeout(&self.addr, Duration::from_secs(1)).is_err() {
            // Not woken: its threads are left to end with the process rather than hang here.
            return;
        }
        if let Some(acceptor) = self.acceptor.take() {
            let _ = acceptor.join();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

fn work(shared: &Shared, rx: &Mutex<Receiver<TcpStream>>) {
    loop {
        let conn = match rx.lock() {
            Ok(rx) => rx.recv(),
            Err(_) => return,
        };
        let Ok(conn) = conn else { return };
        if shared.stop.load(Ordering::SeqCst) {
            continue; // dropped: closed unanswered
        }
        if let Err(e) = serve(shared, conn) {
            log::debug!("fault proxy: {e}");
        }
    }
}

/// Which fault, if any, the `nth` request (1 for the first) for `path` gets.
pub fn choose(seed: u64, path: &str, nth: u64, rate: f64) -> Option<Fault> {
    // FNV-1a over the path and the count, from a basis keyed by the seed, then a SplitMix64
    // finish so that every bit depends on every input.
    let h = crate::hash::FNV_BASIS ^ splitmix64(seed);
    let h = crate::hash::fnv1a64(crate::hash::fnv1a64(h, path.as_bytes()), &nth.to_le_bytes());
    let h = splitmix64(h);
    let unit = (h >> 11) as f64 / (1u64 << 53) as f64;
    if unit >= rate {
        return None;
    }
    Some(Fault::ALL[(splitmix64(h) % Fault::ALL.len() as u64) as usize])
}

fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Answers one connection (one request: every answer closes it).
fn serve(shared: &Shared, mut client: TcpStream) -> std::io::Result<()> {
    client.set_read_timeout(Some(REQUEST_HEAD_TIMEOUT))?;
    client.set_write_timeout(Some(UPSTREAM_TIMEOUT))?;
    // Peeked, not read: a reset closes the connection with the request unread.
    let Some(head) = peek_head(&client)? else {
        return Ok(());
    };
    let text = String::from_utf8_lossy(&head).into_owned();
    let mut words = text.lines().next().unwrap_or("").split_whitespace();
    let (method, target) = (words.next().unwrap_or(""), words.next().unwrap_or("/"));
    let path = target.split(['?', '#']).next().unwrap_or("");
    let (relative, query) = (path.trim_start_matches('/'), &target[path.len()..]);
    let spared = shared
        .options
        .spared
        .iter()
        .any(|p| relative.starts_with(p.as_str()));
    let fault = if relative.starts_with("tiles/") && !spared {
        let nth = shared
            .asked
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .ask(path);
        choose(shared.options.seed, path, nth, shared.options.rate)
    } else {
        None
    };
    let count = |update: &dyn Fn(&mut FaultCounts)| {
        let mut c = shared.counts.lock().unwrap_or_else(|e| e.into_inner());
        c.requests += 1;
        update(&mut c);
    };
    if fault != Some(Fault::Reset) {
        client.read_exact(&mut vec![0; head.len()])?;
    }
    match fault {
        None if !matches!(method, "GET" | "HEAD") => {
            count(&|c| c.passed += 1);
            client.write_all(
                b"HTTP/1.1 405 Method Not Allowed\r\nAllow: GET, HEAD\r\n\
                  Content-Length: 0\r\nConnection: close\r\n\r\n",
            )?;
        }
        None => match forward(shared, &text, relative, query) {
            Ok(mut upstream) => {
                count(&|c| c.passed += 1);
                std::io::copy(&mut upstream, &mut client)?;
            }
            Err(e) => {
                count(&|c| c.upstream_errors += 1);
                let body = format!("fault proxy: upstream {}: {e}\n", shared.upstream.authority);
                write!(
                    client,
                    "HTTP/1.1 502 Bad Gateway\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                    body.len()
                )?;
            }
        },
        Some(kind) => {
            count(&|c| c.count(kind));
            inject(shared, kind, &mut client, &text, relative, query)?;
        }
    }
    client.flush()?;
    if fault != Some(Fault::Reset) {
        let _ = client.shutdown(Shutdown::Write);
    }
    Ok(())
}

/// Does fault `kind` to the request on `client`.
fn inject(
    shared: &Shared,
    kind: Fault,
    client: &mut TcpStream,
    head: &str,
    relative: &str,
    query: &str,
) -> std::io::Result<()> {
    let status = |code: &str| {
        format!("HTTP/1.1 {code}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n").into_bytes()
    };
    match kind {
        Fault::Status500 => client.write_all(&status("500 Internal Server Error")),
        Fault::Status503 => client.write_all(&status("503 Service Unavailable")),
        Fault::Stall => {
            let start = Instant::now();
            client.set_read_timeout(Some(Duration::from_millis(100)))?;
            let mut buf = [0u8; 1024];
            while start.elapsed() < shared.options.stall && !shared.stop.load(Ordering::SeqCst) {
                match client.read(&mut buf) {
                    Ok(0) => break, // the client hung up
                    Ok(_) => {}
                    Err(e)
                        if matches!(
                            e.kind(),
                            std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                        ) => {}
                    Err(_) => break,
                }
            }
            Ok(())
        }
        // The request is still unread: closing now makes the kernel send a reset.
        Fault::Reset => client.write_all(b"HTTP/1.1 200 OK\r\nContent-Ty"),
        Fault::ShortBody => {
            let (fields, body) = match forward(shared, head, relative, query)
                .and_then(read_response)
            {
                Ok((fields, body))
                    if fields[0].split_whitespace().nth(1) == Some("200") && body.len() >= 2 =>
                {
                    (fields, body)
                }
                // No body to cut short (a 304, an error): announce one and send half of it.
                _ => (vec!["HTTP/1.1 200 OK".to_string()], vec![0; 1024]),
            };
            let mut head = fields.join("\r\n");
            head.push_str(&format!(
                "\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                body.len()
            ));
            client.write_all(head.as_bytes())?;
            client.write_all(&body[..body.len() / 2])
        }
    }
}

/// Sends the request (head `head`, file `relative` and its `query`) to the upstream server
/// and returns the connection its answer comes on.
fn forward(shared: &Shared, head: &str, relative: &str, query: &str) -> std::io::Result<TcpStream> {
    let up = &shared.upstream;
    let mut lines = head.lines();
    let method = lines
        .next()
        .and_then(|l| l.split_whitespace().next())
        .unwrap_or("GET");
    let query = match (query.strip_prefix('?').unwrap_or(query), up.query.as_str()) {
        ("", "") => String::new(),
        (q, "") | ("", q) => format!("?{q}"),
        (client, world) => format!("?{world}&{client}"),
    };
    let mut request = format!("{method} {}{relative}{query} HTTP/1.1\r\n", up.base);
    for line in lines.take_while(|l| !l.is_empty()) {
        let name = line.split(':').next().unwrap_or("").trim();
        // Hop-by-hop fields and the host are the proxy's own.
        if [
            "host",
            "connection",
            "keep-alive",
            "proxy-connection",
            "te",
            "upgrade",
        ]
        .iter()
        .any(|h| name.eq_ignore_ascii_case(h))
        {
            continue;
        }
        request.push_str(line);
        request.push_str("\r\n");
    }
    request.push_str(&format!(
        "Host: {}\r\nConnection: close\r\n\r\n",
        up.authority
    ));
    let mut stream = up.connect()?;
    stream.write_all(request.as_bytes())?;
    Ok(stream)
}

/// Reads a whole upstream answer until the upstream closes (at most [`MAX_HELD_BODY`] bytes
/// of body): its status line and header fields other than those of framing (`Content-Length`,
/// `Transfer-Encoding`, `Connection`), and its body, de-chunked.
fn read_response(upstream: TcpStream) -> std::io::Result<(Vec<String>, Vec<u8>)> {
    let mut all = Vec::new();
    upstream
        .take((MAX_REQUEST_HEAD + MAX_HELD_BODY) as u64)
        .read_to_end(&mut all)?;
    let end = find_head_end(&all)
        .ok_or_else(|| std::io::Error::other("upstream answer without a complete head"))?;
    let body = all.split_off(end);
    let head = String::from_utf8_lossy(&all).into_owned();
    let mut chunked = false;
    let mut fields = Vec::new();
    for line in head.lines().filter(|l| !l.is_empty()) {
        let name = line.split(':').next().unwrap_or("").trim();
        if name.eq_ignore_ascii_case("transfer-encoding") {
            chunked = line.to_ascii_lowercase().contains("chunked");
        } else if !["content-length", "connection"]
            .iter()
            .any(|f| name.eq_ignore_ascii_case(f))
        {
            fields.push(line.to_string());
        }
    }
    if fields.is_empty() {
        return Err(std::io::Error::other(
            "upstream answer without a status line",
        ));
    }
    let body = if chunked {
        dechunk(&body).ok_or_else(|| std::io::Error::other("upstream chunks malformed"))?
    } else {
        body
    };
    Ok((fields, body))
}

/// The data of a chunked body (through its last chunk; trailers ignored), if well formed.
fn dechunk(mut bytes: &[u8]) -> Option<Vec<u8>> {
    let mut data = Vec::new();
    loop {
        let line_end = bytes.windows(2).position(|w| w == b"\r\n")?;
        let size = std::str::from_utf8(&bytes[..line_end]).ok()?;
        let size = usize::from_str_radix(size.split(';').next()?.trim(), 16).ok()?;
        bytes = &bytes[line_end + 2..];
        if size == 0 {
            return Some(data);
        }
        data.extend_from_slice(bytes.get(..size)?);
        bytes = bytes.get(size + 2..)?;
    }
}

/// The length of a request or response head (through its blank line), if complete.
fn find_head_end(bytes: &[u8]) -> Option<usize> {
    bytes
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map(|p| p + 4)
}

/// Peeks at the request head without reading it; `None` if the client closed first.
fn peek_head(client: &TcpStream) -> std::io::Result<Option<Vec<u8>>> {
    let start = Instant::now();
    let mut buf = vec![0; MAX_REQUEST_HEAD];
    loop {
        let n = client.peek(&mut buf)?;
        if n == 0 {
            return Ok(None);
        }
        if let Some(end) = find_head_end(&buf[..n]) {
            buf.truncate(end);
            return Ok(Some(buf));
        }
        if n == buf.len() {
            return Err(std::io::Error::other("request head too long"));
        }
        if start.elapsed() > REQUEST_HEAD_TIMEOUT {
            return Err(std::io::Error::other("request head incomplete"));
        }
        // Part of the head is here; peeking again returns at once until more arrives.
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_choice_is_deterministic_and_follows_the_rate() {
        let paths: Vec<String> = (0..2000)
            .map(|i| format!("/tiles/L2/{}_{}.height.exr", i % 40, i / 40))
            .collect();
        let faulted = |seed, rate| {
            paths
                .iter()
                .filter(|p| choose(seed, p, 1, rate).is_some())
                .count()
        };
        assert_eq!(faulted(7, 0.0), 0);
        assert_eq!(faulted(7, 1.0), paths.len());
        let quarter = faulted(7, 0.25);
        assert!((400..600).contains(&quarter), "{quarter} of 2000 at 0.25");
        for p in &paths[..50] {
            assert_eq!(choose(7, p, 1, 0.5), choose(7, p, 1, 0.5));
        }
        // Another seed, or the next request of a path, is another choice.
        let same = |f: &dyn Fn(&String) -> Option<Fault>| {
            paths
                .iter()
                .filter(|p| choose(7, p, 1, 1.0) == f(p))
                .count()
        };
        assert!(same(&|p| choose(8, p, 1, 1.0)) < 600);
        assert!(same(&|p| choose(7, p, 2, 1.0)) < 600);
        // Each kind about a fifth of the faults.
        for kind in Fault::ALL {
            let n = paths
                .iter()
                .filter(|p| choose(3, p, 1, 1.0) == Some(kind))
                .count();
            assert!((300..500).contains(&n), "{kind:?}: {n} of 2000");
        }
    }

    /// Requests of ever new paths keep at most [`MAX_ASKED_PATHS`] counts, forgetting the path
    /// asked first; a path still counted goes on from its count.
    #[test]
    fn the_paths_counted_are_bounded() {
        let mut asked = AskedPaths::default();
        let path = |i: usize| format!("/tiles/L9/{i}_0.height.exr");
        assert_eq!((asked.ask(&path(0)), asked.ask(&path(0))), (1, 2));
        for i in 1..MAX_ASKED_PATHS + 100 {
            assert_eq!(asked.ask(&path(i)), 1);
        }
        assert_eq!(asked.counts.len(), MAX_ASKED_PATHS);
        assert_eq!(asked.order.len(), MAX_ASKED_PATHS);
        let last = path(MAX_ASKED_PATHS + 99);
        assert_eq!(asked.ask(&last), 2, "still counted");
        // The first 100 are forgotten: counted from 1 again.
        assert_eq!(asked.ask(&path(0)), 1);
        assert_eq!(asked.counts.len(), MAX_ASKED_PATHS);
    }

    #[test]
    fn chunked_bodies_are_joined() {
        assert_eq!(
            dechunk(b"4\r\nWiki\r\n7;x=1\r\npedia i\r\n0\r\nTrailer: t\r\n\r\n").unwrap(),
            b"Wikipedia i"
        );
        assert_eq!(dechunk(b"0\r\n\r\n").unwrap(), b"");
        assert!(dechunk(b"9\r\nWiki\r\n").is_none(), "cut short");
        assert!(dechunk(b"zz\r\n").is_none());
    }

    #[test]
    fn upstream_addresses_parse_into_host_and_base() {
        let up = Upstream::parse("http://127.0.0.1:8080/worlds/santa-cruz").unwrap();
        assert_eq!(up.authority, "127.0.0.1:8080");
        assert_eq!(up.base, "/worlds/santa-cruz/");
        assert_eq!(up.addrs, vec!["127.0.0.1:8080".parse().unwrap()]);
        assert_eq!(up.query, "");
        let up = Upstream::parse("HTTP://127.0.0.1:9/").unwrap();
        assert_eq!(up.base, "/");
        let up = Upstream::parse("http://127.0.0.1:9?sig=a%2F#top").unwrap();
        assert_eq!(
            (up.authority.as_str(), up.base.as_str()),
            ("127.0.0.1:9", "/")
        );
        assert_eq!(up.query, "sig=a%2F");
        let up = Upstream::parse("http://127.0.0.1:9/w/?x=1&y=2#f?z").unwrap();
        assert_eq!((up.base.as_str(), up.query.as_str()), ("/w/", "x=1&y=2"));
        assert_eq!(
            Upstream::parse("http://127.0.0.1").unwrap().addrs[0].port(),
            80
        );
        for bad in ["https://127.0.0.1/", "127.0.0.1:80/", "http:///w"] {
            let e = Upstream::parse(bad).err().unwrap();
            assert!(e.to_string().contains(bad), "{e}");
        }
    }

    #[test]
    fn options_out_of_range_are_refused() {
        let up = "http://127.0.0.1:9/";
        for (options, words) in [
            (
                FaultOptions {
                    rate: 1.5,
                    ..FaultOptions::default()
                },
                "must be in 0..=1",
            ),
            (
                FaultOptions {
                    rate: f64::NAN,
                    ..FaultOptions::default()
                },
                "must be in 0..=1",
            ),
            (
                FaultOptions {
                    workers: 0,
                    ..FaultOptions::default()
                },
                "must be in 1..=1024",
            ),
            (
                FaultOptions {
                    stall: Duration::MAX,
                    ..FaultOptions::default()
                },
                "must be at most 3600 s",
            ),
        ] {
            let e = FaultProxy::start_with(up, options).unwrap_err();
            assert!(e.to_string().contains(words), "{e}");
        }
    }
}
