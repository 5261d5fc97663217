//! Errors of the codec. Framing errors ([`FrameError`]) end a connection; value
//! errors ([`DecodeError`]) concern one frame, which the framer has already consumed
//! whole, so the caller drops it, counts it by [`DecodeError::kind`] and reads on.

/// A frame's value could not be read as the message its type names.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("unknown message type {0}")]
    UnknownType(u32),
    /// For variable-length types `expected` is the largest accepted length.
    #[error("{name} (type {msg_type}): value is {got} bytes, expected {expected}")]
    WrongLength {
        msg_type: u32,
        name: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{name} (type {msg_type}): {what}")]
    InvalidValue {
        msg_type: u32,
        name: &'static str,
        what: String,
    },
}

impl DecodeError {
    /// Bounded metric label: `unknown_type`, `wrong_length` or `invalid_value`.
    pub fn kind(&self) -> &'static str {
        match self {
            DecodeError::UnknownType(_) => "unknown_type",
            DecodeError::WrongLength { .. } => "wrong_length",
            DecodeError::InvalidValue { .. } => "invalid_value",
        }
    }

    /// The type id of the offending frame.
    pub fn msg_type(&self) -> u32 {
        match self {
            DecodeError::UnknownType(t) => *t,
            DecodeError::WrongLength { msg_type, .. }
            | DecodeError::InvalidValue { msg_type, .. } => *msg_type,
        }
    }
}

/// The byte stream cannot be framed any further: close the connection.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("declared value length {declared} exceeds the maximum {max}")]
    TooLong { declared: u32, max: usize },
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

impl FrameError {
    /// Bounded metric label: `too_long` or `io`.
    pub fn kind(&self) -> &'static str {
        match self {
            FrameError::TooLong { .. } => "too_long",
            FrameError::Io(_) => "io",
        }
    }
}

/// A UDP datagram is not exactly one valid frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DatagramError {
    #[error("datagram of {got} bytes is shorter than the {HEADER_LEN}-byte header", HEADER_LEN = crate::HEADER_LEN)]
    ShortHeader { got: usize },
    #[error("datagram declares a {declared}-byte value but carries {got} bytes")]
    Truncated { declared: u32, got: usize },
    #[error("datagram carries {extra} bytes after its {declared}-byte value")]
    TrailingBytes { declared: u32, extra: usize },
    #[error(transparent)]
    Decode(#[from] DecodeError),
}

impl DatagramError {
    /// Bounded metric label: `short_header`, `truncated`, `trailing_bytes`, or the
    /// [`DecodeError::kind`] of the value.
    pub fn kind(&self) -> &'static str {
        match self {
            DatagramError::ShortHeader { .. } => "short_header",
            DatagramError::Truncated { .. } => "truncated",
            DatagramError::TrailingBytes { .. } => "trailing_bytes",
            DatagramError::Decode(e) => e.kind(),
        }
    }
}
