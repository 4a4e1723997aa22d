//! Plan: the granule files given (folders expanded), paired L1B with L2A by their granule key.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::GranulePair;
use crate::error::{Error, Result};

/// The part of a GEDI file name shared by the L1B and L2A files of one granule.
///
/// `GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub` and
/// `GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub` both give
/// `2019108080338_O01964_T05337_02` (V2 names keep their sub-orbit field). A name that does not
/// follow the convention is its own key.
pub fn granule_key(path: &Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let tokens: Vec<&str> = stem.split('_').collect();
    let is_product = tokens.len() > 2 && tokens[0].starts_with("GEDI0") && tokens[1].len() == 1;
    if is_product {
        let track =
            tokens.iter().position(|t| t.len() > 1 && t.starts_with('T') && t[1..].bytes().all(|b| b.is_ascii_digit()));
        if let Some(t) = track.filter(|&t| t > 2 && t + 1 < tokens.len()) {
            return tokens[2..=t + 1].join("_");
        }
    }
    stem
}

/// Files as given; folders expanded to the `.h5` files they hold whose name starts with
/// `product` (GEDI's naming: `GEDI01_B…` for L1B, `GEDI02_A…` for L2A).
pub fn expand_granule_inputs(inputs: &[PathBuf], product: &str) -> Result<Vec<PathBuf>> {
    crate::io::expand_inputs(inputs, |f| {
        crate::io::has_extension(f, "h5")
            && f.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(product))
    })
}

/// Pair L1B and L2A files by [`granule_key`]; a file without a partner becomes a one-sided pair.
///
/// Returns the pairs (in the order the files were given, L1B first) and one note per file left
/// without a partner when both lists are non-empty.
pub fn pair_granules(l1b: &[PathBuf], l2a: &[PathBuf]) -> Result<(Vec<GranulePair>, Vec<String>)> {
    let mut l2a_by_key: BTreeMap<String, &PathBuf> = BTreeMap::new();
    for p in l2a {
        if let Some(other) = l2a_by_key.insert(granule_key(p), p) {
            return Err(Error::Usage(format!("{} and {} are the same L2A granule", other.display(), p.display())));
        }
    }
    let mut seen = BTreeMap::new();
    let mut pairs = Vec::new();
    let mut notes = Vec::new();
    let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    for p in l1b {
        let key = granule_key(p);
        if let Some(other) = seen.insert(key.clone(), p) {
            return Err(Error::Usage(format!("{} and {} are the same L1B granule", other.display(), p.display())));
        }
        let partner = l2a_by_key.remove(&key).cloned();
        if partner.is_none() && !l2a.is_empty() {
            notes.push(format!(
                "{}: no L2A file of granule {key} was given; its shots have null L2A columns",
                p.display()
            ));
        }
        pairs.push(GranulePair { granule: stem(p), l1b: Some(p.clone()), l2a: partner });
    }
    for p in l2a.iter().filter(|p| l2a_by_key.contains_key(&granule_key(p))) {
        if !l1b.is_empty() {
            notes.push(format!(
                "{}: no L1B file of granule {} was given; its shots have null L1B columns",
                p.display(),
                granule_key(p)
            ));
        }
        pairs.push(GranulePair { granule: stem(p), l1b: None, l2a: Some(p.clone()) });
    }
    Ok((pairs, notes))
}
