//! The report's figures, drawn with plotters into PNG (bitmap backend, encoded with `png`) and SVG.
//! Text uses the bundled DejaVu Sans through plotters' `ab_glyph` backend: no fontconfig or
//! freetype on the machine. Each figure is a plain data struct (filled from the report tables by
//! `report::figure_data`) and one drawing function generic over the backend.

use std::error::Error as StdError;
use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::error::{Error, Result};

type DrawResult = std::result::Result<(), Box<dyn StdError>>;

/// DejaVu Sans 2.37 (Bitstream Vera license; assets/fonts/PROVENANCE.md).
static FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bundled font is valid TrueType; a failure would only leave text undrawn.
        let _ = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT);
    });
}

/// Series colours (colour-blind-safe Okabe–Ito palette).
pub const COLORS: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(213, 94, 0),
    RGBColor(0, 0, 0),
];

/// A figure: a size and a drawing on any plotters backend.
pub trait Figure {
    /// Width and height in pixels (PNG) or user units (SVG).
    fn size(&self) -> (u32, u32);
    /// Draw on `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static;
}

/// Render `fig` to `<dir>/<name>.png` and `<dir>/<name>.svg` (each written atomically).
pub fn render(fig: &impl Figure, dir: &Path, name: &str) -> Result<[PathBuf; 2]> {
    register_font();
    let (w, h) = fig.size();
    let fail = |e: Box<dyn StdError>| Error::file(dir.join(name), format!("cannot draw figure: {e}"));
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        fig.draw(&root).map_err(fail)?;
        root.present().map_err(|e| fail(Box::new(e)))?;
    }
    let mut png_bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut png_bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(|e| fail(Box::new(e)))?;
        writer.write_image_data(&rgb).map_err(|e| fail(Box::new(e)))?;
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        fig.draw(&root).map_err(fail)?;
        root.present().map_err(|e| fail(Box::new(e)))?;
    }
    let png_path = dir.join(format!("{name}.png"));
    let svg_path = dir.join(format!("{name}.svg"));
    crate::dataset::write_atomic(&png_path, &png_bytes)?;
    crate::dataset::write_atomic(&svg_path, svg.as_bytes())?;
    Ok([png_path, svg_path])
}

/// The legend of a chart's labelled series, drawn the same way in every figure.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    font_size: u32,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .position(position)
        .label_font(font(font_size))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

pub(super) fn font(size: u32) -> TextStyle<'static> {
    (FAMILY, size).into_font().color(&BLACK)
}

/// Axis tick text: at most two decimals, trailing zeros dropped (10 not 10.0, 0.25, 1.5).
pub(super) fn tick(v: &f64) -> String {
    let t = format!("{v:.2}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    if t == "-0" {
        "0".to_string()
    } else {
        t.to_string()
    }
}

/// Colour of the fine grid lines.
pub(super) const LIGHT: RGBColor = RGBColor(236, 236, 236);

/// Range of `values` with a margin; a fallback when empty or flat.
fn padded_range(values: impl Iterator<Item = f64>, include_zero: bool) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return 0.0..1.0;
    }
    if hi - lo < 1e-9 {
        return lo - 0.5..hi + 0.5;
    }
    let pad = (hi - lo) * 0.06;
    lo - if include_zero && lo == 0.0 { 0.0 } else { pad }..hi + pad
}

/// One panel of MSD stacked bars: per percentile (SB, SDSD, LCS).
#[derive(Debug, Clone)]
pub struct MsdPanel {
    pub title: String,
    /// (percentile, sb, sdsd, lcs)
    pub bars: Vec<(u32, f64, f64, f64)>,
}

/// Per-percentile MSD stacked bars, one panel per setting (baseline, best), shared y scale.
#[derive(Debug, Clone)]
pub struct MsdBars {
    pub panels: Vec<MsdPanel>,
}

impl Figure for MsdBars {
    fn size(&self) -> (u32, u32) {
        (1100, 330 * self.panels.len().max(1) as u32 + 40)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled("MSD of simulated vs real RH per percentile: SB + SDSD + LCS", font(22))?;
        let ymax = padded_range(self.panels.iter().flat_map(|p| p.bars.iter().map(|b| b.1 + b.2 + b.3)), true).end;
        let areas = root.split_evenly((self.panels.len().max(1), 1));
        for (panel, area) in self.panels.iter().zip(&areas) {
            let mut chart = ChartBuilder::on(area)
                .caption(&panel.title, font(18))
                .margin(10)
                .margin_right(25)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0f64..100f64, 0f64..ymax)?;
            chart
                .configure_mesh()
                .x_label_formatter(&tick)
                .y_label_formatter(&tick)
                .light_line_style(LIGHT)
                .disable_x_mesh()
                .x_desc("RH percentile")
                .y_desc("MSD (m²)")
                .label_style(font(14))
                .axis_desc_style(font(15))
                .draw()?;
            let parts: [(&str, RGBColor); 3] = [("SB", COLORS[0]), ("SDSD", COLORS[1]), ("LCS", COLORS[2])];
            for (k, (label, color)) in parts.iter().enumerate() {
                let rects = panel.bars.iter().map(|&(p, sb, sdsd, lcs)| {
                    let v = [sb, sdsd, lcs];
                    let base: f64 = v[..k].iter().sum();
                    let x = p as f64;
                    Rectangle::new([(x - 0.42, base), (x + 0.42, base + v[k])], color.filled())
                });
                let color = *color;
                chart
                    .draw_series(rects)?
                    .label(*label)
                    .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled()));
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
        }
        Ok(())
    }
}

/// A named series of (x, y) points.
pub type Series = (String, Vec<(f64, f64)>);
/// A titled panel of series.
pub type Panel = (String, Vec<Series>);
/// A phenology panel: title, leaf-on (percentile, bias), leaf-off (percentile, bias).
pub type PhenologyPanel = (String, Vec<(f64, f64)>, Vec<(f64, f64)>);

/// A multi-panel line chart: per panel, named series of (x, y) points.
#[derive(Debug, Clone)]
pub struct LinePanels {
    pub title: String,
    pub x_desc: String,
    pub y_desc: String,
    /// (panel title, [(series label, points)])
    pub panels: Vec<Panel>,
    /// Draw y = 0.
    pub zero_line: bool,
    /// Where the legend goes.
    pub legend_lower: bool,
    /// Each panel scales its own y axis (default: one range for all, so panels compare).
    pub own_y: bool,
}

impl Figure for LinePanels {
    fn size(&self) -> (u32, u32) {
        (420 * self.panels.len().max(1) as u32 + 40, 460)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled(&self.title, font(20))?;
        let all = || self.panels.iter().flat_map(|p| p.1.iter().flat_map(|s| s.1.iter()));
        let xr = padded_range(all().map(|p| p.0), false);
        let yr = padded_range(all().map(|p| p.1), self.zero_line);
        let areas = root.split_evenly((1, self.panels.len().max(1)));
        for ((title, series), area) in self.panels.iter().zip(&areas) {
            let yr = if self.own_y {
                padded_range(series.iter().flat_map(|s| s.1.iter()).map(|p| p.1), self.zero_line)
            } else {
                yr.clone()
            };
            let mut chart = ChartBuilder::on(area)
                .caption(title, font(16))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(xr.clone(), yr.clone())?;
            chart
                .configure_mesh()
                .x_label_formatter(&tick)
                .y_label_formatter(&tick)
                .light_line_style(LIGHT)
                .x_desc(&self.x_desc)
                .y_desc(&self.y_desc)
                .label_style(font(13))
                .axis_desc_style(font(14))
                .draw()?;
            if self.zero_line {
                chart.draw_series(LineSeries::new([(xr.start, 0.0), (xr.end, 0.0)], BLACK.mix(0.5)))?;
            }
            for (k, (label, pts)) in series.iter().enumerate() {
                // The pooled series ("all …") in black and thicker, over the others.
                let pooled = label.starts_with("all");
                let color = if pooled { BLACK } else { COLORS[k % (COLORS.len() - 1)] };
                let color = color.stroke_width(if pooled { 3 } else { 2 });
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), color))?
                    .label(label.as_str())
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], color));
            }
            if !series.is_empty() {
                let corner =
                    if self.legend_lower { SeriesLabelPosition::LowerLeft } else { SeriesLabelPosition::UpperLeft };
                draw_legend(&mut chart, corner, 13)?;
            }
        }
        Ok(())
    }
}

/// Leaf-on vs leaf-off bias profiles, one panel per setting, with the |ΔBias| band between them.
#[derive(Debug, Clone)]
pub struct PhenologyBands {
    /// (panel title, leaf-on (percentile, bias), leaf-off (percentile, bias))
    pub panels: Vec<PhenologyPanel>,
}

impl Figure for PhenologyBands {
    fn size(&self) -> (u32, u32) {
        (520 * self.panels.len().max(1) as u32 + 40, 480)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled("Bias of simulated RH, leaf-on vs leaf-off (band: |ΔBias|)", font(20))?;
        let yr = padded_range(self.panels.iter().flat_map(|p| p.1.iter().chain(&p.2).map(|q| q.1)), true);
        let areas = root.split_evenly((1, self.panels.len().max(1)));
        for ((title, on, off), area) in self.panels.iter().zip(&areas) {
            let mut chart = ChartBuilder::on(area)
                .caption(title, font(16))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(0f64..100f64, yr.clone())?;
            chart
                .configure_mesh()
                .x_label_formatter(&tick)
                .y_label_formatter(&tick)
                .light_line_style(LIGHT)
                .x_desc("RH percentile")
                .y_desc("bias, simulated − real (m)")
                .label_style(font(13))
                .axis_desc_style(font(14))
                .draw()?;
            chart.draw_series(LineSeries::new([(0.0, 0.0), (100.0, 0.0)], BLACK.mix(0.5)))?;
            // The band joins the two curves at the percentiles both have.
            let off_at = |p: f64| off.iter().find(|q| q.0 == p).map(|q| q.1);
            let pairs: Vec<(f64, f64, f64)> = on.iter().filter_map(|&(p, b)| off_at(p).map(|o| (p, b, o))).collect();
            if pairs.len() > 1 {
                let mut poly: Vec<(f64, f64)> = pairs.iter().map(|&(p, a, _)| (p, a)).collect();
                poly.extend(pairs.iter().rev().map(|&(p, _, b)| (p, b)));
                chart
                    .draw_series(std::iter::once(Polygon::new(poly, RGBColor(150, 150, 150).mix(0.35).filled())))?
                    .label("|ΔBias|")
                    .legend(|(x, y)| {
                        Rectangle::new([(x, y - 6), (x + 14, y + 6)], RGBColor(150, 150, 150).mix(0.35).filled())
                    });
            }
            for (label, pts, color) in [("leaf-on", on, COLORS[2]), ("leaf-off", off, COLORS[5])] {
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))?
                    .label(label)
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], color.stroke_width(2)));
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 13)?;
        }
        Ok(())
    }
}

/// Collocation: Pearson r of each segment before vs after, with the 1:1 line.
#[derive(Debug, Clone)]
pub struct CollocationScatter {
    /// (r_before, r_after)
    pub points: Vec<(f64, f64)>,
}

impl Figure for CollocationScatter {
    fn size(&self) -> (u32, u32) {
        (620, 600)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let r = padded_range(self.points.iter().flat_map(|p| [p.0, p.1]), false);
        let (lo, hi) = (r.start.max(-1.0), r.end.min(1.0));
        let mut chart = ChartBuilder::on(root)
            .caption("Waveform correlation per segment, before vs after collocation", font(18))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(lo..hi, lo..hi)?;
        chart
            .configure_mesh()
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .light_line_style(LIGHT)
            .x_desc("Pearson r at the reported position")
            .y_desc("Pearson r after collocation")
            .label_style(font(13))
            .axis_desc_style(font(14))
            .draw()?;
        chart
            .draw_series(LineSeries::new([(lo, lo), (hi, hi)], BLACK.mix(0.6)))?
            .label("1:1")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLACK.mix(0.6)));
        chart
            .draw_series(self.points.iter().map(|&(a, b)| Circle::new((a, b), 4, COLORS[0].mix(0.8).filled())))?
            .label(format!("{} segments", self.points.len()))
            .legend(|(x, y)| Circle::new((x + 7, y), 4, COLORS[0].filled()));
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 13)?;
        Ok(())
    }
}

/// Real and simulated waveforms of a few shots: amplitude (x) against elevation (y).
#[derive(Debug, Clone)]
pub struct Waveforms {
    /// (panel title, [(series label, [(amplitude, elevation)])])
    pub panels: Vec<Panel>,
}

impl Figure for Waveforms {
    fn size(&self) -> (u32, u32) {
        (400 * self.panels.len().max(1) as u32 + 40, 620)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let root = root.titled("Real vs simulated waveforms (ALS vertical datum)", font(20))?;
        let areas = root.split_evenly((1, self.panels.len().max(1)));
        for ((title, series), area) in self.panels.iter().zip(&areas) {
            let xr = padded_range(series.iter().flat_map(|s| s.1.iter().map(|p| p.0)), true);
            let yr = padded_range(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)), false);
            let mut chart = ChartBuilder::on(area)
                .caption(title, font(15))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(xr, yr)?;
            chart
                .configure_mesh()
                .x_label_formatter(&tick)
                .y_label_formatter(&tick)
                .light_line_style(LIGHT)
                .x_desc("amplitude (unit area)")
                .y_desc("elevation (m)")
                .label_style(font(12))
                .axis_desc_style(font(14))
                .draw()?;
            for (k, (label, pts)) in series.iter().enumerate() {
                let color = if label == "GEDI" { BLACK } else { COLORS[k % COLORS.len()] };
                let width = if label == "GEDI" { 3 } else { 2 };
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(width)))?
                    .label(label.as_str())
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], color.stroke_width(2)));
            }
            draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 13)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padded_range_handles_flat_and_empty() {
        assert_eq!(padded_range(std::iter::empty(), false), 0.0..1.0);
        assert_eq!(padded_range([2.0, 2.0].into_iter(), false), 1.5..2.5);
        let r = padded_range([1.0, 3.0].into_iter(), true);
        assert!(r.start == 0.0 && r.end > 3.0);
        assert!(padded_range([f64::NAN, 1.0, 2.0].into_iter(), false).start < 1.0);
    }
}
