//! NASA's Common Metadata Repository (CMR) granule search, for `gedisim granules`
//! (docs/granules.md): the granules of one collection (short name and version) that cross a
//! longitude/latitude box, in a time range, page by page.
//!
//! CMR's JSON response is `{"feed": {"entry": [...]}}`; each entry has `producer_granule_id` (or
//! `title`), `time_start`, `time_end`, `granule_size` (MB, as a string) and `links`, of which the
//! one whose `rel` ends in `/data#` is the granule's download address. Pages are chained by the
//! `CMR-Search-After` header: sent back with the next request, until a page comes back empty or
//! without it.

use crate::error::{Error, Result};

/// Granules asked for per page (CMR's largest page).
pub const PAGE_SIZE: usize = 2000;

/// What one search asks for.
#[derive(Debug, Clone, PartialEq)]
pub struct GranuleQuery {
    /// e.g. `GEDI01_B`.
    pub short_name: String,
    /// e.g. `002`.
    pub version: String,
    /// West, south, east, north (degrees).
    pub bbox: [f64; 4],
    /// CMR's `temporal` value (`start,end`, either side may be empty), if any.
    pub temporal: Option<String>,
}

/// One granule found.
#[derive(Debug, Clone, PartialEq)]
pub struct Granule {
    /// The collection's short name it was found in.
    pub short_name: String,
    /// The granule's file name (`producer_granule_id`, else `title`).
    pub granule_id: String,
    pub time_start: String,
    pub time_end: String,
    /// Size as announced (MB), if any.
    pub size_mb: Option<f64>,
    /// Download address, if the entry has one.
    pub url: Option<String>,
}

/// The granules of one CMR JSON page (`source` names it in errors).
pub fn parse_page(body: &str, short_name: &str, source: &str) -> Result<Vec<Granule>> {
    let v: serde_json::Value =
        serde_json::from_str(body).map_err(|e| Error::file(source, format!("not CMR's JSON: {e}")))?;
    let entries = v
        .get("feed")
        .and_then(|f| f.get("entry"))
        .and_then(|e| e.as_array())
        .ok_or_else(|| Error::field(source, "feed.entry", "missing: not a CMR granule search response"))?;
    entries
        .iter()
        .map(|e| {
            let text = |k: &str| e.get(k).and_then(|v| v.as_str()).map(str::to_string);
            let granule_id = text("producer_granule_id")
                .or_else(|| text("title"))
                .ok_or_else(|| Error::field(source, "feed.entry.producer_granule_id", "missing (and no title)"))?;
            let size_mb = match e.get("granule_size") {
                None | Some(serde_json::Value::Null) => None,
                Some(serde_json::Value::Number(n)) => n.as_f64(),
                Some(serde_json::Value::String(s)) => Some(s.trim().parse::<f64>().map_err(|_| {
                    Error::field(source, "feed.entry.granule_size", format!("`{s}` is not a number (MB)"))
                })?),
                Some(other) => {
                    return Err(Error::field(source, "feed.entry.granule_size", format!("`{other}` is not a number")))
                }
            };
            let url = e.get("links").and_then(|l| l.as_array()).and_then(|links| {
                links.iter().find_map(|l| {
                    let rel = l.get("rel").and_then(|r| r.as_str()).unwrap_or("");
                    let inherited = l.get("inherited").and_then(|i| i.as_bool()).unwrap_or(false);
                    (rel.ends_with("/data#") && !inherited).then(|| l.get("href")?.as_str().map(str::to_string))?
                })
            });
            Ok(Granule {
                short_name: short_name.to_string(),
                granule_id,
                time_start: text("time_start").unwrap_or_default(),
                time_end: text("time_end").unwrap_or_default(),
                size_mb,
                url,
            })
        })
        .collect()
}

/// The address of one page of `q` at CMR `base` (e.g. `https://cmr.earthdata.nasa.gov`).
pub fn page_url(base: &str, q: &GranuleQuery) -> Result<url::Url> {
    let root = format!("{}/search/granules.json", base.trim_end_matches('/'));
    let mut u = url::Url::parse(&root).map_err(|e| Error::Usage(format!("--cmr: `{base}` is not a URL: {e}")))?;
    {
        let mut p = u.query_pairs_mut();
        p.append_pair("short_name", &q.short_name);
        p.append_pair("version", &q.version);
        let [w, s, e, n] = q.bbox;
        p.append_pair("bounding_box", &format!("{w:.6},{s:.6},{e:.6},{n:.6}"));
        if let Some(t) = &q.temporal {
            p.append_pair("temporal", t);
        }
        p.append_pair("page_size", &PAGE_SIZE.to_string());
    }
    Ok(u)
}

/// Every granule of `q` at CMR `base`, all pages; `on_page` hears the granules found so far.
pub fn search(base: &str, q: &GranuleQuery, on_page: &dyn Fn(usize)) -> Result<Vec<Granule>> {
    let url = page_url(base, q)?;
    let (rt, client) = super::download::http()?;
    rt.block_on(async {
        let source = url.as_str().to_string();
        let (mut out, mut after) = (Vec::new(), None::<String>);
        loop {
            let mut req = client.get(url.clone());
            if let Some(a) = &after {
                req = req.header("CMR-Search-After", a);
            }
            let resp = req
                .send()
                .await
                .map_err(|e| Error::file(&source, format!("CMR search failed: {}", e.without_url())))?;
            let status = resp.status();
            let next = resp.headers().get("CMR-Search-After").and_then(|h| h.to_str().ok()).map(str::to_string);
            let body = resp.text().await.map_err(|e| Error::file(&source, format!("CMR response: {e}")))?;
            if !status.is_success() {
                let head: String = body.chars().take(200).collect();
                return Err(Error::file(&source, format!("CMR answered {status}: {head}")));
            }
            let page = parse_page(&body, &q.short_name, &source)?;
            let empty = page.is_empty();
            out.extend(page);
            if !empty {
                on_page(out.len());
            }
            match next {
                Some(n) if !empty && after.as_deref() != Some(n.as_str()) => after = Some(n),
                _ => break,
            }
        }
        Ok(out)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_page_gives_names_times_sizes_and_the_data_link() {
        let body = r#"{"feed": {"entry": [
          {"producer_granule_id": "GEDI01_B_2019108_O01959_V002.h5", "title": "SC:GEDI01_B.002:1",
           "time_start": "2019-04-18T00:20:11.000Z", "time_end": "2019-04-18T01:52:00.000Z",
           "granule_size": "7012.5",
           "links": [{"rel": "http://esipfed.org/ns/fedsearch/1.1/browse#", "href": "https://x/b.png"},
                     {"rel": "http://esipfed.org/ns/fedsearch/1.1/data#", "href": "https://x/d.h5", "inherited": true},
                     {"rel": "http://esipfed.org/ns/fedsearch/1.1/data#", "href": "https://x/GEDI01_B.h5"}]},
          {"title": "only-a-title", "granule_size": 12}
        ]}}"#;
        let g = parse_page(body, "GEDI01_B", "page").unwrap();
        assert_eq!(g.len(), 2);
        assert_eq!(g[0].granule_id, "GEDI01_B_2019108_O01959_V002.h5");
        assert_eq!(g[0].size_mb, Some(7012.5));
        assert_eq!(g[0].url.as_deref(), Some("https://x/GEDI01_B.h5"));
        assert_eq!((g[1].granule_id.as_str(), g[1].size_mb, g[1].url.as_deref()), ("only-a-title", Some(12.0), None));
    }

    #[test]
    fn bad_pages_are_one_line_errors_naming_the_field() {
        let e = parse_page("{\"feed\": {}}", "GEDI02_A", "p").unwrap_err().to_string();
        assert!(e.contains("feed.entry"), "{e}");
        let e = parse_page(r#"{"feed": {"entry": [{"title": "t", "granule_size": "big"}]}}"#, "x", "p").unwrap_err();
        assert!(e.to_string().contains("granule_size") && !e.to_string().contains('\n'), "{e}");
        assert!(parse_page("<html>", "x", "p").unwrap_err().to_string().contains("not CMR's JSON"));
    }

    #[test]
    fn the_query_names_collection_box_time_and_page_size() {
        let q = GranuleQuery {
            short_name: "GEDI02_A".into(),
            version: "002".into(),
            bbox: [5.5, 44.0, 5.75, 44.25],
            temporal: Some("2020-01-01T00:00:00Z,".into()),
        };
        let u = page_url("http://127.0.0.1:9/", &q).unwrap();
        assert_eq!(u.path(), "/search/granules.json");
        let pairs: Vec<(String, String)> = u.query_pairs().into_owned().collect();
        let get = |k: &str| pairs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str());
        assert_eq!(get("short_name"), Some("GEDI02_A"));
        assert_eq!(get("bounding_box"), Some("5.500000,44.000000,5.750000,44.250000"));
        assert_eq!(get("temporal"), Some("2020-01-01T00:00:00Z,"));
        assert!(page_url("not a url", &q).is_err());
    }
}
