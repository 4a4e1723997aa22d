//! The simulator as SQL (`gedi_simulate`, `gedi_rh`, `queries/simulated_rh.sql`) gives the same
//! numbers as the direct path and the kernels.

mod common;

use std::sync::Arc;

use arrow::array::{AsArray, Float64Array, RecordBatch, UInt64Array};
use arrow::datatypes::{DataType, Field, Float32Type, Float64Type, Schema};

use common::data;
use gedisim::dataset::{self, Dataset};
use gedisim::kernels::sim::{self, Footprint, Profile, SimConfig, Weighting};
use gedisim::ops::ingest_als::{ingest_tiles, AlsOptions};
use gedisim::ops::sql::SqlSession;
use gedisim::sql::Engine;

/// A dataset with one real tile and a `shots` table of 12 positions on it (plus one off it).
fn dataset() -> (tempfile::TempDir, Dataset, Vec<Footprint>) {
    let tmp = tempfile::tempdir().unwrap();
    let ds = Dataset::create(tmp.path()).unwrap();
    ingest_tiles(
        &ds,
        &[data("als/lidarforfuel_2_bas_lig.laz")],
        &AlsOptions::default(),
        &gedisim::ops::progress::NoProgress,
    )
    .unwrap();
    let mut fps = Vec::new();
    for i in 0..4 {
        for j in 0..3 {
            let id = 19_640_500_100_108_424u64 + (i * 3 + j) as u64;
            fps.push(Footprint::at(id.to_string(), 368500.0 + 18.0 * i as f64, 6807430.0 + 22.0 * j as f64));
        }
    }
    fps.push(Footprint::at("19640500100109999", 360000.0, 6800000.0));
    let schema = Arc::new(Schema::new(vec![
        Field::new("shot_number", DataType::UInt64, false),
        Field::new("x", DataType::Float64, true),
        Field::new("y", DataType::Float64, true),
    ]));
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(UInt64Array::from(fps.iter().map(|f| f.id.parse::<u64>().unwrap()).collect::<Vec<_>>())),
            Arc::new(Float64Array::from(fps.iter().map(|f| f.x).collect::<Vec<_>>())),
            Arc::new(Float64Array::from(fps.iter().map(|f| f.y).collect::<Vec<_>>())),
        ],
    )
    .unwrap();
    let dest = ds.table_file("shots", "test").unwrap();
    dataset::write_parquet(&dest, schema, &[batch], &Default::default()).unwrap();
    (tmp, ds, fps)
}

#[test]
fn sql_query_matches_the_direct_path_and_the_kernels() {
    let (_tmp, ds, fps) = dataset();
    let query = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/queries/simulated_rh.sql")).unwrap();
    let session = SqlSession::open(ds.root(), &Default::default(), &Engine::Local).unwrap();
    let batches = session.collect(&query).unwrap();
    let rows: usize = batches.iter().map(|b| b.num_rows()).sum();
    assert_eq!(rows, fps.len() * 3);

    // Direct path: every point of the tile minus the classes ingest drops, default profile.
    let points = gedisim::io::las::read_points(&data("als/lidarforfuel_2_bas_lig.laz")).unwrap();
    let points = gedisim::ops::simulate::drop_ingest_classes(&points);
    let direct = sim::simulate(&points, &fps, &SimConfig::new(Profile::Default)).unwrap();

    let mut compared = 0;
    for b in &batches {
        let shot = b.column_by_name("shot").unwrap().as_string::<i32>();
        let weighting = b.column_by_name("weighting").unwrap().as_string::<i32>();
        let status = b.column_by_name("status").unwrap().as_string::<i32>();
        let ground = b.column_by_name("als_ground").unwrap().as_primitive::<Float64Type>();
        let rh = b.column_by_name("rh").unwrap().as_list::<i32>();
        let rh2 = b.column_by_name("rh_from_wave").unwrap().as_list::<i32>();
        for i in 0..b.num_rows() {
            let k = fps.iter().position(|f| f.id == shot.value(i)).unwrap();
            let w = Weighting::ALL.iter().copied().find(|w| w.name() == weighting.value(i)).unwrap();
            match &direct[k] {
                Err(_) => assert_ne!(status.value(i), "ok", "{}", shot.value(i)),
                Ok(s) => {
                    assert_eq!(status.value(i), "ok");
                    let ww = s.get(w);
                    assert_eq!(Some(ground.value(i)), ww.truth.als_ground);
                    let sql_rh = rh.value(i);
                    let sql_rh: Vec<f32> = sql_rh.as_primitive::<Float32Type>().values().to_vec();
                    assert_eq!(sql_rh, ww.rh.unwrap().to_vec(), "{} {}", shot.value(i), w.name());
                    let from_wave = rh2.value(i);
                    assert_eq!(
                        from_wave.as_primitive::<Float32Type>().values().to_vec(),
                        sql_rh,
                        "gedi_rh agrees with the kernel"
                    );
                    compared += 1;
                }
            }
        }
    }
    println!("{compared} simulated rows compared (SQL vs direct path vs gedi_rh)");
    assert_eq!(compared, 12 * 3, "the 12 shots on the tile are simulated, the off-tile one is not");
}
