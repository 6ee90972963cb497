//! The numerical core's one error type.

use thiserror::Error;

/// Result alias for the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything the core can refuse. Input errors name the field and, for
/// tabular input, the 1-based data row, so a caller can point at the cell.
///
/// Rows are counted from the first row after the header (row 1), as the
/// service's `row` is; the message says so (`row 5 after the header, column
/// q2_deg: ...`, or for a whole row `row 5 after the header: ...`).
#[derive(Debug, Error)]
pub enum Error {
    /// A value in an input file or request is invalid.
    #[error("{}", input_message(field.as_deref(), *row, message))]
    Input {
        /// Column or JSON field name; `None` when the whole row is at fault
        /// (a short or long row, unreadable text).
        field: Option<String>,
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

/// The text of [`Error::Input`]: where, then what.
fn input_message(field: Option<&str>, row: Option<usize>, message: &str) -> String {
    match (row, field) {
        (Some(r), Some(f)) => format!("row {r} after the header, column {f}: {message}"),
        (Some(r), None) => format!("row {r} after the header: {message}"),
        (None, Some(f)) => format!("{f}: {message}"),
        (None, None) => message.to_string(),
    }
}

impl Error {
    /// An input error on a named field without a row.
    pub fn field(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Input {
            field: Some(field.into()),
            row: None,
            message: message.into(),
        }
    }

    /// An input error on a cell of a table (`row` 1-based, header excluded).
    pub fn cell(row: usize, field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Input {
            field: Some(field.into()),
            row: Some(row),
            message: message.into(),
        }
    }

    /// An input error on a whole row of a table (`row` 1-based, header
    /// excluded), with no one column at fault.
    pub fn row(row: usize, message: impl Into<String>) -> Self {
        Error::Input {
            field: None,
            row: Some(row),
            message: message.into(),
        }
    }
}
