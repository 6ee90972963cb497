//! The numerical core's one error type.

use thiserror::Error;

/// Result alias for the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything the core can refuse. Input errors name the field and, for
/// tabular input, the 1-based data row, so a caller can point at the cell.
#[derive(Debug, Error)]
pub enum Error {
    /// A value in an input file or request is invalid.
    #[error("{}{field}: {message}", row.map(|r| format!("row {r}, ")).unwrap_or_default())]
    Input {
        /// Column or JSON field name.
        field: String,
        /// 1-based data row (header excluded) for tabular input.
        row: Option<usize>,
        /// What is wrong, for a human.
        message: String,
    },
    /// The data cannot support the requested computation (too few poses,
    /// no measurements...).
    #[error("insufficient data: {0}")]
    InsufficientData(String),
    /// A numerical procedure failed to produce a usable answer.
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// The work was cancelled by the caller.
    #[error("cancelled")]
    Cancelled,
}

impl Error {
    /// An input error on a named field without a row.
    pub fn field(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Input {
            field: field.into(),
            row: None,
            message: message.into(),
        }
    }

    /// An input error on a cell of a table.
    pub fn cell(row: usize, field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Input {
            field: field.into(),
            row: Some(row),
            message: message.into(),
        }
    }
}
