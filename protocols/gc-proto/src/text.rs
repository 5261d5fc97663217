//! `CMD_EXT_TEXT`: up to [`TEXT_MAX_BYTES`] bytes of text in a record's intParam2
//! (bytes 0..4) and its two i64 (bytes 4..12 and 12..20), NUL padded, as the
//! reference client packs it. intParam1 is reserved (the client sends 0).
//!
//! The reference client pads with NUL and encodes with the platform default (UTF-8
//! on .NET Core, in practice ASCII); skymesh reads and writes UTF-8 and refuses
//! invalid UTF-8 rather than guessing.

/// The most text bytes a record carries.
pub const TEXT_MAX_BYTES: usize = 20;

/// Why text cannot be packed or unpacked.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TextError {
    #[error("text is {len} bytes, a record carries at most {TEXT_MAX_BYTES}")]
    TooLong { len: usize },
    #[error("text contains a NUL byte (the padding character)")]
    ContainsNul,
    #[error("text is not valid UTF-8")]
    NotUtf8,
}

/// Packs `text` into `(intParam2, [i64; 2])`.
pub fn pack_text(text: &str) -> Result<(i32, [i64; 2]), TextError> {
    let b = text.as_bytes();
    if b.len() > TEXT_MAX_BYTES {
        return Err(TextError::TooLong { len: b.len() });
    }
    if b.contains(&0) {
        return Err(TextError::ContainsNul);
    }
    let mut all = [0u8; TEXT_MAX_BYTES];
    all[..b.len()].copy_from_slice(b);
    let int2 = i32::from_le_bytes([all[0], all[1], all[2], all[3]]);
    let mut l0 = [0u8; 8];
    let mut l1 = [0u8; 8];
    l0.copy_from_slice(&all[4..12]);
    l1.copy_from_slice(&all[12..20]);
    Ok((int2, [i64::from_le_bytes(l0), i64::from_le_bytes(l1)]))
}

/// Unpacks the text of a `CMD_EXT_TEXT` record: the 20 bytes up to the first NUL.
pub fn unpack_text(int2: i32, longs: [i64; 2]) -> Result<String, TextError> {
    let mut all = [0u8; TEXT_MAX_BYTES];
    all[0..4].copy_from_slice(&int2.to_le_bytes());
    all[4..12].copy_from_slice(&longs[0].to_le_bytes());
    all[12..20].copy_from_slice(&longs[1].to_le_bytes());
    let len = all.iter().position(|&b| b == 0).unwrap_or(TEXT_MAX_BYTES);
    std::str::from_utf8(&all[..len])
        .map(str::to_owned)
        .map_err(|_| TextError::NotUtf8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_packed_fixture() {
        // "HELLO SWARM" as the reference client sends it.
        let (int2, longs) = pack_text("HELLO SWARM").unwrap();
        assert_eq!(int2.to_le_bytes(), *b"HELL");
        assert_eq!(longs[0].to_le_bytes(), *b"O SWARM\0");
        assert_eq!(longs[1], 0);
        assert_eq!(unpack_text(int2, longs).unwrap(), "HELLO SWARM");
    }

    #[test]
    fn limits() {
        let twenty = "abcdefghijklmnopqrst";
        let (i, l) = pack_text(twenty).unwrap();
        assert_eq!(unpack_text(i, l).unwrap(), twenty);
        assert_eq!(
            pack_text("abcdefghijklmnopqrstu"),
            Err(TextError::TooLong { len: 21 })
        );
        assert_eq!(pack_text("a\0b"), Err(TextError::ContainsNul));
        assert_eq!(unpack_text(0, [0, 0]).unwrap(), "");
        // Multi-byte UTF-8 fits by bytes: 6 × "é" = 12 bytes.
        let (i, l) = pack_text("éééééé").unwrap();
        assert_eq!(unpack_text(i, l).unwrap(), "éééééé");
        // A code point cut by the 20-byte limit is not UTF-8.
        assert_eq!(
            unpack_text(i32::from_le_bytes([0xC3, b'a', b'b', b'c']), [0, 0]),
            Err(TextError::NotUtf8)
        );
    }
}
