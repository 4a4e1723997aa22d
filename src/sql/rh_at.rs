//! `rh(rh_list, k)`: RH k (k = 0…100, the percentile itself) of an RH0…RH100 list — `rh_sim`,
//! `rh_gedi`, `rh_aligned` of `results`, `rh` of `sim`, `gedi_rh(…)` — so that RH98 is
//! `rh(rh_sim, 98)`, not the 1-based `rh_sim[99]`.

use std::sync::{Arc, LazyLock};

use arrow::array::{Array, AsArray, Float32Builder};
use arrow::datatypes::{DataType, Float32Type, Int64Type};
use datafusion::common::{exec_err, Result as DfResult};
use datafusion::logical_expr::{
    ColumnarValue, Documentation, ScalarFunctionArgs, ScalarUDFImpl, Signature, Volatility,
};

use super::DOC_SECTION;
use crate::dataset::list_f32;
use crate::kernels::gedi::RH_LEN;

/// The `rh` scalar function.
#[derive(Debug, PartialEq, Eq, Hash)]
pub struct RhAt {
    signature: Signature,
}

impl RhAt {
    /// Takes (list<float32>, int64).
    pub fn new() -> Self {
        RhAt { signature: Signature::exact(vec![list_f32(), DataType::Int64], Volatility::Immutable) }
    }
}

impl Default for RhAt {
    fn default() -> Self {
        Self::new()
    }
}

static DOCUMENTATION: LazyLock<Documentation> = LazyLock::new(|| {
    Documentation::builder(
        DOC_SECTION,
        "RH k (m) of an RH0…RH100 list, by its percentile k (0…100): rh(rh_sim, 98) is RH98. Null when the list \
            or k is null; an error when k is outside 0…100 or the list does not hold 101 values.",
        "rh(rh_list, k)",
    )
    .with_argument("rh_list", "RH0…RH100 (list<float32> of 101 values): rh_sim, rh_gedi, rh_aligned, sim.rh")
    .with_argument("k", "the percentile, 0…100")
    .with_sql_example(
        "select weighting, avg(rh(rh_sim, 98) - rh(rh_aligned, 98)) as rh98_bias from results \
        where algorithm = 'default' group by weighting",
    )
    .build()
});

impl ScalarUDFImpl for RhAt {
    fn name(&self) -> &str {
        "rh"
    }
    fn documentation(&self) -> Option<&Documentation> {
        Some(&DOCUMENTATION)
    }
    fn signature(&self) -> &Signature {
        &self.signature
    }
    fn return_type(&self, _: &[DataType]) -> DfResult<DataType> {
        Ok(DataType::Float32)
    }
    fn invoke_with_args(&self, args: ScalarFunctionArgs) -> DfResult<ColumnarValue> {
        let n = args.number_rows;
        let arrays = ColumnarValue::values_to_arrays(&args.args)?;
        let (lists, ks) = (arrays[0].as_list::<i32>(), arrays[1].as_primitive::<Int64Type>());
        let mut out = Float32Builder::with_capacity(n);
        for i in 0..n {
            if lists.is_null(i) || ks.is_null(i) {
                out.append_null();
                continue;
            }
            let k = ks.value(i);
            if !(0..=100).contains(&k) {
                return exec_err!("rh: the percentile k must be 0…100, got {k}");
            }
            let list = lists.value(i);
            if list.len() != RH_LEN {
                return exec_err!("rh: an RH list holds RH0…RH100 ({RH_LEN} values), this one {}", list.len());
            }
            let v = list.as_primitive::<Float32Type>();
            if v.is_null(k as usize) {
                out.append_null();
            } else {
                out.append_value(v.value(k as usize));
            }
        }
        Ok(ColumnarValue::Array(Arc::new(out.finish())))
    }
}
