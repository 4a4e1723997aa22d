//! Derived tables: their Arrow schemas and the conversion of kernel outputs into record batches.

pub mod l2a;
pub mod results;
pub mod offsets;
pub mod sim;

use std::sync::Arc;

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
