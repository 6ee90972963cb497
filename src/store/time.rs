//! Timestamps as the store keeps them: RFC 3339 UTC text with milliseconds
//! (`2026-11-23T19:47:49.123Z`), which sorts like time on every backend.

use std::time::{SystemTime, UNIX_EPOCH};

/// Milliseconds since the Unix epoch, now.
pub fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Now, as stored.
pub fn now_rfc3339() -> String {
    ms_to_rfc3339(now_ms())
}

/// Days since 1970-01-01 to (year, month, day), proleptic Gregorian
/// (H. Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

/// Epoch milliseconds to stored text.
pub fn ms_to_rfc3339(ms: i64) -> String {
    let days = ms.div_euclid(86_400_000);
    let rem = ms.rem_euclid(86_400_000);
    let (y, m, d) = civil_from_days(days);
    let (h, mi, s, milli) = (
        rem / 3_600_000,
        (rem / 60_000) % 60,
        (rem / 1000) % 60,
        rem % 1000,
    );
    format!("{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{milli:03}Z")
}

/// Days in a month of the proleptic Gregorian calendar.
fn days_in_month(year: u32, month: u32) -> u32 {
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    match month {
        2 if leap => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Normalise a date-range bound given by a client: `YYYY-MM-DD` (the start
/// of that day, or its last millisecond when `end_of_day`) or
/// `YYYY-MM-DDTHH:MM:SS[.fff]Z`. `None` if it is neither.
pub fn normalize_bound(s: &str, end_of_day: bool) -> Option<String> {
    let b = s.as_bytes();
    let digits = |r: std::ops::Range<usize>| b[r].iter().all(u8::is_ascii_digit);
    if b.len() < 10
        || !digits(0..4)
        || b[4] != b'-'
        || !digits(5..7)
        || b[7] != b'-'
        || !digits(8..10)
    {
        return None;
    }
    let year: u32 = s[0..4].parse().ok()?;
    let month: u32 = s[5..7].parse().ok()?;
    let day: u32 = s[8..10].parse().ok()?;
    if !(1..=12).contains(&month) || day < 1 || day > days_in_month(year, month) {
        return None;
    }
    let date = &s[..10];
    if b.len() == 10 {
        return Some(if end_of_day {
            format!("{date}T23:59:59.999Z")
        } else {
            format!("{date}T00:00:00.000Z")
        });
    }
    // Full timestamp: THH:MM:SS, optional fraction, Z.
    if b.len() < 20
        || b[10] != b'T'
        || !digits(11..13)
        || b[13] != b':'
        || !digits(14..16)
        || b[16] != b':'
        || !digits(17..19)
    {
        return None;
    }
    let field = |r: std::ops::Range<usize>| s[r].parse::<u32>().unwrap_or(u32::MAX);
    if field(11..13) > 23 || field(14..16) > 59 || field(17..19) > 59 {
        return None;
    }
    let rest = &s[19..];
    let frac = if let Some(f) = rest.strip_prefix('.') {
        let f = f.strip_suffix('Z')?;
        if f.is_empty() || !f.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        let mut f = f.to_string();
        f.truncate(3);
        while f.len() < 3 {
            f.push('0');
        }
        f
    } else if rest == "Z" {
        "000".to_string()
    } else {
        return None;
    };
    Some(format!("{}.{frac}Z", &s[..19]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_known_instants() {
        assert_eq!(ms_to_rfc3339(0), "1970-01-01T00:00:00.000Z");
        // 2000-02-29T12:34:56.789Z
        assert_eq!(ms_to_rfc3339(951_827_696_789), "2000-02-29T12:34:56.789Z");
    }

    #[test]
    fn bounds() {
        assert_eq!(
            normalize_bound("2026-01-02", false).unwrap(),
            "2026-01-02T00:00:00.000Z"
        );
        assert_eq!(
            normalize_bound("2026-01-02", true).unwrap(),
            "2026-01-02T23:59:59.999Z"
        );
        assert_eq!(
            normalize_bound("2026-01-02T03:04:05Z", false).unwrap(),
            "2026-01-02T03:04:05.000Z"
        );
        assert_eq!(
            normalize_bound("2026-01-02T03:04:05.5Z", false).unwrap(),
            "2026-01-02T03:04:05.500Z"
        );
        assert!(normalize_bound("yesterday", false).is_none());
        assert!(normalize_bound("2026-13-02", false).is_none());
        // Days that do not exist, and times past the clock.
        assert!(normalize_bound("2026-02-29", false).is_none());
        assert!(normalize_bound("2026-04-31", false).is_none());
        assert!(normalize_bound("2024-02-29", false).is_some());
        assert!(normalize_bound("2000-02-29", false).is_some());
        assert!(normalize_bound("1900-02-29", false).is_none());
        assert!(normalize_bound("2026-01-02T24:00:00Z", false).is_none());
        assert!(normalize_bound("2026-01-02T23:60:00Z", false).is_none());
        assert!(normalize_bound("2026-01-02T23:59:60Z", false).is_none());
        assert!(normalize_bound("2026-01-02T03:04:05+01:00", false).is_none());
    }
}
