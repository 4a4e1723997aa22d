//! What the two noise-twin functions share (`gedi_noise_twin`, [`super::noise_twin`];
//! `gedi_link_margin_twin`, [`super::link_margin_twin`]): one scalar UDF driven by a
//! [`TwinFunction`] (its name, arguments, per-row twin and documentation), the per-row numeric
//! arguments and the struct both return.
//!
//! `wave` is a simulated waveform (sample k labelled `z0 − k·dz`, the `sim` table's convention).
//! The struct: `rxwaveform` (list<float32>, DN, 1 ns samples), `elevation_bin0`,
//! `elevation_lastbin` (m, in the datum of `z0`), `noise_mean`, `noise_stddev` (DN, what L2A
//! should use) and `no_result_reason` (null when the twin was made). The same seed gives the same
//! twin on any machine; a null argument gives a null struct.

use std::sync::Arc;

use arrow::array::{Array, ArrayRef, AsArray, Float64Array, PrimitiveArray, StringArray, StructArray};
use arrow::datatypes::{DataType, Field, Fields, Float32Type, Float64Type, Int64Type, UInt64Type};
use datafusion::common::{plan_err, Result as DfResult};
use datafusion::logical_expr::{
    ColumnarValue, Documentation, ScalarFunctionArgs, ScalarUDFImpl, Signature, Volatility,
};

use super::args::{coerce_number, coerce_waveform};
use crate::dataset::{list_f32, list_f32_builder};
use crate::kernels::waveform::noise_twin::{TwinError, TwinWaveform, GEDI_BIN_M};

/// Fields of the struct both twin functions return.
pub fn twin_struct_fields() -> Fields {
    let f = |n: &str, t: DataType| Field::new(n, t, true);
    Fields::from(vec![
        f("rxwaveform", list_f32()),
        f("elevation_bin0", DataType::Float64),
        f("elevation_lastbin", DataType::Float64),
        f("noise_mean", DataType::Float64),
        f("noise_stddev", DataType::Float64),
        f("no_result_reason", DataType::Utf8),
    ])
}

/// One noise-twin SQL function.
pub struct TwinFunction {
    pub name: &'static str,
    /// Argument names: the required ones, then the optional ones (any leading part of them).
    pub required: &'static [&'static str],
    pub optional: &'static [&'static str],
    /// The twin of one row: the simulated waveform, `z0`, `dz`, the other arguments, the row.
    pub make: fn(&[f64], f64, f64, &[Column], usize) -> Made,
    pub documentation: fn() -> Documentation,
}

/// Whether the argument named `arg` is an integer.
fn is_integer(arg: &str) -> bool {
    matches!(arg, "sample_count" | "start" | "seed")
}

/// The scalar UDF of a [`TwinFunction`].
pub struct GediTwin {
    function: &'static TwinFunction,
    signature: Signature,
    documentation: Documentation,
}

impl GediTwin {
    pub fn new(function: &'static TwinFunction) -> Self {
        Self {
            function,
            signature: Signature::user_defined(Volatility::Immutable),
            documentation: (function.documentation)(),
        }
    }
}

impl std::fmt::Debug for GediTwin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GediTwin").field("name", &self.function.name).finish()
    }
}

impl PartialEq for GediTwin {
    fn eq(&self, other: &Self) -> bool {
        self.function.name == other.function.name
    }
}

impl Eq for GediTwin {}

impl std::hash::Hash for GediTwin {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.function.name.hash(state);
    }
}

/// Per-row numeric argument: float64, int64 or uint64 (seeds may be shot numbers).
pub enum Column<'a> {
    F64(&'a PrimitiveArray<Float64Type>),
    I64(&'a PrimitiveArray<Int64Type>),
    U64(&'a PrimitiveArray<UInt64Type>),
}

impl Column<'_> {
    pub fn of(a: &ArrayRef) -> Column<'_> {
        match a.data_type() {
            DataType::UInt64 => Column::U64(a.as_primitive()),
            DataType::Int64 => Column::I64(a.as_primitive()),
            _ => Column::F64(a.as_primitive()),
        }
    }
    pub fn is_null(&self, i: usize) -> bool {
        match self {
            Column::F64(a) => a.is_null(i),
            Column::I64(a) => a.is_null(i),
            Column::U64(a) => a.is_null(i),
        }
    }
    pub fn f64(&self, i: usize) -> f64 {
        match self {
            Column::F64(a) => a.value(i),
            Column::I64(a) => a.value(i) as f64,
            Column::U64(a) => a.value(i) as f64,
        }
    }
    /// An integer argument as a signed value (u64 above i64::MAX saturates).
    pub fn i64(&self, i: usize) -> i64 {
        match self {
            Column::F64(a) => a.value(i) as i64,
            Column::I64(a) => a.value(i),
            Column::U64(a) => i64::try_from(a.value(i)).unwrap_or(i64::MAX),
        }
    }
    /// A seed: the bits of the integer (a negative int64 is as good a seed as any).
    pub fn seed(&self, i: usize) -> u64 {
        match self {
            Column::U64(a) => a.value(i),
            other => other.i64(i) as u64,
        }
    }
}

impl ScalarUDFImpl for GediTwin {
    fn name(&self) -> &str {
        self.function.name
    }
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn coerce_types(&self, arg_types: &[DataType]) -> DfResult<Vec<DataType>> {
        let name = self.function.name;
        let (required, optional) = (self.function.required, self.function.optional);
        let most = required.len() + optional.len();
        if !(required.len()..=most).contains(&arg_types.len()) {
            return plan_err!(
                "{name}({}[, {}]): {} to {most} arguments, got {}",
                required.join(", "),
                optional.join(", "),
                required.len(),
                arg_types.len()
            );
        }
        arg_types
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let arg = required.iter().chain(optional).nth(i).copied().unwrap_or_default();
                if i == 0 {
                    coerce_waveform(name, t)
                } else if is_integer(arg) && *t == DataType::UInt64 {
                    Ok(DataType::UInt64)
                } else if is_integer(arg) {
                    coerce_number(name, arg, t, DataType::Int64)
                } else {
                    coerce_number(name, arg, t, DataType::Float64)
                }
            })
            .collect()
    }
    fn documentation(&self) -> Option<&Documentation> {
        Some(&self.documentation)
    }
    fn return_type(&self, _: &[DataType]) -> DfResult<DataType> {
        Ok(DataType::Struct(twin_struct_fields()))
    }
    fn invoke_with_args(&self, args: ScalarFunctionArgs) -> DfResult<ColumnarValue> {
        let n = args.number_rows;
        let arrays = ColumnarValue::values_to_arrays(&args.args)?;
        let waves = arrays[0].as_list::<i32>();
        let cols: Vec<Column> = arrays[1..].iter().map(Column::of).collect();
        let mut out = TwinColumns::with_capacity(n);
        let mut sim = Vec::new();
        for i in 0..n {
            if waves.is_null(i) || cols.iter().any(|c| c.is_null(i)) {
                out.append_null();
                continue;
            }
            let w = waves.value(i);
            let w = w.as_primitive::<Float32Type>();
            // Null samples become NaN, which the kernel reports as an invalid waveform.
            sim.clear();
            sim.extend((0..w.len()).map(|k| if w.is_null(k) { f64::NAN } else { f64::from(w.value(k)) }));
            let (z0, dz) = (cols[0].f64(i), cols[1].f64(i));
            let made = (self.function.make)(&sim, z0, dz, &cols[2..], i);
            out.append(made);
        }
        Ok(ColumnarValue::Array(Arc::new(out.finish()?)))
    }
}

/// A made twin and the elevation of its record's first and last sample.
pub type Made = Result<(TwinWaveform, f64, f64), TwinError>;

/// Elevations of the record's first and last samples when the simulated sample 0 (label `z0`)
/// lies at record sample `start` (negative: above the record), on the 1 ns grid.
pub fn record_elevations(z0: f64, start: isize, len: usize) -> (f64, f64) {
    let bin0 = z0 + start as f64 * GEDI_BIN_M;
    (bin0, bin0 - len.saturating_sub(1) as f64 * GEDI_BIN_M)
}

/// Builders of the twin struct column.
struct TwinColumns {
    wave: arrow::array::ListBuilder<arrow::array::Float32Builder>,
    bin0: Vec<Option<f64>>,
    last: Vec<Option<f64>>,
    mean: Vec<Option<f64>>,
    stddev: Vec<Option<f64>>,
    reason: Vec<Option<String>>,
    valid: Vec<bool>,
}

impl TwinColumns {
    fn with_capacity(n: usize) -> Self {
        Self {
            wave: list_f32_builder(n),
            bin0: Vec::with_capacity(n),
            last: Vec::with_capacity(n),
            mean: Vec::with_capacity(n),
            stddev: Vec::with_capacity(n),
            reason: Vec::with_capacity(n),
            valid: Vec::with_capacity(n),
        }
    }

    fn append(&mut self, made: Made) {
        self.valid.push(true);
        match made {
            Ok((t, bin0, last)) => {
                self.wave.append_value(t.wave.iter().map(|&v| Some(v)));
                self.bin0.push(Some(bin0));
                self.last.push(Some(last));
                self.mean.push(Some(t.noise.mean));
                self.stddev.push(Some(t.noise.stddev));
                self.reason.push(None);
            }
            Err(e) => {
                self.push_nulls();
                self.reason.push(Some(e.to_string()));
            }
        }
    }

    fn append_null(&mut self) {
        self.valid.push(false);
        self.push_nulls();
        self.reason.push(None);
    }

    fn push_nulls(&mut self) {
        self.wave.append_null();
        for v in [&mut self.bin0, &mut self.last, &mut self.mean, &mut self.stddev] {
            v.push(None);
        }
    }

    fn finish(mut self) -> Result<StructArray, arrow::error::ArrowError> {
        let arrays: Vec<ArrayRef> = vec![
            Arc::new(self.wave.finish()),
            Arc::new(Float64Array::from(self.bin0)),
            Arc::new(Float64Array::from(self.last)),
            Arc::new(Float64Array::from(self.mean)),
            Arc::new(Float64Array::from(self.stddev)),
            Arc::new(StringArray::from(self.reason)),
        ];
        let nulls = self.valid.iter().any(|v| !v).then(|| self.valid.into());
        StructArray::try_new(twin_struct_fields(), arrays, nulls)
    }
}
