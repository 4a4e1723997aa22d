//! `gedisim ingest strata`: Corine Land Cover GeoTIFFs (written here with the `tiff` encoder and
//! the GeoTIFF tags) and CSVs sampled at the shots of a small dataset; bad inputs.

mod common;

use std::path::Path;
use std::sync::Arc;

use arrow::array::{AsArray, Float64Array, RecordBatch, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema, UInt16Type, UInt64Type};
use gedisim::dataset::{write_parquet, Dataset};
use gedisim::io::landcover::{LandCoverRaster, PixelSample};
use gedisim::kernels::geo::projection::Projector;
use gedisim::ops::ingest_strata::ingest_strata;
use gedisim::ops::progress::NoProgress;
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;

/// Shots around (5°E, 45°N): (shot_number, lon, lat); `None` = no position at all.
const SHOTS: [(u64, Option<(f64, f64)>); 7] = [
    (19640513500108370, Some((5.000, 45.000))),
    (19640513500108371, Some((5.004, 45.001))),
    (19640513500108372, Some((5.008, 45.002))),
    (19640513500108373, Some((5.012, 45.003))),
    (19640513500108374, Some((5.0165, 45.0015))),
    (19640513500108375, Some((7.5, 46.0))), // far outside the raster
    (19640513500108376, None),
];

/// A dataset whose shots table has the position columns `ingest strata` reads. Shot 0 has only
/// its L1B bins (no valid lowest mode), the others their lowest mode.
fn dataset_with_shots(dir: &Path) -> Dataset {
    let ds = Dataset::create(dir).unwrap();
    let f = |n: &str| Field::new(n, DataType::Float64, true);
    let schema = Arc::new(Schema::new(vec![
        Field::new("shot_number", DataType::UInt64, false),
        f("lat_lowestmode"),
        f("lon_lowestmode"),
        f("lat_bin0"),
        f("lon_bin0"),
        f("lat_lastbin"),
        f("lon_lastbin"),
    ]));
    let lowest = |i: usize, lat: bool| if i == 0 { None } else { SHOTS[i].1.map(|(lo, la)| if lat { la } else { lo }) };
    let bin = |i: usize, lat: bool, d: f64| SHOTS[i].1.map(|(lo, la)| if lat { la + d } else { lo + d });
    let n = SHOTS.len();
    let col = |g: &dyn Fn(usize) -> Option<f64>| Arc::new((0..n).map(g).collect::<Float64Array>()) as _;
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(SHOTS.iter().map(|s| s.0).collect::<UInt64Array>()),
            col(&|i| lowest(i, true)),
            col(&|i| lowest(i, false)),
            col(&|i| bin(i, true, 1e-5)),
            col(&|i| bin(i, false, 1e-5)),
            col(&|i| bin(i, true, -1e-5)),
            col(&|i| bin(i, false, -1e-5)),
        ],
    )
    .unwrap();
    write_parquet(&ds.table_file("shots", "s").unwrap(), schema, &[batch], &Default::default()).unwrap();
    ds
}

/// The raster's top-left corner and each shot's pixel (column, row), if inside.
type Layout = ((f64, f64), Vec<Option<(u32, u32)>>);

/// A 40 × 30 raster of 100 m pixels in EPSG:3035 whose top-left corner lies 500 m west and north
/// of shot 0; returns (x0, y0) and the pixel (col, row) of each shot inside it.
fn layout() -> Layout {
    let p = Projector::new(3035).unwrap();
    let (sx, sy) = p.project(5.0, 45.0).unwrap();
    let (x0, y0) = ((sx / 100.0).floor() * 100.0 - 500.0, (sy / 100.0).ceil() * 100.0 + 500.0);
    let pixels = SHOTS
        .iter()
        .map(|(_, pos)| {
            let (lon, lat) = (*pos)?;
            let (x, y) = p.project(lon, lat).unwrap();
            let (c, r) = (((x - x0) / 100.0).floor(), ((y0 - y) / 100.0).floor());
            (c >= 0.0 && r >= 0.0 && c < 40.0 && r < 30.0).then_some((c as u32, r as u32))
        })
        .collect();
    ((x0, y0), pixels)
}

const GEOKEYS_3035: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 3035];

/// Write an 8-bit raster (Copernicus grid codes) with `values[k]` at shot k's pixel, `fill` elsewhere.
fn write_grid_tiff(path: &Path, values: &[u8], fill: u8, geokeys: Option<&[u16]>) {
    let ((x0, y0), pixels) = layout();
    let mut data = vec![fill; 40 * 30];
    for (k, px) in pixels.iter().enumerate() {
        if let Some((c, r)) = px {
            data[(*r * 40 + *c) as usize] = values[k];
        }
    }
    let mut enc = TiffEncoder::new(std::fs::File::create(path).unwrap()).unwrap();
    let mut img = enc.new_image::<colortype::Gray8>(40, 30).unwrap();
    img.rows_per_strip(4).unwrap(); // several strips: only those holding a shot are decoded
    img.encoder().write_tag(Tag::ModelPixelScaleTag, &[100.0f64, 100.0, 0.0][..]).unwrap();
    img.encoder().write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, x0, y0, 0.0][..]).unwrap();
    if let Some(keys) = geokeys {
        img.encoder().write_tag(Tag::GeoKeyDirectoryTag, keys).unwrap();
    }
    img.encoder().write_tag(Tag::GdalNodata, "48").unwrap();
    img.write_data(&data).unwrap();
}

fn read_strata(ds: &Dataset) -> Vec<(u64, String, String, Option<u16>)> {
    let f = ds.table_file("strata", "strata").unwrap();
    let r = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(f).unwrap())
        .unwrap()
        .build()
        .unwrap();
    let mut out = Vec::new();
    for b in r {
        let b = b.unwrap();
        let sn = b.column(0).as_primitive::<UInt64Type>();
        let ft = b.column(1).as_string::<i32>();
        let src = b.column(2).as_string::<i32>();
        let code = b.column(3).as_primitive::<UInt16Type>();
        for i in 0..b.num_rows() {
            out.push((
                sn.value(i),
                ft.value(i).to_string(),
                src.value(i).to_string(),
                (!arrow::array::Array::is_null(code, i)).then(|| code.value(i)),
            ));
        }
    }
    out.sort();
    out
}

#[test]
fn grid_code_raster_gives_forest_types_and_unknown_outside() {
    let (_, pixels) = layout();
    // The five positioned shots near (5°E, 45°N) fall in five different pixels of the raster.
    let inside: Vec<_> = pixels.iter().flatten().collect();
    assert_eq!(inside.len(), 5, "{pixels:?}");
    assert!(inside.iter().collect::<std::collections::HashSet<_>>().len() == 5);

    let dir = tempfile::tempdir().unwrap();
    let ds = dataset_with_shots(&dir.path().join("ds"));
    let tif = dir.path().join("clc.tif");
    // grid codes: 23 → 311 broadleaf, 24 → 312 coniferous, 25 → 313 mixed, 12 → 211 other, 48 = no data.
    write_grid_tiff(&tif, &[23, 24, 25, 12, 48, 0, 0], 12, Some(&GEOKEYS_3035));
    let progress = common::Recorder::default();
    let report = ingest_strata(&ds, &tif, &progress).unwrap();
    assert!(progress.events.lock().unwrap().contains(&"total 7".to_string()), "the total is every shot");
    assert_eq!(progress.advanced.load(std::sync::atomic::Ordering::Relaxed), 7, "progress covers every shot");
    assert_eq!((report.rows, report.outside, report.no_position), (7, 1, 1));
    let got = read_strata(&ds);
    let types: Vec<&str> = got.iter().map(|r| r.1.as_str()).collect();
    assert_eq!(types, ["broadleaf", "coniferous", "mixed", "other", "unknown", "unknown", "unknown"]);
    let codes: Vec<Option<u16>> = got.iter().map(|r| r.3).collect();
    assert_eq!(codes, [Some(311), Some(312), Some(313), Some(211), None, None, None]);
    assert!(got.iter().all(|r| r.2 == "clc:clc.tif"));

    // Re-running replaces the table (atomically) rather than appending.
    ingest_strata(&ds, &tif, &NoProgress).unwrap();
    assert_eq!(read_strata(&ds).len(), 7);
}

#[test]
fn sixteen_bit_raster_holds_clc_codes() {
    let ((x0, y0), pixels) = layout();
    let mut data = vec![211u16; 40 * 30];
    for (k, code) in [(0usize, 313u16), (1, 312), (2, 311)] {
        let (c, r) = pixels[k].unwrap();
        data[(r * 40 + c) as usize] = code;
    }
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset_with_shots(&dir.path().join("ds"));
    let tif = dir.path().join("clc16.tiff");
    let mut enc = TiffEncoder::new(std::fs::File::create(&tif).unwrap()).unwrap();
    let mut img = enc.new_image::<colortype::Gray16>(40, 30).unwrap();
    img.encoder().write_tag(Tag::ModelPixelScaleTag, &[100.0f64, 100.0, 0.0][..]).unwrap();
    img.encoder().write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, x0, y0, 0.0][..]).unwrap();
    img.encoder().write_tag(Tag::GeoKeyDirectoryTag, &GEOKEYS_3035[..]).unwrap();
    img.write_data(&data).unwrap();
    ingest_strata(&ds, &tif, &NoProgress).unwrap();
    let types: Vec<String> = read_strata(&ds).into_iter().map(|r| r.1).collect();
    assert_eq!(types, ["mixed", "coniferous", "broadleaf", "other", "other", "unknown", "unknown"]);
}

#[test]
fn wrong_or_missing_crs_is_a_one_line_error_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset_with_shots(&dir.path().join("ds"));
    let lambert = [1u16, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 2154];
    let tif = dir.path().join("lambert93.tif");
    write_grid_tiff(&tif, &[23; 7], 12, Some(&lambert));
    let e = ingest_strata(&ds, &tif, &NoProgress).unwrap_err().to_string();
    assert!(e.contains("lambert93.tif") && e.contains("ProjectedCSTypeGeoKey") && e.contains("EPSG:2154"), "{e}");
    assert!(!e.contains('\n'));

    let plain = dir.path().join("plain.tif");
    write_grid_tiff(&plain, &[23; 7], 12, None);
    let e = ingest_strata(&ds, &plain, &NoProgress).unwrap_err().to_string();
    assert!(e.contains("plain.tif") && e.contains("GeoKeyDirectory"), "{e}");

    let junk = dir.path().join("junk.tif");
    std::fs::write(&junk, b"not a tiff").unwrap();
    let e = ingest_strata(&ds, &junk, &NoProgress).unwrap_err().to_string();
    assert!(e.contains("junk.tif"), "{e}");

    // Nothing was written by the failed runs.
    assert!(!ds.has_table("strata"));

    // Through the CLI: non-zero exit, one line.
    let (ok, _, err) = common::gedisim(&[
        "ingest",
        "strata",
        "--landcover",
        tif.to_str().unwrap(),
        "--dataset",
        ds.root().to_str().unwrap(),
    ]);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("lambert93.tif"), "{err}");
}

#[test]
fn csv_strata_and_its_errors() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset_with_shots(&dir.path().join("ds"));
    let csv = dir.path().join("types.csv");
    std::fs::write(
        &csv,
        "forest_type,shot_number,comment\nConiferous,19640513500108371,x\nbroadleaf,19640513500108370,\nmixed,42,\n",
    )
    .unwrap();
    let (ok, _, err) = common::gedisim(&[
        "ingest",
        "strata",
        "--landcover",
        csv.to_str().unwrap(),
        "--dataset",
        ds.root().to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(err.contains("not in the dataset"), "{err}");
    let got = read_strata(&ds);
    assert_eq!(got.len(), 3);
    assert_eq!((got[0].0, got[0].1.as_str(), got[0].2.as_str()), (42, "mixed", "csv:types.csv"));
    assert_eq!((got[1].0, got[1].1.as_str()), (19640513500108370, "broadleaf"));
    assert_eq!((got[2].0, got[2].1.as_str()), (19640513500108371, "coniferous"));
    // The same as a spreadsheet exports it: byte-order mark, `;`, quotes, other column names.
    std::fs::write(
        &csv,
        concat!(
            "\u{feff}\"Forest\";\"Shot_ID\";note\n",
            "\"coniferous\";19640513500108371;\"a; b\"\nBroadleaf;19640513500108370;\n"
        ),
    )
    .unwrap();
    ingest_strata(&ds, &csv, &NoProgress).unwrap();
    let got = read_strata(&ds);
    assert_eq!(got.len(), 2);
    assert_eq!((got[0].0, got[0].1.as_str()), (19640513500108370, "broadleaf"));
    assert_eq!((got[1].0, got[1].1.as_str()), (19640513500108371, "coniferous"));

    let cases: [(&str, &[&str]); 5] = [
        ("shot_number,kind\n1,mixed\n", &["no `forest_type`", "column"]),
        ("forest_type\nmixed\n", &["no `shot_number`", "column"]),
        ("shot_number,forest_type\n1,pine\n", &["line 2: forest_type", "pine"]),
        ("shot_number,forest_type\n1.5e3,mixed\n", &["line 2: shot_number"]),
        ("shot_number,forest_type\n1,mixed\n1,other\n", &["line 3: shot_number", "twice"]),
    ];
    for (text, needles) in cases {
        let bad = dir.path().join("bad.csv");
        std::fs::write(&bad, text).unwrap();
        let e = ingest_strata(&ds, &bad, &NoProgress).unwrap_err().to_string();
        assert!(e.contains("bad.csv"), "{e}");
        for n in needles {
            assert!(e.contains(n), "{text:?}: {e}");
        }
    }
    let e = ingest_strata(&ds, &dir.path().join("x.shp"), &NoProgress).unwrap_err().to_string();
    assert!(e.contains("x.shp") && e.contains("GeoTIFF"), "{e}");
}

/// A tiled GeoTIFF written byte by byte (the `tiff` encoder writes strips only): 40 × 30 pixels in
/// 16 × 16 tiles, so the right and bottom tiles are partly outside the image.
fn write_tiled_tiff(path: &Path, data: &[u8], (x0, y0): (f64, f64)) {
    let (w, h, t) = (40u32, 30u32, 16u32);
    let (across, down) = (w.div_ceil(t), h.div_ceil(t));
    let mut tiles: Vec<Vec<u8>> = Vec::new();
    for ty in 0..down {
        for tx in 0..across {
            let mut tile = vec![0u8; (t * t) as usize];
            for r in 0..t {
                for c in 0..t {
                    let (col, row) = (tx * t + c, ty * t + r);
                    if col < w && row < h {
                        tile[(r * t + c) as usize] = data[(row * w + col) as usize];
                    }
                }
            }
            tiles.push(tile);
        }
    }
    // Layout: header, IFD, then the arrays and the tiles.
    let entries: u32 = 15;
    let ifd_len = 2 + 12 * entries + 4;
    let mut extra: Vec<u8> = Vec::new();
    let base = 8 + ifd_len;
    let mut put = |bytes: &[u8]| -> u32 {
        let at = base + extra.len() as u32;
        extra.extend_from_slice(bytes);
        at
    };
    let n_tiles = tiles.len() as u32;
    let scale: Vec<u8> = [100.0f64, 100.0, 0.0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let tie: Vec<u8> = [0.0f64, 0.0, 0.0, x0, y0, 0.0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let keys: Vec<u8> = GEOKEYS_3035.iter().flat_map(|v| v.to_le_bytes()).collect();
    let scale_at = put(&scale);
    let tie_at = put(&tie);
    let keys_at = put(&keys);
    let counts_at = put(&vec![0u8; 4 * n_tiles as usize]);
    let offsets_at = put(&vec![0u8; 4 * n_tiles as usize]);
    let mut tile_offsets = Vec::new();
    for tile in &tiles {
        tile_offsets.push(put(tile));
    }
    for (k, off) in tile_offsets.iter().enumerate() {
        let i = (offsets_at - base) as usize + 4 * k;
        extra[i..i + 4].copy_from_slice(&off.to_le_bytes());
        let j = (counts_at - base) as usize + 4 * k;
        extra[j..j + 4].copy_from_slice(&(t * t).to_le_bytes());
    }
    // (tag, type, count, value or offset): types 3 SHORT, 4 LONG, 12 DOUBLE.
    let ifd: [(u16, u16, u32, u32); 15] = [
        (256, 4, 1, w),
        (257, 4, 1, h),
        (258, 3, 1, 8),
        (259, 3, 1, 1),
        (262, 3, 1, 1),
        (277, 3, 1, 1),
        (284, 3, 1, 1),
        (322, 4, 1, t),
        (323, 4, 1, t),
        (324, 4, n_tiles, offsets_at),
        (325, 4, n_tiles, counts_at),
        (339, 3, 1, 1),
        (33550, 12, 3, scale_at),
        (33922, 12, 6, tie_at),
        (34735, 3, GEOKEYS_3035.len() as u32, keys_at),
    ];
    let mut out: Vec<u8> = b"II".to_vec();
    out.extend_from_slice(&42u16.to_le_bytes());
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&(entries as u16).to_le_bytes());
    for (tag, typ, count, value) in ifd {
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&typ.to_le_bytes());
        out.extend_from_slice(&count.to_le_bytes());
        if typ == 3 && count == 1 {
            out.extend_from_slice(&(value as u16).to_le_bytes());
            out.extend_from_slice(&[0, 0]);
        } else {
            out.extend_from_slice(&value.to_le_bytes());
        }
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&extra);
    std::fs::write(path, out).unwrap();
}

#[test]
fn tiled_raster_including_edge_tiles() {
    let ((x0, y0), pixels) = layout();
    // Every pixel gets a value from its position, so a wrong offset inside a tile shows.
    let grid = |c: u32, r: u32| [23u8, 24, 25, 12, 1][((c * 7 + r * 3) % 5) as usize];
    let data: Vec<u8> = (0..30).flat_map(|r| (0..40).map(move |c| grid(c, r))).collect();
    let dir = tempfile::tempdir().unwrap();
    let ds = dataset_with_shots(&dir.path().join("ds"));
    let tif = dir.path().join("tiled.tif");
    write_tiled_tiff(&tif, &data, (x0, y0));
    ingest_strata(&ds, &tif, &NoProgress).unwrap();
    let got = read_strata(&ds);
    let name = |v: u8| match v {
        23 => "broadleaf",
        24 => "coniferous",
        25 => "mixed",
        _ => "other",
    };
    for (k, px) in pixels.iter().enumerate() {
        let expected = px.map(|(c, r)| name(grid(c, r))).unwrap_or("unknown");
        assert_eq!(got[k].1, expected, "shot {k} at {px:?}");
    }
    // Every pixel centre, including those of the partial right-hand and bottom tiles.
    let mut raster = LandCoverRaster::open(&tif).unwrap();
    let centres: Vec<(f64, f64)> = (0..30)
        .flat_map(|r| (0..40).map(move |c| (x0 + 100.0 * c as f64 + 50.0, y0 - 100.0 * r as f64 - 50.0)))
        .collect();
    let samples = raster.sample_xy(&centres, &|_| {}).unwrap();
    let clc = |v: u8| gedisim::kernels::study::classes::clc_code_of_grid_code(v as u16).unwrap();
    for (k, s) in samples.iter().enumerate() {
        let (c, r) = ((k % 40) as u32, (k / 40) as u32);
        assert_eq!(*s, PixelSample::Clc(clc(grid(c, r))), "pixel ({c}, {r})");
    }
    let outside = raster.sample_xy(&[(x0 - 1.0, y0 - 1.0), (x0 + 4000.5, y0 - 10.0)], &|_| {}).unwrap();
    assert_eq!(outside, [PixelSample::Outside, PixelSample::Outside]);
}
