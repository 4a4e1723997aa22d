//! The dataset directory: table names, atomic Parquet writes, and the content-hash registry.
//!
//! A dataset is a directory; each table is a folder of Parquet files (zstd). Every file is
//! written under a temporary name (`*.parquet.tmp`, which readers ignore) and renamed when
//! complete, so a crash never leaves a half-written table.
//!
//! Table modules: [`als`] (reading ALS points back around footprints), [`sim`], [`l2a`],
//! [`offsets`], [`results`] (schemas of the derived tables and kernel outputs as Arrow).

pub mod als;
pub mod l2a;
pub mod lock;
pub mod offsets;
pub mod read;
pub mod results;
pub mod shots;
pub mod sim;
pub mod strata;

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use arrow::record_batch::RecordBatch;
use parquet::arrow::arrow_writer::{compute_leaves, ArrowColumnChunk, ArrowRowGroupWriterFactory};
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::file::writer::SerializedFileWriter;
use rayon::prelude::*;
use sha2::{Digest, Sha256};

use crate::error::{Error, Result};

/// Tables of a dataset, one folder each.
pub mod tables {
    /// ALS points, clustered by spatial cell.
    pub const ALS: &str = "als";
    /// One row per ingested ALS file.
    pub const TILES: &str = "tiles";
    /// One row per GEDI shot.
    pub const SHOTS: &str = "shots";
    /// One row per ingested GEDI granule file.
    pub const GRANULES: &str = "granules";
    /// Simulated waveforms and RH of the shots, written by `run` alone (one file per granule).
    pub const SIM: &str = "sim";
    /// What `simulate --dataset` writes (every shot, or a footprint CSV's positions): apart from
    /// `sim/`, so that a shot is never there twice and plot rows never mix with shot rows.
    pub const SIMULATED: &str = "simulated";
    /// Shot → forest type (`ingest strata`).
    pub const STRATA: &str = "strata";
    /// One row per shot × weighting × algorithm: the study's input (`run`).
    pub const RESULTS: &str = "results";
    /// Collocation offsets per track segment (`collocate`).
    pub const OFFSETS: &str = "offsets";
    /// Report outputs (`report`): not a table; the SQL session does not register it.
    pub const REPORT: &str = "report";
}

/// The schema gedisim writes for the table `name`, if it is one of its tables (not `report/`).
pub fn table_schema(name: &str) -> Option<SchemaRef> {
    Some(match name {
        tables::ALS => als::als_schema(),
        tables::TILES => als::tiles_schema(),
        tables::SHOTS => shots::shots_schema(0),
        tables::GRANULES => shots::granules_schema(),
        tables::SIM | tables::SIMULATED => sim::sim_schema(),
        tables::STRATA => strata::strata_schema(),
        tables::RESULTS => results::results_schema(),
        tables::OFFSETS => offsets::offsets_schema(),
        _ => return None,
    })
}

/// Refuse the first of `files` of table `name` that is a readable Parquet file but not one of the
/// table's: it holds a column the table does not have, or one of the table's with another type (a
/// user's own file put in the folder by hand, whose rows a query would otherwise count among the
/// table's and whose columns it would add). A file lacking some of the table's columns passes (an
/// earlier gedisim's, before a column was added); an unreadable file is left to the reader that
/// meets it. docs/robustness.md.
pub fn foreign_file(name: &str, files: &[PathBuf]) -> Result<()> {
    let Some(table) = table_schema(name) else { return Ok(()) };
    let not_ours = "not a file of this table (a table folder holds only gedisim's own files); move it out";
    for f in files {
        let Ok(file) = File::open(f) else { continue };
        let Ok(meta) = parquet::arrow::arrow_reader::ArrowReaderMetadata::load(&file, Default::default()) else {
            continue;
        };
        for theirs in meta.schema().fields() {
            let column = theirs.name();
            let why = match table.field_with_name(column) {
                Err(_) => format!("no such column in the `{name}` table: {not_ours}"),
                Ok(ours) if !theirs.data_type().equals_datatype(ours.data_type()) => {
                    format!("{} where the `{name}` table has {}: {not_ours}", theirs.data_type(), ours.data_type())
                }
                Ok(_) => continue,
            };
            return Err(Error::field(f, column, why));
        }
    }
    Ok(())
}

/// Refuse a dataset path the SQL engine cannot address: its object store rejects control
/// characters (a newline) in a path, so `sql` and `report` would fail after `run` had worked.
fn addressable(root: &Path) -> Result<()> {
    match root.to_string_lossy().chars().find(|c| c.is_control()) {
        Some(c) => Err(Error::file(
            root,
            format!(
                "the dataset path holds a control character ({c:?}), which the SQL engine cannot address: rename it"
            ),
        )),
        None => Ok(()),
    }
}

/// A dataset directory.
#[derive(Debug, Clone)]
pub struct Dataset {
    root: PathBuf,
    /// The writer lock, for a dataset opened by [`Dataset::writer`].
    lock: Option<Arc<lock::WriteLock>>,
}

impl Dataset {
    /// Open (and create if needed) the dataset at `root`, without the writer lock (library use
    /// where the caller is the only writer; commands use [`Dataset::writer`]).
    pub fn create(root: &Path) -> Result<Self> {
        addressable(root)?;
        std::fs::create_dir_all(root)
            .map_err(|e| Error::file(root, format!("cannot create dataset directory: {e}")))?;
        Ok(Dataset { root: root.to_path_buf(), lock: None })
    }

    /// Open (and create if needed) the dataset at `root` as its one writer: take the writer lock
    /// (one line if another process holds it) and remove what dead writers left
    /// ([`lock::WriteLock::acquire`]). The lock is held while any clone of the dataset lives.
    pub fn writer(root: &Path) -> Result<(Self, lock::Cleanup)> {
        let mut ds = Self::create(root)?;
        let (lock, cleanup) = lock::WriteLock::acquire(&ds)?;
        ds.lock = Some(Arc::new(lock));
        Ok((ds, cleanup))
    }

    /// This dataset as its one writer, for an operation about to write into it: itself when it
    /// holds the writer lock already (an operation inside another, as `run`'s ingest), else
    /// opened again with the lock taken ([`Dataset::writer`]), what dead writers left removed and
    /// said on stderr. Every operation in `ops` that writes a dataset starts with this, so no
    /// caller can forget the lock.
    pub fn as_writer(&self) -> Result<Dataset> {
        if self.lock.is_some() {
            return Ok(self.clone());
        }
        let (ds, cleanup) = Dataset::writer(&self.root)?;
        let (tmp, orphans) = (cleanup.temporaries.len(), cleanup.orphan_points.len());
        if tmp + orphans > 0 {
            tracing::info!(
                "{}: removed what an interrupted writer left: {tmp} temporary file(s), \
                 {orphans} als/ file(s) without a tiles/ row",
                self.root.display()
            );
        }
        Ok(ds)
    }

    /// Open an existing dataset for reading.
    pub fn open(root: &Path) -> Result<Self> {
        addressable(root)?;
        if !root.is_dir() {
            return Err(Error::file(root, "not a dataset directory (run `gedisim ingest` first)"));
        }
        Ok(Dataset { root: root.to_path_buf(), lock: None })
    }

    /// The complete files of table `name` that readers may see, sorted: every Parquet file,
    /// except `als/` files whose `tiles/` row is absent (a tile's points appear with its row).
    pub fn visible_files(&self, name: &str) -> std::io::Result<Vec<PathBuf>> {
        let files = table_files(&self.root.join(name))?;
        if name != tables::ALS {
            return Ok(files);
        }
        let tiles = self.root.join(tables::TILES);
        Ok(files
            .into_iter()
            .filter(|f| {
                let name = f.file_name().and_then(|n| n.to_str());
                name.is_some_and(|n| is_visible(tables::ALS, n, |t| tiles.join(t).is_file()))
            })
            .collect())
    }

    /// The dataset's directory.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Folder of table `name` (created if needed).
    pub fn table_dir(&self, name: &str) -> Result<PathBuf> {
        let dir = self.root.join(name);
        std::fs::create_dir_all(&dir).map_err(|e| Error::file(&dir, format!("cannot create table directory: {e}")))?;
        Ok(dir)
    }

    /// Whether table `name` has at least one complete Parquet file.
    pub fn has_table(&self, name: &str) -> bool {
        table_files(&self.root.join(name)).map(|f| !f.is_empty()).unwrap_or(false)
    }

    /// Path of the Parquet file `stem` of table `name`.
    pub fn table_file(&self, name: &str, stem: &str) -> Result<PathBuf> {
        Ok(self.table_dir(name)?.join(format!("{stem}.parquet")))
    }
}

/// The CRS (EPSG) of the dataset: the one recorded by its ingested tiles and shots (`None` before
/// the first ingest). A dataset holds one CRS; tables that disagree are an error.
pub fn dataset_epsg(dataset: &Dataset) -> Result<Option<u32>> {
    let mut found: Option<(u32, PathBuf)> = None;
    for table in [tables::TILES, tables::SHOTS] {
        let dir = dataset.root().join(table);
        let Some(first) = table_files(&dir).ok().and_then(|f| f.into_iter().next()) else { continue };
        let kv = read::key_value_metadata(&first).unwrap_or_default();
        let Some(epsg) = kv.get(als::meta::EPSG).and_then(|v| v.parse::<u32>().ok()) else { continue };
        match &found {
            Some((other, at)) if *other != epsg => {
                return Err(Error::field(
                    &first,
                    als::meta::EPSG,
                    format!("EPSG:{epsg} differs from EPSG:{other} of {}", at.display()),
                ))
            }
            Some(_) => {}
            None => found = Some((epsg, first)),
        }
    }
    Ok(found.map(|(e, _)| e))
}

/// Whether file `file` of table `table` is one readers may see, given whether `tiles/` has a file of
/// that name (`has_tile`): an `als/` file appears with its `tiles/` row, written after it under the same
/// name; every other table's files always.
pub fn is_visible(table: &str, file: &str, has_tile: impl Fn(&str) -> bool) -> bool {
    table != tables::ALS || has_tile(file)
}

/// The complete Parquet files of a table folder, sorted by name.
pub fn table_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.extension().and_then(|e| e.to_str()) == Some("parquet") {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// Writer properties shared by every table: zstd, page-level statistics, the given
/// key-value metadata and row-group size.
pub fn writer_properties(metadata: &HashMap<String, String>, max_row_group_rows: usize) -> WriterProperties {
    let mut kv: Vec<KeyValue> = metadata.iter().map(|(k, v)| KeyValue::new(k.clone(), v.clone())).collect();
    kv.sort_by(|a, b| a.key.cmp(&b.key));
    WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(3).expect("valid zstd level")))
        .set_statistics_enabled(EnabledStatistics::Page)
        .set_max_row_group_row_count(Some(max_row_group_rows))
        .set_key_value_metadata(Some(kv))
        .build()
}

/// A Parquet file being written under a temporary name; [`AtomicParquet::finish`] renames it
/// into place. Dropping it unfinished removes the temporary file.
///
/// Batches go through [`write`](Self::write) (buffered into row groups by the writer) or
/// [`write_row_group`](Self::write_row_group) (one row group per call, columns encoded in
/// parallel); a file uses one or the other.
pub struct AtomicParquet {
    writer: Option<Writer>,
    tmp: PathBuf,
    dest: PathBuf,
}

enum Writer {
    Buffered(ArrowWriter<File>),
    RowGroups(SerializedFileWriter<File>, ArrowRowGroupWriterFactory),
}

impl AtomicParquet {
    /// Start writing `dest` with `schema` and `props`.
    pub fn create(dest: &Path, schema: SchemaRef, props: WriterProperties) -> Result<Self> {
        writable_name(dest)?;
        let tmp = tmp_path(dest);
        let file = File::create(&tmp).map_err(|e| Error::file(dest, format!("cannot create: {e}")))?;
        let writer = ArrowWriter::try_new(file, schema, Some(props)).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            Error::table(dest, e)
        })?;
        Ok(AtomicParquet { writer: Some(Writer::Buffered(writer)), tmp, dest: dest.to_path_buf() })
    }

    /// Append a batch.
    pub fn write(&mut self, batch: &RecordBatch) -> Result<()> {
        match self.writer.as_mut().expect("writer is present until finish") {
            Writer::Buffered(w) => w.write(batch).map_err(|e| Error::table(&self.dest, e)),
            Writer::RowGroups(..) => Err(Error::table(&self.dest, "write after write_row_group")),
        }
    }

    /// Write `batch` as one row group, encoding and compressing its columns in parallel.
    pub fn write_row_group(&mut self, batch: &RecordBatch) -> Result<()> {
        let table_err = |e: parquet::errors::ParquetError| Error::table(&self.dest, e);
        if let Some(Writer::Buffered(_)) = self.writer {
            let Some(Writer::Buffered(w)) = self.writer.take() else { unreachable!() };
            let (file, factory) = w.into_serialized_writer().map_err(table_err)?;
            self.writer = Some(Writer::RowGroups(file, factory));
        }
        let Some(Writer::RowGroups(file, factory)) = self.writer.as_mut() else { unreachable!() };
        let writers = factory.create_column_writers(file.flushed_row_groups().len()).map_err(table_err)?;
        let schema = batch.schema();
        // One leaf per column: the tables written this way have no nested columns.
        let chunks: Vec<ArrowColumnChunk> = writers
            .into_par_iter()
            .zip(schema.fields().par_iter().zip(batch.columns().par_iter()))
            .map(|(mut writer, (field, column))| {
                for leaf in compute_leaves(field, column)? {
                    writer.write(&leaf)?;
                }
                writer.close()
            })
            .collect::<std::result::Result<_, _>>()
            .map_err(table_err)?;
        let mut row_group = file.next_row_group().map_err(table_err)?;
        for chunk in chunks {
            chunk.append_to_row_group(&mut row_group).map_err(table_err)?;
        }
        row_group.close().map_err(table_err)?;
        Ok(())
    }

    /// Write the footer, sync, and rename into place.
    pub fn finish(self) -> Result<PathBuf> {
        let dest = self.dest.clone();
        let tmp = self.finish_staged()?;
        place(&tmp, &dest, Ok(()))?;
        Ok(dest)
    }

    /// Write the footer and sync, but leave the file under its temporary name (not a table file:
    /// no reader sees it), for another process to put in place with [`place_staged`]: a cluster's
    /// executor writes, the client commits. Returns the temporary name.
    pub fn finish_staged(mut self) -> Result<PathBuf> {
        let file = match self.writer.take().expect("writer is present until finish") {
            Writer::Buffered(w) => w.into_inner(),
            Writer::RowGroups(w, _) => w.into_inner(),
        }
        .map_err(|e| Error::table(&self.dest, e));
        let synced = file.and_then(|f| f.sync_all().map_err(|e| Error::file(&self.tmp, e)));
        if synced.is_err() {
            let _ = std::fs::remove_file(&self.tmp);
        }
        synced.map(|_| self.tmp.clone())
    }
}

/// Put a file [`AtomicParquet::finish_staged`] left at `staged` in place at `dest` (a rename; the
/// staged file is removed if that fails).
pub fn place_staged(staged: &Path, dest: &Path) -> Result<()> {
    place(staged, dest, Ok(()))
}

impl Drop for AtomicParquet {
    fn drop(&mut self) {
        if self.writer.is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Write `batches` to `dest` atomically.
pub fn write_parquet(
    dest: &Path,
    schema: SchemaRef,
    batches: &[RecordBatch],
    metadata: &HashMap<String, String>,
) -> Result<PathBuf> {
    stage_parquet(dest, schema, batches, metadata)?.finish()
}

/// The writer of `dest` with `batches` written under its temporary name, to be finished in place
/// ([`AtomicParquet::finish`]) or left staged ([`AtomicParquet::finish_staged`]).
pub fn stage_parquet(
    dest: &Path,
    schema: SchemaRef,
    batches: &[RecordBatch],
    metadata: &HashMap<String, String>,
) -> Result<AtomicParquet> {
    let mut w = AtomicParquet::create(dest, schema, writer_properties(metadata, 1 << 17))?;
    for b in batches {
        w.write(b)?;
    }
    Ok(w)
}

/// Write `bytes` to `path` through a temporary name in the same folder, renamed when complete (the
/// one atomic write of every non-Parquet output: CSV, JSON, figures, HTML).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    writable_name(path)?;
    let tmp = tmp_path(path);
    place(&tmp, path, std::fs::write(&tmp, bytes).map_err(|e| Error::file(path, format!("cannot write: {e}"))))
}

/// End a write to the temporary `tmp`: rename it onto `dest` when `written` is `Ok`, remove it
/// otherwise (and when the rename fails), so that neither a partial file nor a temporary remains.
pub(crate) fn place(tmp: &Path, dest: &Path, written: Result<()>) -> Result<()> {
    let placed = written.and_then(|_| rename_into_place(tmp, dest));
    if placed.is_err() {
        let _ = std::fs::remove_file(tmp);
    }
    placed
}

/// Rename a complete temporary file onto `dest` (never onto a directory).
fn rename_into_place(tmp: &Path, dest: &Path) -> Result<()> {
    if dest.is_dir() {
        return Err(Error::file(dest, "is a directory: give a file name"));
    }
    std::fs::rename(tmp, dest).map_err(|e| Error::file(dest, format!("cannot rename into place: {e}")))
}

/// Refuse an output name no file should have: `-` (standard output, which gedisim does not write
/// tables or figures to; the user meant a file or a pipe) and an empty name.
pub fn writable_name(dest: &Path) -> Result<()> {
    match dest.file_name().and_then(|n| n.to_str()) {
        Some("-") => Err(Error::file(dest, "--out -: standard output is not an output here; give a file name")),
        None => Err(Error::file(dest, "names no file: give a file name")),
        Some(_) => Ok(()),
    }
}

/// Refuse an output chosen by the user (`sql --out`, `simulate --out`) that lies in a table folder of
/// a dataset: a table is written only by gedisim's own commands, under the writer lock and with
/// its registry rows (a query result in `results/` would be read as results by `run` and
/// `report`). The folder counts as a dataset's when it holds the writer lock file or another
/// table. docs/robustness.md.
pub fn outside_tables(out: &Path) -> Result<()> {
    let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    // A table folder not created yet (`results/` before the first run) is one all the same.
    let resolved = parent.canonicalize().ok().or_else(|| {
        let name = parent.file_name()?;
        let above = parent.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        Some(above.canonicalize().ok()?.join(name))
    });
    let Some(parent) = resolved else { return Ok(()) };
    let (Some(table), Some(root)) = (parent.file_name().and_then(|n| n.to_str()), parent.parent()) else {
        return Ok(());
    };
    const TABLES: [&str; 9] = [
        tables::ALS,
        tables::TILES,
        tables::SHOTS,
        tables::GRANULES,
        tables::SIM,
        tables::SIMULATED,
        tables::STRATA,
        tables::RESULTS,
        tables::OFFSETS,
    ];
    let in_dataset = root.join(lock::LOCK_FILE).exists() || TABLES.iter().any(|t| *t != table && root.join(t).is_dir());
    if TABLES.contains(&table) && in_dataset {
        return Err(Error::file(
            out,
            format!(
                "--out: inside the `{table}` table of the dataset {}: only gedisim's own commands write its \
                 tables; write elsewhere",
                root.display()
            ),
        ));
    }
    Ok(())
}

/// A temporary name beside `dest`, unique to this process and this call:
/// `<name>.<pid>-<n>.tmp`. Readers ignore `*.tmp`; [`remove_stale_temporaries`] removes those of
/// dead processes.
pub fn tmp_path(dest: &Path) -> PathBuf {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut name = dest.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(format!(".{}-{n}.tmp", std::process::id()));
    dest.with_file_name(name)
}

/// SHA-256 of a file's content, lowercase hex: the key that makes ingest idempotent.
pub fn content_hash(path: &Path) -> Result<String> {
    let mut file = File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = file.read(&mut buf).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex::encode(hasher.finalize()))
}

/// Files up to this size are keyed by [`content_hash`] in [`granule_hash`]; larger ones by samples.
pub const WHOLE_HASH_MAX_BYTES: u64 = 256 << 20;

/// The content key of a GEDI granule file: [`content_hash`] up to [`WHOLE_HASH_MAX_BYTES`]; above,
/// `sampled:` and the SHA-256 of its length and of 32 blocks of 1 MiB spread evenly from its first
/// byte to its last (a full-size granule of 5 GB is read for its kept shots only; hashing it whole
/// would read all of it: docs/gedi-products.md §6). A renamed copy has the same key; a change that
/// keeps the length and touches no sampled block goes unseen (ingest it under a new name).
pub fn granule_hash(path: &Path) -> Result<String> {
    use std::io::{Seek, SeekFrom};
    let mut file = File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))?;
    let len = file.metadata().map_err(|e| Error::file(path, format!("cannot open: {e}")))?.len();
    if len <= WHOLE_HASH_MAX_BYTES {
        return content_hash(path);
    }
    let (block, blocks) = (1u64 << 20, 32u64);
    let mut hasher = Sha256::new();
    hasher.update(len.to_le_bytes());
    let mut buf = vec![0u8; block as usize];
    for i in 0..blocks {
        let at = i * (len - block) / (blocks - 1);
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.read_exact(&mut buf))
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        hasher.update(&buf);
    }
    Ok(format!("sampled:{}", hex::encode(hasher.finalize())))
}

/// A Parquet row selection of the sorted row indices `rows` of a file of `total` rows
/// (consecutive rows merged into one range).
pub fn row_selection(rows: &[usize], total: usize) -> parquet::arrow::arrow_reader::RowSelection {
    let mut ranges: Vec<std::ops::Range<usize>> = Vec::new();
    for &r in rows {
        match ranges.last_mut() {
            Some(last) if last.end == r => last.end = r + 1,
            _ => ranges.push(r..r + 1),
        }
    }
    parquet::arrow::arrow_reader::RowSelection::from_consecutive_ranges(ranges.into_iter(), total)
}

// Column types shared by the derived tables.

use arrow::array::{Float32Builder, ListBuilder};
use arrow::datatypes::{DataType, Field};

/// `list<float32>` with nullable items, the type of every waveform and RH column.
pub fn list_f32() -> DataType {
    DataType::List(Arc::new(Field::new_list_field(DataType::Float32, true)))
}

/// A builder of `list<float32>` columns.
pub fn list_f32_builder(capacity: usize) -> ListBuilder<Float32Builder> {
    ListBuilder::with_capacity(Float32Builder::new(), capacity)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Seek, SeekFrom, Write};

    #[test]
    fn large_granules_are_keyed_by_samples_small_ones_whole() {
        let dir = tempfile::tempdir().unwrap();
        let small = dir.path().join("small.h5");
        std::fs::write(&small, b"granule").unwrap();
        assert_eq!(granule_hash(&small).unwrap(), content_hash(&small).unwrap());
        // A sparse file just above the limit: nothing is written but the bytes changed below.
        let big = dir.path().join("big.h5");
        let f = File::create(&big).unwrap();
        f.set_len(WHOLE_HASH_MAX_BYTES + 1).unwrap();
        let key = granule_hash(&big).unwrap();
        assert!(key.starts_with("sampled:"), "{key}");
        // The last block is always sampled: a change there changes the key; the length is keyed too.
        let mut f = std::fs::OpenOptions::new().write(true).open(&big).unwrap();
        f.seek(SeekFrom::End(-1)).unwrap();
        f.write_all(&[1]).unwrap();
        let changed = granule_hash(&big).unwrap();
        assert_ne!(changed, key);
        f.set_len(WHOLE_HASH_MAX_BYTES + 2).unwrap();
        assert_ne!(granule_hash(&big).unwrap(), changed);
    }
}
