//! Companion devices family: LcdControl (307), LedBrightness (312),
//! QueryLedBrightness (313), SetLedBrightness (314), GpioState (2000),
//! GpioStateGet (2001), GpioStateSet (2002).

use crate::message::ids;
use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError, Message};

pub(crate) fn read(id: u16, r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    Ok(match id {
        ids::LCD_CONTROL => Message::LcdControl {
            op: r.enumeration("op")?,
            text: r.plaintext("text")?,
        },
        ids::LED_BRIGHTNESS => Message::LedBrightness {
            name: r.plaintext("name")?,
            value: r.u8("value")?,
        },
        ids::QUERY_LED_BRIGHTNESS => Message::QueryLedBrightness {
            name: r.plaintext("name")?,
        },
        ids::SET_LED_BRIGHTNESS => Message::SetLedBrightness {
            name: r.plaintext("name")?,
            value: r.u8("value")?,
        },
        ids::GPIO_STATE => Message::GpioState {
            name: r.plaintext("name")?,
            value: r.u8("value")?,
        },
        ids::GPIO_STATE_GET => Message::GpioStateGet {
            name: r.plaintext("name")?,
        },
        ids::GPIO_STATE_SET => Message::GpioStateSet {
            name: r.plaintext("name")?,
            value: r.u8("value")?,
        },
        other => return Err(DecodeError::UnknownId(other)),
    })
}

pub(crate) fn write(m: &Message, w: &mut Writer) -> Result<(), EncodeError> {
    match m {
        Message::LcdControl { op, text } => {
            w.u8(op.to_u8());
            w.plaintext("text", text)?;
        }
        Message::LedBrightness { name, value }
        | Message::SetLedBrightness { name, value }
        | Message::GpioState { name, value }
        | Message::GpioStateSet { name, value } => {
            w.plaintext("name", name)?;
            w.u8(*value);
        }
        Message::QueryLedBrightness { name } | Message::GpioStateGet { name } => {
            w.plaintext("name", name)?;
        }
        _ => {}
    }
    Ok(())
}
