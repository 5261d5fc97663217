//! `skymesh-imc-gateway`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_imc_gateway::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::ImcGateway,
            about: "LSTS IMC over UDP (Neptus, DUNE, any IMC peer) on the skymesh bus",
        },
        skymesh_imc_gateway::service::run_service,
    )
}
