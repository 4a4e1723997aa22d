//! `gedisim diagnose`: reads a dataset's shots (and their per-beam collocation offsets, strata)
//! and ALS points into [`diagnose::ShotCase`]s, runs the kernels of [`crate::kernels::diagnose`], and writes
//! `<out>/diagnosis.json`, its tables (Parquet + CSV) and figures (PNG + SVG). docs/diagnosis.md.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, Float64Array, RecordBatch, StringArray};
use arrow::datatypes::{Field, Schema};

use crate::dataset::als::AlsTable;
use crate::dataset::read::{self, value};
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::collocate::segments::Level;
use crate::kernels::diagnose::case::{
    configs, nominal_noise_stddev, site_grid, site_of, RealAlgorithm, RealShot, SimShot, Site, Strata, FSIGMA_GRID,
    NOMINAL_WIDTH, RECOLLOCATE_SHIFT_M, RECOLLOCATE_STEP_M, SHORT_SEGMENT_SHOTS, SITE_HALF, SITE_STEP_M,
};
use crate::kernels::diagnose::gap::N_PCT;
use crate::kernels::diagnose::json::{params, DiagnosisJson};
use crate::kernels::diagnose::selftest::{SelfTest, Verdict};
use crate::kernels::diagnose::{self, Diagnosis, ShotCase};
use crate::kernels::gedi::{BeamType, N_ALGORITHMS, RH_LEN};
use crate::kernels::scenario::effects::{EffectKind, ParamValue};
use crate::kernels::sim::{self, Footprint, PulseModel, PulseReference, Weighting};
use crate::kernels::study::classes;
use crate::kernels::waveform::l2a::Noise;
use crate::ops::collocate::{CollocateOptions, CollocateReport};
use crate::ops::progress::{Progress, Step};
use crate::ops::report::figures::{self, LinePanels};
use crate::ops::run::{RunOptions, RunReport};

/// What [`read_cases`] kept and dropped.
#[derive(Debug, Clone, Default)]
pub struct CaseReport {
    pub shots_read: usize,
    /// (reason, count)
    pub dropped: Vec<(String, usize)>,
}

fn count_dropped(report: &mut CaseReport, reason: &str) {
    match report.dropped.iter_mut().find(|(r, _)| r == reason) {
        Some((_, n)) => *n += 1,
        None => report.dropped.push((reason.to_string(), 1)),
    }
}

/// A real shot waiting for its simulation.
struct Pending {
    real: RealShot,
    footprint: Footprint,
    /// Reported position (m, ALS CRS).
    reported: (f64, f64),
    /// Its collocation segment is short ([`SHORT_SEGMENT_SHOTS`]): its [`site_grid`] is centred on
    /// the segment's re-collocated position and simulated at every width.
    short_segment: bool,
    /// Its track is among those ranked ([`diagnose::sample`]): simulated at its sites. Another
    /// shot is simulated at its collocated position, nominal width, for `where` alone.
    ranked: bool,
}

/// The shots of a dataset, read and simulated for the diagnosis.
pub struct Cases {
    /// Shots of the ranked tracks.
    pub ranked: Vec<ShotCase>,
    /// The other shots (located only).
    pub located: Vec<ShotCase>,
    pub report: CaseReport,
}

/// Read every usable shot of the dataset with its simulations, simulated as one
/// [`Step::DiagnoseSimulate`]: the shots of tracks drawn up to `ranked_shots`
/// ([`diagnose::sample::ranked_tracks`]) at all their sites and widths, the others for `where`.
/// `pulse`: the shots' transmit pulse in the nominal chain (recorded, a file, or the Gaussian).
pub fn read_cases(ds: &Dataset, pulse: &PulseModel, ranked_shots: usize, progress: &dyn Progress) -> Result<Cases> {
    let res = configs().0.res;
    let pulses = ShotPulseSource::new(pulse, res)?;
    let mut report = CaseReport::default();
    let offsets = crate::dataset::offsets::read_offsets(ds)?;
    let forest = crate::dataset::strata::read_forest_types(ds)?;
    let dir = ds.root().join(tables::SHOTS);
    let files = dataset::table_files(&dir)
        .map_err(|e| Error::file(&dir, format!("no shots table ({e}): run `gedisim ingest gedi`")))?;
    let mut pending = Vec::new();
    for f in files {
        read::for_each_batch(&f, None, None, |c| read_shots(c, &offsets, &forest, &pulses, &mut pending, &mut report))?;
    }
    let mut segment_shots: HashMap<&str, usize> = HashMap::new();
    offsets.values().for_each(|o| *segment_shots.entry(o.segment_id.as_str()).or_default() += 1);
    let ranked = diagnose::sample::ranked_tracks(pending.iter().map(|p| p.real.track.as_str()), ranked_shots);
    for p in &mut pending {
        p.short_segment = segment_shots.get(p.real.segment.as_str()).is_some_and(|&n| n < SHORT_SEGMENT_SHOTS);
        p.ranked = ranked.contains(&p.real.track);
    }
    let als = AlsTable::open(ds)?;
    let centres = recollocate(&als, &pending, reference_dz(&offsets))?;
    progress.start(Step::DiagnoseSimulate, pending.len() as u64);
    let cases = simulate_cases(&als, pending, &centres, &mut report, &|| progress.advance(1));
    progress.finish();
    let (ranked, located) = cases?.into_iter().partition(|(r, _)| *r);
    let strip = |v: Vec<(bool, ShotCase)>| v.into_iter().map(|(_, c)| c).collect();
    Ok(Cases { ranked: strip(ranked), located: strip(located), report })
}

fn read_shots(
    c: read::Columns,
    offsets: &HashMap<u64, crate::dataset::offsets::AppliedOffset>,
    forest: &HashMap<u64, String>,
    pulses: &ShotPulseSource,
    out: &mut Vec<Pending>,
    report: &mut CaseReport,
) -> Result<()> {
    let (granule, beam, beam_type) = (c.strings("granule")?, c.strings("beam")?, c.strings("beam_type")?);
    let sn = c.u64s("shot_number")?;
    let (x, y) = (c.f64s("x")?, c.f64s("y")?);
    let (bin0, lastbin) = (c.f64s("elevation_bin0")?, c.f64s("elevation_lastbin")?);
    let (nmean, nsd) = (c.f64s("noise_mean_corrected")?, c.f64s("noise_stddev_corrected")?);
    let (geoid, geoid_used) = (c.f64s("geoid")?, c.f64s("geoid_offset_used")?);
    let degrade = c.u8s("degrade_flag")?;
    let selected = c.u8s("selected_algorithm")?;
    let leaf_off = c.u8s("leaf_off_flag")?;
    let mut alg_cols = Vec::new();
    for a in 1..=N_ALGORITHMS {
        alg_cols.push((
            c.f64s(&format!("elev_lowestmode_a{a}"))?,
            format!("rh_a{a}"),
            c.f64s(&format!("sensitivity_a{a}"))?,
            c.u8s(&format!("quality_flag_a{a}"))?,
        ));
    }
    for i in 0..c.num_rows() {
        report.shots_read += 1;
        let (Some(px), Some(py)) = (value(x, i), value(y, i)) else {
            count_dropped(report, "no position");
            continue;
        };
        let Some(wave) = c.f32_list("rx_waveform", i)?.filter(|w| w.len() > 1) else {
            count_dropped(report, "no L1B waveform");
            continue;
        };
        let (Some(e0), Some(e1), Some(mean), Some(sd)) =
            (value(bin0, i), value(lastbin, i), value(nmean, i), value(nsd, i))
        else {
            count_dropped(report, "no record geolocation or noise");
            continue;
        };
        let Some(n_geoid) = value(geoid_used, i).or(value(geoid, i)) else {
            count_dropped(report, "no geoid");
            continue;
        };
        let Some(bt) = BeamType::from_name(beam.value(i)).or(match beam_type.value(i) {
            "coverage" => Some(BeamType::Coverage),
            "full_power" => Some(BeamType::FullPower),
            _ => None,
        }) else {
            count_dropped(report, "unknown beam type");
            continue;
        };
        let shot = sn.value(i);
        let algorithms: [Option<RealAlgorithm>; N_ALGORITHMS] = std::array::from_fn(|a| {
            let (elev, rh, sens, q) = &alg_cols[a];
            if !classes::passes_quality(value(q, i), value(degrade, i), value(sens, i)) {
                return None;
            }
            let ground = value(elev, i)?;
            let rh = c.f32_list(rh, i).ok().flatten().filter(|r| r.len() == RH_LEN)?;
            ground.is_finite().then_some(RealAlgorithm { ground: ground - n_geoid, rh })
        });
        if algorithms.iter().all(Option::is_none) {
            count_dropped(report, "no algorithm passes quality (quality_flag, degrade_flag, sensitivity ≥ 0.9)");
            continue;
        }
        let sel = value(selected, i).filter(|s| (1..=N_ALGORITHMS as u8).contains(s)).unwrap_or(1);
        let sens_sel = value(alg_cols[usize::from(sel) - 1].2, i).unwrap_or(f64::NAN);
        let energy: f64 = wave.iter().map(|&v| f64::from(v) - mean).sum();
        let (dx, dy) = offsets.get(&shot).map_or((0.0, 0.0), |o| (o.dx, o.dy));
        let collocation_dz = offsets.get(&shot).map(|o| o.dz).filter(|dz| dz.is_finite());
        let segment = offsets.get(&shot).map_or_else(|| shot.to_string(), |o| o.segment_id.clone());
        let real = RealShot {
            shot_number: shot,
            track: format!("{}/{}", granule.value(i), beam.value(i)),
            beam_type: bt,
            noise: Noise { mean, stddev: sd },
            nominal_noise_stddev: nominal_noise_stddev(bt),
            energy,
            sample_count: wave.len(),
            bin0: e0 - n_geoid,
            lastbin: e1 - n_geoid,
            wave: wave.iter().map(|&v| (f64::from(v) - mean) as f32).collect(),
            selected: sel,
            algorithms,
            segment,
            collocation_dz,
            pulse: pulses.of(&c, i)?,
            strata: Strata {
                forest_type: forest.get(&shot).cloned().unwrap_or_else(|| classes::UNKNOWN.to_string()),
                phenology: classes::phenology(value(leaf_off, i)).to_string(),
                sensitivity_group: classes::sensitivity_group(sens_sel).unwrap_or(classes::UNKNOWN).to_string(),
                beam_type: beam_type.value(i).to_string(),
                ..Default::default()
            },
        };
        out.push(Pending {
            real,
            footprint: Footprint::at(shot.to_string(), px + dx, py + dy),
            reported: (px, py),
            short_segment: false,
            ranked: false,
        });
    }
    Ok(())
}

/// The vertical reference of the re-collocation: the median of the collocation segments'
/// vertical offsets (GEDI − N − ALS, m), one value for all (0 without offsets).
fn reference_dz(offsets: &HashMap<u64, crate::dataset::offsets::AppliedOffset>) -> f64 {
    let by_segment: HashMap<&str, f64> =
        offsets.values().filter(|o| o.dz.is_finite()).map(|o| (o.segment_id.as_str(), o.dz)).collect();
    let mut dz: Vec<f64> = by_segment.into_values().collect();
    dz.sort_by(|a, b| a.total_cmp(b));
    if dz.is_empty() {
        0.0
    } else {
        dz[dz.len() / 2]
    }
}

/// The centre of the [`site_grid`] of each short segment's shots: the segment's horizontal
/// collocation redone with the vertical offset fixed at `dz`
/// ([`crate::kernels::collocate::horizontal_offset_at`]), as an absolute position per shot.
fn recollocate(als: &AlsTable, pending: &[Pending], dz: f64) -> Result<HashMap<u64, (f64, f64)>> {
    use crate::kernels::collocate::{
        horizontal_offset_at, profile::real_profile, CollocateConfig, ShotInput, SUB_BATCH,
    };
    let cfg = CollocateConfig::new(RECOLLOCATE_SHIFT_M, RECOLLOCATE_STEP_M)?;
    let half = cfg.support_half_width();
    let mut segments: std::collections::BTreeMap<&str, Vec<&Pending>> = Default::default();
    pending
        .iter()
        .filter(|p| p.short_segment && p.ranked)
        .for_each(|p| segments.entry(p.real.segment.as_str()).or_default().push(p));
    let inputs: Vec<(&[&Pending], Vec<ShotInput>)> = segments
        .values()
        .map(|shots| {
            let inputs = shots
                .iter()
                .filter_map(|p| {
                    let r = &p.real;
                    let real = real_profile(&r.wave, r.bin0, r.lastbin, cfg.model.res).ok()?;
                    Some(ShotInput { x: p.reported.0, y: p.reported.1, real, pulse: r.pulse.clone() })
                })
                .collect();
            (shots.as_slice(), inputs)
        })
        .collect();
    // Whole segments, about SUB_BATCH shots at a time, share one read, like the collocation's.
    let mut out = HashMap::new();
    let mut start = 0;
    while start < inputs.len() {
        let (mut end, mut n) = (start, 0);
        while end < inputs.len() && n < SUB_BATCH {
            n += inputs[end].1.len();
            end += 1;
        }
        let chunk = &inputs[start..end];
        start = end;
        let boxes: Vec<crate::dataset::als::BBox> =
            chunk.iter().flat_map(|(_, i)| i).map(|s| [s.x - half, s.y - half, s.x + half, s.y + half]).collect();
        if boxes.is_empty() {
            continue;
        }
        let (cloud, _) = als.xyz_in_boxes(&boxes)?;
        for (shots, inputs) in chunk.iter().filter(|(_, i)| !i.is_empty()) {
            if let Some((ox, oy)) = horizontal_offset_at(inputs, &cloud, &cfg, dz) {
                for p in shots.iter() {
                    out.insert(p.real.shot_number, (p.reported.0 + ox, p.reported.1 + oy));
                }
            }
        }
    }
    Ok(out)
}

/// A shot to simulate: its real facts, whether its segment is short, whether it is ranked, and
/// its sites.
type ToSimulate = (RealShot, bool, bool, Vec<(f64, f64)>);

fn simulate_cases(
    als: &AlsTable,
    pending: Vec<Pending>,
    centres: &HashMap<u64, (f64, f64)>,
    report: &mut CaseReport,
    on_shot: &(dyn Fn() + Sync),
) -> Result<Vec<(bool, ShotCase)>> {
    if pending.is_empty() {
        return Ok(Vec::new());
    }
    let (nominal, variants) = configs();
    let fmax = FSIGMA_GRID[FSIGMA_GRID.len() - 1] as f32;
    let half = sim::footprint::read_radius(fmax);
    let grid = site_grid();
    // Site 0 at the collocated position, then the grid around the short segment's re-collocated
    // centre (every width) or around the collocated position (a long segment: nominal width). A
    // shot that is not ranked: site 0 alone, at the nominal width.
    let items: Vec<(Footprint, ToSimulate)> = pending
        .into_iter()
        .map(|p| {
            let (x0, y0) = (p.footprint.x, p.footprint.y);
            let centre = if p.short_segment { centres.get(&p.real.shot_number).copied() } else { Some((x0, y0)) };
            let mut sites = vec![(x0, y0)];
            if let Some((cx, cy)) = centre.filter(|_| p.ranked) {
                sites.extend(grid.iter().map(|(dx, dy)| (cx + dx, cy + dy)));
            }
            (p.footprint, (p.real, p.short_segment, p.ranked, sites))
        })
        .collect();
    let mut cases = Vec::new();
    for block in crate::dataset::blocks::blocks(items) {
        let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for (x, y) in block.iter().flat_map(|(_, (_, _, _, sites))| sites.iter().copied()) {
            bb = [bb[0].min(x - half), bb[1].min(y - half), bb[2].max(x + half), bb[3].max(y + half)];
        }
        let (points, _) = als.points_in(bb)?;
        let (fps, reals): (Vec<Footprint>, Vec<ToSimulate>) = block.into_iter().unzip();
        let nom = sim::simulate(&points, &fps, &nominal)?;
        // Sites simulated at every width (a ranked shot's site 0, a short segment's grid) and at
        // the nominal one (a long segment's grid, a shot not ranked), each as one footprint:
        // index[j][k] = (light, i) for shot j, site k.
        let (mut full, mut light): (Vec<Footprint>, Vec<Footprint>) = (Vec::new(), Vec::new());
        let mut index: Vec<Vec<(bool, usize)>> = Vec::with_capacity(fps.len());
        for (f, (_, short, ranked, sites)) in fps.iter().zip(&reals) {
            index.push(
                sites
                    .iter()
                    .enumerate()
                    .map(|(k, &(x, y))| {
                        let is_light = !ranked || (k > 0 && !short);
                        let list = if is_light { &mut light } else { &mut full };
                        list.push(Footprint { id: f.id.clone(), x, y, pulse: f.pulse.clone() });
                        (is_light, list.len() - 1)
                    })
                    .collect(),
            );
        }
        let vars = variants.iter().map(|cfg| sim::simulate(&points, &full, cfg)).collect::<Result<Vec<_>, _>>()?;
        let light_vars = sim::simulate(&points, &light, &variants[NOMINAL_WIDTH])?;
        for (j, (mut real, short, ranked, positions)) in reals.into_iter().enumerate() {
            on_shot();
            let Ok(n) = &nom[j] else {
                count_dropped(report, "footprint not simulated (no ALS points or partly covered)");
                continue;
            };
            let count = n.get(Weighting::Count);
            let (Some(ground), Some(rh)) = (count.truth.als_ground, count.rh) else {
                count_dropped(report, "simulated footprint has no ground");
                continue;
            };
            let mut sites = Vec::with_capacity(index[j].len());
            let mut dz = f64::NAN;
            let (x0, y0) = positions[0];
            for (k, &(is_light, i)) in index[j].iter().enumerate() {
                let vs: Vec<&sim::SimulatedFootprint> = if is_light {
                    light_vars[i].as_ref().ok().into_iter().collect()
                } else {
                    vars.iter().filter_map(|v| v[i].as_ref().ok()).collect()
                };
                let complete = vs.len() == if is_light { 1 } else { FSIGMA_GRID.len() };
                // The collocated position keeps the nominal run's ground; another site needs
                // its widths and a ground of its own, or is kept empty (never chosen) so that
                // site k is the same offset for every shot of the segment.
                let nominal_width = if is_light { vs.first() } else { vs.get(NOMINAL_WIDTH) };
                let site_ground = if k == 0 {
                    Some(ground)
                } else {
                    nominal_width.and_then(|v| v.get(Weighting::Count).truth.als_ground)
                };
                let offset = (positions[k].0 - x0, positions[k].1 - y0);
                match site_ground {
                    Some(g) if complete => {
                        dz = vs[0].dz;
                        sites.push(site_of(&vs, g, offset));
                    }
                    _ if k == 0 => break,
                    _ => sites.push(Site { z0: f64::NAN, variants: Vec::new(), als_ground: f64::NAN, offset }),
                }
            }
            if sites.is_empty() {
                count_dropped(report, "footprint not simulated at every footprint width");
                continue;
            }
            real.strata.slope_class = classes::slope_class(count.truth.slope_deg.map(f64::from)).to_string();
            let cover = f64::from(count.truth.als_cover);
            real.strata.cover_class = classes::cover_class((cover >= 0.0).then_some(cover)).to_string();
            cases.push((
                ranked,
                ShotCase {
                    real,
                    sim: Arc::new(SimShot { dz, sites, short_segment: short, rh_nominal: rh.to_vec() }),
                    mismatch: [false; N_ALGORITHMS],
                },
            ));
        }
    }
    Ok(cases)
}

/// What `diagnose` wrote (or found already written for the same inputs).
#[derive(Debug, Clone)]
pub struct DiagnosisOutput {
    pub json: DiagnosisJson,
    pub files: Vec<PathBuf>,
    /// The inputs were those of the diagnosis already in the folder: nothing was recomputed.
    pub reused: bool,
}

/// The key of a diagnosis's inputs (a hex SHA-256 over these facts), built from content keys as
/// `run`'s work is: this binary's content, the effects, pulse (a pulse file's content) and
/// self-test asked for; each granule of `shots/` by the content hashes and area it was ingested
/// from (`ops::run::granule_inputs`); and the content of the files of `tiles/` (hence of what
/// `als/` holds), `offsets/` and `strata/` (files above 256 MiB by their length and 32 blocks,
/// `dataset::granule_hash`). Stored in diagnosis.json: a re-run on the same inputs — even a copy
/// of the dataset elsewhere — reuses the diagnosis; `--force` recomputes.
fn inputs_key(ds: &Dataset, kinds: &[EffectKind], opts: &DiagnoseOptions) -> Result<String> {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let (pulse, twins, ranked) = (&opts.pulse, opts.twins, opts.ranked_shots);
    h.update(format!(
        "gedisim {}\0{}\0{pulse:?}\0{twins}\0{ranked}\0",
        env!("CARGO_PKG_VERSION"),
        kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join(",")
    ));
    // The program by its content: a rebuild of the same version counts.
    if let Ok(exe) = std::env::current_exe() {
        h.update(format!("{}\0", dataset::granule_hash(&exe)?));
    }
    if let PulseModel::File(p) = pulse {
        h.update(format!("{}\0", dataset::content_hash(p)?));
    }
    // shots/: each granule by what it was ingested from, as `run` keys it.
    for f in ds.visible_files(tables::SHOTS).unwrap_or_default() {
        let (key, inputs) = crate::ops::run::granule_inputs(ds, &f)?;
        h.update(format!("shots {key}\0{inputs}\0"));
    }
    // als/ is what the rows of tiles/ say was read (each tile's content hash, the cells read);
    // tiles/, offsets/ and strata/ by their files' content.
    for table in [tables::TILES, tables::OFFSETS, tables::STRATA] {
        for f in ds.visible_files(table).unwrap_or_default() {
            let name = f.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            h.update(format!("{table} {name}\0{}\0", dataset::granule_hash(&f)?));
        }
    }
    Ok(hex::encode(h.finalize()))
}

/// The diagnosis in `out` when it was made from inputs of key `key` and all its files are there.
fn reusable(out: &Path, key: &str) -> Option<DiagnosisOutput> {
    let text = std::fs::read_to_string(out.join("diagnosis.json")).ok()?;
    let json: DiagnosisJson = serde_json::from_str(&text).ok()?;
    let mut files: Vec<PathBuf> = json.files.iter().map(|f| out.join(f)).collect();
    let complete = !files.is_empty() && files.iter().all(|f| f.is_file());
    files.push(out.join("diagnosis.json"));
    (json.inputs_key.as_deref() == Some(key) && complete).then_some(DiagnosisOutput { json, files, reused: true })
}

/// Collocation of a dataset the diagnosis makes: per beam (the baseline's horizontal collocation),
/// every run solved however short, with the diagnosis's pulse.
pub fn diagnosis_collocation(pulse: &PulseModel) -> CollocateOptions {
    CollocateOptions {
        level: Level::Beam,
        segment: 40,
        max_shift: 10.0,
        step: 1.0,
        min_segment: 1,
        pulse: pulse.clone(),
    }
}

/// Half-width (m) of the ALS window a shot's case needs: the largest shift of its sites' centre
/// (the collocation's, or a short segment's re-collocation around the reported position), the
/// grid of sites around it, and the read radius of the widest footprint tried.
pub fn window_half(max_shift: f64) -> f64 {
    let fmax = FSIGMA_GRID[FSIGMA_GRID.len() - 1] as f32;
    max_shift.max(RECOLLOCATE_SHIFT_M) + f64::from(SITE_HALF) * SITE_STEP_M + sim::footprint::read_radius(fmax)
}

/// Where each shot's pulse in the nominal chain comes from.
enum ShotPulseSource {
    /// The study's Gaussian.
    Gaussian,
    /// The shot's `tx_waveform` at this reference point and bin size (m).
    Recorded(PulseReference, f64),
    /// One pulse for every shot.
    Fixed(Arc<sim::Pulse>),
}

impl ShotPulseSource {
    fn new(pulse: &PulseModel, res: f64) -> Result<ShotPulseSource> {
        if let Some(p) = crate::io::pulse::fixed_pulse(pulse, res)? {
            return Ok(ShotPulseSource::Fixed(Arc::new(p.resampled(res))));
        }
        Ok(match pulse {
            PulseModel::Recorded(r) => ShotPulseSource::Recorded(*r, res),
            _ => ShotPulseSource::Gaussian,
        })
    }

    /// The pulse of row `i` (`None`: the Gaussian, also for a shot without a usable record).
    fn of(&self, c: &read::Columns, i: usize) -> Result<Option<Arc<sim::Pulse>>> {
        Ok(match self {
            ShotPulseSource::Gaussian => None,
            ShotPulseSource::Fixed(p) => Some(p.clone()),
            ShotPulseSource::Recorded(r, res) => c
                .f32_list("tx_waveform", i)?
                .and_then(|tx| crate::dataset::shots::recorded_pulse(&tx, *r, *res))
                .map(Arc::new),
        })
    }
}

/// What `gedisim diagnose` reads.
#[derive(Debug, Clone)]
pub enum DiagnoseInput {
    /// A dataset after `gedisim run` (or at least both ingests; collocated first if it has no
    /// offsets).
    Dataset(PathBuf),
    /// The first half of `gedisim run` into `<out>/dataset` (its `out` and `collocate` are set
    /// here): tiles, granules and land cover ingested, collocated per beam.
    Chain(Box<RunOptions>),
}

/// What `gedisim diagnose` did.
#[derive(Debug, Clone)]
pub struct DiagnoseReport {
    /// The ingest and collocation of [`DiagnoseInput::Chain`].
    pub chain: Option<RunReport>,
    /// The collocation of a dataset that had no offsets.
    pub collocated: Option<CollocateReport>,
    pub output: DiagnosisOutput,
}

/// What a diagnosis is asked for.
#[derive(Debug, Clone)]
pub struct DiagnoseOptions {
    /// The effects tried (names of `diagnose::fit::FITTED_EFFECTS`; empty = all).
    pub effects: Vec<String>,
    /// The shots' transmit pulse in the nominal chain.
    pub pulse: PulseModel,
    /// Twin sets per planted hypothesis in the self-test (`diagnose::selftest`); 0 = none.
    pub twins: usize,
    /// The configuration, the effects and the self-test on the shots of tracks drawn up to this
    /// many shots (`diagnose::sample`); 0 = every shot.
    pub ranked_shots: usize,
    /// Diagnose again even when `out` holds the diagnosis of the same inputs.
    pub force: bool,
}

impl DiagnoseOptions {
    /// Every effect, each shot's recorded pulse, the default self-test.
    pub fn new() -> DiagnoseOptions {
        DiagnoseOptions {
            effects: Vec::new(),
            pulse: PulseModel::Recorded(Default::default()),
            twins: diagnose::selftest::TWINS,
            ranked_shots: diagnose::sample::RANKED_SHOTS,
            force: false,
        }
    }
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions::new()
    }
}

/// `gedisim diagnose`: the dataset (made or collocated first when needed) diagnosed into `out`.
pub fn diagnose(
    input: DiagnoseInput,
    out: &Path,
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnoseReport> {
    let pulse = &opts.pulse;
    // What this command writes into a dataset (the chain's tables, a missing `offsets/`) it writes
    // as the dataset's one writer: the lock is held until the diagnosis ends.
    let (ds, chain) = match input {
        DiagnoseInput::Dataset(root) => {
            let ds = Dataset::open(&root)?;
            let ds = if ds.has_table(tables::OFFSETS) { ds } else { ds.as_writer()? };
            (ds, None)
        }
        DiagnoseInput::Chain(opts) => {
            let collocate = diagnosis_collocation(pulse);
            let als_window = Some(window_half(collocate.max_shift));
            let opts = RunOptions { out: out.join("dataset"), collocate, als_window, ..*opts };
            let (ds, report) = crate::ops::run::ingest_and_collocate(&opts, progress)?;
            (ds, Some(report))
        }
    };
    let collocated = if ds.has_table(tables::OFFSETS) {
        None
    } else {
        Some(crate::ops::collocate::collocate(&ds, &diagnosis_collocation(pulse), progress)?)
    };
    let output = diagnose_dataset(&ds, out, opts, progress)?;
    Ok(DiagnoseReport { chain, collocated, output })
}

/// Diagnose the dataset into `out`: its cases read and simulated, then each effect fitted and
/// scored as one [`Step::DiagnoseFit`] (each effect a note) — unless `out` holds the diagnosis
/// of the same inputs ([`inputs_key`]) and `opts.force` is false, which is then returned as it is.
pub fn diagnose_dataset(
    ds: &Dataset,
    out: &Path,
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnosisOutput> {
    let (effects, pulse) = (&opts.effects, &opts.pulse);
    let kinds: Vec<EffectKind> = if effects.is_empty() {
        diagnose::fit::FITTED_EFFECTS.to_vec()
    } else {
        effects
            .iter()
            .map(|e| {
                EffectKind::from_name(e).filter(|k| diagnose::fit::FITTED_EFFECTS.contains(k)).ok_or_else(|| {
                    Error::Usage(format!(
                        "--effects: '{e}' is not an effect the diagnosis fits (known: {})",
                        diagnose::fit::FITTED_EFFECTS.map(EffectKind::name).join(", ")
                    ))
                })
            })
            .collect::<Result<_>>()?
    };
    let key = inputs_key(ds, &kinds, opts)?;
    if let Some(done) = reusable(out, &key).filter(|_| !opts.force) {
        return Ok(done);
    }
    let Cases { ranked: cases, located, report } = read_cases(ds, pulse, opts.ranked_shots, progress)?;
    if cases.len() < 4 {
        return Err(Error::file(
            ds.root().join(tables::SHOTS),
            format!(
                "only {} usable shot(s) for the diagnosis (need ≥ 4): {}",
                cases.len(),
                dropped_text(&report.dropped)
            ),
        ));
    }
    progress.start(Step::DiagnoseFit, 0);
    let d = diagnose::diagnose(cases, &located, &kinds, opts.twins, &|step| progress.note(step));
    drop(located);
    progress.finish();
    std::fs::create_dir_all(out).map_err(|e| Error::file(out, e))?;
    // The old diagnosis.json goes first: tables half rewritten by an interrupted run are never
    // taken for those of the earlier key.
    let path = out.join("diagnosis.json");
    if path.exists() {
        std::fs::remove_file(&path).map_err(|e| Error::file(&path, e))?;
    }
    let mut files = write_tables(&d, out)?;
    files.extend(write_figures(&d, out)?);
    let names = files.iter().filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned())).collect();
    let json = DiagnosisJson {
        summary: summary_lines(&d),
        dataset: Some(ds.root().canonicalize().unwrap_or_else(|_| ds.root().to_path_buf()).display().to_string()),
        inputs_key: Some(key),
        files: names,
        ..DiagnosisJson::of(&d, report.shots_read, &report.dropped, opts.ranked_shots)
    };
    // diagnosis.json last: a diagnosis interrupted before it is never reused.
    let text = serde_json::to_string_pretty(&json).map_err(|e| Error::file(&path, e))?;
    crate::dataset::write_atomic(&path, text.as_bytes())?;
    files.push(path);
    Ok(DiagnosisOutput { json, files, reused: false })
}

/// "reason (n), …" of (reason, count) pairs.
pub fn dropped_text<S: AsRef<str>>(dropped: &[(S, usize)]) -> String {
    if dropped.is_empty() {
        return "none dropped".into();
    }
    dropped.iter().map(|(k, n)| format!("{} ({n})", k.as_ref())).collect::<Vec<_>>().join(", ")
}

fn batch(fields: Vec<(&str, Arc<dyn Array>)>) -> Result<RecordBatch> {
    let schema =
        Schema::new(fields.iter().map(|(n, a)| Field::new(*n, a.data_type().clone(), true)).collect::<Vec<_>>());
    RecordBatch::try_new(Arc::new(schema), fields.into_iter().map(|(_, a)| a).collect())
        .map_err(|e| Error::table("diagnosis", e))
}

fn floats(v: impl IntoIterator<Item = f64>) -> Arc<dyn Array> {
    Arc::new(Float64Array::from_iter_values(v))
}

fn texts<S: AsRef<str>>(v: impl IntoIterator<Item = S>) -> Arc<dyn Array> {
    Arc::new(StringArray::from_iter_values(v))
}

fn write_tables(d: &Diagnosis, out: &Path) -> Result<Vec<PathBuf>> {
    let w = &d.where_;
    let mut files = Vec::new();
    let p = &w.percentiles;
    files.extend(crate::ops::report::write_named_table(
        out,
        "where_percentiles",
        &batch(vec![
            ("rh", floats(p.iter().map(|p| p.k as f64))),
            ("bias", floats(p.iter().map(|p| p.bias))),
            ("bias_als_frame", floats(p.iter().map(|p| p.bias_als_frame))),
            ("rmse", floats(p.iter().map(|p| p.rmse))),
            ("sb", floats(p.iter().map(|p| p.sb))),
            ("sdsd", floats(p.iter().map(|p| p.sdsd))),
            ("lcs", floats(p.iter().map(|p| p.lcs))),
        ])?,
    )?);
    let s = &w.strata;
    files.extend(crate::ops::report::write_named_table(
        out,
        "where_strata",
        &batch(vec![
            ("kind", texts(s.iter().map(|s| s.kind.as_str()))),
            ("label", texts(s.iter().map(|s| s.label.as_str()))),
            ("n_shots", floats(s.iter().map(|s| s.n_shots as f64))),
            ("mean_abs_bias_rh1_99", floats(s.iter().map(|s| s.metrics.mean_abs_bias_rh))),
            ("msd", floats(s.iter().map(|s| s.metrics.msd))),
            ("sb", floats(s.iter().map(|s| s.metrics.sb))),
            ("sdsd", floats(s.iter().map(|s| s.metrics.sdsd))),
            ("lcs", floats(s.iter().map(|s| s.metrics.lcs))),
            ("ground_bias_m", floats(s.iter().map(|s| s.metrics.ground_bias))),
            ("share_of_squared_error", floats(s.iter().map(|s| s.share_of_squared_error))),
        ])?,
    )?);
    let r = &w.waveform;
    files.extend(crate::ops::report::write_named_table(
        out,
        "waveform_residual",
        &batch(vec![
            ("height_m", floats(r.height.iter().copied())),
            ("real", floats(r.real.iter().copied())),
            ("simulated", floats(r.simulated.iter().copied())),
            ("residual", floats(r.residual.iter().copied())),
        ])?,
    )?);
    let c = &d.configuration;
    let t = &c.trials;
    files.extend(crate::ops::report::write_named_table(
        out,
        "configurations",
        &batch(vec![
            ("configuration", texts(t.iter().map(|t| t.config.label()))),
            ("weighting", texts(t.iter().map(|t| t.config.weighting.name()))),
            (
                "chosen",
                Arc::new(arrow::array::BooleanArray::from(t.iter().map(|t| t.config == c.chosen).collect::<Vec<_>>())),
            ),
            ("mean_abs_bias_rh1_99", floats(t.iter().map(|t| t.metrics.mean_abs_bias))),
            ("systematic_gap", floats(t.iter().map(|t| t.metrics.systematic))),
            ("msd", floats(t.iter().map(|t| t.metrics.msd))),
            ("rh98_bias", floats(t.iter().map(|t| t.metrics.bias_rh[97]))),
            ("rh50_bias", floats(t.iter().map(|t| t.metrics.bias_rh[49]))),
            ("ground_bias_m", floats(t.iter().map(|t| t.metrics.ground_bias))),
            ("waveform_chi2", floats(t.iter().map(|t| t.waveform_chi2))),
            ("waveform_chi2_profiled", floats(t.iter().map(|t| t.waveform_chi2_profiled))),
        ])?,
    )?);
    let g = &c.ground;
    files.extend(crate::ops::report::write_named_table(
        out,
        "ground_by_algorithm",
        &batch(vec![
            ("algorithm", floats(g.iter().map(|g| f64::from(g.algorithm)))),
            ("n_shots", floats(g.iter().map(|g| g.n as f64))),
            ("ground_bias_m", floats(g.iter().map(|g| g.bias_m))),
            ("ci95_lo", floats(g.iter().map(|g| g.ci95[0]))),
            ("ci95_hi", floats(g.iter().map(|g| g.ci95[1]))),
        ])?,
    )?);
    for (name, trials) in [("effects", &d.ranking.effects), ("ladder", &d.ranking.ladder)] {
        files.extend(crate::ops::report::write_named_table(
            out,
            name,
            &batch(vec![
                ("step", floats((0..trials.len()).map(|i| i as f64 + 1.0))),
                ("effect", texts(trials.iter().map(|t| t.effect.name()))),
                ("params", texts(trials.iter().map(|t| serde_json::to_string(&params(&t.effect)).unwrap_or_default()))),
                ("frame", texts(trials.iter().map(|t| t.held_out.frame.name()))),
                ("mean_abs_bias_before", floats(trials.iter().map(|t| t.held_out.before.mean_abs_bias))),
                ("mean_abs_bias_after", floats(trials.iter().map(|t| t.held_out.after.mean_abs_bias))),
                ("shrink", floats(trials.iter().map(|t| t.held_out.shrink))),
                ("shrink_ci95_lo", floats(trials.iter().map(|t| t.held_out.ci95[0]))),
                ("shrink_ci95_hi", floats(trials.iter().map(|t| t.held_out.ci95[1]))),
                ("msd_before", floats(trials.iter().map(|t| t.held_out.before.msd))),
                ("msd_after", floats(trials.iter().map(|t| t.held_out.after.msd))),
                (
                    "waveform_shrink",
                    Arc::new(Float64Array::from(
                        trials.iter().map(|t| t.held_out.profile_shrink()).collect::<Vec<_>>(),
                    )),
                ),
                ("score", floats(trials.iter().map(|t| t.held_out.score()))),
            ])?,
        )?);
    }
    Ok(files)
}

fn write_figures(d: &Diagnosis, out: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let profile = |label: &str, b: &[f64; N_PCT]| {
        (label.to_string(), (0..N_PCT).map(|k| ((k + 1) as f64, b[k])).collect::<Vec<_>>())
    };
    let mut rh = vec![
        profile("baseline (noise-free)", &d.where_.overall.bias_rh),
        profile("chosen configuration", &d.nominal.bias_rh),
    ];
    let mut als = vec![
        profile("baseline (noise-free)", &d.where_.overall.bias_als),
        profile("chosen configuration", &d.nominal.bias_als),
    ];
    let mut names = Vec::new();
    for t in &d.ranking.ladder {
        names.push(t.effect.name());
        let label = format!("+ {}", names.join(" + "));
        rh.push(profile(&label, &t.held_out.after.bias_rh));
        als.push(profile(&label, &t.held_out.after.bias_als));
    }
    if d.ranking.ladder.is_empty() {
        if let Some(t) = d.ranking.effects.first() {
            let label = format!("+ {} (not significant)", t.effect.name());
            rh.push(profile(&label, &t.held_out.after.bias_rh));
            als.push(profile(&label, &t.held_out.after.bias_als));
        }
    }
    let fig = LinePanels {
        title: "Held-out RH bias (simulated − GEDI) before and after the diagnosed effects".into(),
        x_desc: "RH percentile".into(),
        y_desc: "bias, simulated − GEDI (m)".into(),
        panels: vec![("RH frame (own grounds)".into(), rh), ("ALS frame (heights above the ALS ground)".into(), als)],
        zero_line: true,
        legend_lower: false,
        own_y: false,
    };
    files.extend(figures::render(&fig, out, "bias_profile_before_after")?);
    let r = &d.where_.waveform;
    // In % of the waveform energy, so that the residual's ticks stay readable.
    let series = |label: &str, v: &[f64]| {
        (label.to_string(), r.height.iter().zip(v).map(|(&h, &y)| (h, 100.0 * y)).collect::<Vec<_>>())
    };
    let fig = LinePanels {
        title: format!("Mean normalised waveform by height above the ALS ground ({} shots)", r.n_shots),
        x_desc: "height above ALS ground (m)".into(),
        y_desc: "% of the waveform energy per 0.5 m".into(),
        panels: vec![
            ("real and simulated (baseline)".into(), vec![series("real", &r.real), series("simulated", &r.simulated)]),
            ("residual simulated − real".into(), vec![series("residual", &r.residual)]),
        ],
        zero_line: true,
        legend_lower: false,
        own_y: true,
    };
    files.extend(figures::render(&fig, out, "waveform_residual")?);
    Ok(files)
}

/// "shrink 62 % (95 % CI 40–80 %)", saying so when the estimate lies outside its interval (as printed): the
/// resampled tracks then add a spread between tracks that the systematic gap of all tracks together does not have
/// (docs/diagnosis.md, "Which effect, and how far").
fn shrink_text(c: &crate::kernels::diagnose::rank::Comparison) -> String {
    let [shrink, lo, hi] = [c.shrink, c.ci95[0], c.ci95[1]].map(|x| (100.0 * x).round());
    let outside = if (lo..=hi).contains(&shrink) || !(lo <= hi) {
        ""
    } else {
        ", the estimate outside its interval: the gap differs between tracks more than within them"
    };
    format!("shrink {shrink:.0} % (95 % CI {lo:.0}–{hi:.0} %{outside})")
}

/// The configuration stage in a few lines: the choice and how far it takes the study's gap, every
/// configuration's gap, the ground bias per algorithm.
fn configuration_lines(c: &crate::kernels::diagnose::configuration::ConfigurationChoice) -> Vec<String> {
    let h = &c.held_out;
    let folds = if c.fold_chosen.iter().all(|k| *k == c.chosen) {
        String::new()
    } else {
        format!(" (the calibration folds chose {} and {})", c.fold_chosen[0].label(), c.fold_chosen[1].label())
    };
    let rows: Vec<String> = c
        .trials
        .iter()
        .map(|t| {
            format!(
                "{} {:.2} m, MSD {:.2} m², RH98 {:+.2} m",
                t.config.label(),
                t.metrics.mean_abs_bias,
                t.metrics.msd,
                t.metrics.bias_rh[97]
            )
        })
        .collect();
    let grounds: Vec<String> = c
        .ground
        .iter()
        .filter(|g| g.n > 0)
        .map(|g| format!("a{} {:+.2} m ({:+.2} to {:+.2})", g.algorithm, g.bias_m, g.ci95[0], g.ci95[1]))
        .collect();
    let mut lines = vec![
        format!(
            "Configuration first (weighting × pulse, chosen on calibration tracks by the waveforms at the best \
             ground/vegetation ratio, scored on held-out ones): {}{folds}; from the study's count + Gaussian 15 ns \
             the held-out gap goes {:.2} → {:.2} m at ρ = 1 ({}). A configuration is never reported as an effect: \
             the causes below, a ratio ρ among them, are ranked on top of it.",
            c.chosen.label(),
            h.before.mean_abs_bias,
            h.after.mean_abs_bias,
            shrink_text(h)
        ),
        format!("  every configuration (mean |RH bias| RH1–RH99, MSD, RH98 bias): {}.", rows.join("; ")),
    ];
    if let Some(best) = c.least_biased_algorithm() {
        lines.push(format!(
            "  ground bias (GEDI − ALS, 95 % CI) per L2A algorithm: {}; least biased: a{}.",
            grounds.join(", "),
            best.algorithm
        ));
    }
    lines
}

/// "its ground test failed: β 0.05 (95 % CI −0.3 to 0.4) …" (docs/diagnosis.md, "Geolocation").
fn ground_test_text(g: &crate::kernels::diagnose::geolocation::GroundTest) -> String {
    format!(
        "its ground test failed: the ground elevations GEDI reports follow the positions the canopy asks for with \
         slope β {:.2} (95 % CI {:.2} to {:.2}, needs ≥ {}; {} shots, predicted changes {:.2} m RMS), so the \
         re-placement mends the model rather than the positions",
        g.beta,
        g.ci95[0],
        g.ci95[1],
        crate::kernels::diagnose::geolocation::MIN_BETA_LOWER,
        g.n_shots,
        g.rms_predicted_m
    )
}

/// An effect's parameters as `name = value, …` (numbers to 3 decimals), in its own order.
pub fn params_text(e: &crate::kernels::scenario::effects::Effect) -> String {
    let p: Vec<(String, ParamValue)> = e.params().into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    crate::kernels::diagnose::json::params_text(&p)
}

/// The self-test in one line: what the twins of each planting were named first, and the named
/// effect's recovery.
fn self_test_line(t: &SelfTest, verdict: &Verdict) -> String {
    let outcome = |n: &Option<String>| n.clone().unwrap_or_else(|| "nothing".into());
    let plantings: Vec<String> = t
        .plantings
        .iter()
        .map(|p| {
            let what: Vec<String> = p.outcomes().iter().map(|(n, k)| format!("{} {k}", outcome(n))).collect();
            let planted = match &p.effect {
                Some(e) => format!("{} planted ({})", e.name(), params_text(e)),
                None => "nothing planted".into(),
            };
            format!("{planted} → named first: {}", what.join(", "))
        })
        .collect();
    let head = match t.subject(verdict) {
        Some(e) => match (t.planting(Some(e)), t.planting(None)) {
            (Some(p), Some(none)) => format!(
                "on data like yours, {e} was named first in {} of {} twins where it was planted and in {} of {} \
                 where nothing was",
                p.count(Some(e)),
                p.named.len(),
                none.count(Some(e)),
                none.named.len()
            ),
            _ => String::new(),
        },
        None => String::new(),
    };
    format!(
        "Self-test ({} twin sets of these shots per hypothesis, made from {} and ranked the same way): {head}. {}.",
        t.twins,
        t.configuration.label(),
        plantings.join("; ")
    )
}

/// The diagnosis in a few lines a scientist can read.
pub fn summary_lines(d: &Diagnosis) -> Vec<String> {
    let mut lines = Vec::new();
    let w = &d.where_;
    let ranked = if d.n_shots < d.n_located {
        format!(
            " The configuration, the effects and the self-test use the {} shots of {} tracks drawn at random \
             (--ranked-shots); where the gap lies uses them all.",
            d.n_shots, d.n_tracks
        )
    } else {
        String::new()
    };
    lines.push(format!(
        "{} shots on {} tracks.{ranked} Signs: RH bias = simulated − GEDI RH; ground bias = GEDI ground − ALS \
         ground (positive: GEDI's ground is higher; GEDI's brought into the ALS datum through the geoid).",
        d.n_located, d.n_located_tracks
    ));
    lines.push(format!(
        "Baseline (the study's simulation — noise-free, 15 ns Gaussian pulse, at the collocated position — against \
         each shot's L2A selected algorithm, before the study's filters): mean |RH bias| over RH1–RH99 {:.2} m, \
         ground bias {:+.2} m.",
        w.overall.mean_abs_bias_rh, w.overall.ground_bias
    ));
    let (k, b) = w
        .overall
        .bias_rh
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map_or((0, 0.0), |(k, b)| (k + 1, *b));
    let mut place = format!("Where: the largest RH bias is at RH{k} ({b:+.2} m)");
    // Among strata of kinds with at least two labels: the one holding most of the squared error
    // relative to its share of the shots.
    let labels = |kind: &str| w.strata.iter().filter(|s| s.kind == kind).count();
    let worst = w.strata.iter().filter(|s| labels(&s.kind) >= 2 && s.n_shots >= 5).max_by(|a, b| {
        (a.share_of_squared_error / a.n_shots as f64).total_cmp(&(b.share_of_squared_error / b.n_shots as f64))
    });
    if let Some(s) = worst {
        place += &format!(
            "; {} = {} holds {:.0} % of the squared error with {:.0} % of the shots",
            s.kind,
            s.label,
            100.0 * s.share_of_squared_error,
            100.0 * s.n_shots as f64 / d.n_shots.max(1) as f64
        );
    }
    lines.push(place + ".");
    lines.extend(configuration_lines(&d.configuration));
    lines.push(
        "Held-out gap, what the causes below are judged by (not comparable with the baseline): mean |RH bias| over \
         RH1–RH99 of the full chain (noise twin, L2A a1–a6) on tracks left out of each fit, each effect where it \
         acts: a datum above the ALS ground (ALS frame), a ground detection and the noise above GEDI's own ground \
         (RH frame), the others in both."
            .into(),
    );
    // What a trial changed, in the unit it is judged in.
    let gap = |t: &crate::kernels::diagnose::rank::Trial| match &t.held_out.spread {
        Some(s) => format!("held-out MSD above the noise floor {:.2} → {:.2} m²", s.excess()[0], s.excess()[1]),
        None => {
            format!("held-out gap {:.2} → {:.2} m", t.held_out.before.mean_abs_bias, t.held_out.after.mean_abs_bias)
        }
    };
    let verdict = &d.verdict;
    if d.ranking.unexplained {
        let best = d.ranking.effects.first();
        lines.push(match best {
            Some(t) => format!(
                "Which: unexplained — the best candidate, {} ({}), {}, is not enough to name it{}.",
                t.effect.name(),
                gap(t),
                shrink_text(&t.held_out),
                match &t.ground_test {
                    Some(g) if !g.passes() => format!(" ({})", ground_test_text(g)),
                    Some(_) => format!(
                        " (or its per-shot offsets are under {} m)",
                        crate::kernels::diagnose::rank::MIN_SHOT_SIGMA_M
                    ),
                    None => String::new(),
                }
            ),
            None => "Which: unexplained — no effect could be fitted.".into(),
        });
    } else if *verdict == Verdict::Unexplained {
        let t = &d.ranking.effects[0];
        let (k, n) = d
            .self_test
            .as_ref()
            .and_then(|s| s.planting(None))
            .map_or((0, 0), |p| (p.count(Some(t.effect.name())), p.named.len()));
        lines.push(format!(
            "Which: unexplained — {} ({}, {}) clears the intervals, but twins of these shots without any effect \
             name it first in {k} of {n}: on data like these it is what the chain finds when nothing is there.",
            t.effect.name(),
            gap(t),
            shrink_text(&t.held_out)
        ));
    } else {
        for (i, t) in d.ranking.ladder.iter().enumerate() {
            let params = params_text(&t.effect);
            let gap = gap(t);
            let caveat = match (t.at_bound(), t.equivalent()) {
                (_, Some(e)) => format!(" — equivalent to the simpler {}", e.name()),
                (Some(b), None) => format!(" — fit on the edge of its range ({b}): the effect may not be this one"),
                (None, None) => String::new(),
            };
            lines.push(format!(
                "{} {} ({params}): {gap}, {}{caveat}.",
                if i == 0 { "Which:" } else { "  then" },
                t.effect.name(),
                shrink_text(&t.held_out)
            ));
            match (verdict, &d.self_test) {
                (Verdict::Ambiguous(v), Some(test)) if i == 0 => {
                    let taken: Vec<String> = v[1..]
                        .iter()
                        .filter_map(|m| test.planting(Some(m)))
                        .map(|p| {
                            format!(
                                "{} planted is named {} in {} of {}",
                                p.label(),
                                v[0],
                                p.count(Some(&v[0])),
                                p.named.len()
                            )
                        })
                        .collect();
                    lines.push(format!("  ambiguous: in twins of these shots, {}.", taken.join("; ")));
                }
                (Verdict::Ambiguous(v), None) if i == 0 => lines.push(format!(
                    "  ambiguous: {} explain(s) the gap as well within noise (paired 95 % interval of the shrink \
                     difference contains 0).",
                    v[1..].join(", ")
                )),
                _ => {}
            }
        }
    }
    lines.extend(d.self_test.as_ref().map(|t| self_test_line(t, verdict)));
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shrink_outside_its_interval_is_said_so() {
        let c = |shrink: f64, ci95: [f64; 2]| crate::kernels::diagnose::rank::Comparison {
            frame: crate::kernels::diagnose::gap::Frame::Both,
            before: Default::default(),
            after: Default::default(),
            shrink,
            ci95,
            gain_ci95: [0.0, 0.0],
            shrink_mean_abs_bias: 0.0,
            profile_chi2: [0.0, 0.0],
            spread: None,
        };
        assert_eq!(shrink_text(&c(0.62, [0.40, 0.80])), "shrink 62 % (95 % CI 40–80 %)");
        // As printed: 96.4 % with an interval ending at 96.3 % reads 96 within 42–96.
        assert_eq!(shrink_text(&c(0.964, [0.42, 0.963])), "shrink 96 % (95 % CI 42–96 %)");
        let outside = shrink_text(&c(0.97, [0.42, 0.96]));
        assert!(outside.starts_with("shrink 97 % (95 % CI 42–96 %, the estimate outside its interval"), "{outside}");
    }

    #[test]
    fn the_inputs_key_follows_effects_pulse_and_the_content_of_every_table() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(&dir.path().join("ds")).unwrap();
        let shots = ds.table_file(tables::SHOTS, "g1").unwrap();
        std::fs::write(&shots, b"first").unwrap();
        let pulse = PulseModel::Recorded(Default::default());
        let with = |pulse: &PulseModel, twins, ranked_shots| DiagnoseOptions {
            pulse: pulse.clone(),
            twins,
            ranked_shots,
            ..DiagnoseOptions::new()
        };
        let key = |kinds: &[EffectKind], pulse: &PulseModel| inputs_key(&ds, kinds, &with(pulse, 10, 1500)).unwrap();
        let k0 = key(&[EffectKind::Datum], &pulse);
        assert_eq!(k0, key(&[EffectKind::Datum], &pulse), "the same inputs, the same key");
        assert_ne!(k0, key(&[EffectKind::Datum, EffectKind::Pulse], &pulse), "other effects");
        assert_ne!(k0, key(&[EffectKind::Datum], &PulseModel::Gaussian(None)), "another pulse");
        assert_ne!(k0, inputs_key(&ds, &[EffectKind::Datum], &with(&pulse, 4, 1500)).unwrap(), "another self-test");
        assert_ne!(k0, inputs_key(&ds, &[EffectKind::Datum], &with(&pulse, 10, 0)).unwrap(), "another sample");
        // A new file in a table the diagnosis reads.
        let strata = ds.table_file(tables::STRATA, "strata").unwrap();
        std::fs::write(&strata, b"s").unwrap();
        let k1 = key(&[EffectKind::Datum], &pulse);
        assert_ne!(k0, k1);
        // A shots file rewritten: another size, or the same size at another time.
        std::fs::write(&shots, b"second!").unwrap();
        let k2 = key(&[EffectKind::Datum], &pulse);
        assert_ne!(k1, k2);
        std::fs::write(&shots, b"third!!").unwrap();
        let later = std::time::SystemTime::now() + std::time::Duration::from_secs(5);
        std::fs::File::options().write(true).open(&shots).unwrap().set_modified(later).unwrap();
        assert_ne!(k2, key(&[EffectKind::Datum], &pulse));
        // A file of a table it does not read (the report's) changes nothing.
        let k3 = key(&[EffectKind::Datum], &pulse);
        std::fs::create_dir_all(ds.root().join("report")).unwrap();
        std::fs::write(ds.root().join("report/msd.parquet"), b"r").unwrap();
        assert_eq!(k3, key(&[EffectKind::Datum], &pulse));
        // Content, not times: strata rewritten with the same size at the same time is seen…
        let mtime = |f: &Path| std::fs::metadata(f).unwrap().modified().unwrap();
        let at = mtime(&strata);
        std::fs::write(&strata, b"t").unwrap();
        std::fs::File::options().write(true).open(&strata).unwrap().set_modified(at).unwrap();
        let k4 = key(&[EffectKind::Datum], &pulse);
        assert_ne!(k3, k4);
        // …and a copy of the dataset elsewhere has the same key.
        let copy = Dataset::create(&dir.path().join("copy")).unwrap();
        for (table, name) in [(tables::SHOTS, "g1"), (tables::STRATA, "strata")] {
            let (from, to) = (ds.table_file(table, name).unwrap(), copy.table_file(table, name).unwrap());
            std::fs::copy(&from, &to).unwrap();
            std::fs::File::options().write(true).open(&to).unwrap().set_modified(mtime(&from)).unwrap();
        }
        assert_eq!(k4, inputs_key(&copy, &[EffectKind::Datum], &with(&pulse, 10, 1500)).unwrap());
    }
}
