//! The noise twin as SQL: GEDI-like received waveforms from noise-free simulated ones, as a
//! struct that `gedi_l2a` can process in the same query. Thin wrappers over
//! [`crate::kernels::waveform::noise_twin`]:
//! - `gedi_noise_twin(wave, z0, dz, energy_total, noise_mean, noise_stddev, sample_count, start,
//!   seed [, quantum [, noise_correlation, noise_ratio]])`: mode (a), the twin of one real shot
//!   ([`ShotTwin`]); the noise is correlated like real GEDI records ([`NoiseShape::GEDI_V1`])
//!   unless `noise_correlation` (samples; 0 = white) and `noise_ratio` (per-sample σ over
//!   `noise_stddev`) say otherwise;
//! - `gedi_link_margin_twin(wave, z0, dz, link_margin_db, cover, seed [, true_cover])`: mode (b),
//!   gediMetric's link-margin noise ([`LinkMarginTwin`], reference defaults otherwise).
//!
//! `wave` is a simulated waveform (sample k labelled `z0 − k·dz`, the `sim` table's convention);
//! in mode (a) its sample 0 goes to record sample `start` (negative: above the record; simulated
//! samples outside the record must be zero, as a simulation's empty buffers are).
//! The struct: `rxwaveform` (list<float32>, DN, 1 ns samples), `elevation_bin0`,
//! `elevation_lastbin` (m, in the datum of `z0`), `noise_mean`, `noise_stddev` (DN, what L2A
//! should use) and `no_result_reason` (null when the twin was made). The same seed gives the same
//! twin on any machine; a null argument gives a null struct.

use std::sync::Arc;

use arrow::array::{
    Array, ArrayRef, AsArray, Float64Array, PrimitiveArray, StringArray, StructArray,
};
use arrow::datatypes::{DataType, Field, Fields, Float32Type, Float64Type, Int64Type, UInt64Type};
use datafusion::common::{plan_err, Result as DfResult};
use datafusion::logical_expr::{
    ColumnarValue, ScalarFunctionArgs, ScalarUDFImpl, Signature, Volatility,
};

use super::l2a::{coerce_number, coerce_waveform};
use crate::kernels::waveform::l2a::Noise;
use crate::kernels::waveform::noise_twin::{
    LinkMarginTwin, NoiseShape, ShotTwin, TwinError, TwinWaveform, GEDI_BIN_M,
};
use crate::dataset::{list_f32, list_f32_builder};

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

/// Which twin a function makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Mode {
    Shot,
    LinkMargin,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Shot => "gedi_noise_twin",
            Mode::LinkMargin => "gedi_link_margin_twin",
        }
    }
    /// Argument names: the required ones, then the optional ones (any leading part of them).
    fn args(self) -> (&'static [&'static str], &'static [&'static str]) {
        match self {
            Mode::Shot => (
                &[
                    "wave",
                    "z0",
                    "dz",
                    "energy_total",
                    "noise_mean",
                    "noise_stddev",
                    "sample_count",
                    "start",
                    "seed",
                ],
                &["quantum", "noise_correlation", "noise_ratio"],
            ),
            Mode::LinkMargin => (
                &["wave", "z0", "dz", "link_margin_db", "cover", "seed"],
                &["true_cover"],
            ),
        }
    }
    /// Whether the argument named `arg` is an integer.
    fn is_integer(self, arg: &str) -> bool {
        matches!(arg, "sample_count" | "start" | "seed")
    }
}

/// `gedi_noise_twin` (mode a) or `gedi_link_margin_twin` (mode b).
#[derive(Debug, PartialEq, Eq, Hash)]
pub struct GediNoiseTwin {
    mode: Mode,
    signature: Signature,
}

impl GediNoiseTwin {
    /// `gedi_noise_twin`: the twin of one real shot.
    pub fn shot() -> Self {
        Self::new(Mode::Shot)
    }
    /// `gedi_link_margin_twin`: gediMetric's link-margin noise.
    pub fn link_margin() -> Self {
        Self::new(Mode::LinkMargin)
    }
    fn new(mode: Mode) -> Self {
        Self {
            mode,
            signature: Signature::user_defined(Volatility::Immutable),
        }
    }
}

/// Per-row numeric argument: float64, int64 or uint64 (seeds may be shot numbers).
enum Column<'a> {
    F64(&'a PrimitiveArray<Float64Type>),
    I64(&'a PrimitiveArray<Int64Type>),
    U64(&'a PrimitiveArray<UInt64Type>),
}

impl Column<'_> {
    fn of(a: &ArrayRef) -> Column<'_> {
        match a.data_type() {
            DataType::UInt64 => Column::U64(a.as_primitive()),
            DataType::Int64 => Column::I64(a.as_primitive()),
            _ => Column::F64(a.as_primitive()),
        }
    }
    fn is_null(&self, i: usize) -> bool {
        match self {
            Column::F64(a) => a.is_null(i),
            Column::I64(a) => a.is_null(i),
            Column::U64(a) => a.is_null(i),
        }
    }
    fn f64(&self, i: usize) -> f64 {
        match self {
            Column::F64(a) => a.value(i),
            Column::I64(a) => a.value(i) as f64,
            Column::U64(a) => a.value(i) as f64,
        }
    }
    /// An integer argument as a signed value (u64 above i64::MAX saturates).
    fn i64(&self, i: usize) -> i64 {
        match self {
            Column::F64(a) => a.value(i) as i64,
            Column::I64(a) => a.value(i),
            Column::U64(a) => i64::try_from(a.value(i)).unwrap_or(i64::MAX),
        }
    }
    /// A seed: the bits of the integer (a negative int64 is as good a seed as any).
    fn seed(&self, i: usize) -> u64 {
        match self {
            Column::U64(a) => a.value(i),
            other => other.i64(i) as u64,
        }
    }
}

impl ScalarUDFImpl for GediNoiseTwin {
    fn name(&self) -> &str {
        self.mode.name()
    }
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn coerce_types(&self, arg_types: &[DataType]) -> DfResult<Vec<DataType>> {
        let name = self.mode.name();
        let (required, optional) = self.mode.args();
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
                let arg = required
                    .iter()
                    .chain(optional)
                    .nth(i)
                    .copied()
                    .unwrap_or_default();
                if i == 0 {
                    coerce_waveform(name, t)
                } else if self.mode.is_integer(arg) && *t == DataType::UInt64 {
                    Ok(DataType::UInt64)
                } else if self.mode.is_integer(arg) {
                    coerce_number(name, arg, t, DataType::Int64)
                } else {
                    coerce_number(name, arg, t, DataType::Float64)
                }
            })
            .collect()
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
            sim.extend((0..w.len()).map(|k| {
                if w.is_null(k) {
                    f64::NAN
                } else {
                    f64::from(w.value(k))
                }
            }));
            let (z0, dz) = (cols[0].f64(i), cols[1].f64(i));
            let made = match self.mode {
                Mode::Shot => shot_twin(&sim, z0, dz, &cols[2..], i),
                Mode::LinkMargin => link_margin_twin(&sim, z0, dz, &cols[2..], i),
            };
            out.append(made);
        }
        Ok(ColumnarValue::Array(Arc::new(out.finish()?)))
    }
}

/// A made twin and the elevation of its record's first and last sample.
type Made = Result<(TwinWaveform, f64, f64), TwinError>;

/// Elevations of the record's first and last samples when the simulated sample 0 (label `z0`)
/// lies at record sample `start` (negative: above the record), on the 1 ns grid.
fn record_elevations(z0: f64, start: isize, len: usize) -> (f64, f64) {
    let bin0 = z0 + start as f64 * GEDI_BIN_M;
    (bin0, bin0 - len.saturating_sub(1) as f64 * GEDI_BIN_M)
}

/// Mode (a); `c` = energy_total, noise_mean, noise_stddev, sample_count, start, seed
/// [, quantum [, noise_correlation [, noise_ratio]]]. The noise shape defaults to the one measured
/// on real GEDI records ([`NoiseShape::GEDI_V1`]).
fn shot_twin(sim: &[f64], z0: f64, dz: f64, c: &[Column], i: usize) -> Made {
    let (count, start) = (c[3].i64(i), c[4].i64(i));
    let count = usize::try_from(count).map_err(|_| TwinError::Invalid("sample_count"))?;
    let start = isize::try_from(start).map_err(|_| TwinError::Invalid("start"))?;
    if !z0.is_finite() {
        return Err(TwinError::Invalid("z0"));
    }
    let twin = ShotTwin {
        energy_total: c[0].f64(i),
        noise: Noise {
            mean: c[1].f64(i),
            stddev: c[2].f64(i),
        },
        sample_count: count,
        tx_pulse: None,
        quantum: c.get(6).map_or(0.0, |q| q.f64(i)),
        noise_shape: NoiseShape {
            correlation: c
                .get(7)
                .map_or(NoiseShape::GEDI_V1.correlation, |v| v.f64(i)),
            per_sample_ratio: c
                .get(8)
                .map_or(NoiseShape::GEDI_V1.per_sample_ratio, |v| v.f64(i)),
        },
    };
    let made = twin.apply(sim, dz, start, c[5].seed(i))?;
    let (bin0, last) = record_elevations(z0, start, made.wave.len());
    Ok((made, bin0, last))
}

/// Mode (b); `c` = link_margin_db, cover, seed [, true_cover].
fn link_margin_twin(sim: &[f64], z0: f64, dz: f64, c: &[Column], i: usize) -> Made {
    if !z0.is_finite() {
        return Err(TwinError::Invalid("z0"));
    }
    let mut twin = LinkMarginTwin::new(c[0].f64(i), c[1].f64(i));
    twin.true_cover = c.get(3).map(|t| t.f64(i));
    let made = twin.apply(sim, dz, c[2].seed(i))?;
    let (bin0, last) = record_elevations(z0, twin.pre_samples as isize, made.wave.len());
    Ok((made, bin0, last))
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
        for v in [
            &mut self.bin0,
            &mut self.last,
            &mut self.mean,
            &mut self.stddev,
        ] {
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
