//! The history export on SQLite, read straight from SQLite's C interface.
//!
//! Through sqlx a row costs far more than SQLite's own work: every value is
//! copied (`sqlite3_value_dup`, an allocation and the allocator's mutex)
//! and freed, type-checked and looked up by name, and every row crosses a
//! channel from the connection's thread to the runtime's, which on a busy
//! machine means a thread wake-up per row. For a site's 5,000-row CSV that
//! was most of the request's 29-33 ms of CPU; SQLite's own stepping and
//! sorting were 14 % (BENCHMARKS.md, "Fleet scale"). Here the export's
//! statement runs on a blocking thread that holds the pooled connection's
//! handle (`SqliteConnection::lock_handle`, sqlx's door for this), reads
//! each row's columns in place, borrowed, into the export's sink
//! ([`ExportSink`]: for a CSV, the CSV's bytes are written here, not on the
//! runtime's thread) and hands the sink's pieces over as they are ready.
//!
//! The statement is sqlx's export query text (`calibration_export_sql`),
//! with the same bound values; only the reading differs. The store suite
//! compares every column of every exported row with the paged list's
//! (sqlx's decoding) on both backends.

use std::ffi::{CStr, CString, c_int};
use std::ptr::NonNull;

use libsqlite3_sys as ffi;

use super::{CalibrationRow, ExportSink, Result, StoreError};

/// A bound value of the export's statement, owned (the statement runs on
/// another thread than the one that built the filter).
pub(super) enum Arg {
    Int(i64),
    Text(String),
    Real(f64),
}

fn error(what: &str, detail: impl std::fmt::Display) -> StoreError {
    StoreError::Db(sqlx::Error::Protocol(format!(
        "sqlite export: {what}: {detail}"
    )))
}

/// A prepared statement, finalized when dropped (before the connection's
/// lock is given back).
struct Statement {
    db: *mut ffi::sqlite3,
    stmt: *mut ffi::sqlite3_stmt,
}

impl Drop for Statement {
    fn drop(&mut self) {
        // SAFETY: `stmt` came from `sqlite3_prepare_v2` on `db` and is
        // finalized once, here.
        unsafe {
            ffi::sqlite3_finalize(self.stmt);
        }
    }
}

impl Statement {
    /// The connection's last error message, with the result code.
    fn fail(&self, what: &str, code: c_int) -> StoreError {
        // SAFETY: `db` is the open connection this thread holds; the message
        // is copied before any other call on it.
        let msg = unsafe { CStr::from_ptr(ffi::sqlite3_errmsg(self.db)) }
            .to_string_lossy()
            .into_owned();
        error(what, format!("{msg} (code {code})"))
    }

    fn prepare(db: NonNull<ffi::sqlite3>, sql: &str) -> Result<Statement> {
        let text = CString::new(sql).map_err(|e| error("query text", e))?;
        let mut stmt = std::ptr::null_mut();
        // SAFETY: `db` is an open connection that this thread holds the
        // lock of; `text` is NUL-terminated and outlives the call.
        let code = unsafe {
            ffi::sqlite3_prepare_v2(
                db.as_ptr(),
                text.as_ptr(),
                -1,
                &mut stmt,
                std::ptr::null_mut(),
            )
        };
        let s = Statement {
            db: db.as_ptr(),
            stmt,
        };
        if code != ffi::SQLITE_OK || stmt.is_null() {
            // Finalizing a null statement is a no-op.
            return Err(s.fail("prepare", code));
        }
        Ok(s)
    }

    /// Bind `$1`, `$2`... (the names sqlx's query text uses) to `args`.
    fn bind(&mut self, args: &[Arg]) -> Result<()> {
        for (i, a) in args.iter().enumerate() {
            let name = CString::new(format!("${}", i + 1)).expect("no NUL in a parameter name");
            // SAFETY: `stmt` is a live statement; `name` is NUL-terminated.
            let index = unsafe { ffi::sqlite3_bind_parameter_index(self.stmt, name.as_ptr()) };
            if index == 0 {
                return Err(error("bind", format!("no parameter ${}", i + 1)));
            }
            // SAFETY: as above; SQLITE_TRANSIENT makes SQLite copy the text
            // before the call returns.
            let code = unsafe {
                match a {
                    Arg::Int(v) => ffi::sqlite3_bind_int64(self.stmt, index, *v),
                    Arg::Real(v) => ffi::sqlite3_bind_double(self.stmt, index, *v),
                    Arg::Text(v) => ffi::sqlite3_bind_text(
                        self.stmt,
                        index,
                        v.as_ptr().cast(),
                        c_int::try_from(v.len()).map_err(|e| error("bind", e))?,
                        ffi::SQLITE_TRANSIENT(),
                    ),
                }
            };
            if code != ffi::SQLITE_OK {
                return Err(self.fail("bind", code));
            }
        }
        Ok(())
    }

    /// The next row, if any.
    fn step(&mut self) -> Result<bool> {
        // SAFETY: `stmt` is a live statement of the connection this thread
        // holds.
        match unsafe { ffi::sqlite3_step(self.stmt) } {
            ffi::SQLITE_ROW => Ok(true),
            ffi::SQLITE_DONE => Ok(false),
            code => Err(self.fail("step", code)),
        }
    }

    fn is_null(&self, col: c_int) -> bool {
        // SAFETY: after a step that returned a row, `col` < column count.
        unsafe { ffi::sqlite3_column_type(self.stmt, col) == ffi::SQLITE_NULL }
    }

    fn int(&self, col: c_int) -> i64 {
        // SAFETY: as `is_null`.
        unsafe { ffi::sqlite3_column_int64(self.stmt, col) }
    }

    fn real(&self, col: c_int) -> Option<f64> {
        // SAFETY: as `is_null`.
        (!self.is_null(col)).then(|| unsafe { ffi::sqlite3_column_double(self.stmt, col) })
    }

    /// A text column, borrowed from SQLite: valid until the next step of
    /// the statement (which takes `&mut self`, so the borrow checker keeps
    /// the text from outliving it). No other call is made on the column
    /// while the text is held (SQLite frees a column's text when it
    /// converts the value to another type).
    fn text(&self, col: c_int) -> Result<&str> {
        // SAFETY: as `is_null`. The length is asked after the text (the
        // order SQLite's documentation gives for a conversion-free read);
        // the pointer stays valid until the statement is stepped, reset or
        // finalized, none of which can happen while `&self` is borrowed.
        let bytes = unsafe {
            let p = ffi::sqlite3_column_text(self.stmt, col);
            let n = ffi::sqlite3_column_bytes(self.stmt, col);
            if p.is_null() {
                // Out of memory, or NULL in a column that may not hold it.
                return Err(error("text column", format!("column {col} has no text")));
            }
            if n <= 0 {
                &[][..]
            } else {
                std::slice::from_raw_parts(p, n as usize)
            }
        };
        std::str::from_utf8(bytes).map_err(|e| error("text column", e))
    }

    fn opt_text(&self, col: c_int) -> Result<Option<&str>> {
        if self.is_null(col) {
            Ok(None)
        } else {
            self.text(col).map(Some)
        }
    }

    /// The current row, in `calibration_select!`'s column order, borrowed.
    fn calibration(&self) -> Result<CalibrationRow<'_>> {
        Ok(CalibrationRow {
            id: self.int(0),
            robot_id: self.int(1),
            serial_number: self.text(2)?,
            model_id: self.int(3),
            site: self.opt_text(4)?,
            line: self.opt_text(5)?,
            cell: self.opt_text(6)?,
            session_id: self.int(7),
            job_id: self.int(8),
            version: self.int(9),
            method: self.text(10)?,
            n_poses: self.int(11),
            n_test: self.int(12),
            test_rms_before_mm: self.real(13),
            test_rms_after_mm: self.real(14),
            train_rms_after_mm: self.real(15),
            effects: self.text(16)?,
            active: self.int(17) != 0,
            created_at: self.text(18)?,
        })
    }
}

/// Run the export's `sql` with `args` on the connection `db` (whose lock the
/// calling thread holds), write its rows into `sink` as they are stepped to,
/// oldest first, and send the sink's pieces to `out` as they are ready and
/// what is left at the end; a failure is sent as the last item. Returns
/// when every row is written, or early when the receiver is gone (the
/// client went away). Blocking: run it on a blocking thread.
pub(super) fn read_calibrations<S: ExportSink>(
    db: NonNull<ffi::sqlite3>,
    sql: &str,
    args: &[Arg],
    mut sink: S,
    out: &tokio::sync::mpsc::Sender<Result<S::Piece>>,
) {
    let mut run = || -> Result<()> {
        let mut stmt = Statement::prepare(db, sql)?;
        // SAFETY: a live statement; the count is fixed once prepared.
        let columns = unsafe { ffi::sqlite3_column_count(stmt.stmt) };
        if columns != 19 {
            return Err(error("columns", format!("{columns}, not the 19 expected")));
        }
        stmt.bind(args)?;
        while stmt.step()? {
            sink.row(&stmt.calibration()?);
            if let Some(piece) = sink.ready()
                && out.blocking_send(Ok(piece)).is_err()
            {
                return Ok(());
            }
        }
        if let Some(piece) = sink.finish() {
            let _ = out.blocking_send(Ok(piece));
        }
        Ok(())
    };
    if let Err(e) = run() {
        let _ = out.blocking_send(Err(e));
    }
}
