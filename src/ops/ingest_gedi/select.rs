//! Which shots of a beam an ingest reads (docs/gedi-products.md, "Shots kept"): the cheap per-shot
//! datasets that place every shot are read first, the shots inside the area
//! ([`ShotArea`](crate::kernels::geo::area::ShotArea), indexed) kept, and only their runs are read of
//! every other dataset, waveforms included (`BeamGroup::select`).

use std::collections::HashMap;

use crate::error::Result;
use crate::io::gedi::{read_l1b_places, read_l2a_places, runs_of, valid_lowestmode, BeamGroup, Runs};
use crate::kernels::geo::area::AreaIndex;
use crate::kernels::geo::projection::Projector;

use super::join::{duplicate_check, position};
use super::GranulePair;

/// The shots of one beam inside the area: the runs of each side's rows to read.
pub(super) struct Kept {
    pub l1b: Runs,
    pub l2a: Runs,
    /// Shots (of either side) inside the area, and outside it.
    pub inside: usize,
    pub outside: usize,
}

/// Place every shot of the beam as its row will be placed (L2A lowest mode, else the L1B bin mean)
/// and keep those inside `area`. A shot without a valid position, or that cannot be projected
/// when the area needs its projected position, is outside.
pub(super) fn kept(
    pair: &GranulePair,
    beam: &str,
    l1b: Option<&BeamGroup>,
    l2a: Option<&BeamGroup>,
    area: &AreaIndex,
    projector: &Projector,
) -> Result<Kept> {
    let p1 = l1b.map(read_l1b_places).transpose()?;
    let p2 = l2a.map(read_l2a_places).transpose()?;
    let mut by_shot: HashMap<u64, (Option<usize>, Option<usize>)> = HashMap::new();
    if let Some(p) = &p1 {
        duplicate_check(pair.l1b.as_deref(), beam, &p.shot_number)?;
        for (i, &s) in p.shot_number.iter().enumerate() {
            by_shot.entry(s).or_default().0 = Some(i);
        }
    }
    if let Some(p) = &p2 {
        duplicate_check(pair.l2a.as_deref(), beam, &p.shot_number)?;
        for (i, &s) in p.shot_number.iter().enumerate() {
            by_shot.entry(s).or_default().1 = Some(i);
        }
    }
    let (mut rows1, mut rows2, mut inside_n, mut outside) = (Vec::new(), Vec::new(), 0, 0);
    for (i1, i2) in by_shot.into_values() {
        let lowest = p2.as_ref().zip(i2).and_then(|(p, i)| {
            valid_lowestmode(p.lat_lowestmode.as_ref().map(|v| v[i]), p.lon_lowestmode.as_ref().map(|v| v[i]))
        });
        let bins = p1.as_ref().zip(i1).map(|(p, i)| [p.lat_bin0[i], p.lon_bin0[i], p.lat_lastbin[i], p.lon_lastbin[i]]);
        let inside = position(lowest, bins).is_some_and(|(lat, lon, _)| {
            let xy = if area.needs_xy() { projector.project(lon, lat).ok() } else { None };
            area.contains(lon, lat, xy)
        });
        if inside {
            rows1.extend(i1);
            rows2.extend(i2);
            inside_n += 1;
        } else {
            outside += 1;
        }
    }
    rows1.sort_unstable();
    rows2.sort_unstable();
    Ok(Kept { l1b: runs_of(&rows1), l2a: runs_of(&rows2), inside: inside_n, outside })
}
