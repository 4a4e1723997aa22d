//! `gedisim report`: runs the study's queries (`queries/*.sql`, compiled into the binary) over a
//! dataset's `results` (and `strata`, `shots`, `sim`, `offsets` when present), writes each table to
//! `<dataset>/report/<name>.parquet` and `.csv`, draws the figures (PNG + SVG), writes
//! `report.html`, and hands `shots`/`results` off as GeoParquet.
//!
//! A query names the tables it needs on a `-- requires: a, b` line; when one is missing the query
//! is skipped and the report says so.

pub mod agreement;
pub mod diagnosis;
pub mod figures;
pub mod geoparquet;
pub mod headline;
pub mod html;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, AsArray, RecordBatch};
use arrow::datatypes::{DataType, Float64Type, SchemaRef};

use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::ops::progress::{Progress, Step};
pub use crate::sql::Engine;

/// One of the study's tables: its name (file stem), a title and its SQL.
#[derive(Debug, Clone, Copy)]
pub struct Query {
    pub name: &'static str,
    pub title: &'static str,
    pub sql: &'static str,
}

macro_rules! query {
    ($name:literal, $title:literal) => {
        Query { name: $name, title: $title, sql: include_str!(concat!("../../../queries/", $name, ".sql")) }
    };
}

/// The study's tables, in report order (the files of `queries/`, bundled).
pub const QUERIES: &[Query] = &[
    query!("dataset_summary", "Dataset summary by forest type and beam type"),
    query!("rh_agreement", "Simulated vs aligned GEDI RH98 and RH50: n, bias (m), RMSE (m), R²"),
    query!("shot_agreement", "RH98 and RH50 of each shot, simulated and aligned GEDI (m), and its position"),
    query!("tile_extents", "Extents of the ALS tiles"),
    query!("ground_detection", "Ground detection: GEDI ground − ALS ground"),
    query!("msd", "MSD of simulated vs real RH (mean over RH1–RH99), split into SB, SDSD, LCS"),
    query!("msd_profile", "MSD split per percentile"),
    query!("bias_summary", "Bias of simulated RH: mean |bias| over RH1–RH99"),
    query!("bias_profiles", "Bias of simulated RH per percentile, by forest type and sensitivity group"),
    query!("phenology", "Leaf-on vs leaf-off: bias, RMSE, R² per percentile"),
    query!("collocation", "Collocation: waveform correlation before and after"),
    query!("collocation_segments", "Collocation per segment"),
    query!("waveform_examples", "Waveforms of typical shots"),
];

/// The tables a query names on its `-- requires:` line.
pub fn required_tables(sql: &str) -> Vec<String> {
    sql.lines()
        .filter_map(|l| l.trim().strip_prefix("--")?.trim().strip_prefix("requires:").map(str::to_string))
        .flat_map(|l| l.split(',').map(|t| t.trim().to_string()).filter(|t| !t.is_empty()).collect::<Vec<_>>())
        .collect()
}

/// A query's result.
#[derive(Debug, Clone)]
pub struct TableOutput {
    pub query: Query,
    pub schema: SchemaRef,
    pub batches: Vec<RecordBatch>,
}

impl TableOutput {
    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.batches.iter().map(|b| b.num_rows()).sum()
    }

    /// All rows in one batch.
    pub fn batch(&self) -> Result<RecordBatch> {
        arrow::compute::concat_batches(&self.schema, &self.batches).map_err(|e| Error::table(self.query.name, e))
    }
}

/// What running one query gave.
#[derive(Debug, Clone)]
pub enum QueryOutcome {
    Ran(TableOutput),
    /// Not run: these tables are missing from the dataset.
    Skipped {
        query: Query,
        missing: Vec<String>,
    },
}

/// Run every query of [`QUERIES`] whose tables exist, on `engine`. `on_query(name)` is called before each.
pub async fn run_queries(ds: &Dataset, engine: &Engine, on_query: &dyn Fn(&str)) -> Result<Vec<QueryOutcome>> {
    if !ds.has_table(tables::RESULTS) {
        return Err(Error::file(ds.root().join(tables::RESULTS), "no results table: run `gedisim run` first"));
    }
    let ctx = crate::sql::session_on(ds, &Default::default(), engine).await?;
    let mut out = Vec::new();
    for q in QUERIES {
        let missing: Vec<String> = required_tables(q.sql).into_iter().filter(|t| !ds.has_table(t)).collect();
        if !missing.is_empty() {
            out.push(QueryOutcome::Skipped { query: *q, missing });
            continue;
        }
        on_query(q.name);
        let where_ = format!("queries/{}.sql", q.name);
        let df = ctx.sql(q.sql).await.map_err(|e| Error::field(&where_, "SQL", e))?;
        let schema = plain_schema(df.schema().as_arrow());
        let batches = df.collect().await.map_err(|e| Error::field(&where_, "SQL", e))?;
        let batches = batches.iter().map(|b| plain_batch(b, &schema)).collect::<Result<Vec<_>>>()?;
        out.push(QueryOutcome::Ran(TableOutput { query: *q, schema, batches }));
    }
    Ok(out)
}

/// `schema` with DataFusion's view types (`Utf8View`, `BinaryView`, lists of them) replaced by the
/// plain Arrow types, so that the report's files read the same everywhere; every field nullable
/// (the data, not the plan, decides: a UNION can make a column nullable).
pub fn plain_schema(schema: &arrow::datatypes::Schema) -> SchemaRef {
    fn plain(t: &DataType) -> DataType {
        match t {
            DataType::Utf8View => DataType::Utf8,
            DataType::BinaryView => DataType::Binary,
            DataType::List(f) => DataType::List(Arc::new(f.as_ref().clone().with_data_type(plain(f.data_type())))),
            DataType::LargeList(f) => {
                DataType::LargeList(Arc::new(f.as_ref().clone().with_data_type(plain(f.data_type()))))
            }
            other => other.clone(),
        }
    }
    let fields: Vec<arrow::datatypes::Field> = schema
        .fields()
        .iter()
        .map(|f| f.as_ref().clone().with_data_type(plain(f.data_type())).with_nullable(true))
        .collect();
    Arc::new(arrow::datatypes::Schema::new(fields))
}

/// `b` cast to `schema` (same column names and order; see [`plain_schema`]).
pub fn plain_batch(b: &RecordBatch, schema: &SchemaRef) -> Result<RecordBatch> {
    let cols = b
        .columns()
        .iter()
        .zip(schema.fields())
        .map(
            |(c, f)| {
                if c.data_type() == f.data_type() {
                    Ok(c.clone())
                } else {
                    arrow::compute::cast(c, f.data_type())
                }
            },
        )
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|e| Error::table("report", e))?;
    RecordBatch::try_new(schema.clone(), cols).map_err(|e| Error::table("report", e))
}

/// Write a query's result as `<dir>/<name>.parquet` and `<dir>/<name>.csv` (list columns are
/// written to the CSV as text `[a, b, …]`).
pub fn write_table(dir: &Path, t: &TableOutput) -> Result<[PathBuf; 2]> {
    write_named_table(dir, t.query.name, &t.batch()?)
}

/// Write `batch` as `<dir>/<name>.parquet` and `<dir>/<name>.csv` (list columns as text).
pub fn write_named_table(dir: &Path, name: &str, batch: &RecordBatch) -> Result<[PathBuf; 2]> {
    let pq = dir.join(format!("{name}.parquet"));
    dataset::write_parquet(&pq, batch.schema(), std::slice::from_ref(batch), &Default::default())?;
    let csv = dir.join(format!("{name}.csv"));
    let mut bytes = Vec::new();
    {
        let mut w = arrow::csv::WriterBuilder::new().with_header(true).build(&mut bytes);
        let batch = lists_as_text(batch).map_err(|e| Error::table(&csv, e))?;
        w.write(&batch).map_err(|e| Error::table(&csv, e))?;
    }
    crate::dataset::write_atomic(&csv, &bytes)?;
    Ok([pq, csv])
}

fn lists_as_text(b: &RecordBatch) -> std::result::Result<RecordBatch, arrow::error::ArrowError> {
    let mut fields = Vec::new();
    let mut cols = Vec::new();
    for (f, c) in b.schema().fields().iter().zip(b.columns()) {
        if matches!(f.data_type(), DataType::List(_) | DataType::LargeList(_)) {
            let opts = arrow::util::display::FormatOptions::default();
            let fmt = arrow::util::display::ArrayFormatter::try_new(c.as_ref(), &opts)?;
            let text: arrow::array::StringArray =
                (0..c.len()).map(|i| (!c.is_null(i)).then(|| fmt.value(i).to_string())).collect();
            fields.push(arrow::datatypes::Field::new(f.name(), DataType::Utf8, true));
            cols.push(Arc::new(text) as _);
        } else {
            fields.push(f.as_ref().clone());
            cols.push(c.clone());
        }
    }
    RecordBatch::try_new(Arc::new(arrow::datatypes::Schema::new(fields)), cols)
}

/// What `report` wrote.
#[derive(Debug, Clone, Default)]
pub struct ReportSummary {
    /// (table name, rows)
    pub tables: Vec<(String, usize)>,
    /// (table name, missing input tables)
    pub skipped: Vec<(String, Vec<String>)>,
    /// PNG and SVG files.
    pub figures: Vec<PathBuf>,
    /// Figures not drawn, and why.
    pub figure_notes: Vec<String>,
    /// GeoParquet files.
    pub geoparquet: Vec<PathBuf>,
    /// report.html
    pub html: PathBuf,
    /// Output directory.
    pub dir: PathBuf,
}

/// Where `report` writes, and what else it shows.
#[derive(Debug, Clone, Default)]
pub struct ReportOptions {
    /// Output directory (default `<dataset>/report/`).
    pub out: Option<PathBuf>,
    /// A `gedisim diagnose --out` folder whose verdict, effects and figures the page shows.
    pub diagnosis: Option<PathBuf>,
}

/// `gedisim report`: the whole report, as one [`Step::Report`] whose notes name what it is doing;
/// its queries run on `engine`.
pub fn run_report(
    ds: &Dataset,
    opts: &ReportOptions,
    engine: &Engine,
    progress: &dyn Progress,
) -> Result<ReportSummary> {
    let ds = &ds.as_writer()?;
    progress.start(Step::Report, 0);
    let summary = report(ds, opts, engine, &|what| progress.note(what));
    progress.finish();
    summary
}

fn report(ds: &Dataset, opts: &ReportOptions, engine: &Engine, on_step: &dyn Fn(&str)) -> Result<ReportSummary> {
    let dir = match &opts.out {
        Some(d) => d.clone(),
        None => ds.root().join(tables::REPORT),
    };
    // Read before anything is written: a bad folder fails in one line and leaves no report.
    let diagnosis = opts.diagnosis.as_deref().map(|d| diagnosis::section(d, ds.root())).transpose()?;
    std::fs::create_dir_all(&dir).map_err(|e| Error::file(&dir, format!("cannot create report directory: {e}")))?;
    let rt = crate::sql::runtime()?;
    let outcomes = rt.block_on(run_queries(ds, engine, &|name| on_step(&format!("query {name}"))))?;
    let mut summary = ReportSummary { dir: dir.clone(), ..Default::default() };
    let mut ran = Vec::new();
    for o in outcomes {
        match o {
            QueryOutcome::Ran(t) => {
                write_table(&dir, &t)?;
                summary.tables.push((t.query.name.to_string(), t.rows()));
                ran.push(t);
            }
            QueryOutcome::Skipped { query, missing } => summary.skipped.push((query.name.to_string(), missing)),
        }
    }
    on_step("figures");
    let figs = figure_data(&ran)?;
    let mut drawn = Vec::new();
    for (name, fig) in figs.drawable {
        let files = match &fig {
            AnyFigure::Msd(f) => figures::render(f, &dir, name)?,
            AnyFigure::Lines(f) => figures::render(f, &dir, name)?,
            AnyFigure::Phenology(f) => figures::render(f, &dir, name)?,
            AnyFigure::Collocation(f) => figures::render(f, &dir, name)?,
            AnyFigure::Waveforms(f) => figures::render(f, &dir, name)?,
            AnyFigure::Scatter(f) => figures::render(f, &dir, name)?,
            AnyFigure::Map(f) => figures::render(f, &dir, name)?,
        };
        summary.figures.extend(files.iter().cloned());
        drawn.push((name, fig.caption()));
    }
    summary.figure_notes = figs.notes;
    on_step("GeoParquet");
    let mut geo_notes = Vec::new();
    for table in [tables::SHOTS, tables::RESULTS] {
        if !ds.has_table(tables::SHOTS) {
            geo_notes.push(format!("{table}: no GeoParquet (positions come from the shots table, which is missing)"));
            continue;
        }
        let path = dir.join(format!("{table}.geoparquet"));
        let rows = rt.block_on(geoparquet::export(ds, table, &path, geoparquet::GeoCrs::Wgs84))?;
        summary.geoparquet.push(path);
        on_step(&format!("{table}.geoparquet: {rows} rows"));
    }
    on_step("report.html");
    let page = html::page(ds, &ran, &summary, &drawn, &geo_notes, diagnosis.as_deref())?;
    summary.html = dir.join("report.html");
    crate::dataset::write_atomic(&summary.html, page.as_bytes())?;
    Ok(summary)
}

/// A figure of any kind.
#[derive(Debug, Clone)]
pub enum AnyFigure {
    Msd(figures::MsdBars),
    Lines(figures::LinePanels),
    Phenology(figures::PhenologyBands),
    Collocation(figures::CollocationScatter),
    Waveforms(figures::Waveforms),
    Scatter(agreement::RhScatter),
    Map(agreement::ShotMap),
}

impl AnyFigure {
    /// The caption shown under the figure in report.html.
    pub fn caption(&self) -> String {
        match self {
            AnyFigure::Msd(_) => {
                "Per-percentile MSD split (SB: bias, SDSD: spread, LCS: lack of correlation) of the baseline \
                                  (count weighting, default algorithm) and of the setting with the lowest MSD."
                    .into()
            }
            AnyFigure::Lines(f) => f.title.clone(),
            AnyFigure::Phenology(_) => {
                "Bias of simulated RH per percentile for leaf-on and leaf-off shots; the grey band is \
                                        |ΔBias| between the two."
                    .into()
            }
            AnyFigure::Collocation(_) => {
                "Mean Pearson r between real and simulated waveforms of each segment at the reported \
                                          position and at the collocated offset."
                    .into()
            }
            AnyFigure::Scatter(f) => f.caption(),
            AnyFigure::Map(f) => f.caption(),
            AnyFigure::Waveforms(_) => {
                "Real GEDI waveform (noise mean removed) and the simulated waveforms of the three \
                                        weightings, each scaled to unit area, on the ALS vertical datum."
                    .into()
            }
        }
    }
}

/// Figures that can be drawn from the tables that ran, and notes on those that cannot.
#[derive(Debug, Clone, Default)]
pub struct FigureData {
    pub drawable: Vec<(&'static str, AnyFigure)>,
    pub notes: Vec<String>,
}

fn table<'a>(ran: &'a [TableOutput], name: &str) -> Option<&'a TableOutput> {
    ran.iter().find(|t| t.query.name == name)
}

/// A column as strings (`None` for null).
pub fn strings(b: &RecordBatch, name: &str) -> Result<Vec<Option<String>>> {
    let c = b.column_by_name(name).ok_or_else(|| Error::field("report", name, "column missing"))?;
    let c = arrow::compute::cast(c, &DataType::Utf8).map_err(|e| Error::field("report", name, e))?;
    let s = c.as_string::<i32>();
    Ok((0..s.len()).map(|i| (!s.is_null(i)).then(|| s.value(i).to_string())).collect())
}

/// A column as f64 (`NaN` for null).
pub fn floats(b: &RecordBatch, name: &str) -> Result<Vec<f64>> {
    let c = b.column_by_name(name).ok_or_else(|| Error::field("report", name, "column missing"))?;
    let c = arrow::compute::cast(c, &DataType::Float64).map_err(|e| Error::field("report", name, e))?;
    let a = c.as_primitive::<Float64Type>();
    Ok((0..a.len()).map(|i| if a.is_null(i) { f64::NAN } else { a.value(i) }).collect())
}

/// Build the figures' data from the report tables.
pub fn figure_data(ran: &[TableOutput]) -> Result<FigureData> {
    let mut fd = FigureData::default();
    agreement::add_figures(ran, &mut fd)?;
    // MSD bars: baseline count–default and the (weighting, algorithm) of lowest MSD over all shots.
    if let (Some(msd), Some(profile)) = (table(ran, "msd"), table(ran, "msd_profile")) {
        let b = msd.batch()?;
        let (w, a, g, m) = (
            strings(&b, "weighting")?,
            strings(&b, "algorithm")?,
            strings(&b, "sensitivity_group")?,
            floats(&b, "msd")?,
        );
        let best = (0..b.num_rows())
            .filter(|&i| g[i].as_deref() == Some("all") && m[i].is_finite())
            .min_by(|&i, &j| m[i].total_cmp(&m[j]))
            .map(|i| (w[i].clone().unwrap_or_default(), a[i].clone().unwrap_or_default(), m[i]));
        let p = profile.batch()?;
        let (pw, pa, pg, pp) = (
            strings(&p, "weighting")?,
            strings(&p, "algorithm")?,
            strings(&p, "sensitivity_group")?,
            floats(&p, "percentile")?,
        );
        let (sb, sdsd, lcs) = (floats(&p, "sb")?, floats(&p, "sdsd")?, floats(&p, "lcs")?);
        let bars = |wt: &str, al: &str| -> Vec<(u32, f64, f64, f64)> {
            (0..p.num_rows())
                .filter(|&i| {
                    pw[i].as_deref() == Some(wt) && pa[i].as_deref() == Some(al) && pg[i].as_deref() == Some("all")
                })
                .map(|i| (pp[i] as u32, sb[i], sdsd[i], lcs[i]))
                .collect()
        };
        let mut panels = Vec::new();
        let base = bars("count", "default");
        let base_msd = (0..b.num_rows())
            .find(|&i| {
                w[i].as_deref() == Some("count") && a[i].as_deref() == Some("default") && g[i].as_deref() == Some("all")
            })
            .map(|i| m[i]);
        if let Some(bm) = base_msd.filter(|_| !base.is_empty()) {
            let also_best = best.as_ref().map(|(bw, ba, _)| bw == "count" && ba == "default").unwrap_or(false);
            let title = format!(
                "baseline: count weighting, default algorithm (MSD {bm:.2} m²){}",
                if also_best { ", also the lowest" } else { "" }
            );
            panels.push(figures::MsdPanel { title, bars: base });
        }
        if let Some((bw, ba, bm)) = best.filter(|(bw, ba, _)| !(bw == "count" && ba == "default")) {
            panels.push(figures::MsdPanel {
                title: format!("lowest MSD: {bw} weighting, algorithm {ba} (MSD {bm:.2} m²)"),
                bars: bars(&bw, &ba),
            });
        }
        if panels.is_empty() {
            fd.notes.push("msd_bars: no rows in msd_profile".into());
        } else {
            fd.drawable.push(("msd_bars", AnyFigure::Msd(figures::MsdBars { panels })));
        }
    }
    // Bias profiles by forest type, one panel per sensitivity group, baseline setting.
    if let Some(t) = table(ran, "bias_profiles") {
        let b = t.batch()?;
        let (w, a, f, g) = (
            strings(&b, "weighting")?,
            strings(&b, "algorithm")?,
            strings(&b, "forest_type")?,
            strings(&b, "sensitivity_group")?,
        );
        let (p, bias, n) = (floats(&b, "percentile")?, floats(&b, "bias")?, floats(&b, "n")?);
        let mut panels = Vec::new();
        for group in ["low", "high", "all"] {
            let mut series: Vec<figures::Series> = Vec::new();
            let present = |ft: &str| {
                (0..b.num_rows()).any(|i| {
                    w[i].as_deref() == Some("count")
                        && a[i].as_deref() == Some("default")
                        && g[i].as_deref() == Some(group)
                        && f[i].as_deref() == Some(ft)
                })
            };
            let types: Vec<&str> =
                crate::kernels::study::classes::FOREST_TYPES.iter().copied().filter(|ft| present(ft)).collect();
            // One forest type alone is the same shots as `all`: drawn once and labelled so.
            let only = types.len() == 1;
            for ft in types.iter().copied().chain((!only).then_some("all")) {
                let rows: Vec<usize> = (0..b.num_rows())
                    .filter(|&i| {
                        w[i].as_deref() == Some("count")
                            && a[i].as_deref() == Some("default")
                            && g[i].as_deref() == Some(group)
                            && f[i].as_deref() == Some(ft)
                    })
                    .collect();
                if rows.is_empty() {
                    continue;
                }
                let shots = rows.iter().map(|&i| n[i]).fold(0.0, f64::max);
                let label = if only {
                    format!("{ft} (n={shots}): the only forest type (= all shots)")
                } else {
                    format!("{ft} (n={shots})")
                };
                series.push((label, rows.iter().map(|&i| (p[i], bias[i])).collect()));
            }
            if !series.is_empty() {
                panels.push((format!("sensitivity: {group}"), series));
            }
        }
        if panels.is_empty() {
            fd.notes.push("bias_profiles: no rows for the count weighting and the default algorithm".into());
        } else {
            fd.drawable.push((
                "bias_profiles",
                AnyFigure::Lines(figures::LinePanels {
                    title: "Bias of simulated RH by forest type (count weighting, default algorithm)".into(),
                    x_desc: "RH percentile".into(),
                    y_desc: "bias, simulated − real (m)".into(),
                    panels,
                    zero_line: true,
                    legend_lower: true,
                    own_y: false,
                }),
            ));
        }
    }
    // Leaf-on vs leaf-off.
    if let Some(t) = table(ran, "phenology") {
        let b = t.batch()?;
        let (ph, w, a) = (strings(&b, "phenology")?, strings(&b, "weighting")?, strings(&b, "algorithm")?);
        let (p, bias) = (floats(&b, "percentile")?, floats(&b, "bias")?);
        let curve = |phen: &str, wt: &str, al: &str| -> Vec<(f64, f64)> {
            (0..b.num_rows())
                .filter(|&i| {
                    ph[i].as_deref() == Some(phen) && w[i].as_deref() == Some(wt) && a[i].as_deref() == Some(al)
                })
                .map(|i| (p[i], bias[i]))
                .collect()
        };
        let mut panels = Vec::new();
        for (wt, al, title) in
            [("count", "default", "count weighting, default algorithm"), ("int", "a3", "int weighting, algorithm a3")]
        {
            let (on, off) = (curve("leaf_on", wt, al), curve("leaf_off", wt, al));
            if !on.is_empty() || !off.is_empty() {
                panels.push((title.to_string(), on, off));
            }
        }
        if panels.is_empty() {
            fd.notes.push(
                "phenology: no shot with a known phenology (V1 granules carry no leaf_off_flag: every shot is \
                    `unknown`)"
                    .into(),
            );
        } else {
            fd.drawable.push(("phenology", AnyFigure::Phenology(figures::PhenologyBands { panels })));
        }
    }
    // Collocation.
    match table(ran, "collocation_segments") {
        Some(t) => {
            let b = t.batch()?;
            let (rb, ra) = (floats(&b, "r_before")?, floats(&b, "r_after")?);
            let points: Vec<(f64, f64)> =
                rb.into_iter().zip(ra).filter(|(a, b)| a.is_finite() && b.is_finite()).collect();
            if points.is_empty() {
                fd.notes.push("collocation: no segment with both correlations".into());
            } else {
                fd.drawable.push(("collocation", AnyFigure::Collocation(figures::CollocationScatter { points })));
            }
        }
        None => fd.notes.push("collocation: no offsets table (run `gedisim collocate`)".into()),
    }
    // Waveforms.
    match table(ran, "waveform_examples") {
        Some(t) => {
            let wf = waveform_panels(&t.batch()?)?;
            if wf.panels.is_empty() {
                fd.notes.push("waveforms: no shot with both a real and a simulated waveform".into());
            } else {
                fd.drawable.push(("waveforms", AnyFigure::Waveforms(wf)));
            }
        }
        None => fd.notes.push("waveforms: needs the shots and sim tables".into()),
    }
    Ok(fd)
}

/// Waveform panels from `waveform_examples` rows: each waveform scaled to unit area
/// (Σ amplitude·dz = 1) after removing the noise mean, at elevations z0 − k·dz.
pub fn waveform_panels(b: &RecordBatch) -> Result<figures::Waveforms> {
    let (shot, source) = (strings(b, "shot_number")?, strings(b, "source")?);
    let (z0, dz, noise) = (floats(b, "z0")?, floats(b, "dz")?, floats(b, "noise_mean")?);
    let wave = b.column_by_name("wave").ok_or_else(|| Error::field("waveform_examples", "wave", "column missing"))?;
    let wave = arrow::compute::cast(
        wave,
        &DataType::List(Arc::new(arrow::datatypes::Field::new_list_field(DataType::Float64, true))),
    )
    .map_err(|e| Error::field("waveform_examples", "wave", e))?;
    let wave = wave.as_list::<i32>();
    let mut panels: Vec<figures::Panel> = Vec::new();
    for i in 0..b.num_rows() {
        let (Some(s), Some(src)) = (&shot[i], &source[i]) else {
            continue;
        };
        if wave.is_null(i) || dz[i].is_nan() || dz[i] <= 0.0 || !z0[i].is_finite() {
            continue;
        }
        let v = wave.value(i);
        let v = v.as_primitive::<Float64Type>();
        let nm = if noise[i].is_finite() { noise[i] } else { 0.0 };
        let amps: Vec<f64> = (0..v.len()).map(|k| if v.is_null(k) { 0.0 } else { v.value(k) - nm }).collect();
        let area: f64 = amps.iter().map(|a| a.max(0.0)).sum::<f64>() * dz[i];
        if area.is_nan() || area <= 0.0 {
            continue;
        }
        let pts: Vec<(f64, f64)> = amps.iter().enumerate().map(|(k, a)| (a / area, z0[i] - k as f64 * dz[i])).collect();
        let label = if src == "gedi" { "GEDI".to_string() } else { format!("sim {src}") };
        let title = format!("shot {s}");
        match panels.iter_mut().find(|p| p.0 == title) {
            Some(p) => p.1.push((label, pts)),
            None => panels.push((title, vec![(label, pts)])),
        }
    }
    // The real waveform first, then the weightings.
    for (_, series) in panels.iter_mut() {
        series.sort_by_key(|s| (s.0 != "GEDI", s.0.clone()));
    }
    // A panel needs the real waveform and at least one simulated one.
    panels.retain(|p| p.1.iter().any(|s| s.0 == "GEDI") && p.1.len() > 1);
    // Show the part of the real waveform around the simulated ones (the real one has long noise tails).
    for (_, series) in panels.iter_mut() {
        let (lo, hi) = series
            .iter()
            .filter(|s| s.0 != "GEDI")
            .flat_map(|s| s.1.iter().filter(|p| p.0 > 1e-4).map(|p| p.1))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| (lo.min(z), hi.max(z)));
        if lo.is_finite() {
            let margin = 0.25 * (hi - lo) + 3.0;
            for s in series.iter_mut() {
                s.1.retain(|p| p.1 >= lo - margin && p.1 <= hi + margin);
            }
        }
    }
    Ok(figures::Waveforms { panels })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_query_declares_its_tables() {
        for q in QUERIES {
            let req = required_tables(q.sql);
            assert!(!req.is_empty(), "{} has no `-- requires:` line", q.name);
            for t in &req {
                assert!(
                    ["results", "shots", "sim", "offsets", "strata", "tiles"].contains(&t.as_str()),
                    "{}: {t}",
                    q.name
                );
            }
        }
        assert_eq!(required_tables("-- requires: results, shots\nselect 1"), ["results", "shots"]);
    }
}
