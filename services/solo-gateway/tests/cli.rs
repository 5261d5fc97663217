//! The `skymesh-solo` binary against an in-process gateway.

mod common;

use std::process::Stdio;

use common::{other_host, Gateway, PATIENCE};
use skymesh_ipc_types::ShotEvent;
use skymesh_ipc_types::{topics, Button, ButtonEvent, ButtonEventKind, ServiceId};
use skymesh_runtime::{Bus, Stats};
use skymesh_solo_gateway::client::AppClient;
use solo_proto::{ids, SoloMessage};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

fn skymesh_solo(gw: &Gateway, args: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_skymesh-solo"))
        .arg("--addr")
        .arg(gw.tcp.to_string())
        .args(args)
        .env("SKYMESH_DOMAIN", &gw.domain.name)
        .env_remove("SKYMESH_IPC_CONFIG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("spawn skymesh-solo")
}

/// Reads the child's stdout until a line equal to `want` (returns the lines read).
async fn wait_line(child: &mut Child, want: &str) -> Vec<String> {
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let mut seen = Vec::new();
    let found = tokio::time::timeout(PATIENCE, async {
        while let Some(line) = lines.next_line().await.expect("read stdout") {
            let done = line == want;
            seen.push(line);
            if done {
                return true;
            }
        }
        false
    })
    .await;
    assert_eq!(found, Ok(true), "`{want}` not printed; got {seen:?}");
    seen
}

#[tokio::test]
async fn a_shot_command_is_sent_and_the_answer_printed() {
    let mut gw = Gateway::start().await;
    let mut cli = skymesh_solo(&gw, &["--wait", "60", "shot", "orbit"]);
    let got = gw.next_from_app().await;
    assert_eq!(got.msg_type, ids::SET_CURRENT_SHOT);
    assert_eq!(
        SoloMessage::decode(got.msg_type, got.value()),
        Ok(SoloMessage::SetCurrentShot(1))
    );
    gw.send_to_app(0, &ShotEvent::CurrentShot(1));
    wait_line(&mut cli, "GET_CURRENT_SHOT shot=orbit(1)").await;
    cli.kill().await.expect("kill");
    gw.stop().await;
}

#[tokio::test]
async fn a_button_press_goes_on_the_bus() {
    let gw = Gateway::start().await;
    let bus = Bus::open(
        &gw.domain,
        "button-reader",
        ServiceId::Tool,
        0,
        Stats::new(),
    )
    .expect("bus");
    let mut buttons = bus
        .subscriber::<ButtonEvent>(&topics::input_buttons())
        .expect("subscriber");
    let mut cli = skymesh_solo(&gw, &["--wait", "60", "button", "a"]);
    let event = buttons
        .recv_timeout(PATIENCE)
        .await
        .expect("recv")
        .expect("a button event");
    assert_eq!(event.button(), Ok(Button::A));
    assert_eq!(event.event(), Ok(ButtonEventKind::Press));
    assert_eq!(event.vehicle_id, 1);
    cli.kill().await.expect("kill");
    drop((buttons, bus));
    gw.stop().await;
}

#[tokio::test]
async fn a_second_phone_notification_is_an_error() {
    let mut gw = Gateway::start().await;
    let _phone = AppClient::connect_from(other_host(), gw.tcp)
        .await
        .expect("connect");
    gw.wait_connected(1).await;
    let cli = skymesh_solo(&gw, &["--wait", "60", "listen"]);
    let out = tokio::time::timeout(PATIENCE, cli.wait_with_output())
        .await
        .expect("exits")
        .expect("output");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("another phone"), "{stderr}");
    gw.stop().await;
}

#[tokio::test]
async fn no_gateway_is_a_clear_error() {
    let unused = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = unused.local_addr().expect("addr");
    drop(unused);
    let out = Command::new(env!("CARGO_BIN_EXE_skymesh-solo"))
        .args(["--addr", &addr.to_string(), "pause"])
        .output()
        .await
        .expect("run");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("cannot connect"), "{stderr}");
}
