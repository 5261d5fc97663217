//! `skymesh-dji-gateway`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_dji_gateway::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::DjiGateway,
            about: "DJI Cloud API live flight controls (device side) over MQTT",
        },
        skymesh_dji_gateway::service::run_service,
    )
}
