//! COPC tiles written by another tool (copclib, tests/data/als-copc/PROVENANCE.md) read through
//! their hierarchy: every point of the LAZ original when the whole tile is asked for, exactly the
//! points of the cells asked for otherwise, decoding fewer nodes than the tile holds.

mod common;

use std::path::{Path, PathBuf};

use common::{data, TILES};
use gedisim::io::copc::{Attributes, CopcTile};
use gedisim::io::las::read_points;
use gedisim::kernels::geo::cells::Cells;
use gedisim::kernels::sim::AlsPoints;

/// A point as a comparable record: coordinates on the 1 cm grid, GPS time bits, intensity, return
/// number, number of returns, class, point source, scan angle in m°.
type Record = (i64, i64, i64, u64, u16, u8, u8, u8, u16, i32);

/// Every point as a record, sorted.
fn canonical(p: &AlsPoints) -> Vec<Record> {
    let mut v: Vec<_> = (0..p.len())
        .map(|i| {
            (
                (p.x[i] * 100.0).round() as i64,
                (p.y[i] * 100.0).round() as i64,
                (p.z[i] * 100.0).round() as i64,
                p.gps_time[i].to_bits(),
                p.intensity[i],
                p.return_number[i],
                p.number_of_returns[i],
                p.classification[i],
                p.point_source_id[i],
                (p.scan_angle_deg[i] * 1000.0).round() as i32,
            )
        })
        .collect();
    v.sort_unstable();
    v
}

fn in_cells(p: &AlsPoints, cells: &Cells) -> AlsPoints {
    let keep: Vec<u32> = (0..p.len() as u32).filter(|&i| cells.contains(p.x[i as usize], p.y[i as usize])).collect();
    p.permuted(&keep)
}

/// Footprint-sized squares (18.4 m: the simulation's read radius) around three positions of a tile.
fn some_cells(p: &AlsPoints) -> Cells {
    let (x0, y0) =
        (p.x.iter().copied().fold(f64::INFINITY, f64::min), p.y.iter().copied().fold(f64::INFINITY, f64::min));
    Cells::around([(x0 + 12.0, y0 + 15.0), (x0 + 31.0, y0 + 40.0), (x0 + 70.0, y0 + 80.0)], 18.4)
}

/// Every row of a Parquet file, as one batch.
fn read_table(path: &Path) -> arrow::record_batch::RecordBatch {
    let file = std::fs::File::open(path).unwrap();
    let r = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap();
    let batches: Vec<_> = r.build().unwrap().map(|b| b.unwrap()).collect();
    arrow::compute::concat_batches(&batches[0].schema(), &batches).unwrap()
}

#[test]
fn a_whole_copc_tile_holds_the_points_of_its_laz_original() {
    for tile in TILES {
        let laz = read_points(&data(&format!("als/{tile}.laz"))).unwrap();
        let copc = CopcTile::open(&data(&format!("als-copc/{tile}.copc.laz"))).unwrap();
        assert!(copc.header().copc, "{tile}: the COPC info VLR is found");
        let (points, read) = copc.read(None, Attributes::All).unwrap();

        assert_eq!(read.nodes, read.nodes_in_tile);
        assert_eq!(read.points_decoded, laz.len() as u64);
        assert!(canonical(&points) == canonical(&laz), "{tile}: the COPC points differ from the LAZ points");
    }
}

#[test]
fn the_cells_asked_for_are_read_and_only_their_nodes_decoded() {
    let cases = [
        // copclib files with an info VLR that records no cube (zeros): the cube is taken from the
        // header bounds, and checked against every decoded point.
        ("als-copc/lidarforfuel_1_42.copc.laz", "als/lidarforfuel_1_42.laz", true),
        ("als-copc/lidarforfuel_2_bas_lig.copc.laz", "als/lidarforfuel_2_bas_lig.laz", true),
        // Depth 6, 29 hierarchy pages, the cube recorded.
        (
            "als-copc/pdal-ign-plugin_mnx_input_crop_2.depth6-paged.copc.laz",
            "als/pdal-ign-plugin_mnx_input_crop_2.laz",
            false,
        ),
    ];
    for (copc, laz, inferred) in cases {
        let laz = read_points(&data(laz)).unwrap();
        let tile = CopcTile::open(&data(copc)).unwrap();
        assert_eq!(tile.cube_inferred(), inferred, "{copc}");
        let cells = some_cells(&laz);
        let (points, read) = tile.read(Some(&cells), Attributes::All).unwrap();
        let want = in_cells(&laz, &cells);
        assert!(!want.is_empty() && want.len() < laz.len());
        assert!(
            canonical(&points) == canonical(&want),
            "{copc}: {} points read, {} in the cells",
            points.len(),
            want.len()
        );
        assert!(!read.read_whole, "{copc}: the node bounds hold");
        assert!(read.nodes < read.nodes_in_tile, "{copc}: {} of {} nodes decoded", read.nodes, read.nodes_in_tile);
        assert!(read.points_decoded < read.points_in_tile);
        eprintln!(
            "{copc}: {} of {} nodes, {} of {} points decoded, {} kept",
            read.nodes, read.nodes_in_tile, read.points_decoded, read.points_in_tile, read.points_kept
        );
        assert_eq!(read.points_kept, want.len() as u64);
    }
}

#[test]
fn a_read_without_the_pulse_identity_skips_gps_time_and_point_source_only() {
    let tile = CopcTile::open(&data("als-copc/lidarforfuel_2_bas_lig.copc.laz")).unwrap();
    let (all, _) = tile.read(None, Attributes::All).unwrap();
    let (some, _) = tile.read(None, Attributes::WithoutPulseIdentity).unwrap();
    assert!(some.gps_time.iter().all(|t| t.is_nan()) && some.point_source_id.iter().all(|&s| s == 0));
    assert!(all.gps_time.iter().all(|t| t.is_finite()) && all.point_source_id.iter().any(|&s| s != 0));
    let strip = |p: &AlsPoints| {
        let mut p = p.clone();
        p.gps_time.fill(0.0);
        p.point_source_id.fill(0);
        p
    };
    assert!(strip(&all) == strip(&some), "every other attribute decoded alike");
}

#[test]
fn a_cube_that_cannot_be_inferred_costs_a_whole_read_not_a_point() {
    // copclib file whose octree cube has its corner at the bounds' minimum (0.46 m off the centred
    // cube that is inferred) and is not recorded in the info VLR.
    let laz = read_points(&data("als/pdal-ign-plugin_mnx_input_crop_2.laz")).unwrap();
    let tile =
        CopcTile::open(&data("als-copc/pdal-ign-plugin_mnx_input_crop_2.corner-cube-unrecorded.copc.laz")).unwrap();
    assert!(tile.cube_inferred());
    let cells = some_cells(&laz);
    let (points, read) = tile.read(Some(&cells), Attributes::All).unwrap();
    assert!(read.read_whole, "a point outside its inferred node is found");
    assert_eq!(read.nodes, read.nodes_in_tile);
    assert!(canonical(&points) == canonical(&in_cells(&laz, &cells)));
}

#[test]
fn header_bounds_that_say_nothing_cost_a_whole_read_not_a_point() {
    // The small copclib tile with its header's maximum x made NaN: the recorded cube no longer holds
    // the bounds, and a cube inferred from them is not finite, so it can select no node.
    let mut bytes = std::fs::read(data("als-copc/small-4000.depth3-paged.copc.laz")).unwrap();
    bytes[179..187].copy_from_slice(&f64::NAN.to_le_bytes()); // max x (LAS 1.4 header)
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nan-bounds.copc.laz");
    std::fs::write(&path, &bytes).unwrap();
    let good = CopcTile::open(&data("als-copc/small-4000.depth3-paged.copc.laz")).unwrap();
    let (all, _) = good.read(None, Attributes::All).unwrap();
    let cells = some_cells(&all);
    let tile = CopcTile::open(&path).unwrap();
    let (points, read) = tile.read(Some(&cells), Attributes::All).unwrap();
    assert!(read.read_whole);
    assert!(canonical(&points) == canonical(&in_cells(&all, &cells)));
}

#[test]
fn a_plain_laz_file_is_not_taken_for_copc() {
    let e = CopcTile::open(&data("als/lidarforfuel_1_42.laz")).unwrap_err().to_string();
    assert!(e.contains("COPC info VLR") && e.contains("lidarforfuel_1_42.laz"), "{e}");
}

#[test]
fn simulate_from_copc_equals_simulate_from_the_laz_original() {
    use arrow::array::Array;
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("plots.csv");
    std::fs::write(&csv, "id,x,y\na,817600,6460800\nb,817640,6460830\nc,817575,6460850\n").unwrap();
    let mut tables = Vec::new();
    for (name, als) in [("laz", "als/lidarforfuel_1_42.laz"), ("copc", "als-copc/lidarforfuel_1_42.copc.laz")] {
        let out = dir.path().join(format!("{name}.parquet"));
        let (ok, _, err) = common::gedisim(&[
            "simulate",
            "--als",
            data(als).to_str().unwrap(),
            "--footprints",
            csv.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        assert_eq!(err.contains("COPC: "), name == "copc", "{err}");
        tables.push(read_table(&out));
    }
    let (laz, copc) = (&tables[0], &tables[1]);
    assert_eq!(laz.num_rows(), 9);
    // Every column, the mean scan angle too (summed in f64: the tiles store their points in different orders).
    for (i, field) in laz.schema().fields().iter().enumerate() {
        assert_eq!(laz.column(i).to_data(), copc.column(i).to_data(), "column {}", field.name());
    }
}

#[test]
fn simulate_reads_several_tiles_and_skips_those_no_footprint_reaches() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("plots.csv");
    // Two plots on lidarforfuel_1_42, one on pdal-ign-plugin_mnx_input_crop_2 (600 km away), listed
    // between them: the tiles are taken one at a time.
    std::fs::write(&csv, "id,x,y\na,817600,6460800\nc,689425,6735475\nb,817640,6460830\n").unwrap();
    let table = |als: &[PathBuf], name: &str| {
        let out = dir.path().join(name);
        let mut args = vec!["simulate".to_string(), "--footprints".into(), csv.to_string_lossy().into_owned()];
        args.extend(["--out".to_string(), out.to_string_lossy().into_owned(), "--als".into()]);
        args.extend(als.iter().map(|p| p.to_string_lossy().into_owned()));
        let (ok, _, err) = common::gedisim(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(ok, "{err}");
        (read_table(&out), err)
    };
    let copc = data("als-copc/lidarforfuel_1_42.copc.laz");
    let far = data("als-copc/pdal-ign-plugin_mnx_input_crop_2.depth6-paged.copc.laz");
    let other = data("als-copc/lidarforfuel_2_bas_lig.copc.laz");
    // The tile no plot reaches adds its nodes to the count, none decoded.
    let nodes: usize = [&copc, &far, &other].iter().map(|f| CopcTile::open(f).unwrap().node_count()).sum();
    let (both, err) = table(&[copc.clone(), far.clone(), other], "both.parquet");
    assert!(err.contains(&format!(" of {nodes} octree nodes")), "{err}");
    // Each plot simulated as from its own tile alone.
    let (one, _) = table(&[copc], "one.parquet");
    let (two, _) = table(&[far], "two.parquet");
    let status = |b: &arrow::record_batch::RecordBatch| {
        use arrow::array::AsArray;
        let c = b.column_by_name("status").unwrap().as_string::<i32>();
        (0..b.num_rows()).map(|i| c.value(i).to_string()).collect::<Vec<_>>()
    };
    let ids = |b: &arrow::record_batch::RecordBatch| {
        use arrow::array::AsArray;
        let c = b.column_by_name("footprint_id").unwrap().as_string::<i32>();
        (0..b.num_rows()).step_by(3).map(|i| c.value(i).to_string()).collect::<Vec<_>>()
    };
    // Tile after tile (written as they come), in the CSV's order within a tile.
    assert_eq!(ids(&both), ["a", "b", "c"]);
    // Alone, each tile's run has its own plots first, then those no tile holds.
    assert_eq!(ids(&one), ["a", "b", "c"]);
    assert_eq!(ids(&two), ["c", "a", "b"]);
    let (sb, s1, s2) = (status(&both), status(&one), status(&two));
    assert_eq!(sb.len(), 9);
    assert!(sb.iter().all(|s| s == "ok"), "{sb:?}");
    // Each plot's rows as from its own tile alone: a and b (rows 0–5) as in the first tile's run,
    // c (rows 6–8) as in the far tile's, where it comes first.
    let rh = |b: &arrow::record_batch::RecordBatch, r: usize| b.column_by_name("rh").unwrap().slice(r, 1).to_data();
    let alone = [
        (&one, &s1, 0),
        (&one, &s1, 1),
        (&one, &s1, 2),
        (&one, &s1, 3),
        (&one, &s1, 4),
        (&one, &s1, 5),
        (&two, &s2, 0),
        (&two, &s2, 1),
        (&two, &s2, 2),
    ];
    for (r, (batch, statuses, k)) in alone.into_iter().enumerate() {
        assert_eq!(sb[r], statuses[k], "row {r}");
        assert_eq!(rh(&both, r), rh(batch, k), "row {r}");
    }
}

/// Two granules of a world over the COPC tile, and their runs: the first alone, then both.
mod dataset_path {
    use super::*;
    use arrow::array::{Array, AsArray};
    use arrow::datatypes::{Float64Type, UInt64Type};
    use gedisim::dataset::als::DROPPED_CLASSES;
    use gedisim::ops::collocate::CollocateOptions;
    use gedisim::ops::ingest_als::TileOutcome;
    use gedisim::ops::progress::NoProgress;
    use gedisim::ops::run::{run_study, RunOptions, RunReport};
    use std::path::{Path, PathBuf};

    const COPC: &str = "als-copc/lidarforfuel_1_42.copc.laz";
    const LAZ: &str = "als/lidarforfuel_1_42.laz";

    fn run(ds: &Path, als: &str, granules: &[PathBuf]) -> RunReport {
        let opts = RunOptions {
            als: vec![data(als)],
            l1b: granules.iter().filter(|f| f.to_string_lossy().contains("GEDI01_B")).cloned().collect(),
            l2a: granules.iter().filter(|f| f.to_string_lossy().contains("GEDI02_A")).cloned().collect(),
            collocate: CollocateOptions { min_segment: 1, ..CollocateOptions::default() },
            ..RunOptions::new(ds)
        };
        run_study(&opts, &NoProgress).unwrap()
    }

    fn table(ds: &Path, name: &str) -> Vec<(PathBuf, arrow::record_batch::RecordBatch)> {
        common::files_with_suffix(&ds.join(name), ".parquet").into_iter().map(|f| (f.clone(), read_table(&f))).collect()
    }

    /// The cells the tile was read in, from its `tiles/` row.
    fn read_cells(ds: &Path) -> Cells {
        let (_, row) = table(ds, "tiles").pop().unwrap();
        let text = row.column_by_name("read_window").unwrap().as_string::<i32>().value(0).to_string();
        let cells = Cells::parse(&text, 1 << 20).unwrap();
        let n = row.column_by_name("read_cells").unwrap().as_primitive::<UInt64Type>().value(0);
        assert_eq!(n as usize, cells.len());
        cells
    }

    /// The points of the LAZ original the ingest keeps (classes not dropped) inside `cells`.
    fn laz_points_in(cells: &Cells) -> Vec<Record> {
        let all = read_points(&data(LAZ)).unwrap();
        let keep: Vec<u32> = (0..all.len() as u32)
            .filter(|&i| !DROPPED_CLASSES.contains(&all.classification[i as usize]))
            .filter(|&i| cells.contains(all.x[i as usize], all.y[i as usize]))
            .collect();
        canonical(&all.permuted(&keep))
    }

    fn als_points(ds: &Path) -> Vec<Record> {
        let mut p = AlsPoints::default();
        for f in common::files_with_suffix(&ds.join("als"), ".parquet") {
            p.extend_from(&gedisim::dataset::als::read_file_points(&f).unwrap());
        }
        canonical(&p)
    }

    /// The same columns, the mean scan angle too (summed in f64: the tiles store their points in different orders).
    fn assert_same_columns(a: &arrow::record_batch::RecordBatch, b: &arrow::record_batch::RecordBatch) {
        assert_eq!(a.schema(), b.schema());
        for (i, field) in a.schema().fields().iter().enumerate() {
            assert_eq!(a.column(i).to_data(), b.column(i).to_data(), "column {}", field.name());
        }
    }

    /// `simulate --dataset` at `positions`, as one batch.
    fn simulate_at(dir: &Path, ds: &Path, positions: &[(f64, f64)]) -> arrow::record_batch::RecordBatch {
        let csv = dir.join("at.csv");
        let rows: Vec<String> = positions.iter().enumerate().map(|(i, (x, y))| format!("p{i},{x},{y}")).collect();
        std::fs::write(&csv, format!("id,x,y\n{}\n", rows.join("\n"))).unwrap();
        let out = dir.join(format!("{}.parquet", ds.file_name().unwrap().to_string_lossy()));
        let args = ["simulate", "--dataset", ds.to_str().unwrap(), "--footprints", csv.to_str().unwrap()];
        let (ok, _, err) = common::gedisim(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
        assert!(ok, "{err}");
        read_table(&out)
    }

    #[test]
    fn a_run_reads_copc_only_around_its_shots_tops_up_later_and_simulates_as_from_the_whole_laz() {
        let tmp = tempfile::tempdir().unwrap();
        let world = tmp.path().join("world");
        let (ok, _, err) = common::gedisim(&[
            "scenario",
            "--effect",
            "none",
            "--als",
            data(LAZ).to_str().unwrap(),
            "--passes",
            "2",
            "--seed",
            "3",
            "--out",
            world.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        let all = common::files_with_suffix(&world.join("gedi"), ".h5");
        assert_eq!(all.len(), 4);
        let stamp = |f: &PathBuf| f.file_name().unwrap().to_string_lossy().split('_').nth(2).unwrap().to_string();
        let first: Vec<PathBuf> = all.iter().filter(|f| stamp(f) == stamp(&all[0])).cloned().collect();

        // The first granule: the tile is read around its shots only.
        let ds = tmp.path().join("copc");
        let r1 = run(&ds, COPC, &first);
        let TileOutcome::Ingested { window: Some(w1), .. } = &r1.tiles[0] else { panic!("{:?}", r1.tiles) };
        let cells1 = read_cells(&ds);
        assert_eq!((w1.cells_new, w1.cells_read), (cells1.len(), cells1.len()));
        assert!(w1.copc.nodes < w1.copc.nodes_in_tile, "{w1:?}");
        assert!(cells1.len() < 100, "a 100 m tile holds 100 to 121 cells; {} read", cells1.len());
        let points1 = als_points(&ds);
        assert_eq!(points1, laz_points_in(&cells1), "exactly the original's points of the cells read");

        // Both granules: only the cells still missing are read, and no point twice.
        let r2 = run(&ds, COPC, &all);
        let TileOutcome::Ingested { window: Some(w2), points, .. } = &r2.tiles[0] else { panic!("{:?}", r2.tiles) };
        let cells2 = read_cells(&ds);
        assert!(w2.cells_new > 0 && w2.cells_read == cells2.len() && cells2.len() == cells1.len() + w2.cells_new);
        assert_eq!(cells2.without(&cells1).len(), w2.cells_new);
        let points2 = als_points(&ds);
        assert_eq!(points2, laz_points_in(&cells2));
        assert_eq!(points2.len() as u64, points1.len() as u64 + points);

        // Nothing new: nothing read or rewritten.
        let als_file = common::files_with_suffix(&ds.join("als"), ".parquet").pop().unwrap();
        let mtime = std::fs::metadata(&als_file).unwrap().modified().unwrap();
        let r3 = run(&ds, COPC, &all);
        assert!(matches!(r3.tiles[0], TileOutcome::AlreadyIngested { .. }), "{:?}", r3.tiles);
        assert_eq!(std::fs::metadata(&als_file).unwrap().modified().unwrap(), mtime);

        // The whole LAZ tile: the same segments collocated (to float summation order: the tiles
        // store their points in different orders), and at the same positions the same waveforms
        // and metrics.
        let whole = tmp.path().join("laz");
        let r = run(&whole, LAZ, &all);
        assert!(matches!(&r.tiles[0], TileOutcome::Ingested { window: None, .. }));
        assert!(r.shots_simulated() > 0 && r.shots_simulated() == r1.shots_simulated() + r2.shots_simulated());
        let offsets = |ds: &Path| {
            let b = table(ds, "offsets").pop().unwrap().1;
            let f = |c: &str| b.column_by_name(c).unwrap().as_primitive::<Float64Type>().clone();
            let (id, dx, dy, dz) =
                (b.column_by_name("segment_id").unwrap().as_string::<i32>(), f("dx"), f("dy"), f("dz"));
            let rows = (0..b.num_rows()).map(|i| (id.value(i).to_string(), [dx.value(i), dy.value(i), dz.value(i)]));
            rows.collect::<std::collections::BTreeMap<_, _>>()
        };
        let (oa, ob) = (offsets(&ds), offsets(&whole));
        assert!(!oa.is_empty() && oa.keys().eq(ob.keys()), "{oa:?} {ob:?}");
        for (k, a) in &oa {
            assert!(a.iter().zip(ob[k]).all(|(a, b)| (a - b).abs() < 1e-3), "{k}: {a:?} {:?}", ob[k]);
        }
        let mut positions = Vec::new();
        for (_, b) in table(&ds, "sim") {
            let (x, y) = (b.column_by_name("x").unwrap(), b.column_by_name("y").unwrap());
            let (x, y) = (x.as_primitive::<Float64Type>(), y.as_primitive::<Float64Type>());
            positions.extend((0..b.num_rows()).map(|i| (x.value(i), y.value(i))));
        }
        positions.dedup();
        assert!(positions.len() >= 5, "{positions:?}");
        assert_same_columns(&simulate_at(tmp.path(), &ds, &positions), &simulate_at(tmp.path(), &whole, &positions));

        // A footprint where the tile was not read is refused, naming the file.
        let csv = tmp.path().join("plots.csv");
        let missing =
            (0..100).map(|k| (817572.0 + 10.0 * (k % 10) as f64 + 5.0, 6460768.0 + 10.0 * (k / 10) as f64 + 5.0));
        let (x, y) = missing.into_iter().find(|&(x, y)| !cells2.contains(x, y)).expect("a cell not read");
        std::fs::write(&csv, format!("id,x,y\nfar,{x},{y}\n")).unwrap();
        let (ok, _, err) = common::gedisim(&[
            "simulate",
            "--dataset",
            ds.to_str().unwrap(),
            "--footprints",
            csv.to_str().unwrap(),
            "--out",
            tmp.path().join("far.parquet").to_str().unwrap(),
        ]);
        assert!(
            !ok && err.trim().lines().count() == 1 && err.contains("was not read") && err.contains("als/"),
            "{err}"
        );
    }
}

/// COPC tiles served by a loopback HTTP server that answers range requests and counts the bytes
/// it sends: read through `object_store`, only the ranges a read needs are fetched.
mod remote {
    use super::*;
    use std::path::{Path, PathBuf};
    use std::sync::atomic::{AtomicU64, Ordering};
    use std::sync::Arc;

    struct Server {
        url: String,
        /// Body bytes sent in answer to GET requests.
        sent: Arc<AtomicU64>,
    }

    /// Serve the files of `dir` on 127.0.0.1 over HTTP/1.1 with keep-alive, as object stores do:
    /// HEAD, GET, and GET with `Range: bytes=a-b`; a thread per connection.
    fn serve(dir: PathBuf) -> Server {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let sent = Arc::new(AtomicU64::new(0));
        let counter = sent.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let (dir, counter) = (dir.clone(), counter.clone());
                std::thread::spawn(move || {
                    let _ = connection(stream, &dir, &counter);
                });
            }
        });
        Server { url: format!("http://127.0.0.1:{port}"), sent }
    }

    /// Answer the requests of one connection until the client closes it.
    fn connection(stream: std::net::TcpStream, dir: &Path, counter: &AtomicU64) -> std::io::Result<()> {
        use std::io::{BufRead, Write};
        let mut reader = std::io::BufReader::new(stream.try_clone()?);
        let mut out = stream;
        loop {
            let mut line = String::new();
            if reader.read_line(&mut line)? == 0 {
                return Ok(());
            }
            let mut parts = line.split_whitespace();
            let (method, target) = (parts.next().unwrap_or("").to_string(), parts.next().unwrap_or("").to_string());
            let mut range = None;
            loop {
                let mut h = String::new();
                reader.read_line(&mut h)?;
                if h.trim().is_empty() {
                    break;
                }
                if let Some((k, v)) = h.split_once(':') {
                    if k.trim().eq_ignore_ascii_case("range") {
                        range = v.trim().strip_prefix("bytes=").and_then(|r| {
                            let (a, b) = r.split_once('-')?;
                            Some((a.parse::<usize>().ok()?, b.parse::<usize>().ok()))
                        });
                    }
                }
            }
            let Ok(data) = std::fs::read(dir.join(target.trim_start_matches('/'))) else {
                out.write_all(b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\n")?;
                continue;
            };
            let len = data.len();
            let (status, body, extra) = match range {
                Some((a, b)) if a < len => {
                    let b = b.unwrap_or(len - 1).min(len - 1);
                    ("206 Partial Content", &data[a..=b], format!("Content-Range: bytes {a}-{b}/{len}\r\n"))
                }
                _ => ("200 OK", &data[..], String::new()),
            };
            let head = format!(
                "HTTP/1.1 {status}\r\nContent-Length: {}\r\n{extra}ETag: \"v1\"\r\n\
                 Last-Modified: Wed, 25 Nov 2026 10:00:00 GMT\r\n\r\n",
                body.len()
            );
            out.write_all(head.as_bytes())?;
            if method == "GET" {
                out.write_all(body)?;
                counter.fetch_add(body.len() as u64, Ordering::Relaxed);
            }
        }
    }

    /// The number after `fetched ` in a line of the CLI's stderr.
    fn reported_fetched(err: &str) -> u64 {
        let line = err.lines().find(|l| l.contains("fetched ")).unwrap_or_else(|| panic!("{err}"));
        line.split("fetched ").nth(1).unwrap().split(' ').next().unwrap().parse().unwrap()
    }

    #[test]
    fn simulate_from_a_url_fetches_only_the_ranges_it_decodes_and_equals_the_local_read() {
        let server = serve(data("als-copc"));
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("plots.csv");
        std::fs::write(&csv, "id,x,y\na,817600,6460800\nb,817640,6460830\n").unwrap();
        let name = "lidarforfuel_1_42.copc.laz";
        let size = std::fs::metadata(data("als-copc").join(name)).unwrap().len();
        let mut tables = Vec::new();
        for als in [data("als-copc").join(name).to_string_lossy().into_owned(), format!("{}/{name}", server.url)] {
            let out = dir.path().join(format!("{}.parquet", tables.len()));
            let args =
                ["simulate", "--als", &als, "--footprints", csv.to_str().unwrap(), "--out", out.to_str().unwrap()];
            let (ok, _, err) = common::gedisim(&args);
            assert!(ok, "{err}");
            if als.starts_with("http") {
                let sent = server.sent.load(Ordering::Relaxed);
                assert_eq!(reported_fetched(&err), sent, "{err}");
                assert!(sent > 0 && sent < size * 3 / 4, "{sent} of {size} bytes fetched");
                let decoded: u64 =
                    err.split(" compressed bytes").next().unwrap().rsplit(' ').next().unwrap().parse().unwrap();
                assert!(sent >= decoded, "{err}");
                eprintln!("{err}");
            }
            tables.push(read_table(&out));
        }
        assert_eq!(tables[0], tables[1]);
    }

    #[test]
    fn a_url_that_does_not_answer_or_holds_nothing_is_one_line() {
        let server = serve(data("als-copc"));
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("plots.csv");
        std::fs::write(&csv, "id,x,y\na,817600,6460800\n").unwrap();
        let out = dir.path().join("o.parquet");
        for url in [format!("{}/missing.copc.laz", server.url), "http://127.0.0.1:9/x.copc.laz".to_string()] {
            let args =
                ["simulate", "--als", &url, "--footprints", csv.to_str().unwrap(), "--out", out.to_str().unwrap()];
            let (ok, _, err) = common::gedisim(&args);
            assert!(!ok && err.trim().lines().count() == 1 && err.contains(&url), "{err}");
        }
    }

    #[test]
    fn ingest_from_urls_equals_ingest_from_files() {
        let server = serve(data(""));
        let tmp = tempfile::tempdir().unwrap();
        let world = tmp.path().join("world");
        let laz = data("als/lidarforfuel_1_42.laz");
        let args = ["scenario", "--effect", "none", "--als", laz.to_str().unwrap(), "--passes", "1", "--seed", "5"];
        let (ok, _, err) = common::gedisim(&[&args[..], &["--out", world.to_str().unwrap()]].concat());
        assert!(ok, "{err}");
        let gedi = world.join("gedi");
        // A COPC tile (read around the shots) and a plain LAZ tile elsewhere (read whole).
        let tiles = ["als-copc/lidarforfuel_1_42.copc.laz", "als/pdal-ign-plugin_mnx_input_crop_2.laz"];
        let mut datasets = Vec::new();
        for remote in [false, true] {
            let ds = tmp.path().join(if remote { "url" } else { "file" });
            let d = ds.to_str().unwrap();
            let (ok, _, err) = common::gedisim(&[
                "ingest",
                "gedi",
                "--l1b",
                gedi.to_str().unwrap(),
                "--l2a",
                gedi.to_str().unwrap(),
                "--out",
                d,
            ]);
            assert!(ok, "{err}");
            let inputs: Vec<String> = tiles
                .iter()
                .map(|t| if remote { format!("{}/{t}", server.url) } else { data(t).to_string_lossy().into_owned() })
                .collect();
            let before = server.sent.load(Ordering::Relaxed);
            let (ok, _, err) = common::gedisim(
                &[&["ingest", "als"][..], &inputs.iter().map(String::as_str).collect::<Vec<_>>(), &["--out", d]]
                    .concat(),
            );
            assert!(ok, "{err}");
            assert!(err.contains("new cells of 10 m"), "{err}");
            if remote {
                // No input read twice: the COPC tile's windows cover most of this 100 m tile, so
                // the bound is the file's size, plus its header and hierarchy read by two readers.
                let lines: Vec<&str> = err.lines().filter(|l| l.contains(" range requests")).collect();
                assert_eq!(lines.len(), 2, "{err}");
                let mut total = 0;
                for line in lines {
                    let n: Vec<u64> =
                        line.split("fetched ").nth(1).unwrap().split(' ').filter_map(|w| w.parse().ok()).collect();
                    assert!(n[0] as f64 <= 1.1 * n[1] as f64, "{line}");
                    total += n[0];
                }
                assert_eq!(total, server.sent.load(Ordering::Relaxed) - before);
            }
            let mut points = AlsPoints::default();
            for f in common::files_with_suffix(&ds.join("als"), ".parquet") {
                points.extend_from(&gedisim::dataset::als::read_file_points(&f).unwrap());
            }
            datasets.push(canonical(&points));
        }
        assert!(datasets[0].len() > 200_000, "{}", datasets[0].len());
        assert_eq!(datasets[0], datasets[1]);
    }
}
