//! Python 2's `random` module, as far as `evaluate_rpe.py` uses it: the Mersenne Twister
//! (MT19937) seeded by `random.seed(0)`, `random()`, `randint(a, b)` and `sample`. The TUM
//! RGB-D script draws 10,000 random pose pairs beyond 100 poses; the same generator picks
//! the same pairs, so the numbers agree.

const N: usize = 624;
const M: usize = 397;

/// Python 2.7's `random.Random`.
pub struct PyRandom {
    mt: [u32; N],
    index: usize,
}

impl PyRandom {
    /// `random.seed(n)` for a non-negative integer below 2^32 (Python splits larger seeds in
    /// 32-bit words; the TUM script seeds 0).
    pub fn new(seed: u32) -> PyRandom {
        let mut r = PyRandom {
            mt: [0; N],
            index: N,
        };
        r.init_by_array(&[seed]);
        r
    }

    fn init_genrand(&mut self, s: u32) {
        self.mt[0] = s;
        for i in 1..N {
            let prev = self.mt[i - 1];
            self.mt[i] = 1_812_433_253u32
                .wrapping_mul(prev ^ (prev >> 30))
                .wrapping_add(i as u32);
        }
        self.index = N;
    }

    fn init_by_array(&mut self, key: &[u32]) {
        self.init_genrand(19_650_218);
        let (mut i, mut j) = (1usize, 0usize);
        for _ in 0..N.max(key.len()) {
            let prev = self.mt[i - 1];
            self.mt[i] = (self.mt[i] ^ (prev ^ (prev >> 30)).wrapping_mul(1_664_525))
                .wrapping_add(key[j])
                .wrapping_add(j as u32);
            i += 1;
            j += 1;
            if i >= N {
                self.mt[0] = self.mt[N - 1];
                i = 1;
            }
            if j >= key.len() {
                j = 0;
            }
        }
        for _ in 0..N - 1 {
            let prev = self.mt[i - 1];
            self.mt[i] = (self.mt[i] ^ (prev ^ (prev >> 30)).wrapping_mul(1_566_083_941))
                .wrapping_sub(i as u32);
            i += 1;
            if i >= N {
                self.mt[0] = self.mt[N - 1];
                i = 1;
            }
        }
        self.mt[0] = 0x8000_0000;
    }

    fn genrand_u32(&mut self) -> u32 {
        const UPPER: u32 = 0x8000_0000;
        const LOWER: u32 = 0x7fff_ffff;
        const MATRIX_A: u32 = 0x9908_b0df;
        if self.index >= N {
            for k in 0..N {
                let y = (self.mt[k] & UPPER) | (self.mt[(k + 1) % N] & LOWER);
                let mag = if y & 1 == 1 { MATRIX_A } else { 0 };
                self.mt[k] = self.mt[(k + M) % N] ^ (y >> 1) ^ mag;
            }
            self.index = 0;
        }
        let mut y = self.mt[self.index];
        self.index += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^= y >> 18;
        y
    }

    /// `random.random()`: a double in [0, 1) from 53 random bits.
    pub fn random(&mut self) -> f64 {
        let a = (self.genrand_u32() >> 5) as f64;
        let b = (self.genrand_u32() >> 6) as f64;
        (a * 67_108_864.0 + b) * (1.0 / 9_007_199_254_740_992.0)
    }

    /// Python 2's `random.randint(a, b)`: `a + int(random() * (b - a + 1))`.
    pub fn randint(&mut self, a: usize, b: usize) -> usize {
        a + (self.random() * (b - a + 1) as f64) as usize
    }

    /// Python 2's `random.sample(population, k)` for `k <= population.len()`.
    pub fn sample<T: Clone>(&mut self, population: &[T], k: usize) -> Vec<T> {
        let n = population.len();
        let k = k.min(n);
        let mut setsize = 21.0;
        if k > 5 {
            setsize += 4f64.powf((((k * 3) as f64).ln() / 4f64.ln()).ceil());
        }
        let mut result = Vec::with_capacity(k);
        if (n as f64) <= setsize {
            let mut pool = population.to_vec();
            for i in 0..k {
                let j = (self.random() * (n - i) as f64) as usize;
                result.push(pool[j].clone());
                pool[j] = pool[n - i - 1].clone();
            }
        } else {
            let mut selected = std::collections::HashSet::with_capacity(k);
            for _ in 0..k {
                let mut j = (self.random() * n as f64) as usize;
                while selected.contains(&j) {
                    j = (self.random() * n as f64) as usize;
                }
                selected.insert(j);
                result.push(population[j].clone());
            }
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Python 2.7.18: random.seed(0); random.random(), random.random(); then
    // [random.randint(0, 99) for i in range(6)]; then random.sample(range(20), 5)
    #[test]
    fn matches_python_2() {
        let mut r = PyRandom::new(0);
        assert_eq!(r.random(), 0.844_421_851_525_048_1);
        assert_eq!(r.random(), 0.757_954_402_940_302_5);
        let mut r = PyRandom::new(0);
        let v: Vec<usize> = (0..6).map(|_| r.randint(0, 99)).collect();
        assert_eq!(v, [84, 75, 42, 25, 51, 40]);
        let mut r = PyRandom::new(0);
        let pop: Vec<usize> = (0..20).collect();
        assert_eq!(r.sample(&pop, 5), [16, 14, 7, 4, 8]);
    }
}
