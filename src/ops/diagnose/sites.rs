//! Compute: every shot simulated at its sites (the collocated position, the grid around a short
//! segment's re-collocated centre) and widths ([`FSIGMA_GRID`]), block by block of the ALS.

use std::collections::HashMap;
use std::sync::Arc;

use super::cases::{count_dropped, CaseReport, Pending};
use crate::dataset::als::AlsTable;
use crate::error::Result;
use crate::kernels::diagnose::case::{
    configs, fsigma_grid, site_grid, site_of, RealShot, SimShot, Site, FSIGMA_GRID, NOMINAL_WIDTH,
};
use crate::kernels::diagnose::ShotCase;
use crate::kernels::gedi::N_ALGORITHMS;
use crate::kernels::sim::{self, Footprint, Weighting};
use crate::kernels::study::classes;

/// A shot to simulate: its real facts, whether its segment is short, whether it is ranked, and
/// its sites.
type ToSimulate = (RealShot, bool, bool, Vec<(f64, f64)>);

pub(super) fn simulate_cases(
    als: &AlsTable,
    pending: Vec<Pending>,
    centres: &HashMap<u64, (f64, f64)>,
    report: &mut CaseReport,
    on_shot: &(dyn Fn() + Sync),
) -> Result<Vec<(bool, ShotCase)>> {
    if pending.is_empty() {
        return Ok(Vec::new());
    }
    let (nominal, chain) = configs();
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
    for block in crate::sql::blocks::blocks(items) {
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
        let vars = sim::simulate_widths(&points, &full, &chain, &fsigma_grid())?;
        let light_vars = sim::simulate(&points, &light, &chain)?;
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
