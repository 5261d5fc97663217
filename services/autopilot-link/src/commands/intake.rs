//! Command intake: the checks a `VehicleCommand` sample passes before anything
//! else looks at it.

use skymesh_ipc_types::{Command, RefusalReason, VehicleCommand};

/// Why a command sample was not admitted.
#[derive(Debug, Clone, PartialEq)]
pub struct Refusal {
    pub reason: RefusalReason,
    pub detail: String,
}

/// Command intake: checks a sample before anything else looks at it.
///
/// Order: addressed to this vehicle, decodes to a valid [`Command`] (finite, in
/// range, known kind and source), link up.
pub fn admit(sample: &VehicleCommand, vehicle_id: u8, link_up: bool) -> Result<Command, Refusal> {
    if sample.vehicle_id != vehicle_id {
        return Err(Refusal {
            reason: RefusalReason::WrongVehicle,
            detail: format!(
                "for vehicle {}, this is vehicle {vehicle_id}",
                sample.vehicle_id
            ),
        });
    }
    let invalid = |e: skymesh_ipc_types::CommandError| Refusal {
        reason: e.reason(),
        detail: e.to_string(),
    };
    sample.source().map_err(invalid)?;
    let command = sample.command().map_err(invalid)?;
    if !link_up {
        return Err(Refusal {
            reason: RefusalReason::LinkDown,
            detail: "no autopilot heartbeat".to_string(),
        });
    }
    Ok(command)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acks::Origin;
    use skymesh_ipc_types::{CameraModeKind, CommandKind, CommandSource, FocusMode};

    #[test]
    fn new_payload_commands_pass_intake_from_the_wire() {
        for cmd in [
            Command::CameraMode {
                camera: 0,
                mode: CameraModeKind::Video,
            },
            Command::CameraCaptureStop { camera: 1 },
            Command::GimbalRate {
                pitch_rate_dps: 0.0,
                yaw_rate_dps: 0.0,
            },
            Command::CameraFocus {
                camera: 0,
                mode: FocusMode::Auto,
                value: 0.0,
            },
        ] {
            assert_eq!(admit(&sample(&cmd, 3), 1, true), Ok(cmd));
        }
        let mut bad = sample(
            &Command::GimbalRate {
                pitch_rate_dps: 1.0,
                yaw_rate_dps: 1.0,
            },
            4,
        );
        bad.f[0] = 400.0;
        let r = admit(&bad, 1, true).unwrap_err();
        assert_eq!(r.reason, RefusalReason::InvalidParameter);
        assert!(r.detail.contains("pitch_rate_dps"), "{}", r.detail);
    }

    fn sample(kind_cmd: &Command, id: u32) -> VehicleCommand {
        let mut s = VehicleCommand::new(1, CommandSource::Operator, id, kind_cmd).unwrap();
        s.header.seq = u64::from(id) + 100;
        s
    }

    #[test]
    fn intake_checks_vehicle_validity_and_link_in_that_order() {
        let good = sample(&Command::Land, 1);
        assert_eq!(admit(&good, 1, true), Ok(Command::Land));
        let r = admit(&good, 2, true).unwrap_err();
        assert_eq!(r.reason, RefusalReason::WrongVehicle);
        assert_eq!(
            admit(&good, 1, false).unwrap_err().reason,
            RefusalReason::LinkDown
        );
        let mut nan = sample(&Command::Takeoff { alt_rel_m: 5.0 }, 2);
        nan.f[0] = f32::NAN;
        let r = admit(&nan, 1, false).unwrap_err();
        assert_eq!(r.reason, RefusalReason::InvalidParameter);
        assert!(r.detail.contains("alt_rel_m"), "{}", r.detail);
        let mut bad_source = good;
        bad_source.source = 99;
        assert_eq!(
            admit(&bad_source, 1, true).unwrap_err().reason,
            RefusalReason::InvalidParameter
        );
        let o = Origin::of(&good);
        assert_eq!(
            (o.kind, o.command_id, o.command_seq),
            (CommandKind::Land.to_wire(), 1, 101)
        );
    }
}
