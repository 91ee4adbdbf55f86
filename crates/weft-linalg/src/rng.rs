//! SplitMix64 (Steele, Lea & Flood 2014): the one pseudo-random generator of weft. It is
//! tiny and fully specified, so a seed means the same motion, jitter and perturbation on
//! every machine and in every version — which datasets rely on.
//!
//! It lives here, in the lowest crate that both of its users already depend on: weft-sim
//! (scene motion and perturbations, re-exported as `weft_sim::rng`) and weft-testkit (its
//! `TestRng` wraps it). It is not linear algebra; weft-mesh would be lower, but weft-testkit
//! depending on weft-mesh would close a cycle with weft-mesh's own tests.

/// The SplitMix64 generator: state advanced by the golden-ratio increment, output by
/// its finaliser.
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[0, 1)` with 53 random bits.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

#[cfg(test)]
mod tests {
    use super::SplitMix64;

    #[test]
    fn matches_the_reference_outputs() {
        // First outputs for seed 1234567 of the reference C implementation (Vigna's
        // splitmix64.c), as quoted by many ports.
        let mut r = SplitMix64::new(1234567);
        assert_eq!(r.next_u64(), 6457827717110365317);
        assert_eq!(r.next_u64(), 3203168211198807973);
        let mut u = SplitMix64::new(0);
        let x = u.unit();
        assert!((0.0..1.0).contains(&x));
    }
}
