//! LED, GPIO, power channel, LCD and companion power messages become
//! HardwareRequests (answered here by a fake hardware service) and the IMC replies
//! the document prescribes.

mod common;

use std::time::Duration;

use common::{barrier, expect, next_reply, settings, Gateway};
use imc_proto::{ChannelOp, ChannelState, LcdOperation, Message, PowerOp};
use skymesh_ipc_types::{
    HardwareOp, HardwareResult, HardwareState, HwName, LcdOp, PowerChannelOp, SystemPowerOp,
};

#[tokio::test]
async fn leds_and_gpio_are_set_queried_and_answered() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;

    peer.send(&Message::SetLedBrightness {
        name: "status".into(),
        value: 200,
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::LedSet));
    assert_eq!((req.name.as_str(), req.value), ("status", 200));
    gw.hw_reply(&req, HardwareResult::Ok, 200);
    assert_eq!(
        next_reply(&peer).await,
        Message::LedBrightness {
            name: "status".into(),
            value: 200
        }
    );

    peer.send(&Message::QueryLedBrightness {
        name: "status".into(),
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::LedQuery));
    gw.hw_reply(&req, HardwareResult::Ok, 200);
    assert_eq!(
        next_reply(&peer).await,
        Message::LedBrightness {
            name: "status".into(),
            value: 200
        }
    );

    peer.send(&Message::GpioStateSet {
        name: "camera_trigger".into(),
        value: 1,
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::GpioSet));
    assert_eq!(req.value, 1);
    gw.hw_reply(&req, HardwareResult::Ok, 1);
    assert_eq!(
        next_reply(&peer).await,
        Message::GpioState {
            name: "camera_trigger".into(),
            value: 1
        }
    );
    peer.send(&Message::GpioStateGet {
        name: "camera_trigger".into(),
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::GpioGet));
    gw.hw_reply(&req, HardwareResult::Ok, 1);
    assert_eq!(
        next_reply(&peer).await,
        Message::GpioState {
            name: "camera_trigger".into(),
            value: 1
        }
    );

    // An unknown name: no IMC reply (the protocol has none), counted.
    peer.send(&Message::QueryLedBrightness {
        name: "nope".into(),
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    gw.hw_reply(&req, HardwareResult::UnknownName, 0);
    gw.wait_dropped("hardware_unknown_name", 1.0).await;
    barrier(&peer).await;
    gw.stop().await;
}

#[tokio::test]
async fn power_channels_toggle_schedule_and_report_from_the_state() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;

    peer.send(&Message::PowerChannelControl {
        name: "payload".into(),
        op: ChannelOp::Toggle,
        sched_time: 0.0,
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::PowerChannel));
    assert_eq!(req.sub_op, PowerChannelOp::Toggle.to_wire());
    gw.hw_reply(&req, HardwareResult::Ok, 1);
    assert_eq!(
        next_reply(&peer).await,
        Message::PowerChannelState {
            name: "payload".into(),
            state: ChannelState::On
        }
    );

    peer.send(&Message::PowerChannelControl {
        name: "radio".into(),
        op: ChannelOp::ScheduleOn,
        sched_time: 5.0,
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.sub_op, PowerChannelOp::ScheduleOn.to_wire());
    assert_eq!(req.sched_s, 5.0);
    gw.hw_reply(&req, HardwareResult::Ok, 0);
    assert_eq!(
        next_reply(&peer).await,
        Message::PowerChannelState {
            name: "radio".into(),
            state: ChannelState::Off
        }
    );

    // QueryPowerChannelState: one state per channel from the latest HardwareState.
    let mut state = HardwareState::default();
    for (i, (name, on)) in [("payload", 1), ("radio", 0)].into_iter().enumerate() {
        state.channels[i].name = HwName::new(name);
        state.channels[i].on = on;
    }
    state.n_channels = 2;
    gw.hw_state.publish(state).unwrap();
    // The state arrives asynchronously: ask until it is answered.
    let deadline = tokio::time::Instant::now() + common::PATIENCE;
    loop {
        peer.send(&Message::QueryPowerChannelState).await.unwrap();
        if let Some(m) = peer
            .recv_message(Duration::from_millis(500), |m| {
                matches!(m, Message::PowerChannelState { .. })
            })
            .await
        {
            assert_eq!(
                m,
                Message::PowerChannelState {
                    name: "payload".into(),
                    state: ChannelState::On
                }
            );
            break;
        }
        assert!(tokio::time::Instant::now() < deadline, "never answered");
    }
    assert_eq!(
        next_reply(&peer).await,
        Message::PowerChannelState {
            name: "radio".into(),
            state: ChannelState::Off
        }
    );
    assert!(
        gw.hw_requests.try_recv().unwrap().is_none(),
        "no round trip"
    );
    gw.stop().await;
}

#[tokio::test]
async fn lcd_requests_get_no_reply_and_silence_times_out() {
    let mut s = settings();
    s.hardware_timeout = Duration::from_millis(200);
    let mut gw = Gateway::start_with(s).await;
    let peer = gw.peer().await;
    peer.send(&Message::LcdControl {
        op: LcdOperation::Write1,
        text: "hello".into(),
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::Lcd));
    assert_eq!(req.sub_op, LcdOp::WriteLine1.to_wire());
    assert_eq!(req.text.as_str(), "hello");
    gw.hw_reply(&req, HardwareResult::Ok, 0);
    barrier(&peer).await;

    // No hardware service answers: hardware_timeout, no IMC reply.
    peer.send(&Message::GpioStateGet { name: "in1".into() })
        .await
        .unwrap();
    gw.next_hw_request().await;
    gw.wait_dropped("hardware_timeout", 1.0).await;
    barrier(&peer).await;
    gw.stop().await;
}

#[tokio::test]
async fn a_power_down_reports_progress_then_its_abort() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;
    peer.send(&Message::PowerOperation {
        op: PowerOp::PowerDown,
        time_remain: 0.0,
        sched_time: 0.0,
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    assert_eq!(req.op(), Ok(HardwareOp::SystemPower));
    assert_eq!(req.sub_op, SystemPowerOp::PowerDown.to_wire());
    gw.hw_reply_with(
        &req,
        HardwareResult::Ok,
        0,
        SystemPowerOp::PowerDownInProgress.to_wire(),
        60.0,
    );
    assert_eq!(
        next_reply(&peer).await,
        Message::PowerOperation {
            op: PowerOp::PowerDownInProgress,
            time_remain: 60.0,
            sched_time: 0.0
        }
    );
    let mut state = HardwareState {
        system_power: SystemPowerOp::PowerDownInProgress.to_wire(),
        system_power_in_s: 55.0,
        ..Default::default()
    };
    gw.hw_state.publish(state).unwrap();
    expect(&peer, "PWR_DOWN_IP with the time left", |m| {
        *m == Message::PowerOperation {
            op: PowerOp::PowerDownInProgress,
            time_remain: 55.0,
            sched_time: 0.0,
        }
    })
    .await;
    state.system_power = SystemPowerOp::PowerDownAborted.to_wire();
    state.system_power_in_s = -1.0;
    gw.hw_state.publish(state).unwrap();
    expect(&peer, "PWR_DOWN_ABORTED", |m| {
        matches!(
            m,
            Message::PowerOperation {
                op: PowerOp::PowerDownAborted,
                ..
            }
        )
    })
    .await;

    // Refused by the hardware service (the default: no power-down command).
    peer.send(&Message::PowerOperation {
        op: PowerOp::PowerDown,
        time_remain: 0.0,
        sched_time: 0.0,
    })
    .await
    .unwrap();
    let req = gw.next_hw_request().await;
    gw.hw_reply_with(
        &req,
        HardwareResult::Refused,
        0,
        SystemPowerOp::PowerDownAborted.to_wire(),
        -1.0,
    );
    assert!(matches!(
        next_reply(&peer).await,
        Message::PowerOperation {
            op: PowerOp::PowerDownAborted,
            ..
        }
    ));
    gw.wait_dropped("hardware_refused", 1.0).await;
    gw.stop().await;
}
