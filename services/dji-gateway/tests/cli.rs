//! The `skymesh-dji-gateway` binary from outside: its shipped config, bad configs
//! refused with exit 64 naming the key, and a graceful SIGTERM while the cloud
//! broker is unreachable (the gateway keeps retrying, never exits on its own).

use skymesh_test_support::{shipped_config, Ready, ServiceCli};

fn gateway() -> ServiceCli {
    ServiceCli::new(env!("CARGO_BIN_EXE_skymesh-dji-gateway"), "djicli")
}

#[tokio::test]
async fn the_shipped_config_passes_its_check() {
    gateway()
        .expect_config_ok(&shipped_config("dji-gateway.toml"))
        .await;
}

#[tokio::test]
async fn bad_configs_exit_64_naming_the_key() {
    gateway()
        .expect_config_errors(&[
            ("gateway_sn = \"\"\n", "gateway_sn"),
            ("gateway_sn = \"dock 1/#\"\n", "gateway_sn"),
            ("[broker]\naddress = \"no-port\"\n", "address"),
            ("[broker]\ntls = true\n", "ca_file"),
            (
                "[broker]\nreconnect_initial_ms = 5000\nreconnect_max_ms = 100\n",
                "reconnect",
            ),
            ("[drc]\nstick_max_age_ms = 5\n", "stick_max_age_ms"),
            ("[drc]\nheartbeat_timeout_s = 0\n", "heartbeat_timeout_s"),
            (
                "[poi]\nmax_circle_speed_mps = -1.0\n",
                "max_circle_speed_mps",
            ),
            ("[payload]\npayload_index = \"camera\"\n", "payload_index"),
            ("unknown_key = 1\n", "unknown_key"),
        ])
        .await;
}

#[tokio::test]
async fn sigterm_stops_it_while_the_broker_is_unreachable() {
    // A port nothing listens on: the gateway retries with backoff, forever.
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind port 0");
        l.local_addr().expect("addr").port()
    };
    let config = format!(
        "gateway_sn = \"CLI-TEST\"\n[broker]\naddress = \"127.0.0.1:{port}\"\nreconnect_initial_ms = 50\nreconnect_max_ms = 200\n"
    );
    // SIGTERM once it has failed a connection attempt: it says so after its signal
    // handlers are installed (a fixed wait could end before that on a loaded machine).
    gateway()
        .sigterm_exits_cleanly(
            &config,
            Ready::StderrContains("cannot reach the cloud broker; retrying"),
        )
        .await;
}
