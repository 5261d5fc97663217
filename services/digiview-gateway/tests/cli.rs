//! The `skymesh-digiview` binary from outside: its shipped config, bad configs
//! refused with exit 64 naming the key, and a graceful SIGTERM.

use skymesh_test_support::{shipped_config, Ready, ServiceCli};

fn gateway() -> ServiceCli {
    ServiceCli::new(env!("CARGO_BIN_EXE_skymesh-digiview"), "dvcli")
}

#[tokio::test]
async fn the_shipped_config_passes_its_check() {
    gateway()
        .expect_config_ok(&shipped_config("digiview-gateway.toml"))
        .await;
}

#[tokio::test]
async fn bad_configs_exit_64_naming_the_key() {
    gateway()
        .expect_config_errors(&[
            ("listen = \"nowhere\"\n", "listen"),
            ("write_allowed = [\"300.1.1.1\"]\n", "write_allowed"),
            ("max_clients = 0\n", "max_clients"),
            ("roi_rel_frame = 7\n", "roi_rel_frame"),
            ("set_timeout_ms = -1\n", "set_timeout_ms"),
            ("unknown_key = 1\n", "unknown_key"),
        ])
        .await;
}

#[tokio::test]
async fn sigterm_stops_it_cleanly() {
    // Until it serves (it runs without a pipeline: GETs would be UNKNOWN). Its
    // signal handlers are in place before that line; a fixed second was not always
    // enough for a debug build on a busy machine, and SIGTERM then killed it.
    gateway()
        .sigterm_exits_cleanly(
            "listen = \"127.0.0.1:0\"\n",
            Ready::StderrContains("digiview-gateway serving DigiView clients"),
        )
        .await;
}
