//! `skymesh-swarm-queue`: CLI, config, logs, heartbeats and signals come from the
//! shared runtime; the queue is in the library.

fn main() -> std::process::ExitCode {
    // `animations_dir` is relative to the config file's directory.
    skymesh_swarm_queue::config::set_config_dir_from_args();
    skymesh_runtime::service_main::<skymesh_swarm_queue::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::SwarmQueue,
            about: "GroundControl swarm queue: per-drone command queues flown through the arbiter, site frame, animations, swarm state",
        },
        skymesh_swarm_queue::run,
    )
}
