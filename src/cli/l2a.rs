//! `gedisim l2a`.

use std::path::PathBuf;

use clap::Args;

use gedisim::{Error, Result};


#[derive(Args)]
pub struct L2aArgs {
    /// GEDI L1B file (V1 or V2).
    #[arg(long)]
    l1b: PathBuf,
    /// Output Parquet file: one row per shot × algorithm.
    #[arg(long)]
    pub out: PathBuf,
    /// Algorithms to run, e.g. 1,3.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6")]
    pub algorithms: Vec<u8>,
}

pub fn l2a(a: L2aArgs) -> Result<()> {
    use gedisim::kernels::waveform::l2a::AlgorithmSettings;
    let settings = a
        .algorithms
        .iter()
        .map(|&n| AlgorithmSettings::gedi(n).ok_or_else(|| Error::Usage(format!("--algorithms: {n} is not a GEDI algorithm (1..6)"))))
        .collect::<Result<Vec<_>>>()?;
    let opts = gedisim::ops::ingest_gedi::GediOptions::default();
    let schema = gedisim::dataset::l2a::l2a_schema();
    let props = gedisim::dataset::writer_properties(&Default::default(), 1 << 16);
    let mut writer = gedisim::dataset::AtomicParquet::create(&a.out, schema, props)?;
    let mut rows = 0;
    let report = gedisim::ops::ingest_gedi::ingest_gedi(std::slice::from_ref(&a.l1b), &[], &opts, |shots| {
        let batch = gedisim::dataset::l2a::l2a_batch(&shots, &settings, &a.l1b)?;
        rows += batch.num_rows();
        writer.write(&batch)
    })?;
    writer.finish()?;
    eprintln!("{} shots × {} algorithms → {rows} rows in {}", report.rows(), settings.len(), a.out.display());
    Ok(())
}
