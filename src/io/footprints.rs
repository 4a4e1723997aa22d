//! Footprint lists: CSV with a header naming `id`, `x`, `y` (other columns ignored).

use std::path::Path;

use crate::error::{Error, Result};
use crate::kernels::sim::Footprint;

/// Read a footprint CSV (`id,x,y` header, any column order, extra columns ignored).
pub fn read_footprints_csv(path: &Path) -> Result<Vec<Footprint>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
    let (_, header) =
        lines.next().ok_or_else(|| Error::field(path, "header", "empty file: expected a header `id,x,y`"))?;
    let names: Vec<String> = header.split(',').map(|s| s.trim().to_ascii_lowercase()).collect();
    let col = |name: &str| {
        names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| Error::field(path, name, format!("no `{name}` column in the header `{header}`")))
    };
    let (ci, cx, cy) = (col("id")?, col("x")?, col("y")?);
    let mut out = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for (lineno, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let get = |c: usize, name: &str| {
            fields
                .get(c)
                .copied()
                .ok_or_else(|| Error::field(path, name, format!("line {}: missing value", lineno + 1)))
        };
        let num = |c: usize, name: &str| -> Result<f64> {
            let s = get(c, name)?;
            let v: f64 = s
                .parse()
                .map_err(|_| Error::field(path, name, format!("line {}: `{s}` is not a number", lineno + 1)))?;
            if !v.is_finite() {
                return Err(Error::field(path, name, format!("line {}: non-finite value `{s}`", lineno + 1)));
            }
            Ok(v)
        };
        let id = get(ci, "id")?.to_string();
        if !seen.insert(id.clone()) {
            return Err(Error::field(path, "id", format!("line {}: duplicate id `{id}`", lineno + 1)));
        }
        out.push(Footprint::at(id, num(cx, "x")?, num(cy, "y")?));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_any_column_order_and_rejects_bad_values() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("fp.csv");
        std::fs::write(&f, "x,id,y,extra\n1.5,a,2.5,z\n3,b,4,z\n").unwrap();
        let fps = read_footprints_csv(&f).unwrap();
        assert_eq!(fps[1], Footprint::at("b", 3.0, 4.0));
        std::fs::write(&f, "id,x,y\na,1,nan\n").unwrap();
        let e = read_footprints_csv(&f).unwrap_err().to_string();
        assert!(e.contains("fp.csv") && e.contains("y"), "{e}");
        std::fs::write(&f, "id,x\na,1\n").unwrap();
        assert!(read_footprints_csv(&f).unwrap_err().to_string().contains("no `y` column"));
    }
}
