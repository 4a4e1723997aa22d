//! The report's two headline tables (`ground_detection`, `msd`) read back from
//! `<report>/<name>.parquet` and laid out compactly for a terminal (`gedisim demo`).

use std::fmt::Write;
use std::path::Path;

use arrow::array::{Array, AsArray, RecordBatch};
use arrow::datatypes::{DataType, Float64Type};

use crate::error::{Error, Result};

/// A row of `ground_detection`.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundRow {
    pub algorithm: String,
    pub sensitivity_group: String,
    pub n: i64,
    pub bias: f64,
    pub rmse: f64,
}

/// A row of `msd`.
#[derive(Debug, Clone, PartialEq)]
pub struct MsdRow {
    pub weighting: String,
    pub algorithm: String,
    pub sensitivity_group: String,
    pub sb: f64,
    pub sdsd: f64,
    pub lcs: f64,
    pub msd: f64,
    pub n: i64,
}

/// The two tables.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Headline {
    pub ground: Vec<GroundRow>,
    pub msd: Vec<MsdRow>,
    /// Shots by `results.vertical_reference` (how GEDI's ground came into the ALS datum), for the
    /// ground table's header (`dataset::results::vertical_references`).
    pub vertical_references: std::collections::BTreeMap<String, usize>,
}

fn read(path: &Path) -> Result<Vec<RecordBatch>> {
    let mut out = Vec::new();
    crate::dataset::read::for_each_batch(path, None, None, |c| {
        out.push(c.batch().clone());
        Ok(())
    })?;
    Ok(out)
}

fn strings(b: &RecordBatch, path: &Path, name: &str) -> Result<Vec<String>> {
    let c = b.column_by_name(name).ok_or_else(|| Error::field(path, name, "column missing"))?;
    let c = c.as_string_opt::<i32>().ok_or_else(|| Error::field(path, name, "not a string"))?;
    Ok((0..c.len()).map(|i| if c.is_null(i) { String::new() } else { c.value(i).to_string() }).collect())
}

fn numbers(b: &RecordBatch, path: &Path, name: &str) -> Result<Vec<f64>> {
    let c = b.column_by_name(name).ok_or_else(|| Error::field(path, name, "column missing"))?;
    let c = arrow::compute::cast(c, &DataType::Float64).map_err(|e| Error::field(path, name, e))?;
    let c = c.as_primitive::<Float64Type>();
    Ok((0..c.len()).map(|i| if c.is_null(i) { f64::NAN } else { c.value(i) }).collect())
}

impl Headline {
    /// Read `ground_detection.parquet` and `msd.parquet` from a report directory.
    pub fn read(report_dir: &Path) -> Result<Headline> {
        let mut h = Headline::default();
        let path = report_dir.join("ground_detection.parquet");
        for b in read(&path)? {
            let (a, g) = (strings(&b, &path, "algorithm")?, strings(&b, &path, "sensitivity_group")?);
            let (n, bias, rmse) = (numbers(&b, &path, "n")?, numbers(&b, &path, "bias")?, numbers(&b, &path, "rmse")?);
            for i in 0..b.num_rows() {
                h.ground.push(GroundRow {
                    algorithm: a[i].clone(),
                    sensitivity_group: g[i].clone(),
                    n: n[i] as i64,
                    bias: bias[i],
                    rmse: rmse[i],
                });
            }
        }
        let path = report_dir.join("msd.parquet");
        for b in read(&path)? {
            let (w, a, g) = (
                strings(&b, &path, "weighting")?,
                strings(&b, &path, "algorithm")?,
                strings(&b, &path, "sensitivity_group")?,
            );
            let (sb, sdsd, lcs) = (numbers(&b, &path, "sb")?, numbers(&b, &path, "sdsd")?, numbers(&b, &path, "lcs")?);
            let (msd, n) = (numbers(&b, &path, "msd")?, numbers(&b, &path, "n")?);
            for i in 0..b.num_rows() {
                h.msd.push(MsdRow {
                    weighting: w[i].clone(),
                    algorithm: a[i].clone(),
                    sensitivity_group: g[i].clone(),
                    sb: sb[i],
                    sdsd: sdsd[i],
                    lcs: lcs[i],
                    msd: msd[i],
                    n: n[i] as i64,
                });
            }
        }
        Ok(h)
    }

    /// Algorithms in table order (`default`, a1 … a6 as present).
    fn algorithms(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for a in self.ground.iter().map(|r| &r.algorithm).chain(self.msd.iter().map(|r| &r.algorithm)) {
            if !out.contains(a) {
                out.push(a.clone());
            }
        }
        out
    }

    /// `ground_detection`, one line per algorithm: all shots, then the low and high sensitivity groups.
    pub fn ground_table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "Ground detection (m): bias = GEDI ground − ALS ground (positive: GEDI's ground is higher), per L2A \
             algorithm, count weighting, shots kept by the study's filters"
        );
        if !self.vertical_references.is_empty() {
            let refs: Vec<String> = self.vertical_references.iter().map(|(r, n)| format!("{r} ({n} shots)")).collect();
            let _ = writeln!(s, "GEDI ground in the ALS vertical datum through: {}", refs.join(", "));
        }
        let _ = writeln!(
            s,
            "{:<10} {:>6} {:>8} {:>7} │ {:>6} {:>8} │ {:>6} {:>8}",
            "algorithm", "n", "bias", "rmse", "n low", "bias", "n high", "bias"
        );
        let cell = |a: &str, g: &str| self.ground.iter().find(|r| r.algorithm == a && r.sensitivity_group == g);
        for a in self.algorithms() {
            let (all, low, high) = (cell(&a, "all"), cell(&a, "low"), cell(&a, "high"));
            let n = |r: Option<&GroundRow>| r.map_or("0".to_string(), |r| r.n.to_string());
            let v = |r: Option<&GroundRow>, f: fn(&GroundRow) -> f64, sign: bool| match r {
                Some(r) if sign => format!("{:+.3}", f(r)),
                Some(r) => format!("{:.3}", f(r)),
                None => "–".to_string(),
            };
            let _ = writeln!(
                s,
                "{:<10} {:>6} {:>8} {:>7} │ {:>6} {:>8} │ {:>6} {:>8}",
                a,
                n(all),
                v(all, |r| r.bias, true),
                v(all, |r| r.rmse, false),
                n(low),
                v(low, |r| r.bias, true),
                n(high),
                v(high, |r| r.bias, true)
            );
        }
        s
    }

    /// `msd` over all sensitivities, one line per algorithm, one column per weighting: MSD (m²) and
    /// the shares of SB, SDSD and LCS in it (%).
    pub fn msd_table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "MSD of simulated vs real RH1–RH99, all sensitivities: MSD m² (SB / SDSD / LCS % of \
            MSD)"
        );
        let weightings = crate::kernels::study::select::WEIGHTINGS;
        let mut line = format!("{:<10} {:>6}", "algorithm", "n");
        for w in weightings {
            line += &format!("   {w:<21}");
        }
        let _ = writeln!(s, "{}", line.trim_end());
        for a in self.algorithms() {
            let cell = |w: &str| {
                self.msd.iter().find(|r| r.algorithm == a && r.weighting == w && r.sensitivity_group == "all")
            };
            let n = weightings.iter().filter_map(|w| cell(w)).map(|r| r.n).max().unwrap_or(0);
            let mut line = format!("{a:<10} {n:>6}");
            for w in weightings {
                let text = match cell(w) {
                    Some(r) if r.msd > 0.0 => {
                        let p = |x: f64| (100.0 * x / r.msd).round();
                        format!("{:.2} ({:.0}/{:.0}/{:.0})", r.msd, p(r.sb), p(r.sdsd), p(r.lcs))
                    }
                    Some(r) => format!("{:.2}", r.msd),
                    None => "–".to_string(),
                };
                line += &format!("   {text:<21}");
            }
            let _ = writeln!(s, "{}", line.trim_end());
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_lay_out_every_algorithm_and_weighting() {
        let g = |a: &str, grp: &str, n: i64, bias: f64| GroundRow {
            algorithm: a.into(),
            sensitivity_group: grp.into(),
            n,
            bias,
            rmse: bias.abs() + 0.1,
        };
        let m = |w: &str, a: &str| MsdRow {
            weighting: w.into(),
            algorithm: a.into(),
            sensitivity_group: "all".into(),
            sb: 1.0,
            sdsd: 0.5,
            lcs: 2.5,
            msd: 4.0,
            n: 12,
        };
        let h = Headline {
            ground: vec![g("default", "low", 4, 0.4), g("default", "all", 12, 0.5), g("a1", "all", 10, -0.25)],
            msd: vec![m("count", "default"), m("int", "a1")],
            vertical_references: [("geoid".to_string(), 2), ("geoid+collocation_dz".to_string(), 10)].into(),
        };
        let t = h.ground_table();
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 5, "{t}");
        assert!(lines[0].contains("GEDI ground − ALS ground"), "the sign is stated: {t}");
        assert!(lines[1].contains("geoid (2 shots), geoid+collocation_dz (10 shots)"), "{t}");
        assert!(lines[3].starts_with("default") && lines[3].contains("+0.500") && lines[3].contains("+0.400"), "{t}");
        assert!(lines[4].starts_with("a1") && lines[4].contains("-0.250"), "{t}");
        let t = h.msd_table();
        assert!(t.contains("4.00 (25/13/63)"), "{t}");
        let a1 = t.lines().find(|l| l.starts_with("a1")).unwrap();
        assert_eq!(a1.matches('–').count(), 2, "{t}");
    }
}
