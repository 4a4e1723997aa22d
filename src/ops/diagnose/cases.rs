//! Plan: the dataset's shots read into the diagnosis's cases — each shot's columns decoded into a
//! [`RealShot`], the ranked tracks drawn, and each short segment re-collocated to centre its sites —
//! before [`super::sites`] simulates them.

use std::collections::HashMap;
use std::sync::Arc;

use super::sites::simulate_cases;
use crate::dataset::als::{AlsTable, BBox};
use crate::dataset::read::{self, value};
use crate::dataset::shots::{col, ShotColumns, ALGORITHMS};
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::diagnose::case::{
    configs, nominal_noise_stddev, RealAlgorithm, RealShot, Strata, RECOLLOCATE_SHIFT_M, RECOLLOCATE_STEP_M,
    SHORT_SEGMENT_SHOTS,
};
use crate::kernels::diagnose::{self, ShotCase};
use crate::kernels::gedi::{N_ALGORITHMS, RH_LEN};
use crate::kernels::sim::{self, Footprint, PulseModel, PulseReference};
use crate::kernels::study::classes;
use crate::kernels::waveform::l2a::Noise;
use crate::ops::progress::{Progress, Step};

/// What [`read_cases`] kept and dropped.
#[derive(Debug, Clone, Default)]
pub struct CaseReport {
    pub shots_read: usize,
    /// (reason, count)
    pub dropped: Vec<(String, usize)>,
}

pub(super) fn count_dropped(report: &mut CaseReport, reason: &str) {
    match report.dropped.iter_mut().find(|(r, _)| r == reason) {
        Some((_, n)) => *n += 1,
        None => report.dropped.push((reason.to_string(), 1)),
    }
}

/// A real shot waiting for its simulation.
pub(super) struct Pending {
    pub(super) real: RealShot,
    pub(super) footprint: Footprint,
    /// Reported position (m, ALS CRS).
    pub(super) reported: (f64, f64),
    /// Its collocation segment is short ([`SHORT_SEGMENT_SHOTS`]): its [`site_grid`] is centred on
    /// the segment's re-collocated position and simulated at every width.
    pub(super) short_segment: bool,
    /// Its track is among those ranked ([`diagnose::sample`]): simulated at its sites. Another
    /// shot is simulated at its collocated position, nominal width, for `where` alone.
    pub(super) ranked: bool,
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
    let shots = ShotColumns(c);
    let (granule, beam) = (c.strings(col::GRANULE)?, c.strings(col::BEAM)?);
    let sn = c.u64s(col::SHOT_NUMBER)?;
    let (x, y) = (c.f64s(col::X)?, c.f64s(col::Y)?);
    let (bin0, lastbin) = (c.f64s(col::ELEVATION_BIN0)?, c.f64s(col::ELEVATION_LASTBIN)?);
    let (nmean, nsd) = (c.f64s(col::NOISE_MEAN_CORRECTED)?, c.f64s(col::NOISE_STDDEV_CORRECTED)?);
    let degrade = c.u8s(col::DEGRADE_FLAG)?;
    let selected = c.u8s(col::SELECTED_ALGORITHM)?;
    let leaf_off = c.u8s(col::LEAF_OFF_FLAG)?;
    let alg_cols = ALGORITHMS.iter().map(|(a, _)| shots.algorithm(a)).collect::<Result<Vec<_>>>()?;
    for i in 0..c.num_rows() {
        report.shots_read += 1;
        let (Some(px), Some(py)) = (value(x, i), value(y, i)) else {
            count_dropped(report, "no position");
            continue;
        };
        let Some(wave) = c.f32_list(col::RX_WAVEFORM, i)?.filter(|w| w.len() > 1) else {
            count_dropped(report, "no L1B waveform");
            continue;
        };
        let (Some(e0), Some(e1), Some(mean), Some(sd)) =
            (value(bin0, i), value(lastbin, i), value(nmean, i), value(nsd, i))
        else {
            count_dropped(report, "no record geolocation or noise");
            continue;
        };
        let Some(n_geoid) = shots.geoid_offset(i)? else {
            count_dropped(report, "no geoid");
            continue;
        };
        let Some(bt) = shots.beam_type(i)? else {
            count_dropped(report, "unknown beam type");
            continue;
        };
        let shot = sn.value(i);
        let algorithms: [Option<RealAlgorithm>; N_ALGORITHMS] = std::array::from_fn(|a| {
            let cols = &alg_cols[a];
            if !classes::passes_quality(value(cols.quality_flag, i), value(degrade, i), value(cols.sensitivity, i)) {
                return None;
            }
            let ground = value(cols.elev_lowestmode, i)?;
            let rh = c.f32_list(ALGORITHMS[a].0.rh, i).ok().flatten().filter(|r| r.len() == RH_LEN)?;
            ground.is_finite().then_some(RealAlgorithm { ground: ground - n_geoid, rh })
        });
        if algorithms.iter().all(Option::is_none) {
            count_dropped(report, "no algorithm passes quality (quality_flag, degrade_flag, sensitivity ≥ 0.9)");
            continue;
        }
        let sel = value(selected, i).filter(|s| (1..=N_ALGORITHMS as u8).contains(s)).unwrap_or(1);
        let sens_sel = value(alg_cols[usize::from(sel) - 1].sensitivity, i).unwrap_or(f64::NAN);
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
                beam_type: bt.as_str().to_string(),
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
/// ([`crate::kernels::collocate::horizontal_offsets_at`]), as an absolute position per shot.
fn recollocate(als: &AlsTable, pending: &[Pending], dz: f64) -> Result<HashMap<u64, (f64, f64)>> {
    use crate::kernels::collocate::{horizontal_offsets_at, profile::real_profile, CollocateConfig, ShotInput};
    let cfg = CollocateConfig::new(RECOLLOCATE_SHIFT_M, RECOLLOCATE_STEP_M)?;
    let half = cfg.support_half_width();
    let mut segments: std::collections::BTreeMap<&str, Vec<&Pending>> = Default::default();
    pending
        .iter()
        .filter(|p| p.short_segment && p.ranked)
        .for_each(|p| segments.entry(p.real.segment.as_str()).or_default().push(p));
    let groups: Vec<Vec<ShotInput>> = segments
        .values()
        .map(|shots| {
            shots
                .iter()
                .filter_map(|p| {
                    let r = &p.real;
                    let real = real_profile(&r.wave, r.bin0, r.lastbin, cfg.model.res).ok()?;
                    Some(ShotInput { x: p.reported.0, y: p.reported.1, real, pulse: r.pulse.clone() })
                })
                .collect()
        })
        .collect();
    let offsets = horizontal_offsets_at(&groups, &cfg, dz, &mut |shots| {
        let boxes: Vec<BBox> = shots.iter().map(|s| [s.x - half, s.y - half, s.x + half, s.y + half]).collect();
        als.xyz_in_boxes(&boxes).map(|(cloud, _)| cloud)
    })?;
    let mut out = HashMap::new();
    for (shots, offset) in segments.values().zip(offsets) {
        if let Some((ox, oy)) = offset {
            for p in shots {
                out.insert(p.real.shot_number, (p.reported.0 + ox, p.reported.1 + oy));
            }
        }
    }
    Ok(out)
}

/// Where each shot's pulse in the nominal chain comes from.
pub(super) enum ShotPulseSource {
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
                .f32_list(col::TX_WAVEFORM, i)?
                .and_then(|tx| crate::sql::pulses::recorded_pulse(&tx, *r, *res))
                .map(Arc::new),
        })
    }
}
