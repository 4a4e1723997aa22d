//! User CSV files as people have them, read with the `csv` crate: a header row, `,` `;` or tab
//! separators (the one the header uses most), quoted fields, a UTF-8 byte-order mark, `#`
//! comment lines, blank lines, surrounding spaces; columns found by any of their aliases,
//! case-insensitive. Errors name the file, the line and the column.

use std::path::Path;

use crate::error::{Error, Result};

/// A CSV file's header and rows.
#[derive(Debug, Clone)]
pub struct CsvTable {
    path: std::path::PathBuf,
    /// Header names, trimmed and lower-cased.
    names: Vec<String>,
    header: String,
    /// (line number, fields) of each row.
    rows: Vec<(u64, csv::StringRecord)>,
}

/// The separator the header line uses most (`,` when it uses none).
fn sniff_delimiter(text: &str) -> u8 {
    let first = text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#')).unwrap_or("");
    [b',', b';', b'\t']
        .into_iter()
        .max_by_key(|&d| (first.bytes().filter(|&b| b == d).count(), d == b','))
        .unwrap_or(b',')
}

impl CsvTable {
    /// Read `path`; `expected` names the header for the error of an empty file.
    pub fn read(path: &Path, expected: &str) -> Result<CsvTable> {
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
        let text = std::str::from_utf8(bytes).map_err(|e| Error::file(path, format!("not UTF-8 text: {e}")))?;
        let delimiter = sniff_delimiter(text);
        let mut reader = csv::ReaderBuilder::new()
            .delimiter(delimiter)
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .flexible(true)
            .from_reader(text.as_bytes());
        let headers = reader.headers().map_err(|e| Error::file(path, format!("header: {e}")))?.clone();
        if headers.iter().all(str::is_empty) {
            return Err(Error::field(path, "header", format!("empty file: expected a header `{expected}`")));
        }
        let names: Vec<String> = headers.iter().map(|h| h.to_ascii_lowercase()).collect();
        for (j, n) in names.iter().enumerate().filter(|(_, n)| !n.is_empty()) {
            if let Some(i) = names[..j].iter().position(|m| m == n) {
                return Err(Error::field(
                    path,
                    &headers[j],
                    format!(
                        "the header names `{}` twice (columns {} and {}): rename or drop one",
                        &headers[j],
                        i + 1,
                        j + 1
                    ),
                ));
            }
        }
        let mut rows = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(String::new(), |p| format!("line {}: ", p.line()));
                Error::file(path, format!("{line}{e}"))
            })?;
            if record.iter().all(str::is_empty) {
                continue;
            }
            rows.push((record.position().map_or(0, |p| p.line()), record));
        }
        Ok(CsvTable {
            path: path.to_path_buf(),
            names,
            header: headers.iter().collect::<Vec<_>>().join(&char::from(delimiter).to_string()),
            rows,
        })
    }

    /// Index of the first column named by one of `aliases` (lower case).
    pub fn column(&self, aliases: &[&str]) -> Option<usize> {
        aliases.iter().find_map(|a| self.names.iter().position(|n| n == a))
    }

    /// [`column`](Self::column), or an error naming the column and the header.
    pub fn require(&self, aliases: &[&str]) -> Result<usize> {
        self.column(aliases).ok_or_else(|| {
            let also = if aliases.len() > 1 { format!(" (or {})", aliases[1..].join(", ")) } else { String::new() };
            Error::field(
                &self.path,
                aliases[0],
                format!("no `{}`{also} column in the header `{}`", aliases[0], self.header),
            )
        })
    }

    /// The rows: (line number, fields).
    pub fn rows(&self) -> &[(u64, csv::StringRecord)] {
        &self.rows
    }

    /// Field `column` of `row`, or an error naming the line and the column `name`.
    pub fn field<'a>(&self, row: &'a (u64, csv::StringRecord), column: usize, name: &str) -> Result<&'a str> {
        row.1
            .get(column)
            .filter(|v| !v.is_empty())
            .ok_or_else(|| Error::field(&self.path, name, format!("line {}: missing value", row.0)))
    }

    /// Field `column` of `row` as a finite number.
    pub fn number(&self, row: &(u64, csv::StringRecord), column: usize, name: &str) -> Result<f64> {
        let s = self.field(row, column, name)?;
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(Error::field(&self.path, name, format!("line {}: non-finite value `{s}`", row.0))),
            Err(_) => Err(Error::field(&self.path, name, format!("line {}: `{s}` is not a number", row.0))),
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header as written (names joined by the file's separator).
    pub fn header(&self) -> &str {
        &self.header
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &[u8]) -> CsvTable {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("t.csv");
        std::fs::write(&f, text).unwrap();
        CsvTable::read(&f, "a,b").unwrap()
    }

    #[test]
    fn separators_quotes_bom_comments_and_aliases() {
        for text in [
            &b"\xEF\xBB\xBFPlot_ID;X;Y\n# a comment\n\"p 1\"; 1,5 ;2\n\np2;3;4\n"[..],
            b"plot_id,x,y\n\"p 1\",\"1,5\",2\np2,3,4\n",
            b"plot_id\tx\ty\n\"p 1\"\t1,5\t2\np2\t3\t4\n",
        ] {
            let t = table(text);
            let id = t.require(&["id", "plot_id"]).unwrap();
            assert_eq!(t.rows().len(), 2, "{}", String::from_utf8_lossy(text));
            assert_eq!(t.field(&t.rows()[0], id, "id").unwrap(), "p 1");
            assert_eq!(t.field(&t.rows()[0], t.require(&["x"]).unwrap(), "x").unwrap(), "1,5");
            assert_eq!(t.number(&t.rows()[1], t.require(&["y"]).unwrap(), "y").unwrap(), 4.0);
        }
    }

    #[test]
    fn errors_name_the_column_and_the_line() {
        let t = table(b"id,x\na,1\nb,zz\n");
        let e = t.require(&["y", "northing"]).unwrap_err().to_string();
        assert!(e.contains("no `y` (or northing) column") && e.contains("t.csv"), "{e}");
        let e = t.number(&t.rows()[1], 1, "x").unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("`zz` is not a number"), "{e}");
    }
}
