//! The standard error of every `U(k)`: the sampling part from the sandwich covariance of the
//! last Gauss-Newton step (tiles of pixels as the independent units), and what the prior and
//! the continuation beyond the data may add.

use nalgebra::{DMatrix, DVector};

use super::prior::{extrapolate, extrapolate_with, EXTRAPOLATION_WINDOW};
use super::solver::{gauge, singular, u_system, Fit};
use crate::PhotometricError;

/// `u` scaled to `U(top) = 255` (exactly: the product with the scale can be an ulp off).
pub(super) fn normalized(u: &[f64]) -> Vec<f64> {
    let s = 255.0 / u[u.len() - 1];
    let mut out: Vec<f64> = u.iter().map(|v| v * s).collect();
    if let Some(last) = out.last_mut() {
        *last = 255.0;
    }
    out
}

/// The parts of the standard errors of the normalised table.
pub(super) struct Errors {
    /// The sampling part (what more pixels would reduce).
    pub sampling: Vec<f64>,
    /// The prior's and the continuation's part.
    pub systematic: Vec<f64>,
}

/// The standard errors of the fit whose data determine the knots `first..=last`.
pub(super) fn standard_errors(
    fit: &Fit,
    first: usize,
    last: usize,
) -> Result<Errors, PhotometricError> {
    let (u, ext) = extrapolate(&fit.u, first, last);
    let n = u.len();
    let g = gauge(n);
    let (a, _) = u_system(&fit.u_prev, &fit.sums, &fit.penalty, 1.0);
    let chol = a.clone().cholesky().ok_or_else(singular)?;
    // meat: the centred per-tile gradients (the gauge is held: its component is zero)
    let tiles = &fit.sums.tiles;
    let c = tiles.len();
    let mut meat = DMatrix::<f64>::zeros(n, n);
    if c >= 2 {
        let mut mean = vec![0.0; n];
        for (_, grad) in tiles {
            for k in 0..n {
                mean[k] += grad[k] / c as f64;
            }
        }
        for (_, grad) in tiles {
            let v = DVector::from_fn(n, |k, _| {
                if k == g || k == 0 {
                    0.0
                } else {
                    grad[k] - mean[k]
                }
            });
            meat.ger(1.0, &v, &v, 1.0);
        }
        meat *= c as f64 / (c as f64 - 1.0);
    }
    let x = chol.solve(&meat);
    let cov = &ext * chol.solve(&x.transpose()) * ext.transpose();
    // normalisation U_n = 255 U / U(top): J = 255 / U_top (I - U e_top^T / U_top)
    let s = 255.0 / u[n - 1];
    let mut jac = DMatrix::<f64>::identity(n, n) * s;
    for k in 0..n {
        jac[(k, n - 1)] -= s * u[k] / u[n - 1];
    }
    let cov_n = &jac * cov * jac.transpose();
    // the prior's part: the change with a ten times weaker prior
    let (a10, b10) = u_system(&fit.u_prev, &fit.sums, &fit.penalty, 0.1);
    let (_, b1) = u_system(&fit.u_prev, &fit.sums, &fit.penalty, 1.0);
    let d1 = chol.solve(&b1);
    let d10 = a10.cholesky().ok_or_else(singular)?.solve(&b10);
    let u1: Vec<f64> = fit
        .u_prev
        .iter()
        .zip(d1.iter())
        .map(|(a, b)| a + b)
        .collect();
    let u10: Vec<f64> = fit
        .u_prev
        .iter()
        .zip(d10.iter())
        .map(|(a, b)| a + b)
        .collect();
    let n1 = normalized(&extrapolate(&u1, first, last).0);
    let n10 = normalized(&extrapolate(&u10, first, last).0);
    // the continuation's part: the change with half the window
    let nu = normalized(&u);
    let nh = normalized(&extrapolate_with(&fit.u, first, last, EXTRAPOLATION_WINDOW / 2).0);
    let systematic = (0..n)
        .map(|k| {
            let p = (n10[k] - n1[k]).abs() / 0.9;
            let e = (nh[k] - nu[k]).abs();
            p.hypot(e)
        })
        .collect();
    let sampling = (0..n).map(|k| cov_n[(k, k)].max(0.0).sqrt()).collect();
    Ok(Errors {
        sampling,
        systematic,
    })
}
