//! The statistics every trajectory metric reports over its error values, as evo and the TUM
//! scripts compute them with numpy: sums by numpy's pairwise summation (so the last digits
//! agree too), the population standard deviation, the median as the mean of the two middle
//! values for an even count.

use serde::{Deserialize, Serialize};

/// Statistics of a list of errors: evo's `rmse`, `mean`, `median`, `std` (population), `min`,
/// `max` and `sse` (sum of squares), and the count `n`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// Population standard deviation (numpy's `std`, `ddof = 0`).
    pub std: f64,
    /// Smallest error.
    pub min: f64,
    /// Largest error.
    pub max: f64,
    /// Sum of squared errors.
    pub sse: f64,
    /// Number of errors.
    pub n: usize,
}

impl ErrorStats {
    /// The statistics of `errors`; `None` for an empty list.
    ///
    /// ```
    /// use eval_metrics::ErrorStats;
    ///
    /// let s = ErrorStats::of(&[1.0, 2.0, 3.0, 6.0]).unwrap();
    /// assert_eq!((s.mean, s.median, s.min, s.max, s.sse, s.n), (3.0, 2.5, 1.0, 6.0, 50.0, 4));
    /// assert!((s.rmse - 12.5f64.sqrt()).abs() < 1e-15);
    /// assert!((s.std - 3.5f64.sqrt()).abs() < 1e-15);
    /// ```
    pub fn of(errors: &[f64]) -> Option<ErrorStats> {
        let n = errors.len();
        if n == 0 {
            return None;
        }
        let squares: Vec<f64> = errors.iter().map(|e| e * e).collect();
        let sse = pairwise_sum(&squares);
        let mean = pairwise_sum(errors) / n as f64;
        let dev: Vec<f64> = errors.iter().map(|e| (e - mean) * (e - mean)).collect();
        let std = (pairwise_sum(&dev) / n as f64).sqrt();
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let median = if n % 2 == 1 {
            sorted[n / 2]
        } else {
            (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
        };
        Some(ErrorStats {
            rmse: (sse / n as f64).sqrt(),
            mean,
            median,
            std,
            min: sorted[0],
            max: sorted[n - 1],
            sse,
            n,
        })
    }

    /// The statistics scaled by a positive factor (a unit change: radians to degrees). The
    /// sum of squares scales by the square.
    pub fn scaled(&self, k: f64) -> ErrorStats {
        ErrorStats {
            rmse: self.rmse * k,
            mean: self.mean * k,
            median: self.median * k,
            std: self.std * k,
            min: self.min * k,
            max: self.max * k,
            sse: self.sse * k * k,
            n: self.n,
        }
    }
}

/// numpy's pairwise summation of float64 (`np.sum`, `np.mean`): blocks of up to 128 values
/// summed in eight interleaved partial sums, larger arrays split in halves.
pub fn pairwise_sum(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        let mut r = 0.0;
        for v in a {
            r += v;
        }
        r
    } else if n <= 128 {
        let mut r = [a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]];
        let mut i = 8;
        while i < n - n % 8 {
            for (j, rj) in r.iter_mut().enumerate() {
                *rj += a[i + j];
            }
            i += 8;
        }
        let mut res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for v in &a[i..] {
            res += v;
        }
        res
    } else {
        let mut n2 = n / 2;
        n2 -= n2 % 8;
        pairwise_sum(&a[..n2]) + pairwise_sum(&a[n2..])
    }
}
