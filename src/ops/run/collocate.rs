//! Collocate: the granules never collocated (or re-ingested since), merged into
//! `offsets/offsets.parquet`.

use std::collections::{BTreeMap, HashMap, HashSet};

use arrow::array::{AsArray, BooleanArray, RecordBatch};

use super::granules::GranuleFile;
use super::{RunOptions, RunReport, META_GRANULES};
use crate::dataset::offsets::col as offsets_col;
use crate::dataset::offsets::{offsets_metadata, offsets_schema};
use crate::dataset::{self, read, tables, Dataset};
use crate::error::{Error, Result};
use crate::ops::collocate::{solve_granules, CollocateReport};
use crate::ops::progress::Progress;

/// Collocate the granules never collocated (or re-ingested since), merging their segments into
/// `offsets/offsets.parquet`.
pub(super) fn collocate(
    ds: &Dataset,
    opts: &RunOptions,
    granules: &[GranuleFile],
    progress: &dyn Progress,
    report: &mut RunReport,
) -> Result<()> {
    let dest = ds.table_file(tables::OFFSETS, "offsets")?;
    let mut existing: Vec<RecordBatch> = Vec::new();
    let mut meta = HashMap::new();
    if dest.exists() {
        meta = read::key_value_metadata(&dest).unwrap_or_default();
        read::for_each_batch(&dest, None, None, |c| {
            let b = RecordBatch::try_new(offsets_schema(), c.batch().columns().to_vec());
            existing.push(b.map_err(|e| Error::table(&dest, e))?);
            Ok(())
        })?;
    }
    let granule_col =
        |b: &RecordBatch| b.column_by_name(offsets_col::GRANULE).and_then(|c| c.as_string_opt::<i32>().cloned());
    let mut present = HashSet::new();
    for b in &existing {
        let g = granule_col(b).ok_or_else(|| Error::field(&dest, offsets_col::GRANULE, "missing or not a string"))?;
        present.extend(g.iter().flatten().map(str::to_string));
    }
    let recorded: Option<BTreeMap<String, String>> = meta.get(META_GRANULES).and_then(|s| serde_json::from_str(s).ok());
    let needed: Vec<&GranuleFile> = granules
        .iter()
        .filter(|g| match &recorded {
            Some(map) => map.get(&g.key) != Some(&g.inputs),
            // A table made by `gedisim collocate`: its granules are current.
            None => !present.contains(&g.name),
        })
        .collect();
    if needed.is_empty() {
        return Ok(());
    }
    let files = needed.iter().map(|g| g.path.clone()).collect();
    let (offsets, collocation) = solve_granules(&opts.engine, ds, &opts.collocate, files, progress)?;
    // Keep the other granules' segments; replace those of the granules just collocated, and drop
    // those of granules no longer in `shots/` (a granule renamed when its L1B file arrived).
    let replaced: HashSet<&str> = needed.iter().map(|g| g.name.as_str()).collect();
    let current: HashSet<&str> = granules.iter().map(|g| g.name.as_str()).collect();
    let mut batches = Vec::new();
    let mut kept_levels = HashSet::new();
    for b in existing {
        let g = granule_col(&b).ok_or_else(|| Error::field(&dest, offsets_col::GRANULE, "missing or not a string"))?;
        let keep: BooleanArray =
            g.iter().map(|v| Some(v.is_some_and(|v| current.contains(v) && !replaced.contains(v)))).collect();
        let b = arrow::compute::filter_record_batch(&b, &keep).map_err(|e| Error::table(&dest, e))?;
        if let Some(l) = b.column_by_name(offsets_col::LEVEL).and_then(|c| c.as_string_opt::<i32>().cloned()) {
            kept_levels.extend(l.iter().flatten().map(str::to_string));
        }
        batches.push(b);
    }
    batches.extend(offsets);
    let mut map = recorded.unwrap_or_else(|| {
        granules.iter().filter(|g| present.contains(&g.name)).map(|g| (g.key.clone(), g.inputs.clone())).collect()
    });
    for g in &needed {
        map.insert(g.key.clone(), g.inputs.clone());
    }
    let level = opts.collocate.level.name();
    kept_levels.insert(level.to_string());
    let level = if kept_levels.len() > 1 { "mixed" } else { level };
    let mut out_meta = offsets_metadata(level, opts.collocate.max_shift, opts.collocate.step);
    out_meta.insert(META_GRANULES.to_string(), serde_json::to_string(&map).map_err(|e| Error::table(&dest, e))?);
    dataset::write_parquet(&dest, offsets_schema(), &batches, &out_meta)?;
    report.collocation = Some(CollocateReport { table: dest, ..collocation });
    report.collocated = needed.iter().map(|g| g.key.clone()).collect();
    Ok(())
}
