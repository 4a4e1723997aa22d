//! Which shots of a beam an ingest reads (docs/gedi-products.md, "Shots kept"): the cheap per-shot
//! datasets that place every shot are read first, the shots inside the area
//! ([`ShotArea`](crate::kernels::geo::area::ShotArea), indexed) kept, and only their runs are read of
//! every other dataset, waveforms included (`BeamGroup::select`).

use crate::error::Result;
use crate::io::gedi::{read_l1b_bins, read_l2a_places, runs_of, valid_lowestmode, BeamGroup, Runs};
use crate::kernels::geo::area::AreaIndex;
use crate::kernels::geo::projection::Projector;

use super::join::{pair_by_shot, position};
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
/// when the area needs its projected position, is outside. The L1B bins are read only for the
/// shots that need them (no valid lowest mode).
pub(super) fn kept(
    pair: &GranulePair,
    beam: &str,
    l1b: Option<&BeamGroup>,
    l2a: Option<&BeamGroup>,
    area: &AreaIndex,
    projector: &Projector,
) -> Result<Kept> {
    let sn1 = l1b.map(|g| g.shot_numbers()).transpose()?;
    let p2 = l2a.map(read_l2a_places).transpose()?;
    let by_shot = pair_by_shot(pair, beam, sn1.as_deref(), p2.as_ref().map(|p| &p.shot_number[..]))?;
    let lowest = |i2: Option<usize>| {
        let (p, i) = p2.as_ref().zip(i2)?;
        valid_lowestmode(p.lat_lowestmode.as_ref().map(|v| v[i]), p.lon_lowestmode.as_ref().map(|v| v[i]))
    };
    let mut need_bins: Vec<usize> =
        by_shot.iter().filter(|&&(_, i1, i2)| i1.is_some() && lowest(i2).is_none()).filter_map(|p| p.1).collect();
    need_bins.sort_unstable();
    let bins = match (l1b, &sn1) {
        (Some(g), Some(sn)) if !need_bins.is_empty() => read_l1b_bins(g, &need_bins, sn)?,
        _ => Vec::new(),
    };
    let (mut rows1, mut rows2, mut inside_n, mut outside) = (Vec::new(), Vec::new(), 0, 0);
    for (_, i1, i2) in by_shot {
        let lowest = lowest(i2);
        let bins = match (lowest, i1) {
            (None, Some(i)) => need_bins.binary_search(&i).ok().map(|k| bins[k]),
            _ => None,
        };
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
