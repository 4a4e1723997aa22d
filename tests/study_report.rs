//! `gedisim report` on a synthetic results table written with the results schema: the two exact
//! contracts (ground_detection, msd), the MSD identity SB + SDSD + LCS = mean((y − ŷ)²) checked
//! against a direct computation from the results file, the other tables, figures, report.html and
//! the GeoParquet hand-off.

mod common;
#[path = "common/study.rs"]
mod study;

use std::collections::HashMap;
use std::path::Path;

use arrow::array::{Array, AsArray, RecordBatch};
use arrow::datatypes::{DataType, Float32Type, Float64Type, Int64Type, UInt64Type};
use gedisim::dataset::Dataset;
use gedisim::ops::report::{run_report, ReportOptions};

const N_SHOTS: usize = 90;

fn full_dataset(dir: &Path) -> Dataset {
    let ds = Dataset::create(dir).unwrap();
    study::write_results(&ds, &study::synthetic_results(N_SHOTS));
    study::write_offsets(&ds, 12);
    study::write_shots_and_sim(&ds, N_SHOTS);
    study::write_tiles(&ds);
    ds
}

fn s(b: &RecordBatch, name: &str) -> Vec<String> {
    let c = b.column_by_name(name).unwrap_or_else(|| panic!("no column {name}"));
    let c = c.as_string::<i32>();
    (0..c.len()).map(|i| c.value(i).to_string()).collect()
}

fn f(b: &RecordBatch, name: &str) -> Vec<f64> {
    let c = b.column_by_name(name).unwrap_or_else(|| panic!("no column {name}"));
    let c = arrow::compute::cast(c, &DataType::Float64).unwrap();
    let c = c.as_primitive::<Float64Type>();
    (0..c.len()).map(|i| if c.is_null(i) { f64::NAN } else { c.value(i) }).collect()
}

fn columns(b: &RecordBatch) -> Vec<(String, DataType)> {
    b.schema().fields().iter().map(|f| (f.name().clone(), f.data_type().clone())).collect()
}

/// The results table as read back: per row (weighting, algorithm, group, rh_aligned, rh_sim, ground diff).
struct Row {
    weighting: String,
    algorithm: String,
    group: String,
    forest: String,
    phenology: String,
    y: Vec<f64>,
    yhat: Vec<f64>,
    ground_diff: f64,
}

fn results_rows(ds: &Dataset) -> Vec<Row> {
    let b = study::read(&ds.root().join("results/part-0.parquet"));
    let list = |name: &str, i: usize| -> Vec<f64> {
        let l = b.column_by_name(name).unwrap().as_list::<i32>().value(i);
        l.as_primitive::<Float32Type>().values().iter().map(|&v| v as f64).collect()
    };
    let (w, a, g, ft, ph) =
        (s(&b, "weighting"), s(&b, "algorithm"), s(&b, "sensitivity_group"), s(&b, "forest_type"), s(&b, "phenology"));
    let (gg, ag) = (f(&b, "gedi_ground"), f(&b, "als_ground"));
    (0..b.num_rows())
        .map(|i| Row {
            weighting: w[i].clone(),
            algorithm: a[i].clone(),
            group: g[i].clone(),
            forest: ft[i].clone(),
            phenology: ph[i].clone(),
            y: list("rh_aligned", i),
            yhat: list("rh_sim", i),
            ground_diff: gg[i] - ag[i],
        })
        .collect()
}

fn in_group(r: &Row, group: &str) -> bool {
    group == "all" || r.group == group
}

#[test]
fn report_tables_contracts_and_msd_identity() {
    let dir = tempfile::tempdir().unwrap();
    let ds = full_dataset(&dir.path().join("ds"));
    let progress = common::Recorder::default();
    let summary = run_report(&ds, &Default::default(), &Default::default(), &progress).unwrap();
    let steps = progress.events.lock().unwrap();
    let out = ds.root().join("report");
    assert_eq!(summary.dir, out);
    assert!(summary.skipped.is_empty(), "{:?}", summary.skipped);
    assert!(steps.iter().any(|s| s == "query msd"), "progress names each query");
    let rows = results_rows(&ds);
    assert_eq!(rows.len(), N_SHOTS * 3 * 7);

    // ground_detection: exact contract and values.
    let gd = study::read(&out.join("ground_detection.parquet"));
    assert_eq!(
        columns(&gd),
        [
            ("algorithm".into(), DataType::Utf8),
            ("sensitivity_group".into(), DataType::Utf8),
            ("n".into(), DataType::Int64),
            ("bias".into(), DataType::Float64),
            ("rmse".into(), DataType::Float64),
        ]
    );
    assert_eq!(gd.num_rows(), 7 * 3);
    let (ga, gg, gb, gr) = (s(&gd, "algorithm"), s(&gd, "sensitivity_group"), f(&gd, "bias"), f(&gd, "rmse"));
    let gn = gd.column_by_name("n").unwrap().as_primitive::<Int64Type>();
    assert_eq!(&ga[..3], ["default", "default", "default"]);
    assert_eq!(&gg[..3], ["low", "high", "all"]);
    for i in 0..gd.num_rows() {
        let d: Vec<f64> = rows
            .iter()
            .filter(|r| r.weighting == "count" && r.algorithm == ga[i] && in_group(r, &gg[i]))
            .map(|r| r.ground_diff)
            .collect();
        assert_eq!(gn.value(i) as usize, d.len(), "{} {}", ga[i], gg[i]);
        let bias = d.iter().sum::<f64>() / d.len() as f64;
        let rmse = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        assert!((gb[i] - bias).abs() < 1e-9 && (gr[i] - rmse).abs() < 1e-9, "{} {}: {} vs {bias}", ga[i], gg[i], gb[i]);
    }
    // The planted ground error of a3 (−0.5 m, noise 0.3 m) shows in its bias over all shots.
    let a3 = (0..gd.num_rows()).find(|&i| ga[i] == "a3" && gg[i] == "all").unwrap();
    assert!((gb[a3] + 0.5).abs() < 0.15, "a3 bias {}", gb[a3]);

    // rh_agreement (the 1:1 scatter's figures): bias = simulated − aligned GEDI, RMSE and R² of
    // RH98 and RH50, the default algorithm, recomputed from the rows.
    let ag = study::read(&out.join("rh_agreement.parquet"));
    let (aw, am, an) = (s(&ag, "weighting"), s(&ag, "metric"), f(&ag, "n"));
    let (ab, ar, ar2) = (f(&ag, "bias"), f(&ag, "rmse"), f(&ag, "r2"));
    assert_eq!(ag.num_rows(), 6);
    for i in 0..ag.num_rows() {
        let k = if am[i] == "RH98" { 98 } else { 50 };
        let pairs: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.weighting == aw[i] && r.algorithm == "default")
            .map(|r| (r.yhat[k], r.y[k]))
            .collect();
        let n = pairs.len() as f64;
        assert_eq!(an[i], n);
        let bias = pairs.iter().map(|(p, y)| p - y).sum::<f64>() / n;
        let rmse = (pairs.iter().map(|(p, y)| (p - y) * (p - y)).sum::<f64>() / n).sqrt();
        let (mp, my) = (pairs.iter().map(|p| p.0).sum::<f64>() / n, pairs.iter().map(|p| p.1).sum::<f64>() / n);
        let cov: f64 = pairs.iter().map(|(p, y)| (p - mp) * (y - my)).sum();
        let (vp, vy): (f64, f64) =
            (pairs.iter().map(|(p, _)| (p - mp).powi(2)).sum(), pairs.iter().map(|(_, y)| (y - my).powi(2)).sum());
        let r2 = cov * cov / (vp * vy);
        assert!((ab[i] - bias).abs() < 1e-6 && (ar[i] - rmse).abs() < 1e-6, "{} {}: {} {}", aw[i], am[i], ab[i], bias);
        assert!((ar2[i] - r2).abs() < 1e-6, "{} {}: R² {} vs {r2}", aw[i], am[i], ar2[i]);
    }

    // msd: exact contract, identity, and equality with the direct mean of (y − ŷ)² over RH1..RH99.
    let msd = study::read(&out.join("msd.parquet"));
    let names: Vec<String> = columns(&msd).into_iter().map(|c| c.0).collect();
    assert_eq!(names, ["weighting", "algorithm", "sensitivity_group", "sb", "sdsd", "lcs", "msd", "n"]);
    for c in ["sb", "sdsd", "lcs", "msd"] {
        assert_eq!(msd.schema().field_with_name(c).unwrap().data_type(), &DataType::Float64);
    }
    assert_eq!(msd.num_rows(), 3 * 7 * 3);
    let (mw, ma, mg) = (s(&msd, "weighting"), s(&msd, "algorithm"), s(&msd, "sensitivity_group"));
    let (sb, sdsd, lcs, m, mn) = (f(&msd, "sb"), f(&msd, "sdsd"), f(&msd, "lcs"), f(&msd, "msd"), f(&msd, "n"));
    for i in 0..msd.num_rows() {
        let sel: Vec<&Row> =
            rows.iter().filter(|r| r.weighting == mw[i] && r.algorithm == ma[i] && in_group(r, &mg[i])).collect();
        assert!(!sel.is_empty());
        let mut total = 0.0;
        for r in &sel {
            for k in 1..=99 {
                total += (r.y[k] - r.yhat[k]).powi(2);
            }
        }
        let direct = total / (99 * sel.len()) as f64;
        assert!(
            (sb[i] + sdsd[i] + lcs[i] - direct).abs() < 1e-9,
            "{} {} {}: {} vs {direct}",
            mw[i],
            ma[i],
            mg[i],
            sb[i] + sdsd[i] + lcs[i]
        );
        assert!((m[i] - direct).abs() < 1e-9);
        assert!(sb[i] >= 0.0 && sdsd[i] >= 0.0 && lcs[i] >= -1e-9);
        assert_eq!(mn[i] as usize, sel.len());
    }
    // The per-percentile table obeys the identity too, percentile by percentile (checked at RH50:
    // RH k is element k of the 0-based list, `rh[k + 1]` in SQL).
    let prof = study::read(&out.join("msd_profile.parquet"));
    let (pw, pa, pg, pp) =
        (s(&prof, "weighting"), s(&prof, "algorithm"), s(&prof, "sensitivity_group"), f(&prof, "percentile"));
    let (psb, psd, plc) = (f(&prof, "sb"), f(&prof, "sdsd"), f(&prof, "lcs"));
    assert_eq!(prof.num_rows(), 3 * 7 * 3 * 99);
    let mut checked = 0;
    for i in (0..prof.num_rows()).filter(|&i| pp[i] == 50.0) {
        let sel: Vec<&Row> =
            rows.iter().filter(|r| r.weighting == pw[i] && r.algorithm == pa[i] && in_group(r, &pg[i])).collect();
        let direct = sel.iter().map(|r| (r.y[50] - r.yhat[50]).powi(2)).sum::<f64>() / sel.len() as f64;
        assert!((psb[i] + psd[i] + plc[i] - direct).abs() < 1e-9);
        // and matches the library's own kernel
        let y: Vec<f64> = sel.iter().map(|r| r.y[50]).collect();
        let yh: Vec<f64> = sel.iter().map(|r| r.yhat[50]).collect();
        let k = gedisim::kernels::study::msd::msd_split(&y, &yh).unwrap();
        assert!((k.sb - psb[i]).abs() < 1e-9 && (k.sdsd - psd[i]).abs() < 1e-9 && (k.lcs - plc[i]).abs() < 1e-9);
        checked += 1;
    }
    assert_eq!(checked, 63);

    // bias profiles: bias at one percentile and the mean |bias| over RH1..RH99.
    let bp = study::read(&out.join("bias_profiles.parquet"));
    let (bw, ba, bf, bg, bpp, bb, bm) = (
        s(&bp, "weighting"),
        s(&bp, "algorithm"),
        s(&bp, "forest_type"),
        s(&bp, "sensitivity_group"),
        f(&bp, "percentile"),
        f(&bp, "bias"),
        f(&bp, "mean_abs_bias"),
    );
    let sel = |ft: &str, g: &str| -> Vec<&Row> {
        rows.iter()
            .filter(|r| {
                r.weighting == "count" && r.algorithm == "default" && (ft == "all" || r.forest == ft) && in_group(r, g)
            })
            .collect()
    };
    let profile: Vec<usize> = (0..bp.num_rows())
        .filter(|&i| bw[i] == "count" && ba[i] == "default" && bf[i] == "coniferous" && bg[i] == "high")
        .collect();
    assert_eq!(profile.len(), 99);
    let rs = sel("coniferous", "high");
    let mut abs_sum = 0.0;
    for &i in &profile {
        let k = bpp[i] as usize;
        let direct = rs.iter().map(|r| r.yhat[k] - r.y[k]).sum::<f64>() / rs.len() as f64;
        assert!((bb[i] - direct).abs() < 1e-9, "RH{k}: {} vs {direct}", bb[i]);
        abs_sum += direct.abs();
    }
    assert!((bm[profile[0]] - abs_sum / 99.0).abs() < 1e-9);
    let forests: std::collections::BTreeSet<&str> = bf.iter().map(String::as_str).collect();
    assert_eq!(
        forests.into_iter().collect::<Vec<_>>(),
        ["all", "broadleaf", "coniferous", "mixed", "other", "unknown"]
    );

    // phenology: both settings, the three phenologies, R² within [0, 1], bias against a direct mean.
    let ph = study::read(&out.join("phenology.parquet"));
    let (qp, qw, qa, qk, qb, qr) = (
        s(&ph, "phenology"),
        s(&ph, "weighting"),
        s(&ph, "algorithm"),
        f(&ph, "percentile"),
        f(&ph, "bias"),
        f(&ph, "r2"),
    );
    assert_eq!(ph.num_rows(), 3 * 2 * 99);
    assert!(qr.iter().all(|r| (0.0..=1.0).contains(r)));
    let i =
        (0..ph.num_rows()).find(|&i| qp[i] == "leaf_off" && qw[i] == "int" && qa[i] == "a3" && qk[i] == 90.0).unwrap();
    let rs: Vec<&Row> =
        rows.iter().filter(|r| r.phenology == "leaf_off" && r.weighting == "int" && r.algorithm == "a3").collect();
    let direct = rs.iter().map(|r| r.yhat[90] - r.y[90]).sum::<f64>() / rs.len() as f64;
    assert!((qb[i] - direct).abs() < 1e-9);
    // The planted leaf-off effect (real RH 1 m lower) makes leaf-off bias higher than leaf-on.
    let on =
        (0..ph.num_rows()).find(|&i| qp[i] == "leaf_on" && qw[i] == "int" && qa[i] == "a3" && qk[i] == 90.0).unwrap();
    assert!(qb[i] - qb[on] > 0.5, "leaf-off {} leaf-on {}", qb[i], qb[on]);

    // dataset summary: shot counts, leaf-off share, a1 share.
    let ds_sum = study::read(&out.join("dataset_summary.parquet"));
    let (sf, sbt, sn) = (s(&ds_sum, "forest_type"), s(&ds_sum, "beam_type"), f(&ds_sum, "n_shots"));
    let (leaf, a1) = (f(&ds_sum, "leaf_off_pct"), f(&ds_sum, "a1_selected_pct"));
    let total = (0..ds_sum.num_rows()).find(|&i| sf[i] == "all" && sbt[i] == "all").unwrap();
    assert_eq!(sn[total] as usize, N_SHOTS);
    assert!((leaf[total] - 50.0).abs() < 1e-9, "leaf-off share among known: {}", leaf[total]);
    assert!((a1[total] - 80.0).abs() < 1e-9, "a1 selected: {}", a1[total]);
    let mixed: f64 = (0..ds_sum.num_rows()).filter(|&i| sf[i] == "mixed" && sbt[i] != "all").map(|i| sn[i]).sum();
    assert_eq!(mixed as usize, (0..N_SHOTS).filter(|i| i % 9 != 0 && i % 4 == 2).count());

    // collocation tables from offsets.
    let col = study::read(&out.join("collocation.parquet"));
    let (cl, cb, cn) = (s(&col, "level"), s(&col, "beam"), f(&col, "n_segments"));
    let all = (0..col.num_rows()).find(|&i| cl[i] == "beam" && cb[i] == "all").unwrap();
    assert_eq!(cn[all], 12.0);
    assert!(f(&col, "mean_gain")[all] > 0.0);
    assert_eq!(study::read(&out.join("collocation_segments.parquet")).num_rows(), 12);

    // Waveform examples: 3 shots × (GEDI + 3 weightings).
    let wf = study::read(&out.join("waveform_examples.parquet"));
    assert_eq!(wf.num_rows(), 12);
    let sources: std::collections::BTreeSet<String> = s(&wf, "source").into_iter().collect();
    assert_eq!(sources.into_iter().collect::<Vec<_>>(), ["count", "frac", "gedi", "int"]);

    // Every table also as CSV with the same rows (header + rows).
    for (name, n) in &summary.tables {
        let csv = std::fs::read_to_string(out.join(format!("{name}.csv"))).unwrap();
        assert!(csv.lines().count() > *n, "{name}");
    }
    // No temporary file left behind.
    let leftovers: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn figures_html_and_geoparquet() {
    let dir = tempfile::tempdir().unwrap();
    let ds = full_dataset(&dir.path().join("ds"));
    let (ok, _, err) = common::gedisim(&["report", "--dataset", ds.root().to_str().unwrap()]);
    assert!(ok, "{err}");
    let out = ds.root().join("report");
    // To look at the figures: GEDISIM_KEEP_REPORT=<dir> cargo test --test study_report figures
    if let Ok(keep) = std::env::var("GEDISIM_KEEP_REPORT") {
        let keep = Path::new(&keep);
        std::fs::create_dir_all(keep).unwrap();
        for e in std::fs::read_dir(&out).unwrap().flatten() {
            std::fs::copy(e.path(), keep.join(e.file_name())).unwrap();
        }
    }
    for name in ["msd_bars", "bias_profiles", "phenology", "collocation", "waveforms", "rh_scatter", "shot_map"] {
        let png = out.join(format!("{name}.png"));
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
        let reader = decoder.read_info().unwrap();
        let info = reader.info();
        assert!(info.width >= 600 && info.height >= 300, "{name}: {}×{}", info.width, info.height);
        let svg = std::fs::read_to_string(out.join(format!("{name}.svg"))).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("</svg>"), "{name}");
        assert!(
            ["RH percentile", "elevation", "Pearson", "aligned GEDI RH98", "north"].iter().any(|t| svg.contains(t)),
            "{name}: axis text in the SVG"
        );
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(html.matches("data:image/png;base64,").count(), 7);
    // Units in the headers; every numeric column of every table has a known unit.
    for th in ["<th>bias (m)</th>", "<th>msd (m²)</th>", "<th>leaf_off_pct (%)</th>", "<th>r2</th>"] {
        assert!(html.contains(th), "{th}");
    }
    for e in std::fs::read_dir(&out).unwrap().flatten().filter(|e| e.path().extension().is_some_and(|x| x == "parquet"))
    {
        for field in study::read(&e.path()).schema().fields() {
            if field.data_type().is_numeric() {
                let name = field.name();
                assert!(gedisim::ops::report::html::unit(name).is_some(), "{:?}: no unit for {name}", e.file_name());
            }
        }
    }
    for t in ["ground_detection", "msd", "bias_summary", "phenology", "dataset_summary", "collocation"] {
        assert!(html.contains(&format!("href=\"{t}.csv\"")), "{t}");
    }
    assert!(!html.contains("src=\"http"), "readable offline: nothing fetched");

    // GeoParquet: `geo` metadata, WKB points at the shots' positions, bbox covering, all rows.
    for (table, rows) in [("shots", N_SHOTS), ("results", N_SHOTS * 21)] {
        let path = out.join(format!("{table}.geoparquet"));
        let file = std::fs::File::open(&path).unwrap();
        let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap();
        let kv = builder.metadata().file_metadata().key_value_metadata().unwrap().clone();
        let geo = kv.iter().find(|k| k.key == "geo").and_then(|k| k.value.clone()).expect("geo metadata");
        let geo: serde_json::Value = serde_json::from_str(&geo).unwrap();
        assert_eq!(geo["version"], "1.1.0");
        assert_eq!(geo["columns"]["geometry"]["encoding"], "WKB");
        assert_eq!(geo["columns"]["geometry"]["covering"]["bbox"]["ymax"][1], "ymax");
        let b = study::read(&path);
        assert_eq!(b.num_rows(), rows, "{table}");
        let sn = b.column_by_name("shot_number").unwrap().as_primitive::<UInt64Type>();
        let wkb = b.column_by_name("geometry").unwrap().as_binary::<i32>();
        let bbox = b.column_by_name("bbox").unwrap().as_struct();
        let xmin = bbox.column_by_name("xmin").unwrap().as_primitive::<Float64Type>();
        for i in [0, rows - 1] {
            let shot = (sn.value(i) - study::FIRST_SHOT) as f64;
            let g = wkb.value(i);
            assert_eq!(g.len(), 21);
            let x = f64::from_le_bytes(g[5..13].try_into().unwrap());
            let y = f64::from_le_bytes(g[13..21].try_into().unwrap());
            assert!(
                (x - (5.0 + shot * 1e-3)).abs() < 1e-12 && (y - (45.0 + shot * 1e-3)).abs() < 1e-12,
                "{table} row {i}"
            );
            assert_eq!(xmin.value(i), x);
        }
        // Same via the export command.
        let alone = dir.path().join(format!("{table}_export.parquet"));
        let (ok, _, err) = common::gedisim(&[
            "export",
            "geoparquet",
            "--dataset",
            ds.root().to_str().unwrap(),
            "--table",
            table,
            "--out",
            alone.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        assert_eq!(study::read(&alone).num_rows(), rows);
    }
    let (ok, _, err) = common::gedisim(&[
        "export",
        "geoparquet",
        "--dataset",
        ds.root().to_str().unwrap(),
        "--table",
        "sim",
        "--out",
        "/tmp/x.parquet",
    ]);
    assert!(!ok && err.contains("--table sim"), "{err}");

    // `gedisim sql` still works on a dataset holding a report (report/ is not a table).
    let (ok, out_sql, err) =
        common::gedisim(&["sql", "--dataset", ds.root().to_str().unwrap(), "select count(*) as n from results"]);
    assert!(ok && out_sql.contains(&format!("{}", N_SHOTS * 21)), "{err}");
}

#[test]
fn results_alone_skips_what_needs_other_tables() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::create(&dir.path().join("ds")).unwrap();
    // V1-like: no phenology known anywhere.
    let mut rows = study::synthetic_results(20);
    for r in &mut rows {
        r.leaf_off_flag = None;
    }
    study::write_results(&ds, &rows);
    let out = dir.path().join("elsewhere");
    let summary = run_report(
        &ds,
        &ReportOptions { out: Some(out.clone()), diagnosis: None },
        &Default::default(),
        &gedisim::ops::progress::NoProgress,
    )
    .unwrap();
    let skipped: HashMap<String, Vec<String>> = summary.skipped.iter().cloned().collect();
    assert_eq!(skipped["collocation"], ["offsets"]);
    assert_eq!(skipped["waveform_examples"], ["shots", "sim"]);
    assert!(out.join("msd.parquet").exists() && out.join("report.html").exists());
    assert!(summary.geoparquet.is_empty());
    assert!(
        summary.figure_notes.iter().any(|n| n.contains("phenology") && n.contains("unknown")),
        "{:?}",
        summary.figure_notes
    );
    let ph = study::read(&out.join("phenology.parquet"));
    assert!(s(&ph, "phenology").iter().all(|p| p == "unknown"));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("no offsets table"), "the page says why a table is missing");
}

#[test]
fn no_results_table_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let ds = Dataset::create(&dir.path().join("ds")).unwrap();
    let (ok, _, err) = common::gedisim(&["report", "--dataset", ds.root().to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("results") && err.contains("gedisim run"), "{err}");
    let (ok, _, err) = common::gedisim(&["report", "--dataset", dir.path().join("nope").to_str().unwrap()]);
    assert!(!ok && err.contains("nope"), "{err}");
}
