//! System family: Heartbeat (150) and Announce (151).

use std::f64::consts::{FRAC_PI_2, PI};

use crate::catalog::check;
use crate::message::ids;
use crate::wire::{Reader, Writer};
use crate::{Announce, DecodeError, EncodeError, Message};

pub(crate) fn read(id: u16, r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    match id {
        ids::HEARTBEAT => Ok(Message::Heartbeat),
        ids::ANNOUNCE => Ok(Message::Announce(Announce {
            sys_name: r.plaintext("sys_name")?,
            sys_type: r.enumeration("sys_type")?,
            owner: r.u16("owner")?,
            lat: r.f64("lat")?,
            lon: r.f64("lon")?,
            height: r.f32("height")?,
            services: r.plaintext("services")?,
        })),
        other => Err(DecodeError::UnknownId(other)),
    }
}

pub(crate) fn write(m: &Message, w: &mut Writer) -> Result<(), EncodeError> {
    if let Message::Announce(a) = m {
        w.plaintext("sys_name", &a.sys_name)?;
        w.u8(a.sys_type.to_u8());
        w.u16(a.owner);
        w.f64(a.lat);
        w.f64(a.lon);
        w.f32(a.height);
        w.plaintext("services", &a.services)?;
    }
    Ok(())
}

pub(crate) fn validate(m: &Message) -> Result<(), DecodeError> {
    if let Message::Announce(a) = m {
        let name = "Announce";
        check(a.lat.abs() <= FRAC_PI_2, name, "lat", a.lat)?;
        check(a.lon.abs() <= PI, name, "lon", a.lon)?;
        check(a.height.is_finite(), name, "height", f64::from(a.height))?;
    }
    Ok(())
}
