//! `skymesh-camera`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_camera::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::Camera,
            about: "Camera frames into shared memory, written in place: a synthetic scene rendered for the vehicle's pose",
        },
        skymesh_camera::run,
    )
}
