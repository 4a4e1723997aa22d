//! Query results written as their batches come, never gathered whole (docs/robustness.md "What `gedisim
//! sql` may touch"): CSV or JSON text to any writer (standard output), or CSV, JSON or Parquet to a
//! file under a temporary name renamed when complete.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use arrow::record_batch::RecordBatch;

use crate::dataset::AtomicParquet;
use crate::error::{Error, Result};

/// A file format of query results.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResultFormat {
    /// CSV with a header; list and struct cells as JSON text.
    Csv,
    /// One JSON array of objects, every column in every object (`null` included).
    Json,
    Parquet,
}

impl ResultFormat {
    /// Its name (`csv`, `json`, `parquet`), also the file extension.
    pub fn name(self) -> &'static str {
        match self {
            ResultFormat::Csv => "csv",
            ResultFormat::Json => "json",
            ResultFormat::Parquet => "parquet",
        }
    }

    /// The format `path`'s extension names, if any.
    pub fn of_file(path: &Path) -> Option<ResultFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        [ResultFormat::Csv, ResultFormat::Json, ResultFormat::Parquet].into_iter().find(|f| f.name() == ext)
    }
}

/// One result as CSV or JSON text, written to `W` batch by batch (`name` names it in errors).
#[allow(clippy::large_enum_variant)] // one per result: its size does not matter
pub enum TextWriter<W: Write> {
    Csv(arrow::csv::Writer<W>, PathBuf),
    Json(arrow::json::Writer<W, arrow::json::writer::JsonArray>, PathBuf),
}

impl<W: Write> TextWriter<W> {
    /// A writer of `format` (not Parquet) to `w`; a CSV's header is written at once, so that a
    /// result without rows still names its columns.
    pub fn new(name: &Path, w: W, schema: &SchemaRef, format: ResultFormat) -> Result<TextWriter<W>> {
        let name = name.to_path_buf();
        match format {
            ResultFormat::Csv => {
                let mut writer = TextWriter::Csv(arrow::csv::Writer::new(w), name);
                writer.write(&RecordBatch::new_empty(schema.clone()))?;
                Ok(writer)
            }
            ResultFormat::Json => {
                Ok(TextWriter::Json(arrow::json::WriterBuilder::new().with_explicit_nulls(true).build(w), name))
            }
            ResultFormat::Parquet => Err(Error::file(&name, "Parquet is not text: write it to a .parquet file")),
        }
    }

    pub fn write(&mut self, batch: &RecordBatch) -> Result<()> {
        match self {
            TextWriter::Csv(w, name) => w.write(&nested_as_json(name, batch)?).map_err(|e| Error::table(&*name, e)),
            TextWriter::Json(w, name) => w.write(batch).map_err(|e| Error::table(&*name, e)),
        }
    }

    /// End the text (a JSON array's `]`) and give the writer back, flushed.
    pub fn finish(self) -> Result<W> {
        let (mut w, name) = match self {
            TextWriter::Csv(w, name) => (w.into_inner(), name),
            TextWriter::Json(mut w, name) => {
                w.finish().map_err(|e| Error::table(&name, e))?;
                (w.into_inner(), name)
            }
        };
        w.flush().map_err(|e| Error::file(&name, e))?;
        Ok(w)
    }
}

/// One result written to a file as it comes, under a temporary name beside it: [`ResultFile::finish`]
/// renames it into place; dropped unfinished (a later statement failed), the temporary is removed.
#[allow(clippy::large_enum_variant)] // one per command: its size does not matter
pub enum ResultFile {
    Text { writer: TextWriter<BufWriter<File>>, tmp: Temporary, dest: PathBuf },
    Parquet(AtomicParquet),
}

/// A temporary file, removed when dropped unless taken to be renamed into place.
pub struct Temporary(Option<PathBuf>);

impl Drop for Temporary {
    fn drop(&mut self) {
        if let Some(path) = self.0.take() {
            let _ = std::fs::remove_file(path);
        }
    }
}

impl ResultFile {
    pub fn create(out: &Path, schema: &SchemaRef, format: ResultFormat) -> Result<ResultFile> {
        if out.is_dir() {
            return Err(Error::file(out, "is a directory: give a .csv, .json or .parquet file name"));
        }
        crate::dataset::writable_name(out)?;
        if format == ResultFormat::Parquet {
            let props = crate::dataset::writer_properties(&Default::default(), 1 << 17);
            return AtomicParquet::create(out, schema.clone(), props).map(ResultFile::Parquet);
        }
        let path = crate::dataset::tmp_path(out);
        let file = File::create(&path).map_err(|e| Error::file(out, format!("cannot create: {e}")))?;
        let tmp = Temporary(Some(path));
        let writer = TextWriter::new(out, BufWriter::new(file), schema, format)?;
        Ok(ResultFile::Text { writer, tmp, dest: out.to_path_buf() })
    }

    pub fn write(&mut self, batch: &RecordBatch) -> Result<()> {
        match self {
            ResultFile::Text { writer, .. } => writer.write(batch),
            ResultFile::Parquet(w) => w.write(batch),
        }
    }

    /// Complete the file and rename it into place.
    pub fn finish(self) -> Result<()> {
        match self {
            ResultFile::Parquet(w) => w.finish().map(|_| ()),
            ResultFile::Text { writer, mut tmp, dest } => {
                let tmp = tmp.0.take().expect("the temporary is kept until finish");
                let written = writer.finish().and_then(|w| {
                    let file = w.into_inner().map_err(|e| Error::file(&tmp, e.error().to_string()))?;
                    file.sync_all().map_err(|e| Error::file(&tmp, e))
                });
                crate::dataset::place(&tmp, &dest, written)
            }
        }
    }
}

/// `batch` with each list, map or struct column replaced by its cells as JSON text (null stays null).
fn nested_as_json(out: &Path, batch: &RecordBatch) -> Result<RecordBatch> {
    let schema = batch.schema();
    if !schema.fields().iter().any(|f| f.data_type().is_nested()) {
        return Ok(batch.clone());
    }
    let mut fields = Vec::new();
    let mut columns = Vec::new();
    for (field, column) in schema.fields().iter().zip(batch.columns()) {
        if !field.data_type().is_nested() {
            fields.push(field.as_ref().clone());
            columns.push(column.clone());
            continue;
        }
        // Each cell through arrow's JSON writer: one line `{"v": <cell>}` per row (`{}` for a null).
        let one =
            arrow::datatypes::Schema::new(vec![arrow::datatypes::Field::new("v", field.data_type().clone(), true)]);
        let one = RecordBatch::try_new(Arc::new(one), vec![column.clone()])
            .map_err(|e| Error::field(out, field.name(), e))?;
        let mut lines = arrow::json::LineDelimitedWriter::new(Vec::new());
        lines.write(&one).and_then(|_| lines.finish()).map_err(|e| Error::field(out, field.name(), e))?;
        let text = lines.into_inner();
        let cells = text
            .split(|b| *b == b'\n')
            .filter(|l| !l.is_empty())
            .map(|l| {
                let row: serde_json::Value =
                    serde_json::from_slice(l).map_err(|e| Error::field(out, field.name(), e))?;
                Ok(row.get("v").map(|v| v.to_string()))
            })
            .collect::<Result<arrow::array::StringArray>>()?;
        fields.push(arrow::datatypes::Field::new(field.name(), arrow::datatypes::DataType::Utf8, true));
        columns.push(Arc::new(cells));
    }
    RecordBatch::try_new(Arc::new(arrow::datatypes::Schema::new(fields)), columns).map_err(|e| Error::table(out, e))
}
