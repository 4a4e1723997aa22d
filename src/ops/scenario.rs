//! Adapter of `gedisim scenario`: reads the ALS tiles, runs the scenario kernels
//! ([`crate::kernels::scenario`]) and the simulator, and writes the world: `<out>/als/` (copies of the
//! tiles), `<out>/gedi/` (V2-layout L1B + L2A granules) and `<out>/truth.json`. Every file is
//! written under a temporary name and renamed when complete; truth.json is written last.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use chrono::{DateTime, TimeZone, Utc};

use crate::error::{Error, Result};
use crate::io::granule::{write_l1b_v2, write_l2a_v2, Beam, GranuleMeta};
use crate::io::las::TileReader;
use crate::kernels::gedi::{beam_number, BeamType, BEAM_NAMES};
use crate::kernels::gedi::{L1bShot, L2aShot, LandCover};
use crate::kernels::geo::projection::Projector;
use crate::kernels::scenario::effects::{EffectSet, Physics, NOMINAL_FSIGMA_M};
use crate::kernels::scenario::granules::{delta_time, granule_ids, is_leaf_off, GROUND_SPEED_M_S};
use crate::kernels::scenario::plan::{plan, Extent, PlanSettings};
use crate::kernels::scenario::real::{self, ENERGY_LOG_SPREAD, NOISE_MEAN_SPREAD, NOISE_STDDEV_LOG_SPREAD};
use crate::kernels::scenario::rng::Stream;
use crate::kernels::scenario::shot::{draw_transmit, make_shot, ShotSpec, TX_STRETCH_SIGMA};
use crate::kernels::scenario::truth::{
    finite, DroppedShot, GeoidTruth, GeolocationTruth, GranuleTruth, NoiseTruth, PlantedEffect, ShotTruthRecord,
    TileTruth, TrackTruth, TruePhysics, Truth, TRUTH_FORMAT,
};
use crate::kernels::sim::{self, Footprint, PulseReference};
use crate::kernels::waveform::forward::L2aRunner;
use crate::kernels::waveform::l2a::Noise;
use crate::ops::ingest_gedi::DEFAULT_EPSG;

/// Default nominal geoid height N (m): EGM2008/RAF20 N over metropolitan France spans about
/// 44–55 m; 49 m is typical of the Massif Central and Alpine foothills.
pub const DEFAULT_GEOID_M: f64 = 49.0;

/// Options of one world.
#[derive(Debug, Clone)]
pub struct ScenarioOptions {
    /// The `--effect` text: an effect, a pair `a+b`, or `none` (recorded as given).
    pub effect_spec: String,
    /// Scale of the main parameter's departure from nominal (docs/scenario.md).
    pub magnitude: Option<f64>,
    /// `--param key=value` pairs.
    pub params: Vec<(String, String)>,
    pub seed: u64,
    /// LAS/LAZ files or folders; empty: the bundled tiles ([`bundled_tiles`]).
    pub tiles: Vec<PathBuf>,
    pub out: PathBuf,
    /// Granules (passes) per tile.
    pub passes_per_tile: usize,
    /// Nominal geoid height N (m).
    pub geoid_m: f64,
    /// RMS per axis of the per-track offsets (m).
    pub track_offset_sigma_m: f64,
    /// CRS of tiles without one (`None`: [`DEFAULT_EPSG`], said in [`ScenarioReport::notes`]).
    pub default_epsg: Option<u32>,
    /// Replace an existing world in `out`.
    pub force: bool,
}

/// What was written.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioReport {
    pub tiles: usize,
    pub granules: usize,
    pub tracks: usize,
    pub shots: usize,
    pub dropped: usize,
    pub truth: PathBuf,
    /// What the user should know (a tile taken to be in the default CRS).
    pub notes: Vec<String>,
}

/// One tile as the world uses it.
struct Tile {
    path: PathBuf,
    points: sim::AlsPoints,
    extent: Extent,
    epsg: u32,
    acquired: Option<DateTime<Utc>>,
}

fn read_tile(path: &Path, default_epsg: Option<u32>, notes: &mut Vec<String>) -> Result<Tile> {
    let reader = TileReader::open(path)?;
    let h = reader.header().clone();
    let points = crate::ops::simulate::drop_ingest_classes(&reader.read_all()?);
    if points.is_empty() {
        return Err(Error::file(path, "no point left after dropping classes 7, 18, 64-67"));
    }
    let mut gps: Vec<f64> = points.gps_time.iter().copied().filter(|t| t.is_finite()).collect();
    gps.sort_by(f64::total_cmp);
    let acquired = gps
        .get(gps.len() / 2)
        .and_then(|&t| crate::ops::ingest_als::gps_to_utc_micros(t))
        .and_then(|us| Utc.timestamp_micros(us).single());
    let [xmin, ymin, _, xmax, ymax, _] = h.bounds;
    if !(xmax > xmin && ymax > ymin) {
        return Err(Error::field(path, "header bounds", format!("empty extent {xmin}..{xmax} x {ymin}..{ymax}")));
    }
    Ok(Tile {
        path: path.to_path_buf(),
        points,
        extent: Extent { xmin, ymin, xmax, ymax },
        epsg: match (h.epsg, default_epsg) {
            (Some(e), _) | (None, Some(e)) => e,
            (None, None) => {
                notes.push(format!(
                    "{}: no CRS in the header; taken as EPSG:{DEFAULT_EPSG} (Lambert-93, LiDAR HD's); --epsg names \
                     another",
                    path.display()
                ));
                DEFAULT_EPSG
            }
        },
        acquired,
    })
}

/// The three real LiDAR HD tiles bundled with gedisim (`io::bundled`), the default of `scenario`
/// and the tiles of `demo`.
pub fn bundled_tiles() -> Result<PathBuf> {
    crate::io::bundled::tiles()
}

/// The real L1B bundled with gedisim (`io::bundled`): its transmit records are the library from
/// which every scenario shot draws its pulse.
pub fn bundled_l1b() -> Result<PathBuf> {
    crate::io::bundled::l1b()
}

/// The transmit records of the bundled L1B, by beam type (`[coverage, full power]`).
fn pulse_library() -> Result<[Vec<Vec<f32>>; 2]> {
    let l1b = bundled_l1b()?;
    let files = crate::ops::ingest_gedi::expand_granule_inputs(std::slice::from_ref(&l1b), "GEDI01_B")?;
    let mut lib: [Vec<Vec<f32>>; 2] = [Vec::new(), Vec::new()];
    for f in &files {
        for (full_power, tx) in crate::io::gedi::read_transmit_records(f)? {
            lib[usize::from(full_power)].push(tx);
        }
    }
    if lib.iter().any(Vec::is_empty) {
        return Err(Error::file(&l1b, "no transmit records of both beam types for the pulse library"));
    }
    Ok(lib)
}

/// Build the world and write it under `opts.out`.
pub fn make_scenario(opts: &ScenarioOptions) -> Result<ScenarioReport> {
    let effects =
        EffectSet::parse(&opts.effect_spec, opts.magnitude, &opts.params).map_err(|e| Error::Usage(e.to_string()))?;
    let inputs = if opts.tiles.is_empty() { vec![bundled_tiles()?] } else { opts.tiles.clone() };
    let tile_files = crate::ops::ingest_als::expand_inputs(&inputs)?;
    if tile_files.is_empty() {
        return Err(Error::Usage("--als: no LAS/LAZ file".into()));
    }
    if opts.passes_per_tile == 0 || opts.passes_per_tile > 64 {
        return Err(Error::Usage(format!("--passes: {} is not in 1..64", opts.passes_per_tile)));
    }
    if !opts.geoid_m.is_finite() || opts.geoid_m.abs() > 200.0 {
        return Err(Error::Usage(format!("--geoid: {} m is not a geoid height (|N| ≤ 200 m)", opts.geoid_m)));
    }
    if !(opts.track_offset_sigma_m.is_finite() && (0.0..=50.0).contains(&opts.track_offset_sigma_m)) {
        return Err(Error::Usage(format!("--offset-sigma: {} m is not in 0..50", opts.track_offset_sigma_m)));
    }
    let gedi_dir = opts.out.join("gedi");
    let als_dir = opts.out.join("als");
    let truth_path = opts.out.join("truth.json");
    let existing = truth_path.exists() || std::fs::read_dir(&gedi_dir).map(|mut d| d.next().is_some()).unwrap_or(false);
    if existing && !opts.force {
        return Err(Error::file(&opts.out, "already holds a world (truth.json or gedi/); use --force to replace it"));
    }

    let mut notes = Vec::new();
    let tiles = tile_files.iter().map(|p| read_tile(p, opts.default_epsg, &mut notes)).collect::<Result<Vec<_>>>()?;
    let physics = effects.physics(&Physics::nominal());
    // Keep 2σ_f of ALS around every true and reported footprint centre, plus a metre.
    let margin = 2.0 * f64::from(physics.sim.fsigma).max(NOMINAL_FSIGMA_M) + 1.0;
    let settings = PlanSettings {
        passes_per_tile: opts.passes_per_tile,
        track_offset_sigma_m: opts.track_offset_sigma_m,
        margin_m: margin,
        extra_offset: effects.extra_offset(),
    };
    let extents: Vec<Extent> = tiles.iter().map(|t| t.extent).collect();
    let layout = plan(&extents, &settings, opts.seed);

    // Granule identities.
    let acquired: Vec<Option<DateTime<Utc>>> = tiles.iter().map(|t| t.acquired).collect();
    let granules = granule_ids(opts.seed, &acquired, opts.passes_per_tile);

    // Each shot's transmit pulse, drawn from the real pulses of its laser type (docs/scenario.md).
    let library = pulse_library()?;
    let reference = PulseReference::default();
    let extra_pulse = effects.extra_pulse_sigma();
    let pulses: Vec<Option<(Vec<f32>, sim::Pulse)>> = layout
        .shots
        .iter()
        .map(|ps| {
            let track = &layout.tracks[ps.track];
            let full_power = BeamType::from_name(track.beam) == Some(BeamType::FullPower);
            let mut r = Stream::new(opts.seed, &["pulse", &track.id, &ps.along_index.to_string()]);
            let lib = &library[usize::from(full_power)];
            let pick = ((r.uniform() * lib.len() as f64) as usize).min(lib.len() - 1);
            draw_transmit(&lib[pick], &mut r, reference, physics.sim.res)
        })
        .collect();

    // Simulate every tile's shots at their true positions with the true physics.
    let mut sims = vec![None; layout.shots.len()];
    for (t, tile) in tiles.iter().enumerate() {
        let idx: Vec<usize> =
            (0..layout.shots.len()).filter(|&i| layout.tracks[layout.shots[i].track].tile == t).collect();
        let fps: Vec<Footprint> = idx
            .iter()
            .map(|&i| {
                let s = &layout.shots[i];
                let pulse = pulses[i].as_ref().map(|(_, p)| Arc::new(p.broadened(extra_pulse)));
                Footprint { pulse, ..Footprint::at(i.to_string(), s.x + s.dx, s.y + s.dy) }
            })
            .collect();
        let out = sim::simulate(&tile.points, &fps, &physics.sim).map_err(|e| Error::file(&tile.path, e))?;
        for (i, r) in idx.into_iter().zip(out) {
            sims[i] = Some(r);
        }
    }

    // Make every shot.
    let projectors: Vec<Projector> = tiles.iter().map(|t| Projector::new(t.epsg)).collect::<Result<_, _>>()?;
    let mut l1b: Vec<Vec<Vec<L1bShot>>> = granules.iter().map(|_| vec![Vec::new(); BEAM_NAMES.len()]).collect();
    let mut l2a: Vec<Vec<Vec<L2aShot>>> = granules.iter().map(|_| vec![Vec::new(); BEAM_NAMES.len()]).collect();
    let mut shots_written = Vec::new();
    let mut shots_dropped = Vec::new();
    let mut track_counts = vec![0usize; layout.tracks.len()];
    let mut processor = L2aRunner::default();
    let factor = effects.noise_sigma_factor();
    for (i, ps) in layout.shots.iter().enumerate() {
        let track = &layout.tracks[ps.track];
        let tile = &tiles[track.tile];
        let gr = &granules[track.granule];
        let beam_idx = BEAM_NAMES.iter().position(|b| *b == track.beam).unwrap_or(0);
        let beam_type = BeamType::from_name(track.beam).unwrap_or(BeamType::Coverage);
        let rec = real::record(beam_type);
        let mut r = Stream::new(opts.seed, &["shot", &track.id, &ps.along_index.to_string()]);
        let (lon, lat) =
            projectors[track.tile].unproject(ps.x, ps.y).map_err(|e| Error::field(&tile.path, "extent", e))?;
        let leaf_off = is_leaf_off(Some(gr.start).filter(|_| tile.acquired.is_some()));
        let along_s = ps.along_m / GROUND_SPEED_M_S;
        let dt = delta_time(gr.start) + along_s;
        let shot_number = u64::from(gr.orbit) * 10_000_000_000_000
            + u64::from(beam_number(track.beam).unwrap_or(0)) * 100_000_000_000
            + (ps.track as u64 % 1000) * 100_000
            + u64::from(ps.along_index)
            + 1;
        let spec = ShotSpec {
            shot_number,
            delta_time: dt,
            beam_type,
            lat,
            lon,
            geoid_m: opts.geoid_m,
            noise: Noise {
                mean: rec.noise_mean + NOISE_MEAN_SPREAD * r.normal(),
                stddev: rec.noise_stddev * factor * (NOISE_STDDEV_LOG_SPREAD * r.normal()).exp(),
            },
            energy: rec.energy * (ENERGY_LOG_SPREAD * r.normal()).exp(),
            above_signal_m: rec.above_signal_m + r.normal(),
            below_ground_m: rec.below_ground_m + r.normal(),
            noise_seed: r.next_u64(),
            dem_error_m: 1.5 * r.normal(),
            tx_waveform: pulses[i].as_ref().map(|(record, _)| record.clone()).unwrap_or_default(),
            land_cover: LandCover {
                leaf_off_flag: u8::from(leaf_off),
                leaf_off_doy: 305,
                leaf_on_doy: 105,
                leaf_on_cycle: 1,
                ..Default::default()
            },
        };
        let outcome = match &sims[i] {
            Some(Ok(fp)) => make_shot(fp, &physics, &effects, &spec, &mut processor).map_err(|e| e.to_string()),
            Some(Err(reason)) => Err(format!("simulation skipped: {reason:?}")),
            None => Err("not simulated".to_string()),
        };
        match outcome {
            Ok((a, b, truth)) => {
                track_counts[ps.track] += 1;
                shots_written.push(ShotTruthRecord {
                    shot_number,
                    track: track.id.clone(),
                    x: ps.x,
                    y: ps.y,
                    true_x: ps.x + ps.dx,
                    true_y: ps.y + ps.dy,
                    dx: ps.dx,
                    dy: ps.dy,
                    als_ground_m: finite(truth.als_ground_m),
                    true_top_m: truth.true_top_m.and_then(finite),
                    gedi_ground_expected_m: finite(truth.gedi_ground_expected_m),
                    noise_stddev: finite(truth.noise_stddev),
                    selected_algorithm: b.selected_algorithm,
                    quality_flag: b.quality_flag,
                });
                l1b[track.granule][beam_idx].push(a);
                l2a[track.granule][beam_idx].push(b);
            }
            Err(reason) => shots_dropped.push(DroppedShot { track: track.id.clone(), x: ps.x, y: ps.y, reason }),
        }
    }

    if shots_written.is_empty() {
        return Err(Error::Usage(format!(
            "--als: no shot fits {} m inside the tiles ({} planned, {} dropped); give larger tiles or more --passes",
            margin,
            layout.shots.len(),
            shots_dropped.len()
        )));
    }

    // Write: granules and tiles under temporary names, then truth.json.
    let tmp = opts.out.join(format!(".scenario-tmp-{}", std::process::id()));
    let mk = |d: &Path| std::fs::create_dir_all(d).map_err(|e| Error::file(d, format!("cannot create folder: {e}")));
    if opts.force {
        for d in [&gedi_dir, &als_dir] {
            if d.exists() {
                std::fs::remove_dir_all(d)
                    .map_err(|e| Error::file(d, format!("cannot remove the previous world: {e}")))?;
            }
        }
    }
    mk(&tmp)?;
    mk(&gedi_dir)?;
    mk(&als_dir)?;
    let result = write_outputs(
        opts,
        &tmp,
        &gedi_dir,
        &als_dir,
        &tiles,
        &granules.iter().map(|g| (g.l1b.clone(), g.l2a.clone())).collect::<Vec<_>>(),
        &l1b,
        &l2a,
    );
    let _ = std::fs::remove_dir_all(&tmp);
    result?;

    let truth = Truth {
        format: TRUTH_FORMAT.to_string(),
        effect: effects.name(),
        effect_spec: opts.effect_spec.clone(),
        effects: effects.effects.iter().map(PlantedEffect::of).collect(),
        magnitude: opts.magnitude,
        params_given: opts.params.clone(),
        seed: opts.seed,
        physics: TruePhysics {
            weighting: physics.weighting.name().to_string(),
            rho_ground_over_veg: physics.rho_ground_over_veg,
            pulse: format!(
                "recorded (real L1B transmit pulses of the shot's laser, stretched 1 ± {TX_STRETCH_SIGMA}; \
                 reference {reference})"
            ),
            extra_pulse_sigma_m: extra_pulse,
            fsigma_m: f64::from(physics.sim.fsigma),
            profile: "default".to_string(),
        },
        geoid: GeoidTruth {
            n_m: opts.geoid_m,
            dataset: "geophys_corr/geoid".to_string(),
            relation: "GEDI elevation = ALS height (IGN69) + N + datum_dz_m".to_string(),
        },
        datum_dz_m: effects.vertical_offset_m(),
        noise: NoiseTruth {
            noise_sigma_factor: factor,
            median_noise_stddev_corrected: [
                ("coverage", real::COVERAGE.noise_stddev),
                ("full_power", real::FULL_POWER.noise_stddev),
            ]
            .into_iter()
            .map(|(k, v)| (k.to_string(), v))
            .collect(),
            shape: "GEDI_V1 (per-sample 0.52 sigma, Gaussian correlation 1.63 samples)".to_string(),
        },
        geolocation: GeolocationTruth {
            convention: "true position = reported (x, y) + (dx, dy), as collocate reports offsets".to_string(),
            track_offset_sigma_m: opts.track_offset_sigma_m,
            clip_sigmas: 2.5,
        },
        ground_detection_offset_m: (1..=6u8).map(|a| effects.ground_offset_m(a)).collect(),
        margin_m: margin,
        n_shots: shots_written.len(),
        n_dropped: shots_dropped.len(),
        tiles: tiles
            .iter()
            .map(|t| TileTruth {
                file: format!(
                    "als/{}",
                    t.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
                ),
                source: t.path.display().to_string(),
                epsg: t.epsg,
                extent: [t.extent.xmin, t.extent.ymin, t.extent.xmax, t.extent.ymax],
                points_used: t.points.len(),
                acquired_utc: t.acquired.map(|d| d.to_rfc3339()),
                leaf_off: is_leaf_off(t.acquired),
            })
            .collect(),
        granules: granules
            .iter()
            .enumerate()
            .map(|(i, g)| GranuleTruth {
                l1b: format!("gedi/{}", g.l1b),
                l2a: format!("gedi/{}", g.l2a),
                tile: g.tile,
                pass: g.pass,
                start_utc: g.start.to_rfc3339(),
                orbit: g.orbit,
                sub_orbit: g.sub_orbit,
                reference_track: g.reference_track,
                heading_deg: layout.tracks.iter().find(|t| t.granule == i).map(|t| t.heading_deg),
            })
            .collect(),
        tracks: layout
            .tracks
            .iter()
            .zip(&track_counts)
            .map(|(t, &n)| TrackTruth {
                id: t.id.clone(),
                tile: t.tile,
                granule: t.granule,
                beam: t.beam.to_string(),
                beam_type: BeamType::from_name(t.beam).map(|b| b.as_str().to_string()),
                heading_deg: t.heading_deg,
                dx: t.dx,
                dy: t.dy,
                n_shots: n,
            })
            .collect(),
        shots: shots_written,
        dropped: shots_dropped,
    };
    let text = serde_json::to_string_pretty(&truth).map_err(|e| Error::file(&truth_path, e))?;
    crate::dataset::write_atomic(&truth_path, text.as_bytes())?;
    Ok(ScenarioReport {
        tiles: tiles.len(),
        granules: granules.len(),
        tracks: layout.tracks.len(),
        shots: truth.n_shots,
        dropped: truth.n_dropped,
        truth: truth_path,
        notes,
    })
}

#[allow(clippy::too_many_arguments)]
fn write_outputs(
    _opts: &ScenarioOptions,
    tmp: &Path,
    gedi_dir: &Path,
    als_dir: &Path,
    tiles: &[Tile],
    names: &[(String, String)],
    l1b: &[Vec<Vec<L1bShot>>],
    l2a: &[Vec<Vec<L2aShot>>],
) -> Result<()> {
    let meta = GranuleMeta::default();
    for (g, (n1, n2)) in names.iter().enumerate() {
        let beams1: Vec<Beam<L1bShot>> = BEAM_NAMES
            .iter()
            .zip(&l1b[g])
            .filter(|(_, s)| !s.is_empty())
            .map(|(b, s)| Beam::new(*b, s.clone()))
            .collect();
        let beams2: Vec<Beam<L2aShot>> = BEAM_NAMES
            .iter()
            .zip(&l2a[g])
            .filter(|(_, s)| !s.is_empty())
            .map(|(b, s)| Beam::new(*b, s.clone()))
            .collect();
        if beams1.is_empty() {
            continue; // a granule without a shot over the tile is not distributed
        }
        write_l1b_v2(&tmp.join(n1), &beams1, &meta)?;
        write_l2a_v2(&tmp.join(n2), &beams2, &meta)?;
        for n in [n1, n2] {
            let (from, to) = (tmp.join(n), gedi_dir.join(n));
            std::fs::rename(&from, &to).map_err(|e| Error::file(&to, format!("cannot move into place: {e}")))?;
        }
    }
    for t in tiles {
        let name = t.path.file_name().ok_or_else(|| Error::file(&t.path, "not a file name"))?;
        let dest = als_dir.join(name);
        let staged = tmp.join(name);
        std::fs::copy(&t.path, &staged)
            .map_err(|e| Error::file(&t.path, format!("cannot copy to {}: {e}", staged.display())))?;
        std::fs::rename(&staged, &dest).map_err(|e| Error::file(&dest, format!("cannot move into place: {e}")))?;
    }
    Ok(())
}
