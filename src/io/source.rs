//! Where a tile's bytes come from: a local file, or a remote object read by range requests
//! through the `object_store` crate: `https://…` and `http://…` (HTTP range requests) and
//! `s3://bucket/key` (credentials and region from the `AWS_*` environment). A [`RangeReader`]
//! fetches as it reads, in ranges of at least [`BLOCK_BYTES`], and holds one range; a COPC read
//! fetches the chunks of the nodes it decodes with [`Remote::fetch_ranges`] (in batches: see
//! `io::copc`). A plain LAS/LAZ file is streamed whole (docs/copc.md, "Remote tiles").

use std::collections::HashMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use object_store::{ObjectStore, ObjectStoreExt};
use sha2::{Digest, Sha256};

use crate::error::{Error, Result};

/// Smallest range fetched at once (bytes): a header with its VLRs, or a hierarchy page, in one
/// request.
pub const BLOCK_BYTES: u64 = 16 * 1024;

/// Ranges fetched together closer than this (bytes) are fetched in one request, gap included.
pub const COALESCE_BYTES: u64 = 64 * 1024;

/// A reader over a tile's bytes.
pub trait ReadSeek: Read + Seek + Send + Sync {}
impl<T: Read + Seek + Send + Sync> ReadSeek for T {}

/// Whether an input names a remote object (`http://`, `https://` or `s3://`), not a local path.
pub fn is_remote(input: &Path) -> bool {
    input.to_str().is_some_and(|s| ["http://", "https://", "s3://"].iter().any(|p| s.starts_with(p)))
}

/// A remote object, opened once per process (its size and version asked once).
pub struct Remote {
    url: String,
    store: Arc<dyn ObjectStore>,
    location: object_store::path::Path,
    size: u64,
    /// ETag or last-modified time: with the URL and size, what identifies this content.
    version: String,
    runtime: tokio::runtime::Runtime,
    fetched: AtomicU64,
    requests: AtomicU64,
    /// The small ranges read through [`RangeReader`]s (headers, VLRs, hierarchy pages), kept:
    /// each reader of the same object reads them again.
    small: Mutex<HashMap<(u64, u64), bytes::Bytes>>,
}

/// Ranges up to this size are kept once fetched (bytes), up to [`SMALL_RANGES_KEPT`] of them.
const SMALL_RANGE_BYTES: u64 = 256 * 1024;
const SMALL_RANGES_KEPT: usize = 64;

/// What was fetched from a remote object so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Fetched {
    pub bytes: u64,
    pub requests: u64,
    /// The object's size.
    pub size: u64,
}

impl Remote {
    /// The remote object named by `input` (opened at the first call; later calls share it).
    pub fn get(input: &Path) -> Result<Arc<Remote>> {
        static OPENED: OnceLock<Mutex<HashMap<String, Arc<Remote>>>> = OnceLock::new();
        let url = input.to_string_lossy().into_owned();
        let opened = OPENED.get_or_init(Default::default);
        if let Some(r) = opened.lock().expect("remote registry").get(&url) {
            return Ok(r.clone());
        }
        let remote = Arc::new(Remote::open(&url)?);
        opened.lock().expect("remote registry").insert(url, remote.clone());
        Ok(remote)
    }

    fn open(url: &str) -> Result<Remote> {
        let fail = |what: &str, e: &dyn std::fmt::Display| {
            Error::file(Path::new(url), format!("{what}: {}", crate::error::one_line(&e.to_string())))
        };
        let parsed = url::Url::parse(url).map_err(|e| fail("not a URL", &e))?;
        let location = object_store::path::Path::from_url_path(parsed.path()).map_err(|e| fail("not a path", &e))?;
        let store = super::store::open(&parsed).map_err(|e| fail("cannot open", &e))?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("gedisim-fetch")
            .enable_all()
            .build()
            .map_err(|e| fail("cannot start the I/O runtime", &e))?;
        let meta = runtime.block_on(store.head(&location)).map_err(|e| fail("cannot read", &e))?;
        let version = meta.e_tag.clone().unwrap_or_else(|| meta.last_modified.to_rfc3339());
        Ok(Remote {
            url: url.to_string(),
            store,
            location,
            size: meta.size,
            version,
            runtime,
            fetched: AtomicU64::new(0),
            requests: AtomicU64::new(0),
            small: Mutex::new(HashMap::new()),
        })
    }

    /// The object's size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// What was fetched so far.
    pub fn fetched(&self) -> Fetched {
        Fetched {
            bytes: self.fetched.load(Ordering::Relaxed),
            requests: self.requests.load(Ordering::Relaxed),
            size: self.size,
        }
    }

    /// A key for this content without reading it: SHA-256 of the URL, size and version (ETag or
    /// last-modified time). Another URL for the same bytes gets another key.
    pub fn content_key(&self) -> String {
        let mut h = Sha256::new();
        h.update(format!("{}\n{}\n{}", self.url, self.size, self.version));
        hex::encode(h.finalize())
    }

    fn fetch(&self, start: u64, end: u64) -> std::io::Result<bytes::Bytes> {
        let small = end - start <= SMALL_RANGE_BYTES;
        if let Some(b) = small.then(|| self.small.lock().expect("range cache").get(&(start, end)).cloned()).flatten() {
            return Ok(b);
        }
        let got = self.runtime.block_on(self.store.get_range(&self.location, start..end)).map_err(|e| {
            std::io::Error::other(format!("bytes {start}–{end}: {}", crate::error::one_line(&e.to_string())))
        })?;
        whole(&(start..end), &got)?;
        self.fetched.fetch_add(got.len() as u64, Ordering::Relaxed);
        self.requests.fetch_add(1, Ordering::Relaxed);
        let mut kept = self.small.lock().expect("range cache");
        if small && kept.len() < SMALL_RANGES_KEPT {
            kept.insert((start, end), got.clone());
        }
        Ok(got)
    }

    /// The bytes of each of `ranges` (sorted or not), fetched concurrently; ranges less than
    /// [`COALESCE_BYTES`] apart are fetched in one request.
    pub fn fetch_ranges(&self, ranges: &[std::ops::Range<u64>]) -> std::io::Result<Vec<bytes::Bytes>> {
        let fetch = |r: std::ops::Range<u64>| {
            let (len, store, location) = (r.end - r.start, self.store.clone(), self.location.clone());
            self.fetched.fetch_add(len, Ordering::Relaxed);
            self.requests.fetch_add(1, Ordering::Relaxed);
            async move { store.get_range(&location, r).await }
        };
        let got = self
            .runtime
            .block_on(object_store::coalesce_ranges(ranges, fetch, COALESCE_BYTES))
            .map_err(|e| std::io::Error::other(crate::error::one_line(&e.to_string())))?;
        ranges.iter().zip(&got).try_for_each(|(r, b)| whole(r, b))?;
        Ok(got)
    }

    /// A reader positioned at the start of the object.
    pub fn reader(self: &Arc<Self>) -> RangeReader {
        RangeReader { remote: self.clone(), pos: 0, block_start: 0, block: bytes::Bytes::new() }
    }
}

/// An error unless `got` holds the whole of `range`.
fn whole(range: &std::ops::Range<u64>, got: &bytes::Bytes) -> std::io::Result<()> {
    let want = range.end - range.start;
    if got.len() as u64 == want {
        return Ok(());
    }
    Err(std::io::Error::other(format!(
        "bytes {}–{}: the server sent {} bytes instead of {want}",
        range.start,
        range.end,
        got.len()
    )))
}

/// Read + Seek over a remote object: each read outside the block held fetches the range from the
/// position on, of the read's length but at least [`BLOCK_BYTES`].
pub struct RangeReader {
    remote: Arc<Remote>,
    pos: u64,
    block_start: u64,
    block: bytes::Bytes,
}

impl Read for RangeReader {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let size = self.remote.size;
        if self.pos >= size || buf.is_empty() {
            return Ok(0);
        }
        let held = self.block_start..self.block_start + self.block.len() as u64;
        if !held.contains(&self.pos) {
            let end = size.min(self.pos + BLOCK_BYTES.max(buf.len() as u64));
            self.block = self.remote.fetch(self.pos, end)?;
            self.block_start = self.pos;
        }
        let at = (self.pos - self.block_start) as usize;
        let n = buf.len().min(self.block.len() - at);
        buf[..n].copy_from_slice(&self.block[at..at + n]);
        self.pos += n as u64;
        Ok(n)
    }
}

impl Seek for RangeReader {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let target = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.remote.size.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = target.ok_or_else(|| std::io::Error::other("seek before the start of the object"))?;
        Ok(self.pos)
    }
}

/// A tile's bytes, from a local file or a remote object, and their size.
pub fn open(input: &Path) -> Result<(Box<dyn ReadSeek>, u64)> {
    if is_remote(input) {
        let remote = Remote::get(input)?;
        return Ok((Box::new(remote.reader()), remote.size()));
    }
    let file = std::fs::File::open(input).map_err(|e| Error::file(input, format!("cannot open: {e}")))?;
    let len = file.metadata().map_err(|e| Error::file(input, format!("cannot stat: {e}")))?.len();
    Ok((Box::new(file), len))
}

/// The remote object `input` names, if it names one.
pub fn remote(input: &Path) -> Result<Option<Arc<Remote>>> {
    is_remote(input).then(|| Remote::get(input)).transpose()
}

/// What was fetched from `input` so far, if it is remote and was opened.
pub fn fetched(input: &Path) -> Option<Fetched> {
    is_remote(input).then(|| Remote::get(input).ok().map(|r| r.fetched())).flatten()
}
