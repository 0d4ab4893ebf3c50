//! The disk cache of fetched files: bounded in bytes, each body checked against its length
//! and checksum before use, revalidated with the server's `ETag` or `Last-Modified`.

use std::collections::HashMap;
use std::path::PathBuf;

use super::{HttpCacheConfig, HttpError};

/// What a cached body is revalidated with.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Validator {
    ETag(String),
    LastModified(String),
}

impl Validator {
    /// The response's `ETag`, or else its `Last-Modified` (a value that is not text, which
    /// could not be sent back, counts as none).
    pub(super) fn from_headers(headers: &ureq::http::HeaderMap) -> Option<Validator> {
        let text = |name| Some(headers.get(name)?.to_str().ok()?.trim().to_string());
        if let Some(tag) = text("etag") {
            return Some(Validator::ETag(tag));
        }
        text("last-modified").map(Validator::LastModified)
    }

    pub(super) fn to_line(&self) -> String {
        match self {
            Validator::ETag(t) => format!("etag {t}"),
            Validator::LastModified(d) => format!("last-modified {d}"),
        }
    }

    /// The validator a cache entry's metadata line names, or why there is none: the line
    /// names none, or its value cannot be sent back as a header (a damaged entry: dropped, and
    /// the file fetched again, rather than refused by the client on every run).
    pub(super) fn from_line(line: &str) -> Result<Validator, &'static str> {
        let validator = match line.split_once(' ') {
            Some(("etag", value)) => Validator::ETag(value.to_string()),
            Some(("last-modified", value)) => Validator::LastModified(value.to_string()),
            _ => return Err("no validator in metadata"),
        };
        let (Validator::ETag(value) | Validator::LastModified(value)) = &validator;
        match ureq::http::HeaderValue::from_str(value) {
            Ok(_) => Ok(validator),
            Err(_) => Err("a validator that cannot be sent back as a header"),
        }
    }
}

/// FNV-1a, 64 bits ([`crate::hash::fnv1a64`]): enough to name a URL's entry and to catch a
/// damaged body (not an adversary).
pub(super) fn fnv1a64(bytes: &[u8]) -> u64 {
    crate::hash::fnv1a64(crate::hash::FNV_BASIS, bytes)
}

/// The most bytes of a cache entry's metadata (a URL, a validator and a checksum).
pub(super) const MAX_META_BYTES: u64 = 16 << 10;

/// Whether `name` is a key of the cache ([`DiskCache::key`]): 16 lowercase hexadecimal digits.
fn is_key(name: &str) -> bool {
    name.len() == 16 && name.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// How old a temporary of the cache must be to be taken for one a killed run left.
const STALE_TEMPORARY: std::time::Duration = std::time::Duration::from_secs(60);

/// Whether `name` is a temporary of the cache's own: `KEY.body.PID.tmp` or `KEY.meta.PID.tmp`
/// (or, as earlier builds named them, without the `PID`).
fn is_temporary(name: &str) -> bool {
    let Some(rest) = name.strip_suffix(".tmp") else {
        return false;
    };
    let mut parts = rest.splitn(3, '.');
    let (Some(key), Some(kind)) = (parts.next(), parts.next()) else {
        return false;
    };
    is_key(key)
        && matches!(kind, "body" | "meta")
        && parts
            .next()
            .is_none_or(|pid| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// The bytes of one of the cache's files, `what` (its body or metadata), of at most `max`
/// bytes. A file that is not a regular one (a FIFO, whose opening would wait for a writer for
/// ever, and with it every load behind the cache's lock; a device) is refused before it is
/// opened, as worlds' files are, and so is one longer than `max`.
fn read_cached(path: &std::path::Path, max: u64, what: &str) -> Result<Vec<u8>, String> {
    use crate::world::WorldError;
    match crate::world::format::read_regular(path, max) {
        Ok(bytes) => Ok(bytes),
        Err(WorldError::NotARegularFile { kind, .. }) => {
            Err(format!("{what} is not a regular file ({kind})"))
        }
        Err(WorldError::FileTooLarge { size, .. }) => {
            Err(format!("{what} of {size} bytes, more than {max}"))
        }
        Err(WorldError::Io { source, .. }) => Err(format!("{what}: {source}")),
        Err(e) => Err(format!("{what}: {e}")),
    }
}

/// Fetched bodies on disk, one `{key}.body` and `{key}.meta` per URL, the key a hash of the
/// URL. The metadata holds three lines: the URL, the validator, and `fnv1a64 {hex} {length}`
/// of the body. Each is written to a temporary file and renamed into place, the body before
/// its metadata, so that an interrupted write leaves a body that its metadata does not match
/// (and that is dropped) rather than a torn file. The least recently used go first beyond
/// `max_bytes`.
pub(super) struct DiskCache {
    pub(super) dir: PathBuf,
    pub(super) max_bytes: u64,
    pub(super) bytes: u64,
    pub(super) clock: u64,
    /// Key to (body bytes, last use).
    pub(super) entries: HashMap<String, (u64, u64)>,
    /// A write has failed and been reported: later failures (a full disk fails every write)
    /// are not reported again.
    pub(super) warned: bool,
    /// A file whose validator made its metadata longer than [`MAX_META_BYTES`] was not cached:
    /// said once.
    told_long_meta: bool,
}

impl DiskCache {
    pub(super) fn open(config: &HttpCacheConfig) -> Result<DiskCache, HttpError> {
        let err = |source| HttpError::Cache {
            path: config.dir.clone(),
            source,
        };
        // Never among a world's files: the cache writes and evicts its entries there.
        if let Some(why) = crate::world::format::refused_output(&config.dir) {
            return Err(err(std::io::Error::other(format!(
                "it is {why}; give the cache a folder of its own"
            ))));
        }
        if std::fs::metadata(&config.dir).is_ok_and(|m| !m.is_dir()) {
            return Err(err(std::io::Error::other(
                "it is a file, not a folder; give the cache a folder of its own",
            )));
        }
        std::fs::create_dir_all(&config.dir).map_err(err)?;
        let mut cache = DiskCache {
            dir: config.dir.clone(),
            max_bytes: config.max_bytes,
            bytes: 0,
            clock: 0,
            entries: HashMap::new(),
            warned: false,
            told_long_meta: false,
        };
        for entry in std::fs::read_dir(&config.dir).map_err(err)? {
            let Ok(entry) = entry else { continue };
            let name = entry.file_name().to_string_lossy().into_owned();
            // A write that was cut short (a killed run) left its temporary: removed once it is
            // a minute old, so that another run writing into the same cache keeps its own.
            if is_temporary(&name) {
                let stale = entry
                    .metadata()
                    .and_then(|m| m.modified())
                    .ok()
                    .and_then(|t| t.elapsed().ok())
                    .is_some_and(|age| age >= STALE_TEMPORARY);
                if stale {
                    let _ = std::fs::remove_file(entry.path());
                }
                continue;
            }
            // Only the cache's own entries, named by their key: a user's files in the folder
            // (`thesis.body`, say) are neither counted nor ever removed.
            let Some(key) = name.strip_suffix(".body").filter(|k| is_key(k)) else {
                continue;
            };
            if let Ok(meta) = entry.metadata()
                && meta.is_file()
            {
                // The entry's bytes on disk: its body and its metadata file.
                let meta_len = std::fs::metadata(config.dir.join(format!("{key}.meta")))
                    .map_or(0, |m| m.len());
                let size = meta.len() + meta_len;
                cache.entries.insert(key.to_string(), (size, 0));
                cache.bytes += size;
            }
        }
        cache.evict(0);
        Ok(cache)
    }

    /// The key of `url`: 16 hexadecimal digits ([`is_key`]).
    pub(super) fn key(url: &str) -> String {
        format!("{:016x}", fnv1a64(url.as_bytes()))
    }

    pub(super) fn path(&self, key: &str, suffix: &str) -> PathBuf {
        self.dir.join(format!("{key}.{suffix}"))
    }

    /// The cached validator and body of `url` (at most `max` bytes), if its entry is whole; a
    /// damaged entry is removed (with a warning) so that the file is fetched again
    /// unconditionally.
    pub(super) fn get(&mut self, url: &str, max: u64) -> Option<(Validator, Vec<u8>)> {
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
                // Gone whole (another run sharing the cache evicted it) is a plain miss;
                // anything else is damage, said.
                let gone = !self.path(&key, "meta").exists() && !self.path(&key, "body").exists();
                if !gone {
                    log::warn!(
                        "{}: cached copy of {url} dropped ({problem}); fetching it again",
                        self.dir.display()
                    );
                }
                self.remove(&key);
                None
            }
        }
    }

    pub(super) fn read_entry(
        &self,
        key: &str,
        url: &str,
        max: u64,
    ) -> Result<(Validator, Vec<u8>), String> {
        let meta_path = self.path(key, "meta");
        let meta = read_cached(&meta_path, MAX_META_BYTES, "metadata")?;
        let meta = String::from_utf8(meta).map_err(|_| "metadata not UTF-8".to_string())?;
        let lines: Vec<&str> = meta.lines().collect();
        let [meta_url, validator, sum] = lines[..] else {
            return Err(format!("metadata has {} lines, not 3", lines.len()));
        };
        if meta_url != url {
            return Err(format!("metadata names {meta_url}"));
        }
        let validator = Validator::from_line(validator)?;
        let (hash, len) = sum
            .strip_prefix("fnv1a64 ")
            .and_then(|s| s.split_once(' '))
            .and_then(|(h, l)| Some((u64::from_str_radix(h, 16).ok()?, l.parse::<u64>().ok()?)))
            .ok_or("no checksum in metadata")?;
        if len > max {
            return Err(format!(
                "body of {len} bytes, more than the {max} this file may hold"
            ));
        }
        let body = read_cached(&self.path(key, "body"), len, "body")?;
        if body.len() as u64 != len || fnv1a64(&body) != hash {
            return Err("body does not match its checksum".into());
        }
        Ok((validator, body))
    }

    pub(super) fn put(&mut self, url: &str, validator: &Validator, body: &[u8]) {
        let meta = format!(
            "{url}\n{}\nfnv1a64 {:016x} {}\n",
            validator.to_line(),
            fnv1a64(body),
            body.len()
        );
        // What the entry holds on disk, its metadata included (an entry of an empty body
        // costs its metadata's bytes).
        let size = (body.len() + meta.len()) as u64;
        if size > self.max_bytes {
            return;
        }
        // Metadata that `get` would refuse to read is not written (an ETag of kilobytes), and
        // an older entry of the address, no longer the file, goes.
        if meta.len() as u64 > MAX_META_BYTES {
            self.remove(&Self::key(url));
            if !self.told_long_meta {
                log::warn!(
                    "{url}: not cached: its address and validator ({} bytes) make metadata \
                     longer than the {MAX_META_BYTES} bytes the tile cache reads (files like it \
                     are fetched whole each time; further ones are not reported)",
                    meta.len()
                );
                self.told_long_meta = true;
            }
            return;
        }
        let key = Self::key(url);
        self.remove(&key);
        self.evict(size);
        // Named by the process too: two runs may share a cache.
        let dir = self.dir.clone();
        let tmp = |suffix: &str| dir.join(format!("{key}.{suffix}.{}.tmp", std::process::id()));
        let write = |suffix: &str, bytes: &[u8]| {
            std::fs::write(tmp(suffix), bytes)
                .and_then(|()| std::fs::rename(tmp(suffix), self.path(&key, suffix)))
        };
        if let Err(e) = write("body", body).and_then(|()| write("meta", meta.as_bytes())) {
            if !self.warned {
                log::warn!(
                    "{}: tile cache: {e}; tiles that cannot be cached are fetched again when \
                     next needed (further failures are not reported)",
                    self.dir.display()
                );
                self.warned = true;
            }
            for suffix in ["body", "meta"] {
                let _ = std::fs::remove_file(tmp(suffix));
                let _ = std::fs::remove_file(self.path(&key, suffix));
            }
            return;
        }
        self.clock += 1;
        self.entries.insert(key, (size, self.clock));
        self.bytes += size;
    }

    pub(super) fn remove(&mut self, key: &str) {
        if let Some((size, _)) = self.entries.remove(key) {
            self.bytes -= size;
            let _ = std::fs::remove_file(self.path(key, "body"));
            let _ = std::fs::remove_file(self.path(key, "meta"));
        }
    }

    /// Removes the least recently used entries until `incoming` more bytes fit.
    pub(super) fn evict(&mut self, incoming: u64) {
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
    use std::path::Path;

    use super::*;

    /// A file whose validator would make metadata that `get` refuses to read is not cached
    /// (it was written, then dropped with a warning on every later read); one of ordinary
    /// metadata beside it is.
    #[test]
    fn metadata_too_long_to_read_back_is_not_written() {
        let tmp = tempfile::tempdir().unwrap();
        let config = HttpCacheConfig {
            dir: tmp.path().join("cache"),
            max_bytes: 1 << 20,
        };
        let mut cache = DiskCache::open(&config).unwrap();
        let long = Validator::ETag(format!("\"{}\"", "e".repeat(20_000)));
        cache.put("http://h/long", &long, &[1; 100]);
        assert!(cache.entries.is_empty() && cache.told_long_meta);
        assert_eq!(std::fs::read_dir(&config.dir).unwrap().count(), 0);
        assert!(cache.get("http://h/long", 1000).is_none());
        let short = Validator::ETag("\"a\"".into());
        cache.put("http://h/short", &short, &[2; 100]);
        assert_eq!(cache.get("http://h/short", 1000).unwrap().1, [2; 100]);
        // The file at an address, now with a long validator: its old entry is not kept.
        cache.put("http://h/short", &long, &[3; 100]);
        assert!(cache.get("http://h/short", 1000).is_none());
        assert_eq!(std::fs::read_dir(&config.dir).unwrap().count(), 0);
    }

    #[test]
    fn the_disk_cache_stays_within_its_bytes_and_drops_the_least_recently_used() {
        let tmp = tempfile::tempdir().unwrap();
        // Each entry is its 100 bytes and about 50 of metadata: two fit, not three.
        let config = HttpCacheConfig {
            dir: tmp.path().join("cache"),
            max_bytes: 400,
        };
        let mut cache = DiskCache::open(&config).unwrap();
        let tag = Validator::ETag("\"a\"".into());
        cache.put("http://h/a", &tag, &[1; 100]);
        cache.put("http://h/b", &tag, &[2; 100]);
        assert_eq!(cache.entries.len(), 2);
        assert!(cache.get("http://h/a", 1000).is_some()); // a is now more recent than b
        cache.put("http://h/c", &tag, &[3; 100]);
        assert!(cache.bytes <= 400);
        // What the cache counts is what its folder holds.
        let on_disk: u64 = std::fs::read_dir(&config.dir)
            .unwrap()
            .map(|e| e.unwrap().metadata().unwrap().len())
            .sum();
        assert_eq!(cache.bytes, on_disk);
        assert!(
            cache.get("http://h/b", 1000).is_none(),
            "b was the least recently used"
        );
        assert_eq!(cache.get("http://h/a", 1000).unwrap().1, vec![1; 100]);
        assert_eq!(
            cache.get("http://h/c", 1000).unwrap(),
            (tag.clone(), vec![3; 100])
        );
        cache.put("http://h/huge", &tag, &[0; 400]);
        assert!(cache.get("http://h/huge", 1000).is_none());
        // Empty bodies cost their metadata: they cannot fill the folder past its bytes.
        for i in 0..100 {
            cache.put(&format!("http://h/empty{i}"), &tag, &[]);
        }
        assert!(
            cache.bytes <= 400 && cache.entries.len() < 10,
            "{}",
            cache.entries.len()
        );
        // Reopened, it finds its files and still keeps within its bytes.
        drop(cache);
        let small = HttpCacheConfig {
            max_bytes: 200,
            ..config
        };
        let cache = DiskCache::open(&small).unwrap();
        assert!(
            cache.bytes <= 200 && !cache.entries.is_empty(),
            "{}",
            cache.bytes
        );
    }

    /// The cache shares its folder with whatever else is there: a user's `thesis.body` and
    /// `thesis.meta`, a key-named folder, other files, are neither counted nor removed, however
    /// little room the cache has.
    #[test]
    fn files_in_the_cache_folder_that_are_not_its_entries_are_left_alone() {
        let tmp = tempfile::tempdir().unwrap();
        let mine: [(&str, &[u8]); 4] = [
            ("thesis.body", &[9; 5000]),
            ("thesis.meta", b"my notes"),
            ("0123456789ABCDEF.body", &[8; 300]),
            ("keep.txt", b"keep"),
        ];
        for (name, bytes) in mine {
            std::fs::write(tmp.path().join(name), bytes).unwrap();
        }
        std::fs::create_dir(tmp.path().join("0123456789abcdef.body")).unwrap();
        let config = HttpCacheConfig {
            dir: tmp.path().to_path_buf(),
            max_bytes: 150,
        };
        let mut cache = DiskCache::open(&config).unwrap();
        assert_eq!((cache.bytes, cache.entries.len()), (0, 0));
        let tag = Validator::ETag("\"a\"".into());
        for i in 0..5 {
            cache.put(&format!("http://h/{i}"), &tag, &[1; 100]);
        }
        assert!(cache.bytes <= 150);
        for (name, bytes) in mine {
            assert_eq!(
                std::fs::read(tmp.path().join(name)).unwrap(),
                bytes,
                "{name}"
            );
        }
        assert!(tmp.path().join("0123456789abcdef.body").is_dir());
    }

    /// A write that fails (here the entry's metadata cannot be put in place: a folder stands
    /// at its name) leaves neither the body nor a temporary; temporaries a killed run left are
    /// swept when the cache opens, a user's files of like names kept; a file as the cache's
    /// folder is refused saying so.
    #[test]
    fn a_failed_write_leaves_no_temporaries_and_old_ones_are_swept() {
        let tmp = tempfile::tempdir().unwrap();
        let config = HttpCacheConfig {
            dir: tmp.path().join("cache"),
            max_bytes: 1 << 20,
        };
        let mut cache = DiskCache::open(&config).unwrap();
        let key = DiskCache::key("http://h/a");
        std::fs::create_dir_all(config.dir.join(format!("{key}.meta/x"))).unwrap();
        cache.put("http://h/a", &Validator::ETag("\"a\"".into()), &[1; 100]);
        assert!(cache.warned);
        assert_eq!(cache.bytes, 0);
        let names = |d: &Path| {
            let mut v: Vec<String> = std::fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        assert_eq!(names(&config.dir), [format!("{key}.meta")]);
        // Temporaries of a killed run go when the cache opens, once a minute old; a young one
        // (another run's, writing now) and a user's file stay.
        let old = std::time::SystemTime::now() - std::time::Duration::from_secs(120);
        for name in [
            "00000000000000ff.body.tmp",
            "00000000000000ff.meta.4242.tmp",
            "draft.body.tmp",
        ] {
            let f = std::fs::File::create(config.dir.join(name)).unwrap();
            f.set_modified(old).unwrap();
        }
        std::fs::write(config.dir.join("00000000000000aa.body.77.tmp"), "now").unwrap();
        drop(cache);
        let cache = DiskCache::open(&config).unwrap();
        assert_eq!(cache.bytes, 0);
        assert_eq!(
            names(&config.dir),
            [
                "00000000000000aa.body.77.tmp".to_owned(),
                format!("{key}.meta"),
                "draft.body.tmp".to_owned()
            ]
        );
        // A file where the folder should be.
        let file = tmp.path().join("afile");
        std::fs::write(&file, "x").unwrap();
        let e = DiskCache::open(&HttpCacheConfig {
            dir: file,
            max_bytes: 1 << 20,
        })
        .err()
        .map(|e| e.to_string())
        .unwrap();
        assert!(e.contains("afile") && e.contains("not a folder"), "{e}");
    }

    /// A cache is refused a world's folder or a folder in its `tiles/`, however spelled, and
    /// writes nothing there.
    #[test]
    fn a_cache_in_a_worlds_folder_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let w = tmp.path().join("w");
        std::fs::create_dir_all(w.join("tiles/L0")).unwrap();
        std::fs::write(w.join("world.toml"), "name = \"w\"").unwrap();
        for dir in [
            w.clone(),
            w.join("tiles/L0"),
            tmp.path().join("gone/../w/tiles/L9"),
        ] {
            let config = HttpCacheConfig {
                dir: dir.clone(),
                max_bytes: 1 << 20,
            };
            let err = DiskCache::open(&config).err().map(|e| e.to_string());
            assert!(
                err.as_deref()
                    .is_some_and(|e| e.contains("a folder of its own")),
                "{dir:?}: {err:?}"
            );
        }
        assert!(!w.join("tiles/L9").exists() && !tmp.path().join("gone").exists());
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
        let damages: [(&str, Damage); 7] = [
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
            // A validator with a control character: the client could not send it back.
            ("a validator that cannot be a header", |_, m| {
                let meta = std::fs::read_to_string(m).unwrap();
                std::fs::write(m, meta.replace("07:28:00", "07:28\u{1}00")).unwrap();
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
        // Said as what it is.
        cache.put(url, &tag, b"x");
        let meta = std::fs::read_to_string(&meta_path).unwrap();
        std::fs::write(&meta_path, meta.replace("07:28:00", "07:28\u{7f}00")).unwrap();
        let problem = cache.read_entry(&key, url, 1000).unwrap_err();
        assert_eq!(problem, "a validator that cannot be sent back as a header");
        cache.remove(&key);
        // A whole body larger than the file may now be is not used either.
        cache.put(url, &tag, &[b'a'; 100]);
        assert!(cache.get(url, 99).is_none());
        assert!(!body_path.exists());
    }
}
