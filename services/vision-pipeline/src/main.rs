//! `skymesh-vision`: see the library docs; the runtime does the rest.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_vision_pipeline::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::VisionPipeline,
            about: "Vision pipeline: detection, tracking, virtual cameras, geolocation and captures on shared-memory camera frames",
        },
        skymesh_vision_pipeline::run,
    )
}
