//! Teleoperation family: RemoteActionsRequest (304), RemoteActions (305),
//! ButtonEvent (306). The actions text is a TupleList (see [`crate::parse_tuple_list`]);
//! the codec carries it as text and the gateway parses it.

use crate::message::ids;
use crate::wire::{Reader, Writer};
use crate::{DecodeError, EncodeError, Message};

pub(crate) fn read(id: u16, r: &mut Reader<'_>) -> Result<Message, DecodeError> {
    Ok(match id {
        ids::REMOTE_ACTIONS_REQUEST => Message::RemoteActionsRequest {
            op: r.enumeration("op")?,
            actions: r.plaintext("actions")?,
        },
        ids::REMOTE_ACTIONS => Message::RemoteActions {
            actions: r.plaintext("actions")?,
        },
        ids::BUTTON_EVENT => Message::ButtonEvent {
            button: r.u8("button")?,
            value: r.u8("value")?,
        },
        other => return Err(DecodeError::UnknownId(other)),
    })
}

pub(crate) fn write(m: &Message, w: &mut Writer) -> Result<(), EncodeError> {
    match m {
        Message::RemoteActionsRequest { op, actions } => {
            w.u8(op.to_u8());
            w.plaintext("actions", actions)?;
        }
        Message::RemoteActions { actions } => w.plaintext("actions", actions)?,
        Message::ButtonEvent { button, value } => {
            w.u8(*button);
            w.u8(*value);
        }
        _ => {}
    }
    Ok(())
}
