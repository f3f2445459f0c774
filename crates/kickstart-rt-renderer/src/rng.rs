//! The demo's deterministic generator (SplitMix64): the generated scenes, the benchmarks' inputs
//! and the tests' noise are the same on every run. (The soak keeps its own xorshift, whose seeds
//! replay a recorded churn.)

use glam::Vec3;

/// A SplitMix64 stream from its seed.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    /// A cosine-weighted direction about the unit vector `n`.
    pub fn cosine(&mut self, n: Vec3) -> Vec3 {
        let (t, b) = n.any_orthonormal_pair();
        let (r1, r2) = (self.f32(), self.f32());
        let phi = std::f32::consts::TAU * r1;
        let r = r2.sqrt();
        (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - r2).max(0.0).sqrt()).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_values_stay_in_range_and_cosine_directions_in_the_hemisphere() {
        let mut rng = Rng(5);
        let n = Vec3::new(0.0, 0.6, 0.8);
        let mut sum = 0.0f64;
        for _ in 0..10_000 {
            let u = rng.f32();
            assert!((0.0..1.0).contains(&u));
            sum += f64::from(u);
            let r = rng.range(-2.0, 3.0);
            assert!((-2.0..3.0).contains(&r));
            let d = rng.cosine(n);
            assert!((d.length() - 1.0).abs() < 1e-4 && d.dot(n) >= 0.0);
        }
        assert!(
            (sum / 10_000.0 - 0.5).abs() < 0.01,
            "mean {}",
            sum / 10_000.0
        );
        assert_eq!(Rng(9).next_u64(), Rng(9).next_u64());
        assert_ne!(Rng(9).next_u64(), Rng(10).next_u64());
    }
}
