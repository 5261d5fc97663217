//! Field primitives in either byte order: integers, floats, plaintext, rawdata,
//! inline message and message list.
//!
//! A [`Reader`] walks one payload and names the message and field in every error;
//! a [`Writer`] builds one. The datagram codec uses them little-endian out and in the
//! sender's order in; they are public so a message added later (or a test) can use
//! the same primitives, including the inline message (`u16 id` then that message's
//! fields, [`INLINE_NONE`] for none) and the message list (`u16 count` then inline
//! messages) that none of the implemented messages carries yet.

use crate::catalog;
use crate::{ByteOrder, DecodeError, EncodeError, Message, HEADER_LEN, INLINE_NONE, MAX_DATAGRAM};

/// Reads fields in order from one payload.
#[derive(Debug)]
pub struct Reader<'a> {
    rest: &'a [u8],
    order: ByteOrder,
    /// The message being read, named in errors (changes inside an inline message).
    message: &'static str,
}

macro_rules! read_number {
    ($(#[$meta:meta])* $name:ident, $t:ty) => {
        $(#[$meta])*
        pub fn $name(&mut self, field: &'static str) -> Result<$t, DecodeError> {
            let bytes = self.take::<{ std::mem::size_of::<$t>() }>(field)?;
            Ok(match self.order {
                ByteOrder::Little => <$t>::from_le_bytes(bytes),
                ByteOrder::Big => <$t>::from_be_bytes(bytes),
            })
        }
    };
}

impl<'a> Reader<'a> {
    /// A reader over `payload` written in `order`, for the message named `message`.
    pub fn new(payload: &'a [u8], order: ByteOrder, message: &'static str) -> Self {
        Reader {
            rest: payload,
            order,
            message,
        }
    }

    /// The byte order fields are read in.
    pub fn byte_order(&self) -> ByteOrder {
        self.order
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.rest.len()
    }

    /// The message named in errors.
    pub fn message(&self) -> &'static str {
        self.message
    }

    /// A [`DecodeError::InvalidValue`] for `field` of the current message.
    pub fn invalid(&self, field: &'static str, value: f64) -> DecodeError {
        DecodeError::InvalidValue {
            message: self.message,
            field,
            value,
        }
    }

    fn truncated(&self, field: &'static str) -> DecodeError {
        DecodeError::Truncated {
            message: self.message,
            field,
        }
    }

    fn take<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DecodeError> {
        match self.rest.split_first_chunk::<N>() {
            Some((head, tail)) => {
                self.rest = tail;
                Ok(*head)
            }
            None => Err(self.truncated(field)),
        }
    }

    fn take_slice(&mut self, field: &'static str, len: usize) -> Result<&'a [u8], DecodeError> {
        if self.rest.len() < len {
            return Err(self.truncated(field));
        }
        let (head, tail) = self.rest.split_at(len);
        self.rest = tail;
        Ok(head)
    }

    read_number!(
        /// `uint8_t`.
        u8, u8
    );
    read_number!(
        /// `int8_t`.
        i8, i8
    );
    read_number!(
        /// `uint16_t`.
        u16, u16
    );
    read_number!(
        /// `int16_t`.
        i16, i16
    );
    read_number!(
        /// `uint32_t`.
        u32, u32
    );
    read_number!(
        /// `int32_t`.
        i32, i32
    );
    read_number!(
        /// `uint64_t`.
        u64, u64
    );
    read_number!(
        /// `int64_t`.
        i64, i64
    );
    read_number!(
        /// `fp32_t` as written (NaN and ±∞ included: range checks are the message's).
        f32, f32
    );
    read_number!(
        /// `fp64_t` as written (NaN and ±∞ included: range checks are the message's).
        f64, f64
    );

    /// A `uint8_t` enumeration: a value outside it is [`DecodeError::InvalidValue`].
    pub fn enumeration<E: TryFrom<u8, Error = u8>>(
        &mut self,
        field: &'static str,
    ) -> Result<E, DecodeError> {
        let raw = self.u8(field)?;
        E::try_from(raw).map_err(|v| self.invalid(field, f64::from(v)))
    }

    /// `rawdata`: `u16` length then that many bytes.
    pub fn rawdata(&mut self, field: &'static str) -> Result<Vec<u8>, DecodeError> {
        let len = self.u16(field)?;
        Ok(self.take_slice(field, usize::from(len))?.to_vec())
    }

    /// `plaintext`: `u16` length then that many bytes of UTF-8.
    pub fn plaintext(&mut self, field: &'static str) -> Result<String, DecodeError> {
        let len = self.u16(field)?;
        let bytes = self.take_slice(field, usize::from(len))?;
        match std::str::from_utf8(bytes) {
            Ok(text) => Ok(text.to_owned()),
            Err(_) => Err(DecodeError::InvalidText {
                message: self.message,
                field,
            }),
        }
    }

    /// An inline message: `u16` id ([`INLINE_NONE`] → `None`) then its fields, checked
    /// like a top-level message (an id outside the implemented set is
    /// [`DecodeError::UnknownId`]: its length is unknown, so nothing after it can be read).
    pub fn inline_message(&mut self, field: &'static str) -> Result<Option<Message>, DecodeError> {
        let id = self.u16(field)?;
        if id == INLINE_NONE {
            return Ok(None);
        }
        self.nested(id).map(Some)
    }

    /// A message list: `u16` count then that many inline messages (none may be
    /// [`INLINE_NONE`]).
    pub fn message_list(&mut self, field: &'static str) -> Result<Vec<Message>, DecodeError> {
        let count = usize::from(self.u16(field)?);
        // Every element takes at least its two id bytes: a lying count cannot make us
        // reserve more than the payload could hold.
        let mut list = Vec::with_capacity(count.min(self.rest.len() / 2));
        for _ in 0..count {
            let id = self.u16(field)?;
            if id == INLINE_NONE {
                return Err(self.invalid(field, f64::from(id)));
            }
            list.push(self.nested(id)?);
        }
        Ok(list)
    }

    /// Reads the fields of message `id` in place, naming it in errors meanwhile.
    fn nested(&mut self, id: u16) -> Result<Message, DecodeError> {
        let name = catalog::message_name(id).ok_or(DecodeError::UnknownId(id))?;
        let outer = std::mem::replace(&mut self.message, name);
        let result = catalog::read_fields(id, self).and_then(|m| m.validate().map(|()| m));
        self.message = outer;
        result
    }

    /// Ends the payload: bytes left over are [`DecodeError::TrailingBytes`].
    pub fn finish(self) -> Result<(), DecodeError> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(DecodeError::TrailingBytes {
                message: self.message,
                extra: self.rest.len(),
            })
        }
    }
}

/// Builds one payload field by field.
#[derive(Debug)]
pub struct Writer {
    buf: Vec<u8>,
    order: ByteOrder,
    /// The message being written, named in errors (changes inside an inline message).
    message: &'static str,
}

macro_rules! write_number {
    ($(#[$meta:meta])* $name:ident, $t:ty) => {
        $(#[$meta])*
        pub fn $name(&mut self, v: $t) {
            match self.order {
                ByteOrder::Little => self.buf.extend_from_slice(&v.to_le_bytes()),
                ByteOrder::Big => self.buf.extend_from_slice(&v.to_be_bytes()),
            }
        }
    };
}

impl Writer {
    /// An empty payload in `order` for the message named `message`.
    pub fn new(order: ByteOrder, message: &'static str) -> Self {
        Writer {
            buf: Vec::new(),
            order,
            message,
        }
    }

    /// Bytes written so far.
    pub fn len(&self) -> usize {
        self.buf.len()
    }

    /// Nothing written yet.
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// The payload.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }

    write_number!(
        /// `uint8_t`.
        u8, u8
    );
    write_number!(
        /// `int8_t`.
        i8, i8
    );
    write_number!(
        /// `uint16_t`.
        u16, u16
    );
    write_number!(
        /// `int16_t`.
        i16, i16
    );
    write_number!(
        /// `uint32_t`.
        u32, u32
    );
    write_number!(
        /// `int32_t`.
        i32, i32
    );
    write_number!(
        /// `uint64_t`.
        u64, u64
    );
    write_number!(
        /// `int64_t`.
        i64, i64
    );
    write_number!(
        /// `fp32_t`.
        f32, f32
    );
    write_number!(
        /// `fp64_t`.
        f64, f64
    );

    /// `rawdata`: `u16` length then the bytes; more than 65535 is
    /// [`EncodeError::TextTooLong`].
    pub fn rawdata(&mut self, field: &'static str, bytes: &[u8]) -> Result<(), EncodeError> {
        let len = u16::try_from(bytes.len()).map_err(|_| EncodeError::TextTooLong {
            message: self.message,
            field,
            len: bytes.len(),
        })?;
        self.u16(len);
        self.buf.extend_from_slice(bytes);
        Ok(())
    }

    /// `plaintext`: `u16` length then the UTF-8 bytes.
    pub fn plaintext(&mut self, field: &'static str, text: &str) -> Result<(), EncodeError> {
        self.rawdata(field, text.as_bytes())
    }

    /// An inline message: `u16` id then its fields, or [`INLINE_NONE`] for `None`.
    pub fn inline_message(&mut self, message: Option<&Message>) -> Result<(), EncodeError> {
        match message {
            None => {
                self.u16(INLINE_NONE);
                Ok(())
            }
            Some(m) => self.nested(m),
        }
    }

    /// A message list: `u16` count then inline messages. More than 65535 messages
    /// cannot fit a datagram: [`EncodeError::TooLong`].
    pub fn message_list(&mut self, messages: &[Message]) -> Result<(), EncodeError> {
        let count = u16::try_from(messages.len()).map_err(|_| EncodeError::TooLong {
            // At least the two id bytes of every element.
            len: HEADER_LEN + self.buf.len() + 2 * messages.len(),
            max: MAX_DATAGRAM,
        })?;
        self.u16(count);
        messages.iter().try_for_each(|m| self.nested(m))
    }

    fn nested(&mut self, m: &Message) -> Result<(), EncodeError> {
        self.u16(m.id());
        let outer = std::mem::replace(&mut self.message, m.name());
        let result = catalog::write_fields(m, self);
        self.message = outer;
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_follow_the_byte_order() {
        let mut le = Writer::new(ByteOrder::Little, "t");
        let mut be = Writer::new(ByteOrder::Big, "t");
        for w in [&mut le, &mut be] {
            w.u16(0x0102);
            w.i32(-2);
            w.f32(1.0);
        }
        assert_eq!(
            le.into_bytes(),
            [0x02, 0x01, 0xFE, 0xFF, 0xFF, 0xFF, 0x00, 0x00, 0x80, 0x3F]
        );
        assert_eq!(
            be.into_bytes(),
            [0x01, 0x02, 0xFF, 0xFF, 0xFF, 0xFE, 0x3F, 0x80, 0x00, 0x00]
        );
    }

    #[test]
    fn a_short_field_names_message_and_field() {
        let mut r = Reader::new(&[1, 2, 3], ByteOrder::Little, "Msg");
        assert_eq!(r.u16("a"), Ok(0x0201));
        assert_eq!(
            r.u16("b"),
            Err(DecodeError::Truncated {
                message: "Msg",
                field: "b"
            })
        );
    }
}
