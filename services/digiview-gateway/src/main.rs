//! `skymesh-digiview`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_digiview_gateway::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::DigiviewGateway,
            about: "DigiView's TCP protocol (port 8555) onto the skymesh vision pipeline",
        },
        skymesh_digiview_gateway::service::run_service,
    )
}
