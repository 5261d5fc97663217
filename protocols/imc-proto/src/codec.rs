//! One datagram: header, payload, CRC-16/ARC. Pure functions over byte slices.
//!
//! Decoding checks, in order: length bounds, sync (which also gives the byte order),
//! declared size against the bytes present, CRC over header and payload, message id,
//! then the fields and their ranges. Nothing is allocated before the CRC has matched.

use crc::{Crc, CRC_16_ARC};

use crate::catalog;
use crate::wire::{Reader, Writer};
use crate::{
    ByteOrder, DecodeError, EncodeError, Header, Message, Packet, CRC_LEN, HEADER_LEN,
    MAX_DATAGRAM, SYNC, SYNC_SWAPPED,
};

const ARC: Crc<u16> = Crc::<u16>::new(&CRC_16_ARC);

/// CRC-16/ARC (poly 0x8005 reflected, init 0, no final xor); check value 0xBB3D.
pub fn crc16_arc(bytes: &[u8]) -> u16 {
    ARC.checksum(bytes)
}

fn u16_at(buf: &[u8], at: usize, order: ByteOrder) -> u16 {
    let bytes = [buf[at], buf[at + 1]];
    match order {
        ByteOrder::Little => u16::from_le_bytes(bytes),
        ByteOrder::Big => u16::from_be_bytes(bytes),
    }
}

/// Reads the header fields of a datagram already known to hold `HEADER_LEN` bytes.
fn read_header(buf: &[u8], order: ByteOrder) -> Result<Header, DecodeError> {
    let mut r = Reader::new(&buf[..HEADER_LEN], order, "header");
    r.u16("sync")?;
    Ok(Header {
        mgid: r.u16("mgid")?,
        size: r.u16("size")?,
        timestamp: r.f64("timestamp")?,
        src: r.u16("src")?,
        src_ent: r.u8("src_ent")?,
        dst: r.u16("dst")?,
        dst_ent: r.u8("dst_ent")?,
    })
}

/// Decodes one datagram (either byte order), checking sync, size, CRC and fields.
///
/// The header's addresses and timestamp are passed through as sent (a peer's clock
/// is its own business); everything in the payload is checked.
pub fn decode_datagram(buf: &[u8]) -> Result<Packet, DecodeError> {
    let len = buf.len();
    if len < HEADER_LEN + CRC_LEN {
        return Err(DecodeError::TooShort { len });
    }
    if len > MAX_DATAGRAM {
        return Err(DecodeError::TooLong {
            len,
            max: MAX_DATAGRAM,
        });
    }
    let byte_order = match u16_at(buf, 0, ByteOrder::Little) {
        SYNC => ByteOrder::Little,
        SYNC_SWAPPED => ByteOrder::Big,
        other => return Err(DecodeError::BadSync(other)),
    };
    let header = read_header(buf, byte_order)?;
    let actual = len - HEADER_LEN - CRC_LEN;
    if usize::from(header.size) != actual {
        return Err(DecodeError::SizeMismatch {
            declared: usize::from(header.size),
            actual,
        });
    }
    let crc_at = len - CRC_LEN;
    let received = u16_at(buf, crc_at, byte_order);
    let computed = crc16_arc(&buf[..crc_at]);
    if received != computed {
        return Err(DecodeError::BadCrc { received, computed });
    }
    let name = catalog::message_name(header.mgid).ok_or(DecodeError::UnknownId(header.mgid))?;
    let mut r = Reader::new(&buf[HEADER_LEN..crc_at], byte_order, name);
    let message = catalog::read_fields(header.mgid, &mut r)?;
    r.finish()?;
    message.validate()?;
    Ok(Packet {
        header,
        byte_order,
        message,
    })
}

/// Encodes `message` little-endian with `header`'s timestamp and addresses
/// (`mgid` and `size` are computed).
pub fn encode_datagram(header: &Header, message: &Message) -> Result<Vec<u8>, EncodeError> {
    let mut payload = Writer::new(ByteOrder::Little, message.name());
    catalog::write_fields(message, &mut payload)?;
    let payload = payload.into_bytes();
    let total = HEADER_LEN + payload.len() + CRC_LEN;
    let too_long = EncodeError::TooLong {
        len: total,
        max: MAX_DATAGRAM,
    };
    if total > MAX_DATAGRAM {
        return Err(too_long);
    }
    let size = u16::try_from(payload.len()).map_err(|_| too_long)?;

    let mut w = Writer::new(ByteOrder::Little, message.name());
    w.u16(SYNC);
    w.u16(message.id());
    w.u16(size);
    w.f64(header.timestamp);
    w.u16(header.src);
    w.u8(header.src_ent);
    w.u16(header.dst);
    w.u8(header.dst_ent);
    let mut out = w.into_bytes();
    out.reserve_exact(payload.len() + CRC_LEN);
    out.extend_from_slice(&payload);
    let crc = crc16_arc(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(out)
}

impl Header {
    /// A header from `src`/`src_ent` to `dst`/`dst_ent` at `timestamp` (seconds since
    /// the Unix epoch); `mgid` and `size` are left 0 for [`encode_datagram`] to fill.
    pub fn new(timestamp: f64, src: u16, src_ent: u8, dst: u16, dst_ent: u8) -> Self {
        Header {
            mgid: 0,
            size: 0,
            timestamp,
            src,
            src_ent,
            dst,
            dst_ent,
        }
    }

    /// The header of a reply to this datagram: from `own_addr`/`own_ent` to this
    /// datagram's source system and entity. The timestamp is 0: set it with
    /// [`Header::with_timestamp`] (the codec has no clock).
    pub fn reply_to(&self, own_addr: u16, own_ent: u8) -> Self {
        Header::new(0.0, own_addr, own_ent, self.src, self.src_ent)
    }

    /// The same header at `timestamp` (seconds since the Unix epoch).
    pub fn with_timestamp(self, timestamp: f64) -> Self {
        Header { timestamp, ..self }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16_arc(b"123456789"), 0xBB3D);
        assert_eq!(crc16_arc(b""), 0);
    }

    #[test]
    fn heartbeat_round_trips() {
        let h = Header::new(1.5, 0x10, 2, 0x20, 255);
        let bytes = encode_datagram(&h, &Message::Heartbeat).expect("encodes");
        assert_eq!(bytes.len(), HEADER_LEN + CRC_LEN);
        let p = decode_datagram(&bytes).expect("decodes");
        assert_eq!(p.message, Message::Heartbeat);
        assert_eq!(p.byte_order, ByteOrder::Little);
        assert_eq!(
            p.header,
            Header {
                mgid: 150,
                size: 0,
                ..h
            }
        );
    }

    #[test]
    fn reply_goes_back_to_the_source() {
        let h = Header::new(7.0, 0x4001, 3, 0x2000, 255);
        let r = h.reply_to(0x2000, 1).with_timestamp(8.0);
        assert_eq!(r, Header::new(8.0, 0x2000, 1, 0x4001, 3));
    }
}
