//! `skymesh-groundcontrol-gateway`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_groundcontrol_gateway::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::GroundcontrolGateway,
            about: "GroundControl's external interface (state server TCP 8000, pose broadcast UDP 6666) on the skymesh bus",
        },
        skymesh_groundcontrol_gateway::service::run_service,
    )
}
