//! While the autopilot flies its own failsafe, only manual RC may change the
//! mode or the motion.

use skymesh_ipc_types::{Command, CommandSource, FlightMode};

/// The autopilot flies its own failsafe (or a pilot's choice of it): RTL, LAND,
/// SmartRTL.
pub(super) fn in_failsafe(mode: FlightMode) -> bool {
    matches!(
        mode,
        FlightMode::Rtl | FlightMode::Land | FlightMode::SmartRtl
    )
}

/// Why `command` from `source` may not run while the autopilot flies its failsafe
/// in `mode`; `None` when it may. Sources below manual RC may not change the mode
/// or the motion: `SetMode`, `Brake`, `GoTo`, `VelocityNed`, `Takeoff`, `SetYaw`,
/// `SetHome` (it moves where RTL goes), and RTL during LAND (a LAND failsafe
/// usually means too little battery to fly back). `Land` stays allowed (it ends the
/// flight where the vehicle is, as the autopilot's own escalation would); so do the
/// camera's ROI, payload commands and an emergency stop (which holds the
/// failsafe's descent rather than overriding it).
pub(super) fn failsafe_refusal(
    mode: FlightMode,
    source: CommandSource,
    command: &Command,
) -> Option<String> {
    if !in_failsafe(mode) || source.priority() >= CommandSource::ManualRc.priority() {
        return None;
    }
    let refused = match command {
        Command::SetMode(_)
        | Command::Brake
        | Command::GoTo { .. }
        | Command::VelocityNed { .. }
        | Command::Takeoff { .. }
        | Command::SetYaw { .. }
        | Command::SetHome { .. } => true,
        Command::ReturnToLaunch => mode != FlightMode::Rtl,
        _ => false,
    };
    refused.then(|| format!("{mode} failsafe held: manual RC only"))
}
