//! Arbitrary bytes as one IMC datagram (imc-gateway, UDP 6002), and as a message
//! list read by the field primitives.
//!
//! Checks, beyond "never panics": every accepted datagram re-encodes (little-endian)
//! to a datagram that decodes to the same message and header; a little-endian input
//! re-encodes to exactly its own bytes; a message list that reads re-writes to the
//! bytes it consumed, in either byte order.
#![no_main]

use imc_proto::wire::{Reader, Writer};
use imc_proto::{decode_datagram, encode_datagram, ByteOrder, Header};
use libfuzzer_sys::fuzz_target;

/// Headers compared with the timestamp as bits (a NaN timestamp is not refused).
fn same_header(a: &Header, b: &Header) -> bool {
    Header {
        timestamp: 0.0,
        ..*a
    } == Header {
        timestamp: 0.0,
        ..*b
    } && a.timestamp.to_bits() == b.timestamp.to_bits()
}

fn check_datagram(data: &[u8]) {
    let Ok(packet) = decode_datagram(data) else {
        return;
    };
    let bytes = match encode_datagram(&packet.header, &packet.message) {
        Ok(bytes) => bytes,
        Err(e) => panic!("{} decoded but does not encode: {e}", packet.message.name()),
    };
    let again = match decode_datagram(&bytes) {
        Ok(again) => again,
        Err(e) => panic!("{} re-encoded does not decode: {e}", packet.message.name()),
    };
    assert_eq!(again.message, packet.message, "message changed");
    assert!(same_header(&again.header, &packet.header), "header changed");
    assert_eq!(again.byte_order, ByteOrder::Little);
    if packet.byte_order == ByteOrder::Little {
        assert_eq!(bytes, data, "little-endian input re-encodes differently");
    }
}

fn check_list(data: &[u8]) {
    let Some((&first, rest)) = data.split_first() else {
        return;
    };
    let order = if first & 1 == 0 {
        ByteOrder::Little
    } else {
        ByteOrder::Big
    };
    let mut r = Reader::new(rest, order, "fuzz");
    let Ok(list) = r.message_list("list") else {
        return;
    };
    let consumed = rest.len() - r.remaining();
    let mut w = Writer::new(order, "fuzz");
    if let Err(e) = w.message_list(&list) {
        panic!("list read but does not write: {e}");
    }
    assert_eq!(
        w.into_bytes(),
        &rest[..consumed],
        "list re-writes differently"
    );
}

fuzz_target!(|data: &[u8]| {
    check_datagram(data);
    check_list(data);
});
