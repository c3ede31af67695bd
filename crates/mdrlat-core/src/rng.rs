//! A small, value-stable, serialisable random number generator.
//!
//! xoshiro256++ seeded through SplitMix64. Written out here rather than taken from a crate so
//! that the same seed gives the same bytes across dependency upgrades, and so the state can be
//! stored in checkpoints as four integers. Every random choice in mdrlat takes an explicit
//! `&mut Rng`; there is no thread-local generator.

use serde::{Deserialize, Serialize};

/// xoshiro256++ (Blackman & Vigna), seeded with SplitMix64.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Rng {
    s: [u64; 4],
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// A generator seeded from one integer.
    pub fn seed_from_u64(seed: u64) -> Self {
        let mut sm = seed;
        let s =
            [splitmix64(&mut sm), splitmix64(&mut sm), splitmix64(&mut sm), splitmix64(&mut sm)];
        Self { s }
    }

    /// An independent stream derived from this seed and a stream id (e.g. env index, or a
    /// purpose such as "pedestrians"), so adding a consumer never shifts another's numbers.
    pub fn derive(seed: u64, stream: u64) -> Self {
        let mut sm = seed ^ splitmix64(&mut stream.wrapping_mul(0xD605_BBB5_8C8A_BE8B));
        Self::seed_from_u64(splitmix64(&mut sm))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 bits of precision.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range_f32(&mut self, lo: f32, hi: f32) -> f32 {
        let x = lo as f64 + (hi as f64 - lo as f64) * self.uniform();
        (x as f32).min(hi).max(lo)
    }

    /// Uniform integer in [0, n). `n` must be positive.
    pub fn below(&mut self, n: usize) -> usize {
        assert!(n > 0, "Rng::below(0)");
        // Lemire's multiply-shift; the bias for n << 2^64 is negligible and value-stable.
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }

    /// Standard normal sample (Box–Muller, one value per call).
    pub fn normal(&mut self) -> f32 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_stream_and_golden_values() {
        let mut a = Rng::seed_from_u64(42);
        let mut b = Rng::seed_from_u64(42);
        let xs: Vec<u64> = (0..4).map(|_| a.next_u64()).collect();
        let ys: Vec<u64> = (0..4).map(|_| b.next_u64()).collect();
        assert_eq!(xs, ys);
        // Golden value: changing the generator changes every seeded result downstream.
        assert_eq!(Rng::seed_from_u64(0).next_u64(), 0x53175d61490b23df);
    }

    #[test]
    fn derived_streams_differ() {
        let a = Rng::derive(7, 0).next_u64();
        let b = Rng::derive(7, 1).next_u64();
        assert_ne!(a, b);
    }

    #[test]
    fn ranges_hold() {
        let mut r = Rng::seed_from_u64(1);
        for _ in 0..10_000 {
            let x = r.range_f32(-1.0, 2.0);
            assert!((-1.0..=2.0).contains(&x));
            assert!(r.below(7) < 7);
            assert!(r.normal().is_finite());
        }
    }
}
