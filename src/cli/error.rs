//! The CLI layer's one error type: what went wrong and with which file or
//! option. `main` prints it after `error: ` and exits with status 1.

use std::path::PathBuf;

/// The CLI layer's error: what went wrong and with which file.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The core refused the input of a file or failed on it.
    #[error("{path}: {source}")]
    Core {
        /// The file being processed.
        path: PathBuf,
        /// The cause.
        source: crate::Error,
    },
    /// A JSON file that does not parse as what it should be.
    #[error("{path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: serde_json::Error,
    },
    /// The core failed on input that is not one file (a simulation spec
    /// and the files it names, a sweep).
    #[error("{0}")]
    Engine(#[from] crate::Error),
    /// An option's value is out of its range.
    #[error("{0}")]
    Usage(String),
    /// A result could not be written as JSON.
    #[error("{0}")]
    Json(serde_json::Error),
    /// The service could not start, or stopped with an error.
    #[error("{0}")]
    Service(Box<dyn std::error::Error + Send + Sync>),
    /// Anything else the core reports as text.
    #[error("{0}")]
    Other(String),
}
