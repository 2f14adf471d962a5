//! Box plots of a metric over the runs of each method (Tukey's: the box from the first to the
//! third quartile, the median inside, whiskers to the most extreme values within 1.5 times
//! the box's height, the values beyond as points). Failed runs have no value; the legend says
//! how many runs each box holds.

use eval_metrics::{Metric, RunRecord};
use monovo_figures::{Chart, Corner, Figure, Series, PALETTE};
use serde::Serialize;

/// The five numbers of a box and the outliers.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoxStats {
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Lower end of the whisker.
    pub low: f64,
    /// Upper end of the whisker.
    pub high: f64,
    /// Values beyond the whiskers.
    pub outliers: Vec<f64>,
    /// Number of finite values in the box.
    pub n: usize,
}

/// The quantile `p` of sorted values, linearly interpolated (numpy's default).
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (h - lo as f64)
}

impl BoxStats {
    /// The box of the finite values; `None` when there are none.
    ///
    /// ```
    /// use monovo_pipelines::BoxStats;
    ///
    /// let b = BoxStats::of(&[1.0, 2.0, 3.0, 4.0, 100.0, f64::INFINITY]).unwrap();
    /// assert_eq!((b.q1, b.median, b.q3, b.high), (2.0, 3.0, 4.0, 4.0));
    /// assert_eq!((b.outliers.clone(), b.n), (vec![100.0], 5));
    /// ```
    pub fn of(values: &[f64]) -> Option<BoxStats> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let (q1, median, q3) = (quantile(&v, 0.25), quantile(&v, 0.5), quantile(&v, 0.75));
        let reach = 1.5 * (q3 - q1);
        let inside = |x: &&f64| **x >= q1 - reach && **x <= q3 + reach;
        let low = v.iter().find(inside).copied().unwrap_or(q1);
        let high = v.iter().rev().find(inside).copied().unwrap_or(q3);
        let outliers = v.iter().copied().filter(|x| !inside(&x)).collect();
        Some(BoxStats {
            q1,
            median,
            q3,
            low,
            high,
            outliers,
            n: v.len(),
        })
    }

    /// The box drawn at `x` (half width `w`): outline, median, whiskers, outliers.
    fn series(&self, x: f64, w: f64, label: String, color: [u8; 3]) -> Vec<Series> {
        let nan = [f64::NAN, f64::NAN];
        let outline = vec![
            [x - w, self.q1],
            [x + w, self.q1],
            [x + w, self.q3],
            [x - w, self.q3],
            [x - w, self.q1],
            nan,
            [x, self.q1],
            [x, self.low],
            nan,
            [x - w / 2.0, self.low],
            [x + w / 2.0, self.low],
            nan,
            [x, self.q3],
            [x, self.high],
            nan,
            [x - w / 2.0, self.high],
            [x + w / 2.0, self.high],
        ];
        let mut med = Series::line("", vec![[x - w, self.median], [x + w, self.median]], color);
        med.width = 3.5;
        let mut out = vec![Series::line(label, outline, color), med];
        if !self.outliers.is_empty() {
            let mut o = Series::points("", self.outliers.iter().map(|v| [x, *v]).collect(), color);
            o.marker = Some(2.5);
            out.push(o);
        }
        out
    }
}

/// A box per group (`(label, values)`, one colour each, at x = 1, 2, ...), the legend naming
/// the groups and their counts of finite values.
pub fn box_chart(title: &str, metric: Metric, groups: &[(String, Vec<f64>)]) -> Chart {
    let mut c = Chart::new(title, "method", metric.label());
    for (i, (label, values)) in groups.iter().enumerate() {
        let x = (i + 1) as f64;
        let color = PALETTE[i % PALETTE.len()];
        let text = |n: usize| format!("{label} ({n}/{} runs)", values.len());
        match BoxStats::of(values) {
            Some(b) => c.series.extend(b.series(x, 0.3, text(b.n), color)),
            None => c.series.push(Series::line(text(0), Vec::new(), color)),
        }
    }
    c.x_range = Some([0.4, groups.len() as f64 + 0.6]);
    c.x_categories = groups.iter().map(|(l, _)| l.clone()).collect();
    c.legend = Some(Corner::TopRight);
    c
}

/// The box plot of a metric over the runs of each method of a results table.
pub fn method_box_figure(records: &[RunRecord], metric: Metric) -> Figure {
    let mut methods: Vec<&str> = records.iter().map(|r| r.key.method.as_str()).collect();
    methods.sort_unstable();
    methods.dedup();
    let groups: Vec<(String, Vec<f64>)> = methods
        .iter()
        .map(|m| {
            let v = records
                .iter()
                .filter(|r| r.key.method == *m)
                .map(|r| metric.of(r))
                .collect();
            (m.to_string(), v)
        })
        .collect();
    let short = if metric == Metric::ES {
        "e'_s"
    } else {
        metric.name()
    };
    let title = format!("{short} per method (failed runs left out)");
    Figure::single(box_chart(&title, metric, &groups), 900, 600)
}
