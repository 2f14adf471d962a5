//! Axes: data ranges, tick positions and their labels (linear, logarithmic, categories), and
//! the clipping of lines and polygons to the plot area.

use crate::{Chart, Series};

// ------------------------------------------------------------------------------- charts

/// Tick labels of an axis: as many decimals as the spacing of the ticks needs (plotters
/// puts them at 1, 2 or 5 times a power of ten), trailing zeros dropped, scientific
/// notation for very small or large spacings.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TickFormat {
    /// The (smallest possible) spacing of the ticks; 0 on a logarithmic axis, where each
    /// label is written by its own magnitude.
    pub(crate) step: f64,
}

impl TickFormat {
    /// A linear axis over `span` with at most `labels` labels.
    pub(crate) fn linear(span: f64, labels: usize) -> TickFormat {
        TickFormat {
            step: span.abs() / labels.max(1) as f64,
        }
    }

    /// A logarithmic axis (ticks at 1, 2 or 5 times powers of ten).
    pub(crate) const LOG: TickFormat = TickFormat { step: 0.0 };

    pub(crate) fn format(self, v: f64) -> String {
        if v == 0.0 || !v.is_finite() {
            return if v == 0.0 { "0".into() } else { v.to_string() };
        }
        let step = if self.step > 0.0 { self.step } else { v.abs() };
        let mag = step.log10().floor();
        let trim = |t: &str| -> String {
            if t.contains('.') {
                t.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                t.to_string()
            }
        };
        if !(-4.0..6.0).contains(&mag) || v.abs() >= 1e7 {
            let t = format!("{v:.2e}");
            let (mantissa, exp) = t.split_once('e').unwrap_or((&t, "0"));
            return format!("{}e{exp}", trim(mantissa));
        }
        let decimals = (1.0 - mag).max(0.0) as usize;
        let t = trim(&format!("{v:.decimals$}"));
        if t == "-0" {
            "0".into()
        } else {
            t
        }
    }
}

/// The label of a category axis at `v`: the name at a whole number 1..=n, nothing elsewhere;
/// `None` for a numeric axis.
pub(crate) fn category_label(categories: &[String], v: f64) -> Option<String> {
    if categories.is_empty() {
        return None;
    }
    let k = v.round();
    Some(
        if (v - k).abs() < 1e-9 && k >= 1.0 && k <= categories.len() as f64 {
            categories[k as usize - 1].clone()
        } else {
            String::new()
        },
    )
}

pub(crate) fn data_range(series: &[Series], axis: usize, log: bool) -> Option<[f64; 2]> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in series {
        for p in s.points.iter().chain(s.band_upper.iter().flatten()) {
            let v = p[axis];
            if v.is_finite() && (!log || v > 0.0) {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        return None;
    }
    if hi <= lo {
        let pad = if log {
            lo * 0.5
        } else {
            lo.abs().max(1.0) * 0.05
        };
        return Some([lo - pad, hi + pad]);
    }
    Some([lo, hi])
}

/// The axis ranges of a chart: given, or the data's with a small margin.
pub(crate) fn chart_ranges(c: &Chart) -> ([f64; 2], [f64; 2]) {
    let mut xr = c
        .x_range
        .or_else(|| data_range(&c.series, 0, c.x_log))
        .unwrap_or(if c.x_log { [0.1, 10.0] } else { [0.0, 1.0] });
    let mut yr = c
        .y_range
        .or_else(|| data_range(&c.series, 1, false))
        .unwrap_or([0.0, 1.0]);
    if c.x_log {
        xr = [xr[0].max(1e-300), xr[1].max(xr[0] * 1.0001)];
    } else if c.x_range.is_none() {
        let pad = (xr[1] - xr[0]) * 0.03;
        xr = [xr[0] - pad, xr[1] + pad];
    }
    if c.y_range.is_none() {
        let pad = (yr[1] - yr[0]) * 0.04;
        yr = [yr[0] - pad, yr[1] + pad];
    }
    if xr[1] <= xr[0] {
        xr[1] = xr[0] + 1.0;
    }
    if yr[1] <= yr[0] {
        yr[1] = yr[0] + 1.0;
    }
    (xr, yr)
}

/// Maps data to the chart's axis space (log10 on a logarithmic x axis) and back.
#[derive(Clone, Copy)]
pub(crate) struct AxisSpace {
    pub(crate) x_log: bool,
}

impl AxisSpace {
    pub(crate) fn to_axis(self, p: [f64; 2]) -> [f64; 2] {
        if self.x_log {
            [p[0].log10(), p[1]]
        } else {
            p
        }
    }
    pub(crate) fn to_data(self, p: [f64; 2]) -> [f64; 2] {
        if self.x_log {
            [10f64.powf(p[0]), p[1]]
        } else {
            p
        }
    }
    pub(crate) fn valid(self, p: [f64; 2]) -> bool {
        p[0].is_finite() && p[1].is_finite() && (!self.x_log || p[0] > 0.0)
    }
}

/// Clips a segment to the rectangle `[x0, x1] x [y0, y1]` (Liang-Barsky).
pub(crate) fn clip_segment(a: [f64; 2], b: [f64; 2], r: [f64; 4]) -> Option<([f64; 2], [f64; 2])> {
    let d = [b[0] - a[0], b[1] - a[1]];
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-d[0], a[0] - r[0]),
        (d[0], r[1] - a[0]),
        (-d[1], a[1] - r[2]),
        (d[1], r[3] - a[1]),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    (t0 <= t1).then(|| {
        (
            [a[0] + t0 * d[0], a[1] + t0 * d[1]],
            [a[0] + t1 * d[0], a[1] + t1 * d[1]],
        )
    })
}

/// The visible pieces of a polyline: broken at non-finite points, clipped to `r` (axis
/// space), returned in data coordinates.
pub(crate) fn visible_runs(
    points: &[[f64; 2]],
    space: AxisSpace,
    r: [f64; 4],
) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut cur: Vec<[f64; 2]> = Vec::new();
    let mut flush = |cur: &mut Vec<[f64; 2]>| {
        if cur.len() >= 2 {
            runs.push(
                cur.iter()
                    .map(|p| {
                        let d = space.to_data(*p);
                        (d[0], d[1])
                    })
                    .collect(),
            );
        }
        cur.clear();
    };
    let mut prev: Option<[f64; 2]> = None;
    for &p in points {
        if !space.valid(p) {
            flush(&mut cur);
            prev = None;
            continue;
        }
        let q = space.to_axis(p);
        if let Some(a) = prev {
            match clip_segment(a, q, r) {
                Some((s, e)) => {
                    if cur.last() != Some(&s) {
                        flush(&mut cur);
                        cur.push(s);
                    }
                    cur.push(e);
                    if e != q {
                        flush(&mut cur);
                    }
                }
                None => flush(&mut cur),
            }
        }
        prev = Some(q);
    }
    flush(&mut cur);
    runs
}

/// Clips a polygon to the rectangle `r` (Sutherland-Hodgman; the rectangle is convex).
pub(crate) fn clip_polygon(poly: Vec<[f64; 2]>, r: [f64; 4]) -> Vec<[f64; 2]> {
    let edges: [(usize, f64, bool); 4] = [
        (0, r[0], true),
        (0, r[1], false),
        (1, r[2], true),
        (1, r[3], false),
    ];
    let mut out = poly;
    for (axis, bound, keep_above) in edges {
        let inside = |p: &[f64; 2]| {
            if keep_above {
                p[axis] >= bound
            } else {
                p[axis] <= bound
            }
        };
        let input = std::mem::take(&mut out);
        for (i, &cur) in input.iter().enumerate() {
            let prev = input[(i + input.len() - 1) % input.len()];
            let cross = |a: [f64; 2], b: [f64; 2]| {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
            };
            match (inside(&prev), inside(&cur)) {
                (true, true) => out.push(cur),
                (true, false) => out.push(cross(prev, cur)),
                (false, true) => {
                    out.push(cross(prev, cur));
                    out.push(cur);
                }
                (false, false) => {}
            }
        }
        if out.is_empty() {
            break;
        }
    }
    out
}

/// The ticks of a logarithmic axis: 1, 2 and 5 times the powers of ten in the range (or
/// only the powers, or every n-th, when that is too many; 1 to 9 times them when that is too
/// few); on a range shorter than a factor of about 3, evenly spaced ticks as on a linear
/// axis, so that e'_s from 1 to 1.4 still has labelled ticks.
pub(crate) struct LogTicks {
    pub(crate) bold: Vec<f64>,
    pub(crate) light: Vec<f64>,
    pub(crate) format: TickFormat,
}

impl LogTicks {
    pub(crate) fn new(range: [f64; 2], max_labels: usize) -> LogTicks {
        let [lo, hi] = range;
        let max_labels = max_labels.max(2);
        let inside = |v: &f64| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9);
        let multiples = |m: &[f64]| -> Vec<f64> {
            let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
            (k0..=k1)
                .flat_map(|k| m.iter().map(move |m| m * 10f64.powi(k)))
                .filter(inside)
                .collect()
        };
        let all = multiples(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        let mut bold = multiples(&[1.0, 2.0, 5.0]);
        if bold.len() > max_labels {
            let decades = multiples(&[1.0]);
            let every = decades.len().div_ceil(max_labels).max(1);
            bold = decades.into_iter().step_by(every).collect();
        } else if bold.len() < 3 {
            bold = all.clone();
        }
        if bold.len() >= 3 && bold.len() <= max_labels {
            return LogTicks {
                bold,
                light: all,
                format: TickFormat::LOG,
            };
        }
        // a short range: evenly spaced, 1, 2 or 5 times a power of ten apart
        let raw = (hi - lo) / max_labels.min(8) as f64;
        let p = 10f64.powf(raw.log10().floor());
        let step = [1.0, 2.0, 5.0, 10.0]
            .into_iter()
            .map(|m| m * p)
            .find(|s| *s >= raw)
            .unwrap_or(10.0 * p);
        let first = (lo / step).ceil() as i64;
        let last = (hi / step).floor() as i64;
        let bold: Vec<f64> = (first..=last).map(|i| i as f64 * step).collect();
        let light = (first * 5 - 5..=last * 5 + 5)
            .map(|i| i as f64 * step / 5.0)
            .filter(inside)
            .collect();
        LogTicks {
            bold,
            light,
            format: TickFormat { step },
        }
    }
}

#[derive(Clone, Copy)]
pub(crate) struct Ticks {
    pub(crate) x: usize,
    pub(crate) y: usize,
    pub(crate) x_format: TickFormat,
    pub(crate) y_format: TickFormat,
}
