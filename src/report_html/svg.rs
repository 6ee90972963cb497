//! Minimal SVG plots (scatter and grouped bars) as strings, no JavaScript.

use std::fmt::Write;

/// One series of a scatter plot.
pub struct Series<'a> {
    /// Legend label.
    pub label: &'a str,
    /// CSS colour.
    pub color: &'a str,
    /// Points (x, y).
    pub points: Vec<(f64, f64)>,
    /// Dot diameter (px); 0 for the default (smaller above 3000 points).
    pub dot: f64,
}

/// Escape text for HTML and SVG.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// "Nice" tick positions covering [lo, hi].
fn ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if !(hi > lo) || !lo.is_finite() || !hi.is_finite() {
        return vec![lo];
    }
    let raw = (hi - lo) / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut out = Vec::new();
    while t <= hi + step * 1e-9 {
        out.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        t += step;
    }
    out
}

fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1000.0..1e6).contains(&a) {
        format!("{v:.0}")
    } else if a >= 1e6 || a < 0.001 {
        format!("{v:.2e}")
    } else {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    }
}

fn range(vals: impl Iterator<Item = f64>, zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    if hi - lo < 1e-12 {
        let d = if lo.abs() > 0.0 { lo.abs() * 0.1 } else { 1.0 };
        return (lo - d, hi + d);
    }
    let pad = (hi - lo) * 0.04;
    (if zero && lo == 0.0 { 0.0 } else { lo - pad }, hi + pad)
}

/// How values map to a plot's height.
#[derive(Clone, Copy, Debug, PartialEq)]
enum YAxis {
    /// From `.0` at the bottom to `.1` at the top.
    Linear(f64, f64),
    /// Powers of ten from `10^.0` at the bottom to `10^.1` at the top.
    Log10(i32, i32),
}

impl YAxis {
    /// Bars of positive values spanning more than two decades (before
    /// calibration beside after, typically 100-300 times smaller) go on a
    /// log axis, so every bar can be read; otherwise a linear one from 0.
    fn for_bars(values: impl Iterator<Item = f64> + Clone) -> YAxis {
        let finite = values.filter(|v| v.is_finite());
        let max = finite.clone().fold(f64::NEG_INFINITY, f64::max);
        let min_pos = finite
            .clone()
            .filter(|v| *v > 0.0)
            .fold(f64::INFINITY, f64::min);
        let any_negative = finite.clone().any(|v| v < 0.0);
        if !any_negative && min_pos.is_finite() && max / min_pos > 100.0 {
            // At least 0.3 decade of the smallest bar shows, and at most
            // six decades are drawn: a bar below them says its value.
            let hi = max.log10().ceil() as i32;
            let lo = ((min_pos.log10() - 0.3).floor() as i32).clamp(hi - 6, hi - 1);
            return YAxis::Log10(lo, hi);
        }
        let (lo, hi) = range(finite, true);
        YAxis::Linear(0.0f64.min(lo), hi)
    }

    /// Height fraction (0 bottom, 1 top) of `v`, clamped to the axis.
    fn frac(&self, v: f64) -> f64 {
        let f = match *self {
            YAxis::Linear(lo, hi) => (v - lo) / (hi - lo),
            YAxis::Log10(lo, hi) if v > 0.0 => (v.log10() - lo as f64) / (hi - lo) as f64,
            YAxis::Log10(..) => 0.0,
        };
        f.clamp(0.0, 1.0)
    }

    fn ticks(&self) -> Vec<f64> {
        match *self {
            YAxis::Linear(lo, hi) => ticks(lo, hi, 5),
            YAxis::Log10(lo, hi) => (lo..=hi).map(|k| 10f64.powi(k)).collect(),
        }
    }
}

const W: f64 = 560.0;
const H: f64 = 300.0;
const L: f64 = 62.0;
const R: f64 = 12.0;
/// Top margin: the title, then the legend's row above the plot, where it
/// never hides a bar or a point.
const T: f64 = 40.0;
const B: f64 = 42.0;

fn frame(
    out: &mut String,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    x: (f64, f64),
    y: YAxis,
    xticks: bool,
) {
    let pw = W - L - R;
    let ph = H - T - B;
    let _ = write!(
        out,
        r##"<svg class="plot" viewBox="0 0 {W} {H}" width="{W}" height="{H}" role="img" aria-label="{t}"><title>{t}</title><rect x="{L}" y="{T}" width="{pw}" height="{ph}" fill="#fff" stroke="#999"/><text x="{cx}" y="16" text-anchor="middle" font-size="13" font-weight="bold">{t}</text><text x="{cx}" y="{xl}" text-anchor="middle" font-size="12">{xlab}</text><text transform="translate(14 {cy}) rotate(-90)" text-anchor="middle" font-size="12">{ylab}</text>"##,
        t = esc(title),
        cx = L + pw / 2.0,
        cy = T + ph / 2.0,
        xl = H - 6.0,
        xlab = esc(xlabel),
        ylab = esc(ylabel),
    );
    for v in y.ticks() {
        let py = T + ph * (1.0 - y.frac(v));
        let _ = write!(
            out,
            r##"<line x1="{L}" x2="{x2}" y1="{py:.1}" y2="{py:.1}" stroke="#e4e4e4"/><text x="{tx}" y="{ty:.1}" text-anchor="end" font-size="11">{s}</text>"##,
            x2 = L + pw,
            tx = L - 4.0,
            ty = py + 4.0,
            s = fmt_tick(v)
        );
    }
    if xticks {
        for v in ticks(x.0, x.1, 6) {
            let px = L + pw * (v - x.0) / (x.1 - x.0);
            let _ = write!(
                out,
                r##"<line y1="{T}" y2="{y2}" x1="{px:.1}" x2="{px:.1}" stroke="#eee"/><text x="{px:.1}" y="{ty}" text-anchor="middle" font-size="11">{s}</text>"##,
                y2 = T + ph,
                ty = T + ph + 14.0,
                s = fmt_tick(v)
            );
        }
    }
}

fn legend(out: &mut String, items: &[(&str, &str)]) {
    let mut x = L + 6.0;
    for (label, color) in items {
        let _ = write!(
            out,
            r#"<rect x="{x}" y="{y}" width="10" height="10" fill="{color}"/><text x="{tx}" y="{ty}" font-size="11">{l}</text>"#,
            y = T - 15.0,
            tx = x + 13.0,
            ty = T - 6.0,
            l = esc(label)
        );
        x += 22.0 + 6.5 * label.len() as f64;
    }
}

/// A scatter plot. Each series is drawn as one SVG path of round dots, so
/// tens of thousands of points stay cheap to draw.
pub fn scatter(title: &str, xlabel: &str, ylabel: &str, series: &[Series]) -> String {
    let x = range(
        series.iter().flat_map(|s| s.points.iter().map(|p| p.0)),
        false,
    );
    let y = range(
        series.iter().flat_map(|s| s.points.iter().map(|p| p.1)),
        true,
    );
    let mut out = String::new();
    frame(
        &mut out,
        title,
        xlabel,
        ylabel,
        x,
        YAxis::Linear(y.0, y.1),
        true,
    );
    let pw = W - L - R;
    let ph = H - T - B;
    let n: usize = series.iter().map(|s| s.points.len()).sum();
    let dot = if n > 3000 { 2.0 } else { 4.0 };
    for s in series {
        let mut d = String::with_capacity(s.points.len() * 16);
        for &(px, py) in &s.points {
            if !(px.is_finite() && py.is_finite()) {
                continue;
            }
            let sx = L + pw * (px - x.0) / (x.1 - x.0);
            let sy = T + ph * (1.0 - (py - y.0) / (y.1 - y.0));
            let _ = write!(d, "M{sx:.1} {sy:.1}h0");
        }
        let _ = write!(
            out,
            r#"<path class="series" data-label="{l}" data-n="{n}" d="{d}" stroke="{c}" stroke-width="{w}" stroke-linecap="round" fill="none" opacity="0.8"/>"#,
            l = esc(s.label),
            n = s.points.len(),
            c = s.color,
            w = if s.dot > 0.0 { s.dot } else { dot },
        );
    }
    let items: Vec<(&str, &str)> = series.iter().map(|s| (s.label, s.color)).collect();
    legend(&mut out, &items);
    out.push_str("</svg>");
    out
}

/// A group's label under the axis, centred at `x`, within `width`: on two
/// lines (split at its last space) and in a smaller font when one line at
/// 11 px would run into its neighbours.
fn group_label(out: &mut String, name: &str, x: f64, y: f64, width: f64) {
    // About 0.6 em per character in the sans-serif fonts of the page.
    let fits = |text: &str, px: f64| text.chars().count() as f64 * 0.6 * px <= 0.95 * width;
    if fits(name, 11.0) {
        let _ = write!(
            out,
            r#"<text x="{x:.1}" y="{y}" text-anchor="middle" font-size="11">{n}</text>"#,
            n = esc(name)
        );
        return;
    }
    let lines: Vec<&str> = match name.rsplit_once(' ') {
        Some((a, b)) => vec![a, b],
        None => vec![name],
    };
    let longest = lines.iter().map(|l| l.chars().count()).max().unwrap_or(1) as f64;
    let px = (0.95 * width / (0.6 * longest)).clamp(6.0, 11.0);
    let _ = write!(
        out,
        r#"<text x="{x:.1}" y="{y}" text-anchor="middle" font-size="{px:.1}">"#
    );
    for (i, line) in lines.iter().enumerate() {
        let _ = write!(
            out,
            r#"<tspan x="{x:.1}" dy="{dy:.1}">{t}</tspan>"#,
            dy = if i == 0 { 0.0 } else { px * 1.1 },
            t = esc(line)
        );
    }
    out.push_str("</text>");
}

/// Grouped bars: `groups` along x, one bar per entry of `bars` (label,
/// colour) in each group; `values[g][b]`.
pub fn bars(
    title: &str,
    ylabel: &str,
    groups: &[&str],
    bars: &[(&str, &str)],
    values: &[Vec<f64>],
) -> String {
    let y = YAxis::for_bars(values.iter().flatten().copied());
    let ylabel = match y {
        YAxis::Log10(..) => format!("{ylabel}, log scale"),
        YAxis::Linear(..) => ylabel.to_string(),
    };
    let mut out = String::new();
    frame(&mut out, title, "", &ylabel, (0.0, 1.0), y, false);
    let pw = W - L - R;
    let ph = H - T - B;
    let gw = pw / groups.len().max(1) as f64;
    let bw = gw * 0.8 / bars.len().max(1) as f64;
    for (g, name) in groups.iter().enumerate() {
        let gx = L + gw * g as f64 + gw * 0.1;
        group_label(&mut out, name, L + gw * (g as f64 + 0.5), T + ph + 14.0, gw);
        for (b, (label, color)) in bars.iter().enumerate() {
            let v = values
                .get(g)
                .and_then(|r| r.get(b))
                .copied()
                .unwrap_or(f64::NAN);
            if !v.is_finite() {
                continue; // no figure (no held-out poses): no bar
            }
            let top = T + ph * (1.0 - y.frac(v));
            // A log axis has no zero: its bars stand on the bottom.
            let base = T + ph * (1.0 - y.frac(0.0));
            let h = (base - top).abs().max(0.5);
            let _ = write!(
                out,
                r#"<rect class="bar" x="{x:.1}" y="{yy:.1}" width="{bw:.1}" height="{h:.1}" fill="{color}" data-value="{v}"><title>{n} {l}: {v:.4}</title></rect>"#,
                x = gx + bw * b as f64,
                yy = top.min(base),
                n = esc(name),
                l = esc(label),
            );
            // A bar too short to see beside bars a hundred times taller
            // (after calibration beside before) says its value above it.
            if h < 0.04 * ph {
                let (cx, cy) = (gx + bw * (b as f64 + 0.5), top.min(base) - 3.0);
                let _ = write!(
                    out,
                    r#"<text class="bar-value" x="{cx:.1}" y="{cy:.1}" font-size="9" transform="rotate(-90 {cx:.1} {cy:.1})" dominant-baseline="middle">{}</text>"#,
                    fmt_tick(v)
                );
            }
        }
    }
    legend(&mut out, bars);
    out.push_str("</svg>");
    out
}

#[cfg(test)]
mod tests {
    use super::{bars, group_label};

    #[test]
    fn a_bar_too_short_to_see_says_its_value() {
        let svg = bars(
            "t",
            "mm",
            &["x"],
            &[("before", "#aaa"), ("after", "#f00")],
            &[vec![3.0, 0.0339]],
        );
        // 88 times smaller, within two decades: linear.
        assert!(!svg.contains("log scale"), "{svg}");
        assert_eq!(svg.matches(r#"class="bar-value""#).count(), 1, "{svg}");
        assert!(svg.contains(">0.0339</text>"), "{svg}");
    }

    #[test]
    fn bars_spanning_decades_go_on_a_log_axis() {
        let svg = bars(
            "t",
            "RMS (mm)",
            &["x", "3-D"],
            &[("before", "#aaa"), ("after", "#f00")],
            &[vec![7.2, 0.0339], vec![7.46, 0.0445]],
        );
        assert!(svg.contains("RMS (mm), log scale"), "{svg}");
        // Decade ticks from 0.01 to 10, each one drawn.
        for t in [">0.01</text>", ">0.1</text>", ">1</text>", ">10</text>"] {
            assert!(svg.contains(t), "{t} in {svg}");
        }
        // Every bar tall enough to read: no value written beside one.
        assert_eq!(svg.matches(r#"class="bar-value""#).count(), 0, "{svg}");
        let heights: Vec<f64> = svg
            .split(r#"class="bar""#)
            .skip(1)
            .map(|r| {
                r.split("height=\"")
                    .nth(1)
                    .unwrap()
                    .split('"')
                    .next()
                    .unwrap()
                    .parse()
                    .unwrap()
            })
            .collect();
        assert_eq!(heights.len(), 4);
        // log10(7.2 / 0.0339) = 2.33 decades between the two heights.
        let per_decade = (heights[0] - heights[1]) / (7.2f64 / 0.0339).log10();
        let (a, b) = (heights[2], heights[3]);
        assert!(
            ((a - b) / per_decade - (7.46f64 / 0.0445).log10()).abs() < 0.01,
            "{heights:?}"
        );
        assert!(heights[1] > 0.05 * heights[0], "{heights:?}");
    }

    #[test]
    fn a_log_axis_spans_at_most_six_decades() {
        let svg = bars(
            "t",
            "mm",
            &["x"],
            &[("before", "#aaa"), ("after", "#f00")],
            &[vec![5.0, 1e-300]],
        );
        assert!(svg.contains("mm, log scale"), "{svg}");
        // Ticks 1e-5 .. 10: seven lines.
        assert_eq!(svg.matches(r##"stroke="#e4e4e4""##).count(), 7, "{svg}");
        assert_eq!(svg.matches(r#"class="bar-value""#).count(), 1, "{svg}");
    }

    #[test]
    fn bars_within_two_decades_stay_linear_from_zero() {
        let svg = bars(
            "t",
            "RMS (mm)",
            &["3-D"],
            &[("before", "#aaa"), ("after", "#f00")],
            &[vec![0.99, 0.48]],
        );
        assert!(!svg.contains("log scale"), "{svg}");
        assert!(svg.contains(">0</text>"), "{svg}");
    }

    #[test]
    fn long_group_labels_wrap_and_shrink_to_their_width() {
        let mut short = String::new();
        group_label(&mut short, "rig_step", 100.0, 300.0, 120.0);
        assert!(
            short.contains(r#"font-size="11">rig_step</text>"#),
            "{short}"
        );

        let mut long = String::new();
        group_label(&mut long, "joint_compliance j2", 100.0, 300.0, 70.0);
        assert_eq!(long.matches("<tspan").count(), 2, "{long}");
        let px: f64 = long
            .split(r#"font-size=""#)
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap()
            .parse()
            .unwrap();
        // "joint_compliance" (16 characters) within 95% of 70 px.
        assert!(px < 11.0 && 16.0 * 0.6 * px <= 0.95 * 70.0 + 1e-9, "{px}");
    }
}
