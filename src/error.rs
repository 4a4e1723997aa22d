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

/// Longest word an error line keeps whole: a longer one (a 20 MB CSV field a parser echoes) is
/// shown by its first [`WORD_HEAD`] bytes and its length.
pub const MAX_WORD: usize = 1024;
const WORD_HEAD: usize = 60;
/// Longest error line (bytes); a longer one is cut and says so.
pub const MAX_LINE: usize = 4000;

/// Collapse a multi-line message from a library into one line of at most [`MAX_LINE`] bytes.
pub fn one_line(s: &str) -> String {
    let mut out = String::new();
    for w in s.split_whitespace() {
        if out.len() >= MAX_LINE {
            out.push_str(" …(cut)");
            break;
        }
        if !out.is_empty() {
            out.push(' ');
        }
        if w.len() <= MAX_WORD {
            out.push_str(w);
        } else {
            let head = (0..=WORD_HEAD).rev().find(|&i| w.is_char_boundary(i)).unwrap_or(0);
            out.push_str(&format!("{}…({} bytes)", &w[..head], w.len()));
        }
    }
    out
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A kernel's usage error (a value it cannot work with) is the caller's usage error.
impl From<crate::kernels::error::Error> for Error {
    fn from(e: crate::kernels::error::Error) -> Self {
        match e {
            crate::kernels::error::Error::Usage(m) => Error::Usage(m),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_lines_stay_short() {
        assert_eq!(one_line("a\n  b\tc"), "a b c");
        let field = "é".repeat(10_000_000);
        let line = one_line(&format!("bad field {field} in x.csv"));
        assert!(line.starts_with("bad field é") && line.ends_with("…(20000000 bytes) in x.csv"), "{}", &line[..80]);
        assert!(line.len() < 200);
        let many = "1+1 ".repeat(100_000);
        let line = one_line(&many);
        assert!(line.len() <= MAX_LINE + 20 && line.ends_with("…(cut)"));
    }
}
