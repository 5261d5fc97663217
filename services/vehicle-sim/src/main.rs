//! `skymesh-vehicle-sim`: CLI, config, logs, heartbeats and signals come from the
//! shared runtime; the simulation is in the library.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_vehicle_sim::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::VehicleSim,
            about: "A simulated multicopter that looks like ArduCopter on the MAVLink 2 wire",
        },
        skymesh_vehicle_sim::service::run_service,
    )
}
