//! FNV-1a (64-bit): a small deterministic hash for layout keys and file fingerprints (the
//! same value on every machine and run; not for security).

/// An FNV-1a hasher over 64-bit words: each word is xored in and the state multiplied by the
/// FNV prime.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fnv1a(u64);

impl Default for Fnv1a {
    fn default() -> Self {
        Self(0xcbf29ce484222325)
    }
}

impl Fnv1a {
    /// A hasher at the FNV offset basis.
    pub fn new() -> Self {
        Self::default()
    }

    /// Mix the word `v` in.
    pub fn mix(&mut self, v: u64) {
        self.0 = (self.0 ^ v).wrapping_mul(0x100000001b3);
    }

    /// Mix an index or count in.
    pub fn mix_usize(&mut self, v: usize) {
        self.mix(v as u64);
    }

    /// The hash so far.
    pub fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The published FNV-1a 64 test vectors: "" and "a" (byte by byte).
    #[test]
    fn matches_the_fnv1a_test_vectors() {
        assert_eq!(Fnv1a::new().finish(), 0xcbf29ce484222325);
        let mut h = Fnv1a::new();
        h.mix(u64::from(b'a'));
        assert_eq!(h.finish(), 0xaf63dc4c8601ec8c);
    }
}
