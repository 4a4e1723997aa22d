//! A synthetic study dataset (results, offsets, shots, sim) for the report tests, written with the
//! library's own results builder. Include with `#[path = "common/study.rs"] mod study;`.
#![allow(dead_code)]

use std::path::Path;
use std::sync::Arc;

use arrow::array::{
    ArrayRef, Float32Builder, Float64Array, ListBuilder, RecordBatch, StringArray, UInt32Array, UInt64Array,
};
use arrow::datatypes::{DataType, Field, Schema};
use gedisim::dataset::results::{results_metadata, results_schema};
use gedisim::dataset::{write_parquet, Dataset};
use gedisim::kernels::study::align::VerticalReference;
use gedisim::kernels::study::select::{ResultInput, StudyAlgorithm};
use gedisim::ops::run::results_batch;

/// Deterministic uniform numbers in [0, 1) (xorshift64*).
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Roughly normal (sum of uniforms), mean 0, sd 1.
    pub fn normal(&mut self) -> f64 {
        (0..12).map(|_| self.next()).sum::<f64>() - 6.0
    }
}

pub const FIRST_SHOT: u64 = 19640513500108000;
pub const GEOID: f64 = 50.0;
/// Constant ground error of each algorithm, m (index 0 = default, then a1..a6).
pub const GROUND_OFFSET: [f64; 7] = [0.1, 0.1, 0.2, -0.5, 0.3, 0.0, -0.2];
pub const FORESTS: [&str; 4] = ["broadleaf", "coniferous", "mixed", "other"];

/// Canopy truth of shot i: (als_ground, canopy height, slope, cover).
pub fn truth(i: usize) -> (f64, f64, f64, f64) {
    let mut r = Rng::new(1000 + i as u64);
    (300.0 + 20.0 * r.next(), 8.0 + 25.0 * r.next(), 40.0 * r.next(), r.next())
}

/// `n` shots × 3 weightings × 7 algorithms of a synthetic study.
pub fn synthetic_results(n: usize) -> Vec<ResultInput> {
    let mut rows = Vec::new();
    for i in 0..n {
        let mut r = Rng::new(7 + i as u64);
        let (als_ground, height, slope, cover) = truth(i);
        let leaf_off_flag = [Some(0u8), Some(1), None][i % 3];
        let rh_true: Vec<f64> = (0..=100).map(|k| height * (k as f64 / 100.0).powf(1.5) - 0.5).collect();
        let sens_base = 0.90 + 0.099 * r.next();
        for (a, alg) in std::iter::once(StudyAlgorithm::Default).chain((1..=6).map(StudyAlgorithm::A)).enumerate() {
            let e = GROUND_OFFSET[a] + 0.3 * r.normal();
            let leaf = if leaf_off_flag == Some(1) { -1.0 } else { 0.0 };
            let rh_gedi: Vec<f32> = rh_true.iter().map(|h| (h - e + 0.5 * r.normal() + leaf) as f32).collect();
            for (w, (scale, bias)) in ["count", "frac", "int"].into_iter().zip([(0.95, 0.0), (1.0, 0.2), (1.02, -0.3)])
            {
                let rh_sim: Vec<f32> = rh_true.iter().map(|h| (h * scale + bias + 0.4 * r.normal()) as f32).collect();
                rows.push(ResultInput {
                    shot_number: FIRST_SHOT + i as u64,
                    granule: "GEDI02_A_2019108080338_O01964_T05337_02_001_01".into(),
                    beam: if i % 2 == 0 { "BEAM0000".into() } else { "BEAM0101".into() },
                    beam_type: if i % 2 == 0 { "coverage".into() } else { "full_power".into() },
                    forest_type: (i % 9 != 0).then(|| FORESTS[i % 4].to_string()),
                    leaf_off_flag,
                    selected_algorithm: Some(if i % 5 == 0 { 2 } else { 1 }),
                    sensitivity: (sens_base + 0.002 * a as f64).min(0.999),
                    slope_deg: Some(slope),
                    als_cover: Some(cover),
                    weighting: w.into(),
                    algorithm: alg,
                    als_ground,
                    elev_lowestmode: als_ground + GEOID + e,
                    vertical_reference: VerticalReference::Geoid { geoid_offset: GEOID },
                    rh_sim,
                    rh_gedi: rh_gedi.clone(),
                    r_collocation: (i % 4 != 0).then(|| 0.9 + 0.09 * r.next()),
                });
            }
        }
    }
    rows
}

/// Write `rows` as `<dataset>/results/part-0.parquet`.
pub fn write_results(ds: &Dataset, rows: &[ResultInput]) {
    let batch = results_batch(rows).unwrap();
    write_parquet(&ds.table_file("results", "part-0").unwrap(), results_schema(), &[batch], &results_metadata())
        .unwrap();
}

/// An offsets table of `n` segments with the contract's columns.
pub fn write_offsets(ds: &Dataset, n: usize) {
    let mut r = Rng::new(99);
    let f64s = |v: Vec<f64>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let before: Vec<f64> = (0..n).map(|_| 0.6 + 0.3 * r.next()).collect();
    let after: Vec<f64> = before.iter().map(|b| (b + 0.05 + 0.1 * r.next()).min(0.999)).collect();
    let mut shots = ListBuilder::new(arrow::array::UInt64Builder::new());
    for s in 0..n {
        shots.append_value((0..3).map(|k| Some(FIRST_SHOT + (3 * s + k) as u64)));
    }
    let fields = vec![
        Field::new("segment_id", DataType::Utf8, false),
        Field::new("granule", DataType::Utf8, false),
        Field::new("beam", DataType::Utf8, false),
        Field::new("level", DataType::Utf8, false),
        Field::new("shot_numbers", DataType::List(Arc::new(Field::new_list_field(DataType::UInt64, true))), false),
        Field::new("n_shots", DataType::UInt32, false),
        Field::new("dx", DataType::Float64, false),
        Field::new("dy", DataType::Float64, false),
        Field::new("dz", DataType::Float64, false),
        Field::new("geoid_offset", DataType::Float64, false),
        Field::new("r_before", DataType::Float64, false),
        Field::new("r_after", DataType::Float64, false),
        Field::new("dx_halfwidth", DataType::Float64, false),
        Field::new("dy_halfwidth", DataType::Float64, false),
        Field::new("dz_halfwidth", DataType::Float64, false),
    ];
    let schema = Arc::new(Schema::new(fields));
    let cols: Vec<ArrayRef> = vec![
        Arc::new((0..n).map(|s| Some(format!("seg{s:03}"))).collect::<StringArray>()),
        Arc::new(StringArray::from(vec!["g"; n])),
        Arc::new((0..n).map(|s| Some(if s % 2 == 0 { "BEAM0000" } else { "BEAM0101" })).collect::<StringArray>()),
        Arc::new(StringArray::from(vec!["beam"; n])),
        Arc::new(shots.finish()),
        Arc::new(UInt32Array::from(vec![3; n])),
        f64s((0..n).map(|s| s as f64 % 5.0 - 2.0).collect()),
        f64s((0..n).map(|s| 1.0 - s as f64 % 3.0).collect()),
        f64s(vec![0.2; n]),
        f64s(vec![GEOID; n]),
        f64s(before),
        f64s(after),
        f64s(vec![1.0; n]),
        f64s(vec![1.5; n]),
        f64s(vec![0.3; n]),
    ];
    let batch = RecordBatch::try_new(schema.clone(), cols).unwrap();
    write_parquet(&ds.table_file("offsets", "beam").unwrap(), schema, &[batch], &Default::default()).unwrap();
}

fn gauss(z: f64, mu: f64, s: f64) -> f64 {
    (-(z - mu) * (z - mu) / (2.0 * s * s)).exp()
}

/// A `tiles` table of two 1 km tiles under the shots of [`write_shots_and_sim`] (only the columns
/// the report's `tile_extents` reads).
#[allow(dead_code)]
pub fn write_tiles(ds: &Dataset) {
    let schema = Arc::new(Schema::new(vec![
        Field::new("tile", DataType::Utf8, false),
        Field::new("xmin", DataType::Float64, false),
        Field::new("ymin", DataType::Float64, false),
        Field::new("xmax", DataType::Float64, false),
        Field::new("ymax", DataType::Float64, false),
        Field::new("n_points", DataType::UInt64, false),
        Field::new("epsg", DataType::UInt32, false),
    ]));
    let f64s = |v: [f64; 2]| Arc::new(Float64Array::from(v.to_vec())) as ArrayRef;
    let b = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(StringArray::from(vec!["west", "east"])),
            f64s([899_900.0, 1_199_900.0]),
            f64s([6_399_900.0, 6_399_900.0]),
            f64s([900_900.0, 1_200_900.0]),
            f64s([6_400_900.0, 6_400_900.0]),
            Arc::new(UInt64Array::from(vec![1000, 1000])),
            Arc::new(UInt32Array::from(vec![2154, 2154])),
        ],
    )
    .unwrap();
    write_parquet(&ds.table_file("tiles", "t").unwrap(), schema, &[b], &Default::default()).unwrap();
}

/// Minimal `shots` and `sim` tables for the first `n` shots: positions around (5°E, 45°N), x, y in
/// two areas 300 km apart, a real waveform (ground + canopy Gaussians over noise 200 counts) and
/// three simulated ones.
pub fn write_shots_and_sim(ds: &Dataset, n: usize) {
    let list = || ListBuilder::new(Float32Builder::new());
    let (mut rx, mut sim_wave) = (list(), list());
    let (mut sn, mut lat, mut lon, mut bin0, mut last, mut count, mut noise, mut elev) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut fid, mut wt, mut st, mut z0s, mut dzs) = (vec![], vec![], vec![], vec![], vec![]);
    for i in 0..n {
        let (ground, h, _, _) = truth(i);
        let top = ground + GEOID + h + 15.0;
        let ns = 400u32;
        let dz = 0.15;
        sn.push(FIRST_SHOT + i as u64);
        lat.push(Some(45.0 + i as f64 * 1e-3));
        lon.push(Some(5.0 + i as f64 * 1e-3));
        bin0.push(top);
        last.push(top - dz * (ns - 1) as f64);
        count.push(ns);
        noise.push(200.0);
        elev.push(ground + GEOID + GROUND_OFFSET[0]);
        rx.append_value((0..ns).map(|k| {
            let z = top - k as f64 * dz;
            Some(
                (200.0 + 300.0 * gauss(z, ground + GEOID, 0.8) + 150.0 * gauss(z, ground + GEOID + 0.7 * h, 2.5))
                    as f32,
            )
        }));
        for (w, canopy) in [("count", 0.8), ("frac", 1.0), ("int", 1.2)] {
            let top = ground + h + 10.0;
            fid.push(format!("{}", FIRST_SHOT + i as u64));
            wt.push(w);
            st.push("ok");
            z0s.push(top);
            dzs.push(dz);
            let raw: Vec<f64> = (0..300)
                .map(|k| {
                    let z = top - k as f64 * dz;
                    gauss(z, ground, 0.7) + canopy * 0.5 * gauss(z, ground + 0.7 * h, 2.2)
                })
                .collect();
            let area: f64 = raw.iter().sum::<f64>() * dz;
            sim_wave.append_value(raw.iter().map(|v| Some((v / area) as f32)));
        }
    }
    let f64s = |v: Vec<f64>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let opt = |v: Vec<Option<f64>>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let none = |n: usize| opt(vec![None; n]);
    let lf = || DataType::List(Arc::new(Field::new_list_field(DataType::Float32, true)));
    let shots_schema = Arc::new(Schema::new(vec![
        Field::new("shot_number", DataType::UInt64, false),
        Field::new("beam", DataType::Utf8, false),
        Field::new("lat_lowestmode", DataType::Float64, true),
        Field::new("lon_lowestmode", DataType::Float64, true),
        Field::new("lat_bin0", DataType::Float64, true),
        Field::new("lon_bin0", DataType::Float64, true),
        Field::new("lat_lastbin", DataType::Float64, true),
        Field::new("lon_lastbin", DataType::Float64, true),
        Field::new("elevation_bin0", DataType::Float64, true),
        Field::new("elevation_lastbin", DataType::Float64, true),
        Field::new("rx_sample_count", DataType::UInt32, true),
        Field::new("rx_waveform", lf(), true),
        Field::new("noise_mean_corrected", DataType::Float64, true),
        Field::new("elev_lowestmode", DataType::Float64, true),
        Field::new("granule", DataType::Utf8, false),
        Field::new("x", DataType::Float64, true),
        Field::new("y", DataType::Float64, true),
    ]));
    let shots = RecordBatch::try_new(
        shots_schema.clone(),
        vec![
            Arc::new(UInt64Array::from(sn)),
            Arc::new((0..n).map(|i| Some(if i % 2 == 0 { "BEAM0000" } else { "BEAM0101" })).collect::<StringArray>()),
            opt(lat),
            opt(lon),
            none(n),
            none(n),
            none(n),
            none(n),
            f64s(bin0),
            f64s(last),
            Arc::new(UInt32Array::from(count)),
            Arc::new(rx.finish()),
            f64s(noise),
            f64s(elev),
            Arc::new((0..n).map(|_| Some("GEDI02_A_2019108080338_O01964_T05337_02_001_01")).collect::<StringArray>()),
            // Two areas 300 km apart (Lambert-93 metres), as shots on two tiles would be.
            f64s((0..n).map(|i| 900_000.0 + (i % 2) as f64 * 300_000.0 + i as f64 * 25.0).collect()),
            f64s((0..n).map(|i| 6_400_000.0 + i as f64 * 15.0).collect()),
        ],
    )
    .unwrap();
    write_parquet(&ds.table_file("shots", "s").unwrap(), shots_schema, &[shots], &Default::default()).unwrap();
    let sim_schema = Arc::new(Schema::new(vec![
        Field::new("footprint_id", DataType::Utf8, false),
        Field::new("weighting", DataType::Utf8, false),
        Field::new("status", DataType::Utf8, false),
        Field::new("z0", DataType::Float64, true),
        Field::new("dz", DataType::Float64, true),
        Field::new("wave", lf(), true),
    ]));
    let sim = RecordBatch::try_new(
        sim_schema.clone(),
        vec![
            Arc::new(StringArray::from(fid)),
            Arc::new(StringArray::from(wt)),
            Arc::new(StringArray::from(st)),
            f64s(z0s),
            f64s(dzs),
            Arc::new(sim_wave.finish()),
        ],
    )
    .unwrap();
    write_parquet(&ds.table_file("sim", "shots").unwrap(), sim_schema, &[sim], &Default::default()).unwrap();
}

/// Read every row of a Parquet file.
pub fn read(path: &Path) -> RecordBatch {
    let f = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let r = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f).unwrap().build().unwrap();
    let batches: Vec<RecordBatch> = r.map(|b| b.unwrap()).collect();
    arrow::compute::concat_batches(&batches[0].schema(), &batches).unwrap()
}
