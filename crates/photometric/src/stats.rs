//! Small robust statistics shared by the estimators.

/// Median of a slice (reordered; the mean of the two middle values of an even count); NaN
/// when empty.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let (n, mid) = (v.len(), v.len() / 2);
    let (lower, &mut m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    if n % 2 == 1 {
        m
    } else {
        let below = lower.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (below + m)
    }
}

/// The most values [`small_median`] takes through its sorting network.
pub(crate) const SMALL: usize = 24;

/// Batcher's odd-even merge sort for `n` inputs: its compare-exchange pairs `(lower, upper)`
/// in order, and how many there are. Made for `n` a power of two, and for any `n` by leaving
/// out the pairs that reach past it (those would compare with an input at +infinity, which
/// changes nothing).
const fn merge_network<const M: usize>(n: usize) -> ([(u8, u8); M], usize) {
    let mut pairs = [(0u8, 0u8); M];
    let mut count = 0;
    let mut p = 1;
    while p < n {
        let mut k = p;
        while k >= 1 {
            let mut j = k % p;
            while j + k < n {
                let mut i = 0;
                while i < k && i + j + k < n {
                    if (i + j) / (2 * p) == (i + j + k) / (2 * p) {
                        pairs[count] = ((i + j) as u8, (i + j + k) as u8);
                        count += 1;
                    }
                    i += 1;
                }
                j += 2 * k;
            }
            k /= 2;
        }
        p *= 2;
    }
    (pairs, count)
}

/// The sorting network of [`small_median`] (132 pairs for 24 inputs).
const NETWORK: ([(u8, u8); 160], usize) = merge_network::<160>(SMALL);

// [`small_median`] unrolls the first 144 pairs
const _: () = assert!(NETWORK.1 <= 144);

/// The bits of `x` as an integer that orders as [`f64::total_cmp`] does.
#[inline]
fn total_key(x: f64) -> i64 {
    let b = x.to_bits() as i64;
    b ^ ((((b >> 63) as u64) >> 1) as i64)
}

/// The inverse of [`total_key`].
#[inline]
fn from_total_key(k: i64) -> f64 {
    f64::from_bits((k ^ ((((k >> 63) as u64) >> 1) as i64)) as u64)
}

/// [`median`] of at most [`SMALL`] values, the same number (up to the sign of a zero, which
/// [`median`] leaves to `f64::max`), by a sorting network: the same compare-exchanges
/// whatever the values, without the mispredicted branches of a selection (a quarter of
/// its time on 20 values). More values go to [`median`].
pub(crate) fn small_median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 || n > SMALL {
        return median(v);
    }
    let mut k = [i64::MAX; SMALL];
    for (d, x) in k.iter_mut().zip(v.iter()) {
        *d = total_key(*x);
    }
    // the network unrolled: every pair's indices are constants, so that the values stay in
    // registers (a loop over the table goes through memory at every step: twice the time)
    macro_rules! exchange {
        ($i:expr) => {
            if $i < NETWORK.1 {
                let (a, b) = NETWORK.0[$i];
                let (x, y) = (k[a as usize], k[b as usize]);
                k[a as usize] = x.min(y);
                k[b as usize] = x.max(y);
            }
        };
    }
    macro_rules! times4 {
        ($i:expr) => {
            exchange!($i);
            exchange!($i + 1);
            exchange!($i + 2);
            exchange!($i + 3);
        };
    }
    macro_rules! times16 {
        ($i:expr) => {
            times4!($i);
            times4!($i + 4);
            times4!($i + 8);
            times4!($i + 12);
        };
    }
    macro_rules! times64 {
        ($i:expr) => {
            times16!($i);
            times16!($i + 16);
            times16!($i + 32);
            times16!($i + 48);
        };
    }
    times64!(0);
    times64!(64);
    times16!(128);
    let mid = n / 2;
    if n % 2 == 1 {
        from_total_key(k[mid])
    } else {
        0.5 * (from_total_key(k[mid - 1]) + from_total_key(k[mid]))
    }
}

#[cfg(test)]
mod tests {
    use super::{median, small_median, NETWORK, SMALL};

    /// The network sorts 0-1 inputs of its size (every 97th of the 2^24: a network that
    /// sorts all of them sorts every input), and the small median is the median at every
    /// length, with ties, zeros of both signs, infinities and values of every magnitude.
    #[test]
    fn the_network_sorts_and_the_small_median_is_the_median() {
        let (pairs, count) = &NETWORK;
        assert_eq!(*count, 132);
        for bits in (0u32..1 << SMALL).step_by(97) {
            let mut v: Vec<u32> = (0..SMALL).map(|i| (bits >> i) & 1).collect();
            for &(a, b) in &pairs[..*count] {
                let (x, y) = (v[a as usize], v[b as usize]);
                v[a as usize] = x.min(y);
                v[b as usize] = x.max(y);
            }
            assert!(v.windows(2).all(|w| w[0] <= w[1]), "{bits:b}");
        }
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let pool = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            2.5,
            1e-300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for case in 0..20_000 {
            let n = 1 + case % (SMALL + 2);
            let mut v: Vec<f64> = (0..n)
                .map(|_| {
                    let r = next();
                    if r % 4 == 0 {
                        pool[(r >> 8) as usize % pool.len()]
                    } else {
                        ((r >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((r % 7) as i32)
                    }
                })
                .collect();
            let want = median(&mut v.clone());
            let got = small_median(&mut v);
            assert!(
                got == want || (got.is_nan() && want.is_nan()),
                "{n} values: {got} vs {want}"
            );
        }
    }

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }
}
