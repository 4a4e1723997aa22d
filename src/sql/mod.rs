//! The DataFusion session: the dataset's tables registered by name, and gedisim's SQL functions
//! (thin wrappers over the kernels).

pub mod args;
pub mod l2a;
pub mod link_margin_twin;
pub mod noise_twin;
pub mod rh;
pub mod simulate;
pub mod twin;

use std::path::Path;

use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::ListingOptions;
use datafusion::logical_expr::{DocSection, ScalarUDF};
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
        if name == dataset::tables::REPORT
            || !dir.is_dir()
            || dataset::table_files(&dir).map(|f| f.is_empty()).unwrap_or(true)
        {
            continue;
        }
        register_table(&ctx, &name, &dir).await?;
    }
    Ok(ctx)
}

/// The section gedisim's functions are documented under (`documentation()`, `information_schema`).
pub const DOC_SECTION: DocSection =
    DocSection { include: true, label: "gedisim", description: Some("GEDI waveform functions") };

/// gedisim's scalar functions, one file each: `gedi_rh` ([`rh`]), `gedi_l2a` ([`l2a`]),
/// `gedi_noise_twin` ([`noise_twin`]), `gedi_link_margin_twin` ([`link_margin_twin`]).
pub fn scalar_functions() -> Vec<ScalarUDF> {
    vec![
        ScalarUDF::new_from_impl(rh::GediRh::new()),
        ScalarUDF::new_from_impl(l2a::GediL2a::new()),
        ScalarUDF::new_from_impl(twin::GediTwin::new(&noise_twin::NOISE_TWIN)),
        ScalarUDF::new_from_impl(twin::GediTwin::new(&link_margin_twin::LINK_MARGIN_TWIN)),
    ]
}

/// Register gedisim's SQL functions: [`scalar_functions`] and the table function
/// `gedi_simulate([profile])` ([`simulate`]), which reads `ds`.
pub fn register_functions(ctx: &SessionContext, ds: &Dataset) {
    for f in scalar_functions() {
        ctx.register_udf(f);
    }
    ctx.register_udtf("gedi_simulate", Arc::new(simulate::GediSimulate::new(ds.clone())));
}

/// Register the Parquet folder `dir` as table `name`.
pub async fn register_table(ctx: &SessionContext, name: &str, dir: &Path) -> Result<()> {
    let options = ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    let url = format!("{}/", dir.canonicalize().map_err(|e| Error::file(dir, e))?.display());
    ctx.register_listing_table(name, &url, options, None, None).await.map_err(|e| Error::table(dir, e))
}
