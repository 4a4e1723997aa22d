//! Downloading files over HTTP(S) with a bearer token, for `gedisim granules --download`
//! (docs/granules.md): each file written under a `.part` name and renamed when complete, a
//! `.part` left by an interrupted run resumed by a range request, the bytes received checked
//! against the size the server gives and the size announced, several files at once.

use std::io::Write;
use std::path::{Path, PathBuf};

use futures::StreamExt;

use crate::error::{Error, Result};

/// One file to fetch.
#[derive(Debug, Clone, PartialEq)]
pub struct Download {
    pub url: String,
    /// Where it goes.
    pub path: PathBuf,
    /// The size announced beforehand (MB, as CMR gives it), if any: the file must agree with it
    /// within [`ANNOUNCED_TOLERANCE`], the MB read as 10⁶ or as 2²⁰ bytes (catalogues use both).
    pub announced_mb: Option<f64>,
}

/// Relative agreement needed between the bytes received and the size announced.
pub const ANNOUNCED_TOLERANCE: f64 = 0.01;

/// What happened to one file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fetched {
    /// Downloaded whole (bytes).
    New(u64),
    /// Resumed from a `.part` of the first count, to the second.
    Resumed(u64, u64),
    /// Already there.
    Present(u64),
}

/// The `.part` name of `path`.
pub fn part_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".part");
    path.with_file_name(name)
}

/// A one-thread runtime and an HTTP client (gedisim's user agent, a 30 s connect timeout): what
/// the CMR search and the downloads run on.
pub(crate) fn http() -> Result<(tokio::runtime::Runtime, reqwest::Client)> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Error::Usage(format!("cannot start the HTTP runtime: {e}")))?;
    let client = reqwest::Client::builder()
        .user_agent(concat!("gedisim/", env!("CARGO_PKG_VERSION")))
        .connect_timeout(std::time::Duration::from_secs(30))
        .build()
        .map_err(|e| Error::Usage(format!("cannot make an HTTP client: {e}")))?;
    Ok((rt, client))
}

/// Fetch every download, at most `parallel` at once, with `token` as the bearer; `on_bytes`
/// hears every chunk written. Returns each file's outcome, in order; the first failure ends the
/// run with its error (files completed stay, the failed one's `.part` stays for a resume).
pub fn fetch_all(
    downloads: &[Download],
    token: &str,
    parallel: usize,
    on_bytes: &(dyn Fn(u64) + Sync),
) -> Result<Vec<Fetched>> {
    let (rt, client) = http()?;
    rt.block_on(async {
        let results: Vec<Result<Fetched>> = futures::stream::iter(downloads)
            .map(|d| fetch_one(&client, d, token, on_bytes))
            .buffered(parallel.max(1))
            .collect()
            .await;
        results.into_iter().collect()
    })
}

async fn fetch_one(client: &reqwest::Client, d: &Download, token: &str, on_bytes: &dyn Fn(u64)) -> Result<Fetched> {
    let io = |e: std::io::Error| Error::file(&d.path, e);
    if let Ok(m) = std::fs::metadata(&d.path) {
        check_announced(d, m.len())?;
        return Ok(Fetched::Present(m.len()));
    }
    let part = part_path(&d.path);
    let have = std::fs::metadata(&part).map(|m| m.len()).unwrap_or(0);
    let mut req = client.get(&d.url).bearer_auth(token);
    if have > 0 {
        req = req.header(reqwest::header::RANGE, format!("bytes={have}-"));
    }
    let failed = |e: reqwest::Error| Error::file(&d.url, format!("download failed: {}", e.without_url()));
    let mut resp = req.send().await.map_err(failed)?;
    let status = resp.status();
    let resumed = status == reqwest::StatusCode::PARTIAL_CONTENT;
    let nothing_left = status == reqwest::StatusCode::RANGE_NOT_SATISFIABLE && have > 0;
    if !status.is_success() && !nothing_left {
        let hint = if matches!(status.as_u16(), 401 | 403) {
            " (is EARTHDATA_TOKEN a current Earthdata Login token?)"
        } else {
            ""
        };
        return Err(Error::file(&d.url, format!("the server answered {status}{hint}")));
    }
    // The whole file's size, as the server gives it.
    let total = if nothing_left {
        Some(have)
    } else if resumed {
        resp.headers()
            .get(reqwest::header::CONTENT_RANGE)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.rsplit('/').next())
            .and_then(|t| t.parse::<u64>().ok())
    } else {
        resp.content_length()
    };
    let start = if resumed || nothing_left { have } else { 0 };
    let mut file = if start > 0 {
        std::fs::OpenOptions::new().append(true).open(&part).map_err(io)?
    } else {
        std::fs::File::create(&part).map_err(io)?
    };
    let mut written = start;
    if !nothing_left {
        while let Some(chunk) = resp.chunk().await.map_err(failed)? {
            file.write_all(&chunk).map_err(io)?;
            written += chunk.len() as u64;
            on_bytes(chunk.len() as u64);
        }
    }
    file.sync_all().map_err(io)?;
    drop(file);
    if let Some(t) = total.filter(|&t| t != written) {
        return Err(Error::file(&d.url, format!("received {written} bytes of {t}: run again to resume")));
    }
    check_announced(d, written)?;
    std::fs::rename(&part, &d.path).map_err(io)?;
    Ok(if start > 0 { Fetched::Resumed(start, written) } else { Fetched::New(written) })
}

/// `bytes` agrees with the size announced for `d`.
fn check_announced(d: &Download, bytes: u64) -> Result<()> {
    let Some(mb) = d.announced_mb else { return Ok(()) };
    let near = |unit: f64| (bytes as f64 - mb * unit).abs() <= ANNOUNCED_TOLERANCE * (mb * unit).max(1.0);
    if near(1e6) || near(1_048_576.0) {
        Ok(())
    } else {
        let msg =
            format!("{bytes} bytes, where {mb} MB were announced: not the granule listed (delete it to fetch again)");
        Err(Error::file(&d.path, msg))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_names_and_the_announced_size() {
        assert_eq!(part_path(Path::new("/d/G.h5")), PathBuf::from("/d/G.h5.part"));
        let d = |a| Download { url: "u".into(), path: "/d/G.h5".into(), announced_mb: a };
        assert!(check_announced(&d(Some(1.0)), 1_004_000).is_ok());
        assert!(check_announced(&d(Some(1.0)), 1_050_000).is_ok(), "MB as 2²⁰ bytes");
        assert!(check_announced(&d(Some(1.0)), 1_200_000).is_err());
        assert!(check_announced(&d(Some(1.0)), 1_025_000).is_err(), "between the two readings");
        assert!(check_announced(&d(None), 5).is_ok());
    }
}
