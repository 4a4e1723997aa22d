//! `report.html`: one self-contained page (figures embedded as PNG data URIs, with links to the
//! SVG files beside it), the study's tables, and notes on what could not be computed. Readable
//! offline: no script, no external style or font.

use std::fmt::Write;

use arrow::array::RecordBatch;
use arrow::util::display::{ArrayFormatter, FormatOptions};

use super::{ReportSummary, TableOutput};
use crate::dataset::Dataset;
use crate::error::{Error, Result};

/// Rows shown of a table in the page (the CSV has them all).
const MAX_ROWS: usize = 100;

/// Per-percentile and per-shot tables: linked only (their figures show them).
const LINK_ONLY: [&str; 5] = ["msd_profile", "bias_profiles", "phenology", "waveform_examples", "shot_agreement"];

/// Escape text for HTML.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Standard base64 (RFC 4648, with padding).
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The unit of a numeric column of the report's tables, shown in its header (`Some("")`:
/// a count, an identifier or a dimensionless number); `None` for a column this list does not
/// know (a test keeps every report column known).
pub fn unit(column: &str) -> Option<&'static str> {
    const METRES: [&str; 20] = [
        "bias",
        "rmse",
        "mean_abs_bias",
        "mean_bias",
        "dx",
        "dy",
        "dz",
        "mean_dx",
        "mean_dy",
        "mean_dz",
        "mean_dx_halfwidth",
        "mean_dy_halfwidth",
        "x",
        "y",
        "xmin",
        "ymin",
        "xmax",
        "ymax",
        "z0",
        "ground_bias_m",
    ];
    const PLAIN: [&str; 14] = [
        "n",
        "n_shots",
        "n_segments",
        "n_points",
        "percentile",
        "r2",
        "r_before",
        "r_after",
        "mean_r_before",
        "mean_r_after",
        "mean_gain",
        "epsg",
        "shot_number",
        "step",
    ];
    let rh = |c: &str| c.strip_prefix("rh").is_some_and(|r| r.starts_with(|ch: char| ch.is_ascii_digit()));
    match column {
        c if METRES.contains(&c) || rh(c) => Some("m"),
        "sb" | "sdsd" | "lcs" | "msd" => Some("m²"),
        c if c.ends_with("_pct") => Some("%"),
        c if c.ends_with("_deg") => Some("°"),
        "mean_cover" => Some("fraction"),
        "noise_mean" => Some("DN"),
        c if PLAIN.contains(&c) => Some(""),
        _ => None,
    }
}

/// A column's header: its name and unit, `bias (m)`.
fn header(name: &str) -> String {
    match unit(name) {
        Some(u) if !u.is_empty() => format!("{name} ({u})"),
        _ => name.to_string(),
    }
}

/// An HTML table of `b` (floats with 3 decimals), at most `max_rows` rows.
pub fn html_table(b: &RecordBatch, max_rows: usize) -> std::result::Result<String, arrow::error::ArrowError> {
    let opts = FormatOptions::default().with_null("–");
    let mut s = String::from("<table>\n<thead><tr>");
    for f in b.schema().fields() {
        let _ = write!(s, "<th>{}</th>", escape(&header(f.name())));
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    let fmts = b
        .columns()
        .iter()
        .map(|c| ArrayFormatter::try_new(c.as_ref(), &opts))
        .collect::<std::result::Result<Vec<_>, _>>()?;
    for i in 0..b.num_rows().min(max_rows) {
        s.push_str("<tr>");
        for (f, fmt) in b.schema().fields().iter().zip(&fmts) {
            let text = fmt.value(i).to_string();
            let text = match f.data_type() {
                arrow::datatypes::DataType::Float32 | arrow::datatypes::DataType::Float64 => {
                    text.parse::<f64>().map(|v| format!("{v:.3}")).unwrap_or(text)
                }
                _ => text,
            };
            let class = if f.data_type().is_numeric() { " class=\"num\"" } else { "" };
            let _ = write!(s, "<td{class}>{}</td>", escape(&text));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table>\n");
    if b.num_rows() > max_rows {
        let _ = writeln!(s, "<p class=\"note\">First {max_rows} of {} rows.</p>", b.num_rows());
    }
    Ok(s)
}

/// The name a dataset is known by: its folder's name, with the parent's when the folder is named
/// `dataset` (`gedisim run --out`, `diagnose --out` and `demo --out` make `<out>/dataset`).
pub fn dataset_name(root: &std::path::Path) -> String {
    let root = root.canonicalize().unwrap_or_else(|_| root.to_path_buf());
    let name = |p: &std::path::Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    match (name(&root), root.parent().and_then(name)) {
        (Some(n), Some(parent)) if n == "dataset" => format!("{parent}/{n}"),
        (Some(n), _) => n,
        (None, _) => root.display().to_string(),
    }
}

/// The page.
pub fn page(
    ds: &Dataset,
    ran: &[TableOutput],
    summary: &ReportSummary,
    figures: &[(&str, String)],
    geo_notes: &[String],
    diagnosis: Option<&str>,
) -> Result<String> {
    let mut s = String::new();
    let title = format!("{} — gedisim study report", dataset_name(ds.root()));
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n<style>\n\
         body {{ font-family: 'DejaVu Sans', Arial, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }}\n\
         table {{ border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0 1em; }}\n\
         th, td {{ border: 1px solid #ccc; padding: 0.2em 0.5em; }}\n\
         th {{ background: #eee; }} td.num {{ text-align: right; font-variant-numeric: tabular-nums; }}\n\
         figure {{ margin: 1em 0; }} img {{ max-width: 100%; border: 1px solid #ddd; }}\n\
         .note {{ color: #666; font-size: 0.9em; }} code {{ background: #f4f4f4; padding: 0 0.2em; }}\n\
         </style>\n</head>\n<body>\n<h1>{}</h1>\n",
        escape(&title),
        escape(&title)
    );
    let _ = writeln!(
        s,
        "<p>Simulated GEDI RH against real GEDI RH aligned to the ALS ground \
         (<code>RH_aligned = RH_GEDI + (z_ground,GEDI − z_ALS)</code>). \
         Bias is simulated − aligned GEDI RH unless said otherwise (positive: the simulation is taller); \
         ground detection is GEDI ground − ALS ground (positive: GEDI's ground is higher). \
         MSD split after Kobayashi &amp; Salam (2000), population moments. \
         Every table is also in this folder as Parquet and CSV; the SQL is in <code>queries/</code>.</p>"
    );
    let mut contents = vec![("figures", "Figures")];
    if diagnosis.is_some() {
        contents.push(("diagnosis", "Diagnosis"));
    }
    contents.push(("tables", "Tables"));
    let links: Vec<String> = contents.iter().map(|(id, name)| format!("<a href=\"#{id}\">{name}</a>")).collect();
    let _ = writeln!(s, "<p>Contents: {}.</p>", links.join(" · "));
    // Figures first, then the tables in report order.
    if !figures.is_empty() {
        s.push_str("<h2 id=\"figures\">Figures</h2>\n");
    }
    for (name, caption) in figures {
        let png = summary.dir.join(format!("{name}.png"));
        let bytes = std::fs::read(&png).map_err(|e| Error::file(&png, format!("cannot read: {e}")))?;
        let _ = writeln!(
            s,
            "<figure><img alt=\"{n}\" src=\"data:image/png;base64,{}\">\n<figcaption>{} (<a \
                href=\"{n}.svg\">SVG</a>, <a href=\"{n}.png\">PNG</a>)</figcaption></figure>",
            base64(&bytes),
            escape(caption),
            n = escape(name)
        );
    }
    for note in &summary.figure_notes {
        let _ = writeln!(s, "<p class=\"note\">Figure not drawn — {}</p>", escape(note));
    }
    if let Some(section) = diagnosis {
        s.push_str(section);
    }
    s.push_str("<h2 id=\"tables\">Tables</h2>\n");
    for t in ran {
        let _ = writeln!(
            s,
            "<h3 id=\"{n}\">{}</h3>\n<p class=\"note\"><a href=\"{n}.csv\">{n}.csv</a> · <a \
                href=\"{n}.parquet\">{n}.parquet</a> · {} rows</p>",
            escape(t.query.title),
            t.rows(),
            n = escape(t.query.name)
        );
        if LINK_ONLY.contains(&t.query.name) {
            continue;
        }
        let b = t.batch()?;
        s.push_str(&html_table(&b, MAX_ROWS).map_err(|e| Error::table(t.query.name, e))?);
    }
    for (name, missing) in &summary.skipped {
        let _ = writeln!(
            s,
            "<p class=\"note\">Table <code>{}</code> not computed: the dataset has no {} table.</p>",
            escape(name),
            escape(&missing.join(", "))
        );
    }
    if !summary.geoparquet.is_empty() || !geo_notes.is_empty() {
        s.push_str("<h2>GeoParquet hand-off</h2>\n<ul>\n");
        for p in &summary.geoparquet {
            let n = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            let _ = writeln!(
                s,
                "<li><a href=\"{n}\">{n}</a>: GeoParquet 1.1, WKB points (lon, lat, OGC:CRS84), \
                bbox covering column</li>",
                n = escape(&n)
            );
        }
        for n in geo_notes {
            let _ = writeln!(s, "<li class=\"note\">{}</li>", escape(n));
        }
        s.push_str("</ul>\n");
    }
    let _ = writeln!(s, "<p class=\"note\">Written by gedisim {}.</p>\n</body>\n</html>", env!("CARGO_PKG_VERSION"));
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
    }

    #[test]
    fn headers_carry_units() {
        for (column, text) in [
            ("bias", "bias (m)"),
            ("rh98_sim", "rh98_sim (m)"),
            ("msd", "msd (m²)"),
            ("leaf_off_pct", "leaf_off_pct (%)"),
            ("mean_slope_deg", "mean_slope_deg (°)"),
            ("n", "n"),
            ("algorithm", "algorithm"),
        ] {
            assert_eq!(header(column), text);
        }
        assert_eq!(unit("rhx"), None);
    }

    #[test]
    fn dataset_names() {
        let dir = tempfile::tempdir().unwrap();
        let demo = dir.path().join("demo-x").join("dataset");
        std::fs::create_dir_all(&demo).unwrap();
        assert_eq!(dataset_name(&demo), "demo-x/dataset");
        assert_eq!(dataset_name(&dir.path().join("demo-x")), "demo-x");
    }

    #[test]
    fn escape_html() {
        assert_eq!(escape("a<b & \"c\">"), "a&lt;b &amp; &quot;c&quot;&gt;");
    }
}
