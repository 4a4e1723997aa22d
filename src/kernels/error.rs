//! The kernels' one error of their own: a value they cannot work with (a pulse width, an EPSG code,
//! a raster cell), which is the caller's usage error. `gedisim::Error` takes it in through `?`
//! (`Error::Usage`); the kernels' other errors are per kernel (`TwinError`, `ProfileError`, …).

/// A value a kernel cannot work with, said in one line.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    #[error("{0}")]
    Usage(String),
}

pub type Result<T> = std::result::Result<T, Error>;
