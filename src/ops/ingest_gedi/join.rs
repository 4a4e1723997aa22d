//! Compute: one beam's L1B and L2A joined on `shot_number` into rows (a shot on one side only kept,
//! with nulls), each placed (L2A lowest mode, else L1B bin0/lastbin), duplicates refused.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use arrow::array::RecordBatch;

use super::{BeamReport, GediOptions, GranulePair};
use crate::dataset::shots::col;
use crate::error::{Error, Result};
use crate::io::gedi::{L1bBeam, L2aBeam};
use crate::kernels::geo::projection::Projector;

/// Where the `x`, `y` of a row come from.
#[derive(Clone, Copy)]
pub(super) enum XySource {
    /// L2A `lat/lon_lowestmode` (the footprint as L2A reports it).
    LowestMode,
    /// Mean of L1B bin0 and lastbin (the reference simulator's convention), for rows without a
    /// valid L2A lowest mode.
    BinMean,
}

impl XySource {
    pub(super) fn as_str(self) -> &'static str {
        match self {
            XySource::LowestMode => "lowestmode",
            XySource::BinMean => "bin_mean",
        }
    }
}

/// Where a shot is (lat, lon, source): its valid L2A lowest mode, else the mean of its L1B bin0 and
/// lastbin (`[lat_bin0, lon_bin0, lat_lastbin, lon_lastbin]`); the same rule places rows and
/// chooses the shots kept ([`select`]).
pub(super) fn position(lowest: Option<(f64, f64)>, bins: Option<[f64; 4]>) -> Option<(f64, f64, XySource)> {
    match (lowest, bins) {
        (Some((lat, lon)), _) => Some((lat, lon, XySource::LowestMode)),
        (None, Some([lat0, lon0, lat1, lon1])) => Some(((lat0 + lat1) / 2.0, (lon0 + lon1) / 2.0, XySource::BinMean)),
        (None, None) => None,
    }
}

/// One output row: the shot's index on each side and its projected position.
pub(super) struct Row {
    pub(super) shot_number: u64,
    pub(super) l1b: Option<usize>,
    pub(super) l2a: Option<usize>,
    pub(super) xy: Option<(f64, f64, XySource)>,
}

/// The shot numbers of the dataset's granules and of those this call writes: a shot number is
/// unique across GEDI (it encodes the orbit, beam and shot, docs/gedi-products.md §1), so one
/// seen in two beams of a granule, or in two granules (a copy under another name), is a broken
/// file, and would put one shot in two collocation segments, which `run` cannot write
/// (docs/robustness.md).
pub(super) struct ShotOwners {
    /// (shot number, index in `keys`) of every shot the dataset holds, sorted.
    pub(super) stored: Vec<(u64, usize)>,
    pub(super) keys: Vec<String>,
    /// Shots written by this call so far: their granule key and beam.
    pub(super) claimed: std::sync::Mutex<HashMap<u64, Owner>>,
}

/// The granule key and beam of a shot.
pub(super) type Owner = (Arc<str>, Arc<str>);

impl ShotOwners {
    /// The shots of every file of the dataset's `shots/` table (one per granule key).
    pub(super) fn read(shots_dir: &Path) -> Result<ShotOwners> {
        let mut stored = Vec::new();
        let mut keys = Vec::new();
        for f in crate::dataset::table_files(shots_dir).map_err(|e| Error::file(shots_dir, e))? {
            let k = keys.len();
            keys.push(f.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_string());
            crate::dataset::read::for_each_batch(&f, Some(&[col::SHOT_NUMBER]), None, |c| {
                stored.extend(c.u64s(col::SHOT_NUMBER)?.values().iter().map(|&s| (s, k)));
                Ok(())
            })?;
        }
        stored.sort_unstable();
        Ok(ShotOwners { stored, keys, claimed: Default::default() })
    }

    /// Claim the shots of a batch of granule `key`'s rows; refuse one that another beam of the
    /// granule or another granule holds (the granule's own earlier rows are replaced by this
    /// ingest).
    pub(super) fn claim(&self, pair: &GranulePair, key: &Arc<str>, batch: &RecordBatch) -> Result<()> {
        let (Some(sn), Some(beams)) = (batch.column_by_name(col::SHOT_NUMBER), batch.column_by_name(col::BEAM)) else {
            return Ok(());
        };
        use arrow::array::AsArray;
        let (sn, beams) = (sn.as_primitive::<arrow::datatypes::UInt64Type>(), beams.as_string::<i32>());
        let path = pair.l1b.as_deref().or(pair.l2a.as_deref()).unwrap_or(Path::new(&pair.granule));
        let refuse = |why: String| Err(Error::field(path, col::SHOT_NUMBER, why));
        let in_granule = |shot: u64, other: &str| {
            refuse(format!(
                "shot {shot} is also in granule {other}: a shot number is unique across GEDI (a copy of that \
                 granule, or a broken file)"
            ))
        };
        let mut claimed = self.claimed.lock().unwrap_or_else(|e| e.into_inner());
        let mut beam: Arc<str> = Arc::from("");
        for (i, &shot) in sn.values().iter().enumerate() {
            if *beam != *beams.value(i) {
                beam = Arc::from(beams.value(i));
            }
            let from = self.stored.partition_point(|&(s, _)| s < shot);
            if let Some(&(_, k)) =
                self.stored[from..].iter().take_while(|(s, _)| *s == shot).find(|(_, k)| *self.keys[*k] != **key)
            {
                return in_granule(shot, &self.keys[k]);
            }
            match claimed.get(&shot) {
                Some((other, _)) if other != key => return in_granule(shot, other),
                Some((_, first)) if *first != beam => {
                    return refuse(format!(
                        "shot {shot} is in {first} and in {beam}: a shot number is unique in a granule"
                    ))
                }
                Some(_) => {}
                None => {
                    claimed.insert(shot, (key.clone(), beam.clone()));
                }
            }
        }
        Ok(())
    }
}

/// One shot of a beam: its number and its row on each side.
pub(super) type Paired = (u64, Option<usize>, Option<usize>);

/// The two sides' rows paired by shot number, in shot-number order; a shot number twice on one
/// side is refused. GEDI writes a beam's shots in along-track order, so the shot numbers are
/// increasing and this is a merge (no hashing: it ran through every shot of a full granule); a
/// side out of order is sorted first.
pub(super) fn pair_by_shot(
    pair: &GranulePair,
    beam: &str,
    l1b: Option<&[u64]>,
    l2a: Option<&[u64]>,
) -> Result<Vec<Paired>> {
    let order1 = l1b.map(|s| shot_order(pair.l1b.as_deref(), beam, s)).transpose()?.unwrap_or_default();
    let order2 = l2a.map(|s| shot_order(pair.l2a.as_deref(), beam, s)).transpose()?.unwrap_or_default();
    let (s1, s2) = (l1b.unwrap_or_default(), l2a.unwrap_or_default());
    let mut out = Vec::with_capacity(order1.len().max(order2.len()));
    let (mut a, mut b) = (order1.iter().copied().peekable(), order2.iter().copied().peekable());
    loop {
        let next = match (a.peek(), b.peek()) {
            (Some(&i), Some(&j)) if s1[i] == s2[j] => (s1[i], a.next(), b.next()),
            (Some(&i), Some(&j)) if s1[i] < s2[j] => (s1[i], a.next(), None),
            (Some(&i), None) => (s1[i], a.next(), None),
            (_, Some(&j)) => (s2[j], None, b.next()),
            (None, None) => return Ok(out),
        };
        out.push(next);
    }
}

/// The rows of one side in shot-number order (themselves when already increasing); a shot number
/// seen twice is refused, naming the file and the beam's dataset.
fn shot_order(path: Option<&Path>, beam: &str, shots: &[u64]) -> Result<Vec<usize>> {
    let mut order: Vec<usize> = (0..shots.len()).collect();
    if shots.windows(2).all(|w| w[0] < w[1]) {
        return Ok(order);
    }
    order.sort_unstable_by_key(|&i| shots[i]);
    if let Some(w) = order.windows(2).find(|w| shots[w[0]] == shots[w[1]]) {
        return Err(Error::field(
            path.unwrap_or(Path::new("")),
            format!("{beam}/shot_number"),
            format!("duplicate shot {}", shots[w[0]]),
        ));
    }
    Ok(order)
}

/// Join the two sides on shot_number (rows sorted by shot number) and project every row.
pub(super) fn join(
    pair: &GranulePair,
    beam: &str,
    l1b: Option<&L1bBeam>,
    l2a: Option<&L2aBeam>,
    opts: &GediOptions,
    projector: &Projector,
    report: &mut BeamReport,
) -> Result<Vec<Row>> {
    let by_shot = pair_by_shot(pair, beam, l1b.map(|b| &b.shot_number[..]), l2a.map(|b| &b.shot_number[..]))?;
    report.l1b_shots = l1b.map_or(0, |b| b.shot_number.len());
    report.l2a_shots = l2a.map_or(0, |b| b.shot_number.len());

    let mut rows = Vec::with_capacity(by_shot.len());
    for (shot_number, i1, i2) in by_shot {
        match (i1, i2) {
            (Some(_), Some(_)) => report.joined += 1,
            // A one-sided shot is an anomaly only when the other product's file was given.
            (Some(_), None) if pair.l2a.is_some() => report.l1b_only.push(shot_number),
            (None, Some(_)) if pair.l1b.is_some() => report.l2a_only.push(shot_number),
            _ => {}
        }
        let lowest = match (l2a, i2) {
            (Some(b), Some(i)) => {
                let v = b.lowestmode(i);
                if v.is_none() {
                    report.invalid_lowestmode.push(shot_number);
                }
                v
            }
            _ => None,
        };
        let bins = l1b.zip(i1).map(|(b, i)| [b.lat_bin0[i], b.lon_bin0[i], b.lat_lastbin[i], b.lon_lastbin[i]]);
        let Some((lat, lon, source)) = position(lowest, bins) else {
            rows.push(Row { shot_number, l1b: i1, l2a: i2, xy: None });
            continue;
        };
        let field = match source {
            XySource::LowestMode => "lat_lowestmode",
            XySource::BinMean => "geolocation/latitude_bin0",
        };
        let (x, y) = projector.project(lon, lat).map_err(|e| {
            let path = if matches!(source, XySource::LowestMode) { pair.l2a.as_deref() } else { pair.l1b.as_deref() };
            Error::field(path.unwrap_or(Path::new("")), format!("{beam}/{field}"), format!("shot {shot_number}: {e}"))
        })?;
        rows.push(Row { shot_number, l1b: i1, l2a: i2, xy: Some((x, y, source)) });
    }

    if opts.strict_join {
        if let Some(&first) = report.l1b_only.first() {
            let path = pair.l1b.as_deref().unwrap_or(Path::new(""));
            return Err(Error::field(
                path,
                format!("{beam}/shot_number"),
                format!(
                    "{} shot(s) have no L2A partner (first {first}) and --strict-join is set",
                    report.l1b_only.len()
                ),
            ));
        }
        if let Some(&first) = report.l2a_only.first() {
            let path = pair.l2a.as_deref().unwrap_or(Path::new(""));
            return Err(Error::field(
                path,
                format!("{beam}/shot_number"),
                format!(
                    "{} shot(s) have no L1B partner (first {first}) and --strict-join is set",
                    report.l2a_only.len()
                ),
            ));
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair() -> GranulePair {
        GranulePair { granule: "g".into(), l1b: Some("a_L1B.h5".into()), l2a: Some("a_L2A.h5".into()) }
    }

    #[test]
    fn pairs_by_shot_number_in_order_whatever_order_the_sides_are_in() {
        let l1b = [10, 20, 30, 40];
        let l2a = [40, 5, 20, 35];
        let got = pair_by_shot(&pair(), "BEAM0000", Some(&l1b), Some(&l2a)).unwrap();
        let want = vec![
            (5, None, Some(1)),
            (10, Some(0), None),
            (20, Some(1), Some(2)),
            (30, Some(2), None),
            (35, None, Some(3)),
            (40, Some(3), Some(0)),
        ];
        assert_eq!(got, want);
        // One side only, and no side.
        let got = pair_by_shot(&pair(), "BEAM0000", None, Some(&l2a)).unwrap();
        assert_eq!(got.iter().map(|p| p.0).collect::<Vec<_>>(), [5, 20, 35, 40]);
        assert!(got.iter().all(|p| p.1.is_none()));
        assert!(pair_by_shot(&pair(), "BEAM0000", None, None).unwrap().is_empty());
    }

    #[test]
    fn a_shot_twice_on_one_side_is_refused_naming_the_file() {
        for (l1b, l2a, file) in [([1, 2, 2, 3], [1, 2, 3, 4], "a_L1B.h5"), ([1, 2, 3, 4], [3, 1, 4, 3], "a_L2A.h5")] {
            let e = pair_by_shot(&pair(), "BEAM0101", Some(&l1b), Some(&l2a)).unwrap_err().to_string();
            assert!(e.contains(file) && e.contains("BEAM0101/shot_number"), "{e}");
            assert!(e.contains(&format!("duplicate shot {}", if file == "a_L1B.h5" { 2 } else { 3 })), "{e}");
        }
    }
}
