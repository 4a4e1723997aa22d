//! Where the shots of a world fall: tracks (beams of granules) crossing each tile at a few
//! headings, ~60 m shot spacing along track, a random horizontal offset per track (plus the
//! `geolocation` effect's extra offsets), and only shots whose reported and true footprints lie
//! well inside the tile. Pure: tile extents in, planned shots out.

use super::effects::GeoLevel;
use super::rng::Stream;
use crate::gedi::BEAM_NAMES;

/// GEDI shot spacing along track (m).
pub const SHOT_SPACING_M: f64 = 60.0;
/// Ground-track headings of GEDI's 51.6° orbit at 45–47° N (degrees clockwise from north):
/// ascending ≈ 61°, descending ≈ 119° (sin h = cos 51.6° / cos φ).
pub const HEADINGS_DEG: [f64; 2] = [61.0, 119.0];

/// A tile's horizontal extent (projected metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    pub xmin: f64,
    pub ymin: f64,
    pub xmax: f64,
    pub ymax: f64,
}

impl Extent {
    /// Whether (x, y) is at least `margin` inside the extent.
    pub fn contains_with_margin(&self, x: f64, y: f64, margin: f64) -> bool {
        x >= self.xmin + margin && x <= self.xmax - margin && y >= self.ymin + margin && y <= self.ymax - margin
    }
}

/// Settings of the layout.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanSettings {
    /// Granules (passes) crossing each tile.
    pub passes_per_tile: usize,
    /// RMS per axis of the per-track horizontal offset (m).
    pub track_offset_sigma_m: f64,
    /// Distance from the tile edge that both the reported and the true footprint centre keep (m).
    pub margin_m: f64,
    /// Extra geolocation error of the `geolocation` effect.
    pub extra_offset: Option<(GeoLevel, f64)>,
}

/// One track: a beam of one granule crossing one tile.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// `t<tile>_g<pass>_<BEAM>`.
    pub id: String,
    pub tile: usize,
    /// Granule index (global, over tiles × passes).
    pub granule: usize,
    pub beam: &'static str,
    /// Heading, degrees clockwise from north.
    pub heading_deg: f64,
    /// Offset of the track (m): true position = reported + (dx, dy), as `collocate` reports it.
    pub dx: f64,
    pub dy: f64,
}

/// One planned shot.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedShot {
    /// Index into the track list.
    pub track: usize,
    /// Shot index along its track (0-based, in acquisition order).
    pub along_index: u32,
    /// Along-track distance from the track's origin (m), for timing.
    pub along_m: f64,
    /// Reported (geolocated) centre.
    pub x: f64,
    pub y: f64,
    /// Total offset of this shot (track + extra): where the waveform was formed = (x+dx, y+dy).
    pub dx: f64,
    pub dy: f64,
}

/// The planned world layout.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Plan {
    pub tracks: Vec<Track>,
    pub shots: Vec<PlannedShot>,
}

/// Clip a normal draw to ±2.5 σ so that offsets stay "a few metres".
fn clipped_normal(s: &mut Stream, sigma: f64) -> f64 {
    (s.normal() * sigma).clamp(-2.5 * sigma, 2.5 * sigma)
}

/// Lay out tracks and shots over the tiles. Granule g = tile·passes + pass; its eight beams run
/// parallel, spread evenly across the tile's usable width, at the pass's heading (alternately
/// ascending and descending, ±4° jitter). Shots sit every [`SHOT_SPACING_M`] from a random phase.
pub fn plan(tiles: &[Extent], s: &PlanSettings, seed: u64) -> Plan {
    let mut out = Plan::default();
    for (t, ext) in tiles.iter().enumerate() {
        for pass in 0..s.passes_per_tile {
            let granule = t * s.passes_per_tile + pass;
            let mut rng = Stream::new(seed, &["plan", &t.to_string(), &pass.to_string()]);
            let heading =
                HEADINGS_DEG[pass % 2] + (rng.uniform() - 0.5) * 8.0 + if pass % 4 >= 2 { 180.0 } else { 0.0 };
            let h = heading.to_radians();
            let (ux, uy) = (h.sin(), h.cos()); // along track
            let (vx, vy) = (h.cos(), -h.sin()); // cross track
            let m = s.margin_m;
            let corners = [
                (ext.xmin + m, ext.ymin + m),
                (ext.xmax - m, ext.ymin + m),
                (ext.xmin + m, ext.ymax - m),
                (ext.xmax - m, ext.ymax - m),
            ];
            let proj = |ax: f64, ay: f64| {
                let v: Vec<f64> = corners.iter().map(|&(x, y)| x * ax + y * ay).collect();
                (v.iter().cloned().fold(f64::INFINITY, f64::min), v.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
            };
            let (cmin, cmax) = proj(vx, vy);
            let (amin, amax) = proj(ux, uy);
            if !(cmax > cmin) || !(amax > amin) {
                continue; // tile too small for the margin
            }
            for (b, beam) in BEAM_NAMES.iter().enumerate() {
                let track = out.tracks.len();
                let mut tr = Stream::new(seed, &["track", &granule.to_string(), beam]);
                let (mut dx, mut dy) =
                    (clipped_normal(&mut tr, s.track_offset_sigma_m), clipped_normal(&mut tr, s.track_offset_sigma_m));
                if let Some((GeoLevel::Beam, sigma)) = s.extra_offset {
                    dx += clipped_normal(&mut tr, sigma);
                    dy += clipped_normal(&mut tr, sigma);
                }
                out.tracks.push(Track {
                    id: format!("t{t}_g{granule}_{beam}"),
                    tile: t,
                    granule,
                    beam,
                    heading_deg: heading.rem_euclid(360.0),
                    dx,
                    dy,
                });
                let c = cmin + (b as f64 + 0.25 + 0.5 * tr.uniform()) / BEAM_NAMES.len() as f64 * (cmax - cmin);
                let phase = tr.uniform() * SHOT_SPACING_M;
                let mut along_index = 0;
                let mut a = amin - SHOT_SPACING_M + phase;
                while a <= amax + SHOT_SPACING_M {
                    let (x, y) = (c * vx + a * ux, c * vy + a * uy);
                    let (mut sdx, mut sdy) = (dx, dy);
                    if let Some((GeoLevel::Shot, sigma)) = s.extra_offset {
                        sdx += clipped_normal(&mut tr, sigma);
                        sdy += clipped_normal(&mut tr, sigma);
                    }
                    if ext.contains_with_margin(x, y, m) && ext.contains_with_margin(x + sdx, y + sdy, m) {
                        out.shots.push(PlannedShot { track, along_index, along_m: a - amin, x, y, dx: sdx, dy: sdy });
                        along_index += 1;
                    }
                    a += SHOT_SPACING_M;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> PlanSettings {
        PlanSettings { passes_per_tile: 4, track_offset_sigma_m: 3.0, margin_m: 12.0, extra_offset: None }
    }

    #[test]
    fn shots_stay_inside_with_their_offsets_and_spacing() {
        let ext = Extent { xmin: 0.0, ymin: 0.0, xmax: 100.0, ymax: 100.0 };
        let p = plan(&[ext], &settings(), 7);
        assert_eq!(p.tracks.len(), 32);
        assert!(p.shots.len() >= 16, "{} shots", p.shots.len());
        for s in &p.shots {
            assert!(ext.contains_with_margin(s.x, s.y, 12.0) && ext.contains_with_margin(s.x + s.dx, s.y + s.dy, 12.0));
            let t = &p.tracks[s.track];
            assert_eq!((s.dx, s.dy), (t.dx, t.dy), "no extra offset without the effect");
            assert!(t.dx.abs() <= 7.5 && t.dy.abs() <= 7.5);
        }
        // Consecutive shots of a track are 60 m apart.
        for w in p.shots.windows(2) {
            if w[0].track == w[1].track {
                let d = ((w[1].x - w[0].x).powi(2) + (w[1].y - w[0].y).powi(2)).sqrt();
                assert!((d - SHOT_SPACING_M).abs() < 1e-6 || d > SHOT_SPACING_M, "{d}");
            }
        }
        assert_eq!(plan(&[ext], &settings(), 7), p, "same seed, same plan");
        assert_ne!(plan(&[ext], &settings(), 8), p);
    }

    #[test]
    fn shot_level_geolocation_adds_per_shot_offsets() {
        let ext = Extent { xmin: 0.0, ymin: 0.0, xmax: 100.0, ymax: 100.0 };
        let mut s = settings();
        s.extra_offset = Some((GeoLevel::Shot, 2.0));
        let p = plan(&[ext], &s, 7);
        assert!(p.shots.iter().any(|sh| (sh.dx, sh.dy) != (p.tracks[sh.track].dx, p.tracks[sh.track].dy)));
    }

    #[test]
    fn tile_smaller_than_the_margin_gets_no_shot() {
        let ext = Extent { xmin: 0.0, ymin: 0.0, xmax: 20.0, ymax: 20.0 };
        assert!(plan(&[ext], &settings(), 1).shots.is_empty());
    }
}
