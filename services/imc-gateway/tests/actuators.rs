//! Actuator messages become the configured VehicleCommands (source `imc`), answered
//! here by a fake autopilot-link; PWM is answered only after the command is accepted.

mod common;

use common::{barrier, next_reply, Gateway};
use imc_proto::{Message, ZoomAction};
use skymesh_ipc_types::{AckResult, Command, CommandSource, RefusalReason, ZoomMode};

#[tokio::test]
async fn servo_thruster_and_zoom_become_their_commands() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;

    peer.send(&Message::SetServoPosition {
        id: 0,
        value: std::f32::consts::FRAC_PI_2,
    })
    .await
    .unwrap();
    let cmd = gw.next_command().await;
    assert_eq!(cmd.source(), Ok(CommandSource::Imc));
    assert_eq!(cmd.vehicle_id, 1);
    assert_eq!(
        cmd.command().unwrap(),
        Command::Servo {
            channel: 9,
            pwm_us: 2000
        }
    );
    gw.ack(&cmd, AckResult::Accepted, RefusalReason::None);

    peer.send(&Message::SetThrusterActuation { id: 1, value: 0.5 })
        .await
        .unwrap();
    let cmd = gw.next_command().await;
    assert_eq!(
        cmd.command().unwrap(),
        Command::MotorTest {
            motor: 2,
            throttle_pct: 7.5,
            duration_s: 2.0
        }
    );
    // The arbiter refuses motor tests in the air: counted, nothing answered.
    gw.ack(&cmd, AckResult::Refused, RefusalReason::InAir);
    gw.wait_dropped("refused_in_air", 1.0).await;

    peer.send(&Message::CameraZoom {
        id: 0,
        zoom: 255,
        action: ZoomAction::Stop,
    })
    .await
    .unwrap();
    assert_eq!(
        gw.next_command().await.command().unwrap(),
        Command::CameraZoom {
            camera: 0,
            mode: ZoomMode::Range,
            value: 100.0
        }
    );
    barrier(&peer).await;
    gw.stop().await;
}

#[tokio::test]
async fn pwm_is_answered_only_once_the_command_is_accepted() {
    let mut gw = Gateway::start().await;
    let peer = gw.peer().await;
    let set = Message::SetPwm {
        id: 0,
        period: 20_000,
        duty_cycle: 1700,
    };
    peer.send(&set).await.unwrap();
    let cmd = gw.next_command().await;
    assert_eq!(
        cmd.command().unwrap(),
        Command::Servo {
            channel: 10,
            pwm_us: 1700
        }
    );
    // Not answered yet: the marker's REPORT is the first reply.
    barrier(&peer).await;
    gw.ack(&cmd, AckResult::Accepted, RefusalReason::None);
    assert_eq!(
        next_reply(&peer).await,
        Message::Pwm {
            id: 0,
            period: 20_000,
            duty_cycle: 1700
        }
    );

    // Refused: never answered, counted with the arbiter's reason.
    peer.send(&set).await.unwrap();
    let cmd = gw.next_command().await;
    gw.ack(&cmd, AckResult::Refused, RefusalReason::NoAuthority);
    gw.wait_dropped("refused_no_authority", 1.0).await;
    barrier(&peer).await;

    // A period the autopilot does not run at: unsupported, nothing published.
    peer.send(&Message::SetPwm {
        id: 0,
        period: 2_500,
        duty_cycle: 1500,
    })
    .await
    .unwrap();
    gw.wait_dropped("unsupported", 1.0).await;
    barrier(&peer).await;
    assert!(gw.commands.try_recv().unwrap().is_none());
    gw.stop().await;
}
