//! Why a datagram was refused. Every variant has a stable [`DecodeError::kind`] for
//! metric labels.

/// A datagram that is not a valid IMC message of the implemented set.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("datagram of {len} bytes is shorter than a header and CRC")]
    TooShort { len: usize },
    #[error("datagram of {len} bytes is longer than {max}")]
    TooLong { len: usize, max: usize },
    #[error("bad sync number {0:#06x}")]
    BadSync(u16),
    #[error("header declares {declared} payload bytes, datagram holds {actual}")]
    SizeMismatch { declared: usize, actual: usize },
    #[error("CRC {received:#06x} does not match computed {computed:#06x}")]
    BadCrc { received: u16, computed: u16 },
    #[error("message id {0} is not implemented")]
    UnknownId(u16),
    #[error("{message}: payload ends inside field {field}")]
    Truncated {
        message: &'static str,
        field: &'static str,
    },
    #[error("{message}: {extra} bytes after the last field")]
    TrailingBytes { message: &'static str, extra: usize },
    #[error("{message}: field {field} has invalid value {value}")]
    InvalidValue {
        message: &'static str,
        field: &'static str,
        value: f64,
    },
    #[error("{message}: field {field} is not valid UTF-8")]
    InvalidText {
        message: &'static str,
        field: &'static str,
    },
}

impl DecodeError {
    /// A stable label: `too_short`, `too_long`, `bad_sync`, `size_mismatch`, `bad_crc`,
    /// `unknown_id`, `truncated`, `trailing_bytes`, `invalid_value`, `invalid_text`.
    pub fn kind(&self) -> &'static str {
        match self {
            DecodeError::TooShort { .. } => "too_short",
            DecodeError::TooLong { .. } => "too_long",
            DecodeError::BadSync(_) => "bad_sync",
            DecodeError::SizeMismatch { .. } => "size_mismatch",
            DecodeError::BadCrc { .. } => "bad_crc",
            DecodeError::UnknownId(_) => "unknown_id",
            DecodeError::Truncated { .. } => "truncated",
            DecodeError::TrailingBytes { .. } => "trailing_bytes",
            DecodeError::InvalidValue { .. } => "invalid_value",
            DecodeError::InvalidText { .. } => "invalid_text",
        }
    }
}

/// A message that cannot be written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EncodeError {
    #[error("{message}: text field {field} is {len} bytes, more than 65535")]
    TextTooLong {
        message: &'static str,
        field: &'static str,
        len: usize,
    },
    #[error("encoded datagram of {len} bytes exceeds {max}")]
    TooLong { len: usize, max: usize },
}
