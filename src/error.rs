//! Typed errors. Every error reaching the user is one line naming the file and the field.

use std::path::PathBuf;

/// Errors of gedisim. `Display` is a single line: `<file>: <field>: <what>`. Serde carries one from
/// a child process (`ops::ingest_gedi::child`).
#[derive(Debug, thiserror::Error, serde::Serialize, serde::Deserialize)]
pub enum Error {
    /// A problem with one field (dataset, column, header entry) of one input file.
    #[error("{}: {field}: {message}", path.display())]
    Field { path: PathBuf, field: String, message: String },

    /// The file itself could not be opened, read or written.
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },

    /// A bad command-line value or a contradictory combination of options.
    #[error("{0}")]
    Usage(String),

    /// Arrow / Parquet / DataFusion failures while writing or querying a table.
    #[error("{}: {message}", path.display())]
    Table { path: PathBuf, message: String },
}

impl Error {
    /// Error about `field` of the file at `path`.
    pub fn field(path: impl Into<PathBuf>, field: impl Into<String>, message: impl std::fmt::Display) -> Self {
        Error::Field { path: path.into(), field: field.into(), message: message.to_string() }
    }

    /// Error about the file at `path` as a whole.
    pub fn file(path: impl Into<PathBuf>, message: impl std::fmt::Display) -> Self {
        Error::File { path: path.into(), message: one_line(&message.to_string()) }
    }

    /// Error while writing or reading a table at `path`.
    pub fn table(path: impl Into<PathBuf>, message: impl std::fmt::Display) -> Self {
        Error::Table { path: path.into(), message: one_line(&message.to_string()) }
    }
}

/// Collapse a multi-line message from a library into one line.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
