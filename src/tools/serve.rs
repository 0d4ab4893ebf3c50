//! `verdant serve`: a small static file server for a world folder, for trying worlds over HTTP
//! locally. It answers `GET` and `HEAD` with the file's content type, an `ETag` and a
//! `Last-Modified`, and a conditional `GET` (`If-None-Match`, `If-Modified-Since`) whose file
//! has not changed with `304 Not Modified`; a `Range` request (one range) gets `206 Partial
//! Content` with those bytes. Production puts the world folder behind any
//! ordinary HTTP server, object store or CDN instead.

use std::net::SocketAddr;
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, bail};
use tiny_http::{Header, Method, Request, Response};

/// Requests answered at once.
const WORKERS: usize = 8;

/// A running server; dropping it stops it.
pub struct WorldServer {
    server: Arc<tiny_http::Server>,
    addr: SocketAddr,
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
        for name in ["world.toml", "tiles"] {
            if let Ok(real) = root.join(name).canonicalize()
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
        let root = Arc::new(
            root.canonicalize()
                .with_context(|| format!("{}: cannot open", root.display()))?,
        );
        let server = tiny_http::Server::http(addr)
            .map_err(|e| anyhow::anyhow!("cannot listen on {addr}: {e}"))?;
        let addr = server
            .server_addr()
            .to_ip()
            .context("the server has no IP address")?;
        let server = Arc::new(server);
        let workers = (0..WORKERS)
            .map(|_| {
                let (server, root) = (Arc::clone(&server), Arc::clone(&root));
                std::thread::spawn(move || {
                    while let Ok(request) = server.recv() {
                        if let Err(e) = answer(&root, request) {
                            log::debug!("serve: {e}");
                        }
                    }
                })
            })
            .collect();
        Ok(WorldServer {
            server,
            addr,
            workers,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The world's URL: `http://ADDR/`.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Serves until the process ends.
    pub fn wait(mut self) {
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

impl Drop for WorldServer {
    fn drop(&mut self) {
        for _ in 0..self.workers.len() {
            self.server.unblock();
        }
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
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
    // Percent-encoded names (a plant file `my%20fern.gltf`) are decoded first, then checked
    // like any other: `%2e%2e` is `..` and refused, a NUL never reaches the file system.
    let path = percent_encoding::percent_decode_str(raw)
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

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

fn answer(root: &Path, request: Request) -> std::io::Result<()> {
    if !matches!(request.method(), Method::Get | Method::Head) {
        return request.respond(Response::empty(405).with_header(header("Allow", "GET, HEAD")));
    }
    let Some(file) = resolve(root, request.url()) else {
        return request.respond(Response::from_string("not found\n").with_status_code(404));
    };
    let meta = std::fs::metadata(&file)?;
    let modified = meta.modified().unwrap_or(UNIX_EPOCH);
    let nanos = modified
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let etag = format!("\"{:x}-{:x}\"", meta.len(), nanos);
    let last_modified = httpdate::fmt_http_date(modified);
    let value = |name: &'static str| {
        request
            .headers()
            .iter()
            .find(|h| h.field.equiv(name))
            .map(|h| h.value.as_str().to_string())
    };
    // If-None-Match wins over If-Modified-Since (RFC 9110, 13.2.2).
    let not_modified = match value("If-None-Match") {
        Some(tags) => tags
            .split(',')
            .any(|t| t.trim() == "*" || t.trim().trim_start_matches("W/") == etag),
        None => value("If-Modified-Since")
            .and_then(|d| httpdate::parse_http_date(&d).ok())
            .is_some_and(|since| truncate_to_seconds(modified) <= since),
    };
    let validators = [
        header("ETag", &etag),
        header("Last-Modified", &last_modified),
    ];
    if not_modified {
        let mut response = Response::empty(304);
        for h in validators {
            response = response.with_header(h);
        }
        return request.respond(response);
    }
    let len = meta.len();
    let (status, span) = match value("Range").map(|r| byte_range(&r, len)) {
        None => (200, None),
        Some(Some(span)) => (206, Some(span)),
        Some(None) => {
            return request.respond(
                Response::empty(416)
                    .with_header(header("Content-Range", &format!("bytes */{len}"))),
            );
        }
    };
    // The body is read from the file as it is sent (never whole into memory, and not at all
    // for HEAD), with a Content-Length, never chunked (tiny_http chunks bodies over 32 KiB by
    // default, such as a world manifest with many paths).
    let [first, last] = span.unwrap_or([0, len.saturating_sub(1)]);
    let length = if len == 0 { 0 } else { last - first + 1 };
    let mut reader = std::fs::File::open(&file)?;
    std::io::Seek::seek(&mut reader, std::io::SeekFrom::Start(first))?;
    let body = std::io::Read::take(reader, length);
    let mut response = Response::new(
        tiny_http::StatusCode(status),
        Vec::new(),
        body,
        usize::try_from(length).ok(),
        None,
    )
    .with_chunked_threshold(usize::MAX)
    .with_header(header("Content-Type", content_type(&file)))
    .with_header(header("Accept-Ranges", "bytes"));
    if let Some([first, last]) = span {
        response = response.with_header(header(
            "Content-Range",
            &format!("bytes {first}-{last}/{len}"),
        ));
    }
    for h in validators {
        response = response.with_header(h);
    }
    request.respond(response)
}

/// The bytes (first, last, inclusive) that a `Range` header asks of a file of `len` bytes: one
/// range, `bytes=A-B`, `bytes=A-` or `bytes=-N`; `None` where it cannot be satisfied (the
/// server then answers 416).
fn byte_range(value: &str, len: u64) -> Option<[u64; 2]> {
    let spec = value.trim().strip_prefix("bytes=")?;
    if spec.contains(',') || len == 0 {
        return None;
    }
    let (a, b) = spec.split_once('-')?;
    let (a, b) = (a.trim(), b.trim());
    let [first, last] = if a.is_empty() {
        let n: u64 = b.parse().ok()?;
        [len.saturating_sub(n), len - 1]
    } else {
        let first: u64 = a.parse().ok()?;
        let last = if b.is_empty() {
            len - 1
        } else {
            b.parse::<u64>().ok()?.min(len - 1)
        };
        [first, last]
    };
    (first <= last && first < len).then_some([first, last])
}

fn truncate_to_seconds(t: SystemTime) -> SystemTime {
    let s = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    UNIX_EPOCH + std::time::Duration::from_secs(s)
}

#[cfg(test)]
mod tests {
    use super::byte_range;

    #[test]
    fn ranges_are_read_as_rfc_9110_writes_them() {
        assert_eq!(byte_range("bytes=0-0", 10), Some([0, 0]));
        assert_eq!(byte_range("bytes=2-5", 10), Some([2, 5]));
        assert_eq!(byte_range("bytes=7-", 10), Some([7, 9]));
        assert_eq!(byte_range("bytes=-3", 10), Some([7, 9]));
        assert_eq!(byte_range("bytes=4-100", 10), Some([4, 9]));
        for bad in [
            "bytes=10-12",
            "bytes=5-2",
            "bytes=0-1,4-5",
            "items=0-1",
            "bytes=a-b",
        ] {
            assert_eq!(byte_range(bad, 10), None, "{bad}");
        }
        assert_eq!(byte_range("bytes=0-0", 0), None);
    }
}
