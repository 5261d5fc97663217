//! `skymesh-shot-engine`: CLI, config, logs, heartbeats and signals come from the
//! shared runtime; the engine is in the library.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_shot_engine::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::ShotEngine,
            about: "Smart shots for the Solo app (selfie, orbit, follow, cable cam), flying through the arbiter",
        },
        skymesh_shot_engine::run,
    )
}
