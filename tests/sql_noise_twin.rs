//! The noise twin in SQL: `gedi_noise_twin` / `gedi_link_margin_twin` make the same waveforms as
//! the kernels, are reproducible per seed, feed `gedi_l2a` in the same query, and report bad input
//! as a reason.

use std::sync::Arc;

use arrow::array::{Array, AsArray, Float32Builder, Float64Array, ListBuilder, RecordBatch, UInt64Array};
use arrow::datatypes::{DataType, Field, Float32Type, Float64Type, Schema};

use gedisim::dataset::{self, Dataset};
use gedisim::kernels::waveform::l2a::{AlgorithmSettings, L2aProcessor, Noise, WaveformGeolocation};
use gedisim::kernels::waveform::noise_twin::{LinkMarginTwin, NoiseShape, ShotTwin, GEDI_BIN_M};
use gedisim::ops::sql::SqlSession;
use gedisim::sql::Engine;

const DZ: f64 = 0.15;
const Z0: f64 = 350.0;
const GROUND_BIN: f64 = 230.0;

/// A canopy and a ground return on 0.15 m bins, as the simulator writes them.
fn sim_wave() -> Vec<f32> {
    (0..300)
        .map(|i| {
            let z = i as f32;
            0.3 * (-0.5 * ((z - 100.0) / 15.0).powi(2)).exp() + (-0.5 * ((z - GROUND_BIN as f32) / 6.0).powi(2)).exp()
        })
        .collect()
}

/// A dataset with a table `waves(id, wave, z0, dz, seed)` (not one of gedisim's tables, whose files
/// hold only their own columns): rows 0, 1 the same waveform (seeds 41, 42), row 2 empty, row 3 null.
fn dataset() -> (tempfile::TempDir, Dataset) {
    let tmp = tempfile::tempdir().unwrap();
    let ds = Dataset::create(tmp.path()).unwrap();
    let mut list = ListBuilder::new(Float32Builder::new());
    let w = sim_wave();
    list.append_value(w.iter().map(|&v| Some(v)));
    list.append_value(w.iter().map(|&v| Some(v)));
    list.append_value(Vec::<Option<f32>>::new());
    list.append_null();
    let schema = Arc::new(Schema::new(vec![
        Field::new("id", DataType::UInt64, false),
        Field::new("wave", gedisim::dataset::list_f32(), true),
        Field::new("z0", DataType::Float64, false),
        Field::new("dz", DataType::Float64, false),
        Field::new("seed", DataType::UInt64, false),
    ]));
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(UInt64Array::from(vec![0, 1, 2, 3])),
            Arc::new(list.finish()),
            Arc::new(Float64Array::from(vec![Z0; 4])),
            Arc::new(Float64Array::from(vec![DZ; 4])),
            Arc::new(UInt64Array::from(vec![41, 42, 43, 44])),
        ],
    )
    .unwrap();
    dataset::write_parquet(&ds.table_file("waves", "test").unwrap(), schema, &[batch], &Default::default()).unwrap();
    (tmp, ds)
}

fn query(ds: &Dataset, sql: &str) -> Vec<RecordBatch> {
    let session = SqlSession::open(ds.root(), &Default::default(), &Engine::Local).unwrap();
    session.collect(sql).unwrap_or_else(|e| panic!("{sql}: {e}"))
}

/// Twin then L2A a1 on it, in one query; `twin` is the twin call with `seed` as its seed.
fn twin_then_l2a(twin: &str) -> String {
    format!(
        "with t as (select id, {twin} as tw from waves) \
         select id, tw, gedi_l2a(tw['rxwaveform'], tw['noise_mean'], tw['noise_stddev'], 1, \
                                 tw['elevation_bin0'], tw['elevation_lastbin']) as l2a \
         from t order by id"
    )
}

fn waves(b: &RecordBatch) -> Vec<Option<Vec<f32>>> {
    let tw = b.column_by_name("tw").unwrap().as_struct();
    let w = tw.column_by_name("rxwaveform").unwrap().as_list::<i32>();
    (0..b.num_rows())
        .map(|i| (!w.is_null(i)).then(|| w.value(i).as_primitive::<Float32Type>().values().to_vec()))
        .collect()
}

fn reasons(b: &RecordBatch, col: &str) -> Vec<Option<String>> {
    let s = b.column_by_name(col).unwrap().as_struct();
    let r = s.column_by_name("no_result_reason").unwrap().as_string::<i32>();
    (0..b.num_rows()).map(|i| (!r.is_null(i)).then(|| r.value(i).to_string())).collect()
}

#[test]
fn shot_twin_in_sql_is_the_kernel_seeded_and_processed_by_gedi_l2a() {
    let (_tmp, ds) = dataset();
    let call = "gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 3.0, 1000, 150, seed)";
    let first = query(&ds, &twin_then_l2a(call));
    let again = query(&ds, &twin_then_l2a(call));
    assert_eq!(first, again, "same seed, same twin and same L2A");
    let b = &first[0];
    let w = waves(b);
    assert_ne!(w[0], w[1], "another seed, another noise draw");

    // The kernel, called directly, gives the same waveform bit for bit.
    let sim: Vec<f64> = sim_wave().iter().map(|&v| f64::from(v)).collect();
    let twin = ShotTwin {
        energy_total: 20000.0,
        noise: Noise { mean: 220.0, stddev: 3.0 },
        sample_count: 1000,
        tx_pulse: None,
        quantum: 0.0,
        noise_shape: NoiseShape::GEDI_V1,
    };
    let made = twin.apply(&sim, DZ, 150, 41).unwrap();
    assert_eq!(w[0].as_deref(), Some(made.wave.as_slice()));

    // gedi_l2a on the twin: the ground of the simulation, in the simulation's heights.
    let tw = b.column_by_name("tw").unwrap().as_struct();
    let bin0 = tw.column_by_name("elevation_bin0").unwrap().as_primitive::<Float64Type>();
    let last = tw.column_by_name("elevation_lastbin").unwrap().as_primitive::<Float64Type>();
    assert!((bin0.value(0) - (Z0 + 150.0 * GEDI_BIN_M)).abs() < 1e-9);
    assert!((bin0.value(0) - last.value(0) - 999.0 * GEDI_BIN_M).abs() < 1e-9);
    let l2a = b.column_by_name("l2a").unwrap().as_struct();
    let elev = l2a.column_by_name("elev_lowestmode").unwrap().as_primitive::<Float64Type>();
    let ground = Z0 - GROUND_BIN * DZ;
    for i in 0..2 {
        assert!((elev.value(i) - ground).abs() < 0.3, "row {i}: ground {} vs {ground}", elev.value(i));
    }
    let geo = WaveformGeolocation::vertical(1000, bin0.value(0), last.value(0));
    let direct = L2aProcessor::new().process(&made.wave, made.noise, &geo, &AlgorithmSettings::a1()).unwrap();
    assert_eq!(elev.value(0), direct.elev_lowestmode);

    // Bad input: an empty simulation gives a reason, a null one a null struct.
    let r = reasons(b, "tw");
    assert_eq!(r[..2], [None, None]);
    assert_eq!(r[2].as_deref(), Some("empty simulated waveform"));
    assert!(tw.is_null(3) && l2a.is_null(3));
}

#[test]
fn shot_twin_bad_parameters_give_reasons() {
    let (_tmp, ds) = dataset();
    let cases = [
        (
            "gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 3.0, 100, 150, seed)",
            "has energy outside a record of 100 samples",
        ),
        ("gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 3.0, -5, 0, seed)", "invalid value for sample_count"),
        (
            "gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 3.0, 1000, -1, seed)",
            "has energy outside a record of 1000 samples",
        ),
        ("gedi_noise_twin(wave, z0, dz, -1.0, 220.0, 3.0, 1000, 0, seed)", "invalid value for energy_total"),
        ("gedi_noise_twin(wave, z0, 0.0, 20000.0, 220.0, 3.0, 1000, 0, seed)", "invalid value for input_bin_m"),
        ("gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 3.0, 1000, 0, seed, -1.0)", "invalid value for quantum"),
        (
            "gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 3.0, 1000, 0, seed, 0.0, -1.0, 0.5)",
            "invalid value for noise_shape",
        ),
    ];
    for (call, reason) in cases {
        let r = reasons(&query(&ds, &format!("select {call} as tw from waves order by id"))[0], "tw");
        assert!(r[0].as_deref().is_some_and(|s| s.contains(reason)), "{call}: {r:?}");
    }
    // σ = 0: the twin is made (noise-free); L2A then reports the invalid noise, no panic.
    let b = &query(&ds, &twin_then_l2a("gedi_noise_twin(wave, z0, dz, 20000.0, 220.0, 0.0, 1000, 150, seed)"))[0];
    assert_eq!(reasons(b, "tw")[0], None);
    assert_eq!(reasons(b, "l2a")[0].as_deref(), Some("invalid noise statistics (mean not finite or stddev not > 0)"));
}

#[test]
fn link_margin_twin_in_sql_is_the_kernel() {
    let (_tmp, ds) = dataset();
    let b = &query(&ds, &twin_then_l2a("gedi_link_margin_twin(wave, z0, dz, 5.0, 0.5, seed)"))[0];
    let w = waves(b);
    let sim: Vec<f64> = sim_wave().iter().map(|&v| f64::from(v)).collect();
    let made = LinkMarginTwin::new(5.0, 0.5).apply(&sim, DZ, 41).unwrap();
    assert_eq!(w[0].as_deref(), Some(made.wave.as_slice()));
    assert_ne!(w[0], w[1]);
    let l2a = b.column_by_name("l2a").unwrap().as_struct();
    let elev = l2a.column_by_name("elev_lowestmode").unwrap().as_primitive::<Float64Type>();
    assert!((elev.value(0) - (Z0 - GROUND_BIN * DZ)).abs() < 0.3, "{}", elev.value(0));
    let r =
        reasons(&query(&ds, "select gedi_link_margin_twin(wave, z0, dz, 5.0, 1.0, seed) as tw from waves")[0], "tw");
    assert_eq!(r[0].as_deref(), Some("invalid value for cover"));
}

mod common;

/// `queries/simulated_l2a.sql`: simulations of 12 positions on a real tile, each given the noise
/// twin of a real shot (its energy, noise and record length), processed by L2A a1–a6 in one query.
#[test]
fn simulated_l2a_query_processes_twins_of_simulations() {
    use arrow::array::UInt32Array;
    let tmp = tempfile::tempdir().unwrap();
    let ds = Dataset::create(tmp.path()).unwrap();
    let tile = common::data("als/lidarforfuel_2_bas_lig.laz");
    gedisim::ops::ingest_als::ingest_tiles(&ds, &[tile], &Default::default(), &gedisim::ops::progress::NoProgress)
        .unwrap();
    let real = common::nasa::load_real_shots();
    let n = 12;
    let pos = |k: usize| (368500.0 + 18.0 * (k / 3) as f64, 6807430.0 + 22.0 * (k % 3) as f64);
    let shots = |ground: &dyn Fn(usize) -> f64| {
        let schema = Arc::new(Schema::new(vec![
            Field::new("shot_number", DataType::UInt64, false),
            Field::new("x", DataType::Float64, true),
            Field::new("y", DataType::Float64, true),
            Field::new("energy_total", DataType::Float64, true),
            Field::new("noise_mean_corrected", DataType::Float64, true),
            Field::new("noise_stddev_corrected", DataType::Float64, true),
            Field::new("rx_sample_count", DataType::UInt32, true),
            Field::new("elevation_bin0", DataType::Float64, true),
            Field::new("geoid_offset_used", DataType::Float64, true),
        ]));
        let f64s = |f: &dyn Fn(usize) -> f64| Arc::new(Float64Array::from((0..n).map(f).collect::<Vec<_>>()));
        let batch = RecordBatch::try_new(
            schema.clone(),
            vec![
                Arc::new(UInt64Array::from((0..n).map(|k| real[k].shot_number).collect::<Vec<_>>())),
                f64s(&|k| pos(k).0),
                f64s(&|k| pos(k).1),
                f64s(&|k| real[k].energy_total),
                f64s(&|k| real[k].noise.mean),
                f64s(&|k| real[k].noise.stddev),
                Arc::new(UInt32Array::from((0..n).map(|k| real[k].wave.len() as u32).collect::<Vec<_>>())),
                // The real shot's record top lies as far above its own ground as here (N = 20 m).
                f64s(&|k| {
                    ground(k) + 20.0 + (real[k].geo.elevation_bin0 - real[k].geo.elevation_at(real[k].nasa[0].zcross))
                }),
                f64s(&|_| 20.0),
            ],
        )
        .unwrap();
        dataset::write_parquet(&ds.table_file("shots", "test").unwrap(), schema, &[batch], &Default::default())
            .unwrap();
    };
    // First the positions alone, to know each footprint's ALS ground.
    shots(&|_| 0.0);
    let grounds = query(&ds, "select footprint_id, als_ground from gedi_simulate('default') where weighting = 'count'");
    let mut ground = vec![f64::NAN; n];
    for b in &grounds {
        let id = b.column_by_name("footprint_id").unwrap().as_string::<i32>();
        let g = b.column_by_name("als_ground").unwrap().as_primitive::<Float64Type>();
        for i in 0..b.num_rows() {
            let k = (0..n).find(|&k| real[k].shot_number.to_string() == id.value(i)).unwrap();
            ground[k] = g.value(i);
        }
    }
    shots(&|k| ground[k]);

    let sql = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/queries/simulated_l2a.sql")).unwrap();
    let first = query(&ds, &sql);
    assert_eq!(first, query(&ds, &sql), "seeded by shot number: the same rows again");
    let (mut rows, mut processed, mut near) = (0, 0, 0);
    for b in &first {
        let twin_reason = b.column_by_name("twin_reason").unwrap().as_string::<i32>();
        let reason = b.column_by_name("no_result_reason").unwrap().as_string::<i32>();
        let ground = b.column_by_name("als_ground").unwrap().as_primitive::<Float64Type>();
        let elev = b.column_by_name("elev_lowestmode").unwrap().as_primitive::<Float64Type>();
        for i in 0..b.num_rows() {
            rows += 1;
            assert!(twin_reason.is_null(i), "twin made: {}", twin_reason.value(i));
            if reason.is_null(i) {
                processed += 1;
                let d = elev.value(i) - ground.value(i);
                near += usize::from(d.abs() <= 1.0);
            }
        }
    }
    println!(
        "simulated_l2a.sql: {rows} rows, {processed} processed, {near} with the ground within 1 m of the ALS ground"
    );
    assert_eq!(rows, n * 6);
    assert_eq!(processed, rows, "every twin is processed by every algorithm");
    assert_eq!(near, processed, "the L2A ground of each twin is the simulation's ground");
}
