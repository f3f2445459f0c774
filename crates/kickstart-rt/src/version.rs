//! The SDK's version, checked against the one the application was built with.

/// A semantic version.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Version {
    /// Incompatible API changes.
    pub major: u32,
    /// Compatible additions.
    pub minor: u32,
    /// Fixes.
    pub patch: u32,
}

impl std::fmt::Display for Version {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

const fn parse(s: &str) -> u32 {
    let b = s.as_bytes();
    let mut i = 0;
    let mut v = 0;
    while i < b.len() {
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    v
}

/// This library's version (the crate's Cargo version).
pub const VERSION: Version = Version {
    major: parse(env!("CARGO_PKG_VERSION_MAJOR")),
    minor: parse(env!("CARGO_PKG_VERSION_MINOR")),
    patch: parse(env!("CARGO_PKG_VERSION_PATCH")),
};
