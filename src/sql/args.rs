//! Argument coercion shared by gedisim's SQL functions: waveforms to `list<float32>`, numbers to
//! the type a kernel takes, with planning errors that name the function and the argument.

use arrow::datatypes::DataType;
use datafusion::common::{plan_err, Result as DfResult};

use crate::dataset::list_f32;

/// The type a waveform argument is cast to: any list of numbers becomes `list<float32>`.
pub fn coerce_waveform(name: &str, t: &DataType) -> DfResult<DataType> {
    match t {
        DataType::Null => Ok(list_f32()),
        DataType::List(f) | DataType::LargeList(f) | DataType::FixedSizeList(f, _)
            if f.data_type().is_numeric() || f.data_type().is_null() =>
        {
            Ok(list_f32())
        }
        other => plan_err!("{name}: the waveform must be a list of numbers, got {other}"),
    }
}

/// The type a numeric argument is cast to (`target`), or a planning error naming the argument.
pub fn coerce_number(name: &str, arg: &str, t: &DataType, target: DataType) -> DfResult<DataType> {
    let ok = t.is_null() || if target == DataType::Int64 { t.is_integer() } else { t.is_numeric() };
    if ok {
        Ok(target)
    } else {
        plan_err!("{name}: {arg} must be a number, got {t}")
    }
}
