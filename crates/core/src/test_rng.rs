//! Deterministic pseudo-random numbers for unit tests (xorshift64): compiled for this crate's
//! tests and, through the `test-support` feature, for the backends' unit tests. Not part of the
//! renderer.

pub struct Rng(pub u64);

impl Rng {
    /// The next state (never 0 from a non-zero seed).
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// A float in [0, 1) from the next state's top 24 bits.
    pub fn f(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}
