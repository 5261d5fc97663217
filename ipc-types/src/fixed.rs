//! Fixed-capacity UTF-8 strings for shared-memory samples.

use iceoryx2::prelude::ZeroCopySend;

/// A UTF-8 string of at most `N` bytes stored inline and zero padded.
///
/// Writing truncates at a character boundary (never splits a code point) so a
/// reader always gets valid UTF-8; reading re-validates because the bytes came from
/// another process.
#[derive(Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct FixedStr<const N: usize> {
    bytes: [u8; N],
}

impl<const N: usize> FixedStr<N> {
    /// The empty string.
    pub const EMPTY: Self = Self { bytes: [0; N] };

    /// Copies `s`, truncated to fit at a character boundary.
    pub fn new(s: &str) -> Self {
        let mut out = Self::EMPTY;
        let mut end = s.len().min(N);
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        out.bytes[..end].copy_from_slice(&s.as_bytes()[..end]);
        out
    }

    /// The stored string up to the first NUL; `None` if another process wrote invalid UTF-8.
    pub fn try_as_str(&self) -> Option<&str> {
        let len = self.bytes.iter().position(|&b| b == 0).unwrap_or(N);
        core::str::from_utf8(&self.bytes[..len]).ok()
    }

    /// The stored string, or `"<invalid utf-8>"`.
    pub fn as_str(&self) -> &str {
        self.try_as_str().unwrap_or("<invalid utf-8>")
    }

    pub fn is_empty(&self) -> bool {
        self.bytes[0] == 0
    }

    pub const fn capacity() -> usize {
        N
    }
}

impl<const N: usize> Default for FixedStr<N> {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl<const N: usize> core::fmt::Debug for FixedStr<N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        core::fmt::Debug::fmt(self.as_str(), f)
    }
}

impl<const N: usize> core::fmt::Display for FixedStr<N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl<const N: usize> From<&str> for FixedStr<N> {
    fn from(s: &str) -> Self {
        Self::new(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_truncates_on_char_boundary() {
        let s = FixedStr::<8>::new("abc");
        assert_eq!(s.as_str(), "abc");
        let t = FixedStr::<4>::new("aéé"); // a(1) é(2) é(2) → only "aé" fits
        assert_eq!(t.as_str(), "aé");
        assert_eq!(FixedStr::<4>::new("abcdef").as_str(), "abcd");
        assert!(FixedStr::<4>::EMPTY.is_empty());
    }

    #[test]
    fn invalid_utf8_from_another_process_is_detected() {
        let mut s = FixedStr::<4>::EMPTY;
        s.bytes = [0xff, 0xfe, 0, 0];
        assert_eq!(s.try_as_str(), None);
        assert_eq!(s.as_str(), "<invalid utf-8>");
    }
}
