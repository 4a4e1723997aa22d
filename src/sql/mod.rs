//! The DataFusion session: the dataset's tables registered by name, and gedisim's SQL functions
//! (thin wrappers over the kernels).

pub mod l2a;
pub mod noise_twin;
pub mod rh;
pub mod simulate;

use std::path::Path;

use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::ListingOptions;
use datafusion::prelude::{SessionConfig, SessionContext};
use std::sync::Arc;

use crate::dataset::{self, Dataset};
use crate::error::{Error, Result};

/// A session with every table folder of `dataset` registered under its folder name.
pub async fn session(ds: &Dataset) -> Result<SessionContext> {
    let config = SessionConfig::new().with_information_schema(true);
    let ctx = SessionContext::new_with_config(config);
    register_functions(&ctx, ds);
    for entry in std::fs::read_dir(ds.root()).map_err(|e| Error::file(ds.root(), e))? {
        let dir = entry.map_err(|e| Error::file(ds.root(), e))?.path();
        let Some(name) = dir.file_name().and_then(|n| n.to_str()).map(str::to_string) else { continue };
        // `report/` holds the report's outputs (many schemas), not a table.
        if name == dataset::tables::REPORT || !dir.is_dir() || dataset::table_files(&dir).map(|f| f.is_empty()).unwrap_or(true) {
            continue;
        }
        register_table(&ctx, &name, &dir).await?;
    }
    Ok(ctx)
}

/// Register gedisim's SQL functions: `gedi_rh(wave, z0, dz, ground)`, `gedi_l2a(…)`,
/// `gedi_noise_twin(…)`, `gedi_link_margin_twin(…)` and the table function `gedi_simulate([profile])`.
pub fn register_functions(ctx: &SessionContext, ds: &Dataset) {
    use datafusion::logical_expr::ScalarUDF;
    ctx.register_udf(ScalarUDF::new_from_impl(rh::GediRh::new()));
    ctx.register_udf(ScalarUDF::new_from_impl(l2a::GediL2a::new()));
    ctx.register_udf(ScalarUDF::new_from_impl(noise_twin::GediNoiseTwin::shot()));
    ctx.register_udf(ScalarUDF::new_from_impl(noise_twin::GediNoiseTwin::link_margin()));
    ctx.register_udtf("gedi_simulate", Arc::new(simulate::GediSimulate::new(ds.clone())));
}

/// Register the Parquet folder `dir` as table `name`.
pub async fn register_table(ctx: &SessionContext, name: &str, dir: &Path) -> Result<()> {
    let options = ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    let url = format!("{}/", dir.canonicalize().map_err(|e| Error::file(dir, e))?.display());
    ctx.register_listing_table(name, &url, options, None, None)
        .await
        .map_err(|e| Error::table(dir, e))
}
