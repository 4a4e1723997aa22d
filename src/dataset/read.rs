//! Reading the dataset's Parquet files: the one opener ([`open`]), batches of chosen columns and
//! rows ([`for_each_batch`]), and the one typed-column reader ([`Columns`]), whose errors name
//! the file and the column.

use std::collections::HashMap;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow::array::{
    Array, ArrayRef, AsArray, Float32Array, Float64Array, ListArray, PrimitiveArray, StringArray,
    TimestampMicrosecondArray, UInt16Array, UInt32Array, UInt64Array, UInt8Array,
};
use arrow::compute::{cast_with_options, CastOptions};
use arrow::datatypes::{
    ArrowPrimitiveType, Float32Type, Float64Type, TimestampMicrosecondType, UInt16Type, UInt32Type, UInt64Type,
    UInt8Type,
};
use arrow::datatypes::{Field, Schema};
use arrow::record_batch::RecordBatch;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ProjectionMask;

use crate::error::{Error, Result};

/// Open a Parquet file for reading (its schema, metadata and row groups are read now).
pub fn open(path: &Path) -> Result<ParquetRecordBatchReaderBuilder<File>> {
    let file = File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))?;
    ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| Error::table(path, e))
}

/// The key-value metadata of a Parquet file; `None` when the file cannot be read.
pub fn key_value_metadata(path: &Path) -> Option<HashMap<String, String>> {
    let builder = open(path).ok()?;
    let kv = builder.metadata().file_metadata().key_value_metadata()?;
    Some(kv.iter().filter_map(|k| Some((k.key.clone(), k.value.clone()?))).collect())
}

/// Call `f` on every batch of `path`: only `columns` when given (all otherwise; each must exist),
/// only the rows `rows` (sorted file row numbers) when given.
pub fn for_each_batch(
    path: &Path,
    columns: Option<&[&str]>,
    rows: Option<&[usize]>,
    mut f: impl FnMut(Columns) -> Result<()>,
) -> Result<()> {
    let mut builder = open(path)?;
    if let Some(columns) = columns {
        if let Some(missing) = columns.iter().find(|c| builder.schema().field_with_name(c).is_err()) {
            return Err(Error::field(path, *missing, "column missing from the table"));
        }
        let mask = ProjectionMask::columns(builder.parquet_schema(), columns.iter().copied());
        builder = builder.with_projection(mask);
    }
    if let Some(rows) = rows {
        let total = builder.metadata().file_metadata().num_rows() as usize;
        builder = builder.with_row_selection(super::row_selection(rows, total));
    }
    for b in builder.build().map_err(|e| Error::table(path, e))? {
        let b = b.map_err(|e| Error::table(path, e))?;
        f(Columns { path, batch: &b })?;
    }
    Ok(())
}

/// The columns `names` of `batch`, a table from elsewhere (a Python one: int64 intensities, a
/// float64 waveform, a large list), cast to the types `schema` gives them, in that order; those of
/// `optional` may be missing (and are then left out). A missing column, or a value its type cannot
/// hold (no wrap, no truncation to null), is an error naming `path` and the column. The fields are
/// nullable: the caller says which nulls it takes.
pub fn cast_columns(
    path: &Path,
    batch: &RecordBatch,
    schema: &Schema,
    names: &[&str],
    optional: &[&str],
) -> Result<RecordBatch> {
    let options = CastOptions { safe: false, ..Default::default() };
    let (mut fields, mut columns) = (Vec::with_capacity(names.len()), Vec::with_capacity(names.len()));
    for &name in names {
        let Some(column) = batch.column_by_name(name) else {
            if optional.contains(&name) {
                continue;
            }
            return Err(Error::field(path, name, "column missing from the table"));
        };
        let to = schema.field_with_name(name).map_err(|e| Error::field(path, name, e))?.data_type();
        let cast = cast_with_options(column, to, &options).map_err(|e| {
            let why = e.to_string();
            let why = why.strip_prefix("Cast error: ").unwrap_or(&why).to_string();
            Error::field(path, name, format!("{} cannot be read as {to} ({why})", column.data_type()))
        })?;
        fields.push(Field::new(name, to.clone(), true));
        columns.push(cast);
    }
    RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).map_err(|e| Error::table(path, e))
}

/// Typed access to the columns of a batch read from `path`: a missing column or one of another
/// type is an error naming the file and the column.
#[derive(Clone, Copy)]
pub struct Columns<'a> {
    path: &'a Path,
    batch: &'a RecordBatch,
}

impl<'a> Columns<'a> {
    pub fn new(path: &'a Path, batch: &'a RecordBatch) -> Self {
        Columns { path, batch }
    }

    pub fn num_rows(&self) -> usize {
        self.batch.num_rows()
    }

    pub fn batch(&self) -> &'a RecordBatch {
        self.batch
    }

    /// The column `name`, whatever its type.
    pub fn column(&self, name: &str) -> Result<&'a ArrayRef> {
        self.batch.column_by_name(name).ok_or_else(|| Error::field(self.path, name, "column missing from the table"))
    }

    fn primitive<T: ArrowPrimitiveType>(&self, name: &str, ty: &str) -> Result<&'a PrimitiveArray<T>> {
        self.column(name)?.as_primitive_opt::<T>().ok_or_else(|| Error::field(self.path, name, format!("not {ty}")))
    }

    pub fn f64s(&self, name: &str) -> Result<&'a Float64Array> {
        self.primitive::<Float64Type>(name, "float64")
    }

    pub fn f32s(&self, name: &str) -> Result<&'a Float32Array> {
        self.primitive::<Float32Type>(name, "float32")
    }

    pub fn u8s(&self, name: &str) -> Result<&'a UInt8Array> {
        self.primitive::<UInt8Type>(name, "uint8")
    }

    pub fn u16s(&self, name: &str) -> Result<&'a UInt16Array> {
        self.primitive::<UInt16Type>(name, "uint16")
    }

    pub fn u32s(&self, name: &str) -> Result<&'a UInt32Array> {
        self.primitive::<UInt32Type>(name, "uint32")
    }

    pub fn u64s(&self, name: &str) -> Result<&'a UInt64Array> {
        self.primitive::<UInt64Type>(name, "uint64")
    }

    pub fn timestamps(&self, name: &str) -> Result<&'a TimestampMicrosecondArray> {
        self.primitive::<TimestampMicrosecondType>(name, "timestamp[µs]")
    }

    pub fn strings(&self, name: &str) -> Result<&'a StringArray> {
        self.column(name)?.as_string_opt::<i32>().ok_or_else(|| Error::field(self.path, name, "not a string"))
    }

    pub fn lists(&self, name: &str) -> Result<&'a ListArray> {
        self.column(name)?.as_list_opt::<i32>().ok_or_else(|| Error::field(self.path, name, "not a list"))
    }

    /// Row `i` of the float64 column `name`; `None` when null.
    pub fn f64(&self, name: &str, i: usize) -> Result<Option<f64>> {
        Ok(value(self.f64s(name)?, i))
    }

    /// Row `i` of the uint8 column `name`; `None` when null.
    pub fn u8(&self, name: &str, i: usize) -> Result<Option<u8>> {
        Ok(value(self.u8s(name)?, i))
    }

    /// Row `i` of the uint64 column `name`; `None` when null.
    pub fn u64(&self, name: &str, i: usize) -> Result<Option<u64>> {
        Ok(value(self.u64s(name)?, i))
    }

    /// Row `i` of the timestamp[µs] column `name` (µs since 1970); `None` when null.
    pub fn timestamp(&self, name: &str, i: usize) -> Result<Option<i64>> {
        Ok(value(self.timestamps(name)?, i))
    }

    /// Row `i` of the string column `name`; `None` when null.
    pub fn string(&self, name: &str, i: usize) -> Result<Option<String>> {
        Ok(text(self.strings(name)?, i))
    }

    /// Row `i` of the `list<float32>` column `name` (null items as NaN); `None` when null.
    pub fn f32_list(&self, name: &str, i: usize) -> Result<Option<Vec<f32>>> {
        let l = self.lists(name)?;
        if l.is_null(i) {
            return Ok(None);
        }
        let v = l.value(i);
        let v = v
            .as_primitive_opt::<Float32Type>()
            .ok_or_else(|| Error::field(self.path, name, "not a list of float32"))?;
        Ok(Some(v.iter().map(|x| x.unwrap_or(f32::NAN)).collect()))
    }
}

/// Row `i` of a primitive column; `None` when null.
pub fn value<T: ArrowPrimitiveType>(a: &PrimitiveArray<T>, i: usize) -> Option<T::Native> {
    a.is_valid(i).then(|| a.value(i))
}

/// Row `i` of a string column; `None` when null.
pub fn text(a: &StringArray, i: usize) -> Option<String> {
    a.is_valid(i).then(|| a.value(i).to_string())
}
