//! The report's agreement figures: the 1:1 scatter of simulated against aligned GEDI RH98 and RH50
//! per weighting (with each panel's n, bias, RMSE and R² from `queries/rh_agreement.sql`), and the
//! map of shots coloured by their RH98 bias over the ALS tiles' extents (`shot_agreement.sql`,
//! `tile_extents.sql`). Bias is simulated − aligned GEDI throughout (docs/diagnosis.md "Signs").

use std::error::Error as StdError;

use arrow::array::RecordBatch;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::figures::{font, tick, Figure, COLORS, LIGHT};
use super::{floats, strings, AnyFigure, FigureData, TableOutput};
use crate::error::Result;
use crate::kernels::study::select::WEIGHTINGS;

type DrawResult = std::result::Result<(), Box<dyn StdError>>;

/// The weighting and algorithm the map shows (the report's baseline, as in its other figures).
const MAP_WEIGHTING: &str = "count";

/// One panel of the scatter: simulated (y) against aligned GEDI (x), m.
#[derive(Debug, Clone, PartialEq)]
pub struct ScatterPanel {
    pub title: String,
    /// RH98 or RH50.
    pub metric: String,
    /// (aligned GEDI, simulated)
    pub points: Vec<(f64, f64)>,
}

/// Simulated vs aligned GEDI RH, one row per metric (RH98, RH50), one column per weighting.
#[derive(Debug, Clone, PartialEq)]
pub struct RhScatter {
    pub panels: Vec<ScatterPanel>,
    pub columns: usize,
}

/// Shots coloured by their RH98 bias over the tiles' extents: one panel per area (tiles within
/// [`AREA_GAP_M`] of each other), so that tiles far apart each get a readable map.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotMap {
    pub areas: Vec<MapArea>,
    /// EPSG code of x, y (from `tiles.epsg`), if one.
    pub epsg: Option<u32>,
    /// Symmetric colour range (m), shared by the panels: [`colour_limit`].
    pub limit: f64,
    /// Areas not drawn (beyond [`MAX_AREAS`], those with fewest shots).
    pub left_out: usize,
}

/// One panel of the map.
#[derive(Debug, Clone, PartialEq)]
pub struct MapArea {
    /// (xmin, ymin, xmax, ymax), m.
    pub tiles: Vec<[f64; 4]>,
    /// (x, y, bias), m.
    pub shots: Vec<(f64, f64, f64)>,
}

/// Tiles closer than this (m) are drawn in one panel.
pub const AREA_GAP_M: f64 = 5_000.0;

/// Panels drawn at most (the areas with most shots); the caption counts the others.
pub const MAX_AREAS: usize = 6;

/// Group `tiles` into areas (single linkage: a tile within [`AREA_GAP_M`] of a tile of an area
/// joins it) and put each shot in the area whose extent, grown by [`AREA_GAP_M`], holds it; the
/// shots near no tile (all of them without a `tiles` table) make one more area. Areas sorted by
/// number of shots, most first.
pub fn areas(tiles: &[[f64; 4]], shots: &[(f64, f64, f64)]) -> Vec<MapArea> {
    let gap = |a: &[f64; 4], b: &[f64; 4]| {
        let dx = (a[0] - b[2]).max(b[0] - a[2]).max(0.0);
        let dy = (a[1] - b[3]).max(b[1] - a[3]).max(0.0);
        dx.hypot(dy)
    };
    let mut group: Vec<usize> = (0..tiles.len()).collect();
    fn root(g: &mut [usize], mut i: usize) -> usize {
        while g[i] != i {
            g[i] = g[g[i]];
            i = g[i];
        }
        i
    }
    for i in 0..tiles.len() {
        for j in i + 1..tiles.len() {
            if gap(&tiles[i], &tiles[j]) <= AREA_GAP_M {
                let (a, b) = (root(&mut group, i), root(&mut group, j));
                group[a] = b;
            }
        }
    }
    let mut out: Vec<MapArea> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for (i, t) in tiles.iter().enumerate() {
        let r = root(&mut group, i);
        let k = *index.entry(r).or_insert_with(|| {
            out.push(MapArea { tiles: Vec::new(), shots: Vec::new() });
            out.len() - 1
        });
        out[k].tiles.push(*t);
    }
    let extent = |a: &MapArea| {
        a.tiles.iter().fold([f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY], |e, t| {
            [e[0].min(t[0]), e[1].min(t[1]), e[2].max(t[2]), e[3].max(t[3])]
        })
    };
    let extents: Vec<[f64; 4]> = out.iter().map(extent).collect();
    let mut off_tiles = MapArea { tiles: Vec::new(), shots: Vec::new() };
    for &(x, y, b) in shots {
        let near = |e: &[f64; 4]| {
            x >= e[0] - AREA_GAP_M && x <= e[2] + AREA_GAP_M && y >= e[1] - AREA_GAP_M && y <= e[3] + AREA_GAP_M
        };
        match extents.iter().position(near) {
            Some(k) => out[k].shots.push((x, y, b)),
            None => off_tiles.shots.push((x, y, b)),
        }
    }
    out.push(off_tiles);
    out.retain(|a| !a.shots.is_empty());
    out.sort_by_key(|a| std::cmp::Reverse(a.shots.len()));
    out
}

fn table<'a>(ran: &'a [TableOutput], name: &str) -> Option<&'a TableOutput> {
    ran.iter().find(|t| t.query.name == name)
}

/// The points of `metric` (`rh98` or `rh50`) and weighting `w` from `shot_agreement`.
fn points(b: &RecordBatch, w: &str, metric: &str) -> Result<Vec<(f64, f64)>> {
    let weighting = strings(b, "weighting")?;
    let (sim, gedi) = (floats(b, &format!("{metric}_sim"))?, floats(b, &format!("{metric}_gedi"))?);
    Ok((0..b.num_rows())
        .filter(|&i| weighting[i].as_deref() == Some(w) && sim[i].is_finite() && gedi[i].is_finite())
        .map(|i| (gedi[i], sim[i]))
        .collect())
}

/// Add the scatter and the map to `fd` (or notes on why they cannot be drawn).
pub fn add_figures(ran: &[TableOutput], fd: &mut FigureData) -> Result<()> {
    let (Some(shots), Some(stats)) = (table(ran, "shot_agreement"), table(ran, "rh_agreement")) else {
        fd.notes.push("rh_scatter, shot_map: need the results and shots tables".into());
        return Ok(());
    };
    let (b, s) = (shots.batch()?, stats.batch()?);
    let (sw, sm) = (strings(&s, "weighting")?, strings(&s, "metric")?);
    let (n, bias, rmse, r2) = (floats(&s, "n")?, floats(&s, "bias")?, floats(&s, "rmse")?, floats(&s, "r2")?);
    let mut panels = Vec::new();
    for metric in ["RH98", "RH50"] {
        for w in WEIGHTINGS {
            let pts = points(&b, w, &metric.to_lowercase())?;
            let Some(i) = (0..s.num_rows()).find(|&i| sw[i].as_deref() == Some(w) && sm[i].as_deref() == Some(metric))
            else {
                continue;
            };
            if pts.is_empty() {
                continue;
            }
            let title = format!(
                "{metric}, {w}: n {}, bias {:+.2} m, RMSE {:.2} m, R² {}",
                n[i],
                bias[i],
                rmse[i],
                if r2[i].is_finite() { format!("{:.2}", r2[i]) } else { "–".into() }
            );
            panels.push(ScatterPanel { title, metric: metric.into(), points: pts });
        }
    }
    if panels.is_empty() {
        fd.notes.push("rh_scatter: no shot with both a simulated and an aligned GEDI RH".into());
    } else {
        fd.drawable.push(("rh_scatter", AnyFigure::Scatter(RhScatter { panels, columns: WEIGHTINGS.len() })));
    }
    let (x, y, w, rh98) = (floats(&b, "x")?, floats(&b, "y")?, strings(&b, "weighting")?, floats(&b, "rh98_bias")?);
    let map_shots: Vec<(f64, f64, f64)> = (0..b.num_rows())
        .filter(|&i| w[i].as_deref() == Some(MAP_WEIGHTING) && x[i].is_finite() && y[i].is_finite())
        .filter(|&i| rh98[i].is_finite())
        .map(|i| (x[i], y[i], rh98[i]))
        .collect();
    let (tiles, epsg) = match table(ran, "tile_extents") {
        Some(t) => {
            let t = t.batch()?;
            let (x0, y0, x1, y1) = (floats(&t, "xmin")?, floats(&t, "ymin")?, floats(&t, "xmax")?, floats(&t, "ymax")?);
            let epsg = floats(&t, "epsg")?;
            let tiles =
                (0..t.num_rows()).map(|i| [x0[i], y0[i], x1[i], y1[i]]).filter(|e| e.iter().all(|v| v.is_finite()));
            (tiles.collect(), epsg.first().filter(|e| e.is_finite()).map(|&e| e as u32))
        }
        None => (Vec::new(), None),
    };
    if map_shots.is_empty() {
        fd.notes.push("shot_map: no shot with a position and an RH98 bias".into());
    } else {
        let limit = colour_limit(&map_shots);
        let all = areas(&tiles, &map_shots);
        let left_out = all.len().saturating_sub(MAX_AREAS);
        let areas = all.into_iter().take(MAX_AREAS).collect();
        fd.drawable.push(("shot_map", AnyFigure::Map(ShotMap { areas, epsg, limit, left_out })));
    }
    Ok(())
}

impl RhScatter {
    pub fn caption(&self) -> String {
        "Simulated against aligned GEDI RH98 and RH50 (m above the ALS ground), L2A's selected algorithm, one panel \
         per weighting; bias = simulated − GEDI, R² = squared Pearson correlation; the line is 1:1."
            .into()
    }
}

impl ShotMap {
    pub fn caption(&self) -> String {
        format!(
            "Shots coloured by RH98 bias (simulated − aligned GEDI, m; {MAP_WEIGHTING} weighting, L2A's selected \
             algorithm) over the extents of the ALS tiles (grey), one panel per area of tiles within {:.0} km of each \
             other ({}).",
            AREA_GAP_M / 1000.0,
            self.epsg.map_or("the dataset's projected CRS".to_string(), |e| format!("EPSG:{e}"))
        ) + &if self.left_out > 0 {
            format!(" {} more area(s) with fewer shots are not drawn.", self.left_out)
        } else {
            String::new()
        }
    }
}

/// Symmetric colour range of the map: the 95th percentile of |bias| (at least 0.5 m), so that one
/// outlier does not wash out the rest.
pub fn colour_limit(shots: &[(f64, f64, f64)]) -> f64 {
    let mut a: Vec<f64> = shots.iter().map(|s| s.2.abs()).collect();
    a.sort_by(|x, y| x.total_cmp(y));
    let p95 = a.get(((a.len() as f64 * 0.95).ceil() as usize).saturating_sub(1)).copied().unwrap_or(0.0);
    p95.max(0.5)
}

/// Diverging blue (simulation too low) – white – red (simulation too high), `t` in −1…1.
pub fn diverging(t: f64) -> RGBColor {
    let t = t.clamp(-1.0, 1.0);
    let mix = |a: u8, b: u8, f: f64| (a as f64 + (b as f64 - a as f64) * f).round() as u8;
    let (blue, white, red) = ((33, 102, 172), (247, 247, 247), (178, 24, 43));
    let (from, to, f) = if t < 0.0 { (white, blue, -t) } else { (white, red, t) };
    RGBColor(mix(from.0, to.0, f), mix(from.1, to.1, f), mix(from.2, to.2, f))
}

impl Figure for RhScatter {
    fn size(&self) -> (u32, u32) {
        let rows = self.panels.len().div_ceil(self.columns.max(1)).max(1) as u32;
        (380 * self.columns.max(1) as u32 + 40, 390 * rows + 50)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled("Simulated vs aligned GEDI RH (bias = simulated − GEDI)", font(20))?;
        let rows = self.panels.len().div_ceil(self.columns.max(1)).max(1);
        let areas = root.split_evenly((rows, self.columns.max(1)));
        for (p, area) in self.panels.iter().zip(&areas) {
            let all = p.points.iter().flat_map(|&(a, b)| [a, b]).filter(|v| v.is_finite());
            let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
            let pad = ((hi - lo) * 0.05).max(0.5);
            let (lo, hi) = (lo.min(0.0) - pad, hi + pad);
            let mut chart = ChartBuilder::on(area)
                .caption(&p.title, font(12))
                .margin(8)
                .x_label_area_size(38)
                .y_label_area_size(48)
                .build_cartesian_2d(lo..hi, lo..hi)?;
            chart
                .configure_mesh()
                .x_label_formatter(&tick)
                .y_label_formatter(&tick)
                .light_line_style(LIGHT)
                .x_desc(format!("aligned GEDI {} (m)", p.metric))
                .y_desc(format!("simulated {} (m)", p.metric))
                .label_style(font(11))
                .axis_desc_style(font(12))
                .draw()?;
            chart.draw_series(LineSeries::new([(lo, lo), (hi, hi)], BLACK.mix(0.6)))?;
            chart.draw_series(p.points.iter().map(|&(a, b)| Circle::new((a, b), 3, COLORS[0].mix(0.6).filled())))?;
        }
        Ok(())
    }
}

impl ShotMap {
    /// Panels per row.
    fn columns(&self) -> usize {
        self.areas.len().clamp(1, 3)
    }
}

/// Side of one map panel (px).
const MAP_PANEL: u32 = 380;

impl Figure for ShotMap {
    fn size(&self) -> (u32, u32) {
        let rows = self.areas.len().div_ceil(self.columns()).max(1) as u32;
        (MAP_PANEL * self.columns() as u32 + 110, MAP_PANEL * rows + 50)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled(
            &format!("RH98 bias of each shot (simulated − GEDI, {MAP_WEIGHTING} weighting) over the ALS tiles"),
            font(18),
        )?;
        let (w, _) = root.dim_in_pixel();
        let (maps, bar) = root.split_horizontally(w.saturating_sub(110));
        let rows = self.areas.len().div_ceil(self.columns()).max(1);
        let crs = self.epsg.map_or("projected CRS".to_string(), |e| format!("EPSG:{e}"));
        for (area, panel) in self.areas.iter().zip(&maps.split_evenly((rows, self.columns()))) {
            draw_area(area, panel, self.limit, &crs)?;
        }
        // Colour bar.
        let limit = self.limit;
        let mut cb = ChartBuilder::on(&bar)
            .margin_top(40)
            .margin_bottom(60)
            .margin_right(20)
            .y_label_area_size(45)
            .caption("bias (m)", font(12))
            .build_cartesian_2d(0.0..1.0, -limit..limit)?;
        cb.configure_mesh()
            .disable_x_mesh()
            .disable_x_axis()
            .y_label_formatter(&tick)
            .label_style(font(11))
            .light_line_style(LIGHT)
            .draw()?;
        let steps = 60;
        cb.draw_series((0..steps).map(|k| {
            let a = -limit + 2.0 * limit * k as f64 / steps as f64;
            let b = a + 2.0 * limit / steps as f64;
            Rectangle::new([(0.0, a), (1.0, b)], diverging((a + b) / 2.0 / limit).filled())
        }))?;
        Ok(())
    }
}

/// One area: its tiles' outlines and its shots, equal metres per pixel on both axes, in m (km
/// beyond 5 km) from the area's south-west corner (the corner's coordinates in the panel's title).
fn draw_area<DB: DrawingBackend>(area: &MapArea, panel: &DrawingArea<DB, Shift>, limit: f64, crs: &str) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let xs = area.tiles.iter().flat_map(|t| [t[0], t[2]]).chain(area.shots.iter().map(|s| s.0));
    let ys = area.tiles.iter().flat_map(|t| [t[1], t[3]]).chain(area.shots.iter().map(|s| s.1));
    let span =
        |v: &mut dyn Iterator<Item = f64>| v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(x), h.max(x)));
    let ((x0, x1), (y0, y1)) = (span(&mut { xs }), span(&mut { ys }));
    let (w, h) = panel.dim_in_pixel();
    let (pw, ph) = ((w as f64 - 70.0).max(1.0), (h as f64 - 80.0).max(1.0));
    let scale = ((x1 - x0).max(100.0) / pw).max((y1 - y0).max(100.0) / ph) * 1.08;
    let (cx, cy) = ((x0 + x1) / 2.0 - x0, (y0 + y1) / 2.0 - y0);
    let (hx, hy) = (scale * pw / 2.0, scale * ph / 2.0);
    let (per, unit) = if (x1 - x0).max(y1 - y0) < 5000.0 { (1.0, "m") } else { (1000.0, "km") };
    let km = |v: f64| v / per;
    let mut chart = ChartBuilder::on(panel)
        .caption(format!("{} shots; origin x {x0:.0}, y {y0:.0} ({crs})", area.shots.len()), font(12))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(46)
        .build_cartesian_2d(km(cx - hx)..km(cx + hx), km(cy - hy)..km(cy + hy))?;
    chart
        .configure_mesh()
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .light_line_style(LIGHT)
        .x_labels(5)
        .y_labels(5)
        .x_desc(format!("east ({unit})"))
        .y_desc(format!("north ({unit})"))
        .label_style(font(11))
        .axis_desc_style(font(12))
        .draw()?;
    let outline = RGBColor(120, 120, 120).stroke_width(1);
    chart.draw_series(
        area.tiles
            .iter()
            .map(|t| Rectangle::new([(km(t[0] - x0), km(t[1] - y0)), (km(t[2] - x0), km(t[3] - y0))], outline)),
    )?;
    let at = |x: f64, y: f64| (km(x - x0), km(y - y0));
    chart.draw_series(area.shots.iter().map(|&(x, y, b)| Circle::new(at(x, y), 5, diverging(b / limit).filled())))?;
    chart.draw_series(area.shots.iter().map(|&(x, y, _)| Circle::new(at(x, y), 5, BLACK.mix(0.5))))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diverging_colours_and_the_colour_limit() {
        assert_eq!(diverging(0.0), RGBColor(247, 247, 247));
        assert_eq!(diverging(-1.0), RGBColor(33, 102, 172));
        assert_eq!(diverging(3.0), RGBColor(178, 24, 43));
        let shots = |b: &[f64]| b.iter().map(|&b| (0.0, 0.0, b)).collect::<Vec<_>>();
        // 20 shots: the 95th percentile of |bias| is the 19th value, the outlier is clipped.
        let mut b: Vec<f64> = (1..=19).map(|i| i as f64 * 0.1).collect();
        b.push(-40.0);
        assert!((colour_limit(&shots(&b)) - 1.9).abs() < 1e-12);
        assert_eq!(colour_limit(&shots(&[0.1, -0.2])), 0.5);
    }

    #[test]
    fn tiles_far_apart_make_separate_areas() {
        let tile = |x: f64, y: f64| [x, y, x + 1000.0, y + 1000.0];
        // Two touching tiles, one 3 km away (same area), one 400 km away.
        let tiles = [tile(0.0, 0.0), tile(1000.0, 0.0), tile(5000.0, 0.0), tile(400_000.0, 0.0)];
        let shots = [(500.0, 500.0, 1.0), (1500.0, 200.0, -1.0), (400_500.0, 500.0, 0.3), (900_000.0, 0.0, 0.0)];
        let a = areas(&tiles, &shots);
        assert_eq!(a.len(), 3, "{a:?}");
        assert_eq!((a[0].tiles.len(), a[0].shots.len()), (3, 2));
        assert!(a[1..].iter().any(|a| a.tiles.len() == 1 && a.shots == [(400_500.0, 500.0, 0.3)]));
        assert!(a[1..].iter().any(|a| a.tiles.is_empty() && a.shots.len() == 1), "shots near no tile: one area");
        // Without tiles every shot is in that one area.
        assert_eq!(areas(&[], &shots).len(), 1);
    }
}
