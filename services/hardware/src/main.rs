//! `skymesh-hardware`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_hardware::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::Hardware,
            about: "The companion computer's LEDs, GPIO lines, power channels, LCD and power on the skymesh bus",
        },
        skymesh_hardware::service::run_service,
    )
}
