//! Object stores by URL, built in one place: `s3://bucket/…` (credentials, region and endpoint from the
//! `AWS_*` environment) and `http(s)://host/…` (range requests; listing a folder needs a WebDAV
//! server). Remote tiles ([`super::source`]) and datasets by URL (SQL sessions, cluster nodes:
//! [`Stores`], docs/scale.md) read through them.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use datafusion::execution::object_store::{DefaultObjectStoreRegistry, ObjectStoreRegistry};
use object_store::ObjectStore;
use url::Url;

/// Whether `url`'s scheme is one [`open`] serves.
pub fn is_remote_scheme(scheme: &str) -> bool {
    matches!(scheme, "http" | "https" | "s3")
}

/// The store holding `url` (its bucket, or its host).
pub fn open(url: &Url) -> std::result::Result<Arc<dyn ObjectStore>, String> {
    // A few quick retries: a wrong address ends in seconds, not after object_store's default of
    // 10 retries over 3 minutes.
    let retry = object_store::RetryConfig {
        max_retries: 3,
        retry_timeout: std::time::Duration::from_secs(30),
        backoff: Default::default(),
    };
    let built: std::result::Result<Arc<dyn ObjectStore>, object_store::Error> = match url.scheme() {
        // A plain `http://` URL, written as such, is allowed (object_store refuses it by default).
        "http" | "https" => object_store::http::HttpBuilder::new()
            .with_url(&url[..url::Position::BeforePath])
            .with_client_options(
                object_store::ClientOptions::new()
                    .with_allow_http(url.scheme() == "http")
                    .with_connect_timeout(std::time::Duration::from_secs(10)),
            )
            .with_retry(retry)
            .build()
            .map(|s| Arc::new(s) as Arc<dyn ObjectStore>),
        // Credentials, region, endpoint and client settings from the AWS_* environment; an endpoint
        // written as `http://…` is allowed as such.
        "s3" => {
            let http_endpoint = ["AWS_ENDPOINT", "AWS_ENDPOINT_URL"]
                .iter()
                .any(|v| std::env::var(v).is_ok_and(|e| e.starts_with("http://")));
            let mut builder = object_store::aws::AmazonS3Builder::from_env().with_url(url.as_str()).with_retry(retry);
            if http_endpoint {
                builder = builder.with_allow_http(true);
            }
            builder.build().map(|s| Arc::new(s) as Arc<dyn ObjectStore>)
        }
        other => return Err(format!("{other}:// is not http://, https:// or s3://")),
    };
    built.map_err(|e| crate::error::one_line(&e.to_string()))
}

/// DataFusion's object store registry, which also opens `s3://` and `http(s)://` stores the first time
/// a URL names them ([`open`]): what every session and cluster node of gedisim reads through.
#[derive(Debug, Default)]
pub struct Stores {
    local: DefaultObjectStoreRegistry,
    /// Stores opened, by scheme and authority (bucket or host).
    opened: Mutex<HashMap<String, Arc<dyn ObjectStore>>>,
}

fn key(url: &Url) -> String {
    format!("{}://{}", url.scheme(), &url[url::Position::BeforeHost..url::Position::AfterPort])
}

impl ObjectStoreRegistry for Stores {
    fn register_store(&self, url: &Url, store: Arc<dyn ObjectStore>) -> Option<Arc<dyn ObjectStore>> {
        if is_remote_scheme(url.scheme()) {
            self.opened.lock().expect("object stores").insert(key(url), store)
        } else {
            self.local.register_store(url, store)
        }
    }

    fn deregister_store(&self, url: &Url) -> datafusion::common::Result<Arc<dyn ObjectStore>> {
        if is_remote_scheme(url.scheme()) {
            if let Some(s) = self.opened.lock().expect("object stores").remove(&key(url)) {
                return Ok(s);
            }
        }
        self.local.deregister_store(url)
    }

    fn get_store(&self, url: &Url) -> datafusion::common::Result<Arc<dyn ObjectStore>> {
        if !is_remote_scheme(url.scheme()) {
            return self.local.get_store(url);
        }
        let mut opened = self.opened.lock().expect("object stores");
        if let Some(s) = opened.get(&key(url)) {
            return Ok(s.clone());
        }
        let store = open(url).map_err(|e| datafusion::error::DataFusionError::Execution(format!("{url}: {e}")))?;
        opened.insert(key(url), store.clone());
        Ok(store)
    }
}
