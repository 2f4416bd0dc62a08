//! A small deterministic pseudo-random generator for reproducible synthetic data and tests.

/// Deterministic pseudo-random numbers (64-bit linear congruential generator, high bits).
pub struct Lcg(u64);

impl Lcg {
    /// A generator from `seed` (the seed is stepped once first).
    pub fn new(seed: u64) -> Self {
        Self(
            seed.wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407),
        )
    }

    /// A generator whose state is exactly `state` (no initial step).
    pub fn from_state(state: u64) -> Self {
        Self(state)
    }

    /// The next number in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// The next number in [−1, 1).
    pub fn next_signed(&mut self) -> f64 {
        2.0 * self.next_f64() - 1.0
    }
}
