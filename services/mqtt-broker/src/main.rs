//! `skymesh-mqtt-broker`: CLI, config, logs, heartbeats and signals come from the
//! shared runtime; the broker is in the library.

fn main() -> std::process::ExitCode {
    skymesh_runtime::service_main::<skymesh_mqtt_broker::RawConfig, _, _>(
        skymesh_runtime::ServiceSpec {
            kind: skymesh_ipc_types::ServiceId::MqttBroker,
            about: "Embedded MQTT 3.1.1 broker (rumqttd) for the DJI Cloud API gateway",
        },
        skymesh_mqtt_broker::run,
    )
}
