//! `gedisim granules` against a loopback server that answers as NASA's CMR granule search does
//! (docs/granules.md): the dataset's tile box and the time range asked, every page followed by
//! its `CMR-Search-After` header, the list as CSV; and the errors. No test reaches the internet.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::sync::{Arc, Mutex};

use common::gedisim;

/// One CMR entry as CMR's JSON gives it.
fn entry(id: &str, size: &str) -> String {
    entry_at("data.example", id, size)
}

/// The same, its file served by `host` over plain HTTP (the loopback server).
fn entry_at(host: &str, id: &str, size: &str) -> String {
    let scheme = if host == "data.example" { "https" } else { "http" };
    format!(
        r#"{{"producer_granule_id": "{id}", "title": "SC:{id}", "time_start": "2020-06-01T10:00:00.000Z",
            "time_end": "2020-06-01T11:30:00.000Z", "granule_size": "{size}",
            "links": [{{"rel": "http://esipfed.org/ns/fedsearch/1.1/data#", "href": "{scheme}://{host}/data/{id}"}}]}}"#
    )
}

/// What the server was asked.
#[derive(Debug, Clone, Default)]
struct Request {
    path: String,
    query: String,
    search_after: Option<String>,
    range: Option<String>,
    authorization: Option<String>,
    host: String,
}

/// What it answers: status, extra headers, body.
type Reply = (u16, Vec<(String, String)>, Vec<u8>);

/// A server answering each request with `answer`; every request is kept.
fn serve(answer: fn(&Request) -> Reply) -> (String, Arc<Mutex<Vec<Request>>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = seen.clone();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            let mut reader = BufReader::new(stream.try_clone().unwrap());
            let mut line = String::new();
            reader.read_line(&mut line).unwrap();
            let target = line.split_whitespace().nth(1).unwrap_or("").to_string();
            let (path, query) = target.split_once('?').unwrap_or((&target, ""));
            let mut r = Request { path: path.to_string(), query: query.to_string(), ..Default::default() };
            loop {
                let mut h = String::new();
                if reader.read_line(&mut h).unwrap() == 0 || h.trim().is_empty() {
                    break;
                }
                if let Some((k, v)) = h.split_once(':') {
                    let v = v.trim().to_string();
                    match k.to_ascii_lowercase().as_str() {
                        "cmr-search-after" => r.search_after = Some(v),
                        "range" => r.range = Some(v),
                        "authorization" => r.authorization = Some(v),
                        "host" => r.host = v,
                        _ => {}
                    }
                }
            }
            let (status, headers, body) = answer(&r);
            log.lock().unwrap().push(r);
            let mut head = format!("HTTP/1.1 {status} X\r\nContent-Length: {}\r\nConnection: close\r\n", body.len());
            for (k, v) in headers {
                head.push_str(&format!("{k}: {v}\r\n"));
            }
            head.push_str("\r\n");
            let _ = stream.write_all(head.as_bytes());
            let _ = stream.write_all(&body);
        }
    });
    (base, seen)
}

/// A JSON reply, with the next page's `CMR-Search-After` if any.
fn json(status: u16, body: &str, next: Option<&str>) -> Reply {
    let headers = next.map(|n| vec![("CMR-Search-After".to_string(), n.to_string())]).unwrap_or_default();
    (status, headers, body.as_bytes().to_vec())
}

/// CMR as documented: L1B in three pages (2, 1, then none), L2A in two (1, then none).
fn cmr(r: &Request) -> Reply {
    let page = |entries: Vec<String>| format!(r#"{{"feed": {{"entry": [{}]}}}}"#, entries.join(","));
    let (entries, next) = match (r.query.contains("short_name=GEDI01_B"), r.search_after.as_deref()) {
        (true, None) => (vec![entry("GEDI01_B_A_V002.h5", "7012.5"), entry("GEDI01_B_B_V002.h5", "6500")], "b1"),
        (true, Some("b1")) => (vec![entry("GEDI01_B_C_V002.h5", "5000")], "b2"),
        (false, None) => (vec![entry("GEDI02_A_A_V002.h5", "2100.25")], "a1"),
        _ => (vec![], "end"),
    };
    json(200, &page(entries), Some(next))
}

fn dataset(dir: &std::path::Path) -> String {
    let ds = dir.join("ds");
    let tile = common::data("als/lidarforfuel_2_bas_lig.laz");
    let (ok, _, err) = gedisim(&["ingest", "als", tile.to_str().unwrap(), "--out", ds.to_str().unwrap()]);
    assert!(ok, "{err}");
    ds.to_str().unwrap().to_string()
}

#[test]
fn granules_over_the_tiles_are_listed_from_every_page() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let (base, seen) = serve(cmr);
    let args = ["granules", "--dataset", &ds, "--cmr", &base, "--from", "2020-01-01", "--to", "2020-12-31"];
    let (ok, stdout, err) = gedisim(&args);
    assert!(ok, "{err}");
    let rows: Vec<&str> = stdout.lines().collect();
    assert_eq!(rows[0], "product,granule_id,time_start,time_end,size_mb,url");
    let ids: Vec<&str> = rows[1..].iter().map(|r| r.split(',').nth(1).unwrap()).collect();
    assert_eq!(ids, ["GEDI01_B_A_V002.h5", "GEDI01_B_B_V002.h5", "GEDI01_B_C_V002.h5", "GEDI02_A_A_V002.h5"]);
    assert!(
        rows[4].starts_with("GEDI02_A,") && rows[4].ends_with(",2100.25,https://data.example/data/GEDI02_A_A_V002.h5")
    );
    assert!(err.contains("3 L1B and 1 L2A granules"), "{err}");
    // What was asked: each collection, version 2, the tile's box (a LiDAR HD tile in France), the
    // days as UTC, each next page with the header the last one gave.
    let seen = seen.lock().unwrap().clone();
    let afters: Vec<Option<&str>> = seen.iter().map(|r| r.search_after.as_deref()).collect();
    assert_eq!(afters, [None, Some("b1"), Some("b2"), None, Some("a1")]);
    for r in &seen {
        assert_eq!(r.path, "/search/granules.json");
        let pairs: Vec<(String, String)> = url::form_urlencoded::parse(r.query.as_bytes()).into_owned().collect();
        let get = |k: &str| pairs.iter().find(|(a, _)| a == k).map(|(_, v)| v.clone()).unwrap_or_default();
        assert_eq!(get("version"), "002");
        assert_eq!(get("temporal"), "2020-01-01T00:00:00Z,2020-12-31T23:59:59Z");
        let b: Vec<f64> = get("bounding_box").split(',').map(|v| v.parse().unwrap()).collect();
        assert!(b[0] < b[2] && b[1] < b[3] && b[2] - b[0] < 0.05 && b[3] - b[1] < 0.05, "{b:?}");
        assert!((-5.0..10.0).contains(&b[0]) && (41.0..52.0).contains(&b[1]), "{b:?}");
    }
    // --out: the same list in a file, written whole.
    let out = tmp.path().join("granules.csv");
    let (ok, stdout2, err) = gedisim(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    assert!(ok && stdout2.is_empty(), "{err}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), stdout);
}

#[test]
fn failures_are_one_line_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let one_line = |args: &[&str], want: &str| {
        let (ok, _, err) = gedisim(args);
        assert!(!ok, "{args:?}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(want), "{want}: {err}");
    };
    // CMR refuses the request.
    let (base, _) = serve(|_| json(400, r#"{"errors": ["bounding_box is invalid"]}"#, None));
    one_line(&["granules", "--dataset", &ds, "--cmr", &base], "CMR answered 400");
    // Something that is not CMR.
    let (base, _) = serve(|_| json(200, "<html>maintenance</html>", None));
    one_line(&["granules", "--dataset", &ds, "--cmr", &base], "not CMR's JSON");
    // Nobody listens.
    let closed = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    one_line(&["granules", "--dataset", &ds, "--cmr", &format!("http://{closed}")], "CMR search failed");
    // A reversed range, a dataset without tiles: said before any request.
    one_line(&["granules", "--dataset", &ds, "--from", "2021-01-02", "--to", "2021-01-01"], "is after --to");
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    one_line(&["granules", "--dataset", empty.to_str().unwrap(), "--cmr", "http://127.0.0.1:9"], "no ALS tiles");
}

/// A granule's bytes (deterministic, distinct per granule).
fn content(id: &str, len: usize) -> Vec<u8> {
    (0..len).map(|i| (i as u8).wrapping_mul(31).wrapping_add(id.len() as u8 + id.as_bytes()[9])).collect()
}

/// The granules of the archive: (name, bytes).
const ARCHIVE: [(&str, usize); 3] =
    [("GEDI01_B_X_V002.h5", 3000), ("GEDI01_B_Y_V002.h5", 5000), ("GEDI02_A_X_V002.h5", 2000)];

/// CMR listing the archive's granules (sizes in MB) and the archive serving them to the bearer of
/// `tok`, by ranges when asked.
fn archive(r: &Request) -> Reply {
    if r.path == "/search/granules.json" {
        let l1b = r.query.contains("short_name=GEDI01_B");
        let entries: Vec<String> = match r.search_after {
            Some(_) => vec![],
            None => ARCHIVE
                .iter()
                .filter(|(id, _)| id.starts_with("GEDI01_B") == l1b)
                .map(|(id, n)| entry_at(&r.host, id, &format!("{}", *n as f64 / 1e6)))
                .collect(),
        };
        return json(200, &format!(r#"{{"feed": {{"entry": [{}]}}}}"#, entries.join(",")), Some("next"));
    }
    if r.authorization.as_deref() != Some("Bearer tok") {
        return (401, vec![], b"Unauthorized".to_vec());
    }
    let Some((id, n)) = ARCHIVE.iter().find(|(id, _)| r.path == format!("/data/{id}")) else {
        return (404, vec![], vec![]);
    };
    let body = content(id, *n);
    match r.range.as_deref().and_then(|v| v.strip_prefix("bytes=")).and_then(|v| v.strip_suffix('-')) {
        Some(from) => {
            let from: usize = from.parse().unwrap();
            let range = format!("bytes {from}-{}/{n}", n - 1);
            (206, vec![("Content-Range".into(), range)], body[from..].to_vec())
        }
        None => (200, vec![], body),
    }
}

/// One error line (the search's progress lines come before it).
fn one_error(stderr: &str) -> bool {
    stderr.lines().filter(|l| l.starts_with("error:")).count() == 1
        && stderr.trim_end().lines().last().is_some_and(|l| l.starts_with("error:"))
}

/// `gedisim` with EARTHDATA_TOKEN set to `token` (unset with `None`).
fn gedisim_with_token(args: &[&str], token: Option<&str>) -> (bool, String, String) {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_gedisim"));
    c.args(args).env_remove("EARTHDATA_TOKEN");
    if let Some(t) = token {
        c.env("EARTHDATA_TOKEN", t);
    }
    let o = c.output().unwrap();
    (o.status.success(), String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

#[test]
fn download_fetches_resumes_and_skips_what_is_there() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = dataset(tmp.path());
    let (base, seen) = serve(archive);
    let dir = tmp.path().join("granules");
    let dir_s = dir.to_str().unwrap();
    let args = ["granules", "--dataset", &ds, "--cmr", &base, "--download", dir_s, "--parallel", "2"];
    // Without a token: said before any request.
    let (ok, _, err) = gedisim_with_token(&args, None);
    assert!(!ok && err.contains("EARTHDATA_TOKEN") && err.trim().lines().count() == 1, "{err}");
    assert!(seen.lock().unwrap().is_empty());
    // A wrong token: the server's refusal, one line, nothing left under a granule's name.
    let (ok, _, err) = gedisim_with_token(&args, Some("wrong"));
    assert!(!ok && err.contains("401") && one_error(&err), "{err}");
    assert!(ARCHIVE.iter().all(|(id, _)| !dir.join(id).exists()));
    // An earlier run stopped 1,000 bytes into Y: resumed from there.
    let (y, ny) = ARCHIVE[1];
    std::fs::write(dir.join(format!("{y}.part")), &content(y, ny)[..1000]).unwrap();
    seen.lock().unwrap().clear();
    let (ok, _, err) = gedisim_with_token(&args, Some("tok"));
    assert!(ok, "{err}");
    assert!(err.contains("2 downloaded, 1 resumed, 0 already there"), "{err}");
    for (id, n) in ARCHIVE {
        assert_eq!(std::fs::read(dir.join(id)).unwrap(), content(id, n), "{id}");
        assert!(!dir.join(format!("{id}.part")).exists());
    }
    let ranges: Vec<(String, Option<String>)> = seen
        .lock()
        .unwrap()
        .iter()
        .filter(|r| r.path.starts_with("/data/"))
        .map(|r| (r.path.clone(), r.range.clone()))
        .collect();
    assert_eq!(ranges.len(), 3, "{ranges:?}");
    assert!(ranges.contains(&(format!("/data/{y}"), Some("bytes=1000-".into()))), "{ranges:?}");
    // Again: everything is there, nothing is fetched.
    seen.lock().unwrap().clear();
    let (ok, _, err) = gedisim_with_token(&args, Some("tok"));
    assert!(ok && err.contains("0 downloaded, 0 resumed, 3 already there"), "{err}");
    assert!(seen.lock().unwrap().iter().all(|r| !r.path.starts_with("/data/")));
    // A file that is not the size CMR announced is refused.
    std::fs::write(dir.join(ARCHIVE[0].0), b"short").unwrap();
    let (ok, _, err) = gedisim_with_token(&args, Some("tok"));
    assert!(!ok && err.contains("were announced") && one_error(&err), "{err}");
}
