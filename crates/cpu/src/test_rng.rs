//! Deterministic pseudo-random numbers for the crate's unit tests (xorshift64).

pub(crate) struct Rng(pub(crate) u64);

impl Rng {
    /// The next state (never 0 from a non-zero seed).
    pub(crate) fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// A float in [0, 1) from the next state's top 24 bits.
    pub(crate) fn f(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}
