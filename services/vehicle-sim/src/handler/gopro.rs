//! The Solo gimbal's GoPro bridge: GOPRO_SET_REQUEST / GOPRO_GET_REQUEST in,
//! GOPRO_SET_RESPONSE / GOPRO_GET_RESPONSE out from the gimbal (component 154).
//! Without a GoPro (`gopro = false`) requests go unanswered, as with no camera
//! on the gimbal.

use mavlink::dialects::ardupilotmega::{
    GoproRequestStatus, MavMessage, GOPRO_GET_REQUEST_DATA, GOPRO_GET_RESPONSE_DATA,
    GOPRO_SET_REQUEST_DATA, GOPRO_SET_RESPONSE_DATA,
};
use tracing::{debug, info};

use super::{GoProRequest, Outgoing, Response};
use crate::model::Vehicle;

/// Apply a setting; answer SUCCESS or FAILED.
pub(super) fn set_request(
    v: &mut Vehicle,
    d: &GOPRO_SET_REQUEST_DATA,
    from: u32,
    resp: &mut Response,
) {
    let Some(result) = v.gopro_set(d.cmd_id, d.value) else {
        debug!(from, cmd = ?d.cmd_id, "GOPRO_SET_REQUEST ignored: no GoPro");
        return;
    };
    let status = match result {
        Ok(()) => {
            info!(from, cmd = ?d.cmd_id, value = ?d.value, "GoPro set");
            GoproRequestStatus::GOPRO_REQUEST_SUCCESS
        }
        Err(why) => {
            info!(from, cmd = ?d.cmd_id, value = ?d.value, %why, "GoPro set refused");
            GoproRequestStatus::GOPRO_REQUEST_FAILED
        }
    };
    resp.replies
        .push(Outgoing::from_gimbal(MavMessage::GOPRO_SET_RESPONSE(
            GOPRO_SET_RESPONSE_DATA {
                cmd_id: d.cmd_id,
                status,
            },
        )));
    resp.gopro = Some((GoProRequest::Set, status));
}

/// Read a setting; a refusal is FAILED with zero value bytes.
pub(super) fn get_request(v: &Vehicle, d: &GOPRO_GET_REQUEST_DATA, from: u32, resp: &mut Response) {
    let Some(gopro) = v.gopro() else {
        debug!(from, cmd = ?d.cmd_id, "GOPRO_GET_REQUEST ignored: no GoPro");
        return;
    };
    let (status, value) = match gopro.get(d.cmd_id) {
        Ok(value) => (GoproRequestStatus::GOPRO_REQUEST_SUCCESS, value),
        Err(why) => {
            debug!(from, cmd = ?d.cmd_id, %why, "GoPro get refused");
            (GoproRequestStatus::GOPRO_REQUEST_FAILED, [0; 4])
        }
    };
    resp.replies
        .push(Outgoing::from_gimbal(MavMessage::GOPRO_GET_RESPONSE(
            GOPRO_GET_RESPONSE_DATA {
                cmd_id: d.cmd_id,
                status,
                value,
            },
        )));
    resp.gopro = Some((GoProRequest::Get, status));
}
