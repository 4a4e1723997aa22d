//! The re-use key of a diagnosis (its inputs by content) and the diagnosis already written for it.

use std::path::{Path, PathBuf};

use super::{DiagnoseOptions, DiagnosisOutput};
use crate::dataset::{self, tables, Dataset};
use crate::error::Result;
use crate::kernels::diagnose::json::DiagnosisJson;
use crate::kernels::scenario::effects::EffectKind;
use crate::kernels::sim::PulseModel;

/// The key of a diagnosis's inputs (a hex SHA-256 over these facts), built from content keys as
/// `run`'s work is: this binary's content, the effects, pulse (a pulse file's content) and
/// self-test asked for; each granule of `shots/` by the content hashes and area it was ingested
/// from (`ops::run::granule_inputs`); and the content of the files of `tiles/` (hence of what
/// `als/` holds), `offsets/` and `strata/` (files above 256 MiB by their length and 32 blocks,
/// `dataset::granule_hash`). Stored in diagnosis.json: a re-run on the same inputs — even a copy
/// of the dataset elsewhere — reuses the diagnosis; `--force` recomputes.
pub(super) fn inputs_key(ds: &Dataset, kinds: &[EffectKind], opts: &DiagnoseOptions) -> Result<String> {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let (pulse, twins, ranked) = (&opts.pulse, opts.twins, opts.ranked_shots);
    h.update(format!(
        "gedisim {}\0{}\0{pulse:?}\0{twins}\0{ranked}\0",
        env!("CARGO_PKG_VERSION"),
        kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join(",")
    ));
    // The program by its content: a rebuild of the same version counts.
    if let Ok(exe) = std::env::current_exe() {
        h.update(format!("{}\0", dataset::granule_hash(&exe)?));
    }
    if let PulseModel::File(p) = pulse {
        h.update(format!("{}\0", dataset::content_hash(p)?));
    }
    // shots/: each granule by what it was ingested from, as `run` keys it.
    for f in ds.visible_files(tables::SHOTS).unwrap_or_default() {
        let (key, inputs) = crate::ops::run::granule_inputs(ds, &f)?;
        h.update(format!("shots {key}\0{inputs}\0"));
    }
    // als/ is what the rows of tiles/ say was read (each tile's content hash, the cells read);
    // tiles/, offsets/ and strata/ by their files' content.
    for table in [tables::TILES, tables::OFFSETS, tables::STRATA] {
        for f in ds.visible_files(table).unwrap_or_default() {
            let name = f.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            h.update(format!("{table} {name}\0{}\0", dataset::granule_hash(&f)?));
        }
    }
    Ok(hex::encode(h.finalize()))
}

/// The diagnosis in `out` when it was made from inputs of key `key` and all its files are there.
pub(super) fn reusable(out: &Path, key: &str) -> Option<DiagnosisOutput> {
    let text = std::fs::read_to_string(out.join("diagnosis.json")).ok()?;
    let json: DiagnosisJson = serde_json::from_str(&text).ok()?;
    let mut files: Vec<PathBuf> = json.files.iter().map(|f| out.join(f)).collect();
    let complete = !files.is_empty() && files.iter().all(|f| f.is_file());
    files.push(out.join("diagnosis.json"));
    (json.inputs_key.as_deref() == Some(key) && complete).then_some(DiagnosisOutput { json, files, reused: true })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_inputs_key_follows_effects_pulse_and_the_content_of_every_table() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(&dir.path().join("ds")).unwrap();
        let shots = ds.table_file(tables::SHOTS, "g1").unwrap();
        std::fs::write(&shots, b"first").unwrap();
        let pulse = PulseModel::Recorded(Default::default());
        let with = |pulse: &PulseModel, twins, ranked_shots| DiagnoseOptions {
            pulse: pulse.clone(),
            twins,
            ranked_shots,
            ..DiagnoseOptions::new()
        };
        let key = |kinds: &[EffectKind], pulse: &PulseModel| inputs_key(&ds, kinds, &with(pulse, 10, 1500)).unwrap();
        let k0 = key(&[EffectKind::Datum], &pulse);
        assert_eq!(k0, key(&[EffectKind::Datum], &pulse), "the same inputs, the same key");
        assert_ne!(k0, key(&[EffectKind::Datum, EffectKind::Pulse], &pulse), "other effects");
        assert_ne!(k0, key(&[EffectKind::Datum], &PulseModel::Gaussian(None)), "another pulse");
        assert_ne!(k0, inputs_key(&ds, &[EffectKind::Datum], &with(&pulse, 4, 1500)).unwrap(), "another self-test");
        assert_ne!(k0, inputs_key(&ds, &[EffectKind::Datum], &with(&pulse, 10, 0)).unwrap(), "another sample");
        // A new file in a table the diagnosis reads.
        let strata = ds.table_file(tables::STRATA, "strata").unwrap();
        std::fs::write(&strata, b"s").unwrap();
        let k1 = key(&[EffectKind::Datum], &pulse);
        assert_ne!(k0, k1);
        // A shots file rewritten: another size, or the same size at another time.
        std::fs::write(&shots, b"second!").unwrap();
        let k2 = key(&[EffectKind::Datum], &pulse);
        assert_ne!(k1, k2);
        std::fs::write(&shots, b"third!!").unwrap();
        let later = std::time::SystemTime::now() + std::time::Duration::from_secs(5);
        std::fs::File::options().write(true).open(&shots).unwrap().set_modified(later).unwrap();
        assert_ne!(k2, key(&[EffectKind::Datum], &pulse));
        // A file of a table it does not read (the report's) changes nothing.
        let k3 = key(&[EffectKind::Datum], &pulse);
        std::fs::create_dir_all(ds.root().join("report")).unwrap();
        std::fs::write(ds.root().join("report/msd.parquet"), b"r").unwrap();
        assert_eq!(k3, key(&[EffectKind::Datum], &pulse));
        // Content, not times: strata rewritten with the same size at the same time is seen…
        let mtime = |f: &Path| std::fs::metadata(f).unwrap().modified().unwrap();
        let at = mtime(&strata);
        std::fs::write(&strata, b"t").unwrap();
        std::fs::File::options().write(true).open(&strata).unwrap().set_modified(at).unwrap();
        let k4 = key(&[EffectKind::Datum], &pulse);
        assert_ne!(k3, k4);
        // …and a copy of the dataset elsewhere has the same key.
        let copy = Dataset::create(&dir.path().join("copy")).unwrap();
        for (table, name) in [(tables::SHOTS, "g1"), (tables::STRATA, "strata")] {
            let (from, to) = (ds.table_file(table, name).unwrap(), copy.table_file(table, name).unwrap());
            std::fs::copy(&from, &to).unwrap();
            std::fs::File::options().write(true).open(&to).unwrap().set_modified(mtime(&from)).unwrap();
        }
        assert_eq!(k4, inputs_key(&copy, &[EffectKind::Datum], &with(&pulse, 10, 1500)).unwrap());
    }
}
