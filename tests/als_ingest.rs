//! `ingest als` on the real LiDAR HD tiles and on constructed bad inputs.

mod common;

use std::fs::File;
use std::path::Path;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float32Type, Float64Type, UInt16Type, UInt64Type, UInt8Type};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::file::reader::FileReader;
use parquet::file::serialized_reader::SerializedFileReader;
use parquet::file::statistics::Statistics;

use common::{data, files_with_suffix, gedisim};
use gedisim::dataset::Dataset;
use gedisim::ops::ingest_als::{ingest_tiles, AlsOptions, TileOutcome};

fn ingest(dir: &Path, files: &[&Path], opts: &AlsOptions) -> gedisim::Result<Vec<TileOutcome>> {
    let ds = Dataset::create(dir).unwrap();
    let files: Vec<_> = files.iter().map(|p| p.to_path_buf()).collect();
    ingest_tiles(&ds, &files, opts, &gedisim::ops::progress::NoProgress)
}

/// All rows of the Parquet files of one table.
fn read_table(dir: &Path) -> Vec<arrow::record_batch::RecordBatch> {
    let mut out = Vec::new();
    for f in files_with_suffix(dir, ".parquet") {
        let r = ParquetRecordBatchReaderBuilder::try_new(File::open(f).unwrap()).unwrap().build().unwrap();
        out.extend(r.map(|b| b.unwrap()));
    }
    out
}

fn rows(batches: &[arrow::record_batch::RecordBatch]) -> usize {
    batches.iter().map(|b| b.num_rows()).sum()
}

/// Facts of each bundled tile, as measured with laspy in tests/data/als/PROVENANCE.md:
/// (name, points, intensity min, max, scan angle min/max in degrees, class-65 points).
const FACTS: [(&str, u64, u16, u16, f32, f32, u64); 3] = [
    ("lidarforfuel_1_42", 419_079, 114, 1537, -8.922, -4.794, 0),
    ("lidarforfuel_2_bas_lig", 247_194, 25602, 54219, 4.704, 8.64, 0),
    ("pdal-ign-plugin_mnx_input_crop_2", 221_565, 16, 2032, 10.65, 21.78, 250),
];

#[test]
fn real_tiles_counts_attributes_and_metadata() {
    let tmp = tempfile::tempdir().unwrap();
    let paths: Vec<_> = FACTS.iter().map(|f| data(&format!("als/{}.laz", f.0))).collect();
    let refs: Vec<&Path> = paths.iter().map(|p| p.as_path()).collect();
    let outcomes = ingest(tmp.path(), &refs, &AlsOptions::default()).unwrap();
    assert_eq!(outcomes.len(), 3);

    let tiles = read_table(&tmp.path().join("tiles"));
    assert_eq!(rows(&tiles), 3);
    for (name, n, imin, imax, smin, smax, class65) in FACTS {
        let b = tiles.iter().find(|b| b.column_by_name("tile").unwrap().as_string::<i32>().value(0) == name).unwrap();
        let u64c = |c: &str| b.column_by_name(c).unwrap().as_primitive::<UInt64Type>().value(0);
        let u16c = |c: &str| b.column_by_name(c).unwrap().as_primitive::<UInt16Type>().value(0);
        assert_eq!(u64c("n_points_header"), n, "{name}");
        assert_eq!(u64c("n_points") + u64c("n_dropped"), n, "{name}");
        assert_eq!(u64c("n_dropped"), class65, "{name}: only class 65 is dropped");
        assert_eq!(b.column_by_name("epsg").unwrap().as_primitive::<arrow::datatypes::UInt32Type>().value(0), 2154);
        if class65 == 0 {
            assert_eq!((u16c("intensity_min"), u16c("intensity_max")), (imin, imax), "{name}");
        }
        assert!(!b.column_by_name("acquisition_start").unwrap().is_null(0));

        // Points of this tile: count, attribute ranges.
        let pts: Vec<_> = read_table(&tmp.path().join("als"))
            .into_iter()
            .filter(|p| p.column_by_name("tile").unwrap().as_string::<i32>().value(0) == name)
            .collect();
        assert_eq!(rows(&pts) as u64, n - class65, "{name}");
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        let mut classes = std::collections::BTreeSet::new();
        for p in &pts {
            for &s in p.column_by_name("scan_angle_deg").unwrap().as_primitive::<Float32Type>().values() {
                lo = lo.min(s);
                hi = hi.max(s);
            }
            classes.extend(
                p.column_by_name("classification").unwrap().as_primitive::<UInt8Type>().values().iter().copied(),
            );
            let rn = p.column_by_name("return_number").unwrap().as_primitive::<UInt8Type>();
            let nr = p.column_by_name("number_of_returns").unwrap().as_primitive::<UInt8Type>();
            assert!(rn.values().iter().zip(nr.values()).all(|(r, n)| r <= n && *r >= 1));
        }
        assert!((lo - smin).abs() < 1e-3 && (hi - smax).abs() < 1e-3, "{name}: scan angle {lo}..{hi}");
        assert!(!classes.contains(&65) && !classes.contains(&7));
    }

    // Keeping every class brings the 250 class-65 points back.
    let tmp2 = tempfile::tempdir().unwrap();
    let crop = data("als/pdal-ign-plugin_mnx_input_crop_2.laz");
    ingest(tmp2.path(), &[&crop], &AlsOptions { keep_all_classes: true, ..Default::default() }).unwrap();
    assert_eq!(rows(&read_table(&tmp2.path().join("als"))), 221_565);
}

#[test]
fn bbox_query_reads_only_the_row_groups_it_needs() {
    let tmp = tempfile::tempdir().unwrap();
    let tile = data("als/lidarforfuel_1_42.laz");
    ingest(tmp.path(), &[&tile], &AlsOptions::default()).unwrap();
    let file = &files_with_suffix(&tmp.path().join("als"), ".parquet")[0];
    let reader = SerializedFileReader::new(File::open(file).unwrap()).unwrap();
    let meta = reader.metadata();
    let schema = meta.file_metadata().schema_descr();
    let col = |name: &str| (0..schema.num_columns()).find(|&i| schema.column(i).name() == name).unwrap();
    let (xi, yi) = (col("x"), col("y"));
    let range = |rg: &parquet::file::metadata::RowGroupMetaData, i: usize| match rg.column(i).statistics() {
        Some(Statistics::Double(s)) => (*s.min_opt().unwrap(), *s.max_opt().unwrap()),
        other => panic!("no f64 statistics: {other:?}"),
    };
    // A footprint-sized box (35 m) in the tile.
    let (x0, y0, x1, y1) = (817600.0, 6460790.0, 817635.0, 6460825.0);
    let n_groups = meta.num_row_groups();
    let needed: Vec<usize> = (0..n_groups)
        .filter(|&g| {
            let (ax, bx) = range(meta.row_group(g), xi);
            let (ay, by) = range(meta.row_group(g), yi);
            ax <= x1 && bx >= x0 && ay <= y1 && by >= y0
        })
        .collect();
    // Points in the box: by a full scan, and by reading only the needed row groups.
    let in_box = |batches: &[arrow::record_batch::RecordBatch]| -> usize {
        batches
            .iter()
            .map(|b| {
                let x = b.column_by_name("x").unwrap().as_primitive::<Float64Type>();
                let y = b.column_by_name("y").unwrap().as_primitive::<Float64Type>();
                (0..b.num_rows())
                    .filter(|&i| (x0..=x1).contains(&x.value(i)) && (y0..=y1).contains(&y.value(i)))
                    .count()
            })
            .sum()
    };
    let full = in_box(&read_table(&tmp.path().join("als")));
    let pruned: Vec<_> = ParquetRecordBatchReaderBuilder::try_new(File::open(file).unwrap())
        .unwrap()
        .with_row_groups(needed.clone())
        .build()
        .unwrap()
        .map(|b| b.unwrap())
        .collect();
    println!("row groups: {} of {n_groups} needed; {full} points in the box", needed.len());
    assert!(full > 10_000);
    assert_eq!(in_box(&pruned), full);
    assert!(needed.len() <= 4 && n_groups >= 4 * needed.len(), "{} of {n_groups}", needed.len());
    // Rows are clustered: the cell key never decreases.
    let cells: Vec<u64> = read_table(&tmp.path().join("als"))
        .iter()
        .flat_map(|b| b.column_by_name("cell").unwrap().as_primitive::<UInt64Type>().values().to_vec())
        .collect();
    assert!(cells.windows(2).all(|w| w[0] <= w[1]));
    // CRS in the key-value metadata.
    let kv = meta.file_metadata().key_value_metadata().unwrap();
    assert!(kv.iter().any(|k| k.key == "gedisim:crs_epsg" && k.value.as_deref() == Some("2154")));
}

#[test]
fn ingesting_twice_does_not_duplicate() {
    let tmp = tempfile::tempdir().unwrap();
    let tile = data("als/lidarforfuel_2_bas_lig.laz");
    let out = tmp.path().to_str().unwrap();
    let (ok, _, err) = gedisim(&["ingest", "als", tile.to_str().unwrap(), "--out", out]);
    assert!(ok, "{err}");
    // A copy under another name has the same content hash.
    let copy = tmp.path().join("copy.laz");
    std::fs::copy(&tile, &copy).unwrap();
    let (ok, _, err) = gedisim(&["ingest", "als", tile.to_str().unwrap(), copy.to_str().unwrap(), "--out", out]);
    assert!(ok, "{err}");
    assert!(err.contains("already ingested"), "{err}");
    assert_eq!(rows(&read_table(&tmp.path().join("als"))), 247_194);
    assert_eq!(rows(&read_table(&tmp.path().join("tiles"))), 1);
}

/// Write a small LAS file of `format` with 100 points, optionally with a CRS and extra bytes.
fn write_las(path: &Path, format: u8, wkt: bool, extra_bytes: u16, evlr: bool) {
    let mut b = las::Builder::from((1, 4));
    b.point_format = las::point::Format::new(format).unwrap();
    b.point_format.extra_bytes = extra_bytes;
    b.transforms = las::Vector {
        x: las::Transform { scale: 0.01, offset: 700000.0 },
        y: las::Transform { scale: 0.01, offset: 6600000.0 },
        z: las::Transform { scale: 0.01, offset: 0.0 },
    };
    if wkt {
        b.vlrs.push(las::Vlr {
            user_id: "LASF_Projection".into(),
            record_id: 2112,
            description: "WKT".into(),
            data: concat!(
                r#"PROJCS["RGF93 v1 / Lambert-93",GEOGCS["RGF93 v1",AUTHORITY["EPSG","4171"]],"#,
                r#"AUTHORITY["EPSG","2154"]]"#
            )
            .as_bytes()
            .to_vec(),
        });
    }
    if extra_bytes > 0 {
        // One extra-bytes descriptor (192 bytes): an unsigned char array of `extra_bytes` bytes.
        let mut d = vec![0u8; 192];
        d[2] = 0; // data type 0 = undocumented bytes, length in `options`
        d[3] = 0;
        d[4..4 + 7].copy_from_slice(b"marker1");
        b.vlrs.push(las::Vlr { user_id: "LASF_Spec".into(), record_id: 4, description: "extra".into(), data: d });
    }
    if evlr {
        b.evlrs.push(las::Vlr {
            user_id: "PDAL".into(),
            record_id: 13,
            description: "pipeline".into(),
            data: vec![b'x'; 70_000],
        });
    }
    let header = b.into_header().unwrap();
    let mut w = las::Writer::from_path(path, header).unwrap();
    for i in 0..100 {
        let mut p = las::Point {
            x: 700000.0 + i as f64,
            y: 6600000.0 + (i % 10) as f64,
            z: 100.0 + i as f64 * 0.1,
            intensity: 100 + i as u16,
            return_number: 1,
            number_of_returns: 1,
            classification: las::point::Classification::Ground,
            scan_angle: if format >= 6 { -3.006 } else { -3.0 },
            point_source_id: 7,
            extra_bytes: vec![i as u8; extra_bytes as usize],
            ..Default::default()
        };
        if b_has_gps(format) {
            p.gps_time = Some(338_993_840.0 + i as f64);
        }
        if matches!(format, 2 | 3 | 5 | 7 | 8 | 10) {
            p.color = Some(las::Color { red: 1, green: 2, blue: 3 });
        }
        if matches!(format, 8 | 10) {
            p.nir = Some(4);
        }
        if matches!(format, 4 | 5 | 9 | 10) {
            p.waveform = Some(Default::default());
        }
        w.write_point(p).unwrap();
    }
    w.close().unwrap();
}

fn b_has_gps(format: u8) -> bool {
    format != 0 && format != 2
}

#[test]
fn every_point_format_extra_bytes_and_evlrs() {
    let tmp = tempfile::tempdir().unwrap();
    for format in 0..=10u8 {
        let f = tmp.path().join(format!("pf{format}.las"));
        write_las(&f, format, true, if format % 2 == 0 { 3 } else { 0 }, format >= 6);
        let out = tmp.path().join(format!("ds{format}"));
        ingest(&out, &[&f], &AlsOptions::default()).unwrap_or_else(|e| panic!("format {format}: {e}"));
        let pts = read_table(&out.join("als"));
        assert_eq!(rows(&pts), 100, "format {format}");
        let scan = pts[0].column_by_name("scan_angle_deg").unwrap().as_primitive::<Float32Type>().value(0);
        let want = if format >= 6 { -3.006 } else { -3.0 };
        assert!((scan - want).abs() < 1e-4, "format {format}: scan angle {scan}");
        let gps = pts[0].column_by_name("gps_time").unwrap();
        assert_eq!(gps.is_null(0), !b_has_gps(format), "format {format}");
        let tiles = read_table(&out.join("tiles"));
        let eb = tiles[0].column_by_name("extra_bytes").unwrap().as_string::<i32>().value(0).to_string();
        assert_eq!(eb == "marker1", format % 2 == 0, "format {format}: extra bytes {eb:?}");
    }
}

#[test]
fn tile_without_crs_needs_epsg() {
    let tmp = tempfile::tempdir().unwrap();
    let f = tmp.path().join("nocrs.las");
    write_las(&f, 1, false, 0, false);
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", f.to_str().unwrap(), "--out", ds.to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("nocrs.las") && err.contains("CRS") && err.contains("--epsg"), "{err}");
    let (ok, _, err) =
        gedisim(&["ingest", "als", f.to_str().unwrap(), "--out", ds.to_str().unwrap(), "--epsg", "2154"]);
    assert!(ok, "{err}");
    // A contradicting --epsg is refused.
    let g = tmp.path().join("crs.las");
    write_las(&g, 1, true, 0, false);
    let (ok, _, err) = gedisim(&[
        "ingest",
        "als",
        g.to_str().unwrap(),
        "--out",
        tmp.path().join("ds2").to_str().unwrap(),
        "--epsg",
        "32631",
    ]);
    assert!(!ok && err.contains("EPSG:2154"), "{err}");
}

/// A failed ingest leaves no Parquet file (complete or partial) and no temporary file.
fn assert_no_table_files(ds: &Path) {
    assert!(files_with_suffix(ds, ".parquet").is_empty(), "{:?}", files_with_suffix(ds, ".parquet"));
    assert!(files_with_suffix(ds, ".tmp").is_empty(), "{:?}", files_with_suffix(ds, ".tmp"));
}

#[test]
fn truncated_laz_is_a_one_line_error_and_leaves_no_table() {
    let tmp = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(data("als/lidarforfuel_2_bas_lig.laz")).unwrap();
    let f = tmp.path().join("truncated.laz");
    std::fs::write(&f, &bytes[..bytes.len() / 2]).unwrap();
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", f.to_str().unwrap(), "--out", ds.to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("truncated.laz"), "{err}");
    assert_no_table_files(&ds);
}

#[test]
fn lying_point_count_is_an_error_naming_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let f = tmp.path().join("liar.las");
    write_las(&f, 1, true, 0, false);
    let mut bytes = std::fs::read(&f).unwrap();
    // Legacy point count (offset 107) and LAS 1.4 64-bit count (offset 247): claim 150 points.
    bytes[107..111].copy_from_slice(&150u32.to_le_bytes());
    bytes[247..255].copy_from_slice(&150u64.to_le_bytes());
    std::fs::write(&f, &bytes).unwrap();
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", f.to_str().unwrap(), "--out", ds.to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("liar.las") && (err.contains("number_of_points") || err.contains("points")), "{err}");
    assert_no_table_files(&ds);
}

#[test]
fn nan_coordinates_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let f = tmp.path().join("nan.las");
    write_las(&f, 1, true, 0, false);
    let mut bytes = std::fs::read(&f).unwrap();
    // x scale factor (offset 131) set to NaN: every x decodes to NaN.
    bytes[131..139].copy_from_slice(&f64::NAN.to_le_bytes());
    std::fs::write(&f, &bytes).unwrap();
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", f.to_str().unwrap(), "--out", ds.to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("nan.las") && err.contains('x'), "{err}");
    assert_no_table_files(&ds);
}
