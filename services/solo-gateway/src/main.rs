//! `skymesh-solo-gateway`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_solo_gateway::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::SoloGateway,
            about:
                "The 3DR Solo app protocol (TCP 5507, follow stream UDP 14558) on the skymesh bus",
        },
        skymesh_solo_gateway::service::run_service,
    )
}
