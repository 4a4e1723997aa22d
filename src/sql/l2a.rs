//! `gedi_l2a(rxwaveform, noise_mean, noise_stddev, algorithm [, elevation_bin0, elevation_lastbin])`:
//! GEDI L2A (algorithm 1..6) of each waveform as a struct, a thin wrapper over
//! [`crate::kernels::waveform::l2a`]. The struct's fields and types are those of the `l2a` table
//! ([`crate::dataset::l2a::l2a_struct_fields`]); `no_result_reason` is null when the waveform was
//! processed and says why otherwise. A null argument gives a null struct.
//!
//! Without elevations the waveform is placed on GEDI's nominal 1 ns grid ([`GEDI_BIN_M`]): RH are
//! still metres, `elev_lowestmode` is null.

use std::sync::{Arc, LazyLock};

use arrow::array::{Array, AsArray};
use arrow::datatypes::{DataType, Float32Type, Float64Type, Int64Type};
use datafusion::common::{exec_err, plan_err, Result as DfResult};
use datafusion::logical_expr::{
    ColumnarValue, Documentation, ScalarFunctionArgs, ScalarUDFImpl, Signature, Volatility,
};

use super::args::{coerce_number, coerce_waveform};
use super::DOC_SECTION;
use crate::dataset::l2a::{l2a_struct_fields, L2aColumns};
use crate::kernels::waveform::l2a::{AlgorithmSettings, L2aProcessor, NoResult, Noise, WaveformGeolocation};
use crate::kernels::waveform::noise_twin::GEDI_BIN_M;

/// The `gedi_l2a` scalar function.
#[derive(Debug, PartialEq, Eq, Hash)]
pub struct GediL2a {
    signature: Signature,
}

impl GediL2a {
    /// Takes 4 or 6 arguments; numbers are cast (waveform to list<float32>, algorithm to int64,
    /// the others to float64).
    pub fn new() -> Self {
        GediL2a { signature: Signature::user_defined(Volatility::Immutable) }
    }
}

impl Default for GediL2a {
    fn default() -> Self {
        Self::new()
    }
}

const ARGS: [&str; 6] =
    ["rxwaveform", "noise_mean", "noise_stddev", "algorithm", "elevation_bin0", "elevation_lastbin"];

static DOCUMENTATION: LazyLock<Documentation> = LazyLock::new(|| {
    Documentation::builder(
        DOC_SECTION,
        "GEDI L2A (algorithm 1..6) of one waveform, as a struct {toploc, botloc, zcross, elev_lowestmode, rh, \
            sensitivity, energy_total, num_modes, no_result_reason}: the same kernel and values as `gedisim l2a` \
            (docs/l2a.md). rh[k+1] is RH k (m above the ground found).",
        "gedi_l2a(rxwaveform, noise_mean, noise_stddev, algorithm [, elevation_bin0, elevation_lastbin])",
    )
    .with_argument("rxwaveform", "received waveform (list of numbers, DN, 1 ns samples), e.g. shots.rx_waveform")
    .with_argument("noise_mean", "noise mean (DN), e.g. L1B noise_mean_corrected")
    .with_argument("noise_stddev", "noise standard deviation (DN), e.g. L1B noise_stddev_corrected")
    .with_argument("algorithm", "GEDI L2A algorithm setting, 1..6")
    .with_argument("elevation_bin0", "optional: elevation of the first sample (m); without it elev_lowestmode is null")
    .with_argument("elevation_lastbin", "optional: elevation of the last sample (m)")
    .with_sql_example(
        "select shot_number, gedi_l2a(rx_waveform, noise_mean_corrected, noise_stddev_corrected, 1, \
        elevation_bin0, elevation_lastbin)['rh'] as rh from shots where rx_waveform is not null limit 3",
    )
    .build()
});

impl ScalarUDFImpl for GediL2a {
    fn name(&self) -> &str {
        "gedi_l2a"
    }
    fn documentation(&self) -> Option<&Documentation> {
        Some(&DOCUMENTATION)
    }
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn coerce_types(&self, arg_types: &[DataType]) -> DfResult<Vec<DataType>> {
        if arg_types.len() != 4 && arg_types.len() != 6 {
            return plan_err!(
                "gedi_l2a(rxwaveform, noise_mean, noise_stddev, algorithm [, elevation_bin0, elevation_lastbin]): \
                 4 or 6 arguments, got {}",
                arg_types.len()
            );
        }
        arg_types
            .iter()
            .enumerate()
            .map(|(i, t)| match i {
                0 => coerce_waveform("gedi_l2a", t),
                3 => coerce_number("gedi_l2a", ARGS[i], t, DataType::Int64),
                _ => coerce_number("gedi_l2a", ARGS[i], t, DataType::Float64),
            })
            .collect()
    }
    fn return_type(&self, _: &[DataType]) -> DfResult<DataType> {
        Ok(DataType::Struct(l2a_struct_fields()))
    }
    fn invoke_with_args(&self, args: ScalarFunctionArgs) -> DfResult<ColumnarValue> {
        let n = args.number_rows;
        let arrays = ColumnarValue::values_to_arrays(&args.args)?;
        let waves = arrays[0].as_list::<i32>();
        let mean = arrays[1].as_primitive::<Float64Type>();
        let sd = arrays[2].as_primitive::<Float64Type>();
        let alg = arrays[3].as_primitive::<Int64Type>();
        let elevations = (arrays.len() == 6)
            .then(|| (arrays[4].as_primitive::<Float64Type>(), arrays[5].as_primitive::<Float64Type>()));
        let settings = AlgorithmSettings::all_gedi();
        let mut processor = L2aProcessor::new();
        let mut out = L2aColumns::with_capacity(n);
        for i in 0..n {
            let null_elevation = elevations.is_some_and(|(z0, zn)| z0.is_null(i) || zn.is_null(i));
            if waves.is_null(i) || mean.is_null(i) || sd.is_null(i) || alg.is_null(i) || null_elevation {
                out.append_null();
                continue;
            }
            let a = alg.value(i);
            let Some(s) = usize::try_from(a).ok().and_then(|a| settings.get(a.wrapping_sub(1))) else {
                return exec_err!("gedi_l2a: algorithm must be 1..6, got {a}");
            };
            let wave = waves.value(i);
            let wave = wave.as_primitive::<Float32Type>();
            let len = wave.len();
            let geo = match elevations {
                Some((z0, zn)) => WaveformGeolocation::vertical(len, z0.value(i), zn.value(i)),
                None => WaveformGeolocation::from_spacing(len, 0.0, GEDI_BIN_M),
            };
            let noise = Noise { mean: mean.value(i), stddev: sd.value(i) };
            // A null sample is a missing value: reported like a NaN, never read as its slot.
            let outcome = match (0..len).find(|&k| wave.is_null(k)) {
                Some(index) => Err(NoResult::NonFiniteSample { index }),
                None => processor.process(wave.values(), noise, &geo, s),
            };
            out.append(&outcome, &geo, elevations.is_some());
        }
        Ok(ColumnarValue::Array(Arc::new(out.finish_struct()?)))
    }
}
