//! A fingerprint of an estimator's built coefficients: FNV-1a (64 bit)
//! over their IEEE-754 bits, so two builds that would compute different
//! velocities from the same positions almost surely differ here.

/// FNV-1a, 64 bit (offset basis 0xcbf29ce484222325, prime 0x100000001b3).
#[derive(Debug, Clone, Copy)]
pub struct Fingerprint(u64);

impl Default for Fingerprint {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Fingerprint {
    pub fn bytes(mut self, b: &[u8]) -> Self {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
        self
    }

    pub fn u64(self, x: u64) -> Self {
        self.bytes(&x.to_le_bytes())
    }

    pub fn f64(self, x: f64) -> Self {
        self.u64(x.to_bits())
    }

    pub fn finish(self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_of_known_strings() {
        // The FNV reference values: "" → cbf29ce484222325, "a" → af63dc4c8601ec8c.
        assert_eq!(Fingerprint::default().finish(), 0xcbf2_9ce4_8422_2325);
        assert_eq!(
            Fingerprint::default().bytes(b"a").finish(),
            0xaf63_dc4c_8601_ec8c
        );
    }
}
