//! The calibration inputs, typed and validated: the robot's nominal model
//! (robot.json), the measuring rig (rig.json), recorded poses (poses.csv) and
//! compensation targets (targets.csv), and the compensated targets written
//! back (compensated.csv). Formats: `DATA_FORMAT.md` v1.

pub mod compensated;
pub mod dataset;
pub mod rig;
pub mod robot;
pub mod targets;
pub mod urdf;

pub use compensated::{Compensated, CompensationStatus};
pub use dataset::{Dataset, Measurement, PoseRecord, Split};
pub use rig::{BasePose, Rig, SensorSpec};
pub use robot::{Convention, JointSpec, LinkMass, Robot};
pub use targets::{Target, TargetKind, target_payloads, target_splits, targets_from_csv};

use crate::error::{Error, Result};

/// Parse a robot.json or rig.json text (`file`) strictly: a key the format
/// does not have is an error naming it, where it is (`joints[2]`), and the
/// nearest key the format has (a typo such as `conventon` is never silently
/// ignored).
pub(crate) fn parse_strict<T: serde::de::DeserializeOwned>(file: &str, text: &str) -> Result<T> {
    // serde reads a struct from an array too (`[]` as every default):
    // these files are objects.
    if !text
        .trim_start_matches('\u{feff}')
        .trim_start()
        .starts_with('{')
    {
        return Err(Error::field(
            file,
            "a JSON object ({ ... }) with the keys DATA_FORMAT.md lists",
        ));
    }
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let message = with_key_hint(&e.into_inner().to_string());
        match path.as_str() {
            "." | "" => Error::field(file, message),
            // The path of the value at fault (an unknown key: the key).
            _ => Error::field(format!("{file}: {path}"), message),
        }
    })
}

/// serde's "unknown field `x`, expected one of `a`, `b`" (or "expected
/// `a`") as "unknown key `x` (did you mean `a`?); the keys here are a, b",
/// the nearest known key by edit distance; any other message unchanged.
pub fn with_key_hint(message: &str) -> String {
    let Some(rest) = message.strip_prefix("unknown field `") else {
        return message.to_string();
    };
    let Some(end) = rest.find('`') else {
        return message.to_string();
    };
    let key = &rest[..end];
    let after = &rest[end + 1..];
    // The known keys are the back-quoted words after "expected".
    let expected = after.split_once("expected").map_or("", |(_, e)| e);
    let tail_at = expected.rfind('`').map_or(0, |i| i + 1);
    let (list, tail) = expected.split_at(tail_at);
    let known: Vec<&str> = list.split('`').skip(1).step_by(2).collect();
    let nearest = known
        .iter()
        .map(|k| (edit_distance(key, k), *k))
        .filter(|(d, k)| *d <= (k.len().max(key.len()) / 2).max(2))
        .min();
    let hint = nearest.map_or(String::new(), |(_, k)| format!(" (did you mean `{k}`?)"));
    let keys = if known.is_empty() {
        "none".to_string()
    } else {
        known.join(", ")
    };
    format!("unknown key `{key}`{hint}; the keys here are {keys}{tail}")
}

/// Levenshtein distance between two keys (bytes; keys are ASCII).
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, &ca) in a.iter().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, &cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != cb))
                .min(prev[j + 1] + 1)
                .min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

/// Reject NaN and infinities with an error naming the field.
pub(crate) fn finite(field: &str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::field(
            field,
            format!("must be a finite number, got {v}"),
        ))
    }
}

/// Largest |angle| (in a file's `_deg` numbers) that radians take: 2π,
/// with a little room for rounding.
pub const RADIANS_BOUND: f64 = std::f64::consts::TAU + 1e-6;

/// Heaviest payload (kg) recorded or compensated for: beyond any serial
/// arm's rating (the largest carry about 2,300 kg).
pub const MAX_PAYLOAD_KG: f64 = 5000.0;

/// A number as an error message shows it: plain, or in exponent form when
/// very large or very small (1e300 is not 301 digits).
pub(crate) fn shown(v: f64) -> String {
    if v != 0.0 && !(1e-6..1e9).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Largest |length| (mm) accepted in robot.json and rig.json: 100 m, far
/// beyond any arm or rig; past it a value is a typo or a unit error, and
/// the kinematics would lose all precision.
pub const MAX_LENGTH_MM: f64 = 1e5;

/// A finite length within ±[`MAX_LENGTH_MM`], with an error naming the field.
pub(crate) fn length(field: &str, v: f64) -> Result<f64> {
    finite(field, v)?;
    if v.abs() > MAX_LENGTH_MM {
        return Err(Error::field(
            field,
            format!(
                "{} mm: more than 100 m, not a length of a robot or a rig",
                shown(v)
            ),
        ));
    }
    Ok(v)
}

/// A CSV reader that trims cells and tolerates ragged rows (so a short row
/// is reported by [`csv_record`] with its row number), with its header.
///
/// A header that is one column holding `;` or a tab (a file exported with
/// another separator, e.g. by a spreadsheet set to a European locale) is
/// refused with a message saying the file must be comma-separated.
pub(crate) fn csv_with_header<R: std::io::Read>(
    input: R,
) -> Result<(csv::Reader<R>, csv::StringRecord)> {
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .flexible(true)
        .from_reader(input);
    let headers = match rdr.headers() {
        Ok(h) => h.clone(),
        Err(e) => {
            let message = match e.kind() {
                csv::ErrorKind::Utf8 { .. } => {
                    "the header is not UTF-8 text: save the file as UTF-8 CSV".to_string()
                }
                _ => format!("unreadable CSV header: {e}"),
            };
            return Err(Error::field("header", message));
        }
    };
    // The same column twice: which one holds the data is anyone's guess.
    for (i, h) in headers.iter().enumerate() {
        if !h.is_empty() && headers.iter().take(i).any(|g| g == h) {
            return Err(Error::field(h, "column appears twice"));
        }
    }
    if headers.len() == 1 {
        let only = &headers[0];
        let sep = [(';', "';'"), ('\t', "tab")]
            .into_iter()
            .find(|(c, _)| only.contains(*c));
        if let Some((_, sep)) = sep {
            return Err(Error::field(
                "header",
                format!(
                    "the file must be comma-separated (with '.' as the decimal point): its header reads as one column holding {sep} separators ('{}')",
                    abbreviate(&only.replace('\t', "\\t"), 60)
                ),
            ));
        }
    }
    Ok((rdr, headers))
}

/// `s` cut to at most `max` characters, with an ellipsis when cut.
fn abbreviate(s: &str, max: usize) -> String {
    match s.char_indices().nth(max) {
        Some((i, _)) => format!("{}...", &s[..i]),
        None => s.to_string(),
    }
}

/// A record of a table read by [`csv_with_header`], checked: readable
/// (UTF-8) and exactly as many cells as the header has columns. `row` is
/// 1-based, header excluded (blank lines are skipped and a quoted cell may
/// span lines, so it is not the line of the file).
pub(crate) fn csv_record(
    row: usize,
    rec: csv::Result<csv::StringRecord>,
    headers: &csv::StringRecord,
) -> Result<csv::StringRecord> {
    let rec = match rec {
        Ok(r) => r,
        Err(e) => {
            return Err(match e.kind() {
                csv::ErrorKind::Utf8 { err, .. } => {
                    let message = "not UTF-8 text: save the file as UTF-8 CSV";
                    match headers.get(err.field()) {
                        Some(col) => Error::cell(row, col, message),
                        None => Error::row(row, message),
                    }
                }
                _ => Error::row(row, format!("unreadable CSV: {e}")),
            });
        }
    };
    if rec.len() != headers.len() {
        let cells = match rec.len() {
            1 if rec[0].is_empty() => "an empty row".to_string(),
            1 => "1 cell".to_string(),
            n => format!("{n} cells"),
        };
        return Err(Error::row(
            row,
            format!("{cells} where the header has {} columns", headers.len()),
        ));
    }
    // A control character is no text anyone typed in a cell (a NUL,
    // which PostgreSQL refuses in text, or a line break or tab inside
    // quotes, which forges rows in logs and exports): refused here, naming
    // the cell, for every file read.
    if let Some(i) = rec.iter().position(|c| c.chars().any(char::is_control)) {
        return Err(Error::cell(
            row,
            headers.get(i).unwrap_or("?"),
            "contains a control character (a NUL, a line break, a tab...)",
        ));
    }
    Ok(rec)
}

/// A finite number from a cell, or an error naming the row and column.
pub(crate) fn parse_cell(row: usize, col: &str, raw: &str) -> Result<f64> {
    let v: f64 = raw
        .trim()
        .parse()
        .map_err(|_| Error::cell(row, col, format!("'{raw}' is not a number")))?;
    if !v.is_finite() {
        return Err(Error::cell(
            row,
            col,
            format!("'{raw}' is not a finite number"),
        ));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_key_names_the_nearest_known_one() {
        let m = with_key_hint(
            "unknown field `conventon`, expected one of `name`, `convention`, `joints` at line 1 column 12",
        );
        assert_eq!(
            m,
            "unknown key `conventon` (did you mean `convention`?); the keys here are name, convention, joints at line 1 column 12"
        );
        // Nothing near: no guess.
        let m = with_key_hint("unknown field `zzzzzzzz`, expected `a_mm` or `d_mm`");
        assert!(!m.contains("did you mean"), "{m}");
        assert!(m.contains("a_mm, d_mm"), "{m}");
        // Other messages pass through.
        assert_eq!(
            with_key_hint("missing field `joints`"),
            "missing field `joints`"
        );
        assert_eq!(edit_distance("r_m", "r_mm"), 1);
    }
}
