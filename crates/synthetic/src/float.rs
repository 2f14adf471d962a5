//! Rounding of `f64` without calls into the C library: the baseline x86-64 has no rounding
//! instruction, and the renderers round or floor every sample.

/// `x.floor()` without a call into the C library (the baseline x86-64 has no rounding
/// instruction): the same value.
#[inline]
pub(crate) fn floor(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = x as i64 as f64;
        // without branches: the comparison is as likely true as false on noisy data
        t - f64::from(u8::from(t > x))
    } else {
        x.floor()
    }
}

/// `x.round()` (halves away from zero; the sign of a zero aside) without a call into the C
/// library, which the baseline x86-64 needs for it: `x - trunc(x)` is exact.
#[inline]
pub(crate) fn round(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = x as i64 as f64;
        let d = x - t;
        // without branches (the sensor rounds every sample: a branch here is a coin toss)
        t + (f64::from(u8::from(d >= 0.5)) - f64::from(u8::from(d <= -0.5)))
    } else {
        x.round()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Rng;

    #[test]
    fn round_and_floor_are_the_standard_ones() {
        let mut rng = Rng::new(7);
        let mut values = vec![
            0.5,
            -0.5,
            1.5,
            -2.5,
            0.49999999999999994,
            4.5e15,
            -4.6e15,
            1e300,
        ];
        for _ in 0..100_000 {
            let scale = 10f64.powf(rng.range(-3.0, 17.0));
            values.push(rng.range(-1.0, 1.0) * scale);
            // halves and their neighbours
            let half = (rng.range(-1e6, 1e6)).floor() + 0.5;
            values.extend([half, half.next_up(), half.next_down()]);
        }
        for x in values {
            assert_eq!(round(x), x.round(), "{x:e}");
            assert_eq!(floor(x), x.floor(), "{x:e}");
        }
        assert!(round(f64::NAN).is_nan());
        assert_eq!(round(f64::INFINITY), f64::INFINITY);
    }
}
