//! The output side of the engine: command ids and validation, messages for the app
//! (dropped while no app is connected), and their metrics.

use skymesh_ipc_types::shot_api::ShotEvent;
use skymesh_ipc_types::{Command, CommandSource, VehicleCommand};

use super::MAX_ERROR_TEXT;
use crate::metrics::Metrics;

/// The output side: command ids, the pending outputs and their metrics.
#[derive(Debug)]
pub(crate) struct Out {
    pub vehicle_id: u8,
    pub max_age_ms: u32,
    pub next_id: u32,
    pub metrics: Metrics,
    /// As last learned from the gateway (or an app message).
    pub app_connected: bool,
    pub commands: Vec<VehicleCommand>,
    pub to_app: Vec<ShotEvent>,
}

impl Out {
    /// The id the next command will get.
    pub fn peek_id(&self) -> u32 {
        self.next_id
    }

    /// Queues `command`; `None` (logged) if it does not validate.
    pub fn command(&mut self, command: Command) -> Option<u32> {
        let id = self.next_id;
        let mut wire =
            match VehicleCommand::new(self.vehicle_id, CommandSource::ShotEngine, id, &command) {
                Ok(w) => w,
                Err(e) => {
                    tracing::warn!(?command, error = %e, "not sending an invalid command");
                    return None;
                }
            };
        if command.kind().is_setpoint() {
            wire.max_age_ms = self.max_age_ms;
        }
        self.next_id = self.next_id.wrapping_add(1).max(1);
        self.metrics.command_sent(command.kind().as_str());
        self.commands.push(wire);
        Some(id)
    }

    /// Queues a message for the app; dropped (debug log) when no app is connected.
    pub fn app(&mut self, msg: ShotEvent) {
        if !self.app_connected {
            tracing::debug!(msg = msg.name(), "no app connected; not sent");
            return;
        }
        self.metrics.app_out(msg.name());
        self.to_app.push(msg);
    }

    /// GET_CURRENT_SHOT; not sent for shots without a Solo index (Site Scan).
    pub fn current_shot(&mut self, shot: i32) {
        if !(skymesh_ipc_types::shot_api::shots::MIN..=skymesh_ipc_types::shot_api::shots::MAX)
            .contains(&shot)
        {
            tracing::debug!(shot, "no Solo shot index; GET_CURRENT_SHOT not sent");
            return;
        }
        self.app(ShotEvent::CurrentShot(shot));
    }

    /// SOLO_MESSAGE_SHOTMANAGER_ERROR, cut to [`MAX_ERROR_TEXT`] bytes.
    pub fn error(&mut self, text: &str) {
        let mut end = text.len().min(MAX_ERROR_TEXT);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.app(ShotEvent::Error(text[..end].to_string()));
    }
}
