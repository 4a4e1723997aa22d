//! The dataset directory: table names, atomic writes, content-hash registry.
