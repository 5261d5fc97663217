//! `autopilot-link`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_autopilot_link::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::AutopilotLink,
            about: "The one MAVLink connection to the flight controller: vehicle state out, vehicle commands in",
        },
        skymesh_autopilot_link::run,
    )
}
