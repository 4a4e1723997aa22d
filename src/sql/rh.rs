//! `gedi_rh(wave, z0, dz, ground)`: RH0…RH100 (m above `ground`) of a waveform list column whose
//! sample k is labelled `z0 − k·dz` (the `sim` table's convention). Wraps [`crate::kernels::waveform::rh`].

use std::sync::{Arc, LazyLock};

use arrow::array::{Array, AsArray};
use arrow::datatypes::{DataType, Float32Type, Float64Type};
use datafusion::common::{exec_err, Result as DfResult};
use datafusion::logical_expr::{
    ColumnarValue, Documentation, ScalarFunctionArgs, ScalarUDFImpl, Signature, Volatility,
};

use super::DOC_SECTION;

use crate::dataset::{list_f32, list_f32_builder};
use crate::kernels::waveform::rh::{has_energy, rh_profile};

/// The `gedi_rh` scalar function.
#[derive(Debug, PartialEq, Eq, Hash)]
pub struct GediRh {
    signature: Signature,
}

impl GediRh {
    /// Takes (list<float32>, float64, float64, float64).
    pub fn new() -> Self {
        GediRh {
            signature: Signature::exact(
                vec![list_f32(), DataType::Float64, DataType::Float64, DataType::Float64],
                Volatility::Immutable,
            ),
        }
    }
}

impl Default for GediRh {
    fn default() -> Self {
        Self::new()
    }
}

static DOCUMENTATION: LazyLock<Documentation> = LazyLock::new(|| {
    Documentation::builder(
        DOC_SECTION,
        "RH0…RH100 (m above `ground`) of a simulated waveform, as gediMetric computes them: a list of 101 values, \
            element k+1 is RH k. Null when the waveform holds a NaN, infinite or null sample or no positive energy \
            (empty, all zero or negative), or when z0 or ground is not finite.",
        "gedi_rh(wave, z0, dz, ground)",
    )
    .with_argument("wave", "waveform (list<float32>); sample k at elevation z0 − k·dz")
    .with_argument("z0", "elevation of sample 0 (m)")
    .with_argument("dz", "sample spacing (m)")
    .with_argument("ground", "ground elevation the heights are measured from (m)")
    .with_sql_example(
        "select footprint_id, gedi_rh(wave, z0, dz, als_ground)[99] as rh98 from sim \
        where weighting = 'count' limit 3",
    )
    .build()
});

impl ScalarUDFImpl for GediRh {
    fn name(&self) -> &str {
        "gedi_rh"
    }
    fn documentation(&self) -> Option<&Documentation> {
        Some(&DOCUMENTATION)
    }
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn return_type(&self, _: &[DataType]) -> DfResult<DataType> {
        Ok(list_f32())
    }
    fn invoke_with_args(&self, args: ScalarFunctionArgs) -> DfResult<ColumnarValue> {
        let n = args.number_rows;
        let arrays = ColumnarValue::values_to_arrays(&args.args)?;
        let (waves, z0, dz, ground) = (
            arrays[0].as_list::<i32>(),
            arrays[1].as_primitive::<Float64Type>(),
            arrays[2].as_primitive::<Float64Type>(),
            arrays[3].as_primitive::<Float64Type>(),
        );
        let mut out = list_f32_builder(n);
        for i in 0..n {
            if waves.is_null(i) || z0.is_null(i) || dz.is_null(i) || ground.is_null(i) {
                out.append_null();
                continue;
            }
            if !(dz.value(i) > 0.0 && dz.value(i).is_finite()) {
                return exec_err!("gedi_rh: dz must be > 0, got {}", dz.value(i));
            }
            let w = waves.value(i);
            let w = w.as_primitive::<Float32Type>();
            // RH is undefined without a finite waveform holding positive energy and finite
            // elevations: null, not the reference's all-zero profile.
            let finite = [z0.value(i), ground.value(i)].iter().all(|v| v.is_finite());
            if !finite || w.null_count() > 0 || !has_energy(w.values()) {
                out.append_null();
                continue;
            }
            let rh = rh_profile(w.values(), z0.value(i), dz.value(i), ground.value(i));
            out.append_value(rh.iter().map(|&v| Some(v)));
        }
        Ok(ColumnarValue::Array(Arc::new(out.finish())))
    }
}
